"""Rolls and rollers (the nodes of the line): radius and inertia, surface speed, the torque
balance J(R)·dω/dt, the lengths an unwind or rewind roll holds, and eccentric rollers.

A node is a roller (fixed radius ``NodeP.R``, inertia ``NodeP.J``) or a roll (``NodeKind``
UNWIND/REWIND): a roll's radius follows from the web length s it holds (state
``NodeI.S``, R² = R0² ∓ c_w·s/π, physics.md eq. 1.6), its inertia from its radius, and it
also counts the unstretched length u paid out or taken up (state ``NodeI.U``).
"""

from __future__ import annotations

import math

from .base import (
    DRAG_CACHE,
    H,
    Mode,
    NodeI,
    NodeKind,
    NodeP,
    SpanP,
    TableKind,
    g_add,
    g_axpy,
    j_add,
    j_axpy,
    kernel,
    nodes,
    quantity_ids,
    scratch,
    spans,
)
from .programme import has_sines, setpoint, sines_slope, table_value
from .transport import _df, flux, j_flux

PI = math.pi


@kernel(inline=False)
def roll_wound_in_strain(node_p, k, R):
    """Wound-in strain of a roll at radius R and its derivative (polynomial in R)."""
    e1 = node_p[k, NodeP.EPSW1]
    e2 = node_p[k, NodeP.EPSW2]
    return node_p[k, NodeP.EPSW] + e1 * R + e2 * R * R, e1 + 2.0 * e2 * R


@kernel
def _drag(I, P, w, k, t):
    """Random bearing-drag torque on node ``k`` at ``t``, through a three-slot cache: Radau
    IIA evaluates each stage time at every Newton iteration and again at the step's end, and
    the drag tables are fixed when the line is compiled, so ``t`` alone is the key."""
    c = w.drag_cache
    b = DRAG_CACHE * k
    for s in range(3):
        if c[b + s] == t:
            return c[b + 3 + s]
    v = table_value(I, P, TableKind.DRAG, k, t)
    s = int(c[b + 6]) % 3
    c[b + s] = t
    c[b + 3 + s] = v
    c[b + 6] = s + 1
    return v


@kernel
def eccentric_lengths(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 0 (rollers): an eccentric roller's centre runs on a circle of radius ECC with
    the roller angle th (state ``NodeI.TH``, dth/dt = ω), so L_up += ECC·cos(th) and
    L_dn -= ECC·cos(th - wrap) (physics.md §1.2, non-ideal rollers); the web still leaves the
    roller surface at ω·R."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    node_i, node_p = nodes(I, P)
    for k in range(I[H.NN]):
        ith = node_i[k, NodeI.TH]
        if ith < 0:
            continue
        iw = node_i[k, NodeI.W]
        ecc = node_p[k, NodeP.ECC]
        th = y[ith]
        om = y[iw]
        yd[ith] = om
        if jac:
            j_add(JJ, mode, ith, iw, 1.0)
        for side in range(2):
            sp = node_i[k, NodeI.SPAN_UP + side]
            if sp < 0:
                continue
            ph = th - side * node_p[k, NodeP.WRAP]
            sg = 1.0 - 2.0 * side
            w.length[sp] += sg * ecc * math.cos(ph)
            w.length_rate[sp] -= sg * ecc * om * math.sin(ph)
            if jac:
                g_add(GI, GC, GV, maxd, qid.length + sp, ith, -sg * ecc * math.sin(ph))
                g_add(GI, GC, GV, maxd, qid.length_rate + sp, ith, -sg * ecc * om * math.cos(ph))
                g_add(GI, GC, GV, maxd, qid.length_rate + sp, iw, -sg * ecc * math.sin(ph))


@kernel
def roll_geometry(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 2: radius and inertia of every node, its angular speed state, and the drive
    torques the later phases accumulate set to zero."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    node_i, node_p = nodes(I, P)
    for k in range(I[H.NN]):
        kind = node_i[k, NodeI.KIND]
        if kind != NodeKind.ROLLER:
            iS = node_i[k, NodeI.S]
            sg = -1.0 if kind == NodeKind.UNWIND else 1.0
            R2 = node_p[k, NodeP.R0] ** 2 + sg * node_p[k, NodeP.CW] / PI * y[iS]
            R = math.sqrt(R2) if R2 > 1e-12 else 1e-6
            w.radius[k] = R
            Rc = node_p[k, NodeP.RC]
            w.inertia[k] = node_p[k, NodeP.JC] + 0.5 * PI * node_p[k, NodeP.RHOW] * (R**4 - Rc**4)
            if jac:
                dR = sg * node_p[k, NodeP.CW] / (2.0 * PI * R)
                g_add(GI, GC, GV, maxd, qid.radius + k, iS, dR)
        else:
            w.radius[k] = node_p[k, NodeP.R]
            w.inertia[k] = node_p[k, NodeP.J]
        iw = node_i[k, NodeI.W]
        w.speed_trim[k] = 0.0
        w.torque_cmd[k] = 0.0
        w.torque[k] = 0.0
        if iw >= 0:
            w.omega[k] = y[iw]
            if jac:
                g_add(GI, GC, GV, maxd, qid.omega + k, iw, 1.0)


@kernel
def surface_speeds(t, V, A, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 7: surface speeds, ω·R of a node with a speed state, else imposed (the line
    speed V times draw and gain, an offset and slope, and a controller's trim); a draw error
    (``NodeP.REFF``) makes the effective radius R·(1 + REFF)."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    node_i, node_p = nodes(I, P)
    for k in range(I[H.NN]):
        iw = node_i[k, NodeI.W]
        R = w.radius[k]
        rf = 1.0 + node_p[k, NodeP.REFF]
        if iw >= 0:
            w.speed[k] = rf * R * y[iw]
            if jac:
                g_add(GI, GC, GV, maxd, qid.speed + k, iw, rf * R)
                g_axpy(GI, GC, GV, maxd, qid.speed + k, rf * y[iw], qid.radius + k)
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
                + w.speed_trim[k]
            )
            w.speed[k] = rf * v
            w.omega[k] = v / R
            if jac:
                g_axpy(GI, GC, GV, maxd, qid.speed + k, rf, qid.speed_trim + k)
                g_axpy(GI, GC, GV, maxd, qid.omega + k, 1.0 / R, qid.speed_trim + k)
                g_axpy(GI, GC, GV, maxd, qid.omega + k, -v / (R * R), qid.radius + k)


@kernel
def torque_balance(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 9: J(R)·dω/dt = R_e·(T_out - T_in) + τ_m - τ_f (+ torque ripple, bearing drag,
    an eccentric roller's pull) for every node with a speed state (physics.md eq. 1.7)."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    node_i, node_p = nodes(I, P)
    for k in range(I[H.NN]):
        iw = node_i[k, NodeI.W]
        if iw < 0:
            continue
        up = node_i[k, NodeI.SPAN_UP]
        dn = node_i[k, NodeI.SPAN_DN]
        Tup = w.tension[up] if up >= 0 else 0.0
        Tdn = w.tension[dn] if dn >= 0 else 0.0
        R = w.radius[k]
        Re = R * (1.0 + node_p[k, NodeP.REFF])
        J = w.inertia[k]
        om = y[iw]
        weps = node_p[k, NodeP.WEPS]
        th = math.tanh(om / weps)
        fr = node_p[k, NodeP.FRICF]
        tf = fr * (node_p[k, NodeP.B] * om + node_p[k, NodeP.TC] * th)
        dtf = fr * (node_p[k, NodeP.B] + node_p[k, NodeP.TC] * (1.0 - th * th) / weps)
        num = Re * (Tdn - Tup) + w.torque[k] - tf
        if node_p[k, NodeP.RIPA] != 0.0:
            num += node_p[k, NodeP.RIPA] * math.sin(node_p[k, NodeP.RIPW] * t)
        # random bearing drag torque (a process disturbance); it enters dω/dt only, which
        # no output reads: the outputs of a sample skip its sum of sinusoids
        if I[H.NTB] > 0 and mode != Mode.OUTPUTS:
            num -= _drag(I, P, w, k, t)
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
        if not jac:
            continue
        if dn >= 0:
            j_axpy(JJ, mode, iw, (Re + fd) / J, GI, GC, GV, maxd, qid.tension + dn)
        if up >= 0:
            j_axpy(JJ, mode, iw, (fu - Re) / J, GI, GC, GV, maxd, qid.tension + up)
        if ith >= 0:
            wrap = node_p[k, NodeP.WRAP]
            dth = node_p[k, NodeP.ECC] * (math.cos(y[ith]) * Tup - math.cos(y[ith] - wrap) * Tdn)
            j_add(JJ, mode, iw, ith, dth / J)
        j_axpy(JJ, mode, iw, 1.0 / J, GI, GC, GV, maxd, qid.torque + k)
        j_add(JJ, mode, iw, iw, -dtf / J)
        if node_i[k, NodeI.KIND] != NodeKind.ROLLER:
            dJdR = 2.0 * PI * node_p[k, NodeP.RHOW] * R**3
            dR = (Tdn - Tup) / J - num * dJdR / (J * J)
            j_axpy(JJ, mode, iw, dR, GI, GC, GV, maxd, qid.radius + k)


@kernel
def roll_lengths(t, y, yd, JJ, mode, I, P, W, GI, GC, GV):
    """Phase 10: a roll's web length through its tangent point, ds/dt = v, and the
    unstretched length paid out or taken up, du/dt = the flux through the roll's node (an
    unwind's web arrives at its wound-in strain)."""
    jac = mode == Mode.JAC or mode == Mode.TOUCH
    w = scratch(I, W)
    node_i, node_p = nodes(I, P)
    linear = I[H.MODEL] == 1
    for k in range(I[H.NN]):
        kind = node_i[k, NodeI.KIND]
        if kind == NodeKind.ROLLER:
            continue
        iU = node_i[k, NodeI.U]
        v = w.speed[k]
        yd[node_i[k, NodeI.S]] = v
        xk = w.joint_factor[k]
        if kind == NodeKind.UNWIND:
            sp = node_i[k, NodeI.SPAN_DN]
            esrc_fwd, desrc = roll_wound_in_strain(node_p, k, w.radius[k])
            # the wound-in strain along the web enters du/dt and the first span's de/dt
            # only, which no output reads: the outputs of a sample skip its sum
            if I[H.NTB] > 0 and mode != Mode.OUTPUTS:
                esrc_fwd += table_value(I, P, TableKind.WOUND, k, y[iU])
            # kept for the first span (spans.span_balance): its sum of sinusoids costs as
            # much as the rest of the evaluation
            w.wound_strain[2 * k] = esrc_fwd
            w.wound_strain[2 * k + 1] = desrc
            yd[iU] = flux(v, xk * esrc_fwd, xk * w.strain_web[sp], linear)
        else:
            sp = node_i[k, NodeI.SPAN_UP]
            yd[iU] = flux(v, xk * w.strain_web[sp], xk * w.strain_web[sp], linear)
        if jac:
            _roll_lengths_jac(k, kind, sp, v, xk, y, JJ, mode, I, P, W, GI, GC, GV)


@kernel
def _roll_lengths_jac(k, kind, sp, v, xk, y, JJ, mode, I, P, W, GI, GC, GV):
    """The chain rule of a roll's ds/dt and du/dt (see :func:`roll_lengths`)."""
    maxd = I[H.MAXD]
    w = scratch(I, W)
    qid = quantity_ids(I)
    node_i, node_p = nodes(I, P)
    span_i, span_p = spans(I, P)
    linear = I[H.MODEL] == 1
    iU = node_i[k, NodeI.U]
    j_axpy(JJ, mode, node_i[k, NodeI.S], 1.0, GI, GC, GV, maxd, qid.speed + k)
    ea = span_p[sp, SpanP.EA] if sp >= 0 else 1.0
    if kind != NodeKind.UNWIND:
        j_flux(
            JJ, mode, iU, 1.0, v, w.strain_web[sp], w.strain_web[sp], sp, sp, xk, linear,
            GI, GC, GV, maxd, qid.speed + k, qid.tension, ea, ea,
        )  # fmt: skip
        return
    esrc_fwd = w.wound_strain[2 * k]
    desrc = w.wound_strain[2 * k + 1]
    j_flux(
        JJ, mode, iU, 1.0, v, esrc_fwd, w.strain_web[sp], -1, sp, xk, linear,
        GI, GC, GV, maxd, qid.speed + k, qid.tension, 1.0, ea,
    )  # fmt: skip
    dq = v * _df(xk * esrc_fwd, linear) * xk * desrc if v >= 0.0 else 0.0
    j_axpy(JJ, mode, iU, dq, GI, GC, GV, maxd, qid.radius + k)
    if I[H.NTB] > 0 and has_sines(I, TableKind.WOUND, k):  # the strain along u = y[iU]
        slope = sines_slope(I, P, TableKind.WOUND, k, y[iU])
        dq = v * _df(xk * esrc_fwd, linear) * xk * slope if v >= 0.0 else 0.0
        j_add(JJ, mode, iU, iU, dq)
