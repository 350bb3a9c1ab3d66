"""Stage 3 of the pipeline: integrate a compiled line (r2rsim's compiled Radau IIA, CVODE
BDF or scipy's Radau, behind :class:`r2rsim.solve.backends.SolverBackend`)."""

from .initial import nominal_state, steady_state
from .simulate import Event, SimulationResult, SolverSettings, simulate

__all__ = [
    "Event",
    "SimulationResult",
    "SolverSettings",
    "nominal_state",
    "simulate",
    "steady_state",
]
