"""Calibration identifies the values a description declares unknown, first.

A table file may hold an ``[unknown]`` table (``mjcf/unknowns.py``): dotted keys of the
description with the range (SI) the lab knows them to lie in. Before ``calibrate`` looks
for missing effects, :func:`identify` fits those values jointly, within their ranges, to
the fit runs on the replay path (recorded valve commands) or the closed-loop path (a
recorded reference): the same simulations as the effect search
(:meth:`sim.calibrate.paths.PathRun.job`, :func:`sim.calibrate.paths.simulate_many`),
with the description's own numbers changed, so that a dotted key acts on the model
exactly as the description is built (``"fluid.bulk_modulus_pa"`` is the bulk modulus of
every oil column, ``"servovalve.tau_s"`` every valve's time constant,
``"platen.mass_kg"`` the platen's mass).

* Keys declared with the same range and the same nominal are one parameter (the two
  chambers of an actuator class, given by the lab as one dead volume).
* Each parameter is fitted in the logarithm of its value (a range that starts at 0: in
  the value over the range's top), bounded by its range: a coarse scan of each
  parameter on its own (5 points over the range, one batch of simulations) gives the
  start, ``scipy.optimize.least_squares`` (trust region reflective, bounded, forward
  differences of one batch per Jacobian) the estimate.
* The 95 % interval is ``+/- 1.96 sigma`` in the fitted variable, sigma from the
  residual's autocorrelation within each compared column
  (:func:`sim.calibrate.hac.hac_sigma`), clipped to the range.
* The identified values are kept when the held-out error falls (held-out runs as the
  effect search splits them, :func:`sim.calibrate.holdout.split_for_replay`); else the nominals
  stay and the report says why.

The values enter the calibrated description with ``calibrated:`` on their lines
(:func:`write_identified`) and ``calibration.json`` as ``unknowns_identified``.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import numpy as np

Z95 = 1.96
SCAN_POINTS = 5  #: points of each parameter's start scan over its range
MAX_NFEV = 12  #: least-squares evaluations (each a batch of the fit runs' simulations)
STEP = 0.02  #: forward-difference step of the fitted variable (2 % of a value in log)


@dataclass
class Parameter:
    """One fitted value: the dotted keys it sets, its range and nominal (SI)."""

    keys: tuple
    lo: float
    hi: float
    nominal: float

    @property
    def log(self) -> bool:
        return self.lo > 0

    def to_z(self, v: float) -> float:
        return math.log(v) if self.log else v / self.hi

    def to_v(self, z: float) -> float:
        v = math.exp(z) if self.log else z * self.hi
        return min(max(v, self.lo), self.hi)  # exp(log(hi)) may round past hi: the loader refuses that

    @property
    def bounds(self) -> tuple[float, float]:
        return self.to_z(self.lo), self.to_z(self.hi)


def parameters(desc) -> list[Parameter]:
    """The description's unknowns as fitted parameters (tied keys grouped)."""
    from mjcf.unknowns import value_at

    groups: dict = {}
    for key, (lo, hi) in desc.unknowns.items():
        nominal = float(value_at(desc.raw, key))
        groups.setdefault((lo, hi, nominal), []).append(key)
    return [Parameter(tuple(keys), lo, hi, nom) for (lo, hi, nom), keys in groups.items()]


def with_values(raw: dict, params, values) -> dict:
    """A copy of the parsed description ``raw`` with each parameter's keys set."""
    from mjcf.unknowns import set_value_at

    out = copy.deepcopy(raw)
    for p, v in zip(params, values):
        for k in p.keys:
            set_value_at(out, k, float(v))
    return out


def _path_of(runs) -> str | None:
    """The path the identification runs on: replay where every run has valve commands,
    closed loop where every run has a reference, else none."""
    from sim.calibrate.paths import FIT_CHANNELS

    outputs = all(any(getattr(r, c) is not None for c in FIT_CHANNELS) for r in runs)
    if outputs and all(r.valve_command is not None for r in runs):
        return "replay"
    if outputs and all(r.reference is not None for r in runs):
        return "closed_loop"
    return None


class _Fit:
    """The fit runs' residual as a function of the fitted variables (one batch of
    simulations per set of points)."""

    def __init__(self, prs, desc, payload, params, workers):
        self.prs, self.desc, self.payload, self.params, self.workers = prs, desc, payload, params, workers
        self.replays = 0

    def models(self, zs) -> list:
        """The models of the runs at each point of ``zs`` (a list per point)."""
        from sim.calibrate import paths as P

        jobs = []
        for z in zs:
            raw = with_values(self.desc.raw, self.params, [p.to_v(x) for p, x in zip(self.params, z)])
            jobs += [pr.job(raw, str(self.desc.source), self.payload, []) for pr in self.prs]
        ms = P.simulate_many(jobs, workers=self.workers)
        self.replays += len(jobs)
        k = len(self.prs)
        return [ms[i * k : (i + 1) * k] for i in range(len(zs))]

    def residuals(self, zs) -> list:
        from sim.calibrate import paths as P

        return [P.stacked(self.prs, m) for m in self.models(zs)]


def _start(fit: _Fit, z0: np.ndarray) -> np.ndarray:
    """Each parameter at the best of a scan over its range, the others at their nominal."""
    pts, owner = [z0], [None]
    for i, p in enumerate(fit.params):
        lo, hi = p.bounds
        for x in np.linspace(lo, hi, SCAN_POINTS):
            z = z0.copy()
            z[i] = x
            pts.append(z)
            owner.append(i)
    cost = [float(r @ r) if r is not None else math.inf for r in fit.residuals(pts)]
    z = z0.copy()
    for i in range(len(fit.params)):
        best = min((c, k) for k, c in enumerate(cost) if owner[k] == i)
        if best[0] < cost[0]:
            z[i] = pts[best[1]][i]
    return z


def _solve(fit: _Fit, z_start: np.ndarray):
    """Bounded least squares from ``z_start``: ``(z, residual, jacobian)``."""
    from scipy.optimize import least_squares

    lo = np.array([p.bounds[0] for p in fit.params])
    hi = np.array([p.bounds[1] for p in fit.params])
    cache: dict = {}

    def fun(z):
        key = tuple(np.round(z, 12))
        if key not in cache:
            (r,) = fit.residuals([z])
            cache[key] = r
        r = cache[key]
        return r if r is not None else np.full(fit.n_res, 1e3)

    def jac(z):
        r0 = fun(z)
        steps = [STEP if z[i] + STEP <= hi[i] else -STEP for i in range(len(z))]
        pts = []
        for i, h in enumerate(steps):
            zi = z.copy()
            zi[i] += h
            pts.append(zi)
        rs = fit.residuals(pts)
        return np.stack([(r - r0) / h if r is not None else np.zeros_like(r0) for r, h in zip(rs, steps)], axis=1)

    (r0,) = fit.residuals([z_start])
    fit.n_res = len(r0)
    cache[tuple(np.round(z_start, 12))] = r0
    sol = least_squares(fun, np.clip(z_start, lo, hi), jac=jac, bounds=(lo, hi), method="trf", max_nfev=MAX_NFEV)
    return sol.x, fun(sol.x), jac(sol.x)


def _interval(p: Parameter, z: float, sigma: float) -> list[float]:
    a, b = z - Z95 * sigma, z + Z95 * sigma
    lo, hi = p.bounds
    return [p.to_v(max(a, lo)), p.to_v(min(b, hi))] if math.isfinite(sigma) else [p.lo, p.hi]


def identify(runs, ho_given, desc, payload, *, workers=None, say=None):
    """Fit the unknowns of ``desc`` to ``runs`` (hold-out as the search splits them);
    ``(description with the identified values, report)``; the description unchanged
    and the report empty when it declares no unknowns."""
    from mjcf.description import parse_table
    from sim.calibrate import paths as P
    from sim.calibrate.hac import hac_sigma
    from sim.calibrate.holdout import split_for_replay

    say = say or (lambda *_: None)
    params = parameters(desc)
    if not params:
        return desc, {}
    path = _path_of(list(runs) + list(ho_given or []))
    if path is None:
        why = "not identified: the runs have neither valve commands nor a reference with a recorded output"
        return desc, {"path": None, "note": why, "values": {}}
    fit_runs, ho_runs, score_from, _ = split_for_replay(list(runs), list(ho_given or []))
    pfit = P.path_runs(fit_runs, desc, path)
    pho = P.path_runs(ho_runs, desc, path, score_from=score_from)
    fit = _Fit(pfit, desc, payload, params, workers)
    z0 = np.array([p.to_z(p.nominal) for p in params])
    z, r, J = _solve(fit, _start(fit, z0))
    sigma = hac_sigma(J, r, P.residual_segments(pfit))
    values = [p.to_v(x) for p, x in zip(params, z)]
    hold = _Fit(pho, desc, payload, params, workers)
    m0, m1 = hold.models([z0, z])
    e0, e1 = P.nrmse(pho, m0), P.nrmse(pho, m1)
    kept = bool(np.isfinite(e1) and e1 < e0)
    report = {
        "path": path,
        "holdout_error_nominal": e0,
        "holdout_error_identified": e1,
        "accepted": kept,
        "note": "identified values kept: the held-out error falls"
        if kept
        else "identified values NOT kept (the held-out error does not fall): the nominals stay",
        "replays": fit.replays + hold.replays,
        "values": {},
    }
    for p, x, s, v in zip(params, z, sigma, values):
        for k in p.keys:
            report["values"][k] = {
                "value": v,
                "interval_95": _interval(p, x, float(s)),
                "range": [p.lo, p.hi],
                "nominal": p.nominal,
                "at_bound": bool(min(abs(x - b) for b in p.bounds) < 1e-6),
                "tied_with": [q for q in p.keys if q != k],
            }
    say(
        f"unknowns ({path} path): "
        + ", ".join(
            f"{k} {d['value']:.4g} [{d['interval_95'][0]:.4g}, {d['interval_95'][1]:.4g}]"
            for k, d in report["values"].items()
        )
        + f"; held-out NRMSE {e0:.4f} -> {e1:.4f}"
        + ("" if kept else " (not kept)")
    )
    if not kept:
        return desc, report
    return parse_table(with_values(desc.raw, params, values), src=desc.source), report


def write_identified(doc, report: dict, tag: str) -> None:
    """Write the kept identified values into ``doc`` (a :class:`sim.calibrate.description.TomlText`),
    each with ``calibrated: ...`` and its interval on its line; the ``[unknown]`` entry
    keeps the range (the value stays a fitted one) with the identified value noted."""
    if not report or not report.get("accepted"):
        return
    for key, d in report["values"].items():
        section, name = key.rsplit(".", 1)
        lo, hi = d["interval_95"]
        doc.set_value(section, name, float(d["value"]), f"{tag}; 95 % between {lo:.4g} and {hi:.4g} (was unknown)")
        doc.set_value(
            "unknown", f'"{key}"', None, f"identified {d['value']:.4g} ({tag})", value_text=_range(d["range"])
        )


def _range(r) -> str:
    from sim.calibrate.description import format_value

    return format_value([float(r[0]), float(r[1])])


__all__ = ["identify", "parameters", "with_values", "write_identified"]
