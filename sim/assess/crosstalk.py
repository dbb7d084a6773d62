"""Geometric nonlinearity in motion: closed-loop crosstalk with the exact and the
linearised DOF transformation.

The table's controller turns the DOF reference into actuator strokes. With the exact
inverse kinematics of the linkages (what the model's controller does) a large
longitudinal stroke commands the small extra strokes the tilting linkages need; with the
home-pose (linearised) transformation ``s = J(0) r`` it does not, and the platen moves
in the DOFs that were not asked for: the parasitic motion or crosstalk. :func:`crosstalk`
runs the same motion both ways and measures the motion in every DOF the reference leaves
at rest (peak and RMS, m or rad).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mjcf.description import DOFS6
from sim.scenario.motions import tapered_sine

#: the study's motions: (dof, amplitude m, frequency Hz) for the sines; El Centro at 80 %
#: (the CGS paper's earthquake validation level). The frequencies keep the rated velocity
#: (1.1 m/s) and acceleration (1 g) of the CGS table: 2 pi f A <= 1.1, (2 pi f)^2 A <= 9.81.
SINES = {"x_250mm_sine": ("x", 0.250, 0.25), "y_150mm_sine": ("y", 0.150, 0.25)}
EL_CENTRO_FACTOR = 0.8


@dataclass
class Crosstalk:
    """Per motion and DOF: the parasitic peak and RMS with each transformation, and the
    time histories (``t``, ``exact``, ``linearised``: (n, 6) achieved poses)."""

    table: dict
    histories: dict


def _motions(name: str, desc, rate: float, quick: bool):
    from sim.scenario.records import el_centro_motions

    if name in SINES:
        dof, amp, f = SINES[name]
        half = dict(zip(DOFS6, np.concatenate([desc.limits.stroke_m, desc.limits.rotation_rad])))[dof]
        amp = min(amp, float(half))
        cycles = 1.0 if quick else 2.0
        dur = (2 * cycles + (1.0 if quick else 2.0)) / f
        return {
            dof: tapered_sine(amplitude=amp, frequency_hz=f, duration_s=dur, sample_rate_hz=rate, taper_cycles=cycles)
        }
    if name == "elcentro_3c":
        mo = el_centro_motions(sample_rate_hz=rate, amplitude_factor=EL_CENTRO_FACTOR)
        return {d: m for d, m in mo.items() if d in desc.dofs}
    raise ValueError(f"unknown crosstalk motion '{name}'")


def crosstalk(
    desc,
    payload=None,
    *,
    motions=("x_250mm_sine", "y_150mm_sine", "elcentro_3c"),
    quick: bool = False,
    duration_s: float | None = None,
) -> Crosstalk:
    """Run each motion closed loop with the exact and with the linearised transformation.

    ``quick``: one-cycle sines (tests). ``duration_s``: cut every run to this length.
    Returns a :class:`Crosstalk`; a DOF counts as parasitic when the motion's reference
    does not drive it.
    """
    from sim.control.tvc import ControllerGains
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.scenario.reference import reference_from_motions

    tm = build_model(desc, payload)
    gains = ControllerGains.for_table(desc)
    sim = Simulation(tm, gains=gains)
    rate = gains.rate_hz
    table, hist = {}, {}
    for name in motions:
        mo = _motions(name, desc, rate, quick)
        length = max(m.duration_s for m in mo.values())
        ref = reference_from_motions(mo, rate, min(length, duration_s) if duration_s else length)
        driven = {d for d, m in mo.items() if np.any(m.d != 0)}
        runs = {}
        for kin in ("exact", "linear"):
            sim.reset()
            res = sim.run(reference=ref, kinematics=kin)
            if res.incomplete_reason:
                raise RuntimeError(f"crosstalk run {name} ({kin}) stopped: {res.incomplete_reason}")
            runs[kin] = res.channels["table_displacement"]
        n = min(len(runs["exact"]), len(runs["linear"]))
        row = {}
        for i, d in enumerate(DOFS6):
            if d in driven or d not in desc.dofs:
                continue
            ex, li = runs["exact"][:n, i], runs["linear"][:n, i]
            ex, li = ex - ex[0], li - li[0]  # about the rest pose at the start
            row[d] = {
                "linearised_peak": float(np.max(np.abs(li))),
                "exact_peak": float(np.max(np.abs(ex))),
                "linearised_rms": float(np.sqrt(np.mean(li**2))),
                "exact_rms": float(np.sqrt(np.mean(ex**2))),
            }
            # linearised / exact peak, where the linearised crosstalk is above round-off
            floor = 1e-9
            row[d]["ratio"] = (
                float(row[d]["linearised_peak"] / max(row[d]["exact_peak"], floor))
                if row[d]["linearised_peak"] > floor
                else None
            )
        table[name] = row
        hist[name] = {
            "t": np.arange(n) / rate,
            "exact": runs["exact"][:n],
            "linearised": runs["linear"][:n],
            "reference": ref.d[:n],
            "driven": sorted(driven),
        }
    return Crosstalk(table=table, histories=hist)


__all__ = ["Crosstalk", "EL_CENTRO_FACTOR", "SINES", "crosstalk"]
