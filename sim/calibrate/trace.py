"""Trace the residual to effects: fit a set of terms, score each candidate by the
residual it explains, and the statistics the acceptance needs.

A *term* is one effect at one place: a :class:`sim.calibrate.laws.Law`, a ``where``
and its shape parameters (the exponent of power-law damping). On the mechanical path
every term is linear in its coefficient, so a set of terms is fitted by one weighted
linear least squares over the fit runs (each run and DOF weighted by its recorded
force, the NEES-UCSD paper's Eq. 14); a shape parameter is scanned on its grid and
refined by a bounded scalar search, each point a linear least squares. The parameters'
standard deviations account for the residual's correlation in time within each run and
DOF (:func:`sim.calibrate.hac.hac_sigma`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sim.calibrate.hac import hac_sigma


@dataclass
class Term:
    law: object
    where: str
    shape: dict = field(default_factory=dict)
    index: int = 0  #: the n-th term of a law that repeats at one place (a specimen's modes)

    @property
    def key(self) -> tuple:
        return (self.law.type, self.where) + ((self.index,) if self.index else ())


@dataclass
class Fit:
    """Terms fitted together: parameters, their standard deviations, the residual."""

    terms: list
    theta: np.ndarray  # linear coefficients, in term order (one per term, several for a vector law)
    values: list  # per term: {param: value}
    sigma: list  # per term: {param: standard deviation}
    rss: float  # weighted residual sum of squares over the fit rows
    n: int  # rows x DOFs
    p: int  # parameters (coefficients + shape parameters)
    residuals: list  # per run (n, k): recorded - model - terms

    @property
    def bic(self) -> float:
        return self.n * math.log(max(self.rss, 1e-300) / self.n) + self.p * math.log(self.n)

    @property
    def aic(self) -> float:
        return self.n * math.log(max(self.rss, 1e-300) / self.n) + 2 * self.p


def _weights(mr) -> np.ndarray:
    """Per DOF, the weight of its residual in the fit: over its recorded force (the
    paper's Eq. 14), times the root of its noise weight
    (:func:`sim.calibrate.mechnoise.dof_noise_weights`), so that the fit minimises the
    pooled error the held-out judgement reads (:func:`sim.calibrate.residuals.nrmse_runs`)."""
    from sim.calibrate.mechnoise import dof_noise_weights

    F = mr.demean(mr.force)[mr.rows]
    den = np.sqrt(np.sum(F**2, axis=0))
    if mr.excited is not None:  # a DOF the run does not excite: noise over nothing, left out
        den = np.where(mr.excited, den, 0.0)
    return np.where(den > 0, np.sqrt(dof_noise_weights(mr)) / np.where(den > 0, den, 1.0), 0.0)


def _key(t) -> tuple:
    return (t.law.type, t.where, tuple(sorted(t.shape.items())))  # no index: equal terms share a column


def _stack(mruns, terms):
    """Weighted, demeaned target and columns over the fit rows, stacked over runs and
    DOFs (each run's pieces cached: candidates share them)."""
    ys, Xs = [], []
    for mr in mruns:
        cache = mr.extra.setdefault("columns", {})
        if "y" not in mr.extra:
            w = _weights(mr)
            mr.extra["w"] = w
            mr.extra["y"] = (mr.residual[mr.rows] * w).reshape(-1)
        w = mr.extra["w"]
        cols = []
        for t in terms:
            k = _key(t)
            if getattr(t.law, "recorded_force", False):  # the force as re-timed: not kept across timings
                cols.extend((mr.demean(Q)[mr.rows] * w).reshape(-1) for Q in mr.columns(t.law, t.where, t.shape))
                continue
            if k not in cache:
                if len(cache) > 256:
                    cache.clear()
                cache[k] = [(mr.demean(Q)[mr.rows] * w).reshape(-1) for Q in mr.columns(t.law, t.where, t.shape)]
            cols.extend(cache[k])
        ys.append(mr.extra["y"])
        Xs.append(np.stack(cols, axis=1) if cols else np.zeros((mr.extra["y"].size, 0)))
    return np.concatenate(ys), np.concatenate(Xs, axis=0)


def _segments(mruns) -> list:
    """Positions in the stacked target (:func:`_stack`: per run, the fit rows by DOF,
    row-major) of each run's DOF in time order, ``-1`` at the rows not in the fit."""
    out, k0 = [], 0
    for mr in mruns:
        rows = np.asarray(mr.rows, bool)
        k = mr.force.shape[1]
        idx = np.flatnonzero(rows)
        if idx.size:
            span = rows[idx[0] : idx[-1] + 1]
            order = np.where(span, np.cumsum(span) - 1, -1)
            for j in range(k):
                out.append(np.where(order >= 0, k0 + order * k + j, -1))
        k0 += idx.size * k
    return out


def _solve(y, X):
    if X.shape[1] == 0:
        return np.zeros(0), float(y @ y)
    theta, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ theta
    return theta, float(r @ r)


def _shape_jacobian(mruns, term, coef, h=1e-3):
    """Columns d(model)/d(shape parameter), one per shape parameter (stacked, weighted),
    central differences (step ``h`` relative to the value for a parameter above 1)."""
    cols = []
    for name, val in term.shape.items():
        hh = h * max(1.0, abs(val))
        up = Term(term.law, term.where, {**term.shape, name: val + hh})
        dn = Term(term.law, term.where, {**term.shape, name: val - hh})
        _, Xu = _stack(mruns, [up])
        _, Xd = _stack(mruns, [dn])
        cols.append(coef * (Xu[:, 0] - Xd[:, 0]) / (2 * hh))
    return np.stack(cols, axis=1)


def _joint_shape(mruns, terms, i) -> Term:
    """Term ``i``'s shape parameters refined together (Nelder-Mead from the coordinate
    scan's point, inside the grids' range): one pass per parameter stops short when they
    trade off (a payload mode 5 % low in frequency and 34 % high in damping)."""
    from scipy.optimize import minimize

    t = terms[i]
    names = list(t.law.shape)
    lims = [scan_limits(t.law, n, mruns) for n in names]
    lo = np.array([x[0] for x in lims], float)
    hi = np.array([x[1] for x in lims], float)

    def rss(x):
        trial = list(terms)
        trial[i] = Term(
            t.law, t.where, {**t.shape, **{n: float(v) for n, v in zip(names, np.clip(x, lo, hi))}}, t.index
        )
        return _fit_linear(mruns, trial)[1]

    x0 = np.array([t.shape[n] for n in names], float)
    r0 = rss(x0)
    r = minimize(rss, x0, method="Nelder-Mead", options={"xatol": 1e-4, "fatol": 1e-9 * r0, "maxiter": 200})
    if not r.fun < r0:
        return t
    return Term(t.law, t.where, {**t.shape, **{n: float(v) for n, v in zip(names, np.clip(r.x, lo, hi))}}, t.index)


#: steps a scan takes past its grid's edge, at most (geometric, the grid's own ratio there)
MAX_EDGE_STEPS = 12


def scan_limits(law, name: str, mruns) -> tuple[float, float]:
    """How far the scan of shape parameter ``name`` may go: the law's physical limits
    (``Law.limits``; "nyquist": 0.4 x the record rate), else its grid's range."""
    grid = law.shape[name]
    lo, hi = law.limits.get(name, (min(grid), max(grid)))
    if hi == "nyquist":
        hi = 0.4 / max(mr.dt for mr in mruns)
    return float(lo), float(hi)


def walk_edges(grid: list, vals: list, rss_at, limits) -> tuple[list, list]:
    """The scan extended past its edge while the optimum sits there (a mode damped 0.3 %
    below a grid that starts at 0.3 %), by the grid's own step there (geometric for a
    positive grid), up to ``limits``; returns the grid and its residuals, sorted."""
    grid, vals = [float(g) for g in grid], list(vals)
    lo, hi = limits
    for _ in range(MAX_EDGE_STEPS):
        k = int(np.argmin(vals))
        if len(grid) < 2 or 0 < k < len(grid) - 1:
            break
        a, b = (grid[0], grid[1]) if k == 0 else (grid[-1], grid[-2])
        nxt = a * a / b if a > 0 and b > 0 else 2 * a - b
        nxt = min(max(nxt, lo), hi)
        if abs(nxt - a) <= 1e-9 * max(abs(a), 1e-12):
            break  # at the limit
        at = 0 if k == 0 else len(grid)
        grid.insert(at, nxt)
        vals.insert(at, rss_at(nxt))
    return grid, vals


def fit_terms(mruns, terms: list, *, refine: str = "all") -> Fit:
    """Fit ``terms`` jointly on ``mruns`` (shape parameters chosen in turn on their grid,
    then refined: ``refine`` "all" terms, the "last" one only (a candidate added to an
    accepted set), or "none"); returns the :class:`Fit`."""
    given = [set(t.shape) for t in terms]
    terms = [
        Term(t.law, t.where, {**{k: float(np.median(g)) for k, g in t.law.shape.items()}, **t.shape}, t.index)
        for t in terms
    ]
    todo = {"all": range(len(terms)), "last": range(len(terms) - 1, len(terms)), "none": ()}[refine]
    for i, t in enumerate(terms):
        if i not in todo:
            continue
        for name, grid in t.law.shape.items():

            def rss_at(val, i=i, name=name, t=t):
                trial = list(terms)
                trial[i] = Term(t.law, t.where, {**t.shape, name: float(val)}, t.index)
                return _fit_linear(mruns, trial)[1]

            grid = list(grid)
            if name in given[i]:
                # a value found before is refined near it (between its neighbouring grid
                # points): rescanning the whole grid lets one of several terms of a law (a
                # specimen's modes) jump onto another's peak
                val = t.shape[name]
                k = int(np.searchsorted(grid, val))
                grid = sorted({grid[max(k - 1, 0)], val, grid[min(k, len(grid) - 1)]})
            grid, vals = walk_edges(grid, [rss_at(g) for g in grid], rss_at, scan_limits(t.law, name, mruns))
            k = int(np.argmin(vals))
            lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
            best = grid[k]
            if hi > lo:
                from scipy.optimize import minimize_scalar

                r = minimize_scalar(rss_at, bounds=(lo, hi), method="bounded", options={"xatol": 1e-3})
                if r.fun <= vals[k]:
                    best = float(r.x)
            terms[i] = t = Term(t.law, t.where, {**t.shape, name: float(best)}, t.index)
        if len(t.law.shape) > 1:  # correlated shape parameters (a mode's frequency and damping): jointly
            terms[i] = _joint_shape(mruns, terms, i)
    theta, rss, y, X = _fit_linear(mruns, terms)
    off = _offsets(terms)
    # the Jacobian of the fit: coefficient columns (with the second-order force's change)
    # and each shape parameter's column
    Jcols = [X + _second_jacobian(mruns, terms, theta, X.shape)]
    for i, t in enumerate(terms):
        if t.shape:
            Jcols.append(_shape_jacobian(mruns, t, theta[off[i]]))
    Jm = np.concatenate(Jcols, axis=1) if Jcols else X
    n, p = len(y), Jm.shape[1]
    # the residual is coloured (prefilter, unmodelled dynamics): the estimate's standard
    # deviations from its autocorrelation within each run and DOF (sim.calibrate.hac)
    q = _second_stack(mruns, terms, theta)
    r = y - X @ theta - (q if q is not None else 0.0)
    sd = hac_sigma(Jm, r, _segments(mruns)) if p else np.zeros(0)
    values, sigma = [], []
    js = X.shape[1]
    for i, t in enumerate(terms):
        v = {name: float(theta[off[i] + j]) for j, name in enumerate(t.law.linears)}
        s = {name: float(sd[off[i] + j]) for j, name in enumerate(t.law.linears)}
        for name, val in t.shape.items():
            v[name] = float(val)
            s[name] = float(sd[js])
            js += 1
        v.update(t.law.fixed)  # held at a bound (a nested law): a value, no interval
        values.append(v)
        sigma.append(s)
    residuals = _residuals(mruns, terms, theta)
    return Fit(terms=terms, theta=theta, values=values, sigma=sigma, rss=rss, n=n, p=p, residuals=residuals)


SECOND_ORDER_ITERATIONS = 8  #: fixed-point passes of a law's second-order force (converged: 1e-10)


def _fit_linear(mruns, terms):
    """``(theta, rss, y, X)``: the terms' coefficients by linear least squares; a law's
    force of second order in its coefficients (the CG offset's own parallel-axis inertia,
    ``Law.second_order``) is taken to the target at the current coefficients, and the
    solve repeated to a fixed point (the second-order force is small: a few passes)."""
    y, X = _stack(mruns, terms)
    theta, rss = _solve(y, X)
    for _ in range(SECOND_ORDER_ITERATIONS):
        q = _second_stack(mruns, terms, theta)
        if q is None:
            break
        new, rss = _solve(y - q, X)
        done = np.allclose(new, theta, rtol=1e-10, atol=0.0)
        theta = new
        if done:
            break
    return theta, rss, y, X


def _term_values(t, theta, k: int) -> dict:
    return {name: float(theta[k + j]) for j, name in enumerate(t.law.linears)}


def _second_stack(mruns, terms, theta):
    """The terms' second-order force at ``theta``, weighted and stacked as the target
    (None: no term has one)."""
    if not any(getattr(t.law, "second_order", None) for t in terms):
        return None
    off = _offsets(terms)
    parts = []
    for mr in mruns:
        tot = 0.0
        for i, t in enumerate(terms):
            if getattr(t.law, "second_order", None):
                Q, pairs = _second_columns(mr, t)
                th = theta[off[i] : off[i] + len(t.law.linears)]
                tot = tot + Q @ np.array([th[a] * th[b] for a, b in pairs])
        parts.append(tot)
    return np.concatenate(parts)


def _second_columns(mr, t):
    """A term's second-order force as a quadratic form in its coefficients: the stacked,
    weighted column of each product theta_i theta_j (i <= j), and the pairs (cached per
    run: the fit's passes and shape scans reuse them)."""
    cache = mr.extra.setdefault("second", {})
    k = _key(t)
    if k not in cache:
        names = t.law.linears
        E = np.eye(len(names))

        def q(vec):
            F = mr.second(t.law, t.where, t.shape, dict(zip(names, map(float, vec))))
            return (mr.demean(F)[mr.rows] * mr.extra["w"]).reshape(-1)

        sq = [q(E[i]) for i in range(len(names))]
        pairs = [(i, j) for i in range(len(names)) for j in range(i, len(names))]
        cols = [sq[i] if i == j else q(E[i] + E[j]) - sq[i] - sq[j] for i, j in pairs]
        cache[k] = (np.stack(cols, axis=1), pairs)
    return cache[k]


def _second_jacobian(mruns, terms, theta, shape, h: float = 1e-4) -> np.ndarray:
    """d(second-order force)/d(coefficient), stacked like ``X`` (central differences:
    exact for a quadratic); zeros without a second-order term."""
    out = np.zeros(shape)
    if not any(getattr(t.law, "second_order", None) for t in terms):
        return out
    off = _offsets(terms)
    for i, t in enumerate(terms):
        if not getattr(t.law, "second_order", None):
            continue
        for j in range(len(t.law.linears)):
            up, dn = np.array(theta, float), np.array(theta, float)
            up[off[i] + j] += h
            dn[off[i] + j] -= h
            out[:, off[i] + j] = (_second_stack(mruns, terms, up) - _second_stack(mruns, terms, dn)) / (2 * h)
    return out


def _offsets(terms) -> list:
    """Index of each term's first linear coefficient in the stacked ``theta``."""
    return [int(k) for k in np.cumsum([0] + [len(t.law.linears) for t in terms])[:-1]]


def _residuals(mruns, terms, theta) -> list:
    """Each run's residual less the terms' force at coefficients ``theta`` (stacked)."""
    out = []
    for mr in mruns:
        e = mr.residual.copy()
        k = 0
        for t in terms:
            if getattr(t.law, "second_order", None):
                e -= mr.demean(mr.second(t.law, t.where, t.shape, _term_values(t, theta, k)))
            for Q in mr.columns(t.law, t.where, t.shape):
                e -= theta[k] * mr.demean(Q)
                k += 1
        out.append(e)
    return out


def predict(mruns, fit: Fit) -> list:
    """Residuals of other runs (held out) with the fitted terms' values."""
    return _residuals(mruns, fit.terms, fit.theta)


def flatness(mruns, residuals) -> float:
    """Mean spectral flatness of the residual over runs and DOFs (1: white)."""
    from sim.calibrate.residuals import spectral_flatness

    vals = []
    for mr, e in zip(mruns, residuals):
        for j in range(e.shape[1]):
            if mr.excited is not None and not mr.excited[j]:
                continue
            x = e[:, j][mr.rows]
            if np.any(x):
                vals.append(spectral_flatness(x, 1.0 / mr.dt))
    return float(np.mean(vals)) if vals else 0.0


__all__ = ["Fit", "Term", "fit_terms", "flatness", "predict", "scan_limits", "walk_edges"]
