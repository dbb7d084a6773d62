"""A black-box linear baseline for every ``shaketable calibrate`` report.

A calibrated physical model is worth its parameters only if it predicts held-out runs
better than a model that knows no physics at all. The baseline here is an ARX model
(AutoRegressive with eXogenous inputs; Ljung, *System Identification: Theory for the
User*, 2nd ed., 1999, ch. 4), one multi-input single-output model per compared column:

    y(t) = sum_{k=1..na} alpha_k y(t-k) + sum_i sum_{l=0..nb-1} beta_{i,l} u_i(t-nk-l) + c

* **Inputs**: what the path's physical model is driven by, and nothing else: the valve
  commands on the replay path (with the same per-run valve null estimate the replay
  uses, :attr:`sim.calibrate.paths.PathRun.drive`), the reference pose on the
  closed-loop path, the recorded table motion (displacement, velocity, acceleration of
  every DOF) on the mechanical path, where the output is the actuator force in DOF space.
  Input columns that never move in the fit runs carry no information and are left out.
* **Outputs**: the columns the calibration compares (force, acceleration, velocity ...),
  as recorded (band-passed displacement where the path compares that).
* **Fit**: linear least squares of the equation error on the SAME fit runs the
  calibration fits (the mechanical path's equations only at the samples its fit uses);
  the best of each output order then also refined to the free-run (output) error
  (:func:`refine_output_error`): least squares is biased when what a linear model cannot
  explain is large and coloured (dry friction), and the output-error model is kept where
  it predicts the fit runs' last part better (on the lab example's friction table with a
  two-storey specimen, held out: 51 % -> 6.9 %, the calibrated model 0.74 %).
* **Prediction: free run (simulation), not one-step-ahead.** Each held-out run is
  simulated from its first sample with the model's own past outputs, from rest at the
  run's first input values (steady state), as the physical model replays the run open
  loop: neither sees a recorded output after the start. A one-step-ahead predictor reads
  the recorded output of the previous sample; at 1 kHz that is nearly the answer and no
  physical replay could compete with it, so it would be no fair comparison.
* **Score**: the SAME NRMSE and pooling as the calibration's held-out error
  (:func:`sim.calibrate.paths.nrmse` / :func:`sim.calibrate.residuals.nrmse_runs`), on
  the SAME held-out runs and rows.
* **Orders**: a small grid (:data:`NA`, :data:`NB`, :data:`NK`) chosen per column on the
  fit runs only: fitted on the first 70 % of every fit run, each candidate (the
  :data:`SHORTLIST` best of each ``na`` by the one-step error there, which costs no
  simulation) simulated free-run through the whole run and scored on its last 30 %; the
  best stable one (orders and estimator) is refitted on all of the fit runs. A candidate with a pole on or outside the unit circle
  (an unstable or drifting free run) is skipped; ``na = 0`` (a finite impulse response)
  is always stable, so every column gets a model.

Numpy/scipy only; the normal equations are accumulated once per run (every lag of every
input and output, at most :data:`MAX_EQUATIONS` equations) and each grid point is a small
solve on a block of them.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: output (autoregressive) orders tried; 0: a finite impulse response, always stable
NA = (0, 1, 2, 3, 4, 6, 8)
#: input orders tried (taps per input)
NB = (1, 2, 3, 4, 6, 8)
#: input delays tried, in samples (a valve's or a conditioner's lag of a few ms)
NK = (0, 1, 2, 3)
#: candidates of each output order simulated free-run (the best by the one-step screen)
SHORTLIST = 4
#: Levenberg-Marquardt steps of the output-error refinement (:func:`refine_output_error`)
OE_STEPS = 8
#: fit records up to this many samples x parameters refine the best ARX of every output
#: order as output-error models (the lab example: 1.6e5), up to OE_LIMIT the best one
#: only, beyond it none (two 60 s, 12-valve CGS records: 1.3e7; each refinement step
#: filters every regressor over every sample: 30 s a column on the loaded 2-core machine)
OE_SMALL = 2_000_000
OE_LIMIT = 6_000_000
#: share of each fit run (its end) the orders are chosen on
VALIDATION_SHARE = 0.3
#: a pole this close to the unit circle is a drifting integrator over a record (time
#: constant > 1e6 samples, 16 min at 1024 Hz): the free run is not trusted, the order skipped
POLE_LIMIT = 1.0 - 1e-6
#: ridge on the unit-diagonal (Jacobi-scaled) normal equations: numerical only, it keeps
#: the solve defined when lagged inputs are collinear (a slow signal sampled at 1 kHz)
RIDGE = 1e-10
#: equations fitted at most, over all fit runs (longer records: every k-th sample's; two
#: 60 s CGS runs at 1024 Hz hold 123 000)
MAX_EQUATIONS = 40_000
#: rows of the regressor matrix built at a time (memory: rows x columns x 8 bytes)
CHUNK = 8192
#: the acceleration band issue #23 judges a calibration in (the specimen modes of a
#: light uni-axial table, 7.5 and 19.9 Hz, sit in it)
ACCEL_BAND_HZ = (0.0, 20.0)

LU = max(NK) + max(NB) - 1  # the largest input lag of the grid
LY = max(NA)  # the largest output lag


@dataclass
class Record:
    """One run as the baseline sees it: inputs, outputs by column key, the samples fitted."""

    name: str
    u: np.ndarray  # (n, p) inputs
    ys: dict  # column key -> (n,) recorded output
    fit: np.ndarray  # bool (n,): the samples whose equations are fitted
    demean: bool = False  # scored with the mean removed (the mechanical path's residual is)


@dataclass
class Arx:
    """One fitted ARX model: ``a = [1, -alpha_1, ..]``, ``b`` (p, nb) taps from delay ``nk``."""

    na: int
    nb: int
    nk: int
    a: np.ndarray
    b: np.ndarray
    c: float
    #: how its parameters were fitted: "least_squares" (the ARX equation error) or
    #: "output_error" (the free-run error, :func:`refine_output_error`)
    estimator: str = "least_squares"

    def stable(self) -> bool:
        return self.na == 0 or float(np.max(np.abs(np.roots(self.a)))) < POLE_LIMIT

    def simulate(self, u: np.ndarray) -> np.ndarray:
        """Free run over inputs ``u`` (n, p), from rest at the first sample's values: the
        input history before the record is its first value, the output the steady state."""
        from scipy.signal import lfilter, lfilter_zi

        n = len(u)
        # (n, nb): each tap's input sum, shifted below by its lag (einsum, not BLAS: a
        # threaded BLAS on a tall thin product was 5x slower on a loaded 2-core machine)
        V = np.einsum("ij,jk->ik", u, self.b)
        w = np.full(n, self.c)
        for k in range(self.nb):
            lag = self.nk + k
            w[lag:] += V[: n - lag, k]
            w[: min(lag, n)] += V[0, k]  # before the record: its first value
        if self.na == 0:
            return w
        y, _ = lfilter([1.0], self.a, w, zi=lfilter_zi([1.0], self.a) * w[0])
        return y


# ------------------------------------------------------------------ least squares
def _lags(x: np.ndarray, lags, t: np.ndarray) -> np.ndarray:
    """``x[t - lag]`` for each lag, side by side (before the record: its first value, at rest)."""
    x = x if x.ndim == 2 else x[:, None]
    return np.concatenate([x[np.maximum(t - lag, 0)] for lag in lags], axis=1)


def _gram(rec: Record, keys: list, mask: np.ndarray) -> tuple[np.ndarray, list]:
    """The normal equations over the samples ``mask``, in the parts the keys need: the
    input block [every input at lags 0..LU, 1] against itself and every key's [lags
    1..LY, value] (``A``), and each key's own block (``Y``). The keys' blocks against one
    another are never used and not computed."""
    idx = np.flatnonzero(mask)
    head = rec.u.shape[1] * (LU + 1) + 1
    A = np.zeros((head, head + len(keys) * (LY + 1)))
    Y = [np.zeros((LY + 1, LY + 1)) for _ in keys]
    for s in range(0, len(idx), CHUNK):
        t = idx[s : s + CHUNK]
        Zu = np.concatenate([_lags(rec.u, range(LU + 1), t), np.ones((len(t), 1))], axis=1)
        Zy = [_lags(rec.ys[k], range(1, LY + 1), t) for k in keys]
        Zy = [np.concatenate([z, rec.ys[k][t][:, None]], axis=1) for k, z in zip(keys, Zy)]
        A += Zu.T @ np.concatenate([Zu, *Zy], axis=1)
        for q, z in enumerate(Zy):
            Y[q] += z.T @ z
    return A, Y


def _key_block(gram: tuple, q: int) -> np.ndarray:
    """A run's normal equations for its ``q``-th key: inputs, constant, that key's lags and value."""
    A, Y = gram
    head = A.shape[0]
    C = A[:, head + q * (LY + 1) : head + (q + 1) * (LY + 1)]
    return np.block([[A[:, :head], C], [C.T, Y[q]]])


def _columns(p: int, na: int, nb: int, nk: int) -> list[int]:
    """Positions in a key's block of the regressors of orders (na, nb, nk): the input
    taps (lag-major), the constant, the output lags; the value itself is last of all."""
    head = p * (LU + 1)
    return [lag * p + i for lag in range(nk, nk + nb) for i in range(p)] + [head] + [head + k for k in range(1, na + 1)]


def _solve(G: np.ndarray, p: int, na: int, nb: int, nk: int) -> Arx | None:
    """The least-squares ARX of orders (na, nb, nk) from a key's block ``G``."""
    import scipy.linalg

    cols = _columns(p, na, nb, nk)
    A, g = G[np.ix_(cols, cols)], G[cols, -1]
    d = np.sqrt(np.diag(A))
    d[d == 0] = 1.0
    As = A / d[:, None] / d[None, :] + RIDGE * np.eye(len(cols))
    try:
        th = scipy.linalg.solve(As, g / d, assume_a="pos") / d
    except (np.linalg.LinAlgError, ValueError):
        return None
    if not np.all(np.isfinite(th)):
        return None
    b = th[: p * nb].reshape(nb, p).T
    return Arx(na, nb, nk, np.r_[1.0, -th[p * nb + 1 :]], b, float(th[p * nb]))


def _one_step_sse(G: np.ndarray, p: int, m: Arx) -> float:
    """The model's one-step-ahead squared error over the samples of a key's block ``G``
    (from the normal equations alone: ``y'y - 2 th'g + th'A th``). A cheap screen only:
    the orders are chosen by the free run (:func:`fit_column`)."""
    cols = _columns(p, m.na, m.nb, m.nk)
    th = np.r_[m.b.T.reshape(-1), m.c, -m.a[1:]]
    return float(G[-1, -1] - 2 * th @ G[cols, -1] + th @ G[np.ix_(cols, cols)] @ th)


def _ratio(y: np.ndarray, yhat: np.ndarray, rows: np.ndarray, demean: bool) -> float:
    """``sum e^2 / sum y^2`` over ``rows`` (both with their mean removed if ``demean``)."""
    e, x = (y - yhat)[rows], y[rows]
    if demean:
        e, x = e - e.mean(), x - x.mean()
    den = float(np.sum(x**2))
    return float(np.sum(e**2)) / den if den > 0 else math.nan


def _split_grams(recs: list[Record], keys: list) -> list[tuple]:
    """Per record: its keys among ``keys``, the normal equations of the first part of its
    fit samples and of the rest (the orders are chosen on the rest), and the rest's mask."""
    out = []
    # every stride-th equation of long records: neighbouring samples of a 1 kHz record
    # carry nearly the same equation, and the normal equations' cost grows with their count
    stride = max(1, math.ceil(sum(int(np.count_nonzero(r.fit)) for r in recs) / MAX_EQUATIONS))
    for r in recs:
        ks = [k for k in keys if k in r.ys]
        cut = np.arange(len(r.fit)) >= int((1 - VALIDATION_SHARE) * len(r.fit))
        fit = r.fit & (np.arange(len(r.fit)) % stride == 0)
        out.append((ks, _gram(r, ks, fit & ~cut), _gram(r, ks, fit & cut), cut))
    return out


def fit_column(recs: list[Record], key, grams=None) -> tuple[Arx | None, int]:
    """The linear model of output ``key`` from the records that have it, orders and
    estimator chosen on the fit records only (module docstring); ``(model, candidates
    skipped as unstable)``. ``grams``: :func:`_split_grams` of ``recs`` (made here if not given)."""
    grams = grams if grams is not None else _split_grams(recs, [key])
    have = [(r, g) for r, g in zip(recs, grams) if key in g[0]]
    if not have:
        return None, 0
    p = have[0][0].u.shape[1]
    G_train = sum(_key_block(g[1], g[0].index(key)) for _r, g in have)
    G_all = G_train + sum(_key_block(g[2], g[0].index(key)) for _r, g in have)
    ranked, skipped = _rank_arx(have, key, p, G_train, G_all - G_train)
    train = [(r.u, r.ys[key], r.fit & ~g[3]) for r, g in have]
    ranked += _rank_oe(ranked, have, key, train)
    for _err, kind, na, nb, nk, _m in sorted(ranked, key=lambda c: c[:2]):  # the best refitted on everything
        m = _solve(G_all, p, na, nb, nk)
        if m is not None and m.stable() and kind == "output_error":
            m = refine_output_error(m, [(r.u, r.ys[key], r.fit) for r, _g in have])
        if m is not None and m.stable():
            return m, skipped
        skipped += 1
    return None, skipped


def _validation(m: Arx, have, key) -> float:
    """Mean over the fit records of the free run's ``sum e^2 / sum y^2`` on their last part."""
    errs = [_ratio(r.ys[key], m.simulate(r.u), r.fit & g[3], r.demean) for r, g in have]
    return float(np.nanmean(errs)) if np.any(np.isfinite(errs)) else math.inf


def _rank_arx(have, key, p, G_train, G_rest) -> tuple[list, int]:
    """Every grid point's least-squares ARX on the first part of the fit records, the
    stable ones screened by their one-step error on the rest (the SHORTLIST best of each
    na: the one-step error favours output feedback the free run may not) and scored by
    their free run there: ``[(error, "arx", na, nb, nk, model)]`` and the unstable count."""
    screened, skipped = {}, 0
    for na, nb, nk in itertools.product(NA, NB, NK):
        m = _solve(G_train, p, na, nb, nk)
        if m is None or not m.stable():
            skipped += 1
            continue
        screened.setdefault(na, []).append((_one_step_sse(G_rest, p, m), nb, nk, m))
    ranked = []
    for na, cands in screened.items():
        for _sse, nb, nk, m in sorted(cands, key=lambda c: c[0])[:SHORTLIST]:
            ranked.append((_validation(m, have, key), "arx", na, nb, nk, m))
    return ranked, skipped


def _rank_oe(ranked, have, key, train) -> list:
    """The best ARX of each output order (the best one only when the fit records are
    large: samples x regressors over :data:`OE_SMALL`; none over :data:`OE_LIMIT`) refined
    as output-error models on the first part of the fit records and scored by their free
    run on the rest."""
    best: dict = {}
    for c in sorted(ranked, key=lambda c: c[0]):
        if c[2] > 0 and c[2] not in best:
            best[c[2]] = c
    picks = sorted(best.values(), key=lambda c: c[0])
    size = sum(len(u) for u, _y, _rows in train) * max((c[5].b.size + c[2] for c in picks), default=0)
    out = []
    for _err, _kind, na, nb, nk, m in picks if size <= OE_SMALL else picks[:1] if size <= OE_LIMIT else []:
        oe = refine_output_error(m, train)
        out.append((_validation(oe, have, key), "output_error", na, nb, nk, oe))
    return out


# ------------------------------------------------------------------ output error
def _theta(m: Arx) -> np.ndarray:
    return np.r_[m.b.T.reshape(-1), m.c, -m.a[1:]]


def _with_theta(m: Arx, th: np.ndarray) -> Arx:
    p = m.b.shape[0]
    k = p * m.nb
    return Arx(m.na, m.nb, m.nk, np.r_[1.0, -th[k + 1 :]], th[:k].reshape(m.nb, p).T, float(th[k]), "output_error")


def _sse(m: Arx, data) -> float:
    return sum(float(np.sum((y - m.simulate(u))[rows] ** 2)) for u, y, rows in data)


def _output_error_normal(m: Arx, data) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton normal equations of the free-run error: the gradient of the simulated
    output is the regressors with the model's own output lags filtered by ``1/A``
    (Ljung 1999, sec. 10.2), at most :data:`MAX_EQUATIONS` rows of them."""
    n_rows = sum(int(np.count_nonzero(rows)) for _u, _y, rows in data)
    stride = max(1, math.ceil(n_rows / MAX_EQUATIONS))
    JtJ, Jte = 0.0, 0.0
    for u, y, rows in data:
        yh = m.simulate(u)
        t = np.arange(len(u))
        sel = rows & (t % stride == 0)
        J = np.concatenate(
            [
                _filtered_lags(u, range(m.nk, m.nk + m.nb), m.a, sel),
                _filtered_lags(np.ones(len(u)), [0], m.a, sel),
                _filtered_lags(yh, range(1, m.na + 1), m.a, sel),
            ],
            axis=1,
        )
        JtJ, Jte = JtJ + J.T @ J, Jte + J.T @ (y - yh)[sel]
    return JtJ, Jte


def _filtered_lags(x: np.ndarray, lags, a: np.ndarray, sel: np.ndarray) -> np.ndarray:
    """``1/A`` applied (from rest) to each lag of ``x`` as :func:`_lags` lays them out, at
    the rows ``sel``, with one filter pass per column of ``x`` instead of one per lag: a lag
    of ``x`` is its first value held plus ``x - x[0]`` delayed with zeros before it, and a
    delay commutes with the filter (exact; the output-error fit's filtering was 90 % of a
    60 s 12-actuator record's baseline)."""
    from scipy.signal import lfilter

    x = x if x.ndim == 2 else x[:, None]
    lags = list(lags)
    t = np.flatnonzero(sel)
    if not lags:
        return np.zeros((len(t), 0))
    held = lfilter([1.0], a, np.ones(len(x)))[t, None] * x[0]  # the first value held from the start
    pad = max(lags)
    moved = np.concatenate([np.zeros((pad, x.shape[1])), lfilter([1.0], a, x - x[0], axis=0)])
    return np.concatenate([held + moved[t + pad - lag] for lag in lags], axis=1)


def refine_output_error(m: Arx, data, steps: int = OE_STEPS) -> Arx:
    """The model's parameters moved to minimise its free-run squared error over ``data``
    (``[(u, y, rows)]``): an output-error fit (Levenberg-Marquardt from the least-squares
    ARX, every step kept stable). Least squares minimises the one-step equation error; when
    what the model cannot explain is large and coloured (dry friction against a linear
    model) that biases the poles it finds, and its free run suffers; this is the best
    linear simulation model near it. An FIR (``na = 0``) is its own output-error model."""
    import scipy.linalg

    if m.na == 0:
        return m
    best, sse, lam = m, _sse(m, data), 1e-3
    for _ in range(steps):
        JtJ, Jte = _output_error_normal(best, data)
        d = np.sqrt(np.diag(JtJ))
        d[d == 0] = 1.0
        A = JtJ / d[:, None] / d[None, :]
        for _try in range(4):  # damping raised until a step lowers the error and stays stable
            try:
                step = scipy.linalg.solve(A + lam * np.eye(len(d)), Jte / d, assume_a="pos") / d
            except (np.linalg.LinAlgError, ValueError):
                step = None
            cand = _with_theta(best, _theta(best) + step) if step is not None else None
            if cand is not None and cand.stable() and (s2 := _sse(cand, data)) < sse:
                best, sse, lam = cand, s2, lam / 10
                break
            lam *= 10
        else:
            break
    return best


def fit_models(recs: list[Record], keys: list) -> tuple[dict, int]:
    """``{key: Arx or None}`` for every output key, and the unstable candidates skipped."""
    grams = _split_grams(recs, keys)  # every lag of every input once per record, shared by the keys
    out, skipped = {}, 0
    for k in keys:
        out[k], s = fit_column(recs, k, grams)
        skipped += s
    return out, skipped


# ------------------------------------------------------------------ the paths
def _moving(inputs: list[np.ndarray]) -> np.ndarray:
    """Indices of the input columns that move in some fit run."""
    return np.flatnonzero(np.any([np.ptp(u, axis=0) > 0 for u in inputs], axis=0))


def _path_records(prs, cols) -> list[Record]:
    return [
        Record(
            name=pr.name,
            u=np.asarray(pr.drive, float)[:, cols],
            ys={(ch, j): pr.recorded[ch][:, j] for ch in pr.recorded for j in range(pr.recorded[ch].shape[1])},
            fit=np.ones(pr.n, bool),
        )
        for pr in prs
    ]


def path_baseline(pfit, pho) -> dict:
    """The baseline on the replay or closed-loop path: fitted on ``pfit``, scored on
    ``pho`` (lists of :class:`sim.calibrate.paths.PathRun`) as the calibration scores."""
    from sim.calibrate import paths as P

    cols = _moving([np.asarray(p.drive, float) for p in pfit])
    keys = sorted({(ch, j) for pr in pho for ch, js in pr.columns.items() for j in js})
    models, skipped = fit_models(_path_records(pfit, cols), keys)
    preds = []
    for pr in pho:
        u = np.asarray(pr.drive, float)[:, cols]
        pred = {ch: np.zeros_like(pr.recorded[ch]) for ch in pr.columns}
        for ch, js in pr.columns.items():
            for j in js:
                m = models.get((ch, j))
                pred[ch][:, j] = m.simulate(u) if m is not None else 0.0
        preds.append(pred)
    per = {}
    for pr, m in zip(pho, preds):
        per.update({f"{Path(pr.name).name}:{k}": v for k, v in P.column_errors(pr, m).items()})
    first = pho[0]
    orders = {
        f"{ch}[{P._place(first, ch, j)}]": _orders(m)  # a DOF, an actuator or a specimen sensor
        for (ch, j), m in models.items()
    }
    out = _summary(P.nrmse(pho, preds), per, orders, skipped)
    out["inputs"] = "valve_command" if pho[0].path == "replay" else "reference"
    return out | {"_predictions": preds}


def _mech_records(mruns) -> list[Record]:
    return [
        Record(
            name=mr.name,
            u=np.concatenate([mr.u, mr.v, mr.a], axis=1),
            ys={j: mr.force[:, j] for j in range(len(mr.dofs))},
            fit=np.asarray(mr.rows, bool),
            demean=True,
        )
        for mr in mruns
    ]


def mechanical_baseline(mfit, mho) -> dict:
    """The baseline on the mechanical path (table motion in, force in DOF space out),
    fitted on ``mfit``, scored on ``mho`` (lists of :class:`sim.calibrate.residuals.MechRun`)."""
    from sim.calibrate.residuals import nrmse_runs

    fit_recs = _mech_records(mfit)
    cols = _moving([r.u for r in fit_recs])
    for r in fit_recs:
        r.u = r.u[:, cols]
    keys = list(range(len(mfit[0].dofs)))
    models, skipped = fit_models(fit_recs, keys)
    residuals, per = [], {}
    for mr in mho:
        u = np.concatenate([mr.u, mr.v, mr.a], axis=1)[:, cols]
        pred = np.stack([models[j].simulate(u) if models[j] is not None else np.zeros(len(u)) for j in keys], axis=1)
        e = mr.demean(mr.force - pred)
        residuals.append(e)
        for j, d in enumerate(mr.dofs):
            per[f"{Path(mr.name).name}:{d}"] = nrmse_runs([_one_dof(mr, j)], [e[:, [j]]])
    orders = {f"force[{d}]": _orders(models[j]) for j, d in enumerate(mfit[0].dofs)}
    out = _summary(nrmse_runs(mho, residuals), per, orders, skipped)
    out["inputs"] = "table_displacement, table_velocity, table_acceleration"
    return out


def _one_dof(mr, j):
    """A view of a mechanical run with only DOF ``j`` (for its own NRMSE): its own
    excitation flag and weight, and its own ``extra`` (the run's is not to be written)."""
    import copy

    one = copy.copy(mr)
    one.dofs, one.force = [mr.dofs[j]], mr.force[:, [j]]
    one.excited = None if mr.excited is None else np.asarray(mr.excited)[[j]]
    one.extra = {**mr.extra, "noise_weight": np.ones(1)}
    return one


def _orders(m: Arx | None) -> dict | None:
    return None if m is None else {"na": m.na, "nb": m.nb, "nk": m.nk, "estimator": m.estimator}


def _summary(pooled, per, orders, skipped) -> dict:
    return {
        "model": "ARX, one multi-input model per compared column; least squares on the fit runs "
        "(refined to the free-run error where that predicts the fit runs better); simulated free-run "
        "(not one-step-ahead) on the held-out runs",
        "free_run": True,
        "grid": {"na": list(NA), "nb": list(NB), "nk": list(NK), "validation_share": VALIDATION_SHARE},
        "orders": orders,
        "skipped_unstable": skipped,
        "holdout_error": float(pooled),
        "per_channel": per,
    }


# ------------------------------------------------------------------ a band of one channel
def band_error(prs, models, channel: str, band_hz) -> float:
    """Pooled NRMSE of ``channel`` in ``band_hz`` over the scored rows (as
    :func:`sim.calibrate.paths.nrmse`: root of the mean over runs and columns of
    ``sum |E(f)|^2 / sum |X(f)|^2`` over the band), the mean removed (a sensor's offset is
    not the table's motion); NaN when no run compares the channel or a model failed."""
    vals = []
    for pr, m in zip(prs, models):
        if m is None:
            return math.nan
        for j in pr.columns.get(channel, []):
            x = pr.recorded[channel][pr.rows][:, j]
            e = x - m[channel][pr.rows][:, j]
            f = np.fft.rfftfreq(len(x), pr.dt)
            w = (f >= band_hz[0]) & (f <= band_hz[1]) & (f > 0)
            X, E = np.fft.rfft(x - x.mean())[w], np.fft.rfft(e - e.mean())[w]
            den = float(np.sum(np.abs(X) ** 2))
            if den > 0:
                vals.append(float(np.sum(np.abs(E) ** 2)) / den)
    return float(math.sqrt(np.mean(vals))) if vals else math.nan


# ------------------------------------------------------------------ the verdict
def flag(error_after: float, baseline: dict | None) -> str | None:
    """The report's and the CLI's line when the calibrated model does not beat the
    baseline on the held-out runs (pooled NRMSE, and the acceleration band if scored)."""
    if not baseline or not math.isfinite(baseline.get("holdout_error", math.nan)):
        return None
    base = baseline["holdout_error"]
    lost = []
    if not error_after < base:
        lost.append(f"held-out NRMSE {100 * error_after:.2f} % calibrated vs {100 * base:.2f} % ARX")
    b = baseline.get("band")
    if b and math.isfinite(b["baseline"]) and not b["after"] < b["baseline"]:
        lo, hi = b["band_hz"]
        lost.append(
            f"{b['channel']} {lo:g}-{hi:g} Hz {100 * b['after']:.2f} % calibrated vs {100 * b['baseline']:.2f} % ARX"
        )
    if not lost:
        return None
    return "the calibrated model does not beat a linear ARX baseline on held-out runs: " + "; ".join(lost)


def beats(error_after: float, baseline: dict | None) -> bool | None:
    """Whether the calibrated model's pooled held-out error is below the baseline's
    (None without a baseline)."""
    if not baseline or not math.isfinite(baseline.get("holdout_error", math.nan)):
        return None
    return bool(error_after < baseline["holdout_error"])


def attach(res) -> None:
    """Fit the baseline for a finished calibration (its ``series``: the same fit and
    held-out runs) and set ``res.baseline``, ``res.beats_baseline`` and its time."""
    t0 = time.perf_counter()
    s = res.series
    if s.get("kind") == "path":
        out = path_baseline(s["fit"], s["holdout"])
        preds = out.pop("_predictions")
        if any("table_acceleration" in pr.columns for pr in s["holdout"]):
            ch = "table_acceleration"
            out["band"] = {
                "channel": ch,
                "band_hz": list(ACCEL_BAND_HZ),
                "before": band_error(s["holdout"], s["before"], ch, ACCEL_BAND_HZ),
                "after": band_error(s["holdout"], s["after"], ch, ACCEL_BAND_HZ),
                "baseline": band_error(s["holdout"], preds, ch, ACCEL_BAND_HZ),
            }
    else:
        out = mechanical_baseline(s["fit"], s["holdout"])
    res.baseline = out
    res.beats_baseline = beats(res.error_after, out)
    res.timing["baseline_s"] = time.perf_counter() - t0


__all__ = [
    "ACCEL_BAND_HZ",
    "Arx",
    "Record",
    "attach",
    "band_error",
    "beats",
    "fit_column",
    "fit_models",
    "flag",
    "mechanical_baseline",
    "path_baseline",
]
