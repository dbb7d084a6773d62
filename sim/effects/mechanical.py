"""The mechanical effect library: springs, dampers, friction, masses and modes.

Every class is a registered :class:`sim.effects.base.Effect` with SI parameters and a
place (``where``). What MuJoCo has an element for is built into the MjSpec in
:meth:`edit_spec` (implicit, stable, no per-step Python work):

* on a slide joint (``dof:<d>`` of a platen on bearings: the slide ``platen_<d>``;
  ``actuator:<name>``: the stroke slide ``<name>_stroke``; ``class:<c>``: every stroke
  slide of the class): joint ``stiffness``, ``damping``, ``frictionloss``, ``armature``;
* on a DOF of a free (6-DOF) platen: a fixed tendon ``dof_<d>`` over the actuator stroke
  slides with the coefficients c = row d of pinv(J) (J = d stroke / d pose at home, the
  exact inverse kinematics): its length is the platen's DOF d to first order, and a
  tendon force F reaches the platen as J^T c F = e_d F, so the tendon's ``stiffness``,
  ``damping``, ``frictionloss`` and ``armature`` act on that DOF alone;
* bodies (``added_mass`` at the payload, ``payload_mode``, ``foundation_mode``).

Forces MuJoCo has no element for (C |v|^alpha, pre-sliding friction, friction that grows
with load or displacement) are ``per_step``: :meth:`apply` reads the velocity of its
place and adds the force to ``qfrc_applied`` (on a free platen's DOF through the free
joint: linear DOF directly, rotations through the platen's rotation matrix).

The effects of the older registry keep their names (``platen_spring``,
``platen_coulomb``, ``platen_power_damping``: a ``dof`` key instead of ``where``).
"""

from __future__ import annotations

import difflib
import math
from dataclasses import replace

import mujoco
import numpy as np

from mjcf.builder import SHOE_SLIDE_SHARE
from mjcf.description import DOFS6, actuator_strokes
from sim.effects.base import Effect, register
from sim.errors import ScenarioError

INF = math.inf


def dahl_step(z, v, zss: float, dt: float):
    """The pre-sliding state after one step at velocity ``v`` (Dahl: dz/dt = v - |v| z / zss,
    advanced exactly for the velocity held; at rest z stays). Scalars or arrays; the
    numpy reference of ``sim.loop._kernels.presliding_friction``."""
    target = np.sign(v) * zss
    return np.where(v != 0.0, target + (z - target) * np.exp(-np.abs(v) * dt / zss), z)


def _hint(name: str, known) -> str:
    known = sorted(known)
    close = difflib.get_close_matches(str(name), known, n=1)
    return f" (did you mean '{close[0]}'?)" if close else f"; known: {', '.join(known)}"


def dof_jacobian(desc, h: float = 1e-6) -> np.ndarray:
    """(n_act, 6) d(stroke)/d(pose) at home, by central differences of the exact inverse
    kinematics (:func:`mjcf.description.actuator_strokes`)."""
    J = np.zeros((len(desc.actuators), 6))
    for k in range(6):
        dp = np.zeros(6)
        dp[k] = h
        J[:, k] = (actuator_strokes(desc, dp) - actuator_strokes(desc, -dp)) / (2 * h)
    return J


class Place:
    """Where an effect acts, resolved against the table: ``joints`` (slide joints whose
    parameters carry it) or ``free_dof`` (index 0-5 of a free platen's DOF)."""

    def __init__(self, effect: Effect, desc, spec=None):
        kind, name = effect.where.partition(":")[::2]
        src = effect.source
        self.kind, self.name = kind, name
        self.joints: list[str] = []
        self.free_dof: int | None = None
        if kind == "dof":
            if name not in DOFS6:
                raise ScenarioError(f"{src}: where = '{effect.where}': no DOF '{name}'{_hint(name, DOFS6)}")
            if desc.platen.guided:
                if name not in desc.dofs:
                    raise ScenarioError(
                        f"{src}: where = '{effect.where}': the platen of '{desc.name}' slides along "
                        f"{', '.join(desc.dofs)} only (table.dofs){_hint(name, desc.dofs)}"
                    )
                self.joints = [f"platen_{name}"]
            else:
                self.free_dof = DOFS6.index(name)
        elif kind == "actuator":
            if name not in desc.actuator_names:
                raise ScenarioError(
                    f"{src}: where = '{effect.where}': no actuator '{name}'{_hint(name, desc.actuator_names)}"
                )
            self.joints = [f"{name}_stroke"]
        elif kind == "class":
            if name not in desc.actuator_classes:
                raise ScenarioError(
                    f"{src}: where = '{effect.where}': no actuator class '{name}'{_hint(name, desc.actuator_classes)}"
                )
            self.joints = [f"{a.name}_stroke" for a in desc.actuators if a.cls.name == name]
        elif kind in ("supports", "shoes"):
            if desc.supports is None:
                raise ScenarioError(f"{src}: where = '{kind}': '{desc.name}' has no [supports]")
            n = len(desc.supports.positions_m)
            if kind == "supports":
                self.joints = [f"S{i}_air" for i in range(1, n + 1)]
            else:  # each shoe slides on two joints, x and y
                self.joints = [f"S{i}_shoe_{ax}" for i in range(1, n + 1) for ax in ("x", "y")]
        if spec is not None:
            for j in self.joints:
                if spec.joint(j) is None:
                    raise ScenarioError(f"{src}: the model has no joint '{j}' for where = '{effect.where}'")


def dof_tendon(spec, desc, i: int):
    """The fixed tendon ``dof_<d>`` whose length is the free platen's DOF ``i`` (see the
    module docstring); made once per DOF and shared by every effect acting there."""
    name = f"dof_{DOFS6[i]}"
    t = spec.tendon(name)
    if t is not None:
        return t
    J = dof_jacobian(desc)
    if np.linalg.matrix_rank(J, tol=1e-9 * np.abs(J).max()) < 6:
        raise ScenarioError(
            f"{desc.source}: the actuators do not fix all six DOF of the free platen, so an effect "
            f"at dof:{DOFS6[i]} has no linkage to act through; put it at 'actuator:<name>'"
        )
    c = np.linalg.pinv(J)[i]
    t = spec.add_tendon(name=name)
    for a, coef in zip(desc.actuators, c):
        if abs(coef) > 1e-12:
            t.wrap_joint(f"{a.name}_stroke", float(coef))
    t.springlength = [0.0, 0.0]  # home (every stroke 0)
    t.solref_friction = list(spec.default.joint.solref_friction)
    t.solimp_friction = list(spec.default.joint.solimp_friction)
    return t


def _elements(effect: Effect, spec, desc):
    """The spec elements (joints or the DOF tendon) that carry ``effect``'s parameters."""
    p = Place(effect, desc, spec)
    if p.free_dof is not None:
        return [dof_tendon(spec, desc, p.free_dof)]
    return [spec.joint(j) for j in p.joints]


def _add(elements, attr: str, value: float) -> None:
    for el in elements:
        cur = getattr(el, attr)
        if np.ndim(cur):  # stiffness / damping: polynomial coefficients, the first is linear
            new = np.array(cur, dtype=float)
            new[0] += value
            setattr(el, attr, new.tolist())
        else:
            setattr(el, attr, float(cur) + value)


class StepForce(Effect):
    """Base of the per-step forces: resolves its place at :meth:`bind` and gives
    :meth:`velocity`, :meth:`displacement` and :meth:`add` (the force along the place's
    coordinate: N on slides and translations, N m on rotations)."""

    per_step = True

    def edit_spec(self, spec, desc):
        self._place = Place(self, desc, spec)
        self._desc = desc

    def bind(self, model, hydraulics=None):
        p = self._place
        jid = lambda n: mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n)
        self._dt = float(model.opt.timestep)
        self._i = p.free_dof
        if p.free_dof is None:
            ids = [jid(j) for j in p.joints]
            self._d = np.array([model.jnt_dofadr[j] for j in ids], dtype=int)
            self._q = np.array([model.jnt_qposadr[j] for j in ids], dtype=int)
            self._q0 = model.qpos0[self._q].copy()
            self._act = (
                np.array(
                    [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, j[: -len("_stroke")]) for j in p.joints],
                    dtype=int,
                )
                if p.kind in ("actuator", "class")
                else None
            )
            self.n = len(ids)
            self._d0 = int(self._d[0]) if self.n == 1 else None  # one slide: the scalar fast path
        else:
            self._d0 = None
            j = jid("platen")
            self._pd, self._pq = int(model.jnt_dofadr[j]), int(model.jnt_qposadr[j])
            self._body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "platen")
            self._q0 = model.qpos0[self._pq : self._pq + 7].copy()
            self._act = None
            self.n = 1
        self.reset()

    def velocity(self, data) -> np.ndarray:
        if self._i is None:
            return data.qvel[self._d]
        i, pd = self._i, self._pd
        if i < 3:
            return data.qvel[pd + i : pd + i + 1]
        R = data.xmat[self._body].reshape(3, 3)
        return (R @ data.qvel[pd + 3 : pd + 6])[i - 3 : i - 2]

    def displacement(self, data) -> np.ndarray:
        """From home (m, or rad to first order for a free platen's rotation)."""
        if self._i is None:
            return data.qpos[self._q] - self._q0
        i, pq = self._i, self._pq
        if i < 3:
            return data.qpos[pq + i : pq + i + 1] - self._q0[i : i + 1]
        q = data.qpos[pq + 3 : pq + 7]
        return np.array([2.0 * q[i - 2] * math.copysign(1.0, q[0])])  # small-angle: 2 x vector part

    def add(self, data, force: np.ndarray) -> None:
        if self._i is None:
            data.qfrc_applied[self._d] += force
            return
        i, pd = self._i, self._pd
        if i < 3:
            data.qfrc_applied[pd + i] += force[0]
        else:  # a world torque about axis i-3, in the free joint's (platen-frame) angular coordinates
            R = data.xmat[self._body].reshape(3, 3)
            data.qfrc_applied[pd + 3 : pd + 6] += R[i - 3, :] * force[0]


# ------------------------------------------------------------------------ springs and dampers
@register
class Spring(Effect):
    """A linear spring about home on a DOF or actuator stroke (N/m; N m/rad on rotations):
    hold-down struts, air springs, centring springs. Joint/tendon ``stiffness``. At
    ``supports``: each static support's air spring stiffer by this much (its preload
    kept: :func:`mjcf.builder.build` sets the air spring on top of it)."""

    type = "spring"
    places = ("dof", "actuator", "class", "supports")
    SPEC = {"stiffness_n_m": ("N/m", 0.0, INF, None)}

    def edit_spec(self, spec, desc):
        _add(_elements(self, spec, desc), "stiffness", self.values["stiffness_n_m"])


@register
class ViscousDamping(Effect):
    """Linear viscous damping F = -c v (N s/m; N m s/rad on rotations). Joint/tendon ``damping``."""

    type = "viscous_damping"
    places = ("dof", "actuator", "class")
    SPEC = {"damping_n_s_m": ("N s/m", 0.0, INF, None)}

    def edit_spec(self, spec, desc):
        _add(_elements(self, spec, desc), "damping", self.values["damping_n_s_m"])


@register
class PowerDamping(StepForce):
    """F = -C |v|^alpha sign(v), linear below ``linear_below_m_s`` (finite slope at rest)."""

    type = "power_damping"
    places = ("dof", "actuator", "class")
    SPEC = {"coefficient": ("N (s/m)^alpha", 0.0, INF, None), "exponent": ("1", 1e-3, 5.0, None)}
    OPTIONS = {"linear_below_m_s": 1e-3}  # assumed: regularisation below 1 mm/s (a setting, not calibrated)

    def __init__(self, entry, *, source="effect"):
        super().__init__(entry, source=source)
        _positive_option(self, "linear_below_m_s")

    def force(self, v):
        c, a, v0 = self.values["coefficient"], self.values["exponent"], self.options["linear_below_m_s"]
        av = np.abs(v)
        return np.where(av >= v0, -c * av**a * np.sign(v), -c * v0**a * (v / v0))

    def bind(self, model, hydraulics=None):
        super().bind(model, hydraulics)
        c, a, v0 = self.values["coefficient"], self.values["exponent"], self.options["linear_below_m_s"]
        self._k = (c, a, v0, c * v0**a / v0)

    def apply(self, model, data):
        d = self._d0
        if d is None:
            self.add(data, self.force(self.velocity(data)))
            return
        c, a, v0, slope = self._k  # one slide: scalar arithmetic (this runs every physics step)
        v = float(data.qvel[d])
        av = abs(v)
        data.qfrc_applied[d] -= c * av**a * math.copysign(1.0, v) if av >= v0 else slope * v


# ------------------------------------------------------------------------ friction
GROWS = ("none", "load", "displacement")


@register
class CoulombFriction(StepForce):
    """Dry friction of level ``force_n`` (N; N m on rotations) on a DOF or actuator stroke.

    * constant level, ``presliding_m = 0``: MuJoCo ``frictionloss`` (joint or DOF tendon;
      an implicit stick-slip constraint, no per-step work). With the table's
      ``[friction] model = "presliding"`` a joint's frictionloss is applied by the loop's
      pre-sliding law like every other joint friction.
    * ``presliding_m > 0``: pre-sliding (Dahl) friction applied every step,
      dz/dt = v - |v| z / delta, F = -(F_c / delta) z: a spring F_c / delta for travels
      much smaller than delta, F_c after many delta (z advanced exactly per step).
    * ``grows_with = "load"``: F_c = force_n + coefficient * load, the load being the
      actuator's own force |F| at ``actuator:``/``class:`` (seal friction rising with
      pressure) and the weight the platen carries (platen and everything on it, m g) at
      ``dof:``; ``"displacement"``: F_c = force_n + coefficient |x| (N/m), x from home.
      A level that changes is applied every step (with ``presliding_m``, else linear
      below ``linear_below_m_s``).
    * at ``supports``: each static support's piston friction higher by ``force_n`` (the
      description's ``[supports] piston_friction_n`` is the same joint's ``frictionloss``);
      ``grows_with = "load"`` is not offered there (a support's load is its air pressure,
      which no run records).
    * at ``shoes``: each support's sliding shoe's friction higher by ``force_n``, split over
      its x and y slides as the builder splits ``[supports] shoe_friction_n``
      (``force_n / sqrt 2`` on each); a constant level only.
    """

    type = "coulomb_friction"
    places = ("dof", "actuator", "class", "supports", "shoes")
    per_step = (
        False  # per instance: only a level that changes, pre-sliding, or a free platen's DOF on a pre-sliding table
    )
    SPEC = {
        "force_n": ("N", 0.0, INF, None),
        "coefficient": ("1 (load) or N/m (displacement)", 0.0, INF, 0.0),
        "presliding_m": ("m", 0.0, INF, 0.0),
    }
    OPTIONS = {"grows_with": "none", "linear_below_m_s": 1e-3}  # assumed: regularisation below 1 mm/s

    def __init__(self, entry, *, source="effect"):
        super().__init__(entry, source=source)
        _positive_option(self, "linear_below_m_s")
        g = self.options["grows_with"]
        if g not in GROWS:
            raise ScenarioError(f"{source}: grows_with = '{g}' is not one of {', '.join(GROWS)}{_hint(g, GROWS)}")
        if g == "load" and self.where == "supports":
            raise ScenarioError(
                f"{source}: grows_with = 'load' has no load at where = 'supports' (their air pressure is "
                "not modelled as a friction load); use grows_with = 'none' or 'displacement' there"
            )
        if self.where == "shoes" and (g != "none" or self.values["presliding_m"] > 0):
            raise ScenarioError(
                f"{source}: at where = 'shoes' a coulomb_friction is a constant level (the table's own "
                "friction law applies): leave out grows_with and presliding_m there"
            )
        self.z = np.zeros(1)
        self.per_step = self._needs_step(None)

    def parameters(self):
        """Without ``grows_with`` the coefficient is no parameter; with it, its unit is
        1 (load) or N/m (displacement)."""
        g = self.options["grows_with"]
        unit = {"load": "1", "displacement": "N/m"}.get(g)
        return [
            p if p.name != "coefficient" else replace(p, unit=unit)
            for p in super().parameters()
            if p.name != "coefficient" or unit
        ]

    def _needs_step(self, desc) -> bool:
        v = self.values
        if v["presliding_m"] > 0:
            return True
        g = self.options["grows_with"]
        if g == "displacement" and v["coefficient"] > 0:
            return True
        if g == "load" and v["coefficient"] > 0:
            # the platen's weight is a constant load on a platen on bearings without z
            kind = self.where.partition(":")[0]
            return not (kind == "dof" and desc is not None and desc.platen.guided and "z" not in desc.dofs)
        return False

    def edit_spec(self, spec, desc):
        super().edit_spec(spec, desc)
        self.per_step = self._needs_step(desc)
        self._table_zss = 0.0
        if (
            not self.per_step
            and self._place.free_dof is not None
            and self.values["presliding_m"] == 0
            and desc.friction_model == "presliding"
        ):
            # a table whose joint friction is pre-sliding: a free platen's DOF friction too
            # (its tendon has no place in the loop's pre-sliding law), with the table's travel
            self.per_step, self._table_zss = True, float(desc.friction_presliding_m)
        self._constant_load = (
            not self.per_step and self.options["grows_with"] == "load" and self.values["coefficient"] > 0
        )
        if not self.per_step:
            level = self.values["force_n"]
            if self._constant_load:
                level += self.values["coefficient"] * _platen_weight(spec, desc)
            if self.where == "shoes":  # over each shoe's two slides, as the build splits it
                level *= SHOE_SLIDE_SHARE
            _add(_elements(self, spec, desc), "frictionloss", level)

    def with_values(self, values):
        new = super().with_values(values)
        new.per_step = new._needs_step(getattr(self, "_desc", None)) or bool(getattr(self, "_table_zss", 0.0))
        return new

    def bind(self, model, hydraulics=None):
        super().bind(model, hydraulics)
        self._zss = self.values["presliding_m"] or getattr(self, "_table_zss", 0.0)
        pb = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "platen")
        self._g = float(-model.opt.gravity[2])
        self._weight = float(model.body_subtreemass[pb]) * self._g
        self._pzd = None
        if not self._place.joints or self._place.kind == "dof":
            j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "platen")
            if j >= 0:
                self._pzd = int(model.jnt_dofadr[j]) + 2

    def reset(self):
        self.z = np.zeros(getattr(self, "n", 1))

    def level(self, data) -> np.ndarray | float:
        """The friction level F_c now (N)."""
        v = self.values
        g = self.options["grows_with"]
        if g == "displacement":
            return v["force_n"] + v["coefficient"] * np.abs(self.displacement(data))
        if g == "load":
            if self._act is not None:
                load = np.abs(data.ctrl[self._act])
            else:  # the weight the bearings carry, with the platen's vertical acceleration
                az = float(data.qacc[self._pzd]) if self._pzd is not None else 0.0
                load = self._weight * (1.0 + az / self._g) if self._g else 0.0
            return v["force_n"] + v["coefficient"] * load
        return v["force_n"]

    def advance(self, v, dt: float, level=None):
        """Pre-sliding: advance z over one step at velocity ``v``; returns the force.
        (Without ``presliding_m``: the force linear below ``linear_below_m_s``.)"""
        fc = self.values["force_n"] if level is None else level
        d = self.values["presliding_m"] or getattr(self, "_table_zss", 0.0)
        if d > 0:
            self.z = dahl_step(self.z, v, d, dt)
            f = -fc / d * self.z
        else:
            f = -fc * np.clip(np.asarray(v, float) / self.options["linear_below_m_s"], -1.0, 1.0)
        return float(np.ravel(f)[0]) if np.ndim(v) == 0 else f

    def apply(self, model, data):
        d = self._d0
        if d is not None and self.options["grows_with"] == "none":  # one slide, constant level: scalars
            v = float(data.qvel[d])
            fc, zss = self.values["force_n"], self._zss
            if zss > 0:
                z = float(self.z[0])
                if v != 0.0:
                    t = math.copysign(zss, v)
                    z = t + (z - t) * math.exp(-abs(v) * self._dt / zss)
                    self.z[0] = z
                data.qfrc_applied[d] -= fc / zss * z
            else:
                data.qfrc_applied[d] -= fc * max(-1.0, min(1.0, v / self.options["linear_below_m_s"]))
            return
        self.add(data, np.atleast_1d(self.advance(self.velocity(data), self._dt, self.level(data))))


def _platen_weight(spec, desc) -> float:
    """Weight (N) of the platen and every body on it, from the spec being built."""

    def mass(b):
        return float(b.mass) + sum(mass(c) for c in b.bodies)

    return mass(spec.body("platen")) * desc.gravity_m_s2


# ------------------------------------------------------------------------ masses and modes
@register
class AddedMass(Effect):
    """A mass (kg) and optional inertia (kg m^2 about its centre, principal axes x y z).

    ``where = "payload"``: a rigid body on the payload (its first body, or the platen's
    reference point without a payload) at ``position_m`` from that body's frame;
    ``dof:<d>``, ``actuator:``, ``class:``: mass along that coordinate only (the slide's
    ``armature``; on a free platen the free joint's armature of that DOF, set in
    :meth:`edit_model`: oil columns, rods, the moving part of a bearing); on a rotation
    the mass is read as kg m^2 (about the platen's own axes); ``supports``: each static
    support's piston heavier by ``mass_kg`` (its body's mass: the build's preload carries
    the weight, and the air spring stiffens with it, as ``[supports] piston_mass_kg``
    raised by as much would)."""

    type = "added_mass"
    places = ("payload", "dof", "actuator", "class", "supports")
    SPEC = {
        "mass_kg": ("kg", 0.0, INF, None),
        "inertia_x_kg_m2": ("kg m^2", 0.0, INF, 0.0),
        "inertia_y_kg_m2": ("kg m^2", 0.0, INF, 0.0),
        "inertia_z_kg_m2": ("kg m^2", 0.0, INF, 0.0),
    }
    OPTIONS = {"position_m": None}

    def __init__(self, entry, *, source="effect"):
        super().__init__(entry, source=source)
        a, b, c = sorted(self.values[f"inertia_{k}_kg_m2"] for k in "xyz")
        if a + b < c * (1 - 1e-12):
            raise ScenarioError(
                f"{source}: inertia_x/y/z_kg_m2 are not the principal moments of a body (the two "
                "smaller must sum to at least the largest); give all three, e.g. equal ones for a "
                "compact mass"
            )

    def edit_spec(self, spec, desc):
        v = self.values
        self._free = None
        if self.where == "supports":
            Place(self, desc, spec)  # checks the table has supports
            for i in range(1, len(desc.supports.positions_m) + 1):
                spec.body(f"S{i}_piston").mass += v["mass_kg"]
            return
        if self.where != "payload":
            place = Place(self, desc, spec)
            if place.free_dof is not None:  # one DOF of the free joint: edit_model
                self._free = place.free_dof
            else:
                _add([spec.joint(j) for j in place.joints], "armature", v["mass_kg"])
            return
        parent = _payload_body(spec) or spec.body("platen")
        pos = _vector(self.options["position_m"], self, "position_m")
        b = parent.add_body(name=_unique(spec, "added_mass"), pos=pos.tolist())
        b.explicitinertial = True
        b.mass = v["mass_kg"]
        b.ipos = [0, 0, 0]
        # a welded body: its inertia only adds to the parent's (zero is allowed)
        b.inertia = [v["inertia_x_kg_m2"], v["inertia_y_kg_m2"], v["inertia_z_kg_m2"]]

    def edit_model(self, model):
        # a free platen's DOF: the free joint's own armature on that DOF (a tendon's armature
        # would only add m c_i^2 on each stroke: MuJoCo keeps the mass matrix tree-sparse)
        if getattr(self, "_free", None) is not None:
            j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "platen")
            model.dof_armature[model.jnt_dofadr[j] + self._free] += self.values["mass_kg"]


@register
class CgOffset(Effect):
    """Moves the payload's centre of gravity by (dx, dy, dz) m: the mass centre of every
    payload body (its ``ipos``); the support preloads follow when the model is built."""

    type = "cg_offset"
    places = ("payload",)
    SPEC = {"dx_m": ("m", -INF, INF, 0.0), "dy_m": ("m", -INF, INF, 0.0), "dz_m": ("m", -INF, INF, 0.0)}

    def default_where(self):
        return "payload"

    def edit_spec(self, spec, desc):
        bodies = _payload_bodies(spec)
        if not bodies:
            raise ScenarioError(f"{self.source}: a cg_offset needs a payload on the table (none is built)")
        d = np.array([self.values["dx_m"], self.values["dy_m"], self.values["dz_m"]])
        for b in bodies:
            b.ipos = (np.asarray(b.ipos, float) + d).tolist()


@register
class FoundationMode(Effect):
    """The reaction mass on springs (``where = "table"``): ``mass_kg`` on a spring-damper
    per axis of ``frequency_hz`` and ``damping_ratio`` (x, y, z alike; ``frequency_z_hz``
    for a different vertical one). Replaces a ``[foundation] mode = "spring"``'s values; a
    fixed foundation is made a body carrying every swivel base and support."""

    type = "foundation_mode"
    places = ("table",)
    SPEC = {
        "frequency_hz": ("Hz", 1e-3, INF, None),
        "frequency_z_hz": ("Hz", 0.0, INF, 0.0),
        "mass_kg": ("kg", 1e-9, INF, None),
        "damping_ratio": ("1", 0.0, 10.0, None),
    }

    def default_where(self):
        return "table"

    def edit_spec(self, spec, desc):
        v = self.values
        fd = spec.body("foundation")
        if fd is None:
            fd = _make_foundation(spec, desc)
        fd.mass = v["mass_kg"]
        for ax in "xyz":
            f = v["frequency_z_hz"] if ax == "z" and v["frequency_z_hz"] > 0 else v["frequency_hz"]
            w = 2 * math.pi * f
            j = spec.joint(f"foundation_{ax}")
            j.stiffness = [v["mass_kg"] * w * w, 0, 0]
            j.damping = [2 * v["damping_ratio"] * v["mass_kg"] * w, 0, 0]
        # home: the springs carry the whole weight (every body built so far)
        total = sum(float(b.mass) for b in spec.bodies)
        jz = spec.joint("foundation_z")
        jz.springref = total * desc.gravity_m_s2 / float(jz.stiffness[0])


_MOVED = "moved_"
_EQ_KEYS = ("name", "type", "objtype", "name1", "name2", "data", "solref", "solimp", "active")
_ACT_KEYS = (
    "name",
    "target",
    "trntype",
    "gear",
    "ctrllimited",
    "ctrlrange",
    "forcelimited",
    "forcerange",
    "dyntype",
    "gaintype",
    "biastype",
    "dynprm",
    "gainprm",
    "biasprm",
)


def _copy(v):
    return v.copy() if isinstance(v, np.ndarray) else v


def _make_foundation(spec, desc):
    """A foundation body on three slides; every body standing on the world (swivel
    bases, supports) is moved onto it."""
    world = spec.worldbody
    movers = [b for b in world.bodies if b.name != "platen" or desc.platen.guided]
    fd = world.add_body(name="foundation", pos=[0, 0, 0])
    fd.explicitinertial = True
    fd.ipos = [0, 0, -3.0]  # assumed: as mjcf.builder's spring foundation
    fd.inertia = [1.0, 1.0, 1.0]
    for k, ax in enumerate("xyz"):
        axis = [0.0, 0.0, 0.0]
        axis[k] = 1.0
        fd.add_joint(name=f"foundation_{ax}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
    # MjSpec moves a subtree by attaching a copy of it (from a copy of the spec, under a
    # prefix that is taken off again); the copy brings the equalities and actuators that
    # name its bodies and joints, so the originals go
    if len(spec.tendons):
        raise ScenarioError(
            "foundation_mode must come before the effects that act on a DOF of a free platen "
            "(they make tendons); move its [[effect]] entry up"
        )
    src = spec.copy()
    eqs = [{k: _copy(getattr(e, k)) for k in _EQ_KEYS} for e in spec.equalities]
    acts = [{k: _copy(getattr(a, k)) for k in _ACT_KEYS} for a in spec.actuators]
    for el in list(spec.equalities) + list(spec.actuators):
        spec.delete(el)
    for b in movers:
        name = b.name
        spec.delete(b)
        fd.add_frame().attach_body(src.body(name), _MOVED, "")
    for el in [*spec.bodies, *spec.joints, *spec.geoms, *spec.sites, *spec.equalities, *spec.actuators]:
        for k in ("name", "name1", "name2", "target"):
            v = getattr(el, k, None)
            if isinstance(v, str) and v.startswith(_MOVED):
                setattr(el, k, v[len(_MOVED) :])
    # those the copy did not bring (they also name a body that stayed): made again
    have = {e.name for e in spec.equalities} | {"act:" + a.name for a in spec.actuators}
    for saved, add, tag in ((eqs, spec.add_equality, ""), (acts, spec.add_actuator, "act:")):
        for e in saved:
            if tag + e["name"] not in have:
                new = add()
                for k, v in e.items():
                    setattr(new, k, v)
    return fd


# ------------------------------------------------------------------------ helpers
def _positive_option(effect, key) -> None:
    v = effect.options[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (math.isfinite(v) and v > 0):
        raise ScenarioError(f"{effect.source}: '{key}' must be a positive number (got {v!r})")
    effect.options[key] = float(v)


def _vector(val, effect, key) -> np.ndarray:
    if val is None:
        return np.zeros(3)
    a = np.asarray(val, dtype=float) if isinstance(val, (list, tuple)) else None
    if a is None or a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ScenarioError(f"{effect.source}: '{key}' must be [x, y, z] in m (got {val!r})")
    return a


def _unique(spec, stem: str) -> str:
    i = 1
    while spec.body(f"{stem}{i}") is not None:
        i += 1
    return f"{stem}{i}"


def _payload_bodies(spec) -> list:
    plat = spec.body("platen")
    names = ("payload", "payload_fixed")
    out = [b for b in plat.bodies if b.name in names]
    if out:
        return out
    return [b for b in plat.find_all(mujoco.mjtObj.mjOBJ_BODY) if b.name.startswith(("floor", "segment"))]


def _payload_body(spec):
    bodies = _payload_bodies(spec)
    return bodies[0] if bodies else None


# ------------------------------------------------------------------------ the older names
def _legacy(entry: dict, source: str) -> dict:
    entry = dict(entry)
    dof = entry.pop("dof", "x")
    if "where" not in entry:
        entry["where"] = f"dof:{dof}"
    return entry


@register
class PlatenSpring(Spring):
    """``platen_spring`` (``dof`` key): a :class:`Spring` at ``dof:<dof>``."""

    type = "platen_spring"
    places = ("dof",)

    def __init__(self, entry, *, source="effect"):
        super().__init__(_legacy(entry, source), source=source)


@register
class PlatenCoulomb(CoulombFriction):
    """``platen_coulomb`` (``dof`` key, optional ``presliding_m``): a :class:`CoulombFriction`."""

    type = "platen_coulomb"
    places = ("dof",)

    def __init__(self, entry, *, source="effect"):
        super().__init__(_legacy(entry, source), source=source)


@register
class PlatenPowerDamping(PowerDamping):
    """``platen_power_damping`` (``dof`` key): a :class:`PowerDamping`."""

    type = "platen_power_damping"
    places = ("dof",)

    def __init__(self, entry, *, source="effect"):
        super().__init__(_legacy(entry, source), source=source)


__all__ = [
    "AddedMass",
    "CgOffset",
    "CoulombFriction",
    "FoundationMode",
    "Place",
    "PowerDamping",
    "Spring",
    "StepForce",
    "ViscousDamping",
    "dahl_step",
    "dof_jacobian",
    "dof_tendon",
]
