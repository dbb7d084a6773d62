"""The replay and closed-loop paths' steps of the one search (:class:`PathState`, a
:class:`sim.calibrate.engine.SearchPath` driven by :func:`sim.calibrate.engine.search`).

Per round: every candidate of the library (:func:`sim.calibrate.sensitivity.candidates`)
screened against the current model (the declared description plus the effects accepted
so far) on short windows of the fit runs (where they hold the most excitation, never
their first seconds: :func:`search_windows`; one replay per parameter, on the batch
route of :func:`sim.calibrate.paths.simulate_many`); the best few chosen
(:func:`to_refine`) and refined by nonlinear least squares on longer windows, each from a
line search (:func:`line_search`); then judged best first on the whole runs
(:mod:`sim.calibrate.pathjudge`: the rules of :mod:`sim.calibrate.acceptance`; a sensor
candidate on the columns it acts on). The first that passes is added; from the second
acceptance on, the accepted effects are refitted jointly and each earlier one is dropped
if the others do as well without it (:mod:`sim.calibrate.revisit`). A valve null offset
found on the replay path is reported as the valve's whole null, the path's estimate plus
the fitted correction (:func:`null_total`).
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
#: a horizon further out would cost a replay of everything before it). From three windows'
#: length on: on a 10 s earthquake record (3 s quiet) of a friction table carrying a
#: two-storey frame, replay only, one 2 s window let a friction fitted before the frame's
#: first mode stay 26 % low (the joint refit raised the held-out error) and a power-law
#: damper took the rest; two 1 s segments found 1118 N and both modes (held out 15.6 % ->
#: 6.9 %; tests/runs/test_lab_replay_only.py)
REFINE_SEGMENTS = 2
LONG_RECORD_S = 3 * REFINE_S
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
    if desc.supports is not None:  # each support's vertical travel, each shoe's slides
        from sim.calibrate.residuals import shoe_jacobian, support_jacobian

        for place, Js in (("supports", support_jacobian(desc)), ("shoes", shoe_jacobian(desc))):
            travel = [size(x[:, [DOFS6.index(d) for d in desc.dofs]] @ Js.T) for x in six]
            out[place] = tuple(float(np.max(x) if stat == "peak" else np.mean(x)) for x in travel)
    return out


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


@dataclass
class PathState:
    """The replay or closed-loop path's steps of the search
    (:class:`sim.calibrate.engine.SearchPath`) and its state: the runs and windows, the
    current model's channels and errors, what was accepted and tried, the replays'
    counts and times, and the declared model's held-out channels and error (the "before")."""

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
    declared: tuple = ()  # (held-out channels, held-out NRMSE) of the declared model
    undeclared: bool = False  # a specimen stands on the table undeclared (--payload none)
    timing: dict | None = None  # filled with tm and the replays' routes by outputs()
    #: the accepted effects are revisited after every acceptance (from the second on)
    revisit_every_round = True
    max_nfev = MAX_NFEV

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

    def screen(self, rnd: int) -> list:
        """Every candidate not dropped, screened on the screening window (one replay per
        parameter, :func:`sim.calibrate.sensitivity.screen`), best linearised score first."""
        from sim.calibrate.sensitivity import candidates, screen

        cands = candidates(
            self.desc, self.payload, self.wscr, self.accepted, self.mot, self.effects, undeclared=self.undeclared
        )
        cands = [c for c in cands if c.key not in self.dropped]
        t = time.perf_counter()
        sc = screen(
            cands, self.wscr, self.models["scr"], self.ctx, workers=self.workers, say=self.say, counts=self.routes
        )
        self.tm["screen_s"] += time.perf_counter() - t
        self.tm["replays"] += sum(len(c.screened) * len(c.scan or (0,)) for c in cands if not c.sensor) * len(self.wscr)
        sc.sort(key=lambda s: -s.score)
        return sc

    def choose(self, sc: list, rnd: int) -> list:
        """The screened candidates to refine (:func:`to_refine`); none: the best few's rows."""
        from sim.calibrate.pathjudge import path_row

        top = to_refine(sc)
        self.say(
            "  best by sensitivity: " + ", ".join(f"{s.cand.type} {s.cand.where} {100 * s.score:.1f} %" for s in top)
        )
        if not top:
            for s in sc[:5]:
                self.tried.append(
                    path_row(rnd, s, None, None, f"explains less than {100 * MIN_SCORE:g} % (linearised)")
                )
        return top

    def refine(self, top: list, rnd: int) -> list:
        """The line search and the least squares of each of ``top`` (:func:`_refine`)."""
        return _refine(self, top) if top else []

    def judge(self, top: list, refined: list, rnd: int):
        """Best refined first on the whole runs (:func:`sim.calibrate.pathjudge.judge_best_first`);
        the winner ``(refined, unc, mfit, mho, e_ho, rss, n_par, flat)`` or None."""
        from sim.calibrate.pathjudge import judge_best_first

        return judge_best_first(self, rnd, top, refined) if top else None

    def record(self, sc: list, top: list, refined: list, winner, rnd: int) -> None:
        """The rows of the refined candidates after the winner and of the next screened ones."""
        from sim.calibrate.pathjudge import record_the_rest

        if top:
            record_the_rest(self, rnd, sc, top, refined, winner)

    def take(self, winner, rnd: int) -> None:
        """The winner added to the model (its whole-run channels and numbers are the model's)."""
        rf, unc, mfit, mho, self.e_ho, self.rss, self.n_par, self.flat = winner
        self.models.update(fit=mfit, ho=mho)
        self.items.append({"cand": rf.cand, "theta": np.array(rf.theta, float), "unc": unc})

    def revisit(self, rnd: int) -> None:
        """From the second acceptance on, the accepted effects revisited (:func:`_revisit`);
        then the current model's windows replayed for the next round."""
        if len(self.items) >= 2:
            _revisit(self, rnd)
        self.accepted = [a["cand"].entry(a["theta"]) for a in self.items]
        self.models["scr"], self.models["ref"] = self.simulate([self.wscr, self.wref], self.accepted)

    def outputs(self) -> dict:
        """The fields of a :class:`sim.calibrate.search.CalibrationResult` (:func:`_outputs`)."""
        return _outputs(self, *self.declared, self.timing)


def calibrate_path(
    runs,
    ho_given,
    desc,
    payload,
    path,
    *,
    effects=None,
    margin,
    max_rounds,
    workers=None,
    say=None,
    timing=None,
    undeclared=False,
):
    """The search on ``path`` (:func:`sim.calibrate.engine.search`); returns the fields of a
    :class:`sim.calibrate.search.CalibrationResult` as a dict. ``undeclared``: a specimen
    stands on the table undeclared (``--payload none``): its modes are candidates."""
    from sim.calibrate.engine import search

    st = _start(runs, ho_given, desc, payload, path, effects, margin, workers, say or (lambda *_: None))
    st.declared, st.timing, st.undeclared = (st.models["ho"], st.e_ho), timing, undeclared
    return search(st, max_rounds)


def _start(runs, ho_given, desc, payload, path, effects, margin, workers, say) -> PathState:
    """The runs on ``path``, their windows, and the declared model's channels and errors."""
    from sim.calibrate import paths as P
    from sim.calibrate.acceptance import table_scale
    from sim.calibrate.holdout import split_for_replay
    from sim.calibrate.residuals import CalibrationError

    fit_runs, ho_runs, score_from, ho_note = split_for_replay(runs, ho_given)
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


def _revisit(st: PathState, rnd: int) -> None:
    """The accepted effects refitted jointly and each earlier one dropped if the others do
    as well without it (:func:`sim.calibrate.revisit.revisit_accepted`); a refit that takes
    an effect where the table cannot have it is not kept."""
    from sim.calibrate.acceptance import implausible_candidate
    from sim.calibrate.revisit import revisit_accepted

    t = time.perf_counter()
    keys = ("mfit", "mho", "e_ho", "rss", "n_par", "flat")
    state = dict(zip(keys, (st.models["fit"], st.models["ho"], st.e_ho, st.rss, st.n_par, st.flat)))
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


def _outputs(st: PathState, mho0, e_ho0, timing) -> dict:
    """The fields of a :class:`sim.calibrate.search.CalibrationResult`."""
    from sim.calibrate import offsets
    from sim.calibrate import paths as P
    from sim.calibrate.residuals import UNEXPLAINED_FRACTION

    per, per_run, quiet = path_errors(st.pho, mho0, st.models["ho"])
    zeros, zero_rows = [], []
    if st.effects is None or "sensor_offset" in st.effects:  # what the records' zeros share
        zeros, zero_rows = offsets.judged(st.pfit, st.models["fit"], st.pho, st.models["ho"], st.margin)
    if timing is not None:
        timing.update(st.tm)
        timing["replays_batch"], timing["replays_fallback"] = st.routes["batch"], st.routes["fallback"]
    return {
        "holdout": [str(p.name) for p in st.pho],
        "holdout_note": st.ho_note,
        "error_before": e_ho0,
        "error_after": st.e_ho,
        "effects_added": [_found(a, st.path, st.pfit, st.desc) for a in st.items] + zeros,
        "candidates": st.tried + zero_rows,
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
    -> before/after, the record's noise floor, :func:`sim.calibrate.paths.column_floors`,
    and the column's weight in the pooled error, :func:`sim.calibrate.paths.column_weights`),
    per run (pooled), and the ``"<run>:<channel>[<place>]"`` the runs do
    not excite (:attr:`sim.calibrate.paths.PathRun.not_excited`), left out of both."""
    from sim.calibrate import paths as P

    per, per_run, quiet = {}, {}, []
    for p, m0, m1 in zip(pho, before, after):
        run = Path(p.name).name
        per_run[run] = {"before": P.nrmse([p], [m0]), "after": P.nrmse([p], [m1])}
        e0, e1, floor, w = P.column_errors(p, m0), P.column_errors(p, m1), P.column_floors(p), P.column_weights(p)
        for k in e0:
            per[f"{run}:{k}"] = {"before": e0[k], "after": e1[k], "floor": floor[k], "weight": w[k]}
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
    from sim.calibrate.acceptance import Z95
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


__all__ = ["PathState", "calibrate_path", "motion_rms", "null_total", "to_refine"]
