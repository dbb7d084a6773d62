"""The replay and closed-loop residual paths of ``shaketable calibrate``.

* ``replay``: runs with recorded valve commands. Each actuator's valve null offset is
  estimated from the recorded motion and removed first (:func:`sim.calibrate.valve_null.estimate`,
  or a real record drifts to the end stop in seconds); the estimate replaces the null the
  description declares (drive = command + estimate - declared null, so the model's valve
  sees command + estimate whatever it declares); the model replays the commands
  open loop at the record's own rate (:func:`sim.calibrate.replay.run_at_record`).
* ``closed_loop``: runs with only a reference: the model runs it through the table's
  controller (:class:`sim.loop.simulation.Simulation`, the table's own gains).

The model's channels pass through what the record says of its recorder chain
(:mod:`sim.calibrate.conditioning`: ``meta.recorder``'s anti-alias low-pass and each
channel's declared ``meta.channel_conditioning``), so record and model are compared
like for like; nothing else about the sensors is read. The residual is recorded minus model on the channels present
(:data:`FIT_CHANNELS`: actuator force, table acceleration and velocity; the band-passed
displacement when a run has no velocity; the chamber pressures when it has no force),
per column (actuator / DOF), each record's zero its own (:func:`tared`: the residual's and
the record's means removed), each column scaled by its recorded RMS about its mean: the
pooled NRMSE is the root of the mean over runs and columns of ``sum e^2 / sum x^2``, each
column weighted by its noise floor (:func:`noise_weights`: alike where the record is clean).

:func:`simulate_job` is the one simulation of these paths (a picklable job in, the
compared channels out). Many jobs (a round's candidate replays) go through
:func:`simulate_many`: dealt into one chunk per worker process
(:func:`sim.parallel.map_jobs`), each chunk run on the batch route
(:func:`sim.loop.batch.run_many`: MuJoCo's batch with the twin inside ``mj_step``, open
loop on the replay path; each simulation's own ``run`` where the callback cannot take
it, e.g. a valve delay), with the same answers as :func:`simulate_job`, bit for bit.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass, field

import numpy as np

from hydraulics.params import HydraulicsParamError
from sim.calibrate import conditioning
from sim.calibrate.residuals import CalibrationError, check_finite
from sim.calibrate.specimen_model import sensors_of, watch_modes
from sim.calibrate.windows import QUIET_COLUMN, dof_weights, excited
from sim.errors import UserError

#: channels compared on these paths, in order of preference
FIT_CHANNELS = ("actuator_force", "table_acceleration", "table_velocity")
#: a column is compared when the run excites it (:func:`sim.calibrate.windows.excited`:
#: its RMS at least QUIET_COLUMN of its channel's largest, DOFs in actuator units) and its
#: RMS is at least this many times its noise floor (its level in the top of the band,
#: :func:`sim.calibrate.conditioning.noise_floor`: read off the record, as a real one holds
#: nothing about its sensors)
NOISE_COLUMN = 3.0
DOF_CHANNELS = ("table_displacement", "table_velocity", "table_acceleration")
#: accelerometers on the specimen: compared where the model gives their reading
#: (:mod:`sim.calibrate.specimen_model`), so that a specimen's mode is pinned by them too
SPECIMEN = "specimen_acceleration"
#: ``path_runs(payload=...)`` not given: the specimen channel is not compared (the model
#: it would be compared with is not known)
NOT_GIVEN = object()


@dataclass
class PathRun:
    """One run on the replay or closed-loop path."""

    name: str
    path: str
    t: np.ndarray  # (n,) from 0
    drive: np.ndarray  # (n, n_act) valve command (null removed) or (n, 6) reference pose
    dofs: list
    actuators: list
    recorded: dict  # channel -> (n, m) as compared (band-passed displacement, if used)
    columns: dict  # channel -> indices of the columns compared
    scale: dict  # channel -> (m,) recorded RMS of each compared column over the scored rows
    rows: slice = field(default_factory=lambda: slice(None))  # the scored rows
    conditioning: dict | None = None
    valve_null: dict | None = None
    bandpass: dict = field(default_factory=dict)  # channel -> band (Hz) it is compared in
    #: channel -> (m,) each compared column's weight in the pooled error (:func:`noise_weights`;
    #: empty: alike)
    weight: dict = field(default_factory=dict)
    #: columns not compared: channel -> places the run does not excite (:func:`sim.calibrate.windows.excited`)
    not_excited: dict = field(default_factory=dict)
    origin: tuple = ()  # a window's (start, first scored, stop) samples in its record
    #: the record's force holds the actuators' total in one column, the others zero (the
    #: NEES-UCSD runs: column E the measured total, W zero): the model's is summed to match
    force_total: bool = False
    #: the run's ``meta.specimen_sensors`` (one per column of ``specimen_acceleration``)
    specimen: list = field(default_factory=list)
    #: how the recorder's command is held between its samples (``meta.command_hold``):
    #: the replay applies it as ``replay`` does (a 204.8 Hz drive held where the lab's
    #: controller interpolated it reads as a different valve)
    hold: str = "zoh"

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    @property
    def n(self) -> int:
        return len(self.t)

    def window(self, seconds: float | None) -> "PathRun":
        """The ``seconds`` of this run holding the most excitation, replayed from a point
        where the record is at rest and scored over its own rows (:meth:`windows`); all of
        it for None."""
        return self.windows(seconds)[0]

    def windows(self, seconds: float | None, *, segments: int = 1, horizon_s: float | None = None) -> list:
        """The windows of this run holding the most excitation (:func:`sim.calibrate.windows.choose`:
        ``segments`` of ``seconds / segments`` each, anywhere in the record, each replayed
        from a point where the record is at rest and scored over its own rows); all of it
        for None."""
        from sim.calibrate.windows import choose

        chans = [self.drive] + [self.recorded[c][:, cols] for c, cols in self.columns.items()]
        return [self.span(w) for w in choose(chans, 1.0 / self.dt, seconds, segments=segments, horizon_s=horizon_s)]

    def span(self, w) -> "PathRun":
        """Samples ``[w.start, w.stop)`` of the run (time from 0 at ``w.start``: the replay
        starts there at rest), scored over ``[w.score_from, w.stop)``."""
        a, b = w.start, w.stop
        rows = slice(w.score_from - a, None)
        rec = {c: x[a:b] for c, x in self.recorded.items()}
        out = copy.copy(self)
        out.t, out.drive, out.recorded, out.rows = self.t[a:b] - self.t[a], self.drive[a:b], rec, rows
        out.scale = _scales(rec, self.columns, rows)
        out.origin = (a, w.score_from, b)
        return out

    def job(self, raw, src, payload, extra) -> tuple:
        """The picklable job of one simulation of this run with ``extra`` effect entries."""
        return (
            raw,
            src,
            payload,
            list(extra),
            self.path,
            self.t,
            self.drive,
            list(self.dofs),
            {c: list(v) for c, v in self.columns.items()},
            self.conditioning,
            dict(self.bandpass),
            self.force_total,
            list(self.specimen),
            self.hold,
        )

    def only(self, keep) -> "PathRun":
        """This run compared on the columns ``(channel, column)`` for which ``keep`` holds."""
        out = copy.copy(self)
        cols = {c: [j for j in v if keep(c, j)] for c, v in self.columns.items()}
        out.columns = {c: v for c, v in cols.items() if v}
        at = {c: [self.columns[c].index(j) for j in v] for c, v in out.columns.items()}
        out.scale = {c: self.scale[c][k] for c, k in at.items()}
        out.weight = {c: self.weight[c][k] for c, k in at.items() if c in self.weight}
        return out

    def weights(self, ch: str) -> np.ndarray:
        """Each compared column of ``ch``'s weight in the pooled error (1 where not set)."""
        return self.weight.get(ch, np.ones(len(self.columns[ch])))

    def column_names(self) -> list[tuple[str, int, str]]:
        """(channel, column index, place) of each compared column, in residual order."""
        out = []
        for ch, cols in self.columns.items():
            for j in cols:
                if ch.startswith("table_"):
                    out.append((ch, j, f"dof:{self.dofs[j]}"))
                elif ch == SPECIMEN:
                    out.append((ch, j, f"sensor:{_place(self, ch, j)}"))
                else:
                    out.append((ch, j, f"actuator:{self.actuators[j]}"))
        return out


def _scales(rec, columns, rows) -> dict:
    """Each compared column's RMS about its mean over ``rows``: what the test put into it."""
    return {c: np.std(rec[c][rows][:, cols], axis=0) for c, cols in columns.items()}


def tared(e: np.ndarray) -> np.ndarray:
    """A residual with its mean over the scored rows removed, per column: each record's
    zero is its own. A lab tares its load cells, accelerometers and pressure gauges before
    each test, with the table at rest under its static load, and their zeros wander from
    record to record (docs/sensors.md ``offset_rms``); a record that starts and ends at rest
    holds no mean acceleration or velocity of its own. The mechanical path removes the
    static part alike (:meth:`sim.calibrate.residuals.MechRun.demean`). Measured: a load
    cell's zero of 2 kN a record, on one held-out CGS record, took a vertical class's
    leakage of 1.4e-10 m^3/(s Pa) as its explanation."""
    return e - e.mean(axis=0)


def fit_channels(run) -> list[str]:
    """The channels of ``run`` this path compares (see the module docstring)."""
    have = [c for c in FIT_CHANNELS if getattr(run, c) is not None]
    if run.table_velocity is None and run.table_displacement is not None:
        have.append("table_displacement")
    if run.actuator_force is None:
        have += [c for c in ("pressure_a", "pressure_b") if getattr(run, c) is not None]
    return have


def path_runs(runs, desc, path: str, *, score_from: dict | None = None, payload=NOT_GIVEN) -> list[PathRun]:
    """The records of ``runs`` on ``path`` (``"replay"`` or ``"closed_loop"``).
    ``score_from``: run name -> first scored sample (the held-out part of one run);
    ``payload``: the model's payload (None: a bare table); given, a run's
    ``specimen_acceleration`` is compared where the model reads it (:func:`specimen_columns`)."""
    from sim.calibrate.replay import command_hold
    from sim.calibrate.valve_null import declared_null
    from sim.control.tvc import dof_jacobian

    out = []
    null0 = declared_null(desc) if path == "replay" else None
    J6 = dof_jacobian(desc)
    for r in runs:
        chans = fit_channels(r)
        check_finite(r, chans + (["valve_command"] if path == "replay" else ["reference"]))
        drive, vn = _drive(r, desc, path, null0)
        readable = specimen_columns(r, payload)
        rec, cols, bands, quiet, floors = _compared_columns(r, chans + ([SPECIMEN] if readable else []), J6, readable)
        if not rec:
            raise CalibrationError(
                f"{r.name}: no recorded output moves (actuator_force, table_acceleration, "
                "table_velocity all silent); calibrate runs that excite the table"
            )
        rows = slice((score_from or {}).get(r.name, 0), None)
        out.append(
            PathRun(
                name=r.name,
                path=path,
                t=np.asarray(r.t, float) - float(r.t[0]),
                drive=drive,
                dofs=list(r.dofs),
                actuators=list(r.actuators),
                recorded=rec,
                columns=cols,
                scale=_scales(rec, cols, rows),
                weight=noise_weights(floors),
                rows=rows,
                conditioning=conditioning.of_run(r),
                valve_null=vn,
                bandpass=bands,
                not_excited=quiet,
                force_total=holds_total(r.actuator_force),
                hold=command_hold(r, desc),
                specimen=sensors_of(r) if SPECIMEN in cols else [],
            )
        )
    return out


def _drive(r, desc, path: str, null0):
    """The replay's valve command (the null the motion shows in place of the declared
    one) with that null, or the closed loop's reference pose: ``(drive, null or None)``."""
    from mjcf.description import DOFS6
    from sim.calibrate.valve_null import estimate

    if path == "replay":
        est = estimate(r, desc, drift=False)
        # the estimate is the whole null the motion shows: it replaces the declared one
        drive = np.asarray(r.valve_command, float) + est.at(np.asarray(r.t, float)) - null0[None, :]
        return drive, est.as_dict(r.actuators)
    drive = np.zeros((r.n_samples, 6))
    for j, d in enumerate(r.dofs):
        drive[:, DOFS6.index(d)] = r.reference[:, j]
    return drive, None


def _compared_columns(r, chans, J6, readable):
    """Per channel of ``chans``, the record as compared and the columns the run excites
    above their noise: ``(recorded, columns, bands, not excited, noise floors)``, the
    floors (noise over RMS, the whole record) of the compared columns."""
    from sim.calibrate.replay import DISPLACEMENT_BAND_HZ
    from sim.signals.resample import bandpass

    rec, cols, bands, quiet, floors = {}, {}, {}, {}, {}
    for c in chans:
        x = np.asarray(getattr(r, c), float)
        if c == "table_displacement":
            band = (DISPLACEMENT_BAND_HZ[0], min(DISPLACEMENT_BAND_HZ[1], 0.45 * r.sample_rate_hz))
            x = bandpass(x, r.sample_rate_hz, band)
            bands[c] = band
        if c == SPECIMEN:
            # an accelerometer's zero is set anew each record (docs/sensors.md offset_rms),
            # and a body that starts and ends at rest has a mean acceleration of zero: the
            # record's mean is its sensor's zero (0.05 m/s^2 of it took the 6 Hz block's
            # frequency interval from +/-0.0026 Hz without the sensor to +/-0.0039 Hz with it)
            x = x - x.mean(axis=0)
        rms = np.sqrt(np.mean((x - x.mean(axis=0)) ** 2, axis=0))
        noise = conditioning.noise_floor(x, r.sample_rate_hz)
        # a DOF channel in actuator units (a rotation as the strokes it takes): one rule for
        # both paths (sim.calibrate.windows.excited)
        w = dof_weights(J6, r.dofs, "motion") if c.startswith("table_") else None
        on = excited(rms, w) & (rms > NOISE_COLUMN * noise)
        if c == SPECIMEN:  # the model reads these sensors only
            on &= np.isin(np.arange(x.shape[1]), readable)
        keep = [j for j in range(x.shape[1]) if on[j]]
        names = r.dofs if c.startswith("table_") else (r.column_names(c) if c == SPECIMEN else r.actuators)
        if len(keep) < x.shape[1]:
            quiet[c] = [names[j] for j in range(x.shape[1]) if not on[j]]
        if keep:
            rec[c], cols[c], floors[c] = x, keep, noise[keep] / rms[keep]
    return rec, cols, bands, quiet, floors


def noise_weights(floors: dict) -> dict:
    """Per channel, each compared column's weight in the pooled error: ``1 / (floor^2 +
    MODEL_ERROR^2)`` over ``1 / MODEL_ERROR^2`` (:func:`sim.calibrate.conditioning.noise_weight`;
    1 for a column without noise). A column's
    NRMSE cannot fall below its noise floor whatever the model; counted alike with the
    others, a light table's 3 kN forces under 1 kN of load-cell noise (a floor of 31 %)
    held the Rice table's replay held-out error at 19 %, and a 400 MPa bulk modulus lowered
    it 3.3 %, under the margin. Weighted (the force 0.026), 5.65 % -> 3.72 %."""
    return {c: conditioning.noise_weight(f) for c, f in floors.items()}


def holds_total(force) -> bool:
    """A force record with one column moving and every other zero throughout holds the
    actuators' total in that column (how the NEES-UCSD runs are written), not each one's."""
    if force is None or force.shape[1] < 2:
        return False
    zero = np.all(np.asarray(force) == 0, axis=0)
    return int(np.sum(~zero)) == 1


def specimen_columns(run, payload) -> list[int]:
    """The columns of ``run``'s ``specimen_acceleration`` the model with ``payload`` reads
    (:func:`sim.calibrate.specimen_model.readable`); [] without the channel, or when the
    payload is not given (:data:`NOT_GIVEN`)."""
    if payload is NOT_GIVEN or getattr(run, SPECIMEN, None) is None:
        return []
    sensors = sensors_of(run)
    if len(sensors) != run.specimen_acceleration.shape[1]:
        return []
    check_finite(run, [SPECIMEN])
    from sim.calibrate.specimen_model import readable

    return readable(sensors, payload)


# ------------------------------------------------------------------ the simulation
def condition(chans: dict, known: dict | None, fs: float) -> dict:
    """The model's channels through the record's known chain (:func:`sim.calibrate.conditioning.apply`)."""
    return conditioning.apply(chans, known, fs)


def simulate_job(job) -> dict | None:
    """The model's compared channels for one job (:meth:`PathRun.job`): ``{channel: (n, m)}``
    over every column of the channel, or None when the run diverged or stopped early."""
    prep = _setup(job)
    if prep is None:
        return None
    sim, ref, cmd, post = prep
    try:
        res = sim.run(reference=ref) if ref is not None else sim.run(valve_command=cmd)
    except _REFUSED:
        return None
    return post(res)


#: what a candidate's model may raise instead of running (a supply drop below the return)
_REFUSED = (FloatingPointError, UserError, HydraulicsParamError)


def _setup(job):
    """The simulation of one job, ready to run from its reset: ``(sim, reference,
    valve_command, post)`` (one of reference / valve_command None; ``post(result)`` gives
    :func:`simulate_job`'s answer), or None when the model refuses the candidate."""
    raw, src, payload, extra, path, t, drive, dofs, columns, cond, bands, total, specimen, hold = job
    from mjcf.description import parse_table
    from sim.loop.simulation import table_model

    raw = copy.deepcopy(raw)
    if extra:
        raw["effect"] = build_order(list(raw.get("effect", [])) + [dict(e) for e in extra])
    cond = without_replaced(cond, raw.get("effect", []))
    drive = conditioning.on_the_analog_clock(drive, conditioning.controller_lag(raw.get("effect")), float(t[1] - t[0]))
    try:  # a candidate's value the model refuses (a supply drop below the return): no model
        desc = parse_table(raw, src=src)
        tm = table_model(desc, payload)
        modes = watch_modes(tm) if SPECIMEN in columns else []  # their slides recorded
        if path == "replay":
            from sim.calibrate.replay import record_channels, replay_setup

            sim, cmd = replay_setup(tm, t, drive, hold=hold)
            ref = None

            def chans_of(res):
                chans, _extras, n = record_channels(res, tm, t, dofs, sim.gains.rate_hz)
                return chans, n
        else:
            sim, ref = _closed_loop_setup(tm, t, drive)
            cmd = None

            def chans_of(res):
                return _closed_loop_channels(res, tm, t, dofs, sim.gains.rate_hz)
    except _REFUSED:
        return None

    def post(res):
        if res.incomplete_reason:
            return None
        chans, n = chans_of(res)
        if SPECIMEN in columns:
            chans[SPECIMEN] = _specimen_at(res, tm, payload, specimen, modes, t[:n])
        lag = float(getattr(res, "force_lag_s", 0.0) or 0.0)
        chans = conditioning.force_at_record_instant(chans, lag, cond, float(t[1] - t[0]))
        if (cond or {}).get("velocity_from_displacement") and "table_displacement" in chans:
            chans["table_velocity"] = np.gradient(chans["table_displacement"], float(t[1] - t[0]), axis=0)
        if total and "actuator_force" in chans:  # the record's one column holds the total
            f = chans["actuator_force"]
            chans["actuator_force"] = np.repeat(f.sum(axis=1, keepdims=True), f.shape[1], axis=1)
        return _compared(chans, n, t, columns, cond, bands)

    return sim, ref, cmd, post


def without_replaced(cond: dict | None, entries: list) -> dict | None:
    """A record's known chain less what the description's sensor entries replace
    (``replaces_declared``: the mechanical path's delay or conditioner of a channel is its
    whole one; applied on top of the declared 100 Hz conditioner, a 30 Hz one found for it
    left the closed loop 8 % from the record where the mechanical path reached 1.7 %)."""
    drop = {"sensor_delay": ("delay_s",), "sensor_lowpass": ("lowpass_hz", "lowpass_order")}
    hit = [
        (str(e["where"]).partition(":")[2], drop[e["type"]])
        for e in entries
        if e.get("type") in drop and e.get("replaces_declared") and "[" not in str(e.get("where", ""))
    ]
    if not cond or not hit:
        return cond
    chans = {c: dict(s) for c, s in (cond.get("channels") or {}).items()}
    for ch, keys in hit:
        for k in keys:
            chans.get(ch, {}).pop(k, None)
    return {**cond, "channels": chans}


def _specimen_at(res, tm, payload, sensors, modes, t) -> np.ndarray:
    """The model's specimen sensors (:func:`sim.calibrate.specimen_model.model_specimen`)
    at the record's instants ``t``."""
    from sim.calibrate.specimen_model import model_specimen
    from sim.signals.resample import interpolate

    # a sensor the model does not read is NaN there; it is not compared (path_runs), and a
    # NaN would stop the comparison of the others (_compared)
    arr = np.nan_to_num(model_specimen(res, tm, payload, sensors, modes), nan=0.0)
    if len(res.t) >= len(t) and np.allclose(res.t[: len(t)], t):
        return arr[: len(t)]
    return interpolate(res.t, arr, t)


def _compared(chans, n, t, columns, cond, bands) -> dict | None:
    """The compared channels of a finished model run (conditioned, band-passed), or None."""
    from sim.signals.resample import bandpass

    if n < len(t):
        return None
    want = {c: chans[c][: len(t)] for c in columns if c in chans}
    if len(want) < len(columns):
        return None
    fs = 1.0 / float(t[1] - t[0])
    want = condition(want, cond, fs)
    for c, band in bands.items():
        want[c] = bandpass(want[c], fs, tuple(band))
    if not all(np.all(np.isfinite(x)) for x in want.values()):
        return None
    return want


#: simulations built and run together in one chunk (memory: one model each)
CHUNK_GROUP = 32


def simulate_jobs(jobs, counts: dict | None = None) -> list:
    """:func:`simulate_job` of every job, in this process, the simulations on the batch
    route (:func:`sim.loop.batch.run_many`, one thread: MuJoCo's batch with the coupled
    step inside ``mj_step``, or each simulation's own ``run`` where the callback cannot
    run it) in groups of :data:`CHUNK_GROUP`. Same answers as :func:`simulate_job`, bit
    for bit. ``counts``: ``"batch"``/``"fallback"`` simulations added (jobs the model
    refuses count in neither)."""
    from sim.loop.batch import run_many

    out: list = [None] * len(jobs)
    for g in range(0, len(jobs), CHUNK_GROUP):
        idx = list(range(g, min(g + CHUNK_GROUP, len(jobs))))
        preps = {i: _setup(jobs[i]) for i in idx}
        ready = [i for i in idx if preps[i] is not None]
        for kind in ("reference", "valve_command"):
            part = [i for i in ready if (preps[i][1] if kind == "reference" else preps[i][2]) is not None]
            if not part:
                continue
            sims = [preps[i][0] for i in part]
            given = [preps[i][1] if kind == "reference" else preps[i][2] for i in part]
            got: dict = {}
            try:
                if kind == "reference":
                    res = run_many(sims, given, nthread=1, counts=got)
                else:
                    res = run_many(sims, valve_commands=given, nthread=1, counts=got)
            except _REFUSED:  # one run raised: each job on its own (as simulate_job)
                for i in part:
                    out[i] = simulate_job(jobs[i])
                if counts is not None:
                    counts["fallback"] = counts.get("fallback", 0) + len(part)
                continue
            for key, v in got.items():
                if counts is not None:
                    counts[key] = counts.get(key, 0) + v
            for i, r in zip(part, res):
                out[i] = preps[i][3](r)
    return out


def _chunk_job(jobs) -> tuple[list, dict]:
    counts: dict = {}
    return simulate_jobs(jobs, counts), counts


def simulate_many(jobs, *, workers: int | None = None, counts: dict | None = None) -> list:
    """:func:`simulate_job` of every job (same answers, in order): the jobs dealt into
    ``workers`` chunks (round robin), each chunk one process of
    :func:`sim.parallel.map_jobs` running :func:`simulate_jobs` (process parallelism
    across chunks, MuJoCo's batch inside each). ``counts`` as :func:`simulate_jobs`."""
    from sim.parallel import default_workers, map_jobs

    jobs = list(jobs)
    if not jobs:
        return []
    w = default_workers(len(jobs)) if workers is None else max(1, min(int(workers), len(jobs)))
    if w > 1:  # the compiled callback loaded here once, inherited by forked workers
        from sim.loop.callback import control_callback

        control_callback()
    chunks = [list(range(c, len(jobs), w)) for c in range(w)]
    out: list = [None] * len(jobs)
    for idx, (res, got) in zip(chunks, map_jobs(_chunk_job, [[jobs[i] for i in c] for c in chunks], workers=w)):
        for i, r in zip(idx, res):
            out[i] = r
        if counts is not None:
            for key, v in got.items():
                counts[key] = counts.get(key, 0) + v
    return out


def _closed_loop_setup(tm, t, pose6):
    """The simulation of the closed-loop path and its reference (the recorded 6-DOF pose
    at ``t`` on the controller's ticks)."""
    from sim.calibrate.replay import ticks_covering
    from sim.loop.simulation import Simulation
    from sim.scenario.reference import Reference
    from sim.signals.resample import interpolate

    sim = Simulation(tm)
    rate = sim.gains.rate_hz
    tt = ticks_covering(t, rate)
    d = interpolate(t, pose6, tt) if len(tt) != len(t) or not np.allclose(tt, t) else np.asarray(pose6, float)
    v, a = reference_derivatives(d, 1.0 / rate)
    return sim, Reference(t=tt, d=d, v=v, a=a)


#: 8th-order central stencils (9 points) of the first and second derivative (Fornberg 1988)
_D1 = np.array([1 / 280, -4 / 105, 1 / 5, -4 / 5, 0.0, 4 / 5, -1 / 5, 4 / 105, -1 / 280])
_D2 = np.array([-1 / 560, 8 / 315, -1 / 5, 8 / 5, -205 / 72, 8 / 5, -1 / 5, 8 / 315, -1 / 560])


def reference_derivatives(d: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and acceleration of a recorded reference pose ``d`` (n, m) sampled every
    ``dt``: the controller's feed-forward as it ran. A reference is made with its analytic
    velocity and acceleration (:func:`sim.scenario.reference.reference_from_motions`); the
    run file keeps only the pose. Second-order differences (``np.gradient`` twice) run
    low by ``(sin(w dt) / (w dt))^2``: 1.1 % at 30 Hz and 1024 Hz, 0.4 % of a 1-30 Hz
    random reference's acceleration, and the model's table then moved 0.8-0.9 % short of
    the record's on clean runs (issue #13). The 9-point stencils are exact to
    ``(w dt)^8``: < 1e-8 at 30 Hz. The 4 samples at each end (a reference starts and
    ends at rest) keep ``np.gradient``'s second-order one-sided differences."""
    d = np.asarray(d, float)
    v = np.gradient(d, dt, axis=0, edge_order=2) if len(d) > 2 else np.zeros_like(d)
    a = np.gradient(v, dt, axis=0, edge_order=2) if len(d) > 2 else np.zeros_like(d)
    h = len(_D1) // 2
    if len(d) > 2 * h:
        win = np.lib.stride_tricks.sliding_window_view(d, len(_D1), axis=0)  # (n - 2h, m, 9)
        v[h:-h] = win @ _D1 / dt
        a[h:-h] = win @ _D2 / dt**2
    return v, a


def _closed_loop_channels(res, tm, t, dofs, rate: float):
    """The closed-loop run's channels (controller ``rate``) at the record's instants ``t``:
    ``(channels, n)``."""
    from sim.runs.build import build_runfile
    from sim.runs.runfile import ACTUATOR_CHANNELS
    from sim.signals.resample import interpolate

    tick = build_runfile(res, tm)
    n = int(np.searchsorted(t, res.t[-1] + 1e-6 / rate, side="right"))
    same = abs(rate * float(t[1] - t[0]) - 1.0) < 1e-9
    chans = {}
    for ch in ACTUATOR_CHANNELS + DOF_CHANNELS:
        arr = getattr(tick, ch)
        if arr is None:
            continue
        if ch in DOF_CHANNELS:
            arr = arr[:, [list(tick.dofs).index(x) for x in dofs]]
        chans[ch] = arr[:n].copy() if same else interpolate(res.t, arr, t[:n])
    return chans, n


# ------------------------------------------------------------------ residuals
def residual_vector(pr: PathRun, model: dict | None) -> np.ndarray | None:
    """The scored residual of one run, scaled so that ``sum(r**2)`` is the mean over its
    columns of ``sum e^2 / sum x^2`` (its NRMSE squared), each column weighted by its
    noise (:attr:`PathRun.weight`: alike where the record has none); None if the model
    failed."""
    if model is None:
        return None
    parts = []
    total = sum(float(np.sum(pr.weights(ch))) for ch in pr.columns)
    for ch, cols in pr.columns.items():
        e = tared(pr.recorded[ch][pr.rows][:, cols] - model[ch][pr.rows][:, cols]) / pr.scale[ch]
        e = e * np.sqrt(pr.weights(ch) / (e.shape[0] * total))
        parts.append(e.T.reshape(-1))
    return np.concatenate(parts)


def residual_segments(prs) -> list:
    """Positions of each compared column of each run in :func:`stacked`'s vector (each a
    time series; :func:`residual_vector` stacks them as consecutive blocks)."""
    from sim.calibrate.hac import blocks

    lengths = []
    for pr in prs:
        ch = next(iter(pr.columns))
        n = len(pr.recorded[ch][pr.rows])
        lengths += [n] * sum(len(c) for c in pr.columns.values())
    return blocks(lengths)


def stacked(prs, models) -> np.ndarray | None:
    """Residuals of several runs stacked, each run weighted alike (sum of squares: the
    mean over runs of their NRMSE squared)."""
    rs = [residual_vector(p, m) for p, m in zip(prs, models)]
    if any(r is None for r in rs):
        return None
    return np.concatenate(rs) / math.sqrt(len(rs))


def nrmse(prs, models) -> float:
    r = stacked(prs, models)
    return float(math.sqrt(np.sum(r**2))) if r is not None else float("nan")


def column_errors(pr: PathRun, model: dict) -> dict:
    """NRMSE per compared column: ``"<channel>[<place>]" -> value``."""
    out = {}
    for ch, cols in pr.columns.items():
        for k, j in enumerate(cols):
            e = tared(pr.recorded[ch][pr.rows][:, j] - model[ch][pr.rows][:, j])
            out[f"{ch}[{_place(pr, ch, j)}]"] = float(np.sqrt(np.mean(e**2)) / pr.scale[ch][k])
    return out


def column_weights(pr: PathRun) -> dict:
    """Each compared column's weight in the pooled error (keys as :func:`column_errors`;
    :func:`noise_weights`)."""
    return {
        f"{ch}[{_place(pr, ch, j)}]": float(w) for ch, cols in pr.columns.items() for j, w in zip(cols, pr.weights(ch))
    }


def column_floors(pr: PathRun) -> dict:
    """The NRMSE a perfect model would still leave per compared column (keys as
    :func:`column_errors`): the record's own white noise (its level in the top of the
    band, :func:`sim.calibrate.conditioning.noise_floor`) over the column's scale. A
    model's channels carry none; a light table's 3 kN forces under a 1 kN load-cell noise
    leave a third of their RMS whatever the model."""
    out = {}
    for ch, cols in pr.columns.items():
        noise = conditioning.noise_floor(np.asarray(pr.recorded[ch][pr.rows], float)[:, cols], 1.0 / pr.dt)
        for k, j in enumerate(cols):
            out[f"{ch}[{_place(pr, ch, j)}]"] = float(noise[k] / pr.scale[ch][k])
    return out


def _place(pr, ch, j) -> str:
    if ch == SPECIMEN:
        return str(pr.specimen[j].get("name", f"s{j}"))
    return pr.dofs[j] if ch.startswith("table_") else pr.actuators[j]


def residual_columns(pr: PathRun, model: dict) -> list[tuple[str, int, np.ndarray]]:
    """(channel, column, residual over the scored rows, in channel units) of each column."""
    return [
        (ch, j, tared(pr.recorded[ch][pr.rows][:, j] - model[ch][pr.rows][:, j]))
        for ch, cols in pr.columns.items()
        for j in cols
    ]


def flatness(prs, models, *, bias: bool = False) -> float:
    """Mean spectral flatness of the residual over runs and columns (1: white). The Welch
    spectrum removes each segment's mean, so a constant bias of the residual does not
    show; with ``bias`` each column's flatness is multiplied by the share of its mean
    square that is not that bias, ``var(e) / mean(e^2)`` (1 for zero-mean noise)."""
    from sim.calibrate.residuals import spectral_flatness

    vals = []
    for pr, m in zip(prs, models):
        for _ch, _j, e in residual_columns(pr, m):
            if np.any(e):
                share = float(np.var(e) / np.mean(e**2)) if bias else 1.0
                vals.append(spectral_flatness(e, 1.0 / pr.dt) * share)
    return float(np.mean(vals)) if vals else 0.0


def unexplained(prs, models, fraction: float) -> dict | None:
    """The residual's strongest narrow spectral line over the compared columns (pooled
    over runs): frequency, channel, place, share of that column's residual and its
    coherence with the drive (the valve commands or the reference); None below
    ``fraction``."""
    import scipy.signal as sig

    from sim.calibrate.residuals import spectra

    best = None
    for pr, m in zip(prs, models):
        drive = pr.drive[pr.rows]
        drive = drive[:, np.ptp(drive, axis=0) > 0]
        for ch, j, e in residual_columns(pr, m):
            if not np.any(e):
                continue
            s = spectra(e, 1.0 / pr.dt)
            P, f = s["psd"], s["f"]
            k = int(np.argmax(P[1:]) + 1)
            w = slice(max(k - 2, 1), k + 3)
            frac = float(P[w].sum() / P[1:].sum())
            if best is not None and frac <= best["fraction_of_residual"]:
                continue
            nper = 2 * (len(f) - 1)
            coh = 0.0
            for q in range(drive.shape[1]):
                _, C = sig.coherence(e, drive[:, q], fs=1.0 / pr.dt, nperseg=nper)
                coh = max(coh, float(C[k]))
            place = _place(pr, ch, j)
            kind = "dof" if ch.startswith("table_") else ("sensor" if ch == SPECIMEN else "actuator")
            best = {
                "peak_hz": float(f[k]),
                "channel": f"{ch}[{j}]",
                "where": f"{kind}:{place}" if coh >= 0.5 else f"channel:{ch}[{j}]",
                "fraction_of_residual": frac,
                "coherence_with_drive": coh,
                "run": pr.name,
            }
    if best is None or best["fraction_of_residual"] < fraction:
        return None
    return best


def build_order(entries: list) -> list:
    """``[[effect]]`` entries in the order they can be built: ``foundation_mode`` first
    (it moves the bodies standing on the world onto a new foundation body, which it cannot
    do once a DOF effect of a free platen has made a tendon), the others as given."""
    return [e for e in entries if e.get("type") == "foundation_mode"] + [
        e for e in entries if e.get("type") != "foundation_mode"
    ]


__all__ = [
    "build_order",
    "FIT_CHANNELS",
    "QUIET_COLUMN",
    "PathRun",
    "column_errors",
    "condition",
    "fit_channels",
    "flatness",
    "nrmse",
    "path_runs",
    "residual_columns",
    "residual_vector",
    "simulate_job",
    "simulate_jobs",
    "simulate_many",
    "stacked",
    "unexplained",
]
