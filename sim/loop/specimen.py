"""Accelerometers on a specimen's floors: the run-file channel ``specimen_acceleration``
(docs/run-file.md) of a payload with floors (a lumped shear frame, ``type =
"shear_frame"``: floors on slides along the frame's direction, joined by the storey
springs and dampers as fixed tendons, ``mjcf.builder``).

A floor's accelerometer senses the force on the floor's mass per kilogram along its
axis. The only forces on a floor's slide are the frame's springs and dampers, so the
reading is exact from the recorded floor drifts and their rates:
``a_i = -(K q + C qdot)_i / m_i`` (K, C: the frame's stiffness and damping on the floor
coordinates, read from the compiled model's tendons; m_i: the floor's mass). On a level
platen that is the floor's absolute acceleration along the frame's direction, gravity
removed (as the ``accelerometers`` channel); on a tilting platen it also holds the tilt's
share of gravity, as a real accelerometer reads it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class SpecimenSensors:
    qadr: np.ndarray  # (n,) qpos addresses of the floors' slides
    dadr: np.ndarray  # (n,) dof addresses
    K: np.ndarray  # (n, n) N/m
    C: np.ndarray  # (n, n) N s/m
    mass: np.ndarray  # (n,) kg
    meta: list  # one {name, height_m, direction} per floor


def specimen_sensors(tm) -> SpecimenSensors | None:
    """The floors' sensors of ``tm``'s payload, None when it has no floors."""
    import mujoco

    info = getattr(tm, "info", None)
    pay = getattr(tm, "payload", None)
    if getattr(info, "payload_kind", None) != "shear_frame" or pay is None:
        return None
    m = tm.model
    jid = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n) for n in info.payload_joints]
    dadr = np.array([m.jnt_dofadr[j] for j in jid], int)
    qadr = np.array([m.jnt_qposadr[j] for j in jid], int)
    K = np.zeros((len(dadr), len(dadr)))
    C = np.zeros_like(K)
    for t in range(m.ntendon):
        J = _fixed_tendon_row(m, t, jid)
        if not np.any(J):
            continue
        K += float(m.tendon_stiffness[t].ravel()[0]) * np.outer(J, J)
        C += float(m.tendon_damping[t].ravel()[0]) * np.outer(J, J)
    K += np.diag([m.jnt_stiffness[j] for j in jid])
    C += np.diag([m.dof_damping[k] for k in dadr])
    mass = np.array([m.body_mass[m.jnt_bodyid[j]] for j in jid], float)
    direction, heights = frame_axis(pay), floor_heights(pay)
    meta = [{"name": f"F{i + 1}", "height_m": heights[i], "direction": direction} for i in range(len(jid))]
    return SpecimenSensors(qadr=qadr, dadr=dadr, K=K, C=C, mass=mass, meta=meta)


def floor_heights(payload) -> list[float]:
    """Heights (m above the platen's top surface) of a shear-frame payload's floors, or []:
    floor ``i`` (from 1) at ``base_m[2] + i * storey_height_m`` (``mjcf.builder``)."""
    from mjcf.description import ShearFramePayload

    if not isinstance(payload, ShearFramePayload):
        return []
    z0, h = float(payload.base_m[2]), float(payload.storey_height_m)
    return [z0 + (i + 1) * h for i in range(len(payload.mass_kg))]


def frame_axis(payload) -> list[float]:
    """The unit vector along which a shear frame's floors slide (its ``direction``, x or y)."""
    return [1.0, 0.0, 0.0] if getattr(payload, "direction", "x") == "x" else [0.0, 1.0, 0.0]


def _fixed_tendon_row(m, t: int, jid: list) -> np.ndarray:
    """A fixed tendon's length per unit of each of the joints ``jid`` (its wrap
    coefficients; 0 for a joint it does not wrap)."""
    import mujoco

    row = np.zeros(len(jid))
    for w in range(m.tendon_adr[t], m.tendon_adr[t] + m.tendon_num[t]):
        if int(m.wrap_type[w]) == int(mujoco.mjtWrap.mjWRAP_JOINT) and int(m.wrap_objid[w]) in jid:
            row[jid.index(int(m.wrap_objid[w]))] += float(m.wrap_prm[w])
    return row


def specimen_acceleration(sensors: SpecimenSensors, Q: np.ndarray, V: np.ndarray) -> np.ndarray:
    """(N, n_floors) the floors' accelerometer readings from qpos/qvel samples."""
    q = Q[:, sensors.qadr]
    qd = V[:, sensors.dadr]
    return -(q @ sensors.K.T + qd @ sensors.C.T) / sensors.mass[None, :]


__all__ = ["SpecimenSensors", "floor_heights", "frame_axis", "specimen_acceleration", "specimen_sensors"]
