"""A 6-DOF table description from the few numbers a lab knows (``table new --kind 6dof``).

The lab gives its platen (size, moving mass, perhaps its inertia), its actuators
(piston area, stroke, and the layout: a named standard layout with a few dimensions,
or the attachment points of every actuator), its hydraulics (supply pressure, valve
rated flow and bandwidth) and perhaps its controller gains. Everything else is written
``assumed:`` with a reason or ``derived:`` with the formula, as the uni-axial
generator (:mod:`sim.scenario.tablegen`) does. The output is a plain description:
nothing in the code knows the layout afterwards.

Layouts:

* ``"4h4v"``: 8 actuators, 2 horizontal per axis on the platen's -x and -y edges
  (lines of action through the platen's centre of mass, ``horizontal_spacing_m``
  apart) and 4 vertical under the platen (``vertical_spacing_m`` = [dx, dy] apart);
  the usual layout of 6-DOF tables of a few metres.
* ``"hexapod"``: the 6-6 Stewart platform: joints in pairs on a base circle
  (``base_radius_m``) and a platen circle (``platen_radius_m``), each pair
  ``pair_angle_deg`` wide, the pairs of the two circles 60 deg apart, ``height_m``
  between the joint planes.
* explicit: ``[[lab.actuator]]`` entries with ``name``, ``base_m``, ``platen_m`` (table
  frame at mid-stroke) and ``class = "horizontal" | "vertical"``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim.errors import ScenarioError
from sim.scenario.tablegen import (
    BULK_MODULUS_PA,
    CONTROL_KEYS,
    DEAD_FRACTION,
    _num,
    common_sections,
    control_lines,
    specimen_rating,
)

#: What a lab gives for a 6-DOF table: key -> (meaning, required). SI units.
LAB_KEYS6 = {
    "moving_mass_kg": ("platen + actuator rods + anything rigidly on them (bare table)", True),
    "platen_size_m": ("platen length x width x depth [a, b, h]", True),
    "piston_area_m2": ("piston area of one actuator (double-ended)", True),
    "half_stroke_m": ("actuator stroke from mid-stroke to one end", True),
    "supply_pressure_pa": ("hydraulic supply pressure", True),
    "valve_rated_flow_m3_s": ("servovalve rated flow (at its rated drop), one valve per actuator", True),
    "valve_bandwidth_hz": ("servovalve -3 dB (or 90 deg) frequency", True),
    "layout": ('"4h4v" (8 actuators), "hexapod" (6), or "explicit" with [[lab.actuator]] entries', True),
    "inertia_kg_m2": ("platen principal moments [Ixx, Iyy, Izz] about its centre of mass", False),
    "vertical_piston_area_m2": ("piston area of the vertical actuators, if not piston_area_m2", False),
    "vertical_half_stroke_m": ("half-stroke of the vertical actuators, if not half_stroke_m", False),
    "valve_rated_drop_pa": ("pressure drop of the rated flow (default 6.9 MPa, 1000 psi)", False),
    **CONTROL_KEYS,
    "kp_per_s": ("displacement loop gain, one number or 6 (default from the oil columns)", False),
    "bulk_modulus_pa": ("effective oil + hose bulk modulus (default 1.0 GPa)", False),
    "kfb": ("force-balance gain on the redundant actuators' fighting forces (default 0.05)", False),
    "max_specimen_kg": ("rated specimen mass (default: unknown, feasibility does not rate it)", False),
    "overturning_moment_n_m": ("rated overturning moment (default: unknown, feasibility does not rate it)", False),
    "static_supports": (
        "true: pneumatic supports carry the dead weight (default for 4h4v); false: the actuators",
        False,
    ),
    "actuator_length_m": (
        "4h4v: swivel-to-swivel length at mid-stroke (default max(1 m, 4 x half-stroke + 0.3 m))",
        False,
    ),
    "horizontal_spacing_m": (
        "4h4v: distance between the two parallel horizontal actuators (default 0.6 x side)",
        False,
    ),
    "vertical_spacing_m": ("4h4v: [dx, dy] between the vertical actuators (default 0.7 x the platen)", False),
    "base_radius_m": ("hexapod: radius of the base joint circle (default 1.3 x platen_radius_m)", False),
    "platen_radius_m": ("hexapod: radius of the platen joint circle (default 0.4 x the shorter side)", False),
    "height_m": ("hexapod: height between the joint planes at mid-stroke (default the platen joint radius)", False),
    "pair_angle_deg": ("hexapod: angular width of each joint pair on both circles (default 20)", False),
    "actuator": ("explicit layout: [[lab.actuator]] name, base_m, platen_m, class", False),
    "title": ("a one-line title", False),
}
SUPPORT_PRESSURE_PA = 1.0e6  #: assumed design pressure of pneumatic static supports at capacity (CGS: 1.2 MPa)
SUPPORT_HZ = 2.0  #: assumed vertical frequency of the supported capacity mass on its air springs (below the test band)


def _vec(inputs, key, n, src, default=None):
    v = inputs.get(key, default)
    if v is None:
        raise ScenarioError(f"{src}: missing '{key}' ({LAB_KEYS6[key][0]}); add it in SI units")
    if not (isinstance(v, list) and len(v) == n and all(isinstance(x, (int, float)) and x > 0 for x in v)):
        raise ScenarioError(f"{src}: '{key}' must be {n} positive numbers in SI units (got {v!r})")
    return [float(x) for x in v]


def _strokes(base, plat, pose):
    """Actuator strokes from mid-stroke at 6-DOF poses (6,) -> (n_act,) or (k, 6) -> (k, n_act):
    the description's inverse kinematics (:func:`mjcf.description.actuator_strokes`)."""
    from mjcf.description import rotation_matrices

    P = np.atleast_2d(pose)
    pts = P[:, None, :3] + plat @ rotation_matrices(P[:, 3:]).transpose(0, 2, 1)
    out = np.linalg.norm(pts - base, axis=2) - np.linalg.norm(plat - base, axis=1)
    return out[0] if np.ndim(pose) == 1 else out


def _jacobian(base, plat, h=1e-6):
    J = np.zeros((len(base), 6))
    for k in range(6):
        dp = np.zeros(6)
        dp[k] = h
        J[:, k] = (_strokes(base, plat, dp) - _strokes(base, plat, -dp)) / (2 * h)
    return J


def _layout(kind, inputs, size, s_h, s_v, src):
    """(names, classes, base (n,3), platen (n,3), comment) of the actuator layout."""
    a, b, h = size
    if kind == "4h4v":
        L = _num(inputs, "actuator_length_m", src, default=max(1.0, 4 * max(s_h, s_v) + 0.3))
        hs = _num(inputs, "horizontal_spacing_m", src, default=0.6 * min(a, b))
        vx, vy = _vec(inputs, "vertical_spacing_m", 2, src, default=[0.7 * a, 0.7 * b])
        if hs > min(a, b) or vx > a or vy > b:
            raise ScenarioError(
                f"{src}: 'horizontal_spacing_m'/'vertical_spacing_m' must fit on the platen {a} x {b} m"
            )
        zc = -h / 2
        names = ["X1", "X2", "Y1", "Y2", "Z1", "Z2", "Z3", "Z4"]
        cls = ["horizontal"] * 4 + ["vertical"] * 4
        plat = [[-a / 2, hs / 2, zc], [-a / 2, -hs / 2, zc], [hs / 2, -b / 2, zc], [-hs / 2, -b / 2, zc]]
        base = [
            [-a / 2 - L, hs / 2, zc],
            [-a / 2 - L, -hs / 2, zc],
            [hs / 2, -b / 2 - L, zc],
            [-hs / 2, -b / 2 - L, zc],
        ]
        for sx, sy in ((-1, 1), (-1, -1), (1, 1), (1, -1)):
            plat.append([sx * vx / 2, sy * vy / 2, -h])
            base.append([sx * vx / 2, sy * vy / 2, -h - L])
        note = (
            f"assumed layout 4h4v: X1, X2 on the -x edge and Y1, Y2 on the -y edge, {hs:.4g} m apart, lines of action "
            f"through the platen's centre of mass; Z1..Z4 under the platen {vx:.4g} x {vy:.4g} m apart; {L:.4g} m "
            "swivel to swivel"
        )
        return names, cls, np.array(base), np.array(plat), note
    if kind == "hexapod":
        rp = _num(inputs, "platen_radius_m", src, default=0.4 * min(a, b))
        rb = _num(inputs, "base_radius_m", src, default=1.3 * rp)
        H = _num(inputs, "height_m", src, default=rp)
        pair = math.radians(_num(inputs, "pair_angle_deg", src, default=20.0))
        if rp > 0.5 * min(a, b):
            raise ScenarioError(f"{src}: 'platen_radius_m' {rp:g} must fit under the platen (<= {0.5 * min(a, b):g} m)")
        if not 0 < pair < math.radians(100):
            raise ScenarioError(f"{src}: 'pair_angle_deg' must be between 0 and 100 degrees")
        names, cls, base, plat = [], [], [], []
        for k in range(3):
            c = math.radians(120 * k)
            for j, sgn in enumerate((-1, 1)):
                tb = c + sgn * pair / 2  # base pair centred on 0, 120, 240 deg
                tp = c + sgn * (math.radians(60) - pair / 2)  # to the neighbouring platen pair (60 deg off)
                names.append(f"L{2 * k + j + 1}")
                cls.append("leg")
                base.append([rb * math.cos(tb), rb * math.sin(tb), -h - H])
                plat.append([rp * math.cos(tp), rp * math.sin(tp), -h])
        note = (
            f"assumed layout hexapod (6-6 Stewart): base joints on r = {rb:.4g} m, platen joints on r = {rp:.4g} m "
            f"under the platen, pairs {math.degrees(pair):.4g} deg wide, base pairs at 0/120/240 deg, platen pairs "
            f"60 deg off them, {H:.4g} m between the joint planes"
        )
        return names, cls, np.array(base), np.array(plat), note
    if kind == "explicit":
        rows = inputs.get("actuator")
        if not isinstance(rows, list) or len(rows) < 6:
            raise ScenarioError(
                f'{src}: layout "explicit" needs at least 6 [[lab.actuator]] entries (name, base_m, platen_m, class)'
            )
        names, cls, base, plat = [], [], [], []
        for i, r in enumerate(rows):
            ok = isinstance(r, dict) and isinstance(r.get("name"), str) and r.get("class") in ("horizontal", "vertical")
            pts = [r.get("base_m"), r.get("platen_m")] if isinstance(r, dict) else [None, None]
            if not ok or not all(isinstance(p, list) and len(p) == 3 for p in pts):
                raise ScenarioError(
                    f'{src}: [[lab.actuator]] entry {i + 1} needs name, class ("horizontal" or "vertical"), '
                    "base_m and platen_m ([x, y, z] in m, table frame at mid-stroke)"
                )
            names.append(r["name"])
            cls.append(r["class"])
            base.append([float(x) for x in r["base_m"]])
            plat.append([float(x) for x in r["platen_m"]])
        return names, cls, np.array(base), np.array(plat), f"lab: {src} [[lab.actuator]]"
    raise ScenarioError(f'{src}: \'layout\' must be "4h4v", "hexapod" or "explicit" (got {kind!r})')


def _fit_limits(base, plat, usable, a, b):
    """The largest common fraction c of [usable translation, usable / half-diagonal
    rotation] whose every corner the actuators reach within ``usable`` (per actuator)."""
    R = 0.5 * math.hypot(a, b)
    import itertools

    signs = np.array(list(itertools.product((-1.0, 1.0), repeat=6)))
    umin = usable.min()

    def need(c):
        box = np.array([c * umin] * 3 + [c * umin / R] * 3)
        return float(np.max(np.abs(_strokes(base, plat, signs * box)) / usable))

    lo, hi = 0.0, 2.0
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if need(mid) <= 0.98 else (lo, mid)
    return lo * umin, lo * umin / R


@dataclass
class _Lab6:
    """The lab's numbers for a 6-DOF table, read and checked (SI), and the source of each."""

    kind: str  #: layout name
    m: float  #: moving mass
    a: float  #: platen length
    b: float  #: platen width
    h: float  #: platen depth
    A_h: float  #: piston area (horizontal or all)
    s_h: float  #: half-stroke (horizontal or all)
    A_v: float  #: piston area of the vertical actuators
    s_v: float  #: half-stroke of the vertical actuators
    ps: float  #: supply pressure
    q: float  #: valve rated flow
    fv: float  #: valve bandwidth
    drop: float  #: valve rated drop
    beta: float  #: bulk modulus
    kfb: float  #: force-balance gain
    m_spec: float | None  #: rated specimen mass
    lab: str  #: "lab: <src>", the comment of a lab's number
    given: dict  #: key -> its source comment (lab's number or unknown range)


@dataclass
class _Layout6:
    """The actuators' attachment points, their classes and the layout's Jacobian."""

    names: list
    cls: list
    base: np.ndarray
    plat: np.ndarray
    note: str
    supports: bool
    J: np.ndarray


def sixdof(name: str, inputs: dict, *, src: str = "the command line") -> str:
    """TOML text of a 6-DOF table description named ``name`` from the lab's ``inputs``
    (keys of :data:`LAB_KEYS6`; the moving mass, supply pressure, valve rated flow and
    bandwidth and bulk modulus possibly unknown, :mod:`sim.scenario.labvalues`)."""
    from sim.scenario import labvalues

    inputs, unknowns, L = _read_lab6(name, inputs, src)
    lay = _read_layout(L, inputs, src)
    classes = {}
    for c in dict.fromkeys(lay.cls):
        vert = c == "vertical"
        classes[c] = {"A": L.A_v if vert else L.A_h, "s": L.s_v if vert else L.s_h, "vert": vert}
    n_act = len(lay.names)
    # masses: 5 % of the moving mass in the rods (as the uni-axial generator)
    rod = 0.05 * L.m / n_act
    platen = L.m - n_act * rod
    com = [0.0, 0.0, -L.h / 2]
    inertia, in_src = _platen_inertia(inputs, L, platen, src)
    f_oil, f_dof = _oil_columns(lay, classes, L, inertia, com)
    kp, kp_src = _position_gains(inputs, f_dof, L, src)
    title = inputs.get("title", f"{name}: 6-DOF table ({n_act} actuators, {L.kind} layout)")
    if not isinstance(title, str):
        raise ScenarioError(f"{src}: 'title' must be text")
    out = [
        *_head_lines(name, title, L.lab),
        *_limits_lines(L, lay, classes, f_oil, inputs, src),
        "[platen]",
        f"size_m = {_fl([L.a, L.b, L.h])}   # {L.given['platen_size_m']}",
        f"com_m = {_fl(com)}   # assumed: symmetric platen, centre of mass at mid-depth",
        f"mass_kg = {_f(platen)}   # derived: moving mass ({L.given['moving_mass_kg']}) - {n_act} rods (assumed below)",
        f"inertia_kg_m2 = {_fl(inertia)}   # {in_src}",
        "",
        *common_sections(
            _f,
            L.given,
            ps=L.ps,
            q=L.q,
            drop=L.drop,
            fv=L.fv,
            pump_flow=0.5 * L.q * n_act,
            swept_total=sum(classes[c]["A"] * classes[c]["s"] for c in lay.cls),
            beta=L.beta,
            ps_hi=unknowns["supply_pressure_pa"].hi if "supply_pressure_pa" in unknowns else None,
        ),
    ]
    for c, cd in classes.items():
        out += _class_lines(c, cd, lay, L, rod)
    out += _actuator_lines(lay)
    if lay.supports:
        out += _support_lines(L)
    out += _control_and_sensor_lines(inputs, L, kp, kp_src, src)
    ranges, lab_of = labvalues.description_ranges(unknowns, list(classes), n_act * rod)
    return labvalues.mark("\n".join(out), ranges, unknowns, lab_of)


def _read_lab6(name: str, inputs: dict, src: str):
    """Check the keys and the name, resolve the unknown values and read every number:
    (inputs with unknowns at their nominal, the unknowns, :class:`_Lab6`)."""
    from sim.scenario import labvalues

    unknown = sorted(set(inputs) - set(LAB_KEYS6))
    if unknown:
        raise ScenarioError(f"{src}: unknown key '{unknown[0]}' for --kind 6dof; known: {', '.join(LAB_KEYS6)}")
    if not name or not name.replace("_", "").replace("-", "").isalnum():
        raise ScenarioError(f"table name {name!r} must be letters, digits, '-' or '_'; choose another NAME")
    can = ("moving_mass_kg", "supply_pressure_pa", "valve_rated_flow_m3_s", "valve_bandwidth_hz", "bulk_modulus_pa")
    inputs, unknowns = labvalues.resolve(inputs, src, can, {})  # no actuator count yet: a mass needs its range
    kind = inputs.get("layout")
    if kind is None:
        raise ScenarioError(f"{src}: missing 'layout' ({LAB_KEYS6['layout'][0]})")
    m = _num(inputs, "moving_mass_kg", src)
    a, b, h = _vec(inputs, "platen_size_m", 3, src)
    A_h = _num(inputs, "piston_area_m2", src)
    s_h = _num(inputs, "half_stroke_m", src)
    A_v = _num(inputs, "vertical_piston_area_m2", src, default=A_h)
    s_v = _num(inputs, "vertical_half_stroke_m", src, default=s_h)
    ps = _num(inputs, "supply_pressure_pa", src)
    q = _num(inputs, "valve_rated_flow_m3_s", src)
    fv = _num(inputs, "valve_bandwidth_hz", src)
    drop = _num(inputs, "valve_rated_drop_pa", src, default=6.9e6)
    beta = _num(inputs, "bulk_modulus_pa", src, default=BULK_MODULUS_PA)
    kfb = _num(inputs, "kfb", src, positive=False, default=0.05)
    if kfb < 0:
        raise ScenarioError(f"{src}: 'kfb' must be >= 0 (got {kfb:g})")
    m_spec = _num(inputs, "max_specimen_kg", src) if "max_specimen_kg" in inputs else None
    lab = f"lab: {src}"
    given = {k: lab for k in inputs}
    given.update({k: u.comment() for k, u in unknowns.items()})
    L = _Lab6(kind, m, a, b, h, A_h, s_h, A_v, s_v, ps, q, fv, drop, beta, kfb, m_spec, lab, given)
    return inputs, unknowns, L


def _read_layout(L: _Lab6, inputs: dict, src: str) -> _Layout6:
    """The layout's attachment points, whether static supports carry the weight, and a
    check that the actuators control all six DOF (Jacobian of full rank)."""
    names, cls, base, plat, layout_note = _layout(L.kind, inputs, (L.a, L.b, L.h), L.s_h, L.s_v, src)
    supports = inputs.get("static_supports", L.kind == "4h4v")
    if not isinstance(supports, bool):
        raise ScenarioError(f"{src}: 'static_supports' must be true or false")
    J = _jacobian(base, plat)
    if np.linalg.matrix_rank(J, tol=1e-6) < 6:
        raise ScenarioError(
            f"{src}: the actuator layout does not control all 6 DOF (its Jacobian has rank < 6); move the attachment points"
        )
    return _Layout6(names, cls, base, plat, layout_note, supports, J)


def _platen_inertia(inputs: dict, L: _Lab6, platen: float, src: str):
    """(principal moments, source comment): the lab's, else a uniform solid box."""
    if "inertia_kg_m2" in inputs:
        return _vec(inputs, "inertia_kg_m2", 3, src), L.lab
    a, b, h = L.a, L.b, L.h
    inertia = [platen * (b * b + h * h) / 12, platen * (a * a + h * h) / 12, platen * (a * a + b * b) / 12]
    in_src = "derived: uniform solid box of the platen mass and size, m (b^2 + h^2) / 12 etc. (a welded box is stiffer in inertia: give inertia_kg_m2 if known)"
    return inertia, in_src


def _oil_columns(lay: _Layout6, classes: dict, L: _Lab6, inertia, com):
    """(coupled oil-column frequencies, per-DOF oil-column frequencies) in Hz."""
    # oil columns: k_i = 2 beta A^2 / V per actuator, V = A s (1 + dead fraction); DOF stiffness J^T diag(k) J
    k_act = np.array(
        [2 * L.beta * classes[c]["A"] ** 2 / (classes[c]["A"] * classes[c]["s"] * (1 + DEAD_FRACTION)) for c in lay.cls]
    )
    J, m = lay.J, L.m
    K = J.T @ (k_act[:, None] * J)
    Mref = np.diag([m, m, m, inertia[0] + m * com[2] ** 2, inertia[1] + m * com[2] ** 2, inertia[2]])
    f_oil = np.sqrt(np.clip(np.linalg.eigvals(np.linalg.solve(Mref, K)).real, 0, None)) / (2 * math.pi)
    f_dof = np.sqrt(np.diag(K) / np.diag(Mref)) / (2 * math.pi)
    return f_oil, f_dof


def _position_gains(inputs: dict, f_dof, L: _Lab6, src: str):
    """(displacement loop gain per DOF in 1/s, source comment)."""
    kp_in = inputs.get("kp_per_s")
    if kp_in is None:
        kp = [2 * math.pi * min(f, L.fv) / 5 for f in f_dof]
        kp_src = (
            "derived: per DOF, min(oil column of the DOF, valve bandwidth) / 5 (2 pi f); oil columns "
            + ", ".join(f"{d} {f:.1f}" for d, f in zip(("x", "y", "z", "rx", "ry", "rz"), f_dof))
            + " Hz"
        )
        return kp, kp_src
    kp = [_num(inputs, "kp_per_s", src)] * 6 if not isinstance(kp_in, list) else _vec(inputs, "kp_per_s", 6, src)
    return kp, L.lab


def _f(x):
    return repr(float(f"{x:.6g}"))


def _fl(v):
    return "[" + ", ".join(_f(x) for x in v) + "]"


def _head_lines(name: str, title: str, lab: str) -> list[str]:
    """The file's header comment and its [table] section."""
    return [
        f"# {title}",
        "#",
        "# Written by `shaketable table new --kind 6dof` from the lab's numbers (sim/scenario/tablegen6.py).",
        "# Every number is SI, with its source on the line:",
        f'#   "{lab}"    the lab\'s number,',
        '#   "derived: ..."  computed from the lab\'s numbers (the formula is given),',
        '#   "assumed: ..."  a default with its reason: replace it when you know better, or',
        "#                   calibrate it against a record (docs/lab-example.md).",
        "# Frame: origin at the centre of the platen's top surface, x along the platen's length, z up.",
        "",
        "[table]",
        f'name = "{name}"',
        f'title = "{title}"',
        'dofs = ["x", "y", "z", "rx", "ry", "rz"]',
        "gravity_m_s2 = 9.81                 # standard gravity",
        "",
    ]


def _limits_lines(L: _Lab6, lay: _Layout6, classes: dict, f_oil, inputs: dict, src: str) -> list[str]:
    """[limits]: the reachable box within the strokes, the flow-limited velocity, the
    force-limited acceleration and the frequency range."""
    cls, J = lay.cls, lay.J
    usable = np.array([classes[c]["s"] - min(0.005, 0.1 * classes[c]["s"]) for c in cls])
    trans, rot = _fit_limits(lay.base, lay.plat, usable, L.a, L.b)
    v_act = np.array([L.q * math.sqrt(max(L.ps - 0.3e6, 0.0) / L.drop) / classes[c]["A"] for c in cls])
    v_lim = [float(np.min(v_act / np.maximum(np.abs(J[:, k]), 1e-9))) for k in range(3)]
    F_act = np.array([classes[c]["A"] * L.ps * 2.0 / 3.0 for c in cls])
    a_lim = [float(np.abs(J[:, k]) @ F_act / L.m) for k in range(3)]
    a_lim[2] = max(a_lim[2] - 9.81, 0.1)
    return [
        "[limits]",
        f"stroke_m = {_fl([trans] * 3)}   # derived: largest box (translations u, rotations u / half-diagonal) whose "
        "every corner the actuators reach within their stroke less the cushions",
        f"rotation_rad = {_fl([rot] * 3)}   # derived: as stroke_m",
        f"velocity_m_s = {_fl(v_lim)}   # derived: min over actuators of (rated flow at supply - 0.3 MPa over the "
        "rated drop / A) / |d stroke / d DOF|",
        f"acceleration_m_s2 = {_fl(a_lim)}   # derived: sum |d stroke / d DOF| A (2/3 supply) / moving mass (bare; z less g)",
        *specimen_rating(_f, inputs, L.given, src),
        f"frequency_range_hz = [0.0, {_f(min(min(f_oil), L.fv))}]   # derived: up to the lowest oil column or the valve bandwidth",
        "",
    ]


def _class_lines(c: str, cd: dict, lay: _Layout6, L: _Lab6, rod: float) -> list[str]:
    """[actuator_class.C]: the lab's area and stroke, the rest assumed with reasons."""
    f, given = _f, L.given
    A, s = cd["A"], cd["s"]
    L_sw = float(np.median([np.linalg.norm(p - bb) for p, bb, k in zip(lay.plat, lay.base, lay.cls) if k == c]))
    a_src = given["vertical_piston_area_m2" if cd["vert"] and "vertical_piston_area_m2" in given else "piston_area_m2"]
    s_src = given["vertical_half_stroke_m" if cd["vert"] and "vertical_half_stroke_m" in given else "half_stroke_m"]
    k1 = 2 * L.beta * A * A / (A * s * (1 + DEAD_FRACTION))
    return [
        f"[actuator_class.{c}]",
        f"half_stroke_m = {f(s)}   # {s_src}",
        f"area_a_m2 = {f(A)}   # {a_src}",
        f"area_b_m2 = {f(A)}   # assumed: double-ended (equal areas)",
        f"dead_volume_a_m3 = {f(DEAD_FRACTION * A * s)}   # assumed: {DEAD_FRACTION:g} x the swept half volume A s "
        "(hoses, manifold)",
        f"dead_volume_b_m3 = {f(DEAD_FRACTION * A * s)}   # as chamber a",
        "leakage_cross_m3_s_pa = 0.0         # assumed: none (calibrate from a record)",
        "leakage_external_m3_s_pa = 0.0      # assumed: none",
        "seal_friction_n = 0.0               # assumed: none (calibrate from a record)",
        "seal_viscous_n_s_m = 0.0            # assumed: none",
        f"cushion_length_m = {f(min(0.005, 0.1 * s))}   # assumed: end cushion travel, min(5 mm, 10 % of the half-stroke)",
        f"cushion_stiffness_n_m = {f(100 * k1)}   # assumed: end stop 100 x the actuator's oil-column stiffness",
        f"cylinder_mass_kg = {f(2 * rod)}   # assumed: twice the rod",
        f"cylinder_length_m = {f(0.6 * L_sw)}   # assumed: 0.6 x the swivel-to-swivel length (drawing and inertia size)",
        f"cylinder_radius_m = {f(max(0.03, 1.5 * math.sqrt(A / math.pi)))}   # assumed: 1.5 x the piston radius",
        f"rod_mass_kg = {f(rod)}   # assumed: 5 % of the moving mass shared by the rods",
        f"rod_length_m = {f(0.6 * L_sw)}   # assumed: as the cylinder",
        f"rod_radius_m = {f(max(0.01, 0.5 * math.sqrt(A / math.pi)))}   # assumed: half the piston radius",
        "",
    ]


def _actuator_lines(lay: _Layout6) -> list[str]:
    """The [[actuator]] entries, after a comment naming the layout."""
    out = [
        f"# The {len(lay.names)} linkages (foundation swivel base_m, platen swivel platen_m, at mid-stroke): "
        f"{lay.note}."
    ]
    for nm, c, bb, p in zip(lay.names, lay.cls, lay.base, lay.plat):
        out += [
            "[[actuator]]",
            f'name = "{nm}"',
            f'class = "{c}"',
            f"base_m = {_pt(bb)}   # see the layout above",
            f"platen_m = {_pt(p)}   # see the layout above",
            "",
        ]
    return out


def _support_lines(L: _Lab6) -> list[str]:
    """[supports]: four pneumatic static supports sized for the capacity weight."""
    f, m, h = _f, L.m, L.h
    cap = 1.2 * (m + (L.m_spec or m))
    area = cap * 9.81 / (4 * SUPPORT_PRESSURE_PA)
    p_bare = m * 9.81 / (4 * area)
    vol = 1.4 * p_bare * area * area * 4 / (m * (2 * math.pi * SUPPORT_HZ) ** 2)
    sx, sy = 0.25 * L.a, 0.25 * L.b
    return [
        "# Four pneumatic static supports carry the dead weight (as on the CGS table), so that the",
        "# vertical actuators start unloaded; set static_supports = false under [lab] if yours carry it.",
        "[supports]",
        f"capacity_kg = {f(cap)}   # assumed: 1.2 x (moving mass + "
        + ("max specimen)" if L.m_spec else "a specimen of the moving mass; the rating is unknown)"),
        f"positions_m = [[{f(-sx)}, {f(-sy)}, {f(-h)}], [{f(sx)}, {f(-sy)}, {f(-h)}], [{f(-sx)}, {f(sy)}, {f(-h)}], "
        f"[{f(sx)}, {f(sy)}, {f(-h)}]]   # assumed: under the platen, a quarter of its size from the centre",
        f"piston_area_m2 = {f(area)}   # derived: capacity weight / (4 x {SUPPORT_PRESSURE_PA:g} Pa, assumed design pressure)",
        f"chamber_volume_m3 = {f(vol)}   # derived: bare table bounces {SUPPORT_HZ:g} Hz on the air springs "
        "(assumed: below the test band), V = 4 n p A^2 / (m w^2)",
        "polytropic_exponent = 1.4           # assumed: adiabatic air at test frequencies",
        'air_law = "polytropic"              # assumed: the air spring law, not its linearisation',
        f"piston_mass_kg = {f(0.02 * m)}   # assumed: 2 % of the moving mass",
        f"shoe_mass_kg = {f(0.005 * m)}   # assumed: 0.5 % of the moving mass",
        "piston_friction_n = 0.0             # assumed: none (calibrate from a record)",
        "shoe_friction_n = 0.0               # assumed: none (calibrate from a record)",
        f"piston_radius_m = {f(math.sqrt(area / math.pi))}   # derived: from the area",
        f"piston_length_m = {f(0.5 * h + 0.2)}   # assumed: drawing size",
        "",
    ]


def _control_and_sensor_lines(inputs: dict, L: _Lab6, kp, kp_src: str, src: str) -> list[str]:
    """[sensors], three [[accelerometer]]s at the platen centre, the controller and [friction]."""
    sensors, controller = control_lines(
        _f,
        _fl,
        inputs,
        L.given,
        src,
        kp=kp,
        kp_src=kp_src,
        tau=1 / (2 * math.pi * L.fv),
        kdp_why="assumed: dP stabilisation of the oil columns (the CGS description's)",
        kfb=f"kfb = {_f(L.kfb)}   # "
        + L.given.get("kfb", "assumed: force balance of the redundant actuators (the CGS description's)"),
    )
    out = [*sensors, ""]
    for nm, d in (("AX", "1.0, 0.0, 0.0"), ("AY", "0.0, 1.0, 0.0"), ("AZ", "0.0, 0.0, 1.0")):
        out += [
            "[[accelerometer]]",
            f'name = "{nm}"',
            "position_m = [0.0, 0.0, 0.0]        # assumed: platen centre",
            f"direction = [{d}]         # assumed: along a table axis",
            "",
        ]
    out += [
        "# MTS 469D-style controller (sim/control/tvc.py).",
        *controller,
        "",
        "# Dry friction in the loop with a pre-sliding travel (Dahl form): no friction is declared above,",
        "# a calibrated effect uses it.",
        "[friction]",
        'model = "presliding"',
        "presliding_m = 0.5e-3               # assumed: 0.5 mm, the CGS description's value",
        "",
    ]
    return out


def _pt(p):
    return "[" + ", ".join(repr(float(f"{x:.6g}")) for x in p) + "]"


__all__ = ["LAB_KEYS6", "sixdof"]
