"""Will this specimen and motion work on this table? Checks of a run against the table's
capability, with margins and a verdict."""

from __future__ import annotations

import numpy as np


def feasibility(res, tm, hp, force_frac, stroke_frac) -> dict:
    """Will this specimen and motion work on this table? Checks with margins and a verdict.

    Each check compares a peak over the run with the table's capability: actuator stroke
    (cushions start at half-stroke - cushion length), actuator force (A p_supply), valve
    opening (saturation means the demanded flow was not available), supply pressure
    (accumulators drained below 90 % of the set pressure), the overturning moment at the
    reference point from the vertical actuators (seed 000: about 180 t.m), loop closure.
    """
    from sim.control.tvc import dof_jacobian

    ch = res.channels
    desc = tm.desc
    J = dof_jacobian(desc)
    W = ch["actuator_force"] @ J  # wrench at the reference point (home Jacobian): Fx..Fz, Mx..Mz
    m_ot = float(np.nanmax(np.hypot(W[:, 3], W[:, 4]))) if len(W) else 0.0
    lim_ot = desc.limits.overturning_moment_n_m
    sat = float(np.mean(np.abs(ch["valve_command"]) >= 0.999))
    ps_min = float(np.nanmin(res.extras["supply_pressure"]))
    cush = np.asarray(hp.cushion_length_m) / np.asarray(hp.half_stroke_m)
    checks = {
        "stroke": {"peak_fraction": float(np.max(stroke_frac)), "limit": float(np.min(1 - cush)),
                   "ok": bool(np.all(stroke_frac < 1 - cush))},
        "force": {"peak_fraction": float(np.max(force_frac)), "limit": 0.9, "ok": bool(np.max(force_frac) < 0.9)},
        "valve_saturation": {"fraction_of_time": sat, "limit": 0.01, "ok": sat < 0.01},
        "supply_pressure": {"min_fraction": ps_min / hp.supply_pressure_pa, "limit": 0.9,
                            "ok": ps_min >= 0.9 * hp.supply_pressure_pa},
        "overturning_moment": {"peak_n_m": m_ot, "limit_n_m": lim_ot, "ok": (lim_ot <= 0) or m_ot <= lim_ot},
        "loop_closure": {"max_gap_m": float(np.nanmax(res.extras["loop_gap"])), "limit": 1e-4,
                         "ok": bool(np.nanmax(res.extras["loop_gap"]) < 1e-4)},
        "completed": {"ok": res.incomplete_reason is None},
    }
    failed = [k for k, v in checks.items() if not v["ok"]]
    util = utilisation(checks)
    limiting = max(util, key=util.get)
    return {"feasible": not failed, "failed": failed, "checks": checks, "utilisation": util,
            "limiting": limiting, "limiting_utilisation": util[limiting]}


def utilisation(checks: dict) -> dict:
    """Each check's use of its limit as one number (1 = at the limit, above 1 = failed):
    peak / limit for stroke, force, valve saturation, overturning moment and loop gap;
    the supply-pressure drop over the allowed drop; an incomplete run counts as infinite."""
    c = checks
    sp = c["supply_pressure"]
    ot = c["overturning_moment"]
    return {
        "stroke": c["stroke"]["peak_fraction"] / c["stroke"]["limit"],
        "force": c["force"]["peak_fraction"] / c["force"]["limit"],
        "valve_saturation": c["valve_saturation"]["fraction_of_time"] / c["valve_saturation"]["limit"],
        "supply_pressure": (1.0 - sp["min_fraction"]) / (1.0 - sp["limit"]),
        "overturning_moment": ot["peak_n_m"] / ot["limit_n_m"] if ot["limit_n_m"] > 0 else 0.0,
        "loop_closure": c["loop_closure"]["max_gap_m"] / c["loop_closure"]["limit"],
        "completed": 0.0 if c["completed"]["ok"] else float("inf"),
    }


def diagnostics(res, tm, hp) -> dict:
    ch = res.channels
    cap = hp.area_a_m2 * hp.supply_pressure_pa
    fmax = np.nanmax(np.abs(ch["actuator_force"]), axis=0)
    smax = np.nanmax(np.abs(ch["actuator_displacement"]), axis=0)
    half = hp.half_stroke_m
    vc = ch["valve_command"]
    timing = res.timing
    steps = max(timing.get("steps", 1), 1)
    ticks = max(len(res.t), 1)
    feas = feasibility(res, tm, hp, fmax / cap, smax / half)
    return {
        "feasibility": feas,
        "peak_force_fraction_of_capacity": {n: float(f / c) for n, f, c in zip(tm.actuator_names, fmax, cap)},
        "peak_stroke_fraction": {n: float(s / h) for n, s, h in zip(tm.actuator_names, smax, half)},
        "valve_saturation_fraction": float(np.mean(np.abs(vc) >= 0.999)),
        "min_supply_pressure_pa": float(np.nanmin(res.extras["supply_pressure"])),
        "max_loop_gap_m": float(np.nanmax(res.extras["loop_gap"])),
        "cost_us": {
            "physics_per_step": 1e6 * timing.get("physics_s", 0) / steps,
            "hydraulics_per_step": 1e6 * timing.get("hydraulics_s", 0) / steps,
            "controller_per_tick": 1e6 * timing.get("controller_s", 0) / ticks,
            "output_per_tick": 1e6 * timing.get("output_s", 0) / ticks,
        },
    }
