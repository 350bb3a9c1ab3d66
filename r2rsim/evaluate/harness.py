"""The evaluation harness: fit a diagnostic plug-in on healthy runs, score test runs, and
compute every metric of :mod:`r2rsim.evaluate.metrics` the same way for every plug-in.

The protocol (docs/diagnostics.md §4, §5):

* **train** runs are fault-free; the plug-in is fitted on them and on nothing else;
* **val** runs are fault-free; the harness calibrates its own threshold theta on their scores
  at the false-alarm rate ``alpha`` (M6) and reports the ``*_cal`` metrics at ``score > theta``
  next to the metrics at the plug-in's own alarms (``decide``);
* **test** runs (faulty and fault-free) are scored and the metrics computed on them, per
  stratum: operating condition (``runs.operating_mode``) × fault (type and target, e.g.
  ``sensor.offset:sensor_A``), and per magnitude where a fault was run at several magnitudes
  (M15).

:func:`split_by_seed` and :func:`split_by_condition` build the two standard splits from a pool
of runs. Confidence intervals are percentile bootstraps over the runs of a stratum (never over
samples), computed from per-run counts so that a thousand replicates cost milliseconds.
"""

from __future__ import annotations

import collections
import hashlib
import json
import math
import time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.stats import rankdata
from sklearn.base import clone

from ..dataset.paths import SWEEP_MARKER
from ..dataset.read import Run, is_dataset_dir, read_runs
from ..diagnostics.line import attach_line
from ..diagnostics.registry import call
from ..errors import InputError, PluginError
from ..limits import MAX_BOOTSTRAP, MAX_SEED, MAX_VUS_BUFFER_S, MAX_VUS_BUFFER_SAMPLES
from .metrics import (
    DETECTION_WINDOW_S,
    RunData,
    average_precision,
    bootstrap_indices,
    calibrate_threshold,
    ci_percentiles,
    detect_run,
    detectability,
    false_alarm_events,
    far,
    isolation_counts,
    localization_counts,
    null_outcomes,
    percentile_interval,
    pooled_rate,
    pooled_scores,
    restrict_to_mode,
    roc_auc,
    run_hit,
    scored_groups,
    steady_counts,
    steady_detection,
    vus_pr,
    window_counts,
)
from .results import DATASETS_FILE, write_results
from .splits import (
    Split,
    acting_faults,
    is_faulty,
    no_training_run,
    split_by_condition,
    split_by_seed,
)

__all__ = [
    "METRICS",
    "PRINTED_METRICS",
    "Evaluation",
    "Split",
    "acting_faults",
    "check_settings",
    "evaluate",
    "no_training_run",
    "read_datasets",
    "run_data",
    "split_by_condition",
    "split_by_seed",
]


@dataclass(frozen=True)
class Metric:
    """What a metric name in the results table means."""

    description: str
    #: None: no better direction (a benchmark flags a change either way)
    higher_is_better: bool | None
    unit: str = ""


#: every metric the harness reports, by the name used in the results table
METRICS: dict[str, Metric] = {
    "far_ff": Metric("M1 sample false-alarm rate over fault-free runs", False),
    "far_pre": Metric("M1 sample false-alarm rate over pre-onset samples of faulty runs", False),
    "fa_per_h": Metric("M2 false-alarm events per hour of fault-free time", False, "1/h"),
    "dr": Metric("M3 sample detection rate over the fault windows", True),
    "dr_steady": Metric("M3 over the steady-state samples (severity 1)", True),
    "pd": Metric("M4 run-level detection probability in the detection window", True),
    "pd_null": Metric("M4 rule on fault-free test runs at pretend onsets: P_D by chance", None),
    "dd_median_s": Metric("M5 median detection delay over detected runs", False, "s"),
    "dd_mean_s": Metric("M5 mean detection delay over detected runs", False, "s"),
    "dd_p90_s": Metric("M5 90th percentile of the detection delay", False, "s"),
    "dd_censored_mean_s": Metric("M5 mean delay, a miss counting its horizon", False, "s"),
    "n_missed": Metric("M5 faulty runs not detected", False),
    "pd_steady": Metric("M4 detection of the fully developed fault", True),
    "pd_steady_null": Metric("pd_steady's rule at pretend onsets on fault-free test runs", None),
    "dd_steady_median_s": Metric("M5 median delay from the first severity-1 sample", False, "s"),
    "roc_auc": Metric("M7 area under the ROC curve of the statistic", True),
    "pr_auc": Metric("M7 average precision of the statistic", True),
    "vus_pr": Metric("M7 volume under the range-based PR surface of the statistic", True),
    "ia": Metric("M9 isolation accuracy over alarmed fault samples", True),
    "hit1": Metric("M13 channel hit@1 at the first detection onset", True),
    "hit1_samples": Metric("M13 channel hit@1 over alarmed sensor-fault samples", True),
    "mdm90": Metric(
        "M15 smallest |magnitude| with P_D >= 0.9 and significantly above pd_null (plug-in alarms)",
        False,
    ),
    "mdm90_cal": Metric(
        "M15 smallest |magnitude| with P_D >= 0.9 and significantly above "
        "pd_null_cal, at theta (M6)",
        False,
    ),
    "theta": Metric("M6 threshold calibrated on the validation runs", None),
    "far_ff_cal": Metric("M1 FAR over fault-free test runs at theta (M6)", False),
    "far_pre_cal": Metric("M1 pre-onset FAR at theta (M6)", False),
    "dr_cal": Metric("M3 detection rate at theta (M6)", True),
    "pd_cal": Metric("M4 detection probability at theta (M6)", True),
    "pd_null_cal": Metric("pd_null at theta (M6)", None),
    "dd_median_cal_s": Metric("M5 median delay at theta (M6)", False, "s"),
    "dr_steady_cal": Metric("M3 over the steady-state samples at theta (M6)", True),
    "hit1_cal": Metric("M13 channel hit@1 at the first detection onset at theta (M6)", True),
    "fit_s": Metric("wall time of fit", False, "s"),
    "exec_s_per_sim_h": Metric("wall time of score per simulated hour", False, "s/h"),
}

#: metrics about the run of the method, not a stratum (left out of the wide table)
_META = ("fit_s", "exec_s_per_sim_h", "theta")

#: metrics computed per run (not per sample): left out of the per-regime strata
_RUN_LEVEL = frozenset(
    {
        "pd",
        "pd_null",
        "dd_median_s",
        "dd_mean_s",
        "dd_p90_s",
        "dd_censored_mean_s",
        "n_missed",
        "pd_steady",
        "dd_steady_median_s",
        "hit1",
        "mdm90",
        "pd_steady_null",
    }
)
#: the metrics reported at theta, by the name of the metric at the plug-in's alarms
_CAL = {
    "far_ff": "far_ff_cal",
    "far_pre": "far_pre_cal",
    "dr": "dr_cal",
    "pd": "pd_cal",
    "dd_median_s": "dd_median_cal_s",
    "dr_steady": "dr_steady_cal",
    "hit1": "hit1_cal",
    "pd_null": "pd_null_cal",
}
#: condition label of a per-regime stratum (``label.mode`` per sample)
MODE_PREFIX = "mode:"
#: values of the ``window`` option
WINDOWS = ("fault", "steady")
#: where the plug-in's own threshold comes from: its calibrate() on the val runs, or its fit
OWN_THRESHOLDS = ("val", "fit")

#: stratum value meaning "pooled over every value"
ALL = "all"
#: fault stratum of fault-free runs
NONE = "none"


def read_datasets(
    paths: Sequence[str | Path], verify: bool = True, where: dict | None = None
) -> list[Run]:
    """Every run of the given dataset directories (runs or sweeps); a directory that is not
    a dataset but holds datasets (one level down) contributes all of them. ``verify``: check
    each dataset's files against its manifest.json (sizes, and the sha256 of each file read)
    and each run's ``label.*`` columns against faults.parquet, as ``r2rsim validate`` derives
    them; ``where``: only the runs with these runs.parquet values, e.g. a sweep's axis values
    (:func:`r2rsim.dataset.read.read_runs`)."""
    runs: list[Run] = []
    for p in map(Path, paths):
        if not p.is_dir():
            raise InputError(f"{p}: no such dataset directory")
        if is_dataset_dir(p) or (p / SWEEP_MARKER).is_file():
            runs += read_runs(p, verify=verify, where=where)
            continue
        subs = sorted(d for d in p.iterdir() if d.is_dir() and is_dataset_dir(d))
        if not subs:
            raise InputError(f"{p}: not an r2rsim dataset and holds none")
        for d in subs:
            runs += read_runs(d, verify=verify, where=where)
    if where and paths and not runs:
        raise InputError(
            f"no run of {', '.join(map(str, paths))} has "
            + ", ".join(f"{k} = {v}" for k, v in where.items())
        )
    return runs


# --------------------------------------------------------------------------- one run


def fault_key(run: Run) -> str:
    """The run's fault as ``type:target`` (several joined by ``+``; ``none`` when healthy):
    the fault stratum of the results table."""
    faults = acting_faults(run)
    keys = sorted(
        {f"{t}:{g}" for t, g in zip(faults["fault_type"], faults["target_id"], strict=True)}
    )
    return "+".join(keys) if keys else NONE


def _magnitude(run: Run) -> float:
    faults = acting_faults(run)
    return float(faults["magnitude"].iloc[0]) if len(faults) == 1 else math.nan


def run_data(
    run: Run,
    statistic: np.ndarray,
    alarm: np.ndarray,
    diagnosis: np.ndarray | None = None,
    *,
    ranking: pd.DataFrame | None = None,
    modes: bool = False,
    steady: bool = False,
) -> RunData:
    """The ground truth of a run (``label.*``) with a detector's output, as :class:`RunData`.

    Faulty samples are ``label.is_faulty``, scored samples ``label.score_mask`` (false in the
    warm-up), the true type per sample ``label.primary_type``; the magnitude is the run's
    fault magnitude when it has exactly one fault. ``modes`` adds ``label.mode``, ``steady``
    ``label.severity``; a ``ranking`` (:meth:`Diagnostic.rank_channels`) adds the
    ``label.ch.*`` columns as the channel truth.
    """
    s = run.samples
    extra = {}
    if modes:
        extra["mode"] = _label(run, "label.mode").astype(str).to_numpy()
    if steady:
        extra["severity"] = _label(run, "label.severity").to_numpy(float)
    elif "label.severity" in s.columns:  # the detection window starts when fully developed
        extra["severity"] = s["label.severity"].to_numpy(float)
    if ranking is not None:
        extra.update(_channel_data(run, ranking))
    return RunData(
        t=s["t_s"].to_numpy(float),
        faulty=s["label.is_faulty"].to_numpy(bool),
        scored=s["label.score_mask"].to_numpy(bool),
        alarm=alarm,
        score=statistic,
        diagnosis=diagnosis,
        true_type=s["label.primary_type"].astype(str).to_numpy() if diagnosis is not None else None,
        magnitude=_magnitude(run),
        **extra,
    )


def _label(run: Run, column: str) -> pd.Series:
    if column not in run.samples.columns:
        raise InputError(f"run {run.run_id} ({run.path}) has no {column} column")
    return run.samples[column]


def _channel_data(run: Run, ranking: pd.DataFrame) -> dict:
    """``channel_truth`` from ``label.ch.*`` and the top-ranked channel as an index into it
    (-1 for a name that is not a labelled channel, or no name)."""
    cols = [c for c in run.samples.columns if c.startswith("label.ch.")]
    names = tuple(c[len("label.ch.") :] for c in cols)
    lookup = {n: i for i, n in enumerate(names)}
    top = ranking.iloc[:, 0] if ranking.shape[1] else pd.Series(index=ranking.index)
    code = top.map(
        lambda v: lookup.get(str(v).removeprefix("meas."), -1) if isinstance(v, str) else -1
    )
    return {
        "channels": names,
        "channel_truth": run.samples[cols].to_numpy(bool),
        "ranking": code.to_numpy(np.int64)[:, None],
    }


# --------------------------------------------------------------------------- per-run counts


@dataclass(frozen=True)
class _Rule:
    """The detection rule of an evaluation: persistence m, grace h [s], detection window w
    [s], and whether the steady-state window is reported."""

    m: int
    h: float
    w: float
    steady: bool = False


def _counts(r: RunData, rule: _Rule) -> dict[str, float]:
    """Everything the metrics of one stratum need from one run, as numbers that add up over
    runs (so a bootstrap replicate is a sum over resampled rows)."""
    f = far([r])
    ev = false_alarm_events([r])
    out = {
        "ff_a": f.alarms_ff,
        "ff_n": f.n_ff,
        "pre_a": f.alarms_pre,
        "pre_n": f.n_pre,
        "fa_ev": ev.n_events,
        "ok_h": ev.hours,
        "dr_hit": 0,
        "dr_tot": 0,
        "elig": 0,
        "det": 0,
        "delay": math.nan,
        "cens": math.nan,
        "ia_hit": 0,
        "ia_tot": 0,
        "t_on": math.nan,
        "w_len": math.nan,
        **_extra_counts(r, rule),
    }
    if r.is_faulty:
        out["dr_hit"], out["dr_tot"] = window_counts(r)
        d = detect_run(r, rule.m, rule.h, rule.w)
        if d.eligible:
            out.update(
                elig=1,
                det=int(d.detected),
                delay=d.delay,
                cens=d.delay if d.detected else d.horizon,
                t_on=d.onset_s,
                w_len=d.horizon,
            )
        if r.diagnosis is not None:
            out["ia_hit"], out["ia_tot"] = isolation_counts(r)
    return out


def _extra_counts(r: RunData, rule: _Rule) -> dict[str, float]:
    """The counts of the optional metrics: steady-state window (``rule.steady``) and
    channel isolation (with a ranking); zeros (nan delays) when the run has no such data."""
    out = {
        "st_hit": 0,
        "st_tot": 0,
        "st_elig": 0,
        "st_det": 0,
        "st_delay": math.nan,
        "st_t_on": math.nan,
        "st_w_len": math.nan,
        "hit_r": 0,
        "hit_n": 0,
        "loc_hit": 0,
        "loc_tot": 0,
    }
    if rule.steady and r.severity is not None:
        out["st_hit"], out["st_tot"] = steady_counts(r)
        d = steady_detection(r, rule.m, rule.h, rule.w) if r.is_faulty else None
        if d is not None and d.eligible:
            out.update(
                st_elig=1,
                st_det=int(d.detected),
                st_delay=d.delay,
                st_t_on=d.onset_s,
                st_w_len=d.horizon,
            )
    if r.ranking is not None:
        out["hit_r"], out["hit_n"] = run_hit(r, 1, rule.m, rule.h, rule.w)
        out["loc_hit"], out["loc_tot"] = localization_counts(r)
    return out


#: metric name -> function of a (replicates x runs) view of the per-run counts
_FROM_COUNTS = {
    "far_ff": lambda c: pooled_rate(c["ff_a"], c["ff_n"]),
    "far_pre": lambda c: pooled_rate(c["pre_a"], c["pre_n"]),
    "fa_per_h": lambda c: pooled_rate(c["fa_ev"], c["ok_h"]),
    "dr": lambda c: pooled_rate(c["dr_hit"], c["dr_tot"]),
    "pd": lambda c: pooled_rate(c["det"], c["elig"]),
    "dd_median_s": lambda c: _nanstat(np.nanmedian, c["delay"]),
    "dd_mean_s": lambda c: _nanstat(np.nanmean, c["delay"]),
    "dd_p90_s": lambda c: _nanstat(lambda x, axis: np.nanpercentile(x, 90, axis=axis), c["delay"]),
    "dd_censored_mean_s": lambda c: _nanstat(np.nanmean, c["cens"]),
    "ia": lambda c: pooled_rate(c["ia_hit"], c["ia_tot"]),
    "dr_steady": lambda c: pooled_rate(c["st_hit"], c["st_tot"]),
    "pd_steady": lambda c: pooled_rate(c["st_det"], c["st_elig"]),
    "dd_steady_median_s": lambda c: _nanstat(np.nanmedian, c["st_delay"]),
    "hit1": lambda c: pooled_rate(c["hit_r"], c["hit_n"]),
    "hit1_samples": lambda c: pooled_rate(c["loc_hit"], c["loc_tot"]),
}


def _nanstat(fn, x: np.ndarray) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-nan replicates give nan
        return fn(x, axis=-1)


def _bootstrap(
    counts: pd.DataFrame, n_boot: int, seed: int, level: float = 0.95
) -> dict[str, tuple[float, float, float]]:
    """Point estimate and percentile CI of every count-based metric, resampling runs
    (:func:`~r2rsim.evaluate.metrics.bootstrap_indices`, the resampling of
    :func:`~r2rsim.evaluate.metrics.bootstrap_ci`, vectorised over the replicates)."""
    cols = {k: counts[k].to_numpy(float) for k in counts.columns}
    idx = bootstrap_indices(len(counts), n_boot, seed)
    resampled = {k: v[idx] for k, v in cols.items()}
    percentiles = ci_percentiles(level)
    out = {}
    for name, fn in _FROM_COUNTS.items():
        boot = fn(resampled) if n_boot else np.empty(0)
        lo, hi, _ = percentile_interval(boot, percentiles)
        out[name] = (float(fn(cols)), lo, hi)
    return out


# --------------------------------------------------------------------------- evaluation


#: the metrics ``r2rsim diagnose`` prints (and the report's summary table shows), in order
PRINTED_METRICS = (
    "far_ff",
    "far_pre",
    "fa_per_h",
    "dr",
    "dr_steady",
    "pd",
    "pd_null",
    "dd_median_s",
    "dd_p90_s",
    "n_missed",
    "pd_steady",
    "pd_steady_null",
    "dd_steady_median_s",
    "roc_auc",
    "pr_auc",
    "vus_pr",
    "ia",
    "hit1",
    "mdm90",
    "far_ff_cal",
    "dr_cal",
    "dr_steady_cal",
    "pd_cal",
    "pd_null_cal",
    "dd_median_cal_s",
    "mdm90_cal",
)


@dataclass
class Evaluation:
    """What :func:`evaluate` measured.

    Attributes
    ----------
    method : str
        The plug-in's registry name.
    params : dict
        Its parameters (``get_params``).
    predictions : pandas.DataFrame
        One row per test sample: ``run_id, k, t_s, statistic, alarm`` (the plug-in's),
        ``alarm_cal`` (at theta, when calibrated) and ``diagnosis`` (when it diagnoses).
    metrics : pandas.DataFrame
        The long, typed results table: ``method, params_sha256, dataset_sha256, split,
        condition, fault, magnitude, metric, value, ci_low, ci_high, n_runs``.
    theta : float
        The calibrated threshold (nan without validation runs).
    settings : dict
        The harness settings (alpha, persistence, split, ...).
    test_datasets : list of str
        The dataset directories of the test runs (absolute), so that the report stage finds
        their labels again (``r2rsim report`` without ``--data``).
    """

    method: str
    params: dict
    predictions: pd.DataFrame
    metrics: pd.DataFrame
    theta: float
    settings: dict = field(default_factory=dict)
    test_datasets: list[str] = field(default_factory=list)

    def table(self) -> pd.DataFrame:
        """The results as a wide table: one row per stratum (magnitude rows left out), one
        column per metric."""
        m = self.metrics[self.metrics["magnitude"].isna() & ~self.metrics["metric"].isin(_META)]
        keys = ["condition", "fault"]
        order = pd.MultiIndex.from_frame(m[keys].drop_duplicates())
        wide = m.pivot_table(index=keys, columns="metric", values="value", aggfunc="first")
        wide.insert(0, "n_runs", m.groupby(keys)["n_runs"].max())
        wide.columns.name = None
        cols = ["n_runs"] + [k for k in METRICS if k in wide.columns]
        return wide.reindex(order)[cols]

    def format(self) -> str:
        """The readable table printed by ``r2rsim diagnose``."""
        t = self.table()
        show = ["n_runs", *(c for c in PRINTED_METRICS if c in t.columns)]
        st = self.settings
        own = {
            "val": f"own threshold recalibrated on val at alpha={st.get('alpha')}",
            "fit": "own threshold from fit",
        }.get(str(st.get("own_threshold")), "own threshold")
        head = (
            f"{self.method} {json.dumps(self.params, sort_keys=True, default=str)}  "
            f"[{st.get('split', '')}; m={st.get('m')}, h={st.get('h')} s, "
            f"W={st.get('detection_window', DETECTION_WINDOW_S):g} s, "
            f"alpha={st.get('alpha')}, theta={self.theta:.4g}, "
            f"fit {st.get('fit_s', math.nan):.2g} s]\n"
            f"columns without _cal: {own}; _cal: at theta"
        )
        if st.get("causal") is False:
            head += (
                "\nOFFLINE method: its statistic at t uses samples after t, so its "
                "delays (DD) and P_D are not those of an online detector"
            )
        short = {
            "fa_per_h": "FA/h",
            "dd_median_s": "DD med s",
            "dd_p90_s": "DD p90 s",
            "n_missed": "missed",
            "dd_median_cal_s": "DD_cal s",
            "dd_steady_median_s": "DD_st s",
            "pd_null": "pd_null",
            "pd_null_cal": "pd_null_cal",
        }
        body = (
            t[show].rename(columns=short).to_string(float_format=lambda v: f"{v:.3g}", na_rep="-")
        )
        return head + "\n" + body

    def write(self, outdir: str | Path, overwrite: bool = False) -> Path:
        """Write ``predictions.parquet``, ``metrics.parquet``, ``metrics.csv`` and
        ``datasets.json`` (the test dataset directories, :data:`DATASETS_FILE`).

        Parameters
        ----------
        outdir : str or Path
            A new or empty directory, or one holding only results of ``r2rsim diagnose``
            (:func:`r2rsim.evaluate.results.check_results_output`).
        overwrite : bool
            Replace earlier diagnose results there.

        Returns
        -------
        Path
            ``outdir``, written completely or not at all.

        Raises
        ------
        InputError
            When ``outdir`` holds anything else, or earlier results without ``overwrite``.
        """
        datasets = json.dumps({"test": self.test_datasets}, indent=1) + "\n"
        return write_results(
            outdir,
            "diagnose",
            {
                "predictions.parquet": lambda p: self.predictions.to_parquet(p, index=False),
                "metrics.parquet": lambda p: self.metrics.to_parquet(p, index=False),
                "metrics.csv": lambda p: self.metrics.to_csv(p, index=False),
                DATASETS_FILE: lambda p: p.write_text(datasets, encoding="utf-8"),
            },
            overwrite,
        )


def _sha(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()


def _check_healthy(runs: Sequence[Run], role: str) -> None:
    for r in runs:
        if is_faulty(r):
            raise InputError(
                f"{r.path}: run {r.run_id} has faults; {role} runs must be "
                f"fault-free (plug-ins learn from healthy data only)"
            )


def _check_disjoint(roles: dict[str, list[Run]]) -> None:
    seen: dict[tuple, str] = {}
    for role, runs in roles.items():
        for r in runs:
            key = (str(Path(r.path).resolve()), r.run_id)
            if key in seen and seen[key] != role:
                raise InputError(
                    f"run {r.run_id} ({r.path}) is both a {seen[key]} and a "
                    f"{role} run; the roles must not share runs"
                )
            seen.setdefault(key, role)


def _strata(test: list[Run]) -> list[tuple[str, str, list[int]]]:
    """(condition, fault, indices of test runs): each condition and fault, with pooled
    'all' levels where there is more than one value. A stratum holds the fault-free runs of
    its condition(s) and the faulty runs of its fault(s)."""
    cond = [r.mode or "-" for r in test]
    ftype = [fault_key(r) for r in test]
    conds = sorted(set(cond))
    out = []
    for c in conds + ([ALL] if len(conds) > 1 else []):
        out += _fault_strata(c, [i for i in range(len(test)) if c in (ALL, cond[i])], ftype)
    return out


def _fault_strata(c: str, in_c: list[int], ftype: list[str]) -> list[tuple[str, str, list[int]]]:
    """The fault strata of one condition holding the test runs ``in_c``."""
    healthy = [i for i in in_c if ftype[i] == NONE]
    present = sorted({ftype[i] for i in in_c} - {NONE})
    if not present:
        return [(c, NONE, healthy)]
    return [
        (c, t, healthy + [i for i in in_c if ftype[i] != NONE and t in (ALL, ftype[i])])
        for t in present + ([ALL] if len(present) > 1 else [])
    ]


def _mode_strata(
    test: list[Run], view: list[RunData], mode: str
) -> list[tuple[str, str, list[int]]]:
    """The strata of one regime: the test runs with a scored sample in it (``view``: the
    runs restricted to it, :func:`restrict_to_mode`), by fault as in :func:`_strata`."""
    in_m = [i for i, r in enumerate(view) if r.scored.any()]
    return _fault_strata(MODE_PREFIX + mode, in_m, [fault_key(r) for r in test])


def _modes(rd: list[RunData]) -> list[str]:
    """The regimes (``label.mode`` values but "") of the scored samples of the runs."""
    return sorted({m for r in rd if r.mode is not None for m in np.unique(r.mode[r.scored])} - {""})


def evaluate(
    estimator,
    train: Sequence[Run],
    test: Sequence[Run],
    val: Sequence[Run] = (),
    *,
    alpha: float = 0.01,
    m: int = 1,
    h: float = 0.0,
    n_boot: int = 1000,
    seed: int = 0,
    split: str = "explicit",
    drive_data: bool = False,
    mode_strata: bool = False,
    window: str = "fault",
    isolation: bool = False,
    vus_buffer: float | None = None,
    detection_window: float = DETECTION_WINDOW_S,
    own_threshold: str = "val",
) -> Evaluation:
    """Fit a plug-in on healthy runs, score the test runs and compute every metric.

    Parameters
    ----------
    estimator : Diagnostic
        An unfitted plug-in instance (it is cloned, never modified).
    train : sequence of Run
        Fault-free runs to fit on.
    test : sequence of Run
        Runs to score (faulty and fault-free).
    val : sequence of Run, optional
        Fault-free runs on which the harness calibrates theta at ``alpha`` (M6); without them
        the ``*_cal`` metrics are not reported.
    alpha : float
        Target false-alarm rate of the calibration.
    m : int
        Persistence for detection (P_D, delays).
    h : float
        Grace period after a fault's end, in seconds.
    detection_window : float
        W [s]: a fault is detected only within W of the moment it is fully developed (and
        not after its end plus h); ``inf``: up to the fault's end plus h. Default
        :data:`~r2rsim.evaluate.metrics.DETECTION_WINDOW_S`.
    own_threshold : {"val", "fit"}
        ``"val"`` (default): with validation runs, the plug-in's own threshold is moved by
        its :meth:`~r2rsim.diagnostics.base.Diagnostic.calibrate` so that its own alarms hold
        ``alpha`` on them; ``"fit"``: the threshold its ``fit`` set is kept.
    n_boot : int
        Bootstrap replicates over runs for the confidence intervals (0: none).
    seed : int
        Seed of the bootstrap, from 0 to 2**64 - 1.
    split : str
        Name of the split, recorded in the table.
    drive_data : bool
        Also show the plug-in the drive data (``cmd.*``, ``act.*``, ``ctrl.*``), for a
        protocol that treats them as observable (:meth:`r2rsim.dataset.read.Run.visible`).
    mode_strata : bool
        Also report the per-sample metrics per operating regime (``label.mode``), as strata
        ``mode:<name>`` × fault: a run that switches regimes contributes each sample to the
        stratum of its regime.
    window : {"fault", "steady"}
        ``"steady"`` also reports ``dr_steady``, ``pd_steady`` and ``dd_steady_median_s``
        over the samples with ``label.severity`` 1 (the fault fully developed).
    isolation : bool
        Score the plug-in's :meth:`~r2rsim.diagnostics.base.Diagnostic.rank_channels`
        against ``label.ch.*`` (``hit1``, ``hit1_samples``); nothing when it returns None.
    vus_buffer : float, optional
        Report ``vus_pr`` with buffer lengths from 0 up to this many seconds (rounded to
        samples of the test runs' median period); None: not reported. At most
        :data:`~r2rsim.limits.MAX_VUS_BUFFER_S` and
        :data:`~r2rsim.limits.MAX_VUS_BUFFER_SAMPLES` samples.

    Returns
    -------
    Evaluation
    """
    check_settings(
        alpha=alpha,
        m=m,
        h=h,
        n_boot=n_boot,
        window=window,
        vus_buffer=vus_buffer,
        seed=seed,
        detection_window=detection_window,
        own_threshold=own_threshold,
    )
    train, val, test = list(train), list(val), list(test)
    if not train:
        raise InputError("no training runs")
    if not test:
        raise InputError("no test runs")
    _check_healthy(train, "training")
    _check_healthy(val, "validation")
    _check_disjoint({"train": train, "val": val, "test": test})
    max_buffer = _vus_max_buffer(vus_buffer, test)  # before the fit, which may take long
    plugin = _Scored(estimator, drive_data)
    fit_s = plugin.fit(train)
    recalibrated = bool(val) and own_threshold == "val"
    theta = plugin.calibrate(val, alpha, recalibrated) if val else math.nan

    t0 = time.perf_counter()
    ranks = isolation and hasattr(plugin.est, "rank_channels")
    scored = [plugin.outputs(r, ranks) for r in test]
    exec_s = time.perf_counter() - t0
    rd, rd_cal = _run_data(test, scored, theta if val else None, mode_strata, window)

    dataset_sha = _sha(
        sorted(
            (r.info.get("scenario_sha256"), int(r.info["seed"]), role)
            for role, rs in (("train", train), ("val", val), ("test", test))
            for r in rs
        )
    )
    params_sha = _sha(plugin.params)
    base = {
        "method": plugin.name,
        "params_sha256": params_sha,
        "dataset_sha256": dataset_sha,
        "split": split,
        "causal": plugin.causal,
        "own_threshold": "val" if recalibrated else "fit",
    }
    rule = _Rule(m, h, float(detection_window), steady=window == "steady")
    table = _MetricTable(base, rule, n_boot, seed, max_buffer)
    table.add_strata(test, rd, rd_cal)
    if mode_strata:
        table.add_mode_strata(test, rd, rd_cal)
    table.add(ALL, ALL, math.nan, "fit_s", fit_s, n=len(train))
    sim_h = sum(float(r.samples["t_s"].iloc[-1] - r.samples["t_s"].iloc[0]) for r in test) / 3600
    if sim_h > 0:
        table.add(ALL, ALL, math.nan, "exec_s_per_sim_h", exec_s / sim_h, n=len(test))
    if val:
        table.add(ALL, ALL, math.nan, "theta", theta, n=len(val))
    return Evaluation(
        plugin.name,
        plugin.params,
        _predictions(test, scored, rd_cal, plugin.name, params_sha),
        table.frame(),
        theta,
        {
            "alpha": alpha,
            "m": m,
            "h": h,
            "detection_window": detection_window,
            "own_threshold": "val" if recalibrated else "fit",
            "causal": plugin.causal,
            "n_boot": n_boot,
            "seed": seed,
            "split": split,
            "fit_s": fit_s,
            "drive_data": drive_data,
            "mode_strata": mode_strata,
            "window": window,
            "isolation": isolation,
            "vus_buffer": vus_buffer,
            "vus_max_buffer_samples": max_buffer,
        },
        list(dict.fromkeys(str(Path(r.path).resolve()) for r in test)),
    )


def check_settings(
    *,
    alpha: float = 0.01,
    m: int = 1,
    h: float = 0.0,
    n_boot: int = 1000,
    window: str = "fault",
    vus_buffer: float | None = None,
    seed: int = 0,
    detection_window: float = DETECTION_WINDOW_S,
    own_threshold: str = "val",
) -> None:
    """Check the settings of :func:`evaluate` (same names and meaning) before any data is
    read: ``r2rsim diagnose`` calls it first, so a bad flag costs nothing.

    Raises
    ------
    InputError
        Naming the setting, its bounds and the value.
    """
    if not 0.0 < alpha < 1.0:
        raise InputError(f"alpha must be in (0, 1), got {alpha!r}")
    if int(m) != m or m < 1:
        raise InputError(f"persistence m must be an integer >= 1, got {m!r}")
    if not h >= 0:
        raise InputError(f"grace period h must be >= 0 s, got {h!r}")
    if (
        isinstance(detection_window, bool)
        or not isinstance(detection_window, (int, float, np.integer, np.floating))
        or not detection_window > 0
    ):
        raise InputError(
            f"detection window must be a time > 0 s (inf: up to the fault's "
            f"end), got {detection_window!r}"
        )
    if own_threshold not in OWN_THRESHOLDS:
        raise InputError(
            f"own_threshold must be one of {', '.join(OWN_THRESHOLDS)}, got {own_threshold!r}"
        )
    if not 0 <= n_boot <= MAX_BOOTSTRAP:
        raise InputError(
            f"n_boot must be from 0 to {MAX_BOOTSTRAP} (docs/security.md), got {n_boot!r}"
        )
    if window not in WINDOWS:
        raise InputError(f"window must be one of {', '.join(WINDOWS)}, got {window!r}")
    if vus_buffer is not None and not 0 <= vus_buffer <= MAX_VUS_BUFFER_S:
        raise InputError(
            f"vus_buffer must be from 0 to {MAX_VUS_BUFFER_S:g} s "
            f"(docs/security.md), got {vus_buffer!r}"
        )
    # the bounds of a run's seed; numpy refuses a negative one (with a traceback)
    if (
        isinstance(seed, bool)
        or not isinstance(seed, (int, np.integer))
        or not 0 <= seed <= MAX_SEED
    ):
        raise InputError(f"seed must be an integer from 0 to 2**64 - 1, got {seed!r}")


def _vus_max_buffer(vus_buffer: float | None, test: list[Run]) -> int | None:
    """``vus_buffer`` [s] in samples of the test runs' median period (None: no VUS-PR),
    refused above :data:`~r2rsim.limits.MAX_VUS_BUFFER_SAMPLES`."""
    if vus_buffer is None:
        return None
    periods = [
        float(np.median(np.diff(t)))
        for r in test
        if (t := r.samples["t_s"].to_numpy(float)).size > 1
    ]
    period = float(np.median(periods)) if periods else 1.0
    n = vus_buffer / period
    if not n <= MAX_VUS_BUFFER_SAMPLES:
        raise InputError(
            f"vus_buffer {vus_buffer:g} s is {n:.3g} samples of the test runs "
            f"(period {period:g} s), more than the limit of "
            f"{MAX_VUS_BUFFER_SAMPLES} buffer lengths (docs/security.md): "
            f"lower it"
        )
    return int(round(n))


class _Scored:
    """A clone of the plug-in under evaluation, called through :func:`call` so that its
    failures are named, and given the visible columns of runs only."""

    def __init__(self, estimator, drive_data: bool):
        self.est = call(estimator, "clone", clone, estimator)
        self.name = getattr(self.est, "name", type(self.est).__name__)
        self.params = call(self.est, "get_params", self.est.get_params)
        self.drive_data = drive_data
        is_causal = getattr(self.est, "is_causal", None)
        self.causal = bool(
            is_causal() if callable(is_causal) else getattr(self.est, "causal", True)
        )

    def frame(self, run: Run) -> pd.DataFrame:
        """The plug-in's view of a run: no labels, faults or true states; the run's line in
        ``attrs`` (:func:`r2rsim.diagnostics.line.frame_line`)."""
        f = attach_line(run.visible(self.drive_data), run)
        try:
            self.est.required_columns(f)
        except InputError as exc:
            raise InputError(f"{exc.message} (run {run.run_id} in {run.path})") from None
        return f

    def fit(self, train: list[Run]) -> float:
        """Fit on the training runs; returns the wall time [s]."""
        frames = [self.frame(r) for r in train]
        t0 = time.perf_counter()
        call(self.est, "fit", self.est.fit, frames)
        return time.perf_counter() - t0

    def calibrate(self, val: list[Run], alpha: float, own: bool) -> float:
        """Theta at false-alarm rate ``alpha`` on the scored samples of the validation runs
        (M6); with ``own``, first the plug-in's own threshold through its ``calibrate``."""
        if own:
            frames = [self.frame(r) for r in val]
            masks = [r.samples["label.score_mask"].to_numpy(bool) for r in val]
            if not callable(getattr(self.est, "calibrate", None)):
                raise PluginError(
                    f"plug-in '{self.name}' has no calibrate(runs, alpha, "
                    f"masks) method: derive it from r2rsim.diagnostics."
                    f"Diagnostic, or evaluate with own_threshold='fit'"
                )
            call(self.est, "calibrate", self.est.calibrate, frames, alpha, masks)
        cal = [self.outputs(r) for r in val]
        pool = np.concatenate(
            [
                s[r.samples["label.score_mask"].to_numpy(bool)]
                for r, (s, *_) in zip(val, cal, strict=True)
            ]
        )
        pool = pool[~np.isnan(pool)]  # +inf alarms at any theta: it counts as an exceedance
        if not np.isfinite(pool).any():
            raise InputError(f"{self.name}: no finite statistic on the validation runs")
        return calibrate_threshold(pool, alpha)

    def outputs(self, run: Run, rank: bool = False) -> tuple:
        """(statistic, alarm, diagnosis or None, ranking or None) of one run, each checked
        against the contract."""
        est, name = self.est, self.name
        f = self.frame(run)
        where = f"run {run.run_id} of {run.path}"
        scores = call(est, f"score ({where})", est.score, f)
        if not isinstance(scores, pd.DataFrame) or "statistic" not in scores.columns:
            got = (
                "a DataFrame without a 'statistic' column"
                if isinstance(scores, pd.DataFrame)
                else f"a {type(scores).__name__}"
            )
            raise PluginError(
                f"plug-in '{name}': score ({where}) returned {got}; it must "
                f"return a DataFrame with a 'statistic' column"
            )
        if not scores.index.equals(f.index):
            raise InputError(
                f"{name}: score() returned rows not aligned to the samples of run {run.run_id}"
            )
        stat = call(est, f"score ({where})", scores["statistic"].to_numpy, float)
        alarm = np.asarray(call(est, f"decide ({where})", est.decide, scores), dtype=bool)
        diag = (
            np.asarray(call(est, f"diagnose ({where})", est.diagnose, scores)).astype(str)
            if hasattr(est, "diagnose")
            else None
        )
        if len(alarm) != len(f) or (diag is not None and len(diag) != len(f)):
            raise PluginError(
                f"plug-in '{name}': decide/diagnose ({where}) returned "
                f"{len(alarm)} values for {len(f)} samples"
            )
        if not rank:
            return stat, alarm, diag, None
        ranking = call(est, f"rank_channels ({where})", est.rank_channels, scores)
        if ranking is not None and (
            not isinstance(ranking, pd.DataFrame) or len(ranking) != len(f)
        ):
            raise PluginError(
                f"plug-in '{name}': rank_channels ({where}) must return None "
                f"or a DataFrame with one row per sample"
            )
        return stat, alarm, diag, ranking


def ranking_scores(statistics: Sequence[np.ndarray]) -> list[np.ndarray]:
    """The statistics of several runs as their ranks over all of them (ties share a rank), the
    score ROC-AUC, AP and VUS-PR read: they depend only on the order, and a rank keeps it
    where a value cannot (+inf ranks highest; a NaN, which the plug-in could not compute,
    ranks lowest, with -inf; statistics beyond 2**53 stay apart from the lowest)."""
    pooled = np.concatenate([np.where(np.isnan(s), -np.inf, s) for s in statistics])
    ranks = rankdata(pooled, method="average")
    return np.split(ranks, np.cumsum([len(s) for s in statistics])[:-1])


def _run_data(
    test: list[Run], scored: list[tuple], theta: float | None, mode_strata: bool, window: str
) -> tuple[list[RunData], list[RunData] | None]:
    """The test runs' RunData at the plug-in's own threshold, and (with ``theta``) the same
    runs with the alarms at theta."""
    ranks = ranking_scores([s for s, *_ in scored])
    rd = [
        run_data(r, rank, a, d, ranking=rk, modes=mode_strata, steady=window == "steady")
        for r, rank, (s, a, d, rk) in zip(test, ranks, scored, strict=True)
    ]
    # the same runs at theta: only the alarm differs (a nan statistic never exceeds theta)
    rd_cal = (
        [replace(x, alarm=o[0] > theta) for x, o in zip(rd, scored, strict=True)]
        if theta is not None
        else None
    )
    return rd, rd_cal


#: the percentiles of pd_null's 95 % interval. They are written out rather than
#: ci_percentiles(0.95) = (2.500000000000002, 97.5), which the other intervals use, so that
#: its bounds stay the numbers they have always been, to the last bit.
_NULL_PERCENTILES = (2.5, 97.5)


class _NullRates:
    """pd_null of one set of alarms (the plug-in's, or at theta): the detection rule applied
    to the fault-free test runs at the pretend windows of a stratum's faulty runs, with the
    (run, window) outcomes cached across strata."""

    def __init__(self, runs: list[RunData], m: int, n_boot: int, seed: int):
        self.runs, self.m, self.n_boot, self.seed = runs, m, n_boot, seed
        self._cache: dict[tuple[int, float, float], tuple[int, int]] = {}

    def counts(self, healthy: list[int], windows: list[tuple[float, float]]) -> np.ndarray:
        """(detected, eligible) per fault-free run of ``healthy`` over ``windows``."""
        want = collections.Counter(windows)
        out = np.zeros((len(healthy), 2))
        for row, i in enumerate(healthy):
            todo = [w for w in want if (i, *w) not in self._cache]
            for w, o in zip(todo, null_outcomes(self.runs[i], todo, self.m), strict=True):
                self._cache[(i, *w)] = (int(o is True), int(o is not None))
            out[row] = np.sum(
                [np.multiply(self._cache[(i, *w)], k) for w, k in want.items()], axis=0
            )
        return out

    def rate(
        self, healthy: list[int], windows: list[tuple[float, float]]
    ) -> tuple[float, float, float]:
        """pd_null with its percentile bootstrap CI over the fault-free runs."""
        if not healthy or not windows:
            return math.nan, math.nan, math.nan
        c = self.counts(healthy, windows)
        est = float(pooled_rate(c[:, 0], c[:, 1]))
        if not self.n_boot:
            return est, math.nan, math.nan
        idx = bootstrap_indices(len(c), self.n_boot, self.seed)
        lo, hi, _ = percentile_interval(pooled_rate(c[idx, 0], c[idx, 1]), _NULL_PERCENTILES)
        return est, lo, hi


#: a set of runs with their per-run counts and null rates (:meth:`_MetricTable._view`)
_View = tuple[list[RunData], pd.DataFrame, _NullRates]


def _windows(counts: pd.DataFrame, steady: bool = False) -> list[tuple[float, float]]:
    """The detection windows (onset time, length) of the eligible faulty runs of ``counts``
    (``steady``: the windows of ``pd_steady``, from the first severity-1 sample)."""
    p = "st_" if steady else ""
    c = counts[counts[f"{p}elig"] > 0]
    return list(zip(c[f"{p}t_on"].astype(float), c[f"{p}w_len"].astype(float), strict=True))


class _MetricTable:
    """The rows of the long results table, stratum by stratum."""

    def __init__(self, base: dict, rule: _Rule, n_boot: int, seed: int, max_buffer: int | None):
        self.base, self.rule = base, rule
        self.n_boot, self.seed, self.max_buffer = n_boot, seed, max_buffer
        self.rows: list[dict] = []

    def add(self, cond, ftype, mag, metric, value, lo=math.nan, hi=math.nan, n=0):
        if value is None or (isinstance(value, float) and math.isnan(value)):
            return
        self.rows.append(
            {
                **self.base,
                "condition": cond,
                "fault": ftype,
                "magnitude": mag,
                "metric": metric,
                "value": float(value),
                "ci_low": lo,
                "ci_high": hi,
                "n_runs": n,
            }
        )

    def _counts(self, runs: list[RunData] | None) -> pd.DataFrame | None:
        """Per-run counts, once per run; a stratum takes its runs' rows."""
        return None if runs is None else pd.DataFrame([_counts(r, self.rule) for r in runs])

    def _view(self, rd: list[RunData] | None):
        """A set of runs with their per-run counts and their null rates."""
        if rd is None:
            return None
        return rd, self._counts(rd), _NullRates(rd, self.rule.m, self.n_boot, self.seed)

    def add_strata(self, test: list[Run], rd: list[RunData], rd_cal) -> None:
        """Every condition × fault stratum, by magnitude where there are several, with the
        minimum detectable magnitude."""
        view, view_cal = self._view(rd), self._view(rd_cal)
        for cond, ftype, idx in _strata(test):
            self.stratum(cond, ftype, math.nan, idx, view, view_cal)
            faulty_idx = [i for i in idx if rd[i].is_faulty]
            healthy = [i for i in idx if not rd[i].is_faulty]
            mags = np.array([rd[i].magnitude for i in faulty_idx])
            mags = np.unique(mags[np.isfinite(mags)])
            if ftype in (NONE, ALL) or mags.size <= 1:
                continue
            by_mag = {float(mg): [i for i in faulty_idx if rd[i].magnitude == mg] for mg in mags}
            for mg, at in by_mag.items():
                self.stratum(cond, ftype, mg, at, view, view_cal, healthy)
            for key, v in (("mdm90", view), ("mdm90_cal", view_cal)):
                if v is not None:
                    self._mdm(cond, ftype, key, v, by_mag, healthy)

    def _mdm(self, cond, ftype, key, view, by_mag: dict, healthy: list[int]) -> None:
        """M15 over the magnitudes of one stratum, each tested against its own null rate."""
        _, counts, nulls = view
        mag, det, null = [], [], {}
        for mg, at in by_mag.items():
            c = counts.iloc[at]
            c = c[c["elig"] > 0]
            mag += [mg] * len(c)
            det += c["det"].astype(bool).tolist()
            null[mg] = nulls.rate(healthy, _windows(c))[0]
        curve = detectability(mag, det, null=null)
        self.add(cond, ftype, math.nan, key, abs(curve.mdm), n=len(mag))

    def add_mode_strata(self, test: list[Run], rd: list[RunData], rd_cal) -> None:
        """The per-sample metrics of each regime (``label.mode``) × fault."""
        for mode in _modes(rd):
            view = [restrict_to_mode(r, mode) for r in rd]
            view_cal = (
                [replace(r, alarm=x.alarm) for r, x in zip(view, rd_cal, strict=True)]
                if rd_cal
                else None
            )
            v, v_cal = self._view(view), self._view(view_cal)
            for cond, ftype, idx in _mode_strata(test, view, mode):
                self.stratum(cond, ftype, math.nan, idx, v, v_cal, regime=True)

    def stratum(
        self,
        cond,
        ftype,
        mag,
        idx,
        view: _View,
        view_cal: _View | None,
        healthy=None,
        regime: bool = False,
    ) -> None:
        """Add the rows of one stratum. ``view``/``view_cal``: (runs, their counts, their
        null rates) at the plug-in's alarms and at theta; ``healthy``: the fault-free runs
        whose pretend onsets give pd_null (default: those of ``idx``); ``regime``: runs
        restricted to a regime, per-sample metrics only."""
        runs_all, pr, nulls = view
        skip = _RUN_LEVEL if regime else frozenset()
        runs = [runs_all[i] for i in idx]
        n = len(idx)
        if healthy is None:
            healthy = [i for i in idx if not runs_all[i].is_faulty]
        counts = pr.iloc[idx]
        for metric, (est_, lo, hi) in _bootstrap(counts, self.n_boot, self.seed).items():
            if (metric == "ia" and runs[0].diagnosis is None) or metric in skip:
                continue
            self.add(cond, ftype, mag, metric, est_, lo, hi, n)
        n_faulty = int(counts["elig"].sum())
        if n_faulty and not regime:
            self.add(cond, ftype, mag, "n_missed", float(n_faulty - counts["det"].sum()), n=n)
            self.add(
                cond, ftype, mag, "pd_null", *nulls.rate(healthy, _windows(counts)), n=len(healthy)
            )
        if counts["st_elig"].sum() and not regime:
            self.add(
                cond,
                ftype,
                mag,
                "pd_steady_null",
                *nulls.rate(healthy, _windows(counts, steady=True)),
                n=len(healthy),
            )
        s, y = pooled_scores(runs)
        if y.any() and not y.all():
            self.add(cond, ftype, mag, "roc_auc", roc_auc(s, y), n=n)
            self.add(cond, ftype, mag, "pr_auc", average_precision(s, y), n=n)
            if self.max_buffer is not None:
                g = scored_groups(runs)
                self.add(cond, ftype, mag, "vus_pr", vus_pr(s, y, self.max_buffer, groups=g), n=n)
        if view_cal is None:
            return
        _, prc, nulls_cal = view_cal
        cc = prc.iloc[idx]
        for metric, (est_, lo, hi) in _bootstrap(cc, self.n_boot, self.seed).items():
            if metric in _CAL and metric not in skip:
                self.add(cond, ftype, mag, _CAL[metric], est_, lo, hi, n)
        if n_faulty and not regime:
            self.add(
                cond,
                ftype,
                mag,
                "pd_null_cal",
                *nulls_cal.rate(healthy, _windows(cc)),
                n=len(healthy),
            )

    def frame(self) -> pd.DataFrame:
        """The typed long table."""
        metrics = pd.DataFrame(
            self.rows,
            columns=[
                *self.base,
                "condition",
                "fault",
                "magnitude",
                "metric",
                "value",
                "ci_low",
                "ci_high",
                "n_runs",
            ],
        )
        return metrics.astype(
            {
                "magnitude": float,
                "value": float,
                "ci_low": float,
                "ci_high": float,
                "n_runs": "int64",
            }
        )


def _predictions(
    test: list[Run], scored: list[tuple], rd_cal, name: str, params_sha: str
) -> pd.DataFrame:
    """One row per test sample: the plug-in's statistic, alarm (and at theta), diagnosis."""
    preds = []
    for r, (s, a, d, _), rc in zip(test, scored, rd_cal or [None] * len(test), strict=True):
        p = pd.DataFrame(
            {
                "run_id": r.run_id,
                "k": r.samples["k"].to_numpy(np.int64),
                "t_s": r.samples["t_s"].to_numpy(float),
                "statistic": s,
                "alarm": a,
            }
        )
        if rc is not None:
            p["alarm_cal"] = rc.alarm
        if d is not None:
            p["diagnosis"] = d
        preds.append(p)
    predictions = pd.concat(preds, ignore_index=True)
    predictions["method"] = name
    predictions["params_sha256"] = params_sha
    return predictions
