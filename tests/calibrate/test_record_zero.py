"""What real records carry and the replay and closed-loop paths must not take for the
table: each record's own zero (sim.calibrate.paths.tared, sim.calibrate.offsets), an
accelerometer's gain read against the velocity (sim.calibrate.anchor.kinematic_gain),
and a description's number that is wrong on every actuator (``where = "actuators"``)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

FS = 256.0


def _run(zero: float, seed: int, n: int = 2048):
    """A one-column record (force) and the model's channel: the same signal plus the
    sensor's ``zero`` and a little noise."""
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(size=n))
    x -= x.mean()
    rec = x + zero + 0.01 * rng.normal(size=n)
    pr = SimpleNamespace(
        columns={"actuator_force": [0]},
        recorded={"actuator_force": rec[:, None]},
        rows=slice(0, None),
        scale={"actuator_force": np.array([np.std(rec)])},
        weights=lambda ch: np.ones(1),  # one column: its weight cancels
        dt=1.0 / FS,
    )
    return pr, {"actuator_force": x[:, None]}


def _judge(zeros_fit, zeros_ho):
    from sim.calibrate.offsets import judged

    fit = [_run(z, k) for k, z in enumerate(zeros_fit)]
    ho = [_run(z, 10 + k) for k, z in enumerate(zeros_ho)]
    return judged([p for p, _ in fit], [m for _, m in fit], [p for p, _ in ho], [m for _, m in ho], 0.05)


def test_the_residual_is_taken_about_each_records_zero():
    from sim.calibrate import paths as P

    pr, model = _run(3.0, 1)
    shifted = {"actuator_force": model["actuator_force"] - 7.0}
    assert P.nrmse([pr], [model]) == pytest.approx(P.nrmse([pr], [shifted]), rel=1e-12)
    assert P.nrmse([pr], [model]) < 0.01


def test_a_zero_every_record_shares_is_a_sensor_offset():
    found, rows = _judge([3.0, 3.0, 3.0], [3.0, 3.0])
    (e,) = found
    assert (e["name"], e["where"]) == ("sensor_offset", "channel:actuator_force")
    v, u = e["parameters"]["offset"], e["uncertainty"]["offset"]
    assert abs(v - 3.0) <= u < 0.01 and rows[0]["accepted"]


def test_zeros_that_wander_from_record_to_record_are_no_offset():
    found, rows = _judge([2.0, -1.5, 0.5], [-2.5, 1.0])
    assert found == []
    assert all(not r["accepted"] for r in rows)


def test_one_fit_run_cannot_tell_a_shared_zero_from_its_own():
    found, _rows = _judge([3.0], [3.0, 3.0])
    assert found == []


@pytest.mark.parametrize("gain", [1.0, 1.04])
def test_an_accelerometers_gain_is_read_against_the_velocity(gain):
    """A velocity of band-limited noise (2-pole band-pass, 0.5-15 Hz); the acceleration its
    derivative (by the FFT) times ``gain`` plus noise: the gain read within its interval
    (measured: 0.9985 +/- 0.0020 and 1.0385 +/- 0.0021)."""
    import scipy.signal as sig

    from sim.calibrate.anchor import kinematic_gain

    rng = np.random.default_rng(3)
    n = 8192
    v = sig.lfilter(*sig.butter(2, [0.5 / (FS / 2), 15.0 / (FS / 2)], "bandpass"), rng.normal(size=n))
    f = np.fft.rfftfreq(n, 1.0 / FS)
    a = gain * np.fft.irfft(np.fft.rfft(v) * 2j * np.pi * f, n) + 0.002 * np.std(v) * rng.normal(size=n)
    pr = SimpleNamespace(
        recorded={"table_velocity": v[:, None], "table_acceleration": a[:, None]}, rows=slice(0, None), dt=1.0 / FS
    )
    g, s = kinematic_gain([pr], [0])
    assert abs(g - gain) <= 1.96 * s < 0.005, (g, s)


@pytest.mark.parametrize("gain", [1.0, 1.04])
def test_an_accelerometers_gain_is_read_against_the_displacement_without_leakage(gain):
    """A table's motion as a test makes it: a white acceleration of 0.3-20 Hz (2 m/s^2,
    12 s at 1024 Hz), its velocity and displacement, each sensor with its own noise. The
    displacement holds most of its power below 1 Hz, and a Hann window leaks it into the
    bins above: read as the velocity against the acceleration (P_va / P_vv) the gain came
    out 0.993-0.995 for 1 (bins' median, three seeds). Read against the displacement with
    the velocity's central difference, whose spectrum has the acceleration's slope, it is
    0.9998-1.0001 (measured, seeds 1-3)."""
    from sim.calibrate.anchor import kinematic_gain

    n, fs = int(12 * 1024), 1024.0
    rng = np.random.default_rng(1)
    f = np.fft.rfftfreq(n, 1.0 / fs)
    A = (rng.normal(size=f.size) + 1j * rng.normal(size=f.size)) * ((f > 0.3) & (f < 20.0))
    A *= 2.0 / np.fft.irfft(A, n).std()
    s = np.where(f > 0, 2j * np.pi * f, 1.0)
    a, v, u = (np.fft.irfft(A / s**k, n) for k in (0, 1, 2))
    rec = {
        "table_displacement": (u + 20e-6 * rng.normal(size=n))[:, None],
        "table_velocity": (v + 2.5e-4 * rng.normal(size=n))[:, None],
        "table_acceleration": (gain * a + 0.03 * rng.normal(size=n))[:, None],
    }
    g, sd = kinematic_gain([SimpleNamespace(recorded=rec, rows=slice(0, None), dt=1.0 / fs)], [0])
    assert abs(g - gain) <= 1.96 * sd < 0.015, (g, sd)
    assert abs(g - gain) < 1e-3, g


def test_every_actuator_is_a_place_on_a_table_of_several_classes():
    import mjcf
    from hydraulics.params import HydraulicParams
    from sim.calibrate.sensitivity import _table_of
    from sim.effects import create
    from sim.effects.hydraulic import actuator_indices

    cgs = mjcf.load_table("cgs")
    e = create({"type": "bulk_modulus", "where": "actuators", "bulk_modulus_pa": 0.6e9})
    hp = HydraulicParams.from_table(cgs.raw)
    assert list(actuator_indices(e, hp)) == list(range(12))
    assert e.edit_hydraulics(hp).per_actuator("chamber_bulk_modulus_pa").tolist() == [0.6e9] * 12
    assert _table_of(cgs, None, [], None).hyd_places[0] == "actuators"
    assert (
        "actuators" not in _table_of(mjcf.load_table("lab"), None, [], None).hyd_places
    )  # one class: class:main is all
