"""Stage 7 of the pipeline: evaluation. The metrics (:mod:`.metrics`), the harness that fits,
calibrates and scores a plug-in (:mod:`.harness`), its results files (:mod:`.results`) and
the plug-in contract as checks a plug-in's author runs (:func:`check_plugin`)."""

from __future__ import annotations

__all__ = ["check_plugin", "example_runs"]


def __getattr__(name: str):
    """``check_plugin`` and ``example_runs``, imported on first access (PEP 562): the harness
    they use loads scikit-learn."""
    if name in __all__:
        from . import checks

        return getattr(checks, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
