"""How much each DOF of a mechanical-path run counts: the error a perfect model would
still leave there (its noise floor), and the weight that floor gives it in the fit and
in the pooled held-out error, as the replay path weighs its columns
(:func:`sim.calibrate.paths.noise_weights`).

The balance's residual is the recorded force less the model's force at the recorded
motion, so a perfect model still leaves two noises: the accelerometers' times the
moving mass (:func:`accelerometer_floor`) and the load cells' own (:func:`force_floor`).
Over the DOF's recorded force they make its floor. On a test that moves a 6-DOF table
along one axis, a rotation the test drives only through coupling sits at its floor
(CGS under x-only noise: the moment about y at 19.9 % against a floor of 18.7 %). Counted
alike with the driven axis (2.7 %), it set most of the pooled error (14.2 %), and an
effect that halved the driven axis's error fell under the acceptance margin.

A DOF's squared error counts by ``1 / (floor^2 + MODEL_ERROR^2)``, scaled so that a
run's weights over its excited DOFs average 1: where every DOF is well above its noise,
and on a table with one DOF, the pooled error is what it was, each run and DOF alike.
"""

from __future__ import annotations

import numpy as np

#: length of the white probe that measures the prefilter's noise gain (samples; the first
#: PROBE_SETTLE left out, the conditioner starting from rest). A numerical setting: 7680
#: samples give the gain within ~1 % (the RMS of n white samples scatters by 1/sqrt(2n));
#: a 4-pole conditioner at 100 Hz and 1 kHz settles in well under 512 samples
PROBE_N = 8192
PROBE_SETTLE = 512


def accelerometer_floor(mr) -> np.ndarray:
    """Per DOF, the NRMSE a perfect model would still leave on the mechanical path from
    the accelerometers: the recorded acceleration's white noise times the declared moving
    mass (the balance's inertial term read in the top of its band, where the table's
    motion holds next to nothing: :func:`sim.calibrate.conditioning.noise_floor`), over
    the DOF's recorded force. A rotation that a translational test moves only through
    coupling has its accelerometers' noise times its inertia for most of its error (CGS:
    the moments about x and y); this says so beside the error instead of leaving it to be
    read as a model that misses."""
    from sim.calibrate.conditioning import noise_floor

    inertial = mr.extra.get("inertial")
    span = _fit_span(mr)
    if inertial is None or span is None:
        return np.full(len(mr.dofs), np.nan)
    # the span of the fit rows, whole: the still rows cut out of it would put steps into
    # the spectrum's top band
    return _over_force(mr, noise_floor(inertial[span], 1.0 / mr.dt))


def force_floor(mr) -> np.ndarray:
    """Per DOF, the NRMSE the load cells' own noise leaves: the white level of the
    recorded actuator forces taken to the DOFs (``extra["force_noise"]``, read off the
    whole record by :func:`sim.calibrate.residuals.mechanical_runs`), through the
    prefilter the balance applies to the force (which passes only part of a white
    noise: :func:`prefilter_noise_gain`), over the DOF's recorded force."""
    noise = mr.extra.get("force_noise")
    if noise is None or _fit_span(mr) is None:
        return np.full(len(mr.dofs), np.nan)
    return _over_force(mr, np.asarray(noise, float) * prefilter_noise_gain(mr))


def dof_floor(mr) -> np.ndarray:
    """Per DOF, both floors together (independent noises: root sum of squares); NaN
    where neither is known."""
    a, f = accelerometer_floor(mr), force_floor(mr)
    both = np.sqrt(np.nan_to_num(a) ** 2 + np.nan_to_num(f) ** 2)
    return np.where(np.isnan(a) & np.isnan(f), np.nan, both)


def prefilter_noise_gain(mr) -> float:
    """The RMS the balance's prefilter (:meth:`sim.calibrate.residuals.MechRun.filt`)
    leaves of a unit white noise at the record's rate: 1 without one, about
    ``sqrt(2 f_c / f_s)`` for a conditioner at ``f_c``. Measured on a seeded probe."""
    if mr.prefilter is None:
        return 1.0
    probe = np.random.default_rng(0).standard_normal((PROBE_N, 1))
    out = mr.filt(probe)[PROBE_SETTLE:]
    return float(np.sqrt(np.mean(out**2)))


def dof_noise_weights(mr) -> np.ndarray:
    """Per DOF, its weight in the fit and the pooled error: ``1 / (floor^2 +
    MODEL_ERROR^2)`` (:func:`sim.calibrate.conditioning.noise_weight`; a DOF without a known floor
    as one without noise), scaled to average 1 over the run's excited DOFs. Computed once
    per run (``extra["noise_weight"]``)."""
    if "noise_weight" in mr.extra:
        return mr.extra["noise_weight"]
    from sim.calibrate.conditioning import noise_weight

    w = noise_weight(np.nan_to_num(dof_floor(mr)))
    on = np.ones(len(w), bool) if mr.excited is None else np.asarray(mr.excited, bool)
    mean = float(np.mean(w[on])) if on.any() else 1.0
    mr.extra["noise_weight"] = w / mean if mean > 0 else np.ones(len(w))
    return mr.extra["noise_weight"]


def _fit_span(mr) -> slice | None:
    rows = np.flatnonzero(mr.rows)
    return slice(rows[0], rows[-1] + 1) if rows.size >= 2 else None


def _over_force(mr, noise: np.ndarray) -> np.ndarray:
    F = mr.demean(mr.force)[mr.rows]
    rms = np.sqrt(np.mean(F**2, axis=0))
    return np.where(rms > 0, noise / np.where(rms > 0, rms, 1.0), np.nan)


__all__ = ["accelerometer_floor", "dof_floor", "dof_noise_weights", "force_floor", "prefilter_noise_gain"]
