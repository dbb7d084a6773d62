"""Off-line drive-signal iteration on the model (what table controllers do before a test).

The closed loop of table + controller has a frequency response H(f) per DOF that is not
1: the oil columns (16-29 Hz on the CGS table) amplify, the servovalves lag. Labs
therefore iterate the drive: run, measure, correct the drive by the error divided by the
estimated response, run again. Here the "table" is the model, so the iteration is done
before the test to predict what the table will achieve after its own compensation.

Per DOF, in the frequency domain of the whole record (diagonal, no cross-coupling)::

    D_{i+1}(f) = D_i(f) + g * (T(f) - Y_i(f)) / H_i(f)      for f in band
    H_i(f)     = S_dy(f) / S_dd(f)   (Welch estimate of achieved/drive, |H| >= h_min)

with T the target displacement, Y_i the achieved one and D_i the drive. Velocity and
acceleration of the drive come from the same spectrum (i w D, -w^2 D), so the drive is
consistent for the controller's feed-forward.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal

from sim.loop import Reference


@dataclass(frozen=True, kw_only=True)
class IterationSettings:
    count: int = 3  #: corrections after the first run
    gain: float = 0.8  #: fraction of the estimated correction applied per iteration
    band_hz: tuple[float, float] = (0.2, 40.0)  #: frequencies corrected
    h_min: float = 0.25  #: floor on |H| (do not amplify notches without bound)
    nperseg: int = 4096  #: Welch segment for the FRF estimate


def _spectral_derivatives(d: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    n = len(d)
    D = np.fft.rfft(d, axis=0)
    w = 2 * np.pi * np.fft.rfftfreq(n, 1.0 / rate)
    v = np.fft.irfft(1j * w[:, None] * D, n=n, axis=0)
    a = np.fft.irfft(-(w ** 2)[:, None] * D, n=n, axis=0)
    return v, a


def update_drive(drive: Reference, target: Reference, achieved_d: np.ndarray, s: IterationSettings,
                 dofs: list[int]) -> Reference:
    """One iteration step: a corrected drive from the last run's achieved displacement."""
    rate = target.rate_hz
    n = len(target.t)
    y = np.zeros_like(target.d)
    m = min(n, len(achieved_d))
    y[:m] = achieved_d[:m]
    f = np.fft.rfftfreq(n, 1.0 / rate)
    band = (f >= s.band_hz[0]) & (f <= s.band_hz[1])
    new_d = drive.d.copy()
    for i in dofs:
        fw, Pdd = signal.welch(drive.d[:, i], fs=rate, nperseg=min(s.nperseg, n))
        _, Pdy = signal.csd(drive.d[:, i], y[:, i], fs=rate, nperseg=min(s.nperseg, n))
        H = Pdy / np.maximum(Pdd, 1e-30)
        Hf = np.interp(f, fw, H.real) + 1j * np.interp(f, fw, H.imag)
        mag = np.abs(Hf)
        Hf = np.where(mag < s.h_min, Hf / np.maximum(mag, 1e-12) * s.h_min, Hf)
        E = np.fft.rfft(target.d[:, i] - y[:, i])
        Dn = np.fft.rfft(drive.d[:, i])
        Dn[band] += s.gain * E[band] / Hf[band]
        new_d[:, i] = np.fft.irfft(Dn, n=n)
    v, a = _spectral_derivatives(new_d, rate)
    # keep the target's own v, a for DOFs not iterated
    keep = [j for j in range(6) if j not in dofs]
    v[:, keep] = target.v[:, keep]
    a[:, keep] = target.a[:, keep]
    return Reference(t=target.t, d=new_d, v=v, a=a)


def iterate(sim, target: Reference, settings: IterationSettings, *, progress=None):
    """Run the plain controller, then ``settings.count`` corrected drives.

    Returns (results, drives): the RunResult of every run (first = plain controller) and
    the drive of each run.
    """
    dofs = [i for i in range(6) if np.sqrt(np.mean(target.d[:, i] ** 2)) > 1e-9]
    drive = target
    results, drives = [], []
    for it in range(settings.count + 1):
        if progress:
            progress(it)
        sim.reset()
        res = sim.run(reference=drive)
        results.append(res)
        drives.append(drive)
        if res.incomplete_reason or it == settings.count:
            break
        drive = update_drive(drive, target, res.channels["table_displacement"], settings, dofs)
    return results, drives
