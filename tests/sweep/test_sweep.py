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
    loc = run_sweep(sw, tmp_path / "local", workers=2)
    assert res["ran"] == 4
    assert [r["limiting_utilisation"] for r in res["rows"]] == [r["limiting_utilisation"] for r in loc["rows"]]
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
