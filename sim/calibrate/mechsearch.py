"""The mechanical path on the search engine (:func:`sim.calibrate.engine.search`).

The residual is the recorded generalised force minus the declared model's force for the
recorded motion (:func:`sim.calibrate.residuals.mechanical_runs`); each candidate law is a
least-squares term of it (:mod:`sim.calibrate.trace`). :class:`MechStage` gives the
engine the path's steps: every candidate fitted with the current terms (its screening
is its least-squares fit, shape parameters refined) beside the sensor timing
candidates (:mod:`sim.calibrate.timing`), judged best explained first
(:func:`sim.calibrate.mechjudge.forward_round`), and, after the last round, two
backward passes (:func:`backward_pass`, :func:`demote_nested`).
:func:`mechanical_stage` returns a :class:`sim.calibrate.search.CalibrationResult`
without its baseline.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim.calibrate.residuals import CalibrationError

#: passes at most of refitting the accepted sensor timing and the terms in turn after a
#: term is added (a mode's frequency and the force's delay move together; 2-3 settle them
#: on the worked example's records)
TIMING_PASSES = 4


def accel_lowpass(desc, accel_lowpass_hz, rate_hz: float):
    """The accelerometer conditioner the records went through: the table's (``"table"``)
    or the one given; None above the recorder's Nyquist (it does not delay the record)."""
    lp = desc.accelerometer_bandwidth_hz if accel_lowpass_hz == "table" else accel_lowpass_hz
    return None if lp and lp >= 0.5 * rate_hz else lp


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


def stage_laws(effects, payload, pl=None) -> list:
    """The candidate laws: ``effects`` or the library; the laws of a specimen that is there
    but not declared only with ``--payload none`` (or when named); the modes of a declared
    payload's own mass (``payload_mode`` with ``from_payload``) only where the declared
    payload ``pl`` is rigid (a frame's or a cantilever's modes are in its model already),
    and then not an added modal mass besides it unless named."""
    from mjcf.description import RigidPayload

    laws = candidate_laws(effects)
    rigid = isinstance(pl, RigidPayload)
    laws = [w for w in laws if w.when != "declared_rigid_specimen" or rigid]
    if not effects:
        laws = [w for w in laws if w.when != "undeclared_specimen" or payload == "none"]
        laws = [w for w in laws if w.when != "not_with_rigid_payload" or not rigid]
    return laws


def stage_candidates(laws, mfit, desc, pl) -> list:
    """``(law, place)`` pairs: each law at the places it acts on, one place per distinct
    force direction. A law of the actuators' own loads needs each actuator's force: a
    record with an actuator's force zero throughout holds a total (the NEES-UCSD runs:
    column E the measured total, W zero), not each actuator's own."""
    from sim.calibrate.residuals import places

    own_forces = not any(np.all(mr.extra["actuator_force"] == 0, axis=0).any() for mr in mfit)
    laws = [law for law in laws if own_forces or not (law.load or law.recorded_force)]
    out = []
    for law in laws:
        wheres = distinct_places(mfit[0], [p for p in places(desc, law.places, pl is not None) if law.acts_at(p)])
        out += [(law, w) for w in (alone_in_direction(mfit[0], wheres) if law.recorded_force else wheres)]
    return out


def alone_in_direction(mr, wheres) -> list:
    """The class (actuator) places of ``wheres`` whose force maps into DOF space as no
    other class's (actuator's) does, on a table of several: a load cell's gain is told from
    the others' only there (NEES-UCSD's east and west actuators both push along x: their
    gains traded 0.603 against 0.892 beside an undeclared conditioner; CGS's X1 and X3 are
    a push-pull pair on one line, its Z1-Z4 each alone)."""
    from sim.calibrate.residuals import same_direction

    def alone(w: str) -> bool:
        kind = w.partition(":")[0]
        others = [f"class:{c}" for c in mr.classes] if kind == "class" else [f"actuator:{a}" for a in mr.actuators]
        n = sum(same_direction(_direction(mr, w), _direction(mr, o)) for o in others)
        return len(others) > 1 and n == 1

    return [w for w in wheres if alone(w)]


def mechanical_stage(runs, ho_given, desc, pl, *, effects, payload, accel_lowpass_hz, margin, say, t0):
    """The mechanical path's search on ``runs`` (held out: ``ho_given`` or a share of
    ``runs``); a :class:`~sim.calibrate.search.CalibrationResult` without its baseline."""
    from sim.calibrate.acceptance import table_scale
    from sim.calibrate.engine import MAX_ROUNDS, search
    from sim.calibrate.holdout import split_holdout
    from sim.calibrate.mechjudge import RoundState
    from sim.calibrate.residuals import mechanical_runs, nrmse_runs
    from sim.calibrate.trace import fit_terms, flatness, predict

    lp = accel_lowpass(desc, accel_lowpass_hz, runs[0].sample_rate_hz)
    fit_runs, ho_runs, ho_note = split_holdout(runs, ho_given)
    t1 = time.perf_counter()
    mfit = mechanical_runs(fit_runs, desc, pl, accel_lowpass_hz=lp)
    mho = mechanical_runs(ho_runs, desc, pl, accel_lowpass_hz=lp)
    t2 = time.perf_counter()
    cur = fit_terms(mfit, [])
    e_ho0 = nrmse_runs(mho, predict(mho, cur))
    say(f"mechanical path: {len(fit_runs)} fit runs, {len(ho_runs)} held out; held-out NRMSE {e_ho0:.4f}")
    cands = stage_candidates(stage_laws(effects, payload, pl), mfit, desc, pl)
    flat = flatness(mfit, cur.residuals)
    st = RoundState(mfit, mho, e_ho0, flat, margin, table_scale(desc, pl), effects=effects, timing_on=True)
    ms = MechStage(st, cur, cands, say, places=(desc, pl), declared_timing=declared_timing(mfit + mho))
    cur, tried, _ = search(ms, MAX_ROUNDS)  # a sensor's timing found: ms's records re-timed
    t3 = time.perf_counter()
    times = {"read_s": t1 - t0, "residuals_s": t2 - t1, "search_s": t3 - t2, "total_s": t3 - t0}
    return _result(ms, cur, tried, st.timed_added, (mfit, mho), (e_ho0, times, ho_note), desc, runs)


def _sensor_predicts_better(timed: dict, win: tuple, rows: list, margin: float) -> bool:
    """Whether a sensor's candidate that passed (``timed``) goes in before the law that
    passed explaining more of the fit runs (``win``: its fit, held-out error, flatness):
    it predicts the held-out runs better by more than ``margin``. The law's row then says
    so. NEES-UCSD, a load-cell conditioner nobody declared and the load cells 5 % high: a
    17.9 Hz, 16 % mode of 2.5 t explained 71.74 % against the gain's 71.39 % and predicted
    2.44 % against 2.08 %. The load cells' gain read beside a law (:mod:`sim.calibrate.gainpair`)
    is judged by the pair's held-out error: that law comes in the next round."""
    e = timed.get("e_pair", timed["e_ho"])
    if not e < (1.0 - margin) * win[1]:
        return False
    for row in rows:
        if row.get("accepted"):
            row["accepted"] = False
            row["reason"] = (
                f"passed, not added: {timed['row']['name']} at {timed['row']['where']} predicts the held-out "
                f"runs better by more than {100 * margin:g} % ({e:.4f} against {win[1]:.4f})"
                + (f", beside {timed['row']['partner']['name']}" if "partner" in timed["row"] else "")
            )
    return True


def declared_timing(mruns) -> dict:
    return {mr.name: dict(mr.extra["timing"]) for mr in mruns}


def forward_search(st, cur, cands: list, max_rounds: int, say) -> tuple:
    """The forward rounds alone (no backward pass) from the fit ``cur`` over ``cands``
    (``(law, where)``) judged against ``st`` (a :class:`~sim.calibrate.mechjudge.RoundState`,
    which follows the current model). Returns ``(fit, rows, least-squares fits)``."""
    from sim.calibrate.engine import rounds

    ms = MechStage(st, cur, cands, say)
    rounds(ms, max_rounds)
    return ms.outputs()


@dataclass
class MechStage:
    """The mechanical path's steps of the search (:class:`sim.calibrate.engine.SearchPath`):
    the judgement's state ``st`` (:class:`~sim.calibrate.mechjudge.RoundState`: the fit and
    held-out runs, re-timed when a sensor's timing is accepted, the current held-out
    error and flatness, the margin), the current fit ``cur``, the candidates ``(law,
    where)``, the log, the least-squares fits run and the ``candidates`` rows.
    ``places``: ``(desc, payload)``, where the revisit finds a simpler law's place (None:
    no revisit)."""

    st: object
    cur: object
    cands: list
    say: object
    places: tuple | None = None
    #: run name -> its sensor timing before any was accepted (what a dropped one returns to)
    declared_timing: dict = field(default_factory=dict)
    n_fits: int = 0
    tried: list = field(default_factory=list)
    #: the round's law to judge first (:func:`sim.calibrate.gainpair.class_gain_first`), or None
    first: object = None
    #: the mechanical path revisits once, after the last round
    revisit_every_round = False

    @property
    def mfit(self) -> list:
        return self.st.mfit

    @property
    def mho(self) -> list:
        return self.st.mho

    @property
    def margin(self) -> float:
        return self.st.margin

    def screen(self, rnd) -> tuple[list, list | None]:
        """Every candidate fitted with the current terms (its least-squares fit, shape
        parameters scanned and refined: the screening and the refinement at once), best
        explained first, and the sensor-timing candidates fitted and judged (None: off)."""
        from sim.calibrate import timingjudge
        from sim.calibrate.trace import Term, fit_terms

        cur, scored = self.cur, []
        rank = {"dof": 0, "class": 1, "actuator": 2}
        for law, w in self.cands:
            # a law that repeats at a place (a specimen's modes) offers its next term there
            # (a term held at a bound, a nested law, counts as its own law's: fixed_law's base)
            n_have = sum(1 for t in cur.terms if ((t.law.base or t.law).type, t.where) == (law.type, w))
            if n_have >= getattr(law, "repeats", 1):
                continue
            if any(
                (t.law.name, t.where) == (law.name, w) and (t.law.base or t.law).type != law.type for t in cur.terms
            ):
                continue  # one entry of an effect per place: a variant of one already there is not added beside it
            new = fit_terms(self.st.mfit, cur.terms + [Term(law, w, index=n_have)], refine="last")
            self.n_fits += 1
            scored.append((1.0 - new.rss / cur.rss if cur.rss > 0 else 0.0, law, w, new))
        scored.sort(key=lambda s: (-round(s[0], 6), rank.get(s[2].split(":")[0], 3)))
        from sim.calibrate.gainpair import beside_a_law, class_gain_first

        self.first = class_gain_first(self.st, cur, scored, self.say)
        st = self.st
        if not st.timing_on:
            return scored, None
        args = (st.mfit, st.mho, cur, st.e_ho, st.flat, st.margin, st.effects, st.timed_added)
        return scored, beside_a_law(st, cur, scored, timingjudge.round_candidates(*args), self.say)

    def choose(self, screened, rnd) -> list:
        """Every candidate (a least-squares fit is cheap), the laws and the timing ones in
        one order, most explained first (:func:`sim.calibrate.timing.merged`), a load cell's
        gain read beside a law before them (:func:`sim.calibrate.gainpair.class_gain_first`)."""
        from sim.calibrate import timing

        scored, timed = screened
        order = scored if timed is None else timing.merged(scored, timed)
        return order if self.first is None else [self.first] + [s for s in order if s is not self.first]

    def refine(self, chosen: list, rnd) -> list:
        """Nothing more: each candidate's screening was its refined least-squares fit."""
        return chosen

    def judge(self, chosen: list, refined: list, rnd):
        """The timing candidates up to the first that passes, the laws that explain more
        than it judged with the tie-break (:func:`sim.calibrate.mechjudge.forward_round`);
        ``(law winner or None, timing winner or None)``, or None when neither passes."""
        from sim.calibrate.mechjudge import forward_round, split_at_timing

        ahead, timed, trs = split_at_timing(refined, rnd, self.say)
        rs, win = forward_round(self.st, self.cur, ahead, rnd, self.say)
        if win is not None and timed is not None and _sensor_predicts_better(timed, win, rs, self.st.margin):
            self.say(
                f"  set aside: {timed['row']['name']} at {timed['row']['where']} predicts the held-out runs better"
            )
            win = None
        self.tried += rs + trs
        return None if win is None and timed is None else (win, timed)

    def record(self, screened, chosen, refined, winner, rnd) -> None:
        """Nothing: :meth:`judge` wrote the row of every candidate it saw."""

    def take(self, winner, rnd) -> None:
        """The winner in; a sensor's timing re-times the records and the terms are refitted
        on them; every shape parameter refitted with the new term in."""
        from sim.calibrate import timing
        from sim.calibrate.trace import fit_terms

        win, timed = winner
        st = self.st
        # the load cells' gain taken for the law beside it: held where the pair read it until
        # that law is judged (refitted alone it takes the law's force back in)
        beside = win is None and "partner" in timed["row"]
        if win is None:  # a sensor's timing: the records re-timed, the model refitted on them
            st.mfit, st.mho = timed["mfit"], timed["mho"]
            st.timed_added.append(timing.added_entry(timed["row"]))
            self.say(f"  ACCEPTED {timed['row']['name']} at {timed['row']['where']}")
            win = (timed["fit"],)
        elif timed is not None:
            timed["row"]["accepted"] = False
            timed["row"]["reason"] = "passed, not added: a candidate that explains more was added"
        self.cur = fit_terms(st.mfit, win[0].terms)
        self.refit_timing(passes=0 if beside else TIMING_PASSES)

    def refit_timing(self, passes: int = TIMING_PASSES) -> None:
        """The sensor timing found so far refitted with the current terms, and they on it, in
        turn (at most ``passes`` times); the held-out error and flatness read again."""
        from sim.calibrate import timing
        from sim.calibrate.residuals import nrmse_runs
        from sim.calibrate.trace import fit_terms, flatness, predict

        st = self.st
        for _ in range(passes if st.timed_added else 0):
            before = [dict(e["parameters"]) for e in st.timed_added]
            st.mfit, st.mho = timing.refit_accepted(st.mfit, st.mho, self.cur.terms, st.timed_added)
            self.cur = fit_terms(st.mfit, self.cur.terms)
            if timing.settled(before, st.timed_added):
                break
        st.e_ho, st.flat = nrmse_runs(st.mho, predict(st.mho, self.cur)), flatness(st.mfit, self.cur.residuals)

    def revisit(self, rnd) -> None:
        """After the last round: the terms a later one superseded dropped
        (:func:`backward_pass`), those that ended at a simpler law's value demoted to it
        (:func:`demote_nested`)."""
        if self.places is None:
            return
        self.cur, self.st.e_ho = timing_backward(self, self.cur, self.st.e_ho)
        self.cur, e_ho = backward_pass(self, self.cur, self.st.e_ho, self.tried)
        self.cur, _ = demote_nested(self, self.cur, e_ho, self.tried, *self.places)

    def outputs(self) -> tuple:
        """``(fit, candidates rows, least-squares fits)``."""
        return self.cur, self.tried, self.n_fits


def _result(ms, cur, tried, timed_added, declared, facts, desc, runs):
    """The stage's :class:`~sim.calibrate.search.CalibrationResult` (``declared``: the
    fit and held-out runs at the declared timing, the report's "before")."""
    from sim.calibrate.gainpair import joint_intervals
    from sim.calibrate.residuals import nrmse_runs, unexplained
    from sim.calibrate.result import CalibrationResult
    from sim.calibrate.trace import predict

    (mfit0, mho0), (e_ho0, times, ho_note) = declared, facts
    ho_res = predict(ms.mho, cur)
    ho_res0 = [mr.residual for mr in mho0]
    per, per_run, quiet = mechanical_errors(ms.mho, ho_res0, ho_res)
    return CalibrationResult(
        table=desc.name,
        table_source=str(desc.source),
        runs=[str(r.name) for r in runs],
        holdout=[str(mr.name) for mr in ms.mho],
        holdout_note=ho_note,
        residual_path="mechanical",
        error_before=e_ho0,
        error_after=nrmse_runs(ms.mho, ho_res),
        effects_added=added_entries(joint_intervals(ms.mfit, cur, timed_added), ms.mfit[0]) + timed_added,
        candidates=tried,
        unexplained=unexplained(ms.mfit, cur.residuals),
        per_channel=per,
        per_run=per_run,
        not_excited=quiet,
        timing={**times, "least_squares_fits": ms.n_fits},
        series={
            "fit": ms.mfit,
            "holdout": ms.mho,
            "before": ho_res0,
            "after": ho_res,
            "fit_before": [mr.residual for mr in mfit0],
            "fit_after": cur.residuals,
            "terms": list(cur.terms),  # effects_added[i] is terms[i]; the timing entries follow
        },
    )


def refit_subset(res, keep: list[int]):
    """The mechanical stage ``res``'s terms ``keep`` (indices into its ``effects_added``)
    refitted alone on its fit runs (its sensor timing kept): ``(held-out NRMSE, their
    effects_added entries)``."""
    from sim.calibrate.residuals import nrmse_runs
    from sim.calibrate.trace import fit_terms, predict

    terms = res.series["terms"]
    fit = fit_terms(res.series["fit"], [terms[i] for i in keep])
    return nrmse_runs(res.series["holdout"], predict(res.series["holdout"], fit)), added_entries(
        fit, res.series["fit"][0]
    )


def backward_pass(ms: MechStage, cur, e_ho: float, tried: list):
    """Drop a term whose removal keeps the held-out error within the acceptance margin: a
    term accepted early may be superseded by later ones (viscous damping standing in for
    friction the flatness test kept out until a specimen's mode was in). ``(fit, error)``."""
    from sim.calibrate.residuals import nrmse_runs
    from sim.calibrate.trace import fit_terms, flatness, predict

    dropped = True
    while dropped and len(cur.terms) > 1:
        dropped = False
        for i, t in enumerate(cur.terms):
            rest = fit_terms(ms.mfit, cur.terms[:i] + cur.terms[i + 1 :])
            ms.n_fits += 1
            e_rest = nrmse_runs(ms.mho, predict(ms.mho, rest))
            if e_rest > (1 + ms.margin) * e_ho or _needed_where_it_pushes(ms, cur, rest, i):
                continue
            why = f"dropped: without it the held-out error is {e_ho:.4f} -> {e_rest:.4f} (within {100 * ms.margin:g} %)"
            ms.say(f"  {t.law.type:18s} {t.where:14s} {why}")
            expl = (rest.rss - cur.rss) / rest.rss if rest.rss > 0 else 0.0
            flat = flatness(ms.mfit, rest.residuals)
            tried.append(backward_row(t, cur.values[i], {}, rest, cur, e_rest, expl, flat, why))
            cur, e_ho, dropped = rest, e_rest, True
            break
    return cur, e_ho


def timing_backward(ms: MechStage, cur, e_ho: float):
    """Put an accepted sensor timing back at its declared value when the held-out error
    without it (the other timing and the terms refitted) stays within the acceptance
    margin. An acceleration delay timed by the displacement is put back only when the
    displacement puts it less than half a sample off its chain
    (:data:`sim.calibrate.timing.DISPLACEMENT_SKEW_SAMPLES`): the displacement's own skew
    may be that large, so below it the displacement cannot say which of the two is late (a
    load cell 4 ms early and a displacement 0.3 sample early gave the acceleration +0.32
    ms while the load cell's delay waited, and the load cell -3.68 ms). The motion's own
    delay, timed by the acceleration, is put back only when it is under half a sample
    (beyond, it was accepted without a margin: :func:`sim.calibrate.kinematic_timing.off_its_chain`).
    ``(fit, error)``."""
    from sim.calibrate import timing
    from sim.calibrate.residuals import nrmse_runs
    from sim.calibrate.trace import fit_terms, flatness, predict

    st, dropped = ms.st, True
    while dropped and st.timed_added:
        dropped = False
        for k, entry in enumerate(st.timed_added):
            if not _may_drop(entry, st.mfit[0], ms.declared_timing):
                continue
            alt = timing.without(st.mfit, st.mho, cur.terms, st.timed_added, k, ms.declared_timing)
            if alt is None:
                continue
            mfit, mho, rest = alt
            fit = fit_terms(mfit, cur.terms)
            ms.n_fits += 1
            e_rest = nrmse_runs(mho, predict(mho, fit))
            if e_rest > (1 + ms.margin) * e_ho:
                continue
            why = f"dropped: without it the held-out error is {e_ho:.4f} -> {e_rest:.4f} (within {100 * ms.margin:g} %)"
            ms.say(f"  {entry['name']:18s} {entry['where']:14s} {why}")
            expl = (fit.rss - cur.rss) / fit.rss if fit.rss > 0 else 0.0
            row = {"round": "backward", "name": entry["name"], "where": entry["where"]}
            row.update({k_: entry[k_] for k_ in ("options", "parameters", "uncertainty") if k_ in entry})
            row.update(explained_fraction=expl, holdout_error=e_rest, bic_change=fit.bic - cur.bic)
            row.update(flatness=flatness(mfit, fit.residuals), accepted=False, reason=why)
            ms.tried.append(row)
            st.mfit, st.mho, st.timed_added = mfit, mho, rest
            cur, e_ho, dropped = fit, e_rest, True
            break
    return cur, e_ho


def _may_drop(entry: dict, mr, declared: dict) -> bool:
    """Whether the backward pass may put a timing entry back (:func:`timing_backward`)."""
    from sim.calibrate.timing import DISPLACEMENT_SKEW_SAMPLES, MOTION_WHERES

    if entry["where"] in MOTION_WHERES:  # the motion's own skew: no margin beyond a scan's (off_its_chain)
        return abs(entry["parameters"]["delay_s"]) < DISPLACEMENT_SKEW_SAMPLES * mr.dt
    if entry.get("timed_by") != "displacement" and "displacement_reads" not in entry:
        return True  # the balance's own: judged by its held-out error alone
    off = entry["parameters"]["delay_s"] - declared[mr.name]["accel_delay_s"]
    return abs(off) < DISPLACEMENT_SKEW_SAMPLES * mr.dt


def _needed_where_it_pushes(ms: MechStage, cur, rest, i: int) -> bool:
    """Whether term ``i`` of ``cur`` is needed on the DOFs it pushes on
    (:func:`sim.calibrate.mechjudge.own_dofs`, as it was judged): their held-out error
    without it (``rest``) above the margin."""
    from sim.calibrate.mechjudge import own_dofs
    from sim.calibrate.residuals import nrmse_runs
    from sim.calibrate.trace import predict

    own = own_dofs(ms.mfit, cur, i)
    if not own:
        return False
    e_own = nrmse_runs(ms.mho, predict(ms.mho, cur), own)
    return nrmse_runs(ms.mho, predict(ms.mho, rest), own) > (1 + ms.margin) * e_own


def demote_nested(ms: MechStage, cur, e_ho: float, tried: list, desc, pl):
    """Replace a term whose nesting parameter ended at the simpler law's value once the
    later terms were in (a load-growing friction that stood in for the damping, its
    coefficient now 0 +/- its interval) by that simpler law at the same place, when the
    held-out error stays within the margin. ``(fit, error)``."""
    demoted, any_demoted = True, False
    while demoted:
        demoted = False
        for i, t in enumerate(cur.terms):
            for name, (at, simpler) in _simpler_laws(t.law).items():
                alt = _demoted(ms, cur, i, name, at, simpler, desc, pl)
                if alt is None or alt[1] > (1 + ms.margin) * e_ho:
                    continue
                (fit, e_alt, w2) = alt
                _log_demotion(ms, cur, i, name, at, (simpler, w2), (fit, e_ho, e_alt), tried)
                cur, e_ho, demoted, any_demoted = fit, e_alt, True, True
                break
            if demoted:
                break
    if any_demoted and ms.st.timed_added:  # a sensor's gain or timing read beside the term replaced
        ms.cur = cur
        ms.refit_timing()
        cur, e_ho = ms.cur, ms.st.e_ho
    return cur, e_ho


def _simpler_laws(law) -> dict:
    """Parameter -> (value, simpler law) of ``law``: its nested laws, and for a specimen's
    mode at a DOF a rigid mass (value None: the held-out runs alone decide). A mode far
    above the test's band is a mass to the test: beside the load cells' gain (NEES-UCSD
    records, 5 % high, 8 t added) a 9.1 t mode at 83 Hz, 10 %, stood for the mass and the
    model's own mismatch above 20 Hz."""
    if law.type == "payload_mode":
        return {**law.nested, "frequency_hz": (None, "added_mass")}
    return law.nested


def _demoted(ms: MechStage, cur, i: int, name: str, at: float, simpler: str, desc, pl):
    """``(fit, held-out error, place)`` with term ``i`` replaced by ``simpler``, or None
    when its parameter ``name`` is off ``at`` or the simpler law has no place of its own."""
    from sim.calibrate.acceptance import Z95
    from sim.calibrate.laws import LAWS
    from sim.calibrate.residuals import nrmse_runs, places
    from sim.calibrate.trace import Term, fit_terms, predict

    t = cur.terms[i]
    s95 = Z95 * cur.sigma[i].get(name, math.inf)
    if simpler not in LAWS or (at is not None and abs(cur.values[i][name] - at) > s95):
        return None
    law2 = LAWS[simpler]
    w2 = same_place(ms.mfit[0], t.where, places(desc, law2.places, pl is not None))
    if w2 is None or any((u.law.name, u.where) == (law2.name, w2) for j, u in enumerate(cur.terms) if j != i):
        return None
    terms = cur.terms[:i] + [Term(law2, w2)] + cur.terms[i + 1 :]
    alt = fit_terms(ms.mfit, terms)
    ms.n_fits += 1
    from sim.calibrate.gainpair import LOAD_CELLS_GAIN, WHERE, gain_accepted

    if not gain_accepted(ms.st.timed_added):
        return alt, nrmse_runs(ms.mho, predict(ms.mho, alt)), w2
    # the load cells' gain was read beside the term replaced: judged with it read again
    # beside the simpler law (its column), refitted after
    with_gain = fit_terms(ms.mfit, terms + [Term(LOAD_CELLS_GAIN, WHERE)], refine="none")
    return alt, nrmse_runs(ms.mho, predict(ms.mho, with_gain)), w2


def _log_demotion(ms: MechStage, cur, i, name, at, simpler_at, fits, tried) -> None:
    from sim.calibrate.acceptance import Z95
    from sim.calibrate.trace import flatness

    (simpler, w2), (alt, e_ho, e_alt), t = simpler_at, fits, cur.terms[i]
    s95 = Z95 * cur.sigma[i].get(name, math.inf)
    held = f"holds {at:g}" if at is not None else "the held-out runs do not tell it from the simpler law"
    why = f"replaced by {simpler} at {w2}: {name} = {cur.values[i][name]:.4g} +/-{s95:.3g} {held} (held-out {e_ho:.4f} -> {e_alt:.4f})"
    ms.say(f"  {t.law.type:18s} {t.where:14s} {why}")
    unc95 = {k: Z95 * v for k, v in cur.sigma[i].items()}
    tried.append(backward_row(t, cur.values[i], unc95, alt, cur, e_alt, 0.0, flatness(ms.mfit, alt.residuals), why))


def added_entries(cur, mr=None) -> list:
    """The ``effects_added`` entries of the fit's terms (``mr``: a run of theirs, where a
    class's or an actuator's load cells' gain is written at its force columns)."""
    from sim.calibrate.acceptance import param_report

    out = []
    for i, t in enumerate(cur.terms):
        _, _, unc = param_report(t, cur.values[i], cur.sigma[i])
        if getattr(t.law, "recorded_force", False):
            out.append(class_gain_entry(t.where, cur.values[i], unc, mr))
            continue
        out.append(
            {
                "name": t.law.name,
                "where": t.where,
                **({"options": dict(t.law.options)} if t.law.options else {}),
                **({"label": f"{t.law.name} {t.index + 1}"} if getattr(t.law, "repeats", 1) > 1 else {}),
                **({"fixed": dict(t.law.fixed)} if t.law.fixed else {}),
                "parameters": cur.values[i],
                "uncertainty": unc,
                "units": t.law.units,
            }
        )
    return out


def class_gain_entry(where: str, values: dict, unc: dict, mr) -> dict:
    """The ``sensor_gain`` entry of a class's or an actuator's load cells
    (:data:`sim.calibrate.laws.LOAD_CELLS_GAIN_CLASS`) at their columns of the recorded
    force (``mr``'s): ``gain = 1 / (1 - read_excess)``."""
    from sim.calibrate.laws import class_gain

    b = values["read_excess"]
    cols = ",".join(str(k) for k in mr.actuator_columns(where))
    return {
        "name": "sensor_gain",
        "where": f"channel:actuator_force[{cols}]",
        "class": where,
        "parameters": {"gain": class_gain(b)},
        "uncertainty": {"gain": unc.get("read_excess", math.inf) * class_gain(b) ** 2},
        "units": {"gain": "1"},
    }


def backward_row(t, values, unc, new, cur, e_new, explained, flat, why) -> dict:
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


def _direction(mr, where) -> np.ndarray:
    return mr.place_motion(where)[3]


def same_place(mr, where, wheres) -> str | None:
    """The first of ``wheres`` whose force maps into DOF space as ``where``'s does (on a
    uni-axial table ``dof:x`` for ``actuator:E``), else None."""
    from sim.calibrate.residuals import same_direction

    m0 = _direction(mr, where)
    return next((w for w in wheres if same_direction(_direction(mr, w), m0)), None)


def distinct_places(mr, wheres) -> list:
    """Places whose force maps into DOF space differently (a uni-axial table's actuators
    and classes all push along x: one place, ``dof:x``, stands for them)."""
    from sim.calibrate.residuals import first_of_each_direction

    return first_of_each_direction(wheres, lambda w: _direction(mr, w))


def mechanical_errors(mho, before, after) -> tuple[dict, dict, list]:
    """Where the held-out error sits: per run and excited DOF (``"<run>:<dof>"`` ->
    before/after, the floor the accelerometers' and load cells' noise sets there and the
    DOF's weight in the pooled error, :mod:`sim.calibrate.mechnoise`), per run (pooled
    over its excited DOFs), and the ``"<run>:<dof>"`` the runs do not excite
    (:func:`sim.calibrate.residuals.excited_dofs`), left out of both."""
    from sim.calibrate.mechnoise import dof_floor, dof_noise_weights
    from sim.calibrate.residuals import nrmse_runs

    per, per_run, quiet = {}, {}, []
    for mr, e0, e1 in zip(mho, before, after):
        run = Path(mr.name).name
        per_run[run] = {"before": nrmse_runs([mr], [e0]), "after": nrmse_runs([mr], [e1])}
        floor, weight = dof_floor(mr), dof_noise_weights(mr)
        for j, d in enumerate(mr.dofs):
            if mr.excited is not None and not mr.excited[j]:
                quiet.append(f"{run}:{d}")
                continue
            per[f"{run}:{d}"] = {"before": _nrmse_col(mr, e0, j), "after": _nrmse_col(mr, e1, j)}
            if np.isfinite(floor[j]):
                per[f"{run}:{d}"]["floor"] = float(floor[j])
            per[f"{run}:{d}"]["weight"] = float(weight[j])
    return per, per_run, quiet


def _nrmse_col(mr, e, j) -> float:
    F = mr.demean(mr.force)[mr.rows, j]
    den = float(np.sum(F**2))
    return float(math.sqrt(np.sum(e[mr.rows, j] ** 2) / den)) if den > 0 else float("nan")


__all__ = [
    "MechStage",
    "accel_lowpass",
    "candidate_laws",
    "check_effect_names",
    "added_entries",
    "backward_pass",
    "backward_row",
    "demote_nested",
    "distinct_places",
    "forward_search",
    "refit_subset",
    "mechanical_errors",
    "mechanical_stage",
    "same_place",
    "stage_candidates",
    "stage_laws",
]
