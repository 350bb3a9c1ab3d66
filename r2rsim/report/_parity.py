"""Figures of parity-space (and other residual-based) diagnostics: residual panels with the
fault windows shaded (thesis Figs. 3-4, 3-5), a signature matrix (fault × residual, mean
shift in σ), and post-optimal sensitivities along data (thesis Figs. 3-6, 3-7)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from ..errors import InputError
from ._mpl import require_matplotlib


def plot_residuals(
    series: Mapping[str, pd.DataFrame],
    columns: Sequence[str],
    *,
    time: str = "t_s",
    scale: Mapping[str, float] | None = None,
    threshold: float | None = None,
    spans: Sequence[tuple[float, float, str]] = (),
    title: str | None = None,
    ylabel: str | None = None,
):
    """Per-sample columns over time, one axes per column, several series overlaid.

    Parameters
    ----------
    series : mapping of str to DataFrame
        Label → a frame with the ``time`` column and the ``columns`` (e.g. the output of a
        plug-in's ``score`` with ``t_s`` added, or a sensitivity table).
    columns : sequence of str
        The columns to draw, one axes each (top to bottom).
    time : str
        The time column [s].
    scale : mapping of str to float, optional
        Divide column c by ``scale[c]`` (e.g. σ_j, to show residuals in standard deviations).
    threshold : float, optional
        Draw ±threshold (in the plotted units) as dashed lines.
    spans : sequence of (t0, t1, label)
        Time windows shaded on every axes (e.g. fault windows).
    title, ylabel : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    Figure = require_matplotlib()
    if not series:
        raise InputError("plot_residuals: no series to plot")
    columns = list(columns)
    for label, df in series.items():
        missing = [c for c in [time, *columns] if c not in df.columns]
        if missing:
            raise InputError(f"plot_residuals: series '{label}' has no column {', '.join(missing)}")
    fig = Figure(figsize=(8, 1.2 + 1.6 * len(columns)), layout="constrained")
    axes = fig.subplots(len(columns), 1, sharex=True, squeeze=False)[:, 0]
    for ax, col in zip(axes, columns, strict=True):
        for t0, t1, text in spans:
            ax.axvspan(
                t0,
                t1,
                color="tab:red",
                alpha=0.12,
                gid=f"span:{text}",
                label=text if ax is axes[0] else None,
            )
        s = 1.0 if scale is None else float(scale.get(col, 1.0))
        for label, df in series.items():
            ax.plot(
                df[time].to_numpy(float),
                df[col].to_numpy(float) / s,
                lw=0.8,
                label=label if ax is axes[0] else None,
            )
        if threshold is not None:
            for sign in (1, -1):
                ax.axhline(sign * threshold, color="k", ls="--", lw=0.8, gid="threshold")
        unit = f" [{ylabel}]" if ylabel else (" [σ]" if scale is not None else "")
        ax.set_ylabel(f"{col}{unit}")
    axes[-1].set_xlabel("t [s]")
    axes[0].legend(loc="upper left", fontsize="x-small", ncol=3)
    if title:
        axes[0].set_title(title)
    return fig


def plot_signature(
    table: pd.DataFrame,
    *,
    threshold: float | None = None,
    title: str | None = None,
    fmt: str = "{:+.1f}",
):
    """A signature matrix: rows are fault cases, columns residuals, cells the mean shift
    (e.g. in σ), annotated; cells with |value| ≥ ``threshold`` are outlined.

    Returns
    -------
    matplotlib.figure.Figure
    """
    Figure = require_matplotlib()
    if table.empty:
        raise InputError("plot_signature: the table is empty")
    values = table.to_numpy(float)
    fig = Figure(
        figsize=(1.6 + 1.2 * table.shape[1], 0.9 + 0.38 * table.shape[0]), layout="constrained"
    )
    ax = fig.add_subplot()
    lim = max(float(np.nanmax(np.abs(values))), 1e-12)
    im = ax.imshow(values, cmap="RdBu_r", vmin=-lim, vmax=lim, aspect="auto")
    for (i, j), v in np.ndenumerate(values):
        ax.text(j, i, fmt.format(v), ha="center", va="center", fontsize="small")
        if threshold is not None and abs(v) >= threshold:
            ax.add_patch(_rectangle(j, i))
    ax.set_xticks(range(table.shape[1]), [str(c) for c in table.columns])
    ax.set_yticks(range(table.shape[0]), [str(r) for r in table.index])
    fig.colorbar(im, ax=ax, shrink=0.8)
    if title:
        ax.set_title(title)
    return fig


def _rectangle(j, i):
    from matplotlib.patches import Rectangle

    return Rectangle((j - 0.5, i - 0.5), 1, 1, fill=False, lw=1.5, ec="k", gid="fired")


def plot_sensitivity(
    series: Mapping[str, pd.DataFrame], columns: Sequence[str], *, title: str | None = None
):
    """Post-optimal sensitivities (e.g. ``dJ/d<p>`` of
    :meth:`r2rsim.diagnostics.parity.ParitySpaceDetector.sensitivity`) along data, one axes
    per column, one line per series (thesis Figs. 3-6, 3-7).

    Returns
    -------
    matplotlib.figure.Figure
    """
    return plot_residuals(series, columns, title=title)
