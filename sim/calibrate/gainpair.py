"""The load cells' gain read beside a law on the mechanical path.

The load cells' gain (``sensor_gain`` at ``channel:actuator_force``,
:mod:`sim.calibrate.timing`) is searched with the accepted terms refitted, not with a
candidate law beside it. Where the records hold a law nobody declared as well, each
alone takes in the other's force: NEES-UCSD records with the load cells 5 % high and
8 t added read the gain alone at 1.106 (92.5 % of the residual) and a 69 Hz mode of
15 t alone (94.3 %); the mode was taken, and a second one, below the band, for the
gain's share of the friction.

Read at the current gain ``g0``, the force recorded at a gain ``g`` is
``(1 + b) (model + laws)`` with ``1 + b = g / g0``: linear in ``b`` beside each law's
coefficient (that times ``1 + b``), the declared model's own force the gain's column
(:data:`LOAD_CELLS_GAIN`; with the fit's weights this is the measure
:func:`sim.calibrate.timing.retime` scores a gain by). :func:`beside_a_law` fits the
gain with each of the round's best laws; where a pair predicts the held-out runs better
than its law alone and than the gain alone, by the margin each, the gain is judged at
the pair's value, and it goes in before a law that explains more of the fit runs alone
when the pair predicts the held-out runs better than that law by the margin
(:func:`sim.calibrate.mechsearch._sensor_predicts_better`). The law comes in the next
round, fitted at the gain taken.
"""

from __future__ import annotations

import numpy as np

from sim.calibrate.laws import Law

#: the round's laws (most explained first) the gain is fitted beside (assumed: 3; on the
#: NEES-UCSD records with 8 t added the added mass was the second, a mode the first)
PARTNERS = 3
#: where the gain acts: the load cells
WHERE = "channel:actuator_force"


def _model_force(u, v, a, s):
    raise NotImplementedError("the gain's column is the declared model's force (MechRun.columns)")


#: the load cells' gain relative to the one the records are read at, as a term: its
#: column is the declared model's force, its coefficient ``g / g0 - 1`` (bounds: a factor
#: of 2 either way, as :data:`sim.calibrate.timing.FORCE_GAIN_RANGE`)
LOAD_CELLS_GAIN = Law(
    type="load_cells_gain_all",  # every load cell's (one class's: sim.calibrate.laws.LOAD_CELLS_GAIN_CLASS)
    params={"gain_change": ("1", -0.5, 1.0)},
    linear="gain_change",
    basis=_model_force,
    places=("channel",),
    what="the load cells' gain over the one the records are read at",
    model_force=True,
)


def pair_fit(mfit, cur, term):
    """The current terms, the gain's column and ``term`` fitted together (``term``'s shape
    refined near the value its own fit found)."""
    from sim.calibrate.trace import Term, fit_terms

    return fit_terms(mfit, cur.terms + [Term(LOAD_CELLS_GAIN, WHERE), term], refine="last")


def _inside_bounds(fit) -> bool:
    """Whether every term of ``fit`` has its parameters inside their bounds (a pair that
    pushes a law past its bound is a compensation, not a reading)."""
    for t, vals in zip(fit.terms, fit.values):
        for name, (_unit, lo, hi) in t.law.params.items():
            v = vals.get(name)
            if v is not None and not (np.isfinite(v) and lo <= v <= hi):
                return False
    return True


def gain_accepted(timed_added: list) -> bool:
    """Whether the load cells' gain is among the accepted sensor entries."""
    return any((e["name"], e["where"]) == ("sensor_gain", WHERE) for e in timed_added)


def joint_intervals(mfit, cur, timed_added: list):
    """``cur`` with each term's standard deviations read with the load cells' gain fitted
    beside it (its column), where a gain was accepted, and never narrower than its own.
    The laws are fitted at the gain taken, so their intervals leave its uncertainty out,
    and where the model's force is mostly inertia a mass and the gain are near-collinear:
    NEES-UCSD records, 5 % high and 8 t added, read 8 358 +/- 49 kg (95 %) beside a gain
    of 1.0469 +/- 0.0043."""
    import dataclasses

    from sim.calibrate.trace import Term, fit_terms

    if not cur.terms or not gain_accepted(timed_added):
        return cur
    joint = fit_terms(mfit, cur.terms + [Term(LOAD_CELLS_GAIN, WHERE)], refine="none")
    r = 1.0 + joint.values[-1]["gain_change"]
    sigma = []
    for t, own, js in zip(cur.terms, cur.sigma, joint.sigma):
        lin = set(t.law.linears)
        sigma.append({k: max(v, js.get(k, 0.0) / (r if k in lin else 1.0)) for k, v in own.items()})
    return dataclasses.replace(cur, sigma=sigma)


def _gain_index(timed: list) -> int | None:
    for k, ev in enumerate(timed):
        if (ev["row"]["name"], ev["row"]["where"]) == ("sensor_gain", WHERE):
            return k
    return None


def best_pair(st, cur, scored: list):
    """``(pair fit, its held-out error, its law's alone, law, where)`` of the round's
    :data:`PARTNERS` best laws (``scored``: ``(explained, law, where, fit)``) whose pair
    with the gain keeps every term inside its bounds, the one that predicts the held-out
    runs best (a mode beside the gain explained the fit runs a little more than the
    added mass beside it, with the gain at 1.041 for 1.05); None without one."""
    from sim.calibrate.residuals import nrmse_runs
    from sim.calibrate.trace import predict

    best = None
    for _expl, law, w, single in scored[:PARTNERS]:
        pair = pair_fit(st.mfit, cur, single.terms[-1])
        if not _inside_bounds(pair):
            continue
        e_pair = nrmse_runs(st.mho, predict(st.mho, pair))
        if best is None or e_pair < best[1]:
            best = (pair, e_pair, nrmse_runs(st.mho, predict(st.mho, single)), law, w)
    return best


def beside_a_law(st, cur, scored: list, timed: list, say) -> list:
    """``timed`` (the round's sensor candidates, :func:`sim.calibrate.timingjudge.round_candidates`)
    with the load cells' gain judged at its reading beside the law it goes with best,
    where that pair predicts the held-out runs better than either alone by the margin
    (the evaluation then holds ``e_pair`` and its row a ``partner``)."""
    from sim.calibrate import timing, timingjudge

    k = _gain_index(timed)
    found = best_pair(st, cur, scored) if k is not None and scored else None
    if found is None:
        return timed
    pair, e_pair, e_law, law, w = found
    if not e_pair < (1.0 - st.margin) * min(e_law, timed[k]["e_ho"]):
        return timed
    i = len(cur.terms)
    g0 = st.mfit[0].extra["timing"].get("force_gain", 1.0)
    x = g0 * (1.0 + pair.values[i]["gain_change"])
    s = g0 * pair.sigma[i]["gain_change"]
    cand = next(c for c in timing.candidates(st.mfit) if c.field == "force_gain")
    ev = timingjudge.evaluate(st.mfit, st.mho, cur, cand, st.e_ho, st.flat, st.margin, at=(x, s, None))
    expl = 1.0 - pair.rss / cur.rss if cur.rss > 0 else 0.0
    ev["row"]["partner"] = {"name": law.name, "where": w, "explained_fraction": expl, "holdout_error": e_pair}
    ev["e_pair"] = e_pair
    say(
        f"  sensor_gain at {WHERE} read beside {law.name} at {w}: gain = {x:.5g}, the two explain "
        f"{100 * expl:.2f} %, held-out {e_pair:.4f} (the law alone {e_law:.4f}, the gain alone {timed[k]['e_ho']:.4f})"
    )
    return timed[:k] + [ev] + timed[k + 1 :]


def class_gain_first(st, cur, scored: list, say):
    """The entry of ``scored`` (the round's laws, ``(explained, law, where, fit)``, most
    explained first) to judge first, or None: a class's or an actuator's load-cell gain
    (:data:`sim.calibrate.laws.LOAD_CELLS_GAIN_CLASS`, among the round's best) where it and one of the :data:`PARTNERS` best other
    laws, fitted together, predict the held-out runs better than each alone and than the
    best of those laws by the margin. That gain is a law: once in, the law beside it is
    fitted with it in the next round. CGS, the vertical class 5 % high and 6 t added in
    z: the class's gain took the mass in alone (1.095), and an added mass at the supports
    explained more and was taken, then 4.2 t in z and a friction."""
    from sim.calibrate.residuals import nrmse_runs
    from sim.calibrate.trace import fit_terms, predict

    top = scored[: 2 * PARTNERS]  # assumed: twice the partners (the class's gain was the fourth on CGS)
    gains = [s for s in top if s[1].recorded_force]
    others = [s for s in top if not s[1].recorded_force][:PARTNERS]
    if not gains or not others:
        return None
    alone = {id(s): nrmse_runs(st.mho, predict(st.mho, s[3])) for s in gains + others}
    e_best = min(alone[id(o)] for o in others)
    for g in gains:
        for o in others:
            pair = fit_terms(st.mfit, cur.terms + [g[3].terms[-1], o[3].terms[-1]], refine="none")
            e_pair = nrmse_runs(st.mho, predict(st.mho, pair))
            if _inside_bounds(pair) and e_pair < (1.0 - st.margin) * min(alone[id(g)], alone[id(o)], e_best):
                say(
                    f"  {g[1].type} at {g[2]} judged first: beside {o[1].name} at {o[2]} the two predict "
                    f"the held-out runs at {e_pair:.4f} (alone {alone[id(g)]:.4f} and {alone[id(o)]:.4f})"
                )
                return g
    return None


__all__ = [
    "LOAD_CELLS_GAIN",
    "PARTNERS",
    "beside_a_law",
    "best_pair",
    "class_gain_first",
    "gain_accepted",
    "joint_intervals",
    "pair_fit",
]
