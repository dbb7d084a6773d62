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
  (:func:`read_by_kinematics`);
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
is late is told by the displacement (:mod:`sim.calibrate.anchor`, :func:`kinematic_check`):
a candidate of the acceleration's timing must be corroborated by it, a force delay waits
while it puts the acceleration off its chain on the same side, and an acceleration delay
the balance finds but the displacement puts elsewhere is judged at the displacement's
value (:func:`placed`). Accepted parameters are fitted again with every later term
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
#: (:func:`_margin_of`)
DISPLACEMENT_SKEW_SAMPLES = 0.5
#: the timing fields of the motion's own skew (the displacement's and velocity's together;
#: the velocity's own), read by the kinematics (:func:`read_by_kinematics`)
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
        a sample needs no held-out margin (:func:`_margin_of`)."""
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
    out.append(  # the motion sensors' own skew, timed by the acceleration (:func:`read_by_kinematics`)
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


def evaluate(mfit, mho, cur, cand: Candidate, e_ho: float, flat: float, margin: float, first=None, at=None) -> dict:
    """The candidate fitted and judged: ``{"row", "accepted", "fit", "mfit", "mho"}`` (the
    retimed runs and the refit); ``first``: a kinematic candidate's reading at its neutral
    value, when taken to offer it; ``at``: ``(value, sd, None)`` read by :mod:`sim.calibrate.gainpair`."""
    from sim.calibrate.acceptance import accept_numbers
    from sim.calibrate.residuals import nrmse_runs
    from sim.calibrate.trace import fit_terms, flatness, predict

    if at is not None:
        x, s, kin = at
    elif cand.read_by_kinematics:
        x, s, kin = read_by_kinematics(mfit, cand, first)
    else:
        x, s, kin = placed(mfit, cur.terms, cand, search(mfit, cur.terms, cand))
    nf = [retime(mr, cand.state(mr.extra["timing"], x)) for mr in mfit]
    nh = [retime(mr, cand.state(mr.extra["timing"], x)) for mr in mho]
    if cand.read_by_kinematics:  # judged on the samples where the re-timed motion moves
        cur, e_ho, flat = _on_the_rows_of(mfit, mho, nf, nh, cur)
    new = fit_terms(nf, cur.terms, refine="none")
    e_new = nrmse_runs(nh, predict(nh, new))
    f_new = flatness(nf, new.residuals)
    bic_new = new.n * math.log(max(new.rss, 1e-300) / new.n) + (new.p + 1) * math.log(new.n)
    ok, why = _param_check(cand, x, s)
    if ok and cand.field == "force_gain":
        ok, why = _accelerometer_reads_true(mfit)
    share = coherent_share(mfit, cur.residuals, new.residuals)
    # the motion's delay is the kinematics', not fitted to the residual, and what it takes
    # out goes through the friction's sign: not a filtered copy of the motion's own force
    if ok and share < COHERENT_SHARE and not cand.read_by_kinematics:
        ok, why = False, f"what it takes out of the residual is {100 * share:.0f} % coherent with the motion"
    if ok and kin is not None and not kin["ok"]:
        ok, why = False, kin["reason"]
    if ok:
        m = _margin_of(cand, x, mfit[0].dt, margin)
        # read by the kinematics beyond a scan: no whiteness veto either (a velocity 2 samples early
        # was refused at flatness 0.518 -> 0.506, an undeclared conditioner's shape in the residual)
        ok, why = accept_numbers(e_ho, e_new, cur.bic, bic_new, -math.inf if m == 0.0 else flat, f_new, m)
    value, unc = cand.value(x), _uncertainty(cand, x, s)
    row = {
        "name": cand.name,
        "where": cand.where,
        **({"options": {"order": cand.order}} if cand.order else {}),
        "explained_fraction": 1.0 - new.rss / cur.rss if cur.rss > 0 else 0.0,
        "parameters": value,
        "uncertainty": unc,
        "holdout_error": e_new,
        "bic_change": bic_new - cur.bic,
        "flatness": f_new,
        "coherent_share": share,
        **({"kinematics": {k: v for k, v in kin.items() if k not in ("reason", "sigma_s")}} if kin else {}),
        "accepted": ok,
        "reason": why,
    }
    return {"row": row, "accepted": ok, "fit": new, "mfit": nf, "mho": nh, "e_ho": e_new, "flat": f_new}


def _margin_of(cand: Candidate, x: float, dt: float, margin: float) -> float:
    """The held-out gain ``cand`` at ``x`` must make: the search's ``margin``, or none (the
    error only may not rise, and the residual need not whiten) for a motion read off its
    clock by more than a recorder's scan (:data:`DISPLACEMENT_SKEW_SAMPLES`). That value
    is measured by the kinematics to a hundredth of a sample, not fitted to the residual;
    the laws fitted before it take up most of what it changes: NEES-UCSD records with the
    displacement 2 samples early and 8 t added took the added mass 3.9 % low while the
    delay moved the held-out error by 1.7 %."""
    if cand.read_by_kinematics and abs(x - cand.neutral) > DISPLACEMENT_SKEW_SAMPLES * dt:
        return 0.0
    return margin


def _on_the_rows_of(mfit, mho, nf, nh, cur) -> tuple:
    """``(fit, held-out error, flatness)`` of the current terms refitted on ``mfit`` and
    scored on ``mho`` over the samples the re-timed runs ``nf`` and ``nh`` read. A re-timed
    motion has its own still samples (:func:`sim.calibrate.residuals.moving_rows`); judged
    against the model on the old ones, a candidate is judged by which samples the noise on
    the velocity leaves below the deadband: on clean NEES-UCSD records (tests/calibrate/
    test_timing.py) the displacement re-timed 0.3 sample either way moved the held-out
    error up by 2.9-3.4 %, on the same samples by 0.2 % or less."""
    from sim.calibrate.residuals import nrmse_runs
    from sim.calibrate.trace import fit_terms, flatness, predict

    bf = [on_rows(mr, r.rows) for mr, r in zip(mfit, nf)]
    bh = [on_rows(mr, r.rows) for mr, r in zip(mho, nh)]
    fit = fit_terms(bf, cur.terms, refine="none")
    return fit, nrmse_runs(bh, predict(bh, fit)), flatness(bf, fit.residuals)


def on_rows(mr, rows: np.ndarray):
    """A mechanical run read over ``rows`` (its weighted target and stacked columns made
    anew, its weights kept: :func:`retime`'s)."""
    return _restacked(
        dataclasses.replace(mr, rows=rows, extra={k: v for k, v in mr.extra.items() if k not in ("y", "columns")})
    )


def placed(mfit, terms, cand: Candidate, x: float) -> tuple[float, float, dict | None]:
    """The candidate's value, its standard deviation and what the displacement says of it
    (:func:`kinematic_check`): the balance's value and interval, or, for an acceleration
    delay the balance finds (its interval leaving out the declared value) while the
    displacement puts the acceleration measurably off its chain and reads another value
    (more than the displacement's own skew apart, :data:`DISPLACEMENT_SKEW_SAMPLES`), the
    displacement's own value and interval (the balance gave the acceleration a skew that
    is partly the force's: an accelerometer late and the pressure early at once). Where
    the two agree the balance's value stands, and the displacement's reading goes with it
    (``displacement_s``, ``displacement_sigma_s``): a later refit of the balance may not
    move it out of that agreement (:func:`refit_accepted`)."""

    def check(xx):
        return kinematic_check(cand, xx, mfit, lambda: [retime(mr, cand.state(mr.extra["timing"], xx)) for mr in mfit])

    kin, s = check(x), sigma(mfit, terms, cand, x)
    skew = abs(x - cand.neutral) > Z95 * s  # the balance sees the acceleration skewed
    if kin is None or not kin["significant"] or not skew or cand.field != "accel_delay_s":
        return x, s, kin
    x_kin, aligned = _displacement_reading(cand, kin, check)
    if kin["ok"] and abs(x - x_kin) < DISPLACEMENT_SKEW_SAMPLES * mfit[0].dt:
        return x, s, {**kin, "displacement_s": x_kin, "displacement_sigma_s": aligned["sigma_after_s"]}
    # nearer the displacement is not enough: an accelerometer 2 samples late and a
    # pressure 1 early put 14.5 ms on the acceleration, which the displacement read 9.8
    return x_kin, aligned["sigma_after_s"], {**aligned, "from_displacement": True}


def read_by_kinematics(mfit, cand: Candidate, first=None) -> tuple[float, float, dict | None]:
    """The motion's own delay (:data:`MOTION_FIELDS`) at which two sensors of one motion
    agree (:mod:`sim.calibrate.anchor`), its standard deviation and the reading
    (:func:`kinematic_check`'s keys): the displacement's (the velocity's with it) where the
    re-read displacement and the acceleration through its chain agree; the velocity's own
    where the re-read velocity and the displacement do. Offered where they disagree
    (:func:`round_candidates`), beside the acceleration's own candidates: where the balance
    sees the force and the acceleration apart, the acceleration is the one off and its
    candidate explains more; where it sees them together, the displacement is. Its value is
    the kinematics', not the balance's: a Coulomb law switches a whole sample at a time, so
    the balance's residual is a staircase in the motion's delay, its least on the worked
    example's records on time already 0.4-0.8 sample off. Read again with the sensor
    aligned by the last reading, as :func:`_displacement_reading`. A velocity whose phase
    against the displacement is not a delay's (:attr:`sim.calibrate.anchor.Anchor.a_delay`:
    a filtered velocity, as the LHPOST DAQ's complementary one) is not a skew: the reading
    says so and the candidate is refused."""
    from sim.calibrate import anchor

    first = a = first if first is not None else _kinematic_reading(mfit, cand, cand.neutral)
    x = cand.neutral
    for _ in range(ANCHOR_PASSES):
        if not math.isfinite(a.delay_s):
            return x, math.inf, None
        # the acceleration read early against the displacement: the displacement late; the
        # velocity read late against the displacement: the velocity late
        x += a.delay_s if cand.field == "velocity_delay_s" else -a.delay_s
        a = _kinematic_reading(mfit, cand, x)
        if abs(a.delay_s) < 0.1 * a.sigma_s:
            break
    bent = cand.field == "velocity_delay_s" and not a.a_delay
    return (
        x,
        a.sigma_s,
        {
            "ok": not bent,
            "reason": _bent_reason(a) if bent else "",
            "significant": first.significant,
            "delay_before_s": float(first.delay_s),
            "delay_after_s": float(a.delay_s),
            "uncertainty_s": float(anchor.Z95 * a.sigma_s),
            "sigma_after_s": a.sigma_s,
            "band_hz": list(a.band_hz),
        },
    )


def _bent_reason(a) -> str:
    from sim.calibrate.anchor import Z95

    return (
        "the velocity's phase against the displacement is not a delay's: a line through it meets 0 Hz "
        f"at {a.offset_rad:+.4f} +/- {Z95 * a.offset_sigma_rad:.4f} rad (a filtered velocity, not a skewed one)"
    )


def _kinematic_reading(mfit, cand: Candidate, x: float):
    """The anchor (:func:`sim.calibrate.anchor.measure`) of the runs with ``cand`` at
    ``x``: the acceleration against the re-read displacement, or the re-read velocity
    against the displacement."""
    from sim.calibrate import anchor

    def delays(mr) -> list:
        return [cand.state(mr.extra["timing"], x).get(k, 0.0) for k in MOTION_FIELDS]

    if cand.field == "velocity_delay_s":  # the velocity re-read, against the displacement as the runs read it
        runs = [dataclasses.replace(mr, v=shift(mr.extra["motion"][1], -sum(delays(mr)), mr.dt)) for mr in mfit]
        return anchor.measure(runs, anchor.velocity_bins)
    # the displacement re-read (the anchor reads no velocity)
    return anchor.measure(
        [dataclasses.replace(mr, u=shift(mr.extra["motion"][0], -delays(mr)[0], mr.dt)) for mr in mfit]
    )


def _displacement_reading(cand: Candidate, kin: dict, check) -> tuple[float, dict]:
    """The acceleration's delay as the displacement reads it (absolute, s) and that
    reading's check, read again with the acceleration aligned by the last reading: a
    record's changing envelope biases a phase read across a lag in proportion to the lag
    (unaligned, the lab example's 9.77 ms read 6.4 ms; and a lag of two samples wraps the
    phase of the top bins: +/-0.74 ms then for +/-0.02 aligned, at 204.8 Hz)."""
    x_kin = cand.neutral + kin["delay_before_s"]
    for _ in range(ANCHOR_PASSES):
        k1 = check(x_kin)
        x_kin += k1["delay_after_s"] or 0.0
        if abs(k1["delay_after_s"] or 0.0) < 0.1 * k1["sigma_after_s"]:
            break
    return x_kin, check(x_kin)


def kinematic_check(cand: Candidate, x: float, before, after) -> dict | None:
    """What the displacement says of a timing candidate (:mod:`sim.calibrate.anchor`):
    the force balance sees only the skew between the force and the acceleration; the
    displacement tells which of the two is off. The acceleration's delay against the
    displacement at the current timing (``before``: the runs) and at the candidate's
    (``after()``: the runs re-timed to ``x``, made only for a candidate of the
    acceleration). A candidate of the acceleration's timing passes when the displacement
    corroborates it (:func:`sim.calibrate.anchor.corroborates`);
    one of the force's delay is refused while the displacement puts the acceleration off
    its chain on the side of the same skew (the acceleration's timing is settled first).
    None for a candidate the anchor cannot judge: no coherent band (a motion too small
    for the displacement sensor), where the balance alone decides as before."""
    import dataclasses as dc

    from sim.calibrate import anchor

    if cand.field == "force_gain":  # a gain, not a timing: the displacement has nothing to say
        return None
    a0 = anchor.measure(before)
    if not math.isfinite(a0.delay_s):  # no band where both hold the motion: the balance alone decides
        return None
    if cand.where == "channel:table_acceleration":
        a1 = anchor.measure(after())
        ok, why = anchor.corroborates(a0, a1, DISPLACEMENT_SKEW_SAMPLES * before[0].dt)
    elif cand.where == "channel:actuator_force":
        mirror = cand.neutral - x  # the force read dx later is the acceleration read dx earlier
        a1 = dc.replace(a0, delay_s=a0.delay_s - mirror)
        ok = not (a0.significant and mirror * a0.delay_s > 0)
        why = (
            ""
            if ok
            else f"the displacement puts the acceleration {a0.text()} off its chain, on this skew's side: its timing first"
        )
    else:
        return None

    def num(v):
        return float(v) if math.isfinite(v) else None

    return {
        "ok": ok,
        "reason": why,
        "significant": a0.significant,
        "delay_before_s": num(a0.delay_s),
        "delay_after_s": num(a1.delay_s),
        "uncertainty_s": num(anchor.Z95 * a0.sigma_s),
        "sigma_s": a0.sigma_s,
        "sigma_after_s": a1.sigma_s,
        "band_hz": list(a0.band_hz),
    }


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


def _uncertainty(cand, x, s) -> dict:
    if cand.field == "accel_lowpass_hz":  # delta method from 1/cut-off to the cut-off
        return {"cutoff_hz": Z95 * s / x**2 if x > 0 else math.inf}
    return {cand.param: Z95 * s}


def _param_check(cand, x, s) -> tuple[bool, str]:
    """Off its bounds, a finite interval, the declared value outside it; a gain beyond a
    transducer's tolerance."""
    from sim.calibrate.pathjudge import within_tolerance

    if not math.isfinite(s):
        return False, f"{cand.param}: no finite confidence interval"
    span = cand.hi - cand.lo
    if x - cand.lo <= 1e-3 * span or cand.hi - x <= 1e-3 * span:
        return False, f"{cand.param} at the edge of its searched range"
    if abs(x - cand.neutral) <= Z95 * s:
        what = "the declared conditioner" if cand.field == "accel_lowpass_hz" else f"{cand.neutral:g} {cand.unit}"
        return False, f"{cand.param}: its 95 % interval holds {what}"
    why = within_tolerance(x) if cand.field == "force_gain" else ""
    return not why, why


def _accelerometer_reads_true(mfit) -> tuple[bool, str]:
    """Whether the balance's scale is the load cells': a gain of the accelerometers scales
    its inertial force alike (on NEES-UCSD records an accelerometer 4 % high was taken as
    load cells 4 % low, then a specimen's mode and more made up the friction that gain
    scaled). The velocity reads the acceleration's own gain
    (:func:`sim.calibrate.anchor.balance_acceleration_gain`): where that leaves out 1 by more
    than a transducer's tolerance the accelerometer is the one off, and the later path
    compares it alone."""
    from sim.calibrate.anchor import balance_acceleration_gain
    from sim.calibrate.pathjudge import GAIN_TOLERANCE

    g, s = balance_acceleration_gain(mfit)
    if math.isfinite(g) and abs(g - 1.0) > max(Z95 * s, GAIN_TOLERANCE):
        return (
            False,
            f"the velocity reads the accelerometer at a gain of {g:.4f} +/- {Z95 * s:.4f}: its gain, not the load cells'",
        )
    return True, ""


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
        entry["parameters"], entry["uncertainty"] = cand.value(x), _uncertainty(cand, x, s)
    return mfit, mho


def _held_to_the_displacement(entry: dict, x: float, s: float, dt: float) -> tuple[float, float]:
    """``(x, s)`` of a refitted acceleration delay, or the displacement's reading of it
    where the refit moves it out of their agreement at acceptance (:func:`placed`): the
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


def round_candidates(mfit, mho, cur, e_ho, flat, margin, effects, done) -> list:
    """Every timing candidate not yet accepted (``done``: effects_added entries) and
    allowed by ``effects`` (None: all), fitted and judged against the current fit."""
    have = {(d["name"], d["where"]) for d in done}
    out = []
    for cand in candidates(mfit):
        if (cand.name, cand.where) in have or (effects and cand.name not in effects):
            continue
        first = _kinematic_reading(mfit, cand, cand.neutral) if cand.read_by_kinematics else None
        if first is not None and not first.significant:
            continue  # the two sensors of the motion agree: nothing to time
        out.append(evaluate(mfit, mho, cur, cand, e_ho, flat, margin, first))
    return out


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
    (:func:`placed`), which its later refits are held to."""
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
    "kinematic_check",
    "placed",
    "evaluate",
    "prefilter_of",
    "refit_accepted",
    "retime",
    "search",
    "settled",
    "shift",
    "sigma",
    "without",
]
