"""What :meth:`sim.loop.simulation.Simulation.run` sets up once per run, so that its loop
only reads locals: the recorder's arrays (:class:`Recording`), the arguments of the step
kernels (:class:`Wiring`: views of the MjData and of the hydraulic state, int64 indices,
which kernel does each part) and what a loop hands back (:class:`Tally`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


class Recording:
    """The recorder's arrays for ``n`` samples, NaN until written: raw qpos, qvel and the
    platen's qacc (``Q``, ``V``, ``ACC``), the hydraulic channels (``H``) and the extras."""

    HYDRAULIC = ("valve_command", "spool_position", "actuator_force", "pressure_a", "pressure_b")

    def __init__(self, n: int, nq: int, nv: int, na: int):
        self.Q = np.full((n, nq), np.nan)
        self.V = np.full((n, nv), np.nan)
        self.ACC = np.full((n, 6), np.nan)
        self.H = {k: np.full((n, na), np.nan) for k in self.HYDRAULIC}
        self.ex = {
            "supply_pressure": np.full(n, np.nan),
            "accumulator_gas_volume": np.full(n, np.nan),
            "loop_gap": np.full(n, np.nan),
        }


@dataclass
class Tally:
    """What a loop hands back: samples done, why it stopped early, seconds in each part."""

    done: int
    reason: str | None
    interrupted: bool
    t_ctrl: float = 0.0
    t_hyd: float = 0.0
    t_phys: float = 0.0
    t_out: float = 0.0
    t_fused: float = 0.0


def _record_numpy(k, qpos, qvel, Q, V, spool, force, pa, pb, psup, gasv, Hsp, Hf, Hpa, Hpb, Eps, Egas):
    """Reference (numpy) version of :func:`sim.loop._kernels.record`."""
    Q[k] = qpos
    V[k] = qvel
    Hsp[k] = spool
    Hf[k] = force
    Hpa[k] = pa
    Hpb[k] = pb
    Eps[k] = psup[0]
    Egas[k] = gasv[0]


class Wiring:
    """What the loop hands the step kernels, set up once per run: views of the MjData and
    the hydraulic state, int64 indices, the step's input buffers, and which kernel does
    each part (compiled, or the numpy reference with ``fast`` False)."""

    def __init__(self, sim, fast: bool, w0: np.ndarray):
        tm, d, hs = sim.tm, sim.d, sim.hs
        self.sim, self.fast = sim, fast
        self.qpos, self.qvel, self.qacc, self.dctrl, self.qfa = d.qpos, d.qvel, d.qacc, d.ctrl, d.qfrc_applied
        na = tm.n_act
        self.x2, self.v2, self.cmd2 = np.zeros((1, na)), np.zeros((1, na)), np.zeros((1, na))
        self.cmd = self.cmd2[0]
        self.qa64, self.da64, self.ids64 = (
            np.asarray(a, dtype=np.int64) for a in (tm.stroke_qadr, tm.stroke_dadr, tm.actuator_ids)
        )
        self.one = na == 1
        self.q0, self.d0, self.i0 = int(self.qa64[0]), int(self.da64[0]), int(self.ids64[0])
        self.free, self.effects, self.pd = tm.platen_free, tm.step_effects, tm.platen_dadr
        self.slide_d, self.n_pd = np.asarray(tm.platen_slide_dadr, dtype=np.int64), len(tm.platen_dof_index)
        self.fnd_d = sim._fnd_d  # a spring-mounted foundation's slides: absolute table acceleration
        st = hs.state
        self.force, self.psup = hs.force[0], st.p_supply
        self.hyd = (self.cmd2, self.x2, self.v2, hs._X, hs._Y, hs._IC, hs._ICS, hs._buf)
        self._friction_and_air(sim, fast)
        lims, lim = sim._pressure_limits(), sim.controller.stroke_limit_m
        slim = math.inf if lim is None else float(lim)
        wnum = d.warning.number  # MuJoCo's warning counters (a view)
        self.health_args = (self.qpos, self.qvel, st.p_a, st.p_b, self.psup, *lims, wnum, sim._warn_idx, w0)
        self.health_args += (self.qa64, slim)

    def _friction_and_air(self, sim, fast):
        """The loop's own generalised forces (pre-sliding friction, air springs) and the
        pre-step kernel that computes them with the hydraulic step when it can."""
        tm, hs, dt = sim.tm, sim.hs, sim.dt
        self.fr = (tm.friction_dofs, tm.friction_force, sim._zfr, tm.friction_presliding_m)
        self.nfr = len(tm.friction_dofs)
        self.air_args = (self.qpos, self.qfa, tm.air_qadr, tm.air_dadr, tm.air_preload)
        self.air_args += (float(tm.air_area_over_volume), float(tm.air_exponent))
        self.nair = len(tm.air_qadr)
        nq = self.nfr or self.nair  # qfrc_applied written by the loop every step
        self.fused = fast and hs.delay_steps == 0 and hs.backend == "numba"  # one compiled call per step
        self.clear_qfa = not (self.fused and nq) and bool(self.effects or nq)
        self.fr_args = (self.qvel, self.qfa) + self.fr + ((dt,) if fast else ())
        self.pre_args = (self.qpos, self.qvel, self.dctrl, self.qa64, self.da64, self.ids64) + self.hyd
        self.pre_args += (0, hs._P, hs._G)
        if fast:
            from hydraulics import _layout as HL
            from sim.loop import _kernels as FL

            self.layout = HL
            self.friction, self.air, self.record = FL.presliding_friction, FL.air_springs, FL.record
            self.pre_step = FL.pre_step_friction if self.fused and nq else FL.pre_step
            if self.fused and nq:
                self.pre_args += (self.qfa,) + self.fr + (dt,) + self.air_args[2:]
        else:
            self.friction, self.air, self.record, self.pre_step = (
                sim._presliding_numpy,
                sim._air_numpy,
                _record_numpy,
                None,
            )
        #: the loop's own forces where the pre-step does not add them, in order
        own = ((self.friction, self.fr_args),) if self.nfr else ()
        self.own_forces = own + (((self.air, self.air_args),) if self.nair else ())

    def record_args(self, rec: Recording) -> tuple:
        """The recorder's arguments after the sample index (compiled or numpy ``record``)."""
        H, ex, hs = rec.H, rec.ex, self.sim.hs
        out = (H["spool_position"], H["actuator_force"], H["pressure_a"], H["pressure_b"])
        if self.fast:
            L = self.layout
            idx = (L.SPOOL, L.FORCE, L.PA, L.PB)
            tail = (L.PS, L.GASV, ex["supply_pressure"], ex["accumulator_gas_volume"])
            return (self.qpos, self.qvel, rec.Q, rec.V, hs._X, hs._Y) + idx + out + tail
        st = hs.state
        state = (st.spool[0], self.force, st.p_a[0], st.p_b[0], self.psup, st.gas_volume)
        return (
            (self.qpos, self.qvel, rec.Q, rec.V) + state + out + (ex["supply_pressure"], ex["accumulator_gas_volume"])
        )

    def fused_args(self, rec: Recording, ctrl) -> tuple[tuple, tuple]:
        """The arguments of :func:`sim.loop._kernels.tick_first_step` and
        :func:`~sim.loop._kernels.later_step` after the sample index."""
        sim, H, ex = self.sim, rec.H, rec.ex
        hs = sim.hs
        idx = (self.qa64, self.da64, self.ids64)
        hyd_args = idx + self.hyd[:3] + (hs._X, hs._Y, hs._IC, hs._ICS, hs._buf, hs._P, hs._G) + self.fr + (sim.dt,)
        hyd_args += self.air_args[2:]
        out = (rec.Q, rec.V, H["spool_position"], H["actuator_force"], H["pressure_a"], H["pressure_b"])
        out += (H["valve_command"], ex["supply_pressure"], ex["accumulator_gas_volume"])
        refs = (ctrl.s_ref_all, ctrl.v_ref_all, ctrl.vff_all)
        d = sim.d
        first = (self.qpos, self.qvel, d.xmat, self.dctrl, self.qfa) + out + refs + idx + (self.pd, sim.tm.platen_body)
        first += ctrl.kernel_args() + hyd_args[3:]
        later = (self.qpos, self.qvel, self.qacc, self.dctrl, self.qfa, rec.ACC, self.pd) + hyd_args
        return first, later
