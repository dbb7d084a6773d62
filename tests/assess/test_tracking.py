"""Earthquake tracking on the model (slow: full El Centro runs with drive iteration).

The issue's acceptance figures for El Centro at 80 %: displacement NRMSE <= 5 %, PGA
within 10 %, 5 %-damped response spectrum of the achieved acceleration within
0.8-1.25 x the reference's from 0.5 to 20 Hz. The plain controller falls short of it
(PGA 1.13-1.17 in x, spectrum up to 1.25-1.43 in 13-20 Hz): the dry friction (1.25 %
of capability, [Airouche 2014]) reverses at every velocity reversal and rings the oil
columns. The scenarios therefore iterate the drive on the model (two corrections, FRF
from a white-noise identification run), as table controllers do before a test; the
criterion is asserted on the iterated run.
"""

import json

import numpy as np
import pytest

from sim.assess.metrics import spectrum_ratio
from sim.cli import main
from sim.runs.runfile import read_run

_CACHE = {}


def _summary(tmp_path_factory, scenario):
    if scenario not in _CACHE:
        out = tmp_path_factory.mktemp(scenario)
        rc = main(["run", scenario, "--out", str(out)])
        assert rc == 0
        s = json.loads((out / "summary.json").read_text())
        run = read_run(s["run_file"])
        ratios = {}
        for i, dof in enumerate(("x", "y", "z")):
            ref_a = np.gradient(np.gradient(run.reference[:, i], run.dt), run.dt)
            ratios[dof] = spectrum_ratio(run.table_acceleration[:, i], ref_a, run.dt)
        _CACHE[scenario] = (s, ratios)
    return _CACHE[scenario]


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["elcentro_bare", "elcentro_20t"])
def test_el_centro_80_percent_tracks(tmp_path_factory, scenario):
    s, ratios = _summary(tmp_path_factory, scenario)
    assert s["complete"]
    assert s["drive_iterations"]["count"] == 2
    assert s["feasibility"]["feasible"]
    for dof in ("x", "y", "z"):
        e = s["tracking"][dof]
        assert e["nrmse_displacement"] <= 0.05, (dof, e)
    # the iteration helps: the chosen drive beats the plain controller on acceleration
    hist = s["drive_iterations"]["history"]
    assert hist[s["drive_iterations"]["chosen"]]["mean_nrmse_acceleration"] <= hist[0]["mean_nrmse_acceleration"]


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["elcentro_bare", "elcentro_20t"])
def test_el_centro_full_acceptance_criterion(tmp_path_factory, scenario):
    s, ratios = _summary(tmp_path_factory, scenario)
    for dof in ("x", "y", "z"):
        assert abs(s["tracking"][dof]["pga_ratio"] - 1) <= 0.10, (dof, s["tracking"][dof])
        f, r = ratios[dof]
        assert r.min() >= 0.8 and r.max() <= 1.25, (dof, r.min(), r.max(), f[r.argmax()])
    # the iteration is doing real work: it at least halves the plain controller's
    # acceleration error
    hist = s["drive_iterations"]["history"]
    assert hist[s["drive_iterations"]["chosen"]]["mean_nrmse_acceleration"] <= 0.5 * hist[0]["mean_nrmse_acceleration"]
