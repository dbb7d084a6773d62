"""The replay and closed-loop paths' judgement of their refined candidates.

Best refined first (:func:`judge_best_first`): an implausible value against the table's
scale is refused before any replay (:func:`sim.calibrate.acceptance.implausible_candidate`,
a ``compensation`` row); a parameter at its bound brings its nested candidate (that
parameter held there, the rest refined again: :func:`refit_at_bound`), judged right
after it; each is then replayed on the whole fit and held-out runs and judged by the
rules every path shares (:func:`sim.calibrate.acceptance.accept_numbers`: held-out error
down by the margin, BIC down, residual whiter) with :func:`param_check` (off its bounds,
a finite 95 % interval excluding the neutral value). A sensor candidate, which changes
only its own channel or column of the model, is judged on those columns
(:func:`judge_sensor`). The first that passes is the round's winner; the search writes
the rows of the rest (:func:`record_the_rest`).
"""

from __future__ import annotations

import math
import time

import numpy as np


def bic(rss, n, p) -> float:
    """The Bayesian information criterion of a Gaussian residual: ``rss`` over ``n`` samples, ``p`` parameters."""
    return n * math.log(max(rss, 1e-300) / n) + p * math.log(n)


def judge_best_first(st, rnd: int, top, refined):
    """Each refined candidate, best first, on the whole runs (a nested refit is judged
    right after the one it comes from); the first that passes, or None."""
    from sim.calibrate.acceptance import implausible_candidate

    for rf in refined:
        sc_of = next(s.score for s in top if s.cand.key == rf.cand.key)
        if not rf.ok:
            st.tried.append(path_row(rnd, None, rf, None, rf.why, score=sc_of))
            continue
        bad = implausible_candidate(rf.cand, rf.cand.values(rf.theta), st.scale, st.peaks)
        if bad:  # refused before its whole-run replay: it stands in for something else
            st.tried.append({**path_row(rnd, None, rf, None, bad, score=sc_of), "compensation": True})
            st.say(f"  {rf.cand.type:20s} {rf.cand.where:26s} ({bad})")
            continue
        nested = refit_at_bound(rf, (st.wref, st.models["ref"], st.ctx), st.max_nfev)
        if nested is not None:  # judged right after it: its parameter held at the bound
            refined.insert(index_of(refined, rf) + 1, nested)
        winner = judge_whole_runs(st, rnd, rf, sc_of)
        if winner is not None:
            return winner
    return None


def judge_whole_runs(st, rnd: int, rf, sc_of):
    """One refined candidate judged on the whole fit and held-out runs; the winner tuple
    when it passes, else None (its row in ``st.tried`` either way)."""
    from sim.calibrate import paths as P
    from sim.calibrate.acceptance import Z95, accept_numbers
    from sim.calibrate.sensorcands import sensor_model

    pfit, pho = st.pfit, st.pho
    t = time.perf_counter()
    if rf.cand.sensor:
        ms = [sensor_model(rf.cand, rf.theta, p, m) for p, m in zip(pfit + pho, st.models["fit"] + st.models["ho"])]
    else:
        (ms,) = st.simulate([pfit + pho], st.accepted + [rf.cand.entry(rf.theta)])
    st.tm["accept_s"] += time.perf_counter() - t
    mf, mh = ms[: len(pfit)], ms[len(pfit) :]
    rn = P.stacked(pfit, mf)
    if rn is None or any(m is None for m in mh):
        st.tried.append(path_row(rnd, None, rf, None, "the whole-run replay diverged", score=sc_of))
        return None
    e_new, rss_new, p_new, f_new = P.nrmse(pho, mh), float(rn @ rn), st.n_par + len(rf.theta), P.flatness(pfit, mf)
    okp, why, unc = param_check(rf, Z95)
    in_model = list(st.desc.raw.get("effect", [])) + list(st.accepted)
    if okp and (why := same_mode(rf, unc, in_model) or same_law(rf, unc, in_model) or accel_gain_unseen(rf, unc, pfit)):
        okp = False
    bics = (bic(st.rss, st.N, st.n_par), bic(rss_new, st.N, p_new))
    local = None
    if not okp:
        ok = False
    elif rf.cand.sensor:  # judged on the columns it acts on
        cur = (st.models["fit"], st.models["ho"])
        ok, why, local = judge_sensor(rf.cand, pfit, pho, cur, (mf, mh), bics, st.margin)
    else:
        ok, why = accept_numbers(st.e_ho, e_new, *bics, st.flat, f_new, st.margin)
    row = path_row(rnd, None, rf, unc, why, score=sc_of)
    if local is not None:
        row["on_its_columns"] = local
    row.update({"holdout_error": e_new, "bic_change": bics[1] - bics[0], "flatness": f_new, "accepted": ok})
    st.tried.append(row)
    st.say(
        f"  {rf.cand.type:20s} {rf.cand.where:26s} explains {100 * rf.explained:6.2f} %  held-out {e_new:.4f}"
        + ("  ACCEPTED" if ok else f"  ({why})")
    )
    return (rf, unc, mf, mh, e_new, rss_new, p_new, f_new) if ok else None


def record_the_rest(st, rnd: int, sc, top, refined, winner) -> None:
    """The rows of the refined candidates after the winner and of the next screened ones,
    for the record, with their linearised scores on their own columns."""
    if winner is not None:
        for rf in refined[index_of(refined, winner[0]) + 1 :]:
            sc_of = next(s.score for s in top if s.cand.key == rf.cand.key)
            why = f"refined, not judged: {winner[0].cand.type} {winner[0].cand.where} explains more and passed"
            st.tried.append(path_row(rnd, None, rf, None, why if rf.ok else rf.why, score=sc_of))
    for s in [s for s in sc if all(s is not x for x in top)][:10]:  # the next ones by score, for the record
        st.tried.append(path_row(rnd, s, None, None, "not refined (lower linearised score)"))
    own_of = {s.cand.key: s.own for s in sc if s.own is not None}
    for row in st.tried:
        if row["round"] == rnd and (row["name"], row["where"]) in own_of:
            row["linearised_score_own_columns"] = own_of[(row["name"], row["where"])]


def judge_sensor(cand, pfit, pho, cur, new, bics, margin) -> tuple[bool, str, dict | None]:
    """``(accepted, reason, numbers)`` of a sensor candidate, judged on the columns it acts
    on: a sensor effect changes only its own channel (or column) of the model, so pooled
    over every compared column (18 on a 6-DOF table) a clear error on one column moves
    the held-out error by less than the margin. Its columns' held-out NRMSE must fall by
    ``margin`` of itself, the BIC (pooled) fall, its columns' fit residual get whiter
    (flatness counting a constant bias, :func:`sim.calibrate.paths.flatness`), and the
    other columns' held-out error not rise. ``cur``/``new``: (fit, held-out) model
    channels without / with it."""
    from sim.calibrate import paths as P
    from sim.calibrate.acceptance import accept_numbers
    from sim.calibrate.sensorcands import acts_on

    keep = acts_on(cand)
    on_ho = [p.only(keep) for p in pho]
    if any(not p.columns for p in on_ho):
        return False, f"{cand.where} is not compared in every held-out run", None
    on_fit = [p.only(keep) for p in pfit]
    e0, e1 = P.nrmse(on_ho, cur[1]), P.nrmse(on_ho, new[1])
    f0, f1 = P.flatness(on_fit, cur[0], bias=True), P.flatness(on_fit, new[0], bias=True)
    nums = {"holdout_error": [e0, e1], "flatness": [f0, f1]}
    ok, why = accept_numbers(e0, e1, *bics, f0, f1, margin)
    if not ok:
        return False, f"on {cand.where}: {why}", nums
    off_ho = [p.only(lambda c, j: not keep(c, j)) for p in pho]
    if all(p.columns for p in off_ho):
        o0, o1 = P.nrmse(off_ho, cur[1]), P.nrmse(off_ho, new[1])
        nums["other_columns_holdout_error"] = [o0, o1]
        if o1 > o0 * (1 + 1e-9):
            return False, f"the other columns' held-out error rises ({o0:.4f} -> {o1:.4f})", nums
    return True, "", nums


#: a sensor gain nearer 1 than this is within a transducer's own calibration tolerance
#: (assumed: 0.5 %, the class of a calibrated load cell or servo accelerometer); a lab
#: cannot act on it. Measured: a load cell's gain of 0.99952 +/- 0.00009 passed on the
#: lab table's replay, whose held-out error is 0.44 %
GAIN_TOLERANCE = 0.005


def param_check(rf, z95) -> tuple[bool, str, dict]:
    """Off the bounds (:func:`sim.calibrate.acceptance.bound_hit`, the mechanical path's
    test), a finite 95 % interval, the neutral value (no effect) outside it."""
    from sim.calibrate.acceptance import bound_hit

    c = rf.cand
    sig = c.sigmas(rf.theta, rf.sigma)
    vals = c.values(rf.theta)
    unc = {k: z95 * s for k, s in sig.items()}
    for i, k in enumerate(c.names):
        th, s = float(rf.theta[i]), float(rf.sigma[i])
        if not math.isfinite(s) or not math.isfinite(sig[k]):
            return False, f"{k}: no finite confidence interval", unc
        if bound_hit(th, c.lower[i], c.upper[i], 1e-3 * abs(c.step[i])):
            return False, f"{k} = {vals[k]:.4g} {c.units[k]} at its bound", unc
        if i in c.screened and abs(th - c.neutral[i]) <= z95 * s:
            return False, f"{k} = {vals[k]:.4g} {c.units[k]}: its 95 % interval includes the no-effect value", unc
    why = within_tolerance(vals["gain"]) if c.type == "sensor_gain" else _a_shorter_valve_delay(c, vals)
    return (False, why, unc) if why else (True, "", unc)


def _a_shorter_valve_delay(c, vals: dict) -> str:
    """Why the controller's channels recorded late (:data:`sim.calibrate.sensorcands.COMMAND`)
    are not named ("" where they are): within the declared valve delay the same records are
    a valve delay that much shorter, a number of the description read off a paper
    (the Rice table's 13.5 ms, Table 1 of [Trombetti 2002]); its own candidate reads it."""
    from sim.calibrate.sensorcands import COMMAND

    if c.where != COMMAND or vals["delay_s"] > c.ref.get("valve_delay_s", 0.0):
        return ""
    vd = c.ref["valve_delay_s"]
    return f"the records of a valve delay of {1e3 * (vd - vals['delay_s']):.3g} ms ({1e3 * vd:.3g} declared): its own candidate's"


def within_tolerance(gain: float) -> str:
    """Why a sensor's ``gain`` is not named (:data:`GAIN_TOLERANCE`); "" beyond it."""
    if abs(gain - 1.0) < GAIN_TOLERANCE:
        return f"gain = {gain:.5g}: within a transducer's calibration tolerance (+/-{GAIN_TOLERANCE:g})"
    return ""


def accel_gain_unseen(rf, unc: dict, pfit) -> str:
    """Why an accelerometer's gain is not that sensor's ("" where it is): the velocity (or
    displacement) of the same motion reads the acceleration at a gain whose 95 % interval
    holds 1 and leaves out the candidate's (:func:`sim.calibrate.anchor.kinematic_gain`).
    A gain of 0.987 +/- 0.002 on the lab table's replay stood in for the model's own
    amplitude error, where the velocity read the accelerometer true."""
    from sim.calibrate.acceptance import Z95
    from sim.calibrate.anchor import kinematic_gain

    c = rf.cand
    if c.type != "sensor_gain" or not c.where.startswith("channel:table_acceleration"):
        return ""
    cols = pfit[0].columns.get("table_acceleration", [])
    if "[" in c.where:
        cols = [int(c.where.split("[")[1][:-1])]
    g, s = kinematic_gain(pfit, cols)
    v = c.values(rf.theta)["gain"]
    if not math.isfinite(g) or abs(g - 1.0) > Z95 * s or abs(v - g) <= math.hypot(unc["gain"], Z95 * s):
        return ""
    return f"the velocity reads the accelerometer at a gain of {g:.4f} +/- {Z95 * s:.4f}: its own, not {v:.4f}"


def same_mode(rf, unc: dict, entries: list) -> str:
    """Why a specimen's mode (``payload_mode``) is one the model holds already: its
    frequency's 95 % interval holds that of a mode at the same place ('' when none does).
    Two modes that the records cannot tell apart are one mode with its damping misfitted
    (measured: 754 kg at 7.46 Hz, 1.3 %, then 66 kg at 7.71 +/- 1.0 Hz, 16 %, on a replay-only
    record of a 7.5 Hz, 2 % frame)."""
    c = rf.cand
    if c.type != "payload_mode":
        return ""
    f, u = c.values(rf.theta)["frequency_hz"], unc.get("frequency_hz", math.inf)
    for e in entries:
        if e.get("type") == "payload_mode" and e.get("where") == c.where and abs(float(e["frequency_hz"]) - f) <= u:
            return (
                f"frequency_hz = {f:.4g} Hz: its 95 % interval holds the mode at {float(e['frequency_hz']):.4g} Hz "
                "already in the model (one mode, not two)"
            )
    return ""


#: the power law's exponent at which it is another law of the library (F = c |v|^a sign v)
NESTED_EXPONENTS = {"coulomb_friction": 0.0, "viscous_damping": 1.0}


def same_law(rf, unc: dict, entries: list) -> str:
    """Why a power-law damper (``power_damping``) is a law the model holds already at its
    place: its exponent's 95 % interval holds 0 beside a Coulomb friction there, or 1
    beside a viscous damper ('' when not). It would split one effect in two (measured on
    the worked example's replay-only record, one 2 s window: 882 N of Coulomb friction,
    then a power law of exponent 0.028 +/- 0.069 taking 204 N more, for 1200 N in all)."""
    c = rf.cand
    if c.type != "power_damping":
        return ""
    a, u = c.values(rf.theta)["exponent"], unc.get("exponent", 0.0)
    for e in entries:
        nested = NESTED_EXPONENTS.get(e.get("type"))
        if nested is not None and e.get("where") == c.where and "grows_with" not in e and abs(a - nested) <= u:
            return f"exponent = {a:.3g}: its 95 % interval holds {nested:g}, the {e['type']} already at {c.where}"
    return ""


def index_of(items: list, x) -> int:
    """Position of ``x`` itself in ``items`` (a dataclass's == compares arrays)."""
    return next(i for i, y in enumerate(items) if y is x)


def refit_at_bound(rf, windows, max_nfev: int):
    """The nested candidate of a refined one with a parameter at its bound (beside others):
    that parameter held there (:func:`fixed_candidate`), the rest refined again on the
    refinement ``windows`` (``(prs, base models, ctx)``, at most ``max_nfev`` evaluations); None when no parameter is at a
    bound or none would be left."""
    from sim.calibrate.acceptance import bound_hit
    from sim.calibrate.sensitivity import refine_job

    c = rf.cand
    for i in range(len(c.names)):
        side = bound_hit(float(rf.theta[i]), c.lower[i], c.upper[i], 1e-3 * abs(c.step[i]))
        c2 = fixed_candidate(c, i, float(c.lower[i] if side == "lower" else c.upper[i])) if side else None
        if c2 is not None:
            theta0 = np.delete(np.asarray(rf.theta, float), i)
            return refine_job((c2, theta0, *windows[:2], windows[2], max_nfev))
    return None


def fixed_candidate(c, i: int, value: float):
    """Candidate ``c`` with its parameter ``i`` held at ``value`` (its entry then carries it
    as a fixed key), or None where the rest cannot stand alone (one parameter; the
    transformed first parameter of a sensor low-pass or a foundation mode; a payload mode)."""
    import dataclasses

    if len(c.names) < 2 or c.grid is not None or (i == 0 and c.type in ("sensor_lowpass", "foundation_mode")):
        return None
    if c.type == "payload_mode":  # transformed parameters (log f) and no mode without its mass
        return None
    keep = [j for j in range(len(c.names)) if j != i]
    screened = tuple(keep.index(j) for j in c.screened if j != i)
    if not screened:
        return None
    return dataclasses.replace(
        c,
        names=tuple(c.names[j] for j in keep),
        neutral=c.neutral[keep],
        step=c.step[keep],
        lower=c.lower[keep],
        upper=c.upper[keep],
        screened=screened,
        fixed={**c.fixed, c.names[i]: value},
        line=None,
    )


def path_row(rnd, s, rf, unc, why, score=None) -> dict:
    c = (s or rf).cand
    theta = rf.theta if rf is not None else s.theta
    return {
        "round": rnd,
        "name": c.type,
        "where": c.where,
        "explained_fraction": rf.explained if rf is not None else s.score,
        "linearised_score": score if score is not None else s.score,
        "parameters": {**c.fixed, **c.values(theta)},
        **({"fixed": dict(c.fixed)} if c.fixed else {}),
        "uncertainty": unc or {},
        "holdout_error": None,
        "bic_change": None,
        "flatness": None,
        "accepted": False,
        "reason": why,
    }


__all__ = [
    "bic",
    "fixed_candidate",
    "judge_best_first",
    "judge_sensor",
    "judge_whole_runs",
    "param_check",
    "record_the_rest",
    "refit_at_bound",
    "path_row",
    "within_tolerance",
]
