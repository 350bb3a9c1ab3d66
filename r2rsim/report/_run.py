"""The run figure: chosen channels of one run on shared time axes, one axes per physical
quantity, with the run's fault windows shaded and its events marked."""

from __future__ import annotations

import numpy as np
import pandas as pd

from ..dataset.verify import Verifier
from ..errors import InputError
from ._data import (
    channel_table,
    check_run_labels,
    constant_columns,
    is_encoder,
    open_dataset,
    open_run,
    read_envelopes,
    resolve_run,
    run_rows,
    select_channels,
    verified,
)
from ._mpl import axis_label, display_unit, plain_ticks, require_matplotlib, wrap_title

#: what a run figure shows unless told: span tensions with the tension readings and
#: set-points, web speeds with the line speed set-point, dancer and festoon positions,
#: roll radii and drive torques (states that never change, like an idler's radius, are
#: left out of this default set)
DEFAULT_CHANNELS = (
    "state.*.tension_N",
    "meas.*",
    "sp.*tension_N",
    "sp.line_speed_m_s",
    "state.*.surface_speed_m_s",
    "state.*.position_*",
    "state.*.radius_m",
    "act.*.torque_N_m",
)
#: words that name a physical quantity in a column name (``surface_speed_m_s``: speed); a
#: column without one is its own quantity (``ctrl.x.error_N``: error)
_QUANTITIES = (
    "tension",
    "speed",
    "position",
    "angle",
    "velocity",
    "radius",
    "diameter",
    "torque",
    "force",
    "length",
    "strain",
    "inertia",
    "mass",
    "acceleration",
)
_AXES_HEIGHT_IN = 2.0
_WIDTH_IN = 10.0
#: colour and dash pattern of the set-points of one axes, in turn: each its own, all dark
#: (a reading is a thin coloured line, a set-point a dark dashed one)
SETPOINT_STYLES = (
    ("k", "--"),
    ("0.45", "-."),
    ("k", ":"),
    ("0.45", (0, (6, 2, 1, 2, 1, 2))),
    ("k", (0, (1, 1))),
    ("0.45", (0, (8, 3))),
)


def plot_run(
    dataset,
    run_id: str | None = None,
    channels=None,
    t0: float | None = None,
    t1: float | None = None,
    *,
    n_buckets: int | None = None,
    faults: bool = True,
    events: bool = True,
    figsize: tuple[float, float] | None = None,
    verify: bool = True,
):
    """Plot channels of one run against time.

    One axes per physical quantity and unit (span tensions, web speeds, positions, radii,
    torques...), all sharing the time axis, each labelled ``quantity (unit)`` with plain tick
    labels (no offset; small lengths and angles in mm or mrad). Set-points (``sp.*``) are
    drawn dark and dashed against the readings, each set-point of an axes with its own
    colour and dash pattern (:data:`SETPOINT_STYLES`) and legend entry. An encoder's speed
    (quantised to one count per sample period) is drawn as its mean per pixel column, the
    speed over a longer counting window, in a light band from its minimum to its maximum
    there. Fault windows from ``faults.parquet`` are shaded and named (a fault
    without an end lasts to the end of the run); events from ``events.parquet`` (splices,
    slack, web breaks, dancer end stops...) are vertical lines, one colour per kind. Only
    the requested columns are read, row group by row group, and each is thinned to a
    min/max envelope per pixel column (:func:`decimate_minmax`), so spikes stay visible and
    an hour at 1 kHz plots in seconds.

    Parameters
    ----------
    dataset : str or Path
        Dataset directory written by ``r2rsim run`` or ``r2rsim sweep``.
    run_id : str, optional
        Run to plot (default: the first in runs.parquet).
    channels : str or list of str, optional
        Column globs (``fnmatch``), e.g. ``"state.span*.tension_N"`` or ``"meas.*"``. Every
        glob must match a numeric column. Default :data:`DEFAULT_CHANNELS` (globs that match
        nothing and constant channels are skipped there).
    t0, t1 : float, optional
        Time window [s] (default: the whole run).
    n_buckets : int, optional
        Buckets of the min/max envelope (default: the figure width in pixels).
    faults, events : bool
        Shade the fault windows, mark the events.
    figsize : (float, float), optional
        Figure size in inches (default 10 wide, 2 per axes high).
    verify : bool
        Check the dataset against its manifest.json, as every reader does
        (:mod:`r2rsim.dataset.verify`): every listed file is there with its size, and the
        files read (runs, channels, faults and events tables, the run's samples, each hashed
        whole although only some columns are parsed) have their sha256. A dataset changed
        after it was written is refused; ``verify=False`` (``--no-verify``) draws it anyway.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    InputError
        For a missing dataset, an unfinished sweep, a file that differs from manifest.json
        (``verify``), an unknown run, a glob matching no column, an empty time window, or
        when matplotlib is not installed.
    """
    Figure = require_matplotlib()
    root = open_dataset(dataset)
    with Verifier(root, verify) as v:
        fig = _plot_run(
            root, v, run_id, channels, t0, t1, n_buckets, faults, events, figsize, Figure
        )
        verified(v)
    return fig


def _plot_run(root, v, run_id, channels, t0, t1, n_buckets, faults, events, figsize, Figure):
    run = open_run(root, resolve_run(root, run_id, v), v)
    if v.verify:
        check_run_labels(run)  # the figure shades the fault windows faults.parquet gives
    columns = _channels(run, channels)
    t0 = run.t_start if t0 is None else float(t0)
    t1 = run.t_end if t1 is None else float(t1)
    if not t0 < t1 or t1 < run.t_start or t0 > run.t_end:
        raise InputError(
            f"dataset {root}: run {run.run_id}: no samples between t0 = {t0:g} "
            f"and t1 = {t1:g} s (the run spans {run.t_start:g} to "
            f"{run.t_end:g} s)"
        )
    table = channel_table(root, v)
    units = {c: table.get(c, ("", ""))[0] for c in columns}
    encoders = {c for c in columns if is_encoder(table.get(c, ("", ""))[1])}
    groups = _group_by_quantity(columns, units)
    fig = Figure(
        figsize=figsize or (_WIDTH_IN, 1.0 + _AXES_HEIGHT_IN * len(groups)), layout="constrained"
    )
    n_buckets = n_buckets or int(fig.get_figwidth() * fig.dpi)
    data = read_envelopes(run, columns, t0, t1, n_buckets, means=encoders)
    axes = fig.subplots(len(groups), 1, sharex=True, squeeze=False)[:, 0]
    for ax, ((quantity, unit), group) in zip(axes, groups.items(), strict=True):
        factor, shown = display_unit(
            unit, np.concatenate([np.ravel(data[c][1:]) for c in group] or [np.empty(0)])
        )
        _draw_channels(ax, group, data, factor)
        ax.set_ylabel(axis_label(quantity, shown))
        plain_ticks(ax, xbins=12)
    axes[-1].set_xlim(t0, t1)
    axes[-1].set_xlabel(axis_label("time", "s"))
    handles = []
    if faults:
        handles += _shade_faults(
            axes, run_rows(root, "faults.parquet", run.run_id, v), run.t_end, t0, t1
        )
    if events:
        handles += _mark_events(axes, run_rows(root, "events.parquet", run.run_id, v), t0, t1)
    if handles:
        fig.legend(
            handles=handles,
            loc="outside lower center",
            ncols=min(len(handles), 4),
            fontsize="small",
            frameon=False,
        )
    fig.suptitle(wrap_title(f"{root.name}: {run.run_id}", fig, "medium"), fontsize="medium")
    return fig


def _channels(run, channels) -> list[str]:
    """The columns to draw: the user's globs (each must match), else the default set."""
    if channels is not None:
        globs = [channels] if isinstance(channels, str) else list(channels)
        if not globs:
            raise InputError("no channel globs given")
        return select_channels(run, globs)
    picked = []
    for g in DEFAULT_CHANNELS:
        try:
            picked += [c for c in select_channels(run, [g]) if c not in picked]
        except InputError:
            pass  # a line without dancers has no position: fine for the default set
    # an idler's radius or torque never changes: leave such states out (not set-points,
    # which are drawn against the readings however constant)
    fixed = constant_columns(run, [c for c in picked if not c.startswith(("sp.", "meas."))])
    picked = [c for c in picked if c not in fixed]
    if not picked:
        raise InputError(
            f"dataset {run.root}: run {run.run_id}: none of the default "
            f"channels varies; name some with channels="
        )
    return picked


def _quantity(column: str, unit: str) -> str:
    """The physical quantity a column holds: a known word of its name, else its name
    without the unit suffix (``error_N`` -> ``error``); a speed in rad/s is an angular
    speed."""
    name = column.rsplit(".", 1)[-1]
    word = next((w for w in name.split("_") if w in _QUANTITIES), None)
    if word:
        return "angular speed" if word == "speed" and unit == "rad/s" else word
    suffix = "_" + unit.replace("/", "_").replace("*", "_").replace("^", "")
    return name[: -len(suffix)] if unit and name.endswith(suffix) else name


def _group_by_quantity(
    columns: list[str], units: dict[str, str]
) -> dict[tuple[str, str], list[str]]:
    """Columns grouped by ``(quantity, unit)`` (one axes each), in order of first use."""
    groups: dict[tuple[str, str], list[str]] = {}
    for c in columns:
        unit = units.get(c, "")
        groups.setdefault((_quantity(c, unit), unit), []).append(c)
    return groups


def _draw_channels(ax, columns: list[str], data: dict, factor: float = 1.0) -> None:
    """One line per column: each set-point dark and dashed in its own style, readings thin,
    true values solid; an encoder (``data`` holding its bucket means, minima and maxima) as
    its mean in a light min-max band. Values are multiplied by ``factor`` (the axes' unit)."""
    n_sp = 0
    for c in columns:
        t, y, *band = data[c]
        if c.startswith("sp."):
            colour, dashes = SETPOINT_STYLES[n_sp % len(SETPOINT_STYLES)]
            n_sp += 1
            ax.plot(t, y * factor, color=colour, ls=dashes, lw=1.2, label=c)
        elif band:
            (line,) = ax.plot(t, y * factor, lw=1.0, label=c)
            ax.fill_between(
                t,
                band[0] * factor,
                band[1] * factor,
                color=line.get_color(),
                alpha=0.25,
                lw=0,
                gid=f"band:{c}",
            )
        elif c.startswith("meas."):
            ax.plot(t, y * factor, lw=0.7, alpha=0.8, label=c)
        else:
            ax.plot(t, y * factor, lw=1.1, label=c)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize="x-small", frameon=False)
    ax.grid(True, alpha=0.3)


def _shade_faults(axes, faults, run_end: float, t0: float, t1: float) -> list:
    """Shade each fault's window (onset to end, or to the run's end) on every axes and name
    it at the top; return the legend handles."""
    from matplotlib import colormaps
    from matplotlib.patches import Patch

    handles = []
    colours = colormaps["tab10"]
    for i, f in faults.iterrows():
        start = float(f["onset_t_s"])
        end = run_end if pd.isna(f["end_t_s"]) else float(f["end_t_s"])
        if end < t0 or start > t1:
            continue
        colour = colours(i % 10)
        fid = f["fault_id"]
        for ax in axes:
            ax.axvspan(start, end, color=colour, alpha=0.15, lw=0, gid=f"fault:{fid}")
        axes[0].text(
            max(start, t0),
            0.98,
            f" {fid}",
            transform=axes[0].get_xaxis_transform(),
            va="top",
            fontsize="x-small",
            color=colour,
            clip_on=True,
        )
        handles.append(Patch(color=colour, alpha=0.3, label=f"{fid}: {f['fault_type']}"))
    return handles


def _mark_events(axes, events, t0: float, t1: float) -> list:
    """A vertical line on every axes at each event in the window (fault start/end events
    are left out: the fault windows show them); return one legend handle per kind."""
    from matplotlib import colormaps
    from matplotlib.lines import Line2D

    if events.empty:
        return []
    shown = events[(events["kind"] != "fault") & events["t_s"].between(t0, t1)]
    handles = []
    colours = colormaps["Dark2"]
    for i, (kind, rows) in enumerate(shown.groupby("kind", sort=True)):
        colour = colours(i % 8)
        for ax in axes:
            ax.vlines(
                rows["t_s"].to_numpy(),
                0,
                1,
                transform=ax.get_xaxis_transform(),
                colors=[colour],
                linestyles=":",
                lw=1.0,
                gid=f"event:{kind}",
            )
        handles.append(Line2D([], [], color=colour, ls=":", label=f"{kind} ({len(rows)})"))
    return handles
