"""Hydraulic step timing: microseconds per step for the CGS table (12 actuators).

    python bench/hydraulics_bench.py

Measures, in one run: one 12-actuator system on the numba and numpy backends, and a
batch of 64 x 12 on both. Target: a 12-actuator numba step <= ~12 us (30 % of one
mj_step of the CGS model, ~42 us).
"""

from __future__ import annotations

import time
import tomllib
from pathlib import Path

import numpy as np

from hydraulics import HydraulicParams, HydraulicSystem

TABLE = Path(__file__).resolve().parents[1] / "scenarios" / "tables" / "cgs.toml"


def _time_step(params, n_sim, backend, seconds=0.5, dt=0.0005):
    hs = HydraulicSystem(params, n_sim=n_sim, dt=dt, backend=backend)
    rng = np.random.default_rng(0)
    x = np.zeros((n_sim, params.n_act))
    v = np.zeros_like(x)
    hs.reset(x)
    cmds = rng.uniform(-0.5, 0.5, (16, n_sim, params.n_act))
    hs.step(cmds[0], x, v)  # compile / warm up
    n = 0
    t0 = time.perf_counter()
    t1 = t0
    while t1 - t0 < seconds:
        for k in range(100):
            hs.step(cmds[k & 15], x, v)
        n += 100
        t1 = time.perf_counter()
    return (t1 - t0) / n * 1e6


def run(report=None):
    """Return {name: microseconds per step}; call report(name, value, unit) for each."""
    with open(TABLE, "rb") as fh:
        params = HydraulicParams.from_table(tomllib.load(fh))
    res = {}
    for backend in ("numba", "numpy"):
        for n_sim in (1, 64):
            name = f"hydraulics.step {backend} {n_sim}x{params.n_act}"
            us = _time_step(params, n_sim, backend, seconds=0.5 if backend == "numba" else 1.0)
            res[name] = us
            if report is not None:
                report(name, us, "us/step")
    return res


def main():
    def report(name, value, unit):
        print(f"{name:40s} {value:10.2f} {unit}")

    res = run(report)
    nb = res["hydraulics.step numba 1x12"]
    print(f"target: 12-actuator numba step <= 12 us: {'met' if nb <= 12.0 else 'NOT met'} ({nb:.2f} us)")


if __name__ == "__main__":
    main()
