"""Will this specimen and motion work on this table? Every limit as a check with a
demand, a capacity and a utilisation; the verdict is that every check passes.

A check is ``{"name", "demand", "capacity", "unit", "utilisation", "pass"}`` with
``utilisation = demand / capacity`` and ``pass = utilisation <= 1``. The groups:

* specimen (no simulation needed): mass against the rated specimen mass, static support
  load against the supports' capacity (``specimen_checks``);
* rated envelope at the reference point, per DOF, from the demanded motion: stroke or
  rotation, velocity, acceleration against the table file's ``[limits]``
  (``envelope_checks``);
* from a simulation (``run_checks``): per actuator stroke (to the cushion), velocity
  (full valve opening at no load), force (both directions, against the chamber area
  times the supply pressure *at that instant*, so the supply-pressure drop counts);
  servovalve saturation time; accumulator oil drawn against the usable oil (between the
  supply and the precharge pressure) and the supply-pressure drop against the drop to
  the precharge (an accumulator bank is sized to sag: below the precharge only the pumps
  deliver. An earlier rule, "supply above 90 % of its set pressure", had no source and
  failed UCSD test T8, which Ozcelik et al. [Ozcelik 2008] ran on the real table: 84 % of 20.7 MPa with
  0.62 of 1.51 m^3 usable oil drawn. What a sagging supply costs is counted where it
  matters: the force capacity uses the supply pressure of the moment); overturning moment of the specimen at the platen surface against the
  rated moment; loop closure; the run completing; tracking (PGA error, the fraction of
  the 0.5-20 Hz band where the 5 %-damped spectrum of the achieved acceleration is more
  than :data:`TOLERANCES` ``spectrum`` off the target's).

The verdict is that every capability check passes. The tracking checks (PGA error,
spectrum band) are listed with the others but do not enter it: they depend on the drive
iterations a lab runs before the test, not on what the table can do, so a failure is a
warning (``tracking_failed``). Displacement and acceleration NRMSE are reported in
``figures.tracking``.
"""

from __future__ import annotations

import numpy as np

from mjcf.description import DOFS6

#: Tolerances of the checks that have no rated value in a table file.
TOLERANCES = {
    "valve_saturation_fraction": 0.01,  # assumed: valves fully open at most 1 % of the run (flow limit reached)
    "pga_error": 0.10,  # assumed: achieved PGA within +/-10 % of the target's, a common acceptance band
    "spectrum": 0.20,  # assumed: 5 %-damped spectrum within +/-20 % ...
    "spectrum_band_fraction": 0.10,  # assumed: ... over at least 90 % of the 0.5-20 Hz band
    "loop_gap_m": 1e-4,  # numerical: a swivel gap above 0.1 mm means the linkage solve failed
}


def check(name, demand, capacity, unit) -> dict:
    """One check; a zero capacity with a positive demand is an infinite utilisation; a
    capacity of None (a rating the table file says is unknown) is no check: its
    utilisation is NaN, it passes, and its ``note`` says so (a verdict warning)."""
    if capacity is None:
        return {
            "name": name,
            "demand": float(demand),
            "capacity": float("nan"),
            "unit": unit,
            "utilisation": float("nan"),
            "pass": True,
            "note": f"{name}: the table's rating is unknown (its file says so): {float(demand):.4g} {unit} not checked",
        }
    demand, capacity = float(demand), float(capacity)
    if capacity > 0:
        u = demand / capacity
    else:
        u = 0.0 if demand <= 0 else float("inf")
    return {
        "name": name,
        "demand": demand,
        "capacity": capacity,
        "unit": unit,
        "utilisation": float(u),
        "pass": bool(u <= 1.0),
    }


TRACKING_PREFIXES = ("pga_error_", "spectrum_")


def is_tracking(c: dict) -> bool:
    """Tracking checks say how well the controller reproduces the motion; drive
    iterations improve them, a larger table does not: they are reported, not part of
    the verdict."""
    return c["name"].startswith(TRACKING_PREFIXES)


def verdict(checks: list[dict], warnings: list[str] | None = None) -> dict:
    """The verdict of a list of checks: feasible (every capability check passes), the
    limiting capability check (highest utilisation), the failed ones, the tracking
    checks outside tolerance (``tracking_failed``: reported with a warning)."""
    cap = [c for c in checks if not is_tracking(c)]
    finite = [c for c in cap if c["utilisation"] == c["utilisation"]]
    lim = max(finite, key=lambda c: c["utilisation"]) if finite else None
    failed = [c["name"] for c in cap if not c["pass"]]
    tfailed = [c["name"] for c in checks if is_tracking(c) and not c["pass"]]
    warns = list(warnings or []) + [c["note"] for c in checks if c.get("note")]
    if tfailed:
        warns.append(
            "tracking outside tolerance (" + ", ".join(tfailed) + "): drive iterations "
            "(--iterations) should bring it in; not part of the verdict"
        )
    return {
        "feasible": not failed,
        "limiting": lim["name"] if lim else None,
        "limiting_utilisation": lim["utilisation"] if lim else None,
        "failed": failed,
        "tracking_failed": tfailed,
        "checks": checks,
        "warnings": warns,
    }


# ------------------------------------------------------------------ specimen
def bare_support_load_n(desc) -> float:
    """Static load of the bare table on its supports (N): the preloads the builder solves."""
    from sim.effects import build_model

    return float(np.sum(build_model(desc, None).info.support_loads_n))


def specimen_checks(desc, payload, *, bare_support_n: float | None = None) -> list[dict]:
    """Mass against the rated specimen mass; static support load (the bare table's plus
    the specimen's weight: the actuators carry no static load) against the supports'
    capacity. Needs no model with the specimen, so an overweight specimen gets a verdict."""
    from mjcf.description import payload_mass

    m = payload_mass(payload)
    out = [check("specimen_mass", m, desc.limits.max_specimen_kg, "kg")]
    if desc.supports is not None:
        bare = bare_support_load_n(desc) if bare_support_n is None else bare_support_n
        g = desc.gravity_m_s2
        out.append(check("support_load", bare / g + m, desc.supports.capacity_kg, "kg"))
    return out


# ------------------------------------------------------------------ envelope
def envelope_checks(desc, ref) -> list[dict]:
    """Per table DOF: peak demanded displacement (rotation), velocity and acceleration of
    the reference against the rated ``[limits]`` (translations; rotations have a rated
    rotation only)."""
    lim = desc.limits
    out = []
    for i, dof in enumerate(DOFS6):
        if dof not in desc.dofs:
            continue
        d = float(np.max(np.abs(ref.d[:, i]))) if len(ref.d) else 0.0
        if i < 3:
            out.append(check(f"stroke_{dof}", d, lim.stroke_m[i], "m"))
            out.append(check(f"velocity_{dof}", np.max(np.abs(ref.v[:, i])), lim.velocity_m_s[i], "m/s"))
            out.append(check(f"acceleration_{dof}", np.max(np.abs(ref.a[:, i])), lim.acceleration_m_s2[i], "m/s^2"))
        else:
            out.append(check(f"rotation_{dof}", d, lim.rotation_rad[i - 3], "rad"))
    return out


# ------------------------------------------------------------------ from a run
def actuator_velocity(res) -> np.ndarray:
    """(n, n_act) piston velocity from the recorded strokes (m/s)."""
    s = res.channels["actuator_displacement"]
    dt = float(res.t[1] - res.t[0]) if len(res.t) > 1 else 1.0
    return np.gradient(s, dt, axis=0) if len(s) > 1 else np.zeros_like(s)


def flow_demand(res, hp) -> np.ndarray:
    """(n,) oil flow the actuators draw from the supply (m^3/s): the inflow to the chamber
    that grows, summed over the actuators (leakage left out)."""
    v = actuator_velocity(res)
    return np.sum(np.where(v > 0, hp.area_a_m2 * v, -hp.area_b_m2 * v), axis=1)


def usable_accumulator_oil(hp) -> float:
    """Oil the accumulators give between the supply pressure and their precharge (m^3)."""
    if hp.accumulator_volume_m3 <= 0:
        return 0.0
    v_supply = hp.accumulator_volume_m3 * (hp.accumulator_precharge_pa / hp.supply_pressure_pa) ** (
        1.0 / hp.polytropic_exponent
    )
    return float(hp.accumulator_volume_m3 - v_supply)


def force_utilisation(res, hp) -> tuple[np.ndarray, np.ndarray]:
    """(n, n_act) |F| / capacity at each instant, with the capacity in the force's
    direction: extension A_a p_s(t), retraction A_b p_s(t) (p_s the supply pressure
    then); and the (n, n_act) capacity."""
    F = res.channels["actuator_force"]
    ps = res.extras["supply_pressure"][:, None]
    cap = np.where(F >= 0, hp.area_a_m2, hp.area_b_m2) * ps
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.abs(F) / cap, cap


def specimen_response(res, tm) -> dict:
    """Base shear (N), overturning moment at the platen surface (N m) and deformation of
    the specimen over the run, as time histories (``None`` without a specimen).

    Rigid: inertia force of the mass at its centre of gravity moving with the platen,
    m a(t), with a the platen acceleration at the reference point (x, y), and its moment
    about the platen surface m a h_cg. Shear frame: the floors' elastic forces K q (q the
    floor displacements relative to the platen), their sum and their moment sum_i (K q)_i
    h_i; peak storey drift. Cantilever: moment at the base hinge k theta_1 plus the base
    shear's moment over the half segment below it; tip displacement from the hinge
    rotations (small angles).
    """
    from mjcf.description import CantileverPayload, RigidPayload, ShearFramePayload

    p = tm.payload
    if p is None:
        return None
    a = res.channels["table_acceleration"][:, :2]
    if isinstance(p, RigidPayload):
        m, h = p.mass_kg, float(p.com_m[2])
        shear = m * np.hypot(a[:, 0], a[:, 1])
        return {
            "kind": "rigid",
            "base_shear_n": shear,
            "overturning_n_m": shear * h,
            "deformation": None,
            "deformation_name": None,
        }
    q = res.extras.get("payload_qpos")
    if q is None:
        return None
    if isinstance(p, ShearFramePayload):
        f = q @ p.stiffness_n_m  # K symmetric: (K q)_i per sample
        h = p.storey_height_m * np.arange(1, len(p.mass_kg) + 1)
        drift = np.diff(np.concatenate([np.zeros((len(q), 1)), q], axis=1), axis=1)
        return {
            "kind": "shear_frame",
            "base_shear_n": np.abs(f.sum(axis=1)),
            "overturning_n_m": np.abs(f @ h),
            "deformation": np.max(np.abs(drift), axis=1),
            "deformation_name": "storey_drift_m",
        }
    if isinstance(p, CantileverPayload):
        n = p.n_segments
        seg = p.height_m / n
        k = p.bending_stiffness_n_m2 / seg
        th = q.reshape(len(q), n, 2)  # per segment: bend about x, about y
        z = seg / 2 + seg * np.arange(n)  # hinge heights
        tip_x = th[:, :, 1] @ (p.height_m - z)
        tip_y = -th[:, :, 0] @ (p.height_m - z)
        m1 = k * np.hypot(th[:, 0, 0], th[:, 0, 1])
        m2 = k * np.hypot(th[:, 1, 0], th[:, 1, 1]) if n > 1 else np.zeros(len(q))
        shear = np.abs(m1 - m2) / seg
        return {
            "kind": "cantilever",
            "base_shear_n": shear,
            "overturning_n_m": m1 + shear * seg / 2,
            "deformation": np.hypot(tip_x, tip_y),
            "deformation_name": "tip_displacement_m",
        }
    return None


def run_checks(res, tm, hp, ref) -> tuple[list[dict], dict]:
    """Checks of a simulated run (see the module docstring); returns the checks and the
    figures behind them (tracking, specimen response peaks)."""
    from sim.assess.metrics import SPECTRUM_BAND_HZ, spectrum_ratio, tracking

    desc = tm.desc
    ch = res.channels
    n = len(res.t)
    names = tm.actuator_names
    checks = []
    usable = hp.half_stroke_m - hp.cushion_length_m
    s = np.nanmax(np.abs(ch["actuator_displacement"]), axis=0) if n else np.zeros(len(names))
    i = int(np.argmax(s / usable))
    checks.append(check(f"actuator_stroke_{names[i]}", s[i], usable[i], "m"))
    v = np.nanmax(np.abs(actuator_velocity(res)), axis=0) if n else np.zeros(len(names))
    vmax = (
        hp.rated_flow_m3_s
        * np.sqrt(max(hp.supply_pressure_pa - hp.return_pressure_pa, 0.0) / hp.rated_drop_pa)
        / np.maximum(hp.area_a_m2, hp.area_b_m2)
    )
    i = int(np.argmax(v / vmax))
    checks.append(check(f"actuator_velocity_{names[i]}", v[i], vmax[i], "m/s"))
    fu, cap = force_utilisation(res, hp)
    if n:
        k = np.nanargmax(np.where(np.isfinite(fu), fu, -1.0))
        t_i, a_i = np.unravel_index(k, fu.shape)
        checks.append(check(f"actuator_force_{names[a_i]}", abs(ch["actuator_force"][t_i, a_i]), cap[t_i, a_i], "N"))
    dur = float(res.sim_s) if res.sim_s > 0 else 1.0
    sat_s = float(np.sum(np.any(np.abs(ch["valve_command"]) >= 0.999, axis=1))) / max(desc_rate(res), 1.0)
    checks.append(check("valve_saturation", sat_s, TOLERANCES["valve_saturation_fraction"] * dur, "s"))
    ps = res.extras["supply_pressure"]
    if hp.accumulator_volume_m3 > 0:
        gas = res.extras["accumulator_gas_volume"]
        drawn = float(np.nanmax(gas) - gas[0]) if n else 0.0
        checks.append(check("accumulator_oil", drawn, usable_accumulator_oil(hp), "m^3"))
        checks.append(
            check(
                "supply_pressure_drop",
                hp.supply_pressure_pa - float(np.nanmin(ps)),
                hp.supply_pressure_pa - hp.accumulator_precharge_pa,
                "Pa",
            )
        )
    else:
        q = flow_demand(res, hp)
        checks.append(check("oil_flow", float(np.max(q)) if n else 0.0, hp.pump_flow_m3_s, "m^3/s"))
    resp = specimen_response(res, tm)
    if resp is not None and (desc.limits.overturning_moment_n_m is None or desc.limits.overturning_moment_n_m > 0):
        checks.append(
            check(
                "overturning_moment",
                float(np.nanmax(resp["overturning_n_m"])),
                desc.limits.overturning_moment_n_m,
                "N m",
            )
        )
    gap = float(np.nanmax(res.extras["loop_gap"])) if n else 0.0
    checks.append(check("loop_closure", gap, TOLERANCES["loop_gap_m"], "m"))
    t_total = (len(ref.t) - 1) / ref.rate_hz
    checks.append(check("run_completed", 0.0 if res.incomplete_reason is None else 1.0, 0.0, "-"))
    tr = tracking(res.t, ref.d, ref.a, ch["table_displacement"], ch["table_acceleration"]) if n > 1 else {}
    dt = float(res.t[1] - res.t[0]) if n > 1 else 1.0
    for dof, e in tr.items():
        if dof not in desc.dofs:
            continue
        checks.append(check(f"pga_error_{dof}", abs(e["pga_ratio"] - 1.0), TOLERANCES["pga_error"], "-"))
        if n * dt > 2.0 / SPECTRUM_BAND_HZ[0]:
            j = DOFS6.index(dof)
            m = min(n, len(ref.a))
            _, r = spectrum_ratio(ch["table_acceleration"][:m, j], ref.a[:m, j], dt)
            out = float(np.mean(np.abs(r - 1.0) > TOLERANCES["spectrum"]))
            e["spectrum_band_fraction_outside"] = out
            checks.append(check(f"spectrum_{dof}", out, TOLERANCES["spectrum_band_fraction"], "-"))
    figures = {"tracking": tr, "simulated_s": float(res.sim_s), "reference_s": float(t_total)}
    if resp is not None:
        figures["specimen"] = {
            "kind": resp["kind"],
            "peak_base_shear_n": float(np.nanmax(resp["base_shear_n"])),
            "peak_overturning_n_m": float(np.nanmax(resp["overturning_n_m"])),
        }
        if resp["deformation"] is not None:
            figures["specimen"]["peak_" + resp["deformation_name"]] = float(np.nanmax(resp["deformation"]))
    return checks, figures


def desc_rate(res) -> float:
    return 1.0 / float(res.t[1] - res.t[0]) if len(res.t) > 1 else 1.0


def assess_run(res, tm, hp, ref, *, payload=None, envelope_reference=None, warnings=None) -> dict:
    """The verdict of a run: specimen, envelope (of ``envelope_reference``, default the
    simulated reference) and run checks; ``figures`` holds tracking and specimen response."""
    desc = tm.desc
    checks = specimen_checks(
        desc,
        payload if payload is not None else tm.payload,
        bare_support_n=None if desc.supports is None else float(np.sum(tm.info.support_loads_n)) - _payload_weight(tm),
    )
    checks += envelope_checks(desc, envelope_reference if envelope_reference is not None else ref)
    rc, figures = run_checks(res, tm, hp, ref)
    out = verdict(checks + rc, warnings)
    out["figures"] = figures
    return out


def _payload_weight(tm) -> float:
    from mjcf.description import payload_mass

    return payload_mass(tm.payload) * tm.desc.gravity_m_s2


def diagnostics(res, tm, hp, ref=None, *, payload=None, envelope_reference=None, warnings=None) -> dict:
    """``summary.json``'s verdict and the peak figures of a run."""
    ch = res.channels
    cap = hp.area_a_m2 * hp.supply_pressure_pa
    fmax = np.nanmax(np.abs(ch["actuator_force"]), axis=0)
    smax = np.nanmax(np.abs(ch["actuator_displacement"]), axis=0)
    half = hp.half_stroke_m
    vc = ch["valve_command"]
    timing = res.timing
    steps = max(timing.get("steps", 1), 1)
    ticks = max(len(res.t), 1)
    out = {}
    if ref is not None:
        out["feasibility"] = assess_run(
            res, tm, hp, ref, payload=payload, envelope_reference=envelope_reference, warnings=warnings
        )
    out.update(
        {
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
    )
    return out


__all__ = [
    "TOLERANCES",
    "assess_run",
    "check",
    "diagnostics",
    "envelope_checks",
    "flow_demand",
    "force_utilisation",
    "run_checks",
    "specimen_checks",
    "specimen_response",
    "usable_accumulator_oil",
    "verdict",
]
