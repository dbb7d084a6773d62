"""``shaketable replay --closed-loop``: a record's reference through the model's controller,
written as a run file with the model's tracking beside the record's (issue #24 item 4)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sim.cli import main

SECONDS = 2.0


@pytest.fixture(scope="module")
def lab_run(tmp_path_factory):
    """2 s of band-limited white noise (1-15 Hz, 1 m/s^2 RMS) on the lab table, closed
    loop, written as a run file with its reference (the record)."""
    import mjcf
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.runfile import write_run
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    tm = build_model(mjcf.load_table("lab"))
    mo = {
        "x": M.white_noise(duration_s=SECONDS, sample_rate_hz=1024.0, band_hz=(1.0, 15.0), seed=7, rms_acceleration=1.0)
    }
    ref = reference_from_motions(mo, 1024.0, SECONDS)
    res = Simulation(tm).run(reference=ref)
    assert res.incomplete_reason is None
    run = build_runfile(res, tm, source="simulated", reference=ref)
    return write_run(tmp_path_factory.mktemp("cl") / "lab_noise.run.npz", run)


def test_closed_loop_replay_writes_a_run_with_both_trackings(lab_run, tmp_path, capsys, monkeypatch):
    from sim.runs.runfile import read_run

    assert main(["replay", str(lab_run), "--closed-loop", "--out", str(tmp_path)]) == 0
    out = read_run(tmp_path / "lab_noise.closedloop.run.npz")
    src = read_run(lab_run)
    assert out.n_samples == src.n_samples and out.meta["closed_loop_of"] == str(lab_run)
    assert out.table_displacement is not None and out.reference is not None
    summary = json.loads((tmp_path / "replay_summary.json").read_text())
    model, record = summary["tracking"]["model"]["x"], summary["tracking"]["record"]["x"]
    for k in ("nrmse_displacement", "nrmse_acceleration", "pga_ratio"):
        assert np.isfinite(model[k]) and np.isfinite(record[k])
    # the record was made by this very model: run again it tracks as the record did
    assert model["nrmse_displacement"] == pytest.approx(record["nrmse_displacement"], rel=0.02, abs=1e-4)
    assert model["nrmse_acceleration"] == pytest.approx(record["nrmse_acceleration"], rel=0.02, abs=1e-3)
    assert model["pga_ratio"] == pytest.approx(record["pga_ratio"], rel=0.02)
    assert 0 < record["nrmse_displacement"] < 0.5  # a tracking figure, not a zero by construction
    # ... and its motion is the record's
    assert summary["residual_nrmse"]["table_displacement"]["x"] < 0.01
    assert "tracking" in capsys.readouterr().out
    # the bearing-guided table ran on the compiled callback route; the Python loop (the
    # reference, SHAKETABLE_ENGINE=loop) writes the same run file, array for array
    assert summary["engine"] == "callback"
    monkeypatch.setenv("SHAKETABLE_ENGINE", "loop")
    assert main(["replay", str(lab_run), "--closed-loop", "--out", str(tmp_path / "loop")]) == 0
    assert json.loads((tmp_path / "loop" / "replay_summary.json").read_text())["engine"] == "loop"
    with (
        np.load(tmp_path / "lab_noise.closedloop.run.npz") as a,
        np.load(tmp_path / "loop" / "lab_noise.closedloop.run.npz") as b,
    ):
        assert sorted(a.files) == sorted(b.files)
        for k in a.files:
            assert np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f"), k


def test_closed_loop_replay_of_a_run_without_reference_is_one_line(lab_run, tmp_path, capsys):
    from sim.runs.runfile import read_run, write_run

    run = read_run(lab_run)
    run.reference = None
    bare = write_run(tmp_path / "noref.run.npz", run)
    assert main(["replay", str(bare), "--closed-loop", "--out", str(tmp_path / "o")]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error")]
    assert len(err) == 1 and "reference" in err[0], err
    assert not (tmp_path / "o").exists()
