"""``shaketable table new``: a table description from the numbers a lab knows."""

from __future__ import annotations

import sys

FLAGS = {  # flag -> key of sim.scenario.tablegen.LAB_KEYS
    "moving_mass": "moving_mass_kg",
    "piston_area": "piston_area_m2",
    "half_stroke": "half_stroke_m",
    "supply_pressure": "supply_pressure_pa",
    "valve_flow": "valve_rated_flow_m3_s",
    "valve_bandwidth": "valve_bandwidth_hz",
    "actuators": "n_actuators",
    "oil_column": "oil_column_hz",
    "kp": "kp_per_s",
    "kdp": "kdp",
    "controller_rate": "controller_rate_hz",
    "recorder_rate": "recorder_rate_hz",
}


def cmd_table_new(args) -> int:
    from sim.scenario import tablegen

    inputs, src = {}, "the command line"
    if args.from_file:
        inputs = dict(tablegen.read_lab_inputs(args.from_file))
        src = f"{args.from_file} [lab]"
    for flag, key in FLAGS.items():
        v = getattr(args, flag)
        if v is not None:
            inputs[key] = int(v) if key == "n_actuators" else v
    out = args.out or f"scenarios/tables/{args.name}.toml"
    path = tablegen.write_uniaxial(args.name, inputs, out, src=src, kind=args.kind)
    what = (
        f"6-DOF, {inputs.get('layout')} layout"
        if args.kind == "6dof"
        else f"uni-axial, {inputs.get('n_actuators', 1)} actuator(s)"
    )
    print(
        f"wrote {path} ({what}); every number not given is marked assumed: or derived: in the file"
        + (
            "; the values given as unknown are marked unknown: and listed under [unknown]"
            if "[unknown]" in path.read_text()
            else ""
        ),
        file=sys.stderr,
    )
    print(path)
    return 0


def add_parsers(sub) -> None:
    t = sub.add_parser("table", help="describe a lab's own table")
    tsub = t.add_subparsers(dest="table_command", required=True)
    n = tsub.add_parser("new", help="write a table description from a few numbers (the rest assumed, marked so)")
    n.add_argument("name", help="table name (letters, digits, - or _)")
    n.add_argument(
        "--kind",
        choices=["uniaxial", "6dof"],
        default="uniaxial",
        help="6dof: give the layout (4h4v, hexapod or explicit attachment points) in the --from file's [lab]",
    )
    n.add_argument("--from", dest="from_file", metavar="FILE.toml", help="the lab's numbers under [lab] (SI units)")
    n.add_argument("--out", help="output .toml (default scenarios/tables/NAME.toml)")
    n.add_argument("--moving-mass", dest="moving_mass", type=float, metavar="KG")
    n.add_argument("--piston-area", dest="piston_area", type=float, metavar="M2")
    n.add_argument("--half-stroke", dest="half_stroke", type=float, metavar="M")
    n.add_argument("--supply-pressure", dest="supply_pressure", type=float, metavar="PA")
    n.add_argument("--valve-flow", dest="valve_flow", type=float, metavar="M3_S", help="rated flow")
    n.add_argument("--valve-bandwidth", dest="valve_bandwidth", type=float, metavar="HZ")
    n.add_argument("--actuators", type=int, metavar="N", help="actuators side by side (default 1)")
    n.add_argument("--oil-column", dest="oil_column", type=float, metavar="HZ", help="measured oil-column frequency")
    n.add_argument("--kp", type=float, metavar="1/S", help="displacement loop gain")
    n.add_argument("--kdp", type=float, metavar="GAIN", help="delta-P gain (0: none)")
    n.add_argument("--controller-rate", dest="controller_rate", type=float, metavar="HZ", help="divides 2048 Hz")
    n.add_argument("--recorder-rate", dest="recorder_rate", type=float, metavar="HZ", help="data recorder rate")
    n.set_defaults(func=cmd_table_new)


__all__ = ["add_parsers"]
