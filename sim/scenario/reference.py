"""The 6-DOF reference a table is asked to follow: pose, velocity and acceleration per
DOF at the controller rate, stacked from per-DOF motions (``sim.scenario.motions``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mjcf.description import DOFS6
from sim.errors import ScenarioError


@dataclass
class Reference:
    """A 6-DOF reference at the controller rate: pose (N, 6), velocity, acceleration."""

    t: np.ndarray
    d: np.ndarray
    v: np.ndarray
    a: np.ndarray

    @property
    def rate_hz(self) -> float:
        return 1.0 / float(self.t[1] - self.t[0])


def reference_from_motions(motions: dict, rate_hz: float, duration_s: float) -> Reference:
    """Stack per-DOF motions (dict dof -> Motion sampled at rate_hz) into a 6-DOF Reference."""
    n = int(round(duration_s * rate_hz)) + 1
    t = np.arange(n) / rate_hz
    D = np.zeros((n, 6))
    V = np.zeros((n, 6))
    A = np.zeros((n, 6))
    for dof, mo in motions.items():
        i = DOFS6.index(dof)
        if abs(mo.sample_rate_hz - rate_hz) > 1e-6 * rate_hz:
            raise ScenarioError(f"motion for {dof} is sampled at {mo.sample_rate_hz:g} Hz, expected {rate_hz:g} Hz")
        m = min(n, len(mo.d))
        D[:m, i] = mo.d[:m]
        V[:m, i] = mo.v[:m]
        A[:m, i] = mo.a[:m]
    return Reference(t=t, d=D, v=V, a=A)
