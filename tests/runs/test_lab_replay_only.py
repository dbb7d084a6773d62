"""A flexible specimen on replay-only records (issue #23): the worked example's light lab
table (docs/lab-example.md: a 0.84 t platen carrying a 1.9 t two-storey frame, 1200 N of
bearing friction, earthquake records at 204.8 Hz that sit still for their first 3 s, a
valve null that changes from record to record, the accelerometer's 50 Hz conditioner)
exported without its pressure channel: no force, so only the replay path can see the
specimen. Calibrated with defaults and ``--payload none`` (a specimen stands there,
undeclared), El Centro fitted and Corralitos held out.

Slow (about 95 s on 2 cores: the fast suite had grown to 21 min there); the fast suite's
replay-only specimen is ``tests/calibrate/test_payload_mode_paths.py::
test_undeclared_flexible_specimen_found_on_a_replay``."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

import mjcf
from sim.cli import main

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[2]
EX = ROOT / "scenarios" / "lab_example"


def _quake_example():
    spec = importlib.util.spec_from_file_location("lab_quake_export", EX / "make_quake_export.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _map_without_force(folder: Path) -> Path:
    """The example's column map less its pressure column (a recorder that logs no force),
    its table named by path (the map then lives outside the example's folder)."""
    text = (EX / "light_map.toml").read_text()
    text = text[: text.index('[[column]]\nname = "dp"')]
    table = ROOT / "scenarios" / "tables" / "lab_light.toml"
    out = folder / "map_no_force.toml"
    out.write_text(text.replace('table = "lab_light"', f'table = "{table}"'))
    return out


def _first_mode():
    """(frequency Hz, effective modal mass kg, damping ratio) of the frame's first mode."""
    from scipy.linalg import eigh

    pl = mjcf.load_payload("lab_2storey_heavy")
    M, K = np.diag(pl.mass_kg), np.asarray(pl.stiffness_n_m)
    w2, phi = eigh(K, M)
    p = phi[:, 0]
    return float(np.sqrt(w2[0]) / (2 * np.pi)), float((p @ M @ np.ones(len(M))) ** 2 / (p @ M @ p)), pl.damping_ratio


@pytest.fixture(scope="module")
def calibrated(tmp_path_factory):
    folder = tmp_path_factory.mktemp("replay_only")
    mod = _quake_example()
    csvs = mod.make_export(folder / "ex", durations={"elcentro": 10.0, "corralitos": 8.0})
    runs = folder / "runs"
    assert main(["import", *map(str, csvs.values()), "--map", str(_map_without_force(folder)), "--out", str(runs)]) == 0
    cal = folder / "cal"
    args = ["calibrate", str(runs / "elcentro.run.npz"), "--holdout", str(runs / "corralitos.run.npz")]
    assert main([*args, "--payload", "none", "--out", str(cal)]) == 0
    return mod, json.loads((cal / "calibration.json").read_text())


def test_the_first_mode_is_named_on_the_replay_path(calibrated):
    """The frame's first mode (7.50 Hz, 857 kg, 2 %) found as an added modal mass on the
    replay path, its frequency and damping inside their 95 % intervals."""
    _mod, js = calibrated
    assert js["residual_path"] == "replay" and list(js["paths"]) == ["replay"]
    f1, m1, z1 = _first_mode()
    modes = [e for e in js["effects_added"] if e["name"] == "payload_mode"]
    assert modes and all(e["where"] == "dof:x" for e in modes), js["effects_added"]
    e = min(modes, key=lambda e: abs(e["parameters"]["frequency_hz"] - f1))
    p, u = e["parameters"], e["uncertainty"]
    assert abs(p["frequency_hz"] - f1) <= u["frequency_hz"], (p, u)
    assert abs(p["damping_ratio"] - z1) <= u["damping_ratio"], (p, u)
    assert p["mass_kg"] == pytest.approx(m1, rel=0.05), (p, u)


def test_the_friction_is_found_once_and_the_held_out_error_beats_the_baseline(calibrated):
    """The bearing friction found at one place (not split between ``dof:x`` and the
    actuator's class, which push alike on a uni-axial table); the held-out error falls
    and beats the linear ARX baseline fitted on the same record."""
    mod, js = calibrated
    frictions = [e for e in js["effects_added"] if e["name"] in ("coulomb_friction", "power_damping")]
    assert len(frictions) == 1 and frictions[0]["name"] == "coulomb_friction", js["effects_added"]
    assert frictions[0]["parameters"]["force_n"] == pytest.approx(mod.FRICTION_N, rel=0.10)
    assert js["error_after"] < 0.2 * js["error_before"]
    assert js["beats_baseline"] and js["error_after"] < js["baseline"]["holdout_error"]
