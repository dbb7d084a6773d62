"""A mode as MuJoCo's step has it.

MuJoCo's Euler, implicit and implicitfast integrators take joint damping implicitly and
springs explicitly (semi-implicit Euler: ``(M + h D) v' = M v + h f(q, v)``, then
``q' = q + h v'``). A mass ``m`` on ``k = m w^2`` and ``c = 2 z m w`` so stepped is a mode
at about ``(1 - z w h / 2) f``: -0.045 % for a 6 Hz, 5 % mode at h = 1/2048 s, -1.6 % (and
its damping -1.9 %) for a 60 Hz, 20 % one (tests/mjcf/test_mode_spring.py: one slide's
free vibration). The stepped oscillator's two poles have the product ``1 / beta``,
``beta = 1 + h c / m``, and the sum ``1 + (1 - h^2 k / m) / beta``.

:func:`matched_spring` sets ``k`` and ``c`` so that those poles are ``exp(s h)`` of the
continuous mode's ``s`` (the builder's specimen modes); :func:`stepped_mode` reads the
mode a ``k``, ``c`` make once stepped (what the calibration's mechanical path models of
the parts the model carries on their own joints). Under RK4 neither changes anything.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

#: the integrators whose step takes joint damping implicitly and springs explicitly
DAMPING_IMPLICIT = ("mjINT_EULER", "mjINT_IMPLICIT", "mjINT_IMPLICITFAST")


def damping_implicit(integrator) -> bool:
    """Whether ``integrator`` (an ``mjtIntegrator`` value) steps as this module says."""
    return int(integrator) in {int(getattr(mujoco.mjtIntegrator, n)) for n in DAMPING_IMPLICIT}


def matched_spring(mass: float, frequency_hz: float, damping_ratio: float, h: float) -> tuple[float, float]:
    """(stiffness N/m, damping N s/m) that carry ``mass`` on a mode of ``frequency_hz`` and
    ``damping_ratio`` once stepped at ``h`` (s)."""
    w = 2.0 * math.pi * frequency_hz
    s = np.roots([1.0, 2.0 * damping_ratio * w, w * w])
    beta = math.exp(2.0 * damping_ratio * w * h)
    pole_sum = float(np.exp(s * h).sum().real)
    return mass * beta / h**2 * (1.0 + 1.0 / beta - pole_sum), mass * (beta - 1.0) / h


def mode_spring(spec, mass: float, frequency_hz: float, damping_ratio: float) -> tuple[float, float]:
    """(stiffness N/m, damping N s/m) of a slide carrying ``mass`` on a mode of
    ``frequency_hz`` and ``damping_ratio`` as ``spec``'s integrator steps it
    (:func:`matched_spring`; the continuous values under RK4). On a CGS block's clamp the
    plain values were the calibration's mechanical path's -0.065 %, which the replay,
    stepping the same model, could not see."""
    if damping_implicit(spec.option.integrator):
        return matched_spring(mass, frequency_hz, damping_ratio, float(spec.option.timestep))
    w = 2.0 * math.pi * frequency_hz
    return mass * w * w, 2.0 * damping_ratio * mass * w


def stepped_mode(frequency_hz: float, damping_ratio: float, h: float) -> tuple[float, float]:
    """(frequency Hz, damping ratio) of the mode that ``k = m w^2``, ``c = 2 z m w`` of a
    continuous ``frequency_hz``, ``damping_ratio`` make once stepped at ``h`` (s)."""
    w = 2.0 * math.pi * frequency_hz
    beta = 1.0 + 2.0 * damping_ratio * w * h
    lam = np.roots([1.0, -(1.0 + (1.0 - (w * h) ** 2) / beta), 1.0 / beta]).astype(complex)
    s = np.log(lam) / h
    wn = math.sqrt(abs(s[0] * s[1]))  # |s1 s2| = w^2, for two real poles too
    return wn / (2.0 * math.pi), float(-(s[0] + s[1]).real / (2.0 * wn))


__all__ = ["DAMPING_IMPLICIT", "damping_implicit", "matched_spring", "mode_spring", "stepped_mode"]
