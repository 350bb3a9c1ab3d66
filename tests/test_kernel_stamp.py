"""numba's cache and the kernel's sources: every file compiled into the cached kernel is in
its cache key (r2rsim/compile/stamp.py)."""

import re
from pathlib import Path

from r2rsim.compile import kernels, stamp
from r2rsim.solve import radau

COMPILE = Path(stamp.__file__).resolve().parent


def _imports_numba(path: Path) -> bool:
    # independent of stamp.imports_numba: a plain text scan of the import statements
    return re.search(r"^\s*(import numba\b|from numba\b)", path.read_text(), re.M) is not None


def test_every_compile_module_with_numba_is_stamped():
    files = stamp.stamped_files()
    numba_modules = {p for p in COMPILE.glob("*.py") if _imports_numba(p)}
    assert COMPILE / "kernels.py" in numba_modules
    assert numba_modules <= set(files)
    assert COMPILE / "layout.py" in files  # its fields are compiled in as constants
    assert len(files) == len(set(files))


def test_the_stamp_changes_with_any_stamped_file(monkeypatch):
    files = stamp.stamped_files()
    base = stamp.kernel_stamp()
    assert stamp.kernel_stamp() == base  # deterministic
    real = stamp._read
    for path in files:
        monkeypatch.setattr(stamp, "_read", lambda p, e=path: real(p) + (b" " if p == e else b""))
        assert stamp.kernel_stamp() != base, path
    monkeypatch.setattr(stamp, "_read", real)
    assert stamp.kernel_stamp() == base


def test_kernel_and_integrator_carry_the_stamp():
    s = stamp.kernel_stamp()
    assert kernels.STAMP == s
    cached = [
        f
        for f in vars(kernels).values()
        if isinstance(f, kernels.Dispatcher) and f.py_func.__module__ == kernels.__name__
    ]
    assert kernels.evaluate in cached and len(cached) > 10
    for f in cached:
        assert isinstance(f._cache, kernels._StampedCache), f
        key = f._cache._index_key(("sig",), f.targetctx.codegen())
        assert key[-1] == s, f
    assert radau._kernel_stamp() == s
    for fn in (radau.integrate, radau._initial_step):
        assert s in [c.cell_contents for c in fn.py_func.__closure__ or ()], fn
