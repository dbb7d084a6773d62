"""`shaketable calibrate` on the replay and closed-loop paths: runs made on the CGS 6-DOF
table with a hydraulic or sensor effect the description lacks (3-axis random motion,
measured through the built-in 1024 Hz recorder model of `run --measure`: anti-alias
filter, noise, quantisation), calibrated against the description without it, name the
effect at its place, recover its parameter within a few times the error measured (each
test says what it measured), with the truth inside its 95 % interval where it is, and
bring the held-out error down to the clean runs' floor; clean runs add nothing.

The candidate list is cut to a few effect types per test (``EFFECTS``; every place of
each) to keep the runtime down on a shared 2-core machine; the whole library on a 60 s
run is measured in docs/calibration.md."""

from __future__ import annotations

import copy
import json
import tomllib

import pytest

from sim.calibrate import search as S

#: candidate types of these tests: the planted ones and their nearest confusers
EFFECTS = ["valve_flow_gain", "valve_delay", "bulk_modulus", "sensor_gain", "sensor_delay"]
SENSORS = ["sensor_gain", "sensor_offset", "sensor_delay", "sensor_lowpass"]
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
        # a recorder writes the table's name, not the truth's description with the planted
        # effect (which calibrate would otherwise rebuild the model from: nothing to find)
        run.meta.pop("table_description", None)
        run.meta.pop("table_sha256", None)
        paths.append(str(write_run(out / f"cgs_{seed}.run.npz", measure_run(run, sensors, seed=seed))))
    return paths


@pytest.fixture(scope="module")
def clean_paths(tmp_path_factory):
    return _cgs_measured(tmp_path_factory.mktemp("clean"))


@pytest.fixture(scope="module")
def floor(clean_paths):
    """The clean held-out run's replay NRMSE against the declared model: the noise floor."""
    import mjcf
    from sim.calibrate import paths as P
    from sim.runs.runfile import read_run

    desc = mjcf.load_table("cgs")
    (pr,) = P.path_runs([read_run(clean_paths[1])], desc, "replay")  # held out: every third run from the second
    return P.nrmse([pr], [P.simulate_job(pr.job(desc.raw, str(desc.source), None, []))])


def _check(res, floor, name, where, key, truth, *, rel, inside=True, fall=1.0, near_floor=1.02):
    """The planted effect first, at its place; its value within ``rel`` of the truth (set
    from the error measured); the truth inside its 95 % interval (``inside`` False where it
    was measured outside: the test says by how much); the held-out error fallen below
    ``fall`` x before, to within ``near_floor`` x the clean held-out run's (the floor:
    measured 4.51 %)."""
    assert res.residual_path == "replay"
    assert [(e["name"], e["where"]) for e in res.effects_added][:1] == [(name, where)], res.effects_added
    e = res.effects_added[0]
    v, u = e["parameters"][key], e["uncertainty"][key]
    assert v == pytest.approx(truth, rel=rel), (key, v, u, truth)
    assert 0 < u < 0.1 * abs(v), (key, v, u)
    assert not inside or abs(v - truth) <= u, (key, v, u, truth)
    assert res.error_after < fall * res.error_before, (res.error_before, res.error_after)
    assert res.error_after <= near_floor * floor, (res.error_before, res.error_after, floor)


def test_clean_runs_add_nothing(clean_paths):
    res = S.calibrate(clean_paths, path="replay", effects=EFFECTS + SENSORS, workers=2)
    assert res.residual_path == "replay"
    assert res.effects_added == []
    assert res.error_after == res.error_before
    assert res.error_before < 0.08  # the recorder model's noise floor on these runs


@pytest.mark.slow
def test_flow_gain_of_one_actuator_found(floor, tmp_path):
    paths = _cgs_measured(tmp_path, [{"type": "valve_flow_gain", "where": "actuator:X1", "factor": 0.8}])
    res = S.calibrate(paths, path="replay", effects=EFFECTS, workers=2)
    # measured: 0.80019 +/- 0.00014, 0.024 % high: the truth OUTSIDE its interval (by 1.35 x
    # its half width); held out 52.1 % -> 4.58 % (1.015 x the floor)
    _check(res, floor, "valve_flow_gain", "actuator:X1", "factor", 0.8, rel=0.001, inside=False, near_floor=1.05)


@pytest.fixture(scope="module")
def sensor_runs(tmp_path_factory):
    """Y1's load cell (column 4) reading 20 % high (a wrong sensitivity entered). A
    sensor effect acts on one column of 18 compared: smaller errors move the pooled
    held-out error by less than the 5 % acceptance margin."""
    return _cgs_measured(
        tmp_path_factory.mktemp("sgain"),
        [{"type": "sensor_gain", "where": "channel:actuator_force[4]", "gain": 1.2}],
    )


def test_sensor_gain_of_one_load_cell_found(sensor_runs, floor):
    res = S.calibrate(sensor_runs, path="replay", effects=SENSORS, workers=2)
    # measured: 1.19997 +/- 0.00156; held out 5.94 % -> 4.45 % (floor 4.51 %)
    _check(res, floor, "sensor_gain", "channel:actuator_force[4]", "gain", 1.2, rel=0.002)
    assert len(res.effects_added) == 1


def test_sensor_delay_of_one_accelerometer_found(floor, tmp_path):
    """The y accelerometer 3 ms late (3.07 samples at 1024 Hz)."""
    paths = _cgs_measured(
        tmp_path, [{"type": "sensor_delay", "where": "channel:table_acceleration[1]", "delay_s": 3e-3}]
    )
    res = S.calibrate(paths, path="replay", effects=SENSORS, workers=2)
    # measured: 2.9989 +/- 0.0045 ms; held out 11.6 % -> 4.51 %, the floor
    _check(res, floor, "sensor_delay", "channel:table_acceleration[1]", "delay_s", 3e-3, rel=0.002)


def _shared_zero(res, floor, where, truth, rel, *, inside=True):
    """The one effect found is the offset at ``where`` (the zero every record shares,
    sim.calibrate.offsets), its value within ``rel`` of the truth and the truth inside its
    interval; each record being compared about its own zero (paths.tared), the held-out
    error is the clean floor before and after."""
    assert [(e["name"], e["where"]) for e in res.effects_added] == [("sensor_offset", where)], res.effects_added
    e = res.effects_added[0]
    v, u = e["parameters"]["offset"], e["uncertainty"]["offset"]
    assert v == pytest.approx(truth, rel=rel) and u < 0.1 * abs(v), (v, u, truth)
    assert not inside or abs(v - truth) <= u, (v, u, truth)
    assert res.error_after == res.error_before <= 1.02 * floor, (res.error_before, floor)


def test_sensor_offset_of_one_accelerometer_found(floor, tmp_path):
    """The z accelerometer's zero 0.15 m/s^2 off in every record (15 mg, a DC
    accelerometer's zero after a temperature change). One column of 18."""
    paths = _cgs_measured(
        tmp_path, [{"type": "sensor_offset", "where": "channel:table_acceleration[2]", "offset": 0.15}]
    )
    res = S.calibrate(paths, path="replay", effects=SENSORS, workers=2)
    # measured: 0.14957 +/- 0.00383 m/s^2 (0.14937 +/- 0.00091 as a candidate of the search
    # before each record's zero was its own: held out 5.19 % -> 4.51 %)
    _shared_zero(res, floor, "channel:table_acceleration[2]", 0.15, rel=0.005)


def test_load_cell_offset_of_one_actuator_found(floor, tmp_path):
    """X1's load cell reading 2 kN high in every record (a zero not set before the tests;
    the cells' noise is 1 kN RMS)."""
    paths = _cgs_measured(tmp_path, [{"type": "sensor_offset", "where": "channel:actuator_force[0]", "offset": 2.0e3}])
    res = S.calibrate(paths, path="replay", effects=SENSORS, workers=2)
    # measured: 2007.6 +/- 5.2 N, the truth outside: the clean runs share a zero of 7.6 +/-
    # 5.0 N at X1 (the model's own, under 5 % of the column's 17 kN RMS, not named there).
    # 2012.7 +/- 30.4 N as a candidate of the search before (held out 5.17 % -> 4.51 %)
    _shared_zero(res, floor, "channel:actuator_force[0]", 2.0e3, rel=0.005, inside=False)


def test_sensor_lowpass_of_one_accelerometer_found(floor, tmp_path):
    """The x accelerometer's conditioner set to a 40 Hz 2-pole low-pass (the description
    and the recorder model have none below the 256 Hz anti-alias filter)."""
    paths = _cgs_measured(
        tmp_path, [{"type": "sensor_lowpass", "where": "channel:table_acceleration[0]", "cutoff_hz": 40.0}]
    )
    res = S.calibrate(paths, path="replay", effects=SENSORS, workers=2)
    # measured: 40.006 +/- 0.023 Hz; held out 22.5 % -> 4.52 %, the floor
    _check(res, floor, "sensor_lowpass", "channel:table_acceleration[0]", "cutoff_hz", 40.0, rel=0.001)


@pytest.mark.slow
def test_valve_bandwidth_of_a_class_found(floor, tmp_path):
    """The vertical valves' main stage at 25 Hz where the description says 41.5 Hz
    (the second-order fit of Sec. 4 of [Airouche 2014]; a worn pilot stage, or a valve of a lower rating)."""
    paths = _cgs_measured(tmp_path, [{"type": "valve_bandwidth", "where": "class:vertical", "bandwidth_hz": 25.0}])
    res = S.calibrate(
        paths, path="replay", effects=["valve_bandwidth", "valve_delay", "valve_flow_gain", "bulk_modulus"], workers=2
    )
    # measured: 24.9971 +/- 0.0017 Hz, 0.012 % low: the truth OUTSIDE its interval (by 1.7 x
    # its half width); held out 81.0 % -> 0.79 %
    _check(res, floor, "valve_bandwidth", "class:vertical", "bandwidth_hz", 25.0, rel=0.001, inside=False)


@pytest.mark.slow
def test_valve_bandwidth_of_one_actuator_found(floor, tmp_path):
    """Y2's valve alone at 25 Hz (41.5 Hz declared); its nearest confuser, a delay of Y2's
    valve (3.9 ms explains 83 % against the bandwidth's 97 % on the refinement windows)."""
    paths = _cgs_measured(tmp_path, [{"type": "valve_bandwidth", "where": "actuator:Y2", "bandwidth_hz": 25.0}])
    res = S.calibrate(paths, path="replay", effects=["valve_bandwidth", "valve_delay", "valve_flow_gain"], workers=2)
    # measured: 24.997 +/- 0.033 Hz; held out 54.0 % -> 8.15 %, 1.8 x the clean floor with the
    # truth inside its interval (not explained here)
    _check(res, floor, "valve_bandwidth", "actuator:Y2", "bandwidth_hz", 25.0, rel=0.002, fall=0.2, near_floor=2.0)


@pytest.mark.slow
def test_supply_pressure_drop_found(floor, tmp_path):
    """The supply 3 MPa below the declared 21 MPa (18 MPa: a pump compensator set low; it
    stays above the accumulators' 14 MPa precharge). Its nearest confuser: the flow gain
    of every class (the valve flow goes as sqrt(p_s - p_L))."""
    paths = _cgs_measured(tmp_path, [{"type": "supply_pressure_drop", "where": "supply", "drop_pa": 3.0e6}])
    res = S.calibrate(paths, path="replay", effects=["supply_pressure_drop", "valve_flow_gain"], workers=2)
    # measured: 2.9977 +/- 0.0106 MPa; held out 9.77 % -> 4.75 % (1.05 x the floor)
    _check(res, floor, "supply_pressure_drop", "supply", "drop_pa", 3.0e6, rel=0.003, near_floor=1.1)


@pytest.mark.slow
def test_leakage_of_a_class_found(floor, tmp_path):
    """Worn piston seals in the lateral actuators: cross-piston leakage 2e-11 m^3/(s Pa)
    (1.2 l/min at 1 MPa across the piston) where the description says 1e-12."""
    paths = _cgs_measured(tmp_path, [{"type": "leakage", "where": "class:lateral", "coefficient_m3_s_pa": 2e-11}])
    res = S.calibrate(paths, path="replay", effects=["leakage", "bulk_modulus", "valve_flow_gain"], workers=2)
    # measured: (2.0076 +/- 0.0173)e-11; held out 7.90 % -> 4.60 % (1.02 x the floor)
    _check(res, floor, "leakage", "class:lateral", "coefficient_m3_s_pa", 2e-11, rel=0.01, near_floor=1.05)


@pytest.mark.slow
def test_valve_null_offset_of_one_actuator_found(floor, tmp_path):
    """X1's valve 1 % open at zero command (a torque-motor null shift). The replay path's
    null estimate (from the motion) takes most of it, ~0.009: X1 pushes against X2-X4, an
    internal force the motion does not show, held by the closed loop's commands against the
    leakage (docs/calibration.md, issue #13); the search adds the rest, and the
    reported offset is the whole null (estimate + correction, pathsearch.null_total)."""
    paths = _cgs_measured(tmp_path, [{"type": "valve_null_offset", "where": "actuator:X1", "offset": 0.01}])
    res = S.calibrate(paths, path="replay", effects=["valve_null_offset", "valve_flow_gain"], workers=2)
    # measured: 0.01075 +/- 0.00039, 7.5 % high: the truth OUTSIDE its interval (by 1.9 x its
    # half width; 0.01049 with every column alike). Held out 19.4 % -> 7.17 % with the columns
    # weighted by their noise (43.8 % -> 6.86 % alike): X1 pushes against X2-X4, and the load
    # cells' 4-5 % floors weigh their columns half the motion's, which the model already
    # matches to its floor before; X1's own force 63.1 % -> 19.8 %
    _check(
        res,
        floor,
        "valve_null_offset",
        "actuator:X1",
        "offset",
        0.01,
        rel=0.10,
        inside=False,
        fall=0.45,
        near_floor=2.0,
    )
    x1 = next(v for k, v in res.per_channel.items() if k.endswith("actuator_force[X1]"))
    assert x1["after"] < 0.4 * x1["before"], x1
    (row,) = [c for c in res.candidates if c["accepted"] and c["name"] == "valve_null_offset"][:1]
    assert 0 < row["parameters"]["offset"] < 0.5 * res.effects_added[0]["parameters"]["offset"]  # the correction


@pytest.mark.slow
def test_valve_delay_of_a_class_found(floor, tmp_path):
    """The vertical valves 4 ms late (realised as 8 physics steps of 1/2048 s: 3.9 ms)."""
    paths = _cgs_measured(tmp_path, [{"type": "valve_delay", "where": "class:vertical", "delay_s": 4e-3}])
    res = S.calibrate(paths, path="replay", effects=EFFECTS, workers=2)
    # measured: 3.90625 ms, the 8 steps realised (4 ms planted); held out 73.4 % -> 0.56 %
    _check(res, floor, "valve_delay", "class:vertical", "delay_s", 8 / 2048, rel=0.001)


@pytest.mark.slow
def test_bulk_modulus_of_a_class_found(floor, tmp_path):
    """Aerated oil in the lateral actuators: 0.7 GPa where the description says 1.0 GPa."""
    paths = _cgs_measured(tmp_path, [{"type": "bulk_modulus", "where": "class:lateral", "bulk_modulus_pa": 0.7e9}])
    res = S.calibrate(paths, path="replay", effects=EFFECTS, workers=2)
    # measured: 0.700026 +/- 0.000232 GPa; held out 92.4 % -> 5.01 % (1.11 x the floor)
    _check(res, floor, "bulk_modulus", "class:lateral", "bulk_modulus_pa", 0.7e9, rel=0.001, near_floor=1.2)


@pytest.mark.slow
def test_bulk_modulus_far_from_the_model_found(floor, tmp_path, monkeypatch):
    """0.6 GPa in the lateral actuators against a declared 1.0 GPa: the open-loop replay is
    145 % off (issue #13). Calibrated twice: as it is, and with the bulk-modulus candidate
    screened by the former step, 10 % up, whose linearisation at 1.0 GPa ranks a lateral flow
    gain (55.8 %) far above any bulk modulus (12-13 %) and estimates 0.96 GPa, in a local
    minimum of the residual. The best of each effect type is refined as well
    (pathsearch.to_refine), from a line search along the screened direction
    (pathsearch.line_search); the refined fits, compared by the residual they leave, name
    the bulk modulus. Without either, the flow gain (0.20, 73.5 %) was added."""
    from sim.calibrate import sensitivity as SE

    paths = _cgs_measured(tmp_path, [{"type": "bulk_modulus", "where": "class:lateral", "bulk_modulus_pa": 0.6e9}])
    res = S.calibrate(paths, path="replay", effects=EFFECTS, workers=2)
    # measured: 0.600000 +/- 0.000137 GPa; held out 145.5 % -> 5.32 % (1.18 x the floor)
    _check(res, floor, "bulk_modulus", "class:lateral", "bulk_modulus_pa", 0.6e9, rel=0.001, near_floor=1.25)
    assert res.error_before > 1.0  # far from the model

    stock = SE.candidates

    def upward_step(*a, **k):
        out = stock(*a, **k)
        for c in out:
            if c.type == "bulk_modulus":
                c.step = 0.1 * c.neutral
        return out

    monkeypatch.setattr(SE, "candidates", upward_step)
    res = S.calibrate(paths, path="replay", effects=EFFECTS, workers=2)
    first = [c for c in res.candidates if c["round"] == 0]
    best_screened = max(first, key=lambda c: c["linearised_score"])
    assert best_screened["name"] == "valve_flow_gain", best_screened  # the linearisation ranks the wrong type first
    # measured: 0.600023 +/- 0.000202 GPa; held out 145.5 % -> 5.32 %
    _check(res, floor, "bulk_modulus", "class:lateral", "bulk_modulus_pa", 0.6e9, rel=0.001, near_floor=1.25)


def test_the_best_of_each_type_is_refined():
    """to_refine: the 3 best by linearised score, plus the best of every other (type, kind
    of place) among the 20 best that explain >= 5 %; failed screens are left out."""
    import numpy as np

    from sim.calibrate.pathsearch import to_refine
    from sim.calibrate.sensitivity import Candidate, Screen

    def scr(t, where, score, ok=True):
        one = np.array([1.0])
        return Screen(Candidate(t, where, ("k",), one, one, -one, 2 * one, {"k": "1"}), score, one, ok)

    sc = [
        scr("valve_flow_gain", "class:lateral", 0.56),
        scr("sensor_gain", "channel:actuator_force", 0.43),
        scr("sensor_gain", "channel:actuator_force[4]", 0.17),
        scr("sensor_gain", "channel:actuator_force[5]", 0.16),
        scr("valve_delay", "class:lateral", 0.15, ok=False),
        scr("bulk_modulus", "actuator:Y2", 0.133),
        scr("bulk_modulus", "actuator:Y1", 0.132),
        scr("bulk_modulus", "class:lateral", 0.123),
        scr("valve_flow_gain", "actuator:Y1", 0.10),
    ] + [scr("sensor_delay", f"channel:table_velocity[{j}]", 0.09 - 0.001 * j) for j in range(12)]
    sc += [scr("leakage", "class:vertical", 0.06), scr("spring", "dof:x", 0.04)]
    got = [(s.cand.type, s.cand.where) for s in to_refine(sc)]
    assert got == [
        ("valve_flow_gain", "class:lateral"),
        ("sensor_gain", "channel:actuator_force"),
        ("sensor_gain", "channel:actuator_force[4]"),
        ("bulk_modulus", "actuator:Y2"),
        ("bulk_modulus", "class:lateral"),
        ("valve_flow_gain", "actuator:Y1"),
        ("sensor_delay", "channel:table_velocity[0]"),
    ]  # leakage is the 21st usable screen (beyond the 20), the spring below 5 %
    assert [s.cand.where for s in to_refine(sc, n_top=1, pool=1)] == ["class:lateral"]


@pytest.mark.slow
def test_two_effects_at_once_hydraulic_and_mechanical(floor, tmp_path):
    """X1's valve flowing 20 % short and 5 kN more dry friction on every lateral actuator."""
    planted = [
        {"type": "valve_flow_gain", "where": "actuator:X1", "factor": 0.8},
        {"type": "coulomb_friction", "where": "class:lateral", "force_n": 5000.0},
    ]
    res = S.calibrate(
        _cgs_measured(tmp_path, planted), path="replay", effects=EFFECTS + ["coulomb_friction"], workers=2
    )
    found = {(e["name"], e["where"]): e["parameters"] for e in res.effects_added}
    assert set(found) == {("valve_flow_gain", "actuator:X1"), ("coulomb_friction", "class:lateral")}, found
    sd = {(e["name"], e["where"]): e["uncertainty"] for e in res.effects_added}
    # measured: 0.80020 +/- 0.00015, 0.025 % high: the truth OUTSIDE its interval (by 1.3 x its
    # half width, as when planted alone)
    assert found[("valve_flow_gain", "actuator:X1")]["factor"] == pytest.approx(0.8, rel=0.001)
    f, u = found[("coulomb_friction", "class:lateral")]["force_n"], sd[("coulomb_friction", "class:lateral")]["force_n"]
    assert f == pytest.approx(5000.0, rel=0.002) and abs(f - 5000.0) <= u, (f, u)  # measured: 4998.9 +/- 15.7 N
    # measured: held out 52.8 % -> 4.54 % (1.005 x the floor)
    assert res.error_after < res.error_before and res.error_after <= 1.02 * floor, (res.error_after, floor)


@pytest.mark.slow
def test_a_wrong_effect_accepted_first_is_dropped(floor, tmp_path, monkeypatch):
    """The lateral valves flowing 20 % short, with the first round offered only the sensor
    gains (monkeypatched): the lateral velocity sensor reading 0.798 stands in for the
    flow gain and passes on its column. In the next round the flow gain is added (0.822,
    with the sensor gain held); the joint refit (sim.calibrate.revisit) takes the sensor
    gain back to 1.000 and the flow gain to 0.800, and the backward pass drops the
    sensor gain. Without the revisit both stayed (effects_added: the sensor gain 0.798
    and the flow gain 0.822)."""
    from sim.calibrate import sensitivity as SE

    stock = SE.candidates

    def sensors_first(desc, payload, prs, accepted, mot, effects=None, **kw):
        out = stock(desc, payload, prs, accepted, mot, effects, **kw)
        return [c for c in out if c.sensor] if not accepted else out

    monkeypatch.setattr(SE, "candidates", sensors_first)
    paths = _cgs_measured(tmp_path, [{"type": "valve_flow_gain", "where": "class:lateral", "factor": 0.8}])
    res = S.calibrate(paths, path="replay", effects=["valve_flow_gain", "sensor_gain"], workers=2)
    first = [c for c in res.candidates if c["round"] == 0 and c["accepted"]]
    assert [(c["name"], c["where"]) for c in first] == [("sensor_gain", "channel:table_velocity[1]")], first
    gone = [c for c in res.candidates if c.get("revisited") == "dropped"]
    assert [(c["name"], c["where"]) for c in gone] == [("sensor_gain", "channel:table_velocity[1]")], gone
    assert gone[0]["parameters"]["gain"] == pytest.approx(1.0, abs=0.02)  # refitted to no effect first
    assert len(res.effects_added) == 1
    # measured: 0.80010 +/- 0.00050; held out 15.1 % -> 4.72 % (1.045 x the floor)
    _check(res, floor, "valve_flow_gain", "class:lateral", "factor", 0.8, rel=0.001, near_floor=1.1)
    assert res.timing["revisit_replays"] > 0


def _reference_only(paths, out):
    """The runs with only the reference and the table's motion (no valve commands, no
    forces or pressures): the closed-loop path is the one left."""
    from sim.runs.runfile import read_run, write_run

    res = []
    for p in paths:
        r = read_run(p)
        r.valve_command = r.actuator_force = r.pressure_a = r.pressure_b = r.spool_position = None
        r.actuator_displacement = None
        res.append(str(write_run(out / p.split("/")[-1], r)))
    return res


def test_closed_loop_reference_derivatives_are_the_controllers():
    """The closed-loop path rebuilds the reference's velocity and acceleration (the run file
    keeps only the pose) as the controller had them (analytic, reference_from_motions).
    np.gradient twice ran 0.43 % low on the acceleration of this 1-30 Hz reference (0.48 %
    RMS error; velocity 0.05 %), and the model's table moved ~0.8 % short (issue #13)."""
    import numpy as np

    import mjcf
    from sim.calibrate import paths as P
    from sim.effects import build_model
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    rms = {"x": 1.0, "y": 1.0, "z": 0.8}
    mo = {
        d: M.white_noise(duration_s=3.0, sample_rate_hz=1024.0, band_hz=(1.0, 30.0), seed=(3, k), rms_acceleration=a)
        for k, (d, a) in enumerate(rms.items())
    }
    ref = reference_from_motions(mo, 1024.0, 3.0)
    _sim, got = P._closed_loop_setup(build_model(mjcf.load_table("cgs")), ref.t, ref.d)
    np.testing.assert_array_equal(got.d, ref.d)
    assert np.linalg.norm(got.v - ref.v) < 1e-5 * np.linalg.norm(ref.v)  # was 5.5e-4
    # 3.1e-4 (was 4.8e-3): the cosine taper's onset, where the analytic acceleration jumps
    assert np.linalg.norm(got.a - ref.a) < 1e-3 * np.linalg.norm(ref.a)
    assert float(np.sum(got.a * ref.a) / np.sum(ref.a**2)) == pytest.approx(1.0, abs=1e-4)  # was 0.9965


def test_closed_loop_clean_runs_match_in_amplitude(clean_paths, tmp_path):
    """The clean runs on the closed-loop path: the model's table acceleration matches the
    record's in amplitude per DOF (least-squares gain record / model 0.9999-1.0005; with the
    reference's derivatives by differences 1.0074-1.0089, the bias an accelerometer gain
    then absorbed)."""

    import mjcf
    from sim.calibrate import paths as P
    from sim.runs.runfile import read_run

    desc = mjcf.load_table("cgs")
    (tmp_path / "ref").mkdir()
    prs = P.path_runs([read_run(p) for p in _reference_only(clean_paths, tmp_path / "ref")], desc, "closed_loop")
    for pr in prs:
        m = P.simulate_job(pr.job(desc.raw, str(desc.source), None, []))
        for ch in ("table_acceleration", "table_velocity"):
            for j in pr.columns[ch]:
                x, y = pr.recorded[ch][:, j], m[ch][:, j]
                assert float(x @ y / (y @ y)) == pytest.approx(1.0, abs=2e-3), (pr.name, ch, j)


def test_closed_loop_path_finds_an_accelerometer_gain(sensor_runs, tmp_path):
    """Only the reference recorded: the model runs closed loop through the table's
    controller; an x accelerometer reading 15 % low is found there: 0.8505 +/- 0.0010
    (with the reference's derivatives by differences 0.8568 +/- 0.0010, the truth outside)."""
    src = _cgs_measured(
        tmp_path, [{"type": "sensor_gain", "where": "channel:table_acceleration[0]", "gain": 0.85}], seeds=(3, 4)
    )
    (tmp_path / "ref").mkdir()
    paths = _reference_only(src, tmp_path / "ref")
    res = S.calibrate(paths, effects=SENSORS, workers=2)
    assert res.residual_path == "closed_loop"
    assert [(e["name"], e["where"]) for e in res.effects_added] == [("sensor_gain", "channel:table_acceleration[0]")]
    e = res.effects_added[0]
    # measured: 0.85027 +/- 0.00082, inside its 95 % interval
    assert abs(e["parameters"]["gain"] - 0.85) < e["uncertainty"]["gain"]
    assert e["parameters"]["gain"] == pytest.approx(0.85, rel=0.002)
    # measured: held out 7.41 % -> 1.71 % (the clean runs' closed-loop floor: 1.64 %)
    assert res.error_after < 0.3 * res.error_before and res.error_after < 0.02, (res.error_before, res.error_after)


def test_closed_loop_clean_runs_add_nothing(clean_paths, tmp_path):
    """The clean runs with only the reference and the motion: nothing is added on the
    closed-loop path either, with the sensor types among the candidates (no sensor
    candidate explains 5 % of its own columns there: at most 0.3 %)."""
    (tmp_path / "ref").mkdir()
    paths = _reference_only(clean_paths, tmp_path / "ref")
    res = S.calibrate(paths, effects=EFFECTS + SENSORS, workers=2)
    assert res.residual_path == "closed_loop"
    assert res.effects_added == []
    assert res.error_after == res.error_before
    assert res.error_before < 0.03  # 1.64 %: no load cells here, the acceleration's noise floor


@pytest.fixture(scope="module")
def small_sensor_runs(tmp_path_factory):
    """Two small sensor errors: Y1's load cell (column 4) 5 % high and the x accelerometer
    3 % low. Each explains little of the pooled residual (2.3 % and 0.9 % on the replay
    path) and much of its own column's (43 %, 38 %)."""
    return _cgs_measured(
        tmp_path_factory.mktemp("small"),
        [
            {"type": "sensor_gain", "where": "channel:actuator_force[4]", "gain": 1.05},
            {"type": "sensor_gain", "where": "channel:table_acceleration[0]", "gain": 0.97},
        ],
    )


def _deviation(res, where):
    """A found sensor gain's error (gain - 1) at ``where``, and its 95 % half width."""
    (e,) = [e for e in res.effects_added if e["where"] == where]
    assert e["name"] == "sensor_gain"
    return e["parameters"]["gain"] - 1.0, e["uncertainty"]["gain"]


def test_small_sensor_gains_found_on_their_own_columns(small_sensor_runs):
    """Replay path: both found, each error (gain - 1) within a few times the error
    measured and the truth inside its interval, and nothing else (sensor candidates
    screened also by the share of their own columns' residual, pathsearch.to_refine)."""
    res = S.calibrate(small_sensor_runs, path="replay", effects=SENSORS, workers=2)
    assert res.residual_path == "replay"
    assert len(res.effects_added) == 2, res.effects_added
    d, u = _deviation(res, "channel:actuator_force[4]")  # measured: 0.04996 +/- 0.00156
    assert d == pytest.approx(0.05, rel=0.01) and abs(d - 0.05) <= u, (d, u)
    d, u = _deviation(res, "channel:table_acceleration[0]")  # measured: -0.02975 +/- 0.00055
    assert d == pytest.approx(-0.03, rel=0.02) and abs(d + 0.03) <= u, (d, u)
    assert res.error_after < res.error_before  # measured: 4.69 % -> 4.50 % (the floor 4.51 %)


def test_closed_loop_path_finds_a_small_accelerometer_gain(small_sensor_runs, tmp_path):
    """The same runs with only the reference and the motion: the x accelerometer's 3 %
    found on the closed-loop path (the load cell is not recorded there)."""
    (tmp_path / "ref").mkdir()
    res = S.calibrate(_reference_only(small_sensor_runs, tmp_path / "ref"), effects=SENSORS, workers=2)
    assert res.residual_path == "closed_loop"
    assert [e["where"] for e in res.effects_added] == ["channel:table_acceleration[0]"], res.effects_added
    d, u = _deviation(res, "channel:table_acceleration[0]")  # measured: -0.02974 +/- 0.00055
    assert d == pytest.approx(-0.03, rel=0.02) and abs(d + 0.03) <= u, (d, u)
    assert res.error_after < res.error_before  # measured: 2.08 % -> 1.65 %


def test_sensor_candidates_refined_by_their_own_columns():
    """to_refine: a sensor candidate below the pooled 5 % is refined when it explains >= 5 %
    of its own columns, the best of each (sensor type, kind of place) by that share."""
    import numpy as np

    from sim.calibrate.pathsearch import to_refine
    from sim.calibrate.sensitivity import Candidate, Screen

    def scr(t, where, score, own=None):
        one = np.array([1.0])
        c = Candidate(t, where, ("k",), one, one, -one, 2 * one, {"k": "1"}, sensor=own is not None)
        return Screen(c, score, one, True, own)

    sc = [
        scr("valve_flow_gain", "class:lateral", 0.30),
        scr("sensor_gain", "channel:actuator_force[4]", 0.023, own=0.43),
        scr("sensor_gain", "channel:table_acceleration[0]", 0.009, own=0.38),
        scr("sensor_gain", "channel:table_acceleration", 0.003, own=0.09),
        scr("sensor_delay", "channel:actuator_force[2]", 0.005, own=0.04),
        scr("sensor_offset", "channel:table_velocity[1]", 0.0, own=0.06),
    ]
    got = [(s.cand.type, s.cand.where) for s in to_refine(sc)]
    assert got == [
        ("valve_flow_gain", "class:lateral"),
        ("sensor_gain", "channel:actuator_force[4]"),
        ("sensor_gain", "channel:table_acceleration"),
        ("sensor_offset", "channel:table_velocity[1]"),
    ]  # the accelerometer's column: a sensor_gain column already in; the delay: 4 % of its column


def test_cli_replay_path_writes_json_report_and_table(sensor_runs, tmp_path):
    from sim.cli import main

    out = tmp_path / "out"
    rc = main(["calibrate", *sensor_runs, "--path", "replay", "--effects", "sensor_gain", "--out", str(out), "--json"])
    assert rc == 0
    js = json.loads((out / "calibration.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    assert js["residual_path"] == "replay"
    assert [(e["name"], e["where"]) for e in js["effects_added"]] == [("sensor_gain", "channel:actuator_force[4]")]
    for k in ("error_before", "error_after", "candidates", "unexplained", "per_channel", "timing"):
        assert k in js
    raw = tomllib.loads((out / "cgs_calibrated.toml").read_text())
    (e,) = [e for e in raw["effect"] if e["type"] == "sensor_gain"]
    assert e["where"] == "channel:actuator_force[4]" and e["source"].startswith("calibrated: shaketable calibrate")
    md = (out / "report.md").read_text()
    for fig in ("holdout_error.png", "residual_time.png", "residual_spectra.png", "effects.png"):
        assert (out / fig).stat().st_size > 1000 and fig in md


def test_forced_path_the_runs_cannot_take_is_one_line(sensor_runs, tmp_path, capsys):
    from sim.cli import main

    (tmp_path / "ref").mkdir()
    paths = _reference_only(sensor_runs[:1], tmp_path / "ref")
    out = tmp_path / "out"
    rc = main(["calibrate", *paths, "--path", "replay", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.startswith("error: ") and "\n" not in err and "valve_command" in err, err
    assert not out.exists()
