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
from dataclasses import dataclass
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


def score(measured, replayed) -> tuple[float, dict]:
    """Mean NRMSE over the fit channels; and the per-channel, per-column figures."""
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
            if np.sqrt(np.nanmean(m[:n, j] ** 2)) == 0:
                continue
            e = nrmse(r[:n, j], m[:n, j])
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
