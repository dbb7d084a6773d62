"""``shaketable`` command line.

Every user error (bad file, bad parameter, unwritable output) is printed as one line
``error: ...`` on stderr with exit code 2 and no traceback.
"""

from __future__ import annotations

import argparse
import json
import sys

from sim.errors import user_errors
from sim.effects import build_model


# ------------------------------------------------------------------ model
def cmd_model(args) -> int:
    import numpy as np

    import mjcf
    from mjcf.builder import payload_mass

    desc = mjcf.load_table(args.table)
    payload = mjcf.load_payload(args.payload) if args.payload else None
    tm = build_model(desc, payload)
    m = tm.model
    eff = tm.effective_mass()
    acts = [
        {"name": a.name, "class": a.cls.name, "base": a.base_m.tolist(), "platen": a.platen_m.tolist(),
         "stroke": a.cls.half_stroke_m, "length_m": a.length0_m,
         "area_a_m2": a.cls.area_a_m2, "area_b_m2": a.cls.area_b_m2}
        for a in desc.actuators
    ]
    sup = []
    if desc.supports is not None:
        for i, (p, f) in enumerate(zip(desc.supports.positions_m, tm.info.support_loads_n), start=1):
            sup.append({"name": f"S{i}", "position": p.tolist(), "preload_n": float(f)})
    out = {
        "table": desc.name,
        "title": desc.title,
        "payload": payload.name if payload else None,
        "payload_kind": tm.info.payload_kind,
        "payload_mass_kg": payload_mass(payload),
        "n_bodies": int(m.nbody - 1),
        "n_joints": int(m.njnt),
        "nq": int(m.nq),
        "nv": int(m.nv),
        "n_equalities": int(m.neq),
        "timestep_s": float(m.opt.timestep),
        "total_mass_kg": tm.moving_mass(),
        "effective_mass": eff,
        "actuators": acts,
        "supports": sup,
        "accelerometers": [{"name": a.name, "position": a.position_m.tolist(), "direction": a.direction.tolist()}
                           for a in desc.accelerometers],
    }
    if args.xml:
        t, s = mjcf.write_xml(tm, args.xml)
        out["xml"] = {"table": str(t), "scene": str(s)}
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"{desc.title}  [{desc.name}]" + (f" + payload {payload.name} ({tm.info.payload_kind})" if payload else ""))
    print(f"  bodies {out['n_bodies']}, joints {out['n_joints']} (nq {m.nq}, nv {m.nv}), "
          f"loop equalities {m.neq}, step {m.opt.timestep * 1e3:.2f} ms")
    print(f"  moving mass {out['total_mass_kg'] / 1000:.2f} t (payload {out['payload_mass_kg'] / 1000:.2f} t)")
    print("  effective mass at the reference point:")
    for k, v in eff.items():
        unit = "t" if k in ("x", "y", "z") else "t m^2"
        print(f"    {k:2s} {v / 1000:8.2f} {unit}")
    print("  linkages (base -> platen swivel, m; half-stroke):")
    for a in acts:
        b = ", ".join(f"{v:+.2f}" for v in a["base"])
        p = ", ".join(f"{v:+.2f}" for v in a["platen"])
        print(f"    {a['name']:3s} {a['class']:12s} ({b}) -> ({p})  L {a['length_m']:.2f}  +/-{a['stroke'] * 1000:.0f} mm")
    if sup:
        print("  static supports (preload holding the home pose):")
        for s_ in sup:
            print(f"    {s_['name']}  at ({s_['position'][0]:+.2f}, {s_['position'][1]:+.2f})  {s_['preload_n'] / 1e3:8.1f} kN")
    if args.xml:
        print(f"  wrote {out['xml']['scene']} (includes {out['xml']['table']})")
    return 0


# ------------------------------------------------------------------ calibrate
def cmd_calibrate(args) -> int:
    import mjcf
    from mjcf.calibrate import calibrate_masses, write_calibrated

    desc = mjcf.load_table(args.table)
    res = calibrate_masses(desc)
    if args.write:
        write_calibrated(desc.source, res)
    if args.json:
        print(json.dumps({k: res[k] for k in ("values", "before", "after", "target")}, indent=2))
        return 0
    print(f"effective-mass calibration of {desc.name} against seed 000 Table 2")
    print(f"  {'dof':4s} {'target':>10s} {'before':>10s} {'after':>10s}")
    for k in res["target"]:
        print(f"  {k:4s} {res['target'][k] / 1e3:10.2f} {res['before'][k] / 1e3:10.2f} {res['after'][k] / 1e3:10.2f}")
    for k, v in res["values"].items():
        print(f"  {k} = {v:.2f}")
    print("  written to " + desc.source if args.write else "  (dry run: --write rewrites the table file)")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="shaketable", description="Digital twin of servo-hydraulic shaking tables")
    sub = p.add_subparsers(dest="command", required=True)

    m = sub.add_parser("model", help="build a table (+ payload) and show its model")
    m.add_argument("table", help="table name in scenarios/tables (e.g. cgs) or a .toml path")
    m.add_argument("--payload", help="payload name in scenarios/payloads or a .toml path")
    m.add_argument("--xml", metavar="DIR", help="write table.xml and scene.xml to DIR")
    m.add_argument("--json", action="store_true", help="print JSON")
    m.set_defaults(func=cmd_model)

    c = sub.add_parser("calibrate", help="calibrate the unpublished masses against the measured effective masses")
    c.add_argument("table")
    c.add_argument("--write", action="store_true", help="rewrite the calibrated values in the table file")
    c.add_argument("--json", action="store_true")
    c.set_defaults(func=cmd_calibrate)

    from sim.cli import characterize as characterize_cli, identify as identify_cli, run as run_cli, view as view_cli

    run_cli.add_parsers(sub)  # run, replay, fit, geometry
    view_cli.add_parsers(sub)  # rerun recordings of run files
    from sim.cli import sweep as sweep_cli

    sweep_cli.add_parsers(sub)  # many runs of one scenario (grid / random, local batch or Dask)
    characterize_cli.add_parsers(sub)  # the CGS identification programme (and rice/ucsd dispatch)
    identify_cli.add_parsers(sub)  # uni-axial identification, Rice/UCSD programmes
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except user_errors() as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
