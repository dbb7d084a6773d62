"""Effects: named, parameterised parts of the model declared in a description
(``[[effect]]``), built into the MjSpec and applied every physics step.

One mechanism (:mod:`sim.effects.base`: :class:`Effect`, :class:`Parameter`, the
registry ``EFFECTS``); the mechanical library in :mod:`sim.effects.mechanical`; a
user's own effect from a Python file (:mod:`sim.effects.registry`); the description's
own numbers as parameters in :mod:`sim.effects.table` (docs/effects.md).

:func:`build_model` is how ``sim`` builds a table: ``mjcf.build`` plus the description's
effects (``mjcf`` itself knows none).
"""

from __future__ import annotations

from sim.effects import faults, hydraulic, mechanical, sensors, specimen  # noqa: F401,E402  (register the built-in effects)
from sim.effects.base import EFFECTS, Effect, Parameter, create, register
from sim.effects.registry import build_effects, catalogue, dahl_step, known, load_user_effect
from sim.effects.table import table_parameters, with_parameter_values


def build_model(desc, payload=None, options=None):
    """The compiled :class:`mjcf.model.TableModel` of ``desc`` (+ ``payload``) with its
    ``[[effect]]`` entries built in (``tm.step_effects``: those applied every step)."""
    import mjcf

    tm = mjcf.build(desc, payload, options, effects=build_effects)
    for e in tm.effects:
        e.edit_model(tm.model)
    return tm


__all__ = [
    "EFFECTS",
    "Effect",
    "Parameter",
    "build_effects",
    "build_model",
    "catalogue",
    "create",
    "dahl_step",
    "known",
    "load_user_effect",
    "register",
    "table_parameters",
    "with_parameter_values",
]
