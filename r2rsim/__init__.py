"""r2rsim: a physics-based roll-to-roll web-handling line simulator.

Pipeline (one package per stage): :mod:`r2rsim.schema` → :mod:`r2rsim.compile` →
:mod:`r2rsim.solve` → :mod:`r2rsim.measure` → :mod:`r2rsim.dataset`.

The public names below are loaded lazily (PEP 562): ``import r2rsim`` costs almost nothing,
and e.g. ``r2rsim.simulate`` imports :mod:`r2rsim.solve` (numba, scipy) on first access. This
keeps ``r2rsim --version``, ``r2rsim schema`` or ``r2rsim validate LINE`` fast.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

# Cheap (standard library only), so imported eagerly.
from ._version import __version__
from .errors import InputError, R2RError, SimulationError

if TYPE_CHECKING:  # the real imports, for type checkers and IDEs
    from .compile import CompiledLine, Programme, compile_line
    from .run import RunSummary, run_scenario
    from .schema import Line, Scenario, load_line, load_scenario
    from .solve import SimulationResult, SolverSettings, nominal_state, simulate, steady_state

# Public name -> submodule that defines it (imported on first attribute access).
_LAZY = {
    "CompiledLine": ".compile",
    "Programme": ".compile",
    "compile_line": ".compile",
    "RunSummary": ".run",
    "run_scenario": ".run",
    "Line": ".schema",
    "Scenario": ".schema",
    "load_line": ".schema",
    "load_scenario": ".schema",
    "SimulationResult": ".solve",
    "SolverSettings": ".solve",
    "nominal_state": ".solve",
    "simulate": ".solve",
    "steady_state": ".solve",
}
# Stage packages that the former eager imports made available as ``r2rsim.<stage>`` after a
# bare ``import r2rsim``; still reachable that way, now imported on first access.
_SUBMODULES = frozenset({"compile", "dataset", "measure", "run", "schema", "solve", "units"})

__all__ = [
    "CompiledLine",
    "InputError",
    "Line",
    "Programme",
    "R2RError",
    "RunSummary",
    "Scenario",
    "SimulationError",
    "SimulationResult",
    "SolverSettings",
    "__version__",
    "compile_line",
    "load_line",
    "load_scenario",
    "nominal_state",
    "run_scenario",
    "simulate",
    "steady_state",
]


def __getattr__(name: str):
    """Import the submodule that defines ``name`` on first access (PEP 562).

    Parameters
    ----------
    name : str
        A public name of :data:`__all__` or a stage package such as ``"solve"``.

    Returns
    -------
    object
        The attribute, cached in the module namespace so the next access is direct.

    Raises
    ------
    AttributeError
        If ``name`` is neither.
    """
    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    elif name in _SUBMODULES:
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The module's attributes including the not yet loaded public names."""
    return sorted(set(globals()) | set(__all__))
