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
        raise InputError("plotting needs matplotlib, which is not installed: "
                         'pip install "r2rsim[plot]"') from None
    return Figure
