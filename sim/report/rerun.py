"""Rerun recordings of run files (``.rrd``): the table in 3-D and every channel as a time series.

One recording holds one run (measured or simulated), optionally laid side by side with
a second run (``compare``): its series next to the first run's and the residual
``run - compare`` per channel, plus a translucent "ghost" platen at the compare run's pose.

What goes in (entity paths follow the model):

==========================================  ==========================================================
``table/foundation``                        static world geoms (pit floor); ``table/ground`` if a foundation body moves
``table/platen``                            platen body, its transform per display frame
``table/platen/accelerometers``             sensor positions and directions (platen frame)
``table/actuators/<A>/cylinder``, ``/rod``  the linkage bodies; geoms coloured by |force| / (A_a p_supply)
``table/supports/S<i>/piston``, ``/shoe``   static supports (hydrostatic bearings)
``table/payload/<body>``                    payload bodies (deformed when ``payload_qpos`` is given)
``compare/platen``                          the compare run's platen (translucent)
``plots/dof/<d>/displacement``              one entity, a value per series: ``reference``, ``achieved``
``plots/dof/<d>/acceleration``              ``reference`` (second difference of the reference), ``achieved``
``plots/actuators/<A>/valve``               ``command``, ``spool``
``plots/actuators/<A>/pressure``            ``a``, ``b``
``plots/actuators/force``, ``/stroke``      net piston force, stroke: one series per actuator
``plots/accelerometers``                    one series per accelerometer channel
``plots/hydraulics/<q>``                    ``supply_pressure``, ``accumulator_gas_volume`` (one series each)
``plots/model/loop_gap``                    largest swivel opening of the model (finite samples only)
``plots/compare/<same sub-path>``           the compare run's series (not its reference), on this run's time
``plots/residual/<same sub-path>``          ``run - compare`` per series (with a compare run)
``payload/sensors/<name>/acceleration``     a specimen sensor (``specimen_acceleration``); ``<name> (compare)``
==========================================  ==========================================================

Time is the run's own time on the timeline ``time`` (a duration in s). Each body's geoms are
logged once as static shapes in the body frame; per display frame (default 50 Hz, never
every physics step) only the body transforms and linkage colours change. Each group of
time series goes out in one ``send_columns`` call as one entity with one scalar per
series and row (``rr.Scalars`` with several values per row, named by ``rr.SeriesLines``),
so the time column and row ids are stored once per group, not once per channel. Time series
keep every n-th sample, n the largest that keeps at least ``series_rate_hz`` (default
250 Hz: every 4th sample of a 1024 Hz run); ``series_rate_hz=None`` keeps the full rate. A
series with drop-outs (non-finite samples where the rest of its group is finite) leaves
its group for ``<group>/<name>``, finite samples only. The blueprint (3-D view beside
tabbed time-series panels) is built by :func:`blueprint` and travels with the recording.

A recording file is written to a temporary file in the target folder and moved into
place with ``os.replace`` only when complete; on any error the temporary file is removed,
so a reader sees either no file or the whole recording.

rerun itself (about 1 s to import, with pyarrow and pandas) runs in a writer process that
:meth:`RrdTarget.open` starts for a file target, so the import happens beside the
simulation rather than after it: :meth:`RrdTarget.write_run` notes the recording's rerun
calls as plain data (:class:`_Ops`, :class:`_Lazy`), sends them in one pickle and waits
for the writer; its failures come back as exceptions here. Viewer targets record
in-process (:func:`_execute` either way).
"""

from __future__ import annotations

import os
import tempfile
import uuid
from pathlib import Path

import numpy as np

from sim.errors import RunFileError, UserError
from sim.report.rerun_scene import (  # noqa: F401
    _body_poses,
    _geom_archetype,
    _LoopSolver,
    _quat_xyzw,
    _rotations_xyz,
    _Scene,
    _scene,
    body_entity,
    log_compare_platen,
    log_static_scene,
    specimen_sensor_marks,
)
from sim.report.rerun_series import (  # noqa: F401
    _C_ACH,
    _C_CMP,
    _C_REF,
    _C_RES,
    _CMP_SHADES,
    _RES_SHADES,
    _ROLE_COLORS,
    _aligned,
    _channel_groups,
    _Group,
    _reference_acceleration,
    _role_colors,
    _specimen_groups,
    series_stride,
)
from sim.report.rerun_worker import (  # noqa: F401
    ViewerTimeout,
    _escape,
    _execute,
    _Lazy,
    _one_line,
    _Ops,
    _run_in_worker,
    _start_worker,
    _stop_worker,
)

TIMELINE = "time"
DEFAULT_RATE_HZ = 50.0
DEFAULT_SERIES_RATE_HZ = 250.0  # time series: every n-th sample, n the largest keeping >= this rate
APPLICATION_ID = "shaketable"
SUFFIX = ".rrd"
DEFAULT_URL = "rerun+http://127.0.0.1:9876/proxy"

# series colours (RGB)
_FORCE_MAP = np.array(
    [  # fraction of capacity -> colour
        [0.0, 60, 100, 170],
        [0.25, 60, 170, 200],
        [0.5, 230, 200, 40],
        [0.75, 240, 120, 30],
        [1.0, 215, 25, 28],
    ]
)


_PRELOAD = None
_TARGET = object()  # write_run: "the target's setting"


def preload() -> None:
    """Start importing rerun in a background thread (it takes ~1 s); :func:`_rerun` waits for it."""
    global _PRELOAD
    if os.environ.get("SHAKETABLE_RRD_PRELOAD", "1") == "0":  # for bench/recording_bench.py
        return
    if _PRELOAD is None and "rerun" not in __import__("sys").modules:
        import threading

        def work():
            try:
                import pyarrow as pa
                import rerun  # noqa: F401
                import rerun.blueprint  # noqa: F401

                pa.array([0.0]).to_numpy()
                try:  # pyarrow imports pandas lazily on first conversion; do it here too
                    import pandas  # noqa: F401
                except ImportError:
                    pass
            except Exception:  # noqa: BLE001 - the import is retried (and fails loudly) in the main thread
                pass

        _PRELOAD = threading.Thread(target=work, name="rerun-preload", daemon=True)
        _PRELOAD.start()


def _rerun():
    if _PRELOAD is not None:
        _PRELOAD.join()
    import rerun

    return rerun


#: How long a live viewer (``--spawn``, ``--connect``) may take to take a recording, s
#: (assumed: a local viewer takes a run of minutes in a few seconds; 30 s is patient).
DEFAULT_VIEWER_TIMEOUT_S = 30.0


class RecordingError(UserError):
    """A recording that cannot be written (bad name, missing or unwritable folder)."""


def force_colors(fraction: np.ndarray) -> np.ndarray:
    """(n,) force fractions of capacity (|F| / (A_a p_supply)) -> (n, 4) uint8 RGBA.

    Blue at 0, yellow at 0.5, red at 1 and beyond; NaN gives grey.
    """
    raw = np.asarray(fraction, dtype=float)
    f = np.clip(np.nan_to_num(raw, nan=0.0), 0.0, 1.0)
    out = np.empty(f.shape + (4,), dtype=np.uint8)
    for k in range(3):
        out[..., k] = np.interp(f, _FORCE_MAP[:, 0], _FORCE_MAP[:, k + 1]).round().astype(np.uint8)
    out[..., 3] = 255
    out[np.isnan(raw)] = (128, 128, 128, 255)
    return out


def check_path(path) -> Path:
    """Check that a recording can be written at ``path``; RecordingError (one line) if not.

    The name must end ``.rrd`` and must not be a folder. Its folder is created when the
    recording is written (as ``run --out`` creates its own), so here the nearest existing
    ancestor must be a writable folder (tried by creating and removing a temporary file
    there): nothing is created by a check that a later error would leave behind.
    """
    p = Path(path)
    name = str(path)
    if not p.name.endswith(SUFFIX) or p.name == SUFFIX:
        raise RecordingError(f"recording {name} does not end with {SUFFIX!r}; name it like 'run01{SUFFIX}'")
    if p.is_dir():
        raise RecordingError(f"recording {name} is a folder; give a file name ending {SUFFIX!r}")
    folder = p.parent if str(p.parent) else Path(".")
    probe_dir = folder
    while not probe_dir.exists() and probe_dir != probe_dir.parent:
        probe_dir = probe_dir.parent
    if not probe_dir.is_dir():
        raise RecordingError(
            f"recording {name} cannot be written: {probe_dir} is a file, not a folder; choose another path"
        )
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".probe", dir=probe_dir)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise RecordingError(
            f"recording {name} cannot be written ({_one_line(exc.strerror or exc)}); choose a folder you can write to"
        ) from None
    return p


# ---------------------------------------------------------------------- geometry
def blueprint(run, compare=None, *, tm=None):
    """The recording's layout: 3-D table view on the left, tabbed time-series panels on the right.

    Args:
        run: the RunFile recorded (its actuators, DOFs and accelerometers name the panels).
        compare: the compare RunFile, if any (adds a residual tab).
        tm: unused; accepted so callers can pass the model.
    """
    import rerun.blueprint as rrb

    acts = run.actuators
    dofs = run.dofs

    def ts(name, *subs, compare_too=True):
        # each panel: plots/<sub> (with any channel split off below it) and, with a compare run,
        # plots/compare/<sub>
        contents = []
        for sub in subs:
            contents.append(f"plots/{sub}/**")
            if compare is not None and compare_too:
                contents.append(f"plots/compare/{sub}/**")
        return rrb.TimeSeriesView(name=name, origin="/", contents=contents)

    tabs = [
        rrb.Grid(*[ts(f"{d} displacement", f"dof/{d}/displacement") for d in dofs], name="DOF displacement"),
        rrb.Grid(*[ts(f"{d} acceleration", f"dof/{d}/acceleration") for d in dofs], name="DOF acceleration"),
        rrb.Grid(*[ts(f"{a} valve", f"actuators/{a}/valve") for a in acts], name="valves"),
        rrb.Grid(*[ts(f"{a} pressure", f"actuators/{a}/pressure") for a in acts], name="pressures"),
        rrb.Vertical(
            ts("actuator force", "actuators/force", compare_too=False),
            ts("actuator stroke", "actuators/stroke", compare_too=False),
            name="forces",
        ),
        rrb.Vertical(
            ts("supply pressure", "hydraulics/supply_pressure"),
            ts("accumulator gas volume", "hydraulics/accumulator_gas_volume"),
            ts("loop-closure gap", "model/loop_gap", compare_too=False),
            name="hydraulics",
        ),
    ]
    if run.accelerometers is not None:
        tabs.append(rrb.Grid(ts("accelerometers", "accelerometers", compare_too=False), name="accelerometers"))
    if getattr(run, "specimen_acceleration", None) is not None:  # under the payload, not plots/
        specimen = rrb.TimeSeriesView(name="specimen sensors", origin="/", contents=["payload/sensors/**"])
        tabs.append(rrb.Grid(specimen, name="specimen"))
    if compare is not None:
        tabs.append(
            rrb.Grid(
                *[ts(f"{d} residual", f"residual/dof/{d}", compare_too=False) for d in dofs],
                ts("force residual", "residual/actuators/force", compare_too=False),
                name="residuals",
            )
        )
    view3d = rrb.Spatial3DView(
        name="table",
        origin="/",
        contents=["table/**", "compare/**"],
        eye_controls=rrb.EyeControls3D(
            position=[11.0, -13.0, 7.0], look_target=[0.0, 0.0, 0.5], eye_up=[0.0, 0.0, 1.0]
        ),
    )
    return rrb.Blueprint(
        rrb.Horizontal(view3d, rrb.Tabs(*tabs, active_tab=0), column_shares=[0.45, 0.55]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed"),
        auto_views=False,
    )


# ---------------------------------------------------------------------- target
def _log_force_colors(rec, rr, tm, sc, force: np.ndarray, times) -> None:
    """Colour each actuator's cylinder and rod by its force over its capacity (supply
    pressure times piston area) at the display frames."""
    import mujoco

    m = tm.model
    cap = np.array([a.cls.area_a_m2 for a in tm.desc.actuators]) * float(tm.desc.raw["supply"]["pressure_pa"])
    frac = np.abs(force) / cap
    for i, gents in sc.force_geoms.items():
        cols = force_colors(frac[:, i])
        for gent in gents:
            arch = rr.Cylinders3D if gent.endswith(("cylinder", "rod")) else None
            g = next(gg for gg, e, _ in sc.geoms if e == gent)
            arch = {
                int(mujoco.mjtGeom.mjGEOM_BOX): rr.Boxes3D,
                int(mujoco.mjtGeom.mjGEOM_CYLINDER): rr.Cylinders3D,
                int(mujoco.mjtGeom.mjGEOM_CAPSULE): rr.Capsules3D,
            }.get(int(m.geom_type[g]), arch)
            if arch is not None:
                rec.send_columns(gent, indexes=[times], columns=arch.columns(colors=cols))


def _checked_inputs(run, tm, payload_qpos, compare):
    """Refuse a run of another table, payload positions of the wrong shape or a comparison
    run of other DOFs; returns ``payload_qpos`` as a float array (or None)."""
    if list(run.actuators) != list(tm.actuator_names):
        raise RunFileError(
            f"run file {run.name} has actuators {', '.join(run.actuators)} but table "
            f"'{tm.desc.name}' has {', '.join(tm.actuator_names)}; give the matching --table"
        )
    if payload_qpos is not None:
        payload_qpos = np.asarray(payload_qpos, dtype=float)
        nj = len(getattr(tm.info, "payload_joints", []))
        if payload_qpos.shape != (run.n_samples, nj):
            raise ValueError(f"payload_qpos has shape {payload_qpos.shape}, need ({run.n_samples}, {nj})")
    if compare is not None and list(compare.dofs) != list(run.dofs):
        raise RunFileError(
            f"run file {compare.name} has DOFs {', '.join(compare.dofs)} but "
            f"{run.name} has {', '.join(run.dofs)}; compare runs of the same table"
        )
    return payload_qpos


def _temp_beside(path: Path) -> str:
    """An empty hidden temporary file in ``path``'s folder (made as run --out makes its own)."""
    if str(path.parent):
        path.parent.mkdir(parents=True, exist_ok=True)  # as run --out creates its folder
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent if str(path.parent) else ".")
    os.close(fd)
    return tmp


def _publish(tmp: str, path: Path) -> None:
    """Give the finished temporary file the usual permissions (umask) and move it in place."""
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    os.replace(tmp, path)


class RrdTarget:
    """Where a recording goes: an ``.rrd`` file and/or a live viewer.

    Use :meth:`open` before a long computation (it fails early, as a one-line
    :class:`~sim.errors.UserError`, when the file cannot be written), then
    :meth:`write_run` once the run exists. ``path`` is the recording file (None for a
    viewer-only target).
    """

    def __init__(
        self,
        path: Path | None,
        *,
        spawn: bool = False,
        connect: str | None = None,
        rate_hz: float = DEFAULT_RATE_HZ,
        series_rate_hz: float | None = DEFAULT_SERIES_RATE_HZ,
        application_id: str = APPLICATION_ID,
    ):
        self.path = path
        self.spawn = spawn
        self.connect = connect
        self.rate_hz = float(rate_hz)
        self.series_rate_hz = None if series_rate_hz is None else float(series_rate_hz)
        self.application_id = application_id
        self.recording_id: str | None = None
        self._worker = None  # writer process (subprocess.Popen) started by open()
        self.timeout_s = DEFAULT_VIEWER_TIMEOUT_S  #: how long a live viewer may take to answer

    @classmethod
    def open(
        cls,
        path=None,
        *,
        spawn: bool = False,
        connect: str | None = None,
        rate_hz: float = DEFAULT_RATE_HZ,
        series_rate_hz: float | None = DEFAULT_SERIES_RATE_HZ,
        application_id: str = APPLICATION_ID,
        timeout_s: float = None,
    ) -> "RrdTarget":
        """Check the target now; nothing is written until :meth:`write_run`.

        Args:
            path: ``.rrd`` file to write (its folder must exist and be writable), or None.
            spawn: also stream to a viewer started here (needs a screen).
            connect: also stream to a running viewer at this gRPC URL ("" for the default URL).
            rate_hz: display rate of the 3-D transforms.
            series_rate_hz: time series keep every n-th sample, n the largest that keeps at
                least this rate (default 250 Hz: every 4th sample of a 1024 Hz run); None keeps
                the run's full rate.
            timeout_s: with ``spawn`` or ``connect``, give up (RecordingError, nothing
                kept) when the viewer has not taken the recording after this long
                (default :data:`DEFAULT_VIEWER_TIMEOUT_S`).
        """
        if timeout_s is None:
            timeout_s = DEFAULT_VIEWER_TIMEOUT_S
        if not (np.isfinite(timeout_s) and timeout_s > 0):
            raise RecordingError(f"viewer timeout {timeout_s!r} s is not a positive number; give e.g. 30")
        if path is None and not spawn and connect is None:
            raise RecordingError("no recording target; give a .rrd file, spawn a viewer or connect to one")
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise RecordingError(f"display rate {rate_hz!r} Hz is not a positive number; give e.g. 50")
        if series_rate_hz is not None and not (np.isfinite(series_rate_hz) and series_rate_hz > 0):
            raise RecordingError(
                f"time-series rate {series_rate_hz!r} Hz is not a positive number; "
                "give e.g. 250, or None for the full rate"
            )
        p = check_path(path) if path is not None else None
        target = cls(
            p,
            spawn=spawn,
            connect=connect,
            rate_hz=rate_hz,
            series_rate_hz=series_rate_hz,
            application_id=application_id,
        )
        target.timeout_s = float(timeout_s)
        if p is not None and not spawn and connect is None and os.environ.get("SHAKETABLE_RRD_PRELOAD", "1") != "0":
            # a file only: rerun is imported (~1 s) and used in a writer process of its own,
            # started now, so the import runs beside the simulation instead of after it
            try:
                target._worker = _start_worker()
            except OSError:
                target._worker = None
        if target._worker is None:
            preload()
        return target

    # ------------------------------------------------------------------ writing
    def write_run(
        self,
        run,
        tm,
        payload_qpos: np.ndarray | None = None,
        *,
        compare=None,
        rate_hz: float | None = None,
        series_rate_hz=_TARGET,
        name: str | None = None,
    ) -> Path | None:
        """Record ``run`` (a RunFile) with the geometry of ``tm`` (a TableModel).

        Args:
            run: the run to record.
            tm: the table model the run belongs to (its actuators must match the run's).
            payload_qpos: optional (N, n_payload_q) joint positions of a flexible payload
                (``tm.info.payload_joints`` order) to show it deformed; run files do not carry them.
            compare: optional second RunFile laid beside ``run`` (series, residuals, ghost platen).
            rate_hz: display rate of the 3-D scene (default: the target's, 50 Hz).
            series_rate_hz: least rate of the time series, None for the run's full rate
                (default: the target's, 250 Hz).
            name: recording name shown in the viewer (default: the run's description or path).

        Returns:
            The recording file written, or None for a viewer-only target.
        """
        payload_qpos = _checked_inputs(run, tm, payload_qpos, compare)
        rate = float(rate_hz) if rate_hz is not None else self.rate_hz
        series_rate = self.series_rate_hz if series_rate_hz is _TARGET else series_rate_hz

        self.recording_id = str(uuid.uuid4())
        worker, self._worker = self._worker, None
        tmp = None
        try:
            # the recording as a list of rerun calls (plain data and numpy arrays), made here;
            # rerun itself runs in the writer process started by open() (or here)
            ops = _Ops()
            self._log(ops, _Lazy(), run, tm, payload_qpos, compare, rate, series_rate, name)
            job = self._job(ops, run, compare)
            if self.path is not None:
                tmp = _temp_beside(self.path)
            job["file"] = tmp
            live = self.spawn or self.connect is not None
            if live and (worker is None or worker.poll() is not None):
                worker = _start_worker()  # a live viewer is fed from a process that can be stopped
            if worker is not None and worker.poll() is None:
                try:
                    _run_in_worker(worker, job, timeout_s=self.timeout_s if live else None)
                except ViewerTimeout:
                    worker = None
                    raise self._timeout_error(job) from None
                worker = None
            else:
                _execute(job)
            if tmp is not None:
                _publish(tmp, self.path)
                tmp = None
        except OSError as exc:
            raise RecordingError(
                f"recording {self.path} cannot be written ({_one_line(exc.strerror or exc)}); "
                "choose a folder you can write to, with free space"
            ) from None
        finally:
            if worker is not None:
                _stop_worker(worker)
            if tmp is not None:
                try:
                    os.unlink(tmp)
                except OSError:
                    pass
        return self.path

    def _job(self, ops, run, compare) -> dict:
        """What the writer process needs: where to send the recording, the blueprint's
        parts and the noted rerun calls (``file`` is added by the caller)."""
        return {
            "application_id": self.application_id,
            "recording_id": self.recording_id,
            "spawn": self.spawn,
            "connect": (self.connect or DEFAULT_URL) if self.connect is not None else None,
            "blueprint": (
                [str(a) for a in run.actuators],
                [str(d) for d in run.dofs],
                run.accelerometers is not None,
                compare is not None,
                run.specimen_acceleration is not None,
            ),
            "ops": ops.calls,
        }

    def _timeout_error(self, job: dict) -> "RecordingError":
        """The one-line error of a live viewer that did not take the recording in time."""
        where = "the spawned viewer" if self.spawn else f"the viewer at {job['connect']}"
        how = (
            "--spawn needs a screen; write a file with --rrd and open it where there is one"
            if self.spawn
            else "start one (`rerun`) or write a file with --rrd"
        )
        return RecordingError(f"{where} did not take the recording within {self.timeout_s:g} s (nothing kept); {how}")

    def close(self) -> None:
        """Stop the background writer process, if any (a target never written)."""
        worker, self._worker = getattr(self, "_worker", None), None
        if worker is not None:
            _stop_worker(worker)

    def __del__(self):
        try:
            self.close()
        except Exception:  # noqa: BLE001 - interpreter shutdown
            pass

    # ------------------------------------------------------------------ content
    def _log(self, rec, rr, run, tm, payload_qpos, compare, rate_hz, series_rate_hz, name) -> None:
        """Make the recording: ``rec`` and ``rr`` are the recording stream and the rerun module,
        or stand-ins (:class:`_Ops`, :class:`_Lazy`) that note the calls for :func:`_execute`."""

        title = name or run.meta.get("description") or Path(run.name).name
        rec.send_recording_name(str(title))
        props = {
            k: str(run.meta[k])
            for k in ("table", "source", "description", "scenario", "payload")
            if run.meta.get(k) is not None
        }
        props["run_file"] = run.name
        if compare is not None:
            props["compare_file"] = compare.name
        if run.incomplete:
            props["incomplete_reason"] = str(run.incomplete_reason)
        rec.send_property("run", rr.AnyValues(**props))
        rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._log_scene(rec, rr, run, tm, payload_qpos, compare, rate_hz)
        self._log_series(rec, rr, run, compare, series_rate_hz)

    def _log_scene(self, rec, rr, run, tm, payload_qpos, compare, rate_hz) -> None:
        """The model's geometry and sensors (static), then the bodies' poses at the display
        rate, the actuators coloured by force and the compared run's platen."""
        sc = _scene(tm)
        colored = {g for gs in sc.force_geoms.values() for g in gs} if run.actuator_force is not None else set()
        log_static_scene(rec, rr, tm, sc, colored, run.meta.get("specimen_sensors"))
        # display frames
        pose_src = run.table_displacement if run.table_displacement is not None else run.reference
        if pose_src is None or pose_src.shape[1] != 6:
            return  # not a 6-DOF pose: no motion to show (the static scene stays at home)
        step = max(1, int(round(run.sample_rate_hz / rate_hz)))
        idx = np.arange(0, run.n_samples, step)
        idx = idx[np.all(np.isfinite(pose_src[idx]), axis=1)]
        if len(idx) == 0:
            return
        times = rr.TimeColumn(TIMELINE, duration=run.t[idx])
        pq = payload_qpos[idx] if payload_qpos is not None else None
        pos, quat = _body_poses(tm, pose_src[idx], pq, sc.bodies)
        for k, (_, ent) in enumerate(sc.bodies):
            rec.send_columns(
                ent,
                indexes=[times],
                columns=rr.Transform3D.columns(translation=pos[:, k], quaternion=_quat_xyzw(quat[:, k])),
            )
        if colored:
            _log_force_colors(rec, rr, tm, sc, run.actuator_force[idx], times)
        if compare is not None and compare.table_displacement is not None and compare.table_displacement.shape[1] == 6:
            log_compare_platen(rec, rr, run, tm, compare, idx, TIMELINE)

    def _log_series(self, rec, rr, run, compare, series_rate_hz) -> None:
        stride = series_stride(run.sample_rate_hz, series_rate_hz)
        idx = np.arange(0, run.n_samples, stride)
        t = run.t[idx]
        theirs = {}
        if compare is not None:
            for g in _channel_groups(compare):
                for lab, role, j in zip(g.labels, g.roles, range(len(g.labels))):
                    if role != "reference":
                        theirs[(g.sub, lab)] = g.values[:, j]
        for g in _channel_groups(run):
            self._send_group(
                rr, rec, t, f"plots/{g.sub}", g.labels, g.unit, _role_colors(g.roles, "run"), g.values[idx]
            )
            pick = [j for j, lab in enumerate(g.labels) if (g.sub, lab) in theirs]
            if not pick:
                continue
            # the compare run, resampled onto this run's time, and the residual run - compare
            other = _aligned(run, compare.t, np.column_stack([theirs[(g.sub, g.labels[j])] for j in pick]))[idx]
            labels = [g.labels[j] for j in pick]
            roles = [g.roles[j] for j in pick]
            self._send_group(
                rr,
                rec,
                t,
                f"plots/compare/{g.sub}",
                [f"{lab} (compare)" for lab in labels],
                g.unit,
                _role_colors(roles, "compare"),
                other,
            )
            self._send_group(
                rr,
                rec,
                t,
                f"plots/residual/{g.sub}",
                [f"{lab}: run - compare" for lab in labels],
                g.unit,
                _role_colors(roles, "residual"),
                g.values[idx][:, pick] - other,
            )
        for g in _specimen_groups(run, compare):  # payload/sensors/<name>/acceleration
            self._send_group(rr, rec, t, g.sub, g.labels, g.unit, None, g.values[idx])

    @staticmethod
    def _send_group(rr, rec, t, ent, labels, unit, colors, values) -> None:
        """One entity with one scalar per column and row (``send_columns``, one call).

        Rows where no column is finite are left out. A column that is not finite exactly
        where the others are (a sensor drop-out, a channel that starts late) goes to its own
        entity ``<ent>/<label>`` with its finite samples only, so no row carries a NaN.
        """
        values = np.asarray(values, dtype=float).reshape(len(t), -1)
        fin = np.isfinite(values)
        rows = fin.any(axis=1)
        if not rows.any():
            return
        together = np.all(fin == rows[:, None], axis=0)
        names = [f"{lab} [{unit}]" if unit else str(lab) for lab in labels]
        widths = 1.5

        def send(path, cols, keep):
            rec.log(
                path,
                rr.SeriesLines(
                    names=[names[j] for j in cols],
                    colors=[colors[j] for j in cols] if colors else None,
                    widths=[widths] * len(cols),
                ),
                static=True,
            )
            v = values[np.ix_(keep, cols)] if len(cols) > 1 else values[keep, cols[0]]
            rec.send_columns(
                path, indexes=[rr.TimeColumn(TIMELINE, duration=t[keep])], columns=rr.Scalars.columns(scalars=v)
            )

        cols = np.flatnonzero(together)
        if len(cols):
            send(ent, list(cols), np.flatnonzero(rows))
        for j in np.flatnonzero(~together):
            keep = np.flatnonzero(fin[:, j])
            if len(keep):
                send(f"{ent}/{_escape(str(labels[j]))}", [j], keep)


def record_run(
    path,
    run,
    tm,
    *,
    compare=None,
    payload_qpos=None,
    rate_hz: float = DEFAULT_RATE_HZ,
    series_rate_hz: float | None = DEFAULT_SERIES_RATE_HZ,
    spawn: bool = False,
    connect: str | None = None,
) -> Path | None:
    """Convenience: ``RrdTarget.open(path, ...).write_run(run, tm, ...)``."""
    return RrdTarget.open(path, spawn=spawn, connect=connect, rate_hz=rate_hz, series_rate_hz=series_rate_hz).write_run(
        run, tm, payload_qpos, compare=compare
    )


__all__ = [
    "DEFAULT_RATE_HZ",
    "DEFAULT_SERIES_RATE_HZ",
    "TIMELINE",
    "RecordingError",
    "RrdTarget",
    "blueprint",
    "body_entity",
    "check_path",
    "force_colors",
    "record_run",
    "series_stride",
]
