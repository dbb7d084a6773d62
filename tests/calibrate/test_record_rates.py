"""Records whose rate is not the controller's: the model a record is compared with steps
as ``shaketable run`` does (the Rice table's analog controller acts every 1/8000 s and
its 4000 Hz records are the model's samples there only), its ticks reach every recorded
instant, and a slower recorder's samples of a faster controller's command are
interpolated, not held (docs/import.md)."""

from __future__ import annotations

import numpy as np
import pytest

import mjcf
from sim.calibrate.replay import command_hold, tick_rate, ticks_covering
from sim.loop.simulation import description_as_run, table_model


@pytest.mark.parametrize(
    "record_hz, hold, physics_hz, controller_hz, tick",
    [
        (1024.0, "zoh", 2048.0, 1024.0, 1024.0),  # the MTS-style tables' own records
        (204.8, "linear", 2048.0, 1024.0, 1024.0),  # the worked example: onto the controller's ticks
        (1000.0, "zoh", 2048.0, 1024.0, 1024.0),  # a rate that does not divide the physics rate
        (4000.0, "zoh", 8000.0, 8000.0, 4000.0),  # the Rice records, held: on their own samples
        (4000.0, "linear", 8000.0, 8000.0, 8000.0),  # interpolated: on the analog controller's steps
        (1024.0, "zoh", 8000.0, 8000.0, 1000.0),  # 1024 Hz does not divide 8000 Hz: 1000 Hz ticks
    ],
)
def test_the_tick_divides_the_model_physics_rate(record_hz, hold, physics_hz, controller_hz, tick):
    got = tick_rate(record_hz, hold, physics_hz, controller_hz)
    assert got == pytest.approx(tick)
    assert (physics_hz / got) == pytest.approx(round(physics_hz / got))


def test_the_ticks_reach_the_record_last_instant():
    """A 4000 Hz window of 8560 samples on 1000 Hz ticks: the last tick before its last
    instant left four samples unmodelled, and the model was refused as 'stopped early'."""
    t = np.arange(8560) / 4000.0
    tt = ticks_covering(t, 1000.0)
    assert tt[-1] >= t[-1] and tt[-2] < t[-1]
    # where the grids agree, the same ticks as the record's own
    t1024 = np.arange(13312) / 1024.0
    assert np.array_equal(ticks_covering(t1024, 1024.0), t1024)


class _Record:
    def __init__(self, rate, meta=None):
        self.sample_rate_hz = rate
        self.meta = meta or {}


def test_the_command_is_interpolated_where_the_controller_is_faster():
    rice, ucsd = mjcf.load_table("rice"), mjcf.load_table("ucsd")
    assert command_hold(_Record(4000.0), rice) == "cubic"  # analog controller, 8000 Hz
    assert command_hold(_Record(1024.0), ucsd) == "zoh"  # the controller's own rate
    assert command_hold(_Record(256.0), ucsd) == "cubic"  # a slower recorder
    assert command_hold(_Record(4000.0, {"command_hold": "zoh"}), rice) == "zoh"  # the record says


def test_the_declared_model_is_the_one_run_simulates():
    """The Rice description's analog controller names a parameter set (Table 1 of
    Trombetti and Conte 2002) whose delay, bulk modulus and leakage ``run`` applies over
    the file's: the model a record is compared with has them, at 1/8000 s."""
    rice = mjcf.load_table("rice")
    raw = dict(rice.raw, servovalve=dict(rice.raw["servovalve"], delay_s=0.005))
    edited = mjcf.description.parse_table(raw, src=rice.source)
    ran = description_as_run(edited)
    assert ran.raw["servovalve"]["delay_s"] == pytest.approx(0.0135)  # set d18: tau = 13.5 ms
    assert str(ran.source) == str(rice.source)  # the file the calibrated copy is written from
    assert table_model(ran).model.opt.timestep == pytest.approx(1 / 8000)
    ucsd = mjcf.load_table("ucsd")
    assert description_as_run(ucsd) is ucsd
    assert table_model(ucsd).model.opt.timestep == pytest.approx(1 / 2048)


def test_a_rice_record_replays_to_round_off(tmp_path):
    """A simulated 2 s Rice run (4000 Hz, analog controller) replayed open loop: the model's
    acceleration is the run's to round-off. Held on 1024 Hz ticks at 1/2048 s it was 3.5 %
    off (force 6.2 %) on an 8 s white noise."""
    from sim.calibrate.replay import replay
    from sim.cli import main

    scen = tmp_path / "wn.toml"
    scen.write_text(
        '[scenario]\nname = "wn"\ntable = "rice"\nduration_s = 2.0\n'
        '[motion.x]\ntype = "white_noise"\nband_hz = [1.0, 30.0]\nseed = 3\nrms_acceleration = 3.0\ntaper_s = 0.25\n'
        "[output]\nsample_rate_hz = 4000.0\n"
    )
    assert main(["run", str(scen), "--out", str(tmp_path)]) == 0
    out = replay(str(tmp_path / "wn.run.npz"))
    assert out.complete and out.tick_hz == 8000.0 and out.hold == "cubic"
    for ch in ("table_acceleration", "actuator_force"):
        err = [v for v in out.residual_nrmse[ch].values() if v is not None]
        assert err and max(err) < 1e-3, (ch, out.residual_nrmse[ch])


def test_a_1000_hz_record_is_modelled_whole(tmp_path):
    """A lab's 1000 Hz export of a table whose controller ticks at 1024 Hz: the model is
    sampled back at every recorded instant. The last 1024 Hz tick fell before the
    record's last instant, and `calibrate` refused every such record ('the declared
    model's replay run diverged or stopped early')."""
    from sim.calibrate import paths as P
    from sim.calibrate import search as S
    from sim.cli import main
    from sim.runs.runfile import read_run, write_run
    from sim.signals.resample import interpolate

    scen = tmp_path / "wn.toml"
    scen.write_text(
        '[scenario]\nname = "wn"\ntable = "ucsd"\nduration_s = 2.0\n'
        '[motion.x]\ntype = "white_noise"\nband_hz = [1.0, 15.0]\nseed = 4\nrms_acceleration = 2.0\ntaper_s = 0.25\n'
    )
    assert main(["run", str(scen), "--out", str(tmp_path)]) == 0
    run = read_run(tmp_path / "wn.run.npz")
    t = np.asarray(run.t) - run.t[0]
    t1000 = np.arange(int(t[-1] * 1000.0)) / 1000.0  # to 1.999 s
    assert t1000[-1] * 1024.0 % 1.0 > 0  # the record's last instant is not on a tick
    for ch in ("valve_command", "reference", "actuator_displacement", "actuator_force", "table_displacement"):
        setattr(run, ch, interpolate(t, np.asarray(getattr(run, ch), float), t1000))
    for ch in ("table_velocity", "table_acceleration", "accelerometers", "spool_position", "pressure_a", "pressure_b"):
        setattr(run, ch, None)
    run.t, run.extras = t1000, {}
    run.meta["sample_rate_hz"] = 1000.0
    path = write_run(tmp_path / "wn1000.run.npz", run)
    runs, _, desc, pl = S._inputs([str(path)], None, "ucsd", None, None, None, None)
    prs = P.path_runs(runs, desc, "replay", payload=pl)
    models = P.simulate_many([p.job(desc.raw, str(desc.source), pl, []) for p in prs], workers=1)
    assert all(m is not None for m in models)
    assert P.nrmse(prs, models) < 0.05, P.nrmse(prs, models)


def test_a_cubic_spline_keeps_the_drive_amplitude_that_linear_loses():
    """A 20 Hz drive sampled at 200 Hz, put onto 1024 Hz ticks: linear interpolation
    keeps sinc^2(0.1) = 96.7 % of its RMS, a cubic spline over 99.9 %; held, all of it
    but half a sample late."""
    from sim.calibrate.replay import command_on_ticks

    t = np.arange(400) / 200.0
    u = np.sin(2 * np.pi * 20.0 * t + 0.3)[:, None]
    tt = np.arange(int(t[-1] * 1024)) / 1024.0
    keep = (tt > 0.2) & (tt < t[-1] - 0.2)
    true = np.sin(2 * np.pi * 20.0 * tt[keep] + 0.3)

    def kept(hold):
        return float(np.std(command_on_ticks(t, u, tt, hold)[keep, 0]) / np.std(true))

    assert kept("linear") == pytest.approx(np.sinc(0.1) ** 2, abs=0.01)
    assert kept("cubic") > 0.999
    err = command_on_ticks(t, u, tt, "cubic")[keep, 0] - true
    assert float(np.std(err)) < 0.01
