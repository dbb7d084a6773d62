"""Table controller model in the style of the MTS 469D (Sec. 2 of [Airouche 2014]).

Runs at the controller rate (1024 Hz by default, one tick every two physics steps of
1/2048 s) and holds its valve commands between ticks (zero-order hold, like a DAC).

DOF control with three-variable control (TVC), per tick:

1. The reference pose r(t) (6 DOF) goes to actuator space through the EXACT geometry
   (inverse kinematics of the table description), precomputed for the whole test:
   ``s_ref = IK(r)``. Actuator errors ``e = s_ref - s`` (LVDT strokes) go back to DOF
   space with the pseudo-inverse of the home Jacobian ``J = d s / d r``:
   ``e_dof = J+ e``.
2. DOF velocity demand (TVC): feed-forward of the reference velocity and acceleration,
   displacement feedback, velocity feedback::

       v_dem = kff_v * v_ref + kff_a * a_ref + kp * e_dof + kv * (v_ref - v)

   (per-DOF gains; ``kff_a`` is in seconds and cancels the servovalve's lag).
3. To actuator space ``J v_dem`` and to valve openings by the valve's no-load gain
   (opening = velocity * A / Q_full), with optional flow linearisation for the load
   pressure (opening scaled by sqrt(dP_no_load / dP_available)).
4. Differential-pressure stabilisation: ``- kdp * HP(p_L) / p_s`` per actuator (negative
   load-pressure feedback through a first-order high-pass; damps the oil column without
   a static error).
5. Force balance compensation: the part of the actuator forces that produces no platen
   wrench (the null space of J^T: 12 actuators for 6 DOF leave 6 "fighting" modes) is
   fed back with ``kfb`` so the redundant actuators do not fight.
6. Clip to +/- ``command_limit``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mjcf.description import DOFS6, TableDescription, actuator_strokes

try:  # compiled tick (the numpy method below is the reference; tests check they agree)
    import numba as _nb
except ImportError:  # pragma: no cover
    _nb = None
from sim.errors import ScenarioError

DOF6 = DOFS6


def _vec6(v, name) -> np.ndarray:
    a = np.asarray(v, dtype=float)
    if a.ndim == 0:
        a = np.full(6, float(a))
    if a.shape != (6,) or not np.all(np.isfinite(a)):
        raise ScenarioError(f"controller.{name} must be a number or 6 numbers (x, y, z, rx, ry, rz); got {v!r}")
    return a


@dataclass(frozen=True, kw_only=True)
class ControllerGains:
    """Gains of the table controller (per DOF where a list of 6 is given)."""

    kp_per_s: np.ndarray = field(default_factory=lambda: np.full(6, 25.0))
    """Displacement gain: DOF velocity demand per unit DOF error (1/s)."""
    kff_velocity: np.ndarray = field(default_factory=lambda: np.ones(6))
    """Velocity feed-forward (fraction of the reference velocity)."""
    kff_acceleration_s: np.ndarray = field(default_factory=lambda: np.full(6, 0.0056))
    """Acceleration feed-forward time (s): v_dem += k a_ref; default = servovalve tau."""
    kff_jerk_s2: np.ndarray = field(default_factory=lambda: np.zeros(6))
    """Jerk feed-forward (s^2): v_dem += k d(a_ref)/dt; ~1/w_oil^2 cancels the oil column."""
    kv_feedback: np.ndarray = field(default_factory=lambda: np.zeros(6))
    """Velocity feedback gain (dimensionless) on v_ref - v."""
    kdp: float = 0.3
    """Differential-pressure stabilisation: opening per unit load pressure / supply pressure."""
    dp_highpass_hz: float = 2.0
    """Corner of the first-order high-pass on the dP feedback (0 = none): stabilises the
    oil column (16-29 Hz) without the static tracking error a plain dP feedback costs."""
    kfb: float = 0.05
    """Force-balance compensation gain on the internal (wrench-free) force component."""
    flow_linearisation: bool = True
    """Scale openings by sqrt(no-load drop / available drop)."""
    command_limit: float = 1.0
    rate_hz: float = 1024.0

    @classmethod
    def for_table(cls, desc: TableDescription, overrides: dict | None = None) -> "ControllerGains":
        """The table's default gains (its [controller] section) with ``overrides`` on top."""
        base = dict(desc.raw.get("controller", {}) or {})
        base.update(overrides or {})
        if base.get("type", "digital") == "digital":  # the controller's type (sim.control.base), not a gain
            base.pop("type", None)
        return cls.from_dict(base)

    # ---- the settings protocol of sim.control.base: one tick per recorded sample
    @property
    def controller_rate_hz(self) -> float:
        """The controller's tick rate: the recorder's (one recorded sample per tick)."""
        return self.rate_hz

    timestep_s = None  #: the table's own physics step

    def table(self, desc: TableDescription) -> TableDescription:
        """The description this controller runs on: the table's own."""
        return desc

    def build(self, desc: TableDescription, *, hp, full_flow_m3_s: float, dt: float) -> "TableController":
        """The controller of one simulation (``hp``: its hydraulic parameters)."""
        return TableController(
            desc,
            self,
            area_m2=hp.area_a_m2,
            full_flow_m3_s=full_flow_m3_s,
            supply_pressure_pa=hp.supply_pressure_pa,
            return_pressure_pa=hp.return_pressure_pa,
        )

    @classmethod
    def from_dict(cls, d: dict | None) -> "ControllerGains":
        d = dict(d or {})
        kw = {}
        for key in ("kp_per_s", "kff_velocity", "kff_acceleration_s", "kff_jerk_s2", "kv_feedback"):
            if key in d:
                kw[key] = _vec6(d.pop(key), key)
        for key in ("kdp", "dp_highpass_hz", "kfb", "command_limit", "rate_hz"):
            if key in d:
                v = d.pop(key)
                if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                    raise ScenarioError(f"controller.{key} must be a number (got {v!r})")
                kw[key] = float(v)
        if "flow_linearisation" in d:
            v = d.pop("flow_linearisation")
            if not isinstance(v, bool):
                raise ScenarioError(f"controller.flow_linearisation must be true or false (got {v!r})")
            kw["flow_linearisation"] = v
        if d:
            known = (
                "kp_per_s",
                "kff_velocity",
                "kff_acceleration_s",
                "kff_jerk_s2",
                "kv_feedback",
                "kdp",
                "dp_highpass_hz",
                "kfb",
                "flow_linearisation",
                "command_limit",
                "rate_hz",
            )
            from sim.validate import suggest

            key = sorted(d)[0]
            raise ScenarioError(f"unknown controller key '{key}'{suggest(key, known)}; known: {', '.join(known)}")
        g = cls(**kw)
        if not 0 < g.command_limit <= 1:
            raise ScenarioError(f"controller.command_limit must be in (0, 1] (got {g.command_limit})")
        if g.rate_hz <= 0:
            raise ScenarioError(f"controller.rate_hz must be > 0 (got {g.rate_hz})")
        return g


def dof_jacobian(desc: TableDescription, pose=None, h: float = 1e-6) -> np.ndarray:
    """(n_act, 6) d(stroke)/d(pose) of the exact inverse kinematics, by central differences."""
    p0 = np.zeros(6) if pose is None else np.asarray(pose, float)
    J = np.zeros((len(desc.actuators), 6))
    for k in range(6):
        dp = np.zeros(6)
        dp[k] = h
        J[:, k] = (actuator_strokes(desc, p0 + dp) - actuator_strokes(desc, p0 - dp)) / (2 * h)
    return J


class TableController:
    """Closed-loop controller of one table (see the module docstring)."""

    def __init__(
        self,
        desc: TableDescription,
        gains: ControllerGains,
        *,
        area_m2: np.ndarray,
        full_flow_m3_s: float,
        supply_pressure_pa: float,
        return_pressure_pa: float,
    ):
        self.desc = desc
        self.g = gains
        self.J = dof_jacobian(desc)
        # only the table's own DOFs are controlled (a uni-axial table has just x)
        mask = np.array([d in desc.dofs for d in DOF6], dtype=float)
        self.J = self.J * mask
        self.Jp = np.linalg.pinv(self.J)
        n = self.J.shape[0]
        self.N = np.eye(n) - self.J @ self.Jp  # projector onto wrench-free actuator forces
        self.area = np.asarray(area_m2, float)
        self.open_per_velocity = self.area / full_flow_m3_s  # opening per m/s of stroke rate
        self.ps = supply_pressure_pa
        self.dp0 = supply_pressure_pa - return_pressure_pa
        self._kp = gains.kp_per_s
        dt = 1.0 / gains.rate_hz
        self._hp_a = 1.0 / (1.0 + 2 * np.pi * gains.dp_highpass_hz * dt) if gains.dp_highpass_hz > 0 else None
        # constants of the compiled tick: per-actuator [area, opening per velocity], and
        # [kp (6), kv (6), kdp, kfb, hp_a (-1 = no high-pass), ps, dp0, flow linearisation, limit]
        self._consts = np.ascontiguousarray(np.stack([self.area, self.open_per_velocity]))
        self._gains_arr = np.ascontiguousarray(
            np.concatenate(
                [
                    self._kp,
                    gains.kv_feedback,
                    [
                        gains.kdp,
                        gains.kfb,
                        self._hp_a if self._hp_a is not None else -1.0,
                        self.ps,
                        self.dp0,
                        1.0 if gains.flow_linearisation else 0.0,
                        gains.command_limit,
                    ],
                ]
            )
        )
        self.reset()

    stroke_limit_m = None  #: the loop does not stop at the stroke ends (the feasibility verdict reports them)

    @property
    def rate_hz(self) -> float:
        return self.g.rate_hz

    def start(self, tm, d, hs, reference, n_ticks: int, *, kinematics: str = "exact", fast: bool = True) -> None:
        """Prepare a closed-loop run of ``n_ticks`` ticks on ``reference`` (at the
        controller rate): the reference strokes (``kinematics``: ``"exact"``, the inverse
        kinematics of the linkage geometry, as the table's controller does, or
        ``"linear"``, the home Jacobian ``s = J(0) r``), the DOF velocities, the
        feed-forward demand, and the state arrays :meth:`tick` reads (MuJoCo's ``d``, the
        hydraulics ``hs``). ``fast``: the compiled tick (False: the numpy reference)."""
        n = n_ticks
        if kinematics == "exact":
            self.s_ref_all = actuator_strokes(tm.desc, reference.d[:n])
        elif kinematics == "linear":
            self.s_ref_all = np.ascontiguousarray(reference.d[:n] @ self.J.T)
        else:
            raise ValueError(f"kinematics must be 'exact' or 'linear' (got {kinematics!r})")
        self.v_ref_all = np.ascontiguousarray(reference.v[:n])
        self.vff_all = self.feedforward(reference.v[:n], reference.a[:n], self.g.rate_hz)
        self._io = (d.qpos, d.qvel, d.xmat, hs.force[0], hs.state.p_supply)
        self._qa = np.asarray(tm.stroke_qadr, dtype=np.int64)
        self._pd, self._pb = tm.platen_dadr, tm.platen_body
        self._slide_d, self._pdi = tm.platen_slide_dadr, tm.platen_dof_index
        self._x = np.zeros(len(self._qa))
        self._v6 = np.zeros(6)
        self._mode = 0 if not tm.platen_free else (1 if fast else 2)

    def tick(self, i: int, out: np.ndarray) -> None:
        """Valve commands of tick ``i`` (after :meth:`start`) into ``out`` (n_act,)."""
        qpos, qvel, xmat, force, psup = self._io
        if self._mode == 1:  # free platen, compiled, reading MuJoCo's arrays
            self.command_from_state(
                i,
                self.s_ref_all,
                self.v_ref_all,
                self.vff_all,
                qpos,
                qvel,
                xmat,
                self._qa,
                self._pd,
                self._pb,
                force,
                psup[0],
                out,
            )
        elif self._mode == 0:  # bearing-guided platen: the table's slides
            x, v6 = self._x, self._v6
            x[:] = qpos[self._qa]
            v6[:] = 0.0
            v6[self._pdi] = qvel[self._slide_d]
            self.command_fast(self.s_ref_all[i], self.v_ref_all[i], self.vff_all[i], x, v6, force, psup[0], out)
        else:  # free platen, numpy reference
            x, v6, pd = self._x, self._v6, self._pd
            x[:] = qpos[self._qa]
            v6[:3] = qvel[pd : pd + 3]
            v6[3:] = xmat[self._pb].reshape(3, 3) @ qvel[pd + 3 : pd + 6]
            out[:] = self.command(self.s_ref_all[i], self.v_ref_all[i], self.vff_all[i], x, v6, force, psup[0])

    def reset(self):
        """Clear the dP high-pass filter (call before a new run)."""
        n = self.J.shape[0]
        self._pl_hp = np.zeros(n)
        self._pl_prev = np.zeros(n)
        self._state = np.zeros(1)  # [0] = 1 once the filter has its first sample

    def command_fast(self, s_ref, v_ref6, vff6, strokes, v6, force, supply_pressure, out) -> np.ndarray:
        """Same as :meth:`command`, compiled (numba); writes into ``out`` (n_act,)."""
        if _tick is None:
            out[:] = self.command(s_ref, v_ref6, vff6, strokes, v6, force, supply_pressure)
            return out
        _tick(
            s_ref,
            v_ref6,
            vff6,
            strokes,
            v6,
            force,
            supply_pressure,
            self.J,
            self.Jp,
            self.N,
            self._consts,
            self._gains_arr,
            self._state,
            self._pl_hp,
            self._pl_prev,
            out,
        )
        return out

    def kernel_args(self) -> tuple:
        """The compiled tick's constant and state arrays, in its argument order (valid
        until the next :meth:`reset`)."""
        return (self._consts, self.J, self.Jp, self.N, self._gains_arr, self._state, self._pl_hp, self._pl_prev)

    @staticmethod
    def has_compiled_tick() -> bool:
        return _tick_state is not None

    def command_from_state(
        self, k, s_ref_all, v_ref_all, vff_all, qpos, qvel, xmat, qa, pd, pb, force, supply_pressure, out
    ) -> np.ndarray:
        """Compiled tick reading strokes and the platen velocity straight from MuJoCo's arrays."""
        if _tick_state is None:
            x = qpos[qa]
            R = xmat[pb].reshape(3, 3)
            v6 = np.concatenate([qvel[pd : pd + 3], R @ qvel[pd + 3 : pd + 6]])
            out[:] = self.command(s_ref_all[k], v_ref_all[k], vff_all[k], x, v6, force, supply_pressure)
            return out
        _tick_state(
            k,
            s_ref_all,
            v_ref_all,
            vff_all,
            qpos,
            qvel,
            xmat,
            qa,
            pd,
            pb,
            force,
            supply_pressure,
            *self.kernel_args(),
            out,
        )
        return out

    def feedforward(self, v_ref: np.ndarray, a_ref: np.ndarray, rate_hz: float) -> np.ndarray:
        """(N, 6) feed-forward DOF velocity demand: kff_v v + kff_a a + kff_j jerk.

        The jerk is the derivative of the reference acceleration (central differences;
        the reference is known in advance, as in the table's own off-line compensation).
        """
        g = self.g
        out = g.kff_velocity * v_ref + g.kff_acceleration_s * a_ref
        if np.any(g.kff_jerk_s2) and len(a_ref) > 2:
            out = out + g.kff_jerk_s2 * np.gradient(a_ref, 1.0 / rate_hz, axis=0)
        return np.ascontiguousarray(out)

    def command(self, s_ref, v_ref6, vff6, strokes, v6, force, supply_pressure=None) -> np.ndarray:
        """Valve commands (n_act,) for one tick.

        Args:
            s_ref: (n_act,) reference strokes (exact IK of the reference pose), m.
            v_ref6: (6,) reference DOF velocity; vff6: (6,) feed-forward velocity demand
                (see :meth:`feedforward`).
            strokes: (n_act,) measured strokes (LVDT), m.
            v6: (6,) measured DOF velocity.
            force: (n_act,) measured actuator forces (pressure), N.
        """
        g = self.g
        e_dof = self.Jp @ (s_ref - strokes)
        v_dem = vff6 + self._kp * e_dof
        if g.kv_feedback.any():
            v_dem = v_dem + g.kv_feedback * (v_ref6 - v6)
        c = (self.J @ v_dem) * self.open_per_velocity
        pl = force / self.area  # load pressure, + pushes extension
        if g.flow_linearisation:
            ps = self.ps if supply_pressure is None else supply_pressure
            dp_avail = np.maximum(self.dp0 - (ps - self.ps) - np.sign(c) * pl, 0.1 * self.dp0)
            c = c * np.sqrt(self.dp0 / dp_avail)
        if self._hp_a is not None:
            if self._state[0] == 0.0:
                self._pl_prev[:] = pl
            self._state[0] = 1.0
            self._pl_hp[:] = self._hp_a * (self._pl_hp + pl - self._pl_prev)
            self._pl_prev[:] = pl
            c -= g.kdp * self._pl_hp / self.ps
        else:
            c -= g.kdp * pl / self.ps
        if g.kfb:
            c -= g.kfb * (self.N @ force) / (self.area * self.ps)
        np.clip(c, -g.command_limit, g.command_limit, out=c)
        return c


if _nb is not None:

    @_nb.njit(cache=True)
    def _tick(s_ref, v_ref6, vff6, x, v6, force, ps_now, J, Jp, N, consts, gains, state, pl_hp, pl_prev, out):
        area = consts[0]
        opv = consts[1]
        kp = gains[0:6]
        kv = gains[6:12]
        kdp, kfb, hp_a, ps, dp0, flowlin, lim = (
            gains[12],
            gains[13],
            gains[14],
            gains[15],
            gains[16],
            gains[17],
            gains[18],
        )
        n = x.shape[0]
        e = np.empty(n)
        for i in range(n):
            e[i] = s_ref[i] - x[i]
        vd = np.empty(6)
        for k in range(6):
            acc = 0.0
            for i in range(n):
                acc += Jp[k, i] * e[i]
            vd[k] = vff6[k] + kp[k] * acc + kv[k] * (v_ref6[k] - v6[k])
        first = state[0] == 0.0
        state[0] = 1.0
        for i in range(n):
            c = 0.0
            for k in range(6):
                c += J[i, k] * vd[k]
            c *= opv[i]
            pl = force[i] / area[i]
            if flowlin > 0.0:
                sg = 1.0 if c > 0.0 else (-1.0 if c < 0.0 else 0.0)
                avail = dp0 - (ps_now - ps) - sg * pl
                if avail < 0.1 * dp0:
                    avail = 0.1 * dp0
                c *= np.sqrt(dp0 / avail)
            if hp_a >= 0.0:
                if first:
                    pl_prev[i] = pl
                pl_hp[i] = hp_a * (pl_hp[i] + pl - pl_prev[i])
                pl_prev[i] = pl
                c -= kdp * pl_hp[i] / ps
            else:
                c -= kdp * pl / ps
            out[i] = c
        if kfb != 0.0:
            for i in range(n):
                fi = 0.0
                for j in range(n):
                    fi += N[i, j] * force[j]
                out[i] -= kfb * fi / (area[i] * ps)
        for i in range(n):
            if out[i] > lim:
                out[i] = lim
            elif out[i] < -lim:
                out[i] = -lim
        return out

    @_nb.njit(cache=True)
    def _tick_state(
        k,
        s_ref_all,
        v_ref_all,
        vff_all,
        qpos,
        qvel,
        xmat,
        qa,
        pd,
        pb,
        force,
        ps_now,
        consts,
        J,
        Jp,
        N,
        gains,
        state,
        pl_hp,
        pl_prev,
        out,
    ):
        n = qa.shape[0]
        x = np.empty(n)
        for i in range(n):
            x[i] = qpos[qa[i]]
        v6 = np.empty(6)
        v6[0] = qvel[pd]
        v6[1] = qvel[pd + 1]
        v6[2] = qvel[pd + 2]
        for r in range(3):
            v6[3 + r] = (
                xmat[pb, 3 * r] * qvel[pd + 3] + xmat[pb, 3 * r + 1] * qvel[pd + 4] + xmat[pb, 3 * r + 2] * qvel[pd + 5]
            )
        _tick(
            s_ref_all[k],
            v_ref_all[k],
            vff_all[k],
            x,
            v6,
            force,
            ps_now,
            J,
            Jp,
            N,
            consts,
            gains,
            state,
            pl_hp,
            pl_prev,
            out,
        )
        return out

    # fmt: off
    @_nb.njit(cache=True)
    def _tick_guided(
        k, s_ref_all, v_ref_all, vff_all, qpos, qvel, qa, slide_d, dof_i, force, ps_now, consts, J, Jp, N, gains, state,
        pl_hp, pl_prev, out,
    ):
        """:func:`_tick_state` of a bearing-guided platen: the DOF velocity is its slides'
        (``qvel[slide_d[i]]`` at DOF ``dof_i[i]``, the others 0), as :meth:`TableController.tick`
        builds it (mode 0) before :meth:`~TableController.command_fast`; same values, same
        compiled :func:`_tick`, so the same commands bit for bit."""
        n = qa.shape[0]
        x = np.empty(n)
        for i in range(n):
            x[i] = qpos[qa[i]]
        v6 = np.zeros(6)
        for i in range(slide_d.shape[0]):
            v6[dof_i[i]] = qvel[slide_d[i]]
        _tick(
            s_ref_all[k], v_ref_all[k], vff_all[k], x, v6, force, ps_now, J, Jp, N, consts, gains, state, pl_hp, pl_prev,
            out,
        )
        return out
    # fmt: on
else:  # pragma: no cover
    _tick = _tick_state = _tick_guided = None
