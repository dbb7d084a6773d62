"""Cost of ``--rrd``: wall time of ``shaketable run`` with and without it, and the file size.

    python bench/recording_bench.py [--repeat 5] [--duration 20] [--iterations 0]
    python bench/recording_bench.py --full            # the whole scenario (89 s, 2 drive iterations)

Runs the command as a fresh process each time (imports included, as a user sees it),
alternating without/with ``--rrd`` so drifting machine load hits both alike, and prints
the minimum and median wall times, the overhead ratio (min with / min without - 1) and
the processes' CPU time (user + sys, writer process included), less sensitive to other load.
Then times the recording alone (``RrdTarget.open`` + ``write_run`` on the run just made,
the writer process's rerun import included) at the default time-series rate and at the
full rate, with the sizes. For very short runs (a few seconds) the ~1 s import cannot hide
behind the simulation. Target: overhead <= 10 %.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from sim.effects import build_model

ROOT = Path(__file__).resolve().parents[1]


def _wall(cmd: list[str]) -> tuple[float, float]:
    """(wall s, CPU s of the child: user + sys)."""
    r0 = os.times()
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    r1 = os.times()
    return wall, (r1.children_user - r0.children_user) + (r1.children_system - r0.children_system)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--iterations", type=int, default=0, help="drive iterations (default 0: one simulation)")
    ap.add_argument("--full", action="store_true", help="the whole scenario: its duration and iterations")
    ap.add_argument("--scenario", default="elcentro_bare")
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        base = [sys.executable, "-m", "sim", "run", args.scenario, "--out", str(out)]
        what = f"shaketable run {args.scenario}"
        if not args.full:
            base += ["--duration", f"{args.duration:g}", "--iterations", str(args.iterations)]
            what += f" --duration {args.duration:g} --iterations {args.iterations}"
        rrd = out / "run.rrd"
        without, with_rrd = [], []
        _wall(base)  # warm the file cache (and numba caches)
        for _ in range(args.repeat):
            without.append(_wall(base))
            with_rrd.append(_wall(base + ["--rrd", str(rrd)]))
        size = rrd.stat().st_size

        # the recording alone: open (starts the writer) + write_run
        import mjcf
        from sim.report import rerun as recording
        from sim.runs.runfile import read_run

        run_file = out / f"{args.scenario}.run.npz"
        run = read_run(run_file)
        run_size = run_file.stat().st_size
        tm = build_model(
            mjcf.load_table(run.meta["table"]),
            mjcf.load_payload(run.meta["payload"]) if run.meta.get("payload") else None,
        )
        import rerun  # noqa: F401  (import cost is in the end-to-end figures above)

        alone = {}
        for label, rate in (("default", recording.DEFAULT_SERIES_RATE_HZ), ("full rate", None)):
            t0 = time.perf_counter()
            p = recording.RrdTarget.open(out / "alone.rrd", series_rate_hz=rate).write_run(run, tm)
            alone[label] = (time.perf_counter() - t0, p.stat().st_size)

    def fmt(xs):
        return f"min {min(xs):6.2f} s  median {statistics.median(xs):6.2f} s  ({', '.join(f'{x:.2f}' for x in xs)})"

    w0, w1 = [w for w, _ in without], [w for w, _ in with_rrd]
    c0, c1 = [c for _, c in without], [c for _, c in with_rrd]
    ratio = min(w1) / min(w0) - 1.0
    med = statistics.median(w1) / statistics.median(w0) - 1.0
    cpu = statistics.median(c1) / statistics.median(c0) - 1.0
    print(f"{what}  ({args.repeat} runs each)")
    print(f"  without --rrd  wall {fmt(w0)}")
    print(f"  with --rrd     wall {fmt(w1)}")
    print(f"  overhead       {100 * ratio:+.1f} % (min/min), {100 * med:+.1f} % (median/median); target <= 10 %")
    print(
        f"  CPU time       {statistics.median(c0):.2f} s -> {statistics.median(c1):.2f} s "
        f"({100 * cpu:+.1f} %, medians, all threads)"
    )
    print(f"  run file {run_size / 1e6:.1f} MB; recording (--rrd) {size / 1e6:.1f} MB, {run.n_samples} samples")
    for label, (secs, sz) in alone.items():
        print(
            f"  recording alone (open + write_run, writer import included), {label:9s}: {secs:.2f} s, {sz / 1e6:.1f} MB"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
