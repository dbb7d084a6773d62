"""What a fault did: the events of a run with faults and the demands that followed.

:func:`fault_summary` reads the fault effects of the table model after a run
(:mod:`sim.effects.faults`: each keeps when it took effect, the interlock its trip) and
the recorded channels, and returns ``summary["faults"]``:

* ``events``: each fault (what, where, declared start, when it took effect); a run with
  no fault that drives an actuator into its end cushion has that as its event (a
  summary without faults and cushions has no ``faults`` at all);
* ``interlock``: its limits and its trip (what tripped, where, when, value and limit),
  or None when the run had no interlock;
* ``after``: the peak demands on the table and the specimen from the first event on:
  stroke per actuator (and the fraction of the usable stroke), the first time an
  actuator entered its end cushion, force (and fraction of the stall force), chamber
  pressure, supply pressure (minimum), table acceleration per DOF, and with a payload
  its base shear and deformation (storey drift, tip displacement);
* ``interlock_before_end_stops``: did the interlock trip before any actuator reached
  its end cushion (None when either did not happen), with both times.
"""

from __future__ import annotations

import numpy as np

from mjcf.description import DOFS6


def _peak(a) -> float | None:
    a = np.asarray(a, float)
    a = a[np.isfinite(a)]
    return float(np.max(np.abs(a))) if a.size else None


def fault_summary(res, tm, hp, payload=None) -> dict | None:
    """``summary["faults"]`` of run ``res`` of table model ``tm`` (None: no fault and no
    end cushion reached)."""
    from sim.assess.feasibility import specimen_response
    from sim.effects.faults import Interlock, is_fault

    faults = [e for e in tm.effects if is_fault(e)]
    t = np.asarray(res.t, float)
    names = list(hp.names)
    usable = np.asarray(hp.half_stroke_m - hp.cushion_length_m, float)
    whole = np.abs(res.channels["actuator_displacement"]) > usable
    hit = None
    if whole.any():  # an end cushion reached (a fault or a drive beyond the stroke)
        k, i = np.argwhere(whole)[0]
        hit = {
            "type": "end_cushion",
            "what": "end cushion reached",
            "where": f"actuator:{names[i]}",
            "start_s": None,
            "t_s": float(t[k]),
        }
    if not faults and hit is None:
        return None
    events = [e.event() for e in faults if not isinstance(e, Interlock)]
    if not events and hit is not None:
        events = [hit]
    locks = [e for e in faults if isinstance(e, Interlock)]
    lock = locks[0].event() if locks else None
    times = [ev["t_s"] for ev in events if ev["t_s"] is not None]
    if lock and lock["trip"] and not times:
        times = [lock["trip"]["t_s"]]
    t0 = min(times) if times else None
    out = {"events": events, "interlock": lock, "from_s": t0, "after": None, "interlock_before_end_stops": None}
    if t0 is None or not len(t):
        return out
    sel = t >= t0 - 1e-9
    ch = res.channels
    s = ch["actuator_displacement"][sel]
    peak_s = np.nanmax(np.abs(s), axis=0) if len(s) else np.zeros(len(names))
    into = np.abs(s) > usable
    cushion = None
    if into.any():
        k, i = np.argwhere(into)[0]
        cushion = {"actuator": names[i], "t_s": float(t[sel][k])}
    F = ch["actuator_force"][sel]
    stall = np.asarray(hp.area_a_m2, float) * hp.supply_pressure_pa
    peak_f = np.nanmax(np.abs(F), axis=0) if len(F) else np.zeros(len(names))
    acc = ch["table_acceleration"][sel]
    after = {
        "peak_stroke_m": {n: float(v) for n, v in zip(names, peak_s)},
        "peak_stroke_fraction_of_usable": {n: float(v / u) for n, v, u in zip(names, peak_s, usable)},
        "end_cushion_reached": cushion,
        "peak_force_n": {n: float(v) for n, v in zip(names, peak_f)},
        "peak_force_fraction_of_stall": {n: float(v / c) for n, v, c in zip(names, peak_f, stall)},
        "peak_chamber_pressure_pa": _peak(
            np.concatenate([ch["pressure_a"][sel].ravel(), ch["pressure_b"][sel].ravel()])
        ),
        "min_supply_pressure_pa": float(np.nanmin(res.extras["supply_pressure"][sel]))
        if sel.any() and np.isfinite(res.extras["supply_pressure"][sel]).any()
        else None,
        "peak_table_acceleration_m_s2": {d: _peak(acc[:, j]) for j, d in enumerate(DOFS6) if np.any(acc[:, j])},
        "specimen": None,
    }
    sp = specimen_response(res, tm) if payload is not None or tm.payload is not None else None
    if sp is not None:
        after["specimen"] = {
            "kind": sp["kind"],
            "peak_base_shear_n": _peak(sp["base_shear_n"][sel]),
            "peak_overturning_n_m": _peak(sp["overturning_n_m"][sel]),
        }
        if sp["deformation"] is not None:
            after["specimen"]["peak_" + sp["deformation_name"]] = _peak(sp["deformation"][sel])
    out["after"] = after
    trip = lock["trip"] if lock else None
    if trip is not None and cushion is not None:
        out["interlock_before_end_stops"] = bool(trip["t_s"] < cushion["t_s"])
    elif trip is not None:
        out["interlock_before_end_stops"] = True  # tripped, and no actuator reached its cushion
    return out


def fault_lines(f: dict) -> list[str]:
    """The printed lines of ``summary["faults"]``."""
    lines = []
    for ev in f["events"]:
        when = f"t = {ev['t_s']:.4f} s" if ev["t_s"] is not None else f"not reached (start {ev['start_s']:g} s)"
        lines.append(f"fault: {ev['what']} at {ev['where']}, {when}")
    lock = f.get("interlock")
    if lock is not None:
        tr = lock["trip"]
        if tr is None:
            lines.append("interlock: did not trip")
        else:
            lines.append(
                f"interlock tripped: {tr['what']} at {tr['where']}, t = {tr['t_s']:.4f} s "
                f"({tr['value']:.4g} {tr['unit']} vs limit {tr['limit']:.4g} {tr['unit']}); {tr['action']}"
            )
    a = f.get("after")
    if a:
        name = max(a["peak_stroke_fraction_of_usable"], key=a["peak_stroke_fraction_of_usable"].get)
        fname = max(a["peak_force_fraction_of_stall"], key=a["peak_force_fraction_of_stall"].get)
        acc = a["peak_table_acceleration_m_s2"]
        lines.append(
            f"after t = {f['from_s']:.3f} s: peak stroke {1e3 * a['peak_stroke_m'][name]:.1f} mm ({name}, "
            f"{100 * a['peak_stroke_fraction_of_usable'][name]:.0f} % of usable), peak force "
            f"{a['peak_force_n'][fname] / 1e3:.0f} kN ({fname}, {100 * a['peak_force_fraction_of_stall'][fname]:.0f} % "
            f"of stall), min supply {(a['min_supply_pressure_pa'] or float('nan')) / 1e6:.1f} MPa"
        )
        if acc:
            lines.append(
                "  peak table acceleration "
                + ", ".join(f"{d} {v:.2f}" for d, v in acc.items())
                + " m/s^2"
                + (" (rotations in rad/s^2)" if any(d.startswith("r") for d in acc) else "")
            )
        c = a["end_cushion_reached"]
        lines.append(
            f"  end cushion reached by {c['actuator']} at t = {c['t_s']:.4f} s"
            if c
            else "  no actuator reached its end cushion"
        )
        if a["specimen"]:
            sp = a["specimen"]
            extra = ", ".join(
                f"{k[5:]} {v:.4g}" for k, v in sp.items() if k.startswith("peak_") and k != "peak_base_shear_n"
            )
            lines.append(f"  specimen ({sp['kind']}): peak base shear {sp['peak_base_shear_n'] / 1e3:.1f} kN, {extra}")
    if f.get("interlock_before_end_stops") is not None:
        lines.append(
            "  interlock before the end stops: "
            + ("yes" if f["interlock_before_end_stops"] else "NO (see the times above)")
        )
    return lines


__all__ = ["fault_lines", "fault_summary"]
