"""The algebraic outputs of one evaluation: one row of ``aux`` per recorded sample, in the
order of :meth:`r2rsim.compile.compiler.CompiledLine.aux_names` (per span, node, sensor,
controller, mover and joint slot the ``AUX_*`` fields of :mod:`..layout`, then the line
speed and acceleration and the other set-point channels)."""

from __future__ import annotations

import math

from ..layout import AUX_CTRL, AUX_JOINT, AUX_MOVER, AUX_NODE, AUX_SENS, AUX_SPAN
from .base import (
    CtrlI,
    CtrlKind,
    H,
    JointP,
    MoverI,
    MoverP,
    NodeI,
    NodeKind,
    NodeP,
    SensorI,
    SensorKind,
    SensorP,
    SpanI,
    controllers,
    joints,
    kernel,
    movers,
    nodes,
    scratch,
    sensors,
    spans,
)
from .programme import setpoint

PI = math.pi


@kernel
def _node_outputs(m, aux, I, P, w):
    """v, ω, R, J, the roll's mass, applied and commanded torque, and the ratio of the
    larger to the smaller tension at the node (its capstan margin) of every node."""
    node_i, node_p = nodes(I, P)
    for k in range(I[H.NN]):
        R = w.radius[k]
        aux[m] = w.speed[k]
        aux[m + 1] = w.omega[k]
        aux[m + 2] = R
        aux[m + 3] = w.inertia[k]
        if node_i[k, NodeI.KIND] != NodeKind.ROLLER:
            aux[m + 4] = PI * node_p[k, NodeP.RHOW] * (R * R - node_p[k, NodeP.RC] ** 2)
        else:
            aux[m + 4] = 0.0
        aux[m + 5] = w.torque[k]
        aux[m + 6] = w.torque_cmd[k]
        up = node_i[k, NodeI.SPAN_UP]
        dn = node_i[k, NodeI.SPAN_DN]
        if up >= 0 and dn >= 0:
            lo = min(w.tension[up], w.tension[dn])
            hi = max(w.tension[up], w.tension[dn])
            aux[m + 7] = hi / lo if lo > 0.0 else (math.inf if hi > 0.0 else 1.0)
        else:
            aux[m + 7] = math.nan
        m += AUX_NODE
    return m


@kernel
def _sensor_outputs(m, aux, I, P, w):
    """The physical value (the fault-free reading with gain and offset undone), what the
    controllers see, and a load cell's bearing force, of every sensor."""
    node_i, node_p = nodes(I, P)
    sensor_i, sensor_p = sensors(I, P)
    for j in range(I[H.NSE]):
        g = sensor_p[j, SensorP.GAIN]
        aux[m] = (w.raw_true[j] - sensor_p[j, SensorP.OFF]) / g if g != 0.0 else math.nan
        aux[m + 1] = w.seen[j]
        if sensor_i[j, SensorI.TYPE] == SensorKind.LOADCELL:
            node = sensor_i[j, SensorI.NODE]
            up = node_i[node, NodeI.SPAN_UP]
            dn = node_i[node, NodeI.SPAN_DN]
            f = 0.0
            if up >= 0:
                f += sensor_p[j, SensorP.CIN] * w.tension[up]
            if dn >= 0:
                f += sensor_p[j, SensorP.COUT] * w.tension[dn]
            aux[m + 2] = f
        else:
            aux[m + 2] = math.nan
        m += AUX_SENS
    return m


@kernel
def outputs(t, V, A, y, aux, I, P, W):
    """Write the algebraic outputs of the evaluation just done into the row ``aux``."""
    w = scratch(I, W)
    node_i, node_p = nodes(I, P)
    span_i, span_p = spans(I, P)
    ctrl_i, ctrl_p = controllers(I, P)
    mover_i, mover_p = movers(I, P)
    joint_p = joints(I, P)
    m = 0
    for i in range(I[H.NS]):
        aux[m] = w.tension[i]
        aux[m + 1] = y[span_i[i, SpanI.E]]
        aux[m + 2] = w.length[i]
        m += AUX_SPAN
    m = _node_outputs(m, aux, I, P, w)
    m = _sensor_outputs(m, aux, I, P, w)
    for c in range(I[H.NC]):
        aux[m] = w.ctrl_err[c]
        ix = ctrl_i[c, CtrlI.X]
        if ctrl_i[c, CtrlI.TYPE] == CtrlKind.SPEED:
            aux[m + 1] = w.torque_cmd[ctrl_i[c, CtrlI.NODE]]
        else:
            aux[m + 1] = w.ctrl_out[c]
        aux[m + 2] = y[ix] if ix >= 0 else 0.0
        m += AUX_CTRL
    for mv in range(I[H.NM]):
        aux[m] = y[mover_i[mv, MoverI.Q]]
        aux[m + 1] = y[mover_i[mv, MoverI.QD]]
        aux[m + 2] = w.mover_web[mv]
        aux[m + 3] = w.mover_force[mv]
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
