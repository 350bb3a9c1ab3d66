"""The plug-in contract for diagnostic algorithms (docs/diagnostics.md §2, scikit-learn
conventions).

A plug-in is a :class:`Diagnostic` subclass:

* ``__init__`` stores its parameters and nothing else (``get_params``/``clone`` work);
* ``fit(runs)`` learns from healthy runs only, sets attributes ending in ``_`` and returns
  ``self``; all randomness comes from a ``random_state`` parameter;
* ``score(run)`` returns per-sample statistics aligned to the run's samples (same index),
  with at least the column ``statistic`` (larger = more anomalous);
* ``decide(scores)`` turns them into boolean alarms (default ``statistic > threshold_``);
* optionally ``diagnose(scores)`` names the fault type per sample (``normal`` when none);
* ``rank_channels(scores)`` orders the measured channels most likely at fault, per sample
  (default: ``None``, no ranking; the harness then reports no hit@1);
* ``calibrate(runs, alpha, masks)`` moves the plug-in's own threshold so that its own alarms
  hold a false-alarm rate ``alpha`` on held-out healthy runs (the harness calls it on the
  validation runs; default: ``threshold_`` becomes the (1 - alpha) quantile of the statistic);
* every frame carries its run's line: :func:`r2rsim.diagnostics.line.frame_line` (None for
  data without one), so a physical model can read the line it is applied to;
* ``causal`` says whether the statistic at sample k uses only samples up to k (an online
  method). A plug-in that reads later samples (a centred filter, a whole-run transform) sets
  it False, as a class attribute or through an ``__init__`` parameter of that name; the harness
  marks its results "offline".

The harness hands a plug-in only the visible columns of each run, as a DataFrame indexed
like the run's samples (:data:`r2rsim.dataset.read.VISIBLE`; never labels, faults or true
states). A plug-in declares the columns it needs in ``requires`` (glob patterns); the harness
checks them with :meth:`Diagnostic.required_columns` before ``fit`` and ``score``. The
harness, not the plug-in, computes metrics. Plug-ins are found through the
``r2rsim.diagnostics`` entry-point group (:func:`r2rsim.diagnostics.registry.plugins`).
"""

from __future__ import annotations

import fnmatch
from typing import ClassVar

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator

from ..dataset.read import DRIVE_DATA
from ..errors import InputError
from ..limits import MAX_SEED
from .line import attach_line


def exceedance_threshold(statistic, alpha: float, name: str = "plug-in") -> float:
    """The threshold that at most a fraction ``alpha`` of the statistic exceeds.

    The alarm rule is strict, ``statistic > threshold``. With the n finite-or-+inf values
    sorted ascending, j = floor(alpha * n) exceedances are allowed (at most n - 1) and the
    threshold is the (n - j)-th smallest value: the (1 - alpha) empirical quantile in its
    inverted-CDF form. Values equal to the threshold do not alarm, so with ties the rate is at
    or below ``alpha``. NaN values (an undefined statistic, which never alarms) are left out;
    +inf counts as an exceedance.

    Parameters
    ----------
    statistic : array_like of float
    alpha : float
        Target exceedance fraction, 0 <= alpha < 1.
    name : str
        Named in the error when no value is finite.

    Returns
    -------
    float
    """
    s = np.asarray(statistic, dtype=float).ravel()
    s = np.sort(s[~np.isnan(s)])
    if not np.isfinite(s).any():
        raise InputError(f"{name}: no finite statistic on the calibration runs")
    if not 0.0 <= alpha < 1.0:
        raise ValueError(f"alpha must be in [0, 1), got {alpha!r}")
    n = s.size
    # the small epsilon keeps e.g. 0.29 * 100 = 28.999999999999996 from losing an exceedance
    j = min(int(np.floor(alpha * n + 1e-9)), n - 1)
    return float(s[n - 1 - j])


def _frame(run) -> pd.DataFrame:
    """The visible columns of a run (a :class:`r2rsim.dataset.read.Run` or a frame)."""
    return attach_line(run.visible(), run) if hasattr(run, "visible") else run


class Diagnostic(BaseEstimator):
    """Base class of r2rsim diagnostic plug-ins (see the module docstring)."""

    #: registry name (the entry point's name)
    name: ClassVar[str] = "abstract"
    #: glob patterns of the columns the plug-in needs; each must match at least one column
    requires: ClassVar[tuple[str, ...]] = ("meas.*",)
    #: True: the statistic at sample k depends on samples 0..k only (an online method). A
    #: plug-in whose causality is an option has an ``__init__`` parameter ``causal`` instead.
    causal: bool = True

    # ---- the contract ----------------------------------------------------------------------
    def fit(self, runs) -> Diagnostic:
        """Learn from healthy runs (a list of runs or frames); returns ``self``."""
        raise NotImplementedError

    def score(self, run) -> pd.DataFrame:
        """Per-sample statistics of one run, indexed like its samples, with a ``statistic``
        column."""
        raise NotImplementedError

    def decide(self, scores: pd.DataFrame) -> pd.Series:
        """Boolean alarms per sample: ``statistic > threshold_``."""
        return scores["statistic"] > self.threshold_

    def calibrate(self, runs, alpha: float, masks=None) -> Diagnostic:
        """Move the plug-in's own threshold so that its alarms hold the false-alarm rate
        ``alpha`` on held-out healthy runs.

        The harness calls it after :meth:`fit` with the validation runs, so that the metrics
        at the plug-in's own alarms (``pd``, ``far_ff``, ...) are taken at the requested
        false-alarm rate on any line, not at a threshold tuned on other data. The default
        sets ``threshold_`` to the (1 - alpha) empirical quantile of the statistic over the
        samples of ``masks`` (:func:`exceedance_threshold`), which is exact for the default
        :meth:`decide`. A plug-in whose :meth:`decide` is not ``statistic > threshold_``
        overrides this method so that the rule holds for its own alarms;
        :func:`r2rsim.evaluate.check_plugin` checks it.

        Parameters
        ----------
        runs : list of runs or frames
            Healthy runs the plug-in was not fitted on.
        alpha : float
            Target fraction of alarmed samples, in (0, 1).
        masks : list of array_like of bool, optional
            Per run, the samples that count (the harness passes ``label.score_mask``, false
            in the warm-up); None: every sample.

        Returns
        -------
        Diagnostic
            ``self``.
        """
        self._check_fitted()
        frames = self._frames(runs)
        if masks is None:
            masks = [np.ones(len(f), dtype=bool) for f in frames]
        pool = [
            np.asarray(self.score(f)["statistic"], dtype=float)[np.asarray(m, dtype=bool)]
            for f, m in zip(frames, masks, strict=True)
        ]
        self.threshold_ = exceedance_threshold(np.concatenate(pool), alpha, self.name)
        return self

    def is_causal(self) -> bool:
        """Whether this instance is an online method (``causal``, as set)."""
        return bool(getattr(self, "causal", True))

    def rank_channels(self, scores: pd.DataFrame) -> pd.DataFrame | None:
        """The measured channels ordered from most to least likely at fault, per sample.

        Parameters
        ----------
        scores : pandas.DataFrame
            The output of :meth:`score` for one run.

        Returns
        -------
        pandas.DataFrame or None
            Indexed like ``scores``; column 0 holds the name of the channel most likely at
            fault at that sample, column 1 the next, and so on. Names are the ``meas.``
            columns (e.g. ``meas.lc_A.tension_N``); None or NaN where the plug-in cannot
            rank. The default returns None: the plug-in does not isolate by channel, and
            the harness reports no ``hit1``.
        """
        return None

    # ---- helpers for subclasses ------------------------------------------------------------
    def required_columns(self, frame: pd.DataFrame) -> list[str]:
        """The columns matching ``requires``, in the frame's order; raises InputError naming
        the patterns nothing matches."""
        cols = [
            c
            for c in frame.columns
            if any(fnmatch.fnmatch(c, p) for p in self.requires) and c != "t_s"
        ]
        missing = [
            p for p in self.requires if not any(fnmatch.fnmatch(c, p) for c in frame.columns)
        ]
        if missing:
            drive = any(p.startswith(tuple(d.rstrip("*") for d in DRIVE_DATA)) for p in missing)
            raise InputError(
                f"{self.name}: the data has no column matching "
                f"{', '.join(missing)}"
                + (
                    " (act.*, cmd.* and ctrl.* are drive data, shown to "
                    "plug-ins only under the drive-data protocol: --drive-data, "
                    "evaluate(..., drive_data=True) or evaluation: "
                    "{drive_data: true})"
                    if drive
                    else ""
                )
            )
        return cols

    def _check_alpha(self):
        """``alpha``, a false-alarm fraction, must lie in (0, 1)."""
        a = getattr(self, "alpha", None)
        if not (isinstance(a, (int, float)) and not isinstance(a, bool) and 0 < a < 1):
            raise InputError(f"{self.name}: alpha must be a number in (0, 1), got {a!r}")

    def _number(self, key: str) -> float:
        """Parameter ``key`` as a float; a bool or a non-number is refused."""
        v = getattr(self, key)
        if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise InputError(f"{self.name}: {key} must be a number, got {v!r}")
        return float(v)

    def _check_int(self, key: str, low: int, high: int):
        """Parameter ``key`` must be an integer from ``low`` to ``high`` (bounds that keep a
        fit's memory and time finite)."""
        v = getattr(self, key)
        if not (isinstance(v, (int, np.integer)) and not isinstance(v, bool) and low <= v <= high):
            raise InputError(
                f"{self.name}: {key} must be an integer from {low} to {high}, got {v!r}"
            )

    def _check_seed(self, key: str = "random_state", high: int = MAX_SEED):
        """Parameter ``key``, a seed, must be null or an integer from 0 to ``high`` (numpy
        refuses a negative seed and scikit-learn one above 2**32 - 1, each in the middle of
        a fit)."""
        v = getattr(self, key)
        if v is not None and not (
            isinstance(v, (int, np.integer)) and not isinstance(v, bool) and 0 <= v <= high
        ):
            raise InputError(
                f"{self.name}: {key} must be null or an integer from 0 to {high}, got {v!r}"
            )

    def _check_fitted(self):
        if not any(k.endswith("_") and not k.startswith("_") for k in vars(self)):
            raise RuntimeError(f"{self.name} is not fitted: call fit first")

    @staticmethod
    def _matrix(frames, cols) -> np.ndarray:
        """Rows of the given columns from several frames, with rows holding a NaN (a
        dropped-out reading) removed."""
        X = np.vstack([f[cols].to_numpy(dtype=float) for f in frames])
        return X[np.all(np.isfinite(X), axis=1)]

    def _fit_scaling(self, X: np.ndarray) -> np.ndarray:
        """Learn each column's mean and standard deviation (``mean_``, ``std_``; a constant
        column keeps scale 1) and return X standardised."""
        self.mean_ = X.mean(axis=0)
        sd = X.std(axis=0)
        self.std_ = np.where(sd > 0, sd, 1.0)
        return (X - self.mean_) / self.std_

    def _frames(self, runs) -> list[pd.DataFrame]:
        if not isinstance(runs, (list, tuple)):
            runs = [runs]
        if not runs:
            raise InputError(f"{self.name}: fit needs at least one healthy run")
        return [_frame(r) for r in runs]
