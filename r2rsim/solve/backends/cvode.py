"""SUNDIALS CVODE BDF (through scikit-sundae) with a banded analytic Jacobian."""

from __future__ import annotations

import contextlib
import io
from typing import TYPE_CHECKING

import numpy as np

from .base import Chunk, Located, Root, SolverBackend

if TYPE_CHECKING:
    from ...compile.compiler import CompiledLine
    from ...schema.scenario import SolverOptions


class CVODEBackend(SolverBackend):
    """CVODE BDF (``solver.backend: cvode``), order at most ``solver.max_order``.

    Two solver objects: one without event functions for ordinary chunks (scikit-sundae calls
    a Python event function after every step, which doubles the cost of a BDF2 run), and one
    with them (root finding) for hot chunks and :meth:`locate`.
    """

    name = "cvode"

    @staticmethod
    def describe(settings: SolverOptions) -> str:
        """See :meth:`SolverBackend.describe`."""
        return f"CVODE BDF max_order={settings.max_order} band analytic-jac rtol={settings.rtol:g}"

    @staticmethod
    def locates_events(hot: bool) -> bool:
        """Whether advance() itself stops at events: with root finding on (hot chunks)."""
        return hot

    def __init__(self, cl: CompiledLine, settings: SolverOptions):
        from sksundae.cvode import CVODE

        super().__init__(cl, settings)
        s = settings
        rhs, jac = cl.make_rhs(), cl.make_jac()
        self.rhs = rhs
        common = dict(
            method="BDF",
            rtol=s.rtol,
            atol=cl.atol * s.atol_scale,
            linsolver="band",
            lband=max(cl.lband, 0),
            uband=max(cl.uband, 0),
            jacfn=jac,
            max_order=s.max_order,
            max_num_steps=200000,
        )
        self.solver = CVODE(rhs, **common)

        from ...compile import kernels

        yd = np.zeros(cl.n_states)
        I, P, W, GI, GC, GV, J1 = cl.I, cl.P, cl._W, cl._GI, cl._GC, cl._GV, cl._J1

        def eventsfn(t, y, g):  # called at every step: no allocation
            kernels.event_values(t, y, g, I, P, W, GI, GC, GV, yd, J1)

        if len(cl.event_kinds):
            # scikit-sundae reads these attributes of the event function
            eventsfn.terminal = [True] * len(cl.event_kinds)  # type: ignore[attr-defined]
            eventsfn.direction = [0] * len(cl.event_kinds)  # type: ignore[attr-defined]
            self.locator = CVODE(rhs, eventsfn=eventsfn, num_events=len(cl.event_kinds), **common)

    def _quiet(self, solve, *args):
        """Call a scikit-sundae solve with SUNDIALS' messages kept off the terminal.

        scikit-sundae prints every SUNDIALS warning and error with ``print`` (e.g. "root
        functions identically 0" when a located event starts on its root, which r2rsim
        handles). They are kept, the first few, in ``stats["solver_messages"]``; a failure
        reaches the user as the run's termination reason."""
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            res = solve(*args)
        text = buf.getvalue().strip()
        if text and len(self.messages) < 20:
            self.messages.extend(m.strip() for m in text.split("\n\n") if m.strip())
        return res

    def advance(self, tspan, y0, find_events=False, resume=False) -> Chunk:
        """States at the times ``tspan``: CVODE returns every internal step (one-step mode,
        one return per step instead of one per sample), and the samples are interpolated
        with cubic Hermite polynomials from the step states and their exact derivatives.

        With ``find_events`` CVODE's root finding stops the integration at the first event
        (about 5 µs more per step) and ``Chunk.root`` is that root. ``resume`` is ignored.
        See :meth:`SolverBackend.advance`."""
        from ...compile import kernels

        cl = self.cl
        hot = find_events and len(cl.event_kinds) > 0
        res = self._quiet(
            (self.locator if hot else self.solver).solve, np.array([tspan[0], tspan[-1]]), y0
        )
        self.nfev += int(res.nfev)
        self.njev += int(res.njev)
        ts = np.ascontiguousarray(res.t)
        ys = np.ascontiguousarray(res.y)
        self.steps += len(ts) - 1
        root = failure = None
        if hot and res.status == 2:
            root = Root(
                float(res.t_events[-1]),
                np.array(res.y_events[-1]),
                np.asarray(res.i_events)[-1],
            )
        elif not res.success:
            failure = res.message
        fs = np.empty_like(ys)
        kernels.rows(
            kernels.ROWS_RHS,
            ts,
            ys,
            fs,
            cl.I,
            cl.P,
            cl._W,
            cl._GI,
            cl._GC,
            cl._GV,
            cl._aux0,
            cl._J1,
        )
        if root is not None or failure is not None:  # the samples up to where it stopped
            keep = tspan <= ts[-1]
            out = np.empty((int(keep.sum()), cl.n_states))
            kernels.hermite(ts, ys, fs, tspan[keep], out)
            return Chunk(tspan[keep], out, failure, ts, ys, root)
        out = np.empty((len(tspan), cl.n_states))
        kernels.hermite(ts, ys, fs, np.ascontiguousarray(tspan), out)
        return Chunk(tspan, out, None, ts, ys, None)

    def locate(self, t0, y0, t1) -> Located | None:
        """Integrate [t0, t1] with CVODE's root finding; see :meth:`SolverBackend.locate`."""
        tspan = np.array([t0, 0.5 * (t0 + t1), t1])
        res = self._quiet(self.locator.solve, tspan, y0)
        self.nfev += int(res.nfev)
        if res.status == 2 and res.t_events is not None and len(res.t_events):
            row = np.asarray(res.i_events)[-1]
            return Located(
                float(res.t_events[-1]), np.asarray(res.y_events[-1]), np.nonzero(row)[0]
            )
        return None
