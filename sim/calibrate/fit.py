"""Close the loop with measured data: replay, find the residual, add the missing effect.

A measured run (``source = "measured"``, with the valve commands the controller sent)
is replayed open loop through the model (the plant alone, as the CGS paper validated its
model). The residual between measured and replayed channels is what the model lacks.
Each candidate effect is a named, one-parameter change of the table description
(:data:`CANDIDATES`); for each, the parameter that best explains the measurement is
found by a bounded scalar search on the replay residual, and the candidate that removes
the most residual is added (greedy, one at a time, while it removes at least
``min_gain`` of what is left). The result is the error before and after, per channel,
and a calibrated copy of the table description.

The residual score is the mean NRMSE over the measured channels present among
``actuator_force``, ``table_acceleration`` and ``table_displacement`` (commanded DOF
columns only, those with a reference RMS above zero).
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
from scipy.optimize import minimize_scalar

from mjcf.description import parse_table
from sim.assess.metrics import nrmse
from sim.effects import build_model
from sim.errors import RunFileError

FIT_CHANNELS = ("actuator_force", "table_acceleration", "table_displacement")


@dataclass(frozen=True)
class Candidate:
    """A one-parameter effect: ``apply(raw_table_dict, value)`` edits the description."""

    name: str
    what: str
    bounds: tuple[float, float]
    neutral: float
    apply: Callable[[dict, float], None]
    unit: str = ""


def _scale_key(section_path, key):
    def apply(raw, v):
        if section_path == "actuator_class":
            for cls in raw["actuator_class"].values():
                cls[key] = cls[key] * v
        else:
            raw[section_path][key] = raw[section_path][key] * v

    return apply


def _friction(raw, v):
    for cls in raw["actuator_class"].values():
        cls["seal_friction_n"] = cls["seal_friction_n"] * v
    if "supports" in raw:
        raw["supports"]["piston_friction_n"] *= v
        raw["supports"]["shoe_friction_n"] *= v


def _delay(raw, v):
    raw["servovalve"]["delay_s"] = raw["servovalve"].get("delay_s", 0.0) + v


def _added_mass(raw, v):
    raw["platen"]["mass_kg"] = raw["platen"]["mass_kg"] + v


CANDIDATES = (
    Candidate(
        "bulk_modulus",
        "effective bulk modulus scale (entrained air, hose compliance)",
        (0.4, 1.6),
        1.0,
        _scale_key("fluid", "bulk_modulus_pa"),
        "x",
    ),
    Candidate("friction", "seal and support friction scale", (0.0, 5.0), 1.0, _friction, "x"),
    Candidate("valve_delay", "extra pure delay of the servovalves", (0.0, 0.006), 0.0, _delay, "s"),
    Candidate(
        "added_mass", "mass moving with the platen that the description lacks", (0.0, 20000.0), 0.0, _added_mass, "kg"
    ),
    Candidate(
        "valve_gain", "servovalve rated-flow scale", (0.6, 1.4), 1.0, _scale_key("servovalve", "rated_flow_m3_s"), "x"
    ),
)


def score(measured, replayed, start: int = 0) -> tuple[float, dict]:
    """Mean NRMSE over the fit channels (samples from ``start`` on); and the per-channel,
    per-column figures."""
    per = {}
    vals = []
    dof_used = None
    if measured.reference is not None:
        dof_used = [
            j for j in range(measured.reference.shape[1]) if np.sqrt(np.mean(measured.reference[:, j] ** 2)) > 0
        ]
    n = min(measured.n_samples, len(replayed["t"]))
    for ch in FIT_CHANNELS:
        m = getattr(measured, ch)
        r = replayed.get(ch)
        if m is None or r is None:
            continue
        cols = range(m.shape[1])
        if ch.startswith("table_") and dof_used is not None:
            cols = dof_used
        names = measured.column_names(ch)
        per[ch] = {}
        for j in cols:
            if np.sqrt(np.nanmean(m[start:n, j] ** 2)) == 0:
                continue
            e = nrmse(r[start:n, j], m[start:n, j])
            per[ch][names[j]] = e
            vals.append(e)
    if not vals:
        raise RunFileError(f"{measured.name}: none of {', '.join(FIT_CHANNELS)} is present to compare with")
    return float(np.mean(vals)), per


def _replay(raw: dict, payload, measured, src: str):
    from sim.calibrate.replay import run_at_record

    desc = parse_table(raw, src=src)
    tm = build_model(desc, payload)
    # at the record's own rate: commands held (or interpolated, meta.command_hold) onto the
    # model's ticks, channels sampled back at the record's instants in its DOF columns
    t_rec = np.asarray(measured.t, float) - float(measured.t[0])
    res, ch, _, n = run_at_record(
        tm, t_rec, measured.valve_command, measured.dofs, hold=measured.meta.get("command_hold", "zoh")
    )
    out = dict(ch)
    out["t"] = t_rec[:n]
    out["_incomplete"] = res.incomplete_reason
    return out


def fit(
    measured,
    raw_table: dict,
    payload=None,
    *,
    candidates=CANDIDATES,
    rounds: int = 2,
    min_gain: float = 0.2,
    xatol_frac: float = 2e-3,
    log=None,
) -> dict:
    """Greedy effect search; returns a report dict and the calibrated raw description."""
    say = log or (lambda *_: None)
    src = "<fit>"
    raw = copy.deepcopy(raw_table)
    base_s, base_per = score(measured, _replay(raw, payload, measured, src))
    say(f"baseline residual {100 * base_s:.2f} %")
    current = base_s
    chosen = []
    remaining = list(candidates)
    tried = {}
    for rnd in range(rounds):
        best = None
        for c in remaining:

            def obj(v, c=c):
                r2 = copy.deepcopy(raw)
                c.apply(r2, v)
                rep = _replay(r2, payload, measured, src)
                if rep["_incomplete"]:
                    return 1e3
                return score(measured, rep)[0]

            lo, hi = c.bounds
            say(f"round {rnd + 1}: trying {c.name} ({lo:g}..{hi:g} {c.unit})")
            res = minimize_scalar(
                obj, bounds=(lo, hi), method="bounded", options={"xatol": xatol_frac * (hi - lo), "maxiter": 25}
            )
            tried.setdefault(c.name, []).append({"round": rnd, "value": float(res.x), "residual": float(res.fun)})
            say(f"  {c.name:12s} -> {res.x:.6g} {c.unit}: residual {100 * res.fun:.2f} %")
            if best is None or res.fun < best[1]:
                best = (c, float(res.fun), float(res.x))
        if best is None or current - best[1] < min_gain * current:
            break
        c, s_new, v = best
        c.apply(raw, v)
        chosen.append(
            {
                "effect": c.name,
                "what": c.what,
                "value": v,
                "unit": c.unit,
                "residual_before": current,
                "residual_after": s_new,
            }
        )
        say(f"added {c.name} = {v:.6g} {c.unit}: residual {100 * current:.2f} % -> {100 * s_new:.2f} %")
        current = s_new
        remaining = [x for x in remaining if x.name != c.name]
    final_s, final_per = score(measured, _replay(raw, payload, measured, src))
    return {
        "run": measured.name,
        "baseline_residual": base_s,
        "baseline_per_channel": base_per,
        "effects_added": chosen,
        "final_residual": final_s,
        "final_per_channel": final_per,
        "candidates_tried": tried,
        "calibrated_table": raw,
    }


def write_table_toml(raw: dict, path, note: str, original=None) -> None:
    """Write a calibrated description: the ``original`` file (a path) with every value
    that ``raw`` changes rewritten in place, tagged ``note``, its comments kept (the one
    writer, :mod:`sim.calibrate.description`). Without ``original``, ``raw['_source']``
    or a bare error."""
    import tomllib
    from pathlib import Path

    from sim.calibrate.description import DescriptionWriteError, TomlText, changed_values

    if original is None:
        raise DescriptionWriteError(
            f"{path}: the calibrated description is written into a copy of the original file; give original="
        )
    doc = TomlText.read(original)
    old = tomllib.loads(doc.text)
    for section, key, value in changed_values(old, raw):
        doc.set_value(section, key, value, note, keep_comment=True, create=True)
    doc.save(Path(path))


# ------------------------------------------------------------------ `calibrate --strategy scale`
#: what each knob's value is called in ``effects_added`` (by its unit)
_PARAM_OF_UNIT = {"x": ("scale", "1"), "s": ("delay_s", "s"), "kg": ("mass_kg", "kg")}
#: a knob within this share of its range from a bound is "at its bound" (not accepted)
BOUND_TOL = 0.01


@dataclass
class _Part:
    """A run as fitted or held out: the record, and the first sample scored (a run that
    is both: its first 70 % fitted, replayed whole and scored after the cut)."""

    run: object
    start: int = 0
    label: str = ""


def _split(runs, ho_given):
    import dataclasses
    from pathlib import Path

    from sim.runs.runfile import CHANNELS

    if ho_given:
        return [_Part(r) for r in runs], [_Part(r) for r in ho_given], "given with --holdout"
    if len(runs) >= 2:
        ho = [_Part(r) for i, r in enumerate(runs) if i % 3 == 1]
        fit_ = [_Part(r) for i, r in enumerate(runs) if i % 3 != 1]
        return fit_, ho, "held out (no --holdout): " + ", ".join(Path(p.run.name).name for p in ho)
    r = runs[0]
    cut = int(0.7 * r.n_samples)
    kw = {c: (getattr(r, c)[:cut].copy() if getattr(r, c) is not None else None) for c in CHANNELS}
    head = dataclasses.replace(r, t=r.t[:cut].copy(), extras={}, **kw)
    head.path = f"{r.name} (fit part)"
    note = (
        f"held out (one run, no --holdout): the last 30 % of {Path(r.name).name} (from t = {r.t[cut]:.2f} s; "
        "the whole record replayed, scored after the cut)"
    )
    return [_Part(head)], [_Part(r, cut, "held-out part")], note


def _knob_param(c: Candidate) -> tuple[str, str]:
    return _PARAM_OF_UNIT.get(c.unit, ("value", c.unit or "1"))


def at_bound(c: Candidate, v: float, tol: float = BOUND_TOL) -> bool:
    """Is ``v`` within ``tol`` of its range from either of ``c``'s bounds?"""
    lo, hi = c.bounds
    return v - lo <= tol * (hi - lo) or hi - v <= tol * (hi - lo)


def calibrate_scale(
    run_paths,
    *,
    table=None,
    payload=None,
    holdout=None,
    effects=None,
    rounds: int = 2,
    margin: float | None = None,
    xatol_frac: float = 2e-3,
    log=None,
):
    """``shaketable calibrate RUN... --strategy scale`` (formerly ``shaketable fit``):
    global scale factors of the description (:data:`CANDIDATES`) chosen on the replay of
    the recorded valve commands, greedy, one knob a round. A knob is accepted only when
    its value sits off its bounds (by :data:`BOUND_TOL` of its range) and the held-out
    error falls by ``margin`` (default ``search.HOLDOUT_MARGIN``) of itself: on a run the
    model already matches, nothing is added. Returns a
    :class:`sim.calibrate.search.CalibrationResult` (``residual_path = "replay"``) and,
    in ``series["calibrated_raw"]``, the calibrated description (raw)."""
    import time

    from sim.calibrate.residuals import CalibrationError
    from sim.calibrate.search import HOLDOUT_MARGIN, Z95, CalibrationResult, _check_names, holdout_not_enough, load_runs
    from sim.runs.runfile import payload_of, table_of

    margin = HOLDOUT_MARGIN if margin is None else margin
    say = log or (lambda *_: None)
    t0 = time.perf_counter()
    if not run_paths:
        raise CalibrationError("no runs given: name the .run.npz files to calibrate against")
    _check_names(run_paths, holdout)
    all_runs = load_runs(list(run_paths) + list(holdout or []), table)
    for r in all_runs:
        if r.valve_command is None:
            raise CalibrationError(
                f"{r.name}: has no valve_command channel; --strategy scale replays the recorded valve "
                "commands (use --strategy search for runs with table motion and actuator forces)"
            )
    cands = list(CANDIDATES)
    if effects:
        known = {c.name: c for c in CANDIDATES}
        bad = [n for n in effects if n not in known]
        if bad:
            raise CalibrationError(
                f"--effects: unknown scale knob '{bad[0]}'; --strategy scale tries {', '.join(known)}"
            )
        cands = [known[n] for n in effects]
    runs, ho_given = all_runs[: len(run_paths)], all_runs[len(run_paths) :]
    desc = table_of(runs[0], table)
    for r in all_runs:
        if list(r.actuators) != list(desc.actuator_names):
            raise CalibrationError(
                f"{r.name}: actuators {r.actuators} do not match table '{desc.name}' "
                f"({list(desc.actuator_names)}); give --table"
            )
    pl = payload_of(runs[0], payload)
    fit_parts, ho_parts, ho_note = _split(runs, ho_given)
    src = "<calibrate --strategy scale>"
    n_replays = 0

    def mean_score(raw, parts):
        nonlocal n_replays
        vals, per = [], {}
        for p in parts:
            rep = _replay(raw, pl, p.run, src)
            n_replays += 1
            if rep["_incomplete"]:
                return 1e3, {}
            s, pc = score(p.run, rep, p.start)
            vals.append(s)
            per[p.run.name] = pc
        return float(np.mean(vals)), per

    raw = copy.deepcopy(desc.raw)
    t1 = time.perf_counter()
    fit_cur, _ = mean_score(raw, fit_parts)
    ho0, per0 = mean_score(raw, ho_parts)
    ho_cur = ho0
    say(f"replay path: {len(fit_parts)} fit, {len(ho_parts)} held out; held-out error {ho0:.4f}, fit {fit_cur:.4f}")
    tried, added = [], []
    remaining = list(cands)
    for rnd in range(rounds):
        scored = []
        for c in remaining:

            def obj(v, c=c, prev=raw):
                r2 = copy.deepcopy(prev)
                c.apply(r2, v)
                return mean_score(r2, fit_parts)[0]

            lo, hi = c.bounds
            res = minimize_scalar(
                obj, bounds=(lo, hi), method="bounded", options={"xatol": xatol_frac * (hi - lo), "maxiter": 25}
            )
            scored.append((float(res.fun), c, float(res.x)))
        scored.sort(key=lambda s: s[0])
        accepted = None
        for s_fit, c, v in scored:
            name, unit = _knob_param(c)
            row = {
                "round": rnd,
                "name": c.name,
                "where": "table",
                "parameters": {name: v},
                "fit_error": s_fit,
                "explained_fraction": 1.0 - s_fit / fit_cur if fit_cur > 0 else 0.0,
                "holdout_error": None,
                "accepted": False,
                "reason": "",
            }
            tried.append(row)
            if not s_fit < fit_cur:
                row["reason"] = f"fit error does not fall ({fit_cur:.4f} -> {s_fit:.4f})"
            elif at_bound(c, v):
                row["reason"] = f"{name} = {v:.4g} {unit} at its bound [{c.bounds[0]:g}, {c.bounds[1]:g}]"
            else:
                r2 = copy.deepcopy(raw)
                c.apply(r2, v)
                e_new, per_new = mean_score(r2, ho_parts)
                row["holdout_error"] = e_new
                if not e_new <= (1 - margin) * ho_cur:
                    row["reason"] = holdout_not_enough(ho_cur, e_new, margin)
                else:
                    row["accepted"] = True
                    accepted = (c, v, s_fit, e_new, r2)
            say(
                f"  {c.name:14s} {name} = {v:.6g} {unit}: fit {s_fit:.4f}"
                + ("  ACCEPTED" if row["accepted"] else f"  ({row['reason']})")
            )
            if accepted:
                break
        if accepted is None:
            break
        c, v, s_fit, e_new, raw_new = accepted
        # a 95 % interval from the score's curvature (Gauss: RSS ~ N s^2, s^2 = RSS / N)
        name, unit = _knob_param(c)
        h = max(1e-3 * (c.bounds[1] - c.bounds[0]), 1e-9)

        def at(x, c=c, prev=raw):
            r2 = copy.deepcopy(prev)
            c.apply(r2, x)
            return mean_score(r2, fit_parts)[0]

        sp, sm = at(min(v + h, c.bounds[1])), at(max(v - h, c.bounds[0]))
        curv = (sp**2 + sm**2 - 2 * s_fit**2) / h**2
        raw = raw_new
        n_pts = sum(p.run.n_samples - p.start for p in fit_parts)
        sd = math.sqrt(2 * s_fit**2 / (n_pts * curv)) if curv > 0 else math.inf
        added.append(
            {
                "name": c.name,
                "where": "table",
                "what": c.what,
                "parameters": {name: v},
                "uncertainty": {name: Z95 * sd},
                "units": {name: unit},
                "error_before": ho_cur,
                "error_after": e_new,
            }
        )
        say(f"added {c.name}: {name} = {v:.6g} {unit}; held-out error {ho_cur:.4f} -> {e_new:.4f}")
        fit_cur, ho_cur = s_fit, e_new
        remaining = [x for x in remaining if x.name != c.name]
    ho1, per1 = mean_score(raw, ho_parts) if added else (ho0, per0)
    per = {}
    for rn, chans in per0.items():
        for ch, cols in chans.items():
            for col, e0 in cols.items():
                per[f"{Path(rn).name}:{ch}:{col}"] = {"before": e0, "after": per1.get(rn, {}).get(ch, {}).get(col)}
    t2 = time.perf_counter()
    return CalibrationResult(
        table=desc.name,
        table_source=str(desc.source),
        runs=[str(r.name) for r in runs],
        holdout=[str(p.run.name) + (f" ({p.label})" if p.label else "") for p in ho_parts],
        holdout_note=ho_note,
        residual_path="replay",
        error_before=ho0,
        error_after=ho1,
        effects_added=added,
        candidates=tried,
        unexplained=None,
        per_channel=per,
        timing={"read_s": t1 - t0, "search_s": t2 - t1, "total_s": t2 - t0, "replays": n_replays},
        series={"calibrated_raw": raw, "strategy": "scale"},
    )


def write_scale_outputs(result, out, run_names) -> dict:
    """``calibration.json`` and ``<table>_calibrated.toml`` (the original file, every
    comment kept, the changed values rewritten in place and tagged) of a scale
    calibration; returns the JSON written."""
    from sim.runs.files import write_json_atomic

    out = Path(out)
    tag = "calibrated: shaketable calibrate --strategy scale " + " ".join(Path(p).name for p in run_names)
    if result.effects_added:
        tag += "; " + ", ".join(
            f"{e['name']} {k} = {v:.6g} {e['units'][k]}"
            for e in result.effects_added
            for k, v in e["parameters"].items()
        )
    toml_path = out / f"{result.table}_calibrated.toml"
    write_table_toml(result.series["calibrated_raw"], toml_path, tag, original=result.table_source)
    js = result.to_json()
    js["strategy"] = "scale"
    js["calibrated_table_file"] = str(toml_path)
    write_json_atomic(out / "calibration.json", js)
    return js
