"""A calibration's effects as description entries, the model with them, and that model's
held-out error on a replay or closed-loop path: what the stages (:mod:`sim.calibrate.stages`)
and the refit of the mechanical path's effects on the later path
(:mod:`sim.calibrate.inherited`) both judge by."""

from __future__ import annotations

import copy
import math


def as_entries(effects, tag: str = "calibrated") -> list:
    """The description entries (``[[effect]]`` tables, sourced with ``tag``) of
    ``effects_added`` items."""
    from sim.calibrate.result import effect_entry

    return [effect_entry(e, tag)[0] for e in effects]


def with_effects(desc, entries):
    """``desc`` with the description entries ``entries`` added to its ``[[effect]]`` list."""
    from mjcf.description import parse_table
    from sim.calibrate.paths import build_order

    raw = copy.deepcopy(desc.raw)
    raw["effect"] = build_order(list(raw.get("effect", [])) + [dict(e) for e in entries])
    return parse_table(raw, src=desc.source)


def holdout_error(runs, ho_given, desc, payload, path, entries, workers) -> float:
    """The held-out NRMSE of ``path`` replayed through ``desc`` with ``entries`` added
    (the same held-out runs and scored samples as a stage's own search)."""
    return holdout_errors(runs, ho_given, desc, payload, path, [entries], workers)[0]


def holdout_errors(runs, ho_given, desc, payload, path, entry_sets, workers) -> list[float]:
    """:func:`holdout_error` of each of ``entry_sets``, their replays run together."""
    from sim.calibrate import paths as P
    from sim.calibrate.holdout import split_for_replay

    _fit, ho_runs, score_from, _note = split_for_replay(runs, ho_given)
    pho = P.path_runs(ho_runs, desc, path, score_from=score_from, payload=payload)
    jobs = [p.job(desc.raw, str(desc.source), payload, entries) for entries in entry_sets for p in pho]
    ms = P.simulate_many(jobs, workers=workers)
    out = []
    for k in range(len(entry_sets)):
        mk = ms[k * len(pho) : (k + 1) * len(pho)]
        out.append(math.inf if any(m is None for m in mk) else P.nrmse(pho, mk))
    return out
