"""``shaketable run`` on its default engine (the coupled step compiled inside MuJoCo's
step, sim.loop.callback) writes the run file the Python loop (the reference,
``--engine loop``) writes, array for array and bit for bit."""

import json
from pathlib import Path

import numpy as np
import pytest

from sim.cli import main

DUR = "0.3"  # s: 308 ticks, 616 physics steps: the bearing, the payload and the controller all act
#: the worked example's white noise on the bearing-guided ``lab`` table with its 2-storey frame
LAB_NOISE = str(Path(__file__).resolve().parents[2] / "scenarios" / "lab_example" / "lab_noise.toml")

#: drive iterations on the callback route: the record's own FRF (the white-noise run
#: would take 40 s of simulation per engine)
ITERATED = """
[scenario]
name = "iterated_20t"
table = "cgs"
payload = "rigid_20t"
duration_s = 0.5
[motion.x]
type = "sine"
amplitude = 0.004
frequency_hz = 3.0
[iteration]
count = 1
frf = "record"
"""


def _arrays(path) -> dict:
    with np.load(path, allow_pickle=False) as z:
        return {k: z[k] for k in z.files}


def _run(tmp_path, capsys, scenario, engine, *extra):
    out = tmp_path / engine
    argv = ["run", scenario, "--out", str(out), "--json", *extra]
    assert main([*argv, "--engine", engine] if engine != "default" else argv) == 0
    summary = json.loads(capsys.readouterr().out)
    return summary, _arrays(summary["run_file"])


def _same_run_file(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for k in a:
        assert a[k].dtype == b[k].dtype and a[k].shape == b[k].shape, k
        assert np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f"), k


@pytest.mark.parametrize(
    "scenario, extra, force_n",
    [
        ("harmonic_bare", (), 1e3),  # the bare table
        ("elcentro_20t", ("--iterations", "0"), 1e3),  # the 20 t rigid block, El Centro's strong motion
        ("frame_3storey", (), 1e3),  # the 3-storey frame
        # bearing-guided platens (slides), whose controller reads the slides' velocity:
        (LAB_NOISE, (), 300.0),  # the small lab table with its 2-storey frame (peak force 0.9 kN)
        ("ucsd_s10", (), 1e5),  # the LHPOST, with its per-step power damping
    ],
)
def test_default_engine_writes_the_loops_run_file_bit_for_bit(tmp_path, capsys, scenario, extra, force_n):
    cb, cb_arrays = _run(tmp_path, capsys, scenario, "default", "--duration", DUR, *extra)
    loop, loop_arrays = _run(tmp_path, capsys, scenario, "loop", "--duration", DUR, *extra)
    assert cb["engine"] == "callback" and loop["engine"] == "loop"
    assert cb["complete"] and cb["duration_s"] == pytest.approx(float(DUR), abs=1e-3)
    assert np.abs(loop_arrays["actuator_force"]).max() > force_n  # a run that does something
    _same_run_file(cb_arrays, loop_arrays)
    assert cb["tracking"] == loop["tracking"] and cb["feasibility"] == loop["feasibility"]


def test_drive_iterations_run_on_the_callback_route_too(tmp_path, capsys):
    path = tmp_path / "iterated.toml"
    path.write_text(ITERATED)
    cb, cb_arrays = _run(tmp_path, capsys, str(path), "callback")
    loop, loop_arrays = _run(tmp_path, capsys, str(path), "loop")
    assert cb["engine"] == "callback" and cb["drive_iterations"]["count"] == 1
    assert cb["drive_iterations"] == loop["drive_iterations"]
    _same_run_file(cb_arrays, loop_arrays)


def test_tables_the_callback_cannot_run_fall_back_to_the_loop(tmp_path, capsys):
    """The Rice table's analog controller (a tick every physics step, a stop at the stroke
    ends) has no compiled tick: the loop runs it. (The bearing-guided UCSD and lab tables
    used to fall back for their platen; they run on the callback now, above.)"""
    s, _ = _run(tmp_path, capsys, "rice_sine", "callback", "--duration", "0.1")
    assert s["engine"] == "loop" and s["complete"]


def test_a_bad_engine_variable_is_one_line_exit_2(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("SHAKETABLE_ENGINE", "fast")
    assert main(["run", "harmonic_bare", "--out", str(tmp_path), "--duration", "0.05"]) == 2
    err = capsys.readouterr().err
    assert "SHAKETABLE_ENGINE" in err and "'callback' or 'loop'" in err and "Traceback" not in err
    assert not (tmp_path / "harmonic_bare.run.npz").exists()


def test_ctrl_c_on_the_callback_route_keeps_the_ticks_done(tmp_path, capsys, monkeypatch):
    """Ctrl-C lands while MuJoCo steps a chunk (512 ticks): the command stops after it
    with the loop's message and exit code, and the run file keeps those ticks, equal to
    the loop's first ticks."""
    import mujoco

    real, calls = mujoco.mj_step, {"n": 0}

    def step(m, d, nstep=1):
        real(m, d, nstep)
        calls["n"] += 1
        if calls["n"] == 2:  # the signal arrived during the second chunk
            raise KeyboardInterrupt

    monkeypatch.setattr(mujoco, "mj_step", step)
    out = tmp_path / "cb"
    rc = main(["run", "harmonic_bare", "--out", str(out), "--duration", "1.5", "--engine", "callback"])
    monkeypatch.setattr(mujoco, "mj_step", real)
    err = capsys.readouterr().err
    assert rc == 130 and "interrupted: kept" in err and "Traceback" not in err
    cut = _arrays(out / "harmonic_bare.run.npz")
    meta = json.loads(str(cut["meta"]))
    assert meta["incomplete_reason"].startswith("interrupted (Ctrl-C) at t = 1.0000 s")
    _, whole = _run(tmp_path, capsys, "harmonic_bare", "loop", "--duration", "1.5")
    assert len(cut["t"]) == 1024 < len(whole["t"])
    for k in ("t", "actuator_force", "table_acceleration", "pressure_a"):
        assert np.array_equal(cut[k], whole[k][:1024]), k
