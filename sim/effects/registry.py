"""Named physical effects: parameterised parts of the model, declared in the description.

A table description may list effects::

    [[effect]]
    type = "platen_spring"          # hold-down struts, air springs, centring springs
    dof = "x"
    stiffness_n_m = 1.263e6

    [[effect]]
    type = "platen_coulomb"         # bearing friction
    dof = "x"
    force_n = 26.5e3
    presliding_m = 2e-3             # optional: pre-sliding travel (Dahl), see PreslidingFriction

    [[effect]]
    type = "platen_power_damping"   # C |v|^alpha sign(v) (seed 002)
    dof = "x"
    coefficient = 45.9e3            # N (s/m)^alpha
    exponent = 0.5
    linear_below_m_s = 1e-3         # regularisation: linear below this speed

Each effect is applied at one defined place: springs and Coulomb friction become joint
parameters of the platen's bearing slide in the MJCF (``apply_to_spec``: implicit,
so friction sticks properly); forces that MuJoCo has no element for are computed from
the state before every physics step and written to ``qfrc_applied`` (``StepEffect``;
``reset`` is called by ``sim.loop.simulation.Simulation.reset``). A ``platen_coulomb`` with
``presliding_m`` is such a force: pre-sliding (Dahl) friction instead of the stick
constraint.
Users can add their own with :func:`register`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import mujoco
import numpy as np

from sim.errors import ScenarioError

_REGISTRY: dict[str, Callable] = {}


def register(name: str):
    """Decorator: register an effect factory ``f(spec_or_none, params: dict) -> StepEffect | None``."""
    def deco(fn):
        _REGISTRY[name] = fn
        return fn
    return deco


def known() -> list[str]:
    from sim.effects.base import EFFECTS

    return sorted(set(_REGISTRY) | set(EFFECTS))


def _num(p: dict, key: str, where: str, *, positive=False, nonneg=False) -> float:
    if key not in p:
        raise ScenarioError(f"{where}: missing '{key}'")
    v = p[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
        raise ScenarioError(f"{where}: '{key}' must be a number (got {v!r})")
    if positive and v <= 0:
        raise ScenarioError(f"{where}: '{key}' must be > 0 (got {v})")
    if nonneg and v < 0:
        raise ScenarioError(f"{where}: '{key}' must be >= 0 (got {v})")
    return float(v)


def _check_keys(p: dict, allowed: set, where: str):
    extra = sorted(set(p) - allowed)
    if extra:
        raise ScenarioError(f"{where}: unknown key '{extra[0]}'; known: {', '.join(sorted(allowed))}")


class StepEffect:
    """An effect computed every physics step: ``force(model, data) -> None`` adds to qfrc_applied."""

    name = "effect"

    def bind(self, model: mujoco.MjModel) -> None:  # resolve indices once
        pass

    def reset(self) -> None:  # back to the initial state (effects with a state of their own)
        pass

    def apply(self, model: mujoco.MjModel, data: mujoco.MjData) -> None:
        raise NotImplementedError


def _platen_joint(spec, dof, where):
    j = spec.joint(f"platen_{dof}") if spec is not None else None
    if spec is not None and j is None:
        raise ScenarioError(f"{where}: the platen has no bearing slide '{dof}'; platen effects need "
                            "'platen.guide = \"bearings\"' and the DOF in table.dofs")
    return j


@register("platen_spring")
def _spring(spec, p, where="effect platen_spring"):
    _check_keys(p, {"type", "dof", "stiffness_n_m", "name", "source"}, where)
    k = _num(p, "stiffness_n_m", where, nonneg=True)
    j = _platen_joint(spec, p.get("dof", "x"), where)
    if j is not None:
        j.stiffness = [float(j.stiffness[0]) + k, 0, 0]
    return None


def dahl_step(z, v, zss: float, dt: float):
    """The pre-sliding state after one step at velocity ``v`` (Dahl: dz/dt = v - |v| z / zss,
    advanced exactly for the velocity held; at rest z stays). Scalars or arrays; the
    numpy reference of ``sim.loop._kernels.presliding_friction``."""
    target = np.sign(v) * zss
    return np.where(v != 0.0, target + (z - target) * np.exp(-np.abs(v) * dt / zss), z)


@dataclass
class PreslidingFriction(StepEffect):
    """Dry friction with pre-sliding on one platen slide: the Dahl law of the
    ``[friction] model = "presliding"`` joint friction (``sim.loop._kernels.presliding_friction``),

        dz/dt = u' - |u'| z / delta,   F = -(F_mu / delta) z,

    so the force saturates at F_mu after a travel of a few delta and, for travels much
    smaller than delta (between close velocity reversals), acts as a spring of stiffness
    F_mu / delta about the position of the last reversal. Over a physics step z is
    advanced exactly for the velocity held (z -> sign(u') delta at rate |u'| / delta):
    stable at any speed; at rest z and the force stay (elastic stick).
    """

    dof: str
    force_n: float
    presliding_m: float
    name: str = "platen_coulomb"
    z: float = 0.0
    _d: int = -1
    _dt: float = 0.0

    def bind(self, model):
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"platen_{self.dof}")
        self._d = int(model.jnt_dofadr[j])
        self._dt = float(model.opt.timestep)

    def reset(self):
        self.z = 0.0

    def advance(self, v: float, dt: float) -> float:
        """Advance z over one step at velocity ``v``; returns the friction force."""
        self.z = float(dahl_step(self.z, v, self.presliding_m, dt))
        return -self.force_n / self.presliding_m * self.z

    def apply(self, model, data):
        data.qfrc_applied[self._d] += self.advance(float(data.qvel[self._d]), self._dt)


@register("platen_coulomb")
def _coulomb(spec, p, where="effect platen_coulomb"):
    _check_keys(p, {"type", "dof", "force_n", "presliding_m", "name", "source"}, where)
    f = _num(p, "force_n", where, nonneg=True)
    dof = p.get("dof", "x")
    j = _platen_joint(spec, dof, where)
    if "presliding_m" in p:  # pre-sliding (Dahl) friction, applied every step instead of the stick constraint
        return PreslidingFriction(dof=dof, force_n=f, presliding_m=_num(p, "presliding_m", where, positive=True))
    if j is not None:
        j.frictionloss = float(j.frictionloss) + f
    return None


@dataclass
class PowerDamping(StepEffect):
    """F = -C |v|^alpha sign(v) on one platen slide, linear below ``v0`` (finite slope)."""

    dof: str
    coefficient: float
    exponent: float
    v0: float
    name: str = "platen_power_damping"
    _d: int = -1

    def bind(self, model):
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"platen_{self.dof}")
        self._d = int(model.jnt_dofadr[j])

    def force(self, v: float) -> float:
        a = abs(v)
        if a >= self.v0:
            return -self.coefficient * a ** self.exponent * np.sign(v)
        return -self.coefficient * self.v0 ** self.exponent * (v / self.v0)

    def apply(self, model, data):
        data.qfrc_applied[self._d] += self.force(data.qvel[self._d])


@register("platen_power_damping")
def _power(spec, p, where="effect platen_power_damping"):
    _check_keys(p, {"type", "dof", "coefficient", "exponent", "linear_below_m_s", "name", "source"}, where)
    dof = p.get("dof", "x")
    _platen_joint(spec, dof, where)
    return PowerDamping(dof=dof, coefficient=_num(p, "coefficient", where, nonneg=True),
                        exponent=_num(p, "exponent", where, positive=True),
                        v0=float(p.get("linear_below_m_s", 1e-3)))


def build_effects(spec, effects: list[dict], desc=None) -> tuple[list, list]:
    """Build a description's ``[[effect]]`` entries into ``spec``.

    Returns ``(step_effects, effects)``: the per-step ones (applied by the loop every
    physics step, unbound) and every :class:`sim.effects.base.Effect` (whose lifecycle the
    loop runs: ``edit_hydraulics``, ``bind``, ``reset``, ``apply``, ``measure``)."""
    from sim.effects.base import EFFECTS, create

    steps, objs = [], []
    for i, p in enumerate(effects or []):
        if not isinstance(p, dict) or "type" not in p:
            raise ScenarioError(f"effect[{i}] needs a 'type' ({', '.join(known())})")
        kind = p["type"]
        if kind in EFFECTS:
            e = create(p, source=f"effect[{i}] {kind}")
            e.edit_spec(spec, desc)
            objs.append(e)
            if e.per_step:
                steps.append(e)
            continue
        if kind not in _REGISTRY:
            raise ScenarioError(f"effect[{i}]: unknown type '{kind}'; known effects: {', '.join(known())}")
        e = _REGISTRY[kind](spec, p, f"effect[{i}] {kind}")
        if e is not None:
            steps.append(e)
    return steps, objs
