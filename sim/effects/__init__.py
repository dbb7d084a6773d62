"""Effects: named, parameterised parts of the model declared in a description
(``[[effect]]``), built into the MjSpec and applied every physics step.

:func:`build_model` is how ``sim`` builds a table: ``mjcf.build`` plus the description's
effects (``mjcf`` itself knows none).
"""

from __future__ import annotations

from sim.effects.registry import StepEffect, build_effects, dahl_step, known, register
from sim.effects import hydraulic, sensors  # noqa: F401  (register the hydraulic and sensor effects)


def build_model(desc, payload=None, options=None):
    """The compiled :class:`mjcf.model.TableModel` of ``desc`` (+ ``payload``) with its
    ``[[effect]]`` entries built in (``tm.step_effects``: those applied every step)."""
    import mjcf

    return mjcf.build(desc, payload, options, effects=build_effects)


__all__ = ["StepEffect", "build_effects", "build_model", "dahl_step", "known", "register"]
