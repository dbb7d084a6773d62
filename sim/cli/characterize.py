"""``shaketable characterize``: the virtual identification programme (sim/identify/characterize.py)."""

from __future__ import annotations

import sys
import time

from sim.runs.files import json_text, out_dir


def _progress(show: bool):
    if not show:
        return None
    t0 = time.perf_counter()

    def cb(done, total):
        sys.stderr.write(f"\r  tests {done}/{total}  ({time.perf_counter() - t0:5.0f} s)")
        sys.stderr.flush()
        if done == total:
            sys.stderr.write("\n")

    return cb


def cmd_characterize(args) -> int:
    from sim.identify import characterize as C
    show = sys.stderr.isatty() and not args.json
    from sim.papers.uniaxial import PROGRAMMES

    if args.table in PROGRAMMES:
        # the uni-axial tables of seeds 001/002 run their papers' own programmes (sim/papers/uniaxial.py)
        if args.calibrate or args.payload:
            raise C.CharacterizeError(f"characterize {args.table} runs its paper's programme; "
                                      "--calibrate and --payload are for the CGS programme")
        import argparse

        from sim.cli.identify import cmd_uniaxial

        return cmd_uniaxial(argparse.Namespace(table=args.table, out=args.out, workers=args.workers or 2,
                                               quick=args.quick))
    if args.calibrate:
        return _calibrate(args, show)
    from sim.report.characterization import write_characterization

    C.load_inputs(args.table, args.payload)  # the inputs first: a mistake there creates no folder
    out_dir(args.out)  # checked before the work starts
    s = C.characterize(args.table, args.payload, quick=args.quick, workers=args.workers, progress=_progress(show))
    write_characterization(args.out, s)
    s.pop("_results", None)
    if args.json:
        print(json_text(s, indent=2))
        return 0
    print(f"characterisation of {s['table']}" + (f" + {s['payload']}" if s["payload"] else "")
          + f" ({s['mode']}): {s['wall_s']:.0f} s wall, {s['sim_s']:.0f} s simulated")
    print(f"  {'quantity':34s} {'dof':4s} {'paper':>9s} {'model':>9s} {'error':>8s}")
    for r in s["comparison"]:
        flag = "" if r["within"] is None else ("" if r["within"] else "  <- outside tolerance")
        print(f"  {r['quantity']:34s} {r['dof']:4s} {r['paper']:9.4g} {r['model']:9.4g} {100 * r['error']:+7.2f} %{flag}")
    if s["failed_tests"]:
        for f in s["failed_tests"]:
            print(f"  test did not complete: {f}")
    if s["payload"]:
        print("  (with a payload the paper's numbers are the bare table's: the differences are the payload's effect)")
    print(f"  wrote {args.out}/characterization.json and {args.out}/report.md")
    return 0


def _calibrate(args, show) -> int:
    from sim.calibrate import programme as P
    from sim.identify import characterize as C
    if args.payload:
        raise C.CharacterizeError("--calibrate works on the bare table; leave out --payload")
    desc, _ = C.load_inputs(args.table, None)
    cal = P.calibrate(args.table, quick=args.quick, workers=args.workers, progress=_progress(show))
    P.write_calibration(desc.source, cal)
    out = {"dead_volume_m3": cal["dead_volume_m3"], "seal_friction_n": cal["seal_friction_n"],
           "oil_column_hz_before": cal["before"]["oil_column_hz"],
           "friction_fraction_before": cal["before"].get("friction_fraction"),
           "linear_oil_column_hz_after": cal["linear_after"], "written": str(desc.source),
           "effective_mass_before": cal["before"].get("effective_mass"),
           "effective_mass_offset": cal.get("effective_mass_offset"),
           "masses": cal["masses"]["values"] if cal.get("masses") else None}
    if args.json:
        print(json_text(out, indent=2))
        return 0
    pub = C.published(desc)
    print(f"calibrated {desc.name} against its published oil columns and friction ({pub.source}):")
    for c, v in cal["dead_volume_m3"].items():
        print(f"  actuator_class.{c}.dead_volume_a/b_m3 = {v:.4e}")
    for c, v in cal["seal_friction_n"].items():
        print(f"  actuator_class.{c}.seal_friction_n = {v:.1f}")
    if cal.get("masses"):
        print("  effective mass (t, t m^2): published / virtual tests before / rigid-body before -> after")
        for d in C.DOFS:
            print(f"    {d:3s} {pub.effective_mass[d] / 1e3:8.2f} / {cal['before']['effective_mass'][d] / 1e3:8.2f}"
                  f" / {cal['rigid_effective_mass_before'][d] / 1e3:8.2f} -> {cal['rigid_effective_mass_after'][d] / 1e3:8.2f}")
        for k, v in cal["masses"]["values"].items():
            print(f"  {k} = {v:.2f}")
    print("  written to " + str(desc.source) + "; run `shaketable characterize " + args.table + "` to confirm")
    return 0


def add_parsers(sub) -> None:
    p = sub.add_parser("characterize", help="run the identification programme of the paper on the model")
    p.add_argument("table", help="table name in scenarios/tables (e.g. cgs) or a .toml path")
    p.add_argument("--payload", help="payload name in scenarios/payloads or a .toml path")
    p.add_argument("--out", default="characterization", help="output directory (default: ./characterization)")
    p.add_argument("--json", action="store_true", help="print the JSON summary")
    p.add_argument("--quick", action="store_true", help="shorter records (CI); coarser estimates")
    p.add_argument("--workers", type=int, default=None, help="parallel test processes (default: CPU count)")
    p.add_argument("--calibrate", action="store_true",
                   help="choose dead volumes and seal friction from the virtual tests and rewrite the table file")
    p.set_defaults(func=cmd_characterize)
