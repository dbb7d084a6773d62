"""Geometric nonlinearity of a table: what a linear (small-motion) view of the table misses.

``shaketable geometry TABLE`` reports, over the rated motion envelope:

* **kinematic nonlinearity**: the largest difference between each actuator's exact
  stroke (inverse kinematics of the linkage geometry) and the linear estimate
  ``J(0) pose``; the second-order stroke a pure motion of one DOF induces in the
  actuators of the other axes (e.g. a lateral 150 mm moves the longitudinal actuators);
* **parasitic motion**: if a controller turned the DOF reference into actuator strokes
  with the linear map ``J(0)`` (as a small-motion DOF transformation does), the pose the
  table would really reach (forward kinematics of those strokes) differs from the
  reference; the report gives that error per DOF at the corners of each axis' stroke;
* **force transformation**: the change of the actuator-to-DOF force map ``J(q)^T`` over
  the envelope (how much of an actuator's force leaks into other DOFs at full stroke);
* **oil-column stiffness vs position**: chamber volumes change with the stroke, so the
  hydraulic stiffness ``J^T diag(beta (A_a^2/V_a + A_b^2/V_b)) J`` and the oil-column
  frequencies (with the model's effective mass) change across the envelope.
"""

from __future__ import annotations

import numpy as np

from mjcf.description import DOFS6, TableDescription, actuator_strokes, envelope_corners
from sim.control.tvc import dof_jacobian


def forward_kinematics(desc: TableDescription, strokes: np.ndarray, guess=None, tol=1e-12, max_iter=50):
    """Pose (6,) whose exact inverse kinematics gives ``strokes`` (Newton on the IK)."""
    dofs = [i for i, d in enumerate(DOFS6) if d in desc.dofs]
    pose = np.zeros(6) if guess is None else np.array(guess, float)
    for _ in range(max_iter):
        r = actuator_strokes(desc, pose) - strokes
        if np.abs(r).max() < tol:
            break
        J = dof_jacobian(desc, pose)[:, dofs]
        pose[dofs] -= np.linalg.lstsq(J, r, rcond=None)[0]
    return pose


def _axis_extremes(desc: TableDescription):
    half = np.concatenate([desc.limits.stroke_m, desc.limits.rotation_rad])
    for i, d in enumerate(DOFS6):
        if d not in desc.dofs or half[i] == 0:
            continue
        for s in (-1.0, 1.0):
            p = np.zeros(6)
            p[i] = s * half[i]
            yield d, p


def dof_stiffness(desc: TableDescription, hp, pose, dofs) -> np.ndarray:
    """The oil columns' stiffness in DOF space at ``pose``: J(q)^T diag(k(q)) J(q), with each
    actuator's chamber volumes at its stroke there, k = beta (A_a^2/V_a + A_b^2/V_b)."""
    x = actuator_strokes(desc, pose)
    va = hp.dead_volume_a_m3 + hp.area_a_m2 * (hp.half_stroke_m + x)
    vb = hp.dead_volume_b_m3 + hp.area_b_m2 * (hp.half_stroke_m - x)
    k = hp.bulk_modulus_pa * (hp.area_a_m2**2 / va + hp.area_b_m2**2 / vb)
    J = dof_jacobian(desc, pose)[:, dofs]
    return J.T @ np.diag(k) @ J


def study(desc: TableDescription, effective_mass: np.ndarray | None = None, hydraulics=None) -> dict:
    """The geometric-nonlinearity report (dict, SI units)."""
    names = list(desc.actuator_names)
    J0 = dof_jacobian(desc)
    corners = envelope_corners(desc)
    exact = actuator_strokes(desc, corners)
    lin = corners @ J0.T
    dev = np.abs(exact - lin)
    out = {
        "table": desc.name,
        "kinematic_nonlinearity_m": {n: float(v) for n, v in zip(names, dev.max(axis=0))},
        "worst_corner": corners[int(np.argmax(dev.max(axis=1)))].tolist(),
    }

    # cross-axis strokes from a pure motion of one DOF (second-order geometry)
    cross = {}
    for d, p in _axis_extremes(desc):
        s = actuator_strokes(desc, p)
        s_lin = J0 @ p
        cross.setdefault(d, {})
        for n, a, b in zip(names, s, s_lin):
            cross[d][n] = max(cross[d].get(n, 0.0), float(abs(a - b)))
    out["second_order_stroke_m"] = cross

    # parasitic motion with a linear DOF transformation
    par = {}
    for d, p in _axis_extremes(desc):
        reached = forward_kinematics(desc, J0 @ p, guess=p)
        err = reached - p
        key = f"{d}{'+' if p[DOFS6.index(d)] > 0 else '-'}"
        par[key] = {dd: float(e) for dd, e in zip(DOFS6, err) if dd in desc.dofs}
    out["parasitic_motion_linear_map"] = par

    # force map change over the envelope: largest change of any J entry (dimensionless / m)
    dJ = 0.0
    for p in corners:
        dJ = max(dJ, float(np.abs(dof_jacobian(desc, p) - J0)[:, :3].max()))
    out["force_map_change_max"] = dJ

    # oil-column frequencies at the centre and at the ends of each axis
    if effective_mass is not None and hydraulics is not None:
        hp = hydraulics
        dofs = [i for i, d in enumerate(DOFS6) if d in desc.dofs]
        M = effective_mass

        def freqs(pose):
            K = dof_stiffness(desc, hp, pose, dofs)
            w2 = np.linalg.eigvals(np.linalg.solve(M, K)).real
            return np.sort(np.sqrt(np.clip(w2, 0, None)) / (2 * np.pi))

        f0 = freqs(np.zeros(6))
        oc = {"centre": f0.tolist()}
        for d, p in _axis_extremes(desc):
            key = f"{d}{'+' if p[DOFS6.index(d)] > 0 else '-'}"
            oc[key] = freqs(p).tolist()
        out["oil_column_hz"] = oc
        spread = max(np.max(np.abs(np.array(v) / f0 - 1)) for v in oc.values())
        out["oil_column_max_relative_change"] = float(spread)
    return out


def print_report(r: dict) -> None:
    print(f"geometric nonlinearity of {r['table']} over the rated envelope")
    kn = r["kinematic_nonlinearity_m"]
    print(
        "  exact stroke - linear J(0) estimate, worst corner (mm): "
        + ", ".join(f"{n} {1e3 * v:.2f}" for n, v in kn.items())
    )
    print("  second-order strokes from one axis at full stroke (mm, largest actuator):")
    for d, m in r["second_order_stroke_m"].items():
        n, v = max(m.items(), key=lambda kv: kv[1])
        print(f"    {d:3s} -> {n} {1e3 * v:.2f}")
    print("  parasitic motion if the reference went through the linear map J(0):")
    for k, e in r["parasitic_motion_linear_map"].items():
        big = {d: v for d, v in e.items() if abs(v) > 1e-9}
        txt = (
            ", ".join(
                f"{d} {v * (1e3 if d in ('x', 'y', 'z') else 1e3):+.3f} {'mm' if d in ('x', 'y', 'z') else 'mrad'}"
                for d, v in big.items()
            )
            or "none"
        )
        print(f"    {k:4s}: {txt}")
    print(f"  actuator-to-DOF force map: largest entry change over the envelope {r['force_map_change_max']:.4f}")
    if "max_tilt_rad" in r:
        jc = r["jacobian_condition"]
        print(
            f"  over {r['n_poses']} poses of the rated envelope: largest length error "
            f"{1e3 * max(r['max_length_error_m'].values()):.2f} mm, largest linkage tilt "
            f"{np.degrees(max(r['max_tilt_rad'].values())):.1f} deg, Jacobian condition {jc['min']:.2f}-{jc['max']:.2f}"
        )
    for name, row in r.get("crosstalk", {}).items():
        txt = ", ".join(
            f"{d} {1e3 * v['linearised_peak']:.3f} vs {1e3 * v['exact_peak']:.4f}"
            for d, v in row.items()
            if v["ratio"] is not None
        )
        print(f"  crosstalk {name} (peak, mm or mrad, linearised vs exact): {txt or 'none'}")
    if "oil_column_hz" in r:
        oc = r["oil_column_hz"]
        print("  oil-column frequencies (Hz), centre: " + ", ".join(f"{v:.2f}" for v in oc["centre"]))
        print(f"  largest change across the envelope: {100 * r['oil_column_max_relative_change']:.1f} %")


# ---------------------------------------------------------------- over the whole envelope
def envelope_samples(desc: TableDescription, n: int = 4000, seed: int = 0) -> np.ndarray:
    """The rated envelope's corners plus ``n`` poses drawn uniformly inside it (seeded)."""
    half = np.concatenate([desc.limits.stroke_m, desc.limits.rotation_rad])
    mask = np.array([d in desc.dofs for d in DOFS6], dtype=float)
    rng = np.random.default_rng(seed)
    inside = rng.uniform(-1.0, 1.0, size=(n, 6)) * half * mask
    return np.vstack([envelope_corners(desc), inside])


def actuator_axes(desc: TableDescription, pose) -> np.ndarray:
    """Unit vectors base -> platen swivel of every actuator at ``pose`` ((n_act, 3))."""
    from mjcf.description import rotation_matrix

    pose = np.asarray(pose, float)
    base = np.array([a.base_m for a in desc.actuators])
    plat = np.array([a.platen_m for a in desc.actuators])
    pts = pose[:3] + plat @ rotation_matrix(*pose[3:6]).T
    v = pts - base
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def envelope_study(desc: TableDescription, *, n: int = 4000, seed: int = 0) -> dict:
    """Over the rated envelope (corners + ``n`` interior poses): the largest error of the
    linearised map per actuator (m), the largest tilt of each linkage from its home axis
    (rad), and the range of the condition number of the actuator Jacobian J(q)."""
    names = list(desc.actuator_names)
    dofs = [i for i, d in enumerate(DOFS6) if d in desc.dofs]
    P = envelope_samples(desc, n, seed)
    J0 = dof_jacobian(desc)
    err = np.abs(actuator_strokes(desc, P) - P @ J0.T)
    a0 = actuator_axes(desc, np.zeros(6))
    tilt = np.zeros(len(names))
    conds = []
    for p in P[:: max(1, len(P) // 400)]:  # the Jacobian by finite differences: a subsample
        ax = actuator_axes(desc, p)
        tilt = np.maximum(tilt, np.arccos(np.clip(np.sum(ax * a0, axis=1), -1, 1)))
        conds.append(np.linalg.cond(dof_jacobian(desc, p)[:, dofs]))
    return {
        "max_length_error_m": {nm: float(v) for nm, v in zip(names, err.max(axis=0))},
        "max_tilt_rad": {nm: float(v) for nm, v in zip(names, tilt)},
        "jacobian_condition": {
            "home": float(np.linalg.cond(J0[:, dofs])),
            "min": float(np.min(conds)),
            "max": float(np.max(conds)),
        },
        "n_poses": int(len(P)),
    }


def offset_plane_maps(desc: TableDescription, tm=None, hydraulics=None, *, n: int = 11) -> dict:
    """Over the x-y offset plane (the platen held at each offset, other DOFs at home): the
    largest linearised-map length error of any actuator (m) and, with the compiled model
    (also the x effective mass, kg, which moves as the linkages tilt)
    ``tm`` and ``hydraulics``, the lowest and the x oil-column frequency (Hz) from the
    stiffness and mass matrices in DOF space at that pose (mass matrix from MuJoCo with
    the loops closed at the offset)."""
    from mjcf import analysis

    hx, hy = float(desc.limits.stroke_m[0]), float(desc.limits.stroke_m[1])
    xs, ys = np.linspace(-hx, hx, n), np.linspace(-hy, hy, n)
    J0 = dof_jacobian(desc)
    err = np.zeros((n, n))
    f_low = np.full((n, n), np.nan)
    f_x = np.full((n, n), np.nan)
    m_x = np.full((n, n), np.nan)
    dofs = [i for i, d in enumerate(DOFS6) if d in desc.dofs]
    d = tm.new_data() if tm is not None else None
    for i, y in enumerate(ys):
        for j, x in enumerate(xs):
            p = np.zeros(6)
            p[0], p[1] = x, y
            err[i, j] = float(np.max(np.abs(actuator_strokes(desc, p) - J0 @ p)))
            if tm is not None and hydraulics is not None:
                hp = hydraulics
                tm.set_platen_pose(d, p)
                M = analysis.effective_mass_matrix(tm.model, d)
                m_x[i, j] = float(M[0, 0])
                K = dof_stiffness(desc, hp, p, dofs)
                w2, vec = np.linalg.eig(np.linalg.solve(M, K))
                f = np.sqrt(np.clip(w2.real, 0, None)) / (2 * np.pi)
                f_low[i, j] = float(f.min())
                f_x[i, j] = float(f[int(np.argmax(np.abs(vec[0].real)))])  # the mode most in x
    return {
        "x_m": xs.tolist(),
        "y_m": ys.tolist(),
        "max_length_error_m": err.tolist(),
        "lowest_oil_column_hz": f_low.tolist(),
        "x_oil_column_hz": f_x.tolist(),
        "x_effective_mass_kg": m_x.tolist(),
    }


def force_coupling(desc: TableDescription) -> dict:
    """How the tilting linkages couple forces between DOFs over the rated envelope.

    ``vertical_tilt_into_horizontal``: the largest horizontal force at the reference point
    per newton of one vertical actuator (the horizontal entries of its row of J(q): zero at
    home, the sine of its tilt at an offset). ``overturning_to_actuator_n_per_n_m``: the
    largest actuator force per N m of overturning moment (rx or ry) a payload puts on the
    platen, ``pinv(J^T)``, at home and the worst over the envelope corners."""
    J0 = dof_jacobian(desc)
    vert = [i for i, a in enumerate(desc.actuators) if abs(actuator_axes(desc, np.zeros(6))[i][2]) > 0.7]
    corners = envelope_corners(desc)
    tilt_h, ot = 0.0, {}
    dofs = [DOFS6.index(d) for d in ("rx", "ry") if d in desc.dofs]

    def ot_per_moment(J):
        G = np.linalg.pinv(J.T)  # actuator forces (n_act) for a wrench (6)
        return float(np.abs(G[:, dofs]).max()) if dofs else 0.0

    ot["home"] = ot_per_moment(J0)
    worst = ot["home"]
    for p in corners:
        J = dof_jacobian(desc, p)
        if vert:
            tilt_h = max(tilt_h, float(np.abs(J[vert][:, :2]).max()))
        worst = max(worst, ot_per_moment(J))
    ot["envelope_max"] = worst
    return {
        "vertical_tilt_into_horizontal": tilt_h,
        "vertical_actuators": [desc.actuators[i].name for i in vert],
        "overturning_to_actuator_n_per_n_m": ot,
    }


def stroke_for_error(desc: TableDescription, dof: str, error_m: float) -> float | None:
    """The pure ``dof`` offset (m) at which the linearised map first misses some actuator's
    length by ``error_m`` (None if not within the rated stroke). The miss grows as d^2."""
    i = DOFS6.index(dof)
    half = float(np.concatenate([desc.limits.stroke_m, desc.limits.rotation_rad])[i])
    J0 = dof_jacobian(desc)
    ds = np.linspace(0.0, half, 2001)
    P = np.zeros((len(ds), 6))
    P[:, i] = ds
    miss = np.abs(actuator_strokes(desc, P) - P @ J0.T).max(axis=1)
    hit = np.nonzero(miss >= error_m)[0]
    return float(ds[hit[0]]) if len(hit) else None


def geometry(
    desc: TableDescription,
    payload=None,
    *,
    quick: bool = False,
    crosstalk_motions=None,
    envelope_poses: int = 4000,
    map_points: int = 11,
) -> dict:
    """The whole geometric-nonlinearity study of a table, as data: the static report
    (:func:`study`), the envelope (:func:`envelope_study`), the x-y offset-plane maps
    (:func:`offset_plane_maps`), the strokes at which the linearised map misses by 0.1, 1
    and 10 mm, and the closed-loop crosstalk (:func:`sim.assess.crosstalk.crosstalk`;
    ``crosstalk_motions=()`` skips it). The crosstalk time histories are under
    ``"_histories"`` (arrays, for the report's figures)."""
    from hydraulics import HydraulicParams
    from sim.assess.crosstalk import crosstalk
    from sim.effects import build_model

    tm = build_model(desc, payload)
    hp = HydraulicParams.from_table(desc.raw)
    out = study(desc, tm.effective_mass_matrix(), hp)
    env = envelope_study(desc, n=1000 if quick else envelope_poses)
    out.update(env)
    out["maps"] = offset_plane_maps(desc, tm, hp, n=5 if quick else map_points)
    out["stroke_for_length_error_m"] = {
        d: {f"{e * 1e3:g}mm": stroke_for_error(desc, d, e) for e in (1e-4, 1e-3, 1e-2)}
        for d in ("x", "y", "z")
        if d in desc.dofs
    }
    out["force_coupling"] = force_coupling(desc)
    if payload is not None:
        out["maps"]["effective_mass_note"] = "with the payload"
    if crosstalk_motions is None:
        crosstalk_motions = (
            ("x_250mm_sine", "y_150mm_sine") if quick else ("x_250mm_sine", "y_150mm_sine", "elcentro_3c")
        )
    if crosstalk_motions:
        c = crosstalk(
            desc,
            payload,
            motions=tuple(m for m in crosstalk_motions if m == "elcentro_3c" or m.split("_")[0] in desc.dofs),
            quick=quick,
        )
        out["crosstalk"] = c.table
        out["_histories"] = c.histories
    return out
