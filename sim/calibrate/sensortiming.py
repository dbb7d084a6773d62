"""A sensor's delay or its conditioner, on the replay and closed-loop paths: which to judge first.

Within a test's band a causal low-pass delays a signal by about its group delay (4.2 ms
for a 4-pole Butterworth at 100 Hz), so a channel that is late reads as a
``sensor_delay`` and as a ``sensor_lowpass`` alike, and both candidates are refined at
the same channel. The search accepts the first refined candidate that passes
(:func:`sim.calibrate.pathsearch.calibrate_path`); :func:`prefer_timing` orders each such
pair before it is judged:

* the one whose held-out error on the columns it acts on is lower goes first (it explains
  more of what the fit never saw);
* when the two are within the acceptance margin of each other (the records cannot tell
  them apart), the pure delay goes first on a force, pressure or motion-transducer
  channel and the conditioner on an acceleration channel. A load cell's or pressure
  transducer's bridge amplifier passes kHz, far above a table's band: a lag there is the
  recorder's timing (a skew, a separately clocked channel), and a low-pass "explaining"
  it would also filter the channel's noise and mains pickup out of the comparison
  (sim.calibrate.timing.ORDERS: on the NEES-UCSD runs a 51.6 Hz "conditioner" took 34 %
  of a load cell's residual by filtering a 60 Hz line out). An accelerometer's signal
  goes through an analog conditioner (the LHPOST's: 100 Hz low-pass [Ozcelik 2008]), whose
  within-band lag is that filter's: the conditioner is the physical effect there.
"""

from __future__ import annotations

#: channels whose sensor chain is an analog conditioner (a lag there is preferably a low-pass)
CONDITIONED = ("table_acceleration", "accelerometers", "specimen_acceleration")
PAIR = ("sensor_delay", "sensor_lowpass")


def heldout_on_columns(rf, pho, mho) -> float:
    """Held-out NRMSE of the columns a refined sensor candidate ``rf`` acts on, with it applied."""
    from sim.calibrate import paths as P
    from sim.calibrate.sensorcands import acts_on, sensor_model

    keep = acts_on(rf.cand)
    on = [p.only(keep) for p in pho]
    if any(not p.columns for p in on):
        return float("inf")
    return P.nrmse(on, [sensor_model(rf.cand, rf.theta, p, m) for p, m in zip(pho, mho)])


def preferred(where: str, e_delay: float, e_lowpass: float, margin: float) -> str:
    """``"sensor_delay"`` or ``"sensor_lowpass"`` at channel place ``where``, from each one's
    held-out error on its columns (see the module docstring)."""
    from sim.effects.sensors import parse_channel

    if abs(e_delay - e_lowpass) > margin * max(e_delay, e_lowpass):
        return PAIR[0] if e_delay < e_lowpass else PAIR[1]
    ch, _col = parse_channel(where)
    return PAIR[1] if ch in CONDITIONED else PAIR[0]


def prefer_timing(refined: list, pho, mho, margin: float, say=None) -> list:
    """``refined`` (best first) with each delay / low-pass pair at one channel place put in
    the order :func:`preferred` gives (the first of the pair takes the place of the
    earlier one); every other candidate keeps its place."""
    out = list(refined)
    by_where: dict = {}
    for rf in out:
        if rf.ok and rf.cand.sensor and rf.cand.type in PAIR:
            by_where.setdefault(rf.cand.where, {})[rf.cand.type] = rf
    for where, pair in by_where.items():
        if len(pair) < 2:
            continue
        e = {t: heldout_on_columns(pair[t], pho, mho) for t in PAIR}
        first = preferred(where, e[PAIR[0]], e[PAIR[1]], margin)
        second = PAIR[1] if first == PAIR[0] else PAIR[0]
        i, j = (next(k for k, x in enumerate(out) if x is pair[t]) for t in (first, second))
        if j < i:
            out[i], out[j] = out[j], out[i]
        if say:
            say(
                f"  {where}: held-out {e[PAIR[0]]:.4f} with a delay, {e[PAIR[1]]:.4f} with a low-pass: "
                f"{first} judged first"
            )
    return out


__all__ = ["CONDITIONED", "heldout_on_columns", "prefer_timing", "preferred"]
