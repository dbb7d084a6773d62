"""The controller protocol of the one stepping loop, and the factory that picks a table's
controller by its ``[controller] type``.

A table's controller comes in two parts:

* its **settings** (:class:`ControllerSettings`: the gains of a scenario run, parsed from
  the table's ``[controller]`` with a scenario's overrides on top): the recorder rate
  ``rate_hz`` (the run file's sample rate), the controller's own rate
  ``controller_rate_hz``, the physics step it needs (``timestep_s``, None: the table's),
  the description it runs on (``table(desc)``: e.g. the analog controller's parameter set
  applied) and ``build(...)``, which makes the controller for one simulation;
* the **controller** (:class:`Controller`), which :class:`sim.loop.simulation.Simulation`
  ticks every ``steps_per_tick`` physics steps: ``reset()`` before a run, ``start(...)`` with
  the run's reference at the controller rate and the simulation's state arrays, then
  ``tick(i, out)`` writes the valve commands of tick ``i`` (held until the next tick).
  ``has_compiled_tick()`` says whether the loop may fuse recorder, tick and hydraulics
  into one compiled call per physics step (the MTS-style controller); ``stroke_limit_m``
  (None: no limit) makes the loop stop a run whose actuator leaves its stroke.

Types: ``"digital"`` (the default: :mod:`sim.control.tvc`, MTS-469D style, 1024 Hz) and
``"analog"`` (:mod:`sim.control.analog`, PIDF + dP at every physics step).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from sim.errors import ScenarioError


@runtime_checkable
class Controller(Protocol):
    """What the loop needs of a controller (see the module docstring)."""

    rate_hz: float  #: ticks per second
    stroke_limit_m: float | None  #: stop the run when an actuator's stroke exceeds this (None: never)

    def reset(self) -> None: ...

    def has_compiled_tick(self) -> bool: ...

    def start(self, tm, d, hs, reference, n_ticks: int, *, kinematics: str = "exact", fast: bool = True) -> None: ...

    def tick(self, i: int, out: np.ndarray) -> None: ...


@runtime_checkable
class ControllerSettings(Protocol):
    """A controller's settings for one run (see the module docstring)."""

    rate_hz: float  #: the recorder's rate (the run file's sample rate)
    controller_rate_hz: float  #: the controller's ticks per second
    timestep_s: float | None  #: the physics step the controller needs (None: the table's)

    def table(self, desc): ...

    def build(self, desc, *, hp, full_flow_m3_s: float, dt: float) -> Controller: ...


TYPES = ("digital", "analog")


def controller_type(desc) -> str:
    """The ``[controller] type`` of a description (``"digital"`` when absent)."""
    t = (desc.raw.get("controller", {}) or {}).get("type", "digital")
    if t not in TYPES:
        raise ScenarioError(f"{desc.source}: controller.type '{t}' is not one of {', '.join(TYPES)}; use one of them")
    return t


def controller_settings(desc, overrides: dict | None = None) -> ControllerSettings:
    """The settings of ``desc``'s controller (its ``[controller]`` with ``overrides`` on
    top), chosen by ``[controller] type``: the one factory."""
    if controller_type(desc) == "analog":
        from sim.control.analog import AnalogGains

        return AnalogGains.for_table(desc, overrides)
    from sim.control.tvc import ControllerGains

    return ControllerGains.for_table(desc, overrides)


__all__ = ["TYPES", "Controller", "ControllerSettings", "controller_settings", "controller_type"]
