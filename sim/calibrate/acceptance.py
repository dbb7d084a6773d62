"""The rules a candidate effect passes to be added, shared by every residual path.

* **Bounds** (:func:`bound_hit`): a parameter at (or beyond) a bound of its range, or at
  the limit its scan may reach, is not a fitted value. The search then holds it there and
  refits the rest (:func:`nested_at_bound`): the *nested* law (dry friction growing with
  the stroke whose constant part sits at 0 is the pure growing law), judged again by the
  same rules and reported with that parameter fixed.
* **Numbers** (:func:`accept_numbers`): the held-out error falls by the margin, the BIC
  falls, and the residual gets whiter unless the held-out gain is large
  (:data:`LARGE_GAIN`): whiteness guards a small gain against an effect that only
  reshapes the residual, it does not veto one that removes a fifth of the error. Between
  candidates that pass with held-out errors within the margin of each other, the whiter
  residual wins (:func:`tie_break`).
* **Plausibility** (:func:`implausible`): an effect whose force, mass or flow the table
  cannot have is refused as *compensation* (it stands in for something else: a valve
  bandwidth of 0.004 Hz, 12 t added to a 0.84 t table), whatever it does to the error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: a held-out gain this large (a fifth of the error) is accepted even if the residual is
#: not whiter: a physical effect removed from a coloured residual can leave another
#: coloured residual (a specimen's second mode under the first)
LARGE_GAIN = 0.20
Z95 = 1.96  #: the 95 % half-width in standard deviations
HOLDOUT_MARGIN = 0.05  #: the held-out NRMSE must fall by at least 5 % of itself

#: the word a refused candidate's reason starts with when the effect is implausible
COMPENSATION = "compensation"
#: an effect's force at the recorded motion may not exceed this share of what the actuators
#: deliver along its place (stall force: piston area x supply pressure, summed): a friction or
#: damping force above it would stop the table the records show moving
FORCE_SHARE = 1.0
#: added mass: at most this many times the declared moving mass at the place (platen,
#: payload and actuator parts, the effective mass): a description off by more is not a
#: description of this table (12.5 t found on a 0.84 t table stood in for friction)
MASS_RATIO = 2.0
#: a valve's flow gain factor: flow goes as the square root of the pressure drop across
#: the valve, so a factor f is a drop f^2 times the rated one: beyond 1/9-9 x (0.3-3) no
#: supply of the table's own pressure gives it (a factor of 0.015 stood in for the lead-in)
FLOW_GAIN_RANGE = (0.3, 3.0)
#: a servovalve's bandwidth (Hz): shaking-table valves have 10-200 Hz (90 degree phase);
#: below 1 Hz the valve could not follow the table's own test signals
MIN_VALVE_BANDWIDTH_HZ = 1.0
#: leakage: its flow at the supply pressure may not exceed this share of the valve's rated
#: flow (worn seals leak a few per cent; a leak of the whole rated flow stalls the piston)
LEAK_SHARE = 1.0
#: effective bulk modulus (Pa): oil 1.4-1.8 GPa, hoses and entrained air bring it to
#: 0.3-1 GPa (Merritt, Hydraulic Control Systems, 1967); below 0.1 GPa the column is foam
MIN_BULK_MODULUS_PA = 1e8
#: ... and no effective value exceeds the stiffest mineral oil's with no air and rigid
#: walls (1.8 GPa, the same source; 2.0 GPa with a margin): a stiffer column stands in for
#: something else (a fitted 2.89 GPa on the worked example's declared-frame variant)
MAX_BULK_MODULUS_PA = 2.0e9


# ------------------------------------------------------------------ bounds
def bound_hit(value: float, lo: float, hi: float, tol: float) -> str | None:
    """ "lower" or "upper" when ``value`` sits within ``tol`` of (or beyond) a finite
    bound, else None: the one test of both paths' parameter checks."""
    if math.isfinite(lo) and value - lo <= tol:
        return "lower"
    if math.isfinite(hi) and hi - value <= tol:
        return "upper"
    return None


def nested_at_bound(law, values: dict, limits: dict, sigma: dict | None = None) -> tuple[str, float] | None:
    """``(name, value)`` of the first parameter of ``law`` at a bound of its range, with the
    value it is held at there, or None; a linear coefficient beside others (dry friction's
    constant part beside its growing part) also when its 95 % interval (``sigma``) reaches
    its bound (:func:`linear_holds_bound`). A scanned parameter at its scan's limit
    (``limits[name]``) inside its range is not held there: the limit is where the law stops
    being itself (a power law's exponent towards 0 is dry friction) or where no record
    tells (a mode's damping below 0.05 %); the candidate is refused. A linear coefficient
    can be held only at 0 beside another one (:func:`sim.calibrate.laws.fixed_law`)."""
    for name, (_u, lo, hi) in law.params.items():
        v = values[name]
        if name in law.shape:
            a, b = limits.get(name, (lo, hi))
            if bound_hit(v, a, b, 1e-3 * max(abs(v), 1e-12)) and not bound_hit(v, lo, hi, 1e-3 * max(abs(v), 1e-12)):
                return None
        side = bound_hit(v, lo, hi, 1e-3 * max(abs(v), 1e-12))
        if side is None and sigma is not None and linear_holds_bound(law, name, v, sigma.get(name, math.inf)):
            side = "lower" if abs(v - lo) <= abs(v - hi) else "upper"
        if side is None:
            continue
        at = lo if side == "lower" else hi
        if name in law.nested and law.nested[name][0] == at:
            continue  # held there it is the simpler law, a candidate of its own
        if name in law.linears and (at != 0.0 or len(law.linears) == 1):
            return None
        return name, float(at)
    return None


def linear_holds_bound(law, name: str, value: float, sigma: float) -> bool:
    """A linear coefficient of a law with several (the constant part of a dry friction
    growing with the stroke) whose 95 % interval reaches a finite bound of its range: the
    data cannot tell it from the bound, so the nested law without it is the one to judge."""
    if name not in law.linears or len(law.linears) < 2 or name in law.nested:
        return False  # (a nested coefficient has its own rule: Law.nested)
    _u, lo, hi = law.params[name]
    return any(math.isfinite(b) and abs(value - b) <= Z95 * sigma for b in (lo, hi))


# ------------------------------------------------------------------ numbers
def holdout_not_enough(before: float, after: float, margin: float) -> str:
    """Why a held-out error ``before -> after`` does not pass the margin, in the words of
    what it did: it rose, stayed, or fell by less than the margin."""
    change = f"held-out error {before:.4f} -> {after:.4f}"
    if after > before:
        return f"{change} rose (by {100 * (after / before - 1):.3g} %)" if before > 0 else f"{change} rose"
    if after == before:
        return f"{change} did not change"
    return f"{change} falls by less than {100 * margin:g} %"


def accept_numbers(e_ho_cur, e_ho_new, bic_cur, bic_new, flat_cur, flat_new, margin) -> tuple[bool, str]:
    """``(accepted, reason)`` by the tests every path shares (parameters checked apart):
    held-out error down by ``margin`` of itself, BIC down, residual whiter unless the
    held-out error falls by :data:`LARGE_GAIN` or more."""
    if not e_ho_new <= (1 - margin) * e_ho_cur:
        return False, holdout_not_enough(e_ho_cur, e_ho_new, margin)
    if not bic_new < bic_cur:
        return False, f"BIC does not improve ({bic_cur:.1f} -> {bic_new:.1f})"
    gain = 1.0 - e_ho_new / e_ho_cur if e_ho_cur > 0 else 0.0
    if not flat_new > flat_cur and gain < LARGE_GAIN:
        return False, (
            f"residual no whiter (spectral flatness {flat_cur:.3f} -> {flat_new:.3f}) "
            f"and the held-out gain {100 * gain:.1f} % is below {100 * LARGE_GAIN:g} %"
        )
    return True, ""


def param_report(term, values: dict, sigma: dict, limits: dict | None = None) -> tuple[bool, str, dict]:
    """Are the parameters off their bounds (a scanned one: off its scan's limits,
    ``limits``, default :func:`sim.calibrate.trace.scan_limits` without a record rate)
    with a finite 95 % interval excluding zero?"""
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


def tie_break(passed: list, margin: float) -> int:
    """Index into ``passed`` (``(held-out error, flatness)`` of the candidates that passed,
    best explained first) of the one to add: the first, unless another's held-out error is
    within ``margin`` of it, in which case the whitest of those."""
    if not passed:
        raise ValueError("tie_break: no candidate passed")
    e0 = passed[0][0]
    close = [i for i, (e, _f) in enumerate(passed) if abs(e - e0) <= margin * e0]
    return max(close, key=lambda i: (passed[i][1], -i))


# ------------------------------------------------------------------ plausibility
@dataclass
class TableScale:
    """What the table can do, per place: the actuators' stall force (N) and the declared
    moving mass (kg), and its valves' rated flow and supply pressure."""

    force_n: dict  # place -> N
    mass_kg: dict  # place -> kg
    rated_flow_m3_s: float
    supply_pa: float
    payload_kg: float = 0.0  # the declared payload's mass (0: none)


def table_scale(desc, payload=None) -> TableScale:
    """The :class:`TableScale` of ``desc`` (with ``payload``): stall force A p_s per
    actuator (the larger piston area), summed along each DOF through the Jacobian; the
    effective mass at home (:meth:`sim.effects.TableModel.effective_mass_matrix`), seen
    along each DOF and each actuator's stroke."""
    from hydraulics.params import HydraulicParams
    from mjcf.description import DOFS6
    from sim.control.tvc import dof_jacobian
    from sim.effects import build_model

    hp = HydraulicParams.from_table(desc.raw)
    stall = np.maximum(np.asarray(hp.area_a_m2, float), np.asarray(hp.area_b_m2, float)) * hp.supply_pressure_pa
    tm = build_model(desc, payload)
    idx6 = [DOFS6[j] for j in tm.platen_dof_index]
    k_of = [idx6.index(d) for d in desc.dofs]
    Me = tm.effective_mass_matrix()[np.ix_(k_of, k_of)]
    J = dof_jacobian(desc)[:, [DOFS6.index(d) for d in desc.dofs]]
    force, mass = {}, {}
    for j, d in enumerate(desc.dofs):
        force[f"dof:{d}"] = float(np.sum(stall * np.abs(J[:, j])))
        mass[f"dof:{d}"] = float(Me[j, j])
    Mi = np.linalg.pinv(Me)
    for i, name in enumerate(desc.actuator_names):
        force[f"actuator:{name}"] = float(stall[i])
        mass[f"actuator:{name}"] = 1.0 / max(float(J[i] @ Mi @ J[i]), 1e-30)
    for c in sorted({a.cls.name for a in desc.actuators}):
        idx = [i for i, a in enumerate(desc.actuators) if a.cls.name == c]
        force[f"class:{c}"] = float(np.min(stall[idx]))  # the effect acts on each actuator of it
        mass[f"class:{c}"] = float(np.min([mass[f"actuator:{desc.actuator_names[i]}"] for i in idx]))
    force["actuators"] = float(np.min(stall))
    mass["actuators"] = float(np.min([mass[f"actuator:{n}"] for n in desc.actuator_names]))
    payload_kg = float(np.sum(getattr(payload, "mass_kg", 0.0))) if payload is not None else 0.0
    return TableScale(force, mass, float(hp.rated_flow_m3_s), float(hp.supply_pressure_pa), payload_kg)


def implausible(name: str, where: str, params: dict, scale: TableScale, force: tuple | None = None) -> str:
    """Why an effect at ``where`` is not physically there (empty: plausible); ``force``:
    ``(place, N)``, its force's peak at the recorded motion along a place (None: not checked)."""
    if force is not None:
        at, peak = force
        cap = scale.force_n.get(at)
        if cap and peak > FORCE_SHARE * cap:
            return (
                f"{COMPENSATION}: its force reaches {peak / 1e3:.3g} kN at the recorded motion, more than "
                f"the actuators deliver along {at} ({cap / 1e3:.3g} kN: piston area x supply pressure)"
            )
    taken = params.get("taken_from_payload_kg", 0.0)  # the modes' share of the declared payload
    if name == "payload_mode" and params.get("from_payload") and taken > scale.payload_kg:
        return f"{COMPENSATION}: the modes take {taken:.4g} kg out of a declared payload of {scale.payload_kg:.4g} kg"
    m0 = scale.mass_kg.get(where)
    if name == "added_mass" and m0 and abs(params.get("mass_kg", 0.0)) > MASS_RATIO * m0:
        return (
            f"{COMPENSATION}: {params['mass_kg']:.4g} kg is more than {MASS_RATIO:g} x the moving mass "
            f"at {where} ({m0:.4g} kg)"
        )
    return _implausible_hydraulic(name, params, scale)


def _implausible_hydraulic(name: str, params: dict, scale: TableScale) -> str:
    if name == "valve_flow_gain":
        f = params["factor"]
        lo, hi = FLOW_GAIN_RANGE
        if not lo <= f <= hi:
            return (
                f"{COMPENSATION}: a flow gain factor of {f:.3g} is outside {lo:g}-{hi:g} (flow ~ sqrt(pressure drop))"
            )
    if name == "valve_bandwidth" and params["bandwidth_hz"] < MIN_VALVE_BANDWIDTH_HZ:
        return f"{COMPENSATION}: a valve bandwidth of {params['bandwidth_hz']:.3g} Hz is below {MIN_VALVE_BANDWIDTH_HZ:g} Hz"
    if name == "leakage":
        q = params["coefficient_m3_s_pa"] * scale.supply_pa
        if q > LEAK_SHARE * scale.rated_flow_m3_s:
            return (
                f"{COMPENSATION}: the leak passes {q:.3g} m^3/s at the supply pressure, more than the valve's "
                f"rated flow {scale.rated_flow_m3_s:.3g} m^3/s"
            )
    if name == "bulk_modulus" and params["bulk_modulus_pa"] < MIN_BULK_MODULUS_PA:
        return f"{COMPENSATION}: a bulk modulus of {params['bulk_modulus_pa']:.3g} Pa is below {MIN_BULK_MODULUS_PA:.3g} Pa"
    if name == "bulk_modulus" and params["bulk_modulus_pa"] > MAX_BULK_MODULUS_PA:
        return (
            f"{COMPENSATION}: a bulk modulus of {params['bulk_modulus_pa']:.3g} Pa is above any oil's "
            f"({MAX_BULK_MODULUS_PA:.3g} Pa)"
        )
    return ""


def force_peak_of_entry(name: str, params: dict, motion: tuple) -> float | None:
    """The peak force (N) of a mechanical effect entry at a place whose recorded motion
    peaks at ``motion`` = (u, v, a); None for an effect without a force law here."""
    u, v, a = motion
    if name == "coulomb_friction":
        return abs(params["force_n"]) + abs(params.get("coefficient", 0.0)) * u
    if name == "viscous_damping":
        return abs(params["damping_n_s_m"]) * v
    if name == "power_damping":
        return abs(params["coefficient"]) * v ** params["exponent"]
    if name == "spring":
        return abs(params["stiffness_n_m"]) * u
    if name == "added_mass":
        return abs(params["mass_kg"]) * a
    return None


def implausible_candidate(cand, values: dict, scale: TableScale, peaks: dict) -> str:
    """:func:`implausible` of a replay or closed-loop candidate: its force at the place's
    recorded peak motion ``peaks[where]`` = (u, v, a) (:func:`force_peak_of_entry`)."""
    vals = {**cand.fixed, **values}
    fp = force_peak_of_entry(cand.type, vals, peaks[cand.where]) if cand.where in peaks else None
    return implausible(cand.type, cand.where, vals, scale, (cand.where, fp) if fp is not None else None)


__all__ = [
    "COMPENSATION",
    "HOLDOUT_MARGIN",
    "LARGE_GAIN",
    "TableScale",
    "Z95",
    "accept",
    "accept_numbers",
    "bound_hit",
    "force_peak_of_entry",
    "implausible",
    "implausible_candidate",
    "nested_at_bound",
    "param_report",
    "table_scale",
    "tie_break",
]
