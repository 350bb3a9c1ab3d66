"""Event functions: one value per event record, whose condition holds where it is < 0.

slack: geometric strain; break: T_break - T; capstan: e^(μβ)·T_lo - T_hi; roll empty:
R² - R_core²; end stop: q - q_min (q_max - q), and while latched the force pressing the mover
into the stop (released when it reverses); splice joint: unstretched length to the next node
minus the joint's lead (or trail); joint break: T_break,s - T; splice trigger: R - R_trigger;
refill: storage short of its set-point. Read after an evaluation, from its intermediates.
"""

from __future__ import annotations

import math

from .base import (
    CtrlP,
    EventI,
    EventKind,
    H,
    JointP,
    MoverI,
    MoverP,
    NodeI,
    NodeP,
    SpanI,
    SpanP,
    controllers,
    events,
    joints,
    kernel,
    movers,
    nodes,
    scratch,
    spans,
)

PI = math.pi


@kernel
def _end_stop(kind, idx, y, I, P, w):
    """A mover's end-stop event: distance to the stop while free, else the force that holds
    it there (the stop releases when it changes sign)."""
    mover_i, mover_p = movers(I, P)
    md = mover_p[idx, MoverP.MODE]
    q = y[mover_i[idx, MoverI.Q]]
    lo = kind == EventKind.STOP_LO
    if md == 0.0:
        return q - mover_p[idx, MoverP.QMIN] if lo else mover_p[idx, MoverP.QMAX] - q
    if md == -1.0 and lo:
        return w.mover_force[idx]
    if md == 1.0 and not lo:
        return -w.mover_force[idx]
    return 1.0


@kernel
def _joint(kind, idx, y, I, P, w):
    """A splice joint's events: its break (T_break,s - T of the span holding its lead), or
    the next node crossing of its lead or its trail, whichever comes first."""
    span_i, span_p = spans(I, P)
    node_i, node_p = nodes(I, P)
    joint_p = joints(I, P)
    nS = I[H.NS]
    if joint_p[idx, JointP.ACTIVE] == 0.0:
        return 1.0
    sp = int(joint_p[idx, JointP.SPAN])
    if kind == EventKind.JOINT_BREAK:
        return joint_p[idx, JointP.TBRK] - w.tension[min(max(sp, 0), nS - 1)]
    k0 = int(joint_p[idx, JointP.NODE])
    lead = y[node_i[k0, NodeI.U]] - joint_p[idx, JointP.U0]
    st = int(joint_p[idx, JointP.TSPAN])
    c0 = 0.0
    c_trail = 0.0
    for i in range(min(sp + 1, nS)):
        c0 += w.length[i] / max(1.0 + y[span_i[i, SpanI.E]], 1e-6)
        if i == st:
            c_trail = c0
    g_lead = c0 - lead if sp < nS else 1.0
    return min(g_lead, c_trail - (lead - joint_p[idx, JointP.LEN]))


@kernel
def event_functions(t, y, g, I, P, W):
    """Fill ``g`` with every event function at (t, y); the intermediates of W must be those
    of an evaluation at (t, y)."""
    w = scratch(I, W)
    node_i, node_p = nodes(I, P)
    span_i, span_p = spans(I, P)
    ctrl_i, ctrl_p = controllers(I, P)
    event_i = events(I, P)
    for m in range(I[H.NEV]):
        kind = event_i[m, EventI.KIND]
        idx = event_i[m, EventI.INDEX]
        if kind == EventKind.SLACK:
            g[m] = y[span_i[idx, SpanI.E]]
        elif kind == EventKind.BREAK:
            g[m] = span_p[idx, SpanP.TBRK] - w.tension[idx]
        elif kind == EventKind.CAPSTAN:
            t1 = w.tension[node_i[idx, NodeI.SPAN_UP]]
            t2 = w.tension[node_i[idx, NodeI.SPAN_DN]]
            g[m] = node_p[idx, NodeP.EMB] * min(t1, t2) - max(t1, t2)
        elif kind == EventKind.EMPTY:
            R2 = node_p[idx, NodeP.R0] ** 2 - node_p[idx, NodeP.CW] / PI * y[node_i[idx, NodeI.S]]
            g[m] = R2 - node_p[idx, NodeP.RC] ** 2
        elif kind == EventKind.STOP_LO or kind == EventKind.STOP_HI:
            g[m] = _end_stop(kind, idx, y, I, P, w)
        elif kind == EventKind.JOINT_PASS or kind == EventKind.JOINT_BREAK:
            g[m] = _joint(kind, idx, y, I, P, w)
        elif kind == EventKind.SPLICE_RADIUS:
            rt = node_p[idx, NodeP.RTRIG]
            g[m] = w.radius[idx] - rt if rt > 0.0 else 1.0
        elif kind == EventKind.REFILL:
            if ctrl_p[idx, CtrlP.GATE] == -1.0:
                g[m] = ctrl_p[idx, CtrlP.SIGN] * w.ctrl_err[idx]
            else:
                g[m] = 1.0
        else:
            g[m] = 1.0
