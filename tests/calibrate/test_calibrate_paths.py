"""`shaketable calibrate` on the replay and closed-loop paths: runs made on the CGS 6-DOF
table with a hydraulic or sensor effect the description lacks (3-axis random motion,
measured through the built-in 1024 Hz recorder model of `run --measure`: anti-alias
filter, noise, quantisation), calibrated against the description without it, name the
effect at its place, recover its parameter within 10 % and bring the held-out error
down; clean runs add nothing.

The candidate list is cut to a few effect types per test (``EFFECTS``; every place of
each) to keep the runtime down on a shared 2-core machine; the whole library on a 60 s
run is measured in docs/calibration.md."""

from __future__ import annotations

import copy

import pytest

from sim.calibrate import search as S

#: candidate types of these tests: the planted ones and their nearest confusers
EFFECTS = ["valve_flow_gain", "valve_delay", "bulk_modulus", "coulomb_friction", "sensor_gain", "sensor_delay"]
SECONDS = 3.0


def _cgs_measured(out, effects=(), seeds=(3, 4, 5), seconds=SECONDS):
    """3-axis band-limited white noise (1-30 Hz) on the CGS model with ``effects`` planted,
    closed loop, measured through the built-in recorder model (seeded)."""
    import mjcf
    from mjcf.description import parse_table
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.measure import load_sensors, measure_run
    from sim.runs.runfile import write_run
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    base = mjcf.load_table("cgs")
    raw = copy.deepcopy(base.raw)
    raw["effect"] = list(raw.get("effect", [])) + [dict(e) for e in effects]
    tm = build_model(parse_table(raw, src=base.source))
    rms = {"x": 1.0, "y": 1.0, "z": 0.8}  # m/s^2 RMS per axis
    sensors = load_sensors()
    paths = []
    for seed in seeds:
        mo = {
            d: M.white_noise(
                duration_s=seconds, sample_rate_hz=1024.0, band_hz=(1.0, 30.0), seed=(seed, k), rms_acceleration=rms[d]
            )
            for k, d in enumerate(rms)
        }
        ref = reference_from_motions(mo, 1024.0, seconds)
        res = Simulation(tm).run(reference=ref)
        assert res.incomplete_reason is None
        run = build_runfile(res, tm, source="simulated", reference=ref)
        paths.append(str(write_run(out / f"cgs_{seed}.run.npz", measure_run(run, sensors, seed=seed))))
    return paths


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    paths = _cgs_measured(tmp_path_factory.mktemp("clean"))
    return paths, S.calibrate(paths, path="replay", effects=EFFECTS, workers=2)


def _check(res, clean_res, name, where, key, truth):
    assert res.residual_path == "replay"
    assert [(e["name"], e["where"]) for e in res.effects_added][:1] == [(name, where)], res.effects_added
    e = res.effects_added[0]
    assert e["parameters"][key] == pytest.approx(truth, rel=0.10)
    assert 0 < e["uncertainty"][key] < abs(e["parameters"][key])
    assert res.error_after <= 0.2 * res.error_before or res.error_after <= 1.3 * clean_res.error_before, (
        res.error_before,
        res.error_after,
        clean_res.error_before,
    )


def test_clean_runs_add_nothing(clean):
    _paths, res = clean
    assert res.residual_path == "replay"
    assert res.effects_added == []
    assert res.error_after == res.error_before
    assert res.error_before < 0.08  # the recorder model's noise floor on these runs


def test_flow_gain_of_one_actuator_found(clean, tmp_path):
    paths = _cgs_measured(tmp_path, [{"type": "valve_flow_gain", "where": "actuator:X1", "factor": 0.8}])
    res = S.calibrate(paths, path="replay", effects=EFFECTS, workers=2)
    _check(res, clean[1], "valve_flow_gain", "actuator:X1", "factor", 0.8)
