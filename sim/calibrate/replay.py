"""Open-loop replay of a run file's recorded valve commands through the model: the
first step of closing the loop with measured data (the residual is what the model
lacks).

The record keeps its own time. The model keeps the physics step ``shaketable run`` gives
its table (1/2048 s; 1/8000 s for the Rice table's analog controller,
:func:`sim.loop.simulation.table_model`) and ticks at a rate that divides it; the
recorded command is held onto those ticks (zero-order hold, as the lab's DAC held it) or,
where the table's controller ticks faster than the record, interpolated onto the
controller's ticks (:func:`command_hold`), and the model's channels are sampled back at
the record's instants, where the comparison is made. A record at 1024 Hz (or any rate
dividing the physics rate) is replayed on its own samples.

Before anything is compared the valve null bias (and its drift) is estimated from the
recorded motion (:mod:`sim.calibrate.valve_null`) and added to the command, so that an
offset the closed loop hid does not walk the open-loop model to its end stop. Open loop,
the displacement is the integral of the flow: any small flow error accumulates, so the
residual is also given for velocity, acceleration and the band-passed displacement.

The model's channels are compared as the record's chain gives them: through the
recorder's anti-alias and each channel's conditioner and delay that the record declares
(``meta.recorder``, ``meta.channel_conditioning``; :func:`through_declared_chain`, as
calibration compares them); the replay's run file keeps the model's own channels. The
record's set-up, the model's run file and this comparison are shared with the
closed-loop replay (:mod:`sim.calibrate.closed_replay`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim.errors import RunFileError
from sim.runs.runfile import COMMAND_HOLDS

PHYSICS_HZ = 2048.0  #: the model's physics rate (mjcf.builder default step 1/2048 s)
TICK_HZ = 1024.0  #: replay tick for records whose rate does not divide the physics rate
INPUTS = ("valve_command", "reference")  #: what drives the replay: not compared
DISPLACEMENT_BAND_HZ = (0.2, 50.0)  #: band of the displacement comparison (open-loop drift removed)


@dataclass
class ReplayOutcome:
    """The replayed run (a run file at the record's instants, the record's DOF
    columns), the loop's result (at the model's tick), the residual NRMSE per channel and
    column against the source run, the valve null estimate and notes for the summary."""

    run: object
    result: object
    residual_nrmse: dict
    source: str
    valve_null: dict | None = None
    tick_hz: float = TICK_HZ
    notes: list = field(default_factory=list)
    stroke_fraction: dict = field(default_factory=dict)
    not_compared: dict = field(default_factory=dict)
    hold: str = "zoh"

    @property
    def complete(self) -> bool:
        return self.result.incomplete_reason is None

    def summary(self) -> dict:
        return {
            "replay_of": self.source,
            "record_rate_hz": self.run.sample_rate_hz,
            "model_tick_hz": self.tick_hz,
            "complete": self.complete,
            "incomplete_reason": self.result.incomplete_reason,
            "realtime_factor": float(self.result.realtime_factor),
            "valve_null": self.valve_null,
            "peak_stroke_fraction": self.stroke_fraction,
            "residual_nrmse": self.residual_nrmse,
            "not_compared": self.not_compared,
            "command_hold": self.hold,
            "notes": self.notes,
        }


def tick_rate(
    record_hz: float, hold: str = "zoh", physics_hz: float = PHYSICS_HZ, controller_hz: float = TICK_HZ
) -> float:
    """The model's tick for a record at ``record_hz`` on a model stepping at ``physics_hz``.
    A held command (``"zoh"``) ticks at the record's own rate when it divides the physics
    rate (the command changes only there), else at the whole fraction of the physics rate
    nearest :data:`TICK_HZ` (1024 Hz at 2048 Hz; 1000 Hz at the Rice table's 8000 Hz).
    An interpolated one (``"linear"``, ``"cubic"``) ticks at the table controller's own rate
    ``controller_hz`` (the record's where that is faster and divides the physics rate):
    what the controller did between the record's samples."""
    r = physics_hz / record_hz
    own = abs(r - round(r)) < 1e-9 and round(r) >= 1
    if hold != "zoh":
        fast = physics_hz / max(1, round(physics_hz / controller_hz))
        return max(fast, float(record_hz)) if own else fast
    return float(record_hz) if own else physics_hz / max(1, round(physics_hz / TICK_HZ))


def command_on_ticks(t_rec, command, t_tick, hold: str) -> np.ndarray:
    """The recorded command on the model's ticks: held (``"zoh"``), or interpolated
    linearly or by a cubic spline through the samples (held flat past the ends). Linear
    interpolation loses 3 % of a command's amplitude at a tenth of the record's rate
    (sinc^2), which a flow gain then made up: 1.0055 +/- 0.0010 on the worked example's
    200 Hz bare-table record (2026-11-27); a cubic spline loses about 0.05 % there."""
    from scipy.interpolate import CubicSpline

    from sim.signals.resample import hold as zoh
    from sim.signals.resample import interpolate

    if hold == "zoh":
        return zoh(t_rec, command, t_tick)
    if hold == "linear":
        return interpolate(t_rec, command, t_tick)
    return CubicSpline(t_rec, np.asarray(command, float), axis=0)(np.clip(t_tick, t_rec[0], t_rec[-1]))


def model_rates(tm) -> tuple[float, float]:
    """``(physics, controller)`` rates of the model ``tm`` in Hz (the controller's: its
    table's ``[controller]``)."""
    from sim.control.base import controller_settings

    return 1.0 / float(tm.model.opt.timestep), float(controller_settings(tm.desc).controller_rate_hz)


def command_hold(src, desc) -> str:
    """How a record's valve command goes onto the model's ticks: the record's
    ``meta.command_hold`` where it says; else held (``"zoh"``) when the table's
    controller ticks no faster than the record, interpolated (``"cubic"``) when it ticks
    faster. A slower recorder's samples of a faster controller's command, held, lag it by
    half a record step (docs/import.md): on the Rice table's 4000 Hz records of its
    analog controller (8000 Hz), a 12 ms valve delay came out one physics step short."""
    from sim.control.base import controller_settings

    said = src.meta.get("command_hold")
    if said:
        return str(said)
    return "cubic" if controller_settings(desc).controller_rate_hz > src.sample_rate_hz * (1 + 1e-9) else "zoh"


def ticks_covering(t_rec, rate: float) -> np.ndarray:
    """The model's ticks at ``rate`` from 0 through the record's last instant (one tick
    past it when the two grids differ): a model sampled back at every recorded instant
    (a 4000 Hz record's last instant lies after the last 1000 Hz tick before it)."""
    n_tick = int(np.ceil(float(t_rec[-1]) * rate - 1e-6)) + 1
    return np.arange(n_tick) / rate


def _columns(src, ch: str, run, model: dict | None = None) -> np.ndarray | None:
    """``run``'s channel ``ch`` (``model[ch]`` in ``run``'s columns where given) with the
    columns of ``src`` (by name); None if a name is missing."""
    a = getattr(src, ch)
    b = getattr(run, ch) if model is None or ch not in model else model[ch]
    if a is None or b is None:
        return None
    names_a, names_b = src.column_names(ch), run.column_names(ch)
    if not all(n in names_b for n in names_a):
        return None
    return b[:, [names_b.index(n) for n in names_a]]


def not_compared(src, run) -> dict:
    """Every channel (and column) of the record that :func:`residuals` does not compare,
    with the reason."""
    from sim.runs.runfile import CHANNELS

    out = {}
    for ch in CHANNELS:
        a = getattr(src, ch)
        if a is None:
            continue
        if ch in INPUTS:
            out[ch] = (
                "the replay's input"
                if ch == "valve_command"
                else "kept in the replay file; the open-loop replay does not use it"
            )
            continue
        if getattr(run, ch) is None:
            out[ch] = "the model does not record it"
            continue
        names_b = run.column_names(ch)
        miss = [nm for nm in src.column_names(ch) if nm not in names_b]
        if miss:
            out[ch] = (
                f"column(s) {', '.join(miss)} are not sensors of the table description "
                f"(it has {', '.join(names_b) or 'none'}); declare them as [[accelerometer]] to compare"
            )
    return out


def residuals(src, run, model: dict | None = None) -> dict:
    """NRMSE of every channel the record and the replay share (by column name), plus the
    band-passed displacements and, for a record without velocity, the velocity from its
    displacement. ``model``: the replay's channels as compared (:func:`through_declared_chain`),
    in place of ``run``'s own. Keys: channel names; ``<channel>_bandpassed`` and
    ``table_velocity_from_displacement`` for the derived comparisons."""
    from sim.assess.metrics import nrmse
    from sim.runs.runfile import CHANNELS
    from sim.signals.resample import bandpass

    n = min(src.n_samples, run.n_samples)
    fs = src.sample_rate_hz
    out = {}
    for ch in CHANNELS:
        if ch in INPUTS:
            continue
        b = _columns(src, ch, run, model)
        if b is None:
            continue
        a = getattr(src, ch)[:n]
        b = b[:n]
        out[ch] = {nm: nrmse(b[:, j], a[:, j]) for j, nm in enumerate(src.column_names(ch))}
        if (
            ch in ("table_displacement", "actuator_displacement")
            and n > 30
            and np.all(np.isfinite(a))
            and np.all(np.isfinite(b))
        ):
            ab, bb = bandpass(a, fs, DISPLACEMENT_BAND_HZ), bandpass(b, fs, DISPLACEMENT_BAND_HZ)
            out[ch + "_bandpassed"] = {nm: nrmse(bb[:, j], ab[:, j]) for j, nm in enumerate(src.column_names(ch))}
    if src.table_velocity is None and src.table_displacement is not None and run.table_velocity is not None:
        b = _columns(src, "table_displacement", run, model)
        if b is not None and n > 2:
            va = np.gradient(src.table_displacement[:n], 1.0 / fs, axis=0)
            vb = np.gradient(b[:n], 1.0 / fs, axis=0)
            out["table_velocity_from_displacement"] = {nm: nrmse(vb[:, j], va[:, j]) for j, nm in enumerate(src.dofs)}
    return out


@dataclass
class RecordModel:
    """A record and the model it is replayed through: the record's name and run, the
    table description, payload and built model, and the record's time from 0."""

    name: str
    src: object
    desc: object
    payload: object
    tm: object
    t: np.ndarray


def read_record(source, require: str) -> tuple[str, object]:
    """``(name, run)`` of ``source`` (a run-file path, or a
    :class:`~sim.runs.runfile.RunFile` checked here), which must hold channel ``require``."""
    from sim.runs.runfile import read_run

    if isinstance(source, (str, Path)):
        return str(source), read_run(source, require=(require,))
    source.validate(require=(require,))
    return source.path or "<run>", source


def record_model(name: str, src, table: str | None, payload: str | None, *, check_actuators: bool) -> RecordModel:
    """The model a record is replayed through: ``table``/``payload`` when given, else the
    descriptions the run carries (``meta.table_description``/``meta.payload_description``),
    else the stock files its meta names. The record's declared conditioning must be
    readable, its DOF columns DOF names and, with ``check_actuators``, its actuator
    columns the table's (one-line errors)."""
    from mjcf.description import DOFS6
    from sim.calibrate.conditioning import channel_conditioning
    from sim.loop.simulation import description_as_run, table_model
    from sim.runs.runfile import payload_of, table_of

    channel_conditioning(src)  # a declaration the comparison cannot read: said before the run
    desc = description_as_run(table_of(src, table))  # as `run` simulates it (the Rice table's parameter set)
    if check_actuators and list(src.actuators) != list(desc.actuator_names):
        raise RunFileError(
            f"{name}: actuators {src.actuators} do not match table '{desc.name}' "
            f"({list(desc.actuator_names)}); give --table or rename the actuator columns"
        )
    missing = [d for d in src.dofs if d not in DOFS6]
    if missing:
        raise RunFileError(f"{name}: DOF column(s) {missing} are not DOF names ({', '.join(DOFS6)}); fix meta.dofs")
    pl = payload_of(src, payload)
    t = np.asarray(src.t, float) - float(src.t[0])
    return RecordModel(name=name, src=src, desc=desc, payload=pl, tm=table_model(desc, pl), t=t)


def model_run(rec: RecordModel, res, chans: dict, extras: dict, n: int, description: str, meta: dict, notes: list):
    """The model's run file at the record's first ``n`` instants: its channels ``chans``
    (:func:`record_channels`), the record's reference kept, the specimen sensors the
    record declares (:func:`_specimen_at_record`, a note for each the model cannot give),
    the record's rate and DOF columns, and ``meta`` added to the model's own."""
    from sim.runs.build import build_runfile
    from sim.runs.runfile import RunFile

    src = rec.src
    pl = rec.payload
    tick_run = build_runfile(res, rec.tm, description=description, payload_name=pl.name if pl else None)
    m = dict(tick_run.meta)
    m.update({"sample_rate_hz": src.sample_rate_hz, "dofs": list(src.dofs)})
    m.update(meta)
    if src.reference is not None:
        chans["reference"] = np.asarray(src.reference[:n], float).copy()
    if src.meta.get("specimen_sensors"):
        m["specimen_sensors"] = list(src.meta["specimen_sensors"])
        chans["specimen_acceleration"] = _specimen_at_record(res, pl, m["specimen_sensors"], rec.t[:n], notes)
    run = RunFile(t=np.asarray(src.t[:n], float).copy(), meta=m, extras=extras, **chans)
    if res.incomplete_reason:
        run.mark_incomplete(res.incomplete_reason)
    return run


def through_declared_chain(src, run) -> tuple[dict, str | None]:
    """The model's channels of ``run`` (all but the inputs) as the record ``src`` holds
    them: through the recorder chain it declares (:func:`sim.calibrate.conditioning.apply`:
    ``meta.recorder``'s anti-alias low-pass, then each channel's declared conditioner and
    delay, ``meta.channel_conditioning``), as calibration compares them; and the line
    that says so (None when the record declares nothing)."""
    from sim.calibrate import conditioning
    from sim.runs.runfile import CHANNELS

    chans = {c: getattr(run, c) for c in CHANNELS if c not in INPUTS and getattr(run, c) is not None}
    known = {"recorder": conditioning.recorder(src), "channels": conditioning.channel_conditioning(src)}
    fs = run.sample_rate_hz
    fc = known["recorder"].get("anti_alias_hz")
    fc = fc if fc and fc < 0.5 * fs else None  # conditioning.apply filters below the Nyquist frequency only
    applied = [c for c in known["channels"] if c in chans and getattr(src, c) is not None]
    if not applied and not fc:
        return chans, None
    parts = []
    if applied:
        parts.append(
            "the declared conditioning of "
            + ", ".join(f"{c} ({_chain_text(known['channels'][c], fs)})" for c in applied)
        )
    if fc:
        parts.append(f"the recorder's {int(known['recorder'].get('anti_alias_order', 4))}-pole {fc:g} Hz anti-alias")
    return conditioning.apply(chans, known, fs), "compared through " + " and ".join(parts)


def _chain_text(spec: dict, fs: float) -> str:
    """``4-pole 50 Hz low-pass, 2.00 ms delay`` for a declared conditioning of a record at
    ``fs`` (a low-pass at or above its Nyquist frequency is not applied, and says so)."""
    out = []
    if spec.get("lowpass_hz"):
        above = spec["lowpass_hz"] >= 0.5 * fs
        out.append(
            f"{spec['lowpass_order']}-pole {spec['lowpass_hz']:g} Hz low-pass"
            + (f" at or above the record's Nyquist frequency {0.5 * fs:g} Hz: not applied" if above else "")
        )
    if spec.get("delay_s"):
        out.append(f"{1e3 * spec['delay_s']:.2f} ms delay")
    return ", ".join(out) or "nothing"


def comparison(src, run, notes: list) -> tuple[dict, dict]:
    """``(residual NRMSE, model channels as compared)`` of the replay ``run`` against the
    record ``src``, through the record's declared chain (:func:`through_declared_chain`;
    its line goes into ``notes``)."""
    model, line = through_declared_chain(src, run)
    if line:
        notes.append(line)
    return residuals(src, run, model), model


def replay(
    source,
    *,
    table: str | None = None,
    payload: str | None = None,
    progress: bool = False,
    bias: str | float | None = None,
    drift: bool = False,
    hold: str | None = None,
) -> ReplayOutcome:
    """Replay ``source`` (a run-file path or :class:`~sim.runs.runfile.RunFile`) open loop.

    ``table``/``payload``: override the descriptions the run carries
    (``meta.table_description``/``meta.payload_description``, else the stock files named
    by ``meta.table``/``meta.payload``).
    ``bias``: ``"estimate"`` (the valve null offset, and with ``drift`` its linear drift,
    from the recorded motion), ``"none"``, or a number (the same offset, fraction of rated
    opening, on every valve); default ``"estimate"`` for a measured run, ``"none"`` for a
    simulated one (its valves had no hidden null: it replays to round-off). ``hold``:
    ``"zoh"``, ``"linear"`` or ``"cubic"`` (command onto the model's ticks, :data:`sim.runs.runfile.COMMAND_HOLDS`).
    """
    name, src = read_record(source, "valve_command")
    rec = record_model(name, src, table, payload, check_actuators=True)
    hold = hold or command_hold(src, rec.desc)
    if hold not in COMMAND_HOLDS:
        raise RunFileError(
            f"{name}: command hold must be one of {', '.join(COMMAND_HOLDS)} (got {hold!r}); fix meta.command_hold or --hold"
        )
    desc = rec.desc
    notes = []
    if bias is None:
        bias = "estimate" if src.source == "measured" else "none"
    u, vn = _with_valve_null(src, desc, bias, drift, notes)
    u = drive_on_the_analog_clock(u, desc, rec.t, notes)
    rate = tick_rate(src.sample_rate_hz, hold, *model_rates(rec.tm))
    if rate != src.sample_rate_hz:
        notes.append(
            f"record at {src.sample_rate_hz:g} Hz: command "
            + ("held (zero-order hold)" if hold == "zoh" else "interpolated")
            + f" onto the model's {rate:g} Hz ticks, model sampled at the record's instants"
        )
    res, chans, extras, n = run_at_record(rec.tm, rec.t, u, src.dofs, hold=hold, progress=progress)
    meta = {"replay_of": name, "model_tick_hz": rate}
    if vn is not None:
        meta["valve_null"] = vn
    run = model_run(rec, res, chans, extras, n, f"open-loop replay of {Path(name).name}", meta, notes)
    frac = _stroke_fractions(desc, res, notes)
    notes.append(
        f"open loop the displacement is the integral of the flow (a small flow error drifts): "
        f"displacements are also compared band-passed {DISPLACEMENT_BAND_HZ[0]:g}-"
        f"{min(DISPLACEMENT_BAND_HZ[1], 0.45 * src.sample_rate_hz):g} Hz; velocity and acceleration "
        "are the meaningful comparisons"
    )
    resid, _ = comparison(src, run, notes)
    return ReplayOutcome(
        run=run,
        result=res,
        residual_nrmse=resid,
        source=name,
        valve_null=vn,
        tick_hz=rate,
        notes=notes,
        stroke_fraction=frac,
        not_compared=not_compared(src, run),
        hold=hold,
    )


def drive_on_the_analog_clock(u: np.ndarray, desc, t, notes: list, what: str = "command") -> np.ndarray:
    """The recorded ``what`` (the commands, or ``shaketable replay --closed-loop``'s
    reference) read as late as the description says the controller's channels were
    recorded (:func:`sim.calibrate.conditioning.on_the_analog_clock`), said in a note."""
    from sim.calibrate import conditioning

    lag = conditioning.controller_lag(desc.raw.get("effect", []))
    if lag:
        notes.append(
            f"the controller's channels recorded {1e3 * lag:.3g} ms late (the description's "
            f"sensor_delay at channel:valve_command): the {what} replayed that much earlier"
        )
    return conditioning.on_the_analog_clock(u, lag, float(t[1] - t[0]))


def _with_valve_null(src, desc, bias, drift: bool, notes: list) -> tuple[np.ndarray, dict | None]:
    """The record's valve commands with the valve null offset :func:`replay`'s ``bias``
    asks for, and that offset as the summary gives it (None: none added)."""
    from sim.calibrate.valve_null import estimate

    u = np.asarray(src.valve_command, float)
    vn = None
    if bias == "estimate":
        est = estimate(src, desc, drift=drift)
        vn = est.as_dict(src.actuators)
        u = u + est.at(np.asarray(src.t, float))
        notes.append(
            "valve null offset estimated from the recorded motion and added to the command "
            f"(mean {100 * float(np.mean(est.offset)):+.3f} % of rated opening"
            + (f", drift {100 * float(np.mean(est.drift_per_s)):+.4f} %/s)" if drift else ")")
        )
    elif bias != "none":
        try:
            b = float(bias)
        except (TypeError, ValueError):
            raise RunFileError(f"replay bias must be 'estimate', 'none' or a number (got {bias!r})") from None
        vn = {"offset": {a: b for a in src.actuators}, "method": "given"}
        u = u + b
    return u, vn


def _stroke_fractions(desc, res, notes: list) -> dict:
    """Peak stroke of each actuator in the replay ``res`` (fraction of its half-stroke); a
    note when one reached its end cushions."""
    half = np.array([a.cls.half_stroke_m for a in desc.actuators])
    peak = np.nanmax(np.abs(res.channels["actuator_displacement"]), axis=0) / half
    frac = {a: float(p) for a, p in zip(desc.actuator_names, peak)}
    cush = np.array(
        [
            1.0 - float(desc.raw["actuator_class"][a.cls.name].get("cushion_length_m", 0.0)) / a.cls.half_stroke_m
            for a in desc.actuators
        ]
    )
    hit = [a for a, p, c in zip(desc.actuator_names, peak, cush) if p >= c]
    if hit:
        notes.append(
            f"actuator(s) {', '.join(hit)} reached the end cushions: the replay drifted to the stroke end "
            "(a valve null bias not removed, or a flow-gain error); the comparison after that is meaningless"
        )
    return frac


def _specimen_at_record(res, payload, sensors, t_rec, notes) -> np.ndarray:
    """The model's specimen sensors (:func:`sim.runs.specimen.specimen_accelerations`) at
    the record's instants ``t_rec``; a note for each sensor the model cannot give."""
    from sim.runs.specimen import specimen_accelerations
    from sim.signals.resample import interpolate

    acc = res.channels["table_acceleration"]
    arr, why = specimen_accelerations(res.t, acc, res.extras.get("payload_qpos"), payload, sensors)
    notes.extend(why)
    if len(res.t) == len(t_rec) and np.allclose(res.t, t_rec):
        return arr
    return interpolate(res.t, arr, t_rec)


def run_at_record(tm, t_rec, valve_command, dofs, *, hold: str = "zoh", progress: bool = False):
    """Run the model ``tm`` open loop on ``valve_command`` (N, n_act) sampled at ``t_rec``
    (from 0, uniform, any rate): the command is held (``"zoh"``) or interpolated
    (``"linear"``) onto the model's ticks (:func:`tick_rate`), and the recorder's channels
    (sensor effects applied) are sampled back at the record's instants, DOF channels in
    the columns ``dofs``. Returns ``(result, channels, extras, n)``: ``n`` record samples
    were reached (all of them unless the run stopped early)."""
    sim, cmd = replay_setup(tm, t_rec, valve_command, hold=hold)
    res = sim.run(valve_command=cmd, progress=progress)
    chans, extras, n = record_channels(res, tm, t_rec, dofs, sim.gains.rate_hz)
    return res, chans, extras, n


def replay_setup(tm, t_rec, valve_command, *, hold: str = "zoh"):
    """The simulation of :func:`run_at_record` (controller at the model's tick rate) and
    the command on its ticks: ``(sim, command)``, to run as ``sim.run(valve_command=command)``
    (or on the batch route, :func:`sim.loop.batch.run_many`)."""
    from sim.control.tvc import ControllerGains
    from sim.loop.simulation import Simulation

    t_rec = np.asarray(t_rec, float)
    fs = 1.0 / float(t_rec[1] - t_rec[0])
    rate = tick_rate(fs, hold, *model_rates(tm))
    t_tick = ticks_covering(t_rec, rate)
    cmd = command_on_ticks(t_rec, valve_command, t_tick, hold)
    return Simulation(tm, gains=ControllerGains(rate_hz=rate)), cmd


def record_channels(res, tm, t_rec, dofs, rate: float):
    """The recorder's channels of the replay ``res`` (at the model's tick ``rate``) at the
    record's instants ``t_rec``: ``(channels, extras, n)`` as :func:`run_at_record`
    returns them."""
    from sim.runs.build import build_runfile
    from sim.runs.runfile import ACTUATOR_CHANNELS, DOF_CHANNELS
    from sim.signals.resample import interpolate

    t_rec = np.asarray(t_rec, float)
    fs = 1.0 / float(t_rec[1] - t_rec[0])
    tick_run = build_runfile(res, tm)
    n = int(np.searchsorted(t_rec, res.t[-1] + 1e-6 / rate, side="right"))
    chans = {}
    for ch in ACTUATOR_CHANNELS + DOF_CHANNELS + ("accelerometers",):
        arr = getattr(tick_run, ch)
        if arr is None:
            continue
        if ch in DOF_CHANNELS:
            arr = arr[:, [list(tick_run.dofs).index(d) for d in dofs]]
        chans[ch] = arr[:n].copy() if rate == fs else interpolate(res.t, arr, t_rec[:n])
    extras = {
        k: (np.asarray(v, float)[:n].copy() if rate == fs else interpolate(res.t, np.asarray(v, float), t_rec[:n]))
        for k, v in tick_run.extras.items()
    }
    return chans, extras, n


__all__ = [
    "RecordModel",
    "ReplayOutcome",
    "comparison",
    "drive_on_the_analog_clock",
    "model_rates",
    "model_run",
    "read_record",
    "record_channels",
    "record_model",
    "replay",
    "replay_setup",
    "residuals",
    "run_at_record",
    "through_declared_chain",
    "command_hold",
    "command_on_ticks",
    "tick_rate",
    "ticks_covering",
]
