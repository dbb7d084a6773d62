"""The recorder's derived channels: poses, velocities and accelerometer signals from the
raw samples the loop copies (qpos, qvel, the platen's qacc), vectorised after the run.

A bearing-guided platen on a spring-mounted foundation (``[foundation] mode = "spring"``)
is recorded in absolute terms, as an accelerometer on it measures: its slide plus the
foundation's along the same axis (the loop records the acceleration that way too,
:func:`foundation_slides`); the actuator displacement stays the stroke (the LVDT).
"""

from __future__ import annotations

import mujoco
import numpy as np

from mjcf.description import DOFS6


def foundation_slides(tm):
    """(qpos addresses, dof addresses) of the foundation's slides along the guided platen's
    DOFs, or (None, None) when the platen is free or the foundation fixed."""
    if tm.platen_free:
        return None, None
    m = tm.model
    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"foundation_{DOFS6[i]}") for i in tm.platen_dof_index]
    if not ids or min(ids) < 0:
        return None, None
    return (
        np.array([m.jnt_qposadr[j] for j in ids], dtype=np.int64),
        np.array([m.jnt_dofadr[j] for j in ids], dtype=np.int64),
    )


def derive(tm, Q, V, ACC) -> dict:
    """Recorder channels of table model ``tm`` from raw qpos/qvel/platen-qacc samples
    (with ``specimen_acceleration`` for a payload with floors, :mod:`sim.loop.specimen`)."""
    from sim.loop.specimen import specimen_acceleration, specimen_sensors

    out = _derive_table(tm, Q, V, ACC)
    sp = specimen_sensors(tm)
    if sp is not None:
        out["specimen_acceleration"] = specimen_acceleration(sp, Q, V)
    return out


def _derive_table(tm, Q, V, ACC) -> dict:
    pq, pd = tm.platen_qadr, tm.platen_dadr
    if not tm.platen_free:
        n = len(Q)
        pose = np.zeros((n, 6))
        vel = np.zeros((n, 6))
        pose[:, tm.platen_dof_index] = Q[:, tm.platen_slide_qadr]
        vel[:, tm.platen_dof_index] = V[:, tm.platen_slide_dadr]
        fq, fd = foundation_slides(tm)
        if fq is not None:  # absolute motion: the foundation's slide plus the platen's on it
            pose[:, tm.platen_dof_index] = Q[:, fq] + Q[:, tm.platen_slide_qadr]
            vel[:, tm.platen_dof_index] = V[:, fd] + V[:, tm.platen_slide_dadr]
        acc = np.zeros((n, 6))
        acc[:, tm.platen_dof_index] = ACC[:, : len(tm.platen_dof_index)]
        out = {
            "table_displacement": pose,
            "table_velocity": vel,
            "table_acceleration": acc,
            "actuator_displacement": Q[:, tm.stroke_qadr].copy(),
        }
        accs = tm.desc.accelerometers
        Dn = np.array([a.direction for a in accs]).reshape(-1, 3)
        out["accelerometers"] = acc[:, :3] @ Dn.T  # no rotation: every point moves alike
        if len(tm.payload_dadr):
            qadr = [tm.model.jnt_qposadr[tm.model.dof_jntid[k]] for k in tm.payload_dadr]
            out["_payload_qpos"] = Q[:, qadr].copy()
        return out
    quat = Q[:, pq + 3 : pq + 7]
    w, x, y, z = quat.T
    # rotation matrices of the platen (rows of R for each sample)
    R = np.empty((len(Q), 3, 3))
    R[:, 0, 0] = 1 - 2 * (y * y + z * z)
    R[:, 0, 1] = 2 * (x * y - z * w)
    R[:, 0, 2] = 2 * (x * z + y * w)
    R[:, 1, 0] = 2 * (x * y + z * w)
    R[:, 1, 1] = 1 - 2 * (x * x + z * z)
    R[:, 1, 2] = 2 * (y * z - x * w)
    R[:, 2, 0] = 2 * (x * z - y * w)
    R[:, 2, 1] = 2 * (y * z + x * w)
    R[:, 2, 2] = 1 - 2 * (x * x + y * y)
    angles = np.stack(
        [
            np.arctan2(-R[:, 1, 2], R[:, 2, 2]),
            np.arcsin(np.clip(R[:, 0, 2], -1, 1)),
            np.arctan2(-R[:, 0, 1], R[:, 0, 0]),
        ],
        axis=1,
    )
    pose = np.concatenate([Q[:, pq : pq + 3], angles], axis=1)
    w_world = np.einsum("nij,nj->ni", R, V[:, pd + 3 : pd + 6])
    vel = np.concatenate([V[:, pd : pd + 3], w_world], axis=1)
    alin = ACC[:, :3]
    aang = np.einsum("nij,nj->ni", R, ACC[:, 3:6])
    acc = np.concatenate([alin, aang], axis=1)
    out = {
        "table_displacement": pose,
        "table_velocity": vel,
        "table_acceleration": acc,
        "actuator_displacement": Q[:, tm.stroke_qadr].copy(),
    }
    accs = tm.desc.accelerometers
    if accs:
        P = np.array([a.position_m for a in accs])
        Dn = np.array([a.direction for a in accs])
        r = np.einsum("nij,aj->nai", R, P)  # sensor offsets in world
        a_site = (
            alin[:, None, :]
            + np.cross(aang[:, None, :], r)
            + np.cross(w_world[:, None, :], np.cross(w_world[:, None, :], r))
        )
        dirs = np.einsum("nij,aj->nai", R, Dn)  # sensor axes in world
        out["accelerometers"] = np.einsum("nai,nai->na", a_site, dirs)
    else:
        out["accelerometers"] = np.zeros((len(Q), 0))
    # payload coordinates (for drawing a flexible payload): qpos of its joints
    if len(tm.payload_dadr):
        qadr = [tm.model.jnt_qposadr[tm.model.dof_jntid[k]] for k in tm.payload_dadr]
        out["_payload_qpos"] = Q[:, qadr].copy()
    return out


__all__ = ["derive", "foundation_slides"]
