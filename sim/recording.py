"""Rerun recordings of run files (``.rrd``): the table in 3-D and every channel as a time series.

One recording holds one run (measured or simulated), optionally laid side by side with
a second run (``compare``): its series next to the first run's and the residual
``run - compare`` per channel, plus a translucent "ghost" platen at the compare run's pose.

What goes in (entity paths follow the model):

==========================================  ==========================================================
``table/foundation``                        static world geoms (pit floor, foundation)
``table/platen``                            platen body, its transform per display frame
``table/platen/accelerometers``             sensor positions and directions (platen frame)
``table/actuators/<A>/cylinder``, ``/rod``  the linkage bodies; geoms coloured by |force| / (A_a p_supply)
``table/supports/S<i>/piston``, ``/shoe``   static supports (hydrostatic bearings)
``table/payload/<body>``                    payload bodies (deformed when ``payload_qpos`` is given)
``compare/platen``                          the compare run's platen (translucent)
``plots/dof/<d>/displacement/...``          ``reference``, ``achieved``, ``compare``
``plots/dof/<d>/acceleration/...``          ``reference`` (second difference of the reference), ``achieved``, ``compare``
``plots/actuators/<A>/valve/...``           ``command``, ``spool``
``plots/actuators/<A>/pressure/...``        ``a``, ``b``
``plots/actuators/<A>/force``, ``/stroke``  net piston force, stroke
``plots/accelerometers/<name>``             accelerometer channels
``plots/hydraulics/...``                    ``supply_pressure``, ``accumulator_gas_volume``
``plots/model/loop_gap``                    largest swivel opening of the model (finite samples only)
``plots/residual/<same sub-path>``          ``run - compare`` per channel (with a compare run)
==========================================  ==========================================================

Time is the run's own time on the timeline ``time`` (a duration in s). Each body's geoms are
logged once as static shapes in the body frame; per display frame (default 50 Hz, never
every physics step) only the body transforms and linkage colours change. Time series go
out whole, at the run's full rate, with ``send_columns``. The blueprint (3-D view beside
tabbed time-series panels) is built by :func:`blueprint` and travels with the recording.

A recording file is written to a temporary file in the target folder and moved into
place with ``os.replace`` only when complete; on any error the temporary file is removed,
so a reader sees either no file or the whole recording.
"""

from __future__ import annotations

import os
import tempfile
import uuid
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sim.errors import RunFileError, UserError

TIMELINE = "time"
DEFAULT_RATE_HZ = 50.0
APPLICATION_ID = "shaketable"
SUFFIX = ".rrd"
DEFAULT_URL = "rerun+http://127.0.0.1:9876/proxy"

# series colours (RGB)
_C_REF = (150, 150, 150)
_C_ACH = (31, 119, 180)
_C_CMP = (255, 127, 14)
_C_RES = (214, 39, 40)
_C_B = (44, 160, 44)
_FORCE_MAP = np.array([  # fraction of capacity -> colour
    [0.0, 60, 100, 170],
    [0.25, 60, 170, 200],
    [0.5, 230, 200, 40],
    [0.75, 240, 120, 30],
    [1.0, 215, 25, 28],
])


class RecordingError(UserError):
    """A recording that cannot be written (bad name, missing or unwritable folder)."""


def _one_line(text) -> str:
    return " ".join(str(text).split())


def force_colors(fraction: np.ndarray) -> np.ndarray:
    """(n,) force fractions of capacity (|F| / (A_a p_supply)) -> (n, 4) uint8 RGBA.

    Blue at 0, yellow at 0.5, red at 1 and beyond; NaN gives grey.
    """
    f = np.clip(np.asarray(fraction, dtype=float), 0.0, 1.0)
    out = np.empty(f.shape + (4,), dtype=np.uint8)
    for k in range(3):
        out[..., k] = np.interp(f, _FORCE_MAP[:, 0], _FORCE_MAP[:, k + 1]).round().astype(np.uint8)
    out[..., 3] = 255
    out[~np.isfinite(np.asarray(fraction, dtype=float))] = (128, 128, 128, 255)
    return out


def check_path(path) -> Path:
    """Check that a recording can be written at ``path``; RecordingError (one line) if not.

    The name must end ``.rrd``, the folder must exist and be writable (tried by creating
    and removing a temporary file there), and the path must not be a folder.
    """
    p = Path(path)
    name = str(path)
    if not p.name.endswith(SUFFIX) or p.name == SUFFIX:
        raise RecordingError(f"recording {name} does not end with {SUFFIX!r}; name it like 'run01{SUFFIX}'")
    if p.is_dir():
        raise RecordingError(f"recording {name} is a folder; give a file name ending {SUFFIX!r}")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise RecordingError(f"recording {name} cannot be written: folder {folder} does not exist; "
                             "create the folder first")
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".probe", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise RecordingError(f"recording {name} cannot be written ({_one_line(exc.strerror or exc)}); "
                             "choose a folder you can write to") from None
    return p


# ---------------------------------------------------------------------- geometry
def _quat_xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    q = np.asarray(q_wxyz, dtype=float)
    return np.concatenate([q[..., 1:4], q[..., :1]], axis=-1)


def body_entity(name: str, actuators, world: bool = False) -> str:
    """Entity path of a MuJoCo body (see the module table)."""
    if world or name in ("world", "foundation"):
        return "table/foundation"
    if name == "platen":
        return "table/platen"
    for suffix in ("_cylinder", "_rod"):
        if name.endswith(suffix) and name[: -len(suffix)] in actuators:
            return f"table/actuators/{name[: -len(suffix)]}/{suffix[1:]}"
    if name.startswith("S") and "_" in name:
        s, part = name.split("_", 1)
        if s[1:].isdigit() and part in ("piston", "shoe"):
            return f"table/supports/{s}/{part}"
    return f"table/payload/{name}"


def _geom_archetype(rr, m, g: int, *, color=True, alpha=None):
    """The rerun archetype for MuJoCo geom ``g`` in its own frame (None if not drawable)."""
    import mujoco

    gt = int(m.geom_type[g])
    size = m.geom_size[g]
    rgba = m.geom_rgba[g].copy()
    if alpha is not None:
        rgba[3] = alpha
    col = [tuple(int(round(255 * c)) for c in rgba)] if color else None
    solid = rr.components.FillMode.Solid
    T = mujoco.mjtGeom
    if gt == T.mjGEOM_BOX:
        return rr.Boxes3D(half_sizes=[size[:3]], colors=col, fill_mode=solid)
    if gt == T.mjGEOM_CYLINDER:
        return rr.Cylinders3D(lengths=[2 * size[1]], radii=[size[0]], colors=col, fill_mode=solid)
    if gt == T.mjGEOM_CAPSULE:
        return rr.Capsules3D(lengths=[2 * size[1]], radii=[size[0]], translations=[[0, 0, -size[1]]], colors=col)
    if gt == T.mjGEOM_SPHERE:
        return rr.Ellipsoids3D(half_sizes=[[size[0]] * 3], colors=col, fill_mode=solid)
    if gt == T.mjGEOM_ELLIPSOID:
        return rr.Ellipsoids3D(half_sizes=[size[:3]], colors=col, fill_mode=solid)
    if gt == T.mjGEOM_PLANE:
        hx = size[0] if size[0] > 0 else 10.0
        hy = size[1] if size[1] > 0 else 10.0
        return rr.Boxes3D(half_sizes=[[hx, hy, 0.001]], colors=col, fill_mode=solid)
    if gt == T.mjGEOM_MESH and m.geom_dataid[g] >= 0:
        k = int(m.geom_dataid[g])
        v0, nv = int(m.mesh_vertadr[k]), int(m.mesh_vertnum[k])
        f0, nf = int(m.mesh_faceadr[k]), int(m.mesh_facenum[k])
        return rr.Mesh3D(vertex_positions=m.mesh_vert[v0:v0 + nv], triangle_indices=m.mesh_face[f0:f0 + nf],
                         albedo_factor=col[0] if col else None)
    return None


@dataclass
class _Scene:
    """Which bodies and geoms of a TableModel go where."""

    bodies: list = field(default_factory=list)  # (body id, entity path), moving bodies only
    geoms: list = field(default_factory=list)  # (geom id, entity path, body entity)
    force_geoms: dict = field(default_factory=dict)  # actuator index -> [geom entity paths]


def _scene(tm) -> _Scene:
    import mujoco

    m = tm.model
    acts = list(tm.actuator_names)
    sc = _Scene()
    for b in range(m.nbody):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
        ent = body_entity(name, acts, world=(b == 0))
        if b != 0:
            sc.bodies.append((b, ent))
        for g in range(int(m.body_geomadr[b]), int(m.body_geomadr[b]) + int(m.body_geomnum[b])):
            if m.geom_rgba[g][3] <= 0:
                continue
            gname = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) or f"geom{g}"
            gent = f"{ent}/{gname}"
            sc.geoms.append((g, gent, ent))
            for i, a in enumerate(acts):
                if ent.startswith(f"table/actuators/{a}/"):
                    sc.force_geoms.setdefault(i, []).append(gent)
    return sc


def _body_poses(tm, poses: np.ndarray, payload_qpos: np.ndarray | None, bodies: list) -> tuple[np.ndarray, np.ndarray]:
    """World positions (F, nb, 3) and quaternions (F, nb, 4, wxyz) of ``bodies`` per pose.

    Each platen pose goes through ``tm.set_platen_pose`` (closes every linkage loop);
    the previous frames' loop coordinates are extrapolated as the Newton start.
    """
    import mujoco

    m = tm.model
    d = tm.new_data()
    ids = np.array([b for b, _ in bodies], dtype=int)
    pos = np.empty((len(poses), len(ids), 3))
    quat = np.empty((len(poses), len(ids), 4))
    pq_adr = None
    if payload_qpos is not None:
        jn = list(getattr(tm.info, "payload_joints", []))
        pq_adr = np.array([m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)] for n in jn], dtype=int)
    q_prev = q_prev2 = None
    for k, pose in enumerate(poses):
        if q_prev is not None and q_prev2 is not None:
            d.qpos[:] = 2.0 * q_prev - q_prev2
        if pq_adr is not None:
            d.qpos[pq_adr] = payload_qpos[k]
        tm.set_platen_pose(d, pose)
        pos[k] = d.xpos[ids]
        quat[k] = d.xquat[ids]
        q_prev2, q_prev = q_prev, d.qpos.copy()
    return pos, quat


# ---------------------------------------------------------------------- blueprint
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

    def ts(name, origin=None, contents=None):
        if contents is not None:
            return rrb.TimeSeriesView(name=name, origin="/", contents=contents)
        return rrb.TimeSeriesView(name=name, origin=origin)

    tabs = [
        rrb.Grid(*[ts(f"{d} displacement", f"plots/dof/{d}/displacement") for d in dofs], name="DOF displacement"),
        rrb.Grid(*[ts(f"{d} acceleration", f"plots/dof/{d}/acceleration") for d in dofs], name="DOF acceleration"),
        rrb.Grid(*[ts(f"{a} valve", f"plots/actuators/{a}/valve") for a in acts], name="valves"),
        rrb.Grid(*[ts(f"{a} pressure", f"plots/actuators/{a}/pressure") for a in acts], name="pressures"),
        rrb.Vertical(ts("actuator force", contents=[f"plots/actuators/{a}/force" for a in acts]),
                     ts("actuator stroke", contents=[f"plots/actuators/{a}/stroke" for a in acts]),
                     name="forces"),
        rrb.Vertical(ts("supply pressure", contents=["plots/hydraulics/supply_pressure"]),
                     ts("accumulator gas volume", contents=["plots/hydraulics/accumulator_gas_volume"]),
                     ts("loop-closure gap", contents=["plots/model/loop_gap"]),
                     name="hydraulics"),
    ]
    if run.accelerometers is not None:
        tabs.append(rrb.Grid(ts("accelerometers", "plots/accelerometers"), name="accelerometers"))
    if compare is not None:
        tabs.append(rrb.Grid(
            *[ts(f"{d} residual", contents=[f"plots/residual/dof/{d}/**"]) for d in dofs],
            ts("force residual", contents=[f"plots/residual/actuators/{a}/force" for a in acts]),
            name="residuals"))
    view3d = rrb.Spatial3DView(
        name="table", origin="/", contents=["table/**", "compare/**"],
        eye_controls=rrb.EyeControls3D(position=[11.0, -13.0, 7.0], look_target=[0.0, 0.0, 0.5],
                                       eye_up=[0.0, 0.0, 1.0]),
    )
    return rrb.Blueprint(
        rrb.Horizontal(view3d, rrb.Tabs(*tabs, active_tab=0), column_shares=[0.45, 0.55]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(state="collapsed"),
        auto_views=False,
    )


# ---------------------------------------------------------------------- series
def _aligned(run, other_t: np.ndarray, other_vals: np.ndarray) -> np.ndarray:
    """``other_vals`` sampled at ``run.t`` (linear), NaN outside the other run's span."""
    t = run.t
    vals = np.atleast_2d(np.asarray(other_vals, dtype=float).T).T if other_vals.ndim == 1 else other_vals
    if len(other_t) == len(t) and np.allclose(other_t, t, rtol=0, atol=1e-9):
        return vals
    out = np.full((len(t), vals.shape[1]), np.nan)
    inside = (t >= other_t[0]) & (t <= other_t[-1])
    for j in range(vals.shape[1]):
        out[inside, j] = np.interp(t[inside], other_t, vals[:, j])
    return out


def _reference_acceleration(run) -> np.ndarray | None:
    if run.reference is None:
        return None
    dt = run.dt
    return np.gradient(np.gradient(run.reference, dt, axis=0), dt, axis=0)


def _channel_series(run) -> list[tuple[str, str, np.ndarray]]:
    """(entity sub-path under plots/, role, (N,) values) for every channel the run has."""
    out = []
    dofs, acts = run.dofs, run.actuators

    def add(ch_arr, names, template, role):
        if ch_arr is None:
            return
        for j, n in enumerate(names):
            out.append((template.format(n=n), role, ch_arr[:, j]))

    add(run.reference, dofs, "dof/{n}/displacement", "reference")
    add(run.table_displacement, dofs, "dof/{n}/displacement", "achieved")
    add(_reference_acceleration(run), dofs, "dof/{n}/acceleration", "reference")
    add(run.table_acceleration, dofs, "dof/{n}/acceleration", "achieved")
    add(run.valve_command, acts, "actuators/{n}/valve", "command")
    add(run.spool_position, acts, "actuators/{n}/valve", "spool")
    add(run.pressure_a, acts, "actuators/{n}/pressure", "a")
    add(run.pressure_b, acts, "actuators/{n}/pressure", "b")
    add(run.actuator_force, acts, "actuators/{n}", "force")
    add(run.actuator_displacement, acts, "actuators/{n}", "stroke")
    if run.accelerometers is not None:
        for j, n in enumerate(run.column_names("accelerometers")):
            out.append(("accelerometers", n, run.accelerometers[:, j]))
    for key, where in (("supply_pressure", "hydraulics"), ("accumulator_gas_volume", "hydraulics"),
                       ("loop_gap", "model")):
        if key in run.extras:
            arr = np.asarray(run.extras[key], dtype=float)
            out.append((where, key, arr if arr.ndim == 1 else arr[:, 0]))
    return out


_UNITS = {"displacement": "m or rad", "acceleration": "m/s² or rad/s²", "valve": "fraction of rated opening",
          "pressure": "Pa", "force": "N", "stroke": "m", "accelerometers": "m/s²",
          "supply_pressure": "Pa", "accumulator_gas_volume": "m³", "loop_gap": "m"}


def _entity(sub: str, role: str) -> str:
    # accelerometers: plots/accelerometers/<name>; others: plots/<sub>/<role>
    return f"plots/{sub}/{role}"


def _role_color(role: str):
    return {"reference": _C_REF, "achieved": _C_ACH, "command": _C_REF, "spool": _C_ACH,
            "a": _C_ACH, "b": _C_B, "compare": _C_CMP, "residual": _C_RES}.get(role)


# ---------------------------------------------------------------------- target
class RrdTarget:
    """Where a recording goes: an ``.rrd`` file and/or a live viewer.

    Use :meth:`open` before a long computation (it fails early, as a one-line
    :class:`~sim.errors.UserError`, when the file cannot be written), then
    :meth:`write_run` once the run exists. ``path`` is the recording file (None for a
    viewer-only target).
    """

    def __init__(self, path: Path | None, *, spawn: bool = False, connect: str | None = None,
                 rate_hz: float = DEFAULT_RATE_HZ, application_id: str = APPLICATION_ID):
        self.path = path
        self.spawn = spawn
        self.connect = connect
        self.rate_hz = float(rate_hz)
        self.application_id = application_id
        self.recording_id: str | None = None

    @classmethod
    def open(cls, path=None, *, spawn: bool = False, connect: str | None = None,
             rate_hz: float = DEFAULT_RATE_HZ, application_id: str = APPLICATION_ID) -> "RrdTarget":
        """Check the target now; nothing is written until :meth:`write_run`.

        Args:
            path: ``.rrd`` file to write (its folder must exist and be writable), or None.
            spawn: also stream to a viewer started here (needs a screen).
            connect: also stream to a running viewer at this gRPC URL ("" for the default URL).
            rate_hz: display rate of the 3-D transforms (time series keep the run's rate).
        """
        if path is None and not spawn and connect is None:
            raise RecordingError("no recording target; give a .rrd file, spawn a viewer or connect to one")
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise RecordingError(f"display rate {rate_hz!r} Hz is not a positive number; give e.g. 50")
        p = check_path(path) if path is not None else None
        return cls(p, spawn=spawn, connect=connect, rate_hz=rate_hz, application_id=application_id)

    # ------------------------------------------------------------------ writing
    def write_run(self, run, tm, payload_qpos: np.ndarray | None = None, *, compare=None,
                  rate_hz: float | None = None, name: str | None = None) -> Path | None:
        """Record ``run`` (a RunFile) with the geometry of ``tm`` (a TableModel).

        Args:
            run: the run to record.
            tm: the table model the run belongs to (its actuators must match the run's).
            payload_qpos: optional (N, n_payload_q) joint positions of a flexible payload
                (``tm.info.payload_joints`` order) to show it deformed; run files do not carry them.
            compare: optional second RunFile laid beside ``run`` (series, residuals, ghost platen).
            rate_hz: display rate of the 3-D scene (default: the target's, 50 Hz).
            name: recording name shown in the viewer (default: the run's description or path).

        Returns:
            The recording file written, or None for a viewer-only target.
        """
        import rerun as rr

        if list(run.actuators) != list(tm.actuator_names):
            raise RunFileError(f"run file {run.name} has actuators {', '.join(run.actuators)} but table "
                               f"'{tm.desc.name}' has {', '.join(tm.actuator_names)}; give the matching --table")
        if payload_qpos is not None:
            payload_qpos = np.asarray(payload_qpos, dtype=float)
            nj = len(getattr(tm.info, "payload_joints", []))
            if payload_qpos.shape != (run.n_samples, nj):
                raise ValueError(f"payload_qpos has shape {payload_qpos.shape}, need ({run.n_samples}, {nj})")
        if compare is not None and list(compare.dofs) != list(run.dofs):
            raise RunFileError(f"run file {compare.name} has DOFs {', '.join(compare.dofs)} but "
                               f"{run.name} has {', '.join(run.dofs)}; compare runs of the same table")
        rate = float(rate_hz) if rate_hz is not None else self.rate_hz

        self.recording_id = str(uuid.uuid4())
        rec = rr.RecordingStream(self.application_id, recording_id=self.recording_id)
        bp = blueprint(run, compare, tm=tm)
        tmp = None
        try:
            sinks = []
            if self.path is not None:
                fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".tmp",
                                           dir=self.path.parent if str(self.path.parent) else ".")
                os.close(fd)
                sinks.append(rr.FileSink(tmp))
            if self.spawn:
                rr.spawn(connect=False)
            if self.spawn or self.connect is not None:
                sinks.append(rr.GrpcSink(self.connect or DEFAULT_URL))
            rec.set_sinks(*sinks, default_blueprint=bp)
            self._log(rec, run, tm, payload_qpos, compare, rate, name)
            rec.flush()
            rec.disconnect()
            if tmp is not None:
                umask = os.umask(0)
                os.umask(umask)
                os.chmod(tmp, 0o666 & ~umask)
                os.replace(tmp, self.path)
                tmp = None
        except OSError as exc:
            raise RecordingError(f"recording {self.path} cannot be written ({_one_line(exc.strerror or exc)}); "
                                 "choose a folder you can write to, with free space") from None
        finally:
            if tmp is not None:
                try:
                    rec.disconnect()
                except Exception:  # noqa: BLE001 - best effort before removing the partial file
                    pass
                try:
                    os.unlink(tmp)
                except OSError:
                    pass
        return self.path

    # ------------------------------------------------------------------ content
    def _log(self, rec, run, tm, payload_qpos, compare, rate_hz, name) -> None:
        import rerun as rr

        title = name or run.meta.get("description") or Path(run.name).name
        rec.send_recording_name(str(title))
        props = {k: str(run.meta[k]) for k in ("table", "source", "description", "scenario", "payload")
                 if run.meta.get(k) is not None}
        props["run_file"] = run.name
        if compare is not None:
            props["compare_file"] = compare.name
        if run.incomplete:
            props["incomplete_reason"] = str(run.incomplete_reason)
        rec.send_property("run", rr.AnyValues(**props))
        rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._log_scene(rec, run, tm, payload_qpos, compare, rate_hz)
        self._log_series(rec, run, compare)

    def _log_scene(self, rec, run, tm, payload_qpos, compare, rate_hz) -> None:
        import mujoco
        import rerun as rr

        m = tm.model
        sc = _scene(tm)
        colored = {g for gs in sc.force_geoms.values() for g in gs} if run.actuator_force is not None else set()
        for g, gent, _ in sc.geoms:
            arch = _geom_archetype(rr, m, g, color=gent not in colored)
            if arch is None:
                continue
            rec.log(gent, rr.Transform3D(translation=m.geom_pos[g], quaternion=_quat_xyzw(m.geom_quat[g])),
                    arch, static=True)
        # accelerometers, in the frame of the body that carries them
        acc_by_body: dict[int, list] = {}
        for a, s in zip(tm.desc.accelerometers, tm.acc_sites):
            if s >= 0:
                acc_by_body.setdefault(int(m.site_bodyid[s]), []).append((a, s))
        ents = dict(sc.bodies)
        for b, items in acc_by_body.items():
            ent = ents.get(b, "table/foundation") + "/accelerometers"
            p = np.array([m.site_pos[s] for _, s in items])
            rec.log(ent, rr.Points3D(p, radii=0.05, colors=(255, 215, 0), labels=[a.name for a, _ in items],
                                     show_labels=False),
                    rr.Arrows3D(origins=p, vectors=np.array([0.5 * a.direction for a, _ in items]),
                                colors=(255, 215, 0), radii=0.02), static=True)

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
            rec.send_columns(ent, indexes=[times],
                             columns=rr.Transform3D.columns(translation=pos[:, k], quaternion=_quat_xyzw(quat[:, k])))
        if colored:
            cap = np.array([a.cls.area_a_m2 for a in tm.desc.actuators]) * float(tm.desc.raw["supply"]["pressure_pa"])
            frac = np.abs(run.actuator_force[idx]) / cap
            for i, gents in sc.force_geoms.items():
                cols = force_colors(frac[:, i])
                for gent in gents:
                    arch = rr.Cylinders3D if gent.endswith(("cylinder", "rod")) else None
                    g = next(gg for gg, e, _ in sc.geoms if e == gent)
                    arch = {int(mujoco.mjtGeom.mjGEOM_BOX): rr.Boxes3D,
                            int(mujoco.mjtGeom.mjGEOM_CYLINDER): rr.Cylinders3D,
                            int(mujoco.mjtGeom.mjGEOM_CAPSULE): rr.Capsules3D}.get(int(m.geom_type[g]), arch)
                    if arch is not None:
                        rec.send_columns(gent, indexes=[times], columns=arch.columns(colors=cols))
        # the compare run's platen, translucent
        if compare is not None and compare.table_displacement is not None and compare.table_displacement.shape[1] == 6:
            from mjcf.model import xyz_to_quat

            other = _aligned(run, compare.t, compare.table_displacement)[idx]
            ok = np.all(np.isfinite(other), axis=1)
            if np.any(ok):
                pb = tm.platen_body
                for g in range(int(m.body_geomadr[pb]), int(m.body_geomadr[pb]) + int(m.body_geomnum[pb])):
                    arch = _geom_archetype(rr, m, g, alpha=0.35)
                    if arch is not None:
                        rec.log(f"compare/platen/g{g}", rr.Transform3D(translation=m.geom_pos[g],
                                                                        quaternion=_quat_xyzw(m.geom_quat[g])),
                                arch, static=True)
                # platen body frame relative to the reference point pose (home offset)
                d = tm.new_data()
                tm.set_platen_pose(d, np.zeros(6))
                off_p, off_q = d.xpos[pb].copy(), d.xquat[pb].copy()
                qs = np.array([xyz_to_quat(*o[3:6]) for o in other[ok]])
                tr = np.empty((int(ok.sum()), 3))
                qq = np.empty((int(ok.sum()), 4))
                for k, (o, q) in enumerate(zip(other[ok], qs)):
                    # world pose = pose(o) * home body offset (home reference pose is the identity)
                    R = np.zeros(9)
                    mujoco.mju_quat2Mat(R, q)
                    tr[k] = o[:3] + R.reshape(3, 3) @ off_p
                    mujoco.mju_mulQuat(qq[k], q, off_q)
                rec.send_columns("compare/platen", indexes=[rr.TimeColumn(TIMELINE, duration=run.t[idx][ok])],
                                 columns=rr.Transform3D.columns(translation=tr, quaternion=_quat_xyzw(qq)))

    def _log_series(self, rec, run, compare) -> None:
        import rerun as rr

        mine = _channel_series(run)
        theirs = {}
        if compare is not None:
            for sub, role, vals in _channel_series(compare):
                if role == "reference":
                    continue
                theirs[(sub, role)] = (_aligned(run, compare.t, vals[:, None])[:, 0])
        for sub, role, vals in mine:
            self._series(rec, run.t, _entity(sub, role), vals, role, sub)
            other = theirs.get((sub, role))
            if other is None:
                continue
            # the compare run's series sits next to this run's; the residual goes to plots/residual/...
            cmp_ent = _entity(sub, f"{role}_compare") if role != "achieved" else _entity(sub, "compare")
            self._series(rec, run.t, cmp_ent, other, "compare", sub, label=f"{role} (compare)")
            self._series(rec, run.t, f"plots/residual/{sub}/{role}", vals - other, "residual", sub,
                         label=f"{role} residual (run - compare)")

    @staticmethod
    def _series(rec, t, ent, vals, role, sub, label=None) -> None:
        import rerun as rr

        vals = np.asarray(vals, dtype=float)
        ok = np.isfinite(vals)
        if not np.any(ok):
            return
        unit = _UNITS.get(sub.split("/")[-1]) or _UNITS.get(role) or _UNITS.get(sub.split("/")[0], "")
        color = _role_color(role)
        rec.log(ent, rr.SeriesLines(names=f"{label or role} [{unit}]" if unit else (label or role),
                                    colors=[color] if color else None, widths=1.5), static=True)
        rec.send_columns(ent, indexes=[rr.TimeColumn(TIMELINE, duration=t[ok])],
                         columns=rr.Scalars.columns(scalars=vals[ok]))


def record_run(path, run, tm, *, compare=None, payload_qpos=None, rate_hz: float = DEFAULT_RATE_HZ,
               spawn: bool = False, connect: str | None = None) -> Path | None:
    """Convenience: ``RrdTarget.open(path, ...).write_run(run, tm, ...)``."""
    return RrdTarget.open(path, spawn=spawn, connect=connect, rate_hz=rate_hz).write_run(
        run, tm, payload_qpos, compare=compare)


__all__ = ["DEFAULT_RATE_HZ", "TIMELINE", "RecordingError", "RrdTarget", "blueprint", "body_entity",
           "check_path", "force_colors", "record_run"]
