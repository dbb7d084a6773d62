"""The CLI's outputs for a new user (issue #12): run files carry their descriptions,
``--duration`` keeps the strong motion, ``characterize`` writes JSON for every table,
progress lines, the format documentation covers every key the loaders accept."""

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from sim import cli

ROOT = Path(__file__).resolve().parents[1]


# ------------------------------------------------------------------ run files carry their descriptions
@pytest.fixture(scope="module")
def modified_run(tmp_path_factory):
    """A short UCSD triangle run on a copy of ucsd.toml with twice the platen mass."""
    d = tmp_path_factory.mktemp("carried")
    text = (ROOT / "scenarios" / "tables" / "ucsd.toml").read_text()
    assert "\nmass_kg = 140000.0 " in text
    table = d / "heavy.toml"
    table.write_text(text.replace("\nmass_kg = 140000.0 ", "\nmass_kg = 280000.0 ", 1))
    sc = (ROOT / "scenarios" / "ucsd_t8.toml").read_text().replace('table = "ucsd"', 'table = "heavy.toml"')
    (d / "sc.toml").write_text(sc)
    assert cli.main(["run", str(d / "sc.toml"), "--duration", "0.3", "--out", str(d / "out"), "--json"]) == 0
    return d, table, d / "out" / "ucsd_t8.run.npz"


def test_run_file_carries_the_table_text(modified_run):
    from sim.runs.runfile import payload_of, read_run, table_of

    d, table, path = modified_run
    run = read_run(path)
    assert run.meta["table_description"] == table.read_text()
    assert run.meta["table_sha256"] == hashlib.sha256(table.read_bytes()).hexdigest()
    assert "payload_description" not in run.meta and payload_of(run) is None
    desc = table_of(run)
    assert desc.raw["platen"]["mass_kg"] == 280000.0
    assert table_of(run, "ucsd").raw["platen"]["mass_kg"] == 140000.0  # --table still overrides


def test_replay_uses_the_carried_table(modified_run, tmp_path):
    from sim.calibrate.replay import replay

    d, table, path = modified_run
    table.write_text("not a table any more")  # the file is gone: the run still replays with its own
    carried = replay(str(path))
    stock = replay(str(path), table="ucsd")
    assert carried.residual_nrmse["table_acceleration"]["x"] < 1e-6
    assert stock.residual_nrmse["table_acceleration"]["x"] > 0.05


def test_tampered_description_is_a_user_error(modified_run, tmp_path, capsys):
    from sim.runs.runfile import read_run, write_run

    _, _, path = modified_run
    run = read_run(path)
    run.meta["table_description"] += "\n# edited\n"
    bad = write_run(tmp_path / "bad.run.npz", run)
    rc = cli.main(["replay", str(bad), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "table_sha256" in err and "Traceback" not in err
    assert not (tmp_path / "o" / "bad.replay.run.npz").exists()


# ------------------------------------------------------------------ one process-pool helper
@pytest.mark.parametrize("workers", [1, 2])
def test_map_jobs_keeps_the_jobs_order(workers):
    import functools

    from sim.parallel import map_jobs

    seen = []
    jobs = [7, 1, 5, 3, 0]
    out = map_jobs(functools.partial(pow, 3), jobs, workers=workers, progress=lambda d, n: seen.append((d, n)))
    assert out == [3 ** j for j in jobs]
    assert seen == [(i, len(jobs)) for i in range(1, len(jobs) + 1)]
    assert map_jobs(abs, [], workers=workers) == []


def test_one_pool_helper():
    """No module starts its own process pool: they all go through sim.parallel.map_jobs."""
    bad = [str(p.relative_to(ROOT)) for p in (ROOT / "sim").rglob("*.py")
           if p.name != "parallel.py" and any(s in p.read_text() for s in ("ProcessPoolExecutor", ".Pool(", "get_context("))]
    assert not bad, bad


def test_iteration_frf_is_the_estimation_frf():
    """Drive iteration estimates its FRF with sim.signals.estimation.frf: on bins with input
    power it equals the Welch H1 it used before (scipy welch/csd, Hann, half overlap)."""
    from scipy import signal

    from sim.control.iteration import _welch_frf
    from sim.scenario.motions import white_noise

    x = white_noise(duration_s=20, sample_rate_hz=1024, band_hz=(0.5, 25), seed=(0, 0), rms_acceleration=1.0).d
    b, a = signal.butter(2, 20, fs=1024)
    y = signal.lfilter(b, a, x) + 1e-6 * np.random.default_rng(0).standard_normal(len(x))
    f, H = _welch_frf(x, y, 1024.0, 4096)
    _, pxx = signal.welch(x, fs=1024.0, nperseg=4096)
    _, pxy = signal.csd(x, y, fs=1024.0, nperseg=4096)
    live = pxx > 1e-30
    assert live[(f > 0.2) & (f < 25)].all()
    np.testing.assert_allclose(H[live], pxy[live] / pxx[live], rtol=1e-12, atol=0)
    assert abs(H[np.argmin(abs(f - 20))]) == pytest.approx(1 / np.sqrt(2), rel=0.05)  # the 20 Hz Butterworth
