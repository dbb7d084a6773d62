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


def study(desc: TableDescription, effective_mass: np.ndarray | None = None, hydraulics=None) -> dict:
    """The geometric-nonlinearity report (dict, SI units)."""
    names = list(desc.actuator_names)
    J0 = dof_jacobian(desc)
    corners = envelope_corners(desc)
    exact = actuator_strokes(desc, corners)
    lin = corners @ J0.T
    dev = np.abs(exact - lin)
    out = {"table": desc.name,
           "kinematic_nonlinearity_m": {n: float(v) for n, v in zip(names, dev.max(axis=0))},
           "worst_corner": corners[int(np.argmax(dev.max(axis=1)))].tolist()}

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
            x = actuator_strokes(desc, pose)
            va = hp.dead_volume_a_m3 + hp.area_a_m2 * (hp.half_stroke_m + x)
            vb = hp.dead_volume_b_m3 + hp.area_b_m2 * (hp.half_stroke_m - x)
            k = hp.bulk_modulus_pa * (hp.area_a_m2 ** 2 / va + hp.area_b_m2 ** 2 / vb)
            J = dof_jacobian(desc, pose)[:, dofs]
            K = J.T @ np.diag(k) @ J
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
    print("  exact stroke - linear J(0) estimate, worst corner (mm): "
          + ", ".join(f"{n} {1e3 * v:.2f}" for n, v in kn.items()))
    print("  second-order strokes from one axis at full stroke (mm, largest actuator):")
    for d, m in r["second_order_stroke_m"].items():
        n, v = max(m.items(), key=lambda kv: kv[1])
        print(f"    {d:3s} -> {n} {1e3 * v:.2f}")
    print("  parasitic motion if the reference went through the linear map J(0):")
    for k, e in r["parasitic_motion_linear_map"].items():
        big = {d: v for d, v in e.items() if abs(v) > 1e-9}
        txt = ", ".join(f"{d} {v * (1e3 if d in ('x', 'y', 'z') else 1e3):+.3f} {'mm' if d in ('x', 'y', 'z') else 'mrad'}"
                        for d, v in big.items()) or "none"
        print(f"    {k:4s}: {txt}")
    print(f"  actuator-to-DOF force map: largest entry change over the envelope {r['force_map_change_max']:.4f}")
    if "oil_column_hz" in r:
        oc = r["oil_column_hz"]
        print("  oil-column frequencies (Hz), centre: " + ", ".join(f"{v:.2f}" for v in oc["centre"]))
        print(f"  largest change across the envelope: {100 * r['oil_column_max_relative_change']:.1f} %")
