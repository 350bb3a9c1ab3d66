"""How a sweep's worker processes are started: spawned, with SIGINT blocked.

A Ctrl-C in a terminal signals every process of the group, worker processes included. A
worker that is still starting (importing r2rsim, reading its start-up data) would print a
``KeyboardInterrupt`` traceback before its initializer ignores SIGINT. A blocked signal is
inherited by the new process, so it holds the signal until the initializer
(:func:`._execute._worker_init`) ignores it and unblocks it, which drops it. Python starts
its own resource tracker the same way.

Its own module so that ``multiprocessing`` is imported only when a sweep starts workers,
and so that a worker (which unpickles its process object) finds the class by name.
"""

from __future__ import annotations

import multiprocessing
import signal
from multiprocessing.context import SpawnContext, SpawnProcess


class SigintBlockedProcess(SpawnProcess):
    """A spawned process that starts with SIGINT blocked (see the module's docstring)."""

    def start(self) -> None:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            super().start()
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


class SigintBlockedContext(SpawnContext):
    """The ``spawn`` start method with :class:`SigintBlockedProcess` processes."""

    Process = SigintBlockedProcess


def worker_context():
    """The multiprocessing context of a sweep's worker pool: ``spawn``, each worker started
    with SIGINT blocked where the platform has signal masks (POSIX)."""
    if not hasattr(signal, "pthread_sigmask"):
        return multiprocessing.get_context("spawn")
    return SigintBlockedContext()
