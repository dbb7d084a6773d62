"""Servo-hydraulic actuators, servovalves and supply of a shaking table (no MuJoCo here).

Where the step sits
-------------------
One hydraulic step per physics step, BEFORE it. At time t_n the simulator reads the
piston positions x_n and velocities v_n of the current mechanical state, calls
``F = hs.step(command_n, x_n, v_n)``, applies F (and, if it wants, ``seal_friction(v_n)``)
to MuJoCo, then MuJoCo steps t_n -> t_n + dt. The step advances the hydraulic state
t_n -> t_n + dt with the piston moving at v_n over the step and returns the force of the
pressures at t_n + dt (the end of the step). Using the end-of-step pressure makes the
oil column a position-consistent spring for the semi-implicit (symplectic) Euler of
MuJoCo: the pressure change over the step is -beta A v_n dt / V, and v_n dt is exactly
the position increment MuJoCo made on the previous step, so the oil column neither
gains nor loses energy from the coupling (a lagged force would pump energy in).

Model (per actuator, arrays of shape (n_sim, n_act))
----------------------------------------------------
Servovalve: command u (fraction of rated opening) -> pure delay of round(delay_s/dt)
steps (ring buffer; the realised delay is that integer number of steps, within dt/2 of
delay_s) -> first-order (tau) or second-order (wn, zeta) main stage, discretised EXACTLY
for a zero-order-held input (y_{n+1} = e^{A dt} y_n + A^-1 (e^{A dt} - I) B u_n) -> optional
slew limit -> saturation at +/-1. With no delay, the spool after step n already
responds to command n (the command is held over the step). Per actuator (overrides in
``HydraulicParams.PER_ACTUATOR``, set by hydraulic effects): the delay (each actuator
reads the shared delay line at its own depth), tau or wn, a null offset added to the
delayed command (a valve bias), a flow gain factor on K (all four lands, null leakage
included) and the chamber bulk modulus. ``no_load_flow`` and ``valve_gain`` stay the
nominal (scalar) valve: what a controller designed from the data sheet assumes.

Metering: four lands, critically lapped unless ``overlap`` > 0 (the opening starts at
|y| = overlap and reaches 1 at |y| = 1). Land flow Q = K o g(dp) with
g = sign(dp) sqrt(|dp|) beyond ``laminar_drop_pa`` and a C1 odd cubic inside (finite
slope 5/(4 sqrt(dl)) at dp = 0). K is set so that ``rated_flow_m3_s`` flows at full
opening with no load when the TOTAL valve drop is ``rated_drop_pa``: two lands in
series each dropping rated_drop/2, K = Q_rated / sqrt(rated_drop/2). Null leakage is a
residual opening o_leak of every land (o = o_open + o_leak (1 - o_open)) chosen so that
at null, ports blocked, supply at its set pressure, the valve passes
``null_leakage_m3_s`` from P to T.

Chambers: V_a = dead_a + A_a (half_stroke + x), V_b = dead_b + A_b (half_stroke - x)
(x clamped to the stroke in the volumes), (V / beta_eff(p)) dp/dt = Q_valve - A dx/dt
- cross leakage k_c (p_a - p_b) - external leakage k_e p (to a drain at 0 Pa gauge).
beta_eff is constant unless ``fluid.entrained_air_fraction`` > 0 (free air, polytropic).
Pressures are clipped to [vapour, relief]; each clip is counted and the oil it removes
(relief) or the void it creates (cavitation) is booked.

Integration: linearly implicit (Rosenbrock-Euler) in the pressures. Over a step the
land flows are linearised about the pressures at t_n, and chamber pressures of all
actuators and the supply pressure are solved together (a bordered system: a 2x2 block
per actuator plus the supply row, solved exactly by elimination). This is L-stable for
the stiff oil columns (V/(beta K_c) ~ 0.2 ms < dt near null) and keeps the bookkeeping
exact: the flows booked are the linearised flows actually integrated.

Supply: pressure-compensated pumps deliver up to ``pump_flow_m3_s`` to hold
``pressure_pa`` (ideal compensator: if the flow limit allows, the supply is back at the
set pressure at the end of the step); above that the gas accumulators (p V^n = const on
the gas, ``accumulator_volume_m3`` of gas at ``accumulator_precharge_pa``) and the oil
compressed in the supply lines (``line_volume_m3``) make up the difference and the
supply pressure falls. A drained accumulator leaves only the line compliance; the
supply pressure is floored at the vapour pressure (counted). The pump never absorbs oil
(check valve). Return at the constant ``return_pressure_pa``.

Bookkeeping (cumulative m^3, exact in the discretisation up to round-off):
  vol_pump + vol_store_out + vol_supply_cav = sum(vol_in_a + vol_in_b)
  sum(vol_in_a + vol_in_b) = sum(vol_out_a + vol_out_b + vol_ext_a + vol_ext_b
        + vol_comp_a + vol_comp_b + vol_disp_a + vol_disp_b
        + vol_relief_a + vol_relief_b - vol_cav_a - vol_cav_b)
(cross leakage vol_cross moves oil a -> b and cancels; relief oil goes to return.)
"""

from __future__ import annotations

import functools
import math

import numpy as np

from . import _layout as L
from ._kernel import store_of_p
from ._numpy_step import step_numpy
from .params import HydraulicParams

_NUMBA_KERNEL = None


def _numba_kernel():
    global _NUMBA_KERNEL
    if _NUMBA_KERNEL is None:
        import numba

        from . import _kernel

        opts = dict(cache=True, nogil=True, fastmath=False, error_model="numpy", boundscheck=False)
        # helpers must be jitted for the kernel to call them
        for name in ("land_flow", "inv_beta", "store_of_p", "dstore_dp", "p_of_store"):
            setattr(_kernel, name, numba.njit(**opts)(getattr(_kernel, name)))
        _kernel.step_loops = numba.njit(**opts)(
            _kernel.step_loops.py_func if hasattr(_kernel.step_loops, "py_func") else _kernel.step_loops
        )
        _NUMBA_KERNEL = _kernel.step_loops
    return _NUMBA_KERNEL


class HydraulicState:
    """Views into the packed state arrays (all writable numpy views, no copies).

    Per actuator, shape (n_sim, n_act): spool, spool_rate, p_a, p_b, force, cushion_force,
    flow_a, flow_b (net valve flow into each chamber over the last step, m^3/s), q_pa,
    q_at, q_pb, q_bt (land flows), and the cumulative volumes vol_* (m^3, see the module
    docstring). Per simulation, shape (n_sim,): p_supply, supply_store, gas_volume,
    q_pump, q_demand, vol_pump, vol_store_out, vol_accumulator_out, vol_supply_cav.
    Counters (int64): relief_count, cavitation_count (n_sim, n_act; chambers a and b
    together), supply_low_count, pump_saturated_count (n_sim,).
    """

    def __init__(self, X, Y, IC, ICS):
        self._X, self._Y, self._IC, self._ICS = X, Y, IC, ICS
        for k, j in L.X_FIELDS.items():
            setattr(self, k, X[j])
        for k, j in L.Y_FIELDS.items():
            setattr(self, k, Y[j])
        self.relief_count = IC[L.C_RELIEF]
        self.cavitation_count = IC[L.C_CAV]
        self.supply_low_count = ICS[L.CS_LOW]
        self.pump_saturated_count = ICS[L.CS_PUMPSAT]

    def oil_balance(self):
        """(supply side, chamber side, residual) totals in m^3 over all simulations.

        supply side = pump + supply-node storage given + supply void;
        chamber side = return + external leakage + compression + displacement + relief - void.
        """
        s = self
        supply = float(np.sum(s.vol_pump) + np.sum(s.vol_store_out) + np.sum(s.vol_supply_cav))
        valve_in = float(np.sum(s.vol_in_a) + np.sum(s.vol_in_b))
        out = float(
            np.sum(s.vol_out_a + s.vol_out_b + s.vol_ext_a + s.vol_ext_b)
            + np.sum(s.vol_comp_a + s.vol_comp_b + s.vol_disp_a + s.vol_disp_b)
            + np.sum(s.vol_relief_a + s.vol_relief_b - s.vol_cav_a - s.vol_cav_b)
        )
        return supply, valve_in, out


@functools.lru_cache(maxsize=256)
def _valve_transition(fn_hz: float, zeta: float, dt: float) -> np.ndarray:
    """The second-order valve's exact one-step transition ``expm(M dt)`` (3 x 3, read
    only) for natural frequency ``fn_hz`` and damping ratio ``zeta``. Cached: scipy's
    ``expm`` of a 3 x 3 costs ~10 ms, and every simulation of a table (twelve valves
    alike, every candidate of a calibration round) asks for the same few."""
    from scipy.linalg import expm

    wn = 2.0 * math.pi * fn_hz
    M = np.zeros((3, 3))
    M[0, 1] = 1.0
    M[1, 0] = -wn * wn
    M[1, 1] = -2.0 * zeta * wn
    M[1, 2] = wn * wn
    E = expm(M * dt)
    E.flags.writeable = False
    return E


class HydraulicSystem:
    """Batch of ``n_sim`` identical hydraulic systems of ``params.n_act`` actuators.

    ``step(command, x, v)`` returns the net piston force (pressure + cushion), shape
    (n_sim, n_act) in N. The returned array is the system's internal force buffer
    (allocation-free): copy it if you keep it past the next step. 1-D inputs of shape
    (n_act,) are accepted when n_sim == 1 (a 1-D view is returned then).
    """

    def __init__(self, params: HydraulicParams, n_sim: int = 1, dt: float = 0.0005, backend: str = "numba"):
        if not isinstance(params, HydraulicParams):
            raise TypeError("params must be a HydraulicParams")
        params.validate()
        if not (isinstance(n_sim, (int, np.integer)) and n_sim >= 1):
            raise ValueError(f"n_sim must be an integer >= 1 (got {n_sim!r})")
        if not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"dt must be > 0 (got {dt!r})")
        if backend not in ("numba", "numpy"):
            raise ValueError(f'backend must be "numba" or "numpy" (got {backend!r})')
        self.params = params
        self.n_sim = int(n_sim)
        self.n_act = params.n_act
        self.dt = float(dt)
        self.backend = backend
        self._P, self._G = self._pack(params, self.dt)
        self.delay_steps = int(self._G[L.G_ND])
        ns, na = self.n_sim, self.n_act
        self._X = np.zeros((L.NX, ns, na))
        self._Y = np.zeros((L.NY, ns))
        self._IC = np.zeros((L.NC, ns, na), dtype=np.int64)
        self._ICS = np.zeros((L.NCS, ns), dtype=np.int64)
        self._buf = np.zeros((ns, na, max(self.delay_steps, 1)))
        self._head = 0
        self.state = HydraulicState(self._X, self._Y, self._IC, self._ICS)
        self.force = self._X[L.FORCE]
        self.flow_a = self._X[L.FLOWA]
        self.flow_b = self._X[L.FLOWB]
        self._kern = _numba_kernel() if backend == "numba" else step_numpy
        self._fric = None
        self.reset(np.zeros((ns, na)))

    # ------------------------------------------------------------------ parameters
    @staticmethod
    def _pack(p: HydraulicParams, dt: float):
        na = p.n_act
        P = np.zeros((L.NP, na))
        P[L.P_H] = p.half_stroke_m
        P[L.P_AA] = p.area_a_m2
        P[L.P_AB] = p.area_b_m2
        P[L.P_VDA] = p.dead_volume_a_m3
        P[L.P_VDB] = p.dead_volume_b_m3
        P[L.P_KC] = p.leakage_cross_m3_s_pa
        P[L.P_KE] = p.leakage_external_m3_s_pa
        P[L.P_LC] = p.cushion_length_m
        P[L.P_KCUSH] = p.cushion_stiffness_n_m
        P[L.P_BETA] = p.per_actuator("chamber_bulk_modulus_pa")
        G = np.zeros(L.NG)
        G[L.G_DT] = dt
        G[L.G_BETA] = p.bulk_modulus_pa
        G[L.G_PV] = p.vapour_pressure_pa
        G[L.G_PREL] = p.relief_pressure_pa
        G[L.G_AIR] = p.entrained_air_fraction
        G[L.G_AIRN] = p.air_polytropic_exponent
        G[L.G_PATM] = p.atmospheric_pressure_pa
        G[L.G_PSET] = p.supply_pressure_pa
        G[L.G_PT] = p.return_pressure_pa
        G[L.G_QMAX] = p.pump_flow_m3_s
        G[L.G_V0] = p.accumulator_volume_m3
        G[L.G_PPRE] = p.accumulator_precharge_pa
        G[L.G_NACC] = p.polytropic_exponent
        G[L.G_CLINE] = p.line_volume_m3 / p.bulk_modulus_pa
        G[L.G_SSET] = store_of_p(p.supply_pressure_pa, G[L.G_CLINE], G[L.G_V0], G[L.G_PPRE], G[L.G_NACC])
        K = p.rated_flow_m3_s / math.sqrt(0.5 * p.rated_drop_pa)
        G[L.G_K] = K
        P[L.P_K] = K * p.per_actuator("valve_flow_gain")
        P[L.P_U0] = p.per_actuator("valve_null_offset")
        dl = p.laminar_drop_pa
        G[L.G_DL] = dl
        G[L.G_SQDL] = math.sqrt(dl)
        G[L.G_OV] = p.overlap
        # null leakage: P->A->T and P->B->T, each land dropping (ps - pt)/2
        half = 0.5 * (p.supply_pressure_pa - p.return_pressure_pa)
        from ._kernel import land_flow as _lf

        gq = _lf(half, dl, math.sqrt(dl))[0]
        G[L.G_OLEAK] = p.null_leakage_m3_s / (2.0 * K * gq)
        if p.model == "second":
            G[L.G_MODEL] = 1.0
            z = p.damping_ratio
            for i, fn in enumerate(p.per_actuator("valve_natural_frequency_hz")):
                E = _valve_transition(float(fn), float(z), float(dt))
                P[L.P_F00, i], P[L.P_F01, i], P[L.P_F10, i], P[L.P_F11, i] = E[0, 0], E[0, 1], E[1, 0], E[1, 1]
                P[L.P_G0, i], P[L.P_G1, i] = E[0, 2], E[1, 2]
            # the globals keep the nominal (scalar) valve, for reference
            G[L.G_F00], G[L.G_F01], G[L.G_F10], G[L.G_F11], G[L.G_G0], G[L.G_G1] = (
                P[L.P_F00, 0],
                P[L.P_F01, 0],
                P[L.P_F10, 0],
                P[L.P_F11, 0],
                P[L.P_G0, 0],
                P[L.P_G1, 0],
            )
        else:
            G[L.G_MODEL] = 0.0
        P[L.P_A1] = np.exp(-dt / p.per_actuator("valve_tau_s"))
        G[L.G_A1] = math.exp(-dt / p.tau_s)
        G[L.G_SLEW] = p.slew_limit_per_s
        P[L.P_ND] = np.round(p.per_actuator("valve_delay_s") / dt)
        G[L.G_ND] = float(np.max(P[L.P_ND]))  # length of the delay line
        return P, G

    @property
    def valve_gain(self) -> float:
        """Land coefficient K (m^3/s/sqrt(Pa)): Q = K o g(dp)."""
        return float(self._G[L.G_K])

    @property
    def null_opening(self) -> float:
        """Residual land opening that produces the null leakage."""
        return float(self._G[L.G_OLEAK])

    # ------------------------------------------------------------------ inputs
    def _in(self, a, name):
        if (
            type(a) is np.ndarray
            and a.dtype == np.float64
            and a.ndim == 2
            and a.shape[0] == self.n_sim
            and a.shape[1] == self.n_act
            and a.flags.c_contiguous
        ):
            return a
        a = np.asarray(a, dtype=np.float64)
        if a.ndim == 1 and self.n_sim == 1 and a.shape[0] == self.n_act:
            a = a.reshape(1, self.n_act)
        if a.shape != (self.n_sim, self.n_act):
            raise ValueError(f"{name} must have shape ({self.n_sim}, {self.n_act}) (got {a.shape})")
        return np.ascontiguousarray(a)

    # ------------------------------------------------------------------ API
    def reset(self, x, force=None):
        """Zero the spool, fill the delay line with 0, set the supply at its set pressure
        (accumulator gas at its equilibrium volume), zero all counters, and set chamber
        pressures so that each actuator's net force (pressure + cushion at x) equals
        ``force`` (default 0) with p_a, p_b as close as possible (least squares) to the
        mid level (p_supply + p_return)/2; pressures are then clipped to
        [vapour, relief] (a force that needs more is not reached). Pass the static
        actuator loads (e.g. the platen weight on the vertical actuators) as ``force``
        to start in equilibrium."""
        p = self.params
        x2 = self._in(x, "x")
        self._X[:] = 0.0
        self._Y[:] = 0.0
        self._IC[:] = 0
        self._ICS[:] = 0
        self._buf[:] = 0.0
        self._head = 0
        h = self._P[L.P_H]
        e = np.abs(x2) - (h - self._P[L.P_LC])
        fc = np.where(e > 0.0, -np.copysign(self._P[L.P_KCUSH] * np.maximum(e, 0.0), x2), 0.0)
        f = np.zeros_like(x2) if force is None else self._in(force, "force")
        aa, ab = self._P[L.P_AA], self._P[L.P_AB]
        pm = 0.5 * (p.supply_pressure_pa + p.return_pressure_pa)
        lam = (f - fc - pm * (aa - ab)) / (aa * aa + ab * ab)
        self._X[L.PA] = np.clip(pm + lam * aa, p.vapour_pressure_pa, p.relief_pressure_pa)
        self._X[L.PB] = np.clip(pm - lam * ab, p.vapour_pressure_pa, p.relief_pressure_pa)
        self._X[L.FCUSH] = fc
        self._X[L.FORCE] = self._X[L.PA] * aa - self._X[L.PB] * ab + fc
        self._Y[L.PS] = p.supply_pressure_pa
        self._Y[L.STORE] = self._G[L.G_SSET]
        if p.accumulator_volume_m3 > 0:
            self._Y[L.GASV] = p.accumulator_volume_m3 * (p.accumulator_precharge_pa / p.supply_pressure_pa) ** (
                1.0 / p.polytropic_exponent
            )
        return self.force

    def step(self, command, x, v):
        """Advance one step dt with piston (x, v) of the current mechanical state; return the
        net piston force at the end of the step (n_sim, n_act), N (internal buffer)."""
        c = self._in(command, "command")
        xx = self._in(x, "x")
        vv = self._in(v, "v")
        self._kern(c, xx, vv, self._X, self._Y, self._IC, self._ICS, self._buf, self._head, self._P, self._G)
        if self.delay_steps > 0:
            self._head += 1
            if self._head == self.delay_steps:
                self._head = 0
        if self.n_sim == 1 and np.ndim(command) == 1:
            return self.force[0]
        return self.force

    def seal_friction(self, v, out=None):
        """Seal friction force (n_sim, n_act), N, opposing v: viscous + Coulomb with an
        optional Stribeck peak, the sign regularised by tanh(v / friction_smoothing_m_s)
        so that it is smooth and usable explicitly (its slope at v = 0 is
        c0 = F_static / friction_smoothing + viscous; explicit use on a mass m needs
        c0 dt / m < 2, e.g. 3e6 N s/m * 0.5 ms / 1000 kg = 1.5 for the CGS seals).
        Not included in ``step``'s force (the simulator may instead apply the Coulomb
        part through MuJoCo's frictionloss)."""
        p = self.params
        vv = np.asarray(v, dtype=np.float64)
        fc = p.seal_friction_n
        fs = p.seal_static_friction_n
        st = fc + (fs - fc) * np.exp(-((vv / p.stribeck_velocity_m_s) ** 2))
        r = -(st * np.tanh(vv / p.friction_smoothing_m_s) + p.seal_viscous_n_s_m * vv)
        if out is not None:
            out[...] = r
            return out
        return r

    # ------------------------------------------------------------------ helpers
    def no_load_flow(self, opening):
        """Closed-form steady flow (m^3/s) at spool ``opening`` with no load on a
        symmetric actuator at the set supply pressure (each land drops (ps - pt)/2)."""
        G = self._G
        o = np.maximum(np.abs(opening) - G[L.G_OV], 0.0) / (1.0 - G[L.G_OV])
        from ._kernel import land_flow

        # the metering lands open by o + o_leak (1 - o); the opposite pair leaks o_leak
        half = 0.5 * (G[L.G_PSET] - G[L.G_PT])
        return np.sign(opening) * G[L.G_K] * o * (1.0 - G[L.G_OLEAK]) * land_flow(half, G[L.G_DL], G[L.G_SQDL])[0]
