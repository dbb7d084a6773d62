"""``shaketable view``: record any run file (measured or simulated) as a rerun recording.

    shaketable view RUN.run.npz --rrd FILE.rrd [--compare OTHER.run.npz] [--table T]
                    [--payload P] [--rate HZ] [--full-rate] [--spawn | --connect [URL]]

The geometry comes from the table description the run carries (``meta.table_description``;
the stock table named by ``meta.table`` for runs without it) or ``--table``, with the run's
payload likewise (or ``--payload``; ``--payload none`` for a bare table). ``--compare``
lays a second run beside the first (its series, the residual per channel and a ghost
platen). Time series keep every n-th sample, n the largest that keeps at least 250 Hz
(every 4th of a 1024 Hz run); ``--full-rate`` keeps every sample (a file ~3x larger).
``--spawn`` / ``--connect`` also stream to a live viewer (needs a screen, or a
viewer already running at URL).

rerun's own script helpers (``rr.script_add_args`` / ``rr.script_setup``) exist in 0.41
but are not used here: without ``--headless`` they spawn a viewer by default, their
``--save`` writes the file in place (no temporary file, so a failure would leave a
partial recording), and they set a single sink, so a file and a live viewer cannot be
fed together. ``--spawn`` and ``--connect`` map onto ``rr.spawn`` and ``rr.GrpcSink``.
"""

from __future__ import annotations

from sim.effects import build_model
from sim.errors import UserError
from sim.runs.files import json_text


def cmd_view(args) -> int:
    from sim.report import rerun as recording
    from sim.runs.runfile import payload_of, read_run, table_of

    if not args.rrd and not args.spawn and args.connect is None:
        raise UserError("view needs a target: give --rrd FILE.rrd, --spawn or --connect [URL]")
    # check the target before reading anything large
    target = recording.RrdTarget.open(
        args.rrd,
        spawn=args.spawn,
        connect=args.connect,
        rate_hz=args.rate,
        series_rate_hz=None if args.full_rate else recording.DEFAULT_SERIES_RATE_HZ,
        timeout_s=args.timeout,
    )
    run = read_run(args.run)
    compare = read_run(args.compare) if args.compare else None
    desc = table_of(run, args.table)  # --table, else the description the run carries, else the stock file
    payload = payload_of(run, args.payload)
    tm = build_model(desc, payload)
    path = target.write_run(run, tm, compare=compare)
    out = {
        "run": str(args.run),
        "compare": args.compare,
        "table": desc.name,
        "payload": payload.name if payload else None,
        "recording": str(path) if path else None,
        "samples": run.n_samples,
        "display_rate_hz": args.rate,
        "series_rate_hz": run.sample_rate_hz / recording.series_stride(run.sample_rate_hz, target.series_rate_hz),
    }
    if args.json:
        print(json_text(out, indent=2))
    else:
        what = f"{args.run}" + (f" beside {args.compare}" if args.compare else "")
        dest = [str(path)] if path else []
        if args.spawn:
            dest.append("a spawned viewer")
        if args.connect is not None:
            dest.append(f"the viewer at {args.connect or recording.DEFAULT_URL}")
        print(f"recorded {what} ({run.n_samples} samples, {run.duration_s:.2f} s) -> {' and '.join(dest)}")
    return 0


def _rate(text: str) -> float:
    """A positive finite number (a rate in Hz, a time in s)."""
    import argparse
    import math

    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(v) or v <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a positive number")
    return v


def add_parsers(sub) -> None:
    from sim.report.rerun import DEFAULT_RATE_HZ, DEFAULT_SERIES_RATE_HZ

    v = sub.add_parser("view", help="record a run file (measured or simulated) as a rerun recording")
    v.add_argument("run", help="a .run.npz file")
    v.add_argument("--rrd", metavar="FILE", help="write the recording to FILE.rrd")
    v.add_argument("--compare", metavar="OTHER", help="a second .run.npz laid beside the first (with residuals)")
    v.add_argument("--table", help="table (default: the description the run carries, else its meta.table)")
    v.add_argument(
        "--payload", help="payload (default: the description the run carries, else its meta.payload; 'none': bare)"
    )
    v.add_argument(
        "--rate",
        type=_rate,
        default=DEFAULT_RATE_HZ,
        metavar="HZ",
        help=f"display rate of the 3-D scene (default {DEFAULT_RATE_HZ:g} Hz)",
    )
    v.add_argument(
        "--full-rate",
        action="store_true",
        help=f"time series at the run's full rate (default: every n-th sample, at least {DEFAULT_SERIES_RATE_HZ:g} Hz)",
    )
    v.add_argument("--spawn", action="store_true", help="also stream to a viewer started now (needs a screen)")
    v.add_argument(
        "--connect",
        nargs="?",
        const="",
        default=None,
        metavar="URL",
        help="also stream to a running viewer (default rerun+http://127.0.0.1:9876/proxy)",
    )
    v.add_argument(
        "--timeout",
        type=_rate,
        default=None,
        metavar="S",
        help="with --spawn/--connect: give up when the viewer has not taken the recording after S seconds (default 30)",
    )
    v.add_argument("--json", action="store_true", help="print a JSON summary")
    v.set_defaults(func=cmd_view)


__all__ = ["add_parsers", "cmd_view"]
