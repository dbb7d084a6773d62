"""The one effect mechanism: :class:`Parameter` and :class:`Effect`.

An effect is a named, parameterised physical part of the model, declared in a table
description (or a scenario) as an ``[[effect]]`` entry and applied at one place:

    [[effect]]
    type = "coulomb_friction"      # the registered type
    where = "dof:x"                # a DOF, an actuator, an actuator class, the supply, a channel
    force_n = 26.5e3               # parameters in SI units, named with their unit
    source = "calibrated: shaketable calibrate run1.run.npz"

Places (``where``): ``"dof:<x|y|z|rx|ry|rz>"``, ``"actuator:<name>"``, ``"class:<actuator
class>"``, ``"actuators"`` (every actuator of the table), ``"supports"`` (the static
supports' air pistons, each alike), ``"shoes"`` (the supports' sliding shoes, in x and y,
each alike), ``"supply"``, ``"channel:<run-file channel>[<column>]"``, ``"payload"`` and
``"table"`` (the whole table, e.g. a foundation mode).

Lifecycle (every method optional but the parameters):

* ``edit_spec(spec, desc)``: what it adds to the MJCF before compiling (joint friction,
  springs, bodies of a payload mode);
* ``edit_model(model)``: once after compiling, per-DOF numbers MjSpec cannot address
  (called by :func:`sim.effects.build_model`);
* ``edit_hydraulics(params)``: hydraulic effects return a changed
  :class:`hydraulics.HydraulicParams` (bulk modulus, leakage, valve delay, ...);
* ``bind(model, hydraulics)``: indices and compiled parameters, once after compiling;
* ``reset()``: its state at the start of a run;
* ``apply(model, data)``: what it adds every physics step (into ``qfrc_applied``), only
  for effects with ``per_step = True``;
* ``measure(t, channels, rng)``: sensor effects change the recorded channels of a run.

Parameters are :class:`Parameter` objects (name, value, unit, bounds, where): the one
concept that calibration, characterisation and sweeps vary. :meth:`Effect.with_values`
gives a copy with new values; :meth:`Effect.entry` the ``[[effect]]`` table to write back.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, replace
from typing import ClassVar

from sim.errors import ScenarioError

PLACE_KINDS = ("dof", "actuator", "class", "actuators", "supports", "shoes", "supply", "channel", "payload", "table")


@dataclass(frozen=True)
class Parameter:
    """One number of the model that can be varied.

    ``name``: the key in the ``[[effect]]`` entry (with its unit: ``force_n``);
    ``value`` in SI ``unit``; ``lower``/``upper``: physical bounds; ``where``: the place
    the effect acts (see the module docstring); ``scale``: a typical magnitude (for
    optimisers and for reporting relative uncertainty), default ``|value|`` or 1.
    """

    name: str
    value: float
    unit: str
    lower: float = -math.inf
    upper: float = math.inf
    where: str = ""
    scale: float | None = None

    def with_value(self, value: float) -> "Parameter":
        return replace(self, value=float(value))

    @property
    def typical(self) -> float:
        return float(self.scale) if self.scale else (abs(self.value) or 1.0)

    def at_bound(self, rel: float = 1e-3) -> bool:
        """Is the value on (within ``rel`` of the typical size of) one of its bounds?"""
        tol = rel * self.typical
        return (math.isfinite(self.lower) and self.value - self.lower <= tol) or (
            math.isfinite(self.upper) and self.upper - self.value <= tol
        )


def parse_where(where: str, source: str = "effect") -> tuple[str, str]:
    """``"dof:x"`` -> ``("dof", "x")``; ``"supply"`` -> ``("supply", "")``."""
    if not isinstance(where, str) or not where:
        raise ScenarioError(f"{source}: 'where' must name a place ({', '.join(k + ':...' for k in PLACE_KINDS)})")
    kind, _, name = where.partition(":")
    if kind not in PLACE_KINDS:
        raise ScenarioError(
            f"{source}: where = '{where}' is not a place{_did_you_mean(kind, PLACE_KINDS)}; "
            "places are " + ", ".join(PLACE_KINDS)
        )
    return kind, name


def _did_you_mean(word: str, known) -> str:
    import difflib

    close = difflib.get_close_matches(str(word), sorted(known), n=1)
    return f" (did you mean '{close[0]}'?)" if close else ""


class Effect:
    """Base class of every effect (built-in or a user's own).

    A subclass sets ``type`` (the registered name), ``places`` (the place kinds it can act
    at), ``per_step`` (True if :meth:`apply` runs every physics step) and declares its
    parameters in :attr:`SPEC`: ``{key: (unit, lower, upper, default or None)}`` (None:
    required). The entry's keys are checked (unknown key: one-line error naming the
    closest known key).
    """

    type: ClassVar[str] = ""
    places: ClassVar[tuple[str, ...]] = ()
    per_step: ClassVar[bool] = False
    #: parameter key -> (unit, lower bound, upper bound, default or None when required)
    SPEC: ClassVar[dict[str, tuple[str, float, float, float | None]]] = {}
    #: keys that are settings, not parameters (strings, flags), with their defaults
    OPTIONS: ClassVar[dict[str, object]] = {}

    def __init__(self, entry: dict, *, source: str = "effect"):
        entry = dict(entry)
        self.source = source
        self.where = str(entry.pop("where", self.default_where()))
        entry.pop("type", None)
        self.note = entry.pop("source", None)
        self.label = entry.pop("name", None)
        kind, _ = parse_where(self.where, source)
        if self.places and kind not in self.places:
            raise ScenarioError(
                f"{source}: a {self.type} effect acts at {', '.join(self.places)}, "
                f"not at '{self.where}'{_did_you_mean(kind, self.places)}"
            )
        known = set(self.SPEC) | set(self.OPTIONS)
        for k in entry:
            if k not in known:
                import difflib

                close = difflib.get_close_matches(k, sorted(known), n=1)
                hint = f" (did you mean '{close[0]}'?)" if close else f"; known: {', '.join(sorted(known))}"
                raise ScenarioError(f"{source}: unknown key '{k}' for a {self.type} effect{hint}")
        self.values: dict[str, float] = {}
        for k, (unit, lo, hi, default) in self.SPEC.items():
            v = entry.get(k, default)
            if v is None:
                raise ScenarioError(f"{source}: a {self.type} effect needs '{k}' ({unit})")
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise ScenarioError(f"{source}: '{k}' must be a finite number in {unit} (got {v!r})")
            if not (lo <= v <= hi):
                raise ScenarioError(f"{source}: '{k}' = {v:g} {unit} is outside [{lo:g}, {hi:g}]")
            self.values[k] = float(v)
        self.options = {k: entry.get(k, d) for k, d in self.OPTIONS.items()}

    # ---------------------------------------------------------------- parameters
    def default_where(self) -> str:
        return ""

    def parameters(self) -> list[Parameter]:
        return [
            Parameter(name=k, value=self.values[k], unit=u, lower=lo, upper=hi, where=self.where)
            for k, (u, lo, hi, _d) in self.SPEC.items()
        ]

    def with_values(self, values: dict[str, float]) -> "Effect":
        """A copy with some parameter values changed (state reset)."""
        new = copy.copy(self)
        new.values = dict(self.values)
        for k, v in values.items():
            if k not in self.SPEC:
                raise KeyError(f"{self.type} has no parameter '{k}'")
            new.values[k] = float(v)
        return new

    def entry(self) -> dict:
        """The ``[[effect]]`` table for a description file."""
        e = {"type": self.type, "where": self.where}
        e.update(self.values)
        e.update({k: v for k, v in self.options.items() if v is not None})
        if self.note:
            e["source"] = self.note
        return e

    # ---------------------------------------------------------------- lifecycle
    def edit_spec(self, spec, desc) -> None:
        """Add to the MJCF before compiling."""

    def edit_model(self, model) -> None:
        """Change the compiled ``mujoco.MjModel`` once after the build (per-DOF numbers
        that MjSpec cannot address, e.g. one DOF of a free joint); called by
        :func:`sim.effects.build_model`."""

    def edit_hydraulics(self, params):
        """Return the hydraulic parameters with this effect applied."""
        return params

    def bind(self, model, hydraulics=None) -> None:
        """Resolve indices once the model is compiled."""

    def reset(self) -> None:
        """State at the start of a run."""

    def apply(self, model, data) -> None:
        """Add this effect's generalised forces to ``data.qfrc_applied`` (per_step only)."""

    def measure(self, t, channels: dict, rng) -> dict:
        """Sensor effects: the recorded channels as the sensor reports them."""
        return channels

    def __repr__(self) -> str:
        vals = ", ".join(f"{k}={v:.6g}" for k, v in self.values.items())
        return f"{type(self).__name__}({self.where}: {vals})"


#: type name -> Effect subclass (built-in and user effects alike)
EFFECTS: dict[str, type[Effect]] = {}


def register(cls: type[Effect]) -> type[Effect]:
    """Class decorator: register an :class:`Effect` subclass under its ``type``."""
    if not cls.type:
        raise TypeError(f"{cls.__name__} needs a 'type' name to be registered")
    EFFECTS[cls.type] = cls
    return cls


def create(entry: dict, *, source: str = "effect") -> Effect:
    """The :class:`Effect` of one ``[[effect]]`` entry (one-line error for an unknown type)."""
    kind = entry.get("type")
    if not isinstance(kind, str) or kind not in EFFECTS:  # (a list or a table is no type name either)
        import difflib

        close = difflib.get_close_matches(str(kind), sorted(EFFECTS), n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else f"; known: {', '.join(sorted(EFFECTS))}"
        raise ScenarioError(f"{source}: unknown effect type '{kind}'{hint}")
    return EFFECTS[kind](entry, source=source)


__all__ = ["EFFECTS", "Effect", "PLACE_KINDS", "Parameter", "create", "parse_where", "register"]
