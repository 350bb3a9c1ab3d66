"""Splice joints: a span holding joint length l_s has compliance (l - l_s)/EA + l_s/EA_s
(physics.md eq. 1.19). The joint's place is fixed by the unstretched length paid out
since the splice. Mass conservation: while the joint crosses a node the web crossing
it is the joint, at strain T/EA_s (factor XF = EA/EA_s on the carried strain); without
this the span's tension would jump with its compliance as the joint enters. The
Jacobian treats the overlap as constant (it changes only while the joint crosses a node).
Which nodes the joint straddles is latched by the joint-pass events (JointP.SPAN holds the
lead, JointP.TSPAN the trail), not read from the state: the flux jumps there, and a jump
inside a step makes an implicit method shrink its step until it fails (scipy's Radau
did, at rtol 1e-5..1e-7). Between events the right-hand side stays smooth.
"""

from __future__ import annotations

from .base import H, JointP, NodeI, SpanI, joints, kernel, nodes, scratch, spans


@kernel
def joint_compliance(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 0 (joints): the joint factor XF of every node and the E·A of every span a
    joint lies in, from the unstretched length paid out since the splice."""
    nN = I[H.NN]
    nS = I[H.NS]
    w = scratch(I, W)
    node_i, node_p = nodes(I, P)
    span_i, span_p = spans(I, P)
    joint_p = joints(I, P)
    for k in range(nN):
        w.joint_factor[k] = 1.0
    for js in range(joint_p.shape[0]):
        if joint_p[js, JointP.ACTIVE] == 0.0:
            continue
        k0 = int(joint_p[js, JointP.NODE])
        lead = y[node_i[k0, NodeI.U]] - joint_p[js, JointP.U0]
        trail = lead - joint_p[js, JointP.LEN]
        xf = 1.0 / joint_p[js, JointP.RATIO]
        sp_lead = int(joint_p[js, JointP.SPAN])
        sp_trail = int(joint_p[js, JointP.TSPAN])
        if sp_trail < k0:  # the trail is still on the roll
            w.joint_factor[k0] = xf
        for i in range(max(sp_trail, 0), min(sp_lead, nS)):
            w.joint_factor[span_i[i, SpanI.DN]] = xf
        c0 = 0.0
        for i in range(nS):
            ell = w.length[i] / max(1.0 + y[span_i[i, SpanI.E]], 1e-6)
            ov = min(c0 + ell, lead) - max(c0, trail)
            if ov > 0.0:
                frac = min(ov / ell, 1.0)
                w.ea_eff[i] = w.ea_eff[i] / (1.0 - frac * (1.0 - xf))
            c0 += ell
            if c0 >= lead:
                break
