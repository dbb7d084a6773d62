"""Run a sweep: every case of a :class:`sim.sweep.spec.Sweep`, one results table.

The per-task function is a plain library call, :func:`run_cases`: each case planned by
:func:`sim.assess.run.plan_scenario` with its overrides, then all simulated together by
:func:`sim.assess.many.run_plans` (the route feasibility suites and calibration
candidates share: :class:`sim.loop.batch.BatchRunner`, MuJoCo's batch with the coupled
step compiled as MuJoCo's control callback), then each assessed. The cases are dealt out
in tasks (:mod:`sim.sweep.split`: worker processes x batch threads, cases per task and
per batch, chosen from the cores and the case count unless given). Executors:

* ``local``: a pool of worker processes on this machine (one process: this one), each
  task one :func:`run_cases` in a worker;
* ``dask``: each task one :func:`run_cases` on a Dask cluster (``dask.distributed``): a
  scheduler address, or a ``LocalCluster`` of the split's processes when none is given.

The parent only deals the tasks and writes the rows. Each finished case is written at
once, atomically, to ``OUT/cases/<id>.json`` (plus its run file with ``run_files``); a
case whose file exists is not run again, so an interrupted sweep resumes where it
stopped. At the end every case file goes into ``OUT/results.csv`` (and
``results.parquet`` when pyarrow is installed). The rows do not depend on the split:
every case's simulation is its own single run, bit for bit (``tests/sweep/test_split.py``).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
import time
from pathlib import Path

from sim.errors import UserError

EXECUTORS = ("local", "dask")


def run_cases(
    scenario, cases, *, duration_s=None, start_s=None, iterations=None, run_dir=None, nthread: int = 1, batch=32
) -> list:
    """Cases of one scenario (one task): each planned with its ``overrides``, then
    simulated in batches of ``batch`` cases (:func:`sim.assess.many.run_plans`: MuJoCo's
    batch on ``nthread`` threads where the table allows, the plan's own run otherwise;
    the same runs as :func:`sim.assess.run.run_scenario`); returns one row per case, in
    order (varied values, verdict, limiting utilisation, timing). A case the inputs make
    impossible (a user error, e.g. divergence before the second sample) gives a row with
    ``error`` instead of raising, so one bad case does not stop a sweep. ``case_wall_s``
    is the task's wall time shared equally among its cases."""
    from sim.assess.many import run_plans
    from sim.assess.run import plan_scenario
    from sim.scenario.files import load_scenario

    t0 = time.perf_counter()
    plans, rows = [], {}
    motions = None  # the scenario's motions, built once for the worker when no case changes them
    if not any(k.split(".")[0] == "motion" for c in cases for k in c.overrides):
        try:
            motions = scenario_motions(load_scenario(scenario) if isinstance(scenario, (str, Path)) else scenario)
        except UserError:
            motions = None  # each case's plan reports it
    for c in cases:
        try:
            p = plan_scenario(
                scenario,
                duration_s=duration_s,
                start_s=start_s,
                iterations=iterations,
                overrides=c.overrides,
                engine="callback",
                motions=motions,
            )
            plans.append((c, p))
        except UserError as e:
            rows[c.id] = e
    outs = run_plans([p for _, p in plans], nthread=nthread, group=batch)
    for (c, _), o in zip(plans, outs):
        rows[c.id] = o
    wall = (time.perf_counter() - t0) / max(len(cases), 1)
    result = []
    for c in cases:
        o = rows[c.id]
        if isinstance(o, UserError):
            result.append(error_row(c, str(o), wall))
            continue
        try:
            result.append(outcome_row(c, o, run_dir, wall))
        except UserError as e:
            result.append(error_row(c, str(e), wall))
    return result


_MOTIONS: dict = {}  #: this process's motions of the last scenarios it ran (a worker runs many tasks of one)


def scenario_motions(sc) -> dict:
    """``build_motions(sc)``, kept for the next task of the same scenario in this process
    (a record's processing is a tenth of a second of a short case); keyed by the file,
    its modification time and the motion table."""
    from sim.scenario.files import build_motions

    try:
        stamp = Path(sc.path).stat().st_mtime_ns if sc.path else None
    except OSError:
        stamp = None
    key = (str(sc.path), stamp, repr(sc.motion), sc.sample_rate_hz)
    if key not in _MOTIONS:
        if len(_MOTIONS) >= 4:
            _MOTIONS.clear()
        _MOTIONS[key] = build_motions(sc)
    return _MOTIONS[key]


def run_case(scenario, case, *, duration_s=None, start_s=None, iterations=None, run_dir=None) -> dict:
    """One case (:func:`run_cases` of one): its row."""
    return run_cases(scenario, [case], duration_s=duration_s, start_s=start_s, iterations=iterations, run_dir=run_dir)[
        0
    ]


#: checks that do not depend on the simulation: the rated envelope of the demanded motion
#: (``sim.assess.feasibility.envelope_checks``) and the static specimen checks
_DEMAND = re.compile(r"^(stroke|velocity|acceleration|rotation)_(x|y|z|rx|ry|rz)$|^(specimen_mass|support_load)$")


def is_demand_check(name: str) -> bool:
    """A check of the demanded motion's envelope or a static specimen check (not from the
    simulation)."""
    return bool(_DEMAND.match(name))


def simulated_limiting(checks: list) -> tuple[str, float]:
    """The most used capability check among those computed from the simulation (not the
    demanded motion's envelope nor the static specimen checks; not the tracking checks,
    which are not part of the verdict either) and its utilisation; ("", nan) without any."""
    from sim.assess.feasibility import is_tracking

    run = [
        c
        for c in checks
        if not is_demand_check(c["name"]) and not is_tracking(c) and c["utilisation"] == c["utilisation"]
    ]
    if not run:
        return "", math.nan
    c = max(run, key=lambda c: float(c["utilisation"]))
    return c["name"], float(c["utilisation"])


def error_row(case, message, wall) -> dict:
    return {
        "id": case.id,
        **case.values,
        "feasible": False,
        "limiting": "error",
        "limiting_utilisation": math.inf,
        "complete": False,
        "error": message,
        "case_wall_s": wall,
    }


def outcome_row(case, out, run_dir, wall) -> dict:
    """The results-table row of a :class:`sim.assess.run.RunOutcome` (a run stopped by
    Ctrl-C is no case result: the interrupt goes on up, nothing is written for it)."""
    if getattr(out.result, "interrupted", False):
        raise KeyboardInterrupt
    s = out.summary
    f = s["feasibility"]
    row = {
        "id": case.id,
        **case.values,
        "feasible": bool(f["feasible"]),
        "limiting": f["limiting"],
        "limiting_utilisation": (
            float(f["limiting_utilisation"]) if f["limiting_utilisation"] is not None else math.nan
        ),
        "failed": ";".join(f["failed"]),
        "run_limiting": "",
        "run_limiting_utilisation": math.nan,
        "complete": bool(s["complete"]),
        "incomplete_reason": s["incomplete_reason"] or "",
        "duration_s": s["duration_s"],
        "sim_wall_s": s["wall_s"],
        "case_wall_s": wall,
        "error": "",
    }
    row["run_limiting"], row["run_limiting_utilisation"] = simulated_limiting(f["checks"])
    for c in f["checks"]:  # one column per kind of check ("actuator_force_X3" -> util_actuator_force)
        name = c["name"]
        kind = "_".join(name.split("_")[:2]) if name.startswith("actuator_") else name
        u = float(c["utilisation"])
        row[f"util_{kind}"] = max(u, row.get(f"util_{kind}", -math.inf))
    if run_dir is not None:
        from sim.runs.files import out_dir
        from sim.runs.runfile import write_run

        path = out_dir(run_dir) / f"{case.id}.run.npz"
        write_run(path, out.run)
        row["run_file"] = str(path)
    return row


def _case_path(out: Path, case) -> Path:
    return out / "cases" / f"{case.id}.json"


def _kw(sweep, out):
    return dict(
        duration_s=sweep.duration_s,
        start_s=sweep.start_s,
        iterations=sweep.iterations,
        run_dir=out / "runs" if sweep.run_files else None,
    )


def _tasks(todo: list, split) -> list:
    from sim.sweep.split import deal

    return deal(todo, split)


def _local(sweep, todo, out, split, done_cb):
    """The tasks on a pool of ``split.processes`` worker processes (this process alone
    for one), each task's rows written as it finishes."""
    from functools import partial

    from sim.parallel import iter_jobs

    tasks = _tasks(todo, split)
    fn = partial(run_cases, sweep.scenario, nthread=split.threads, batch=split.batch, **_kw(sweep, out))
    for i, rows in iter_jobs(fn, tasks, workers=split.processes):
        for c, row in zip(tasks[i], rows):
            done_cb(c, row)


def _dask(sweep, todo, out, split, address, done_cb):
    """The tasks on a Dask cluster: the scheduler at ``address``, or a ``LocalCluster``
    of ``split.processes`` single-threaded worker processes (each task's batch brings
    its own ``split.threads``)."""
    import dask
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if address is None:
        # a case holds its worker's GIL for seconds; on a loaded machine heartbeats come
        # late: no time-to-live, so a slow worker is waited for, not restarted
        with dask.config.set({"distributed.scheduler.worker-ttl": None}):
            cluster = LocalCluster(
                n_workers=split.processes, threads_per_worker=1, processes=True, dashboard_address=":0"
            )
        address = cluster
    client = Client(address)
    try:
        tasks = _tasks(todo, split)
        futs = {
            client.submit(
                run_cases,
                sweep.scenario,
                task,
                nthread=split.threads,
                batch=split.batch,
                pure=False,
                key=f"cases-{sweep.name}-{task[0].id}-{task[-1].id}",
                **_kw(sweep, out),
            ): task
            for task in tasks
        }
        for fut in as_completed(futs):
            for c, row in zip(futs[fut], fut.result()):
                done_cb(c, row)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _dask_workers(address) -> int | None:
    """The worker processes of the Dask scheduler at ``address`` (None: not reachable
    now; the split then assumes this machine's cores)."""
    try:
        from dask.distributed import Client

        with Client(address, timeout="10s") as c:
            return max(1, len(c.scheduler_info()["workers"]))
    except Exception:  # noqa: BLE001 - any failure to ask is reported by the run itself
        return None


def sweep_split(sweep, n_cases: int, *, workers=None, executor="local", address=None, **given):
    """The :class:`~sim.sweep.split.Split` of a run of ``n_cases`` cases: ``given``
    (``processes``, ``threads``, ``task``, ``batch``: CLI flags) over the sweep file's
    ``task`` and ``batch``, the rest chosen for ``workers`` cores (default this
    machine's; with an external Dask scheduler, its workers)."""
    from sim.sweep.split import choose_split

    task = given["task"] if given.get("task") is not None else sweep.task
    batch = given["batch"] if given.get("batch") is not None else sweep.batch
    procs, cores = given.get("processes"), workers
    if executor == "dask" and address is not None and procs is None:
        procs = _dask_workers(address)
        cores = cores or (procs * (given.get("threads") or 1) if procs else None)
    return choose_split(n_cases, cores=cores, processes=procs, threads=given.get("threads"), task=task, batch=batch)


def run_sweep(
    sweep,
    out,
    *,
    workers: int | None = None,
    executor: str = "local",
    address: str | None = None,
    processes: int | None = None,
    threads: int | None = None,
    task: int | None = None,
    batch: int | None = None,
    progress=None,
) -> dict:
    """Run every case of ``sweep`` not yet in ``out``; write the results table.

    ``workers``: the cores to use (default: all of this machine's); ``processes``,
    ``threads``, ``task``, ``batch``: the split (:func:`sim.sweep.split.choose_split`;
    ``task`` and ``batch`` default to the sweep file's). ``address``: a Dask scheduler
    to submit to instead of a local cluster. ``progress(done, total)`` is called after
    each case. Returns ``{"cases", "ran", "skipped", "wall_s", "table", "rows", "split", ...}``.
    """
    from sim.runs.files import out_dir, write_json_atomic

    if executor not in EXECUTORS:
        raise UserError(f"--executor must be one of {', '.join(EXECUTORS)} (got '{executor}')")
    cases = sweep.cases()
    _check_cases(sweep, cases)
    todo = [c for c in cases if not _case_path(Path(out), c).exists()]
    split = sweep_split(
        sweep,
        len(todo),
        workers=workers,
        executor=executor,
        address=address,
        processes=processes,
        threads=threads,
        task=task,
        batch=batch,
    )  # a bad split fails here, before anything is written
    out = out_dir(out)
    (out / "cases").mkdir(exist_ok=True)
    skipped = len(cases) - len(todo)
    n_done = [skipped]
    if progress:
        progress(skipped, len(cases))

    def done(case, row):
        write_json_atomic(_case_path(out, case), row)
        n_done[0] += 1
        if progress:
            progress(n_done[0], len(cases))

    t0 = time.perf_counter()
    if todo:
        if executor == "local":
            _local(sweep, todo, out, split, done)
        else:
            _dask(sweep, todo, out, split, address, done)
    wall = time.perf_counter() - t0
    rows = [json.loads(_case_path(out, c).read_text()) for c in cases]
    table = write_table(out, rows)
    info = {
        "sweep": sweep.name,
        "scenario": sweep.scenario,
        "cases": len(cases),
        "ran": len(todo),
        "skipped": skipped,
        "executor": executor,
        "workers": split.processes * split.threads,
        "split": {"processes": split.processes, "threads": split.threads, "task": split.task, "batch": split.batch},
        "varied": [v.name for v in sweep.vary],
        "wall_s": wall,
        "table": str(table),
    }
    write_json_atomic(out / "sweep.json", info)
    return {**info, "rows": rows}


def _check_cases(sweep, cases) -> None:
    """Every case has the same keys: a bad key fails here, on the first and last case,
    before any run."""
    from sim.assess.run import check_overrides

    where = str(sweep.path or sweep.name)
    for c in cases[:1] + cases[-1:]:
        try:
            check_overrides(sweep.scenario, c.overrides)
        except UserError as e:
            raise UserError(f"{where}: case {c.id}: {e}") from None


def write_table(out: Path, rows: list) -> Path:
    """``results.csv`` (always) and ``results.parquet`` (with pyarrow); returns the
    Parquet path when written, else the CSV path."""
    from sim.runs.files import write_text_atomic

    cols = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in cols})
    write_text_atomic(out / "results.csv", buf.getvalue())
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return out / "results.csv"
    tbl = pa.Table.from_pylist([{k: r.get(k) for k in cols} for r in rows])
    tmp = out / ".results.parquet.tmp"
    pq.write_table(tbl, tmp)
    os.replace(tmp, out / "results.parquet")
    return out / "results.parquet"


class ProgressLine:
    """A progress bar on a terminal; one line per ``every`` cases otherwise."""

    def __init__(self, stream, every: int = 10):
        self.stream, self.every = stream, max(1, every)
        self.tty = hasattr(stream, "isatty") and stream.isatty()
        self.t0 = time.perf_counter()

    def __call__(self, done: int, total: int) -> None:
        el = time.perf_counter() - self.t0
        if self.tty:
            bar = "#" * int(30 * done / max(total, 1))
            self.stream.write(f"\r  [{bar:<30s}] {done}/{total} cases  {el:7.1f} s")
            if done == total:
                self.stream.write("\n")
        elif done % self.every == 0 or done == total:
            self.stream.write(f"  {done}/{total} cases  {el:.1f} s\n")
        self.stream.flush()


__all__ = [
    "EXECUTORS",
    "ProgressLine",
    "error_row",
    "outcome_row",
    "run_case",
    "run_cases",
    "run_sweep",
    "simulated_limiting",
    "sweep_split",
    "write_table",
]
