"""Cost of ``--rrd``: wall time of ``shaketable run elcentro_bare --duration 20`` with and without it.

    python bench/recording_bench.py [--repeat 3] [--duration 20] [--rate 50]

Runs the command as a fresh process each time (imports included, as a user sees it),
alternating without/with ``--rrd`` so drifting machine load hits both alike, and prints
the minimum and median wall times and the overhead ratio (min with / min without - 1).
Then times the recording alone (``RrdTarget.write_run`` on the run just made, rerun
already imported) and its size. Target: overhead <= 10 %.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _wall(cmd: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--scenario", default="elcentro_bare")
    args = ap.parse_args(argv)

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp)
        base = [sys.executable, "-m", "sim", "run", args.scenario, "--out", str(out),
                "--duration", f"{args.duration:g}"]
        rrd = out / "run.rrd"
        without, with_rrd = [], []
        _wall(base)  # warm the file cache (and numba caches)
        for _ in range(args.repeat):
            without.append(_wall(base))
            with_rrd.append(_wall(base + ["--rrd", str(rrd)]))
        size = rrd.stat().st_size

        # the recording alone, in this process
        import mjcf
        from sim import recording
        from sim.runfile import read_run

        run = read_run(out / f"{args.scenario}.run.npz")
        tm = mjcf.build(mjcf.load_table(run.meta["table"]),
                        mjcf.load_payload(run.meta["payload"]) if run.meta.get("payload") else None)
        import rerun  # noqa: F401  (import cost is in the end-to-end figures above)

        t0 = time.perf_counter()
        recording.RrdTarget.open(out / "alone.rrd").write_run(run, tm)
        alone = time.perf_counter() - t0

    def fmt(xs):
        return f"min {min(xs):6.2f} s  median {statistics.median(xs):6.2f} s  ({', '.join(f'{x:.2f}' for x in xs)})"

    ratio = min(with_rrd) / min(without) - 1.0
    med = statistics.median(with_rrd) / statistics.median(without) - 1.0
    print(f"shaketable run {args.scenario} --duration {args.duration:g}  ({args.repeat} runs each)")
    print(f"  without --rrd  {fmt(without)}")
    print(f"  with --rrd     {fmt(with_rrd)}")
    print(f"  overhead       {100 * ratio:+.1f} % (min/min), {100 * med:+.1f} % (median/median); target <= 10 %")
    print(f"  recording alone: {alone:.2f} s for {run.n_samples} samples, file {size / 1e6:.1f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
