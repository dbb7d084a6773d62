"""Closing the loop: a 'measured' run with an undeclared effect is replayed, the effect found."""

import copy

import numpy as np
import pytest

import mjcf
from mjcf.description import parse_table
from sim.calibrate import fit as F
from sim.effects import build_model
from sim.loop.simulation import Simulation
from sim.runs.build import build_runfile
from sim.scenario import motions as M
from sim.scenario.reference import reference_from_motions


def _measured_run(modify, seconds=4.0, seed=3):
    """Simulate the CGS table with a modified description; return it as a measured run."""
    desc = mjcf.load_table("cgs")
    raw = copy.deepcopy(desc.raw)
    modify(raw)
    true_desc = parse_table(raw, src="<truth>")
    tm = build_model(true_desc)
    rate = 1024.0
    mo = {
        "x": M.white_noise(
            duration_s=seconds, sample_rate_hz=rate, band_hz=(0.5, 30.0), seed=(seed, 0), rms_acceleration=1.0
        ),
        "z": M.white_noise(
            duration_s=seconds, sample_rate_hz=rate, band_hz=(0.5, 30.0), seed=(seed, 2), rms_acceleration=0.8
        ),
    }
    ref = reference_from_motions(mo, rate, seconds)
    res = Simulation(tm).run(reference=ref)
    run = build_runfile(res, tm, source="measured", reference=ref)
    rng = np.random.default_rng(seed)
    for ch in ("actuator_force", "table_acceleration"):
        arr = getattr(run, ch)
        arr += rng.normal(0, 0.005, arr.shape) * np.sqrt(np.mean(arr**2, axis=0))  # 0.5 % sensor noise
    return run, desc


@pytest.mark.slow
def test_fit_finds_undeclared_soft_oil(tmp_path):
    run, desc = _measured_run(lambda raw: raw["fluid"].__setitem__("bulk_modulus_pa", 0.75e9))
    cands = tuple(c for c in F.CANDIDATES if c.name in ("bulk_modulus", "friction", "valve_delay"))
    rep = F.fit(run, desc.raw, None, candidates=cands, rounds=2)
    assert rep["effects_added"], rep
    first = rep["effects_added"][0]
    assert first["effect"] == "bulk_modulus"
    assert abs(first["value"] - 0.75) < 0.02, first
    assert rep["final_residual"] < 0.25 * rep["baseline_residual"], (rep["baseline_residual"], rep["final_residual"])


@pytest.mark.slow
def test_fit_finds_undeclared_valve_delay():
    run, desc = _measured_run(lambda raw: raw["servovalve"].__setitem__("delay_s", 0.002), seed=5)
    cands = tuple(c for c in F.CANDIDATES if c.name in ("bulk_modulus", "valve_delay", "added_mass"))
    rep = F.fit(run, desc.raw, None, candidates=cands, rounds=1)
    assert rep["effects_added"] and rep["effects_added"][0]["effect"] == "valve_delay"
    # the delay is realised in whole physics steps (1/2048 s)
    assert abs(rep["effects_added"][0]["value"] - 0.002) <= 0.5 / 2048 + 1e-4
    assert rep["final_residual"] < 0.25 * rep["baseline_residual"]


def test_fit_cli_refuses_a_run_without_valve_commands(tmp_path, capsys):
    from sim.cli import main
    from sim.runs.runfile import RunFile, write_run

    t = np.arange(10) / 1024
    meta = {
        "format": "shaketable-run/1",
        "table": "cgs",
        "sample_rate_hz": 1024.0,
        "actuators": list(mjcf.load_table("cgs").actuator_names),
        "dofs": ["x", "y", "z", "rx", "ry", "rz"],
        "source": "measured",
    }
    p = tmp_path / "m.run.npz"
    write_run(p, RunFile(t=t, meta=meta, reference=np.zeros((10, 6))))
    rc = main(["fit", str(p), "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and "valve_command" in err and len(err.strip().splitlines()) == 1
