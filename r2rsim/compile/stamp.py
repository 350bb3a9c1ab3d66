"""A hash of the sources compiled into the line kernel, for numba's cache.

numba keys a cached function on its own file's time stamp and its own bytecode. Everything
else it compiles in is invisible to that key: the record fields of :mod:`.layout` (frozen
into the machine code as constants) and the njit functions of other modules the function
calls (linked into its cached library). An edit of one of those files alone would leave the
cached kernel, and every cached caller of it, running the old code. :func:`kernel_stamp`
hashes all of them; every function compiled with :func:`.model.base.kernel` adds it to its
cache key, and the integrator (:mod:`r2rsim.solve.radau`) is built in a closure over it.

This module does not import numba (so it is not one of the files it stamps).
"""

from __future__ import annotations

import ast
import functools
import hashlib
from pathlib import Path

HERE = Path(__file__).resolve().parent


def imports_numba(path: Path) -> bool:
    """Whether the module at ``path`` imports numba (anywhere in it)."""
    source = path.read_bytes()
    if b"numba" not in source:
        return False
    for node in ast.walk(ast.parse(source, filename=str(path))):
        if isinstance(node, ast.Import) and any(
            a.name.split(".")[0] == "numba" for a in node.names
        ):
            return True
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            if node.module.split(".")[0] == "numba":
                return True
    return False


@functools.cache
def stamped_files() -> tuple[Path, ...]:
    """The files the stamp hashes: ``kernels.py`` and ``layout.py`` first, then every module
    of the kernel's phases (``model/``, which compile through ``model.base.kernel`` without
    importing numba themselves) and every other module of ``r2rsim/compile`` that imports
    numba, by path."""
    first = [HERE / "kernels.py", HERE / "layout.py"]
    phases = set((HERE / "model").glob("*.py"))
    rest = sorted(
        p for p in HERE.rglob("*.py") if p not in first and (p in phases or imports_numba(p))
    )
    return (*first, *rest)  # cached: the files do not change under a running process


def _read(path: Path) -> bytes:
    return path.read_bytes()


def kernel_stamp() -> int:
    """A 60-bit hash of :func:`stamped_files`' bytes."""
    h = hashlib.sha256()
    for path in stamped_files():
        h.update(_read(path))
    return int(h.hexdigest()[:15], 16)
