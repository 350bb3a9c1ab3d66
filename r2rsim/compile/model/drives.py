"""Drives: what a motor delivers of the torque its controller commands."""

from __future__ import annotations

from .base import (
    CtrlI,
    CtrlP,
    DriveKind,
    H,
    Mode,
    NodeI,
    NodeP,
    controllers,
    g_add,
    g_axpy,
    j_add,
    j_axpy,
    kernel,
    nodes,
    quantity_ids,
    scratch,
)


@kernel
def drive_torques(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 6: saturation at ±τ_max and the first-order torque lag (state ``NodeI.TAU``,
    dτ/dt = (τ_applied - τ)/lag) of every torque drive; the applied torque carries the
    actuator faults (efficiency TEFF, bias, stuck), which the controller does not see (its
    anti-windup knows only the limit). A speed loop's integrator sees the saturation."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    node_i, node_p = nodes(I, P)
    ctrl_i, ctrl_p = controllers(I, P)
    for k in range(I[H.NN]):
        if node_i[k, NodeI.DRIVE] != DriveKind.TORQUE:
            continue
        tmax = node_p[k, NodeP.TMAX]
        tc = w.torque_cmd[k]
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
            w.torque[k] = y[it]
            yd[it] = (tapp - y[it]) / lag
            if jac:
                g_add(GI, GC, GV, maxd, qid.torque + k, it, 1.0)
                j_axpy(JJ, mode, it, dapp / lag, GI, GC, GV, maxd, qid.torque_cmd + k)
                j_add(JJ, mode, it, it, -1.0 / lag)
        else:
            w.torque[k] = tapp
            if jac:
                g_axpy(GI, GC, GV, maxd, qid.torque + k, dapp, qid.torque_cmd + k)
        # speed-PI anti-windup sees the drive saturation
        c = node_i[k, NodeI.SPEEDC]
        if c >= 0 and ctrl_i[c, CtrlI.X] >= 0:
            ix = ctrl_i[c, CtrlI.X]
            kaw = ctrl_p[c, CtrlP.KAW] / ctrl_p[c, CtrlP.KI]
            yd[ix] = w.ctrl_err[c] + kaw * (ts - tc)
            if jac:
                j_axpy(JJ, mode, ix, 1.0, GI, GC, GV, maxd, qid.ctrl_err + c)
                j_axpy(JJ, mode, ix, kaw * (act - 1.0), GI, GC, GV, maxd, qid.torque_cmd + k)
