"""NEES-UCSD LHPOST [Ozcelik 2008]: description and the identification of simulated tests."""

import math

import numpy as np
import pytest

from sim.effects import build_model
from sim.identify import least_squares as I
from sim.papers import uniaxial as U


def test_description_matches_the_paper():
    desc = U.ucsd_description(13.8)
    tm = build_model(desc)
    assert tm.effective_mass()["x"] == pytest.approx(144e3, rel=1e-3)  # M_e 144 t
    assert desc.actuator_names == ("E", "W")
    eff = {e["type"]: e for e in desc.effects}
    assert eff["platen_spring"]["stiffness_n_m"] == pytest.approx(1.263e6)
    assert eff["platen_coulomb"]["force_n"] == pytest.approx(4.1e3 + 0.0039 * 5.783e6)
    assert eff["platen_power_damping"]["coefficient"] == 45.9e3 and eff["platen_power_damping"]["exponent"] == 0.5
    # oil column: both oil springs 4 beta A^2 / V at mid-stroke on M_e -> 10.66 Hz
    beta = desc.raw["fluid"]["bulk_modulus_pa"]
    k = sum(
        4 * beta * c.area_a_m2**2 / (2 * (c.dead_volume_a_m3 + c.area_a_m2 * c.half_stroke_m))
        for c in (a.cls for a in desc.actuators)
    )
    assert math.sqrt(k / 144e3) / (2 * math.pi) == pytest.approx(10.66, abs=0.02)
    assert desc.raw["controller"]["rate_hz"] == 1024.0
    assert U.ucsd_description(6.9).raw["effect"][0]["stiffness_n_m"] == pytest.approx(0.635e6)
    assert U.ucsd_description(0.0).raw["effect"][1]["force_n"] == pytest.approx(4.1e3 + 0.0039 * 1.613e6)


def test_programme_motions():
    for n in U.ucsd_tests("triangular"):
        mo = U.ucsd_motion(n, 1024.0)
        D, V = U.UCSD_TRIANGLES[n]
        assert np.abs(mo.d).max() == pytest.approx(D / 100, rel=1e-3)
        assert np.abs(mo.v).max() == pytest.approx(V / 100, rel=1e-3)
        assert np.abs(mo.a).max() <= 2 * 9.81 * 1.001
    mo = U.ucsd_motion("S8", 1024.0)
    assert np.abs(mo.v).max() == pytest.approx(0.7536, rel=0.01)


def _identify(names, **kw):
    res = U.ucsd_programme(names, workers=2)
    recs = {r.name: I.prepare(r, **kw) for r in U.ucsd_records(res)}
    return recs


def test_periodic_identification_recovers_friction_and_table8():
    """The periodic tests of [Ozcelik 2008] on the model, through the DAQ model (512 Hz, 100 Hz
    accelerometer filter, noise): with the accelerometer filter applied to every term
    and the stuck samples left out, the least squares returns the model's parameters,
    F_mu within 2 % of the paper's 26.5 kN and Table 8 within 1 % on every row."""
    names = ["T3", "T4", "T6", "T8", "T10", "S3", "S4", "S5", "S7", "S8", "S10"]
    recs = _identify(names, accel_lowpass_hz=100.0, deadband_m_s=U.UCSD_DEADBAND_M_S)
    con = I.identify(list(recs.values()), 0.5, ce_fixed=45.9e3)
    unc = I.identify(list(recs.values()), 0.5)
    print(con.as_dict(), unc.as_dict())
    assert con.F_mu_N == pytest.approx(26.5e3, rel=0.02)
    assert con.F_mu_N == pytest.approx(4.1e3 + 0.0039 * 5.783e6, rel=0.01)  # the model's own friction
    assert con.M_e_kg == pytest.approx(144e3, rel=0.005)
    assert con.K_e_N_per_m == pytest.approx(1.263e6, rel=0.005)
    assert unc.C_e == pytest.approx(45.9e3, rel=0.05)
    rows = I.table8([p[0] / 100 for p in U.PAPER_TABLE8], con.M_e_kg, con.K_e_N_per_m, con.C_e, con.F_mu_N)
    for row, p in zip(rows, U.PAPER_TABLE8):
        got = [row["xi_pct"], row["f_m_hz"], row["A_m"], row["u_max_cm"], row["F0_kN"]]
        for g, want in zip(got, p[1:]):
            assert g == pytest.approx(want, rel=0.01)


def test_el_centro_identification_recovers_friction():
    """El Centro: many reversals and quiet stretches where the platen sticks; with the
    dead band the friction is the model's (it was 15 kN with every sample in the fit)."""
    recs = _identify(["EC20", "EC100"], accel_lowpass_hz=100.0, deadband_m_s=U.UCSD_DEADBAND_M_S)
    con = I.identify(list(recs.values()), 0.5, ce_fixed=45.9e3)
    plain = I.identify([I.prepare(r, accel_lowpass_hz=100.0) for r in recs.values()], 0.5, ce_fixed=45.9e3)
    print(con.as_dict(), plain.F_mu_N)
    assert con.F_mu_N == pytest.approx(4.1e3 + 0.0039 * 5.783e6, rel=0.02)
    assert con.M_e_kg == pytest.approx(144e3, rel=0.01)
    assert plain.F_mu_N < 0.95 * con.F_mu_N


@pytest.mark.slow
def test_identification_of_simulated_periodic_and_white_noise_tests():
    names = ["T4", "T5", "T6", "T7", "T8", "T9", "T10", "S4", "S5", "S6", "S7", "S8", "S9", "S10", "WN3", "WN5", "WN7"]
    res = U.ucsd_programme(names, workers=2)
    recs = {r.name: I.prepare(r, accel_lowpass_hz=100.0, deadband_m_s=U.UCSD_DEADBAND_M_S) for r in U.ucsd_records(res)}
    per = I.identify([recs[n] for n in names if n[0] in "TS"], 0.5)
    print(per.as_dict())
    assert per.M_e_kg == pytest.approx(144e3, rel=0.01)
    assert per.K_e_N_per_m == pytest.approx(1.263e6, rel=0.01)
    # white noise 3-7 % g: with the filter applied to every term and the dead band, the
    # model's mass and stiffness come back (the paper's K_e overestimate from low-level
    # white noise is a property of the real table the model does not have: docs/uniaxial.md)
    wn = I.identify([recs[n] for n in ("WN3", "WN5", "WN7")], 0.5, ce_fixed=45.9e3)
    print(wn.as_dict())
    assert wn.M_e_kg == pytest.approx(144e3, rel=0.02)
    assert wn.K_e_N_per_m == pytest.approx(1.263e6, rel=0.03)
    assert wn.F_mu_N == pytest.approx(4.1e3 + 0.0039 * 5.783e6, rel=0.02)


def test_presliding_platen_friction_law():
    """The platen_coulomb effect with presliding_m (Dahl): a spring F_mu/delta for travels
    much smaller than delta, F_mu after a travel of many delta, bounded at any v dt, and
    the MuJoCo stick constraint replaced (no frictionloss on the slide), reset by the loop."""
    from sim.effects.mechanical import CoulombFriction
    from sim.loop.simulation import Simulation

    fc, delta, dt = 26.65e3, 0.4e-3, 1 / 2048
    e = CoulombFriction({"where": "dof:x", "force_n": fc, "presliding_m": delta})
    amp, w, x, err = 5e-6, 2 * math.pi * 2.0, 0.0, 0.0
    for k in range(2048):  # 5 um at 2 Hz (travel 1/40 of delta): a spring of fc / delta
        v = amp * w * math.cos(w * (k + 0.5) * dt)
        f = e.advance(v, dt)
        x += v * dt
        err = max(err, abs(f + fc / delta * x))
    assert err < 0.03 * fc / delta * amp
    e.reset()
    for _ in range(200):  # 10 cm/s for 0.1 s = 10 mm = 25 delta
        f = e.advance(0.1, dt)
    assert f == pytest.approx(-fc, rel=1e-9)
    assert e.advance(-1e3, dt) == pytest.approx(fc, rel=1e-9)  # a huge step stays bounded
    tm = build_model(U.ucsd_description(13.8, presliding_m=delta))
    j = tm.model.joint("platen_x")
    assert float(j.frictionloss[0]) == 0.0
    (pf,) = [s for s in tm.step_effects if isinstance(s, CoulombFriction)]
    pf.z = 1e-4
    Simulation(tm)  # reset() on construction
    assert pf.z == 0.0


def test_presliding_reproduces_the_low_amplitude_white_noise_stiffness():
    """[Ozcelik 2008]: low-level white noise (3-7 % g rms) gives the right M_e (143.6 t) but
    K_e 2.02 MN/m, +60 % on the periodic 1.263; 10-13 % g gives 1.405 (+11 %). With the
    platen friction's pre-sliding travel (UCSD_PRESLIDING_M, calibrated on the 3-7 % g set
    alone) the model reproduces the first and predicts the second: at 3-7 % g most
    excursions between reversals are shorter than 2 delta, the friction stays elastic
    and the least squares reads it as stiffness. Same processing as the periodic test."""
    names = ["WN3", "WN5", "WN7", "WN10", "WN13"]
    res = U.ucsd_programme(names, workers=2, presliding_m=U.UCSD_PRESLIDING_M)
    recs = {r.name: I.prepare(r, accel_lowpass_hz=100.0, deadband_m_s=U.UCSD_DEADBAND_M_S) for r in U.ucsd_records(res)}
    low = I.identify([recs[n] for n in names[:3]], 0.5, ce_fixed=45.9e3)
    high = I.identify([recs[n] for n in names[3:]], 0.5, ce_fixed=45.9e3)
    low_u = I.identify([recs[n] for n in names[:3]], 0.5)
    print(low.as_dict(), high.as_dict(), low_u.as_dict())
    assert low.M_e_kg == pytest.approx(143.6e3, rel=0.02)
    assert high.M_e_kg == pytest.approx(144.0e3, rel=0.02)
    assert low.K_e_N_per_m == pytest.approx(2.024e6, rel=0.03)  # calibrated on this set
    assert low.K_e_N_per_m > 1.5 * 1.263e6  # well above the periodic K_e
    assert high.K_e_N_per_m == pytest.approx(1.405e6, rel=0.05)  # predicted (not calibrated on)
    assert 1.05 * 1.263e6 < high.K_e_N_per_m < low.K_e_N_per_m  # the smaller the level, the larger the error
    # the paper's unconstrained white-noise friction (14.1-14.6 kN) is far below the periodic 26.5
    assert low_u.F_mu_N < 0.7 * 26.5e3
