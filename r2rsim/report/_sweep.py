"""The sweep figure: one statistic of a channel per run against a sweep axis."""

from __future__ import annotations

import difflib

import numpy as np
import pandas as pd

from ..dataset.verify import Verifier
from ..errors import InputError
from ._data import (
    channel_units,
    iter_window,
    open_dataset,
    open_run,
    runs_table,
    sample_files,
    verified,
)
from ._mpl import require_matplotlib

#: read each run's samples file into memory once, hash and parse it from the same bytes (the
#: files of a sweep's runs are a few MB; False: the hash reads the file again, beside the
#: footer and column chunk the figure reads; benchmarks/bench_verify.py compares the two)
READ_WHOLE_FILES = True
#: per-run statistics of a channel (NaN samples skipped, as pandas does; std with ddof = 1)
STATISTICS = {
    "mean": pd.Series.mean,
    "std": pd.Series.std,
    "min": pd.Series.min,
    "max": pd.Series.max,
    "rms": lambda s: float(np.sqrt((s * s).mean())),
}


def plot_sweep(dataset, channel: str, statistic: str = "mean", axis: str | None = None, *,
               group: str | None = None, t0: float | None = None, t1: float | None = None,
               figsize: tuple[float, float] | None = None, verify: bool = True):
    """Plot a statistic of one channel, one point per run, against a sweep axis.

    Parameters
    ----------
    dataset : str or Path
        Dataset written by ``r2rsim sweep`` (its runs.parquet has ``axis.<name>`` columns).
    channel : str
        Samples column, e.g. ``"state.span3.tension_N"``.
    statistic : {"mean", "std", "min", "max", "rms"}
        Computed per run over the window, NaN samples skipped (``std``: ddof = 1).
    axis : str, optional
        Sweep axis on the x axis, with or without its ``axis.`` prefix (default: the first).
    group : str, optional
        A second axis: one colour per value of it.
    t0, t1 : float, optional
        Time window [s] of each run the statistic covers (default: the whole run).
    figsize : (float, float), optional
    verify : bool
        Check the dataset against its manifest.json, as every reader does
        (:mod:`r2rsim.dataset.verify`): every listed file is there with its size, and the
        runs, channels, faults and events tables and each run's samples (hashed whole,
        although one column is read) have their sha256. A dataset changed after it was
        written is refused; ``verify=False`` (``--no-verify``) draws it anyway.

    Returns
    -------
    matplotlib.figure.Figure
        Its axes hold one marker line per group; the points are the runs with samples and
        a value on the x axis (a failed run without samples, and a run the x axis did not
        apply to, are left out and counted in the title).

    Raises
    ------
    InputError
        For a missing dataset, an unfinished sweep, a file that differs from manifest.json
        (``verify``), a dataset without sweep axes, an unknown axis, channel or statistic,
        or when matplotlib is not installed.
    """
    Figure = require_matplotlib()
    root = open_dataset(dataset)
    if statistic not in STATISTICS:
        raise InputError(f"unknown statistic '{statistic}' (one of: {', '.join(STATISTICS)})")
    with Verifier(root, verify) as v:
        runs = runs_table(root, v)
        x_col = _axis_column(root, runs, axis)
        g_col = _axis_column(root, runs, group) if group is not None else None
        values, skipped = _per_run(root, runs["run_id"], channel, statistic, t0, t1, v)
        unit = channel_units(root, v).get(channel, "")
        verified(v)
    runs = runs.assign(value=values).dropna(subset=["value"])
    no_x = int(runs[x_col].isna().sum())  # an axis that did not apply (a removed fault)
    runs = runs[runs[x_col].notna()]

    fig = Figure(figsize=figsize or (7.0, 4.5), layout="constrained")
    ax = fig.subplots()
    for key, rows in (runs.groupby(g_col, sort=True, dropna=False) if g_col else [(None, runs)]):
        label = None if g_col is None else f"{g_col[len('axis.'):]} = {_show(key)}"
        ax.plot(rows[x_col].to_numpy(), rows["value"].to_numpy(), "o", alpha=0.8, label=label)
    ax.set_xlabel(f"{x_col[len('axis.'):]} (SI)")
    ax.set_ylabel(f"{statistic} of {channel}" + (f" [{unit}]" if unit and unit != "1" else ""))
    if g_col:
        ax.legend(fontsize="small")
    ax.grid(True, alpha=0.3)
    window = "" if t0 is None and t1 is None else \
        f", t in [{_show(t0, 'start')}, {_show(t1, 'end')}] s"
    note = (f"; {skipped} run(s) without samples left out" if skipped else "") + (
        f"; {no_x} run(s) without a value of {x_col[len('axis.'):]} left out" if no_x else "")
    fig.suptitle(f"{root.name}: {len(runs)} runs{window}{note}", fontsize="medium")
    return fig


def _show(value, missing: str = "none") -> str:
    """An axis value or a time for a label."""
    if value is None or (np.isscalar(value) and pd.isna(value)):
        return missing
    return f"{value:g}" if isinstance(value, (int, float, np.number)) else str(value)


def _axis_column(root, runs: pd.DataFrame, name: str | None) -> str:
    """The runs.parquet column of a sweep axis (``offset`` or ``axis.offset``)."""
    axes = [c for c in runs.columns if c.startswith("axis.")]
    if not axes:
        raise InputError(f"dataset {root}: runs.parquet has no sweep axes (axis.* columns): "
                         f"not a sweep; plot its runs with plot_run")
    if name is None:
        return axes[0]
    col = name if name.startswith("axis.") else f"axis.{name}"
    if col not in axes:
        raise InputError(f"dataset {root}: no sweep axis '{name}' (axes: "
                         f"{', '.join(a[len('axis.'):] for a in axes)})")
    return col


def _per_run(root, run_ids, channel: str, statistic: str, t0, t1, v=None
             ) -> tuple[list, int]:
    """The statistic of the channel for each run (NaN for a run without samples), and how
    many runs had no samples. Reads that one column of each run."""
    out, skipped = [], 0
    for run_id in run_ids:
        if not sample_files(root, run_id):  # a failed run of the sweep wrote no samples
            out.append(np.nan)
            skipped += 1
            continue
        run = open_run(root, run_id, v, whole=READ_WHOLE_FILES and v is not None and v.verify)
        if channel not in run.columns:
            like = difflib.get_close_matches(channel, run.columns, n=4, cutoff=0.3)
            raise InputError(f"dataset {root}: no numeric channel '{channel}'"
                             + (f" (like: {', '.join(like)})" if like else ""))
        lo = run.t_start if t0 is None else t0
        hi = run.t_end if t1 is None else t1
        chunks = [v[channel] for _, v in iter_window(run, [channel], lo, hi)]
        series = pd.Series(np.concatenate(chunks) if chunks else np.empty(0))
        out.append(float(STATISTICS[statistic](series)))
    return out, skipped
