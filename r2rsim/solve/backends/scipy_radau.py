"""scipy's Radau (``solve_ivp``) with a sparse analytic Jacobian: the cross-check backend."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .base import Chunk, Located, SolverBackend

if TYPE_CHECKING:
    from ...compile.compiler import CompiledLine
    from ...schema.scenario import SolverOptions

NONFINITE = "the state is not finite (nan or inf)"
"""The failure message of a chunk that starts from a state that is not finite."""


class ScipyRadauBackend(SolverBackend):
    """scipy's Radau IIA (``solver.backend: radau``). scipy does not expose its steps: events
    are detected on the samples, and :attr:`steps` counts samples."""

    name = "radau"
    reports_steps = False

    @staticmethod
    def describe(settings: SolverOptions) -> str:
        """See :meth:`SolverBackend.describe`."""
        return f"scipy Radau sparse analytic-jac rtol={settings.rtol:g}"

    @staticmethod
    def locates_events(hot: bool) -> bool:
        """Never: the caller checks the samples (scipy does not expose its steps)."""
        return False

    def __init__(self, cl: CompiledLine, settings: SolverOptions):
        import scipy.sparse as sps

        super().__init__(cl, settings)
        n = cl.n_states
        rows, cols = cl.pattern
        JJ = np.zeros((n, n))
        from ...compile import kernels

        vals = np.zeros(len(rows))
        yd = np.zeros(n)

        rhs = cl.make_rhs()

        def fun(t, y):
            out = np.empty(n)
            rhs(t, np.ascontiguousarray(y), out)
            return out

        def jac(t, y):
            kernels.jac_values(
                t, np.ascontiguousarray(y), JJ, cl.I, cl.P, cl._W, cl._GI, cl._GC, cl._GV, yd, vals
            )
            return sps.csc_matrix((vals.copy(), (rows, cols)), shape=(n, n))

        self.fun, self.jac = fun, jac

    def _ivp(self, tspan, y0, events=None):
        from scipy.integrate import solve_ivp

        return solve_ivp(
            self.fun,
            (tspan[0], tspan[-1]),
            y0,
            method="Radau",
            t_eval=tspan,
            jac=self.jac,
            rtol=self.settings.rtol,
            atol=self.cl.atol * self.settings.atol_scale,
            events=events,
            dense_output=events is not None,
        )

    def advance(self, tspan, y0, find_events=False, resume=False) -> Chunk:
        """The samples at ``tspan``, which are also the chunk's "steps" (``Chunk.t_steps is
        Chunk.t``); ``find_events`` and ``resume`` are ignored. See
        :meth:`SolverBackend.advance`."""
        if not np.all(np.isfinite(y0)):  # solve_ivp raises on it: a failure like any other
            Y = np.asarray(y0, float)[None, :]
            return Chunk(tspan[:1], Y, NONFINITE, tspan[:1], Y, None)
        res = self._ivp(tspan, y0)
        self.nfev += int(res.nfev)
        self.njev += int(res.njev)
        self.steps += len(res.t)  # samples, not steps: scipy does not report them
        msg = None if res.success else res.message
        tt, Y = np.asarray(res.t), np.ascontiguousarray(np.asarray(res.y).T)
        return Chunk(tt, Y, msg, tt, Y, None)  # steps not exposed: events found on the samples

    def locate(self, t0, y0, t1) -> Located | None:
        """Integrate [t0, t1] with solve_ivp's event location, one terminal event per event
        function; see :meth:`SolverBackend.locate`."""
        cl = self.cl
        m = len(cl.event_kinds)
        evs = []
        for i in range(m):

            def ev(t, y, i=i):
                return cl.events(t, y)[0][i]

            # solve_ivp reads these attributes of an event function
            ev.terminal = True  # type: ignore[attr-defined]
            ev.direction = 0  # type: ignore[attr-defined]
            evs.append(ev)
        res = self._ivp(np.array([t0, t1]), y0, events=evs)
        self.nfev += int(res.nfev)
        if res.status == 1:
            for i, te in enumerate(res.t_events):
                if len(te):
                    t, y = self._past_root(res.sol, i, t0, y0, float(te[0]), t1)
                    return Located(t, y, np.array([i]))
        return None

    def _past_root(self, sol, i, t0, y0, te, t1):
        """The first time at or after scipy's root where event i has changed sign (as CVODE
        and radau5 return it): scipy's root may lie up to 4 eps |t| on the near side, and a
        mode change applied there would act on a state that has not crossed."""
        g0 = self.cl.events(t0, y0)[0][i]
        step = 4.0 * np.finfo(float).eps * max(1.0, abs(te))
        t = te
        for _ in range(60):
            y = sol(t)
            g = self.cl.events(t, y)[0][i]
            if g == 0.0 or (g < 0.0) != (g0 < 0.0) or t >= t1:
                return t, y
            t = min(t1, t + step)
            step *= 2.0
        return t, sol(t)
