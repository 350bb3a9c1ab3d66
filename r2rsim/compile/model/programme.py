"""The operating programme and the process-disturbance tables, as the kernel reads them."""

from __future__ import annotations

import math

from ..layout import N_TABLE_I
from .base import H, Shape, TableI, kernel, records


@kernel(inline=False)
def setpoint(I, P, ch, t):
    """Value and slope of set-point channel ``ch`` at time t (piecewise linear).

    The piece is chosen by the start time of the current solver segment (``P[rt]``), so a
    segment that ends exactly at a corner keeps the slope it started with.
    """
    mx = I[H.MAXPTS]
    n = I[I[H.OFF_SCHN] + ch]
    bt = I[H.OFF_SCHT] + ch * mx
    bv = I[H.OFF_SCHV] + ch * mx
    tseg = P[I[H.OFF_RT]]
    k = 0
    for m in range(n):
        if P[bt + m] <= tseg:
            k = m
    if k >= n - 1:
        return P[bv + n - 1], 0.0
    dt = P[bt + k + 1] - P[bt + k]
    slope = (P[bv + k + 1] - P[bv + k]) / dt if dt > 0.0 else 0.0
    return P[bv + k] + slope * (t - P[bt + k]), slope


@kernel(inline=False)
def table_value(I, P, kind, node, x):
    """Sum of the process disturbances of ``kind`` on ``node`` at x: a sum of sinusoids
    (``Shape.SINES``), or a table interpolated linearly and held constant outside its grid
    (``Shape.TABLE``)."""
    out = 0.0
    ntb = I[H.NTB]
    table_i = records(I, I[H.OFF_TB], ntb, N_TABLE_I)
    for m in range(ntb):
        if table_i[m, TableI.KIND] != kind or table_i[m, TableI.NODE] != node:
            continue
        o = table_i[m, TableI.OFFP]
        n = table_i[m, TableI.N]
        if table_i[m, TableI.SHAPE] == Shape.SINES:
            for j in range(n):
                out += P[o + j] * math.sin(P[o + n + j] * x + P[o + 2 * n + j])
            continue
        s = (x - P[o]) / P[o + 1]
        if s <= 0.0:
            out += P[o + 2]
        elif s >= n - 1:
            out += P[o + 2 + n - 1]
        else:
            i = int(s)
            f = s - i
            out += (1.0 - f) * P[o + 2 + i] + f * P[o + 3 + i]
    return out


@kernel(inline=False)
def sines_slope(I, P, kind, node, x):
    """d/dx of the sum-of-sinusoids disturbances of ``kind`` on ``node`` at x (the
    Jacobian's share; tables keep their earlier zero slope, so that they reproduce old data
    exactly)."""
    out = 0.0
    ntb = I[H.NTB]
    table_i = records(I, I[H.OFF_TB], ntb, N_TABLE_I)
    for m in range(ntb):
        if (
            table_i[m, TableI.KIND] != kind
            or table_i[m, TableI.NODE] != node
            or table_i[m, TableI.SHAPE] != Shape.SINES
        ):
            continue
        o = table_i[m, TableI.OFFP]
        n = table_i[m, TableI.N]
        for j in range(n):
            w = P[o + n + j]
            out += P[o + j] * w * math.cos(w * x + P[o + 2 * n + j])
    return out


@kernel(inline=False)
def has_sines(I, kind, node):
    """Whether ``node`` has a sum-of-sinusoids disturbance of ``kind`` (a structural
    property: it decides the Jacobian pattern)."""
    ntb = I[H.NTB]
    table_i = records(I, I[H.OFF_TB], ntb, N_TABLE_I)
    for m in range(ntb):
        if (
            table_i[m, TableI.KIND] == kind
            and table_i[m, TableI.NODE] == node
            and table_i[m, TableI.SHAPE] == Shape.SINES
        ):
            return True
    return False
