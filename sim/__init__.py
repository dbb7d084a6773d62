"""shaketable: a digital twin of servo-hydraulic earthquake shaking tables.

The public API (imported lazily, so that ``import sim`` stays cheap)::

    from sim import load_scenario, run_scenario
    outcome = run_scenario(load_scenario("elcentro_bare"), duration_s=30)
    outcome.summary["tracking"], outcome.verdict, outcome.run

The package follows the data path: ``scenario`` (input) -> ``loop`` (with ``control``
and ``effects``) -> ``runs`` (run files) -> ``assess`` / ``identify`` / ``calibrate``;
``sweep`` runs any of these many times; ``papers`` holds the three papers' programmes;
``report`` and ``cli`` present.
"""

from __future__ import annotations

_API = {
    "load_scenario": "sim.scenario.files",
    "Scenario": "sim.scenario.files",
    "run_scenario": "sim.assess.run",
    "RunOutcome": "sim.assess.run",
    "replay": "sim.calibrate.replay",
    "Simulation": "sim.loop.simulation",
    "RunResult": "sim.loop.simulation",
    "RunFile": "sim.runs.runfile",
    "read_run": "sim.runs.runfile",
    "write_run": "sim.runs.runfile",
    "build_model": "sim.effects",
    "UserError": "sim.errors",
}

__all__ = sorted(_API)


def __getattr__(name):
    if name in _API:
        import importlib

        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'sim' has no attribute {name!r}")
