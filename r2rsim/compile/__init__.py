"""Stage 2 of the pipeline: lower a line into flat arrays and one numba kernel.

The names below are imported on first access (PEP 562): :mod:`.compiler` loads numba and
the kernels, which the dataset readers do not need when they use :mod:`.faults` to read a
fault record back.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .compiler import CompiledLine, Programme, compile_line

__all__ = ["CompiledLine", "Programme", "compile_line"]


def __getattr__(name: str):
    """Import :mod:`.compiler` on first access of one of its public names."""
    if name not in __all__:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(".compiler", __name__), name)
    globals()[name] = value
    return value
