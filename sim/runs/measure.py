"""Synthetic measurements: a simulated run as a table's data recorder would give it.

:func:`measure_run` applies a sensor model (a ``SENSORS.toml`` file, read by
:func:`load_sensors`; every key and its unit in ``docs/sensors.md``) to a
:class:`sim.runs.runfile.RunFile` and returns a new run with ``meta.source =
"measured"``. Per channel (all its columns, or one value per column): gain, offset
(fixed, and a seeded one per record), the sensor's own analog conditioner (causal
Butterworth of any order), timing skew (either sign), slow drift (ramp and seeded
random walk), white noise (RMS in the channel's units) and quantisation (bits over a
+/- range); for the recorder: a quiet lead-in, an anti-alias low-pass (causal
Butterworth) and the sample rate (an integer decimation of the run's rate).

The platen's accelerometer channels (``table_acceleration``, ``accelerometers``; not
``specimen_acceleration``, whose sensors are the specimen's) go through the table's
declared conditioner (``[sensors] accelerometer_bandwidth_hz`` and
``accelerometer_filter_order`` of the table the run carries) where the sensor file gives
them no ``lowpass_hz`` and the cut-off is below the recorder's Nyquist frequency, and the
measured run declares it in ``meta.channel_conditioning`` unless the sensor file
declares that channel: a record made by ``run --measure`` says what an imported one
says (``shaketable import`` declares the table's conditioner the same way,
:func:`sim.runs.importer.table_conditioning`). The chain, in order:

    lead-in -> gain x signal + offset -> conditioner -> anti-alias (analog channels)
    -> skew -> sampled at the recorder rate -> + drift -> + noise -> quantised

Channels named in ``recorder.digital`` (the controller's own numbers: reference and
valve command) skip the anti-alias filter. Everything random is seeded: the same run,
model and seed give the identical measured run; each channel draws from its own
streams (``numpy.random.default_rng([seed, channel index])`` for the noise, ``[seed,
index, 1]`` for the per-record offset, ``[seed, index, 2]`` for the drift), so adding
one to a channel leaves the others' draws unchanged.

The measured run's meta holds only what a recorder writes: its settings (``recorder``)
and the conditioning the lab declares known (``channel_conditioning``: the sensor
file's declarations, else the table's accelerometer conditioner). The
chain that made it goes to a sidecar file (:func:`chain_record`), which calibration
never reads.
"""

from __future__ import annotations

import copy
import difflib
import math
import tomllib
from pathlib import Path

import numpy as np

from sim.errors import UserError
from sim.signals import sensing

ROOT = Path(__file__).resolve().parents[2]
#: the built-in model of ``shaketable run --measure`` without a file
DEFAULT_SENSORS = ROOT / "scenarios" / "sensors" / "recorder_1024hz.toml"

RECORDER_KEYS = {
    "rate_hz": "Hz",
    "anti_alias_hz": "Hz",
    "anti_alias_order": "1",
    "digital": "channel names",
    "lead_in_s": "s",
    "declared": "true or false",
}
CHANNEL_KEYS = {
    "gain": "1",
    "offset": "channel units",
    "offset_rms": "channel units",
    "noise_rms": "channel units",
    "range": "channel units",
    "bits": "1",
    "skew_s": "s",
    "lowpass_hz": "Hz",
    "lowpass_order": "1",
    "drift_per_sqrt_s": "channel units / sqrt(s)",
    "ramp_per_s": "channel units / s",
    "declared": "true or false",
    "declared_delay_s": "s",
    "declared_lowpass_hz": "Hz",
    "declared_lowpass_order": "1",
}
#: keys that hold one number for the whole channel (not one per column)
_SCALAR_KEYS = ("lowpass_hz", "declared_delay_s", "declared_lowpass_hz")
_ORDER_KEYS = ("lowpass_order", "declared_lowpass_order", "anti_alias_order")
#: the sidecar file of a measured run: the whole sensor chain, which a real record lacks
CHAIN_SUFFIX = ".sensors.json"


class SensorsError(UserError):
    """A sensor model (SENSORS.toml) with a missing, unknown or invalid key."""


def _closest(key, known) -> str:
    close = difflib.get_close_matches(key, sorted(known), n=1)
    return f" (did you mean '{close[0]}'?)" if close else f"; known: {', '.join(sorted(known))}"


def load_sensors(path=None, sample_rate_hz: float | None = None) -> dict:
    """The sensor model of a ``SENSORS.toml`` file (default: :data:`DEFAULT_SENSORS`),
    checked (one-line :class:`SensorsError` naming the file and the key), also against
    the rate of the runs it will measure when ``sample_rate_hz`` is given."""
    path = Path(path) if path is not None else DEFAULT_SENSORS
    try:
        with open(path, "rb") as f:
            data = tomllib.load(f)
    except FileNotFoundError:
        raise SensorsError(
            f"sensor model {path} not found; give an existing SENSORS.toml "
            f"(or none for the built-in {DEFAULT_SENSORS.name})"
        ) from None
    except tomllib.TOMLDecodeError as e:
        raise SensorsError(f"sensor model {path} is not valid TOML ({e}); fix the syntax") from None
    check_sensors(data, str(path))
    if sample_rate_hz is not None:
        decimation(data, sample_rate_hz, str(path))
    return data


def decimation(sensors: dict, fs: float, source: str = "sensor model") -> int:
    """The whole number of run samples per recorder sample (one-line error if the
    recorder rate does not divide the run's rate ``fs`` or the anti-alias cutoff is not
    below its Nyquist frequency)."""
    rec = sensors.get("recorder", {})
    rate = float(rec.get("rate_hz", fs))
    q = fs / rate
    step = int(round(q))
    if step < 1 or abs(q - step) > 1e-6 * q:
        raise SensorsError(
            f"{source}: recorder.rate_hz = {rate:g} Hz does not divide the run's {fs:g} Hz; "
            f"use {fs:g} Hz divided by a whole number (e.g. {fs / max(step, 1):g})"
        )
    fc = rec.get("anti_alias_hz")
    if fc is not None and not fc < 0.5 * fs:
        raise SensorsError(
            f"{source}: recorder.anti_alias_hz = {fc:g} Hz is not below the run's Nyquist "
            f"frequency {0.5 * fs:g} Hz; use a lower cutoff"
        )
    return step


def check_sensors(sensors: dict, source: str = "sensor model") -> None:
    """Raise :class:`SensorsError` (one line) for anything off in a sensor model."""
    from sim.runs.runfile import CHANNELS

    if not isinstance(sensors, dict):
        raise SensorsError(f"{source}: a sensor model is a table with [recorder] and [channel.<name>]")
    for k in sensors:
        if k not in ("recorder", "channel"):
            raise SensorsError(f"{source}: unknown section '{k}'{_closest(k, ('recorder', 'channel'))}")
    rec = sensors.get("recorder", {})
    for k, v in rec.items():
        if k not in RECORDER_KEYS:
            raise SensorsError(f"{source}: unknown key 'recorder.{k}'{_closest(k, RECORDER_KEYS)}")
        if k == "digital":
            if not isinstance(v, list) or any(c not in CHANNELS for c in v):
                raise SensorsError(f"{source}: recorder.digital must list channel names among {', '.join(CHANNELS)}")
        else:
            _check_value(v, k, f"recorder.{k}", source, RECORDER_KEYS[k], positive=k != "lead_in_s")
    chans = sensors.get("channel", {})
    if not isinstance(chans, dict):
        raise SensorsError(f"{source}: [channel.<name>] sections name run-file channels")
    for name, spec in chans.items():
        if name not in CHANNELS:
            raise SensorsError(f"{source}: [channel.{name}] is not a run-file channel{_closest(name, CHANNELS)}")
        if not isinstance(spec, dict):
            raise SensorsError(f"{source}: [channel.{name}] must be a table of keys")
        for k, v in spec.items():
            if k not in CHANNEL_KEYS:
                raise SensorsError(f"{source}: unknown key 'channel.{name}.{k}'{_closest(k, CHANNEL_KEYS)}")
            _check_channel_value(v, k, f"channel.{name}.{k}", source)


def _check_value(v, k: str, where: str, source: str, unit: str, positive: bool = True) -> None:
    """A recorder value: a flag, a whole number (orders) or a number (> 0, or >= 0)."""
    if k == "declared":
        if not isinstance(v, bool):
            raise SensorsError(f"{source}: {where} must be true or false (got {v!r})")
    elif k in _ORDER_KEYS:
        if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 12:
            raise SensorsError(f"{source}: {where} must be a whole number 1..12 (got {v!r})")
    elif (
        isinstance(v, bool)
        or not isinstance(v, (int, float))
        or not math.isfinite(v)
        or not (v > 0 or v == 0 and not positive)
    ):
        raise SensorsError(f"{source}: {where} must be a number {'> 0' if positive else '>= 0'} in {unit} (got {v!r})")


def _check_channel_value(v, k: str, where: str, source: str) -> None:
    if k == "bits":
        if isinstance(v, bool) or not isinstance(v, int) or not 2 <= v <= 32:
            raise SensorsError(f"{source}: {where} must be a whole number 2..32 (got {v!r})")
        return
    if k in _ORDER_KEYS or k == "declared" or k in ("lowpass_hz", "declared_lowpass_hz"):
        return _check_value(v, k, where, source, CHANNEL_KEYS[k])
    if k == "range" and v == "auto":
        return
    if k in _SCALAR_KEYS and isinstance(v, list):
        raise SensorsError(f"{source}: {where} is one number for the whole channel (got {v!r})")
    vals = v if isinstance(v, list) else [v]
    if not vals or any(isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) for x in vals):
        raise SensorsError(
            f"{source}: {where} must be a number or a list of numbers (one per column) "
            f"in {CHANNEL_KEYS[k]}" + (' or "auto"' if k == "range" else "") + f" (got {v!r})"
        )
    nonneg = ("noise_rms", "range", "offset_rms", "drift_per_sqrt_s")
    if k in nonneg and any(x < 0 for x in vals) or k == "range" and 0 in vals:
        raise SensorsError(f"{source}: {where} must be {'> 0' if k == 'range' else '>= 0'} (got {v!r})")


def _columns(value, n: int, where: str) -> np.ndarray:
    if isinstance(value, list):
        if len(value) != n:
            raise SensorsError(
                f"{where} has {len(value)} values but the channel has {n} columns; give one number or one per column"
            )
        return np.asarray(value, dtype=np.float64)
    return np.full(n, float(value))


def _lead_in(x: np.ndarray, n_lead: int, hold=None) -> np.ndarray:
    """``x`` with ``n_lead`` copies of ``hold`` (default: its first sample) before it: the
    recorder ran while the table stood still before the motion (a simulated run starts at
    rest)."""
    if n_lead <= 0 or len(x) == 0:
        return x
    first = x[:1] if hold is None else np.asarray(hold, float).reshape(1, -1)
    return np.concatenate([np.repeat(first, n_lead, axis=0), x], axis=0)


def _held(run, name: str):
    """What ``name`` holds while the table stands still, where the first sample is not it:
    the valve commands at which the valves pass no flow (meta ``valve_hold_command``,
    written by the simulation). A run's first command already drives the motion's onset
    (a white noise's starts at 1.5-2e-4 of rated opening on CGS); held 5 s through a
    lead-in, the record's command moved a table its motion channels show still, which no
    recorder writes (a replay through the model then pushed 3 kN into the longitudinal
    load cells over the lead-in). None: the first sample."""
    hold = (run.meta or {}).get("valve_hold_command") if name == "valve_command" else None
    if hold is None or len(hold) != len(run.actuators):
        return None
    return hold


def _force_at_one_instant(run) -> dict:
    """The force and pressure channels re-timed to the instant of the motion samples: the
    loop records them ``meta.force_lag_s`` before the force behind the acceleration of the
    same index (docs/run-file.md); a recorder samples every channel at one instant, so the
    measured run holds them at t + lag (cubic spline) and no ``force_lag_s``."""
    lag = float((run.meta or {}).get("force_lag_s") or 0.0)
    out = {}
    for name in ("actuator_force", "pressure_a", "pressure_b"):
        x = getattr(run, name)
        if x is None or not lag or len(x) < 4:
            continue
        from scipy.interpolate import CubicSpline

        t = np.asarray(run.t, float)
        out[name] = CubicSpline(t, np.asarray(x, float), axis=0)(np.minimum(t + lag, t[-1]))
    return out


def _analog_part(x, name, spec, rec, fs, n_lead, seed, ci, hold=None):
    """Gain, offset (fixed and per record), the channel's conditioner, the anti-alias
    low-pass and the skew, at the run's rate (lead-in included, holding ``hold``)."""
    ncol = x.shape[1]
    where = f"channel.{name}"
    off = _columns(spec.get("offset", 0.0), ncol, f"{where}.offset")
    orms = _columns(spec.get("offset_rms", 0.0), ncol, f"{where}.offset_rms")
    if np.any(orms > 0):  # a DC offset that changes from record to record (zeroed, then wandered)
        off = off + orms * np.random.default_rng([int(seed), ci, 1]).standard_normal(ncol)
    x = _lead_in(x, n_lead, hold) * _columns(spec.get("gain", 1.0), ncol, f"{where}.gain") + off
    if "lowpass_hz" in spec and len(x) > 1:  # the sensor's own analog conditioner
        fc = float(spec["lowpass_hz"])
        if not fc < 0.5 * fs:
            raise SensorsError(f"{where}.lowpass_hz = {fc:g} Hz is not below the run's Nyquist {0.5 * fs:g} Hz")
        x = sensing.lowpass(x, fc, int(spec.get("lowpass_order", 2)), fs, analog=True)
    fc = rec.get("anti_alias_hz")
    if fc is not None and name not in set(rec.get("digital", ())) and len(x) > 1:
        x = sensing.lowpass(x, fc, int(rec.get("anti_alias_order", 4)), fs)
    skew = _columns(spec.get("skew_s", 0.0), ncol, f"{where}.skew_s")
    for j in np.nonzero(skew)[0]:  # the sample taken skew_s after its time stamp
        x[:, j] = sensing.fractional_delay(x[:, j], -skew[j], 1.0 / fs)
    return x


def _drift(spec, shape, rate, seed, ci, where) -> np.ndarray:
    """A slow drift per column: a ramp plus a seeded random walk (Brownian motion of
    ``drift_per_sqrt_s``: its standard deviation after T seconds is that times sqrt(T))."""
    n, ncol = shape
    t = np.arange(n) / rate
    out = t[:, None] * _columns(spec.get("ramp_per_s", 0.0), ncol, f"{where}.ramp_per_s")[None, :]
    walk = _columns(spec.get("drift_per_sqrt_s", 0.0), ncol, f"{where}.drift_per_sqrt_s")
    if np.any(walk > 0):
        steps = np.random.default_rng([int(seed), ci, 2]).standard_normal((n, ncol)) * math.sqrt(1.0 / rate)
        steps[0] = 0.0
        out = out + walk[None, :] * np.cumsum(steps, axis=0)
    return out


def _digitised(x, spec, where, seed, ci) -> np.ndarray:
    """Noise then the ADC (at the recorder's rate)."""
    ncol = x.shape[1]
    peak = np.nanmax(np.abs(x), axis=0) if len(x) else np.zeros(ncol)
    rms = _columns(spec.get("noise_rms", 0.0), ncol, f"{where}.noise_rms")
    if np.any(rms > 0):
        x = x + rms * np.random.default_rng([int(seed), ci]).standard_normal(x.shape)
    if "range" in spec:
        rng_v = spec["range"]
        if rng_v == "auto":  # set before the test at twice the peak (of the signal, or 5 x its noise)
            full = 2.0 * np.maximum(peak, 5.0 * rms)
        else:
            full = _columns(rng_v, ncol, f"{where}.range")
        bits = int(spec.get("bits", 16))  # assumed: a 16-bit ADC unless the model says otherwise
        for j in np.nonzero(full > 0)[0]:  # a silent, noiseless column stays exactly 0
            x[:, j] = sensing.quantise(x[:, j], bits, full[j])
    return x


def declared_conditioning(sensors: dict, present=None) -> dict:
    """``meta.channel_conditioning`` (docs/run-file.md) of the channels whose sensor file
    marks their conditioning as known (``declared = true``: the channel's own conditioner
    and skew; ``declared_*``: what the lab believes, which may differ from the truth)."""
    out = {}
    for name, spec in sensors.get("channel", {}).items():
        if not (spec.get("declared") or any(k.startswith("declared_") for k in spec)):
            continue
        if present is not None and name not in present:
            continue
        own = bool(spec.get("declared"))
        skew = spec.get("skew_s", 0.0)
        if "declared_delay_s" not in spec and own and isinstance(skew, list) and len(set(skew)) > 1:
            raise SensorsError(
                f"channel.{name}: declared = true with a skew per column; give declared_delay_s (one number)"
            )
        delay = spec.get("declared_delay_s", -(skew[0] if isinstance(skew, list) else skew) if own else 0.0)
        fc = spec.get("declared_lowpass_hz", spec.get("lowpass_hz") if own else None)
        order = spec.get("declared_lowpass_order", spec.get("lowpass_order", 2))
        out[name] = {
            "delay_s": float(delay) + 0.0,  # no "-0.0" in the meta
            "lowpass_hz": None if fc is None else float(fc),
            "lowpass_order": int(order),
        }
    return out


def table_conditioner(run, rate_hz: float) -> dict:
    """The table's declared accelerometer conditioner (``[sensors]
    accelerometer_bandwidth_hz`` and ``accelerometer_filter_order`` of the table the run
    carries, :func:`sim.runs.runfile.table_of`) per accelerometer channel ``run`` holds
    (``{channel: {"delay_s", "lowpass_hz", "lowpass_order"}}``, as
    :func:`sim.runs.importer.table_conditioning` declares it for an imported record);
    {} when its cut-off is not below the recorder's Nyquist frequency ``rate_hz / 2``, or
    the run neither carries its table nor names a stock one (a hand-made run: no table
    declares its accelerometers' conditioner)."""
    from mjcf.description import TABLES_DIR
    from sim.runs.importer import TABLE_CONDITIONED, table_conditioning
    from sim.runs.runfile import table_of

    meta = run.meta or {}
    if not meta.get("table_description") and not (TABLES_DIR / f"{meta.get('table')}.toml").is_file():
        return {}
    held = {ch for ch in TABLE_CONDITIONED if getattr(run, ch) is not None and np.shape(getattr(run, ch))[1] > 0}
    if not held:
        return {}
    return table_conditioning(table_of(run), rate_hz, held)


def with_table_conditioner(sensors: dict, table: dict) -> dict:
    """``sensors`` with the table's conditioner (``table``, :func:`table_conditioner`) as
    the analog conditioner of each of its channels whose sensor file gives none
    (``lowpass_hz``): a sensor file's own ``lowpass_hz`` is the sensor's real conditioner
    and replaces the table's (a conditioner left at 30 Hz where the table declares 100)."""
    if not table:
        return sensors
    out = copy.deepcopy(sensors)
    chans = out.setdefault("channel", {})
    for ch, spec in table.items():
        own = chans.setdefault(ch, {})
        if "lowpass_hz" not in own:
            own.update(lowpass_hz=spec["lowpass_hz"], lowpass_order=spec["lowpass_order"])
    return out


def measure_run(run, sensors: dict, seed: int = 0):
    """``run`` (a :class:`sim.runs.runfile.RunFile`) as measured through ``sensors`` (see
    the module docstring and ``docs/sensors.md``): a new RunFile at the recorder's rate
    with ``meta["source"] = "measured"`` and only what a recorder writes in its meta (its
    own settings, ``recorder``, and the declared ``channel_conditioning``: the sensor
    file's, else the table's accelerometer conditioner, which the platen's acceleration
    channels go through where the sensor file gives them no ``lowpass_hz``); the chain
    that made it is :func:`chain_record`'s, kept apart. The input run is not changed."""
    from sim.runs.runfile import CHANNELS, RunFile

    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SensorsError(f"seed must be a whole number >= 0 (got {seed!r})")
    check_sensors(sensors)
    rec = sensors.get("recorder", {})
    fs = run.sample_rate_hz
    step = decimation(sensors, fs)
    n_lead = int(round(float(rec.get("lead_in_s", 0.0)) * fs))
    retimed = _force_at_one_instant(run)
    table = table_conditioner(run, fs / step)
    sensors = with_table_conditioner(sensors, table)
    out = {}
    for ci, name in enumerate(CHANNELS):
        x = retimed.get(name, getattr(run, name))
        if x is None:
            continue
        spec = sensors.get("channel", {}).get(name, {})
        x = np.array(x, dtype=np.float64)
        x = _analog_part(x, name, spec, rec, fs, n_lead, seed, ci, _held(run, name))[::step]
        x = x + _drift(spec, x.shape, fs / step, seed, ci, f"channel.{name}")
        out[name] = _digitised(x, spec, f"channel.{name}", seed, ci)
    n = run.n_samples
    extras = {
        k: (_lead_in(np.asarray(v), n_lead)[::step] if np.shape(v)[:1] == (n,) else np.asarray(v))
        for k, v in run.extras.items()
    }
    t = float(run.t[0]) + np.arange(n + n_lead) / fs if n else np.asarray(run.t)
    meta = _recorder_meta(run.meta, sensors, fs / step, present=set(out), table=table)
    return RunFile(t=t[::step].copy(), meta=meta, extras=extras, **out)


def _recorder_meta(meta: dict, sensors: dict, rate: float, present=None, table=None) -> dict:
    """The measured run's meta: the simulated run's, less what only a simulator knows
    (``force_lag_s``, ``valve_hold_command``, a ``measurement`` of an earlier measuring), plus the recorder's own
    settings and the declared conditioning: the sensor file's, else the table's
    accelerometer conditioner (``table``, :func:`table_conditioner`) on the channels it
    declares nothing for, as ``shaketable import`` writes it."""
    meta = copy.deepcopy(meta)
    for k in ("measurement", "force_lag_s", "valve_hold_command", "recorder", "channel_conditioning"):
        meta.pop(k, None)
    rec = sensors.get("recorder", {})
    meta["source"] = "measured"
    meta["sample_rate_hz"] = rate
    if rec.get("declared", True):  # a recorder knows (and writes) its own settings
        meta["recorder"] = {
            "rate_hz": rate,
            "anti_alias_hz": rec.get("anti_alias_hz"),
            "anti_alias_order": int(rec.get("anti_alias_order", 4)),
            "digital": list(rec.get("digital", ())),
        }
    cond = {ch: dict(spec) for ch, spec in (table or {}).items() if present is None or ch in present}
    cond.update(declared_conditioning(sensors, present))
    if cond:
        meta["channel_conditioning"] = cond
    return meta


def chain_record(run_meta: dict, sensors: dict, seed: int, model_file=None, table=None) -> dict:
    """The whole sensor chain of a measured run (the sidecar ``<stem>.measured.sensors.json``;
    calibration never reads it: a real record carries nothing like it). ``table``: the
    table's accelerometer conditioner (:func:`table_conditioner`), applied on the channels
    whose sensor model gives no ``lowpass_hz``."""
    return {
        "of": run_meta.get("source"),
        "seed": int(seed),
        "model": copy.deepcopy(sensors),
        "model_file": str(model_file or DEFAULT_SENSORS),
        "table_conditioner": copy.deepcopy(table or {}),
        "chain": "lead-in, gain, offset (fixed + per record), conditioner (the sensor's own, else the table's "
        "accelerometer conditioner), anti-alias, skew, sampling, drift, noise, quantisation",
    }


def write_measured(run, out, stem: str, sensors: dict, seed: int = 0, model_file=None):
    """Measure ``run`` through ``sensors`` (from :func:`load_sensors` of ``model_file``,
    None: the built-in one) and write ``<out>/<stem>.measured.run.npz`` and, beside it, the
    chain that made it (``<stem>.measured.sensors.json``); returns the run's path."""
    from sim.runs.files import out_dir, write_json_atomic
    from sim.runs.runfile import write_run

    meas = measure_run(run, sensors, seed)
    table = table_conditioner(run, meas.sample_rate_hz)
    d = out_dir(out)
    path = write_run(d / f"{stem}.measured.run.npz", meas)
    write_json_atomic(d / f"{stem}.measured{CHAIN_SUFFIX}", chain_record(run.meta, sensors, seed, model_file, table))
    return path


__all__ = [
    "CHAIN_SUFFIX",
    "CHANNEL_KEYS",
    "DEFAULT_SENSORS",
    "RECORDER_KEYS",
    "SensorsError",
    "chain_record",
    "check_sensors",
    "declared_conditioning",
    "decimation",
    "load_sensors",
    "measure_run",
    "table_conditioner",
    "with_table_conditioner",
    "write_measured",
]
