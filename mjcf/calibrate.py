"""Calibrate the unpublished masses of a table description against measured effective masses.

The paper (Table 2 of [Airouche 2014]) gives the effective mass per DOF of the bare table; the
layout and the actuators' moving masses are not published. The effective mass from the
model, ``diag(T^T M T)``, is linear in every body's mass and inertia (the projection T
depends on geometry only), so the unknowns follow from one linear solve:

* platen mass and its three principal moments of inertia,
* the lateral rods' moving mass (the paper attributes y > x to the actuators' weights),
* the static-support pistons' mass (the vertical excess: mass that moves only vertically).

Six unknowns for the six measured values; the other masses stay as assumed. The command
``shaketable calibrate TABLE --write`` rewrites those numbers in the TOML file, marked
``calibrated: matches Table 2``.

Table 2 is a *measured* effective mass (the in-phase acceleration -> force FRF of random
tests), not ``diag(T^T M T)``: whatever stiffness acts in parallel at the test levels (the
friction contacts' pre-sliding stiffness, the supports) reads as a negative mass ``-K/w^2``.
``shaketable characterize TABLE --calibrate`` runs the virtual R1/R2 tests and records the
difference, rigid-body minus virtual test, per DOF as ``[calibration]
effective_mass_offset`` in the table file; the rigid-body targets are then Table 2 plus
that offset, so that the *virtual tests* reproduce Table 2 (:func:`mass_targets`).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np

from mjcf.description import DOFS6 as DOF_NAMES
from mjcf.description import DescriptionError, TableDescription, toml_key_index


def published_effective_mass(desc: TableDescription) -> dict[str, float]:
    """The measured effective masses of the description's ``[published] effective_mass``
    (kg for x, y, z; kg m^2 for rx, ry, rz)."""
    em = (desc.raw.get("published") or {}).get("effective_mass")
    if (
        not isinstance(em, dict)
        or set(em) != set(DOF_NAMES)
        or not all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0 for v in em.values()
        )
    ):
        raise DescriptionError(
            f"{desc.source}: mass calibration needs '[published] effective_mass' with a positive "
            f"number for each of {', '.join(DOF_NAMES)} (the table's measured effective masses)"
        )
    return {d: float(em[d]) for d in DOF_NAMES}


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
    return dataclasses.replace(
        desc,
        platen=dataclasses.replace(platen, mass_kg=mass, inertia_kg_m2=inertia),
        actuator_classes=classes,
        actuators=acts,
        supports=supports,
    )


def values_into_raw(raw: dict, values: dict) -> None:
    """Write calibrated values (keys as in :func:`calibrate_masses`' ``values``) into a
    table's raw TOML dict, in place."""
    for sec, key, idx in PARAMS:
        v = float(values[f"{sec}.{key}" + (f"[{idx}]" if idx is not None else "")])
        node = raw
        for part in sec.split("."):
            node = node[part]
        if idx is None:
            node[key] = v
        else:
            node[key] = list(node[key])
            node[key][idx] = v


def _eff(desc):
    from mjcf.analysis import effective_mass_matrix
    from mjcf.builder import build_spec

    spec, _ = build_spec(desc)
    Me = effective_mass_matrix(spec.compile())
    return np.diag(Me).copy()


def mass_offset(desc: TableDescription) -> dict[str, float]:
    """``[calibration] effective_mass_offset`` of a table file (kg, kg m^2 per DOF; zeros if absent):
    rigid-body minus virtual-test effective mass, measured by ``characterize --calibrate``."""
    cal = desc.raw.get("calibration", {}) or {}
    if not isinstance(cal, dict):
        raise DescriptionError(f"{desc.source}: '[calibration]' must be a table")
    extra = sorted(set(cal) - {"effective_mass_offset"})
    if extra:
        raise DescriptionError(
            f"{desc.source}: unknown key '{extra[0]}' in [calibration]; known keys: effective_mass_offset"
        )
    v = cal.get("effective_mass_offset", [0.0] * 6)
    try:
        arr = np.asarray(v, dtype=float)
    except (TypeError, ValueError):
        arr = np.array([])
    if arr.shape != (6,) or not np.all(np.isfinite(arr)):
        raise DescriptionError(
            f"{desc.source}: 'calibration.effective_mass_offset' must be 6 finite numbers "
            "(x, y, z in kg, rx, ry, rz in kg m^2); rerun `shaketable characterize TABLE --calibrate`"
        )
    return dict(zip(DOF_NAMES, arr.tolist()))


def mass_targets(desc: TableDescription, measured: dict[str, float] | None = None) -> dict[str, float]:
    """Rigid-body effective masses that make the virtual tests read ``measured`` (default:
    the description's ``[published] effective_mass``)."""
    measured = measured if measured is not None else published_effective_mass(desc)
    off = mass_offset(desc)
    return {d: measured[d] + off[d] for d in DOF_NAMES}


def calibrate_masses(desc: TableDescription, targets: dict[str, float] | None = None) -> dict:
    """Solve for the six calibrated masses; returns values, before/after effective masses.

    ``targets`` are rigid-body effective masses; by default :func:`mass_targets`
    (Table 2 plus the table file's recorded test offset)."""
    if targets is None:
        targets = mass_targets(desc)
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
        raise DescriptionError(
            f"{desc.source}: calibration asks for a non-positive {bad[0][0]}.{bad[0][1]}; "
            "the assumed masses or layout cannot reproduce the targets"
        )
    new = _with(desc, x)
    e1 = _eff(new)
    return {
        "values": {f"{s}.{k}" + (f"[{i}]" if i is not None else ""): float(v) for (s, k, i), v in zip(PARAMS, x)},
        "before": dict(zip(DOF_NAMES, e0.tolist())),
        "after": dict(zip(DOF_NAMES, e1.tolist())),
        "target": dict(zip(DOF_NAMES, tgt.tolist())),
        "description": new,
    }


NOTE_FORMULA = "# calibrated: matches Table 2 effective masses (shaketable calibrate)"
NOTE_TESTS = "# calibrated: matches Table 2 in the virtual R1/R2 tests (shaketable characterize --calibrate)"


def write_calibrated(path: Path, result: dict, note: str = NOTE_FORMULA, offset: dict | None = None) -> None:
    """Rewrite the calibrated numbers in place in a table TOML file (comments kept);
    with ``offset``, also (re)write ``[calibration] effective_mass_offset``."""
    text = Path(path).read_text()
    vals = result["values"]

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
    if offset is not None:
        line = (
            "effective_mass_offset = [" + ", ".join(f"{offset[d]:.1f}" for d in DOF_NAMES) + "]"
            "  # measured: rigid-body minus virtual-test effective mass (mean of R1, R2), x y z kg, rx ry rz kg m^2"
        )
        lines = text.split("\n")
        i = toml_key_index(lines, "calibration", "effective_mass_offset")
        if i is not None:
            lines[i] = line
            text = "\n".join(lines)
        else:
            text = (
                text.rstrip("\n")
                + "\n\n"
                + "\n".join(
                    [
                        "# What the virtual effective-mass tests (characterize, R1/R2) read below the rigid-body",
                        "# effective mass diag(T^T M T): the parallel stiffness (pre-sliding friction, supports) as",
                        "# -K/w^2 over the test band. `shaketable calibrate` aims the rigid-body masses at Table 2",
                        "# plus this, so that the virtual tests reproduce Table 2; `characterize --calibrate` measures it.",
                        "[calibration]",
                        line,
                    ]
                )
                + "\n"
            )
    from mjcf.errors import write_text_replacing

    write_text_replacing(path, text)
