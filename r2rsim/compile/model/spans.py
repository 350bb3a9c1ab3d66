"""Spans: their lengths, tensions and the mass balance of the web in them.

The state of span i is its geometric strain e_i (``SpanI.E``). Its tension is E·A times the
positive part of e (a slack span carries none, physics.md eq. 1.3), and its strain changes
with the unstretched flux through its two nodes (mass conservation, eq. 1.4/1.5): the flux
through a node is upwinded, v·f(strain of the web arriving), with f(e) = 1/(1 + e) (exact)
or 1 - e (the linear model of the thesis).
"""

from __future__ import annotations

from .base import (
    H,
    Mode,
    NodeI,
    NodeKind,
    SpanI,
    SpanP,
    TableKind,
    g_add,
    j_add,
    j_axpy,
    kernel,
    nodes,
    quantity_ids,
    scratch,
    spans,
)
from .programme import has_sines, sines_slope, table_value
from .rolls import roll_wound_in_strain
from .transport import _df, flux, j_flux


# --------------------------------------------------------------------------- phases
@kernel
def fixed_lengths(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 0: every span at its fixed length and plain-web E·A (movers, eccentric rollers
    and splice joints change them in the phases that follow)."""
    span_i, span_p = spans(I, P)
    w = scratch(I, W)
    for i in range(I[H.NS]):
        w.length[i] = span_p[i, SpanP.L]
        w.length_rate[i] = 0.0
        w.dlength_dq[i] = 0.0
        w.d2length_dq2[i] = 0.0
        w.ea_eff[i] = span_p[i, SpanP.EA]


@kernel
def span_tensions(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 1: tension from the strain (slack: geometric strain < 0 carries none). The
    strain carried through the nodes is that of the plain web, T/EA."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    span_i, span_p = spans(I, P)
    EAweb = P[I[H.EA]]
    for i in range(I[H.NS]):
        ie = span_i[i, SpanI.E]
        e = y[ie]
        EA = w.ea_eff[i]
        em = e if e > 0.0 else 0.0
        w.tension[i] = EA * em
        w.strain_web[i] = EA * em / EAweb
        if jac:
            g_add(GI, GC, GV, maxd, qid.tension + i, ie, EA if e > 0.0 else 0.0)


@kernel
def _upstream_strain(a, y, I, P, node_i, node_p, w, ntb):
    """(strain, d strain/dR) of the web that forward flow brings into a span from its
    upstream node ``a`` when no span precedes it: a roll's wound-in strain."""
    if node_i[a, NodeI.KIND] == NodeKind.UNWIND:
        return w.wound_strain[2 * a], w.wound_strain[2 * a + 1]  # kept by roll_lengths
    ef, dwa = roll_wound_in_strain(node_p, a, w.radius[a])
    if ntb > 0:
        ef += table_value(I, P, TableKind.WOUND, a, y[node_i[a, NodeI.U]])
    return ef, dwa


@kernel
def span_balance(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 11: mass conservation with the geometric strain as the state,
    de/dt = fac·(q_b - q_a) + g·dL/dt (physics.md eq. 1.4/1.5)."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    w = scratch(I, W)
    node_i, node_p = nodes(I, P)
    span_i, span_p = spans(I, P)
    linear = I[H.MODEL] == 1
    ntb = I[H.NTB]
    for i in range(I[H.NS]):
        ie = span_i[i, SpanI.E]
        a = span_i[i, SpanI.UP]
        bnode = span_i[i, SpanI.DN]
        L = w.length[i]
        Ld = w.length_rate[i]
        eg = y[ie]
        # upstream node a: forward flow brings the strain of the span before a
        sp_before = node_i[a, NodeI.SPAN_UP]
        dwa = 0.0
        if sp_before >= 0:
            ef = w.strain_web[sp_before]
        else:
            ef, dwa = _upstream_strain(a, y, I, P, node_i, node_p, w, ntb)
        xa = w.joint_factor[a]
        xb = w.joint_factor[bnode]
        qa = flux(w.speed[a], xa * ef, xa * w.strain_web[i], linear)
        sp_after = node_i[bnode, NodeI.SPAN_DN]
        er = w.strain_web[sp_after] if sp_after >= 0 else w.strain_web[i]
        qb = flux(w.speed[bnode], xb * w.strain_web[i], xb * er, linear)
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
            j_add(JJ, mode, ie, ie, dfac * (qb - qa) + dgl * Ld)
            rate_per_l = (fac * (qb - qa) + gl * Ld) / L
            _span_balance_jac(
                i, ie, a, bnode, sp_before, sp_after, ef, er, dwa, fac, rate_per_l, gl, y, JJ,
                mode, I, P, GI, GC, GV, node_i, span_p, w,
            )  # fmt: skip


@kernel
def _span_balance_jac(
    i, ie, a, bnode, sp_before, sp_after, ef, er, dwa, fac, rate_per_l, gl, y, JJ, mode, I, P,
    GI, GC, GV, node_i, span_p, w,
):  # fmt: skip
    """The chain rule of span i's strain rate through L, dL/dt, the upstream roll's radius
    and wound-in strain, and the two fluxes."""
    maxd = I[H.MAXD]
    qid = quantity_ids(I)
    linear = I[H.MODEL] == 1
    xa = w.joint_factor[a]
    xb = w.joint_factor[bnode]
    j_axpy(JJ, mode, ie, -rate_per_l, GI, GC, GV, maxd, qid.length + i)
    j_axpy(JJ, mode, ie, gl, GI, GC, GV, maxd, qid.length_rate + i)
    if sp_before < 0:
        va = w.speed[a]
        dqa = va * _df(xa * ef, linear) * xa * dwa if va >= 0.0 else 0.0
        j_axpy(JJ, mode, ie, -fac * dqa, GI, GC, GV, maxd, qid.radius + a)
        if I[H.NTB] > 0 and has_sines(I, TableKind.WOUND, a):
            iua = node_i[a, NodeI.U]
            dqa = (
                va * _df(xa * ef, linear) * xa * sines_slope(I, P, TableKind.WOUND, a, y[iua])
                if va >= 0.0
                else 0.0
            )
            j_add(JJ, mode, ie, iua, -fac * dqa)
    sp_b = sp_after if sp_after >= 0 else i
    j_flux(
        JJ, mode, ie, fac, w.speed[bnode], w.strain_web[i], er, i, sp_b, xb, linear,
        GI, GC, GV, maxd, qid.speed + bnode, qid.tension, span_p[i, SpanP.EA],
        span_p[sp_b, SpanP.EA],
    )  # fmt: skip
    ea_a = span_p[sp_before, SpanP.EA] if sp_before >= 0 else 1.0
    j_flux(
        JJ, mode, ie, -fac, w.speed[a], ef, w.strain_web[i], sp_before, i, xa, linear,
        GI, GC, GV, maxd, qid.speed + a, qid.tension, ea_a, span_p[i, SpanP.EA],
    )  # fmt: skip
