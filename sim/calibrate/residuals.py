"""What the declared model does not explain in measured runs: the residuals.

Three paths, chosen by the channels every run has (:func:`choose_path`):

* ``mechanical``: table motion (displacement, velocity, acceleration) and actuator
  forces. The force the declared model needs for the recorded motion, against the
  recorded force, per table DOF (the NEES-UCSD paper's approach, and the only path for
  runs without valve commands). The recorded force in DOF space is ``J^T f`` (``J`` the
  stroke-per-DOF Jacobian of the exact kinematics, :func:`sim.control.tvc.dof_jacobian`);
  the model's is ``M_e a`` (``M_e`` MuJoCo's effective mass matrix of the declared
  table, loops closed, at home: a small-motion linearisation of ``mj_inverse``) plus
  the force of every declared effect whose law :mod:`sim.calibrate.laws` knows. The
  static part is removed per run and DOF (the paper's pressures were high-passed). An
  accelerometer conditioner (``accel_lowpass_hz``) delays the recorded acceleration
  alone; every other term is passed through the same analog filter
  (:class:`sim.calibrate.conditioning.Conditioner`, discretised at 1 kHz or more as
  ``run --measure`` applies it) so the balance stays exact.
  Samples where the table is still (|v| below :data:`sim.calibrate.laws.DEADBAND`, and
  the filter's memory after them) are left out: there the friction force is anything
  within its bounds.
* ``replay``: recorded valve commands, replayed open loop (after removing a valve null
  offset, or a real record drifts to the end stop); ``closed_loop``: only a reference,
  the run through the controller model. Their residuals and search are in
  :mod:`sim.calibrate.paths` and :mod:`sim.calibrate.pathsearch`.

Residuals are per channel, per DOF, in time and frequency (:func:`spectra`, with the
coherence with the states).
"""

from __future__ import annotations

import functools
import math
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from mjcf.builder import SHOE_SLIDE_SHARE
from sim.calibrate.errors import CalibrationError
from sim.calibrate.supports import air_stiffness_per_kg, shoe_jacobian, support_jacobian

MECH_CHANNELS = ("actuator_force", "table_displacement", "table_velocity", "table_acceleration")
#: channels a replay or closed-loop residual can compare (a run needs one of them)
FIT_CHANNELS = ("actuator_force", "table_acceleration", "table_displacement")
PATHS = ("mechanical", "replay", "closed_loop")


#: bytes of the bases of laws with a shape (scanned: a mode's frequency and damping) a run
#: keeps for its re-timed copies and the next rounds' scans (:meth:`MechRun.basis`; a
#: 2.5 s CGS run's payload-mode grids, 288 points at each of 3 DOFs, hold 17 MB); the
#: shapeless ones are all kept
BASIS_BYTES = 32 * 2**20


class BasisCache:
    """A run's law bases by ``(law type, place, shape[, force delay and gain])``
    (:meth:`MechRun.basis`): those of fixed laws (no shape, no load) all, the others (a
    scan's grid, a load's law at each force delay a search tries) up to
    :data:`BASIS_BYTES`, the least recently used dropped first."""

    def __init__(self):
        self.shapeless: dict = {}
        self.scanned: OrderedDict = OrderedDict()
        self.nbytes = 0

    def get(self, key: tuple, make) -> list:
        if not key[2] and len(key) == 3:
            if key not in self.shapeless:
                self.shapeless[key] = make()
            return self.shapeless[key]
        if key in self.scanned:
            self.scanned.move_to_end(key)
            return self.scanned[key]
        bs = make()
        n = sum(b.nbytes for b in bs)
        while self.scanned and self.nbytes + n > BASIS_BYTES:
            _k, old = self.scanned.popitem(last=False)
            self.nbytes -= sum(b.nbytes for b in old)
        self.scanned[key] = bs
        self.nbytes += n
        return bs


@dataclass
class MechRun:
    """One run on the mechanical path (DOF space of the table's own DOFs)."""

    name: str
    dt: float
    dofs: list
    u: np.ndarray  # (n, k) displacement
    v: np.ndarray
    a: np.ndarray
    force: np.ndarray  # (n, k) recorded generalised force J^T f, prefiltered
    model: np.ndarray  # (n, k) declared model's force for the recorded motion, prefiltered
    J: np.ndarray  # (n_act, k)
    actuators: list
    classes: dict  # class name -> actuator indices
    rows: np.ndarray  # bool (n,): samples in the fit
    #: the acceleration's conditioner applied to every other term: a
    #: :class:`sim.calibrate.conditioning.Conditioner` (or a digital filter's (b, a))
    prefilter: object = None
    #: a delay (s) after the prefilter: the acceleration's own sensor delay
    #: (:mod:`sim.calibrate.timing`), applied to every other term as the prefilter is
    filter_delay_s: float = 0.0
    #: the load cells' declared analog conditioner (:func:`sim.calibrate.conditioning.force_chain_of`):
    #: the recorded force went through it, so every force of the model goes through it too
    force_chain: object = None
    t0: float = 0.0
    presliding_m: float | None = None  #: the table's pre-sliding travel, if its dry friction has one
    #: the declared payload's (mass kg, centre of gravity from the reference point m (3,),
    #: gravity m/s^2), None without one (the ``payload`` place of the CG offset's law)
    payload: tuple | None = None
    extra: dict = field(default_factory=dict)
    #: bool (k,): the DOFs the run excites (:func:`excited_dofs`); the others are left out
    #: of the fit's weights and the pooled error, and reported as not excited
    excited: np.ndarray | None = None
    #: (n_sup, k) each static support's vertical travel per DOF (:func:`support_jacobian`),
    #: None on a table without supports
    supports: np.ndarray | None = None
    #: (2 n_sup, k) each support's shoe's x and y slide per DOF (:func:`shoe_jacobian`)
    shoes: np.ndarray | None = None
    #: N/m a static support's air spring gains per kg it carries (:func:`air_stiffness_per_kg`)
    air_per_kg: float = 0.0

    @property
    def residual(self) -> np.ndarray:
        return self.demean(self.force - self.model)

    def demean(self, x: np.ndarray) -> np.ndarray:
        """Static part removed per DOF (mean over the fit rows)."""
        return x - x[self.rows].mean(axis=0)

    def filt(self, x: np.ndarray) -> np.ndarray:
        if callable(self.prefilter):  # the analog conditioner (sim.calibrate.conditioning.Conditioner)
            x = self.prefilter(x)
        elif self.prefilter is not None:  # a digital filter's (b, a)
            import scipy.signal as sig

            x = sig.lfilter(*self.prefilter, x, axis=0)
        if self.filter_delay_s:
            from sim.calibrate.conditioning import shift

            x = shift(x, self.filter_delay_s, self.dt)
        return x

    def chain(self, x: np.ndarray) -> np.ndarray:
        """A force of the model through the load cells' declared conditioner (if any)."""
        return x if self.force_chain is None else self.force_chain(x)

    def place_motion(self, where: str):
        """(u, v, a, map) of a place: its coordinate's motion (n,) and ``map`` (k,) or
        (m, k) that takes its force into DOF space (``payload``: the whole DOF space)."""
        kind, _, name = where.partition(":")
        if kind == "payload" and self.payload is not None:
            return self.u, self.v, self.a, np.eye(len(self.dofs))
        if kind == "dof":
            j = self.dofs.index(name)
            e = np.zeros(len(self.dofs))
            e[j] = 1.0
            return self.u[:, j], self.v[:, j], self.a[:, j], e
        if kind == "actuator":
            i = self.actuators.index(name)
            Ji = self.J[i]
            return self.u @ Ji, self.v @ Ji, self.a @ Ji, Ji
        if kind == "class" or (kind == "supports" and self.supports is not None):
            Jm = self.J[self.classes[name]] if kind == "class" else self.supports  # several strokes at once
            return self.u @ Jm.T, self.v @ Jm.T, self.a @ Jm.T, Jm
        if kind == "shoes" and self.shoes is not None:  # a shoe's force is split over its two slides
            Jm = self.shoes
            return self.u @ Jm.T, self.v @ Jm.T, self.a @ Jm.T, Jm * SHOE_SLIDE_SHARE
        raise CalibrationError(
            f"where = '{where}': the mechanical path acts at dof:, actuator:, class:, supports or shoes places"
            + (" (payload: only with a declared payload)" if kind == "payload" else "")
            + (f" ({kind}: only on a table with [supports])" if kind in ("supports", "shoes") else "")
        )

    def law_motion(self, law, where: str):
        """:meth:`place_motion` for ``law``; a law that acts at the declared payload's centre
        of gravity along the place's DOF (``law.at_payload_cg``: a mode of the payload's own
        mass) gets every DOF's motion and returns its force as a wrench in DOF space."""
        if getattr(law, "at_payload_cg", False) and self.payload is not None:
            return self.u, self.v, self.a, np.eye(len(self.dofs))
        return self.place_motion(where)

    def place_load(self, where: str) -> np.ndarray:
        """The recorded force's magnitude (N) of the actuators of an ``actuator:`` (n,) or
        ``class:`` (n, m) place: the load a seal friction grows with."""
        kind, _, name = where.partition(":")
        f = self.extra["actuator_force"]
        if kind == "actuator":
            return np.abs(f[:, self.actuators.index(name)])
        if kind == "class":
            return np.abs(f[:, self.classes[name]])
        raise CalibrationError(f"where = '{where}': a load is read at actuator: or class: places")

    def actuator_columns(self, where: str) -> list:
        """The actuator indices of a ``class:`` or ``actuator:`` place."""
        kind, name = where.split(":", 1)
        return list(self.classes[name]) if kind == "class" else [self.actuators.index(name)]

    def column(self, law, where: str, shape: dict) -> np.ndarray:
        """(n, k) generalised force of a one-coefficient ``law`` with unit coefficient at ``where``."""
        return self.columns(law, where, shape)[0]

    def second(self, law, where: str, shape: dict, values: dict) -> np.ndarray:
        """(n, k) the law's force of second order in its coefficients (``law.second_order``)
        at ``values``."""
        u, v, a, m = self.place_motion(where)
        b = np.asarray(law.second_order(u, v, a, _law_args(self, shape), values), float)
        Q = b[:, None] * m[None, :] if b.ndim == 1 else b @ m
        return self.chain(Q if law.inertial else self.filt(Q))

    def basis(self, law, where: str, shape: dict) -> list:
        """The law's unfiltered columns (:func:`_raw_columns`), kept in ``extra["basis"]``,
        which the run's re-timed copies share (:func:`sim.calibrate.timing.retime`): they
        depend on the motion and the shape alone (a load's law on the force delay and gain
        too; a law that filters inside is made anew), and a timing search re-times the runs
        at every point, every round scans a mode's grid again."""
        if getattr(law, "filters_inside", False):
            return _raw_columns(self, law, where, shape)
        key = (law.type, where, tuple(sorted(shape.items())))
        if getattr(law, "load", False):
            timing = self.extra.get("timing", {})
            key += (timing.get("force_delay_s"), timing.get("force_gain", 1.0))
        cache = self.extra.setdefault("basis", BasisCache())
        bs = cache.get(key, lambda: _law_basis(self, law, where, shape))
        return _to_dofs(bs, self.law_motion(law, where)[3])

    def columns(self, law, where: str, shape: dict) -> list:
        """One (n, k) generalised force per linear coefficient of ``law`` (unit value) at ``where``."""
        if getattr(law, "model_force", False):  # already through the prefilter and the force chain
            return [self.model]
        if getattr(law, "recorded_force", False):  # the place's share of the recorded force, as read now
            idx = self.actuator_columns(where)
            return [self.filt(self.extra["actuator_force"][:, idx] @ self.J[idx])]
        key = (law.type, where, tuple(sorted(shape.items())))
        cache = self.extra.setdefault("raw_columns", {})
        if key in cache:
            return cache[key]
        Qs = [self.chain(Q if law.inertial else self.filt(Q)) for Q in self.basis(law, where, shape)]
        if len(cache) > 128:  # shape scans make many; the accepted terms' come back
            for k in [k for k in cache if k[2]][:64]:
                del cache[k]
        cache[key] = Qs
        return Qs


def places(desc, kinds, payload: bool = False) -> list[str]:
    """Every place of ``kinds`` on this table (``payload``: with a payload declared, on a
    table that turns: a CG offset shows through rotations)."""
    out = []
    if "payload" in kinds and payload and {"rx", "ry", "rz"} & set(desc.dofs):
        out.append("payload")
    if "dof" in kinds:
        out += [f"dof:{d}" for d in desc.dofs]
    if "actuator" in kinds and len(desc.actuators) > 1:
        out += [f"actuator:{a}" for a in desc.actuator_names]
    if "class" in kinds:
        cl = sorted({a.cls.name for a in desc.actuators})
        if len(cl) > 1:
            out += [f"class:{c}" for c in cl]
    if "supports" in kinds and desc.supports is not None:
        out.append("supports")
    if "shoes" in kinds and desc.supports is not None:
        out.append("shoes")
    return out


def supported_paths(runs) -> list[str]:
    """The residual paths every run supports, in :data:`PATHS` order: mechanical (forces
    and motion), replay (valve commands and an output to compare), closed loop (the
    reference and an output)."""
    have = [{c for c in MECH_CHANNELS + ("valve_command", "reference") if getattr(r, c) is not None} for r in runs]
    outputs = [bool(h & set(FIT_CHANNELS)) for h in have]
    need = {"mechanical": None, "replay": "valve_command", "closed_loop": "reference"}
    out = []
    for path, chan in need.items():
        if chan is None and all(set(MECH_CHANNELS) <= h for h in have):
            out.append(path)
        elif chan is not None and all(chan in h and o for h, o in zip(have, outputs)):
            out.append(path)
    return out


def choose_path(runs) -> str:
    """The residual path every run supports (mechanical first, then replay, then closed
    loop; the last two need a recorded output to compare: force, acceleration or
    displacement)."""
    have = [{c for c in MECH_CHANNELS + ("valve_command", "reference") if getattr(r, c) is not None} for r in runs]
    outputs = [bool(h & set(FIT_CHANNELS)) for h in have]
    if all(set(MECH_CHANNELS) <= h for h in have):
        return "mechanical"
    if all("valve_command" in h and o for h, o in zip(have, outputs)):
        return "replay"
    if all("reference" in h and o for h, o in zip(have, outputs)):
        return "closed_loop"
    for r, h, o in zip(runs, have, outputs):
        if not (set(MECH_CHANNELS) <= h or (o and {"valve_command", "reference"} & h)):
            miss = [c for c in MECH_CHANNELS if c not in h]
            raise CalibrationError(
                f"{r.name}: lacks {', '.join(miss)} (mechanical path)"
                + ("" if o else " and any output to compare a replay with")
                + "; record table motion with actuator forces, or valve commands or the "
                "reference with the force/acceleration/displacement they produced"
            )
    raise CalibrationError(
        f"{runs[0].name}: the runs support different residual paths; calibrate runs that "
        "record the same channels together"
    )


def check_path(runs, path: str) -> str:
    """``path`` if every run has the channels it needs (one-line error naming the first
    run that lacks them)."""
    need = {
        "mechanical": (MECH_CHANNELS, "actuator_force and table displacement, velocity and acceleration"),
        "replay": (("valve_command",), "valve_command and a recorded output (force, acceleration, displacement)"),
        "closed_loop": (("reference",), "the reference and a recorded output (force, acceleration, displacement)"),
    }
    if path not in need:
        raise CalibrationError(f"--path {path}: give one of {', '.join(PATHS)}")
    chans, what = need[path]
    for r in runs:
        miss = [c for c in chans if getattr(r, c) is None]
        if path != "mechanical" and not any(getattr(r, c) is not None for c in FIT_CHANNELS):
            miss.append("any output")
        if miss:
            raise CalibrationError(
                f"{r.name}: lacks {', '.join(miss)} for --path {path}; it needs {what} (or leave --path out)"
            )
    return path


def check_finite(run, channels) -> None:
    for ch in channels:
        arr = getattr(run, ch)
        if arr is None:
            continue
        bad = ~np.isfinite(arr)
        if bad.any():
            k = int(np.argmax(bad.any(axis=1) if arr.ndim > 1 else bad))
            raise CalibrationError(
                f"{run.name}: channel {ch} has NaN/inf (first at sample {k}, t = {run.t[k]:.4f} s); "
                "cut the run or fill the gap before calibrating"
            )


def moving_rows(v: np.ndarray, prefilter, dt: float, trim: float = 0.01) -> np.ndarray:
    """Bool (n,): the samples a fit reads, from the first to the last where the table moves
    (``trim`` of its top speed), less those where it is still (``DEADBAND``) and the
    acceleration conditioner's memory after them: there a dry friction is anything within
    its bounds."""
    speed = np.max(np.abs(v), axis=1)
    n = len(speed)
    keep = np.ones(n, bool)
    on = np.flatnonzero(speed > trim * speed.max()) if speed.max() > 0 else np.array([], int)
    if len(on) >= 16:
        keep[: on[0]] = False
        keep[on[-1] + 1 :] = False
    from sim.calibrate.laws import DEADBAND

    still = speed < DEADBAND
    if prefilter is not None:
        from sim.identify.least_squares import filter_memory_s

        m = int(math.ceil(filter_memory_s(getattr(prefilter, "ba", prefilter), dt) / dt))
        still = np.convolve(still.astype(float), np.ones(m + 1))[:n] > 0
    if np.count_nonzero(keep & ~still) >= 16:
        keep &= ~still
    return keep


def mechanical_runs(runs, desc, payload=None, *, accel_lowpass_hz: float | None = None) -> list[MechRun]:
    """The mechanical-path records of ``runs`` against the declared ``desc`` (+ ``payload``)."""
    from mjcf.description import DOFS6 as DOF6
    from sim.calibrate import conditioning
    from sim.calibrate.flexible import flexible_parts
    from sim.calibrate.laws import declared_forces
    from sim.control.tvc import dof_jacobian
    from sim.effects import build_model

    tm = build_model(desc, payload)
    Me_all = tm.effective_mass_matrix()
    idx6 = [DOF6[j] for j in tm.platen_dof_index]
    k_of = [idx6.index(d) for d in desc.dofs]
    Me = Me_all[np.ix_(k_of, k_of)]
    J6 = dof_jacobian(desc)
    J = J6[:, [DOF6.index(d) for d in desc.dofs]]
    classes: dict = {}
    for i, a in enumerate(desc.actuators):
        classes.setdefault(a.cls.name, []).append(i)
    joints = joint_terms(tm, k_of)
    parts = flexible_parts(tm, k_of)  # what stands on its own joints: not rigid (sim.calibrate.flexible)
    pay = payload_inertial(tm, desc.gravity_m_s2)
    declared = [d for d in (declared_forces(e) for e in desc.effects) if d is not None]
    out = []
    for r in runs:
        check_finite(r, MECH_CHANNELS)
        cols = [r.dofs.index(d) for d in desc.dofs]
        u = r.table_displacement[:, cols]
        v = r.table_velocity[:, cols]
        a = r.table_acceleration[:, cols]
        u, v = conditioning.motion_on_the_force_clock(r, u, v)
        f = _force_at_acceleration_instant(r)
        known = conditioning.declared_state(r, accel_lowpass_hz, desc.accelerometer_filter_order)
        # the motion's own skew beyond what it declares and the load cells' gain (timing.py)
        known.update(motion_delay_s=0.0, velocity_delay_s=0.0, force_gain=1.0)
        pre = conditioning.prefilter_of(known, r)
        mr = MechRun(
            name=r.name,
            dt=r.dt,
            dofs=list(desc.dofs),
            u=u,
            v=v,
            a=a,
            force=np.zeros_like(u),
            model=np.zeros_like(u),
            J=J,
            actuators=list(desc.actuator_names),
            classes=classes,
            rows=np.ones(len(u), bool),
            prefilter=pre,
            force_chain=conditioning.force_chain_of(r),
            presliding_m=desc.friction_presliding_m if desc.friction_model == "presliding" else None,
            payload=pay,
            supports=support_jacobian(desc),
            shoes=shoe_jacobian(desc),
            air_per_kg=air_stiffness_per_kg(desc),
        )
        mr.filter_delay_s = known["accel_delay_s"]
        mr.extra["force_at_instant"] = f  # before any declared or found force delay
        # the load cells' white noise taken to the DOFs, as recorded (sim.calibrate.mechnoise)
        mr.extra["force_noise"] = conditioning.noise_floor(np.asarray(r.actuator_force, float) @ J, 1.0 / r.dt)
        f = conditioning.shift(f, -known["force_delay_s"], r.dt)
        mr.force = mr.filt(f @ J)
        mr.extra["actuator_force"] = f
        mr.extra["declared_other"] = functools.partial(_declared_other, joints=joints, declared=declared)
        other = mr.extra["declared_other"](mr)
        inertial = a @ Me.T if parts is None else a @ Me.T + parts.force(a, r.dt)
        mr.model = mr.chain(inertial + mr.filt(other))
        mr.extra.update(inertial=inertial, other=other, timing=known, basis=BasisCache(), motion=(u, v))
        mr.extra["velocity_derived"] = conditioning.velocity_derived(r)  # no skew of its own (timing.py)
        mr.rows = moving_rows(v, pre, r.dt)
        mr.excited = excited_dofs(mr, J6)
        out.append(mr)
    return out


def _declared_other(mr, joints, declared) -> np.ndarray:
    """(n, k) the declared model's forces other than the inertial ones for ``mr``'s
    recorded motion, unfiltered: its joints' (:class:`JointTerms`) and its effects' laws
    (:func:`sim.calibrate.laws.declared_forces`: laws of one coefficient, first order in it)."""
    other = joints.force(mr.u, mr.v, mr.dt)
    for law, where, vals in declared:
        other = other + sum(vals[k] * Q for k, Q in zip(law.linears, _raw_columns(mr, law, where, vals)))
    return other


def excited_dofs(mr, J6) -> np.ndarray:
    """Bool (k,): the DOFs whose recorded generalised force (static part removed, over the
    fit rows) reaches :data:`sim.calibrate.windows.QUIET_COLUMN` of the largest, a moment
    and a force compared as the actuator forces that make them
    (:func:`sim.calibrate.windows.dof_weights`). A DOF the test does not drive holds
    cross-talk and noise: normalised by its own force its error is noise over nothing
    (rz 220 % on clean 3-axis translational CGS runs, tests/calibrate/test_windows.py)."""
    from sim.calibrate.windows import dof_weights, excited

    F = mr.demean(mr.force)[mr.rows]
    rms = np.sqrt(np.mean(F**2, axis=0)) if len(F) else np.zeros(len(mr.dofs))
    return excited(rms, dof_weights(J6, mr.dofs, "force"))


def _force_at_acceleration_instant(r) -> np.ndarray:
    """The recorded actuator force at the instants of the force that produced the recorded
    acceleration. A simulated run declares ``meta.force_lag_s`` (the loop records the
    pressures at t_k and the acceleration of the physics step leaving t_k, computed from
    the pressures at t_k + h); its force is read at t + lag (cubic spline). Without this
    the force lags the acceleration by 0.49 ms on CGS, a 28 Hz line at the oil-column modes
    holding > 90 % of a clean run's residual (NRMSE 6.9 % instead of 0.7 %). Measured runs
    sample every channel at one instant: no key, no shift."""
    f = r.actuator_force
    lag = float((r.meta or {}).get("force_lag_s") or 0.0)
    if not lag or len(f) < 4:
        return f
    from scipy.interpolate import CubicSpline

    t = np.asarray(r.t, float)
    return CubicSpline(t, f, axis=0)(np.minimum(t + lag, t[-1]))


def _law_args(mr, shape) -> dict:
    s = {**shape, "_presliding_m": mr.presliding_m, "_dt": mr.dt, "_dofs": mr.dofs, "_filt": mr.filt}
    s["_air_per_kg"] = mr.air_per_kg
    if mr.payload is not None:
        s["_payload"] = mr.payload
    return s


def _raw_columns(mr, law, where, shape) -> list:
    """The law's unfiltered DOF-space force per linear coefficient (list of (n, k))."""
    return _to_dofs(_law_basis(mr, law, where, shape), mr.law_motion(law, where)[3])


def _law_basis(mr, law, where, shape) -> list:
    """The law's force at its place per linear coefficient (list of (n,) or (n, m))."""
    u, v, a, _m = mr.law_motion(law, where)
    s = _law_args(mr, shape)
    if getattr(law, "at_payload_cg", False) and mr.payload is not None:
        s["_along"] = where.partition(":")[2]
    if getattr(law, "load", False):
        s["_load"] = mr.place_load(where)
    b = np.asarray(law.basis(u, v, a, s), float)
    return [b] if len(law.linears) == 1 else list(b)


def _to_dofs(bs: list, m: np.ndarray) -> list:
    """A place's forces ``bs`` in DOF space through its map ``m`` (:meth:`MechRun.place_motion`)."""
    return [x[:, None] * m[None, :] if x.ndim == 1 else x @ m for x in bs]


def payload_inertial(tm, g: float):
    """(mass kg, centre of gravity (3,) m from the platen's reference point in its frame,
    ``g``) of the payload bodies the model built (``tm.info.payload_bodies``) at home;
    None without a payload."""
    import mujoco

    names = list(getattr(getattr(tm, "info", None), "payload_bodies", None) or [])
    m = tm.model
    ids = [i for i in (mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, n) for n in names) if i >= 0]
    if not ids:
        return None
    d = tm.new_data()
    mass = np.array([m.body_mass[i] for i in ids], float)
    com = (mass[:, None] * np.array([d.xipos[i] for i in ids])).sum(axis=0) / mass.sum()
    p = int(tm.platen_body)
    R = np.array(d.xmat[p]).reshape(3, 3)
    return float(mass.sum()), R.T @ (com - np.array(d.xpos[p])), float(g)


@dataclass
class JointTerms:
    """The declared model's joint-level forces on the recorded motion, in DOF space:
    every joint's velocity and displacement from the platen's through ``T`` (MuJoCo's
    loop-closed projection at home, the one behind the effective mass), joint springs
    and dampers (``jnt_stiffness``, ``dof_damping``: seal drag, support air springs,
    platen springs), dry friction as MuJoCo's ``frictionloss`` (sign of the joint
    velocity) or the loop's pre-sliding law (Dahl, :func:`sim.effects.registry.dahl_step`,
    integrated along the record). The polytropic air law's departure from its linear
    spring is left out (second order in the support stroke)."""

    T: np.ndarray  # (nv, k)
    K: np.ndarray  # (nv,)
    D: np.ndarray
    FL: np.ndarray  # frictionloss (coulomb model)
    fr_dofs: np.ndarray
    fr_force: np.ndarray
    fr_zss: float
    #: tendons (springs, dampers, frictionloss on a combination of joints, e.g. a free
    #: platen's DOF): (ntendon, k) length per platen DOF, and their coefficients
    TT: np.ndarray | None = None
    tK: np.ndarray | None = None
    tD: np.ndarray | None = None
    tFL: np.ndarray | None = None

    def force(self, u, v, dt) -> np.ndarray:
        out = self._joint_force(u, v, dt)
        if self.TT is not None and len(self.TT):
            ql, qld = u @ self.TT.T, v @ self.TT.T
            ft = ql * self.tK + qld * self.tD + self.tFL * np.sign(qld)
            out = out + ft @ self.TT
        return out

    def _joint_force(self, u, v, dt) -> np.ndarray:
        from sim.calibrate.laws import DEADBAND
        from sim.effects.registry import dahl_step

        T = self.T
        q = u @ T.T
        qd = v @ T.T
        gen = q * self.K + qd * self.D
        if np.any(self.FL):
            gen = gen + self.FL * np.where(np.abs(qd) > DEADBAND * 1e-3, np.sign(qd), 0.0)
        if len(self.fr_dofs):
            z = np.zeros(len(self.fr_dofs))
            Z = np.zeros((len(u), len(self.fr_dofs)))
            vv = qd[:, self.fr_dofs]
            for i in range(len(u)):
                z = dahl_step(z, vv[i], self.fr_zss, dt)
                Z[i] = z
            gen[:, self.fr_dofs] += Z * (self.fr_force / self.fr_zss)
        return gen @ T


def _tendon_jacobian(m, d) -> np.ndarray:
    """The tendons' Jacobian (ntendon, nv), dense: MuJoCo 4 stores ``ten_J`` in its
    compressed-row form (``m.ten_J_rownnz``, ``rowadr``, ``colind``), not ntendon x nv
    (a shear-frame payload's tendons: 8 entries, not 4 x 6)."""
    import mujoco

    J = np.asarray(d.ten_J, float)
    if J.size == m.ntendon * m.nv:
        return J.reshape(m.ntendon, m.nv)
    dense = np.zeros((m.ntendon, m.nv))
    mujoco.mju_sparse2dense(dense, J, m.ten_J_rownnz, m.ten_J_rowadr, m.ten_J_colind)
    return dense


def joint_terms(tm, k_of) -> JointTerms:
    import mujoco

    from mjcf import analysis

    m = tm.model
    d = analysis.at_home(m)
    T = analysis.projection(m, d)[:, k_of]
    K = np.zeros(m.nv)
    for j in range(m.njnt):
        if int(m.jnt_type[j]) in (int(mujoco.mjtJoint.mjJNT_SLIDE), int(mujoco.mjtJoint.mjJNT_HINGE)):
            K[m.jnt_dofadr[j]] = m.jnt_stiffness[j]
    fr_dofs = np.asarray(getattr(tm, "friction_dofs", []), dtype=int)
    fr_force = np.asarray(getattr(tm, "friction_force", []), dtype=float)
    TT = tK = tD = tFL = None
    if m.ntendon:
        TT = _tendon_jacobian(m, d) @ T
        tK = np.array(m.tendon_stiffness, float).reshape(m.ntendon, -1)[:, 0]
        tD = np.array(m.tendon_damping, float).reshape(m.ntendon, -1)[:, 0]
        tFL = np.array(m.tendon_frictionloss, float)
    return JointTerms(
        T=T,
        K=K,
        D=np.array(m.dof_damping, float),
        FL=np.array(m.dof_frictionloss, float),
        fr_dofs=fr_dofs,
        fr_force=fr_force,
        fr_zss=float(getattr(tm, "friction_presliding_m", 1e-4)),
        TT=TT,
        tK=tK,
        tD=tD,
        tFL=tFL,
    )


def nrmse_runs(mruns, residuals, dofs=None) -> float:
    """Pooled NRMSE of ``residuals`` (list of (n, k)) against the recorded force, over
    each run's excited DOFs (:func:`excited_dofs`), each DOF's squared NRMSE weighted by
    its noise (:func:`sim.calibrate.mechnoise.dof_noise_weights`: alike where the record
    is clean, the paper's force weighting); ``dofs``: only these DOFs (None: every one)."""
    from sim.calibrate.mechnoise import dof_noise_weights

    vals, weights = [], []
    for mr, e in zip(mruns, residuals):
        w = dof_noise_weights(mr)
        for j in range(len(mr.dofs)):
            if (mr.excited is not None and not mr.excited[j]) or (dofs is not None and mr.dofs[j] not in dofs):
                continue
            F = mr.demean(mr.force)[mr.rows, j]
            den = float(np.sum(F**2))
            if den > 0:
                vals.append(float(np.sum(e[mr.rows, j] ** 2)) / den)
                weights.append(float(w[j]))
    return float(math.sqrt(np.average(vals, weights=weights))) if vals and sum(weights) > 0 else float("nan")


# ------------------------------------------------------------------ frequency domain
def spectra(x: np.ndarray, fs: float, states: dict | None = None, nperseg: int | None = None) -> dict:
    """Welch spectrum of a residual (n,) and its coherence with each state (n,)."""
    import scipy.signal as sig

    n = len(x)
    # segments of up to 4 s, at least 8 of them (a coherence from few segments is biased to 1)
    nper = nperseg or 2 ** int(math.log2(max(min(fs * 4, n / 8), 64)))
    nper = max(16, min(nper, n))
    f, P = sig.welch(x, fs=fs, nperseg=nper)
    out = {"f": f, "psd": P, "coherence": {}}
    for k, s in (states or {}).items():
        _, C = sig.coherence(x, s, fs=fs, nperseg=nper)
        out["coherence"][k] = C
    return out


def spectral_flatness(x: np.ndarray, fs: float) -> float:
    """Geometric over arithmetic mean of the Welch spectrum: 1 for white noise, ~0 for a line."""
    s = spectra(x, fs)
    P = s["psd"][1:]
    P = P[P > 0]
    return float(np.exp(np.mean(np.log(P))) / np.mean(P)) if len(P) else 0.0


# ------------------------------------------------------------------ replay / closed loop
#: a spectral line is reported as unexplained when it holds this share of the residual
UNEXPLAINED_FRACTION = 0.1


def unexplained(mruns, residuals, kind: str = "mechanical") -> dict | None:
    """The residual's strongest narrow spectral line (pooled over runs, per DOF): its
    frequency, channel, place and share of the residual power; None if no line holds
    :data:`UNEXPLAINED_FRACTION` of it."""
    best = None
    for j, d in enumerate(mruns[0].dofs):
        Ps, cohs, f = [], [], None
        for mr, e in zip(mruns, residuals):
            x = e[:, j]
            if not np.any(x) or (mr.excited is not None and not mr.excited[j]):  # noise over nothing
                continue
            s = spectra(x, 1.0 / mr.dt, {"u": mr.u[:, j], "v": mr.v[:, j], "a": mr.a[:, j]})
            if f is not None and len(s["f"]) != len(f):
                continue
            f = s["f"]
            Ps.append(s["psd"])
            cohs.append(np.max([c for c in s["coherence"].values()], axis=0))
        if not Ps:
            continue
        P = np.mean(Ps, axis=0)
        C = np.mean(cohs, axis=0)
        k = int(np.argmax(P[1:]) + 1)
        w = slice(max(k - 2, 1), k + 3)
        frac = float(P[w].sum() / P[1:].sum())
        if best is None or frac > best["fraction_of_residual"]:
            coh = float(C[k])
            best = {
                "peak_hz": float(f[k]),
                "channel": "actuator_force",
                "where": f"dof:{d}" if coh >= 0.5 else "channel:actuator_force",
                "fraction_of_residual": frac,
                "coherence_with_motion": coh,
            }
    if best is None or best["fraction_of_residual"] < UNEXPLAINED_FRACTION:
        return None
    return best


def distinct_force_places(desc, wheres) -> list:
    """The places of ``wheres`` whose force maps into the table's DOFs differently, the first
    of each kept: a uni-axial table's class and actuator push along x as ``dof:x`` does,
    and a friction found at both would be one friction split in two (measured on the lab
    table's replay: 882 N at class:main beside 230 N at dof:x, for 1200 N)."""
    from mjcf.description import DOFS6
    from sim.control.tvc import dof_jacobian

    cols = [DOFS6.index(d) for d in desc.dofs]  # the table's own DOFs (a uni-axial table: x)
    J = dof_jacobian(desc)[:, cols]
    classes = {}
    for i, a in enumerate(desc.actuators):
        classes.setdefault(a.cls.name, []).append(i)
    names = list(desc.actuator_names)

    def force_map(w):
        kind, _, name = w.partition(":")
        if kind == "dof":
            return np.eye(len(cols))[[desc.dofs.index(name)]]
        if kind == "supports":
            return support_jacobian(desc)
        if kind == "shoes":
            return shoe_jacobian(desc)
        return J[[names.index(name)]] if kind == "actuator" else J[classes[name]]

    return first_of_each_direction(wheres, force_map)


def same_direction(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two places' force maps into DOF space are parallel (either sign)."""
    a = np.atleast_2d(a) / (np.linalg.norm(a) or 1.0)
    b = np.atleast_2d(b) / (np.linalg.norm(b) or 1.0)
    return a.shape == b.shape and min(np.abs(a - b).max(), np.abs(a + b).max()) < 1e-6


def first_of_each_direction(wheres, force_map) -> list:
    """The places of ``wheres`` whose force maps (``force_map(where)``) differ, the first of
    each direction kept."""
    out, maps = [], []
    for w in wheres:
        m = force_map(w)
        if not any(same_direction(q, m) for q in maps):
            maps.append(m)
            out.append(w)
    return out


__all__ = [
    "CalibrationError",
    "MechRun",
    "PATHS",
    "supported_paths",
    "check_path",
    "choose_path",
    "mechanical_runs",
    "excited_dofs",
    "air_stiffness_per_kg",
    "shoe_jacobian",
    "support_jacobian",
    "nrmse_runs",
    "places",
    "distinct_force_places",
    "spectra",
    "spectral_flatness",
    "UNEXPLAINED_FRACTION",
    "unexplained",
]
