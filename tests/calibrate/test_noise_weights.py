"""The replay and closed-loop paths' pooled error weighs each column by its noise
(sim.calibrate.paths.noise_weights): a column held at its noise floor whatever the model
(a light table's forces under a large load cell) does not hide what the others show,
and a record without noise is pooled as before (every column alike)."""

from __future__ import annotations

import numpy as np
import pytest

from sim.calibrate import paths as P

FS = 1024.0
N = 8192


def _run(force_noise: float, seed: int = 3):
    """A run of two compared columns: a 3 kN RMS force under ``force_noise`` of white
    load-cell noise, and a 2 m/s^2 RMS acceleration without noise; its weights from the
    record's own floors, as :func:`sim.calibrate.paths.path_runs` takes them."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) / FS
    f = 3.0e3 * np.sqrt(2.0) * np.sin(2 * np.pi * 3.0 * t)
    a = 2.0 * np.sqrt(2.0) * np.sin(2 * np.pi * 5.0 * t)
    rec = {"actuator_force": (f + force_noise * rng.standard_normal(N))[:, None], "table_acceleration": a[:, None]}
    cols = {"actuator_force": [0], "table_acceleration": [0]}
    floors = {c: P.conditioning.noise_floor(x, FS) / np.std(x, axis=0) for c, x in rec.items()}
    pr = P.PathRun(
        name="r",
        path="replay",
        t=t,
        drive=np.zeros((N, 1)),
        dofs=["x"],
        actuators=["A"],
        recorded=rec,
        columns=cols,
        scale={c: np.std(x, axis=0) for c, x in rec.items()},
        weight=P.noise_weights(floors),
    )
    return pr, {"actuator_force": f[:, None], "table_acceleration": a[:, None]}


def _model(clean: dict, accel_error: float) -> dict:
    """The model's channels: the force exact, the acceleration ``accel_error`` of its RMS off (a gain)."""
    return {**clean, "table_acceleration": clean["table_acceleration"] * (1.0 + accel_error)}


def test_a_column_weighs_by_its_noise_floor():
    """1 / (floor^2 + 0.05^2) over 1 / 0.05^2: 1 for a column without noise, 0.0244 for a
    floor of 1 / sqrt(10) (3 kN under 1 kN)."""
    w = P.noise_weights({"a": np.array([0.0, 1.0 / np.sqrt(10.0), 0.05])})["a"]
    assert w == pytest.approx([1.0, 0.0025 / (0.1 + 0.0025), 0.5])
    pr, _clean = _run(1.0e3)
    got = P.column_weights(pr)
    assert got["actuator_force[A]"] == pytest.approx(0.0025 / (0.1 + 0.0025), rel=0.1)
    assert got["table_acceleration[x]"] > 0.999


def test_a_column_at_its_noise_does_not_hide_a_fall_elsewhere():
    """The acceleration 10 % off, then 5 %: counted alike with a force held at its 31.6 %
    floor, the pooled error falls 3.5 % (sqrt((0.1 + 0.01) / 2) -> sqrt((0.1 + 0.0025) / 2)),
    under the 5 % margin; weighted by the noise (the force 0.024), it falls 37 %."""
    pr, clean = _run(1.0e3)
    alike = P.PathRun(**{**pr.__dict__, "weight": {}})
    a10, a5 = (P.nrmse([alike], [_model(clean, x)]) for x in (0.10, 0.05))
    assert a10 == pytest.approx(np.sqrt((0.1 + 0.01) / 2), rel=0.02)
    assert 1 - a5 / a10 < 0.05, (a10, a5)
    e10, e5 = (P.nrmse([pr], [_model(clean, x)]) for x in (0.10, 0.05))
    assert 1 - e5 / e10 > 0.3, (e10, e5)


def test_a_record_without_noise_pools_every_column_alike():
    """No noise: every weight 1, the pooled error the mean of the columns' NRMSE squared."""
    pr, clean = _run(0.0)
    assert all(w > 0.999 for w in P.column_weights(pr).values())
    m = _model(clean, 0.10)
    per = P.column_errors(pr, m)
    assert P.nrmse([pr], [m]) == pytest.approx(np.sqrt(np.mean([v**2 for v in per.values()])), rel=1e-3)
