"""The load cells' gain as a column of the declared model's force (sim/calibrate/gainpair.py):
fitted beside a law nobody declared, each is read in its own units, where either alone
takes in the other's force."""

from __future__ import annotations

import numpy as np
import pytest

from sim.calibrate.gainpair import LOAD_CELLS_GAIN, pair_fit
from sim.calibrate.laws import LAWS
from sim.calibrate.pathjudge import GAIN_TOLERANCE
from sim.calibrate.residuals import nrmse_runs
from sim.calibrate.trace import Term, fit_terms, predict
from tests.calibrate.test_acceptance import _mech_run

FS = 200.0
MASS = 840.0  #: kg, declared
FRICTION = 2000.0  #: N, declared dry friction (a light table's: a third of its inertial force here)


def gain_and_mass_run(seed, gain, added_kg, n=4000):
    """Six sines of 0.3-5 Hz; the declared model is the platen's mass and its dry
    friction; the truth adds ``added_kg`` and the load cells read ``gain`` x the force,
    plus 1 % noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None] / FS
    f, A, ph = rng.uniform(0.3, 5.0, 6), rng.uniform(0.005, 0.02, 6), rng.uniform(0, 2 * np.pi, 6)
    w = 2 * np.pi * f
    u, v, a = ((A * x).sum(1) for x in (np.sin(w * t + ph), w * np.cos(w * t + ph), -(w**2) * np.sin(w * t + ph)))
    model = MASS * a + FRICTION * np.clip(v / 1e-3, -1.0, 1.0)
    force = gain * (model + added_kg * a)
    force = force + rng.normal(0.0, 0.01 * np.std(force), force.shape)
    return _mech_run(f"gm{seed}", u, v, a, force, model)


@pytest.mark.parametrize("gain", [1.05, 0.9])
def test_the_gain_beside_an_added_mass_reads_both(gain):
    runs = [gain_and_mass_run(s, gain, 300.0) for s in (1, 2)]
    held = [gain_and_mass_run(3, gain, 300.0)]
    cur = fit_terms(runs, [])
    pair = pair_fit(runs, cur, Term(LAWS["added_mass"], "dof:x"))
    assert pair.terms[0].law is LOAD_CELLS_GAIN
    b = pair.values[0]["gain_change"]
    # within a transducer's tolerance (the gain is told from the mass by the friction alone:
    # its 95 % interval, +/-0.19 %, is narrow for six sines; seeds 1-6 scatter by 0.2 %)
    assert abs(1.0 + b - gain) < GAIN_TOLERANCE * gain, b
    # the law's coefficient is the mass times the gain: read in its own units, the truth
    m = pair.values[1]["mass_kg"] / (1.0 + b)
    assert m == pytest.approx(300.0, rel=0.02), m
    # the mass alone takes the gain's share of the inertia in (g m + (g - 1) M) and
    # predicts the held-out run worse than the pair by more than the search's margin
    mass_alone = fit_terms(runs, [Term(LAWS["added_mass"], "dof:x")])
    m_alone = mass_alone.values[0]["mass_kg"]
    assert m_alone == pytest.approx(gain * 300.0 + (gain - 1.0) * MASS, rel=0.02), m_alone
    e_pair = nrmse_runs(held, predict(held, pair))
    assert e_pair < 0.95 * nrmse_runs(held, predict(held, mass_alone)), e_pair
    assert e_pair < 0.0105, e_pair  # the 1 % noise


def test_clean_records_read_no_gain_beside_a_law():
    runs = [gain_and_mass_run(s, 1.0, 300.0) for s in (1, 2)]
    pair = pair_fit(runs, fit_terms(runs, []), Term(LAWS["added_mass"], "dof:x"))
    b = pair.values[0]["gain_change"]
    assert abs(b) < GAIN_TOLERANCE, b  # within a transducer's tolerance: refused
