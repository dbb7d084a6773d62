"""``TableModel``: the compiled table with named accessors (no raw indices elsewhere)."""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from mjcf import analysis
from mjcf.description import DOFS6, Payload, TableDescription, rotation_matrix


def quat_to_xyz(q: np.ndarray) -> np.ndarray:
    """Intrinsic x-y-z angles (rx, ry, rz) of a unit quaternion (w, x, y, z).

    Inverse of :func:`mjcf.description.rotation_matrix`: R = Rx(rx) Ry(ry) Rz(rz).
    """
    R = np.zeros(9)
    mujoco.mju_quat2Mat(R, q)
    R = R.reshape(3, 3)
    ry = np.arcsin(np.clip(R[0, 2], -1.0, 1.0))
    rx = np.arctan2(-R[1, 2], R[2, 2])
    rz = np.arctan2(-R[0, 1], R[0, 0])
    return np.array([rx, ry, rz])


def xyz_to_quat(rx: float, ry: float, rz: float) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, rotation_matrix(rx, ry, rz).flatten())
    return q


@dataclass
class TableModel:
    """A compiled table scene and the indices that name its parts."""

    desc: TableDescription
    payload: Payload | None
    spec: mujoco.MjSpec
    model: mujoco.MjModel
    info: object
    _idx: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        m = self.model
        jid = lambda n: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)  # noqa: E731
        names = self.desc.actuator_names
        self.actuator_names = names
        self.n_act = len(names)
        self.stroke_qadr = np.array([m.jnt_qposadr[jid(f"{n}_stroke")] for n in names])
        self.stroke_dadr = np.array([m.jnt_dofadr[jid(f"{n}_stroke")] for n in names])
        self.actuator_ids = np.array([mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in names])
        pj = jid("platen")
        self.platen_free = pj >= 0
        if self.platen_free:
            self.platen_qadr = m.jnt_qposadr[pj]
            self.platen_dadr = m.jnt_dofadr[pj]
            self.platen_dof_index = np.arange(6)
            self.platen_slide_qadr = self.platen_slide_dadr = np.zeros(0, dtype=int)
        else:  # platen on bearings: one slide per translational DOF
            dofs = [d for d in ("x", "y", "z") if jid(f"platen_{d}") >= 0]
            self.platen_dof_index = np.array([("x", "y", "z").index(d) for d in dofs], dtype=int)
            self.platen_slide_qadr = np.array([m.jnt_qposadr[jid(f"platen_{d}")] for d in dofs], dtype=int)
            self.platen_slide_dadr = np.array([m.jnt_dofadr[jid(f"platen_{d}")] for d in dofs], dtype=int)
            self.platen_qadr = int(self.platen_slide_qadr[0])
            self.platen_dadr = int(self.platen_slide_dadr[0])
        self.platen_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "platen")
        self.acc_sites = np.array(
            [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_SITE, f"acc_{a.name}") for a in self.desc.accelerometers],
            dtype=int,
        )
        self.home_key = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_KEY, "home")
        self.support_names = (
            [f"S{i + 1}" for i in range(len(self.desc.supports.positions_m))] if self.desc.supports else []
        )
        self.support_qadr = np.array([m.jnt_qposadr[jid(f"{s}_air")] for s in self.support_names], dtype=int)
        fj = list(getattr(self.info, "friction_joints", []))
        self.friction_dofs = np.array([m.jnt_dofadr[jid(n)] for n in fj], dtype=np.int64)
        self.friction_force = np.array(getattr(self.info, "friction_force_n", []), dtype=float)
        self.friction_presliding_m = self.desc.friction_presliding_m
        # static supports' air chambers beyond their linear part (sim.loop._kernels.air_springs):
        # preload F0, A / V0 and the exponent n per support
        aj = list(getattr(self.info, "air_joints", []))
        self.air_qadr = np.array([m.jnt_qposadr[jid(n)] for n in aj], dtype=np.int64)
        self.air_dadr = np.array([m.jnt_dofadr[jid(n)] for n in aj], dtype=np.int64)
        loads = np.asarray(getattr(self.info, "support_loads_n", np.zeros(0)), dtype=float)
        self.air_preload = loads[: len(aj)].copy() if aj else np.zeros(0)
        sp = self.desc.supports
        self.air_area_over_volume = sp.piston_area_m2 / sp.chamber_volume_m3 if aj else 0.0
        self.air_exponent = sp.polytropic_exponent if aj else 1.0
        self.step_effects = list(getattr(self.info, "step_effects", []))
        self.effects = list(getattr(self.info, "effects", []))  # bound by the loop (with its hydraulics)
        self.payload_dadr = np.array(
            [m.jnt_dofadr[jid(n)] for n in getattr(self.info, "payload_joints", [])], dtype=int
        )

    # ------------------------------------------------------------------ data
    def new_data(self) -> mujoco.MjData:
        """MjData at the home keyframe, forward-evaluated."""
        d = mujoco.MjData(self.model)
        if self.home_key >= 0:
            mujoco.mj_resetDataKeyframe(self.model, d, self.home_key)
        mujoco.mj_forward(self.model, d)
        return d

    def actuator_strokes(self, d: mujoco.MjData) -> np.ndarray:
        """(n_act,) piston strokes from mid-stroke, m, + = extension."""
        return d.qpos[self.stroke_qadr].copy()

    def actuator_velocities(self, d: mujoco.MjData) -> np.ndarray:
        return d.qvel[self.stroke_dadr].copy()

    def set_actuator_forces(self, d: mujoco.MjData, force: np.ndarray) -> None:
        d.ctrl[self.actuator_ids] = force

    def platen_pose(self, d: mujoco.MjData) -> np.ndarray:
        """(6,) reference-point pose: x, y, z (m) and intrinsic x-y-z angles (rad)."""
        if not self.platen_free:
            out = np.zeros(6)
            out[self.platen_dof_index] = d.qpos[self.platen_slide_qadr]
            return out
        q = d.qpos[self.platen_qadr : self.platen_qadr + 7]
        return np.concatenate([q[:3], quat_to_xyz(q[3:7])])

    def _platen_rate(self, d: mujoco.MjData, vec: np.ndarray) -> np.ndarray:
        """A platen DOF rate (qvel or qacc) as (6,): linear in world, angular in world frame.

        A free joint's angular part is in the platen frame; R turns it to world (for the
        acceleration too: d/dt(R w) = R dw/dt since w x w = 0)."""
        if not self.platen_free:
            out = np.zeros(6)
            out[self.platen_dof_index] = vec[self.platen_slide_dadr]
            return out
        v = vec[self.platen_dadr : self.platen_dadr + 6]
        R = d.xmat[self.platen_body].reshape(3, 3)
        return np.concatenate([v[:3], R @ v[3:6]])

    def platen_velocity(self, d: mujoco.MjData) -> np.ndarray:
        """(6,) reference-point velocity: linear (world) and angular (world frame)."""
        return self._platen_rate(d, d.qvel)

    def platen_acceleration(self, d: mujoco.MjData) -> np.ndarray:
        """(6,) reference-point acceleration of the last step (linear world, angular world)."""
        return self._platen_rate(d, d.qacc)

    def set_platen_pose(self, d: mujoco.MjData, pose) -> float:
        """Put the platen at ``pose`` (6,) and close every loop; returns the residual (m)."""
        pose = np.asarray(pose, dtype=float)
        if not self.platen_free:
            d.qpos[self.platen_slide_qadr] = pose[self.platen_dof_index]
            err = analysis.settle_loops(self.model, d)
            mujoco.mj_forward(self.model, d)
            return err
        d.qpos[self.platen_qadr : self.platen_qadr + 3] = pose[:3]
        d.qpos[self.platen_qadr + 3 : self.platen_qadr + 7] = xyz_to_quat(*pose[3:6])
        err = analysis.settle_loops(self.model, d)
        mujoco.mj_forward(self.model, d)
        return err

    def loop_gap(self, d: mujoco.MjData) -> float:
        return analysis.loop_gap(self.model, d)

    # ------------------------------------------------------------------ analysis
    def effective_mass_matrix(self) -> np.ndarray:
        return analysis.effective_mass_matrix(self.model)

    def effective_mass(self) -> dict[str, float]:
        """Diagonal of the effective mass about the reference point, by DOF name."""
        Me = self.effective_mass_matrix()
        names = DOFS6
        return {names[j]: float(Me[i, i]) for i, j in enumerate(self.platen_dof_index)}

    def total_mass(self) -> float:
        return float(self.model.body_mass.sum())

    def moving_mass(self) -> float:
        """Mass of everything but the world and a spring-mounted foundation."""
        m = self.model
        fid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "foundation")
        tot = float(m.body_mass.sum())
        return tot - (float(m.body_mass[fid]) if fid >= 0 else 0.0)
