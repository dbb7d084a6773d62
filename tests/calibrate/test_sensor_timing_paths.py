"""Sensor timing of either sign on the replay path (sim/calibrate/sensitivity.py: the
``sensor_delay`` candidate from MAX_ADVANCE_SAMPLES early to MAX_DELAY_S late;
sim/calibrate/sensortiming.py: a delay or a conditioner judged first).

The runs: the lab table (scenarios/tables/lab.toml, uni-axial, 1024 Hz), 1-30 Hz random
motion, 3 s after a 5 s quiet lead-in, three seeds (two fitted, one held out), measured
through scenarios/sensors/real_record_1024hz.toml: anti-alias filter, a declared 100 Hz
accelerometer conditioner two samples late, per-record offsets, drift, noise and
quantisation on every channel. Its load-cell numbers are a large table's (1 kN noise on
~0.2 m^2 pistons); here they are scaled to the lab's 0.005 m^2 piston (x 1/40: 25 N
noise, i.e. 5 kPa over the piston as the pressure transducers; 50 N offset, 2.5 N/sqrt(s)
drift). The calibrator sees only what a recorder writes (its settings and the declared
conditioning).
"""

from __future__ import annotations

import copy
import types

import numpy as np
import pytest

from sim.calibrate import search as S
from tests.calibrate.records import noise_run

FS = 1024.0
SENSORS = ["sensor_gain", "sensor_offset", "sensor_delay", "sensor_lowpass"]
#: the lab's load cell (see the module docstring)
LAB_FORCE = {"noise_rms": 25.0, "offset_rms": 50.0, "drift_per_sqrt_s": 2.5}


def _sensors(force_skew_s: float = 0.0, declare_motion_skew: bool = True) -> dict:
    """The real-record sensor file with the lab's load cell; the force ``force_skew_s``
    early (undeclared); the displacement's and velocity's 0.3-sample skew declared (a
    lab that knows its multiplexer) or not."""
    from sim.runs.measure import ROOT, load_sensors

    s = copy.deepcopy(load_sensors(ROOT / "scenarios" / "sensors" / "real_record_1024hz.toml"))
    s["channel"]["actuator_force"].update(LAB_FORCE)
    if force_skew_s:
        s["channel"]["actuator_force"]["skew_s"] = force_skew_s
    for ch in ("table_displacement", "table_velocity"):
        s["channel"][ch]["declared"] = declare_motion_skew
    return s


def lab_runs(out, sensors, seeds=(1, 2, 3), seconds=3.0) -> list[str]:
    """Closed-loop runs of the lab table under 1-30 Hz random motion (1.5 m/s^2 RMS),
    measured through ``sensors`` (seeded)."""
    import mjcf
    from sim.effects import build_model
    from sim.runs.measure import measure_run
    from sim.runs.runfile import write_run

    tm = build_model(mjcf.load_table("lab"))
    paths = []
    for s in seeds:
        _res, run = noise_run(tm, (s, 0), seconds, fs=FS)
        run = measure_run(run, sensors, seed=s)
        assert "measurement" not in run.meta and "force_lag_s" not in run.meta  # a recorder's meta only
        paths.append(str(write_run(out / f"lab_{s}.run.npz", run)))
    return paths


def _delays(res) -> dict:
    return {e["where"]: e for e in res.effects_added if e["name"] == "sensor_delay"}


def test_force_leading_by_two_samples_found(tmp_path):
    """The load cell two samples early (1.953 ms), and the displacement and velocity 0.3
    sample early (0.293 ms), neither declared: both advances found (negative delays), the
    truth inside each 95 % interval, nothing else added, the held-out error falls."""
    paths = lab_runs(tmp_path, _sensors(force_skew_s=2.0 / FS, declare_motion_skew=False))
    res = S.calibrate(paths, path="replay", effects=SENSORS, workers=2)
    assert res.residual_path == "replay"
    found = _delays(res)
    assert set(found) == {"channel:actuator_force", "channel:table_velocity"}, res.effects_added
    assert len(res.effects_added) == 2, res.effects_added
    for where, truth in (("channel:actuator_force", -2.0 / FS), ("channel:table_velocity", -0.3 / FS)):
        d, u = found[where]["parameters"]["delay_s"], found[where]["uncertainty"]["delay_s"]
        assert abs(d - truth) <= u, (where, d, u, truth)
        assert u < 0.05 * abs(truth), (where, u)  # an interval that tells the lead (measured: 0.3 % and 1.3 %)
    assert res.error_after < 0.25 * res.error_before, (res.error_before, res.error_after)


def test_clean_runs_add_no_delay(tmp_path):
    """The same artifacts, every skew declared: nothing added."""
    paths = lab_runs(tmp_path, _sensors())
    res = S.calibrate(paths, path="replay", effects=SENSORS, workers=2)
    assert res.residual_path == "replay"
    assert res.effects_added == [], res.effects_added
    assert res.error_after == res.error_before


def test_delay_candidate_takes_either_sign():
    """The candidate's range on these paths: MAX_ADVANCE_SAMPLES samples early to MAX_DELAY_S late."""
    from sim.calibrate import sensitivity as SE
    from sim.calibrate import sensorcands as SC

    pr = types.SimpleNamespace(
        path="replay",
        dt=1.0 / FS,
        columns={"actuator_force": [0]},
        scale={"actuator_force": [1.0]},
        recorded={"actuator_force": np.zeros((4, 1))},
    )
    (c,) = [
        c
        for c in SE.candidates(_lab(), None, [pr], [], {}, effects=["sensor_delay"])
        if c.where == "channel:actuator_force"
    ]
    assert c.lower[0] == pytest.approx(-SC.MAX_ADVANCE_SAMPLES / FS)
    assert c.upper[0] == SC.MAX_DELAY_S
    assert c.neutral[0] == 0.0


def _lab():
    import mjcf

    return mjcf.load_table("lab")


@pytest.mark.parametrize(
    ("where", "e_delay", "e_lowpass", "first"),
    [
        ("channel:actuator_force", 0.100, 0.102, "sensor_delay"),  # a tie: a load cell's lag is timing
        ("channel:pressure_a[0]", 0.100, 0.102, "sensor_delay"),
        ("channel:table_acceleration[1]", 0.100, 0.102, "sensor_lowpass"),  # a tie: a conditioner
        ("channel:specimen_acceleration", 0.102, 0.100, "sensor_lowpass"),
        ("channel:table_acceleration", 0.050, 0.100, "sensor_delay"),  # no tie: the lower held-out error
        ("channel:actuator_force", 0.100, 0.050, "sensor_lowpass"),
    ],
)
def test_delay_or_conditioner_first(where, e_delay, e_lowpass, first):
    from sim.calibrate.sensortiming import preferred

    assert preferred(where, e_delay, e_lowpass, margin=0.05) == first


def test_prefer_timing_swaps_only_the_pair(monkeypatch):
    from sim.calibrate import sensortiming as T

    def rf(type_, where):
        return types.SimpleNamespace(ok=True, cand=types.SimpleNamespace(sensor=True, type=type_, where=where))

    a = rf("sensor_lowpass", "channel:actuator_force")
    b = rf("valve_delay", "class:main")
    b.cand.sensor = False
    c = rf("sensor_delay", "channel:actuator_force")
    errors = {id(a): 0.101, id(c): 0.100}
    monkeypatch.setattr(T, "heldout_on_columns", lambda r, pho, mho: errors[id(r)])
    assert T.prefer_timing([a, b, c], None, None, 0.05) == [c, b, a]
    errors[id(a)] = 0.01  # the low-pass explains clearly more: it stays first
    assert T.prefer_timing([a, b, c], None, None, 0.05) == [a, b, c]
