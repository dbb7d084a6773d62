"""Overrides of a scenario's inputs by dotted key: what a sweep varies.

A key names one number (or list of numbers) in the TOML data a run is built from:

* ``table.<section>...<key>``: the table description (``table.fluid.bulk_modulus_pa``);
* ``payload.<key>``: the payload description, under its ``[payload]`` table
  (``payload.mass_kg``);
* ``motion.<key>``, ``controller.<key>``, ``iteration.<key>``: the scenario's own tables
  (``motion.amplitude_factor``, ``controller.kp_per_s``).

A ``*`` segment matches every sub-table (``table.actuator_class.*.seal_friction_n``: the
seal friction of every actuator class). A controller gain the scenario does not set may be
set (the controller checks it). An override either sets the value or, with
``scale``, multiplies the value in the file (a list elementwise). The data is copied,
never changed in place; a key that names nothing raises :class:`OverrideError`.
"""

from __future__ import annotations

import copy

from sim.errors import UserError

ROOTS = ("table", "payload", "motion", "controller", "iteration")


class OverrideError(UserError):
    """An override key that names nothing in the scenario's data."""


def _targets(data: dict, parts: list[str], key: str, where: str):
    """(dict, last key) pairs the dotted ``parts`` address in ``data``."""
    nodes = [data]
    for p in parts[:-1]:
        nxt = []
        for n in nodes:
            if p == "*":
                nxt += [v for v in n.values() if isinstance(v, dict)]
            elif isinstance(n.get(p), dict):
                nxt.append(n[p])
        nodes = nxt
    out = [(n, parts[-1]) for n in nodes if parts[-1] in n]
    if not out:
        raise OverrideError(
            f"{where}: override '{key}' names no value in the data; give an existing key "
            f"(e.g. table.fluid.bulk_modulus_pa, payload.mass_kg, motion.amplitude_factor)"
        )
    return out


def _num(v, key, where):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise OverrideError(f"{where}: override '{key}' must be a number (got {v!r})")
    return float(v)


def apply(data: dict, key: str, value, *, scale: bool = False, where: str = "override") -> dict:
    """A deep copy of ``data`` (a dict with the :data:`ROOTS` as keys) with ``key`` set to
    ``value`` (or multiplied by it with ``scale``)."""
    parts = key.split(".")
    if parts[0] not in ROOTS or len(parts) < 2:
        raise OverrideError(f"{where}: override '{key}' must start with one of {', '.join(ROOTS)}")
    out = copy.deepcopy(data)
    root = out.get(parts[0])
    if root is None:
        raise OverrideError(f"{where}: override '{key}': the scenario has no {parts[0]}")
    sub = parts[1:]
    if parts[0] == "controller" and not scale and len(sub) == 1 and sub[0] not in root:
        root[sub[0]] = value  # a gain the scenario leaves at the table's default (checked by the controller)
        return out
    for node, last in _targets(root, sub, key, where):
        old = node[last]
        if scale:
            f = _num(value, key, where)
            node[last] = [_num(x, key, where) * f for x in old] if isinstance(old, list) else _num(old, key, where) * f
        elif isinstance(old, list) and not isinstance(value, list):
            node[last] = [_num(value, key, where)] * len(old)
        else:
            node[last] = value
    return out


def apply_all(data: dict, overrides: dict, where: str = "override") -> dict:
    """:func:`apply` for each ``{key: value}`` (or ``{key: {"scale": f}}``) in order."""
    for key, v in overrides.items():
        if isinstance(v, dict):
            if set(v) != {"scale"}:
                raise OverrideError(f"{where}: override '{key}' must be a value or {{scale = factor}}")
            data = apply(data, key, v["scale"], scale=True, where=where)
        else:
            data = apply(data, key, v, where=where)
    return data


__all__ = ["OverrideError", "ROOTS", "apply", "apply_all"]
