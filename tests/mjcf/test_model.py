"""The CGS table model: effective mass, kinematics, loop closure, equilibrium, payload modes."""

import dataclasses

import mujoco
import numpy as np
import pytest

import mjcf
from mjcf.analysis import linear_modes, projection
from mjcf.description import actuator_strokes, envelope_corners
from sim.effects import build_model

# Table 2 of [Airouche 2014] (bare-table effective masses).
TABLE2 = {"x": 48.85e3, "y": 49.36e3, "z": 52.50e3, "rx": 208e3, "ry": 217e3, "rz": 354e3}


@pytest.mark.parametrize("dof", list(TABLE2))
def test_rigid_body_effective_mass_matches_its_calibration_target(cgs, cgs_desc, dof):
    """diag(T^T M T) is Table 2 plus the recorded offset of the virtual tests (the
    parallel stiffness read as -K/w^2); the virtual tests themselves are held against
    Table 2 in test_characterize.py."""
    from mjcf.calibrate import mass_offset, mass_targets

    eff = cgs.effective_mass()
    assert eff[dof] == pytest.approx(mass_targets(cgs_desc)[dof], rel=1e-3), (dof, eff[dof])
    # the offset is a correction of a few per cent, not a free mass
    assert 0.0 <= mass_offset(cgs_desc)[dof] < 0.15 * TABLE2[dof]


def test_formula_calibration_is_a_fixed_point(cgs_desc):
    """`shaketable calibrate cgs` (the linear solve from Table 2 plus the recorded offset)
    gives back the masses written by `characterize --calibrate`: the two commands agree."""
    from mjcf.calibrate import calibrate_masses

    res = calibrate_masses(cgs_desc)
    assert res["values"]["platen.mass_kg"] == pytest.approx(cgs_desc.platen.mass_kg, rel=1e-3)
    for i in range(3):
        assert res["values"][f"platen.inertia_kg_m2[{i}]"] == pytest.approx(cgs_desc.platen.inertia_kg_m2[i], rel=1e-3)
    assert res["values"]["supports.piston_mass_kg"] == pytest.approx(cgs_desc.supports.piston_mass_kg, rel=1e-2)


def test_mass_offset_bad_input_is_one_line(cgs_desc):
    from mjcf.calibrate import mass_offset
    from mjcf.description import DescriptionError

    raw = dict(cgs_desc.raw, calibration={"effective_mass_offset": [1.0, 2.0, float("nan"), 0, 0, 0]})
    with pytest.raises(DescriptionError, match="6 finite numbers"):
        mass_offset(dataclasses.replace(cgs_desc, raw=raw))
    raw = dict(cgs_desc.raw, calibration={"offset": [0] * 6})
    with pytest.raises(DescriptionError, match="unknown key 'offset'"):
        mass_offset(dataclasses.replace(cgs_desc, raw=raw))


def test_vertical_excess_is_mass_that_moves_only_vertically(cgs, cgs_desc):
    """Support pistons follow z/rx/ry only: adding piston mass raises z, not x or y."""
    m, d = cgs.model, cgs.new_data()
    T = projection(m, d)
    for i in range(len(cgs_desc.supports.positions_m)):
        j = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"S{i + 1}_air")
        row = T[m.jnt_dofadr[j]]
        assert abs(row[0]) < 1e-12 and abs(row[1]) < 1e-12 and abs(row[5]) < 1e-12
        assert abs(row[2] - 1.0) < 1e-9
    dm = 500.0
    heavier = dataclasses.replace(
        cgs_desc, supports=dataclasses.replace(cgs_desc.supports, piston_mass_kg=cgs_desc.supports.piston_mass_kg + dm)
    )
    e0, e1 = cgs.effective_mass(), build_model(heavier).effective_mass()
    n = len(cgs_desc.supports.positions_m)
    assert abs(e1["z"] - e0["z"] - n * dm) < 1e-6 * e0["z"]
    assert abs(e1["x"] - e0["x"]) < 1e-6 * e0["x"]
    assert abs(e1["y"] - e0["y"]) < 1e-6 * e0["y"]
    # and the z excess over x is mostly piston mass
    assert e0["z"] - e0["x"] > 0.5 * n * cgs_desc.supports.piston_mass_kg


def test_inverse_kinematics_matches_mujoco_over_envelope(cgs, cgs_desc):
    rng = np.random.default_rng(0)
    half = np.concatenate([cgs_desc.limits.stroke_m, cgs_desc.limits.rotation_rad])
    poses = np.vstack([envelope_corners(cgs_desc), rng.uniform(-1, 1, (40, 6)) * half])
    d = cgs.new_data()
    worst = 0.0
    for pose in poses:
        res = cgs.set_platen_pose(d, pose)
        assert res < 1e-9
        worst = max(worst, np.abs(cgs.actuator_strokes(d) - actuator_strokes(cgs_desc, pose)).max())
        assert np.allclose(cgs.platen_pose(d), pose, atol=1e-12)
    assert worst < 1e-6, worst


def test_rated_strokes_fit_inside_every_actuator(cgs_desc):
    need = np.abs(actuator_strokes(cgs_desc, envelope_corners(cgs_desc))).max(axis=0)
    half = np.array([a.cls.half_stroke_m for a in cgs_desc.actuators])
    assert np.all(need < half)
    # the pure translations alone use the paper's strokes on the matching axis
    assert abs(need[0] - 0.25) < 0.07 and abs(need[4] - 0.15) < 0.08 and abs(need[8] - 0.10) < 0.11


def _consistent_velocity(tm, d, v6):
    T = projection(tm.model, d)
    d.qvel[:] = T @ v6


@pytest.mark.parametrize("dt", [0.0005, 1 / 2048])
def test_loop_closure_tight_when_driven_hard(cgs_desc, dt):
    """Forces giving 1 g horizontal and 0.8 g vertical: swivel gaps stay below 0.01 mm
    at a 0.5 ms step (and at the default 1/2048 s)."""
    from mjcf.builder import BuildOptions

    cgs = build_model(cgs_desc, options=BuildOptions(timestep_s=dt))
    m, d = cgs.model, cgs.new_data()
    eff = cgs.effective_mass()
    f = 5.0
    w = 2 * np.pi * f
    g = cgs_desc.gravity_m_s2
    amp = np.array([eff["x"] * g, eff["y"] * g, eff["z"] * 0.8 * g])
    # start with the velocity of the steady sinusoid, so the table oscillates about home
    _consistent_velocity(cgs, d, np.array([-g / w, 0.0, -0.8 * g / w, 0, 0, 0]))
    groups = [int(np.argmax(np.abs(a.axis))) for a in cgs_desc.actuators]
    signs = [float(np.sign(a.axis[k])) for a, k in zip(cgs_desc.actuators, groups)]
    gap = 0.0
    acc_peak = np.zeros(3)
    for _ in range(int(1.0 / m.opt.timestep)):
        t = d.time
        F = amp * np.array([np.sin(w * t), np.cos(w * t), np.sin(w * t)])
        d.ctrl[cgs.actuator_ids] = [F[k] / 4 * s for k, s in zip(groups, signs)]
        mujoco.mj_step(m, d)
        gap = max(gap, cgs.loop_gap(d))
        acc_peak = np.maximum(acc_peak, np.abs(d.qacc[cgs.platen_dadr : cgs.platen_dadr + 3]))
    assert acc_peak[0] > 0.9 * g and acc_peak[1] > 0.9 * g and acc_peak[2] > 0.7 * g
    assert np.abs(cgs.platen_pose(d)[:3]).max() < 0.1
    assert gap < 1e-5, gap
    assert not any(w.number for w in d.warning)


def test_static_supports_hold_dead_weight(cgs):
    m, d = cgs.model, cgs.new_data()
    p0 = cgs.platen_pose(d)
    worst = 0.0
    for i in range(int(10.0 / m.opt.timestep)):
        mujoco.mj_step(m, d)
        if i % 50 == 0:
            worst = max(worst, np.abs(cgs.platen_pose(d)[:3] - p0[:3]).max())
    assert worst < 1e-4, worst


def test_support_preload_equals_weight_share(cgs, cgs_desc):
    """Supports carry the platen and the vertical share of the linkages: < total weight."""
    loads = cgs.info.support_loads_n
    W = cgs.moving_mass() * cgs_desc.gravity_m_s2
    assert np.allclose(loads, loads[0])
    assert cgs_desc.platen.mass_kg * cgs_desc.gravity_m_s2 < loads.sum() < W


@pytest.mark.parametrize(
    "payload,published",
    [
        ("frame_3storey_297", [7.22, 21.58, 33.86]),
        ("frame_3storey_501", [5.53, 16.60, 26.15]),
    ],
)
def test_shear_frame_modes_match_K_M_eigenvalues(cgs_desc, payload, published):
    p = mjcf.load_payload(payload)
    tm = build_model(cgs_desc, p)
    f_model, _ = linear_modes(tm.model, tm.payload_dadr, gravity=True)
    w2 = np.sort(np.linalg.eigvals(np.linalg.solve(np.diag(p.mass_kg), p.stiffness_n_m)).real)
    f_exact = np.sqrt(w2) / (2 * np.pi)
    assert np.allclose(f_model, f_exact, rtol=1e-3)
    assert np.allclose(f_model, published, rtol=0.01), f_model


def test_cantilever_modes_match_beam_theory(cgs_desc):
    p = mjcf.load_payload("tower_6m")
    tm = build_model(cgs_desc, p)
    f, _ = linear_modes(tm.model, tm.payload_dadr, gravity=False)
    f = f[::2]  # each bending mode appears twice (x and y)
    EI, mu, L = p.bending_stiffness_n_m2, p.mass_per_length_kg_m, p.height_m
    beta_l = np.array([1.875104, 4.694091, 7.854757])
    f_beam = beta_l**2 / (2 * np.pi * L**2) * np.sqrt(EI / mu)
    assert abs(f[0] / f_beam[0] - 1) < 0.005, (f[:3], f_beam)
    assert abs(f[1] / f_beam[1] - 1) < 0.015
    assert abs(f[2] / f_beam[2] - 1) < 0.03
    # gravity (P-delta) softens the tower a little, never stiffens it
    fg, _ = linear_modes(tm.model, tm.payload_dadr, gravity=True)
    assert fg[0] <= f[0] + 1e-9


CLAMPED = (
    '[payload]\ntype = "rigid"\nname = "clamped"\nmass_kg = 5000.0\ncom_m = [0.5, 0.0, 0.5]\n'
    "inertia_kg_m2 = [800.0, 800.0, 800.0]\nfootprint_m = [1.5, 1.5]\nheight_m = 1.0\n"
    "clamp_frequency_hz = 52.0\n"
)
SCENES = [
    (None, "fixed"),
    ("rigid_20t", "fixed"),
    ("clamped", "fixed"),
    ("frame_3storey_297", "fixed"),
    ("frame_3storey_501", "fixed"),
    ("tower_6m", "fixed"),
    (None, "spring"),
    ("rigid_20t", "spring"),
]


@pytest.mark.parametrize("payload,foundation", SCENES)
def test_every_scene_compiles_and_steps_without_warnings(cgs_desc, payload, foundation, tmp_path):
    desc = cgs_desc
    if foundation == "spring":
        desc = dataclasses.replace(desc, foundation=dataclasses.replace(desc.foundation, mode="spring"))
    if payload == "clamped":
        import tomllib

        from mjcf.description import parse_payload

        pl = parse_payload(tomllib.loads(CLAMPED))
    else:
        pl = mjcf.load_payload(payload) if payload else None
    tm = build_model(desc, pl)
    d = tm.new_data()
    z0 = tm.platen_pose(d)[2]
    for _ in range(int(1.0 / tm.model.opt.timestep)):
        mujoco.mj_step(tm.model, d)
    assert not any(w.number for w in d.warning)
    assert np.all(np.isfinite(d.qpos))
    assert abs(tm.platen_pose(d)[2] - z0) < 1e-4
    # written XML reloads, with the home keyframe and the linkage classes
    _, scene = mjcf.write_xml(tm, tmp_path)
    m2 = mujoco.MjModel.from_xml_path(str(scene))
    assert m2.nkey == 1 and m2.nq == tm.model.nq
    text = (tmp_path / "table.xml").read_text()
    assert 'class="linkage_longitudinal"' in text or 'childclass="linkage_longitudinal"' in text
