"""Open loop on the callback route (sim.loop.callback with valve commands, the batch and
run_many): the same runs as ``Simulation.run(valve_command=...)``, bit for bit, as a
calibration replay runs them (the CGS table, the controller at the record's 1024 Hz)."""

import copy

import numpy as np
import pytest

from sim.loop.batch import BatchRunner, run_many
from sim.loop.callback import accepts, run_callback

N_TICK = 203  # 0.2 s at 1024 Hz; 202 is not a multiple of the gap check's 8 ticks (the last tick's check)


def _sim(effects=()):
    import mjcf
    from mjcf.description import parse_table
    from sim.control.tvc import ControllerGains
    from sim.effects import build_model
    from sim.loop.simulation import Simulation

    base = mjcf.load_table("cgs")
    raw = copy.deepcopy(base.raw)
    raw["effect"] = list(raw.get("effect", [])) + [dict(e) for e in effects]
    return Simulation(build_model(parse_table(raw, src=base.source)), gains=ControllerGains(rate_hz=1024.0))


def _commands(seed, n=N_TICK, na=12):
    """Zero-mean valve commands (fraction of rated opening): a few sines per valve."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 1024.0
    f = rng.uniform(2.0, 15.0, size=(3, na))
    ph = rng.uniform(0, 2 * np.pi, size=(3, na))
    return 0.02 * np.sin(2 * np.pi * f[None] * t[:, None, None] + ph[None]).sum(axis=1)


def _same(a, b):
    assert len(a.t) == len(b.t)
    assert a.incomplete_reason == b.incomplete_reason
    assert set(a.channels) == set(b.channels) and set(a.extras) == set(b.extras)
    for k in a.channels:
        assert np.array_equal(a.channels[k], b.channels[k], equal_nan=True), k
    for k in a.extras:
        assert np.array_equal(a.extras[k], b.extras[k], equal_nan=True), k


VARIANTS = [
    (),
    ({"type": "bulk_modulus", "where": "class:vertical", "bulk_modulus_pa": 0.8e9},),
    ({"type": "valve_flow_gain", "where": "actuator:X2", "factor": 1.15},),
]


def test_open_loop_callback_run_equals_the_loop_bit_for_bit():
    sim = _sim()
    assert accepts(sim) is None
    vc = _commands(1)
    sim.reset()
    loop = sim.run(valve_command=vc)
    sim.reset()
    cb = run_callback(sim, valve_command=vc)
    assert np.abs(loop.channels["actuator_force"]).max() > 1e3  # a run that does something
    assert np.abs(np.diff(loop.channels["table_acceleration"], axis=0)).max() > 0
    assert np.array_equal(loop.channels["valve_command"], vc)
    assert np.isfinite(loop.extras["loop_gap"][-1])  # the last tick's gap (202 % 8 != 0)
    for k in ("valve_command", "spool_position", "actuator_force", "pressure_a", "pressure_b"):
        assert k in cb.channels
    for k in ("supply_pressure", "accumulator_gas_volume", "loop_gap"):
        assert k in cb.extras
    _same(loop, cb)
    with pytest.raises(ValueError, match="exactly one"):
        run_callback(sim)


def test_open_loop_batch_and_run_many_equal_single_runs():
    """Three simulations (declared, other bulk modulus, other flow gain of one valve) on
    three command arrays of different lengths: the batch and run_many give each its own
    ``Simulation.run(valve_command=...)``."""
    sims = [_sim(v) for v in VARIANTS]
    vcs = [_commands(10 + i, n=N_TICK - 17 * i) for i in range(3)]
    singles = []
    for s, vc in zip(sims, vcs):
        s.reset()
        singles.append(s.run(valve_command=vc))
        s.reset()
    res = BatchRunner(sims, nthread=2).run(valve_commands=vcs)
    for a, b in zip(singles, res):
        _same(a, b)
    # the parameters took effect: the same commands on other parameters give other forces
    same_cmd = run_many(sims, valve_commands=[vcs[0]] * 3, nthread=1)
    f = [r.channels["actuator_force"] for r in same_cmd]
    assert not np.array_equal(f[0], f[1]) and not np.array_equal(f[0], f[2])
    # run_many: a simulation the callback does not take (a valve delay) runs its own loop
    delayed = _sim(({"type": "valve_delay", "where": "class:vertical", "delay_s": 2 / 2048},))
    assert accepts(delayed) is not None
    for s in sims:
        s.reset()
    counts: dict = {}
    many = run_many(sims + [delayed], valve_commands=vcs + [vcs[0]], nthread=2, group=2, counts=counts)
    assert counts == {"batch": 3, "fallback": 1}
    for a, b in zip(singles, many):
        _same(a, b)
    delayed.reset()
    _same(delayed.run(valve_command=vcs[0]), many[3])
    with pytest.raises(ValueError, match="exactly one"):
        run_many(sims, references=[None] * 3, valve_commands=vcs)


def test_run_many_keeps_models_of_other_tendon_layouts_apart():
    """A spring or damper at a DOF adds a tendon (nq, nv, nu, nbody unchanged): such a model
    and the declared one gave ``mjb_setModels: ... does not give mjData the batch model's
    layout`` in one batch (a calibration screening the whole library on the replay path).
    run_many puts them in batches of their own, each result its own run's."""
    sims = [_sim(), _sim(({"type": "spring", "where": "dof:x", "stiffness_n_m": 2e7},)), _sim()]
    assert sims[0].m.ntendon != sims[1].m.ntendon and sims[0].m.nv == sims[1].m.nv
    vcs = [_commands(20 + i, n=N_TICK) for i in range(3)]
    singles = []
    for s, vc in zip(sims, vcs):
        s.reset()
        singles.append(s.run(valve_command=vc))
        s.reset()
    counts: dict = {}
    many = run_many(sims, valve_commands=vcs, nthread=1, counts=counts)
    assert counts == {"batch": 3, "fallback": 0}
    for a, b in zip(singles, many):
        _same(a, b)


def test_closed_loop_callback_checks_the_last_tick_as_the_loop_does():
    """The loop measures the gap (and checks) on the last tick whatever its number; the
    callback now does too (before, a run whose last tick was not a multiple of 8 had NaN
    there on the callback route)."""
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    sim = _sim()
    mo = {"x": M.white_noise(duration_s=1.0, sample_rate_hz=1024.0, band_hz=(2.0, 20.0), seed=7, rms_acceleration=0.5)}
    ref = reference_from_motions(mo, 1024.0, 1.0)
    sim.reset()
    loop = sim.run(reference=ref, duration_s=0.2)
    assert (len(loop.t) - 1) % 8 and np.isfinite(loop.extras["loop_gap"][-1])
    sim.reset()
    _same(loop, run_callback(sim, ref, duration_s=0.2))


def _lab_sim(payload=None, foundation=None):
    """The bearing-guided uni-axial ``lab`` table (optionally with a payload, or its
    foundation on springs) at the replay's 1024 Hz ticks."""
    import mjcf
    from mjcf.description import parse_table
    from sim.control.tvc import ControllerGains
    from sim.effects import build_model
    from sim.loop.simulation import Simulation

    base = mjcf.load_table("lab")
    raw = copy.deepcopy(base.raw)
    if foundation:
        raw["foundation"]["mode"] = foundation
    tm = build_model(parse_table(raw, src=base.source), mjcf.load_payload(payload) if payload else None)
    return Simulation(tm, gains=ControllerGains(rate_hz=1024.0))


def test_a_bearing_guided_table_replays_on_the_callback_bit_for_bit():
    """Calibration replays of the ``lab`` tables (platen on bearings) once all fell back
    from the batch route: the callback recorded the platen's acceleration as a free
    platen's six DOFs. Open loop it records the slides' (plus a spring-mounted
    foundation's) as the loop does (closed loop too: tests/loop/test_batch.py)."""
    sims = [_lab_sim(), _lab_sim("lab_2storey"), _lab_sim(foundation="spring")]
    assert not sims[0].tm.platen_free and sims[2]._fnd_d is not None
    vcs = [_commands(30 + i, na=1) for i in range(3)]
    singles = []
    for s, vc in zip(sims, vcs):
        assert accepts(s, open_loop=True) is None
        assert accepts(s) is None  # closed loop too (the controller reads the slides)
        s.reset()
        singles.append(s.run(valve_command=vc))
        s.reset()
        _same(singles[-1], run_callback(s, valve_command=vc))
        s.reset()
    a = singles[0].channels["table_acceleration"]
    assert np.abs(a[:, 0]).max() > 0.1  # a run that moves the platen
    assert np.array_equal(a[:, 1:], np.zeros_like(a[:, 1:]))  # the guided DOF only (x)
    counts: dict = {}
    many = run_many(sims[:2], valve_commands=vcs[:2], nthread=1, counts=counts)
    assert counts == {"batch": 2, "fallback": 0}
    for one, b in zip(singles, many):
        _same(one, b)
    with pytest.raises(ValueError, match="valve_commands"):
        BatchRunner(sims[:1], open_loop=True).run([None])


def test_a_bearing_guided_table_on_springs_runs_closed_loop_on_the_callback_bit_for_bit():
    """Closed loop on the ``lab`` table with its frame and its foundation on springs: the
    controller reads the platen's slide (relative to the foundation), the recorder the
    absolute acceleration; the callback gives the loop's run."""
    from sim.scenario import motions as M
    from sim.scenario.reference import reference_from_motions

    sim = _lab_sim("lab_2storey", foundation="spring")
    mo = {"x": M.white_noise(duration_s=1.0, sample_rate_hz=1024.0, band_hz=(2.0, 20.0), seed=3, rms_acceleration=2.0)}
    ref = reference_from_motions(mo, 1024.0, 1.0)
    assert sim._fnd_d is not None and accepts(sim) is None
    sim.reset()
    loop = sim.run(reference=ref, duration_s=0.2)
    assert np.abs(loop.channels["actuator_force"]).max() > 1e3  # a run that does something
    sim.reset()
    _same(loop, run_callback(sim, ref, duration_s=0.2))


def test_a_per_step_power_damping_replays_on_the_callback_bit_for_bit():
    """The UCSD LHPOST's ``platen_power_damping`` (a per-step effect on the platen's
    slide) once sent its replays to the loop; the callback computes it with the effect's
    own formula and constants, so the replay is the loop's, bit for bit."""
    import mjcf
    from sim.control.tvc import ControllerGains
    from sim.effects import build_model
    from sim.loop.simulation import Simulation

    sim = Simulation(build_model(mjcf.load_table("ucsd")), gains=ControllerGains(rate_hz=1024.0))
    assert [e.type for e in sim.tm.step_effects] == ["platen_power_damping"] and accepts(sim, open_loop=True) is None
    vc = 5 * _commands(40, na=sim.tm.n_act)
    sim.reset()
    loop = sim.run(valve_command=vc)
    assert np.abs(loop.channels["table_velocity"][:, 0]).max() > 0.01  # above the damping's 1 mm/s linear zone
    sim.reset()
    _same(loop, run_callback(sim, valve_command=vc))
