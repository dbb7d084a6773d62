"""The mechanical residual path on the 6-DOF CGS table (1024 Hz): plant an effect the
description lacks, calibrate against the description without it, recover it.

Runs are simulated once per case (module-scoped, two processes): a 6-DOF band-limited
random run (fitted) and a 6-DOF harmonic run (held out: data the fit never saw), both
measured through the built-in sensor model of ``shaketable run --measure``
(``scenarios/sensors/recorder_1024hz.toml``: 256 Hz 4-pole anti-alias filter on every
analog channel, the table's declared 300 Hz 4-pole accelerometer conditioner on the
accelerations, which the runs declare, 1 kN force noise, 0.003 g acceleration noise,
20 um displacement noise, 16-bit quantisation).

Also the cause of the "28 Hz line" that CGS runs used to leave: the loop records the
pressures at t_k and the acceleration of the physics step leaving t_k (computed from the
pressures at t_k + h); the run declares that lag (``meta.force_lag_s``) and the
mechanical residual reads the force at the acceleration's instant. A clean run's
residual is then near zero and has no line.
"""

from __future__ import annotations

import copy
import math

import pytest

SECONDS = 2.5  #: each run (s): enough reversals for dry friction, short for CI
#: 6-DOF random: RMS acceleration per DOF (m/s^2, rad/s^2), band 1-30 Hz (the CGS
#: oil-column modes sit at 16-28 Hz, inside it; 1 Hz: the lowest a 2.5 s record holds)
RANDOM_RMS = {"x": 1.0, "y": 1.0, "z": 0.8, "rx": 0.5, "ry": 0.5, "rz": 0.5}
#: harmonic: (amplitude m or rad, frequency Hz) per DOF, tapered over one cycle; every DOF
#: moves (a DOF left still holds only sensor noise, and its held-out NRMSE would be ~1
#: whatever the model); peak accelerations 1.6-3.9 m/s^2 (rad/s^2), as the random run's
HARMONIC = {
    "x": (0.010, 3.0),
    "y": (0.008, 3.5),
    "z": (0.004, 4.5),
    "rx": (0.003, 4.0),
    "ry": (0.003, 5.0),
    "rz": (0.004, 3.2),
}


def _cgs_raw():
    import mjcf

    return copy.deepcopy(mjcf.load_table("cgs").raw)


def _reference(kind: str, seed: int):
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    fs = 1024.0
    if kind == "random":
        mo = {
            d: M.white_noise(
                duration_s=SECONDS, sample_rate_hz=fs, band_hz=(1.0, 30.0), seed=(seed, k), rms_acceleration=rms
            )
            for k, (d, rms) in enumerate(RANDOM_RMS.items())
        }
    else:
        mo = {
            d: M.tapered_sine(amplitude=a, frequency_hz=f, duration_s=SECONDS, sample_rate_hz=fs, taper_cycles=1.0)
            for d, (a, f) in HARMONIC.items()
        }
    return reference_from_motions(mo, fs, SECONDS)


def simulate_measured(job):
    """One run of the CGS model described by ``raw`` (with its ``[[effect]]`` entries),
    written as a run file and measured through the built-in sensor model (seeded).
    ``job = (raw, kind, seed, out_path, measure[, payload])`` (``payload``: the name of
    the payload standing on the table, recorded in the run as the declared one); returns
    the path."""
    raw, kind, seed, out, measure, *rest = job
    payload = rest[0] if rest else None
    import mjcf
    from mjcf.description import parse_table
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.measure import load_sensors, measure_run
    from sim.runs.runfile import write_run

    tm = build_model(parse_table(raw, src="<truth>"), mjcf.load_payload(payload) if payload else None)
    ref = _reference(kind, seed)
    res = Simulation(tm).run(reference=ref)
    assert res.incomplete_reason is None, res.incomplete_reason
    run = build_runfile(res, tm, source="simulated", reference=ref, payload_name=payload)
    if measure:  # True: the built-in sensor model; a dict: that one
        run = measure_run(run, measure if isinstance(measure, dict) else load_sensors(), seed=seed)
    return str(write_run(out, run))


#: case -> the [[effect]] entries planted in the truth (absent from the declared table).
#: Values: of the order of the table's own (seal friction 5-10 kN per actuator, platen
#: 44.3 t, 12 actuators); assumed: large enough to stand out of the sensor noise.
CASES = {
    "clean": [],
    "added_mass_x": [{"type": "added_mass", "where": "dof:x", "mass_kg": 6000.0}],
    "coulomb_dof_y": [{"type": "coulomb_friction", "where": "dof:y", "force_n": 15000.0}],
    "coulomb_class_vertical": [{"type": "coulomb_friction", "where": "class:vertical", "force_n": 8000.0}],
    "coulomb_actuator_X2": [{"type": "coulomb_friction", "where": "actuator:X2", "force_n": 12000.0}],
    "viscous_dof_x": [{"type": "viscous_damping", "where": "dof:x", "damping_n_s_m": 2.0e5}],
    "power_dof_y": [{"type": "power_damping", "where": "dof:y", "coefficient": 1.0e5, "exponent": 0.6}],
    "spring_dof_z": [{"type": "spring", "where": "dof:z", "stiffness_n_m": 2.0e7}],
    # inertia about the vertical (kg m^2 on a rotation): 7 % of the platen's 295 614 kg m^2
    "added_inertia_rz": [{"type": "added_mass", "where": "dof:rz", "mass_kg": 20000.0}],
    # dry friction growing with |y| (a bearing loaded as the platen moves off centre; 1 MN/m
    # doubles the level at 6 mm) and a seal's growing with the force X2 carries (0.2: 6 kN at
    # 30 kN); assumed, of the order of the constant levels above
    "coulomb_grows_displacement_y": [
        {
            "type": "coulomb_friction",
            "where": "dof:y",
            "force_n": 6000.0,
            "grows_with": "displacement",
            "coefficient": 1.0e6,
        }
    ],
    "coulomb_grows_load_X2": [
        {
            "type": "coulomb_friction",
            "where": "actuator:X2",
            "force_n": 4000.0,
            "grows_with": "load",
            "coefficient": 0.2,
        }
    ],
    "payload_mode_x": [
        {"type": "payload_mode", "where": "dof:x", "mass_kg": 5000.0, "frequency_hz": 8.0, "damping_ratio": 0.05}
    ],
    "spring_and_coulomb": [
        {"type": "spring", "where": "dof:x", "stiffness_n_m": 1.5e7},
        {"type": "coulomb_friction", "where": "class:vertical", "force_n": 8000.0},
    ],
    # the 20 t block's centre of gravity 0.3 m and 0.2 m off where it is declared (assumed:
    # a specimen's mass distribution known to tens of cm)
    "clean_payload": [],
    "cg_offset_payload": [{"type": "cg_offset", "where": "payload", "dx_m": 0.3, "dy_m": 0.2, "dz_m": 0.0}],
    # the vertical seals' friction with the displacement and velocity 2 samples late (below)
    "coulomb_class_vertical_motion_late": [{"type": "coulomb_friction", "where": "class:vertical", "force_n": 8000.0}],
    # nothing planted in the table: its load cells read 5 % high (below)
    "load_cells_high": [],
    # nothing planted: the vertical class's four load cells read 5 % high (below)
    "vertical_load_cells_high": [],
    # nothing planted: Z1's load cell alone reads 5 % high (below)
    "z1_load_cell_high": [],
    # the vertical class's load cells 5 % high (below) and 6 t in z nobody declared
    "vertical_load_cells_high_mass_z": [{"type": "added_mass", "where": "dof:z", "mass_kg": 6000.0}],
}
#: case -> samples its displacement and velocity are late (not declared)
MOTION_LATE = {"coulomb_class_vertical_motion_late": 2}
#: case -> the gain every load cell reads the force with, or each (columns X1-X4, Y1-Y4,
#: Z1-Z4) (assumed: a piston area or a unit 5 % off, as the NEES-UCSD real-record suite's
#: case; of one kind of actuator, the vertical class's)
FORCE_GAIN = {
    "load_cells_high": 1.05,
    "vertical_load_cells_high": [1.0] * 8 + [1.05] * 4,
    "z1_load_cell_high": [1.0] * 8 + [1.05] + [1.0] * 3,
    "vertical_load_cells_high_mass_z": [1.0] * 8 + [1.05] * 4,
}
#: case -> the payload on the table (declared: the runs name it, the calibration reads it)
PAYLOAD = {"clean_payload": "rigid_20t", "cg_offset_payload": "rigid_20t"}
#: the clean cases (their held-out error is the floor of the cases on the same payload)
CLEAN = ("clean", "clean_payload")
#: what else a case must add: a payload_mode is a body on a slide along its DOF, rigid
#: with the platen along the others, so its modal mass is also found as added_mass at
#: dof:y and dof:z (physically right: 4976 and 4937 kg of the 5 t measured)
ALSO = {
    "payload_mode_x": [
        {"type": "added_mass", "where": "dof:y", "mass_kg": 5000.0},
        {"type": "added_mass", "where": "dof:z", "mass_kg": 5000.0},
    ]
}
#: per case, (effect type, place, parameter) -> (tolerance, the truth inside its 95 %
#: interval): the tolerance relative (absolute where the truth is 0), about 2-3 x the error
#: measured (2026-11-27, one process; value +/- its 95 % half width in the comment);
#: False where the interval was measured to miss the truth (by how much: the comment)
CHECKS = {
    "added_mass_x": {("added_mass", "dof:x", "mass_kg"): (0.005, True)},  # 6008.7 +/- 99.4 kg
    # 14864 +/- 126 N: 0.9 % low, OUTSIDE its interval by 1.08 x its half width
    "coulomb_dof_y": {("coulomb_friction", "dof:y", "force_n"): (0.02, False)},
    "coulomb_class_vertical": {("coulomb_friction", "class:vertical", "force_n"): (0.002, True)},  # 8000.2 +/- 46.3
    "coulomb_actuator_X2": {("coulomb_friction", "actuator:X2", "force_n"): (0.01, True)},  # 11968 +/- 112 N
    "viscous_dof_x": {("viscous_damping", "dof:x", "damping_n_s_m"): (0.02, True)},  # 1.9817e5 +/- 0.0348e5
    "power_dof_y": {
        ("power_damping", "dof:y", "coefficient"): (0.03, True),  # 99188 +/- 5877
        ("power_damping", "dof:y", "exponent"): (0.02, True),  # 0.600 +/- 0.017
    },
    "spring_dof_z": {("spring", "dof:z", "stiffness_n_m"): (0.015, True)},  # 2.0130e7 +/- 0.0133e7
    # 19141 +/- 653 kg m^2: 4.3 % low, OUTSIDE its interval by 1.31 x its half width
    "added_inertia_rz": {("added_mass", "dof:rz", "mass_kg"): (0.08, False)},
    "coulomb_grows_displacement_y": {
        ("coulomb_friction", "dof:y", "force_n"): (0.03, True),  # 5918 +/- 165 N
        ("coulomb_friction", "dof:y", "coefficient"): (0.03, True),  # 0.986e6 +/- 0.067e6 N/m
    },
    "coulomb_grows_load_X2": {
        ("coulomb_friction", "actuator:X2", "force_n"): (0.05, True),  # 3901 +/- 152 N
        ("coulomb_friction", "actuator:X2", "coefficient"): (0.03, True),  # 0.2019 +/- 0.0069
    },
    "payload_mode_x": {
        ("payload_mode", "dof:x", "mass_kg"): (0.03, True),  # 5053.5 +/- 72.1 kg
        ("payload_mode", "dof:x", "frequency_hz"): (0.002, True),  # 7.9968 +/- 0.0067 Hz
        ("payload_mode", "dof:x", "damping_ratio"): (0.015, True),  # 0.05021 +/- 0.00108
        ("added_mass", "dof:y", "mass_kg"): (0.015, True),  # 4975.5 +/- 85.4 kg
        ("added_mass", "dof:z", "mass_kg"): (0.03, True),  # 4936.6 +/- 85.3 kg
    },
    "spring_and_coulomb": {
        # 1.49397e7 +/- 0.00528e7: 0.4 % low, OUTSIDE its interval by 1.14 x its half width
        ("spring", "dof:x", "stiffness_n_m"): (0.01, False),
        ("coulomb_friction", "class:vertical", "force_n"): (0.002, True),  # 8001.1 +/- 46.4 N
    },
    "cg_offset_payload": {
        ("cg_offset", "payload", "dx_m"): (0.03, True),  # 0.3034 +/- 0.0052 m
        # 0.1915 +/- 0.0045 m: 4.3 % low, OUTSIDE its interval by 1.88 x its half width
        ("cg_offset", "payload", "dy_m"): (0.08, False),
        ("cg_offset", "payload", "dz_m"): (0.005, True),  # 0.0007 +/- 0.0040 m (truth 0: absolute)
    },
}
#: per case, the held-out error after calibration within this factor of its clean floor
#: (measured: 0.99-1.01 x; the springs' 1.18 x and 1.14 x)
NEAR_FLOOR = {"spring_dof_z": 1.25, "spring_and_coulomb": 1.2}


def _sensors_of(case: str):
    """The sensor model of a case's runs: the built-in one (True), with the motion late or
    the load cells' gain where the case says so."""
    from sim.runs.measure import load_sensors

    if case in MOTION_LATE:
        return _sensors_late(MOTION_LATE[case])
    if case in FORCE_GAIN:
        sensors = load_sensors()
        sensors["channel"]["actuator_force"]["gain"] = FORCE_GAIN[case]
        return sensors
    return True


def _sensors_late(samples: float) -> dict:
    """The built-in sensor model with the displacement and the velocity ``samples`` late."""
    from sim.runs.measure import load_sensors

    sensors = load_sensors()
    for ch in ("table_displacement", "table_velocity"):
        sensors["channel"][ch]["skew_s"] = -samples / 1024.0  # a skew > 0 is early
    return sensors


def calibrate_case(paths):
    """The search strategy on one case's runs (every law of the library at every place;
    the random run fitted, the harmonic run held out), with the defaults: the measured
    runs went through the table's 300 Hz accelerometer conditioner and declare it."""
    from sim.calibrate import search as S

    res = S.calibrate(paths, path="mechanical")
    res.series = {}  # arrays stay in the worker
    return res


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    """Every case simulated (random, harmonic) and calibrated once, on two processes."""
    from sim.parallel import map_jobs

    base = _cgs_raw()
    out = tmp_path_factory.mktemp("cgs_cases")
    jobs = []
    for name, effects in CASES.items():
        raw = copy.deepcopy(base)
        raw["effect"] = list(raw.get("effect", [])) + [dict(e) for e in effects]
        measure = _sensors_of(name)
        for i, kind in enumerate(("random", "harmonic")):
            jobs.append((raw, kind, 11 + i, out / f"{name}_{kind}.run.npz", measure, PAYLOAD.get(name)))
    paths = map_jobs(simulate_measured, jobs, workers=2)
    results = map_jobs(calibrate_case, [paths[2 * k : 2 * k + 2] for k in range(len(CASES))], workers=2)
    return dict(zip(CASES, results))


# ------------------------------------------------------------------ the 28 Hz line
def test_clean_simulated_run_balances_without_the_28hz_line(tmp_path):
    """A clean run (no sensor noise, no planted effect): the declared model's mechanical
    residual is near zero and has no spectral line; reading the force without the
    recorder's lag brings the 28 Hz line back (the cause, shown)."""
    import mjcf
    from sim.calibrate import residuals as R
    from sim.calibrate.search import unexplained
    from sim.runs.runfile import read_run

    p = simulate_measured((_cgs_raw(), "random", 5, tmp_path / "clean.run.npz", False))
    run = read_run(p)
    assert run.meta["force_lag_s"] == pytest.approx(1 / 2048)
    desc = mjcf.load_table("cgs")
    (mr,) = R.mechanical_runs([run], desc)
    e = R.nrmse_runs([mr], [mr.residual])
    lagged = copy.copy(run)
    lagged.meta = {k: v for k, v in run.meta.items() if k != "force_lag_s"}
    (mr0,) = R.mechanical_runs([lagged], desc)
    e0 = R.nrmse_runs([mr0], [mr0.residual])
    line0 = unexplained([mr0], [mr0.residual])
    # measured on a loaded machine, 4 s run: 6.9 % with the lag, 0.69 % without
    assert e < 0.015, e
    assert e0 > 4 * e, (e0, e)
    assert line0 is not None and 20.0 <= line0["peak_hz"] <= 30.0 and line0["fraction_of_residual"] > 0.5
    assert line0["coherence_with_motion"] > 0.5  # coherent with the motion, as reported


# ------------------------------------------------------------------ plant and recover
@pytest.mark.slow
@pytest.mark.parametrize("case", CLEAN)
def test_clean_measured_runs_add_nothing(case, cases):
    res = cases[case]
    (gain,) = [c for c in res.candidates if c["name"] == "sensor_gain"][:1]  # the model's own scale: 0.99872
    assert abs(gain["parameters"]["gain"] - 1.0) < 0.005 and not gain["accepted"], gain
    assert res.residual_path == "mechanical"
    assert res.effects_added == [], res.effects_added
    assert res.error_after == res.error_before
    assert res.unexplained is None, res.unexplained
    assert res.error_before < 0.04, res.error_before  # noise floor: 2.05 % measured (1.98 % with 20 t)


@pytest.mark.slow
@pytest.mark.parametrize("case", [c for c in CASES if c not in CLEAN and c not in MOTION_LATE and c not in FORCE_GAIN])
def test_planted_effect_recovered(case, cases):
    """Right effect, right place, each parameter within a few times the error measured
    and the truth inside its 95 % interval (CHECKS), the held-out error fallen to its
    clean floor (NEAR_FLOOR); nothing else added."""
    res = cases[case]
    planted = CASES[case] + ALSO.get(case, [])
    got = {(e["name"], e["where"]): e for e in res.effects_added}
    assert set(got) == {(p["type"], p["where"]) for p in planted}, res.effects_added
    truths = {(p["type"], p["where"], k): v for p in planted for k, v in p.items() if isinstance(v, float)}
    assert set(CHECKS[case]) <= set(truths), CHECKS[case]
    for p in planted:
        e = got[(p["type"], p["where"])]
        assert e.get("options", {}) == ({"grows_with": p["grows_with"]} if p.get("grows_with") else {}), e
    for (name, where, k), (tol, inside) in CHECKS[case].items():
        truth, v, u = (
            truths[(name, where, k)],
            got[(name, where)]["parameters"][k],
            got[(name, where)]["uncertainty"][k],
        )
        assert abs(v - truth) <= tol * (abs(truth) if truth else 1.0), (name, where, k, v, u, truth)
        assert 0 < u < (0.1 * abs(truth) if truth else 0.01), (name, where, k, v, u)  # 0.3-6.7 % measured
        assert not inside or abs(v - truth) <= u, (name, where, k, v, u, truth)
    floor = cases["clean_payload" if PAYLOAD.get(case) else "clean"].error_before
    assert res.error_after < res.error_before, (res.error_before, res.error_after)
    assert res.error_after <= NEAR_FLOOR.get(case, 1.05) * floor, (res.error_before, res.error_after, floor)
    assert math.isfinite(res.error_after)
    assert res.unexplained is None, res.unexplained


# ------------------------------------------------------------------ foundation mode
#: (mass kg, frequency Hz) of the reaction mass on springs planted: CGS's own 6400 t at the
#: 30 Hz its description assumes for mode = "spring", and a 1000 t one at 8 Hz (softer and
#: lighter than CGS's; assumed, to move the table's motion by ~10 %)
FOUNDATIONS = ((6.4e6, 30.0), (1.0e6, 8.0))


@pytest.mark.parametrize("mass_kg, frequency_hz", FOUNDATIONS)
def test_foundation_mode_hides_in_the_sensor_noise_on_the_mechanical_path(tmp_path, mass_kg, frequency_hz):
    """The actuators push off the foundation: the force the platen needs for its recorded
    (absolute) motion does not depend on how the foundation moves, except through the
    linkages' own terms (stroke = platen minus foundation end: seal drag and friction on
    the stroke velocity, the supports' springs, the cylinders swinging on the foundation's
    swivels). A planted foundation mode changes the table's motion (what the replay path
    compares) by several %, but the mechanical residual of the declared model (no mode)
    by less than the sensor noise adds to it: not identifiable on this path.

    Measured (2.5 s random run, whole record): residual NRMSE 0.42 % clean, 0.48 % with
    6400 t at 30 Hz, 1.32 % with 1000 t at 8 Hz (0.22 % and 1.25 % added in quadrature),
    3.95 % measured through the sensor model, its accelerations through the table's
    declared 300 Hz conditioner (4.27 % when the record had none and the model's
    acceleration was compared unfiltered). (A 1000 t mass at 4 Hz, in
    the band of the run, reaches 3.1 %: see docs/calibration.md.)"""
    import numpy as np

    import mjcf
    from sim.calibrate import residuals as R
    from sim.runs.runfile import read_run

    desc = mjcf.load_table("cgs")
    fd = {"type": "foundation_mode", "mass_kg": mass_kg, "frequency_hz": frequency_hz, "damping_ratio": 0.05}
    planted = _cgs_raw()
    planted["effect"] = [fd] + list(planted.get("effect", []))  # foundation_mode first (it moves bodies)
    jobs = [
        (_cgs_raw(), "random", 5, tmp_path / "clean.run.npz", False),
        (_cgs_raw(), "random", 5, tmp_path / "measured.run.npz", True),
        (planted, "random", 5, tmp_path / "foundation.run.npz", False),
    ]
    runs = [read_run(simulate_measured(j)) for j in jobs]
    clean, measured, found = (R.mechanical_runs([r], desc)[0] for r in runs)
    e_clean, e_meas, e_found = (R.nrmse_runs([m], [m.residual]) for m in (clean, measured, found))
    noise = math.sqrt(max(e_meas**2 - e_clean**2, 0.0))  # what the sensor model adds
    extra = math.sqrt(max(e_found**2 - e_clean**2, 0.0))  # what the foundation mode adds
    print(f"residual NRMSE clean {e_clean:.4f}, foundation {e_found:.4f}, measured {e_meas:.4f}")
    moved = np.linalg.norm(runs[2].table_acceleration - runs[0].table_acceleration, axis=0) / np.linalg.norm(
        runs[0].table_acceleration, axis=0
    )
    assert moved.max() > 0.05, moved  # the planted mode is there: the table moves differently
    assert extra < 0.5 * noise, (e_clean, e_found, e_meas)


@pytest.mark.slow
def test_a_motion_two_samples_late_is_timed_by_the_acceleration(cases):
    """The vertical seals' 8 kN with the displacement and the velocity 2 samples (1.953 ms)
    late, undeclared: the acceleration reads the motion's delay (1.985 +/- 0.087 ms
    measured) and the friction is what it is on time (8 004.3 +/- 60.8 N; on time
    8 004.4 +/- 59.6), held out at the clean floor (2.030 % against 2.010 %). Before the
    anchor read 8 segments or more, such a 2.5 s record read 0.75 ms and took a spring
    about ry beside it."""
    res = cases["coulomb_class_vertical_motion_late"]
    got = {(e["name"], e["where"]): e for e in res.effects_added}
    assert set(got) == {("coulomb_friction", "class:vertical"), ("sensor_delay", "channel:table_displacement")}, got
    d, u = (got[("sensor_delay", "channel:table_displacement")][k]["delay_s"] for k in ("parameters", "uncertainty"))
    assert abs(d - 2 / 1024) <= u < 2e-4, (d, u)
    f, uf = (got[("coulomb_friction", "class:vertical")][k]["force_n"] for k in ("parameters", "uncertainty"))
    assert abs(f - 8000.0) <= uf and abs(f - 8000.0) < 0.002 * 8000.0, (f, uf)
    assert res.error_after <= 1.05 * cases["clean"].error_before, (res.error_after, cases["clean"].error_before)


@pytest.mark.slow
def test_load_cells_reading_high_are_their_gain_on_six_dofs(cases):
    """Every load cell 5 % high, nothing planted in the table: the load cells' gain alone,
    1.04866 +/- 0.00071 measured, held out 5.13 % -> 1.99 % (the clean floor 2.01 %). The
    clean records read 0.99872 (refused: within a transducer's 0.5 %), the declared model's
    own scale against the simulated truth, so the truth sits 1.9 intervals out."""
    res = cases["load_cells_high"]
    assert [(e["name"], e["where"]) for e in res.effects_added] == [("sensor_gain", "channel:actuator_force")]
    g, u = (res.effects_added[0][k]["gain"] for k in ("parameters", "uncertainty"))
    assert abs(g - 1.05) <= 2 * u < 2e-3, (g, u)
    assert res.error_after < 0.5 * res.error_before, (res.error_before, res.error_after)
    assert res.error_after <= 1.05 * cases["clean"].error_before, (res.error_after, cases["clean"].error_before)


@pytest.mark.slow
def test_one_class_of_load_cells_reading_high_is_that_class_gain(cases):
    """The vertical class's four load cells 5 % high, nothing planted: that class's gain,
    written at its force columns, 1.04981 +/- 0.00111 measured, nothing else; held out
    3.74 % -> 1.96 % (the clean floor 2.01 %). Before the class's candidate an added mass of
    530 kg on the class, 520 kg in z and a friction of 554 N on the class stood for it."""
    res = cases["vertical_load_cells_high"]
    assert [(e["name"], e["where"]) for e in res.effects_added] == [
        ("sensor_gain", "channel:actuator_force[8,9,10,11]")
    ]
    g, u = (res.effects_added[0][k]["gain"] for k in ("parameters", "uncertainty"))
    assert abs(g - 1.05) <= u < 2e-3, (g, u)
    assert res.error_after < 0.6 * res.error_before, (res.error_before, res.error_after)
    assert res.error_after <= 1.05 * cases["clean"].error_before, (res.error_after, cases["clean"].error_before)


@pytest.mark.slow
def test_one_load_cell_reading_high_is_its_own_gain(cases):
    """Z1's load cell alone 5 % high (a transducer's calibration), nothing planted: its
    gain at its column, 1.04729 +/- 0.00248 measured (the truth 1.1 intervals out), nothing
    else; held out 2.59 % -> 2.00 % (the clean floor 2.01 %). A load cell of X1's push-pull
    pair (X1 and X3 on one line) has no gain of its own to tell: an added mass of 405 kg at
    X1 stood for X1's 5 %."""
    res = cases["z1_load_cell_high"]
    assert [(e["name"], e["where"]) for e in res.effects_added] == [("sensor_gain", "channel:actuator_force[8]")]
    g, u = (res.effects_added[0][k]["gain"] for k in ("parameters", "uncertainty"))
    assert abs(g - 1.05) <= 2 * u < 0.005, (g, u)
    assert res.error_after <= 1.05 * cases["clean"].error_before, (res.error_after, cases["clean"].error_before)


@pytest.mark.slow
def test_one_class_of_load_cells_beside_a_mass_is_both(cases):
    """The vertical class's load cells 5 % high and 6 t in z nobody declared: the vertical
    force is mostly the z inertia, so alone the class's gain took the mass in (1.095) and an
    added mass at the supports explained more (then 4.2 t in z and a friction). Judged
    first where the two together predict better (sim/calibrate/gainpair.py): 1.05036 +/-
    0.00154 and 5 925 +/- 118 kg measured, nothing else; held out 6.82 % -> 1.94 %."""
    res = cases["vertical_load_cells_high_mass_z"]
    found = {(e["name"], e["where"]): e for e in res.effects_added}
    assert sorted(found) == [("added_mass", "dof:z"), ("sensor_gain", "channel:actuator_force[8,9,10,11]")], found
    g, u = (
        found[("sensor_gain", "channel:actuator_force[8,9,10,11]")][k]["gain"] for k in ("parameters", "uncertainty")
    )
    assert abs(g - 1.05) <= u < 3e-3, (g, u)
    m, um = (found[("added_mass", "dof:z")][k]["mass_kg"] for k in ("parameters", "uncertainty"))
    assert abs(m - 6000.0) <= um < 0.03 * 6000.0, (m, um)
    assert res.error_after < 0.35 * res.error_before, (res.error_before, res.error_after)
