"""Run files: one table test, measured or simulated (format ``shaketable-run/1``).

The format is specified in ``docs/run-file.md``. In short: a ``numpy.savez_compressed``
archive whose name ends ``.run.npz``, holding a uniform time vector ``t`` (s), a JSON
``meta`` string and any of the channels below, each shaped ``(N, n_columns)`` and in SI
units (m, rad, N, Pa, m/s^2; valve and spool channels as a fraction of rated opening).

| channel group | channels | columns named by |
|---|---|---|
| actuator | valve_command, spool_position, actuator_displacement, actuator_force, pressure_a, pressure_b | ``meta["actuators"]`` |
| DOF | reference, table_displacement, table_velocity, table_acceleration | ``meta["dofs"]`` |
| accelerometer | accelerometers | ``meta["accelerometers"][i]["name"]`` (if given) |
| specimen | specimen_acceleration | ``meta["specimen_sensors"][i]["name"]`` |

Missing samples are NaN, never zero. Readers that need a channel pass it in
``require=``; a NaN there is an error that names the channel, the first bad sample and
its time. A simulation that diverged keeps what it had and marks the file with
``meta["incomplete"] = true`` and ``meta["incomplete_reason"]``.

Every problem a user can fix raises :class:`sim.errors.RunFileError` with a one-line
message naming the file, the problem and the fix.
"""

from __future__ import annotations

import json
import math
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from sim.errors import RunFileError

FORMAT = "shaketable-run/1"
#: the values of ``meta.command_hold`` (docs/run-file.md): how a replay puts the recorded
#: valve command onto the model's ticks (sim.calibrate.replay.command_on_ticks)
COMMAND_HOLDS = ("zoh", "linear", "cubic")
EXTRA_PREFIX = "x_"  #: project extension channels (supply pressure, loop gap, ...)
SUFFIX = ".run.npz"
SOURCES = ("measured", "simulated")
REQUIRED_META = ("format", "table", "sample_rate_hz", "actuators", "dofs", "source")

ACTUATOR_CHANNELS = (
    "valve_command",
    "spool_position",
    "actuator_displacement",
    "actuator_force",
    "pressure_a",
    "pressure_b",
)
DOF_CHANNELS = ("reference", "table_displacement", "table_velocity", "table_acceleration")
ACCELEROMETER_CHANNELS = ("accelerometers",)
#: accelerometers on the specimen (a payload's floors), placed by height above the platen
SPECIMEN_CHANNELS = ("specimen_acceleration",)
#: Every optional channel, in the order of the format table.
CHANNELS = (
    "valve_command",
    "reference",
    "spool_position",
    "actuator_displacement",
    "actuator_force",
    "pressure_a",
    "pressure_b",
    "table_displacement",
    "table_velocity",
    "table_acceleration",
    "accelerometers",
    "specimen_acceleration",
)
#: At least one of these must be present (what drives the plant or the controller).
INPUT_CHANNELS = ("valve_command", "reference")


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _error(name: str, problem: str, fix: str) -> RunFileError:
    return RunFileError(_one_line(f"run file {name} {problem}; {fix}"))


@dataclass(eq=False)
class RunFile:
    """One table test in memory.

    Attributes:
        t: sample times, shape (N,), s; uniform step, strictly increasing.
        meta: the JSON metadata (see docs/run-file.md); required keys ``format``,
            ``table``, ``sample_rate_hz``, ``actuators``, ``dofs``, ``source``.
        valve_command ... accelerometers: optional channels, each (N, n_columns)
            float64 or None when absent. Actuator channels have one column per name
            in ``meta["actuators"]``, DOF channels one per name in ``meta["dofs"]``.
        path: the file this run was read from or last written to (for messages only).
    """

    t: np.ndarray
    meta: dict
    valve_command: np.ndarray | None = None
    reference: np.ndarray | None = None
    spool_position: np.ndarray | None = None
    actuator_displacement: np.ndarray | None = None
    actuator_force: np.ndarray | None = None
    pressure_a: np.ndarray | None = None
    pressure_b: np.ndarray | None = None
    table_displacement: np.ndarray | None = None
    table_velocity: np.ndarray | None = None
    table_acceleration: np.ndarray | None = None
    accelerometers: np.ndarray | None = None
    #: (N, n_spec) m/s^2: absolute acceleration along each specimen sensor's direction,
    #: gravity removed; sensors in ``meta["specimen_sensors"]``
    specimen_acceleration: np.ndarray | None = None
    path: str | None = field(default=None, kw_only=True)
    #: Project extension channels, stored as ``x_<name>`` arrays with one row per sample
    #: (e.g. supply_pressure, loop_gap). Readers of the plain format may ignore them.
    extras: dict = field(default_factory=dict, kw_only=True)

    # -- descriptive helpers -------------------------------------------------------
    @property
    def name(self) -> str:
        """How messages refer to this run: its path, or ``(unsaved run)``."""
        return str(self.path) if self.path else "(unsaved run)"

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return int(np.shape(self.t)[0])

    @property
    def sample_rate_hz(self) -> float:
        """Sample rate from ``meta`` (validated against ``t`` on read and write), Hz."""
        return float(self.meta["sample_rate_hz"])

    @property
    def dt(self) -> float:
        """Sample step 1 / sample_rate_hz, s."""
        return 1.0 / self.sample_rate_hz

    @property
    def duration_s(self) -> float:
        """t[-1] - t[0], s."""
        return float(self.t[-1] - self.t[0]) if self.n_samples else 0.0

    @property
    def actuators(self) -> list[str]:
        """Actuator column names, in order (e.g. X1..X4, Y1..Y4, Z1..Z4)."""
        return list(self.meta.get("actuators", []))

    @property
    def dofs(self) -> list[str]:
        """DOF column names, in order (e.g. x, y, z, rx, ry, rz)."""
        return list(self.meta.get("dofs", []))

    @property
    def accelerometer_names(self) -> list[str] | None:
        """Accelerometer column names from ``meta["accelerometers"]``, or None."""
        acc = self.meta.get("accelerometers")
        if acc is None:
            return None
        return [str(a.get("name", f"acc{i}")) if isinstance(a, dict) else str(a) for i, a in enumerate(acc)]

    @property
    def source(self) -> str:
        """``"measured"`` or ``"simulated"``."""
        return str(self.meta.get("source"))

    @property
    def incomplete(self) -> bool:
        """True when the run stopped early (e.g. the simulation diverged)."""
        return bool(self.meta.get("incomplete", False))

    @property
    def incomplete_reason(self) -> str | None:
        """Why the run is incomplete, or None."""
        return self.meta.get("incomplete_reason") if self.incomplete else None

    def mark_incomplete(self, reason: str) -> None:
        """Flag the run as stopped early, keeping what it has."""
        self.meta["incomplete"] = True
        self.meta["incomplete_reason"] = _one_line(reason)

    def present_channels(self) -> list[str]:
        """Names of the channels this run carries, in format order."""
        return [c for c in CHANNELS if getattr(self, c) is not None]

    def channel(self, name: str) -> np.ndarray:
        """The (N, n_columns) array of a channel; RunFileError if absent."""
        if name not in CHANNELS:
            raise _error(self.name, f"has no channel kind {name!r}", f"channels are {', '.join(CHANNELS)}")
        arr = getattr(self, name)
        if arr is None:
            have = ", ".join(self.present_channels()) or "none"
            raise _error(
                self.name,
                f"has no channel {name!r}",
                f"record or convert it into the run file (channels present: {have})",
            )
        return arr

    def column_names(self, channel: str) -> list[str]:
        """Column names of a channel (actuators, dofs or accelerometer names)."""
        if channel in ACTUATOR_CHANNELS:
            return self.actuators
        if channel in DOF_CHANNELS:
            return self.dofs
        if channel in SPECIMEN_CHANNELS:
            return [str(s.get("name", f"spec{i}")) for i, s in enumerate(self.meta.get("specimen_sensors") or [])]
        if channel in ACCELEROMETER_CHANNELS:
            names = self.accelerometer_names
            if names is None:
                arr = self.channel(channel)
                return [f"acc{i}" for i in range(arr.shape[1])]
            return names
        if channel in SPECIMEN_CHANNELS:
            return [str(s.get("name", f"s{i}")) for i, s in enumerate(self.meta.get("specimen_sensors") or [])]
        raise _error(self.name, f"has no channel kind {channel!r}", f"channels are {', '.join(CHANNELS)}")

    def column(self, channel: str, column_name: str) -> np.ndarray:
        """One column of a channel by name, shape (N,), e.g. column("actuator_force", "Z3")."""
        arr = self.channel(channel)
        names = self.column_names(channel)
        if column_name not in names:
            raise _error(
                self.name, f"channel {channel!r} has no column {column_name!r}", f"columns are {', '.join(names)}"
            )
        return arr[:, names.index(column_name)]

    def validate(self, require: Iterable[str] = ()) -> None:
        """Check the run against the format; RunFileError on the first problem."""
        _validate(self, self.name, tuple(require))


# -- validation --------------------------------------------------------------------
def _validate_meta(meta: Any, name: str) -> None:
    if not isinstance(meta, dict):
        raise _error(
            name,
            "has a meta that is not a JSON object",
            "store meta as a JSON object with keys " + ", ".join(REQUIRED_META),
        )
    missing = [k for k in REQUIRED_META if k not in meta]
    if missing:
        raise _error(
            name, f"meta lacks required key(s) {', '.join(missing)}", "add them (see docs/run-file.md, section meta)"
        )
    if meta["format"] != FORMAT:
        raise _error(
            name,
            f"has format {meta['format']!r}, not {FORMAT!r}",
            f"convert it to {FORMAT} (docs/run-file.md) and set meta format to {FORMAT!r}",
        )
    if not isinstance(meta["table"], str) or not meta["table"]:
        raise _error(
            name,
            f"meta table {meta['table']!r} is not a table name",
            "set it to the name of a table description in scenarios/ (e.g. 'cgs')",
        )
    fs = meta["sample_rate_hz"]
    if isinstance(fs, bool) or not isinstance(fs, (int, float)) or not math.isfinite(fs) or fs <= 0:
        raise _error(name, f"meta sample_rate_hz {fs!r} is not a positive number", "set it to 1 / (t[1] - t[0]) in Hz")
    for key in ("actuators", "dofs"):
        cols = meta[key]
        if not isinstance(cols, list) or not all(isinstance(c, str) and c for c in cols):
            raise _error(
                name,
                f"meta {key} is not a list of names",
                f"set meta {key} to the column names in order, e.g. "
                + ('["X1", "X2"]' if key == "actuators" else '["x", "y", "z", "rx", "ry", "rz"]'),
            )
        dup = sorted({c for c in cols if cols.count(c) > 1})
        if dup:
            raise _error(name, f"meta {key} repeats {', '.join(dup)}", f"give every {key[:-1]} column a unique name")
    if not meta["dofs"]:
        raise _error(name, "meta dofs is empty", 'list the table DOFs, e.g. ["x"] for a uni-axial table')
    if meta["source"] not in SOURCES:
        raise _error(
            name,
            f"meta source {meta['source']!r} is not 'measured' or 'simulated'",
            "set meta source to 'measured' or 'simulated'",
        )
    acc = meta.get("accelerometers")
    if acc is not None and not isinstance(acc, list):
        raise _error(name, "meta accelerometers is not a list", "make it a list of {name, position, direction} objects")
    _validate_specimen_sensors(meta.get("specimen_sensors"), name)
    inc = meta.get("incomplete", False)
    if not isinstance(inc, bool):
        raise _error(name, f"meta incomplete {inc!r} is not true/false", "set it to true or false")
    if inc and not isinstance(meta.get("incomplete_reason"), str):
        raise _error(
            name,
            "is marked incomplete without an incomplete_reason",
            "add meta incomplete_reason with why the run stopped",
        )


def _validate_specimen_sensors(spec: Any, name: str) -> None:
    """``meta.specimen_sensors``: a list of {name, height_m, direction} (docs/run-file.md)."""
    if spec is None:
        return
    fix = 'make it a list of {"name": "F1", "height_m": 0.8, "direction": [1, 0, 0]} objects'
    if not isinstance(spec, list):
        raise _error(name, "meta specimen_sensors is not a list", fix)
    for i, s in enumerate(spec):
        ok = (
            isinstance(s, dict)
            and isinstance(s.get("name"), str)
            and isinstance(s.get("height_m"), (int, float))
            and not isinstance(s.get("height_m"), bool)
            and isinstance(s.get("direction"), list)
            and len(s["direction"]) == 3
            and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in s["direction"])
        )
        if not ok:
            raise _error(name, f"meta specimen_sensors[{i}] is not a {{name, height_m, direction}} object", fix)


def _validate_time(t: Any, fs: float, name: str) -> None:
    t = np.asarray(t)
    if t.ndim != 1 or t.shape[0] < 2:
        raise _error(
            name, f"has t of shape {t.shape}, need (N,) with N >= 2", "store t as a 1-D array of sample times in s"
        )
    if not np.issubdtype(t.dtype, np.number):
        raise _error(name, f"has t of type {t.dtype}", "store t as float64 seconds")
    if not np.all(np.isfinite(t)):
        i = int(np.flatnonzero(~np.isfinite(t))[0])
        raise _error(name, f"has a non-finite time at sample {i}", "store t as t0 + arange(N) / sample_rate_hz")
    dt = np.diff(t.astype(np.float64))
    if np.any(dt <= 0):
        i = int(np.flatnonzero(dt <= 0)[0])
        raise _error(
            name,
            f"has t not strictly increasing at sample {i + 1} (t = {t[i + 1]:.6g} s)",
            "sort the samples and drop duplicates, or regenerate t as t0 + arange(N) / sample_rate_hz",
        )
    step = float(np.median(dt))
    tol = 1e-6 * step + 8 * np.finfo(np.float64).eps * float(np.max(np.abs(t)))
    bad = np.abs(dt - step) > tol
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise _error(
            name,
            f"has a non-uniform time step at sample {i + 1} (step {dt[i]:.6g} s, usual step {step:.6g} s)",
            "resample to a uniform rate or fill gaps with NaN samples",
        )
    if abs(fs * step - 1.0) > 1e-6:
        raise _error(
            name,
            f"meta sample_rate_hz {fs:g} disagrees with t (1/step = {1.0 / step:.9g} Hz)",
            "set meta sample_rate_hz to 1 / (t[1] - t[0])",
        )


def _expected_columns(channel: str, meta: dict, arr: np.ndarray) -> tuple[int | None, str]:
    if channel in ACTUATOR_CHANNELS:
        return len(meta["actuators"]), "actuators in meta actuators"
    if channel in DOF_CHANNELS:
        return len(meta["dofs"]), "DOFs in meta dofs"
    if channel in SPECIMEN_CHANNELS:
        spec = meta.get("specimen_sensors")
        return (len(spec) if isinstance(spec, list) else 0), "sensors in meta specimen_sensors"
    acc = meta.get("accelerometers")
    return (len(acc) if acc is not None else None), "accelerometers in meta accelerometers"


def _validate(run: RunFile, name: str, require: tuple[str, ...]) -> None:
    _validate_meta(run.meta, name)
    _validate_time(run.t, float(run.meta["sample_rate_hz"]), name)
    n = int(np.shape(run.t)[0])
    for unknown in [c for c in require if c not in CHANNELS]:
        raise _error(name, f"was asked for unknown channel {unknown!r}", f"channels are {', '.join(CHANNELS)}")
    for channel in CHANNELS:
        arr = getattr(run, channel)
        if arr is None:
            continue
        arr = np.asarray(arr)
        if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
            raise _error(name, f"channel {channel!r} has type {arr.dtype}", "store it as float64")
        if arr.ndim != 2:
            raise _error(
                name,
                f"channel {channel!r} has shape {arr.shape}, need (N, n_columns)",
                "store one column per actuator/DOF/accelerometer (a[:, None] for one column)",
            )
        if arr.shape[0] != n:
            raise _error(
                name,
                f"channel {channel!r} has {arr.shape[0]} samples but t has {n}",
                "give every channel one row per sample time (NaN for missing samples)",
            )
        ncol, what = _expected_columns(channel, run.meta, arr)
        if ncol is not None and arr.shape[1] != ncol:
            raise _error(
                name,
                f"channel {channel!r} has {arr.shape[1]} columns but there are {ncol} {what}",
                f"make the {what} match the channel's columns",
            )
    for key, arr in run.extras.items():
        arr = np.asarray(arr)
        if not key.replace("_", "").isalnum() or arr.ndim not in (1, 2) or arr.shape[0] != n:
            raise _error(
                name,
                f"extension channel {key!r} has shape {arr.shape}, need ({n},) or ({n}, k)",
                "give extension channels one row per sample and a plain name",
            )
    if all(getattr(run, c) is None for c in INPUT_CHANNELS):
        raise _error(
            name,
            "has neither valve_command nor reference",
            "add the servovalve commands (open-loop replay) or the reference displacement (needs a controller)",
        )
    for channel in require:
        arr = getattr(run, channel)
        if arr is None:
            have = ", ".join(c for c in CHANNELS if getattr(run, c) is not None)
            raise _error(
                name,
                f"has no channel {channel!r}",
                f"record or convert it into the run file (channels present: {have})",
            )
        bad = ~np.isfinite(np.asarray(arr, dtype=np.float64))
        if np.any(bad):
            i, j = (int(k) for k in np.argwhere(bad)[0])
            cols = (
                run.meta["actuators"]
                if channel in ACTUATOR_CHANNELS
                else (run.meta["dofs"] if channel in DOF_CHANNELS else None)
            )
            col = f" column {cols[j]!r}" if cols and j < len(cols) else f" column {j}"
            kind = "NaN" if np.isnan(arr[i, j]) else "an infinite value"
            raise _error(
                name,
                f"has {kind} in channel {channel!r}{col} at sample {i} (t = {float(run.t[i]):.6g} s)",
                "fill or cut the missing samples, or use a run where this channel is complete",
            )


# -- writing -----------------------------------------------------------------------
def write_run(path: str | os.PathLike, run: RunFile) -> Path:
    """Validate ``run`` and write it to ``path`` (must end ``.run.npz``) atomically.

    The archive is written to a temporary file in the same folder and moved into place
    with ``os.replace``, so a reader sees either the old file or the whole new one,
    and a failure leaves no partial file. Returns the path written; sets ``run.path``.
    """
    path = Path(path)
    name = str(path)
    if not path.name.endswith(SUFFIX) or path.name == SUFFIX:
        raise _error(name, f"does not end with {SUFFIX!r}", f"name it like 'test01{SUFFIX}'")
    _validate(run, name, ())
    try:
        meta_text = json.dumps(run.meta, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise _error(
            name,
            f"has meta that cannot be written as JSON ({_one_line(exc)})",
            "keep meta to strings, finite numbers, lists and dicts",
        ) from None
    arrays: dict[str, np.ndarray] = {"t": np.asarray(run.t, dtype=np.float64), "meta": np.array(meta_text)}
    for channel in CHANNELS:
        arr = getattr(run, channel)
        if arr is not None:
            arrays[channel] = np.asarray(arr, dtype=np.float64)
    for key, arr in run.extras.items():
        arrays[EXTRA_PREFIX + key] = np.asarray(arr, dtype=np.float64)

    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise _error(name, f"cannot be written: folder {folder} does not exist", "create the folder first")
    from sim.runs.files import atomic_write

    atomic_write(
        path,
        lambda fh: np.savez_compressed(fh, **arrays),
        error=lambda exc: _error(
            name,
            f"cannot be written ({_one_line(exc.strerror or exc)})",
            "choose a folder you can write to, with free space",
        ),
    )
    run.path = name
    return path


# -- reading -----------------------------------------------------------------------
def read_run(path: str | os.PathLike, require: Iterable[str] = ()) -> RunFile:
    """Read and validate a run file.

    Args:
        path: a ``.run.npz`` file.
        require: channels the caller needs: each must be present and free of NaN.

    Returns:
        The RunFile, channels as float64 arrays (None when absent).

    Raises:
        RunFileError: one line naming the file, the problem and the fix.
    """
    path = Path(path)
    name = str(path)
    _check_archive(path, name)
    data = _members(path, name)
    meta = _meta(data.pop("meta"), name)
    t = data.pop("t")
    channels, extras = _channels(data, name)
    if t.dtype.kind not in "fiu":
        raise _error(name, f"has t of type {t.dtype}", "store t as float64 seconds")
    run = RunFile(t=t.astype(np.float64, copy=False), meta=meta, **channels, path=name, extras=extras)
    _validate(run, name, tuple(require))
    return run


def _check_archive(path: Path, name: str) -> None:
    """The path is an existing file and a zip archive (what ``np.savez`` writes)."""
    if not path.exists():
        raise _error(name, "does not exist", "check the path")
    if path.is_dir():
        raise _error(name, "is a folder", f"give the path of a {SUFFIX} file")
    if not zipfile.is_zipfile(path):
        raise _error(
            name,
            "is not a NumPy .npz archive",
            f"write it with shaketable (sim.runs.runfile.write_run) or numpy.savez_compressed as {FORMAT}",
        )


def _members(path: Path, name: str) -> dict:
    """The archive's arrays by key: only the format's keys (and extension channels), ``t``
    and ``meta`` among them, each a NumPy array."""
    known = set(CHANNELS) | {"t", "meta"}
    try:
        with np.load(path, allow_pickle=False) as npz:
            keys = list(npz.files)
            unknown = sorted(k for k in set(keys) - known if not k.startswith(EXTRA_PREFIX))
            if unknown:
                raise _error(
                    name,
                    f"has unknown array(s) {', '.join(unknown)}",
                    f"rename them to format keys ({', '.join(CHANNELS)}) or drop them",
                )
            for key in ("t", "meta"):
                if key not in keys:
                    raise _error(
                        name,
                        f"has no {key!r} array",
                        "add it (t: sample times in s; meta: JSON text), see docs/run-file.md",
                    )
            data = {k: npz[k] for k in keys}
    except RunFileError:
        raise
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as exc:
        raise _error(
            name,
            f"is a damaged or unreadable archive ({_one_line(exc)})",
            "write it again, or restore it from the recorder export",
        ) from None
    if not all(isinstance(a, np.ndarray) for a in data.values()):
        bad = sorted(k for k, a in data.items() if not isinstance(a, np.ndarray))
        raise _error(
            name,
            f"is a damaged archive (member(s) {', '.join(bad)} are not NumPy arrays)",
            "write it again, or restore it from the recorder export",
        )
    return data


def _meta(meta_arr: np.ndarray, name: str) -> dict:
    """The run's ``meta``: one string of JSON text."""
    if meta_arr.shape != () or meta_arr.dtype.kind not in "US":
        raise _error(name, "has a meta that is not a single string", "store meta as np.array(json.dumps(meta))")
    meta_text = meta_arr.item()
    if isinstance(meta_text, bytes):
        meta_text = meta_text.decode("utf-8", "replace")
    try:
        return json.loads(meta_text)
    except json.JSONDecodeError as exc:
        raise _error(
            name, f"has meta that is not valid JSON ({exc.msg} at char {exc.pos})", "store meta as json.dumps(meta)"
        ) from None


def _channels(data: dict, name: str) -> tuple[dict, dict]:
    """The format's channels and the extension channels (``EXTRA_PREFIX`` dropped), each
    numeric, as float64."""
    channels: dict[str, np.ndarray] = {}
    extras = {}
    for k in [k for k in data if k.startswith(EXTRA_PREFIX)]:
        if data[k].dtype.kind not in "fiu":
            raise _error(name, f"extension channel {k!r} has type {data[k].dtype}", "store it as float64")
        extras[k[len(EXTRA_PREFIX) :]] = data.pop(k).astype(np.float64)
    for key, arr in data.items():
        if arr.dtype.kind not in "fiu":
            raise _error(name, f"channel {key!r} has type {arr.dtype}", "store it as float64")
        channels[key] = arr.astype(np.float64, copy=False)
    return channels, extras


# -- the descriptions a run was made with ------------------------------------------
def description_text(source: str, raw: dict) -> str:
    """The text of a table/payload description as the run carries it: the file's TOML
    text when ``source`` is a file that still parses to ``raw``, else ``raw`` as JSON
    (a description built or modified in memory)."""
    import tomllib

    try:
        text = Path(source).read_text(encoding="utf-8") if source else None
        if text is not None and tomllib.loads(text) == raw:
            return text
    except (OSError, ValueError):
        pass
    return json.dumps(raw, sort_keys=True, default=str)


def description_meta(kind: str, source: str, raw: dict) -> dict:
    """``{kind}_description`` (text) and ``{kind}_sha256`` (of that UTF-8 text) for meta."""
    import hashlib

    text = description_text(source, raw)
    return {f"{kind}_description": text, f"{kind}_sha256": hashlib.sha256(text.encode("utf-8")).hexdigest()}


def _carried(run: RunFile, kind: str):
    """The parsed dict of the description carried in ``meta.{kind}_description`` (or None)."""
    import hashlib
    import tomllib

    text = run.meta.get(f"{kind}_description")
    if not text:
        return None
    if not isinstance(text, str):
        raise _error(run.name, f"has meta {kind}_description that is not text", "store the description's TOML text")
    digest = run.meta.get(f"{kind}_sha256")
    if digest is not None and hashlib.sha256(text.encode("utf-8")).hexdigest() != digest:
        raise _error(
            run.name,
            f"has meta {kind}_description that does not match meta {kind}_sha256",
            f"restore the text or drop both keys (the stock {kind} file is used then)",
        )
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError:
        pass
    try:
        raw = json.loads(text)
    except json.JSONDecodeError:
        raw = None
    if not isinstance(raw, dict):
        raise _error(
            run.name,
            f"has meta {kind}_description that is neither TOML nor a JSON object",
            f"store the {kind} file's text",
        )
    return raw


def carried_label(run: RunFile, kind: str) -> str:
    """The source label of a description parsed from ``meta.{kind}_description``."""
    return f"{run.name} [meta.{kind}_description]"


def source_text(source: str) -> str:
    """The text of a description's ``source``: the file's text, or, for a description
    carried in a run (:func:`carried_label`), the text the run carries. One-line error
    when neither can be read."""
    import re

    p = Path(source)
    if p.is_file():
        return p.read_text(encoding="utf-8")
    m = re.fullmatch(r"(.+) \[meta\.(table|payload)_description\]", str(source))
    if m and Path(m.group(1)).is_file():
        text = read_run(m.group(1)).meta.get(f"{m.group(2)}_description")
        if isinstance(text, str) and text:
            return text
    raise RunFileError(
        _one_line(f"{source}: the description's text cannot be read; give the table's .toml file with --table")
    )


def _same_file(run: RunFile, kind: str) -> str | None:
    """``meta.{kind}_path`` when that file still holds the carried text (same SHA-256):
    the description then keeps its file as its source (a calibrated copy keeps the
    file's comments)."""
    import hashlib

    path, digest = run.meta.get(f"{kind}_path"), run.meta.get(f"{kind}_sha256")
    if not isinstance(path, str) or not isinstance(digest, str):
        return None
    try:
        data = Path(path).read_bytes()
    except OSError:
        return None
    return path if hashlib.sha256(data).hexdigest() == digest else None


def table_of(run: RunFile, override: str | None = None):
    """The table description ``run`` was made with: ``override`` (a name or path) if
    given, else the text carried in ``meta.table_description``, else the stock table
    named by ``meta.table``. Returns a :class:`mjcf.description.TableDescription`."""
    import mjcf
    from mjcf.description import parse_table

    if override:
        return mjcf.load_table(override)
    raw = _carried(run, "table")
    if raw is None:
        return mjcf.load_table(run.meta["table"])
    return parse_table(raw, _same_file(run, "table") or carried_label(run, "table"))


def payload_of(run: RunFile, override: str | None = None):
    """The payload ``run`` was made with (or None for a bare table): ``override`` (a name
    or path; ``"none"`` for a bare table) if given, else ``meta.payload_description``,
    else the stock payload named by ``meta.payload``."""
    import mjcf
    from mjcf.description import parse_payload

    if override is not None:
        return None if override.strip().lower() in ("", "none") else mjcf.load_payload(override)
    raw = _carried(run, "payload")
    if raw is not None:
        return parse_payload(raw, _same_file(run, "payload") or carried_label(run, "payload"))
    name = run.meta.get("payload")
    return mjcf.load_payload(name) if isinstance(name, str) and name.strip().lower() not in ("", "none") else None


__all__ = [
    "ACCELEROMETER_CHANNELS",
    "SPECIMEN_CHANNELS",
    "ACTUATOR_CHANNELS",
    "CHANNELS",
    "DOF_CHANNELS",
    "FORMAT",
    "INPUT_CHANNELS",
    "RunFile",
    "SPECIMEN_CHANNELS",
    "description_meta",
    "payload_of",
    "read_run",
    "source_text",
    "table_of",
    "write_run",
]
