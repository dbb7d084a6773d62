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


# ------------------------------------------------------------------ --duration keeps the strong motion
def _record_like(rate=256.0, quiet_s=20.0, strong_s=6.0, tail_s=14.0):
    """A synthetic 'record': quiet precursor, a burst of strong motion, a quiet tail."""
    from sim.scenario.motions import Motion
    from sim.scenario.records import end_correction, integrate

    n = int((quiet_s + strong_s + tail_s) * rate)
    t = np.arange(n) / rate
    rng = np.random.default_rng(3)
    a = 1e-3 * rng.standard_normal(n)
    burst = (t >= quiet_s) & (t < quiet_s + strong_s)
    a[burst] += 3.0 * np.sin(2 * np.pi * 1.5 * t[burst]) * np.sin(np.pi * (t[burst] - quiet_s) / strong_s) ** 2
    v, d = integrate(a, 1 / rate)
    d, v, a, _ = end_correction(t, d, v, a)
    return Motion(t, d, v, a, "synthetic", {"kind": "record"})


def _scenario(rate=256.0, duration_s=None):
    from sim.scenario.files import Scenario

    return Scenario(name="w", table="cgs", payload=None, duration_s=duration_s, pad_to_duration=False,
                    description="", motion={}, controller={}, sample_rate_hz=rate)


def test_window_keeps_the_strong_motion():
    from sim.scenario.files import build_window
    from sim.scenario.records import arias_interval

    m = _record_like()
    t5, t95 = arias_interval(m.a, 1 / 256.0)
    assert 20.0 <= t5 < t95 <= 26.0
    ref, w = build_window(_scenario(), {"x": m}, 10.0)
    assert w["of_record_s"] == pytest.approx(m.duration_s)
    assert w["start_s"] < 20.5 and w["end_s"] > 25.5 and w["end_s"] - w["start_s"] == pytest.approx(10.0)
    assert "Arias" in w["why"]
    x = ref.a[:, 0]
    assert np.abs(x).max() == pytest.approx(np.abs(m.a).max(), rel=1e-6)  # the peak is inside, untapered
    assert abs(ref.d[0, 0]) < 1e-12 and abs(ref.d[-1, 0]) < 1e-12 and abs(ref.v[0, 0]) < 1e-12  # rest to rest
    # consistent: the trapezoid integral of a is v, of v is d (to the step's accuracy)
    h = 1 / 256.0
    v = np.concatenate([[0.0], np.cumsum(0.5 * h * (x[1:] + x[:-1]))])
    assert np.abs(v - ref.v[:, 0]).max() < 1e-3 * np.abs(ref.v[:, 0]).max()
    # a window shorter than the strong motion: the part holding the most intensity
    ref3, w3 = build_window(_scenario(), {"x": m}, 2.0)
    assert 20.0 <= w3["start_s"] and w3["end_s"] <= 26.0 and "most Arias intensity" in w3["why"]


def test_window_of_other_motions_is_their_start():
    from sim.scenario.files import build_window
    from sim.scenario.motions import sine

    m = sine(amplitude=0.01, frequency_hz=1.0, duration_s=20.0, sample_rate_hz=256.0)
    ref, w = build_window(_scenario(), {"x": m}, 5.0)
    assert w["start_s"] == 0.0 and w["end_s"] == 5.0 and "not an earthquake record" in w["why"]
    np.testing.assert_array_equal(ref.d[:, 0], m.d[:len(ref.t)])
    _, whole = build_window(_scenario(), {"x": m}, None)
    assert whole["why"] == "the whole motion"
