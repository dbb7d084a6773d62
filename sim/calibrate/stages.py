"""One search across every residual path the records support.

A user does not choose where an effect shows. The records decide which paths they
support (:func:`sim.calibrate.residuals.supported_paths`); the search runs them as stages:

1. **mechanical** (recorded forces against recorded motion): mechanical effects, the
   specimen's modes and the force and acceleration sensors' timing are judged here,
   where the evidence is most direct and every fit is a least-squares solve;
2. **replay** of the valve commands (else **closed loop** on the reference): started
   from the model with stage 1's effects in (its force laws and modes refitted there
   first, where that path sees them better: :func:`refit_first`), it looks for what
   stage 1 cannot see: hydraulic and valve effects and the foundation
   (:data:`AFTER_MECHANICAL`). Without stage 1 it looks for everything.

The held-out judgement pools the paths' evidence (:func:`pool`, the RMS of the paths'
held-out NRMSEs): stage 1's effects stay in only when the pooled held-out error with
them is below the pooled error without them (the replay of the held-out runs through
the final model less stage 1's effects), and the later path's own error is not worse
with them by more than the acceptance margin (:func:`agree`). ``--path`` narrows the search to one path.
"""

from __future__ import annotations

import math
from dataclasses import replace

from sim.calibrate.entries import as_entries, holdout_error, with_effects
from sim.calibrate.sensitivity import HYDRAULIC
from sim.errors import UserError

#: effect types the mechanical path cannot see: a later stage looks only for these (the
#: force and acceleration sensors' timing and the specimen's modes are judged on the
#: mechanical path, on the same channels the later stage compares). A sensor's gain or
#: offset is among them: in the balance an accelerometer reading 4 % high is a negative
#: mass (-5.6 t on the NEES-UCSD platen, refused at its bound), while the closed loop or
#: replay compares that channel alone
AFTER_MECHANICAL = HYDRAULIC + ("foundation_mode", "sensor_gain", "sensor_offset")


def pool(errors) -> float:
    """The paths' held-out NRMSEs pooled: their RMS (each path weighs the same)."""
    errors = [e for e in errors if e is not None and math.isfinite(e)]
    return math.sqrt(sum(e * e for e in errors) / len(errors)) if errors else math.nan


def plan(runs, path: str | None) -> list[str]:
    """The stages: ``[path]`` when given (checked against the runs), else the mechanical
    path where every run supports it, then replay (else closed loop)."""
    from sim.calibrate.residuals import check_path, choose_path, supported_paths

    if path:
        return [check_path(runs, path)]
    have = supported_paths(runs)
    if not have:
        choose_path(runs)  # the one-line error naming what the first run lacks
    dynamic = [p for p in ("replay", "closed_loop") if p in have][:1]
    return [p for p in ("mechanical",) if p in have] + dynamic


def on_mechanical(effect: str) -> bool:
    """Whether the mechanical path can look for this effect type (a force law or a
    sensor's timing)."""
    from sim.calibrate.laws import LAWS
    from sim.calibrate.timing import TIMING_EFFECTS

    return effect in LAWS or effect in TIMING_EFFECTS


def stage_effects(effects, after_mechanical: bool):
    """The effect types a stage looks for (None: every one); ``()`` when none is left.
    After the mechanical path: what it cannot see, and any type named in ``effects``
    that it cannot look for."""
    if not after_mechanical:
        return effects
    if not effects:
        return AFTER_MECHANICAL
    return tuple(t for t in effects if t in AFTER_MECHANICAL or not on_mechanical(t))


def first_stage(stages, effects):
    """``(stages, effects of the first)``: with ``effects`` named and a later stage, the
    mechanical path looks only for the named types it can see, and is left out when it
    can see none of them."""
    if not effects or len(stages) < 2 or stages[0] != "mechanical":
        return stages, effects
    mech = [t for t in effects if on_mechanical(t)]
    return (stages, mech) if mech else (stages[1:], effects)


def entries_of(res, tag: str = "calibrated") -> list:
    """The description entries of a result's ``effects_added``."""
    return as_entries(res.effects_added, tag)


def run_stages(runs, ho_given, desc, pl, stages, *, effects, search_one, say, workers):
    """Every stage of ``stages`` in turn (``search_one(path, desc, effects)`` is one
    path's search), stage 1's effects judged on the pooled evidence; the combined
    :class:`~sim.calibrate.search.CalibrationResult` (without the pooled baseline)."""
    stages, first_effects = first_stage(stages, effects)
    first = search_one(stages[0], desc, first_effects)
    if len(stages) == 1:
        return first
    path = stages[1]
    later = stage_effects(effects, after_mechanical=True)
    say(f"{path} path, after the mechanical path: looking for {', '.join(later) or 'nothing'}")
    if not later:
        return first
    first = refit_first(runs, ho_given, desc, pl, path, first, workers=workers, say=say)
    kept = entries_of(first)
    try:
        second = search_one(path, with_effects(desc, kept), later)
    except UserError as e:  # the records do not replay through the model: say so, keep stage 1
        say(f"{path} path left out: {e}")
        first.paths = {first.residual_path: summary(first), path: {"skipped": str(e)}}
        return first
    ev = _pooled_evidence(runs, ho_given, desc, pl, first, second, workers)
    say(
        f"pooled held-out NRMSE (mechanical, {path}): declared {ev['before']:.4f}; with every effect "
        f"{ev['with']:.4f}; without the mechanical path's {ev['without']:.4f}"
    )
    if kept and not agree(ev, second.error_after):

        def redo(entries):  # the later path searched again on what stage 1 keeps
            say(f"{path} path searched again, with only the mechanical path's effects kept")
            return search_one(path, with_effects(desc, entries), later)

        return _one_by_one(first, second, ev, (runs, ho_given, desc, pl, workers), say, redo)
    return combine(first, second, ev)


def refit_first(runs, ho_given, desc, pl, path, first, *, workers, say):
    """``first`` with its force laws placed where the later ``path`` tells a tie apart
    (:func:`sim.calibrate.placement.place_on_later`) and, with its modes, refitted there,
    where its columns see them better (:func:`sim.calibrate.inherited.refit_inherited`)."""
    from sim.calibrate.inherited import refit_inherited
    from sim.calibrate.placement import place_on_later

    if not first.effects_added:
        return first
    first = place_on_later(runs, ho_given, desc, pl, path, first, workers=workers, say=say)
    added = refit_inherited(runs, ho_given, desc, pl, path, first.effects_added, workers=workers, say=say)
    return replace(first, effects_added=added)


def _one_by_one(first, second, ev, ctx, say, redo=None):
    """The paths disagree on stage 1's effects together: keep the subset of its terms
    they agree on (:func:`prune`), else refuse them all. ``redo(entries)``: the later
    path's search again on the declared model with ``entries`` (what stage 1 keeps): its
    effects were fitted with the refused ones in the model, and their values (and which
    of them pass) are not the final model's; None keeps them as found (the later path's
    held-out error then measured without the refused ones)."""
    pr = prune(first, second, ev, ctx) if first.series.get("terms") else None
    if pr is None:
        return _disagree(first, second, ev, say, redo)
    keep, ev_k = pr
    n = len(first.series["terms"])
    why = (
        f"refused on the pooled evidence (the paths disagree on it): without it pooled {ev_k['with']:.4f}, "
        f"the {second.residual_path} path {ev_k['later_with']:.4f} (with every effect {ev['with']:.4f}, "
        f"{second.error_after:.4f})"
    )
    rows = []
    for j, e in enumerate(first.effects_added[:n]):
        if j not in keep:
            say(f"  {e['name']} at {e['where']}: {why}")
            row = {"round": "pooled", "name": e["name"], "where": e["where"], "explained_fraction": 0.0}
            row.update(parameters=e["parameters"], uncertainty=e["uncertainty"], holdout_error=ev_k["later_with"])
            rows.append({**row, "accepted": False, "reason": why})
    added = ev_k["added"]  # the terms kept, refitted without the others, and the timing
    first = replace(first, effects_added=added, error_after=ev_k["mech_with"], candidates=first.candidates + rows)
    first.per_channel, first.per_run = {}, {}  # measured with every term: not this model's
    if redo is None:
        second = replace(second, error_after=ev_k["later_with"], per_channel={}, per_run={})
    else:
        from sim.calibrate.result import effect_entry

        second = redo([effect_entry(e, "calibrated")[0] for e in added])
        ev_k = {**ev_k, "later_with": second.error_after, "with": pool([ev_k["mech_with"], second.error_after])}
    return combine(first, second, ev_k)


def prune(first, second, ev, ctx) -> tuple[list[int], dict] | None:
    """Which of the mechanical path's effects the later path's evidence keeps, one by one
    (when the paths disagree on them together). Greedy: the effect whose removal gives the
    lowest pooled held-out error is taken out (the mechanical path's terms refitted without
    it, :func:`sim.calibrate.mechsearch.refit_subset`; the later path replayed on its
    held-out runs without it), until the paths agree (:func:`agree`). The sensor timing
    found on the mechanical path is kept: it is judged on the channels it acts on, there.
    Returns the indices of ``first.effects_added`` kept and the evidence with only them
    (``ev``'s keys), or None when no subset with a term in it agrees.
    ``ctx = (runs, ho_given, desc, payload, workers)``."""
    n = len(first.series.get("terms", []))
    keep = list(range(n))
    while len(keep) > 1:
        best = min((_prune_one(first, second, ev, keep, i, ctx) for i in keep), key=lambda b: b[0]["with"])
        ev_k, keep = best
        if agree(ev_k, ev_k["later_with"]):
            return keep, ev_k
    return None


def _prune_one(first, second, ev, keep, i, ctx):
    """The evidence with the terms ``keep`` less ``i`` refitted alone (and every timing
    entry kept): ``(evidence, the indices kept)``; the evidence holds the refitted
    entries under ``"added"``."""
    from sim.calibrate.mechsearch import refit_subset

    runs, ho_given, desc, payload, workers = ctx
    n = len(first.series["terms"])
    rest = [j for j in keep if j != i]
    e_mech, added = refit_subset(first, rest)
    added += first.effects_added[n:]
    kept = as_entries(added) + entries_of(second)
    e_dyn = holdout_error(runs, ho_given, desc, payload, second.residual_path, kept, workers)
    return {**ev, "with": pool([e_mech, e_dyn]), "mech_with": e_mech, "later_with": e_dyn, "added": added}, rest


def agree(ev: dict, later_after: float) -> bool:
    """Whether the paths' evidence keeps stage 1's effects: the pooled held-out error is
    lower with them, and the later path's is not worse with them than without by more
    than the acceptance margin (an effect that is physically there does not make another
    path's replay worse: a mode found on the mechanical path of a frame the replay
    already models as flexible counts it twice, 55 % -> 74 % on the replay, measured)."""
    from sim.calibrate.acceptance import HOLDOUT_MARGIN

    return ev["with"] < ev["without"] and later_after <= (1 + HOLDOUT_MARGIN) * ev["without_first"]


def _pooled_evidence(runs, ho_given, desc, pl, first, second, workers) -> dict:
    """The two paths' held-out errors: the declared model's, the final model's, and the
    final model's without stage 1's effects (stage 2 replayed without them)."""
    path = second.residual_path
    e_decl = holdout_error(runs, ho_given, desc, pl, path, [], workers)
    without = (
        holdout_error(runs, ho_given, desc, pl, path, entries_of(second), workers) if first.effects_added else None
    )
    dyn_without = second.error_after if without is None else without
    return {
        "path": path,
        "declared": e_decl,
        "without_first": dyn_without,
        "before": pool([first.error_before, e_decl]),
        "with": pool([first.error_after, second.error_after]),
        "without": pool([first.error_before, dyn_without]),
    }


def summary(res) -> dict:
    """One path's figures for ``calibration.json``'s ``paths``."""
    return {
        "holdout": res.holdout,
        "error_before": res.error_before,
        "error_after": res.error_after,
        "effects_added": [f"{e['name']} at {e['where']}" for e in res.effects_added],
        "per_run": res.per_run,
        "per_channel": res.per_channel,
        "not_excited": res.not_excited,
        "baseline_error": (res.baseline or {}).get("holdout_error"),
        "beats_baseline": res.beats_baseline,
    }


def _tagged(rows, path: str) -> list:
    return [{**r, "path": path} for r in rows]


def combine(first, second, ev, first_kept: bool = True):
    """The result of two stages: the pooled errors at the top, each path's in ``paths``;
    the per-column figures, the series and the baseline's columns of the last stage."""
    p1, p2 = first.residual_path, second.residual_path
    s1 = summary(first)
    if not first_kept:
        s1.update(error_after=first.error_before, effects_added=[], refused="the paths disagree (pooled evidence)")
    s2 = {**summary(second), "error_before_declared": ev["declared"]}
    if not first_kept and not ev.get("redone"):  # the later path's effects on the declared model alone (measured)
        s2.update(error_after=ev["without_first"], per_channel={}, per_run={})
    out = replace(
        second,
        runs=first.runs,
        residual_path=f"{p1} + {p2}",
        error_before=ev["before"],
        error_after=ev["with"] if first_kept else pool([first.error_before, ev["without_first"]]),
        effects_added=_tagged(first.effects_added if first_kept else [], p1) + _tagged(second.effects_added, p2),
        candidates=_tagged(first.candidates, p1) + _tagged(second.candidates, p2),
        unexplained=second.unexplained or first.unexplained,
        timing={p1: first.timing, p2: second.timing},  # the total: set by the caller (search.calibrate)
        paths={p1: s1, p2: s2},
        baseline=_pooled_baseline(first, second),
    )
    from sim.calibrate.baseline import beats

    out.beats_baseline = beats(out.error_after, out.baseline)
    return out


def _disagree(first, second, ev, say, redo=None):
    """Stage 1's effects refused on the pooled evidence: the final model is stage 2's
    effects on the declared model (its held-out error measured, ``ev["without_first"]``),
    searched again there by ``redo`` when given."""
    why = (
        f"refused on the pooled evidence (the paths disagree): pooled {ev['with']:.4f} with, {ev['without']:.4f} "
        f"without; the {second.residual_path} path {second.error_after:.4f} with, {ev['without_first']:.4f} without"
    )
    say(f"  the mechanical path's effects {why}")
    for e in first.effects_added:
        row = {"round": "pooled", "name": e["name"], "where": e["where"], "explained_fraction": 0.0}
        row.update(parameters=e["parameters"], uncertainty=e["uncertainty"], holdout_error=ev["without_first"])
        first.candidates.append({**row, "accepted": False, "reason": why})
    if redo is not None:
        second = redo([])
        ev = {**ev, "without_first": second.error_after, "redone": True}
    return combine(first, second, ev, first_kept=False)


def _pooled_baseline(first, second) -> dict | None:
    """The last stage's baseline with its held-out error replaced by the paths' pooled one."""
    b1, b2 = first.baseline, second.baseline
    if not b1 or not b2:
        return b2
    per_path = {first.residual_path: b1.get("holdout_error"), second.residual_path: b2.get("holdout_error")}
    return {**b2, "holdout_error": pool(per_path.values()), "per_path": per_path}


__all__ = [
    "AFTER_MECHANICAL",
    "combine",
    "entries_of",
    "holdout_error",
    "plan",
    "pool",
    "run_stages",
    "stage_effects",
    "summary",
    "with_effects",
]
