"""Standard deviations of a least-squares estimate whose residual is correlated in time.

Both fitting paths of ``shaketable calibrate`` minimise ``|r(theta)|^2`` over a residual
stacked from several *segments*: one time series per compared column of each run (the
replay path) or per DOF of each run (the mechanical path). Near the solution the
estimate is ``theta - theta_true ~ A^-1 J^T r`` with ``A = J^T J`` (``J``: the Jacobian
of the stacked residual, the design matrix of a linear fit), so

    Cov(theta) = A^-1 Omega A^-1,   Omega = Cov(J^T r) = sum_s sum_t sum_u J_st E[r_st r_su] J_su^T.

The textbook ``s^2 A^-1`` assumes ``E[r_t r_u] = s^2 delta_tu`` (independent samples of
one variance). The residual of a shaking-table run is not: the recorder's anti-alias
filter and unmodelled dynamics colour it, neighbouring samples share most of their
error, and the interval comes out too narrow by about the square root of the samples
per correlation time. Samples of different segments (different runs, or columns with
their own noise) are taken as uncorrelated.

Per parameter ``a`` the variance is the long-run variance of the scalar *score* series
``u_t = c_t r_t``, ``c = J A^-1 e_a`` (so that ``theta_a - theta_a,true ~ sum_t u_t``):
``Var(theta_a) = sum_s sum_{|l| < T} gamma_s(l)`` with ``gamma_s(l) = sum_t u_st u_s,t+l``.
That sum is estimated as Newey and West (1987) do: the autocovariances weighted by the
Bartlett window ``1 - |l| / (L + 1)`` up to lag ``L`` (the estimate is never negative).
With the series zero-padded the weighted sum is exact as the sum of squares of the
moving sums of ``L + 1`` samples over ``L + 1``: ``sum_t (sum_{k=t}^{t+L} u_k)^2 / (L+1)
= sum_{|l| <= L} (L + 1 - |l|) gamma(l) / (L + 1)``, ``O(T)`` for any ``L``.

The bandwidth ``L`` follows the residual's own correlation: Andrews' (1991, Econometrica
59, 817, Eq. 6.4) plug-in for the Bartlett kernel with an AR(1) fit ``rho`` of the score
series (pooled over segments), ``L = 1.1447 (alpha T)^(1/3)``, ``alpha = 4 rho^2 /
((1 - rho)^2 (1 + rho)^2)``, ``T`` the segment length. A white score gives ``L ~ 0``
and the heteroskedasticity-robust (White) variance, which for a residual of one variance
is ``s^2 A^-1`` again. The Bartlett window underweights the long lags, so with a strongly
correlated residual the estimate stays a little low (an AR(1) residual of ``rho = 0.9``,
2000 samples: the 95 % interval covers the true value in ~92 % of the cases, the
textbook one in ~35 %: tests/calibrate/test_hac.py). The variance is scaled by
``n / (n - p)`` as ``s^2`` is.

The AR(1) plug-in reads the score's first lag only. A residual that is mostly white with a
small slow part beside it (an accelerometer's noise times the table's mass, with the
transducers' drift under it) gives a first lag near zero and a bandwidth of a few samples,
while the slow part, where the table's own motion has its power, still moves the estimate:
a Coulomb friction of 8 kN on five seeds of the same NEES-UCSD records measured through
``scenarios/sensors/real_record_1024hz.toml`` scattered by 113 N (standard deviation)
where the Bartlett estimate said 40-44 N. So each variance is also taken in the frequency
domain, for weights ``c`` fixed and a residual stationary within its segment:
``Var(sum_t c_t r_t) = integral |C(nu)|^2 S_r(nu) dnu`` (:func:`spectral_variance`, ``S_r``
by Welch's method over windows of a quarter of the segment), and the larger of the two is
reported (49-112 N on those seeds, the truth inside every 95 % interval): the
Bartlett sum stays for a residual whose size follows the regressor (heteroskedastic),
the spectral one for slow colour the first lag does not show.
"""

from __future__ import annotations

import math

import numpy as np


def bartlett_bandwidth(u_segments, length: int) -> int:
    """Andrews' AR(1) plug-in bandwidth of the Bartlett kernel for the scalar series
    ``u_segments`` (a list of 1-D arrays, correlation within each) of ``length`` samples."""
    num = sum(float(u[1:] @ u[:-1]) for u in u_segments if u.size > 1)
    den = sum(float(u[:-1] @ u[:-1]) for u in u_segments if u.size > 1)
    if den <= 0 or length < 2:
        return 0
    rho = max(-0.999, min(0.999, num / den))
    alpha = 4 * rho**2 / ((1 - rho) ** 2 * (1 + rho) ** 2)
    return int(min(length - 1, math.ceil(1.1447 * (alpha * length) ** (1 / 3))))


def long_run_sum(u_segments, L: int) -> float:
    """Bartlett-weighted sum of the autocovariances (lags up to ``L``) of each segment,
    summed over segments: ``sum_s sum_{|l|<=L} (1 - |l|/(L+1)) sum_t u_st u_s,t+l``."""
    tot = 0.0
    for u in u_segments:
        c = np.concatenate([[0.0], np.cumsum(np.concatenate([u, np.zeros(L)]))])
        m = c[L + 1 :] - c[: c.size - L - 1]  # moving sums of L+1 samples, zero-padded at both ends
        m = np.concatenate([c[1 : L + 1], m])
        tot += float(m @ m) / (L + 1)
    return tot


def hac_sigma(J: np.ndarray, r: np.ndarray, segments) -> np.ndarray:
    """Standard deviations of the least-squares estimate with Jacobian (or design matrix)
    ``J`` (n, p) and residual ``r`` (n,) at the solution, the residual correlated within
    each of ``segments``: a list of integer arrays of positions into ``r`` in time order,
    ``-1`` for a sample of the segment's time grid that is not in the fit (it counts
    as a zero in the lags). Samples in no segment are taken as uncorrelated with any
    other. ``inf`` for a parameter the fit does not determine. See the module docstring."""
    J = np.asarray(J, float)
    r = np.asarray(r, float)
    n, p = J.shape
    if p == 0:
        return np.zeros(0)
    try:
        Ainv = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        return np.full(p, math.inf)
    if not np.all(np.isfinite(Ainv)):
        return np.full(p, math.inf)
    C = J @ Ainv  # (n, p): theta_a - true ~ sum_t C[t, a] r_t
    U = C * r[:, None]
    covered = np.zeros(n, bool)
    segs = []
    for idx in segments:
        idx = np.asarray(idx, int)
        segs.append(idx)
        covered[idx[idx >= 0]] = True
    length = int(np.median([s.size for s in segs])) if segs else 1
    weights = [np.where(s[:, None] >= 0, C[np.maximum(s, 0)], 0.0) for s in segs]
    v_spec = spectral_variance(weights, r, segs) if segs else np.zeros(p)
    out = np.empty(p)
    for a in range(p):
        ua = U[:, a]
        parts = [np.where(s >= 0, ua[np.maximum(s, 0)], 0.0) for s in segs]
        L = bartlett_bandwidth(parts, length)
        v = max(long_run_sum(parts, L), v_spec[a]) + float(ua[~covered] @ ua[~covered])
        out[a] = math.sqrt(max(v, 0.0) * n / max(n - p, 1))
    return out


#: Welch windows of at most this share of a segment (7 or more of them, half overlapping):
#: an eighth smeared a slow part's peak (0.83 of the true standard deviation on the
#: closed-form case of tests/calibrate/test_hac.py), a quarter reads it (0.99)
WELCH_SHARE = 1 / 4


def residual_spectrum(r: np.ndarray):
    """``(nu, S)``: the two-sided power spectral density of one segment's residual in
    cycles per sample (``integral S dnu`` is its variance), Welch's method with Hann
    windows of the largest power of two within :data:`WELCH_SHARE` of the segment; None
    for a segment too short to tell (under 64 samples)."""
    import scipy.signal as sig

    if r.size < 64:
        return None
    nper = 1 << int(math.floor(math.log2(max(r.size * WELCH_SHARE, 32))))
    nu, S = sig.welch(r, fs=1.0, nperseg=nper, return_onesided=False, detrend=False, scaling="density")
    return np.fft.fftshift(nu), np.fft.fftshift(S)


def spectral_variance(weights, r: np.ndarray, segments) -> np.ndarray:
    """Per column ``a`` of the weights, ``sum over segments of integral |C_a(nu)|^2
    S_r(nu) dnu``: the variance of ``sum_t c_t r_t`` for fixed weights ``c`` and a residual
    stationary within each segment (:func:`residual_spectrum`; a segment too short to
    tell adds nothing). ``weights``: per segment, (length, p) in the segment's time order;
    ``segments``: the positions of ``r`` as :func:`hac_sigma` takes them."""
    tot = np.zeros(weights[0].shape[1] if weights else 0)
    for c, s in zip(weights, segments):
        spec = residual_spectrum(np.where(s >= 0, r[np.maximum(s, 0)], 0.0))
        if spec is None:
            continue
        nu, S = spec
        N = 1 << int(math.ceil(math.log2(2 * len(c))))  # zero-padded: no wrap-around
        P = np.abs(np.fft.rfft(c, N, axis=0)) ** 2 * np.interp(np.fft.rfftfreq(N), nu, S)[:, None]
        # c and r real: the negative frequencies mirror the positive ones but 0 and N/2
        tot += (2.0 * P.sum(axis=0) - P[0] - P[-1]) / N
    return tot


def naive_sigma(J: np.ndarray, r: np.ndarray) -> np.ndarray:
    """``sqrt(diag(s^2 (J^T J)^-1))``, ``s^2 = |r|^2 / (n - p)``: independent samples."""
    n, p = J.shape
    s2 = float(r @ r) / max(n - p, 1)
    try:
        return np.sqrt(np.maximum(np.diag(s2 * np.linalg.inv(J.T @ J)), 0.0))
    except np.linalg.LinAlgError:
        return np.full(p, math.inf)


def blocks(lengths) -> list:
    """Segments of a residual stacked as consecutive blocks of the given lengths."""
    out, k = [], 0
    for m in lengths:
        out.append(np.arange(k, k + int(m)))
        k += int(m)
    return out


__all__ = [
    "bartlett_bandwidth",
    "blocks",
    "hac_sigma",
    "long_run_sum",
    "naive_sigma",
    "residual_spectrum",
    "spectral_variance",
]
