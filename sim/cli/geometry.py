"""``shaketable geometry``: how nonlinear is the table, where does it matter, and what it
does to a test (sim/assess/geometry.py, sim/assess/crosstalk.py)."""

from __future__ import annotations

import sys

from sim.runs.files import json_text


def cmd_geometry(args) -> int:
    import mjcf
    from sim.assess import geometry
    from sim.runs.files import out_dir

    desc = mjcf.load_table(args.table)
    payload = mjcf.load_payload(args.payload) if args.payload else None
    if args.out:
        out_dir(args.out)  # checked before the work starts
    if not args.json:
        print(
            f"geometric nonlinearity of {desc.name}: envelope, offset maps"
            + ("" if args.static else ", closed-loop crosstalk (simulations)"),
            file=sys.stderr,
            flush=True,
        )
    r = geometry.geometry(desc, payload, quick=args.quick, crosstalk_motions=() if args.static else None)
    if args.out:
        from sim.report.geometry import write_geometry

        write_geometry(args.out, r)
    if args.json:
        print(json_text({k: v for k, v in r.items() if not k.startswith("_")}, indent=2))
        return 0
    geometry.print_report(r)
    if args.out:
        print(f"  wrote {args.out}/geometry.json and {args.out}/report.md")
    return 0


def add_parsers(sub) -> None:
    g = sub.add_parser("geometry", help="geometric nonlinearity of a table: envelope, maps and closed-loop crosstalk")
    g.add_argument("table", help="table name in scenarios/tables or a .toml path")
    g.add_argument("--payload", help="payload name in scenarios/payloads or a .toml path")
    g.add_argument("--out", metavar="DIR", help="write geometry.json, report.md and figures to DIR")
    g.add_argument("--json", action="store_true", help="print the study as JSON")
    g.add_argument("--static", action="store_true", help="no simulations: the kinematic and hydraulic study only")
    g.add_argument("--quick", action="store_true", help="short crosstalk runs (two sines), coarse maps")
    g.set_defaults(func=cmd_geometry)
