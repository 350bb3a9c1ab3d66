"""Stage 2 of the pipeline: lower a line into flat arrays and one numba kernel."""

from .compiler import CompiledLine, Programme, compile_line

__all__ = ["CompiledLine", "Programme", "compile_line"]
