"""Movers: dancer carriages and arms, festoon carriages. A mover's coordinate q (state
``MoverI.Q``, a travel [m] or an arm angle [rad]) sets the lengths of the spans it carries,
and the web's tensions act back on it (physics.md eq. 1.14-1.16):

    M·q'' = -Σ T·dL/dq + load(q) - c·q' - F_c·tanh(q'/ε)

with the load an actuator (air cylinder, torque motor) scaled by ``MoverP.LOADF``, a spring
and gravity. At an end stop or seized (``MoverP.MODE`` ≠ 0) q' = 0 and q is held.

The second derivative of a dancer's span length (the web's stiffness on it) and the
derivative of its load are taken by central differences, deliberately: both are smooth
closed forms, the step (1e-6 and 1e-7 in q) keeps their relative error near 1e-9 (measured in
``tests/test_phase_jacobians.py``), well inside what a Newton iteration needs, and an
analytic form would duplicate ``_span_geo`` and ``mover_load`` in a second, longer function.
"""

from __future__ import annotations

import math

from .base import (
    H,
    Mode,
    MoverI,
    MoverKind,
    MoverP,
    SpanP,
    g_add,
    j_add,
    j_axpy,
    kernel,
    movers,
    quantity_ids,
    scratch,
    spans,
)

#: central-difference steps in q for d2L/dq2 and d(load)/dq
H_LENGTH = 1e-6
H_LOAD = 1e-7


@kernel(inline=False)
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


@kernel(inline=False)
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
    p = mover_p
    lu, dlu = _span_geo(
        p[m, MoverP.AX], p[m, MoverP.AY], cx, cy, p[m, MoverP.DU], p[m, MoverP.TUX],
        p[m, MoverP.TUY], 1.0, dcx, dcy,
    )  # fmt: skip
    ld, dld = _span_geo(
        cx, cy, p[m, MoverP.BX], p[m, MoverP.BY], p[m, MoverP.DD], p[m, MoverP.TDX],
        p[m, MoverP.TDY], -1.0, dcx, dcy,
    )  # fmt: skip
    return lu, dlu, ld, dld


@kernel(inline=False)
def mover_load(mover_p, m, kind, q):
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


@kernel
def mover_spans(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 0 (movers): the lengths of the spans a mover carries and their rates, L(q) and
    dL/dt = dL/dq·q' (a festoon's strands lumped into one span: L0 + n·q)."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    mover_i, mover_p = movers(I, P)
    span_i, span_p = spans(I, P)
    for m in range(I[H.NM]):
        kind = mover_i[m, MoverI.KIND]
        q = y[mover_i[m, MoverI.Q]]
        su = mover_i[m, MoverI.SPAN_U]
        sd = mover_i[m, MoverI.SPAN_D]
        if kind == MoverKind.FESTOON:
            w.length[su] = span_p[su, SpanP.L] + mover_p[m, MoverP.NSTR] * q
            w.dlength_dq[su] = mover_p[m, MoverP.NSTR]
        else:
            lu, dlu, ld, dld = mover_lengths(mover_p, m, kind, q)
            h = H_LENGTH
            _, dlu1, _, dld1 = mover_lengths(mover_p, m, kind, q + h)
            _, dlu0, _, dld0 = mover_lengths(mover_p, m, kind, q - h)
            w.length[su] = lu
            w.dlength_dq[su] = dlu
            w.d2length_dq2[su] = (dlu1 - dlu0) / (2.0 * h)
            w.length[sd] = ld
            w.dlength_dq[sd] = dld
            w.d2length_dq2[sd] = (dld1 - dld0) / (2.0 * h)
    for m in range(I[H.NM]):
        iq = mover_i[m, MoverI.Q]
        iqd = mover_i[m, MoverI.QD]
        for side in range(2):
            sp = mover_i[m, MoverI.SPAN_U + side]
            if sp < 0:
                continue
            w.length_rate[sp] = w.dlength_dq[sp] * y[iqd]
            if jac:
                g_add(GI, GC, GV, maxd, qid.length + sp, iq, w.dlength_dq[sp])
                g_add(GI, GC, GV, maxd, qid.length_rate + sp, iq, w.d2length_dq2[sp] * y[iqd])
                g_add(GI, GC, GV, maxd, qid.length_rate + sp, iqd, w.dlength_dq[sp])


@kernel
def mover_dynamics(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 2b: the mover's equation of motion (module docstring); the web force and the
    net force without friction are kept for the outputs and the end-stop events."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    mover_i, mover_p = movers(I, P)
    for m in range(I[H.NM]):
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
                fweb -= w.tension[sp] * w.dlength_dq[sp]
                kweb -= w.tension[sp] * w.d2length_dq2[sp]
        load = mover_load(mover_p, m, kind, q)
        h = H_LOAD
        dload = (mover_load(mover_p, m, kind, q + h) - mover_load(mover_p, m, kind, q - h)) / (
            2.0 * h
        )
        eps = mover_p[m, MoverP.EPS]
        th = math.tanh(qd / eps)
        ff = mover_p[m, MoverP.FRICF]
        fric = ff * (mover_p[m, MoverP.C] * qd + mover_p[m, MoverP.FC] * th)
        dfric = ff * (mover_p[m, MoverP.C] + mover_p[m, MoverP.FC] * (1.0 - th * th) / eps)
        w.mover_web[m] = fweb
        w.mover_force[m] = fweb + load
        free = 1.0 if mover_p[m, MoverP.MODE] == 0.0 else 0.0
        M = mover_p[m, MoverP.MASS]
        yd[iq] = free * qd
        yd[iqd] = free * (fweb + load - fric) / M
        if jac:
            j_add(JJ, mode, iq, iqd, free)
            for side in range(2):
                sp = mover_i[m, MoverI.SPAN_U + side]
                if sp >= 0:
                    a = -free * w.dlength_dq[sp] / M
                    j_axpy(JJ, mode, iqd, a, GI, GC, GV, maxd, qid.tension + sp)
            j_add(JJ, mode, iqd, iq, free * (kweb + dload) / M)
            j_add(JJ, mode, iqd, iqd, -free * dfric / M)
