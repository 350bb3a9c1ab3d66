"""r2rsim's compiled Radau IIA of order 5 (:mod:`r2rsim.solve.radau`): the default backend."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .base import Chunk, Located, Root, SolverBackend

if TYPE_CHECKING:
    from ...compile.compiler import CompiledLine
    from ...schema.scenario import SolverOptions

ARITHMETIC = -1
"""Status of a compiled integration that raised an ArithmeticError (not a radau status)."""


class Radau5Backend(SolverBackend):
    """r2rsim's compiled Radau IIA (``solver.backend: radau5``): the integration, the dense
    output at the samples, their algebraic outputs (:attr:`record_outputs`) and the location
    of events all run in one numba kernel, which reports the samples only
    (``Chunk.t_steps is Chunk.t``: events are located in the kernel, at every step)."""

    name = "radau5"

    @staticmethod
    def describe(settings: SolverOptions) -> str:
        """See :meth:`SolverBackend.describe`."""
        return f"r2rsim Radau IIA order 5 (compiled) band analytic-jac rtol={settings.rtol:g}"

    @staticmethod
    def locates_events(hot: bool) -> bool:
        """Always: at every step, in the kernel."""
        return True

    def __init__(self, cl: CompiledLine, settings: SolverOptions):
        from .. import radau

        super().__init__(cl, settings)
        s = settings
        self.radau = radau
        n = cl.n_states
        self.rtol = s.rtol
        self.atol = np.ascontiguousarray(cl.atol * s.atol_scale, float)
        rows, cols = cl.pattern
        self.rows = np.ascontiguousarray(rows, np.int64)
        self.cols = np.ascontiguousarray(cols, np.int64)
        # the Jacobian kernel writes the pattern entries of a dense (n, n) array
        self.line = (
            cl.I,
            cl.P,
            cl._W,
            cl._GI,
            cl._GC,
            cl._GV,
            cl._aux0,
            np.zeros((n, n)),
            np.zeros(n),
            cl._J1,
        )
        m = len(cl.event_kinds)
        self.g = np.zeros(m)
        self.y_root = np.zeros(n)
        self.dirs = np.zeros(m, np.int64)
        self.vals = np.zeros(len(self.rows))  # Jacobian on the pattern, kept between calls
        self.h_next = 0.0
        self.nlu = 0
        #: accepted steps limited by each state (the largest scaled error estimate)
        self.step_limits = np.zeros(n, np.int64)
        self.arithmetic_error = ""

    def _integrate(self, tspan, y0, resume=False, outputs=False):
        r = self.radau
        cl = self.cl
        tq = np.ascontiguousarray(tspan, float)
        out = np.empty((len(tq), cl.n_states))
        aux = np.empty((len(tq), len(cl.aux_names) if outputs else 0))
        warm = resume and self.h_next > 0.0
        try:
            status, t_reached, n_out, nfev, njev, nlu, nsteps, self.h_next = r.integrate(
                float(tq[0]),
                float(tq[-1]),
                np.ascontiguousarray(y0, float),
                tq,
                out,
                self.rtol,
                self.atol,
                200000,
                self.line,
                self.rows,
                self.cols,
                max(cl.lband, 0),
                max(cl.uband, 0),
                r.CONSTS,
                self.g,
                self.y_root,
                self.dirs,
                self.vals,
                self.h_next if warm else 0.0,
                warm,
                self.step_limits,
                aux,
            )
        except ArithmeticError as exc:
            # a division by zero in the compiled code (numba raises as Python does): values
            # so large that the arithmetic broke down. The chunk's samples are lost with it;
            # the run ends as a solver failure at the chunk's start.
            self.h_next = 0.0
            self.arithmetic_error = (
                f"{type(exc).__name__} in the compiled integrator "
                f"({exc}): the states left the range of floating point"
            )
            return ARITHMETIC, float(tq[0]), tq[:0], out[:0], None
        self.nfev += nfev
        self.njev += njev
        self.nlu += nlu
        self.steps += nsteps
        return status, t_reached, tq[:n_out], out[:n_out], aux[:n_out] if outputs else None

    def advance(self, tspan, y0, find_events=False, resume=False) -> Chunk:
        """Samples at ``tspan``. Events are always located (at every step, in the kernel):
        ``Chunk.root`` is the first one, else None.

        ``resume``: the previous call ended here and nothing changed since (a memory chunk
        boundary), so its proposed step size and its Jacobian are reused. See
        :meth:`SolverBackend.advance`."""
        status, t_reached, tt, Y, A = self._integrate(tspan, y0, resume, self.record_outputs)
        if status == self.radau.ROOT:
            root = Root(t_reached, self.y_root.copy(), self.dirs.copy())
            return Chunk(tt, Y, None, tt, Y, root, A)
        if status == ARITHMETIC:
            return Chunk(tt, Y, self.arithmetic_error, tt, Y, None)
        if status != self.radau.DONE:
            return Chunk(tt, Y, self.radau.MESSAGES[status], tt, Y, None, A)
        return Chunk(tt, Y, None, tt, Y, None, A)

    def locate(self, t0, y0, t1) -> Located | None:
        """Integrate [t0, t1] locating events in the kernel; see
        :meth:`SolverBackend.locate`."""
        status, t_reached, _, _, _ = self._integrate(np.array([t0, t1]), y0)
        if status == self.radau.ROOT:
            return Located(t_reached, self.y_root.copy(), np.nonzero(self.dirs)[0])
        return None
