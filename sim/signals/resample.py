"""Moving a record between sample grids without reinterpreting its time.

A record sampled at its own rate (a lab's recorder at 200 Hz, 204.8 Hz, ...) drives a
model that ticks at another rate: the command is *held* (zero-order hold, as a DAC
holds a sample until the next one) or linearly interpolated onto the model's ticks, and
the model's output is sampled back at the record's instants.
"""

from __future__ import annotations

import numpy as np


def hold(t_src: np.ndarray, x_src: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Zero-order hold of ``x_src`` (N, ...) sampled at ``t_src`` onto ``t_dst``: each
    destination instant takes the last source sample at or before it (the first sample
    before the record starts). A tolerance of 1e-9 of the source step keeps instants that
    coincide up to round-off on their own sample."""
    t_src = np.asarray(t_src, float)
    t_dst = np.asarray(t_dst, float)
    step = float(t_src[1] - t_src[0]) if len(t_src) > 1 else 1.0
    idx = np.searchsorted(t_src, t_dst + 1e-9 * step, side="right") - 1
    return np.asarray(x_src)[np.clip(idx, 0, len(t_src) - 1)]


def interpolate(t_src: np.ndarray, x_src: np.ndarray, t_dst: np.ndarray) -> np.ndarray:
    """Linear interpolation of every column of ``x_src`` (N,) or (N, k) at ``t_dst``
    (held flat beyond the ends)."""
    x = np.asarray(x_src, float)
    if x.ndim == 1:
        return np.interp(t_dst, t_src, x)
    out = np.empty((len(t_dst),) + x.shape[1:])
    flat = x.reshape(len(x), -1)
    of = out.reshape(len(t_dst), -1)
    for j in range(flat.shape[1]):
        of[:, j] = np.interp(t_dst, t_src, flat[:, j])
    return out


def bandpass(x: np.ndarray, fs: float, band_hz: tuple[float, float], order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth band-pass of every column (axis 0). The upper edge is
    capped at 0.45 fs."""
    from scipy.signal import butter, sosfiltfilt

    lo, hi = float(band_hz[0]), min(float(band_hz[1]), 0.45 * fs)
    sos = butter(order, [lo, hi], btype="bandpass", fs=fs, output="sos")
    return sosfiltfilt(sos, np.asarray(x, float), axis=0)


__all__ = ["bandpass", "hold", "interpolate"]
