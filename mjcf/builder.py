"""Build the MuJoCo scene of a table (+ payload) with ``mujoco.MjSpec``.

Bodies (all derived from one :class:`~mjcf.description.TableDescription`):

* ``platen`` on a free joint; its frame origin is the table reference point (centre of
  the top surface at home), so ``qpos[0:3]`` is the reference-point position.
* per linkage ``<A>``: ``<A>_cylinder`` on a universal swivel at the foundation (two
  hinges ``<A>_swivel_u``, ``<A>_swivel_v``; no spin about the linkage axis), and
  ``<A>_rod`` on a slide joint ``<A>_stroke`` along the linkage axis (+ = extension,
  0 = mid-stroke). The loop closes at the platen swivel with a ``connect`` equality
  ``<A>_swivel``. A gear-1 ``motor`` named ``<A>`` on the slide makes ``ctrl`` the
  actuator force in newtons. Seal Coulomb friction is the slide's ``frictionloss``
  (implicit, so it sticks properly), seal viscous drag its ``damping``.
* per static support ``S<i>``: ``S<i>_piston`` on a vertical slide (``S<i>_air``; the
  air spring as a linear joint spring whose preload carries the dead weight, piston
  seal friction as ``frictionloss``) and a sliding shoe ``S<i>_shoe`` (two horizontal
  slides with the shoe friction) pinned to the platen by a ``connect`` equality. The
  piston moves only vertically; only the light shoe follows the platen horizontally.
* ``foundation``: world-fixed, or (``mode = "spring"``) a body on three slides with a
  spring-damper per axis; every base swivel and support sits on it.
* the payload: rigid (clamped: a child body of the platen, or on a 3-axis clamping
  spring when ``clamp_frequency_hz`` is given, optionally only ``clamp_mass_fraction`` of
  the mass, the rest rigid), a lumped shear frame (floors on slides
  relative to the platen, the stiffness and modal damping matrices as fixed tendons),
  or a continuum cantilever (a chain of rigid segments with bending springs).

No geom collides: every geom is visual (group 2, contype = conaffinity = 0) and inertia
is explicit per body, so the drawing never changes the dynamics.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import mujoco
import numpy as np

from mjcf.description import (
    CantileverPayload,
    DescriptionError,
    Payload,
    RigidPayload,
    ShearFramePayload,
    TableDescription,
    payload_mass,
)
from mjcf.stepping import mode_spring


@dataclass(frozen=True, kw_only=True)
class BuildOptions:
    """Integrator and constraint settings (proved in tests/mjcf/test_model.py).

    The loop-closing ``connect`` equalities carry hundreds of kN through light rods.
    MuJoCo's default (solref 0.02 s, solimp 0.9/0.95) lets them open by millimetres, so
    they are made as stiff as a 0.5 ms step allows: time constant 2 dt (the smallest
    stable value), critical damping, and impedance 0.9999 (the constraint carries
    99.99 % of the load rigidly, the soft part only regularises the solve).
    """

    timestep_s: float = 1.0 / 2048  #: physics step (0.49 ms): two steps per 1024 Hz controller/recorder tick
    integrator: str = "implicitfast"
    solver_iterations: int = 100
    solver_tolerance: float = 1e-12
    eq_solref: tuple[float, float] = (0.001, 1.0)  #: (time constant s, damping ratio)
    eq_solimp: tuple[float, ...] = (0.9999, 0.9999, 0.001, 0.5, 2.0)
    friction_solref: tuple[float, float] = (0.001, 1.0)
    friction_solimp: tuple[float, ...] = (0.9999, 0.9999, 0.001, 0.5, 2.0)


# colours of the drawing
_STEEL = [0.55, 0.58, 0.62, 1.0]
_CONCRETE = [0.62, 0.6, 0.56, 1.0]
_CYL = [0.2, 0.35, 0.6, 1.0]
_ROD = [0.8, 0.8, 0.82, 1.0]
_SUPPORT = [0.45, 0.5, 0.3, 1.0]
_PAYLOAD = [0.75, 0.45, 0.2, 1.0]

#: the share of a support shoe's friction on each of its x and y slides: the shoe's
#: ``shoe_friction_n`` along a diagonal (assumed: the slides' split, one number per shoe)
SHOE_SLIDE_SHARE = 1.0 / math.sqrt(2.0)


def air_spring_stiffness(sp, load_n: float) -> float:
    """The linear stiffness (N/m) of a static support's air spring carrying ``load_n``:
    ``n p0 A^2 / V0`` at the pressure ``p0 = load / A`` (the polytropic law about its
    preload)."""
    p0 = load_n / sp.piston_area_m2
    return sp.polytropic_exponent * p0 * sp.piston_area_m2**2 / sp.chamber_volume_m3


def _frame_from_z(z: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z) of a frame whose local z axis is ``z``.

    The local x axis is chosen horizontal where possible, so the first swivel hinge of a
    horizontal linkage swings it vertically and the second sideways.
    """
    z = z / np.linalg.norm(z)
    ref = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(ref, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.column_stack([x, y, z])
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, R.flatten())
    return q


def _cyl_inertia(m, r, length):
    return [m * (3 * r * r + length * length) / 12, m * (3 * r * r + length * length) / 12, m * r * r / 2]


def _box_inertia(m, size):
    a, b, c = size
    return [m * (b * b + c * c) / 12, m * (a * a + c * c) / 12, m * (a * a + b * b) / 12]


def _visual(body, **kw):
    return body.add_geom(contype=0, conaffinity=0, group=2, **kw)


@dataclass
class BuildInfo:
    """What the builder made and where, for :class:`mjcf.model.TableModel`."""

    support_loads_n: np.ndarray = field(default_factory=lambda: np.zeros(0))
    payload_kind: str = "none"
    payload_joints: list[str] = field(default_factory=list)
    payload_bodies: list[str] = field(default_factory=list)
    step_effects: list = field(default_factory=list)  #: effects applied every physics step
    effects: list = field(default_factory=list)  #: every effect object (lifecycle run by the loop)
    friction_joints: list[str] = field(default_factory=list)  #: joints whose friction the loop applies
    friction_force_n: list[float] = field(default_factory=list)  #: their Coulomb levels (N or N m)
    air_joints: list[str] = field(default_factory=list)  #: support joints whose nonlinear air law the loop adds


def build_spec(
    desc: TableDescription, payload: Payload | None = None, options: BuildOptions | None = None, *, effects=None
) -> tuple[mujoco.MjSpec, BuildInfo]:
    """Build the table's MjSpec (supports not yet preloaded: see :func:`build`).

    ``effects``: ``effects(spec, entries, desc) -> (step_effects, effects)`` builds the
    description's ``[[effect]]`` entries into the spec and returns those applied every
    physics step and every effect object. ``mjcf`` knows no
    effects (they live in ``sim.effects``, a layer above): a description that declares
    effects is built through ``sim.effects.build_model``, which passes it.
    """
    opt = options or BuildOptions()
    info = BuildInfo()
    spec = _new_spec(desc, opt)
    link_cls, sup_cls = _add_defaults(spec, desc, opt)
    world = spec.worldbody
    _add_scenery(world)
    base_parent = _add_foundation(world, desc.foundation)
    platen = _add_platen(world, base_parent, desc)
    for a in desc.actuators:
        _add_linkage(spec, base_parent, a, link_cls[a.cls.name], opt)
    if desc.supports is not None:
        for i, p in enumerate(desc.supports.positions_m, start=1):
            _add_support(spec, base_parent, f"S{i}", p, desc.supports, sup_cls, opt)
    _add_payload(spec, platen, payload, info)
    if desc.effects:
        if effects is None:
            raise DescriptionError(
                f"{desc.source}: the description declares [[effect]] entries, which mjcf alone cannot build; "
                "build it with sim.effects.build_model"
            )
        info.step_effects, info.effects = effects(spec, list(desc.effects), desc)
    return spec, info


def _new_spec(desc: TableDescription, opt: BuildOptions) -> mujoco.MjSpec:
    """An empty spec with the compiler and solver options (no contacts: the model has none)."""
    spec = mujoco.MjSpec()
    spec.modelname = f"shaketable_{desc.name}"
    spec.compiler.degree = False
    spec.compiler.autolimits = True
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.option.timestep = opt.timestep_s
    spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{opt.integrator.upper()}")
    spec.option.solver = mujoco.mjtSolver.mjSOL_NEWTON
    spec.option.iterations = opt.solver_iterations
    spec.option.tolerance = opt.solver_tolerance
    spec.option.jacobian = mujoco.mjtJacobian.mjJAC_SPARSE  # 20 % cheaper per step than dense here (bench)
    spec.option.gravity = [0.0, 0.0, -desc.gravity_m_s2]
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    spec.stat.extent = 12.0
    spec.stat.center = [0.0, 0.0, -1.0]
    return spec


def _add_defaults(spec: mujoco.MjSpec, desc: TableDescription, opt: BuildOptions):
    """Default classes for the repeated parts (menagerie habit): one per actuator class
    and one for the static supports; returns them."""
    main = spec.default
    main.geom.contype = 0
    main.geom.conaffinity = 0
    main.geom.group = 2
    main.joint.solref_friction = list(opt.friction_solref)
    main.joint.solimp_friction = list(opt.friction_solimp)
    link_cls = {}
    for cname in desc.actuator_classes:
        d = spec.add_default(f"linkage_{cname}", main)
        d.geom.rgba = _CYL
        link_cls[cname] = d
    sup_cls = spec.add_default("static_support", main)
    sup_cls.geom.rgba = _SUPPORT
    return link_cls, sup_cls


def _add_scenery(world) -> None:
    """A light and the pit floor (visual only)."""
    world.add_light(name="sun", pos=[0, 0, 12], dir=[0, 0, -1], type=mujoco.mjtLightType.mjLIGHT_DIRECTIONAL)
    _visual(
        world, name="pit_floor", type=mujoco.mjtGeom.mjGEOM_BOX, pos=[0, 0, -3.3], size=[7.5, 7.5, 0.2], rgba=_CONCRETE
    )


def _add_foundation(world, fd):
    """The body the linkages stand on: the world itself, or a reaction mass on three
    spring-dampers tuned to the foundation's frequencies and damping ratios."""
    if fd.mode == "fixed":
        return world
    base_parent = world.add_body(name="foundation", pos=[0, 0, 0])
    base_parent.explicitinertial = True
    base_parent.mass = fd.mass_kg
    base_parent.ipos = [0, 0, -3.0]
    base_parent.inertia = _box_inertia(fd.mass_kg, [15, 15, 6])
    for k, ax in enumerate(("x", "y", "z")):
        w = 2 * math.pi * fd.frequency_hz[k]
        axis = [0.0, 0.0, 0.0]
        axis[k] = 1.0
        j = base_parent.add_joint(name=f"foundation_{ax}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
        j.stiffness = [fd.mass_kg * w * w, 0, 0]
        j.damping = [2 * fd.damping_ratio[k] * fd.mass_kg * w, 0, 0]
    _visual(
        base_parent,
        name="foundation_block",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        pos=[0, 0, -3.2],
        size=[7.0, 7.0, 0.05],
        rgba=_CONCRETE,
    )
    return base_parent


def _add_platen(world, base_parent, desc: TableDescription):
    """The platen (free, or on linear bearings), its reference site and accelerometer sites."""
    pl = desc.platen
    if pl.guided:
        # Linear bearings on the foundation: one slide per translational DOF of the table.
        platen = base_parent.add_body(name="platen", pos=[0, 0, 0])
        for dof in desc.dofs:
            axis = {"x": [1, 0, 0], "y": [0, 1, 0], "z": [0, 0, 1]}[dof]
            platen.add_joint(name=f"platen_{dof}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
    else:
        platen = world.add_body(name="platen", pos=[0, 0, 0])
        platen.add_freejoint(name="platen")
    platen.explicitinertial = True
    platen.mass = pl.mass_kg
    platen.ipos = pl.com_m.tolist()
    platen.inertia = pl.inertia_kg_m2.tolist()
    _visual(
        platen,
        name="platen_box",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        pos=[0, 0, -pl.size_m[2] / 2],
        size=(pl.size_m / 2).tolist(),
        rgba=_STEEL,
    )
    platen.add_site(name="reference", pos=[0, 0, 0], size=[0.05, 0, 0])
    for acc in desc.accelerometers:
        platen.add_site(
            name=f"acc_{acc.name}",
            pos=acc.position_m.tolist(),
            size=[0.04, 0, 0],
            quat=_frame_from_z(acc.direction).tolist(),
            rgba=[1, 0.2, 0.2, 1],
        )
    return platen


def _add_linkage(spec: mujoco.MjSpec, base_parent, a, default_cls, opt: BuildOptions) -> None:
    """One actuator: a cylinder on a two-axis swivel at the base, a rod sliding in it
    (the stroke joint, with the seal friction), a ball joint (connect) to the platen,
    and the motor on the stroke joint."""
    c = a.cls
    L0 = a.length0_m
    cyl = base_parent.add_body(
        name=f"{a.name}_cylinder",
        pos=a.base_m.tolist(),
        quat=_frame_from_z(a.axis).tolist(),
        childclass=default_cls.name,
    )
    cyl.explicitinertial = True
    cyl.mass = c.cylinder_mass_kg
    cyl.ipos = [0, 0, c.cylinder_length_m / 2]
    cyl.inertia = _cyl_inertia(c.cylinder_mass_kg, c.cylinder_radius_m, c.cylinder_length_m)
    cyl.add_joint(name=f"{a.name}_swivel_u", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[1, 0, 0])
    cyl.add_joint(name=f"{a.name}_swivel_v", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 1, 0])
    _visual(
        cyl,
        name=f"{a.name}_cylinder",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        fromto=[0, 0, 0, 0, 0, c.cylinder_length_m],
        size=[c.cylinder_radius_m, 0, 0],
    )
    cyl.add_site(name=f"{a.name}_base", pos=[0, 0, 0], size=[0.05, 0, 0])

    rod = cyl.add_body(name=f"{a.name}_rod", pos=[0, 0, 0])
    rod.explicitinertial = True
    rod.mass = c.rod_mass_kg
    rod.ipos = [0, 0, L0 - c.rod_length_m / 2]
    rod.inertia = _cyl_inertia(c.rod_mass_kg, c.rod_radius_m, c.rod_length_m)
    js = rod.add_joint(name=f"{a.name}_stroke", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1])
    js.frictionloss = c.seal_friction_n
    js.damping = [c.seal_viscous_n_s_m, 0, 0]
    _visual(
        rod,
        name=f"{a.name}_rod",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        fromto=[0, 0, L0 - c.rod_length_m, 0, 0, L0],
        size=[c.rod_radius_m, 0, 0],
        rgba=_ROD,
    )
    rod.add_site(name=f"{a.name}_rod_end", pos=[0, 0, L0], size=[0.05, 0, 0])
    _connect(spec, f"{a.name}_swivel", f"{a.name}_rod", [0, 0, L0], opt)

    act = spec.add_actuator(name=a.name, target=f"{a.name}_stroke", trntype=mujoco.mjtTrn.mjTRN_JOINT)
    act.gear[0] = 1.0
    act.ctrllimited = False


def _connect(spec: mujoco.MjSpec, name: str, body: str, anchor, opt: BuildOptions) -> None:
    """A ball joint (connect equality) from ``body`` at ``anchor`` to the platen."""
    eq = spec.add_equality(name=name)
    eq.type = mujoco.mjtEq.mjEQ_CONNECT
    eq.objtype = mujoco.mjtObj.mjOBJ_BODY
    eq.name1 = body
    eq.name2 = "platen"
    eq.data[0:3] = anchor
    eq.solref = list(opt.eq_solref)
    eq.solimp = list(opt.eq_solimp)


def _add_support(spec: mujoco.MjSpec, base_parent, nm: str, p, sp, sup_cls, opt: BuildOptions) -> None:
    """One static support at ``p``: an air piston (vertical slide with friction) carrying a
    shoe that slides in x and y, pinned to the platen."""
    pis = base_parent.add_body(
        name=f"{nm}_piston", pos=[p[0], p[1], p[2] - sp.piston_length_m], childclass=sup_cls.name
    )
    pis.explicitinertial = True
    pis.mass = sp.piston_mass_kg
    pis.ipos = [0, 0, sp.piston_length_m / 2]
    pis.inertia = _cyl_inertia(sp.piston_mass_kg, sp.piston_radius_m, sp.piston_length_m)
    ja = pis.add_joint(name=f"{nm}_air", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[0, 0, 1])
    ja.frictionloss = sp.piston_friction_n
    _visual(
        pis,
        name=f"{nm}_piston",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        fromto=[0, 0, 0, 0, 0, sp.piston_length_m],
        size=[sp.piston_radius_m, 0, 0],
    )
    shoe = pis.add_body(name=f"{nm}_shoe", pos=[0, 0, sp.piston_length_m])
    shoe.explicitinertial = True
    shoe.mass = sp.shoe_mass_kg
    shoe.ipos = [0, 0, 0]
    shoe.inertia = _box_inertia(sp.shoe_mass_kg, [0.4, 0.4, 0.1])
    for ax, vec in (("x", [1, 0, 0]), ("y", [0, 1, 0])):
        jsh = shoe.add_joint(name=f"{nm}_shoe_{ax}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=vec)
        jsh.frictionloss = sp.shoe_friction_n * SHOE_SLIDE_SHARE
    _visual(
        shoe,
        name=f"{nm}_shoe",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        pos=[0, 0, -0.05],
        size=[0.2, 0.2, 0.05],
        rgba=_ROD,
    )
    _connect(spec, f"{nm}_pin", f"{nm}_shoe", [0, 0, 0], opt)


def _add_payload(spec, platen, payload, info):
    """The specimen on the platen, by kind (none, rigid block, shear frame, cantilever)."""
    if payload is None:
        return
    if isinstance(payload, RigidPayload):
        _add_rigid_payload(spec, platen, payload, info)
    elif isinstance(payload, ShearFramePayload):
        _add_shear_frame(spec, platen, payload, info)
    elif isinstance(payload, CantileverPayload):
        _add_cantilever(platen, payload, info)


def _add_rigid_payload(spec, platen, p: RigidPayload, info: BuildInfo) -> None:
    """A rigid block, fixed to the platen or (with a clamp frequency) partly on springs."""
    info.payload_kind = "rigid"
    if p.clamp_frequency_hz is None:
        body = platen.add_body(name="payload", pos=p.com_m.tolist())
    else:
        # Clamping flexibility: the block (or the fraction clamp_mass_fraction of its mass,
        # body "payload") on a 3-axis spring-damper of clamp_frequency_hz to the platen; the
        # rest of the mass (body "payload_fixed") rigidly on the platen, same centre.
        a = p.clamp_mass_fraction
        if a < 1.0:
            fixed = platen.add_body(name="payload_fixed", pos=p.com_m.tolist())
            fixed.explicitinertial = True
            fixed.mass = (1.0 - a) * p.mass_kg
            fixed.ipos = [0, 0, 0]
            fixed.inertia = ((1.0 - a) * p.inertia_kg_m2).tolist()
            info.payload_bodies.append("payload_fixed")
        body = platen.add_body(name="payload", pos=p.com_m.tolist())
        for ax, vec in (("x", [1, 0, 0]), ("y", [0, 1, 0]), ("z", [0, 0, 1])):
            j = body.add_joint(name=f"payload_clamp_{ax}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=vec)
            k, c = mode_spring(spec, a * p.mass_kg, p.clamp_frequency_hz, p.clamp_damping_ratio)
            j.stiffness = [k, 0, 0]
            j.damping = [c, 0, 0]
            info.payload_joints.append(j.name)
    a = 1.0 if p.clamp_frequency_hz is None else p.clamp_mass_fraction
    body.explicitinertial = True
    body.mass = a * p.mass_kg
    body.ipos = [0, 0, 0]
    body.inertia = (a * p.inertia_kg_m2).tolist()
    info.payload_bodies.append("payload")
    # The block drawn from its footprint and height, resting on the platen.
    _visual(
        body,
        name="payload_block",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        pos=[0, 0, p.height_m / 2 - p.com_m[2]],
        size=[p.footprint_m[0] / 2, p.footprint_m[1] / 2, p.height_m / 2],
        rgba=_PAYLOAD,
    )


def _add_shear_frame(spec, platen, p: ShearFramePayload, info: BuildInfo) -> None:
    """Floor masses on drift slides, coupled by the frame's stiffness and damping."""
    info.payload_kind = "shear_frame"
    n = len(p.mass_kg)
    axis = [1.0, 0.0, 0.0] if p.direction == "x" else [0.0, 1.0, 0.0]
    names = []
    for i in range(n):
        z = p.base_m[2] + (i + 1) * p.storey_height_m
        b = platen.add_body(name=f"floor{i + 1}", pos=[p.base_m[0], p.base_m[1], z])
        b.explicitinertial = True
        b.mass = float(p.mass_kg[i])
        b.ipos = [0, 0, 0]
        b.inertia = _box_inertia(float(p.mass_kg[i]), [p.footprint_m[0], p.footprint_m[1], 0.05])
        j = b.add_joint(name=f"floor{i + 1}_drift", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
        names.append(j.name)
        _visual(
            b,
            name=f"floor{i + 1}_slab",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=[p.footprint_m[0] / 2, p.footprint_m[1] / 2, 0.02],
            rgba=_PAYLOAD,
        )
        info.payload_bodies.append(b.name)
    info.payload_joints.extend(names)
    _add_frame_tendons(spec, p, names)


def _add_frame_tendons(spec, p: ShearFramePayload, names: list[str]) -> None:
    """K and C as sums of rank-one springs/dampers on fixed tendons: K = sum k_i v_i v_i^T
    with v_i the eigenvectors of K (all k_i > 0 since K is positive definite).

    Both are built mode by mode, ``M phi diag(k_n) phi^T M`` with mass-normalised shapes
    ``phi``, each mode's ``k_n``, ``c_n`` those that give its frequency and the modal
    damping as the model's step has them (:func:`mode_spring`; the damping is classical,
    so the step keeps the modes apart). With a plain K, the 3-storey frame's 34 Hz, 2 %
    mode stepped 0.06 % low."""
    n = len(names)
    M = np.diag(p.mass_kg)
    w2, phi = _generalized_eig(p.stiffness_n_m, M)
    Mphi = M @ phi
    f = np.sqrt(w2) / (2 * np.pi)
    modal = np.array([mode_spring(spec, 1.0, fn, zn) for fn, zn in zip(f, np.broadcast_to(p.damping_ratio, f.shape))])
    K = Mphi @ np.diag(modal[:, 0]) @ Mphi.T
    C = Mphi @ np.diag(modal[:, 1]) @ Mphi.T
    for label, mat, kind in (("k", K, "stiffness"), ("c", C, "damping")):
        vals, vecs = np.linalg.eigh(mat)
        for i in range(n):
            if vals[i] <= 1e-12 * max(abs(vals).max(), 1.0):
                continue
            t = spec.add_tendon(name=f"frame_{label}{i + 1}")
            for jn, coef in zip(names, vecs[:, i]):
                t.wrap_joint(jn, float(coef))
            if kind == "stiffness":
                t.stiffness = [float(vals[i]), 0, 0]
                t.springlength = [0.0, 0.0]
            else:
                t.damping = [float(vals[i]), 0, 0]


def _add_cantilever(platen, p: CantileverPayload, info: BuildInfo) -> None:
    """Rigid finite elements (spring-at-centre discretisation): the beam is cut into
    n segments of length l; a bending spring EI/l sits at the centre of each
    segment, and the rigid bodies span from one spring to the next (half
    segments at the two ends). This converges much faster than springs at the
    segment ends (first mode within 0.1 % at n = 24, see tests)."""
    info.payload_kind = "cantilever"
    n = p.n_segments
    seg = p.height_m / n
    mu = p.mass_per_length_kg_m
    k_rot = p.bending_stiffness_n_m2 / seg
    w1 = (1.875104**2) * math.sqrt(p.bending_stiffness_n_m2 / (mu * p.height_m**4))
    foot = platen.add_body(name="segment0", pos=p.base_m.tolist())
    foot.explicitinertial = True
    foot.mass = mu * seg / 2
    foot.ipos = [0, 0, seg / 4]
    foot.inertia = _box_inertia(mu * seg / 2, [p.width_m, p.width_m, seg / 2])
    _visual(
        foot,
        name="segment0",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        pos=[0, 0, seg / 4],
        size=[p.width_m / 2, p.width_m / 2, seg / 4 * 0.98],
        rgba=_PAYLOAD,
    )
    info.payload_bodies.append("segment0")
    parent = foot
    pos = [0, 0, seg / 2]
    for i in range(n):
        length = seg if i < n - 1 else seg / 2
        m_seg = mu * length
        b = parent.add_body(name=f"segment{i + 1}", pos=pos)
        b.explicitinertial = True
        b.mass = m_seg
        b.ipos = [0, 0, length / 2]
        b.inertia = _box_inertia(m_seg, [p.width_m, p.width_m, length])
        for ax, vec in (("x", [1, 0, 0]), ("y", [0, 1, 0])):
            j = b.add_joint(name=f"segment{i + 1}_bend_{ax}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=vec)
            j.stiffness = [k_rot, 0, 0]
            # stiffness-proportional damping giving damping_ratio at the first mode
            j.damping = [2 * p.damping_ratio * k_rot / w1, 0, 0]
            info.payload_joints.append(j.name)
        _visual(
            b,
            name=f"segment{i + 1}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=[0, 0, length / 2],
            size=[p.width_m / 2, p.width_m / 2, length / 2 * 0.98],
            rgba=_PAYLOAD,
        )
        info.payload_bodies.append(b.name)
        parent = b
        pos = [0, 0, length]


def _generalized_eig(K, M):
    L = np.linalg.cholesky(M)
    Li = np.linalg.inv(L)
    w2, y = np.linalg.eigh(Li @ K @ Li.T)
    phi = Li.T @ y
    return w2, phi


def build(desc: TableDescription, payload: Payload | None = None, options: BuildOptions | None = None, *, effects=None):
    """Build and compile the table, with the static supports preloaded for equilibrium.

    Returns a :class:`mjcf.model.TableModel`. The supports' air springs are given the
    preload that holds the home pose against gravity with zero actuator force (solved by
    least squares on the static balance, see :func:`mjcf.analysis.support_preloads`),
    and the linearised air-spring stiffness n p A^2 / V at that preload.
    """
    from mjcf.analysis import support_preloads
    from mjcf.model import TableModel

    spec, info = build_spec(desc, payload, options, effects=effects)
    model = spec.compile()
    if desc.supports is not None:
        sp = desc.supports
        loads = support_preloads(model, desc)
        if np.any(loads <= 0):
            raise DescriptionError(
                f"{desc.source}: a static support would have to pull (loads {np.round(loads / 1e3, 1).tolist()} kN); "
                "move the payload's centre of gravity inside the supports"
            )
        total = loads.sum() / desc.gravity_m_s2
        if total > sp.capacity_kg:
            raise DescriptionError(
                f"the static supports would carry {total / 1000:.1f} t but their capacity is "
                f"{sp.capacity_kg / 1000:.1f} t; use a lighter payload" + _rated(desc.limits.max_specimen_kg)
            )
        for i, f in enumerate(loads, start=1):
            j = spec.joint(f"S{i}_air")
            # the air's linear stiffness, on top of any an effect put there (a spring at
            # 'supports'); the spring reference keeps the preload at home
            k = air_spring_stiffness(sp, f) + float(j.stiffness[0])
            j.stiffness = [k, 0, 0]
            j.springref = f / k
        info.support_loads_n = loads
        if sp.air_law == "polytropic":
            info.air_joints = [f"S{i}_air" for i in range(1, len(loads) + 1)]
    if desc.foundation.mode == "spring":
        # The foundation spring carries the whole weight at home.
        jz = spec.joint("foundation_z")
        jz.springref = float(model.body_mass.sum()) * desc.gravity_m_s2 / jz.stiffness[0]
    if isinstance(payload, RigidPayload) and payload.clamp_frequency_hz is not None:
        jz = spec.joint("payload_clamp_z")
        jz.springref = payload.clamp_mass_fraction * payload.mass_kg * desc.gravity_m_s2 / jz.stiffness[0]
    if desc.friction_model == "presliding":
        # Dry friction leaves MuJoCo's frictionloss (a stiff stick constraint) and is applied
        # by the loop as a pre-sliding (Dahl/LuGre-type) force; see sim/loop/simulation.py.
        for j in spec.joints:
            if j.frictionloss > 0:
                info.friction_joints.append(j.name)
                info.friction_force_n.append(float(j.frictionloss))
                j.frictionloss = 0.0
    key = spec.add_key(name="home")
    key.qpos = model.qpos0.tolist()
    model = spec.compile()
    return TableModel(desc=desc, payload=payload, spec=spec, model=model, info=info)


def write_xml(tm, out_dir: str | Path) -> tuple[Path, Path]:
    """Write ``table.xml`` (the compiled spec) and ``scene.xml`` (includes the table).

    Both open in MuJoCo's own viewer (``python -m mujoco.viewer --mjcf scene.xml``).
    """
    from mjcf.errors import write_text_replacing

    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
        table_xml = out / "table.xml"
        scene_xml = out / "scene.xml"
        xml = tm.spec.to_xml()
        write_text_replacing(table_xml, xml)
        root = ET.Element("mujoco", model=f"{tm.desc.name} scene")
        ET.SubElement(root, "include", file="table.xml")
        vis = ET.SubElement(root, "visual")
        ET.SubElement(vis, "global", azimuth="135", elevation="-25")
        ET.SubElement(vis, "headlight", diffuse="0.6 0.6 0.6", ambient="0.3 0.3 0.3")
        wb = ET.SubElement(root, "worldbody")
        ET.SubElement(
            wb,
            "geom",
            name="ground",
            type="plane",
            pos="0 0 -3.5",
            size="20 20 0.1",
            rgba="0.3 0.32 0.35 1",
            contype="0",
            conaffinity="0",
        )
        ET.SubElement(wb, "camera", name="overview", pos="14 -14 9", xyaxes="0.707 0.707 0 -0.3 0.3 0.9")
        ET.indent(root)
        write_text_replacing(scene_xml, ET.tostring(root, encoding="unicode"))
    except OSError as e:
        raise DescriptionError(
            f"cannot write the scene to {out}: {e.strerror}; choose a writable --xml folder"
        ) from None
    return table_xml, scene_xml


def _rated(max_specimen_kg) -> str:
    """`` (max specimen X t)`` of a table that rates its specimens, else nothing."""
    return "" if max_specimen_kg is None else f" (max specimen {max_specimen_kg / 1000:.0f} t)"


__all__ = ["BuildOptions", "build", "build_spec", "write_xml", "payload_mass"]
