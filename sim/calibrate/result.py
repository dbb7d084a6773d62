"""What ``shaketable calibrate`` found, as one result (:class:`CalibrationResult`), and the
description entry of an effect it added (:func:`effect_entry`)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class CalibrationResult:
    table: str
    table_source: str
    runs: list
    holdout: list
    holdout_note: str
    residual_path: str
    error_before: float
    error_after: float
    effects_added: list
    candidates: list
    unexplained: dict | None
    per_channel: dict  # holdout NRMSE per run and DOF, before and after
    timing: dict
    #: held-out NRMSE per run (pooled over its excited columns), before and after
    per_run: dict = field(default_factory=dict)
    #: "<run>:<channel or DOF>" the held-out runs do not excite: left out of every error above
    not_excited: list = field(default_factory=list)
    #: the description's [unknown] values identified first (sim/calibrate/unknowns.py)
    unknowns_identified: dict = field(default_factory=dict)
    # arrays for the report (not in the JSON)
    series: dict = field(default_factory=dict, repr=False)
    #: the linear ARX baseline on the same fit and held-out runs (:mod:`sim.calibrate.baseline`)
    baseline: dict | None = None
    #: the calibrated model's held-out error is below the baseline's (None: no baseline)
    beats_baseline: bool | None = None
    #: each residual path's own figures (:func:`sim.calibrate.stages.summary`)
    paths: dict = field(default_factory=dict)

    def searched_paths(self) -> list[str]:
        """The residual paths the search ran on (a path the records could not take is in
        ``paths`` with the reason it was left out)."""
        return [k for k, p in self.paths.items() if "skipped" not in p] or [self.residual_path]

    def to_json(self) -> dict:
        keys = (
            "table",
            "runs",
            "holdout",
            "holdout_note",
            "residual_path",
            "error_before",
            "error_after",
            "effects_added",
            "candidates",
            "unexplained",
            "per_channel",
            "per_run",
            "not_excited",
            "baseline",
            "beats_baseline",
            "timing",
            "unknowns_identified",
            "paths",
        )
        return {k: getattr(self, k) for k in keys}


def effect_entry(e: dict, tag: str) -> tuple[dict, dict]:
    """The description's ``[[effect]]`` entry of an ``effects_added`` item (sourced with
    ``tag``) and the comments of its parameters' lines."""
    opts = e.get("options", {})  # a variant of the effect (friction growing with the stroke)
    entry = {"type": e["name"], "where": e["where"], **opts, **e["parameters"], "source": tag}
    if "label" in e:  # one of several terms of a law at a place (a specimen's modes)
        entry = {"type": e["name"], "where": e["where"], "name": e["label"], **opts, **e["parameters"], "source": tag}
    comments = {
        k: f"+/-{e['uncertainty'][k]:.3g} {e['units'][k]} (95 %)"
        if k in e["uncertainty"]
        else "fixed at its bound (the nested law), not fitted"
        if k in e.get("fixed", {})
        else "held at the description's value, not fitted"
        for k in e["parameters"]
    }
    return entry, comments


__all__ = ["CalibrationResult", "effect_entry"]
