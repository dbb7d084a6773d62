"""``shaketable`` command line.

Every user error (bad file, bad parameter, unwritable output) is printed as one line
``error: ...`` on stderr with exit code 2 and no traceback.
"""

from __future__ import annotations

import argparse
import sys

from sim.effects import build_model
from sim.errors import user_errors
from sim.runs.files import json_text


# ------------------------------------------------------------------ model
def cmd_model(args) -> int:
    import mjcf
    from mjcf.builder import payload_mass

    desc = mjcf.load_table(args.table)
    payload = mjcf.load_payload(args.payload) if args.payload else None
    tm = build_model(desc, payload)
    m = tm.model
    eff = tm.effective_mass()
    acts = [
        {
            "name": a.name,
            "class": a.cls.name,
            "base": a.base_m.tolist(),
            "platen": a.platen_m.tolist(),
            "stroke": a.cls.half_stroke_m,
            "length_m": a.length0_m,
            "area_a_m2": a.cls.area_a_m2,
            "area_b_m2": a.cls.area_b_m2,
        }
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
        "accelerometers": [
            {"name": a.name, "position": a.position_m.tolist(), "direction": a.direction.tolist()}
            for a in desc.accelerometers
        ],
    }
    if args.xml:
        t, s = mjcf.write_xml(tm, args.xml)
        out["xml"] = {"table": str(t), "scene": str(s)}
    if args.json:
        print(json_text(out, indent=2))
        return 0
    print(f"{desc.title}  [{desc.name}]" + (f" + payload {payload.name} ({tm.info.payload_kind})" if payload else ""))
    print(
        f"  bodies {out['n_bodies']}, joints {out['n_joints']} (nq {m.nq}, nv {m.nv}), "
        f"loop equalities {m.neq}, step {m.opt.timestep * 1e3:.2f} ms"
    )
    print(f"  moving mass {out['total_mass_kg'] / 1000:.2f} t (payload {out['payload_mass_kg'] / 1000:.2f} t)")
    print("  effective mass at the reference point:")
    for k, v in eff.items():
        unit = "t" if k in ("x", "y", "z") else "t m^2"
        print(f"    {k:2s} {v / 1000:8.2f} {unit}")
    print("  linkages (base -> platen swivel, m; half-stroke):")
    for a in acts:
        b = ", ".join(f"{v:+.2f}" for v in a["base"])
        p = ", ".join(f"{v:+.2f}" for v in a["platen"])
        print(
            f"    {a['name']:3s} {a['class']:12s} ({b}) -> ({p})  L {a['length_m']:.2f}  +/-{a['stroke'] * 1000:.0f} mm"
        )
    if sup:
        print("  static supports (preload holding the home pose):")
        for s_ in sup:
            print(
                f"    {s_['name']}  at ({s_['position'][0]:+.2f}, {s_['position'][1]:+.2f})  {s_['preload_n'] / 1e3:8.1f} kN"
            )
    if args.xml:
        print(f"  wrote {out['xml']['scene']} (includes {out['xml']['table']})")
    return 0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="shaketable", description="Digital twin of servo-hydraulic shaking tables")
    p.add_argument(
        "--debug", action="store_true", help="show the full traceback of an error instead of its one-line message"
    )
    sub = p.add_subparsers(dest="command", required=True)

    m = sub.add_parser("model", help="build a table (+ payload) and show its model")
    m.add_argument("table", help="table name in scenarios/tables (e.g. cgs) or a .toml path")
    m.add_argument("--payload", help="payload name in scenarios/payloads or a .toml path")
    m.add_argument("--xml", metavar="DIR", help="write table.xml and scene.xml to DIR")
    m.add_argument("--json", action="store_true", help="print JSON")
    m.set_defaults(func=cmd_model)

    from sim.cli import calibrate as calibrate_cli
    from sim.cli import characterize as characterize_cli
    from sim.cli import effects as effects_cli
    from sim.cli import feasibility as feasibility_cli
    from sim.cli import geometry as geometry_cli
    from sim.cli import identify as identify_cli
    from sim.cli import import_ as import_cli
    from sim.cli import run as run_cli
    from sim.cli import table as table_cli
    from sim.cli import view as view_cli

    run_cli.add_parsers(sub)  # run, replay
    calibrate_cli.add_parsers(sub)  # calibrate RUN..., calibrate TABLE (masses); `fit` removed (one line)
    feasibility_cli.add_parsers(sub)  # will it work on this table, and the largest scale
    geometry_cli.add_parsers(sub)  # geometric nonlinearity
    view_cli.add_parsers(sub)  # rerun recordings of run files
    characterize_cli.add_parsers(sub)  # the identification programme each table declares
    identify_cli.add_parsers(sub)  # least squares on run files
    effects_cli.add_parsers(sub)  # the effect library and a table's parameters
    table_cli.add_parsers(sub)  # a lab's own table description from a few numbers
    import_cli.add_parsers(sub)  # a lab's recorder export to run files
    from sim.cli import sweep as sweep_cli

    sweep_cli.add_parsers(sub)  # many runs of one scenario (grid / random, local batch or Dask)
    sub.metavar = "{" + ",".join(k for k in sub.choices if k not in calibrate_cli.REMOVED_COMMANDS) + "}"
    return p


def _quiet_stdout() -> None:
    """Point stdout at /dev/null: the reader of a pipe has gone (``... | head -1``), and
    Python's own flush at exit would otherwise print a BrokenPipeError."""
    import os

    try:
        if sys.stdout.fileno() != 1:  # a replaced stdout (a test's capture): leave descriptors alone
            return
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
    except (OSError, ValueError, AttributeError):  # stdout without a descriptor
        pass


def main(argv=None) -> int:
    """Run one command; returns the exit code: 0 done, 2 a user error (one line on stderr),
    3 a simulation that diverged (what was computed is kept, marked incomplete), 130
    interrupted (Ctrl-C). ``--debug`` re-raises instead, with the traceback."""
    from sim.errors import DivergenceError, is_interrupt

    parser = build_parser()
    args = parser.parse_args(argv)
    debug = getattr(args, "debug", False)
    try:
        return int(args.func(args) or 0)
    except user_errors() as e:
        if debug:
            raise
        print(f"error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    except DivergenceError as e:
        if debug:
            raise
        print(f"error: {e}", file=sys.stderr)
        return 3
    except BrokenPipeError:
        _quiet_stdout()
        return 141  # 128 + SIGPIPE, as a shell reports a pipeline cut short
    except KeyboardInterrupt:
        if debug:
            raise
        print("interrupted: files already written are complete; nothing half-written was kept", file=sys.stderr)
        return 130
    except Exception as e:  # a library that wrapped the Ctrl-C (numba compiling, a pool) is still Ctrl-C
        if debug or not is_interrupt(e):
            raise
        print("interrupted: files already written are complete; nothing half-written was kept", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
