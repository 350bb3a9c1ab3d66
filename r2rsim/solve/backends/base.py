"""The interface between the event loop (:mod:`r2rsim.solve.simulate`) and an integrator.

A backend integrates a compiled line over one chunk of output samples at a time and, when
asked, locates an event exactly. It knows nothing of segments, discrete logic or the sample
grid: :class:`r2rsim.solve.simulate._EventLoop` decides where each chunk starts and ends,
which events to look for and what to do at them.

Units and shapes, throughout: times in seconds; ``n`` is ``compiled.n_states``, ``m`` is
``len(compiled.event_kinds)`` (the event functions ``compiled.events``, whose condition is
``g < 0``).

Ownership of arrays: the arrays a backend returns belong to the caller. A backend returns
new arrays, or the ``tspan`` it was given (or views of it), and neither keeps nor writes them
afterwards; it does not write to the ``tspan`` and ``y0`` it is given.
"""

from __future__ import annotations

import abc
from typing import TYPE_CHECKING, ClassVar, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from ...compile.compiler import CompiledLine
    from ...schema.scenario import SolverOptions


class Root(NamedTuple):
    """Where an integration stopped at an event: the first root of the event functions.

    Attributes
    ----------
    t : float
        Time of the root [s].
    y : ndarray (n,)
        State at ``t``.
    directions : ndarray (m,) of int
        Per event function: -1 where it fell through 0 (its condition ``g < 0`` turned
        true), +1 where it rose through 0, 0 where it did not reach 0.
    """

    t: float
    y: np.ndarray
    directions: np.ndarray


class Chunk(NamedTuple):
    """What :meth:`SolverBackend.advance` returns for one chunk of output samples.

    A NamedTuple (a tuple): building one costs what the anonymous tuple it replaces cost.

    Attributes
    ----------
    t : ndarray (k,)
        The sample times reached [s]: the leading ``k`` entries of the requested ``tspan``,
        all of them (``k = len(tspan)``) unless the integration failed or stopped at a root.
    y : ndarray (k, n)
        The states at ``t``.
    failure : str or None
        Why the integration failed (the solver's message, for the run's termination reason),
        or None when it did not. ``t`` and ``y`` then hold the samples before the failure.
    t_steps : ndarray (j,)
        The solver's own step times [s], from ``tspan[0]`` on, for event detection on the
        steps and the step budget; the sample times for a backend that does not expose its
        steps (then ``t_steps is t``).
    y_steps : ndarray (j, n)
        The states at ``t_steps``.
    root : Root or None
        The event at which the integration stopped (only when event location was on:
        see :meth:`SolverBackend.locates_events`), else None. ``t`` and ``y`` then end at or
        before ``root.t``.
    """

    t: np.ndarray
    y: np.ndarray
    failure: str | None
    t_steps: np.ndarray
    y_steps: np.ndarray
    root: Root | None
    aux: np.ndarray | None = None
    """The algebraic outputs at ``t`` (columns ``CompiledLine.aux_names``), when the backend
    evaluated them as it wrote the samples (:attr:`SolverBackend.record_outputs`); None:
    the caller evaluates them."""


class Located(NamedTuple):
    """An event located exactly by :meth:`SolverBackend.locate`.

    Attributes
    ----------
    t : float
        Time of the event [s]: at or just past the root, where the function has changed sign
        (or is 0).
    y : ndarray (n,)
        State at ``t``.
    which : ndarray of int
        Indices of the event functions found at this root.
    """

    t: float
    y: np.ndarray
    which: np.ndarray


class SolverBackend(abc.ABC):
    """An integrator of a compiled line, as the event loop drives it.

    Subclasses set :attr:`name` (the ``solver.backend`` value that selects them, see
    :data:`r2rsim.solve.backends.BACKENDS`) and implement :meth:`describe`,
    :meth:`locates_events`, :meth:`advance` and :meth:`locate`. They keep the counters
    below up to date; :func:`r2rsim.solve.simulate` reports them in ``stats``.

    Parameters
    ----------
    cl : CompiledLine
        The line to integrate. Its parameters (``cl.I``, ``cl.P``) change between calls (the
        discrete logic acts in place): a backend reads them at every call, through the
        compiled kernels, and must not cache values computed from them.
    settings : SolverOptions
        The run's ``solver:`` settings (tolerances, BDF order, ...).

    Attributes
    ----------
    nfev : int
        Right-hand-side evaluations so far.
    njev : int
        Jacobian evaluations so far.
    steps : int
        Steps taken so far (samples returned, for a backend whose :attr:`reports_steps` is
        False); counted against the run's step budget.
    messages : list of str
        The solver's own diagnostic messages, the first few (``stats["solver_messages"]``).
    record_outputs : bool
        Set by the caller: the algebraic outputs of the samples are wanted. A backend that
        can evaluate them as it writes the samples returns them in ``Chunk.aux``; the others
        leave ``Chunk.aux`` None and the caller evaluates them.
    """

    name: ClassVar[str]
    """The ``solver.backend`` value of this backend."""
    reports_steps: ClassVar[bool] = True
    """Whether :attr:`steps` counts the solver's steps (``stats["steps"]`` is None if not)."""

    def __init__(self, cl: CompiledLine, settings: SolverOptions):
        self.cl = cl
        self.settings = settings
        self.nfev = 0
        self.njev = 0
        self.steps = 0
        self.messages: list[str] = []
        self.record_outputs = False

    @staticmethod
    @abc.abstractmethod
    def describe(settings: SolverOptions) -> str:
        """One line naming the integrator and its settings (for logs and ``runs.parquet``).

        Parameters
        ----------
        settings : SolverOptions

        Returns
        -------
        str
        """

    @abc.abstractmethod
    def locates_events(self, hot: bool) -> bool:
        """Whether :meth:`advance` itself stops at events.

        Parameters
        ----------
        hot : bool
            The ``find_events`` the chunk was advanced with.

        Returns
        -------
        bool
            True: :meth:`advance` returns a :class:`Root` when an event function changes sign
            within the chunk, and the caller need not look for events on the steps. False:
            the caller detects events on ``Chunk.t_steps`` / ``Chunk.y_steps`` and locates
            them with :meth:`locate`.
        """

    @abc.abstractmethod
    def advance(
        self, tspan: np.ndarray, y0: np.ndarray, find_events: bool = False, resume: bool = False
    ) -> Chunk:
        """Integrate from ``(tspan[0], y0)`` to ``tspan[-1]`` and return the states at ``tspan``.

        Parameters
        ----------
        tspan : ndarray (k,)
            Increasing output times [s], at least 3 of them; ``tspan[0]`` is the start.
        y0 : ndarray (n,)
            State at ``tspan[0]``; not modified.
        find_events : bool
            Stop at the first root of the event functions (a "hot" chunk, after a discrete
            change, when more events are likely) if the backend can; see
            :meth:`locates_events`.
        resume : bool
            The previous call ended at ``(tspan[0], y0)`` and nothing changed since (a memory
            chunk boundary): the backend may continue with its step size and Jacobian.

        Returns
        -------
        Chunk
            A failure is returned (``Chunk.failure``), never raised.
        """

    @abc.abstractmethod
    def locate(self, t0: float, y0: np.ndarray, t1: float) -> Located | None:
        """Integrate ``[t0, t1]`` from ``y0`` with root finding on every event function.

        Parameters
        ----------
        t0, t1 : float
            The interval [s] in which an event function changed sign (two steps of a chunk).
        y0 : ndarray (n,)
            State at ``t0``; not modified.

        Returns
        -------
        Located or None
            The first event in the interval, or None when no root was found (a function
            grazing 0).
        """
