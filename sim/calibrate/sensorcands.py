"""The sensor candidates of the replay and closed-loop paths (:mod:`sim.calibrate.sensitivity`):
a compared channel's gain, delay and low-pass (:mod:`sim.effects.sensors`), applied to
the model's channels after the fact (no replay), and the columns each acts on."""

from __future__ import annotations

import math

import numpy as np

from sim.calibrate.candidate import Candidate

SENSOR = ("sensor_gain", "sensor_offset", "sensor_delay", "sensor_lowpass")
#: a sensor delay's range on these paths: a channel up to MAX_DELAY_S late (assumed: 50 ms,
#: ten times the largest conditioner delay of the tables here, 4.2 ms for 4 poles at 100 Hz;
#: the mechanical path's bound, sim.calibrate.timing.MAX_DELAY_S) or up to
#: MAX_ADVANCE_SAMPLES samples early. A sensor cannot answer before its cause: a channel
#: that leads the motion is a recorder's timing, not physics (a multiplexed or separately
#: clocked channel, a conditioner on the *other* channels; issue 23: a pressure leading
#: by 1-2 samples at 204.8 Hz), a few samples at most; a wider advance would let a delay
#: stand in for a model that responds late (a valve, an oil column)
MAX_DELAY_S = 0.05
MAX_ADVANCE_SAMPLES = 8


def sensor_candidates(tb, prs) -> list[Candidate]:
    """The gain, delay and low-pass of each compared channel and column (an offset is each
    record's own zero, :func:`paths.tared`; the zero they share: :mod:`sim.calibrate.offsets`)."""
    from sim.calibrate.conditioning import sensor_channel

    out, have, fs = [], tb.have, 1.0 / prs[0].dt
    for t in (t for t in SENSOR if t != "sensor_offset" and tb.offered(t)):
        for ch, cols in prs[0].columns.items():
            one, s = np.shape(prs[0].recorded[ch])[1:] in ((), (1,)), sensor_channel(ch, prs)  # one: its column
            for w in [f"channel:{s}"] + ([] if one else [f"channel:{s}[{j}]" for j in cols]):
                if (t, w) in have:
                    continue
                if t == "sensor_gain":
                    c = ("gain", 1.0, 0.01, -1e3, 1e3, "1")
                elif t == "sensor_delay":  # either sign: a channel may lead its motion (an advance)
                    c = ("delay_s", 0.0, 0.5 / fs, -MAX_ADVANCE_SAMPLES / fs, MAX_DELAY_S, "s")
                else:  # internal 1/cutoff: the first step a filter at fs/4; the cutoff stays below Nyquist
                    c = ("cutoff_hz", 0.0, 4.0 / fs, 2.2 / fs, math.inf, "Hz")
                k, x0, h, lo, hi, unit = c
                start, step, low, high = (np.array([v]) for v in (x0, h, lo, hi))
                out.append(Candidate(t, w, (k,), start, step, low, high, {k: unit}, sensor=True))
    return out + command_candidate(tb, prs)


#: the controller's recorded channels (what drives a replay or a closed loop)
COMMAND = "channel:valve_command"


def command_candidate(tb, prs) -> list[Candidate]:
    """The controller's channels recorded late against the analog ones (``sensor_delay``
    at :data:`COMMAND`), on the replay path: the drive is then the recorded command read
    ``delay_s`` later, so every compared channel of the model moves ``delay_s`` earlier
    (:func:`sensor_model`). The mechanical path sees the analog channels only against each
    other: several skewed alike (the displacement and the pressure a sample early on the
    worked example's records) leave them on time among themselves and early against the
    command, which no other candidate takes (a valve delay only lags). Offered only early,
    up to :data:`MAX_ADVANCE_SAMPLES` (a recorder's skew; lagging is a valve delay's),
    wherever a valve delay or a sensor's delay is looked for, and judged against the
    declared valve delay (``ref``: the least of it; within it a valve delay that much
    shorter is the same records: :func:`sim.calibrate.pathjudge._a_shorter_valve_delay`)."""
    if prs[0].path != "replay" or ("sensor_delay", COMMAND) in tb.have:
        return []
    if not (tb.offered("sensor_delay") or tb.offered("valve_delay")):  # the valve delay's other sign
        return []
    fs = 1.0 / prs[0].dt
    start, step, low, high = (np.array([v]) for v in (0.0, 0.5 / fs, 0.0, MAX_ADVANCE_SAMPLES / fs))
    ref = {"valve_delay_s": float(np.min(tb.hp.per_actuator("valve_delay_s")))}
    return [
        Candidate("sensor_delay", COMMAND, ("delay_s",), start, step, low, high, {"delay_s": "s"}, ref=ref, sensor=True)
    ]


def sensor_model(cand: Candidate, theta, pr, model: dict) -> dict:
    """The model's channels with sensor candidate ``cand`` at ``theta`` applied (the
    controller's lag as the drive is read for the model: :func:`on_the_analog_clock`)."""
    from sim.calibrate.conditioning import on_the_analog_clock
    from sim.effects.base import EFFECTS

    if model is None:
        return None
    if cand.type == "sensor_lowpass" and not theta[0] > 0:
        return model
    if cand.where == COMMAND:  # the drive read later: every channel of the model that much earlier
        dt = float(pr.t[1] - pr.t[0])
        return {c: on_the_analog_clock(x, float(theta[0]), dt) for c, x in model.items()}
    eff = EFFECTS[cand.type](cand.entry(theta))
    ch = next((c for c in (eff.channel, *_derived(eff.channel)) if c in model), None)
    if ch is None:
        return model
    out = dict(model)  # a velocity derived from the displacement: its sensor's effect, linear, commutes with d/dt
    out[ch] = eff.measure(pr.t, {eff.channel: np.asarray(model[ch], float)}, None)[eff.channel]
    return out


def acts_on(cand: Candidate):
    """``keep(channel, column)``: the compared columns a sensor candidate acts on (every
    one: the controller's channels, :data:`COMMAND`)."""
    from sim.effects.sensors import parse_channel

    if cand.where == COMMAND:
        return lambda c, j: True
    ch, col = parse_channel(cand.where)
    cols = col if isinstance(col, tuple) else (col,)
    return lambda c, j: c in (ch, *_derived(ch)) and (col is None or j in cols)


def _derived(sensor: str) -> tuple:
    """The compared channels a run may derive from ``sensor`` (:data:`sim.calibrate.conditioning.DERIVED_FROM`)."""
    from sim.calibrate.conditioning import DERIVED_FROM

    return tuple(c for c, s in DERIVED_FROM.items() if s == sensor)


__all__ = [
    "COMMAND",
    "MAX_ADVANCE_SAMPLES",
    "MAX_DELAY_S",
    "SENSOR",
    "acts_on",
    "command_candidate",
    "sensor_candidates",
    "sensor_model",
]
