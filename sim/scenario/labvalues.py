"""Numbers a lab does not know, for ``shaketable table new``.

In the lab's ``[lab]`` table any of :data:`UNKNOWABLE` may be written

* ``key = "unknown"``: the default range of :data:`DEFAULT_RANGES` (each with its
  physical reason), the nominal its geometric mean;
* ``key = { unknown = [LO, HI] }``: the lab's range (SI), the nominal its geometric
  mean (LO when LO is 0); ``key = { unknown = [LO, HI], guess = X }``: the lab's guess
  as the nominal.

:func:`resolve` replaces each by its nominal (so the generators compute as if it were
given) and returns what is unknown; :func:`mark` then rewrites the generated text: the
line of every description key the unknown sets gets ``# unknown: between LO and HI
(...)`` and the file ends with the ``[unknown]`` table (``mjcf/unknowns.py`` validates
it; calibration identifies the values in it, ``sim/calibrate/unknowns.py``).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from sim.errors import ScenarioError

G = 9.81

#: lab key -> (low, high) as a function of the nominals already resolved, and the reason
DEFAULT_RANGES = {
    "supply_pressure_pa": (
        lambda v: (7e6, 35e6),
        "industrial hydraulic supplies run at 7-35 MPa (1000-5000 psi)",
    ),
    "bulk_modulus_pa": (
        lambda v: (0.5e9, 1.8e9),
        "mineral oil is 1.4-1.8 GPa; hoses, seals and entrained air lower the effective value to about 0.5 GPa",
    ),
    "valve_bandwidth_hz": (
        lambda v: (10.0, 200.0),
        "large multi-stage servovalves reach 10-60 Hz, small two-stage ones up to about 200 Hz",
    ),
    "piston_area_m2": (
        lambda v: tuple(v["moving_mass_kg"] * G * k / (v["n_actuators"] * v["supply_pressure_pa"]) for k in (1, 20)),
        "the actuators' force n A p_s accelerates the bare table at 1-20 g",
    ),
    "moving_mass_kg": (
        lambda v: tuple(v["n_actuators"] * v["piston_area_m2"] * v["supply_pressure_pa"] / (G * k) for k in (20, 1)),
        "the actuators' force n A p_s accelerates the bare table at 1-20 g",
    ),
    "valve_rated_flow_m3_s": (
        lambda v: (0.1 * v["piston_area_m2"], 2.0 * v["piston_area_m2"]),
        "the rated flow moves the piston at 0.1-2 m/s (tables are rated 0.2-1.8 m/s)",
    ),
    "dead_volume_m3": (
        lambda v: (0.05 * v["piston_area_m2"] * v["half_stroke_m"], 1.5 * v["piston_area_m2"] * v["half_stroke_m"]),
        "from a valve on the cylinder's manifold (5 % of the swept half volume A s) to long hoses (1.5 A s)",
    ),
    "leakage_m3_s_pa": (
        lambda v: (0.0, 0.05 * v["valve_rated_flow_m3_s"] / v["supply_pressure_pa"]),
        "from none to 5 % of the valve's rated flow across the piston at supply pressure",
    ),
}
#: what may be unknown, in the order the defaults are resolved (a default uses those before it)
UNKNOWABLE = tuple(DEFAULT_RANGES)


@dataclass(frozen=True)
class Unknown:
    """A lab value given as unknown: its range (SI), nominal and where the range came from."""

    key: str
    lo: float
    hi: float
    nominal: float
    why: str

    def comment(self) -> str:
        return f"unknown: between {self.lo:.4g} and {self.hi:.4g} ({self.why})"


def _spec(key, v, src):
    """(lo, hi, guess) of a lab value written as unknown, or None for a plain value."""
    if v == "unknown":
        return "default", None, None
    if not isinstance(v, dict):
        return None
    rng, guess = v.get("unknown"), v.get("guess")
    extra = sorted(set(v) - {"unknown", "guess"})
    ok = isinstance(rng, list) and len(rng) == 2 and all(_finite(x) for x in rng)
    if extra or not ok or (guess is not None and not _finite(guess)):
        raise ScenarioError(
            f"{src}: '{key}' must be a number, \"unknown\" or {{ unknown = [LO, HI] }} (optionally guess = X), "
            f"in SI units (got {v!r})"
        )
    lo, hi = float(rng[0]), float(rng[1])
    if not 0 <= lo < hi:
        raise ScenarioError(f"{src}: '{key}' = {{ unknown = [{lo:g}, {hi:g}] }} needs 0 <= LO < HI; give [LO, HI]")
    if guess is not None and not lo <= guess <= hi:
        raise ScenarioError(f"{src}: '{key}' guess {guess:g} is outside [{lo:g}, {hi:g}]; widen the range")
    return (lo, hi), guess, None


def _finite(x) -> bool:
    return not isinstance(x, bool) and isinstance(x, (int, float)) and math.isfinite(x)


def resolve(inputs: dict, src: str, known_keys, defaults: dict) -> tuple[dict, dict[str, Unknown]]:
    """``inputs`` with every unknown value replaced by its nominal, and the unknowns by lab
    key. ``known_keys``: the keys the generator takes (an unknown elsewhere is an error);
    ``defaults``: the nominals of optional keys a default range needs (n_actuators)."""
    out, specs = dict(inputs), {}
    for key, v in inputs.items():
        sp = _spec(key, v, src)
        if sp is None:
            continue
        if key not in UNKNOWABLE or key not in known_keys:
            can = ", ".join(k for k in UNKNOWABLE if k in known_keys)
            raise ScenarioError(f"{src}: '{key}' cannot be unknown here; give a number (unknown may be: {can})")
        specs[key] = sp
    unknowns = {}
    for key in UNKNOWABLE:  # the order of DEFAULT_RANGES: a default uses the nominals before it
        if key not in specs:
            continue
        rng, guess, _ = specs[key]
        if rng == "default":
            fn, why = DEFAULT_RANGES[key]
            try:
                lo, hi = fn({**defaults, **out})
            except (KeyError, TypeError):
                raise ScenarioError(
                    f"{src}: '{key}' = \"unknown\" has a default range only when the numbers it is scaled from "
                    f"are given ({why}); give {{ unknown = [LO, HI] }}"
                ) from None
            why = f"default range: {why}"
        else:
            (lo, hi), why = rng, f"lab: {src}"
        nominal = float(guess) if guess is not None else math.sqrt(lo * hi)
        out[key] = nominal
        unknowns[key] = Unknown(key, float(lo), float(hi), nominal, why)
    return out, unknowns


def mark(text: str, ranges: dict[str, tuple[float, float]], unknowns: dict[str, Unknown], lab_of: dict) -> str:
    """``text`` (a generated description) with each dotted key of ``ranges`` marked
    unknown on its own line and the ``[unknown]`` table appended. ``lab_of``: dotted key
    -> the lab key it comes from."""
    if not ranges:
        return text
    from mjcf.description import toml_key_index

    lines = text.split("\n")
    for dotted, (lo, hi) in ranges.items():
        section, key = dotted.rsplit(".", 1)
        i = toml_key_index(lines, section, key)
        if i is None:  # a generator's key list out of step with its text: a bug, not a user error
            raise RuntimeError(f"generated description has no {dotted} to mark unknown")
        body, _, old = lines[i].partition("#")
        u, old = unknowns[lab_of[dotted]], old.strip()
        nominal = "" if old.startswith("unknown:") or not old else f"; nominal: {old}"
        lines[i] = f"{body.rstrip()}   # unknown: between {lo:.4g} and {hi:.4g} ({u.why}){nominal}"
    out = [
        *lines,
        "# Values the lab does not know (mjcf/unknowns.py): the model runs with the nominal on each key's",
        "# line; `shaketable calibrate` identifies them in these ranges (SI) before it looks for effects.",
        "[unknown]",
    ]
    out += [f'"{k}" = [{_num(lo)}, {_num(hi)}]   # the lab\'s {lab_of[k]}' for k, (lo, hi) in ranges.items()]
    return "\n".join(out) + "\n"


def _num(x: float) -> str:
    t = repr(float(f"{x:.6g}"))
    return t if re.search(r"[.eE]", t) else t + ".0"


def description_ranges(unknowns: dict[str, Unknown], classes: list[str], rods_kg: float) -> tuple[dict, dict]:
    """The description's ``[unknown]`` ranges (dotted key -> (LO, HI)) of the lab's
    unknowns and the lab key of each: a moving mass is the platen's less the rods
    (``rods_kg``), a valve bandwidth f its time constant 1 / (2 pi f), a piston area, dead
    volume or leakage every actuator class's (both chambers alike)."""
    ranges, lab_of = {}, {}

    def put(dotted, lo, hi, key):
        ranges[dotted], lab_of[dotted] = (lo, hi), key

    for key, u in unknowns.items():
        if key == "moving_mass_kg":
            if u.lo - rods_kg <= 0:
                raise ScenarioError(
                    f"moving_mass_kg: the range's low end {u.lo:g} kg must exceed the rods' {rods_kg:.4g} kg "
                    "(5 % of the nominal moving mass); raise LO"
                )
            put("platen.mass_kg", u.lo - rods_kg, u.hi - rods_kg, key)
        elif key == "valve_bandwidth_hz":
            put("servovalve.tau_s", 1 / (2 * math.pi * u.hi), 1 / (2 * math.pi * u.lo), key)
        elif key == "supply_pressure_pa":
            put("supply.pressure_pa", u.lo, u.hi, key)
        elif key == "valve_rated_flow_m3_s":
            put("servovalve.rated_flow_m3_s", u.lo, u.hi, key)
        elif key == "bulk_modulus_pa":
            put("fluid.bulk_modulus_pa", u.lo, u.hi, key)
        else:
            names = {
                "piston_area_m2": ("area_a_m2", "area_b_m2"),
                "dead_volume_m3": ("dead_volume_a_m3", "dead_volume_b_m3"),
                "leakage_m3_s_pa": ("leakage_cross_m3_s_pa",),
            }[key]
            for c in classes:
                for n in names:
                    put(f"actuator_class.{c}.{n}", u.lo, u.hi, key)
    return ranges, lab_of


__all__ = ["DEFAULT_RANGES", "UNKNOWABLE", "Unknown", "description_ranges", "mark", "resolve"]
