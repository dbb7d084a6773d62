"""An analog displacement controller (PIDF with differential-pressure feedback), acting at
every physics step: the controller of Trombetti & Conte's uni-axial table (seed 001,
Eq. 2), usable by any table whose description says ``[controller] type = "analog"``."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Gains:
    """Front-panel control gains (Eq. 2): P (V/V), I (Hz), D (s), FF (s), dP (V/V)."""

    p: float = 1.0
    i_hz: float = 0.0
    d_s: float = 0.0
    ff_s: float = 0.0
    dp: float = 0.0


@dataclass(frozen=True)
class Conditioning:
    """Transducer conditioning constants (Sec. 5.1), SI."""

    k_x: float  # V/m
    k_d: float  # V/m
    k_dp: float  # V/Pa


class RiceController:
    """The paper's analog controller (Eq. 2) in the time domain, for the simulation loop.

    x_c = (P e + I int e dt) K_x + (D de/dt) K_D + (FF dx_d/dt) K_D + dP K_dp dp,
    e = x_d - x_t, with x_t the actuator LVDT (stroke) and dp = p_a - p_b the actuator's
    differential pressure. de/dt uses the commanded and measured velocities (the analog
    differentiator of a noise-free signal). The valve opening (fraction of full opening)
    is k_t x_c / q_full, where q_full is the valve's no-load flow at full opening, so
    that the linearised valve flow is k_t x_c (Eq. 8; the delay is the valve's).
    """

    def __init__(self, gains: Gains, cond: Conditioning, kt_m3_per_v_s: float, q_full_m3_s: float, dt: float):
        self.g, self.c, self.dt = gains, cond, dt
        self.scale = kt_m3_per_v_s / q_full_m3_s
        self.reset()

    def reset(self):
        self.integral = 0.0

    def volts(self, xd, vd, xt, vt, dp) -> float:
        g, c = self.g, self.c
        e = xd - xt
        self.integral += e * self.dt
        return (
            (g.p * e + g.i_hz * self.integral) * c.k_x + (g.d_s * (vd - vt) + g.ff_s * vd) * c.k_d + g.dp * c.k_dp * dp
        )

    def opening(self, xd, vd, xt, vt, dp) -> float:
        u = self.scale * self.volts(xd, vd, xt, vt, dp)
        return 1.0 if u > 1.0 else (-1.0 if u < -1.0 else u)
