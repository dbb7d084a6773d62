"""Which of the mechanical path's effects the later path's evidence keeps, one by one
(:func:`sim.calibrate.stages.run_stages`, when the paths disagree on them together).

Greedy: the effect whose removal gives the lowest pooled held-out error is taken out
(the mechanical path's terms refitted without it, :func:`sim.calibrate.mechsearch.refit_subset`;
the later path replayed on its held-out runs without it), until the paths agree
(:func:`sim.calibrate.stages.agree`). The sensor timing found on the mechanical path is
kept: it is judged on the channels it acts on, there.
"""

from __future__ import annotations


def prune(first, second, ev, ctx) -> tuple[list[int], dict] | None:
    """The indices of ``first.effects_added`` kept and the evidence with only them
    (``ev``'s keys), or None when no subset with a term in it agrees.
    ``ctx = (runs, ho_given, desc, payload, workers)``."""
    from sim.calibrate.stages import agree

    n = len(first.series.get("terms", []))
    keep = list(range(n))
    while len(keep) > 1:
        best = min((_without(first, second, ev, keep, i, ctx) for i in keep), key=lambda b: b[0]["with"])
        ev_k, keep = best
        if agree(ev_k, ev_k["later_with"]):
            return keep, ev_k
    return None


def _without(first, second, ev, keep, i, ctx):
    """The evidence with the terms ``keep`` less ``i`` refitted alone (and every timing
    entry kept): ``(evidence, the indices kept)``; the evidence holds the refitted
    entries under ``"added"``."""
    from sim.calibrate.mechsearch import refit_subset
    from sim.calibrate.search import effect_entry
    from sim.calibrate.stages import entries_of, holdout_error, pool

    runs, ho_given, desc, payload, workers = ctx
    n = len(first.series["terms"])
    rest = [j for j in keep if j != i]
    e_mech, added = refit_subset(first, rest)
    added += first.effects_added[n:]
    kept = [effect_entry(e, "calibrated")[0] for e in added] + entries_of(second)
    e_dyn = holdout_error(runs, ho_given, desc, payload, second.residual_path, kept, workers)
    return {**ev, "with": pool([e_mech, e_dyn]), "mech_with": e_mech, "later_with": e_dyn, "added": added}, rest


__all__ = ["prune"]
