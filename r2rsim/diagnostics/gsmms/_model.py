"""The GSMMS model on arrays: a growing map over the partition features S with local parity
relations over the model features Z (thesis §4.3), grown until the loss-share criterion
(eq. 4.10), the absolute one (relative global-loss improvement) or the size limit stops it.
Both S and Z are already standardised; the plug-in (:mod:`._plugin`) handles columns."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from . import _local
from ._som import MapGraph, neighbourhood, train_codebook


@dataclass
class GrowthSettings:
    """The settings of map growth and local fitting (see :class:`~._plugin.GSMMS`)."""

    initial_nodes: int = 2
    max_nodes: int = 6
    zeta_threshold: float = 0.6
    min_improvement: float | None = 0.05
    k_max: int = 200
    sigma0: float = 1.0
    sigma_final: float = 0.3
    weighting: str = "hard"
    n_relations: int = 1
    fault_directions: np.ndarray | None = None
    solver: str = "minibatch"
    batch_size: int = 128
    step: str = "inv_sqrt"
    eta0: float = 1.0
    n_epochs: float = 1.0
    lambda1: float = 1.0
    lambda2: float = 0.0
    #: G of a node (q, r) from its sample weights (n,): ∇_x O_NL at the node's operating
    #: point, in the standardised model features (eq. 4.21); None: no physics term
    constraint: Callable[[np.ndarray], np.ndarray] | None = None


@dataclass
class NodeModels:
    """Relations of every node: ``omega[m]`` (q, k) unit-norm columns, ``intercept[m]`` (k,)."""

    omega: list[np.ndarray] = field(default_factory=list)
    intercept: list[np.ndarray] = field(default_factory=list)

    def residuals(self, Z: np.ndarray, bmu: np.ndarray) -> np.ndarray:
        """Each sample's residuals under its own node's relations, shape (n, k)."""
        k = self.omega[0].shape[1]
        out = np.empty((len(Z), k))
        for m in np.unique(bmu):
            sel = bmu == m
            out[sel] = _local.residuals(Z[sel], self.omega[m], self.intercept[m])
        return out


@dataclass
class GrowthRecord:
    """One step of growth: map size, global loss, shares and what was decided."""

    n_nodes: int
    loss: float
    zeta: list[float]
    decision: str


def initial_map(S: np.ndarray, n_nodes: int, rng: np.random.Generator) -> MapGraph:
    """Up to ``n_nodes`` nodes by farthest-point selection from a random first sample (fewer
    when the data has fewer distinct points), joined in a chain."""
    first = S[rng.integers(len(S))]
    book = [first]
    d2 = np.sum((S - first) ** 2, axis=1)
    for _ in range(n_nodes - 1):
        i = int(np.argmax(d2))
        if d2[i] <= 1e-18:
            break
        book.append(S[i])
        d2 = np.minimum(d2, np.sum((S - S[i]) ** 2, axis=1))
    return MapGraph(np.array(book), {(m, m + 1) for m in range(len(book) - 1)})


def node_weights(graph: MapGraph, bmu: np.ndarray, s: GrowthSettings) -> np.ndarray:
    """Weights of every sample for every node, shape (M, n): the Gaussian of the hop distance
    from the node to the sample's BMU (eq. 4.11), or 0/1 by BMU (``hard``)."""
    if s.weighting == "hard":
        return (np.arange(graph.n_nodes)[:, None] == bmu[None, :]).astype(float)
    return neighbourhood(graph.hops(), s.sigma_final)[:, bmu]


def fit_nodes(graph: MapGraph, S, Z, s: GrowthSettings, rng) -> tuple[NodeModels, np.ndarray]:
    """Fit every node's relations; returns them and the per-node mean loss J_m (the mean
    squared residual of the samples the node wins, with unit-norm or fault-normalised
    relations; 0 if it wins none)."""
    bmu = graph.bmu(S)
    W = node_weights(graph, bmu, s)
    models = NodeModels()
    J = np.zeros(graph.n_nodes)
    for m in range(graph.n_nodes):
        w = W[m]
        if w.sum() <= 0 or not np.any(bmu == m):
            w = np.ones(len(Z))  # a node that wins nothing: any relation; it has no samples
        G = None if s.constraint is None else s.constraint(w)
        om, _ = _local.fit_relations(
            Z,
            w,
            s.n_relations,
            solver=s.solver,
            lambda1=s.lambda1,
            lambda2=s.lambda2,
            G=G,
            F=s.fault_directions,
            rng=rng,
            **(
                {}
                if s.solver == "eigh"
                else dict(batch_size=s.batch_size, step=s.step, eta0=s.eta0, n_epochs=s.n_epochs)
            ),
        )
        if s.fault_directions is None:  # the loss of a unit-norm relation
            om = om / np.maximum(np.linalg.norm(om, axis=0), 1e-300)
        mu, _ = _local.weighted_moments(Z, w)
        models.omega.append(om)
        models.intercept.append(-(mu @ om))
        sel = bmu == m
        if sel.any():
            J[m] = float(np.mean(_local.residuals(Z[sel], om, models.intercept[m]) ** 2))
    return models, J


def shares(J: np.ndarray) -> np.ndarray:
    """ζ_m = J_m / Σ J (eq. 4.10); equal shares when every loss is 0."""
    tot = J.sum()
    return J / tot if tot > 0 else np.full(len(J), 1.0 / len(J))


def global_loss(graph: MapGraph, S, J) -> float:
    """Mean squared residual over all samples (each under its BMU's relations)."""
    counts = np.bincount(graph.bmu(S), minlength=graph.n_nodes)
    return float(counts @ J / counts.sum())


def _train(graph, S, Z, s, rng, zeta):
    # the ζ-scaled rate plus an equal share: a node that wins no sample (ζ = 0) must still
    # be able to move towards data, or it stays dead for ever
    rate = 0.5 * (zeta + 1.0 / graph.n_nodes)
    train_codebook(
        graph,
        S,
        rate,
        k_max=s.k_max,
        batch_size=s.batch_size,
        sigma0=s.sigma0,
        sigma_final=s.sigma_final,
        rng=rng,
    )
    return fit_nodes(graph, S, Z, s, rng)


def _grow_once(graph: MapGraph, S, zeta) -> bool:
    """Insert a node next to the worst node; False when there is nowhere to put one."""
    p = int(np.argmax(zeta))
    if graph.neighbours(p):
        graph.insert_between(p)
        return True
    mine = S[graph.bmu(S) == p]
    if len(mine) == 0:
        return False
    d2 = np.sum((mine - graph.codebook[p]) ** 2, axis=1)
    i = int(np.argmax(d2))
    if d2[i] <= 1e-18:
        return False
    graph.add_node(mine[i], p)
    return True


def grow(graph: MapGraph, S, Z, s: GrowthSettings, rng, history: list[GrowthRecord]):
    """Train the map and its local models, then grow it until a criterion stops growth.

    Returns the final graph and models. The absolute criterion undoes the last insertion
    when it improved the global loss by less than ``min_improvement`` (relative)."""
    models, J = fit_nodes(graph, S, Z, s, rng)
    models, J = _train(graph, S, Z, s, rng, shares(J))
    loss = global_loss(graph, S, J)
    while True:
        zeta = shares(J)
        if zeta.max() <= s.zeta_threshold:
            history.append(GrowthRecord(graph.n_nodes, loss, zeta.tolist(), "stop: share"))
            return graph, models
        if graph.n_nodes >= s.max_nodes:
            history.append(GrowthRecord(graph.n_nodes, loss, zeta.tolist(), "stop: max_nodes"))
            return graph, models
        trial = graph.copy()
        if not _grow_once(trial, S, zeta):
            history.append(
                GrowthRecord(
                    graph.n_nodes, loss, zeta.tolist(), "stop: no distinct data to grow into"
                )
            )
            return graph, models
        history.append(GrowthRecord(graph.n_nodes, loss, zeta.tolist(), "grow"))
        t_models, t_J = _train(trial, S, Z, s, rng, np.append(zeta, zeta.max()))
        t_loss = global_loss(trial, S, t_J)
        if (
            s.min_improvement is not None
            and loss > 0
            and (loss - t_loss) / loss < s.min_improvement
        ):
            history.append(
                GrowthRecord(
                    trial.n_nodes,
                    t_loss,
                    shares(t_J).tolist(),
                    "stop: improvement below min_improvement (undone)",
                )
            )
            return graph, models
        graph, models, J, loss = trial, t_models, t_J, t_loss
