"""``shaketable characterize``: the identification programme a table declares
(``[published] programme``: the 6-DOF programme of sim/identify/characterize.py, or a
paper's, sim/papers/programmes.py), run on the model; writes ``characterization.json``,
``report.md`` and figures (sim/report/programmes.py)."""

from __future__ import annotations

from sim.runs.files import json_text


def cmd_characterize(args) -> int:
    from sim.cli.progress import Progress
    from sim.report.programmes import characterize_table

    prog = Progress(enabled=not args.json, unit="tests")
    if args.calibrate:
        return _calibrate(args, prog)
    s = characterize_table(
        args.table,
        args.payload,
        out=args.out,
        quick=args.quick,
        workers=args.workers,
        progress=prog.count_callback(),
        stage=prog.text_callback(),
    )
    prog.close()
    if args.json:
        print(json_text(s, indent=2))
        return 0
    print(
        f"characterisation of {s['table']}"
        + (f" + {s['payload']}" if s.get("payload") else "")
        + f" ({s['mode']}, programme {s['programme']}): {s['wall_s']:.0f} s wall"
        + (f", {s['sim_s']:.0f} s simulated" if s.get("sim_s") else "")
    )
    if "comparison" in s:
        _print_comparison(s)
    if "cases" in s:
        print(
            f"  oil column (model FRF, optimal gains): x {s['oil_column_hz']['x']:.2f} Hz "
            f"(analytical {s['oil_column_analytical_hz']['x']:.2f} Hz)"
        )
        print(f"  {'case':28s} {'max |T| error 0-100 Hz':>24s}")
        for c in s["cases"]:
            print(f"  {c['case']:28s} {100 * c['max_error_0_100']:8.1f} % at {c['f_max_error_hz']:5.1f} Hz")
    if "identification" in s:
        i = s["identification"]
        print(
            f"  identified ({i['test_set']} tests, least squares): M_e {i['M_e_kg'] / 1e3:.1f} t, "
            f"K_e {i['K_e_N_per_m'] / 1e6:.3f} MN/m, C_e {i['C_e'] / 1e3:.1f} kN (s/m)^{i['alpha']:g}, "
            f"F_mu {i['F_mu_N'] / 1e3:.2f} kN"
        )
    print(f"  wrote {args.out}/characterization.json, {args.out}/report.md and {len(s.get('figures', []))} figures")
    return 0


def _print_comparison(s: dict) -> None:
    print(f"  {'quantity':34s} {'dof':4s} {'paper':>9s} {'model':>9s} {'error':>8s}")
    for r in s["comparison"]:
        flag = "" if r["within"] is None else ("" if r["within"] else "  <- outside tolerance")
        print(
            f"  {r['quantity']:34s} {r['dof']:4s} {r['paper']:9.4g} {r['model']:9.4g} {100 * r['error']:+7.2f} %{flag}"
        )
    for f in s.get("failed_tests", []):
        print(f"  test did not complete: {f}")
    if s.get("payload"):
        print("  (with a payload the paper's numbers are the bare table's: the differences are the payload's effect)")


def _calibrate(args, prog) -> int:
    from sim.calibrate import programme as P
    from sim.identify import characterize as C

    if args.payload:
        raise C.CharacterizeError("--calibrate works on the bare table; leave out --payload")
    desc, _ = C.load_inputs(args.table, None)
    prog.stage(f"calibrating {args.table} against its published values")
    cal = P.calibrate(args.table, quick=args.quick, workers=args.workers, progress=prog.count_callback())
    prog.close()
    P.write_calibration(desc.source, cal)
    from sim.runs.files import out_dir, write_json_atomic

    # the report shape of `shaketable calibrate` (calibration.json)
    write_json_atomic(out_dir(args.out) / "calibration.json", P.calibration_report(cal, desc, str(desc.source)))
    out = {
        "dead_volume_m3": cal["dead_volume_m3"],
        "seal_friction_n": cal["seal_friction_n"],
        "oil_column_hz_before": cal["before"]["oil_column_hz"],
        "friction_fraction_before": cal["before"].get("friction_fraction"),
        "linear_oil_column_hz_after": cal["linear_after"],
        "written": str(desc.source),
        "effective_mass_before": cal["before"].get("effective_mass"),
        "effective_mass_offset": cal.get("effective_mass_offset"),
        "masses": cal["masses"]["values"] if cal.get("masses") else None,
    }
    if args.json:
        print(json_text(out, indent=2))
        return 0
    pub = C.published(desc)
    print(f"calibrated {desc.name} against its published oil columns and friction:")
    for c, v in cal["dead_volume_m3"].items():
        print(f"  actuator_class.{c}.dead_volume_a/b_m3 = {v:.4e}")
    for c, v in cal["seal_friction_n"].items():
        print(f"  actuator_class.{c}.seal_friction_n = {v:.1f}")
    if cal.get("masses"):
        print("  effective mass (t, t m^2): published / virtual tests before / rigid-body before -> after")
        for d in C.DOFS:
            print(
                f"    {d:3s} {pub.effective_mass[d] / 1e3:8.2f} / {cal['before']['effective_mass'][d] / 1e3:8.2f}"
                f" / {cal['rigid_effective_mass_before'][d] / 1e3:8.2f} -> {cal['rigid_effective_mass_after'][d] / 1e3:8.2f}"
            )
        for k, v in cal["masses"]["values"].items():
            print(f"  {k} = {v:.2f}")
    print("  written to " + str(desc.source) + "; run `shaketable characterize " + args.table + "` to confirm")
    return 0


def add_parsers(sub) -> None:
    p = sub.add_parser(
        "characterize",
        help="run the table's identification programme on the model (characterization.json, report.md, figures)",
    )
    p.add_argument("table", help="table name in scenarios/tables (e.g. cgs) or a .toml path")
    p.add_argument("--payload", help="payload name in scenarios/payloads or a .toml path")
    p.add_argument("--out", default="characterization", help="output directory (default: ./characterization)")
    p.add_argument("--json", action="store_true", help="print the JSON summary")
    p.add_argument(
        "--quick",
        action="store_true",
        help="shorter records (CI), coarser estimates; a frf_random table: 3 segments per FRF; "
        "ls_identification: the periodic tests only",
    )
    p.add_argument("--workers", type=int, default=None, help="parallel test processes (default: CPU count)")
    p.add_argument(
        "--calibrate",
        action="store_true",
        help="choose dead volumes and seal friction from the virtual tests and rewrite the table file",
    )
    p.set_defaults(func=cmd_characterize)
