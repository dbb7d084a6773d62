"""Least-squares identification (Eqs. 2-16 of [Ozcelik 2008]), Table 8 (Eqs. 18-26), CLI."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from sim.cli import main
from sim.identify import least_squares as I
from sim.papers import uniaxial as U

TRUE = dict(M=144e3, K=1.263e6, C=45.9e3, F=26.5e3)


def synthetic(name, amp, f_hz, dt=1 / 512, cycles=3, alpha=0.5, noise=0.0, seed=0):
    t = np.arange(int(cycles / f_hz / dt)) * dt
    w = 2 * np.pi * f_hz
    d = amp * np.sin(w * t)
    v = amp * w * np.cos(w * t)
    a = -amp * w * w * np.sin(w * t)
    F = TRUE["M"] * a + TRUE["K"] * d + TRUE["C"] * np.abs(v) ** alpha * np.sign(v) + TRUE["F"] * np.sign(v)
    if noise:
        F = F + noise * np.random.default_rng(seed).standard_normal(len(F))
    return I.Record(name=name, dt=dt, force=F, acc=a, vel=v, disp=d)


def test_exact_recovery_and_constrained():
    recs = [synthetic("S4", 0.04, 0.4), synthetic("S7", 0.10, 0.8), synthetic("S9", 0.2, 0.6)]
    for w in I.WEIGHTS:
        r = I.identify(recs, 0.5, weights=w)
        assert r.M_e_kg == pytest.approx(TRUE["M"], rel=1e-9)
        assert r.K_e_N_per_m == pytest.approx(TRUE["K"], rel=1e-9)
        assert r.C_e == pytest.approx(TRUE["C"], rel=1e-9)
        assert r.F_mu_N == pytest.approx(TRUE["F"], rel=1e-9)
        assert r.error < 1e-9
    rc = I.identify(recs, 0.5, ce_fixed=45.9e3)
    assert rc.constrained and rc.C_e == 45.9e3 and rc.F_mu_N == pytest.approx(TRUE["F"], rel=1e-9)
    # eps0^2 = 1 - b^T y0 (Eq. 11) equals the direct residual: check with noise
    noisy = [synthetic("a", 0.1, 0.8, noise=5e3, seed=1), synthetic("b", 0.2, 0.6, noise=5e3, seed=2)]
    r = I.identify(noisy, 0.5)
    assert 0 < r.error < 0.1
    # equal weights per test (Eq. 15): eps0^2 is the mean of the per-test squared errors... for the
    # lambda = 1/int F^2 choice the pooled eps^2 = (1/N) sum eps_i^2 at the optimum
    assert r.error**2 == pytest.approx(np.mean([e**2 for e in r.per_test_error.values()]), rel=1e-9)


def test_accelerometer_lowpass_prefilter_is_exact():
    """Only the acceleration went through the 100 Hz analog filter (the LHPOST's
    conditioners). Filtering the force alone leaves K_e H[u] - K_e u as a velocity error;
    filtering every regressor alike recovers the truth exactly."""
    import scipy.signal as sig

    recs = []
    for name, amp, f in (("S4", 0.04, 0.4), ("S7", 0.10, 0.8), ("S10", 0.2, 0.8)):
        r = synthetic(name, amp, f, cycles=4)
        a = sig.lfilter(*I.analog_lowpass(100.0, 1 / r.dt), r.acc)
        recs.append(I.Record(r.name, r.dt, r.force, a, r.vel, r.disp))
    raw = I.identify([I.prepare(r) for r in recs], 0.5, ce_fixed=45.9e3)
    pre = I.identify([I.prepare(r, accel_lowpass_hz=100.0) for r in recs], 0.5)
    assert abs(raw.F_mu_N / TRUE["F"] - 1) > 0.015  # the 4 ms filter delay alone: -2.2 % here
    assert pre.F_mu_N == pytest.approx(TRUE["F"], rel=1e-6)
    assert pre.C_e == pytest.approx(TRUE["C"], rel=1e-6)
    assert pre.M_e_kg == pytest.approx(TRUE["M"], rel=1e-6)
    assert pre.K_e_N_per_m == pytest.approx(TRUE["K"], rel=1e-6)
    # the analog filter's delay does not depend on the sampling rate (butter(fs=) pre-warps: it does)
    for fs in (512.0, 1024.0):
        w, gd = sig.group_delay(I.analog_lowpass(100.0, fs), w=[1.0], fs=fs)
        assert gd[0] / fs == pytest.approx(2.6131 / (2 * math.pi * 100.0), rel=0.01)


def test_deadband_leaves_out_stuck_samples():
    """At a reversal the platen sticks: the friction force is anything in [-F, F] while
    the velocity is (noise around) zero. Leaving out |v| < dead band removes the bias."""
    rng = np.random.default_rng(3)
    recs = []
    for name, amp, f in (("S1", 0.04, 0.04), ("S4", 0.04, 0.4), ("S7", 0.10, 0.8)):
        r = synthetic(name, amp, f, cycles=3, dt=1 / 512)
        v, F = r.vel.copy(), r.force.copy()
        t = np.arange(len(v)) * r.dt
        # a stick phase of 3 % of the period at every reversal of the displacement
        ph = (t * f) % 0.5
        stuck = (ph > 0.25 - 0.0075) & (ph < 0.25 + 0.0075)
        v[stuck] = 2e-4 * rng.standard_normal(stuck.sum())  # velocity noise around zero
        fr = TRUE["F"] * np.sin(np.pi * (ph[stuck] - 0.25) / 0.015) * -np.sign(r.disp[stuck])  # swings through 0
        F[stuck] = TRUE["K"] * r.disp[stuck] + fr
        recs.append(I.Record(name, r.dt, F, np.where(stuck, 0.0, r.acc), v, r.disp))
    plain = I.identify([I.prepare(r) for r in recs], 0.5, ce_fixed=45.9e3)
    db = I.identify([I.prepare(r, deadband_m_s=1e-3) for r in recs], 0.5, ce_fixed=45.9e3)
    assert abs(plain.F_mu_N / TRUE["F"] - 1) > 0.01
    assert db.F_mu_N == pytest.approx(TRUE["F"], rel=1e-6)
    assert db.M_e_kg == pytest.approx(TRUE["M"], rel=1e-6)


def test_alpha_scan_minimum_at_truth():
    recs = [synthetic("S7", 0.10, 0.8, alpha=0.5), synthetic("S10", 0.2, 0.8, alpha=0.5), synthetic("S4", 0.04, 0.4)]
    scan = I.scan_alpha(recs)
    best = min(scan, key=lambda s: s.error)
    assert best.alpha == pytest.approx(0.5)


def test_table8_closed_form_from_paper_parameters():
    g1, g2 = I.gamma_factors(0.5)
    assert g1 == pytest.approx(1.273, abs=5e-4) and g2 == pytest.approx(1.113, abs=5e-4)
    P = U.PAPER_PARAMS
    rows = I.table8([p[0] / 100 for p in U.PAPER_TABLE8], P["M_e_kg"], P["K_e_N_per_m"], P["C_e"], P["F_mu_N"])
    for row, p in zip(rows, U.PAPER_TABLE8):
        got = [row["xi_pct"], row["f_m_hz"], row["A_m"], row["u_max_cm"], row["F0_kN"]]
        for g, want in zip(got, p[1:]):
            assert g == pytest.approx(want, rel=0.005)
    # Eq. 25: xi = (3.97/v + 5.97/sqrt(v)) %
    v = 0.5
    assert 100 * I.xi_equivalent(
        v, **{k: P[k2] for k, k2 in (("M", "M_e_kg"), ("K", "K_e_N_per_m"), ("C", "C_e"), ("F", "F_mu_N"))}
    ) == pytest.approx(3.97 / v + 5.97 / math.sqrt(v), rel=0.01)


def test_harmonic_amplification_near_locus_at_large_force():
    P = U.PAPER_PARAMS
    row = I.table8([1.005], P["M_e_kg"], P["K_e_N_per_m"], P["C_e"], P["F_mu_N"])[0]
    h = I.harmonic_amplification(
        row["F0_kN"] * 1e3, P["M_e_kg"], P["K_e_N_per_m"], P["C_e"], P["F_mu_N"], cycles=20, steps_per_cycle=800
    )
    assert h["R_peak"] == pytest.approx(row["A_m"], rel=0.1)
    assert h["f_peak_hz"] == pytest.approx(row["f_m_hz"], abs=0.02)


def _write(tmp_path, rec, name="t.run.npz", **over):
    from sim.runs.runfile import FORMAT, RunFile, write_run

    n = len(rec.force)
    z6 = lambda c: np.column_stack([c] + [np.zeros(n)] * 5)  # noqa: E731
    ch = dict(
        actuator_force=np.column_stack([0.4 * rec.force, 0.6 * rec.force]),
        table_displacement=z6(rec.disp),
        table_velocity=z6(rec.vel),
        table_acceleration=z6(rec.acc),
        reference=z6(rec.disp),
    )
    ch.update(over)
    meta = {
        "format": FORMAT,
        "table": "ucsd",
        "sample_rate_hz": 1 / rec.dt,
        "actuators": ["E", "W"],
        "dofs": ["x", "y", "z", "rx", "ry", "rz"],
        "source": "simulated",
    }
    return str(write_run(tmp_path / name, RunFile(t=np.arange(n) * rec.dt, meta=meta, **ch)))


def test_cli_identify_json_and_text(tmp_path, capsys):
    p1 = _write(tmp_path, synthetic("a", 0.1, 0.8), "a.run.npz")
    p2 = _write(tmp_path, synthetic("b", 0.2, 0.6), "b.run.npz")
    assert main(["identify", p1, p2, "--model", "ucsd-ls", "--json", "--no-trim"]) == 0
    out = json.loads(capsys.readouterr().out)
    for k in ("M_e_kg", "K_e_N_per_m", "C_e", "F_mu_N", "alpha", "error"):
        assert k in out
    assert out["M_e_kg"] == pytest.approx(144e3, rel=1e-6) and out["error"] < 1e-6
    assert main(["identify", p1, "--model", "ucsd-ls"]) == 0
    assert "M_e" in capsys.readouterr().out


def test_cli_identify_bad_input(tmp_path, capsys):
    bad = tmp_path / "x.run.npz"
    bad.write_text("not a run file")
    assert main(["identify", str(bad), "--model", "ucsd-ls"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error:") and "\n" not in err
    assert main(["identify", str(tmp_path / "missing.run.npz"), "--model", "ucsd-ls"]) == 2
    capsys.readouterr()
    rec = synthetic("a", 0.1, 0.8)
    p = _write(tmp_path, rec, "nof.run.npz", actuator_force=None)
    assert main(["identify", p, "--model", "ucsd-ls"]) == 2
    err = capsys.readouterr().err.strip()
    assert "actuator_force" in err and "\n" not in err
    acc = np.column_stack([rec.acc] + [np.zeros(len(rec.acc))] * 5)
    acc[10, 0] = np.nan
    p = _write(tmp_path, rec, "nan.run.npz", table_acceleration=acc)
    assert main(["identify", p, "--model", "ucsd-ls"]) == 2
    err = capsys.readouterr().err.strip()
    assert ("NaN" in err or "finite" in err) and "\n" not in err


def test_cli_identify_holdout_scores_runs_not_fitted(tmp_path, capsys):
    """--holdout: the model fitted on runs a and d (two frequencies: one sine cannot tell
    mass from stiffness) scores run b of the same table to round-off, and a run whose
    force is 10 % larger at its normalised error, 0.1 / 1.1."""
    a = synthetic("a", 0.1, 0.8)
    b = synthetic("b", 0.2, 0.6)
    pa = _write(tmp_path, a, "a.run.npz")
    pd = _write(tmp_path, synthetic("d", 0.04, 0.4), "d.run.npz")
    pb = _write(tmp_path, b, "b.run.npz")
    f = np.column_stack([0.44 * b.force, 0.66 * b.force])
    pc = _write(tmp_path, b, "c.run.npz", actuator_force=f)
    assert main(["identify", pa, pd, "--model", "ucsd-ls", "--json", "--no-trim", "--holdout", pb, pc]) == 0
    out = json.loads(capsys.readouterr().out)
    ho = {Path(k).name: v for k, v in out["holdout_error"].items()}
    assert ho["b.run.npz"] < 1e-6
    assert ho["c.run.npz"] == pytest.approx(0.1 / 1.1, rel=1e-6)
    assert pa not in out["holdout_error"] and out["error"] < 1e-6
    assert main(["identify", pa, "--model", "ucsd-ls", "--holdout", pa]) == 2
    assert "both a fitted run and a --holdout run" in capsys.readouterr().err
