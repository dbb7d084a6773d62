"""The divergence check of the callback route (:mod:`sim.loop.callback`), in the order
and the words of :meth:`Simulation._check <sim.loop.simulation.Simulation._check>`: a
compiled test of the state as a code, and the message of each code."""

from __future__ import annotations

import mujoco
import numba
import numpy as np

from hydraulics import _layout as HL
from sim.loop.simulation import CAUSE_STEP, GAP_LIMIT_M, MJ_WARNINGS

_J = dict(nogil=True, boundscheck=False, cache=True)

#: the MuJoCo warnings that stop a run (:data:`sim.loop.simulation.MJ_WARNINGS`), by index;
#: ``mjData.warning[w].number`` is the int32 at ``2 * w`` from the first counter
#: (``mjWarningStat``: ``lastinfo``, ``number``)
WARN_IDX = np.array([int(w) for w in MJ_WARNINGS], dtype=np.int64)
NWARN_ALL = len(mujoco.mjtWarning.__members__) - 1  # mjNWARNING (the enum's last member is the count)
CODE_WARN = 10  #: divergence code of MuJoCo warning i of WARN_IDX: CODE_WARN + i
#: divergence code of a simulation MuJoCo reset (which zeroes userdata, so the callback
#: loses it) where the route cannot read its warning counters (a batch)
CODE_RESET = 30


@numba.njit(**_J)
def check_state(qpos, qvel, X, gap, relief, vapour):
    """The divergence check of ``Simulation._check``, in its order, as a code: 0 fine;
    2/9 chamber a/b pressures not finite; 1/8 positions/velocities not finite; 3 swivel
    gap; 4/6 chamber a above relief/below vapour, 5/7 the same for chamber b; and the
    value the message names (gap or pressure)."""
    for r, code in ((HL.PA, 2), (HL.PB, 9)):
        for s in range(X.shape[1]):
            for i in range(X.shape[2]):
                if not np.isfinite(X[r, s, i]):
                    return code, 0.0
    for v in qpos:
        if not np.isfinite(v):
            return 1, 0.0
    for v in qvel:
        if not np.isfinite(v):
            return 8, 0.0
    if gap > GAP_LIMIT_M:
        return 3, gap
    for r, above, below in ((HL.PA, 4, 6), (HL.PB, 5, 7)):
        pmax, pmin = -np.inf, np.inf
        for s in range(X.shape[1]):
            for i in range(X.shape[2]):
                p = X[r, s, i]
                pmax = max(pmax, p)
                pmin = min(pmin, p)
        if pmax > relief:
            return above, pmax
        if pmin < vapour:
            return below, pmin
    return 0, 0.0


def divergence_reason(code: int, val: float, tk: float, sim) -> str:
    """The message of divergence ``code`` (:func:`check_state`, :data:`CODE_WARN`,
    :data:`CODE_RESET`) with the value it names, at time ``tk`` of ``sim``'s run."""
    at = f"simulation diverged at t = {tk:.4f} s"
    step = f"physics step {sim.dt * 1e3:.3g} ms"
    hp = sim.hp
    side = {2: "a", 9: "b", 4: "a", 5: "b", 6: "a", 7: "b"}.get(code, "")
    if code == CODE_RESET:
        return (
            f"{at}: MuJoCo reset the state (its accelerations, positions or velocities were not "
            f"finite); {CAUSE_STEP} ({step})"
        )
    if code >= CODE_WARN:
        w = list(MJ_WARNINGS)[code - CODE_WARN]
        return f"{at}: {MJ_WARNINGS[w]} (MuJoCo warning {w.name}); {CAUSE_STEP} ({step})"
    return {  # the words of Simulation._check, so both routes stop with the same reason
        2: f"{at}: the hydraulic state is not finite: NaN/Inf in the chamber {side} pressures; {CAUSE_STEP} "
        f"(the oil columns are the stiffest part: check bulk modulus and dead volumes; {step})",
        9: f"{at}: the hydraulic state is not finite: NaN/Inf in the chamber {side} pressures; {CAUSE_STEP} "
        f"(the oil columns are the stiffest part: check bulk modulus and dead volumes; {step})",
        1: f"{at}: the mechanical state is not finite: NaN/Inf in the platen/linkage positions (qpos); "
        f"{CAUSE_STEP} ({step})",
        8: f"{at}: the mechanical state is not finite: NaN/Inf in the velocities (qvel); {CAUSE_STEP} ({step})",
        3: (
            f"{at}: a swivel opened by {val * 1e3:.3g} mm (limit {GAP_LIMIT_M * 1e3:.3g} mm): the "
            f"loop closure failed; {CAUSE_STEP} ({step}), or a motion beyond the linkages' reach"
        ),
        4: f"{at}: chamber {side} pressure {val / 1e6:.4g} MPa above the relief pressure "
        f"{hp.relief_pressure_pa / 1e6:.4g} MPa; {CAUSE_STEP} ({step})",
        5: f"{at}: chamber {side} pressure {val / 1e6:.4g} MPa above the relief pressure "
        f"{hp.relief_pressure_pa / 1e6:.4g} MPa; {CAUSE_STEP} ({step})",
        6: f"{at}: chamber {side} pressure {val / 1e6:.4g} MPa below the vapour pressure "
        f"{hp.vapour_pressure_pa / 1e6:.4g} MPa; {CAUSE_STEP} ({step})",
        7: f"{at}: chamber {side} pressure {val / 1e6:.4g} MPa below the vapour pressure "
        f"{hp.vapour_pressure_pa / 1e6:.4g} MPa; {CAUSE_STEP} ({step})",
    }[code]


__all__ = ["CODE_RESET", "CODE_WARN", "NWARN_ALL", "WARN_IDX", "check_state", "divergence_reason"]
