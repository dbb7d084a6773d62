"""`fit` and the characterisation calibration as strategies of `shaketable calibrate`.

``calibrate RUN... --strategy scale`` (formerly ``shaketable fit``, still an alias): global
scale factors on the replay of the recorded valve commands, a knob accepted only off its
bounds and when the held-out error falls by the margin. Runs on the uni-axial ``lab``
table (seal friction 0: the friction knob does nothing there, the case where ``fit``
used to add "friction = 4.99 x"); 2 s records, simulated once per module.
"""

from __future__ import annotations

import copy
import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from sim.calibrate import fit as F
from sim.cli import main

LAB = Path(__file__).resolve().parents[2] / "scenarios" / "tables" / "lab.toml"
#: the truth of the planted case: effective bulk modulus 0.75 x lab.toml's 1.0 GPa
SOFT = 0.75


def _make(raw, seed: int, out) -> str:
    """A 2 s, 1-30 Hz random closed-loop run of the lab table described by ``raw``, 0.5 %
    RMS sensor noise on force, acceleration and displacement (seeded)."""
    from mjcf.description import parse_table
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.runfile import write_run
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    tm = build_model(parse_table(raw, src="<truth>"))
    mo = {
        "x": M.white_noise(
            duration_s=2.0, sample_rate_hz=1024.0, band_hz=(1.0, 30.0), seed=(seed, 0), rms_acceleration=2.0
        )
    }
    ref = reference_from_motions(mo, 1024.0, 2.0)
    res = Simulation(tm).run(reference=ref)
    assert res.incomplete_reason is None
    run = build_runfile(res, tm, source="measured", reference=ref)
    rng = np.random.default_rng(seed)
    for ch in ("actuator_force", "table_acceleration", "table_displacement"):
        a = getattr(run, ch)
        a += rng.normal(0, 0.005, a.shape) * np.sqrt(np.mean(a**2, axis=0))
    return str(write_run(Path(out), run))


@pytest.fixture(scope="module")
def lab_runs(tmp_path_factory):
    import mjcf

    out = tmp_path_factory.mktemp("lab_runs")
    raw = copy.deepcopy(mjcf.load_table("lab").raw)
    clean = _make(raw, 1, out / "clean.run.npz")
    raw["fluid"]["bulk_modulus_pa"] = SOFT * raw["fluid"]["bulk_modulus_pa"]
    soft = _make(raw, 2, out / "soft.run.npz")
    return {"clean": clean, "soft": soft}


def test_knob_at_its_bound_is_refused():
    fr = next(c for c in F.CANDIDATES if c.name == "friction")
    assert F.at_bound(fr, 4.994) and F.at_bound(fr, 0.01)  # 'friction = 4.99 x' of (0, 5)
    assert not F.at_bound(fr, 2.0)


def test_scale_adds_nothing_on_a_run_the_model_matches(lab_runs):
    """The flaw `fit` had: on a run the model matches, the friction knob (which does
    nothing on a table without seal friction) was added at 4.99 x. Now nothing is."""
    res = F.calibrate_scale([lab_runs["clean"]], table="lab", effects=["friction", "bulk_modulus"])
    assert res.residual_path == "replay"
    assert res.effects_added == [], res.effects_added
    assert res.error_after == res.error_before < 0.02  # the 0.5 % sensor noise, replayed
    fr = [c for c in res.candidates if c["name"] == "friction"]
    assert fr and not any(c["accepted"] for c in fr) and all(c["reason"] for c in fr)
    assert "last 30 %" in res.holdout_note


def test_scale_recovers_soft_oil_and_proves_it_held_out(lab_runs):
    res = F.calibrate_scale([lab_runs["soft"]], table="lab", effects=["bulk_modulus", "friction"], rounds=1)
    (e,) = res.effects_added
    assert (e["name"], e["where"]) == ("bulk_modulus", "table")
    assert e["parameters"]["scale"] == pytest.approx(SOFT, rel=0.02)
    assert 0 < e["uncertainty"]["scale"] < 0.05
    assert res.error_after <= 0.2 * res.error_before, (res.error_before, res.error_after)


def test_cli_strategy_scale_report_shape_and_fit_alias(lab_runs, tmp_path, capsys):
    """`calibrate --strategy scale` writes calibration.json in the search strategy's
    shape, report.md and the calibrated table (comments kept, the value rewritten and
    tagged); `fit` is an alias that says so."""
    out = tmp_path / "scale"
    argv = ["calibrate", lab_runs["soft"], "--table", "lab", "--strategy", "scale", "--effects", "bulk_modulus"]
    assert main(argv + ["--rounds", "1", "--out", str(out), "--json"]) == 0
    js = json.loads((out / "calibration.json").read_text())
    for k in ("error_before", "error_after", "residual_path", "effects_added", "candidates", "unexplained"):
        assert k in js
    assert js["strategy"] == "scale" and js["residual_path"] == "replay"
    (e,) = js["effects_added"]
    assert set(e) >= {"name", "where", "parameters", "uncertainty"}
    assert (out / "report.md").read_text().startswith("# Calibration of `lab` (strategy: scale")
    text = Path(js["calibrated_table_file"]).read_text()
    line = next(x for x in text.splitlines() if x.startswith("bulk_modulus_pa"))
    assert "calibrated: shaketable calibrate --strategy scale soft.run.npz" in line
    assert tomllib.loads(text)["fluid"]["bulk_modulus_pa"] == pytest.approx(SOFT * 1e9, rel=0.02)
    n_comments = sum(1 for x in LAB.read_text().splitlines() if x.lstrip().startswith("#"))
    assert sum(1 for x in text.splitlines() if x.lstrip().startswith("#")) == n_comments
    capsys.readouterr()
    out2 = tmp_path / "fit"
    assert main(["fit", lab_runs["clean"], "--table", "lab", "--effects", "friction", "--out", str(out2)]) == 0
    cap = capsys.readouterr()
    assert "calibrate RUN --strategy scale" in cap.out
    assert "added nothing" in cap.out
    assert json.loads((out2 / "calibration.json").read_text())["effects_added"] == []


def test_scale_refuses_runs_without_valve_commands(tmp_path, capsys):
    from sim.runs.runfile import RunFile, write_run

    meta = {
        "format": "shaketable-run/1",
        "table": "lab",
        "sample_rate_hz": 1024.0,
        "actuators": ["A"],
        "dofs": ["x"],
        "source": "measured",
    }
    p = tmp_path / "m.run.npz"
    write_run(p, RunFile(t=np.arange(10) / 1024, meta=meta, reference=np.zeros((10, 1))))
    out = tmp_path / "o"
    rc = main(["calibrate", str(p), "--strategy", "scale", "--out", str(out)])
    err = capsys.readouterr().err
    assert rc == 2 and "valve_command" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_characterisation_calibration_in_the_report_shape():
    """`characterize --calibrate` writes calibration.json in the same shape: the values
    it rewrites as effects per class, the oil-column error before and after."""
    import mjcf
    from sim.calibrate.programme import calibration_report

    desc = mjcf.load_table("cgs")
    tgt = {d: 20.0 for d in ("x", "y", "z", "rx", "ry", "rz")}
    cal = {
        "dead_volume_m3": {"lateral": 2e-3},
        "seal_friction_n": {"lateral": 5000.0},
        "linear_targets": tgt,
        "linear_before": {d: 22.0 for d in tgt},
        "linear_after": {d: 20.2 for d in tgt},
        "masses": None,
    }
    js = calibration_report(cal, desc, "x.toml")
    assert js["error_before"] == pytest.approx(0.10) and js["error_after"] == pytest.approx(0.01)
    assert {(e["name"], e["where"]) for e in js["effects_added"]} == {
        ("dead_volume", "class:lateral"),
        ("seal_friction", "class:lateral"),
    }
    for k in ("residual_path", "candidates", "unexplained", "calibrated_table_file"):
        assert k in js
    json.dumps(js, allow_nan=False)
