"""The sweep figure: one statistic of a channel per run against a sweep axis."""

from __future__ import annotations

import difflib
import json
import re
from typing import Any

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
from ._mpl import axis_label, display_unit, plain_ticks, require_matplotlib, wrap_title

#: read each run's samples file into memory once, hash and parse it from the same bytes (the
#: files of a sweep's runs are a few MB; False: the hash reads the file again, beside the
#: footer and column chunk the figure reads; benchmarks/bench_verify.py compares the two)
READ_WHOLE_FILES = True
#: the marker of each group of a sweep figure, in turn
MARKERS = ("o", "s", "^", "D", "v", "P", "X")
#: per-run statistics of a channel (NaN samples skipped, as pandas does; std with ddof = 1)
STATISTICS = {
    "mean": pd.Series.mean,
    "std": pd.Series.std,
    "min": pd.Series.min,
    "max": pd.Series.max,
    "rms": lambda s: float(np.sqrt((s * s).mean())),
}


def plot_sweep(
    dataset,
    channel: str,
    statistic: str = "mean",
    axis: str | None = None,
    *,
    group: str | None = None,
    t0: float | None = None,
    t1: float | None = None,
    figsize: tuple[float, float] | None = None,
    verify: bool = True,
):
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
        x_unit = axis_unit(root, x_col, v)
        g_unit = axis_unit(root, g_col, v) if g_col else ""
        verified(v)
    runs = runs.assign(value=values).dropna(subset=["value"])
    no_x = int(runs[x_col].isna().sum())  # an axis that did not apply (a removed fault)
    runs = runs[runs[x_col].notna()]

    fig = Figure(figsize=figsize or (7.0, 4.5), layout="constrained")
    ax = fig.subplots()
    text_x = runs[x_col].map(lambda v: isinstance(v, str)).any()  # a fault as JSON, a mode
    categories = sorted(set(runs[x_col])) if text_x else []
    x_factor, x_shown = display_unit(x_unit, pd.to_numeric(runs[x_col], errors="coerce"))
    y_factor, y_shown = display_unit(unit, runs["value"])
    g_unit = "" if g_unit in ("", "1", "SI units") else f" {g_unit}"
    groups = runs.groupby(g_col, sort=True, dropna=False) if g_col else [(None, runs)]
    for i, (key, rows) in enumerate(groups):
        shown = _show(key)
        label = (
            None
            if g_col is None
            else (f"{g_col[len('axis.') :]} = {shown}" + (g_unit if shown != "none" else ""))
        )
        # open markers of a shape per group: groups at the same point stay visible
        x = (
            rows[x_col].map(categories.index).to_numpy()
            if text_x
            else rows[x_col].to_numpy() * x_factor
        )
        ax.plot(
            x,
            rows["value"].to_numpy() * y_factor,
            ls="none",
            marker=MARKERS[i % len(MARKERS)],
            mfc="none",
            mew=1.5,
            ms=8 + 2 * (i % 3),
            label=label,
        )
    if text_x:  # one tick per value, named shortly (the whole text is in runs.parquet)
        ax.set_xticks(
            range(len(categories)),
            [_show(c) for c in categories],
            rotation=20,
            ha="right",
            rotation_mode="anchor",
        )
        ax.set_xmargin(0.2)
        ax.set_xlabel(x_col[len("axis.") :])
    else:
        ax.set_xlabel(axis_label(x_col[len("axis.") :], x_shown))
    ax.set_ylabel(axis_label(f"{statistic} of {channel}", y_shown))
    plain_ticks(ax, xbins=None if text_x else 8)
    if g_col:
        ax.legend(fontsize="small")
    ax.grid(True, alpha=0.3)
    window = (
        "" if t0 is None and t1 is None else f", t in [{_show(t0, 'start')}, {_show(t1, 'end')}] s"
    )
    note = (f"; {skipped} run(s) without samples left out" if skipped else "") + (
        f"; {no_x} run(s) without a value of {x_col[len('axis.') :]} left out" if no_x else ""
    )
    fig.suptitle(
        wrap_title(f"{root.name}: {len(runs)} runs{window}{note}", fig, "medium"), fontsize="medium"
    )
    return fig


#: the unit of a sweep axis whose values carry none and whose path names no fault magnitude
UNKNOWN_UNIT = "SI units"
_FAULT_MAGNITUDE = re.compile(r"^faults(?:\.([^.\[\]]+)|\[(\d+)\])\.magnitude$")


def axis_unit(root, column: str, v=None) -> str:
    """The SI unit of a sweep axis's values (runs.parquet stores them in SI, without one).

    A fault magnitude (``faults.<id>.magnitude``) has the unit its fault type and target
    give, as faults.parquet records it (``magnitude_unit``: ``N`` for a load cell's offset,
    ``rel`` for a gain); any other axis the unit of the quantity its values are written in
    in the sweep file kept in the dataset (``3 m/s``: ``m/s``). A plain number is a
    dimensionless value: ``1``. :data:`UNKNOWN_UNIT` when the dataset does not say (no
    sweep file, no fault row)."""
    from ..dataset.paths import read_json

    try:
        manifest: Any = read_json(root / "manifest.json")  # checked by using it
        sweep = manifest.get("sweep") or {}
        axis = next(a for a in sweep.get("axes", []) if a.get("column") == column)
    except (OSError, ValueError, StopIteration, AttributeError, TypeError):
        return UNKNOWN_UNIT
    path = str(axis.get("path", ""))
    m = _FAULT_MAGNITUDE.match(path)
    if m:
        return _fault_unit(root, m.group(1), m.group(2), v)
    return _written_unit(root, str(sweep.get("file", "")), column, v)


def _fault_unit(root, fault_id, index, v) -> str:
    """The magnitude unit faults.parquet gives the swept fault (by id, else the only one)."""
    from ._data import run_rows_all

    faults = run_rows_all(root, "faults.parquet", ["fault_id", "magnitude_unit"], v)
    if faults.empty or "magnitude_unit" not in faults:
        return UNKNOWN_UNIT
    if fault_id is not None and (faults["fault_id"] == fault_id).any():
        faults = faults[faults["fault_id"] == fault_id]
    units = set(faults["magnitude_unit"].dropna())
    return units.pop() if len(units) == 1 else UNKNOWN_UNIT


def _written_unit(root, rel: str, column: str, v) -> str:
    """The SI unit of the quantity the axis's values are written in, in the sweep file."""
    import yaml

    from ..units import DIMENSIONS, QuantityError, parse_any

    if not rel or not (root / rel).is_file():
        return UNKNOWN_UNIT
    try:
        text = v.read(rel) if v is not None and v.verify else (root / rel).read_bytes()
        spec = yaml.safe_load(text)
        axis = next(a for a in spec["axes"] if f"axis.{a.get('name')}" == column)
        r = axis.get("range") or {}
        values = axis.get("values") or [r.get("start")] or []
        value = next(x for x in values if x is not None)
    except (InputError, yaml.YAMLError, KeyError, TypeError, AttributeError, StopIteration):
        return UNKNOWN_UNIT
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        return UNKNOWN_UNIT
    if not isinstance(value, str):
        return "1"
    try:
        dims = parse_any(value)[1]
    except QuantityError:
        return UNKNOWN_UNIT  # a text value (a mode, a file)
    angular = re.search(r"rpm|rad|deg|rev|°", value) is not None
    for name, (_, si, _) in DIMENSIONS.items():
        want = {} if si == "1" else parse_any("1 " + si)[1]
        if (
            want == dims
            and (name not in ("frequency", "dimensionless") or not angular)
            and (name not in ("angular_speed", "angle") or angular)
        ):
            return si
    return UNKNOWN_UNIT


def _show(value, missing: str = "none", width: int = 32) -> str:
    """An axis value or a time for a label; a text value at most ``width`` characters (a
    fault stored as JSON by its type and target)."""
    if value is None or (np.isscalar(value) and pd.isna(value)):
        return missing
    if isinstance(value, (int, float, np.number)):
        return f"{value:g}"
    text = str(value)
    try:
        obj = json.loads(text)
    except ValueError:
        obj = None
    if isinstance(obj, dict) and "type" in obj:
        text = (
            str(obj["type"])
            + (f" on {obj['target']}" if obj.get("target") else "")
            + (f", {_show(obj['magnitude'])}" if obj.get("magnitude") is not None else "")
        )
        width = max(width, 48)
    return text if len(text) <= width else text[: width - 1] + "…"


def _axis_column(root, runs: pd.DataFrame, name: str | None) -> str:
    """The runs.parquet column of a sweep axis (``offset`` or ``axis.offset``)."""
    axes = [c for c in runs.columns if c.startswith("axis.")]
    if not axes:
        raise InputError(
            f"dataset {root}: runs.parquet has no sweep axes (axis.* columns): "
            f"not a sweep; plot its runs with plot_run"
        )
    if name is None:
        return axes[0]
    col = name if name.startswith("axis.") else f"axis.{name}"
    if col not in axes:
        raise InputError(
            f"dataset {root}: no sweep axis '{name}' (axes: "
            f"{', '.join(a[len('axis.') :] for a in axes)})"
        )
    return col


def _per_run(root, run_ids, channel: str, statistic: str, t0, t1, v=None) -> tuple[list, int]:
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
            raise InputError(
                f"dataset {root}: no numeric channel '{channel}'"
                + (f" (like: {', '.join(like)})" if like else "")
            )
        lo = run.t_start if t0 is None else t0
        hi = run.t_end if t1 is None else t1
        chunks = [v[channel] for _, v in iter_window(run, [channel], lo, hi)]
        series = pd.Series(np.concatenate(chunks) if chunks else np.empty(0))
        out.append(float(STATISTICS[statistic](series)))
    return out, skipped
