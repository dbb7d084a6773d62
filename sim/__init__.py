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

import os

# One BLAS thread per process unless the caller says otherwise, set before numpy loads:
# the heavy work runs in worker processes (sim.parallel.map_jobs: sweeps, calibration
# candidates), and OpenBLAS's own threads then wait on one another. Measured on a loaded
# 2-core machine: a 153 x 153 solve of the ARX baseline took 210 ms with its threads and
# 0.27 ms with one; a CGS mechanical calibration 205 s and 13.6 s, with the same results.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

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
