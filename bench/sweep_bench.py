"""The sweep's scaling: cases per second at 1, 2, 4, ... worker processes up to the cores.

    python -m bench.sweep_bench [--cases N] [--duration S] [--no-dask]

The sweep is ``scenarios/sweeps/mc_elcentro_20t.toml``'s Monte Carlo (El Centro 80 % on
the CGS table with the 20 t block; payload mass, bulk modulus and friction drawn from
their distributions) cut to ``--cases`` cases of ``--duration`` s of the strong motion,
each case planned, simulated and assessed as ``shaketable sweep`` does. The efficiency
at P workers is the rate over P x the one-worker rate, both measured in this run (the
one-worker run first; every run starts from a process that has run one case, so
imports and compiled kernels are warm alike: a worker process is forked from it).
Dask: the same sweep on a ``LocalCluster`` of all the cores (its start and one short
warm-up case per worker are timed apart and left out of its rate). The last line is for scripts:
``sweep efficiency (N cases, P workers): X``.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from sim.parallel import usable_cores
from sim.scenario.files import SCENARIOS_DIR

SWEEP = SCENARIOS_DIR / "sweeps" / "mc_elcentro_20t.toml"


def bench_sweep(n_cases: int, duration_s: float):
    """The Monte Carlo sweep file's sweep, ``n_cases`` cases of ``duration_s`` seconds."""
    import dataclasses

    from sim.sweep.spec import load_sweep

    sw = load_sweep(SWEEP)
    return dataclasses.replace(sw, n=n_cases, duration_s=duration_s, name=f"bench_{n_cases}", task=None, batch=None)


def worker_counts(cores: int) -> list[int]:
    """1, 2, 4, ... up to ``cores`` (and ``cores`` itself)."""
    out, p = [], 1
    while p < cores:
        out.append(p)
        p *= 2
    return out + [cores]


def _cpu() -> float:
    """CPU seconds of this process and of its children that have ended (the pool's)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def timed_sweep(sw, out: Path, **split) -> tuple[float, dict]:
    """Wall seconds of one whole sweep into the empty folder ``out``, and its info
    (with ``cpu_s``: the CPU seconds of this process and its worker processes)."""
    from sim.sweep.run import run_sweep

    c0, t0 = _cpu(), time.perf_counter()
    res = run_sweep(sw, out, **split)
    wall = time.perf_counter() - t0
    res["cpu_s"] = _cpu() - c0
    bad = [r["id"] for r in res["rows"] if r.get("error")]
    if bad:
        raise RuntimeError(f"bench sweep: cases {bad[:3]} failed: {res['rows'][0].get('error')}")
    return wall, res


def _spin(n: int) -> int:
    """``n`` steps of plain Python arithmetic: CPU work with no memory traffic."""
    x = 0
    for i in range(n):
        x = (x + i * i) % 1000003
    return x


#: the plain job's steps: about a second on one core here (0.5 s per 3 million on the
#: loaded 2-core machine), long beside forking the workers from the bench's large parent
SPIN_STEPS = 8_000_000


def machine_efficiency(p: int, n: int = SPIN_STEPS) -> float:
    """What this machine gives ``p`` processes now: ``p`` worker processes doing the
    same CPU work as one process (forked from this one, as the sweep's pool), its wall
    time over theirs (1.0: ``p`` cores to ourselves; about 1/p when the scheduler keeps
    this session to one core's share, e.g. Linux's autogroups with other sessions busy)."""
    from sim.parallel import iter_jobs

    t0 = time.perf_counter()
    _spin(n)
    one = time.perf_counter() - t0
    t0 = time.perf_counter()
    for _ in iter_jobs(_spin, [n] * p, workers=p):
        pass
    return one / (time.perf_counter() - t0)


def dask_rate(sw, out: Path, workers: int) -> tuple[float, float]:
    """Cases per second on a ``LocalCluster`` of ``workers`` processes (started, then
    warmed by one short case on every worker: its start timed apart), and the start's
    seconds."""
    import logging
    from functools import partial

    import dask
    from dask.distributed import Client, LocalCluster

    from sim.sweep.run import run_cases

    logging.getLogger("distributed").setLevel(logging.ERROR)  # the nannies' notes at the cluster's close
    t0 = time.perf_counter()
    with dask.config.set({"distributed.scheduler.worker-ttl": None}):
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0")
    with Client(cluster) as client:  # each worker process imports and compiles as the local pool's parent did
        client.run(partial(run_cases, sw.scenario, sw.cases()[:1], duration_s=0.2, start_s=sw.start_s, iterations=0))
    start = time.perf_counter() - t0
    try:
        wall, _ = timed_sweep(sw, out, executor="dask", address=cluster.scheduler_address, processes=workers)
    finally:
        cluster.close()
    return len(sw.cases()) / wall, start


def main(n_cases: int = 64, duration_s: float = 4.0, *, with_dask: bool = True, cores: int | None = None) -> dict:
    cores = cores or usable_cores()
    sw = bench_sweep(n_cases, duration_s)
    load0 = os.getloadavg()[0]
    print(
        f"sweep scaling: {n_cases} cases of the Monte Carlo {SWEEP.name} ({duration_s:g} s of El Centro each, "
        f"planned, simulated and assessed per case), worker processes x 1 thread, on {cores} cores"
    )
    with tempfile.TemporaryDirectory(prefix="sweep_bench_") as tmp:
        warm = bench_sweep(1, duration_s)
        timed_sweep(warm, Path(tmp) / "warm", processes=1)  # imports, kernels, the record: warm for every run
        print(
            f"  {'executor':9s} {'workers':>7s} {'split':>34s} {'wall s':>8s} {'cases/s':>8s} {'efficiency':>10s} "
            f"{'CPU s/case':>10s} {'CPU eff.':>8s} {'busy':>5s} {'machine':>7s}"
        )
        rows, one = {}, None
        for p in worker_counts(cores):
            machine = machine_efficiency(p)
            wall, res = timed_sweep(sw, Path(tmp) / f"local_{p}", processes=p, threads=1)
            rate, cpu_case = n_cases / wall, res["cpu_s"] / n_cases
            one = one or (rate, cpu_case)
            eff, cpu_eff, busy = rate / (p * one[0]), one[1] / cpu_case, res["cpu_s"] / (wall * p)
            rows[p] = {
                "wall_s": wall,
                "cases_per_s": rate,
                "efficiency": eff,
                "cpu_efficiency": cpu_eff,
                "busy": busy,
                "machine": machine,
            }
            sp = res["split"]
            split = f"{sp['processes']} proc x {sp['threads']} thr, task {sp['task']}, batch {sp['batch']}"
            print(
                f"  {'local':9s} {p:7d} {split:>34s} {wall:8.1f} {rate:8.3f} {eff:10.2f} {cpu_case:10.3f} "
                f"{cpu_eff:8.2f} {busy:5.2f} {machine:7.2f}"
            )
            sys.stdout.flush()
        out = {"cases": n_cases, "cores": cores, "local": rows, "load_before": load0}
        if with_dask:
            rate, start = dask_rate(sw, Path(tmp) / "dask", cores)
            eff = rate / (cores * one[0])
            out["dask"] = {"cases_per_s": rate, "efficiency": eff, "start_s": start}
            print(
                f"  {'dask':9s} {cores:7d} {'LocalCluster, 1 thread each':>34s} {n_cases / rate:8.1f} {rate:8.3f} "
                f"{eff:10.2f}  (cluster start and warm-up {start:.1f} s, not counted)"
            )
    out["load_after"] = os.getloadavg()[0]
    print(
        "  efficiency = cases/s over workers x the 1-worker cases/s; CPU eff. = the 1-worker CPU time per case "
        "over this one's (the work that parallel running adds); busy = CPU time over wall x workers (the share "
        "of the workers' cores they got): efficiency ~ CPU eff. x busy / the 1-worker busy; machine = the same "
        "ratio for a plain CPU-bound job in as many processes, measured just before (what the machine gave "
        "that many processes then: the ceiling of the efficiency)"
    )
    print(f"  load average (1 min) {load0:.1f} before, {out['load_after']:.1f} after, on {cores} cores")
    return out


def cli(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.sweep_bench")
    ap.add_argument("--cases", type=int, default=64)
    ap.add_argument("--duration", type=float, default=4.0, help="seconds of El Centro per case (default 4)")
    ap.add_argument("--no-dask", action="store_true", help="leave out the Dask LocalCluster row")
    args = ap.parse_args(argv)
    r = main(args.cases, args.duration, with_dask=not args.no_dask)
    print(f"sweep efficiency ({r['cases']} cases, {r['cores']} workers): {r['local'][r['cores']]['efficiency']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(cli())
