"""Hydraulic effects (sim/effects/hydraulic.py): plant one, check it against a closed form.

Most checks run the 2-actuator uni-axial table (scenarios/tables/ucsd.toml) with its
platen effects removed (the platen is then a free mass on the two actuators) for about
a second of simulated time.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np
import pytest

import mjcf
from hydraulics import HydraulicParams, HydraulicSystem
from hydraulics._layout import S_GPA as NX_STATE
from mjcf.description import parse_table
from sim.effects import build_model
from sim.effects.base import create
from sim.errors import ScenarioError
from sim.loop.simulation import Simulation
from sim.scenario.reference import Reference

TABLES = Path(__file__).resolve().parents[2] / "scenarios" / "tables"
UNIAXIAL = TABLES / "ucsd.toml"
HEXAPOD = TABLES / "cgs.toml"


@pytest.fixture(scope="module")
def base():
    return mjcf.load_table(UNIAXIAL)


def simulation(base, effects, *, keep_platen=False):
    raw = copy.deepcopy(base.raw)
    raw["effect"] = (raw.get("effect", []) if keep_platen else []) + list(effects)
    return Simulation(build_model(parse_table(raw, "test table")))


def areas(base):
    c = base.raw["actuator_class"]
    return c["east"]["area_a_m2"], c["west"]["area_a_m2"]


def hold_still(sim, seconds):
    n = int(round(seconds * sim.gains.rate_hz))
    z = np.zeros((n, 6))
    return sim.run(reference=Reference(t=np.arange(n) / sim.gains.rate_hz, d=z, v=z, a=z))


def drift_velocity(res, t0=0.5):
    """Mean platen velocity after t0 (slope of a line through the displacement: the
    oil-column ringing averages out)."""
    k = res.t >= t0
    return float(np.polyfit(res.t[k], res.channels["table_displacement"][k, 0], 1)[0])


# ---------------------------------------------------------------- kernel and reference
@pytest.mark.parametrize("model", ["second", "first"])
def test_per_actuator_valves_numba_equals_numpy(model):
    """Both backends agree with different delays, bandwidths, gains, offsets and bulk
    moduli per actuator (12 actuators of the hexapod, random commands and motion)."""
    import tomllib

    with open(HEXAPOD, "rb") as f:
        table = tomllib.load(f)
    table["servovalve"]["model"] = model
    p = HydraulicParams.from_table(table)
    rng = np.random.default_rng(5)
    p.valve_delay_s = rng.choice([0.0, 0.0005, 0.002, 0.004], 12)
    p.valve_tau_s = rng.uniform(0.002, 0.01, 12)
    p.valve_natural_frequency_hz = rng.uniform(30.0, 120.0, 12)
    p.valve_flow_gain = rng.uniform(0.7, 1.3, 12)
    p.valve_null_offset = rng.uniform(-0.02, 0.02, 12)
    p.chamber_bulk_modulus_pa = rng.uniform(0.8e9, 1.6e9, 12)
    n, ns, dt = 800, 2, 0.0005
    cmds = np.repeat(rng.uniform(-1.2, 1.2, (n // 20, ns, 12)), 20, axis=0)
    vs = 0.5 * np.sin(np.cumsum(rng.normal(0, 0.05, (n, ns, 12)), axis=0))
    xs = 0.1 * np.cos(np.cumsum(rng.normal(0, 0.05, (n, ns, 12)), axis=0))
    out = []
    for backend in ("numba", "numpy"):
        hs = HydraulicSystem(p, n_sim=ns, dt=dt, backend=backend)
        assert hs.delay_steps == 8
        hs.reset(xs[0])
        for k in range(n):
            hs.step(np.ascontiguousarray(cmds[k]), np.ascontiguousarray(xs[k]), np.ascontiguousarray(vs[k]))
        out.append((hs._X[:NX_STATE].copy(), hs._Y.copy()))
    for A, B in zip(*out):
        scale = np.max(np.abs(A), axis=tuple(range(1, A.ndim)), keepdims=True) + 1e-300
        assert np.max(np.abs(A - B) / scale) < 1e-9


def test_per_actuator_delay_line_delays_each_valve_by_its_own_steps():
    """A step command reaches each spool after exactly round(delay/dt) steps."""
    import tomllib

    with open(HEXAPOD, "rb") as f:
        table = tomllib.load(f)
    table["servovalve"]["model"] = "first"
    p = HydraulicParams.from_table(table)
    delays = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 2, 0, 5])
    dt = 0.0005
    p.valve_delay_s = delays * dt
    for backend in ("numba", "numpy"):
        hs = HydraulicSystem(p, n_sim=1, dt=dt, backend=backend)
        hs.reset(np.zeros(12))
        first = np.full(12, -1)
        for k in range(12):
            hs.step(np.full(12, 0.1), np.zeros(12), np.zeros(12))
            moved = (hs.state.spool[0] != 0.0) & (first < 0)
            first[moved] = k
        np.testing.assert_array_equal(first, delays)


def test_no_override_is_the_scalar_valve(base):
    """Overrides equal to the scalars give bit-identical results."""
    p = HydraulicParams.from_table(base.raw)
    q = p.copy()
    for name in (
        "valve_delay_s",
        "valve_tau_s",
        "valve_natural_frequency_hz",
        "valve_flow_gain",
        "valve_null_offset",
        "chamber_bulk_modulus_pa",
    ):
        setattr(q, name, p.per_actuator(name))
    cmds = np.random.default_rng(1).uniform(-0.5, 0.5, (300, 2))
    res = []
    for params in (p, q):
        hs = HydraulicSystem(params, dt=1 / 4096)
        hs.reset(np.zeros(2))
        for k in range(300):
            hs.step(cmds[k], np.zeros(2), np.full(2, 0.01))
        res.append(hs._X[:NX_STATE].copy())
    np.testing.assert_array_equal(res[0], res[1])


# ---------------------------------------------------------------- valve null offset and flow gain
def test_null_offset_open_loop_drifts_at_offset_times_rated_flow_over_area(base):
    """Zero valve command, 1 % null offset (in proportion to the areas, so both pistons
    want the same speed): the platen drifts at v = offset x Q(full opening) / A, with
    Q(full opening) = Q_rated sqrt((p_s - p_t) / dp_rated) (no load)."""
    aE, aW = areas(base)
    o = 0.01
    sim = simulation(
        base,
        [
            {"type": "valve_null_offset", "where": "actuator:E", "offset": o},
            {"type": "valve_null_offset", "where": "actuator:W", "offset": o * aW / aE},
        ],
    )
    sv, su = base.raw["servovalve"], base.raw["supply"]
    q_full = sv["rated_flow_m3_s"] * math.sqrt((su["pressure_pa"] - su["return_pressure_pa"]) / sv["rated_drop_pa"])
    v_pred = o * q_full / aE
    res = sim.run(valve_command=np.zeros((1024, 2)))
    v = drift_velocity(res)
    print(f"null offset drift {v * 1e3:.2f} mm/s, predicted {v_pred * 1e3:.2f} mm/s")
    assert v == pytest.approx(v_pred, rel=0.02)
    assert np.all(res.channels["valve_command"] == 0.0)
    assert res.channels["spool_position"][-1] == pytest.approx([o, o * aW / aE], rel=1e-3)


def test_flow_gain_scales_the_drift(base):
    """The same drift with the flow gain of both valves doubled: twice the speed."""
    aE, aW = areas(base)
    off = [
        {"type": "valve_null_offset", "where": "actuator:E", "offset": 0.005},
        {"type": "valve_null_offset", "where": "actuator:W", "offset": 0.005 * aW / aE},
    ]
    gain = [{"type": "valve_flow_gain", "where": f"class:{c}", "factor": 2.0} for c in ("east", "west")]
    v1 = drift_velocity(simulation(base, off).run(valve_command=np.zeros((1024, 2))))
    v2 = drift_velocity(simulation(base, off + gain).run(valve_command=np.zeros((1024, 2))))
    print(f"drift {v1 * 1e3:.2f} -> {v2 * 1e3:.2f} mm/s with the flow gain doubled")
    assert v2 / v1 == pytest.approx(2.0, rel=0.02)


def test_null_offset_closed_loop_is_cancelled_by_the_valve_command(base):
    """Closed loop holding zero: the controller ends up commanding -offset (the spools
    back at null) and the platen sits off by the proportional loop's error, between
    v_E / kp and v_W / kp (v_i = offset x Q(full opening) / A_i)."""
    o = 0.01
    sim = simulation(base, [{"type": "valve_null_offset", "where": f"actuator:{a}", "offset": o} for a in "EW"])
    res = hold_still(sim, 1.5)
    vc = res.channels["valve_command"][-256:]
    print("steady valve commands", vc.mean(axis=0))
    assert vc.mean() == pytest.approx(-o, rel=0.02)
    assert np.all(np.abs(vc.mean(axis=0) + o) < 0.05 * o)
    aE, aW = areas(base)
    q_full = float(sim.hs.no_load_flow(1.0))
    kp = float(sim.gains.kp_per_s[0])  # x
    x = res.channels["table_displacement"][-1, 0]
    assert o * q_full / aW / kp < x < o * q_full / aE / kp
    # without the offset the platen stays at home and the valves at null
    ref = hold_still(simulation(base, []), 0.5)
    assert np.abs(ref.channels["valve_command"]).max() < 1e-3 * o


# ---------------------------------------------------------------- oil
def ringing_frequency(res, t0=0.1):
    """Oil-column frequency from the zero crossings of the velocity about its trend."""
    k = res.t >= t0
    t, v = res.t[k], res.channels["table_velocity"][k, 0]
    s = v - np.polyval(np.polyfit(t, v, 1), t)
    i = np.nonzero((s[:-1] < 0) & (s[1:] >= 0))[0]
    tc = t[i] - s[i] * (t[i + 1] - t[i]) / (s[i + 1] - s[i])
    return (len(tc) - 1) / (tc[-1] - tc[0])


def test_bulk_modulus_scales_the_oil_column_frequency_by_its_square_root(base):
    """The free platen on the two oil columns, rung by a small valve bias: doubling the
    bulk modulus of both classes raises the ringing frequency by sqrt(2); the frequency
    itself is the closed form sqrt(sum beta A^2 (1/V_a + 1/V_b) / M)."""
    aE, aW = areas(base)
    kick = [
        {"type": "valve_null_offset", "where": "actuator:E", "offset": 0.005},
        {"type": "valve_null_offset", "where": "actuator:W", "offset": 0.005 * aW / aE},
    ]
    beta0 = base.raw["fluid"]["bulk_modulus_pa"]
    stiff = [{"type": "bulk_modulus", "where": f"class:{c}", "bulk_modulus_pa": 2 * beta0} for c in ("east", "west")]
    s1 = simulation(base, kick)
    s2 = simulation(base, kick + stiff)
    np.testing.assert_array_equal(s2.hp.per_actuator("chamber_bulk_modulus_pa"), [2 * beta0, 2 * beta0])
    f1 = ringing_frequency(s1.run(valve_command=np.zeros((1536, 2))))
    f2 = ringing_frequency(s2.run(valve_command=np.zeros((1536, 2))))
    hp = s1.hp
    k = sum(
        beta0 * hp.area_a_m2[i] ** 2 / (hp.dead_volume_a_m3[i] + hp.area_a_m2[i] * hp.half_stroke_m[i])
        + beta0 * hp.area_b_m2[i] ** 2 / (hp.dead_volume_b_m3[i] + hp.area_b_m2[i] * hp.half_stroke_m[i])
        for i in range(2)
    )
    m = s1.tm.effective_mass()["x"]
    f_cf = math.sqrt(k / m) / (2 * math.pi)
    print(f"oil column {f1:.3f} Hz (closed form {f_cf:.3f}), doubled bulk modulus {f2:.3f} Hz, ratio {f2 / f1:.4f}")
    assert f1 == pytest.approx(f_cf, rel=0.02)
    assert f2 / f1 == pytest.approx(math.sqrt(2.0), rel=0.01)


def test_leakage_sets_the_class_coefficient(base):
    hp = HydraulicParams.from_table(base.raw)
    e = create({"type": "leakage", "where": "class:west", "coefficient_m3_s_pa": 3e-11})
    out = e.edit_hydraulics(hp)
    assert out.leakage_cross_m3_s_pa[1] == 3e-11
    assert out.leakage_cross_m3_s_pa[0] == hp.leakage_cross_m3_s_pa[0]
    ext = create({"type": "leakage", "where": "actuator:E", "coefficient_m3_s_pa": 1e-12, "kind": "external"})
    out2 = ext.edit_hydraulics(hp)
    assert out2.leakage_external_m3_s_pa.tolist() == [1e-12, hp.leakage_external_m3_s_pa[1]]
    assert hp.leakage_cross_m3_s_pa[1] != 3e-11  # the input is not changed


def test_leakage_creep_of_a_blocked_valve():
    """Valve at null (no null leakage), piston free, a load on it: the piston creeps at
    v = k_c (p_a - p_b) / A with the planted cross leakage (single actuator, no MuJoCo)."""
    import tomllib

    with open(UNIAXIAL, "rb") as f:
        table = tomllib.load(f)
    table["servovalve"]["null_leakage_m3_s"] = 0.0
    p = HydraulicParams.from_table(table)
    kc = 2e-11
    p = create({"type": "leakage", "where": "actuator:E", "coefficient_m3_s_pa": kc}).edit_hydraulics(p)
    p = create({"type": "leakage", "where": "actuator:W", "coefficient_m3_s_pa": 0.0}).edit_hydraulics(p)
    dt = 1 / 4096
    hs = HydraulicSystem(p, dt=dt)
    load = 1.0e6  # N pushing on the piston; held at rest, the chambers settle to carry it
    hs.reset(np.zeros(2), force=np.array([load, load]))
    dp = hs.state.p_a[0] - hs.state.p_b[0]
    # piston moving at the creep speed keeps the pressures: flow balance in chamber a
    aa = p.area_a_m2
    v_pred = kc * dp[0] / aa[0]
    assert p.area_a_m2[0] == p.area_b_m2[0]  # symmetric piston: both chambers see the same creep
    for _ in range(4000):
        hs.step(np.zeros(2), np.zeros(2), np.array([-v_pred, 0.0]))
    dp_end = hs.state.p_a[0] - hs.state.p_b[0]
    print(f"creep {v_pred * 1e3:.3f} mm/s, pressure difference {dp[0] / 1e6:.4f} -> {dp_end[0] / 1e6:.4f} MPa")
    assert abs(dp_end[0] - dp[0]) < 1e-3 * abs(dp[0])  # leakage balanced by the creep: pressures hold
    assert abs(dp_end[1] - dp[1]) < 1e-6 * abs(dp[1])  # the other actuator, no leakage, no motion: holds
    hs.reset(np.zeros(2), force=np.array([load, load]))
    for _ in range(4000):  # held still instead, the leak unloads actuator E
        hs.step(np.zeros(2), np.zeros(2), np.zeros(2))
    assert hs.state.p_a[0, 0] - hs.state.p_b[0, 0] < 0.9 * dp[0]


# ---------------------------------------------------------------- valve dynamics
def spool_phasor(res, col, f, t0):
    k = res.t >= t0
    t = res.t[k]
    e = np.exp(-2j * np.pi * f * t)
    return np.sum(res.channels["spool_position"][k, col] * e) / np.sum(res.channels["valve_command"][k, col] * e)


def test_valve_delay_shifts_the_valve_phase_by_2_pi_f_tau(base):
    """Sine on both valves (open loop); a 3.9 ms delay on valve E (8 physics steps)
    changes its spool/command phase by -2 pi f tau and nothing else; valve W, untouched,
    is the control. A bandwidth effect on W at the same time moves its -90 degree point
    to the new natural frequency."""
    f = 8.0  # Hz, an integer number of periods in the window
    sim0 = simulation(base, [])
    dt = sim0.dt
    tau = 8 * dt
    sim1 = simulation(base, [{"type": "valve_delay", "where": "actuator:E", "delay_s": tau}])
    n, fs = 1024, sim0.gains.rate_hz
    t = np.arange(n) / fs
    cmd = np.repeat((0.004 * np.sin(2 * np.pi * f * t))[:, None], 2, axis=1)
    r0 = sim0.run(valve_command=cmd)
    r1 = sim1.run(valve_command=cmd)
    h0E, h1E = spool_phasor(r0, 0, f, 0.5), spool_phasor(r1, 0, f, 0.5)
    h0W, h1W = spool_phasor(r0, 1, f, 0.5), spool_phasor(r1, 1, f, 0.5)
    dphi = np.angle(h1E / h0E)
    print(f"phase shift {np.degrees(dphi):.3f} deg, expected {-360 * f * tau:.3f} deg")
    assert dphi == pytest.approx(-2 * np.pi * f * tau, abs=2e-4)
    assert abs(h1E) == pytest.approx(abs(h0E), rel=1e-3)
    assert h1W == pytest.approx(h0W, rel=1e-9)
    # bandwidth: the second-order valve's response at its natural frequency is -90 deg
    # (less the zero-order hold's half tick) with magnitude 1 / (2 zeta)
    fb = 24.0
    simb = simulation(base, [{"type": "valve_bandwidth", "where": "actuator:W", "bandwidth_hz": fb}])
    cmd = np.repeat((0.004 * np.sin(2 * np.pi * fb * t))[:, None], 2, axis=1)
    hb = spool_phasor(simb.run(valve_command=cmd), 1, fb, 0.5)
    zoh = -np.pi * fb / fs  # the command is held over each tick: half a tick of delay
    zeta = base.raw["servovalve"]["damping_ratio"]
    print(f"valve at its bandwidth: {np.degrees(np.angle(hb)):.2f} deg, |H| = {abs(hb):.4f}")
    assert np.angle(hb) == pytest.approx(-np.pi / 2 + zoh, abs=np.radians(1.0))
    assert abs(hb) == pytest.approx(1 / (2 * zeta) * np.sinc(fb / fs), rel=0.01)


# ---------------------------------------------------------------- supply
def test_supply_drop_lowers_the_force_capacity(base):
    """A 5 MPa supply drop: the valve fully open on a blocked piston stalls at
    (p_s - drop) A_a - p_t A_b, and the run's force capacity is (p_s - drop) A_a."""
    drop = 5e6
    sim = simulation(base, [{"type": "supply_pressure_drop", "drop_pa": drop, "where": "supply"}])
    ps, pt = base.raw["supply"]["pressure_pa"], base.raw["supply"]["return_pressure_pa"]
    assert sim.hp.supply_pressure_pa == ps - drop
    hs = sim.hs
    hs.reset(np.zeros((1, 2)))
    for _ in range(4000):
        F = hs.step(np.ones((1, 2)), np.zeros((1, 2)), np.zeros((1, 2)))
    hp = sim.hp
    stall = (ps - drop) * hp.area_a_m2 - pt * hp.area_b_m2
    print("stall force", F[0], "closed form", stall)
    np.testing.assert_allclose(F[0], stall, rtol=2e-3)
    from sim.assess.feasibility import diagnostics

    res = hold_still(sim, 0.05)
    cap = diagnostics(res, sim.tm, sim.hp)["peak_force_fraction_of_capacity"]
    fmax = np.abs(res.channels["actuator_force"]).max(axis=0)
    assert cap["E"] == pytest.approx(fmax[0] / ((ps - drop) * hp.area_a_m2[0]), rel=1e-12)


# ---------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "entry, match",
    [
        ({"type": "valve_delay", "where": "actuator:Q", "delay_s": 0.001}, "names no actuator; actuators: E, W"),
        ({"type": "bulk_modulus", "where": "class:north", "bulk_modulus_pa": 1e9}, "names no actuator class"),
        ({"type": "valve_null_offset", "where": "supply", "offset": 0.01}, "acts at actuator, class"),
        ({"type": "supply_pressure_drop", "drop_pa": 20.6e6}, "use a smaller drop"),
        ({"type": "valve_flow_gain", "where": "actuator:E", "factor": 0.0}, "outside"),
        ({"type": "leakage", "where": "class:east", "coefficient_m3_s_pa": 1e-12, "kind": "inner"}, "cross"),
    ],
)
def test_bad_entries_are_one_line_errors(base, entry, match):
    with pytest.raises(ScenarioError, match=match) as ei:
        create(entry, source="ucsd.toml effect[3]").edit_hydraulics(HydraulicParams.from_table(base.raw))
    assert "\n" not in str(ei.value) and "ucsd.toml effect[3]" in str(ei.value)


def test_effects_are_parameters_for_calibration():
    e = create({"type": "valve_bandwidth", "where": "class:east", "bandwidth_hz": 40.0})
    (p,) = e.parameters()
    assert (p.name, p.value, p.unit, p.where) == ("bandwidth_hz", 40.0, "Hz", "class:east")
    e2 = e.with_values({"bandwidth_hz": 50.0})
    assert e2.entry() == {"type": "valve_bandwidth", "where": "class:east", "bandwidth_hz": 50.0}
    assert e.values["bandwidth_hz"] == 40.0


def test_the_analog_loop_takes_hydraulic_effects_too():
    """The one loop with the uni-axial table's analog controller edits its hydraulics
    with the description's effects, as with the digital one."""
    from sim.loop.simulation import Simulation

    desc = mjcf.load_table(TABLES / "rice.toml")
    raw = copy.deepcopy(desc.raw)
    name = raw["actuator"][0]["name"]
    raw.setdefault("effect", []).append({"type": "valve_null_offset", "where": f"actuator:{name}", "offset": 0.02})
    sim = Simulation.for_table(parse_table(raw, "test"))
    assert sim.hp.per_actuator("valve_null_offset")[0] == 0.02
    assert Simulation.for_table(desc).hp.valve_null_offset is None
