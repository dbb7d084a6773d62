"""What the displacement says of a sensor-timing candidate on the mechanical path.

The force balance sees only the skew between the force and the acceleration; which of
the two is late is told by the displacement (:mod:`sim.calibrate.anchor`): a candidate
of the acceleration's timing must be corroborated by it (:func:`kinematic_check`), a
force delay waits while it puts the acceleration off its chain on the same side, an
acceleration delay the balance finds but the displacement puts elsewhere is judged at
the displacement's value (:func:`placed`), and the motion's own skew is the delay at
which the displacement and the acceleration agree (:func:`read_by_kinematics`). The
candidates, their fit and their judgement are :mod:`sim.calibrate.timing`'s.
"""

from __future__ import annotations

import dataclasses
import math

from sim.calibrate.conditioning import shift
from sim.calibrate.timing import ANCHOR_PASSES, DISPLACEMENT_SKEW_SAMPLES, MOTION_FIELDS, Z95, Candidate, retime, sigma


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
    if kin is None or not kin["significant"] or cand.field != "accel_delay_s":
        return x, s, kin
    if not skew and not abs(kin["delay_before_s"]) > DISPLACEMENT_SKEW_SAMPLES * mfit[0].dt:
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

    first = a = first if first is not None else kinematic_reading(mfit, cand, cand.neutral)
    x = cand.neutral
    for _ in range(ANCHOR_PASSES):
        if not math.isfinite(a.delay_s):
            return x, math.inf, None
        # the acceleration read early against the displacement: the displacement late; the
        # velocity read late against the displacement: the velocity late
        x += a.delay_s if cand.field == "velocity_delay_s" else -a.delay_s
        a = kinematic_reading(mfit, cand, x)
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


def kinematic_reading(mfit, cand: Candidate, x: float):
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


def off_its_chain(cand: Candidate, x: float, kin: dict | None, dt: float) -> bool:
    """Whether the displacement reads the motion's sensors apart by more than a recorder's
    scan (:data:`~sim.calibrate.timing.DISPLACEMENT_SKEW_SAMPLES`) and ``cand`` at ``x`` is
    what puts them back: the motion's own delay read by the kinematics beyond that, or a
    timing of the acceleration the displacement corroborates (:func:`kinematic_check`)
    where it reads the acceleration that far off its chain. Such a candidate needs no
    held-out margin and the residual need not whiten (its value is measured by the
    kinematics, not fitted to the residual), and it goes in before any law
    (:func:`sim.calibrate.mechjudge.split_at_timing`): a law fitted on records whose
    acceleration is off its chain keeps what it took. The worked example's accelerometer 3
    samples early (14.6 ms at 204.8 Hz, read -14.628 +/- 0.029 ms): its delay gained 5.5 %
    held out in the first round, refused by the whiteness rule, then a specimen's mode and a
    power-law damping were fitted on the mistimed records and the delay gained 4.3 % (42 %
    held out at the end). NEES-UCSD records with the displacement 2 samples early and 8 t
    added took the mass 3.9 % low while the motion's delay moved the held-out error by 1.7 %."""
    half = DISPLACEMENT_SKEW_SAMPLES * dt
    if cand.read_by_kinematics:
        return abs(x - cand.neutral) > half
    if cand.where != "channel:table_acceleration" or kin is None or not kin["ok"] or not kin["significant"]:
        return False
    return abs(kin["delay_before_s"] or 0.0) > half


__all__ = ["kinematic_check", "kinematic_reading", "off_its_chain", "placed", "read_by_kinematics"]
