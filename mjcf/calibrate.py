"""Calibrate the unpublished masses of a table description against measured effective masses.

The paper (seed 000, Table 2) gives the effective mass per DOF of the bare table; the
layout and the actuators' moving masses are not published. The effective mass from the
model, ``diag(T^T M T)``, is linear in every body's mass and inertia (the projection T
depends on geometry only), so the unknowns follow from one linear solve:

* platen mass and its three principal moments of inertia,
* the lateral rods' moving mass (the paper attributes y > x to the actuators' weights),
* the static-support pistons' mass (the vertical excess: mass that moves only vertically).

Six unknowns for the six measured values; the other masses stay as assumed. The command
``shaketable calibrate TABLE --write`` rewrites those numbers in the TOML file, marked
``calibrated: matches Table 2``.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np

from mjcf.description import DescriptionError, TableDescription, toml_key_index

DOF_NAMES = ("x", "y", "z", "rx", "ry", "rz")

#: Seed 000, Table 2: bare-table effective masses (kg, kg m^2).
CGS_TABLE2 = {"x": 48.85e3, "y": 49.36e3, "z": 52.50e3, "rx": 208e3, "ry": 217e3, "rz": 354e3}

PARAMS = (
    ("platen", "mass_kg", None),
    ("platen", "inertia_kg_m2", 0),
    ("platen", "inertia_kg_m2", 1),
    ("platen", "inertia_kg_m2", 2),
    ("actuator_class.lateral", "rod_mass_kg", None),
    ("supports", "piston_mass_kg", None),
)


def _get(desc: TableDescription, p):
    sec, key, idx = p
    if sec == "platen":
        v = getattr(desc.platen, key)
    elif sec == "supports":
        v = getattr(desc.supports, key)
    else:
        v = getattr(desc.actuator_classes[sec.split(".")[1]], key)
    return float(v[idx]) if idx is not None else float(v)


def _with(desc: TableDescription, values) -> TableDescription:
    platen = desc.platen
    inertia = platen.inertia_kg_m2.copy()
    mass = platen.mass_kg
    classes = dict(desc.actuator_classes)
    supports = desc.supports
    for p, v in zip(PARAMS, values):
        sec, key, idx = p
        if sec == "platen" and key == "mass_kg":
            mass = v
        elif sec == "platen":
            inertia[idx] = v
        elif sec == "supports":
            supports = dataclasses.replace(supports, piston_mass_kg=v)
        else:
            cname = sec.split(".")[1]
            classes[cname] = dataclasses.replace(classes[cname], **{key: v})
    acts = tuple(dataclasses.replace(a, cls=classes[a.cls.name]) for a in desc.actuators)
    return dataclasses.replace(desc, platen=dataclasses.replace(platen, mass_kg=mass, inertia_kg_m2=inertia),
                               actuator_classes=classes, actuators=acts, supports=supports)


def _eff(desc):
    from mjcf.builder import build_spec
    from mjcf.analysis import effective_mass_matrix

    spec, _ = build_spec(desc)
    Me = effective_mass_matrix(spec.compile())
    return np.diag(Me).copy()


def calibrate_masses(desc: TableDescription, targets: dict[str, float] = CGS_TABLE2) -> dict:
    """Solve for the six calibrated masses; returns values, before/after effective masses."""
    if desc.supports is None or "lateral" not in desc.actuator_classes:
        raise DescriptionError(f"{desc.source}: mass calibration needs static supports and a 'lateral' actuator class")
    x0 = np.array([_get(desc, p) for p in PARAMS])
    e0 = _eff(desc)
    B = np.zeros((6, len(PARAMS)))
    for k in range(len(PARAMS)):
        x = x0.copy()
        step = 1e-3 * max(abs(x0[k]), 1.0)
        x[k] += step
        B[:, k] = (_eff(_with(desc, x)) - e0) / step
    tgt = np.array([targets[d] for d in DOF_NAMES])
    x = x0 + np.linalg.solve(B, tgt - e0)
    bad = [PARAMS[k] for k in range(len(x)) if x[k] <= 0]
    if bad:
        raise DescriptionError(f"{desc.source}: calibration asks for a non-positive {bad[0][0]}.{bad[0][1]}; "
                               "the assumed masses or layout cannot reproduce the targets")
    new = _with(desc, x)
    e1 = _eff(new)
    return {
        "values": {f"{s}.{k}" + (f"[{i}]" if i is not None else ""): float(v) for (s, k, i), v in zip(PARAMS, x)},
        "before": dict(zip(DOF_NAMES, e0.tolist())),
        "after": dict(zip(DOF_NAMES, e1.tolist())),
        "target": dict(zip(DOF_NAMES, tgt.tolist())),
        "description": new,
    }


def write_calibrated(path: Path, result: dict) -> None:
    """Rewrite the calibrated numbers in place in a table TOML file (comments kept)."""
    text = Path(path).read_text()
    vals = result["values"]
    note = "# calibrated: matches Table 2 effective masses (shaketable calibrate)"

    def set_key(text, section, key, value_text):
        lines = text.split("\n")
        i = toml_key_index(lines, section, key)
        if i is None:
            raise DescriptionError(f"{path}: cannot find {section}.{key} to rewrite")
        lines[i] = f"{key} = {value_text}  {note}"
        return "\n".join(lines)

    text = set_key(text, "platen", "mass_kg", f"{vals['platen.mass_kg']:.1f}")
    inertia = [vals[f"platen.inertia_kg_m2[{i}]"] for i in range(3)]
    text = set_key(text, "platen", "inertia_kg_m2", "[" + ", ".join(f"{v:.1f}" for v in inertia) + "]")
    text = set_key(text, "actuator_class.lateral", "rod_mass_kg", f"{vals['actuator_class.lateral.rod_mass_kg']:.2f}")
    text = set_key(text, "supports", "piston_mass_kg", f"{vals['supports.piston_mass_kg']:.2f}")
    tmp = Path(str(path) + ".tmp")
    tmp.write_text(text)
    tmp.replace(path)
