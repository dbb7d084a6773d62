"""Where a force law acts, when the mechanical path cannot tell: the later path places it.

The mechanical path fits each law at every place it may act and keeps the one that
explains most; a place whose held-out error is within the margin of the winner's ties
with it, and the whiter residual breaks the tie. On a test that moves one DOF, places
that push that DOF alike tie exactly: a vertical test on CGS holds the rotations to
~2e-5 rad, so a spring at one vertical actuator, at the four of the class or along z
explains the same (82.72 % each, measured). The replay does not hold the rotations: there
a spring at one corner tilts the platen and loads its own actuator, and the record shows
it. Measured (the supports' air springs twice as stiff, 3 x 4 s of vertical noise): held
out on the replay 0.0968 declared, 0.0522 with the spring along z or at the class, 0.127
at actuator Z1, where the mechanical path had put it; the replay then took two horizontal
valve nulls in its place (compensations).

So before the later path refits what it inherits, each law whose place tied is moved to
the tied place the later path's held-out error prefers, refitted there on the mechanical
path (the same fit, the same evidence there, within the margin).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sim.calibrate.entries import as_entries, holdout_errors


def place_on_later(runs, ho_given, desc, payload, path, first, *, workers, say):
    """``first`` (the mechanical stage's result) with each law whose place tied
    (:func:`tied_places`) moved to the tied place with the lowest held-out error on the
    later ``path``; that effect carries ``placed_on``. Unchanged where nothing tied."""
    terms = list(first.series.get("terms") or [])
    for i in range(len(terms)):
        alts = tied_places(first.candidates, first.effects_added[i])
        if not alts:
            continue
        fits = [_moved(first, i, w) for w in [first.effects_added[i]["where"], *alts]]
        timing = first.effects_added[len(terms) :]
        sets = [as_entries(_added(fit, first) + timing) for fit in fits]
        errs = holdout_errors(runs, ho_given, desc, payload, path, sets, workers)
        k = int(np.argmin(errs))
        e, wheres = first.effects_added[i], [first.effects_added[i]["where"], *alts]
        say(
            f"{path} path: {e['name']} at {e['where']} tied on the mechanical path with "
            f"{', '.join(alts)}; held out here "
            + ", ".join(f"{w} {x:.4f}" for w, x in zip(wheres, errs))
            + ("" if k == 0 else f": placed at {alts[k - 1]}")
        )
        if k:
            first = _with_fit(first, fits[k], path, i)
        still = still_tied(wheres, errs, k)
        if still:
            first.effects_added[i]["tied_on_later"] = still
    return first


def still_tied(wheres: list, errs: list, k: int) -> list[str]:
    """The places the later path does not tell from the chosen ``wheres[k]`` either: a
    held-out error within the acceptance margin of its (a vertical test holds the
    rotations on the replay too: along z, at the vertical class and at the supports a
    spring replays 0.0522 each, measured)."""
    from sim.calibrate.acceptance import HOLDOUT_MARGIN

    return [w for j, (w, x) in enumerate(zip(wheres, errs)) if j != k and x <= (1 + HOLDOUT_MARGIN) * errs[k]]


def tied_places(candidates: list, effect: dict) -> list[str]:
    """The places where the same law (its options and fixed part alike) passed and lost to
    ``effect`` only on the tie-break: a held-out error within the margin of its
    (:func:`sim.calibrate.mechjudge.forward_round`'s reason). None for one of several
    terms of a law at a place (a specimen's modes): the rows do not say which one won."""
    if "label" in effect:
        return []
    lost = f"passed, not added: {effect['name']} at {effect['where']} has a held-out error within"
    out = []
    for r in candidates:
        same = (r.get("options"), r.get("fixed")) == (effect.get("options"), effect.get("fixed"))
        if r["name"] == effect["name"] and same and str(r.get("reason", "")).startswith(lost):
            if r["where"] != effect["where"] and r["where"] not in out:
                out.append(r["where"])
    return out


def _moved(first, i: int, where: str):
    """The mechanical fit with term ``i`` moved to ``where``, the terms refitted together."""
    from sim.calibrate.trace import Term, fit_terms

    terms = list(first.series["terms"])
    t = terms[i]
    terms[i] = Term(t.law, where, dict(t.shape), t.index)
    return fit_terms(first.series["fit"], terms)


def _added(fit, first) -> list:
    from sim.calibrate.mechsearch import added_entries

    return added_entries(fit, first.series["fit"][0])


def _with_fit(first, fit, path: str, i: int):
    """``first`` with ``fit``'s terms: its effects, held-out figures and series."""
    from sim.calibrate.mechsearch import mechanical_errors
    from sim.calibrate.residuals import nrmse_runs
    from sim.calibrate.trace import predict

    s = first.series
    after = predict(s["holdout"], fit)
    per, per_run, quiet = mechanical_errors(s["holdout"], s["before"], after)
    added = _added(fit, first)
    added[i]["placed_on"] = path
    return replace(
        first,
        effects_added=added + first.effects_added[len(fit.terms) :],
        error_after=nrmse_runs(s["holdout"], after),
        per_channel=per,
        per_run=per_run,
        not_excited=quiet,
        series={**s, "terms": list(fit.terms), "after": after, "fit_after": fit.residuals},
    )


__all__ = ["place_on_later", "still_tied", "tied_places"]
