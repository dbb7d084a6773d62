"""A sensor's constant offset, told from the zero each record takes anew.

The replay and closed-loop paths compare each record about its own zero
(:func:`sim.calibrate.paths.tared`): a lab tares its transducers before each test and
their zeros wander from record to record. What is left of a sensor's offset is the part
that every record shares. After the search, each compared column's zero (the mean of
recorded minus model over its scored rows) is read in every fit run; an offset is named
where the fit runs agree on it (their mean over twice its 95 % interval, Student's t
over the runs' scatter), it is at least :data:`MIN_SHARE` of what the test put into the
column, and it predicts the held-out runs' zeros (their RMS about it below the
acceptance margin times their RMS about nothing). One run cannot tell a shared offset
from its own zero: nothing is named then.
"""

from __future__ import annotations

import math

import numpy as np

#: an offset smaller than this share of its column's RMS about its mean is not named
#: (assumed: 5 %, the acceptance margin of the held-out error)
MIN_SHARE = 0.05
#: an offset is named only when its 95 % interval is under this share of it: a zero of
#: -3507 +/- 3497 N shared by chance by two CGS records and their held-out one (the
#: recorder's 2 kN zero a record, 18 columns compared) is not a sensor's (assumed: 2)
DETERMINED = 2.0
#: channels whose zero is read: a band-passed displacement has none, and the specimen's
#: accelerometers are compared about their record's mean already
READ = ("actuator_force", "table_acceleration", "table_velocity", "pressure_a", "pressure_b")


def zeros(prs, models) -> dict:
    """``(channel, column) -> [each run's mean of recorded minus model over its scored rows]``."""
    out = {}
    for pr, m in zip(prs, models):
        if m is None:
            continue
        for ch, cols in pr.columns.items():
            if ch not in READ:
                continue
            for j in cols:
                e = pr.recorded[ch][pr.rows][:, j] - m[ch][pr.rows][:, j]
                out.setdefault((ch, j), []).append(float(np.mean(e)))
    return out


def _scale(prs, ch: str, j: int) -> float:
    vals = [float(pr.scale[ch][pr.columns[ch].index(j)]) for pr in prs if j in pr.columns.get(ch, [])]
    return float(np.mean(vals)) if vals else math.inf


def judged(prs_fit, m_fit, prs_ho, m_ho, margin: float) -> tuple[list, list]:
    """``(effects_added entries, candidates rows)`` of the offsets the runs share."""
    from scipy.stats import t as student

    fit, ho = zeros(prs_fit, m_fit), zeros(prs_ho, m_ho)
    found, rows = [], []
    for (ch, j), z in sorted(fit.items()):
        n = len(z)
        if n < 2 or (ch, j) not in ho:
            continue
        mean, half = float(np.mean(z)), float(student.ppf(0.975, n - 1) * np.std(z, ddof=1) / math.sqrt(n))
        zh = np.asarray(ho[(ch, j)])
        before, after = float(np.sqrt(np.mean(zh**2))), float(np.sqrt(np.mean((zh - mean) ** 2)))
        why = _refusal(mean, half, _scale(prs_fit, ch, j), before, after, margin)
        where = f"channel:{ch}" if np.shape(prs_fit[0].recorded[ch])[1] == 1 else f"channel:{ch}[{j}]"
        if why is None or abs(mean) > half:
            rows.append(_row(where, mean, half, before, after, why))
        if why is None:
            found.append(_entry(where, mean, half))
    return found, rows


def _refusal(mean, half, scale, before, after, margin) -> str | None:
    if not abs(mean) > DETERMINED * half:
        return f"the runs' zeros scatter: {mean:.4g} +/- {half:.3g}"
    if abs(mean) < MIN_SHARE * scale:
        return f"{abs(mean):.4g} is under {100 * MIN_SHARE:g} % of the column's RMS ({scale:.4g})"
    if not after < (1 - margin) * before:
        return f"the held-out runs' zeros ({before:.4g} RMS) are not nearer it ({after:.4g} RMS)"
    return None


def _entry(where: str, mean: float, half: float) -> dict:
    return {
        "name": "sensor_offset",
        "where": where,
        "parameters": {"offset": mean},
        "uncertainty": {"offset": half},
        "units": {"offset": "channel units"},
        "note": "the zero every record shares (each record's own is taken about it)",
    }


def _row(where, mean, half, before, after, why) -> dict:
    return {
        "round": "zeros",
        "name": "sensor_offset",
        "where": where,
        "explained_fraction": 0.0,
        "parameters": {"offset": mean},
        "uncertainty": {"offset": half},
        "holdout_error": None,
        "held_out_zeros": {"before": before, "after": after},
        "accepted": why is None,
        "reason": why or "",
    }


__all__ = ["MIN_SHARE", "READ", "judged", "zeros"]
