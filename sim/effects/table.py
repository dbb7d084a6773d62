"""The description's own physical numbers as :class:`Parameter` objects.

:func:`table_parameters` lists what calibration may vary in a table description besides
its ``[[effect]]`` entries: per actuator class the dead volumes, leakage, seal friction
and seal drag and the moving masses; the fluid's bulk modulus; the static supports'
friction, air law (chamber volume, polytropic exponent) and masses; the platen's mass
and inertia; a spring foundation's mass; the pre-sliding travel of the joint friction;
and every ``[[effect]]`` parameter. A parameter's ``name`` is its path in the TOML
file (``actuator_class.vertical.dead_volume_a_m3``, ``platen.inertia_kg_m2[2]``,
``effect[1].force_n``), ``where`` the place it acts (``class:<c>``, ``table``,
``supply``, the effect's own ``where``), bounds physical (see ``_BOUNDS``).

:func:`with_parameter_values` returns the description with some of them changed
(re-parsed, so every check of the description runs again).
"""

from __future__ import annotations

import copy
import difflib
import math
import re

from mjcf.description import TableDescription, parse_table
from sim.effects.base import EFFECTS, Parameter, create
from sim.effects.registry import description_folder, load_user_effect
from sim.errors import ScenarioError

INF = math.inf

#: per actuator-class key: unit and physical bounds as a function of the class's raw table
#: (``c``) and the supply pressure (``ps``)
_CLASS_KEYS = {
    # a dead volume beyond five swept volumes (5 x 2 A half-stroke) is not a servo-actuator (assumed)
    "dead_volume_a_m3": ("m^3", lambda c, ps: 0.0, lambda c, ps: 10.0 * c["area_a_m2"] * c["half_stroke_m"]),
    "dead_volume_b_m3": ("m^3", lambda c, ps: 0.0, lambda c, ps: 10.0 * c["area_b_m2"] * c["half_stroke_m"]),
    # 1e-10 m^3/(s Pa) leaks 60 l/min at 10 MPa: a failed seal, not a working actuator (assumed)
    "leakage_cross_m3_s_pa": ("m^3/(s Pa)", lambda c, ps: 0.0, lambda c, ps: 1e-10),
    "leakage_external_m3_s_pa": ("m^3/(s Pa)", lambda c, ps: 0.0, lambda c, ps: 1e-10),
    # seal friction above 10 % of the actuator's capability A ps is not a working seal (assumed)
    "seal_friction_n": ("N", lambda c, ps: 0.0, lambda c, ps: 0.1 * c["area_a_m2"] * ps),
    "seal_viscous_n_s_m": ("N s/m", lambda c, ps: 0.0, lambda c, ps: INF),
    "cylinder_mass_kg": ("kg", lambda c, ps: 0.0, lambda c, ps: INF),
    "rod_mass_kg": ("kg", lambda c, ps: 1e-3, lambda c, ps: INF),
}
#: (section, key): unit, lower, upper, where
_BOUNDS = {
    # mineral oil is 1.4-2.0 GPa; air and hoses lower the effective value, 0.1 GPa is heavily aerated (assumed)
    ("fluid", "bulk_modulus_pa"): ("Pa", 1e8, 2.2e9, "table"),
    ("supports", "piston_friction_n"): ("N", 0.0, INF, "table"),
    ("supports", "shoe_friction_n"): ("N", 0.0, INF, "table"),
    ("supports", "chamber_volume_m3"): ("m^3", 1e-6, INF, "table"),
    ("supports", "polytropic_exponent"): ("1", 1.0, 1.4, "table"),  # isothermal .. adiabatic air
    ("supports", "piston_mass_kg"): ("kg", 1e-3, INF, "table"),
    ("supports", "shoe_mass_kg"): ("kg", 1e-3, INF, "table"),
    ("platen", "mass_kg"): ("kg", 1e-3, INF, "table"),
    ("platen", "inertia_kg_m2"): ("kg m^2", 1e-3, INF, "table"),
    ("foundation", "mass_kg"): ("kg", 1e-3, INF, "table"),
    ("friction", "presliding_m"): ("m", 1e-7, 1e-2, "table"),  # 0.1 um .. 10 mm: contact travels
}


def table_parameters(desc: TableDescription) -> list[Parameter]:
    """The description's physical numbers calibration may vary (see the module docstring)."""
    raw = desc.raw
    out: list[Parameter] = []
    ps = float(raw.get("supply", {}).get("pressure_pa", 0.0))
    for cname, c in (raw.get("actuator_class") or {}).items():
        for key, (unit, lo, hi) in _CLASS_KEYS.items():
            if key in c:
                out.append(
                    Parameter(
                        f"actuator_class.{cname}.{key}",
                        float(c[key]),
                        unit,
                        lo(c, ps),
                        hi(c, ps),
                        where=f"class:{cname}",
                    )
                )
    for (sec, key), (unit, lo, hi, where) in _BOUNDS.items():
        s = raw.get(sec)
        if not isinstance(s, dict) or key not in s:
            continue
        if sec == "foundation" and s.get("mode", "fixed") != "spring":
            continue
        if sec == "friction" and s.get("model", "coulomb") != "presliding":
            continue
        v = s[key]
        if isinstance(v, list):
            out += [Parameter(f"{sec}.{key}[{i}]", float(x), unit, lo, hi, where=where) for i, x in enumerate(v)]
        else:
            out.append(Parameter(f"{sec}.{key}", float(v), unit, lo, hi, where=where))
    if "supports" in raw:
        # the supports' friction is at most the friction of a working seal: 10 % of the load it carries (assumed)
        cap = float(raw["supports"].get("capacity_kg", INF)) * desc.gravity_m_s2
        n = max(len(raw["supports"].get("positions_m", [])), 1)
        out = [
            p
            if not p.name.endswith(("piston_friction_n", "shoe_friction_n"))
            else Parameter(p.name, p.value, p.unit, p.lower, 0.1 * cap / n, p.where)
            for p in out
        ]
    folder = description_folder(desc)
    for i, e in enumerate(desc.effects):
        src = f"{desc.source}: effect[{i}]"
        kind = str(e.get("type", ""))
        if kind not in EFFECTS and ".py:" in kind:
            load_user_effect(kind, folder, src)
        eff = create(e, source=src)
        out += [
            Parameter(f"effect[{i}].{p.name}", p.value, p.unit, p.lower, p.upper, p.where, p.scale)
            for p in eff.parameters()
        ]
    return out


_PATH = re.compile(r"^(?:effect\[(\d+)\]\.(\w+)|([\w.]+?)(?:\[(\d+)\])?)$")


def with_parameter_values(desc: TableDescription, values: dict[str, float]) -> TableDescription:
    """``desc`` with the named parameters (names of :func:`table_parameters`) set to
    ``values`` (checked against their bounds); the description is re-parsed."""
    params = {p.name: p for p in table_parameters(desc)}
    raw = copy.deepcopy(desc.raw)
    for name, v in values.items():
        if name not in params:
            close = difflib.get_close_matches(name, sorted(params), n=1)
            hint = f" (did you mean '{close[0]}'?)" if close else ""
            raise ScenarioError(f"{desc.source}: no parameter '{name}'{hint}; table_parameters(desc) lists them")
        p = params[name]
        v = float(v)
        if not (math.isfinite(v) and p.lower <= v <= p.upper):
            raise ScenarioError(
                f"{desc.source}: {name} = {v:g} {p.unit} is outside its bounds [{p.lower:g}, {p.upper:g}]"
            )
        m = _PATH.match(name)
        if m.group(1) is not None:
            raw["effect"][int(m.group(1))][m.group(2)] = v
            continue
        *secs, key = m.group(3).split(".")
        node = raw
        for s in secs:
            node = node[s]
        if m.group(4) is not None:
            node[key][int(m.group(4))] = v
        else:
            node[key] = v
    return parse_table(raw, desc.source)


__all__ = ["table_parameters", "with_parameter_values"]
