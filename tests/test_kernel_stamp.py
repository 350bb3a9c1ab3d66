"""numba's cache and the kernel's sources: every file compiled into the cached kernel is in
its cache key (r2rsim/compile/stamp.py)."""

import importlib
import pkgutil
import re
from pathlib import Path

from numba.core.dispatcher import Dispatcher

from r2rsim.compile import kernels, model, stamp
from r2rsim.compile.model import base
from r2rsim.solve import radau

COMPILE = Path(stamp.__file__).resolve().parent


def _imports_numba(path: Path) -> bool:
    # independent of stamp.imports_numba: a plain text scan of the import statements
    return re.search(r"^\s*(import numba\b|from numba\b)", path.read_text(), re.M) is not None


def test_every_compile_module_with_numba_is_stamped():
    files = stamp.stamped_files()
    numba_modules = {p for p in COMPILE.rglob("*.py") if _imports_numba(p)}
    assert COMPILE / "kernels.py" in numba_modules
    # every module of the phases: they compile through model.base.kernel, not numba itself
    phases = set((COMPILE / "model").glob("*.py"))
    assert COMPILE / "model" / "spans.py" in phases and phases <= set(files)
    numba_modules |= phases
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


def _kernel_modules():
    yield kernels
    for info in pkgutil.iter_modules(model.__path__):
        yield importlib.import_module(f"{model.__name__}.{info.name}")


def test_kernel_and_integrator_carry_the_stamp():
    s = stamp.kernel_stamp()
    assert kernels.STAMP == s
    cached = [
        f
        for mod in _kernel_modules()
        for f in vars(mod).values()
        if isinstance(f, Dispatcher) and f.py_func.__module__ == mod.__name__
    ]
    assert kernels.evaluate in cached and len(cached) > 40
    inlined = [f for f in cached if f.targetoptions.get("forceinline")]
    cached = [f for f in cached if f not in inlined]
    assert len(inlined) > 20 and len(cached) > 10
    for f in inlined:  # compiled only into their (cached) callers
        assert not f.targetoptions.get("cache"), f
    for f in cached:
        assert isinstance(f._cache, base.StampedCache), f
        key = f._cache._index_key(("sig",), f.targetctx.codegen())
        assert key[-1] == s, f
    assert radau._kernel_stamp() == s
    for fn in (radau.integrate, radau._initial_step):
        assert s in [c.cell_contents for c in fn.py_func.__closure__ or ()], fn
