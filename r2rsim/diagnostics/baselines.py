"""Baseline detectors (diagnostics.md A5): a per-channel residual threshold, PCA with T² and
SPE, dynamic PCA, and an isolation forest. Each calibrates its own threshold on the healthy
training data at the false-alarm rate ``alpha`` unless the harness sets one."""

from __future__ import annotations

import numpy as np
import pandas as pd
from scipy import stats

from ..errors import InputError
from .base import Diagnostic

#: bounds of PCA's retained components and dynamic PCA's lags (the lagged design matrix
#: has (lags + 1) × channels columns)
MAX_COMPONENTS = 10_000
MAX_LAGS = 50


class ResidualThreshold(Diagnostic):
    """Per-channel z-score against healthy statistics; the statistic is the largest |z|.

    Parameters
    ----------
    alpha : float
        Fraction of healthy training samples above the threshold.
    """

    name = "residual"

    def __init__(self, alpha: float = 0.001):
        self.alpha = alpha

    def fit(self, runs):
        self._check_alpha()
        frames = self._frames(runs)
        self.columns_ = self.required_columns(frames[0])
        z = np.abs(self._fit_scaling(self._matrix(frames, self.columns_))).max(axis=1)
        self.threshold_ = float(np.quantile(z, 1.0 - self.alpha))
        return self

    def score(self, run):
        self._check_fitted()
        f = self._frames(run)[0]
        z = np.abs((f[self.columns_].to_numpy(float) - self.mean_) / self.std_)
        out = pd.DataFrame(z, index=f.index, columns=[f"z.{c}" for c in self.columns_])
        out.insert(0, "statistic", np.nanmax(np.where(np.isfinite(z), z, -np.inf), axis=1))
        return out

    def rank_channels(self, scores: pd.DataFrame) -> pd.DataFrame:
        """Channels ordered by |z| at each sample (column 0 the most likely at fault)."""
        z = scores[[f"z.{c}" for c in self.columns_]].to_numpy()
        order = np.argsort(-np.nan_to_num(z, nan=-np.inf), axis=1)
        return pd.DataFrame(np.array(self.columns_, dtype=object)[order], index=scores.index)


class PCAMonitor(Diagnostic):
    """PCA on standardised channels with Hotelling's T² and the squared prediction error.

    Parameters
    ----------
    n_components : int or float
        Retained components, or the fraction of variance to keep (0 < x < 1).
    alpha : float
        False-alarm rate of each limit.
    limits : {"analytic", "empirical"}
        T² from the F distribution and SPE from Jackson & Mudholkar's approximation, or both
        as (1 - alpha) quantiles of the training statistics.

    The statistic is max(T²/T²_lim, SPE/SPE_lim); the threshold is 1.
    """

    name = "pca"
    lags = 0

    def __init__(
        self, n_components: float | int = 0.95, alpha: float = 0.01, limits: str = "analytic"
    ):
        self.n_components = n_components
        self.alpha = alpha
        self.limits = limits

    def _design(self, f: pd.DataFrame) -> np.ndarray:
        X = f[self.columns_].to_numpy(float)
        if self.lags:  # dynamic PCA: each row carries the previous `lags` rows
            n = len(X)
            X = np.hstack(
                [
                    np.vstack([np.full((j, X.shape[1]), np.nan), X[: n - j]])
                    for j in range(self.lags + 1)
                ]
            )
        return X

    def fit(self, runs):
        if self.limits not in ("analytic", "empirical"):
            raise InputError(
                f"{self.name}: limits must be 'analytic' or 'empirical', got {self.limits!r}"
            )
        self._check_alpha()
        nc = self.n_components
        if not (
            isinstance(nc, (int, float))
            and not isinstance(nc, bool)
            and (0 < nc < 1 or (nc >= 1 and nc == int(nc) and nc <= MAX_COMPONENTS))
        ):
            raise InputError(
                f"{self.name}: n_components must be a fraction of variance in "
                f"(0, 1) or a whole number from 1 to {MAX_COMPONENTS}, got {nc!r}"
            )
        self._check_int("lags", 0, MAX_LAGS)
        frames = self._frames(runs)
        self.columns_ = self.required_columns(frames[0])
        X = np.vstack([self._design(f) for f in frames])
        Z = self._fit_scaling(X[np.all(np.isfinite(X), axis=1)])
        n = len(Z)
        _, s, Vt = np.linalg.svd(Z, full_matrices=False)
        lam = s**2 / (n - 1)
        if 0 < self.n_components < 1:
            a = int(np.searchsorted(np.cumsum(lam) / lam.sum(), self.n_components) + 1)
        else:
            a = int(self.n_components)
        a = max(1, min(a, len(lam) - 1))
        self.n_components_ = a
        self.P_ = Vt[:a].T
        self.lam_ = lam[:a]
        if self.limits == "analytic":
            self.t2_limit_ = float(
                a * (n - 1) * (n + 1) / (n * (n - a)) * stats.f.ppf(1 - self.alpha, a, n - a)
            )
            rest = lam[a:]
            th1, th2, th3 = (np.sum(rest**i) for i in (1, 2, 3))
            h0 = 1 - 2 * th1 * th3 / (3 * th2**2)
            c = stats.norm.ppf(1 - self.alpha)
            self.spe_limit_ = float(
                th1
                * (c * np.sqrt(2 * th2 * h0**2) / th1 + 1 + th2 * h0 * (h0 - 1) / th1**2)
                ** (1 / h0)
            )
        else:
            t2, spe = self._stats(Z)
            self.t2_limit_ = float(np.quantile(t2, 1 - self.alpha))
            self.spe_limit_ = float(np.quantile(spe, 1 - self.alpha))
        self.threshold_ = 1.0
        return self

    def _stats(self, Z):
        T = Z @ self.P_
        t2 = np.sum(T**2 / self.lam_, axis=1)
        spe = np.sum((Z - T @ self.P_.T) ** 2, axis=1)
        return t2, spe

    def score(self, run):
        self._check_fitted()
        f = self._frames(run)[0]
        Z = (self._design(f) - self.mean_) / self.std_
        t2, spe = self._stats(Z)
        out = pd.DataFrame({"t2": t2, "spe": spe}, index=f.index)
        out.insert(0, "statistic", np.fmax(t2 / self.t2_limit_, spe / self.spe_limit_))
        return out


class DynamicPCAMonitor(PCAMonitor):
    """PCA on channels augmented with ``lags`` past samples (Ku, Storer & Georgakis 1995);
    the first ``lags`` samples of a run have no statistic (NaN, no alarm)."""

    name = "dpca"

    def __init__(
        self,
        lags: int = 2,
        n_components: float | int = 0.95,
        alpha: float = 0.01,
        limits: str = "analytic",
    ):
        super().__init__(n_components=n_components, alpha=alpha, limits=limits)
        self.lags = lags


class IsolationForestDetector(Diagnostic):
    """scikit-learn's isolation forest on the channels; statistic = -score_samples.

    Parameters
    ----------
    n_estimators, max_samples : see :class:`sklearn.ensemble.IsolationForest`
    alpha : float
        Fraction of healthy training samples above the threshold.
    random_state : int or None
    """

    name = "iforest"

    def __init__(
        self,
        n_estimators: int = 100,
        max_samples: int = 256,
        alpha: float = 0.001,
        random_state: int | None = None,
    ):
        self.n_estimators = n_estimators
        self.max_samples = max_samples
        self.alpha = alpha
        self.random_state = random_state

    def fit(self, runs):
        from sklearn.ensemble import IsolationForest

        self._check_alpha()
        self._check_int("n_estimators", 1, 10_000)
        self._check_int("max_samples", 2, 10_000_000)
        self._check_seed(high=2**32 - 1)  # scikit-learn's bound

        frames = self._frames(runs)
        self.columns_ = self.required_columns(frames[0])
        Z = self._fit_scaling(self._matrix(frames, self.columns_))
        self.forest_ = IsolationForest(
            n_estimators=self.n_estimators,
            max_samples=min(self.max_samples, len(Z)),
            random_state=self.random_state,
        ).fit(Z)
        self.threshold_ = float(np.quantile(-self.forest_.score_samples(Z), 1 - self.alpha))
        return self

    def score(self, run):
        self._check_fitted()
        f = self._frames(run)[0]
        Z = (f[self.columns_].to_numpy(float) - self.mean_) / self.std_
        ok = np.all(np.isfinite(Z), axis=1)
        stat = np.full(len(Z), np.nan)
        if ok.any():
            stat[ok] = -self.forest_.score_samples(Z[ok])
        return pd.DataFrame({"statistic": stat}, index=f.index)
