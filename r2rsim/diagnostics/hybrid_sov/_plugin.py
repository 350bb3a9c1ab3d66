"""The ``hybrid-sov`` plug-in: the hybrid multistage model as a virtual sensor and a
residual detector (thesis Ch. 2, §2.5-2.6)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import InputError
from ..base import Diagnostic
from ..line import attach_line, frame_line
from . import _features as F
from ._line import ROLES, load_stages
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

    By default the plug-in is causal (an online method): the statistic at sample k uses
    samples 0..k only. Each channel is smoothed and differentiated by a least-squares
    quadratic over the trailing ``window_s`` window, read at the window's centre (the
    centred filter's noise; the window's last point would multiply the derivatives' noise
    variance by about 15). The load cell and pitch readings (the regression targets), the
    radius and the flags are delayed by the same half window, so every signal of a row
    refers to one instant, ``delay_s_`` (half the window, 0.24 s at 50 Hz) before the row:
    the model is the offline one, and the outputs lag by ``delay_s_``. The first window of
    a run has no statistic (NaN, no alarm). ``causal=False`` is the thesis's offline
    preprocessing: centred Savitzky-Golay filter, central differences, optional wavelet
    de-noising of the whole run; each output refers to its own sample, but reads later
    ones, and the harness marks the results "offline". Wavelet de-noising has no causal
    form here and needs ``causal=False``.

    The model needs drive data (the unwind and driven-roller torques): run the harness with
    ``--drive-data``. Given a :class:`~r2rsim.dataset.read.Run` directly, the plug-in reads
    its visible columns with drive data.

    **What a line needs** (docs/diagnostics.md §9.1): an unwind (stage 1), a dancer (stage
    3) and a driven roller (stage 4) in this order along the web, at least one idler
    between the unwind and the dancer (stage 2), and seven sensors: a roll-diameter sensor
    and an encoder on the unwind, an encoder and a load cell on stage-2 idlers, an encoder
    on the driven roller, a dancer-position sensor on the dancer and a pitch-length sensor
    on the span leaving the driven roller. Each role is found from the elements' ``stage:``
    keys and the sensors' types and positions (one candidate each); a role parameter below
    names it by id instead, which overrides the search. A stage no element is marked with
    takes its idlers from the web path (:func:`load_stages`). A wrong id, a missing
    role or an ambiguous one is refused by ``fit`` with one ``InputError`` naming the
    parameter and the line's candidates.

    Parameters
    ----------
    line : str or None
        Path of the line file whose stages and sensors the model reads. None (the default):
        the line each run was simulated on, which the harness hands the plug-in with the
        data (:func:`r2rsim.diagnostics.line.frame_line`); a run scored on a line that
        differs from the fitted one in what the model uses is then refused.
    censor_at : float
        Lower range limit of the stage-2 load cell [N]: readings at or below are censored.
    selection : {"LR", "F"}
        "LR": Tobit stages with likelihood-ratio entry tests; "F": OLS with F-tests.
    alpha_enter : float
        Entry level of forward stepwise selection.
    denoise : {"savgol", "wavelet", None}
        Preprocessing: Savitzky-Golay smoothing and differentiation, the same after wavelet
        de-noising (needs the ``wavelet`` extra and ``causal=False``), or none (raw values
        and central differences, one sample late when causal).
    window_s : float
        Smoothing window [s] (also the moving average of the residuals).
    alpha : float
        False-alarm rate of the threshold on the healthy training runs.
    random_state : int or None
        Unused (the fit is deterministic); kept for the harness.
    causal : bool
        True: online, trailing filters with the delay compensated (above); False: the
        offline, centred preprocessing of the thesis.
    unwind, dancer, driven : str or None
        Ids of the stage-1 unwind, the stage-3 dancer (translating or pivoted) and the
        stage-4 driven roller. None: the only element of that type with ``stage:`` 1, 3, 4.
    diameter_sensor, unwind_encoder : str or None
        Ids of the roll-diameter sensor and the encoder on the unwind. None: the only one
        there.
    idler_encoder, load_cell : str or None
        Ids of the encoder (the web speed) and of the load cell (the stage-2 tension the
        model is fitted to) on stage-2 idlers. None: the only one on a stage-2 idler.
    driven_encoder : str or None
        Id of the encoder on the driven roller. None: the only one there.
    dancer_sensor : str or None
        Id of the dancer-position sensor on the dancer. None: the only one there.
    pitch_sensor : str or None
        Id of the pitch-length sensor on the span leaving the driven roller. None: the only
        one there.

    Attributes
    ----------
    dt_ : float or None
        The training runs' sample period [s] (causal only: a scored run must share it).
    delay_s_ : float
        Age of each row's estimates [s]: 0 offline, half the smoothing window when causal.
    """

    name = "hybrid-sov"
    requires = ("meas.*", "act.*")

    def __init__(
        self,
        line: str | None = None,
        censor_at: float = 0.0,
        selection: str = "LR",
        alpha_enter: float = 0.05,
        denoise: str | None = "savgol",
        window_s: float = 0.5,
        alpha: float = 0.001,
        random_state: int | None = None,
        causal: bool = True,
        unwind: str | None = None,
        dancer: str | None = None,
        driven: str | None = None,
        diameter_sensor: str | None = None,
        unwind_encoder: str | None = None,
        idler_encoder: str | None = None,
        driven_encoder: str | None = None,
        load_cell: str | None = None,
        dancer_sensor: str | None = None,
        pitch_sensor: str | None = None,
    ):
        self.line = line
        self.censor_at = censor_at
        self.selection = selection
        self.alpha_enter = alpha_enter
        self.denoise = denoise
        self.window_s = window_s
        self.alpha = alpha
        self.random_state = random_state
        self.causal = causal
        self.unwind = unwind
        self.dancer = dancer
        self.driven = driven
        self.diameter_sensor = diameter_sensor
        self.unwind_encoder = unwind_encoder
        self.idler_encoder = idler_encoder
        self.driven_encoder = driven_encoder
        self.load_cell = load_cell
        self.dancer_sensor = dancer_sensor
        self.pitch_sensor = pitch_sensor

    def _frames(self, runs):
        if not isinstance(runs, (list, tuple)):
            runs = [runs]
        if not runs:
            raise InputError(f"{self.name}: fit needs at least one healthy run")
        return [attach_line(r.visible(True), r) if hasattr(r, "visible") else r for r in runs]

    def _check_params(self):
        if self.line is None:
            pass  # the run's own line (frame_line), checked in fit
        elif not isinstance(self.line, (str, Path)):
            raise InputError(f"hybrid-sov: line must be the path of a line file, got {self.line!r}")
        elif not Path(self.line).exists():
            raise InputError(f"hybrid-sov: line file {self.line!s} does not exist")
        elif not Path(self.line).is_file():  # a directory, /dev/zero: there, not a file
            raise InputError(f"hybrid-sov: line file {self.line!s} is not a regular file")
        if self.selection not in ("LR", "F"):
            raise InputError(
                f"hybrid-sov: selection must be 'LR' (Tobit) or 'F' (OLS), got {self.selection!r}"
            )
        if self.denoise not in F.DENOISE:
            raise InputError(
                f"hybrid-sov: denoise must be 'savgol', 'wavelet' or None, got {self.denoise!r}"
            )
        if not isinstance(self.causal, (bool, np.bool_)):
            raise InputError(f"hybrid-sov: causal must be true or false, got {self.causal!r}")
        if self.causal and self.denoise == "wavelet":
            raise InputError(
                "hybrid-sov: denoise='wavelet' de-noises each run as a whole, "
                "which reads later samples: it needs causal=False (offline)"
            )
        self._check_alpha()
        if not 0 < self._number("alpha_enter") < 1:
            raise InputError(
                f"hybrid-sov: alpha_enter must be a number in (0, 1), got {self.alpha_enter!r}"
            )
        # a window over a minute smears every roll change; a limit beyond ±1 MN overflows
        # the Tobit likelihood and censors nothing or everything
        if not 0 < self._number("window_s") <= 60.0:
            raise InputError(
                f"hybrid-sov: window_s must be a finite number > 0 s and at "
                f"most 60 s, got {self.window_s!r}"
            )
        if not abs(self._number("censor_at")) <= 1e6:
            raise InputError(
                f"hybrid-sov: censor_at must be a finite number of newtons "
                f"within ±1e6 N, got {self.censor_at!r}"
            )
        self._check_seed()  # unused by the method, but a value must be one
        for role in ROLES:
            value = getattr(self, role)
            if value is not None and not isinstance(value, str):
                kind = "an element" if role in ("unwind", "dancer", "driven") else "a sensor"
                raise InputError(
                    f"hybrid-sov: {role} must be null or the id of {kind} of "
                    f"the line, got {value!r}"
                )

    def _roles(self) -> dict:
        """The role parameters given (role -> id; None: found from the line)."""
        return {role: getattr(self, role) for role in ROLES}

    def _signals(self, frame):
        return F.signals(
            frame,
            self.stages_,
            self.denoise,
            self.window_s,
            self.censor_at,
            causal=bool(self.causal),
            dt=self.dt_ if self.causal else None,
        )

    def _sample_period(self, frames) -> float:
        """The training runs' common sample period [s] (the causal filter's coefficients
        are fixed by it; see :meth:`_check_period`)."""
        periods = [float(np.median(np.diff(f["t_s"].to_numpy(float)))) for f in frames]
        for i, p in enumerate(periods, start=1):
            if not abs(p - periods[0]) <= 1e-3 * periods[0]:
                raise InputError(
                    f"hybrid-sov: training run {i} is sampled every {p:.6g} s "
                    f"and run 1 every {periods[0]:.6g} s: the causal filter "
                    f"needs one sample period (or causal=False)"
                )
        return periods[0]

    def _check_period(self, frame) -> None:
        """A scored run must be sampled like the training runs: the causal filter uses the
        training period rather than one estimated from the whole scored run, so that the
        statistic at a sample depends on no later time stamp."""
        p = float(np.median(np.diff(frame["t_s"].to_numpy(float))))
        if not abs(p - self.dt_) <= 1e-3 * self.dt_:
            raise InputError(
                f"hybrid-sov: the run is sampled every {p:.6g} s, the model "
                f"was fitted on runs sampled every {self.dt_:.6g} s (the "
                f"causal filter is fixed by it; causal=False filters each run "
                f"at its own period)"
            )

    def _line(self, frame):
        """The line the model is built from: ``line=`` when given, else the run's own."""
        if self.line is not None:
            return self.line
        line = frame_line(frame)
        if line is None:
            raise InputError(
                "hybrid-sov: the data carries no line (a frame made by hand, or "
                "a dataset without its scenario/ copy): give line=<path of the "
                "line file>"
            )
        return line

    def _check_line(self, frame) -> None:
        """Refuse a run whose own line differs from the fitted model's in what the model
        uses (the stages' constants and sensors), naming what differs."""
        line = frame_line(frame)
        if line is None or self.line is not None:
            return
        now = load_stages(line, self._roles())
        for field in dataclasses.fields(now):
            if field.name == "name":
                continue
            a, b = getattr(now, field.name), getattr(self.stages_, field.name)
            if a != b:

                def shown(v):
                    return f"{v:.6g}" if isinstance(v, float) else repr(v)

                raise InputError(
                    f"hybrid-sov: the scored run's line differs from the one "
                    f"the model was fitted on in {field.name} ({shown(a)} here, "
                    f"{shown(b)} in the model): fit on data of this line"
                )

    def fit(self, runs):
        frames = self._frames(runs)
        self.required_columns(frames[0])
        self._check_params()
        self.stages_ = load_stages(self._line(frames[0]), self._roles())
        self.columns_ = F.required_columns(self.stages_)
        for f in frames:
            F.check_frame(f, self.stages_)
        self.dt_ = self._sample_period(frames) if self.causal else None
        for i, f in enumerate(frames, start=1):  # a dead sensor would train on zeros
            dead = [
                c
                for c in self.columns_
                if c in f.columns and not np.isfinite(f[c].to_numpy(float)).any()
            ]
            if dead:
                raise InputError(
                    f"hybrid-sov: training run {i} has no finite sample of "
                    f"{', '.join(dead)} (a dead sensor cannot train the model)"
                )
        sigs = [self._signals(f) for f in frames]
        self.delay_s_ = sigs[0].delay_s
        self._check_censoring(sigs)
        kind = "tobit" if self.selection == "LR" else "ols"
        try:
            self.model_ = HybridModel(self.stages_, kind, self.alpha_enter, self.censor_at).fit(
                sigs
            )
        except InputError as exc:  # the regressions' own words, with the plug-in's name
            if exc.message.startswith("hybrid-sov"):
                raise
            raise InputError(
                f"hybrid-sov: {exc.message} (the regressions are fitted on "
                f"samples thinned in time: give longer or more training "
                f"runs)"
            ) from None
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
            raise InputError(
                f"hybrid-sov: censor_at={self.censor_at:g} N censors every "
                f"stage-2 load-cell reading of the training runs (the largest "
                f"is {t2.max():.6g} N): set it to the load cell's lower range "
                f"limit, below the readings of a running line"
            )

    def _residuals(self, s: F.Signals):
        pred = self.model_.predict(s)
        raw = np.column_stack([s.T2 - pred["T_s2"].to_numpy(), s.Y - pred["Y_s4"].to_numpy()])
        raw[~s.valid] = np.nan
        n = max(1, int(round(self.window_s / s.dt)))
        smooth = pd.DataFrame(raw).rolling(n, min_periods=1).mean().to_numpy()
        return smooth, raw, pred

    def score(self, run):
        self._check_fitted()
        f = self._frames(run)[0]
        self._check_line(f)
        if self.causal:
            F.check_frame(f, self.stages_)
            self._check_period(f)
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
