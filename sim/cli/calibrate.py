"""``shaketable calibrate``: runs -> what the model lacks (``sim.calibrate.search``:
effects of the library on the residual, against a linear ARX baseline); a table name (or
``--masses``) -> the effective-mass calibration of the table's unpublished masses
(``mjcf.calibrate``). ``--strategy scale`` and ``shaketable fit`` (global scale factors
on the replay) were removed (issue #23: the scale fit added 12.5 t to a 0.84 t table);
both now stop with a one-line error that says what to run instead."""

from __future__ import annotations

import argparse
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


#: commands kept only to say they were removed (left out of the command list)
REMOVED_COMMANDS = ("fit",)
#: what `--strategy scale` and `fit` say now
REMOVED = (
    "was removed (its global scale factors fitted absurd values: 12.5 t added to a 0.84 t table, "
    "issue #23); use `shaketable calibrate RUN... --out DIR`"
)


def cmd_fit(args) -> int:
    """``shaketable fit``: removed."""
    raise UserError(f"shaketable fit {REMOVED}")


def cmd_calibrate(args) -> int:
    if _is_masses(args):
        return cmd_masses(args)
    if args.strategy not in (None, "search"):  # `search` was the default: still accepted
        raise UserError(f"calibrate --strategy {args.strategy} {REMOVED}")
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
    pooled = " (pooled over the paths)" if len(res.searched_paths()) > 1 else ""
    print(
        f"held-out NRMSE{pooled} {100 * res.error_before:.2f} % -> {100 * res.error_after:.2f} % ({res.holdout_note})"
    )
    if len(res.paths) > 1:
        for name, p in res.paths.items():
            if "skipped" in p:
                print(f"  {name} path left out: {p['skipped']}")
                continue
            before = p.get("error_before_declared", p["error_before"])
            print(f"  {name} path: {100 * before:.2f} % -> {100 * p['error_after']:.2f} %")
    if res.not_excited:
        print(f"  not excited, left out of the error: {', '.join(res.not_excited)}")
    _print_baseline(res)
    for e in res.effects_added:
        vals = ", ".join(
            f"{k} = {v:.6g} +/- {e['uncertainty'][k]:.2g} {e['units'][k]}"
            if e["uncertainty"].get(k) is not None
            else f"{k} = {v:.6g} {e['units'][k]} (held at the description's value)"
            for k, v in e["parameters"].items()
        )
        found = f" (on the {e['path']} path)" if "path" in e else ""
        print(f"  added {e['name']} at {e['where']}{found}: {vals}")
    if res.unexplained:
        u = res.unexplained
        print(
            f"  unexplained: {u['peak_hz']:.2f} Hz in {u['channel']} ({u['where']}), "
            f"{100 * u['fraction_of_residual']:.1f} % of the residual"
        )
    print(f"  wrote {out / 'calibration.json'}, {out / 'report.md'}, {js['calibrated_table_file']}")
    return 0


def _print_baseline(res) -> None:
    from sim.calibrate.baseline import flag

    b = res.baseline
    if not b:
        return
    print(f"  linear ARX baseline (fit runs, free run): held-out NRMSE {100 * b['holdout_error']:.2f} %")
    line = flag(res.error_after, b)
    if line:
        print("  FLAG: " + line)


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
        help="narrow the search to one residual path (default: every path the runs support: "
        "the mechanical path where they record forces and motion, then the replay of the valve "
        "commands, else the closed loop on the reference, for what the first cannot see)",
    )
    c.add_argument("--workers", type=int, help="processes for the replay / closed-loop search (default: every core)")
    c.add_argument(
        "--masses",
        action="store_true",
        help="calibrate the table's unpublished masses against its "
        "published effective masses (the first argument is a table)",
    )
    c.add_argument("--write", action="store_true", help="--masses: rewrite the calibrated values in the table file")
    c.add_argument("--strategy", help=argparse.SUPPRESS)  # removed: `scale` stops with one line (REMOVED)
    c.add_argument("--json", action="store_true")
    c.set_defaults(func=cmd_calibrate)

    # removed: any arguments, one line (REMOVED), exit 2; no help line (and left out of the
    # command list, sim.cli.build_parser)
    f = sub.add_parser("fit", add_help=False, prefix_chars="\x00")  # every word an argument, -h too
    f.add_argument("rest", nargs="*")
    f.set_defaults(func=cmd_fit)


__all__ = ["add_parsers", "cmd_calibrate", "cmd_fit"]
