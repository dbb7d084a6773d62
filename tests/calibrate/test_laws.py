"""The mechanical path's force laws against the MuJoCo model they stand for.

``cg_offset``: the closed form of :func:`sim.calibrate.laws.cg_offset_force` against MuJoCo's
inverse dynamics of the CGS platen carrying the 20 t rigid block with its centre of gravity
planted off by ``R_OFF``, minus the declared one's, on a 6-DOF motion of the size the
calibration tests run.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

R_OFF = np.array([0.3, 0.2, 0.15])  #: m: a 20 t specimen's centre of gravity off by tens of cm


def _motion(n=400, seconds=2.0):
    """u, v, a (n, 6): a sine per DOF, amplitudes and frequencies of the calibration
    tests' harmonic run (tests/calibrate/test_cgs_mechanical.py), peak 1.6-3.9 m/s^2 (rad/s^2)."""
    amp = np.array([0.010, 0.008, 0.004, 0.003, 0.003, 0.004])
    f = np.array([3.0, 3.5, 4.5, 4.0, 5.0, 3.2])
    t = np.linspace(0.0, seconds, n)[:, None]
    w = 2 * np.pi * f
    ph = np.arange(6) * 0.7
    u = amp * np.sin(w * t + ph)
    v = amp * w * np.cos(w * t + ph)
    a = -amp * w**2 * np.sin(w * t + ph)
    return u, v, a


def _models(offset):
    import mjcf
    from mjcf.description import parse_table
    from sim.effects import build_model

    raw = copy.deepcopy(mjcf.load_table("cgs").raw)
    pl = mjcf.load_payload("rigid_20t")
    planted = copy.deepcopy(raw)
    planted["effect"] = list(planted.get("effect", [])) + [
        {"type": "cg_offset", "dx_m": offset[0], "dy_m": offset[1], "dz_m": offset[2]}
    ]
    return build_model(parse_table(raw, src="<declared>"), pl), build_model(parse_table(planted, src="<planted>"), pl)


def _platen_inverse(tm, u, v, a) -> np.ndarray:
    """(n, 6) force and moment (world axes, about the platen's reference point) MuJoCo's
    inverse dynamics needs on the platen's free joint for the motion, the linkages cut
    (equality constraints off: the platen and what it carries alone)."""
    import mujoco
    from scipy.spatial.transform import Rotation

    m = tm.model
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_EQUALITY) | int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    d = tm.new_data()
    j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "platen")
    pq, pd = int(m.jnt_qposadr[j]), int(m.jnt_dofadr[j])
    p0 = d.qpos[pq : pq + 3].copy()
    out = np.zeros((len(u), 6))
    for k in range(len(u)):
        R = Rotation.from_rotvec(u[k, 3:]).as_matrix()
        d.qpos[pq : pq + 3] = p0 + u[k, :3]
        d.qpos[pq + 3 : pq + 7] = Rotation.from_rotvec(u[k, 3:]).as_quat(scalar_first=True)
        d.qvel[:] = 0.0
        d.qacc[:] = 0.0
        d.qvel[pd : pd + 3], d.qvel[pd + 3 : pd + 6] = v[k, :3], R.T @ v[k, 3:]
        d.qacc[pd : pd + 3], d.qacc[pd + 3 : pd + 6] = a[k, :3], R.T @ a[k, 3:]
        mujoco.mj_inverse(m, d)
        f = d.qfrc_inverse[pd : pd + 6]
        out[k] = np.concatenate([f[:3], R @ f[3:]])  # the free joint's moment is in the platen frame
    return out


def test_cg_offset_closed_form_is_the_models_inverse_dynamics():
    """Planted minus declared inverse dynamics (static part removed, as the mechanical path
    does) is the closed form to < 1 % per DOF; without its second-order term (the law's
    linear part) the yaw moment misses by the offset's own parallel-axis inertia, and the
    law's three columns sum to that linear part."""
    from sim.calibrate.laws import LAWS, cg_offset_force
    from sim.calibrate.residuals import payload_inertial

    decl, plant = _models(R_OFF)
    m, c, g = payload_inertial(decl, decl.desc.gravity_m_s2)
    assert m == pytest.approx(20000.0) and c == pytest.approx([0.0, 0.0, 0.465])
    u, v, a = _motion()
    model = _platen_inverse(plant, u, v, a) - _platen_inverse(decl, u, v, a)
    model -= model.mean(axis=0)
    law = cg_offset_force(R_OFF, m, c, u, a, g)
    law -= law.mean(axis=0)
    err = np.linalg.norm(law - model, axis=0) / np.linalg.norm(model, axis=0)
    assert np.all(err < 0.01), err
    first = cg_offset_force(R_OFF, m, c, u, a, g, second_order=False)
    first -= first.mean(axis=0)
    err1 = np.linalg.norm(first - model, axis=0) / np.linalg.norm(model, axis=0)
    assert err1[5] > 5 * err[5], (err1, err)  # the parallel-axis term shows about z
    cols = LAWS["cg_offset"].basis(
        u, v, a, {"_dofs": ["x", "y", "z", "rx", "ry", "rz"], "_payload": (m, c, g), "_filt": lambda x: x}
    )
    assert cols.shape == (3, len(u), 6)
    np.testing.assert_allclose(
        np.tensordot(R_OFF, cols, axes=1), cg_offset_force(R_OFF, m, c, u, a, g, second_order=False)
    )


def test_cg_offset_inertial_part_is_the_effective_mass_change():
    """The declared model of the mechanical path (the effective mass at home, linkages
    closed): its change with the planted offset, times the acceleration, is the closed
    form's inertial part (first and second order in the offset) to 1e-9."""
    from sim.calibrate.laws import cg_offset_force
    from sim.calibrate.residuals import payload_inertial

    decl, plant = _models(R_OFF)
    m, c, g = payload_inertial(decl, decl.desc.gravity_m_s2)
    _, _, a = _motion(n=50)
    dM = plant.effective_mass_matrix() - decl.effective_mass_matrix()
    np.testing.assert_allclose(a @ dM.T, cg_offset_force(R_OFF, m, c, np.zeros_like(a), a, g), rtol=0, atol=1e-9 * m)


def test_cg_offset_fit_takes_the_second_order_to_a_fixed_point():
    """A residual that is exactly the closed form's force (first and second order) of
    ``R_OFF``: the fit finds the offset to 1e-9 and leaves nothing; the linear solve alone
    (the first-order law) is off by more than 1 mm (the parallel-axis term aliased)."""
    from sim.calibrate import trace
    from sim.calibrate.laws import LAWS, cg_offset_force
    from sim.calibrate.residuals import MechRun

    m, c, g = 20000.0, np.array([0.0, 0.0, 0.465]), 9.81
    u, v, a = _motion(n=1200, seconds=3.0)
    rng = np.random.default_rng(3)
    a = a + rng.normal(0.0, 0.5, a.shape)  # broadband, so that the columns are not collinear
    f = cg_offset_force(R_OFF, m, c, u, a, g)
    dofs = ["x", "y", "z", "rx", "ry", "rz"]
    mr = MechRun(
        name="planted",
        dt=1 / 400,
        dofs=dofs,
        u=u,
        v=v,
        a=a,
        force=f + 1e3 * a,  # a declared force the model explains (the weights see a force)
        model=1e3 * a,
        J=np.eye(6),
        actuators=dofs,
        classes={},
        rows=np.ones(len(u), bool),
        payload=(m, c, g),
    )
    fit = trace.fit_terms([mr], [trace.Term(LAWS["cg_offset"], "payload")])
    got = np.array([fit.values[0][k] for k in ("dx_m", "dy_m", "dz_m")])
    np.testing.assert_allclose(got, R_OFF, rtol=0, atol=1e-9)
    assert np.abs(fit.residuals[0]).max() < 1e-6 * np.abs(mr.residual).max()
    assert all(0 < s < 1e-6 for s in fit.sigma[0].values())
    y, X = trace._stack([mr], fit.terms)
    first, _ = trace._solve(y, X)
    assert np.abs(first - R_OFF).max() > 1e-3, first


def test_foundation_mode_named_on_the_mechanical_path_says_use_the_replay_path():
    """``--effects foundation_mode`` on the mechanical path: a one-line error naming the
    replay path (no law: see test_cgs_mechanical's foundation test for why)."""
    from sim.calibrate.residuals import CalibrationError
    from sim.calibrate.search import candidate_laws

    with pytest.raises(CalibrationError, match=r"foundation_mode.*not identifiable.*--path replay") as e:
        candidate_laws(["foundation_mode"])
    assert "\n" not in str(e.value)
    assert [w.type for w in candidate_laws(["cg_offset"])] == ["cg_offset"]


def test_payload_mode_at_the_cg_holds_the_weight_it_moves():
    """A declared payload's mode 1 m up, brought to a steady 1 m/s^2 along x: once it has
    settled (away from the record's end, where the interpolation rings), the mode lags by
    d / w^2 and the actuators hold no force but the moment of the weight it moved,
    m g d / w^2 about y (the P-delta the law carries); on the way, the moment is the
    force's at 1 m plus g times the lag, the drive through 1 / (s^2 + 2 z w s + w^2)
    (to 0.1 %)."""
    import scipy.signal as sig

    from sim.calibrate.laws import LAWS

    dt, f, z, g = 1.0 / 1024, 6.0, 0.5, 9.81
    w = 2.0 * np.pi * f
    n = 4096
    t = np.arange(n) * dt
    a = np.zeros((n, 6))
    a[:, 0] = np.where(t < 0.25, 0.5 - 0.5 * np.cos(np.pi * t / 0.25), 1.0)  # (smooth: no interpolation's ripple)
    s = {
        "_dt": dt,
        "frequency_hz": f,
        "damping_ratio": z,
        "_dofs": ["x", "y", "z", "rx", "ry", "rz"],
        "_payload": (20000.0, np.array([0.0, 0.0, 1.0]), g),
        "_along": "x",
        "_filt": lambda x: x,
    }
    cols = LAWS["payload_mode_from_payload"].basis(np.zeros_like(a), np.zeros_like(a), a, s)
    assert cols.shape == (n, 6)
    assert abs(cols[n // 2, 0]) < 1e-6 and np.all(np.abs(cols[:, [1, 2, 3, 5]]) < 1e-12)
    assert cols[n // 2, 4] == pytest.approx(g / w**2, rel=1e-4)  # (the pre-warp: w (pi f h)^2 / 3)
    _, lag, _ = sig.lsim(([1.0], [1.0, 2 * z * w, w * w]), a[:, 0], t)  # -x: the mode's lag behind the platen
    weight = cols[:, 4] - cols[:, 0] * 1.0  # the force's moment at 1 m taken out
    assert np.max(np.abs(weight - g * lag)[: n // 2]) < 1e-3 * g / w**2


#: the stepped clamp's base (kg): a platen's order of mass
BASE_KG = 30000.0


def _stepped_clamp_record(m: float, f: float, z: float, n: int = 6 * 2048):
    """A 30 t base on a slide carrying ``m`` on a clamp (``mjcf.stepping.mode_spring``)
    pushed by seeded 0.5-20 Hz force, stepped at the builder's step: (step, base
    acceleration, force on the base less the whole rigid mass's m a)."""
    import mujoco
    import scipy.signal as sig

    from mjcf.builder import BuildOptions
    from mjcf.stepping import mode_spring

    spec = mujoco.MjSpec()
    spec.option.timestep = h = BuildOptions().timestep_s
    spec.option.gravity = [0.0, 0.0, 0.0]
    base = spec.worldbody.add_body(name="base", mass=BASE_KG, inertia=[1.0, 1.0, 1.0])
    base.add_joint(type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0])
    block = base.add_body(name="block", mass=m, inertia=[1.0, 1.0, 1.0])
    k, c = mode_spring(spec, m, f, z)
    block.add_joint(type=mujoco.mjtJoint.mjJNT_SLIDE, axis=[1, 0, 0], stiffness=[k, 0, 0], damping=[c, 0, 0])
    model = spec.compile()
    d = mujoco.MjData(model)
    sos = sig.butter(4, [0.5, 20.0], btype="band", fs=1.0 / h, output="sos")
    force = sig.sosfilt(sos, np.random.default_rng(1).standard_normal(n)) * 4e5
    acc = np.zeros(n)
    for i in range(n):
        d.qfrc_applied[0] = force[i]
        mujoco.mj_step(model, d)
        acc[i] = d.qacc[0]
    return h, acc, force - (BASE_KG + m) * acc


def test_payload_mode_law_reads_the_stepped_clamp_at_its_declared_mode():
    """The mechanical path's mode law against MuJoCo's stepped clamp (one slide, the
    builder's step and integrator): at the declared 6 Hz, 5 % it reads the modal mass to
    0.01 % (12000.44 kg for 12000, measured); fitted free, the step's remaining bias shows
    as 5.99779 Hz and 12012 kg (measured: the simulated record's, not a real one's; the
    CGS block's frequency on raw runs reads the same 5.99771)."""
    from scipy.optimize import least_squares

    from sim.calibrate.laws import LAWS

    h, a, residual = _stepped_clamp_record(12000.0, 6.0, 0.05)

    def mass(f, z):
        col = LAWS["payload_mode"].basis(None, None, a, {"_dt": h, "frequency_hz": f, "damping_ratio": z}) - a
        return (col @ residual) / (col @ col), col

    m, _ = mass(6.0, 0.05)
    assert m == pytest.approx(12000.0, rel=1e-4)

    def misfit(p):
        mp, col = mass(*p)
        return residual - mp * col

    f, z = least_squares(misfit, [6.0, 0.05], x_scale=[1.0, 0.01]).x
    assert f == pytest.approx(6.0, rel=5e-4) and z == pytest.approx(0.05, rel=1e-3)
    assert mass(f, z)[0] == pytest.approx(12000.0, rel=2e-3)
