"""``shaketable sweep SWEEP.toml``: many runs of one scenario with varied inputs."""

from __future__ import annotations

import sys


def cmd_sweep(args) -> int:
    from sim.sweep import sweep_file

    res = sweep_file(
        args.sweep,
        out=args.out,
        workers=args.workers,
        executor=args.executor,
        address=args.scheduler,
        progress_stream=sys.stderr,
        warn_stream=sys.stderr,
        processes=args.processes,
        threads=args.threads,
        task=args.task,
        batch=args.batch,
    )
    sp = res["split"]
    print(
        f"{res['cases']} cases ({res['ran']} run, {res['skipped']} already done) in {res['wall_s']:.1f} s "
        f"({sp['processes']} processes x {sp['threads']} threads, tasks of {sp['task']}, batches of {sp['batch']})"
    )
    print(f"  wrote {res['table']} and {res['report']}")
    return 0


def add_parsers(sub) -> None:
    s = sub.add_parser("sweep", help="run one scenario over a grid or random draws of its inputs")
    s.add_argument("sweep", help="a sweep .toml file ([sweep] + [[vary]])")
    s.add_argument("--out", default=None, help="output folder (default: out/sweeps/<name>)")
    s.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="cores to use: processes x threads (default: all of this machine's)",
    )
    s.add_argument(
        "--processes",
        type=int,
        default=None,
        metavar="P",
        help="worker processes, each planning, simulating and assessing its tasks' cases "
        "(default: one per core, at most one per case)",
    )
    s.add_argument("--threads", type=int, default=None, metavar="T", help="threads of each MuJoCo batch (default 1)")
    s.add_argument(
        "--task",
        type=int,
        default=None,
        metavar="N",
        help="cases dealt to a worker at once (default: the file's 'task', else about 4 tasks per process, at most 32)",
    )
    s.add_argument(
        "--batch",
        type=int,
        default=None,
        metavar="N",
        help="cases simulated together on one batch (default: the file's 'batch', else the whole task)",
    )
    s.add_argument(
        "--executor",
        choices=("local", "dask"),
        default="local",
        help="local: worker processes on this machine; dask: a Dask cluster (a LocalCluster of the "
        "processes unless --scheduler)",
    )
    s.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (tcp://host:8786)")
    s.set_defaults(func=cmd_sweep)


__all__ = ["add_parsers"]
