"""Sweeps: sweep files, resume, the local batch and the Dask executor, CLI errors."""

import json

import numpy as np
import pytest

from sim.cli import main
from sim.sweep.run import run_sweep
from sim.sweep.spec import SweepError, load_sweep

SCENARIO = """
[scenario]
name = "sine_20t"
table = "cgs"
payload = "rigid_20t"
duration_s = 1.0
description = "test: 4 Hz sine in x, 20 t block"
[motion.x]
type = "sine"
amplitude = 0.005
frequency_hz = 4.0
"""

SWEEP = """
[sweep]
name = "tiny"
scenario = "sine_20t.toml"
duration_s = 0.1
iterations = 0
mode = "grid"

[[vary]]
name = "bulk_modulus_pa"
key = "table.fluid.bulk_modulus_pa"
values = [0.8e9, 1.2e9]

[[vary]]
name = "mass_factor"
keys = ["payload.mass_kg", "payload.inertia_kg_m2"]
scale = true
values = [1.0, 1.25]
"""


@pytest.fixture()
def sweep_file(tmp_path):
    (tmp_path / "sine_20t.toml").write_text(SCENARIO)
    p = tmp_path / "tiny.toml"
    p.write_text(SWEEP)
    return p


def test_grid_and_random_cases(tmp_path, sweep_file):
    sw = load_sweep(sweep_file)
    cases = sw.cases()
    assert [c.values for c in cases] == [
        {"bulk_modulus_pa": b, "mass_factor": m} for b in (0.8e9, 1.2e9) for m in (1.0, 1.25)
    ]
    assert cases[1].overrides == {
        "table.fluid.bulk_modulus_pa": 0.8e9,
        "payload.mass_kg": {"scale": 1.25},
        "payload.inertia_kg_m2": {"scale": 1.25},
    }
    r = tmp_path / "r.toml"
    r.write_text(
        SWEEP.replace('mode = "grid"', 'mode = "random"\nn = 5\nseed = 3')
        .replace("values = [0.8e9, 1.2e9]", 'distribution = "uniform"\nlow = 0.8e9\nhigh = 1.2e9')
        .replace("values = [1.0, 1.25]", 'distribution = "lognormal"\nmean = 0.0\nstd = 0.2')
    )
    a, b = load_sweep(r).cases(), load_sweep(r).cases()
    assert len(a) == 5 and [c.values for c in a] == [c.values for c in b]  # the seed fixes the draws
    bm = np.array([c.values["bulk_modulus_pa"] for c in a])
    assert np.all((bm >= 0.8e9) & (bm < 1.2e9)) and len(set(bm)) == 5


def test_local_sweep_resumes_without_redoing_cases(tmp_path, sweep_file):
    out = tmp_path / "out"
    sw = load_sweep(sweep_file)
    first = run_sweep(sw, out, workers=2)
    assert first["ran"] == 4 and first["skipped"] == 0
    rows = first["rows"]
    assert all(r["complete"] and r["error"] == "" for r in rows)
    # a heavier block needs more force: the varied inputs reached the runs
    f = {(r["bulk_modulus_pa"], r["mass_factor"]): r["util_actuator_force"] for r in rows}
    assert f[(0.8e9, 1.25)] > f[(0.8e9, 1.0)]
    # the limiting check among those from the simulation: not an envelope/specimen check, at most the overall
    for r in rows:
        assert r["run_limiting"] and not r["run_limiting"].startswith(("stroke_", "velocity_", "acceleration_"))
        assert 0 < r["run_limiting_utilisation"] <= r["limiting_utilisation"]
        assert r["run_limiting_utilisation"] == r[f"util_{'_'.join(r['run_limiting'].split('_')[:2])}"] or not r[
            "run_limiting"
        ].startswith("actuator_")
    # the batch gives each case its single run: compare one case with run_scenario
    from sim.sweep.run import run_case

    single = run_case(sw.scenario, sw.cases()[3], duration_s=sw.duration_s, iterations=0)
    assert single["limiting_utilisation"] == rows[3]["limiting_utilisation"]
    # interrupted after two cases: the other two are lost, the first two are kept
    keep = out / "cases" / f"{rows[0]['id']}.json"
    stamp = keep.stat().st_mtime_ns
    for r in rows[2:]:
        (out / "cases" / f"{r['id']}.json").unlink()
    again = run_sweep(sw, out, workers=2)
    assert again["ran"] == 2 and again["skipped"] == 2
    assert keep.stat().st_mtime_ns == stamp
    assert [r["limiting_utilisation"] for r in again["rows"]] == [r["limiting_utilisation"] for r in rows]
    text = (out / "results.csv").read_text().splitlines()
    assert len(text) == 5 and text[0].startswith("id,bulk_modulus_pa,mass_factor,feasible")


@pytest.mark.slow  # ~35 s: starting a two-process LocalCluster dominates
def test_dask_local_cluster_runs_a_tiny_sweep(tmp_path, sweep_file):
    pytest.importorskip("dask.distributed")
    sw = load_sweep(sweep_file)
    res = run_sweep(sw, tmp_path / "dask", workers=2, executor="dask")
    loc = run_sweep(sw, tmp_path / "local", processes=1, task=4)
    assert res["ran"] == 4 and res["split"]["processes"] == 2  # a LocalCluster of two worker processes
    timing = ("case_wall_s", "sim_wall_s")
    for a, b in zip(res["rows"], loc["rows"], strict=True):  # the same results table, case for case
        assert {k: v for k, v in a.items() if k not in timing} == {k: v for k, v in b.items() if k not in timing}
    assert json.loads((tmp_path / "dask" / "sweep.json").read_text())["executor"] == "dask"


@pytest.mark.parametrize(
    "edit, words",
    [
        (lambda s: s.replace('mode = "grid"', 'mode = "grids"'), "'sweep.mode'"),
        (lambda s: s.replace("values = [0.8e9, 1.2e9]", "values = []"), "needs 'values'"),
        (lambda s: s.replace("iterations = 0", "iterations = 0\nspeed = 2"), "unknown key 'sweep.speed'"),
        (lambda s: s.replace('"table.fluid.bulk_modulus_pa"', '"table.fluid.bulk_modulus"'), "names no value"),
    ],
)
def test_bad_sweep_file_is_one_line_exit_2(tmp_path, sweep_file, capsys, edit, words):
    sweep_file.write_text(edit(SWEEP))
    out = tmp_path / "o"
    code = main(["sweep", str(sweep_file), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and words in lines[0]
    assert "Traceback" not in err
    assert not (out / "results.csv").exists()


def test_load_sweep_names_the_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("[sweep]\nscenario = 3\n")
    with pytest.raises(SweepError, match="bad.toml: 'sweep.scenario'"):
        load_sweep(p)


def test_start_s_places_the_window_and_the_default_keeps_the_strong_motion(tmp_path):
    """One windowing mechanism (build_window): a duration alone keeps a record's strong
    motion; scenario.start_s / start_s= place the same tapered window elsewhere; a start
    past the motion is a one-line scenario error."""
    from dataclasses import replace

    from sim.errors import ScenarioError
    from sim.scenario.files import build_motions, build_window, load_scenario

    sc = load_scenario("elcentro_20t")
    motions = build_motions(sc)
    strong_ref, strong = build_window(sc, motions, 4.0)
    assert "strong motion" in strong["why"] and strong["start_s"] > 0
    ref, win = build_window(sc, motions, 4.0, start_s=10.0)
    assert win["start_s"] == pytest.approx(10.0) and win["end_s"] == pytest.approx(14.0)
    assert "start_s = 10" in win["why"] and len(ref.t) == len(strong_ref.t)
    # the file's key does the same, and the argument wins over it
    sc2 = replace(sc, start_s=strong["start_s"])
    ref2, win2 = build_window(sc2, motions, 4.0)
    assert win2["start_s"] == strong["start_s"] and np.array_equal(ref2.d, strong_ref.d)
    assert build_window(sc2, motions, 4.0, start_s=10.0)[1]["start_s"] == pytest.approx(10.0)
    # the window is the record's motion between the tapers, at rest at both ends
    rate = sc.sample_rate_hz
    i = int(round(2.0 * rate))  # mid-window (the taper is 0.8 s)
    x = motions["x"]
    assert ref.d[i, 0] == pytest.approx(x.d[int(round(10.0 * rate)) + i], abs=1e-12)
    assert abs(ref.d[0, 0]) < 1e-12 and abs(ref.d[-1, 0]) < 1e-12
    with pytest.raises(ScenarioError, match="past the end of the motion"):
        build_window(sc, motions, 4.0, start_s=x.duration_s - 1.0)
    bad = tmp_path / "bad.toml"
    bad.write_text(SCENARIO.replace("duration_s = 1.0", "duration_s = 1.0\nstart_s = -2.0"))
    with pytest.raises(ScenarioError, match="scenario.start_s"):
        load_scenario(bad)


def test_run_plans_equals_each_plans_own_run():
    """The shared route (sim.assess.many.run_plans): batchable plans with other table
    parameters and a plan it cannot batch (the analog-controller table) together, each
    outcome equal to the plan's own run, in order."""
    from sim.assess.many import batchable, run_plans
    from sim.assess.run import plan_scenario

    def plans():
        return [
            plan_scenario("elcentro_20t", duration_s=0.15, iterations=0, engine="callback"),
            plan_scenario("rice_sine", duration_s=0.1),
            plan_scenario(
                "elcentro_20t",
                duration_s=0.15,
                iterations=0,
                engine="callback",
                overrides={"table.fluid.bulk_modulus_pa": 0.7e9, "payload.mass_kg": {"scale": 1.2}},
            ),
        ]

    together = run_plans(plans(), nthread=2)
    alone = [p.run() for p in plans()]
    assert [batchable(p) for p in plans()] == [True, False, True]
    for a, b in zip(together, alone):
        assert a.result.channels.keys() == b.result.channels.keys()
        for k in a.result.channels:
            assert np.array_equal(a.result.channels[k], b.result.channels[k]), k
        assert a.summary["feasibility"]["limiting_utilisation"] == b.summary["feasibility"]["limiting_utilisation"]
    # the overrides reached the third run
    assert not np.array_equal(
        together[0].result.channels["actuator_force"], together[2].result.channels["actuator_force"]
    )


def test_feasibility_suite_runs_its_cases_together_with_each_cases_own_verdict():
    """The suite stages every case, runs the simulations together on run_plans (the
    batch), and gives each case the verdict of its own assess()."""
    import mjcf
    from sim.assess import study

    pay = mjcf.load_payload("rigid_20t")
    rows = study.suite("cgs", ["elcentro1940"], [0.3, 0.6], [pay], window_s=1.0, nthread=2, processes=1)
    assert [r["scale"] for r in rows] == [0.3, 0.6] and all(r["simulated"] for r in rows)
    # a worker process per case (each its own task, one thread): the same rows
    assert study.suite("cgs", ["elcentro1940"], [0.3, 0.6], [pay], window_s=1.0, nthread=1, processes=2) == rows
    for r in rows:
        alone = study.assess(
            study.Case(table="cgs", motion="elcentro1940", payload=pay, scale=r["scale"], window_s=1.0)
        )
        assert alone["limiting"] == r["limiting"]
        assert alone["limiting_utilisation"] == r["limiting_utilisation"]
    assert rows[1]["limiting_utilisation"] > rows[0]["limiting_utilisation"]
    # and these cases did go to the batch (not each plan's own loop)
    from sim.assess.many import batchable

    case = study.Case(table="cgs", motion="elcentro1940", payload=pay, scale=0.3, window_s=1.0)
    pre, plan = study.stage(study.prepare(case), 0.3)
    assert pre is None and batchable(plan)


def test_report_gives_both_distributions(tmp_path):
    """report.md: percentiles of the overall and of the simulated limiting utilisation
    (failed cases apart), the limiting checks counted, and the two-panel histogram."""
    import math

    from sim.sweep.report import summarize, write_report

    rows = [
        {
            "id": f"{i}",
            "error": "",
            "feasible": True,
            "limiting": "stroke_y",
            "limiting_utilisation": 0.83,
            "run_limiting": "actuator_force" if i % 4 else "oil_flow",
            "run_limiting_utilisation": 0.1 + 0.01 * i,
            "mass": 1.0 + i,
            "util_actuator_force": 0.05 * (1.0 + i),  # grows with the mass: correlation +1
        }
        for i in range(20)
    ]
    rows.append(
        {"id": "bad", "error": "diverged", "feasible": False, "limiting": "error", "limiting_utilisation": math.inf}
    )
    r = summarize(rows, "run_limiting_utilisation", "run_limiting")
    assert r["simulated"] == 20 and r["utilisation"]["min"] == pytest.approx(0.1)
    assert r["utilisation"]["max"] == pytest.approx(0.29) and r["limiting"] == {"actuator_force": 15, "oil_flow": 5}
    info = {"sweep": "t", "scenario": "s", "ran": 21, "skipped": 0, "executor": "local", "workers": 1, "wall_s": 1.0}
    info["varied"] = ["mass"]
    text = write_report(tmp_path, info, rows).read_text()
    assert "median 0.83" in text and "checks computed from the simulation" in text and "median 0.195" in text
    assert "actuator_force 15, oil_flow 5" in text and "errors: 1" in text
    assert "| actuator_force | 0.05 | " in text and "| corr. mass |" in text and "| +1.00 |" in text
    assert (tmp_path / "limiting_utilisation.png").stat().st_size > 1000
