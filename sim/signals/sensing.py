"""What a sensor and a recorder do to a signal: gain, offset, delay, low-pass, noise,
sampling and quantisation. Pure functions on arrays sampled uniformly in time (axis 0),
used by the sensor effects (``sim.effects.sensors``) and the measurement model
(``sim.runs.measure``).
"""

from __future__ import annotations

import numpy as np


def fractional_delay(x: np.ndarray, delay_s: float, dt: float) -> np.ndarray:
    """``x`` delayed by ``delay_s`` (any real number of samples, may be negative = ahead):
    y(t) = x(t - delay), linear interpolation between samples; before the first sample
    (after the last, for a negative delay) the end value is held. Axis 0 is time."""
    x = np.asarray(x, dtype=np.float64)
    n = x.shape[0]
    if n == 0 or delay_s == 0.0:
        return x.copy()
    pos = np.arange(n) - delay_s / dt  # where each output sample reads the input
    pos = np.clip(pos, 0.0, n - 1)
    i0 = np.minimum(np.floor(pos).astype(np.int64), n - 2) if n > 1 else np.zeros(n, np.int64)
    if n == 1:
        return x.copy()
    w = (pos - i0).reshape((n,) + (1,) * (x.ndim - 1))
    return (1.0 - w) * x[i0] + w * x[i0 + 1]


def butter_lowpass_sos(cutoff_hz: float, order: int, fs: float) -> np.ndarray:
    """Second-order sections of a digital Butterworth low-pass (bilinear transform with
    the cutoff pre-warped, ``scipy.signal.butter(fs=...)``)."""
    import scipy.signal as S

    if not 0.0 < cutoff_hz < 0.5 * fs:
        raise ValueError(f"cutoff {cutoff_hz:g} Hz must lie in (0, {0.5 * fs:g}) Hz (the Nyquist frequency)")
    return S.butter(int(order), cutoff_hz, btype="lowpass", fs=fs, output="sos")


def analog_lowpass_sos(cutoff_hz: float, order: int, fs: float) -> np.ndarray:
    """Second-order sections of an analog Butterworth low-pass (a sensor's signal
    conditioner) discretised at ``fs`` by the bilinear transform *without* pre-warping,
    so its low-frequency delay is the analog filter's at any rate (as
    ``sim.identify.least_squares.analog_lowpass``, which calibration applies)."""
    import scipy.signal as S

    if not 0.0 < cutoff_hz < 0.5 * fs:
        raise ValueError(f"cutoff {cutoff_hz:g} Hz must lie in (0, {0.5 * fs:g}) Hz (the Nyquist frequency)")
    z, p, k = S.butter(int(order), 2.0 * np.pi * cutoff_hz, analog=True, output="zpk")
    return S.zpk2sos(*S.bilinear_zpk(z, p, k, fs))


def lowpass(x: np.ndarray, cutoff_hz: float, order: int, fs: float, analog: bool = False) -> np.ndarray:
    """Causal Butterworth low-pass along axis 0, started in steady state on the first
    sample (no start-up transient for a signal that starts constant); ``analog``: the
    analog conditioner of :func:`analog_lowpass_sos`, else the digital filter of
    :func:`butter_lowpass_sos`."""
    import scipy.signal as S

    x = np.asarray(x, dtype=np.float64)
    if x.shape[0] == 0:
        return x.copy()
    sos = (analog_lowpass_sos if analog else butter_lowpass_sos)(cutoff_hz, order, fs)
    zi = S.sosfilt_zi(sos)  # (n_sections, 2), unit step steady state
    zi = zi.reshape(zi.shape + (1,) * (x.ndim - 1)) * x[0][None, None]
    y, _ = S.sosfilt(sos, x, axis=0, zi=zi)
    return y


def quantise(x: np.ndarray, bits: int, full_scale: float) -> np.ndarray:
    """An ADC of ``bits`` over [-full_scale, +full_scale): the step is 2 full_scale / 2^bits,
    values round to the nearest step and clip at the ends (NaN stays NaN)."""
    step = 2.0 * full_scale / 2.0 ** int(bits)
    lo, hi = -(2.0 ** (int(bits) - 1)), 2.0 ** (int(bits) - 1) - 1
    return np.clip(np.round(np.asarray(x, dtype=np.float64) / step), lo, hi) * step


def quantisation_step(bits: int, full_scale: float) -> float:
    return 2.0 * full_scale / 2.0 ** int(bits)


__all__ = ["analog_lowpass_sos", "butter_lowpass_sos", "fractional_delay", "lowpass", "quantisation_step", "quantise"]
