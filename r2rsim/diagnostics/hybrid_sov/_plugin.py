"""The ``hybrid-sov`` plug-in: the hybrid multistage model as a virtual sensor and a
residual detector (thesis Ch. 2, thesis-methods.md §1.5)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import InputError
from ..base import Diagnostic
from . import _features as F
from ._line import load_stages
from ._model import HybridModel

_RESIDUALS = ("tension_N", "pitch_m")


class HybridSoV(Diagnostic):
    """Hybrid stream-of-variation tension model and virtual sensor (Shui 2018, Ch. 2).

    ``fit`` learns the stage models on healthy runs; ``score`` returns per sample the
    virtual-sensor tension of every stage (``T_s1_N`` ... ``T_s5_N``), the predicted pitch
    (``Y_s4_m``), the residuals between measured and predicted stage-2 tension and pitch
    (``resid.tension_N``, ``resid.pitch_m``), their healthy-standardised moving averages
    (``z.*``) and ``statistic`` = the larger |z|. ``decide`` alarms where the statistic
    exceeds its healthy (1 - ``alpha``) quantile.

    The model needs drive data (the unwind and driven-roller torques): run the harness with
    ``--drive-data``. Given a :class:`~r2rsim.dataset.read.Run` directly, the plug-in reads
    its visible columns with drive data.

    Parameters
    ----------
    line : str or None
        Path of the line file whose ``stage:`` attributes define the stages (required).
    censor_at : float
        Lower range limit of the stage-2 load cell [N]: readings at or below are censored.
    selection : {"LR", "F"}
        "LR": Tobit stages with likelihood-ratio entry tests; "F": OLS with F-tests.
    alpha_enter : float
        Entry level of forward stepwise selection.
    denoise : {"savgol", "wavelet", None}
        Preprocessing: Savitzky-Golay smoothing and differentiation, the same after wavelet
        de-noising (needs the ``wavelet`` extra), or none.
    window_s : float
        Smoothing window [s] (also the moving average of the residuals).
    alpha : float
        False-alarm rate of the threshold on the healthy training runs.
    random_state : int or None
        Unused (the fit is deterministic); kept for the harness.
    """

    name = "hybrid-sov"
    requires = ("meas.*", "act.*")

    def __init__(self, line: str | None = None, censor_at: float = 0.0,
                 selection: str = "LR", alpha_enter: float = 0.05,
                 denoise: str | None = "savgol", window_s: float = 0.5,
                 alpha: float = 0.001, random_state: int | None = None):
        self.line = line
        self.censor_at = censor_at
        self.selection = selection
        self.alpha_enter = alpha_enter
        self.denoise = denoise
        self.window_s = window_s
        self.alpha = alpha
        self.random_state = random_state

    def _frames(self, runs):
        if not isinstance(runs, (list, tuple)):
            runs = [runs]
        if not runs:
            raise InputError(f"{self.name}: fit needs at least one healthy run")
        return [r.visible(True) if hasattr(r, "visible") else r for r in runs]

    def _check_params(self):
        if self.line is None:
            raise InputError("hybrid-sov needs line=<path of the line file> (its stage: "
                             "attributes define the model)")
        if not isinstance(self.line, (str, Path)):
            raise InputError(f"hybrid-sov: line must be the path of a line file, "
                             f"got {self.line!r}")
        if not Path(self.line).exists():
            raise InputError(f"hybrid-sov: line file {self.line!s} does not exist")
        if not Path(self.line).is_file():  # a directory, /dev/zero: there, but not a file
            raise InputError(f"hybrid-sov: line file {self.line!s} is not a regular file")
        if self.selection not in ("LR", "F"):
            raise InputError(f"hybrid-sov: selection must be 'LR' (Tobit) or 'F' (OLS), "
                             f"got {self.selection!r}")
        if self.denoise not in F.DENOISE:
            raise InputError(f"hybrid-sov: denoise must be 'savgol', 'wavelet' or None, got "
                             f"{self.denoise!r}")
        self._check_alpha()
        if not 0 < self._number("alpha_enter") < 1:
            raise InputError(f"hybrid-sov: alpha_enter must be a number in (0, 1), "
                             f"got {self.alpha_enter!r}")
        # a window over a minute smears every roll change; a limit beyond ±1 MN overflows
        # the Tobit likelihood and censors nothing or everything
        if not 0 < self._number("window_s") <= 60.0:
            raise InputError(f"hybrid-sov: window_s must be a finite number > 0 s and at "
                             f"most 60 s, got {self.window_s!r}")
        if not abs(self._number("censor_at")) <= 1e6:
            raise InputError(f"hybrid-sov: censor_at must be a finite number of newtons "
                             f"within ±1e6 N, got {self.censor_at!r}")
        self._check_seed()  # unused by the method, but a value must be one

    def _signals(self, frame):
        return F.signals(frame, self.stages_, self.denoise, self.window_s, self.censor_at)

    def fit(self, runs):
        frames = self._frames(runs)
        self.required_columns(frames[0])
        self._check_params()
        self.stages_ = load_stages(self.line)
        self.columns_ = F.required_columns(self.stages_)
        for i, f in enumerate(frames, start=1):  # a dead sensor would train on zeros
            dead = [c for c in self.columns_
                    if c in f.columns and not np.isfinite(f[c].to_numpy(float)).any()]
            if dead:
                raise InputError(f"hybrid-sov: training run {i} has no finite sample of "
                                 f"{', '.join(dead)} (a dead sensor cannot train the model)")
        sigs = [self._signals(f) for f in frames]
        self._check_censoring(sigs)
        kind = "tobit" if self.selection == "LR" else "ols"
        try:
            self.model_ = HybridModel(self.stages_, kind, self.alpha_enter,
                                      self.censor_at).fit(sigs)
        except InputError as exc:  # the regressions' own words, with the plug-in's name
            if exc.message.startswith("hybrid-sov"):
                raise
            raise InputError(f"hybrid-sov: {exc.message} (the regressions are fitted on "
                             f"samples thinned in time: give longer or more training "
                             f"runs)") from None
        resid = np.vstack([self._residuals(s)[0] for s in sigs])
        ok = np.all(np.isfinite(resid), axis=1)
        self.resid_mean_ = resid[ok].mean(axis=0)
        sd = resid[ok].std(axis=0)
        self.resid_std_ = np.where(sd > 0, sd, 1.0)
        stat = np.max(np.abs((resid[ok] - self.resid_mean_) / self.resid_std_), axis=1)
        self.threshold_ = float(np.quantile(stat, 1.0 - self.alpha))
        return self

    def _check_censoring(self, sigs: list[F.Signals]) -> None:
        """Refuse a ``censor_at`` at or above every stage-2 load-cell reading of the training
        runs: with every reading censored the Tobit likelihood has no maximum (it grows as
        the predicted tension falls without bound), and the fit ended with statsmodels'
        warnings and a meaningless model."""
        t2 = np.concatenate([s.T2[s.valid] for s in sigs])
        if t2.size and not (t2 > self.censor_at).any():
            raise InputError(f"hybrid-sov: censor_at={self.censor_at:g} N censors every "
                             f"stage-2 load-cell reading of the training runs (the largest "
                             f"is {t2.max():.6g} N): set it to the load cell's lower range "
                             f"limit, below the readings of a running line")

    def _residuals(self, s: F.Signals):
        pred = self.model_.predict(s)
        raw = np.column_stack([s.T2 - pred["T_s2"].to_numpy(), s.Y - pred["Y_s4"].to_numpy()])
        raw[~s.valid] = np.nan
        n = max(1, int(round(self.window_s / float(np.median(np.diff(s.t))))))
        smooth = pd.DataFrame(raw).rolling(n, min_periods=1).mean().to_numpy()
        return smooth, raw, pred

    def score(self, run):
        self._check_fitted()
        f = self._frames(run)[0]
        s = self._signals(f)
        smooth, raw, pred = self._residuals(s)
        z = (smooth - self.resid_mean_) / self.resid_std_
        out = pd.DataFrame(index=f.index)
        for k in range(1, 6):
            out[f"T_s{k}_N"] = pred[f"T_s{k}"].to_numpy()
        out["Y_s4_m"] = pred["Y_s4"].to_numpy()
        for i, name in enumerate(_RESIDUALS):
            out[f"resid.{name}"] = raw[:, i]
            out[f"z.{name}"] = z[:, i]
        absz = np.abs(z)
        stat = np.full(len(z), np.nan)
        ok = np.isfinite(absz).any(axis=1)
        stat[ok] = np.nanmax(absz[ok], axis=1)
        out.insert(0, "statistic", stat)
        return out

    def decide(self, scores: pd.DataFrame) -> pd.Series:
        """Alarms where the statistic exceeds the healthy threshold (NaN: no alarm)."""
        return (scores["statistic"] > self.threshold_).fillna(False).astype(bool)

    def rank_channels(self, scores: pd.DataFrame) -> pd.DataFrame:
        """The load cell or the pitch sensor first, by the larger |z|."""
        cols = [self.stages_.column("tension"), self.stages_.column("pitch")]
        z = np.abs(scores[[f"z.{n}" for n in _RESIDUALS]].to_numpy())
        order = np.argsort(-np.nan_to_num(z, nan=-np.inf), axis=1)
        return pd.DataFrame(np.array(cols, dtype=object)[order], index=scores.index)
