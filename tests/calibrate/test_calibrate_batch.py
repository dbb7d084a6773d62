"""Calibration candidates on the batch route (sim.calibrate.paths.simulate_many /
simulate_jobs: MuJoCo's batch with the twin inside ``mj_step``, or each simulation's
own run where the callback cannot take it): the compared channels of every job equal
the one-job-at-a-time ``simulate_job`` bit for bit, on the replay and the closed-loop
path."""

from __future__ import annotations

import copy

import numpy as np
import pytest

SECONDS = 1.0


@pytest.fixture(scope="module")
def short_run(tmp_path_factory):
    """A 1 s CGS run (2-axis band-limited noise, closed loop), measured through the
    built-in recorder model (seeded), read back as a record."""
    import mjcf
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.measure import load_sensors, measure_run
    from sim.runs.runfile import read_run, write_run
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    desc = mjcf.load_table("cgs")
    tm = build_model(desc)
    mo = {
        d: M.white_noise(
            duration_s=SECONDS, sample_rate_hz=1024.0, band_hz=(2.0, 30.0), seed=(11, k), rms_acceleration=0.8
        )
        for k, d in enumerate(("x", "z"))
    }
    ref = reference_from_motions(mo, 1024.0, SECONDS)
    res = Simulation(tm).run(reference=ref)
    assert res.incomplete_reason is None
    run = build_runfile(res, tm, source="simulated", reference=ref)
    path = write_run(tmp_path_factory.mktemp("cb") / "cgs.run.npz", measure_run(run, load_sensors(), seed=11))
    return desc, read_run(path)


EXTRAS = [
    [],  # the declared model
    [{"type": "valve_flow_gain", "where": "actuator:X1", "factor": 0.9}],
    [{"type": "bulk_modulus", "where": "class:vertical", "bulk_modulus_pa": 0.9e9}],
    [{"type": "valve_delay", "where": "class:vertical", "delay_s": 2 / 2048}],  # not on the callback: fallback
    [{"type": "valve_flow_gain", "where": "class:lateral", "factor": 0.0}],  # refused by the model: None
]


def _equal(a, b):
    assert (a is None) == (b is None)
    if a is None:
        return
    assert set(a) == set(b)
    for c in a:
        assert np.array_equal(a[c], b[c]), c


@pytest.mark.parametrize("path", ["replay", "closed_loop"])
def test_batch_route_equals_one_job_at_a_time(short_run, path):
    from sim.calibrate import paths as P

    desc, run = short_run
    (pr,) = P.path_runs([run], desc, path)
    pr = pr.window(0.5)
    jobs = [pr.job(copy.deepcopy(desc.raw), str(desc.source), None, e) for e in EXTRAS]
    one = [P.simulate_job(j) for j in jobs]
    assert all(m is not None for m in one[:4]) and one[4] is None
    assert not np.array_equal(one[0]["actuator_force"], one[1]["actuator_force"])  # the candidates act
    assert not np.array_equal(one[0]["actuator_force"], one[2]["actuator_force"])
    counts: dict = {}
    here = P.simulate_jobs(jobs, counts)
    assert counts == {"batch": 3, "fallback": 1}
    counts2: dict = {}
    pooled = P.simulate_many(jobs, workers=2, counts=counts2)
    assert counts2 == counts
    for a, b, c in zip(one, here, pooled):
        _equal(a, b)
        _equal(a, c)


@pytest.fixture(scope="module")
def lab_run():
    """1 s of the bearing-guided ``lab`` table with its two-storey frame (band-limited
    noise along x, closed loop), as a record."""
    import mjcf
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    desc, pay = mjcf.load_table("lab"), mjcf.load_payload("lab_2storey")
    tm = build_model(desc, pay)
    mo = {
        "x": M.white_noise(duration_s=SECONDS, sample_rate_hz=1024.0, band_hz=(2.0, 15.0), seed=5, rms_acceleration=1.0)
    }
    ref = reference_from_motions(mo, 1024.0, SECONDS)
    res = Simulation(tm).run(reference=ref)
    assert res.incomplete_reason is None
    return desc, pay, build_runfile(res, tm, source="simulated", reference=ref, payload_name="lab_2storey")


@pytest.mark.parametrize("path", ["replay", "closed_loop"])
def test_guided_table_replays_take_the_batch_route(lab_run, path):
    """A uni-axial table's platen runs on bearings: its replays (open loop) and its
    closed-loop runs (the compiled controller reads the slides) take the batch route, bit
    for bit, each its own ``simulate_job``."""
    from sim.calibrate import paths as P

    desc, pay, run = lab_run
    (pr,) = P.path_runs([run], desc, path)
    extras = [
        [],
        [{"type": "valve_flow_gain", "where": "actuator:A", "factor": 0.9}],
        [{"type": "bulk_modulus", "where": "actuator:A", "bulk_modulus_pa": 0.7e9}],
    ]
    jobs = [pr.job(copy.deepcopy(desc.raw), str(desc.source), pay, e) for e in extras]
    one = [P.simulate_job(j) for j in jobs]
    assert all(m is not None for m in one)
    assert not np.array_equal(one[0]["table_acceleration"], one[1]["table_acceleration"])  # the candidates act
    counts: dict = {}
    here = P.simulate_jobs(jobs, counts)
    assert counts == {"batch": 3, "fallback": 0}
    for a, b in zip(one, here):
        _equal(a, b)
