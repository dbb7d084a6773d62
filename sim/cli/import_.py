"""``shaketable import``: a lab's recorder export (CSV, MAT) to run files through a map."""

from __future__ import annotations

from sim.runs.files import json_text


def cmd_import(args) -> int:
    from sim.runs.files import write_json_atomic
    from sim.runs.importer import import_files

    done = import_files(args.files, args.map, table=args.table, out=args.out)
    reports = [d.report for d in done]
    from pathlib import Path

    write_json_atomic(Path(args.out) / "import_report.json", {"map": args.map, "runs": reports})
    if args.json:
        print(json_text(reports, indent=2))
        return 0
    for r in reports:
        print(f"{r['file']} -> {r['run_file']}")
        print(
            f"  {r['samples']} samples at {r['sample_rate_hz']:g} Hz ({r['rate_from']}), "
            f"{r['duration_s']:.3f} s, table {r['table']} ({r['table_path']})"
            + (f", payload {r['payload']}" if r["payload"] else "")
        )
        for ch, cols in r["ranges_si"].items():
            txt = ", ".join(
                f"{k} {v['min']:.4g}..{v['max']:.4g}"
                + (f" ({v['missing_samples']} missing)" if v["missing_samples"] else "")
                for k, v in cols.items()
            )
            print(f"  {ch:22s} {txt}")
        for p, st in r["paths"].items():
            print(f"  {p:28s} " + ("ready" if st["ready"] else "needs " + "; ".join(st["missing"])))
    return 0


def add_parsers(sub) -> None:
    p = sub.add_parser("import", help="convert a lab's recorder export (CSV, MAT-file) to run files through a map")
    p.add_argument("files", nargs="+", metavar="FILE", help=".csv/.txt or .mat exports, one test each")
    p.add_argument("--map", required=True, metavar="MAP.toml", help="the column map (docs/import.md)")
    p.add_argument("--table", help="table description (default: the map's [source] table)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder for <name>.run.npz")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_import)


__all__ = ["add_parsers"]
