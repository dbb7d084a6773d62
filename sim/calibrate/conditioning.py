"""What a record says about its own recorder chain, and the model's channels put through it.

A real record carries nothing about its sensors but what its recorder writes and what
the lab declares (docs/run-file.md): ``meta.recorder`` (the recorder's own settings:
rate, anti-alias cut-off and order, the digital channels that bypass it) and
``meta.channel_conditioning`` (per channel, the KNOWN delay and analog conditioner:
``{"delay_s", "lowpass_hz", "lowpass_order"}``). Calibration applies these to the
model's channels before comparing and searches for what they do not say
(:mod:`sim.calibrate.timing`); it never reads how a synthetic record was made.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from sim.calibrate.errors import CalibrationError

#: a declared conditioner's order when the declaration gives none (assumed: 2 poles,
#: as the sensor effects' default, ``sim.effects.sensors.SensorLowpass``)
DEFAULT_ORDER = 2
#: the analog conditioner's order when only a cut-off is declared (the table's
#: ``accelerometer_bandwidth_hz`` or ``--accel-lowpass``): 4 poles, as
#: :func:`sim.identify.least_squares.analog_lowpass` assumes
TABLE_ORDER = 4


def channel_conditioning(run) -> dict:
    """``{channel: {"delay_s", "lowpass_hz", "lowpass_order"}}`` declared by ``run``'s
    meta, checked (one-line :class:`CalibrationError` naming the run, the field and the fix)."""
    raw = (run.meta or {}).get("channel_conditioning") or {}
    if not isinstance(raw, dict):
        raise CalibrationError(
            f"{run.name}: meta.channel_conditioning must map channel names to "
            '{"delay_s", "lowpass_hz", "lowpass_order"}; fix or remove it'
        )
    out = {}
    for ch, spec in raw.items():
        where = f"{run.name}: meta.channel_conditioning.{ch}"
        if not isinstance(spec, dict):
            raise CalibrationError(f"{where} must be a table of delay_s, lowpass_hz, lowpass_order")
        delay = spec.get("delay_s", 0.0) or 0.0
        fc = spec.get("lowpass_hz")
        order = spec.get("lowpass_order", DEFAULT_ORDER)
        if not isinstance(delay, (int, float)) or isinstance(delay, bool) or not math.isfinite(delay):
            raise CalibrationError(f"{where}.delay_s must be a number of seconds (got {delay!r})")
        if fc is not None and (isinstance(fc, bool) or not isinstance(fc, (int, float)) or not fc > 0):
            raise CalibrationError(f"{where}.lowpass_hz must be a cut-off > 0 Hz or null (got {fc!r})")
        if fc is None:
            # no low-pass, no poles: an import writes 0 for a column that declares only its delay
            order = DEFAULT_ORDER
        elif isinstance(order, bool) or not isinstance(order, int) or not 1 <= order <= 12:
            raise CalibrationError(f"{where}.lowpass_order must be a whole number 1..12 (got {order!r})")
        out[ch] = {"delay_s": float(delay), "lowpass_hz": None if fc is None else float(fc), "lowpass_order": order}
    return out


def velocity_derived(run) -> bool:
    """Whether ``run``'s velocity is one an import made from its displacement (map
    ``derive_velocity``: ``meta.derived_channels``)."""
    return "table_velocity" in ((run.meta or {}).get("derived_channels") or {})


#: a channel a run may derive from another (an import's ``derive_velocity``): its sensor is that one
DERIVED_FROM = {"table_velocity": "table_displacement"}


def path_velocity_derived(pr) -> bool:
    """:func:`velocity_derived` of a path run (:class:`sim.calibrate.paths.PathRun`), from its conditioning."""
    return bool((getattr(pr, "conditioning", None) or {}).get("velocity_from_displacement"))


def sensor_channel(ch: str, prs) -> str:
    """The sensor behind compared channel ``ch`` of the path runs ``prs``: the displacement
    for a velocity every run derives from it (the worked example's LVDT reading 3 % high
    came out as a gain of a velocity transducer the lab does not have)."""
    return DERIVED_FROM.get(ch, ch) if all(path_velocity_derived(pr) for pr in prs) else ch


def declared_channels(run) -> dict:
    """:func:`channel_conditioning`, a velocity an import made from the displacement given
    the displacement's chain (it went through it)."""
    chans = channel_conditioning(run)
    if velocity_derived(run) and "table_displacement" in chans:
        chans["table_velocity"] = chans["table_displacement"]
    return chans


def recorder(run) -> dict:
    """The recorder's own settings (``meta.recorder``), {} when the record has none."""
    rec = (run.meta or {}).get("recorder") or {}
    return rec if isinstance(rec, dict) else {}


def of_run(run) -> dict:
    """What the model's channels go through to compare with ``run``'s: the recorder's
    settings, the declared conditioning, and how long the record's force lags its motion
    (``meta.force_lag_s``: a simulator's own record; 0 for a recorder's)."""
    lag = float((run.meta or {}).get("force_lag_s") or 0.0)
    return {
        "recorder": recorder(run),
        "channels": declared_channels(run),
        "force_lag_s": lag,
        # an import's velocity is the displacement's central difference (map derive_velocity):
        # the model's is made alike, sin(w T) / T, 6 % under w at 20 Hz of a 204.8 Hz record
        "velocity_from_displacement": velocity_derived(run),
    }


#: the channels the simulation loop records a step before the motion (docs/run-file.md)
LAGGED = ("actuator_force", "pressure_a", "pressure_b")


def force_at_record_instant(chans: dict, model_lag_s: float, known: dict | None, dt: float) -> dict:
    """The model's force and pressures at the instants the record holds them: the loop
    records them ``model_lag_s`` before the motion they drive; a recorder samples every
    channel at one instant (``known["force_lag_s"]`` = 0), a simulator's record keeps its
    own lag. Read ``model_lag_s - record lag`` later (cubic spline)."""
    shift_s = model_lag_s - float((known or {}).get("force_lag_s", 0.0))
    if not shift_s:
        return chans
    return {c: (shift(x, -shift_s, dt) if c in LAGGED else x) for c, x in chans.items()}


def apply(chans: dict, known: dict | None, fs: float) -> dict:
    """The model's channels through a record's known chain (:func:`of_run`): the
    recorder's anti-alias (a digital Butterworth, as ``run --measure`` makes it) on the
    analog channels, then each channel's declared analog conditioner and delay."""
    if not known:
        return chans
    from sim.signals import sensing

    rec = known.get("recorder") or {}
    fc = rec.get("anti_alias_hz")
    digital = set(rec.get("digital") or ())
    out = {}
    for name, x in chans.items():
        x = np.asarray(x, float)
        if fc and name not in digital and len(x) > 1 and fc < 0.5 * fs:
            x = sensing.lowpass(x, fc, int(rec.get("anti_alias_order", 4)), fs)
        out[name] = condition_channel(x, (known.get("channels") or {}).get(name), fs)
    return out


def condition_channel(x: np.ndarray, spec: dict | None, fs: float) -> np.ndarray:
    """``x`` through one declared conditioning: the analog low-pass, then the delay."""
    if not spec or len(x) < 2:
        return x
    from sim.signals import sensing

    fc = spec.get("lowpass_hz")
    if fc and fc < 0.5 * fs:
        x = analog_response(x, fc, int(spec.get("lowpass_order", DEFAULT_ORDER)), fs)
    if spec.get("delay_s"):
        x = sensing.fractional_delay(x, float(spec["delay_s"]), 1.0 / fs)
    return x


#: the rate (Hz) at which an analog conditioner is discretised, at least: the record's
#: rate or the smallest whole multiple of it above this. The bilinear transform keeps a
#: conditioner's low-frequency delay but warps its band by about (pi f / rate)^2 / 3 of the
#: frequency: at a 204.8 Hz record's own rate a 4-pole 50 Hz conditioner's phase at 20 Hz
#: is a 51 Hz one's (and calibration found a 51.2 Hz conditioner on records made with the
#: declared 50 Hz); at 1 kHz the warp at 20 Hz is 0.13 %. ``run --measure`` applies a
#: sensor's conditioner at the simulation's rate (1024 Hz, sim.runs.measure) by the same
#: transform, so a record decimated from it is matched exactly.
CONDITIONER_RATE_HZ = 1000.0
#: record samples each end is extended by (its first and last value) before it is
#: interpolated to the conditioner's rate: more than the interpolating filter's half
#: length (10 record samples, ``scipy.signal.resample_poly``)
_EDGE = 16


@functools.lru_cache(maxsize=256)
def _bilinear(cutoff_hz: float, fs: float, order: int) -> tuple:
    """:func:`sim.identify.least_squares.analog_lowpass`, made once per cut-off and rate
    (``scipy.signal.bilinear`` is slow; a timing search filters at each point it tries)."""
    from sim.identify.least_squares import analog_lowpass

    b, a = analog_lowpass(cutoff_hz, fs, order)
    b.flags.writeable = a.flags.writeable = False
    return b, a


def oversampling(fs: float) -> int:
    """The whole multiple of the record rate ``fs`` at which its conditioner is filtered."""
    return max(1, math.ceil(CONDITIONER_RATE_HZ / fs - 1e-9))


def analog_response(x: np.ndarray, cutoff_hz: float, order: int, fs: float, from_rest: bool = False) -> np.ndarray:
    """``x`` (axis 0 time, sampled at ``fs``) through an analog Butterworth low-pass (a
    sensor's conditioner), discretised by the bilinear transform without pre-warping at
    ``fs`` times :func:`oversampling` (the record interpolated band-limited, Kaiser window
    of beta 12 as the payload modes', and taken back at its own samples). Started in
    steady state on the first sample, or ``from_rest`` (the mechanical path's balance,
    whose lead-in is left out of the fit)."""
    import scipy.signal as sig

    from sim.signals import sensing

    x = np.asarray(x, float)
    n, P = x.shape[0], oversampling(fs)
    if n < 2:
        return x.copy()
    if P > 1:
        x = np.concatenate([np.repeat(x[:1], _EDGE, axis=0), x, np.repeat(x[-1:], _EDGE, axis=0)])
        x = sig.resample_poly(x, P, 1, axis=0, window=("kaiser", 12.0))
    if from_rest:
        y = sig.lfilter(*_bilinear(float(cutoff_hz), float(fs * P), int(order)), x, axis=0)
    else:
        y = sensing.lowpass(x, cutoff_hz, order, fs * P, analog=True)
    return y if P == 1 else y[::P][_EDGE : _EDGE + n]


@dataclass(frozen=True)
class Conditioner:
    """A sensor's analog conditioner as calibration applies it to a record's samples at
    ``fs`` (:func:`analog_response`, from rest): the mechanical path's prefilter."""

    cutoff_hz: float
    order: int
    fs: float

    def __call__(self, x: np.ndarray) -> np.ndarray:
        return analog_response(x, self.cutoff_hz, self.order, self.fs, from_rest=True)

    @property
    def ba(self) -> tuple:
        """The recursive filter (b, a) of it at the record's own rate (the same
        low-frequency delay), for how long it remembers a sample."""
        return _bilinear(float(self.cutoff_hz), float(self.fs), int(self.order))


#: the share of a well-measured column's RMS the model's own approximations leave, against
#: which a column's (or a DOF's) noise floor weighs it (:func:`noise_weight`): its squared
#: error counts by ``1 / (floor^2 + MODEL_ERROR^2)``, a chi-square whose every column also
#: carries this much model error. Assumed; measured: the Rice table's clean replays leave
#: 5.9 % on the columns well above their noise (docs/calibration-validation-blind.md)
MODEL_ERROR = 0.05


def noise_weight(floor) -> np.ndarray:
    """The weight of a column (or DOF) whose noise floor (its noise over its RMS) is
    ``floor`` in a pooled error: ``1 / (floor^2 + MODEL_ERROR^2)`` over ``1 /
    MODEL_ERROR^2`` (1 without noise, 0.5 at a floor of MODEL_ERROR)."""
    f = np.asarray(floor, float)
    return MODEL_ERROR**2 / (f**2 + MODEL_ERROR**2)


def noise_floor(x: np.ndarray, fs: float) -> np.ndarray:
    """Per column, the RMS of the white noise under a record: its level in the top of the
    band (0.35-0.5 of the sample rate), where a table's motion and forces hold next to
    nothing, spread over the whole band. What a lab reads off a spectrum; it replaces the
    noise a synthetic record's sensor model stated."""
    import scipy.signal as sig

    x = np.asarray(x, float)
    if len(x) < 256:
        return np.zeros(x.shape[1])
    f, P = sig.welch(x - x.mean(axis=0), fs=fs, nperseg=256, axis=0)
    top = f >= 0.35 * fs
    return np.sqrt(np.mean(P[top], axis=0) * 0.5 * fs)


def shift(x: np.ndarray, delay_s: float, dt: float) -> np.ndarray:
    """``x`` delayed by ``delay_s`` (either sign, any fraction of a sample): y(t) =
    x(t - delay), by a cubic spline through the samples (linear interpolation loses
    amplitude between samples), the end values held beyond the record."""
    x = np.asarray(x, float)
    if not delay_s or len(x) < 4:
        return x
    from scipy.interpolate import CubicSpline

    n = len(x)
    k = np.clip(np.arange(n) - delay_s / dt, 0.0, n - 1)
    return CubicSpline(np.arange(n, dtype=float), x, axis=0)(k)


def controller_lag(effects) -> float:
    """How late the controller's channels were recorded against the analog ones (s): the
    description's ``sensor_delay`` at ``channel:valve_command`` (calibrate's replay path
    writes it, :func:`sim.calibrate.sensorcands.command_candidate`), 0 without one."""
    return sum(
        float(e.get("delay_s", 0.0))
        for e in effects or []
        if e.get("type") == "sensor_delay" and e.get("where") == "channel:valve_command"
    )


def on_the_analog_clock(drive: np.ndarray, lag_s: float, dt: float) -> np.ndarray:
    """A recorded drive (valve commands or reference), or a model channel made from it, as
    on the analog channels' clock: read ``lag_s`` (:func:`controller_lag`) later, by the
    interpolation of the sensor effect that delays it
    (:func:`sim.signals.sensing.fractional_delay`), which then delays the model's own
    command channel back (``sim.runs.build``), as the record's was."""
    from sim.signals.sensing import fractional_delay

    return fractional_delay(np.asarray(drive, float), -lag_s, dt) if lag_s else drive


def declared_state(run, accel_lowpass_hz, table_order: int = TABLE_ORDER) -> dict:
    """What is known of ``run``'s force and acceleration timing: its
    ``meta.channel_conditioning`` (:mod:`sim.calibrate.conditioning`), else
    ``accel_lowpass_hz`` (the table's or ``--accel-lowpass``) as a conditioner of
    ``table_order`` poles (the table's ``[sensors] accelerometer_filter_order``). A
    declared conditioner too close to the record's Nyquist frequency to be filtered at its
    rate counts as its low-frequency delay, 1 / (2 pi f_c sin(pi / 2n)) for n poles."""
    cond = channel_conditioning(run)
    acc = cond.get("table_acceleration", {})
    fc = acc.get("lowpass_hz") if "table_acceleration" in cond else accel_lowpass_hz
    order = int(acc["lowpass_order"]) if acc.get("lowpass_hz") else table_order
    delay = acc.get("delay_s", 0.0)
    if fc and not filterable(fc, run.dt) and "table_acceleration" in cond:
        delay += low_frequency_delay_s(fc, order)
        fc = None
    return {
        "force_delay_s": cond.get("actuator_force", {}).get("delay_s", 0.0)
        + _unfilterable_delay(cond.get("actuator_force", {}), run.dt),
        "accel_delay_s": delay,
        "accel_lowpass_hz": fc or None,
        "accel_lowpass_order": order,
    }


def _unfilterable_delay(spec: dict, dt: float) -> float:
    """The low-frequency delay of a channel's declared conditioner ``spec`` when it is too
    close to the Nyquist frequency of a record sampled every ``dt`` to be filtered at its
    rate (0 otherwise)."""
    fc = spec.get("lowpass_hz")
    if not fc or filterable(fc, dt):
        return 0.0
    return low_frequency_delay_s(fc, int(spec["lowpass_order"]))


def filterable(fc: float, dt: float) -> bool:
    """Whether a conditioner at ``fc`` can be filtered at the rate of a record sampled
    every ``dt``: below 0.45 of the rate, near the Nyquist frequency (assumed: the number
    the accelerometer's conditioner was held to before it was shared; above it the
    conditioner counts as its low-frequency delay)."""
    return fc < 0.45 / dt


def low_frequency_delay_s(fc: float, order: int) -> float:
    """The delay of an ``order``-pole Butterworth low-pass at ``fc`` well below its
    cut-off (its group delay at 0 Hz): ``1 / (2 pi f_c sin(pi / 2n))``."""
    return 1.0 / (2 * math.pi * fc * math.sin(math.pi / (2 * order)))


def force_chain_of(run):
    """The load cells' declared analog conditioner (``meta.channel_conditioning.actuator_force``'s
    low-pass) at the run's rate (:class:`Conditioner`), None without one or for one too
    close to the Nyquist frequency to filter (its delay counts instead, :func:`declared_state`).
    The recorded force went through it; the mechanical path puts the model's forces through
    it too. Left out, NEES-UCSD records' declared 50 Hz, 4-pole load-cell conditioner read
    as a force 8.40 ms late, and a clean calibration's pooled held-out error stayed at
    22.8 % (1.02 % with it: tests/calibrate/test_real_record_suite.py,
    tests/calibrate/test_force_conditioner.py)."""
    spec = channel_conditioning(run).get("actuator_force", {})
    fc = spec.get("lowpass_hz")
    if not fc or not filterable(fc, run.dt):
        return None
    return Conditioner(float(fc), int(spec["lowpass_order"]), 1.0 / run.dt)


def motion_on_the_force_clock(run, u: np.ndarray, v: np.ndarray) -> tuple:
    """The recorded displacement and velocity read at the instants their time stamps say:
    each less its channel's declared delay (``meta.channel_conditioning``, a map's
    ``delay_s``) and its declared low-pass's low-frequency delay (an LVDT demodulator's
    filter: the friction's switching and the damping are not linear in the motion, so it
    is not undone as a filter), a velocity an import made from the displacement with the
    displacement's. Left late, they put the friction's switching, the damping and the
    springs off the force: the worked example's LVDT 2 samples late and read as if on
    time, 8.5 % held out instead of 1.84 %, the frame's second mode lost
    (tests/calibrate/test_timing_anchor.py)."""
    cond = declared_channels(run)

    def late(channel: str) -> float:
        spec = cond.get(channel, {})
        fc = spec.get("lowpass_hz")
        return spec.get("delay_s", 0.0) + (low_frequency_delay_s(fc, spec["lowpass_order"]) if fc else 0.0)

    return shift(u, -late("table_displacement"), run.dt), shift(v, -late("table_velocity"), run.dt)


def prefilter_of(state: dict, run):
    """The acceleration's analog conditioner in ``state`` at the run's rate
    (:class:`sim.calibrate.conditioning.Conditioner`; one-line error when above the
    Nyquist frequency)."""
    fc = state["accel_lowpass_hz"]
    if not fc:
        return None
    if fc >= 0.5 / run.dt:
        raise CalibrationError(
            f"{run.name}: the accelerometer low-pass {fc:g} Hz is above the Nyquist frequency "
            f"{0.5 / run.dt:g} Hz; give --accel-lowpass none or declare a lower cut-off"
        )
    return Conditioner(float(fc), int(state["accel_lowpass_order"]), 1.0 / run.dt)


__all__ = [
    "TABLE_ORDER",
    "controller_lag",
    "on_the_analog_clock",
    "declared_state",
    "force_chain_of",
    "low_frequency_delay_s",
    "motion_on_the_force_clock",
    "prefilter_of",
    "shift",
    "LAGGED",
    "Conditioner",
    "analog_response",
    "apply",
    "force_at_record_instant",
    "oversampling",
    "channel_conditioning",
    "condition_channel",
    "noise_floor",
    "noise_weight",
    "MODEL_ERROR",
    "of_run",
    "recorder",
]
