"""The real-record artifacts of ``run --measure`` (sim/runs/measure.py, docs/sensors.md):
skew of either sign, a causal analog conditioner of any order (it delays), drift, a
per-record offset, a quiet lead-in, unknown units; seeded and reproducible; a measured
run's meta holds only what a recorder writes (the chain goes to a sidecar file)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sim.runs import measure as M
from sim.runs.runfile import RunFile, read_run

FS = 1024.0


def sine_run(n=8192, f=8.0):
    """A 1-DOF run whose every motion/force channel is a sine (starting at rest: sin)."""
    t = np.arange(n) / FS
    s = np.sin(2 * np.pi * f * t)[:, None]
    meta = {
        "format": "shaketable-run/1",
        "table": "lab",
        "sample_rate_hz": FS,
        "actuators": ["A"],
        "dofs": ["x"],
        "source": "simulated",
        "force_lag_s": 0.5 / 2048,
    }
    return RunFile(
        t=t,
        meta=meta,
        reference=0.01 * s,
        actuator_force=1e4 * s,
        pressure_a=1e6 * s + 1e7,
        table_displacement=0.01 * s,
        table_acceleration=s.copy(),
    )


def phase_delay(y, x, t, f):
    """Delay (s) of ``y`` behind ``x`` at ``f`` (their phasors over whole cycles)."""
    e = np.exp(-2j * np.pi * f * t)
    return -np.angle(np.sum(y * e) / np.sum(x * e)) / (2 * np.pi * f)


ARTIFACTS = {
    "recorder": {"lead_in_s": 2.0},
    "channel": {
        "table_acceleration": {"skew_s": -2.0 / FS, "noise_rms": 0.01, "offset_rms": 0.05, "drift_per_sqrt_s": 0.01},
        "table_displacement": {"skew_s": 0.3 / FS, "offset_rms": 1e-3},
        "actuator_force": {"lowpass_hz": 30.0, "lowpass_order": 6, "ramp_per_s": 50.0},
        "pressure_a": {"gain": 1.0 / 6894.757},  # written in psi: a unit the file does not state
    },
}


def test_same_seed_identical_arrays_other_seed_other_offsets_and_drift():
    run = sine_run()
    a, b, c = (M.measure_run(run, ARTIFACTS, seed=s) for s in (5, 5, 6))
    for ch in ("table_acceleration", "table_displacement", "actuator_force", "pressure_a"):
        np.testing.assert_array_equal(getattr(a, ch), getattr(b, ch))
    assert not np.array_equal(a.table_acceleration, c.table_acceleration)
    # the per-record offset: the lead-in's mean (still, before drift grows) differs by seed
    n_lead = int(2.0 * FS)
    off = [np.mean(m.table_displacement[: n_lead // 2, 0]) for m in (a, c)]
    assert off[0] != pytest.approx(off[1], abs=1e-5)
    assert np.ptp(a.table_displacement[:n_lead, 0]) < 1e-12  # an offset, constant over the record


def test_quiet_lead_in_then_the_motion():
    run = sine_run()
    m = M.measure_run(run, {"recorder": {"lead_in_s": 2.0}}, seed=0)
    n_lead = int(2.0 * FS)
    assert m.n_samples == run.n_samples + n_lead
    assert np.all(m.table_acceleration[:n_lead] == 0.0) and np.all(m.reference[:n_lead] == 0.0)
    np.testing.assert_array_equal(m.table_acceleration[n_lead:], run.table_acceleration)
    assert m.t[0] == run.t[0] and np.allclose(np.diff(m.t), 1.0 / FS)


def test_skew_either_sign_and_a_two_sample_accelerometer_lag():
    run = sine_run()
    sens = {"channel": {"table_acceleration": {"skew_s": -2.0 / FS}, "table_displacement": {"skew_s": 0.3 / FS}}}
    m = M.measure_run(run, sens, seed=0)
    np.testing.assert_array_equal(m.table_acceleration[2:, 0], run.table_acceleration[:-2, 0])  # 2 samples late
    k = slice(128, -128)  # whole cycles of 8 Hz
    assert phase_delay(m.table_displacement[k, 0], run.table_displacement[k, 0], run.t[k], 8.0) == pytest.approx(
        -0.3 / FS, rel=0.01
    )  # 0.3 sample early


@pytest.mark.parametrize("order", [1, 2, 6])
def test_conditioner_of_any_order_is_causal_and_delays(order):
    """An analog Butterworth conditioner: the gain and phase delay of the continuous-time
    filter at 8 Hz (bilinear without pre-warping: within 0.1 %), nothing before an impulse."""
    run = sine_run()
    fc = 30.0
    m = M.measure_run(run, {"channel": {"table_acceleration": {"lowpass_hz": fc, "lowpass_order": order}}}, seed=0)
    import scipy.signal as sig

    b, a = sig.butter(order, 2 * math.pi * fc, analog=True)
    _, h = sig.freqs(b, a, [2 * math.pi * 8.0])
    k = slice(2048, None)  # after the start, whole cycles of 8 Hz
    y, x = m.table_acceleration[k, 0], run.table_acceleration[k, 0]
    e = np.exp(-2j * np.pi * 8.0 * run.t[k])
    assert abs(np.sum(y * e) / np.sum(x * e)) == pytest.approx(abs(h[0]), rel=1e-3)
    assert phase_delay(y, x, run.t[k], 8.0) == pytest.approx(-np.angle(h[0]) / (2 * np.pi * 8.0), rel=1e-2)
    assert phase_delay(y, x, run.t[k], 8.0) > 0  # causal: it delays
    imp = sine_run()
    imp.table_acceleration = np.zeros_like(imp.table_acceleration)
    imp.table_acceleration[3000] = 1.0
    yi = M.measure_run(imp, {"channel": {"table_acceleration": {"lowpass_hz": fc, "lowpass_order": order}}}, 0)
    assert np.all(yi.table_acceleration[:3000] == 0.0) and yi.table_acceleration[3000, 0] > 0


def test_drift_is_a_seeded_random_walk_and_a_ramp():
    n = 8192
    run = sine_run(n)
    run.table_acceleration = np.zeros((n, 1))
    walk = {"channel": {"table_acceleration": {"drift_per_sqrt_s": 0.01}}}
    ends = [M.measure_run(run, walk, seed=s).table_acceleration[-1, 0] for s in range(200)]
    T = (n - 1) / FS
    assert np.std(ends) == pytest.approx(0.01 * math.sqrt(T), rel=0.15)  # sigma sqrt(T)
    ramp = M.measure_run(run, {"channel": {"table_acceleration": {"ramp_per_s": 0.2}}}, seed=0)
    np.testing.assert_allclose(ramp.table_acceleration[:, 0], 0.2 * (run.t - run.t[0]), atol=1e-12)


def _analog_phase_delay(f, fc, order):
    """Phase delay (s) at ``f`` of an analog Butterworth low-pass of cut-off ``fc``."""
    import scipy.signal as sig

    b, a = sig.butter(order, 2 * np.pi * fc, analog=True)
    _w, h = sig.freqs(b, a, worN=[2 * np.pi * f])
    return -np.angle(h[0]) / (2 * np.pi * f)


def test_acceleration_through_the_tables_declared_conditioner(tmp_path):
    """A run on the ucsd table, whose ``[sensors]`` declares a 100 Hz accelerometer
    conditioner (4 poles: no order given), measured through a sensor file that gives the
    accelerometer none: its acceleration lags by that conditioner's delay (4.16 ms at low
    frequency, 1 / (2 pi 100 Hz sin(pi / 8))) and the meta declares it, as ``shaketable
    import`` does. A sensor file's own ``lowpass_hz`` is the sensor's real conditioner
    (the meta still says what the lab believes: the table's); a declaration in the sensor
    file wins; above the recorder's Nyquist frequency nothing is applied or declared."""
    run = sine_run(f=8.0)
    run.meta["table"] = "ucsd"
    k = slice(2048, None)  # past the filters' start
    t, x = run.t[k], run.table_acceleration[k, 0]
    table = {"delay_s": 0.0, "lowpass_hz": 100.0, "lowpass_order": 4}
    m = M.measure_run(run, {}, seed=0)
    assert m.meta["channel_conditioning"] == {"table_acceleration": table}
    delay = phase_delay(m.table_acceleration[k, 0], x, t, 8.0)
    assert delay == pytest.approx(_analog_phase_delay(8.0, 100.0, 4), rel=2e-3)  # 4.17 ms at 8 Hz
    assert delay == pytest.approx(1 / (2 * np.pi * 100.0 * math.sin(math.pi / 8)), rel=0.02)
    np.testing.assert_array_equal(m.actuator_force[k], M.measure_run(sine_run(f=8.0), {}, 0).actuator_force[k])
    # the sensor's own conditioner left at 30 Hz: the record lags by it, the meta says 100 Hz
    own = {"channel": {"table_acceleration": {"lowpass_hz": 30.0, "lowpass_order": 4}}}
    m30 = M.measure_run(run, own, seed=0)
    assert phase_delay(m30.table_acceleration[k, 0], x, t, 8.0) == pytest.approx(
        _analog_phase_delay(8.0, 30.0, 4), rel=2e-3
    )
    assert m30.meta["channel_conditioning"] == {"table_acceleration": table}
    # declared by the sensor file: its own chain (the table's conditioner it went through), or what it says
    decl = M.measure_run(run, {"channel": {"table_acceleration": {"declared": True, "skew_s": -1 / FS}}}, 0)
    assert decl.meta["channel_conditioning"] == {"table_acceleration": dict(table, delay_s=1 / FS)}
    says = M.measure_run(run, {"channel": {"table_acceleration": {"declared_lowpass_hz": 80.0}}}, 0)
    assert says.meta["channel_conditioning"]["table_acceleration"]["lowpass_hz"] == 80.0
    # a 128 Hz recorder (Nyquist 64 Hz): the 100 Hz conditioner is neither applied nor declared
    slow = M.measure_run(run, {"recorder": {"rate_hz": 128.0}}, seed=0)
    assert "channel_conditioning" not in slow.meta
    np.testing.assert_array_equal(slow.table_acceleration, run.table_acceleration[::8])
    # the sidecar names the table's conditioner
    M.write_measured(run, tmp_path, "u", {}, seed=0)
    side = json.loads((tmp_path / f"u.measured{M.CHAIN_SUFFIX}").read_text())
    assert side["table_conditioner"] == {"table_acceleration": table}


def test_meta_holds_only_what_a_recorder_writes(tmp_path):
    run = sine_run()
    sens = {
        "recorder": {"anti_alias_hz": 256.0},
        "channel": {
            "table_acceleration": {"lowpass_hz": 30.0, "lowpass_order": 4, "declared_lowpass_hz": 100.0},
            "actuator_force": {"skew_s": -0.004, "declared": True},
            "table_displacement": {"noise_rms": 1e-5},
        },
    }
    m = M.measure_run(run, sens, seed=0)
    assert "measurement" not in m.meta and "force_lag_s" not in m.meta
    assert m.meta["recorder"] == {"rate_hz": FS, "anti_alias_hz": 256.0, "anti_alias_order": 4, "digital": []}
    assert m.meta["channel_conditioning"] == {
        "table_acceleration": {"delay_s": 0.0, "lowpass_hz": 100.0, "lowpass_order": 4},  # what the lab believes
        "actuator_force": {"delay_s": 0.004, "lowpass_hz": None, "lowpass_order": 2},
    }
    p = M.write_measured(run, tmp_path, "s", sens, seed=3)
    side = json.loads((tmp_path / f"s.measured{M.CHAIN_SUFFIX}").read_text())
    assert side["seed"] == 3 and side["model"] == sens and side["of"] == "simulated"
    assert "measurement" not in read_run(p).meta


def test_the_force_is_sampled_at_the_motions_instant():
    """A simulated run's force lags its acceleration by ``force_lag_s``; measured, it is
    re-timed (read at t + lag) and the key dropped."""
    run = sine_run()
    m = M.measure_run(run, {}, seed=0)
    k = slice(128, -128)
    lag = run.meta["force_lag_s"]
    assert phase_delay(m.actuator_force[k, 0], run.actuator_force[k, 0], run.t[k], 8.0) == pytest.approx(-lag, rel=1e-3)


def test_unknown_units_a_pressure_in_psi():
    run = sine_run()
    m = M.measure_run(run, ARTIFACTS, seed=0)
    pa = M.measure_run(run, {"recorder": {"lead_in_s": 2.0}}, seed=0).pressure_a
    np.testing.assert_allclose(m.pressure_a, pa / 6894.757, rtol=1e-14)
    assert "units" not in json.dumps(m.meta)  # nothing says which


@pytest.mark.parametrize(
    "sensors, match",
    [
        ({"recorder": {"lead_in_s": -1.0}}, "recorder.lead_in_s must be a number >= 0"),
        ({"channel": {"actuator_force": {"lowpass_hz": [10.0]}}}, "lowpass_hz must be a number > 0"),
        ({"channel": {"actuator_force": {"lowpass_order": 0}}}, "whole number 1..12"),
        ({"channel": {"actuator_force": {"declared": "yes"}}}, "true or false"),
        ({"channel": {"actuator_force": {"drift_per_sqrt_s": -1.0}}}, ">= 0"),
        ({"channel": {"actuator_force": {"lowpass_hz": 600.0}}}, "Nyquist"),
        ({"channel": {"actuator_force": {"declared_delay_s": [0.0]}}}, "one number for the whole channel"),
    ],
)
def test_bad_new_keys_are_one_line_errors(sensors, match):
    with pytest.raises(M.SensorsError, match=match) as ei:
        M.measure_run(sine_run(n=64), sensors, seed=0)
    assert "\n" not in str(ei.value)


def test_specimen_accelerometers_of_a_shear_frame(tmp_path):
    """A run of the lab table carrying its 2-storey frame records each floor's
    accelerometer (``specimen_acceleration``, meta ``specimen_sensors``): the floor's
    absolute acceleration, here against the second difference of the floor's absolute
    displacement (table + drift; within its own truncation error, 0.2 %); measured, it
    gets the sensor model's noise like any channel."""
    from mjcf import load_payload, load_table
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.runfile import write_run
    from sim.scenario import motions as MO
    from sim.scenario.reference import reference_from_motions

    tm = build_model(load_table("lab"), load_payload("lab_2storey"))
    mo = MO.white_noise(duration_s=4.0, sample_rate_hz=FS, band_hz=(0.5, 20.0), seed=(1, 0), rms_acceleration=1.0)
    ref = reference_from_motions({"x": mo}, FS, 4.0)
    run = build_runfile(Simulation(tm).run(reference=ref), tm, reference=ref, payload_name="lab_2storey")
    assert run.meta["specimen_sensors"] == [
        {"name": "F1", "height_m": 0.8, "direction": [1.0, 0.0, 0.0]},
        {"name": "F2", "height_m": 1.6, "direction": [1.0, 0.0, 0.0]},
    ]
    back = read_run(write_run(tmp_path / "frame.run.npz", run))
    a = back.specimen_acceleration
    x = back.table_displacement[:, :1] + back.extras["payload_qpos"]
    d2 = (x[2:] - 2 * x[1:-1] + x[:-2]) * FS**2
    rms = np.sqrt(np.mean(a**2, axis=0))
    assert np.all(rms > 1.0)  # the floors move (1.5 m/s^2 RMS)
    assert np.all(np.sqrt(np.mean((a[1:-1] - d2) ** 2, axis=0)) < 0.005 * rms)
    assert back.column_names("specimen_acceleration") == ["F1", "F2"]
    m = M.measure_run(back, {"channel": {"specimen_acceleration": {"noise_rms": 0.03}}}, seed=1)
    assert np.std(m.specimen_acceleration - a) == pytest.approx(0.03, rel=0.05)
    bare = build_model(load_table("lab"))
    assert "specimen_sensors" not in build_runfile(Simulation(bare).run(reference=ref), bare, reference=ref).meta


def test_cli_measure_with_real_record_artifacts_is_reproducible(tmp_path):
    """``run --measure scenarios/sensors/real_record_1024hz.toml``: the same seed gives
    identical arrays, another seed other offsets; the 5 s lead-in is there; the meta
    declares the accelerometer's conditioner and 2-sample lag and nothing else of the chain."""
    from sim.cli import main

    model = str(M.DEFAULT_SENSORS.parent / "real_record_1024hz.toml")
    runs = []
    for k, seed in enumerate((4, 4, 5)):
        out = tmp_path / f"o{k}"
        argv = ["run", "ucsd_t8", "--duration", "0.25", "--out", str(out), "--measure", model]
        assert main(argv + ["--measure-seed", str(seed), "--json"]) == 0
        runs.append((read_run(out / "ucsd_t8.run.npz"), read_run(out / "ucsd_t8.measured.run.npz")))
    (sim_a, a), (_, b), (_, c) = runs
    for ch in a.present_channels():
        np.testing.assert_array_equal(getattr(a, ch), getattr(b, ch))
    assert not np.array_equal(a.actuator_force, c.actuator_force)
    assert a.n_samples == sim_a.n_samples + int(5.0 * FS)
    assert a.meta["channel_conditioning"]["table_acceleration"] == {
        "delay_s": 0.0019531,
        "lowpass_hz": 100.0,
        "lowpass_order": 4,
    }
    assert set(a.meta["channel_conditioning"]) == {"table_acceleration", "accelerometers"}
    assert "measurement" not in a.meta and "force_lag_s" not in a.meta


def test_the_lead_in_holds_the_valves_at_their_null():
    """The lead-in holds each valve at the command that passes no flow (minus its null
    offset: the simulation's ``valve_hold_command``), not the run's first command, which
    already drives the motion's onset; the measured meta does not keep the key (a recorder
    does not write it)."""
    import copy

    import mjcf
    from mjcf.description import parse_table
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.scenario import motions as Mo
    from sim.scenario.reference import reference_from_motions

    base = mjcf.load_table("lab")
    raw = copy.deepcopy(base.raw)
    raw["effect"] = list(raw.get("effect", [])) + [{"type": "valve_null_offset", "where": "actuators", "offset": 0.004}]
    tm = build_model(parse_table(raw, src=base.source))
    mo = {
        "x": Mo.white_noise(duration_s=4.0, sample_rate_hz=FS, band_hz=(1.0, 20.0), seed=(1, 0), rms_acceleration=2.0)
    }
    ref = reference_from_motions(mo, FS, 4.0)
    run = build_runfile(Simulation(tm).run(reference=ref), tm, reference=ref)
    assert run.meta["valve_hold_command"] == pytest.approx([-0.004])
    assert abs(run.valve_command[0, 0] + 0.004) > 1e-5  # the first command is not the hold
    m = M.measure_run(run, {"recorder": {"lead_in_s": 1.0, "digital": ["valve_command"]}}, seed=0)
    n_lead = int(FS)
    assert np.all(m.valve_command[:n_lead] == -0.004)
    np.testing.assert_array_equal(m.valve_command[n_lead:], run.valve_command)
    assert "valve_hold_command" not in m.meta
