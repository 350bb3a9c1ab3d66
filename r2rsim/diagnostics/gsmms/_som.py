"""The growing self-organising map (thesis eqs. 4.7-4.10, §4.3.1): nodes with codebook vectors
in the (standardised) partition space, joined by edges; hop distances over the edges define
the Gaussian neighbourhood of both the codebook update and the local models' weights."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np


@dataclass
class MapGraph:
    """Codebook vectors (one row per node) and the undirected edges between nodes."""

    codebook: np.ndarray
    edges: set[tuple[int, int]] = field(default_factory=set)

    @property
    def n_nodes(self) -> int:
        return len(self.codebook)

    def neighbours(self, m: int) -> list[int]:
        return sorted({b for a, b in self.edges if a == m} | {a for a, b in self.edges if b == m})

    def hops(self) -> np.ndarray:
        """All-pairs hop distances over the edges (BFS; unreachable pairs get n_nodes)."""
        M = self.n_nodes
        out = np.full((M, M), float(M))
        for s in range(M):
            out[s, s] = 0.0
            todo = deque([s])
            while todo:
                a = todo.popleft()
                for b in self.neighbours(a):
                    if out[s, b] > out[s, a] + 1:
                        out[s, b] = out[s, a] + 1
                        todo.append(b)
        return out

    def bmu(self, S: np.ndarray) -> np.ndarray:
        """Index of the best-matching unit of each row of S (eq. 4.8)."""
        d2 = ((S[:, None, :] - self.codebook[None, :, :]) ** 2).sum(axis=2)
        return np.argmin(d2, axis=1)

    def insert_between(self, p: int) -> int:
        """Insert a node halfway between node p and its Euclidean-farthest neighbour f; the
        edge p-f is replaced by p-new and new-f (Fritzke). Returns the new node's index."""
        nb = self.neighbours(p)
        f = max(nb, key=lambda m: float(np.sum((self.codebook[m] - self.codebook[p]) ** 2)))
        new = self.n_nodes
        self.codebook = np.vstack([self.codebook, (self.codebook[p] + self.codebook[f]) / 2])
        self.edges.discard((min(p, f), max(p, f)))
        self.edges |= {(p, new), (f, new)}
        return new

    def add_node(self, vector: np.ndarray, connect_to: int) -> int:
        """Append a node at ``vector`` joined to node ``connect_to``."""
        new = self.n_nodes
        self.codebook = np.vstack([self.codebook, vector[None, :]])
        self.edges.add((connect_to, new))
        return new

    def copy(self) -> MapGraph:
        return MapGraph(self.codebook.copy(), set(self.edges))


def neighbourhood(hops: np.ndarray, sigma: float) -> np.ndarray:
    """h = exp(−dis² / 2σ²) (eqs. 4.9, 4.11)."""
    return np.exp(-(hops**2) / (2.0 * sigma**2))


def train_codebook(
    graph: MapGraph,
    S: np.ndarray,
    zeta: np.ndarray,
    *,
    k_max: int,
    batch_size: int,
    sigma0: float,
    sigma_final: float,
    rng: np.random.Generator,
) -> None:
    """``k_max`` codebook updates (eq. 4.7), each averaged over a mini-batch of rows of S:
    ε_m += ζ_m · mean_i h(k, dis(m, c_i)) (s_i − ε_m), with σ(k) decaying geometrically from
    ``sigma0`` to ``sigma_final`` hops and ζ_m the node's loss share (eq. 4.10), so badly
    fitted nodes move most."""
    hops = graph.hops()
    for k in range(k_max):
        sigma = sigma0 * (sigma_final / sigma0) ** (k / max(1, k_max - 1))
        batch = S[rng.integers(0, len(S), size=min(batch_size, len(S)))]
        h = neighbourhood(hops, sigma)[:, graph.bmu(batch)]  # (M, b)
        pull = (h @ batch - h.sum(axis=1, keepdims=True) * graph.codebook) / len(batch)
        graph.codebook = graph.codebook + zeta[:, None] * pull
