"""The accepted effects revisited on the replay and closed-loop paths (issue #13).

The forward search (:func:`sim.calibrate.pathsearch.calibrate_path`) adds one effect per
round, fitted with the effects accepted before it held at their values. An effect
accepted early can then be partly wrong: far from the model a nearly linear effect (a
flow gain) absorbs part of the residual of a strongly nonlinear one (a bulk modulus),
and keeps it when the right one comes in later. So, after every acceptance from the
second on:

* **Joint refit** (:func:`refit`): the parameters of every accepted effect together, by
  ``scipy.optimize.least_squares`` (bounded, Jacobian by the candidates' own finite
  steps, at most :data:`JOINT_NFEV` evaluations) on the refinement windows, starting
  from their values; a valve delay (whole physics steps) is held at its value. The
  refit is kept if the whole runs' held-out NRMSE does not rise (else the values stay).
* **Backward pass** (:func:`drop_rule`): each effect accepted before the newest one is
  taken out, the others refitted jointly without it, and the whole runs replayed. It
  is dropped when the forward rule would no longer add it next to the others: the
  held-out NRMSE with it is not below ``(1 - margin)`` times the one without it (the
  error rises by less than the margin of itself on removal) **and** the BIC without
  it is lower. One effect at a time, repeated while one is dropped.

Functions here return data; the search writes the rows (``revisited`` in
``candidates``).
"""

from __future__ import annotations

import math

import numpy as np

#: evaluations of the joint least squares (each: one replay of every refinement window,
#: plus one per free parameter for its Jacobian)
JOINT_NFEV = 5


def free_index(items) -> list[tuple[int, int]]:
    """``(item, parameter)`` of the jointly refitted parameters: every parameter of every
    accepted item ``(cand, theta)`` but a gridded one (a valve delay)."""
    return [(i, p) for i, (c, _th) in enumerate(items) if c.grid is None for p in range(len(c.names))]


def _thetas(items, free, x) -> list[np.ndarray]:
    out = [np.array(th, float) for _c, th in items]
    for (i, p), v in zip(free, x):
        out[i][p] = v
    return out


def entries(items, thetas=None) -> list[dict]:
    return [c.entry(th) for (c, _), th in zip(items, thetas or [t for _, t in items])]


class _Joint:
    """The replays of a joint fit of ``items`` on the windows ``prs``: the stacked
    residual of a parameter vector (cached) and its forward-difference Jacobian, each
    column one replay, all of a Jacobian in one batch over the workers."""

    def __init__(self, items, prs, base, workers, counts):
        self.items, self.prs, self.base, self.workers, self.counts = items, prs, base, workers, counts
        self.free = free_index(items)
        self.n_rep = 0
        self.cache: dict = {}
        self.step = np.array([abs(items[i][0].step[p]) for i, p in self.free])
        self.lo = np.array([items[i][0].lower[p] for i, p in self.free], float)
        self.hi = np.array([items[i][0].upper[p] for i, p in self.free], float)

    def sim_many(self, xs) -> list:
        from sim.calibrate import paths as P

        raw, src, payload = self.base
        its, prs = self.items, self.prs
        jobs = [pr.job(raw, src, payload, entries(its, _thetas(its, self.free, x))) for x in xs for pr in prs]
        ms = P.simulate_many(jobs, workers=self.workers, counts=self.counts)
        self.n_rep += len(jobs)
        n = len(prs)
        return [P.stacked(prs, ms[k * n : (k + 1) * n]) for k in range(len(xs))]

    def fun(self, x):
        k = tuple(np.round(x, 15))
        if k not in self.cache:
            (r,) = self.sim_many([np.asarray(x, float)])
            self.cache[k] = r
        return self.cache[k]

    def jac(self, x):
        x = np.asarray(x, float)
        r = self.fun(x)
        hs, xs = [], []
        for k in range(len(x)):
            h = 0.5 * self.step[k]
            if x[k] + h > self.hi[k]:
                h = -h
            xk = x.copy()
            xk[k] += h
            hs.append(h)
            xs.append(xk)
        rs = self.sim_many(xs)  # the columns together: one batch over the workers
        if any(rk is None for rk in rs):
            return None
        return np.stack([(rk - r) / h for h, rk in zip(hs, rs)], axis=1)


def refit(items, prs, base, workers=None, counts=None, max_nfev=JOINT_NFEV) -> dict:
    """Joint least squares of the accepted ``items`` (``[(cand, theta)]``) on the windows
    ``prs``; ``base = (raw, src, payload)``. Returns ``{"thetas": [...], "sigmas": [...],
    "rss0", "rss", "replays"}`` (``sigmas`` per item, HAC covariance of the joint fit;
    ``None`` for a held item)."""
    jf = _Joint(items, prs, base, workers, counts)
    x0 = np.array([items[i][1][p] for i, p in jf.free], float)
    r0 = jf.fun(x0)
    if r0 is None:
        return {"thetas": [t for _, t in items], "sigmas": None, "rss0": math.inf, "rss": math.inf, "replays": jf.n_rep}
    x = _solve(jf, x0, r0, max_nfev) if len(jf.free) else x0
    r = _safe_fun(jf, x, r0)
    sig_items = _sigmas(jf, x, r) if len(jf.free) else None
    return {
        "thetas": _thetas(items, jf.free, x),
        "sigmas": sig_items,
        "rss0": float(r0 @ r0),
        "rss": float(r @ r),
        "replays": jf.n_rep,
    }


def _safe_fun(jf: _Joint, x, r0):
    """The residual at ``x``, or a large one where the replay diverged."""
    r = jf.fun(x)
    return r if r is not None else np.full_like(r0, 1e3)


def _solve(jf: _Joint, x0, r0, max_nfev: int):
    """The bounded least-squares solution from ``x0`` (``x0`` itself when it does not
    lower the residual)."""
    from scipy.optimize import least_squares

    def jac_safe(x):
        J = jf.jac(x)
        return J if J is not None else np.zeros((len(r0), len(x)))

    x_in = np.clip(x0, jf.lo + 1e-9 * jf.step, jf.hi - 1e-9 * jf.step)
    fun = lambda x: _safe_fun(jf, x, r0)  # noqa: E731
    sol = least_squares(
        fun, x_in, jac=jac_safe, bounds=(jf.lo, jf.hi), x_scale=jf.step, max_nfev=max_nfev, method="trf"
    )
    return sol.x if float(fun(sol.x) @ fun(sol.x)) <= float(r0 @ r0) else x0


def _sigmas(jf: _Joint, x, r):
    """Per item, the HAC standard deviations of its free parameters at ``x`` (inf for a
    parameter held; None for a scanned item; None in all when the Jacobian diverged)."""
    from sim.calibrate.hac import hac_sigma
    from sim.calibrate.paths import residual_segments

    J = jf.jac(x)
    if J is None:
        return None
    sig = hac_sigma(J, r, residual_segments(jf.prs))
    sig_items = [None if c.grid is not None else np.full(len(c.names), math.inf) for c, _ in jf.items]
    for (i, p), s in zip(jf.free, sig):
        sig_items[i][p] = s
    return sig_items


def drop_rule(e_with, e_without, bic_with, bic_without, margin) -> tuple[bool, str]:
    """``(drop, reason)``: the mirror of the forward rule for an accepted effect judged
    next to the others. It is kept when its held-out NRMSE ``e_with`` is at least
    ``margin`` of itself below the error without it, as a new effect must be; dropped
    when not, provided the BIC without it is lower as well."""
    if e_with <= (1 - margin) * e_without:
        return False, (
            f"kept: without it the held-out error rises {e_with:.4f} -> {e_without:.4f} "
            f"(by >= {100 * margin:g} % of the error without it)"
        )
    if not bic_without < bic_with:
        return False, f"kept: the BIC without it is higher ({bic_with:.1f} -> {bic_without:.1f})"
    return True, (
        f"dropped: without it the held-out error is {e_with:.4f} -> {e_without:.4f} "
        f"(within {100 * margin:g} %) and the BIC falls ({bic_with:.1f} -> {bic_without:.1f})"
    )


def revisit_accepted(items, st, ctx, rnd, say=None, implausible=None) -> tuple[list, dict, list]:
    """The joint refit and the backward pass after an acceptance. ``items``: the accepted
    effects ``{"cand", "theta", "unc"}`` in the order accepted (the newest last); ``st``:
    the current model's whole-run numbers (``mfit``, ``mho``: model channels of the fit
    and held-out runs; ``e_ho``: held-out NRMSE; ``rss``, ``n_par``, ``flat``);
    ``ctx = (pfit, pho, wref, (raw, src, payload), N, margin, workers, counts)``.
    Returns the items left (refitted), the numbers of their model (with ``replays``:
    how many replays the revisit ran) and the rows for ``candidates`` (``revisited``:
    ``refitted`` / ``refit_not_kept`` / ``kept`` / ``dropped``). ``implausible``:
    ``(cand, values) -> reason`` (empty: plausible); a joint refit that takes an effect
    where the table cannot have it is not kept (sim.calibrate.acceptance)."""
    rv = _Revisit(ctx, rnd, dict(st, replays=0), say or (lambda *_: None), implausible)
    items = rv.joint_refit(items)
    items = rv.backward(items)
    return items, rv.st, rv.rows


class _Revisit:
    """One revisit: its context, the current model's numbers (``st``) and its rows."""

    def __init__(self, ctx, rnd, st, say, implausible):
        self.pfit, self.pho, self.wref, self.base, self.N, self.margin, self.workers, self.counts = ctx
        self.rnd, self.st, self.say, self.implausible = rnd, st, say, implausible
        self.rows: list = []

    def whole(self, its, thetas) -> dict | None:
        """The whole fit and held-out runs replayed with ``its`` at ``thetas``."""
        from sim.calibrate import paths as P

        raw, src, payload = self.base
        pfit, pho = self.pfit, self.pho
        jobs = [p.job(raw, src, payload, [a["cand"].entry(th) for a, th in zip(its, thetas)]) for p in pfit + pho]
        ms = P.simulate_many(jobs, workers=self.workers, counts=self.counts)
        self.st["replays"] += len(jobs)
        mf, mh = ms[: len(pfit)], ms[len(pfit) :]
        rn = P.stacked(pfit, mf)
        if rn is None or any(m is None for m in mh):
            return None
        return {"mfit": mf, "mho": mh, "e_ho": P.nrmse(pho, mh), "rss": float(rn @ rn), "flat": P.flatness(pfit, mf)}

    def joint(self, its):
        """``its`` refitted together on the refinement windows, with their intervals."""
        from sim.calibrate.acceptance import Z95

        out = refit([(a["cand"], a["theta"]) for a in its], self.wref, self.base, self.workers, self.counts)
        self.st["replays"] += out["replays"]
        new = []
        for k, a in enumerate(its):
            b = dict(a, theta=np.asarray(out["thetas"][k], float))
            sg = out["sigmas"][k] if out["sigmas"] is not None else None
            if sg is not None:
                b["unc"] = {n: Z95 * s for n, s in a["cand"].sigmas(b["theta"], sg).items()}
            new.append(b)
        return new, out

    def row(self, a, how, why, num=None, expl=0.0) -> dict:
        c = a["cand"]
        r = {
            "round": self.rnd,
            "name": c.type,
            "where": c.where,
            "explained_fraction": expl,
            "linearised_score": None,
            "parameters": c.values(a["theta"]),
            "uncertainty": dict(a["unc"]),
            "holdout_error": None,
            "bic_change": None,
            "flatness": None,
            "accepted": False,
            "revisited": how,
            "reason": why,
        }
        r.update(num or {})
        return r

    def joint_refit(self, items) -> list:
        """Every accepted effect refitted jointly; kept when the held-out error does not rise."""
        st = self.st
        new, out = self.joint(items)
        moved = any(not np.array_equal(a["theta"], b["theta"]) for a, b in zip(items, new))
        imp = self.implausible
        bad = next((x for b in new if imp and (x := imp(b["cand"], b["cand"].values(b["theta"])))), "")
        w = self.whole(new, [b["theta"] for b in new]) if moved and not bad else None
        if w is not None and w["e_ho"] <= st["e_ho"]:
            for a, b in zip(items, new):
                why = (
                    f"joint refit with the {len(items) - 1} other accepted effect(s) on the refinement windows "
                    f"(residual {out['rss0']:.4g} -> {out['rss']:.4g}): {a['cand'].values(a['theta'])} -> "
                    f"{b['cand'].values(b['theta'])}; held-out {st['e_ho']:.5f} -> {w['e_ho']:.5f}"
                )
                self.rows.append(self.row(b, "refitted", why, {"holdout_error": w["e_ho"], "flatness": w["flat"]}))
            st.update(w)
            items = new
        else:
            why = "joint refit: no parameter moved" if not moved else "joint refit not kept: "
            if moved and bad:
                why += bad
            elif moved:
                why += (
                    "a whole-run replay diverged"
                    if w is None
                    else f"held-out {st['e_ho']:.5f} -> {w['e_ho']:.5f} rises"
                )
            self.rows += [self.row(a, "refit_not_kept", why) for a in items]
        self.say(f"  revisit: {self.rows[-1]['reason']}")
        return items

    def backward(self, items) -> list:
        """Each effect accepted before the newest, taken out (the others refitted): dropped
        when the model does as well without it (:func:`drop_rule`)."""
        changed = True
        while changed and len(items) >= 2:
            changed = False
            for i in range(len(items) - 1):
                rest = self.without(items, i)
                if rest is not None:
                    items, changed = rest, True
                    break
        return items

    def without(self, items, i: int) -> list | None:
        """The items without item ``i`` when it is dropped, else None (its row written)."""
        from sim.calibrate import paths as P
        from sim.calibrate.pathjudge import bic
        from sim.calibrate.sensorcands import acts_on

        st, a = self.st, items[i]
        rest, _ = self.joint(items[:i] + items[i + 1 :])
        w = self.whole(rest, [b["theta"] for b in rest])
        if w is None:
            self.rows.append(self.row(a, "kept", "kept: the model without it diverged"))
            return None
        p_rest = st["n_par"] - len(a["theta"])
        b_with, b_without = bic(st["rss"], self.N, st["n_par"]), bic(w["rss"], self.N, p_rest)
        if a["cand"].sensor:  # judged on the columns it acts on, as when it was added
            on = [p.only(acts_on(a["cand"])) for p in self.pho]
            e_with, e_without = P.nrmse(on, st["mho"]), P.nrmse(on, w["mho"])
        else:
            e_with, e_without = st["e_ho"], w["e_ho"]
        drop, why = drop_rule(e_with, e_without, b_with, b_without, self.margin)
        num = {"holdout_error": w["e_ho"], "bic_change": b_without - b_with, "flatness": w["flat"]}
        expl = (w["rss"] - st["rss"]) / w["rss"] if w["rss"] > 0 else 0.0
        self.rows.append(self.row(a, "dropped" if drop else "kept", why, num, expl))
        self.say(f"  backward: {a['cand'].type} {a['cand'].where}: {why}")
        if not drop:
            return None
        st.update(w)
        st["n_par"] = p_rest
        return rest


__all__ = ["JOINT_NFEV", "drop_rule", "entries", "free_index", "refit", "revisit_accepted"]
