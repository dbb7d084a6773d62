"""Which runs, or which part of a run, the search fits and which it holds out."""

from __future__ import annotations

from pathlib import Path


def split_holdout(runs, holdout_runs):
    """Fit and held-out runs; with none given, every third run (from the second) is held
    out (one run: its last 30 %)."""
    if holdout_runs:
        return runs, holdout_runs, "given with --holdout"
    if len(runs) >= 2:
        ho = [r for i, r in enumerate(runs) if i % 3 == 1]
        fit = [r for i, r in enumerate(runs) if i % 3 != 1]
        return fit, ho, "held out (no --holdout): " + ", ".join(Path(r.name).name for r in ho)
    r = runs[0]
    cut = int(0.7 * r.n_samples)
    return (
        [slice_run(r, 0, cut, "fit part")],
        [slice_run(r, cut, r.n_samples, "held-out part")],
        f"held out (one run, no --holdout): the last 30 % of {Path(r.name).name} (from t = {r.t[cut]:.2f} s)",
    )


def slice_run(r, a: int, b: int, label: str):
    """Samples [a, b) of a run, as a run of its own (named after the part)."""
    import dataclasses

    from sim.runs.runfile import CHANNELS

    kw = {c: (getattr(r, c)[a:b].copy() if getattr(r, c) is not None else None) for c in CHANNELS}
    out = dataclasses.replace(r, t=r.t[a:b].copy(), extras={}, **kw)
    out.path = f"{r.name} ({label})"
    return out


def split_for_replay(runs, ho_given):
    """Fit and held-out runs; with one run, the held-out part is its last 30 % of the same
    replay (a replay cannot start mid-record: the state there is unknown)."""
    if ho_given:
        return runs, ho_given, {}, "given with --holdout"
    if len(runs) >= 2:
        ho = [r for i, r in enumerate(runs) if i % 3 == 1]
        fit = [r for i, r in enumerate(runs) if i % 3 != 1]
        return fit, ho, {}, "held out (no --holdout): " + ", ".join(Path(r.name).name for r in ho)
    r = runs[0]
    cut = int(0.7 * r.n_samples)
    note = (
        f"held out (one run, no --holdout): the last 30 % of {Path(r.name).name} (from t = {r.t[cut]:.2f} s; "
        "replayed from the start, scored after the cut)"
    )
    return [slice_run(r, 0, cut, "fit part")], [r], {r.name: cut}, note


__all__ = ["slice_run", "split_for_replay", "split_holdout"]
