"""Figures of virtual sensors and regression models (thesis Ch. 2, Figs. 2-13 to 2-15):
traces of estimated against measured or true signals with shaded transients, normal QQ
plots of residuals, and aligned profiles of several cycles side by side."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from scipy import stats

from ..errors import InputError
from ._mpl import require_matplotlib


def plot_virtual_sensor(
    t,
    panels: Sequence[tuple[str, Mapping[str, np.ndarray]]],
    spans: Sequence[tuple[float, float]] = (),
    title: str | None = None,
    span_label: str = "transient",
):
    """Estimated and measured (or true) signals over time, one axes per panel (Fig. 2-13).

    Parameters
    ----------
    t : array (n,)
        Time [s].
    panels : sequence of (ylabel, {label: array (n,)})
        One axes each, its curves in the order given (e.g. measured, then estimated).
    spans : sequence of (start, end)
        Time windows shaded on every axes (e.g. roll changes).
    title : str, optional
    span_label : str
        Legend entry of the shaded windows.

    Returns
    -------
    matplotlib.figure.Figure
    """
    Figure = require_matplotlib()
    t = np.asarray(t, float)
    if not panels:
        raise InputError("plot_virtual_sensor needs at least one panel")
    fig = Figure(figsize=(8, 2.4 * len(panels) + 0.6), layout="constrained")
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    for ax, (ylabel, curves) in zip(axes, panels, strict=True):
        for k, (a, b) in enumerate(spans):
            ax.axvspan(a, b, color="0.85", gid="span", label=span_label if k == 0 else None)
        for label, y in curves.items():
            y = np.asarray(y, float)
            if y.shape != t.shape:
                raise InputError(
                    f"plot_virtual_sensor: '{label}' has {y.size} values for {t.size} times"
                )
            ax.plot(t, y, lw=0.8, label=label)
        ax.set_ylabel(ylabel)
        ax.legend(loc="upper right", fontsize="small")
    axes[-1].set(xlabel="t [s]", xlim=(t[0], t[-1]))
    if title:
        fig.suptitle(title)
    return fig


def plot_residual_qq(residuals: Mapping[str, np.ndarray], title: str | None = None):
    """Normal QQ plots of model residuals, one axes each (Fig. 2-14).

    Parameters
    ----------
    residuals : {label: array}
        Residuals (NaNs ignored); each is standardised by its own mean and standard
        deviation, so the reference line is y = x.
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
        Per axes: the ordered standardised residuals against the normal quantiles (gid
        "qq") and the line y = x (gid "reference").
    """
    Figure = require_matplotlib()
    if not residuals:
        raise InputError("plot_residual_qq needs at least one residual series")
    fig = Figure(figsize=(3.6 * len(residuals), 3.6), layout="constrained")
    axes = fig.subplots(1, len(residuals), squeeze=False)[0]
    for ax, (label, r) in zip(axes, residuals.items(), strict=True):
        r = np.asarray(r, float)
        r = r[np.isfinite(r)]
        if r.size < 3 or not np.std(r) > 0:
            raise InputError(f"plot_residual_qq: '{label}' needs 3 or more distinct values")
        z = np.sort((r - r.mean()) / r.std())
        q = stats.norm.ppf((np.arange(1, z.size + 1) - 0.5) / z.size)
        ax.plot(q, z, ls="none", marker=".", ms=2, gid="qq")
        lim = float(max(np.abs(q).max(), np.abs(z).max()))
        ax.plot([-lim, lim], [-lim, lim], color="k", lw=1, ls="--", gid="reference")
        ax.set(xlabel="normal quantile", ylabel="standardised residual", title=label)
    if title:
        fig.suptitle(title)
    return fig


def plot_profiles(
    groups: Mapping[str, Sequence[tuple[np.ndarray, np.ndarray]]],
    ylabel: str,
    xlabel: str = "t - t_event [s]",
    title: str | None = None,
):
    """Aligned profiles of several cycles, one axes per group with a shared y axis
    (Fig. 2-15: tension around the roll change, normal cycles against dancer failures).

    Parameters
    ----------
    groups : {label: [(x, y), ...]}
        One axes per group; one line per (x, y) profile.
    ylabel, xlabel : str
    title : str, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    Figure = require_matplotlib()
    if not groups:
        raise InputError("plot_profiles needs at least one group")
    fig = Figure(figsize=(4.2 * len(groups), 3.6), layout="constrained")
    axes = fig.subplots(1, len(groups), sharey=True, squeeze=False)[0]
    for ax, (label, profiles) in zip(axes, groups.items(), strict=True):
        for i, (x, y) in enumerate(profiles):
            ax.plot(np.asarray(x, float), np.asarray(y, float), lw=0.9, label=f"{i + 1}")
        ax.axvline(0.0, color="k", lw=0.8, ls=":")
        ax.set(xlabel=xlabel, title=label)
        if profiles:
            ax.legend(title="cycle", fontsize="x-small", loc="lower left")
    axes[0].set_ylabel(ylabel)
    if title:
        fig.suptitle(title)
    return fig
