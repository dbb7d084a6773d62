"""The second-order valve's transition matrix is computed once per (frequency, damping,
step) and shared: the same numbers as scipy's ``expm`` of that system, bit for bit."""

import math

import numpy as np
from scipy.linalg import expm

from hydraulics.system import _valve_transition


def test_cached_transition_equals_expm_and_is_shared():
    fn, z, dt = 41.5, 0.75, 1.0 / 2048
    wn = 2.0 * math.pi * fn
    M = np.array([[0.0, 1.0, 0.0], [-wn * wn, -2.0 * z * wn, wn * wn], [0.0, 0.0, 0.0]])
    E = _valve_transition(fn, z, dt)
    assert np.array_equal(E, expm(M * dt))
    assert _valve_transition(fn, z, dt) is E  # computed once
    assert not E.flags.writeable  # shared: nobody may change it
    assert not np.array_equal(_valve_transition(1.1 * fn, z, dt), E)
    # the step response's first step: the spool moves towards the command, less than all the way
    assert 0 < E[0, 2] < 1
