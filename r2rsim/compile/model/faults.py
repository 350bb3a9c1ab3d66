"""Faults on parameters: a ramp or exponential profile written into ``P`` before the phases
read it (the parameter slots are packed by :mod:`r2rsim.compile.faults`)."""

from __future__ import annotations

import math

from .base import FaultP, fault_slots, kernel


@kernel
def fault_profiles(t, I, P):
    """Write each active fault slot's value at ``t``, base + a + b·dt + c·exp(-dt/tau), into
    the parameter it targets (no state dependence, so no Jacobian share)."""
    fault_p = fault_slots(I, P)
    for fs in range(fault_p.shape[0]):
        if fault_p[fs, FaultP.ON] != 0.0:
            dt = t - fault_p[fs, FaultP.T0]
            P[int(fault_p[fs, FaultP.IDX])] = (
                fault_p[fs, FaultP.BASE]
                + fault_p[fs, FaultP.A]
                + fault_p[fs, FaultP.B] * dt
                + fault_p[fs, FaultP.C] * math.exp(-dt / fault_p[fs, FaultP.TAU])
            )
