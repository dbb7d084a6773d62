"""The model's flexible parts on the mechanical path: what stands on the platen on its own
joints (a declared shear frame's floors, a cantilever's segments, a rigid payload's
clamp, a description's ``payload_mode`` entries).

The mechanical path balances the recorded actuator forces against the declared model's
forces at the recorded motion. Its inertia is the effective mass at home
(:meth:`mjcf.model.TableModel.effective_mass_matrix`), which holds every body rigidly to
the platen. A body on its own spring does not move with the platen: the declared frame
of the worked example, counted rigid there and flexible on the replay, put its first mode
into the mechanical path's residual (the search added it a second time, 701.9 kg at
7.52 Hz, and the paths then disagreed: docs/lab-example-validation.md), and a calibrated
description's ``payload_mode`` entries read as added mass when it was calibrated again.

Here the parts on their own joints are the model's own linear system about home: their
coordinates ``q`` (the joints under the platen that a platen motion leaves still,
:func:`mjcf.analysis.projection`), mass ``M_qq``, coupling to the platen ``M_qp``,
stiffness ``K`` and damping ``C`` read from the compiled model (springs, tendons and
gravity, by finite differences of the passive and bias forces). With mass-normalised
modes ``phi_n`` (``K phi = w^2 M_qq phi``), modal damping ``phi^T C phi / 2 w`` (the
off-diagonal terms are dropped: classical damping) and participation
``L_n = phi_n^T M_qp``, the modal coordinate obeys ``eta'' + 2 z w eta' + w^2 eta =
-L_n a`` and the platen carries ``M_pq q'' = sum_n L_n^T eta_n''`` beyond the rigid
``M_pp a``; ``eta_n'' = (H_n - 1) L_n a`` with ``H_n`` the absolute-acceleration filter of
the ``payload_mode`` law (:func:`sim.calibrate.laws.payload_mode`'s basis: pre-warped
bilinear, interpolated). For one body of mass ``m`` on a slide this is ``m (H - 1) a``,
the law's ``m H a`` less the rigid ``m a`` the effective mass holds.

Each mode's frequency and damping are taken as the model's integrator steps them
(:func:`mjcf.stepping.stepped_mode`): the builder's clamps, ``payload_mode`` entries and
shear frames are set so that this is the declared mode; a cantilever's segments, on plain
springs with stiffness-proportional damping, step up to ``z w h / 2`` low, and the model's
records have them there.

Assumed: the platen's rotations drive the parts through their coupling at home only (a
floor's rocking by ``alpha h`` is in ``M_qp``; the frame's geometric stiffness under
rotation is not), and the parts start at rest at the record's start.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: finite-difference step of a joint coordinate (m or rad) and rate for K and C: the
#: parts are linear (springs, tendons, dampers), so the step only has to clear round-off
STEP = 1e-6
#: a mode whose participation ``|L_n|^2`` is below this share of the parts' total
#: (``diag(M_pq M_qq^-1 M_qp)``) is left out: it moves nothing the platen feels
MIN_SHARE = 1e-6


@dataclass(frozen=True)
class FlexibleParts:
    """The modes of the parts on their own joints: participation ``L`` (n_modes, k) in
    the platen's DOF units (kg^0.5, kg^0.5 m), frequency (Hz) and damping ratio each."""

    L: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray

    def force(self, a: np.ndarray, dt: float) -> np.ndarray:
        """(n, k) the generalised force the parts put on the platen beyond their rigid
        share, for the platen's acceleration ``a`` (n, k) sampled at ``dt``."""
        from sim.calibrate.laws import LAWS

        out = np.zeros_like(a, dtype=float)
        basis = LAWS["payload_mode"].basis
        for L, f, z in zip(self.L, self.frequency_hz, self.damping_ratio):
            g = a @ L  # the modal drive per unit modal coordinate
            h = basis(None, None, g, {"_dt": dt, "frequency_hz": float(f), "damping_ratio": float(z)})
            out += np.outer(np.asarray(h, float) - g, L)
        return out


def internal_dofs(model, T: np.ndarray) -> list[int]:
    """The DOFs of the joints under the platen that a platen motion leaves still (rows of
    ``T`` zero): what stands on the platen on its own joints."""
    import mujoco

    pid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "platen")
    out = []
    for j in range(model.njnt):
        if int(model.jnt_type[j]) not in (int(mujoco.mjtJoint.mjJNT_SLIDE), int(mujoco.mjtJoint.mjJNT_HINGE)):
            continue
        b, under = int(model.jnt_bodyid[j]), False
        while b > 0 and not under:
            b = int(model.body_parentid[b])
            under = b == pid
        dof = int(model.jnt_dofadr[j])
        if under and not np.any(T[dof]):
            out.append(dof)
    return out


def _passive_jacobians(model, data, dofs: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """(K, C) on ``dofs``: minus the derivative of the passive less the bias forces with
    respect to the coordinates and the rates, at ``data``'s state (home, at rest)."""
    import mujoco

    def load(d):
        mujoco.mj_forward(model, d)
        return (d.qfrc_passive - d.qfrc_bias)[dofs].copy()

    f0 = load(data)
    n = len(dofs)
    K, C = np.zeros((n, n)), np.zeros((n, n))
    qadr = {int(model.jnt_dofadr[j]): int(model.jnt_qposadr[j]) for j in range(model.njnt)}
    for i, dof in enumerate(dofs):
        d = mujoco.MjData(model)
        d.qpos[:], d.qvel[:] = data.qpos, data.qvel
        d.qpos[qadr[dof]] += STEP
        K[:, i] = -(load(d) - f0) / STEP
        d.qpos[:] = data.qpos
        d.qvel[dof] += STEP
        C[:, i] = -(load(d) - f0) / STEP
    return 0.5 * (K + K.T), 0.5 * (C + C.T)


def flexible_parts(tm, k_of) -> FlexibleParts | None:
    """The modes of ``tm``'s parts on their own joints, coupled to the platen DOFs
    ``k_of`` (indices into the model's platen DOFs); None when it has none."""

    from mjcf import analysis, stepping

    m = tm.model
    d = analysis.at_home(m)
    T = analysis.projection(m, d)[:, k_of]
    q = internal_dofs(m, T)
    if not q:
        return None
    M = analysis.full_mass_matrix(m, d)
    Mqq, Mqp = M[np.ix_(q, q)], M[q] @ T
    K, C = _passive_jacobians(m, d, q)
    w2, phi = _modes(K, Mqq)
    L = phi.T @ Mqp  # (n_modes, k)
    share = np.sum(L**2, axis=1) / max(float(np.sum(L**2)), 1e-300)
    keep = (w2 > 0) & (share >= MIN_SHARE)
    w = np.sqrt(w2[keep])
    z = np.einsum("in,ij,jn->n", phi[:, keep], C, phi[:, keep]) / (2.0 * w)
    f = w / (2 * np.pi)
    if stepping.damping_implicit(m.opt.integrator):  # each mode as the model steps it
        f, z = np.array([stepping.stepped_mode(fn, zn, float(m.opt.timestep)) for fn, zn in zip(f, z)]).T.reshape(2, -1)
    return FlexibleParts(L[keep], f, z)


def _modes(K: np.ndarray, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues ``w^2`` and mass-normalised shapes (columns) of ``K phi = w^2 M phi``."""
    from scipy.linalg import eigh

    w2, phi = eigh(K, M)
    return w2, phi
