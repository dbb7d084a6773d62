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

from sim.calibrate.acceptance import holdout_not_enough
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
    #: held-out NRMSE per run (pooled over its excited columns), before and after
    per_run: dict = field(default_factory=dict)
    #: "<run>:<channel or DOF>" the held-out runs do not excite: left out of every error above
    not_excited: list = field(default_factory=list)
    #: the description's [unknown] values identified first (sim/calibrate/unknowns.py)
    unknowns_identified: dict = field(default_factory=dict)
    # arrays for the report (not in the JSON)
    series: dict = field(default_factory=dict, repr=False)
    #: the linear ARX baseline on the same fit and held-out runs (:mod:`sim.calibrate.baseline`)
    baseline: dict | None = None
    #: the calibrated model's held-out error is below the baseline's (None: no baseline)
    beats_baseline: bool | None = None
    #: each residual path's own figures (:func:`sim.calibrate.stages.summary`)
    paths: dict = field(default_factory=dict)

    def searched_paths(self) -> list[str]:
        """The residual paths the search ran on (a path the records could not take is in
        ``paths`` with the reason it was left out)."""
        return [k for k, p in self.paths.items() if "skipped" not in p] or [self.residual_path]

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
            "per_run",
            "not_excited",
            "baseline",
            "beats_baseline",
            "timing",
            "unknowns_identified",
            "paths",
        )
        return {k: getattr(self, k) for k in keys}


# ------------------------------------------------------------------ inputs
def load_runs(paths, table=None):
    """Read the runs; check they share a table and a sample rate."""
    from sim.runs.runfile import read_run

    runs = [read_run(p) for p in paths]
    check_one_table(runs)
    rates = {float(r.sample_rate_hz) for r in runs}
    if len(rates) > 1:
        raise CalibrationError(
            f"{runs[-1].name}: sample rates differ between runs ({', '.join(f'{x:g}' for x in sorted(rates))} Hz); "
            "resample the runs to one rate"
        )
    return runs


def check_one_table(runs) -> None:
    """One-line error when the runs name different tables (``meta.table``): one
    calibration is of one table, and ``--table`` does not make runs of another one its
    records (it only replaces the description they are replayed through)."""
    first = runs[0]
    other = next((r for r in runs[1:] if r.meta["table"] != first.meta["table"]), None)
    if other is not None:
        raise CalibrationError(
            f"{other.name}: runs of different tables (meta.table '{other.meta['table']}' here, "
            f"'{first.meta['table']}' in {first.name}); calibrate the runs of one table at a time "
            "(--table replaces the description they are replayed through, not the table they were recorded on)"
        )


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
def param_report(term, values: dict, sigma: dict, limits: dict | None = None) -> tuple[bool, str, dict]:
    """Are the parameters off their bounds (a scanned one: off its scan's limits,
    ``limits``, default :func:`sim.calibrate.trace.scan_limits` without a record rate)
    with a finite 95 % interval excluding zero?"""
    from sim.calibrate.acceptance import bound_hit, linear_holds_bound

    law = term.law
    unc = {name: Z95 * sigma.get(name, math.inf) for name in law.params}  # every one, also on a refusal
    for name, (unit, lo, hi) in law.params.items():
        v, s = values[name], sigma.get(name, math.inf)
        if not math.isfinite(s):
            return False, f"{name}: no finite confidence interval", unc
        if bound_hit(v, lo, hi, 1e-3 * max(abs(v), 1e-12)):
            return False, f"{name} = {v:.4g} {unit} at or beyond its bounds [{lo:g}, {hi:g}]", unc
        if name in law.shape:
            a, b = (limits or {}).get(name) or _limits(law, name)
            if bound_hit(v, a, b, 1e-3 * max(abs(v), 1e-12)):
                return False, f"{name} = {v:.4g} at the limit of its scan [{a:g}, {b:g}]", unc
        elif abs(v) <= Z95 * s and len(law.linears) == 1:
            return False, f"{name} = {v:.4g} {unit}: its 95 % interval +/-{Z95 * s:.3g} includes zero", unc
        elif linear_holds_bound(law, name, v, s):
            return False, f"{name} = {v:.4g} +/-{Z95 * s:.3g} {unit} holds its bound: the nested law without it", unc
    lin = law.linears
    if len(lin) > 1 and all(abs(values[k]) <= Z95 * sigma[k] for k in lin):
        # the components of one vector (a CG offset): one of them must differ from zero
        return False, f"{', '.join(lin)}: every 95 % interval includes zero", unc
    for name, (at, simpler) in getattr(law, "nested", {}).items():
        if abs(values[name] - at) <= Z95 * sigma.get(name, math.inf):
            return False, f"{name} = {values[name]:.4g} +/-{unc[name]:.3g} holds {at:g}: that is {simpler}", unc
    return True, "", unc


def _limits(law, name) -> tuple[float, float]:
    """A scanned parameter's limits without a record rate ("nyquist": unbounded)."""
    grid = law.shape[name]
    lo, hi = law.limits.get(name, (min(grid), max(grid)))
    return float(lo), (math.inf if hi == "nyquist" else float(hi))


def accept(cur, new, e_ho_cur, e_ho_new, flat_cur, flat_new, term, margin=HOLDOUT_MARGIN, limits=None):
    """``(accepted, reason, uncertainty)`` of adding ``term`` (fit ``new`` vs ``cur``)."""
    i = [t.key for t in new.terms].index(term.key)
    ok, why, unc = param_report(new.terms[i], new.values[i], new.sigma[i], limits)
    if not ok:
        return False, why, unc
    ok, why = accept_numbers(e_ho_cur, e_ho_new, cur.bic, new.bic, flat_cur, flat_new, margin)
    return ok, why, unc


def accept_numbers(e_ho_cur, e_ho_new, bic_cur, bic_new, flat_cur, flat_new, margin=HOLDOUT_MARGIN):
    """The numbers every path judges (:func:`sim.calibrate.acceptance.accept_numbers`)."""
    from sim.calibrate.acceptance import accept_numbers as judge

    return judge(e_ho_cur, e_ho_new, bic_cur, bic_new, flat_cur, flat_new, margin)


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
            if not np.any(x) or (mr.excited is not None and not mr.excited[j]):  # noise over nothing
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
def declared_model(run, table: str | None, payload: str | None):
    """The table description and payload the calibration starts from: ``table`` /
    ``payload`` when given (``payload="none"``: no specimen declared); else, for a run
    imported from a lab's export, the descriptions the import carried into it (the lab's
    declaration); else the stock ones its ``meta`` names. A simulated run's carried
    description is the simulator's truth, effects planted in it included, not a
    declaration: calibrating against it would find nothing to add."""
    import mjcf
    from sim.runs.runfile import payload_of, table_of

    imported = "imported_from" in run.meta or "table_path" in run.meta
    if table or imported:
        desc = table_of(run, table)
    else:
        desc = mjcf.load_table(run.meta["table"])
    if payload is not None or imported:
        return desc, payload_of(run, payload)
    name = run.meta.get("payload")
    declared = isinstance(name, str) and name.strip().lower() not in ("", "none")
    return desc, mjcf.load_payload(name) if declared else None


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
    docstring. ``path``: narrow the search to one residual path (default: every path the
    runs support, :mod:`sim.calibrate.stages`); ``workers``: processes of the replay and
    closed-loop searches (default: every core)."""
    from sim.calibrate.mechsearch import mechanical_stage
    from sim.calibrate.stages import plan, run_stages
    from sim.calibrate.unknowns import identify as identify_unknowns

    say = log or (lambda *_: None)
    t0 = time.perf_counter()
    runs, ho_given, desc, pl = _inputs(run_paths, holdout, table, payload, effects, effect_file, path)
    stages = plan(runs + ho_given, path)
    desc, unk = identify_unknowns(runs, ho_given, desc, pl, workers=workers, say=say)

    def search_one(p, d, eff):
        t_stage = time.perf_counter()  # each path's timing from its own start
        if p == "mechanical":
            kw = {"payload": payload, "accel_lowpass_hz": accel_lowpass_hz}
            res = mechanical_stage(runs, ho_given, d, pl, effects=eff, margin=margin, say=say, t0=t_stage, **kw)
        else:
            res = _calibrate_path(runs, ho_given, d, pl, p, eff, margin, workers, say, t_stage)
        return _with_baseline(res, say)

    kw = {"effects": effects, "search_one": search_one, "say": say, "workers": workers}
    res = run_stages(runs, ho_given, desc, pl, stages, **kw)
    res.unknowns_identified = unk
    res.timing["total_s"] = time.perf_counter() - t0  # the unknowns, every path and the pooled verdict
    if not res.paths:
        from sim.calibrate.stages import summary

        res.paths = {res.residual_path: summary(res)}
    return res


def _inputs(run_paths, holdout, table, payload, effects, effect_file, path):
    """The fit runs, the given held-out runs, the declared description and payload,
    each checked (one-line errors)."""
    from sim.calibrate.residuals import PATHS

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
    desc, pl = declared_model(runs[0], table, payload)
    for r in all_runs:
        if list(r.actuators) != list(desc.actuator_names):
            raise CalibrationError(
                f"{r.name}: actuators {r.actuators} do not match table '{desc.name}' "
                f"({list(desc.actuator_names)}); give --table"
            )
    return runs, ho_given, desc, pl


def _with_baseline(res: CalibrationResult, say) -> CalibrationResult:
    """``res`` with the linear ARX baseline fitted on its fit runs and scored on its
    held-out runs (:func:`sim.calibrate.baseline.attach`)."""
    from sim.calibrate.baseline import attach

    attach(res)
    say(f"linear ARX baseline (free run): held-out NRMSE {res.baseline['holdout_error']:.4f}")
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


# the mechanical stage's helpers, where they were before (sim.calibrate.mechsearch)
def mechanical_errors(mho, before, after):
    from sim.calibrate.mechsearch import mechanical_errors as errors

    return errors(mho, before, after)


# ------------------------------------------------------------------ outputs
def effect_entry(e: dict, tag: str) -> tuple[dict, dict]:
    """The description's ``[[effect]]`` entry of an ``effects_added`` item (sourced with
    ``tag``) and the comments of its parameters' lines."""
    opts = e.get("options", {})  # a variant of the effect (friction growing with the stroke)
    entry = {"type": e["name"], "where": e["where"], **opts, **e["parameters"], "source": tag}
    if "label" in e:  # one of several terms of a law at a place (a specimen's modes)
        entry = {"type": e["name"], "where": e["where"], "name": e["label"], **e["parameters"], "source": tag}
    comments = {
        k: f"+/-{e['uncertainty'][k]:.3g} {e['units'][k]} (95 %)"
        if k in e["uncertainty"]
        else "fixed at its bound (the nested law), not fitted"
        if k in e.get("fixed", {})
        else "held at the description's value, not fitted"
        for k in e["parameters"]
    }
    return entry, comments


def write_outputs(result: CalibrationResult, out, run_names) -> dict:
    """``calibration.json`` and ``<table>_calibrated.toml`` (the original with every
    comment kept and the accepted ``[[effect]]`` entries, sourced) into ``out``."""
    from sim.calibrate.description import TomlText
    from sim.calibrate.unknowns import write_identified
    from sim.runs.files import write_json_atomic

    out = Path(out)
    tag = "calibrated: shaketable calibrate " + " ".join(Path(p).name for p in run_names)
    doc = TomlText.read(result.table_source)
    for e in result.effects_added:
        entry, comments = effect_entry(e, tag)
        doc.set_effect(entry, comments=comments)
    write_identified(doc, result.unknowns_identified, tag)
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
    "holdout_not_enough",
    "load_runs",
    "split_holdout",
    "unexplained",
    "write_outputs",
]
