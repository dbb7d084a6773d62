"""THE TWIN: the stepping loop (MuJoCo + hydraulics + controller + recorder), its compiled kernels and recorder; one loop for every table and controller."""

from sim.loop.simulation import GAP_LIMIT_M, RunResult, Simulation

__all__ = ["GAP_LIMIT_M", "RunResult", "Simulation"]
