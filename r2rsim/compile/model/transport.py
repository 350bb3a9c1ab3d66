"""Web transport through a node: the unstretched flux v·f(strain of the web arriving),
upwinded, and its chain rule (physics.md eq. 1.4/1.5; f(e) = 1/(1 + e), or 1 - e in the
linear model of the thesis)."""

from __future__ import annotations

from .base import j_axpy, kernel


@kernel(inline=False)
def _f(e, linear):
    return 1.0 - e if linear else 1.0 / (1.0 + e)


@kernel(inline=False)
def _df(e, linear):
    return -1.0 if linear else -1.0 / ((1.0 + e) * (1.0 + e))


@kernel(inline=False)
def flux(v, e_fwd, e_rev, linear):
    """Unstretched flux through a node, upwinded: v·f(strain of the web arriving)."""
    return v * _f(e_fwd if v >= 0.0 else e_rev, linear)


@kernel(inline=False)
def j_flux(
    JJ, mode, row, a, v, e_fwd, e_rev, sp_fwd, sp_rev, xf, linear, GI, GC, GV, maxd, qv, qT,
    ea_fwd, ea_rev,
):  # fmt: skip
    """Add a·d(flux)/dy to a Jacobian row for the flux v·f(xf·e) (xf: splice-joint factor
    of the node). Both upwind sources are recorded (one with 0). ``ea_fwd``, ``ea_rev``: the
    E·A of spans ``sp_fwd``, ``sp_rev`` (a scalar rather than the span records: passing a
    record view to this non-inlined function made the Jacobian ~15 % slower)."""
    fwd = v >= 0.0
    e = xf * (e_fwd if fwd else e_rev)
    j_axpy(JJ, mode, row, a * _f(e, linear), GI, GC, GV, maxd, qv)
    if sp_fwd >= 0:
        w = a * v * _df(e, linear) * xf / ea_fwd if fwd else 0.0
        j_axpy(JJ, mode, row, w, GI, GC, GV, maxd, qT + sp_fwd)
    if sp_rev >= 0:
        w = 0.0 if fwd else a * v * _df(e, linear) * xf / ea_rev
        j_axpy(JJ, mode, row, w, GI, GC, GV, maxd, qT + sp_rev)
