"""Where a table's static supports move and what they carry, for the mechanical path's
places ``supports`` and ``shoes`` (:mod:`sim.calibrate.residuals`): each support's
vertical travel and each shoe's slides per DOF of the table, small angles about home,
and the air spring a kilogram more on a support adds."""

from __future__ import annotations

import numpy as np

from mjcf.builder import air_spring_stiffness
from mjcf.description import DOFS6


def support_jacobian(desc) -> np.ndarray | None:
    """(n_sup, k) each static support's vertical travel per unit motion of the table's
    DOFs (``desc.dofs``), small angles: ``z + y_i rx - x_i ry`` at the support's position
    from the reference point (the shoe slides: horizontal motion does not reach the air
    piston). None without supports."""
    if desc.supports is None:
        return None
    rows = []
    for x, y, _z in desc.supports.positions_m:
        r = np.zeros(6)
        r[2], r[3], r[4] = 1.0, y, -x
        rows.append(r)
    return np.asarray(rows)[:, [DOFS6.index(d) for d in desc.dofs]]


def shoe_jacobian(desc) -> np.ndarray | None:
    """(2 n_sup, k) each support's shoe's x and y slide per unit motion of the table's
    DOFs, small angles: the platen's motion at the shoe's pin (the support's position
    from the reference point), ``x + z_i ry - y_i rz`` and ``y + x_i rz - z_i rx`` (the
    piston under it moves only vertically). None without supports."""
    if desc.supports is None:
        return None
    rows = []
    for x, y, z in desc.supports.positions_m:
        rows.append([1.0, 0.0, 0.0, 0.0, z, -y])
        rows.append([0.0, 1.0, 0.0, -z, 0.0, x])
    return np.asarray(rows)[:, [DOFS6.index(d) for d in desc.dofs]]


def air_stiffness_per_kg(desc) -> float:
    """N/m a static support's air spring gains per kg of load: the build's linear stiffness
    at the preload it solves for (:func:`mjcf.builder.air_spring_stiffness`, linear in the
    load) at the weight of one kilogram, ``n g A / V0``. 0 without supports."""
    if desc.supports is None:
        return 0.0
    return float(air_spring_stiffness(desc.supports, desc.gravity_m_s2))


__all__ = ["air_stiffness_per_kg", "shoe_jacobian", "support_jacobian"]
