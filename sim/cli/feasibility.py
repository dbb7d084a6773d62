"""``shaketable feasibility``: will this specimen and this motion work on this table, and
how far can we go? Exit code 0 feasible, 1 not feasible, 2 a user error."""

from __future__ import annotations

import sys

from sim.errors import UserError
from sim.runs.files import json_text

DEFAULT_WINDOW_S = 8.0  # run choice: a record is simulated on its strongest 8 s (+1 s lead-in); --window 0: whole


def _fmt(v: float, unit: str) -> str:
    if unit == "N":
        return f"{v / 1e3:.0f} kN"
    if unit == "N m":
        return f"{v / 9.81e3:.1f} t.m"
    if unit == "Pa":
        return f"{v / 1e6:.2f} MPa"
    if unit == "kg":
        return f"{v / 1e3:.1f} t"
    if unit == "m":
        return f"{v * 1e3:.1f} mm"
    if unit == "m/s^2":
        return f"{v / 9.81:.2f} g"
    if unit == "m^3":
        return f"{v * 1e3:.0f} l"
    if unit == "-":
        return f"{v:.3f}"
    return f"{v:.3g} {unit}"


def verdict_lines(fe: dict, top: int = 6) -> list[str]:
    """The verdict as text: feasible or not, the limiting check, the margins of the most
    utilised checks (the same lines for ``run`` and ``feasibility``)."""
    lines = []
    lim = next((c for c in fe["checks"] if c["name"] == fe.get("limiting")), None)
    head = "feasible on this table: " + ("yes" if fe["feasible"] else "NO (" + ", ".join(fe["failed"]) + ")")
    if lim is not None:
        head += f"; limiting: {lim['name']} at {100 * lim['utilisation']:.0f} %"
    lines.append(head)
    from sim.assess.feasibility import is_tracking

    ranked = sorted(
        (c for c in fe["checks"] if c["utilisation"] == c["utilisation"] and not is_tracking(c)),
        key=lambda c: -c["utilisation"],
    )[:top]
    ranked += [c for c in fe["checks"] if is_tracking(c)]
    for c in ranked:
        margin = 100 * (1 - c["utilisation"])
        lines.append(
            f"  {c['name']:28s} {_fmt(c['demand'], c['unit']):>12s} of {_fmt(c['capacity'], c['unit']):>12s}"
            f"  {100 * c['utilisation']:6.0f} %  margin {margin:+.0f} %"
            + ("" if c["pass"] else "  (tracking)" if is_tracking(c) else "  FAIL")
        )
    for w in fe.get("warnings", []):
        lines.append(f"warning: {w}")
    return lines


def _count(n: int, what: str) -> str:
    return f"{n} {what}" + ("" if n == 1 else "s")


def _floats(text: str, what: str) -> list[float]:
    try:
        vals = [float(x) for x in text.replace("x", ",").replace("X", ",").split(",") if x.strip()]
    except ValueError:
        raise UserError(f"{what} must be numbers separated by commas (got {text!r})") from None
    return vals


def _payload(args, desc_size):
    import mjcf
    from sim.assess.specimen import specimen_from_numbers

    nums = args.payload_mass is not None or args.payload_cg_height is not None
    if args.payload and nums:
        raise UserError("give --payload or --payload-mass/--payload-cg-height, not both")
    if args.payload:
        return mjcf.load_payload(args.payload)
    if not nums:
        if args.payload_footprint or args.payload_modes:
            raise UserError("--payload-footprint and --payload-modes need --payload-mass and --payload-cg-height")
        return None
    if args.payload_mass is None or args.payload_cg_height is None:
        raise UserError("a specimen from numbers needs both --payload-mass KG and --payload-cg-height M")
    fp = _floats(args.payload_footprint, "--payload-footprint") if args.payload_footprint else None
    if fp is not None and len(fp) != 2:
        raise UserError(f"--payload-footprint must be LxW in m (got {args.payload_footprint!r})")
    modes = _floats(args.payload_modes, "--payload-modes") if args.payload_modes else None
    return specimen_from_numbers(
        mass_kg=args.payload_mass,
        cg_height_m=args.payload_cg_height,
        footprint_m=fp,
        modes_hz=modes,
        direction=args.payload_direction,
        platen_size_m=desc_size,
    )


def cmd_feasibility(args) -> int:
    import mjcf
    from sim.assess import study
    from sim.runs.files import out_dir, write_json_atomic

    sc = None
    if args.scenario:
        from sim.scenario.files import load_scenario

        sc = load_scenario(args.scenario)
    table = args.table or (sc.table if sc else None)
    if table is None:
        raise UserError("give a scenario or --table (cgs, rice, ucsd or a .toml path)")
    desc = mjcf.load_table(table)
    payload = _payload(args, desc.platen.size_m[:2])
    if sc is not None and args.table:
        sc.table = table
    if args.suite and (args.max_scale or args.motion or sc):
        raise UserError("--suite runs its own records; leave out the scenario, --motion and --max-scale")
    window = args.window
    if window is None:
        window = DEFAULT_WINDOW_S if (args.motion or args.suite) else None
    elif window == 0:
        window = None
    say = None if args.json else (lambda text: print(f"  {text}", file=sys.stderr, flush=True))
    out = out_dir(args.out)  # checked before the work starts
    if args.suite:
        return _suite(args, table, payload, window, out, say)
    case = study.Case(
        table=table,
        motion=args.motion,
        payload=payload,
        scale=args.scale,
        window_s=window,
        iterations=args.iterations,
        scenario=sc,
        name=sc.name if sc else "feasibility",
    )
    if sc is not None and payload is None and sc.payload:
        case.payload = mjcf.load_payload(sc.payload)
    res = study.max_scale(case, progress=say) if args.max_scale else study.assess(case, progress=say)
    outcome = res.pop("_outcome", None)
    write_json_atomic(out / "feasibility.json", {k: v for k, v in res.items() if not k.startswith("_")})
    from sim.report.feasibility import write_report

    write_report(out, res, outcome)
    if args.json:
        print(json_text({k: v for k, v in res.items() if not k.startswith("_")}, indent=2))
    else:
        for line in verdict_lines(res):
            print(line)
        if args.max_scale:
            if res.get("max_scale") is None:
                print(f"largest scale: none (limited by {res['max_scale_limiting']}, whatever the amplitude)")
            else:
                up = res.get("max_scale_upper")
                print(
                    f"largest scale: {res['max_scale']:.3f}"
                    + (f" (fails at {up:.3f} on {res['limiting_above']})" if up else " (no failure found above it)")
                    + f"; {_count(res['max_scale_runs'], 'simulation')} in {_count(res['max_scale_rounds'], 'round')}"
                )
        print(f"wrote {out / 'feasibility.json'} and {out / 'report.md'}")
    return 0 if res["feasible"] else 1


def _suite(args, table, payload, window, out, say) -> int:
    import csv
    import io

    import mjcf
    from sim.assess import study
    from sim.runs.files import write_text_atomic

    records = study.suite_records(args.suite)
    scales = _floats(args.scales, "--scales") if args.scales else [args.scale]
    if any(not s > 0 for s in scales):
        raise UserError(f"--scales must all be positive amplitude factors (got {args.scales})")
    payloads = [mjcf.load_payload(p) for p in args.payloads.split(",")] if args.payloads else [payload]
    rows = study.suite(table, records, scales, payloads, window_s=window, iterations=args.iterations, progress=say)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=study.SUITE_COLUMNS)
    w.writeheader()
    w.writerows(rows)
    write_text_atomic(out / "suite.csv", buf.getvalue())
    if args.json:
        print(json_text(rows, indent=2))
    else:
        for r in rows:
            print(
                f"{r['record']:30s} x{r['scale']:<6g} {r['payload']:24s} "
                f"{'feasible' if r['feasible'] else 'NOT feasible'}  limiting {r['limiting']} "
                f"({100 * r['limiting_utilisation']:.0f} %)"
            )
        print(f"wrote {out / 'suite.csv'}")
    return 0 if all(r["feasible"] for r in rows) else 1


def add_parsers(sub) -> None:
    p = sub.add_parser("feasibility", help="will this specimen and motion work on this table, and how far can we go?")
    p.add_argument("scenario", nargs="?", help="a scenario (name or .toml); or give --table and --motion")
    p.add_argument("--table", help="table name or .toml (default: the scenario's)")
    p.add_argument("--payload", help="payload name or .toml (default: the scenario's)")
    p.add_argument("--payload-mass", type=float, metavar="KG", help="specimen from numbers: mass in kg")
    p.add_argument("--payload-cg-height", type=float, metavar="M", help="centre-of-gravity height above the platen, m")
    p.add_argument("--payload-footprint", metavar="LxW", help="base size in m (default 3x3)")
    p.add_argument("--payload-modes", metavar="HZ,...", help="a shear frame with these modes (one floor per mode)")
    p.add_argument("--payload-direction", default="x", choices=("x", "y"), help="the frame's weak direction")
    p.add_argument("--motion", help="elcentro1940, an .AT2 file (x) or a folder of .AT2 components (x, y, z)")
    p.add_argument("--scale", type=float, default=1.0, help="amplitude scale (default 1.0)")
    p.add_argument("--max-scale", action="store_true", help="find the largest scale at which every check passes")
    p.add_argument(
        "--window",
        type=float,
        default=None,
        metavar="S",
        help=f"simulate the strongest S seconds of a record (default {DEFAULT_WINDOW_S:g}; 0: all of it)",
    )
    p.add_argument("--iterations", type=int, default=None, help="drive iterations (default: the scenario's, or 0)")
    p.add_argument("--suite", metavar="DIR", help="every record folder in DIR x --scales x --payloads -> suite.csv")
    p.add_argument("--scales", help="suite: comma-separated scales (default --scale)")
    p.add_argument("--payloads", help="suite: comma-separated payload names (default --payload)")
    p.add_argument("--out", default="out/feasibility", help="output folder (default out/feasibility)")
    p.add_argument("--json", action="store_true", help="print the result as JSON")
    p.set_defaults(func=cmd_feasibility)


__all__ = ["add_parsers", "verdict_lines"]
