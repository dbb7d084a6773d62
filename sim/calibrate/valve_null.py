"""A servovalve's null bias (and its drift), estimated from a record before anything
else is compared.

A real valve passes flow at zero command when its spool's null is off by a fraction
``delta`` of its rated opening (a torque-motor offset, a null that drifts with oil
temperature). In closed loop the controller hides it: the recorded command settles at
``-delta`` to keep the table still. Replayed open loop through a model whose valve has no
such offset, that command drives the piston at a steady ``K delta`` and the model runs to
its end stop. The estimate: each actuator's stroke velocity ``v`` against its recorded
command ``u`` by least squares, ``v = K (u + delta0 + delta1 (t - t_mid))``, i.e. the mean
command that keeps the actuator still, and its linear drift over the record.
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

    def at(self, t: np.ndarray) -> np.ndarray:
        """The offset (len(t), n_act) to add to the recorded command."""
        return self.offset[None, :] + np.outer(np.asarray(t) - self.t_mid, self.drift_per_s)

    def as_dict(self, actuators) -> dict:
        return {
            "offset": {a: float(v) for a, v in zip(actuators, self.offset)},
            "drift_per_s": {a: float(v) for a, v in zip(actuators, self.drift_per_s)},
            "velocity_gain_m_s": {a: (float(v) if np.isfinite(v) else None) for a, v in zip(actuators, self.gain)},
            "velocity_from": self.velocity_from,
            "method": "least squares of stroke velocity on valve command: v = K (u + offset + drift (t - t_mid))",
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


def estimate(run, desc, *, drift: bool = True) -> ValveNull:
    """Least-squares valve null offset (and drift) per actuator of ``run`` (a RunFile
    with ``valve_command`` and a motion channel) on table ``desc``."""
    u = np.asarray(run.valve_command, float)
    v, what = stroke_velocity(run, desc)
    t = np.asarray(run.t, float)
    tm = 0.5 * (t[0] + t[-1])
    n_act = u.shape[1]
    off, dr, gain = np.zeros(n_act), np.zeros(n_act), np.zeros(n_act)
    for i in range(n_act):
        if np.ptp(u[:, i]) < 1e-12 and np.max(np.abs(v[:, i])) < 1e-9:
            # a constant command holding a still actuator: that command is the null itself
            # (no flow gain can be read from such a record, and none is needed)
            off[i], dr[i], gain[i] = -float(u[0, i]), 0.0, float("nan")
            continue
        cols = [u[:, i], np.ones_like(t)] + ([t - tm] if drift else [])
        A = np.stack(cols, axis=1)
        coef, *_ = np.linalg.lstsq(A, v[:, i], rcond=None)
        K = coef[0]
        if not np.isfinite(K) or abs(K) < 1e-12:
            raise RunFileError(
                f"run file {run.name}: actuator {run.actuators[i]}'s motion does not follow its "
                "valve command (no flow gain); check the valve_command column and its sign in the map"
            )
        gain[i] = K
        off[i] = coef[1] / K
        dr[i] = coef[2] / K if drift else 0.0
    return ValveNull(offset=off, drift_per_s=dr, gain=gain, velocity_from=what, t_mid=tm)


def declared_null(desc) -> np.ndarray:
    """Each actuator's valve null offset as ``desc`` declares it (``[servovalve]`` and its
    ``valve_null_offset`` effects), fraction of rated opening."""
    from hydraulics.params import HydraulicParams
    from sim.effects.base import EFFECTS

    hp = HydraulicParams.from_table(desc.raw)
    for e in desc.raw.get("effect", []) or []:
        if isinstance(e, dict) and e.get("type") == "valve_null_offset":
            hp = EFFECTS["valve_null_offset"](e, source=f"{desc.source}: effect").edit_hydraulics(hp)
    return np.asarray(hp.per_actuator("valve_null_offset"), float)


__all__ = ["ValveNull", "declared_null", "estimate", "internal_basis", "stroke_velocity"]
