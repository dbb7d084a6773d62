"""``shaketable effects [TABLE]``: the effect library, and what a table lets calibration vary."""

from __future__ import annotations

from sim.runs.files import json_text


def cmd_effects(args) -> int:
    from sim.effects import catalogue, table_parameters

    if args.table is None:
        cat = catalogue()
        if args.json:
            print(json_text(cat, indent=1))
            return 0
        for e in cat:
            print(f"{e['type']}  [{', '.join(e['places']) or 'any place'}]{'  (every step)' if e['per_step'] else ''}")
            print(f"    {e['doc']}")
            for k, p in e["parameters"].items():
                dflt = "required" if p["default"] is None else f"default {p['default']:g}"
                print(f"    {k:24s} {p['unit']:18s} [{p['lower']:g}, {p['upper']:g}]  {dflt}")
            for k, v in e["settings"].items():
                print(f"    {k:24s} setting, default {v!r}")
        return 0
    import mjcf

    desc = mjcf.load_table(args.table)
    ps = table_parameters(desc)
    if args.json:
        print(
            json_text(
                [
                    {
                        "name": p.name,
                        "value": p.value,
                        "unit": p.unit,
                        "lower": p.lower,
                        "upper": p.upper,
                        "where": p.where,
                    }
                    for p in ps
                ],
                indent=1,
            )
        )
        return 0
    print(f"{desc.title}: {len(ps)} parameters (name = value unit [bounds] where)")
    for p in ps:
        print(f"  {p.name:48s} = {p.value:<12.6g} {p.unit:14s} [{p.lower:g}, {p.upper:g}]  {p.where}")
    return 0


def add_parsers(sub) -> None:
    e = sub.add_parser("effects", help="list the effect types, or a table's parameters calibration may vary")
    e.add_argument("table", nargs="?", help="table name in scenarios/tables or a .toml path")
    e.add_argument("--json", action="store_true", help="print JSON")
    e.set_defaults(func=cmd_effects)
