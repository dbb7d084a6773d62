"""The effect search of ``shaketable calibrate`` on the replay and closed-loop paths.

Per round: the residual of the current model (the declared description plus the effects
accepted so far) on the fit runs; every candidate of the library
(:func:`sim.calibrate.sensitivity.candidates`) screened on short windows of the fit runs
(where they hold the most excitation, never their first seconds: :func:`search_windows`;
one replay per parameter, on the batch route of :func:`sim.calibrate.paths.simulate_many`);
the best few refined by nonlinear least squares on longer windows; then, best first,
each judged on the whole runs by the rules of the mechanical path
(:func:`sim.calibrate.search.accept_numbers`: held-out error down by the margin, BIC
down, parameters off their bounds with finite 95 % intervals that exclude the neutral
value, residual whiter). A sensor candidate, which changes only its own channel or
column of the model, is judged on those columns (:func:`judge_sensor`; pooled over the
18 columns of a 6-DOF table a clear error on one column moves the held-out error by less
than the margin). The first that passes is added; repeated while one passes. From the
second acceptance on, the accepted effects are refitted jointly and each earlier one is
dropped if the others do as well without it (:mod:`sim.calibrate.revisit`). A valve
null offset found on the replay path is reported as the valve's whole null, the path's
estimate plus the fitted correction (:func:`null_total`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

#: screening window (s): one window of the first fit run, where it holds the most
#: excitation (sim.calibrate.windows.choose; short: one replay per parameter)
SCREEN_S = 1.0
#: refinement windows (s): as much of every fit run, where it holds the most excitation
#: (a few least-squares iterations per candidate) ...
REFINE_S = 2.0
#: ... in this many segments on a run at least LONG_RECORD_S long, one in each part of the
#: REFINE_HORIZON_S after its quiet lead-in (each segment replays from the lead-in's end:
#: a horizon further out would cost a replay of everything before it)
REFINE_SEGMENTS = 2
LONG_RECORD_S = 20.0
REFINE_HORIZON_S = 4 * REFINE_S
#: candidates refined per round (the best by their linearised score) ...
N_REFINE = 3
#: ... plus the best of every other effect type and place kind among this many best screened
#: (a linearisation far from the model can rank a wrong type first: issue #13)
N_RIVALS_FROM = 20
#: a candidate whose linearised fit explains less than this share is not refined
MIN_SCORE = 0.05
MAX_NFEV = 6
#: the line search before the refinement: the screened parameter stepped this many screening
#: steps from its neutral value, towards the linearised estimate
LINE_STEPS = (1, 2, 4, 8)
#: a mode's line search: at each frequency of its scan, the linearised modal mass times
#: these. The mass is far from linear: 900 kg of a 1.5 t block on a 1.1 t table moved to a
#: 6 Hz mode changes the replay by twice the record (held-out NRMSE 2.06), and the
#: linearisation at a few kg ranked 21 Hz, 377 kg first (measured on the lab table,
#: tests/calibrate/test_payload_mode_paths.py)
MODE_MASS_STEPS = (1.0, 2.0, 4.0)
#: ... or, for a mode taken from a declared payload, these shares of the payload's mass
#: (every other frequency of the scan): the replay is steep in the mass (750 kg for 900 at
#: 6 Hz: NRMSE 0.65 against 0.10 on the screening window; 1050 kg at 1.05 Hz read 0.31)
MODE_MASS_SHARES = tuple(np.round(np.arange(0.05, 0.96, 0.05), 2))


def motion_rms(runs, desc, stat: str = "rms") -> dict:
    """place -> (u, v, a) RMS (``stat`` "peak": largest magnitude) of the recorded motion
    (from the table channels, else the reference), for the mechanical candidates' step
    sizes (and the plausibility test's forces)."""
    from mjcf.description import DOFS6
    from sim.control.tvc import dof_jacobian

    r = runs[0]
    fs = r.sample_rate_hz
    src = r.table_displacement if r.table_displacement is not None else r.reference
    u = np.asarray(src, float) - np.mean(src, axis=0) if src is not None else None
    v = (
        r.table_velocity
        if r.table_velocity is not None
        else (np.gradient(u, 1 / fs, axis=0) if u is not None else None)
    )
    a = r.table_acceleration if r.table_acceleration is not None else np.gradient(v, 1 / fs, axis=0)
    if u is None:
        u = np.cumsum(v - v.mean(0), axis=0) / fs
    six = [np.zeros((len(r.t), 6)) for _ in range(3)]
    for j, d in enumerate(r.dofs):
        for k, x in enumerate((u, v, a)):
            six[k][:, DOFS6.index(d)] = x[:, j]
    J = dof_jacobian(desc)
    out = {}

    def size(x):
        return np.max(np.abs(x), axis=0) if stat == "peak" else np.sqrt(np.mean(x**2, axis=0))

    rms = [size(x) for x in six]
    for d in desc.dofs:
        out[f"dof:{d}"] = tuple(float(x[DOFS6.index(d)]) for x in rms)
    stroke = [size(x @ J.T) for x in six]
    for i, name in enumerate(desc.actuator_names):
        out[f"actuator:{name}"] = tuple(float(x[i]) for x in stroke)
    for c in sorted({a_.cls.name for a_ in desc.actuators}):
        idx = [i for i, a_ in enumerate(desc.actuators) if a_.cls.name == c]
        out[f"class:{c}"] = tuple(float(np.max(x[idx]) if stat == "peak" else np.mean(x[idx])) for x in stroke)
    return out


def _split(runs, ho_given):
    """Fit and held-out runs; with one run, the held-out part is its last 30 % of the same
    replay (a replay cannot start mid-record: the state there is unknown)."""
    if ho_given:
        return runs, ho_given, {}, "given with --holdout"
    if len(runs) >= 2:
        ho = [r for i, r in enumerate(runs) if i % 3 == 1]
        fit = [r for i, r in enumerate(runs) if i % 3 != 1]
        return fit, ho, {}, "held out (no --holdout): " + ", ".join(Path(r.name).name for r in ho)
    from sim.calibrate.search import _slice_run

    r = runs[0]
    cut = int(0.7 * r.n_samples)
    note = (
        f"held out (one run, no --holdout): the last 30 % of {Path(r.name).name} (from t = {r.t[cut]:.2f} s; "
        "replayed from the start, scored after the cut)"
    )
    return [_slice_run(r, 0, cut, "fit part")], [r], {r.name: cut}, note


def _kind(where: str) -> str:
    """The kind of a place: dof, class, actuator, supply, channel or column (of a channel)."""
    kind = where.split(":", 1)[0]
    return "column" if kind == "channel" and "[" in where else kind


def to_refine(sc, n_top=N_REFINE, pool=N_RIVALS_FROM, min_score=MIN_SCORE) -> list:
    """The screened candidates to refine (``sc`` sorted best first): the ``n_top`` best by
    their linearised score, and the best of every other (effect type, kind of place) among
    the ``pool`` best, each explaining at least ``min_score``. The screening linearises at
    the current model; far from it, an effect whose response is strongly nonlinear in its
    parameter (a bulk modulus: the oil-column frequency goes as its root) ranks below a
    wrong one that is nearly linear (a flow gain), and only the refined fits, compared by
    the residual they leave, tell them apart. A sensor candidate (``own``: the share of
    the residual of the columns it acts on, which it alone changes) is also refined when it
    is the best of its (type, kind of place) by that share, at least ``min_score``."""
    ok = [s for s in sc if s.ok and s.score >= min_score]
    out = ok[:n_top]
    seen = {(s.cand.type, _kind(s.cand.where)) for s in out}
    for s in ok[:pool]:
        k = (s.cand.type, _kind(s.cand.where))
        if k not in seen:
            seen.add(k)
            out.append(s)
    # sensor candidates also by their own columns: one column of 18 is a small share of
    # the whole (Y1's load cell 5 % high: 2.3 %) but most of its own (43 %); the best of each
    # (sensor type, kind of place) by that share, at least min_score (clean CGS runs: <= 2.2 %)
    own = sorted((s for s in sc if s.ok and s.own is not None and s.own >= min_score), key=lambda s: -s.own)
    for s in own:
        k = (s.cand.type, _kind(s.cand.where))
        if k not in seen and all(s is not x for x in out):
            seen.add(k)
            out.append(s)
    return out


def line_search(top, prs, base_models, ctx, workers=None, counts=None) -> dict:
    """Starts of the refinement, by a coarse line search on the screening windows ``prs``:
    for each replayed one-parameter candidate (no valve delay: its grid is scanned in the
    refinement), the parameter at ``LINE_STEPS`` screening steps from its neutral value in
    the direction of the linearised estimate (clipped into its bounds), and the linearised
    estimate itself (a candidate with its own ``line`` of points: those); the point with
    the smallest residual starts the refinement. Far from
    the model the linearisation falls short of a strongly nonlinear effect (a bulk modulus
    stepped up 10 % from 1.0 GPa put 0.6 GPa at 0.96 GPa, where a local minimum of the
    residual held the least squares) and a local refinement from it stays there.
    Returns ``id(screen) -> {"start": theta, "tried": [(theta, rss), ...]}``."""
    from sim.calibrate import paths as P
    from sim.calibrate.sensitivity import _inside

    raw, src, payload, accepted = ctx
    pts, jobs = [], []
    for s in top:
        c = s.cand
        if c.scan is not None:  # a mode: every frequency of its scan at masses of its own (mode_points)
            cand_pts = [s.theta] + mode_points(s)
        elif c.sensor or c.grid is not None or (len(c.names) != 1 and c.line is None):
            continue
        elif c.line is not None:  # its own points (a foundation mode: a grid of frequencies through the band)
            cand_pts = [s.theta] + [_inside(c, np.array([x, *c.neutral[1:]])) for x in c.line]
        else:
            d = float(s.theta[0] - c.neutral[0])
            sign = math.copysign(1.0, d) if d != 0 else math.copysign(1.0, c.step[0])
            cand_pts = [s.theta] + [_inside(c, c.neutral + sign * k * abs(c.step)) for k in LINE_STEPS]
        for th in cand_pts:
            pts.append((s, th))
            jobs += [pr.job(raw, src, payload, list(accepted) + [c.entry(th)]) for pr in prs]
    if not jobs:
        return {}
    ms = P.simulate_many(jobs, workers=workers, counts=counts)
    out: dict = {}
    n = len(prs)
    for i, (s, th) in enumerate(pts):
        r = P.stacked(prs, ms[i * n : (i + 1) * n])
        rss = float(r @ r) if r is not None else math.inf
        e = out.setdefault(id(s), {"start": s.theta, "best": math.inf, "tried": []})
        e["tried"].append((th, rss))
        if rss < e["best"]:
            e["start"], e["best"] = th, rss
    return out


def mode_points(s) -> list:
    """A mode's line-search points: at each frequency of its scan, the modal mass at
    :data:`MODE_MASS_SHARES` of the most it may have (every other frequency) (a mode taken from a declared
    payload), else its linearised estimate there times :data:`MODE_MASS_STEPS`."""
    from sim.calibrate.sensitivity import _inside

    c = s.cand
    if np.isfinite(c.upper[0]):
        pts = [np.array([k * c.upper[0], *b[1:]]) for b in c.scan[::2] for k in MODE_MASS_SHARES]
    else:
        pts = [np.array([k * e[0], *e[1:]]) for e in s.estimates for k in MODE_MASS_STEPS]
    return [_inside(c, p) for p in pts]


def search_windows(pfit) -> tuple[list, list]:
    """The screening windows (the first fit run's) and the refinement windows (every fit
    run's), chosen by the excitation they hold (:meth:`sim.calibrate.paths.PathRun.window`),
    never by position: a record's first seconds may be its quiet lead-in."""
    wscr = [pfit[0].window(SCREEN_S)]
    wref = []
    for p in pfit:
        long = p.t[-1] >= LONG_RECORD_S
        wref += (
            p.windows(REFINE_S, segments=REFINE_SEGMENTS, horizon_s=REFINE_HORIZON_S) if long else [p.window(REFINE_S)]
        )
    return wscr, wref


def window_seconds(pfit, wscr, wref) -> dict:
    """The cost of the windows (replayed seconds per screening replay and per refinement
    evaluation, all windows) against the fixed first seconds they replace, and where they
    sit in their records (s)."""

    def fixed(s):
        return sum(min(s, float(p.t[-1])) for p in pfit)

    return {
        "screen_window_replay_s": sum(float(w.t[-1]) for w in wscr),
        "screen_window_replay_s_first_seconds": min(SCREEN_S, float(pfit[0].t[-1])),
        "refine_windows_replay_s": sum(float(w.t[-1]) for w in wref),
        "refine_windows_replay_s_first_seconds": fixed(REFINE_S),
        "windows": [
            {
                "run": Path(w.name).name,
                "stage": st,
                "replayed_from_s": float(w.origin[0] * w.dt),
                "scored_from_s": float(w.origin[1] * w.dt),
                "to_s": float(w.origin[2] * w.dt),
            }
            for st, ws in (("screen", wscr), ("refine", wref))
            for w in ws
        ],
    }


def _bic(rss, n, p) -> float:
    return n * math.log(max(rss, 1e-300) / n) + p * math.log(n)


@dataclass
class PathState:
    """The search's state on one path: the runs, the current model's channels and
    errors, what was accepted and tried, and the replays' counts and times."""

    path: str
    desc: object
    payload: object
    effects: object
    margin: float
    workers: object
    say: object
    pfit: list
    pho: list
    wscr: list
    wref: list
    ho_note: str
    mot: dict
    peaks: dict
    scale: object
    tm: dict = field(default_factory=dict)
    routes: dict = field(default_factory=lambda: {"batch": 0, "fallback": 0})
    items: list = field(default_factory=list)  # the accepted effects: {"cand", "theta", "unc"}, in order
    accepted: list = field(default_factory=list)  # their description entries
    dropped: set = field(default_factory=set)  # (type, where) dropped by a backward pass: not tried again
    tried: list = field(default_factory=list)
    models: dict = field(default_factory=dict)  # "fit", "ho", "scr", "ref": the current model's channels
    e_ho: float = math.nan
    rss: float = math.nan
    n_par: int = 0
    N: int = 0
    flat: float = math.nan

    @property
    def ctx(self) -> tuple:
        return (self.desc.raw, str(self.desc.source), self.payload, list(self.accepted))

    def simulate(self, prs_lists, extra) -> list:
        """The model with ``extra`` entries on every run of each list (one list each)."""
        from sim.calibrate import paths as P

        jobs = [p.job(self.desc.raw, str(self.desc.source), self.payload, extra) for prs in prs_lists for p in prs]
        t = time.perf_counter()
        ms = P.simulate_many(jobs, workers=self.workers, counts=self.routes)
        self.tm["simulate_s"] += time.perf_counter() - t
        self.tm["replays"] += len(jobs)
        out, k = [], 0
        for prs in prs_lists:
            out.append(ms[k : k + len(prs)])
            k += len(prs)
        return out


def calibrate_path(
    runs, ho_given, desc, payload, path, *, effects=None, margin, max_rounds, workers=None, say=None, timing=None
):
    """The search on ``path``; returns the fields of a
    :class:`sim.calibrate.search.CalibrationResult` as a dict."""
    st = _start(runs, ho_given, desc, payload, path, effects, margin, workers, say or (lambda *_: None))
    mho0, e_ho0 = st.models["ho"], st.e_ho
    for rnd in range(max_rounds):
        winner = _round(st, rnd)
        if winner is None:
            break
        _take(st, winner, rnd)
    return _outputs(st, mho0, e_ho0, timing)


def _start(runs, ho_given, desc, payload, path, effects, margin, workers, say) -> PathState:
    """The runs on ``path``, their windows, and the declared model's channels and errors."""
    from sim.calibrate import paths as P
    from sim.calibrate.acceptance import table_scale
    from sim.calibrate.residuals import CalibrationError

    fit_runs, ho_runs, score_from, ho_note = _split(runs, ho_given)
    pfit = P.path_runs(fit_runs, desc, path, payload=payload)  # payload: its specimen sensors compared
    pho = P.path_runs(ho_runs, desc, path, score_from=score_from, payload=payload)
    wscr, wref = search_windows(pfit)
    st = PathState(
        path,
        desc,
        payload,
        effects,
        margin,
        workers,
        say,
        pfit,
        pho,
        wscr,
        wref,
        ho_note,
        mot=motion_rms(runs, desc),
        peaks=motion_rms(runs, desc, stat="peak"),  # the plausibility test's recorded motion
        scale=table_scale(desc, payload),
    )
    st.tm = {"simulate_s": 0.0, "screen_s": 0.0, "refine_s": 0.0, "accept_s": 0.0, "replays": 0}
    st.tm.update(window_seconds(pfit, wscr, wref))
    mfit, mho, mscr, mref = st.simulate([pfit, pho, wscr, wref], [])
    for p, m in zip(pfit + pho, mfit + mho):
        if m is None:
            raise CalibrationError(
                f"{p.name}: the declared model's {path.replace('_', '-')} run diverged or stopped early; "
                "check the table description against the run (valve map, controller, payload)"
            )
    st.models = {"fit": mfit, "ho": mho, "scr": mscr, "ref": mref}
    st.e_ho = P.nrmse(pho, mho)
    r = P.stacked(pfit, mfit)
    st.N, st.rss, st.flat = len(r), float(r @ r), P.flatness(pfit, mfit)
    say(f"{path} path: {len(pfit)} fit runs, {len(pho)} held out; held-out NRMSE {st.e_ho:.4f}")
    return st


def _round(st: PathState, rnd: int):
    """One round: screen every candidate, refine the best, judge them best first; the
    winner (``(refined, unc, mfit, mho, e_ho, rss, n_par, flat)``) or None."""
    from sim.calibrate.sensitivity import candidates, screen

    cands = [
        c for c in candidates(st.desc, st.payload, st.wscr, st.accepted, st.mot, st.effects) if c.key not in st.dropped
    ]
    t = time.perf_counter()
    sc = screen(cands, st.wscr, st.models["scr"], st.ctx, workers=st.workers, say=st.say, counts=st.routes)
    st.tm["screen_s"] += time.perf_counter() - t
    st.tm["replays"] += sum(len(c.screened) * len(c.scan or (0,)) for c in cands if not c.sensor) * len(st.wscr)
    sc.sort(key=lambda s: -s.score)
    top = to_refine(sc)
    st.say("  best by sensitivity: " + ", ".join(f"{s.cand.type} {s.cand.where} {100 * s.score:.1f} %" for s in top))
    if not top:
        for s in sc[:5]:
            st.tried.append(_row(rnd, s, None, None, f"explains less than {100 * MIN_SCORE:g} % (linearised)"))
        return None
    refined = _refine(st, top)
    winner = _judge_best_first(st, rnd, top, refined)
    _record_the_rest(st, rnd, sc, top, refined, winner)
    return winner


def _refine(st: PathState, top) -> list:
    """The line search, then the refinement of each of ``top``, best explained first."""
    from sim.calibrate.sensitivity import refine_job
    from sim.calibrate.sensortiming import prefer_timing
    from sim.parallel import map_jobs

    t = time.perf_counter()
    wscr, mscr, ctx = st.wscr, st.models["scr"], st.ctx
    starts = line_search(top, wscr, mscr, ctx, workers=st.workers, counts=st.routes)
    n_line = sum(len(v["tried"]) for v in starts.values())
    st.tm["replays"] += n_line * len(wscr)
    st.tm["line_search_replays"] = st.tm.get("line_search_replays", 0) + n_line
    jobs = [
        (s.cand, starts.get(id(s), {}).get("start", s.theta), st.wref, st.models["ref"], ctx, MAX_NFEV) for s in top
    ]
    for s in top:
        if id(s) in starts and starts[id(s)]["start"] is not s.theta:
            st.say(f"  line search: {s.cand.type} {s.cand.where} starts at {s.cand.values(starts[id(s)]['start'])}")
    sens = [j for j in jobs if j[0].sensor]
    mods = [j for j in jobs if not j[0].sensor]
    ref = {id(j): refine_job(j) for j in sens}
    for j, rf in zip(mods, map_jobs(refine_job, mods, workers=st.workers)):
        ref[id(j)] = rf
    refined = sorted((ref[id(j)] for j in jobs), key=lambda rf: -rf.explained)
    # a delay or a conditioner first (sim.calibrate.sensortiming)
    refined = prefer_timing(refined, st.pho, st.models["ho"], st.margin, st.say)
    st.tm["refine_s"] += time.perf_counter() - t
    st.say(
        "  refined: "
        + ", ".join(
            f"{rf.cand.type} {rf.cand.where} {rf.cand.values(rf.theta)} {100 * rf.explained:.1f} %" for rf in refined
        )
    )
    return refined


def _judge_best_first(st: PathState, rnd: int, top, refined):
    """Each refined candidate, best first, on the whole runs (a nested refit is judged
    right after the one it comes from); the first that passes, or None."""
    from sim.calibrate.acceptance import implausible_candidate

    for rf in refined:
        sc_of = next(s.score for s in top if s.cand.key == rf.cand.key)
        if not rf.ok:
            st.tried.append(_row(rnd, None, rf, None, rf.why, score=sc_of))
            continue
        bad = implausible_candidate(rf.cand, rf.cand.values(rf.theta), st.scale, st.peaks)
        if bad:  # refused before its whole-run replay: it stands in for something else
            st.tried.append({**_row(rnd, None, rf, None, bad, score=sc_of), "compensation": True})
            st.say(f"  {rf.cand.type:20s} {rf.cand.where:26s} ({bad})")
            continue
        nested = refit_at_bound(rf, (st.wref, st.models["ref"], st.ctx))
        if nested is not None:  # judged right after it: its parameter held at the bound
            refined.insert(_index(refined, rf) + 1, nested)
        winner = _judge_whole_runs(st, rnd, rf, sc_of)
        if winner is not None:
            return winner
    return None


def _judge_whole_runs(st: PathState, rnd: int, rf, sc_of):
    """One refined candidate judged on the whole fit and held-out runs; the winner tuple
    when it passes, else None (its row in ``st.tried`` either way)."""
    from sim.calibrate import paths as P
    from sim.calibrate.search import Z95, accept_numbers
    from sim.calibrate.sensitivity import sensor_model

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
        st.tried.append(_row(rnd, None, rf, None, "the whole-run replay diverged", score=sc_of))
        return None
    e_new, rss_new, p_new, f_new = P.nrmse(pho, mh), float(rn @ rn), st.n_par + len(rf.theta), P.flatness(pfit, mf)
    okp, why, unc = param_check(rf, Z95)
    bics = (_bic(st.rss, st.N, st.n_par), _bic(rss_new, st.N, p_new))
    local = None
    if not okp:
        ok = False
    elif rf.cand.sensor:  # judged on the columns it acts on
        cur = (st.models["fit"], st.models["ho"])
        ok, why, local = judge_sensor(rf.cand, pfit, pho, cur, (mf, mh), bics, st.margin)
    else:
        ok, why = accept_numbers(st.e_ho, e_new, *bics, st.flat, f_new, st.margin)
    row = _row(rnd, None, rf, unc, why, score=sc_of)
    if local is not None:
        row["on_its_columns"] = local
    row.update({"holdout_error": e_new, "bic_change": bics[1] - bics[0], "flatness": f_new, "accepted": ok})
    st.tried.append(row)
    st.say(
        f"  {rf.cand.type:20s} {rf.cand.where:26s} explains {100 * rf.explained:6.2f} %  held-out {e_new:.4f}"
        + ("  ACCEPTED" if ok else f"  ({why})")
    )
    return (rf, unc, mf, mh, e_new, rss_new, p_new, f_new) if ok else None


def _record_the_rest(st: PathState, rnd: int, sc, top, refined, winner) -> None:
    """The rows of the refined candidates after the winner and of the next screened ones,
    for the record, with their linearised scores on their own columns."""
    if winner is not None:
        for rf in refined[_index(refined, winner[0]) + 1 :]:
            sc_of = next(s.score for s in top if s.cand.key == rf.cand.key)
            why = f"refined, not judged: {winner[0].cand.type} {winner[0].cand.where} explains more and passed"
            st.tried.append(_row(rnd, None, rf, None, why if rf.ok else rf.why, score=sc_of))
    for s in [s for s in sc if all(s is not x for x in top)][:10]:  # the next ones by score, for the record
        st.tried.append(_row(rnd, s, None, None, "not refined (lower linearised score)"))
    own_of = {s.cand.key: s.own for s in sc if s.own is not None}
    for row in st.tried:
        if row["round"] == rnd and (row["name"], row["where"]) in own_of:
            row["linearised_score_own_columns"] = own_of[(row["name"], row["where"])]


def _take(st: PathState, winner, rnd: int) -> None:
    """The winner added to the model; from the second on, the accepted effects revisited
    (joint refit, backward pass: :mod:`sim.calibrate.revisit`); the windows replayed."""
    from sim.calibrate.acceptance import implausible_candidate
    from sim.calibrate.revisit import revisit_accepted

    rf, unc, mfit, mho, st.e_ho, st.rss, st.n_par, st.flat = winner
    st.models.update(fit=mfit, ho=mho)
    st.items.append({"cand": rf.cand, "theta": np.array(rf.theta, float), "unc": unc})
    if len(st.items) >= 2:
        t = time.perf_counter()
        keys = ("mfit", "mho", "e_ho", "rss", "n_par", "flat")
        state = dict(zip(keys, (mfit, mho, st.e_ho, st.rss, st.n_par, st.flat)))
        ctx_r = (st.pfit, st.pho, st.wref, st.ctx[:3], st.N, st.margin, st.workers, st.routes)
        plaus = lambda c, v: implausible_candidate(c, v, st.scale, st.peaks)  # noqa: E731
        st.items, state, rows = revisit_accepted(st.items, state, ctx_r, rnd, st.say, implausible=plaus)
        mfit, mho, st.e_ho, st.rss, st.n_par, st.flat = (state[k] for k in keys)
        st.models.update(fit=mfit, ho=mho)
        st.tried.extend(rows)
        st.dropped |= {(r["name"], r["where"]) for r in rows if r["revisited"] == "dropped"}
        st.tm["revisit_s"] = st.tm.get("revisit_s", 0.0) + time.perf_counter() - t
        st.tm["revisit_replays"] = st.tm.get("revisit_replays", 0) + state["replays"]
        st.tm["replays"] += state["replays"]
    st.accepted = [a["cand"].entry(a["theta"]) for a in st.items]
    st.models["scr"], st.models["ref"] = st.simulate([st.wscr, st.wref], st.accepted)


def _outputs(st: PathState, mho0, e_ho0, timing) -> dict:
    """The fields of a :class:`sim.calibrate.search.CalibrationResult`."""
    from sim.calibrate import paths as P
    from sim.calibrate.search import UNEXPLAINED_FRACTION

    per, per_run, quiet = path_errors(st.pho, mho0, st.models["ho"])
    if timing is not None:
        timing.update(st.tm)
        timing["replays_batch"], timing["replays_fallback"] = st.routes["batch"], st.routes["fallback"]
    return {
        "holdout": [str(p.name) for p in st.pho],
        "holdout_note": st.ho_note,
        "error_before": e_ho0,
        "error_after": st.e_ho,
        "effects_added": [_found(a, st.path, st.pfit, st.desc) for a in st.items],
        "candidates": st.tried,
        "unexplained": P.unexplained(st.pfit, st.models["fit"], UNEXPLAINED_FRACTION),
        "per_channel": per,
        "per_run": per_run,
        "not_excited": quiet,
        "series": {
            "kind": "path",
            "holdout": st.pho,
            "before": mho0,
            "after": st.models["ho"],
            "fit": st.pfit,
            "fit_after": st.models["fit"],
        },
    }


def path_errors(pho, before, after) -> tuple[dict, dict, list]:
    """Where the held-out error sits: per run and compared column (``"<run>:<channel>[<place>]"``
    -> before/after), per run (pooled), and the ``"<run>:<channel>[<place>]"`` the runs do
    not excite (:attr:`sim.calibrate.paths.PathRun.not_excited`), left out of both."""
    from sim.calibrate import paths as P

    per, per_run, quiet = {}, {}, []
    for p, m0, m1 in zip(pho, before, after):
        run = Path(p.name).name
        per_run[run] = {"before": P.nrmse([p], [m0]), "after": P.nrmse([p], [m1])}
        e0, e1 = P.column_errors(p, m0), P.column_errors(p, m1)
        for k in e0:
            per[f"{run}:{k}"] = {"before": e0[k], "after": e1[k]}
        quiet += [f"{run}:{ch}[{place}]" for ch, places in p.not_excited.items() for place in places]
    return per, per_run, quiet


def _found(a, path, pfit, desc) -> dict:
    """The ``effects_added`` entry of an accepted effect ``{"cand", "theta", "unc"}``."""
    c, th, unc = a["cand"], a["theta"], a["unc"]
    found = {
        "name": c.type,
        "where": c.where,
        "parameters": {**c.fixed, **c.values(th)},
        "uncertainty": unc,
        "units": dict(c.units),
        **({"fixed": dict(c.fixed)} if c.fixed else {}),
    }
    if path == "replay" and c.type == "valve_null_offset":
        found.update(null_total(c, th, unc, pfit, desc))
    return found


def null_total(cand, theta, unc, pfit, desc) -> dict:
    """A valve null offset found on the replay path, as the valve's whole null: the replay
    drives the model with the command plus each run's null estimate
    (:mod:`sim.calibrate.valve_null`, in place of the declared null), and the candidate
    adds its correction ``theta - declared``. The whole null is the estimate (mean over the
    fit runs and the place's actuators) plus that correction; its 95 % half-width adds the
    estimate's spread over the fit runs to the correction's in quadrature."""
    from hydraulics.params import HydraulicParams
    from sim.calibrate.search import Z95
    from sim.calibrate.valve_null import declared_null
    from sim.effects.base import EFFECTS
    from sim.effects.hydraulic import actuator_indices

    names = list(desc.actuator_names)
    idx = actuator_indices(EFFECTS[cand.type](cand.entry(theta)), HydraulicParams.from_table(desc.raw))
    per_run = [float(np.mean([pr.valve_null["offset"][names[i]] for i in idx])) for pr in pfit]
    est = float(np.mean(per_run))
    spread = float(np.std(per_run, ddof=1)) / math.sqrt(len(per_run)) if len(per_run) > 1 else 0.0
    corr = float(theta[0]) - float(np.mean(declared_null(desc)[idx]))
    return {
        "parameters": {"offset": est + corr},
        "uncertainty": {"offset": math.hypot(unc["offset"], Z95 * spread)},
        "note": (
            f"the valve's whole null: {est:.4g} estimated from the recorded motion (mean over the fit runs) "
            f"{'+' if corr >= 0 else '-'} {abs(corr):.3g} fitted by the search"
        ),
    }


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
    from sim.calibrate.search import accept_numbers
    from sim.calibrate.sensitivity import acts_on

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
    return True, "", unc


def _index(items: list, x) -> int:
    """Position of ``x`` itself in ``items`` (a dataclass's == compares arrays)."""
    return next(i for i, y in enumerate(items) if y is x)


def refit_at_bound(rf, windows):
    """The nested candidate of a refined one with a parameter at its bound (beside others):
    that parameter held there (:func:`fixed_candidate`), the rest refined again on the
    refinement ``windows`` (``(prs, base models, ctx)``); None when no parameter is at a
    bound or none would be left."""
    from sim.calibrate.acceptance import bound_hit
    from sim.calibrate.sensitivity import refine_job

    c = rf.cand
    for i in range(len(c.names)):
        side = bound_hit(float(rf.theta[i]), c.lower[i], c.upper[i], 1e-3 * abs(c.step[i]))
        c2 = fixed_candidate(c, i, float(c.lower[i] if side == "lower" else c.upper[i])) if side else None
        if c2 is not None:
            theta0 = np.delete(np.asarray(rf.theta, float), i)
            return refine_job((c2, theta0, *windows[:2], windows[2], MAX_NFEV))
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


def _row(rnd, s, rf, unc, why, score=None) -> dict:
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


__all__ = ["calibrate_path", "judge_sensor", "motion_rms", "null_total", "param_check", "to_refine"]
