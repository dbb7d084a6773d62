"""Earthquake tracking on the model (slow: full El Centro runs with drive iteration)."""

import json

import numpy as np
import pytest

from sim.cli import main


def _run(tmp_path, capsys, scenario):
    rc = main(["run", scenario, "--out", str(tmp_path), "--json"])
    out = capsys.readouterr().out
    assert rc == 0
    return json.loads(out)


@pytest.mark.slow
@pytest.mark.parametrize("scenario", ["elcentro_bare", "elcentro_20t"])
def test_el_centro_80_percent_tracks(tmp_path, capsys, scenario):
    s = _run(tmp_path, capsys, scenario)
    assert s["complete"]
    assert s["drive_iterations"]["count"] == 2
    for dof in ("x", "y", "z"):
        e = s["tracking"][dof]
        assert e["nrmse_displacement"] <= 0.05, (dof, e)
        assert abs(e["pga_ratio"] - 1) <= 0.10, (dof, e)
    # 5 %-damped spectrum of the achieved acceleration within 0.8-1.25 of the reference's
    # from 0.5 Hz up to 12 Hz on every axis, and up to 20 Hz on x and z. On y the band
    # 13-20 Hz (lateral oil column, 16.5 Hz in the model) reaches 1.3: content there is
    # incoherent with the reference (coherence < 0.1) and not removed by drive iteration;
    # the issue notes give the figures.
    from sim.metrics import spectrum_ratio
    from sim.runfile import read_run

    run = read_run(s["run_file"])
    for i, dof in enumerate(("x", "y", "z")):
        f, r = spectrum_ratio(run.table_acceleration[:, i],
                              np.gradient(np.gradient(run.reference[:, i], run.dt), run.dt), run.dt)
        top = 20.0 if dof in ("x", "z") else 12.0
        band = f <= top
        assert r[band].min() >= 0.8 and r[band].max() <= 1.25, (dof, f[band][np.argmax(r[band])], r[band].max())
    # the plain controller (no iteration) is reported too
    plain = s["drive_iterations"]["tracking_plain_controller"]
    assert set(plain) == {"x", "y", "z"}
