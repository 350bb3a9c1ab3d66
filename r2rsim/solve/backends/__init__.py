"""The integrators a run can use, one module each behind :class:`SolverBackend`.

=========  ==========================================  ===================================
name       class                                       integrator
=========  ==========================================  ===================================
radau5     :class:`.radau5.Radau5Backend`              r2rsim's compiled Radau IIA (default)
cvode      :class:`.cvode.CVODEBackend`                SUNDIALS CVODE BDF (scikit-sundae)
radau      :class:`.scipy_radau.ScipyRadauBackend`     scipy's Radau (cross-check)
=========  ==========================================  ===================================

The scenario's ``solver.backend`` picks one by name (:data:`BACKENDS`). The modules import
their integrator libraries only when a backend is built.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ...errors import InputError
from .base import Chunk, Located, Root, SolverBackend
from .cvode import CVODEBackend
from .radau5 import Radau5Backend
from .scipy_radau import ScipyRadauBackend

if TYPE_CHECKING:
    from ...compile.compiler import CompiledLine
    from ...schema.scenario import SolverOptions

BACKENDS: dict[str, type[SolverBackend]] = {
    cls.name: cls for cls in (CVODEBackend, Radau5Backend, ScipyRadauBackend)
}
"""The backends by ``solver.backend`` name."""


def backend_class(name: str) -> type[SolverBackend]:
    """The backend class registered under ``name``.

    Parameters
    ----------
    name : str
        A ``solver.backend`` value.

    Returns
    -------
    type of SolverBackend

    Raises
    ------
    InputError
        ``name`` is not a registered backend (the message the scenario's validation gives).
    """
    try:
        return BACKENDS[name]
    except (KeyError, TypeError):
        names = [repr(k) for k in BACKENDS]
        raise InputError(
            f"got {name!r}, expected {', '.join(names[:-1])} or {names[-1]}",
            path="solver.backend",
        ) from None


def make_backend(cl: CompiledLine, settings: SolverOptions) -> SolverBackend:
    """The backend ``settings.backend`` names, set up for the compiled line ``cl``.

    Parameters
    ----------
    cl : CompiledLine
    settings : SolverOptions

    Returns
    -------
    SolverBackend
    """
    return backend_class(settings.backend)(cl, settings)


__all__ = [
    "BACKENDS",
    "CVODEBackend",
    "Chunk",
    "Located",
    "Radau5Backend",
    "Root",
    "ScipyRadauBackend",
    "SolverBackend",
    "backend_class",
    "make_backend",
]
