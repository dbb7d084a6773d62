"""``shaketable run`` and ``shaketable replay``: simulate a scenario / replay a run file."""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sim.errors import RunFileError, ScenarioError, UserError

SCHEMA = "shaketable-summary/1"


class DivergenceAtStart(UserError):
    """Diverged before a second sample: nothing to keep (a run file needs two samples)."""


def _out_dir(path) -> Path:
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=out, prefix=".probe", delete=True)
        probe.close()
    except OSError as e:
        raise UserError(f"cannot write to output folder {out}: {e.strerror}; choose a writable --out folder") from None
    return out


def _write_json_atomic(path: Path, obj) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(json.dumps(obj, indent=2, allow_nan=True))
        os.replace(tmp, path)
    except OSError as e:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise UserError(f"cannot write {path}: {e.strerror}") from None


def build_runfile(res, tm, *, source="simulated", description="", payload_name=None, reference=None, extra_meta=None):
    """RunFile from a :class:`sim.loop.RunResult` (every channel of the format)."""
    from sim.runfile import FORMAT, RunFile

    desc = tm.desc
    n = len(res.t)
    meta = {
        "format": FORMAT,
        "table": desc.name,
        "sample_rate_hz": 1.0 / float(res.t[1] - res.t[0]) if n > 1 else 1024.0,
        "actuators": list(desc.actuator_names),
        "dofs": ["x", "y", "z", "rx", "ry", "rz"],
        "source": source,
        "description": description,
        "payload": payload_name,
        "accelerometers": [{"name": a.name, "position": a.position_m.tolist(), "direction": a.direction.tolist()}
                           for a in desc.accelerometers],
        "accelerometer_convention": "kinematic acceleration along the sensor direction, gravity removed",
        "angle_convention": "intrinsic x-y-z rotation of the platen from home",
    }
    if extra_meta:
        meta.update(extra_meta)
    ch = res.channels
    run = RunFile(t=res.t, meta=meta, valve_command=ch["valve_command"], spool_position=ch["spool_position"],
                  actuator_displacement=ch["actuator_displacement"], actuator_force=ch["actuator_force"],
                  pressure_a=ch["pressure_a"], pressure_b=ch["pressure_b"],
                  table_displacement=ch["table_displacement"], table_velocity=ch["table_velocity"],
                  table_acceleration=ch["table_acceleration"], accelerometers=ch["accelerometers"],
                  reference=None if reference is None else reference.d[:n].copy(),
                  extras=dict(res.extras))
    if res.incomplete_reason:
        run.mark_incomplete(res.incomplete_reason)
    return run


def feasibility(res, tm, hp, force_frac, stroke_frac) -> dict:
    """Will this specimen and motion work on this table? Checks with margins and a verdict.

    Each check compares a peak over the run with the table's capability: actuator stroke
    (cushions start at half-stroke - cushion length), actuator force (A p_supply), valve
    opening (saturation means the demanded flow was not available), supply pressure
    (accumulators drained below 90 % of the set pressure), the overturning moment at the
    reference point from the vertical actuators (seed 000: about 180 t.m), loop closure.
    """
    from sim.controller import dof_jacobian

    ch = res.channels
    desc = tm.desc
    J = dof_jacobian(desc)
    W = ch["actuator_force"] @ J  # wrench at the reference point (home Jacobian): Fx..Fz, Mx..Mz
    m_ot = float(np.nanmax(np.hypot(W[:, 3], W[:, 4]))) if len(W) else 0.0
    lim_ot = desc.limits.overturning_moment_n_m
    sat = float(np.mean(np.abs(ch["valve_command"]) >= 0.999))
    ps_min = float(np.nanmin(res.extras["supply_pressure"]))
    cush = np.asarray(hp.cushion_length_m) / np.asarray(hp.half_stroke_m)
    checks = {
        "stroke": {"peak_fraction": float(np.max(stroke_frac)), "limit": float(np.min(1 - cush)),
                   "ok": bool(np.all(stroke_frac < 1 - cush))},
        "force": {"peak_fraction": float(np.max(force_frac)), "limit": 0.9, "ok": bool(np.max(force_frac) < 0.9)},
        "valve_saturation": {"fraction_of_time": sat, "limit": 0.01, "ok": sat < 0.01},
        "supply_pressure": {"min_fraction": ps_min / hp.supply_pressure_pa, "limit": 0.9,
                            "ok": ps_min >= 0.9 * hp.supply_pressure_pa},
        "overturning_moment": {"peak_n_m": m_ot, "limit_n_m": lim_ot, "ok": (lim_ot <= 0) or m_ot <= lim_ot},
        "loop_closure": {"max_gap_m": float(np.nanmax(res.extras["loop_gap"])), "limit": 1e-4,
                         "ok": bool(np.nanmax(res.extras["loop_gap"]) < 1e-4)},
        "completed": {"ok": res.incomplete_reason is None},
    }
    failed = [k for k, v in checks.items() if not v["ok"]]
    return {"feasible": not failed, "failed": failed, "checks": checks}


def _diagnostics(res, tm, hp) -> dict:
    ch = res.channels
    cap = hp.area_a_m2 * hp.supply_pressure_pa
    fmax = np.nanmax(np.abs(ch["actuator_force"]), axis=0)
    smax = np.nanmax(np.abs(ch["actuator_displacement"]), axis=0)
    half = hp.half_stroke_m
    vc = ch["valve_command"]
    timing = res.timing
    steps = max(timing.get("steps", 1), 1)
    ticks = max(len(res.t), 1)
    feas = feasibility(res, tm, hp, fmax / cap, smax / half)
    return {
        "feasibility": feas,
        "peak_force_fraction_of_capacity": {n: float(f / c) for n, f, c in zip(tm.actuator_names, fmax, cap)},
        "peak_stroke_fraction": {n: float(s / h) for n, s, h in zip(tm.actuator_names, smax, half)},
        "valve_saturation_fraction": float(np.mean(np.abs(vc) >= 0.999)),
        "min_supply_pressure_pa": float(np.nanmin(res.extras["supply_pressure"])),
        "max_loop_gap_m": float(np.nanmax(res.extras["loop_gap"])),
        "cost_us": {
            "physics_per_step": 1e6 * timing.get("physics_s", 0) / steps,
            "hydraulics_per_step": 1e6 * timing.get("hydraulics_s", 0) / steps,
            "controller_per_tick": 1e6 * timing.get("controller_s", 0) / ticks,
            "output_per_tick": 1e6 * timing.get("output_s", 0) / ticks,
        },
    }


def cmd_run(args) -> int:
    import mjcf
    from sim.controller import ControllerGains
    from sim.loop import Simulation
    from sim.metrics import tracking
    from sim.runfile import write_run
    from sim.scenario import build_motions, build_reference, limit_warnings, load_scenario

    sc = load_scenario(args.scenario)
    if args.duration is not None and not args.duration > 0:
        raise ScenarioError(f"--duration must be positive (got {args.duration})")
    desc = mjcf.load_table(sc.table)
    payload = mjcf.load_payload(sc.payload) if sc.payload else None
    rice = None
    from sim.uniaxial import RiceGains, RiceSimulation, is_rice

    if is_rice(desc):  # seed 001's analog controller, 8 kHz steps

        if args.iterations or sc.iteration.get("count", 0):
            raise ScenarioError("drive iterations are not available with the rice controller")
        gains = RiceGains.for_table(desc, sc.controller)
        rice = RiceSimulation(desc, payload, gains)
    else:
        gains = ControllerGains.for_table(desc, sc.controller)
    if abs(gains.rate_hz - sc.sample_rate_hz) > 1e-9:
        raise ScenarioError(f"output.sample_rate_hz ({sc.sample_rate_hz:g}) must equal controller.rate_hz "
                            f"({gains.rate_hz:g}): the recorder samples at the controller ticks")
    motions = build_motions(sc)
    ref = build_reference(sc, motions, args.duration)
    warns = limit_warnings(desc, motions)
    for w in warns:
        print(f"warning: {w}", file=sys.stderr)
    out = _out_dir(args.out)
    tm = rice.tm if rice else mjcf.build(desc, payload)
    sim = rice or Simulation(tm, gains=gains)
    rec = None
    if getattr(args, "rrd", None):
        from sim import recording

        rec = recording.RrdTarget.open(args.rrd)  # fails early (exit 2) if unwritable
    show = sys.stderr.isatty() and not args.json
    it = dict(sc.iteration)
    if args.iterations is not None:
        if args.iterations < 0 or args.iterations > 10:
            raise ScenarioError(f"--iterations must be 0..10 (got {args.iterations})")
        it["count"] = args.iterations
    history = []
    if it.get("count", 0) > 0:
        from sim.iteration import IterationSettings, iterate

        settings = IterationSettings.from_scenario(it)

        def note(i):
            if show:
                sys.stderr.write(f"  drive iteration {i} of {settings.count}\n")

        results, drives = iterate(sim, ref, settings, progress=note)
        scores = []
        for i, r in enumerate(results):
            tr = tracking(r.t, ref.d, ref.a, r.channels["table_displacement"], r.channels["table_acceleration"])
            score = float(np.mean([e["nrmse_acceleration"] for e in tr.values()])) if tr else 0.0
            scores.append(score if r.incomplete_reason is None else np.inf)
            history.append({"iteration": i, "mean_nrmse_acceleration": score, "tracking": tr})
        best = int(np.argmin(scores))
        res = results[best]
        plain = results[0]
        wall_total = sum(r.wall_s for r in results)
    else:
        res = sim.run(reference=ref, progress=show)
        plain, best, wall_total = res, 0, res.wall_s
    if len(res.t) < 2:
        raise DivergenceAtStart(res.incomplete_reason or "the simulation stopped before its second sample")
    run = build_runfile(res, tm, description=sc.description or sc.name,
                        payload_name=payload.name if payload else None, reference=ref,
                        extra_meta={"scenario": sc.name, "controller": _gains_json(gains)})
    run_path = out / f"{sc.name}.run.npz"
    write_run(run_path, run)
    summary = {
        "schema": SCHEMA,
        "scenario": sc.name,
        "table": desc.name,
        "payload": payload.name if payload else None,
        "duration_s": float(res.sim_s),
        "wall_s": float(res.wall_s),
        "realtime_factor": float(res.realtime_factor),
        "complete": res.incomplete_reason is None,
        "incomplete_reason": res.incomplete_reason,
        "tracking": tracking(res.t, ref.d, ref.a, res.channels["table_displacement"],
                             res.channels["table_acceleration"]),
        "drive_iterations": {"count": len(history) - 1 if history else 0, "chosen": best,
                             "frf": settings.frf if history else None,
                             "tracking_plain_controller": tracking(plain.t, ref.d, ref.a,
                                                                   plain.channels["table_displacement"],
                                                                   plain.channels["table_acceleration"]),
                             "history": [{"iteration": h["iteration"],
                                          "mean_nrmse_acceleration": h["mean_nrmse_acceleration"]}
                                         for h in history]},
        "wall_s_all_runs": float(wall_total),
        "warnings": warns,
        "run_file": str(run_path),
    }
    summary.update(_diagnostics(res, tm, sim.hp))
    if rec is not None:
        rec.write_run(run, tm)
        summary["recording"] = str(rec.path)
    _write_json_atomic(out / "summary.json", summary)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        _print_summary(summary)
    if res.incomplete_reason:
        print(f"error: {res.incomplete_reason}; kept {res.sim_s:.3f} s in {run_path} (marked incomplete)",
              file=sys.stderr)
        return 3
    return 0


def _gains_json(g) -> dict:
    from dataclasses import asdict, is_dataclass

    return {k: (v.tolist() if isinstance(v, np.ndarray) else asdict(v) if is_dataclass(v) else v)
            for k, v in g.__dict__.items()}


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
    import mjcf
    from sim.loop import Simulation
    from sim.metrics import channel_residuals
    from sim.runfile import read_run, write_run

    src = read_run(args.run, require=("valve_command",))
    table = args.table or src.meta["table"]
    desc = mjcf.load_table(table)
    if list(src.actuators) != list(desc.actuator_names):
        raise RunFileError(f"{args.run}: actuators {src.actuators} do not match table '{desc.name}' "
                           f"({list(desc.actuator_names)}); give --table")
    pay = args.payload if args.payload is not None else src.meta.get("payload")
    payload = mjcf.load_payload(pay) if pay else None
    tm = mjcf.build(desc, payload)
    from sim.controller import ControllerGains

    gains = ControllerGains(rate_hz=src.sample_rate_hz)
    sim = Simulation(tm, gains=gains)
    out = _out_dir(args.out)
    res = sim.run(valve_command=src.valve_command, progress=sys.stderr.isatty() and not args.json)
    run = build_runfile(res, tm, description=f"open-loop replay of {Path(args.run).name}",
                        payload_name=payload.name if payload else None,
                        extra_meta={"replay_of": str(args.run)})
    if src.reference is not None:
        run.reference = src.reference[:len(res.t)].copy()
    stem = Path(args.run).name[: -len(".run.npz")] if args.run.endswith(".run.npz") else Path(args.run).stem
    path = out / f"{stem}.replay.run.npz"
    write_run(path, run)
    resid = channel_residuals(src, run)
    summary = {"schema": SCHEMA, "replay_of": str(args.run), "run_file": str(path),
               "realtime_factor": float(res.realtime_factor), "complete": res.incomplete_reason is None,
               "residual_nrmse": resid}
    _write_json_atomic(out / "replay_summary.json", summary)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(f"replayed {args.run} open loop ({res.sim_s:.2f} s, {res.realtime_factor:.2f}x real time) -> {path}")
        for ch in ("table_displacement", "table_acceleration", "actuator_force"):
            if ch in resid:
                vals = ", ".join(f"{k} {100 * v:.2f}%" for k, v in resid[ch].items() if np.isfinite(v))
                print(f"  {ch} NRMSE: {vals}")
    return 0 if res.incomplete_reason is None else 3


def cmd_fit(args) -> int:
    import mjcf
    from sim import fit as F
    from sim.runfile import read_run

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
    out = _out_dir(args.out)
    log = (lambda m: print(m, file=sys.stderr)) if not args.json else None
    rep = F.fit(run, desc.raw, payload, candidates=cands, rounds=args.rounds, log=log)
    toml_path = out / f"{desc.name}_calibrated.toml"
    note = ("calibrated: shaketable fit of " + Path(args.run).name + "; effects added: "
            + (", ".join(f"{e['effect']} = {e['value']:.6g} {e['unit']}" for e in rep["effects_added"]) or "none"))
    F.write_table_toml(rep.pop("calibrated_table"), toml_path, note)
    rep["calibrated_table_file"] = str(toml_path)
    _write_json_atomic(out / "fit.json", rep)
    if args.json:
        print(json.dumps(rep, indent=2))
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
    from sim import geometry

    desc = mjcf.load_table(args.table)
    payload = mjcf.load_payload(args.payload) if args.payload else None
    tm = mjcf.build(desc, payload)
    r = geometry.study(desc, tm.effective_mass_matrix(), HydraulicParams.from_table(desc.raw))
    if args.json:
        print(json.dumps(r, indent=2))
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


__all__ = ["add_parsers", "build_runfile", "time"]
