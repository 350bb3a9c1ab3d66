"""Local parity relations of one map node (thesis eqs. 4.11-4.15, 4.21-4.23).

A relation is a vector Ω (one column of ``omega``) with an intercept b: the residual of a
sample z is ``P = z·Ω + b``. A node fits its relations to all samples with weights (the
topological neighbourhood of eq. 4.11) by minimising the penalised parity loss

    J(Ω) = Σ w_i (z_i·Ω + b)² / Σ w_i + λ1 (Ω·Ω − 1)² + λ2 ‖Gᵀ Ω‖²      (4.21)

Before (4.21) a node's data are divided by √tr C_w, the root of its total weighted variance,
so that λ1 and the step size mean the same in a tight regime as in a wide one (in globally
standardised units a regime can be a hundred times tighter than the pooled data, and the
penalty would then swamp the data term); :func:`objective` and the oracles use the same
scaling. The intercept is the exact minimiser b = −μ_w·Ω (μ_w the weighted mean): the
thesis's P is uncentred, so without it the loss would mix each regime's level into the
relation. Several unit-norm relations are fitted one after the other, each orthogonal to the
previous ones (deflation); fault-normalised relations (one per fault direction, the plug-in's
default) are fitted independently.

Solvers: mini-batch SGD (the thesis's, batch 128), single-sample SGD, full-batch gradient
descent, and the exact oracle: the smallest eigenvectors of the weighted covariance within
the null space of ``G`` (and of the previous relations), scaled to the penalised optimum
‖Ω‖² = 1 − λ/(2 λ1). ``G`` is the λ2 term's ∇_x O_NL (eq. 4.21): the gradient solvers
penalise λ2‖GᵀΩ‖², the oracles impose GᵀΩ = 0 (the limit λ2 → ∞). The plug-in takes ``G``
from the parity plug-in's reduced model (:mod:`r2rsim.diagnostics.parity`).
"""

from __future__ import annotations

import numpy as np
from scipy import linalg

SOLVERS = ("minibatch", "sgd", "batch", "eigh")
STEPS = ("inv_sqrt", "inv_sq")


def weighted_moments(Z: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean and (biased) covariance of the rows of Z, the covariance divided by its
    trace (the node scaling of the module docstring)."""
    w = np.asarray(w, float)
    mu = w @ Z / w.sum()
    D = Z - mu
    C = (D * w[:, None]).T @ D / w.sum()
    tr = float(np.trace(C))
    return mu, C / tr if tr > 0 else C


def _node_scale(D: np.ndarray, w: np.ndarray) -> float:
    tr = float(w @ np.sum(D**2, axis=1) / w.sum())
    return np.sqrt(tr) if tr > 0 else 1.0


def objective(
    omega: np.ndarray,
    Z: np.ndarray,
    w: np.ndarray,
    lambda1: float = 1.0,
    lambda2: float = 0.0,
    G: np.ndarray | None = None,
    fault_normalised: bool = False,
) -> float:
    """The penalised loss (4.21) of the relations ``omega`` (columns), summed over them, with
    each relation's optimal intercept (without the unit-norm penalty when the relations are
    fault-normalised: their scale is fixed by Ω·f = 1)."""
    _, C = weighted_moments(Z, w)
    omega = omega.reshape(len(C), -1)
    total = 0.0
    for om in omega.T:
        total += om @ C @ om
        if not fault_normalised:
            total += lambda1 * (om @ om - 1.0) ** 2
        if G is not None and lambda2:
            total += lambda2 * float(np.sum((G.T @ om) ** 2))
    return float(total)


def _penalised_scale(eigval: float, lambda1: float) -> float:
    """‖Ω‖ at the minimum of λ r² + λ1 (r² − 1)² over r ≥ 0."""
    return float(np.sqrt(max(0.0, 1.0 - eigval / (2.0 * lambda1))))


def oracle_relations(
    Z: np.ndarray,
    w: np.ndarray,
    n_relations: int = 1,
    lambda1: float = 1.0,
    G: np.ndarray | None = None,
) -> np.ndarray:
    """The exact minimisers of (4.21): the ``n_relations`` smallest eigenvectors of the
    weighted covariance restricted to the null space of ``Gᵀ`` (a hard constraint), each
    scaled to the penalised optimum. Returns a (q, n_relations) array."""
    _, C = weighted_moments(Z, w)
    q = len(C)
    N = np.eye(q) if G is None else linalg.null_space(np.asarray(G, float).reshape(q, -1).T)
    if N.shape[1] < n_relations:
        raise ValueError(
            f"the constraint leaves {N.shape[1]} dimensions for {n_relations} relations"
        )
    vals, vecs = linalg.eigh(N.T @ C @ N)
    omega = N @ vecs[:, :n_relations]
    for k in range(n_relations):
        v = omega[:, k]
        v = v * np.sign(v[np.argmax(np.abs(v))])  # a fixed sign: comparable across fits
        omega[:, k] = v * _penalised_scale(vals[k], lambda1)
    return omega


def fault_normalised_oracle(
    Z: np.ndarray, w: np.ndarray, F: np.ndarray, G: np.ndarray | None = None
) -> np.ndarray:
    """The exact minimum-variance relations with unit response to each fault direction:
    Ω_j = C⁺f_j / (f_jᵀ C⁺ f_j) minimises Ωᵀ C Ω subject to f_j·Ω = 1. With ``G`` the
    relations also satisfy GᵀΩ = 0 (Ω = N·a over a basis N of that null space, the same
    formula for NᵀCN and Nᵀf_j). Returns (q, k).

    A fault direction with a component that the node's data never move (a channel constant
    in the node) gets a zero-variance relation along that component instead: the limit of
    the formula, which C⁺ alone would turn into 0/0.

    Raises
    ------
    ValueError
        When a fault direction has no component in the null space of Gᵀ: such a fault
        looks like a change of the state, and no relation of that space can see it.
    """
    _, C = weighted_moments(Z, w)
    q = len(C)
    N = np.eye(q) if G is None else linalg.null_space(np.asarray(G, float).reshape(q, -1).T)
    vals, vecs = linalg.eigh(N.T @ C @ N)
    still = vals <= 1e-12 * max(float(vals.max(initial=0.0)), 1e-300)
    M = (vecs[:, ~still] / vals[~still]) @ vecs[:, ~still].T  # the pseudo-inverse
    V0 = vecs[:, still]  # directions the node's data never move (a constant channel)
    F = np.asarray(F, float).reshape(q, -1)
    out = []
    for f in F.T:
        g = N.T @ f
        if g @ g <= 1e-24 * max(f @ f, 1e-300):
            raise ValueError(
                "a fault direction lies in the span of the constraint G: no "
                "relation that cancels the state can see it"
            )
        h = V0 @ (V0.T @ g)
        if h @ h > 1e-12 * (g @ g):  # a zero-variance relation with h·g = h·h > 0 exists
            out.append(N @ h / (g @ h))
        else:  # C⁺f/(fᵀC⁺f) (with a constant channel C⁺f alone would be 0/0)
            out.append(N @ (M @ g) / (g @ M @ g))
    return np.column_stack(out)


def _gradient(om, D, lambda1, lambda2, G):
    """Gradient of the loss at Ω for the centred rows D (equal weights within D)."""
    r = D @ om
    g = 2.0 * (r @ D) / len(D) + 4.0 * lambda1 * (om @ om - 1.0) * om
    if G is not None and lambda2:
        g = g + 2.0 * lambda2 * (G @ (G.T @ om))
    return g


def sgd_relation(
    D: np.ndarray,
    w: np.ndarray,
    *,
    solver: str = "minibatch",
    batch_size: int = 128,
    n_epochs: float = 1.0,
    batch_iter: int = 2000,
    eta0: float = 1.0,
    min_steps: int = 3000,
    step: str = "inv_sqrt",
    lambda1: float = 1.0,
    lambda2: float = 0.0,
    G: np.ndarray | None = None,
    previous: np.ndarray | None = None,
    fault: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """One relation of the centred rows ``D`` by a gradient method (see :data:`SOLVERS`).

    Mini-batches are drawn with probabilities ∝ ``w`` (importance sampling, so every step
    is an unbiased estimate of the weighted gradient at a cost independent of how many
    samples have negligible weight); ``n_epochs`` counts passes' worth of samples, at least
    ``min_steps`` steps (full-batch
    gradient descent takes ``batch_iter`` steps, each a pass over all samples). The step
    at iteration idx is η0/√idx (default) or η0/idx² (``inv_sq``, eq. 4.15 as printed),
    divided by L = 1 + 4 λ1 (half a bound on the loss's curvature with tr C = 1), so η0 < 1
    is stable.
    After each step Ω is projected orthogonal to the ``previous`` relations. With a
    ``fault`` direction f the relation is fault-normalised instead: it starts at f/‖f‖², the
    unit-norm penalty is dropped and each step is projected on f·Ω = 1.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    n, q = D.shape
    w = np.asarray(w, float)
    D = D / _node_scale(D, w)
    P = None
    if previous is not None and previous.size:
        Q, _ = np.linalg.qr(previous)
        P = np.eye(q) - Q @ Q.T
    if fault is not None:
        lambda1 = 0.0
        fault = np.asarray(fault, float)
        P = np.eye(q) - np.outer(fault, fault) / (fault @ fault)  # keeps f·Ω fixed
        om = fault / (fault @ fault)
    else:
        om = rng.standard_normal(q)
        om = om if P is None else P @ om
        om /= np.linalg.norm(om)
    if solver == "batch":
        Dw = D * np.sqrt(w / w.mean())[:, None]  # full gradient of the weighted mean
        n_iter, size = max(1, int(batch_iter)), None
    else:
        size = 1 if solver == "sgd" else batch_size
        n_iter = max(min_steps, int(np.ceil(n_epochs * n / size)))
        cdf = np.cumsum(w, dtype=float)
        cdf /= cdf[-1]
        draws = np.minimum(np.searchsorted(cdf, rng.random(n_iter * size)), n - 1)
    scale = 1.0 + 4.0 * lambda1  # tr C = 1 after the node scaling
    if G is not None and lambda2:
        scale += lambda2 * float(np.sum(np.asarray(G) ** 2))
    for idx in range(1, n_iter + 1):
        eta = (eta0 / np.sqrt(idx) if step == "inv_sqrt" else eta0 / idx**2) / scale
        batch = Dw if size is None else D[draws[(idx - 1) * size : idx * size]]
        g = _gradient(om, batch, lambda1, lambda2, G)
        om = om - eta * (g if P is None else P @ g)
    return om if fault is not None else om * np.sign(om[np.argmax(np.abs(om))])


def fit_relations(
    Z: np.ndarray,
    w: np.ndarray,
    n_relations: int = 1,
    *,
    solver: str = "minibatch",
    lambda1: float = 1.0,
    lambda2: float = 0.0,
    G: np.ndarray | None = None,
    F: np.ndarray | None = None,
    rng: np.random.Generator | None = None,
    **sgd,
) -> tuple[np.ndarray, np.ndarray]:
    """Fit a node's relations to the rows of Z with weights w: ``n_relations`` unit-norm
    ones, or, when fault directions ``F`` (q, k) are given, one fault-normalised relation per
    column of F (``n_relations`` is then ignored).

    Returns
    -------
    omega : ndarray, shape (q, n_relations)
    intercept : ndarray, shape (n_relations,)
        b = −μ_w·Ω, so the weighted mean residual is zero.
    """
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    w = np.asarray(w, float)
    mu, _ = weighted_moments(Z, w)
    if F is not None:
        F = np.asarray(F, float).reshape(Z.shape[1], -1)
    if solver == "eigh":
        omega = (
            oracle_relations(Z, w, n_relations, lambda1=lambda1, G=G)
            if F is None
            else fault_normalised_oracle(Z, w, F, G=G)
        )
    else:
        D = Z - mu
        k_total = n_relations if F is None else F.shape[1]
        omega = np.zeros((Z.shape[1], k_total))
        for k in range(k_total):
            omega[:, k] = sgd_relation(
                D,
                w,
                solver=solver,
                lambda1=lambda1,
                lambda2=lambda2,
                G=G,
                previous=omega[:, :k] if F is None else None,
                fault=None if F is None else F[:, k],
                rng=rng,
                **sgd,
            )
    return omega, -(mu @ omega)


def residuals(Z: np.ndarray, omega: np.ndarray, intercept: np.ndarray) -> np.ndarray:
    """The parity residuals P = Z·Ω + b of every row and relation, shape (n, n_relations)."""
    return Z @ omega + intercept
