"""Vectorised numpy implementation of the hydraulic step (the reference backend).

Same equations as ``_kernel.step_loops``, written independently over whole
``(n_sim, n_act)`` arrays. Slower for one simulation, but readable and warning-free.
"""

from __future__ import annotations

import numpy as np

from ._kernel import NEWTON_ITERS
from ._layout import (
    C_CAV,
    C_RELIEF,
    CS_LOW,
    CS_PUMPSAT,
    FCUSH,
    FLOWA,
    FLOWB,
    FORCE,
    G_AIR,
    G_AIRN,
    G_CLINE,
    G_DL,
    G_DT,
    G_MODEL,
    G_NACC,
    G_ND,
    G_OLEAK,
    G_OV,
    G_PATM,
    G_PPRE,
    G_PREL,
    G_PSET,
    G_PT,
    G_PV,
    G_QMAX,
    G_SLEW,
    G_SQDL,
    G_SSET,
    G_V0,
    GASV,
    P_A1,
    P_AA,
    P_AB,
    P_BETA,
    P_F00,
    P_F01,
    P_F10,
    P_F11,
    P_G0,
    P_G1,
    P_H,
    P_K,
    P_KC,
    P_KCUSH,
    P_KE,
    P_LC,
    P_ND,
    P_U0,
    P_VDA,
    P_VDB,
    PA,
    PB,
    PS,
    QAT,
    QBT,
    QDEMAND,
    QPA,
    QPB,
    QPUMP,
    RATE,
    SPOOL,
    STORE,
    V_ACC_OUT,
    V_CAV_A,
    V_CAV_B,
    V_COMP_A,
    V_COMP_B,
    V_CROSS,
    V_DISP_A,
    V_DISP_B,
    V_EXT_A,
    V_EXT_B,
    V_IN_A,
    V_IN_B,
    V_OUT_A,
    V_OUT_B,
    V_PUMP,
    V_RELIEF_A,
    V_RELIEF_B,
    V_STORE_OUT,
    V_SUPPLY_CAV,
)


def land_flow_np(dp, dl, sqdl):
    a = np.abs(dp)
    turb = a >= dl
    sq = np.sqrt(np.maximum(a, dl))
    r = np.clip(dp / dl, -1.0, 1.0)
    q = np.where(turb, np.copysign(sq, dp), sqdl * r * (5.0 - r * r) * 0.25)
    g = np.where(turb, 0.5 / sq, (5.0 - 3.0 * r * r) * 0.25 / sqdl)
    return q, g


def inv_beta_np(p, beta, air, airn, patm):
    if air > 0.0:
        pp = np.maximum(p, 1.0e-3 * patm)
        return 1.0 / beta + air * (patm / pp) ** (1.0 / airn) / (airn * pp)
    return np.zeros_like(p) + 1.0 / beta  # beta: a scalar or per actuator


def store_of_p_np(p, cline, v0, ppre, nacc):
    s = cline * p
    if v0 > 0.0:
        pp = np.maximum(p, ppre)
        s = s + np.where(p > ppre, v0 * (1.0 - (ppre / pp) ** (1.0 / nacc)), 0.0)
    return s


def dstore_dp_np(p, cline, v0, ppre, nacc):
    c = np.full_like(p, cline)
    if v0 > 0.0:
        pp = np.maximum(p, ppre)
        c = c + np.where(p > ppre, v0 / nacc * (ppre / pp) ** (1.0 / nacc) / pp, 0.0)
    return c


def p_of_store_np(s, guess, cline, v0, ppre, nacc):
    lin = s / cline
    if v0 <= 0.0:
        return lin
    p = np.maximum(guess, ppre)
    for _ in range(NEWTON_ITERS):
        f = store_of_p_np(p, cline, v0, ppre, nacc) - s
        p = np.maximum(p - f / dstore_dp_np(p, cline, v0, ppre, nacc), ppre)
    return np.where(s <= cline * ppre, lin, p)


def step_numpy(cmd, xin, vin, X, Y, IC, ICS, buf, head, P, G):
    """One hydraulic step of every actuator of every simulation: servovalve, valve land
    flows, the chambers' pressures solved implicitly with the supply node, then the
    chambers' flows, relief, cavitation, volume balances and the actuator forces."""
    dt = G[G_DT]
    pv, prel, pt = G[G_PV], G[G_PREL], G[G_PT]
    oleak, dl, sqdl, ov = G[G_OLEAK], G[G_DL], G[G_SQDL], G[G_OV]
    K = P[P_K]

    # ---- servovalve: delay line, spool dynamics, slew, saturation
    yn = _servovalve_np(cmd, X, buf, head, P, G)

    op = np.maximum(yn - ov, 0.0) / (1.0 - ov)
    on = np.maximum(-yn - ov, 0.0) / (1.0 - ov)
    op = op + oleak * (1.0 - op)
    on = on + oleak * (1.0 - on)

    ps = Y[PS][:, None]
    pa = X[PA].copy()
    pb = X[PB].copy()
    q, g = land_flow_np(ps - pa, dl, sqdl)
    qpa, gpa = K * op * q, K * op * g
    q, g = land_flow_np(pa - pt, dl, sqdl)
    qat, gat = K * on * q, K * on * g
    q, g = land_flow_np(ps - pb, dl, sqdl)
    qpb, gpb = K * on * q, K * on * g
    q, g = land_flow_np(pb - pt, dl, sqdl)
    qbt, gbt = K * op * q, K * op * g

    h, aa, ab = P[P_H], P[P_AA], P[P_AB]
    kc, ke = P[P_KC], P[P_KE]
    xc = np.clip(xin, -h, h)
    va = P[P_VDA] + aa * (h + xc)
    vb = P[P_VDB] + ab * (h - xc)
    cva = va * inv_beta_np(pa, P[P_BETA], G[G_AIR], G[G_AIRN], G[G_PATM])
    cvb = vb * inv_beta_np(pb, P[P_BETA], G[G_AIR], G[G_AIRN], G[G_PATM])
    fa = qpa - qat - kc * (pa - pb) - ke * pa - aa * vin
    fb = qpb - qbt + kc * (pa - pb) - ke * pb + ab * vin
    m00 = cva / dt + gpa + gat + kc + ke
    m11 = cvb / dt + gpb + gbt + kc + ke
    det = m00 * m11 - kc * kc
    ua = (m11 * fa + kc * fb) / det
    ub = (kc * fa + m00 * fb) / det
    wa = (m11 * gpa + kc * gpb) / det
    wb = (kc * gpa + m00 * gpb) / det
    d0 = np.sum(qpa + qpb - gpa * ua - gpb * ub, axis=1)
    sig = np.sum(gpa * (1.0 - wa) + gpb * (1.0 - wb), axis=1)

    # ---- supply node
    ds = _supply_node_np(Y, ICS, d0, sig, G)

    # ---- chambers
    dsc = ds[:, None]
    dpa = ua + wa * dsc
    dpb = ub + wb * dsc
    qpa = qpa + gpa * (dsc - dpa)
    qat = qat + gat * dpa
    qpb = qpb + gpb * (dsc - dpb)
    qbt = qbt + gbt * dpb
    pan = pa + dpa
    pbn = pb + dpb
    X[V_EXT_A] += ke * pan * dt
    X[V_EXT_B] += ke * pbn * dt
    qc = kc * (pan - pbn)
    for pn, cv, vrel, vcav in ((pan, cva, V_RELIEF_A, V_CAV_A), (pbn, cvb, V_RELIEF_B, V_CAV_B)):
        hi = pn > prel
        lo = pn < pv
        X[vrel] += np.where(hi, (pn - prel) * cv, 0.0)
        X[vcav] += np.where(lo, (pv - pn) * cv, 0.0)
        IC[C_RELIEF] += hi
        IC[C_CAV] += lo
        np.clip(pn, pv, prel, out=pn)
    X[V_COMP_A] += cva * (pan - pa)
    X[V_COMP_B] += cvb * (pbn - pb)
    X[V_DISP_A] += aa * vin * dt
    X[V_DISP_B] -= ab * vin * dt
    X[V_IN_A] += qpa * dt
    X[V_OUT_A] += qat * dt
    X[V_IN_B] += qpb * dt
    X[V_OUT_B] += qbt * dt
    X[V_CROSS] += qc * dt
    X[QPA] = qpa
    X[QAT] = qat
    X[QPB] = qpb
    X[QBT] = qbt
    X[FLOWA] = qpa - qat
    X[FLOWB] = qpb - qbt
    X[PA] = pan
    X[PB] = pbn
    e = np.abs(xin) - (h - P[P_LC])
    fc = np.where(e > 0.0, -np.copysign(P[P_KCUSH] * np.maximum(e, 0.0), xin), 0.0)
    X[FCUSH] = fc
    X[FORCE] = pan * aa - pbn * ab + fc


def _servovalve_np(cmd, X, buf, head, P, G):
    """Servovalve: the command through each actuator's delay line, the spool's first- or
    second-order dynamics, slew limit and saturation; writes X[SPOOL], X[RATE] and
    returns the new spool position."""
    dt = G[G_DT]
    slew = G[G_SLEW]
    nd = int(G[G_ND])
    if nd > 0:
        ndi = P[P_ND].astype(np.int64)
        slot = (head + nd - ndi) % nd  # actuator i reads the command of ndi steps ago
        u = np.where(ndi > 0, buf[:, np.arange(buf.shape[1]), slot], cmd)
        buf[:, :, head] = cmd
    else:
        u = cmd
    u = u + P[P_U0]
    y = X[SPOOL]
    r = X[RATE]
    if G[G_MODEL] > 0.5:
        yn = P[P_F00] * y + P[P_F01] * r + P[P_G0] * u
        rn = P[P_F10] * y + P[P_F11] * r + P[P_G1] * u
    else:
        a1 = P[P_A1]
        yn = a1 * y + (1.0 - a1) * u
        rn = np.zeros_like(y)
    if slew > 0.0:
        lim = slew * dt
        yn = np.clip(yn, y - lim, y + lim)
        rn = np.clip(rn, -slew, slew)
    rn = np.where((yn > 1.0) & (rn > 0.0), 0.0, rn)
    rn = np.where((yn < -1.0) & (rn < 0.0), 0.0, rn)
    yn = np.clip(yn, -1.0, 1.0)
    if G[G_MODEL] < 0.5:
        rn = (yn - y) / dt
    X[SPOOL] = yn
    X[RATE] = rn
    return yn


def _supply_node_np(Y, ICS, d0, sig, G):
    """Supply node: the pump regulates the supply pressure to its set point where its flow
    is within [0, max]; otherwise the accumulator and line store take the difference
    (clamped at the vapour pressure). Updates Y and ICS; returns the supply pressure step."""
    dt = G[G_DT]
    pv = G[G_PV]
    pset, qmax = G[G_PSET], G[G_QMAX]
    v0, ppre, nacc, cline, sset = G[G_V0], G[G_PPRE], G[G_NACC], G[G_CLINE], G[G_SSET]
    ps1 = Y[PS].copy()
    sto = Y[STORE].copy()
    ds = pset - ps1
    dem = d0 + sig * ds
    qp = (sset - sto) / dt + dem
    reg = (qp >= 0.0) & (qp <= qmax)
    qp_c = np.clip(qp, 0.0, qmax)
    cs = dstore_dp_np(ps1, cline, v0, ppre, nacc)
    ds_c = (qp_c - d0) / (cs / dt + sig)
    dem_c = d0 + sig * ds_c
    sn_c = sto + (qp_c - dem_c) * dt
    smin = cline * pv
    low = (~reg) & (sn_c < smin)
    Y[V_SUPPLY_CAV] += np.where(low, smin - sn_c, 0.0)
    sn_c = np.where(low, smin, sn_c)
    psn_c = np.where(low, pv, p_of_store_np(sn_c, ps1 + ds_c, cline, v0, ppre, nacc))
    ICS[CS_PUMPSAT] += ~reg
    ICS[CS_LOW] += low
    ds = np.where(reg, ds, ds_c)
    dem = np.where(reg, dem, dem_c)
    qp = np.where(reg, qp, qp_c)
    snew = np.where(reg, sset, sn_c)
    psn = np.where(reg, pset, psn_c)
    if v0 > 0.0:
        pp = np.maximum(psn, ppre)
        gas = np.where(psn > ppre, v0 * (ppre / pp) ** (1.0 / nacc), v0)
    else:
        gas = np.zeros_like(psn)
    Y[V_ACC_OUT] += gas - Y[GASV]
    Y[V_STORE_OUT] += sto - snew
    Y[V_PUMP] += qp * dt
    Y[QPUMP] = qp
    Y[QDEMAND] = dem
    Y[STORE] = snew
    Y[PS] = psn
    Y[GASV] = gas
    return ds
