"""The coupled simulation: MuJoCo multibody table + hydraulic step + controller.

Coupling order (one physics step, time t_n -> t_n + dt):

1. MuJoCo state at t_n gives every linkage's stroke x_n and stroke rate v_n (named
   accessors of :class:`mjcf.model.TableModel`).
2. On a controller tick (every ``steps_per_tick`` steps) the driver produces the valve
   commands, held until the next tick: either the closed-loop controller
   (:class:`sim.control.tvc.TableController`) or the recorded commands of a run file
   (open-loop replay).
3. ``hydraulics.step(command, x_n, v_n)`` advances the servovalves, chambers and supply
   over the step and returns the net piston forces (pressures at the end of the step;
   see ``hydraulics/system.py`` for why).
4. The forces go into ``data.ctrl`` of the gear-1 motors on the stroke slides (so each
   force acts along its linkage, between cylinder and rod). With the table's
   ``[friction] model = "presliding"``, dry friction of the seals, support pistons and
   shoes is computed from the same state (pre-sliding model, ``sim.loop._kernels``) and
   written to ``qfrc_applied``; named per-step effects add theirs there too.
5. ``mj_step`` advances the mechanics t_n -> t_n + dt (``data.qacc`` then holds the
   acceleration at t_n, which the recorder reads).

The recorder samples at the controller tick (1024 Hz as the CGS data recorder): states
at t_k, the command computed at t_k, and the accelerations of the step leaving t_k. The
default physics step is 1/2048 s (0.49 ms), so a tick is exactly two steps and a replay
of the recorded commands reproduces the run to round-off.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import mujoco
import numpy as np

from hydraulics import HydraulicSystem
from mjcf.model import TableModel
from sim.control.base import controller_settings
from sim.effects.faults import hooks_for  # faults:
from sim.effects.registry import dahl_step, hydraulics_with
from sim.errors import RunInterrupted, ScenarioError, is_interrupt
from sim.loop.recorder import derive, foundation_slides
from sim.loop.wiring import Recording, Tally, Wiring
from sim.scenario.reference import Reference, reference_from_motions
from sim.validate import check_samples

GAP_LIMIT_M = 1e-3  #: a swivel opening by more than 1 mm means the solve has failed
#: MuJoCo's warnings that mean the mechanics failed (MuJoCo resets the state after a bad
#: qacc, so the run would go on from the home pose as if nothing had happened), with
#: what each means.
MJ_WARNINGS = {
    mujoco.mjtWarning.mjWARN_BADQACC: "MuJoCo's accelerations were not finite (it reset the state)",
    mujoco.mjtWarning.mjWARN_BADQPOS: "MuJoCo's positions were not finite (it reset the state)",
    mujoco.mjtWarning.mjWARN_BADQVEL: "MuJoCo's velocities were not finite (it reset the state)",
    mujoco.mjtWarning.mjWARN_BADCTRL: "a control input (actuator force) was not finite",
    mujoco.mjtWarning.mjWARN_INERTIA: "a body has an inertia that is not physical",
}
#: MuJoCo's last warning texts (MuJoCo would print them on stdout, mixing them into
#: ``--json`` output, and append them to MUJOCO_LOG.TXT in the working folder; the loop
#: reports them itself, in its divergence message).
MJ_WARNING_TEXTS: list[str] = []


def _keep_warning(text: str) -> None:
    MJ_WARNING_TEXTS[:] = (MJ_WARNING_TEXTS + [str(text)])[-8:]


mujoco.set_mju_user_warning(_keep_warning)

#: The likely causes, said with every divergence message.
CAUSE_STEP = (
    "likely cause: a physics step too large for the stiffest part of the model "
    "(halve the time step) or a stiffness, bulk modulus or gain set too high"
)


@dataclass
class RunResult:
    """Arrays recorded at the controller rate, plus timing and status."""

    t: np.ndarray
    channels: dict
    extras: dict
    wall_s: float
    sim_s: float
    timing: dict = field(default_factory=dict)
    incomplete_reason: str | None = None
    interrupted: bool = False  #: stopped by Ctrl-C (``incomplete_reason`` says when)
    #: how long the recorded actuator force (and pressures) lag the force that produced the
    #: recorded acceleration: the recorder takes the pressures at t_k and the acceleration of
    #: the physics step leaving t_k, which MuJoCo computed from the pressures of the
    #: hydraulic step before it, at t_k + h (h the physics step). 0 when they agree.
    force_lag_s: float = 0.0
    #: each valve's command at which it passes no flow (minus its null offset, effects
    #: included): what the controller holds while the table stands still. ``run --measure``
    #: holds it through a quiet lead-in (:func:`sim.runs.measure.measure_run`)
    valve_hold: np.ndarray | None = None

    @property
    def realtime_factor(self) -> float:
        return self.sim_s / self.wall_s if self.wall_s > 0 else float("inf")


def description_as_run(desc, gains=None):
    """``desc`` as its controller runs it (``gains.table``, default the table's
    controller's: the Rice analog controller's parameter set written into the bulk
    modulus, leakage and valve delay), under its own source name: the declared model a
    record of the table is compared with, as ``shaketable run`` simulates it."""
    from mjcf.description import parse_table

    ran = (gains or controller_settings(desc)).table(desc)
    return desc if ran is desc else parse_table(ran.raw, src=desc.source)


def table_model(desc, payload=None, gains=None) -> TableModel:
    """The model of ``desc`` (+ ``payload``) at the physics step its controller acts on
    (``gains.timestep_s``, default the table's controller's; None: the builder's 1/2048 s).
    A replay or a calibration of a table's records builds this one: the analog controller
    of the Rice table acts every 1/8000 s, and its 4000 Hz records are the model's samples
    there only."""
    from mjcf.builder import BuildOptions
    from sim.effects import build_model

    dt = (gains or controller_settings(desc)).timestep_s
    return build_model(desc, payload) if dt is None else build_model(desc, payload, BuildOptions(timestep_s=dt))


class Simulation:
    """One table simulation (one MjData, one hydraulic system, one controller).

    ``gains``: the controller's settings (:mod:`sim.control.base`; default: the table's
    ``[controller]``, chosen by its ``type``). The controller ticks every
    ``steps_per_tick`` physics steps (2 for the MTS-style controller at 1024 Hz with a
    1/2048 s step, 1 for the analog one); the recorder samples every ``steps_per_sample``
    steps (2 for both: 1024 Hz, and 4000 Hz at the analog controller's 8000 Hz), at a
    controller tick. :meth:`for_table` builds the model the controller needs.
    """

    def __init__(self, tm: TableModel, *, backend: str = "numba", gains=None):
        self.tm = tm
        self.m = tm.model
        self.dt = float(self.m.opt.timestep)
        # hydraulic effects (bulk modulus, leakage, valve delay, ...) edit the description's
        hp = hydraulics_with(tm.desc, tm.effects)
        self.hp = hp
        self.hs = HydraulicSystem(self.hp, n_sim=1, dt=self.dt, backend=backend)
        for e in tm.effects:
            e.bind(self.m, self.hs)
        self.gains = gains or controller_settings(tm.desc)
        self.steps_per_tick = self._steps(self.gains.controller_rate_hz, "controller")
        self.steps_per_sample = self._steps(self.gains.rate_hz, "recorder")
        if self.steps_per_sample % self.steps_per_tick:
            raise ScenarioError(
                f"recorder rate {self.gains.rate_hz:g} Hz does not divide the controller rate "
                f"{self.gains.controller_rate_hz:g} Hz; the recorder samples at controller ticks"
            )
        full_flow = float(self.hs.no_load_flow(1.0))
        self.controller = self.gains.build(tm.desc, hp=self.hp, full_flow_m3_s=full_flow, dt=self.dt)
        self._fnd_q, self._fnd_d = foundation_slides(tm)
        self._warn_idx = np.array([int(w) for w in MJ_WARNINGS], dtype=np.int64)
        self._prepare_gap()
        self.reset()

    def _steps(self, rate_hz: float, what: str) -> int:
        ratio = 1.0 / (rate_hz * self.dt)
        n = int(round(ratio))
        if abs(ratio - n) > 1e-9 or n < 1:
            raise ScenarioError(
                f"{what} rate {rate_hz} Hz is not a whole fraction of the physics rate "
                f"{1 / self.dt:.1f} Hz; use a rate that divides it (e.g. 1024 Hz with a 1/2048 s step)"
            )
        return n

    @classmethod
    def for_table(cls, desc, payload=None, gains=None, *, backend: str = "numba") -> "Simulation":
        """The simulation of table ``desc`` (+ ``payload``) with the model its controller
        needs: ``gains`` (default: the table's, by ``[controller] type``) edit the
        description (``gains.table``, e.g. the analog controller's parameter set) and set
        the physics step (``gains.timestep_s``, None: the table's)."""
        gains = gains or controller_settings(desc)
        desc = gains.table(desc)
        return cls(table_model(desc, payload, gains), backend=backend, gains=gains)

    # ------------------------------------------------------------------ state
    def reset(self, pose=None, forces=None):
        """Back to the home keyframe (or ``pose``), hydraulics at rest.

        ``forces`` (n_act,) presets the actuator forces (chamber pressures and ``ctrl``),
        e.g. :meth:`static_forces` for a table whose actuators carry dead weight.
        """
        self.d = self.tm.new_data()
        self._warn0 = [0] * len(MJ_WARNINGS)  # MuJoCo warning counts at the start of a run (new data: none)
        self._zfr = np.zeros(len(self.tm.friction_dofs))  # pre-sliding friction states
        objs = {id(e): e for e in self.tm.step_effects + self.tm.effects}.values()
        for e in objs:  # effects with a state of their own
            reset = getattr(e, "reset", None)
            if reset is not None:
                reset()
        if pose is not None:
            self.tm.set_platen_pose(self.d, pose)
        x = self.tm.actuator_strokes(self.d)[None, :]
        self.hs.reset(x, force=None if forces is None else np.asarray(forces, float)[None, :])
        self.d.ctrl[self.tm.actuator_ids] = self.hs.force[0]
        mujoco.mj_forward(self.m, self.d)

    def _presliding_numpy(self, qvel, qfa, dofs, fc, z, zss):
        """Reference (numpy) version of :func:`sim.loop._kernels.presliding_friction`."""
        z[:] = dahl_step(z, qvel[dofs], zss, self.dt)
        qfa[dofs] += -fc / zss * z

    @staticmethod
    def _air_numpy(qpos, qfa, aq, ad, F0, c, n):
        """Reference (numpy) version of :func:`sim.loop._kernels.air_springs`."""
        x = c * qpos[aq]
        qfa[ad] += F0 * ((1.0 + x) ** (-n) - 1.0 + n * x)

    def static_forces(self) -> np.ndarray:
        """Actuator forces (n_act,) that hold the home pose against gravity with the
        supports at their preload (zero when the supports carry everything)."""
        from mjcf.analysis import static_balance

        return static_balance(self.m, self.tm.stroke_dadr, qpos=self.d.qpos.copy())

    def _prepare_gap(self):
        m = self.m
        ids = [i for i in range(m.neq) if m.eq_type[i] == mujoco.mjtEq.mjEQ_CONNECT]
        self._g_b1 = np.array([m.eq_obj1id[i] for i in ids])
        self._g_b2 = np.array([m.eq_obj2id[i] for i in ids])
        self._g_a1 = np.array([m.eq_data[i, 0:3] for i in ids])
        self._g_a2 = np.array([m.eq_data[i, 3:6] for i in ids]).reshape(-1, 3)
        self._g_a1 = self._g_a1.reshape(-1, 3)
        self._g_b1 = self._g_b1.astype(np.int64)
        self._g_b2 = self._g_b2.astype(np.int64)
        try:
            from sim.loop import _kernels as _fastloop

            self._fl = _fastloop
            self._fl_healthy = _fastloop.healthy
        except ImportError:  # pragma: no cover
            self._fl = None
            self._fl_healthy = lambda *a: False  # every check takes the slow path of _check

    def _pressure_limits(self) -> tuple[float, float]:
        """The chamber pressures' sane range [vapour, relief] (with round-off margins)."""
        hp = self.hp
        return hp.vapour_pressure_pa * (1 - 1e-9) - 1e-3, hp.relief_pressure_pa * (1 + 1e-9)

    def _at_ticks(self, reference: Reference, n: int, tps: int) -> Reference:
        """``reference`` (first ``n`` samples at the recorder rate) linearly interpolated to
        the controller's ``n * tps`` ticks (held after its last sample)."""
        rate = self.gains.rate_hz
        tk = np.arange(n) / rate
        ts = np.arange(n * tps) * (self.steps_per_tick * self.dt)
        cols = lambda a: np.stack([np.interp(ts, tk, a[:n, i]) for i in range(a.shape[1])], axis=1)  # noqa: E731
        return Reference(t=ts, d=cols(reference.d), v=cols(reference.v), a=cols(reference.a))

    def loop_gap(self) -> float:
        d = self.d
        if self._fl is not None:
            return float(self._fl.loop_gap(d.xpos, d.xmat, self._g_b1, self._g_b2, self._g_a1, self._g_a2))
        x1 = d.xpos[self._g_b1] + np.einsum("nij,nj->ni", d.xmat[self._g_b1].reshape(-1, 3, 3), self._g_a1)
        x2 = d.xpos[self._g_b2] + np.einsum("nij,nj->ni", d.xmat[self._g_b2].reshape(-1, 3, 3), self._g_a2)
        return float(np.sqrt(((x1 - x2) ** 2).sum(axis=1).max()))

    # ------------------------------------------------------------------ run
    def run(
        self,
        *,
        reference: Reference | None = None,
        valve_command: np.ndarray | None = None,
        duration_s: float | None = None,
        progress: bool = False,
        gap_every: int = 8,
        fast: bool = True,
        fuse: bool = True,
        kinematics: str = "exact",
    ) -> RunResult:
        """Run closed loop on ``reference`` or open loop on recorded ``valve_command``.

        ``kinematics``: how the controller turns the DOF reference into actuator strokes:
        ``"exact"`` (the inverse kinematics of the linkage geometry, as the table's
        controller does) or ``"linear"`` (the home Jacobian, ``s = J(0) r``: a
        small-motion DOF transformation; for the geometric-nonlinearity study).

        Both inputs are sampled at the controller rate. Returns the recorder's arrays.
        A simulation that leaves its physical bounds stops with the arrays up to then and
        ``incomplete_reason`` set (never raises for divergence). The loop-closure gap is
        evaluated every ``gap_every`` ticks (NaN in between).

        Inside the loop only raw state is copied (qpos, qvel, the platen's qacc, the
        hydraulic state); poses, velocities and accelerometer signals are derived from
        those copies after the run, vectorised. ``fast`` uses the compiled per-step and
        per-tick kernels of :mod:`sim.loop._kernels` (``False``: the plain numpy reference).
        ``fuse`` (with ``fast``, closed loop on a free platen, no step effects, two or more
        physics steps per tick): recorder, controller and pre-step in one compiled call per
        physics step (same results; ``timing`` then has the three together under
        ``fused_s`` and no separate hydraulics/controller split).

        Steps: the run's length (:meth:`_run_length`), the controller started on the
        reference or the commands taken (:meth:`_start_input`), the recorder's arrays
        (:class:`Recording`), the fault hooks, the kernels' arguments (:class:`Wiring`),
        then one of the two loops (:meth:`_loop_fused`, :meth:`_loop_stepwise`) and the
        channels derived from what it recorded (:meth:`_result`).
        """
        if (reference is None) == (valve_command is None):
            raise ValueError("give exactly one of reference and valve_command")
        self.controller.reset()
        n, tps, at_ticks = self._run_length(reference, valve_command, duration_s)
        w0 = self.d.warning.number[self._warn_idx].copy()  # MuJoCo's warning counts at the start
        self._warn0 = [int(v) for v in w0]
        vc_all = self._start_input(reference, valve_command, n, tps, at_ticks, kinematics, fast)
        rec = Recording(n, self.m.nq, self.m.nv, self.tm.n_act)
        hooks = self._start_hooks(reference)
        io = Wiring(self, fast, w0)
        clock = time.perf_counter
        wall0 = clock()
        if hooks is None and fuse and io.fused and self._fuses(reference, tps):  # faults: the fused tick has no hooks
            tally = self._loop_fused(n, rec, io, gap_every, progress)
        else:
            tally = self._loop_stepwise(n, tps, rec, io, hooks, vc_all, gap_every, progress)
        wall = clock() - wall0
        if progress:
            sys.stderr.write("\r" + " " * 70 + "\r")
            sys.stderr.flush()
        result = self._result(rec, tally, wall)
        if tally.interrupted:
            raise RunInterrupted(result)
        return result

    def _run_length(self, reference, valve_command, duration_s) -> tuple[int, int, bool]:
        """(samples ``n`` to record, controller ticks per sample, whether ``reference`` is
        sampled at the controller rate rather than the recorder's)."""
        rate = self.gains.rate_hz
        tps = self.steps_per_sample // self.steps_per_tick  # controller ticks per recorded sample
        at_ticks = (  # a reference sampled at the controller rate (else at the recorder's)
            reference is not None
            and tps > 1
            and len(reference.t) > 1
            and abs(reference.rate_hz - self.gains.controller_rate_hz) <= 1e-6 * self.gains.controller_rate_hz
        )
        n_in = len(reference.t) // (tps if at_ticks else 1) if reference is not None else len(valve_command)
        n = n_in if duration_s is None else min(n_in, int(round(duration_s * rate)) + 1)
        check_samples(n, f"a run of {n / rate:g} s at {rate:g} Hz", None, ScenarioError)  # before allocating
        return n, tps, at_ticks

    def _start_input(self, reference, valve_command, n, tps, at_ticks, kinematics, fast):
        """Closed loop: start the controller on the reference at its ticks (returns None);
        open loop: the first ``n`` recorded commands, contiguous float64."""
        if reference is None:
            return np.ascontiguousarray(valve_command[:n], dtype=np.float64)
        ref_ticks = reference if tps == 1 or at_ticks else self._at_ticks(reference, n, tps)
        self.controller.start(self.tm, self.d, self.hs, ref_ticks, n * tps, kinematics=kinematics, fast=fast)
        return None

    def _start_hooks(self, reference):
        """The controller-tick hooks of fault effects (sim/effects/faults.py), started, or None."""
        hooks = hooks_for(self)  # faults: started before the loop, called at its ticks
        if hooks is not None:
            if reference is None:
                raise ScenarioError("fault effects act on closed-loop runs; this is an open-loop replay")
            hooks.start(self.d)
        return hooks

    def _fuses(self, reference, tps: int) -> bool:
        """Whether recorder, controller tick and pre-step can run as one compiled call per
        physics step (given the compiled hydraulic step and no fault hooks): closed loop on a
        free platen, no per-step effects, two or more steps per tick, recording every tick."""
        return (
            self.tm.platen_free
            and reference is not None
            and not self.tm.step_effects
            and self.steps_per_sample >= 2
            and tps == 1
            and self.controller.has_compiled_tick()
        )

    def _loop_fused(self, n, rec, io, gap_every, progress) -> Tally:
        """The run with one compiled call per physics step (recorder, controller tick and
        hydraulics together, :func:`sim.loop._kernels.tick_first_step` then
        :func:`~sim.loop._kernels.later_step`) between the ``mj_step`` calls."""
        from sim.loop import _kernels as FL

        first, later, step, m, d = FL.tick_first_step, FL.later_step, mujoco.mj_step, self.m, self.d
        first_args, later_args = io.fused_args(rec, self.controller)
        spt = self.steps_per_sample
        t_phys = t_out = t_fused = 0.0
        reason, interrupted, done = None, False, 0
        clock = time.perf_counter
        last_print = clock()
        try:
            for k in range(n):
                t0 = clock()
                first(k, *first_args)
                t1 = clock()
                step(m, d)
                t2 = clock()
                later(k, *later_args)  # also records the first step's platen acceleration
                t3 = clock()
                step(m, d)
                t4 = clock()
                t_fused += (t1 - t0) + (t3 - t2)
                t_phys += (t2 - t1) + (t4 - t3)
                for _ in range(spt - 2):
                    later(-1, *later_args)
                    t6 = clock()
                    step(m, d)
                    t7 = clock()
                    t_fused += t6 - t4
                    t_phys += t7 - t6
                    t4 = t7
                done = k + 1  # tick k is complete (kept even if the check below stops the run)
                if k % gap_every == 0 or k == n - 1:  # divergence checks (a call every gap_every ticks)
                    t6 = clock()
                    reason = self._diverged(k, io, rec.ex["loop_gap"])
                    t_out += clock() - t6
                    if reason:
                        break
                if progress and clock() - last_print > 0.25:
                    last_print = self._show_progress(k, n)
        except (KeyboardInterrupt, SystemError) as e:
            reason, interrupted = self._interrupted(e, done, n), True
        return Tally(done, reason, interrupted, t_phys=t_phys, t_out=t_out, t_fused=t_fused)

    def _loop_stepwise(self, n, tps, rec, w, hooks, vc_all, gap_every, progress) -> Tally:
        """The run one physics step at a time: per sample the recorder and the controller tick
        (or the recorded command, or the fault hooks), then per physics step the hydraulic
        step, the loop's own forces and effects, and ``mj_step``. One body on purpose: it is
        the per-step hot path; everything it calls is set up once (:class:`Wiring`)."""
        m, d, hs, ctrl, tick, closed = self.m, self.d, self.hs, self.controller, self.controller.tick, vc_all is None
        rate, cp, spt, step = self.gains.rate_hz, self.steps_per_tick, self.steps_per_sample, mujoco.mj_step
        sub_ticks = closed and tps > 1  # controller ticks between recorded samples (open loop: commands held)
        qpos, qvel, qacc, dctrl, qfa = w.qpos, w.qvel, w.qacc, w.dctrl, w.qfa
        x2, v2, cmd2, cmd, force, psup = w.x2, w.v2, w.cmd2, w.cmd, w.force, w.psup
        record, rec_args, fused, pre_step, pre_args = w.record, w.record_args(rec), w.fused, w.pre_step, w.pre_args
        one, q0, d0, i0, qa64, da64, ids64 = w.one, w.q0, w.d0, w.i0, w.qa64, w.da64, w.ids64
        clear_qfa, own_forces = w.clear_qfa, w.own_forces  # pre-sliding friction, air springs
        effects, free, pd, fnd_d, slide_d, n_pd = w.effects, w.free, w.pd, w.fnd_d, w.slide_d, w.n_pd
        ACC, Hcmd = rec.ACC, rec.H["valve_command"]
        t_ctrl = t_hyd = t_phys = t_out = 0.0
        reason, interrupted, done = None, False, 0
        clock = time.perf_counter
        last_print = clock()
        try:
            for k in range(n):
                t0 = clock()  # ---- recorder: raw state at t_k
                record(k, *rec_args)
                t1 = clock()
                t_out += t1 - t0
                # ---- controller tick (valve commands held until the next tick)
                if hooks is not None:  # faults: the tick with feedback faults, interlock, stuck valves
                    hooks.tick(k, k / rate, ctrl.s_ref_all, ctrl.v_ref_all, ctrl.vff_all, d, force, psup[0], cmd)
                elif closed:
                    tick(k * tps, cmd)
                else:
                    cmd[:] = vc_all[k]
                Hcmd[k] = cmd
                t2 = clock()
                t_ctrl += t2 - t1
                # ---- physics steps of this sample: (later controller ticks,) hydraulics, then mj_step
                for j in range(spt):
                    t3 = clock()
                    if j and sub_ticks and j % cp == 0:
                        tick(k * tps + j // cp, cmd)
                    if fused:  # one compiled call: strokes, hydraulic step, forces (and friction, air springs)
                        pre_step(*pre_args)
                    elif one:  # one actuator (a uni-axial table): scalar copies, ~10x cheaper than a fancy index
                        x2[0, 0] = qpos[q0]
                        v2[0, 0] = qvel[d0]
                        f = hs.step(cmd2, x2, v2)
                        dctrl[i0] = f[0, 0]
                    else:
                        x2[0] = qpos[qa64]  # (int64 indices: a fancy index with MuJoCo's int32 ones is slower)
                        v2[0] = qvel[da64]
                        f = hs.step(cmd2, x2, v2)
                        dctrl[ids64] = f[0]
                    if clear_qfa:
                        qfa[:] = 0.0
                        for f, args in own_forces:
                            f(*args)
                    for e in effects:
                        e.apply(m, d)
                    t4 = clock()
                    step(m, d)
                    t5 = clock()
                    t_hyd += t4 - t3
                    t_phys += t5 - t4
                    if j == 0:
                        if free:
                            ACC[k] = qacc[pd : pd + 6]
                        elif fnd_d is not None:
                            ACC[k, :n_pd] = qacc[fnd_d] + qacc[slide_d]
                        else:
                            ACC[k, :n_pd] = qacc[slide_d]
                done = k + 1  # tick k is complete (kept even if the check below stops the run)
                if k % gap_every == 0 or k == n - 1:  # divergence checks (a call every gap_every ticks)
                    t6 = clock()
                    reason = self._diverged(k, w, rec.ex["loop_gap"])
                    t_out += clock() - t6
                    if reason:
                        break
                if progress and clock() - last_print > 0.25:
                    last_print = self._show_progress(k, n)
        except (KeyboardInterrupt, SystemError) as e:
            reason, interrupted = self._interrupted(e, done, n), True
        return Tally(done, reason, interrupted, t_ctrl=t_ctrl, t_hyd=t_hyd, t_phys=t_phys, t_out=t_out)

    def _diverged(self, k: int, io, gaps) -> str | None:
        """Why the run must stop after sample ``k`` (None: it goes on): the loop-closure gap,
        recorded in ``gaps``, and one compiled test of the state; the message only when it fails."""
        gap = self.loop_gap()
        gaps[k] = gap
        if gap <= GAP_LIMIT_M and self._fl_healthy(*io.health_args):
            return None
        return self._check(k / self.gains.rate_hz, gap)

    def _show_progress(self, k: int, n: int) -> float:
        """The progress bar on stderr after sample ``k`` of ``n``; returns when it was drawn."""
        now = time.perf_counter()
        frac = (k + 1) / n
        bar = "#" * int(30 * frac)
        sys.stderr.write(f"\r  [{bar:<30s}] {100 * frac:5.1f} %  t = {k / self.gains.rate_hz:7.2f} s")
        sys.stderr.flush()
        return now

    def _interrupted(self, e: BaseException, done: int, n: int) -> str:
        """The reason of a run stopped by Ctrl-C after ``done`` of ``n`` samples (re-raises
        ``e`` when it is not an interrupt: a SystemError is one when the Ctrl-C landed in a
        numba call)."""
        if not is_interrupt(e):
            raise e
        rate = self.gains.rate_hz
        return f"interrupted (Ctrl-C) at t = {done / rate:.4f} s of {n / rate:.4f} s"

    def _result(self, rec: Recording, tally: Tally, wall: float) -> RunResult:
        """The run's result from the ``tally.done`` samples recorded: the channels derived
        from the raw state (:func:`sim.loop.recorder.derive`), the hydraulic channels and
        the extras, with the timing of each part."""
        t7 = time.perf_counter()
        n_done, ex = tally.done, rec.ex
        ch = self._derive(rec.Q[:n_done], rec.V[:n_done], rec.ACC[:n_done])
        for key, arr in rec.H.items():
            ch[key] = arr[:n_done]
        for key in ex:
            ex[key] = ex[key][:n_done]
        if "_payload_qpos" in ch:
            ex["payload_qpos"] = ch.pop("_payload_qpos")
        t_post = time.perf_counter() - t7
        rate = self.gains.rate_hz
        return RunResult(
            t=np.arange(n_done) / rate,
            channels=ch,
            extras=ex,
            wall_s=wall + t_post,
            sim_s=n_done / rate,
            timing={
                "physics_s": tally.t_phys,
                "hydraulics_s": tally.t_hyd,
                "controller_s": tally.t_ctrl,
                "output_s": tally.t_out + t_post,
                "fused_s": tally.t_fused,
                "steps": n_done * self.steps_per_sample,
            },
            incomplete_reason=tally.reason,
            interrupted=tally.interrupted,
            force_lag_s=self.dt,
            valve_hold=self.valve_hold,
        )

    @property
    def valve_hold(self) -> np.ndarray:
        """Each valve's command at which it passes no flow: minus its null offset."""
        return -self.hp.per_actuator("valve_null_offset")

    def _derive(self, Q, V, ACC) -> dict:
        """Recorder channels from raw qpos/qvel/platen-qacc samples (:func:`sim.loop.recorder.derive`)."""
        return derive(self.tm, Q, V, ACC)

    def _check(self, tk: float, gap: float) -> str | None:
        """Why the run must stop at ``tk``, or None: a NaN/Inf in the mechanical or the
        hydraulic state, a swivel gap beyond :data:`GAP_LIMIT_M`, a pressure outside
        [vapour, relief] (the hydraulics clip to that range, so outside it means the step
        failed), a MuJoCo warning of :data:`MJ_WARNINGS` raised during the run, or an
        actuator beyond its stroke when the controller has a ``stroke_limit_m``. The
        message names the time, the quantity and the likely cause. (The loop tests all of
        this in one compiled call, :func:`sim.loop._kernels.healthy`, and comes here only
        when that fails.)"""
        d = self.d
        st = self.hs.state
        hp = self.hp
        lo, hi = self._pressure_limits()
        lim = self.controller.stroke_limit_m
        warned = [w for w, n0 in zip(MJ_WARNINGS, self._warn0) if d.warning[w].number > n0]
        at = f"simulation diverged at t = {tk:.4f} s"
        step = f"physics step {self.dt * 1e3:.3g} ms"
        for what, arr in (
            ("chamber a pressures", st.p_a),
            ("chamber b pressures", st.p_b),
            ("supply pressure", st.p_supply),
        ):
            if not np.all(np.isfinite(arr)):
                return (
                    f"{at}: the hydraulic state is not finite: NaN/Inf in the {what}; {CAUSE_STEP} "
                    f"(the oil columns are the stiffest part: check bulk modulus and dead volumes; {step})"
                )
        for what, arr in (("platen/linkage positions (qpos)", d.qpos), ("velocities (qvel)", d.qvel)):
            if not np.all(np.isfinite(arr)):
                return f"{at}: the mechanical state is not finite: NaN/Inf in the {what}; {CAUSE_STEP} ({step})"
        if warned:
            w = warned[0]
            return f"{at}: {MJ_WARNINGS[w]} (MuJoCo warning {w.name}); {CAUSE_STEP} ({step})"
        if lim is not None:
            x = d.qpos[self.tm.stroke_qadr]
            if np.any(np.abs(x) > lim):
                return (
                    f"{at}: an actuator left its stroke (|x| = {np.abs(x).max():.4g} m, half stroke {lim:.4g} m); "
                    f"likely cause: an unstable control loop (gains) or a motion beyond the stroke ({step})"
                )
        if gap > GAP_LIMIT_M:
            return (
                f"{at}: a swivel opened by {gap * 1e3:.3g} mm (limit {GAP_LIMIT_M * 1e3:.3g} mm): the "
                f"loop closure failed; {CAUSE_STEP} ({step}), or a motion beyond the linkages' reach"
            )
        # the chambers only: the supply sits between the accumulators' precharge and the relief
        # setting by construction (the hydraulics clip it), and its NaN is caught above
        for what, arr in (("chamber a", st.p_a), ("chamber b", st.p_b)):
            pmax, pmin = float(np.max(arr)), float(np.min(arr))
            if pmax > hi:
                return (
                    f"{at}: {what} pressure {pmax / 1e6:.4g} MPa above the relief pressure "
                    f"{hp.relief_pressure_pa / 1e6:.4g} MPa; {CAUSE_STEP} ({step})"
                )
            if pmin < lo:
                return (
                    f"{at}: {what} pressure {pmin / 1e6:.4g} MPa below the vapour pressure "
                    f"{hp.vapour_pressure_pa / 1e6:.4g} MPa; {CAUSE_STEP} ({step})"
                )
        return None


__all__ = ["Reference", "RunResult", "Simulation", "description_as_run", "reference_from_motions", "table_model"]
