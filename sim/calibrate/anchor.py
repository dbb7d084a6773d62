"""The acceleration's timing against the displacement: an absolute anchor for the
mechanical path's sensor timing.

The force balance compares the recorded force with the force the model needs for the
recorded motion, so it sees a skew between the force and the acceleration, not which of
the two is off: a pressure recorded one sample early and an accelerometer one sample late
leave the same residual. Kinematics settles it, whatever the table's dynamics (friction
as large as inertia included): the acceleration is the second derivative of the
displacement. The recorded displacement, put through the acceleration's declared chain
(its conditioner and delay, :meth:`sim.calibrate.residuals.MechRun.filt`, as every other
term of the balance), and the recorded acceleration have, where both are well above their
noise, the transfer function -(2 pi f)^2 exp(-i 2 pi f tau): ``tau`` is how late the
acceleration is beyond its declared chain, against the displacement sensor's clock.

It is read from the cross-spectrum (Welch segments, each detrended: a displacement's
offset and drift and the quantised LVDT's steps stay out of the band), so the
displacement is never differentiated sample by sample; its phase is fitted by a line
through the origin over the bins whose coherence says both signals hold the motion
(weights from the phase variance (1 - g^2) / (2 n g^2) of n segments at coherence g^2:
J. S. Bendat and A. G. Piersol, "Random Data: Analysis and Measurement Procedures", 4th
ed. 2010, ch. 9). A causal conditioner left out of the chain shows as a positive slope;
nothing here filters acausally.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Welch segment length, s (assumed: 1.25 s, 256 samples at 204.8 Hz: 0.8 Hz bins, about
#: 14 segments on a 18 s record; the phase of a delay of a few ms is linear in any bin)
SEGMENT_S = 1.25
#: Welch segments a record's coherence is read over, at least (assumed: 8, shorter
#: segments where the record is shorter than 8 of :data:`SEGMENT_S`). Of n independent
#: segments a bin of noise alone reaches a coherence of 0.9 with probability 0.1^(n - 1):
#: 1e-7 at 8, 0.1 at 2, where a 2.5 s CGS record in 1.25 s segments had "coherent" bins
#: up to 400 Hz, in the sensors' noise, and read its displacement 0.17 +/- 0.08 ms off
#: the acceleration (in 0.31 s segments: -0.01 +/- 0.08 ms, 12.8-32 Hz)
MIN_SEGMENTS = 8
#: the coherence a bin needs (assumed: 0.9, both signals 10 dB over what they do not
#: share: noise, the displacement's quantisation, the lead-in's nothing)
MIN_COHERENCE = 0.9
#: the band's top as a fraction of the sample rate (assumed: 0.4, below the recorder's
#: anti-alias roll-off, where the record's own samples still hold the signal)
TOP_FRACTION = 0.4
#: bins a line needs before its slope counts (assumed: 5)
MIN_BINS = 5
Z95 = 1.96
#: standard deviations a line's phase at zero frequency may sit off the origin for the
#: line to be a delay's (assumed: 3; a pure delay leaves it off by chance 0.3 % of the
#: time). Measured on NEES-UCSD records: a velocity 2 samples late, +0.6; the LHPOST DAQ's
#: complementary velocity (the displacement's derivative below 2 Hz, the 100 Hz
#: conditioned acceleration's integral above) against its displacement, -1 278
DELAY_Z = 3.0


@dataclass(frozen=True)
class Anchor:
    """How late the acceleration is beyond ``state``'s chain, against the displacement:
    ``delay_s`` +/- ``sigma_s`` (one standard deviation), from ``n_bins`` bins between
    ``band_hz``; ``delay_s`` is NaN when no bin is coherent enough."""

    delay_s: float
    sigma_s: float
    n_bins: int
    band_hz: tuple
    #: the phase at zero frequency of a free line through the same bins (rad) and its
    #: standard deviation: a delay's phase passes through the origin, a filter's bends
    #: (:attr:`a_delay`)
    offset_rad: float = 0.0
    offset_sigma_rad: float = math.inf

    @property
    def a_delay(self) -> bool:
        """The phase is a line through the origin, as a delay's: a filter's bends, and a
        free line through its bins meets zero frequency off the origin (:data:`DELAY_Z`)."""
        return not abs(self.offset_rad) > DELAY_Z * self.offset_sigma_rad

    @property
    def significant(self) -> bool:
        """The 95 % interval leaves out 0 (the acceleration is not where its chain says)."""
        return math.isfinite(self.delay_s) and abs(self.delay_s) > Z95 * self.sigma_s

    def text(self) -> str:
        if not math.isfinite(self.delay_s):
            return "no band where the displacement and the acceleration are both above their noise"
        lo, hi = self.band_hz
        return (
            f"{1e3 * self.delay_s:+.3f} +/- {1e3 * Z95 * self.sigma_s:.3f} ms "
            f"({self.n_bins} bins, {lo:.1f}-{hi:.1f} Hz)"
        )


def spectral_span(mr) -> slice | None:
    """The samples from a mechanical run's first fit row to its last (the test: a quiet
    lead-in holds nothing coherent), whole, for a spectrum; None under 16 fit rows."""
    rows = np.flatnonzero(mr.rows)
    return slice(rows[0], rows[-1] + 1) if len(rows) >= 16 else None


def phase_bins(mr, j: int) -> tuple:
    """``(omega, phase, variance)`` of DOF ``j`` of a mechanical run: the coherent bins of
    the recorded acceleration against the displacement through the run's chain (phase of
    the transfer function over -(2 pi f)^2, which is -omega tau for a delay tau)."""

    fs = 1.0 / mr.dt
    span = spectral_span(mr)
    if span is None:
        return (np.zeros(0),) * 3
    f, Pua, _Puu, var = _coherent_bins(mr.filt(mr.u)[span, j], mr.a[span, j], fs, TOP_FRACTION * fs)
    return 2 * np.pi * f, np.angle(-Pua), var


def _coherent_bins(x, a, fs: float, top_hz: float) -> tuple:
    """``(f, Pxa, Pxx, var)`` of the bins up to ``top_hz`` where ``x`` and ``a`` are
    coherent (:data:`MIN_COHERENCE`): Welch segments of :data:`SEGMENT_S`, detrended; the
    variance (1 - g^2) / (2 n g^2) of the phase (and of the log-magnitude) of n segments."""
    import scipy.signal as sig

    nper = min(len(x), max(32, min(int(round(SEGMENT_S * fs)), len(x) // MIN_SEGMENTS)))
    f, Pxa = sig.csd(x, a, fs=fs, nperseg=nper, detrend="linear")
    _, Pxx = sig.welch(x, fs=fs, nperseg=nper, detrend="linear")
    _, Paa = sig.welch(a, fs=fs, nperseg=nper, detrend="linear")
    den = Pxx * Paa
    coh = np.divide(np.abs(Pxa) ** 2, den, out=np.zeros_like(Pxx), where=den > 0)
    n_seg = max(1.0, len(x) / nper)  # 50 % overlapped segments count as this many independent ones
    keep = (f > 0) & (f <= top_hz) & (coh >= MIN_COHERENCE)
    g2 = np.clip(coh[keep], MIN_COHERENCE, 1.0 - 1e-9)
    return f[keep], Pxa[keep], Pxx[keep], (1.0 - g2) / (2.0 * n_seg * g2)


def velocity_bins(mr, j: int) -> tuple:
    """``(omega, phase, variance)`` of DOF ``j`` of a mechanical run: the coherent bins of
    the recorded velocity against the recorded displacement (phase of their transfer
    function over i omega, -omega tau for a velocity tau late; a velocity the import made
    by a central difference has none)."""
    fs = 1.0 / mr.dt
    span = spectral_span(mr)
    if span is None:
        return (np.zeros(0),) * 3
    f, Puv, _Puu, var = _coherent_bins(mr.u[span, j], mr.v[span, j], fs, TOP_FRACTION * fs)
    return 2 * np.pi * f, np.angle(-1j * Puv), var


def measure(mruns, bins_of=None) -> Anchor:
    """The acceleration's delay beyond the runs' chain (``bins_of``: :func:`phase_bins`; or
    the velocity's, :func:`velocity_bins`), pooled over runs and DOFs: the
    weighted least-squares slope of phase = -omega tau, its standard deviation from the
    weights, scaled up by the scatter about the line when that is larger (a conditioner of
    another shape bends the phase: the line then fits it less well and says so)."""
    bins_of = bins_of or phase_bins
    bins = [bins_of(mr, j) for mr in mruns for j in range(mr.u.shape[1])]
    w = np.concatenate([b[0] for b in bins]) if bins else np.zeros(0)
    if len(w) < MIN_BINS:
        return Anchor(math.nan, math.inf, len(w), (0.0, 0.0))
    wt = 1.0 / np.concatenate([b[2] for b in bins])
    ph = unwrapped(w, np.concatenate([b[1] for b in bins]), wt)
    sw2 = float(np.sum(wt * w**2))
    tau = -float(np.sum(wt * w * ph)) / sw2
    chi2 = float(np.sum(wt * (ph + w * tau) ** 2)) / max(len(w) - 1, 1)
    sigma = math.sqrt(max(chi2, 1.0) / sw2)
    f = w / (2 * np.pi)
    return Anchor(tau, sigma, len(w), (float(f.min()), float(f.max())), *_offset(w, ph, wt))


#: the largest delay the anchor looks for, s (assumed: as the timing candidates' bound,
#: :data:`sim.calibrate.timing.MAX_DELAY_S`)
MAX_ANCHOR_DELAY_S = 0.05


def unwrapped(w: np.ndarray, ph: np.ndarray, wt: np.ndarray) -> np.ndarray:
    """The bins' phases ``ph`` (wrapped to +/-pi) about the delay whose phasors line up
    best: ``tau0`` maximising the weighted sum of ``exp(i (ph + w tau))`` over a grid
    fine enough for the top bin (its phase moves pi / 8 a step) within
    :data:`MAX_ANCHOR_DELAY_S`; each phase is then ``-w tau0`` plus its own wrapped
    remainder. Where no bin wraps this is ``ph`` itself. A line fitted to wrapped phases
    goes wrong once the top bin's phase passes pi: the worked example's accelerometer 3
    samples late beyond its 50 Hz conditioner (14.6 ms, 1.2 turns at 82 Hz) read -4.5 ms,
    and the force took the skew."""
    step = np.pi / 8 / float(np.max(w))
    taus = np.arange(-MAX_ANCHOR_DELAY_S, MAX_ANCHOR_DELAY_S + step, step)
    power = [abs(np.sum(wt * np.exp(1j * (ph + w * tau)))) for tau in taus]
    tau0 = float(taus[int(np.argmax(power))])
    return np.angle(np.exp(1j * (ph + w * tau0))) - w * tau0


def _offset(w: np.ndarray, ph: np.ndarray, wt: np.ndarray) -> tuple[float, float]:
    """``(c, sigma_c)``: the intercept of the weighted line phase = c - omega tau through
    the bins and its standard deviation (scaled up by the scatter about the line, as the
    slope's)."""
    X = np.column_stack([np.ones_like(w), -w])
    A = X.T @ (wt[:, None] * X)
    if len(w) < 3 or np.linalg.cond(A) > 1e12:
        return 0.0, math.inf
    coef = np.linalg.solve(A, X.T @ (wt * ph))
    chi2 = float(np.sum(wt * (ph - X @ coef) ** 2)) / (len(w) - 2)
    return float(coef[0]), math.sqrt(max(chi2, 1.0) * np.linalg.inv(A)[0, 0])


def corroborates(before: Anchor, after: Anchor, scan_s: float = 0.0) -> tuple[bool, str]:
    """Whether a timing candidate of the acceleration is what the displacement says: the
    acceleration measurably off its declared chain (``before``: at the declared timing,
    its interval leaving out 0), and with the candidate (``after``) on it, up to the
    displacement's own skew (``scan_s``: a multiplexed recorder's scan, the displacement
    may be that far off itself) or the reading's interval, its phase no less a delay's
    line than before. Nearer is not enough: on the worked example's records, the
    accelerometer a sample late and the pressure a sample early, a 26.7 Hz conditioner in
    place of the declared 50 Hz took both skews (the balance's) and left the acceleration
    3.9 ms the other side of the displacement; a sample early, an 81 Hz one in place of
    the declared 50 Hz left it 0.65 ms off with its phase bent (a line through it met 0 Hz
    at 0.26 +/- 0.03 rad), where a delay left it on the line. ``(ok, reason when not)``."""
    if not math.isfinite(before.delay_s):
        return False, f"the displacement cannot time the acceleration: {before.text()}"
    if not before.significant:
        return False, f"the displacement puts the acceleration on its declared chain ({before.text()})"
    off = f"the displacement puts the acceleration {before.text()} off its declared chain; "
    if not abs(after.delay_s) < abs(before.delay_s):
        return False, off + f"with this it is {1e3 * after.delay_s:+.3f} ms off: the skew is on another channel"
    if abs(after.delay_s) > max(scan_s, Z95 * after.sigma_s):
        return False, off + f"with this it is {1e3 * after.delay_s:+.3f} ms off the other way: not this sensor's alone"
    if before.a_delay and not after.a_delay:
        return False, off + (
            f"with this its phase bends (a line through it meets 0 Hz at {after.offset_rad:+.3f} +/- "
            f"{Z95 * after.offset_sigma_rad:.3f} rad): not its shape"
        )
    return True, ""


#: the band where an accelerometer's gain is read against the velocity (assumed: up to
#: 20 Hz, where a declared conditioner of 100 Hz and an anti-alias filter change the
#: magnitude by under 1e-5)
GAIN_TOP_HZ = 20.0


def kinematic_gain(prs, columns) -> tuple[float, float]:
    """The recorded acceleration's gain against the recorded velocity (the displacement's
    second difference where the run has no velocity): ``(gain, sigma)`` from the coherent
    bins up to :data:`GAIN_TOP_HZ` of ``columns`` (DOF indices) of the replay/closed-loop
    runs ``prs``, pooled (weights from the log-magnitude's variance, as the phase's);
    ``(nan, inf)`` without such bins (:func:`_gain_bins`). A sensor's gain is read
    against another sensor of the same motion, as its timing is: the model's own
    amplitude error is not in it."""
    from sim.calibrate.conditioning import path_velocity_derived

    logs, wts = [], []
    for pr in prs:
        rec = pr.recorded
        if "table_acceleration" not in rec or not {"table_velocity", "table_displacement"} & set(rec):
            continue
        central = path_velocity_derived(pr)
        for j in columns:
            u, v = (rec[c][pr.rows][:, j] if c in rec else None for c in ("table_displacement", "table_velocity"))
            f, mag, var = _gain_bins(u, v, rec["table_acceleration"][pr.rows][:, j], 1.0 / pr.dt, central)
            logs.append(np.log(mag))
            wts.append(1.0 / var)
    return _pooled_gain(logs, wts)


def balance_acceleration_gain(mruns) -> tuple[float, float]:
    """:func:`kinematic_gain` on mechanical runs, over each run's excited DOFs. On the
    mechanical path a gain of the load cells and one of the accelerometers both leave the
    force balance off by a scale; this reads which sensor is off."""
    logs, wts = [], []
    for mr in mruns:
        span = spectral_span(mr)
        for j in range(mr.a.shape[1] if span is not None else 0):
            if mr.excited is None or mr.excited[j]:
                u, v, a = mr.u[span, j], mr.v[span, j], mr.a[span, j]
                f, mag, var = _gain_bins(u, v, a, 1.0 / mr.dt, bool(mr.extra.get("velocity_derived")))
                logs.append(np.log(mag))
                wts.append(1.0 / var)
    return _pooled_gain(logs, wts)


def _gain_bins(u, v, a, fs: float, central: bool) -> tuple:
    """``(f, |H|, var(log |H|))`` of the acceleration ``a`` against the velocity ``v``
    (None: against the displacement ``u``), over the bins up to :data:`GAIN_TOP_HZ` where
    the reference (``u``, else ``v``) is coherent with both ``a`` and ``d``, the
    velocity's central difference (the displacement's second): ``H = P_ra / P_rd`` times
    ``(sin(w T) / (w T))`` for each central difference in ``d`` (``central``: the velocity
    is itself an import's central difference). ``a`` and ``d`` share their spectrum's
    slope, so ``H`` is flat and the window's leakage of the displacement's strong low
    frequencies into the bins above cannot bend it; nor is either sensor's noise in the
    reference. Read as ``P_va / P_vv`` the NEES-UCSD real-record suite's accelerometers
    came out 1.25 % low, as ``P_ua / P_uv`` over 2 pi f their 3-5 Hz bins 4 % low."""
    ref = u if u is not None else v
    d, steps = (np.gradient(v) * fs, 1 + central) if v is not None else (np.gradient(np.gradient(u)) * fs * fs, 2)
    fa, Pra, _, var_a = _coherent_bins(ref, a, fs, GAIN_TOP_HZ)
    fd, Prd, _, var_d = _coherent_bins(ref, d, fs, GAIN_TOP_HZ)
    f, ia, idd = np.intersect1d(fa, fd, return_indices=True)
    wT = 2 * np.pi * f / fs
    return f, np.abs(Pra[ia]) / np.abs(Prd[idd]) * (np.sin(wT) / wT) ** steps, var_a[ia] + var_d[idd]


def _pooled_gain(logs: list, wts: list) -> tuple[float, float]:
    """The weighted mean of the bins' log-magnitudes as a gain and its standard deviation
    (scaled up by their scatter when that is larger); ``(nan, inf)`` with too few bins."""
    if not logs or sum(len(x) for x in logs) < MIN_BINS:
        return math.nan, math.inf
    lg, wt = np.concatenate(logs), np.concatenate(wts)
    mean = float(np.sum(wt * lg) / np.sum(wt))
    chi2 = float(np.sum(wt * (lg - mean) ** 2)) / max(len(lg) - 1, 1)
    sigma = math.sqrt(max(chi2, 1.0) / float(np.sum(wt)))
    return math.exp(mean), math.exp(mean) * sigma


__all__ = [
    "Anchor",
    "balance_acceleration_gain",
    "corroborates",
    "kinematic_gain",
    "measure",
    "phase_bins",
    "spectral_span",
    "velocity_bins",
]
