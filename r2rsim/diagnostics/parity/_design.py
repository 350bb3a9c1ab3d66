"""Robust min-max parity coefficients (thesis eqs. 3.14-3.15) and their post-optimal KKT
sensitivity (eqs. 3.16-3.23).

The design problem for one relation ω (a row of Ω^⊥), over design scenarios c with
mean-square matrices S_c of the model errors (operating points × parameter corners):

    minimise_ω  max_c ω S_c ωᵀ   subject to  ω N(p) = 0   (null space, eq. 3.8)
                                            ω F = 1      (fault-normalised, the default)
                                       or  ω ωᵀ = 1     (unit norm, the thesis's choice)

It is solved in epigraph form (variables ω, t; ω S_c ωᵀ ≤ t) with SLSQP and polished by
Newton's method on its KKT conditions with the active scenarios fixed, which gives the
multipliers (eq. 3.23) and the sensitivities dJ/dp and dω/dp (eqs. 3.20-3.22).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
from scipy.optimize import LinearConstraint, NonlinearConstraint, minimize

from ...errors import InputError

KINDS = ("fault_normalised", "unit_norm")


@dataclass
class Design:
    """A solved min-max relation.

    Attributes
    ----------
    omega : ndarray (n,)
        The coefficients.
    J : float
        max_c ω S_c ωᵀ at the optimum.
    active : ndarray of int
        The scenarios attaining the max.
    mu, nu, eta : ndarray
        Multipliers of the active scenarios, the null-space and the normalisation
        constraints.
    """

    omega: np.ndarray
    J: float
    active: np.ndarray
    mu: np.ndarray
    nu: np.ndarray
    eta: np.ndarray
    #: signs s of the fault normalisation ω F = s (None for unit norm)
    signs: np.ndarray | None = None


def _check(S, N, F, kind):
    S = np.asarray(S, float)
    if S.ndim == 2:
        S = S[None]
    N = np.asarray(N, float).reshape(S.shape[1], -1)
    if kind not in KINDS:
        raise InputError(f"design must be one of {', '.join(KINDS)}, got {kind!r}")
    if kind == "fault_normalised":
        if F is None:
            raise InputError("the fault-normalised design needs fault directions F")
        F = np.asarray(F, float).reshape(S.shape[1], -1)
    return S, N, F


def _start(S, N, F, kind):
    """The minimiser of the average S under the equality constraints (an eigen or a linear
    problem): a feasible start for SLSQP."""
    n = S.shape[1]
    Sbar = S.mean(axis=0)
    if kind == "unit_norm":
        from scipy.linalg import null_space

        Z = null_space(N.T)
        w, V = np.linalg.eigh(Z.T @ Sbar @ Z)
        return Z @ V[:, 0]
    # min ω S̄ ωᵀ s.t. [N F]ᵀ ω = [0 1]: a KKT linear system
    A = np.hstack([N, F])
    b = np.concatenate([np.zeros(N.shape[1]), np.ones(F.shape[1])])
    K = np.block([[2 * Sbar, A], [A.T, np.zeros((A.shape[1], A.shape[1]))]])
    sol = np.linalg.lstsq(K, np.concatenate([np.zeros(n), b]), rcond=None)[0]
    return sol[:n]


def design_relation(
    S,
    N,
    F=None,
    kind: str = "fault_normalised",
    solver: str = "slsqp",
    start=None,
    polish: bool = True,
    signs=None,
) -> Design:
    """Min-max coefficients of one parity relation.

    Parameters
    ----------
    S : array (K, n, n) or (n, n)
        Mean-square matrices of the model errors, one per design scenario.
    N : array (n, q)
        ∇_x O_NL at the design point: the relation must annihilate its columns.
    F : array (n, r), optional
        Fault directions (one column per fault, e.g. a unit offset on a sensor as seen in
        the stack); required for ``kind="fault_normalised"``, which sets ω F = s, |s_k| = 1
        (the sign pattern with the lowest optimum).
    kind : {"fault_normalised", "unit_norm"}
    solver : {"slsqp", "trust-constr"}
        Two independent formulations of the epigraph problem (to check one against the
        other).
    start : array (n,), optional
        A warm start (e.g. the previous solution when re-solving along data).
    polish : bool
        Newton on the KKT conditions after the solver (machine-precision ω, multipliers).
    signs : array (r,), optional
        Fix the signs of ω F = s (e.g. those chosen at the design point, when re-solving
        along data) instead of choosing them.

    Returns
    -------
    Design
    """
    S, N, F = _check(S, N, F, kind)
    if kind == "fault_normalised" and signs is not None:
        d = _solve(S, N, F * np.asarray(signs, float), kind, solver, start, polish)
        d.signs = np.asarray(signs, float)
        return d
    if kind == "fault_normalised" and F.shape[1] > 1:
        best = None
        for tail in itertools.product((1.0, -1.0), repeat=F.shape[1] - 1):
            signs = np.array([1.0, *tail])
            d = _solve(S, N, F * signs, kind, solver, start, polish)
            d.signs = signs
            if best is None or d.J < best.J:
                best = d
        return best
    return _solve(S, N, F, kind, solver, start, polish)


def _solve(S, N, F, kind, solver, start, polish) -> Design:
    n = S.shape[1]
    w0 = _start(S, N, F, kind) if start is None else np.asarray(start, float)
    z0 = np.append(w0, max(float(w0 @ s @ w0) for s in S))
    if kind == "unit_norm":
        eq_fun = lambda z: np.concatenate([N.T @ z[:n], [z[:n] @ z[:n] - 1.0]])  # noqa: E731
    else:
        eq_fun = lambda z: np.concatenate([N.T @ z[:n], F.T @ z[:n] - 1.0])  # noqa: E731
    ineq = lambda z: np.array([z[n] - z[:n] @ s @ z[:n] for s in S])  # noqa: E731
    if solver == "slsqp":
        res = minimize(
            lambda z: z[n],
            z0,
            jac=lambda z: np.eye(n + 1)[n],
            method="SLSQP",
            constraints=[{"type": "eq", "fun": eq_fun}, {"type": "ineq", "fun": ineq}],
            options={"ftol": 1e-15, "maxiter": 500},
        )
    elif solver == "trust-constr":
        # exact derivatives: quasi-Newton updates of linear parts warn and lose accuracy
        def ineq_jac(z):
            return np.column_stack([-2 * S @ z[:n], np.ones(len(S))])

        def ineq_hess(z, v):
            H = np.zeros((n + 1, n + 1))
            H[:n, :n] = -2 * np.tensordot(v, S, axes=1)
            return H

        cons = [NonlinearConstraint(ineq, 0.0, np.inf, jac=ineq_jac, hess=ineq_hess)]
        if kind == "unit_norm":

            def eq_jac(z):
                return np.vstack(
                    [np.hstack([N.T, np.zeros((N.shape[1], 1))]), np.append(2 * z[:n], 0.0)]
                )

            def eq_hess(z, v):
                H = np.zeros((n + 1, n + 1))
                H[:n, :n] = 2 * v[-1] * np.eye(n)
                return H

            cons.append(NonlinearConstraint(eq_fun, 0.0, 0.0, jac=eq_jac, hess=eq_hess))
        else:
            A = np.hstack([np.hstack([N, F]).T, np.zeros((N.shape[1] + F.shape[1], 1))])
            b = np.concatenate([np.zeros(N.shape[1]), np.ones(F.shape[1])])
            cons.append(LinearConstraint(A, b, b))
        res = minimize(
            lambda z: z[n],
            z0,
            jac=lambda z: np.eye(n + 1)[n],
            hess=lambda z: np.zeros((n + 1, n + 1)),
            method="trust-constr",
            constraints=cons,
            options={"gtol": 1e-13, "xtol": 1e-15, "maxiter": 5000},
        )
    else:
        raise InputError(f"solver must be 'slsqp' or 'trust-constr', got {solver!r}")
    w = res.x[:n]
    if kind == "unit_norm":
        w = w / np.linalg.norm(w) * np.sign(w[np.argmax(np.abs(w))])
    d = _multipliers(w, S, N, F, kind)
    d = _polish(d, S, N, F, kind) if polish else d
    d.signs = np.ones(F.shape[1]) if kind == "fault_normalised" else None
    return d


def _multipliers(w, S, N, F, kind, tol: float = 1e-7) -> Design:
    """Active scenarios and the multipliers from stationarity (eq. 3.23), by least squares
    with Σμ = 1; scenarios with a negative multiplier leave the active set."""
    vals = np.array([w @ s @ w for s in S])
    J = vals.max()
    active = np.flatnonzero(vals >= J - tol * max(abs(J), 1e-300))
    while True:
        Fn = F if kind == "fault_normalised" else w[:, None]
        cols = [2 * S[a] @ w for a in active]
        A = np.vstack(
            [
                np.column_stack([*cols, N, (2 if kind == "unit_norm" else 1) * Fn]),
                np.concatenate([np.ones(len(active)), np.zeros(N.shape[1] + Fn.shape[1])]),
            ]
        )
        rhs = np.zeros(A.shape[0])
        rhs[-1] = 1.0
        lam = np.linalg.lstsq(A, rhs, rcond=None)[0]
        mu = lam[: len(active)]
        if len(active) > 1 and mu.min() < 0:
            active = np.delete(active, np.argmin(mu))
            continue
        nu = lam[len(active) : len(active) + N.shape[1]]
        eta = lam[len(active) + N.shape[1] :]
        return Design(w, float(J), active, mu, nu, eta)


def _kkt(d: Design, S, N, F, kind):
    """The KKT residual G(w) and its Jacobian G_w for w = (ω, t, μ_A, ν, η)."""
    n, a, q = len(d.omega), len(d.active), N.shape[1]
    r = F.shape[1] if kind == "fault_normalised" else 1
    w, t = d.omega, d.J
    SA = S[d.active]
    M = 2 * np.tensordot(d.mu, SA, axes=1)  # 2 Σ μ_a S_a
    norm_col = F if kind == "fault_normalised" else 2 * w[:, None]
    G = np.concatenate(
        [
            M @ w + N @ d.nu + norm_col @ d.eta,
            [1.0 - d.mu.sum()],
            [w @ s @ w - t for s in SA],
            N.T @ w,
            F.T @ w - 1.0 if kind == "fault_normalised" else [w @ w - 1.0],
        ]
    )
    size = n + 1 + a + q + r
    J = np.zeros((size, size))
    iw, it, imu = slice(0, n), n, slice(n + 1, n + 1 + a)
    inu, ieta = slice(n + 1 + a, n + 1 + a + q), slice(n + 1 + a + q, size)
    J[iw, iw] = M + (2 * d.eta[0] * np.eye(n) if kind == "unit_norm" else 0.0)
    J[iw, imu] = np.column_stack([2 * s @ w for s in SA])
    J[iw, inu] = N
    J[iw, ieta] = norm_col
    J[it, imu] = -1.0
    J[imu, iw] = np.vstack([2 * s @ w for s in SA])
    J[imu, it] = -1.0
    J[inu, iw] = N.T
    J[ieta, iw] = F.T if kind == "fault_normalised" else 2 * w[None, :]
    return G, J


def _unpack(d: Design, z) -> Design:
    n, a, q = len(d.omega), len(d.active), len(d.nu)
    return Design(
        z[:n],
        float(z[n]),
        d.active,
        z[n + 1 : n + 1 + a],
        z[n + 1 + a : n + 1 + a + q],
        z[n + 1 + a + q :],
    )


def _pack(d: Design) -> np.ndarray:
    return np.concatenate([d.omega, [d.J], d.mu, d.nu, d.eta])


def _polish(d: Design, S, N, F, kind, steps: int = 8) -> Design:
    """Newton on the KKT conditions with the active set fixed."""
    for _ in range(steps):
        G, Jw = _kkt(d, S, N, F, kind)
        if np.max(np.abs(G)) < 1e-15 * max(1.0, abs(d.J)):
            break
        d = _unpack(d, _pack(d) - np.linalg.lstsq(Jw, G, rcond=None)[0])
    return d


def sensitivity(d: Design, S, N, F, dN, kind: str = "fault_normalised"):
    """Post-optimal sensitivity of a solved design to the point p (eqs. 3.16-3.22).

    Parameters
    ----------
    d : Design
        A polished solution.
    S, N, F, kind
        As for :func:`design_relation`.
    dN : array (P, n, q)
        ∂N/∂p_k for each parameter p_k (``NonlinearModel.grad_xp``, scaled like N).

    Returns
    -------
    dJ : ndarray (P,)
        dJ/dp from the KKT system (3.20), the chain of eq. 3.21.
    domega : ndarray (P, n)
        dω/dp (eq. 3.22).
    dJ_envelope : ndarray (P,)
        dJ/dp = ω (∂N/∂p) ν, the envelope theorem: a check of ``dJ``.
    """
    S, N, F = _check(S, N, F, kind)
    if d.signs is not None:
        F = F * d.signs
    _, Jw = _kkt(d, S, N, F, kind)
    n, a = len(d.omega), len(d.active)
    dJ, dom, env = [], [], []
    for dNk in np.asarray(dN, float):
        dNk = dNk.reshape(N.shape)
        # ∂G/∂p_k: N enters the stationarity (N ν) and the null-space rows (Nᵀ ω)
        Gp = np.zeros(Jw.shape[0])
        Gp[:n] = dNk @ d.nu
        Gp[n + 1 + a : n + 1 + a + N.shape[1]] = dNk.T @ d.omega
        dz = -np.linalg.solve(Jw, Gp)
        dom.append(dz[:n])
        dJ.append(dz[n])
        env.append(d.omega @ dNk @ d.nu)
    return np.array(dJ), np.array(dom), np.array(env)
