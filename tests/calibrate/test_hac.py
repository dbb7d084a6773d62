"""The correlated-residual standard deviations (sim.calibrate.hac) on a closed-form case:
a linear regression with AR(1) noise of known coefficient, where the estimate's true
standard deviation is (X^T X)^-1 X^T Sigma X (X^T X)^-1 with Sigma_ij = rho^|i-j| / (1 - rho^2)."""

import math

import numpy as np
import pytest

from sim.calibrate.hac import blocks, hac_sigma, long_run_sum, naive_sigma

T = 2000  # samples per segment (a 2 s window at 1 kHz)
RUNS = 2  # segments stacked, independent of each other


def _design():
    t = np.arange(T) / T
    # a smooth regressor (a few periods per segment, like a table's motion) and an offset
    x = np.concatenate([np.sin(2 * math.pi * (3 + k) * t + k) for k in range(RUNS)])
    return np.stack([np.ones(RUNS * T), x], axis=1)


def _true_sd(X, rho):
    lag = np.abs(np.subtract.outer(np.arange(T), np.arange(T)))
    S = rho**lag / (1 - rho**2)
    Ainv = np.linalg.inv(X.T @ X)
    Om = sum(X[k * T : (k + 1) * T].T @ S @ X[k * T : (k + 1) * T] for k in range(RUNS))
    return np.sqrt(np.diag(Ainv @ Om @ Ainv))


def _ar1(rng, rho):
    w = rng.standard_normal(RUNS * (T + 200)).reshape(RUNS, T + 200)
    e = np.empty_like(w)
    e[:, 0] = w[:, 0] / math.sqrt(1 - rho**2)
    for i in range(1, w.shape[1]):
        e[:, i] = rho * e[:, i - 1] + w[:, i]
    return e[:, 200:].reshape(-1)


def _coverage(rho, seeds):
    X = _design()
    truth = np.array([0.3, 1.7])
    true_sd = _true_sd(X, rho)
    segs = blocks([T] * RUNS)
    hits_h = hits_n = 0
    ratio, est = [], []
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        y = X @ truth + _ar1(rng, rho)
        theta, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ theta
        sh, sn = hac_sigma(X, r, segs)[1], naive_sigma(X, r)[1]
        err = abs(theta[1] - truth[1])
        hits_h += err <= 1.96 * sh
        hits_n += err <= 1.96 * sn
        ratio.append(sh / true_sd[1])
        est.append(theta[1])
    return hits_h / seeds, hits_n / seeds, float(np.mean(ratio)), float(np.std(est)) / true_sd[1]


def test_ar1_coverage_strongly_correlated():
    """rho = 0.9: the textbook interval is ~4x too narrow; the HAC interval covers ~95 %."""
    cov_h, cov_n, ratio, mc = _coverage(0.9, 300)
    assert 0.9 < mc < 1.1  # the closed form is the estimate's spread (checks the test itself)
    assert cov_n < 0.5, cov_n
    assert 0.9 <= cov_h <= 0.99, cov_h
    assert 0.8 < ratio < 1.1, ratio


def test_ar1_coverage_mildly_correlated():
    cov_h, cov_n, ratio, _ = _coverage(0.5, 300)
    assert cov_n < 0.85, cov_n
    assert 0.92 <= cov_h <= 0.99, cov_h
    assert 0.9 < ratio < 1.1, ratio


def test_white_residual_matches_textbook():
    """Independent samples of one variance: the Bartlett sum is the textbook s^2 (X^T X)^-1
    (within 10 %), and the reported value (the larger of it and the spectral variance) is
    never below it and on average within a few per cent of the textbook (1.027 measured
    over 200 seeds: the larger of two estimates of one value is a little above either)."""
    from sim.calibrate.hac import bartlett_bandwidth

    X = _design()
    segs = blocks([T] * RUNS)
    ratio = []
    for seed in range(7, 47):
        rng = np.random.default_rng(seed)
        y = X @ np.array([0.3, 1.7]) + rng.standard_normal(len(X))
        theta, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ theta
        h, n = hac_sigma(X, r, segs), naive_sigma(X, r)
        u = (X @ np.linalg.inv(X.T @ X))[:, 1] * r
        parts = [u[s] for s in segs]
        b = math.sqrt(long_run_sum(parts, bartlett_bandwidth(parts, T)) * len(y) / (len(y) - 2))
        if seed == 7:
            assert b == pytest.approx(n[1], rel=0.1), (b, n)
        assert h[1] >= b * (1 - 1e-12), (h, b)
        ratio.append(h[1] / n[1])
    assert 1.0 <= float(np.mean(ratio)) < 1.06, np.mean(ratio)


def test_holes_count_as_zeros():
    """A segment given with -1 at samples not in the fit equals the same samples with the
    score zeroed there, and a segment in two pieces loses the lags across the cut."""
    rng = np.random.default_rng(3)
    X = np.stack([np.ones(T), np.sin(np.arange(T) / 50)], axis=1)
    r = _ar1(rng, 0.8)[:T]
    keep = np.ones(T, bool)
    keep[500:520] = False
    pos = np.where(keep, np.cumsum(keep) - 1, -1)
    Xk, rk = X[keep], r[keep]
    a = hac_sigma(Xk, rk, [pos])
    zeroed = hac_sigma(np.where(keep[:, None], X, 0.0), np.where(keep, r, 0.0), [np.arange(T)])
    assert np.allclose(a * math.sqrt((T - 20 - 2) / (T - 20)), zeroed * math.sqrt((T - 2) / T), rtol=1e-9)


def test_long_run_sum_is_bartlett_weighted_autocovariance():
    u = np.random.default_rng(1).standard_normal(300)
    L = 11
    g = [float(u[k:] @ u[: u.size - k]) for k in range(L + 1)]
    want = g[0] + 2 * sum((1 - k / (L + 1)) * g[k] for k in range(1, L + 1))
    assert long_run_sum([u], L) == pytest.approx(want, rel=1e-12)


def test_mechanical_segments_follow_the_stacked_layout():
    """trace._segments: per run and DOF, the positions of the fit rows in the row-major
    stacked target, -1 at a row inside the span left out of the fit."""
    from types import SimpleNamespace

    from sim.calibrate.trace import _segments

    a = SimpleNamespace(rows=np.array([0, 1, 1, 0, 1, 0], bool), force=np.zeros((6, 2)))
    b = SimpleNamespace(rows=np.ones(2, bool), force=np.zeros((2, 2)))
    segs = [s.tolist() for s in _segments([a, b])]
    assert segs == [[0, 2, -1, 4], [1, 3, -1, 5], [6, 8], [7, 9]]


SLOW_RHO = 0.995  #: a slow part (a transducer's drift) beside white noise


def _white_plus_slow(rng, slow_var):
    w = rng.standard_normal(RUNS * T)
    e = rng.standard_normal((RUNS, T + 2000)) * math.sqrt(slow_var * (1 - SLOW_RHO**2))
    for i in range(1, e.shape[1]):
        e[:, i] += SLOW_RHO * e[:, i - 1]
    return w + e[:, 2000:].reshape(-1)


def _mixture_true_sd(X, slow_var):
    lag = np.abs(np.subtract.outer(np.arange(T), np.arange(T)))
    S = np.eye(T) + slow_var * SLOW_RHO**lag
    Ainv = np.linalg.inv(X.T @ X)
    Om = sum(X[k * T : (k + 1) * T].T @ S @ X[k * T : (k + 1) * T] for k in range(RUNS))
    return np.sqrt(np.diag(Ainv @ Om @ Ainv))


def test_a_slow_part_under_white_noise_is_covered():
    """White noise with a slow part of a fifth of its variance (AR(1), rho = 0.995): the
    residual's first lag is ~0.2, so the Bartlett bandwidth is a few samples and its
    interval covers the truth in about half the cases (0.52 measured, its standard
    deviation 0.37 of the true one); the spectral variance beside it (hac_sigma reports
    the larger) brings the coverage to 0.95 (0.99 of the true standard deviation)."""
    from sim.calibrate.hac import bartlett_bandwidth

    X = _design()
    truth = np.array([0.3, 1.7])
    true_sd = _mixture_true_sd(X, 0.2)[1]
    segs = blocks([T] * RUNS)
    hits, hits_bartlett, ratio = 0, 0, []
    for seed in range(200):
        y = X @ truth + _white_plus_slow(np.random.default_rng(seed), 0.2)
        theta, *_ = np.linalg.lstsq(X, y, rcond=None)
        r = y - X @ theta
        sd = hac_sigma(X, r, segs)[1]
        u = (X @ np.linalg.inv(X.T @ X))[:, 1] * r
        parts = [u[s] for s in segs]
        sb = math.sqrt(long_run_sum(parts, bartlett_bandwidth(parts, T)) * len(y) / (len(y) - 2))
        err = abs(theta[1] - truth[1])
        hits += err <= 1.96 * sd
        hits_bartlett += err <= 1.96 * sb
        ratio.append(sd / true_sd)
    assert hits_bartlett / 200 < 0.7, hits_bartlett
    assert 0.9 <= hits / 200 <= 0.99, hits
    assert 0.85 < float(np.mean(ratio)) < 1.15, np.mean(ratio)


def test_no_segments_is_the_white_variance():
    """Samples in no segment are each their own: the heteroskedasticity-robust (White)
    variance, with no spectral term to add."""
    rng = np.random.default_rng(11)
    X = _design()
    r = rng.standard_normal(len(X))
    C = X @ np.linalg.inv(X.T @ X)
    want = np.sqrt(np.sum((C * r[:, None]) ** 2, axis=0) * len(X) / (len(X) - 2))
    assert np.allclose(hac_sigma(X, r, []), want, rtol=1e-12)
