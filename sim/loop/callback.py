"""The coupled step as MuJoCo's own control callback: the whole twin inside ``mj_step``.

:func:`control_callback` is a compiled C function (numba ``cfunc``) installed as
``mjcb_control`` through ctypes (:func:`installed`). MuJoCo calls it in every
``mj_forward`` of ``mj_step``, after positions and velocities and before actuation, so it
does what the Python loop of :meth:`sim.loop.simulation.Simulation.run` does between
two ``mj_step`` calls: on a controller tick the recorder sample and the controller
(:func:`sim.loop._kernels.tick_first_step`), on every step the hydraulic step into
``ctrl`` and the applied forces (:func:`sim.loop._kernels.later_step`), on the last step
of every ``gap_every``-th tick the loop-closure gap, and on the next step the divergence
check of :meth:`Simulation._check <sim.loop.simulation.Simulation._check>`. So
``mj_step(m, d, nstep)``, ``mujoco.rollout`` and ``mujoco.batch`` run the twin without
coming back to Python.

Per-simulation data: ``mjData.userdata`` (``nuserdata`` = :data:`NUSERDATA`, part of
MuJoCo's state row, so a batch or a rollout carries it per simulation): ``[0]`` the
address of the simulation's :class:`Context` (a float64 block of scalars and array
descriptors: the recorder, the reference, the hydraulic and controller state), ``[1]``
the physics-step counter. A model with fewer userdata, or a simulation whose
``userdata[0]`` is 0 (any other MjData, a reset), is left alone.

Same run as the loop, bit for bit (``tests/loop/test_batch.py``): the same compiled kernels in
the same order on the same MuJoCo state. Two details make it so: the loop's controller
reads ``xmat`` as the previous ``mj_step`` left it (the pose one step before ``qpos``),
so the callback keeps the platen's ``xmat`` of the previous step; and the loop's gap is
measured on the last step's kinematics, which is what the callback sees on that step.

Open loop (a context built with ``valve_command``, scalar ``S_OPEN`` = 1): the first
step of tick ``k`` records, holds the recorded command ``VC[k]`` and runs the pre-step
(:func:`sim.loop._kernels.tick_first_step_open`), as ``Simulation.run(valve_command=...)``
does; the later steps are the same as closed loop. A bearing-guided platen (scalar
``S_GUIDED``): its acceleration is recorded from its slides' DOFs (``PSD``, plus a
spring-mounted foundation's ``FND``) as the loop records it, and closed loop its
controller reads the slides' velocity (:func:`sim.loop._kernels.tick_first_step_guided`,
DOF ``PDI[i]`` from ``qvel[PSD[i]]``) as the loop's Python tick does. A per-step power
damping on one slide (``PWD``, ``PWK``; the UCSD table's) is added after the applied
forces, with the effect's own formula (:func:`_power_damping`).

``mjData`` field addresses are read from the MjData struct (:func:`sim.loop.mjlayout.field_offsets`,
found by matching the Python binding's array addresses, so no header layout is assumed);
the callback is compiled once per process (a few seconds) with those offsets.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import sys
import threading
import time

import mujoco
import numba
import numpy as np
from numba import types
from numba.extending import intrinsic

from sim.errors import RunInterrupted, ScenarioError, is_interrupt
from sim.loop import _kernels as FL
from sim.loop.divergence import CODE_RESET, CODE_WARN, NWARN_ALL, WARN_IDX, check_state, divergence_reason
from sim.loop.mjlayout import field_offsets
from sim.loop.simulation import RunResult

NUSERDATA = 2  #: userdata[0] = context address, userdata[1] = physics-step counter
_FIELDS = ("qpos", "qvel", "qacc", "ctrl", "qfrc_applied", "xpos", "xmat", "userdata")
# ---- context scalars
# fmt: off
(S_N, S_SPT, S_GAP_EVERY, S_RELIEF, S_PD, S_PB, S_DT, S_ZSS, S_AC, S_AN, S_DONE, S_PENDING, S_CODE, S_VALUE,
 S_TICK, S_NQ, S_NV, S_NA, S_NBODY, S_NFR, S_NAIR, S_NEQ, S_VAPOUR, S_OPEN, S_CALLS, S_GUIDED) = range(26)
NS = 26
# ---- context arrays (descriptor rows: address, dim0, dim1, dim2)
ARRAYS = ("Q", "V", "ACC", "HSP", "HF", "HPA", "HPB", "HCMD", "EPS", "EGAS", "GAP",
          "SREF", "VREF", "VFF", "QA", "DA", "IDS", "CONSTS", "J", "JP", "NN", "GAINS", "CSTATE", "PLHP", "PLPREV",
          "CMD2", "X2", "V2", "X", "Y", "IC", "ICS", "BUF", "P", "G", "FRD", "FRFC", "ZFR", "AQ", "AD", "AF0",
          "XMP", "GB1", "GB2", "GA1", "GA2", "VC", "W0", "PSD", "FND", "PDI", "PWD", "PWK")
# fmt: on
A = {name: i for i, name in enumerate(ARRAYS)}
NCTX = NS + 4 * len(ARRAYS)


@intrinsic
def _ptr(typingctx, addr):
    """int64 address -> void*."""

    def codegen(context, builder, sig, args):
        return builder.inttoptr(args[0], context.get_value_type(types.voidptr))

    return types.voidptr(types.int64), codegen


@intrinsic
def _addr(typingctx, p):
    """void* -> int64 address."""

    def codegen(context, builder, sig, args):
        return builder.ptrtoint(args[0], context.get_value_type(types.int64))

    return types.int64(types.voidptr), codegen


_J = dict(nogil=True, boundscheck=False, cache=True)


@numba.njit(**_J)
def _d(C, name):
    o = NS + 4 * name
    return np.int64(C[o]), np.int64(C[o + 1]), np.int64(C[o + 2]), np.int64(C[o + 3])


@numba.njit(**_J)
def _f1(C, i):
    a, n0, _, _ = _d(C, i)
    return numba.carray(_ptr(a), (n0,), np.float64)


@numba.njit(**_J)
def _f2(C, i):
    a, n0, n1, _ = _d(C, i)
    return numba.carray(_ptr(a), (n0, n1), np.float64)


@numba.njit(**_J)
def _f3(C, i):
    a, n0, n1, n2 = _d(C, i)
    return numba.carray(_ptr(a), (n0, n1, n2), np.float64)


@numba.njit(**_J)
def _i1(C, i):
    a, n0, _, _ = _d(C, i)
    return numba.carray(_ptr(a), (n0,), np.int64)


@numba.njit(**_J)
def _i2(C, i):
    a, n0, n1, _ = _d(C, i)
    return numba.carray(_ptr(a), (n0, n1), np.int64)


@numba.njit(**_J)
def _i3(C, i):
    a, n0, n1, n2 = _d(C, i)
    return numba.carray(_ptr(a), (n0, n1, n2), np.int64)


# the argument lists of the tick kernels, a few per line
# fmt: off
@numba.njit(**_J)
def _tick(
    k, C, qpos, qvel, XMP, ctrl, qfa, qa, da, ids, pd, pb, cmd2, x2, v2, X, Y, IC, ICS, buf, P, G, frd, frfc, zfr,
    zss, dt, aq, ad, af0, ac, an,
):
    Q, V, HSP, HF = _f2(C, A_Q), _f2(C, A_V), _f2(C, A_HSP), _f2(C, A_HF)
    HPA, HPB, HCMD, EPS, EGAS = _f2(C, A_HPA), _f2(C, A_HPB), _f2(C, A_HCMD), _f1(C, A_EPS), _f1(C, A_EGAS)
    SREF, VREF, VFF = _f2(C, A_SREF), _f2(C, A_VREF), _f2(C, A_VFF)
    consts, J, Jp, N, gains = _f2(C, A_CONSTS), _f2(C, A_J), _f2(C, A_JP), _f2(C, A_NN), _f1(C, A_GAINS)
    cst, plhp, plprev = _f1(C, A_CSTATE), _f1(C, A_PLHP), _f1(C, A_PLPREV)
    FL.tick_first_step(
        k, qpos, qvel, XMP, ctrl, qfa, Q, V, HSP, HF, HPA, HPB, HCMD, EPS, EGAS, SREF, VREF, VFF, qa, da, ids, pd, pb,
        consts, J, Jp, N, gains, cst, plhp, plprev, cmd2, x2, v2, X, Y, IC, ICS, buf, P, G, frd, frfc, zfr, zss, dt,
        aq, ad, af0, ac, an,
    )


@numba.njit(**_J)
def _tick_open(k, C, qpos, qvel, ctrl, qfa, qa, da, ids, cmd2, x2, v2, X, Y, IC, ICS, buf, P, G, frd, frfc, zfr):
    FL.tick_first_step_open(
        k, qpos, qvel, ctrl, qfa, _f2(C, A_Q), _f2(C, A_V), _f2(C, A_HSP), _f2(C, A_HF), _f2(C, A_HPA), _f2(C, A_HPB),
        _f2(C, A_HCMD), _f1(C, A_EPS), _f1(C, A_EGAS), _f2(C, A_VC), qa, da, ids, cmd2, x2, v2, X, Y, IC, ICS, buf, P,
        G, frd, frfc, zfr, C[S_ZSS], C[S_DT], _i1(C, A_AQ), _i1(C, A_AD), _f1(C, A_AF0), C[S_AC], C[S_AN],
    )


@numba.njit(**_J)
def _tick_guided(k, C, qpos, qvel, ctrl, qfa, qa, da, ids, cmd2, x2, v2, X, Y, IC, ICS, buf, P, G, frd, frfc, zfr):
    FL.tick_first_step_guided(
        k, qpos, qvel, ctrl, qfa, _f2(C, A_Q), _f2(C, A_V), _f2(C, A_HSP), _f2(C, A_HF), _f2(C, A_HPA), _f2(C, A_HPB),
        _f2(C, A_HCMD), _f1(C, A_EPS), _f1(C, A_EGAS), _f2(C, A_SREF), _f2(C, A_VREF), _f2(C, A_VFF), qa, da, ids,
        _i1(C, A_PSD), _i1(C, A_PDI), _f2(C, A_CONSTS), _f2(C, A_J), _f2(C, A_JP), _f2(C, A_NN), _f1(C, A_GAINS),
        _f1(C, A_CSTATE), _f1(C, A_PLHP), _f1(C, A_PLPREV), cmd2, x2, v2, X, Y, IC, ICS, buf, P, G, frd, frfc, zfr,
        C[S_ZSS], C[S_DT], _i1(C, A_AQ), _i1(C, A_AD), _f1(C, A_AF0), C[S_AC], C[S_AN],
    )
# fmt: on


@numba.njit(**_J)
def _power_damping(C, qvel, qfa, cleared):
    """The per-step power dampers on one slide each (``PWD``: DOF, ``PWK``: C, alpha, v0,
    slope C v0^alpha / v0), as :meth:`sim.effects.mechanical.PowerDamping.apply` adds them
    after the loop's own forces (``qfrc_applied`` zeroed first unless the pre-step did)."""
    pwd = _i1(C, A_PWD)
    if pwd.shape[0] == 0:
        return
    if not cleared:
        qfa[:] = 0.0
    pwk = _f2(C, A_PWK)
    for i in range(pwd.shape[0]):
        c, a, v0, slope = pwk[i, 0], pwk[i, 1], pwk[i, 2], pwk[i, 3]
        v = qvel[pwd[i]]
        av = abs(v)
        qfa[pwd[i]] -= c * av**a * math.copysign(1.0, v) if av >= v0 else slope * v


@numba.njit(**_J)
def coupled_step(C, qpos, qvel, qacc, ctrl, qfa, xpos, xmat, ud, wn):
    """One call of the control callback on one simulation (``C``: its context; ``wn``:
    its ``mjData.warning`` as int32 pairs)."""
    s = np.int64(ud[1])
    ud[1] = s + 1
    C[S_CALLS] = s + 1  # MuJoCo's reset after a bad state zeroes userdata: the calls stop short
    if C[S_DONE] >= 0:  # stopped (diverged): leave the state alone
        return
    spt = np.int64(C[S_SPT])
    k = s // spt
    j = s - k * spt
    n = np.int64(C[S_N])
    if k >= n:
        return
    pb = np.int64(C[S_PB])
    pd = np.int64(C[S_PD])
    XMP = _f2(C, A_XMP)
    X = _f3(C, A_X)
    if s == 0:
        for r in range(9):
            XMP[pb, r] = xmat[pb, r]
        W0 = _i1(C, A_W0)
        for i in range(WARN_IDX.shape[0]):  # MuJoCo's warning counts at the start (a reused MjData: not 0)
            W0[i] = wn[2 * WARN_IDX[i]]
    if j == 0 and C[S_PENDING] > 0:  # the check of the previous tick, on the state after its steps
        C[S_PENDING] = 0.0
        code, val = check_state(qpos, qvel, X, C[S_VALUE], C[S_RELIEF], C[S_VAPOUR])
        if code == 0 or code >= 3:  # as Simulation._check: a MuJoCo warning after the finite state, before the rest
            W0 = _i1(C, A_W0)
            for i in range(WARN_IDX.shape[0]):
                if wn[2 * WARN_IDX[i]] > W0[i]:
                    code = CODE_WARN + i
                    break
        if code:
            C[S_CODE] = code
            C[S_VALUE] = val
            C[S_DONE] = k
            return
    cmd2 = _f2(C, A_CMD2)
    x2 = _f2(C, A_X2)
    v2 = _f2(C, A_V2)
    Y = _f2(C, A_Y)
    IC = _i3(C, A_IC)
    ICS = _i2(C, A_ICS)
    buf = _f3(C, A_BUF)
    P = _f2(C, A_P)
    G = _f1(C, A_G)
    qa = _i1(C, A_QA)
    da = _i1(C, A_DA)
    ids = _i1(C, A_IDS)
    frd = _i1(C, A_FRD)
    frfc = _f1(C, A_FRFC)
    zfr = _f1(C, A_ZFR)
    aq = _i1(C, A_AQ)
    ad = _i1(C, A_AD)
    af0 = _f1(C, A_AF0)
    zss, dt, ac, an = C[S_ZSS], C[S_DT], C[S_AC], C[S_AN]
    if j == 0 and C[S_OPEN] > 0:
        _tick_open(k, C, qpos, qvel, ctrl, qfa, qa, da, ids, cmd2, x2, v2, X, Y, IC, ICS, buf, P, G, frd, frfc, zfr)
    elif j == 0 and C[S_GUIDED] > 0:  # a bearing-guided platen's controller reads its slides
        _tick_guided(k, C, qpos, qvel, ctrl, qfa, qa, da, ids, cmd2, x2, v2, X, Y, IC, ICS, buf, P, G, frd, frfc, zfr)
    elif j == 0:
        # fmt: off
        _tick(
            k, C, qpos, qvel, XMP, ctrl, qfa, qa, da, ids, pd, pb, cmd2, x2, v2, X,
            Y, IC, ICS, buf, P, G, frd, frfc, zfr, zss, dt, aq, ad, af0, ac, an,
        )
        # fmt: on
    else:
        kk = k if j == 1 else -1
        if kk >= 0 and C[S_GUIDED] > 0:  # a bearing-guided platen: its slides' acceleration, as the loop records it
            _record_guided(k, C, qacc)
            kk = -1
        # fmt: off
        FL.later_step(
            kk, qpos, qvel, qacc, ctrl, qfa, _f2(C, A_ACC), pd, qa, da, ids, cmd2, x2, v2, X, Y,
            IC, ICS, buf, P, G, frd, frfc, zfr, zss, dt, aq, ad, af0, ac, an,
        )
        # fmt: on
    _power_damping(C, qvel, qfa, frd.shape[0] > 0 or aq.shape[0] > 0)
    if j == spt - 1 and (k % np.int64(C[S_GAP_EVERY]) == 0 or k == n - 1):  # as the loop: also the last tick
        gap = FL.loop_gap(xpos, xmat, _i1(C, A_GB1), _i1(C, A_GB2), _f2(C, A_GA1), _f2(C, A_GA2))
        _f1(C, A_GAP)[k] = gap
        C[S_PENDING] = 1.0
        C[S_VALUE] = gap
        C[S_TICK] = k
    for r in range(9):
        XMP[pb, r] = xmat[pb, r]


@numba.njit(**_J)
def _record_guided(k, C, qacc):
    """Row ``k`` of the recorder's platen acceleration of a bearing-guided platen from the
    tick's first step (still in ``qacc``): per guided DOF its slide's, plus a spring-mounted
    foundation's slide along it (absolute), the loop's ``ACC[k, :n] = qacc[fnd] + qacc[slide]``."""
    ACC = _f2(C, A_ACC)
    psd = _i1(C, A_PSD)
    fnd = _i1(C, A_FND)
    for i in range(psd.shape[0]):
        if fnd.shape[0]:
            ACC[k, i] = qacc[fnd[i]] + qacc[psd[i]]
        else:
            ACC[k, i] = qacc[psd[i]]


A_Q, A_V, A_ACC, A_HSP, A_HF, A_HPA, A_HPB, A_HCMD, A_EPS, A_EGAS, A_GAP = range(11)
(A_SREF, A_VREF, A_VFF, A_QA, A_DA, A_IDS, A_CONSTS, A_J, A_JP, A_NN, A_GAINS, A_CSTATE, A_PLHP, A_PLPREV) = range(
    11, 25
)
A_CMD2, A_X2, A_V2, A_X, A_Y, A_IC, A_ICS, A_BUF, A_P, A_G, A_FRD, A_FRFC, A_ZFR, A_AQ, A_AD, A_AF0 = range(25, 41)
A_XMP, A_GB1, A_GB2, A_GA1, A_GA2, A_VC, A_W0, A_PSD, A_FND, A_PDI, A_PWD, A_PWK = range(41, 53)
assert (
    A_PWK == A["PWK"]
    and A_FND == A["FND"]
    and A_W0 == A["W0"]
    and A_VC == A["VC"]
    and A_GA2 == A["GA2"]
    and A_XMP == A["XMP"]
    and A_CMD2 == A["CMD2"]
    and A_SREF == A["SREF"]
)


# ------------------------------------------------------------------ MjData layout
_cfunc = None
_lock = threading.Lock()


# byte offsets of the mjData array pointers, set by control_callback before compiling
# _callback (numba freezes them as constants: they depend only on the MuJoCo build, pinned
# in pyproject.toml, so the compiled callback is cached on disk)
O_QPOS = O_QVEL = O_QACC = O_CTRL = O_QFA = O_XPOS = O_XMAT = O_UD = O_NUD = O_WARN = 0


@numba.njit(**_J)
def _field(base, o, n):
    return numba.carray(_ptr(numba.carray(_ptr(base + o), (1,), np.int64)[0]), (n,), np.float64)


def _callback(m, d):
    if numba.carray(_ptr(_addr(m) + O_NUD), (1,), np.int32)[0] < NUSERDATA:
        return  # a model without our userdata: not ours
    base = _addr(d)
    ud = _field(base, O_UD, NUSERDATA)
    ctx = np.int64(ud[0])
    if ctx == 0:
        return
    C = numba.carray(_ptr(ctx), (NCTX,), np.float64)
    nq, nv, na, nb = np.int64(C[S_NQ]), np.int64(C[S_NV]), np.int64(C[S_NA]), np.int64(C[S_NBODY])
    xpos = _field(base, O_XPOS, 3 * nb).reshape((nb, 3))
    xmat = _field(base, O_XMAT, 9 * nb).reshape((nb, 9))
    coupled_step(
        C,
        _field(base, O_QPOS, nq),
        _field(base, O_QVEL, nv),
        _field(base, O_QACC, nv),
        _field(base, O_CTRL, na),
        _field(base, O_QFA, nv),
        xpos,
        xmat,
        ud,
        numba.carray(_ptr(base + O_WARN), (2 * NWARN_ALL,), np.int32),
    )


def control_callback():
    """The compiled ``mjcb_control`` (numba ``cfunc``), built (or loaded from numba's
    cache) on first use."""
    global _cfunc, O_QPOS, O_QVEL, O_QACC, O_CTRL, O_QFA, O_XPOS, O_XMAT, O_UD, O_NUD, O_WARN
    with _lock:
        if _cfunc is not None:
            return _cfunc
        off = field_offsets(_FIELDS)
        O_QPOS, O_QVEL, O_QACC, O_CTRL = off["qpos"], off["qvel"], off["qacc"], off["ctrl"]
        O_QFA, O_XPOS, O_XMAT, O_UD = off["qfrc_applied"], off["xpos"], off["xmat"], off["userdata"]
        O_NUD, O_WARN = off["nuserdata"], off["warning"]
        _cfunc = numba.cfunc(
            types.void(types.voidptr, types.voidptr), nopython=True, nogil=True, boundscheck=False, cache=True
        )(_callback)
        return _cfunc


@contextlib.contextmanager
def installed():
    """Install :func:`control_callback` as ``mjcb_control`` for the ``with`` block
    (process-wide, as MuJoCo's callbacks are), then restore the previous one."""
    cb = control_callback()
    fn = ctypes.CFUNCTYPE(None, ctypes.c_void_p, ctypes.c_void_p)(cb.address)
    prev = mujoco.get_mjcb_control()
    mujoco.set_mjcb_control(fn)
    try:
        yield
    finally:
        mujoco.set_mjcb_control(prev)


# ------------------------------------------------------------------ contexts and runs
def callback_model(sim) -> mujoco.MjModel:
    """``sim``'s model compiled again from its spec with ``nuserdata`` =
    :data:`NUSERDATA` (nothing else changes)."""
    spec = sim.tm.spec.copy()
    spec.nuserdata = NUSERDATA
    return spec.compile()


def accepts(sim, *, open_loop: bool = False) -> str | None:
    """Why ``sim`` cannot run on the callback (None: it can): the callback is the fused
    loop, closed or open, on a free or a bearing-guided platen (a controller with a
    compiled tick and no stop at the stroke ends; no per-step effects but a power damping
    on one slide, no fault hooks, no valve delay, two or more physics steps per controller
    tick, the recorder sampling every tick). ``open_loop``: the run replays valve
    commands (the controller does not run)."""
    tm, hs = sim.tm, sim.hs
    if getattr(sim.controller, "stroke_limit_m", None) is not None:
        return "the controller stops the run at the stroke ends (the loop's check)"
    if not hasattr(sim.controller, "kernel_args"):
        return "the controller has no compiled tick"
    if not all(_compiled_damper(e) for e in tm.step_effects):
        return "the table has per-step effects (other than a power damping on one slide)"
    if any(getattr(e, "fault", False) for e in tm.effects):  # faults: their hooks run in the Python loop only
        return "the run has fault effects (valve_stuck, sensor_loss, interlock: controller-tick hooks)"
    if hs.delay_steps != 0 or hs.backend != "numba":
        return "the hydraulics have a valve delay or the numpy backend"
    if sim.steps_per_tick < 2:
        return "one physics step per controller tick"
    if sim.steps_per_sample != sim.steps_per_tick:
        return "the recorder samples every few controller ticks"
    return None


def _compiled_damper(e) -> bool:
    """Whether per-step effect ``e`` is a power damping on one slide (its scalar path),
    which the callback computes itself (:func:`_power_damping`)."""
    from sim.effects.mechanical import PowerDamping

    return isinstance(e, PowerDamping) and type(e).apply is PowerDamping.apply and getattr(e, "_d0", None) is not None


def _power_dampers(tm) -> tuple[np.ndarray, np.ndarray]:
    """The table's per-step power dampers as the callback reads them: their DOFs (int64)
    and (n, 4) [C, alpha, v0, C v0^alpha / v0] (the effect's own constants)."""
    dampers = [e for e in tm.step_effects if _compiled_damper(e)]
    dofs = np.array([e._d0 for e in dampers], dtype=np.int64)
    k = np.array([[float(v) for v in e._k] for e in dampers], dtype=np.float64).reshape(len(dampers), 4)
    return dofs, np.ascontiguousarray(k)


class Context:
    """The float64 block :func:`coupled_step` reads, with the arrays it points to (kept
    alive here): recorder arrays of ``n`` ticks, the reference (closed loop) or the valve
    commands ``valve_command`` (n, n_act) (open loop, ``reference`` None), and views of
    the simulation's hydraulic and controller state (or, with ``state``, arrays given by
    a batch)."""

    def __init__(
        self,
        sim,
        reference,
        n: int,
        *,
        gap_every: int = 8,
        state: dict | None = None,
        valve_command: np.ndarray | None = None,
    ):
        if (reference is None) == (valve_command is None):
            raise ValueError("give exactly one of reference and valve_command")
        tm, hs, ctrl = sim.tm, sim.hs, sim.controller
        m = sim.m
        na = tm.n_act
        ctrl.reset()
        self.n = n
        arr = {}
        arr["Q"] = np.full((n, m.nq), np.nan)
        arr["V"] = np.full((n, m.nv), np.nan)
        arr["ACC"] = np.full((n, 6), np.nan)
        for key in ("HSP", "HF", "HPA", "HPB", "HCMD"):
            arr[key] = np.full((n, na), np.nan)
        for key in ("EPS", "EGAS", "GAP"):
            arr[key] = np.full(n, np.nan)
        from mjcf.description import actuator_strokes

        rate = sim.gains.rate_hz
        if reference is not None:
            arr["SREF"] = np.ascontiguousarray(actuator_strokes(tm.desc, reference.d[:n]), dtype=float)
            arr["VREF"] = np.ascontiguousarray(reference.v[:n], dtype=float)
            arr["VFF"] = np.ascontiguousarray(ctrl.feedforward(reference.v[:n], reference.a[:n], rate), dtype=float)
            arr["VC"] = np.zeros((1, na))
        else:  # open loop: the commands as Simulation.run holds them (float64, C order)
            if len(valve_command) < n or np.shape(valve_command)[1:] != (na,):
                raise ValueError(f"valve_command: {np.shape(valve_command)}, wanted ({n}, {na})")
            arr["VC"] = np.ascontiguousarray(valve_command[:n], dtype=np.float64)
            arr["SREF"], arr["VREF"], arr["VFF"] = np.zeros((1, na)), np.zeros((1, 6)), np.zeros((1, na))
        arr["QA"], arr["DA"], arr["IDS"] = (
            np.asarray(a, dtype=np.int64) for a in (tm.stroke_qadr, tm.stroke_dadr, tm.actuator_ids)
        )
        consts, J, Jp, N, gains, cstate, plhp, plprev = ctrl.kernel_args()
        st = state or {}
        arr.update(
            CONSTS=consts,
            J=J,
            JP=Jp,
            NN=N,
            GAINS=gains,
            CSTATE=st.get("CSTATE", cstate),
            PLHP=st.get("PLHP", plhp),
            PLPREV=st.get("PLPREV", plprev),
        )
        arr["CMD2"] = st.get("CMD2", np.zeros((1, na)))
        arr["X2"] = np.zeros((1, na))
        arr["V2"] = np.zeros((1, na))
        arr["X"], arr["Y"] = st.get("X", hs._X), st.get("Y", hs._Y)
        arr["IC"], arr["ICS"], arr["BUF"] = st.get("IC", hs._IC), st.get("ICS", hs._ICS), hs._buf
        arr["P"], arr["G"] = hs._P, hs._G
        arr["FRD"] = np.asarray(tm.friction_dofs, dtype=np.int64)
        arr["FRFC"] = np.asarray(tm.friction_force, dtype=float)
        arr["ZFR"] = st.get("ZFR", sim._zfr)
        arr["AQ"], arr["AD"] = np.asarray(tm.air_qadr, np.int64), np.asarray(tm.air_dadr, np.int64)
        arr["AF0"] = np.asarray(tm.air_preload, dtype=float)
        arr["XMP"] = np.zeros((m.nbody, 9))
        arr["W0"] = np.zeros(len(WARN_IDX), dtype=np.int64)
        arr["GB1"], arr["GB2"] = sim._g_b1.astype(np.int64), sim._g_b2.astype(np.int64)
        arr["GA1"], arr["GA2"] = np.ascontiguousarray(sim._g_a1), np.ascontiguousarray(sim._g_a2)
        arr["PSD"] = np.asarray(tm.platen_slide_dadr, dtype=np.int64)
        arr["FND"] = np.asarray(sim._fnd_d if sim._fnd_d is not None else np.zeros(0), dtype=np.int64)
        arr["PDI"] = np.asarray(tm.platen_dof_index, dtype=np.int64)
        arr["PWD"], arr["PWK"] = _power_dampers(tm)
        C = np.zeros(NCTX)
        C[S_N], C[S_SPT], C[S_GAP_EVERY] = n, sim.steps_per_tick, gap_every
        C[S_RELIEF] = sim.hp.relief_pressure_pa * (1 + 1e-9)  # the bounds of Simulation._check
        C[S_VAPOUR] = sim.hp.vapour_pressure_pa * (1 - 1e-9) - 1e-3
        C[S_PD], C[S_PB], C[S_DT] = tm.platen_dadr, tm.platen_body, sim.dt
        C[S_ZSS], C[S_AC], C[S_AN] = tm.friction_presliding_m, tm.air_area_over_volume, tm.air_exponent
        C[S_DONE] = -1
        C[S_OPEN] = 0.0 if valve_command is None else 1.0
        C[S_GUIDED] = 0.0 if tm.platen_free else 1.0
        C[S_NQ], C[S_NV], C[S_NA], C[S_NBODY] = m.nq, m.nv, m.nu, m.nbody
        for name, a in arr.items():
            want = (
                np.int64
                if name
                in ("QA", "DA", "IDS", "IC", "ICS", "FRD", "AQ", "AD", "GB1", "GB2", "W0", "PSD", "FND", "PDI", "PWD")
                else np.float64
            )
            if a.dtype != want or not a.flags.c_contiguous:
                raise ValueError(f"context array {name}: {a.dtype}, contiguous {a.flags.c_contiguous}")
            o = NS + 4 * A[name]
            C[o] = a.ctypes.data
            C[o + 1 : o + 1 + a.ndim] = a.shape
        self.arrays, self.C = arr, C
        self.sim = sim

    @property
    def address(self) -> float:
        return float(self.C.ctypes.data)

    def _warned(self, final_state) -> int:
        """``CODE_WARN + i`` of the first MuJoCo warning of :data:`WARN_IDX` whose counter
        rose during the run, from ``final_state[2]`` (``mjData.warning.number``) when the
        route has it; else 0."""
        if len(final_state) < 3:
            return 0
        rose = np.flatnonzero(np.asarray(final_state[2])[WARN_IDX] > self.arrays["W0"])
        return CODE_WARN + int(rose[0]) if len(rose) else 0

    def result(self, wall_s: float, final_state, *, interrupted: bool = False) -> RunResult:
        """The :class:`RunResult` of the finished run (``final_state``: qpos, qvel after
        the last step, for the last tick's pending check, and MuJoCo's warning counters
        (``mjData.warning.number``) where the route has them: a single run does, a batch
        keeps its MjData to itself). ``interrupted``: Ctrl-C stopped the stepping; the
        result keeps the ticks whose physics steps all ran, marked as the loop marks it."""
        C, arr, sim = self.C, self.arrays, self.sim
        rate = sim.gains.rate_hz
        spt = int(C[S_SPT])
        if interrupted and C[S_DONE] < 0:
            return self._interrupted(wall_s, min(int(C[S_CALLS]) // spt, self.n))
        if C[S_DONE] < 0 and C[S_CALLS] < self.n * spt:  # MuJoCo reset the simulation (userdata zeroed)
            k = max(int(C[S_CALLS]) - 1, 0) // spt
            # the warning that made MuJoCo reset it, where the route has the counters
            C[S_CODE], C[S_VALUE], C[S_TICK], C[S_DONE] = self._warned(final_state) or CODE_RESET, 0.0, k, k + 1
        if C[S_DONE] < 0 and C[S_PENDING] > 0:  # the last tick's check, as the loop does after it
            code, val = check_state(final_state[0], final_state[1], arr["X"], C[S_VALUE], C[S_RELIEF], C[S_VAPOUR])
            if code == 0 or code >= 3:  # MuJoCo's warning counters, when the route has them
                code = self._warned(final_state) or code
            if code:
                C[S_CODE], C[S_VALUE], C[S_DONE] = code, val, self.n
        n_done = self.n if C[S_DONE] < 0 else int(C[S_DONE])
        reason = None
        if C[S_DONE] >= 0:
            tk = int(C[S_TICK]) / rate
            code, val = int(C[S_CODE]), float(C[S_VALUE])
            reason = divergence_reason(code, val, tk, sim)
        return self._result(wall_s, n_done, reason)

    def _interrupted(self, wall_s: float, n_done: int) -> RunResult:
        """The result of a run stopped by Ctrl-C after ``n_done`` whole ticks (the loop's
        reason text and flag)."""
        rate = self.sim.gains.rate_hz
        reason = f"interrupted (Ctrl-C) at t = {n_done / rate:.4f} s of {self.n / rate:.4f} s"
        res = self._result(wall_s, n_done, reason)
        res.interrupted = True
        return res

    def _result(self, wall_s: float, n_done: int, reason) -> RunResult:
        """The recorder's first ``n_done`` ticks as a :class:`RunResult`."""
        arr, sim = self.arrays, self.sim
        rate = sim.gains.rate_hz
        t0 = time.perf_counter()
        ch = sim._derive(arr["Q"][:n_done], arr["V"][:n_done], arr["ACC"][:n_done])
        for key, name in (
            ("valve_command", "HCMD"),
            ("spool_position", "HSP"),
            ("actuator_force", "HF"),
            ("pressure_a", "HPA"),
            ("pressure_b", "HPB"),
        ):
            ch[key] = arr[name][:n_done]
        ex = {
            "supply_pressure": arr["EPS"][:n_done],
            "accumulator_gas_volume": arr["EGAS"][:n_done],
            "loop_gap": arr["GAP"][:n_done],
        }
        if "_payload_qpos" in ch:
            ex["payload_qpos"] = ch.pop("_payload_qpos")
        post = time.perf_counter() - t0
        spt = sim.steps_per_tick
        return RunResult(
            t=np.arange(n_done) / rate,
            channels=ch,
            extras=ex,
            wall_s=wall_s + post,
            sim_s=n_done / rate,
            timing={"callback_s": wall_s, "output_s": post, "steps": n_done * spt},
            incomplete_reason=reason,
            force_lag_s=sim.dt,
            valve_hold=sim.valve_hold,
        )


def run_length(sim, reference=None, valve_command=None, duration_s: float | None = None) -> int:
    """Ticks of a run on ``reference`` or ``valve_command`` (as ``Simulation.run`` counts
    them when the recorder samples every tick)."""
    if (reference is None) == (valve_command is None):
        raise ValueError("give exactly one of reference and valve_command")
    n_in = len(reference.t) if reference is not None else len(valve_command)
    return n_in if duration_s is None else min(n_in, int(round(duration_s * sim.gains.rate_hz)) + 1)


def run_callback(
    sim,
    reference=None,
    *,
    valve_command: np.ndarray | None = None,
    duration_s: float | None = None,
    gap_every: int = 8,
    chunk_ticks: int = 512,
    progress: bool = False,
) -> RunResult:
    """Closed-loop run of ``sim`` on ``reference`` (or open loop on ``valve_command``,
    (n, n_act) at the controller rate) with the coupled step inside MuJoCo
    (``mj_step(m, d, nstep)`` in chunks of ``chunk_ticks`` controller ticks, stopping at
    a divergence). Starts from ``sim``'s current state (its :meth:`reset`), which it
    leaves unchanged; same result as ``sim.run(reference=...)`` (the fused loop) or
    ``sim.run(valve_command=...)``. ``progress``: the loop's progress bar on stderr,
    drawn between chunks. Ctrl-C (seen between chunks) keeps the ticks done, marked
    incomplete, and raises :class:`~sim.errors.RunInterrupted` with them, as the loop does."""
    why = accepts(sim, open_loop=valve_command is not None)
    if why:
        raise ScenarioError(f"the callback route cannot run this table: {why}; use Simulation.run")
    n = run_length(sim, reference, valve_command, duration_s)
    m2 = callback_model(sim)
    d2 = mujoco.MjData(m2)
    copy_state(sim.m, sim.d, m2, d2)
    st = {
        "X": sim.hs._X.copy(),
        "Y": sim.hs._Y.copy(),
        "IC": sim.hs._IC.copy(),
        "ICS": sim.hs._ICS.copy(),
        "ZFR": sim._zfr.copy(),
    }
    ctx = Context(sim, reference, n, gap_every=gap_every, state=st, valve_command=valve_command)
    d2.userdata[0] = ctx.address
    d2.userdata[1] = 0.0
    bar = _Bar(n, sim.gains.rate_hz) if progress else None
    with installed():
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            _step_chunks(m2, d2, ctx, n, sim.steps_per_tick, chunk_ticks, bar)
        except (KeyboardInterrupt, SystemError) as e:  # Ctrl-C: keep the ticks done so far
            if not is_interrupt(e):
                raise
            d2.userdata[0] = 0.0
            res = ctx.result(time.perf_counter() - t0, (d2.qpos, d2.qvel, d2.warning.number), interrupted=True)
            raise RunInterrupted(res) from None
        finally:
            if bar is not None:
                bar.close()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    d2.userdata[0] = 0.0
    res = ctx.result(wall, (d2.qpos, d2.qvel, d2.warning.number))
    res.timing["callback_cpu_s"] = cpu  # the stepping's CPU time (this process's threads)
    return res


def _step_chunks(m2, d2, ctx, n: int, spt: int, chunk_ticks: int, bar) -> None:
    """``mj_step`` ``d2`` through ``n`` ticks, ``chunk_ticks`` at a time, until done or
    stopped by the callback's check."""
    done = 0
    while done < n and ctx.C[S_DONE] < 0:
        k = min(chunk_ticks, n - done)
        mujoco.mj_step(m2, d2, nstep=k * spt)
        done += k
        if bar is not None:
            bar.show(done)


class _Bar:
    """The loop's progress bar (``Simulation.run(progress=True)``), at most every 0.25 s."""

    def __init__(self, n: int, rate_hz: float):
        self.n, self.rate, self.last = n, rate_hz, time.perf_counter()

    def show(self, done: int) -> None:
        if time.perf_counter() - self.last <= 0.25:
            return
        self.last = time.perf_counter()
        frac = done / self.n
        sys.stderr.write(f"\r  [{'#' * int(30 * frac):<30s}] {100 * frac:5.1f} %  t = {(done - 1) / self.rate:7.2f} s")
        sys.stderr.flush()

    @staticmethod
    def close() -> None:
        sys.stderr.write("\r" + " " * 70 + "\r")
        sys.stderr.flush()


STATE_SPEC = int(mujoco.mjtState.mjSTATE_INTEGRATION) & ~int(mujoco.mjtState.mjSTATE_USERDATA)


def copy_state(m_from, d_from, m_to, d_to) -> None:
    """The integration state (without userdata) of ``d_from`` into ``d_to``, then
    ``mj_forward`` (the derived fields the reference loop starts from)."""
    spec = int(STATE_SPEC)
    s = np.empty(mujoco.mj_stateSize(m_from, spec))
    mujoco.mj_getState(m_from, d_from, s, spec)
    mujoco.mj_setState(m_to, d_to, s, spec)
    mujoco.mj_forward(m_to, d_to)


__all__ = [
    "Context",
    "NUSERDATA",
    "accepts",
    "callback_model",
    "control_callback",
    "copy_state",
    "coupled_step",
    "installed",
    "run_callback",
    "run_length",
]
