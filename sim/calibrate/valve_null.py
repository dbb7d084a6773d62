"""A servovalve's null bias (and its drift), estimated from a record before anything
else is compared.

A real valve passes flow at zero command when its spool's null is off by a fraction
``delta`` of its rated opening (a torque-motor offset, a null that drifts with oil
temperature). In closed loop the controller hides it: the recorded command settles at
``-delta`` to keep the table still. Replayed open loop through a model whose valve has no
such offset, that command drives the piston at a steady ``K delta`` and the model runs to
its end stop. The estimate: each actuator's stroke velocity ``v`` against its recorded
command ``u`` by least squares, ``v = K (u + delta0 + delta1 (t - t_mid))``, i.e. the mean
command that keeps the actuator still, and its linear drift over the record. Where the
record starts still (an earthquake record's quiet seconds), the command held there is
the null (and, where it also ends still, the change between the two is the drift): the
fit's intercept over a strong test takes in what the valve's square-root flow law
rectifies, up to 0.7e-4 of rated opening on an x-only CGS test.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.errors import RunFileError


@dataclass
class ValveNull:
    """Per actuator: ``offset`` (fraction of rated opening, at the record's middle),
    ``drift_per_s`` (fraction per second), ``gain`` (stroke velocity per unit command,
    m/s), the stroke-velocity source and the record's mid time."""

    offset: np.ndarray
    drift_per_s: np.ndarray
    gain: np.ndarray
    velocity_from: str
    t_mid: float
    #: "fit": the intercept of the whole record's fit; "lead-in" (or "lead-in and end"):
    #: the commands held at the record's still start (and end), :func:`still_holds`
    method: str = "fit"

    def at(self, t: np.ndarray) -> np.ndarray:
        """The offset (len(t), n_act) to add to the recorded command."""
        return self.offset[None, :] + np.outer(np.asarray(t) - self.t_mid, self.drift_per_s)

    def as_dict(self, actuators) -> dict:
        return {
            "offset": {a: float(v) for a, v in zip(actuators, self.offset)},
            "drift_per_s": {a: float(v) for a, v in zip(actuators, self.drift_per_s)},
            "velocity_gain_m_s": {a: (float(v) if np.isfinite(v) else None) for a, v in zip(actuators, self.gain)},
            "velocity_from": self.velocity_from,
            "method": "least squares of stroke velocity on valve command: v = K (u + offset + drift (t - t_mid))"
            + ("" if self.method == "fit" else f"; the null and drift from the commands held still ({self.method})"),
        }


def internal_basis(desc) -> np.ndarray:
    """(n_act, k) orthonormal basis of the stroke-velocity directions the table cannot
    take: the complement of the kinematic Jacobian's range (its left null space, the
    directions of an internal force ``J^T f = 0``). k = 0 for a table with no more
    actuators than the rank of its Jacobian; 6 on CGS (12 actuators, 6 DOF)."""
    from sim.control.tvc import dof_jacobian

    U, s, _ = np.linalg.svd(dof_jacobian(desc))
    r = int(np.sum(s > 1e-9 * max(float(s[0]), 1e-300))) if len(s) else 0
    return U[:, r:]


def stroke_velocity(run, desc) -> tuple[np.ndarray, str]:
    """Each actuator's stroke velocity (N, n_act), m/s, from what the record has:
    ``actuator_displacement`` (differentiated), else the table's velocity or displacement
    through the actuators' kinematic Jacobian at home.

    On an over-actuated table (more actuators than DOF: CGS, 12 for 6) the differentiated
    actuator transducers are projected onto the motions the table can make (the range of
    the kinematic Jacobian, i.e. the DOF velocity fitted to the 12 strokes by least squares
    and mapped back): the actuators cannot move apart, so what the transducers show in
    the other directions is their own noise. Unprojected, that noise (the displacement's
    end-point noise over the record, ~10-25 um/s on 3 s CGS runs with 20 um transducers)
    entered each actuator's null estimate and, replayed, drove an internal force of ~1 kN
    (issue #13; docs/calibration.md)."""
    from mjcf.description import DOFS6

    fs = run.sample_rate_hz
    if run.actuator_displacement is not None and np.all(np.isfinite(run.actuator_displacement)):
        v = np.gradient(run.actuator_displacement, 1.0 / fs, axis=0)
        what = "actuator_displacement (differentiated)"
        N = internal_basis(desc)
        if N.shape[1]:
            v = v - (v @ N) @ N.T
            what += f", projected onto the table's {v.shape[1] - N.shape[1]} DOF motions"
        return v, what
    if run.table_velocity is not None and np.all(np.isfinite(run.table_velocity)):
        q, what = run.table_velocity, "table_velocity"
    elif run.table_displacement is not None and np.all(np.isfinite(run.table_displacement)):
        q, what = np.gradient(run.table_displacement, 1.0 / fs, axis=0), "table_displacement (differentiated)"
    else:
        raise RunFileError(
            f"run file {run.name} has no complete actuator_displacement, table_velocity or "
            "table_displacement; the valve null bias needs the recorded motion: import one of them "
            "(or replay with --no-bias)"
        )
    q6 = np.zeros((len(q), 6))
    for j, d in enumerate(run.dofs):
        q6[:, DOFS6.index(d)] = q[:, j]
    from sim.control.tvc import dof_jacobian

    return q6 @ dof_jacobian(desc).T, what + " through the kinematic Jacobian"


#: the largest relative standard error of a valve's gain read off a record: above it the
#: record does not tell the gain (the command barely moved: an axis the test left still),
#: and the declared one divides the intercept instead. Assumed: 10 %; measured on a
#: vertical CGS test, the still horizontal valves' 0.005 +/- 1.2 m/s (240 times its size)
#: and the moved vertical ones' 1.078 +/- 0.003 (0.3 %) fall far either side of it
GAIN_READ_WITHIN = 0.1


#: the shortest still lead-in (s) read as the valves' null (assumed: half a second, 500
#: samples at 1 kHz, averages a command's noise well below the nulls of 1e-4 to 1e-2 that
#: matter; an earthquake record's lead-in is seconds)
NULL_LEAD_S = 0.5
#: the largest difference (fraction of rated opening) between a still stretch's null and
#: the fit's for the stretch to be read as a held null: assumed 2e-4, three times the
#: largest the flow law's rectification was measured to put into the fit (0.6e-4 on a
#: strong lab test). Beyond it the stretch is not the controller holding the table (the
#: hydraulics off before the test, the table on its stops), and the fit stands
HELD_AGREES = 2e-4


def estimate(run, desc, *, drift: bool = True) -> ValveNull:
    """Least-squares valve null offset (and drift) per actuator of ``run`` (a RunFile
    with ``valve_command`` and a motion channel) on table ``desc``; where the record
    starts still (:func:`still_holds`), the null is the command held there."""
    u = np.asarray(run.valve_command, float)
    v, what = stroke_velocity(run, desc)
    t = np.asarray(run.t, float)
    tm = 0.5 * (t[0] + t[-1])
    n_act = u.shape[1]
    declared = declared_velocity_gain(desc)
    holds = still_holds(u, v, run.sample_rate_hz)
    moving = _moving_rows(len(u), holds)
    off, dr, gain, n_held = np.zeros(n_act), np.zeros(n_act), np.zeros(n_act), 0
    for i in range(n_act):
        if np.ptp(u[:, i]) < 1e-12 and np.max(np.abs(v[:, i])) < 1e-9:
            # a constant command holding a still actuator: that command is the null itself
            # (no flow gain can be read from such a record, and none is needed)
            off[i], dr[i], gain[i] = -float(u[0, i]), 0.0, float("nan")
            continue
        ui, vi, ti = u[moving, i], v[moving, i], t[moving] - tm
        gain[i], off[i], dr[i] = _one_null(ui, vi, ti, drift, declared[i], run, i)
        held = _null_held(u[:, i], t - tm, holds, drift) if holds else None
        if held is not None and abs(held[0] - off[i]) <= HELD_AGREES:
            (off[i], dr[i]), n_held = held, n_held + 1
    return ValveNull(off, dr, gain, what, tm, method=_method(holds, n_held, n_act))


def still_holds(u: np.ndarray, v: np.ndarray, fs: float) -> list[slice]:
    """The record's still stretches at its start and its end (each at least
    :data:`NULL_LEAD_S`): the first half of its quiet lead-in
    (:func:`sim.calibrate.windows.quiet_lead` of the commands and stroke velocities) and
    the last half of its quiet end (the same, the record reversed); none without a still
    start. A valve's stretch is read where it agrees with the fit (:data:`HELD_AGREES`). Half: the quiet test ends where the motion reaches 5 % of its RMS, and the
    onset's oil compression before that (the pressure that starts the table) is not
    flow through the piston.
    The stroke velocity counts through its running mean over the quiet test's window: a
    transducer differentiated at 1 kHz is noisy (20 um of noise: ~0.03 m/s), the
    motion's onset is not."""
    from sim.calibrate.windows import QUIET_SMOOTH_S, quiet_lead

    w = max(1, int(round(QUIET_SMOOTH_S * fs)))
    slow = np.apply_along_axis(lambda c: np.convolve(c, np.ones(w) / w, mode="same"), 0, np.asarray(v, float))
    n, m = len(u), int(NULL_LEAD_S * fs)
    lead = quiet_lead([u, slow], fs) // 2
    if lead < m or 2 * lead >= n:
        return []
    tail = quiet_lead([u[::-1], slow[::-1]], fs) // 2
    return [slice(0, lead)] + ([slice(n - tail, n)] if m <= tail and 2 * (lead + tail) < n else [])


def _moving_rows(n: int, holds: list) -> np.ndarray:
    """Bool (n,): the rows the fit reads, the still start and end left out (twice each
    hold: the whole quiet stretch). A still stretch shows no gain, and one the controller
    did not hold (the hydraulics off, the command at zero) would read as flow at zero
    velocity: 0.0026 for a 0.004 null on the lab table, 2 s of 6 off."""
    keep = np.ones(n, bool)
    if holds:
        keep[: 2 * holds[0].stop] = False
    if len(holds) > 1:
        keep[n - 2 * (n - holds[1].start) :] = False
    return keep


def _null_held(u, dt, holds: list, drift: bool) -> tuple[float, float]:
    """``(offset at the record's middle, drift)`` from the still stretches: the lead-in's
    alone (no drift), or the lead-in's and the end's (the drift between them). Over each,
    the null is minus the mean command: what holds the table still passes no flow. (Not
    corrected by the stroke's change over the stretch: read off two displacement samples
    of 20 um noise it was 0.1-0.3e-4 of rated opening over 2.6 s, on a still table.)"""
    n0, t0 = -float(np.mean(u[holds[0]])), float(np.mean(dt[holds[0]]))
    if len(holds) < 2 or not drift:
        return n0, 0.0
    n1, t1 = -float(np.mean(u[holds[1]])), float(np.mean(dt[holds[1]]))
    d = (n1 - n0) / (t1 - t0)
    return n0 - d * t0, d


def _method(holds: list, n_held: int, n_act: int) -> str:
    if not n_held:
        return "fit"
    where = "lead-in" if len(holds) == 1 else "lead-in and end"
    return where if n_held == n_act else f"{where}, {n_held} of {n_act} valves (the others: the fit)"


def _one_null(u, v, dt, drift: bool, declared: float, run, i) -> tuple[float, float, float]:
    """One actuator's ``(gain, offset, drift)`` from ``v = K (u + offset + drift dt)``.

    The intercept is the velocity at zero command; divided by the gain it is the null. On
    an actuator the test left still (a vertical test's horizontal valves, commands of
    2e-4), the gain read off the record is noise (0.005 +/- 1.2 m/s where the valve
    gives 1.7) and the null it gave, 1e-2 of rated opening, replayed open loop, pushed an
    internal force the closed loop never held (the vertical load cells' replay error
    0.07 -> 0.15-0.33 on clean CGS runs, a leakage then accepted in its place). Where the gain
    is not read within :data:`GAIN_READ_WITHIN`, the declared one divides the intercept.
    (A record that starts still shows its null without a fit: :func:`_null_held`.)"""
    A = np.stack([u, np.ones_like(u)] + ([dt] if drift else []), axis=1)
    coef, *_ = np.linalg.lstsq(A, v, rcond=None)
    K = coef[0]
    if not np.isfinite(K) or abs(K) < 1e-12:
        raise RunFileError(
            f"run file {run.name}: actuator {run.actuators[i]}'s motion does not follow its "
            "valve command (no flow gain); check the valve_command column and its sign in the map"
        )
    if _relative_error(A, v, coef) > GAIN_READ_WITHIN:
        K = declared
        rest, *_ = np.linalg.lstsq(A[:, 1:], v - K * u, rcond=None)
        coef = np.concatenate([[K], rest])
    return float(K), float(coef[1] / K), float(coef[2] / K) if drift else 0.0


def _relative_error(A, v, coef) -> float:
    """The standard error of the fitted gain (``coef[0]``) over its size (white residual)."""
    r = v - A @ coef
    dof = max(len(v) - A.shape[1], 1)
    cov = np.linalg.pinv(A.T @ A) * float(r @ r) / dof
    return float(np.sqrt(max(cov[0, 0], 0.0)) / abs(coef[0]))


def declared_velocity_gain(desc) -> np.ndarray:
    """Each actuator's stroke velocity per unit valve command as ``desc`` declares it
    (m/s): the valve's no-load flow at full opening, ``rated_flow sqrt((p_s - p_t) /
    rated_drop)`` times its flow gain factor, over the piston area. CGS: 1.09 m/s on its
    vertical actuators, where the records read 1.078 under the dead weight."""
    from sim.effects.registry import hydraulics_with

    hp = hydraulics_with(desc)
    drop = (hp.supply_pressure_pa - hp.return_pressure_pa) / hp.rated_drop_pa
    flow = hp.rated_flow_m3_s * np.sqrt(drop) * hp.per_actuator("valve_flow_gain")
    return np.asarray(flow / hp.area_a_m2, float)


def declared_null(desc) -> np.ndarray:
    """Each actuator's valve null offset as ``desc`` declares it (``[servovalve]`` and its
    ``valve_null_offset`` effects), fraction of rated opening."""
    from sim.effects.registry import hydraulics_with

    return np.asarray(hydraulics_with(desc).per_actuator("valve_null_offset"), float)


__all__ = [
    "ValveNull",
    "declared_null",
    "declared_velocity_gain",
    "estimate",
    "internal_basis",
    "still_holds",
    "stroke_velocity",
]
