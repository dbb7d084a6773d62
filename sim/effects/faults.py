"""Table faults: effects with a start time, and the controller's interlock.

A fault is an :class:`~sim.effects.base.Effect` that starts acting at ``start_s`` (s of the
run). A scenario declares it as ``[[fault]]`` (or ``[[effect]]``)::

    [[fault]]
    type = "valve_stuck"
    where = "actuator:X1"
    opening = 1.0                   # hard-over: full opening, extension
    start_s = 1.0

| type | where | parameters | what happens from ``start_s`` |
|---|---|---|---|
| ``pump_trip`` | ``supply`` | | the pumps deliver nothing; the accumulators drain, the supply pressure falls |
| ``valve_stuck`` | ``actuator:<name>`` | ``opening`` (-1..1) | the valve receives ``opening`` whatever the controller asks (1: hard-over) |
| ``support_pressure_loss`` | ``table`` | ``support`` (``"S1"`` ...), ``ramp_s`` | the static support's lift falls to zero (over ``ramp_s``) |
| ``sensor_loss`` | ``actuator:<name>`` | ``mode`` (``"frozen"``/``"zero"``) | the controller sees a frozen (or zero) stroke for it |
| ``interlock`` | ``table`` | limits (see :class:`Interlock`) | the limit detectors: a trip nulls every valve command and turns the pumps off |

The end cushions need no fault: they are always in the hydraulics (``cushion_length_m``,
``cushion_stiffness_n_m`` of each actuator class); a drive beyond the stroke provokes them.

Two ways in: ``pump_trip`` and ``support_pressure_loss`` act every physics step
(``per_step``, :meth:`apply`, so they work in every stepping loop that runs per-step
effects, the uni-axial analog loop included); ``valve_stuck``, ``sensor_loss`` and the
interlock act at the controller tick (``tick = True``) through :class:`FaultHooks`, which
:meth:`sim.loop.simulation.Simulation.run` calls in its Python (non-fused) path. The
compiled engines (the fused tick, the MuJoCo callback, the batch) refuse them.

Each fault keeps when it took effect (:meth:`Fault.event`); the interlock keeps its trip
(:attr:`Interlock.trip`); :mod:`sim.assess.faults` turns these into the run's summary.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

from sim.effects.base import EFFECTS, Effect, create, register
from sim.errors import ScenarioError

START = ("s", 0.0, 1e6, 0.0)  #: every fault's start time (s of the run; 0: from the start)


def _g_qmax():
    from hydraulics import _layout as HL

    return HL.G_QMAX


class Fault(Effect):
    """A fault: an effect that starts at ``start_s``. ``what`` says it in words;
    ``tick``: it acts at the controller tick (:class:`FaultHooks`), not per step."""

    fault: ClassVar[bool] = True
    tick: ClassVar[bool] = False
    what: ClassVar[str] = ""

    def __init__(self, entry: dict, *, source: str = "fault"):
        super().__init__(entry, source=source)
        self.fired_at: float | None = None
        self.t_origin = 0.0  # the data's time at the start of the run (per-step faults read data.time)
        self.run_end_s: float | None = None

    def check(self, desc) -> None:
        """Raise a one-line :class:`ScenarioError` if the fault names nothing of ``desc``."""

    def actuator_index(self, names) -> int:
        kind, name = self.where.partition(":")[::2]
        if kind != "actuator" or name not in list(names):
            raise ScenarioError(
                f"{self.source}: where = '{self.where}' names no actuator; actuators: {', '.join(names)}"
            )
        return list(names).index(name)

    def reset(self) -> None:
        self.fired_at = None

    def started(self, t: float) -> bool:
        """Is the fault on at run time ``t``? (books the first such time)"""
        if t + 1e-12 < self.values["start_s"]:
            return False
        if self.fired_at is None:
            self.fired_at = float(t)
        return True

    def event(self) -> dict:
        """What happened, where and when (``t_s``: when it took effect; None: the run
        ended before ``start_s``)."""
        return {
            "type": self.type,
            "what": self.what,
            "where": self.where,
            "start_s": self.values["start_s"],
            "t_s": self.fired_at,
            **self.details(),
        }

    def details(self) -> dict:
        return {}


@register
class PumpTrip(Fault):
    """The pumps trip at ``start_s``: the supply flow falls to zero; the accumulators and
    the line compliance give what the valves draw, and the supply pressure falls."""

    type = "pump_trip"
    what = "pump trip: supply flow to zero"
    places = ("supply",)
    per_step = True
    SPEC = {"start_s": START}

    def default_where(self) -> str:
        return "supply"

    def bind(self, model, hydraulics=None) -> None:
        self.hs = hydraulics
        self.q0 = float(hydraulics._G[_g_qmax()]) if hydraulics is not None else 0.0

    def reset(self) -> None:
        super().reset()
        if getattr(self, "hs", None) is not None:
            self.hs._G[_g_qmax()] = self.q0

    def apply(self, model, data) -> None:
        if self.fired_at is None and self.started(data.time - self.t_origin):
            self.hs._G[_g_qmax()] = 0.0

    def details(self) -> dict:
        return {"pump_flow_before_m3_s": getattr(self, "q0", None)}


@register
class ValveStuck(Fault):
    """One servovalve stuck at ``opening`` (fraction of full opening, + extends) from
    ``start_s``, whatever the controller asks; ``opening = 1`` or ``-1`` is hard-over."""

    type = "valve_stuck"
    what = "servovalve stuck"
    places = ("actuator",)
    tick = True
    SPEC = {"opening": ("1", -1.0, 1.0, None), "start_s": START}

    def check(self, desc) -> None:
        self.actuator_index([a.name for a in desc.actuators])

    def bind(self, model, hydraulics=None) -> None:
        if hydraulics is not None:
            self.i = self.actuator_index(hydraulics.params.names)

    def command(self, t: float, cmd: np.ndarray) -> None:
        if self.started(t):
            cmd[self.i] = self.values["opening"]

    def details(self) -> dict:
        o = self.values["opening"]
        return {"opening": o, "hard_over": abs(o) >= 1.0}


@register
class SensorLoss(Fault):
    """The loss of one actuator's stroke feedback (LVDT) from ``start_s``: the controller
    (and the interlock's limit detectors) see its last value (``mode = "frozen"``) or
    zero (``"zero"``: a broken cable reads mid-stroke)."""

    type = "sensor_loss"
    what = "stroke feedback lost"
    places = ("actuator",)
    tick = True
    SPEC = {"start_s": START}
    OPTIONS = {"mode": "frozen"}

    def __init__(self, entry: dict, *, source: str = "fault"):
        super().__init__(entry, source=source)
        if self.options["mode"] not in ("frozen", "zero"):
            raise ScenarioError(f'{source}: mode = {self.options["mode"]!r}; use "frozen" or "zero"')
        self.held = 0.0

    def check(self, desc) -> None:
        self.actuator_index([a.name for a in desc.actuators])

    def bind(self, model, hydraulics=None) -> None:
        if hydraulics is not None:
            self.i = self.actuator_index(hydraulics.params.names)

    def feedback(self, t: float, strokes: np.ndarray) -> None:
        first = self.fired_at is None
        if self.started(t):
            if first:
                self.held = float(strokes[self.i]) if self.options["mode"] == "frozen" else 0.0
            strokes[self.i] = self.held

    def details(self) -> dict:
        return {"mode": self.options["mode"], "reads_m": self.held if self.fired_at is not None else None}


@register
class SupportPressureLoss(Fault):
    """A static support loses its air pressure at ``start_s``: its lift force (preload,
    spring and the air law's non-linear part) falls to zero, linearly over ``ramp_s``
    (0: at once). The platen's weight moves to the vertical actuators."""

    type = "support_pressure_loss"
    what = "static support lost its pressure"
    places = ("table",)
    per_step = True
    SPEC = {"start_s": START, "ramp_s": ("s", 0.0, 100.0, 0.0)}
    OPTIONS = {"support": "S1"}

    def default_where(self) -> str:
        return "table"

    def check(self, desc) -> None:
        sp = getattr(desc, "supports", None)
        n = len(sp.positions_m) if sp is not None else 0
        names = [f"S{i + 1}" for i in range(n)]
        if self.options["support"] not in names:
            have = ", ".join(names) if names else f"none: table '{desc.name}' has no static supports"
            raise ScenarioError(f"{self.source}: support = {self.options['support']!r} names no support ({have})")

    def edit_spec(self, spec, desc) -> None:
        self.check(desc)
        sp = desc.supports
        self.poly = sp.air_law == "polytropic"
        self.c = sp.piston_area_m2 / sp.chamber_volume_m3
        self.n = sp.polytropic_exponent

    def bind(self, model, hydraulics=None) -> None:
        import mujoco

        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"{self.options['support']}_air")
        self.qadr = int(model.jnt_qposadr[j])
        self.dadr = int(model.jnt_dofadr[j])
        self.k = float(model.jnt_stiffness[j])
        self.f0 = self.k * float(model.qpos_spring[self.qadr])
        self.lost_n = self.f0

    def apply(self, model, data) -> None:
        t = data.time - self.t_origin
        if not self.started(t):
            return
        ramp = self.values["ramp_s"]
        frac = 1.0 if ramp <= 0 else min(1.0, (t - self.values["start_s"]) / ramp)
        q = data.qpos[self.qadr]
        lift = self.f0 - self.k * q  # MuJoCo's joint spring
        if self.poly:  # the part the loop adds (sim.loop._kernels.air_springs)
            x = self.c * q
            lift += self.f0 * ((1.0 + x) ** (-self.n) - 1.0 + self.n * x)
        data.qfrc_applied[self.dadr] -= frac * lift

    def details(self) -> dict:
        s = self.options["support"]
        return {"where": f"support:{s}", "support": s, "lift_lost_n": getattr(self, "lost_n", None)}


#: The interlock's limits: key -> (unit, lower, upper, default, why the default).
INTERLOCK_LIMITS = {
    "stroke_fraction": (
        "1",
        0.0,
        1.0,
        0.95,
        "assumed: the stroke limit detectors set at 95 % of the usable stroke (half-stroke less the cushion)",
    ),
    "error_limit_m": (
        "m",
        0.0,
        1.0,
        0.02,
        "assumed: 20 mm stroke error, several times the error of a healthy test at rated motion",
    ),
    "force_fraction": (
        "1",
        0.0,
        2.0,
        0.95,
        "assumed: 95 % of the actuator's stall force (A p_supply set), the force limit detector",
    ),
    "supply_low_fraction": (
        "1",
        0.0,
        1.0,
        0.7,
        "assumed: supply pressure below 70 % of its set pressure (the accumulators nearly at precharge)",
    ),
    "ramp_down_s": (
        "s",
        0.0,
        10.0,
        0.0,
        "assumed: 0, the valve commands to null at once (a hard interlock); > 0 scales them down over that time",
    ),
}


@register
class Interlock(Fault):
    """The controller's interlock (the limit detectors of an MTS 469D-style controller),
    checked at every controller tick on what the controller measures:

    * a stroke beyond ``stroke_fraction`` of the usable stroke (half-stroke - cushion),
    * a stroke error |s_ref - s| beyond ``error_limit_m``,
    * an actuator force beyond ``force_fraction`` of its stall force (A p_set),
    * the supply pressure below ``supply_low_fraction`` of its set pressure.

    The first that trips stops the test: every valve command to null from that tick on
    (or scaled down to null over ``ramp_down_s``) and the pumps off (a stuck valve stays
    where it is stuck); the run goes on to its end (what follows the trip is recorded). Limits: the scenario's ``[interlock]``, else the table's
    ``[interlock]``, else the defaults of :data:`INTERLOCK_LIMITS` (each with its reason).
    """

    type = "interlock"
    what = "interlock"
    places = ("table",)
    tick = True
    SPEC = {k: v[:4] for k, v in INTERLOCK_LIMITS.items()}
    OPTIONS = {"enabled": True}

    def __init__(self, entry: dict, *, source: str = "interlock"):
        super().__init__(entry, source=source)
        if not isinstance(self.options["enabled"], bool):
            raise ScenarioError(f"{source}: 'enabled' must be true or false (got {self.options['enabled']!r})")
        self.trip: dict | None = None

    def default_where(self) -> str:
        return "table"

    def reset(self) -> None:
        super().reset()
        self.trip = None
        if getattr(self, "hs", None) is not None:
            self.hs._G[_g_qmax()] = self.q0

    def bind(self, model, hydraulics=None) -> None:
        self.hs = hydraulics
        if hydraulics is None:
            return
        p = hydraulics.params
        self.q0 = float(hydraulics._G[_g_qmax()])
        self.names = list(p.names)
        self.usable = np.asarray(p.half_stroke_m - p.cushion_length_m, float)
        self.stall = np.asarray(p.area_a_m2, float) * p.supply_pressure_pa
        self.p_set = float(p.supply_pressure_pa)

    def check_tick(self, t: float, s_ref, strokes, force, supply_pressure: float) -> None:
        """Trip if a limit is exceeded at tick time ``t`` (the first trip is kept)."""
        if self.trip is not None:
            return
        v = self.values
        found = None
        lim = v["stroke_fraction"] * self.usable
        over = np.abs(strokes) - lim
        if np.any(over > 0):
            i = int(np.argmax(over))
            found = ("stroke limit", i, float(strokes[i]), float(lim[i]), "m")
        if found is None and s_ref is not None:
            err = np.abs(s_ref - strokes)
            i = int(np.argmax(err))
            if err[i] > v["error_limit_m"]:
                found = ("stroke error limit", i, float(s_ref[i] - strokes[i]), v["error_limit_m"], "m")
        if found is None:
            fl = v["force_fraction"] * self.stall
            over = np.abs(force) - fl
            if np.any(over > 0):
                i = int(np.argmax(over))
                found = ("force limit", i, float(force[i]), float(fl[i]), "N")
        if found is None and supply_pressure < v["supply_low_fraction"] * self.p_set:
            found = ("supply pressure low", None, float(supply_pressure), v["supply_low_fraction"] * self.p_set, "Pa")
        if found is None:
            return
        what, i, value, limit, unit = found
        self.fired_at = float(t)
        self.trip = {
            "what": what,
            "where": "supply" if i is None else f"actuator:{self.names[i]}",
            "t_s": float(t),
            "value": value,
            "limit": limit,
            "unit": unit,
            "action": "valve commands to null"
            + (f" over {v['ramp_down_s']:g} s" if v["ramp_down_s"] > 0 else "")
            + ", pumps off",
        }
        if self.hs is not None:
            self.hs._G[_g_qmax()] = 0.0

    def command(self, t: float, cmd: np.ndarray) -> None:
        if self.trip is not None:
            ramp = self.values["ramp_down_s"]
            cmd *= max(0.0, 1.0 - (t - self.trip["t_s"]) / ramp) if ramp > 0 else 0.0

    def event(self) -> dict:
        return {"type": "interlock", "limits": dict(self.values), "trip": self.trip}


def is_fault(e) -> bool:
    return bool(getattr(e, "fault", False))


def tick_faults(effects) -> list:
    """The faults among ``effects`` that act at the controller tick."""
    return [e for e in effects if is_fault(e) and getattr(e, "tick", False)]


def scenario_entries(
    faults: list, interlock: dict | None, desc, source: str, *, interlock_ok: bool = True
) -> list[dict]:
    """The ``[[effect]]`` entries a scenario adds to its table: its ``[[fault]]`` /
    ``[[effect]]`` entries (each checked against ``desc``; errors name ``source``) and,
    when it declares a fault (and ``interlock_ok``: a loop with controller-tick hooks), the interlock (the table's ``[interlock]`` limits with the
    scenario's ``[interlock]`` on top; ``enabled = false`` leaves it out)."""
    out = []
    for i, entry in enumerate(faults):
        src = f"{source}: [[fault]] #{i + 1}"
        if not isinstance(entry, dict) or "type" not in entry:
            raise ScenarioError(f"{src} needs a 'type' (pump_trip, valve_stuck, support_pressure_loss, sensor_loss)")
        e = create(entry, source=src)
        if isinstance(e, Fault):
            e.check(desc)
        out.append(dict(entry))
    table = desc.raw.get("interlock", {}) or {}
    if not isinstance(table, dict):
        raise ScenarioError(f"{desc.source}: [interlock] must be a table of limits")
    mine = dict(interlock or {})
    armed = (interlock_ok and any(is_fault(_probe(e)) for e in out)) or bool(mine)
    entry = {**{k: v for k, v in table.items()}, **mine}
    entry.pop("type", None)
    entry["type"] = "interlock"
    e = create(entry, source=f"{source}: [interlock] (with {desc.source} [interlock])")
    if armed and e.options["enabled"] and not any(x.get("type") == "interlock" for x in out):
        out.append(entry)
    return out


def _probe(entry: dict):
    return EFFECTS.get(entry.get("type"), Effect)


class FaultHooks:
    """The controller-tick hooks of a run with faults (``valve_stuck``, ``sensor_loss``,
    the interlock): the measured strokes as the feedback faults leave them, the
    controller's tick on them, the interlock's check, then the valve commands as the
    interlock and the stuck valves leave them. Built by :func:`hooks_for`."""

    def __init__(self, sim, effects):
        self.tm, self.ctrl, self.hs = sim.tm, sim.controller, sim.hs
        self.faults = [e for e in effects if is_fault(e)]
        self.feedback = [e for e in self.faults if hasattr(e, "feedback")]
        self.interlocks = [e for e in self.faults if isinstance(e, Interlock)]
        self.commands = self.interlocks + [e for e in self.faults if hasattr(e, "command") and e not in self.interlocks]
        na = self.tm.n_act
        self.x = np.zeros(na)
        self.v6 = np.zeros(6)

    def start(self, d) -> None:
        """Before a run: every fault reset, times counted from the data's time now."""
        for e in self.faults:
            e.reset()
            e.t_origin = float(d.time)

    def tick(self, k: int, t: float, s_ref_all, v_ref_all, vff_all, d, force, supply_pressure, cmd) -> None:
        """The controller tick ``k`` at run time ``t`` with the faults; writes ``cmd``."""
        tm = self.tm
        x, v6 = self.x, self.v6
        x[:] = d.qpos[tm.stroke_qadr]
        for e in self.feedback:
            e.feedback(t, x)
        if tm.platen_free:
            pd = tm.platen_dadr
            v6[:3] = d.qvel[pd : pd + 3]
            v6[3:] = d.xmat[tm.platen_body].reshape(3, 3) @ d.qvel[pd + 3 : pd + 6]
        else:
            v6[:] = 0.0
            v6[tm.platen_dof_index] = d.qvel[tm.platen_slide_dadr]
        self.ctrl.command_fast(s_ref_all[k], v_ref_all[k], vff_all[k], x, v6, force, supply_pressure, cmd)
        for e in self.interlocks:
            e.check_tick(t, s_ref_all[k], x, force, supply_pressure)
        for e in self.commands:
            e.command(t, cmd)


def hooks_for(sim) -> FaultHooks | None:
    """The :class:`FaultHooks` of ``sim`` (None when its model has no fault effect)."""
    effects = list(sim.tm.effects)
    if not any(is_fault(e) for e in effects):
        return None
    return FaultHooks(sim, effects)


__all__ = [
    "INTERLOCK_LIMITS",
    "Fault",
    "FaultHooks",
    "Interlock",
    "PumpTrip",
    "SensorLoss",
    "SupportPressureLoss",
    "ValveStuck",
    "hooks_for",
    "is_fault",
    "scenario_entries",
    "tick_faults",
]
