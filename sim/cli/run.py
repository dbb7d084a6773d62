"""``shaketable run`` and ``shaketable replay``: simulate a scenario / replay a run file."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from sim.assess.run import SCHEMA
from sim.runs.files import json_text, out_dir, write_json_atomic
from sim.runs.runfile import COMMAND_HOLDS


def _progress(args):
    """Stage lines on stderr (a terminal or a log alike), a bar on a terminal; silent with --json."""
    from sim.cli.progress import Progress

    return Progress(enabled=not getattr(args, "json", False))


#: the environment variable that sets ``run``'s default engine (``loop``: the Python loop, the reference)
ENGINE_ENV = "SHAKETABLE_ENGINE"


def _engine(args) -> str:
    """``--engine``, else $SHAKETABLE_ENGINE, else ``callback`` (the coupled step inside
    MuJoCo where the table allows it: the same run file as the loop, faster)."""
    import os

    from sim.errors import UserError

    if getattr(args, "engine", None):  # replay has no --engine: the variable only
        return args.engine
    env = os.environ.get(ENGINE_ENV, "").strip()
    if env and env not in ("callback", "loop"):
        raise UserError(f"environment variable {ENGINE_ENV}={env!r}: must be 'callback' or 'loop'; unset it or fix it")
    return env or "callback"


def cmd_run(args) -> int:
    from sim.assess.run import plan_scenario

    prog = _progress(args)
    plan = plan_scenario(args.scenario, duration_s=args.duration, iterations=args.iterations, engine=_engine(args))
    sensors = None
    if getattr(args, "measure", None) is not None:  # a bad sensor model fails before anything is written
        from sim.runs.measure import load_sensors

        sensors = load_sensors(None if args.measure is True else args.measure, sample_rate_hz=plan.gains.rate_hz)
    for w in plan.warnings:
        print(f"warning: {w}", file=sys.stderr)
    out = out_dir(args.out)  # checked before the work starts
    target = None
    if getattr(args, "rrd", None):
        from sim.report import rerun

        target = rerun.RrdTarget.open(args.rrd)  # fails early (exit 2) if unwritable; rerun loads beside the run
    outcome = plan.run(progress=prog.text_callback())
    prog.close()
    res = outcome.result
    if res.interrupted:  # Ctrl-C: keep what was computed (no recording: the user asked to stop)
        summary = outcome.write(out)
        print(
            f"interrupted: kept {res.sim_s:.3f} s in {summary['run_file']} (marked incomplete) "
            f"and {out / 'summary.json'}",
            file=sys.stderr,
        )
        return 130
    if target is not None:
        target.write_run(outcome.run, outcome.tm)
        outcome.summary["recording"] = str(target.path)
    if sensors is not None:
        from sim.runs.measure import write_measured

        outcome.summary["measured_run_file"] = str(
            write_measured(
                outcome.run,
                out,
                outcome.summary["scenario"],
                sensors,
                seed=args.measure_seed,
                model_file=None if args.measure is True else args.measure,
            )
        )
    summary = outcome.write(out)
    if args.json:
        print(json_text(summary, indent=2))
    else:
        _print_summary(summary, prog.elapsed_s)
    if res.incomplete_reason:
        print(
            f"error: {res.incomplete_reason}; kept {res.sim_s:.3f} s in {summary['run_file']} (marked incomplete)",
            file=sys.stderr,
        )
        return 3
    return 0


def _print_summary(s: dict, command_wall_s: float | None = None) -> None:
    runs = 1 + s.get("drive_iterations", {}).get("count", 0)
    last = "" if runs == 1 else " (the chosen run)"
    print(
        f"{s['scenario']}: {s['table']}"
        + (f" + {s['payload']}" if s["payload"] else "")
        + f", {s['duration_s']:.2f} s simulated in {s['wall_s']:.1f} s{last} ({s['realtime_factor']:.2f}x real time)"
    )
    if command_wall_s:
        print(
            f"  whole command: {command_wall_s:.1f} s wall for {runs} run(s) of {s['duration_s']:.2f} s"
            + (" and the FRF measurement" if s.get("drive_iterations", {}).get("frf") == "noise" and runs > 1 else "")
            + f" ({s['duration_s'] / command_wall_s:.2f}x real time)"
        )
    print(f"  {'dof':4s} {'NRMSE d':>8s} {'NRMSE a':>8s} {'PGA ratio':>9s} {'spectrum ratio (0.5-20 Hz)':>28s}")
    for dof, e in s["tracking"].items():
        sr = f"{e['spectrum_ratio_min']:.2f} .. {e['spectrum_ratio_max']:.2f}" if "spectrum_ratio_min" in e else "-"
        print(
            f"  {dof:4s} {100 * e['nrmse_displacement']:7.2f}% {100 * e['nrmse_acceleration']:7.1f}% "
            f"{e['pga_ratio']:9.3f} {sr:>28s}"
        )
    w = s.get("window")
    if w and (w["start_s"] > 0 or w["end_s"] < w["of_record_s"] - 1e-6):
        print(f"  ran {w['start_s']:.1f}-{w['end_s']:.1f} s of the {w['of_record_s']:.1f} s motion ({w['why']})")
    fe = s.get("feasibility")
    if fe is not None:
        from sim.cli.feasibility import verdict_lines

        for line in verdict_lines(fe):
            print("  " + line)
    ff = max(s["peak_force_fraction_of_capacity"].values())
    sf = max(s["peak_stroke_fraction"].values())
    print(
        f"  peak force {100 * ff:.0f} % of capacity, peak stroke {100 * sf:.0f} % of half-stroke, "
        f"min supply {s['min_supply_pressure_pa'] / 1e6:.1f} MPa, max swivel gap {s['max_loop_gap_m'] * 1e6:.2f} um"
    )
    if s.get("faults"):
        from sim.assess.faults import fault_lines

        for line in fault_lines(s["faults"]):
            print("  " + line)
    di = s.get("drive_iterations", {})
    if di.get("count"):
        hist = ", ".join(f"{100 * h['mean_nrmse_acceleration']:.1f}%" for h in di["history"])
        print(f"  drive iterations: mean acceleration NRMSE per run {hist}; using run {di['chosen']}")
    print(f"  wrote {s['run_file']}" + (f" and {s['recording']}" if s.get("recording") else ""))
    if s.get("measured_run_file"):
        print(f"  wrote {s['measured_run_file']} (through the sensor model)")


def cmd_replay_closed_loop(args) -> int:
    """``replay --closed-loop``: the record's reference through the model's controller."""
    from sim.calibrate.closed_replay import closed_loop_replay
    from sim.runs.runfile import write_run

    prog = _progress(args)
    prog.stage(f"running {args.run}'s reference closed loop")
    bar = prog.enabled and prog.tty
    rep = closed_loop_replay(args.run, table=args.table, payload=args.payload, progress=bar, engine=_engine(args))
    out = out_dir(args.out)  # after the run: a run or description it refuses leaves nothing behind
    stem = Path(args.run).name[: -len(".run.npz")] if args.run.endswith(".run.npz") else Path(args.run).stem
    path = out / f"{stem}.closedloop.run.npz"
    write_run(path, rep.run)
    summary = {"schema": SCHEMA, "run_file": str(path), **rep.summary()}
    write_json_atomic(out / "replay_summary.json", summary)
    if args.json:
        print(json_text(summary, indent=2))
        return 0 if rep.complete else 3
    print(f"ran {args.run}'s reference closed loop through the model -> {path}")
    print(f"  {'tracking against the reference':30s} {'model':>10s}   {'record':>10s}")
    for dof, m in rep.model_tracking.items():
        r = rep.record_tracking.get(dof, {})
        for k in ("nrmse_displacement", "nrmse_acceleration", "pga_ratio"):
            print(f"  {dof} {k:28s} {m[k]:10.4f}   {r.get(k, float('nan')):10.4f}")
    for ch, cols in rep.residual_nrmse.items():
        vals = ", ".join(f"{k} {100 * v:.2f}%" if np.isfinite(v) else f"{k} -" for k, v in cols.items())
        print(f"  {ch} NRMSE model against record: {vals}")
    for note in rep.notes:
        print(f"  note: {note}")
    if rep.result.incomplete_reason:
        print(f"error: {rep.result.incomplete_reason}", file=sys.stderr)
    return 0 if rep.complete else 3


def cmd_replay(args) -> int:
    from sim.calibrate.replay import replay
    from sim.runs.runfile import write_run

    if args.closed_loop:
        return cmd_replay_closed_loop(args)
    prog = _progress(args)
    prog.stage(f"replaying {args.run} open loop")
    bias = "none" if args.no_bias else args.bias  # None: estimated for a measured run
    rep = replay(
        args.run,
        table=args.table,
        payload=args.payload,
        progress=prog.enabled and prog.tty,
        bias=bias,
        drift=args.drift,
        hold=args.hold,
    )
    res = rep.result
    out = out_dir(args.out)  # after the replay: a run or description it refuses leaves nothing behind
    stem = Path(args.run).name[: -len(".run.npz")] if args.run.endswith(".run.npz") else Path(args.run).stem
    path = out / f"{stem}.replay.run.npz"
    write_run(path, rep.run)
    summary = {"schema": SCHEMA, "run_file": str(path), **rep.summary()}
    write_json_atomic(out / "replay_summary.json", summary)
    if args.json:
        print(json_text(summary, indent=2))
    else:
        print(
            f"replayed {args.run} open loop ({res.sim_s:.2f} s at the record's {rep.run.sample_rate_hz:g} Hz, "
            f"model ticks {rep.tick_hz:g} Hz, {res.realtime_factor:.2f}x real time; "
            f"whole command {prog.elapsed_s:.1f} s) -> {path}"
        )
        for note in rep.notes:
            print(f"  note: {note}")
        sf = ", ".join(f"{k} {100 * v:.0f}%" for k, v in rep.stroke_fraction.items())
        print(f"  peak stroke (fraction of half-stroke): {sf}")
        for ch, cols in rep.residual_nrmse.items():
            vals = ", ".join(f"{k} {100 * v:.2f}%" if np.isfinite(v) else f"{k} -" for k, v in cols.items())
            print(f"  {ch} NRMSE: {vals}")
        for ch, why in rep.not_compared.items():
            print(f"  {ch}: not compared ({why})")
        if res.incomplete_reason:
            print(f"error: {res.incomplete_reason}", file=sys.stderr)
    return 0 if rep.complete else 3


def add_parsers(sub) -> None:
    r = sub.add_parser("run", help="simulate a scenario and write its run file and summary")
    r.add_argument("scenario", help="scenario name in scenarios/ or a .toml path")
    r.add_argument("--out", default="out", help="output folder (default: out)")
    r.add_argument(
        "--duration",
        type=float,
        default=None,
        metavar="S",
        help="simulate S seconds: of an earthquake record its strongest S s (tapered), of other motions the first S s",
    )
    r.add_argument("--json", action="store_true", help="print the summary as JSON")
    r.add_argument("--rrd", metavar="FILE", help="also write a rerun recording")
    r.add_argument(
        "--iterations",
        type=int,
        default=None,
        help="off-line drive iterations on the model (default: the scenario's [iteration] count)",
    )
    r.add_argument(
        "--measure",
        nargs="?",
        const=True,
        default=None,
        metavar="SENSORS.toml",
        help="also write <scenario>.measured.run.npz through a sensor model (docs/sensors.md; "
        "default: the built-in 1024 Hz recorder, scenarios/sensors/recorder_1024hz.toml)",
    )
    r.add_argument("--measure-seed", type=int, default=0, help="seed of the measurement noise (default 0)")
    r.add_argument(
        "--engine",
        choices=("callback", "loop"),
        default=None,
        help="callback: the coupled step compiled inside MuJoCo's step where the table allows it (the Python "
        "loop elsewhere); loop: the Python loop, the reference; both write the same run file "
        f"(default: ${ENGINE_ENV}, else callback)",
    )
    r.set_defaults(func=cmd_run)

    p = sub.add_parser(
        "replay", help="replay a run file's valve commands open loop (or its reference closed loop) through the model"
    )
    p.add_argument("run", help="a .run.npz file with valve_command (--closed-loop: with reference)")
    p.add_argument("--table", help="table (default: the description the run carries, else its meta.table)")
    p.add_argument("--payload", help="payload (default: the description the run carries; 'none' for a bare table)")
    p.add_argument("--out", default="out", help="output folder")
    p.add_argument(
        "--bias",
        type=float,
        default=None,
        metavar="FRACTION",
        help="valve null offset to add to every command (default: estimated from the recorded motion "
        "for a measured run, none for a simulated one)",
    )
    p.add_argument("--no-bias", action="store_true", help="replay the commands as recorded (no valve null offset)")
    p.add_argument(
        "--drift", action="store_true", help="also estimate and apply a linear drift of the valve null over the record"
    )
    p.add_argument(
        "--hold",
        choices=list(COMMAND_HOLDS),
        default=None,
        help="command onto the model's ticks: zero-order hold (the record is the controller's DAC "
        "rate), or a cubic spline or linear interpolation (a slower recorder sampled the drive); "
        "default the run's meta.command_hold, else zoh where the table's controller ticks at the "
        "record's rate, cubic where it ticks faster",
    )
    p.add_argument(
        "--closed-loop",
        dest="closed_loop",
        action="store_true",
        help="run the record's reference through the model's controller instead (needs a reference); "
        "writes <run>.closedloop.run.npz with the model's and the record's tracking figures",
    )
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_replay)


__all__ = ["add_parsers"]
