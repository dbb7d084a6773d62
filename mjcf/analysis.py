"""Model analysis on the compiled MuJoCo model: loop Jacobians, effective mass,
static equilibrium of the supports, pose setting by closing the loops, loop gaps.

The closed loops (linkages and supports pinned to the platen) make every linkage and
support coordinate a function of the platen pose. With ``J_eq`` the Jacobian of the
``connect`` equalities split into platen columns ``J_p`` and loop columns ``J_o``
(square: each linkage has 3 coordinates and 3 constraints, each support too), the loop
velocities follow from the platen velocity as ``qdot_o = -J_o^-1 J_p v``; the projection
``T = [I; -J_o^-1 J_p]`` carries the full mass matrix onto the 6 platen DOF:
``M_eff = T^T M T`` (mass matrix from ``mj_fullM``; MuJoCo 4 has no ``MjData.qM``).
"""

from __future__ import annotations

import mujoco
import numpy as np


def connect_rows(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
    """Residuals (3 n_eq,) and Jacobian (3 n_eq, nv) of every active ``connect`` equality.

    Needs ``mj_kinematics`` and ``mj_comPos`` (or ``mj_forward``) on ``data``.
    """
    ids = [i for i in range(model.neq) if model.eq_type[i] == mujoco.mjtEq.mjEQ_CONNECT]
    r = np.zeros(3 * len(ids))
    J = np.zeros((3 * len(ids), model.nv))
    jp1 = np.zeros((3, model.nv))
    jp2 = np.zeros((3, model.nv))
    for k, i in enumerate(ids):
        b1, b2 = model.eq_obj1id[i], model.eq_obj2id[i]
        p1 = data.xpos[b1] + data.xmat[b1].reshape(3, 3) @ model.eq_data[i, 0:3]
        p2 = data.xpos[b2] + data.xmat[b2].reshape(3, 3) @ model.eq_data[i, 3:6]
        mujoco.mj_jac(model, data, jp1, None, p1, b1)
        mujoco.mj_jac(model, data, jp2, None, p2, b2)
        r[3 * k : 3 * k + 3] = p1 - p2
        J[3 * k : 3 * k + 3] = jp1 - jp2
    return r, J


def loop_gap(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    """Largest swivel/pin opening (m) over all connect equalities, from current positions."""
    ids = [i for i in range(model.neq) if model.eq_type[i] == mujoco.mjtEq.mjEQ_CONNECT]
    worst = 0.0
    for i in ids:
        b1, b2 = model.eq_obj1id[i], model.eq_obj2id[i]
        p1 = data.xpos[b1] + data.xmat[b1].reshape(3, 3) @ model.eq_data[i, 0:3]
        p2 = data.xpos[b2] + data.xmat[b2].reshape(3, 3) @ model.eq_data[i, 3:6]
        worst = max(worst, float(np.linalg.norm(p1 - p2)))
    return worst


def loop_dofs(model: mujoco.MjModel) -> np.ndarray:
    """DOF indices of the linkage and support coordinates (closed by the loops)."""
    out = []
    for j in range(model.njnt):
        name = mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j) or ""
        if name.endswith(("_swivel_u", "_swivel_v", "_stroke", "_air", "_shoe_x", "_shoe_y")):
            out.append(model.jnt_dofadr[j])
    return np.array(sorted(out), dtype=int)


def platen_dofs(model: mujoco.MjModel) -> np.ndarray:
    """DOF indices of the platen: its free joint (6) or its bearing slides (platen_x, ...)."""
    j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "platen")
    if j >= 0:
        a = model.jnt_dofadr[j]
        return np.arange(a, a + 6)
    out = []
    for dof in ("x", "y", "z"):
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"platen_{dof}")
        if j >= 0:
            out.append(model.jnt_dofadr[j])
    return np.array(out, dtype=int)


def projection(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    """T (nv, n_p): all joint velocities produced by a unit platen velocity, loops closed.

    Columns are the platen's free-joint velocities (linear in world, angular in the
    platen frame; identical at the home pose). Payload and foundation coordinates are
    held (they move with the platen rigidly / stay put).
    """
    _, J = connect_rows(model, data)
    pd = platen_dofs(model)
    od = loop_dofs(model)
    Jo = J[:, od]
    Jp = J[:, pd]
    if Jo.shape[0] != Jo.shape[1]:
        raise ValueError(f"loop Jacobian is {Jo.shape}, expected square")
    T = np.zeros((model.nv, len(pd)))
    T[pd, :] = np.eye(len(pd))
    if len(od):
        T[od, :] = -np.linalg.solve(Jo, Jp)
    return T


def full_mass_matrix(model: mujoco.MjModel, data: mujoco.MjData) -> np.ndarray:
    M = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, M)
    return M


def at_home(model: mujoco.MjModel) -> mujoco.MjData:
    """Data at the model's ``home`` keyframe (its reset state without one), forwarded."""
    data = mujoco.MjData(model)
    key = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_KEY, "home")
    if key >= 0:
        mujoco.mj_resetDataKeyframe(model, data, key)
    mujoco.mj_forward(model, data)
    return data


def effective_mass_matrix(model: mujoco.MjModel, data: mujoco.MjData | None = None) -> np.ndarray:
    """Effective mass of the platen DOF about the reference point (kg, kg m^2): 6x6 for a
    free platen, n x n for a platen on bearings with n translational DOF."""
    data = at_home(model) if data is None else data
    mujoco.mj_forward(model, data)
    M = full_mass_matrix(model, data)
    T = projection(model, data)
    return T.T @ M @ T


def static_balance(model: mujoco.MjModel, force_dofs, qpos=None) -> np.ndarray:
    """Generalised forces on ``force_dofs`` that hold a pose against gravity (N or N m).

    Solves ``qfrc_bias = J_eq^T lambda + S f`` over the platen and loop coordinates by
    least squares (minimum norm where the supports/actuators are redundant); raises if
    the balance cannot be met (residual above 1e-6 of the load).
    """
    data = mujoco.MjData(model)
    if qpos is not None:
        data.qpos[:] = qpos
    mujoco.mj_forward(model, data)
    _, J = connect_rows(model, data)
    rows = np.concatenate([platen_dofs(model), loop_dofs(model)])
    S = np.zeros((model.nv, len(force_dofs)))
    for i, d in enumerate(force_dofs):
        S[d, i] = 1.0
    A = np.hstack([J.T, S])[rows]
    b = (data.qfrc_bias - data.qfrc_passive)[rows]  # gravity less the springs (supports)
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    res = np.abs(A @ x - b).max()
    if res > 1e-6 * max(np.abs(b).max(), 1.0):
        raise ValueError(f"static balance not met (residual {res:.3g} N)")
    return x[-len(force_dofs) :]


def support_preloads(model: mujoco.MjModel, desc) -> np.ndarray:
    """Vertical force (N, upward) each static support must give to hold the home pose.

    Solves the static balance ``qfrc_bias = J_eq^T lambda + S f`` over the platen and
    loop coordinates (gravity only, zero velocity, zero actuator force) by least
    squares; with four supports and three vertical platen DOF the minimum-norm solution
    is taken. Raises if the balance cannot be met (residual above 1e-6 of the weight).
    """
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    _, J = connect_rows(model, data)
    rows = np.concatenate([platen_dofs(model), loop_dofs(model)])
    n_sup = len(desc.supports.positions_m)
    S = np.zeros((model.nv, n_sup))
    for i in range(n_sup):
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"S{i + 1}_air")
        S[model.jnt_dofadr[j], i] = 1.0
    A = np.hstack([J.T, S])[rows]
    b = data.qfrc_bias[rows]
    x, *_ = np.linalg.lstsq(A, b, rcond=None)
    res = np.abs(A @ x - b).max()
    weight = np.abs(b).max()
    if res > 1e-6 * max(weight, 1.0):
        raise ValueError(f"static support balance not met (residual {res:.3g} N)")
    return x[-n_sup:]


def settle_loops(model: mujoco.MjModel, data: mujoco.MjData, *, tol: float = 1e-12, max_iter: int = 30) -> float:
    """Close every loop for the current platen pose by Newton steps on the loop coordinates.

    Moves only the linkage and support coordinates (the platen stays where it was put);
    returns the final largest residual in m.
    """
    od = loop_dofs(model)
    # loop joints are all 1-DOF: qpos address of each dof
    qadr = np.array([model.jnt_qposadr[model.dof_jntid[d]] for d in od])
    err = np.inf
    for _ in range(max_iter):
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        r, J = connect_rows(model, data)
        err = float(np.abs(r).max()) if len(r) else 0.0
        if err < tol:
            break
        dq = np.linalg.solve(J[:, od], -r)
        data.qpos[qadr] += dq
    return err


def linear_modes(
    model: mujoco.MjModel, dofs: np.ndarray, *, gravity: bool = True, qpos: np.ndarray | None = None, eps: float = 1e-6
) -> tuple[np.ndarray, np.ndarray]:
    """Natural frequencies (Hz) and mode shapes of the coordinates ``dofs``, others held.

    Mass from ``mj_fullM``; stiffness by central differences of the passive force
    (joint and tendon springs) and, with ``gravity``, of the gravity force, around
    ``qpos`` (default: the model's qpos0). Only 1-DOF joints may be listed.
    """
    d = mujoco.MjData(model)
    d.qpos[:] = model.qpos0 if qpos is None else qpos
    mujoco.mj_forward(model, d)
    M = full_mass_matrix(model, d)[np.ix_(dofs, dofs)]
    qadr = np.array([model.jnt_qposadr[model.dof_jntid[k]] for k in dofs])

    def force(q):
        d.qpos[qadr] = q
        d.qvel[:] = 0
        mujoco.mj_forward(model, d)
        f = d.qfrc_passive.copy()
        if gravity:
            f -= d.qfrc_bias
        return f[dofs]

    q0 = d.qpos[qadr].copy()
    K = np.zeros((len(dofs), len(dofs)))
    for k in range(len(dofs)):
        dq = np.zeros(len(dofs))
        dq[k] = eps
        K[:, k] = -(force(q0 + dq) - force(q0 - dq)) / (2 * eps)
    d.qpos[qadr] = q0
    K = 0.5 * (K + K.T)
    L = np.linalg.cholesky(M)
    Li = np.linalg.inv(L)
    w2, y = np.linalg.eigh(Li @ K @ Li.T)
    return np.sqrt(np.clip(w2, 0, None)) / (2 * np.pi), Li.T @ y
