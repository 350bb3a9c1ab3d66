"""Figures of diagnostics results: the results tables of ``r2rsim diagnose`` (metrics.parquet,
predictions.parquet) and ``r2rsim bench`` (results.parquet).

The per-sample figures (statistic over time, ROC and PR curves) need the ground truth, which
the results directories do not hold: they take the test datasets the results were scored on.
The curves pool the scored samples exactly as :func:`r2rsim.evaluate.harness.evaluate` does
(:func:`~r2rsim.evaluate.harness.run_data`, :func:`~r2rsim.evaluate.metrics.pooled_scores`),
so their areas are the ``roc_auc`` and ``pr_auc`` of the results table.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from pathlib import Path
from typing import TypeAlias

import numpy as np
import pandas as pd

from ..dataset.read import Run
from ..errors import InputError
from ..evaluate.harness import ALL, METRICS, NONE, fault_key, run_data
from ..evaluate.metrics import average_precision, pooled_scores, roc_auc
from ._data import label_runs
from ._mpl import axis_label, display_unit, plain_ticks, require_matplotlib, wrap_title

#: the results file of each kind of results directory
DIAGNOSE_FILE = "metrics.parquet"
PREDICTIONS_FILE = "predictions.parquet"
BENCH_FILE = "results.parquet"
#: the values of ``by`` in :func:`plot_metric`
BY = ("condition", "fault", "magnitude")
#: the P_D level of MDM90
MDM_LEVEL = 0.9

Results: TypeAlias = str | Path | pd.DataFrame | Sequence[str | Path | pd.DataFrame]


# --------------------------------------------------------------------------- reading


def results_kind(path: str | Path) -> str:
    """``"diagnose"`` or ``"bench"``: which command wrote the results directory.

    Raises
    ------
    InputError
        When ``path`` is not a directory or holds neither results file.
    """
    d = Path(path)
    if not d.is_dir():
        raise InputError(f"{d}: no such results directory")
    if (d / DIAGNOSE_FILE).is_file():
        return "diagnose"
    if (d / BENCH_FILE).is_file():
        return "bench"
    raise InputError(
        f"{d}: not an r2rsim results directory (no {DIAGNOSE_FILE} written by "
        f"`r2rsim diagnose`, no {BENCH_FILE} written by `r2rsim bench -o`)"
    )


#: the columns of predictions.parquet the figures use (the others are not read)
PREDICTION_COLUMNS = ("run_id", "k", "t_s", "statistic", "alarm", "method")


def _read_table(path: Path, columns=None) -> pd.DataFrame:
    """A Parquet file of a results directory (``columns``: these of them, those it has);
    one InputError naming it when it cannot be read (truncated, not Parquet)."""
    try:
        if columns is not None:
            import pyarrow.parquet as pq

            names = set(pq.read_schema(path).names)
            columns = [c for c in columns if c in names]
        return pd.read_parquet(path, columns=columns)
    except Exception as exc:  # noqa: BLE001 - pyarrow raises several types on bad files
        first = (str(exc).strip().splitlines() or [""])[0]
        raise InputError(
            f"{path}: not a readable Parquet file ({type(exc).__name__}: {first})"
        ) from None


def results_table(results: Results) -> pd.DataFrame:
    """The long results table (one row per method × stratum × metric) with a ``series``
    column naming the method: the plug-in for diagnose, the bench label (with its study
    when the bench has several)."""
    if isinstance(results, Sequence) and not isinstance(results, str):
        return pd.concat([results_table(r) for r in results], ignore_index=True)
    source = None
    if isinstance(results, pd.DataFrame):
        table = results.copy()
    else:
        d = Path(results)
        source = d / (DIAGNOSE_FILE if results_kind(d) == "diagnose" else BENCH_FILE)
        table = _read_table(source)
    missing = {"condition", "fault", "magnitude", "metric", "value"} - set(table.columns)
    if missing or not {"method", "label"} & set(table.columns):
        raise InputError(
            f"{f'{source}: ' if source else ''}not a results table of r2rsim "
            f"diagnose or bench: no column "
            f"{', '.join(sorted(missing) or ['method'])}"
        )
    if "label" in table.columns:  # bench
        several = "study" in table.columns and table["study"].nunique() > 1
        table["series"] = table["study"] + "/" + table["label"] if several else table["label"]
    else:
        table["series"] = table["method"]
    if "causal" in table.columns:  # an offline method is named so in every figure
        offline = table["causal"].astype("boolean").eq(False).fillna(False).to_numpy(bool)
        table.loc[offline, "series"] = table.loc[offline, "series"] + " (offline)"
    return table


def _predictions(results: Results) -> pd.DataFrame:
    """The predictions of one or more diagnose directories (or a predictions DataFrame)."""
    if isinstance(results, Sequence) and not isinstance(results, str):
        return pd.concat([_predictions(r) for r in results], ignore_index=True)
    if isinstance(results, pd.DataFrame):
        return results
    d = Path(results)
    if results_kind(d) != "diagnose" or not (d / PREDICTIONS_FILE).is_file():
        raise InputError(
            f"{d}: no {PREDICTIONS_FILE} (written by `r2rsim diagnose`; a bench directory has none)"
        )
    return _read_table(d / PREDICTIONS_FILE, PREDICTION_COLUMNS)


def _test_runs(datasets: Sequence[str | Path] | str | Path, run_ids) -> dict[str, Run]:
    """The runs of the datasets (paths, or runs already read), by run id; every run of the
    predictions must be among them."""
    if isinstance(datasets, str | Path):
        datasets = [datasets]
    datasets = list(datasets or [])
    if not datasets:
        raise InputError(
            "name the test datasets the results were scored on (their labels "
            "and faults are not in the results directory)"
        )
    paths = [d for d in datasets if not isinstance(d, Run)]
    runs: dict[str, Run] = {}
    # only the label columns of the samples: the figures draw no channel
    for r in [d for d in datasets if isinstance(d, Run)] + (label_runs(paths) if paths else []):
        if r.run_id in runs:
            raise InputError(
                f"run {r.run_id} is in {runs[r.run_id].path} and in {r.path}; "
                f"name the test datasets only once"
            )
        runs[r.run_id] = r
    missing = [rid for rid in dict.fromkeys(run_ids) if rid not in runs]
    if missing:
        raise InputError(
            f"run {missing[0]} of the predictions is in none of the datasets "
            f"{', '.join(str(getattr(d, 'path', d)) for d in datasets)}"
            + (f" ({len(missing) - 1} more missing)" if len(missing) > 1 else "")
        )
    return runs


def _aligned(p: pd.DataFrame, run: Run) -> pd.DataFrame:
    """The predictions of one run in the order of its samples."""
    k = run.samples["k"].to_numpy(np.int64)
    if len(p) != len(k) or not np.array_equal(np.sort(p["k"].to_numpy(np.int64)), k):
        raise InputError(
            f"run {run.run_id} of {run.path} has {len(k)} samples, the "
            f"predictions {len(p)} others: not the dataset it was scored on"
        )
    return p.set_index("k").loc[k]


def _theta(table: pd.DataFrame, series: str) -> float:
    """The threshold the harness calibrated (M6), nan when it had no validation runs."""
    rows = table[(table["series"] == series) & (table["metric"] == "theta")]
    return float(rows["value"].iloc[0]) if len(rows) else math.nan


# --------------------------------------------------------------------------- statistic


def plot_statistic(
    results: str | Path, datasets, run_id: str | None = None, *, theta: float | None = None
):
    """The detector statistic of one test run over time, with the calibrated threshold, the
    plug-in's alarms and the fault windows.

    Parameters
    ----------
    results : str or Path
        A directory written by ``r2rsim diagnose``.
    datasets : path or sequence of paths (or of Run)
        The test datasets the results were scored on (their faults.parquet gives the fault
        windows; the results directory does not record them).
    run_id : str, optional
        The run to show; default the first faulty test run (else the first run).
    theta : float, optional
        The threshold to draw (default: the one in the results' metrics table; give it when
        ``results`` is a predictions DataFrame already read).

    Returns
    -------
    matplotlib.figure.Figure
        One axes: the statistic, the threshold theta (M6) as a dashed line when the harness
        calibrated one, the plug-in's alarms as markers, each fault window shaded from its
        onset to its end (the end of the run when it lasts) and the unscored warm-up greyed.
    """
    Figure = require_matplotlib()
    preds = _predictions(results)
    runs = _test_runs(datasets, preds["run_id"])
    ids = list(dict.fromkeys(preds["run_id"]))
    if run_id is None:
        run_id = next((i for i in ids if len(runs[i].faults)), ids[0])
    if run_id not in ids:
        raise InputError(
            f"no run '{run_id}' in the predictions of {results} (runs: "
            f"{', '.join(ids[:5])}{', ...' if len(ids) > 5 else ''})"
        )
    run = runs[run_id]
    p = _aligned(preds[preds["run_id"] == run_id], run)
    t, stat, alarm = p["t_s"].to_numpy(), p["statistic"].to_numpy(), p["alarm"].to_numpy(bool)
    method = str(p["method"].iloc[0])
    if theta is None:
        theta = _theta(results_table(results), method)

    fig = Figure(figsize=(8, 3.5), layout="constrained")
    ax = fig.add_subplot()
    scored = run.samples["label.score_mask"].to_numpy(bool)
    if scored.any() and not scored[0]:
        ax.axvspan(t[0], t[np.argmax(scored)], color="0.85", label="warm-up (not scored)")
    for f in run.faults.itertuples(index=False):
        end = f.end_t_s if np.isfinite(f.end_t_s) else t[-1]
        unit = getattr(f, "magnitude_unit", "") or ""
        ax.axvspan(
            f.onset_t_s,
            min(end, t[-1]),
            color="tab:red",
            alpha=0.15,
            gid=f"fault:{f.fault_id}",
            label=f"fault {f.fault_type} on {f.target_id} ({f.magnitude:g} {unit})",
        )
    ax.plot(t, stat, color="tab:blue", lw=0.8, label=f"statistic ({method})")
    if np.isfinite(theta):
        ax.axhline(
            theta,
            color="k",
            ls="--",
            lw=1,
            gid="theta",
            label=f"threshold θ = {theta:.4g} (calibrated)",
        )
    ax.plot(
        t[alarm],
        stat[alarm],
        ls="none",
        marker="|",
        color="tab:orange",
        ms=8,
        gid="alarms",
        label=f"alarm ({int(alarm.sum())} samples)",
    )
    ax.set(
        xlabel=axis_label("time", "s"),
        ylabel=axis_label("detector statistic", "1"),
        xlim=(t[0], t[-1]),
        title=f"{method}: run {run_id}",
    )
    plain_ticks(ax, xbins=10)
    ax.legend(loc="upper left", fontsize="small")
    return fig


# --------------------------------------------------------------------------- ROC / PR


def _pooled_stratum(
    preds: pd.DataFrame, runs: dict[str, Run], condition: str, fault: str
) -> tuple[np.ndarray, np.ndarray]:
    """Scores and truth of the scored samples of one method's stratum, pooled as the
    harness does: a stratum holds the healthy runs of its condition(s) and the faulty runs of
    its fault(s); a nan statistic ranks lowest (below every finite one)."""
    finite = preds["statistic"][np.isfinite(preds["statistic"])]
    floor = (finite.min() if len(finite) else 0.0) - 1.0
    data = []
    for rid, p in preds.groupby("run_id", sort=False):
        run = runs[rid]
        key = fault_key(run)
        if condition not in (ALL, run.mode or "-") or (key != NONE and fault not in (ALL, key)):
            continue
        p = _aligned(p, run)
        stat = p["statistic"].to_numpy(float)
        data.append(
            run_data(run, np.where(np.isfinite(stat), stat, floor), p["alarm"].to_numpy(bool))
        )
    return pooled_scores(data)


def plot_roc_pr(results: Results, datasets, condition: str = ALL, fault: str = ALL):
    """ROC and precision-recall curves of the detector statistic, one per method.

    Parameters
    ----------
    results : path, DataFrame or sequence of them
        Directories written by ``r2rsim diagnose`` (one per method, scored on the same test
        datasets), or predictions DataFrames.
    datasets : path or sequence of paths (or of Run)
        The test datasets the results were scored on (the labels are not in the results).
    condition, fault : str
        The stratum, as in the results table: ``"all"`` pools every condition (fault); a
        fault stratum holds the fault-free runs too, as in the harness.

    Returns
    -------
    matplotlib.figure.Figure
        Two axes: ROC (false-positive rate vs true-positive rate) and PR (recall vs
        precision, drawn as the steps whose area is the average precision). The legends give
        ``roc_auc`` and ``pr_auc`` (:func:`~r2rsim.evaluate.metrics.roc_auc`,
        :func:`~r2rsim.evaluate.metrics.average_precision`) of the pooled scored samples.
    """
    Figure = require_matplotlib()
    from sklearn.metrics import precision_recall_curve, roc_curve

    preds = _predictions(results)
    runs = _test_runs(datasets, preds["run_id"])
    fig = Figure(figsize=(9, 4), layout="constrained")
    ax_roc, ax_pr = fig.subplots(1, 2)
    prevalence = math.nan
    for method, p in preds.groupby("method", sort=False):
        score, y = _pooled_stratum(p, runs, condition, fault)
        if not y.any() or y.all():
            raise InputError(
                f"stratum {condition} × {fault} of {method}: the scored samples "
                f"are all {'faulty' if y.any() else 'fault-free'}; no curve"
            )
        fpr, tpr, _ = roc_curve(y, score)
        precision, recall, _ = precision_recall_curve(y, score)
        ax_roc.plot(fpr, tpr, gid=f"roc:{method}", label=f"{method} (AUC {roc_auc(score, y):.3f})")
        ax_pr.plot(
            recall,
            precision,
            drawstyle="steps-post",
            gid=f"pr:{method}",
            label=f"{method} (AP {average_precision(score, y):.3f})",
        )
        prevalence = y.mean()
    ax_roc.plot([0, 1], [0, 1], color="0.6", ls=":", label="chance")
    ax_pr.axhline(prevalence, color="0.6", ls=":", label=f"chance ({prevalence:.2f})")
    ax_roc.set(
        xlabel=axis_label("false-positive rate", "1"),
        ylabel=axis_label("true-positive rate", "1"),
        title="ROC",
        xlim=(0, 1),
        ylim=(0, 1.02),
    )
    ax_pr.set(
        xlabel=axis_label("recall", "1"),
        ylabel=axis_label("precision", "1"),
        title="precision-recall",
        xlim=(0, 1),
        ylim=(0, 1.02),
    )
    ax_roc.legend(loc="lower right", fontsize="small")
    ax_pr.legend(loc="best", fontsize="small")
    fig.suptitle(wrap_title(f"scored test samples, condition {condition}, fault {fault}", fig))
    return fig


# --------------------------------------------------------------------------- metric tables


def _pooled_level(values) -> str | None:
    """The value of a stratum column that pools the others: "all" if there is one, else
    the only value; None when there are several and none pools them."""
    vals = set(values)
    if ALL in vals:
        return ALL
    return vals.pop() if len(vals) == 1 else None


def _metric_rows(
    table: pd.DataFrame, metric: str, by: str, condition: str | None, fault: str | None
) -> pd.DataFrame:
    """The rows of one metric to draw against ``by``; the other stratum columns fixed to the
    given values, or to the pooled one (per condition for the fault)."""
    if metric not in set(table["metric"]):
        raise InputError(
            f"no metric '{metric}' in the results (there are: "
            f"{', '.join(sorted(set(table['metric'])))})"
        )
    rows = table[table["metric"] == metric]
    rows = rows[rows["magnitude"].notna() if by == "magnitude" else rows["magnitude"].isna()]
    if by != "condition":
        cond = condition or _pooled_level(rows["condition"])
        if cond is None:
            raise InputError(
                f"several conditions and none pools them: choose one of "
                f"{', '.join(sorted(set(rows['condition'])))}"
            )
        rows = rows[rows["condition"] == cond]
    if fault is not None:
        rows = rows[rows["fault"] == fault]
    elif by == "condition":  # each condition pooled over its faults
        pooled = rows.groupby(["series", "condition"])["fault"].transform(
            lambda f: _pooled_level(f) or ""
        )
        rows = rows[rows["fault"] == pooled]
    if rows.empty:
        raise InputError(
            f"no '{metric}' value to show by {by} (condition {condition or '-'}, "
            f"fault {fault or '-'})"
        )
    return rows


def _ylabel(metric: str) -> str:
    """``metric (unit)``; a probability, rate or count is ``(1)``."""
    m = METRICS.get(metric)
    return axis_label(metric, m.unit if m is not None else "")


def plot_metric(
    results: Results,
    metric: str = "dd_median_s",
    by: str = "condition",
    condition: str | None = None,
    fault: str | None = None,
    *,
    units: dict[str, str] | None = None,
):
    """One metric of a results table by condition, fault or fault magnitude, per method.

    Parameters
    ----------
    results : path, DataFrame or sequence of them
        A ``r2rsim diagnose`` or ``r2rsim bench -o`` directory, or its results table.
    metric : str
        A metric name of the table (:data:`r2rsim.evaluate.harness.METRICS`), e.g. ``far_ff``,
        ``pd``, ``dd_median_s``, ``roc_auc``.
    by : {"condition", "fault", "magnitude"}
        The stratum column on the x axis.
    condition : str, optional
        With ``by="fault"`` or ``"magnitude"``: the condition (default: the pooled ``all``,
        or the only one).
    fault : str, optional
        The fault (``type:target``); default: each condition pooled over its faults for
        ``by="condition"``, every fault as its own series for ``by="magnitude"``.
    units : dict, optional
        The magnitude unit of each fault (``type:target``), as :func:`plot_mdm` takes it.

    Returns
    -------
    matplotlib.figure.Figure
        Grouped bars (condition, fault) or points over the magnitude, one colour per method,
        with the bootstrap confidence interval as error bars where the table has one.
    """
    Figure = require_matplotlib()
    if by not in BY:
        raise InputError(f"by must be one of {', '.join(BY)}, got {by!r}")
    rows = _metric_rows(results_table(results), metric, by, condition, fault)
    fig = Figure(figsize=(8, 4), layout="constrained")
    ax = fig.add_subplot()
    if by == "magnitude":
        several = rows["fault"].nunique() > 1
        for (series, f), g in rows.groupby(["series", "fault"], sort=False):
            g = g.sort_values("magnitude")
            bars = ax.errorbar(
                g["magnitude"],
                g["value"],
                yerr=_ci(g),
                marker="o",
                capsize=3,
                label=f"{series} {f}" if several else series,
            )
            bars.lines[0].set_gid(f"{series}|{f}")  # the data line (not the caps)
        ax.set_xlabel(axis_label("fault magnitude", _common_unit(rows["fault"], units)))
    else:
        levels = list(dict.fromkeys(rows[by]))
        series = list(dict.fromkeys(rows["series"]))
        width = 0.8 / len(series)
        for i, s in enumerate(series):
            g = rows[rows["series"] == s].set_index(by).reindex(levels)
            x = np.arange(len(levels)) + (i - (len(series) - 1) / 2) * width
            ax.bar(x, g["value"], width, yerr=_ci(g), capsize=3, gid=s, label=s)
            if metric in NULL_OF:  # a P_D is drawn with what chance alone gives
                null = _null_rows(results, NULL_OF[metric], rows, s, by, levels)
                ax.plot(
                    x,
                    null,
                    ls="none",
                    marker="_",
                    markersize=14,
                    mew=2,
                    color="k",
                    gid=f"null:{s}",
                    label=NULL_OF[metric] if i == 0 else None,
                )
        # category labels (faults are long: type:target) turned so that they never meet
        turn = by == "fault" or sum(len(str(v)) for v in levels) > 60
        ax.set_xticks(
            np.arange(len(levels)),
            levels,
            rotation=30 if turn else 0,
            ha="right" if turn else "center",
            rotation_mode="anchor",
        )
        ax.set_xlabel(by)
    desc = METRICS[metric].description if metric in METRICS else ""
    ax.set(ylabel=_ylabel(metric))
    ax.set_title(wrap_title(f"{metric} by {by}: {desc}".rstrip(": "), fig))
    plain_ticks(ax)
    ax.legend(fontsize="small")
    return fig


def fault_units(runs) -> dict[str, str]:
    """The magnitude unit of each fault stratum (``type:target``) of the runs (Run objects),
    from their faults.parquet rows (``magnitude_unit``, as the dataset stores it)."""
    from ..evaluate.harness import fault_key
    from ..evaluate.splits import acting_faults

    out: dict[str, str] = {}
    for run in runs or ():
        faults = acting_faults(run)
        if len(faults) == 1 and "magnitude_unit" in faults.columns:
            unit = faults["magnitude_unit"].iloc[0]
            if isinstance(unit, str):
                out.setdefault(fault_key(run), unit)
    return out


def recorded_units(results) -> dict[str, str]:
    """The magnitude unit of each fault (``type:target``) of the test datasets a
    ``r2rsim diagnose`` directory recorded in datasets.json, from their faults.parquet
    (checked against each dataset's manifest.json; a dataset that is gone, or refused, gives
    none). Empty for anything else (a bench, a DataFrame)."""
    from ..dataset.verify import Verifier
    from ._data import is_dataset_dir
    from ._html import _recorded_datasets

    if not isinstance(results, str | Path) or results_kind(results) != "diagnose":
        return {}
    try:
        paths = _recorded_datasets(Path(results))[0] or []
    except InputError:
        return {}
    roots = []
    for p in map(Path, paths):
        roots += (
            [p]
            if is_dataset_dir(p)
            else sorted(d for d in p.iterdir() if d.is_dir() and is_dataset_dir(d))
        )
    out: dict[str, str] = {}
    for root in roots:
        try:
            with Verifier(root) as v:
                faults = pd.read_parquet(
                    io.BytesIO(v.read("faults.parquet")),
                    columns=["fault_type", "target_id", "magnitude_unit"],
                )
        except (InputError, OSError, ValueError, KeyError):
            continue
        for f in faults.itertuples(index=False):
            if isinstance(f.magnitude_unit, str):
                out.setdefault(f"{f.fault_type}:{f.target_id}", f.magnitude_unit)
    return out


def magnitude_unit(fault: str, units: dict[str, str] | None = None) -> str | None:
    """The unit of a fault stratum's magnitude: from ``units`` (:func:`fault_units`), else
    from the fault type where it does not depend on the target (a gain is relative, a
    bearing friction in N*m); None when only the target's reading would tell."""
    if units and fault in units:
        return units[fault]
    from ..schema.faults import CATALOGUE
    from ..schema.faults import magnitude_unit as catalogue_unit

    ftype = fault.split(":", 1)[0]
    if "+" in fault or ftype not in CATALOGUE or CATALOGUE[ftype].magnitude.startswith("reading"):
        return None
    return catalogue_unit(ftype, None)


#: how a magnitude axis says that the results do not give its unit (no test datasets)
UNKNOWN_UNIT = "unit of the target's reading"


def _common_unit(faults, units) -> str:
    found = {magnitude_unit(f, units) for f in set(faults)}
    return found.pop() or UNKNOWN_UNIT if len(found) == 1 else UNKNOWN_UNIT


def _magnitude_quantity(fault: str) -> str:
    """The magnitude's name on an axis: the fault type's last word (``sensor.offset``:
    offset)."""
    if "+" in fault:
        return "fault magnitude"
    return fault.split(":", 1)[0].rsplit(".", 1)[-1].replace("_", " ")


#: the null rate drawn beside each detection probability
NULL_OF = {"pd": "pd_null", "pd_cal": "pd_null_cal"}


def _null_rows(
    results: Results, null: str, rows: pd.DataFrame, series: str, by: str, levels: list
) -> np.ndarray:
    """The null rates of one series at the strata of ``rows`` (nan where there is none)."""
    table = results_table(results)
    want = rows[rows["series"] == series][["condition", "fault"]].drop_duplicates()
    n = table[
        (table["metric"] == null) & (table["series"] == series) & table["magnitude"].isna()
    ].merge(want, on=["condition", "fault"])
    return n.set_index(by)["value"].reindex(levels).to_numpy(float)


def _ci(g: pd.DataFrame) -> np.ndarray | None:
    """Error bar lengths below and above the value from ci_low/ci_high (None: no CI)."""
    if not {"ci_low", "ci_high"} <= set(g.columns) or g["ci_low"].isna().all():
        return None
    v = g["value"].to_numpy(float)
    lo = np.nan_to_num(v - g["ci_low"].to_numpy(float))
    hi = np.nan_to_num(g["ci_high"].to_numpy(float) - v)
    return np.clip(np.vstack([lo, hi]), 0, None)


def plot_mdm(
    results: Results,
    calibrated: bool = False,
    condition: str | None = None,
    *,
    units: dict[str, str] | None = None,
):
    """Detection probability against fault magnitude (MDM curves), one axes per fault, one
    line per method, with the P_D = 0.9 level and the MDM90 of the results table marked.

    Parameters
    ----------
    results : path, DataFrame or sequence of them
        A ``r2rsim diagnose`` or ``r2rsim bench -o`` directory, or its results table; faults
        run at several magnitudes have per-magnitude rows.
    calibrated : bool
        False: P_D at the plug-in's own alarms (``pd``, ``mdm90``); True: at the calibrated
        threshold theta (``pd_cal``, ``mdm90_cal``).
    condition : str, optional
        The condition (default: the pooled ``all``, or the only one).
    units : dict, optional
        The magnitude unit of each fault (``type:target`` to an SI unit as faults.parquet
        stores it, :func:`fault_units` of the test runs): the x axis is ``offset (N)``.
        Default: from the faults.parquet of the test datasets a ``r2rsim diagnose``
        directory recorded (:func:`recorded_units`). A fault missing from it takes the unit
        its type gives alone (``gain (relative)``), else the axis says that the unit is the
        target reading's. Small magnitudes are shown with a prefix (a gain error of 5.8e-05
        as 58 ppm).

    Returns
    -------
    matplotlib.figure.Figure
    """
    Figure = require_matplotlib()
    pd_name, mdm_name, null_name = (
        ("pd_cal", "mdm90_cal", "pd_null_cal") if calibrated else ("pd", "mdm90", "pd_null")
    )
    table = results_table(results)
    if units is None:
        units = recorded_units(results)
    if not ((table["metric"] == pd_name) & table["magnitude"].notna()).any():
        raise InputError(
            f"no per-magnitude {pd_name} in the results: MDM curves need a "
            f"fault run at several magnitudes"
        )
    rows = _metric_rows(table, pd_name, "magnitude", condition, None)
    cond = rows["condition"].iloc[0]
    faults = list(dict.fromkeys(rows["fault"]))
    fig = Figure(figsize=(max(6.5, 4.5 * len(faults)), 4.2), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(faults), squeeze=False)[0])
    for ax, f in zip(axes, faults, strict=True):
        unit = magnitude_unit(f, units)
        factor, shown = display_unit(unit, rows[rows["fault"] == f]["magnitude"])
        for series, g in rows[rows["fault"] == f].groupby("series", sort=False):
            g = g.sort_values("magnitude")
            (line,) = ax.plot(
                g["magnitude"] * factor, g["value"], marker="o", gid=f"{series}|{f}", label=series
            )
            null = table[
                (table["series"] == series)
                & (table["metric"] == null_name)
                & (table["condition"] == cond)
                & (table["fault"] == f)
                & table["magnitude"].notna()
            ].sort_values("magnitude")
            if not null.empty:  # what chance alone gives in the same windows
                ax.plot(
                    null["magnitude"] * factor,
                    null["value"],
                    ls=":",
                    marker=".",
                    color=line.get_color(),
                    gid=f"null:{series}|{f}",
                    label=f"{series}: {null_name} (chance)",
                )
            mdm = table[
                (table["series"] == series)
                & (table["metric"] == mdm_name)
                & (table["condition"] == cond)
                & (table["fault"] == f)
                & table["magnitude"].isna()
            ]["value"]
            for i, x in enumerate(_mdm_marks(mdm, g["magnitude"])):
                ax.axvline(
                    x * factor,
                    color=line.get_color(),
                    ls="--",
                    lw=1,
                    gid=f"mdm:{series}|{f}",
                    label=f"{series}: {mdm_name}" if i == 0 else None,
                )
        ax.axhline(MDM_LEVEL, color="0.5", ls=":", label=f"P_D = {MDM_LEVEL}")
        ax.set(
            xlabel=axis_label(_magnitude_quantity(f), shown if unit is not None else UNKNOWN_UNIT),
            ylabel=axis_label(pd_name, "1"),
            ylim=(-0.03, 1.03),
            title=f,
        )
        plain_ticks(ax, xbins=6)
        ax.legend(fontsize="small")
    at = "at theta" if calibrated else "plug-in alarms"
    fig.suptitle(
        wrap_title(f"detection probability by fault magnitude ({at}, condition {cond})", fig),
        fontsize="large",
    )
    return fig


def _mdm_marks(mdm: pd.Series, magnitudes: pd.Series) -> list[float]:
    """Where to mark an MDM90 (an absolute magnitude) on a signed magnitude axis: at +MDM
    and/or -MDM, on the side(s) the magnitudes lie."""
    if mdm.empty or not np.isfinite(mdm.iloc[0]):
        return []
    m = float(mdm.iloc[0])
    return [s * m for s in (1, -1) if (np.sign(magnitudes) == s).any()]
