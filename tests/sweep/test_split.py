"""How a sweep is dealt out (sim.sweep.split): the split chosen from the cores and the
case count, the user's overrides, the sweep file's keys, and rows (and run files) that
do not depend on the split, case for case."""

import os

import numpy as np
import pytest

from sim.cli import main
from sim.errors import UserError
from sim.parallel import usable_cores
from sim.sweep.run import run_sweep
from sim.sweep.spec import SweepError, load_sweep
from sim.sweep.split import choose_split, deal
from tests.sweep.test_sweep import SCENARIO, SWEEP

#: columns that time the run (wall clock): the only ones the split may change
TIMING = ("case_wall_s", "sim_wall_s", "run_file")


@pytest.fixture()
def sweep_file(tmp_path):
    (tmp_path / "sine_20t.toml").write_text(SCENARIO)
    p = tmp_path / "tiny.toml"
    p.write_text(SWEEP.replace("iterations = 0", "iterations = 0\nrun_files = true"))
    return p


def test_the_split_puts_processes_first_and_deals_about_four_tasks_each():
    s = choose_split(64, cores=2)
    assert (s.processes, s.threads, s.task, s.batch) == (2, 1, 8, 8)
    s = choose_split(256, cores=16)
    assert (s.processes, s.threads, s.task, s.batch) == (16, 1, 4, 4)
    s = choose_split(1000, cores=16)
    assert (s.processes, s.task) == (16, 16)
    assert choose_split(100_000, cores=4).task == 32  # at most 32 cases redone after an interruption
    assert choose_split(3, cores=16).processes == 3  # never more processes than cases
    assert choose_split(0, cores=4).processes == 1  # a resumed sweep with nothing left


def test_tasks_shrink_at_the_end_so_no_worker_waits_on_a_long_last_task():
    s = choose_split(256, cores=16)
    tasks = deal(list(range(256)), s)
    assert [c for t in tasks for c in t] == list(range(256))  # every case once, in order
    sizes = [len(t) for t in tasks]
    assert max(sizes) == s.task and sizes == sorted(sizes, reverse=True)
    assert sizes[-s.processes :] == [1] * s.processes  # the last round: one case each
    threaded = choose_split(64, cores=16, threads=4)
    assert min(len(t) for t in deal(list(range(64)), threaded)) == 4  # a batch still fills its threads


def test_the_default_cores_are_the_ones_this_process_may_run_on():
    if not hasattr(os, "sched_getaffinity"):
        pytest.skip("no affinity mask on this platform")
    assert usable_cores() == len(os.sched_getaffinity(0))
    one = next(iter(os.sched_getaffinity(0)))
    every = os.sched_getaffinity(0)
    os.sched_setaffinity(0, {one})  # as `taskset -c N` would start it
    try:
        assert choose_split(64).processes == 1
    finally:
        os.sched_setaffinity(0, every)


def test_the_user_overrides_any_part_of_the_split():
    s = choose_split(64, cores=16, processes=4)
    assert (s.processes, s.threads) == (4, 4) and s.task >= 4  # the cores left to each process
    s = choose_split(64, cores=16, threads=4)
    assert (s.processes, s.threads) == (4, 4)
    s = choose_split(64, cores=2, task=10, batch=5)
    assert (s.task, s.batch) == (10, 5)
    assert choose_split(64, cores=2, task=4, batch=9).batch == 4  # a batch is part of a task
    for bad in ({"processes": 0}, {"threads": -1}, {"task": 1.5}, {"cores": 0}):
        with pytest.raises(UserError, match="must be a positive integer"):
            choose_split(8, **bad)


def _runs(rows) -> dict:
    out = {}
    for r in rows:
        with np.load(r["run_file"], allow_pickle=False) as z:
            out[r["id"]] = {k: z[k] for k in z.files}
    return out


def test_rows_and_run_files_do_not_depend_on_the_split(tmp_path, sweep_file):
    """One process with one batch of 4 on one thread (the reference), two worker
    processes with a task each case, one process with batches of 2 on 2 threads: the same
    rows and run files, case for case, bit for bit."""
    sw = load_sweep(sweep_file)
    splits = {
        "one": dict(processes=1, threads=1, task=4),
        "procs": dict(processes=2, threads=1, task=1),
        "threads": dict(processes=1, threads=2, task=2, batch=2),
    }
    res = {k: run_sweep(sw, tmp_path / k, **v) for k, v in splits.items()}
    assert res["procs"]["split"] == {"processes": 2, "threads": 1, "task": 1, "batch": 1}
    ref = res["one"]["rows"]
    assert len(ref) == 4 and all(r["complete"] and r["error"] == "" for r in ref)
    ref_runs = _runs(ref)
    for k in ("procs", "threads"):
        rows = res[k]["rows"]
        assert [r["id"] for r in rows] == [r["id"] for r in ref]
        for a, b in zip(rows, ref):
            assert {c: v for c, v in a.items() if c not in TIMING} == {c: v for c, v in b.items() if c not in TIMING}
        for cid, arrays in _runs(rows).items():
            for name, x in arrays.items():
                assert np.array_equal(x, ref_runs[cid][name], equal_nan=x.dtype.kind == "f"), (k, cid, name)


def test_the_old_group_key_reads_as_task_with_a_warning(tmp_path, sweep_file, capsys):
    text = sweep_file.read_text()
    old = tmp_path / "old.toml"
    old.write_text(text.replace("iterations = 0", "iterations = 0\ngroup = 3"))
    sw = load_sweep(old)
    assert (sw.task, sw.batch) == (3, None)
    assert len(sw.warnings) == 1 and str(old) in sw.warnings[0] and "write 'task = 3'" in sw.warnings[0]
    both = tmp_path / "both.toml"
    both.write_text(text.replace("iterations = 0", "iterations = 0\ngroup = 3\ntask = 2"))
    with pytest.raises(SweepError, match="'sweep.group' and 'sweep.task' both given"):
        load_sweep(both)
    big = tmp_path / "big.toml"
    big.write_text(text.replace("iterations = 0", "iterations = 0\ntask = 2\nbatch = 4"))
    assert main(["sweep", str(big), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'sweep.batch' (4) is more than 'sweep.task' (2)" in err[0]
    assert main(["sweep", str(sweep_file), "--out", str(tmp_path / "o"), "--processes", "0"]) == 2
    assert "--processes must be a positive integer" in capsys.readouterr().err
    assert main(["sweep", str(sweep_file), "--out", str(tmp_path / "o"), "--task", "0"]) == 2
    assert "task (cases per task) must be a positive integer" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()  # nothing written
