"""A specimen declared rigid that is flexible, found on the replay path: the lab table
(uni-axial, 1024 Hz) carrying a 1.5 t block declared rigid whose truth has 60 % of its
mass on a 6 Hz, 5 % clamping mode along x (``clamp_mass_fraction``: mjcf.builder's own
model of it, not the candidate's effect), 1-30 Hz random runs measured through the
built-in recorder model; calibrated with only ``payload_mode`` offered, against the
declared rigid block: the mode is named at ``dof:x``, its frequency, damping and modal
mass inside their 95 % intervals, the held-out error falls. Clean runs (the block rigid)
with the candidate offered add nothing."""

from __future__ import annotations

from pathlib import Path

import pytest

from sim.calibrate import search as S

ROOT = Path(__file__).resolve().parents[2]

SECONDS = 3.0
BLOCK = """[payload]
type = "rigid"
name = "block_1500"
description = "1.5 t block (test)"
source = "assumed: a test specimen"
mass_kg = 1500.0
com_m = [0.0, 0.0, 0.3]
inertia_kg_m2 = [200.0, 200.0, 300.0]
footprint_m = [1.0, 1.0]
height_m = 0.6
"""
#: the truth: 60 % of the block on a 6 Hz, 5 % mode (the clamp moves along x, y, z alike)
FLEXIBLE = BLOCK + "clamp_frequency_hz = 6.0\nclamp_damping_ratio = 0.05\nclamp_mass_fraction = 0.6\n"


def _runs(folder, payload_text: str, seeds=(1, 2, 3)) -> list[str]:
    """1-30 Hz random closed-loop runs of the lab table with the payload, measured
    through the built-in recorder model (seeded)."""
    import tomllib

    import mjcf
    from mjcf.description import parse_payload
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.measure import load_sensors, measure_run
    from sim.runs.runfile import write_run
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    tm = build_model(mjcf.load_table("lab"), parse_payload(tomllib.loads(payload_text), src="<truth>"))
    paths = []
    for seed in seeds:
        mo = {
            "x": M.white_noise(
                duration_s=SECONDS, sample_rate_hz=1024.0, band_hz=(1.0, 30.0), seed=(seed, 0), rms_acceleration=1.5
            )
        }
        ref = reference_from_motions(mo, 1024.0, SECONDS)
        res = Simulation(tm).run(reference=ref)
        assert res.incomplete_reason is None
        run = build_runfile(res, tm, source="simulated", reference=ref)
        paths.append(str(write_run(folder / f"lab_{seed}.run.npz", measure_run(run, load_sensors(), seed=seed))))
    return paths


@pytest.fixture(scope="module")
def declared(tmp_path_factory):
    folder = tmp_path_factory.mktemp("block")
    p = folder / "block.toml"
    p.write_text(BLOCK)
    return str(p)


def test_declared_rigid_specimen_that_is_flexible_found(declared, tmp_path):
    paths = _runs(tmp_path, FLEXIBLE)
    res = S.calibrate(paths, table="lab", payload=declared, path="replay", effects=["payload_mode"], workers=2)
    assert [(e["name"], e["where"]) for e in res.effects_added] == [("payload_mode", "dof:x")]
    e = res.effects_added[0]
    p, u = e["parameters"], e["uncertainty"]
    assert p["from_payload"] is True
    for k, truth in (("frequency_hz", 6.0), ("damping_ratio", 0.05), ("mass_kg", 900.0)):
        assert abs(p[k] - truth) <= u[k], (k, p[k], u[k])
    assert res.error_after < 0.5 * res.error_before


def test_rigid_specimen_adds_no_mode(declared, tmp_path):
    paths = _runs(tmp_path, BLOCK)
    res = S.calibrate(paths, table="lab", payload=declared, path="replay", effects=["payload_mode"], workers=2)
    assert res.effects_added == [], res.effects_added


def test_undeclared_flexible_specimen_found_on_a_replay(tmp_path):
    """The worked example's 2-storey frame (2 x 150 kg, first mode 4.0 Hz, 2 %) on the lab
    table, not declared (``--payload none``): its first mode found as an added modal mass,
    frequency and damping, the truth inside the 95 % intervals (modal mass of the first
    mode of two equal floors, shape (0.618, 1): (m sum phi)^2 / (m sum phi^2) = 284.2 kg);
    the held-out error falls. (The second mode, 10.5 Hz, 15.8 kg, explains less than the
    screening's 5 % here: not found.)"""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "scenarios/payloads/lab_2storey.toml").read_text()
    paths = _runs(tmp_path, text)
    res = S.calibrate(paths, table="lab", payload="none", path="replay", effects=["payload_mode"], workers=2)
    assert [(e["name"], e["where"]) for e in res.effects_added] == [("payload_mode", "dof:x")]
    p, u = res.effects_added[0]["parameters"], res.effects_added[0]["uncertainty"]
    assert "from_payload" not in p
    for k, truth in (("frequency_hz", 4.0), ("damping_ratio", 0.02), ("mass_kg", 284.2)):
        assert abs(p[k] - truth) <= u[k], (k, p[k], u[k])
    assert res.error_after < res.error_before


def test_declared_rigid_specimen_that_is_flexible_found_on_the_mechanical_path(declared, tmp_path):
    """The same with the default paths: the mechanical path finds the mode with its mass
    taken from the declared block (``m (H - 1) a``: held rigid and given ``m H a``, the
    mode fitted -813 kg and was refused, and the replay had to find it): 890.75 +/- 7.94
    kg for 900, 1.0 % low. The replay refits it (sim.calibrate.inherited): 899.67 +/- 0.33
    kg, 6.0028 +/- 0.0072 Hz, 5.030 +/- 0.055 % (2026-11-27); held at the mechanical
    path's values, the replay's acceleration was 3.1 % off against a 1.1 % noise floor and
    a 19 Hz foundation mode was accepted in its place. The replay adds nothing; the written
    entry takes its mass from the payload."""
    paths = _runs(tmp_path, FLEXIBLE)
    res = S.calibrate(paths, table="lab", payload=declared, workers=2)
    assert [(e["name"], e["where"], e["path"]) for e in res.effects_added] == [("payload_mode", "dof:x", "mechanical")]
    e = res.effects_added[0]
    assert e["options"] == {"from_payload": True} and e["refined_on"] == "replay"
    p, u = e["parameters"], e["uncertainty"]
    assert u["mass_kg"] < 1.0, u  # the replay's interval, not the mechanical path's 7.94 kg
    for k, truth, k_u in (("frequency_hz", 6.0, 1), ("damping_ratio", 0.05, 1), ("mass_kg", 900.0, 2)):
        assert abs(p[k] - truth) <= k_u * u[k], (k, p[k], u[k])
    rep = res.paths["replay"]
    assert rep["error_before"] < 0.2 * rep["error_before_declared"], rep  # the mode is the replay's too
    assert res.error_after < 0.2 * res.error_before and res.beats_baseline
    from sim.report.calibration import write_report

    write_report(res, tmp_path, "lab_calibrated.toml")
    text = (tmp_path / "report.md").read_text()
    assert "`payload_mode` at dof:x: found on the mechanical path, its values refitted on the replay path" in text


def test_rigid_specimen_adds_no_mode_with_the_default_paths(declared, tmp_path):
    paths = _runs(tmp_path, BLOCK)
    res = S.calibrate(paths, table="lab", payload=declared, workers=2)
    assert res.effects_added == [], res.effects_added


@pytest.mark.slow
def test_cgs_declared_rigid_20t_block_on_a_clamp_found_along_x_y_and_z(tmp_path):
    """The issue's CGS case: the 20 t block declared rigid (``rigid_20t``) is 60 % on a 6 Hz,
    5 % clamp in x, y and z (``clamp_mass_fraction``, mjcf.builder's model); a 6-DOF random
    run fitted, a harmonic one held out (tests/calibrate/test_cgs_mechanical.py's), the
    mechanical path. A mode of the block's own mass at each of x, y and z (one part of the
    block shared by the three: 12 t each out of 20 t), each at the block's centre of
    gravity (its rocking and its moment), masses inside their 95 % intervals, damping
    within two of its, frequencies within 0.1 % (measured: 11988.6 +/- 68, 12025.8 +/- 70,
    12037.7 +/- 64 kg; 5.9984 +/- 0.0028, 5.9955 +/- 0.0051, 5.9944 +/- 0.0026 Hz: the
    vertical's 0.09 % is a bias of twice its interval; 5.03, 4.90, 4.98 %); held out
    12.2 % -> 1.9 %, the
    clean 20 t floor (1.98 %). At the reference point without the rocking, x was not kept
    and y came out at 6.164 Hz. ~70 s."""
    import copy

    from tests.calibrate.test_cgs_mechanical import _cgs_raw, simulate_measured

    src = (ROOT / "scenarios/payloads/rigid_20t.toml").read_text()
    truth = tmp_path / "rigid_20t_clamped.toml"
    truth.write_text(src + "clamp_frequency_hz = 6.0\nclamp_damping_ratio = 0.05\nclamp_mass_fraction = 0.6\n")
    raw = copy.deepcopy(_cgs_raw())
    paths = [
        simulate_measured((raw, kind, 11 + i, tmp_path / f"{kind}.run.npz", True, str(truth)))
        for i, kind in enumerate(("random", "harmonic"))
    ]
    res = S.calibrate(paths, payload="rigid_20t", path="mechanical", workers=2)
    found = {e["where"]: e for e in res.effects_added if e["name"] == "payload_mode"}
    assert sorted(found) == ["dof:x", "dof:y", "dof:z"] and len(res.effects_added) == 3, res.effects_added
    for e in found.values():
        p, u = e["parameters"], e["uncertainty"]
        assert e["options"] == {"from_payload": True}
        assert abs(p["mass_kg"] - 12000.0) <= u["mass_kg"], e
        assert abs(p["frequency_hz"] - 6.0) <= 1e-3 * 6.0, e  # 0.03-0.09 % achieved
        assert abs(p["damping_ratio"] - 0.05) <= 2 * u["damping_ratio"], e
    assert res.error_after < 0.03 < 0.1 < res.error_before
