"""System-identification tools for the characterisation programme (``sim.identify.characterize``).

What scipy.signal gives (Welch cross/auto spectra) is used as is; this module adds the
pieces a shaking-table identification needs on top:

* :func:`frf` - frequency-response function from an input and an output record by
  Welch/Bartlett averaging (chosen window, segment count or length, overlap), with the
  ordinary coherence and the H1 (``Gxy/Gxx``), H2 (``Gyy/Gyx``) estimators, or the
  *instrumental* estimator ``Gry/Grx`` that uses an external reference ``r`` (the test's
  command signal). In a closed loop the plant input is correlated with anything that
  disturbs the plant output (friction, nonlinearity), which biases H1 near a resonance
  the controller suppresses; ``Gry/Grx`` is unbiased for disturbances uncorrelated with
  ``r`` (the joint input-output method).
* :func:`peak_pick` - the resonance peak of |H| in a band (parabolic interpolation on
  the bins around the maximum) and its half-power (-3 dB) damping ratio
  ``zeta = (f2 - f1) / (2 f_n)`` with the crossings linearly interpolated.
* :func:`band_average` - mean of |H| (or Re H) over a band: effective mass from an
  acceleration -> force FRF.
* :func:`friction_fit` / :func:`hysteresis_loop` - Coulomb friction from a slow
  force-displacement test: least squares of ``F = m a + k d + c v + F0 + Fc sign(v)``,
  and the loop's half-width against displacement.
* :func:`fit_first_order` / :func:`fit_second_order` - servovalve models
  ``K/(tau s + 1)`` and ``K w^2/(s^2 + 2 zeta w s + w^2)`` fitted to a complex FRF over a
  band (complex least squares on ``H_model/H - 1``, so magnitude and phase weigh alike).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.signal


@dataclass
class FRF:
    """A frequency-response estimate.

    Attributes:
        f: frequencies, Hz (N,).
        H: complex FRF output/input (N,).
        coherence: ordinary coherence of input and output (N,), in [0, 1].
        estimator: "H1", "H2" or "instrumental".
        n_segments: number of averaged segments; nperseg: samples per segment.
    """

    f: np.ndarray
    H: np.ndarray
    coherence: np.ndarray
    estimator: str
    n_segments: int
    nperseg: int

    def band(self, f_lo: float, f_hi: float) -> np.ndarray:
        """Boolean mask of the bins in [f_lo, f_hi]."""
        return (self.f >= f_lo) & (self.f <= f_hi)


def _segments(n: int, nperseg: int | None, n_segments: int | None, overlap: float) -> int:
    if nperseg is None:
        k = 8 if n_segments is None else int(n_segments)
        if k < 1:
            raise ValueError("n_segments must be >= 1")
        # k segments with the given fractional overlap cover n samples
        nperseg = int(n / (1 + (k - 1) * (1 - overlap)))
    if nperseg < 8 or nperseg > n:
        raise ValueError(f"segment length {nperseg} does not fit a record of {n} samples")
    return int(nperseg)


def frf(
    x,
    y,
    fs: float,
    *,
    nperseg: int | None = None,
    n_segments: int | None = None,
    window="hann",
    overlap: float = 0.5,
    estimator: str = "H1",
    reference=None,
    detrend="constant",
) -> FRF:
    """FRF of output ``y`` to input ``x`` (same length, sampled at ``fs``).

    Give either ``nperseg`` (samples per segment) or ``n_segments`` (default 8); the
    records are split into segments with ``overlap`` (0 = Bartlett averaging), each
    windowed (any scipy window spec, e.g. "hann" or "blackmanharris") and detrended.
    ``estimator``: "H1" = Gxy/Gxx (noise on the output), "H2" = Gyy/Gyx (noise on the
    input); with ``reference`` (the command record) the instrumental estimate Gry/Grx.
    """
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError("x and y must be 1-D records of the same length")
    nps = _segments(len(x), nperseg, n_segments, overlap)
    nov = int(round(overlap * nps))
    kw = dict(fs=fs, window=window, nperseg=nps, noverlap=nov, detrend=detrend)
    f, gxx = scipy.signal.welch(x, **kw)
    _, gyy = scipy.signal.welch(y, **kw)
    _, gxy = scipy.signal.csd(x, y, **kw)  # conj(X) Y
    with np.errstate(divide="ignore", invalid="ignore"):
        coh = np.abs(gxy) ** 2 / (gxx * gyy)
        if reference is not None:
            r = np.asarray(reference, float)
            _, grx = scipy.signal.csd(r, x, **kw)
            _, gry = scipy.signal.csd(r, y, **kw)
            H = gry / grx
            est = "instrumental"
        elif estimator.upper() == "H1":
            H = gxy / gxx
            est = "H1"
        elif estimator.upper() == "H2":
            H = gyy / np.conj(gxy)
            est = "H2"
        else:
            raise ValueError(f"estimator must be H1 or H2 (got {estimator!r})")
    step = nps - nov
    nseg = 1 + (len(x) - nps) // step
    return FRF(f=f, H=H, coherence=np.nan_to_num(coh), estimator=est, n_segments=int(nseg), nperseg=nps)


@dataclass
class Peak:
    """A resonance peak: frequency (Hz), |H| at the peak, half-power damping ratio and
    the -3 dB crossings (NaN where the curve does not fall to -3 dB inside the band)."""

    f_hz: float
    magnitude: float
    zeta: float
    f1_hz: float
    f2_hz: float


def peak_pick(f, H, band: tuple[float, float]) -> Peak:
    """Peak of |H| inside ``band`` and its half-power damping ratio."""
    f = np.asarray(f, float)
    mag = np.abs(np.asarray(H))
    sel = np.flatnonzero((f >= band[0]) & (f <= band[1]) & np.isfinite(mag))
    if sel.size < 3:
        raise ValueError(f"band {band} holds fewer than 3 frequency bins")
    i = sel[np.argmax(mag[sel])]
    fp, mp = f[i], mag[i]
    if 0 < i < len(f) - 1:  # parabola through the three bins (in dB: exact for a Gaussian top)
        y0, y1, y2 = np.log(mag[i - 1 : i + 2])
        den = y0 - 2 * y1 + y2
        if den < 0:
            p = 0.5 * (y0 - y2) / den
            df = f[i + 1] - f[i]
            fp = f[i] + p * df
            mp = float(np.exp(y1 - 0.25 * (y0 - y2) * p))
    half = mp / np.sqrt(2.0)
    f1 = f2 = np.nan
    j = i
    while j > sel[0] and mag[j] > half:
        j -= 1
    if mag[j] <= half < mag[j + 1]:
        f1 = f[j] + (half - mag[j]) / (mag[j + 1] - mag[j]) * (f[j + 1] - f[j])
    j = i
    while j < sel[-1] and mag[j] > half:
        j += 1
    if mag[j] <= half < mag[j - 1]:
        f2 = f[j - 1] + (mag[j - 1] - half) / (mag[j - 1] - mag[j]) * (f[j] - f[j - 1])
    zeta = (f2 - f1) / (2 * fp) if np.isfinite(f1) and np.isfinite(f2) else np.nan
    return Peak(f_hz=float(fp), magnitude=float(mp), zeta=float(zeta), f1_hz=float(f1), f2_hz=float(f2))


def band_average(f, H, band: tuple[float, float], *, part: str = "abs", weights=None) -> float:
    """Mean of |H| ("abs") or Re H ("real") over the bins in ``band`` (optionally weighted,
    e.g. by coherence)."""
    f = np.asarray(f, float)
    H = np.asarray(H)
    sel = (f >= band[0]) & (f <= band[1]) & np.isfinite(H)
    if not sel.any():
        raise ValueError(f"band {band} holds no frequency bins")
    v = np.abs(H[sel]) if part == "abs" else H[sel].real
    w = np.ones(sel.sum()) if weights is None else np.asarray(weights, float)[sel]
    return float(np.sum(w * v) / np.sum(w))


# ------------------------------------------------------------------ friction
@dataclass
class FrictionFit:
    """Least-squares split of a slow-test force: F = m a + k d + c v + F0 + Fc sign(v)."""

    coulomb: float
    mass: float
    stiffness: float
    viscous: float
    offset: float
    rms_residual: float


def friction_fit(d, v, a, force, *, v_min_fraction: float = 0.05) -> FrictionFit:
    """Coulomb friction level of a force record (samples with |v| below
    ``v_min_fraction`` of the peak velocity are left out: there the friction force is
    between its two levels)."""
    d, v, a, F = (np.asarray(z, float) for z in (d, v, a, force))
    vmax = np.nanmax(np.abs(v))
    sel = np.isfinite(F) & (np.abs(v) > v_min_fraction * vmax)
    A = np.stack([a[sel], d[sel], v[sel], np.ones(sel.sum()), np.sign(v[sel])], axis=1)
    sc = np.abs(A).max(axis=0)
    sc[sc == 0] = 1.0
    x, *_ = np.linalg.lstsq(A / sc, F[sel], rcond=None)
    x = x / sc
    res = F[sel] - A @ x
    return FrictionFit(
        coulomb=float(x[4]),
        mass=float(x[0]),
        stiffness=float(x[1]),
        viscous=float(x[2]),
        offset=float(x[3]),
        rms_residual=float(np.sqrt(np.mean(res**2))),
    )


def hysteresis_loop(d, v, force, *, n_bins: int = 20, v_min_fraction: float = 0.05) -> dict:
    """Upper (v > 0) and lower (v < 0) branches of a force-displacement loop, binned on
    displacement; ``half_width`` = (upper - lower) / 2 is the friction level per bin."""
    d, v, F = (np.asarray(z, float) for z in (d, v, force))
    vmax = np.nanmax(np.abs(v))
    lo, hi = np.nanpercentile(d, 1), np.nanpercentile(d, 99)
    edges = np.linspace(lo, hi, n_bins + 1)
    mid = 0.5 * (edges[1:] + edges[:-1])
    up = np.full(n_bins, np.nan)
    dn = np.full(n_bins, np.nan)
    idx = np.digitize(d, edges) - 1
    for k in range(n_bins):
        inb = idx == k
        pu = inb & (v > v_min_fraction * vmax)
        pdn = inb & (v < -v_min_fraction * vmax)
        if pu.any():
            up[k] = np.mean(F[pu])
        if pdn.any():
            dn[k] = np.mean(F[pdn])
    return {"d": mid, "upper": up, "lower": dn, "half_width": 0.5 * (up - dn)}


# ------------------------------------------------------------------ servovalve fits
def zero_order_hold(f, fs: float) -> np.ndarray:
    """FRF of a zero-order hold at rate ``fs`` seen from its input samples:
    ``sinc(f/fs) exp(-j pi f/fs)`` (a half-sample delay and the sinc droop)."""
    x = np.asarray(f, float) / fs
    return np.sinc(x) * np.exp(-1j * np.pi * x)


def first_order(f, K: float, tau: float) -> np.ndarray:
    s = 2j * np.pi * np.asarray(f, float)
    return K / (tau * s + 1)


def second_order(f, K: float, wn_hz: float, zeta: float) -> np.ndarray:
    s = 2j * np.pi * np.asarray(f, float)
    w = 2 * np.pi * wn_hz
    return K * w * w / (s * s + 2 * zeta * w * s + w * w)


def _fit(model, f, H, band, x0, fix_gain, magnitude=False):
    f = np.asarray(f, float)
    H = np.asarray(H)
    sel = (f >= band[0]) & (f <= band[1]) & np.isfinite(H) & (np.abs(H) > 0)
    fs_, Hs = f[sel], H[sel]
    if sel.sum() < len(x0) + 1:
        raise ValueError(f"band {band} holds too few bins for the fit")

    def res(p):
        pp = (1.0, *p) if fix_gain else p
        if magnitude:  # linear magnitude only
            return np.abs(model(fs_, *pp)) - np.abs(Hs)
        r = model(fs_, *pp) / Hs - 1.0
        return np.concatenate([r.real, r.imag])

    sol = scipy.optimize.least_squares(res, x0, method="lm")
    return sol.x, float(np.sqrt(np.mean(sol.fun**2)))


def fit_first_order(f, H, band: tuple[float, float] = (0.5, 20.0), *, fix_gain: bool = False) -> dict:
    """K/(tau s + 1) fitted to H over ``band``: {"K", "tau_s", "rms_rel_error"}."""
    x0 = [0.005] if fix_gain else [1.0, 0.005]
    p, e = _fit(first_order, f, H, band, x0, fix_gain)
    K, tau = (1.0, p[0]) if fix_gain else p
    return {"K": float(K), "tau_s": float(abs(tau)), "rms_rel_error": e}


def fit_first_order_magnitude(f, H, band: tuple[float, float] = (0.5, 125.0)) -> dict:
    """1/(tau s + 1) fitted to |H| alone over ``band`` (linear magnitude, gain 1):
    {"tau_s", "rms_error"}. Another reading of a first-order valve fit, for comparison
    with :func:`fit_first_order` (complex, over the band where the phase holds)."""
    p, e = _fit(first_order, f, H, band, [0.005], True, magnitude=True)
    return {"tau_s": float(abs(p[0])), "rms_error": e}


def fit_second_order(f, H, band: tuple[float, float] = (0.5, 50.0), *, fix_gain: bool = False) -> dict:
    """K w^2/(s^2 + 2 zeta w s + w^2) fitted over ``band``: {"K", "wn_hz", "zeta", ...}."""
    x0 = [40.0, 0.7] if fix_gain else [1.0, 40.0, 0.7]
    p, e = _fit(second_order, f, H, band, x0, fix_gain)
    K, wn, z = (1.0, *p) if fix_gain else p
    return {"K": float(K), "wn_hz": float(abs(wn)), "zeta": float(abs(z)), "rms_rel_error": e}


__all__ = [
    "FRF",
    "Peak",
    "FrictionFit",
    "frf",
    "peak_pick",
    "band_average",
    "friction_fit",
    "hysteresis_loop",
    "first_order",
    "second_order",
    "zero_order_hold",
    "fit_first_order",
    "fit_first_order_magnitude",
    "fit_second_order",
]
