"""Figures of the GSMMS multi-regime detector (thesis Figs. 4-8 to 4-10 analogues): the map
over the operating space, the node-standardised residuals per regime, and the residual
against fault severity. They take a fitted :class:`r2rsim.diagnostics.gsmms.GSMMS` and runs
(or frames of visible columns); the report stage may import the diagnostics stage."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import InputError
from ._mpl import require_matplotlib


def _frame(run):
    return run.visible() if hasattr(run, "visible") else run


def _colours(n: int):
    from matplotlib import colormaps

    cmap = colormaps["tab10"]
    return [cmap(i % 10) for i in range(n)]


def plot_gsmms_map(
    estimator, runs: Sequence, x: str, y: str, *, max_points: int = 4000, title: str | None = None
):
    """Samples of ``runs`` in the plane of two visible columns, coloured by their
    best-matching node, with the map's nodes and edges when both columns are partition
    features (thesis Fig. 4-8a/b).

    Parameters
    ----------
    estimator : GSMMS
        A fitted GSMMS (or gsmms_global) plug-in.
    runs : sequence of Run or DataFrame
        The runs whose samples are drawn (evenly thinned to ``max_points`` in all).
    x, y : str
        Visible column names for the axes.
    max_points : int
        At most this many points are drawn.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        One axes; one scatter collection per node that wins a drawn sample (label
        ``node m``), plus the nodes (black markers) and edges when x and y are partition
        columns, or one dotted line per node when only one of them is.
    """
    Figure = require_matplotlib()
    frames = [_frame(r) for r in runs]
    if not frames:
        raise InputError("plot_gsmms_map needs at least one run")
    for c in (x, y):
        if c not in frames[0].columns:
            raise InputError(f"plot_gsmms_map: no column {c!r} in the runs")
    xs, ys, bs = [], [], []
    for f in frames:
        b = estimator.score(f)["bmu"].to_numpy()
        xs.append(f[x].to_numpy(float))
        ys.append(f[y].to_numpy(float))
        bs.append(b)
    X, Y, B = (np.concatenate(a) for a in (xs, ys, bs))
    keep = np.linspace(0, len(X) - 1, min(len(X), max_points)).astype(int)
    X, Y, B = X[keep], Y[keep], B[keep]
    fig = Figure(figsize=(6.5, 4.5), layout="constrained")
    ax = fig.add_subplot()
    colours = _colours(estimator.n_nodes_)
    for m in range(estimator.n_nodes_):
        sel = B == m
        if sel.any():
            ax.scatter(X[sel], Y[sel], s=4, color=colours[m], alpha=0.5, label=f"node {m}")
    cols = list(estimator.partition_columns_)
    book = estimator.graph_.codebook * estimator.s_scale_ + estimator.s_mean_
    if x in cols and y in cols:
        i, j = cols.index(x), cols.index(y)
        for a, b in sorted(estimator.graph_.edges):
            ax.plot(book[[a, b], i], book[[a, b], j], color="k", lw=1)
        ax.scatter(book[:, i], book[:, j], marker="X", s=80, color="k", label="nodes")
    elif x in cols or y in cols:  # one partition axis: each node is a line across the plot
        line = ax.axvline if x in cols else ax.axhline
        i = cols.index(x if x in cols else y)
        for m, v in enumerate(book[:, i]):
            line(v, color=colours[m], ls=":", lw=1.5, label="nodes" if m == 0 else None)
    ax.set_xlabel(x)
    ax.set_ylabel(y)
    ax.set_title(title or f"{estimator.name}: {estimator.n_nodes_} nodes")
    ax.legend(loc="best", fontsize="small", markerscale=2)
    return fig


def plot_gsmms_residuals(
    estimator, runs: Mapping[str, object], *, relation: int = 0, title: str | None = None
):
    """The node-standardised residual (P − μ_node)/σ_node over time of each named run, one
    axes per run, with the ±k_sigma threshold and the fault window shaded (thesis
    Fig. 4-9 / 4-10).

    Parameters
    ----------
    estimator : GSMMS
        A fitted plug-in.
    runs : mapping of str to Run or DataFrame
        Title of each panel and its run. With a :class:`~r2rsim.dataset.read.Run` the
        samples where ``label.is_faulty`` is set are shaded.
    relation : int
        Which relation's residual (column ``z.<relation>`` of the scores).
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        One axes per run (in order), each with the residual line, two dashed threshold
        lines and, for a faulty run, one shaded span per fault window.
    """
    Figure = require_matplotlib()
    if not runs:
        raise InputError("plot_gsmms_residuals needs at least one run")
    fig = Figure(figsize=(8, 1.9 * len(runs) + 0.6), layout="constrained")
    axes = fig.subplots(len(runs), 1, sharex=True, squeeze=False)[:, 0]
    k = float(estimator.threshold_)
    for ax, (name, run) in zip(axes, runs.items(), strict=True):
        f = _frame(run)
        s = estimator.score(f)
        t = f["t_s"].to_numpy()
        ax.plot(t, s[f"z.{relation}"].to_numpy(), lw=0.6, color="C0")
        for v in (k, -k):
            ax.axhline(v, ls="--", color="C3", lw=1)
        samples = getattr(run, "samples", None)
        if samples is not None and "label.is_faulty" in samples:
            faulty = samples["label.is_faulty"].to_numpy(bool)
            edges = np.flatnonzero(np.diff(np.r_[0, faulty.astype(int), 0]))
            for a, b in zip(edges[::2], edges[1::2], strict=True):
                ax.axvspan(t[a], t[b - 1], color="C3", alpha=0.12)
        nodes = sorted(set(s["bmu"][s["bmu"] >= 0].astype(int)))
        ax.set_title(f"{name} (node {', '.join(map(str, nodes))})", fontsize="small")
        ax.set_ylabel("(P − μ)/σ")
    axes[-1].set_xlabel("t [s]")
    if title:
        fig.suptitle(title)
    return fig


def plot_severity(
    values: Mapping[str, Mapping[float, float]],
    *,
    ylabel: str = "mean |residual| [σ]",
    xlabel: str = "fault magnitude",
    threshold: float | None = None,
    title: str | None = None,
):
    """A residual summary against fault severity, one line per condition (thesis
    Fig. 4-8c/d).

    Parameters
    ----------
    values : mapping of str to mapping of float to float
        Per condition, the value at each magnitude.
    threshold : float, optional
        Drawn as a dashed horizontal line (e.g. the detector's threshold).

    Returns
    -------
    matplotlib.figure.Figure
        One axes with one marked line per condition (magnitudes sorted).
    """
    Figure = require_matplotlib()
    if not values:
        raise InputError("plot_severity needs at least one condition")
    fig = Figure(figsize=(5.5, 3.8), layout="constrained")
    ax = fig.add_subplot()
    for name, series in values.items():
        mags = sorted(series)
        ax.plot(mags, [series[m] for m in mags], marker="o", label=name)
    if threshold is not None:
        ax.axhline(threshold, ls="--", color="0.4", lw=1, label="threshold")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    ax.legend(fontsize="small")
    return fig
