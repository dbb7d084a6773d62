"""``shaketable calibrate``: find what the declared model lacks in measured runs, add
it, prove it on held-out runs.

:func:`calibrate` reads and checks the runs (one-line errors), identifies the
description's unknown values first (:mod:`sim.calibrate.unknowns`), then searches every
residual path the runs support (:mod:`sim.calibrate.stages`): each path is one
:class:`sim.calibrate.engine.SearchPath` driven by the one search loop
(:func:`sim.calibrate.engine.search`: screen, refine, judge by
:mod:`sim.calibrate.acceptance`, take, revisit), the mechanical path in
:mod:`sim.calibrate.mechsearch`, the replay and closed-loop paths in
:mod:`sim.calibrate.pathsearch`. Each path's result gets the linear ARX baseline
(:mod:`sim.calibrate.baseline`); :func:`write_outputs` writes ``calibration.json`` and
the calibrated description. The names below from lower modules are kept here for the
callers that import them from this module.
"""

from __future__ import annotations

import time
from pathlib import Path

from sim.calibrate.acceptance import HOLDOUT_MARGIN, Z95, accept, holdout_not_enough, param_report
from sim.calibrate.engine import MAX_ROUNDS
from sim.calibrate.holdout import split_holdout
from sim.calibrate.mechsearch import candidate_laws, check_effect_names, mechanical_errors
from sim.calibrate.residuals import UNEXPLAINED_FRACTION, CalibrationError, unexplained
from sim.calibrate.result import CalibrationResult, effect_entry


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


# ------------------------------------------------------------------ acceptance
def accept_numbers(e_ho_cur, e_ho_new, bic_cur, bic_new, flat_cur, flat_new, margin=HOLDOUT_MARGIN):
    """The numbers every path judges (:func:`sim.calibrate.acceptance.accept_numbers`)."""
    from sim.calibrate.acceptance import accept_numbers as judge

    return judge(e_ho_cur, e_ho_new, bic_cur, bic_new, flat_cur, flat_new, margin)


# ------------------------------------------------------------------ the search
def declared_model(run, table: str | None, payload: str | None):
    """The table description and payload the calibration starts from: ``table`` /
    ``payload`` when given (``payload="none"``: no specimen declared); else, for a run
    imported from a lab's export, the descriptions the import carried into it (the lab's
    declaration); else the stock ones its ``meta`` names. A simulated run's carried
    description is the simulator's truth, effects planted in it included, not a
    declaration: calibrating against it would find nothing to add."""
    import mjcf
    from sim.loop.simulation import description_as_run
    from sim.runs.runfile import payload_of, table_of

    imported = "imported_from" in run.meta or "table_path" in run.meta
    if table or imported:
        desc = table_of(run, table)
    else:
        desc = mjcf.load_table(run.meta["table"])
    desc = refuse_unknowns_run_sets(desc, description_as_run(desc))  # the Rice table's parameter set
    if payload is not None or imported:
        return desc, payload_of(run, payload)
    name = run.meta.get("payload")
    declared = isinstance(name, str) and name.strip().lower() not in ("", "none")
    return desc, mjcf.load_payload(name) if declared else None


def refuse_unknowns_run_sets(desc, ran):
    """``ran`` (``desc`` as its controller runs it), unless a value ``desc`` marks
    ``[unknown]`` is one its controller sets: the Rice table's parameter set writes its
    bulk modulus, leakage and valve delay over the file's, so a value identified there and
    written into the calibrated file would be written over again by ``run``."""
    import copy

    from mjcf.description import parse_table
    from mjcf.unknowns import set_value_at, value_at
    from sim.loop.simulation import description_as_run

    for key, (lo, hi) in desc.unknowns.items():
        moved = copy.deepcopy(desc.raw)  # the value moved within its range: does `run` keep it?
        probe = lo + 0.618 * (hi - lo)  # any inside point but the ends; golden, to miss a round nominal
        set_value_at(moved, key, probe)
        if value_at(description_as_run(parse_table(moved, src=desc.source)).raw, key) != probe:
            c = desc.raw.get("controller", {})
            raise CalibrationError(
                f"{desc.source}: [unknown] '{key}' is set by controller.parameter_set "
                f"'{c.get('parameter_set', '')}' whenever the table runs, whatever calibration finds; "
                "drop it from [unknown] (a value the runs do not bear out is then found as an effect)"
            )
    return ran


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
    from sim.calibrate.readings import add_readings
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
            res = _calibrate_path(runs, ho_given, d, pl, p, eff, margin, workers, say, t_stage, payload == "none")
        return _with_baseline(res, say)

    kw = {"effects": effects, "search_one": search_one, "say": say, "workers": workers}
    res = run_stages(runs, ho_given, desc, pl, stages, **kw)
    add_readings(res, desc, pl)
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


def _calibrate_path(runs, ho_given, desc, pl, path, effects, margin, workers, say, t0, undeclared) -> CalibrationResult:
    """The replay / closed-loop search (:mod:`sim.calibrate.pathsearch`) as a result;
    ``undeclared``: ``--payload none`` (a specimen's modes are candidates there too)."""
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
        undeclared=undeclared,
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


# ------------------------------------------------------------------ outputs
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
    "MAX_ROUNDS",
    "UNEXPLAINED_FRACTION",
    "Z95",
    "accept",
    "accept_numbers",
    "calibrate",
    "candidate_laws",
    "check_effect_names",
    "effect_entry",
    "holdout_not_enough",
    "load_effect_file",
    "load_runs",
    "mechanical_errors",
    "param_report",
    "split_holdout",
    "unexplained",
    "write_outputs",
]
