"""The numba kernel of a compiled line: right-hand side, analytic Jacobian, outputs, events.

One function, :func:`evaluate`, computes the right-hand side. With ``mode=MODE_JAC`` it also
propagates, for every intermediate quantity (span tension, node speed, sensor reading,
controller output, drive torque, ...), a short sparse gradient with respect to the states, and
accumulates the chain rule into the Jacobian; ``MODE_TOUCH`` marks the entries instead, which
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

from .layout import (
    AUX_CTRL,
    AUX_NODE,
    AUX_SENS,
    AUX_SPAN,
    C_SPEED,
    C_TENSION_TRIM,
    CI_CH,
    CI_NODE,
    CI_RSENSOR,
    CI_SENSOR,
    CI_TYPE,
    CI_X,
    CP_DRAW,
    CP_FF,
    CP_KAW,
    CP_KI,
    CP_KP,
    CP_LIM,
    CP_SIGN,
    DRV_TORQUE,
    EV_BREAK,
    EV_CAPSTAN,
    EV_EMPTY,
    EV_SLACK,
    H_MAXD,
    H_MAXPTS,
    H_MODEL,
    H_NC,
    H_NCH,
    H_NEV,
    H_NN,
    H_NPAT,
    H_NS,
    H_NSE,
    H_OFF_CI,
    H_OFF_CP,
    H_OFF_EV,
    H_OFF_NI,
    H_OFF_NP,
    H_OFF_PAT,
    H_OFF_RT,
    H_OFF_SCHN,
    H_OFF_SCHT,
    H_OFF_SCHV,
    H_OFF_SEI,
    H_OFF_SEP,
    H_OFF_SI,
    H_OFF_SP,
    MODE_JAC,
    MODE_RHS,
    MODE_TOUCH,
    NCI,
    NCP,
    NEVI,
    NI,
    NI_DRIVE,
    NI_KIND,
    NI_S,
    NI_SPAN_DN,
    NI_SPAN_UP,
    NI_SPEEDC,
    NI_TAU,
    NI_U,
    NI_W,
    NK_ROLLER,
    NK_UNWIND,
    NP,
    NP_B,
    NP_CW,
    NP_DRAW,
    NP_EMB,
    NP_EPSW,
    NP_J,
    NP_JC,
    NP_R,
    NP_R0,
    NP_RC,
    NP_RHOW,
    NP_RIPA,
    NP_RIPW,
    NP_TC,
    NP_TLAG,
    NP_TMAX,
    NP_WEPS,
    NSEI,
    NSEP,
    NSI,
    NSP,
    SE_ENCODER,
    SE_LOADCELL,
    SEI_F,
    SEI_NODE,
    SEI_TYPE,
    SEP_CIN,
    SEP_COUT,
    SEP_GAIN,
    SEP_OFF,
    SEP_TAU,
    SEP_WIN,
    SEP_WOUT,
    SI_DN,
    SI_E,
    SI_UP,
    SP_EA,
    SP_L,
    SP_TBRK,
)

PI = math.pi


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
def _j_add(JJ, mode, row, col, val):
    if mode == MODE_TOUCH:
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
    mx = I[H_MAXPTS]
    n = I[I[H_OFF_SCHN] + ch]
    bt = I[H_OFF_SCHT] + ch * mx
    bv = I[H_OFF_SCHV] + ch * mx
    tseg = P[I[H_OFF_RT]]
    k = 0
    for m in range(n):
        if P[bt + m] <= tseg:
            k = m
    if k >= n - 1:
        return P[bv + n - 1], 0.0
    dt = P[bt + k + 1] - P[bt + k]
    slope = (P[bv + k + 1] - P[bv + k]) / dt if dt > 0.0 else 0.0
    return P[bv + k] + slope * (t - P[bt + k]), slope


# --------------------------------------------------------------------------- the kernel
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
        Jacobian (``MODE_JAC``: pattern entries are zeroed then filled; ``MODE_TOUCH``: pattern
        entries are set to 1). Ignored for ``MODE_RHS``.
    mode : int
        ``MODE_RHS``, ``MODE_JAC`` or ``MODE_TOUCH``.
    I, P : ndarray
        The compiled line (layout in :mod:`r2rsim.compile.layout`).
    W, GI, GC, GV : ndarray
        Scratch: values of intermediates; gradient indices, counts and values.
    aux : ndarray
        Output row of algebraic quantities (length 0 to skip).
    """
    nN = I[H_NN]
    nS = I[H_NS]
    nSe = I[H_NSE]
    nC = I[H_NC]
    oNI = I[H_OFF_NI]
    oSI = I[H_OFF_SI]
    oSEI = I[H_OFF_SEI]
    oCI = I[H_OFF_CI]
    oNP = I[H_OFF_NP]
    oSP = I[H_OFF_SP]
    oSEP = I[H_OFF_SEP]
    oCP = I[H_OFF_CP]
    linear = I[H_MODEL] == 1
    jac = mode != MODE_RHS
    maxd = I[H_MAXD]

    # scratch value offsets
    oT = 0
    oEM = oT + nS
    oV = oEM + nS
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
    # gradient quantity ids
    qT = 0
    qV = qT + nS
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
        if mode == MODE_JAC:
            npat = I[H_NPAT]
            op = I[H_OFF_PAT]
            for m in range(npat):
                JJ[I[op + m], I[op + npat + m]] = 0.0

    V, A = setpoint(I, P, 0, t)

    # 1. spans: tension from the material strain (slack: geometric strain < 0 carries none)
    for i in range(nS):
        ie = I[oSI + i * NSI + SI_E]
        e = y[ie]
        EA = P[oSP + i * NSP + SP_EA]
        em = e if e > 0.0 else 0.0
        W[oEM + i] = em
        W[oT + i] = EA * em
        if jac:
            _g_add(GI, GC, GV, maxd, qT + i, ie, EA if e > 0.0 else 0.0)

    # 2. nodes: radius, inertia, angular speed state
    for k in range(nN):
        kind = I[oNI + k * NI + NI_KIND]
        b = oNP + k * NP
        if kind != NK_ROLLER:
            iS = I[oNI + k * NI + NI_S]
            sg = -1.0 if kind == NK_UNWIND else 1.0
            R2 = P[b + NP_R0] ** 2 + sg * P[b + NP_CW] / PI * y[iS]
            R = math.sqrt(R2) if R2 > 1e-12 else 1e-6
            W[oR + k] = R
            Rc = P[b + NP_RC]
            W[oJ + k] = P[b + NP_JC] + 0.5 * PI * P[b + NP_RHOW] * (R ** 4 - Rc ** 4)
            if jac:
                _g_add(GI, GC, GV, maxd, qR + k, iS, sg * P[b + NP_CW] / (2.0 * PI * R))
        else:
            W[oR + k] = P[b + NP_R]
            W[oJ + k] = P[b + NP_J]
        iw = I[oNI + k * NI + NI_W]
        W[oTRIM + k] = 0.0
        W[oTCMD + k] = 0.0
        W[oTM + k] = 0.0
        if iw >= 0:
            W[oOM + k] = y[iw]
            if jac:
                _g_add(GI, GC, GV, maxd, qOM + k, iw, 1.0)

    # 3. sensor readings that do not need imposed speeds
    for j in range(nSe):
        typ = I[oSEI + j * NSEI + SEI_TYPE]
        node = I[oSEI + j * NSEI + SEI_NODE]
        iF = I[oSEI + j * NSEI + SEI_F]
        b = oSEP + j * NSEP
        g = P[b + SEP_GAIN]
        if typ == SE_ENCODER and I[oNI + node * NI + NI_W] < 0:
            continue  # imposed-speed node: read after step 7
        _sensor_raw(j, typ, node, g, P[b + SEP_OFF], P[b + SEP_WIN], P[b + SEP_WOUT], I, oNI,
                    W, oT, oR, oOM, oRAW, jac, GI, GC, GV, maxd, qT, qR, qOM, qRAW)
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
        typ = I[oCI + c * NCI + CI_TYPE]
        if typ == C_SPEED:
            continue
        b = oCP + c * NCP
        node = I[oCI + c * NCI + CI_NODE]
        ix = I[oCI + c * NCI + CI_X]
        sens = I[oCI + c * NCI + CI_SENSOR]
        Tref, _ = setpoint(I, P, I[oCI + c * NCI + CI_CH], t)
        kp = P[b + CP_KP]
        ki = P[b + CP_KI]
        lim = P[b + CP_LIM]
        e = Tref - W[oYS + sens]
        x = y[ix] if ix >= 0 else 0.0
        upi = kp * e + ki * x
        u = min(max(upi, -lim), lim)
        act = 1.0 if u == upi else 0.0
        W[oU + c] = u
        W[oE + c] = e
        if jac:
            _g_axpy(GI, GC, GV, maxd, qU + c, -kp * act, qY + sens)
            if ix >= 0:
                _g_add(GI, GC, GV, maxd, qU + c, ix, ki * act)
        if ix >= 0:
            kaw = P[b + CP_KAW] / ki
            yd[ix] = e + kaw * (u - upi)
            if jac:
                # d(u - upi) = (act - 1) * d(upi)
                _j_axpy(JJ, mode, ix, -1.0 + kaw * (act - 1.0) * (-kp), GI, GC, GV, maxd,
                        qY + sens)
                _j_add(JJ, mode, ix, ix, kaw * (act - 1.0) * ki)
        if typ == C_TENSION_TRIM:
            sgn = P[b + CP_SIGN]
            W[oTRIM + node] += sgn * u
            if jac:
                _g_axpy(GI, GC, GV, maxd, qTRIM + node, sgn, qU + c)

    # 5. torque commands: speed PI (+ inertia feed-forward) and torque-mode tension control
    for c in range(nC):
        typ = I[oCI + c * NCI + CI_TYPE]
        if typ == C_TENSION_TRIM:
            continue
        b = oCP + c * NCP
        k = I[oCI + c * NCI + CI_NODE]
        bn = oNP + k * NP
        ix = I[oCI + c * NCI + CI_X]
        kp = P[b + CP_KP]
        ki = P[b + CP_KI]
        ff = P[b + CP_FF]
        kind = I[oNI + k * NI + NI_KIND]
        if typ == C_SPEED:
            R = W[oR + k]
            vref = V * (1.0 + P[b + CP_DRAW]) + W[oTRIM + k]
            wref = vref / R
            sens = I[oCI + c * NCI + CI_SENSOR]
            wm = W[oYS + sens] if sens >= 0 else W[oOM + k]
            e = wref - wm
            W[oE + c] = e
            x = y[ix] if ix >= 0 else 0.0
            J = W[oJ + k]
            aref = A * (1.0 + P[b + CP_DRAW]) / R
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
                if kind != NK_ROLLER:
                    dJdR = 2.0 * PI * P[bn + NP_RHOW] * R ** 3
                    _g_axpy(GI, GC, GV, maxd, qTCMD + k,
                            ff * (dJdR * aref - J * aref / R), qR + k)
        else:  # torque-mode tension control of a roll
            sgn = -1.0 if kind == NK_UNWIND else 1.0
            rs = I[oCI + c * NCI + CI_RSENSOR]
            Rh = 0.5 * W[oYS + rs] if rs >= 0 else W[oR + k]
            Rc = P[bn + NP_RC]
            # the radius estimate is never below the core (a failed sensor reading 0 must not
            # divide by zero); clamped, it no longer depends on the states
            live = 1.0
            if Rh < Rc:
                Rh = Rc
                live = 0.0
            Tref, _ = setpoint(I, P, I[oCI + c * NCI + CI_CH], t)
            u = W[oU + c]
            Jh = P[bn + NP_JC] + 0.5 * PI * P[bn + NP_RHOW] * (Rh ** 4 - Rc ** 4)
            dJh = 2.0 * PI * P[bn + NP_RHOW] * Rh ** 3
            cw = P[bn + NP_CW]
            alpha = A / Rh - sgn * cw * V * V / (2.0 * PI * Rh ** 3)
            dalpha = -A / (Rh * Rh) + 3.0 * sgn * cw * V * V / (2.0 * PI * Rh ** 4)
            om = W[oOM + k]
            weps = P[bn + NP_WEPS]
            th = math.tanh(om / weps)
            tf = P[bn + NP_B] * om + P[bn + NP_TC] * th
            dtf = P[bn + NP_B] + P[bn + NP_TC] * (1.0 - th * th) / weps
            tau = sgn * Rh * (ff * Tref + u) + ff * (Jh * alpha + tf)
            W[oTCMD + k] += tau
            if jac:
                dRh = live * (sgn * (ff * Tref + u) + ff * (dJh * alpha + Jh * dalpha))
                if rs >= 0:
                    _g_axpy(GI, GC, GV, maxd, qTCMD + k, 0.5 * dRh, qY + rs)
                else:
                    _g_axpy(GI, GC, GV, maxd, qTCMD + k, dRh, qR + k)
                _g_axpy(GI, GC, GV, maxd, qTCMD + k, sgn * Rh, qU + c)
                _g_axpy(GI, GC, GV, maxd, qTCMD + k, ff * dtf, qOM + k)

    # 6. drives: saturation and first-order torque lag
    for k in range(nN):
        if I[oNI + k * NI + NI_DRIVE] != DRV_TORQUE:
            continue
        b = oNP + k * NP
        tmax = P[b + NP_TMAX]
        tc = W[oTCMD + k]
        ts = min(max(tc, -tmax), tmax)
        act = 1.0 if ts == tc else 0.0
        it = I[oNI + k * NI + NI_TAU]
        if it >= 0:
            lag = P[b + NP_TLAG]
            W[oTM + k] = y[it]
            yd[it] = (ts - y[it]) / lag
            if jac:
                _g_add(GI, GC, GV, maxd, qTM + k, it, 1.0)
                _j_axpy(JJ, mode, it, act / lag, GI, GC, GV, maxd, qTCMD + k)
                _j_add(JJ, mode, it, it, -1.0 / lag)
        else:
            W[oTM + k] = ts
            if jac:
                _g_axpy(GI, GC, GV, maxd, qTM + k, act, qTCMD + k)
        # speed-PI anti-windup sees the drive saturation
        c = I[oNI + k * NI + NI_SPEEDC]
        if c >= 0 and I[oCI + c * NCI + CI_X] >= 0:
            ix = I[oCI + c * NCI + CI_X]
            kaw = P[oCP + c * NCP + CP_KAW] / P[oCP + c * NCP + CP_KI]
            yd[ix] = W[oE + c] + kaw * (ts - tc)
            if jac:
                _j_axpy(JJ, mode, ix, 1.0, GI, GC, GV, maxd, qE + c)
                _j_axpy(JJ, mode, ix, kaw * (act - 1.0), GI, GC, GV, maxd, qTCMD + k)

    # 7. surface speeds
    for k in range(nN):
        iw = I[oNI + k * NI + NI_W]
        R = W[oR + k]
        if iw >= 0:
            W[oV + k] = R * y[iw]
            if jac:
                _g_add(GI, GC, GV, maxd, qV + k, iw, R)
                _g_axpy(GI, GC, GV, maxd, qV + k, y[iw], qR + k)
        else:  # imposed speed
            v = V * (1.0 + P[oNP + k * NP + NP_DRAW]) + W[oTRIM + k]
            W[oV + k] = v
            W[oOM + k] = v / R
            if jac:
                _g_axpy(GI, GC, GV, maxd, qV + k, 1.0, qTRIM + k)
                _g_axpy(GI, GC, GV, maxd, qOM + k, 1.0 / R, qTRIM + k)
                _g_axpy(GI, GC, GV, maxd, qOM + k, -v / (R * R), qR + k)

    # 8. encoders on imposed-speed nodes
    for j in range(nSe):
        typ = I[oSEI + j * NSEI + SEI_TYPE]
        node = I[oSEI + j * NSEI + SEI_NODE]
        if typ != SE_ENCODER or I[oNI + node * NI + NI_W] >= 0:
            continue
        b = oSEP + j * NSEP
        _sensor_raw(j, typ, node, P[b + SEP_GAIN], P[b + SEP_OFF], 0.0, 0.0, I, oNI, W, oT,
                    oR, oOM, oRAW, jac, GI, GC, GV, maxd, qT, qR, qOM, qRAW)
        iF = I[oSEI + j * NSEI + SEI_F]
        W[oYS + j] = y[iF] if iF >= 0 else W[oRAW + j]

    # 9. roller and roll torque balance: J(R) domega/dt = R (T_out - T_in) + tau_m - tau_f
    for k in range(nN):
        iw = I[oNI + k * NI + NI_W]
        if iw < 0:
            continue
        b = oNP + k * NP
        up = I[oNI + k * NI + NI_SPAN_UP]
        dn = I[oNI + k * NI + NI_SPAN_DN]
        Tup = W[oT + up] if up >= 0 else 0.0
        Tdn = W[oT + dn] if dn >= 0 else 0.0
        R = W[oR + k]
        J = W[oJ + k]
        om = y[iw]
        weps = P[b + NP_WEPS]
        th = math.tanh(om / weps)
        tf = P[b + NP_B] * om + P[b + NP_TC] * th
        dtf = P[b + NP_B] + P[b + NP_TC] * (1.0 - th * th) / weps
        num = R * (Tdn - Tup) + W[oTM + k] - tf
        if P[b + NP_RIPA] != 0.0:
            num += P[b + NP_RIPA] * math.sin(P[b + NP_RIPW] * t)
        yd[iw] = num / J
        if jac:
            if dn >= 0:
                _j_axpy(JJ, mode, iw, R / J, GI, GC, GV, maxd, qT + dn)
            if up >= 0:
                _j_axpy(JJ, mode, iw, -R / J, GI, GC, GV, maxd, qT + up)
            _j_axpy(JJ, mode, iw, 1.0 / J, GI, GC, GV, maxd, qTM + k)
            _j_add(JJ, mode, iw, iw, -dtf / J)
            if I[oNI + k * NI + NI_KIND] != NK_ROLLER:
                dJdR = 2.0 * PI * P[b + NP_RHOW] * R ** 3
                _j_axpy(JJ, mode, iw, (Tdn - Tup) / J - num * dJdR / (J * J), GI, GC, GV,
                        maxd, qR + k)

    # 10. rolls: length through the tangent point (s) and unstretched length (u)
    for k in range(nN):
        kind = I[oNI + k * NI + NI_KIND]
        if kind == NK_ROLLER:
            continue
        iS = I[oNI + k * NI + NI_S]
        iU = I[oNI + k * NI + NI_U]
        v = W[oV + k]
        yd[iS] = v
        if kind == NK_UNWIND:
            sp = I[oNI + k * NI + NI_SPAN_DN]
            esrc_fwd = P[oNP + k * NP + NP_EPSW]
            q = _flux(v, esrc_fwd, W[oEM + sp], linear)
        else:
            sp = I[oNI + k * NI + NI_SPAN_UP]
            q = _flux(v, W[oEM + sp], W[oEM + sp], linear)
        yd[iU] = q
        if jac:
            _j_axpy(JJ, mode, iS, 1.0, GI, GC, GV, maxd, qV + k)
            if kind == NK_UNWIND:
                _j_flux(JJ, mode, iU, 1.0, v, esrc_fwd, W[oEM + sp], -1, sp, linear, I, P,
                        GI, GC, GV, maxd, qV + k, qT, oSP)
            else:
                _j_flux(JJ, mode, iU, 1.0, v, W[oEM + sp], W[oEM + sp], sp, sp, linear, I,
                        P, GI, GC, GV, maxd, qV + k, qT, oSP)

    # 11. spans: mass conservation with the geometric strain as the state
    for i in range(nS):
        ie = I[oSI + i * NSI + SI_E]
        a = I[oSI + i * NSI + SI_UP]
        bnode = I[oSI + i * NSI + SI_DN]
        L = P[oSP + i * NSP + SP_L]
        eg = y[ie]
        # upstream node a: forward flow brings the strain of the span before a
        sp_before = I[oNI + a * NI + NI_SPAN_UP]
        if sp_before >= 0:
            ef = W[oEM + sp_before]
        else:
            ef = P[oNP + a * NP + NP_EPSW]
        qa = _flux(W[oV + a], ef, W[oEM + i], linear)
        sp_after = I[oNI + bnode * NI + NI_SPAN_DN]
        er = W[oEM + sp_after] if sp_after >= 0 else W[oEM + i]
        qb = _flux(W[oV + bnode], W[oEM + i], er, linear)
        if linear:
            fac = 1.0 / L
            dfac = 0.0
        else:
            fac = (1.0 + eg) * (1.0 + eg) / L
            dfac = 2.0 * (1.0 + eg) / L
        yd[ie] = fac * (qb - qa)
        if jac:
            _j_add(JJ, mode, ie, ie, dfac * (qb - qa))
            _j_flux(JJ, mode, ie, fac, W[oV + bnode], W[oEM + i], er, i,
                    sp_after if sp_after >= 0 else i, linear, I, P, GI, GC, GV, maxd,
                    qV + bnode, qT, oSP)
            _j_flux(JJ, mode, ie, -fac, W[oV + a], ef, W[oEM + i], sp_before, i, linear, I, P,
                    GI, GC, GV, maxd, qV + a, qT, oSP)

    # 12. first-order sensor filters
    for j in range(nSe):
        iF = I[oSEI + j * NSEI + SEI_F]
        if iF < 0:
            continue
        tau = P[oSEP + j * NSEP + SEP_TAU]
        yd[iF] = (W[oRAW + j] - y[iF]) / tau
        if jac:
            _j_axpy(JJ, mode, iF, 1.0 / tau, GI, GC, GV, maxd, qRAW + j)
            _j_add(JJ, mode, iF, iF, -1.0 / tau)

    # 13. algebraic outputs
    if aux.shape[0] > 0:
        m = 0
        for i in range(nS):
            aux[m] = W[oT + i]
            aux[m + 1] = y[I[oSI + i * NSI + SI_E]]
            m += AUX_SPAN
        for k in range(nN):
            b = oNP + k * NP
            R = W[oR + k]
            aux[m] = W[oV + k]
            aux[m + 1] = W[oOM + k]
            aux[m + 2] = R
            aux[m + 3] = W[oJ + k]
            if I[oNI + k * NI + NI_KIND] != NK_ROLLER:
                aux[m + 4] = PI * P[b + NP_RHOW] * (R * R - P[b + NP_RC] ** 2)
            else:
                aux[m + 4] = 0.0
            aux[m + 5] = W[oTM + k]
            aux[m + 6] = W[oTCMD + k]
            up = I[oNI + k * NI + NI_SPAN_UP]
            dn = I[oNI + k * NI + NI_SPAN_DN]
            if up >= 0 and dn >= 0:
                lo = min(W[oT + up], W[oT + dn])
                hi = max(W[oT + up], W[oT + dn])
                aux[m + 7] = hi / lo if lo > 0.0 else (math.inf if hi > 0.0 else 1.0)
            else:
                aux[m + 7] = math.nan
            m += AUX_NODE
        for j in range(nSe):
            b = oSEP + j * NSEP
            g = P[b + SEP_GAIN]
            aux[m] = (W[oRAW + j] - P[b + SEP_OFF]) / g if g != 0.0 else math.nan
            aux[m + 1] = W[oYS + j]
            if I[oSEI + j * NSEI + SEI_TYPE] == SE_LOADCELL:
                node = I[oSEI + j * NSEI + SEI_NODE]
                up = I[oNI + node * NI + NI_SPAN_UP]
                dn = I[oNI + node * NI + NI_SPAN_DN]
                f = 0.0
                if up >= 0:
                    f += P[b + SEP_CIN] * W[oT + up]
                if dn >= 0:
                    f += P[b + SEP_COUT] * W[oT + dn]
                aux[m + 2] = f
            else:
                aux[m + 2] = math.nan
            m += AUX_SENS
        for c in range(nC):
            aux[m] = W[oE + c]
            ix = I[oCI + c * NCI + CI_X]
            if I[oCI + c * NCI + CI_TYPE] == C_SPEED:
                aux[m + 1] = W[oTCMD + I[oCI + c * NCI + CI_NODE]]
            else:
                aux[m + 1] = W[oU + c]
            aux[m + 2] = y[ix] if ix >= 0 else 0.0
            m += AUX_CTRL
        aux[m] = V
        aux[m + 1] = A
        m += 2
        for ch in range(1, I[H_NCH]):
            aux[m], _ = setpoint(I, P, ch, t)
            m += 1


@njit(cache=True)
def _sensor_raw(j, typ, node, g, off, win, wout, I, oNI, W, oT, oR, oOM, oRAW, jac, GI, GC, GV,
                maxd, qT, qR, qOM, qRAW):
    if typ == SE_LOADCELL:
        up = I[oNI + node * NI + NI_SPAN_UP]
        dn = I[oNI + node * NI + NI_SPAN_DN]
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
    elif typ == SE_ENCODER:
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
def _j_flux(JJ, mode, row, a, v, e_fwd, e_rev, sp_fwd, sp_rev, linear, I, P, GI, GC, GV, maxd,
            qv, qT, oSP):
    """Add a·d(flux)/dy to a Jacobian row. Both upwind sources are recorded (one with 0)."""
    fwd = v >= 0.0
    e = e_fwd if fwd else e_rev
    _j_axpy(JJ, mode, row, a * _f(e, linear), GI, GC, GV, maxd, qv)
    if sp_fwd >= 0:
        w = a * v * _df(e_fwd, linear) / P[oSP + sp_fwd * NSP + SP_EA] if fwd else 0.0
        _j_axpy(JJ, mode, row, w, GI, GC, GV, maxd, qT + sp_fwd)
    if sp_rev >= 0:
        w = 0.0 if fwd else a * v * _df(e_rev, linear) / P[oSP + sp_rev * NSP + SP_EA]
        _j_axpy(JJ, mode, row, w, GI, GC, GV, maxd, qT + sp_rev)


# --------------------------------------------------------------------------- events
@njit(cache=True)
def event_values(y, g, I, P):
    """Event functions at one state; an event's condition holds where its value is < 0.

    slack: geometric strain; break: T_break - T; capstan: e^(mu beta)·T_lo - T_hi;
    roll empty: R - R_core.
    """
    oNI = I[H_OFF_NI]
    oSI = I[H_OFF_SI]
    oNP = I[H_OFF_NP]
    oSP = I[H_OFF_SP]
    oEV = I[H_OFF_EV]
    for m in range(I[H_NEV]):
        kind = I[oEV + m * NEVI]
        idx = I[oEV + m * NEVI + 1]
        if kind == EV_SLACK:
            g[m] = y[I[oSI + idx * NSI + SI_E]]
        elif kind == EV_BREAK:
            e = y[I[oSI + idx * NSI + SI_E]]
            g[m] = P[oSP + idx * NSP + SP_TBRK] - P[oSP + idx * NSP + SP_EA] * max(e, 0.0)
        elif kind == EV_CAPSTAN:
            up = I[oNI + idx * NI + NI_SPAN_UP]
            dn = I[oNI + idx * NI + NI_SPAN_DN]
            t1 = P[oSP + up * NSP + SP_EA] * max(y[I[oSI + up * NSI + SI_E]], 0.0)
            t2 = P[oSP + dn * NSP + SP_EA] * max(y[I[oSI + dn * NSI + SI_E]], 0.0)
            g[m] = P[oNP + idx * NP + NP_EMB] * min(t1, t2) - max(t1, t2)
        elif kind == EV_EMPTY:
            b = oNP + idx * NP
            R2 = P[b + NP_R0] ** 2 - P[b + NP_CW] / PI * y[I[oNI + idx * NI + NI_S]]
            g[m] = R2 - P[b + NP_RC] ** 2
        else:
            g[m] = 1.0


@njit(cache=True)
def event_values_rows(Y, G, I, P):
    """:func:`event_values` for every row of a state matrix."""
    for r in range(Y.shape[0]):
        event_values(Y[r], G[r], I, P)


@njit(cache=True)
def outputs_rows(T, Y, AUX, I, P, W, GI, GC, GV, yd, JJ):
    """Algebraic outputs for every row of a state matrix (one row per sample)."""
    for r in range(Y.shape[0]):
        evaluate(T[r], Y[r], yd, JJ, MODE_RHS, I, P, W, GI, GC, GV, AUX[r])


@njit(cache=True)
def jac_values(t, y, JJ, I, P, W, GI, GC, GV, yd, vals):
    """Jacobian at (t, y) as values on the compiled pattern (for sparse solvers)."""
    evaluate(t, y, yd, JJ, MODE_JAC, I, P, W, GI, GC, GV, yd[:0])
    npat = I[H_NPAT]
    op = I[H_OFF_PAT]
    for m in range(npat):
        vals[m] = JJ[I[op + m], I[op + npat + m]]



@njit(cache=True)
def rhs_rows(T, Y, F, I, P, W, GI, GC, GV, JJ, aux0):
    """dy/dt for every row of a state matrix."""
    for r in range(Y.shape[0]):
        evaluate(T[r], Y[r], F[r], JJ, MODE_RHS, I, P, W, GI, GC, GV, aux0)


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
            out[r, i] = (h00 * ys[j, i] + h10 * h * fs[j, i] + h01 * ys[j + 1, i]
                         + h11 * h * fs[j + 1, i])
