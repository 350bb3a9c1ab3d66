"""Stage 3 of the pipeline: integrate a compiled line (CVODE BDF, or scipy Radau)."""

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
