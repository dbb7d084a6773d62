"""Hydraulics against closed forms (CGS table description, dt = 0.5 ms)."""

from __future__ import annotations

import copy
import math
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest

from hydraulics import HydraulicParams, HydraulicsParamError, HydraulicSystem
from hydraulics._layout import S_GPA as NX_STATE  # fields before the scratch area

TABLE = Path(__file__).resolve().parents[2] / "scenarios" / "tables" / "cgs.toml"
DT = 0.0005


@pytest.fixture(scope="module")
def table():
    with open(TABLE, "rb") as f:
        return tomllib.load(f)


def make_params(table, **over):
    """Params from a modified copy of the table description: over = {"section.key": value}
    (servovalve/fluid/supply keys) or {"class.key": value} applied to every actuator class."""
    t = copy.deepcopy(table)
    for k, v in over.items():
        sec, key = k.split(".")
        if sec == "class":
            for c in t["actuator_class"].values():
                c[key] = v
        else:
            t[sec][key] = v
    return HydraulicParams.from_table(t)


def oil_column_k(p, x):
    va = p.dead_volume_a_m3 + p.area_a_m2 * (p.half_stroke_m + x)
    vb = p.dead_volume_b_m3 + p.area_b_m2 * (p.half_stroke_m - x)
    return p.bulk_modulus_pa * (p.area_a_m2**2 / va + p.area_b_m2**2 / vb)


# ---------------------------------------------------------------- parameters
def test_from_table(table):
    p = HydraulicParams.from_table(table)
    assert p.n_act == 12
    assert p.names == tuple(a["name"] for a in table["actuator"])
    assert p.bulk_modulus_pa == table["fluid"]["bulk_modulus_pa"]
    assert p.area_a_m2[8] == table["actuator_class"]["vertical"]["area_a_m2"]
    assert p.rated_flow_m3_s == table["servovalve"]["rated_flow_m3_s"]


@pytest.mark.parametrize(
    "key,value,name",
    [
        ("class.area_a_m2", -0.01, "area_a_m2"),
        ("class.area_b_m2", 0.0, "area_b_m2"),
        ("class.dead_volume_a_m3", 0.0, "dead_volume_a_m3"),
        ("class.dead_volume_b_m3", -1e-3, "dead_volume_b_m3"),
        ("class.half_stroke_m", 0.0, "half_stroke_m"),
        ("class.leakage_cross_m3_s_pa", -1e-12, "leakage_cross_m3_s_pa"),
        ("class.cushion_length_m", 1.0, "cushion_length_m"),
        ("fluid.bulk_modulus_pa", 0.0, "fluid.bulk_modulus_pa"),
        ("fluid.bulk_modulus_pa", -1e9, "fluid.bulk_modulus_pa"),
        ("fluid.relief_pressure_pa", 20e6, "fluid.relief_pressure_pa"),
        ("servovalve.rated_flow_m3_s", 0.0, "servovalve.rated_flow_m3_s"),
        ("servovalve.delay_s", -0.001, "servovalve.delay_s"),
        ("servovalve.tau_s", 0.0, "servovalve.tau_s"),
        ("servovalve.model", "third", "servovalve.model"),
        ("servovalve.overlap", 1.0, "servovalve.overlap"),
        ("servovalve.laminar_drop_pa", 0.0, "servovalve.laminar_drop_pa"),
        ("servovalve.rated_drop_pa", "7 MPa", "servovalve.rated_drop_pa"),
        ("supply.pressure_pa", -1.0, "supply.pressure_pa"),
        ("supply.accumulator_precharge_pa", 30e6, "supply.accumulator_precharge_pa"),
        ("supply.pump_flow_m3_s", float("nan"), "supply.pump_flow_m3_s"),
    ],
)
def test_bad_parameter(table, key, value, name):
    with pytest.raises(HydraulicsParamError) as ei:
        make_params(table, **{key: value})
    msg = str(ei.value)
    assert name in msg and "\n" not in msg
    assert isinstance(ei.value, ValueError)


def test_missing_key(table):
    t = copy.deepcopy(table)
    del t["actuator_class"]["vertical"]["area_b_m2"]
    with pytest.raises(HydraulicsParamError, match=r"actuator_class\.vertical\.area_b_m2 is missing"):
        HydraulicParams.from_table(t)
    t = copy.deepcopy(table)
    del t["supply"]["pump_flow_m3_s"]
    with pytest.raises(HydraulicsParamError, match=r"supply\.pump_flow_m3_s"):
        HydraulicParams.from_table(t)
    t = copy.deepcopy(table)
    del t["servovalve"]
    with pytest.raises(HydraulicsParamError, match="servovalve"):
        HydraulicParams.from_table(t)


def test_validate_after_edit(table):
    p = HydraulicParams.from_table(table)
    p.area_a_m2[3] = -0.01
    with pytest.raises(
        HydraulicsParamError, match=r"actuator_class\.longitudinal\.area_a_m2 must be > 0 \(got -0.01\)"
    ):
        p.validate()


# ---------------------------------------------------------------- oil column
def test_oil_column_stiffness(table):
    p = make_params(table, **{"servovalve.null_leakage_m3_s": 0.0, "class.leakage_cross_m3_s_pa": 0.0})
    hs = HydraulicSystem(p, n_sim=3, dt=DT)
    x = np.array([[0.0] * 12, [0.1] * 12, [-0.15] * 12])
    dx = 1e-6
    F0 = hs.reset(x).copy()
    F1 = hs.step(np.zeros_like(x), x, np.full_like(x, dx / DT))
    k_num = -(F1 - F0) / dx
    k_cf = np.stack([oil_column_k(p, xr) for xr in x])
    assert np.max(np.abs(k_num / k_cf - 1.0)) < 1e-6


def zero_crossing_freq(t, s):
    i = np.nonzero((s[:-1] < 0) & (s[1:] >= 0))[0]
    tc = t[i] - s[i] * (t[i + 1] - t[i]) / (s[i + 1] - s[i])
    return (len(tc) - 1) / (tc[-1] - tc[0])


def test_oil_column_frequency(table):
    p = make_params(table, **{"servovalve.null_leakage_m3_s": 0.0, "class.leakage_cross_m3_s_pa": 0.0})
    hs = HydraulicSystem(p, n_sim=1, dt=DT)
    m = np.array([5000.0] * 4 + [5000.0] * 4 + [8000.0] * 4)
    x = np.zeros((1, 12))
    v = np.full((1, 12), 0.01)
    hs.reset(x)
    c = np.zeros((1, 12))
    n = 2000
    vs = np.empty((n, 12))
    for k in range(n):
        F = hs.step(c, x, v)
        v = v + F / m * DT  # symplectic Euler, as MuJoCo
        x = x + v * DT
        vs[k] = v[0]
    t = np.arange(n) * DT
    f_cf = np.sqrt(oil_column_k(p, 0.0) / m) / (2 * math.pi)
    f_num = np.array([zero_crossing_freq(t, vs[:, j]) for j in range(12)])
    err = np.abs(f_num / f_cf - 1.0)
    print(f"oil column: f = {f_cf[[0, 4, 8]]} Hz, max rel error {err.max():.2e}")
    assert err.max() < 0.005


# ---------------------------------------------------------------- flow, hold, creep
def test_no_load_speed_is_q_over_a(table):
    p = make_params(table, **{"servovalve.null_leakage_m3_s": 0.0, "class.leakage_cross_m3_s_pa": 0.0})
    c = 0.1  # 12 x Q stays below the pump flow, so the supply holds its set pressure
    # closed form: each land drops (ps - pt)/2 at no load; rated flow at rated_drop/2 per land
    q = p.rated_flow_m3_s * c * math.sqrt((p.supply_pressure_pa - p.return_pressure_pa) / p.rated_drop_pa)
    v_cf = q / p.area_a_m2
    x0 = -0.8 * p.half_stroke_m

    def load_at(vscale):
        vv = np.stack([v_cf * s for s in vscale])
        hs = HydraulicSystem(p, n_sim=len(vscale), dt=DT)
        x = np.tile(x0, (len(vscale), 1))
        hs.reset(x)
        cmd = np.full_like(x, c)
        for _ in range(1200):
            F = hs.step(cmd, x, vv)
            x = x + vv * DT
        return vv, F.copy()

    vv, F = load_at([0.98, 1.02])
    v_star = vv[0] - F[0] * (vv[1] - vv[0]) / (F[1] - F[0])
    vv, F = load_at([v_star / v_cf * 0.999, v_star / v_cf * 1.001])
    v_star = vv[0] - F[0] * (vv[1] - vv[0]) / (F[1] - F[0])
    err = np.abs(v_star / v_cf - 1.0)
    print(f"no-load speed: Q/A = {v_cf[[0, 8]]} m/s, max rel error {err.max():.2e}")
    assert err.max() < 0.005


def test_closed_valve_holds_and_creeps_through_leakage(table):
    kc = 1.0e-12
    p = make_params(table, **{"servovalve.null_leakage_m3_s": 0.0, "class.leakage_cross_m3_s_pa": kc})
    hs = HydraulicSystem(p, n_sim=1, dt=DT)
    FL = 2.0e5  # external load pushing the piston in; the oil holds it
    m = 5000.0
    x = np.zeros((1, 12))
    v = np.zeros((1, 12))
    F = hs.reset(x, force=np.full((1, 12), FL))
    assert np.allclose(F, FL, rtol=1e-12)
    k = oil_column_k(p, 0.0)
    cdamp = 2 * 0.3 * np.sqrt(k * m)  # test-rig damper to kill the start transient
    c = np.zeros((1, 12))
    n = 1000
    vs = np.empty((n, 12))
    for i in range(n):
        F = hs.step(c, x, v)
        v = v + (F - FL - cdamp * v) / m * DT
        x = x + v * DT
        vs[i] = v[0]
    A = p.area_a_m2
    # steady creep: A v = -kc (pa - pb), (pa - pb) A = FL + cdamp v
    v_cf = -kc * FL / (A * A + kc * cdamp)
    v_meas = vs[-200:].mean(axis=0)
    err = np.abs(v_meas / v_cf - 1.0)
    print(f"creep: {v_cf[[0, 8]]} m/s, max rel error {err.max():.2e}")
    assert err.max() < 0.005
    # and without leakage it does not move at all
    p0 = make_params(table, **{"servovalve.null_leakage_m3_s": 0.0, "class.leakage_cross_m3_s_pa": 0.0})
    hs0 = HydraulicSystem(p0, n_sim=1, dt=DT)
    x = np.zeros((1, 12))
    v = np.zeros((1, 12))
    hs0.reset(x, force=np.full((1, 12), FL))
    for _ in range(200):
        F = hs0.step(c, x, v)
        v = v + (F - FL) / m * DT
        x = x + v * DT
    assert np.max(np.abs(x)) < 1e-12


# ---------------------------------------------------------------- servovalve
FREQS = np.array([0.5, 1.0, 2.0, 5.0, 10.0, 15.0, 20.0, 30.0, 41.5, 50.0])


def spool_frf(p, freqs, amp=0.2, t_end=3.0, t_fit=0.5):
    hs = HydraulicSystem(p, n_sim=len(freqs), dt=DT)
    n = int(round(t_end / DT))
    x = np.zeros((len(freqs), p.n_act))
    hs.reset(x)
    cmd = np.zeros_like(x)
    y = np.empty((n, len(freqs)))
    for k in range(n):
        cmd[:] = (amp * np.sin(2 * np.pi * freqs * k * DT))[:, None]
        hs.step(cmd, x, x)
        y[k] = hs.state.spool[:, 0]
    t = (np.arange(n) + 1) * DT  # the spool after step k belongs to t_{k+1}
    sel = t >= t_fit
    H = np.empty(len(freqs), complex)
    for j, f in enumerate(freqs):
        w = 2 * np.pi * f
        M = np.stack([np.sin(w * t[sel]), np.cos(w * t[sel]), np.ones(sel.sum())], axis=1)
        b, a, _ = np.linalg.lstsq(M, y[sel, j], rcond=None)[0]
        H[j] = (b + 1j * a) / amp
    return H


@pytest.mark.parametrize("model", ["first", "second"])
def test_spool_frequency_response(table, model):
    p = make_params(table, **{"servovalve.model": model})
    H = spool_frf(p, FREQS)
    w = 2 * np.pi * FREQS
    s = 1j * w
    if model == "first":
        Hc = 1.0 / (p.tau_s * s + 1.0)
        Ac = np.array([[-1.0 / p.tau_s]])
        Bc = np.array([1.0 / p.tau_s])
    else:
        wn = 2 * np.pi * p.natural_frequency_hz
        z = p.damping_ratio
        Hc = wn**2 / (s**2 + 2 * z * wn * s + wn**2)
        Ac = np.array([[0.0, 1.0], [-wn * wn, -2 * z * wn]])
        Bc = np.array([0.0, wn * wn])
    # the held command lags the continuous one by half a step: remove exp(-s dt/2)
    Hcorr = H * np.exp(s * DT / 2)
    mag_err = np.abs(np.abs(Hcorr) / np.abs(Hc) - 1.0)
    ph_err = np.degrees(np.abs(np.angle(Hcorr / Hc)))
    print(f"{model}: max |mag| error {mag_err.max():.2e}, max phase error {ph_err.max():.2e} deg")
    assert mag_err.max() < 0.01
    assert ph_err.max() < 2.0
    # and the spool is exactly the zero-order-hold discretisation of the model
    from scipy.linalg import expm

    nx = len(Bc)
    M = np.zeros((nx + 1, nx + 1))
    M[:nx, :nx] = Ac
    M[:nx, nx] = Bc
    E = expm(M * DT)
    Phi, Gam = E[:nx, :nx], E[:nx, nx]
    Hd = np.array([np.linalg.solve(np.exp(1j * wi * DT) * np.eye(nx) - Phi, Gam)[0] for wi in w])
    assert np.max(np.abs(H / Hd - 1.0)) < 1e-6


@pytest.mark.parametrize("delay_s", [0.0049, 0.00124, 0.0005])
def test_delay_exact_to_one_step(table, delay_s):
    p0 = make_params(table, **{"servovalve.delay_s": 0.0})
    p1 = make_params(table, **{"servovalve.delay_s": delay_s})
    nd = int(round(delay_s / DT))
    assert abs(nd * DT - delay_s) <= DT / 2 + 1e-15
    rng = np.random.default_rng(1)
    cmds = rng.uniform(-0.5, 0.5, (200, 1, 12))
    cmds[:5] = 0.0
    out = []
    for p in (p0, p1):
        hs = HydraulicSystem(p, n_sim=1, dt=DT)
        x = np.zeros((1, 12))
        hs.reset(x)
        ys = []
        for k in range(200):
            hs.step(cmds[k], x, x)
            ys.append(hs.state.spool.copy())
        out.append(np.array(ys))
    assert hs.delay_steps == nd
    assert np.all(out[1][: 5 + nd] == 0.0)
    np.testing.assert_array_equal(out[1][nd:], out[0][: 200 - nd])


def test_spool_saturation_and_slew(table):
    p = make_params(table, **{"servovalve.slew_limit_per_s": 20.0, "servovalve.model": "first"})
    hs = HydraulicSystem(p, n_sim=1, dt=DT)
    x = np.zeros((1, 12))
    hs.reset(x)
    ys = []
    for _ in range(200):
        hs.step(np.full((1, 12), 5.0), x, x)
        ys.append(hs.state.spool[0, 0])
    ys = np.array(ys)
    assert np.all(np.diff(np.r_[0.0, ys]) <= 20.0 * DT + 1e-15)
    assert ys.max() == 1.0


# ---------------------------------------------------------------- oil bookkeeping
def random_run(hs, n, seed, m=6000.0, amp=1.0, hold=40, record=False):
    rng = np.random.default_rng(seed)
    ns, na = hs.n_sim, hs.n_act
    x = np.zeros((ns, na))
    v = np.zeros((ns, na))
    hs.reset(x)
    cmd = np.zeros((ns, na))
    rec = {"pa": [], "pb": [], "x": [], "v": []}
    h = hs.params.half_stroke_m
    for k in range(n):
        if k % hold == 0:
            cmd = rng.uniform(-amp, amp, (ns, na))
        # a soft position loop keeps the pistons inside the stroke
        c = np.clip(cmd - 4.0 * x / h, -1.0, 1.0)
        if record:
            rec["pa"].append(hs.state.p_a.copy())
            rec["pb"].append(hs.state.p_b.copy())
            rec["x"].append(x.copy())
            rec["v"].append(v.copy())
        F = hs.step(c, x, v)
        v = v + (F + hs.seal_friction(v)) / m * DT
        x = x + v * DT
    if record:
        rec["pa"].append(hs.state.p_a.copy())
        rec["pb"].append(hs.state.p_b.copy())
        return {k: np.array(val) for k, val in rec.items()}


@pytest.mark.parametrize("air", [0.0, 0.005])
def test_oil_conserved(table, air):
    p = make_params(table, **{"fluid.entrained_air_fraction": air, "class.leakage_external_m3_s_pa": 2e-12})
    hs = HydraulicSystem(p, n_sim=2, dt=DT)
    rec = random_run(hs, 8000, seed=2, record=True)
    st = hs.state
    # independent recomputation of the chamber terms from the recorded trajectory
    pa, pb, x, v = rec["pa"], rec["pb"], rec["x"], rec["v"]
    h = p.half_stroke_m
    xc = np.clip(x, -h, h)
    va = p.dead_volume_a_m3 + p.area_a_m2 * (h + xc)
    vb = p.dead_volume_b_m3 + p.area_b_m2 * (h - xc)

    def inv_beta(pp):
        if air == 0.0:
            return 1.0 / p.bulk_modulus_pa
        n = p.air_polytropic_exponent
        pp = np.maximum(pp, 1e-3 * p.atmospheric_pressure_pa)
        return 1.0 / p.bulk_modulus_pa + air * (p.atmospheric_pressure_pa / pp) ** (1 / n) / (n * pp)

    comp = np.sum(va * inv_beta(pa[:-1]) * np.diff(pa, axis=0)) + np.sum(vb * inv_beta(pb[:-1]) * np.diff(pb, axis=0))
    disp = np.sum((p.area_a_m2 - p.area_b_m2) * v * DT)
    supply = np.sum(st.vol_pump + st.vol_store_out + st.vol_supply_cav)
    out = np.sum(st.vol_out_a + st.vol_out_b + st.vol_ext_a + st.vol_ext_b)
    clip = np.sum(st.vol_relief_a + st.vol_relief_b - st.vol_cav_a - st.vol_cav_b)
    rel = abs(supply - (out + comp + disp + clip)) / supply
    print(
        f"oil (air={air}): pump {st.vol_pump.sum():.4f} m3, accumulators+line {st.vol_store_out.sum():.2e} m3, "
        f"ext leak {np.sum(st.vol_ext_a + st.vol_ext_b):.2e}, relative imbalance {rel:.2e}"
    )
    assert rel < 1e-6
    assert np.all(st.q_pump <= p.pump_flow_m3_s * (1 + 1e-12))
    s_in, s_valve, s_out = st.oil_balance()
    assert abs(s_in - s_valve) < 1e-9 * s_in and abs(s_valve - s_out) < 1e-9 * s_in
    assert np.all(np.isfinite(hs.force))


# ---------------------------------------------------------------- edge cases
def test_edge_cases_finite_no_warnings(table):
    p = HydraulicParams.from_table(table)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with np.errstate(all="raise"):
            for backend in ("numpy", "numba"):
                hs = HydraulicSystem(p, n_sim=3, dt=DT, backend=backend)
                x = np.zeros((3, 12))
                v = np.zeros((3, 12))
                hs.reset(x)
                # zero pressure drop across every land, full and zero opening
                hs.state.p_a[:] = p.supply_pressure_pa
                hs.state.p_b[:] = p.return_pressure_pa
                cmd = np.array([[1.0] * 12, [0.0] * 12, [-5.0] * 12])
                F = hs.step(cmd, x, v)
                assert np.all(np.isfinite(F)) and np.all(np.abs(hs.state.spool) <= 1.0)
                hs.state.p_a[:] = p.return_pressure_pa
                hs.state.p_b[:] = p.supply_pressure_pa
                F = hs.step(cmd, x, v)
                assert np.all(np.isfinite(F))
                # cavitation and relief: closed valve, piston driven hard
                hs.reset(x)
                vv = np.full((3, 12), 2.0)
                xx = x.copy()
                for _ in range(40):
                    F = hs.step(np.zeros((3, 12)), xx, vv)
                    xx += vv * DT
                assert np.all(hs.state.cavitation_count > 0) and np.all(hs.state.relief_count > 0)
                assert np.all(hs.state.p_a >= p.vapour_pressure_pa) and np.all(hs.state.p_b <= p.relief_pressure_pa)
                assert np.all(np.isfinite(F))
                # beyond the stroke: cushions push back, volumes stay positive
                xx = np.tile(np.r_[p.half_stroke_m[:6] + 0.05, -p.half_stroke_m[6:] - 0.05], (3, 1))
                F = hs.step(np.zeros((3, 12)), xx, np.zeros((3, 12)))
                assert np.all(np.sign(hs.state.cushion_force) == -np.sign(xx))
                # drained accumulators: all valves wide open, pistons moving at no-load speed
                hs.reset(x)
                qa = hs.no_load_flow(1.0)
                xx = np.zeros((3, 12))
                for k in range(1600):
                    c = 1.0 if (k // 250) % 2 == 0 else -1.0
                    vv = np.full((3, 12), c * qa) / p.area_a_m2
                    F = hs.step(np.full((3, 12), c), xx, vv)
                    xx += vv * DT
                    assert np.all(np.isfinite(F)) and np.all(np.isfinite(hs.state.p_supply))
                assert np.all(hs.state.gas_volume == p.accumulator_volume_m3)  # fully drained
                assert np.all(hs.state.p_supply < p.accumulator_precharge_pa)
                assert np.all(hs.state.p_supply >= p.vapour_pressure_pa)


# ---------------------------------------------------------------- backends
@pytest.mark.parametrize(
    "over",
    [
        {},
        {
            "servovalve.model": "first",
            "servovalve.delay_s": 0.003,
            "servovalve.slew_limit_per_s": 30.0,
            "servovalve.overlap": 0.02,
            "fluid.entrained_air_fraction": 0.01,
            "class.leakage_external_m3_s_pa": 1e-12,
        },
    ],
)
def test_backends_agree(table, over):
    p = make_params(table, **over)
    rng = np.random.default_rng(3)
    n, ns = 1500, 2
    cmds = np.repeat(rng.uniform(-1.2, 1.2, (n // 30, ns, 12)), 30, axis=0)
    vs = 0.5 * np.sin(np.cumsum(rng.normal(0, 0.05, (n, ns, 12)), axis=0))
    xs = 0.1 * np.cos(np.cumsum(rng.normal(0, 0.05, (n, ns, 12)), axis=0))
    res = []
    for backend in ("numba", "numpy"):
        hs = HydraulicSystem(p, n_sim=ns, dt=DT, backend=backend)
        hs.reset(xs[0])
        for k in range(n):
            hs.step(np.ascontiguousarray(cmds[k]), np.ascontiguousarray(xs[k]), np.ascontiguousarray(vs[k]))
        res.append((hs._X[:NX_STATE].copy(), hs._Y.copy(), hs._IC.copy(), hs._ICS.copy()))
    (X1, Y1, I1, J1), (X2, Y2, I2, J2) = res
    for A, B in ((X1, X2), (Y1, Y2)):
        scale = np.max(np.abs(A), axis=tuple(range(1, A.ndim)), keepdims=True) + 1e-300
        err = np.max(np.abs(A - B) / scale)
        print(f"backends: max relative difference {err:.2e}")
        assert err < 1e-9
    np.testing.assert_array_equal(I1, I2)
    np.testing.assert_array_equal(J1, J2)


def test_one_dimensional_inputs(table):
    p = HydraulicParams.from_table(table)
    hs = HydraulicSystem(p, n_sim=1, dt=DT)
    F = hs.step(np.zeros(12), np.zeros(12), np.zeros(12))
    assert F.shape == (12,)
    with pytest.raises(ValueError):
        hs.step(np.zeros(11), np.zeros(12), np.zeros(12))


def test_seal_friction(table):
    p = HydraulicParams.from_table(table)
    hs = HydraulicSystem(p, n_sim=1, dt=DT)
    v = np.array([[1.0, -1.0, 0.0] + [0.1] * 9])
    f = hs.seal_friction(v)
    assert f[0, 0] == pytest.approx(-(p.seal_friction_n[0] * np.tanh(1e3) + p.seal_viscous_n_s_m[0]))
    assert f[0, 1] == -f[0, 0] and f[0, 2] == 0.0


# ---------------------------------------------------------------- stability at dt
@pytest.mark.parametrize("dt", [DT, 1.0 / 2048])
def test_stable_random_cgs(table, dt):
    p = HydraulicParams.from_table(table)
    hs = HydraulicSystem(p, n_sim=2, dt=dt)
    # rod-only masses (highest oil-column frequency) and bare-table shares (Table 2 / 4)
    m = np.array([[450.0] * 12, [12000.0] * 8 + [13000.0] * 4])
    rng = np.random.default_rng(4)
    x = np.zeros((2, 12))
    v = np.zeros((2, 12))
    hs.reset(x)
    n_drive, n_free = 4000, 2000
    vmax = []
    for k in range(n_drive + n_free):
        if k < n_drive and k % 20 == 0:
            cmd = rng.uniform(-0.5, 0.5, (2, 12))
        if k >= n_drive:
            cmd = np.zeros((2, 12))
        c = np.clip(cmd - 4.0 * x / p.half_stroke_m, -1, 1)
        F = hs.step(c, x, v)
        v = v + (F + hs.seal_friction(v)) / m * dt
        x = x + v * dt
        assert np.all(hs.state.p_a >= p.vapour_pressure_pa) and np.all(hs.state.p_a <= p.relief_pressure_pa)
        vmax.append(np.abs(v).max())
    vmax = np.array(vmax)
    assert np.all(np.isfinite(vmax))
    # after the drive stops, the motion dies out instead of growing
    w = 200
    early = vmax[n_drive + 200 : n_drive + 200 + w].max()
    late = vmax[-w:].max()
    assert late < early


def step_map_jacobian(hs, m, cmd, x, v, F_ext):
    """Finite-difference Jacobian of one coupled step (hydraulics + symplectic Euler mass)
    with respect to z = (spool, spool_rate, p_a, p_b, x, v) of the single actuator."""
    X0, Y0 = hs._X.copy(), hs._Y.copy()

    def f(z):
        hs._X[:] = X0
        hs._Y[:] = Y0
        hs._X[0, 0, 0], hs._X[1, 0, 0], hs._X[2, 0, 0], hs._X[3, 0, 0] = z[:4]
        xx = np.array([[z[4]]])
        vv = np.array([[z[5]]])
        F = hs.step(cmd, xx, vv)[0, 0]
        vn = z[5] + (F - F_ext) / m * DT
        xn = z[4] + vn * DT
        return np.array([hs._X[0, 0, 0], hs._X[1, 0, 0], hs._X[2, 0, 0], hs._X[3, 0, 0], xn, vn])

    z0 = np.array([X0[0, 0, 0], X0[1, 0, 0], X0[2, 0, 0], X0[3, 0, 0], x, v])
    hsteps = np.array([1e-7, 1e-5, 1.0, 1.0, 1e-8, 1e-6])
    J = np.empty((6, 6))
    for j in range(6):
        e = np.zeros(6)
        e[j] = hsteps[j]
        J[:, j] = (f(z0 + e) - f(z0 - e)) / (2 * hsteps[j]) * (hsteps[j] / hsteps)  # scaled
    hs._X[:] = X0
    hs._Y[:] = Y0
    return J


@pytest.mark.parametrize("opening", [0.05, 0.3, 1.0])
@pytest.mark.parametrize("mass", [450.0, 12000.0])
def test_linearised_step_is_stable(table, opening, mass):
    """Spectral radius of the linearised coupled step <= 1 at the stiffest operating points:
    piston stalled against a load so the open lands sit in the laminar region (K_c large)."""
    t = copy.deepcopy(table)
    t["actuator"] = t["actuator"][:1]
    p = HydraulicParams.from_table(t)
    hs = HydraulicSystem(p, n_sim=1, dt=DT, backend="numpy")
    x = np.zeros((1, 1))
    hs.reset(x)
    cmd = np.full((1, 1), opening)
    for _ in range(1000):  # stall: pressures settle at p_a -> p_s, p_b -> p_t
        F = hs.step(cmd, x, x)
    dpa = p.supply_pressure_pa - hs.state.p_a[0, 0]
    assert dpa < p.laminar_drop_pa  # in the laminar region: the stiff case
    J = step_map_jacobian(hs, mass, cmd, 0.0, 0.0, float(F[0, 0]))
    lam = np.linalg.eigvals(J)
    rho = np.max(np.abs(lam))
    # the piston position is a pure integrator under valve control (one eigenvalue 1);
    # every other mode must decay
    rest = np.sort(np.abs(lam))[:-1]
    # explicit Euler of the chamber-a pressure equation would multiply by 1 - dt beta K_c / V,
    # K_c = K o g'(dp) of the open P-A land in its laminar region
    K = p.rated_flow_m3_s / math.sqrt(p.rated_drop_pa / 2)
    r = dpa / p.laminar_drop_pa
    kc = K * opening * (5 - 3 * r * r) / (4 * math.sqrt(p.laminar_drop_pa))
    va = p.dead_volume_a_m3[0] + p.area_a_m2[0] * p.half_stroke_m[0]
    explicit = 1.0 - DT * p.bulk_modulus_pa * kc / va
    print(
        f"opening {opening}, mass {mass}: |eigenvalues| {np.round(np.sort(np.abs(lam)), 6)} "
        f"(explicit Euler pressure factor {explicit:.2f})"
    )
    assert np.max(rest) < 1.0
    assert rho <= 1.0 + 1e-9
