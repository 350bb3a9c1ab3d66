"""matplotlib, imported on demand with one clear message when it is missing."""

from __future__ import annotations

from ..errors import InputError


def require_matplotlib():
    """Import matplotlib with a non-interactive default (figures are built, then saved or
    shown by the caller) and return its ``pyplot``-free ``Figure`` class.

    Returns
    -------
    type
        :class:`matplotlib.figure.Figure`.

    Raises
    ------
    InputError
        When matplotlib is not installed.
    """
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise InputError(
            "plotting needs matplotlib, which is not installed: "
            'pip install matplotlib (or pip install -e ".[plot]" in the r2rsim '
            "checkout)"
        ) from None
    return Figure


# ---- axis labels and ticks -----------------------------------------------------------------
#
# Every axes that shows data is labelled ``quantity (unit)``, the unit an SI unit as the
# dataset stores it (channels.parquet, faults.parquet), possibly with a prefix chosen for
# readable ticks (``pitch (mm)``, ``gain (ppm)``); a unitless number says so: ``(1)`` for a
# probability, a rate as a fraction, a count or a detector statistic (``pd (1)``), and
# ``(relative)`` for a relative magnitude. An axis whose ticks name categories (conditions,
# faults) has a plain name. The tests of the figures (tests/test_figures.py) hold every
# figure the run, sweep and report commands draw to this rule.

#: units that take an SI prefix when their values are small (below 1): lengths in mm or µm,
#: angles in mrad, relative changes in ppm
_PREFIXED = {
    "m": (("mm", 1e3), ("µm", 1e6)),
    "rad": (("mrad", 1e3), ("µrad", 1e6)),
    "1": (("ppm", 1e6),),
    "rel": (("ppm", 1e6),),
}
#: how a unitless value is named in a label
_UNITLESS = {"": "1", "1": "1", "rel": "relative"}


def axis_label(quantity: str, unit: str | None) -> str:
    """``quantity (unit)``: a dimensionless unit ("1", "rel", none) shown as such."""
    unit = "" if unit is None else str(unit)
    return f"{quantity} ({_UNITLESS.get(unit, unit)})"


def display_unit(unit: str | None, values) -> tuple[float, str]:
    """The factor and unit to show values stored in ``unit`` with: an SI prefix when they
    are all small (a pitch of 0.2502 m as 250.2 mm, a gain error of 5.8e-05 as 58 ppm), so
    the tick labels stay short and plain. ``(1.0, unit)`` otherwise."""
    import numpy as np

    unit = "" if unit is None else str(unit)
    v = np.abs(np.asarray(values, dtype=float))
    v = v[np.isfinite(v)]
    big = float(v.max()) if v.size else 0.0
    if unit not in _PREFIXED or big == 0.0 or big >= 1.0:
        return 1.0, unit
    if unit in ("1", "rel") and big >= 1e-2:
        return 1.0, unit  # a gain of 0.05 reads well as it is
    choices = _PREFIXED[unit]
    for name, factor in choices:
        if big * factor >= 1.0:
            return factor, name
    return choices[-1][1], choices[-1][0]


def plain_ticks(ax, xbins: int | None = None, ybins: int | None = 6) -> None:
    """Tick labels as plain numbers: no offset (``1e-5+2.502e-1``) on either axis of ``ax``
    (a linear axis with matplotlib's default formatter). ``xbins``, ``ybins``: at most this
    many tick intervals on that axis (None: matplotlib's choice, by the axes' size): a fixed
    number keeps the tick labels, so their width, the same while the constrained layout
    resizes the axes (with the default locator a label can gain a decimal after the layout
    made room for it, and stick out of the figure)."""
    from matplotlib.ticker import AutoLocator, MaxNLocator, ScalarFormatter

    for axis, bins in ((ax.xaxis, xbins), (ax.yaxis, ybins)):
        if isinstance(axis.get_major_formatter(), ScalarFormatter):
            axis.set_major_formatter(ScalarFormatter(useOffset=False))
            if bins is not None and isinstance(axis.get_major_locator(), AutoLocator):
                axis.set_major_locator(MaxNLocator(nbins=bins, steps=[1, 2, 2.5, 5, 10]))


def wrap_title(text: str, fig, fontsize: float | str = "large") -> str:
    """``text`` broken into lines that fit the figure's width (a suptitle longer than the
    figure is cut off on both sides, not wrapped, by matplotlib)."""
    import textwrap

    from matplotlib.font_manager import FontProperties

    size = FontProperties(size=fontsize).get_size_in_points()
    width_pt = fig.get_figwidth() * 72.0 * 0.92
    per_line = max(20, int(width_pt / (0.60 * size)))  # a generous average glyph width
    return "\n".join(textwrap.fill(part, per_line) for part in text.split("\n"))
