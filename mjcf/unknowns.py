"""The ``[unknown]`` table of a table description: values the lab does not know.

A description may mark any number it holds as unknown within a range (SI)::

    [unknown]
    "fluid.bulk_modulus_pa" = [0.5e9, 1.8e9]
    "actuator_class.main.dead_volume_a_m3" = [1e-4, 2e-3]

The key is the dotted path of the number in the file (tables only, as the description
is built from them); the number on its own line stays the nominal the model runs with,
and calibration (:mod:`sim.calibrate.unknowns`) identifies it within the range before it
looks for missing effects. :func:`parse_unknowns` checks each entry: the key names a
number of the file, the range is two finite numbers ``LO < HI`` and holds the nominal,
and a value that is not negative keeps a range that is not negative either (bulk
moduli, volumes, flows, masses).
"""

from __future__ import annotations

import math

from mjcf.errors import DescriptionError

EXAMPLE = '"fluid.bulk_modulus_pa" = [0.5e9, 1.8e9]'


def value_at(data: dict, key: str):
    """The value of the dotted ``key`` in the parsed description ``data`` (KeyError if none)."""
    node = data
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            raise KeyError(key)
        node = node[part]
    return node


def set_value_at(data: dict, key: str, value) -> None:
    """Set the dotted ``key`` of ``data`` (a parsed description) to ``value`` in place."""
    *head, last = key.split(".")
    node = data
    for part in head:
        node = node[part]
    node[last] = value


def _is_number(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)


def _check_entry(data: dict, key: str, rng, src: str) -> tuple[float, float]:
    where = f"{src}: [unknown] '{key}'"
    try:
        nominal = value_at(data, key)
    except KeyError:
        raise DescriptionError(
            f"{where} names no value of the description; give the dotted key of a number in the file (e.g. {EXAMPLE})"
        ) from None
    if not _is_number(nominal):
        raise DescriptionError(f"{where} names {nominal!r}, not a number; only numbers can be unknown")
    if not (isinstance(rng, list) and len(rng) == 2 and all(_is_number(x) for x in rng)):
        raise DescriptionError(f"{where} must be [LO, HI], two numbers in SI units (got {rng!r})")
    lo, hi = float(rng[0]), float(rng[1])
    if not lo < hi:
        raise DescriptionError(f"{where} = [{lo:g}, {hi:g}]: LO must be below HI; give [LO, HI]")
    if nominal >= 0 > lo:
        raise DescriptionError(f"{where} = [{lo:g}, {hi:g}]: a value that cannot be negative needs LO >= 0")
    if not lo <= nominal <= hi:
        raise DescriptionError(
            f"{where}: the nominal {nominal:g} on the key's own line is outside [{lo:g}, {hi:g}]; "
            "set the nominal inside the range or widen the range"
        )
    return lo, hi


def parse_unknowns(data: dict, src: str) -> dict[str, tuple[float, float]]:
    """``{dotted key: (LO, HI)}`` of the description's ``[unknown]`` table (empty without
    one); a bad entry raises :class:`DescriptionError` (one line: file, key, fix)."""
    table = data.get("unknown")
    if table is None:
        return {}
    if not isinstance(table, dict):
        raise DescriptionError(f"{src}: [unknown] must be a table of dotted keys and ranges (e.g. {EXAMPLE})")
    return {key: _check_entry(data, key, rng, src) for key, rng in table.items()}


__all__ = ["parse_unknowns", "set_value_at", "value_at"]
