"""Scenarios: table + payload + motion + controller + duration + outputs, as TOML data.

A scenario file (``scenarios/<name>.toml``)::

    [scenario]
    name = "elcentro_20t"
    table = "cgs"                 # scenarios/tables/cgs.toml
    payload = "rigid_20t"         # optional, scenarios/payloads/rigid_20t.toml
    duration_s = 60.0             # optional: default = the motion's length
    start_s = 20.0                # optional: where the run starts in the motion (default: the strong motion)
    pad_to_duration = false       # allow a duration longer than the motion (quiet padding)
    description = "..."

    [motion]                      # either one multi-DOF motion ...
    type = "el_centro_1940"       # the real 1940 El Centro record (3 components)
    amplitude_factor = 0.8

    [motion.x]                    # ... or one table per DOF
    type = "tapered_sine"         # sine | tapered_sine | triangle | white_noise | at2
    amplitude = 0.1
    frequency_hz = 0.25

    [controller]                  # optional gains (see sim.control.tvc.ControllerGains)
    kp_per_s = 25.0

    [output]
    sample_rate_hz = 1024.0       # recorder = controller rate

Relative paths (AT2 files, tables, payloads given as paths) are taken relative to the
scenario file. Every key is checked: an unknown key is an error that lists the known
ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjcf.description import DOFS6, REPO_ROOT, load_toml, resolve
from sim import validate as V
from sim.errors import MotionError, ScenarioError
from sim.scenario import motions as M
from sim.scenario import records as R
from sim.scenario.reference import Reference, reference_from_motions

SCENARIOS_DIR = REPO_ROOT / "scenarios"
DOFS = DOFS6

_SCEN_KEYS = {"name", "table", "payload", "duration_s", "start_s", "pad_to_duration", "description"}
#: Every motion type's keys and what each must be: "num" any finite number, "pos" > 0,
#: "nonneg" >= 0, "int" a whole number >= 0, "band" [f_lo, f_hi] in Hz, "text", "table".
_MOTION_SPEC = {
    "sine": {"type": "text", "amplitude": "num", "frequency_hz": "pos", "phase_rad": "num", "delay_s": "nonneg"},
    "tapered_sine": {
        "type": "text",
        "amplitude": "num",
        "frequency_hz": "pos",
        "phase_rad": "num",
        "taper_cycles": "nonneg",
        "delay_s": "nonneg",
    },
    "triangle": {
        "type": "text",
        "peak_displacement": "pos",
        "peak_velocity": "pos",
        "n_cycles": "pos",
        "rounding_fraction": "nonneg",
        "max_acceleration": "pos",
        "delay_s": "nonneg",
    },
    "white_noise": {
        "type": "text",
        "band_hz": "band",
        "seed": "int",
        "rms_acceleration": "pos",
        "rms_displacement": "pos",
        "taper_s": "nonneg",
        "delay_s": "nonneg",
    },
    "at2": {
        "type": "text",
        "file": "text",
        "amplitude_factor": "num",
        "target_pga": "pos",
        "time_factor": "pos",
        "highpass_hz": "pos",
        "filter_order": "int",
        "baseline": "text",
    },
}
_ITERATION_KEYS = {"count", "gain", "band_hz", "h_min", "frf", "noise_level", "seed"}
_OUTPUT_KEYS = {"sample_rate_hz"}
_MOTION_KEYS = {k: set(v) for k, v in _MOTION_SPEC.items()}
_EQ_SPEC = {
    "type": "text",
    "amplitude_factor": "num",
    "time_factor": "pos",
    "highpass_hz": "pos",
    "filter_order": "int",
    "baseline": "text",
    "mapping": "table",
}
_EQ_KEYS = set(_EQ_SPEC)
#: The keys a motion cannot do without.
_MOTION_REQUIRED = {
    "sine": ("amplitude", "frequency_hz"),
    "tapered_sine": ("amplitude", "frequency_hz"),
    "triangle": ("peak_displacement", "peak_velocity"),
    "white_noise": ("band_hz",),
    "at2": ("file",),
}


def _check_values(m: dict, spec: dict, where: str, src: str) -> None:
    """Each value of motion table ``m`` against its kind in ``spec`` (one line on error)."""
    for key, kind in spec.items():
        if key not in m:
            continue
        v, field = m[key], f"{where}.{key}"
        if kind == "num":
            V.number(v, field, src, ScenarioError)
        elif kind == "pos":
            V.number(v, field, src, ScenarioError, positive=True)
        elif kind == "nonneg":
            V.number(v, field, src, ScenarioError, nonneg=True)
        elif kind == "int":
            V.number(v, field, src, ScenarioError, integer=True, nonneg=True)
        elif kind == "band":
            V.numbers(v, field, src, ScenarioError, n=2, positive=True, increasing=True)
        elif kind == "text":
            V.text(v, field, src, ScenarioError)
        elif kind == "table" and not isinstance(v, dict):
            raise ScenarioError(f"{src}: '{field}' must be a table such as {{ x = \"180\" }} (got {v!r})")


@dataclass
class Scenario:
    name: str
    table: str
    payload: str | None
    duration_s: float | None
    pad_to_duration: bool
    description: str
    motion: dict
    controller: dict
    sample_rate_hz: float
    path: Path | None = None
    iteration: dict = field(default_factory=dict)
    raw: dict = field(default_factory=dict, repr=False)
    faults: list = field(default_factory=list)  #: [[fault]] and [[effect]] entries (sim.effects.faults)
    interlock: dict = field(default_factory=dict)  #: [interlock] limits over the table's
    start_s: float | None = None  #: where the run starts in the motion (None: the strong motion of a record)


def _load(path: Path) -> dict:
    return load_toml(path, ScenarioError, "scenario file")


def _unknown(keys, known, where, src):
    V.check_keys(keys, known, where, src, ScenarioError)


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load and check a scenario by name (``scenarios/<name>.toml``) or path."""
    try:
        path = resolve(name_or_path, SCENARIOS_DIR, "scenario")
    except Exception as e:  # DescriptionError from resolve: re-badge as a scenario problem
        raise ScenarioError(str(e)) from None
    data = _load(path)
    src = str(path)
    _unknown(
        data,
        {"scenario", "motion", "controller", "output", "iteration", "fault", "effect", "interlock"},
        "top level",
        src,
    )
    sc = V.require_table(data, "scenario", "scenario", src, ScenarioError, what="name, table, ...")
    _unknown(sc, _SCEN_KEYS, "scenario", src)
    for k in ("name", "table"):
        if k not in sc:
            raise ScenarioError(f"{src}: [scenario] lacks '{k}'; give it as text")
        V.text(sc[k], f"scenario.{k}", src, ScenarioError)
    if not all(c.isalnum() or c in "-_." for c in sc["name"]):
        raise ScenarioError(
            f"{src}: 'scenario.name' {sc['name']!r} names the output files; use letters, digits, '-', '_' and '.' only"
        )
    dur = sc.get("duration_s")
    if dur is not None:
        V.number(dur, "scenario.duration_s", src, ScenarioError, unit="s", positive=True)
    start = sc.get("start_s")
    if start is not None:
        V.number(start, "scenario.start_s", src, ScenarioError, unit="s", nonneg=True)
    mo = V.require_table(data, "motion", "motion", src, ScenarioError, what="type = ... or one [motion.<dof>] per DOF")
    if not mo:
        raise ScenarioError(f'{src}: [motion] is empty; give type = "el_centro_1940" or one [motion.<dof>] table')
    out = data.get("output", {})
    if not isinstance(out, dict):
        raise ScenarioError(f"{src}: [output] must be a table (sample_rate_hz)")
    _unknown(out, _OUTPUT_KEYS, "output", src)
    rate = V.sample_rate(out.get("sample_rate_hz", 1024.0), "output.sample_rate_hz", src, ScenarioError)
    if dur is not None:
        V.check_samples(float(dur) * rate + 1, f"'scenario.duration_s' = {dur:g} s at {rate:g} Hz", src, ScenarioError)
    it = _check_iteration(data, src)
    ctrl = data.get("controller", {})
    if not isinstance(ctrl, dict):
        raise ScenarioError(f"{src}: [controller] must be a table of gains")
    payload = sc.get("payload")
    if payload is not None and not isinstance(payload, str):
        raise ScenarioError(f"{src}: 'scenario.payload' must be a payload name or path")
    base = path.parent
    table = sc["table"]
    if table.endswith(".toml") and not Path(table).is_absolute():
        table = str(base / table)
    if payload and payload.endswith(".toml") and not Path(payload).is_absolute():
        payload = str(base / payload)
    faults = _scenario_effects(data, src)
    interlock = data.get("interlock", {})
    if not isinstance(interlock, dict):
        raise ScenarioError(f"{src}: [interlock] must be a table of limits (see docs/faults.md)")
    pad = sc.get("pad_to_duration", False)
    if not isinstance(pad, bool):
        raise ScenarioError(f"{src}: 'scenario.pad_to_duration' must be true or false")
    s = Scenario(
        name=sc["name"],
        table=table,
        payload=payload,
        duration_s=float(dur) if dur else None,
        pad_to_duration=pad,
        description=str(sc.get("description", "")),
        motion=mo,
        controller=ctrl,
        sample_rate_hz=float(rate),
        path=path,
        raw=data,
        iteration=dict(it),
        faults=faults,
        interlock=dict(interlock),
        start_s=float(start) if start is not None else None,
    )
    _check_motion(s)
    return s


def _check_iteration(data: dict, src: str) -> dict:
    """[iteration] (drive-file iteration before the run), checked; default no iteration."""
    it = data.get("iteration", {"count": 0})
    if not isinstance(it, dict):
        raise ScenarioError(f"{src}: [iteration] must be a table (count, gain, band_hz)")
    _unknown(it, _ITERATION_KEYS, "iteration", src)
    cnt = it.get("count", 0)
    if isinstance(cnt, bool) or not isinstance(cnt, int) or not 0 <= cnt <= 10:
        raise ScenarioError(f"{src}: 'iteration.count' must be an integer 0..10 (got {cnt!r})")
    if it.get("frf", "noise") not in ("noise", "record"):
        raise ScenarioError(f'{src}: \'iteration.frf\' must be "noise" or "record" (got {it["frf"]!r})')
    if "band_hz" in it:
        V.numbers(it["band_hz"], "iteration.band_hz", src, ScenarioError, n=2, positive=True, increasing=True)
    for key in ("gain", "noise_level", "h_min"):
        v = it.get(key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v < 1e3):
            raise ScenarioError(f"{src}: 'iteration.{key}' must be a positive number (got {v!r})")
    seed = it.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ScenarioError(f"{src}: 'iteration.seed' must be a non-negative integer (got {seed!r})")
    return it


def _scenario_effects(data: dict, src: str) -> list:
    """[[fault]] and [[effect]] entries, each a table with a 'type' (checked by sim.effects)."""
    faults = []  # [[fault]] / [[effect]]: effects the scenario adds to the table (docs/faults.md)
    for key in ("fault", "effect"):
        got = data.get(key, [])
        if not isinstance(got, list) or not all(isinstance(e, dict) and "type" in e for e in got):
            raise ScenarioError(f"{src}: [[{key}]] entries must be tables with a 'type' (see docs/faults.md)")
        faults += got
    return faults


def _check_factor(m: dict, where: str, src: str):
    f = m.get("amplitude_factor", 1.0)
    if isinstance(f, bool) or not isinstance(f, (int, float)) or not f > 0:
        raise ScenarioError(
            f"{src}: '{where}.amplitude_factor' must be a positive scale (got {f!r}); 1.0 is the record as recorded"
        )


def _check_motion(s: Scenario):
    src = str(s.path)
    mo = s.motion
    if "type" in mo:
        if mo["type"] != "el_centro_1940":
            raise ScenarioError(
                f"{src}: [motion] type {mo['type']!r} is not a multi-DOF motion; "
                'use type = "el_centro_1940" or one [motion.<dof>] table per DOF'
            )
        _unknown(mo, _EQ_KEYS, "motion", src)
        _check_values(mo, _EQ_SPEC, "motion", src)
        for dof, comp in mo.get("mapping", {}).items():
            if dof not in DOFS or not isinstance(comp, str):
                raise ScenarioError(
                    f"{src}: 'motion.mapping' maps DOF names ({', '.join(DOFS)}) to components "
                    f'such as "180" (got {dof} = {comp!r})'
                )
        _check_factor(mo, "motion", src)
        return
    for dof, m in mo.items():
        if dof not in DOFS:
            raise ScenarioError(
                f"{src}: [motion.{dof}]: '{dof}' is not a DOF{V.suggest(dof, DOFS)}; "
                f'DOFs are {", ".join(DOFS)} (or type = "el_centro_1940" in [motion])'
            )
        if not isinstance(m, dict) or "type" not in m:
            raise ScenarioError(f"{src}: [motion.{dof}] needs a 'type' ({', '.join(_MOTION_KEYS)})")
        if m["type"] not in _MOTION_KEYS:
            raise ScenarioError(
                f"{src}: [motion.{dof}] type {m['type']!r} is unknown"
                f"{V.suggest(m['type'], _MOTION_KEYS)}; types: {', '.join(_MOTION_KEYS)}"
            )
        _unknown(m, _MOTION_KEYS[m["type"]], f"motion.{dof}", src)
        _check_values(m, _MOTION_SPEC[m["type"]], f"motion.{dof}", src)
        for key in _MOTION_REQUIRED[m["type"]]:
            if key not in m:
                raise ScenarioError(f"{src}: [motion.{dof}] ({m['type']}) lacks '{key}'")
        if m["type"] == "at2":
            _check_factor(m, f"motion.{dof}", src)


def _shift(mo: M.Motion, delay_s: float, rate: float) -> M.Motion:
    n = int(round(delay_s * rate))
    if n <= 0:
        return mo
    z = np.zeros(n)
    t = np.arange(len(mo.t) + n) / rate
    return M.Motion(
        t, np.concatenate([z, mo.d]), np.concatenate([z, mo.v]), np.concatenate([z, mo.a]), mo.name, mo.info
    )


def build_motions(s: Scenario) -> dict[str, M.Motion]:
    """Per-DOF motions at the scenario's rate (SI: m, rad)."""
    rate = s.sample_rate_hz
    mo = s.motion
    if mo.get("type") == "el_centro_1940":
        kw = {k: v for k, v in mo.items() if k in ("time_factor", "highpass_hz", "filter_order", "baseline")}
        return R.el_centro_motions(
            sample_rate_hz=rate,
            amplitude_factor=float(mo.get("amplitude_factor", 1.0)),
            mapping=mo.get("mapping"),
            **kw,
        )
    out = {}
    for i, (dof, m) in enumerate(mo.items()):
        try:
            out[dof] = _build_one(s, i, dof, dict(m), rate)
        except MotionError as e:  # name the file and the table the motion came from
            raise MotionError(f"{s.path}: [motion.{dof}]: {e}") from None
    return out


def _build_one(s: Scenario, i: int, dof: str, m: dict, rate: float) -> M.Motion:
    default_dur = s.duration_s
    kind = m.pop("type")
    delay = float(m.pop("delay_s", 0.0))
    if kind in ("sine", "tapered_sine", "white_noise"):
        if default_dur is None:
            raise ScenarioError(f"{s.path}: a {kind} motion needs 'scenario.duration_s'")
        dur = default_dur - delay
        if not dur > 0:
            raise ScenarioError(
                f"{s.path}: 'motion.{dof}.delay_s' ({delay:g} s) leaves nothing of "
                f"'scenario.duration_s' ({default_dur:g} s); shorten the delay"
            )
    if kind == "sine":
        x = M.sine(duration_s=dur, sample_rate_hz=rate, **m)
    elif kind == "tapered_sine":
        x = M.tapered_sine(duration_s=dur, sample_rate_hz=rate, **m)
    elif kind == "triangle":
        x = M.triangle(sample_rate_hz=rate, **m)
    elif kind == "white_noise":
        seed = m.pop("seed", 0)
        band = tuple(m.pop("band_hz"))
        x = M.white_noise(duration_s=dur, sample_rate_hz=rate, band_hz=band, seed=(int(seed), i), **m)
    else:  # at2
        f = Path(m.pop("file"))
        if not f.is_absolute():
            f = s.path.parent / f
        rec = R.read_at2(f)
        x = R.process_record(rec.acceleration, rec.dt, sample_rate_hz=rate, name=f.name, **m)
    V.check_samples(len(x.t) + delay * rate, f"'motion.{dof}' with its delay", s.path, ScenarioError)
    return _shift(x, delay, rate)


def build_reference(s: Scenario, motions: dict[str, M.Motion], duration_s: float | None = None) -> Reference:
    """Stack the motions into a 6-DOF reference over the run's duration (see :func:`build_window`)."""
    return build_window(s, motions, duration_s)[0]


#: taper at each end of a record window, s (at most a fifth of the window); assumed: two
#: seconds bring the table from rest into the strong motion with added accelerations
#: (2 v w' + d w'') of a few tenths of m/s^2 for El Centro's 0.1 m, 0.3 m/s
WINDOW_TAPER_S = 2.0


def build_window(
    s: Scenario, motions: dict[str, M.Motion], duration_s: float | None = None, start_s: float | None = None
) -> tuple[Reference, dict]:
    """The 6-DOF reference over the run's duration and the window of the motion it holds.

    A duration (``duration_s``, else ``scenario.duration_s``) shorter than an earthquake
    record keeps the strong motion (its Arias intensity, the translations' together):
    centred on the record's 5-95 % Arias-intensity interval when it covers it, else the
    window of that length holding the most intensity; the window's displacement is
    tapered over :data:`WINDOW_TAPER_S` at both ends (:func:`sim.scenario.records.window_motion`),
    so the table starts and ends at rest. Other motions run their first ``duration`` seconds.
    A start (``start_s``, else ``scenario.start_s``) places the window there instead, in
    any motion, tapered the same way (default duration: the rest of the motion).
    The window: ``{"start_s", "end_s", "of_record_s", "why"}`` (s of the motion's time).
    """
    rate = s.sample_rate_hz
    length = max(m.duration_s for m in motions.values())
    start = start_s if start_s is not None else s.start_s
    if start is not None:
        return _window_at(s, motions, duration_s if duration_s is not None else s.duration_s, float(start))
    dur = duration_s if duration_s is not None else (s.duration_s if s.duration_s is not None else length)
    V.check_samples(dur * rate + 1, f"a run of {dur:g} s at {rate:g} Hz", s.path, ScenarioError)
    if dur > length + 1.5 / rate and not s.pad_to_duration:
        raise ScenarioError(
            f"{s.path}: duration {dur:g} s is longer than the motion ({length:.2f} s); shorten --duration or set "
            "'scenario.pad_to_duration = true' to pad with rest"
        )
    record = any(m.info.get("kind") == "record" for m in motions.values())
    n_win = int(round(dur * rate)) + 1
    n_len = max(len(m.t) for m in motions.values())
    if not record or n_win >= n_len:
        why = "the whole motion" if n_win >= n_len else f"the first {dur:g} s (the motion is not an earthquake record)"
        return reference_from_motions(motions, rate, dur), {
            "start_s": 0.0,
            "end_s": float(dur),
            "of_record_s": float(length),
            "why": why,
        }
    h = 1.0 / rate
    # Arias intensity of the translations (m/s^2); of the rotations only if there are no translations
    trans = [m for d, m in motions.items() if DOFS.index(d) < 3] or list(motions.values())
    acc = np.zeros((n_len, len(trans)))
    for k, m in enumerate(trans):
        acc[: len(m.a), k] = m.a
    t5, t95 = R.arias_interval(acc, h)
    if dur >= t95 - t5:
        i0 = int(round(min(max(0.5 * (t5 + t95) - dur / 2, 0.0), (n_len - n_win) * h) * rate))
        how = f"centred on the record's 5-95 % Arias-intensity interval ({t5:.1f}-{t95:.1f} s)"
    else:
        cum = np.concatenate([[0.0], np.cumsum((acc**2).sum(axis=1))])
        i0 = int(np.argmax(cum[n_win:] - cum[:-n_win]))
        share = (cum[i0 + n_win] - cum[i0]) / cum[-1]
        how = (
            f"the {dur:g} s holding the most Arias intensity ({100 * share:.0f} % of the record's; "
            f"its 5-95 % interval is {t5:.1f}-{t95:.1f} s)"
        )
    return _cut(motions, rate, n_len, i0, dur, f"strong motion: {how}")


def _cut(motions: dict, rate: float, n_len: int, i0: int, dur: float, why: str) -> tuple[Reference, dict]:
    """Samples [i0, i0 + dur * rate] of every motion (a shorter one at rest after its end),
    tapered at both ends (:data:`WINDOW_TAPER_S`, at most a fifth of the window)."""
    h = 1.0 / rate
    i1 = i0 + int(round(dur * rate)) + 1
    taper = min(WINDOW_TAPER_S, 0.2 * dur)
    cut = {}
    for dof, m in motions.items():
        if len(m.d) < max(n_len, i1):  # at rest after its end
            m = R.pad(m, 0.0, (max(n_len, i1) - len(m.d)) * h)
        cut[dof] = R.window_motion(m, i0, i1, taper)
    window = {
        "start_s": i0 * h,
        "end_s": (i1 - 1) * h,
        "of_record_s": float(max(mo.duration_s for mo in motions.values())),
        "why": f"{why}; the displacement tapered over {taper:g} s at both ends",
    }
    return reference_from_motions(cut, rate, dur), window


def _window_at(s: Scenario, motions: dict, dur: float | None, start: float) -> tuple[Reference, dict]:
    """The window of :func:`build_window` placed at ``start`` (s of the motion)."""
    rate = s.sample_rate_hz
    length = max(m.duration_s for m in motions.values())
    n_len = max(len(m.t) for m in motions.values())
    where = s.path or s.name
    if not start >= 0:
        raise ScenarioError(f"{where}: start {start:g} s must be 0 or more seconds into the motion")
    if start >= length:
        raise ScenarioError(
            f"{where}: start {start:g} s is at or past the end of the motion ({length:.2f} s); give a start_s before it"
        )
    dur = length - start if dur is None else float(dur)
    V.check_samples(dur * rate + 1, f"a run of {dur:g} s at {rate:g} Hz", s.path, ScenarioError)
    if start + dur > length + 1.5 / rate and not s.pad_to_duration:
        raise ScenarioError(
            f"{where}: start {start:g} s + duration {dur:g} s runs past the end of the motion ({length:.2f} s); "
            "start earlier, shorten the duration or set 'scenario.pad_to_duration = true'"
        )
    i0 = int(round(start * rate))
    return _cut(motions, rate, n_len, i0, dur, f"from start_s = {start:g} s")


def limit_warnings(desc, motions: dict[str, M.Motion]) -> list[str]:
    """Warnings for a reference beyond the table's rated stroke, velocity or acceleration."""
    lim = desc.limits
    limits = {
        "stroke_m": {d: float(v) for d, v in zip(("x", "y", "z"), lim.stroke_m)},
        "rotation_rad": {d: float(v) for d, v in zip(("rx", "ry", "rz"), lim.rotation_rad)},
        "velocity_m_s": {d: float(v) for d, v in zip(("x", "y", "z"), lim.velocity_m_s)},
        "acceleration_m_s2": {d: float(v) for d, v in zip(("x", "y", "z"), lim.acceleration_m_s2)},
    }
    try:
        return M.check_limits(motions, limits)
    except MotionError:
        raise
    except Exception:  # pragma: no cover - defensive: the check must never stop a run
        return []


def list_scenarios() -> list[str]:
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))


__all__ = [
    "Scenario",
    "WINDOW_TAPER_S",
    "build_motions",
    "build_reference",
    "build_window",
    "limit_warnings",
    "list_scenarios",
    "load_scenario",
]
