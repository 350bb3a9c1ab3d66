"""Field offsets of the flat arrays a compiled line is lowered to.

The kernel reads everything from two flat arrays: ``I`` (int64: counts, offsets, state
indices, topology) and ``P`` (float64: every parameter, the set-point tables and a small
runtime block). Records of one kind (node, span, sensor, controller) have a fixed number of
fields; the constants below name them. Kept in one module so the compiler and the kernel
cannot disagree.
"""

import numpy as np

# ---- header of I (offsets of the record blocks and counts) ----
H_NN, H_NS, H_NSE, H_NC, H_NY = 0, 1, 2, 3, 4  # nodes, spans, sensors, controllers, states
H_OFF_NI, H_OFF_SI, H_OFF_SEI, H_OFF_CI = 5, 6, 7, 8  # record blocks in I
H_OFF_NP, H_OFF_SP, H_OFF_SEP, H_OFF_CP = 9, 10, 11, 12  # record blocks in P
H_MODEL = 13  # 0 exact span model, 1 linear
H_NCH = 14  # number of set-point channels (0 = line speed)
H_OFF_SCHN = 15  # I block: number of points per channel
H_OFF_SCHT, H_OFF_SCHV = 16, 17  # P blocks: times, values (H_MAXPTS per channel)
H_MAXPTS = 18
H_OFF_RT = 19  # P block: runtime values (segment start time)
H_NPAT, H_OFF_PAT = 20, 21  # Jacobian pattern (rows then cols) in I
H_NQ, H_MAXD = 22, 23  # gradient scratch: number of quantities, slots per quantity
H_NAUX = 25  # length of one row of algebraic outputs
H_NEV = 26  # number of event functions
H_OFF_EV = 27  # I block: event records
H_NM, H_OFF_MI, H_OFF_MP = 28, 29, 30  # movers (dancers, festoon carriages)
H_NJ, H_OFF_JP = 31, 32  # splice-joint slots (P block)
H_EA = 33  # index in P of the web's EA
H_NFS, H_OFF_FS = 34, 35  # fault parameter slots (P block)
H_NTB, H_OFF_TB = 36, 37  # process-disturbance tables (I records; values in P)
HEADER = 40

# ---- node records ----
NK_UNWIND, NK_REWIND, NK_ROLLER = 0, 1, 2
DRV_NONE, DRV_TORQUE, DRV_IDEAL = 0, 1, 2
NI_KIND, NI_DRIVE, NI_W, NI_S, NI_U, NI_TAU = 0, 1, 2, 3, 4, 5
NI_SPAN_UP, NI_SPAN_DN, NI_SPEEDC, NI_TENSC, NI_MOVER = 6, 7, 8, 9, 10
NI_TH = 11  # roller angle state (only for an eccentric roller), else -1
# set-point channels of a node (-1: none): a programmed draw (replaces the speed PI's CP_DRAW
# or the ideal-speed drive's NP_DRAW) and an open-loop torque command (added to tau_cmd)
NI_DRAWCH, NI_TQCH = 12, 13
NI = 14
(
    NP_R,
    NP_J,
    NP_B,
    NP_TC,
    NP_WEPS,
    NP_R0,
    NP_RC,
    NP_JC,
    NP_CW,
    NP_RHOW,
    NP_EPSW,
    NP_TLAG,
    NP_TMAX,
    NP_DRAW,
    NP_EMB,
    NP_RIPA,
    NP_RIPW,
    NP_EPSW1,
    NP_EPSW2,
    NP_VGAIN,
    NP_VOFF,
    NP_VSLOPE,
    NP_VT0,
    NP_RTRIG,
    NP_TEFF,
    NP_TBIAS,
    NP_TSTUCK,
    NP_TSV,
    NP_FRICF,
    NP_REFF,
    NP_ECC,
    NP_WRAP,
) = range(32)
NP = 32
# faults on a node (defaults: TEFF 1, FRICF 1, the rest 0):
#   applied torque = TSV while TSTUCK, else clip(TEFF·command + TBIAS, ±TMAX)
#   bearing friction ×FRICF; surface speed and torque arm R·(1 + REFF) (draw error);
#   eccentricity ECC [m] of a roller wrapped by WRAP [rad] (its angle is state NI_TH)
# reference surface speed of a speed-controlled node (splice phases override it):
#   v_ref = V·(1 + draw)·VGAIN + VOFF + VSLOPE·(t - VT0) + trim

# ---- span records ----
SI_E, SI_UP, SI_DN, SI_MOVER = 0, 1, 2, 3
NSI = 4
SP_L, SP_EA, SP_TBRK = 0, 1, 2
NSP = 3

# ---- sensor records ----
SE_LOADCELL, SE_ENCODER, SE_DIAMETER, SE_DANCER, SE_PITCH = 1, 2, 3, 4, 5
# SE_PITCH: SEI_NODE is the span; SEP_CIN holds L0 (q0 of a law), SEP_COUT the calibration
# E·S. With a relaxed-pitch law or variation (else -1/0): SEI_RNODE is the unwind node,
# L0 = SEP_CIN + SEP_Q1·R³ + sum_m a_m·cos(kappa_m·u + phi_m), u the unwind's unwound length,
# the SEI_VN triples (a, kappa, phi) at P[SEI_VOFF:]
SEI_TYPE, SEI_NODE, SEI_F, SEI_RNODE, SEI_VN, SEI_VOFF = 0, 1, 2, 3, 4, 5
NSEI = 6
# sensor faults acting in the loop (set by the solver's fault actions): with dt = t - FT0,
#   reading = (1 + GA + GB·dt + GC·exp(-dt/GTAU))·raw + BA + BB·dt + BC·exp(-dt/BTAU),
# or the held value SV while STUCK; FON = 0 skips all of it
# SEP_DL0 (pitch): relaxed-pitch offset of the web at the sensor while no material joint
# (below) covers it, i.e. that of the roll on the unwind at t = 0
(
    SEP_WIN,
    SEP_WOUT,
    SEP_GAIN,
    SEP_OFF,
    SEP_TAU,
    SEP_CIN,
    SEP_COUT,
    SEP_FON,
    SEP_FT0,
    SEP_BA,
    SEP_BB,
    SEP_BC,
    SEP_BTAU,
    SEP_GA,
    SEP_GB,
    SEP_GC,
    SEP_GTAU,
    SEP_STUCK,
    SEP_SV,
    SEP_Q1,
    SEP_DL0,
) = range(21)
NSEP = 21

# ---- controller records ----
C_SPEED, C_TENSION_TORQUE, C_TENSION_TRIM, C_DANCER = 1, 2, 3, 4
CI_TYPE, CI_NODE, CI_X, CI_SENSOR, CI_RSENSOR, CI_CH, CI_MOVER = 0, 1, 2, 3, 4, 5, 6
NCI = 7
CP_KP, CP_KI, CP_KAW, CP_LIM, CP_DRAW, CP_FF, CP_SIGN, CP_SETP, CP_GATE = range(9)
# torque-mode feed-forward terms of a tension PI on a roll (CP_FF: the tension term):
#   J_est = JFAC·J(R_hat) + JABS; RR, FRF: 1/0 radius-rate and friction terms
CP_JFAC, CP_JABS, CP_RR, CP_FRF = 9, 10, 11, 12
NCP = 13

# ---- mover records (dancer carriage/arm, festoon carriage): generalised coordinate q ----
MV_LINEAR, MV_PIVOT, MV_FESTOON = 1, 2, 3
MI_KIND, MI_Q, MI_QD, MI_SPAN_U, MI_SPAN_D, MI_NODE = range(6)
NMI = 6
(
    MP_MASS,
    MP_QMIN,
    MP_QMAX,
    MP_C,
    MP_FC,
    MP_EPS,
    MP_F0,
    MP_K,
    MP_Q0,
    MP_G1,
    MP_G2,
    MP_MODE,
    MP_CX,
    MP_CY,
    MP_NX,
    MP_NY,
    MP_AX,
    MP_AY,
    MP_BX,
    MP_BY,
    MP_DU,
    MP_DD,
    MP_TUX,
    MP_TUY,
    MP_TDX,
    MP_TDY,
    MP_LU0,
    MP_LD0,
    MP_NSTR,
    MP_CYLF,
    MP_CYLX,
    MP_CYLY,
    MP_CYLA,
    MP_SEIZED_Q,
    MP_FAIR,
    MP_LOADF,
    MP_FRICF,
) = range(37)
NMP = 37
# MP_FAIR: actuator force of a linear dancer or festoon (MP_F0 then holds gravity only);
# MP_LOADF scales the actuator (air cylinder, torque motor): loss of loading;
# MP_FRICF scales the carriage/arm friction
# MP_MODE: 0 free, -1 latched at the lower stop, +1 at the upper stop, 2 seized

# ---- splice-joint slots (P only) ----
# JP_SPAN: span holding the joint's lead (front); JP_TSPAN: span holding its trail (-1 while
# the trail is still on the roll). JP_MAT: 1 for a material joint (the web of another roll,
# or a modulus change: JP_RATIO is its E·A over the first roll's and JP_DL0 its relaxed-pitch
# offset), 0 for a splice overlap
(JP_ACTIVE, JP_U0, JP_LEN, JP_RATIO, JP_TBRK, JP_SPAN, JP_NODE, JP_TSPAN, JP_MAT, JP_DL0) = range(
    10
)
NJP = 10

# ---- fault parameter slots (P only): while FS_ON, the kernel sets, at every evaluation,
#   P[FS_IDX] = FS_BASE + FS_A + FS_B·dt + FS_C·exp(-dt/FS_TAU),  dt = t - FS_T0
# (a ramp or exponential fault profile on a parameter); the solver's fault actions set the
# coefficients at each breakpoint and write constant values directly
(FS_IDX, FS_BASE, FS_ON, FS_T0, FS_A, FS_B, FS_C, FS_TAU) = range(8)
NFS = 8

# ---- process disturbances: I record (kind, node, n, offset in P, shape).
# SH_TABLE: P holds [x0, dx, v0 .. v(n-1)], interpolated linearly (held outside the grid);
# SH_SINES: P holds n amplitudes, n angular frequencies, n phases: sum a·sin(w·x + phase)
TB_DRAG, TB_WOUND = 1, 2  # drag torque on node vs time; wound-in strain of an unwind vs u
TI_KIND, TI_NODE, TI_N, TI_OFFP, TI_SHAPE = range(5)
NTI = 5
SH_TABLE, SH_SINES = 0, 1

# ---- event records (I block, 3 ints each: kind, index, sign convention) ----
EV_SLACK, EV_BREAK, EV_CAPSTAN, EV_EMPTY = 1, 2, 3, 4
EV_STOP_LO, EV_STOP_HI, EV_JOINT_PASS, EV_JOINT_BREAK, EV_SPLICE_RADIUS, EV_REFILL = (
    5,
    6,
    7,
    8,
    9,
    10,
)
NEVI = 2

# ---- algebraic outputs, per record ----
AUX_SPAN = 3  # tension, geometric strain, length
AUX_NODE = 8  # v, omega, R, J, m, tau_applied, tau_cmd, capstan margin ratio
AUX_SENS = 3  # physical value, controller-visible value, bearing force (load cell)
AUX_CTRL = 3  # error, output, integrator
AUX_MOVER = 5  # position, velocity, web force, net force, mode
AUX_JOINT = 2  # leading-edge position (unstretched, from the unwind), span index
# set-points after the records: line speed, line acceleration, one per channel >= 1

# ---- evaluation modes ----
MODE_RHS, MODE_JAC, MODE_TOUCH = 0, 1, 2
#: the modes as a constant array, for compiled callers: ``evaluate(..., RUNTIME_MODE[MODE_RHS],
#: ...)`` passes an int64, while ``MODE_RHS`` itself would be typed as the literal 0, and numba
#: would compile the kernel once per literal mode and once more for the int64 of Python's calls
#: (each compile of the kernel is ~20 s of CPU on a cold start)
RUNTIME_MODE = np.array([MODE_RHS, MODE_JAC, MODE_TOUCH], dtype=np.int64)
