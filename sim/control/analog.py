"""An analog displacement controller (PIDF with differential-pressure feedback), acting at
every physics step: the controller of Trombetti and Conte's uni-axial table ([Trombetti 2002],
Eq. 2), usable by any table whose description says ``[controller] type = "analog"``."""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

from sim.errors import ScenarioError

PHYSICS_RATE_HZ = 8000.0  #: [Trombetti 2002]: the analog controller evaluated at every 1/8000 s physics step
RECORDER_RATE_HZ = 4000.0  #: [Trombetti 2002]: the DAQ rate


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


def apply_parameter_set(raw: dict, parameter_set: str, delay: bool, src: str):
    """The description ``raw`` with one of its ``[controller.parameter_sets]`` applied:
    beta -> fluid.bulk_modulus_pa, k_le -> cross leakage k_le * A, tau -> valve delay (0
    with ``delay=False``). Returns the description and k_t (the controller's volt-to-flow
    scale, m^3/(V s))."""
    from mjcf.description import parse_table

    raw = copy.deepcopy(raw)
    ps = raw["controller"]["parameter_sets"][parameter_set]
    raw["fluid"]["bulk_modulus_pa"] = float(ps["beta_pa"])
    cls = raw["actuator_class"]["main"]
    cls["leakage_cross_m3_s_pa"] = float(ps["kle_m3_per_n_s"]) * float(cls["area_a_m2"])
    raw["servovalve"]["delay_s"] = float(ps["tau_s"]) if delay else 0.0
    desc = parse_table(raw, f"{src} [{parameter_set}{'' if delay else ', tau = 0'}]")
    return desc, float(ps["kt_m3_per_v_s"])


def conditioning(raw: dict) -> Conditioning:
    """The transducer conditioning constants of a description's ``[controller]``."""
    c = raw["controller"]
    return Conditioning(float(c["k_x_cond_v_per_m"]), float(c["k_d_cond_v_per_m"]), float(c["k_dp_cond_v_per_pa"]))


@dataclass
class AnalogGains:
    """The analog controller's settings for a run (the settings protocol of
    :mod:`sim.control.base`): the front-panel gains (Eq. 2), the parameter set (Tables
    1-2), the recorder rate (``rate_hz``: the run file's rate, the paper's 4000 Hz DAQ)
    and the controller's rate ``physics_rate_hz`` (it acts at every physics step)."""

    gains: Gains
    parameter_set: str
    rate_hz: float = RECORDER_RATE_HZ
    physics_rate_hz: float = PHYSICS_RATE_HZ
    delay: bool = True

    @property
    def controller_rate_hz(self) -> float:
        return self.physics_rate_hz

    @property
    def timestep_s(self) -> float:
        """One physics step per controller tick."""
        return 1.0 / self.physics_rate_hz

    def table(self, desc):
        """``desc`` with this run's parameter set applied (beta, leakage, valve delay)."""
        return apply_parameter_set(desc.raw, self.parameter_set, self.delay, desc.source)[0]

    def build(self, desc, *, hp, full_flow_m3_s: float, dt: float) -> "RiceController":
        """The controller of one simulation (``desc``: as returned by :meth:`table`)."""
        kt = float(desc.raw["controller"]["parameter_sets"][self.parameter_set]["kt_m3_per_v_s"])
        ctl = RiceController(self.gains, conditioning(desc.raw), kt, full_flow_m3_s, dt)
        ctl.stroke_limit_m = float(desc.actuators[0].cls.half_stroke_m)
        return ctl

    @classmethod
    def for_table(cls, desc, overrides: dict | None = None) -> "AnalogGains":
        """The table's ``[controller]`` (type = "analog") with a scenario's overrides on top."""
        c = dict(desc.raw.get("controller", {}) or {})
        c.update(overrides or {})
        keys = {"p_gain": "p", "i_gain_hz": "i_hz", "d_gain_s": "d_s", "ff_gain_s": "ff_s", "dp_gain": "dp"}
        known = set(keys) | {
            "type",
            "parameter_set",
            "rate_hz",
            "recorder_rate_hz",
            "parameter_sets",
            "k_x_cond_v_per_m",
            "k_d_cond_v_per_m",
            "k_dp_cond_v_per_pa",
        }
        extra = sorted(set(c) - known)
        if extra:
            raise ScenarioError(f"unknown analog controller key '{extra[0]}'; known: {', '.join(sorted(known))}")
        kw = {}
        for k, g in keys.items():
            v = c.get(k, 0.0 if k != "p_gain" else 1.0)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ScenarioError(f"controller.{k} must be a number (got {v!r})")
            kw[g] = float(v)
        ps = str(c.get("parameter_set", "d18"))
        if ps not in c.get("parameter_sets", {}):
            raise ScenarioError(
                f"controller.parameter_set '{ps}' is not one of the table's parameter sets "
                f"({', '.join(sorted(c.get('parameter_sets', {})))})"
            )
        phys = float(c.get("rate_hz", PHYSICS_RATE_HZ))
        rec = float(c.get("recorder_rate_hz", RECORDER_RATE_HZ))
        if not (phys > 0 and rec > 0) or abs(phys / rec - round(phys / rec)) > 1e-9:
            raise ScenarioError(
                f"controller.recorder_rate_hz ({rec:g}) must divide the controller's physics rate rate_hz ({phys:g})"
            )
        return cls(gains=Gains(**kw), parameter_set=ps, rate_hz=rec, physics_rate_hz=phys)


class RiceController:
    """The paper's analog controller (Eq. 2) in the time domain, for the simulation loop.

    x_c = (P e + I int e dt) K_x + (D de/dt) K_D + (FF dx_d/dt) K_D + dP K_dp dp,
    e = x_d - x_t, with x_t the actuator LVDT (stroke) and dp = p_a - p_b the actuator's
    differential pressure. de/dt uses the commanded and measured velocities (the analog
    differentiator of a noise-free signal). The valve opening (fraction of full opening)
    is k_t x_c / q_full, where q_full is the valve's no-load flow at full opening, so
    that the linearised valve flow is k_t x_c (Eq. 8; the delay is the valve's).
    """

    stroke_limit_m: float | None = None  #: set by :meth:`AnalogGains.build`: the actuator's half stroke

    def __init__(self, gains: Gains, cond: Conditioning, kt_m3_per_v_s: float, q_full_m3_s: float, dt: float):
        self.g, self.c, self.dt = gains, cond, dt
        self.rate_hz = 1.0 / dt  # one tick per physics step
        self.scale = kt_m3_per_v_s / q_full_m3_s
        self.reset()

    def reset(self):
        self.integral = 0.0

    @staticmethod
    def has_compiled_tick() -> bool:
        return False

    def start(self, tm, d, hs, reference, n_ticks: int, *, kinematics: str = "exact", fast: bool = True) -> None:
        """Prepare a run on ``reference`` (at the controller rate, one actuator along x:
        its x column is the commanded displacement x_d, compared with the stroke x_t);
        ``kinematics`` and ``fast`` do not apply (one actuator, no compiled tick)."""
        self._xd = np.ascontiguousarray(reference.d[:n_ticks, 0])
        self._vd = np.ascontiguousarray(reference.v[:n_ticks, 0])
        self._qs, self._ds = int(tm.stroke_qadr[0]), int(tm.stroke_dadr[0])
        self._io = (d.qpos, d.qvel, hs.state.p_a, hs.state.p_b)

    def tick(self, i: int, out: np.ndarray) -> None:
        """The valve opening of tick ``i`` (the state at the step's start) into ``out[0]``."""
        qpos, qvel, pa, pb = self._io
        out[0] = self.opening(self._xd[i], self._vd[i], qpos[self._qs], qvel[self._ds], pa[0, 0] - pb[0, 0])

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
