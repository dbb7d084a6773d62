"""Index constants of the packed state/parameter arrays (shared by both backends)."""

# ---- per-actuator state, array X of shape (NX, n_sim, n_act)
SPOOL = 0  # main-stage spool position, fraction of rated opening, [-1, 1]
RATE = 1  # spool velocity, 1/s
PA = 2  # chamber a (extension side) pressure, Pa
PB = 3  # chamber b pressure, Pa
FORCE = 4  # net piston force returned by step (pressure + cushion), N
FCUSH = 5  # end-of-stroke cushion force (included in FORCE), N
FLOWA = 6  # net valve flow into chamber a over the last step (P->A minus A->T), m^3/s
FLOWB = 7  # net valve flow into chamber b over the last step (P->B minus B->T), m^3/s
QPA = 8  # land flows over the last step (linearised, as integrated), m^3/s
QAT = 9
QPB = 10
QBT = 11
# cumulative oil volumes, m^3 (exact bookkeeping of the discretisation)
V_IN_A = 12  # supply -> chamber a through land P-A
V_OUT_A = 13  # chamber a -> return through land A-T
V_IN_B = 14
V_OUT_B = 15
V_CROSS = 16  # chamber a -> chamber b across the piston
V_EXT_A = 17  # chamber a -> drain (external leakage)
V_EXT_B = 18
V_COMP_A = 19  # oil stored by compression in chamber a: sum (V_a / beta_eff) * dp_a
V_COMP_B = 20
V_DISP_A = 21  # chamber a swept-volume growth: sum A_a * v * dt
V_DISP_B = 22  # chamber b swept-volume growth: sum -A_b * v * dt
V_RELIEF_A = 23  # oil let out of chamber a by the relief clip
V_RELIEF_B = 24
V_CAV_A = 25  # void created in chamber a by the cavitation clip (vapour volume)
V_CAV_B = 26
# scratch (pass 1 -> pass 2 of a step)
S_GPA = 27
S_GAT = 28
S_GPB = 29
S_GBT = 30
S_UA = 31
S_UB = 32
S_WA = 33
S_WB = 34
S_CA = 35  # V_a / beta_eff(p_a), m^3/Pa
S_CB = 36
NX = 37

# ---- per-simulation state, array Y of shape (NY, n_sim)
PS = 0  # supply pressure at the valves, Pa
STORE = 1  # oil stored in the supply node (accumulator oil + line compression), m^3
GASV = 2  # accumulator gas volume, m^3
QPUMP = 3  # pump flow over the last step, m^3/s
QDEMAND = 4  # valves' supply flow over the last step (sum of P-A and P-B lands), m^3/s
V_PUMP = 5  # cumulative pump delivery, m^3
V_STORE_OUT = 6  # cumulative oil given by the supply node (accumulators + line), m^3
V_ACC_OUT = 7  # cumulative oil given by the accumulators alone, m^3
V_SUPPLY_CAV = 8  # void created by clipping the supply pressure at vapour pressure, m^3
NY = 9

# ---- integer counters
# IC (2, n_sim, n_act): relief clips, cavitation clips (chambers a and b counted together)
C_RELIEF = 0
C_CAV = 1
NC = 2
# ICS (2, n_sim): supply at vapour pressure, pump saturated (at max flow or at zero)
CS_LOW = 0
CS_PUMPSAT = 1
NCS = 2

# ---- per-actuator parameters, array P of shape (NP, n_act)
P_H = 0
P_AA = 1
P_AB = 2
P_VDA = 3
P_VDB = 4
P_KC = 5
P_KE = 6
P_LC = 7
P_KCUSH = 8
# per-actuator servovalve and fluid (the globals' values unless HydraulicParams overrides them)
P_BETA = 9  # bulk modulus of the oil in this actuator's chambers, Pa
P_K = 10  # land coefficient K x flow gain factor, m^3/s/sqrt(Pa)
P_U0 = 11  # null offset added to the (delayed) command, fraction of rated opening
P_A1 = 12  # first-order spool: exp(-dt / tau)
P_F00 = 13  # second-order spool: exact ZOH discretisation
P_F01 = 14
P_F10 = 15
P_F11 = 16
P_G0 = 17
P_G1 = 18
P_ND = 19  # delay in steps (<= G_ND, the delay line's length)
NP = 20

# ---- global parameters, array G of shape (NG,)
G_DT = 0
G_BETA = 1
G_PV = 2
G_PREL = 3
G_AIR = 4
G_AIRN = 5
G_PATM = 6
G_PSET = 7
G_PT = 8
G_QMAX = 9
G_V0 = 10
G_PPRE = 11
G_NACC = 12
G_CLINE = 13
G_SSET = 14
G_K = 15
G_OLEAK = 16
G_DL = 17
G_SQDL = 18
G_OV = 19
G_MODEL = 20  # 0 first order, 1 second order
G_A1 = 21
G_F00 = 22
G_F01 = 23
G_F10 = 24
G_F11 = 25
G_G0 = 26
G_G1 = 27
G_SLEW = 28
G_ND = 29  # delay line length in steps (the largest actuator delay)
NG = 30

X_FIELDS = {
    "spool": SPOOL,
    "spool_rate": RATE,
    "p_a": PA,
    "p_b": PB,
    "force": FORCE,
    "cushion_force": FCUSH,
    "flow_a": FLOWA,
    "flow_b": FLOWB,
    "q_pa": QPA,
    "q_at": QAT,
    "q_pb": QPB,
    "q_bt": QBT,
    "vol_in_a": V_IN_A,
    "vol_out_a": V_OUT_A,
    "vol_in_b": V_IN_B,
    "vol_out_b": V_OUT_B,
    "vol_cross": V_CROSS,
    "vol_ext_a": V_EXT_A,
    "vol_ext_b": V_EXT_B,
    "vol_comp_a": V_COMP_A,
    "vol_comp_b": V_COMP_B,
    "vol_disp_a": V_DISP_A,
    "vol_disp_b": V_DISP_B,
    "vol_relief_a": V_RELIEF_A,
    "vol_relief_b": V_RELIEF_B,
    "vol_cav_a": V_CAV_A,
    "vol_cav_b": V_CAV_B,
}
Y_FIELDS = {
    "p_supply": PS,
    "supply_store": STORE,
    "gas_volume": GASV,
    "q_pump": QPUMP,
    "q_demand": QDEMAND,
    "vol_pump": V_PUMP,
    "vol_store_out": V_STORE_OUT,
    "vol_accumulator_out": V_ACC_OUT,
    "vol_supply_cav": V_SUPPLY_CAV,
}
