"""``shaketable calibrate``: find what the declared model lacks in measured runs, add
it, prove it on held-out runs.

1. Residuals (:mod:`sim.calibrate.residuals`), on the path every run supports.
2. Trace (:mod:`sim.calibrate.trace`): every candidate (each effect law at each place
   it can act on this table) scored by the share of the fit runs' residual it explains.
3. Accept (:func:`accept`): the best-scoring candidate that passes every test: the
   held-out error falls by at least :data:`HOLDOUT_MARGIN`, the BIC improves, every
   parameter sits off its bounds with a finite 95 % confidence interval that excludes
   zero, and the residual is closer to white (spectral flatness rises). Repeated while
   one passes.
4. What is left: the residual's strongest spectral line, with its frequency, channel,
   place and share of the residual (:func:`unexplained`), reported, not papered over.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim.calibrate.residuals import CalibrationError

HOLDOUT_MARGIN = 0.05  #: the held-out NRMSE must fall by at least 5 % of itself
MAX_ROUNDS = 5
#: a spectral line is reported as unexplained when it holds this share of the residual
UNEXPLAINED_FRACTION = 0.1
Z95 = 1.96


@dataclass
class CalibrationResult:
    table: str
    table_source: str
    runs: list
    holdout: list
    holdout_note: str
    residual_path: str
    error_before: float
    error_after: float
    effects_added: list
    candidates: list
    unexplained: dict | None
    per_channel: dict  # holdout NRMSE per run and DOF, before and after
    timing: dict
    # arrays for the report (not in the JSON)
    series: dict = field(default_factory=dict, repr=False)

    def to_json(self) -> dict:
        keys = (
            "table",
            "runs",
            "holdout",
            "holdout_note",
            "residual_path",
            "error_before",
            "error_after",
            "effects_added",
            "candidates",
            "unexplained",
            "per_channel",
            "timing",
        )
        return {k: getattr(self, k) for k in keys}


# ------------------------------------------------------------------ inputs
def load_runs(paths, table=None):
    """Read the runs; check they share a table and a sample rate."""
    from sim.runs.runfile import read_run

    runs = [read_run(p) for p in paths]
    tables = {r.meta["table"] for r in runs}
    if table is None and len(tables) > 1:
        raise CalibrationError(
            f"runs come from different tables ({', '.join(sorted(tables))}): "
            "calibrate the runs of one table at a time (or give --table)"
        )
    rates = {float(r.sample_rate_hz) for r in runs}
    if len(rates) > 1:
        raise CalibrationError(
            f"{runs[-1].name}: sample rates differ between runs ({', '.join(f'{x:g}' for x in sorted(rates))} Hz); "
            "resample the runs to one rate"
        )
    return runs


def _check_names(paths, holdout):
    fit_names = {str(Path(p).resolve()) for p in paths}
    both = [h for h in holdout or [] if str(Path(h).resolve()) in fit_names]
    if both:
        raise CalibrationError(f"{both[0]}: is both a fit run and a --holdout run; hold out runs that are not fitted")


def check_effect_names(effects) -> None:
    """One-line error for a name in ``--effects`` that is no effect type."""
    from sim.calibrate.laws import LAWS
    from sim.effects.base import EFFECTS

    known = sorted(set(LAWS) | set(EFFECTS))
    bad = [e for e in effects or [] if e not in known]
    if bad:
        import difflib

        close = difflib.get_close_matches(bad[0], known, n=1)
        raise CalibrationError(
            f"--effects: unknown effect '{bad[0]}'"
            + (f" (did you mean '{close[0]}'?)" if close else f"; known: {', '.join(known)}")
        )


def candidate_laws(effects=None) -> list:
    """The laws to try: every law whose effect type is usable (see
    :func:`sim.calibrate.laws.usable`), or those named in ``effects``."""
    from sim.calibrate.laws import LAWS, NOT_ON_MECHANICAL, usable
    from sim.calibrate.timing import TIMING_EFFECTS

    if effects:
        check_effect_names(effects)
        nolaw = [e for e in effects if e not in LAWS and e not in TIMING_EFFECTS]
        if nolaw and nolaw[0] in NOT_ON_MECHANICAL:
            raise CalibrationError(
                f"--effects: '{nolaw[0]}' is not identifiable on the mechanical path: " + NOT_ON_MECHANICAL[nolaw[0]]
            )
        if nolaw:
            raise CalibrationError(
                f"--effects: '{nolaw[0]}' has no force law for the mechanical path; "
                f"the mechanical path can try {', '.join(sorted(LAWS))}"
            )
    # a name takes its variants too (coulomb_friction: also growing with the stroke or the load)
    return [LAWS[k] for k in sorted(LAWS) if usable(LAWS[k]) and (not effects or {k, LAWS[k].name} & set(effects))]


def load_effect_file(path) -> None:
    """Import a user's Python file that registers effects (``sim.effects.base.register``)."""
    import importlib.util

    p = Path(path)
    if not p.is_file():
        raise CalibrationError(
            f"{path}: effect file does not exist; give the path of a .py file that registers effects"
        )
    try:
        spec = importlib.util.spec_from_file_location(f"user_effects_{p.stem}", p)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    except Exception as e:  # a user's file: any failure is theirs to fix
        msg = str(e).splitlines()[0] if str(e) else type(e).__name__
        raise CalibrationError(
            f"{path}: effect file does not load ({type(e).__name__}: {msg}); fix it or leave it out"
        ) from None


def split_holdout(runs, holdout_runs):
    """Fit and held-out runs; with none given, every third run (from the second) is held
    out (one run: its last 30 %)."""
    if holdout_runs:
        return runs, holdout_runs, "given with --holdout"
    if len(runs) >= 2:
        ho = [r for i, r in enumerate(runs) if i % 3 == 1]
        fit = [r for i, r in enumerate(runs) if i % 3 != 1]
        return fit, ho, "held out (no --holdout): " + ", ".join(Path(r.name).name for r in ho)
    r = runs[0]
    cut = int(0.7 * r.n_samples)
    return (
        [_slice_run(r, 0, cut, "fit part")],
        [_slice_run(r, cut, r.n_samples, "held-out part")],
        f"held out (one run, no --holdout): the last 30 % of {Path(r.name).name} (from t = {r.t[cut]:.2f} s)",
    )


def _slice_run(r, a: int, b: int, label: str):
    """Samples [a, b) of a run, as a run of its own (named after the part)."""
    import dataclasses

    from sim.runs.runfile import CHANNELS

    kw = {c: (getattr(r, c)[a:b].copy() if getattr(r, c) is not None else None) for c in CHANNELS}
    out = dataclasses.replace(r, t=r.t[a:b].copy(), extras={}, **kw)
    out.path = f"{r.name} ({label})"
    return out


# ------------------------------------------------------------------ acceptance
def param_report(term, values: dict, sigma: dict) -> tuple[bool, str, dict]:
    """Are the parameters off their bounds with a finite 95 % interval excluding zero?"""
    unc = {name: Z95 * sigma.get(name, math.inf) for name in term.law.params}  # every one, also on a refusal
    for name, (unit, lo, hi) in term.law.params.items():
        v, s = values[name], sigma.get(name, math.inf)
        if not math.isfinite(s):
            return False, f"{name}: no finite confidence interval", unc
        tol = 1e-3 * max(abs(v), 1e-12)
        if (math.isfinite(lo) and v - lo <= tol) or (math.isfinite(hi) and hi - v <= tol) or not (lo <= v <= hi):
            return False, f"{name} = {v:.4g} {unit} at or beyond its bounds [{lo:g}, {hi:g}]", unc
        if name in term.law.shape:
            grid = term.law.shape[name]
            if v <= min(grid) + 1e-9 or v >= max(grid) - 1e-9:
                return False, f"{name} = {v:.4g} at the edge of its scanned range", unc
        elif abs(v) <= Z95 * s and len(term.law.linears) == 1:
            return False, f"{name} = {v:.4g} {unit}: its 95 % interval +/-{Z95 * s:.3g} includes zero", unc
    lin = term.law.linears
    if len(lin) > 1 and all(abs(values[k]) <= Z95 * sigma[k] for k in lin):
        # the components of one vector (a CG offset): one of them must differ from zero
        return False, f"{', '.join(lin)}: every 95 % interval includes zero", unc
    for name, (at, simpler) in getattr(term.law, "nested", {}).items():
        if abs(values[name] - at) <= Z95 * sigma.get(name, math.inf):
            return False, f"{name} = {values[name]:.4g} +/-{unc[name]:.3g} holds {at:g}: that is {simpler}", unc
    return True, "", unc


def accept(cur, new, e_ho_cur, e_ho_new, flat_cur, flat_new, term, margin=HOLDOUT_MARGIN):
    """``(accepted, reason, uncertainty)`` of adding ``term`` (fit ``new`` vs ``cur``)."""
    i = [t.key for t in new.terms].index(term.key)
    ok, why, unc = param_report(new.terms[i], new.values[i], new.sigma[i])
    if not ok:
        return False, why, unc
    ok, why = accept_numbers(e_ho_cur, e_ho_new, cur.bic, new.bic, flat_cur, flat_new, margin)
    return ok, why, unc


def accept_numbers(e_ho_cur, e_ho_new, bic_cur, bic_new, flat_cur, flat_new, margin=HOLDOUT_MARGIN):
    """``(accepted, reason)`` by the tests every path shares (parameters checked apart):
    held-out error down by ``margin`` of itself, BIC down, residual whiter."""
    if not e_ho_new <= (1 - margin) * e_ho_cur:
        return False, f"held-out error {e_ho_cur:.4f} -> {e_ho_new:.4f} falls by less than {100 * margin:g} %"
    if not bic_new < bic_cur:
        return False, f"BIC does not improve ({bic_cur:.1f} -> {bic_new:.1f})"
    if not flat_new > flat_cur:
        return False, f"residual no whiter (spectral flatness {flat_cur:.3f} -> {flat_new:.3f})"
    return True, ""


# ------------------------------------------------------------------ what is left
def unexplained(mruns, residuals, kind: str = "mechanical") -> dict | None:
    """The residual's strongest narrow spectral line (pooled over runs, per DOF): its
    frequency, channel, place and share of the residual power; None if no line holds
    :data:`UNEXPLAINED_FRACTION` of it."""
    from sim.calibrate.residuals import spectra

    best = None
    for j, d in enumerate(mruns[0].dofs):
        Ps, cohs, f = [], [], None
        for mr, e in zip(mruns, residuals):
            x = e[:, j]
            if not np.any(x):
                continue
            s = spectra(x, 1.0 / mr.dt, {"u": mr.u[:, j], "v": mr.v[:, j], "a": mr.a[:, j]})
            if f is not None and len(s["f"]) != len(f):
                continue
            f = s["f"]
            Ps.append(s["psd"])
            cohs.append(np.max([c for c in s["coherence"].values()], axis=0))
        if not Ps:
            continue
        P = np.mean(Ps, axis=0)
        C = np.mean(cohs, axis=0)
        k = int(np.argmax(P[1:]) + 1)
        w = slice(max(k - 2, 1), k + 3)
        frac = float(P[w].sum() / P[1:].sum())
        if best is None or frac > best["fraction_of_residual"]:
            coh = float(C[k])
            best = {
                "peak_hz": float(f[k]),
                "channel": "actuator_force",
                "where": f"dof:{d}" if coh >= 0.5 else "channel:actuator_force",
                "fraction_of_residual": frac,
                "coherence_with_motion": coh,
            }
    if best is None or best["fraction_of_residual"] < UNEXPLAINED_FRACTION:
        return None
    return best


# ------------------------------------------------------------------ the search
def calibrate(
    run_paths,
    *,
    table=None,
    payload=None,
    holdout=None,
    effects=None,
    effect_file=None,
    accel_lowpass_hz="table",
    margin: float = HOLDOUT_MARGIN,
    log=None,
    path: str | None = None,
    workers: int | None = None,
) -> CalibrationResult:
    """Calibrate ``table`` (default: the runs' table) against the runs; see the module
    docstring. ``path``: force a residual path (default: chosen by the channels every
    run has, :func:`sim.calibrate.residuals.choose_path`); ``workers``: processes of the
    replay and closed-loop searches (default: every core)."""
    import mjcf
    from sim.calibrate import timing
    from sim.calibrate.residuals import PATHS, check_path, choose_path, mechanical_runs, nrmse_runs, places
    from sim.calibrate.trace import Term, fit_terms, flatness, predict

    say = log or (lambda *_: None)
    t0 = time.perf_counter()
    if not run_paths:
        raise CalibrationError("no runs given: name the .run.npz files to calibrate against")
    _check_names(run_paths, holdout)
    if effect_file:
        load_effect_file(effect_file)
    check_effect_names(effects)
    if path is not None and path not in PATHS:
        raise CalibrationError(f"--path {path}: give one of {', '.join(PATHS)}")
    all_runs = load_runs(list(run_paths) + list(holdout or []), table)
    runs, ho_given = all_runs[: len(run_paths)], all_runs[len(run_paths) :]
    desc = mjcf.load_table(table or runs[0].meta["table"])
    for r in all_runs:
        if list(r.actuators) != list(desc.actuator_names):
            raise CalibrationError(
                f"{r.name}: actuators {r.actuators} do not match table '{desc.name}' "
                f"({list(desc.actuator_names)}); give --table"
            )
    pay = payload if payload is not None else runs[0].meta.get("payload")
    pl = mjcf.load_payload(pay) if pay and pay != "none" else None  # "none": the specimen is not declared
    path = check_path(all_runs, path) if path else choose_path(all_runs)
    if path != "mechanical":
        return _calibrate_path(all_runs[: len(run_paths)], ho_given, desc, pl, path, effects, margin, workers, say, t0)
    laws = candidate_laws(effects)
    if not effects:  # laws for a specimen that is there but not declared: only when told so
        laws = [w for w in laws if w.when == "always" or (w.when == "undeclared_specimen" and payload == "none")]
    lp = desc.accelerometer_bandwidth_hz if accel_lowpass_hz == "table" else accel_lowpass_hz
    if lp and lp >= 0.5 * runs[0].sample_rate_hz:
        lp = None  # the conditioner is above the recorder's Nyquist: it does not delay the record
    fit_runs, ho_runs, ho_note = split_holdout(runs, ho_given)
    t1 = time.perf_counter()
    mfit = mechanical_runs(fit_runs, desc, pl, accel_lowpass_hz=lp)
    mho = mechanical_runs(ho_runs, desc, pl, accel_lowpass_hz=lp)
    t2 = time.perf_counter()
    cur = fit_terms(mfit, [])
    e_ho0 = nrmse_runs(mho, predict(mho, cur))
    mfit0, mho0 = mfit, mho  # the declared timing: the "before" of the report
    e_ho = e_ho0
    flat = flatness(mfit, cur.residuals)
    say(f"{path} path: {len(fit_runs)} fit runs, {len(ho_runs)} held out; held-out NRMSE {e_ho0:.4f}")
    # a law of the actuators' own loads needs each actuator's force: a record with an
    # actuator's force zero throughout holds a total (the NEES-UCSD runs: column E the
    # measured total, W zero), not each actuator's own
    own_forces = not any(np.all(mr.extra["actuator_force"] == 0, axis=0).any() for mr in mfit)
    laws = [law for law in laws if own_forces or not law.load]
    cands = [
        (law, w)
        for law in laws
        for w in distinct_places(mfit[0], [p for p in places(desc, law.places, pl is not None) if law.acts_at(p)])
    ]
    tried, added, timed_added = [], [], []
    n_fits = 0
    for rnd in range(MAX_ROUNDS):
        scored = []
        for law, w in cands:
            # a law that repeats at a place (a specimen's modes) offers its next term there
            n_have = sum(1 for t in cur.terms if (t.law.type, t.where) == (law.type, w))
            if n_have >= getattr(law, "repeats", 1):
                continue
            if any((t.law.name, t.where) == (law.name, w) and t.law.type != law.type for t in cur.terms):
                continue  # one entry of an effect per place: a variant of one already there is not added beside it
            new = fit_terms(mfit, cur.terms + [Term(law, w, index=n_have)], refine="last")
            n_fits += 1
            scored.append((1.0 - new.rss / cur.rss if cur.rss > 0 else 0.0, law, w, new))
        rank = {"dof": 0, "class": 1, "actuator": 2}
        scored.sort(key=lambda s: (-round(s[0], 6), rank.get(s[2].split(":")[0], 3)))
        timed = timing.round_candidates(mfit, mho, cur, e_ho, flat, margin, effects, timed_added)
        accepted = None
        for expl, law, w, new in timing.merged(scored, timed):
            if law is None:  # a timing candidate (sim.calibrate.timing), fitted and judged already
                tried.append({"round": rnd, **new["row"]})
                say(timing.log_line(new["row"]))
                if new["accepted"]:
                    timed_added.append(timing.added_entry(new["row"]))
                    mfit, mho = new["mfit"], new["mho"]
                    accepted = (new["fit"], new["e_ho"], new["flat"])
                    break
                continue
            e_new = nrmse_runs(mho, predict(mho, new))
            f_new = flatness(mfit, new.residuals)
            term = new.terms[-1]  # the candidate: added last
            ok, why, unc = accept(cur, new, e_ho, e_new, flat, f_new, term, margin)
            i = len(new.terms) - 1
            tried.append(
                {
                    "round": rnd,
                    "name": law.name,
                    "where": w,
                    **({"options": dict(law.options)} if law.options else {}),
                    "explained_fraction": expl,
                    "parameters": new.values[i],
                    "uncertainty": unc,
                    "holdout_error": e_new,
                    "bic_change": new.bic - cur.bic,
                    "flatness": f_new,
                    "accepted": ok,
                    "reason": why,
                }
            )
            say(
                f"  {law.type:18s} {w:14s} explains {100 * expl:6.2f} %  held-out {e_new:.4f}"
                + ("  ACCEPTED" if ok else f"  ({why})")
            )
            if ok:
                accepted = (new, e_new, f_new)
                break
        if accepted is None:
            break
        cur = fit_terms(mfit, accepted[0].terms)  # every shape parameter again, with the new term in
        e_ho, flat = nrmse_runs(mho, predict(mho, cur)), flatness(mfit, cur.residuals)
    # Backward: a term accepted early may be superseded by later ones (viscous damping
    # standing in for friction the flatness test kept out until a specimen's mode was in):
    # drop a term whose removal keeps the held-out error within the acceptance margin.
    dropped = True
    while dropped and len(cur.terms) > 1:
        dropped = False
        for i, t in enumerate(cur.terms):
            rest = fit_terms(mfit, cur.terms[:i] + cur.terms[i + 1 :])
            n_fits += 1
            e_rest = nrmse_runs(mho, predict(mho, rest))
            if e_rest <= (1 + margin) * e_ho:
                why = (
                    f"dropped: without it the held-out error is {e_ho:.4f} -> {e_rest:.4f} (within {100 * margin:g} %)"
                )
                say(f"  {t.law.type:18s} {t.where:14s} {why}")
                expl = (rest.rss - cur.rss) / rest.rss if rest.rss > 0 else 0.0
                tried.append(
                    _backward_row(t, cur.values[i], {}, rest, cur, e_rest, expl, flatness(mfit, rest.residuals), why)
                )
                cur, e_ho, dropped = rest, e_rest, True
                break
    # A term whose nesting parameter ended at the simpler law's value once the later terms
    # were in (a load-growing friction that stood in for the damping, its coefficient now
    # 0 +/- its interval) is that simpler law: replaced by it (at the same place, named as
    # the simpler law's candidates name it), when the held-out error stays within the margin.
    from sim.calibrate.laws import LAWS

    demoted = True
    while demoted:
        demoted = False
        for i, t in enumerate(cur.terms):
            for name, (at, simpler) in t.law.nested.items():
                s95 = Z95 * cur.sigma[i].get(name, math.inf)
                if simpler not in LAWS or abs(cur.values[i][name] - at) > s95:
                    continue
                law2 = LAWS[simpler]
                w2 = _same_place(mfit[0], t.where, places(desc, law2.places, pl is not None))
                if w2 is None or any(
                    (u.law.name, u.where) == (law2.name, w2) for j, u in enumerate(cur.terms) if j != i
                ):
                    continue
                alt = fit_terms(mfit, cur.terms[:i] + [Term(law2, w2)] + cur.terms[i + 1 :])
                n_fits += 1
                e_alt = nrmse_runs(mho, predict(mho, alt))
                if e_alt > (1 + margin) * e_ho:
                    continue
                why = (
                    f"replaced by {simpler} at {w2}: {name} = {cur.values[i][name]:.4g} +/-{s95:.3g} holds {at:g} "
                    f"(held-out {e_ho:.4f} -> {e_alt:.4f})"
                )
                say(f"  {t.law.type:18s} {t.where:14s} {why}")
                unc95 = {k: Z95 * v for k, v in cur.sigma[i].items()}
                tried.append(
                    _backward_row(t, cur.values[i], unc95, alt, cur, e_alt, 0.0, flatness(mfit, alt.residuals), why)
                )
                cur, e_ho, demoted = alt, e_alt, True
                break
            if demoted:
                break
    for i, t in enumerate(cur.terms):
        _, _, unc = param_report(t, cur.values[i], cur.sigma[i])
        added.append(
            {
                "name": t.law.name,
                "where": t.where,
                **({"options": dict(t.law.options)} if t.law.options else {}),
                **({"label": f"{t.law.type} {t.index + 1}"} if getattr(t.law, "repeats", 1) > 1 else {}),
                "parameters": cur.values[i],
                "uncertainty": unc,
                "units": {k: u for k, (u, *_r) in t.law.params.items()},
            }
        )
    added += timed_added
    ho_res = predict(mho, cur)
    ho_res0 = [mr.residual for mr in mho0]
    per = {}
    for mr, e0, e1 in zip(mho, ho_res0, ho_res):
        for j, d in enumerate(mr.dofs):
            per[f"{Path(mr.name).name}:{d}"] = {"before": _nrmse_col(mr, e0, j), "after": _nrmse_col(mr, e1, j)}
    t3 = time.perf_counter()
    res = CalibrationResult(
        table=desc.name,
        table_source=str(desc.source),
        runs=[str(r.name) for r in runs],
        holdout=[str(r.name) for r in ho_runs],
        holdout_note=ho_note,
        residual_path=path,
        error_before=e_ho0,
        error_after=nrmse_runs(mho, ho_res),
        effects_added=added,
        candidates=tried,
        unexplained=unexplained(mfit, cur.residuals),
        per_channel=per,
        timing={
            "read_s": t1 - t0,
            "residuals_s": t2 - t1,
            "search_s": t3 - t2,
            "total_s": t3 - t0,
            "least_squares_fits": n_fits,
        },
        series={
            "fit": mfit,
            "holdout": mho,
            "before": ho_res0,
            "after": ho_res,
            "fit_before": [mr.residual for mr in mfit0],
            "fit_after": cur.residuals,
        },
    )
    return res


def _calibrate_path(runs, ho_given, desc, pl, path, effects, margin, workers, say, t0) -> CalibrationResult:
    """The replay / closed-loop search (:mod:`sim.calibrate.pathsearch`) as a result."""
    from sim.calibrate.pathsearch import calibrate_path

    t1 = time.perf_counter()
    timing: dict = {}
    out = calibrate_path(
        runs,
        ho_given,
        desc,
        pl,
        path,
        effects=effects,
        margin=margin,
        max_rounds=MAX_ROUNDS,
        workers=workers,
        say=say,
        timing=timing,
    )
    t2 = time.perf_counter()
    timing.update({"read_s": t1 - t0, "search_s": t2 - t1, "total_s": t2 - t0})
    return CalibrationResult(
        table=desc.name,
        table_source=str(desc.source),
        runs=[str(r.name) for r in runs],
        residual_path=path,
        timing=timing,
        **out,
    )


def _backward_row(t, values, unc, new, cur, e_new, explained, flat, why) -> dict:
    """The ``candidates`` row of a term the backward pass dropped or replaced (``new``:
    the fit without it or with its replacement, ``cur``: the fit before)."""
    return {
        "round": "backward",
        "name": t.law.name,
        "where": t.where,
        **({"options": dict(t.law.options)} if t.law.options else {}),
        "explained_fraction": explained,
        "parameters": values,
        "uncertainty": unc,
        "holdout_error": e_new,
        "bic_change": new.bic - cur.bic,
        "flatness": flat,
        "accepted": False,
        "reason": why,
    }


def _same_place(mr, where, wheres) -> str | None:
    """The first of ``wheres`` whose force maps into DOF space as ``where``'s does (on a
    uni-axial table ``dof:x`` for ``actuator:E``), else None."""
    m0 = np.atleast_2d(mr.place_motion(where)[3]).astype(float)
    m0 = m0 / (np.linalg.norm(m0) or 1.0)
    for w in wheres:
        m = np.atleast_2d(mr.place_motion(w)[3]).astype(float)
        m = m / (np.linalg.norm(m) or 1.0)
        if m.shape == m0.shape and min(np.abs(m - m0).max(), np.abs(m + m0).max()) < 1e-6:
            return w
    return None


def distinct_places(mr, wheres) -> list:
    """Places whose force maps into DOF space differently (a uni-axial table's actuators
    and classes all push along x: one place, ``dof:x``, stands for them)."""
    out, maps = [], []
    for w in wheres:
        m = np.atleast_2d(mr.place_motion(w)[3]).astype(float)
        m = m / (np.linalg.norm(m) or 1.0)
        if any(q.shape == m.shape and min(np.abs(q - m).max(), np.abs(q + m).max()) < 1e-6 for q in maps):
            continue
        maps.append(m)
        out.append(w)
    return out


def _nrmse_col(mr, e, j) -> float:
    F = mr.demean(mr.force)[mr.rows, j]
    den = float(np.sum(F**2))
    return float(math.sqrt(np.sum(e[mr.rows, j] ** 2) / den)) if den > 0 else float("nan")


# ------------------------------------------------------------------ outputs
def write_outputs(result: CalibrationResult, out, run_names) -> dict:
    """``calibration.json`` and ``<table>_calibrated.toml`` (the original with every
    comment kept and the accepted ``[[effect]]`` entries, sourced) into ``out``."""
    from sim.calibrate.description import TomlText
    from sim.runs.files import write_json_atomic

    out = Path(out)
    tag = "calibrated: shaketable calibrate " + " ".join(Path(p).name for p in run_names)
    doc = TomlText.read(result.table_source)
    for e in result.effects_added:
        opts = e.get("options", {})  # a variant of the effect (friction growing with the stroke)
        entry = {"type": e["name"], "where": e["where"], **opts, **e["parameters"], "source": tag}
        if "label" in e:  # one of several terms of a law at a place (a specimen's modes)
            entry = {"type": e["name"], "where": e["where"], "name": e["label"], **e["parameters"], "source": tag}
        comments = {
            k: f"+/-{e['uncertainty'][k]:.3g} {e['units'][k]} (95 %)"
            if k in e["uncertainty"]
            else "held at the description's value, not fitted"
            for k in e["parameters"]
        }
        doc.set_effect(entry, comments=comments)
    toml_path = out / f"{result.table}_calibrated.toml"
    doc.save(toml_path)
    js = result.to_json()
    js["calibrated_table_file"] = str(toml_path)
    write_json_atomic(out / "calibration.json", js)
    return js


__all__ = [
    "CalibrationResult",
    "HOLDOUT_MARGIN",
    "accept",
    "accept_numbers",
    "calibrate",
    "check_effect_names",
    "candidate_laws",
    "load_effect_file",
    "load_runs",
    "split_holdout",
    "unexplained",
    "write_outputs",
]
