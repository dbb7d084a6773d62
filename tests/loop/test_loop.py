"""The coupled simulation: closed valves hold, replay reproduces, tracking, bad input."""

import dataclasses
import json

import numpy as np
import pytest

import mjcf
from sim.cli import main
from sim.control.tvc import ControllerGains
from sim.effects import build_model
from sim.loop.simulation import Simulation
from sim.scenario.files import build_motions, build_reference, load_scenario


@pytest.fixture(scope="module")
def loaded_no_supports():
    """CGS + 20 t block with the static supports removed: the vertical actuators carry
    the whole dead weight, so a force applied in the wrong place would make it sag."""
    d = mjcf.load_table("cgs")
    raw = json.loads(json.dumps(d.raw))
    raw["servovalve"]["null_leakage_m3_s"] = 0.0  # creep only through the piston leakage
    for cls in raw["actuator_class"].values():  # and no seal friction sharing the load
        cls["seal_friction_n"] = 0.0
    d2 = dataclasses.replace(mjcf.description.parse_table(raw, src="<no friction>"), supports=None)
    return build_model(d2, mjcf.load_payload("rigid_20t"))


def test_closed_valves_hold_the_loaded_table(loaded_no_supports):
    tm = loaded_no_supports
    sim = Simulation(tm)
    F = sim.static_forces()
    assert np.all(F[8:] > 1.5e5)  # Z1..Z4 carry ~700 kN together
    assert np.allclose(F[:8], 0, atol=1e-3)
    sim.reset(forces=F)
    secs = 4.0
    res = sim.run(valve_command=np.zeros((int(secs * 1024), tm.n_act)))
    assert res.incomplete_reason is None
    pose = res.channels["table_displacement"]
    # the table creeps down only through the cross-piston leakage: v = k_c * F / A^2
    hp = sim.hp
    A = hp.area_a_m2[8]
    v_creep = hp.leakage_cross_m3_s_pa[8] * F[8] / A**2
    dz = pose[-1, 2] - pose[0, 2]
    assert dz < 0
    assert abs(dz / (-v_creep * res.t[-1]) - 1) < 0.05, (dz, v_creep)
    assert np.abs(pose[:, [0, 1, 3, 4, 5]]).max() < 1e-6
    # and the sag stays far below the oil-column compliance a misplaced force would show
    assert abs(dz) < 1e-3


def test_closed_valves_hold_with_supports():
    tm = build_model(mjcf.load_table("cgs"), mjcf.load_payload("rigid_20t"))
    sim = Simulation(tm)
    res = sim.run(valve_command=np.zeros((3 * 1024, tm.n_act)))
    pose = res.channels["table_displacement"]
    assert np.abs(pose - pose[0]).max() < 1e-4


@pytest.fixture(scope="module")
def harmonic():
    sc = load_scenario("harmonic_bare")
    desc = mjcf.load_table(sc.table)
    tm = build_model(desc)
    ref = build_reference(sc, build_motions(sc))
    return tm, ref


def test_harmonic_test_tracks_within_2_percent(harmonic):
    tm, ref = harmonic
    sim = Simulation(tm)
    res = sim.run(reference=ref)
    assert res.incomplete_reason is None
    d = res.channels["table_displacement"]
    for i in range(3):
        e = d[:, i] - ref.d[: len(d), i]
        nrmse = np.sqrt(np.mean(e**2)) / np.sqrt(np.mean(ref.d[:, i] ** 2))
        assert nrmse < 0.02, (i, nrmse)
    assert np.nanmax(res.extras["loop_gap"]) < 1e-5


def test_replay_of_valve_commands_reproduces_the_run(harmonic):
    tm, ref = harmonic
    sim = Simulation(tm)
    short = dataclasses.replace(ref)
    res = sim.run(reference=short, duration_s=3.0)
    sim2 = Simulation(tm)
    rep = sim2.run(valve_command=res.channels["valve_command"])
    for ch in ("table_displacement", "table_acceleration", "actuator_force", "pressure_a", "accelerometers"):
        assert np.array_equal(res.channels[ch], rep.channels[ch]), ch


def test_compiled_and_numpy_paths_agree(harmonic):
    tm, ref = harmonic
    a = Simulation(tm).run(reference=ref, duration_s=1.0, fast=True)
    b = Simulation(tm, backend="numpy").run(reference=ref, duration_s=1.0, fast=False)
    for ch in ("table_displacement", "valve_command", "actuator_force"):
        scale = np.abs(a.channels[ch]).max() + 1e-12
        assert np.abs(a.channels[ch] - b.channels[ch]).max() / scale < 1e-7, ch


def test_fused_tick_gives_the_same_run_bit_for_bit(harmonic):
    """The default loop fuses recorder, controller and hydraulics into one compiled call
    per physics step; the per-stage calls (fuse=False) must give exactly the same run."""
    tm, ref = harmonic
    assert len(tm.friction_dofs)  # the fused call carries the pre-sliding friction too
    a = Simulation(tm).run(reference=ref, duration_s=1.0)
    b = Simulation(tm).run(reference=ref, duration_s=1.0, fuse=False)
    assert a.timing["fused_s"] > 0 and b.timing["fused_s"] == 0
    for ch in a.channels:
        assert np.array_equal(a.channels[ch], b.channels[ch], equal_nan=True), ch
    for key in a.extras:
        assert np.array_equal(a.extras[key], b.extras[key], equal_nan=True), key


def test_divergence_stops_and_keeps_the_partial_run(harmonic, monkeypatch):
    tm, ref = harmonic
    sim = Simulation(tm)
    calls = {"n": 0}
    orig = sim.loop_gap

    def bad_gap():
        calls["n"] += 1
        return 5e-3 if calls["n"] > 40 else orig()

    monkeypatch.setattr(sim, "loop_gap", bad_gap)
    res = sim.run(reference=ref, duration_s=2.0)
    assert res.incomplete_reason and "swivel opened by 5 mm" in res.incomplete_reason
    assert "t = " in res.incomplete_reason
    assert 0 < len(res.t) < 2.0 * 1024
    assert all(len(v) == len(res.t) for v in res.channels.values())


def test_run_cli_writes_run_file_and_summary(tmp_path, capsys):
    rc = main(["run", "harmonic_bare", "--out", str(tmp_path), "--duration", "2", "--json"])
    assert rc == 0
    s = json.loads(capsys.readouterr().out)
    assert s["realtime_factor"] > 0
    assert set(s["tracking"]) == {"x", "y", "z"}
    for e in s["tracking"].values():
        assert {"nrmse_displacement", "nrmse_acceleration", "pga_ratio"} <= set(e)
    from sim.runs.runfile import CHANNELS, SPECIMEN_CHANNELS, read_run

    # every channel a bare table's run has (a specimen's accelerometers need a specimen)
    bare = [c for c in CHANNELS if c not in SPECIMEN_CHANNELS]
    run = read_run(tmp_path / "harmonic_bare.run.npz", require=bare)
    assert run.sample_rate_hz == 1024.0 and run.n_samples == 2 * 1024 + 1
    assert run.accelerometers.shape[1] == 11
    assert json.loads((tmp_path / "summary.json").read_text())["scenario"] == "harmonic_bare"
    # the replay command reproduces it to round-off
    rc = main(["replay", str(tmp_path / "harmonic_bare.run.npz"), "--out", str(tmp_path), "--json"])
    rep = json.loads(capsys.readouterr().out)
    assert rc == 0
    assert max(rep["residual_nrmse"]["table_displacement"][k] for k in "xyz") < 1e-12


@pytest.mark.parametrize(
    "text,expect",
    [
        (
            '[scenario]\nname = "s"\ntable = "cgs"\ncolour = 1\n[motion]\ntype = "el_centro_1940"\n',
            "unknown key 'colour'",
        ),
        (
            '[scenario]\nname = "s"\ntable = "cgs"\nduration_s = 500.0\n[motion]\ntype = "el_centro_1940"\n',
            "longer than the motion",
        ),
        ('[scenario]\nname = "s"\ntable = "cgs"\n[motion.x]\ntype = "at2"\nfile = "rec.AT2"\n', "AT2"),
        ('[scenario]\nname = "s"\ntable = "cgs"\n[motion.q]\ntype = "sine"\n', "'q' is not a DOF"),
        (
            '[scenario]\nname = "s"\ntable = "cgs"\n[motion]\ntype = "el_centro_1940"\n[controller]\nkq = 1\n',
            "unknown controller key 'kq'",
        ),
    ],
)
def test_bad_scenarios_are_refused_in_one_line(tmp_path, capsys, text, expect):
    (tmp_path / "rec.AT2").write_text("this is not a PEER record\n1 2 3\n")
    p = tmp_path / "s.toml"
    p.write_text(text)
    rc = main(["run", str(p), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert expect in err, err
    assert len(err.splitlines()) == 1
    assert not list((tmp_path / "out").glob("*.run.npz")) if (tmp_path / "out").exists() else True


def test_limits_warn_and_unwritable_output_refused(tmp_path, capsys):
    p = tmp_path / "big.toml"
    p.write_text(
        '[scenario]\nname = "big"\ntable = "cgs"\nduration_s = 5.0\n'
        '[motion.x]\ntype = "sine"\namplitude = 0.3\nfrequency_hz = 0.1\n'
    )
    blocker = tmp_path / "file"
    blocker.write_text("x")
    rc = main(["run", str(p), "--out", str(blocker / "sub")])
    err = capsys.readouterr().err
    assert rc == 2 and "cannot write to output folder" in err
    assert "x peak displacement 0.3 m exceeds the +/-0.25 m stroke by 20 %" in err


def test_scenario_gains_override_table_defaults():
    d = mjcf.load_table("cgs")
    g = ControllerGains.for_table(d, {"kp_per_s": 12.0})
    assert np.all(g.kp_per_s == 12.0)
    assert g.kdp == d.raw["controller"]["kdp"]


def test_feasibility_verdict_flags_a_motion_beyond_the_stroke(tmp_path, capsys):
    p = tmp_path / "far.toml"
    p.write_text(
        '[scenario]\nname = "far"\ntable = "cgs"\nduration_s = 5.0\n'
        '[motion.x]\ntype = "sine"\namplitude = 0.31\nfrequency_hz = 0.1\n'
    )
    rc = main(["run", str(p), "--out", str(tmp_path), "--json"])
    out = capsys.readouterr()
    s = json.loads(out.out)
    assert rc == 0
    fe = s["feasibility"]
    checks = {c["name"]: c for c in fe["checks"]}
    assert not fe["feasible"] and "stroke_x" in fe["failed"]
    assert checks["stroke_x"]["demand"] == pytest.approx(0.31, rel=1e-3) and checks["stroke_x"]["capacity"] == 0.25
    assert all(c["pass"] for n, c in checks.items() if n.startswith("actuator_force"))
    ok = json.loads((tmp_path / "summary.json").read_text())
    assert ok["feasibility"]["failed"] == fe["failed"]


def test_diverged_run_is_kept_and_marked_incomplete(tmp_path, capsys, monkeypatch):
    import sim.loop.simulation

    monkeypatch.setattr(sim.loop.simulation, "GAP_LIMIT_M", 1.5e-7)  # a 0.15 um gap now counts as a failed loop closure
    # the loop's gap limit (a constant the compiled callback freezes at compile time): the loop engine
    rc = main(["run", "harmonic_bare", "--out", str(tmp_path), "--duration", "1", "--engine", "loop"])
    err = capsys.readouterr().err
    assert rc == 3
    assert "diverged at t = " in err and "swivel opened" in err and "marked incomplete" in err
    from sim.runs.runfile import read_run

    run = read_run(tmp_path / "harmonic_bare.run.npz")
    assert run.incomplete and "swivel" in run.incomplete_reason
    assert 2 <= run.n_samples < 1025
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["complete"] is False


def test_presliding_friction_model_compiled_matches_numpy(harmonic):
    """The pre-sliding friction option: compiled and numpy paths agree, friction is active
    (force reverses within ~the pre-sliding travel) and MuJoCo's frictionloss is off."""
    import tomllib

    from mjcf.description import TABLES_DIR, parse_table

    raw = tomllib.loads((TABLES_DIR / "cgs.toml").read_text())
    raw["friction"]["model"] = "presliding"
    tm = build_model(parse_table(raw, src="<presliding>"))
    assert len(tm.friction_dofs) == 24 and tm.model.dof_frictionloss.max() == 0.0
    _, ref = harmonic
    a = Simulation(tm).run(reference=ref, duration_s=2.0, fast=True)
    b = Simulation(tm, backend="numpy").run(reference=ref, duration_s=2.0, fast=False)
    for ch in ("table_displacement", "actuator_force"):
        scale = np.abs(a.channels[ch]).max()
        assert np.abs(a.channels[ch] - b.channels[ch]).max() / scale < 1e-7, ch
    # the exact pre-sliding update: 1 mm of travel (10 zss) from z = 0 gives
    # z = zss (1 - e^-10), force -Fc (1 - e^-10)
    from sim.loop import _kernels as FL

    z = np.zeros(1)
    q = np.zeros(1)
    FL.presliding_friction(np.array([0.1]), q, np.array([0]), np.array([1000.0]), z, 1e-4, 0.01)
    assert abs(z[0] - 1e-4 * (1 - np.exp(-10))) < 1e-18
    assert abs(q[0] + 1000.0 * (1 - np.exp(-10))) < 1e-9


def test_air_spring_kernel_matches_the_polytropic_law():
    """MuJoCo's joint spring plus sim.loop._kernels.air_springs = F0 (V0 / (V0 + A q))^n."""
    from sim.loop import _kernels as FL
    from sim.loop.simulation import Simulation

    F0, c, n = np.array([1.4e5, 1.2e5]), 0.2827 / 0.4, 1.4
    for q in (-0.1, -0.02, 0.0, 0.03, 0.1):
        qpos = np.array([q, -q])
        qfa = np.zeros(2)
        FL.air_springs(qpos, qfa, np.array([0, 1], dtype=np.int64), np.array([0, 1], dtype=np.int64), F0, c, n)
        qfa_np = np.zeros(2)
        Simulation._air_numpy(qpos, qfa_np, np.array([0, 1]), np.array([0, 1]), F0, c, n)
        linear = F0 - n * F0 * c * qpos
        exact = F0 * (1 + c * qpos) ** (-n)
        assert np.allclose(linear + qfa, exact, rtol=1e-12, atol=1e-9)
        assert np.array_equal(qfa, qfa_np) or np.allclose(qfa, qfa_np, rtol=1e-15, atol=1e-12)


# ------------------------------------------------------------------ one loop, two controllers
@pytest.fixture(scope="module")
def rice_sim():
    return Simulation.for_table(mjcf.load_table("rice"))


def test_the_controller_is_chosen_by_its_type_and_both_follow_the_protocol(harmonic, rice_sim):
    from sim.control.analog import AnalogGains, RiceController
    from sim.control.base import Controller, ControllerSettings, controller_settings
    from sim.control.tvc import TableController
    from sim.errors import ScenarioError

    tm, _ = harmonic
    cgs = Simulation(tm)
    assert isinstance(cgs.controller, TableController) and isinstance(cgs.controller, Controller)
    assert isinstance(rice_sim.controller, RiceController) and isinstance(rice_sim.controller, Controller)
    assert isinstance(cgs.gains, ControllerGains) and isinstance(rice_sim.gains, AnalogGains)
    assert isinstance(cgs.gains, ControllerSettings) and isinstance(rice_sim.gains, ControllerSettings)
    # MTS style: a tick and a record every 2 steps of 1/2048 s; analog: a tick every 1/8000 s step, a record every 2
    assert (cgs.steps_per_tick, cgs.steps_per_sample) == (2, 2)
    assert (rice_sim.steps_per_tick, rice_sim.steps_per_sample) == (1, 2) and rice_sim.dt == 1 / 8000
    assert cgs.controller.has_compiled_tick() and not rice_sim.controller.has_compiled_tick()
    # the analog controller's model has its parameter set applied (the bulk modulus of set d18)
    ps = rice_sim.tm.desc.raw["controller"]["parameter_sets"]["d18"]
    assert rice_sim.hp.bulk_modulus_pa == ps["beta_pa"]
    raw = json.loads(json.dumps(tm.desc.raw))
    raw.setdefault("controller", {})["type"] = "hydromechanical"
    with pytest.raises(ScenarioError, match="controller.type 'hydromechanical' is not one of digital, analog"):
        controller_settings(mjcf.description.parse_table(raw, src="t.toml"))


def _rice_ref(rate, n, slope=0.01):
    """A ramp of the commanded x (m, m/s): linear, so interpolating it is exact."""
    from sim.scenario.reference import Reference

    t = np.arange(n) / rate
    D, V = np.zeros((n, 6)), np.zeros((n, 6))
    D[:, 0], V[:, 0] = slope * t, slope
    return Reference(t=t, d=D, v=V, a=np.zeros((n, 6)))


def _paper_ramp_response(t, slope=0.01):
    """The actuator stroke the paper's linear model gives for ``_rice_ref``'s ramp: H(s) of
    Eqs. 1-8 of [Trombetti 2002] (sim.papers.rice.transfer, valve delay and foundation
    included) applied by FFT to the ramp, held, ramped back and held at 0 over a 4 s
    period (causal: the first ``len(t)`` samples see only the ramp, the previous period's
    tail has settled)."""
    from sim.papers import rice

    fs, n, period = 1.0 / (t[1] - t[0]), len(t), 16000
    k = np.arange(period)
    top = slope * t[-1]
    r = np.where(k < n, slope * k / fs, top)
    r[period // 2 :] = np.clip(top - slope * (k[period // 2 :] - period // 2) / fs, 0.0, None)
    f = np.fft.rfftfreq(period, 1.0 / fs)
    H = np.concatenate([[1.0], rice.transfer(f[1:]).H])  # H(0) = 1: the integral gain
    return np.fft.irfft(np.fft.rfft(r) * H, period)[:n]


def test_analog_controller_ticks_every_step_from_either_reference_rate(rice_sim):
    """The loop takes a reference at the recorder rate (interpolated to the controller's
    ticks) or at the controller rate (the paper's per-step command): the same run for a
    linear command; the valve command changes at every physics step, recorded every 2;
    the stroke follows the ramp as the paper's linear model of the loop says it should."""
    rice_sim.reset()
    a = rice_sim.run(reference=_rice_ref(4000.0, 201))
    rice_sim.reset()
    b = rice_sim.run(reference=_rice_ref(8000.0, 402))
    assert a.incomplete_reason is None and len(a.t) == len(b.t) == 201 and a.timing["steps"] == 402
    assert a.t[1] == 1 / 4000.0
    for ch in a.channels:
        assert np.allclose(a.channels[ch], b.channels[ch], rtol=1e-9, atol=1e-12), ch
    # the commanded ramp is followed as the analytical H(s) predicts: the valve's 13.5 ms
    # delay, then the stroke 22 % behind the ramp at 50 ms (measured: 0.17 % NRMSE)
    x = a.channels["actuator_displacement"][:, 0]
    y = _paper_ramp_response(a.t)
    assert np.sqrt(np.mean((x - y) ** 2)) < 0.01 * np.sqrt(np.mean(y**2))
    assert np.all(np.isfinite(a.channels["valve_command"]))


def test_analog_run_stops_when_the_actuator_leaves_its_stroke(rice_sim):
    """The analog controller's stroke limit (the paper's sign of an unstable loop) is part
    of the loop's one compiled divergence test."""
    rice_sim.reset()
    half = rice_sim.tm.desc.actuators[0].cls.half_stroke_m
    rice_sim.d.qpos[rice_sim.tm.stroke_qadr[0]] = 1.5 * half
    res = rice_sim.run(reference=_rice_ref(4000.0, 100, slope=0.0))
    assert res.incomplete_reason.startswith("simulation diverged at t = 0.0000 s: an actuator left its stroke")
    assert len(res.t) == 1


def test_the_recorder_can_sample_every_physics_step(rice_sim):
    """Recorder period 1 (records at the 8000 Hz physics rate) against period 2 on the
    same per-step command: the same run, every second record."""
    from sim.control.analog import AnalogGains

    g = rice_sim.gains
    every = Simulation.for_table(mjcf.load_table("rice"), gains=dataclasses.replace(g, rate_hz=8000.0))
    assert (every.steps_per_tick, every.steps_per_sample) == (1, 1) and isinstance(every.gains, AnalogGains)
    ref = _rice_ref(8000.0, 400, slope=0.02)
    rice_sim.reset()
    half = rice_sim.run(reference=ref)
    full = every.run(reference=ref)
    assert len(full.t) == 400 and len(half.t) == 200 and full.t[1] == 1 / 8000.0
    for ch in half.channels:
        assert np.array_equal(full.channels[ch][::2], half.channels[ch]), ch


def test_open_loop_on_the_analog_table_holds_the_recorded_commands(rice_sim):
    """Open loop (recorded valve commands at the recorder rate) on a table whose controller
    ticks between records: the commands are held for the whole sample, no tick runs."""
    rice_sim.reset()
    res = rice_sim.run(valve_command=np.full((200, 1), 0.01))  # 50 ms: past the valve's delay (set d18's tau)
    assert res.incomplete_reason is None and len(res.t) == 200
    assert np.all(res.channels["valve_command"] == 0.01)
    # the delayed spool settles on the held command (a tick would have moved it)
    assert np.allclose(res.channels["spool_position"][150:], 0.01, rtol=1e-6, atol=0)
    assert res.channels["actuator_displacement"][-1, 0] > res.channels["actuator_displacement"][0, 0]
