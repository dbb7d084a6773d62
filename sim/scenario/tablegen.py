"""A table description from the few numbers a lab knows.

A lab knows its table's moving mass, its actuators' piston area and stroke, the supply
pressure, the servovalve's rated flow and bandwidth, and (perhaps) its oil-column
frequency and its controller's gains. Everything else a description holds is written
here with a physically reasonable default, marked ``assumed:`` with the reason, or
``derived:`` with the formula, so that the file builds (``mjcf.load_table``), runs a
scenario and replays a record with no code of its own. The lab's numbers carry the
source it gives (``lab: ...``).

The uni-axial kind is written here (one or more actuators side by side on one DOF, as
the Rice and LHPOST tables); the 6-DOF kind by :mod:`sim.scenario.tablegen6` (a named
standard layout with a few dimensions, or every actuator's attachment points).
"""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

from sim.errors import ScenarioError

#: The controller and recorder a lab runs, mapped onto the description's digital
#: three-variable controller (``[controller]``, sim/control/tvc.py) and ``[sensors]``.
CONTROL_KEYS = {
    "controller_rate_hz": ("controller tick (must divide the 2048 Hz physics rate; default 1024)", False),
    "recorder_rate_hz": ("data recorder's sample rate (default: the controller's)", False),
    "kp_per_s": ("displacement (P) gain: velocity demand per displacement error (default from the oil column)", False),
    "kff_velocity": ("velocity feed-forward, fraction of the reference velocity (default 1)", False),
    "kff_acceleration_s": ("acceleration feed-forward time (default: the valve's time constant)", False),
    "kdp": (
        "differential-pressure (delta-P) gain, opening per load pressure / supply pressure; 0: none (default 0.3)",
        False,
    ),
    "dp_highpass_hz": ("corner of the high-pass on the delta-P feedback; 0: none (default 1)", False),
    "accelerometer_lowpass_hz": ("cutoff of the accelerometers' analog conditioner (default 1000: flat)", False),
    "accelerometer_lowpass_order": ("poles of that conditioner, Butterworth (default 4)", False),
}

#: What a lab gives: key -> (meaning, required). SI units.
LAB_KEYS = {
    "moving_mass_kg": ("platen + actuator rods + anything rigidly on them (bare table)", True),
    "piston_area_m2": ("piston area of one actuator (double-ended: the same both sides)", True),
    "half_stroke_m": ("actuator stroke from mid-stroke to one end", True),
    "supply_pressure_pa": ("hydraulic supply pressure", True),
    "valve_rated_flow_m3_s": ("servovalve rated flow (at its rated drop)", True),
    "valve_bandwidth_hz": ("servovalve -3 dB (or 90 deg) frequency", True),
    "n_actuators": ("actuators side by side on the one DOF (default 1)", False),
    "valve_rated_drop_pa": ("pressure drop of the rated flow (default 6.9 MPa, 1000 psi)", False),
    "oil_column_hz": ("measured oil-column frequency of the bare table (sets the dead volume)", False),
    "dead_volume_m3": ("oil volume per chamber outside the swept volume: hoses, manifold (default 0.3 A s)", False),
    "bulk_modulus_pa": ("effective oil + hose bulk modulus (default 1.0 GPa)", False),
    "leakage_m3_s_pa": ("cross-port leakage coefficient across the piston (default none)", False),
    "max_specimen_kg": ("rated specimen mass (default: unknown, feasibility does not rate it)", False),
    "overturning_moment_n_m": ("rated overturning moment (default: unknown, feasibility does not rate it)", False),
    **CONTROL_KEYS,
    "platen_size_m": ("platen length x width x thickness", False),
    "title": ("a one-line title", False),
}
BULK_MODULUS_PA = 1.0e9  #: assumed effective oil + hose bulk modulus (mineral oil 1.4-1.8 GPa, hoses and air lower it)
DEAD_FRACTION = 0.3  #: assumed dead volume per chamber as a fraction of its swept half volume (hoses, manifold)


def read_lab_inputs(path: str | Path) -> dict:
    """The ``[lab]`` table of a TOML file (values in SI, see :data:`LAB_KEYS`)."""
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except OSError as e:
        raise ScenarioError(f"{p}: cannot read ({e.strerror}); give an existing TOML file with a [lab] table") from None
    except tomllib.TOMLDecodeError as e:
        raise ScenarioError(f"{p}: not valid TOML ({e}); fix the syntax") from None
    lab = data.get("lab")
    if not isinstance(lab, dict):
        raise ScenarioError(
            f"{p}: no [lab] table; put the table's numbers under [lab] "
            f"({', '.join(k for k, (_, req) in LAB_KEYS.items() if req)})"
        )
    return lab


def _num(inputs: dict, key: str, src: str, *, positive=True, default=None):
    v = inputs.get(key, default)
    if v is None:
        raise ScenarioError(f"{src}: missing '{key}' ({LAB_KEYS[key][0]}); add it in SI units")
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or (positive and v <= 0):
        raise ScenarioError(f"{src}: '{key}' must be a positive number in SI units (got {v!r})")
    return float(v)


def common_sections(f, given: dict, *, ps, q, drop, fv, pump_flow, swept_total, beta=BULK_MODULUS_PA, ps_hi=None):
    """The description's lines every generated table shares (uni-axial and 6-DOF):
    foundation, fluid, supply and servovalve, each number given, assumed or derived with
    its reason. ``f`` formats a number; ``given`` says where each given number came from;
    ``beta`` the bulk modulus; ``ps_hi`` the top of an unknown supply pressure's range
    (the relief valve sits above it)."""
    beta_src = given.get(
        "bulk_modulus_pa",
        "assumed: effective oil + hose bulk modulus (oil 1.4-1.8 GPa, hoses and entrained air lower it)",
    )
    relief = 1.2 * max(ps, ps_hi or ps)
    return [
        "[foundation]",
        'mode = "fixed"                      # assumed: rigid reaction mass (measure it if it rocks)',
        'mass_kg = 1.0e6                     # assumed: only used with mode = "spring"',
        'frequency_hz = [30.0, 30.0, 30.0]   # assumed: only used with mode = "spring"',
        'damping_ratio = [0.05, 0.05, 0.05]  # assumed: only used with mode = "spring"',
        "",
        "[fluid]",
        f"bulk_modulus_pa = {f(beta)}   # {beta_src}",
        "vapour_pressure_pa = 1.0e3          # assumed: lower pressure clip (cavitation)",
        f"relief_pressure_pa = {f(relief)}   # assumed: relief 20 % above supply"
        + (" (the top of its unknown range)" if ps_hi else ""),
        "",
        "[supply]",
        f"pressure_pa = {f(ps)}   # {given['supply_pressure_pa']}",
        "return_pressure_pa = 0.3e6          # assumed: return line back pressure",
        f"pump_flow_m3_s = {f(pump_flow)}   # assumed: half the valves' rated flow (accumulators carry the peaks)",
        f"accumulator_volume_m3 = {f(max(0.01, 10 * 2 * swept_total))}   # assumed: gas volume of ten full strokes of oil",
        f"accumulator_precharge_pa = {f(2 * ps / 3)}   # assumed: precharge at 2/3 of supply",
        "polytropic_exponent = 1.4           # assumed: adiabatic nitrogen",
        "line_resistance_pa_s_m3 = 0.0       # assumed: no supply line loss",
        "",
        "[servovalve]",
        f"rated_flow_m3_s = {f(q)}   # {given['valve_rated_flow_m3_s']}",
        f"rated_drop_pa = {f(drop)}   # " + given.get("valve_rated_drop_pa", "assumed: 1000 psi rating convention"),
        'model = "first"                     # assumed: first-order spool (the bandwidth is the one number given)',
        f"tau_s = {f(1 / (2 * math.pi * fv))}   # derived: 1 / (2 pi bandwidth), bandwidth {fv:g} Hz ({given['valve_bandwidth_hz']})",
        f'natural_frequency_hz = {f(fv)}   # derived: the bandwidth (unused with model = "first")',
        'damping_ratio = 0.7                 # assumed: unused with model = "first"',
        "delay_s = 0.0                       # assumed: no pure delay (calibrate if the phase says otherwise)",
        "slew_limit_per_s = 0.0              # assumed: no slew limit",
        "laminar_drop_pa = 0.1e6             # assumed: laminar region below 0.1 MPa",
        f"null_leakage_m3_s = {f(1e-3 * q)}   # assumed: 0.1 % of rated flow",
        "overlap = 0.0                       # assumed: zero-lapped spool",
        "",
    ]


def _rate(inputs: dict, src: str) -> tuple[float, float]:
    """(controller rate, recorder rate) in Hz; the controller's divides the physics rate."""
    rate = _num(inputs, "controller_rate_hz", src, default=1024.0)
    if abs(2048.0 / rate - round(2048.0 / rate)) > 1e-9:
        raise ScenarioError(
            f"{src}: 'controller_rate_hz' {rate:g} must divide the 2048 Hz physics rate (e.g. 1024, 512, 256)"
        )
    return rate, _num(inputs, "recorder_rate_hz", src, default=rate)


KDP_WHY = "assumed: dP stabilisation of the oil column (the UCSD description's)"


def control_lines(f, fl, inputs: dict, given: dict, src: str, *, kp, kp_src, tau, kdp_why=KDP_WHY, kfb=None):
    """The ``[sensors]`` and ``[controller]`` lines of a generated description: the
    lab's controller (P gain, feed-forwards, delta-P gain and its high-pass, rates) and
    recorder (rate, accelerometer conditioner) where given, else the defaults with their
    reasons. The controller is the digital three-variable one (sim/control/tvc.py):
    a lab's P gain is ``kp_per_s``, its velocity and acceleration feed-forwards
    ``kff_velocity`` and ``kff_acceleration_s``, its delta-P gain ``kdp`` (0: none)."""
    rate, rec = _rate(inputs, src)
    kffv = _num(inputs, "kff_velocity", src, positive=False, default=1.0)
    kffa = _num(inputs, "kff_acceleration_s", src, positive=False, default=tau)
    kdp = _num(inputs, "kdp", src, positive=False, default=0.3)
    hp = _num(inputs, "dp_highpass_hz", src, positive=False, default=1.0)
    lp = _num(inputs, "accelerometer_lowpass_hz", src, default=1000.0)
    order = inputs.get("accelerometer_lowpass_order", 4)
    for key, v in (("kff_velocity", kffv), ("kff_acceleration_s", kffa), ("kdp", kdp), ("dp_highpass_hz", hp)):
        if v < 0:
            raise ScenarioError(f"{src}: '{key}' must be >= 0 in SI units (got {v:g})")
    if isinstance(order, bool) or not isinstance(order, int) or not 1 <= order <= 8:
        raise ScenarioError(f"{src}: 'accelerometer_lowpass_order' must be a whole number 1..8 (got {order!r})")
    out = [
        "[sensors]",
        "accelerometer_range_m_s2 = 98.1     # assumed: +/-10 g",
        f"accelerometer_bandwidth_hz = {f(lp)}   # "
        + given.get("accelerometer_lowpass_hz", "assumed: flat well beyond the table's band"),
        f"accelerometer_filter_order = {order}   # "
        + given.get("accelerometer_lowpass_order", "assumed: 4-pole Butterworth conditioner"),
        f"recorder_rate_hz = {f(rec)}   # "
        + given.get("recorder_rate_hz", given.get("controller_rate_hz", "assumed: 1024 Hz (the model's tick)")),
    ]
    return out, [
        "[controller]",
        f"rate_hz = {f(rate)}   # " + given.get("controller_rate_hz", "assumed: 1024 Hz"),
        f"kp_per_s = {fl(kp)}   # {kp_src}",
        f"kff_velocity = {f(kffv)}   # " + given.get("kff_velocity", "assumed: full velocity feed-forward"),
        f"kff_acceleration_s = {f(kffa)}   # "
        + given.get("kff_acceleration_s", "derived: the valve's tau (cancels its lag)"),
        "kff_jerk_s2 = 0.0                   # assumed: none",
        f"kdp = {f(kdp)}   # " + given.get("kdp", kdp_why),
        f"dp_highpass_hz = {f(hp)}   # " + given.get("dp_highpass_hz", "assumed: high-pass on dP (no static error)"),
        kfb or "kfb = 0.0                           # one DOF: no force balance",
    ]


def specimen_rating(f, inputs: dict, given: dict, src: str) -> list[str]:
    """The ``max_specimen_kg`` and ``overturning_moment_n_m`` lines: the lab's ratings,
    else ``"unknown"`` (feasibility then says the rating is unknown instead of refusing a
    specimen heavier than the platen: a table's ratings are set by its supports,
    bearings and actuators' side loads, none of which the lab's other numbers give)."""
    out = []
    for key in ("max_specimen_kg", "overturning_moment_n_m"):
        if key in inputs:
            out.append(f"{key} = {f(_num(inputs, key, src))}   # {given[key]}")
        else:
            out.append(f'{key} = "unknown"   # unknown: the lab gave no rating (feasibility does not rate it)')
    return out


def _dead_volume(inputs, src, *, n_act, beta, A, s, m, lab):
    """(dead volume per chamber, its source line, oil-column Hz) from the measured oil
    column, the lab's dead volume or the assumed fraction of the swept volume."""
    swept = A * s
    if "oil_column_hz" in inputs and "dead_volume_m3" in inputs:
        raise ScenarioError(f"{src}: give 'oil_column_hz' or 'dead_volume_m3', not both (each sets the other)")
    if "oil_column_hz" in inputs:
        f_oil = _num(inputs, "oil_column_hz", src)
        V = 2 * n_act * beta * A * A / (m * (2 * math.pi * f_oil) ** 2)
        if V - swept <= 0.02 * swept:
            raise ScenarioError(
                f"{src}: 'oil_column_hz' {f_oil:g} Hz is above what this piston can give with no dead volume "
                f"({math.sqrt(2 * n_act * beta * A * A / (m * swept)) / (2 * math.pi):.1f} Hz at "
                f"beta {beta:.1e} Pa); check the moving mass, piston area and stroke"
            )
        why = (
            f"derived: oil column {f_oil:g} Hz ({lab}): V = 2 n beta A^2 / (m w^2) = {V:.4g} m^3 per "
            f"chamber, minus the swept A s"
        )
        return V - swept, why, f_oil
    if "dead_volume_m3" in inputs:
        dead = _num(inputs, "dead_volume_m3", src)
        why = lab
    else:
        dead = DEAD_FRACTION * swept
        why = None
    f_oil = math.sqrt(2 * n_act * beta * A * A / (m * (swept + dead))) / (2 * math.pi)
    if why is None:
        why = (
            f"assumed: {DEAD_FRACTION:g} x the swept half volume A s (hoses, manifold; gives an oil column "
            f"of {f_oil:.1f} Hz; give oil_column_hz if measured)"
        )
    return dead, why, f_oil


def _lab_numbers(name: str, inputs: dict, src: str):
    """The lab's inputs checked, every unknown at its nominal: ``(values, unknowns)``."""
    from sim.scenario import labvalues

    extra = sorted(set(inputs) - set(LAB_KEYS))
    if extra:
        raise ScenarioError(f"{src}: unknown key '{extra[0]}'; known: {', '.join(LAB_KEYS)}")
    if not name or not name.replace("_", "").replace("-", "").isalnum():
        raise ScenarioError(f"table name {name!r} must be letters, digits, '-' or '_'; choose another NAME")
    n_act = inputs.get("n_actuators", 1)
    if isinstance(n_act, bool) or not isinstance(n_act, int) or not 1 <= n_act <= 8:
        raise ScenarioError(f"{src}: 'n_actuators' must be a whole number 1..8 (got {n_act!r})")
    return labvalues.resolve(
        inputs, src, LAB_KEYS, {"n_actuators": n_act, "half_stroke_m": inputs.get("half_stroke_m")}
    )


def _platen_size(inputs: dict, platen: float, src: str, lab: str):
    """([length, width, thickness], its source): the lab's, else an aluminium plate of the mass."""
    size = inputs.get("platen_size_m")
    if size is None:
        side = math.sqrt(platen / (2700.0 * 0.1))
        return [side, side, 0.1], f"assumed: square aluminium plate 0.1 m thick of the platen mass ({side:.2f} m side)"
    if not (isinstance(size, list) and len(size) == 3 and all(isinstance(v, (int, float)) and v > 0 for v in size)):
        raise ScenarioError(f"{src}: 'platen_size_m' must be 3 positive numbers [length, width, thickness] in m")
    return [float(v) for v in size], lab


def _header(title: str, lab: str, unknowns: bool) -> list[str]:
    """The comment lines at the top of a generated uni-axial description."""
    return [
        f"# {title}",
        "#",
        "# Written by `shaketable table new` from the lab's numbers (sim/scenario/tablegen.py).",
        "# Every number is SI, with its source on the line:",
        f'#   "{lab}"    the lab\'s number,',
        '#   "derived: ..."  computed from the lab\'s numbers (the formula is given),',
        '#   "assumed: ..."  a default with its reason: replace it when you know better, or',
        "#                   calibrate it against a record (docs/lab-example.md).",
        *(
            ['#   "unknown: ..."  a number the lab does not know: its nominal, identified by calibrate in [unknown].']
            if unknowns
            else []
        ),
        "# Frame: origin at the centre of the platen's top surface, x along the actuators.",
        "",
    ]


def _class_lines(f, given: dict, *, s, A, dead, dead_src, leak, k_oil, rod) -> list[str]:
    """The ``[actuator_class.main]`` lines of a generated uni-axial description."""
    cushion = min(0.005, 0.1 * s)
    return [
        "[actuator_class.main]",
        f"half_stroke_m = {f(s)}   # {given['half_stroke_m']}",
        f"area_a_m2 = {f(A)}   # {given['piston_area_m2']}",
        f"area_b_m2 = {f(A)}   # assumed: double-ended (equal areas)",
        f"dead_volume_a_m3 = {f(dead)}   # {dead_src}",
        f"dead_volume_b_m3 = {f(dead)}   # as chamber a",
        f"leakage_cross_m3_s_pa = {f(leak)}   # "
        + given.get("leakage_m3_s_pa", "assumed: none (calibrate from a record)"),
        "leakage_external_m3_s_pa = 0.0      # assumed: none",
        "seal_friction_n = 0.0               # assumed: none (calibrate from a record)",
        "seal_viscous_n_s_m = 0.0            # assumed: none",
        f"cushion_length_m = {f(cushion)}   # assumed: end cushion travel, min(5 mm, 10 % of the half-stroke)",
        f"cushion_stiffness_n_m = {f(100 * k_oil)}   # assumed: end stop 100 x the oil-column stiffness",
        f"cylinder_mass_kg = {f(2 * rod)}   # assumed: twice the rod (on the fixed foundation: drawing only)",
        f"cylinder_length_m = {f(2 * s + 0.3)}   # assumed: stroke + 0.3 m (drawing size)",
        f"cylinder_radius_m = {f(max(0.03, 1.5 * math.sqrt(A / math.pi)))}   # assumed: 1.5 x the piston radius",
        f"rod_mass_kg = {f(rod)}   # assumed: 5 % of the moving mass shared by the rods",
        f"rod_length_m = {f(2 * s + 0.3)}   # assumed: as the cylinder",
        f"rod_radius_m = {f(max(0.01, 0.5 * math.sqrt(A / math.pi)))}   # assumed: half the piston radius",
        "",
    ]


def _actuator_entries(f, n_act: int, size, s: float) -> list[str]:
    """The ``[[actuator]]`` entries: horizontal, side by side at the platen's -x edge."""
    a_, b_, h_ = size
    L = max(1.0, 4 * s)
    out = []
    for i in range(n_act):
        y = (i - (n_act - 1) / 2) * min(0.5, b_ / max(n_act, 1))
        out += [
            "[[actuator]]",
            f'name = "{"A" if n_act == 1 else f"A{i + 1}"}"',
            'class = "main"',
            f"base_m = [{f(-a_ / 2 - L)}, {f(y)}, {f(-h_ / 2)}]   # assumed: horizontal, {L:g} m swivel to swivel",
            f"platen_m = [{f(-a_ / 2)}, {f(y)}, {f(-h_ / 2)}]   # assumed: at the platen's -x edge, mid-thickness",
            "",
        ]
    return out


def _accelerometer_entry() -> list[str]:
    return [
        "[[accelerometer]]",
        'name = "AX"',
        "position_m = [0.0, 0.0, 0.0]        # assumed: platen centre",
        "direction = [1.0, 0.0, 0.0]         # assumed: along the table axis",
        "",
    ]


def uniaxial(name: str, inputs: dict, *, src: str = "the command line") -> str:
    """TOML text of a uni-axial table description named ``name`` from the lab's
    ``inputs`` (keys of :data:`LAB_KEYS`, any of :data:`sim.scenario.labvalues.UNKNOWABLE`
    possibly unknown); ``src`` names where they came from."""
    from sim.scenario import labvalues

    inputs, unknowns = _lab_numbers(name, inputs, src)
    m = _num(inputs, "moving_mass_kg", src)
    A = _num(inputs, "piston_area_m2", src)
    s = _num(inputs, "half_stroke_m", src)
    ps = _num(inputs, "supply_pressure_pa", src)
    q = _num(inputs, "valve_rated_flow_m3_s", src)
    fv = _num(inputs, "valve_bandwidth_hz", src)
    n_act = inputs.get("n_actuators", 1)
    drop = _num(inputs, "valve_rated_drop_pa", src, default=6.9e6)
    beta = _num(inputs, "bulk_modulus_pa", src, default=BULK_MODULUS_PA)
    leak = _num(inputs, "leakage_m3_s_pa", src, positive=False, default=0.0)
    lab = f"lab: {src}"
    given = {k: lab for k in inputs}
    given.update({k: u.comment() for k, u in unknowns.items()})

    # masses: the rods are part of the moving mass
    rod = 0.05 * m / n_act
    platen = m - n_act * rod
    # oil column: k = n beta A^2 (1/Va + 1/Vb) = 2 n beta A^2 / V, V = A s + V_dead per chamber
    swept = A * s
    dead, dead_src, f_oil = _dead_volume(inputs, src, n_act=n_act, beta=beta, A=A, s=s, m=m, lab=lab)
    V = swept + dead
    tau = 1.0 / (2 * math.pi * fv)
    kp_src = given.get(
        "kp_per_s",
        f"derived: displacement loop at min(oil column, valve bandwidth) / 5 = {min(f_oil, fv) / 5:.2f} Hz (2 pi f)",
    )
    kp = _num(inputs, "kp_per_s", src) if "kp_per_s" in inputs else 2 * math.pi * min(f_oil, fv) / 5
    (a_, b_, h_), size_src = _platen_size(inputs, platen, src, lab)
    inertia = [platen * (b_**2 + h_**2) / 12, platen * (a_**2 + h_**2) / 12, platen * (a_**2 + b_**2) / 12]
    # performance limits derived from the hydraulics
    v_max = q * math.sqrt(max(ps - 0.3e6, 0.0) / drop) / A  # each valve feeds its own actuator
    a_max = n_act * A * ps * 2.0 / 3.0 / m
    stroke_lim = s - min(0.005, 0.1 * s)  # less the end cushion travel (_class_lines)
    k_oil = 2 * n_act * beta * A * A / V
    title = inputs.get("title", f"{name}: uni-axial table ({n_act} actuator{'s' if n_act > 1 else ''})")
    if not isinstance(title, str):
        raise ScenarioError(f"{src}: 'title' must be text")

    def f(x):
        return repr(float(f"{x:.6g}"))

    sensors, controller = control_lines(f, f, inputs, given, src, kp=kp, kp_src=kp_src, tau=tau)
    ps_hi = unknowns["supply_pressure_pa"].hi if "supply_pressure_pa" in unknowns else None
    out = [
        *_header(title, lab, bool(unknowns)),
        "[table]",
        f'name = "{name}"',
        f'title = "{title}"',
        'dofs = ["x"]',
        "gravity_m_s2 = 9.81                 # standard gravity",
        "",
        "[limits]",
        f"stroke_m = [{f(stroke_lim)}, 0.0, 0.0]   # derived: half-stroke - cushion travel",
        "rotation_rad = [0.0, 0.0, 0.0]      # uni-axial",
        f"velocity_m_s = [{f(v_max)}, 0.0, 0.0]   # derived: rated flow at (supply - 0.3 MPa return) over the rated drop, "
        "/ piston area",
        f"acceleration_m_s2 = [{f(a_max)}, 0.0, 0.0]   # derived: n A (2/3 supply) / moving mass (bare)",
        *specimen_rating(f, inputs, given, src),
        f"frequency_range_hz = [0.0, {f(min(f_oil, fv))}]   # derived: up to the oil column or valve bandwidth",
        "",
        "[platen]",
        'guide = "bearings"                  # uni-axial: the platen slides along x on bearings',
        f"size_m = [{f(a_)}, {f(b_)}, {f(h_)}]   # {size_src}",
        f"com_m = [0.0, 0.0, {f(-h_ / 2)}]   # assumed: uniform plate, centre at mid-thickness",
        f"mass_kg = {f(platen)}   # derived: moving mass ({given['moving_mass_kg']}) - {n_act} rod(s) (assumed below)",
        f"inertia_kg_m2 = [{', '.join(f(v) for v in inertia)}]   # derived: plate m (b^2 + h^2)/12 etc.",
        "",
        *common_sections(
            f,
            given,
            ps=ps,
            q=q,
            drop=drop,
            fv=fv,
            pump_flow=0.5 * q * n_act,
            swept_total=swept * n_act,
            beta=beta,
            ps_hi=ps_hi,
        ),
        *_class_lines(f, given, s=s, A=A, dead=dead, dead_src=dead_src, leak=leak, k_oil=k_oil, rod=rod),
    ]
    out += _actuator_entries(f, n_act, (a_, b_, h_), s)
    out += [*sensors, "", *_accelerometer_entry(), "# MTS 469D-style controller (sim/control/tvc.py).", *controller, ""]
    ranges, lab_of = labvalues.description_ranges(unknowns, ["main"], n_act * rod)
    return labvalues.mark("\n".join(out), ranges, unknowns, lab_of)


def write_uniaxial(name: str, inputs: dict, out: str | Path, *, src: str = "the command line", kind="uniaxial") -> Path:
    """Write :func:`uniaxial`'s description (``kind="6dof"``: :func:`sim.scenario.tablegen6.sixdof`'s)
    to ``out`` (atomically) after checking that it loads; returns the path."""
    import os

    import mjcf
    from mjcf.description import DescriptionError, parse_table

    if kind == "6dof":
        from sim.scenario.tablegen6 import sixdof

        text = sixdof(name, inputs, src=src)
    else:
        text = uniaxial(name, inputs, src=src)
    out = Path(out)
    try:
        parse_table(tomllib.loads(text), src=str(out))  # must load before it is written
    except DescriptionError as e:  # a generated file that does not load: the lab's numbers do not fit together
        raise ScenarioError(f"{src}: the generated description does not load ({e}); check the numbers given") from None
    if out.suffix != ".toml":
        raise ScenarioError(f"{out}: a table description ends in .toml; give --out NAME.toml")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".{out.name}.tmp")
        tmp.write_text(text)
        os.replace(tmp, out)
    except OSError as e:
        raise ScenarioError(f"cannot write {out}: {e.strerror}; choose a writable --out") from None
    mjcf.load_table(out)
    return out


__all__ = ["LAB_KEYS", "read_lab_inputs", "uniaxial", "write_uniaxial"]
