"""Table faults (sim/effects/faults.py) and what the summary says of them (sim/assess/faults.py).

Each fault is planted in a short run of a small table and its consequence is found in
the recorded channels (not in the fault's own bookkeeping): nothing differs before the
fault's start; the stuck valve's spool sits at its opening; the supply pressure falls
after a pump trip; the vertical actuators take up the lost support's lift; the
controller's measured stroke freezes while the real one moves. The hard-over valve
scenario of the lab table checks the issue's must-show: the interlock trips before the
platen reaches its end cushion (and, there, does not stop it).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sim.assess.run import plan_scenario
from sim.cli import main
from sim.errors import ScenarioError

ROOT = Path(__file__).resolve().parents[2]
LAB = ROOT / "scenarios" / "tables" / "lab.toml"

SCEN = """[scenario]
name = "{name}"
table = "{table}"
duration_s = {dur}
{payload}
[motion.x]
type = "tapered_sine"
amplitude = {amp}
frequency_hz = 1.0
taper_cycles = 0.25
{extra}
"""


def scenario(tmp_path, name, extra="", *, table=str(LAB), dur=0.6, amp=0.05, payload=""):
    p = tmp_path / f"{name}.toml"
    p.write_text(SCEN.format(name=name, table=table, dur=dur, amp=amp, extra=extra, payload=payload))
    return p


def run(path, **kw):
    plan = plan_scenario(path, **kw)
    return plan, plan.run()


@pytest.fixture(scope="module")
def healthy(tmp_path_factory):
    """The lab table's 50 mm, 1 Hz sine with no fault (the reference for the others)."""
    return run(scenario(tmp_path_factory.mktemp("h"), "healthy"))[1]


def _same_until(a, b, t0):
    k = int(np.searchsorted(a.result.t, t0 - 1e-9))
    for key in ("actuator_displacement", "pressure_a", "valve_command"):
        assert a.result.channels[key][:k].tobytes() == b.result.channels[key][:k].tobytes(), key
    return k


def test_pump_trip_drains_the_supply(tmp_path, healthy):
    plan, out = run(scenario(tmp_path, "trip", '[[fault]]\ntype = "pump_trip"\nstart_s = 0.3\n'))
    k = _same_until(out, healthy, 0.3)  # nothing of the fault before its start
    ps, ps0 = out.result.extras["supply_pressure"], healthy.result.extras["supply_pressure"]
    assert ps[-1] < ps0[-1] - 0.5e6  # the accumulators alone: the supply falls
    assert np.all(np.diff(ps[k + 2 :]) <= 1e-3)  # and never recovers (nothing refills it)
    assert plan.sim.hs.state.q_pump[0] == 0.0
    ev = out.summary["faults"]["events"][0]
    assert ev["type"] == "pump_trip" and ev["t_s"] == pytest.approx(0.3, abs=1e-3)
    assert out.summary["faults"]["after"]["min_supply_pressure_pa"] == pytest.approx(ps[k:].min())


def test_stuck_valve_holds_its_spool_and_sensor_loss_freezes_the_feedback(tmp_path, healthy):
    extra = (
        '[[fault]]\ntype = "valve_stuck"\nwhere = "actuator:A"\nopening = 0.02\nstart_s = 0.2\n'
        "[interlock]\nenabled = false\n"
    )
    plan, out = run(scenario(tmp_path, "stuck", extra))
    k = _same_until(out, healthy, 0.2)
    ch = out.result.channels
    assert np.all(ch["valve_command"][k:, 0] == 0.02)
    assert np.allclose(ch["spool_position"][k + 40 :, 0], 0.02, atol=1e-4)  # the spool settled at the opening
    # a constant small opening: the actuator creeps out at the valve's flow over the area,
    # whatever the reference (which swings +/-50 mm meanwhile). The valve sizing law from the
    # table file's numbers, not the hydraulic kernel: no load, each metering land drops half
    # of supply - return, so Q = Q_rated x sqrt((p_s - p_t) / dp_rated) (measured: within
    # 0.1 %; the load's 0.24 MPa and the null leakage are the rest)
    s, t = ch["actuator_displacement"][:, 0], out.result.t
    last = t > t[-1] - 0.2
    creep = np.polyfit(t[last], s[last], 1)[0]
    raw = plan.sim.tm.desc.raw
    sv, sup = raw["servovalve"], raw["supply"]
    flow = (
        sv["rated_flow_m3_s"] * 0.02 * np.sqrt((sup["pressure_pa"] - sup["return_pressure_pa"]) / sv["rated_drop_pa"])
    )
    assert creep == pytest.approx(flow / raw["actuator_class"]["main"]["area_a_m2"], rel=0.01)
    assert "interlock" not in json.dumps(out.summary["faults"]["events"])  # enabled = false: no interlock

    extra = '[[fault]]\ntype = "sensor_loss"\nwhere = "actuator:A"\nmode = "zero"\nstart_s = 0.2\n'
    plan, out = run(scenario(tmp_path, "lvdt", extra))
    _same_until(out, healthy, 0.2)
    f = out.summary["faults"]
    assert f["events"][0]["reads_m"] == 0.0
    # the controller sees zero and drives the real stroke off; the error detector sees
    # the reference against the zero reading and trips once that passes 20 mm
    tr = f["interlock"]["trip"]
    assert tr is not None and tr["what"] == "stroke error limit" and tr["t_s"] > 0.2
    t, ref = out.result.t, plan.reference.d[: len(out.result.t), 0]  # one actuator along x: stroke = x
    first = t[(t >= 0.2 - 1e-9) & (np.abs(ref) > 0.02)][0]
    assert tr["t_s"] == pytest.approx(first, abs=2.5 / 1024)
    assert abs(tr["value"]) == pytest.approx(abs(ref[np.searchsorted(t, tr["t_s"])]), rel=0.05)


def test_hard_over_valve_trips_the_interlock_before_the_end_cushion(capsys):
    path = ROOT / "scenarios" / "faults" / "valve_hardover_lab.toml"
    plan, out = run(path)
    f = out.summary["faults"]
    tr, hit = f["interlock"]["trip"], f["after"]["end_cushion_reached"]
    assert f["events"][0]["hard_over"] and f["events"][0]["t_s"] == pytest.approx(0.5, abs=1e-3)
    assert tr is not None and hit is not None
    assert 0.5 < tr["t_s"] < hit["t_s"] and f["interlock_before_end_stops"] is True
    # the recorded strokes agree: under the usable stroke at the trip, in the cushion later
    t, s = out.result.t, out.result.channels["actuator_displacement"][:, 0]
    usable = plan.sim.hp.half_stroke_m[0] - plan.sim.hp.cushion_length_m[0]
    assert abs(s[np.searchsorted(t, tr["t_s"])]) < usable < np.max(np.abs(s))
    # after the trip the controller's command is null but the stuck valve stays open
    assert np.all(out.result.channels["valve_command"][t > tr["t_s"], 0] == 1.0)


def test_support_loss_moves_the_lift_to_the_vertical_actuators(tmp_path):
    extra = '[[fault]]\ntype = "support_pressure_loss"\nsupport = "S1"\nstart_s = 0.05\n'
    plan, out = run(
        scenario(tmp_path, "support", extra, table="cgs", amp=0.0001, payload='payload = "rigid_20t"'),
        duration_s=0.3,
    )
    tm = plan.tm
    lift = float(tm.air_preload[0])
    assert out.summary["faults"]["events"][0]["lift_lost_n"] == pytest.approx(lift)
    assert out.summary["faults"]["events"][0]["where"] == "support:S1"
    F = out.result.channels["actuator_force"]
    z = [i for i, n in enumerate(plan.sim.hp.names) if n.startswith("Z")]
    before = F[:40, z].sum(axis=1).mean()
    after = F[-60:, z].sum(axis=1).mean()
    assert after - before == pytest.approx(lift, rel=0.15)  # the vertical actuators carry what S1 lost


def test_engines_and_tables_that_cannot_run_faults_say_so(tmp_path):
    from sim.loop.callback import accepts

    plan = plan_scenario(
        scenario(tmp_path, "s", '[[fault]]\ntype = "sensor_loss"\nwhere = "actuator:X1"\n', table="cgs", amp=0.001),
        engine="callback",
    )
    assert plan.engine == "loop" and "fault" in accepts(plan.sim)
    with pytest.raises(ScenarioError, match=r"analog .*valve_stuck"):
        plan_scenario(
            scenario(
                tmp_path,
                "r",
                '[[fault]]\ntype = "valve_stuck"\nwhere = "actuator:A"\nopening = 1.0\n',
                table="rice",
                amp=0.01,
            )
        )
    with pytest.raises(ScenarioError, match=r"r2.toml: \[\[fault\]\] #1: where = 'actuator:X9' names no actuator"):
        plan_scenario(
            scenario(tmp_path, "r2", '[[fault]]\ntype = "valve_stuck"\nwhere = "actuator:X9"\nopening = 1.0\n')
        )
    with pytest.raises(ScenarioError, match=r"\[interlock\].*'error_limit_m' = -1"):
        plan_scenario(scenario(tmp_path, "r3", "[interlock]\nerror_limit_m = -1.0\n"))


def test_run_command_prints_and_writes_the_event(tmp_path, capsys):
    path = scenario(tmp_path, "cli", '[[fault]]\ntype = "pump_trip"\nstart_s = 0.1\n', dur=0.6)
    assert main(["run", str(path), "--out", str(tmp_path / "o")]) == 0
    text = capsys.readouterr().out
    assert "fault: pump trip: supply flow to zero at supply, t = 0.100" in text  # the first physics step from 0.1 s
    assert "interlock: did not trip" in text
    doc = json.loads((tmp_path / "o" / "summary.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    assert doc["faults"]["events"][0]["t_s"] == pytest.approx(0.1, abs=1e-3)
    assert doc["faults"]["interlock"]["limits"]["error_limit_m"] == 0.02


def test_a_fault_run_is_reproducible_and_its_run_file_names_the_faults(tmp_path):
    from sim.runs.runfile import read_run

    path = scenario(tmp_path, "again", '[[fault]]\ntype = "sensor_loss"\nwhere = "actuator:A"\nstart_s = 0.2\n')
    for k in range(2):
        assert main(["run", str(path), "--out", str(tmp_path / f"o{k}"), "--json"]) == 0
    a, b = (read_run(tmp_path / f"o{k}" / "again.run.npz") for k in range(2))
    for name in ("t",) + tuple(a.present_channels()):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name
    assert a.meta["faults"] == b.meta["faults"]
    assert [f["type"] for f in a.meta["faults"]] == ["sensor_loss", "interlock"]
    assert a.meta["faults"][0]["where"] == "actuator:A" and a.meta["faults"][0]["start_s"] == 0.2


def test_interlock_ramp_down(tmp_path):
    """``ramp_down_s``: after the trip the valve commands shrink to null over that time
    (0: at once), and the pumps are off."""
    extra = (
        '[[fault]]\ntype = "sensor_loss"\nwhere = "actuator:A"\nmode = "zero"\nstart_s = 0.3\n'
        "[interlock]\nramp_down_s = 0.1\n"
    )
    plan, out = run(scenario(tmp_path, "ramp", extra))
    tr = out.summary["faults"]["interlock"]["trip"]
    assert tr["action"] == "valve commands to null over 0.1 s, pumps off"
    t, u = out.result.t, out.result.channels["valve_command"][:, 0]
    during = (t > tr["t_s"] + 1e-9) & (t < tr["t_s"] + 0.1 - 1e-9)
    assert np.any(u[during] != 0.0) and np.all(u[t >= tr["t_s"] + 0.1 + 1e-9] == 0.0)
    assert plan.sim.hs.state.q_pump[0] == 0.0


def test_a_run_without_faults_keeps_the_fused_tick(tmp_path):
    """No fault declared: no hooks, the compiled fused tick runs as before (the fault
    machinery costs a healthy run nothing)."""
    from sim.effects.faults import hooks_for

    plan = plan_scenario(scenario(tmp_path, "plain", table="cgs", amp=0.001), duration_s=0.05)
    assert hooks_for(plan.sim) is None and "faults" not in plan.run().summary
    assert plan.sim.run(reference=plan.reference).timing["fused_s"] > 0
