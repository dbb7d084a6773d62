"""Synthetic measurements: a simulated run as a table's data recorder would give it.

:func:`measure_run` applies a sensor model (a ``SENSORS.toml`` file, read by
:func:`load_sensors`; every key and its unit in ``docs/sensors.md``) to a
:class:`sim.runs.runfile.RunFile` and returns a new run with ``meta.source =
"measured"``. Per channel (all its columns, or one value per column): gain, offset,
timing skew, white noise (RMS in the channel's units) and quantisation (bits over a
+/- range); for the recorder: an anti-alias low-pass (causal Butterworth) and the
sample rate (an integer decimation of the run's rate). The chain, in order:

    gain x signal + offset  ->  anti-alias low-pass (analog channels)  ->  skew
    ->  sampled at the recorder rate  ->  + noise  ->  quantised

Channels named in ``recorder.digital`` (the controller's own numbers: reference and
valve command) skip the anti-alias filter. The noise is seeded: the same run, model
and seed give the identical measured run; each channel draws from its own stream
(``numpy.random.default_rng([seed, channel index])``), so adding noise to one channel
leaves the others' unchanged.
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

RECORDER_KEYS = {"rate_hz": "Hz", "anti_alias_hz": "Hz", "anti_alias_order": "1", "digital": "channel names"}
CHANNEL_KEYS = {
    "gain": "1",
    "offset": "channel units",
    "noise_rms": "channel units",
    "range": "channel units",
    "bits": "1",
    "skew_s": "s",
}


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
        elif k == "anti_alias_order":
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 12:
                raise SensorsError(f"{source}: recorder.anti_alias_order must be a whole number 1..12 (got {v!r})")
        elif isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise SensorsError(f"{source}: recorder.{k} must be a number > 0 in {RECORDER_KEYS[k]} (got {v!r})")
    chans = sensors.get("channel", {})
    if not isinstance(chans, dict):
        raise SensorsError(f"{source}: [channel.<name>] sections name run-file channels")
    for name, spec in chans.items():
        if name not in CHANNELS:
            raise SensorsError(f"{source}: [channel.{name}] is not a run-file channel{_closest(name, CHANNELS)}")
        if not isinstance(spec, dict):
            raise SensorsError(f"{source}: [channel.{name}] must be a table of keys")
        for k, v in spec.items():
            where = f"channel.{name}.{k}"
            if k not in CHANNEL_KEYS:
                raise SensorsError(f"{source}: unknown key '{where}'{_closest(k, CHANNEL_KEYS)}")
            if k == "bits":
                if isinstance(v, bool) or not isinstance(v, int) or not 2 <= v <= 32:
                    raise SensorsError(f"{source}: {where} must be a whole number 2..32 (got {v!r})")
                continue
            if k == "range" and v == "auto":
                continue
            vals = v if isinstance(v, list) else [v]
            if not vals or any(
                isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) for x in vals
            ):
                raise SensorsError(
                    f"{source}: {where} must be a number or a list of numbers (one per column) "
                    f"in {CHANNEL_KEYS[k]}" + (' or "auto"' if k == "range" else "") + f" (got {v!r})"
                )
            if k in ("noise_rms", "range") and any(x < 0 for x in vals) or k == "range" and 0 in vals:
                raise SensorsError(f"{source}: {where} must be {'> 0' if k == 'range' else '>= 0'} (got {v!r})")


def _columns(value, n: int, where: str) -> np.ndarray:
    if isinstance(value, list):
        if len(value) != n:
            raise SensorsError(
                f"{where} has {len(value)} values but the channel has {n} columns; give one number or one per column"
            )
        return np.asarray(value, dtype=np.float64)
    return np.full(n, float(value))


def measure_run(run, sensors: dict, seed: int = 0):
    """``run`` (a :class:`sim.runs.runfile.RunFile`) as measured through ``sensors`` (see
    the module docstring and ``docs/sensors.md``): a new RunFile at the recorder's rate
    with ``meta["source"] = "measured"`` and ``meta["measurement"]`` recording the model
    and the seed. The input run is not changed."""
    from sim.runs.runfile import CHANNELS, RunFile

    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise SensorsError(f"seed must be a whole number >= 0 (got {seed!r})")
    check_sensors(sensors)
    rec = sensors.get("recorder", {})
    chans = sensors.get("channel", {})
    fs = run.sample_rate_hz
    step = decimation(sensors, fs)
    rate = fs / step
    fc = rec.get("anti_alias_hz")
    order = int(rec.get("anti_alias_order", 4))  # assumed: 4 poles unless the model says otherwise
    digital = set(rec.get("digital", ()))
    n = run.n_samples
    out = {}
    for ci, name in enumerate(CHANNELS):
        x = getattr(run, name)
        if x is None:
            continue
        x = np.array(x, dtype=np.float64)
        spec = chans.get(name, {})
        ncol = x.shape[1]
        where = f"channel.{name}"
        x = x * _columns(spec.get("gain", 1.0), ncol, f"{where}.gain") + _columns(
            spec.get("offset", 0.0), ncol, f"{where}.offset"
        )
        if fc is not None and name not in digital and n > 1:
            x = sensing.lowpass(x, fc, order, fs)
        skew = _columns(spec.get("skew_s", 0.0), ncol, f"{where}.skew_s")
        for j in np.nonzero(skew)[0]:  # the sample taken skew_s after its time stamp
            x[:, j] = sensing.fractional_delay(x[:, j], -skew[j], 1.0 / fs)
        x = x[::step]
        peak = np.nanmax(np.abs(x), axis=0) if len(x) else np.zeros(ncol)
        rms = _columns(spec.get("noise_rms", 0.0), ncol, f"{where}.noise_rms")
        if np.any(rms > 0):
            rng = np.random.default_rng([int(seed), ci])
            x = x + rms * rng.standard_normal(x.shape)
        if "range" in spec:
            rng_v = spec["range"]
            if rng_v == "auto":  # set before the test at twice the peak (of the signal, or 5 x its noise)
                full = 2.0 * np.maximum(peak, 5.0 * rms)
            else:
                full = _columns(rng_v, ncol, f"{where}.range")
            bits = int(spec.get("bits", 16))  # assumed: a 16-bit ADC unless the model says otherwise
            for j in np.nonzero(full > 0)[0]:  # a silent, noiseless column stays exactly 0
                x[:, j] = sensing.quantise(x[:, j], bits, full[j])
        out[name] = x
    extras = {k: (np.asarray(v)[::step] if np.shape(v)[:1] == (n,) else np.asarray(v)) for k, v in run.extras.items()}
    meta = copy.deepcopy(run.meta)
    meta["measurement"] = {
        "of": meta.get("source"),
        "seed": int(seed),
        "model": copy.deepcopy(sensors),
        "chain": "gain, offset, anti-alias, skew, sampling, noise, quantisation",
    }
    meta["source"] = "measured"
    meta["sample_rate_hz"] = rate
    return RunFile(t=np.asarray(run.t)[::step].copy(), meta=meta, extras=extras, **out)


def write_measured(run, out, stem: str, sensors: dict, seed: int = 0, model_file=None):
    """Measure ``run`` through ``sensors`` (from :func:`load_sensors` of ``model_file``,
    None: the built-in one) and write ``<out>/<stem>.measured.run.npz``; returns the path."""
    from sim.runs.files import out_dir
    from sim.runs.runfile import write_run

    meas = measure_run(run, sensors, seed)
    meas.meta["measurement"]["model_file"] = str(model_file or DEFAULT_SENSORS)
    return write_run(out_dir(out) / f"{stem}.measured.run.npz", meas)


__all__ = [
    "CHANNEL_KEYS",
    "DEFAULT_SENSORS",
    "RECORDER_KEYS",
    "SensorsError",
    "check_sensors",
    "decimation",
    "load_sensors",
    "measure_run",
    "write_measured",
]
