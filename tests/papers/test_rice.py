"""Rice table [Trombetti 2002]: description, analytical T(s) (Eqs. 1-8), the model's FRF."""

import math

import numpy as np
import pytest

from sim.effects import build_model
from sim.papers import rice as R

F = np.linspace(0.1, 120.0, 12000)


def mag(gains, ps="d0", **kw):
    return np.abs(R.transfer(F, None, gains, ps, **kw).T)


def test_known_parameters_from_the_description():
    tb = R.load()
    # Sec. 5.1 of [Trombetti 2002]: A = 82.13 cm^2, V = 1668.86 cm^3, m_t = 643 kg, m_b = 29 500 kg
    assert tb.area_m2 == pytest.approx(82.13e-4, rel=1e-9)
    assert tb.volume_m3 == pytest.approx(1668.86e-6, rel=1e-4)
    assert tb.m_t == pytest.approx(643.0)
    assert tb.m_b == pytest.approx(29500.0)
    # the builder's foundation spring reproduces the paper's f_b = 27.1 Hz, xi_b = 5.5 %
    assert tb.f_b_hz == pytest.approx(27.1, abs=0.01)
    assert tb.xi_b == pytest.approx(0.055, abs=2e-4)
    # k_t: 170 in^3/(V s) (Table 1, d0) in SI; k_le -> leakage k_le * A in the hydraulics
    assert tb.sets["d0"].kt_m3_per_v_s == pytest.approx(170 * 0.0254**3, rel=1e-4)
    assert tb.sets["pfr"].kle_m3_per_n_s == pytest.approx(7.0e-9)
    from sim.papers.uniaxial import rice_description

    desc, kt = rice_description("pfr")
    assert desc.raw["actuator_class"]["main"]["leakage_cross_m3_s_pa"] == pytest.approx(7.0e-9 * 82.13e-4)
    assert desc.raw["servovalve"]["delay_s"] == pytest.approx(0.0103)


def test_oil_column_from_known_parameters_without_fitting():
    # Eq. 11 with beta = 689.5 MPa: (A/pi) sqrt(beta / (V m_t))
    f = R.oil_column_hz(82.13e-4, 1668.86e-6, 643.0, 689.5e6)
    assert f == pytest.approx(66.27, abs=0.02)
    # with the flexible foundation (2-DOF: oil spring 4 beta A^2 / V between m_t and m_b)
    tb = R.load()
    k = 4 * 689.5e6 * tb.area_m2**2 / tb.volume_m3
    kb = (tb.m_b + tb.m_t) * (2 * math.pi * tb.f_b_hz) ** 2
    w2 = np.linalg.eigvals(np.linalg.solve(np.diag([tb.m_t, tb.m_b]), [[k, -k], [-k, k + kb]]))
    f2 = np.sqrt(np.sort(w2.real)) / (2 * math.pi)
    assert 67.0 <= f2[1] <= 70.0
    # closed-loop P = 1 (Fig. 3a): the oil-column peak at about 70 Hz
    fp, _ = R.peak_in(F, mag(R.Gains()), (45, 90))
    assert 67.0 <= fp <= 70.0


def test_gain_trends_of_the_analytical_model():
    base = mag(R.Gains())
    # P: a ~15 Hz peak arises (Fig. 3) and the magnitude rises everywhere
    for p in (2.0, 3.0):
        m = mag(R.Gains(p=p))
        fp, hp = R.peak_in(F, m, (10, 20))
        assert 10 <= fp <= 20 and hp > 1.0
        assert np.all(m[F > 1] > base[F > 1])
    assert math.isnan(R.peak_in(F, base, (10, 20))[0])
    # ... which the tau = 0 model misses, while it overestimates the oil column (P = 2)
    m0 = mag(R.Gains(p=2.0), delay=False)
    assert math.isnan(R.peak_in(F, m0, (10, 20))[0])
    assert R.peak_in(F, m0, (45, 90))[1] > 2 * R.peak_in(F, mag(R.Gains(p=2.0)), (45, 90))[1]
    # I: a narrow peak near 6 Hz, nothing changes above 20 Hz (Fig. 4)
    m = mag(R.Gains(i_hz=40.0))
    assert 5.0 <= R.peak_in(F, m, (2, 12))[0] <= 7.0
    assert np.max(np.abs(m[F > 20] / base[F > 20] - 1)) < 0.05
    # D: raises 10-60 Hz, oil column 70 -> 65 Hz (Fig. 5, sets d0/d10/d20)
    m20 = mag(R.Gains(d_s=0.020), "d20")
    band = (F > 10) & (F < 60)
    assert np.all(m20[band] >= 0.85 * base[band])
    assert R.peak_in(F, m20, (45, 90))[0] < R.peak_in(F, base, (45, 90))[0] - 2.5
    # FF: about three-fold rise over the band (Fig. 6)
    m30 = mag(R.Gains(ff_s=0.030))
    assert np.median((m30 / base)[(F > 20) & (F < 60)]) > 2.5
    # dP (Eq. 2 sign: negative damps): lower and lower-frequency oil-column peak (Fig. 7)
    p0, p3 = R.peak_in(F, base, (45, 90)), R.peak_in(F, mag(R.Gains(dp=-3.0)), (45, 90))
    assert p3[1] < p0[1] and p3[0] < p0[0]


def test_optimal_gains_and_payloads_analytical():
    m = mag(R.OPTIMAL, "d18")
    assert 5.0 <= R.peak_in(F, m, (2, 12))[0] <= 7.0  # Sec. 7: peak at about 5 Hz
    assert 24.0 <= R.peak_in(F, m, (20, 31))[0] <= 27.5  # peak and notch at 27 Hz
    assert 26.5 <= R.notch_in(F, m, (25.5, 32))[0] <= 30.0
    assert 62.0 <= R.peak_in(F, m, (45, 90))[0] <= 70.0  # oil column 67 Hz
    # rigid payloads (Fig. 11, set pr): central peak 36-42 Hz, narrowing down with weight
    fc = [R.peak_in(F, mag(R.PAYLOAD_GAINS, "pr", payload=R.rigid_modes(mp)), (30, 50))[0] for mp in (68, 204, 408)]
    assert all(35.5 <= f <= 42.0 for f in fc) and fc[0] > fc[1] > fc[2]
    # frames (Fig. 13, set pf): oil column drops to about 62 Hz
    for n in (297, 501):
        modes = R.payload_from_file(f"frame_3storey_{n}")
        assert [round(md.f_hz, 2) for md in modes] == pytest.approx(list(R.PAPER["frame_modes_model_hz"][n]), abs=0.02)
        assert 60.0 <= R.peak_in(F, mag(R.PAYLOAD_GAINS, "pf", payload=modes), (45, 90))[0] <= 64.0


def test_controller_volts():
    c = R.Conditioning(78.74, 39.37, 1.6115e-9)
    ctl = R.RiceController(R.Gains(p=2.0, i_hz=10.0, d_s=0.01, ff_s=0.02, dp=-3.0), c, 2.0e-3, 4.0e-3, dt=1e-3)
    v = ctl.volts(0.01, 0.1, 0.004, 0.05, 1e5)
    e = 0.006
    expect = (2.0 * e + 10.0 * e * 1e-3) * 78.74 + (0.01 * 0.05 + 0.02 * 0.1) * 39.37 - 3.0 * 1.6115e-9 * 1e5
    assert v == pytest.approx(expect, rel=1e-12)
    assert ctl.opening(1.0, 0, 0, 0, 0) == 1.0


@pytest.mark.slow
def test_model_frf_matches_analytical_optimal():
    """The issue's acceptance: bare optimal gains, |T| within 10 % from 0 to 100 Hz,
    estimated the paper's way (11 x 2^14 at 4000 Hz, Bartlett, Blackman-Harris)."""
    from sim.papers import uniaxial as U

    r = U.run_rice_case(U.RiceCase("optimal", R.OPTIMAL, "d18"))
    print(f"max |model/analytical - 1| 0-100 Hz = {r['max_error_0_100']:.3f} at {r['f_max_error']:.1f} Hz")
    assert r["max_error_0_100"] < 0.10
    fp = r["model_metrics"]["oil_peak"][0]
    assert 62.0 <= fp <= 70.0


@pytest.mark.slow
def test_model_reproduces_payload_and_gain_effects():
    from sim.papers import uniaxial as U

    cases = [
        U.RiceCase("P3", R.Gains(p=3.0), "d0"),
        U.RiceCase("rigid 408", R.PAYLOAD_GAINS, "pr", "rice_rigid_408"),
        U.RiceCase("rigid 68 clamp", R.PAYLOAD_GAINS, "pfr", "rice_rigid_68_clamp"),
        U.RiceCase("frame 297", R.PAYLOAD_GAINS, "pf", "frame_3storey_297"),
    ]
    res = {c.name: U.run_rice_case(c, n_segments=3) for c in cases}
    mm = {k: v["model_metrics"] for k, v in res.items()}
    assert 15.0 <= mm["P3"]["low_peak"][0] <= 20.0  # the ~15 Hz peak of Fig. 3
    assert 35.5 <= mm["rigid 408"]["central_peak"][0] <= 42.0  # central peak 36-42 Hz
    assert mm["rigid 408"]["foundation_peak"][1] > 2.0  # 27 Hz peak grows with payload
    # the split oil-column peak: where Eqs. 1-8 put it (measured 55.63 vs 55.72 Hz), and
    # within 1.5 Hz of the paper's "about 57 Hz" (Sec. 8.2 of [Trombetti 2002])
    small = mm["rigid 68 clamp"]["small_peak"][0]
    assert abs(small - res["rigid 68 clamp"]["analytical_metrics"]["small_peak"][0]) < 0.5
    assert abs(small - 57.0) <= 1.5
    assert 60.0 <= mm["frame 297"]["oil_peak"][0] <= 64.0  # oil column drops to ~62 Hz
    spikes = [s[0] for s in mm["frame 297"]["spikes"]]
    assert spikes[0] == pytest.approx(7.22, abs=1.0)  # spike at the first mode


def test_shaketable_run_rice_scenario_tracks_a_low_frequency_sine(tmp_path):
    """`shaketable run` on a Rice scenario: the Rice controller ([controller] type = "analog")
    at 8 kHz physics steps, run file + summary.json at 4000 Hz; the achieved 1 Hz response
    is Eq. 1's T(j 2 pi 1 Hz) (x_ta / x_d, optimal gains, set d18)."""
    import json

    from sim.cli import main
    from sim.runs.runfile import read_run

    assert main(["run", "scenarios/rice_sine.toml", "--out", str(tmp_path)]) == 0
    s = json.loads((tmp_path / "summary.json").read_text())
    assert s["complete"] and s["table"] == "rice"
    assert s["tracking"]["x"]["nrmse_displacement"] < 0.05
    run = read_run(tmp_path / "rice_sine.run.npz")
    assert run.meta["sample_rate_hz"] == 4000.0
    t = run.t
    x = run.column("table_displacement", "x")
    r = run.reference[:, 0]
    sel = (t >= 0.5) & (t < 2.5)  # two full-amplitude cycles of the tapered sine
    e = np.exp(-2j * np.pi * t[sel])
    H = np.sum(x[sel] * e) / np.sum(r[sel] * e)
    T = R.transfer([1.0], gains=R.OPTIMAL, params="d18").T[0]
    assert abs(H / T - 1) < 0.005


# ------------------------------------------------------------------ the clamped blocks' split (Sec. 8.2)
CLAMPED = (68, 204, 408)


def _clamp_peaks(mass, fraction, f=F):
    """Eq. 1-8 (payload gains, set pfr) with ``fraction`` of the block on the 52 Hz clamp:
    the upper (split oil-column) peak, the central peak, the foundation peak (f, |T|)."""
    m = np.abs(R.transfer(f, None, R.PAYLOAD_GAINS, "pfr", R.rigid_modes(mass, R.PAPER["clamp_hz"], 0.02, fraction)).T)
    return R.peak_in(f, m, (45, 100)), R.peak_in(f, m, (30, 45)), R.peak_in(f, m, (22, 31))


def _fraction_for(mass, target_hz, lo=0.02, hi=1.0):
    """The clamped fraction that puts the upper peak of ``mass`` at ``target_hz`` (bisection;
    the peak rises monotonically with the fraction)."""
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if _clamp_peaks(mass, mid)[0][0] > target_hz else (mid, hi)
    return 0.5 * (lo + hi)


def test_clamp_mass_fraction_in_the_payload_and_the_model():
    import tomllib

    import mujoco

    from mjcf.builder import BuildOptions
    from mjcf.description import DescriptionError, load_payload, parse_payload
    from mjcf.stepping import stepped_mode
    from sim.papers.uniaxial import rice_description

    p = load_payload("rice_rigid_204_clamp")
    a = p.clamp_mass_fraction
    assert 0.0 < a < 1.0
    modes = R.payload_from_file("rice_rigid_204_clamp")
    assert sum(md.mass_kg for md in modes) == pytest.approx(204.0)
    assert [md.mass_kg for md in modes if md.f_hz == 52.0] == pytest.approx([a * 204.0])
    # MuJoCo: the clamped part on the 52 Hz spring, the rest a rigid body of the platen
    desc, _ = rice_description("pfr")
    tm = build_model(desc, p, BuildOptions(timestep_s=1 / 8000))
    m = tm.model
    body = lambda n: m.body(n).id  # noqa: E731
    assert m.body_mass[body("payload")] == pytest.approx(a * 204.0)
    assert m.body_mass[body("payload_fixed")] == pytest.approx((1 - a) * 204.0)
    jx = m.joint("payload_clamp_x")
    k, c = m.jnt_stiffness[jx.id], m.dof_damping[jx.dofadr[0]]
    f_cont, z_cont = math.sqrt(k / (a * 204.0)) / (2 * math.pi), c / (2 * math.sqrt(k * a * 204.0))
    # the spring and damper as the 1/8000 s step has them (mjcf.stepping)
    assert stepped_mode(f_cont, z_cont, m.opt.timestep) == (pytest.approx(52.0), pytest.approx(p.clamp_damping_ratio))
    d = tm.new_data()
    jz = m.joint("payload_clamp_z")
    for _ in range(800):
        mujoco.mj_step(m, d)
    assert not any(w.number for w in d.warning)
    assert abs(d.qpos[m.jnt_qposadr[jz.id]] - m.qpos0[m.jnt_qposadr[jz.id]]) < 1e-6  # at rest under gravity
    # default: the whole block on the clamp (one body); the key needs a clamp and is in (0, 1]
    raw = tomllib.loads(_payload_text("rice_rigid_204_clamp"))
    del raw["payload"]["clamp_mass_fraction"]
    p1 = parse_payload(raw)
    assert p1.clamp_mass_fraction == 1.0
    assert R.rigid_modes(204.0, 52.0, 0.02) == [R.Mode(204.0, 52.0, 0.02)]
    tm1 = build_model(desc, p1, BuildOptions(timestep_s=1 / 8000))
    assert tm1.model.body("payload").mass[0] == pytest.approx(204.0)
    assert mujoco.mj_name2id(tm1.model, mujoco.mjtObj.mjOBJ_BODY, "payload_fixed") == -1
    for bad in ({"clamp_mass_fraction": 1.5}, {"clamp_mass_fraction": 0.0}):
        r2 = tomllib.loads(_payload_text("rice_rigid_204_clamp"))
        r2["payload"].update(bad)
        with pytest.raises(DescriptionError, match="clamp_mass_fraction"):
            parse_payload(r2)
    r3 = tomllib.loads(_payload_text("rice_rigid_204"))
    r3["payload"]["clamp_mass_fraction"] = 0.5
    with pytest.raises(DescriptionError, match="needs 'payload.clamp_frequency_hz'"):
        parse_payload(r3)


def _payload_text(name):
    from mjcf.description import PAYLOADS_DIR

    return (PAYLOADS_DIR / f"{name}.toml").read_text()


def _two_mass_upper_hz(mass_kg, clamp_hz=52.0):
    """Upper natural frequency of the table m_t on its oil column k = 4 beta A^2 / V (Eq. 11
    of [Trombetti 2002], set pfr) carrying ``mass_kg`` on a spring of ``clamp_hz``: the larger
    root of w^4 - w^2 (w_o^2 + w_c^2 (1 + m/m_t)) + w_o^2 w_c^2 = 0 (no loop, no damping)."""
    tb = R.load()
    wo2 = 4 * tb.area_m2**2 * tb.sets["pfr"].beta_pa / (tb.volume_m3 * tb.m_t)
    wc2 = (2 * math.pi * clamp_hz) ** 2
    b = wo2 + wc2 * (1 + mass_kg / tb.m_t)
    return math.sqrt((b + math.sqrt(b * b - 4 * wo2 * wc2)) / 2) / (2 * math.pi)


def test_clamp_split_puts_the_small_peak_near_57_hz_analytical():
    """Sec. 8.1/8.2: a small peak at about 57 Hz for all three blocks, central peak 36-42 Hz,
    foundation peak 1.7 / 2.0 / 3.0. One clamped fraction, the same for every block (the
    payload files' calibrated value), Eq. 1-8 with set pfr."""
    fr = {mp: R.payload_from_file(f"rice_rigid_{mp}_clamp") for mp in CLAMPED}
    fracs = {mp: sum(md.mass_kg for md in m if md.f_hz == 52.0) / mp for mp, m in fr.items()}
    assert len({round(v, 12) for v in fracs.values()}) == 1  # the same fraction for every block
    a = fracs[68]
    got = {mp: _clamp_peaks(mp, a) for mp in CLAMPED}
    whole = {mp: _clamp_peaks(mp, 1.0) for mp in CLAMPED}
    small = [got[mp][0][0] for mp in CLAMPED]
    # the whole block on the clamp (the paper's SDOF taken literally) misses the paper's
    # ~57 Hz by 5 Hz or more on every block (Eqs. 1-8 give 62.1 / 75.4 / 84.8 Hz), rising
    # with the mass as the two-mass closed form does: the upper root of the table on its
    # oil column (Eq. 11, set pfr: 57.0 Hz) carrying the block on its 52 Hz clamp, 64.0 /
    # 71.3 / 79.2 Hz (no loop: the controller stiffens the heavier blocks' peak further)
    up = [w[0][0] for w in whole.values()]
    two_mass = [_two_mass_upper_hz(mp) for mp in CLAMPED]
    assert two_mass[0] < two_mass[1] < two_mass[2] and up[0] < up[1] < up[2]
    assert all(f - 57.0 >= 5.0 for f in up), up
    assert all(abs(f - f2) < 6.0 for f, f2 in zip(up, two_mass)), (up, two_mass)
    # the split: within 1.5 Hz of 57 for all three
    assert all(abs(s - 57.0) <= 1.5 for s in small), small
    # ... but still rising with the mass (the paper's peak stays at about 57 Hz): no one
    # fraction puts all three within 1 Hz (68 kg needs more on the clamp than 408 kg allows)
    assert small[0] < small[1] < small[2]
    assert _fraction_for(68, 56.0) > _fraction_for(408, 58.0)
    # central peak: 68 and 204 kg inside 36-42 Hz; 408 kg below it with set pfr at any
    # fraction, no worse than with the whole block on the clamp
    assert all(36.0 <= got[mp][1][0] <= 42.0 for mp in (68, 204))
    assert whole[408][1][0] < got[408][1][0] < 36.0
    # foundation peak 1.7 / 2.0 / 3.0: 68 and 204 kg within 0.05; 408 kg lower than with
    # the whole block on the clamp (2.96) but above the perfectly rigid model (set pr)
    fd = [got[mp][2][1] for mp in CLAMPED]
    assert fd[0] < fd[1] < fd[2]
    assert fd[:2] == pytest.approx([1.7, 2.0], abs=0.05)
    rigid408 = R.peak_in(F, mag(R.PAYLOAD_GAINS, "pr", payload=R.rigid_modes(408)), (22, 31))[1]
    assert rigid408 < fd[2] < whole[408][2][1]


def test_clamp_fraction_chosen_on_one_block_predicts_the_others():
    """The strong form: the fraction fitted to 57.0 Hz on one block, the others predicted."""
    from mjcf.description import load_payload

    fit = {mp: _fraction_for(mp, 57.0) for mp in CLAMPED}
    assert fit[68] > fit[204] > fit[408]
    pred = {src: {mp: _clamp_peaks(mp, fit[src])[0][0] for mp in CLAMPED} for src in CLAMPED}
    # chosen on 204 kg: 408 kg within 1 Hz, 68 kg within 1.5 Hz
    assert abs(pred[204][408] - 57.0) < 1.0 and abs(pred[204][68] - 57.0) < 1.5
    # chosen on 408 kg: both others within 2 Hz (below 57)
    assert all(55.0 <= pred[408][mp] < 57.0 for mp in (68, 204))
    # chosen on 68 kg: fails for the heavier blocks (the 68 kg peak is insensitive to the fraction)
    assert pred[68][408] > 60.0
    # the payload files' fraction lies between the 204 and 68 kg fits (minimax of the three)
    a = load_payload("rice_rigid_68_clamp").clamp_mass_fraction
    assert fit[204] < a < fit[68]
    # the alternative, the same clamped mass on every block: the peak falls with the mass
    mc = fit[204] * 204.0
    alt = [_clamp_peaks(mp, min(1.0, mc / mp))[0][0] for mp in CLAMPED]
    assert alt[0] > alt[1] > alt[2] and max(abs(x - 57.0) for x in alt) > 1.5


@pytest.mark.slow
def test_model_clamp_split_small_peak():
    """One model FRF (the paper's estimate): 408 kg, the block whose small peak is the most
    sensitive to the split, with the payload file's fraction."""
    from sim.papers import uniaxial as U

    r = U.run_rice_case(U.RiceCase("rigid 408 clamp", R.PAYLOAD_GAINS, "pfr", "rice_rigid_408_clamp"))
    f = r["f"]
    hm = U._smooth(np.abs(r["model"]))
    fm = R.peak_in(f, hm, (45, 100))[0]
    fe = R.peak_in(f, np.abs(r["analytical"]), (45, 100))[0]
    print(f"408 kg clamp split: small peak model {fm:.2f} Hz, Eq. {fe:.2f} Hz")
    assert abs(fm - 57.0) <= 1.5
    assert abs(fm - fe) < 0.5
    mm, am = r["model_metrics"], r["analytical_metrics"]
    assert abs(mm["central_peak"][0] - am["central_peak"][0]) < 0.5
    assert mm["foundation_peak"][1] == pytest.approx(am["foundation_peak"][1], rel=0.03)
