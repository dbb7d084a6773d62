"""The platen's kinematics: rotations of intrinsic x-y-z angles, the actuators' strokes at
a 6-DOF pose (inverse kinematics) and the corners of the rated motion box.
``mjcf.description`` re-exports them (their historical home)."""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from mjcf.description import TableDescription


def rotation_matrices(angles) -> np.ndarray:
    """(n, 3, 3) platen rotations for (n, 3) intrinsic x-y-z angles, R = Rx @ Ry @ Rz."""
    a = np.atleast_2d(np.asarray(angles, dtype=float))
    c, s = np.cos(a), np.sin(a)
    n = len(a)
    one, zero = np.ones(n), np.zeros(n)
    Rx = np.stack([one, zero, zero, zero, c[:, 0], -s[:, 0], zero, s[:, 0], c[:, 0]], axis=1).reshape(n, 3, 3)
    Ry = np.stack([c[:, 1], zero, s[:, 1], zero, one, zero, -s[:, 1], zero, c[:, 1]], axis=1).reshape(n, 3, 3)
    Rz = np.stack([c[:, 2], -s[:, 2], zero, s[:, 2], c[:, 2], zero, zero, zero, one], axis=1).reshape(n, 3, 3)
    return Rx @ Ry @ Rz


def rotation_matrix(rx: float, ry: float, rz: float) -> np.ndarray:
    """Platen rotation: intrinsic x-y-z angles, R = Rx(rx) @ Ry(ry) @ Rz(rz)."""
    return rotation_matrices([[rx, ry, rz]])[0]


def actuator_strokes(desc: TableDescription, pose) -> np.ndarray:
    """Inverse kinematics: 6-DOF pose of the reference point -> actuator strokes.

    Args:
        desc: the table.
        pose: (6,) [x, y, z, rx, ry, rz] in m and rad (intrinsic x-y-z angles), or
            (n, 6) for many poses.
    Returns:
        (n_act,) or (n, n_act) piston strokes from mid-stroke in m, + = extension.
    """
    pose = np.asarray(pose, dtype=float)
    single = pose.ndim == 1
    P = np.atleast_2d(pose)
    base = np.array([a.base_m for a in desc.actuators])
    plat = np.array([a.platen_m for a in desc.actuators])
    L0 = np.linalg.norm(plat - base, axis=1)
    out = np.empty((len(P), len(base)))
    for i0 in range(0, len(P), 8192):  # in blocks: (block, n_act, 3) temporaries stay small
        blk = P[i0 : i0 + 8192]
        pts = blk[:, None, :3] + plat @ rotation_matrices(blk[:, 3:6]).transpose(0, 2, 1)
        out[i0 : i0 + len(blk)] = np.linalg.norm(pts - base, axis=2) - L0
    return out[0] if single else out


def envelope_corners(desc: TableDescription) -> np.ndarray:
    """All corners of the rated motion box over the table's DOFs (m, rad), as 6-vectors."""
    from mjcf.description import DOFS6

    half = np.concatenate([desc.limits.stroke_m, desc.limits.rotation_rad])
    mask = np.array([d in desc.dofs for d in DOFS6], dtype=float)
    corners = np.array([np.array(s) * half * mask for s in itertools.product((-1.0, 1.0), repeat=6)])
    return np.unique(corners, axis=0)
