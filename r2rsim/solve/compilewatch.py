"""Time spent compiling numba kernels, measured with numba's event API.

r2rsim's kernels are compiled with ``cache=True``: the first run after an install (or after
an edit of a kernel) compiles them, about a minute on a small machine; later runs load them
from the cache in a fraction of a second. numba emits a ``numba:compile`` event only when it
really compiles (a cache hit emits none), so a listener on it tells both *that* compilation is
happening, before it starts, and how long it took. ``r2rsim run`` uses the first to say
"compiling (first run only)…" on stderr and the second to keep the compile out of the wall
time and real-time factor it reports.

Nested compilations (a kernel compiling the functions it calls) are counted once, from the
start of the outermost one to its end.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Iterator
from typing import TypedDict


class _State(TypedDict):
    installed: bool
    depth: int
    t0: float
    total: float
    notify: Callable[[bool], None] | None


_lock = threading.Lock()
_state: _State = {"installed": False, "depth": 0, "t0": 0.0, "total": 0.0, "notify": None}


def _install() -> None:
    with _lock:
        if _state["installed"]:
            return
        try:
            from numba.core import event
        except ImportError:  # an old numba without the event API: nothing is measured
            _state["installed"] = True
            return

        class _Listener(event.Listener):
            def on_start(self, ev):
                if _state["depth"] == 0:
                    _state["t0"] = time.perf_counter()
                    _call(True)
                _state["depth"] += 1

            def on_end(self, ev):
                _state["depth"] = max(0, _state["depth"] - 1)
                if _state["depth"] == 0:
                    _state["total"] += time.perf_counter() - _state["t0"]
                    _call(False)

        event.register("numba:compile", _Listener())
        _state["installed"] = True


def _call(compiling: bool) -> None:
    fn = _state["notify"]
    if fn is not None:
        try:
            fn(compiling)
        except Exception:  # noqa: BLE001 - a display problem must never break a compile
            pass


def compile_seconds() -> float:
    """Seconds this process has spent compiling numba functions since the watch was
    installed (by the first call of this function or of :func:`notify_compiling`). Take the
    difference of two calls to time a stretch of code."""
    _install()
    total = _state["total"]
    if _state["depth"]:  # inside a compilation (a call from a notify callback)
        total += time.perf_counter() - _state["t0"]
    return total


@contextlib.contextmanager
def notify_compiling(callback: Callable[[bool], None] | None) -> Iterator[None]:
    """Within the block, call ``callback(True)`` when numba starts compiling and
    ``callback(False)`` when it is done (once per outermost compilation)."""
    _install()
    old = _state["notify"]
    _state["notify"] = callback
    try:
        yield
    finally:
        _state["notify"] = old
