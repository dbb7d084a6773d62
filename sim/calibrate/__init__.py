"""MAKE IT MATCH: replay of measured runs, residuals, the effect search, the calibrated description."""

from sim.calibrate.replay import ReplayOutcome, replay

__all__ = ["ReplayOutcome", "replay"]
