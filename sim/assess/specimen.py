"""Specimens from a few numbers, and how a specimen and the table interact.

:func:`specimen_from_numbers` builds a payload description in memory (through
``mjcf.description.parse_payload``, so it is validated like a payload file): a rigid
block of a given mass, centre-of-gravity height and footprint, or, with modal
frequencies, a shear frame with one floor per frequency.

:func:`interaction` sets the table's oil-column frequencies with the specimen on it
beside the specimen's own modes and measures how much the specimen's reaction distorts
the table motion.
"""

from __future__ import annotations

import numpy as np

from mjcf.description import DOFS6, CantileverPayload, RigidPayload, ShearFramePayload, parse_payload, payload_mass
from sim.errors import UserError


class SpecimenError(UserError):
    """Specimen numbers that do not make a specimen (or do not fit the table)."""


#: How close a specimen mode may come to an oil-column frequency before the warning.
CLOSE_RATIO = 0.25  # assumed: within +/-25 % the oil column's resonance (damping ~10-20 %) amplifies the mode
#: Specimen-to-table mass ratio above which the reaction distorts the table motion noticeably.
INERTIA_RATIO_WARN = 0.5  # assumed: at 0.5 the specimen's reaction is a third of the total inertia force


def uniform_box_inertia(m: float, a: float, b: float, h: float) -> list[float]:
    """Principal moments of a uniform box a x b x h of mass m about its centre."""
    return [m * (b * b + h * h) / 12.0, m * (a * a + h * h) / 12.0, m * (a * a + b * b) / 12.0]


def shear_frame_stiffness(masses: np.ndarray, freqs_hz) -> np.ndarray:
    """Stiffness matrix with the given natural frequencies for floor masses ``masses``.

    The mode shapes are those of the uniform shear building (equal storey stiffness k:
    K0 tridiagonal with 2k on the diagonal, k on the top floor, -k off the diagonal),
    mass-normalised (Phi^T M Phi = I); the eigenvalues are replaced by (2 pi f)^2:
    K = M Phi diag(w^2) Phi^T M. K is symmetric positive definite, has exactly the asked
    frequencies, and is the uniform building's K0 when the frequencies are its own.
    """
    import scipy.linalg

    n = len(masses)
    f = np.sort(np.asarray(freqs_hz, dtype=float))
    K0 = 2 * np.eye(n) - np.eye(n, k=1) - np.eye(n, k=-1)
    K0[-1, -1] = 1.0
    M = np.diag(masses)
    _, phi = scipy.linalg.eigh(K0, M)  # ascending, mass-normalised
    w2 = (2 * np.pi * f) ** 2
    K = M @ phi @ np.diag(w2) @ phi.T @ M
    return (K + K.T) / 2


def specimen_from_numbers(
    *,
    mass_kg: float,
    cg_height_m: float,
    footprint_m=None,
    modes_hz=None,
    direction: str = "x",
    damping_ratio: float = 0.02,
    platen_size_m=None,
    name=None,
):
    """A payload description from numbers.

    Rigid (no ``modes_hz``): a uniform block of ``mass_kg`` resting on the platen, height
    2 x ``cg_height_m``, base ``footprint_m`` (L x W; default 3 m x 3 m), inertia of a
    uniform box. Shear frame (``modes_hz``, one per floor): equal floor masses summing to
    ``mass_kg`` at equal storey heights h with the centre of gravity at
    ``cg_height_m`` = h (n + 1) / 2, stiffness from :func:`shear_frame_stiffness`, weak
    direction ``direction``, modal damping ``damping_ratio``.

    ``platen_size_m`` (L, W): a footprint larger than the platen is refused.
    """
    if not (mass_kg > 0 and np.isfinite(mass_kg)):
        raise SpecimenError(f"--payload-mass must be a positive mass in kg (got {mass_kg!r})")
    if not (cg_height_m > 0 and np.isfinite(cg_height_m)):
        raise SpecimenError(f"--payload-cg-height must be a positive height in m (got {cg_height_m!r})")
    fp = np.array([3.0, 3.0] if footprint_m is None else footprint_m, dtype=float)
    if fp.shape != (2,) or np.any(~np.isfinite(fp)) or np.any(fp <= 0):
        raise SpecimenError(f"--payload-footprint must be LxW in m, both positive (got {footprint_m!r})")
    if platen_size_m is not None and (fp[0] > platen_size_m[0] + 1e-9 or fp[1] > platen_size_m[1] + 1e-9):
        raise SpecimenError(
            f"--payload-footprint {fp[0]:g}x{fp[1]:g} m is larger than the platen "
            f"({platen_size_m[0]:g} x {platen_size_m[1]:g} m); give a footprint that fits"
        )
    tag = name or (f"specimen_{mass_kg / 1000:g}t_cg{cg_height_m:g}m")
    if not modes_hz:
        h = 2.0 * cg_height_m
        data = {
            "payload": {
                "type": "rigid",
                "name": tag,
                "description": f"rigid block {mass_kg / 1000:g} t, centre of gravity {cg_height_m:g} m, "
                f"footprint {fp[0]:g} x {fp[1]:g} m",
                "source": "assumed: a uniform block resting on the platen (inertia of a uniform box)",
                "mass_kg": float(mass_kg),
                "com_m": [0.0, 0.0, float(cg_height_m)],
                "inertia_kg_m2": uniform_box_inertia(mass_kg, fp[0], fp[1], h),
                "footprint_m": fp.tolist(),
                "height_m": h,
            }
        }
        return parse_payload(data, src="--payload-mass")
    f = np.asarray(modes_hz, dtype=float)
    if f.ndim != 1 or len(f) < 1 or len(f) > 20 or np.any(~np.isfinite(f)) or np.any(f <= 0):
        raise SpecimenError(f"--payload-modes must be 1 to 20 positive frequencies in Hz (got {modes_hz!r})")
    if len(set(np.round(f, 9))) != len(f):
        raise SpecimenError(f"--payload-modes must be distinct frequencies (got {f.tolist()})")
    n = len(f)
    m = np.full(n, mass_kg / n)
    K = shear_frame_stiffness(m, f)
    data = {
        "payload": {
            "type": "shear_frame",
            "name": tag + f"_{n}storey",
            "description": f"{n}-storey shear frame {mass_kg / 1000:g} t, modes {', '.join(f'{x:g}' for x in f)} Hz",
            "source": "assumed: equal floor masses, mode shapes of the uniform shear building, stiffness from the given modes",
            "direction": direction,
            "mass_kg": m.tolist(),
            "stiffness_n_m": K.tolist(),
            "damping_ratio": float(damping_ratio),
            "storey_height_m": 2.0 * cg_height_m / (n + 1),
            "base_m": [0.0, 0.0, 0.0],
            "footprint_m": fp.tolist(),
        }
    }
    return parse_payload(data, src="--payload-modes")


def specimen_modes(payload) -> list[dict]:
    """The specimen's own (fixed-base) modes: frequency, direction, effective modal mass."""
    import scipy.linalg

    if payload is None:
        return []
    if isinstance(payload, RigidPayload):
        if payload.clamp_frequency_hz is None:
            return []
        m = payload.mass_kg * payload.clamp_mass_fraction
        return [
            {"frequency_hz": payload.clamp_frequency_hz, "direction": d, "modal_mass_kg": m} for d in ("x", "y", "z")
        ]
    if isinstance(payload, ShearFramePayload):
        M = np.diag(payload.mass_kg)
        w2, phi = scipy.linalg.eigh(payload.stiffness_n_m, M)
        L = phi.T @ payload.mass_kg  # participation (mass-normalised shapes)
        return [
            {
                "frequency_hz": float(np.sqrt(w) / (2 * np.pi)),
                "direction": payload.direction,
                "modal_mass_kg": float(li**2),
            }
            for w, li in zip(w2, L)
        ]
    if isinstance(payload, CantileverPayload):
        out = []
        mtot = payload.mass_per_length_kg_m * payload.height_m
        for beta, share in ((1.875104, 0.6131), (4.694091, 0.1883), (7.854757, 0.0647)):  # Euler-Bernoulli cantilever
            f = (
                beta**2
                * np.sqrt(payload.bending_stiffness_n_m2 / (payload.mass_per_length_kg_m * payload.height_m**4))
                / (2 * np.pi)
            )
            out += [{"frequency_hz": float(f), "direction": d, "modal_mass_kg": share * mtot} for d in ("x", "y")]
        return out
    return []


def interaction(desc, payload) -> dict:
    """Oil-column frequencies with the specimen on the table (the linearised ones of
    ``sim.identify.characterize.linear_oil_columns``; a flexible specimen counts with
    its whole mass, as at frequencies well above its own modes it does not), the
    specimen's modes, the close pairs, and the inertia ratio per horizontal table DOF:
    specimen mass over the bare table's effective mass (how much of the actuators'
    force goes into the specimen's reaction rather than the platen's motion).
    Returns ``{"oil_columns_hz", "specimen_modes", "close", "inertia_ratio", "warnings"}``."""
    from sim.effects import build_model
    from sim.identify.characterize import linear_oil_columns

    rigid = _as_rigid(payload)
    oil = linear_oil_columns(desc, rigid)
    modes = specimen_modes(payload)
    close, warns = [], []
    for mo in modes:
        d = mo["direction"]
        if d not in desc.dofs or d not in oil:
            continue
        r = mo["frequency_hz"] / oil[d]
        if abs(r - 1.0) <= CLOSE_RATIO:
            close.append(
                {
                    "dof": d,
                    "specimen_hz": mo["frequency_hz"],
                    "oil_column_hz": oil[d],
                    "ratio": float(r),
                    "modal_mass_kg": mo["modal_mass_kg"],
                }
            )
            warns.append(
                f"specimen mode {mo['frequency_hz']:.1f} Hz ({d}) is within {100 * abs(r - 1):.0f} % of "
                f"the {d} oil column at {oil[d]:.1f} Hz: the table will amplify or notch it"
            )
    eff = build_model(desc, None).effective_mass()
    m = payload_mass(payload)
    ratio = {d: float(m / eff[d]) for d in ("x", "y") if d in desc.dofs and d in eff}
    for d, r in ratio.items():
        if r > INERTIA_RATIO_WARN:
            warns.append(
                f"specimen mass is {r:.2f} x the table's effective mass in {d}: its reaction will "
                "distort the table motion (drive iterations needed)"
            )
    return {
        "oil_columns_hz": {d: oil[d] for d in desc.dofs if d in oil},
        "specimen_modes": modes,
        "close": close,
        "inertia_ratio": ratio,
        "warnings": warns,
    }


def _as_rigid(payload):
    """The specimen as one rigid block of its mass (for the oil columns)."""
    if payload is None or isinstance(payload, RigidPayload):
        return payload
    m = payload_mass(payload)
    if isinstance(payload, ShearFramePayload):
        h = float(payload.storey_height_m * np.arange(1, len(payload.mass_kg) + 1) @ payload.mass_kg / m)
        fp = payload.footprint_m
        base = payload.base_m
    else:
        h = payload.height_m / 2
        fp = np.array([payload.width_m, payload.width_m])
        base = payload.base_m
    return RigidPayload(
        name=payload.name + "_rigid",
        mass_kg=m,
        com_m=np.array([base[0], base[1], base[2] + h]),
        inertia_kg_m2=np.array(uniform_box_inertia(m, fp[0], fp[1], 2 * h)),
        footprint_m=fp,
        height_m=2 * h,
    )


__all__ = [
    "CLOSE_RATIO",
    "INERTIA_RATIO_WARN",
    "SpecimenError",
    "interaction",
    "shear_frame_stiffness",
    "specimen_from_numbers",
    "specimen_modes",
    "uniform_box_inertia",
    "DOFS6",
]
