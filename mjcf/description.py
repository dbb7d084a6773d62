"""Table and payload descriptions: the one place a table is described.

A table description is a TOML file in ``scenarios/tables/`` (see ``cgs.toml``); a payload
description is a TOML file in ``scenarios/payloads/``. Everything else (the MJCF scene,
the hydraulic parameters, the controller's geometry) is derived from these objects.

All quantities are SI. Loading validates every field: a missing field, an unknown key,
a negative mass, duplicate actuator names, or an actuator whose stroke cannot reach the
rated motion raise :class:`DescriptionError` with one line that names the field and what
was expected.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjcf.errors import DescriptionError
from mjcf.kinematics import actuator_strokes, envelope_corners, rotation_matrices, rotation_matrix  # noqa: F401
from mjcf.unknowns import parse_unknowns

REPO_ROOT = Path(__file__).resolve().parent.parent
TABLES_DIR = REPO_ROOT / "scenarios" / "tables"
PAYLOADS_DIR = REPO_ROOT / "scenarios" / "payloads"

DOFS6 = ("x", "y", "z", "rx", "ry", "rz")


# --------------------------------------------------------------------------- helpers
def suggest(key, known) -> str:
    """`` (did you mean 'x'?)`` for the closest of ``known``, or ``""`` (the same hint as
    ``sim.validate.suggest``; mjcf imports nothing from sim)."""
    close = difflib.get_close_matches(str(key), sorted(str(k) for k in known), n=1, cutoff=0.6)
    return f" (did you mean '{close[0]}'?)" if close else ""


class _Section:
    """Reads keys from one TOML table, remembering which were used.

    ``done()`` refuses keys nobody asked for, so a misspelt key is an error rather than a
    silently ignored setting.
    """

    def __init__(self, data, path: str, src: str):
        if not isinstance(data, dict):
            raise DescriptionError(f"{src}: [{path}] must be a table of keys")
        self.data = data
        self.path = path
        self.src = src
        self.used: set[str] = set()
        self.asked: set[str] = set()  # every key read, present or not (for the closest-key hint)

    def _name(self, key):
        return f"{self.path}.{key}" if self.path else key

    def has(self, key):
        self.asked.add(key)
        return key in self.data

    def raw(self, key, default=...):
        self.asked.add(key)
        if key not in self.data:
            if default is ...:
                typo = difflib.get_close_matches(str(key), [str(k) for k in self.data if k not in self.used], 1, 0.6)
                hint = f" (found '{typo[0]}': a misspelling of '{key}'?)" if typo else ""
                raise DescriptionError(f"{self.src}: missing field '{self._name(key)}'{hint}")
            return default
        self.used.add(key)
        return self.data[key]

    def num(self, key, default=..., *, positive=False, nonneg=False):
        v = self.raw(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise DescriptionError(f"{self.src}: '{self._name(key)}' must be a number (got {v!r})")
        v = float(v)
        if not math.isfinite(v):
            raise DescriptionError(f"{self.src}: '{self._name(key)}' must be finite (got {v})")
        if positive and v <= 0:
            raise DescriptionError(f"{self.src}: '{self._name(key)}' must be > 0 (got {v:g})")
        if nonneg and v < 0:
            raise DescriptionError(f"{self.src}: '{self._name(key)}' must be >= 0 (got {v:g})")
        return v

    def vec(self, key, n, default=..., *, positive=False, nonneg=False):
        v = self.raw(key, default)
        if not isinstance(v, (list, tuple)) or len(v) != n:
            raise DescriptionError(f"{self.src}: '{self._name(key)}' must be a list of {n} numbers (got {v!r})")
        out = []
        for x in v:
            if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(float(x)):
                raise DescriptionError(f"{self.src}: '{self._name(key)}' must hold finite numbers (got {v!r})")
            if positive and x <= 0:
                raise DescriptionError(f"{self.src}: '{self._name(key)}' entries must be > 0 (got {v!r})")
            if nonneg and x < 0:
                raise DescriptionError(f"{self.src}: '{self._name(key)}' entries must be >= 0 (got {v!r})")
            out.append(float(x))
        return np.array(out)

    def text(self, key, default=..., choices=None):
        v = self.raw(key, default)
        if not isinstance(v, str):
            raise DescriptionError(f"{self.src}: '{self._name(key)}' must be text (got {v!r})")
        if choices is not None and v not in choices:
            raise DescriptionError(f"{self.src}: '{self._name(key)}' must be one of {', '.join(choices)} (got {v!r})")
        return v

    def sub(self, key, default=...):
        return _Section(self.raw(key, default), self._name(key), self.src)

    def done(self):
        extra = sorted(set(self.data) - self.used)
        if extra:
            where = f"[{self.path}]" if self.path else "the top level"
            known = sorted(self.asked | self.used)
            raise DescriptionError(
                f"{self.src}: unknown key '{extra[0]}' in {where}{suggest(extra[0], known)}; "
                f"known keys: {', '.join(known)}"
            )


# --------------------------------------------------------------------------- table
@dataclass(frozen=True, kw_only=True)
class Limits:
    """Rated motion at the reference point (SI)."""

    stroke_m: np.ndarray  #: (3,) half-strokes x, y, z
    rotation_rad: np.ndarray  #: (3,) half-range rx, ry, rz
    velocity_m_s: np.ndarray  #: (3,)
    acceleration_m_s2: np.ndarray  #: (3,)
    max_specimen_kg: float | None  #: None: the rating is unknown (``max_specimen_kg = "unknown"``)
    overturning_moment_n_m: float | None  #: None: the rating is unknown (``"unknown"``)
    frequency_range_hz: np.ndarray


@dataclass(frozen=True, kw_only=True)
class Platen:
    size_m: np.ndarray  #: (3,) length x, width y, depth z
    guided: bool = False  #: True: the platen moves only along the table's DOFs (linear bearings)
    com_m: np.ndarray  #: (3,) centre of mass in the table frame
    mass_kg: float
    inertia_kg_m2: np.ndarray  #: (3,) principal moments about the centre of mass


@dataclass(frozen=True, kw_only=True)
class Foundation:
    mode: str  #: "fixed" or "spring"
    mass_kg: float
    frequency_hz: np.ndarray  #: (3,) used with mode "spring"
    damping_ratio: np.ndarray  #: (3,)


@dataclass(frozen=True, kw_only=True)
class ActuatorClass:
    name: str
    half_stroke_m: float
    area_a_m2: float
    area_b_m2: float
    dead_volume_a_m3: float
    dead_volume_b_m3: float
    seal_friction_n: float
    seal_viscous_n_s_m: float
    cylinder_mass_kg: float
    cylinder_length_m: float
    cylinder_radius_m: float
    rod_mass_kg: float
    rod_length_m: float
    rod_radius_m: float


@dataclass(frozen=True, kw_only=True)
class Actuator:
    name: str
    cls: ActuatorClass
    base_m: np.ndarray  #: (3,) foundation swivel, table frame
    platen_m: np.ndarray  #: (3,) platen swivel at the home pose, table frame

    @property
    def length0_m(self) -> float:
        """Swivel-to-swivel length at mid-stroke (home pose)."""
        return float(np.linalg.norm(self.platen_m - self.base_m))

    @property
    def axis(self) -> np.ndarray:
        """Unit vector from base to platen swivel (direction of extension)."""
        d = self.platen_m - self.base_m
        return d / np.linalg.norm(d)


@dataclass(frozen=True, kw_only=True)
class Supports:
    capacity_kg: float
    positions_m: np.ndarray  #: (n, 3) top pins under the platen
    piston_area_m2: float
    chamber_volume_m3: float
    polytropic_exponent: float
    piston_mass_kg: float
    shoe_mass_kg: float
    piston_friction_n: float
    shoe_friction_n: float
    piston_radius_m: float
    piston_length_m: float
    #: "polytropic": the chamber force p0 A (V0 / (V0 + A q))^n (MuJoCo carries its linear
    #: part as the joint spring, the loop adds the rest); "linear": the joint spring alone
    air_law: str = "polytropic"


@dataclass(frozen=True, kw_only=True)
class Accelerometer:
    name: str
    position_m: np.ndarray
    direction: np.ndarray


@dataclass(frozen=True, kw_only=True)
class TableDescription:
    """A whole table, validated. ``raw`` keeps the parsed TOML for the hydraulics."""

    name: str
    title: str
    dofs: tuple[str, ...]
    gravity_m_s2: float
    limits: Limits
    platen: Platen
    foundation: Foundation
    actuator_classes: dict[str, ActuatorClass]
    actuators: tuple[Actuator, ...]
    supports: Supports | None
    accelerometers: tuple[Accelerometer, ...]
    recorder_rate_hz: float
    accelerometer_bandwidth_hz: float
    source: str
    raw: dict = field(repr=False)
    effects: tuple = ()  #: [[effect]] entries (sim/effects/registry.py), validated when the model is built
    friction_model: str = "coulomb"  #: "coulomb" (MuJoCo frictionloss) or "presliding" (sim/loop/simulation.py)
    friction_presliding_m: float = 1e-4  #: pre-sliding displacement of the "presliding" model
    #: ``[unknown]``: dotted key -> (LO, HI) of the values the lab does not know (mjcf/unknowns.py)
    unknowns: dict = field(default_factory=dict)
    accelerometer_filter_order: int = 4  #: poles of the accelerometers' analog conditioner (Butterworth)

    @property
    def actuator_names(self) -> tuple[str, ...]:
        return tuple(a.name for a in self.actuators)

    def actuator(self, name: str) -> Actuator:
        for a in self.actuators:
            if a.name == name:
                return a
        raise DescriptionError(f"no actuator named '{name}'; actuators are {', '.join(self.actuator_names)}")


def load_toml(path: Path, error: type[Exception] = DescriptionError, what: str = "file") -> dict:
    """Parse a TOML file; a missing, unreadable or malformed file raises ``error`` (one line)."""
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise error(f"{path}: no such {what}") from None
    except tomllib.TOMLDecodeError as e:
        raise error(f"{path}: not valid TOML ({e})") from None
    except (IsADirectoryError, PermissionError, UnicodeDecodeError) as e:
        raise error(f"{path}: cannot be read ({e.__class__.__name__})") from None


_load_toml = load_toml


def resolve(name_or_path: str | Path, folder: Path, kind: str) -> Path:
    """A bare name ('cgs') is looked up in ``folder``; anything else is a path."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        return p
    cand = folder / f"{name_or_path}.toml"
    if cand.exists():
        return cand
    known = sorted(x.stem for x in folder.glob("*.toml"))
    raise DescriptionError(
        f"no {kind} named '{name_or_path}'{suggest(name_or_path, known)}; known {kind}s: "
        f"{', '.join(known)} (or give a path to a .toml file)"
    )


def load_table(name_or_path: str | Path) -> TableDescription:
    """Load and validate a table description by name (``"cgs"``) or path."""
    path = resolve(name_or_path, TABLES_DIR, "table")
    data = _load_toml(path)
    desc = parse_table(data, src=str(path))
    check_hydraulics(data, str(path))
    return desc


def check_hydraulics(data: dict, src: str) -> None:
    """The hydraulic sections ([fluid], [supply], [servovalve], actuator classes), checked
    when the file is read (hydraulics.HydraulicParams reads them), so that a mistake there
    is reported with the file's name before any model is built."""
    from hydraulics import HydraulicParams, HydraulicsParamError

    try:
        HydraulicParams.from_table(data)
    except HydraulicsParamError as e:
        raise DescriptionError(f"{src}: {e}") from None


def parse_table(data: dict, src: str = "<table>") -> TableDescription:
    """Validate a table file's data section by section (each part below reads one) and
    build its description; the first mistake raises a DescriptionError naming ``src``."""
    top = _Section(data, "", src)
    name, title, dofs, g = _parse_header(top, src)
    limits = _parse_limits(top)
    platen = _parse_platen(top, dofs, src)
    foundation = _parse_foundation(top)
    classes = _parse_actuator_classes(top)
    actuators = _parse_actuators(top, classes, src)
    supports = _parse_supports(top, src) if top.has("supports") else None
    bw, rate, order = _parse_sensors(top, src)
    accs = _parse_accelerometers(top, src)
    fmodel, fpre, effects = _parse_other_sections(top, src)
    top.done()

    desc = TableDescription(
        name=name,
        title=title,
        dofs=tuple(dofs),
        gravity_m_s2=g,
        limits=limits,
        platen=platen,
        foundation=foundation,
        actuator_classes=classes,
        actuators=tuple(actuators),
        supports=supports,
        accelerometers=tuple(accs),
        recorder_rate_hz=rate,
        accelerometer_bandwidth_hz=bw,
        source=src,
        raw=data,
        effects=tuple(effects),
        friction_model=fmodel,
        friction_presliding_m=fpre,
        unknowns=parse_unknowns(data, src),
        accelerometer_filter_order=order,
    )
    check_stroke_reach(desc)
    return desc


def _parse_header(top: _Section, src: str):
    """[table]: name, title, the platen's degrees of freedom and gravity."""
    t = top.sub("table")
    name = t.text("name")
    title = t.text("title", name)
    dofs = t.raw("dofs")
    if not isinstance(dofs, list) or not all(isinstance(d, str) for d in dofs) or not dofs:
        raise DescriptionError(f"{src}: 'table.dofs' must be a list of DOF names")
    if any(d not in DOFS6 for d in dofs) or len(set(dofs)) != len(dofs):
        raise DescriptionError(f"{src}: 'table.dofs' must be distinct names from {', '.join(DOFS6)} (got {dofs})")
    g = t.num("gravity_m_s2", positive=True)
    t.done()
    return name, title, dofs, g


def _parse_limits(top: _Section) -> Limits:
    """[limits]: the table's rated envelope ("unknown" where the lab does not state it)."""
    li = top.sub("limits")
    limits = Limits(
        stroke_m=li.vec("stroke_m", 3, nonneg=True),
        rotation_rad=li.vec("rotation_rad", 3, nonneg=True),
        velocity_m_s=li.vec("velocity_m_s", 3, nonneg=True),
        acceleration_m_s2=li.vec("acceleration_m_s2", 3, nonneg=True),
        max_specimen_kg=None if li.raw("max_specimen_kg") == "unknown" else li.num("max_specimen_kg", nonneg=True),
        overturning_moment_n_m=None
        if li.raw("overturning_moment_n_m") == "unknown"
        else li.num("overturning_moment_n_m", nonneg=True),
        frequency_range_hz=li.vec("frequency_range_hz", 2, nonneg=True),
    )
    li.done()
    return limits


def _parse_platen(top: _Section, dofs: list, src: str) -> Platen:
    """[platen]: rigid-body properties and whether bearings guide it (translations only)."""
    pl = top.sub("platen")
    guide = pl.text("guide", "free", choices=("free", "bearings"))
    if guide == "bearings" and any(d in ("rx", "ry", "rz") for d in dofs):
        raise DescriptionError(
            f"{src}: 'platen.guide = \"bearings\"' allows translations only; table.dofs has rotations"
        )
    platen = Platen(
        guided=(guide == "bearings"),
        size_m=pl.vec("size_m", 3, positive=True),
        com_m=pl.vec("com_m", 3),
        mass_kg=pl.num("mass_kg", positive=True),
        inertia_kg_m2=pl.vec("inertia_kg_m2", 3, positive=True),
    )
    pl.done()
    _check_inertia(platen.inertia_kg_m2, f"{src}: 'platen.inertia_kg_m2'")
    return platen


def _parse_foundation(top: _Section) -> Foundation:
    """[foundation]: fixed, or a reaction mass on springs."""
    fo = top.sub("foundation")
    foundation = Foundation(
        mode=fo.text("mode", choices=("fixed", "spring")),
        mass_kg=fo.num("mass_kg", positive=True),
        frequency_hz=fo.vec("frequency_hz", 3, positive=True),
        damping_ratio=fo.vec("damping_ratio", 3, nonneg=True),
    )
    fo.done()
    return foundation


#: actuator-class keys read by the hydraulics package only; checked for sign here.
_HYDRAULIC_CLASS_KEYS = (
    "leakage_cross_m3_s_pa",
    "leakage_external_m3_s_pa",
    "cushion_length_m",
    "cushion_stiffness_n_m",
    "seal_static_friction_n",
    "stribeck_velocity_m_s",
    "friction_smoothing_m_s",
)


def _parse_actuator_classes(top: _Section) -> dict:
    """[actuator_class.NAME]: the geometry and seals of each kind of actuator."""
    classes = {}
    ac_all = top.sub("actuator_class")
    for cname in list(ac_all.data):
        c = ac_all.sub(cname)
        classes[cname] = ActuatorClass(
            name=cname,
            half_stroke_m=c.num("half_stroke_m", positive=True),
            area_a_m2=c.num("area_a_m2", positive=True),
            area_b_m2=c.num("area_b_m2", positive=True),
            dead_volume_a_m3=c.num("dead_volume_a_m3", positive=True),
            dead_volume_b_m3=c.num("dead_volume_b_m3", positive=True),
            seal_friction_n=c.num("seal_friction_n", nonneg=True),
            seal_viscous_n_s_m=c.num("seal_viscous_n_s_m", nonneg=True),
            cylinder_mass_kg=c.num("cylinder_mass_kg", positive=True),
            cylinder_length_m=c.num("cylinder_length_m", positive=True),
            cylinder_radius_m=c.num("cylinder_radius_m", positive=True),
            rod_mass_kg=c.num("rod_mass_kg", positive=True),
            rod_length_m=c.num("rod_length_m", positive=True),
            rod_radius_m=c.num("rod_radius_m", positive=True),
        )
        # Hydraulic-only keys are validated by the hydraulics package; mark them used.
        for k in _HYDRAULIC_CLASS_KEYS:
            if c.has(k):
                c.num(k, nonneg=True)
        c.done()
        ac_all.used.add(cname)
    return classes


def _parse_actuators(top: _Section, classes: dict, src: str) -> list:
    """[[actuator]]: each linkage's class and its two attachment points."""
    acts_raw = top.raw("actuator")
    if not isinstance(acts_raw, list) or not acts_raw:
        raise DescriptionError(f"{src}: '[[actuator]]' must list at least one actuator")
    actuators = []
    seen = set()
    for i, a_raw in enumerate(acts_raw):
        a = _Section(a_raw, f"actuator[{i}]", src)
        nm = a.text("name")
        if nm in seen:
            raise DescriptionError(f"{src}: two actuators are named '{nm}'; actuator names must be unique")
        seen.add(nm)
        cname = a.text("class")
        if cname not in classes:
            raise DescriptionError(f"{src}: actuator '{nm}' has class '{cname}'; known classes: {', '.join(classes)}")
        base = a.vec("base_m", 3)
        plat = a.vec("platen_m", 3)
        a.done()
        if np.linalg.norm(plat - base) < 1e-3:
            raise DescriptionError(f"{src}: actuator '{nm}' has base_m == platen_m; a linkage needs a length")
        cls = classes[cname]
        actuators.append(Actuator(name=nm, cls=cls, base_m=base, platen_m=plat))
    return actuators


def _parse_supports(top: _Section, src: str) -> Supports:
    """[supports]: the static (air-spring) supports under the platen."""
    s = top.sub("supports")
    pos = s.raw("positions_m")
    try:
        pos = np.array(pos, dtype=float)
    except (TypeError, ValueError):
        raise DescriptionError(f"{src}: 'supports.positions_m' must be a list of [x, y, z] points") from None
    if pos.ndim != 2 or pos.shape[1] != 3 or len(pos) < 1:
        raise DescriptionError(f"{src}: 'supports.positions_m' must be a list of [x, y, z] points")
    supports = Supports(
        capacity_kg=s.num("capacity_kg", positive=True),
        positions_m=pos,
        piston_area_m2=s.num("piston_area_m2", positive=True),
        chamber_volume_m3=s.num("chamber_volume_m3", positive=True),
        polytropic_exponent=s.num("polytropic_exponent", positive=True),
        piston_mass_kg=s.num("piston_mass_kg", positive=True),
        shoe_mass_kg=s.num("shoe_mass_kg", positive=True),
        piston_friction_n=s.num("piston_friction_n", nonneg=True),
        shoe_friction_n=s.num("shoe_friction_n", nonneg=True),
        piston_radius_m=s.num("piston_radius_m", positive=True),
        piston_length_m=s.num("piston_length_m", positive=True),
        air_law=s.text("air_law", "polytropic", choices=("polytropic", "linear")),
    )
    s.done()
    return supports


def _parse_sensors(top: _Section, src: str):
    """[sensors]: accelerometer bandwidth, recorder rate and anti-alias filter order."""
    se = top.sub("sensors")
    se.num("accelerometer_range_m_s2", positive=True)
    bw = se.num("accelerometer_bandwidth_hz", positive=True)
    rate = se.num("recorder_rate_hz", positive=True)
    order = se.raw("accelerometer_filter_order", 4)
    if isinstance(order, bool) or not isinstance(order, int) or not 1 <= order <= 8:
        raise DescriptionError(
            f"{src}: 'sensors.accelerometer_filter_order' must be a whole number 1..8 (got {order!r})"
        )
    se.done()
    return bw, rate, order


def _parse_accelerometers(top: _Section, src: str) -> list:
    """[[accelerometer]]: named platen sensors, each with a position and a unit direction."""
    accs = []
    acc_names = set()
    for i, a_raw in enumerate(top.raw("accelerometer", [])):
        a = _Section(a_raw, f"accelerometer[{i}]", src)
        nm = a.text("name")
        if nm in acc_names:
            raise DescriptionError(f"{src}: two accelerometers are named '{nm}'")
        acc_names.add(nm)
        d = a.vec("direction", 3)
        if np.linalg.norm(d) < 1e-9:
            raise DescriptionError(f"{src}: accelerometer '{nm}' direction must be non-zero")
        accs.append(Accelerometer(name=nm, position_m=a.vec("position_m", 3), direction=d / np.linalg.norm(d)))
        a.done()
    return accs


def _parse_other_sections(top: _Section, src: str):
    """Sections other modules validate (marked used here), [friction] and [[effect]]."""
    # The hydraulic sections are validated by hydraulics.HydraulicParams; accept them here.
    for k in ("fluid", "supply", "servovalve"):
        top.raw(k)
    if top.has("controller"):
        top.raw("controller")
    if top.has("interlock"):
        top.raw("interlock")  # the controller's limit detectors (read by sim/effects/faults.py, checked there)
    if top.has("calibration"):
        top.raw("calibration")  # read by mjcf/calibrate.py (validated there)
    if top.has("published"):
        pub = top.raw("published")  # what the table's own tests measured (read by characterize / calibrate)
        if not isinstance(pub, dict):
            raise DescriptionError(f"{src}: '[published]' must be a table of measured values")
    fmodel, fpre = "coulomb", 1e-4
    if top.has("friction"):
        fr = top.sub("friction")
        fmodel = fr.text("model", "coulomb", choices=("coulomb", "presliding"))
        fpre = fr.num("presliding_m", 1e-4, positive=True)
        fr.done()
    effects = top.raw("effect", [])
    if not isinstance(effects, list) or not all(isinstance(e, dict) for e in effects):
        raise DescriptionError(f"{src}: '[[effect]]' entries must be tables")
    if top.has("unknown"):
        top.raw("unknown")  # checked by mjcf.unknowns.parse_unknowns below
    return fmodel, fpre, effects


def _check_inertia(I, what):
    a, b, c = sorted(I)
    if a + b < c * (1 - 1e-9):
        raise DescriptionError(
            f"{what} violates the triangle inequality (got {list(I)}); principal moments need A + B >= C"
        )


def toml_key_index(lines: list[str], section: str, key: str) -> int | None:
    """Line index of ``key = ...`` inside ``[section]`` of a TOML text split in lines.

    Used by the calibration commands to rewrite a value in place, keeping the file's
    comments and layout (the sources next to the numbers).
    """
    current = None
    for i, line in enumerate(lines):
        h = re.match(r"^\[+([^\]]+)\]+\s*(#.*)?$", line)
        if h:
            current = h.group(1).strip()
            continue
        if current == section and re.match(rf"^{re.escape(key)}\s*=", line):
            return i
    return None


def check_stroke_reach(desc: TableDescription) -> None:
    """Refuse a table whose actuators cannot reach every corner of the rated motion."""
    strokes = actuator_strokes(desc, envelope_corners(desc))
    need = np.abs(strokes).max(axis=0)
    for a, n in zip(desc.actuators, need):
        if n > a.cls.half_stroke_m:
            raise DescriptionError(
                f"{desc.source}: actuator '{a.name}' needs +/-{n * 1000:.1f} mm to reach the rated motion "
                f"but actuator_class.{a.cls.name}.half_stroke_m is {a.cls.half_stroke_m * 1000:.1f} mm; "
                "raise half_stroke_m or lower [limits]"
            )


# --------------------------------------------------------------------------- payloads
@dataclass(frozen=True, kw_only=True)
class RigidPayload:
    name: str
    mass_kg: float
    com_m: np.ndarray  #: centre of gravity in the table frame (on the platen's top surface z = 0 up)
    inertia_kg_m2: np.ndarray  #: (3,) principal moments about the centre of gravity
    footprint_m: np.ndarray  #: (2,) base size x, y (drawing and overturning checks)
    height_m: float
    clamp_frequency_hz: float | None = None  #: optional clamping flexibility (SDOF per axis)
    clamp_damping_ratio: float = 0.02
    #: with a clamp: the fraction of the mass on the clamping spring (the rest rigidly on the platen)
    clamp_mass_fraction: float = 1.0
    source: str = ""  #: the file it was read from (or a label)
    raw: dict = field(default_factory=dict, repr=False, compare=False)  #: the parsed TOML


@dataclass(frozen=True, kw_only=True)
class ShearFramePayload:
    name: str
    direction: str  #: "x" or "y": the frame's weak direction on the table
    mass_kg: np.ndarray  #: (n,) lumped floor masses
    stiffness_n_m: np.ndarray  #: (n, n) lateral stiffness matrix
    damping_ratio: float  #: modal damping, all modes
    storey_height_m: float
    base_m: np.ndarray  #: (3,) base centre on the platen
    footprint_m: np.ndarray  #: (2,)
    source: str = ""
    raw: dict = field(default_factory=dict, repr=False, compare=False)


@dataclass(frozen=True, kw_only=True)
class CantileverPayload:
    name: str
    height_m: float
    mass_per_length_kg_m: float
    bending_stiffness_n_m2: float  #: EI (same in both horizontal directions)
    n_segments: int
    damping_ratio: float
    base_m: np.ndarray
    width_m: float  #: drawing size
    source: str = ""
    raw: dict = field(default_factory=dict, repr=False, compare=False)


Payload = RigidPayload | ShearFramePayload | CantileverPayload


def load_payload(name_or_path: str | Path) -> Payload:
    path = resolve(name_or_path, PAYLOADS_DIR, "payload")
    return parse_payload(_load_toml(path), src=str(path))


def parse_payload(data: dict, src: str = "<payload>") -> Payload:
    top = _Section(data, "", src)
    p = top.sub("payload")
    kind = p.text("type", choices=("rigid", "shear_frame", "cantilever"))
    name = p.text("name")
    if kind == "rigid":
        out = RigidPayload(
            name=name,
            mass_kg=p.num("mass_kg", positive=True),
            com_m=p.vec("com_m", 3),
            inertia_kg_m2=p.vec("inertia_kg_m2", 3, positive=True),
            footprint_m=p.vec("footprint_m", 2, positive=True),
            height_m=p.num("height_m", positive=True),
            clamp_frequency_hz=(p.num("clamp_frequency_hz", positive=True) if p.has("clamp_frequency_hz") else None),
            clamp_damping_ratio=p.num("clamp_damping_ratio", 0.02, nonneg=True),
            clamp_mass_fraction=p.num("clamp_mass_fraction", 1.0, positive=True),
        )
        if out.clamp_mass_fraction > 1.0:
            raise DescriptionError(
                f"{src}: 'payload.clamp_mass_fraction' must be in (0, 1] (got {out.clamp_mass_fraction:g})"
            )
        if p.has("clamp_mass_fraction") and out.clamp_frequency_hz is None:
            raise DescriptionError(f"{src}: 'payload.clamp_mass_fraction' needs 'payload.clamp_frequency_hz'")
        _check_inertia(out.inertia_kg_m2, f"{src}: 'payload.inertia_kg_m2'")
    elif kind == "shear_frame":
        m = p.raw("mass_kg")
        K = p.raw("stiffness_n_m")
        try:
            m = np.array(m, dtype=float)
            K = np.array(K, dtype=float)
        except (TypeError, ValueError):
            raise DescriptionError(f"{src}: 'payload.mass_kg' and 'payload.stiffness_n_m' must be numbers") from None
        n = len(m)
        if m.ndim != 1 or n < 1 or np.any(m <= 0) or not np.all(np.isfinite(m)):
            raise DescriptionError(
                f"{src}: 'payload.mass_kg' must be a list of positive floor masses (got {m.tolist()})"
            )
        if K.shape != (n, n) or not np.all(np.isfinite(K)):
            raise DescriptionError(f"{src}: 'payload.stiffness_n_m' must be a {n}x{n} matrix (one row per floor)")
        if not np.allclose(K, K.T, rtol=1e-9, atol=0):
            raise DescriptionError(f"{src}: 'payload.stiffness_n_m' must be symmetric")
        if np.linalg.eigvalsh(K).min() <= 0:
            raise DescriptionError(f"{src}: 'payload.stiffness_n_m' must be positive definite")
        out = ShearFramePayload(
            name=name,
            direction=p.text("direction", choices=("x", "y")),
            mass_kg=m,
            stiffness_n_m=K,
            damping_ratio=p.num("damping_ratio", nonneg=True),
            storey_height_m=p.num("storey_height_m", positive=True),
            base_m=p.vec("base_m", 3, default=[0.0, 0.0, 0.0]),
            footprint_m=p.vec("footprint_m", 2, positive=True, default=[1.0, 1.0]),
        )
    else:
        nseg = p.raw("n_segments", 20)
        if not isinstance(nseg, int) or isinstance(nseg, bool) or nseg < 2 or nseg > 200:
            raise DescriptionError(f"{src}: 'payload.n_segments' must be an integer from 2 to 200 (got {nseg!r})")
        out = CantileverPayload(
            name=name,
            height_m=p.num("height_m", positive=True),
            mass_per_length_kg_m=p.num("mass_per_length_kg_m", positive=True),
            bending_stiffness_n_m2=p.num("bending_stiffness_n_m2", positive=True),
            n_segments=nseg,
            damping_ratio=p.num("damping_ratio", nonneg=True),
            base_m=p.vec("base_m", 3, default=[0.0, 0.0, 0.0]),
            width_m=p.num("width_m", 0.5, positive=True),
        )
    p.raw("description", "")
    p.raw("source", "")
    p.done()
    top.done()
    return dataclasses.replace(out, source=src, raw=data)


def payload_mass(payload: Payload | None) -> float:
    if payload is None:
        return 0.0
    if isinstance(payload, RigidPayload):
        return payload.mass_kg
    if isinstance(payload, ShearFramePayload):
        return float(payload.mass_kg.sum())
    return payload.mass_per_length_kg_m * payload.height_m
