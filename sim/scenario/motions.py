"""Table motions: reference displacement for one DOF, with velocity and acceleration.

Every generator returns a :class:`Motion`: sample times ``t`` (s, from 0 at
``sample_rate_hz``) and displacement ``d`` (m or rad), velocity ``v`` and acceleration
``a`` that are consistent with each other: analytic where the waveform has a closed
form (sine, tapered sine, rounded triangle, white noise through its spectrum), or from
the same exact integration (earthquake records, see :mod:`sim.scenario.records`). A Motion
unpacks as ``t, d, v, a = motion``.

Generators here:

* :func:`sine` - ``amplitude * sin(2 pi f t + phase)``.
* :func:`tapered_sine` - a sine under a cosine-tapered envelope (the CGS friction tests
  use a 0.05 Hz tapered sine); starts and ends at rest.
* :func:`triangle` - the NEES-UCSD triangular test (peak displacement D, peak
  velocity V) with parabolic rounding at the peaks, so acceleration is bounded.
* :func:`white_noise` - band-limited white-noise acceleration with a seed; the same
  seed gives the same signal bit for bit.

and the checks used on any motion: :func:`peaks`, :func:`check_limits`,
:func:`response_spectrum`.

Every problem a user can fix raises :class:`sim.errors.MotionError` (one line).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterator, Mapping, Sequence

import numpy as np
import scipy.linalg
import scipy.signal

from sim.errors import MotionError
from sim.validate import check_samples

G = 9.80665  # m/s^2, standard gravity (CODATA conventional value)

ROTATION_DOFS = ("rx", "ry", "rz")


@dataclass(frozen=True)
class Peaks:
    """Peak absolute values of a motion (NaN samples ignored).

    Attributes:
        displacement: max |d|, m (rad for rotations).
        velocity: max |v|, m/s (rad/s).
        acceleration: max |a|, m/s^2 (rad/s^2).
    """

    displacement: float
    velocity: float
    acceleration: float


@dataclass(frozen=True, eq=False)
class Motion:
    """A reference motion for one DOF.

    Attributes:
        t: sample times, shape (N,), s, uniform step 1 / sample_rate_hz from 0.
        d: displacement, shape (N,), m (rad for rotational DOFs).
        v: velocity, shape (N,), m/s (rad/s).
        a: acceleration, shape (N,), m/s^2 (rad/s^2).
        name: what the motion is (for messages and reports).
        info: how it was made (parameters, processing figures).
    """

    t: np.ndarray
    d: np.ndarray
    v: np.ndarray
    a: np.ndarray
    name: str = "motion"
    info: dict = field(default_factory=dict)

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.t, self.d, self.v, self.a))

    @property
    def sample_rate_hz(self) -> float:
        """1 / (t[1] - t[0]), Hz."""
        return 1.0 / float(self.t[1] - self.t[0])

    @property
    def dt(self) -> float:
        """Sample step, s."""
        return float(self.t[1] - self.t[0])

    @property
    def duration_s(self) -> float:
        """t[-1] - t[0], s."""
        return float(self.t[-1] - self.t[0])

    @property
    def peaks(self) -> Peaks:
        """Peak |d|, |v|, |a|."""
        return peaks(self.d, self.v, self.a)

    def scaled(self, factor: float) -> Motion:
        """The same motion with amplitude multiplied by ``factor`` (0.8 for 80 %)."""
        info = dict(self.info, amplitude_factor=self.info.get("amplitude_factor", 1.0) * factor)
        return Motion(self.t, self.d * factor, self.v * factor, self.a * factor, self.name, info)


def peaks(d: np.ndarray, v: np.ndarray, a: np.ndarray) -> Peaks:
    """Peak absolute displacement, velocity and acceleration (NaN ignored)."""

    def pk(x):
        x = np.asarray(x, dtype=float)
        return float(np.nanmax(np.abs(x))) if x.size and not np.all(np.isnan(x)) else 0.0

    return Peaks(pk(d), pk(v), pk(a))


# -- helpers -----------------------------------------------------------------------
def _positive(name: str, value, *, allow_zero: bool = False) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise MotionError(f"{name} {value!r} is not a number; give it in SI units") from None
    if not math.isfinite(x) or x < 0 or (x == 0 and not allow_zero):
        need = "zero or positive" if allow_zero else "positive"
        raise MotionError(f"{name} {value!r} must be {need}; give a {need} value in SI units")
    return x


def time_vector(duration_s: float, sample_rate_hz: float) -> np.ndarray:
    """Sample times 0, dt, ..., up to and including ``duration_s`` (rounded to a sample)."""
    duration_s = _positive("duration_s", duration_s)
    fs = _positive("sample_rate_hz", sample_rate_hz)
    n = check_samples(round(duration_s * fs) + 1, f"a motion of {duration_s:g} s at {fs:g} Hz", None, MotionError)
    return np.arange(n) / fs


# -- sines -------------------------------------------------------------------------
def sine(
    *,
    amplitude: float,
    frequency_hz: float,
    duration_s: float,
    sample_rate_hz: float,
    phase_rad: float = 0.0,
    name: str = "sine",
) -> Motion:
    """``d = amplitude sin(2 pi f t + phase)`` with analytic v and a.

    Peaks: D = amplitude, V = 2 pi f D, A = (2 pi f)^2 D. It starts at full speed
    (phase 0) or off zero: use :func:`tapered_sine` to start and end at rest.
    """
    amp = _positive("amplitude", amplitude, allow_zero=True)
    f = _positive("frequency_hz", frequency_hz)
    t = time_vector(duration_s, sample_rate_hz)
    w = 2 * np.pi * f
    ph = w * t + phase_rad
    return Motion(
        t,
        amp * np.sin(ph),
        amp * w * np.cos(ph),
        -amp * w * w * np.sin(ph),
        name,
        dict(kind="sine", amplitude=amp, frequency_hz=f, phase_rad=phase_rad),
    )


def _cosine_envelope(t: np.ndarray, ramp_s: float, total_s: float):
    """Envelope 0 -> 1 -> 0 with (1 - cos)/2 ramps, and its first two time derivatives."""
    w = np.ones_like(t)
    w1 = np.zeros_like(t)
    w2 = np.zeros_like(t)
    if ramp_s <= 0:
        return w, w1, w2
    k = np.pi / ramp_s
    for sel, s, sign in ((t < ramp_s, t, 1.0), (t > total_s - ramp_s, total_s - t, -1.0)):
        x = k * s[sel]
        w[sel] = 0.5 * (1 - np.cos(x))
        w1[sel] = sign * 0.5 * k * np.sin(x)  # d/dt of s is +1 (start) or -1 (end)
        w2[sel] = 0.5 * k * k * np.cos(x)
    return w, w1, w2


def tapered_sine(
    *,
    amplitude: float,
    frequency_hz: float,
    duration_s: float,
    sample_rate_hz: float,
    taper_cycles: float = 2.0,
    phase_rad: float = 0.0,
    name: str = "tapered sine",
) -> Motion:
    """A sine under an envelope that ramps 0 -> 1 over ``taper_cycles`` cycles at the start
    and 1 -> 0 at the end with a (1 - cos)/2 shape, so the motion starts and ends at rest.

    ``duration_s`` includes both ramps. v and a are analytic (product rule on envelope
    times sine). Peak displacement is ``amplitude`` once the plateau holds a peak.
    """
    amp = _positive("amplitude", amplitude, allow_zero=True)
    f = _positive("frequency_hz", frequency_hz)
    cycles = _positive("taper_cycles", taper_cycles, allow_zero=True)
    ramp = cycles / f
    t = time_vector(duration_s, sample_rate_hz)
    total = float(t[-1])
    if 2 * ramp > total:
        raise MotionError(
            f"tapered sine of {total:g} s is shorter than its two {ramp:g} s ramps "
            f"({cycles:g} cycles at {f:g} Hz); lengthen duration_s or reduce taper_cycles"
        )
    e, e1, e2 = _cosine_envelope(t, ramp, total)
    w = 2 * np.pi * f
    ph = w * t + phase_rad
    s, s1, s2 = np.sin(ph), w * np.cos(ph), -w * w * np.sin(ph)
    return Motion(
        t,
        amp * e * s,
        amp * (e1 * s + e * s1),
        amp * (e2 * s + 2 * e1 * s1 + e * s2),
        name,
        dict(kind="tapered_sine", amplitude=amp, frequency_hz=f, taper_cycles=cycles, phase_rad=phase_rad),
    )


# -- rounded triangle --------------------------------------------------------------
def _piecewise_linear_velocity(knots_t: np.ndarray, knots_v: np.ndarray, t: np.ndarray):
    """d, v, a sampled at t for a velocity piecewise linear through the knots, d(0) = 0.

    Displacement is integrated exactly (piecewise quadratic); a is the slope of the
    segment holding each sample.
    """
    dt_k = np.diff(knots_t)
    slope = np.diff(knots_v) / dt_k
    d_k = np.concatenate([[0.0], np.cumsum(0.5 * (knots_v[:-1] + knots_v[1:]) * dt_k)])
    i = np.clip(np.searchsorted(knots_t, t, side="right") - 1, 0, len(dt_k) - 1)
    s = t - knots_t[i]
    a = slope[i]
    v = knots_v[i] + a * s
    d = d_k[i] + knots_v[i] * s + 0.5 * a * s * s
    return d, v, a


def triangle(
    *,
    peak_displacement: float,
    peak_velocity: float,
    sample_rate_hz: float,
    n_cycles: float = 1,
    rounding_fraction: float = 0.1,
    max_acceleration: float = 2 * G,
    name: str = "triangle",
) -> Motion:
    """Triangular displacement (constant-speed ramps) with parabolic rounding at the peaks.

    The NEES-UCSD triangular tests (Ozcelik et al. 2008, Table 1) give a peak
    displacement D, a peak velocity V and the frequency V / (4 D) of the sharp
    triangle, "rounded at the peaks over 1/10 of the period, acceleration <= 2 g".

    Here the velocity is a trapezoid wave: +V, then a linear reversal to -V over the
    rounding time ``Tr`` (constant acceleration ``2 V / Tr``, a parabola in
    displacement), then -V, and so on. ``Tr`` is ``rounding_fraction`` of the period,
    lengthened if needed so the acceleration stays within ``max_acceleration``. D and V
    are reached exactly; the price is a period ``T = 4 D / V + Tr`` slightly longer
    than the sharp triangle's 4 D / V (by 1/(1 - rounding_fraction) when the fraction
    governs). The test starts and ends at rest at zero: the first and last quarter
    cycles begin/finish with a half reversal (0 -> V over Tr / 2).

    Returns a Motion whose ``info`` holds ``period_s``, ``frequency_hz``,
    ``rounding_s`` and ``peak_acceleration`` (= 2 V / Tr).
    """
    D = _positive("peak_displacement", peak_displacement)
    V = _positive("peak_velocity", peak_velocity)
    fs = _positive("sample_rate_hz", sample_rate_hz)
    r = _positive("rounding_fraction", rounding_fraction)
    a_max = _positive("max_acceleration", max_acceleration)
    if r >= 0.5:
        raise MotionError(
            f"rounding_fraction {r:g} leaves no constant-speed ramp; use a value below 0.5 (0.1 is usual)"
        )
    cycles = _positive("n_cycles", n_cycles)
    if abs(cycles * 2 - round(cycles * 2)) > 1e-9:
        raise MotionError(f"n_cycles {cycles:g} is not a whole number of half cycles; use e.g. 1, 1.5 or 3")
    n_peaks = int(round(cycles * 2))
    tr_fraction = r * (4 * D / V) / (1 - r)  # Tr = r T with T = 4D/V + Tr
    tr_accel = 2 * V / a_max
    Tr = max(tr_fraction, tr_accel)
    hold = 2 * D / V - Tr / 2  # constant-speed time between two peaks
    if Tr > 2 * D / V * (1 + 1e-12):  # the first quarter (0 -> D from rest) needs hold >= Tr / 2
        raise MotionError(
            f"triangle with D = {D:g} m cannot reach V = {V:g} m/s with rounding {Tr:.3g} s "
            f"(acceleration <= {a_max:g} m/s^2 needs V^2 <= a D = {a_max * D:.3g} m^2/s^2; "
            f"rounding_fraction must be <= 1/3); lower peak_velocity or rounding_fraction, or raise max_acceleration"
        )
    check_samples(
        n_peaks / 2 * (4 * D / V + Tr) * fs + 1,
        f"a triangle of {cycles:g} cycles of {4 * D / V + Tr:.3g} s at {fs:g} Hz",
        None,
        MotionError,
    )  # before building its knots
    # knots of the trapezoidal velocity
    kt, kv = [0.0, Tr / 2], [0.0, V]
    t_now, sign = Tr / 2, 1.0
    t_now += hold / 2 - Tr / 4  # first quarter: distance V*Tr/4 (half reversal) + V*h1 + V*Tr/4 = D
    kt.append(t_now), kv.append(sign * V)
    for p in range(n_peaks):
        t_now += Tr
        sign = -sign
        kt.append(t_now), kv.append(sign * V)
        seg = hold if p < n_peaks - 1 else hold / 2 - Tr / 4
        t_now += seg
        kt.append(t_now), kv.append(sign * V)
    t_now += Tr / 2
    kt.append(t_now), kv.append(0.0)
    kt.append(t_now + 2.0 / fs), kv.append(0.0)  # at rest through the last sample
    knots_t, knots_v = np.array(kt), np.array(kv)
    n = check_samples(math.ceil(t_now * fs - 1e-9) + 1, f"a triangle of {t_now:g} s at {fs:g} Hz", None, MotionError)
    t = np.arange(n) / fs
    d, v, a = _piecewise_linear_velocity(knots_t, knots_v, t)
    period = 4 * D / V + Tr
    info = dict(
        kind="triangle",
        peak_displacement=D,
        peak_velocity=V,
        n_cycles=cycles,
        rounding_fraction=r,
        rounding_s=Tr,
        period_s=period,
        frequency_hz=1 / period,
        sharp_frequency_hz=V / (4 * D),
        peak_acceleration=2 * V / Tr,
        acceleration_limited=tr_accel > tr_fraction,
        end_time_s=t_now,
    )
    return Motion(t, d, v, a, name, info)


# -- white noise -------------------------------------------------------------------
def white_noise(
    *,
    duration_s: float,
    sample_rate_hz: float,
    band_hz: tuple[float, float],
    seed: int | Sequence[int] | np.random.SeedSequence,
    rms_acceleration: float | None = None,
    rms_displacement: float | None = None,
    taper_s: float | None = None,
    name: str = "white noise",
) -> Motion:
    """Band-limited white-noise acceleration, flat between ``band_hz`` = (f_lo, f_hi).

    Random Fourier coefficients (``numpy.random.default_rng(seed)``) fill the band
    with a flat acceleration spectrum; displacement and velocity come from the same
    spectrum (D = -A / w^2, V = A / (i w)), so there is no integration drift and the
    signal has no content below f_lo (zero mean). The ends are cosine tapered over
    ``taper_s`` (default: max(1 / f_lo, 5 % of the duration), at most 25 %), with v and a
    from the product rule, so the table starts and ends at rest at zero.

    Give exactly one of ``rms_acceleration`` (m/s^2) and ``rms_displacement`` (m):
    the whole tapered signal is scaled to that RMS. The same seed gives the same signal
    bit for bit; for several DOFs use ``seed=(seed, dof_index)``.
    """
    if (rms_acceleration is None) == (rms_displacement is None):
        raise MotionError("white noise needs exactly one of rms_acceleration and rms_displacement; give one")
    fs = _positive("sample_rate_hz", sample_rate_hz)
    t = time_vector(duration_s, fs)
    n = t.size
    try:
        f_lo, f_hi = (float(x) for x in band_hz)
    except (TypeError, ValueError):
        raise MotionError(f"band_hz {band_hz!r} is not a pair (f_lo, f_hi); give e.g. (0.5, 50)") from None
    total = float(t[-1])
    if not (0 < f_lo < f_hi <= fs / 2):
        raise MotionError(
            f"white-noise band {f_lo:g}-{f_hi:g} Hz is not within 0 < f_lo < f_hi <= {fs / 2:g} Hz "
            f"(half the sample rate); change band_hz or sample_rate_hz"
        )
    if f_lo * total < 2:
        raise MotionError(
            f"white noise of {total:g} s is too short for f_lo = {f_lo:g} Hz; make it at least {2 / f_lo:g} s long"
        )
    if taper_s is None:
        taper_s = min(max(1.0 / f_lo, 0.05 * total), 0.25 * total)
    taper_s = _positive("taper_s", taper_s, allow_zero=True)
    if 2 * taper_s > total:
        raise MotionError(f"taper_s {taper_s:g} s is over half the {total:g} s duration; shorten it")
    rng = np.random.default_rng(seed)
    freqs = np.fft.rfftfreq(n, 1 / fs)
    band = (freqs >= f_lo) & (freqs <= f_hi)
    spec_a = np.zeros(freqs.size, dtype=complex)
    k = int(band.sum())
    spec_a[band] = rng.standard_normal(k) + 1j * rng.standard_normal(k)
    if n % 2 == 0:  # the Nyquist bin of an even-length real signal must be real
        spec_a[-1] = spec_a[-1].real
    w = 2 * np.pi * freqs
    with np.errstate(divide="ignore", invalid="ignore"):
        spec_v = np.where(band, spec_a / (1j * w), 0)
        spec_d = np.where(band, -spec_a / (w * w), 0)
    a0, v0, d0 = (np.fft.irfft(s, n) for s in (spec_a, spec_v, spec_d))
    e, e1, e2 = _cosine_envelope(t, taper_s, total)
    d = e * d0
    v = e1 * d0 + e * v0
    a = e2 * d0 + 2 * e1 * v0 + e * a0
    if rms_acceleration is not None:
        target = _positive("rms_acceleration", rms_acceleration, allow_zero=True)
        scale = target / float(np.sqrt(np.mean(a * a)))
    else:
        target = _positive("rms_displacement", rms_displacement, allow_zero=True)
        scale = target / float(np.sqrt(np.mean(d * d)))
    info = dict(
        kind="white_noise",
        band_hz=(f_lo, f_hi),
        taper_s=taper_s,
        seed=seed if isinstance(seed, (int, np.integer)) else str(seed),
        rms_acceleration=float(np.sqrt(np.mean(a * a))) * scale,
        rms_displacement=float(np.sqrt(np.mean(d * d))) * scale,
    )
    return Motion(t, d * scale, v * scale, a * scale, name, info)


# -- limits ------------------------------------------------------------------------
def _limit_for(limits: Mapping, key: str, dof: str):
    value = limits.get(key)
    if isinstance(value, Mapping):
        value = value.get(dof)
    return None if value is None else float(value)


def check_limits(peaks_by_dof: Mapping[str, Peaks | Motion], limits: Mapping) -> list[str]:
    """Compare each DOF's peak displacement, velocity and acceleration with table limits.

    Args:
        peaks_by_dof: {dof: Peaks or Motion}, dofs named x, y, z, rx, ry, rz.
        limits: ``stroke_m``, ``velocity_m_s``, ``acceleration_m_s2`` (translations) and
            ``rotation_rad``, ``angular_velocity_rad_s``, ``angular_acceleration_rad_s2``
            (rotations); each a number or a {dof: number} dict (the CGS stroke differs
            per axis). A missing limit is not checked.

    Returns:
        One warning per exceeded limit, e.g.
        ``"x peak displacement 0.31 m exceeds the +/-0.25 m stroke by 24 %"``; empty if
        the motion fits.
    """
    warnings = []
    for dof, pk in peaks_by_dof.items():
        if isinstance(pk, Motion):
            pk = pk.peaks
        rot = dof in ROTATION_DOFS
        checks = (
            (
                "displacement",
                pk.displacement,
                "rotation_rad" if rot else "stroke_m",
                "rad" if rot else "m",
                "rotation" if rot else "stroke",
            ),
            (
                "velocity",
                pk.velocity,
                "angular_velocity_rad_s" if rot else "velocity_m_s",
                "rad/s" if rot else "m/s",
                "velocity limit",
            ),
            (
                "acceleration",
                pk.acceleration,
                "angular_acceleration_rad_s2" if rot else "acceleration_m_s2",
                "rad/s^2" if rot else "m/s^2",
                "acceleration limit",
            ),
        )
        for what, value, key, unit, label in checks:
            lim = _limit_for(limits, key, dof)
            if lim is None or not value > lim:
                continue
            over = 100.0 * (value / lim - 1.0)
            extra = f" ({value / G:.2f} g vs {lim / G:.2f} g)" if what == "acceleration" and not rot else ""
            warnings.append(
                f"{dof} peak {what} {value:.3g} {unit} exceeds the +/-{lim:.3g} {unit} {label} by {over:.0f} %{extra}"
            )
    return warnings


# -- response spectrum -------------------------------------------------------------
#: the filters of recent (oscillator frequencies, damping, step) combinations: a sweep or a
#: feasibility suite computes the same spectrum periods at the same step for every run, and
#: the matrix exponentials cost ~0.3 s per call (measured, loaded 2-core machine)
_FOH_CACHE: dict = {}
_FOH_CACHE_SIZE = 16


def _foh_filters(omega: np.ndarray, zeta: float, dt: float):
    """:func:`_foh_filters_uncached`, remembered for the last :data:`_FOH_CACHE_SIZE`
    combinations (the same arrays, read-only: bit-identical results)."""
    omega = np.ascontiguousarray(omega, dtype=float)
    key = (omega.tobytes(), float(zeta), float(dt))
    hit = _FOH_CACHE.get(key)
    if hit is None:
        b, a = _foh_filters_uncached(omega, zeta, dt)
        b.flags.writeable = False
        a.flags.writeable = False
        if len(_FOH_CACHE) >= _FOH_CACHE_SIZE:
            _FOH_CACHE.pop(next(iter(_FOH_CACHE)))
        hit = _FOH_CACHE[key] = (b, a)
    return hit


def _foh_filters_uncached(omega: np.ndarray, zeta: float, dt: float):
    """Second-order IIR coefficients (b, a) per oscillator for u'' + 2 z w u' + w^2 u = -a_g.

    Exact for ground acceleration linear between samples (first-order hold; the
    Nigam-Jennings recurrence): x[k+1] = P x[k] + G1 a[k] + G2 (a[k+1] - a[k]) with
    P, G1, G2 from one matrix exponential per oscillator (batched), written as a
    transfer function for scipy.signal.lfilter.
    """
    m = omega.size
    M = np.zeros((m, 4, 4))
    M[:, 0, 1] = 1.0
    M[:, 1, 0] = -(omega**2)
    M[:, 1, 1] = -2 * zeta * omega
    M[:, 1, 2] = -1.0
    M[:, :, :] *= dt
    M[:, 2, 3] = 1.0
    E = scipy.linalg.expm(M)
    P, G1, G2 = E[:, :2, :2], E[:, :2, 2], E[:, :2, 3]
    G0 = G1 - G2
    b = np.stack(
        [
            G2[:, 0],
            G0[:, 0] - P[:, 1, 1] * G2[:, 0] + P[:, 0, 1] * G2[:, 1],
            -P[:, 1, 1] * G0[:, 0] + P[:, 0, 1] * G0[:, 1],
        ],
        axis=1,
    )
    a = np.stack([np.ones(m), -(P[:, 0, 0] + P[:, 1, 1]), P[:, 0, 0] * P[:, 1, 1] - P[:, 0, 1] * P[:, 1, 0]], axis=1)
    return b, a


def response_spectrum(
    acc: np.ndarray,
    dt: float,
    periods: np.ndarray | None = None,
    *,
    freqs: np.ndarray | None = None,
    damping: float = 0.05,
) -> np.ndarray:
    """Pseudo-acceleration response spectrum PSA = w^2 max|u| of a ground acceleration.

    Args:
        acc: ground (table) acceleration, shape (N,), m/s^2; taken as linear between
            samples and starting from rest.
        dt: sample step, s.
        periods: oscillator periods, s (0 gives the peak ground acceleration); or
        freqs: oscillator frequencies, Hz (give exactly one of the two).
        damping: damping ratio of the oscillators (0.05 = 5 %).

    Returns:
        PSA in m/s^2, same shape as periods / freqs.
    """
    acc = np.asarray(acc, dtype=float)
    if acc.ndim != 1 or acc.size < 2:
        raise MotionError(f"response spectrum needs a 1-D acceleration history, got shape {acc.shape}; pass one DOF")
    if not np.all(np.isfinite(acc)):
        raise MotionError("acceleration for the response spectrum has NaN/inf samples; fill or cut them first")
    dt = _positive("dt", dt)
    zeta = float(damping)
    if not 0 <= zeta < 1:
        raise MotionError(f"damping {damping!r} must be in [0, 1); give a ratio such as 0.05")
    if (periods is None) == (freqs is None):
        raise MotionError("response_spectrum needs exactly one of periods and freqs; give one")
    if periods is not None:
        per = np.asarray(periods, dtype=float)
        with np.errstate(divide="ignore"):
            omega = np.where(per > 0, 2 * np.pi / np.where(per > 0, per, 1), np.inf)
    else:
        f = np.asarray(freqs, dtype=float)
        omega = 2 * np.pi * f
    if np.any(~(omega > 0)):
        raise MotionError("response spectrum periods and frequencies must be positive; drop zero/negative values")
    shape = omega.shape
    omega = omega.ravel()
    psa = np.empty(omega.size)
    pga = float(np.max(np.abs(acc)))
    finite = np.isfinite(omega)
    psa[~finite] = pga
    if np.any(finite):
        w = omega[finite]
        b, a = _foh_filters(w, zeta, dt)
        out = np.empty(w.size)
        for i in range(w.size):
            u = scipy.signal.lfilter(b[i], a[i], acc)
            out[i] = w[i] ** 2 * np.max(np.abs(u))
        psa[finite] = out
    return psa.reshape(shape)


__all__ = [
    "G",
    "Motion",
    "Peaks",
    "check_limits",
    "peaks",
    "response_spectrum",
    "sine",
    "tapered_sine",
    "time_vector",
    "triangle",
    "white_noise",
]
