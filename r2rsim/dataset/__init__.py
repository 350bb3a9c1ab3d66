"""Stage 5 of the pipeline: Parquet datasets with labels and provenance.

The names below are imported on first access (PEP 562): the writer needs the compiled line
(numba, scipy), which the readers (:mod:`r2rsim.dataset.read`, :mod:`.verify`, used by
``plot``, ``report`` and ``diagnose``) do not, so importing one of them stays cheap.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .columns import true_state_columns
    from .writer import SCHEMA_VERSION, DatasetWriter

_LAZY = {"SCHEMA_VERSION": ".writer", "DatasetWriter": ".writer", "true_state_columns": ".columns"}

__all__ = ["SCHEMA_VERSION", "DatasetWriter", "true_state_columns"]


def __getattr__(name: str):
    """Import the submodule that defines ``name`` on first access."""
    if name not in _LAZY:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(_LAZY[name], __name__), name)
    globals()[name] = value
    return value
