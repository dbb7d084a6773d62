"""Least-squares identification of a uni-axial table's mechanical subsystem [Ozcelik 2008].

Ozcelik, Luco & Conte (2008) model the NEES-UCSD platen as (their Eq. 1)

    M_e u'' + K_e u + C_e |u'|^alpha sign(u') + F_mu sign(u') = F_act

and identify y = (M_e, K_e, C_e, F_mu) for a given alpha by minimising the normalised
force error over N pooled tests (Eq. 2)

    eps^2 = sum_i lam_i int (F_act - R^T y)^2 dt / sum_j lam_j int F_act^2 dt,
    R = (u'', u, |u'|^alpha sign u', sign u'),

whose normal equations are a y = b (Eqs. 4-10) with the normalised weights
lam_i / sum_j lam_j int F_j^2 dt (Eq. 8). Weights (their Fig. 3): "force" (lam_i =
1 / int F_i^2 dt, Eq. 14: every test counts alike; the paper's lambda^(4)), "unit"
(lam_i = 1, Eq. 16: lambda^(1)), "velocity" (1 / int u'^2 dt, lambda^(2)) and
"velocity_sqrt" (lambda^(3)). The constrained variant fixes C_e (the paper's 45.9 kN
(s/m)^0.5) and solves for the other three. ``alpha`` is scanned by :func:`scan_alpha`
(eps(alpha) is flat, so the paper picks alpha from the stability of C_e and F_mu across
single tests; :func:`per_test` gives those).

Equivalent linear damping and the peak-amplification locus (Eqs. 18-26, Table 8) are in
:func:`table8`; :func:`harmonic_amplification` integrates Eq. 1 under a harmonic force to
find the peak amplification the nonlinear model actually reaches (their Fig. 9).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from sim.errors import RunFileError

WEIGHTS = ("force", "unit", "velocity", "velocity_sqrt")


@dataclass
class Record:
    """One test: total actuator force and table motion at a uniform step ``dt``."""

    name: str
    dt: float
    force: np.ndarray
    acc: np.ndarray
    vel: np.ndarray
    disp: np.ndarray
    #: (b, a) of a filter already on ``acc`` and applied by :func:`regressors` to every other
    #: regressor (the force is filtered by :func:`prepare`); set by ``prepare(accel_lowpass_hz=...)``
    prefilter: tuple | None = None
    #: indices of the samples that enter the least squares (None: all); the filter runs on
    #: the whole record
    rows: np.ndarray | None = None

    def sl(self):
        return slice(None) if self.rows is None else self.rows

    @property
    def target(self) -> np.ndarray:
        """The force samples the least squares fits."""
        return self.force[self.sl()]


def analog_lowpass(cutoff_hz: float, fs: float, order: int = 4) -> tuple:
    """A Butterworth low-pass defined in continuous time (an analog signal conditioner)
    discretised at ``fs`` by the bilinear transform *without* pre-warping the cutoff, so
    that its low-frequency phase (the delay, 2.613 / (2 pi f_c) = 4.16 ms for 4 poles at
    100 Hz) is the analog filter's at any sampling rate. ``scipy.signal.butter(fs=...)``
    pre-warps the cutoff instead and its delay depends on the rate (4.03 ms at 1024 Hz,
    3.62 ms at 512 Hz): a 0.4 ms mismatch between a record's accelerometer filter and the
    filter applied to the other regressors reads as a viscous force M w^2 0.4 ms."""
    import scipy.signal as sig

    b, a = sig.butter(order, 2 * math.pi * cutoff_hz, analog=True)
    return sig.bilinear(b, a, fs)


@dataclass
class Identified:
    M_e_kg: float
    K_e_N_per_m: float
    C_e: float
    F_mu_N: float
    alpha: float
    error: float
    constrained: bool = False
    weights: str = "force"
    per_test_error: dict = field(default_factory=dict)

    def warnings(self) -> list[str]:
        """One line per unphysical fitted parameter (negative mass, stiffness, damping
        or friction), saying what it means: the model does not describe these records
        and the other parameters absorb what it misses."""
        out = []
        what = {
            "M_e_kg": (
                "M_e",
                "mass",
                "kg",
                "the acceleration term is fitting something else (a force "
                "channel's sign or scale, a time shift between force and motion, a filter)",
            ),
            "K_e_N_per_m": (
                "K_e",
                "stiffness",
                "N/m",
                "no restoring force is seen: the displacement drifts "
                "or the friction (or a flexible specimen's reaction) is taken for a spring; give tests that "
                "return to mid-stroke, on the bare table",
            ),
            "C_e": (
                "C_e",
                "damping",
                "N (s/m)^alpha",
                "the force does less than no dissipation: friction "
                "F_mu is over-fitted against it, or the force lags the motion (sensor filter); "
                "constrain it with --ce, or try another alpha",
            ),
            "F_mu_N": (
                "F_mu",
                "friction",
                "N",
                "the force does negative dry-friction work: the damping "
                "term takes more than all of it, or velocity and force are misaligned",
            ),
        }
        for key, (sym, kind, unit, why) in what.items():
            v = getattr(self, key)
            if key == "C_e" and self.constrained:
                continue
            if v < 0:
                out.append(
                    f"{sym} = {v:.4g} {unit} is negative: an unphysical {kind}. It means {why}; the other "
                    "parameters are then not the table's either (a flexible specimen's own dynamics are in the force: "
                    "identify the bare table)"
                )
        return out

    def as_dict(self) -> dict:
        return {
            "M_e_kg": self.M_e_kg,
            "K_e_N_per_m": self.K_e_N_per_m,
            "C_e": self.C_e,
            "F_mu_N": self.F_mu_N,
            "alpha": self.alpha,
            "error": self.error,
            "constrained": self.constrained,
            "weights": self.weights,
            "per_test_error": self.per_test_error,
            "warnings": self.warnings(),
        }


def prepare(
    rec: Record,
    *,
    trim: float | None = 0.01,
    accel_lowpass_hz: float | None = None,
    deadband_m_s: float | None = None,
    order: int = 4,
) -> Record:
    """Condition a record for the least squares.

    ``trim``: fit only the samples from the first to the last one where |u'| exceeds that
    fraction of its peak. At rest before and after a test the Coulomb element sticks and
    its force is anything in [-F_mu, F_mu], while Eq. 1 says F_mu sign(u') with sign
    taken from sensor noise: those samples only add error (in an El Centro record with
    its quiet pads they are 40 % of the samples and most of the residual).

    ``deadband_m_s``: the same holds *inside* a test wherever the platen stops: at every
    reversal it sticks while the actuator force swings through 2 F_mu (in the model's
    S1-S3 and T1-T3 that is 2-5 % of the samples), and wherever |u'| is below the
    velocity noise the sign of u' in Eq. 1 is the noise's. Samples with |u'| below the
    dead band are left out of the fit (with a prefilter, also the samples within the
    filter's memory after them, :func:`filter_memory_s`, because the filtered force
    carries their error on). The regressors are still computed on the whole record.

    ``accel_lowpass_hz``: the acceleration channel went through an analog low-pass (the
    LHPOST's conditioners: 100 Hz; ``order``-pole Butterworth, :func:`analog_lowpass`)
    that the force, displacement and velocity did not ([Ozcelik 2008]: pressures only
    high-pass filtered). The filter delays the inertia term by ~4 ms against the others,
    which in a 1 Hz test is a velocity-proportional error M w^2 4 ms u' of several kN
    that the least squares puts into C_e and F_mu. Eq. 1 is linear in (M_e, K_e, C_e,
    F_mu), so passing *every* term through the same filter keeps it exact:
    H[F] = M_e H[u''] + K_e H[u] + C_e H[|u'|^a sign u'] + F_mu H[sign u'], with
    H[u''] the recorded acceleration. The force is filtered here, the other regressors
    in :func:`regressors` (after the nonlinear functions of u', so that H[sign u'] is the
    filtered friction force the filtered record contains). Filtering the force alone
    is not enough: K_e H[u] - K_e u = -K_e 4 ms u' is then the velocity-proportional
    error.
    """
    F = np.asarray(rec.force, float)
    v = np.asarray(rec.vel, float)
    n = len(v)
    pre = None
    if accel_lowpass_hz:
        import scipy.signal as sig

        pre = analog_lowpass(accel_lowpass_hz, 1.0 / rec.dt, order)
        F = sig.lfilter(*pre, F)
    keep = np.ones(n, bool)
    if trim:
        vmax = np.max(np.abs(v))
        on = np.flatnonzero(np.abs(v) > trim * vmax)
        if len(on) >= 16:
            keep[: on[0]] = False
            keep[on[-1] + 1 :] = False
    if deadband_m_s:
        still = np.abs(v) < deadband_m_s
        if pre is not None:  # the filtered force carries a stuck sample's error for the filter's memory
            m = int(math.ceil(filter_memory_s(pre, rec.dt) / rec.dt))
            still = np.convolve(still.astype(float), np.ones(m + 1))[:n] > 0
        if np.count_nonzero(keep & ~still) >= 16:
            keep &= ~still
    rows = None if keep.all() else np.flatnonzero(keep)
    return Record(
        name=rec.name,
        dt=rec.dt,
        force=F,
        acc=np.asarray(rec.acc, float),
        vel=v,
        disp=np.asarray(rec.disp, float),
        prefilter=pre,
        rows=rows,
    )


def filter_memory_s(ba: tuple, dt: float, tol: float = 0.01) -> float:
    """How long a filter remembers an input sample: the time after which its impulse
    response stays below ``tol`` of its peak (4 poles at 100 Hz: 31 ms at 512 Hz, 24 ms at 1024 Hz)."""
    import scipy.signal as sig

    n = int(round(1.0 / dt))  # one second is plenty for the low-passes used here
    x = np.zeros(n)
    x[0] = 1.0
    h = np.abs(sig.lfilter(*ba, x))
    above = np.flatnonzero(h > tol * h.max())
    return float((above[-1] + 1) * dt) if len(above) else 0.0


def regressors(rec: Record, alpha: float) -> np.ndarray:
    """R (N, 4): u'', u, |u'|^alpha sign u', sign u' (Eq. 7), over the record's window;
    with a ``prefilter`` every column but the (already filtered) acceleration is filtered."""
    v = rec.vel
    R = np.column_stack([rec.acc, rec.disp, np.abs(v) ** alpha * np.sign(v), np.sign(v)])
    if rec.prefilter is not None:
        import scipy.signal as sig

        R[:, 1:] = sig.lfilter(*rec.prefilter, R[:, 1:], axis=0)
    return R[rec.sl()]


def _weight(rec: Record, kind: str) -> float:
    v = rec.vel[rec.sl()]
    if kind == "force":
        return 1.0 / (np.sum(rec.target**2) * rec.dt)
    if kind == "unit":
        return 1.0
    if kind == "velocity":
        return 1.0 / (np.sum(v**2) * rec.dt)
    if kind == "velocity_sqrt":
        return 1.0 / math.sqrt(np.sum(v**2) * rec.dt)
    raise ValueError(f"weights must be one of {', '.join(WEIGHTS)} (got {kind!r})")


def identify(
    records: list[Record], alpha: float = 0.5, *, weights: str = "force", ce_fixed: float | None = None
) -> Identified:
    """Pooled least squares (Eqs. 2-11); ``ce_fixed`` constrains C_e to that value."""
    if not records:
        raise ValueError("no records to identify from")
    lam = np.array([_weight(r, weights) for r in records])
    E = np.array([np.sum(r.target**2) * r.dt for r in records])
    lbar = lam / np.sum(lam * E)
    a = np.zeros((4, 4))
    b = np.zeros(4)
    Rs = []
    for w, r in zip(lbar, records):
        R = regressors(r, alpha)
        Rs.append(R)
        a += w * (R.T @ R) * r.dt
        b += w * (R.T @ r.target) * r.dt
    if ce_fixed is None:
        y = np.linalg.solve(a, b)
    else:  # move the C_e column to the right-hand side
        keep = [0, 1, 3]
        bb = b[keep] - a[np.ix_(keep, [2])][:, 0] * ce_fixed
        yk = np.linalg.solve(a[np.ix_(keep, keep)], bb)
        y = np.array([yk[0], yk[1], ce_fixed, yk[2]])
    per, tot = {}, 0.0
    for w, r, R, e in zip(lbar, records, Rs, E):
        res = np.sum((r.target - R @ y) ** 2) * r.dt
        per[r.name] = float(math.sqrt(res / e))
        tot += w * res
    return Identified(
        M_e_kg=float(y[0]),
        K_e_N_per_m=float(y[1]),
        C_e=float(y[2]),
        F_mu_N=float(y[3]),
        alpha=float(alpha),
        error=float(math.sqrt(max(tot, 0.0))),
        constrained=ce_fixed is not None,
        weights=weights,
        per_test_error=per,
    )


def holdout_errors(res: Identified, records: list[Record]) -> dict:
    """The identified model ``res`` scored on records it was not fitted to: per record,
    the normalised force error of Eq. 2 with ``res``'s parameters,
    sqrt(int (F - R y)^2 dt / int F^2 dt) (the measure ``per_test_error`` gives the fit's
    own records)."""
    y = np.array([res.M_e_kg, res.K_e_N_per_m, res.C_e, res.F_mu_N])
    out = {}
    for r in records:
        R = regressors(r, res.alpha)
        e = np.sum(r.target**2) * r.dt
        out[r.name] = float(math.sqrt(np.sum((r.target - R @ y) ** 2) * r.dt / e)) if e > 0 else float("nan")
    return out


def scan_alpha(records, alphas=None, **kw) -> list[Identified]:
    """eps and parameters for alpha in (0, 1] (the paper's Fig. 3; alpha = 0 would make the
    viscous term a second Coulomb term, a singular system)."""
    alphas = np.linspace(0.1, 1.0, 10) if alphas is None else alphas
    return [identify(records, float(a), **kw) for a in alphas]


def per_test(records, alpha: float = 0.5, **kw) -> dict:
    """Each test identified alone (the paper's Fig. 4: stability of C_e and F_mu)."""
    return {r.name: identify([r], alpha, **kw) for r in records}


# ------------------------------------------------------------------ run files
def record_from_run(path) -> Record:
    """A :class:`Record` from a uni-axial run file: actuator force summed over the
    actuators (the actuators are taken to extend along the table's +x, as in the
    project's uni-axial descriptions), table displacement/velocity/acceleration x."""
    from sim.runs.runfile import read_run

    run = read_run(path, require=("actuator_force", "table_displacement", "table_acceleration"))
    name = run.name
    if "x" not in run.dofs:
        raise RunFileError(
            f"{name}: has no 'x' DOF column; the ucsd-ls model identifies the x motion of a uni-axial table"
        )
    _check_uniaxial(run)
    F = np.asarray(run.actuator_force, float).sum(axis=1)
    d = np.asarray(run.column("table_displacement", "x"), float)
    if run.table_velocity is not None:
        v = np.asarray(run.column("table_velocity", "x"), float)
    else:  # a lab's record often has none: the displacement's central difference
        v = np.gradient(d, run.dt)
    a = np.asarray(run.column("table_acceleration", "x"), float)
    for ch, arr in (("actuator_force", F), ("table_displacement", d), ("table_velocity", v), ("table_acceleration", a)):
        if not np.all(np.isfinite(arr)):
            k = int(np.argmin(np.isfinite(arr)))
            raise RunFileError(
                f"{name}: channel {ch} has NaN/inf (first at sample {k}); the identification needs "
                "finite force, displacement, velocity and acceleration"
            )
    if len(F) < 16:
        raise RunFileError(f"{name}: only {len(F)} samples; the identification needs a test record")
    return Record(name=name, dt=run.dt, force=F, acc=a, vel=v, disp=d)


def _check_uniaxial(run) -> None:
    """Refuse a run that is not from a uni-axial table: its table description (when it
    can be loaded) has more than one DOF, or its table moved in a DOF other than x (a
    uni-axial table's run files carry those columns as exact zeros). The model sums the
    actuator forces as one force along x: for a multi-axis table that sum is meaningless
    and the fit returns negative masses or stiffnesses."""
    from mjcf.errors import MjcfError
    from sim.runs.runfile import table_of

    try:
        desc = table_of(run)  # the description the run carries, else the stock one it names
    except MjcfError:  # a measured run of a table without a description here: judge by its data
        desc = None
    if desc is not None and list(desc.dofs) != ["x"]:
        raise RunFileError(
            f"{run.name}: is a run of table '{desc.name}' with DOFs {', '.join(desc.dofs)}; "
            "ucsd-ls identifies a uni-axial table (one DOF, x): give runs of such a table"
        )
    td = np.asarray(run.table_displacement, float)
    moving = [d for j, d in enumerate(run.dofs) if d != "x" and np.any(td[:, j] != 0)]
    if moving:
        raise RunFileError(
            f"{run.name}: the table moves in {', '.join(moving)} as well as x; ucsd-ls identifies "
            "a uni-axial table (one DOF, x): give runs of such a table"
        )


# ------------------------------------------------------------------ Table 8 (Eqs. 18-26)
def gamma_factors(alpha: float) -> tuple[float, float]:
    """gamma_1 = 4/pi and gamma_2 (Eq. 22) for a sinusoidal velocity."""
    g1 = 4.0 / math.pi
    # the paper's Eq. 22 in closed form: int |sin|^(1+a) / int sin^2 over a period
    g2 = 2.0 / math.sqrt(math.pi) * math.gamma(1 + alpha / 2) / math.gamma(1.5 + alpha / 2)
    return g1, g2


def xi_equivalent(v, M, K, C, F, alpha=0.5):
    """Eq. 24: equivalent linear damping ratio at peak velocity v (m/s)."""
    g1, g2 = gamma_factors(alpha)
    w = math.sqrt(K / M)
    v = np.asarray(v, float)
    return g1 / 2 * F * w / (K * v) + g2 / 2 * C * w / (K * v ** (1 - alpha))


def table8(v_m_s, M, K, C, F, alpha=0.5) -> list[dict]:
    """Eqs. 24-26: xi_e, f_m, A_m, u_max, F_0 for each peak velocity."""
    fe = math.sqrt(K / M) / (2 * math.pi)
    out = []
    for v in v_m_s:
        xi = float(xi_equivalent(v, M, K, C, F, alpha))
        fm = fe * math.sqrt(max(1 - 2 * xi * xi, 0.0))
        Am = 1.0 / (2 * xi * math.sqrt(1 - xi * xi))
        u = v / (2 * math.pi * fm)
        out.append(
            {
                "v_cm_s": 100 * v,
                "xi_pct": 100 * xi,
                "f_m_hz": fm,
                "A_m": Am,
                "u_max_cm": 100 * u,
                "F0_kN": K * u / Am / 1e3,
            }
        )
    return out


def harmonic_amplification(F0, M, K, C, F, alpha=0.5, *, f_hz=None, cycles=30, steps_per_cycle=2000) -> dict:
    """Steady-state peak displacement of Eq. 1 under F0 sin(2 pi f t), swept over f.

    Semi-implicit Euler with the Coulomb term as a stick-slip switch (the platen sticks
    while |F_act - K u| <= F_mu at rest). Returns the frequency of the largest
    amplification R_d = u_max / (F0 / K) and that R_d (the paper's Fig. 9 curves).
    """
    fe = math.sqrt(K / M) / (2 * math.pi)
    freqs = np.linspace(0.7 * fe, 1.1 * fe, 41) if f_hz is None else np.asarray(f_hz)
    best = (math.nan, -1.0)
    curve = []
    for f in freqs:
        dt = 1.0 / (f * steps_per_cycle)
        u = v = 0.0
        umax = 0.0
        w = 2 * math.pi * f
        n = cycles * steps_per_cycle
        for k in range(n):
            fa = F0 * math.sin(w * k * dt)
            fs = fa - K * u - C * abs(v) ** alpha * math.copysign(1.0, v) if v != 0 else fa - K * u
            if v == 0.0 and abs(fs) <= F:
                acc = 0.0
            else:
                s = math.copysign(1.0, v) if v != 0 else math.copysign(1.0, fs)
                acc = (fs - F * s) / M
            vn = v + acc * dt
            if v != 0.0 and vn * v < 0:  # velocity reversal: stop, let the stick test decide
                vn = 0.0
            v = vn
            u += v * dt
            if k >= n - 3 * steps_per_cycle:
                umax = max(umax, abs(u))
        R = umax / (F0 / K)
        curve.append((float(f), float(R)))
        if R > best[1]:
            best = (float(f), float(R))
    return {"f_peak_hz": best[0], "R_peak": best[1], "curve": curve}
