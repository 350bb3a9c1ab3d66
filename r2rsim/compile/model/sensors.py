"""Sensors: load cells, encoders, roll-diameter gauges, dancer-position sensors and pitch
(vision) sensors. Each reads a raw value from the intermediates (a load cell the tensions at
its roller, weighted by its wrap geometry; an encoder a node's angular speed; a diameter
gauge 2·R; a dancer sensor the mover's coordinate; a pitch sensor (T/ES + 1)·L0, thesis eq.
2.11), then its in-loop fault (offset, gain, drift, stuck) applies; an optional first-order
filter (state ``SensorI.F``) gives what the controllers see.
"""

from __future__ import annotations

import math

from .base import (
    H,
    JointP,
    Mode,
    MoverI,
    NodeI,
    SensorI,
    SensorKind,
    SensorP,
    g_add,
    g_axpy,
    j_add,
    j_axpy,
    joints,
    kernel,
    movers,
    nodes,
    quantity_ids,
    scratch,
    sensors,
)


@kernel(inline=False)
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


@kernel
def _pitch_l0(j, rn, P, sensor_p, sensor_i, node_i, w, y, jac):
    """Relaxed pitch of pitch sensor j with a law/variation: L0 = q0 + q1·R³ + the sum of
    cosines in the unwound length u of unwind rn; returns (L0, dL0/dR, dL0/du, state of u).
    dL0/du (a sum of as many sines) only with ``jac``: the Jacobian alone reads it."""
    R = w.radius[rn]
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
            if jac:
                dL0du -= a * kap * math.sin(ph)
    return L0, dL0dR, dL0du, iU


@kernel
def _pitch_reading(j, node, g, y, I, P, w, qid, jac, GI, GC, GV, maxd):
    """Raw reading of pitch sensor j on span ``node``: (T/ES + 1)·L0 with L0 constant or the
    law of its unwind's radius (and the printing variation in u)."""
    node_i, node_p = nodes(I, P)
    sensor_i, sensor_p = sensors(I, P)
    rn = sensor_i[j, SensorI.RNODE]
    # E·S and L0 offset of the roll whose web is at the sensor
    ratio, dl0 = _pitch_material(node, rn, sensor_p, j, joints(I, P))
    ES = P[I[H.EA]] * ratio
    if rn < 0:
        L0 = sensor_p[j, SensorP.CIN] + dl0
        w.raw[j] = g * (w.tension[node] / ES + 1.0) * L0 + sensor_p[j, SensorP.OFF]
        if jac:
            g_axpy(GI, GC, GV, maxd, qid.raw + j, g * L0 / ES, qid.tension + node)
        return
    # L0 = q0 + q1·R³ of the unwind's radius + the printing variation in u
    L0, dL0dR, dL0du, iU = _pitch_l0(j, rn, P, sensor_p, sensor_i, node_i, w, y, jac)
    L0 += dl0
    h = g * (w.tension[node] / ES + 1.0)
    w.raw[j] = h * L0 + sensor_p[j, SensorP.OFF]
    if jac:
        g_axpy(GI, GC, GV, maxd, qid.raw + j, g * L0 / ES, qid.tension + node)
        g_axpy(GI, GC, GV, maxd, qid.raw + j, h * dL0dR, qid.radius + rn)
        if sensor_i[j, SensorI.VN] > 0:
            g_add(GI, GC, GV, maxd, qid.raw + j, iU, h * dL0du)


@kernel
def _raw_reading(j, typ, node, g, off, win, wout, up, dn, w, qid, jac, GI, GC, GV, maxd):
    """Raw reading of sensor j (load cell: ``up``, ``dn`` are the spans at its node, -1 for
    none; encoder, diameter: of node ``node``)."""
    if typ == SensorKind.LOADCELL:
        val = 0.0
        if up >= 0:
            val += win * w.tension[up]
            if jac:
                g_axpy(GI, GC, GV, maxd, qid.raw + j, g * win, qid.tension + up)
        if dn >= 0:
            val += wout * w.tension[dn]
            if jac:
                g_axpy(GI, GC, GV, maxd, qid.raw + j, g * wout, qid.tension + dn)
        w.raw[j] = g * val + off
    elif typ == SensorKind.ENCODER:
        w.raw[j] = g * w.omega[node] + off
        if jac:
            g_axpy(GI, GC, GV, maxd, qid.raw + j, g, qid.omega + node)
    else:  # roll diameter
        w.raw[j] = g * 2.0 * w.radius[node] + off
        if jac:
            g_axpy(GI, GC, GV, maxd, qid.raw + j, 2.0 * g, qid.radius + node)


@kernel
def _sensor_fault(t, sensor_p, j, w, jac, GC, GV, maxd, q):
    """Apply a sensor's in-loop fault (offset, gain, drift, stuck) to its raw reading; the
    fault-free reading is kept in ``w.raw_true`` for the true (shadow) channel."""
    w.raw_true[j] = w.raw[j]
    if sensor_p[j, SensorP.FON] == 0.0:
        return
    if sensor_p[j, SensorP.STUCK] != 0.0:
        w.raw[j] = sensor_p[j, SensorP.SV]
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
    w.raw[j] = g * w.raw[j] + bias
    if jac:
        for e in range(GC[q]):
            GV[q * maxd + e] *= g


@kernel
def sensor_readings(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 3: every reading that does not need an imposed speed (encoders on imposed-speed
    nodes are read in :func:`imposed_speed_encoders`, after the speeds), with its fault, and
    what the controllers see (the filter state, or the reading itself)."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    node_i, node_p = nodes(I, P)
    sensor_i, sensor_p = sensors(I, P)
    mover_i, mover_p = movers(I, P)
    for j in range(I[H.NSE]):
        typ = sensor_i[j, SensorI.TYPE]
        node = sensor_i[j, SensorI.NODE]
        iF = sensor_i[j, SensorI.F]
        g = sensor_p[j, SensorP.GAIN]
        if typ == SensorKind.ENCODER and node_i[node, NodeI.W] < 0:
            continue  # imposed-speed node: read after the surface speeds
        if typ == SensorKind.DANCER:  # node holds the mover index
            iq = mover_i[node, MoverI.Q]
            w.raw[j] = g * y[iq] + sensor_p[j, SensorP.OFF]
            if jac:
                g_add(GI, GC, GV, maxd, qid.raw + j, iq, g)
        elif typ == SensorKind.PITCH:  # node holds the span index
            _pitch_reading(j, node, g, y, I, P, w, qid, jac, GI, GC, GV, maxd)
        else:
            _raw_reading(
                j, typ, node, g, sensor_p[j, SensorP.OFF], sensor_p[j, SensorP.WIN],
                sensor_p[j, SensorP.WOUT], node_i[node, NodeI.SPAN_UP],
                node_i[node, NodeI.SPAN_DN], w, qid, jac, GI, GC, GV, maxd,
            )  # fmt: skip
        _sensor_fault(t, sensor_p, j, w, jac, GC, GV, maxd, qid.raw + j)
        if iF >= 0:
            w.seen[j] = y[iF]
            if jac:
                g_add(GI, GC, GV, maxd, qid.seen + j, iF, 1.0)
        else:
            w.seen[j] = w.raw[j]
            if jac:
                g_axpy(GI, GC, GV, maxd, qid.seen + j, 1.0, qid.raw + j)


@kernel
def imposed_speed_encoders(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 8: encoders on imposed-speed nodes, read once the speeds are known."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    node_i, node_p = nodes(I, P)
    sensor_i, sensor_p = sensors(I, P)
    for j in range(I[H.NSE]):
        typ = sensor_i[j, SensorI.TYPE]
        node = sensor_i[j, SensorI.NODE]
        if typ != SensorKind.ENCODER or node_i[node, NodeI.W] >= 0:
            continue
        _raw_reading(
            j, typ, node, sensor_p[j, SensorP.GAIN], sensor_p[j, SensorP.OFF], 0.0, 0.0,
            node_i[node, NodeI.SPAN_UP], node_i[node, NodeI.SPAN_DN], w, qid, jac,
            GI, GC, GV, maxd,
        )  # fmt: skip
        _sensor_fault(t, sensor_p, j, w, jac, GC, GV, maxd, qid.raw + j)
        iF = sensor_i[j, SensorI.F]
        w.seen[j] = y[iF] if iF >= 0 else w.raw[j]


@kernel
def sensor_filters(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 12: first-order sensor filters, dy_f/dt = (raw - y_f)/tau."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    sensor_i, sensor_p = sensors(I, P)
    for j in range(I[H.NSE]):
        iF = sensor_i[j, SensorI.F]
        if iF < 0:
            continue
        tau = sensor_p[j, SensorP.TAU]
        yd[iF] = (w.raw[j] - y[iF]) / tau
        if jac:
            j_axpy(JJ, mode, iF, 1.0 / tau, GI, GC, GV, maxd, qid.raw + j)
            j_add(JJ, mode, iF, iF, -1.0 / tau)
