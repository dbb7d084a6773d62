"""The effect mechanism and the mechanical library, planted and checked against closed
forms: each effect is built into a model and the physics it adds is measured (free
vibration, effective mass, the force at a known state, static deflection)."""

import copy
import math
import shutil
import textwrap
from pathlib import Path

import mujoco
import numpy as np
import pytest

import mjcf
from mjcf.analysis import linear_modes
from mjcf.description import parse_table
from mjcf.stepping import stepped_mode
from sim.effects import EFFECTS, build_model, create, table_parameters, with_parameter_values
from sim.effects.mechanical import CoulombFriction, dof_jacobian
from sim.errors import ScenarioError

M_UCSD = 144e3  # tests/papers/test_ucsd.py: the LHPOST's effective mass [Ozcelik 2008]


@pytest.fixture(scope="module")
def ucsd_desc():
    return mjcf.load_table("ucsd")


def _with_effects(desc, effects, **raw_changes):
    raw = copy.deepcopy(desc.raw)
    raw["effect"] = list(effects)
    for sec, vals in raw_changes.items():
        raw[sec].update(vals)
    return parse_table(raw, desc.source)


def _bound(tm):
    for e in tm.effects:
        e.bind(tm.model, None)
    return tm.new_data()


def _free_run(tm, d, seconds, record):
    """MuJoCo alone (no hydraulics, zero actuator force): ``record(d)`` every step."""
    n = int(round(seconds / tm.model.opt.timestep))
    out = np.zeros(n)
    for k in range(n):
        d.qfrc_applied[:] = 0.0
        for e in tm.step_effects:
            e.apply(tm.model, d)
        mujoco.mj_step(tm.model, d)
        out[k] = record(d)
    return out


def _frequency_and_damping(y, dt):
    """Frequency (Hz, from upward zero crossings) and damping ratio (log decrement of the peaks)."""
    s = np.sign(y)
    up = np.where((s[:-1] < 0) & (s[1:] >= 0))[0]
    tc = (up + y[up] / (y[up] - y[up + 1])) * dt  # linear interpolation of the crossing
    f = 1.0 / np.mean(np.diff(tc))
    peaks = [np.max(np.abs(y[a:b])) for a, b in zip(up[:-1], up[1:])]
    delta = np.mean(np.log(np.array(peaks[:-1]) / np.array(peaks[1:])))
    return f, delta / math.sqrt(4 * math.pi**2 + delta**2)


# ----------------------------------------------------------------------------- springs, dampers
def test_spring_and_viscous_damping_on_a_bearing_slide_free_vibration(ucsd_desc):
    """UCSD platen on its x bearing (no other effect, no hydraulic force): the platen and
    the rods it carries (M_e = 144 t) on a spring k with a damper c vibrate at
    sqrt(k / M_e) sqrt(1 - zeta^2) with zeta = c / (2 sqrt(k M_e))."""
    k, zeta = 8.0e6, 0.05
    c = 2 * zeta * math.sqrt(k * M_UCSD)
    tm = build_model(
        _with_effects(
            ucsd_desc,
            [
                {"type": "spring", "where": "dof:x", "stiffness_n_m": k},
                {"type": "viscous_damping", "where": "dof:x", "damping_n_s_m": c},
            ],
        )
    )
    assert tm.effective_mass()["x"] == pytest.approx(M_UCSD, rel=1e-6)
    assert tm.step_effects == []  # both are MuJoCo joint parameters: no per-step work
    d = tm.new_data()
    tm.set_platen_pose(d, [5e-3, 0, 0, 0, 0, 0])
    x = _free_run(tm, d, 3.0, lambda d: d.qpos[tm.platen_qadr])
    f, z = _frequency_and_damping(x, tm.model.opt.timestep)
    f0 = math.sqrt(k / M_UCSD) / (2 * math.pi)
    assert f == pytest.approx(f0 * math.sqrt(1 - zeta**2), rel=5e-3)
    assert z == pytest.approx(zeta, rel=0.03)


def test_dof_effects_on_a_free_platen_act_on_that_dof_alone(cgs):
    """CGS (free platen): spring, damper and added mass at dof:<d> become a tendon over the
    actuator strokes whose length is the platen's DOF; through the linkages they give the
    platen k x_d, c v_d and m on DOF d and nothing on the others."""
    k, kr, c, m = 3.0e7, 4.0e8, 2.0e5, 5.0e3
    desc = _with_effects(
        cgs.desc,
        [
            {"type": "spring", "where": "dof:x", "stiffness_n_m": k},
            {"type": "spring", "where": "dof:rz", "stiffness_n_m": kr},
            {"type": "viscous_damping", "where": "dof:y", "damping_n_s_m": c},
            {"type": "added_mass", "where": "dof:z", "mass_kg": m},
        ],
    )
    tm = build_model(desc)
    assert tm.step_effects == []
    mdl = tm.model
    J = dof_jacobian(desc)
    pose = np.array([1e-3, -2e-3, 1e-3, 0.5e-3, -0.3e-3, 0.8e-3])
    d = tm.new_data()
    tm.set_platen_pose(d, pose)
    for name, i in (("dof_x", 0), ("dof_rz", 5)):
        assert d.ten_length[mdl.tendon(name).id] == pytest.approx(pose[i], rel=2e-3)
    # the wrench on the platen of the spring forces on the strokes: J^T f
    wrench = J.T @ d.qfrc_spring[tm.stroke_dadr]
    assert wrench[0] == pytest.approx(-k * pose[0], rel=2e-3)
    assert wrench[5] == pytest.approx(-kr * pose[5], rel=2e-3)
    assert np.all(np.abs(wrench[1:5]) < 2e-3 * max(k * abs(pose[0]), kr * abs(pose[5])))
    # damper: a velocity along y only, the strokes following (J v)
    d = tm.new_data()
    v = np.array([0, 0.2, 0, 0, 0, 0])
    d.qvel[tm.platen_dadr : tm.platen_dadr + 6] = v
    d.qvel[tm.stroke_dadr] = J @ v
    mujoco.mj_forward(mdl, d)
    base = build_model(cgs.desc)
    d0 = base.new_data()
    d0.qvel[:] = d.qvel
    mujoco.mj_forward(base.model, d0)
    w = J.T @ (d.qfrc_damper - d0.qfrc_damper)[tm.stroke_dadr]  # the seals' own drag taken off
    assert w[1] == pytest.approx(-c * 0.2, rel=1e-6)
    assert np.abs(w[[0, 2, 3, 4, 5]]).max() < 1e-6 * c * 0.2
    # added mass: m on z, nothing elsewhere
    dM = tm.effective_mass_matrix() - base.effective_mass_matrix()
    assert dM[2, 2] == pytest.approx(m, rel=1e-6)
    dM[2, 2] = 0.0
    assert np.abs(dM).max() < 1e-6 * m


def test_the_cgs_default_table_has_no_effect_work(cgs):
    """No effect, no tendon, no per-step effect: the fused compiled tick stays on."""
    assert cgs.effects == [] and cgs.step_effects == [] and cgs.model.ntendon == 0


# ----------------------------------------------------------------------------- masses and modes
def test_added_mass_at_each_place(ucsd_desc, cgs):
    """UCSD: m at dof:x (slide armature), at actuator:E (stroke armature, along x), at the
    payload (a body on the platen) adds m to M_e, so the oil column falls by
    sqrt(M_e / (M_e + m)). CGS: a mass with inertia at 1 m from the reference point adds
    m to x, I_z + m r^2 to rz."""
    m = 7.2e3
    for where in ("dof:x", "actuator:E", "payload"):
        tm = build_model(_with_effects(ucsd_desc, [{"type": "added_mass", "where": where, "mass_kg": m}]))
        assert tm.effective_mass()["x"] == pytest.approx(M_UCSD + m, rel=1e-6), where
    beta = ucsd_desc.raw["fluid"]["bulk_modulus_pa"]
    k_oil = sum(
        4 * beta * c.area_a_m2**2 / (2 * (c.dead_volume_a_m3 + c.area_a_m2 * c.half_stroke_m))
        for c in (a.cls for a in ucsd_desc.actuators)
    )
    f0, f1 = (math.sqrt(k_oil / M) / (2 * math.pi) for M in (M_UCSD, tm.effective_mass()["x"]))
    assert f1 / f0 == pytest.approx(math.sqrt(M_UCSD / (M_UCSD + m)), rel=1e-6)
    iz = 900.0
    tm = build_model(
        _with_effects(
            cgs.desc,
            [
                {
                    "type": "added_mass",
                    "where": "payload",
                    "mass_kg": 1000.0,
                    "inertia_x_kg_m2": 500.0,
                    "inertia_y_kg_m2": 500.0,
                    "inertia_z_kg_m2": iz,
                    "position_m": [1.0, 0.0, 0.0],
                }
            ],
        )
    )
    e0, e1 = cgs.effective_mass(), tm.effective_mass()
    assert e1["x"] - e0["x"] == pytest.approx(1000.0, rel=1e-6)
    assert e1["rz"] - e0["rz"] == pytest.approx(iz + 1000.0 * 1.0**2, rel=1e-6)


def test_payload_mode_frequency_and_damping(ucsd_desc):
    """A mode (f, m, zeta) on the UCSD platen: on a held platen it is f as stepped
    (mjcf.stepping); on the free
    platen (M_e) the relative motion oscillates at f sqrt((M + m) / M) with damping
    zeta sqrt((M + m) / M) (two bodies, one spring-damper)."""
    f, m, zeta = 4.0, 14.4e3, 0.02
    tm = build_model(
        _with_effects(
            ucsd_desc,
            [
                {
                    "type": "payload_mode",
                    "where": "dof:x",
                    "frequency_hz": f,
                    "mass_kg": m,
                    "damping_ratio": zeta,
                    "position_m": [0, 0, 1.5],
                }
            ],
        )
    )
    j = tm.model.joint("payload_mode_x1_slide")
    fr, _ = linear_modes(tm.model, np.array([j.dofadr[0]]))
    zr = float(tm.model.dof_damping[j.dofadr[0]]) / (2 * m * 2 * math.pi * fr[0])
    assert stepped_mode(fr[0], zr, tm.model.opt.timestep) == (pytest.approx(f, rel=1e-6), pytest.approx(zeta, rel=1e-6))
    assert tm.effective_mass()["x"] == pytest.approx(M_UCSD + m, rel=1e-6)  # rigid below the mode
    d = tm.new_data()
    q = j.qposadr[0]
    d.qpos[q] = 1e-3
    y = _free_run(tm, d, 2.0, lambda d: d.qpos[q])
    fm, zm = _frequency_and_damping(y, tm.model.opt.timestep)
    r = math.sqrt((M_UCSD + m) / M_UCSD)
    assert fm == pytest.approx(f * r * math.sqrt(1 - (zeta * r) ** 2), rel=5e-3)
    assert zm == pytest.approx(zeta * r, rel=0.05)


def test_vertical_payload_mode_starts_in_equilibrium(cgs):
    tm = build_model(
        _with_effects(
            cgs.desc,
            [{"type": "payload_mode", "where": "dof:z", "frequency_hz": 8.0, "mass_kg": 2000.0, "damping_ratio": 0.03}],
        )
    )
    d = tm.new_data()
    j = tm.model.joint("payload_mode_z1_slide")
    # the spring carries the mode's weight: its absolute acceleration (relative + the
    # platen's; the bare table's home is not exactly static either) is zero
    assert abs(d.qacc[j.dofadr[0]] + d.qacc[tm.platen_dadr + 2]) < 1e-9 * 9.81
    # the supports carry the mode's weight too
    assert tm.info.support_loads_n.sum() - cgs.info.support_loads_n.sum() == pytest.approx(2000.0 * 9.81, rel=1e-6)


def test_payload_mode_from_payload_is_the_clamped_block():
    """``from_payload``: 60 % of a declared 1.5 t rigid block moved onto a 6 Hz mode along
    x (on the lab table) is mjcf.builder's clamped block (``clamp_mass_fraction`` 0.6) as
    far as x goes: the same total mass, the same mass matrix along the platen's x and
    the mode's, the same spring; more mass than the payload has is one line."""
    from mjcf.description import parse_payload

    block = {
        "type": "rigid",
        "name": "b",
        "mass_kg": 1500.0,
        "com_m": [0.0, 0.0, 0.3],
        "inertia_kg_m2": [200.0, 200.0, 300.0],
        "footprint_m": [1.0, 1.0],
        "height_m": 0.6,
    }
    lab = mjcf.load_table("lab")
    rigid = parse_payload({"payload": block})
    clamp = parse_payload({"payload": {**block, "clamp_frequency_hz": 6.0, "clamp_mass_fraction": 0.6}})
    mode = {"type": "payload_mode", "where": "dof:x", "from_payload": True, "frequency_hz": 6.0}
    tm = build_model(_with_effects(lab, [{**mode, "mass_kg": 900.0, "damping_ratio": 0.02}]), rigid)
    ref = build_model(lab, clamp)
    assert sum(tm.model.body_mass) == pytest.approx(sum(ref.model.body_mass), rel=1e-12)
    j, jr = tm.model.joint("payload_mode_shared1_x"), ref.model.joint("payload_clamp_x")
    assert tm.model.jnt_stiffness[j.id] == pytest.approx(ref.model.jnt_stiffness[jr.id], rel=1e-12)
    assert tm.model.body_pos[tm.model.body("payload_mode_shared1").id][2] == pytest.approx(0.3)

    def mass_x(m, d_mode):
        d = mujoco.MjData(m)
        mujoco.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        k = [tm.platen_dadr, d_mode]
        return M[np.ix_(k, k)]

    assert mass_x(tm.model, j.dofadr[0]) == pytest.approx(mass_x(ref.model, jr.dofadr[0]), rel=1e-9)
    with pytest.raises(ScenarioError, match="from_payload"):
        build_model(_with_effects(lab, [{**mode, "mass_kg": 1600.0, "damping_ratio": 0.02}]), rigid)


def _mass_matrix(m) -> np.ndarray:
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    return M


def test_a_payloads_modes_along_x_y_and_z_share_its_mass():
    """``from_payload`` modes along x, y and z of 900 kg each (60 % of a 1.5 t block on the
    CGS table): one part of the payload on three slides, exactly mjcf.builder's block on its
    clamp (``clamp_mass_fraction`` 0.6): the same total mass and the same mass matrix over
    the platen's and the modes' coordinates. Separate bodies would have taken 2.7 t from
    1.5 t. Unequal modal masses (x 900, y 600 kg) take the larger from the payload and
    move 900 kg along x, 600 kg along y."""
    from mjcf.description import parse_payload
    from sim.effects.specimen import payload_taken

    block = {"type": "rigid", "name": "b", "mass_kg": 1500.0, "com_m": [0.0, 0.0, 0.3]}
    block.update(inertia_kg_m2=[200.0, 200.0, 300.0], footprint_m=[1.0, 1.0], height_m=0.6)
    cgs = mjcf.load_table("cgs")
    rigid = parse_payload({"payload": block})
    clamp = parse_payload({"payload": {**block, "clamp_frequency_hz": 6.0, "clamp_mass_fraction": 0.6}})
    modes = [
        {"type": "payload_mode", "where": f"dof:{d}", "from_payload": True, "frequency_hz": 6.0, "damping_ratio": 0.02}
        for d in "xyz"
    ]
    tm = build_model(_with_effects(cgs, [{**e, "mass_kg": 900.0} for e in modes]), rigid)
    ref = build_model(cgs, clamp)
    assert sum(tm.model.body_mass) == pytest.approx(sum(ref.model.body_mass), rel=1e-12)
    ours = list(range(tm.platen_dadr, tm.platen_dadr + 6)) + [
        tm.model.joint(f"payload_mode_shared3_{d}").dofadr[0] for d in "xyz"
    ]
    theirs = list(range(ref.platen_dadr, ref.platen_dadr + 6)) + [
        ref.model.joint(f"payload_clamp_{d}").dofadr[0] for d in "xyz"
    ]
    Mt, Mr = _mass_matrix(tm.model), _mass_matrix(ref.model)
    assert Mt[np.ix_(ours, ours)] == pytest.approx(Mr[np.ix_(theirs, theirs)], rel=1e-9, abs=1e-6)
    two = [{**modes[0], "mass_kg": 900.0}, {**modes[1], "mass_kg": 600.0}]
    tm2 = build_model(_with_effects(cgs, two), rigid)
    assert sum(tm2.model.body_mass) == pytest.approx(sum(tm.model.body_mass), rel=1e-12)
    M2 = _mass_matrix(tm2.model)
    for d, moving in (("x", 900.0), ("y", 600.0)):
        dofs = [j.dofadr[0] for j in (tm2.model.joint(n) for n in _slides(tm2.model, d))]
        assert sum(M2[k, k] for k in dofs) == pytest.approx(moving, rel=1e-9)
    assert payload_taken([("x", 900.0), ("y", 600.0), ("x", 100.0)]) == 1000.0


def _slides(m, d: str) -> list[str]:
    names = [m.joint(j).name for j in range(m.njnt)]
    return [n for n in names if n.startswith("payload_mode_shared") and n.endswith(f"_{d}")]


def test_cg_offset_moves_the_support_loads(cgs):
    """A 20 t block's centre of gravity moved by dx: the supports' moment about y grows by W dx."""
    payload = mjcf.load_payload("rigid_20t")
    dx = 0.3
    t0 = build_model(cgs.desc, payload)
    t1 = build_model(_with_effects(cgs.desc, [{"type": "cg_offset", "dx_m": dx}]), payload)
    xs = np.asarray(cgs.desc.supports.positions_m)[:, 0]
    W = payload.mass_kg * cgs.desc.gravity_m_s2
    # the supports and the vertical actuators (zero force at home) share it: check the moment
    # of the whole support set against the moment of the payload's weight
    m0, m1 = (xs @ t.info.support_loads_n for t in (t0, t1))
    assert m1 - m0 == pytest.approx(W * dx, rel=1e-3)
    assert t1.info.support_loads_n.sum() == pytest.approx(t0.info.support_loads_n.sum(), rel=1e-9)


def test_foundation_mode_on_a_fixed_foundation_is_the_spring_foundation(ucsd_desc):
    """foundation_mode on the (fixed-foundation) UCSD table builds the same model as
    [foundation] mode = "spring" with the same numbers, and the reaction mass with
    everything on it vibrates at sqrt(k / m_total) on a held table."""
    f, zeta, mf = 12.0, 0.05, 2.0e6
    raw = copy.deepcopy(ucsd_desc.raw)
    raw["foundation"].update(mode="spring", mass_kg=mf, frequency_hz=[f] * 3, damping_ratio=[zeta] * 3)
    ref = build_model(parse_table(raw, ucsd_desc.source))
    tm = build_model(
        _with_effects(ucsd_desc, [{"type": "foundation_mode", "frequency_hz": f, "mass_kg": mf, "damping_ratio": zeta}])
    )
    a, b = ref.model, tm.model
    assert (a.nbody, a.nv, a.neq, a.nu) == (b.nbody, b.nv, b.neq, b.nu)
    for name in ("foundation_x", "foundation_z"):
        for attr in ("jnt_stiffness", "dof_damping", "qpos_spring"):
            ja, jb = a.joint(name), b.joint(name)
            idx = {
                "jnt_stiffness": (ja.id, jb.id),
                "dof_damping": (ja.dofadr[0], jb.dofadr[0]),
                "qpos_spring": (ja.qposadr[0], jb.qposadr[0]),
            }[attr]
            assert getattr(b, attr)[idx[1]] == pytest.approx(getattr(a, attr)[idx[0]], rel=1e-12)
    assert tm.effective_mass()["x"] == pytest.approx(ref.effective_mass()["x"], rel=1e-12)
    fd = b.body("foundation").id
    fx, _ = linear_modes(b, np.array([b.joint("foundation_x").dofadr[0]]))
    assert fx[0] == pytest.approx(f * math.sqrt(mf / b.body_subtreemass[fd]), rel=1e-6)


# ----------------------------------------------------------------------------- friction, power damping
def test_coulomb_friction_sticks_and_slides(ucsd_desc):
    """Implicit friction on the UCSD bearing: a push below F_c leaves the platen at rest;
    above it the platen accelerates at (F - F_c) / M_e."""
    fc = 20e3
    tm = build_model(_with_effects(ucsd_desc, [{"type": "coulomb_friction", "where": "dof:x", "force_n": fc}]))
    assert tm.step_effects == [] and float(tm.model.joint("platen_x").frictionloss[0]) == fc
    for push, want in ((15e3, 0.0), (50e3, (50e3 - fc) / M_UCSD)):
        d = tm.new_data()
        t = 0.25
        for _ in range(int(t / tm.model.opt.timestep)):
            d.qfrc_applied[tm.platen_dadr] = push
            mujoco.mj_step(tm.model, d)
        v = d.qvel[tm.platen_dadr]
        assert v == pytest.approx(want * t, rel=0.01, abs=1e-4)


def test_friction_growing_with_a_constant_load_stays_implicit(ucsd_desc):
    """On a platen on bearings without z the weight it carries is constant: F_c = F0 + mu m g
    is the slide's frictionloss (no per-step work)."""
    f0, mu = 4.1e3, 0.0039
    tm = build_model(
        _with_effects(
            ucsd_desc,
            [{"type": "coulomb_friction", "where": "dof:x", "force_n": f0, "grows_with": "load", "coefficient": mu}],
        )
    )
    assert tm.step_effects == []
    w = ucsd_desc.platen.mass_kg * ucsd_desc.gravity_m_s2
    assert float(tm.model.joint("platen_x").frictionloss[0]) == pytest.approx(f0 + mu * w, rel=1e-12)


def test_per_step_friction_laws_give_their_force(ucsd_desc, cgs):
    """Forces at a known state: grows with displacement (F0 + c |x|), with the actuator's
    load (F0 + mu |F|), and a free platen's rz friction on a pre-sliding table reaches F_c
    after a travel of many delta, as a world torque about z through the rotated platen."""
    f0, cx, mu = 5e3, 2e5, 0.01
    tm = build_model(
        _with_effects(
            ucsd_desc,
            [
                {
                    "type": "coulomb_friction",
                    "where": "dof:x",
                    "force_n": f0,
                    "grows_with": "displacement",
                    "coefficient": cx,
                },
                {
                    "type": "coulomb_friction",
                    "where": "actuator:W",
                    "force_n": f0,
                    "grows_with": "load",
                    "coefficient": mu,
                },
            ],
        )
    )
    assert len(tm.step_effects) == 2
    d = _bound(tm)
    tm.set_platen_pose(d, [0.1, 0, 0, 0, 0, 0])
    d.qvel[tm.platen_dadr] = 0.5
    dw = tm.stroke_dadr[1]
    d.qvel[dw] = -0.5
    d.ctrl[tm.actuator_ids[1]] = 1.0e6
    d.qfrc_applied[:] = 0.0
    for e in tm.step_effects:
        e.apply(tm.model, d)
    assert d.qfrc_applied[tm.platen_dadr] == pytest.approx(-(f0 + cx * 0.1), rel=1e-6)
    assert d.qfrc_applied[dw] == pytest.approx(f0 + mu * 1.0e6, rel=1e-6)
    # CGS rz on its pre-sliding table
    fr = 40e3
    tc = build_model(_with_effects(cgs.desc, [{"type": "coulomb_friction", "where": "dof:rz", "force_n": fr}]))
    (e,) = tc.step_effects
    assert isinstance(e, CoulombFriction) and cgs.desc.friction_model == "presliding"
    d = _bound(tc)
    tc.set_platen_pose(d, [0, 0, 0, 0.02, -0.01, 0.01])
    R = d.xmat[tc.platen_body].reshape(3, 3)
    w = np.array([0, 0, 0.05])  # world angular velocity about z
    d.qvel[tc.platen_dadr + 3 : tc.platen_dadr + 6] = R.T @ w
    for _ in range(400):  # 0.05 rad/s x 0.2 s: 10 mrad, many times the 0.5 mm (mrad) travel
        d.qfrc_applied[:] = 0.0
        e.apply(tc.model, d)
    torque = R @ d.qfrc_applied[tc.platen_dadr + 3 : tc.platen_dadr + 6]
    assert torque == pytest.approx([0, 0, -fr], rel=1e-6, abs=1e-6 * fr)


def test_one_slide_fast_path_is_the_general_law(ucsd_desc):
    """On one slide the per-step friction and power damping run scalar code every step;
    over a velocity history it gives the general (array) law's forces to round-off."""
    tm = build_model(
        _with_effects(
            ucsd_desc,
            [
                {"type": "coulomb_friction", "where": "dof:x", "force_n": 26.65e3, "presliding_m": 0.4e-3},
                {"type": "power_damping", "where": "dof:x", "coefficient": 45.9e3, "exponent": 0.5},
            ],
        )
    )
    fr, pw = tm.step_effects
    d = _bound(tm)
    ref = CoulombFriction({"where": "dof:x", "force_n": 26.65e3, "presliding_m": 0.4e-3})
    dt = tm.model.opt.timestep
    rng = np.random.default_rng(1)
    for v in np.concatenate([rng.normal(0, 2e-3, 300), [0.0, 0.0], rng.normal(0, 0.3, 300)]):
        d.qvel[tm.platen_dadr] = v
        d.qfrc_applied[:] = 0.0
        fr.apply(tm.model, d)
        assert d.qfrc_applied[tm.platen_dadr] == pytest.approx(ref.advance(v, dt), rel=1e-12, abs=1e-9)
        d.qfrc_applied[:] = 0.0
        pw.apply(tm.model, d)
        assert d.qfrc_applied[tm.platen_dadr] == pytest.approx(float(pw.force(v)), rel=1e-12, abs=1e-12)


def test_power_damping_force(ucsd_desc, cgs):
    """C |v|^alpha against the motion at a known velocity (linear below v0), on a slide and
    on a rotated free platen's rz."""
    C, a = 45.9e3, 0.5
    tm = build_model(
        _with_effects(ucsd_desc, [{"type": "power_damping", "where": "dof:x", "coefficient": C, "exponent": a}])
    )
    (e,) = tm.step_effects
    d = _bound(tm)
    for v, want in ((0.3, -C * 0.3**a), (-2e-4, -C * 1e-3**a * (-2e-4 / 1e-3))):
        d.qvel[tm.platen_dadr] = v
        d.qfrc_applied[:] = 0.0
        e.apply(tm.model, d)
        assert d.qfrc_applied[tm.platen_dadr] == pytest.approx(want, rel=1e-9)
    tc = build_model(
        _with_effects(cgs.desc, [{"type": "power_damping", "where": "dof:rz", "coefficient": C, "exponent": 1.5}])
    )
    (e,) = tc.step_effects
    d = _bound(tc)
    tc.set_platen_pose(d, [0, 0, 0, 0.03, 0.02, 0.0])
    R = d.xmat[tc.platen_body].reshape(3, 3)
    d.qvel[tc.platen_dadr + 3 : tc.platen_dadr + 6] = R.T @ np.array([0, 0, -0.2])
    e.apply(tc.model, d)
    torque = R @ d.qfrc_applied[tc.platen_dadr + 3 : tc.platen_dadr + 6]
    assert torque == pytest.approx([0, 0, C * 0.2**1.5], rel=1e-9, abs=1e-9 * C)


def test_old_names_build_the_same_model_as_the_new(ucsd_desc):
    """ucsd.toml's platen_spring / platen_coulomb / platen_power_damping (``dof`` key) are
    the library's spring / coulomb_friction / power_damping at dof:x."""
    old = build_model(ucsd_desc)
    new = build_model(
        _with_effects(
            ucsd_desc,
            [
                {"type": "spring", "where": "dof:x", "stiffness_n_m": 1.263e6},
                {"type": "coulomb_friction", "where": "dof:x", "force_n": 26650.0},
                {"type": "power_damping", "where": "dof:x", "coefficient": 45900.0, "exponent": 0.5},
            ],
        )
    )
    for attr in ("jnt_stiffness", "dof_frictionloss", "dof_damping", "dof_armature"):
        assert np.array_equal(getattr(old.model, attr), getattr(new.model, attr)), attr
    assert [type(e).__mro__[1] for e in old.step_effects] == [type(e) for e in new.step_effects]


# ----------------------------------------------------------------------------- a user's own effect
USER_FILE = '''
import mujoco
from sim.effects import Effect


class Pickup(Effect):
    """A constant push on a platen slide, counting its lifecycle calls."""

    type = "pickup"
    places = ("dof",)
    per_step = True
    SPEC = {"force_n": ("N", -1e9, 1e9, None)}
    calls = {"bind": 0, "reset": 0, "apply": 0}

    def bind(self, model, hydraulics=None):
        j = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, "platen_" + self.where.split(":")[1])
        self.d = model.jnt_dofadr[j]
        Pickup.calls["bind"] += 1

    def reset(self):
        Pickup.calls["reset"] += 1

    def apply(self, model, data):
        data.qfrc_applied[self.d] += self.values["force_n"]
        Pickup.calls["apply"] += 1


class NotAnEffect:
    pass
'''


def _user_table(tmp_path, entry: str) -> Path:
    shutil.copy(mjcf.description.TABLES_DIR / "ucsd.toml", tmp_path / "table.toml")
    with open(tmp_path / "table.toml", "a") as f:
        f.write("\n[[effect]]\n" + textwrap.dedent(entry))
    return tmp_path / "table.toml"


def test_user_effect_is_loaded_and_applied(tmp_path):
    from sim.loop.simulation import Simulation

    (tmp_path / "my_effects.py").write_text(USER_FILE)
    desc = mjcf.load_table(_user_table(tmp_path, 'type = "my_effects.py:Pickup"\nwhere = "dof:x"\nforce_n = 1234.0\n'))
    tm = build_model(desc)
    (e,) = [e for e in tm.step_effects if type(e).__name__ == "Pickup"]
    assert EFFECTS["my_effects.py:Pickup"] is type(e)
    assert e.entry() == {"type": "my_effects.py:Pickup", "where": "dof:x", "force_n": 1234.0}  # writes back
    d = _bound(tm)
    d.qfrc_applied[:] = 0.0
    e.apply(tm.model, d)
    assert d.qfrc_applied[tm.platen_dadr] == 1234.0
    calls = type(e).calls
    before = dict(calls)
    sim = Simulation(tm)  # the loop binds and resets it, then applies it every physics step
    res = sim.run(valve_command=np.zeros((16, 2)))
    assert calls["bind"] == before["bind"] + 1 and calls["reset"] >= before["reset"] + 1
    assert calls["apply"] - before["apply"] == 16 * sim.steps_per_tick
    assert res.incomplete_reason is None


@pytest.mark.parametrize(
    "entry, words",
    [
        ('type = "nofile.py:Pickup"\nwhere = "dof:x"\n', ["no file", "nofile.py"]),
        ('type = "my_effects.py:NotAnEffect"\nwhere = "dof:x"\n', ["is not an Effect", "Pickup"]),
        ('type = "broken.py:Pickup"\nwhere = "dof:x"\n', ["does not load", "SyntaxError"]),
    ],
)
def test_user_effect_errors_are_one_line(tmp_path, entry, words):
    (tmp_path / "my_effects.py").write_text(USER_FILE)
    (tmp_path / "broken.py").write_text("def f(:\n")
    desc = mjcf.load_table(_user_table(tmp_path, entry))
    with pytest.raises(ScenarioError) as ei:
        build_model(desc)
    msg = str(ei.value)
    assert "\n" not in msg and all(w in msg for w in words), msg


# ----------------------------------------------------------------------------- errors
@pytest.mark.parametrize(
    "entry, suggestion",
    [
        ({"type": "spring", "where": "dof:x", "stifness_n_m": 1.0}, "stiffness_n_m"),  # unknown key
        ({"type": "sprng", "where": "dof:x", "stiffness_n_m": 1.0}, "spring"),  # unknown type
        ({"type": "spring", "where": "dofs:x", "stiffness_n_m": 1.0}, "dof"),  # not a place
        ({"type": "spring", "where": "dof:xx", "stiffness_n_m": 1.0}, "x"),  # no such DOF
        ({"type": "spring", "where": "actuator:EE", "stiffness_n_m": 1.0}, "E"),  # no such actuator
        ({"type": "coulomb_friction", "where": "dof:x", "force_n": 1.0, "grows_with": "lode"}, "load"),
        ({"type": "cg_offset", "where": "payloads"}, "payload"),
    ],
)
def test_errors_are_one_line_with_a_suggestion(ucsd_desc, entry, suggestion):
    with pytest.raises(ScenarioError) as ei:
        build_model(_with_effects(ucsd_desc, [entry]))
    msg = str(ei.value)
    assert "\n" not in msg and f"did you mean '{suggestion}'?" in msg, msg


def test_wrong_place_kind_and_impossible_inertia_are_refused():
    with pytest.raises(ScenarioError, match="acts at dof"):
        create({"type": "payload_mode", "where": "payload", "frequency_hz": 3.0, "mass_kg": 1.0, "damping_ratio": 0.02})
    with pytest.raises(ScenarioError, match="not the principal moments of a body"):
        create({"type": "added_mass", "where": "payload", "mass_kg": 1.0, "inertia_z_kg_m2": 1.0})


# ----------------------------------------------------------------------------- table parameters
def test_table_parameters_round_trip(ucsd_desc, cgs):
    ps = {p.name: p for p in table_parameters(cgs.desc)}
    for cls in cgs.desc.actuator_classes:
        for key in ("dead_volume_a_m3", "leakage_cross_m3_s_pa", "seal_friction_n", "rod_mass_kg"):
            p = ps[f"actuator_class.{cls}.{key}"]
            assert p.where == f"class:{cls}" and p.lower <= p.value <= p.upper
    for name in (
        "fluid.bulk_modulus_pa",
        "supports.piston_friction_n",
        "supports.shoe_friction_n",
        "supports.polytropic_exponent",
        "platen.mass_kg",
        "platen.inertia_kg_m2[2]",
        "friction.presliding_m",
    ):
        assert name in ps
    new = with_parameter_values(
        cgs.desc,
        {"fluid.bulk_modulus_pa": 1.3e9, "platen.mass_kg": 45e3, "actuator_class.vertical.seal_friction_n": 8e3},
    )
    assert new.raw["fluid"]["bulk_modulus_pa"] == 1.3e9 and new.platen.mass_kg == 45e3
    assert new.actuator_classes["vertical"].seal_friction_n == 8e3
    assert cgs.desc.raw["fluid"]["bulk_modulus_pa"] == 1.0e9  # the original is untouched
    # an effect's parameter, through the build
    uk = {p.name: p for p in table_parameters(ucsd_desc)}["effect[0].stiffness_n_m"]
    assert uk.value == 1.263e6 and uk.where == "dof:x"
    tm = build_model(with_parameter_values(ucsd_desc, {"effect[0].stiffness_n_m": 2.0e6}))
    assert float(tm.model.joint("platen_x").stiffness[0]) == 2.0e6
    with pytest.raises(ScenarioError, match="did you mean 'fluid.bulk_modulus_pa'"):
        with_parameter_values(cgs.desc, {"fluid.bulk_modulus": 1e9})
    with pytest.raises(ScenarioError, match="outside its bounds"):
        with_parameter_values(cgs.desc, {"supports.polytropic_exponent": 1.6})


def test_the_analog_loop_runs_the_effect_lifecycle(tmp_path):
    """The one loop with the Rice table's analog controller binds, resets and applies
    effects like with the digital one; the user's file is found next to the description."""
    from sim.loop.simulation import Simulation
    from sim.scenario.reference import Reference

    (tmp_path / "my_effects.py").write_text(USER_FILE)
    shutil.copy(mjcf.description.TABLES_DIR / "rice.toml", tmp_path / "rice.toml")
    with open(tmp_path / "rice.toml", "a") as f:
        f.write('\n[[effect]]\ntype = "my_effects.py:Pickup"\nwhere = "dof:x"\nforce_n = 10.0\n')
    sim = Simulation.for_table(mjcf.load_table(tmp_path / "rice.toml"))
    (e,) = sim.tm.step_effects
    calls = type(e).calls
    before = dict(calls)
    sim.reset()
    z = np.zeros((20, 6))  # 20 samples at the 4000 Hz recorder rate: 40 physics steps at 8000 Hz
    sim.run(reference=Reference(t=np.arange(20) / 4000.0, d=z, v=z, a=z))
    assert calls["reset"] == before["reset"] + 1 and calls["apply"] == before["apply"] + 40
    assert sim.d.qfrc_applied[sim.tm.platen_dadr] == 10.0


def test_effects_command_lists_the_library_and_a_tables_parameters(capsys, ucsd_desc):
    import json

    from sim.cli import main

    assert main(["effects"]) == 0
    out = capsys.readouterr().out
    for kind in (
        "spring",
        "viscous_damping",
        "power_damping",
        "coulomb_friction",
        "added_mass",
        "cg_offset",
        "payload_mode",
        "foundation_mode",
        "platen_spring",
    ):
        assert f"\n{kind}  [" in "\n" + out, kind
    assert main(["effects", str(mjcf.description.TABLES_DIR / "ucsd.toml"), "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert rows["effect[0].stiffness_n_m"]["value"] == 1.263e6 and rows["effect[0].stiffness_n_m"]["where"] == "dof:x"
    assert len(rows) == len(table_parameters(ucsd_desc))


def test_the_worked_example_of_docs_effects_md_runs(tmp_path):
    """The user effect of docs/effects.md, as printed there, loads and gives its force."""
    import re

    doc = (Path(__file__).resolve().parents[2] / "docs" / "effects.md").read_text()
    (tmp_path / "my_effects.py").write_text(re.findall(r"```python\n(.*?)```", doc, re.S)[0])
    entry = re.findall(r"```toml\n(.*?)```", doc, re.S)[-1]
    desc = mjcf.load_table(_user_table(tmp_path, entry.split("[[effect]]\n", 1)[1]))
    tm = build_model(desc)
    (e,) = [e for e in tm.step_effects if type(e).__name__ == "CableDrag"]
    d = _bound(tm)
    tm.set_platen_pose(d, [0.1, 0, 0, 0, 0, 0])
    d.qvel[tm.platen_dadr] = 1.0
    d.qfrc_applied[:] = 0.0
    e.apply(tm.model, d)
    assert d.qfrc_applied[tm.platen_dadr] == pytest.approx(-(800.0 + 2000.0 * 0.1) * math.tanh(1.0 / 0.01))


def test_free_platen_dof_friction_is_an_implicit_tendon_constraint(cgs):
    """CGS with Coulomb joint friction (no pre-sliding) and no other friction: a
    coulomb_friction at dof:x is the DOF tendon's frictionloss. Pushed along x for 0.25 s:
    below F_c the platen stays (creep < 1 um, the loops' compliance); at 2 F_c it moves
    as the frictionless platen under a push of F_c (x-pitch coupling included)."""
    raw = copy.deepcopy(cgs.desc.raw)
    raw["friction"]["model"] = "coulomb"
    for c in raw["actuator_class"].values():
        c["seal_friction_n"] = 0.0
    raw["supports"]["piston_friction_n"] = raw["supports"]["shoe_friction_n"] = 0.0
    bare = build_model(parse_table(raw, cgs.desc.source))
    raw["effect"] = [{"type": "coulomb_friction", "where": "dof:x", "force_n": 30e3}]
    tm = build_model(parse_table(raw, cgs.desc.source))
    assert tm.step_effects == [] and float(tm.model.tendon_frictionloss[tm.model.tendon("dof_x").id]) == 30e3

    def push(t, f):
        d = t.new_data()
        for _ in range(512):
            d.qfrc_applied[t.platen_dadr] = f
            mujoco.mj_step(t.model, d)
        return d.qpos[t.platen_qadr], d.qvel[t.platen_dadr]

    assert abs(push(tm, 15e3)[0]) < 1e-6
    assert push(tm, 60e3)[1] == pytest.approx(push(bare, 30e3)[1], rel=0.01)
