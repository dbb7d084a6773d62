"""A sensor-timing candidate of the mechanical path fitted and judged (:mod:`sim.calibrate.timing`).

Each round's timing candidates (:func:`round_candidates`) are fitted on the force balance
(or read by the kinematics, :mod:`sim.calibrate.kinematic_timing`) and judged by the rules
every candidate meets (:func:`sim.calibrate.acceptance.accept_numbers`) plus their own: off
their bounds with the declared value outside their interval, a gain within a
transducer's tolerance, what they take out coherent with the motion, and the
displacement's word on the acceleration's timing (:func:`evaluate`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from sim.calibrate.kinematic_timing import kinematic_reading, off_its_chain, placed, read_by_kinematics
from sim.calibrate.timing import (
    COHERENT_SHARE,
    Z95,
    Candidate,
    _restacked,
    candidates,
    coherent_share,
    retime,
    search,
    uncertainty_of,
)


def evaluate(mfit, mho, cur, cand: Candidate, e_ho: float, flat: float, margin: float, first=None, at=None) -> dict:
    """The candidate fitted and judged: ``{"row", "accepted", "fit", "mfit", "mho"}`` (the
    retimed runs and the refit); ``first``: a kinematic candidate's reading at its neutral
    value, when taken to offer it; ``at``: ``(value, sd, None)`` read by :mod:`sim.calibrate.gainpair`."""
    from sim.calibrate.acceptance import accept_numbers
    from sim.calibrate.residuals import nrmse_runs
    from sim.calibrate.trace import fit_terms, flatness, predict

    if at is not None:
        x, s, kin = at
    elif cand.read_by_kinematics:
        x, s, kin = read_by_kinematics(mfit, cand, first)
    else:
        x, s, kin = placed(mfit, cur.terms, cand, search(mfit, cur.terms, cand))
    nf = [retime(mr, cand.state(mr.extra["timing"], x)) for mr in mfit]
    nh = [retime(mr, cand.state(mr.extra["timing"], x)) for mr in mho]
    if cand.read_by_kinematics:  # judged on the samples where the re-timed motion moves
        cur, e_ho, flat = _on_the_rows_of(mfit, mho, nf, nh, cur)
    new = fit_terms(nf, cur.terms, refine="none")
    e_new = nrmse_runs(nh, predict(nh, new))
    f_new = flatness(nf, new.residuals)
    bic_new = new.n * math.log(max(new.rss, 1e-300) / new.n) + (new.p + 1) * math.log(new.n)
    ok, why = _param_check(cand, x, s)
    if ok and cand.field == "force_gain":
        ok, why = _accelerometer_reads_true(mfit)
    share = coherent_share(mfit, cur.residuals, new.residuals)
    # the motion's delay is the kinematics', not fitted to the residual, and what it takes
    # out goes through the friction's sign: not a filtered copy of the motion's own force
    if ok and share < COHERENT_SHARE and not cand.read_by_kinematics:
        ok, why = False, f"what it takes out of the residual is {100 * share:.0f} % coherent with the motion"
    if ok and kin is not None and not kin["ok"]:
        ok, why = False, kin["reason"]
    first = ok and off_its_chain(cand, x, kin, mfit[0].dt)
    if ok:
        m = 0.0 if first else margin
        # read by the kinematics beyond a scan: no whiteness veto either (a velocity 2 samples early
        # was refused at flatness 0.518 -> 0.506, an undeclared conditioner's shape in the residual)
        ok, why = accept_numbers(e_ho, e_new, cur.bic, bic_new, -math.inf if m == 0.0 else flat, f_new, m)
    value, unc = cand.value(x), uncertainty_of(cand, x, s)
    row = {
        "name": cand.name,
        "where": cand.where,
        **({"options": {"order": cand.order}} if cand.order else {}),
        "explained_fraction": 1.0 - new.rss / cur.rss if cur.rss > 0 else 0.0,
        "parameters": value,
        "uncertainty": unc,
        "holdout_error": e_new,
        "bic_change": bic_new - cur.bic,
        "flatness": f_new,
        "coherent_share": share,
        **({"kinematics": {k: v for k, v in kin.items() if k not in ("reason", "sigma_s")}} if kin else {}),
        "accepted": ok,
        "reason": why,
    }
    out = {"row": row, "accepted": ok, "fit": new, "mfit": nf, "mho": nh, "e_ho": e_new, "flat": f_new}
    return {**out, "first": first and ok}


def _on_the_rows_of(mfit, mho, nf, nh, cur) -> tuple:
    """``(fit, held-out error, flatness)`` of the current terms refitted on ``mfit`` and
    scored on ``mho`` over the samples the re-timed runs ``nf`` and ``nh`` read. A re-timed
    motion has its own still samples (:func:`sim.calibrate.residuals.moving_rows`); judged
    against the model on the old ones, a candidate is judged by which samples the noise on
    the velocity leaves below the deadband: on clean NEES-UCSD records (tests/calibrate/
    test_timing.py) the displacement re-timed 0.3 sample either way moved the held-out
    error up by 2.9-3.4 %, on the same samples by 0.2 % or less."""
    from sim.calibrate.residuals import nrmse_runs
    from sim.calibrate.trace import fit_terms, flatness, predict

    bf = [on_rows(mr, r.rows) for mr, r in zip(mfit, nf)]
    bh = [on_rows(mr, r.rows) for mr, r in zip(mho, nh)]
    fit = fit_terms(bf, cur.terms, refine="none")
    return fit, nrmse_runs(bh, predict(bh, fit)), flatness(bf, fit.residuals)


def on_rows(mr, rows: np.ndarray):
    """A mechanical run read over ``rows`` (its weighted target and stacked columns made
    anew, its weights kept: :func:`retime`'s)."""
    return _restacked(
        dataclasses.replace(mr, rows=rows, extra={k: v for k, v in mr.extra.items() if k not in ("y", "columns")})
    )


def _param_check(cand, x, s) -> tuple[bool, str]:
    """Off its bounds, a finite interval, the declared value outside it; a gain beyond a
    transducer's tolerance."""
    from sim.calibrate.pathjudge import within_tolerance

    if not math.isfinite(s):
        return False, f"{cand.param}: no finite confidence interval"
    span = cand.hi - cand.lo
    if x - cand.lo <= 1e-3 * span or cand.hi - x <= 1e-3 * span:
        return False, f"{cand.param} at the edge of its searched range"
    if abs(x - cand.neutral) <= Z95 * s:
        what = "the declared conditioner" if cand.field == "accel_lowpass_hz" else f"{cand.neutral:g} {cand.unit}"
        return False, f"{cand.param}: its 95 % interval holds {what}"
    why = within_tolerance(x) if cand.field == "force_gain" else ""
    return not why, why


def _accelerometer_reads_true(mfit) -> tuple[bool, str]:
    """Whether the balance's scale is the load cells': a gain of the accelerometers scales
    its inertial force alike (on NEES-UCSD records an accelerometer 4 % high was taken as
    load cells 4 % low, then a specimen's mode and more made up the friction that gain
    scaled). The velocity reads the acceleration's own gain
    (:func:`sim.calibrate.anchor.balance_acceleration_gain`): where that leaves out 1 by more
    than a transducer's tolerance the accelerometer is the one off, and the later path
    compares it alone."""
    from sim.calibrate.anchor import balance_acceleration_gain
    from sim.calibrate.pathjudge import GAIN_TOLERANCE

    g, s = balance_acceleration_gain(mfit)
    if math.isfinite(g) and abs(g - 1.0) > max(Z95 * s, GAIN_TOLERANCE):
        return (
            False,
            f"the velocity reads the accelerometer at a gain of {g:.4f} +/- {Z95 * s:.4f}: its gain, not the load cells'",
        )
    return True, ""


def round_candidates(mfit, mho, cur, e_ho, flat, margin, effects, done) -> list:
    """Every timing candidate not yet accepted (``done``: effects_added entries) and
    allowed by ``effects`` (None: all), fitted and judged against the current fit."""
    have = {(d["name"], d["where"]) for d in done}
    out = []
    for cand in candidates(mfit):
        if (cand.name, cand.where) in have or (effects and cand.name not in effects):
            continue
        first = kinematic_reading(mfit, cand, cand.neutral) if cand.read_by_kinematics else None
        if first is not None and not first.significant:
            continue  # the two sensors of the motion agree: nothing to time
        out.append(evaluate(mfit, mho, cur, cand, e_ho, flat, margin, first))
    return out


__all__ = ["evaluate", "on_rows", "round_candidates"]
