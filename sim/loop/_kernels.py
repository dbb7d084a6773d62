"""Compiled pieces of the coupled loop (numba): everything between two ``mj_step`` calls.

``mj_step`` itself stays a Python call into MuJoCo; what runs around it is fused into one
compiled call per physics step (:func:`pre_step`: read strokes, hydraulic step, write
``ctrl``) and one per controller tick (:func:`record`, :func:`controller_tick`). The
plain-numpy versions in :mod:`sim.loop.simulation` and :mod:`sim.control.tvc` are the reference;
``tests/loop/test_loop.py`` checks that both paths give the same run.
"""

from __future__ import annotations

import numba
import numpy as np

from hydraulics import _layout as L
from hydraulics.system import _numba_kernel
from sim.control.tvc import _tick_guided as _ctrl_tick_guided
from sim.control.tvc import _tick_state as _ctrl_tick

_hyd = _numba_kernel()
_FORCE = L.FORCE

_OPTS = dict(cache=True, nogil=True, boundscheck=False)


@numba.njit(**_OPTS)
def pre_step(qpos, qvel, ctrl, qa, da, ids, cmd2, x2, v2, X, Y, IC, ICS, buf, head, P, G):
    """Strokes from MuJoCo -> hydraulic step -> forces into ``ctrl`` (one physics step)."""
    for i in range(qa.shape[0]):
        x2[0, i] = qpos[qa[i]]
        v2[0, i] = qvel[da[i]]
    _hyd(cmd2, x2, v2, X, Y, IC, ICS, buf, head, P, G)
    F = X[_FORCE]
    for i in range(ids.shape[0]):
        ctrl[ids[i]] = F[0, i]


@numba.njit(**_OPTS)
def pre_step_friction(
    qpos,
    qvel,
    ctrl,
    qa,
    da,
    ids,
    cmd2,
    x2,
    v2,
    X,
    Y,
    IC,
    ICS,
    buf,
    head,
    P,
    G,
    qfa,
    fr_dofs,
    fr_fc,
    zfr,
    zss,
    dt,
    aq,
    ad,
    aF0,
    ac,
    an,
):
    """:func:`pre_step` plus the pre-sliding friction and the air springs' nonlinear part
    into ``qfrc_applied`` (zeroed first)."""
    pre_step(qpos, qvel, ctrl, qa, da, ids, cmd2, x2, v2, X, Y, IC, ICS, buf, head, P, G)
    applied_forces(qpos, qvel, qfa, fr_dofs, fr_fc, zfr, zss, dt, aq, ad, aF0, ac, an)


@numba.njit(**_OPTS)
def applied_forces(qpos, qvel, qfa, fr_dofs, fr_fc, zfr, zss, dt, aq, ad, aF0, ac, an):
    """``qfrc_applied`` of one physics step: zeroed, then :func:`presliding_friction` and
    :func:`air_springs`."""
    qfa[:] = 0.0
    presliding_friction(qvel, qfa, fr_dofs, fr_fc, zfr, zss, dt)
    air_springs(qpos, qfa, aq, ad, aF0, ac, an)


@numba.njit(**_OPTS)
def air_springs(qpos, qfrc_applied, aq, ad, F0, c, n):
    """The static supports' air chambers beyond their linearisation.

    Chamber force at support displacement q (up = chamber expands): F0 (1 + c q)^-n with
    c = A / V0 (polytropic gas, preload F0 at home). MuJoCo's joint spring carries
    F0 - n F0 c q; this adds F0 ((1 + c q)^-n - 1 + n c q), second order in q (compression
    stiffens, suction softens the support)."""
    for i in range(aq.shape[0]):
        x = c * qpos[aq[i]]
        qfrc_applied[ad[i]] += F0[i] * ((1.0 + x) ** (-n) - 1.0 + n * x)


@numba.njit(**_OPTS)
def record(
    k, qpos, qvel, Q, V, X, Y, i_spool, i_force, i_pa, i_pb, H_spool, H_force, H_pa, H_pb, y_ps, y_gas, E_ps, E_gas
):
    """Copy the raw state at tick ``k`` into the recorder's arrays."""
    Q[k, :] = qpos
    V[k, :] = qvel
    na = H_spool.shape[1]
    for i in range(na):
        H_spool[k, i] = X[i_spool, 0, i]
        H_force[k, i] = X[i_force, 0, i]
        H_pa[k, i] = X[i_pa, 0, i]
        H_pb[k, i] = X[i_pb, 0, i]
    E_ps[k] = Y[y_ps, 0]
    E_gas[k] = Y[y_gas, 0]


@numba.njit(**_OPTS)
def presliding_friction(qvel, qfrc_applied, dofs, fc, z, zss, dt):
    """Dry friction with pre-sliding (Dahl form of LuGre with sigma1 = sigma2 = 0).

    Per friction coordinate with Coulomb level Fc and pre-sliding displacement zss:
    dz/dt = v - |v| z / zss, F = -(Fc / zss) z. Over a step z is advanced exactly for the
    velocity held (z -> sign(v) zss with rate |v| / zss), so the update is stable at any
    speed; at rest z (and the force) stays: the coordinate sticks elastically.
    """
    for i in range(dofs.shape[0]):
        v = qvel[dofs[i]]
        target = zss if v > 0.0 else (-zss if v < 0.0 else 0.0)
        if v != 0.0:
            z[i] = target + (z[i] - target) * np.exp(-abs(v) * dt / zss)
        qfrc_applied[dofs[i]] += -fc[i] / zss * z[i]


@numba.njit(**_OPTS)
def tick_first_step(
    k,
    qpos,
    qvel,
    xmat,
    ctrl,
    qfa,
    Q,
    V,
    H_spool,
    H_force,
    H_pa,
    H_pb,
    H_cmd,
    E_ps,
    E_gas,
    s_ref_all,
    v_ref_all,
    vff_all,
    qa,
    da,
    ids,
    pd,
    pb,
    consts,
    J,
    Jp,
    N,
    gains,
    cstate,
    pl_hp,
    pl_prev,
    cmd2,
    x2,
    v2,
    X,
    Y,
    IC,
    ICS,
    buf,
    P,
    G,
    fr_dofs,
    fr_fc,
    zfr,
    zss,
    dt,
    aq,
    ad,
    aF0,
    ac,
    an,
):
    """Everything between two ``mj_step`` calls at the start of controller tick ``k``, in
    one compiled call (each call from Python costs ~1 us plus ~0.1 us per argument):
    :func:`record`, the controller tick (:func:`sim.control.tvc._tick_state`) into
    ``cmd2`` and its row of ``H_cmd``, then :func:`pre_step` and, with friction
    coordinates, :func:`presliding_friction` and, with supports, :func:`air_springs`. Same
    operations in the same order as the separate calls, so the results are identical."""
    record(
        k, qpos, qvel, Q, V, X, Y, L.SPOOL, L.FORCE, L.PA, L.PB, H_spool, H_force, H_pa, H_pb, L.PS, L.GASV, E_ps, E_gas
    )
    cmd = cmd2[0]
    _ctrl_tick(
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
        X[L.FORCE, 0],
        Y[L.PS, 0],
        consts,
        J,
        Jp,
        N,
        gains,
        cstate,
        pl_hp,
        pl_prev,
        cmd,
    )
    H_cmd[k, :] = cmd
    pre_step(qpos, qvel, ctrl, qa, da, ids, cmd2, x2, v2, X, Y, IC, ICS, buf, 0, P, G)
    if fr_dofs.shape[0] or aq.shape[0]:
        applied_forces(qpos, qvel, qfa, fr_dofs, fr_fc, zfr, zss, dt, aq, ad, aF0, ac, an)


# fmt: off
@numba.njit(**_OPTS)
def tick_first_step_guided(
    k, qpos, qvel, ctrl, qfa, Q, V, H_spool, H_force, H_pa, H_pb, H_cmd, E_ps, E_gas, s_ref_all, v_ref_all, vff_all,
    qa, da, ids, slide_d, dof_i, consts, J, Jp, N, gains, cstate, pl_hp, pl_prev, cmd2, x2, v2, X, Y, IC, ICS, buf, P,
    G, fr_dofs, fr_fc, zfr, zss, dt, aq, ad, aF0, ac, an,
):
    """:func:`tick_first_step` of a bearing-guided platen: the controller reads the
    platen's velocity from its slides (``qvel[slide_d]`` at DOFs ``dof_i``,
    :func:`sim.control.tvc._tick_guided`) where a free platen's is read from its free
    joint and ``xmat``. The loop's stepwise tick on such a table (record, the controller's
    mode-0 tick, the pre-step and the applied forces) in its order, so the results are identical."""
    record(
        k, qpos, qvel, Q, V, X, Y, L.SPOOL, L.FORCE, L.PA, L.PB, H_spool, H_force, H_pa, H_pb, L.PS, L.GASV, E_ps, E_gas
    )
    cmd = cmd2[0]
    _ctrl_tick_guided(
        k, s_ref_all, v_ref_all, vff_all, qpos, qvel, qa, slide_d, dof_i, X[L.FORCE, 0], Y[L.PS, 0], consts, J, Jp, N,
        gains, cstate, pl_hp, pl_prev, cmd,
    )
    H_cmd[k, :] = cmd
    pre_step(qpos, qvel, ctrl, qa, da, ids, cmd2, x2, v2, X, Y, IC, ICS, buf, 0, P, G)
    if fr_dofs.shape[0] or aq.shape[0]:
        applied_forces(qpos, qvel, qfa, fr_dofs, fr_fc, zfr, zss, dt, aq, ad, aF0, ac, an)
# fmt: on


@numba.njit(**_OPTS)
def tick_first_step_open(
    k,
    qpos,
    qvel,
    ctrl,
    qfa,
    Q,
    V,
    H_spool,
    H_force,
    H_pa,
    H_pb,
    H_cmd,
    E_ps,
    E_gas,
    vc,
    qa,
    da,
    ids,
    cmd2,
    x2,
    v2,
    X,
    Y,
    IC,
    ICS,
    buf,
    P,
    G,
    fr_dofs,
    fr_fc,
    zfr,
    zss,
    dt,
    aq,
    ad,
    aF0,
    ac,
    an,
):
    """:func:`tick_first_step` of an open-loop replay: :func:`record`, the recorded valve
    command ``vc[k]`` into ``cmd2`` (held until the next tick) and its row of ``H_cmd``,
    then :func:`pre_step` and the applied forces. The operations of the loop's open-loop
    tick (``Simulation.run(valve_command=...)``) in its order, so the results are identical."""
    record(
        k, qpos, qvel, Q, V, X, Y, L.SPOOL, L.FORCE, L.PA, L.PB, H_spool, H_force, H_pa, H_pb, L.PS, L.GASV, E_ps, E_gas
    )
    for i in range(cmd2.shape[1]):
        cmd2[0, i] = vc[k, i]
        H_cmd[k, i] = vc[k, i]
    pre_step(qpos, qvel, ctrl, qa, da, ids, cmd2, x2, v2, X, Y, IC, ICS, buf, 0, P, G)
    if fr_dofs.shape[0] or aq.shape[0]:
        applied_forces(qpos, qvel, qfa, fr_dofs, fr_fc, zfr, zss, dt, aq, ad, aF0, ac, an)


@numba.njit(**_OPTS)
def later_step(
    k,
    qpos,
    qvel,
    qacc,
    ctrl,
    qfa,
    ACC,
    pd,
    qa,
    da,
    ids,
    cmd2,
    x2,
    v2,
    X,
    Y,
    IC,
    ICS,
    buf,
    P,
    G,
    fr_dofs,
    fr_fc,
    zfr,
    zss,
    dt,
    aq,
    ad,
    aF0,
    ac,
    an,
):
    """The pre-step of a tick's later physics steps; on the second one (``k >= 0``) it
    first records the platen acceleration of the tick's first step (still in ``qacc``)."""
    if k >= 0:
        for r in range(6):
            ACC[k, r] = qacc[pd + r]
    pre_step(qpos, qvel, ctrl, qa, da, ids, cmd2, x2, v2, X, Y, IC, ICS, buf, 0, P, G)
    if fr_dofs.shape[0] or aq.shape[0]:
        applied_forces(qpos, qvel, qfa, fr_dofs, fr_fc, zfr, zss, dt, aq, ad, aF0, ac, an)


__all__ = [
    "presliding_friction",
    "air_springs",
    "applied_forces",
    "pre_step_friction",
    "pre_step",
    "record",
    "loop_gap",
    "all_finite",
    "tick_first_step",
    "tick_first_step_open",
    "tick_first_step_guided",
    "later_step",
]


@numba.njit(**_OPTS)
def loop_gap(xpos, xmat, b1, b2, a1, a2):
    """Largest swivel opening over the connect equalities (m), from body poses."""
    worst = 0.0
    for i in range(b1.shape[0]):
        s = 0.0
        for r in range(3):
            p1 = (
                xpos[b1[i], r]
                + xmat[b1[i], 3 * r] * a1[i, 0]
                + xmat[b1[i], 3 * r + 1] * a1[i, 1]
                + xmat[b1[i], 3 * r + 2] * a1[i, 2]
            )
            p2 = (
                xpos[b2[i], r]
                + xmat[b2[i], 3 * r] * a2[i, 0]
                + xmat[b2[i], 3 * r + 1] * a2[i, 1]
                + xmat[b2[i], 3 * r + 2] * a2[i, 2]
            )
            s += (p1 - p2) ** 2
        if s > worst:
            worst = s
    return np.sqrt(worst)


@numba.njit(**_OPTS)
def all_finite(a, b, c, d):
    for x in (a.ravel(), b.ravel(), c.ravel(), d.ravel()):
        for v in x:
            if not np.isfinite(v):
                return False
    return True


@numba.njit(**_OPTS)
def healthy(qpos, qvel, p_a, p_b, p_supply, lo, hi, wnum, widx, w0, sq, slim):
    """The loop's divergence test in one call: MuJoCo's state finite, every chamber
    pressure in [lo, hi] (NaN fails), the supply pressure finite, no MuJoCo warning counter
    of ``widx`` above its start value ``w0`` (``wnum``: a view of ``mjData.warning.number``),
    and every stroke (qpos at ``sq``) within +/- ``slim``. False: the loop asks
    ``Simulation._check`` why."""
    for i in range(qpos.shape[0]):
        if not np.isfinite(qpos[i]):
            return False
    for i in range(qvel.shape[0]):
        if not np.isfinite(qvel[i]):
            return False
    for r in range(p_a.shape[0]):
        for c in range(p_a.shape[1]):
            if not (lo <= p_a[r, c] <= hi and lo <= p_b[r, c] <= hi):
                return False
    if not np.isfinite(p_supply[0]):
        return False
    for i in range(widx.shape[0]):
        if wnum[widx[i]] > w0[i]:
            return False
    for i in range(sq.shape[0]):
        if abs(qpos[sq[i]]) > slim:
            return False
    return True
