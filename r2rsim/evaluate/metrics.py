"""Fault-detection evaluation metrics (docs/diagnostics.md §5: M1–M7, M9, M15).

Every metric works on a list of :class:`RunData`, one per simulated run, holding plain numpy
arrays: the sample times, the ground truth ``y(k)``, the score mask, and the detector's alarm,
score and (optionally) diagnosis. Notation follows §5.1: ``tau`` is a faulty run's first faulty
sample, ``eps`` its last faulty sample, ``N`` its number of samples (indices are 0-based here).

Conventions shared by all metrics
---------------------------------
* **Masking.** Samples with ``scored == False`` (warm-up) are excluded from every metric. The
  alarm is ANDed with the mask before anything else (:attr:`RunData.effective_alarm`), so an
  alarm raised in an unscored sample changes no metric: it neither counts as a false alarm nor
  makes a later alarm event look like a continuation.
* **Persistence.** With ``m > 1`` an alarm event counts for detection only if it lasts at least
  ``m`` samples; its onset is still the first sample of the event (§5.1, M4).
* **Pooling.** Sample-level rates (FAR, DR, IA, ROC-AUC, AP) pool samples over runs; run-level
  metrics (P_D, DD) average over runs. Confidence intervals resample runs, never samples
  (:func:`bootstrap_ci`, §5.5).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, replace

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray
from scipy.stats import binomtest, rankdata

from ..limits import MAX_VUS_BUFFER_SAMPLES

__all__ = [
    "ConfidenceInterval",
    "DelayStats",
    "Detectability",
    "MDM_SIGNIFICANCE",
    "FalseAlarmEvents",
    "FarResult",
    "RunData",
    "RunDetection",
    "apply_threshold",
    "average_precision",
    "bootstrap_ci",
    "bootstrap_indices",
    "ci_percentiles",
    "calibrate_threshold",
    "confirmed",
    "DETECTION_WINDOW_S",
    "detect_run",
    "detectability",
    "detection_delay",
    "detection_probability",
    "detection_rate",
    "detection_windows",
    "false_alarm_events",
    "far",
    "fault_free_scores",
    "isolation_accuracy",
    "hit_at_n",
    "isolation_counts",
    "localization_counts",
    "null_detection",
    "null_detection_rate",
    "null_outcomes",
    "percentile_interval",
    "pooled_rate",
    "pooled_scores",
    "range_pr_auc",
    "restrict_to_mode",
    "roc_auc",
    "run_hit",
    "scored_groups",
    "steady_counts",
    "steady_detection",
    "steady_detection_rate",
    "vus_pr",
    "window_counts",
]

# Relative tolerance (in sample periods) when comparing t[eps] + h with sample times, so that a
# grace period that is a whole number of periods lands on the intended sample despite rounding.
_TIME_RTOL = 1e-9

#: Default detection window W [s]: a fault must be detected within W of the moment it is fully
#: developed (its onset for a step; the end of its ramp for a degradation). 20 s covers five
#: transport time constants L/v of the slowest span of the shipped lines at their slowest
#: speed (1.5 m at 0.5 m/s: L/v = 3 s, so 15 s), by which a step has settled through the span
#: and its tension loop, with a margin for the sensors' filters and persistence. Over a longer
#: window a detector with a sample false-alarm rate of 1 % would "detect" most faults by
#: chance (docs/diagnostics.md §5.1).
DETECTION_WINDOW_S = 20.0

#: severity at or above which a sample is in the steady state (label.severity is float32)
STEADY_SEVERITY = 1.0 - 1e-6


# --------------------------------------------------------------------------- persistence


def confirmed(alarm: ArrayLike, m: int = 1) -> NDArray[np.bool_]:
    """Persistence rule: the alarm is *confirmed* at ``k`` iff ``alarm[k..k+m-1]`` are all true.

    Parameters
    ----------
    alarm : array_like of bool, shape (N,)
        Per-sample alarm.
    m : int, default 1
        Number of consecutive alarmed samples required (m >= 1).

    Returns
    -------
    numpy.ndarray of bool, shape (N,)
        Confirmed alarm. Near the end of the run, where fewer than ``m`` samples remain, the
        window is incomplete and the alarm is not confirmed.
    """
    a = np.asarray(alarm, dtype=bool)
    if a.ndim != 1:
        raise ValueError("alarm must be one-dimensional")
    if int(m) != m or m < 1:
        raise ValueError(f"persistence m must be an integer >= 1, got {m!r}")
    m = int(m)
    n = a.size
    out = np.zeros(n, dtype=bool)
    if n < m:
        return out
    # c[j] = number of alarms in a[0:j]; the window a[k:k+m] is full when its count equals m
    c = np.concatenate(([0], np.cumsum(a, dtype=np.int64)))
    out[: n - m + 1] = (c[m:] - c[: n - m + 1]) == m
    return out


def _onsets(a: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Samples where an alarm event (maximal run of consecutive alarms) starts."""
    prev = np.concatenate(([False], a[:-1]))
    return a & ~prev


# --------------------------------------------------------------------------- run container


@dataclass(frozen=True)
class RunData:
    """One run's ground truth and detector output, as aligned per-sample arrays.

    Parameters
    ----------
    t : array_like of float, shape (N,)
        Sample times in seconds, strictly increasing.
    faulty : array_like of bool, shape (N,)
        Ground truth y(k): at least one fault active at sample k.
    scored : array_like of bool, shape (N,)
        Score mask: False in warm-up (or any other excluded sample).
    alarm : array_like of bool, shape (N,)
        Detector alarm a(k).
    score : array_like of float, shape (N,), optional
        Anomaly score s(k), larger = more anomalous. Needed by M6/M7 only.
    diagnosis : array_like of str, shape (N,), optional
        Diagnosed class d(k) (a fault type, ``"normal"`` or ``"unknown"``). Needed by M9 only.
    true_type : array_like of str, shape (N,), optional
        True fault type per sample, ``"normal"`` where not faulty. Needed by M9 only.
    magnitude : float, default nan
        The run's fault magnitude (nan for fault-free runs). Used by M15.
    mode : array_like of str, shape (N,), optional
        Operating mode per sample (``label.mode``). Needed by :func:`restrict_to_mode` only.
    severity : array_like of float, shape (N,), optional
        Fault severity p(t) of the primary fault per sample (``label.severity``, 1 = fully
        developed). Needed by the steady-state window only (:func:`steady_counts`).
    channel_truth : array_like of bool, shape (N, C), optional
        ``channel_truth[k, c]``: measured channel ``channels[c]`` is corrupted by a sensor fault
        at sample k (``label.ch.*``). Needed by M13 only.
    ranking : array_like of int, shape (N, R), optional
        The detector's channel ranking per sample, most likely first, as indices into
        ``channels`` (-1: a channel outside ``channels`` or no ranking). Needed by M13 only.
    channels : tuple of str, default ()
        Names of the columns of ``channel_truth``.
    """

    t: NDArray[np.float64]
    faulty: NDArray[np.bool_]
    scored: NDArray[np.bool_]
    alarm: NDArray[np.bool_]
    score: NDArray[np.float64] | None = None
    diagnosis: NDArray[np.str_] | None = None
    true_type: NDArray[np.str_] | None = None
    magnitude: float = math.nan
    mode: NDArray[np.str_] | None = None
    severity: NDArray[np.float64] | None = None
    channel_truth: NDArray[np.bool_] | None = None
    ranking: NDArray[np.int64] | None = None
    channels: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        # frozen dataclass: normalise the arrays through object.__setattr__
        t = np.asarray(self.t, dtype=float)
        if t.ndim != 1 or t.size == 0:
            raise ValueError("t must be a non-empty one-dimensional array")
        if t.size > 1 and not np.all(np.diff(t) > 0):
            raise ValueError("t must be strictly increasing")
        object.__setattr__(self, "t", t)
        for name in ("faulty", "scored", "alarm"):
            object.__setattr__(self, name, self._aligned(name, bool))
        if self.score is not None:
            object.__setattr__(self, "score", self._aligned("score", float))
        for name in ("diagnosis", "true_type", "mode"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, self._aligned(name, str))
        if self.severity is not None:
            object.__setattr__(self, "severity", self._aligned("severity", float))
        object.__setattr__(self, "magnitude", float(self.magnitude))
        object.__setattr__(self, "channels", tuple(self.channels))
        if self.channel_truth is not None:
            object.__setattr__(
                self,
                "channel_truth",
                self._aligned("channel_truth", bool, (self.n, len(self.channels))),
            )
        if self.ranking is not None:
            r = np.asarray(self.ranking, dtype=np.int64)
            object.__setattr__(
                self,
                "ranking",
                self._aligned("ranking", np.int64, (self.n, r.shape[1] if r.ndim == 2 else -1)),
            )

    def _aligned(self, name: str, dtype: type, shape: tuple | None = None) -> NDArray:
        a: NDArray = np.asarray(getattr(self, name), dtype=dtype)
        want = self.t.shape if shape is None else shape
        if a.shape != want:
            raise ValueError(
                f"{name} has shape {a.shape}, expected {want}"
                + (" (like t)" if shape is None else "")
            )
        return a

    @property
    def n(self) -> int:
        """Number of samples N."""
        return int(self.t.size)

    @property
    def is_faulty(self) -> bool:
        """True if any sample is faulty."""
        return bool(self.faulty.any())

    @property
    def onset(self) -> int | None:
        """tau: index of the first faulty sample (None for a fault-free run)."""
        idx = np.flatnonzero(self.faulty)
        return int(idx[0]) if idx.size else None

    @property
    def end(self) -> int | None:
        """eps: index of the last faulty sample (None for a fault-free run)."""
        idx = np.flatnonzero(self.faulty)
        return int(idx[-1]) if idx.size else None

    @property
    def period(self) -> float:
        """Sample period in seconds: the median spacing of ``t`` (robust to one odd step)."""
        if self.n < 2:
            raise ValueError("the sample period needs at least two samples")
        return float(np.median(np.diff(self.t)))

    @property
    def effective_alarm(self) -> NDArray[np.bool_]:
        """The alarm restricted to scored samples; every metric uses this, not ``alarm``."""
        return self.alarm & self.scored

    def full_onset(self) -> int | None:
        """Index of the first sample at which the fault is fully developed: the first faulty
        sample with severity 1 (the end of a ramp), tau without ``severity`` or for a step,
        and eps when the fault never develops fully within the run (None when fault-free)."""
        tau = self.onset
        if tau is None or self.severity is None:
            return tau
        full = np.flatnonzero(self.faulty & (self.severity >= STEADY_SEVERITY))
        return int(full[0]) if full.size else self.end

    def window_end(self, h: float = 0.0, w: float = DETECTION_WINDOW_S) -> int | None:
        """Last index of the detection window [tau, min(t_full + w, t_eps + h, last sample)].

        Parameters
        ----------
        h : float, default 0
            Grace period after the fault end, in seconds (h >= 0).
        w : float, default :data:`DETECTION_WINDOW_S`
            Detection window in seconds after the fault is fully developed
            (:meth:`full_onset`); ``inf`` for a window up to the fault's end (plus h).

        Returns
        -------
        int or None
            The largest index k with t[k] <= min(t_full + w, t[eps] + h) (None for a
            fault-free run).
        """
        eps = self.end
        if eps is None:
            return None
        if not h >= 0:
            raise ValueError(f"grace period h must be >= 0, got {h!r}")
        if not w > 0:
            raise ValueError(f"detection window w must be > 0 s, got {w!r}")
        tol = _TIME_RTOL * (self.period if self.n > 1 else 1.0)
        end = (
            eps if h == 0 else int(np.searchsorted(self.t, self.t[eps] + h + tol, side="right") - 1)
        )
        if math.isfinite(w):
            limit = self.t[self.full_onset()] + w
            end = min(end, int(np.searchsorted(self.t, limit + tol, side="right") - 1))
        return end


def _fault_slice(run: RunData) -> slice:
    """The samples [tau, eps] of a faulty run."""
    tau, eps = run.onset, run.end
    if tau is None or eps is None:
        raise ValueError("a faulty run is needed (no faulty sample found)")
    return slice(tau, eps + 1)


def restrict_to_mode(run: RunData, mode: str) -> RunData:
    """The run seen through one operating regime: only its samples in ``mode`` stay scored.

    The ground truth is unchanged (the onset tau, the fault window and whether the run is
    faulty are those of the whole run), so a sample keeps its role (fault-free run, pre-onset,
    fault window) and only the samples of other regimes leave every per-sample metric.

    Parameters
    ----------
    run : RunData
        A run with ``mode`` (``label.mode`` per sample).
    mode : str
        The regime to keep.

    Returns
    -------
    RunData
        A copy whose ``scored`` is ``scored & (mode == mode)``.
    """
    if run.mode is None:
        raise ValueError("restrict_to_mode needs a run with a per-sample mode")
    return replace(run, scored=run.scored & (run.mode == mode))


def _faulty_runs(runs: Sequence[RunData]) -> list[RunData]:
    return [r for r in runs if r.is_faulty]


# --------------------------------------------------------------------------- M1, M2


@dataclass(frozen=True)
class FarResult:
    """Sample false-alarm rates (M1), with the counts behind them.

    Attributes
    ----------
    far_ff : float
        Alarm fraction over scored samples of fully fault-free runs (nan if there are none).
    far_pre : float
        Alarm fraction over scored pre-onset samples (k < tau) of faulty runs (nan if none).
    far : float
        Alarm fraction over all scored fault-free samples of all runs (includes the samples after
        an intermittent fault has ended, which belong to neither stratum).
    alarms_ff, n_ff, alarms_pre, n_pre, alarms_all, n_all : int
        Numerators and denominators of the three rates.
    n_masked : int
        Masked (unscored) samples over all runs, reported separately (§5.1).
    """

    far_ff: float
    far_pre: float
    far: float
    alarms_ff: int
    n_ff: int
    alarms_pre: int
    n_pre: int
    alarms_all: int
    n_all: int
    n_masked: int


def _ratio(num: ArrayLike, den: ArrayLike) -> NDArray[np.float64]:
    """``num / den`` element-wise; nan where ``den`` is not positive (a rate of nothing)."""
    num, den = np.asarray(num), np.asarray(den)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1), np.nan)


def pooled_rate(hits: ArrayLike, totals: ArrayLike) -> NDArray[np.float64]:
    """The rate of counts pooled over runs: summed hits over summed totals along the last
    axis (runs), nan where the totals are 0.

    The one pooling of every count-based rate: the metrics here pool a list of runs (1-d
    counts, a 0-d result); the harness pools the rows of a bootstrap replicate matrix
    (replicates x runs) in one call.
    """
    return _ratio(np.sum(hits, axis=-1), np.sum(totals, axis=-1))


def _pooled(counts: Iterable[tuple[int, int]]) -> float:
    """:func:`pooled_rate` of (hits, total) pairs, one per run."""
    pairs = np.array(list(counts), dtype=float).reshape(-1, 2)
    return float(pooled_rate(pairs[:, 0], pairs[:, 1]))


def far(runs: Sequence[RunData]) -> FarResult:
    """M1: sample false-alarm rate, in the strata FAR_ff and FAR_pre.

    Parameters
    ----------
    runs : sequence of RunData
        Runs to pool; fault-free runs feed FAR_ff, faulty runs' pre-onset samples FAR_pre.

    Returns
    -------
    FarResult
        The rates and their counts; a rate is nan when its stratum has no scored sample.
    """
    a_ff = n_ff = a_pre = n_pre = a_all = n_all = n_masked = 0
    for r in runs:
        a = r.effective_alarm
        ok = r.scored & ~r.faulty
        n_masked += int((~r.scored).sum())
        a_all += int(a[ok].sum())
        n_all += int(ok.sum())
        tau = r.onset
        if tau is None:
            a_ff += int(a[ok].sum())
            n_ff += int(ok.sum())
        else:
            pre = r.scored[:tau]  # all samples before tau are fault-free by definition of tau
            a_pre += int(a[:tau].sum())
            n_pre += int(pre.sum())
    return FarResult(
        far_ff=float(_ratio(a_ff, n_ff)),
        far_pre=float(_ratio(a_pre, n_pre)),
        far=float(_ratio(a_all, n_all)),
        alarms_ff=a_ff,
        n_ff=n_ff,
        alarms_pre=a_pre,
        n_pre=n_pre,
        alarms_all=a_all,
        n_all=n_all,
        n_masked=n_masked,
    )


@dataclass(frozen=True)
class FalseAlarmEvents:
    """False-alarm event rate (M2).

    Attributes
    ----------
    per_hour : float
        FA/h: false-alarm events per hour of scored fault-free time (nan if that time is 0).
    mtbfa_h : float
        Mean time between false alarms in hours, 1 / FA/h (inf when there is no event).
    n_events : int
        Alarm events starting at a scored fault-free sample.
    hours : float
        Scored fault-free duration in hours.
    """

    per_hour: float
    mtbfa_h: float
    n_events: int
    hours: float


def false_alarm_events(runs: Sequence[RunData]) -> FalseAlarmEvents:
    """M2: false-alarm events per hour (FA/h) and mean time between false alarms (MTBFA).

    An alarm event is a maximal run of consecutive (effective) alarms. It is a false-alarm
    event if it *starts* at a scored fault-free sample; an alarm that starts during a fault and
    lasts past its end is not one. The duration is the number of scored fault-free samples times
    each run's sample period (:attr:`RunData.period`).

    Parameters
    ----------
    runs : sequence of RunData
        Runs to pool (fault-free and faulty; every fault-free sample counts).

    Returns
    -------
    FalseAlarmEvents
        FA/h, MTBFA (hours), the event count and the duration in hours.
    """
    n_events = 0
    seconds = 0.0
    for r in runs:
        ok = r.scored & ~r.faulty
        n_events += int((_onsets(r.effective_alarm) & ok).sum())
        n_ok = int(ok.sum())
        if n_ok:
            seconds += n_ok * r.period
    hours = seconds / 3600.0
    rate = float(_ratio(n_events, hours))
    if math.isnan(rate):
        mtbfa = math.nan
    else:
        mtbfa = math.inf if n_events == 0 else 1.0 / rate
    return FalseAlarmEvents(per_hour=rate, mtbfa_h=mtbfa, n_events=n_events, hours=hours)


# --------------------------------------------------------------------------- M3


def detection_rate(runs: Sequence[RunData]) -> float:
    """M3: sample detection rate DR over the fault windows [tau, eps] of the faulty runs.

    Parameters
    ----------
    runs : sequence of RunData
        Runs to pool; fault-free runs are ignored.

    Returns
    -------
    float
        Alarmed scored samples in [tau, eps] / scored samples in [tau, eps], pooled over faulty
        runs (nan if there is none). Samples inside the window where an intermittent fault is
        momentarily inactive count, as in the §5.2 formula.
    """
    return _pooled(window_counts(r) for r in _faulty_runs(runs))


def window_counts(run: RunData) -> tuple[int, int]:
    """Alarmed scored samples and scored samples in a faulty run's window [tau, eps] (the
    numerator and denominator of M3 for one run)."""
    sl = _fault_slice(run)
    return int(run.effective_alarm[sl].sum()), int(run.scored[sl].sum())


# --------------------------------------------------------------------------- M3/M5, steady state


def _steady(run: RunData) -> NDArray[np.bool_]:
    if run.severity is None:
        raise ValueError("the steady-state window needs runs with a per-sample severity")
    return run.faulty & (run.severity >= STEADY_SEVERITY)


def steady_counts(run: RunData) -> tuple[int, int]:
    """Alarmed scored samples and scored samples among a run's steady-state fault samples.

    A steady-state sample is faulty with severity p(t) = 1: the fault is fully developed, so
    the ramps of a degradation and the off-phases of an intermittent fault are left out (unlike
    M3, which counts every sample of [tau, eps]).

    Parameters
    ----------
    run : RunData
        A run with ``severity``.

    Returns
    -------
    tuple of int
        (alarmed, total) over the scored steady-state samples; (0, 0) for a fault-free run.
    """
    sel = _steady(run) & run.scored
    return int(run.effective_alarm[sel].sum()), int(sel.sum())


def steady_detection_rate(runs: Sequence[RunData]) -> float:
    """M3 over the steady-state window: alarmed / scored samples with severity 1, pooled.

    Parameters
    ----------
    runs : sequence of RunData
        Runs with ``severity``.

    Returns
    -------
    float
        The rate (nan when no scored sample has severity 1).
    """
    return _pooled(steady_counts(r) for r in runs)


def steady_detection(
    run: RunData, m: int = 1, h: float = 0.0, w: float = DETECTION_WINDOW_S
) -> RunDetection | None:
    """M4/M5 from the start of the steady state: detection of a fully developed fault.

    The onset is tau_s, the first faulty sample with severity 1, and the window ends
    ``min(t(tau_s) + w, t(eps) + h)``. As everywhere (:func:`detect_run`), an alarm event
    that began during the ramp and is still on at tau_s detects with delay 0: the question is
    how long a fully developed fault goes unflagged, not whether the ramp was caught.

    Parameters
    ----------
    run : RunData
        A faulty run with ``severity``.
    m, h, w
        Persistence, grace period and detection window in seconds, as in :func:`detect_run`.

    Returns
    -------
    RunDetection or None
        None when the run never reaches severity 1.
    """
    steady = _steady(run)
    if not steady.any():
        return None
    return detect_run(replace(run, faulty=steady), m, h, w)


# --------------------------------------------------------------------------- M4, M5


@dataclass(frozen=True)
class RunDetection:
    """Run-level detection outcome of one faulty run (M4/M5).

    Attributes
    ----------
    eligible : bool
        False when no sample of the detection window is scored (the run is then left out of
        P_D and DD rather than counted as a miss).
    detected : bool
        A confirmed alarm is on somewhere in the window [tau, w] (:func:`detect_run`).
    k_star : int or None
        Index of the detection (None if missed).
    delay : float
        DD = t[k*] - t[tau] in seconds (nan if missed).
    horizon : float
        t[w] - t[tau]: what a miss contributes to the censored mean.
    magnitude : float
        The run's fault magnitude (copied from :class:`RunData`, for M15).
    onset_s : float
        t[tau], the time of the onset (the pretend onsets of :func:`null_detection`).
    """

    eligible: bool
    detected: bool
    k_star: int | None
    delay: float
    horizon: float
    magnitude: float
    onset_s: float = math.nan


class _Events:
    """One run's alarm events, prepared for many detection windows: the effective alarm, the
    start of the event each alarmed sample belongs to, and whether each event start is
    confirmed (the event lasts at least m samples)."""

    def __init__(self, run: RunData, m: int):
        self.a = run.effective_alarm
        self.conf = confirmed(self.a, m)
        idx = np.arange(self.a.size)
        starts = np.where(_onsets(self.a), idx, -1)
        self.start = np.maximum.accumulate(starts) if starts.size else starts
        # a confirmed event starts here (the onsets a detection can be taken at)
        self.conf_onset = self.conf & _onsets(self.a)

    def first_detection(self, tau: int, end: int) -> int | None:
        """The detection in the window [tau, end]: tau itself when a confirmed event is on at
        tau (whenever it began), else the first confirmed event starting in (tau, end]."""
        if self.a[tau] and self.conf[self.start[tau]]:
            return tau
        ks = np.flatnonzero(self.conf_onset[tau : end + 1])
        return tau + int(ks[0]) if ks.size else None


def detect_run(
    run: RunData, m: int = 1, h: float = 0.0, w: float = DETECTION_WINDOW_S
) -> RunDetection:
    """Find the detection of one faulty run (M4).

    The detection window is [tau, min(t_full + w, t_eps + h, last sample)]
    (:meth:`RunData.window_end`). The run is detected at the first sample of the window at
    which a *confirmed* alarm event (one lasting at least ``m`` consecutive samples) is on:

    * an event that is on at tau counts from tau (delay 0) if it is confirmed, whenever it
      began: an alarm raised shortly before a fault and still on when it starts does not turn
      a detected fault into a miss (its samples before tau stay false alarms in ``far_pre``
      and ``fa_per_h``);
    * otherwise the first confirmed event that starts inside the window detects, at its start.

    The same rule, applied to fault-free runs with pretend onsets, gives the null rate
    (:func:`null_detection`), which says how much of P_D chance alone explains.

    Parameters
    ----------
    run : RunData
        A faulty run.
    m : int, default 1
        Persistence: minimum number of consecutive alarmed samples.
    h : float, default 0
        Grace period in seconds after the fault end.
    w : float, default :data:`DETECTION_WINDOW_S`
        Detection window in seconds after the fault is fully developed (``inf``: up to the
        fault's end plus h).

    Returns
    -------
    RunDetection
        Whether and where the run was detected, the delay and the censoring horizon.
    """
    tau, end = run.onset, run.window_end(h, w)
    if tau is None or end is None:
        raise ValueError("detect_run needs a faulty run (no faulty sample found)")
    horizon = float(run.t[end] - run.t[tau])
    eligible = bool(run.scored[tau : end + 1].any())
    k_star = _Events(run, m).first_detection(tau, end) if eligible else None
    detected = k_star is not None
    delay = float(run.t[k_star] - run.t[tau]) if detected else math.nan
    return RunDetection(
        eligible=eligible,
        detected=detected,
        k_star=k_star,
        delay=delay,
        horizon=horizon,
        magnitude=run.magnitude,
        onset_s=float(run.t[tau]),
    )


def _detections(runs: Sequence[RunData], m: int, h: float, w: float) -> list[RunDetection]:
    dets = [detect_run(r, m, h, w) for r in _faulty_runs(runs)]
    return [d for d in dets if d.eligible]


def detection_probability(
    runs: Sequence[RunData], m: int = 1, h: float = 0.0, w: float = DETECTION_WINDOW_S
) -> float:
    """M4: run-level detection probability P_D.

    Parameters
    ----------
    runs : sequence of RunData
        Runs; fault-free runs and runs whose window is entirely unscored are ignored.
    m, h, w
        As in :func:`detect_run` (persistence, grace period and detection window in seconds).

    Returns
    -------
    float
        Detected faulty runs / faulty runs (nan if there is none).
    """
    dets = _detections(runs, m, h, w)
    return float(_ratio(sum(d.detected for d in dets), len(dets)))


def detection_windows(
    runs: Sequence[RunData], h: float = 0.0, w: float = DETECTION_WINDOW_S
) -> list[tuple[float, float]]:
    """The detection windows of the eligible faulty runs as (onset time, length) in seconds:
    the pretend windows of :func:`null_detection`, drawn like the real ones."""
    out = []
    for r in _faulty_runs(runs):
        tau, end = r.onset, r.window_end(h, w)
        if tau is not None and end is not None and r.scored[tau : end + 1].any():
            out.append((float(r.t[tau]), float(r.t[end] - r.t[tau])))
    return out


def null_detection(
    run: RunData, windows: Sequence[tuple[float, float]], m: int = 1
) -> tuple[int, int]:
    """The detection rule of :func:`detect_run` applied to a fault-free run at pretend onsets.

    Each window (onset time t0, length L) is placed on the run as [first sample with
    t >= t0, last sample with t <= t0 + L]; a window past the run's end or without a scored
    sample is not eligible. The result counts how often the detector "detects" a fault that
    is not there, with the same persistence and window lengths as the real faults.

    Parameters
    ----------
    run : RunData
        A fault-free run.
    windows : sequence of (float, float)
        Pretend windows (:func:`detection_windows` of the faulty runs), in seconds.
    m : int, default 1
        Persistence.

    Returns
    -------
    tuple of int
        (windows detected, windows eligible).
    """
    outcomes = null_outcomes(run, windows, m)
    return (sum(o is True for o in outcomes), sum(o is not None for o in outcomes))


def null_outcomes(
    run: RunData, windows: Sequence[tuple[float, float]], m: int = 1
) -> list[bool | None]:
    """Per pretend window of :func:`null_detection`: True ("detected"), False, or None when
    the window is not eligible (past the run's end, or without a scored sample)."""
    if run.is_faulty:
        raise ValueError("null_detection needs a fault-free run")
    if not windows:
        return []
    tol = _TIME_RTOL * (run.period if run.n > 1 else 1.0)
    ev = _Events(run, m)
    out: list[bool | None] = []
    for t0, length in windows:
        tau = int(np.searchsorted(run.t, t0 - tol, side="left"))
        end = int(np.searchsorted(run.t, t0 + length + tol, side="right") - 1)
        if tau >= run.n or end < tau or not run.scored[tau : end + 1].any():
            out.append(None)
        else:
            out.append(ev.first_detection(tau, end) is not None)
    return out


def null_detection_rate(
    runs: Sequence[RunData], windows: Sequence[tuple[float, float]], m: int = 1
) -> float:
    """``pd_null``: the share of pretend windows on the fault-free runs that are "detected"
    (:func:`null_detection`, pooled over runs; nan when none is eligible). A detector that
    alarms at random scores P_D close to this rate."""
    return _pooled(null_detection(r, windows, m) for r in runs if not r.is_faulty)


@dataclass(frozen=True)
class DelayStats:
    """Detection-delay summary (M5), in seconds.

    Attributes
    ----------
    median, mean, p90 : float
        Over detected runs only (nan if none); p90 uses linear interpolation between order
        statistics (``numpy.percentile`` default).
    censored_mean : float
        Mean over all faulty runs, a miss contributing its horizon t[w] - t[tau].
    n_detected, n_missed : int
        Run counts.
    """

    median: float
    mean: float
    p90: float
    censored_mean: float
    n_detected: int
    n_missed: int


def detection_delay(
    runs: Sequence[RunData], m: int = 1, h: float = 0.0, w: float = DETECTION_WINDOW_S
) -> DelayStats:
    """M5: detection delay DD = t[k*] - t[tau] over detected runs, with the miss count.

    The delay is measured per run from the onset, never averaged over alarmed samples.

    Parameters
    ----------
    runs : sequence of RunData
        Runs; fault-free runs and runs whose window is entirely unscored are ignored.
    m, h, w
        As in :func:`detect_run`.

    Returns
    -------
    DelayStats
        Median, mean and 90th percentile over detected runs, censored mean over all faulty runs,
        and the detected/missed counts.
    """
    dets = _detections(runs, m, h, w)
    dd = np.array([d.delay for d in dets if d.detected], dtype=float)
    censored = np.array([d.delay if d.detected else d.horizon for d in dets], dtype=float)
    if dd.size:
        med, mean, p90 = float(np.median(dd)), float(dd.mean()), float(np.percentile(dd, 90))
    else:
        med = mean = p90 = math.nan
    return DelayStats(
        median=med,
        mean=mean,
        p90=p90,
        censored_mean=float(censored.mean()) if censored.size else math.nan,
        n_detected=int(dd.size),
        n_missed=len(dets) - int(dd.size),
    )


# --------------------------------------------------------------------------- M6


def fault_free_scores(runs: Sequence[RunData]) -> NDArray[np.float64]:
    """Pool the scores of the scored samples of the fully fault-free runs (M6 calibration set).

    Parameters
    ----------
    runs : sequence of RunData
        Typically the validation runs; faulty runs are skipped.

    Returns
    -------
    numpy.ndarray of float
        The concatenated scores.
    """
    parts = []
    for r in runs:
        if r.is_faulty:
            continue
        if r.score is None:
            raise ValueError("a fault-free run has no score; calibration needs scores")
        parts.append(r.score[r.scored])
    return np.concatenate(parts) if parts else np.empty(0)


def calibrate_threshold(scores: ArrayLike, alpha: float) -> float:
    """M6: threshold theta with at most a fraction ``alpha`` of calibration scores above it.

    The alarm rule is strict, ``score > theta``. theta is the (1 - alpha) empirical quantile in
    its inverted-CDF form: with n scores sorted ascending, j = floor(alpha * n) exceedances are
    allowed and theta is the (n - j)-th smallest score. Tie rule: scores equal to theta do not
    alarm, so with ties at theta the calibration FAR is *below* alpha rather than above it; theta
    is the smallest sample value that keeps the FAR <= alpha.

    Parameters
    ----------
    scores : array_like of float
        Scores of the scored samples of the validation fault-free runs
        (:func:`fault_free_scores`); not NaN (+inf is an exceedance).
    alpha : float
        Target false-alarm rate, 0 <= alpha < 1 (defaults in §5.2: 0.01 and 0.001).

    Returns
    -------
    float
        The threshold theta.
    """
    s = np.sort(np.asarray(scores, dtype=float).ravel())
    if s.size == 0:
        raise ValueError("no calibration scores")
    if np.isnan(s).any():  # +inf is an exceedance at any theta (and theta inf: no alarm)
        raise ValueError("calibration scores must not be NaN")
    if not 0.0 <= alpha < 1.0:
        raise ValueError(f"alpha must be in [0, 1), got {alpha!r}")
    n = s.size
    # the small epsilon keeps e.g. 0.29 * 100 = 28.999999999999996 from losing an exceedance
    j = min(int(math.floor(alpha * n + 1e-9)), n - 1)
    return float(s[n - 1 - j])


def apply_threshold(runs: Sequence[RunData], theta: float) -> list[RunData]:
    """Re-derive each run's alarm as ``score > theta`` (M6 operating point).

    Parameters
    ----------
    runs : sequence of RunData
        Runs with scores.
    theta : float
        Threshold from :func:`calibrate_threshold`.

    Returns
    -------
    list of RunData
        Copies of the runs with the new alarm; everything else unchanged.
    """
    out = []
    for r in runs:
        if r.score is None:
            raise ValueError("apply_threshold needs runs with scores")
        out.append(replace(r, alarm=r.score > theta))
    return out


# --------------------------------------------------------------------------- M7


def pooled_scores(runs: Sequence[RunData]) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Pool scores and ground truth over runs, scored samples only (input of M7).

    Parameters
    ----------
    runs : sequence of RunData
        Runs with scores.

    Returns
    -------
    score : numpy.ndarray of float
    y : numpy.ndarray of bool
    """
    scores = [r.score for r in runs if r.score is not None]
    if len(scores) < len(runs):
        raise ValueError("pooled_scores needs runs with scores")
    if not runs:
        return np.empty(0), np.empty(0, dtype=bool)
    return (
        np.concatenate([s[r.scored] for s, r in zip(scores, runs, strict=True)]),
        np.concatenate([r.faulty[r.scored] for r in runs]),
    )


def scored_groups(runs: Sequence[RunData]) -> NDArray[np.int64]:
    """A group label per sample of :func:`pooled_scores`: a new group at each run and at
    each gap in a run's scored samples (the ranges of :func:`range_pr_auc` and the buffers
    of :func:`vus_pr` do not cross them)."""
    g = []
    n_groups = 0
    for r in runs:
        k = np.flatnonzero(r.scored)
        seg = np.cumsum(np.r_[True, np.diff(k) != 1]) if k.size else k
        g.append(seg + n_groups)
        n_groups += int(seg[-1]) if k.size else 0
    return np.concatenate(g) if g else np.empty(0, dtype=np.int64)


def _check_score_y(score: ArrayLike, y: ArrayLike) -> tuple[NDArray, NDArray]:
    s = np.asarray(score, dtype=float).ravel()
    yy = np.asarray(y, dtype=bool).ravel()
    if s.shape != yy.shape:
        raise ValueError(f"score and y differ in length ({s.size} vs {yy.size})")
    if not np.all(np.isfinite(s)):
        raise ValueError("scores must be finite")
    return s, yy


def roc_auc(score: ArrayLike, y: ArrayLike) -> float:
    """M7: area under the ROC curve of ``score`` against the labels ``y``.

    Computed as the Mann–Whitney statistic: the probability that a random positive sample
    scores higher than a random negative one, ties counting 1/2 (average ranks). This equals the
    trapezoidal ROC area of scikit-learn's ``roc_auc_score``.

    Parameters
    ----------
    score : array_like of float
        Scores, larger = more anomalous.
    y : array_like of bool
        Ground truth (True = faulty).

    Returns
    -------
    float
        ROC-AUC in [0, 1]; nan if either class is empty.
    """
    s, yy = _check_score_y(score, y)
    n1 = int(yy.sum())
    n0 = yy.size - n1
    if n1 == 0 or n0 == 0:
        return math.nan
    ranks = rankdata(s)  # 'average' ranks: a tie contributes 1/2 to each pair
    return float((ranks[yy].sum() - n1 * (n1 + 1) / 2.0) / (n1 * n0))


def average_precision(score: ArrayLike, y: ArrayLike) -> float:
    """M7: average precision (PR-AUC), as scikit-learn defines it.

    AP = sum_n (R_n - R_{n-1}) P_n over the distinct score thresholds taken in decreasing order,
    where P_n and R_n are the precision and recall of the rule ``score >= threshold_n`` and
    R_0 = 0. Tied scores enter together at one threshold (no interpolation).

    Parameters
    ----------
    score : array_like of float
        Scores, larger = more anomalous.
    y : array_like of bool
        Ground truth (True = faulty).

    Returns
    -------
    float
        AP in [0, 1]; nan if there is no positive sample.
    """
    s, yy = _check_score_y(score, y)
    n_pos = int(yy.sum())
    if n_pos == 0:
        return math.nan
    order = np.argsort(-s, kind="mergesort")
    s, yy = s[order], yy[order]
    # last index of each block of equal scores = one distinct threshold
    last = np.flatnonzero(np.r_[s[1:] != s[:-1], True])
    tp = np.cumsum(yy)[last]
    precision = tp / (last + 1)
    recall = tp / n_pos
    return float(np.sum(np.diff(np.r_[0.0, recall]) * precision))


# --------------------------------------------------------------------------- M7, VUS-PR


def _group_bounds(n: int, groups: ArrayLike | None) -> tuple[NDArray, NDArray]:
    """First and last index of the group of every sample (groups: labels, constant on
    contiguous blocks; a change of label starts a new group)."""
    if groups is None:
        return np.zeros(n, dtype=np.int64), np.full(n, n - 1, dtype=np.int64)
    g = np.asarray(groups).ravel()
    if g.size != n:
        raise ValueError(f"groups has {g.size} values for {n} samples")
    new = np.r_[True, g[1:] != g[:-1]]
    starts = np.flatnonzero(new)
    ends = np.r_[starts[1:] - 1, n - 1]
    which = np.cumsum(new) - 1
    return starts[which], ends[which]


def _ranges(y: NDArray[np.bool_], first: NDArray) -> tuple[NDArray, NDArray]:
    """Start and end (inclusive) of every anomaly range: maximal runs of y within a group."""
    joined = y[1:] & y[:-1] & (first[1:] == first[:-1])  # k and k+1 in one range
    return (np.flatnonzero(y & ~np.r_[False, joined]), np.flatnonzero(y & ~np.r_[joined, False]))


def _buffer_weights(
    y: NDArray[np.bool_], first: NDArray, last: NDArray, buffer: int
) -> NDArray[np.float64]:
    """Soft labels: 1 on anomalies; sqrt(1 - d/(buffer+1)) at distance d in 1..buffer samples
    from the nearest anomaly of the same group; 0 elsewhere."""
    w = y.astype(float)
    if buffer == 0 or not y.any():
        return w
    idx = np.arange(y.size)
    prev = np.maximum.accumulate(np.where(y, idx, -1))
    nxt = np.minimum.accumulate(np.where(y, idx, y.size)[::-1])[::-1]
    d_prev = np.where(prev >= first, idx - prev, np.iinfo(np.int64).max)
    d_next = np.where(nxt <= last, nxt - idx, np.iinfo(np.int64).max)
    d = np.minimum(d_prev, d_next)
    near = ~y & (d <= buffer)
    w[near] = np.sqrt(1.0 - d[near] / (buffer + 1.0))
    return w


def range_pr_auc(
    score: ArrayLike, y: ArrayLike, buffer: int = 0, groups: ArrayLike | None = None
) -> float:
    """Range-based PR-AUC with a soft buffer of ``buffer`` samples (one slice of VUS-PR).

    For the rule ``score >= theta`` at each distinct score (decreasing), with p(k) the alarm
    and w(k) the buffered soft label (:func:`vus_pr`):

    * TP = sum_k w(k) p(k);  precision = TP / sum_k p(k);
    * recall = min(TP / P, 1) * E / |ranges|, where P is the number of anomalous samples and
      E the number of anomaly ranges with an alarm inside the range widened by ``buffer``
      samples on each side (existence reward);
    * the area is sum_n (R_n - R_{n-1}) P_n with R_0 = 0 (the step form of
      :func:`average_precision`).

    Parameters
    ----------
    score : array_like of float
        Scores, larger = more anomalous.
    y : array_like of bool
        Ground truth; a range is a maximal run of True within a group.
    buffer : int, default 0
        Buffer length in samples on each side of a range (>= 0).
    groups : array_like, optional
        Group label per sample (e.g. a run id), constant on contiguous blocks: ranges and
        buffers never cross a change of group.

    Returns
    -------
    float
        The area in [0, 1]; nan without anomalous samples. With ``buffer=0`` and a single
        range it equals :func:`average_precision`.
    """
    prep = _range_inputs(score, y, buffer, groups, "buffer")
    if prep is None:
        return math.nan
    s, yy, first, last, order = prep
    return _range_auc(s, yy, int(buffer), first, last, order)


def _range_inputs(
    score: ArrayLike, y: ArrayLike, buffer: float, groups: ArrayLike | None, name: str
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray] | None:
    """Checked ``(score, y, first, last, order)`` for the range-based AUCs, or None when
    no sample is anomalous."""
    s, yy = _check_score_y(score, y)
    if int(buffer) != buffer or buffer < 0:
        raise ValueError(f"{name} must be an integer >= 0, got {buffer!r}")
    if not yy.any():
        return None
    first, last = _group_bounds(s.size, groups)
    return s, yy, first, last, np.argsort(-s, kind="mergesort")


def _range_auc(
    s: NDArray, y: NDArray, buffer: int, first: NDArray, last: NDArray, order: NDArray
) -> float:
    w = _buffer_weights(y, first, last, buffer)
    blocks = np.flatnonzero(np.r_[s[order][1:] != s[order][:-1], True])  # distinct thresholds
    tp = np.cumsum(w[order])[blocks]
    pos = np.empty(s.size, dtype=np.int64)
    pos[order] = np.arange(s.size)  # position of each sample in the decreasing order
    starts, ends = _ranges(y, first)
    lo = np.maximum(starts - buffer, first[starts])
    hi = np.minimum(ends + buffer, last[ends])
    found = np.sort([pos[a : b + 1].min() for a, b in zip(lo, hi, strict=True)])
    existence = np.searchsorted(found, blocks, side="right") / starts.size
    recall = np.minimum(tp / y.sum(), 1.0) * existence
    precision = tp / (blocks + 1)
    return float(np.sum(np.diff(np.r_[0.0, recall]) * precision))


def vus_pr(
    score: ArrayLike, y: ArrayLike, max_buffer: int = 0, groups: ArrayLike | None = None
) -> float:
    """M7: volume under the range-based PR surface (VUS-PR, after Paparrizos et al. 2022).

    The mean of :func:`range_pr_auc` over the buffer lengths 0, 1, ..., ``max_buffer``
    samples. With buffer l, a sample at distance d (1 <= d <= l) from the nearest anomaly
    counts as sqrt(1 - d/(l+1)) of a true positive, and an alarm within l samples of a range
    counts for its existence, so a detector that fires a little early or late is credited
    gradually instead of all or nothing. A perfect score (every anomaly above every normal
    sample) gives 1 at every buffer length.

    Parameters
    ----------
    score : array_like of float
        Scores, larger = more anomalous.
    y : array_like of bool
        Ground truth.
    max_buffer : int, default 0
        Largest buffer length in samples (one side of a range), at most
        :data:`r2rsim.limits.MAX_VUS_BUFFER_SAMPLES`.
    groups : array_like, optional
        Group label per sample (runs): ranges and buffers never cross a change of group.

    Returns
    -------
    float
        VUS-PR in [0, 1]; nan without anomalous samples.

    Raises
    ------
    ValueError
        When ``max_buffer`` is not an integer from 0 to the limit.
    """
    # one range-PR AUC over every sample per buffer length: a bound on the lengths is a bound
    # on the time. Refused, not capped at the series length: the weights sqrt(1 - d/(l+1))
    # keep changing with l beyond it, so a cap would silently change the value.
    if not max_buffer <= MAX_VUS_BUFFER_SAMPLES:  # negative, fractional: _range_inputs
        raise ValueError(
            f"max_buffer must be an integer from 0 to {MAX_VUS_BUFFER_SAMPLES} "
            f"(r2rsim.limits.MAX_VUS_BUFFER_SAMPLES), got {max_buffer!r}"
        )
    prep = _range_inputs(score, y, max_buffer, groups, "max_buffer")
    if prep is None:
        return math.nan
    s, yy, first, last, order = prep
    return float(
        np.mean([_range_auc(s, yy, b, first, last, order) for b in range(int(max_buffer) + 1)])
    )


# --------------------------------------------------------------------------- M9


def isolation_accuracy(runs: Sequence[RunData]) -> float:
    """M9: sample-weighted isolation accuracy, conditional on detection.

    Over the alarmed scored samples in [tau, eps] of the faulty runs, the fraction whose
    diagnosis equals the true fault type. The truth at a sample is ``true_type``; inside an
    intermittent fault's gaps (non-faulty samples within [tau, eps]) it is the type of the most
    recent faulty sample, i.e. the run's fault f_r of §5.3.

    Parameters
    ----------
    runs : sequence of RunData
        Runs with ``diagnosis`` and ``true_type``; fault-free runs are ignored.

    Returns
    -------
    float
        IA in [0, 1]; nan when the detector gives no diagnosis or there is no alarmed sample
        in any fault window.
    """
    faulty = _faulty_runs(runs)
    has = [r.diagnosis is not None for r in faulty]
    if not any(has):
        return math.nan
    if not all(has):
        raise ValueError("some faulty runs have a diagnosis and some do not")
    return _pooled(isolation_counts(r) for r in faulty)


def isolation_counts(run: RunData) -> tuple[int, int]:
    """Correctly diagnosed and all alarmed scored samples in a faulty run's window [tau, eps]
    (the numerator and denominator of M9 for one run)."""
    if run.diagnosis is None or run.true_type is None:
        raise ValueError("isolation_accuracy needs diagnosis and true_type on every faulty run")
    sl = _fault_slice(run)
    # forward-fill the truth from the last faulty sample across intermittent gaps
    idx = np.where(run.faulty[sl], np.arange(sl.start, sl.stop), -1)
    truth = run.true_type[np.maximum.accumulate(idx)]
    sel = run.effective_alarm[sl]
    return int((run.diagnosis[sl][sel] == truth[sel]).sum()), int(sel.sum())


# --------------------------------------------------------------------------- M13


def _top_hit(ranking: NDArray[np.int64], truth: NDArray[np.bool_], n: int) -> NDArray[np.bool_]:
    """Per row: one of the first ``n`` ranked channel indices is true in that row of truth."""
    rows = np.arange(ranking.shape[0])
    hit = np.zeros(ranking.shape[0], dtype=bool)
    for j in range(min(n, ranking.shape[1])):
        c = ranking[:, j]
        ok = c >= 0
        hit |= ok & truth[rows, np.where(ok, c, 0)]
    return hit


def run_hit(
    run: RunData, n: int = 1, m: int = 1, h: float = 0.0, w: float = DETECTION_WINDOW_S
) -> tuple[int, int]:
    """M13 for one run: is a true faulty channel in the top ``n`` of the ranking at k*?

    Parameters
    ----------
    run : RunData
        A run with ``channel_truth`` and ``ranking``.
    n : int, default 1
        List length (hit@n).
    m, h, w
        Persistence, grace period and detection window of the detection (:func:`detect_run`).

    Returns
    -------
    tuple of int
        (hit, counted): counted is 1 for a faulty run that has a faulty measured channel
        (``channel_truth`` true somewhere) and is detected; else (0, 0).
    """
    if not run.is_faulty or run.channel_truth is None or run.ranking is None:
        return 0, 0
    truth = np.asarray(run.channel_truth.any(axis=0))
    if not truth.any():
        return 0, 0
    d = detect_run(run, m, h, w)
    if d.k_star is None:  # not detected
        return 0, 0
    hit = _top_hit(run.ranking[[d.k_star]], truth[None, :], n)
    return int(hit[0]), 1


def hit_at_n(
    runs: Sequence[RunData], n: int = 1, m: int = 1, h: float = 0.0, w: float = DETECTION_WINDOW_S
) -> float:
    """M13: localisation hit@n at the first detection onset, over detected sensor-fault runs.

    hit@n = (1/|R|) sum_r 1[c_r in top-n of the ranking at k*_r], where R holds the detected
    faulty runs with at least one faulty measured channel and c_r is any channel whose
    ``channel_truth`` is true somewhere in run r (several for a multi-sensor fault).

    Parameters
    ----------
    runs : sequence of RunData
        Runs with ``channel_truth`` and ``ranking``; other runs are ignored.
    n : int, default 1
        List length.
    m, h, w
        As in :func:`detect_run`.

    Returns
    -------
    float
        hit@n in [0, 1]; nan when no run qualifies.
    """
    return _pooled(run_hit(r, n, m, h, w) for r in runs)


def localization_counts(run: RunData, n: int = 1) -> tuple[int, int]:
    """Sample-level M13: alarmed scored samples of [tau, eps] with a faulty measured channel,
    and those whose top-``n`` ranking holds a channel faulty at that very sample.

    Parameters
    ----------
    run : RunData
        A run with ``channel_truth`` and ``ranking``.
    n : int, default 1
        List length.

    Returns
    -------
    tuple of int
        (hits, total); (0, 0) for a fault-free run or a run without channel data.
    """
    if not run.is_faulty or run.channel_truth is None or run.ranking is None:
        return 0, 0
    sl = _fault_slice(run)
    truth = run.channel_truth[sl]
    sel = run.effective_alarm[sl] & truth.any(axis=1)
    hit = _top_hit(run.ranking[sl], truth, n)
    return int((hit & sel).sum()), int(sel.sum())


# --------------------------------------------------------------------------- M15


@dataclass(frozen=True)
class Detectability:
    """Detectability curve (M15).

    Attributes
    ----------
    table : pandas.DataFrame
        One row per magnitude value, sorted by absolute magnitude, with columns ``magnitude``,
        ``n_runs``, ``n_detected`` and ``p_d``; with a null rate also ``p_null`` (the null
        detection rate of that magnitude's windows), ``p_value`` (one-sided binomial test of
        ``n_detected`` out of ``n_runs`` against ``p_null``) and ``significant``.
    mdm : float
        Minimum detectable magnitude: the smallest (in absolute value) magnitude whose
        P_D >= level (and, with a null rate, significantly above it), with its sign; nan if
        none qualifies.
    level : float
        The P_D level (0.9 for MDM90).
    """

    table: pd.DataFrame
    mdm: float
    level: float


#: one-sided significance level of the test P_D > pd_null behind the MDM90
MDM_SIGNIFICANCE = 0.05


def detectability(
    magnitude: ArrayLike,
    detected: ArrayLike,
    level: float = 0.9,
    null: Mapping[float, float] | None = None,
    significance: float = MDM_SIGNIFICANCE,
) -> Detectability:
    """M15: P_D per fault magnitude and the minimum detectable magnitude (MDM90 by default).

    Runs are grouped by their exact magnitude value (a sweep uses a grid of magnitudes); runs
    with a nan magnitude are dropped. MDM is the smallest |m| with P_D(m) >= level; it does
    not require P_D to stay above the level at larger magnitudes. With ``null`` (the null
    detection rate p0 of each magnitude, :func:`null_detection_rate`), a magnitude qualifies
    only if its detections are also significantly more than chance: the one-sided exact
    binomial test of ``n_detected`` successes in ``n_runs`` trials against p0 (alternative
    "greater", p0 taken as known) gives a p-value below ``significance``. A magnitude whose
    p0 is nan (no fault-free run to measure it on) never qualifies.

    Parameters
    ----------
    magnitude : array_like of float, shape (R,)
        Per-run fault magnitude (e.g. ``[d.magnitude for d in detections]``).
    detected : array_like of bool, shape (R,)
        Per-run detection flag (:func:`detect_run`).
    level : float, default 0.9
        P_D level defining the minimum detectable magnitude.
    null : mapping of float to float, optional
        Null detection rate per magnitude value.
    significance : float, default :data:`MDM_SIGNIFICANCE`
        Level of the one-sided test.

    Returns
    -------
    Detectability
        The per-magnitude table and the MDM.
    """
    mag = np.asarray(magnitude, dtype=float).ravel()
    det = np.asarray(detected, dtype=bool).ravel()
    if mag.shape != det.shape:
        raise ValueError("magnitude and detected differ in length")
    keep = ~np.isnan(mag)
    df = pd.DataFrame({"magnitude": mag[keep], "detected": det[keep]})
    table = (
        df.groupby("magnitude", sort=False)["detected"]
        .agg(n_runs="size", n_detected="sum")
        .reset_index()
    )
    table["n_detected"] = table["n_detected"].astype(int)
    table["p_d"] = table["n_detected"] / table["n_runs"]
    # sort by |m|, then by m so that -x precedes +x deterministically
    table = (
        table.assign(_abs=table["magnitude"].abs())
        .sort_values(["_abs", "magnitude"], kind="mergesort")
        .drop(columns="_abs")
        .reset_index(drop=True)
    )
    ok = table["p_d"] >= level
    if null is not None:
        table["p_null"] = [float(null.get(float(m), math.nan)) for m in table["magnitude"]]
        table["p_value"] = [
            _binomial_p_greater(int(x), int(n), p0)
            for x, n, p0 in zip(table["n_detected"], table["n_runs"], table["p_null"], strict=True)
        ]
        table["significant"] = table["p_value"] < significance
        ok &= table["significant"]
    hit = table.loc[ok, "magnitude"]
    mdm = float(hit.iloc[0]) if len(hit) else math.nan
    return Detectability(table=table, mdm=mdm, level=level)


def _binomial_p_greater(x: int, n: int, p0: float) -> float:
    """P(X >= x) for X ~ Binomial(n, p0): the p-value of the one-sided exact binomial test
    (nan when p0 is nan or n is 0)."""
    if n == 0 or not 0.0 <= p0 <= 1.0:
        return math.nan
    return float(binomtest(x, n, p0, alternative="greater").pvalue)


# --------------------------------------------------------------------------- statistics


@dataclass(frozen=True)
class ConfidenceInterval:
    """Percentile bootstrap confidence interval.

    Attributes
    ----------
    estimate : float
        The statistic on the full set of runs.
    low, high : float
        Interval bounds (nan if no bootstrap replicate gave a finite value).
    level : float
        Confidence level, e.g. 0.95.
    n_boot : int
        Bootstrap replicates drawn.
    n_valid : int
        Replicates with a finite statistic (a resample may e.g. contain no faulty run).
    """

    estimate: float
    low: float
    high: float
    level: float
    n_boot: int
    n_valid: int


def bootstrap_ci(
    stat: ArrayLike | Callable[[list[RunData]], float],
    runs: Sequence[RunData] | None = None,
    *,
    n_boot: int = 1000,
    seed: int = 0,
    level: float = 0.95,
) -> ConfidenceInterval:
    """Percentile bootstrap CI over runs (§5.5: resample runs, never samples).

    Parameters
    ----------
    stat : array_like of float, or callable
        Either per-run values (one finite number per run; the statistic is their mean), or a
        function mapping a list of runs to a number, e.g.
        ``lambda rs: detection_probability(rs, m=3)``.
    runs : sequence of RunData, optional
        The runs to resample; required when ``stat`` is callable.
    n_boot : int, default 1000
        Number of bootstrap replicates.
    seed : int, default 0
        Seed of the ``numpy.random.default_rng`` generator: same seed, same interval.
    level : float, default 0.95
        Confidence level.

    Returns
    -------
    ConfidenceInterval
        Point estimate, bounds at the (1 -+ level)/2 percentiles of the finite replicates.
    """
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must be in (0, 1), got {level!r}")
    if n_boot < 1:
        raise ValueError("n_boot must be >= 1")
    if callable(stat):
        if runs is None:
            raise ValueError("a callable statistic needs the runs to resample")
        pool = list(runs)
        n = len(pool)

        def evaluate(idx: NDArray[np.intp]) -> float:
            return float(stat([pool[i] for i in idx]))

        estimate = float(stat(pool))
    else:
        values = np.asarray(stat, dtype=float).ravel()
        if not np.all(np.isfinite(values)):
            raise ValueError("per-run values must be finite; use a callable for nan-aware stats")
        n = values.size

        def evaluate(idx: NDArray[np.intp]) -> float:
            return float(values[idx].mean())

        estimate = float(values.mean()) if n else math.nan
    if n == 0:
        raise ValueError("nothing to resample")
    boot = np.array([evaluate(row) for row in bootstrap_indices(n, n_boot, seed)])
    low, high, n_valid = percentile_interval(boot, ci_percentiles(level))
    return ConfidenceInterval(
        estimate=estimate, low=low, high=high, level=level, n_boot=int(n_boot), n_valid=n_valid
    )


def bootstrap_indices(n: int, n_boot: int, seed: int) -> NDArray[np.int64]:
    """The runs of each bootstrap replicate: ``(n_boot, n)`` indices into ``n`` runs, drawn
    with replacement by ``numpy.random.default_rng(seed)`` (§5.5: resample runs, never
    samples). The one resampling of :func:`bootstrap_ci` and of the harness's intervals."""
    return np.random.default_rng(seed).integers(0, n, size=(n_boot, n))


def ci_percentiles(level: float) -> tuple[float, float]:
    """The percentiles [%] that bound a two-sided interval at confidence ``level``."""
    return 50 * (1 - level), 50 * (1 + level)


def percentile_interval(
    boot: ArrayLike, percentiles: tuple[float, float]
) -> tuple[float, float, int]:
    """The percentile interval of the finite bootstrap replicates ``boot``: ``(low, high,
    n_finite)``; ``(nan, nan, 0)`` when no replicate is finite (a resample may e.g. hold no
    faulty run)."""
    b = np.asarray(boot, dtype=float)
    finite = b[np.isfinite(b)]
    if not finite.size:
        return math.nan, math.nan, 0
    low, high = np.percentile(finite, percentiles)
    return float(low), float(high), int(finite.size)
