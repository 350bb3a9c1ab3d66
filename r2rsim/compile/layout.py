"""Field offsets of the flat arrays a compiled line is lowered to.

The kernel reads everything from two flat arrays: ``I`` (int64: counts, offsets, state
indices, topology) and ``P`` (float64: every parameter, the set-point tables and a small
runtime block). Records of one family (node, span, sensor, controller, ...) have a fixed
number of fields; each family declares its fields once, as an :class:`~enum.IntEnum` below,
and its record size is the enum's length (``N_NODE_P = len(NodeP)``). numba compiles an
IntEnum member used as an index to the same machine code as an integer literal (checked on
numba 0.68 when the enums replaced the hand-numbered constants), so the kernel indexes its
record views by name: ``node_p[k, NodeP.R]``. Kept in one module so the compiler and the
kernel cannot disagree.
"""

from collections import namedtuple
from enum import IntEnum
from typing import Any

import numpy as np


# ---- header of I (offsets of the record blocks and counts) ----
class H(IntEnum):
    NN = 0  # nodes
    NS = 1  # spans
    NSE = 2  # sensors
    NC = 3  # controllers
    NY = 4  # states
    OFF_NI = 5  # record blocks in I
    OFF_SI = 6
    OFF_SEI = 7
    OFF_CI = 8
    OFF_NP = 9  # record blocks in P
    OFF_SP = 10
    OFF_SEP = 11
    OFF_CP = 12
    MODEL = 13  # 0 exact span model, 1 linear
    NCH = 14  # number of set-point channels (0 = line speed)
    OFF_SCHN = 15  # I block: number of points per channel
    OFF_SCHT = 16  # P blocks: times, values (MAXPTS per channel)
    OFF_SCHV = 17
    MAXPTS = 18
    OFF_RT = 19  # P block: runtime values (segment start time)
    NPAT = 20  # Jacobian pattern (rows then cols) in I
    OFF_PAT = 21
    NQ = 22  # gradient scratch: number of quantities, slots per quantity
    MAXD = 23
    NAUX = 25  # length of one row of algebraic outputs
    NEV = 26  # number of event functions
    OFF_EV = 27  # I block: event records
    NM = 28  # movers (dancers, festoon carriages)
    OFF_MI = 29
    OFF_MP = 30
    NJ = 31  # splice-joint slots (P block)
    OFF_JP = 32
    EA = 33  # index in P of the web's EA
    NFS = 34  # fault parameter slots (P block)
    OFF_FS = 35
    NTB = 36  # process-disturbance tables (I records; values in P)
    OFF_TB = 37


#: length of the header (slots 24, 38 and 39 are unused)
HEADER = 40


# ---- node records ----
class NodeKind(IntEnum):
    UNWIND = 0
    REWIND = 1
    ROLLER = 2


class DriveKind(IntEnum):
    NONE = 0
    TORQUE = 1
    IDEAL = 2


class NodeI(IntEnum):
    KIND = 0
    DRIVE = 1
    W = 2
    S = 3
    U = 4
    TAU = 5
    SPAN_UP = 6
    SPAN_DN = 7
    SPEEDC = 8
    TENSC = 9
    MOVER = 10
    TH = 11  # roller angle state (only for an eccentric roller), else -1
    # set-point channels of a node (-1: none): a programmed draw (replaces the speed PI's
    # CtrlP.DRAW or the ideal-speed drive's NodeP.DRAW) and an open-loop torque command
    # (added to tau_cmd)
    DRAWCH = 12
    TQCH = 13


class NodeP(IntEnum):
    R = 0
    J = 1
    B = 2
    TC = 3
    WEPS = 4
    R0 = 5
    RC = 6
    JC = 7
    CW = 8
    RHOW = 9
    EPSW = 10
    TLAG = 11
    TMAX = 12
    DRAW = 13
    EMB = 14
    RIPA = 15
    RIPW = 16
    EPSW1 = 17
    EPSW2 = 18
    VGAIN = 19
    VOFF = 20
    VSLOPE = 21
    VT0 = 22
    RTRIG = 23
    TEFF = 24
    TBIAS = 25
    TSTUCK = 26
    TSV = 27
    FRICF = 28
    REFF = 29
    ECC = 30
    WRAP = 31


# faults on a node (defaults: TEFF 1, FRICF 1, the rest 0):
#   applied torque = TSV while TSTUCK, else clip(TEFF·command + TBIAS, ±TMAX)
#   bearing friction ×FRICF; surface speed and torque arm R·(1 + REFF) (draw error);
#   eccentricity ECC [m] of a roller wrapped by WRAP [rad] (its angle is state NodeI.TH)
# reference surface speed of a speed-controlled node (splice phases override it):
#   v_ref = V·(1 + draw)·VGAIN + VOFF + VSLOPE·(t - VT0) + trim


# ---- span records ----
class SpanI(IntEnum):
    E = 0
    UP = 1
    DN = 2
    MOVER = 3


class SpanP(IntEnum):
    L = 0
    EA = 1
    TBRK = 2


# ---- sensor records ----
class SensorKind(IntEnum):
    LOADCELL = 1
    ENCODER = 2
    DIAMETER = 3
    DANCER = 4
    PITCH = 5


# SensorKind.PITCH: SensorI.NODE is the span; SensorP.CIN holds L0 (q0 of a law),
# SensorP.COUT the calibration E·S. With a relaxed-pitch law or variation (else -1/0):
# SensorI.RNODE is the unwind node, L0 = CIN + Q1·R³ + sum_m a_m·cos(kappa_m·u + phi_m),
# u the unwind's unwound length, the SensorI.VN triples (a, kappa, phi) at P[SensorI.VOFF:]
class SensorI(IntEnum):
    TYPE = 0
    NODE = 1
    F = 2
    RNODE = 3
    VN = 4
    VOFF = 5


# sensor faults acting in the loop (set by the solver's fault actions): with dt = t - FT0,
#   reading = (1 + GA + GB·dt + GC·exp(-dt/GTAU))·raw + BA + BB·dt + BC·exp(-dt/BTAU),
# or the held value SV while STUCK; FON = 0 skips all of it
# DL0 (pitch): relaxed-pitch offset of the web at the sensor while no material joint
# (below) covers it, i.e. that of the roll on the unwind at t = 0
class SensorP(IntEnum):
    WIN = 0
    WOUT = 1
    GAIN = 2
    OFF = 3
    TAU = 4
    CIN = 5
    COUT = 6
    FON = 7
    FT0 = 8
    BA = 9
    BB = 10
    BC = 11
    BTAU = 12
    GA = 13
    GB = 14
    GC = 15
    GTAU = 16
    STUCK = 17
    SV = 18
    Q1 = 19
    DL0 = 20


# ---- controller records ----
class CtrlKind(IntEnum):
    SPEED = 1
    TENSION_TORQUE = 2
    TENSION_TRIM = 3
    DANCER = 4


class CtrlI(IntEnum):
    TYPE = 0
    NODE = 1
    X = 2
    SENSOR = 3
    RSENSOR = 4
    CH = 5
    MOVER = 6


# torque-mode feed-forward terms of a tension PI on a roll (FF: the tension term):
#   J_est = JFAC·J(R_hat) + JABS; RR, FRF: 1/0 radius-rate and friction terms
class CtrlP(IntEnum):
    KP = 0
    KI = 1
    KAW = 2
    LIM = 3
    DRAW = 4
    FF = 5
    SIGN = 6
    SETP = 7
    GATE = 8
    JFAC = 9
    JABS = 10
    RR = 11
    FRF = 12


# ---- mover records (dancer carriage/arm, festoon carriage): generalised coordinate q ----
class MoverKind(IntEnum):
    LINEAR = 1
    PIVOT = 2
    FESTOON = 3


class MoverI(IntEnum):
    KIND = 0
    Q = 1
    QD = 2
    SPAN_U = 3
    SPAN_D = 4
    NODE = 5


# FAIR: actuator force of a linear dancer or festoon (F0 then holds gravity only);
# LOADF scales the actuator (air cylinder, torque motor): loss of loading;
# FRICF scales the carriage/arm friction
# MODE: 0 free, -1 latched at the lower stop, +1 at the upper stop, 2 seized
class MoverP(IntEnum):
    MASS = 0
    QMIN = 1
    QMAX = 2
    C = 3
    FC = 4
    EPS = 5
    F0 = 6
    K = 7
    Q0 = 8
    G1 = 9
    G2 = 10
    MODE = 11
    CX = 12
    CY = 13
    NX = 14
    NY = 15
    AX = 16
    AY = 17
    BX = 18
    BY = 19
    DU = 20
    DD = 21
    TUX = 22
    TUY = 23
    TDX = 24
    TDY = 25
    LU0 = 26
    LD0 = 27
    NSTR = 28
    CYLF = 29
    CYLX = 30
    CYLY = 31
    CYLA = 32
    SEIZED_Q = 33
    FAIR = 34
    LOADF = 35
    FRICF = 36


# ---- splice-joint slots (P only) ----
# SPAN: span holding the joint's lead (front); TSPAN: span holding its trail (-1 while the
# trail is still on the roll). MAT: 1 for a material joint (the web of another roll, or a
# modulus change: RATIO is its E·A over the first roll's and DL0 its relaxed-pitch offset),
# 0 for a splice overlap
class JointP(IntEnum):
    ACTIVE = 0
    U0 = 1
    LEN = 2
    RATIO = 3
    TBRK = 4
    SPAN = 5
    NODE = 6
    TSPAN = 7
    MAT = 8
    DL0 = 9


# ---- fault parameter slots (P only): while ON, the kernel sets, at every evaluation,
#   P[IDX] = BASE + A + B·dt + C·exp(-dt/TAU),  dt = t - T0
# (a ramp or exponential fault profile on a parameter); the solver's fault actions set the
# coefficients at each breakpoint and write constant values directly
class FaultP(IntEnum):
    IDX = 0
    BASE = 1
    ON = 2
    T0 = 3
    A = 4
    B = 5
    C = 6
    TAU = 7


# ---- process disturbances: I record (kind, node, n, offset in P, shape).
# Shape.TABLE: P holds [x0, dx, v0 .. v(n-1)], interpolated linearly (held outside the grid);
# Shape.SINES: P holds n amplitudes, n angular frequencies, n phases: sum a·sin(w·x + phase)
class TableKind(IntEnum):
    DRAG = 1  # drag torque on node vs time
    WOUND = 2  # wound-in strain of an unwind vs u


class TableI(IntEnum):
    KIND = 0
    NODE = 1
    N = 2
    OFFP = 3
    SHAPE = 4


class Shape(IntEnum):
    TABLE = 0
    SINES = 1


# ---- event records (I block: kind, index) ----
class EventKind(IntEnum):
    SLACK = 1
    BREAK = 2
    CAPSTAN = 3
    EMPTY = 4
    STOP_LO = 5
    STOP_HI = 6
    JOINT_PASS = 7
    JOINT_BREAK = 8
    SPLICE_RADIUS = 9
    REFILL = 10


class EventI(IntEnum):
    KIND = 0
    INDEX = 1


# ---- record sizes: the length of each family's enum ----
N_NODE_I = len(NodeI)
N_NODE_P = len(NodeP)
N_SPAN_I = len(SpanI)
N_SPAN_P = len(SpanP)
N_SENSOR_I = len(SensorI)
N_SENSOR_P = len(SensorP)
N_CTRL_I = len(CtrlI)
N_CTRL_P = len(CtrlP)
N_MOVER_I = len(MoverI)
N_MOVER_P = len(MoverP)
N_JOINT_P = len(JointP)
N_FAULT_P = len(FaultP)
N_TABLE_I = len(TableI)
N_EVENT_I = len(EventI)

# ---- algebraic outputs, per record ----
AUX_SPAN = 3  # tension, geometric strain, length
AUX_NODE = 8  # v, omega, R, J, m, tau_applied, tau_cmd, capstan margin ratio
AUX_SENS = 3  # physical value, controller-visible value, bearing force (load cell)
AUX_CTRL = 3  # error, output, integrator
AUX_MOVER = 5  # position, velocity, web force, net force, mode
AUX_JOINT = 2  # leading-edge position (unstretched, from the unwind), span index
# set-points after the records: line speed, line acceleration, one per channel >= 1


# ---- evaluation modes ----
class Mode(IntEnum):
    RHS = 0  # dy/dt
    JAC = 1  # dy/dt and the Jacobian
    TOUCH = 2  # the Jacobian's pattern
    # the algebraic outputs: every intermediate they read, without the terms only dy/dt
    # needs (the bearing-drag and wound-in-strain sums); yd is then not dy/dt
    OUTPUTS = 3


#: the modes as a constant array, for compiled callers: ``evaluate(..., RUNTIME_MODE[Mode.RHS],
#: ...)`` passes an int64, while ``Mode.RHS`` itself would be typed as an enum member, and numba
#: would compile the kernel once for it and once more for the int64 of Python's calls (each
#: compile of the kernel is ~20 s of CPU on a cold start)
RUNTIME_MODE = np.array([m.value for m in Mode], dtype=np.int64)


# ---- the fields for compiled code --------------------------------------------------------
def frozen(enum: type[IntEnum]) -> Any:
    """The members of ``enum`` as a namedtuple of plain ints (``frozen(NodeP).R == 0``).

    The kernel reads the fields through these twins of the enums: numba reads the fields of a
    global namedtuple as constants with every numba version r2rsim supports, while an IntEnum
    member as an array index needs numba 0.64 or newer (0.59 and 0.63 refuse it: "Unsupported
    array index type IntEnum"). The machine code is that of an integer literal either way.
    """
    twin = namedtuple(enum.__name__, list(enum.__members__))  # type: ignore[misc]
    return twin(*(int(m) for m in enum))


#: the record blocks of ``I`` and ``P``, declared once: (family, "I" or "P") -> (header slot of
#: the block's offset, header slot of the record count, the record's fields). The kernel's
#: views (model/base.py) and the compiler's accessors by name are built from it.
RECORD_BLOCKS = {
    ("node", "I"): (H.OFF_NI, H.NN, NodeI),
    ("node", "P"): (H.OFF_NP, H.NN, NodeP),
    ("span", "I"): (H.OFF_SI, H.NS, SpanI),
    ("span", "P"): (H.OFF_SP, H.NS, SpanP),
    ("sensor", "I"): (H.OFF_SEI, H.NSE, SensorI),
    ("sensor", "P"): (H.OFF_SEP, H.NSE, SensorP),
    ("ctrl", "I"): (H.OFF_CI, H.NC, CtrlI),
    ("ctrl", "P"): (H.OFF_CP, H.NC, CtrlP),
    ("mover", "I"): (H.OFF_MI, H.NM, MoverI),
    ("mover", "P"): (H.OFF_MP, H.NM, MoverP),
    ("joint", "P"): (H.OFF_JP, H.NJ, JointP),
    ("fault", "P"): (H.OFF_FS, H.NFS, FaultP),
    ("event", "I"): (H.OFF_EV, H.NEV, EventI),
}


#: every enum above by name, as :func:`frozen` twins (what the kernel imports, in model/base.py)
FROZEN = {
    e.__name__: frozen(e)
    for e in (
        H,
        NodeKind,
        DriveKind,
        NodeI,
        NodeP,
        SpanI,
        SpanP,
        SensorKind,
        SensorI,
        SensorP,
        CtrlKind,
        CtrlI,
        CtrlP,
        MoverKind,
        MoverI,
        MoverP,
        JointP,
        FaultP,
        TableKind,
        TableI,
        Shape,
        EventKind,
        EventI,
        Mode,
    )
}
