"""Sensor effects: a run-file channel as its sensor reports it (``measure``).

Each acts at ``where = "channel:<run-file channel>[<column>]"`` (one column, 0-based),
``"channel:<channel>[<column>,<column>,...]"`` (several: one actuator class's load cells)
or ``"channel:<channel>"`` (every column); channels as in ``sim.runs.runfile.CHANNELS``
(``docs/run-file.md``)::

    [[effect]]
    type = "sensor_gain"
    where = "channel:actuator_force[2]"
    gain = 1.02                     # the load cell reads 2 % high
    source = "assumed: ..."

| type | parameters | units | what the channel becomes |
|---|---|---|---|
| ``sensor_gain`` | ``gain`` | 1 | gain x signal |
| ``sensor_offset`` | ``offset`` | channel units | signal + offset |
| ``sensor_delay`` | ``delay_s`` | s | signal(t - delay), linear interpolation (any fraction of a sample; negative: ahead) |
| ``sensor_lowpass`` | ``cutoff_hz``, option ``order`` (default 2) | Hz | causal Butterworth low-pass, started in steady state |
| ``sensor_noise`` | ``rms``, option ``seed`` (default 0) | channel units | + white Gaussian noise of that RMS |

They act when a run file is built (``sim.runs.build.build_runfile``), in the order of
the ``[[effect]]`` entries. The noise takes its own generator seeded by ``seed`` (and
the place), so a run is reproducible; the ``rng`` argument of ``measure`` is ignored.
"""

from __future__ import annotations

import re
import zlib

import numpy as np

from sim.effects.base import Effect, register
from sim.errors import ScenarioError
from sim.signals import sensing

#: the run-file channels a sensor effect can act on (sim.runs.runfile.CHANNELS; the
#: effects layer sits below sim.runs, so the list is repeated and checked by a test)
CHANNEL_NAMES = (
    "valve_command",
    "reference",
    "spool_position",
    "actuator_displacement",
    "actuator_force",
    "pressure_a",
    "pressure_b",
    "table_displacement",
    "table_velocity",
    "table_acceleration",
    "accelerometers",
    "specimen_acceleration",
)

_PLACE = re.compile(r"^([a-z_]+)(?:\[(\d+(?:,\d+)*)\])?$")


def parse_channel(where: str, source: str = "effect") -> tuple[str, int | tuple | None]:
    """``"channel:actuator_force[2]"`` -> ``("actuator_force", 2)``; several columns
    (``[8,9,10,11]``: one actuator class's load cells) -> a tuple; no column -> None."""
    kind, _, rest = where.partition(":")
    m = _PLACE.match(rest)
    if kind != "channel" or not m or m.group(1) not in CHANNEL_NAMES:
        raise ScenarioError(
            f"{source}: where = '{where}' is not a channel; use 'channel:<name>', "
            f"'channel:<name>[<column>]' or 'channel:<name>[<column>,<column>,...]' with a name among "
            f"{', '.join(CHANNEL_NAMES)}"
        )
    if m.group(2) is None:
        return m.group(1), None
    cols = tuple(int(c) for c in m.group(2).split(","))
    return m.group(1), cols[0] if len(cols) == 1 else cols


class _Sensor(Effect):
    places = ("channel",)

    def __init__(self, entry: dict, *, source: str = "effect"):
        super().__init__(entry, source=source)
        self.channel, self.column = parse_channel(self.where, source)

    def transform(self, t: np.ndarray, x: np.ndarray) -> np.ndarray:
        """The sensor's output for the true signal ``x`` (samples on axis 0)."""
        raise NotImplementedError

    def measure(self, t, channels: dict, rng=None) -> dict:
        x = channels.get(self.channel)
        if x is None:
            return channels
        x = np.asarray(x, dtype=np.float64)
        out = dict(channels)
        if self.column is None:
            out[self.channel] = self.transform(np.asarray(t), x)
            return out
        cols = list(self.column) if isinstance(self.column, tuple) else [self.column]
        if x.ndim != 2 or not all(0 <= c < x.shape[1] for c in cols):
            raise ScenarioError(
                f"{self.source}: where = '{self.where}': channel {self.channel} has "
                f"{x.shape[1] if x.ndim == 2 else 1} column(s) (0-based index)"
            )
        y = x.copy()
        y[:, cols] = self.transform(np.asarray(t), x[:, cols])
        out[self.channel] = y
        return out


def _dt(t: np.ndarray) -> float:
    if len(t) < 2:
        raise ScenarioError("a sensor effect needs a run of two samples or more")
    return float(t[1] - t[0])


@register
class SensorGain(_Sensor):
    type = "sensor_gain"
    SPEC = {"gain": ("1", -1e3, 1e3, None)}

    def transform(self, t, x):
        return self.values["gain"] * x


@register
class SensorOffset(_Sensor):
    type = "sensor_offset"
    SPEC = {"offset": ("channel units", -1e12, 1e12, None)}

    def transform(self, t, x):
        return x + self.values["offset"]


@register
class SensorDelay(_Sensor):
    type = "sensor_delay"
    SPEC = {"delay_s": ("s", -10.0, 10.0, None)}  # either sign: a channel may lead (calibrate finds both)
    #: true: this is the channel's whole delay, in place of what a record declares of it
    #: (calibrate's mechanical path writes it so); compared with a record, the declared
    #: delay is then not applied on top (sim.calibrate.paths)
    OPTIONS = {"replaces_declared": False}

    def transform(self, t, x):
        return sensing.fractional_delay(x, self.values["delay_s"], _dt(t))


@register
class SensorLowpass(_Sensor):
    type = "sensor_lowpass"
    SPEC = {"cutoff_hz": ("Hz", 1e-6, 1e9, None)}
    #: ``replaces_declared``: this is the channel's conditioner, in place of the one a
    #: record declares (as :class:`SensorDelay`'s)
    OPTIONS = {"order": 2, "replaces_declared": False}

    def transform(self, t, x):
        order = self.options["order"]
        if isinstance(order, bool) or not isinstance(order, int) or not 1 <= order <= 12:
            raise ScenarioError(f"{self.source}: order = {order!r}; use a whole number 1..12")
        fs = 1.0 / _dt(t)
        if not self.values["cutoff_hz"] < 0.5 * fs:
            raise ScenarioError(
                f"{self.source}: cutoff_hz = {self.values['cutoff_hz']:g} Hz is not below the "
                f"run's Nyquist frequency {0.5 * fs:g} Hz; use a lower cutoff"
            )
        return sensing.lowpass(x, self.values["cutoff_hz"], order, fs)


@register
class SensorNoise(_Sensor):
    type = "sensor_noise"
    SPEC = {"rms": ("channel units", 0.0, 1e12, None)}
    OPTIONS = {"seed": 0}

    def transform(self, t, x):
        seed = self.options["seed"]
        if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
            raise ScenarioError(f"{self.source}: seed = {seed!r}; use a whole number >= 0")
        # one stream per place: two noisy channels with the same seed are independent
        rng = np.random.default_rng([seed, zlib.crc32(self.where.encode())])
        return x + self.values["rms"] * rng.standard_normal(x.shape)


__all__ = [
    "CHANNEL_NAMES",
    "SensorDelay",
    "SensorGain",
    "SensorLowpass",
    "SensorNoise",
    "SensorOffset",
    "parse_channel",
]
