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

from mjcf.description import DOFS6 as DOFS
from sim.scenario.reference import Reference, reference_from_motions


@dataclass(frozen=True, kw_only=True)
class IterationSettings:
    count: int = 2  #: corrections after the first run
    gain: float = 0.6  #: fraction of the estimated correction applied per iteration
    band_hz: tuple[float, float] = (0.2, 25.0)  #: frequencies corrected
    h_min: float = 0.25  #: floor on |H| (do not amplify notches without bound)
    nperseg: int = 4096  #: Welch segment for the FRF estimate
    frf: str = "noise"
    """Where H comes from: ``"record"`` = each run's own drive and response (Welch);
    ``"noise"`` = one identification run with band-limited white noise on every
    commanded DOF before the iteration (what table controllers do before iterating),
    reused for every correction."""
    noise_level: float = 1.0
    """RMS acceleration of the identification noise per DOF, as a multiple of the
    target's own RMS acceleration in that DOF (the FRF is taken near the test's level:
    friction and valve flow make it amplitude dependent)."""
    noise_duration_s: float = 40.0
    noise_band_hz: tuple[float, float] = (0.3, 45.0)
    seed: int = 0  #: seed of the identification noise

    @classmethod
    def from_scenario(cls, it: dict) -> "IterationSettings":
        """From a scenario's (validated, see :mod:`sim.scenario.files`) ``[iteration]`` table;
        keys left out keep the defaults above."""
        conv = {
            "count": int,
            "gain": float,
            "band_hz": tuple,
            "h_min": float,
            "frf": str,
            "noise_level": float,
            "seed": int,
        }
        return cls(**{k: conv[k](v) for k, v in it.items() if k in conv})


def _spectral_derivatives(d: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    n = len(d)
    D = np.fft.rfft(d, axis=0)
    w = 2 * np.pi * np.fft.rfftfreq(n, 1.0 / rate)
    v = np.fft.irfft(1j * w[:, None] * D, n=n, axis=0)
    a = np.fft.irfft(-(w**2)[:, None] * D, n=n, axis=0)
    return v, a


def _welch_frf(x: np.ndarray, y: np.ndarray, rate: float, nperseg: int):
    """H1 estimate (Hann, half overlap, mean removed) by the project's one estimator,
    :func:`sim.signals.estimation.frf`; bins without input power (0/0 at DC) read 0."""
    from sim.signals.estimation import frf

    nps = min(nperseg, len(x))
    r = frf(x, y, rate, nperseg=nps, overlap=(nps // 2) / nps, window="hann", estimator="H1")
    return r.f, np.where(np.isfinite(r.H), r.H, 0.0)


def identify_frf(sim, target: Reference, dofs: list[int], s: IterationSettings, *, run=None) -> dict:
    """Per DOF, H(f) of achieved over commanded displacement from one white-noise run
    (all ``dofs`` excited together with independent seeds). Returns {dof: (f, H)}.
    ``run(reference) -> RunResult``: how the simulation runs (default ``sim.run``).

    Why not the record's own runs: above ~12 Hz an earthquake drive has little content
    while the achieved motion there is dominated by what friction adds at every
    velocity reversal, which is correlated with the drive; the cross-spectral estimate
    is then biased and the corrections in the oil-column band stall (measured on the
    CGS table, El Centro 80 %, 0.1 mm pre-sliding friction, 1 m/s^2 noise: y spectrum
    ratio 1.49 / 1.52 / 1.44 after 1 / 2 / 3 iterations with the record's own H,
    1.27 / 1.13 / 1.07 with this one)."""
    from sim.scenario.motions import white_noise

    rate = target.rate_hz
    motions = {}
    for i in dofs:
        level = s.noise_level * float(np.sqrt(np.mean(target.a[:, i] ** 2)))
        if not level > 0:
            raise ValueError(f"DOF {i} has a displacement target but no acceleration to scale the noise to")
        motions[DOFS[i]] = white_noise(
            duration_s=s.noise_duration_s,
            sample_rate_hz=rate,
            band_hz=s.noise_band_hz,
            seed=(s.seed, i),
            rms_acceleration=level,
        )
    noise = reference_from_motions(motions, rate, s.noise_duration_s)
    d, n = noise.d, len(noise.t)
    sim.reset()
    from sim.errors import RunInterrupted

    try:
        res = run(noise) if run is not None else sim.run(reference=noise)
    except RunInterrupted:  # Ctrl-C in the identification run: nothing of the scenario to keep yet
        raise KeyboardInterrupt from None
    if res.incomplete_reason:
        from sim.errors import ScenarioError

        raise ScenarioError(
            f"the white-noise identification run before the drive iteration stopped "
            f'({res.incomplete_reason}); lower [iteration] noise_level or set frf = "record"'
        )
    y = res.channels["table_displacement"]
    m = min(n, len(y))
    return {i: _welch_frf(d[:m, i], y[:m, i], rate, s.nperseg) for i in dofs}


def update_drive(
    drive: Reference,
    target: Reference,
    achieved_d: np.ndarray,
    s: IterationSettings,
    dofs: list[int],
    frf: dict | None = None,
) -> Reference:
    """One iteration step: a corrected drive from the last run's achieved displacement."""
    rate = target.rate_hz
    n = len(target.t)
    y = np.zeros_like(target.d)
    m = min(n, len(achieved_d))
    y[:m] = achieved_d[:m]
    f = np.fft.rfftfreq(n, 1.0 / rate)
    band = (f >= s.band_hz[0]) & (f <= s.band_hz[1])
    delta = np.zeros_like(drive.d)
    # the error is faded in and out over the first and last second (at most 5 % of the
    # record each) so the correction is periodic and its spectral derivatives are smooth
    nt = max(1, min(int(rate), n // 20))
    taper = np.ones(n)
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(nt) / nt)
    taper[:nt] = ramp
    taper[n - nt :] = ramp[::-1]
    for i in dofs:
        if frf is not None:
            fw, H = frf[i]
        else:
            fw, H = _welch_frf(drive.d[:, i], y[:, i], rate, s.nperseg)
        Hf = np.interp(f, fw, H.real) + 1j * np.interp(f, fw, H.imag)
        mag = np.abs(Hf)
        Hf = np.where(mag < s.h_min, Hf / np.maximum(mag, 1e-12) * s.h_min, Hf)
        E = np.fft.rfft((target.d[:, i] - y[:, i]) * taper)
        C = np.zeros_like(E)
        C[band] = s.gain * E[band] / Hf[band]
        delta[:, i] = np.fft.irfft(C, n=n)
    # Only the band-limited correction is differentiated spectrally: it is periodic by
    # construction, whereas the drive itself need not be (a record cut short by
    # --duration ends mid-motion, and the spectral derivative of its wrap-around jump
    # would put a spike of tens of g into the drive's acceleration).
    dv, da = _spectral_derivatives(delta, rate)
    return Reference(t=target.t, d=drive.d + delta, v=drive.v + dv, a=drive.a + da)


def iterate(sim, target: Reference, settings: IterationSettings, *, progress=None, run=None):
    """Run the plain controller, then ``settings.count`` corrected drives;
    ``run(reference) -> RunResult`` runs ``sim`` from its reset state (default
    ``sim.run``; the callback route gives the same runs).

    Returns (results, drives): the RunResult of every run (first = plain controller) and
    the drive of each run.
    """
    dofs = [i for i in range(6) if np.sqrt(np.mean(target.d[:, i] ** 2)) > 1e-9]
    drive = target
    frf = identify_frf(sim, target, dofs, settings, run=run) if settings.frf == "noise" and settings.count else None
    results, drives = [], []
    for it in range(settings.count + 1):
        if progress:
            progress(it)
        sim.reset()
        res = run(drive) if run is not None else sim.run(reference=drive)
        results.append(res)
        drives.append(drive)
        if res.incomplete_reason or it == settings.count:
            break
        drive = update_drive(drive, target, res.channels["table_displacement"], settings, dofs, frf)
    return results, drives
