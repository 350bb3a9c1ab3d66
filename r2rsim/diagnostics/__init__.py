"""Stage 6 of the pipeline: diagnostic plug-ins (the contract in :mod:`.base`, baselines in
:mod:`.baselines`, discovery in :mod:`.registry`).

``Diagnostic`` is loaded on first use (PEP 562): the contract imports scikit-learn and pandas,
which ``r2rsim list plugins`` and the refusal of an unknown ``--method`` do not need.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .base import Diagnostic

__all__ = ["Diagnostic"]


def __getattr__(name: str):
    if name == "Diagnostic":
        from .base import Diagnostic

        return Diagnostic
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
