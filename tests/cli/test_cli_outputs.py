"""The CLI's outputs for a new user (issue #12): run files carry their descriptions,
``--duration`` keeps the strong motion, ``characterize`` writes JSON for every table,
progress lines, the format documentation covers every key the loaders accept."""

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import pytest

from sim import cli

ROOT = Path(__file__).resolve().parents[2]


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
@pytest.mark.parametrize("workers,context", [(1, None), (2, None), (2, "spawn")])
def test_map_jobs_keeps_the_jobs_order(workers, context):
    import functools

    from sim.parallel import map_jobs

    seen = []
    jobs = [7, 1, 5, 3, 0]
    out = map_jobs(
        functools.partial(pow, 3), jobs, workers=workers, progress=lambda d, n: seen.append((d, n)), context=context
    )
    assert out == [3**j for j in jobs]
    assert seen == [(i, len(jobs)) for i in range(1, len(jobs) + 1)]
    assert map_jobs(abs, [], workers=workers) == []


def test_one_pool_helper():
    """No module starts its own process pool: they all go through sim.parallel.map_jobs."""
    bad = [
        str(p.relative_to(ROOT))
        for p in (ROOT / "sim").rglob("*.py")
        if p.name != "parallel.py"
        and any(s in p.read_text() for s in ("ProcessPoolExecutor", ".Pool(", "get_context("))
    ]
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

    return Scenario(
        name="w",
        table="cgs",
        payload=None,
        duration_s=duration_s,
        pad_to_duration=False,
        description="",
        motion={},
        controller={},
        sample_rate_hz=rate,
    )


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
    np.testing.assert_array_equal(ref.d[:, 0], m.d[: len(ref.t)])
    _, whole = build_window(_scenario(), {"x": m}, None)
    assert whole["why"] == "the whole motion"


# ------------------------------------------------------------------ progress
def test_progress_lines_in_a_log_and_a_bar_on_a_terminal():
    import io

    from sim.cli.progress import Progress

    log = io.StringIO()
    p = Progress(stream=log, tty=False, unit="tests")
    p.stage("characterising")
    for i in range(1, 4):
        p.count(i, 3)
    lines = log.getvalue().splitlines()
    assert len(lines) == 4 and lines[0].startswith("  characterising") and lines[-1].startswith("  3/3 tests done")
    term = io.StringIO()
    p = Progress(stream=term, tty=True, unit="tests")
    for i in range(1, 4):
        p.count(i, 3)
    out = term.getvalue()
    assert out.count("\r") == 3 and out.count("\n") == 1 and "[" + "#" * 30 + "] 3/3 tests" in out
    quiet = io.StringIO()
    p = Progress(stream=quiet, enabled=False)
    p.stage("x")
    p.count(1, 1)
    assert quiet.getvalue() == "" and p.count_callback() is None and p.text_callback() is None


def test_no_paper_jargon_in_cli_text():
    """The CLI's messages and help speak of tables and papers, not of the project's seed numbers."""
    bad = [
        f"{p.relative_to(ROOT)}:{i}"
        for p in (ROOT / "sim" / "cli").glob("*.py")
        for i, line in enumerate(p.read_text().splitlines(), 1)
        if re.search("seed 0{2}", line, re.IGNORECASE)
    ]
    assert not bad, bad


# ------------------------------------------------------------------ format documentation
def _documented(page: str) -> set[str]:
    """The keys of a docs page's key tables: the first cell of rows starting with | `key`."""
    keys = set()
    for line in (ROOT / "docs" / page).read_text().splitlines():
        if line.startswith("| `"):
            keys.add(line.split("`")[1])
    return keys


def _asked_keys(monkeypatch, load, names):
    """Every key the description loader asks for (present or defaulted) while loading ``names``."""
    import re

    import mjcf.description as D

    asked = set()
    orig = D._Section.raw

    def raw(self, key, default=...):
        path = re.sub(r"\[\d+\]", "[]", re.sub(r"^actuator_class\.[^.]+", "actuator_class.<name>", self.path))
        if path and path != "actuator_class":  # top-level keys are sections, actuator_class keys class names
            asked.add(f"{path}.{key}")
        return orig(self, key, default)

    monkeypatch.setattr(D._Section, "raw", raw)
    for n in names:
        load(n)
    return asked


def _file_keys(raw: dict, prefix=""):
    """Dotted keys of a parsed TOML, lists of tables as ``name[]``, named sub-tables as ``<name>``."""
    for k, v in raw.items():
        if isinstance(v, dict) and prefix in ("actuator_class.", "controller.parameter_sets."):
            yield from _file_keys(v, f"{prefix}<name>.")
        elif isinstance(v, dict) and not prefix.startswith("published."):
            yield from _file_keys(v, f"{prefix}{k}.")
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for item in v:
                yield from _file_keys(item, f"{prefix}{k}[].")
        else:
            yield f"{prefix}{k}"


def test_table_file_doc_covers_every_key(monkeypatch):
    import dataclasses
    import tomllib

    import mjcf
    from hydraulics import params as HP
    from sim.control.tvc import ControllerGains

    tables = sorted(p.stem for p in (ROOT / "scenarios" / "tables").glob("*.toml"))
    need = _asked_keys(monkeypatch, mjcf.load_table, tables)
    for t in tables:
        need |= set(_file_keys(tomllib.loads((ROOT / "scenarios" / "tables" / f"{t}.toml").read_text())))
    need |= {f"actuator_class.<name>.{k}" if s == "actuator_class" else f"{s}.{k}" for s, k in HP._OPTIONAL}
    need |= {f"actuator_class.<name>.{k}" for k in HP._CLASS_KEYS}
    need |= {f"controller.{f.name}" for f in dataclasses.fields(ControllerGains)}
    missing = sorted(need - _documented("table-file.md"))
    assert not missing, f"docs/table-file.md lacks {missing}"


def test_payload_file_doc_covers_every_key(monkeypatch):
    import mjcf

    payloads = sorted(str(p) for p in (ROOT / "scenarios" / "payloads").glob("*.toml"))
    need = _asked_keys(monkeypatch, mjcf.load_payload, payloads)
    assert {"payload.clamp_frequency_hz", "payload.bending_stiffness_n_m2", "payload.stiffness_n_m"} <= need
    missing = sorted(need - _documented("payload-file.md"))
    assert not missing, f"docs/payload-file.md lacks {missing}"


def test_scenario_file_doc_covers_every_key():
    from sim.scenario import files as F

    accepted = (
        {f"scenario.{k}" for k in F._SCEN_KEYS}
        | {f"motion.{k}" for k in F._EQ_KEYS}
        | {f"motion.<dof>.{k}" for keys in F._MOTION_KEYS.values() for k in keys}
        | {f"iteration.{k}" for k in F._ITERATION_KEYS}
        | {f"output.{k}" for k in F._OUTPUT_KEYS}
    )
    from sim.effects import faults as FA  # [[fault]] entries and [interlock] (docs/faults.md)

    kinds = (FA.PumpTrip, FA.ValveStuck, FA.SupportPressureLoss, FA.SensorLoss)
    accepted |= {"fault[].type", "fault[].where"} | {f"fault[].{k}" for c in kinds for k in (*c.SPEC, *c.OPTIONS)}
    accepted |= {f"interlock.{k}" for k in (*FA.Interlock.SPEC, *FA.Interlock.OPTIONS)}
    doc = _documented("scenario-file.md")
    assert not sorted(accepted - doc), f"docs/scenario-file.md lacks {sorted(accepted - doc)}"
    assert not sorted(doc - accepted), (
        f"docs/scenario-file.md documents keys the loader rejects: {sorted(doc - accepted)}"
    )


# ------------------------------------------------------------------ characterize for every table
def _fake_programme(desc, *, quick=False, workers=None, progress=None, runs_dir=None):
    """Stands in for a paper's programme (minutes of simulation): the summary shape of
    the frf_random programme with two synthetic FRF cases."""
    from sim.papers.uniaxial import rice_cases

    f = np.linspace(0, 100, 201)
    T = 1 / (1 - (f / 60.0) ** 2 + 0.2j * f / 60.0)
    cases = rice_cases()[:2]
    if progress:
        for i in range(len(cases)):
            progress(i + 1, len(cases))
    res = [{"case": c, "f": f, "model": T * (1 + 0.01 * k), "analytical": T} for k, c in enumerate(cases)]
    return {
        "table": desc.name,
        "payload": None,
        "programme": "frf_random",
        "mode": "quick" if quick else "full",
        "oil_column_hz": {"x": 60.0},
        "oil_column_analytical_hz": {"x": 60.0},
        "wall_s": 0.0,
        "sim_s": 1.0,
        "cases": [{"case": c.name, "max_error_0_100": 0.01 * k, "f_max_error_hz": 50.0} for k, c in enumerate(cases)],
        "_report": ["# report", "", "numbers"],
        "_results": res,
    }


def test_characterize_dispatches_on_the_declared_programme(tmp_path, monkeypatch, capsys):
    from sim.papers import programmes as P

    monkeypatch.setitem(P.PROGRAMMES, "frf_random", _fake_programme)
    out = tmp_path / "char"
    assert cli.main(["characterize", "rice", "--quick", "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    written = json.loads((out / "characterization.json").read_text())
    assert printed == written and written["oil_column_hz"] == {"x": 60.0} and written["programme"] == "frf_random"
    assert written["figures"] and all((out / n).is_file() for n in written["figures"])
    report = (out / "report.md").read_text()
    assert report.startswith("# report") and all(f"]({n})" in report for n in written["figures"])
    assert not list(out.rglob("*.pkl"))
    # the same table under another name dispatches alike: the field decides, not the name
    text = (ROOT / "scenarios" / "tables" / "rice.toml").read_text()
    (tmp_path / "mytable.toml").write_text(text)
    assert cli.main(["characterize", str(tmp_path / "mytable.toml"), "--out", str(tmp_path / "c2"), "--json"]) == 0
    assert json.loads((tmp_path / "c2" / "characterization.json").read_text())["programme"] == "frf_random"
    # an undeclared programme is a one-line user error, nothing written
    (tmp_path / "bad.toml").write_text(text.replace('programme = "frf_random"', 'programme = "nonesuch"'))
    capsys.readouterr()
    assert cli.main(["characterize", str(tmp_path / "bad.toml"), "--out", str(tmp_path / "c3")]) == 2
    err = capsys.readouterr().err
    errors = [x for x in err.splitlines() if x.startswith("error:")]
    assert len(errors) == 1 and "programme 'nonesuch' is unknown" in errors[0] and "bad.toml" in errors[0]
    assert "Traceback" not in err
    assert not (tmp_path / "c3").exists()


def test_uniaxial_command_is_gone(capsys):
    with pytest.raises(SystemExit):
        cli.main(["uniaxial", "rice"])
    assert "invalid choice" in capsys.readouterr().err


def test_identification_figures(tmp_path):
    from sim.report.programmes import identification_figures

    t = np.linspace(0, 10, 500)
    res = [
        {"name": n, "measured": {"disp": 0.1 * np.sin(t + k), "force": 1e5 * np.cos(t + k)}}
        for k, n in enumerate(["T1", "T2", "S1"])
    ]
    ident = {"M_e_kg": 1.4e5, "K_e_N_per_m": 1.2e6, "C_e": 4.5e4, "F_mu_N": 2.6e4}
    s = {"identification_sets": {"periodic": {"unconstrained": ident}}, "paper": ident}
    names = identification_figures(res, s, tmp_path)
    assert names == ["force_displacement.png", "identification.png"]
    assert all((tmp_path / n).stat().st_size > 1000 for n in names)
