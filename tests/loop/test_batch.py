"""The coupled step inside MuJoCo (sim.loop.callback) and the batch (sim.loop.batch)
against the reference loop: the same runs, bit for bit."""

from pathlib import Path

import mujoco
import numpy as np
import pytest

from sim.assess.run import plan_scenario
from sim.loop.batch import BatchRunner
from sim.loop.callback import installed, run_callback

DUR = 0.25  # s: 257 ticks, 512 physics steps

SCENARIO = """
[scenario]
name = "sine_20t"
table = "cgs"
payload = "rigid_20t"
duration_s = 1.0
description = "test: 4 Hz sine, x and z, 20 t block (accelerations about 3 m/s^2 from the first tick)"
[motion.x]
type = "sine"
amplitude = 0.005
frequency_hz = 4.0
[motion.z]
type = "sine"
amplitude = 0.002
frequency_hz = 4.0
"""


@pytest.fixture(scope="module")
def scenario(tmp_path_factory):
    path = tmp_path_factory.mktemp("scen") / "sine_20t.toml"
    path.write_text(SCENARIO)
    return str(path)


def _same(a, b):
    assert len(a.t) == len(b.t)
    assert a.incomplete_reason == b.incomplete_reason
    for k in a.channels:
        assert np.array_equal(a.channels[k], b.channels[k], equal_nan=True), k
    for k in a.extras:
        assert np.array_equal(a.extras[k], b.extras[k], equal_nan=True), k


def _plan(scenario, overrides=None):
    return plan_scenario(scenario, duration_s=DUR, iterations=0, overrides=overrides)


def test_callback_run_equals_the_loop_bit_for_bit(scenario):
    p = _plan(scenario)
    sim, ref = p.sim, p.reference
    sim.reset()
    loop = sim.run(reference=ref)
    sim.reset()
    cb = run_callback(sim, ref)
    assert np.abs(loop.channels["actuator_force"]).max() > 1e3  # a run that does something
    assert np.isfinite(loop.extras["loop_gap"][::8]).all()
    _same(loop, cb)
    # the run left the Simulation's own state alone: running the loop again gives the same
    sim.reset()
    _same(loop, sim.run(reference=ref))


def test_callback_leaves_other_simulations_alone(scenario):
    """With the callback installed, an MjData without a context (userdata[0] = 0) steps
    as plain MuJoCo."""
    p = _plan(scenario)
    m = p.sim.m
    d1, d2 = mujoco.MjData(m), mujoco.MjData(m)
    d1.ctrl[:] = d2.ctrl[:] = 1e4
    mujoco.mj_step(m, d1, nstep=20)
    with installed():
        assert mujoco.get_mjcb_control() is not None
        mujoco.mj_step(m, d2, nstep=20)
    assert np.array_equal(d1.qpos, d2.qpos)


def test_batch_of_n_equals_n_single_runs(scenario):
    ovs = [
        {},
        {
            "table.fluid.bulk_modulus_pa": 0.7e9,
            "payload.mass_kg": {"scale": 1.2},
            "payload.inertia_kg_m2": {"scale": 1.2},
        },
        {
            "table.actuator_class.*.seal_friction_n": {"scale": 2.0},
            "motion.*.amplitude": {"scale": 1.2},
            "controller.kp_per_s": 20.0,
        },
    ]
    plans = [_plan(scenario, o) for o in ovs]
    singles = []
    for p in plans:
        p.sim.reset()
        singles.append(p.sim.run(reference=p.reference))
        p.sim.reset()
    runner = BatchRunner([p.sim for p in plans], nthread=2)
    res = runner.run([p.reference for p in plans])
    for a, b in zip(singles, res):
        _same(a, b)
    # the per-simulation parameters took effect: the three runs differ
    f = [r.channels["actuator_force"] for r in res]
    assert not np.array_equal(f[0], f[1]) and not np.array_equal(f[0], f[2])
    assert runner.force.shape == (3, plans[0].tm.n_act)


def test_batch_rejects_python_callbacks(scenario):
    from mujoco import batch as mjbatch

    p = _plan(scenario)
    b = mjbatch.Batch(p.sim.m, 2, 1)
    prev = mujoco.get_mjcb_control()
    mujoco.set_mjcb_control(lambda m, d: None)
    try:
        with pytest.raises(ValueError, match="mjcb_control"):
            b.step()
    finally:
        mujoco.set_mjcb_control(prev)
    # a C function (ours) is accepted
    with installed():
        b.step()
    assert np.isfinite(b.qpos).all()


def test_mujoco_rollout_runs_the_twin(scenario):
    """mujoco.rollout (C threads, no Python per step) with the callback gives the loop's run."""
    from mujoco import rollout

    from sim.loop import callback as CB

    p = _plan(scenario)
    sim, ref = p.sim, p.reference
    sim.reset()
    loop = sim.run(reference=ref)
    sim.reset()
    m2 = CB.callback_model(sim)
    d2 = mujoco.MjData(m2)
    CB.copy_state(sim.m, sim.d, m2, d2)
    st = {
        "X": sim.hs._X.copy(),
        "Y": sim.hs._Y.copy(),
        "IC": sim.hs._IC.copy(),
        "ICS": sim.hs._ICS.copy(),
        "ZFR": sim._zfr.copy(),
    }
    ctx = CB.Context(sim, ref, len(loop.t), state=st)
    d2.userdata[0], d2.userdata[1] = ctx.address, 0.0  # user state: taken from the MjData by rollout
    spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
    s0 = np.empty(mujoco.mj_stateSize(m2, spec))
    mujoco.mj_getState(m2, d2, s0, spec)
    with installed():
        rollout.rollout(m2, d2, s0[None], nstep=len(loop.t) * sim.steps_per_tick)
    _same(loop, ctx.result(0.0, (d2.qpos, d2.qvel)))


def test_callback_stops_where_the_loop_stops(scenario):
    """The divergence check inside the callback: a relief setting below the run's peak
    chamber pressure stops both routes at the same tick with the same reason."""
    import dataclasses

    p = _plan(scenario)
    sim, ref = p.sim, p.reference
    sim.reset()
    full = sim.run(reference=ref)
    peak = max(np.nanmax(full.channels["pressure_a"]), np.nanmax(full.channels["pressure_b"]))
    sim.hp = dataclasses.replace(sim.hp, relief_pressure_pa=0.97 * peak)  # the check's limit only
    sim.reset()
    loop = sim.run(reference=ref)
    sim.reset()
    cb = run_callback(sim, ref)
    assert loop.incomplete_reason and "above the relief pressure" in loop.incomplete_reason
    assert 1 < len(loop.t) < len(full.t)
    _same(loop, cb)
    res = BatchRunner([sim], nthread=1).run([ref])[0]
    _same(loop, res)


def test_callback_stops_where_the_loop_stops_when_mujoco_resets(scenario):
    """Actuator forces 1e12 times too large: MuJoCo's accelerations pass its limit in the
    first step, it warns (mjWARN_BADQACC) and resets the whole MjData, userdata included, so
    the callback loses the simulation. The single route reads the warning counter, the batch
    sees the callback stop counting steps: both stop at the loop's tick, the single route
    with the loop's reason (before: a full-length run, stopped by the swivel gap at its end)."""
    p = _plan(scenario)
    sim, ref = p.sim, p.reference
    for a in sim.tm.spec.actuators:  # the callback compiles its model from the spec
        g = np.array(a.gear)
        g[0] *= 1e12
        a.gear = g
    sim.m.actuator_gear[:, 0] *= 1e12
    sim.reset()
    loop = sim.run(reference=ref)
    assert loop.incomplete_reason and "mjWARN_BADQACC" in loop.incomplete_reason
    assert len(loop.t) < 5
    sim.reset()
    cb = run_callback(sim, ref)
    # the tick's gap: the loop measures it after the tick's steps (on the state MuJoCo reset
    # to), the callback inside the tick's last step (on the state before the reset)
    assert loop.extras["loop_gap"][-1] < 1e-9 < 1e-3 < cb.extras["loop_gap"][-1]
    loop.extras["loop_gap"] = loop.extras["loop_gap"][:-1]
    cb.extras["loop_gap"] = cb.extras["loop_gap"][:-1]
    _same(loop, cb)
    sim.reset()
    res = BatchRunner([sim, sim], nthread=1).run([ref, ref])
    for r in res:
        assert len(r.t) == len(loop.t)
        assert r.incomplete_reason.startswith(loop.incomplete_reason.split(":")[0])  # same time
        assert "MuJoCo reset the state" in r.incomplete_reason


def test_run_many_groups_batches_and_keeps_the_order(scenario):
    """run_many: the shared route for N simulations. With group=2, three simulations
    (other bulk modulus / mass) make two batches; each result equals its own loop run,
    in the order given."""
    from sim.loop.batch import run_many

    ovs = [None, {"table.fluid.bulk_modulus_pa": 0.6e9}, {"payload.mass_kg": {"scale": 1.3}}]
    plans = [_plan(scenario, o) for o in ovs]
    for p in plans:
        p.sim.reset()
    many = run_many([p.sim for p in plans], [p.reference for p in plans], nthread=2, group=2)
    for o, got in zip(ovs, many):
        p = _plan(scenario, o)
        p.sim.reset()
        _same(p.sim.run(reference=p.reference), got)
    assert not np.array_equal(many[0].channels["actuator_force"], many[1].channels["actuator_force"])
    with pytest.raises(ValueError, match="group"):
        run_many([plans[0].sim], [plans[0].reference], group=0)


#: the worked example's white noise on the bearing-guided ``lab`` table with its 2-storey frame
LAB_NOISE = str(Path(__file__).resolve().parents[2] / "scenarios" / "lab_example" / "lab_noise.toml")


def test_bearing_guided_tables_run_closed_loop_on_the_batch_bit_for_bit():
    """Platens on slides (``lab`` with its frame, the UCSD LHPOST with its power damping):
    the controller reads the slides' velocity (not a free joint's), the batch and run_many
    take them closed loop, each result its own ``Simulation.run``."""
    from sim.loop.batch import run_many
    from sim.loop.callback import accepts

    lab_ovs = [
        {},
        {"table.fluid.bulk_modulus_pa": 0.8e9, "payload.mass_kg": {"scale": 1.3}},
        {"controller.kp_per_s": 20.0, "motion.x.rms_acceleration": {"scale": 1.3}},
    ]
    plans = [_plan(LAB_NOISE, o) for o in lab_ovs]
    plans += [_plan("ucsd_s10"), _plan("ucsd_s10", {"table.fluid.bulk_modulus_pa": 0.7e9})]
    singles = []
    for p in plans:
        assert not p.sim.tm.platen_free and accepts(p.sim) is None
        p.sim.reset()
        singles.append(p.sim.run(reference=p.reference))
        p.sim.reset()
    res = BatchRunner([p.sim for p in plans[:3]], nthread=2).run([p.reference for p in plans[:3]])
    for a, b in zip(singles, res):
        _same(a, b)
    f = [r.channels["actuator_force"] for r in res]
    assert np.abs(f[0]).max() > 300.0 and not np.array_equal(f[0], f[1]) and not np.array_equal(f[0], f[2])
    for p in plans:
        p.sim.reset()
    counts: dict = {}
    many = run_many([p.sim for p in plans], [p.reference for p in plans], nthread=2, group=2, counts=counts)
    assert counts == {"batch": 5, "fallback": 0}
    for a, b in zip(singles, many):
        _same(a, b)
    assert not np.array_equal(many[3].channels["actuator_force"], many[4].channels["actuator_force"])
