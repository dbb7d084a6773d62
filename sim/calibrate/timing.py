"""Sensor timing, conditioning and the load cells' gain on the mechanical path of
``shaketable calibrate``.

The force balance compares the recorded force with the force the model needs for the
recorded motion, sample by sample, so it holds only if every channel was sampled at the
instant its time stamp says. A load cell whose conditioner delays its signal by 4 ms,
or an accelerometer conditioner left at 30 Hz where the lab believes 100 Hz, leaves a
residual in phase quadrature with the motion that no force law explains (a delay tau
reads as a force tau x dF/dt). The candidates here change the records' timing, not the
model's forces:

* ``sensor_delay`` at ``channel:actuator_force``: the recorded force is the true one
  ``delay_s`` late (either sign); it is read at t + delay_s;
* ``sensor_delay`` at ``channel:table_acceleration``: the recorded acceleration is
  ``delay_s`` late; every other term of the balance is delayed alike (as the declared
  conditioner's filter is applied to them);
* ``sensor_lowpass`` at ``channel:table_acceleration``: the accelerometer's analog
  conditioner is a Butterworth of ``cutoff_hz`` and ``order`` instead of the declared
  one; the other terms go through it instead;
* ``sensor_delay`` at ``channel:table_displacement``: the displacement and the velocity
  are ``delay_s`` late beyond what the record declares of them (an LVDT's demodulator, a
  multiplexed recorder); the declared forces are made from the motion read at t +
  delay_s, and the still samples are its own. Its value is not the balance's: it is the
  delay at which the displacement and the acceleration agree
  (:func:`kinematic_timing.read_by_kinematics`);
* ``sensor_delay`` at ``channel:table_velocity``: a velocity of its own channel is
  ``delay_s`` late beyond the displacement (its value: where the two agree). The friction's
  switching and the damping read the velocity: on NEES-UCSD records a velocity 2 samples
  early took an 8 t added mass 3.8 % low;
* ``sensor_gain`` at ``channel:actuator_force``: the load cells read ``gain`` x the force
  (a piston area, a unit); it is read at 1 / gain, where the velocity reads the
  accelerometer true (:func:`_accelerometer_reads_true`).

What a record declares (``meta.channel_conditioning``, else the table's
``accelerometer_bandwidth_hz``) is the starting point (:func:`declared_state`). Each
candidate's parameter is fitted by a grid and a bounded scalar search of the force
balance's residual sum of squares (the accepted terms refitted linearly at each point);
its 95 % interval comes from the Jacobian of the residual in the parameter and the
coefficients together with the residual's autocorrelation (:func:`sim.calibrate.hac.hac_sigma`).
It is judged by the rules every candidate meets (:func:`sim.calibrate.acceptance.accept_numbers`
plus: off its bounds, and the declared value outside its interval).

The balance sees only the skew between the force and the acceleration; which of the two
is late is told by the displacement (:mod:`sim.calibrate.kinematic_timing`):
a candidate of the acceleration's timing must be corroborated by it, a force delay waits
while it puts the acceleration off its chain on the same side, and an acceleration delay
the balance finds but the displacement puts elsewhere is judged at the displacement's
value. Accepted parameters are fitted again with every later term
(:func:`refit_accepted`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from sim.calibrate.conditioning import declared_state, prefilter_of, shift

#: a delay is searched within this many seconds either way (assumed: 50 ms, ten times
#: the largest conditioner delay of the tables here, 4.2 ms for 4 poles at 100 Hz)
MAX_DELAY_S = 0.05
#: conditioner orders tried besides the declared one: none. Within a test's band a
#: Butterworth of another order and a cut-off of the same low-frequency delay balances the
#: force as well (2 poles at 55 Hz against 4 at 100 Hz: 4.1 ms both); what tells them
#: apart is above the band, where a record holds noise and mains pickup: on the NEES-UCSD
#: runs with a 60 Hz line on the load cell a 2-pole 51.6 Hz "conditioner" took 34 % of the
#: residual (held-out 0.038 -> 0.030) by filtering the line out of the force. The order
#: is the declared one (the table's 4 poles unless the run declares another).
ORDERS: tuple = ()
#: the lowest conditioner cut-off searched (assumed: 2 Hz, below any table's test band)
MIN_CUTOFF_HZ = 2.0
Z95 = 1.96
#: the share of what a timing candidate takes out of the residual that must be coherent with the
#: motion (assumed: 0.5, :func:`sim.calibrate.search.unexplained`'s line between a DOF's effect
#: and a sensor's). A sensor that is late or filtered differently
#: changes the balance by a filtered copy of the motion's own force; a low-pass that
#: "explains" a mains line picked up on the load cell (by filtering the force it is
#: applied to) takes out something the motion did not make.
COHERENT_SHARE = 0.5
#: times at most the displacement's reading of the acceleration's delay is taken again with
#: the acceleration aligned by the last (assumed: 3; the second moves it by < 1 % of the first)
ANCHOR_PASSES = 3
#: how far the displacement's own timing may be off, in samples (assumed: half a sample, a
#: multiplexed recorder's scan; the test records skew it 0.3 sample). Nearer than this the
#: displacement cannot tell an acceleration's delay from the balance's own reading of it;
#: beyond it, the motion's own delay read by the acceleration needs no held-out margin
#: (:func:`kinematic_timing.off_its_chain`)
DISPLACEMENT_SKEW_SAMPLES = 0.5
#: the timing fields of the motion's own skew (the displacement's and velocity's together;
#: the velocity's own), read by the kinematics (:func:`kinematic_timing.read_by_kinematics`)
MOTION_FIELDS = ("motion_delay_s", "velocity_delay_s")
#: their places, and the sensor each is timed against
MOTION_WHERES = {"channel:table_displacement": "acceleration", "channel:table_velocity": "displacement"}
#: the effect types of these candidates (``--effects`` names them)
TIMING_EFFECTS = ("sensor_delay", "sensor_lowpass", "sensor_gain")
#: the load cells' gain is searched between these (assumed: a piston area or a force
#: unit wrong by up to a factor 2, a rod side taken for a cap side included)
FORCE_GAIN_RANGE = (0.5, 2.0)


def retime(mr, state: dict):
    """A mechanical run (:class:`sim.calibrate.residuals.MechRun`) with the force,
    acceleration and motion timing of ``state`` in place of its own (the same weights:
    every timing is scored by one measure; the same rows unless the motion is re-timed;
    the terms' columns kept while the filter and the motion are)."""
    from sim.calibrate.conditioning import Conditioner
    from sim.calibrate.mechnoise import dof_noise_weights
    from sim.calibrate.residuals import moving_rows

    old = mr.extra["timing"]
    same_motion = all(old.get(k, 0.0) == state.get(k, 0.0) for k in MOTION_FIELDS)
    same_filter = same_motion and all(
        old[k] == state[k] for k in ("accel_delay_s", "accel_lowpass_hz", "accel_lowpass_order")
    )
    gain = state.get("force_gain", 1.0) / old.get("force_gain", 1.0)
    # the weights stay the run's own (the fit's "w" and each DOF's noise weight): a timing
    # candidate is judged on the same pooled error as the model without it
    keep = ("force_at_instant", "inertial", "w", "noise_weight", "force_noise", "motion", "declared_other")
    keep += (("other", "basis") if same_motion else ()) + (("raw_columns",) if same_filter else ())
    keep += ("columns", "second") if same_filter and gain == 1.0 else ()  # weighted: they scale with "w"
    dof_noise_weights(mr)  # computed on the run as declared, before it is copied
    new = dataclasses.replace(mr, extra={k: mr.extra[k] for k in keep if k in mr.extra})
    if "w" in new.extra:  # the force read at 1 / gain: its weights too, or a gain > 1 shrinks the error by itself
        new.extra["w"] = new.extra["w"] * gain
    fc = state["accel_lowpass_hz"]
    new.prefilter = Conditioner(float(fc), int(state["accel_lowpass_order"]), 1.0 / mr.dt) if fc else None
    new.filter_delay_s = state["accel_delay_s"]
    if not same_motion:  # the motion re-read: the declared forces made from it anew, its still samples its own
        new.u, new.v = motion_at(mr, state["motion_delay_s"], state.get("velocity_delay_s", 0.0))
        new.extra["other"] = mr.extra["declared_other"](new)
        new.rows = moving_rows(new.v, new.prefilter, mr.dt)
    f = shift(mr.extra["force_at_instant"], -state["force_delay_s"], mr.dt) / state.get("force_gain", 1.0)
    new.force = new.filt(f @ mr.J)
    new.model = new.chain(mr.extra["inertial"] + new.filt(new.extra["other"]))
    new.extra.update(actuator_force=f, timing=dict(state))
    return _restacked(new)


def _restacked(mr):
    """``mr`` with its weighted target made anew from its residual and rows (its weights
    kept: a timing is scored by the measure the run was)."""
    if "w" in mr.extra:
        mr.extra["y"] = (mr.residual[mr.rows] * mr.extra["w"]).reshape(-1)
    return mr


def motion_at(mr, delay_s: float, velocity_delay_s: float = 0.0) -> tuple:
    """``(u, v)``: the run's displacement and velocity as read at its declared timing
    (``extra["motion"]``), read ``delay_s`` later (the motion sensors that much late), the
    velocity ``velocity_delay_s`` later still (its own skew)."""
    u, v = mr.extra["motion"]
    return shift(u, -delay_s, mr.dt), shift(v, -(delay_s + velocity_delay_s), mr.dt)


@dataclass
class Candidate:
    """One timing candidate: ``name`` (effect type) at ``where``, its parameter, the state
    field it sets, the search bounds and the declared (neutral) value."""

    name: str
    where: str
    param: str
    field: str
    lo: float
    hi: float
    neutral: float
    order: int | None = None
    unit: str = "s"

    @property
    def read_by_kinematics(self) -> bool:
        """Whether the value is the acceleration's reading, not the balance's fit (the
        motion's own delay, :func:`read_by_kinematics`): it then needs no coherence
        with the motion, is judged on the re-timed motion's own samples, and beyond half
        a sample needs no held-out margin (:func:`kinematic_timing.off_its_chain`)."""
        return self.field in MOTION_FIELDS

    def state(self, base: dict, x: float) -> dict:
        s = dict(base)
        if self.field == "accel_lowpass_hz":  # searched in 1/cut-off (a delay-like scale)
            s["accel_lowpass_hz"] = 1.0 / x if x > 0 else None
            s["accel_lowpass_order"] = self.order
        else:
            s[self.field] = x
        return s

    def value(self, x: float) -> dict:
        if self.field == "accel_lowpass_hz":
            return {"cutoff_hz": 1.0 / x}
        return {self.param: x}


def candidates(mruns) -> list[Candidate]:
    """The timing candidates of these runs (declared timing of the first run as neutral)."""
    base = mruns[0].extra["timing"]
    dt = mruns[0].dt
    out = [
        Candidate(
            "sensor_delay",
            "channel:actuator_force",
            "delay_s",
            "force_delay_s",
            -MAX_DELAY_S,
            MAX_DELAY_S,
            base["force_delay_s"],
        ),
        Candidate(
            "sensor_delay",
            "channel:table_acceleration",
            "delay_s",
            "accel_delay_s",
            -MAX_DELAY_S,
            MAX_DELAY_S,
            base["accel_delay_s"],
        ),
    ]
    out.append(  # the motion sensors' own skew, timed by the acceleration (:func:`kinematic_timing.read_by_kinematics`)
        Candidate(
            "sensor_delay",
            "channel:table_displacement",
            "delay_s",
            "motion_delay_s",
            -MAX_DELAY_S,
            MAX_DELAY_S,
            base.get("motion_delay_s", 0.0),
        )
    )
    if not all(mr.extra.get("velocity_derived") for mr in mruns):
        out.append(velocity_candidate(base))
    out.append(  # the load cells' gain (a piston area or a unit nobody wrote down)
        Candidate("sensor_gain", "channel:actuator_force", "gain", "force_gain", *FORCE_GAIN_RANGE, 1.0, unit="1")
    )
    g0 = 1.0 / base["accel_lowpass_hz"] if base["accel_lowpass_hz"] else 0.0
    for order in sorted(set(ORDERS) | {base["accel_lowpass_order"]}):  # the declared order
        out.append(
            Candidate(
                "sensor_lowpass",
                "channel:table_acceleration",
                "cutoff_hz",
                "accel_lowpass_hz",
                1.0 / (0.45 / dt),
                1.0 / MIN_CUTOFF_HZ,
                g0,
                order,
                "Hz",
            )
        )
    return out


def velocity_candidate(base: dict) -> Candidate:
    """The velocity's own skew against the displacement: a velocity of its own channel
    (a transducer's, a recorder's), not one an import made from the displacement."""
    return Candidate(
        "sensor_delay",
        "channel:table_velocity",
        "delay_s",
        "velocity_delay_s",
        -MAX_DELAY_S,
        MAX_DELAY_S,
        base.get("velocity_delay_s", 0.0),
    )


def _rss(mruns, terms, cand, x) -> float:
    from sim.calibrate.trace import _fit_linear

    runs = [retime(mr, cand.state(mr.extra["timing"], x)) for mr in mruns]
    return _fit_linear(runs, terms)[1]


def search(mruns, terms, cand: Candidate) -> float:
    """The parameter that minimises the balance's residual: a grid (every second sample
    for a delay, 16 points in 1/cut-off), then a bounded scalar search between the best
    point's neighbours."""
    from scipy.optimize import minimize_scalar

    dt = mruns[0].dt
    if cand.field == "accel_lowpass_hz":
        grid = np.geomspace(cand.lo, cand.hi, 16)
    elif cand.field == "force_gain":  # 2 % steps, 1 on the grid
        grid = np.geomspace(cand.lo, cand.hi, 71)
    else:  # every second sample: the residual varies on the motion's time scale (> 10 samples)
        n = int(MAX_DELAY_S / (2 * dt))
        grid = cand.neutral + 2 * dt * np.arange(-n, n + 1)
        grid = grid[(grid >= cand.lo) & (grid <= cand.hi)]
    vals = [_rss(mruns, terms, cand, g) for g in grid]
    k = int(np.argmin(vals))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    r = minimize_scalar(
        lambda x: _rss(mruns, terms, cand, x), bounds=(lo, hi), method="bounded", options={"xatol": 1e-4 * (hi - lo)}
    )
    return float(r.x) if r.fun <= vals[k] else float(grid[k])


def sigma(mruns, terms, cand: Candidate, x: float) -> float:
    """Standard deviation of the parameter at ``x``: the Jacobian of the stacked, weighted
    residual in the terms' coefficients and the parameter (central difference), through
    the autocorrelation-robust sandwich of :func:`sim.calibrate.hac.hac_sigma`."""
    from sim.calibrate.hac import hac_sigma
    from sim.calibrate.trace import _fit_linear, _segments

    h = {"accel_lowpass_hz": 1e-3 * max(x, 1e-4), "force_gain": 1e-4}.get(cand.field, 0.05 * mruns[0].dt)
    runs = [retime(mr, cand.state(mr.extra["timing"], x)) for mr in mruns]
    theta, _, y, X = _fit_linear(runs, terms)

    def stacked(xx):
        rr = [retime(mr, cand.state(mr.extra["timing"], xx)) for mr in mruns]
        from sim.calibrate.trace import _stack

        yy, XX = _stack(rr, terms)
        return yy - XX @ theta

    d = (stacked(x + h) - stacked(x - h)) / (2 * h)
    J = np.column_stack([X, d]) if X.shape[1] else d[:, None]
    return float(hac_sigma(J, y - X @ theta, _segments(runs))[-1])


def coherent_share(mruns, before, after) -> float:
    """The share of the change ``before - after`` of the residuals (per run and DOF)
    that is coherent with the motion: its Welch spectrum weighted by its largest
    coherence with the DOF's acceleration, velocity or displacement, pooled by power."""
    from sim.calibrate.residuals import spectra

    num = den = 0.0
    for mr, r0, r1 in zip(mruns, before, after):
        for j in range(r0.shape[1]):
            d = r0[:, j] - r1[:, j]
            if not np.any(d):
                continue
            sp = spectra(d, 1.0 / mr.dt, {"u": mr.u[:, j], "v": mr.v[:, j], "a": mr.a[:, j]})
            C = np.max(list(sp["coherence"].values()), axis=0)
            num += float(np.sum(C * sp["psd"]))
            den += float(np.sum(sp["psd"]))
    return num / den if den > 0 else 0.0


def uncertainty_of(cand, x, s) -> dict:
    if cand.field == "accel_lowpass_hz":  # delta method from 1/cut-off to the cut-off
        return {"cutoff_hz": Z95 * s / x**2 if x > 0 else math.inf}
    return {cand.param: Z95 * s}


def refit_accepted(mfit, mho, terms, done: list) -> tuple[list, list]:
    """The accepted timing parameters (``done``: their ``effects_added`` entries, updated
    in place) fitted again with ``terms``, one after the other, as the laws' coefficients
    are refitted with every term added: a force delay accepted before a specimen's second
    mode was in held part of that mode's phase. Returns the fit and held-out runs re-timed."""
    for entry in done:
        cand = next(
            (c for c in candidates(mfit) if (c.name, c.where) == (entry["name"], entry["where"])),
            None,
        )
        if cand is None or entry.get("timed_by"):  # kinematics: the terms do not move it
            continue
        x = search(mfit, terms, cand)
        s = sigma(mfit, terms, cand, x)
        x, s = _held_to_the_displacement(entry, x, s, mfit[0].dt)
        mfit = [retime(mr, cand.state(mr.extra["timing"], x)) for mr in mfit]
        mho = [retime(mr, cand.state(mr.extra["timing"], x)) for mr in mho]
        entry["parameters"], entry["uncertainty"] = cand.value(x), uncertainty_of(cand, x, s)
    return mfit, mho


def _held_to_the_displacement(entry: dict, x: float, s: float, dt: float) -> tuple[float, float]:
    """``(x, s)`` of a refitted acceleration delay, or the displacement's reading of it
    where the refit moves it out of their agreement at acceptance (:func:`kinematic_timing.placed`): the
    balance, refitted with a law added, may put on the acceleration a skew that is the
    force's (the lab example's records: 8.7 ms at acceptance, within half a sample of the
    displacement's 9.75, then 14.5 ms, the whole skew, once the friction was in). The entry
    is then timed by the displacement, as if it had been at acceptance."""
    reads = entry.get("displacement_reads") or {}
    if "delay_s" not in reads or abs(x - reads["delay_s"]) < DISPLACEMENT_SKEW_SAMPLES * dt:
        return x, s
    entry["timed_by"] = "displacement"
    return float(reads["delay_s"]), float(reads["sigma_s"])


def candidate_of(mruns, entry: dict) -> Candidate | None:
    """The timing candidate that made the ``effects_added`` entry ``entry``."""
    order = (entry.get("options") or {}).get("order")
    for c in candidates(mruns):
        if (c.name, c.where) == (entry["name"], entry["where"]) and (c.order is None or c.order == order):
            return c
    return None


def without(mfit, mho, terms, done: list, k: int, declared: dict):
    """The runs with accepted timing entry ``k`` of ``done`` put back at its declared value
    (``declared``: run name -> its timing state before any was accepted) and the others
    refitted with ``terms``: ``(fit runs, held-out runs, the other entries)`` (copies), or
    None when the entry has no candidate."""
    cand = candidate_of(mfit, done[k])
    if cand is None:
        return None
    keys = ("accel_lowpass_hz", "accel_lowpass_order") if cand.field == "accel_lowpass_hz" else (cand.field,)

    def back(mr):
        return retime(mr, {**mr.extra["timing"], **{key: declared[mr.name][key] for key in keys}})

    rest = [dict(e, parameters=dict(e["parameters"])) for i, e in enumerate(done) if i != k]
    mfit, mho = [back(mr) for mr in mfit], [back(mr) for mr in mho]
    mfit, mho = refit_accepted(mfit, mho, terms, rest)
    return mfit, mho, rest


def settled(before: list, entries: list) -> bool:
    """Whether every accepted timing parameter moved by less than a tenth of its 95 %
    interval since ``before`` (their parameters at the last pass)."""
    for old, e in zip(before, entries):
        for k, v in e["parameters"].items():
            if abs(v - old[k]) > 0.1 * e["uncertainty"].get(k, math.inf):
                return False
    return True


def merged(scored, timed) -> list:
    """The round's law candidates ``(explained, law, where, fit)`` and the timing ones
    (as ``(explained, None, where, evaluation)``) in one order, most explained first
    (stable: the laws' own order kept among themselves)."""
    rows = [(e["row"]["explained_fraction"], None, e["row"]["where"], e) for e in timed]
    both = list(scored) + rows
    return sorted(both, key=lambda s: -round(s[0], 6))


def log_line(row: dict) -> str:
    p = ", ".join(f"{k} = {v:.5g}" for k, v in row["parameters"].items())
    tail = "  ACCEPTED" if row["accepted"] else f"  ({row['reason']})"
    return (
        f"  {row['name']:18s} {row['where']:14s} explains {100 * row['explained_fraction']:6.2f} %  "
        f"held-out {row['holdout_error']:.4f}  [{p}]" + tail
    )


def added_entry(row: dict) -> dict:
    """The ``effects_added`` entry of an accepted timing candidate."""
    units = {"delay_s": "s", "cutoff_hz": "Hz", "gain": "1"}
    kin = row.get("kinematics") or {}
    # the force's and acceleration's whole delay or conditioner, as the balance fits it: in
    # place of the declared one when the later path compares the record (sim.calibrate.paths);
    # the motion's, beyond what it declares (its declared delay is read before any timing);
    # a gain: none is declared
    replaces = {} if row["name"] == "sensor_gain" else {"replaces_declared": row["where"] not in MOTION_WHERES}
    timed_by = MOTION_WHERES.get(row["where"]) or ("displacement" if kin.get("from_displacement") else None)
    return {
        "name": row["name"],
        "where": row["where"],
        "options": {**row.get("options", {}), **replaces},
        "parameters": row["parameters"],
        "uncertainty": row["uncertainty"],
        "units": {k: units[k] for k in row["parameters"]},
        **({"timed_by": timed_by} if timed_by else {}),
        **_displacement_reads(kin),
    }


def _displacement_reads(kin: dict) -> dict:
    """The displacement's reading of an acceleration delay the balance's value stands for
    (:func:`sim.calibrate.kinematic_timing.placed`), which its later refits are held to."""
    if "displacement_s" not in kin:
        return {}
    return {"displacement_reads": {"delay_s": kin["displacement_s"], "sigma_s": kin["displacement_sigma_s"]}}


__all__ = [
    "TIMING_EFFECTS",
    "Candidate",
    "added_entry",
    "candidate_of",
    "candidates",
    "coherent_share",
    "declared_state",
    "prefilter_of",
    "refit_accepted",
    "retime",
    "search",
    "settled",
    "shift",
    "sigma",
    "uncertainty_of",
    "without",
]
