"""The ``gsmms`` and ``gsmms_global`` plug-ins: column handling, smoothing, standardisation
and the per-node residual statistics around :mod:`._model`."""

from __future__ import annotations

import fnmatch
import inspect
import math

import numpy as np
import pandas as pd

from ...errors import InputError
from ..base import Diagnostic, _frame
from . import _local
from ._model import GrowthRecord, GrowthSettings, grow, initial_map

#: ``fault_channels`` sentinel: a fault-normalised relation for every model channel
ALL_CHANNELS = "all"
_CHOICES = {"solver": _local.SOLVERS, "step": _local.STEPS, "weighting": ("soft", "hard")}
#: allowed ranges of the integer parameters: they bound a fit's memory and time (a mini-batch
#: fit draws at least 3000 × batch_size samples; k_max updates per growth step)
_INT_RANGES = {
    "batch_size": (1, 4096),
    "n_relations": (1, 64),
    "initial_nodes": (1, 1000),
    "max_nodes": (1, 1000),
    "k_max": (1, 100_000),
    "max_samples": (2, 10_000_000),
}
#: upper limits of float parameters: η0 above 2 makes the normalised step diverge; n_epochs
#: bounds the draws; a neighbourhood wider than the largest map means nothing
_FLOAT_LIMITS = {"eta0": 2.0, "n_epochs": 100.0, "sigma0": 1000.0, "sigma_final": 1000.0}


class GSMMS(Diagnostic):
    """Growing self-organising multi-model scheme (thesis Ch. 4): a growing map partitions
    the operating space into regimes, each node carries local parity relations fitted by
    mini-batch SGD, and each node's residual is standardised by its own healthy statistics,
    so one threshold is regime-aware.

    Parameters
    ----------
    partition_features : str or list of str
        Glob patterns of the columns the map partitions on (standardised). Default the
        set-points ``sp.*``: they say which regime the line is in and cannot be faulty. The
        thesis partitions on a state estimated from sensor A, which lets an A fault move the
        best-matching unit (``docs/diagnostics.md`` shows the masking).
    model_features : str or list of str
        Glob patterns of the channels the local parity relations combine (standardised).
    derivatives : bool
        Also give the relations each model channel's time derivative [unit/s] (eq. 4.23).
    smooth_s : float
        Causal moving-average window [s] applied to every feature (0: none).
    n_relations : int
        Unit-norm relations per node (the smallest eigen-directions, fitted one after the
        other, as eq. 4.21); only with ``fault_channels=None`` (anything but 1 otherwise is
        an error: the fault-normalised design has one relation per fault channel).
    fault_channels : "all", str, list of str or None
        The channels whose faults the relations are built to see. Default ``"all"``: every
        model channel. Per node there is one relation per matching model channel j, the
        minimum-variance relation with unit response to a fault on it:
        Ω_j = C⁻¹e_j / (e_jᵀC⁻¹e_j), C the node's covariance of the standardised model
        features, so that e_j·Ω_j = 1 (the fault-normalised design, ``docs/diagnostics.md``
        §11). A fault of size δ on channel j moves relation j's residual by exactly δ, by
        construction, whatever the healthy data look like: the statistic cannot be blind to
        a channel it monitors. Ω_j ∝ C⁻¹e_j is also the direction that maximises the
        ratio of that shift to the residual's spread (the matched filter of a step on
        channel j), and its spread is at most the channel's own spread within the node
        (Ω = e_j is admissible), so each relation sees its channel's faults at least as
        well as a per-node limit check on that channel. A glob pattern or list of them: only
        the matching model channels (the Ch. 4 study normalises on sensor A alone; such a
        map is blind to faults that only move the other channels). None: the thesis's
        ``n_relations`` unit-norm minimum-variance relations (eq. 4.21), which can be blind
        to a channel: on the registration line the one relation is essentially "sensor B
        = const", B being what the tension loop holds still, and it hardly sees sensor A.
    solver : {"minibatch", "sgd", "batch", "eigh"}
        Mini-batch SGD (thesis), single-sample SGD, full-batch gradient descent, or the exact
        eigenvector oracle.
    batch_size : int
        Samples per mini-batch (thesis: 128) and per codebook update.
    step : {"inv_sqrt", "inv_sq"}
        Step size η0/√idx, or η0/idx² as eq. 4.15 prints it (stalls; kept for comparison).
    eta0 : float
        Initial step size.
    n_epochs : float
        Passes' worth of samples per SGD fit.
    lambda1 : float
        Weight of the unit-norm penalty (eq. 4.21).
    physics : dict or None
        The thesis's physics term of eq. 4.21, λ2‖Ω·∇_x O_NL(x, u)‖²: keyword arguments of
        the ``parity`` plug-in (:class:`~r2rsim.diagnostics.parity.ParitySpaceDetector`:
        ``line``, ``sensor_a``, ``sensor_b``, the speed channels...), whose reduced
        registration model supplies ∇_x O_NL, evaluated at each node's mean operating point
        (x̂ from both sensors, u from the encoders) and divided by the model features'
        scales. The model features must then be that model's two sensors. None: no physics
        term (the relations are purely data-driven).
    lambda2 : float
        Weight of the physics term (its ∇_x O_NL has unit norm, like Ω). The gradient
        solvers penalise it; ``solver="eigh"`` imposes Ω·∇_x O_NL = 0 exactly (λ2 → ∞).
    initial_nodes, max_nodes : int
        Map size at the start (farthest-point seeds) and the most growth may reach.
    zeta_threshold : float
        Share criterion: growth stops when every node's loss share ζ_m is at most this.
    min_improvement : float or None
        Absolute criterion: an insertion that lowers the global loss by less than this
        fraction is undone and growth stops (None: off).
    k_max : int
        Codebook updates (mini-batches) per growth step.
    sigma0, sigma_final : float
        Neighbourhood width [hops] at the start and end of each training phase; the local
        models' neighbour weights use ``sigma_final``.
    weighting : {"hard", "soft"}
        Local models use only the samples each node wins, or weight all samples by
        topological distance (eq. 4.11). Hard by default: a relation's residual variance is
        tiny beside the difference between regimes, so even a 0.4 % weight of a neighbouring
        regime's samples (one hop at σ = 0.3) distorts it.
    k_sigma : float
        The threshold on |P − μ_node|/σ_node (thesis: 2σ).
    max_samples : int
        At most this many training samples (an evenly spaced subset) are used to fit.
    random_state : int or None
        Seed of every random choice (initial node, mini-batches, initial relations).
    """

    name = "gsmms"
    requires = ()

    def __init__(
        self,
        partition_features: str | list | tuple = ("sp.*",),
        model_features: str | list | tuple = ("meas.*",),
        derivatives: bool = False,
        smooth_s: float = 1.0,
        n_relations: int = 1,
        fault_channels: str | list | tuple | None = "all",
        solver: str = "minibatch",
        batch_size: int = 128,
        step: str = "inv_sqrt",
        eta0: float = 1.0,
        n_epochs: float = 1.0,
        lambda1: float = 1.0,
        physics: dict | None = None,
        lambda2: float = 1.0,
        initial_nodes: int = 2,
        max_nodes: int = 6,
        zeta_threshold: float = 0.6,
        min_improvement: float | None = 0.05,
        k_max: int = 200,
        sigma0: float = 1.0,
        sigma_final: float = 0.3,
        weighting: str = "hard",
        k_sigma: float = 2.0,
        max_samples: int = 200_000,
        random_state: int | None = None,
    ):
        self.partition_features = partition_features
        self.model_features = model_features
        self.derivatives = derivatives
        self.smooth_s = smooth_s
        self.n_relations = n_relations
        self.fault_channels = fault_channels
        self.solver = solver
        self.batch_size = batch_size
        self.step = step
        self.eta0 = eta0
        self.n_epochs = n_epochs
        self.lambda1 = lambda1
        self.physics = physics
        self.lambda2 = lambda2
        self.initial_nodes = initial_nodes
        self.max_nodes = max_nodes
        self.zeta_threshold = zeta_threshold
        self.min_improvement = min_improvement
        self.k_max = k_max
        self.sigma0 = sigma0
        self.sigma_final = sigma_final
        self.weighting = weighting
        self.k_sigma = k_sigma
        self.max_samples = max_samples
        self.random_state = random_state

    # ---- parameters and columns --------------------------------------------------------
    def _settings(self) -> GrowthSettings:
        for key, allowed in _CHOICES.items():
            if getattr(self, key) not in allowed:
                raise InputError(
                    f"{self.name}: {key} must be one of {', '.join(allowed)}, "
                    f"got {getattr(self, key)!r}"
                )
        for key, (low, high) in _INT_RANGES.items():
            self._check_int(key, low, high)
        for key in ("lambda1", "k_sigma", "zeta_threshold"):
            if not 0 < self._number(key) < math.inf:
                raise InputError(
                    f"{self.name}: {key} must be a positive finite number, "
                    f"got {getattr(self, key)!r}"
                )
        for key, high in _FLOAT_LIMITS.items():  # beyond these a fit diverges or never ends
            if not 0 < self._number(key) <= high:
                raise InputError(
                    f"{self.name}: {key} must be > 0 and at most {high:g}, "
                    f"got {getattr(self, key)!r}"
                )
        if not 0 <= self._number("lambda2") < math.inf:
            raise InputError(
                f"{self.name}: lambda2 must be a finite number >= 0, got {self.lambda2!r}"
            )
        if self.sigma_final > self.sigma0:  # the neighbourhood only narrows (eq. 4.9)
            raise InputError(
                f"{self.name}: sigma_final ({self.sigma_final!r}) must not exceed "
                f"sigma0 ({self.sigma0!r}): the neighbourhood width decays"
            )
        if not self._number("zeta_threshold") < 1:
            raise InputError(
                f"{self.name}: zeta_threshold is a share of the loss, in (0, 1), "
                f"got {self.zeta_threshold!r} (1 or more never grows the map)"
            )
        if not isinstance(self.derivatives, bool):
            raise InputError(
                f"{self.name}: derivatives must be true or false, got {self.derivatives!r}"
            )
        if not 0 <= self._number("smooth_s") < math.inf:
            raise InputError(
                f"{self.name}: smooth_s must be a finite number >= 0 s, got {self.smooth_s!r}"
            )
        if self.min_improvement is not None and not 0 <= self._number("min_improvement") < math.inf:
            raise InputError(
                f"{self.name}: min_improvement must be a finite number >= 0 or "
                f"null, got {self.min_improvement!r}"
            )
        self._check_seed()
        for key in ("partition_features", "model_features", "fault_channels"):
            v = getattr(self, key)
            if v is None and key == "fault_channels":
                continue
            pats = [v] if isinstance(v, str) else v
            # fnmatch needs strings: [1, 2] failed in the fit with a TypeError
            if not (isinstance(pats, (list, tuple)) and all(isinstance(p, str) for p in pats)):
                raise InputError(
                    f"{self.name}: {key} must be a glob pattern or a list of "
                    f"them (strings), got {v!r}"
                )
        if self.fault_channels is not None and self.n_relations != 1:
            raise InputError(
                f"{self.name}: n_relations = {self.n_relations} applies to the "
                f"unit-norm relations (fault_channels: null); with fault_channels "
                f"{self.fault_channels!r} there is one fault-normalised relation "
                f"per matching model channel"
            )
        if self.initial_nodes > self.max_nodes:
            raise InputError(
                f"{self.name}: initial_nodes ({self.initial_nodes}) exceeds "
                f"max_nodes ({self.max_nodes})"
            )
        return GrowthSettings(
            initial_nodes=int(self.initial_nodes),
            max_nodes=int(self.max_nodes),
            zeta_threshold=float(self.zeta_threshold),
            min_improvement=None if self.min_improvement is None else float(self.min_improvement),
            k_max=int(self.k_max),
            sigma0=float(self.sigma0),
            sigma_final=float(self.sigma_final),
            weighting=self.weighting,
            n_relations=int(self.n_relations),
            solver=self.solver,
            batch_size=int(self.batch_size),
            step=self.step,
            eta0=float(self.eta0),
            n_epochs=float(self.n_epochs),
            lambda1=float(self.lambda1),
            lambda2=float(self.lambda2),
        )

    def _check_relations(self, Z: np.ndarray, constraint) -> None:
        """n_relations fits in the space the model features leave (their number, less the
        rank of the physics constraint)."""
        q = Z.shape[1]
        if callable(constraint):  # the physics gradient, per node: its shape is the same
            constraint = constraint(np.ones(len(Z)))
        free = q - (
            np.linalg.matrix_rank(np.asarray(constraint, float).reshape(q, -1))
            if constraint is not None
            else 0
        )
        if self.n_relations > free:
            raise InputError(
                f"{self.name}: n_relations = {self.n_relations}, but the {q} "
                f"model features{' (with derivatives)' if self.derivatives else ''}"
                f" leave {free} dimension(s) for relations; lower n_relations or "
                f"match more model_features"
            )

    def _match(self, frame: pd.DataFrame, patterns, what: str) -> list[str]:
        patterns = [patterns] if isinstance(patterns, str) else list(patterns)
        if not patterns:
            raise InputError(f"{self.name}: {what} is empty")
        cols = [
            c for c in frame.columns if c != "t_s" and any(fnmatch.fnmatch(c, p) for p in patterns)
        ]
        missing = [p for p in patterns if not any(fnmatch.fnmatch(c, p) for c in frame.columns)]
        if missing:
            raise InputError(
                f"{self.name}: the data has no column matching {', '.join(missing)} ({what})"
            )
        return cols

    def _fault_directions(self) -> np.ndarray | None:
        """Unit columns of the standardised model features for each fault channel (every
        model channel with ``fault_channels="all"``; None: unit-norm relations)."""
        if self.fault_channels is None:
            return None
        pats = (
            ["*"]
            if self.fault_channels == ALL_CHANNELS
            else [self.fault_channels]
            if isinstance(self.fault_channels, str)
            else list(self.fault_channels)
        )
        idx = [
            j for j, c in enumerate(self.model_columns_) if any(fnmatch.fnmatch(c, p) for p in pats)
        ]
        if not idx:
            raise InputError(
                f"{self.name}: fault_channels {pats} match none of the model "
                f"channels ({', '.join(self.model_columns_)})"
            )
        n_features = len(self.z_mean_)
        return np.eye(n_features)[:, idx]

    def _physics_model(self, frames) -> None:
        """Set ``physics_`` (the parity plug-in holding the calibrated reduced model) and
        ``physics_rows_`` (the stack row of each model feature), or None without physics."""
        self.physics_ = self.physics_rows_ = None
        if self.physics is None:
            return
        from ..parity import ParitySpaceDetector

        if not isinstance(self.physics, dict):
            raise InputError(
                f"{self.name}: physics must be a mapping of parity plug-in "
                f"parameters or null, got {self.physics!r}"
            )
        allowed = set(inspect.signature(ParitySpaceDetector).parameters)
        unknown = sorted(set(self.physics) - allowed)
        if unknown:
            raise InputError(
                f"{self.name}: physics has no parameter {', '.join(unknown)} "
                f"(it takes the parity plug-in's: {', '.join(sorted(allowed))})"
            )
        det = ParitySpaceDetector(**self.physics).configure(frames)  # roles from the line
        col_a, col_b = det.channels[:2]
        sensors = {col_a: 0, col_b: 1}
        if sorted(self.model_columns_) != sorted(sensors):
            raise InputError(
                f"{self.name}: with physics the model features must be the "
                f"reduced model's sensors {col_a} and {col_b}, "
                f"got {', '.join(self.model_columns_)}"
            )
        for f in frames:
            det.required_columns(f)
        model, _, _ = det.reduced_model(frames)
        orders = [0] * len(self.model_columns_) + (
            [1] * len(self.model_columns_) if self.derivatives else []
        )
        cols = list(self.model_columns_) * (2 if self.derivatives else 1)
        self.physics_ = det
        self.physics_rows_ = np.array(
            [model.rows.index((sensors[c], k)) for c, k in zip(cols, orders, strict=True)]
        )

    def _operating_points(self, frames) -> np.ndarray:
        """The reduced model's p = [x̂, u] of every sample of ``frames`` (n, 4); (n, 0)
        without physics."""
        if self.physics_ is None:
            return np.zeros((sum(len(f) for f in frames), 0))
        return np.vstack([self.physics_.operating_points(f) for f in frames])

    def _constraint(self, P: np.ndarray):
        """G of a node from its sample weights (GrowthSettings.constraint): ∇_x O_NL at the
        weighted mean operating point, in standardised feature units, unit norm."""
        if self.physics_ is None:
            return None
        model, rows, scale = self.physics_.model_, self.physics_rows_, self.z_scale_
        finite = np.all(np.isfinite(P), axis=1)

        def node_gradient(w: np.ndarray) -> np.ndarray:
            sel = finite & (w > 0)
            p = (
                np.average(P[sel], axis=0, weights=w[sel])
                if sel.any()
                else np.mean(P[finite], axis=0)
            )
            G = model.grad_x(p[:1], p[1:])[rows] / scale[:, None]
            norm = np.linalg.norm(G, axis=0)
            return G / np.where(norm > 0, norm, 1.0)

        return node_gradient

    def _features(self, f: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
        """Smoothed partition and model features (raw units) of one run."""
        dt = float(np.median(np.diff(f["t_s"].to_numpy()))) if "t_s" in f and len(f) > 1 else 0.01
        win = max(1, int(round(self.smooth_s / dt))) if self.smooth_s > 0 else 1
        part = f[self.partition_columns_].astype(float)
        model = f[self.model_columns_].astype(float)
        if win > 1:
            part = part.rolling(win, min_periods=1).mean()
            model = model.rolling(win, min_periods=1).mean()
        Z = model.to_numpy()
        if self.derivatives:
            Z = np.hstack(
                [Z, np.vstack([np.full((1, Z.shape[1]), np.nan), np.diff(Z, axis=0) / dt])]
            )
        return part.to_numpy(), Z

    def _standardised(self, f: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
        S, Z = self._features(f)
        return (S - self.s_mean_) / self.s_scale_, (Z - self.z_mean_) / self.z_scale_

    def _pooled(self, frames, points: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Standardised rows of all runs, without rows holding a NaN, evenly thinned to at
        most ``max_samples``, and (with ``points``) their operating points
        (:meth:`_operating_points`; else an (n, 0) array)."""
        parts = [self._standardised(f) for f in frames]
        S = np.vstack([p[0] for p in parts])
        Z = np.vstack([p[1] for p in parts])
        P = self._operating_points(frames) if points else np.zeros((len(S), 0))
        ok = np.all(np.isfinite(S), axis=1) & np.all(np.isfinite(Z), axis=1)
        S, Z, P = S[ok], Z[ok], P[ok]
        if len(S) > self.max_samples:
            keep = np.linspace(0, len(S) - 1, int(self.max_samples)).astype(int)
            S, Z, P = S[keep], Z[keep], P[keep]
        if len(S) < 2:
            raise InputError(f"{self.name}: fewer than two complete training samples")
        return S, Z, P

    def training_arrays(self, runs) -> tuple[np.ndarray, np.ndarray]:
        """The standardised partition features S and model features Z of ``runs`` as a fit
        uses them (rows holding a NaN dropped, evenly thinned to ``max_samples``), with the
        fitted standardisation: for studies of the local solvers on the same data."""
        self._check_fitted()
        S, Z, _ = self._pooled(self._frames(runs), points=False)
        return S, Z

    # ---- the contract ----------------------------------------------------------------------
    def fit(self, runs):
        """Standardise, grow the map on the healthy runs and learn each node's residual
        statistics; returns ``self``."""
        settings = self._settings()
        frames = self._frames(runs)
        self.partition_columns_ = self._match(
            frames[0], self.partition_features, "partition_features"
        )
        self.model_columns_ = self._match(frames[0], self.model_features, "model_features")
        raw = [self._features(f) for f in frames]
        for name, i in (("s", 0), ("z", 1)):
            X = np.vstack([r[i] for r in raw])
            X = X[np.all(np.isfinite(X), axis=1)]
            if len(X) == 0:
                raise InputError(f"{self.name}: no complete training sample")
            sd = X.std(axis=0)
            setattr(self, f"{name}_mean_", X.mean(axis=0))
            # a constant column (a set-point in one regime) keeps its unit as scale
            setattr(self, f"{name}_scale_", np.where(sd > 0, sd, 1.0))
        settings.fault_directions = self._fault_directions()
        self._physics_model(frames)
        S, Z, P = self._pooled(frames)
        settings.constraint = self._constraint(P)
        self._check_relations(Z, settings.constraint)
        self._rng = np.random.default_rng(self.random_state)
        self.history_: list[GrowthRecord] = []
        graph = initial_map(S, settings.initial_nodes, self._rng)
        self._finish(*grow(graph, S, Z, settings, self._rng, self.history_), S, Z, P)
        return self

    def partial_fit(self, runs):
        """Go on learning from new healthy runs: the map keeps its nodes and grows when the
        new data is a regime it does not fit (the standardisation stays the first fit's).
        The new runs are pooled with the samples kept from earlier fits."""
        if not hasattr(self, "graph_"):
            return self.fit(runs)
        settings = self._settings()
        settings.fault_directions = self._fault_directions()
        S_new, Z_new, P_new = self._pooled(self._frames(runs))
        S, Z, P = (
            np.vstack([kept, new])
            for kept, new in zip(self._kept, (S_new, Z_new, P_new), strict=True)
        )
        settings.constraint = self._constraint(P)
        self._finish(*grow(self.graph_.copy(), S, Z, settings, self._rng, self.history_), S, Z, P)
        return self

    def calibrate(self, runs, alpha: float | None = None, masks=None):
        """Re-estimate every node's residual mean and standard deviation on held-out healthy
        runs (the map and relations stay; nodes those runs never reach keep theirs), then,
        with ``alpha``, set ``threshold_`` so that the alarms hold that false-alarm rate on
        the samples of ``masks`` (the contract's :meth:`Diagnostic.calibrate`; without
        ``alpha`` the threshold stays ``k_sigma``). Returns ``self``."""
        self._check_fitted()
        S, Z, _ = self._pooled(self._frames(runs), points=False)
        self._node_statistics(S, Z, keep_unseen=True)
        if alpha is not None:
            super().calibrate(runs, alpha, masks)
        return self

    def _node_statistics(self, S, Z, keep_unseen=False):
        graph = self.graph_
        bmu = graph.bmu(S)
        R = self.models_.residuals(Z, bmu)
        k = R.shape[1]
        if not keep_unseen:
            sd_all = R.std(axis=0)
            self.node_mean_ = np.zeros((graph.n_nodes, k))
            self.node_std_ = np.tile(np.where(sd_all > 0, sd_all, 1.0), (graph.n_nodes, 1))
            self.node_count_ = np.zeros(graph.n_nodes, int)
        for m in range(graph.n_nodes):
            sel = bmu == m
            if sel.sum() >= 2:
                sd = R[sel].std(axis=0)
                self.node_mean_[m] = R[sel].mean(axis=0)
                self.node_std_[m] = np.where(sd > 0, sd, self.node_std_[m])
                self.node_count_[m] = int(sel.sum())

    def _finish(self, graph, models, S, Z, P):
        self.graph_, self.models_ = graph, models
        self.n_nodes_ = graph.n_nodes
        self._node_statistics(S, Z)
        self.threshold_ = float(self.k_sigma)
        keep = np.linspace(0, len(S) - 1, min(len(S), int(self.max_samples) // 2)).astype(int)
        self._kept = (S[keep], Z[keep], P[keep])

    def score(self, run) -> pd.DataFrame:
        """Per sample: ``statistic`` = max over relations of |P − μ_node|/σ_node, ``bmu``
        (the node index; −1 where a feature is missing), each relation's raw residual
        ``residual.k`` (standardised units) and its signed node-standardised value
        ``z.k`` = (P − μ_node)/σ_node."""
        self._check_fitted()
        f = _frame(run)
        if self.physics_ is not None:  # the physics term's model: the scored run's line
            self.physics_._scored_frame(f)  # must match the fitted one (else refused)
        missing = [
            c for c in (*self.partition_columns_, *self.model_columns_) if c not in f.columns
        ]
        if missing:  # another line's data, or a run without a channel the fit used
            raise InputError(
                f"{self.name}: the data has no column {', '.join(missing[:3])}"
                f"{' ...' if len(missing) > 3 else ''} (fitted on it)"
            )
        S, Z = self._standardised(f)
        ok = np.all(np.isfinite(S), axis=1) & np.all(np.isfinite(Z), axis=1)
        k = self.node_mean_.shape[1]
        bmu = np.full(len(f), -1)
        R = np.full((len(f), k), np.nan)
        zs = np.full((len(f), k), np.nan)
        if ok.any():
            b = self.graph_.bmu(S[ok])
            r = self.models_.residuals(Z[ok], b)
            bmu[ok], R[ok] = b, r
            zs[ok] = (r - self.node_mean_[b]) / self.node_std_[b]
        stat = np.full(len(f), np.nan)
        stat[ok] = np.max(np.abs(zs[ok]), axis=1)
        out = pd.DataFrame({"statistic": stat, "bmu": bmu}, index=f.index)
        for j in range(k):
            out[f"residual.{j}"] = R[:, j]
        for j in range(k):
            out[f"z.{j}"] = zs[:, j]
        return out


class GlobalParity(GSMMS):
    """The "global model" of thesis Table 4-2: the GSMMS pipeline with a single node (one
    parity relation set and one residual statistic for every regime)."""

    name = "gsmms_global"

    def __init__(
        self,
        partition_features: str | list | tuple = ("sp.*",),
        model_features: str | list | tuple = ("meas.*",),
        derivatives: bool = False,
        smooth_s: float = 1.0,
        n_relations: int = 1,
        fault_channels: str | list | tuple | None = "all",
        solver: str = "minibatch",
        batch_size: int = 128,
        step: str = "inv_sqrt",
        eta0: float = 1.0,
        n_epochs: float = 1.0,
        lambda1: float = 1.0,
        physics: dict | None = None,
        lambda2: float = 1.0,
        initial_nodes: int = 1,
        max_nodes: int = 1,
        zeta_threshold: float = 0.6,
        min_improvement: float | None = 0.05,
        k_max: int = 200,
        sigma0: float = 1.0,
        sigma_final: float = 0.3,
        weighting: str = "hard",
        k_sigma: float = 2.0,
        max_samples: int = 200_000,
        random_state: int | None = None,
    ):
        super().__init__(
            partition_features=partition_features,
            model_features=model_features,
            derivatives=derivatives,
            smooth_s=smooth_s,
            n_relations=n_relations,
            fault_channels=fault_channels,
            solver=solver,
            batch_size=batch_size,
            step=step,
            eta0=eta0,
            n_epochs=n_epochs,
            lambda1=lambda1,
            physics=physics,
            lambda2=lambda2,
            initial_nodes=initial_nodes,
            max_nodes=max_nodes,
            zeta_threshold=zeta_threshold,
            min_improvement=min_improvement,
            k_max=k_max,
            sigma0=sigma0,
            sigma_final=sigma_final,
            weighting=weighting,
            k_sigma=k_sigma,
            max_samples=max_samples,
            random_state=random_state,
        )
