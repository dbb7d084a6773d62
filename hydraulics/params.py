"""Hydraulic parameters read from a table description (``scenarios/tables/*.toml``).

Every number comes from the table description; the few optional keys that the CGS
description does not carry have documented defaults here (see ``_OPTIONAL``) and can be
given in the description to override them.

Per-actuator quantities (geometry, leakage, friction, cushions) are numpy arrays of shape
``(n_act,)`` in ``[[actuator]]`` order; fluid, supply and servovalve quantities are
scalars (one servovalve specification serves every actuator). A few of those scalars can
be overridden per actuator (``PER_ACTUATOR``: valve delay, time constant, natural
frequency, flow gain, null offset, chamber bulk modulus): the override arrays are None
(every actuator takes the scalar) unless an effect sets them
(``sim.effects.hydraulic``); :meth:`HydraulicParams.per_actuator` gives the values in use.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np


class HydraulicsParamError(ValueError):
    """A hydraulic parameter that is missing or out of range (one-line message naming it)."""


# Optional keys: (section, key) -> default. Documented choices, not table data.
_OPTIONAL = {
    # Entrained-air model of the effective bulk modulus (0 = off: constant bulk modulus).
    ("fluid", "entrained_air_fraction"): 0.0,  # volume fraction of free air at atmospheric pressure
    ("fluid", "air_polytropic_exponent"): 1.4,
    ("fluid", "atmospheric_pressure_pa"): 101325.0,
    # Oil volume of the supply lines and manifolds between pumps/accumulators and valves;
    # it only matters once the accumulators are drained (it sets how fast the supply
    # pressure collapses then).
    ("supply", "line_volume_m3"): 0.05,
    ("supply", "line_resistance_pa_s_m3"): 0.0,
    # Stribeck seal friction (static level > Coulomb level turns it on) and the velocity
    # scale of the smooth sign used for the Coulomb part.
    ("actuator_class", "seal_static_friction_n"): None,  # None -> equal to seal_friction_n (no Stribeck)
    ("actuator_class", "stribeck_velocity_m_s"): 0.01,
    ("actuator_class", "friction_smoothing_m_s"): 1.0e-3,
}

_CLASS_KEYS = (
    "half_stroke_m",
    "area_a_m2",
    "area_b_m2",
    "dead_volume_a_m3",
    "dead_volume_b_m3",
    "leakage_cross_m3_s_pa",
    "leakage_external_m3_s_pa",
    "seal_friction_n",
    "seal_viscous_n_s_m",
    "cushion_length_m",
    "cushion_stiffness_n_m",
)


def _get(d: dict, section: str, key: str, where: str | None = None):
    where = where or section
    if key not in d:
        raise HydraulicsParamError(f"{where}.{key} is missing from the table description")
    val = d[key]
    if isinstance(val, bool) or not isinstance(val, (int, float)):
        raise HydraulicsParamError(f"{where}.{key} must be a number (got {val!r})")
    if val != val or val in (float("inf"), float("-inf")):
        raise HydraulicsParamError(f"{where}.{key} must be finite (got {val!r})")
    return float(val)


def _section(table: dict, name: str) -> dict:
    sec = table.get(name)
    if not isinstance(sec, dict):
        raise HydraulicsParamError(f"[{name}] section is missing from the table description")
    return sec


@dataclass
class HydraulicParams:
    """All hydraulic parameters of one table (SI units).

    Servovalve flow convention: ``rated_flow_m3_s`` is the flow at full opening with no
    load when the TOTAL drop across the valve is ``rated_drop_pa``, i.e. two metering lands
    in series (P->A and B->T, or P->B and A->T) each dropping ``rated_drop_pa / 2``.
    """

    names: tuple
    classes: tuple
    # fluid
    bulk_modulus_pa: float
    vapour_pressure_pa: float
    relief_pressure_pa: float
    entrained_air_fraction: float
    air_polytropic_exponent: float
    atmospheric_pressure_pa: float
    # supply
    supply_pressure_pa: float
    return_pressure_pa: float
    pump_flow_m3_s: float
    accumulator_volume_m3: float
    accumulator_precharge_pa: float
    polytropic_exponent: float
    line_volume_m3: float
    line_resistance_pa_s_m3: float
    # servovalve
    rated_flow_m3_s: float
    rated_drop_pa: float
    model: str
    tau_s: float
    natural_frequency_hz: float
    damping_ratio: float
    delay_s: float
    slew_limit_per_s: float
    laminar_drop_pa: float
    null_leakage_m3_s: float
    overlap: float
    # actuators, arrays (n_act,)
    half_stroke_m: np.ndarray
    area_a_m2: np.ndarray
    area_b_m2: np.ndarray
    dead_volume_a_m3: np.ndarray
    dead_volume_b_m3: np.ndarray
    leakage_cross_m3_s_pa: np.ndarray
    leakage_external_m3_s_pa: np.ndarray
    seal_friction_n: np.ndarray
    seal_viscous_n_s_m: np.ndarray
    cushion_length_m: np.ndarray
    cushion_stiffness_n_m: np.ndarray
    seal_static_friction_n: np.ndarray
    stribeck_velocity_m_s: np.ndarray
    friction_smoothing_m_s: np.ndarray
    # per-actuator overrides (None: the scalar above for every actuator; see PER_ACTUATOR)
    valve_delay_s: np.ndarray | None = None
    valve_tau_s: np.ndarray | None = None
    valve_natural_frequency_hz: np.ndarray | None = None
    valve_flow_gain: np.ndarray | None = None
    valve_null_offset: np.ndarray | None = None
    chamber_bulk_modulus_pa: np.ndarray | None = None

    @property
    def n_act(self) -> int:
        return len(self.names)

    def per_actuator(self, name: str) -> np.ndarray:
        """The (n_act,) values in use of an overridable quantity (a copy): the override
        array if set, else its scalar (``PER_ACTUATOR[name]``) for every actuator."""
        base, _rule = PER_ACTUATOR[name]
        arr = getattr(self, name)
        if arr is not None:
            return np.array(arr, dtype=np.float64)
        val = getattr(self, base) if isinstance(base, str) else base
        return np.full(self.n_act, float(val))

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_table(cls, table: dict) -> "HydraulicParams":
        """Build from ``tomllib.load(...)`` of a table description and validate."""
        if not isinstance(table, dict):
            raise HydraulicsParamError("table description must be a dict (tomllib.load of the TOML)")
        fl = _section(table, "fluid")
        su = _section(table, "supply")
        sv = _section(table, "servovalve")
        classes = table.get("actuator_class")
        if not isinstance(classes, dict) or not classes:
            raise HydraulicsParamError("[actuator_class.<name>] sections are missing from the table description")
        acts = table.get("actuator")
        if not isinstance(acts, list) or not acts:
            raise HydraulicsParamError("[[actuator]] entries are missing from the table description")

        def opt(sec: dict, section: str, key: str, where: str | None = None):
            if key in sec:
                return _get(sec, section, key, where)
            return _OPTIONAL[(section, key)]

        names, cls_names = [], []
        per = {k: [] for k in _CLASS_KEYS}
        per_opt = {"seal_static_friction_n": [], "stribeck_velocity_m_s": [], "friction_smoothing_m_s": []}
        for i, a in enumerate(acts):
            if not isinstance(a, dict) or "name" not in a:
                raise HydraulicsParamError(f"actuator[{i}].name is missing from the table description")
            if "class" not in a:
                raise HydraulicsParamError(f"actuator[{i}].class is missing from the table description")
            cname = a["class"]
            if cname not in classes:
                raise HydraulicsParamError(
                    f"actuator[{i}].class must name an [actuator_class.<name>] section (got {cname!r})"
                )
            c = classes[cname]
            where = f"actuator_class.{cname}"
            names.append(str(a["name"]))
            cls_names.append(cname)
            for k in _CLASS_KEYS:
                per[k].append(_get(c, "actuator_class", k, where))
            fc = per["seal_friction_n"][-1]
            st = opt(c, "actuator_class", "seal_static_friction_n", where)
            per_opt["seal_static_friction_n"].append(fc if st is None else st)
            per_opt["stribeck_velocity_m_s"].append(opt(c, "actuator_class", "stribeck_velocity_m_s", where))
            per_opt["friction_smoothing_m_s"].append(opt(c, "actuator_class", "friction_smoothing_m_s", where))
        if len(set(names)) != len(names):
            raise HydraulicsParamError(f"actuator.name must be unique (got {names})")

        model = sv.get("model", None)
        if model is None:
            raise HydraulicsParamError("servovalve.model is missing from the table description")

        p = cls(
            names=tuple(names),
            classes=tuple(cls_names),
            bulk_modulus_pa=_get(fl, "fluid", "bulk_modulus_pa"),
            vapour_pressure_pa=_get(fl, "fluid", "vapour_pressure_pa"),
            relief_pressure_pa=_get(fl, "fluid", "relief_pressure_pa"),
            entrained_air_fraction=opt(fl, "fluid", "entrained_air_fraction"),
            air_polytropic_exponent=opt(fl, "fluid", "air_polytropic_exponent"),
            atmospheric_pressure_pa=opt(fl, "fluid", "atmospheric_pressure_pa"),
            supply_pressure_pa=_get(su, "supply", "pressure_pa"),
            return_pressure_pa=_get(su, "supply", "return_pressure_pa"),
            pump_flow_m3_s=_get(su, "supply", "pump_flow_m3_s"),
            accumulator_volume_m3=_get(su, "supply", "accumulator_volume_m3"),
            accumulator_precharge_pa=_get(su, "supply", "accumulator_precharge_pa"),
            polytropic_exponent=_get(su, "supply", "polytropic_exponent"),
            line_volume_m3=opt(su, "supply", "line_volume_m3"),
            line_resistance_pa_s_m3=opt(su, "supply", "line_resistance_pa_s_m3"),
            rated_flow_m3_s=_get(sv, "servovalve", "rated_flow_m3_s"),
            rated_drop_pa=_get(sv, "servovalve", "rated_drop_pa"),
            model=str(model),
            tau_s=_get(sv, "servovalve", "tau_s"),
            natural_frequency_hz=_get(sv, "servovalve", "natural_frequency_hz"),
            damping_ratio=_get(sv, "servovalve", "damping_ratio"),
            delay_s=_get(sv, "servovalve", "delay_s"),
            slew_limit_per_s=_get(sv, "servovalve", "slew_limit_per_s"),
            laminar_drop_pa=_get(sv, "servovalve", "laminar_drop_pa"),
            null_leakage_m3_s=_get(sv, "servovalve", "null_leakage_m3_s"),
            overlap=_get(sv, "servovalve", "overlap"),
            **{k: np.array(v, dtype=np.float64) for k, v in per.items()},
            **{k: np.array(v, dtype=np.float64) for k, v in per_opt.items()},
        )
        p.validate()
        return p

    # ------------------------------------------------------------------ validation
    def _where(self, i: int) -> str:
        return f"actuator_class.{self.classes[i]}" if self.classes else f"actuator[{i}]"

    def validate(self) -> None:
        """Raise :class:`HydraulicsParamError` (one line, naming the parameter) if anything is off."""
        n = len(self.names)
        if n == 0:
            raise HydraulicsParamError("actuator list must not be empty")
        if len(self.classes) not in (0, n):
            raise HydraulicsParamError(f"classes must have {n} entries (got {len(self.classes)})")
        for name, (cond, expect) in _SCALAR_RULES.items():
            sec, key = name.split(".")
            attr = {"pressure_pa": "supply_pressure_pa"}.get(key, key) if sec == "supply" else key
            _check_number(name, getattr(self, attr), cond, expect)
        self._validate_relations()
        self._validate_arrays(n)

    def _validate_relations(self) -> None:
        """The scalars' mutual order: vapour < return < supply < relief pressure, a precharge
        below the supply, a laminar drop below half the rated drop, null leakage below the
        rated flow; only the modelled valve models and no supply-line loss."""
        if self.line_resistance_pa_s_m3 != 0.0:
            raise HydraulicsParamError(
                f"supply.line_resistance_pa_s_m3 must be 0 (supply line loss is not modelled; got {self.line_resistance_pa_s_m3!r})"
            )
        if self.model not in ("first", "second"):
            raise HydraulicsParamError(f'servovalve.model must be "first" or "second" (got {self.model!r})')
        if (
            not self.vapour_pressure_pa < self.return_pressure_pa
            or not self.return_pressure_pa < self.supply_pressure_pa
        ):
            raise HydraulicsParamError(
                "supply.return_pressure_pa must lie between fluid.vapour_pressure_pa and supply.pressure_pa "
                f"(got {self.return_pressure_pa!r})"
            )
        if not self.supply_pressure_pa < self.relief_pressure_pa:
            raise HydraulicsParamError(
                f"fluid.relief_pressure_pa must be > supply.pressure_pa (got {self.relief_pressure_pa!r})"
            )
        if self.accumulator_volume_m3 > 0 and not self.accumulator_precharge_pa < self.supply_pressure_pa:
            raise HydraulicsParamError(
                f"supply.accumulator_precharge_pa must be < supply.pressure_pa (got {self.accumulator_precharge_pa!r})"
            )
        if not self.laminar_drop_pa < 0.5 * self.rated_drop_pa:
            raise HydraulicsParamError(
                f"servovalve.laminar_drop_pa must be < rated_drop_pa / 2 (got {self.laminar_drop_pa!r})"
            )
        if self.null_leakage_m3_s >= self.rated_flow_m3_s:
            raise HydraulicsParamError(
                f"servovalve.null_leakage_m3_s must be < rated_flow_m3_s (got {self.null_leakage_m3_s!r})"
            )

    def _validate_arrays(self, n: int) -> None:
        """The per-actuator arrays (class values and overrides): shape (n,), each value
        checked; stored as float64 arrays. A cushion shorter than the half-stroke."""
        for key, (cond, expect) in _ARRAY_RULES.items():
            arr = np.asarray(getattr(self, key), dtype=np.float64)
            if arr.shape != (n,):
                raise HydraulicsParamError(f"{key} must have shape ({n},) (got {arr.shape})")
            setattr(self, key, arr)
            for i in range(n):
                _check_number(f"{self._where(i)}.{key}", arr[i], cond, expect)
        for key, (_base, (cond, expect)) in PER_ACTUATOR.items():
            arr = getattr(self, key)
            if arr is None:
                continue
            arr = np.asarray(arr, dtype=np.float64)
            if arr.shape != (n,):
                raise HydraulicsParamError(f"{key} must have shape ({n},) (got {arr.shape})")
            setattr(self, key, arr)
            for i in range(n):
                _check_number(f"actuator {self.names[i]} {key}", arr[i], cond, expect)
        for i in range(n):
            if self.cushion_length_m[i] >= self.half_stroke_m[i]:
                raise HydraulicsParamError(
                    f"{self._where(i)}.cushion_length_m must be < half_stroke_m (got {self.cushion_length_m[i]!r})"
                )

    def copy(self) -> "HydraulicParams":
        kw = {}
        for f in fields(self):
            v = getattr(self, f.name)
            kw[f.name] = v.copy() if isinstance(v, np.ndarray) else v
        return HydraulicParams(**kw)


#: overridable per-actuator quantities: name -> (the scalar field or the default value,
#: (condition, expectation) of its values)
PER_ACTUATOR = {
    "valve_delay_s": ("delay_s", (lambda v: v >= 0, ">= 0")),
    "valve_tau_s": ("tau_s", (lambda v: v > 0, "> 0")),
    "valve_natural_frequency_hz": ("natural_frequency_hz", (lambda v: v > 0, "> 0")),
    "valve_flow_gain": (1.0, (lambda v: v > 0, "> 0")),
    "valve_null_offset": (0.0, (lambda v: -1.0 < v < 1.0, "in (-1, 1)")),
    "chamber_bulk_modulus_pa": ("bulk_modulus_pa", (lambda v: v > 0, "> 0")),
}


def _check_number(name, val, cond, expect) -> None:
    """A finite number meeting ``cond``, else a one-line error naming ``name``."""
    try:
        v = float(val)
    except (TypeError, ValueError):
        raise HydraulicsParamError(f"{name} must be a number (got {val!r})") from None
    if not math.isfinite(v) or not cond(v):
        shown = repr(v) if isinstance(val, (int, float, np.floating, np.integer)) else repr(val)
        raise HydraulicsParamError(f"{name} must be {expect} (got {shown})")


_POS = (lambda v: v > 0, "> 0")
_NONNEG = (lambda v: v >= 0, ">= 0")
_AT_LEAST_1 = (lambda v: v >= 1.0, ">= 1")
#: the scalar parameters' conditions, by their table key
_SCALAR_RULES = {
    "fluid.bulk_modulus_pa": _POS,
    "fluid.vapour_pressure_pa": _NONNEG,
    "fluid.relief_pressure_pa": _POS,
    "fluid.entrained_air_fraction": _NONNEG,
    "fluid.air_polytropic_exponent": _AT_LEAST_1,
    "fluid.atmospheric_pressure_pa": _POS,
    "supply.pressure_pa": _POS,
    "supply.return_pressure_pa": _NONNEG,
    "supply.pump_flow_m3_s": _NONNEG,
    "supply.accumulator_volume_m3": _NONNEG,
    "supply.accumulator_precharge_pa": _POS,
    "supply.polytropic_exponent": _AT_LEAST_1,
    "supply.line_volume_m3": _POS,
    "servovalve.rated_flow_m3_s": _POS,
    "servovalve.rated_drop_pa": _POS,
    "servovalve.tau_s": _POS,
    "servovalve.natural_frequency_hz": _POS,
    "servovalve.damping_ratio": _POS,
    "servovalve.delay_s": _NONNEG,
    "servovalve.slew_limit_per_s": _NONNEG,
    "servovalve.laminar_drop_pa": _POS,
    "servovalve.null_leakage_m3_s": _NONNEG,
    "servovalve.overlap": (lambda v: 0.0 <= v < 1.0, "in [0, 1)"),
}
#: the per-actuator class arrays' conditions
_ARRAY_RULES = {
    "half_stroke_m": _POS,
    "area_a_m2": _POS,
    "area_b_m2": _POS,
    "dead_volume_a_m3": _POS,
    "dead_volume_b_m3": _POS,
    "leakage_cross_m3_s_pa": _NONNEG,
    "leakage_external_m3_s_pa": _NONNEG,
    "seal_friction_n": _NONNEG,
    "seal_viscous_n_s_m": _NONNEG,
    "cushion_length_m": _NONNEG,
    "cushion_stiffness_n_m": _NONNEG,
    "seal_static_friction_n": _NONNEG,
    "stribeck_velocity_m_s": _POS,
    "friction_smoothing_m_s": _POS,
}
