"""A lab's recorder export (CSV, MAT-file, NI TDMS) to run files, through a column map.

The map (a TOML file, documented in ``docs/import.md``) names, for every column the
lab exports, the run-file channel and its actuator / DOF / accelerometer, the unit and
its scale, an offset and a sign, and the time base (a time column or a sample rate).
Values become SI: ``SI = sign * scale * (raw - offset) * unit``, and a differential
pressure becomes a force through a piston area. Timestamps are checked to be a uniform
grid (a recorder's timestamps rounded to 1e-5 s still are) and replaced by that grid.

Everything is read and checked before anything is written: a bad map, file or table
raises one line naming the file, the row or column and the fix.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim.runs.exports import _err, _read_csv, _read_mat, _read_tdms, uniform_time
from sim.runs.runfile import COMMAND_HOLDS

G = 9.80665  #: standard gravity, m/s^2 (unit "g")
IN = 0.0254
#: unit -> SI factor, per dimension
UNITS = {
    "length": {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "um": 1e-6, "in": IN},
    "rotation": {"rad": 1.0, "mrad": 1e-3, "deg": math.pi / 180},
    "velocity": {"m/s": 1.0, "mm/s": 1e-3, "cm/s": 1e-2, "in/s": IN},
    "acceleration": {"m/s^2": 1.0, "mm/s^2": 1e-3, "cm/s^2": 1e-2, "in/s^2": IN, "g": G},
    "force": {"N": 1.0, "kN": 1e3, "MN": 1e6, "lbf": 4.4482216152605, "kip": 4448.2216152605},
    "pressure": {"Pa": 1.0, "kPa": 1e3, "MPa": 1e6, "bar": 1e5, "psi": 6894.757293168, "ksi": 6894757.293168},
    "valve": {"fraction": 1.0, "%": 1e-2, "V": None, "mA": None},  # V, mA: over the column's full_scale
}
ACTUATOR = ("valve_command", "spool_position", "actuator_displacement", "actuator_force", "pressure_a", "pressure_b")
DOF = ("reference", "table_displacement", "table_velocity", "table_acceleration")
DIMENSION = {
    "valve_command": ("valve",),
    "spool_position": ("valve",),
    "actuator_displacement": ("length",),
    "actuator_force": ("force", "pressure"),
    "pressure_a": ("pressure",),
    "pressure_b": ("pressure",),
    "reference": ("length", "rotation"),
    "table_displacement": ("length", "rotation"),
    "table_velocity": ("velocity",),
    "table_acceleration": ("acceleration",),
    "accelerometers": ("acceleration",),
    "specimen_acceleration": ("acceleration",),
}
COLUMN_KEYS = {
    "name",
    "channel",
    "actuator",
    "dof",
    "accelerometer",
    "unit",
    "scale",
    "offset",
    "sign",
    "full_scale",
    "area_m2",
    "position_m",
    "direction",
    "sensor",
    "height_m",
    "delay_s",
    "lowpass_hz",
    "lowpass_order",
    "note",
}
#: keys that only a specimen_acceleration column takes
SPECIMEN_KEYS = ("sensor", "height_m")
SOURCE_KEYS = {
    "table",
    "time_column",
    "time_unit",
    "sample_rate_hz",
    "delimiter",
    "skip_rows",
    "payload",
    "description",
    "command_hold",
    "derive_velocity",
}
#: calibration paths and the channels each needs (any one of a tuple)
PATHS = {
    "replay (open loop)": (
        ("valve_command",),
        ("table_displacement", "table_velocity", "table_acceleration", "actuator_displacement", "accelerometers"),
    ),
    "mechanical (least squares)": (("actuator_force",), ("table_displacement", "table_acceleration", "accelerometers")),
    "closed loop": (("reference",),),
}


@dataclass
class ColumnMap:
    name: str
    channel: str
    target: str  #: actuator, DOF or accelerometer name
    factor: float  #: SI per raw unit (sign, scale, unit, area folded in)
    offset: float
    unit: str
    position: list = field(default_factory=lambda: [0.0, 0.0, 0.0])
    direction: list = field(default_factory=lambda: [1.0, 0.0, 0.0])
    height_m: float | None = None  #: specimen sensors: height above the platen's top surface
    conditioning: dict | None = None  #: the channel's declared recorder chain (meta channel_conditioning)


@dataclass
class ImportMap:
    path: str
    table: str | None
    columns: list
    time_column: str | None
    time_factor: float
    sample_rate_hz: float | None
    delimiter: str | None
    skip_rows: int
    payload: str | None
    description: str
    #: None: not said; replay and calibrate choose by the table's controller rate
    command_hold: str | None = None
    derive_velocity: bool = False


def load_map(path, table: str | None = None) -> ImportMap:
    """Read and check a column map (TOML); ``table`` overrides its ``[source] table``."""
    import mjcf

    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except OSError as e:
        raise _err(str(p), f"cannot read the map ({e.strerror})", "give an existing map file (--map)") from None
    except tomllib.TOMLDecodeError as e:
        raise _err(str(p), f"is not valid TOML ({e})", "fix the syntax (docs/import.md)") from None
    src = data.get("source", {})
    if not isinstance(src, dict):
        raise _err(str(p), "[source] must be a table", "see docs/import.md")
    bad = sorted(set(src) - SOURCE_KEYS) or sorted(set(data) - {"source", "column"})
    if bad:
        raise _err(
            str(p),
            f"unknown key '{bad[0]}'",
            f"[source] keys are {', '.join(sorted(SOURCE_KEYS))}; columns go in [[column]]",
        )
    if not table:
        table = _map_file(p, src, "table")
    if not isinstance(table, str) or not table:
        raise _err(str(p), "names no table", 'add [source] table = "NAME" (a file in scenarios/tables) or give --table')
    desc = mjcf.load_table(table)
    payload = _map_file(p, src, "payload")
    if payload is not None:
        mjcf.load_payload(payload)  # checked now: nothing is converted through a bad payload
    tcol, fs = src.get("time_column"), src.get("sample_rate_hz")
    if (tcol is None) == (fs is None):
        raise _err(
            str(p),
            "needs exactly one of [source] time_column and sample_rate_hz",
            "name the time column, or give the recorder's rate in Hz",
        )
    if fs is not None and (isinstance(fs, bool) or not isinstance(fs, (int, float)) or not fs > 0):
        raise _err(str(p), f"[source] sample_rate_hz must be a positive number (got {fs!r})", "give the rate in Hz")
    tunit = src.get("time_unit", "s")
    tfac = {"s": 1.0, "ms": 1e-3}.get(tunit)
    if tfac is None:
        raise _err(str(p), f"[source] time_unit {tunit!r} is not known", 'use "s" or "ms"')
    cols_raw = data.get("column")
    if not isinstance(cols_raw, list) or not cols_raw:
        raise _err(str(p), "has no [[column]] entries", "add one [[column]] per exported column (docs/import.md)")
    cols, seen = [], {}
    for i, c in enumerate(cols_raw, start=1):
        cols.append(_column(c, f"{p} [[column]] #{i}", desc, seen))
    delim = src.get("delimiter")
    hold = src.get("command_hold")
    if hold is not None and hold not in COMMAND_HOLDS:
        raise _err(
            str(p),
            f"[source] command_hold {hold!r} is not known",
            'use "zoh" (the record is the controller\'s own rate), or "cubic" or "linear" (a slower recorder sampled the drive)',
        )
    skip = src.get("skip_rows", 0)
    if not isinstance(skip, int) or skip < 0:
        raise _err(
            str(p), f"[source] skip_rows must be a whole number >= 0 (got {skip!r})", "count the lines above the header"
        )
    return ImportMap(
        path=str(p),
        table=table,
        columns=cols,
        time_column=tcol,
        time_factor=tfac,
        sample_rate_hz=None if fs is None else float(fs),
        delimiter=delim,
        skip_rows=skip,
        payload=payload,
        description=str(src.get("description", "")),
        command_hold=hold,
        derive_velocity=_bool(src, "derive_velocity", str(p)),
    )


def _column(c, where: str, desc, seen: dict) -> "ColumnMap":
    """One ``[[column]]`` entry of a map, checked: its channel, target, unit and SI factor."""
    where += f" ('{c.get('name')}')" if isinstance(c, dict) and "name" in c else ""
    if not isinstance(c, dict):
        raise _err(where, "is not a table", "write it as [[column]] with keys")
    extra = sorted(set(c) - COLUMN_KEYS)
    if extra:
        raise _err(where, f"unknown key '{extra[0]}'", f"keys are {', '.join(sorted(COLUMN_KEYS))}")
    name, ch, unit = c.get("name"), c.get("channel"), c.get("unit")
    if not isinstance(name, str) or not name:
        raise _err(where, "has no name", "set name = the column's header in the export")
    if ch not in DIMENSION:
        raise _err(where, f"channel {ch!r} is not a run-file channel", f"use one of {', '.join(DIMENSION)}")
    target = _column_target(c, ch, where, desc)
    if (ch, target) in seen:
        raise _err(
            where,
            f"maps {ch} {target} again (also column '{seen[(ch, target)]}')",
            "keep one column per channel and target",
        )
    seen[(ch, target)] = name
    factor = _column_factor(c, ch, target, unit, where, desc)
    nums = _column_numbers(c, where)
    cm = ColumnMap(
        name=name,
        channel=ch,
        target=target,
        factor=nums["sign"] * nums["scale"] * factor,
        offset=nums["offset"],
        unit=unit,
    )
    if ch == "accelerometers":
        _accelerometer_fields(c, cm, where)
    if ch == "specimen_acceleration":
        _specimen_fields(c, cm, where)
    cm.conditioning = _conditioning(c, where)
    return cm


def _column_target(c: dict, ch: str, where: str, desc) -> str:
    """The actuator, DOF, accelerometer or specimen sensor the column's channel is of,
    checked against the table's description where it names them."""
    if ch in ACTUATOR:
        target, kind, known = c.get("actuator"), "actuator", list(desc.actuator_names)
    elif ch in DOF:
        target, kind, known = c.get("dof"), "dof", list(desc.dofs)
    elif ch == "specimen_acceleration":
        target, kind, known = c.get("sensor"), "sensor", None
    else:
        target, kind, known = c.get("accelerometer"), "accelerometer", None
    stray = [k for k in SPECIMEN_KEYS if k in c] if ch != "specimen_acceleration" else []
    if stray:
        raise _err(
            where,
            f"{stray[0]} is for a specimen sensor, not a {ch} column",
            'set channel = "specimen_acceleration" (a sensor on the specimen) or drop ' + stray[0],
        )
    if ch == "specimen_acceleration" and (not isinstance(target, str) or not target):
        raise _err(where, f"sensor {target!r} is not a name", 'set sensor = the sensor\'s name, e.g. "F1"')
    if not isinstance(target, str) or (known is not None and target not in known):
        raise _err(
            where,
            f"{kind} {target!r} is not one of table '{desc.name}' ({desc.source}): "
            f"{', '.join(known) if known else 'any name'}",
            f"set {kind} = one of them, or describe the table's {kind}s in its description",
        )
    return target


def _column_factor(c: dict, ch: str, target: str, unit, where: str, desc) -> float:
    """The factor from the column's unit to the channel's SI unit: a known unit's, over
    ``full_scale`` for volts or mA, times the piston area for a differential pressure."""
    dims = DIMENSION[ch]
    dim = next((d for d in dims if unit in UNITS[d]), None)
    if dim is None:
        known_u = ", ".join(u for d in dims for u in UNITS[d])
        raise _err(where, f"unit {unit!r} is not known for {ch}", f"use one of {known_u}")
    factor = UNITS[dim][unit]
    if factor is None:  # volts or mA over full scale
        fsv = c.get("full_scale")
        if isinstance(fsv, bool) or not isinstance(fsv, (int, float)) or fsv == 0:
            raise _err(
                where,
                f"unit {unit} needs full_scale (the {unit} at full rated opening)",
                f"add full_scale = 10.0 (e.g. +/-10 {unit} = +/-100 %)",
            )
        factor = 1.0 / float(fsv)
    if ch == "actuator_force" and dim == "pressure":
        factor *= _piston_area(c, target, unit, where, desc)
    return factor


def _piston_area(c: dict, target: str, unit, where: str, desc) -> float:
    """``area_m2`` of a differential-pressure force column (``"table"``: the description's,
    for an actuator of equal areas)."""
    area = c.get("area_m2")
    if area == "table":
        a = desc.actuators[list(desc.actuator_names).index(target)]
        if a.cls.area_a_m2 != a.cls.area_b_m2:
            raise _err(
                where,
                f"table '{desc.name}' actuator {target} has unequal areas "
                f"({a.cls.area_a_m2:g}, {a.cls.area_b_m2:g} m^2): one differential pressure "
                "is not its force",
                "export both chamber pressures (pressure_a, pressure_b)",
            )
        area = a.cls.area_a_m2
    if isinstance(area, bool) or not isinstance(area, (int, float)) or not area > 0:
        raise _err(
            where,
            f"a differential pressure ({unit}) as actuator_force needs the piston area",
            'add area_m2 = the piston area in m^2, or area_m2 = "table" (from the description)',
        )
    return float(area)


def _column_numbers(c: dict, where: str) -> dict:
    """``scale``, ``offset`` and ``sign`` (1 or -1) of a column, as floats."""
    nums = {}
    for key, default in (("scale", 1.0), ("offset", 0.0), ("sign", 1.0)):
        v = c.get(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise _err(where, f"{key} must be a number (got {v!r})", f"set {key} = a number")
        nums[key] = float(v)
    if nums["sign"] not in (1.0, -1.0):
        raise _err(where, f"sign must be 1 or -1 (got {nums['sign']:g})", "set sign = 1 or -1")
    return nums


def _accelerometer_fields(c: dict, cm: "ColumnMap", where: str) -> None:
    """``position_m`` and ``direction`` of a platen accelerometer (defaults: the map's)."""
    for key in ("position_m", "direction"):
        v = c.get(key, getattr(cm, key.split("_")[0] if key == "position_m" else key))
        if not (isinstance(v, list) and len(v) == 3 and all(isinstance(x, (int, float)) for x in v)):
            raise _err(where, f"{key} must be 3 numbers (got {v!r})", f"set {key} = [x, y, z] in the table frame")
        setattr(cm, "position" if key == "position_m" else "direction", [float(x) for x in v])


def _specimen_fields(c: dict, cm: "ColumnMap", where: str) -> None:
    """``height_m`` (above the platen's top surface, m) and ``direction`` of a specimen sensor."""
    h = c.get("height_m")
    if isinstance(h, bool) or not isinstance(h, (int, float)) or not math.isfinite(h) or h < 0:
        raise _err(
            where,
            f"a specimen sensor needs height_m >= 0, m above the platen's top surface (got {h!r})",
            "set height_m = the sensor's height, e.g. 0.8 for a first floor 0.8 m up",
        )
    d = c.get("direction", cm.direction)
    if not (
        isinstance(d, list)
        and len(d) == 3
        and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in d)
        and any(x != 0 for x in d)
    ):
        raise _err(where, f"direction must be 3 numbers, not all zero (got {d!r})", "set direction = [1, 0, 0] for +x")
    n = math.sqrt(sum(float(x) ** 2 for x in d))
    cm.height_m, cm.direction = float(h), [float(x) / n for x in d]


def _conditioning(c: dict, where: str) -> dict | None:
    """A column's declared recorder chain (``delay_s``, ``lowpass_hz``, ``lowpass_order``),
    as meta ``channel_conditioning`` holds it, or None when the column declares none."""
    if not any(k in c for k in ("delay_s", "lowpass_hz", "lowpass_order")):
        return None
    delay, fc, order = c.get("delay_s", 0.0), c.get("lowpass_hz"), c.get("lowpass_order")
    if isinstance(delay, bool) or not isinstance(delay, (int, float)) or not math.isfinite(delay) or delay < 0:
        raise _err(where, f"delay_s must be a number >= 0, s (got {delay!r})", "set delay_s = the conditioner's delay")
    if fc is not None and (isinstance(fc, bool) or not isinstance(fc, (int, float)) or not fc > 0):
        raise _err(where, f"lowpass_hz must be a positive number (got {fc!r})", "set lowpass_hz = the cut-off in Hz")
    if fc is None and order is not None:
        raise _err(
            where, "lowpass_order without lowpass_hz", "give the low-pass's cut-off lowpass_hz, or drop the order"
        )
    if fc is not None and (isinstance(order, bool) or not isinstance(order, int) or order < 1):
        raise _err(
            where,
            f"lowpass_hz needs lowpass_order, a whole number >= 1 (got {order!r})",
            "set lowpass_order = the filter's poles, e.g. 4 for a 4-pole Butterworth",
        )
    return {"delay_s": float(delay), "lowpass_hz": None if fc is None else float(fc), "lowpass_order": order or 0}


def _map_file(map_path: Path, src: dict, key: str):
    """``[source] table`` / ``payload`` of a map: a bare name (``"lab"``) is the stock
    description of that name (scenarios/tables, scenarios/payloads); a file name or path
    (``"td3.toml"``, ``"../tables/td3.toml"``) is read from the MAP's folder (an absolute
    path as it is), so a map works from any working folder."""
    v = src.get(key)
    if v is None or not isinstance(v, str) or not v:
        return v
    if not (v.endswith(".toml") or "/" in v or "\\" in v):
        return v
    path = Path(v).expanduser()
    if not path.is_absolute():
        path = map_path.resolve().parent / path
    if not path.is_file():
        raise _err(
            str(map_path),
            f"[source] {key} = {v!r} is {path}, which does not exist (a path in a map is read from the map's folder)",
            f"give the {key} file's path relative to the map's folder, an absolute path, "
            f'or a stock {key}\'s bare name (e.g. "lab")',
        )
    return str(path)


def _bool(src: dict, key: str, where: str) -> bool:
    v = src.get(key, False)
    if not isinstance(v, bool):
        raise _err(where, f"[source] {key} must be true or false (got {v!r})", f"set {key} = true or false")
    return v


@dataclass
class Imported:
    """One export converted: the run file (not yet written), where it goes, and what
    the importer inferred."""

    run: object
    source: str
    report: dict


def _mapped_channels(mp: ImportMap, raw: dict, n: int, places: dict) -> dict:
    """Each mapped column in its channel's array, in SI units (``(x - offset) * factor``),
    at its place's column (``places``: the table's actuators and DOFs, the mapped
    accelerometers and specimen sensors); NaN where no column is mapped."""
    chans = {}
    for c in mp.columns:
        if c.channel in ACTUATOR:
            names = places["actuator"]
        elif c.channel in DOF:
            names = places["dof"]
        elif c.channel == "specimen_acceleration":
            names = [s.target for s in places["specimen"]]
        else:
            names = places["accelerometer"]
        arr = chans.setdefault(c.channel, np.full((n, len(names)), np.nan))
        arr[:, names.index(c.target)] = (raw[c.name] - c.offset) * c.factor
    return chans


def import_file(path, mp: ImportMap) -> Imported:
    """Convert one export (``.csv``/``.txt``, ``.mat`` or ``.tdms``) through the map ``mp``."""
    import mjcf
    from sim.runs.runfile import FORMAT, RunFile

    path = Path(path)
    wanted = [c.name for c in mp.columns] + ([mp.time_column] if mp.time_column else [])
    wanted = list(dict.fromkeys(wanted))
    reader = {".mat": _read_mat, ".tdms": _read_tdms}.get(path.suffix.lower(), _read_csv)
    raw = reader(path, mp, wanted)
    n = len(next(iter(raw.values())))
    if mp.time_column:
        t0, fs = uniform_time(raw[mp.time_column] * mp.time_factor, f"{path} column '{mp.time_column}'")
    else:
        t0, fs = 0.0, mp.sample_rate_hz
    t = np.arange(n) / fs
    desc = mjcf.load_table(mp.table)
    payload = mjcf.load_payload(mp.payload) if mp.payload else None
    acts, dofs = list(desc.actuator_names), list(desc.dofs)
    accs = list(dict.fromkeys(c.target for c in mp.columns if c.channel == "accelerometers"))
    specs = [c for c in mp.columns if c.channel == "specimen_acceleration"]
    chans = _mapped_channels(mp, raw, n, {"actuator": acts, "dof": dofs, "accelerometer": accs, "specimen": specs})
    derived = {}
    if mp.derive_velocity and "table_velocity" not in chans:
        if "table_displacement" not in chans:
            raise _err(
                mp.path,
                "[source] derive_velocity needs a table_displacement column",
                "map the table's displacement, or drop derive_velocity",
            )
        chans["table_velocity"] = np.gradient(chans["table_displacement"], 1.0 / fs, axis=0)
        derived["table_velocity"] = "central difference of table_displacement (map derive_velocity)"
    acc_meta = []
    for a in accs:
        c = next(c for c in mp.columns if c.channel == "accelerometers" and c.target == a)
        acc_meta.append({"name": a, "position": c.position, "direction": c.direction})
    meta = {
        "format": FORMAT,
        "table": desc.name,
        "sample_rate_hz": fs,
        "actuators": acts,
        "dofs": dofs,
        "source": "measured",
        "description": mp.description or f"imported from {path.name}",
        "payload": payload.name if payload is not None else None,
        "accelerometers": acc_meta,
        "imported_from": str(path),
        "import_map": mp.path,
        "time_origin_s": t0,
        "derived_channels": derived,
        # not said: replay and calibrate choose by the controller's rate (sim.calibrate.replay.command_hold)
        **({"command_hold": mp.command_hold} if mp.command_hold else {}),
    }
    if specs:  # docs/run-file.md: one entry per specimen_acceleration column, in order
        meta["specimen_sensors"] = [{"name": c.target, "height_m": c.height_m, "direction": c.direction} for c in specs]
    cond = channel_conditioning(mp)
    cond.update(table_conditioning(desc, fs, set(chans) - set(cond)))
    if cond:
        meta["channel_conditioning"] = cond
    meta.update(_carried_descriptions(desc, payload))
    run = RunFile(t=t, meta=meta, **chans)
    if run.valve_command is None and run.reference is None:
        raise _err(
            f"{path} (map {mp.path})",
            "maps neither valve_command nor reference",
            "map the valve drive (replay) or the displacement command (closed loop)",
        )
    run.validate()
    return Imported(run=run, source=str(path), report=_report(run, mp, path))


def channel_conditioning(mp: ImportMap) -> dict:
    """Meta ``channel_conditioning`` from the map's columns: per channel, what the map
    declares of its recorder chain. The columns of one channel share one entry (one
    conditioner model per channel, as the run file states it), so two columns of a
    channel that declare different chains are an error."""
    out, by = {}, {}
    for c in mp.columns:
        if c.conditioning is None:
            continue
        have = out.setdefault(c.channel, c.conditioning)
        if have != c.conditioning:
            raise _err(
                mp.path,
                f"columns '{by[c.channel]}' and '{c.name}' declare different conditioning for channel {c.channel}",
                "the run file keeps one per channel: declare the same delay_s, lowpass_hz and lowpass_order",
            )
        by.setdefault(c.channel, c.name)
    return out


#: the channels that go through the table's declared accelerometer conditioner
#: (``[sensors] accelerometer_bandwidth_hz``): the platen's accelerometers, the table
#: file's own (``table_acceleration`` and its ``[[accelerometer]]`` entries as
#: ``accelerometers``). Not ``specimen_acceleration``: sensors on a specimen are the
#: specimen's, of which the table file says nothing (the worked example's
#: light_table.toml declares "the platen accelerometer's conditioner"; its floor
#: sensors are recorded without it, scenarios/lab_example/make_quake_export.py); a map
#: column or a sensor model states their own conditioner
TABLE_CONDITIONED = ("table_acceleration", "accelerometers")


def table_conditioning(desc, fs: float, undeclared) -> dict:
    """The table's own accelerometer conditioner (``[sensors] accelerometer_bandwidth_hz``
    and ``accelerometer_filter_order``) as the declared chain of each accelerometer
    channel (:data:`TABLE_CONDITIONED`) among ``undeclared`` (those the map declares
    nothing for), when the cut-off is below the recorder's Nyquist frequency ``fs / 2``:
    the lab's accelerometers went through it, and every path of calibration and
    ``replay`` then compares the model's acceleration through it (the mechanical path
    read the table's value already; the replay paths read only the run's).
    ``run --measure`` applies and declares the same (sim.runs.measure)."""
    bw = float(desc.accelerometer_bandwidth_hz or 0.0)
    if not 0.0 < bw < 0.5 * fs:
        return {}
    # 4 poles where the table gives no order (mjcf.description), as calibration assumes
    # (sim.calibrate.conditioning.TABLE_ORDER)
    spec = {"delay_s": 0.0, "lowpass_hz": bw, "lowpass_order": int(desc.accelerometer_filter_order)}
    return {ch: dict(spec) for ch in TABLE_CONDITIONED if ch in undeclared}


def _carried_descriptions(desc, payload) -> dict:
    """The table (and payload) the run was recorded on, carried in its meta (docs/run-file.md):
    every command rebuilds the model from these, with no --table; ``table_path`` is
    information only (the file's absolute path at import)."""
    from sim.runs.runfile import description_meta

    meta = description_meta("table", desc.source, desc.raw)
    meta["table_path"] = str(Path(desc.source).resolve())
    if payload is not None:
        meta.update(description_meta("payload", payload.source, payload.raw))
        meta["payload_path"] = str(Path(payload.source).resolve())
    return meta


def _report(run, mp: ImportMap, path: Path) -> dict:
    ranges = {}
    for ch in run.present_channels():
        arr = getattr(run, ch)
        names = run.column_names(ch)
        ranges[ch] = {}
        for j, nm in enumerate(names):
            col = arr[:, j]
            ok = np.isfinite(col)
            if ok.any():
                ranges[ch][nm] = {
                    "min": float(col[ok].min()),
                    "max": float(col[ok].max()),
                    "missing_samples": int((~ok).sum()),
                }
    paths = {}
    for pth, needs in PATHS.items():
        lacking = [
            " or ".join(alt)
            for alt in needs
            if not any(getattr(run, a) is not None and np.isfinite(getattr(run, a)).all(axis=0).any() for a in alt)
        ]
        paths[pth] = {"ready": not lacking, "missing": lacking}
    return {
        "file": str(path),
        "samples": run.n_samples,
        "sample_rate_hz": run.sample_rate_hz,
        "rate_from": f"time column '{mp.time_column}'" if mp.time_column else "map sample_rate_hz",
        "duration_s": run.duration_s,
        "time_origin_s": run.meta["time_origin_s"],
        "table": run.meta["table"],
        "table_path": run.meta["table_path"],
        "payload": run.meta.get("payload"),
        "derived_channels": run.meta["derived_channels"],
        "ranges_si": ranges,
        "paths": paths,
    }


def import_files(files, map_path, *, table: str | None = None, out=None) -> list[Imported]:
    """Convert every export in ``files`` through the map; with ``out`` write
    ``out/<stem>.run.npz`` for each, only once all of them converted."""
    from sim.runs.files import out_dir
    from sim.runs.runfile import write_run

    mp = load_map(map_path, table)
    done = [import_file(f, mp) for f in files]
    stems = [Path(d.source).stem for d in done]
    if len(set(stems)) != len(stems):
        raise _err(
            ", ".join(d.source for d in done),
            "two exports share a file name",
            "rename them (each becomes <name>.run.npz)",
        )
    if out is not None:
        folder = out_dir(out)
        for d, stem in zip(done, stems):
            p = write_run(folder / f"{stem}.run.npz", d.run)
            d.report["run_file"] = str(p)
    return done


def export_csv(run, map_path, path) -> Path:
    """The inverse of :func:`import_file` for a run file and a map: write ``path`` as a
    lab's recorder would (the map's columns, in its units, offsets and signs; a time
    column rounded to 1e-5 s). Used for the worked example and the round-trip test."""
    from sim.runs.files import write_text_atomic

    mp = load_map(map_path)  # the map's own table, as the import reads it back
    if mp.time_column is None:
        raise _err(mp.path, "has no time_column", "export_csv writes one: add [source] time_column")
    cols = [mp.time_column] + [c.name for c in mp.columns]
    data = [np.round((np.asarray(run.t) - run.t[0]) / mp.time_factor, 5 if mp.time_factor == 1.0 else 2)]
    for c in mp.columns:
        arr = getattr(run, c.channel)
        if arr is None:
            raise _err(
                mp.path,
                f"column '{c.name}' maps {c.channel}, which run {run.name} lacks",
                "drop that column from the map",
            )
        names = run.column_names(c.channel)
        if c.target not in names:
            raise _err(
                mp.path,
                f"column '{c.name}' maps {c.channel} {c.target}, not in run {run.name} ({', '.join(names)})",
                "fix the map's target",
            )
        data.append(arr[:, names.index(c.target)] / c.factor + c.offset)
    delim = mp.delimiter or ","
    lines = [delim.join(cols)]
    for row in zip(*data):
        lines.append(delim.join(f"{v:.7g}" for v in row))
    path = Path(path)
    write_text_atomic(path, "\n".join(lines) + "\n")
    return path


__all__ = [
    "UNITS",
    "ImportMap",
    "Imported",
    "export_csv",
    "import_file",
    "import_files",
    "load_map",
    "uniform_time",
]
