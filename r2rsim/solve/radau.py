"""Compiled Radau IIA integrator (3 stages, order 5, L-stable) over the compiled line.

Why: CVODE's BDF must be held at order 2 on R2R lines (orders 3-5 are unstable on the lightly
damped web modes, solver.md §4.1), so at tight accuracy it needs several times the steps of a
5th-order L-stable method. scipy's ``Radau`` takes few steps but pays ~0.2-1 ms of Python per
step. This module is the same method (Hairer & Wanner, *Solving ODEs II*, §IV.8: simplified
Newton on the transformed collocation system, embedded error estimate, predictive step-size
control, Jacobian reuse) written as one numba kernel: the whole integration, the banded real
and complex LU factorisations, the dense output at the sample times and the location of events
run without returning to Python.

The method's constants are derived below from the Butcher tableau, not typed in, in decimal
arithmetic so that they are the same bytes on every machine: the transformation ``T``
block-diagonalises ``A^-1`` (real eigenvalue ``gamma``, complex pair ``alpha +- i beta``), and
the dense-output matrix interpolates the collocation polynomial.
"""

from __future__ import annotations

import math
from decimal import Decimal, localcontext

import numpy as np
from numba import njit

# the evaluation mode comes with the kernel (kernels re-exports layout's RUNTIME_MODE), so
# solve/ imports no record layout
from ..compile.kernels import (
    MODE_OUTPUTS,
    MODE_RHS,
    RUNTIME_MODE,
    evaluate,
    event_values,
    event_values_after_rhs,
    jac_values,
)
from ..compile.stamp import kernel_stamp

# ---- the method --------------------------------------------------------------------------
_S6 = math.sqrt(6.0)
#: nodes of the 3-stage Radau IIA method
C = np.array([(4.0 - _S6) / 10.0, (4.0 + _S6) / 10.0, 1.0])
#: its Butcher matrix (Hairer & Wanner II, Table IV.5.6)
A = np.array(
    [
        [(88.0 - 7.0 * _S6) / 360.0, (296.0 - 169.0 * _S6) / 1800.0, (-2.0 + 3.0 * _S6) / 225.0],
        [(296.0 + 169.0 * _S6) / 1800.0, (88.0 + 7.0 * _S6) / 360.0, (-2.0 - 3.0 * _S6) / 225.0],
        [(16.0 - _S6) / 36.0, (16.0 + _S6) / 36.0, 1.0 / 9.0],
    ]
)
#: embedded error estimate: err = (gamma/h I - J)^-1 (f(t, y) + sum_s E_s Z_s / h)  (IV.8.20)
E = np.array([-13.0 - 7.0 * _S6, -13.0 + 7.0 * _S6, -1.0]) / 3.0


# The constants below are derived in decimal arithmetic of 50 significant digits (Python's
# `decimal`, exact software arithmetic) and rounded once to float64. LAPACK, which derived
# them before, gives results that differ by up to ~250 ulps between its CPU-specific kernels,
# and every simulated sample depends on them: computed this way they are the same bytes on
# every machine (docs/dataset.md §8).
_DIGITS = 50


def _dec_inverse(m: list[list[Decimal]]) -> list[list[Decimal]]:
    """Inverse of a small matrix by Gauss-Jordan elimination with partial pivoting."""
    n = len(m)
    a = [[*row, *(Decimal(int(i == j)) for j in range(n))] for i, row in enumerate(m)]
    for c in range(n):
        p = max(range(c, n), key=lambda r: abs(a[r][c]))
        a[c], a[p] = a[p], a[c]
        a[c] = [x / a[c][c] for x in a[c]]
        for r in range(n):
            if r != c:
                a[r] = [x - a[r][c] * y for x, y in zip(a[r], a[c], strict=True)]
    return [row[n:] for row in a]


def _dec_eigenvector(m, lam_re: Decimal, lam_im: Decimal) -> list[tuple[Decimal, Decimal]]:
    """The eigenvector (complex, as (re, im) pairs) of a 3x3 matrix ``m`` for the eigenvalue
    ``lam_re + i lam_im``, scaled to a last component of 1: rows 1-2 of (m - lam I) v = 0
    solved for v1, v2 by Cramer's rule."""

    def mul(x, y):
        return x[0] * y[0] - x[1] * y[1], x[0] * y[1] + x[1] * y[0]

    def sub(x, y):
        return x[0] - y[0], x[1] - y[1]

    def div(x, y):
        d = y[0] * y[0] + y[1] * y[1]
        return (x[0] * y[0] + x[1] * y[1]) / d, (x[1] * y[0] - x[0] * y[1]) / d

    zero = Decimal(0)
    a11, a12 = (m[0][0] - lam_re, -lam_im), (m[0][1], zero)
    a21, a22 = (m[1][0], zero), (m[1][1] - lam_re, -lam_im)
    r1, r2 = (-m[0][2], zero), (-m[1][2], zero)
    det = sub(mul(a11, a22), mul(a12, a21))
    return [
        div(sub(mul(r1, a22), mul(a12, r2)), det),
        div(sub(mul(a11, r2), mul(a21, r1)), det),
        (Decimal(1), zero),
    ]


def _constants():
    """gamma, mu = alpha - i beta, T, T^-1 and the dense-output matrix P.

    T^-1 A^-1 T = [[g,0,0],[0,a,b],[0,-b,a]]. The eigenvalues of A^-1 in closed form
    (Hairer & Wanner II, §IV.8: with s = 9^(1/3), 1/gamma = (6 + s(s - 1))/30 and
    1/(alpha + i beta) = ((12 - s(s - 1)) + i s(s + 1)sqrt(3))/60). Columns of T: the real
    eigenvector of A^-1 and the real and imaginary parts of the eigenvector of
    alpha + i beta (beta > 0), each scaled to a last component of 1, the scaling in which the
    Newton increments are measured (as in RADAU5). P: y(t + x h) = y + sum_k (Z^T P)_k x^(k+1),
    the collocation polynomial through (0, y) and (C_s, y + Z_s).
    """
    with localcontext() as ctx:
        ctx.prec = _DIGITS
        s6 = Decimal(6).sqrt()
        a = [
            [(88 - 7 * s6) / 360, (296 - 169 * s6) / 1800, (-2 + 3 * s6) / 225],
            [(296 + 169 * s6) / 1800, (88 + 7 * s6) / 360, (-2 - 3 * s6) / 225],
            [(16 - s6) / 36, (16 + s6) / 36, Decimal(1) / 9],
        ]
        ainv = _dec_inverse(a)
        s = Decimal(9) ** (Decimal(1) / 3)
        gamma = 30 / (6 + s * (s - 1))
        re, im = (12 - s * (s - 1)) / 60, s * (s + 1) * Decimal(3).sqrt() / 60
        alpha, beta = re / (re * re + im * im), im / (re * re + im * im)
        v = _dec_eigenvector(ainv, gamma, Decimal(0))
        w = _dec_eigenvector(ainv, alpha, beta)
        t = [[v[i][0], w[i][0], w[i][1]] for i in range(3)]
        c = [(4 - s6) / 10, (4 + s6) / 10, Decimal(1)]
        vander = [[ci, ci * ci, ci * ci * ci] for ci in c]
        p = [list(col) for col in zip(*_dec_inverse(vander), strict=True)]  # transposed

        def as_float(m):
            return np.array([[float(x) for x in row] for row in m])

        return (
            float(gamma),
            complex(float(alpha), -float(beta)),
            as_float(t),
            as_float(_dec_inverse(t)),
            as_float(p),
        )


GAMMA, MU, T, TI, P = _constants()

NEWTON_MAXITER = 6
MIN_FACTOR = 0.2
MAX_FACTOR = 10.0
EPS = float(np.finfo(float).eps)

#: status codes of :func:`integrate`
DONE, ROOT, FAIL_SMALL_STEP, FAIL_MAX_STEPS, FAIL_NONFINITE = 0, 1, 2, 3, 4
MESSAGES = {
    FAIL_SMALL_STEP: "Radau: step size below its minimum (the Newton iteration "
    "fails or the error test cannot be met)",
    FAIL_MAX_STEPS: "Radau: maximum number of steps reached",
    FAIL_NONFINITE: "Radau: the state or its derivative is not finite (nan or inf)",
}


# ---- powers without libm --------------------------------------------------------------------
# x ** 0.25 calls libm's pow, which glibc computes with CPU-specific code (FMA or not) that
# differs in the last bit for some arguments; the step sizes, and so every sample, would differ
# between machines. sqrt is exactly rounded by IEEE 754, and products are too.


@njit(cache=True)
def _root4(x):
    """x ** (1/4) for x >= 0, as two exactly rounded square roots."""
    return math.sqrt(math.sqrt(x))


@njit(cache=True)
def _ipow(x, k):
    """x ** k for an integer k >= 0, by repeated multiplication (k is at most 6 here)."""
    out = 1.0
    for _ in range(k):
        out *= x
    return out


# ---- banded LU with partial pivoting (real and complex) -----------------------------------
# Storage: a[i, j] of the n x n matrix at ab[j, i - j + ku2], ku2 = ku + kl (room for the
# fill-in that row interchanges create above the upper band). One row of ab holds one
# column's band, so every inner loop below runs over contiguous memory.
@njit(cache=True)
def band_lu(ab, piv, n, kl, ku2):
    """Factorise in place; return False if a pivot is exactly zero."""
    for j in range(n):
        last = min(n - 1, j + kl)
        p = j
        big = abs(ab[j, ku2])
        for i in range(j + 1, last + 1):
            v = abs(ab[j, i - j + ku2])
            if v > big:
                big = v
                p = i
        piv[j] = p
        if big == 0.0:
            return False
        cmax = min(n - 1, j + ku2)
        if p != j:
            for c in range(j, cmax + 1):
                a = ab[c, j - c + ku2]
                ab[c, j - c + ku2] = ab[c, p - c + ku2]
                ab[c, p - c + ku2] = a
        d = ab[j, ku2]
        for i in range(j + 1, last + 1):
            ab[j, i - j + ku2] /= d
        for c in range(j + 1, cmax + 1):
            ajc = ab[c, j - c + ku2]
            if ajc != 0.0:
                for i in range(j + 1, last + 1):
                    ab[c, i - c + ku2] -= ab[j, i - j + ku2] * ajc
    return True


@njit(cache=True)
def band_solve(ab, piv, b, n, kl, ku2):
    """Solve a x = b in place with the factors of :func:`band_lu`."""
    for j in range(n):
        p = piv[j]
        if p != j:
            x = b[j]
            b[j] = b[p]
            b[p] = x
        bj = b[j]
        if bj != 0.0:
            for i in range(j + 1, min(n - 1, j + kl) + 1):
                b[i] -= ab[j, i - j + ku2] * bj
    for j in range(n - 1, -1, -1):
        b[j] /= ab[j, ku2]
        bj = b[j]
        if bj != 0.0:
            for i in range(max(0, j - ku2), j):
                b[i] -= ab[j, i - j + ku2] * bj


@njit(cache=True)
def _fill_band(ab, rows, cols, vals, diag, ku2):
    """ab <- diag * I - J for the Jacobian values on the pattern."""
    ab[:, :] = 0.0
    for m in range(rows.shape[0]):
        ab[cols[m], rows[m] - cols[m] + ku2] -= vals[m]
    for j in range(ab.shape[0]):
        ab[j, ku2] += diag


@njit(cache=True)
def _rms(x, scale):
    s = 0.0
    for i in range(x.shape[0]):
        q = x[i] / scale[i]
        s += q * q
    return math.sqrt(s / x.shape[0])


@njit(cache=True)
def _dense(Q, y_old, x, out):
    """The step's collocation polynomial at x = (t - t_old) / h."""
    x2 = x * x
    x3 = x2 * x
    for i in range(out.shape[0]):
        out[i] = y_old[i] + Q[0, i] * x + Q[1, i] * x2 + Q[2, i] * x3


@njit(cache=True)
def _crossed(a, b):
    return (a < 0.0 and b >= 0.0) or (a > 0.0 and b <= 0.0)


@njit(cache=True)
def _any_crossed(active, g0, g):
    for m in range(g.shape[0]):
        if active[m] and _crossed(g0[m], g[m]):
            return True
    return False


def _kernel_stamp() -> int:
    """A hash of the sources the integrator compiles in (the line kernel, its phases, its
    layout: :func:`r2rsim.compile.stamp.kernel_stamp`).

    numba caches a compiled function under its own file's time stamp and its own bytecode:
    an edit of a kernel module alone would leave the cached integrator running the old
    right-hand side. A closure variable is part of numba's cache key, so the two functions
    that call the kernel are built in closures over this hash and compile again when the
    kernel changes.
    """
    return kernel_stamp()


def _build_initial_step(stamp):
    """The first-step estimate, compiled against the line kernel of hash ``stamp``."""

    @njit(cache=True)
    def _initial_step(t, y, f, f1, y1, df, scale, rtol, atol, interval, line):
        """First step (Hairer, Norsett & Wanner I, §II.4) for an error estimate of order 3."""
        _ = stamp  # part of numba's cache key: see _kernel_stamp
        I, Pl, W, GI, GC, GV, aux0, JJ, yd, J1 = line
        n = y.shape[0]
        for i in range(n):
            scale[i] = atol[i] + abs(y[i]) * rtol
        d0 = _rms(y, scale)
        d1 = _rms(f, scale)
        h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
        h0 = min(h0, interval)
        for i in range(n):
            y1[i] = y[i] + h0 * f[i]
        evaluate(t + h0, y1, f1, J1, RUNTIME_MODE[MODE_RHS], I, Pl, W, GI, GC, GV, aux0)
        for i in range(n):
            df[i] = f1[i] - f[i]
        d2 = _rms(df, scale) / h0
        if d1 <= 1e-15 and d2 <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = _root4(0.01 / max(d1, d2))
        return min(100.0 * h0, h1, interval)

    return _initial_step


_initial_step = _build_initial_step(_kernel_stamp())


def _build_integrate(stamp):
    """The integrator, compiled against the line kernel of hash ``stamp``."""

    @njit(cache=True)
    def integrate(
        t0,
        t_end,
        y0,
        tq,
        out,
        rtol,
        atol,
        max_steps,
        line,
        rows,
        cols,
        kl,
        ku,
        consts,
        g_start,
        y_root,
        dirs,
        vals,
        h_init,
        jac_ready,
        limits,
        aux_out,
    ):
        """Integrate the compiled line from ``(t0, y0)`` to ``t_end``.

        Parameters
        ----------
        t0, t_end : float
        y0 : ndarray (n,)
        tq : ndarray (m,)
            Sorted sample times in [t0, t_end]; ``out[k]`` receives the state at ``tq[k]``
            (interpolated with the collocation polynomial of the step that covers it).
        out : ndarray (m, n)
        rtol : float
        atol : ndarray (n,)
        max_steps : int
        line : tuple
            ``(I, P, W, GI, GC, GV, aux0, JJ, yd, J1)`` of the compiled line.
        rows, cols : ndarray
            The Jacobian pattern; ``kl``, ``ku`` its band widths.
        consts : tuple
            ``(C, E, T, TI, P, gamma, mu)`` of the method.
        g_start : ndarray (n_events,)
            Work array for the event functions (length 0: no event location).
        y_root, dirs : ndarray
            Outputs when an event function changes sign: the state at the event and, per event
            function, +1 (rising) / -1 (falling) / 0.
        vals : ndarray (n_pattern,)
            Jacobian values on the pattern (kept between calls).
        h_init : float
            First step to try; <= 0 estimates it. Continuing a smooth integration (a chunk
            boundary where nothing changes) passes the step the last call proposed.
        jac_ready : bool
            ``vals`` holds a recent Jacobian: reuse it (it is evaluated again if Newton fails).
        limits : ndarray (n,) of int64
            Incremented, for every accepted step, at the state with the largest scaled error
            (``|err_i| / scale_i``): the state that limits the step size.

        Returns
        -------
        status : int
            ``DONE``, ``ROOT`` or a ``FAIL_*`` code.
        t_reached : float
            ``t_end``, the event time, or where the integration failed.
        n_out : int
            Samples written.
        nfev, njev, nlu, nsteps : int
        h_next : float
            The step size proposed for the next step.
        """
        _ = stamp  # part of numba's cache key: see _kernel_stamp
        I, Pl, W, GI, GC, GV, aux0, JJ, yd, J1 = line
        Cn, En, Tm, TIm, Pm, gamma, mu = consts
        n = y0.shape[0]
        nev = g_start.shape[0]
        ku2 = ku + kl
        nb = 2 * kl + ku + 1
        ab_r = np.zeros((n, nb))
        ab_c = np.zeros((n, nb), np.complex128)
        piv_r = np.zeros(n, np.int64)
        piv_c = np.zeros(n, np.int64)
        y = y0.copy()
        f = np.empty(n)
        y_new = np.empty(n)
        f_new = np.empty(n)
        ytmp = np.empty(n)
        scale = np.empty(n)
        err = np.empty(n)
        ZE = np.empty(n)
        Z = np.zeros((3, n))
        Wn = np.zeros((3, n))
        F = np.empty((3, n))
        dW = np.empty((3, n))
        Q = np.zeros((3, n))
        Q_prev = np.zeros((3, n))
        y_prev = np.empty(n)
        rhs_c = np.empty(n, np.complex128)
        g_new = np.empty(nev)
        g_mid = np.empty(nev)
        active = np.zeros(nev, np.bool_)
        nfev = njev = nlu = nsteps = 0
        newton_tol = max(10.0 * EPS / rtol, min(0.03, math.sqrt(rtol)))

        t = t0
        rhs_mode = RUNTIME_MODE[MODE_RHS]  # an int64, not a literal: one compile of evaluate
        evaluate(t, y, f, J1, rhs_mode, I, Pl, W, GI, GC, GV, aux0)
        nfev += 1
        k_out = 0
        want_aux = aux_out.shape[1] > 0
        out_mode = RUNTIME_MODE[MODE_OUTPUTS]
        while k_out < tq.shape[0] and tq[k_out] <= t0:
            out[k_out, :] = y
            if want_aux:
                evaluate(
                    tq[k_out], out[k_out], yd, J1, out_mode, I, Pl, W, GI, GC, GV, aux_out[k_out]
                )
            k_out += 1
        for i in range(n):
            # nan compares false everywhere below: the step control would loop or accept it
            if not (math.isfinite(y[i]) and math.isfinite(f[i])):
                return FAIL_NONFINITE, t, k_out, nfev, njev, nlu, nsteps, 0.0
        if nev:
            event_values(t, y, g_start, I, Pl, W, GI, GC, GV, yd, J1)
            for m in range(nev):
                # a function exactly at 0 (the event just handled) counts once it leaves 0
                active[m] = g_start[m] != 0.0
        interval = t_end - t0
        if interval <= 0.0:
            return DONE, t, k_out, nfev, njev, nlu, nsteps, h_init

        if h_init > 0.0:
            h_abs = min(h_init, interval)
        else:
            h_abs = _initial_step(t, y, f, f_new, ytmp, err, scale, rtol, atol, interval, line)
            nfev += 1
        if jac_ready:
            current_jac = False
        else:
            jac_values(t, y, JJ, I, Pl, W, GI, GC, GV, yd, vals)
            njev += 1
            current_jac = True
        lu_valid = False
        h_abs_old = -1.0
        err_old = -1.0
        have_prev = False
        t_prev = 0.0
        h_prev = 1.0
        h = h_abs
        h_next = h_abs
        t_new = t
        n_iter = 0
        rate = -1.0

        while t < t_end:
            min_step = 10.0 * EPS * max(abs(t), 1e-300)
            rejected = False
            accepted = False
            err_norm = 0.0
            safety = 0.9
            while not accepted:
                if not h_abs >= min_step:  # also a nan step
                    return FAIL_SMALL_STEP, t, k_out, nfev, njev, nlu, nsteps, h_abs
                t_new = t + h_abs
                if t_new > t_end:
                    t_new = t_end
                h = t_new - t
                h_abs = h
                # starting values: the previous step's collocation polynomial, extrapolated
                if have_prev:
                    for s in range(3):
                        x = (t + Cn[s] * h - t_prev) / h_prev
                        _dense(Q_prev, y_prev, x, ytmp)
                        for i in range(n):
                            Z[s, i] = ytmp[i] - y[i]
                else:
                    Z[:, :] = 0.0
                for i in range(n):
                    scale[i] = atol[i] + abs(y[i]) * rtol
                converged = False
                while not converged:
                    if not lu_valid:
                        _fill_band(ab_r, rows, cols, vals, gamma / h, ku2)
                        _fill_band(ab_c, rows, cols, vals, mu / h, ku2)
                        nlu += 1
                        if not (
                            band_lu(ab_r, piv_r, n, kl, ku2) and band_lu(ab_c, piv_c, n, kl, ku2)
                        ):
                            break
                        lu_valid = True
                    # simplified Newton iteration on the transformed collocation system
                    for s in range(3):
                        for i in range(n):
                            Wn[s, i] = (
                                TIm[s, 0] * Z[0, i] + TIm[s, 1] * Z[1, i] + TIm[s, 2] * Z[2, i]
                            )
                    dW_norm_old = -1.0
                    rate = -1.0
                    finite = True
                    for k in range(NEWTON_MAXITER):
                        n_iter = k + 1
                        for s in range(3):
                            for i in range(n):
                                ytmp[i] = y[i] + Z[s, i]
                            evaluate(
                                t + Cn[s] * h, ytmp, F[s], J1, rhs_mode, I, Pl, W, GI, GC, GV, aux0
                            )
                            nfev += 1
                        for i in range(n):
                            fr = TIm[0, 0] * F[0, i] + TIm[0, 1] * F[1, i] + TIm[0, 2] * F[2, i]
                            f1 = TIm[1, 0] * F[0, i] + TIm[1, 1] * F[1, i] + TIm[1, 2] * F[2, i]
                            f2 = TIm[2, 0] * F[0, i] + TIm[2, 1] * F[1, i] + TIm[2, 2] * F[2, i]
                            if not (math.isfinite(fr) and math.isfinite(f1) and math.isfinite(f2)):
                                finite = False
                            dW[0, i] = fr - gamma / h * Wn[0, i]
                            rhs_c[i] = complex(f1, f2) - mu / h * complex(Wn[1, i], Wn[2, i])
                        if not finite:
                            break
                        band_solve(ab_r, piv_r, dW[0], n, kl, ku2)
                        band_solve(ab_c, piv_c, rhs_c, n, kl, ku2)
                        s2 = 0.0
                        for i in range(n):
                            dW[1, i] = rhs_c[i].real
                            dW[2, i] = rhs_c[i].imag
                            for s in range(3):
                                q = dW[s, i] / scale[i]
                                s2 += q * q
                        dW_norm = math.sqrt(s2 / (3 * n))
                        if dW_norm_old >= 0.0:
                            rate = dW_norm / dW_norm_old
                        if rate >= 0.0 and (
                            rate >= 1.0
                            or _ipow(rate, NEWTON_MAXITER - k) / (1.0 - rate) * dW_norm > newton_tol
                        ):
                            break
                        for s in range(3):
                            for i in range(n):
                                Wn[s, i] += dW[s, i]
                        for s in range(3):
                            for i in range(n):
                                Z[s, i] = (
                                    Tm[s, 0] * Wn[0, i] + Tm[s, 1] * Wn[1, i] + Tm[s, 2] * Wn[2, i]
                                )
                        if dW_norm == 0.0 or (
                            rate >= 0.0 and rate / (1.0 - rate) * dW_norm < newton_tol
                        ):
                            converged = True
                            break
                        dW_norm_old = dW_norm
                    if not converged:
                        if current_jac:
                            break
                        jac_values(t, y, JJ, I, Pl, W, GI, GC, GV, yd, vals)
                        njev += 1
                        current_jac = True
                        lu_valid = False
                if not converged:
                    h_abs *= 0.5
                    lu_valid = False
                    continue
                # error estimate
                for i in range(n):
                    y_new[i] = y[i] + Z[2, i]
                    ZE[i] = (En[0] * Z[0, i] + En[1] * Z[1, i] + En[2] * Z[2, i]) / h
                    err[i] = f[i] + ZE[i]
                    scale[i] = atol[i] + max(abs(y[i]), abs(y_new[i])) * rtol
                band_solve(ab_r, piv_r, err, n, kl, ku2)
                err_norm = _rms(err, scale)
                safety = 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + n_iter)
                if rejected and err_norm > 1.0:
                    # after a rejection: one more smoothing of the estimate (IV.8, p. 124)
                    for i in range(n):
                        ytmp[i] = y[i] + err[i]
                    evaluate(t, ytmp, err, J1, rhs_mode, I, Pl, W, GI, GC, GV, aux0)
                    nfev += 1
                    for i in range(n):
                        err[i] += ZE[i]
                    band_solve(ab_r, piv_r, err, n, kl, ku2)
                    err_norm = _rms(err, scale)
                if not math.isfinite(err_norm):
                    h_abs *= MIN_FACTOR
                    lu_valid = False
                    rejected = True
                elif err_norm > 1.0:
                    h_abs *= max(MIN_FACTOR, safety * _predict(h_abs, h_abs_old, err_norm, err_old))
                    lu_valid = False
                    rejected = True
                else:
                    accepted = True

            nsteps += 1
            i_lim = 0
            for i in range(n):
                if abs(err[i]) / scale[i] > abs(err[i_lim]) / scale[i_lim]:
                    i_lim = i
            limits[i_lim] += 1
            recompute_jac = n_iter > 2 and rate > 1e-3
            factor = min(MAX_FACTOR, safety * _predict(h_abs, h_abs_old, err_norm, err_old))
            if not recompute_jac and factor < 1.2:
                factor = 1.0
            else:
                lu_valid = False
            evaluate(t_new, y_new, f_new, J1, rhs_mode, I, Pl, W, GI, GC, GV, aux0)
            nfev += 1
            if nev:  # from what that evaluation left in W, before a Jacobian overwrites it
                event_values_after_rhs(t_new, y_new, g_new, I, Pl, W)
            if recompute_jac:
                jac_values(t_new, y_new, JJ, I, Pl, W, GI, GC, GV, yd, vals)
                njev += 1
                current_jac = True
            else:
                current_jac = False
            h_abs_old = h_abs
            err_old = err_norm
            for k in range(3):
                for i in range(n):
                    Q[k, i] = Pm[0, k] * Z[0, i] + Pm[1, k] * Z[1, i] + Pm[2, k] * Z[2, i]

            # events: a sign change of an active event function over the step, located by
            # bisection on the collocation polynomial to CVODE's time tolerance
            if nev:
                if _any_crossed(active, g_start, g_new):
                    tl, tr = t, t_new
                    ttol = 100.0 * EPS * (abs(t_new) + h)
                    g_r = g_new.copy()
                    while tr - tl > ttol:
                        tm = 0.5 * (tl + tr)
                        _dense(Q, y, (tm - t) / h, ytmp)
                        event_values(tm, ytmp, g_mid, I, Pl, W, GI, GC, GV, yd, J1)
                        if _any_crossed(active, g_start, g_mid):
                            tr = tm
                            g_r[:] = g_mid
                        else:
                            tl = tm
                    _dense(Q, y, (tr - t) / h, y_root)
                    for m in range(nev):
                        dirs[m] = 0
                        if active[m] and _crossed(g_start[m], g_r[m]):
                            dirs[m] = 1 if g_r[m] > g_start[m] else -1
                    while k_out < tq.shape[0] and tq[k_out] <= tr:
                        _dense(Q, y, (tq[k_out] - t) / h, out[k_out])
                        if want_aux:
                            evaluate(
                                tq[k_out], out[k_out], yd, J1, out_mode, I, Pl, W, GI, GC, GV,
                                aux_out[k_out],
                            )  # fmt: skip
                        k_out += 1
                    return ROOT, tr, k_out, nfev, njev, nlu, nsteps, h_abs
                for m in range(nev):
                    if not active[m] and g_new[m] != 0.0:
                        active[m] = True
                    g_start[m] = g_new[m]

            # samples covered by this step
            while k_out < tq.shape[0] and tq[k_out] <= t_new:
                _dense(Q, y, (tq[k_out] - t) / h, out[k_out])
                if want_aux:
                    evaluate(
                        tq[k_out], out[k_out], yd, J1, out_mode, I, Pl, W, GI, GC, GV,
                        aux_out[k_out],
                    )  # fmt: skip
                k_out += 1

            Q_prev[:, :] = Q
            y_prev[:] = y
            t_prev = t
            h_prev = h
            have_prev = True
            t = t_new
            y[:] = y_new
            f[:] = f_new
            h_abs *= factor
            if t_new < t_end:
                h_next = h_abs  # the last step may be clipped to t_end: keep the unclipped one
            if nsteps >= max_steps:
                return FAIL_MAX_STEPS, t, k_out, nfev, njev, nlu, nsteps, h_abs
        return DONE, t, k_out, nfev, njev, nlu, nsteps, h_next

    return integrate


integrate = _build_integrate(_kernel_stamp())


@njit(cache=True)
def _predict(h_abs, h_abs_old, err_norm, err_old):
    """Step-size factor of Gustafsson's predictive controller (IV.8.25), before safety."""
    if err_norm == 0.0:
        return 1e300
    if err_old < 0.0 or h_abs_old < 0.0:
        multiplier = 1.0
    else:
        multiplier = h_abs / h_abs_old * _root4(err_old / err_norm)
    return min(1.0, multiplier) / _root4(err_norm)


CONSTS = (C, E, T, TI, P, GAMMA, MU)
