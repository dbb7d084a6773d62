"""Servo-hydraulics of a shaking table: servovalves, actuators, supply (no MuJoCo).

    from hydraulics import HydraulicParams, HydraulicSystem, HydraulicsParamError
    params = HydraulicParams.from_table(tomllib.load(f))
    hs = HydraulicSystem(params, n_sim=1, dt=0.0005, backend="numba")
    hs.reset(x)
    F = hs.step(command, x, v)     # call BEFORE the physics step, with the current x, v

See ``hydraulics.system`` for the model, the integration scheme and where the step sits
relative to the physics step.
"""

from .params import HydraulicParams, HydraulicsParamError
from .system import HydraulicState, HydraulicSystem

__all__ = ["HydraulicParams", "HydraulicSystem", "HydraulicState", "HydraulicsParamError"]
