"""Force laws of the mechanical effects, as regressors for the mechanical residual path.

An effect that adds a generalised force ``theta * basis(motion)`` at a place (a DOF, an
actuator, an actuator class) is *linear in its parameter* ``theta``: the mechanical
residual (recorded force minus the force the declared model needs for the recorded
motion) is then explained by linear least squares on the column ``basis``. This module
is the hook the effect contract (:mod:`sim.effects.base`) does not have yet: a registry
of :class:`Law` objects keyed by effect type (``coulomb_friction``, ``viscous_damping``,
``power_damping``, ``spring``, ``added_mass``, ``payload_mode``, ``cg_offset``: the names of
the effect library; ``coulomb_friction_displacement`` and ``coulomb_friction_load``: dry
friction growing with the stroke or the load, written as ``coulomb_friction`` with its
``grows_with``), plus the
older platen effects of :mod:`sim.effects.registry` (``platen_spring``,
``platen_coulomb``, ``platen_power_damping``) so that a description's *declared*
effects enter the model's force. A law with a nonlinear shape parameter (the exponent
of power-law damping) is fitted on a grid of it, each point a linear least squares. A
law with several linear coefficients (the CG offset's dx, dy, dz at the ``payload`` place)
gives one DOF-space column per coefficient.

``foundation_mode`` has no law here: the actuators push off the foundation, so the force
the platen needs for its recorded (absolute) motion does not involve the foundation's
motion, except through the linkages' own terms on the stroke (platen minus foundation
end: dry friction above all), which need the foundation's motion the runs do not record;
measured in tests/calibrate/test_cgs_mechanical.py, documented in docs/calibration.md.

When an effect type is registered in :data:`sim.effects.base.EFFECTS`, its ``SPEC``
keys must match the law's parameter names for the law to be used as a candidate; when
it is not registered yet, the law still serves (the written entry then needs the effect
library to load).
"""

from __future__ import annotations

import functools
import math
from collections import OrderedDict
from dataclasses import dataclass, field, replace
from typing import Callable

import numpy as np

from mjcf.description import DOFS6


@dataclass(frozen=True)
class Law:
    """``force = value[linear] * basis(u, v, a, shape)`` at one coordinate, or, for a law
    with several linear coefficients (``linear`` a tuple: the CG offset's three
    components), ``force = sum_i value[linear[i]] * basis(...)[i]``.

    ``params``: name -> (unit, lower, upper) (SI, the ``[[effect]]`` keys); ``linear``:
    the name of the coefficient (or a tuple of them; their 95 % test asks that one of
    them differs from zero: the components of one vector); ``shape``: name -> grid of values scanned (nonlinear
    parameters); ``inertial``: the basis is the acceleration (not passed through the
    sensor prefilter, which the recorded acceleration already went through);
    ``places``: the place kinds it can act at; ``dofs``: the DOFs a ``dof:`` place may
    name (empty: any); ``repeats``: how many terms of this law one place may hold (the
    modes of a specimen: one ``payload_mode`` each); ``when``: see the field.
    """

    type: str
    params: dict
    linear: str
    basis: Callable
    places: tuple = ("dof", "actuator", "class")
    shape: dict = field(default_factory=dict)
    inertial: bool = False
    what: str = ""
    #: shape parameter -> (value, simpler law): at that value this law IS the simpler one
    #: (power-law damping at exponent 1 is viscous damping); a fit whose 95 % interval
    #: holds the value is refused for the simpler law (fewer parameters, same force)
    nested: dict = field(default_factory=dict)
    #: the DOFs a ``dof:`` place may be (None: every DOF of the table)
    dofs: tuple | None = None
    #: how many terms of this law one place may hold (a specimen's modes: several)
    repeats: int = 1
    #: "always" a candidate, or only when named (``--effects``) or, for "undeclared_specimen",
    #: when the calibration is told a specimen stands on the table undeclared (``--payload none``)
    when: str = "always"
    #: ``(u, v, a, s, values) -> force``: the part of the force of second order in the
    #: linear coefficients (the CG offset's own parallel-axis inertia), at ``values``: a
    #: quadratic form in them (the fit tabulates it per product of two coefficients),
    #: taken at the current coefficients and the solve repeated to a fixed point
    second_order: Callable | None = None
    #: the effect type an accepted term is written as (None: ``type``) and the options
    #: written with it: a variant of one effect (dry friction growing with the stroke) has
    #: its own law under its own key
    effect: str | None = None
    options: dict = field(default_factory=dict)
    #: the basis needs the load at the place (``s["_load"]``: the recorded actuator force's
    #: magnitude, N, per actuator of the place)
    load: bool = False
    #: the basis applies the sensor prefilter itself (``s["_filt"]``: the CG offset's
    #: weight term), so it changes with the records' timing, not with the motion alone
    filters_inside: bool = False
    #: shape parameter -> (low, high): how far its scan may extend past the grid when the
    #: optimum sits on the grid's edge (physical limits; "nyquist": 0.4 x the record rate);
    #: a parameter without one stays inside its grid
    limits: dict = field(default_factory=dict)
    #: parameters held at a value (a bound) rather than fitted: a nested law of ``base``
    #: (:func:`fixed_law`): dry friction growing with the stroke with no constant part
    fixed: dict = field(default_factory=dict)
    base: object = None
    #: the law acts at the declared payload's centre of gravity along its place's DOF: its
    #: basis gets every DOF's motion and returns a wrench in DOF space (a mode of the
    #: payload's own mass: :func:`_mode_of_payload`)
    at_payload_cg: bool = False
    #: the column is the declared model's own force (the load cells' gain read beside a law:
    #: :mod:`sim.calibrate.gainpair`), not a basis of the motion
    model_force: bool = False
    #: the column is the recorded force of the place's actuators (a class's load cells' gain:
    #: :data:`LOAD_CELLS_GAIN_CLASS`), not a basis of the motion
    recorded_force: bool = False

    @property
    def name(self) -> str:
        """The effect type the law's terms are reported and written as."""
        return self.effect or self.type

    @property
    def linears(self) -> tuple:
        """The linear coefficients' names (one, or several for a vector law)."""
        return (self.linear,) if isinstance(self.linear, str) else tuple(self.linear)

    @property
    def units(self) -> dict:
        """Every parameter's unit, the held ones (``fixed``) too."""
        return {k: u for k, (u, *_r) in (self.base or self).params.items()}

    def acts_at(self, where: str) -> bool:
        kind, _, name = where.partition(":")
        return kind != "dof" or self.dofs is None or name in self.dofs


DEADBAND = 1e-3  #: m/s (rad/s): below it the sign of a velocity is the sensor noise's


def _sign(v):
    return np.sign(v)


LAWS: dict[str, Law] = {}


def add_law(law: Law) -> Law:
    LAWS[law.type] = law
    return law


def dahl_series(v: np.ndarray, zss: float, dt: float) -> np.ndarray:
    """The pre-sliding state z(t) along a velocity record (n,) or (n, m), from z = 0
    (:func:`sim.effects.registry.dahl_step`, the loop's law)."""
    from sim.effects.registry import dahl_step

    v = np.asarray(v, float)
    z = np.zeros(v.shape[1:])
    out = np.empty_like(v)
    for i in range(len(v)):
        z = dahl_step(z, v[i], zss, dt)
        out[i] = z
    return out


def _coulomb(u, v, a, s):
    """sign(v); on a table whose dry friction has pre-sliding (``[friction] model =
    "presliding"``), the same Dahl law: z / delta along the motion."""
    zss = s.get("_presliding_m")
    if not zss:
        return _sign(v)
    return dahl_series(v, zss, s["_dt"]) / zss


add_law(
    Law(
        "coulomb_friction",
        {"force_n": ("N", 0.0, np.inf)},
        "force_n",
        _coulomb,
        # at supports: each static support's piston friction, alike (a seal tighter than
        # declared); at shoes: each sliding shoe's, over its x and y slides
        places=("dof", "actuator", "class", "supports", "shoes"),
        what="dry friction F sign(v) (with the table's pre-sliding law, if it has one)",
    )
)
#: m/s: below it a dry friction whose level changes is linear in the velocity (the
#: effect's ``linear_below_m_s`` default; such a friction is applied every physics step by
#: :meth:`sim.effects.mechanical.CoulombFriction.advance`, without the table's pre-sliding law)
LINEAR_BELOW_M_S = 1e-3


def _coulomb_growing(u, v, a, s, grows):
    """[sign, sign x grows]: the level ``force_n + coefficient * grows`` of a dry friction
    that grows with |displacement| or with the load, as the effect applies it."""
    c = np.clip(np.asarray(v, float) / LINEAR_BELOW_M_S, -1.0, 1.0)
    return [c, c * grows]


add_law(
    Law(
        "coulomb_friction_displacement",
        {"force_n": ("N", 0.0, np.inf), "coefficient": ("N/m", 0.0, np.inf)},
        ("force_n", "coefficient"),
        lambda u, v, a, s: _coulomb_growing(u, v, a, s, np.abs(u)),
        what="dry friction growing with the stroke from home (force_n + coefficient |x|) sign(v)",
        nested={"coefficient": (0.0, "coulomb_friction")},
        effect="coulomb_friction",
        options={"grows_with": "displacement"},
    )
)
add_law(
    Law(
        "coulomb_friction_load",
        {"force_n": ("N", 0.0, np.inf), "coefficient": ("1", 0.0, np.inf)},
        ("force_n", "coefficient"),
        lambda u, v, a, s: _coulomb_growing(u, v, a, s, s["_load"]),
        # at an actuator: seal friction rising with the force it carries; at a DOF the load is
        # the weight on the bearings, constant but for the vertical acceleration's few per
        # cent, so its coefficient cannot be told from the level there: not offered
        places=("actuator", "class"),
        what="seal friction growing with the actuator's force (force_n + coefficient |F|) sign(v)",
        nested={"coefficient": (0.0, "coulomb_friction")},
        effect="coulomb_friction",
        options={"grows_with": "load"},
        load=True,
    )
)
add_law(
    Law(
        "viscous_damping",
        {"damping_n_s_m": ("N s/m", 0.0, np.inf)},
        "damping_n_s_m",
        lambda u, v, a, s: v,
        what="linear damping c v",
    )
)
add_law(
    Law(
        "power_damping",
        {"coefficient": ("N (s/m)^exponent", 0.0, np.inf), "exponent": ("1", 0.05, 2.0)},
        "coefficient",
        lambda u, v, a, s: np.abs(v) ** s["exponent"] * _sign(v),
        shape={"exponent": tuple(np.round(np.arange(0.2, 1.51, 0.1), 3))},
        # the scan extends up to 2 (orifice damping, quadratic) when its optimum sits on the
        # grid's top edge; not below 0.2: towards 0 the law is dry friction (sign(v)), a
        # law of its own, and a low exponent fits friction and damping at once (NEES-UCSD:
        # 0.16, where the truth is 26.5 kN of friction and alpha 0.5)
        limits={"exponent": (0.2, 2.0)},
        what="power-law damping C |v|^alpha sign(v)",
        nested={"exponent": (1.0, "viscous_damping")},
    )
)
add_law(
    Law(
        "spring",
        {"stiffness_n_m": ("N/m", -np.inf, np.inf)},
        "stiffness_n_m",
        lambda u, v, a, s: u,
        # at supports: the static supports' air springs, each alike (stiffer chambers)
        places=("dof", "actuator", "class", "supports"),
        what="linear spring k u",
    )
)
add_law(
    Law(
        "added_mass",
        # >= 0, as the description's added_mass effect: a table lighter than declared has a
        # wrong moving mass ([platen] mass_kg, or an [unknown] range on it), not a negative
        # mass on it; a negative fit (a declared specimen's mass counted twice) is refused at
        # its bound instead of written into a description no command could load
        {"mass_kg": ("kg", 0.0, np.inf)},
        "mass_kg",
        lambda u, v, a, s: a,
        inertial=True,
        what="mass moving with the place m a",
    )
)


def _piston_mass(u, v, a, s):
    """A static support's piston heavier by one kilogram: its inertia along the support's
    travel, and the stiffer air spring its weight makes (the air carries the weight at
    home, and its linear stiffness ``n F0 A / V0`` grows with the load ``F0``:
    ``s["_air_per_kg"]`` = n g A / V0, N/m per kg). The spring's term goes through the
    sensor prefilter, the inertial term not (the recorded acceleration already did)."""
    return np.asarray(a, float) + s["_air_per_kg"] * s["_filt"](np.asarray(u, float))


add_law(
    Law(
        "added_mass_support",
        {"mass_kg": ("kg", 0.0, np.inf)},
        "mass_kg",
        _piston_mass,
        places=("supports",),
        inertial=True,
        filters_inside=True,
        effect="added_mass",
        what="each static support's piston heavier by m: m a, and the air spring its weight stiffens",
    )
)

#: the largest relative warp of a mode's bandwidth its discrete filter may have (:func:`_mode`)
MODE_WARP = 1e-4


def _mode(u, v, a, s, relative: bool = False):
    """Absolute acceleration of a mode (``frequency_hz``, ``damping_ratio``) standing on
    the place and shaken by its acceleration ``a``: H(s) = (2 z w s + w^2) / (s^2 + 2 z w s
    + w^2), the force it puts on the place per unit modal mass (Newton on the mode's
    mass). Bilinear transform with the frequency pre-warped, so that the resonance sits at
    ``frequency_hz`` at any record rate; from rest at the record's start. A mode at or
    above 0.45 x the record rate moves with the place (``a``)."""
    import scipy.signal as sig

    dt, f, z = s["_dt"], s["frequency_hz"], s["damping_ratio"]
    a = np.asarray(a, float)
    if f >= 0.45 / dt:
        return np.zeros_like(a) if relative else a
    # the bilinear transform warps the resonance's bandwidth by about (pi f dt)^2 / 3 of
    # itself (0.5 % at 7.5 Hz in a 200 Hz record: a lightly damped mode's damping and mass
    # 1 % off); the record is interpolated P times (band-limited) so that this stays
    # below MODE_WARP, and the filter runs at P / dt
    P = max(1, math.ceil(np.pi * f * dt / math.sqrt(3.0 * MODE_WARP)))
    # (a Kaiser window of beta 12: passband gain within 2e-6 to 0.1 x the record rate; the
    # default beta 5 is 0.1 % high at 7.5 Hz in 200 Hz, which biased a modal mass)
    x = _upsampled(a, P) if P > 1 else a
    return sig.lfilter(*_mode_filter(float(f), float(z), dt / P, relative), x, axis=0)[::P]


#: bytes of interpolated records :func:`_upsampled` keeps (the least recently used go)
UPSAMPLED_BYTES = 64 * 2**20
_UPSAMPLED: OrderedDict = OrderedDict()


def _upsampled(a: np.ndarray, P: int) -> np.ndarray:
    """``a`` interpolated ``P`` times (band-limited, :func:`_mode`), kept by its content:
    a mode's scan filters one record at every grid point and in every round, and the
    interpolation costs three times the filter."""
    import hashlib

    import scipy.signal as sig

    a = np.ascontiguousarray(a, float)
    key = (P, a.shape, hashlib.blake2b(a.tobytes(), digest_size=16).digest())
    if key in _UPSAMPLED:
        _UPSAMPLED.move_to_end(key)
        return _UPSAMPLED[key]
    x = sig.resample_poly(a, P, 1, axis=0, window=("kaiser", 12.0))
    x.flags.writeable = False
    size = sum(v.nbytes for v in _UPSAMPLED.values())  # (a few dozen records)
    while _UPSAMPLED and size + x.nbytes > UPSAMPLED_BYTES:  # the least recently used go
        size -= _UPSAMPLED.popitem(last=False)[1].nbytes
    if x.nbytes <= UPSAMPLED_BYTES:
        _UPSAMPLED[key] = x
    return x


@functools.lru_cache(maxsize=1024)
def _mode_filter(f: float, z: float, h: float, relative: bool = False) -> tuple:
    """The mode's discrete filter (b, a) at step ``h`` (:func:`_mode`: its absolute
    acceleration, or its ``relative`` displacement), made once per frequency, damping and
    step: ``scipy.signal.bilinear`` is slow, and every round of the search scans the same
    grid."""
    import scipy.signal as sig

    w = 2.0 / h * np.tan(np.pi * f * h)
    num = [-1.0] if relative else [2 * z * w, w * w]
    b, den = sig.bilinear(num, [1.0, 2 * z * w, w * w], 1.0 / h)
    b.flags.writeable = den.flags.writeable = False
    return b, den


add_law(
    Law(
        "payload_mode",
        {"mass_kg": ("kg", 0.0, np.inf), "frequency_hz": ("Hz", 0.0, np.inf), "damping_ratio": ("1", 0.0, 10.0)},
        "mass_kg",
        _mode,
        places=("dof",),
        dofs=("x", "y", "z"),
        # scanned: 0.3-60 Hz (a specimen's modes below the oil column), 0.3-40 % damping; the
        # bounded search refines between grid points
        shape={
            "frequency_hz": tuple(np.round(np.geomspace(0.3, 60.0, 36), 4)),
            "damping_ratio": (0.003, 0.007, 0.015, 0.03, 0.06, 0.12, 0.25, 0.4),
        },
        # past the grid's edge, when the optimum sits there: damping down to 0.05 % (the
        # half-power band 2 z f of a 7.5 Hz mode at z = 0.0005 is 0.0075 Hz: minutes of
        # record to resolve; less than that no record tells) and up to critical (1: above
        # it nothing rings); frequency from 0.1 Hz (a rigid body over a record of tens of
        # seconds) to 0.4 x the record rate (above 0.45 x the law moves with the place)
        limits={"frequency_hz": (0.1, "nyquist"), "damping_ratio": (0.0005, 1.0)},
        inertial=True,
        what="a mode of what stands on the platen: modal mass m, frequency f, damping z (m H(s) a)",
        repeats=3,  # a specimen's modes: up to three at one place
        # with a rigid payload declared, its own mass on a mode is the hypothesis (the law
        # below), not a second, undeclared mass on a spring (named with --effects: both)
        when="not_with_rigid_payload",
    )
)


def _mode_of_payload(u, v, a, s):
    """A mode of the declared rigid payload itself: ``m`` of its mass moves on the mode, the
    rest stays rigid, so the platen carries ``(M - m) a + m H a``: beyond the rigid payload
    the effective mass already holds, ``m (H - 1) a`` (:func:`_mode` less the place's
    acceleration). Held rigid and given ``m H a`` instead, a 6 Hz block's mode fitted a
    negative mass (-813 kg for 900, refused) on the lab table: the law has to move the mass,
    not add it.

    With every DOF's motion (``s["_along"]``: the mode's DOF; the residual path passes them
    for a law ``at_payload_cg``), the mode stands at the payload's centre of gravity ``r``:
    it is shaken by that point's acceleration along its DOF, ``a + alpha x r`` (the
    platen's rocking drives a mode above it), and its force acts there, with the moment
    ``r x F``: a wrench in DOF space (n, k). The mass the mode carries off the centre of
    gravity by ``x`` moves its weight too, the moment ``x e x m g`` (P-delta: g / (h w^2)
    of the inertial moment, 0.7 % for a 6 Hz mode 1 m up; left out, a CGS block's modal
    mass came out 1.0 % high on raw runs, 0.5 % with it; the projection of gravity on the
    tilted slide moved it by 0.005 % and is left out: measured,
    docs/calibration-validation-tests.md, the fourteenth session)."""
    if "_along" not in s:
        return _mode(u, v, a, s) - np.asarray(a, float)
    dofs, r = list(s["_dofs"]), np.asarray(s["_payload"][1], float)
    a6 = np.zeros((len(a), 6))
    for j, d in enumerate(dofs):
        a6[:, DOFS6.index(d)] = a[:, j]
    e = np.zeros(3)
    e[("x", "y", "z").index(s["_along"])] = 1.0
    drive = a6[:, :3] @ e + np.cross(a6[:, 3:], r) @ e
    f = _mode(None, None, drive, s) - drive
    wrench = np.outer(f, np.concatenate([e, np.cross(r, e)]))
    # the residual's sign is the actuators' (force = m (H - 1) a): the weight moved by x
    # turns the platen by x e x m g, which the actuators hold against; filtered only where
    # a recorded rotation takes it (not on a uni-axial table, nor for a vertical mode)
    weight_arm = np.cross(e, [0.0, 0.0, -float(s["_payload"][2])])
    cols = [DOFS6.index(d) for d in dofs]
    if any(k >= 3 and weight_arm[k - 3] for k in cols):
        wrench[:, 3:] -= np.outer(_mode(None, None, drive, s, relative=True), weight_arm)
    return wrench[:, cols]


add_law(
    replace(
        LAWS["payload_mode"],
        type="payload_mode_from_payload",
        basis=_mode_of_payload,
        effect="payload_mode",
        options={"from_payload": True},
        when="declared_rigid_specimen",
        at_payload_cg=True,
        what="a mode of the declared rigid payload: m of its mass on a mode of frequency f, damping z (m (H(s) - 1) a)",
    )
)


def cg_offset_force(r, m: float, c, u6, a6, g: float, *, second_order: bool = True) -> np.ndarray:
    """(n, 6) generalised force (x, y, z; rx, ry, rz about the platen's reference point O,
    world axes) that a payload of mass ``m`` whose centre of gravity sits at ``c + r``
    (``c``: where it is declared, from O in the platen frame) needs beyond the one at ``c``,
    along a small motion: ``u6`` (n, 6) displacement (rotation vector theta), ``a6`` (n, 6)
    acceleration (translational a of O, angular alpha).

    The platen holds the payload with F = m (a + alpha x rho + g e_z) and, about O,
    M = rho x F + I_c alpha, rho = (c + r) + theta x (c + r) (the centre of gravity,
    turned with the platen; I_c its inertia about the centre of gravity, which the offset
    keeps). The part that depends on r, to first order in the motion:

    * F: m alpha x r (the offset centre's tangential acceleration), so the translational
      force changes too (by 3 kN at alpha = 0.5 rad/s^2 for 20 t at 0.3 m);
    * M: m r x a + m [c x (alpha x r) + r x (alpha x c)] (the moment of the inertial force
      and the coupling with the declared centre's lever arm: the parallel-axis terms linear
      in r) + m g (theta x r) x e_z = m g (r theta_z - theta r_z) (the weight's moment as
      the platen turns: a tilt moves a raised centre sideways) + m g r x e_z (static: the
      mechanical path removes each run's static part);
    * ``second_order``: m r x (alpha x r) = m (|r|^2 alpha - r (r . alpha)), the
      parallel-axis inertia of the offset itself (2600 kg m^2 about z for 20 t at
      (0.3, 0.2, 0) m, 0.7 % of CGS's yaw inertia with that payload; the law takes it,
      :func:`_cg_offset_second`).

    Left out: the centripetal terms (omega^2: 1e-3 of the alpha terms at the motions the
    tables run) and the change of the actuators' static forces with the linkage geometry
    (the static moment m g r x e_z times the Jacobian's change with the pose: of the order
    of the weight term)."""
    r = np.asarray(r, float)
    c = np.asarray(c, float)
    acc, alpha, th = a6[:, :3], a6[:, 3:], u6[:, 3:]
    F = m * np.cross(alpha, r)
    M = m * (np.cross(r, acc) + np.cross(c, np.cross(alpha, r)) + np.cross(r, np.cross(alpha, c)))
    M = M + m * g * (r[None, :] * th[:, 2:3] - th * r[2])
    if second_order:
        M = M + m * np.cross(r, np.cross(alpha, r))
    return np.hstack([F, M])


def _cg_offset(u, v, a, s):
    """The three columns (3, n, k) of the CG offset's first-order force, per metre of
    dx, dy, dz (:func:`cg_offset_force`; its second-order part: :func:`_cg_offset_second`), in the
    run's DOF space (``u``, ``a``: (n, k) of the DOFs ``s["_dofs"]``). The weight's term
    (displacement) goes through the sensor prefilter ``s["_filt"]``, the inertial terms
    not (the recorded acceleration already did)."""
    dofs = list(s["_dofs"])
    cols = [DOFS6.index(d) for d in dofs]
    u6 = np.zeros((len(u), 6))
    a6 = np.zeros((len(a), 6))
    u6[:, cols] = u
    a6[:, cols] = a
    m, c, g = s["_payload"]
    inert = np.zeros_like(u6)
    out = []
    for i in range(3):
        e = np.zeros(3)
        e[i] = 1.0
        Q = cg_offset_force(e, m, c, inert, a6, g, second_order=False)  # inertial part
        Q = Q + s["_filt"](cg_offset_force(e, m, c, u6, 0.0 * a6, g, second_order=False))  # weight part
        out.append(Q[:, cols])
    return np.stack(out)


def _cg_offset_second(u, v, a, s, values):
    """(n, k) the CG offset's second-order force m r x (alpha x r) at ``values`` (its
    parallel-axis inertia; :func:`cg_offset_force`)."""
    cols = [DOFS6.index(d) for d in s["_dofs"]]
    a6 = np.zeros((len(a), 6))
    a6[:, cols] = a
    m, c, g = s["_payload"]
    r = np.array([values["dx_m"], values["dy_m"], values["dz_m"]], float)
    full = cg_offset_force(r, m, c, np.zeros_like(a6), a6, g)
    return (full - cg_offset_force(r, m, c, np.zeros_like(a6), a6, g, second_order=False))[:, cols]


add_law(
    Law(
        "cg_offset",
        {"dx_m": ("m", -np.inf, np.inf), "dy_m": ("m", -np.inf, np.inf), "dz_m": ("m", -np.inf, np.inf)},
        ("dx_m", "dy_m", "dz_m"),
        _cg_offset,
        places=("payload",),
        inertial=True,  # the prefilter is applied inside (to the weight's term only)
        filters_inside=True,
        what="the payload's centre of gravity off where it is declared by (dx, dy, dz)",
        second_order=_cg_offset_second,
    )
)


#: effects of the library the mechanical path cannot identify, and why (the --effects error)
NOT_ON_MECHANICAL = {
    "foundation_mode": "the actuators push off the foundation, so its motion is not in the force "
    "the platen needs for its recorded motion (docs/calibration.md); calibrate runs with valve "
    "commands on the replay path (--path replay), where it is a candidate",
}


def declared_forces(entry: dict):
    """``(law, where, values)`` of a declared ``[[effect]]`` entry whose force is not in
    the MuJoCo model's joints (those the mechanical path reads from the compiled model:
    ``platen_spring`` is a joint stiffness, ``platen_coulomb`` a ``frictionloss``), else
    None: ``platen_power_damping``, a ``platen_coulomb`` with pre-sliding (a per-step
    force, taken here as its sliding limit), and effects of the library that act every
    physics step (``per_step``) or are not registered."""
    from sim.effects.base import EFFECTS

    kind = entry.get("type")
    where = "dof:" + str(entry.get("dof", "x"))
    grows = entry.get("grows_with", "none")
    if kind == "coulomb_friction" and grows != "none" and float(entry.get("coefficient", 0.0)) > 0:
        kind = f"coulomb_friction_{grows}"  # its own law (a level that changes: per step)
        if "where" in entry and "force_n" in entry and LAWS[kind].acts_at(str(entry["where"])):
            return LAWS[kind], str(entry["where"]), {k: float(entry[k]) for k in LAWS[kind].params}
    if kind == "platen_coulomb" and entry.get("presliding_m"):
        return LAWS["coulomb_friction"], where, {"force_n": float(entry["force_n"])}
    if kind == "platen_power_damping":
        return (
            LAWS["power_damping"],
            where,
            {"coefficient": float(entry["coefficient"]), "exponent": float(entry.get("exponent", 0.5))},
        )
    if kind in LAWS and "where" in entry:
        cls = EFFECTS.get(kind)
        if cls is not None and not getattr(cls, "per_step", False):
            return None  # built into the MJCF (edit_spec): read from the compiled joints
        law = LAWS[kind]
        vals = {k: float(entry[k]) for k in law.params if k in entry}
        if len(vals) == len(law.params) and len(law.linears) == 1:
            return law, str(entry["where"]), vals
    return None


def fixed_law(law: Law, name: str, value: float) -> Law | None:
    """``law`` with parameter ``name`` held at ``value`` (a bound): the nested law whose
    other parameters are refitted (dry friction growing with the stroke, its constant part
    at its bound 0: the pure growing law). A linear coefficient can be held only at 0 (its
    column dropped) and only beside another; None where no law is left."""
    import dataclasses

    base = law.base or law
    params = {k: p for k, p in law.params.items() if k != name}
    if name in law.linears:
        if value != 0.0 or len(law.linears) == 1 or law.second_order is not None:
            return None
        keep = [i for i, k in enumerate(law.linears) if k != name]
        lin = tuple(law.linears[i] for i in keep)
        one = len(keep) == 1

        def basis(u, v, a, s, _b=law.basis, _keep=tuple(keep), _one=one):
            b = _b(u, v, a, s)
            return b[_keep[0]] if _one else [b[i] for i in _keep]

        linear = lin[0] if len(lin) == 1 else lin
        shape = dict(law.shape)
    else:

        def basis(u, v, a, s, _b=law.basis, _n=name, _v=float(value)):
            return _b(u, v, a, {**s, _n: _v})

        linear, shape = law.linear, {k: g for k, g in law.shape.items() if k != name}
    return dataclasses.replace(
        law,
        type=f"{law.type}|{name}={value:g}",
        params=params,
        linear=linear,
        basis=basis,
        shape=shape,
        limits={k: x for k, x in law.limits.items() if k != name},
        nested={k: x for k, x in law.nested.items() if k != name},
        effect=base.name,
        fixed={**law.fixed, name: float(value)},
        base=base,
    )


def _recorded_force(u, v, a, s):
    raise NotImplementedError("the column is the place's recorded force (MechRun.columns)")


#: one actuator class's load cells reading ``gain`` x the force (a piston area or a unit
#: of one kind of actuator nobody wrote down), or one actuator's (its transducer): their
#: recorded force less the share ``read_excess = 1 - 1 / gain`` of it. Its column is that recorded force (its
#: noise is the load cells', a thousandth of the force: no bias worth a column of its
#: own). Written as the ``sensor_gain`` of the class's force columns
#: (:func:`sim.calibrate.mechsearch.added_entries`); its bounds are a gain of 0.5-2 (as
#: :data:`sim.calibrate.timing.FORCE_GAIN_RANGE`); the gain of every load cell at once
#: is the sensor candidate's (:mod:`sim.calibrate.timing`). CGS records with the vertical
#: class 5 % high: an added mass of 530 kg on the class, 520 kg in z and a friction of
#: 554 N on the class stood for it.
LOAD_CELLS_GAIN_CLASS = add_law(
    Law(
        type="load_cells_gain",
        params={"read_excess": ("1", -1.0, 0.5)},
        linear="read_excess",
        basis=_recorded_force,
        places=("class", "actuator"),
        what="one class's or actuator's load cells read gain x the force: read_excess = 1 - 1 / gain of it is not force",
        recorded_force=True,
    )
)


def class_gain(read_excess: float) -> float:
    """The class's load-cell gain of a :data:`LOAD_CELLS_GAIN_CLASS` coefficient."""
    return 1.0 / (1.0 - read_excess)


def usable(law: Law) -> bool:
    """A law is a candidate when its type is not registered, or registered with the same keys."""
    from sim.effects.base import EFFECTS

    cls = EFFECTS.get(law.name)
    return cls is None or set(law.params) <= set(getattr(cls, "SPEC", {}))


__all__ = [
    "DEADBAND",
    "LAWS",
    "LOAD_CELLS_GAIN_CLASS",
    "LINEAR_BELOW_M_S",
    "NOT_ON_MECHANICAL",
    "Law",
    "add_law",
    "cg_offset_force",
    "class_gain",
    "declared_forces",
    "fixed_law",
    "usable",
]
