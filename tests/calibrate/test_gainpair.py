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


def two_class_run(seed, gain_y, n=4000):
    """Two DOFs, one actuator class pushing each (x: class longitudinal, y: class lateral);
    the declared model is the platen's mass and dry friction; the lateral load cells read
    ``gain_y`` x their force, plus 1 % noise."""
    from sim.calibrate.residuals import MechRun

    rng = np.random.default_rng(seed)
    t = np.arange(n)[:, None] / FS
    f, A, ph = rng.uniform(0.3, 5.0, (2, 6)), rng.uniform(0.005, 0.02, (2, 6)), rng.uniform(0, 2 * np.pi, (2, 6))
    motion = []
    for k in range(2):
        w = 2 * np.pi * f[k]
        motion.append([(A[k] * x).sum(1) for x in (np.sin(w * t + ph[k]), w * np.cos(w * t + ph[k]))])
        motion[-1].append(-((A[k] * w**2) * np.sin(w * t + ph[k])).sum(1))
    u, v, a = (np.column_stack([motion[0][i], motion[1][i]]) for i in range(3))
    model = MASS * a + FRICTION * np.clip(v / 1e-3, -1.0, 1.0)
    act = model * np.array([1.0, gain_y]) + rng.normal(0.0, 0.01 * np.std(model), model.shape)
    run = MechRun(
        name=f"two{seed}", dt=1 / FS, dofs=["x", "y"], u=u, v=v, a=a, force=act, model=model, J=np.eye(2),
        actuators=["X1", "Y1"], classes={"longitudinal": [0], "lateral": [1]}, rows=np.ones(n, bool),
    )  # fmt: skip
    run.extra["actuator_force"] = act
    return run


def test_one_class_of_load_cells_reads_its_own_gain():
    from sim.calibrate.laws import LOAD_CELLS_GAIN_CLASS, class_gain
    from sim.calibrate.mechsearch import alone_in_direction, class_gain_entry

    runs = [two_class_run(s, 1.05) for s in (1, 2)]
    assert alone_in_direction(runs[0], ["class:longitudinal", "class:lateral"]) == [
        "class:longitudinal",
        "class:lateral",
    ]
    fit = fit_terms(runs, [Term(LOAD_CELLS_GAIN_CLASS, "class:lateral")])
    g = class_gain(fit.values[0]["read_excess"])
    assert abs(g - 1.05) < GAIN_TOLERANCE * 1.05, g
    other = fit_terms(runs, [Term(LOAD_CELLS_GAIN_CLASS, "class:longitudinal")])
    assert abs(class_gain(other.values[0]["read_excess"]) - 1.0) < GAIN_TOLERANCE
    entry = class_gain_entry("class:lateral", fit.values[0], {"read_excess": 0.001}, runs[0])
    assert (entry["name"], entry["where"], entry["parameters"]["gain"]) == (
        "sensor_gain",
        "channel:actuator_force[1]",
        g,
    )


def test_classes_that_push_alike_have_no_gain_of_their_own():
    """Two classes along one DOF (NEES-UCSD's east and west actuators): their load cells'
    gains trade against each other, so neither is a candidate."""
    from sim.calibrate.mechsearch import alone_in_direction

    run = gain_and_mass_run(1, 1.0, 0.0)
    run.J, run.actuators, run.classes = np.ones((2, 1)), ["E", "W"], {"east": [0], "west": [1]}
    assert alone_in_direction(run, ["class:east"]) == []


def test_a_class_gain_gives_way_to_the_member_gain_it_stands_for():
    """A class's load-cell gain that passed is refused where one of its actuators' gains
    explained more and predicts the held-out runs better (mechjudge._a_member_stands_for_it);
    a member that explains less, or predicts worse, and another class's actuator, do not
    count."""
    from types import SimpleNamespace

    from sim.calibrate.mechjudge import _a_member_stands_for_it

    mr = SimpleNamespace(classes={"vertical": [8, 9], "lateral": [4]}, actuators=[f"A{i}" for i in range(10)])

    def row(where, expl, e_ho):
        return {"name": "load_cells_gain", "where": where, "explained_fraction": expl, "holdout_error": e_ho}

    cls = row("class:vertical", 0.0155, 0.0581)
    assert _a_member_stands_for_it(mr, cls, [row("actuator:A8", 0.0505, 0.0571), cls])
    assert not cls.get("accepted", True) and "actuator:A8" in cls["reason"], cls
    for other in (row("actuator:A8", 0.0505, 0.0590), row("actuator:A9", 0.01, 0.0571), row("actuator:A4", 0.05, 0.05)):
        fresh = row("class:vertical", 0.0155, 0.0581)
        assert not _a_member_stands_for_it(mr, fresh, [other, fresh]), other
        assert "reason" not in fresh
    # another law at the class is not this rule's
    mass = {**row("class:vertical", 0.0155, 0.0581), "name": "added_mass"}
    assert not _a_member_stands_for_it(mr, mass, [row("actuator:A8", 0.0505, 0.0571)])
