"""The numba kernel of a compiled line: right-hand side, analytic Jacobian, outputs, events.

One function, :func:`evaluate`, computes the right-hand side. With ``mode=Mode.JAC`` it also
propagates, for every intermediate quantity (span tension, node speed, sensor reading,
controller output, drive torque, ...), a short sparse gradient with respect to the states, and
accumulates the chain rule into the Jacobian; ``Mode.TOUCH`` marks the entries instead, which
is how the compiler obtains the exact sparsity pattern. Every dependency is recorded whichever
branch is taken (slack or taut, forward or reverse flow, saturated or not), with a zero
derivative where it is inactive, so the pattern is the same at every state.

Everything the kernel reads is in two flat arrays, ``I`` (int64) and ``P`` (float64), laid out
by :mod:`r2rsim.compile.layout`; scratch arrays are allocated once by the compiler. Nothing
here allocates or touches a Python object.
"""

from __future__ import annotations

import math

from numba import njit
from numba.core import cgutils, types
from numba.core.caching import FunctionCache
from numba.core.dispatcher import Dispatcher
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

from .layout import (
    AUX_CTRL,
    AUX_JOINT,
    AUX_MOVER,
    AUX_NODE,
    AUX_SENS,
    AUX_SPAN,
    FROZEN,
    N_CTRL_I,
    N_CTRL_P,
    N_EVENT_I,
    N_FAULT_P,
    N_JOINT_P,
    N_MOVER_I,
    N_MOVER_P,
    N_NODE_I,
    N_NODE_P,
    N_SENSOR_I,
    N_SENSOR_P,
    N_SPAN_I,
    N_SPAN_P,
    N_TABLE_I,
    RUNTIME_MODE,
)
from .stamp import kernel_stamp

# the record fields and kinds as plain-int namedtuples: numba reads them as constants with
# every supported numba version (layout.frozen says why not the IntEnums themselves)
CtrlI = FROZEN["CtrlI"]
CtrlKind = FROZEN["CtrlKind"]
CtrlP = FROZEN["CtrlP"]
DriveKind = FROZEN["DriveKind"]
EventI = FROZEN["EventI"]
EventKind = FROZEN["EventKind"]
FaultP = FROZEN["FaultP"]
H = FROZEN["H"]
JointP = FROZEN["JointP"]
Mode = FROZEN["Mode"]
MoverI = FROZEN["MoverI"]
MoverKind = FROZEN["MoverKind"]
MoverP = FROZEN["MoverP"]
NodeI = FROZEN["NodeI"]
NodeKind = FROZEN["NodeKind"]
NodeP = FROZEN["NodeP"]
SensorI = FROZEN["SensorI"]
SensorKind = FROZEN["SensorKind"]
SensorP = FROZEN["SensorP"]
Shape = FROZEN["Shape"]
SpanI = FROZEN["SpanI"]
SpanP = FROZEN["SpanP"]
TableI = FROZEN["TableI"]
TableKind = FROZEN["TableKind"]

#: index of the right-hand-side mode in RUNTIME_MODE, for compiled callers outside
#: ``compile/`` (the integrator in ``solve/radau.py``): ``RUNTIME_MODE[MODE_RHS]`` is an int64,
#: so numba compiles :func:`evaluate` once for it and Python's calls alike
MODE_RHS = int(Mode.RHS)

PI = math.pi


# --------------------------------------------------------------------------- record views
@intrinsic
def _records(typingctx, a, start, n, size):
    """Zero-copy C-contiguous (n, size) view of the ``n`` records of ``size`` fields at
    ``a[start:]`` (``a`` a 1-D C array): ``node_p = _records(P, o, nN, N_NODE_P)`` reads
    ``node_p[k, NodeP.R]``.

    Not ``a[start:stop].reshape(n, size)``: numba's reshape checks the new shape at run time,
    which made an evaluation ~400 ns slower (12 views; quickstart and newsprint_splice, the
    right-hand side +65-90 %); and not ``as_strided``: its 'A'-layout view made the Jacobian
    ~65 % slower (measured 2026-11-27). This only fills the array structure. The view holds
    no reference (its meminfo is null): it must not outlive ``a``, which holds for views made
    and dropped inside one kernel call.
    """
    if not (isinstance(a, types.Array) and a.ndim == 1 and a.layout == "C"):
        return None
    retty = a.copy(ndim=2, layout="C")
    sig = retty(a, start, n, size)

    def codegen(context, builder, sig, args):
        aryty, startty, nty, sizety = sig.args
        ary = make_array(aryty)(context, builder, args[0])
        start_ = context.cast(builder, args[1], startty, types.intp)
        n_ = context.cast(builder, args[2], nty, types.intp)
        size_ = context.cast(builder, args[3], sizety, types.intp)
        itemsize = ary.itemsize
        out = make_array(sig.return_type)(context, builder)
        populate_array(
            out,
            data=builder.gep(ary.data, [start_]),
            shape=cgutils.pack_array(builder, [n_, size_]),
            strides=cgutils.pack_array(builder, [builder.mul(size_, itemsize), itemsize]),
            itemsize=itemsize,
            meminfo=None,
        )
        return out._getvalue()

    return sig, codegen


# --------------------------------------------------------------------------- sparse gradients
@njit(cache=True)
def _g_add(GI, GC, GV, maxd, q, idx, val):
    base = q * maxd
    n = GC[q]
    for m in range(n):
        if GI[base + m] == idx:
            GV[base + m] += val
            return
    if n >= maxd:
        raise RuntimeError("r2rsim kernel: too many dependencies for one quantity")
    GI[base + n] = idx
    GV[base + n] = val
    GC[q] = n + 1


@njit(cache=True)
def _g_axpy(GI, GC, GV, maxd, qdst, a, qsrc):
    base = qsrc * maxd
    for m in range(GC[qsrc]):
        _g_add(GI, GC, GV, maxd, qdst, GI[base + m], a * GV[base + m])


@njit(cache=True)
def _sensor_fault(t, sensor_p, j, W, iraw, irw0, jac, GC, GV, maxd, q):
    """Apply a sensor's in-loop fault (offset, gain, drift, stuck) to its raw reading; the
    fault-free reading is kept at W[irw0] for the true (shadow) channel."""
    W[irw0] = W[iraw]
    if sensor_p[j, SensorP.FON] == 0.0:
        return
    if sensor_p[j, SensorP.STUCK] != 0.0:
        W[iraw] = sensor_p[j, SensorP.SV]
        if jac:
            GC[q] = 0
        return
    dt = t - sensor_p[j, SensorP.FT0]
    g = (
        1.0
        + sensor_p[j, SensorP.GA]
        + sensor_p[j, SensorP.GB] * dt
        + sensor_p[j, SensorP.GC] * math.exp(-dt / sensor_p[j, SensorP.GTAU])
    )
    bias = (
        sensor_p[j, SensorP.BA]
        + sensor_p[j, SensorP.BB] * dt
        + sensor_p[j, SensorP.BC] * math.exp(-dt / sensor_p[j, SensorP.BTAU])
    )
    W[iraw] = g * W[iraw] + bias
    if jac:
        for e in range(GC[q]):
            GV[q * maxd + e] *= g


@njit(cache=True)
def _j_add(JJ, mode, row, col, val):
    if mode == Mode.TOUCH:
        JJ[row, col] = 1.0
    else:
        JJ[row, col] += val


@njit(cache=True)
def _j_axpy(JJ, mode, row, a, GI, GC, GV, maxd, q):
    base = q * maxd
    for m in range(GC[q]):
        _j_add(JJ, mode, row, GI[base + m], a * GV[base + m])


# --------------------------------------------------------------------------- set-points
@njit(cache=True)
def setpoint(I, P, ch, t):
    """Value and slope of set-point channel ``ch`` at time t (piecewise linear).

    The piece is chosen by the start time of the current solver segment (``P[rt]``), so a
    segment that ends exactly at a corner keeps the slope it started with.
    """
    mx = I[H.MAXPTS]
    n = I[I[H.OFF_SCHN] + ch]
    bt = I[H.OFF_SCHT] + ch * mx
    bv = I[H.OFF_SCHV] + ch * mx
    tseg = P[I[H.OFF_RT]]
    k = 0
    for m in range(n):
        if P[bt + m] <= tseg:
            k = m
    if k >= n - 1:
        return P[bv + n - 1], 0.0
    dt = P[bt + k + 1] - P[bt + k]
    slope = (P[bv + k + 1] - P[bv + k]) / dt if dt > 0.0 else 0.0
    return P[bv + k] + slope * (t - P[bt + k]), slope


# --------------------------------------------------------------------------- scratch layout
@njit(cache=True)
def _offsets(I):
    """Offsets of the value blocks in the scratch array W and of the gradient quantities."""
    nN = I[H.NN]
    nS = I[H.NS]
    nSe = I[H.NSE]
    nC = I[H.NC]
    nM = I[H.NM]
    oT = 0
    oEM = oT + nS
    oL = oEM + nS
    oLD = oL + nS
    oLP = oLD + nS
    oLPP = oLP + nS
    oEAE = oLPP + nS
    oV = oEAE + nS
    oR = oV + nN
    oOM = oR + nN
    oJ = oOM + nN
    oTRIM = oJ + nN
    oTCMD = oTRIM + nN
    oTM = oTCMD + nN
    oRAW = oTM + nN
    oYS = oRAW + nSe
    oU = oYS + nSe
    oE = oU + nC
    oMF = oE + nC
    oMW = oMF + nM
    oXF = oMW + nM
    oRW0 = oXF + nN
    oEW = oRW0 + nSe
    oDC = oEW + 2 * nN
    return (
        oT,
        oEM,
        oL,
        oLD,
        oLP,
        oLPP,
        oEAE,
        oV,
        oR,
        oOM,
        oJ,
        oTRIM,
        oTCMD,
        oTM,
        oRAW,
        oYS,
        oU,
        oE,
        oMF,
        oMW,
        oXF,
        oRW0,
        oEW,
        oDC,
    )


DRAG_CACHE = 7  # per node: three times, their drag torques, the next slot to fill


@njit(cache=True)
def scratch_layout(I):
    """(start of the drag cache, length W needs): the compiler sizes W with them and marks
    the cache empty."""
    oDC = _offsets(I)[-1]
    return oDC, oDC + DRAG_CACHE * I[H.NN]


@njit(cache=True)
def _drag(I, P, W, oDC, k, t):
    """Random bearing-drag torque on node ``k`` at ``t``, through a three-slot cache: Radau
    IIA evaluates each stage time at every Newton iteration and again at the step's end, and
    the drag tables are fixed when the line is compiled, so ``t`` alone is the key."""
    b = oDC + DRAG_CACHE * k
    for s in range(3):
        if W[b + s] == t:
            return W[b + 3 + s]
    v = table_value(I, P, TableKind.DRAG, k, t)
    s = int(W[b + 6]) % 3
    W[b + s] = t
    W[b + 3 + s] = v
    W[b + 6] = s + 1
    return v


# --------------------------------------------------------------------------- mover geometry
@njit(cache=True)
def _span_geo(ax, ay, bx, by, delta, trx, tr_y, sgn, dcx, dcy):
    """Path length of the web between circle a and circle b (centres, signed radius offset
    delta = s_b·r_b - s_a·r_a) relative to a reference direction, and its rate per unit
    motion of the moving centre (physics.md eq. 1.14: dL = -e·dC).

    L = lambda - delta·(psi - psi_ref): the free tangent length plus the wrap arcs gained or
    lost as the tangent points migrate, so that dL/dq = t·dC/dq exactly.
    """
    dx = bx - ax
    dy = by - ay
    D2 = dx * dx + dy * dy
    lam = math.sqrt(max(D2 - delta * delta, 1e-30))
    tx = (lam * dx + delta * dy) / D2
    ty = (lam * dy - delta * dx) / D2
    dpsi = math.atan2(trx * ty - tr_y * tx, trx * tx + tr_y * ty)
    return lam - delta * dpsi, sgn * (tx * dcx + ty * dcy)


@njit(cache=True)
def mover_lengths(mover_p, m, kind, q):
    """(L_up, dL_up/dq, L_down, dL_down/dq) of the two spans at a dancer at coordinate q."""
    if kind == MoverKind.LINEAR:
        dcx = mover_p[m, MoverP.NX]
        dcy = mover_p[m, MoverP.NY]
        cx = mover_p[m, MoverP.CX] + q * dcx
        cy = mover_p[m, MoverP.CY] + q * dcy
    else:
        arm = mover_p[m, MoverP.NX]
        dcx = -arm * math.sin(q)
        dcy = arm * math.cos(q)
        cx = mover_p[m, MoverP.CX] + arm * math.cos(q)
        cy = mover_p[m, MoverP.CY] + arm * math.sin(q)
    lu, dlu = _span_geo(
        mover_p[m, MoverP.AX],
        mover_p[m, MoverP.AY],
        cx,
        cy,
        mover_p[m, MoverP.DU],
        mover_p[m, MoverP.TUX],
        mover_p[m, MoverP.TUY],
        1.0,
        dcx,
        dcy,
    )
    ld, dld = _span_geo(
        cx,
        cy,
        mover_p[m, MoverP.BX],
        mover_p[m, MoverP.BY],
        mover_p[m, MoverP.DD],
        mover_p[m, MoverP.TDX],
        mover_p[m, MoverP.TDY],
        -1.0,
        dcx,
        dcy,
    )
    return lu, dlu, ld, dld


@njit(cache=True)
def _mover_load(mover_p, m, kind, q):
    """Generalised actuator + spring + gravity force on a mover (without web and friction).
    The actuator (air cylinder, torque motor) is scaled by LOADF (loss of loading)."""
    la = mover_p[m, MoverP.LOADF]
    f = (
        mover_p[m, MoverP.F0]
        + la * mover_p[m, MoverP.FAIR]
        - mover_p[m, MoverP.K] * (q - mover_p[m, MoverP.Q0])
    )
    if kind == MoverKind.PIVOT:
        f += (la - 1.0) * mover_p[m, MoverP.F0]  # a pivot's F0 is its torque motor
        f += mover_p[m, MoverP.G1] * math.cos(q) + mover_p[m, MoverP.G2] * math.sin(q)
        fc = la * mover_p[m, MoverP.CYLF]
        if fc != 0.0:
            a = mover_p[m, MoverP.CYLA]
            rx = mover_p[m, MoverP.CX] + a * math.cos(q) - mover_p[m, MoverP.CYLX]
            ry = mover_p[m, MoverP.CY] + a * math.sin(q) - mover_p[m, MoverP.CYLY]
            ylen = math.sqrt(rx * rx + ry * ry)
            if ylen > 0.0:
                f += fc * (rx * (-a * math.sin(q)) + ry * (a * math.cos(q))) / ylen
    return f


@njit(cache=True)
def table_value(I, P, kind, node, x):
    """Sum of the process disturbances of ``kind`` on ``node`` at x: a sum of sinusoids
    (``Shape.SINES``), or a table interpolated linearly and held constant outside its grid
    (``Shape.TABLE``)."""
    out = 0.0
    ntb = I[H.NTB]
    otb = I[H.OFF_TB]
    table_i = _records(I, otb, ntb, N_TABLE_I)
    for m in range(ntb):
        if table_i[m, TableI.KIND] != kind or table_i[m, TableI.NODE] != node:
            continue
        o = table_i[m, TableI.OFFP]
        n = table_i[m, TableI.N]
        if table_i[m, TableI.SHAPE] == Shape.SINES:
            for j in range(n):
                out += P[o + j] * math.sin(P[o + n + j] * x + P[o + 2 * n + j])
            continue
        s = (x - P[o]) / P[o + 1]
        if s <= 0.0:
            out += P[o + 2]
        elif s >= n - 1:
            out += P[o + 2 + n - 1]
        else:
            i = int(s)
            f = s - i
            out += (1.0 - f) * P[o + 2 + i] + f * P[o + 3 + i]
    return out


@njit(cache=True)
def sines_slope(I, P, kind, node, x):
    """d/dx of the sum-of-sinusoids disturbances of ``kind`` on ``node`` at x (the
    Jacobian's share; tables keep their earlier zero slope, so that they reproduce old data
    exactly)."""
    out = 0.0
    ntb = I[H.NTB]
    otb = I[H.OFF_TB]
    table_i = _records(I, otb, ntb, N_TABLE_I)
    for m in range(ntb):
        if (
            table_i[m, TableI.KIND] != kind
            or table_i[m, TableI.NODE] != node
            or table_i[m, TableI.SHAPE] != Shape.SINES
        ):
            continue
        o = table_i[m, TableI.OFFP]
        n = table_i[m, TableI.N]
        for j in range(n):
            w = P[o + n + j]
            out += P[o + j] * w * math.cos(w * x + P[o + 2 * n + j])
    return out


@njit(cache=True)
def has_sines(I, kind, node):
    """Whether ``node`` has a sum-of-sinusoids disturbance of ``kind`` (a structural
    property: it decides the Jacobian pattern)."""
    ntb = I[H.NTB]
    otb = I[H.OFF_TB]
    table_i = _records(I, otb, ntb, N_TABLE_I)
    for m in range(ntb):
        if (
            table_i[m, TableI.KIND] == kind
            and table_i[m, TableI.NODE] == node
            and table_i[m, TableI.SHAPE] == Shape.SINES
        ):
            return True
    return False


@njit(cache=True)
def roll_wound_in_strain(node_p, k, R):
    """Wound-in strain of a roll at radius R and its derivative (polynomial in R)."""
    e1 = node_p[k, NodeP.EPSW1]
    e2 = node_p[k, NodeP.EPSW2]
    return node_p[k, NodeP.EPSW] + e1 * R + e2 * R * R, e1 + 2.0 * e2 * R


# --------------------------------------------------------------------------- the kernel
# One long function on purpose, read section by section (0. to 13.): split into one njit
# function per section (measured 2026-11-25, pet_film_line_dancer, 33 states) it evaluated
# the right-hand side 2x slower; with inline="always" the Jacobian and the outputs were
# 15-20 % slower and the first compile took 40 % longer.
@njit(cache=True)
def evaluate(t, y, yd, JJ, mode, I, P, W, GI, GC, GV, aux):
    """Evaluate the line's ODE right-hand side into ``yd`` (and the Jacobian into ``JJ``).

    Parameters
    ----------
    t : float
        Time [s].
    y : ndarray
        State vector.
    yd : ndarray
        Output: dy/dt.
    JJ : ndarray (n, n)
        Jacobian (``Mode.JAC``: pattern entries are zeroed then filled; ``Mode.TOUCH``: pattern
        entries are set to 1). Ignored for ``Mode.RHS``.
    mode : int
        ``Mode.RHS``, ``Mode.JAC`` or ``Mode.TOUCH``.
    I, P : ndarray
        The compiled line (layout in :mod:`r2rsim.compile.layout`).
    W, GI, GC, GV : ndarray
        Scratch: values of intermediates; gradient indices, counts and values.
    aux : ndarray
        Output row of algebraic quantities (length 0 to skip).
    """
    nN = I[H.NN]
    nS = I[H.NS]
    nSe = I[H.NSE]
    nC = I[H.NC]
    nM = I[H.NM]
    nJ = I[H.NJ]
    nFS = I[H.NFS]
    # zero-copy views of the record blocks, one row per record: node_p[k, NodeP.R]
    oNI = I[H.OFF_NI]
    node_i = _records(I, oNI, nN, N_NODE_I)
    oSI = I[H.OFF_SI]
    span_i = _records(I, oSI, nS, N_SPAN_I)
    oSEI = I[H.OFF_SEI]
    sensor_i = _records(I, oSEI, nSe, N_SENSOR_I)
    oCI = I[H.OFF_CI]
    ctrl_i = _records(I, oCI, nC, N_CTRL_I)
    oMI = I[H.OFF_MI]
    mover_i = _records(I, oMI, nM, N_MOVER_I)
    oNP = I[H.OFF_NP]
    node_p = _records(P, oNP, nN, N_NODE_P)
    oSP = I[H.OFF_SP]
    span_p = _records(P, oSP, nS, N_SPAN_P)
    oSEP = I[H.OFF_SEP]
    sensor_p = _records(P, oSEP, nSe, N_SENSOR_P)
    oCP = I[H.OFF_CP]
    ctrl_p = _records(P, oCP, nC, N_CTRL_P)
    oMP = I[H.OFF_MP]
    mover_p = _records(P, oMP, nM, N_MOVER_P)
    oJP = I[H.OFF_JP]
    joint_p = _records(P, oJP, nJ, N_JOINT_P)
    oFS = I[H.OFF_FS]
    fault_p = _records(P, oFS, nFS, N_FAULT_P)
    linear = I[H.MODEL] == 1
    jac = mode != Mode.RHS
    maxd = I[H.MAXD]
    EAweb = P[I[H.EA]]
    ntb = I[H.NTB]

    (
        oT,
        oEM,
        oL,
        oLD,
        oLP,
        oLPP,
        oEAE,
        oV,
        oR,
        oOM,
        oJ,
        oTRIM,
        oTCMD,
        oTM,
        oRAW,
        oYS,
        oU,
        oE,
        oMF,
        oMW,
        oXF,
        oRW0,
        oEW,
        oDC,
    ) = _offsets(I)
    # gradient quantity ids
    qT = 0
    qL = qT + nS
    qLD = qL + nS
    qV = qLD + nS
    qR = qV + nN
    qOM = qR + nN
    qTRIM = qOM + nN
    qTCMD = qTRIM + nN
    qTM = qTCMD + nN
    qRAW = qTM + nN
    qY = qRAW + nSe
    qU = qY + nSe
    qE = qU + nC
    nq = qE + nC

    if jac:
        for q in range(nq):
            GC[q] = 0
        if mode == Mode.JAC:
            npat = I[H.NPAT]
            op = I[H.OFF_PAT]
            for m in range(npat):
                JJ[I[op + m], I[op + npat + m]] = 0.0

    V, A = setpoint(I, P, 0, t)

    # fault parameter slots: a ramp or exponential fault profile on a parameter
    for fs in range(nFS):
        if fault_p[fs, FaultP.ON] != 0.0:
            dt = t - fault_p[fs, FaultP.T0]
            P[int(fault_p[fs, FaultP.IDX])] = (
                fault_p[fs, FaultP.BASE]
                + fault_p[fs, FaultP.A]
                + fault_p[fs, FaultP.B] * dt
                + fault_p[fs, FaultP.C] * math.exp(-dt / fault_p[fs, FaultP.TAU])
            )

    # 0. span lengths: fixed, or set by a dancer's or festoon carriage's coordinate q
    for i in range(nS):
        W[oL + i] = span_p[i, SpanP.L]
        W[oLD + i] = 0.0
        W[oLP + i] = 0.0
        W[oLPP + i] = 0.0
        W[oEAE + i] = span_p[i, SpanP.EA]
    for m in range(nM):
        kind = mover_i[m, MoverI.KIND]
        iq = mover_i[m, MoverI.Q]
        q = y[iq]
        su = mover_i[m, MoverI.SPAN_U]
        sd = mover_i[m, MoverI.SPAN_D]
        if kind == MoverKind.FESTOON:
            W[oL + su] = span_p[su, SpanP.L] + mover_p[m, MoverP.NSTR] * q
            W[oLP + su] = mover_p[m, MoverP.NSTR]
        else:
            lu, dlu, ld, dld = mover_lengths(mover_p, m, kind, q)
            h = 1e-6
            _, dlu1, _, dld1 = mover_lengths(mover_p, m, kind, q + h)
            _, dlu0, _, dld0 = mover_lengths(mover_p, m, kind, q - h)
            W[oL + su] = lu
            W[oLP + su] = dlu
            W[oLPP + su] = (dlu1 - dlu0) / (2.0 * h)
            W[oL + sd] = ld
            W[oLP + sd] = dld
            W[oLPP + sd] = (dld1 - dld0) / (2.0 * h)
    for m in range(nM):
        iq = mover_i[m, MoverI.Q]
        iqd = mover_i[m, MoverI.QD]
        for side in range(2):
            sp = mover_i[m, MoverI.SPAN_U + side]
            if sp < 0:
                continue
            W[oLD + sp] = W[oLP + sp] * y[iqd]
            if jac:
                _g_add(GI, GC, GV, maxd, qL + sp, iq, W[oLP + sp])
                _g_add(GI, GC, GV, maxd, qLD + sp, iq, W[oLPP + sp] * y[iqd])
                _g_add(GI, GC, GV, maxd, qLD + sp, iqd, W[oLP + sp])
    # eccentric rollers: the centre runs on a circle of radius ECC with the roller angle th,
    # so L_up += ECC·cos(th) and L_dn -= ECC·cos(th - wrap) (physics.md §1.2, non-ideal
    # rollers); the web still leaves the roller surface at omega·R
    for k in range(nN):
        ith = node_i[k, NodeI.TH]
        if ith < 0:
            continue
        iw = node_i[k, NodeI.W]
        ecc = node_p[k, NodeP.ECC]
        th = y[ith]
        om = y[iw]
        yd[ith] = om
        if jac:
            _j_add(JJ, mode, ith, iw, 1.0)
        for side in range(2):
            sp = node_i[k, NodeI.SPAN_UP + side]
            if sp < 0:
                continue
            ph = th - side * node_p[k, NodeP.WRAP]
            sg = 1.0 - 2.0 * side
            W[oL + sp] += sg * ecc * math.cos(ph)
            W[oLD + sp] -= sg * ecc * om * math.sin(ph)
            if jac:
                _g_add(GI, GC, GV, maxd, qL + sp, ith, -sg * ecc * math.sin(ph))
                _g_add(GI, GC, GV, maxd, qLD + sp, ith, -sg * ecc * om * math.cos(ph))
                _g_add(GI, GC, GV, maxd, qLD + sp, iw, -sg * ecc * math.sin(ph))

    # splice joints: a span holding joint length l_s has compliance (l - l_s)/EA + l_s/EA_s
    # (physics.md eq. 1.19). The joint's place is fixed by the unstretched length paid out
    # since the splice. Mass conservation: while the joint crosses a node the web crossing
    # it is the joint, at strain T/EA_s (factor XF = EA/EA_s on the carried strain); without
    # this the span's tension would jump with its compliance as the joint enters. The
    # Jacobian treats the overlap as constant (it changes only while the joint crosses a node).
    # Which nodes the joint straddles is latched by the joint-pass events (JointP.SPAN holds the
    # lead, JointP.TSPAN the trail), not read from the state: the flux jumps there, and a jump
    # inside a step makes an implicit method shrink its step until it fails (scipy's Radau
    # did, at rtol 1e-5..1e-7). Between events the right-hand side stays smooth.
    for k in range(nN):
        W[oXF + k] = 1.0
    for js in range(nJ):
        if joint_p[js, JointP.ACTIVE] == 0.0:
            continue
        k0 = int(joint_p[js, JointP.NODE])
        lead = y[node_i[k0, NodeI.U]] - joint_p[js, JointP.U0]
        trail = lead - joint_p[js, JointP.LEN]
        xf = 1.0 / joint_p[js, JointP.RATIO]
        sp_lead = int(joint_p[js, JointP.SPAN])
        sp_trail = int(joint_p[js, JointP.TSPAN])
        if sp_trail < k0:  # the trail is still on the roll
            W[oXF + k0] = xf
        for i in range(max(sp_trail, 0), min(sp_lead, nS)):
            W[oXF + span_i[i, SpanI.DN]] = xf
        c0 = 0.0
        for i in range(nS):
            ell = W[oL + i] / max(1.0 + y[span_i[i, SpanI.E]], 1e-6)
            ov = min(c0 + ell, lead) - max(c0, trail)
            if ov > 0.0:
                frac = min(ov / ell, 1.0)
                W[oEAE + i] = W[oEAE + i] / (1.0 - frac * (1.0 - xf))
            c0 += ell
            if c0 >= lead:
                break

    # 1. spans: tension from the material strain (slack: geometric strain < 0 carries none).
    # The strain carried through the nodes is that of the plain web, T/EA.
    for i in range(nS):
        ie = span_i[i, SpanI.E]
        e = y[ie]
        EA = W[oEAE + i]
        em = e if e > 0.0 else 0.0
        W[oT + i] = EA * em
        W[oEM + i] = EA * em / EAweb
        if jac:
            _g_add(GI, GC, GV, maxd, qT + i, ie, EA if e > 0.0 else 0.0)

    # 2. nodes: radius, inertia, angular speed state
    for k in range(nN):
        kind = node_i[k, NodeI.KIND]
        if kind != NodeKind.ROLLER:
            iS = node_i[k, NodeI.S]
            sg = -1.0 if kind == NodeKind.UNWIND else 1.0
            R2 = node_p[k, NodeP.R0] ** 2 + sg * node_p[k, NodeP.CW] / PI * y[iS]
            R = math.sqrt(R2) if R2 > 1e-12 else 1e-6
            W[oR + k] = R
            Rc = node_p[k, NodeP.RC]
            W[oJ + k] = node_p[k, NodeP.JC] + 0.5 * PI * node_p[k, NodeP.RHOW] * (R**4 - Rc**4)
            if jac:
                _g_add(GI, GC, GV, maxd, qR + k, iS, sg * node_p[k, NodeP.CW] / (2.0 * PI * R))
        else:
            W[oR + k] = node_p[k, NodeP.R]
            W[oJ + k] = node_p[k, NodeP.J]
        iw = node_i[k, NodeI.W]
        W[oTRIM + k] = 0.0
        W[oTCMD + k] = 0.0
        W[oTM + k] = 0.0
        if iw >= 0:
            W[oOM + k] = y[iw]
            if jac:
                _g_add(GI, GC, GV, maxd, qOM + k, iw, 1.0)

    # 2b. movers (dancer carriage/arm, festoon carriage): M·q'' = -sum T·dL/dq + load
    #     - c·q' - F_c·tanh(q'/eps); latched at an end stop or seized: q' = 0 and held
    for m in range(nM):
        kind = mover_i[m, MoverI.KIND]
        iq = mover_i[m, MoverI.Q]
        iqd = mover_i[m, MoverI.QD]
        q = y[iq]
        qd = y[iqd]
        fweb = 0.0
        kweb = 0.0
        for side in range(2):
            sp = mover_i[m, MoverI.SPAN_U + side]
            if sp >= 0:
                fweb -= W[oT + sp] * W[oLP + sp]
                kweb -= W[oT + sp] * W[oLPP + sp]
        load = _mover_load(mover_p, m, kind, q)
        h = 1e-7
        dload = (_mover_load(mover_p, m, kind, q + h) - _mover_load(mover_p, m, kind, q - h)) / (
            2.0 * h
        )
        eps = mover_p[m, MoverP.EPS]
        th = math.tanh(qd / eps)
        ff = mover_p[m, MoverP.FRICF]
        fric = ff * (mover_p[m, MoverP.C] * qd + mover_p[m, MoverP.FC] * th)
        dfric = ff * (mover_p[m, MoverP.C] + mover_p[m, MoverP.FC] * (1.0 - th * th) / eps)
        W[oMW + m] = fweb
        W[oMF + m] = fweb + load
        free = 1.0 if mover_p[m, MoverP.MODE] == 0.0 else 0.0
        M = mover_p[m, MoverP.MASS]
        yd[iq] = free * qd
        yd[iqd] = free * (fweb + load - fric) / M
        if jac:
            _j_add(JJ, mode, iq, iqd, free)
            for side in range(2):
                sp = mover_i[m, MoverI.SPAN_U + side]
                if sp >= 0:
                    _j_axpy(JJ, mode, iqd, -free * W[oLP + sp] / M, GI, GC, GV, maxd, qT + sp)
            _j_add(JJ, mode, iqd, iq, free * (kweb + dload) / M)
            _j_add(JJ, mode, iqd, iqd, -free * dfric / M)

    # 3. sensor readings that do not need imposed speeds
    for j in range(nSe):
        typ = sensor_i[j, SensorI.TYPE]
        node = sensor_i[j, SensorI.NODE]
        iF = sensor_i[j, SensorI.F]
        g = sensor_p[j, SensorP.GAIN]
        if typ == SensorKind.ENCODER and node_i[node, NodeI.W] < 0:
            continue  # imposed-speed node: read after step 7
        if typ == SensorKind.DANCER:  # node holds the mover index
            iq = mover_i[node, MoverI.Q]
            W[oRAW + j] = g * y[iq] + sensor_p[j, SensorP.OFF]
            if jac:
                _g_add(GI, GC, GV, maxd, qRAW + j, iq, g)
        elif typ == SensorKind.PITCH:  # node holds the span index; pitch = (T/ES + 1)·L0
            rn = sensor_i[j, SensorI.RNODE]
            # E·S and L0 offset of the roll whose web is at the sensor
            ratio, dl0 = _pitch_material(node, rn, sensor_p, j, joint_p)
            ES = EAweb * ratio
            if rn < 0:
                L0 = sensor_p[j, SensorP.CIN] + dl0
                W[oRAW + j] = g * (W[oT + node] / ES + 1.0) * L0 + sensor_p[j, SensorP.OFF]
                if jac:
                    _g_axpy(GI, GC, GV, maxd, qRAW + j, g * L0 / ES, qT + node)
            else:  # L0 = q0 + q1·R³ of the unwind's radius + the printing variation in u
                L0, dL0dR, dL0du, iU = _pitch_l0(j, rn, P, sensor_p, sensor_i, node_i, W, oR, y)
                L0 += dl0
                h = g * (W[oT + node] / ES + 1.0)
                W[oRAW + j] = h * L0 + sensor_p[j, SensorP.OFF]
                if jac:
                    _g_axpy(GI, GC, GV, maxd, qRAW + j, g * L0 / ES, qT + node)
                    _g_axpy(GI, GC, GV, maxd, qRAW + j, h * dL0dR, qR + rn)
                    if sensor_i[j, SensorI.VN] > 0:
                        _g_add(GI, GC, GV, maxd, qRAW + j, iU, h * dL0du)
        else:
            _sensor_raw(
                j,
                typ,
                node,
                g,
                sensor_p[j, SensorP.OFF],
                sensor_p[j, SensorP.WIN],
                sensor_p[j, SensorP.WOUT],
                node_i[node, NodeI.SPAN_UP],
                node_i[node, NodeI.SPAN_DN],
                W,
                oT,
                oR,
                oOM,
                oRAW,
                jac,
                GI,
                GC,
                GV,
                maxd,
                qT,
                qR,
                qOM,
                qRAW,
            )
        _sensor_fault(t, sensor_p, j, W, oRAW + j, oRW0 + j, jac, GC, GV, maxd, qRAW + j)
        if iF >= 0:
            W[oYS + j] = y[iF]
            if jac:
                _g_add(GI, GC, GV, maxd, qY + j, iF, 1.0)
        else:
            W[oYS + j] = W[oRAW + j]
            if jac:
                _g_axpy(GI, GC, GV, maxd, qY + j, 1.0, qRAW + j)

    # 4. tension controllers (PI on a load cell) with back-calculation anti-windup
    for c in range(nC):
        typ = ctrl_i[c, CtrlI.TYPE]
        if typ == CtrlKind.SPEED:
            continue
        node = ctrl_i[c, CtrlI.NODE]
        ix = ctrl_i[c, CtrlI.X]
        sens = ctrl_i[c, CtrlI.SENSOR]
        kp = ctrl_p[c, CtrlP.KP]
        ki = ctrl_p[c, CtrlP.KI]
        lim = ctrl_p[c, CtrlP.LIM]
        rn = -1  # unwind node of a pitch sensor's relaxed-pitch law (-1: constant L0)
        wr = 0.0
        # the measurement enters with weight -1 through the quantity qmeas (or a state)
        if typ == CtrlKind.DANCER:
            imq = mover_i[ctrl_i[c, CtrlI.MOVER], MoverI.Q]
            e = ctrl_p[c, CtrlP.SETP] - (W[oYS + sens] if sens >= 0 else y[imq])
        else:
            Tref, _ = setpoint(I, P, ctrl_i[c, CtrlI.CH], t)
            # a pitch-length sensor is read as tension through the calibrated Hooke's law
            if sensor_i[sens, SensorI.TYPE] == SensorKind.PITCH:
                rn = sensor_i[sens, SensorI.RNODE]
                if rn < 0:
                    wy = sensor_p[sens, SensorP.COUT] / sensor_p[sens, SensorP.CIN]
                    e = (
                        Tref
                        - (W[oYS + sens] / sensor_p[sens, SensorP.CIN] - 1.0)
                        * sensor_p[sens, SensorP.COUT]
                    )
                else:  # calibrated with the law L0(R), not the (unknown) variation
                    Rn = W[oR + rn]
                    L0c = sensor_p[sens, SensorP.CIN] + sensor_p[sens, SensorP.Q1] * Rn * Rn * Rn
                    wy = sensor_p[sens, SensorP.COUT] / L0c
                    e = Tref - (W[oYS + sens] / L0c - 1.0) * sensor_p[sens, SensorP.COUT]
                    # de/dR through L0c
                    wr = (
                        W[oYS + sens]
                        * sensor_p[sens, SensorP.COUT]
                        / (L0c * L0c)
                        * (3.0 * sensor_p[sens, SensorP.Q1] * Rn * Rn)
                    )
            else:
                wy = 1.0
                e = Tref - W[oYS + sens]
        # a gated loop (dancer loop during a splice) holds its integrator and outputs 0
        gate = 1.0 if ctrl_p[c, CtrlP.GATE] > 0.0 else 0.0
        x = y[ix] if ix >= 0 else 0.0
        upi = kp * e + ki * x
        u = min(max(upi, -lim), lim)
        act = 1.0 if u == upi else 0.0
        W[oU + c] = gate * u
        W[oE + c] = e
        if typ == CtrlKind.DANCER:
            wy = 1.0
        if jac:
            if sens >= 0:
                _g_axpy(GI, GC, GV, maxd, qU + c, -gate * kp * act * wy, qY + sens)
                if rn >= 0:
                    _g_axpy(GI, GC, GV, maxd, qU + c, gate * kp * act * wr, qR + rn)
            else:
                _g_add(GI, GC, GV, maxd, qU + c, imq, -gate * kp * act)
            if ix >= 0:
                _g_add(GI, GC, GV, maxd, qU + c, ix, gate * ki * act)
        if ix >= 0:
            kaw = ctrl_p[c, CtrlP.KAW] / ki
            yd[ix] = gate * (e + kaw * (u - upi))
            if jac:
                # d(u - upi) = (act - 1) * d(upi)
                wm = gate * (-1.0 + kaw * (act - 1.0) * (-kp))
                if sens >= 0:
                    _j_axpy(JJ, mode, ix, wm * wy, GI, GC, GV, maxd, qY + sens)
                    if rn >= 0:
                        _j_axpy(JJ, mode, ix, -wm * wr, GI, GC, GV, maxd, qR + rn)
                else:
                    _j_add(JJ, mode, ix, imq, wm)
                _j_add(JJ, mode, ix, ix, gate * kaw * (act - 1.0) * ki)
        if typ == CtrlKind.TENSION_TRIM or typ == CtrlKind.DANCER:
            sgn = ctrl_p[c, CtrlP.SIGN]
            W[oTRIM + node] += sgn * W[oU + c]
            if jac:
                _g_axpy(GI, GC, GV, maxd, qTRIM + node, sgn, qU + c)

    # 5. torque commands: speed PI (+ inertia feed-forward) and torque-mode tension control
    for c in range(nC):
        typ = ctrl_i[c, CtrlI.TYPE]
        if typ == CtrlKind.TENSION_TRIM or typ == CtrlKind.DANCER:
            continue
        k = ctrl_i[c, CtrlI.NODE]
        ix = ctrl_i[c, CtrlI.X]
        kp = ctrl_p[c, CtrlP.KP]
        ki = ctrl_p[c, CtrlP.KI]
        ff = ctrl_p[c, CtrlP.FF]
        kind = node_i[k, NodeI.KIND]
        if typ == CtrlKind.SPEED:
            R = W[oR + k]
            vg = node_p[k, NodeP.VGAIN]
            # a programmed draw is a set-point channel; its slope enters the feed-forward
            dch = node_i[k, NodeI.DRAWCH]
            if dch >= 0:
                draw, ddraw = setpoint(I, P, dch, t)
            else:
                draw = ctrl_p[c, CtrlP.DRAW]
                ddraw = 0.0
            vref = (
                V * (1.0 + draw) * vg
                + node_p[k, NodeP.VOFF]
                + node_p[k, NodeP.VSLOPE] * (t - node_p[k, NodeP.VT0])
                + W[oTRIM + k]
            )
            wref = vref / R
            sens = ctrl_i[c, CtrlI.SENSOR]
            wm = W[oYS + sens] if sens >= 0 else W[oOM + k]
            e = wref - wm
            W[oE + c] = e
            x = y[ix] if ix >= 0 else 0.0
            J = W[oJ + k]
            acc = A * (1.0 + draw) * vg
            if dch >= 0:
                acc += V * ddraw * vg  # d/dt of V·(1 + draw)
            aref = (acc + node_p[k, NodeP.VSLOPE]) / R
            tau = kp * e + ki * x + ff * J * aref
            W[oTCMD + k] += tau
            if jac:
                _g_axpy(GI, GC, GV, maxd, qE + c, 1.0 / R, qTRIM + k)
                _g_axpy(GI, GC, GV, maxd, qE + c, -vref / (R * R), qR + k)
                if sens >= 0:
                    _g_axpy(GI, GC, GV, maxd, qE + c, -1.0, qY + sens)
                else:
                    _g_axpy(GI, GC, GV, maxd, qE + c, -1.0, qOM + k)
                _g_axpy(GI, GC, GV, maxd, qTCMD + k, kp, qE + c)
                if ix >= 0:
                    _g_add(GI, GC, GV, maxd, qTCMD + k, ix, ki)
                if kind != NodeKind.ROLLER:
                    dJdR = 2.0 * PI * node_p[k, NodeP.RHOW] * R**3
                    _g_axpy(GI, GC, GV, maxd, qTCMD + k, ff * (dJdR * aref - J * aref / R), qR + k)
        else:  # torque-mode tension control of a roll
            sgn = -1.0 if kind == NodeKind.UNWIND else 1.0
            rs = ctrl_i[c, CtrlI.RSENSOR]
            Rh = 0.5 * W[oYS + rs] if rs >= 0 else W[oR + k]
            Rc = node_p[k, NodeP.RC]
            # the radius estimate is never below the core (a failed sensor reading 0 must not
            # divide by zero); clamped, it no longer depends on the states
            live = 1.0
            if Rh < Rc:
                Rh = Rc
                live = 0.0
            Tref, _ = setpoint(I, P, ctrl_i[c, CtrlI.CH], t)
            u = W[oU + c]
            # feed-forward terms (CtrlP.FF, JFAC, JABS, RR, FRF): the inertia
            # estimate J_est = JFAC·J(R_hat) + JABS, the radius-rate part of alpha (rr) and
            # friction (fr) are switched one by one; the defaults reproduce
            # sgn·R_hat·(T_ref + u) + (J(R_hat)·alpha + tau_f) to the last bit
            jfac = ctrl_p[c, CtrlP.JFAC]
            rr = ctrl_p[c, CtrlP.RR]
            fr = ctrl_p[c, CtrlP.FRF]
            Jh = (
                jfac * (node_p[k, NodeP.JC] + 0.5 * PI * node_p[k, NodeP.RHOW] * (Rh**4 - Rc**4))
                + ctrl_p[c, CtrlP.JABS]
            )
            dJh = jfac * (2.0 * PI * node_p[k, NodeP.RHOW] * Rh**3)
            cw = node_p[k, NodeP.CW]
            alpha = A / Rh - rr * sgn * cw * V * V / (2.0 * PI * Rh**3)
            dalpha = -A / (Rh * Rh) + 3.0 * rr * sgn * cw * V * V / (2.0 * PI * Rh**4)
            om = W[oOM + k]
            weps = node_p[k, NodeP.WEPS]
            th = math.tanh(om / weps)
            tf = node_p[k, NodeP.B] * om + node_p[k, NodeP.TC] * th
            dtf = node_p[k, NodeP.B] + node_p[k, NodeP.TC] * (1.0 - th * th) / weps
            tau = sgn * Rh * (ff * Tref + u) + (Jh * alpha + fr * tf)
            W[oTCMD + k] += tau
            if jac:
                dRh = live * (sgn * (ff * Tref + u) + (dJh * alpha + Jh * dalpha))
                if rs >= 0:
                    _g_axpy(GI, GC, GV, maxd, qTCMD + k, 0.5 * dRh, qY + rs)
                else:
                    _g_axpy(GI, GC, GV, maxd, qTCMD + k, dRh, qR + k)
                _g_axpy(GI, GC, GV, maxd, qTCMD + k, sgn * Rh, qU + c)
                _g_axpy(GI, GC, GV, maxd, qTCMD + k, fr * dtf, qOM + k)

    # 5b. open-loop torque commands (a set-point channel; no state dependence)
    for k in range(nN):
        tch = node_i[k, NodeI.TQCH]
        if tch >= 0:
            tq, _ = setpoint(I, P, tch, t)
            W[oTCMD + k] += tq

    # 6. drives: saturation and first-order torque lag
    for k in range(nN):
        if node_i[k, NodeI.DRIVE] != DriveKind.TORQUE:
            continue
        tmax = node_p[k, NodeP.TMAX]
        tc = W[oTCMD + k]
        ts = min(max(tc, -tmax), tmax)
        act = 1.0 if ts == tc else 0.0
        # the torque the drive delivers: actuator faults act here, unseen by the controller
        # (its anti-windup below knows only the limit)
        teff = node_p[k, NodeP.TEFF]
        if node_p[k, NodeP.TSTUCK] != 0.0:
            tapp = node_p[k, NodeP.TSV]
            dapp = 0.0
        else:
            tf_ = teff * tc + node_p[k, NodeP.TBIAS]
            tapp = min(max(tf_, -tmax), tmax)
            dapp = teff if tapp == tf_ else 0.0
        it = node_i[k, NodeI.TAU]
        if it >= 0:
            lag = node_p[k, NodeP.TLAG]
            W[oTM + k] = y[it]
            yd[it] = (tapp - y[it]) / lag
            if jac:
                _g_add(GI, GC, GV, maxd, qTM + k, it, 1.0)
                _j_axpy(JJ, mode, it, dapp / lag, GI, GC, GV, maxd, qTCMD + k)
                _j_add(JJ, mode, it, it, -1.0 / lag)
        else:
            W[oTM + k] = tapp
            if jac:
                _g_axpy(GI, GC, GV, maxd, qTM + k, dapp, qTCMD + k)
        # speed-PI anti-windup sees the drive saturation
        c = node_i[k, NodeI.SPEEDC]
        if c >= 0 and ctrl_i[c, CtrlI.X] >= 0:
            ix = ctrl_i[c, CtrlI.X]
            kaw = ctrl_p[c, CtrlP.KAW] / ctrl_p[c, CtrlP.KI]
            yd[ix] = W[oE + c] + kaw * (ts - tc)
            if jac:
                _j_axpy(JJ, mode, ix, 1.0, GI, GC, GV, maxd, qE + c)
                _j_axpy(JJ, mode, ix, kaw * (act - 1.0), GI, GC, GV, maxd, qTCMD + k)

    # 7. surface speeds; a draw error (REFF) makes the effective radius R·(1 + REFF)
    for k in range(nN):
        iw = node_i[k, NodeI.W]
        R = W[oR + k]
        rf = 1.0 + node_p[k, NodeP.REFF]
        if iw >= 0:
            W[oV + k] = rf * R * y[iw]
            if jac:
                _g_add(GI, GC, GV, maxd, qV + k, iw, rf * R)
                _g_axpy(GI, GC, GV, maxd, qV + k, rf * y[iw], qR + k)
        else:  # imposed speed
            dch = node_i[k, NodeI.DRAWCH]
            if dch >= 0:
                draw, _ = setpoint(I, P, dch, t)
            else:
                draw = node_p[k, NodeP.DRAW]
            v = (
                V * (1.0 + draw) * node_p[k, NodeP.VGAIN]
                + node_p[k, NodeP.VOFF]
                + node_p[k, NodeP.VSLOPE] * (t - node_p[k, NodeP.VT0])
                + W[oTRIM + k]
            )
            W[oV + k] = rf * v
            W[oOM + k] = v / R
            if jac:
                _g_axpy(GI, GC, GV, maxd, qV + k, rf, qTRIM + k)
                _g_axpy(GI, GC, GV, maxd, qOM + k, 1.0 / R, qTRIM + k)
                _g_axpy(GI, GC, GV, maxd, qOM + k, -v / (R * R), qR + k)

    # 8. encoders on imposed-speed nodes
    for j in range(nSe):
        typ = sensor_i[j, SensorI.TYPE]
        node = sensor_i[j, SensorI.NODE]
        if typ != SensorKind.ENCODER or node_i[node, NodeI.W] >= 0:
            continue
        _sensor_raw(
            j,
            typ,
            node,
            sensor_p[j, SensorP.GAIN],
            sensor_p[j, SensorP.OFF],
            0.0,
            0.0,
            node_i[node, NodeI.SPAN_UP],
            node_i[node, NodeI.SPAN_DN],
            W,
            oT,
            oR,
            oOM,
            oRAW,
            jac,
            GI,
            GC,
            GV,
            maxd,
            qT,
            qR,
            qOM,
            qRAW,
        )
        _sensor_fault(t, sensor_p, j, W, oRAW + j, oRW0 + j, jac, GC, GV, maxd, qRAW + j)
        iF = sensor_i[j, SensorI.F]
        W[oYS + j] = y[iF] if iF >= 0 else W[oRAW + j]

    # 9. roller and roll torque balance: J(R) domega/dt = R (T_out - T_in) + tau_m - tau_f
    for k in range(nN):
        iw = node_i[k, NodeI.W]
        if iw < 0:
            continue
        up = node_i[k, NodeI.SPAN_UP]
        dn = node_i[k, NodeI.SPAN_DN]
        Tup = W[oT + up] if up >= 0 else 0.0
        Tdn = W[oT + dn] if dn >= 0 else 0.0
        R = W[oR + k]
        Re = R * (1.0 + node_p[k, NodeP.REFF])
        J = W[oJ + k]
        om = y[iw]
        weps = node_p[k, NodeP.WEPS]
        th = math.tanh(om / weps)
        fr = node_p[k, NodeP.FRICF]
        tf = fr * (node_p[k, NodeP.B] * om + node_p[k, NodeP.TC] * th)
        dtf = fr * (node_p[k, NodeP.B] + node_p[k, NodeP.TC] * (1.0 - th * th) / weps)
        num = Re * (Tdn - Tup) + W[oTM + k] - tf
        if node_p[k, NodeP.RIPA] != 0.0:
            num += node_p[k, NodeP.RIPA] * math.sin(node_p[k, NodeP.RIPW] * t)
        if ntb > 0:  # random bearing drag torque (a process disturbance)
            num -= _drag(I, P, W, oDC, k, t)
        # eccentric roller: the web's pull on the moving centre, -sum T·dL/dth
        ith = node_i[k, NodeI.TH]
        fu = 0.0
        fd = 0.0
        if ith >= 0:
            ecc = node_p[k, NodeP.ECC]
            fu = ecc * math.sin(y[ith])
            fd = -ecc * math.sin(y[ith] - node_p[k, NodeP.WRAP])
            num += fu * Tup + fd * Tdn
        yd[iw] = num / J
        if jac:
            if dn >= 0:
                _j_axpy(JJ, mode, iw, (Re + fd) / J, GI, GC, GV, maxd, qT + dn)
            if up >= 0:
                _j_axpy(JJ, mode, iw, (fu - Re) / J, GI, GC, GV, maxd, qT + up)
            if ith >= 0:
                _j_add(
                    JJ,
                    mode,
                    iw,
                    ith,
                    node_p[k, NodeP.ECC]
                    * (math.cos(y[ith]) * Tup - math.cos(y[ith] - node_p[k, NodeP.WRAP]) * Tdn)
                    / J,
                )
            _j_axpy(JJ, mode, iw, 1.0 / J, GI, GC, GV, maxd, qTM + k)
            _j_add(JJ, mode, iw, iw, -dtf / J)
            if node_i[k, NodeI.KIND] != NodeKind.ROLLER:
                dJdR = 2.0 * PI * node_p[k, NodeP.RHOW] * R**3
                _j_axpy(
                    JJ, mode, iw, (Tdn - Tup) / J - num * dJdR / (J * J), GI, GC, GV, maxd, qR + k
                )

    # 10. rolls: length through the tangent point (s) and unstretched length (u)
    for k in range(nN):
        kind = node_i[k, NodeI.KIND]
        if kind == NodeKind.ROLLER:
            continue
        iS = node_i[k, NodeI.S]
        iU = node_i[k, NodeI.U]
        v = W[oV + k]
        yd[iS] = v
        xk = W[oXF + k]
        if kind == NodeKind.UNWIND:
            sp = node_i[k, NodeI.SPAN_DN]
            esrc_fwd, desrc = roll_wound_in_strain(node_p, k, W[oR + k])
            if ntb > 0:
                esrc_fwd += table_value(I, P, TableKind.WOUND, k, y[iU])
            # kept for the first span (section 11): its sum of sinusoids costs as much as
            # the rest of the evaluation
            W[oEW + 2 * k] = esrc_fwd
            W[oEW + 2 * k + 1] = desrc
            q = _flux(v, xk * esrc_fwd, xk * W[oEM + sp], linear)
        else:
            sp = node_i[k, NodeI.SPAN_UP]
            q = _flux(v, xk * W[oEM + sp], xk * W[oEM + sp], linear)
        yd[iU] = q
        if jac:
            _j_axpy(JJ, mode, iS, 1.0, GI, GC, GV, maxd, qV + k)
            if kind == NodeKind.UNWIND:
                _j_flux(
                    JJ,
                    mode,
                    iU,
                    1.0,
                    v,
                    esrc_fwd,
                    W[oEM + sp],
                    -1,
                    sp,
                    xk,
                    linear,
                    GI,
                    GC,
                    GV,
                    maxd,
                    qV + k,
                    qT,
                    1.0,
                    span_p[sp, SpanP.EA] if sp >= 0 else 1.0,
                )
                dq = v * _df(xk * esrc_fwd, linear) * xk * desrc if v >= 0.0 else 0.0
                _j_axpy(JJ, mode, iU, dq, GI, GC, GV, maxd, qR + k)
                if ntb > 0 and has_sines(I, TableKind.WOUND, k):  # the strain along u = y[iU]
                    dq = (
                        v
                        * _df(xk * esrc_fwd, linear)
                        * xk
                        * sines_slope(I, P, TableKind.WOUND, k, y[iU])
                        if v >= 0.0
                        else 0.0
                    )
                    _j_add(JJ, mode, iU, iU, dq)
            else:
                _j_flux(
                    JJ,
                    mode,
                    iU,
                    1.0,
                    v,
                    W[oEM + sp],
                    W[oEM + sp],
                    sp,
                    sp,
                    xk,
                    linear,
                    GI,
                    GC,
                    GV,
                    maxd,
                    qV + k,
                    qT,
                    span_p[sp, SpanP.EA] if sp >= 0 else 1.0,
                    span_p[sp, SpanP.EA] if sp >= 0 else 1.0,
                )

    # 11. spans: mass conservation with the geometric strain as the state
    for i in range(nS):
        ie = span_i[i, SpanI.E]
        a = span_i[i, SpanI.UP]
        bnode = span_i[i, SpanI.DN]
        L = W[oL + i]
        Ld = W[oLD + i]
        eg = y[ie]
        # upstream node a: forward flow brings the strain of the span before a
        sp_before = node_i[a, NodeI.SPAN_UP]
        dwa = 0.0
        if sp_before >= 0:
            ef = W[oEM + sp_before]
        else:
            if node_i[a, NodeI.KIND] == NodeKind.UNWIND:
                ef = W[oEW + 2 * a]
                dwa = W[oEW + 2 * a + 1]
            else:
                ef, dwa = roll_wound_in_strain(node_p, a, W[oR + a])
                if ntb > 0:
                    ef += table_value(I, P, TableKind.WOUND, a, y[node_i[a, NodeI.U]])
        xa = W[oXF + a]
        xb = W[oXF + bnode]
        qa = _flux(W[oV + a], xa * ef, xa * W[oEM + i], linear)
        sp_after = node_i[bnode, NodeI.SPAN_DN]
        er = W[oEM + sp_after] if sp_after >= 0 else W[oEM + i]
        qb = _flux(W[oV + bnode], xb * W[oEM + i], xb * er, linear)
        # moving length (dancer, festoon): + (1 + eg)/L·dL/dt; the linear model (1.4) keeps
        # d/dt[L(1 - eg)] = qa - qb, hence (1 - eg)/L·dL/dt
        if linear:
            fac = 1.0 / L
            dfac = 0.0
            gl = (1.0 - eg) / L
            dgl = -1.0 / L
        else:
            fac = (1.0 + eg) * (1.0 + eg) / L
            dfac = 2.0 * (1.0 + eg) / L
            gl = (1.0 + eg) / L
            dgl = 1.0 / L
        yd[ie] = fac * (qb - qa) + gl * Ld
        if jac:
            _j_add(JJ, mode, ie, ie, dfac * (qb - qa) + dgl * Ld)
            _j_axpy(JJ, mode, ie, -(fac * (qb - qa) + gl * Ld) / L, GI, GC, GV, maxd, qL + i)
            _j_axpy(JJ, mode, ie, gl, GI, GC, GV, maxd, qLD + i)
            if sp_before < 0:
                dqa = W[oV + a] * _df(xa * ef, linear) * xa * dwa if W[oV + a] >= 0.0 else 0.0
                _j_axpy(JJ, mode, ie, -fac * dqa, GI, GC, GV, maxd, qR + a)
                if ntb > 0 and has_sines(I, TableKind.WOUND, a):
                    iua = node_i[a, NodeI.U]
                    dqa = (
                        W[oV + a]
                        * _df(xa * ef, linear)
                        * xa
                        * sines_slope(I, P, TableKind.WOUND, a, y[iua])
                        if W[oV + a] >= 0.0
                        else 0.0
                    )
                    _j_add(JJ, mode, ie, iua, -fac * dqa)
            _j_flux(
                JJ,
                mode,
                ie,
                fac,
                W[oV + bnode],
                W[oEM + i],
                er,
                i,
                sp_after if sp_after >= 0 else i,
                xb,
                linear,
                GI,
                GC,
                GV,
                maxd,
                qV + bnode,
                qT,
                span_p[i, SpanP.EA],
                span_p[sp_after if sp_after >= 0 else i, SpanP.EA],
            )
            _j_flux(
                JJ,
                mode,
                ie,
                -fac,
                W[oV + a],
                ef,
                W[oEM + i],
                sp_before,
                i,
                xa,
                linear,
                GI,
                GC,
                GV,
                maxd,
                qV + a,
                qT,
                span_p[sp_before, SpanP.EA] if sp_before >= 0 else 1.0,
                span_p[i, SpanP.EA],
            )

    # 12. first-order sensor filters
    for j in range(nSe):
        iF = sensor_i[j, SensorI.F]
        if iF < 0:
            continue
        tau = sensor_p[j, SensorP.TAU]
        yd[iF] = (W[oRAW + j] - y[iF]) / tau
        if jac:
            _j_axpy(JJ, mode, iF, 1.0 / tau, GI, GC, GV, maxd, qRAW + j)
            _j_add(JJ, mode, iF, iF, -1.0 / tau)

    # 13. algebraic outputs
    if aux.shape[0] > 0:
        m = 0
        for i in range(nS):
            aux[m] = W[oT + i]
            aux[m + 1] = y[span_i[i, SpanI.E]]
            aux[m + 2] = W[oL + i]
            m += AUX_SPAN
        for k in range(nN):
            R = W[oR + k]
            aux[m] = W[oV + k]
            aux[m + 1] = W[oOM + k]
            aux[m + 2] = R
            aux[m + 3] = W[oJ + k]
            if node_i[k, NodeI.KIND] != NodeKind.ROLLER:
                aux[m + 4] = PI * node_p[k, NodeP.RHOW] * (R * R - node_p[k, NodeP.RC] ** 2)
            else:
                aux[m + 4] = 0.0
            aux[m + 5] = W[oTM + k]
            aux[m + 6] = W[oTCMD + k]
            up = node_i[k, NodeI.SPAN_UP]
            dn = node_i[k, NodeI.SPAN_DN]
            if up >= 0 and dn >= 0:
                lo = min(W[oT + up], W[oT + dn])
                hi = max(W[oT + up], W[oT + dn])
                aux[m + 7] = hi / lo if lo > 0.0 else (math.inf if hi > 0.0 else 1.0)
            else:
                aux[m + 7] = math.nan
            m += AUX_NODE
        for j in range(nSe):
            g = sensor_p[j, SensorP.GAIN]
            aux[m] = (W[oRW0 + j] - sensor_p[j, SensorP.OFF]) / g if g != 0.0 else math.nan
            aux[m + 1] = W[oYS + j]
            if sensor_i[j, SensorI.TYPE] == SensorKind.LOADCELL:
                node = sensor_i[j, SensorI.NODE]
                up = node_i[node, NodeI.SPAN_UP]
                dn = node_i[node, NodeI.SPAN_DN]
                f = 0.0
                if up >= 0:
                    f += sensor_p[j, SensorP.CIN] * W[oT + up]
                if dn >= 0:
                    f += sensor_p[j, SensorP.COUT] * W[oT + dn]
                aux[m + 2] = f
            else:
                aux[m + 2] = math.nan
            m += AUX_SENS
        for c in range(nC):
            aux[m] = W[oE + c]
            ix = ctrl_i[c, CtrlI.X]
            if ctrl_i[c, CtrlI.TYPE] == CtrlKind.SPEED:
                aux[m + 1] = W[oTCMD + ctrl_i[c, CtrlI.NODE]]
            else:
                aux[m + 1] = W[oU + c]
            aux[m + 2] = y[ix] if ix >= 0 else 0.0
            m += AUX_CTRL
        for mv in range(nM):
            aux[m] = y[mover_i[mv, MoverI.Q]]
            aux[m + 1] = y[mover_i[mv, MoverI.QD]]
            aux[m + 2] = W[oMW + mv]
            aux[m + 3] = W[oMF + mv]
            aux[m + 4] = mover_p[mv, MoverP.MODE]
            m += AUX_MOVER
        for js in range(I[H.NJ]):
            if joint_p[js, JointP.ACTIVE] != 0.0:
                k0 = int(joint_p[js, JointP.NODE])
                aux[m] = y[node_i[k0, NodeI.U]] - joint_p[js, JointP.U0]
                aux[m + 1] = joint_p[js, JointP.SPAN]
            else:
                aux[m] = math.nan
                aux[m + 1] = -1.0
            m += AUX_JOINT
        aux[m] = V
        aux[m + 1] = A
        m += 2
        for ch in range(1, I[H.NCH]):
            aux[m], _ = setpoint(I, P, ch, t)
            m += 1


@njit(cache=True)
def _pitch_material(span, rn, sensor_p, j, joint_p):
    """(E·A over the first roll's, relaxed-pitch offset [m]) of the web at the downstream end
    of pitch span ``span``: those of the newest material joint whose lead has passed that node
    and whose trail has not (both latched by the joint-pass events, so this is constant
    between events), else the first roll's (1, SensorP.DL0). An offset belongs to the rolls of
    the sensor's unwind ``rn`` only."""
    ratio = 1.0
    dl0 = sensor_p[j, SensorP.DL0]
    u0 = -math.inf
    for js in range(joint_p.shape[0]):
        if joint_p[js, JointP.ACTIVE] == 0.0 or joint_p[js, JointP.MAT] == 0.0:
            continue
        if (
            int(joint_p[js, JointP.SPAN]) > span
            and int(joint_p[js, JointP.TSPAN]) <= span
            and joint_p[js, JointP.U0] > u0
        ):
            u0 = joint_p[js, JointP.U0]
            ratio = joint_p[js, JointP.RATIO]
            dl0 = (
                joint_p[js, JointP.DL0]
                if int(joint_p[js, JointP.NODE]) == rn
                else sensor_p[j, SensorP.DL0]
            )
    return ratio, dl0


@njit(cache=True)
def _pitch_l0(j, rn, P, sensor_p, sensor_i, node_i, W, oR, y):
    """Relaxed pitch of pitch sensor j with a law/variation: L0 = q0 + q1·R³ + the sum of
    cosines in the unwound length u of unwind rn; returns (L0, dL0/dR, dL0/du, state of u)."""
    R = W[oR + rn]
    q1 = sensor_p[j, SensorP.Q1]
    L0 = sensor_p[j, SensorP.CIN] + q1 * R * R * R
    dL0dR = 3.0 * q1 * R * R
    dL0du = 0.0
    iU = node_i[rn, NodeI.U]
    nv = sensor_i[j, SensorI.VN]
    if nv > 0:
        u = y[iU]
        ov = sensor_i[j, SensorI.VOFF]
        for m in range(nv):
            a = P[ov + 3 * m]
            kap = P[ov + 3 * m + 1]
            ph = kap * u + P[ov + 3 * m + 2]
            L0 += a * math.cos(ph)
            dL0du -= a * kap * math.sin(ph)
    return L0, dL0dR, dL0du, iU


@njit(cache=True)
def _sensor_raw(
    j,
    typ,
    node,
    g,
    off,
    win,
    wout,
    up,
    dn,
    W,
    oT,
    oR,
    oOM,
    oRAW,
    jac,
    GI,
    GC,
    GV,
    maxd,
    qT,
    qR,
    qOM,
    qRAW,
):
    """Raw reading of sensor j (load cell: ``up``, ``dn`` are the spans at its node, -1 for
    none; encoder, diameter: of node ``node``)."""
    if typ == SensorKind.LOADCELL:
        val = 0.0
        if up >= 0:
            val += win * W[oT + up]
            if jac:
                _g_axpy(GI, GC, GV, maxd, qRAW + j, g * win, qT + up)
        if dn >= 0:
            val += wout * W[oT + dn]
            if jac:
                _g_axpy(GI, GC, GV, maxd, qRAW + j, g * wout, qT + dn)
        W[oRAW + j] = g * val + off
    elif typ == SensorKind.ENCODER:
        W[oRAW + j] = g * W[oOM + node] + off
        if jac:
            _g_axpy(GI, GC, GV, maxd, qRAW + j, g, qOM + node)
    else:  # roll diameter
        W[oRAW + j] = g * 2.0 * W[oR + node] + off
        if jac:
            _g_axpy(GI, GC, GV, maxd, qRAW + j, 2.0 * g, qR + node)


@njit(cache=True)
def _f(e, linear):
    return 1.0 - e if linear else 1.0 / (1.0 + e)


@njit(cache=True)
def _df(e, linear):
    return -1.0 if linear else -1.0 / ((1.0 + e) * (1.0 + e))


@njit(cache=True)
def _flux(v, e_fwd, e_rev, linear):
    """Unstretched flux through a node, upwinded: v·f(strain of the web arriving)."""
    return v * _f(e_fwd if v >= 0.0 else e_rev, linear)


@njit(cache=True)
def _j_flux(
    JJ,
    mode,
    row,
    a,
    v,
    e_fwd,
    e_rev,
    sp_fwd,
    sp_rev,
    xf,
    linear,
    GI,
    GC,
    GV,
    maxd,
    qv,
    qT,
    ea_fwd,
    ea_rev,
):
    """Add a·d(flux)/dy to a Jacobian row for the flux v·f(xf·e) (xf: splice-joint factor
    of the node). Both upwind sources are recorded (one with 0). ``ea_fwd``, ``ea_rev``: the
    E·A of spans ``sp_fwd``, ``sp_rev`` (a scalar rather than the span records: passing a
    record view to this non-inlined function made the Jacobian ~15 % slower)."""
    fwd = v >= 0.0
    e = xf * (e_fwd if fwd else e_rev)
    _j_axpy(JJ, mode, row, a * _f(e, linear), GI, GC, GV, maxd, qv)
    if sp_fwd >= 0:
        w = a * v * _df(e, linear) * xf / ea_fwd if fwd else 0.0
        _j_axpy(JJ, mode, row, w, GI, GC, GV, maxd, qT + sp_fwd)
    if sp_rev >= 0:
        w = 0.0 if fwd else a * v * _df(e, linear) * xf / ea_rev
        _j_axpy(JJ, mode, row, w, GI, GC, GV, maxd, qT + sp_rev)


# --------------------------------------------------------------------------- events
@njit(cache=True)
def event_values(t, y, g, I, P, W, GI, GC, GV, yd, JJ):
    """Event functions at one state; an event's condition holds where its value is < 0.

    slack: geometric strain; break: T_break - T; capstan: e^(mu beta)·T_lo - T_hi;
    roll empty: R - R_core; end stop: q - q_min (q_max - q), and while latched the force
    pressing the mover into the stop (released when it reverses); splice joint: unstretched
    length to the next node minus the joint's lead, joint break: T_break,s - T; splice
    trigger: R - R_trigger; refill: storage short of its set-point.
    """
    evaluate(t, y, yd, JJ, RUNTIME_MODE[Mode.RHS], I, P, W, GI, GC, GV, yd[:0])
    (
        oT,
        oEM,
        oL,
        oLD,
        oLP,
        oLPP,
        oEAE,
        oV,
        oR,
        oOM,
        oJ,
        oTRIM,
        oTCMD,
        oTM,
        oRAW,
        oYS,
        oU,
        oE,
        oMF,
        oMW,
        oXF,
        oRW0,
        oEW,
        oDC,
    ) = _offsets(I)
    nN = I[H.NN]
    nS = I[H.NS]
    nC = I[H.NC]
    nM = I[H.NM]
    nJ = I[H.NJ]
    nEv = I[H.NEV]
    oNI = I[H.OFF_NI]
    node_i = _records(I, oNI, nN, N_NODE_I)
    oSI = I[H.OFF_SI]
    span_i = _records(I, oSI, nS, N_SPAN_I)
    oMI = I[H.OFF_MI]
    mover_i = _records(I, oMI, nM, N_MOVER_I)
    oEV = I[H.OFF_EV]
    event_i = _records(I, oEV, nEv, N_EVENT_I)
    oNP = I[H.OFF_NP]
    node_p = _records(P, oNP, nN, N_NODE_P)
    oSP = I[H.OFF_SP]
    span_p = _records(P, oSP, nS, N_SPAN_P)
    oCP = I[H.OFF_CP]
    ctrl_p = _records(P, oCP, nC, N_CTRL_P)
    oMP = I[H.OFF_MP]
    mover_p = _records(P, oMP, nM, N_MOVER_P)
    oJP = I[H.OFF_JP]
    joint_p = _records(P, oJP, nJ, N_JOINT_P)
    for m in range(nEv):
        kind = event_i[m, EventI.KIND]
        idx = event_i[m, EventI.INDEX]
        if kind == EventKind.SLACK:
            g[m] = y[span_i[idx, SpanI.E]]
        elif kind == EventKind.BREAK:
            g[m] = span_p[idx, SpanP.TBRK] - W[oT + idx]
        elif kind == EventKind.CAPSTAN:
            t1 = W[oT + node_i[idx, NodeI.SPAN_UP]]
            t2 = W[oT + node_i[idx, NodeI.SPAN_DN]]
            g[m] = node_p[idx, NodeP.EMB] * min(t1, t2) - max(t1, t2)
        elif kind == EventKind.EMPTY:
            R2 = node_p[idx, NodeP.R0] ** 2 - node_p[idx, NodeP.CW] / PI * y[node_i[idx, NodeI.S]]
            g[m] = R2 - node_p[idx, NodeP.RC] ** 2
        elif kind == EventKind.STOP_LO or kind == EventKind.STOP_HI:
            md = mover_p[idx, MoverP.MODE]
            q = y[mover_i[idx, MoverI.Q]]
            lo = kind == EventKind.STOP_LO
            if md == 0.0:
                g[m] = q - mover_p[idx, MoverP.QMIN] if lo else mover_p[idx, MoverP.QMAX] - q
            elif md == -1.0 and lo:
                g[m] = W[oMF + idx]
            elif md == 1.0 and not lo:
                g[m] = -W[oMF + idx]
            else:
                g[m] = 1.0
        elif kind == EventKind.JOINT_PASS or kind == EventKind.JOINT_BREAK:
            if joint_p[idx, JointP.ACTIVE] == 0.0:
                g[m] = 1.0
                continue
            sp = int(joint_p[idx, JointP.SPAN])
            if kind == EventKind.JOINT_BREAK:
                g[m] = joint_p[idx, JointP.TBRK] - W[oT + min(max(sp, 0), nS - 1)]
                continue
            # the next node crossing of the lead or of the trail, whichever comes first
            k0 = int(joint_p[idx, JointP.NODE])
            lead = y[node_i[k0, NodeI.U]] - joint_p[idx, JointP.U0]
            st = int(joint_p[idx, JointP.TSPAN])
            c0 = 0.0
            c_trail = 0.0
            for i in range(min(sp + 1, nS)):
                c0 += W[oL + i] / max(1.0 + y[span_i[i, SpanI.E]], 1e-6)
                if i == st:
                    c_trail = c0
            g_lead = c0 - lead if sp < nS else 1.0
            g[m] = min(g_lead, c_trail - (lead - joint_p[idx, JointP.LEN]))
        elif kind == EventKind.SPLICE_RADIUS:
            rt = node_p[idx, NodeP.RTRIG]
            g[m] = W[oR + idx] - rt if rt > 0.0 else 1.0
        elif kind == EventKind.REFILL:
            if ctrl_p[idx, CtrlP.GATE] == -1.0:
                g[m] = ctrl_p[idx, CtrlP.SIGN] * W[oE + idx]
            else:
                g[m] = 1.0
        else:
            g[m] = 1.0


@njit(cache=True)
def event_values_rows(T, Y, G, I, P, W, GI, GC, GV, yd, JJ):
    """:func:`event_values` for every row of a state matrix."""
    for r in range(Y.shape[0]):
        event_values(T[r], Y[r], G[r], I, P, W, GI, GC, GV, yd, JJ)


@njit(cache=True)
def outputs_rows(T, Y, AUX, I, P, W, GI, GC, GV, yd, JJ):
    """Algebraic outputs for every row of a state matrix (one row per sample)."""
    for r in range(Y.shape[0]):
        evaluate(T[r], Y[r], yd, JJ, RUNTIME_MODE[Mode.RHS], I, P, W, GI, GC, GV, AUX[r])


@njit(cache=True)
def jac_values(t, y, JJ, I, P, W, GI, GC, GV, yd, vals):
    """Jacobian at (t, y) as values on the compiled pattern (for sparse solvers)."""
    evaluate(t, y, yd, JJ, RUNTIME_MODE[Mode.JAC], I, P, W, GI, GC, GV, yd[:0])
    npat = I[H.NPAT]
    op = I[H.OFF_PAT]
    for m in range(npat):
        vals[m] = JJ[I[op + m], I[op + npat + m]]


@njit(cache=True)
def rhs_rows(T, Y, F, I, P, W, GI, GC, GV, JJ, aux0):
    """dy/dt for every row of a state matrix."""
    for r in range(Y.shape[0]):
        evaluate(T[r], Y[r], F[r], JJ, RUNTIME_MODE[Mode.RHS], I, P, W, GI, GC, GV, aux0)


@njit(cache=True)
def hermite(ts, ys, fs, tq, out):
    """Cubic Hermite interpolation of solver steps (ts, ys, dy/dt = fs) at sorted times tq.

    Exact derivatives at both ends of each step make it fourth-order accurate, better than the
    BDF2 solution it interpolates; at a step time it returns the step state exactly.
    """
    n = ys.shape[1]
    j = 0
    last = ts.shape[0] - 1
    for r in range(tq.shape[0]):
        t = tq[r]
        while j < last - 1 and ts[j + 1] < t:
            j += 1
        h = ts[j + 1] - ts[j]
        if h <= 0.0:
            for i in range(n):
                out[r, i] = ys[j + 1, i]
            continue
        s = (t - ts[j]) / h
        s2 = s * s
        s3 = s2 * s
        h00 = 2.0 * s3 - 3.0 * s2 + 1.0
        h10 = s3 - 2.0 * s2 + s
        h01 = -2.0 * s3 + 3.0 * s2
        h11 = s3 - s2
        for i in range(n):
            out[r, i] = (
                h00 * ys[j, i] + h10 * h * fs[j, i] + h01 * ys[j + 1, i] + h11 * h * fs[j + 1, i]
            )


# --------------------------------------------------------------------------- numba's cache
class _StampedCache(FunctionCache):
    """numba's cache of one function, with the stamp of the kernel's sources in its key."""

    def __init__(self, py_func, stamp: int):
        super().__init__(py_func)
        self._stamp = stamp

    def _index_key(self, sig, codegen):
        return (*super()._index_key(sig, codegen), self._stamp)


#: hash of this file, layout.py and every other module of r2rsim/compile with njit code: the
#: record fields are compiled in as constants, which numba's own key (this file's time stamp
#: and each function's bytecode) does not see, so an edit of layout.py alone would otherwise
#: load the old machine code (see :mod:`.stamp`)
STAMP = kernel_stamp()
for _disp in list(globals().values()):
    if isinstance(_disp, Dispatcher) and isinstance(_disp._cache, FunctionCache):
        _disp._cache = _StampedCache(_disp.py_func, STAMP)
del _disp
