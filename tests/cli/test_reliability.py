"""Reliability: divergence of the loop (each kind forced), Ctrl-C in a run and in a
characterisation (what is kept, what is not), a reader that went away (a broken pipe),
a viewer that never answers, sizes refused before allocating, and bit-identical
reruns of the same scenario and seed."""

from __future__ import annotations

import dataclasses
import io
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import mujoco
import numpy as np
import pytest

import mjcf
from sim.cli import main
from sim.effects import build_model
from sim.loop import callback as CB
from sim.loop import simulation as S
from sim.runs.runfile import FORMAT, RunFile, read_run, write_run
from sim.scenario import motions as M

ROOT = Path(__file__).resolve().parents[2]

SINE = """[scenario]
name = "sine"
table = "ucsd"
duration_s = {dur}

[motion.x]
type = "sine"
amplitude = 0.002
frequency_hz = 2.0
"""

NOISE = """[scenario]
name = "noise"
table = "ucsd"
duration_s = 4.0

[motion.x]
type = "white_noise"
band_hz = [0.5, 20.0]
rms_acceleration = 0.3
seed = 7
"""


@pytest.fixture(scope="module")
def sim():
    return S.Simulation(build_model(mjcf.load_table("ucsd")))


@pytest.fixture(scope="module")
def ref(sim):
    rate = sim.gains.rate_hz
    mo = {"x": M.sine(amplitude=0.001, frequency_hz=2.0, duration_s=0.05, sample_rate_hz=rate)}
    return S.reference_from_motions(mo, rate, 0.05)


def _diverged(reason: str, *fragments):
    assert reason is not None
    assert reason.startswith("simulation diverged at t = "), reason
    assert "likely cause" in reason and "\n" not in reason
    for f in fragments:
        assert f in reason, (f, reason)


# ---------------------------------------------------------------- divergence, each kind
def test_nan_in_hydraulics(sim, ref):
    sim.reset()
    sim.hs.state.p_a[:] = np.nan
    res = sim.run(reference=ref)
    _diverged(res.incomplete_reason, "hydraulic state is not finite", "chamber a")
    assert len(res.t) == 1 and not res.interrupted


def test_nan_in_mechanics_reported_not_printed(sim, ref, capfd):
    sim.reset()
    sim.d.qvel[:] = np.nan
    res = sim.run(reference=ref)
    _diverged(res.incomplete_reason, "not finite")
    out = capfd.readouterr()
    assert "WARNING" not in out.out and "WARNING" not in out.err  # MuJoCo's own print is kept off stdout
    assert not (Path.cwd() / "MUJOCO_LOG.TXT").exists() or "MUJOCO_LOG" in os.environ.get("KEEP", "")


def test_mujoco_warning(sim, ref):
    sim.reset()
    res = sim.run(reference=ref)
    assert res.incomplete_reason is None
    sim.d.warning[mujoco.mjtWarning.mjWARN_BADQACC].number += 1  # MuJoCo reset the state after a bad qacc
    _diverged(sim._check(0.05, 0.0), "mjWARN_BADQACC", "accelerations were not finite")


def test_pressure_above_relief_and_below_vapour(sim, ref):
    hp = sim.hp
    try:
        sim.reset()
        sim.hp = dataclasses.replace(hp, relief_pressure_pa=1e6)  # the chambers sit near 10 MPa
        _diverged(sim.run(reference=ref).incomplete_reason, "above the relief pressure 1 MPa")
        sim.reset()
        sim.hp = dataclasses.replace(hp, vapour_pressure_pa=30e6)
        _diverged(sim.run(reference=ref).incomplete_reason, "below the vapour pressure 30 MPa")
    finally:
        sim.hp = hp


def test_loop_gap(sim, ref, monkeypatch):
    sim.reset()
    monkeypatch.setattr(sim, "loop_gap", lambda: 2e-3)
    _diverged(sim.run(reference=ref).incomplete_reason, "swivel opened by 2 mm", "loop closure failed")


#: the Python loop, whose gap check these tests make misbehave (the ucsd table's closed
#: loop now runs on the callback route by default, which checks its gap in compiled code;
#: its divergence and Ctrl-C are tested in tests/loop/test_engine.py)
LOOP = ["--engine", "loop"]


def _fail_after(monkeypatch, calls: int, what):
    """Make the loop's gap check misbehave from its ``calls``-th call on."""
    n = {"k": 0}
    real = S.Simulation.loop_gap

    def gap(self):
        n["k"] += 1
        if n["k"] >= calls:
            if what == "interrupt":
                raise KeyboardInterrupt
            return 5e-3
        return real(self)

    monkeypatch.setattr(S.Simulation, "loop_gap", gap)


def test_run_command_keeps_a_diverged_run(tmp_path, capsys, monkeypatch):
    scen = tmp_path / "sine.toml"
    scen.write_text(SINE.format(dur=0.5))
    _fail_after(monkeypatch, 6, "gap")
    rc = main(["run", str(scen), "--out", str(tmp_path / "out"), *LOOP])
    err = capsys.readouterr().err
    assert rc == 3
    assert "simulation diverged at t = 0.0391 s" in err and "kept 0.040 s" in err and "marked incomplete" in err
    run = read_run(tmp_path / "out" / "sine.run.npz")
    assert run.incomplete and "swivel opened by 5 mm" in run.incomplete_reason and run.n_samples == 41
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["complete"] is False and not summary["interrupted"]


# ---------------------------------------------------------------- Ctrl-C
def test_ctrl_c_in_run_keeps_what_was_computed(tmp_path, capsys, monkeypatch):
    scen = tmp_path / "sine.toml"
    scen.write_text(SINE.format(dur=0.5))
    _fail_after(monkeypatch, 4, "interrupt")
    rc = main(["run", str(scen), "--out", str(tmp_path / "out"), "--rrd", str(tmp_path / "out" / "r.rrd"), *LOOP])
    err = capsys.readouterr().err
    assert rc == 130 and "interrupted: kept" in err and "marked incomplete" in err
    run = read_run(tmp_path / "out" / "sine.run.npz")
    assert run.incomplete and run.incomplete_reason.startswith("interrupted (Ctrl-C) at t = ")
    assert run.n_samples == 25  # checks after ticks 0, 8, 16, 24: the 4th was interrupted, tick 24 complete
    assert np.all(np.isfinite(run.table_acceleration)) and np.all(np.isfinite(run.pressure_a))
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["sine.run.npz", "summary.json"]


def _children(pid: int) -> list[int]:
    try:
        return [
            int(c)
            for t in os.listdir(f"/proc/{pid}/task")
            for c in open(f"/proc/{pid}/task/{t}/children").read().split()
        ]
    except OSError:
        return []


def _alive(pid: int) -> bool:
    try:
        state = open(f"/proc/{pid}/stat").read().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _sigint_after(argv, cwd, wait_for: str, workers: int = 0):
    """Start ``python -m sim ARGV``; once ``wait_for`` appears on its stderr and it has
    ``workers`` child processes, send SIGINT. Every wait is on an event (the deadline only
    guards against a hang). Returns the exit code, the stderr before and after the
    signal, the child pids at the signal, the command's own pace (seconds from its first
    stderr line to ``wait_for``) and the seconds from the signal to its exit."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen(
        [sys.executable, "-m", "sim", *argv],
        cwd=cwd,
        env=env,
        stderr=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    seen, first = "", None
    deadline = time.time() + 240
    while wait_for not in seen and time.time() < deadline:
        line = p.stderr.readline()
        if not line:
            break
        first = first or time.time()
        seen += line
    assert wait_for in seen, seen
    pace = time.time() - first
    while len(_children(p.pid)) < workers and time.time() < deadline and p.poll() is None:
        time.sleep(0.1)
    kids = _children(p.pid)
    assert len(kids) >= workers, "the workers never started"
    t0 = time.time()
    p.send_signal(signal.SIGINT)
    after = p.stderr.read()
    rc = p.wait(timeout=120)
    return SimpleNamespace(rc=rc, before=seen, after=after, kids=kids, pace_s=pace, stop_s=time.time() - t0)


def _gone(pids, timeout_s: float = 60.0) -> bool:
    """Whether every process in ``pids`` has ended (waits for it, at most ``timeout_s``)."""
    deadline = time.time() + timeout_s
    while any(_alive(k) for k in pids) and time.time() < deadline:
        time.sleep(0.05)
    return not any(_alive(k) for k in pids)


#: the simulated time on the loop's progress bar ("...  12.3 %  t =    1.23 s")
_BAR_TIME = re.compile(rb"%  t = +([0-9.]+) s")


@pytest.mark.slow
def test_sigint_during_run(tmp_path):
    """Ctrl-C at a terminal once the loop runs (its progress bar is on the screen)."""
    import pty

    scen = tmp_path / "sine.toml"
    scen.write_text(SINE.format(dur=60.0))
    out = tmp_path / "out"
    master, slave = pty.openpty()  # stderr a terminal: the loop draws its progress bar
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen(
        [sys.executable, "-m", "sim", "run", str(scen), "--out", str(out)],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=slave,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    os.close(slave)
    seen = b""
    deadline = time.time() + 240  # only a guard against a hang: the waits below are on the bar
    # the loop is under way once its bar has moved: two different simulated times drawn
    while len(set(_BAR_TIME.findall(seen))) < 2 and time.time() < deadline and p.poll() is None:
        try:
            seen += os.read(master, 4096)
        except OSError:
            break
    drawn = [float(t) for t in _BAR_TIME.findall(seen)]
    assert len(set(drawn)) >= 2, seen
    p.send_signal(signal.SIGINT)
    rc = p.wait(timeout=120)
    while True:
        try:
            chunk = os.read(master, 4096)
        except OSError:
            break
        if not chunk:
            break
        seen += chunk
    os.close(master)
    err = seen.decode("utf-8", "replace")
    assert rc == 130, err
    assert "Traceback" not in err and "interrupted: kept" in err
    assert sorted(p.name for p in out.iterdir()) == ["sine.run.npz", "summary.json"]  # no temporary file left
    run = read_run(out / "sine.run.npz")
    assert run.incomplete and "interrupted" in run.incomplete_reason and 1 < run.n_samples < 60 * 1024
    # it kept what it had computed: at least up to the last time its bar showed before the signal
    assert run.t[-1] >= max(drawn) - 0.01


@pytest.mark.slow
def test_sigint_during_characterization(tmp_path):
    """Ctrl-C while two workers run the programme (its first test done, the others under
    way): exit 130, no traceback, the programme stops (it does not run to its end and
    writes no results), no temporary file, no worker left running."""
    out = tmp_path / "char"
    r = _sigint_after(
        ["characterize", "ucsd", "--quick", "--workers", "2", "--out", str(out)], tmp_path, " tests done", workers=2
    )
    err = r.before + r.after
    assert r.rc == 130, err
    done, total = map(int, re.findall(r"(\d+)/(\d+) tests done", r.before)[-1])
    assert done < total, "the programme ended before the signal: nothing was interrupted"
    assert "Traceback" not in err and "KeyboardInterrupt" not in err and "interrupted" in err
    assert not re.search(rf"\b{total}/{total} tests done", r.after), "the programme ran to its end after Ctrl-C"
    # the workers are stopped, not waited for: the command ends sooner than it took to
    # finish its first test (on this machine, at this load), with tests still to run
    assert r.stop_s < r.pace_s, (r.stop_s, r.pace_s)
    assert not (out / "characterization.json").exists() and not (out / "report.md").exists()
    assert not any(p.name.endswith(".tmp") or p.name.startswith(".") for p in tmp_path.rglob("*"))
    assert _gone(r.kids), "worker processes left running"


# ---------------------------------------------------------------- a reader that went away
class _ClosedPipe(io.TextIOBase):
    def write(self, s):
        raise BrokenPipeError(32, "Broken pipe")

    def fileno(self):
        raise io.UnsupportedOperation("no descriptor")


def test_broken_pipe_in_process(monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdout", _ClosedPipe())
    rc = main(["model", "ucsd", "--json"])
    assert rc == 141 and "Traceback" not in capsys.readouterr().err


def test_broken_pipe_real(tmp_path):
    """``shaketable model ucsd --json | head -0``: the reader is gone before the output."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r, w = os.pipe()
    os.close(r)
    p = subprocess.run(
        [sys.executable, "-m", "sim", "model", "ucsd", "--json"],
        cwd=tmp_path,
        env=env,
        stdout=w,
        stderr=subprocess.PIPE,
        text=True,
        timeout=120,
    )
    os.close(w)
    assert p.returncode == 141 and p.stderr == "", p.stderr


# ---------------------------------------------------------------- a viewer that never answers
def _tiny_run(path: Path) -> Path:
    n, fs = 64, 1024.0
    t = np.arange(n) / fs
    z = np.zeros((n, 6))
    meta = {
        "format": FORMAT,
        "table": "ucsd",
        "sample_rate_hz": fs,
        "actuators": ["E", "W"],
        "dofs": ["x", "y", "z", "rx", "ry", "rz"],
        "source": "measured",
    }
    return write_run(path, RunFile(t=t, meta=meta, valve_command=np.zeros((n, 2)), table_displacement=z))


def test_connect_gives_up_after_timeout(tmp_path, capsys):
    import socket

    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()  # nothing listens there
    run = _tiny_run(tmp_path / "t.run.npz")
    t0 = time.time()
    rc = main(["view", str(run), "--connect", f"rerun+http://127.0.0.1:{port}/proxy", "--timeout", "2"])
    err = capsys.readouterr().err
    assert rc == 2 and "did not take the recording within 2 s" in err and err.count("\n") == 1
    assert time.time() - t0 < 30
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.run.npz"]


# ---------------------------------------------------------------- sizes refused before allocating
def test_huge_duration_refused_even_with_short_window(tmp_path, capsys):
    scen = tmp_path / "long.toml"
    scen.write_text(SINE.format(dur="1e7"))
    rc = main(["run", str(scen), "--duration", "5", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 2 and "'scenario.duration_s' = 1e+07 s" in err and "maximum" in err and err.count("\n") == 1


def test_huge_triangle_refused():
    from sim.errors import MotionError

    with pytest.raises(MotionError, match="maximum"):
        M.triangle(peak_displacement=0.1, peak_velocity=0.1, n_cycles=1e9, sample_rate_hz=1024.0)


# ---------------------------------------------------------------- reproducibility
def test_same_scenario_and_seed_give_identical_run_files(tmp_path, capsys):
    scen = tmp_path / "noise.toml"
    scen.write_text(NOISE)
    runs = []
    for k in range(2):
        assert main(["run", str(scen), "--duration", "0.25", "--out", str(tmp_path / f"o{k}"), "--json"]) == 0
        runs.append(read_run(tmp_path / f"o{k}" / "noise.run.npz"))
    capsys.readouterr()
    a, b = runs
    assert a.meta == b.meta
    assert not any("wall" in k or "time" in k.lower() or "date" in k for k in a.meta)  # nothing of the clock
    for name in ("t",) + tuple(c for c in a.present_channels()):
        x, y = getattr(a, name), getattr(b, name)
        assert x.tobytes() == y.tobytes(), name  # bit-identical
    assert a.extras.keys() == b.extras.keys()
    for k in a.extras:
        assert np.array_equal(a.extras[k], b.extras[k], equal_nan=True), k
    assert np.std(a.table_acceleration[:, 0]) > 0  # the noise moved the table


# ---------------------------------------------------------------- strict JSON everywhere
def test_replay_summary_is_strict_json(tmp_path, capsys):
    """A replay of a run whose channels are constant has NaN residuals: null in the file."""
    run = _tiny_run(tmp_path / "t.run.npz")
    assert main(["replay", str(run), "--out", str(tmp_path / "out"), "--json"]) == 0
    printed = capsys.readouterr().out

    def refuse(name):
        raise AssertionError(f"bare {name} in JSON")

    for text in (printed, (tmp_path / "out" / "replay_summary.json").read_text()):
        doc = json.loads(text, parse_constant=refuse)
        assert doc["residual_nrmse"]["table_displacement"]["x"] is None  # 0/0: no motion to compare


def test_atomic_writers_leave_old_file_on_failure(tmp_path):
    from sim.runs.files import save_figure_atomic, write_json_atomic, write_text_atomic

    target = tmp_path / "a.json"
    write_json_atomic(target, {"x": float("nan"), "y": [1.0, float("inf")]})
    assert json.loads(target.read_text()) == {"x": None, "y": [1.0, None]}

    class Boom:
        def savefig(self, fh, **kw):
            fh.write(b"half a png")
            raise KeyboardInterrupt

    (tmp_path / "f.png").write_bytes(b"the good figure")
    with pytest.raises(KeyboardInterrupt):
        save_figure_atomic(Boom(), tmp_path / "f.png", dpi=90)
    assert (tmp_path / "f.png").read_bytes() == b"the good figure"
    write_text_atomic(tmp_path / "r.md", "report\n")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.json", "f.png", "r.md"]  # no temporary left


def test_ctrl_c_in_drive_iteration_identification_keeps_nothing(tmp_path, capsys, monkeypatch):
    """Ctrl-C in the white-noise run that identifies the FRF: that run is not the
    scenario's, so nothing is written (and no traceback)."""
    scen = tmp_path / "sine.toml"
    scen.write_text(SINE.format(dur=0.5) + "\n[iteration]\ncount = 1\n")
    _fail_after(monkeypatch, 3, "interrupt")
    rc = main(["run", str(scen), "--out", str(tmp_path / "out"), *LOOP])
    err = capsys.readouterr().err
    assert rc == 130 and "interrupted" in err and "Traceback" not in err
    assert list((tmp_path / "out").iterdir()) == []


# ---------------------------------------------------------------- Ctrl-C in a calibration and a sweep
def _interrupt_when(argv, cwd, ready, timeout_s: float = 300.0):
    """Start ``python -m sim ARGV`` (stdout and stderr together); once ``ready(text so
    far)`` is true, send SIGINT. Returns the exit code, the whole output, whether the
    process was still running when the signal went, its pace (seconds from its start to
    ``ready``) and the seconds from the signal to its exit. ``timeout_s`` only guards
    against a hang."""
    import threading

    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen(
        [sys.executable, "-u", "-m", "sim", *argv],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(iter(p.stdout.readline, "")), daemon=True)
    reader.start()
    start = time.time()
    deadline = start + timeout_s
    while not ready("".join(lines)) and p.poll() is None and time.time() < deadline:
        time.sleep(0.05)
    running = p.poll() is None
    t0 = time.time()
    p.send_signal(signal.SIGINT)
    rc = p.wait(timeout=120)
    stop = time.time() - t0
    reader.join(timeout=10)
    return SimpleNamespace(rc=rc, text="".join(lines), running=running, pace_s=t0 - start, stop_s=stop)


def _no_partial_files(folder: Path) -> list[Path]:
    """Every file under ``folder``; none a temporary (the atomic writers' ``.*.tmp``)."""
    files = [p for p in folder.rglob("*") if p.is_file()]
    assert not [p for p in files if p.name.startswith(".") or p.name.endswith((".tmp", ".part"))], files
    return files


@pytest.fixture(scope="module")
def ucsd_run_files(tmp_path_factory):
    """Two short simulated UCSD runs (a sine and a triangle) to calibrate against."""
    out = tmp_path_factory.mktemp("cal_runs")
    for name in ("ucsd_s10", "ucsd_t8"):
        assert main(["run", name, "--duration", "2.0", "--out", str(out), "--json"]) == 0
    return [str(out / "ucsd_s10.run.npz"), str(out / "ucsd_t8.run.npz")]


@pytest.mark.slow  # ~30 s on a loaded 2-core machine: a calibration's start-up
def test_sigint_during_calibration_leaves_no_partial_output(tmp_path, ucsd_run_files, capsys):
    """Ctrl-C once the calibration search is under way (its first candidate printed):
    exit 130, one line, no traceback; the outputs are written at the end, each
    atomically: whichever exist are whole (strict JSON, TOML that loads), no temporary."""
    out = tmp_path / "cal"
    r = _interrupt_when(["calibrate", *ucsd_run_files, "--out", str(out)], tmp_path, lambda s: "explains" in s)
    assert r.running, "the calibration ended before the signal: nothing was interrupted"
    assert r.rc == 130, r.text
    assert "Traceback" not in r.text and "KeyboardInterrupt" not in r.text and "interrupted" in r.text
    assert r.stop_s < r.pace_s, (r.stop_s, r.pace_s)  # it stops, sooner than it took to get going
    import tomllib

    files = _no_partial_files(tmp_path)
    for p in files:
        if p.suffix == ".json":
            json.loads(p.read_text(), parse_constant=lambda c: pytest.fail(c))
        elif p.suffix == ".toml":
            assert tomllib.loads(p.read_text())["table"]["name"] == "ucsd"
    assert not (out / "report.md").exists() or (out / "report.md").read_text().endswith("\n")


@pytest.mark.slow  # ~30 s on a loaded 2-core machine: six short runs of the analog uni-axial loop
def test_sigint_during_sweep_keeps_complete_cases_only(tmp_path, capsys):
    """Ctrl-C while a sweep runs its cases: the sweep stops (the case under way is not
    written as a result, the cases after it are not run), every case file kept is whole
    JSON, no results table or report is written, no temporary is left; a second sweep
    resumes and completes."""
    (tmp_path / "rice.toml").write_text(
        '[scenario]\nname = "rice_short"\ntable = "rice"\nduration_s = 0.6\n'
        '[motion.x]\ntype = "sine"\namplitude = 0.005\nfrequency_hz = 2.0\n'
        "[output]\nsample_rate_hz = 4000.0\n"
    )
    (tmp_path / "sw.toml").write_text(
        '[sweep]\nname = "interrupt"\nscenario = "rice.toml"\niterations = 0\nmode = "grid"\ntask = 1\n'
        '[[vary]]\nname = "bulk_modulus_pa"\nkey = "table.fluid.bulk_modulus_pa"\n'
        "values = [4.0e8, 4.5e8, 5.0e8, 5.5e8, 6.0e8, 6.5e8]\n"
    )
    out = tmp_path / "out"
    r = _interrupt_when(
        ["sweep", str(tmp_path / "sw.toml"), "--out", str(out), "--workers", "1"],
        tmp_path,
        # the first case written: five are left to run when the signal goes (a fixed delay
        # after the start raced a fast machine, which finished all six first); `task = 1`
        # makes each case its own task, so a case file is written as soon as it finishes
        lambda s: (out / "cases" / "00000.json").exists(),
    )
    assert r.running, "the sweep ended before the signal: nothing was interrupted"
    assert r.rc == 130, r.text
    assert "Traceback" not in r.text and "KeyboardInterrupt" not in r.text and "interrupted" in r.text
    assert r.stop_s < r.pace_s, (r.stop_s, r.pace_s)  # it stops, sooner than it took to write one case
    files = _no_partial_files(out)
    cases = sorted((out / "cases").glob("*.json"))
    assert len(cases) < 6, files
    for c in cases:
        row = json.loads(c.read_text(), parse_constant=lambda x: pytest.fail(x))
        assert row["complete"] is True and row["error"] == "" and row["duration_s"] == pytest.approx(0.6, abs=1e-3)
    assert not (out / "results.csv").exists() and not (out / "sweep.json").exists() and not (out / "report.md").exists()
    assert main(["sweep", str(tmp_path / "sw.toml"), "--out", str(out), "--workers", "1"]) == 0
    table = (out / "results.csv").read_text().splitlines()
    assert len(table) == 7  # the header and the six cases
    assert "interrupted" not in "\n".join(table)


def test_ctrl_c_in_a_sweep_case_stops_the_sweep(tmp_path, capsys, monkeypatch):
    """Ctrl-C inside a case's simulation (a loop that keeps the part it computed, for
    ``run``): the sweep does not book that part as the case's result and go on; it stops,
    writes no case, no table (deterministic: the interrupt is raised from the loop)."""
    (tmp_path / "sine.toml").write_text(SINE.format(dur=0.2))
    (tmp_path / "sw.toml").write_text(
        '[sweep]\nname = "stop"\nscenario = "sine.toml"\niterations = 0\nmode = "grid"\ntask = 1\n'
        '[[vary]]\nname = "bulk_modulus_pa"\nkey = "table.fluid.bulk_modulus_pa"\nvalues = [0.8e9, 1.0e9, 1.2e9]\n'
    )
    n, real = {"k": 0}, S.Simulation.loop_gap

    def once(self):  # one Ctrl-C, in the first case's loop (26 gap checks a case)
        n["k"] += 1
        if n["k"] == 20:
            raise KeyboardInterrupt
        return real(self)

    monkeypatch.setattr(S.Simulation, "loop_gap", once)
    # the cases on the Python loop, whose partial run is what must not be booked: the
    # callback (and so the batch) refuses them, as it refuses a table it cannot run
    monkeypatch.setattr(CB, "accepts", lambda sim, open_loop=False: "refused by the test")
    out = tmp_path / "out"
    rc = main(["sweep", str(tmp_path / "sw.toml"), "--out", str(out), "--workers", "1"])
    err = capsys.readouterr().err
    assert rc == 130 and "interrupted" in err and "Traceback" not in err
    assert list((out / "cases").iterdir()) == [] and not (out / "results.csv").exists()
