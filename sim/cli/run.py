"""``shaketable run`` and ``shaketable replay``: simulate a scenario / replay a run file."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from sim.assess.run import SCHEMA
from sim.errors import RunFileError, UserError
from sim.runs.files import json_text, out_dir, write_json_atomic
from sim.effects import build_model

def _progress(args):
    """One line per stage on stderr (a terminal or a log alike), none with --json."""
    if getattr(args, "json", False):
        return None
    return lambda text: print(f"  {text}", file=sys.stderr, flush=True)


def cmd_run(args) -> int:
    from sim.assess.run import plan_scenario

    plan = plan_scenario(args.scenario, duration_s=args.duration, iterations=args.iterations)
    for w in plan.warnings:
        print(f"warning: {w}", file=sys.stderr)
    out = out_dir(args.out)  # checked before the work starts
    target = None
    if getattr(args, "rrd", None):
        from sim.report import rerun

        target = rerun.RrdTarget.open(args.rrd)  # fails early (exit 2) if unwritable; rerun loads beside the run
    outcome = plan.run(progress=_progress(args))
    res = outcome.result
    if res.interrupted:  # Ctrl-C: keep what was computed (no recording: the user asked to stop)
        summary = outcome.write(out)
        print(f"interrupted: kept {res.sim_s:.3f} s in {summary['run_file']} (marked incomplete) "
              f"and {out / 'summary.json'}", file=sys.stderr)
        return 130
    if target is not None:
        target.write_run(outcome.run, outcome.tm)
        outcome.summary["recording"] = str(target.path)
    summary = outcome.write(out)
    if args.json:
        print(json_text(summary, indent=2))
    else:
        _print_summary(summary)
    if res.incomplete_reason:
        print(f"error: {res.incomplete_reason}; kept {res.sim_s:.3f} s in {summary['run_file']} (marked incomplete)",
              file=sys.stderr)
        return 3
    return 0


def _print_summary(s: dict) -> None:
    print(f"{s['scenario']}: {s['table']}" + (f" + {s['payload']}" if s["payload"] else "")
          + f", {s['duration_s']:.2f} s simulated in {s['wall_s']:.1f} s ({s['realtime_factor']:.2f}x real time)")
    print(f"  {'dof':4s} {'NRMSE d':>8s} {'NRMSE a':>8s} {'PGA ratio':>9s} {'spectrum ratio (0.5-20 Hz)':>28s}")
    for dof, e in s["tracking"].items():
        sr = (f"{e['spectrum_ratio_min']:.2f} .. {e['spectrum_ratio_max']:.2f}"
              if "spectrum_ratio_min" in e else "-")
        print(f"  {dof:4s} {100 * e['nrmse_displacement']:7.2f}% {100 * e['nrmse_acceleration']:7.1f}% "
              f"{e['pga_ratio']:9.3f} {sr:>28s}")
    fe = s.get("feasibility")
    if fe is not None:
        print("  feasible on this table: " + ("yes" if fe["feasible"] else "NO (" + ", ".join(fe["failed"]) + ")"))
    ff = max(s["peak_force_fraction_of_capacity"].values())
    sf = max(s["peak_stroke_fraction"].values())
    print(f"  peak force {100 * ff:.0f} % of capacity, peak stroke {100 * sf:.0f} % of half-stroke, "
          f"min supply {s['min_supply_pressure_pa'] / 1e6:.1f} MPa, max swivel gap {s['max_loop_gap_m'] * 1e6:.2f} um")
    di = s.get("drive_iterations", {})
    if di.get("count"):
        hist = ", ".join(f"{100 * h['mean_nrmse_acceleration']:.1f}%" for h in di["history"])
        print(f"  drive iterations: mean acceleration NRMSE per run {hist}; using run {di['chosen']}")
    print(f"  wrote {s['run_file']}" + (f" and {s['recording']}" if s.get("recording") else ""))


def cmd_replay(args) -> int:
    from sim.calibrate.replay import replay
    from sim.runs.runfile import write_run

    out = out_dir(args.out)
    rep = replay(args.run, table=args.table, payload=args.payload, progress=sys.stderr.isatty() and not args.json)
    res = rep.result
    stem = Path(args.run).name[: -len(".run.npz")] if args.run.endswith(".run.npz") else Path(args.run).stem
    path = out / f"{stem}.replay.run.npz"
    write_run(path, rep.run)
    summary = {"schema": SCHEMA, "replay_of": str(args.run), "run_file": str(path),
               "realtime_factor": float(res.realtime_factor), "complete": rep.complete,
               "residual_nrmse": rep.residual_nrmse}
    write_json_atomic(out / "replay_summary.json", summary)
    if args.json:
        print(json_text(summary, indent=2))
    else:
        print(f"replayed {args.run} open loop ({res.sim_s:.2f} s, {res.realtime_factor:.2f}x real time) -> {path}")
        for ch, cols in rep.residual_nrmse.items():
            vals = ", ".join(f"{k} {100 * v:.2f}%" for k, v in cols.items() if np.isfinite(v))
            if vals:
                print(f"  {ch} NRMSE: {vals}")
    return 0 if rep.complete else 3


def cmd_fit(args) -> int:
    import mjcf
    from sim.calibrate import fit as F
    from sim.runs.runfile import read_run

    run = read_run(args.run, require=("valve_command",))
    table = args.table or run.meta["table"]
    desc = mjcf.load_table(table)
    if list(run.actuators) != list(desc.actuator_names):
        raise RunFileError(f"{args.run}: actuators {run.actuators} do not match table '{desc.name}'; give --table")
    pay = args.payload if args.payload is not None else run.meta.get("payload")
    payload = mjcf.load_payload(pay) if pay else None
    cands = F.CANDIDATES
    if args.effects:
        names = [x.strip() for x in args.effects.split(",") if x.strip()]
        known = {c.name: c for c in F.CANDIDATES}
        bad = [n for n in names if n not in known]
        if bad:
            raise UserError(f"unknown effect '{bad[0]}'; candidates: {', '.join(known)}")
        cands = tuple(known[n] for n in names)
    out = out_dir(args.out)
    log = (lambda m: print(m, file=sys.stderr)) if not args.json else None
    rep = F.fit(run, desc.raw, payload, candidates=cands, rounds=args.rounds, log=log)
    toml_path = out / f"{desc.name}_calibrated.toml"
    note = ("calibrated: shaketable fit of " + Path(args.run).name + "; effects added: "
            + (", ".join(f"{e['effect']} = {e['value']:.6g} {e['unit']}" for e in rep["effects_added"]) or "none"))
    F.write_table_toml(rep.pop("calibrated_table"), toml_path, note)
    rep["calibrated_table_file"] = str(toml_path)
    write_json_atomic(out / "fit.json", rep)
    if args.json:
        print(json_text(rep, indent=2))
    else:
        print(f"residual (mean NRMSE of force/acceleration/displacement): "
              f"{100 * rep['baseline_residual']:.2f} % -> {100 * rep['final_residual']:.2f} %")
        for e in rep["effects_added"]:
            print(f"  added {e['effect']} = {e['value']:.6g} {e['unit']} ({e['what']})")
        print(f"  wrote {toml_path} and {out / 'fit.json'}")
    return 0


def cmd_geometry(args) -> int:
    import mjcf
    from hydraulics import HydraulicParams
    from sim.assess import geometry
    desc = mjcf.load_table(args.table)
    payload = mjcf.load_payload(args.payload) if args.payload else None
    tm = build_model(desc, payload)
    r = geometry.study(desc, tm.effective_mass_matrix(), HydraulicParams.from_table(desc.raw))
    if args.json:
        print(json_text(r, indent=2))
    else:
        geometry.print_report(r)
    return 0


def add_parsers(sub) -> None:
    g = sub.add_parser("geometry", help="geometric nonlinearity of a table over its rated envelope")
    g.add_argument("table")
    g.add_argument("--payload")
    g.add_argument("--json", action="store_true")
    g.set_defaults(func=cmd_geometry)

    f = sub.add_parser("fit", help="replay a measured run, find the residual and add the effect the model lacks")
    f.add_argument("run", help="a measured .run.npz with valve_command")
    f.add_argument("--table", help="table (default: the run's meta.table)")
    f.add_argument("--payload", help="payload (default: the run's meta.payload)")
    f.add_argument("--effects", help="comma-separated candidate effects (default: all)")
    f.add_argument("--rounds", type=int, default=2, help="effects to add at most (default 2)")
    f.add_argument("--out", default="out", help="output folder")
    f.add_argument("--json", action="store_true")
    f.set_defaults(func=cmd_fit)

    r = sub.add_parser("run", help="simulate a scenario and write its run file and summary")
    r.add_argument("scenario", help="scenario name in scenarios/ or a .toml path")
    r.add_argument("--out", default="out", help="output folder (default: out)")
    r.add_argument("--duration", type=float, default=None, help="simulate only the first S seconds")
    r.add_argument("--json", action="store_true", help="print the summary as JSON")
    r.add_argument("--rrd", metavar="FILE", help="also write a rerun recording")
    r.add_argument("--iterations", type=int, default=None,
                   help="off-line drive iterations on the model (default: the scenario's [iteration] count)")
    r.set_defaults(func=cmd_run)

    p = sub.add_parser("replay", help="replay a run file's valve commands open loop through the model")
    p.add_argument("run", help="a .run.npz file with valve_command")
    p.add_argument("--table", help="table (default: the run's meta.table)")
    p.add_argument("--payload", help="payload (default: the run's meta.payload)")
    p.add_argument("--out", default="out", help="output folder")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_replay)


__all__ = ["add_parsers"]
