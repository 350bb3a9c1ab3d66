"""r2rsim: a physics-based roll-to-roll web-handling line simulator.

Pipeline (one package per stage): :mod:`r2rsim.schema` → :mod:`r2rsim.compile` →
:mod:`r2rsim.solve` → :mod:`r2rsim.measure` → :mod:`r2rsim.dataset`.
"""

from ._version import __version__
from .compile import CompiledLine, Programme, compile_line
from .errors import InputError, R2RError, SimulationError
from .run import RunSummary, run_scenario
from .schema import Line, Scenario, load_line, load_scenario
from .solve import SimulationResult, SolverSettings, nominal_state, simulate, steady_state

__all__ = [
    "CompiledLine", "InputError", "Line", "Programme", "R2RError", "RunSummary", "Scenario",
    "SimulationError", "SimulationResult", "SolverSettings", "__version__", "compile_line",
    "load_line", "load_scenario", "nominal_state", "run_scenario", "simulate", "steady_state",
]
