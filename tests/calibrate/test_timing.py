"""Sensor timing and conditioning on the mechanical path (sim/calibrate/timing.py):
plant a sensor fault in "measured" runs with real-record artifacts, calibrate with
defaults (the stock ucsd description, which declares 100 Hz accelerometer
conditioners), recover it with the truth inside its 95 % interval; clean runs with the
same artifacts add nothing. The runs' meta holds only what a recorder writes (its
settings and the declared conditioning): the calibrator never sees the chain.

The runs: NEES-UCSD table (scenarios/tables/ucsd.toml), band-limited white noise
0.5-20 Hz, 1 m/s^2 RMS, 6 s after a 3 s quiet lead-in, three seeds (two fitted, one
held out), measured through a 1024 Hz recorder with a 256 Hz anti-alias filter, a
4-pole 100 Hz accelerometer conditioner, the accelerometer two samples late (declared),
displacement and velocity 0.3 sample early (not declared), per-record offsets, drift
and noise on every motion and force channel.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from sim.calibrate import search as S
from tests.calibrate.records import noise_run

FS = 1024.0
#: the artifacts of every run here (docs/sensors.md keys; sizes as the built-in recorder's noise)
ARTIFACTS = {
    "recorder": {"anti_alias_hz": 256.0, "anti_alias_order": 4, "digital": ["reference"], "lead_in_s": 3.0},
    "channel": {
        "table_acceleration": {
            "lowpass_hz": 100.0,
            "lowpass_order": 4,
            "skew_s": -2.0 / FS,  # two samples late
            "declared": True,  # the lab states its conditioner and the lag
            "noise_rms": 0.0294,
            "offset_rms": 0.05,
            "drift_per_sqrt_s": 0.002,
        },
        "actuator_force": {"noise_rms": 1.0e3, "offset_rms": 2.0e3, "drift_per_sqrt_s": 100.0},
        "table_displacement": {"noise_rms": 20e-6, "skew_s": 0.3 / FS, "offset_rms": 1e-3},
        "table_velocity": {"noise_rms": 2.5e-4, "skew_s": 0.3 / FS},
    },
}


def measured_runs(out, sensors, seeds=(1, 2, 3), seconds=6.0):
    """ucsd runs under white noise, through ``sensors`` (a SENSORS.toml as a dict)."""
    from mjcf import load_table
    from sim.effects import build_model
    from sim.runs.measure import measure_run
    from sim.runs.runfile import write_run

    tm = build_model(load_table("ucsd"))
    paths = []
    for s in seeds:
        _res, run = noise_run(tm, (s, 0), seconds, fs=FS, band_hz=(0.5, 20.0), rms=1.0)
        run = measure_run(run, sensors, seed=s)
        assert "measurement" not in run.meta and "force_lag_s" not in run.meta  # a recorder's meta only
        paths.append(str(write_run(out / f"ucsd_{s}.run.npz", run)))
    return paths


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    paths = measured_runs(tmp_path_factory.mktemp("clean"), ARTIFACTS)
    return S.calibrate(paths, path="mechanical")


def test_clean_runs_with_every_artifact_add_nothing(clean):
    assert clean.residual_path == "mechanical"
    assert clean.effects_added == []
    assert clean.error_before < 0.03  # the noise floor of these runs (2.17 % measured)
    timing_rows = [c for c in clean.candidates if c["name"] in ("sensor_delay", "sensor_lowpass")]
    # 2 delays, 1 conditioner, and the motion's own delays: the acceleration puts the
    # displacement 0.3 sample early (-0.368 +/- 0.132 ms measured), which the records hold
    # but which moves the held-out error by less than the margin (+0.07 %); the
    # displacement puts the velocity half a physics step (1/4096 s) late, the simulator's
    # (MuJoCo's semi-implicit Euler: the velocity of a step is its position's backward
    # difference): 0.290 +/- 0.092 ms measured, refused as well (+0.04 %)
    assert len(timing_rows) == 5 and not any(c["accepted"] for c in timing_rows)
    (motion,) = [c for c in timing_rows if c["where"] == "channel:table_displacement"]
    d, u = motion["parameters"]["delay_s"], motion["uncertainty"]["delay_s"]
    assert abs(d + 0.3 / FS) <= u < 2e-4, (d, u)
    (velocity,) = [c for c in timing_rows if c["where"] == "channel:table_velocity"]
    d, u = velocity["parameters"]["delay_s"], velocity["uncertainty"]["delay_s"]
    assert abs(d - 0.5 / 2048) <= u < 2e-4, (d, u)


def test_force_sensor_delay_found(clean, tmp_path):
    """A load cell 4 ms late (the channel's sample taken 4 ms before its time stamp)."""
    sensors = copy.deepcopy(ARTIFACTS)
    sensors["channel"]["actuator_force"]["skew_s"] = -0.004
    res = S.calibrate(measured_runs(tmp_path, sensors), path="mechanical")
    (e,) = res.effects_added
    assert (e["name"], e["where"]) == ("sensor_delay", "channel:actuator_force")
    d, u = e["parameters"]["delay_s"], e["uncertainty"]["delay_s"]
    assert abs(d - 0.004) <= u  # the truth inside the 95 % interval (3.9989 +/- 0.0064 ms measured)
    assert abs(d - 0.004) < 2e-5 and 0 < u < 5e-5
    row = next(c for c in res.candidates if c["accepted"])
    assert row["coherent_share"] > 0.95  # a late load cell's change is the motion's own force
    assert res.error_before > 10 * clean.error_before  # 0.308 against 0.0217
    assert res.error_after <= 1.02 * clean.error_before


def test_accelerometer_conditioner_mismatch_found(clean, tmp_path):
    """The accelerometer's conditioner left at 30 Hz where the lab declares 100 Hz."""
    sensors = copy.deepcopy(ARTIFACTS)
    acc = sensors["channel"]["table_acceleration"]
    acc.update(lowpass_hz=30.0, declared_lowpass_hz=100.0, declared_lowpass_order=4)
    res = S.calibrate(measured_runs(tmp_path, sensors), path="mechanical")
    (e,) = res.effects_added
    assert (e["name"], e["where"], e["options"]) == (
        "sensor_lowpass",
        "channel:table_acceleration",
        {"order": 4, "replaces_declared": True},
    )
    fc, u = e["parameters"]["cutoff_hz"], e["uncertainty"]["cutoff_hz"]
    assert abs(fc - 30.0) <= u  # 29.989 +/- 0.012 Hz measured
    assert abs(fc - 30.0) < 0.05 and 0 < u < 0.1
    assert res.error_before > 10 * clean.error_before  # 0.764 against 0.0217
    assert res.error_after <= 1.02 * clean.error_before


def test_undeclared_accelerometer_lag_found(clean, tmp_path):
    """The accelerometer two samples late (1.953 ms) with only its conditioner declared."""
    sensors = copy.deepcopy(ARTIFACTS)
    acc = sensors["channel"]["table_acceleration"]
    del acc["declared"]
    acc.update(declared_lowpass_hz=100.0, declared_lowpass_order=4)  # the lag is not declared
    res = S.calibrate(measured_runs(tmp_path, sensors), path="mechanical")
    (e,) = res.effects_added
    assert (e["name"], e["where"]) == ("sensor_delay", "channel:table_acceleration")
    d, u = e["parameters"]["delay_s"], e["uncertainty"]["delay_s"]
    assert abs(d - 2.0 / FS) <= u and abs(d - 2.0 / FS) < 2e-5 and 0 < u < 5e-5
    assert res.error_after <= 1.02 * clean.error_before


def test_shift_is_a_delay_of_either_sign():
    from sim.calibrate.timing import shift

    dt = 1.0 / FS
    t = np.arange(4096) * dt
    x = np.sin(2 * np.pi * 7.0 * t)
    for d in (0.0042, -0.0017):
        y = shift(x, d, dt)
        k = slice(64, -64)
        np.testing.assert_allclose(y[k], np.sin(2 * np.pi * 7.0 * (t[k] - d)), atol=1e-6)


def test_mains_pickup_on_the_load_cell_is_not_a_sensor_fault(tmp_path):
    """A 60 Hz, 3 kN line on the force channel adds no timing candidate (the conditioner is
    searched at its declared order: one of another order with the same in-band delay
    would filter the line out of the force it is applied to)."""
    from sim.runs.runfile import read_run, write_run

    paths = []
    for p in measured_runs(tmp_path, ARTIFACTS):
        r = read_run(p)
        r.actuator_force[:, 0] += 3e3 * np.sin(2 * np.pi * 60.0 * r.t + 0.3)
        paths.append(str(write_run(p, r)))
    res = S.calibrate(paths, path="mechanical")
    assert res.effects_added == []
    lows = [c for c in res.candidates if c["name"] == "sensor_lowpass"]
    assert [c["options"] for c in lows] == [{"order": 4}] and abs(lows[0]["parameters"]["cutoff_hz"] - 100.0) < 0.5


def test_coherent_share_tells_the_motions_force_from_a_line():
    """What a timing candidate takes out of the residual: a filtered copy of the motion's
    force is coherent with the motion, a 60 Hz line on the load cell is not."""
    from types import SimpleNamespace

    import scipy.signal as sig

    from sim.calibrate.timing import COHERENT_SHARE, coherent_share

    n = 8192
    rng = np.random.default_rng(4)
    a = sig.lfilter(*sig.butter(4, 20.0, fs=FS), rng.standard_normal(n))
    mr = SimpleNamespace(dt=1 / FS, u=np.zeros((n, 1)), v=np.zeros((n, 1)), a=a[:, None])
    mr.u[:, 0] = rng.standard_normal(n)  # unrelated states: coherence is the largest of the three
    mr.v[:, 0] = rng.standard_normal(n)
    force = 3e4 * a
    late = 3e4 * np.interp(np.arange(n) - 4.1, np.arange(n), a)  # the same force 4 ms late
    line = 3e3 * np.sin(2 * np.pi * 60.0 * np.arange(n) / FS + 0.3) + 300.0 * rng.standard_normal(n)
    zero = np.zeros((n, 1))
    assert coherent_share([mr], [(force - late)[:, None]], [zero]) > 0.95
    assert coherent_share([mr], [line[:, None]], [zero]) < COHERENT_SHARE


def test_declared_conditioning_read_from_the_run_not_the_chain():
    """The mechanical path's starting timing: the run's declared conditioning over the
    table's; a declared conditioner above 0.45 of the rate counts as its delay."""
    from types import SimpleNamespace

    from sim.calibrate.timing import declared_state

    def run(cond):
        return SimpleNamespace(name="r", dt=1 / FS, meta={"channel_conditioning": cond} if cond else {})

    assert declared_state(run(None), 100.0) == {
        "force_delay_s": 0.0,
        "accel_delay_s": 0.0,
        "accel_lowpass_hz": 100.0,
        "accel_lowpass_order": 4,
    }
    s = declared_state(
        run(
            {
                "table_acceleration": {"delay_s": 0.002, "lowpass_hz": 30.0, "lowpass_order": 2},
                "actuator_force": {"delay_s": -0.001, "lowpass_hz": None, "lowpass_order": 2},
            }
        ),
        100.0,
    )
    assert s == {"force_delay_s": -0.001, "accel_delay_s": 0.002, "accel_lowpass_hz": 30.0, "accel_lowpass_order": 2}
    hi = declared_state(run({"table_acceleration": {"delay_s": 0.0, "lowpass_hz": 1000.0, "lowpass_order": 4}}), None)
    assert hi["accel_lowpass_hz"] is None and hi["accel_delay_s"] == pytest.approx(
        2.6131 / (2 * np.pi * 1000.0), rel=1e-4
    )


@pytest.mark.parametrize(
    "cond, match",
    [
        ({"table_acceleration": {"lowpass_hz": -3.0}}, "lowpass_hz must be a cut-off > 0 Hz"),
        (
            {"table_acceleration": {"lowpass_hz": 50.0, "lowpass_order": 0}},
            "lowpass_order must be a whole number 1..12",
        ),
        ({"actuator_force": {"delay_s": "4 ms"}}, "delay_s must be a number of seconds"),
        ({"actuator_force": 0.004}, "must be a table of delay_s"),
    ],
)
def test_bad_declared_conditioning_is_one_line(cond, match):
    from types import SimpleNamespace

    from sim.calibrate.conditioning import channel_conditioning
    from sim.calibrate.residuals import CalibrationError

    with pytest.raises(CalibrationError, match=match) as ei:
        channel_conditioning(SimpleNamespace(name="rec.run.npz", meta={"channel_conditioning": cond}))
    assert "\n" not in str(ei.value) and "rec.run.npz: meta.channel_conditioning" in str(ei.value)


def test_a_declared_delay_without_a_low_pass_is_read_whatever_its_order():
    """What ``import`` writes for a map column that declares only its delay (``lowpass_order
    = 0``: no filter, no poles) is read, not refused (it stopped calibrate until the
    seventeenth session); the acceleration's conditioner order then stays the table's."""
    from types import SimpleNamespace

    from sim.calibrate.conditioning import channel_conditioning, declared_state

    cond = {
        "table_displacement": {"delay_s": 0.002, "lowpass_hz": None, "lowpass_order": 0},
        "table_acceleration": {"delay_s": 0.001, "lowpass_hz": None, "lowpass_order": 0},
    }
    r = SimpleNamespace(name="rec.run.npz", meta={"channel_conditioning": cond}, dt=1 / 204.8)
    got = channel_conditioning(r)
    assert got["table_displacement"]["delay_s"] == 0.002 and got["table_displacement"]["lowpass_hz"] is None
    s = declared_state(r, 50.0, 4)
    assert s["accel_lowpass_hz"] is None and s["accel_delay_s"] == 0.001 and s["accel_lowpass_order"] == 4


def test_the_motion_is_read_at_the_force_instants_through_its_declared_chain():
    """The displacement's declared delay and low-pass (taken as its low-frequency delay)
    come off the displacement, and off a velocity the import made from it; a velocity of
    its own keeps its own channel's."""
    from types import SimpleNamespace

    from sim.calibrate.conditioning import low_frequency_delay_s, motion_on_the_force_clock

    dt = 1 / 1024
    t = np.arange(4096) * dt
    ramp = (t - 1.0)[:, None]
    cond = {"table_displacement": {"delay_s": 0.001, "lowpass_hz": 30.0, "lowpass_order": 4}}
    late = 0.001 + low_frequency_delay_s(30.0, 4)
    for derived, v_late in (({"table_velocity": "central difference"}, late), ({}, 0.0)):
        r = SimpleNamespace(name="r", dt=dt, meta={"channel_conditioning": cond, "derived_channels": derived})
        u, v = motion_on_the_force_clock(r, ramp, ramp)
        mid = slice(1000, 3000)
        assert np.allclose(u[mid], ramp[mid] + late, atol=1e-9), derived
        assert np.allclose(v[mid], ramp[mid] + v_late, atol=1e-9), derived


def test_a_velocity_made_from_the_displacement_is_compared_through_its_chain():
    """On the replay and closed-loop paths the model's velocity of an import's derived
    column is the model displacement's difference, so it goes through the displacement's
    declared chain; a velocity of its own keeps its own (none here). Before, the worked
    example's LVDT declared 2 samples late left the replay's velocity 24 % from the record
    (0.72 % on time), the pooled held-out error 10.9 % (3.9 %)."""
    from types import SimpleNamespace

    from sim.calibrate.conditioning import of_run

    cond = {"table_displacement": {"delay_s": 0.001, "lowpass_hz": 30.0, "lowpass_order": 4}}
    for derived, own in (({"table_velocity": "central difference"}, True), ({}, False)):
        r = SimpleNamespace(name="r", meta={"channel_conditioning": cond, "derived_channels": derived})
        chans = of_run(r)["channels"]
        assert chans.get("table_velocity") == (chans["table_displacement"] if own else None), derived


def test_conditioner_at_a_low_record_rate_is_the_recorders():
    """A 4-pole 50 Hz conditioner applied to a 204.8 Hz record (calibration's model of it)
    is the one a recorder applied at the simulation's 1024 Hz, then kept every fifth sample
    (`run --measure`): 0.05 % RMS apart. Filtered at the record's own rate it was 6 % apart,
    its band warped into a 51 Hz conditioner's (docs/lab-example-validation.md, step 8)."""
    import scipy.signal as sig

    from sim.calibrate.conditioning import Conditioner, analog_response
    from sim.identify.least_squares import analog_lowpass
    from sim.signals import sensing

    rng = np.random.default_rng(7)
    x = sig.lfilter(*sig.butter(4, 25.0, fs=FS), rng.standard_normal(20480))  # a test's band, 0-25 Hz
    truth = sensing.lowpass(x, 50.0, 4, FS, analog=True)[::5]
    k = slice(100, -100)

    def apart(y):
        return np.std((y - truth)[k]) / np.std(truth[k])

    assert apart(analog_response(x[::5], 50.0, 4, FS / 5)) < 1e-3
    assert apart(sensing.lowpass(x[::5], 50.0, 4, FS / 5, analog=True)) > 0.03  # the record's own rate
    assert apart(Conditioner(50.0, 4, FS / 5)(x[::5])) < 1e-3  # from rest: the start is in the lead-in
    np.testing.assert_array_equal(  # at 1 kHz or more: the record's own rate, as before
        Conditioner(100.0, 4, FS)(x), sig.lfilter(*analog_lowpass(100.0, FS, 4), x)
    )


def test_a_motion_off_by_more_than_a_recorders_scan_is_judged_without_a_margin():
    """The motion's own delay is measured by the kinematics, not fitted: beyond half a
    sample (a multiplexed recorder's scan) it is taken when the held-out error does not
    rise, and the backward pass keeps it; so is an acceleration's timing the displacement
    corroborates where it reads the acceleration that far off its chain. Under half a
    sample, and for every delay the balance alone fits, the search's margin holds (tests/calibrate/test_real_record_suite.py has
    the NEES-UCSD case that needs it)."""
    from types import SimpleNamespace

    from sim.calibrate.kinematic_timing import off_its_chain
    from sim.calibrate.mechsearch import _may_drop
    from sim.calibrate.timing import Candidate

    dt = 1 / FS
    motion = Candidate("sensor_delay", "channel:table_displacement", "delay_s", "motion_delay_s", -0.05, 0.05, 0.0)
    accel = Candidate("sensor_delay", "channel:table_acceleration", "delay_s", "accel_delay_s", -0.05, 0.05, 0.0)
    assert off_its_chain(motion, -2 * dt, None, dt)
    assert not off_its_chain(motion, 0.3 * dt, None, dt)
    assert not off_its_chain(accel, 2 * dt, None, dt)  # the balance's own delay, nothing read
    read = {"ok": True, "significant": True, "delay_before_s": -2 * dt}
    assert off_its_chain(accel, 2 * dt, read, dt)  # the displacement reads it 2 samples off
    assert not off_its_chain(accel, 2 * dt, {**read, "delay_before_s": 0.3 * dt}, dt)
    assert not off_its_chain(accel, 2 * dt, {**read, "ok": False}, dt)  # not corroborated
    assert not off_its_chain(accel, 2 * dt, {**read, "significant": False}, dt)
    mr = SimpleNamespace(name="r", dt=dt)
    entry = {
        "name": "sensor_delay",
        "where": motion.where,
        "timed_by": "acceleration",
        "parameters": {"delay_s": -2 * dt},
    }
    assert not _may_drop(entry, mr, {})
    entry["parameters"]["delay_s"] = 0.3 * dt
    assert _may_drop(entry, mr, {})
    # an acceleration delay the balance placed within half a sample of the displacement's reading
    declared = {"r": {"accel_delay_s": 0.0}}
    entry = {"name": "sensor_delay", "where": accel.where, "parameters": {"delay_s": 2 * dt}}
    assert _may_drop(entry, mr, declared)  # the balance's own: the backward pass judges it
    entry["displacement_reads"] = {"delay_s": 2.1 * dt, "sigma_s": 0.01 * dt}
    assert not _may_drop(entry, mr, declared)


def test_a_velocity_the_import_derived_has_no_skew_of_its_own_to_search():
    """A velocity made from the displacement by a central difference shares its clock: its
    own delay is not a candidate. A velocity of its own channel's is; so is the load cells'
    gain, on every record."""
    from types import SimpleNamespace

    from sim.calibrate.timing import candidates

    base = {
        "force_delay_s": 0.0,
        "accel_delay_s": 0.0,
        "accel_lowpass_hz": 100.0,
        "accel_lowpass_order": 4,
        "motion_delay_s": 0.0,
        "velocity_delay_s": 0.0,
        "force_gain": 1.0,
    }

    def places(derived: bool) -> set:
        mr = SimpleNamespace(dt=1 / FS, extra={"timing": base, "velocity_derived": derived})
        return {(c.name, c.where) for c in candidates([mr])}

    assert ("sensor_delay", "channel:table_velocity") not in places(True)
    assert ("sensor_delay", "channel:table_velocity") in places(False)
    assert all(("sensor_gain", "channel:actuator_force") in places(d) for d in (True, False))
