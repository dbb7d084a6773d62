"""The Rice University shaking table's analytical transfer function (Eqs. 1-8 of [Trombetti 2002]).

Trombetti & Conte model the uni-axial, displacement-controlled table as a linear
input-output transfer function from the commanded displacement x_d to the achieved
absolute table displacement x_ta (paper, Sec. 3)::

    T(s) = x_ta / x_d = H(s) (1 + B(s))                                         (1)
    H(s) = x_t / x_d
         = S [(P + I/s) K_x + s (FF + D) K_D]
           / (1 + S [(P + I/s) K_x + s D K_D - dP s^2 (m_t/A) K_dp H_F])          (2)
    S(s) = x_t / x_c = H_t / (s^3 V m_t/(4 beta A) H_F + s^2 m_t k_le H_F + s A)  (3)
    H_t(s) = q_s / x_c = k_t e^{-tau s}                                            (8)
    H_F(s) = (1 + B) (1 + (m_p/m_t) H_p)                                          (5)
    B(s) = x_b / x_t = -s^2 (m_t/m_T) (1 + (m_p/m_t) H_p)
                       / (s^2 (1 + (m_p/m_T) H_p) + 2 xi_b w_b s + w_b^2)         (6)
    H_p(s) = (2 xi_p w_p s + w_p^2) / (s^2 + 2 xi_p w_p s + w_p^2)                (7)

with m_T = m_b + m_t, w_b^2 = k_b/m_T. x_t is the table displacement relative to the
foundation (the actuator LVDT, the controlled quantity), x_b the foundation's.

MDOF payloads. The paper uses, but does not print, an extension to frame payloads. For a
linear payload with modal damping on a base moving x_ta, the base shear is
s^2 x_ta sum_r M_r H_r(s) with M_r the modal effective masses (Gamma_r^2 for mass-
normalised modes) and H_r Eq. 7 of mode r; so ``m_p H_p`` -> ``sum_r M_r H_r`` in Eqs. 5
and 6 (exact for a linear frame; reduces to Eq. 7 for one mode). A rigid payload is
H_p = 1 (its mass adds to m_t).

Units: the paper's gains are the front-panel ones: P and dP in V/V, I in Hz (entering
as I/s, i.e. 1/s), D and FF in seconds. K_x, K_D in V/m, K_dp in V/Pa, k_t in
m^3/(V s), beta in Pa, k_le in m^3/(N s), tau in s. The numbers and their sources live
in ``scenarios/tables/rice.toml`` (read by :func:`load`); see the comments there for the
k_t unit correction and why the paper's dP values are negative.

``python -m sim.papers.rice`` prints the headline numbers (oil column, peaks, optimal case).
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field

import numpy as np

from mjcf.description import REPO_ROOT as ROOT  # noqa: E402
from sim.control.analog import Conditioning, Gains, RiceController  # noqa: F401 (re-exported for the paper's code)

TABLE_FILE = ROOT / "scenarios" / "tables" / "rice.toml"

# ------------------------------------------------------------------ figures of [Trombetti 2002]
#: Paper's statements used as targets ([Trombetti 2002]).
PAPER = {
    "oil_column_bare_hz": (67.0, 70.0),  # Sec. 6.1 "approximately 70 Hz"; Sec. 7 "67 Hz" (optimal gains)
    "foundation_hz": 27.1,  # Sec. 5.1
    "rigid_central_peak_hz": (36.0, 42.0),  # Sec. 8.1/8.2: central peak 36-40 (rigid) / 36-42 Hz (clamp model)
    "rigid_small_peak_hz": 57.0,  # Sec. 8.1/8.2: small peak ~57 Hz (split oil column)
    "clamp_hz": 52.0,  # Sec. 8.2: clamping SDOF 52 Hz
    "frame_oil_column_hz": 62.0,  # Sec. 8.3.1: oil column drops from ~70 to ~62 Hz
    "frame_modes_model_hz": {297: (7.22, 21.58, 33.86), 501: (5.53, 16.60, 26.15)},  # Table 4 (model)
    "frame_modes_measured_hz": {297: (6.40, 16.82, 22.20), 501: (5.15, 13.82, 20.05)},  # Table 4 (measured)
}


@dataclass(frozen=True)
class ParameterSet:
    """Effective servo-hydraulic parameters of one operating point (Tables 1 and 2)."""

    name: str
    kt_m3_per_v_s: float
    beta_pa: float
    kle_m3_per_n_s: float
    tau_s: float


@dataclass(frozen=True)
class Mode:
    """One payload mode for Eq. 7: effective mass (kg), frequency (Hz), damping ratio."""

    mass_kg: float
    f_hz: float
    zeta: float


@dataclass(frozen=True)
class RiceTable:
    """The known system parameters (Sec. 5.1) and everything else Eqs. 1-8 need."""

    area_m2: float
    volume_m3: float
    m_t: float
    m_b: float
    f_b_hz: float
    xi_b: float
    cond: Conditioning
    gains: Gains
    sets: dict = field(default_factory=dict)
    default_set: str = "d18"

    @property
    def params(self) -> ParameterSet:
        return self.sets[self.default_set]


def _raw(path=TABLE_FILE) -> dict:
    with open(path, "rb") as fh:
        return tomllib.load(fh)


def load(path=TABLE_FILE) -> RiceTable:
    """Read the paper's numbers from the table description (single source of truth).

    The physical parameters are recovered from the description in the paper's terms:
    A, V (= 2 (dead + A half_stroke) at mid-stroke), m_t (platen + rods), m_b
    (foundation body + cylinders), f_b and xi_b (undoing the builder's convention, see
    the table file).
    """
    raw = _raw(path)
    c = raw["controller"]
    cls = raw["actuator_class"]["main"]
    A = float(cls["area_a_m2"])
    V = float(cls["dead_volume_a_m3"] + cls["dead_volume_b_m3"]) + 2 * A * float(cls["half_stroke_m"])
    m_t = float(raw["platen"]["mass_kg"]) + float(cls["rod_mass_kg"])
    m_b = float(raw["foundation"]["mass_kg"]) + float(cls["cylinder_mass_kg"])
    f_spring = float(raw["foundation"]["frequency_hz"][0])
    z_spring = float(raw["foundation"]["damping_ratio"][0])
    # builder: k = m_body w'^2, c = 2 z' m_body w'; paper: w_b^2 = k/(m_b + m_t), xi_b = c/(2 sqrt(k (m_b+m_t)))
    mbody = float(raw["foundation"]["mass_kg"])
    k_b = mbody * (2 * math.pi * f_spring) ** 2
    c_b = 2 * z_spring * mbody * 2 * math.pi * f_spring
    mT = m_b + m_t
    f_b = math.sqrt(k_b / mT) / (2 * math.pi)
    xi_b = c_b / (2 * math.sqrt(k_b * mT))
    sets = {
        n: ParameterSet(
            n, float(s["kt_m3_per_v_s"]), float(s["beta_pa"]), float(s["kle_m3_per_n_s"]), float(s["tau_s"])
        )
        for n, s in c["parameter_sets"].items()
    }
    return RiceTable(
        area_m2=A,
        volume_m3=V,
        m_t=m_t,
        m_b=m_b,
        f_b_hz=f_b,
        xi_b=xi_b,
        cond=Conditioning(float(c["k_x_cond_v_per_m"]), float(c["k_d_cond_v_per_m"]), float(c["k_dp_cond_v_per_pa"])),
        gains=Gains(
            float(c["p_gain"]), float(c["i_gain_hz"]), float(c["d_gain_s"]), float(c["ff_gain_s"]), float(c["dp_gain"])
        ),
        sets=sets,
        default_set=str(c.get("parameter_set", "d18")),
    )


#: Optimal bare-table gains (Table 3) and the gain sweeps of Figs. 3-7 (other gains 0, P = 1).
OPTIMAL = Gains(p=1.8, i_hz=40.0, d_s=0.018, ff_s=0.018, dp=-3.0)
#: Sec. 8: the payload tests use the bare-table optimum with I 40 -> 30 Hz and dP -> 0.
PAYLOAD_GAINS = Gains(p=1.8, i_hz=30.0, d_s=0.018, ff_s=0.018, dp=0.0)
SWEEPS = {
    "P": [Gains(p=v) for v in (1.0, 2.0, 3.0)],  # Fig. 3, set d0
    "I": [Gains(i_hz=v) for v in (0.0, 20.0, 40.0)],  # Fig. 4, set d0
    "D": [Gains(d_s=v) for v in (0.0, 0.010, 0.020)],  # Fig. 5, sets d0/d10/d20
    "FF": [Gains(ff_s=v) for v in (0.0, 0.020, 0.030)],  # Fig. 6, set d0
    # Fig. 7 labels dP 0, 1.5, 3.0; in Eq. 2's sign convention the damping values are
    # negative (Table 3's optimum is -3.0; +3 makes the loop unstable), so these are used.
    "dP": [Gains(dp=v) for v in (0.0, -1.5, -3.0)],  # Fig. 7, set d0
}
#: Parameter set per D gain in the D sweep (Table 1).
D_SET = {0.0: "d0", 0.010: "d10", 0.018: "d18", 0.020: "d20"}


# ------------------------------------------------------------------ payloads
def rigid_modes(
    mass_kg: float, clamp_hz: float | None = None, zeta: float = 0.02, clamp_fraction: float = 1.0
) -> list[Mode]:
    """A rigid block: infinitely stiff (H_p = 1) or on a clamping SDOF (Sec. 8.2).

    Sec. 8.2 models the clamped block as "an SDOF payload with a natural frequency of
    52 Hz and a perfectly rigidly clamped payload" without giving the split:
    ``clamp_fraction`` of the mass is on the clamping SDOF, the rest is rigid (H_p = 1).
    """
    if clamp_hz is None:
        return [Mode(mass_kg, math.inf, 0.0)]
    if not 0.0 < clamp_fraction <= 1.0:
        raise ValueError(f"clamp_fraction must be in (0, 1] (got {clamp_fraction})")
    out = [Mode(clamp_fraction * mass_kg, clamp_hz, zeta)]
    if clamp_fraction < 1.0:
        out.insert(0, Mode((1.0 - clamp_fraction) * mass_kg, math.inf, 0.0))
    return out


def frame_modes(M, K, zeta: float) -> list[Mode]:
    """Modal effective masses and frequencies of a shear frame on the table (direction x)."""
    M = np.asarray(M, float)
    K = np.asarray(K, float)
    if M.ndim == 1:
        M = np.diag(M)
    w2, phi = _eig(K, M)
    r = np.ones(len(M))
    out = []
    for j in range(len(w2)):
        p = phi[:, j]
        gam = p @ M @ r / (p @ M @ p)
        out.append(Mode(float(gam**2 * (p @ M @ p)), float(np.sqrt(w2[j]) / (2 * np.pi)), zeta))
    return out


def _eig(K, M):
    L = np.linalg.cholesky(M)
    Li = np.linalg.inv(L)
    w2, y = np.linalg.eigh(Li @ K @ Li.T)
    return w2, Li.T @ y


def payload_from_file(path) -> list[Mode]:
    """Modes of a payload description (rigid with optional clamp, or shear frame)."""
    from mjcf.description import RigidPayload, ShearFramePayload, load_payload

    p = load_payload(path)
    if isinstance(p, RigidPayload):
        return rigid_modes(p.mass_kg, p.clamp_frequency_hz, p.clamp_damping_ratio, p.clamp_mass_fraction)
    if isinstance(p, ShearFramePayload):
        return frame_modes(p.mass_kg, p.stiffness_n_m, p.damping_ratio)
    raise ValueError(f"{path}: payload type not supported by the Rice transfer function")


def _mpHp(s, modes):
    """sum_r M_r H_r(s) (kg): Eq. 7 per mode (H = 1 for a rigid mode)."""
    out = np.zeros_like(s)
    for m in modes or []:
        if math.isinf(m.f_hz):
            out = out + m.mass_kg
        else:
            w = 2 * np.pi * m.f_hz
            out = out + m.mass_kg * (2 * m.zeta * w * s + w * w) / (s * s + 2 * m.zeta * w * s + w * w)
    return out


# ------------------------------------------------------------------ transfer functions
@dataclass
class TF:
    """Transfer functions on a frequency grid (complex arrays)."""

    f: np.ndarray
    T: np.ndarray
    H: np.ndarray
    B: np.ndarray
    S: np.ndarray


def transfer(
    f,
    table: RiceTable | None = None,
    gains: Gains | None = None,
    params: ParameterSet | str | None = None,
    payload: list[Mode] | None = None,
    *,
    delay: bool = True,
    foundation: bool = True,
) -> TF:
    """Eqs. 1-8 at frequencies ``f`` (Hz). ``delay=False``: tau = 0 (the paper's dashed
    curves); ``foundation=False``: rigid foundation (B = 0)."""
    tb = table or load()
    g = gains or tb.gains
    ps = tb.sets[params] if isinstance(params, str) else (params or tb.params)
    f = np.asarray(f, float)
    s = 2j * np.pi * f
    with np.errstate(divide="ignore", invalid="ignore"):
        A, V, mt = tb.area_m2, tb.volume_m3, tb.m_t
        mT = tb.m_b + mt
        wb = 2 * np.pi * tb.f_b_hz
        mpHp = _mpHp(s, payload)
        if foundation:
            B = -s * s * (mt / mT) * (1 + mpHp / mt) / (s * s * (1 + mpHp / mT) + 2 * tb.xi_b * wb * s + wb * wb)
        else:
            B = np.zeros_like(s)
        HF = (1 + B) * (1 + mpHp / mt)
        tau = ps.tau_s if delay else 0.0
        Ht = ps.kt_m3_per_v_s * np.exp(-tau * s)
        S = Ht / (s**3 * V * mt / (4 * ps.beta_pa * A) * HF + s * s * mt * ps.kle_m3_per_n_s * HF + s * A)
        c = tb.cond
        num = S * ((g.p + g.i_hz / s) * c.k_x + s * (g.ff_s + g.d_s) * c.k_d)
        den = 1 + S * ((g.p + g.i_hz / s) * c.k_x + s * g.d_s * c.k_d - g.dp * s * s * mt / A * c.k_dp * HF)
        H = num / den
        T = H * (1 + B)
    return TF(f=f, T=T, H=H, B=B, S=S)


def oil_column_hz(area_m2: float, volume_m3: float, mass_kg: float, beta_pa: float) -> float:
    """Eq. 11: f_oil = (A/pi) sqrt(beta / (V m_t))."""
    return area_m2 / math.pi * math.sqrt(beta_pa / (volume_m3 * mass_kg))


def peaks(f, mag, band, *, min_prominence=0.0) -> list[tuple[float, float]]:
    """Local maxima of ``mag`` inside ``band`` (parabolic interpolation), highest first."""
    f = np.asarray(f)
    mag = np.asarray(mag)
    out = []
    for i in range(1, len(f) - 1):
        if not (band[0] <= f[i] <= band[1]):
            continue
        if mag[i] >= mag[i - 1] and mag[i] > mag[i + 1]:
            y0, y1, y2 = mag[i - 1], mag[i], mag[i + 1]
            den = y0 - 2 * y1 + y2
            d = 0.5 * (y0 - y2) / den if den != 0 else 0.0
            df = f[i + 1] - f[i]
            if min_prominence > 0:
                lo = min(np.nanmin(mag[max(0, i - 40) : i], initial=y1), y1)
                hi_side = min(np.nanmin(mag[i + 1 : i + 41], initial=y1), y1)
                if y1 - max(lo, hi_side) < min_prominence:
                    continue
            if np.isfinite(y1):
                out.append((float(f[i] + d * df), float(y1 - 0.25 * (y0 - y2) * d)))
    out.sort(key=lambda p: -p[1])
    return out


def notch_in(f, mag, band) -> tuple[float, float]:
    """The lowest local minimum in ``band`` (f, |T|); (nan, nan) if none."""
    p = peaks(f, -np.asarray(mag), band)
    return (p[0][0], -p[0][1]) if p else (math.nan, math.nan)


def peak_in(f, mag, band) -> tuple[float, float]:
    """The highest local maximum in ``band`` (f, |T|); (nan, nan) if none."""
    p = peaks(f, mag, band)
    return p[0] if p else (math.nan, math.nan)


def summary() -> dict:
    """Headline numbers of the analytical model (the paper's statements)."""
    tb = load()
    f = np.linspace(0.05, 120, 24001)
    out = {
        "oil_column_eq11_hz": {
            n: oil_column_hz(tb.area_m2, tb.volume_m3, tb.m_t, s.beta_pa) for n, s in tb.sets.items()
        }
    }
    t = transfer(f, tb, OPTIMAL, "d18")
    m = np.abs(t.T)
    out["optimal"] = {
        "oil_peak": peak_in(f, m, (50, 90)),
        "foundation_peak": peak_in(f, m, (20, 30)),
        "low_peak": peak_in(f, m, (2, 12)),
    }
    return out


if __name__ == "__main__":  # pragma: no cover
    from sim.runs.files import json_text

    print(json_text(summary(), indent=1))
