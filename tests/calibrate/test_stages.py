"""One search across every residual path the runs support (sim/calibrate/stages.py):
runs that record forces, motion and valve commands are searched on the mechanical path
and then on the replay, with no path named; each effect is found where it shows, and
the mechanical path's effects are kept on the paths' pooled held-out evidence."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from sim.calibrate import search as S
from sim.calibrate import stages as G
from sim.calibrate.paths import holds_total
from sim.calibrate.residuals import CalibrationError, supported_paths
from tests.calibrate.records import noise_run

#: the lab table's planted truth: 600 N bearing friction (a mechanical effect) and a
#: servovalve delay of 4 physics steps at 1024 Hz, 3.906 ms (hydraulic: the force-motion
#: record cannot show it; the effect realises a whole number of steps)
FRICTION_N, DELAY_S = 600.0, 4 / 1024
#: candidate types of these tests: the planted ones and their nearest confusers
EFFECTS = ["coulomb_friction", "viscous_damping", "valve_delay", "valve_bandwidth", "bulk_modulus"]
SECONDS = 3.0


def _channels(**have):
    names = ("actuator_force", "table_displacement", "table_velocity", "table_acceleration")
    names += ("valve_command", "reference")
    return SimpleNamespace(name="r", **{c: (np.zeros((4, 1)) if have.get(c, True) else None) for c in names})


def test_supported_paths_follow_the_channels():
    assert supported_paths([_channels()]) == ["mechanical", "replay", "closed_loop"]
    assert supported_paths([_channels(), _channels(valve_command=False)]) == ["mechanical", "closed_loop"]
    assert supported_paths([_channels(actuator_force=False)]) == ["replay", "closed_loop"]


def test_the_plan_runs_the_mechanical_path_then_one_replay_and_path_narrows():
    assert G.plan([_channels()], None) == ["mechanical", "replay"]
    assert G.plan([_channels(valve_command=False)], None) == ["mechanical", "closed_loop"]
    assert G.plan([_channels(actuator_force=False)], None) == ["replay"]
    assert G.plan([_channels()], "closed_loop") == ["closed_loop"]
    with pytest.raises(CalibrationError, match="lacks valve_command"):
        G.plan([_channels(valve_command=False)], "replay")


def test_a_later_stage_looks_only_for_what_the_mechanical_path_cannot_see():
    assert "coulomb_friction" not in G.stage_effects(None, after_mechanical=True)
    assert "valve_delay" in G.stage_effects(None, after_mechanical=True)
    assert G.stage_effects(["coulomb_friction", "valve_delay"], after_mechanical=True) == ("valve_delay",)
    assert G.stage_effects(["coulomb_friction"], after_mechanical=True) == ()
    assert G.stage_effects(["coulomb_friction"], after_mechanical=False) == ["coulomb_friction"]


def test_pooled_error_is_the_rms_of_the_paths():
    assert G.pool([0.3, 0.4]) == pytest.approx(math.sqrt((0.09 + 0.16) / 2))
    assert G.pool([0.2, None, math.nan]) == pytest.approx(0.2)
    assert math.isnan(G.pool([]))


def test_a_force_record_holding_the_total_in_one_column_is_recognised():
    f = np.zeros((10, 2))
    assert not holds_total(f)
    f[:, 0] = np.arange(10.0)
    assert holds_total(f)
    f[:, 1] = 1.0
    assert not holds_total(f)
    assert not holds_total(f[:, :1])


def _lab_runs(folder, effects, seeds=(1, 2, 3)) -> list[str]:
    """Band-limited white noise (1-25 Hz) closed loop on the stock lab table with
    ``effects`` planted, measured through the built-in 1024 Hz recorder model (seeded):
    valve command, actuator force, table motion."""
    import mjcf
    from mjcf.description import parse_table
    from sim.effects import build_model
    from sim.runs.measure import load_sensors, measure_run
    from sim.runs.runfile import write_run

    base = mjcf.load_table("lab")
    raw = dict(base.raw)
    raw["effect"] = list(raw.get("effect", [])) + [dict(e) for e in effects]
    tm = build_model(parse_table(raw, src=base.source))
    paths = []
    for seed in seeds:
        _res, run = noise_run(tm, seed, SECONDS, band_hz=(1.0, 25.0), rms=2.0)
        run.meta.pop("table_description", None)  # a recorder writes the table's name, not the truth
        run.meta.pop("table_sha256", None)
        paths.append(str(write_run(folder / f"lab_{seed}.run.npz", measure_run(run, load_sensors(), seed=seed))))
    return paths


@pytest.fixture(scope="module")
def planted(tmp_path_factory):
    effects = [
        {"type": "coulomb_friction", "where": "dof:x", "force_n": FRICTION_N},
        {"type": "valve_delay", "where": "class:main", "delay_s": DELAY_S},
    ]
    paths = _lab_runs(tmp_path_factory.mktemp("planted"), effects)
    return S.calibrate(paths, effects=EFFECTS, workers=2)


def test_each_effect_is_found_on_the_path_where_it_shows(planted):
    res = planted
    assert res.residual_path == "mechanical + replay"
    found = {(e["name"], e["path"]): e for e in res.effects_added}
    assert set(found) == {("coulomb_friction", "mechanical"), ("valve_delay", "replay")}, res.effects_added
    fr, vd = found[("coulomb_friction", "mechanical")], found[("valve_delay", "replay")]
    for e, key, truth in ((fr, "force_n", FRICTION_N), (vd, "delay_s", DELAY_S)):
        v, u = e["parameters"][key], e["uncertainty"][key]
        assert abs(v - truth) <= max(u, 0.02 * truth), (e, truth)


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return S.calibrate(_lab_runs(tmp_path_factory.mktemp("clean"), []), effects=EFFECTS, workers=2)


def test_the_held_out_error_falls_to_the_clean_floor_on_every_path(planted, clean):
    """Each path's held-out error falls by more than the acceptance margin and ends at
    the clean runs' floor (the recorder model's noise: 30.7 % mechanical, 18.2 % replay
    measured); the pooled figures are the RMS of the paths'."""
    res = planted
    assert set(res.paths) == {"mechanical", "replay"}
    for name, p in res.paths.items():
        before = p.get("error_before_declared", p["error_before"])
        assert p["error_after"] < (1 - S.HOLDOUT_MARGIN) * before, (name, p)
        assert p["error_after"] < 1.1 * clean.paths[name]["error_after"], (name, p, clean.paths[name])
    mech, rep = res.paths["mechanical"], res.paths["replay"]
    assert res.error_before == pytest.approx(G.pool([mech["error_before"], rep["error_before_declared"]]))
    assert res.error_after == pytest.approx(G.pool([mech["error_after"], rep["error_after"]]))
    assert res.beats_baseline


def test_clean_runs_add_nothing_on_any_path(clean):
    assert clean.residual_path == "mechanical + replay"
    assert clean.effects_added == []
    assert clean.error_after == pytest.approx(clean.error_before)


def test_named_effects_go_to_the_stages_that_can_look_for_them():
    assert G.first_stage(["mechanical", "replay"], ["coulomb_friction", "valve_delay"]) == (
        ["mechanical", "replay"],
        ["coulomb_friction"],
    )
    assert G.first_stage(["mechanical", "replay"], ["valve_delay"]) == (["replay"], ["valve_delay"])
    assert G.first_stage(["mechanical"], ["valve_delay"]) == (["mechanical"], ["valve_delay"])
    assert G.stage_effects(["sensor_gain", "coulomb_friction"], after_mechanical=True) == ("sensor_gain",)


def _result(path, before, after, added):
    return S.CalibrationResult(
        table="lab",
        table_source="lab.toml",
        runs=["a", "b"],
        holdout=["b"],
        holdout_note="",
        residual_path=path,
        error_before=before,
        error_after=after,
        effects_added=[
            {"name": n, "where": "dof:x", "parameters": {"force_n": 1.0}, "uncertainty": {}, "units": {}} for n in added
        ],
        candidates=[],
        unexplained=None,
        per_channel={},
        timing={"total_s": 1.0},
        baseline={"holdout_error": 0.9},
    )


@pytest.mark.parametrize(
    "after, without, kept",
    [
        (0.10, 0.30, True),  # pooled: 0.158 with the friction, 0.354 without: kept
        (0.50, 0.05, False),  # pooled: 0.381 with, 0.285 without: the paths disagree, refused
        (0.33, 0.30, False),  # pooled: 0.275 with, 0.354 without, but the replay 10 % worse with it
    ],
)
def test_the_mechanical_paths_effects_stay_only_on_the_pooled_evidence(monkeypatch, after, without, kept):
    """The mechanical path takes its error 0.4 -> 0.2 with a friction; the replay, started
    from it, ends at ``after``, and at ``without`` when replayed without the friction."""
    first = _result("mechanical", 0.40, 0.20, ["coulomb_friction"])
    second = _result("replay", 0.50, after, ["valve_delay"])
    # searched again on the declared model once the friction is refused: a valve delay again,
    # its value and error its own (not those fitted with the friction in the model)
    again = _result("replay", 0.6, 0.045, ["valve_delay"])
    again.effects_added[0]["parameters"] = {"delay_s": 0.003}
    monkeypatch.setattr(G, "holdout_error", lambda *a: 0.6 if not a[5] else without)
    monkeypatch.setattr(G, "with_effects", lambda desc, entries: len(entries))
    monkeypatch.setattr(G, "refit_first", lambda *a, **k: a[5])  # the refit on the replay: none here
    calls = []

    def search_one(path, desc, effects):
        calls.append((path, desc))
        return first if path == "mechanical" else (second if desc else again)

    kw = {"effects": None, "search_one": search_one, "say": lambda *_: None, "workers": 1}
    res = G.run_stages([], [], None, None, ["mechanical", "replay"], **kw)
    assert res.residual_path == "mechanical + replay"
    assert res.error_before == pytest.approx(G.pool([0.40, 0.6]))
    assert res.paths["replay"]["error_before_declared"] == 0.6
    names = [e["name"] for e in res.effects_added]
    if kept:
        assert names == ["coulomb_friction", "valve_delay"]
        assert res.error_after == pytest.approx(G.pool([0.20, after]))
    else:
        assert names == ["valve_delay"] and res.effects_added[0]["parameters"] == {"delay_s": 0.003}
        assert calls[-1] == ("replay", 0)  # the replay searched again without the friction
        assert res.error_after == pytest.approx(G.pool([0.40, 0.045]))
        assert res.paths["replay"]["error_after"] == 0.045
        assert res.paths["mechanical"]["refused"]
        assert any(c["round"] == "pooled" and not c["accepted"] for c in res.candidates)
    assert res.baseline["holdout_error"] == pytest.approx(0.9)


#: the CGS cases' candidate types: the planted valve delay and its nearest confusers on both paths
CGS_EFFECTS = ["coulomb_friction", "viscous_damping", "valve_flow_gain", "valve_delay", "bulk_modulus", "sensor_delay"]


def _cgs_declared(out, planted):
    """CGS runs (3-axis noise, the 1024 Hz recorder model) with ``planted``. The recorder
    model puts the accelerometers through the table's declared 300 Hz conditioner and the
    runs declare it (``meta.channel_conditioning``, as an imported record does), so every
    path compares through it (before the recorder applied it, these runs had to declare
    "no conditioner" by hand: the mechanical path stood viscous damping in for its lag)."""
    from tests.calibrate.test_calibrate_paths import _cgs_measured

    return _cgs_measured(out, planted)


@pytest.mark.slow
def test_cgs_valve_delay_found_with_the_default_paths(tmp_path):
    """CGS runs with valve commands, forces and motion, every valve 6 physics steps of
    1/2048 s late (each class's own entry: the truth holds them as one description value
    would): with no path named, the mechanical path adds nothing for them (a valve delay
    does not change the force-motion balance) and the replay finds one delay of every
    actuator (``where = "actuators"``; before that place, each class's, one a round), its
    value (the 2.930 ms realised) inside its interval, and nothing else."""
    truth = 6 / 2048
    classes = ("vertical", "lateral", "longitudinal")
    planted = [{"type": "valve_delay", "where": f"class:{c}", "delay_s": truth} for c in classes]
    res = S.calibrate(_cgs_declared(tmp_path, planted), effects=CGS_EFFECTS, workers=2)
    assert res.residual_path == "mechanical + replay"
    found = [(e["name"], e["where"], e["path"]) for e in res.effects_added]
    assert found == [("valve_delay", "actuators", "replay")], found
    for e in res.effects_added:
        assert abs(e["parameters"]["delay_s"] - truth) <= e["uncertainty"]["delay_s"], e
    rep = res.paths["replay"]
    assert rep["error_after"] < (1 - S.HOLDOUT_MARGIN) * rep["error_before_declared"], rep


def test_cgs_clean_runs_add_nothing_with_the_default_paths(tmp_path):
    """The same runs without the delays: neither path adds anything (24 s at load 4-6)."""
    res = S.calibrate(_cgs_declared(tmp_path, []), effects=CGS_EFFECTS, workers=2)
    assert res.residual_path == "mechanical + replay"
    assert res.effects_added == []
    assert res.error_after == res.error_before


def test_the_paths_keep_the_mechanical_effects_they_agree_on_one_by_one(monkeypatch):
    """A friction and a mode from the mechanical path; the replay is worse with both (the
    mode counted twice). Without the mode the paths agree: the friction stays, refitted
    alone (its entry from the refit), the mode is refused with a pooled row."""
    from sim.calibrate import mechsearch

    first = _result("mechanical", 0.80, 0.20, ["coulomb_friction", "payload_mode"])
    first.series = {"terms": ["friction term", "mode term"]}
    second = _result("replay", 0.55, 0.75, [])
    ev = {"with": G.pool([0.20, 0.75]), "without": G.pool([0.80, 0.55]), "without_first": 0.55, "declared": 0.55}
    ev["before"] = ev["without"]

    def refit(res, keep):  # the friction alone: 0.6 mechanical; the mode alone: 0.7
        name = ["coulomb_friction", "payload_mode"][keep[0]]
        e = {"name": name, "where": "dof:x", "parameters": {"force_n": 1040.0}, "uncertainty": {}, "units": {}}
        return (0.6 if keep == [0] else 0.7), [e]

    monkeypatch.setattr(mechsearch, "refit_subset", refit)
    monkeypatch.setattr(G, "holdout_error", lambda *a: 0.18 if a[5][0]["type"] == "coulomb_friction" else 0.9)
    res = G._one_by_one(first, second, ev, ([], [], None, None, 1), lambda *_: None)
    assert [e["name"] for e in res.effects_added] == ["coulomb_friction"]
    assert res.effects_added[0]["parameters"] == {"force_n": 1040.0}
    assert res.paths["mechanical"]["error_after"] == 0.6 and res.paths["replay"]["error_after"] == 0.18
    assert res.error_after == pytest.approx(G.pool([0.6, 0.18]))
    assert [c["name"] for c in res.candidates if c["round"] == "pooled"] == ["payload_mode"]


def test_the_later_path_is_searched_again_on_what_the_mechanical_path_keeps(monkeypatch):
    """As above, with the later path searched again once the mode is refused: it runs on the
    declared model with the refitted friction only, and its result (effects, error) is the
    final one, not the first search's made with the mode in the model."""
    from sim.calibrate import mechsearch

    first = _result("mechanical", 0.80, 0.20, ["coulomb_friction", "payload_mode"])
    first.series = {"terms": ["friction term", "mode term"]}
    second = _result("replay", 0.55, 0.75, ["valve_bandwidth"])
    ev = {"with": G.pool([0.20, 0.75]), "without": G.pool([0.80, 0.55]), "without_first": 0.55, "declared": 0.55}
    ev["before"] = ev["without"]

    def refit(res, keep):
        name = ["coulomb_friction", "payload_mode"][keep[0]]
        e = {"name": name, "where": "dof:x", "parameters": {"force_n": 1040.0}, "uncertainty": {}, "units": {}}
        return (0.6 if keep == [0] else 0.7), [e]

    monkeypatch.setattr(mechsearch, "refit_subset", refit)
    monkeypatch.setattr(G, "holdout_error", lambda *a: 0.18 if a[5][0]["type"] == "coulomb_friction" else 0.9)
    seen = []

    def redo(entries):
        seen.append(entries)
        return _result("replay", 0.55, 0.15, ["valve_delay"])

    res = G._one_by_one(first, second, ev, ([], [], None, None, 1), lambda *_: None, redo)
    assert [[e["type"] for e in s] for s in seen] == [["coulomb_friction"]]
    assert [e["name"] for e in res.effects_added] == ["coulomb_friction", "valve_delay"]
    assert res.paths["replay"]["error_after"] == 0.15
    assert res.error_after == pytest.approx(G.pool([0.6, 0.15]))
