"""The 3-D scene of a rerun recording: body entities, geoms as rerun archetypes, and the
body poses of every display frame (the linkages' closed loops solved from the platen pose).
Used by :mod:`sim.report.rerun`."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


def _quat_xyzw(q_wxyz: np.ndarray) -> np.ndarray:
    q = np.asarray(q_wxyz, dtype=float)
    return np.concatenate([q[..., 1:4], q[..., :1]], axis=-1)


def body_entity(name: str, actuators, world: bool = False, has_foundation: bool = False) -> str:
    """Entity path of a MuJoCo body (see the module table).

    The world's geoms (pit floor) are ``table/foundation``, unless the model has a
    (spring-mounted, moving) ``foundation`` body: then that body is ``table/foundation``
    and the world's geoms are ``table/ground``.
    """
    if name == "foundation":
        return "table/foundation"
    if world or name == "world":
        return "table/ground" if has_foundation else "table/foundation"
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
        return rr.Mesh3D(
            vertex_positions=m.mesh_vert[v0 : v0 + nv],
            triangle_indices=m.mesh_face[f0 : f0 + nf],
            albedo_factor=col[0] if col else None,
        )
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
    has_fdn = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "foundation") >= 0
    for b in range(m.nbody):
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) or f"body{b}"
        ent = body_entity(name, acts, world=(b == 0), has_foundation=has_fdn)
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


def _rotations_xyz(angles: np.ndarray) -> np.ndarray:
    """(F, 3) intrinsic x-y-z angles -> (F, 3, 3) rotation matrices R = Rx Ry Rz."""
    cx, cy, cz = (np.cos(angles[:, k]) for k in range(3))
    sx, sy, sz = (np.sin(angles[:, k]) for k in range(3))
    R = np.empty((len(angles), 3, 3))
    R[:, 0, 0] = cy * cz
    R[:, 0, 1] = -cy * sz
    R[:, 0, 2] = sy
    R[:, 1, 0] = cx * sz + sx * sy * cz
    R[:, 1, 1] = cx * cz - sx * sy * sz
    R[:, 1, 2] = -sx * cy
    R[:, 2, 0] = sx * sz - cx * sy * cz
    R[:, 2, 1] = sx * cz + cx * sy * sz
    R[:, 2, 2] = cx * cy
    return R


class _LoopSolver:
    """Closed-form loop closure for this project's linkages and supports.

    Every loop of the table model is either a linkage (``<A>_cylinder`` on a universal
    swivel, two hinges about its local x then y, and ``<A>_rod`` on a slide along local z,
    connected to the platen) or a support (``S<i>_piston`` on a slide and ``S<i>_shoe`` on
    two slides, connected to the platen). For a given platen pose both have an exact
    closed-form solution: the swivel angles point the linkage at the platen swivel and the
    stroke makes up the length; the support slides move the shoe anchor onto the platen
    point. This gives the same configuration as ``TableModel.set_platen_pose`` (Newton
    iterations) in microseconds per frame; :meth:`build` returns None for a model it does
    not recognise, and the caller verifies the result against ``set_platen_pose``.
    """

    def __init__(self):
        self.links = []  # (platen anchor (3,), swivel point (3,), R0 (3,3), qadr u, qadr v, qadr s, rod offset)
        self.supports = []  # (platen anchor (3,), anchor world at home (3,), Ainv (3,3), qadrs (3,), q home (3,))

    @classmethod
    def build(cls, tm):
        import mujoco

        m = tm.model
        d = tm.new_data()
        tm.set_platen_pose(d, np.zeros(6))
        pb = tm.platen_body
        if m.body_parentid[pb] != 0 or d.xpos[pb].any() or not np.allclose(d.xquat[pb], [1, 0, 0, 0]):
            return None
        J = mujoco.mjtJoint
        sv = cls()
        eq_ok = [
            e
            for e in range(m.neq)
            if m.eq_type[e] == mujoco.mjtEq.mjEQ_CONNECT and m.eq_objtype[e] == mujoco.mjtObj.mjOBJ_BODY
        ]
        if len(eq_ok) != m.neq:
            return None
        for e in eq_ok:
            b1, b2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
            a1, a2 = m.eq_data[e][0:3].copy(), m.eq_data[e][3:6].copy()
            if b2 != pb:
                if b1 != pb:
                    return None
                b1, b2, a1, a2 = b2, b1, a2, a1
            # joints from b1 up to the world
            chain = []
            b = b1
            while b != 0:
                chain[:0] = [j for j in range(m.body_jntadr[b], m.body_jntadr[b] + m.body_jntnum[b])]
                b = int(m.body_parentid[b])
            types = [int(m.jnt_type[j]) for j in chain]
            if types == [J.mjJNT_HINGE, J.mjJNT_HINGE, J.mjJNT_SLIDE]:
                ju, jv, js = chain
                cyl = int(m.jnt_bodyid[ju])
                if (
                    m.jnt_bodyid[jv] != cyl
                    or m.jnt_bodyid[js] != b1
                    or m.body_parentid[b1] != cyl
                    or not np.allclose(m.jnt_axis[ju], [1, 0, 0])
                    or not np.allclose(m.jnt_axis[jv], [0, 1, 0])
                    or not np.allclose(m.jnt_axis[js], [0, 0, 1])
                    or np.any(m.jnt_pos[[ju, jv]])
                    or np.any(m.body_pos[b1][:2])
                    or not np.allclose(m.body_quat[b1], [1, 0, 0, 0])
                    or np.any(a1[:2])
                ):
                    return None
                R0 = np.zeros(9)
                mujoco.mju_quat2Mat(R0, m.body_quat[cyl])
                R0 = d.xmat[m.body_parentid[cyl]].reshape(3, 3) @ R0.reshape(3, 3)
                off = float(m.body_pos[b1][2] + a1[2])
                sv.links.append(
                    (
                        a2,
                        d.xanchor[ju].copy(),
                        R0,
                        m.jnt_qposadr[ju],
                        m.jnt_qposadr[jv],
                        m.jnt_qposadr[js],
                        off,
                        float(m.qpos0[m.jnt_qposadr[js]]),
                    )
                )
            elif types == [J.mjJNT_SLIDE] * 3:
                # slides only: no rotation, the anchor moves linearly with the three coordinates
                A = np.array([d.xaxis[j] for j in chain]).T
                if abs(np.linalg.det(A)) < 1e-9:
                    return None
                qadr = np.array([m.jnt_qposadr[j] for j in chain])
                R1 = d.xmat[b1].reshape(3, 3)
                w = d.xpos[b1] + R1 @ a1
                sv.supports.append((a2, w, np.linalg.inv(A), qadr, d.qpos[qadr].copy()))
            else:
                return None
        sv.home = d.qpos.copy()
        return sv

    def coordinates(self, pos: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Loop coordinates for F platen poses (pos (F, 3), R (F, 3, 3)): (qpos addresses, (F, n) values)."""
        adr, cols = [], []
        for a2, b, R0, qu, qv, qs, off, _ in self.links:
            v = pos + R @ a2 - b
            L = np.linalg.norm(v, axis=1)
            e = (v / L[:, None]) @ R0  # = R0.T @ unit vector, per row
            adr += [qv, qu, qs]
            cols += [np.arcsin(np.clip(e[:, 0], -1.0, 1.0)), np.arctan2(-e[:, 1], e[:, 2]), L - off]
        for a2, w, Ainv, qadr, qh in self.supports:
            dq = (pos + R @ a2 - w) @ Ainv.T + qh
            adr += list(qadr)
            cols += [dq[:, i] for i in range(len(qadr))]
        return np.array(adr, dtype=int), np.column_stack(cols) if cols else np.zeros((len(pos), 0))


def _body_poses(
    tm, poses: np.ndarray, payload_qpos: np.ndarray | None, bodies: list, exact: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """World positions (F, nb, 3) and quaternions (F, nb, 4, wxyz) of ``bodies`` per platen pose.

    The linkages are closed in closed form (:class:`_LoopSolver`) and the result is checked
    against ``tm.set_platen_pose`` (Newton closure) at the first, the largest and the last
    pose; if they disagree by more than 1 um / 1 urad, or ``exact`` is set, every pose goes
    through ``tm.set_platen_pose``.
    """
    import mujoco

    m = tm.model
    ids = np.array([b for b, _ in bodies], dtype=int)
    F = len(poses)
    pos = np.empty((F, len(ids), 3))
    quat = np.empty((F, len(ids), 4))
    pq_adr = None
    if payload_qpos is not None:
        jn = list(getattr(tm.info, "payload_joints", []))
        pq_adr = np.array([m.jnt_qposadr[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, n)] for n in jn], dtype=int)
    pa = tm.platen_qadr

    def exact_pose(d, k):
        if pq_adr is not None:
            d.qpos[pq_adr] = payload_qpos[k]
        tm.set_platen_pose(d, poses[k])

    solver = None if exact else _LoopSolver.build(tm)
    if solver is not None:
        Rs = _rotations_xyz(poses[:, 3:6])
        qadr, Q = solver.coordinates(poses[:, :3], Rs)
        qp = np.empty((F, 4))
        for k in range(F):
            mujoco.mju_mat2Quat(qp[k], Rs[k].ravel())
        d = tm.new_data()
        d.qpos[:] = solver.home

        def fast_pose(k):
            d.qpos[pa : pa + 3] = poses[k, :3]
            d.qpos[pa + 3 : pa + 7] = qp[k]
            if pq_adr is not None:
                d.qpos[pq_adr] = payload_qpos[k]
            d.qpos[qadr] = Q[k]
            mujoco.mj_kinematics(m, d)

        de = tm.new_data()
        big = int(np.argmax(np.abs(poses[:, :3]).sum(axis=1) + np.abs(poses[:, 3:]).sum(axis=1) * 3.0))
        for k in sorted({0, big, F - 1}):
            fast_pose(k)
            exact_pose(de, k)
            dq = np.abs(np.abs(np.einsum("ij,ij->i", d.xquat[ids], de.xquat[ids])) - 1.0)
            if np.abs(d.xpos[ids] - de.xpos[ids]).max() > 1e-6 or dq.max() > 1e-12:
                solver = None
                break
    if solver is not None:
        for k in range(F):
            fast_pose(k)
            pos[k] = d.xpos[ids]
            quat[k] = d.xquat[ids]
        return pos, quat
    d = tm.new_data()
    q_prev = q_prev2 = None
    for k in range(F):
        if q_prev is not None and q_prev2 is not None:
            d.qpos[:] = 2.0 * q_prev - q_prev2  # warm start: extrapolate the loop coordinates
        exact_pose(d, k)
        pos[k] = d.xpos[ids]
        quat[k] = d.xquat[ids]
        q_prev2, q_prev = q_prev, d.qpos.copy()
    return pos, quat


def specimen_sensor_marks(tm, sensors, ents: dict) -> dict:
    """Where the run's specimen sensors (``meta.specimen_sensors``) sit in the scene:
    ``{entity: (positions (k, 3), directions (k, 3), labels)}``, each under the body that
    carries it (a shear frame's floor at the sensor's height, or the platen at height 0;
    :func:`sim.runs.specimen.sensor_place`), in that body's frame. A sensor the model has
    no floor for is not drawn."""
    import mujoco

    from sim.runs.specimen import sensor_place

    out: dict = {}
    payload = getattr(tm, "payload", None)
    for s in sensors or []:
        place = sensor_place(payload, float(s["height_m"])) if payload is not None else None
        if place is None:
            continue
        name = "platen" if place == 0 else f"floor{place}"
        b = mujoco.mj_name2id(tm.model, mujoco.mjtObj.mjOBJ_BODY, name)
        if b < 0 or b not in ents:
            continue
        pos = [0.0, 0.0, float(s["height_m"])] if place == 0 else [0.0, 0.0, 0.0]
        p, d, lab = out.setdefault(ents[b] + "/specimen_sensors", ([], [], []))
        p.append(pos)
        d.append([float(x) for x in s["direction"]])
        lab.append(str(s["name"]))
    return {k: (np.array(p), np.array(d), lab) for k, (p, d, lab) in out.items()}


def log_static_scene(rec, rr, tm, sc, colored: set, specimen_sensors) -> None:
    """Log the model's geoms (those in ``colored`` left uncoloured: their colour follows
    the force), the platen accelerometers in the frame of the body that carries each,
    and the specimen's sensors, all static."""
    m = tm.model
    for g, gent, _ in sc.geoms:
        arch = _geom_archetype(rr, m, g, color=gent not in colored)
        if arch is None:
            continue
        rec.log(
            gent,
            rr.Transform3D(translation=m.geom_pos[g], quaternion=_quat_xyzw(m.geom_quat[g])),
            arch,
            static=True,
        )
    # accelerometers, in the frame of the body that carries them
    acc_by_body: dict[int, list] = {}
    for a, s in zip(tm.desc.accelerometers, tm.acc_sites):
        if s >= 0:
            acc_by_body.setdefault(int(m.site_bodyid[s]), []).append((a, s))
    ents = dict(sc.bodies)
    for b, items in acc_by_body.items():
        ent = ents.get(b, "table/foundation") + "/accelerometers"
        p = np.array([m.site_pos[s] for _, s in items])
        rec.log(
            ent,
            rr.Points3D(p, radii=0.05, colors=(255, 215, 0), labels=[a.name for a, _ in items], show_labels=False),
            rr.Arrows3D(
                origins=p, vectors=np.array([0.5 * a.direction for a, _ in items]), colors=(255, 215, 0), radii=0.02
            ),
            static=True,
        )

    # the specimen's sensors, on the floor (or the platen) that carries each
    for ent, (p, d, labels) in specimen_sensor_marks(tm, specimen_sensors, ents).items():
        rec.log(
            ent,
            rr.Points3D(p, radii=0.05, colors=(0, 200, 200), labels=labels, show_labels=False),
            rr.Arrows3D(origins=p, vectors=0.5 * d, colors=(0, 200, 200), radii=0.02),
            static=True,
        )


def log_compare_platen(rec, rr, run, tm, compare, idx: np.ndarray, timeline: str) -> None:
    """The compared run's platen, translucent, at the display frames ``idx`` of ``run``."""
    import mujoco

    from mjcf.model import xyz_to_quat
    from sim.report.rerun_series import _aligned

    m = tm.model
    other = _aligned(run, compare.t, compare.table_displacement)[idx]
    ok = np.all(np.isfinite(other), axis=1)
    if not np.any(ok):
        return
    pb = tm.platen_body
    for g in range(int(m.body_geomadr[pb]), int(m.body_geomadr[pb]) + int(m.body_geomnum[pb])):
        arch = _geom_archetype(rr, m, g, alpha=0.35)
        if arch is not None:
            rec.log(
                f"compare/platen/g{g}",
                rr.Transform3D(translation=m.geom_pos[g], quaternion=_quat_xyzw(m.geom_quat[g])),
                arch,
                static=True,
            )
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
    rec.send_columns(
        "compare/platen",
        indexes=[rr.TimeColumn(timeline, duration=run.t[idx][ok])],
        columns=rr.Transform3D.columns(translation=tr, quaternion=_quat_xyzw(qq)),
    )
