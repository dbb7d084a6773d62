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
whether the model tracks as its table did. The record's set-up, the model's run file
(with the specimen's floor sensors the record declares) and the comparison through the
record's declared conditioning are the open-loop replay's own
(:func:`sim.calibrate.replay.record_model`, :func:`~sim.calibrate.replay.model_run`,
:func:`~sim.calibrate.replay.comparison`): the model's tracking is figured on its
channels as the record's sensors would give them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np


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
    engine: str = "loop"  #: which ran it: the compiled callback route or the Python loop (the same run)

    @property
    def complete(self) -> bool:
        return self.result.incomplete_reason is None

    def summary(self) -> dict:
        return {
            "closed_loop_of": self.source,
            "engine": self.engine,
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


def closed_loop_replay(
    source, *, table: str | None = None, payload: str | None = None, progress: bool = False, engine: str = "callback"
):
    """Run ``source``'s (a run-file path or :class:`~sim.runs.runfile.RunFile`) reference
    closed loop through the model (its carried or given table and payload); a
    :class:`ClosedLoopOutcome`. The model's channels are compared with the record's, and
    its tracking figured, through the chain the record declares
    (:func:`sim.calibrate.replay.comparison`). ``engine``: ``"callback"`` runs it on the
    compiled callback route where the model allows it (:func:`sim.loop.callback.accepts`;
    the same result as the loop, bit for bit), ``"loop"`` on ``Simulation.run``."""
    from sim.calibrate.paths import _closed_loop_setup
    from sim.calibrate.replay import (
        comparison,
        drive_on_the_analog_clock,
        model_run,
        read_record,
        record_channels,
        record_model,
    )

    name, src = read_record(source, "reference")
    rec = record_model(name, src, table, payload, check_actuators=False)
    t, notes = rec.t, []
    reference = drive_on_the_analog_clock(np.asarray(src.reference, float), rec.desc, t, notes, "reference")
    sim, ref = _closed_loop_setup(rec.tm, t, _pose6(reference, src.dofs, len(t)))
    res, engine = _run_closed(sim, ref, progress, engine)
    chans, extras, n = record_channels(res, rec.tm, t, src.dofs, sim.gains.rate_hz)
    meta = {"closed_loop_of": name, "model_tick_hz": sim.gains.rate_hz}
    run = model_run(rec, res, chans, extras, n, f"closed-loop run of {Path(name).name}'s reference", meta, notes)
    rec_d = src.table_displacement[:n] if src.table_displacement is not None else None
    rec_a = src.table_acceleration[:n] if src.table_acceleration is not None else None
    notes += [
        f"{m} not recorded: the record's {m} figures are NaN"
        for m, x in (("table_displacement", rec_d), ("table_acceleration", rec_a))
        if x is None
    ]
    resid, model = comparison(src, run, notes)
    tn = t[:n]
    ref_n = reference[:n]  # on the analog clock, as the motion it is compared with
    return ClosedLoopOutcome(
        run=run,
        result=res,
        source=name,
        model_tracking=tracking_of(tn, ref_n, src.dofs, model["table_displacement"], model["table_acceleration"]),
        record_tracking=tracking_of(tn, ref_n, src.dofs, rec_d, rec_a),
        residual_nrmse=resid,
        notes=notes,
        engine=engine,
    )


def _run_closed(sim, ref, progress: bool, engine: str):
    """(the closed-loop result, the engine that ran it): the callback route when asked
    and accepted, else the Python loop."""
    from sim.loop.callback import accepts, run_callback

    if engine == "callback" and accepts(sim) is None:
        return run_callback(sim, ref, progress=progress), "callback"
    return sim.run(reference=ref, progress=progress), "loop"


__all__ = ["ClosedLoopOutcome", "closed_loop_replay", "tracking_of"]
