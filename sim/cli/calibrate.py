"""``shaketable calibrate``: runs -> what the model lacks, by a strategy: ``search``
(``sim.calibrate.search``: effects of the library on the residual) or ``scale``
(``sim.calibrate.fit.calibrate_scale``: global scale factors on the replay, formerly
``shaketable fit``, which stays as an alias); a table name (or ``--masses``) -> the
effective-mass calibration of the table's unpublished masses (``mjcf.calibrate``)."""

from __future__ import annotations

from pathlib import Path

from sim.errors import UserError
from sim.runs.files import json_text


def _is_masses(args) -> bool:
    if args.masses:
        return True
    first = args.inputs[0]
    return len(args.inputs) == 1 and not first.endswith(".npz")


def cmd_masses(args) -> int:
    import mjcf
    from mjcf.calibrate import NOTE_FORMULA, calibrate_masses
    from sim.calibrate.description import TomlText
    from sim.calibrate.programme import write_masses

    if len(args.inputs) != 1:
        raise UserError("calibrate --masses takes one table (a name in scenarios/tables or a .toml path)")
    desc = mjcf.load_table(args.inputs[0])
    res = calibrate_masses(desc)
    if args.write:
        doc = TomlText.read(desc.source)
        write_masses(doc, res, note=NOTE_FORMULA)
        doc.save(desc.source)
    if args.json:
        print(json_text({k: res[k] for k in ("values", "before", "after", "target")}, indent=2))
        return 0
    print(f"effective-mass calibration of {desc.name} against its published effective masses")
    print(f"  {'dof':4s} {'target':>10s} {'before':>10s} {'after':>10s}")
    for k in res["target"]:
        print(f"  {k:4s} {res['target'][k] / 1e3:10.2f} {res['before'][k] / 1e3:10.2f} {res['after'][k] / 1e3:10.2f}")
    for k, v in res["values"].items():
        print(f"  {k} = {v:.2f}")
    print("  written to " + desc.source if args.write else "  (dry run: --write rewrites the table file)")
    return 0


def _lowpass(text):
    if text in (None, "table"):
        return "table"
    if text == "none":
        return None
    try:
        v = float(text)
    except ValueError:
        raise UserError(f"--accel-lowpass {text!r}: give a frequency in Hz, 'table' or 'none'") from None
    if not v > 0:
        raise UserError(f"--accel-lowpass {text!r}: the frequency must be > 0 Hz (or 'none')")
    return v


def _effects(args):
    return [x.strip() for x in args.effects.split(",") if x.strip()] if args.effects else None


def cmd_scale(args, run_paths) -> int:
    """``calibrate RUN... --strategy scale`` (and the ``fit`` alias)."""
    from sim.calibrate.fit import calibrate_scale, write_scale_outputs
    from sim.report.calibration_scale import write_scale_report
    from sim.runs.files import out_dir

    log = None if args.json else (lambda m: print(m, flush=True))
    res = calibrate_scale(
        run_paths,
        table=args.table,
        payload=args.payload,
        holdout=getattr(args, "holdout", None) or None,
        effects=_effects(args),
        rounds=args.rounds,
        log=log,
    )
    out = out_dir(args.out)
    js = write_scale_outputs(res, out, run_paths)
    write_scale_report(res, out, Path(js["calibrated_table_file"]).name)
    if args.json:
        print(json_text(js, indent=2))
        return 0
    print(f"held-out replay error {100 * res.error_before:.2f} % -> {100 * res.error_after:.2f} % ({res.holdout_note})")
    for e in res.effects_added:
        for k, v in e["parameters"].items():
            print(f"  added {e['name']}: {k} = {v:.6g} +/- {e['uncertainty'][k]:.2g} {e['units'][k]} ({e['what']})")
    if not res.effects_added:
        print("  added nothing (no knob lowered the held-out error by the margin off its bounds)")
    print(f"  wrote {out / 'calibration.json'}, {out / 'report.md'}, {js['calibrated_table_file']}")
    return 0


def cmd_fit(args) -> int:
    """``shaketable fit RUN``: an alias of ``calibrate RUN --strategy scale``."""
    if not args.json:  # (stdout: stderr is for the one-line errors)
        print("note: `shaketable fit RUN` is `shaketable calibrate RUN --strategy scale`")
    return cmd_scale(args, [args.run])


def cmd_calibrate(args) -> int:
    if _is_masses(args):
        return cmd_masses(args)
    if args.strategy == "scale":
        if not args.out:
            raise UserError("calibrate RUN... --strategy scale: give --out DIR for calibration.json and the table")
        return cmd_scale(args, args.inputs)
    from sim.calibrate.search import calibrate, write_outputs
    from sim.report.calibration import write_report
    from sim.runs.files import out_dir

    if not args.out:
        raise UserError("calibrate RUN...: give --out DIR for calibration.json, report.md and the calibrated table")
    effects = _effects(args)
    log = None if args.json else (lambda m: print(m, flush=True))
    res = calibrate(
        args.inputs,
        table=args.table,
        payload=args.payload,
        holdout=args.holdout or None,
        effects=effects,
        effect_file=args.effect_file,
        accel_lowpass_hz=_lowpass(args.accel_lowpass),
        log=log,
        path=args.path,
        workers=args.workers,
    )
    out = out_dir(args.out)
    js = write_outputs(res, out, args.inputs)
    write_report(res, out, Path(js["calibrated_table_file"]).name)
    if args.json:
        print(json_text(js, indent=2))
        return 0
    print(f"held-out NRMSE {100 * res.error_before:.2f} % -> {100 * res.error_after:.2f} % ({res.holdout_note})")
    if res.not_excited:
        print(f"  not excited, left out of the error: {', '.join(res.not_excited)}")
    for e in res.effects_added:
        vals = ", ".join(
            f"{k} = {v:.6g} +/- {e['uncertainty'][k]:.2g} {e['units'][k]}"
            if e["uncertainty"].get(k) is not None
            else f"{k} = {v:.6g} {e['units'][k]} (held at the description's value)"
            for k, v in e["parameters"].items()
        )
        print(f"  added {e['name']} at {e['where']}: {vals}")
    if res.unexplained:
        u = res.unexplained
        print(
            f"  unexplained: {u['peak_hz']:.2f} Hz in {u['channel']} ({u['where']}), "
            f"{100 * u['fraction_of_residual']:.1f} % of the residual"
        )
    print(f"  wrote {out / 'calibration.json'}, {out / 'report.md'}, {js['calibrated_table_file']}")
    return 0


def add_parsers(sub) -> None:
    c = sub.add_parser(
        "calibrate",
        help="find what the model lacks in measured runs, add it, prove it on held-out "
        "runs (or, given a table: calibrate its unpublished masses)",
    )
    c.add_argument("inputs", nargs="+", metavar="RUN", help="run files (.run.npz); or one table name for --masses")
    c.add_argument("--table", help="the table description to calibrate (default: the runs' table)")
    c.add_argument(
        "--payload",
        help="payload on the table (default: the runs' payload; 'none': no specimen declared, "
        "calibration adds what stands on the table, e.g. its modes)",
    )
    c.add_argument(
        "--holdout", nargs="+", metavar="RUN", help="runs held out to prove the effects (default: every third run)"
    )
    c.add_argument("--out", help="output folder: calibration.json, report.md, <table>_calibrated.toml")
    c.add_argument("--effects", help="comma-separated effect types to try (default: every one with a force law)")
    c.add_argument("--effect-file", help="a Python file that registers the user's own effects")
    c.add_argument(
        "--accel-lowpass",
        help="the accelerometer conditioner's low-pass in Hz, 'table' (the "
        "description's [sensors] accelerometer_bandwidth_hz, default) or 'none'",
    )
    c.add_argument(
        "--path",
        choices=("mechanical", "replay", "closed_loop"),
        help="the residual path (default: chosen by the channels every run has: mechanical, "
        "else replay of the valve commands, else closed loop on the reference)",
    )
    c.add_argument("--workers", type=int, help="processes for the replay / closed-loop search (default: every core)")
    c.add_argument(
        "--masses",
        action="store_true",
        help="calibrate the table's unpublished masses against its "
        "published effective masses (the first argument is a table)",
    )
    c.add_argument("--write", action="store_true", help="--masses: rewrite the calibrated values in the table file")
    c.add_argument(
        "--strategy",
        choices=("search", "scale"),
        default="search",
        help="search: effects of the library on the residual (default); scale: global scale "
        "factors of the description on the replay of the recorded valve commands (was `fit`)",
    )
    c.add_argument("--rounds", type=int, default=2, help="--strategy scale: knobs to add at most (default 2)")
    c.add_argument("--json", action="store_true")
    c.set_defaults(func=cmd_calibrate)

    f = sub.add_parser("fit", help="alias of `calibrate RUN --strategy scale` (global scale factors on the replay)")
    f.add_argument("run", help="a measured .run.npz with valve_command")
    f.add_argument("--table", help="table (default: the description the run carries, else its meta.table)")
    f.add_argument("--payload", help="payload (default: the description the run carries; 'none' for a bare table)")
    f.add_argument("--effects", help="comma-separated knobs (default: all)")
    f.add_argument("--rounds", type=int, default=2, help="knobs to add at most (default 2)")
    f.add_argument("--out", default="out", help="output folder")
    f.add_argument("--json", action="store_true")
    f.set_defaults(func=cmd_fit)


__all__ = ["add_parsers", "cmd_calibrate", "cmd_fit", "cmd_scale"]
