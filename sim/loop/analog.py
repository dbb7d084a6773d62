"""The loop of a table with an analog controller acting at every physics step
(``[controller] type = "analog"``: seed 001's PIDF + dP controller, 8 kHz steps).

Same model (:func:`sim.effects.build_model`), hydraulics and coupling order as
:mod:`sim.loop.simulation` (hydraulic step before ``mj_step``, end-of-step pressures).
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass

import mujoco
import numpy as np

from hydraulics import HydraulicParams, HydraulicSystem
from mjcf.analysis import loop_gap
from mjcf.builder import BuildOptions
from mjcf.description import parse_table
from sim.control.analog import Conditioning, Gains, RiceController
from sim.effects import build_model

RICE_RATE_HZ = 8000.0  #: seed 001: the analog controller evaluated at every 1/8000 s physics step
RICE_FS_HZ = 4000.0  #: seed 001: the DAQ rate


def _apply_parameter_set(raw: dict, parameter_set: str, delay: bool, src: str):
    raw = copy.deepcopy(raw)
    ps = raw["controller"]["parameter_sets"][parameter_set]
    raw["fluid"]["bulk_modulus_pa"] = float(ps["beta_pa"])
    cls = raw["actuator_class"]["main"]
    cls["leakage_cross_m3_s_pa"] = float(ps["kle_m3_per_n_s"]) * float(cls["area_a_m2"])
    raw["servovalve"]["delay_s"] = float(ps["tau_s"]) if delay else 0.0
    desc = parse_table(raw, f"{src} [{parameter_set}{'' if delay else ', tau = 0'}]")
    return desc, float(ps["kt_m3_per_v_s"])


@dataclass
class RiceGains:
    """The Rice controller's settings for a scenario run: the paper's gains (Eq. 2), the
    parameter set (Tables 1-2) and the recorder rate (``rate_hz``: the run file's rate,
    the paper's 4000 Hz DAQ; the analog controller itself acts at every physics step)."""

    gains: Gains
    parameter_set: str
    rate_hz: float = RICE_FS_HZ
    physics_rate_hz: float = RICE_RATE_HZ
    delay: bool = True

    @classmethod
    def for_table(cls, desc, overrides: dict | None = None) -> "RiceGains":
        """The table's ``[controller]`` (type = "analog") with a scenario's overrides on top."""
        from sim.errors import ScenarioError

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
            raise ScenarioError(f"unknown rice controller key '{extra[0]}'; known: {', '.join(sorted(known))}")
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
        phys = float(c.get("rate_hz", RICE_RATE_HZ))
        rec = float(c.get("recorder_rate_hz", RICE_FS_HZ))
        if not (phys > 0 and rec > 0) or abs(phys / rec - round(phys / rec)) > 1e-9:
            raise ScenarioError(
                f"controller.recorder_rate_hz ({rec:g}) must divide the controller's physics rate rate_hz ({phys:g})"
            )
        return cls(gains=Gains(**kw), parameter_set=ps, rate_hz=rec, physics_rate_hz=phys)


def conditioning(raw: dict) -> Conditioning:
    """The transducer conditioning constants of a description's ``[controller]``."""
    c = raw["controller"]
    return Conditioning(float(c["k_x_cond_v_per_m"]), float(c["k_d_cond_v_per_m"]), float(c["k_dp_cond_v_per_pa"]))


def is_rice(desc) -> bool:
    """Does this table use the Rice controller (``[controller] type = "analog"``)?"""
    return (desc.raw.get("controller", {}) or {}).get("type") == "analog"


class RiceSimulation:
    """The Rice table (one actuator, foundation on springs) with its analog controller.

    The controller (:class:`sim.papers.rice.RiceController`, Eq. 2) acts at every physics step
    (``physics_rate_hz``, 8000 Hz); hydraulic step before ``mj_step`` as in ``sim/loop/simulation.py``.
    :meth:`steps` is the one stepping loop, used by the paper's FRF test
    (:func:`rice_simulation`) and by scenario runs (:meth:`run`, the interface of
    :class:`sim.loop.simulation.Simulation`: ``run(reference=...)`` -> :class:`sim.loop.simulation.RunResult`,
    ``gains.rate_hz``, ``hp``, ``tm``).
    """

    def __init__(
        self, desc, payload=None, gains: RiceGains | None = None, *, kt: float | None = None, backend: str = "numba"
    ):
        self.gains = gains or RiceGains.for_table(desc)
        if kt is None:  # the description's parameter set applied (beta, leakage, delay; k_t returned)
            desc, kt = _apply_parameter_set(desc.raw, self.gains.parameter_set, self.gains.delay, desc.source)
        self.desc = desc
        self.kt = kt
        self.tm = build_model(desc, payload, BuildOptions(timestep_s=1.0 / self.gains.physics_rate_hz))
        self.m = self.tm.model
        self.dt = float(self.m.opt.timestep)
        hp = HydraulicParams.from_table(desc.raw)
        for e in self.tm.effects:  # the effect lifecycle as in sim.loop.simulation.Simulation
            hp = e.edit_hydraulics(hp)
        self.hp = hp
        self.hs = HydraulicSystem(self.hp, n_sim=1, dt=self.dt, backend=backend)
        for e in self.tm.effects:
            e.bind(self.m, self.hs)
        self.q_full = float(self.hs.no_load_flow(1.0))
        self.ctl = RiceController(self.gains.gains, conditioning(desc.raw), kt, self.q_full, self.dt)
        self.steps_per_tick = int(round(self.gains.physics_rate_hz / self.gains.rate_hz))
        self.reset()

    def reset(self):
        tm = self.tm
        self.d = tm.new_data()
        for e in tm.effects:
            e.reset()
        self.hs.reset(tm.actuator_strokes(self.d)[None, :])
        self.d.ctrl[tm.actuator_ids] = self.hs.force[0]
        mujoco.mj_forward(self.m, self.d)
        self.ctl.reset()

    def steps(
        self, XD, VD, *, record_from: int = 0, every: int = 2, n_rec: int | None = None
    ) -> tuple[dict, str | None]:
        """Step through the per-step commands XD, VD (stroke reference m, m/s) and record
        every ``every``-th step from ``record_from`` on: the state at the step's start
        (stroke, stroke rate, absolute table displacement and velocity, pressures, spool,
        opening) and the acceleration of the step (absolute table, MuJoCo's qacc).
        Returns the records and why the run stopped early (None if it did not)."""
        tm, m, d, hs = self.tm, self.m, self.d, self.hs
        n_tot = len(XD)
        if n_rec is None:
            n_rec = max(0, (n_tot - record_from + every - 1) // every)
        x2 = np.zeros((1, 1))
        v2 = np.zeros((1, 1))
        c2 = np.zeros((1, 1))
        qs, ds = int(tm.stroke_qadr[0]), int(tm.stroke_dadr[0])
        jf = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "foundation_x")
        qf, df_ = int(m.jnt_qposadr[jf]), int(m.jnt_dofadr[jf])
        qp, dp_ = int(tm.platen_slide_qadr[0]), int(tm.platen_slide_dadr[0])
        aid = int(tm.actuator_ids[0])
        st = hs.state
        pa, pb, spool = st.p_a, st.p_b, st.spool
        qpos, qvel, qacc, ctrl = d.qpos, d.qvel, d.qacc, d.ctrl
        keys = (
            "a_table",
            "x_table",
            "v_table",
            "stroke",
            "stroke_rate",
            "dp",
            "opening",
            "p_a",
            "p_b",
            "spool",
            "force",
            "p_supply",
            "gas_volume",
        )
        rec = {k: np.full(n_rec, np.nan) for k in keys}
        step = mujoco.mj_step
        hstep = hs.step
        ctl = self.ctl
        half = tm.desc.actuators[0].cls.half_stroke_m
        effects = tm.step_effects
        qfa = d.qfrc_applied
        reason = None
        try:
            for k in range(n_tot):
                x = qpos[qs]
                v = qvel[ds]
                dpk = pa[0, 0] - pb[0, 0]
                j = k - record_from
                i = j // every if (j >= 0 and j % every == 0) else -1
                if 0 <= i < n_rec:
                    rec["x_table"][i] = qpos[qf] + qpos[qp]
                    rec["v_table"][i] = qvel[df_] + qvel[dp_]
                    rec["p_a"][i] = pa[0, 0]
                    rec["p_b"][i] = pb[0, 0]
                    rec["spool"][i] = spool[0, 0]
                    rec["p_supply"][i] = st.p_supply[0]
                    rec["gas_volume"][i] = st.gas_volume[0]
                u = ctl.opening(XD[k], VD[k], x, v, dpk)
                c2[0, 0] = u
                x2[0, 0] = x
                v2[0, 0] = v
                f = hstep(c2, x2, v2)
                ctrl[aid] = f[0, 0]
                if effects:
                    qfa[:] = 0.0
                    for e in effects:
                        e.apply(m, d)
                step(m, d)
                if 0 <= i < n_rec:
                    rec["a_table"][i] = qacc[df_] + qacc[dp_]
                    rec["stroke"][i] = x
                    rec["stroke_rate"][i] = v
                    rec["dp"][i] = dpk
                    rec["opening"][i] = u
                    rec["force"][i] = f[0, 0]
                if not math.isfinite(x) or abs(x) > half:
                    reason = (
                        f"simulation diverged at t = {k * self.dt:.4f} s: the Rice actuator left its stroke "
                        f"(x = {x:.4g} m); unstable loop?"
                    )
                    break
        except (KeyboardInterrupt, SystemError) as e:  # Ctrl-C: keep the samples so far (run() raises RunInterrupted)
            from sim.errors import is_interrupt

            if not is_interrupt(e):
                raise
            reason = f"interrupted (Ctrl-C) at t = {k * self.dt:.4f} s"
            self._interrupted = True
        return rec, reason

    def run(self, *, reference=None, duration_s: float | None = None, progress: bool = False, **_):
        """Closed loop on a 6-DOF :class:`sim.loop.simulation.Reference` at the recorder rate (its x
        column: the commanded table displacement, which the controller compares with the
        stroke, the paper's x_t). The reference is linearly interpolated to every physics
        step. Returns a :class:`sim.loop.simulation.RunResult` at the recorder rate."""
        from sim.loop.simulation import RunResult

        if reference is None:
            raise ValueError("the Rice simulation runs closed loop on a reference (no open-loop replay)")
        self.reset()
        rate = self.gains.rate_hz
        sub = self.steps_per_tick
        n = len(reference.t) if duration_s is None else min(len(reference.t), int(round(duration_s * rate)) + 1)
        tk = np.arange(n) / rate
        ts = np.arange(n * sub) * self.dt
        XD = np.interp(ts, tk, reference.d[:n, 0])
        VD = np.interp(ts, tk, reference.v[:n, 0])
        wall0 = time.perf_counter()
        self._interrupted = False
        rec, reason = self.steps(XD, VD, record_from=0, every=sub, n_rec=n)
        wall = time.perf_counter() - wall0
        done = int(np.argmax(~np.isfinite(rec["a_table"]))) if not np.all(np.isfinite(rec["a_table"])) else n
        done = max(done, 1)
        z = np.zeros((done, 6))
        D, V, A = z.copy(), z.copy(), z.copy()
        D[:, 0] = rec["x_table"][:done]
        V[:, 0] = rec["v_table"][:done]
        A[:, 0] = rec["a_table"][:done]
        accs = self.desc.accelerometers
        Dn = np.array([a.direction for a in accs]).reshape(-1, 3)
        col = lambda k: rec[k][:done, None].copy()  # noqa: E731
        ch = {
            "table_displacement": D,
            "table_velocity": V,
            "table_acceleration": A,
            "actuator_displacement": col("stroke"),
            "accelerometers": A[:, :3] @ Dn.T,
            "valve_command": col("opening"),
            "spool_position": col("spool"),
            "actuator_force": col("force"),
            "pressure_a": col("p_a"),
            "pressure_b": col("p_b"),
        }
        ex = {
            "supply_pressure": rec["p_supply"][:done].copy(),
            "accumulator_gas_volume": rec["gas_volume"][:done].copy(),
            "loop_gap": np.full(done, loop_gap(self.m, self.d)),
        }
        res = RunResult(
            t=np.arange(done) / rate,
            channels=ch,
            extras=ex,
            wall_s=wall,
            sim_s=done / rate,
            timing={"physics_s": wall, "hydraulics_s": 0.0, "controller_s": 0.0, "output_s": 0.0, "steps": done * sub},
            incomplete_reason=reason,
            interrupted=self._interrupted,
        )
        if self._interrupted:
            from sim.errors import RunInterrupted

            raise RunInterrupted(res)
        return res
