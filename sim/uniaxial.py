"""The two uni-axial papers' test programmes run on the model (MuJoCo + hydraulics).

Rice (seed 001): :func:`rice_frf` builds the Rice table (``scenarios/tables/rice.toml``)
with one of the paper's effective servo-hydraulic parameter sets applied, optionally a
payload, and runs the paper's random test: a white-noise acceleration command,
11 segments of 2^14 samples at 4000 Hz (plus a lead-in that is discarded, the paper's
"elimination of the transient"), Bartlett averaging (no overlap) with a 3-term
Blackman-Harris window (:func:`sim.estimation.frf`), FRF commanded -> achieved absolute
table acceleration (= x_ta/x_d of Eq. 1).

Rate. The Rice controller is analog; it is evaluated at every physics step of
1/8000 s (``BuildOptions(timestep_s=1/8000)``), so its zero-order hold adds 0.06 ms to
the valve delay, and the records are taken every second step: 4000 Hz, the paper's
DAQ rate, so the segment length, count, window and the 0.244 Hz resolution are the
paper's. The loop is this module's own (``sim.loop.Simulation`` runs the MTS-style
controller at 1024 Hz); it uses the same model (:func:`mjcf.builder.build`) and
hydraulics (:class:`hydraulics.HydraulicSystem`) and the same coupling order as
``sim/loop.py`` (hydraulic step before ``mj_step``, end-of-step pressures).

UCSD (seed 002): see :func:`ucsd_programme` further down.
"""

from __future__ import annotations

import copy
import math
import time
from dataclasses import dataclass

import mujoco
import numpy as np

from hydraulics import HydraulicParams, HydraulicSystem
from mjcf.builder import BuildOptions, build
from mjcf.description import load_payload, parse_table
from sim import rice as R

RICE_RATE_HZ = 8000.0
RICE_FS_HZ = 4000.0
RICE_NPERSEG = 2 ** 14
RICE_SEGMENTS = 11


def rice_description(parameter_set: str = "d18", *, delay: bool = True, path=R.TABLE_FILE):
    """The Rice table description with a parameter set (Tables 1-2) applied.

    beta -> fluid.bulk_modulus_pa, k_le -> cross leakage k_le * A, tau -> valve delay
    (0 with ``delay=False``). k_t is the controller's volt-to-flow scale (returned).
    """
    raw = copy.deepcopy(R._raw(path))
    ps = raw["controller"]["parameter_sets"][parameter_set]
    raw["fluid"]["bulk_modulus_pa"] = float(ps["beta_pa"])
    cls = raw["actuator_class"]["main"]
    cls["leakage_cross_m3_s_pa"] = float(ps["kle_m3_per_n_s"]) * float(cls["area_a_m2"])
    raw["servovalve"]["delay_s"] = float(ps["tau_s"]) if delay else 0.0
    desc = parse_table(raw, f"{path} [{parameter_set}{'' if delay else ', tau = 0'}]")
    return desc, float(ps["kt_m3_per_v_s"])


def white_noise_command(n: int, fs: float, *, rms_m_s2: float = 2.0, band_hz=(0.3, 250.0), seed: int = 0):
    """Band-limited white-noise acceleration and its exact double integral (FFT synthesis).

    Flat acceleration spectrum inside ``band_hz`` with cosine tapers over the lowest and
    highest 20 % of the band edges; displacement, velocity and acceleration are the same
    periodic signal differentiated in the frequency domain (no drift).
    """
    rng = np.random.default_rng(seed)
    f = np.fft.rfftfreq(n, 1 / fs)
    lo, hi = band_hz
    w = np.zeros_like(f)
    inside = (f >= lo) & (f <= hi)
    w[inside] = 1.0
    ramp_lo = (f >= lo) & (f < 2 * lo)
    w[ramp_lo] = 0.5 - 0.5 * np.cos(np.pi * (f[ramp_lo] - lo) / lo)
    ramp_hi = (f > 0.8 * hi) & (f <= hi)
    w[ramp_hi] = 0.5 + 0.5 * np.cos(np.pi * (f[ramp_hi] - 0.8 * hi) / (0.2 * hi))
    A = w * (rng.standard_normal(len(f)) + 1j * rng.standard_normal(len(f)))
    a = np.fft.irfft(A, n)
    scale = rms_m_s2 / a.std()
    A *= scale
    jw = 2j * np.pi * f
    with np.errstate(divide="ignore", invalid="ignore"):
        V = np.where(f > 0, A / jw, 0)
        D = np.where(f > 0, A / jw ** 2, 0)
    return np.fft.irfft(D, n), np.fft.irfft(V, n), np.fft.irfft(A, n)


@dataclass
class RiceRun:
    """Records of one Rice random test at 4000 Hz and its FRF."""

    t: np.ndarray
    a_cmd: np.ndarray
    a_table: np.ndarray
    x_cmd: np.ndarray
    x_table: np.ndarray
    stroke: np.ndarray
    dp: np.ndarray
    opening: np.ndarray
    frf: object
    wall_s: float
    gains: R.Gains
    parameter_set: str
    delay: bool
    payload: str | None


def rice_simulation(gains: R.Gains, parameter_set: str = "d18", *, payload: str | None = None, delay: bool = True,
                    n_segments: int = RICE_SEGMENTS, nperseg: int = RICE_NPERSEG, lead_in_s: float = 2.0,
                    rms_m_s2: float = 2.0, seed: int = 1, backend: str = "numba") -> RiceRun:
    """Run the paper's random test on the model and estimate T (see module docstring)."""
    from sim.estimation import frf

    desc, kt = rice_description(parameter_set, delay=delay)
    pl = load_payload(payload) if payload else None
    tm = build(desc, pl, BuildOptions(timestep_s=1.0 / RICE_RATE_HZ))
    m = tm.model
    d = tm.new_data()
    dt = float(m.opt.timestep)
    hp = HydraulicParams.from_table(desc.raw)
    hs = HydraulicSystem(hp, n_sim=1, dt=dt, backend=backend)
    q_full = float(hs.no_load_flow(1.0))
    tb = R.load()
    ctl = R.RiceController(gains, tb.cond, kt, q_full, dt)
    sub = int(round(RICE_RATE_HZ / RICE_FS_HZ))
    n_rec = n_segments * nperseg
    n_lead = int(round(lead_in_s * RICE_FS_HZ))
    n_tot = (n_rec + n_lead) * sub
    # the command is periodic over the recorded length; the lead-in is its tail
    xd, vd, ad = white_noise_command(n_rec * sub, RICE_RATE_HZ, rms_m_s2=rms_m_s2, seed=seed)
    idx = (np.arange(n_tot) - n_lead * sub) % (n_rec * sub)
    # ramp the command in over the first second of the lead-in
    ramp = np.clip(np.arange(n_tot) / (RICE_RATE_HZ * 1.0), 0, 1)
    ramp = 0.5 - 0.5 * np.cos(np.pi * ramp)
    XD, VD, AD = xd[idx] * ramp, vd[idx] * ramp, ad[idx] * ramp  # ramp-in transient is discarded
    x2 = np.zeros((1, 1))
    v2 = np.zeros((1, 1))
    c2 = np.zeros((1, 1))
    hs.reset(tm.actuator_strokes(d)[None, :])
    d.ctrl[tm.actuator_ids] = hs.force[0]
    mujoco.mj_forward(m, d)
    qs, ds = int(tm.stroke_qadr[0]), int(tm.stroke_dadr[0])
    jf = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "foundation_x")
    qf, df_ = int(m.jnt_qposadr[jf]), int(m.jnt_dofadr[jf])
    qp, dp_ = int(tm.platen_slide_qadr[0]), int(tm.platen_slide_dadr[0])
    aid = int(tm.actuator_ids[0])
    st = hs.state
    pa, pb = st.p_a, st.p_b
    qpos, qvel, qacc, ctrl = d.qpos, d.qvel, d.qacc, d.ctrl
    rec = {k: np.zeros(n_rec) for k in ("a_table", "x_table", "stroke", "dp", "opening")}
    step = mujoco.mj_step
    hstep = hs.step
    wall0 = time.perf_counter()
    for k in range(n_tot):
        x = qpos[qs]
        v = qvel[ds]
        dpk = pa[0, 0] - pb[0, 0]
        u = ctl.opening(XD[k], VD[k], x, v, dpk)
        c2[0, 0] = u
        x2[0, 0] = x
        v2[0, 0] = v
        f = hstep(c2, x2, v2)
        ctrl[aid] = f[0, 0]
        step(m, d)
        j = k - n_lead * sub
        if j >= 0 and j % sub == 0:
            i = j // sub
            rec["a_table"][i] = qacc[df_] + qacc[dp_]
            rec["x_table"][i] = qpos[qf] + qpos[qp]
            rec["stroke"][i] = x
            rec["dp"][i] = dpk
            rec["opening"][i] = u
        if not math.isfinite(x) or abs(x) > desc.actuator_classes["main"].half_stroke_m:
            raise RuntimeError(f"Rice simulation left the stroke at t = {k * dt:.3f} s (gains {gains}); unstable loop?")
    wall = time.perf_counter() - wall0
    a_cmd = ad[::sub][:n_rec]
    x_cmd = xd[::sub][:n_rec]
    fr = frf(a_cmd, rec["a_table"], RICE_FS_HZ, nperseg=nperseg, overlap=0.0, window="blackmanharris",
             estimator="H1", detrend=False)
    return RiceRun(t=np.arange(n_rec) / RICE_FS_HZ, a_cmd=a_cmd, x_cmd=x_cmd, frf=fr, wall_s=wall, gains=gains,
                   parameter_set=parameter_set, delay=delay, payload=payload, **rec)


# ------------------------------------------------------------------ Rice: the paper's cases
@dataclass(frozen=True)
class RiceCase:
    """One operating condition of the paper: gains, parameter set, payload, delay on/off."""

    name: str
    gains: R.Gains
    parameter_set: str
    payload: str | None = None
    delay: bool = True
    figure: str = ""


def rice_cases() -> list[RiceCase]:
    """The paper's conditions (Figs. 3-7, 9, 11-13) that the report runs on the model."""
    G = R.Gains
    P = R.PAYLOAD_GAINS
    out = [RiceCase("P1 (all others 0)", G(), "d0", figure="Figs. 3-7 base")]
    out += [RiceCase(f"P{v:g}", G(p=v), "d0", figure="Fig. 3") for v in (2.0, 3.0)]
    out += [RiceCase(f"P{v:g} tau=0", G(p=v), "d0", delay=False, figure="Fig. 3 dashed") for v in (1.0, 2.0)]
    out += [RiceCase(f"I{v:g} Hz", G(i_hz=v), "d0", figure="Fig. 4") for v in (20.0, 40.0)]
    out += [RiceCase(f"D{v * 1e3:g} ms", G(d_s=v), R.D_SET[v], figure="Fig. 5") for v in (0.010, 0.020)]
    out += [RiceCase(f"FF{v * 1e3:g} ms", G(ff_s=v), "d0", figure="Fig. 6") for v in (0.020, 0.030)]
    out += [RiceCase(f"dP{v:g}", G(dp=v), "d0", figure="Fig. 7") for v in (-1.5, -3.0)]
    out += [RiceCase("optimal", R.OPTIMAL, "d18", figure="Fig. 9"),
            RiceCase("optimal tau=0", R.OPTIMAL, "d18", delay=False, figure="Fig. 9 dashed"),
            RiceCase("bare, payload gains", P, "d18", figure="Sec. 8 reference")]
    out += [RiceCase(f"rigid {m} kg", P, "pr", f"rice_rigid_{m}", figure="Fig. 11") for m in (68, 204, 408)]
    out += [RiceCase(f"rigid {m} kg, 52 Hz clamp", P, "pfr", f"rice_rigid_{m}_clamp", figure="Fig. 12")
            for m in (68, 204, 408)]
    out += [RiceCase(f"frame {m} kg", P, "pf", f"frame_3storey_{m}", figure="Fig. 13") for m in (297, 501)]
    return out


def _smooth(y, n=5):
    k = np.ones(n) / n
    return np.convolve(np.pad(y, n // 2, mode="edge"), k, mode="valid")


def rice_metrics(f, mag, modes=None) -> dict:
    """Peaks of a |T| curve in the bands the paper discusses (f Hz, |T|); with payload
    modes, the spike nearest each modal frequency (within +/-1.5 Hz)."""
    spikes = [R.peak_in(f, mag, (m.f_hz - 1.5, m.f_hz + 1.5)) for m in (modes or []) if math.isfinite(m.f_hz)
              and m.f_hz < 45]
    return {
        "spikes": spikes,
        "foundation_notch": R.notch_in(f, mag, (25.5, 32.0)),
        "low_peak": R.peak_in(f, mag, (2.0, 20.0)),
        "foundation_peak": R.peak_in(f, mag, (22.0, 31.0)),
        "central_peak": R.peak_in(f, mag, (30.0, 50.0)),
        "oil_peak": R.peak_in(f, mag, (45.0, 90.0)),
        "small_peak": R.peak_in(f, mag, (50.0, 65.0)),
        "T_10Hz": float(np.interp(10.0, f, mag)),
        "T_40Hz": float(np.interp(40.0, f, mag)),
    }


def run_rice_case(case: RiceCase, n_segments: int = RICE_SEGMENTS, rms_m_s2: float = 0.5, seed: int = 1) -> dict:
    """Model FRF and analytical T(s) of one case, with their peak metrics and the error."""
    run = rice_simulation(case.gains, case.parameter_set, payload=case.payload, delay=case.delay,
                          n_segments=n_segments, rms_m_s2=rms_m_s2, seed=seed)
    f = run.frf.f
    modes = R.payload_from_file(case.payload) if case.payload else None
    T = R.transfer(f, None, case.gains, case.parameter_set, modes, delay=case.delay).T
    Hm = np.abs(run.frf.H)
    band = (f > 0) & (f <= 100.0)
    err = np.abs(Hm / np.abs(T) - 1)[band]
    return {"case": case, "f": f, "model": run.frf.H, "analytical": T, "coherence": run.frf.coherence,
            "model_metrics": rice_metrics(f, _smooth(Hm), modes), "analytical_metrics": rice_metrics(f, np.abs(T), modes),
            "max_error_0_100": float(err.max()), "f_max_error": float(f[band][err.argmax()]),
            "rms_error_0_100": float(np.sqrt((err ** 2).mean())), "wall_s": run.wall_s}


def run_rice_programme(cases=None, workers: int = 2, **kw) -> list[dict]:
    cases = cases or rice_cases()
    if workers <= 1:
        return [run_rice_case(c, **kw) for c in cases]
    from concurrent.futures import ProcessPoolExecutor
    from functools import partial

    with ProcessPoolExecutor(workers) as ex:
        return list(ex.map(partial(run_rice_case, **kw), cases))
