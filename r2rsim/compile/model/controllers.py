"""Controllers: tension PI loops (on a load cell or a pitch sensor), dancer position loops,
speed PI loops with inertia feed-forward, and torque-mode tension control of a roll.

A tension or dancer loop's output is a speed trim of its element (or, for a roll in torque
mode, the trim of its torque command); a speed loop and torque-mode control write the torque
command that :mod:`.drives` saturates and lags. Integrators (state ``CtrlI.X``) have
back-calculation anti-windup; a gated loop (a dancer loop during a splice) holds its
integrator and outputs 0.
"""

from __future__ import annotations

import math

from .base import (
    CtrlI,
    CtrlKind,
    CtrlP,
    H,
    Mode,
    MoverI,
    NodeI,
    NodeKind,
    NodeP,
    SensorI,
    SensorKind,
    SensorP,
    controllers,
    g_add,
    g_axpy,
    j_add,
    j_axpy,
    kernel,
    movers,
    nodes,
    quantity_ids,
    scratch,
    sensors,
)
from .programme import setpoint

PI = math.pi


@kernel
def _loop_error(c, t, y, I, P, w):
    """(error, its weight on the sensor reading wy, its derivative wr through the radius of
    unwind rn, rn or -1, the dancer state read when the loop has no sensor) of tension or
    dancer loop c. A pitch-length sensor is read as tension through the calibrated Hooke's
    law, with the law L0(R) when it has one (not the unknown printing variation)."""
    sensor_i, sensor_p = sensors(I, P)
    ctrl_i, ctrl_p = controllers(I, P)
    mover_i, mover_p = movers(I, P)
    sens = ctrl_i[c, CtrlI.SENSOR]
    if ctrl_i[c, CtrlI.TYPE] == CtrlKind.DANCER:
        imq = mover_i[ctrl_i[c, CtrlI.MOVER], MoverI.Q]
        e = ctrl_p[c, CtrlP.SETP] - (w.seen[sens] if sens >= 0 else y[imq])
        return e, 1.0, 0.0, -1, imq
    Tref, _ = setpoint(I, P, ctrl_i[c, CtrlI.CH], t)
    if sensor_i[sens, SensorI.TYPE] != SensorKind.PITCH:
        return Tref - w.seen[sens], 1.0, 0.0, -1, -1
    rn = sensor_i[sens, SensorI.RNODE]
    cout = sensor_p[sens, SensorP.COUT]
    if rn < 0:
        wy = cout / sensor_p[sens, SensorP.CIN]
        e = Tref - (w.seen[sens] / sensor_p[sens, SensorP.CIN] - 1.0) * cout
        return e, wy, 0.0, -1, -1
    Rn = w.radius[rn]
    L0c = sensor_p[sens, SensorP.CIN] + sensor_p[sens, SensorP.Q1] * Rn * Rn * Rn
    wy = cout / L0c
    e = Tref - (w.seen[sens] / L0c - 1.0) * cout
    wr = w.seen[sens] * cout / (L0c * L0c) * (3.0 * sensor_p[sens, SensorP.Q1] * Rn * Rn)
    return e, wy, wr, rn, -1


@kernel
def tension_loops(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 4: tension and dancer PI loops, u = clip(kp·e + ki·x), dx/dt = e + kaw·(u - upi)
    (back-calculation), and the speed trims they add to their elements."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    ctrl_i, ctrl_p = controllers(I, P)
    for c in range(I[H.NC]):
        typ = ctrl_i[c, CtrlI.TYPE]
        if typ == CtrlKind.SPEED:
            continue
        ix = ctrl_i[c, CtrlI.X]
        sens = ctrl_i[c, CtrlI.SENSOR]
        kp = ctrl_p[c, CtrlP.KP]
        ki = ctrl_p[c, CtrlP.KI]
        lim = ctrl_p[c, CtrlP.LIM]
        # the measurement enters with weight -wy through the quantity seen (or a state imq)
        e, wy, wr, rn, imq = _loop_error(c, t, y, I, P, w)
        gate = 1.0 if ctrl_p[c, CtrlP.GATE] > 0.0 else 0.0
        x = y[ix] if ix >= 0 else 0.0
        upi = kp * e + ki * x
        u = min(max(upi, -lim), lim)
        act = 1.0 if u == upi else 0.0
        w.ctrl_out[c] = gate * u
        w.ctrl_err[c] = e
        if jac:
            qu = qid.ctrl_out + c
            if sens >= 0:
                g_axpy(GI, GC, GV, maxd, qu, -gate * kp * act * wy, qid.seen + sens)
                if rn >= 0:
                    g_axpy(GI, GC, GV, maxd, qu, gate * kp * act * wr, qid.radius + rn)
            else:
                g_add(GI, GC, GV, maxd, qu, imq, -gate * kp * act)
            if ix >= 0:
                g_add(GI, GC, GV, maxd, qu, ix, gate * ki * act)
        if ix >= 0:
            kaw = ctrl_p[c, CtrlP.KAW] / ki
            yd[ix] = gate * (e + kaw * (u - upi))
            if jac:
                # d(u - upi) = (act - 1) * d(upi)
                wm = gate * (-1.0 + kaw * (act - 1.0) * (-kp))
                if sens >= 0:
                    j_axpy(JJ, mode, ix, wm * wy, GI, GC, GV, maxd, qid.seen + sens)
                    if rn >= 0:
                        j_axpy(JJ, mode, ix, -wm * wr, GI, GC, GV, maxd, qid.radius + rn)
                else:
                    j_add(JJ, mode, ix, imq, wm)
                j_add(JJ, mode, ix, ix, gate * kaw * (act - 1.0) * ki)
        if typ == CtrlKind.TENSION_TRIM or typ == CtrlKind.DANCER:
            node = ctrl_i[c, CtrlI.NODE]
            sgn = ctrl_p[c, CtrlP.SIGN]
            w.speed_trim[node] += sgn * w.ctrl_out[c]
            if jac:
                g_axpy(GI, GC, GV, maxd, qid.speed_trim + node, sgn, qid.ctrl_out + c)


@kernel
def _speed_loop(c, k, t, V, A, y, I, P, w, qid, jac, GI, GC, GV, maxd):
    """Speed PI of node k with inertia feed-forward: τ = kp·e + ki·x + ff·J·α_ref, the
    reference V·(1 + draw)·gain + offset + slope + trim over R (a programmed draw is a
    set-point channel; its slope enters the feed-forward)."""
    node_i, node_p = nodes(I, P)
    ctrl_i, ctrl_p = controllers(I, P)
    ix = ctrl_i[c, CtrlI.X]
    kp = ctrl_p[c, CtrlP.KP]
    ki = ctrl_p[c, CtrlP.KI]
    ff = ctrl_p[c, CtrlP.FF]
    R = w.radius[k]
    vg = node_p[k, NodeP.VGAIN]
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
        + w.speed_trim[k]
    )
    wref = vref / R
    sens = ctrl_i[c, CtrlI.SENSOR]
    wm = w.seen[sens] if sens >= 0 else w.omega[k]
    e = wref - wm
    w.ctrl_err[c] = e
    x = y[ix] if ix >= 0 else 0.0
    J = w.inertia[k]
    acc = A * (1.0 + draw) * vg
    if dch >= 0:
        acc += V * ddraw * vg  # d/dt of V·(1 + draw)
    aref = (acc + node_p[k, NodeP.VSLOPE]) / R
    w.torque_cmd[k] += kp * e + ki * x + ff * J * aref
    if not jac:
        return
    qe = qid.ctrl_err + c
    qtau = qid.torque_cmd + k
    g_axpy(GI, GC, GV, maxd, qe, 1.0 / R, qid.speed_trim + k)
    g_axpy(GI, GC, GV, maxd, qe, -vref / (R * R), qid.radius + k)
    if sens >= 0:
        g_axpy(GI, GC, GV, maxd, qe, -1.0, qid.seen + sens)
    else:
        g_axpy(GI, GC, GV, maxd, qe, -1.0, qid.omega + k)
    g_axpy(GI, GC, GV, maxd, qtau, kp, qe)
    if ix >= 0:
        g_add(GI, GC, GV, maxd, qtau, ix, ki)
    if node_i[k, NodeI.KIND] != NodeKind.ROLLER:
        dJdR = 2.0 * PI * node_p[k, NodeP.RHOW] * R**3
        g_axpy(GI, GC, GV, maxd, qtau, ff * (dJdR * aref - J * aref / R), qid.radius + k)


@kernel
def _torque_mode(c, k, t, V, A, I, P, w, qid, jac, GI, GC, GV, maxd):
    """Torque-mode tension control of roll k: τ = sgn·R̂·(ff·T_ref + u) + J_est·α + τ_f, with
    R̂ from a diameter sensor or the model. Feed-forward terms (CtrlP.FF, JFAC, JABS, RR,
    FRF): the inertia estimate J_est = JFAC·J(R̂) + JABS, the radius-rate part of α (rr) and
    friction (fr) are switched one by one; the defaults reproduce sgn·R̂·(T_ref + u) +
    (J(R̂)·α + τ_f) to the last bit."""
    node_i, node_p = nodes(I, P)
    ctrl_i, ctrl_p = controllers(I, P)
    ff = ctrl_p[c, CtrlP.FF]
    sgn = -1.0 if node_i[k, NodeI.KIND] == NodeKind.UNWIND else 1.0
    rs = ctrl_i[c, CtrlI.RSENSOR]
    Rh = 0.5 * w.seen[rs] if rs >= 0 else w.radius[k]
    Rc = node_p[k, NodeP.RC]
    # the radius estimate is never below the core (a failed sensor reading 0 must not
    # divide by zero); clamped, it no longer depends on the states
    live = 1.0
    if Rh < Rc:
        Rh = Rc
        live = 0.0
    Tref, _ = setpoint(I, P, ctrl_i[c, CtrlI.CH], t)
    u = w.ctrl_out[c]
    jfac = ctrl_p[c, CtrlP.JFAC]
    rr = ctrl_p[c, CtrlP.RR]
    fr = ctrl_p[c, CtrlP.FRF]
    rhow = node_p[k, NodeP.RHOW]
    Jh = jfac * (node_p[k, NodeP.JC] + 0.5 * PI * rhow * (Rh**4 - Rc**4)) + ctrl_p[c, CtrlP.JABS]
    dJh = jfac * (2.0 * PI * rhow * Rh**3)
    cw = node_p[k, NodeP.CW]
    alpha = A / Rh - rr * sgn * cw * V * V / (2.0 * PI * Rh**3)
    dalpha = -A / (Rh * Rh) + 3.0 * rr * sgn * cw * V * V / (2.0 * PI * Rh**4)
    om = w.omega[k]
    weps = node_p[k, NodeP.WEPS]
    th = math.tanh(om / weps)
    tf = node_p[k, NodeP.B] * om + node_p[k, NodeP.TC] * th
    dtf = node_p[k, NodeP.B] + node_p[k, NodeP.TC] * (1.0 - th * th) / weps
    w.torque_cmd[k] += sgn * Rh * (ff * Tref + u) + (Jh * alpha + fr * tf)
    if jac:
        qtau = qid.torque_cmd + k
        dRh = live * (sgn * (ff * Tref + u) + (dJh * alpha + Jh * dalpha))
        if rs >= 0:
            g_axpy(GI, GC, GV, maxd, qtau, 0.5 * dRh, qid.seen + rs)
        else:
            g_axpy(GI, GC, GV, maxd, qtau, dRh, qid.radius + k)
        g_axpy(GI, GC, GV, maxd, qtau, sgn * Rh, qid.ctrl_out + c)
        g_axpy(GI, GC, GV, maxd, qtau, fr * dtf, qid.omega + k)


@kernel
def torque_commands(t, V, A, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 5: the torque commands of speed loops and of torque-mode tension control, then
    open-loop torque set-points (a set-point channel; no state dependence)."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    node_i, node_p = nodes(I, P)
    ctrl_i, ctrl_p = controllers(I, P)
    for c in range(I[H.NC]):
        typ = ctrl_i[c, CtrlI.TYPE]
        if typ == CtrlKind.TENSION_TRIM or typ == CtrlKind.DANCER:
            continue
        k = ctrl_i[c, CtrlI.NODE]
        if typ == CtrlKind.SPEED:
            _speed_loop(c, k, t, V, A, y, I, P, w, qid, jac, GI, GC, GV, maxd)
        else:
            _torque_mode(c, k, t, V, A, I, P, w, qid, jac, GI, GC, GV, maxd)
    for k in range(I[H.NN]):
        tch = node_i[k, NodeI.TQCH]
        if tch >= 0:
            tq, _ = setpoint(I, P, tch, t)
            w.torque_cmd[k] += tq
