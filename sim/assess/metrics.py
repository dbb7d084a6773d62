"""Tracking and comparison figures for runs (what ``summary.json`` reports)."""

from __future__ import annotations

import numpy as np

from mjcf.description import DOFS6
from sim.scenario.motions import response_spectrum

DOFS = DOFS6
SPECTRUM_BAND_HZ = (0.5, 20.0)


def nrmse(achieved: np.ndarray, reference: np.ndarray) -> float:
    """RMS(achieved - reference) / RMS(reference); NaN if the reference is zero."""
    ok = np.isfinite(achieved) & np.isfinite(reference)
    r = reference[ok]
    den = float(np.sqrt(np.mean(r**2))) if r.size else 0.0
    if den == 0.0:
        return float("nan")
    return float(np.sqrt(np.mean((achieved[ok] - r) ** 2)) / den)


def spectrum_ratio(a_achieved, a_reference, dt, band_hz=SPECTRUM_BAND_HZ, n=60, damping=0.05):
    """5 %-damped pseudo-acceleration spectrum ratio achieved / reference over ``band_hz``.

    Returns (freqs, ratio) on ``n`` log-spaced frequencies.
    """
    f = np.geomspace(band_hz[0], band_hz[1], n)
    ok = np.isfinite(a_achieved) & np.isfinite(a_reference)
    sa = response_spectrum(np.where(ok, a_achieved, 0.0), dt, freqs=f, damping=damping)
    sr = response_spectrum(np.where(ok, a_reference, 0.0), dt, freqs=f, damping=damping)
    return f, sa / np.maximum(sr, 1e-12)


def tracking(t, reference_d, reference_a, achieved_d, achieved_a, *, commanded_tol=1e-9) -> dict:
    """Per commanded DOF: nrmse_displacement, nrmse_acceleration, pga_ratio and the
    response-spectrum ratio range (0.5-20 Hz)."""
    out = {}
    dt = float(t[1] - t[0])
    n = min(len(achieved_d), len(reference_d))
    for i, dof in enumerate(DOFS):
        rd = reference_d[:n, i]
        if np.sqrt(np.mean(rd**2)) <= commanded_tol:
            continue
        ra = reference_a[:n, i]
        ad = achieved_d[:n, i]
        aa = achieved_a[:n, i]
        pga_ref = float(np.nanmax(np.abs(ra)))
        entry = {
            "nrmse_displacement": nrmse(ad, rd),
            "nrmse_acceleration": nrmse(aa, ra),
            "pga_ratio": float(np.nanmax(np.abs(aa)) / pga_ref) if pga_ref > 0 else float("nan"),
            "peak_displacement_reference": float(np.max(np.abs(rd))),
            "peak_displacement_achieved": float(np.nanmax(np.abs(ad))),
            "pga_reference": pga_ref,
        }
        if n * dt > 2.0 / SPECTRUM_BAND_HZ[0]:
            _, r = spectrum_ratio(aa, ra, dt)
            entry["spectrum_ratio_min"] = float(r.min())
            entry["spectrum_ratio_max"] = float(r.max())
        out[dof] = entry
    return out


def channel_residuals(a, b) -> dict:
    """NRMSE of every channel present in both run files (b against a), per column."""
    from sim.runs.runfile import CHANNELS

    out = {}
    n = min(a.n_samples, b.n_samples)
    for ch in CHANNELS:
        x, y = getattr(a, ch), getattr(b, ch)
        if x is None or y is None or x.shape[1] != y.shape[1]:
            continue
        names = a.column_names(ch)
        out[ch] = {nm: nrmse(y[:n, j], x[:n, j]) for j, nm in enumerate(names)}
    return out
