"""An example third-party r2rsim plug-in: an EWMA chart on standardised measurements.

Each measured channel is standardised with its healthy mean and standard deviation, smoothed
by an exponentially weighted moving average, and the statistic is the largest |EWMA| over the
channels. The threshold is a healthy-data quantile. Everything a plug-in needs is here: the
parameters in ``__init__``, ``fit`` on healthy runs, ``score`` aligned to the run's samples.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from r2rsim.diagnostics import Diagnostic


class EwmaDetector(Diagnostic):
    """EWMA chart on standardised measurements; the statistic is the largest |EWMA|.

    Parameters
    ----------
    lam : float
        EWMA weight of the newest sample, 0 < lam <= 1.
    alpha : float
        Fraction of healthy training samples above the threshold.
    """

    name = "example-ewma"
    requires = ("meas.*",)

    def __init__(self, lam: float = 0.1, alpha: float = 0.001):
        self.lam = lam
        self.alpha = alpha

    def _ewma(self, z: np.ndarray) -> np.ndarray:
        # pandas' ewm with adjust=False is the recursion s_k = lam z_k + (1 - lam) s_{k-1}
        return pd.DataFrame(z).ewm(alpha=self.lam, adjust=False, ignore_na=True).mean().to_numpy()

    def fit(self, runs):
        frames = self._frames(runs)
        self.columns_ = self.required_columns(frames[0])
        self._fit_scaling(self._matrix(frames, self.columns_))
        stats = [self._statistic(f) for f in frames]
        pooled = np.concatenate([s[np.isfinite(s)] for s in stats])
        self.threshold_ = float(np.quantile(pooled, 1.0 - self.alpha))
        return self

    def _statistic(self, frame: pd.DataFrame) -> np.ndarray:
        z = (frame[self.columns_].to_numpy(float) - self.mean_) / self.std_
        return np.nanmax(np.abs(self._ewma(z)), axis=1)

    def score(self, run):
        self._check_fitted()
        frame = self._frames(run)[0]
        return pd.DataFrame({"statistic": self._statistic(frame)}, index=frame.index)
