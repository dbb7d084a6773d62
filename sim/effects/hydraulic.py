"""Hydraulic effects: the servovalves, the oil and the supply as they really are.

Each effect changes :class:`hydraulics.HydraulicParams` before the hydraulic system is
built (``edit_hydraulics``); none acts per step. Valve effects act on one actuator
(``where = "actuator:X1"``), on every actuator of a class (``"class:longitudinal"``) or on
every actuator of the table (``"actuators"``: one number of the description, as the oil's
bulk modulus or the valves' rated flow),
the oil effects on a class (or one actuator), the supply drop at ``"supply"``::

    [[effect]]
    type = "valve_null_offset"
    where = "actuator:X1"
    offset = 0.01                   # fraction of full opening added to the command
    source = "assumed: 1 % bias, the drift of an open-loop replay"

| type | parameter | unit | what it sets |
|---|---|---|---|
| ``valve_delay`` | ``delay_s`` | s | the valve's pure delay (rounded to the physics step) |
| ``valve_bandwidth`` | ``bandwidth_hz`` | Hz | first-order valve: tau = 1/(2 pi f); second-order: natural frequency f |
| ``valve_flow_gain`` | ``factor`` | 1 | multiplies the valve's flow (all lands) |
| ``valve_null_offset`` | ``offset`` | 1 | added to the command, fraction of full opening |
| ``bulk_modulus`` | ``bulk_modulus_pa`` | Pa | the oil in the chambers |
| ``leakage`` | ``coefficient_m3_s_pa`` | m^3/(s Pa) | cross-piston (``kind = "cross"``) or external (``"external"``) leakage |
| ``supply_pressure_drop`` | ``drop_pa`` | Pa | lowers the supply set pressure |

Values replace the description's (the factor and the drop are relative to it).
"""

from __future__ import annotations

import math

import numpy as np

from sim.effects.base import Effect, register
from sim.errors import ScenarioError


def actuator_indices(effect: Effect, params) -> np.ndarray:
    """Indices of the actuators an effect at ``actuator:<name>`` / ``class:<name>`` /
    ``actuators`` acts on."""
    kind, name = effect.where.partition(":")[::2]
    if kind == "actuators":
        return np.arange(len(params.names))
    if kind == "actuator":
        if name not in params.names:
            raise ScenarioError(
                f"{effect.source}: where = '{effect.where}' names no actuator; actuators: {', '.join(params.names)}"
            )
        return np.array([params.names.index(name)])
    if name not in params.classes:
        raise ScenarioError(
            f"{effect.source}: where = '{effect.where}' names no actuator class; "
            f"classes: {', '.join(sorted(set(params.classes)))}"
        )
    return np.array([i for i, c in enumerate(params.classes) if c == name])


class _PerActuator(Effect):
    """An effect that sets one per-actuator hydraulic quantity."""

    places = ("actuator", "class", "actuators")

    def set_values(self, params, idx) -> None:
        raise NotImplementedError

    def edit_hydraulics(self, params):
        p = params.copy()
        self.set_values(p, actuator_indices(self, p))
        p.validate()
        return p

    @staticmethod
    def _override(p, name, idx, value) -> None:
        arr = p.per_actuator(name)
        arr[idx] = value
        setattr(p, name, arr)


@register
class ValveDelay(_PerActuator):
    """Pure delay of a servovalve (s), realised as a whole number of physics steps."""

    type = "valve_delay"
    SPEC = {"delay_s": ("s", 0.0, 0.1, None)}

    def set_values(self, p, idx):
        self._override(p, "valve_delay_s", idx, self.values["delay_s"])


@register
class ValveBandwidth(_PerActuator):
    """Bandwidth of a servovalve's main stage (Hz): the corner 1/(2 pi tau) of the
    first-order valve, the natural frequency of the second-order one (damping ratio kept)."""

    type = "valve_bandwidth"
    SPEC = {"bandwidth_hz": ("Hz", 1e-3, 1e4, None)}

    def set_values(self, p, idx):
        f = self.values["bandwidth_hz"]
        self._override(p, "valve_tau_s", idx, 1.0 / (2.0 * math.pi * f))
        self._override(p, "valve_natural_frequency_hz", idx, f)


@register
class ValveFlowGain(_PerActuator):
    """Flow gain of a servovalve relative to its data sheet (1 = rated)."""

    type = "valve_flow_gain"
    SPEC = {"factor": ("1", 1e-3, 10.0, None)}

    def set_values(self, p, idx):
        self._override(p, "valve_flow_gain", idx, p.per_actuator("valve_flow_gain")[idx] * self.values["factor"])


@register
class ValveNullOffset(_PerActuator):
    """Null bias of a servovalve: a fraction of full opening added to its command."""

    type = "valve_null_offset"
    SPEC = {"offset": ("1", -0.5, 0.5, None)}

    def set_values(self, p, idx):
        self._override(p, "valve_null_offset", idx, self.values["offset"])


@register
class BulkModulus(_PerActuator):
    """Effective bulk modulus of the oil in the chambers of a class (Pa)."""

    type = "bulk_modulus"
    SPEC = {"bulk_modulus_pa": ("Pa", 1e7, 1e11, None)}

    def set_values(self, p, idx):
        self._override(p, "chamber_bulk_modulus_pa", idx, self.values["bulk_modulus_pa"])


@register
class Leakage(_PerActuator):
    """Laminar leakage coefficient of a class (m^3/(s Pa)): across the piston
    (``kind = "cross"``, a -> b) or to the drain (``kind = "external"``, each chamber)."""

    type = "leakage"
    SPEC = {"coefficient_m3_s_pa": ("m^3/(s Pa)", 0.0, 1e-6, None)}
    OPTIONS = {"kind": "cross"}

    def set_values(self, p, idx):
        kind = self.options["kind"]
        if kind not in ("cross", "external"):
            raise ScenarioError(f'{self.source}: kind = {kind!r}; use "cross" or "external"')
        getattr(p, f"leakage_{kind}_m3_s_pa")[idx] = self.values["coefficient_m3_s_pa"]


@register
class SupplyPressureDrop(Effect):
    """The supply set pressure lower than the description's by ``drop_pa`` (a worn pump,
    a compensator set low, line losses at the flows of a test)."""

    type = "supply_pressure_drop"
    places = ("supply",)
    SPEC = {"drop_pa": ("Pa", 0.0, 1e9, None)}

    def default_where(self) -> str:
        return "supply"

    def edit_hydraulics(self, params):
        p = params.copy()
        p.supply_pressure_pa = params.supply_pressure_pa - self.values["drop_pa"]
        low = max(p.return_pressure_pa, p.accumulator_precharge_pa if p.accumulator_volume_m3 > 0 else 0.0)
        if p.supply_pressure_pa <= low:
            raise ScenarioError(
                f"{self.source}: drop_pa = {self.values['drop_pa']:g} Pa leaves the supply at "
                f"{p.supply_pressure_pa:g} Pa, not above {low:g} Pa (return or accumulator "
                f"precharge); use a smaller drop"
            )
        p.validate()
        return p


__all__ = [
    "BulkModulus",
    "Leakage",
    "SupplyPressureDrop",
    "ValveBandwidth",
    "ValveDelay",
    "ValveFlowGain",
    "ValveNullOffset",
    "actuator_indices",
]
