"""A record's reference run closed loop through the model (``shaketable replay --closed-loop``).

The record's ``reference`` (the pose its controller was asked to follow) goes through the
model's own controller, as the calibration's closed-loop path runs it
(:func:`sim.calibrate.paths._closed_loop_setup`: the reference on the controller's
ticks, its velocity and acceleration by 9-point stencils); the model's channels are
sampled back at the record's instants (:func:`sim.calibrate.replay.record_channels`)
and written as a run file. Beside it stand two sets of tracking figures per commanded
DOF (:func:`sim.assess.metrics.tracking`: displacement and acceleration NRMSE against
the reference, PGA ratio): the model's (its table motion against the reference) and the
record's own (the measured table motion against the same reference), so that a lab sees
whether the model tracks as its table did.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim.errors import RunFileError


@dataclass
class ClosedLoopOutcome:
    """The model's run at the record's instants, the loop's result and both trackings."""

    run: object
    result: object
    source: str
    model_tracking: dict
    record_tracking: dict
    residual_nrmse: dict = field(default_factory=dict)  #: model against record, per channel and column
    notes: list = field(default_factory=list)

    @property
    def complete(self) -> bool:
        return self.result.incomplete_reason is None

    def summary(self) -> dict:
        return {
            "closed_loop_of": self.source,
            "record_rate_hz": self.run.sample_rate_hz,
            "complete": self.complete,
            "incomplete_reason": self.result.incomplete_reason,
            "realtime_factor": float(self.result.realtime_factor),
            "tracking": {"model": self.model_tracking, "record": self.record_tracking},
            "residual_nrmse": self.residual_nrmse,
            "notes": self.notes,
        }


def _pose6(values, dofs, n) -> np.ndarray:
    """(n, 6) of a run's DOF columns (zeros in the DOFs it does not have)."""
    from mjcf.description import DOFS6

    out = np.zeros((n, 6))
    if values is not None:
        for j, d in enumerate(dofs):
            out[:, DOFS6.index(d)] = np.asarray(values, float)[:n, j]
    return out


def tracking_of(t, reference, dofs, displacement, acceleration) -> dict:
    """:func:`sim.assess.metrics.tracking` of a run's motion (its DOF columns; None when
    not recorded: NaN figures) against its reference (DOF columns)."""
    from sim.assess.metrics import tracking
    from sim.calibrate.paths import reference_derivatives

    n = len(t)
    ref = _pose6(reference, dofs, n)
    _, ref_a = reference_derivatives(ref, float(t[1] - t[0]))
    nan = np.full((n, 6), np.nan)
    d = _pose6(displacement, dofs, n) if displacement is not None else nan
    a = _pose6(acceleration, dofs, n) if acceleration is not None else nan
    return tracking(t, ref, ref_a, d, a)


def closed_loop_replay(source, *, table: str | None = None, payload: str | None = None, progress: bool = False):
    """Run ``source``'s (a run-file path) reference closed loop through the model (its
    carried or given table and payload); a :class:`ClosedLoopOutcome`."""
    from mjcf.description import DOFS6
    from sim.calibrate.paths import _closed_loop_setup
    from sim.calibrate.replay import record_channels, residuals
    from sim.effects import build_model
    from sim.runs.build import build_runfile
    from sim.runs.runfile import RunFile, payload_of, read_run, table_of

    name = str(source)
    src = read_run(source, require=("reference",))
    desc = table_of(src, table)
    bad = [d for d in src.dofs if d not in DOFS6]
    if bad:
        raise RunFileError(f"{name}: DOF column(s) {bad} are not DOF names ({', '.join(DOFS6)}); fix meta.dofs")
    pl = payload_of(src, payload)
    tm = build_model(desc, pl)
    t = np.asarray(src.t, float) - float(src.t[0])
    sim, ref = _closed_loop_setup(tm, t, _pose6(src.reference, src.dofs, len(t)))
    res = sim.run(reference=ref, progress=progress)
    chans, extras, n = record_channels(res, tm, t, src.dofs, sim.gains.rate_hz)
    chans["reference"] = np.asarray(src.reference[:n], float).copy()
    tick_run = build_runfile(
        res, tm, description=f"closed-loop run of {Path(name).name}'s reference", payload_name=pl.name if pl else None
    )
    meta = dict(tick_run.meta)
    meta.update({"sample_rate_hz": src.sample_rate_hz, "dofs": list(src.dofs), "closed_loop_of": name})
    meta["model_tick_hz"] = sim.gains.rate_hz
    run = RunFile(t=np.asarray(src.t[:n], float).copy(), meta=meta, extras=extras, **chans)
    if res.incomplete_reason:
        run.mark_incomplete(res.incomplete_reason)
    tn = t[:n]
    model = tracking_of(tn, src.reference[:n], src.dofs, chans["table_displacement"], chans["table_acceleration"])
    rec_d = src.table_displacement[:n] if src.table_displacement is not None else None
    rec_a = src.table_acceleration[:n] if src.table_acceleration is not None else None
    record = tracking_of(tn, src.reference[:n], src.dofs, rec_d, rec_a)
    notes = [
        f"{m} not recorded: the record's {m} figures are NaN"
        for m, x in (("table_displacement", rec_d), ("table_acceleration", rec_a))
        if x is None
    ]
    return ClosedLoopOutcome(
        run=run,
        result=res,
        source=name,
        model_tracking=model,
        record_tracking=record,
        residual_nrmse=residuals(src, run),
        notes=notes,
    )


__all__ = ["ClosedLoopOutcome", "closed_loop_replay", "tracking_of"]
