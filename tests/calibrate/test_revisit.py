"""The rules of the accepted effects' revisit (sim.calibrate.revisit) without a replay;
the whole search with it is tested in test_calibrate_paths.py
(test_a_wrong_effect_accepted_first_is_dropped, test_two_effects_at_once_hydraulic_and_mechanical)."""

from __future__ import annotations

import numpy as np

from sim.calibrate.revisit import drop_rule, free_index
from sim.calibrate.sensitivity import Candidate


def test_drop_rule_mirrors_the_forward_rule():
    # kept: with it the held-out error is >= 5 % of the error without it lower (as a new effect must be)
    assert drop_rule(0.050, 0.060, -100.0, -90.0, 0.05)[0] is False
    assert drop_rule(0.050, 0.060, -100.0, -120.0, 0.05)[0] is False  # even with the BIC lower without it
    # within the margin: dropped if the BIC falls without it, kept if it rises
    drop, why = drop_rule(0.0515, 0.0520, -100.0, -110.0, 0.05)
    assert drop and why.startswith("dropped")
    drop, why = drop_rule(0.0515, 0.0520, -100.0, -95.0, 0.05)
    assert not drop and "BIC" in why
    # at the edge: 0.95 x 0.06 = 0.057
    assert drop_rule(0.0569, 0.060, 0.0, -1.0, 0.05)[0] is False
    assert drop_rule(0.0571, 0.060, 0.0, -1.0, 0.05)[0] is True


def test_a_gridded_parameter_is_held_in_the_joint_refit():
    one = np.array([1.0])

    def cand(t, grid=None, n=1):
        return Candidate(
            t, "class:lateral", ("a", "b")[:n], np.ones(n), np.ones(n), -np.ones(n), 2 * np.ones(n), {}, grid=grid
        )

    items = [(cand("valve_flow_gain"), one), (cand("valve_delay", grid=1e-3), one), (cand("power_damping", n=2), one)]
    assert free_index(items) == [(0, 0), (2, 0), (2, 1)]
