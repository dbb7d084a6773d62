"""Candidates of the replay and closed-loop paths, screened by sensitivity, refined by
nonlinear least squares.

A candidate is one registered effect type at one place of the table: the hydraulic
effects (:mod:`sim.effects.hydraulic`) at each actuator and each class (the supply drop
at the supply), the mechanical effects with a coefficient that vanishes (spring,
viscous damping, power-law damping, Coulomb friction, added mass) at each DOF, actuator
and class, a specimen's modes (``payload_mode`` at each translational DOF: no modal mass
is its neutral value, its frequency scanned, :func:`mode_candidates`), and the sensor effects (:mod:`sim.effects.sensors`: gain, offset, delay,
low-pass) on each compared channel and on each of its columns (what part of a load
cell's offset an over-actuated table's replay can tell: :func:`internal_force_part`).

*Screening* (:func:`screen`): from the current model (parameters at their *neutral*
value, where the effect changes nothing: a flow-gain factor of 1, the description's
bulk modulus, no delay, zero force), one short replay per parameter with the parameter
stepped gives the sensitivity ``S`` of the compared channels; the linearised least
squares ``r0 + S d = min`` gives the step ``d`` and the share of the residual it
explains (the score). Sensor candidates need no replay: the sensor acts on the
model's channels after the fact; they are also scored by the share of the residual of
the columns they act on (``Screen.own``: one column of the 18 of a 6-DOF table is a
small share of the whole). *Refinement* (:func:`refine_job`): the best few,
``scipy.optimize.least_squares`` from the linearised estimate on longer windows (both
chosen by the excitation they hold: :func:`sim.calibrate.windows.choose`)
(Jacobian by the same finite steps; a valve delay, realised as whole physics steps,
by a scan of its grid), with the covariance ``(J^T J)^-1 Omega (J^T J)^-1`` at the
solution, ``Omega`` from the residual's autocorrelation within each compared column of
each window (:func:`sim.calibrate.hac.hac_sigma`: the residual is coloured, so
``s^2 (J^T J)^-1`` would be too narrow).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sim.calibrate.candidate import Candidate
from sim.calibrate.sensorcands import acts_on, sensor_candidates, sensor_model

#: mechanical effect types tried on these paths: coefficient key, and shape keys held
#: at a start value during the screening (freed in the refinement)
MECHANICAL = {
    "spring": ("stiffness_n_m", {}),
    "viscous_damping": ("damping_n_s_m", {}),
    "coulomb_friction": ("force_n", {}),
    "added_mass": ("mass_kg", {}),
    # assumed: alpha starts at 0.5, the NEES-UCSD table's value (docs/uniaxial.md), refined freely
    "power_damping": ("coefficient", {"exponent": 0.5}),
}
HYDRAULIC = (
    "valve_delay",
    "valve_bandwidth",
    "valve_flow_gain",
    "valve_null_offset",
    "bulk_modulus",
    "leakage",
    "supply_pressure_drop",
)
#: the foundation mode's softest frequency searched (Hz): below the runs' band (1-30 Hz on
#: the CGS tests) a reaction mass on its soil is no longer a foundation but another table mode
FOUNDATION_MIN_HZ = 1.0
#: the foundation mode's line search: frequencies from twice the reference down to
#: FOUNDATION_MIN_HZ, this ratio apart. A mode inside the runs' band is a resonance the
#: linearisation at the rigid foundation does not see (a 12 Hz one on CGS: its estimate
#: pointed to the rigid bound, and 21-60 Hz fit worse than none); measured on CGS: the
#: refinement from the nearest point of this grid reaches 12 Hz and 20 Hz
FOUNDATION_LINE_RATIO = 2.0**0.25
#: fit the foundation's damping ratio as a second parameter (from the declared value; the
#: screening steps only the frequency), else hold it at the description's value
FOUNDATION_FIT_DAMPING = True
#: a specimen's mode (``payload_mode``) on these paths: at most this many at one DOF (a
#: second one in a later round, as the mechanical path's law)
MODE_REPEATS = 3
#: its screening scans the frequency on a grid this ratio apart (12 %: a 5 % damped mode's
#: half-power band is +/- 5 %, so the nearest point is within about one band of it) from
#: MODE_MIN_HZ up to MODE_MAX_SHARE x the record rate (and MODE_MAX_HZ), the damping ratio
#: held at MODE_DAMPING (freed in the refinement): at its neutral value (no modal mass) a
#: mode changes nothing, so a linearisation there sees no frequency (as the foundation's)
MODE_LINE_RATIO = 2.0 ** (1.0 / 6.0)
MODE_MIN_HZ = 1.0
MODE_MAX_HZ = 60.0
MODE_MAX_SHARE = 0.4
#: assumed: 3 %, the middle of the mechanical path's damping grid (steel and RC specimens 1-5 %)
MODE_DAMPING = 0.03
#: the mode's frequency is fitted as log(f) (steps of this, relative) and its damping
#: ratio within these bounds (the mechanical law's scan limits: below 0.05 % no record
#: resolves the band, above 1 nothing rings)
MODE_LOG_STEP = 0.03
MODE_DAMPING_BOUNDS = (0.0005, 1.0)
#: the force a mechanical candidate's screening step adds: this share of the mean
#: actuator's capability A_a p_s (assumed: 1 %, the order of the seal friction of a
#: servo-actuator, docs/effects.md; large enough to stand above round-off, small enough
#: to stay linear)
FORCE_STEP = 0.01


# ------------------------------------------------------------------ the candidates
@dataclass
class _Table:
    """What the candidates of a table are built from: the current model's description,
    hydraulics and step, the force step of the screening, the places, and the filter."""

    cur: object
    hp: object
    dt: float
    Fs: float
    hyd_places: list
    mech_places: list
    want: set | None
    have: set

    def spec(self, t, k):
        from sim.effects.base import EFFECTS

        u, lo, hi, _d = EFFECTS[t].SPEC[k]
        return u, lo, hi

    def offered(self, t) -> bool:
        """An effect type the registry holds and the search was asked for."""
        from sim.effects.base import EFFECTS

        return t in EFFECTS and not (self.want and t not in self.want)


def _table_of(desc, payload, accepted, effects) -> _Table:
    """The current model (the description with ``accepted`` in) as a :class:`_Table`."""
    from mjcf.description import parse_table
    from sim.calibrate.paths import build_order
    from sim.calibrate.residuals import distinct_force_places
    from sim.effects.registry import hydraulics_with
    from sim.loop.simulation import table_model

    raw = dict(desc.raw)
    raw["effect"] = build_order(list(raw.get("effect", [])) + [dict(e) for e in accepted])
    cur = parse_table(raw, src=desc.source)
    tm = table_model(cur, payload)  # at the physics step of the replays (a valve delay's grid)
    hp = hydraulics_with(cur, tm.effects)
    cap = float(np.mean(hp.area_a_m2)) * hp.supply_pressure_pa
    names = list(cur.actuator_names)
    classes = sorted({a.cls.name for a in cur.actuators})
    own = [f"class:{c}" for c in classes] + ([f"actuator:{a}" for a in names] if len(names) > 1 else [])
    # all at once (several classes): a description's number (oil, valve) wrong on every one
    hyd_places = (["actuators"] if len(classes) > 1 else []) + own
    # the supports: their air springs and pistons' friction; their shoes: the shoes' friction
    sup = ["supports", "shoes"] if cur.supports is not None else []
    mech_places = distinct_force_places(cur, [f"dof:{d}" for d in cur.dofs] + own + sup)
    want = set(effects) if effects else None
    have = {(e["type"], e["where"]) for e in accepted}
    return _Table(cur, hp, float(tm.model.opt.timestep), FORCE_STEP * cap, hyd_places, mech_places, want, have)


def candidates(desc, payload, prs, accepted, motion_rms, effects=None, undeclared=False) -> list[Candidate]:
    """Every candidate of the library on this table for the compared channels of ``prs``;
    ``accepted``: entries already added (their parameters are the new neutral values);
    ``motion_rms``: place -> (u, v, a) RMS of the recorded motion (mechanical steps);
    ``effects``: only these types (None: all); ``undeclared``: ``--payload none``."""
    from sim.effects.base import EFFECTS

    tb = _table_of(desc, payload, accepted, effects)
    out = _hydraulic_candidates(tb) + _mechanical_candidates(tb, motion_rms)
    if tb.offered("foundation_mode") and ("foundation_mode", "table") not in tb.have:
        out.append(foundation_candidate(tb.cur, tb.dt))
    if "payload_mode" in EFFECTS and ("payload_mode" in tb.want if tb.want else _rigid(payload) or undeclared):
        # where a specimen may be flexible (a declared rigid payload, --payload none) or when
        # named: not on every bare table, nor after the mechanical path, which looks for it
        out += mode_candidates(tb.cur, payload, accepted, motion_rms, tb.Fs, 1.0 / prs[0].dt)
    return out + sensor_candidates(tb, prs)


def _hydraulic_candidates(tb: _Table) -> list[Candidate]:
    """The valve, oil, leakage and supply candidates at each hydraulic place."""
    from sim.effects.base import EFFECTS
    from sim.effects.hydraulic import actuator_indices

    class _W:  # an effect-like object for actuator_indices
        def __init__(self, where):
            self.where, self.source = where, "candidate"

    out, hp, dt, have, hyd_places, spec = [], tb.hp, tb.dt, tb.have, tb.hyd_places, tb.spec
    for t in HYDRAULIC:
        if not tb.offered(t):
            continue
        for w in ["supply"] if t == "supply_pressure_drop" else hyd_places:
            if (t, w) in have:
                continue
            idx = actuator_indices(_W(w), hp) if w != "supply" else None
            key = next(iter(EFFECTS[t].SPEC))
            unit, lo, hi = spec(t, key)
            grid = None
            if t == "valve_delay":
                x0, h, grid = float(np.mean(hp.per_actuator("valve_delay_s")[idx])), 2 * dt, dt
            elif t == "valve_bandwidth":
                arr = (
                    hp.per_actuator("valve_natural_frequency_hz")
                    if hp.model == "second"
                    else 1.0 / (2 * math.pi * hp.per_actuator("valve_tau_s"))
                )
                x0 = float(np.mean(arr[idx]))
                h = 0.1 * x0
            elif t == "valve_flow_gain":
                x0, h = 1.0, 0.05
            elif t == "valve_null_offset":
                x0, h = float(np.mean(hp.per_actuator("valve_null_offset")[idx])), 2e-3
            elif t == "bulk_modulus":
                # stepped down by 20 %: air and hoses lower the effective value, never raise it,
                # and the oil-column frequency moves far with it (a secant reaches further)
                x0 = float(np.mean(hp.per_actuator("chamber_bulk_modulus_pa")[idx]))
                h = -0.2 * x0
            elif t == "leakage":
                x0 = float(np.mean(hp.leakage_cross_m3_s_pa[idx]))
                # a step that leaks 1 % of rated flow at the supply pressure
                h = 0.01 * hp.rated_flow_m3_s / hp.supply_pressure_pa
            else:  # supply_pressure_drop: the supply stays above the return / accumulator precharge
                x0, h = 0.0, 0.05 * hp.supply_pressure_pa
                floor = max(hp.return_pressure_pa, hp.accumulator_precharge_pa if hp.accumulator_volume_m3 > 0 else 0.0)
                hi = min(hi, hp.supply_pressure_pa - floor - h)
            out.append(
                Candidate(
                    t,
                    w,
                    (key,),
                    np.array([x0]),
                    np.array([h]),
                    np.array([lo]),
                    np.array([hi]),
                    {key: unit},
                    grid=grid,
                )
            )
    return out


def _mechanical_candidates(tb: _Table, motion_rms) -> list[Candidate]:
    """The force laws at each mechanical place they act at, stepped by the recorded motion there."""
    from sim.effects.base import EFFECTS

    out, have, Fs, spec = [], tb.have, tb.Fs, tb.spec
    for t, (key, shape) in MECHANICAL.items():
        if not tb.offered(t):
            continue
        for w in tb.mech_places:
            if (t, w) in have or w not in motion_rms or w.partition(":")[0] not in EFFECTS[t].places:
                continue
            u, v, a = motion_rms[w]
            ref = {"stiffness_n_m": u, "damping_n_s_m": v, "force_n": 1.0, "mass_kg": a, "coefficient": math.sqrt(v)}
            if ref[key] <= 0:
                continue
            keys = (key,) + tuple(shape)
            units, lo, hi = {}, [], []
            for k in keys:
                un, l_, h_ = spec(t, k)
                units[k] = un
                lo.append(l_)
                hi.append(h_)
            out.append(
                Candidate(
                    t,
                    w,
                    keys,
                    np.array([0.0] + list(shape.values())),
                    np.array([Fs / ref[key]] + [0.1] * len(shape)),
                    np.array(lo),
                    np.array(hi),
                    units,
                )
            )
    return out


def foundation_candidate(desc, dt: float, fit_damping: bool | None = None) -> Candidate:
    """The foundation mode (``where = "table"``) as a candidate whose screened parameter is
    neutral at the declared model: the compliance ``s = (f_ref / f)^2`` of the reaction
    mass's spring (``f_ref``: the description's ``[foundation] frequency_hz``, x; on CGS
    30 Hz, assumed), ``s = 0`` a rigid (fixed) foundation, ``s = 1`` a declared spring
    foundation. Below the mode the foundation's motion under the actuator forces goes as
    ``s``, so the screening's linearisation holds near the neutral value. The damping ratio
    is a second parameter (``fit_damping``, default :data:`FOUNDATION_FIT_DAMPING`), from
    the description's value (not screened: at ``s = 0`` it changes nothing); the mass is
    held at the description's ``[foundation] mass_kg``: a reaction mass's weight is known
    from its drawings (CGS 6400 t, Sec. 2 of [Airouche 2014]), its soil spring is not (and the mode's
    frequency and mass are not told apart by the motion alone). Searched from
    :data:`FOUNDATION_MIN_HZ` up to ``1 / (2 pi dt)``: a spring of frequency f is integrated
    explicitly (MuJoCo's implicitfast treats damping, not stiffness, implicitly) and is
    stable for ``2 pi f dt < 2`` (measured on CGS at dt = 1/2048 s: 660 Hz ran, 700 Hz
    diverged at once); half that margin, and a 326 Hz foundation already changes the
    replay's NRMSE by less than 1e-6."""
    fo = desc.foundation
    spring = fo.mode == "spring"
    f_ref = float(fo.frequency_hz[0])
    fz = float(fo.frequency_hz[2])
    f_max = 1.0 / (2 * math.pi * dt)
    s0 = 1.0 if spring else 0.0
    z0 = float(fo.damping_ratio[0])
    fit_damping = FOUNDATION_FIT_DAMPING if fit_damping is None else fit_damping
    held = {"mass_kg": float(fo.mass_kg)} | ({} if fit_damping else {"damping_ratio": z0})
    extra = 1 if fit_damping else 0  # the damping ratio: from the declared value, in [0, 1] (an underdamped mode)
    return Candidate(
        "foundation_mode",
        "table",
        ("frequency_hz",) + ("damping_ratio",) * extra,
        np.array([s0] + [z0] * extra),
        np.array([0.25] + [0.01] * extra),  # from rigid: a foundation at 2 f_ref (60 Hz on CGS), above the band
        np.array([min(s0, (f_ref / f_max) ** 2) if spring else (f_ref / f_max) ** 2] + [0.0] * extra),
        np.array([(f_ref / FOUNDATION_MIN_HZ) ** 2] + [1.0] * extra),
        {"frequency_hz": "Hz", "frequency_z_hz": "Hz", "mass_kg": "kg", "damping_ratio": "1"},
        line=tuple((f_ref / f) ** 2 for f in _geometric(2.0 * f_ref, FOUNDATION_MIN_HZ, FOUNDATION_LINE_RATIO)),
        ref={"f_ref": f_ref, "fz_ref": fz if spring and abs(fz - f_ref) > 1e-9 * f_ref else None, "held": held},
    )


def _rigid(payload) -> bool:
    from mjcf.description import RigidPayload

    return isinstance(payload, RigidPayload)


def mode_candidates(desc, payload, accepted, motion_rms, force_step: float, fs: float) -> list[Candidate]:
    """A specimen's mode (``payload_mode``) at each translational DOF ``dof:x|y|z`` of the
    table, while it holds fewer than :data:`MODE_REPEATS` of them. Internal parameters
    (modal mass kg, log frequency, damping ratio); neutral: no modal mass.

    * A declared rigid payload (:class:`mjcf.description.RigidPayload`) that is flexible:
      the modal mass is taken out of it (``from_payload``: the table carries the same
      weight, :class:`sim.effects.specimen.PayloadMode`), from 0 up to what is left of
      its mass after the modes already accepted; the mode at its centre of gravity.
    * Otherwise (no payload, or one declared flexible): an added modal mass from 0,
      unbounded (a specimen's modal mass may exceed the platen's: no plausibility bound).

    The screening scans the frequency (:data:`MODE_LINE_RATIO` apart, ``scan``), the mass
    stepped by the force step's worth of the place's recorded acceleration (as
    ``added_mass``); the refinement fits all three."""
    from mjcf.description import RigidPayload

    rigid = isinstance(payload, RigidPayload)
    # the current model's modes: those accepted here and those of an earlier path (in ``desc``)
    modes = [e for e in desc.raw.get("effect", []) if e.get("type") == "payload_mode"]
    own = [(e["where"], float(e["mass_kg"])) for e in modes if e.get("from_payload")]
    f_hi = min(MODE_MAX_HZ, MODE_MAX_SHARE * fs)
    freqs = _geometric(f_hi, MODE_MIN_HZ, MODE_LINE_RATIO)
    out = []
    for d in ("x", "y", "z"):
        w = f"dof:{d}"
        n_have = sum(1 for e in modes if e.get("where") == w)
        m_max = _mass_left(float(payload.mass_kg), own, w) if rigid else math.inf
        if d not in desc.dofs or w not in motion_rms or n_have >= MODE_REPEATS or m_max <= 0:
            continue
        a = motion_rms[w][2]
        if a <= 0:
            continue
        dm = min(force_step / a, 0.5 * m_max)
        out.append(
            Candidate(
                "payload_mode",
                w,
                ("mass_kg", "frequency_hz", "damping_ratio"),
                np.array([0.0, math.log(freqs[len(freqs) // 2]), MODE_DAMPING]),
                np.array([dm, MODE_LOG_STEP, 0.1 * MODE_DAMPING]),
                np.array([1e-6 * dm, math.log(0.5 * MODE_MIN_HZ), MODE_DAMPING_BOUNDS[0]]),
                np.array([m_max, math.log(0.45 * fs), MODE_DAMPING_BOUNDS[1]]),
                {"mass_kg": "kg", "frequency_hz": "Hz", "damping_ratio": "1"},
                fixed={"from_payload": True} if rigid else {},
                scan=tuple(np.array([0.0, math.log(f), MODE_DAMPING]) for f in freqs),
            )
        )
    return out


def _mass_left(total: float, own: list, where: str) -> float:
    """The largest modal mass a new mode at ``where`` may take from a payload of ``total``
    kg whose ``own`` modes (``[(where, kg)]``) already use some
    (:func:`sim.effects.specimen.payload_taken`): the first mode at a DOF joins the part
    the first modes share (only what the later modes took is gone), a later mode at a DOF
    takes its own part."""
    from sim.effects.specimen import payload_taken

    if any(w == where for w, _ in own):
        return total - payload_taken(own)
    seen, later = set(), 0.0
    for w, m in own:
        later += m if w in seen else 0.0
        seen.add(w)
    return total - later


def _geometric(hi: float, lo: float, ratio: float) -> list:
    out = [hi]
    while out[-1] / ratio >= lo:
        out.append(out[-1] / ratio)
    return out


def internal_force_part(desc) -> np.ndarray:
    """(n_act, n_act) projector onto the actuator forces that move nothing (``J^T f = 0``,
    ``J`` the kinematic Jacobian at home): zero for a table with no more actuators than the
    rank of its Jacobian; rank 6 on CGS (12 actuators, 6 DOF).

    A constant load-cell offset ``o`` (n_act) splits into this internal part ``P o`` and
    the rest, a net wrench on the platen that the recorded motion contradicts. The internal
    part reads like a constant internal force, which the replay (open loop, the hydraulics
    reset at rest, the valve nulls' internal part held by the recorded commands,
    :func:`sim.calibrate.valve_null.stroke_velocity`) starts at zero and keeps: a record
    that starts from rest (as the simulated ones here) tells it apart; a record that starts
    holding an internal force (a real table whose force-balance loop has settled) does not:
    there the static internal part of the load-cells' offsets and that initial force are
    one unknown. Measured in docs/calibration.md (issue #13)."""
    from sim.calibrate.valve_null import internal_basis

    N = internal_basis(desc)  # the same subspace: force f with J^T f = 0 <=> f orthogonal to range(J)
    return N @ N.T


# ------------------------------------------------------------------ screening
@dataclass
class Screen:
    cand: Candidate
    score: float  # share of the residual sum of squares the linearised fit explains
    theta: np.ndarray  # the linearised estimate (clipped into the bounds)
    ok: bool = True
    #: a sensor candidate's share of the residual of the columns it acts on (None: not a sensor)
    own: float | None = None
    #: a candidate with a ``scan``: the linearised estimate from each of its points that
    #: moves the stepped parameters into their range (the line search's points)
    estimates: list = field(default_factory=list)


def linear_fit(r0, S) -> tuple[np.ndarray, float]:
    """Step ``d`` minimising ``|r0 + S d|`` and the share of ``|r0|^2`` it removes."""
    d, *_ = np.linalg.lstsq(S, -r0, rcond=None)
    rr = r0 + S @ d
    den = float(r0 @ r0)
    return d, (1.0 - float(rr @ rr) / den) if den > 0 else 0.0


def _inside(c: Candidate, theta):
    lo = np.where(np.isfinite(c.lower), c.lower + 1e-6 * np.abs(c.step), -np.inf)
    hi = np.where(np.isfinite(c.upper), c.upper - 1e-6 * np.abs(c.step), np.inf)
    return np.clip(theta, lo, hi)


def screen(cands, prs, base_models, ctx, workers=None, say=None, counts=None) -> list[Screen]:
    """Score every candidate by its linearised fit on the windows ``prs`` (model channels
    ``base_models`` from the current model; ``ctx`` = (raw, src, payload, accepted)); the
    replays on the batch route (:func:`sim.calibrate.paths.simulate_many`, ``counts``)."""
    from sim.calibrate.paths import simulate_many, stacked

    raw, src, payload, accepted = ctx
    r0 = stacked(prs, base_models)
    jobs, where = [], []
    for ci, c in enumerate(cands):
        if c.sensor:
            continue
        for bi, base in enumerate(_bases(c)):
            for p in c.screened:
                th = base.copy()
                th[p] += c.step[p]
                for ri, pr in enumerate(prs):
                    jobs.append(pr.job(raw, src, payload, list(accepted) + [c.entry(th)]))
                    where.append((ci, bi, p, ri))
    if say:
        say(f"  screening: {len(jobs)} short replays ({len(prs)} windows of {prs[0].t[-1]:.2f} s) ...")
    models = simulate_many(jobs, workers=workers, counts=counts)
    got: dict = {}
    for (ci, bi, p, ri), m in zip(where, models):
        got.setdefault((ci, bi), {}).setdefault(p, [None] * len(prs))[ri] = m
    out = []
    for ci, c in enumerate(cands):
        if c.scan is not None:
            out.append(_best_of_scan(c, [got[(ci, bi)] for bi in range(len(c.scan))], prs, r0))
            continue
        got_c = got.get((ci, 0), {})
        cols = []
        own = None
        if c.sensor:
            th = c.neutral.copy()
            th[0] += c.step[0]
            stepped = [sensor_model(c, th, pr, m) for pr, m in zip(prs, base_models)]
            r1 = stacked(prs, stepped)
            cols.append((r1 - r0) / c.step[0])
            on = [pr.only(acts_on(c)) for pr in prs]
            if all(p.columns for p in on):
                r0o = stacked(on, base_models)
                own = linear_fit(r0o, ((stacked(on, stepped) - r0o) / c.step[0])[:, None])[1]
        else:
            bad = False
            for p in c.screened:
                r1 = stacked(prs, got_c[p])
                if r1 is None:
                    bad = True
                    break
                cols.append((r1 - r0) / c.step[p])
            if bad:
                out.append(Screen(c, 0.0, c.neutral.copy(), ok=False))
                continue
        S = np.stack(cols, axis=1)
        d, score = linear_fit(r0, S)
        th = c.neutral.copy()
        th[list(c.screened)] += d
        out.append(Screen(c, score, _inside(c, th), own=own))
    return out


def _bases(c: Candidate) -> tuple:
    """The points the screening steps a candidate from: its scan, else its neutral value."""
    return c.scan if c.scan is not None else (c.neutral,)


def _best_of_scan(c: Candidate, got: list, prs, r0) -> Screen:
    """The screening of a candidate with a ``scan`` (a mode's frequencies): the linearised
    fit of the stepped parameters from each point, the best that moves them into their
    range (a mode's mass up from none) kept, its point the estimate's start."""
    from sim.calibrate.paths import stacked

    best = Screen(c, 0.0, c.neutral.copy(), ok=False)
    found = []
    for base, models in zip(c.scan, got):
        rs = [stacked(prs, models[p]) for p in c.screened]
        if any(r is None for r in rs):
            continue
        S = np.stack([(r1 - r0) / c.step[p] for r1, p in zip(rs, c.screened)], axis=1)
        d, score = linear_fit(r0, S)
        th = base.copy()
        th[list(c.screened)] += d
        if np.any(th[list(c.screened)] <= c.neutral[list(c.screened)]):
            continue  # it asks for less than none (a negative modal mass): not this effect
        found.append(_inside(c, th))
        if not best.ok or score > best.score:
            best = Screen(c, score, found[-1])
    best.estimates = found
    return best


# ------------------------------------------------------------------ refinement
@dataclass
class Refined:
    cand: Candidate
    theta: np.ndarray
    sigma: np.ndarray
    rss: float  # |r|^2 on the refinement windows (the pooled NRMSE squared)
    rss0: float
    nfev: int
    ok: bool
    why: str = ""

    @property
    def explained(self) -> float:
        return 1.0 - self.rss / self.rss0 if self.rss0 > 0 else 0.0


def _residual_at(c, theta, prs, base_models, ctx):
    from sim.calibrate.paths import simulate_jobs, stacked

    if c.sensor:
        return stacked(prs, [sensor_model(c, theta, pr, m) for pr, m in zip(prs, base_models)])
    raw, src, payload, accepted = ctx
    return stacked(prs, simulate_jobs([pr.job(raw, src, payload, list(accepted) + [c.entry(theta)]) for pr in prs]))


def _jac(c, theta, r, prs, base_models, ctx):
    cols = []
    for p in range(len(theta)):
        h = 0.5 * c.step[p] if c.grid is None else c.grid
        th = theta.copy()
        th[p] += h
        if np.isfinite(c.upper[p]) and th[p] > c.upper[p]:
            h, th[p] = -h, theta[p] - h
        r1 = _residual_at(c, th, prs, base_models, ctx)
        if r1 is None:  # the stepped model failed (diverged, refused): the other side
            h, th[p] = -h, theta[p] - h
            r1 = _residual_at(c, th, prs, base_models, ctx)
        if r1 is None:
            return None
        cols.append((r1 - r) / h)
    return np.stack(cols, axis=1)


def refine_job(job) -> Refined:
    """Nonlinear least squares of one candidate on the windows (a picklable job:
    ``(cand, theta0, prs, base_models, ctx, max_nfev)``)."""
    from scipy.optimize import least_squares

    c, theta0, prs, base_models, ctx, max_nfev = job
    from sim.calibrate.hac import hac_sigma
    from sim.calibrate.paths import residual_segments, stacked

    r0 = stacked(prs, base_models)
    rss0 = float(r0 @ r0)
    nfev = 0
    cache: dict = {}

    def fun(th):
        nonlocal nfev
        k = tuple(np.round(th, 15))
        if k not in cache:
            nfev += 1
            r = _residual_at(c, np.asarray(th, float), prs, base_models, ctx)
            cache[k] = r if r is not None else np.full_like(r0, 1e3)
        return cache[k]

    if c.grid is not None:  # a delay realised in whole steps: scan the grid around the estimate
        k0 = max(0, int(round(theta0[0] / c.grid)))
        best = None
        for k in range(max(0, k0 - 2), k0 + 3):
            th = np.array([k * c.grid])
            r = fun(th)
            s = float(r @ r)
            if best is None or s < best[0]:
                best = (s, th)
        while True:  # walk on while it improves
            edge = best[1][0] / c.grid
            moved = False
            for k in (int(round(edge)) - 1, int(round(edge)) + 1):
                if k < 0:
                    continue
                th = np.array([k * c.grid])
                s = float(fun(th) @ fun(th))
                if s < best[0]:
                    best, moved = (s, th), True
            if not moved or nfev > max_nfev + 6:
                break
        theta = best[1]
    else:
        lo = np.where(np.isfinite(c.lower), c.lower, -np.inf)
        hi = np.where(np.isfinite(c.upper), c.upper, np.inf)
        x0 = np.clip(theta0, lo + 1e-9 * np.abs(c.step), hi - 1e-9 * np.abs(c.step))

        def jac(th):
            J = _jac(c, np.asarray(th, float), fun(th), prs, base_models, ctx)
            return J if J is not None else np.zeros((len(r0), len(th)))  # no slope: the solver stops here

        sol = least_squares(
            fun,
            x0,
            jac=jac,
            bounds=(lo, hi),
            x_scale=np.abs(c.step),
            max_nfev=max_nfev,
            method="trf",
        )
        theta = sol.x
    r = fun(theta)
    J = _jac(c, theta, r, prs, base_models, ctx)
    if J is None:
        return Refined(c, theta, np.full(len(theta), math.inf), float(r @ r), rss0, nfev, False, "replay diverged")
    # the residual is coloured (anti-alias filter, unmodelled dynamics): the covariance
    # from its autocorrelation within each column of each window (sim.calibrate.hac)
    sigma = hac_sigma(J, r, residual_segments(prs))
    return Refined(c, theta, sigma, float(r @ r), rss0, nfev, True)


__all__ = [
    "HYDRAULIC",
    "MECHANICAL",
    "Refined",
    "Screen",
    "candidates",
    "mode_candidates",
    "foundation_candidate",
    "internal_force_part",
    "refine_job",
    "screen",
]
