"""The hydraulic step as scalar loops (compiled by numba; see system.py for the algorithm).

``step_loops`` is plain Python that numba compiles with ``cache=True``; the numpy backend
in ``_numpy_step.py`` is an independent vectorised implementation of the same equations,
used as the reference.
"""

from __future__ import annotations

import math

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
    S_CA,
    S_CB,
    S_GAT,
    S_GBT,
    S_GPA,
    S_GPB,
    S_UA,
    S_UB,
    S_WA,
    S_WB,
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

NEWTON_ITERS = 8


def land_flow(dp, dl, sqdl):
    """Normalised land flow g(dp) and its slope g'(dp).

    g = sign(dp) sqrt(|dp|) for |dp| >= dl; inside, the odd cubic
    g = sqrt(dl) r (5 - r^2) / 4, r = dp/dl, which matches value and slope at |dp| = dl
    (C1) and has the finite slope 5 / (4 sqrt(dl)) at dp = 0.
    """
    a = abs(dp)
    if a >= dl:
        sq = math.sqrt(a)
        if dp >= 0.0:
            return sq, 0.5 / sq
        return -sq, 0.5 / sq
    r = dp / dl
    return sqdl * r * (5.0 - r * r) * 0.25, (5.0 - 3.0 * r * r) * 0.25 / sqdl


def inv_beta(p, beta, air, airn, patm):
    """1 / effective bulk modulus (entrained-air model when air > 0)."""
    if air > 0.0:
        pp = p if p > 1.0e-3 * patm else 1.0e-3 * patm
        return 1.0 / beta + air * (patm / pp) ** (1.0 / airn) / (airn * pp)
    return 1.0 / beta


def store_of_p(p, cline, v0, ppre, nacc):
    """Oil stored in the supply node at pressure p (line compression + accumulator oil)."""
    s = cline * p
    if v0 > 0.0 and p > ppre:
        s += v0 * (1.0 - (ppre / p) ** (1.0 / nacc))
    return s


def dstore_dp(p, cline, v0, ppre, nacc):
    c = cline
    if v0 > 0.0 and p > ppre:
        c += v0 / nacc * (ppre / p) ** (1.0 / nacc) / p
    return c


def p_of_store(s, guess, cline, v0, ppre, nacc):
    """Inverse of store_of_p (s >= cline * ppre branch by Newton; concave => monotone)."""
    if v0 <= 0.0 or s <= cline * ppre:
        return s / cline
    p = guess if guess > ppre else ppre
    for _ in range(NEWTON_ITERS):
        f = store_of_p(p, cline, v0, ppre, nacc) - s
        p = p - f / dstore_dp(p, cline, v0, ppre, nacc)
        if p < ppre:
            p = ppre
    return p


# One long body on purpose (the architecture test lists it as a compiled kernel): numba
# compiles it (hydraulics.system._numba_kernel) into one loop over simulations and
# actuators that keeps the ~40 per-actuator scalars of the servovalve, land-flow, supply
# and chamber steps in registers. The same steps, named and readable, are the functions of
# the numpy backend (hydraulics/_numpy_step.py), which test_backends_agree holds it to.
def step_loops(cmd, xin, vin, X, Y, IC, ICS, buf, head, P, G):
    ns = cmd.shape[0]
    na = cmd.shape[1]
    dt = G[G_DT]
    pv = G[G_PV]
    prel = G[G_PREL]
    air = G[G_AIR]
    airn = G[G_AIRN]
    patm = G[G_PATM]
    pset = G[G_PSET]
    pt = G[G_PT]
    qmax = G[G_QMAX]
    v0 = G[G_V0]
    ppre = G[G_PPRE]
    nacc = G[G_NACC]
    cline = G[G_CLINE]
    sset = G[G_SSET]
    oleak = G[G_OLEAK]
    dl = G[G_DL]
    sqdl = G[G_SQDL]
    ov = G[G_OV]
    model = G[G_MODEL]
    slew = G[G_SLEW]
    nd = int(G[G_ND])

    for s in range(ns):
        ps = Y[PS, s]
        d0 = 0.0
        sig = 0.0
        # ---------------- pass 1: spool, land flows, per-actuator 2x2 linear solves
        for i in range(na):
            u = cmd[s, i]
            if nd > 0:
                # delay line of nd steps shared by the actuators; actuator i reads the
                # command of nd_i <= nd steps ago (slot head is the oldest, nd steps)
                ndi = int(P[P_ND, i])
                if ndi > 0:
                    j = head + nd - ndi
                    if j >= nd:
                        j -= nd
                    ud = buf[s, i, j]
                else:
                    ud = u
                buf[s, i, head] = u
                u = ud
            u = u + P[P_U0, i]
            y = X[SPOOL, s, i]
            r = X[RATE, s, i]
            if model > 0.5:
                yn = P[P_F00, i] * y + P[P_F01, i] * r + P[P_G0, i] * u
                rn = P[P_F10, i] * y + P[P_F11, i] * r + P[P_G1, i] * u
            else:
                a1 = P[P_A1, i]
                yn = a1 * y + (1.0 - a1) * u
                rn = 0.0
            if slew > 0.0:
                lim = slew * dt
                if yn > y + lim:
                    yn = y + lim
                elif yn < y - lim:
                    yn = y - lim
                if rn > slew:
                    rn = slew
                elif rn < -slew:
                    rn = -slew
            if yn > 1.0:
                yn = 1.0
                if rn > 0.0:
                    rn = 0.0
            elif yn < -1.0:
                yn = -1.0
                if rn < 0.0:
                    rn = 0.0
            if model < 0.5:
                rn = (yn - y) / dt
            X[SPOOL, s, i] = yn
            X[RATE, s, i] = rn

            # metering openings (overlap removed, null leakage as a residual opening)
            op = yn - ov
            if op < 0.0:
                op = 0.0
            on = -yn - ov
            if on < 0.0:
                on = 0.0
            op = op / (1.0 - ov)
            on = on / (1.0 - ov)
            op = op + oleak * (1.0 - op)
            on = on + oleak * (1.0 - on)

            pa = X[PA, s, i]
            pb = X[PB, s, i]
            K = P[P_K, i]
            q, gd = land_flow(ps - pa, dl, sqdl)
            qpa = K * op * q
            gpa = K * op * gd
            q, gd = land_flow(pa - pt, dl, sqdl)
            qat = K * on * q
            gat = K * on * gd
            q, gd = land_flow(ps - pb, dl, sqdl)
            qpb = K * on * q
            gpb = K * on * gd
            q, gd = land_flow(pb - pt, dl, sqdl)
            qbt = K * op * q
            gbt = K * op * gd

            h = P[P_H, i]
            aa = P[P_AA, i]
            ab = P[P_AB, i]
            kc = P[P_KC, i]
            ke = P[P_KE, i]
            x = xin[s, i]
            v = vin[s, i]
            xc = x
            if xc > h:
                xc = h
            elif xc < -h:
                xc = -h
            va = P[P_VDA, i] + aa * (h + xc)
            vb = P[P_VDB, i] + ab * (h - xc)
            beta = P[P_BETA, i]
            cva = va * inv_beta(pa, beta, air, airn, patm)
            cvb = vb * inv_beta(pb, beta, air, airn, patm)
            fa = qpa - qat - kc * (pa - pb) - ke * pa - aa * v
            fb = qpb - qbt + kc * (pa - pb) - ke * pb + ab * v
            m00 = cva / dt + gpa + gat + kc + ke
            m11 = cvb / dt + gpb + gbt + kc + ke
            det = m00 * m11 - kc * kc
            ua = (m11 * fa + kc * fb) / det
            ub = (kc * fa + m00 * fb) / det
            wa = (m11 * gpa + kc * gpb) / det
            wb = (kc * gpa + m00 * gpb) / det
            d0 += qpa + qpb - gpa * ua - gpb * ub
            sig += gpa * (1.0 - wa) + gpb * (1.0 - wb)
            X[QPA, s, i] = qpa
            X[QAT, s, i] = qat
            X[QPB, s, i] = qpb
            X[QBT, s, i] = qbt
            X[S_GPA, s, i] = gpa
            X[S_GAT, s, i] = gat
            X[S_GPB, s, i] = gpb
            X[S_GBT, s, i] = gbt
            X[S_UA, s, i] = ua
            X[S_UB, s, i] = ub
            X[S_WA, s, i] = wa
            X[S_WB, s, i] = wb
            X[S_CA, s, i] = cva
            X[S_CB, s, i] = cvb

        # ---------------- supply node: pressure-compensated pump + accumulators + line
        sto = Y[STORE, s]
        ds = pset - ps
        dem = d0 + sig * ds
        qp = (sset - sto) / dt + dem
        if qp >= 0.0 and qp <= qmax:
            snew = sset
            psn = pset
        else:
            if qp > qmax:
                qp = qmax
            else:
                qp = 0.0
            ICS[CS_PUMPSAT, s] += 1
            cs = dstore_dp(ps, cline, v0, ppre, nacc)
            ds = (qp - d0) / (cs / dt + sig)
            dem = d0 + sig * ds
            snew = sto + (qp - dem) * dt
            smin = cline * pv
            if snew < smin:
                Y[V_SUPPLY_CAV, s] += smin - snew
                snew = smin
                psn = pv
                ICS[CS_LOW, s] += 1
            else:
                psn = p_of_store(snew, ps + ds, cline, v0, ppre, nacc)
        gas_old = Y[GASV, s]
        if v0 > 0.0 and psn > ppre:
            gas = v0 * (ppre / psn) ** (1.0 / nacc)
        else:
            gas = v0
        Y[V_ACC_OUT, s] += gas - gas_old
        Y[V_STORE_OUT, s] += sto - snew
        Y[V_PUMP, s] += qp * dt
        Y[QPUMP, s] = qp
        Y[QDEMAND, s] = dem
        Y[STORE, s] = snew
        Y[PS, s] = psn
        Y[GASV, s] = gas

        # ---------------- pass 2: chamber pressures, bookkeeping, forces
        for i in range(na):
            pa = X[PA, s, i]
            pb = X[PB, s, i]
            dpa = X[S_UA, s, i] + X[S_WA, s, i] * ds
            dpb = X[S_UB, s, i] + X[S_WB, s, i] * ds
            qpa = X[QPA, s, i] + X[S_GPA, s, i] * (ds - dpa)
            qat = X[QAT, s, i] + X[S_GAT, s, i] * dpa
            qpb = X[QPB, s, i] + X[S_GPB, s, i] * (ds - dpb)
            qbt = X[QBT, s, i] + X[S_GBT, s, i] * dpb
            pan = pa + dpa
            pbn = pb + dpb
            kc = P[P_KC, i]
            ke = P[P_KE, i]
            aa = P[P_AA, i]
            ab = P[P_AB, i]
            v = vin[s, i]
            x = xin[s, i]
            qc = kc * (pan - pbn)
            cva = X[S_CA, s, i]
            cvb = X[S_CB, s, i]
            X[V_EXT_A, s, i] += ke * pan * dt
            X[V_EXT_B, s, i] += ke * pbn * dt
            if pan > prel:
                X[V_RELIEF_A, s, i] += (pan - prel) * cva
                pan = prel
                IC[C_RELIEF, s, i] += 1
            elif pan < pv:
                X[V_CAV_A, s, i] += (pv - pan) * cva
                pan = pv
                IC[C_CAV, s, i] += 1
            if pbn > prel:
                X[V_RELIEF_B, s, i] += (pbn - prel) * cvb
                pbn = prel
                IC[C_RELIEF, s, i] += 1
            elif pbn < pv:
                X[V_CAV_B, s, i] += (pv - pbn) * cvb
                pbn = pv
                IC[C_CAV, s, i] += 1
            X[V_COMP_A, s, i] += cva * (pan - pa)
            X[V_COMP_B, s, i] += cvb * (pbn - pb)
            X[V_DISP_A, s, i] += aa * v * dt
            X[V_DISP_B, s, i] -= ab * v * dt
            X[V_IN_A, s, i] += qpa * dt
            X[V_OUT_A, s, i] += qat * dt
            X[V_IN_B, s, i] += qpb * dt
            X[V_OUT_B, s, i] += qbt * dt
            X[V_CROSS, s, i] += qc * dt
            X[QPA, s, i] = qpa
            X[QAT, s, i] = qat
            X[QPB, s, i] = qpb
            X[QBT, s, i] = qbt
            X[FLOWA, s, i] = qpa - qat
            X[FLOWB, s, i] = qpb - qbt
            X[PA, s, i] = pan
            X[PB, s, i] = pbn
            h = P[P_H, i]
            e = abs(x) - (h - P[P_LC, i])
            fc = 0.0
            if e > 0.0:
                fc = P[P_KCUSH, i] * e
                if x > 0.0:
                    fc = -fc
            X[FCUSH, s, i] = fc
            X[FORCE, s, i] = pan * aa - pbn * ab + fc
