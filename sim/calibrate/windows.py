"""Where a record holds information: the windows the replay and closed-loop searches
screen and refine on, and the columns (channels, DOFs) a test excites at all.

*Windows.* The screening (one short replay per candidate parameter) and the
refinement (a few least-squares iterations per candidate) cannot replay whole records,
so they replay a window of each. A window at a fixed position (the first second)
lands, on a real earthquake record, in the quiet lead-in before the strong motion: a
residual of sensor noise, where every candidate explains nothing or anything.
:func:`choose` picks the window by the excitation it holds: the running mean square of
the drive (valve commands or reference, each channel scaled by its largest column) and
of the recorded motion and force, averaged over channels; among the windows whose
mean square reaches :data:`STRONG_FRACTION` of the strongest window's, the one with the
most excitation per second replayed (a stationary random test keeps the window at its
start, an earthquake gets its strong phase; a window late in a record costs a replay
of all before it, see below). A long record is sampled by several segments
(``segments``), one in each part of its excited span.

*Where a replay starts.* The model starts at rest (:func:`sim.calibrate.replay.replay_setup`:
the platen at home, the hydraulics at their reset, the valve driven by the recorded
command plus the null estimated from the whole record); it cannot start mid-record
without the record's full state (pressures, velocities, the friction's stick state),
which no record holds. So a window is replayed from a point where the record itself
is at rest, and scored only over its own rows: from the end of the quiet lead-in
(every drive and recorded column still within :data:`QUIET_LEAD` of its full swing,
so the model's rest state is the record's state there, to that share), less
:data:`SETTLE_S` for the model to settle, or from the record's start when it has no
quiet lead-in. The cost is honest: a window late in a record replays everything
before it back to that point (:attr:`Window.replay_s`), which is why the strong
window with the most excitation per replayed second is taken.

*Excited columns.* A column (an actuator's force, a DOF's motion or generalised force)
that the test barely moved holds sensor noise and cross-talk: normalised by its own
RMS its error is noise over nothing (a rotation under a translational test: 292 %
where the translations have 2 %). :func:`excited` keeps the columns whose RMS reaches
:data:`QUIET_COLUMN` of the largest in consistent units; DOFs are brought to one unit
through the table's kinematic Jacobian (:func:`dof_weights`: a moment as the actuator
forces that make it, a rotation as the strokes it takes). Both residual paths use it;
the columns it leaves out are reported as not excited and kept out of the pooled error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: a column whose RMS (in consistent units) is below this share of its channel's largest
#: is not excited (a DOF the run does not drive: its residual is noise over nothing).
#: Measured on CGS 3-axis random runs (1-30 Hz, 1 m/s^2, the 1024 Hz recorder model's
#: 0.003 g accelerometer noise), in actuator units: the rotations' acceleration 4-7 % of
#: the largest translation's (sensor noise: their velocity is 2-3 %), the moment about
#: the vertical 2 % of the largest force, the moments about x and y 20-22 % (the real
#: moment of accelerating the platen's mass above the actuators' plane). 10 %: above
#: the noise, below any DOF a test drives.
QUIET_COLUMN = 0.10
#: a window is strong when its mean-square excitation reaches this share of the
#: strongest window's (assumed: a quarter, an RMS half the strongest's: the strong phase
#: of an earthquake, not its weak onset); among the strong ones the search takes the
#: most excitation per second replayed. On a 20 s random record (lab, 1-20 Hz) the
#: strongest 1 s window sat 7 s in, and the earliest at half of it cost 8.5 s a replay
STRONG_FRACTION = 0.25
#: the lead-in is quiet while every column's running RMS stays below this share of its
#: channel's largest running RMS (assumed: 5 %, above a record's sensor noise)
QUIET_LEAD = 0.05
#: running RMS of the quiet-lead test (s): longer than a sensor-noise spike
QUIET_SMOOTH_S = 0.05
#: the replay starts this long before the end of a quiet lead-in (s): time for the
#: model's own start transient (hydraulics from their reset) to settle
SETTLE_S = 0.25


@dataclass(frozen=True)
class Window:
    """Samples ``[start, stop)`` of a record replayed, scored over ``[score_from, stop)``."""

    start: int
    score_from: int
    stop: int
    fs: float

    @property
    def replay_s(self) -> float:
        return (self.stop - self.start) / self.fs

    @property
    def scored_s(self) -> float:
        return (self.stop - self.score_from) / self.fs


def excited(rms, weights=None, fraction: float = QUIET_COLUMN) -> np.ndarray:
    """Bool mask of the columns whose ``rms * weights`` (consistent units) reaches
    ``fraction`` of the largest: the columns a test excites."""
    x = np.abs(np.asarray(rms, float)) * (1.0 if weights is None else np.asarray(weights, float))
    top = float(np.max(x)) if x.size else 0.0
    return x > fraction * top if top > 0 else np.zeros(x.shape, bool)


def dof_weights(J6: np.ndarray, dofs, kind: str) -> np.ndarray:
    """Per DOF of ``dofs``, the factor that takes its motion (``kind="motion"``: the norm of
    the strokes a unit motion takes, ``|J e_j|``) or its generalised force (``"force"``:
    the norm of the smallest actuator forces that make a unit force or moment,
    ``|pinv(J^T) e_j|``) into actuator units, so that a rotation and a translation, a
    moment and a force compare. ``J6``: (n_act, 6) kinematic Jacobian at home."""
    from mjcf.description import DOFS6

    k = [DOFS6.index(d) for d in dofs]
    J = np.asarray(J6, float)[:, k]
    if kind == "motion":
        return np.linalg.norm(J, axis=0)
    if kind == "force":
        return np.linalg.norm(np.linalg.pinv(J.T), axis=0)
    raise ValueError(f"kind must be 'motion' or 'force' (got {kind!r})")


def _scaled_square(x: np.ndarray) -> np.ndarray:
    """(n,) mean over columns of one channel's square, the channel scaled by its largest
    column's RMS about its first value (a static load or null is no excitation)."""
    x = np.asarray(x, float).reshape(len(x), -1)
    x = x - x[: max(1, min(16, len(x)))].mean(axis=0)
    top = float(np.sqrt(np.mean(x**2, axis=0)).max()) if x.size else 0.0
    return np.mean(x**2, axis=1) / top**2 if top > 0 else np.zeros(len(x))


def excitation(channels) -> np.ndarray:
    """(n,) instantaneous excitation of a record: the mean over ``channels`` (arrays (n,)
    or (n, m): drive, motion, force) of each one's scaled square (:func:`_scaled_square`)."""
    parts = [_scaled_square(x) for x in channels if x is not None]
    return np.mean(parts, axis=0)


def quiet_lead(channels, fs: float) -> int:
    """Samples of the record's quiet lead-in: up to the first instant any column's running
    RMS (:data:`QUIET_SMOOTH_S`) about its first value leaves :data:`QUIET_LEAD` of its
    channel's largest; 0 when the record moves from its start."""
    w = max(1, int(round(QUIET_SMOOTH_S * fs)))
    first = None
    for x in channels:
        x = np.asarray(x, float).reshape(len(x), -1)
        x = x - x[: max(1, min(16, len(x)))].mean(axis=0)
        ms = np.apply_along_axis(lambda c: np.convolve(c**2, np.ones(w) / w, mode="same"), 0, x)
        rr = np.sqrt(ms)
        top = float(rr.max()) if rr.size else 0.0  # the channel's largest column: a still column's noise is no motion
        loud = np.flatnonzero(np.any(rr > QUIET_LEAD * top, axis=1)) if top > 0 else np.array([], int)
        if len(loud):
            first = loud[0] if first is None else min(first, loud[0])
    return int(max(0, (first if first is not None else 0) - w // 2))


def _best_window(e: np.ndarray, lo: int, hi: int, width: int, start: int) -> int:
    """Start of the ``width``-sample window in ``[lo, hi)`` that holds the most excitation
    per second replayed (its mean of ``e`` over the samples replayed from ``start`` to its
    end), among the strong ones (mean at least :data:`STRONG_FRACTION` of the strongest
    there): the strong motion, at the least cost."""
    width = min(width, hi - lo)
    c = np.concatenate([[0.0], np.cumsum(e[lo:hi])])
    mean = (c[width:] - c[:-width]) / width
    top = float(mean.max())
    if not top > 0:
        return lo
    a = lo + np.arange(len(mean))
    value = np.where(mean >= STRONG_FRACTION * top, mean / (a + width - min(start, lo)), -np.inf)
    return lo + int(np.argmax(value))


def choose(channels, fs: float, seconds: float | None, *, segments: int = 1, horizon_s: float | None = None) -> list:
    """The windows of one record to replay (:class:`Window`, in time order): ``segments``
    windows of ``seconds / segments`` each, the k-th the strong one with the most
    excitation per second replayed (:func:`_best_window`) in the k-th part of the excited span (from the end of the
    quiet lead-in, :func:`quiet_lead`, over ``horizon_s`` or to the record's end), each
    replayed from the quiet lead-in's end less :data:`SETTLE_S` (or the record's start).
    ``seconds`` None or longer than the record: the whole record."""
    n = len(np.asarray(channels[0]))
    if seconds is None or seconds * fs >= n - 1:
        return [Window(0, 0, n, fs)]
    q = quiet_lead(channels, fs)
    start = max(0, q - int(round(SETTLE_S * fs)))
    end = n if horizon_s is None else min(n, q + int(round(horizon_s * fs)))
    width = max(int(round(seconds / segments * fs)) + 1, 64)
    if end - q < segments * width:  # too short to split: one window from the lead-in's end
        segments, width = 1, min(max(int(round(seconds * fs)) + 1, 64), n - start)
        q = min(q, n - width)
    e = excitation(channels)
    edges = np.linspace(q, end, segments + 1).astype(int)
    out = []
    for k in range(segments):
        lo = min(int(edges[k]), n - width)
        a = _best_window(e, lo, min(n, max(int(edges[k + 1]), lo + width)), width, start)
        a = min(a, n - width)
        out.append(Window(min(start, a), max(a, start), a + width, fs))
    return out


__all__ = [
    "QUIET_COLUMN",
    "QUIET_LEAD",
    "SETTLE_S",
    "STRONG_FRACTION",
    "Window",
    "choose",
    "dof_weights",
    "excitation",
    "excited",
    "quiet_lead",
]
