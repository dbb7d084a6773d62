"""The LHPOST's data acquisition [Ozcelik 2008] applied to a simulated run of the ucsd model:
the sensors, their conditioning and the recorder (:class:`SensorModel`,
:func:`ucsd_measure`), and the run file the NEES-UCSD records would make
(:func:`write_measured_run`). Used by :mod:`sim.papers.uniaxial`'s programme."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mjcf.description import DOFS6

G0 = 9.81  #: m/s^2: the g in which Ozcelik et al. [Ozcelik 2008] give their accelerations (the white-noise tests' % g)


@dataclass
class SensorModel:
    """The LHPOST's DAQ as Ozcelik et al. [Ozcelik 2008] describe it (all numbers there or assumed here).

    Displacement: Temposonics on the actuators (noise ``disp_noise_m``, assumed).
    Acceleration: Setra 141A through a 100 Hz analog low-pass (4-pole Butterworth
    assumed), noise ``acc_noise_m_s2`` (assumed). Force: chamber pressures x areas, the
    pressure transducers' 689.5 Pa resolution and noise ``pressure_noise_pa`` (assumed),
    no low-pass ([Ozcelik 2008]: pressures were only high-pass filtered to remove the static
    part; the model's force has no static part). Velocity: differentiated displacement
    and integrated acceleration blended by a complementary crossover at
    ``crossover_hz`` (assumed 2 Hz). Recorder: anti-alias filter and 1024 -> 512 Hz.
    """

    disp_noise_m: float = 20e-6
    acc_noise_m_s2: float = 0.003 * G0
    pressure_noise_pa: float = 5e3
    pressure_resolution_pa: float = 689.5
    acc_lowpass_hz: float = 100.0
    crossover_hz: float = 2.0
    recorder_hz: float = 512.0


def _instant_channels(res, steps_per_sample: int | None = None) -> dict:
    """The loop's recorder channels brought to one sampling instant per tick.

    ``sim.loop.simulation`` records at tick t_k the state (u, u'), the end-of-step pressures p(t_k)
    and the acceleration of the physics step leaving t_k, which MuJoCo computed from the
    force of the *next* pressures p(t_k + h) (h the physics step; the hydraulic step
    runs before ``mj_step``). A DAQ samples all sensors at one instant; here that
    instant is the middle of the first step of each tick, t_k + h/2, where everything is
    known to O(h^2): the acceleration a_1 of that step (constant over it), the velocity
    u'_k + a_1 h/2, the displacement, and the pressures that produced a_1, p(t_k + h),
    interpolated between p(t_k) and p(t_k+1). Without this the force lags the
    acceleration by one physics step (0.49 ms) and the acceleration leads the velocity
    by half a step, which the complementary velocity filter turns into a sign error of
    u' at every reversal (identified M_e of S1 683 t instead of 144 t).

    Also returns ``acc_steps`` (n, s): the acceleration of every physics step of each
    tick (the first recorded, the mean of the others from the velocity change, exact
    for the semi-implicit integrator), for the accelerometer filter.
    """
    ch = res.channels
    n = len(res.t)
    T = float(res.t[1] - res.t[0])
    s = steps_per_sample or max(1, int(round(res.timing["steps"] / n)))
    h = T / s
    d = ch["table_displacement"][:, 0]
    v = ch["table_velocity"][:, 0]
    a1 = ch["table_acceleration"][:, 0]
    acc = np.repeat(a1[:, None], s, axis=1)
    if s > 1:
        rest = ((v[1:] - v[:-1]) / h - a1[:-1]) / (s - 1)
        acc[:-1, 1:] = rest[:, None]
    vm = v + a1 * h / 2
    dm = d + h / 2 * (v + a1 * h)
    f = 1.0 / s

    def at_step_end(p):  # p(t_k + h) by linear interpolation between ticks
        out = p.copy()
        out[:-1] = (1 - f) * p[:-1] + f * p[1:]
        return out

    return {
        "disp": dm,
        "vel": vm,
        "acc_steps": acc,
        "pressure_a": at_step_end(ch["pressure_a"]),
        "pressure_b": at_step_end(ch["pressure_b"]),
        "steps": s,
        "fs": 1.0 / T,
    }


def ucsd_measure(
    res, desc, sensors: SensorModel | None = None, seed: int = 0, *, steps_per_sample: int | None = None
) -> dict:
    """Apply the DAQ to a simulation result (1024 Hz): returns 512 Hz channels.

    Sampling instants: :func:`_instant_channels`. Accelerometers: the 100 Hz
    conditioner is an analog filter (:func:`sim.identify.least_squares.analog_lowpass`, here at the
    physics rate on the piecewise-constant acceleration of every step, then sampled at
    the ticks). Velocity: the complementary crossover filter
    u'_est = (w u + int a)' / (s + w) in the trapezoidal (Tustin) form, which for
    consistent samples returns u' to O((w T)^2).
    """
    import scipy.signal as sig

    from sim.identify.least_squares import analog_lowpass

    s = sensors or SensorModel()
    rng = np.random.default_rng(seed)
    ch = res.channels
    ic = _instant_channels(res, steps_per_sample)
    fs = ic["fs"]
    n = len(res.t)
    d = ic["disp"] + s.disp_noise_m * rng.standard_normal(n)
    nst = ic["steps"]
    a_fast = ic["acc_steps"].reshape(-1)  # every physics step, at its middle
    a_fast = a_fast + s.acc_noise_m_s2 * math.sqrt(nst) * rng.standard_normal(len(a_fast))  # same noise per tick
    a = sig.lfilter(*analog_lowpass(s.acc_lowpass_hz, fs * nst), a_fast)[::nst]
    areas_a = np.array([a_.cls.area_a_m2 for a_ in desc.actuators])
    areas_b = np.array([a_.cls.area_b_m2 for a_ in desc.actuators])
    q = s.pressure_resolution_pa

    def pres(p):
        p = p + s.pressure_noise_pa * rng.standard_normal(p.shape)
        return np.round(p / q) * q

    F = (pres(ic["pressure_a"]) * areas_a - pres(ic["pressure_b"]) * areas_b).sum(axis=1)
    # the static part removed, as the paper's high-pass: the force at rest before the test
    # (zero in the model; the sample at t_0 + h/2 has already moved)
    F -= (ch["pressure_a"][0] * areas_a).sum() - (ch["pressure_b"][0] * areas_b).sum()
    # complementary velocity V = (w s D + A) / (s + w) by Tustin: with c = w T / 2,
    # v_k+1 = ((1 - c) v_k + w (d_k+1 - d_k) + T/2 (a_k + a_k+1)) / (1 + c)
    w = 2 * math.pi * s.crossover_hz
    dt = 1.0 / fs
    c = w * dt / 2
    v = np.zeros(n)
    v[0] = ic["vel"][0]
    for k in range(n - 1):
        v[k + 1] = ((1 - c) * v[k] + w * (d[k + 1] - d[k]) + dt / 2 * (a[k] + a[k + 1])) / (1 + c)
    step = int(round(fs / s.recorder_hz))
    dec = lambda x: sig.decimate(x, step, ftype="fir", zero_phase=False) if step > 1 else x  # noqa: E731
    return {
        "t": res.t[::step][: len(dec(d))],
        "force": dec(F),
        "disp": dec(d),
        "vel": dec(v),
        "acc": dec(a),
        "fs": fs / step,
        "true_force": ch["actuator_force"].sum(axis=1),
    }


def write_measured_run(meas: dict, desc, name: str, out_dir):
    """A run file (512 Hz) of the measured channels: what the LHPOST recorder would give."""
    from pathlib import Path

    from sim.runs.runfile import FORMAT, RunFile, description_meta, write_run

    n = len(meas["t"])
    z6 = lambda col: np.column_stack([col] + [np.zeros(n)] * 5)  # noqa: E731
    na = len(desc.actuators)
    force = np.zeros((n, na))
    force[:, 0] = meas["force"]  # the measured total force (pressures x areas of both actuators)
    meta = {
        "format": FORMAT,
        "table": desc.name,
        "sample_rate_hz": float(meas["fs"]),
        "actuators": list(desc.actuator_names),
        "dofs": list(DOFS6),
        "source": "simulated",
        "description": f"{name}: [Ozcelik 2008] test on the ucsd model (sim.papers.uniaxial), measured with the LHPOST DAQ "
        "model; actuator_force holds the total measured "
        "force in column E (W zero)",
    }
    meta.update(description_meta("table", desc.source, desc.raw))  # the hold-down pressure's K_e and F_mu
    run = RunFile(
        t=np.arange(n) / meas["fs"],
        meta=meta,
        actuator_force=force,
        table_displacement=z6(meas["disp"]),
        table_velocity=z6(meas["vel"]),
        table_acceleration=z6(meas["acc"]),
        reference=z6(meas.get("reference", meas["disp"])),
    )
    p = Path(out_dir)
    p.mkdir(parents=True, exist_ok=True)
    return write_run(p / f"ucsd_{name}.run.npz", run)


__all__ = ["G0", "SensorModel", "ucsd_measure", "write_measured_run"]
