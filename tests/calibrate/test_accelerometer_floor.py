"""The accelerometer floor of the mechanical path's report (sim.calibrate.mechsearch.
accelerometer_floor): the error a perfect model would still leave, the recorded
acceleration's white noise times the moving mass over the recorded force, read off the
record's own spectrum. Closed form: a 2 Hz motion with white noise of known RMS."""

from types import SimpleNamespace

import numpy as np
import pytest

from sim.calibrate.mechnoise import accelerometer_floor

FS = 1024.0
MASS = 5.0e4  # kg
NOISE = 0.03  # m/s^2 RMS, white


def _run(rows=None):
    n = int(20 * FS)
    t = np.arange(n) / FS
    a = 2.0 * np.sin(2 * np.pi * 2.0 * t)
    rng = np.random.default_rng(5)
    force = MASS * a  # the balance a perfect model closes
    inertial = MASS * (a + NOISE * rng.standard_normal(n))
    rows = np.ones(n, bool) if rows is None else rows
    return SimpleNamespace(
        dofs=["x"],
        dt=1.0 / FS,
        rows=rows,
        force=force[:, None],
        extra={"inertial": inertial[:, None]},
        demean=lambda x: x - x[rows].mean(axis=0),
    )


def test_the_floor_is_the_noise_times_the_mass_over_the_force():
    """NOISE x MASS / RMS(force) = 0.03 / (2 / sqrt 2) = 2.12 %; measured within 3 %."""
    want = NOISE / (2.0 / np.sqrt(2.0))
    assert accelerometer_floor(_run())[0] == pytest.approx(want, rel=0.03)


def test_rows_cut_out_of_the_span_do_not_raise_it():
    """Rows left out inside the span (the still rows of the balance) would put steps into
    the spectrum's top band if the rows were joined (here 20 samples at every zero of the
    acceleration, where it is steepest: the joined rows read 13 % high): the floor
    reads the whole span, and is the closed form over the kept rows' force."""
    rows = np.ones(int(20 * FS), bool)
    rows[:1000] = False  # a lead-in
    for k in range(4, 80):
        i = int(k * 0.25 * FS)
        rows[i - 10 : i + 10] = False
    r = _run(rows)
    want = NOISE * MASS / np.sqrt(np.mean(r.demean(r.force)[rows] ** 2))
    assert accelerometer_floor(r)[0] == pytest.approx(want, rel=0.03)


def test_no_inertial_term_no_floor():
    r = _run()
    r.extra = {}
    assert np.isnan(accelerometer_floor(r)[0])


def test_a_replay_column_floor_is_its_own_noise_over_its_rms():
    """The replay and closed-loop paths' floor (sim.calibrate.paths.column_floors): a 3 kN
    RMS force under 1 kN of white load-cell noise leaves 1 / sqrt(9 + 1) = 31.6 % whatever
    the model; measured within 3 %."""
    from sim.calibrate.paths import column_floors

    n = int(20 * FS)
    t = np.arange(n) / FS
    rng = np.random.default_rng(7)
    force = 3.0e3 * np.sqrt(2.0) * np.sin(2 * np.pi * 3.0 * t) + 1.0e3 * rng.standard_normal(n)
    pr = SimpleNamespace(
        columns={"actuator_force": [0]},
        recorded={"actuator_force": force[:, None]},
        rows=slice(0, None),
        dt=1.0 / FS,
        scale={"actuator_force": np.array([np.std(force)])},
        actuators=["A"],
        dofs=["x"],
    )
    assert column_floors(pr)["actuator_force[A]"] == pytest.approx(1.0 / np.sqrt(10.0), rel=0.03)
