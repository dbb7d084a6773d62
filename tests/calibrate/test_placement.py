"""Which places tied with a mechanical path's effect (issue #23): the rows that passed and
lost only on the tie-break, the same law with the same options and fixed part."""

from __future__ import annotations

from sim.calibrate.placement import tied_places

WON = "passed, not added: spring at actuator:Z1 has a held-out error within 5 % of it and the whiter residual"


def _row(name, where, reason, **kw):
    row = {"round": 1, "name": name, "where": where, "explained_fraction": 0.8272, "holdout_error": 0.0391}
    return {**row, "accepted": False, "reason": reason, **kw}


def test_the_places_that_lost_on_the_tie_break_only():
    effect = {"name": "spring", "where": "actuator:Z1", "parameters": {"stiffness_n_m": 5.5e5}}
    rows = [
        {**_row("spring", "actuator:Z1", ""), "accepted": True},
        _row("spring", "dof:z", WON),
        _row("spring", "class:vertical", WON),
        _row("spring", "dof:z", WON),  # seen again in a later round: once
        _row("spring", "dof:x", "passed, not added: spring at actuator:Z1 explains more (judged first)"),
        _row("spring", "actuator:Z2", "held-out error 0.1 -> 0.2 rose"),
        _row("viscous_damping", "dof:z", WON.replace("spring", "viscous_damping", 1)),
        _row("spring", "dof:rx", WON, options={"from_payload": True}),
        _row("spring", "actuator:Z3", WON.replace("Z1", "Z2")),  # lost to another place
    ]
    assert tied_places(rows, effect) == ["dof:z", "class:vertical"]
    assert tied_places(rows[:1], effect) == []


def test_one_of_several_modes_at_a_place_is_left_where_it_is():
    effect = {"name": "payload_mode", "where": "payload", "label": "payload_mode 2", "parameters": {}}
    rows = [_row("payload_mode", "dof:x", WON.replace("spring at actuator:Z1", "payload_mode at payload"))]
    assert tied_places(rows, effect) == []
    assert tied_places(rows, {k: v for k, v in effect.items() if k != "label"}) == ["dof:x"]


def test_the_report_says_when_no_path_told_the_places_apart():
    from sim.calibrate.search import CalibrationResult
    from sim.report.calibration import report_md

    effect = {"name": "spring", "where": "actuator:Z1", "parameters": {"stiffness_n_m": 5.5e5}}
    effect.update(uncertainty={"stiffness_n_m": 8e3}, units={"stiffness_n_m": "N/m"}, path="mechanical")
    rows = [_row("spring", "dof:z", WON), _row("spring", "class:vertical", WON)]
    res = CalibrationResult(
        table="cgs",
        table_source="cgs.toml",
        runs=["a.run.npz", "b.run.npz"],
        holdout=["b.run.npz"],
        holdout_note="held out: b.run.npz",
        residual_path="mechanical",
        error_before=0.129,
        error_after=0.039,
        effects_added=[effect],
        candidates=rows,
        unexplained=None,
        per_channel={},
        timing={"total_s": 1.0, "read_s": 0.1, "residuals_s": 0.2, "search_s": 0.7, "least_squares_fits": 3},
    )
    md = report_md(res, [], "cgs_calibrated.toml")
    assert "`spring` at actuator:Z1: dof:z, class:vertical explained it as well" in md
    res.effects_added = [{**effect, "where": "dof:z", "placed_on": "replay"}]
    md = report_md(res, [], "cgs_calibrated.toml")
    assert "no later path told them apart" not in md and "the replay path's held-out error chose this one" in md


def test_places_the_later_path_does_not_tell_apart_either():
    """The vertical supports test's replay (measured): Z1 0.1280, z, the class and the
    supports 0.0522 each. z is chosen (the lowest); the class and the supports stay tied
    (within the margin of it) and the report says so; Z1 does not."""
    from sim.calibrate.placement import still_tied
    from sim.report.calibration import _later_path_notes

    wheres = ["actuator:Z1", "dof:z", "class:vertical", "supports"]
    errs = [0.1280, 0.05220, 0.05221, 0.05224]
    assert still_tied(wheres, errs, 1) == ["class:vertical", "supports"]
    assert still_tied(wheres, [0.1280, 0.0522, 0.060, 0.070], 1) == []
    from types import SimpleNamespace

    e = {"name": "spring", "where": "dof:z", "placed_on": "replay", "tied_on_later": ["class:vertical", "supports"]}
    lines = _later_path_notes(SimpleNamespace(effects_added=[e]))
    assert any("class:vertical, supports held out within the margin of it on the later path too" in x for x in lines)
