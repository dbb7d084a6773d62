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
    )
    print(f"{res['cases']} cases ({res['ran']} run, {res['skipped']} already done) in {res['wall_s']:.1f} s")
    print(f"  wrote {res['table']} and {res['report']}")
    return 0


def add_parsers(sub) -> None:
    s = sub.add_parser("sweep", help="run one scenario over a grid or random draws of its inputs")
    s.add_argument("sweep", help="a sweep .toml file ([sweep] + [[vary]])")
    s.add_argument("--out", default=None, help="output folder (default: out/sweeps/<name>)")
    s.add_argument("--workers", type=int, default=None, help="threads or worker processes (default: all cores)")
    s.add_argument(
        "--executor",
        choices=("local", "dask"),
        default="local",
        help="local: batches on this machine; dask: a Dask cluster (local cluster unless --scheduler)",
    )
    s.add_argument("--scheduler", default=None, help="address of a running Dask scheduler (tcp://host:8786)")
    s.set_defaults(func=cmd_sweep)


__all__ = ["add_parsers"]
