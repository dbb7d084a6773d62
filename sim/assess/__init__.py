"""WILL IT WORK: run a scenario (``run``), tracking metrics, the feasibility verdict, geometric nonlinearity."""

from sim.assess.run import RunOutcome, run_scenario

__all__ = ["RunOutcome", "run_scenario"]
