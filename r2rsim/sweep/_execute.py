"""Running a sweep's runs: in this process, on local worker processes, or on a Dask cluster.

Every executor calls :func:`run_one` once per run and hands each result to ``on_result`` in
the parent as it arrives. A worker process imports r2rsim and loads the compiled kernels once,
then runs many scenarios. At most ``2 x workers`` runs are submitted at a time, so the parent's
memory does not grow with the number of runs.
"""

from __future__ import annotations

import atexit
import contextlib
import errno
import functools
import gc
import os
import signal
import time
import traceback
import warnings
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import InputError, PlausibilityWarning, R2RError

if TYPE_CHECKING:
    from ._plan import RunSpec

#: a run is given up (recorded as failed) when the worker process running it died this often
MAX_ATTEMPTS = 3
#: seconds to wait for a Dask scheduler to answer
CONNECT_TIMEOUT_S = 30


#: errno values that say the machine failed, not the run: no space or quota left, a
#: read-only file system, no permission, an I/O error, no file handles left
ENVIRONMENT_ERRNOS = frozenset(
    e
    for e in (
        errno.ENOSPC,
        getattr(errno, "EDQUOT", None),
        errno.EROFS,
        errno.EACCES,
        errno.EPERM,
        errno.EIO,
        errno.EMFILE,
        errno.ENFILE,
    )
    if e is not None
)


def environment_error(exc: BaseException | None) -> OSError | None:
    """The error of the environment behind ``exc`` (itself, or in its chain of causes), as a
    plain OSError with the system's text for its errno; None when the run itself failed."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno is not None and exc.errno in ENVIRONMENT_ERRNOS:
            return OSError(exc.errno, os.strerror(exc.errno), exc.filename)
        exc = exc.__cause__ or exc.__context__
    return None


class WorkerSetupError(R2RError):
    """A worker process cannot run any of the sweep's runs: the sweep stops (its finished
    runs kept) instead of recording every run as failed."""


def kinds_for_workers() -> bytes:
    """The element kinds :func:`~r2rsim.schema.kinds.register` added in this process,
    pickled for the worker processes (they import r2rsim afresh and would not know them);
    empty when there are none.

    Raises
    ------
    InputError
        If a kind cannot be pickled (a class defined inside a function).
    """
    import pickle

    from ..schema.kinds import added_kinds

    kinds = added_kinds()
    if not kinds:
        return b""
    try:
        return pickle.dumps(kinds)
    except (pickle.PicklingError, AttributeError, TypeError) as exc:
        names = ", ".join(repr(k.name) for k in kinds)
        raise InputError(
            f"the element kinds registered in this process ({names}) cannot be sent to the "
            f"sweep's worker processes ({type(exc).__name__}: {exc}): define each kind's "
            f"classes at the top level of a module, or run the sweep in this process "
            f"(workers=0)"
        ) from None


#: the pickled kinds this worker has registered (:func:`_register_kinds`)
_kinds_registered = b""


def _register_kinds(kinds: bytes) -> None:
    """Register in this worker the kinds the sweep's process registered
    (:func:`kinds_for_workers`), once per worker."""
    global _kinds_registered
    if not kinds or kinds == _kinds_registered:
        return
    import pickle

    from ..schema.kinds import register

    try:
        loaded = pickle.loads(kinds)
    except Exception as exc:  # noqa: BLE001 - whatever the unpickling raises, said once
        raise WorkerSetupError(
            f"a worker process cannot load the element kinds registered in the sweep's "
            f"process ({type(exc).__name__}: {exc}): define each kind's classes at the top "
            f"level of a module the workers can import (not under `if __name__ == "
            f'"__main__":`, not in a notebook), or run the sweep in this process '
            f"(workers=0). The finished runs are kept"
        ) from None
    for kind in loaded:
        register(kind, replace=True)
    _kinds_registered = kinds


def run_one(spec, work: str, kinds: bytes = b"") -> dict:
    """Run one sweep run into ``<work>/<run_id>/`` (in a worker).

    A run that raises is recorded as failed in ``<work>/<run_id>.failed.json`` and reported;
    it does not stop the sweep. An error of the environment (:func:`environment_error`: the
    disk is full, read-only, ...) is not the run's: it is raised, and stops the sweep with
    its finished runs kept. Returns a small record: ``run_id``, ``status`` (done or
    failed), ``reason``, ``simulated_s``, ``solver_s`` (the simulation's wall time, numba
    compilation excluded), ``wall_s`` (the whole run in the worker) and ``has_data``.
    ``kinds``: :func:`kinds_for_workers` of the sweep's process (a :class:`WorkerSetupError`
    when they cannot be loaded here).
    """
    _register_kinds(kinds)
    from ..run import RunPlan, execute
    from ..schema.loader import build_scenario
    from ._store import failed_reason, finished, run_columns, write_failure

    t0 = time.perf_counter()
    done = finished(Path(work) / spec.run_id, spec.config_sha256)
    if done is not None:  # written by a worker that died before it could report it
        reason = failed_reason(done)
        return {
            "run_id": spec.run_id,
            "status": "failed" if reason else "done",
            "reason": reason,
            "has_data": True,
            "simulated_s": done["simulated_s"],
            "solver_s": done["wallclock_s"],
            "wall_s": time.perf_counter() - t0,
        }
    try:
        with warnings.catch_warnings():  # reported once, by the plan
            warnings.simplefilter("ignore", PlausibilityWarning)
            scenario_data, line_data = spec.data()
            scenario, line = build_scenario(scenario_data, line_data, spec.source, spec.line_file)
        scenario.seed = spec.seed
        plan = RunPlan(
            scenario,
            line,
            spec.name,
            spec.source,
            spec.config_sha256,
            {},
            {"sweep": spec.columns["sweep"]},
            spec.line_config,
        )
        # labels are derived once, not read back again per run (~20 ms of a 60 ms run);
        # `r2rsim validate` checks the finished dataset in full
        s = execute(
            plan,
            Path(work) / spec.run_id,
            run_id=spec.run_id,
            run_columns=run_columns(spec),
            clean_stale=False,
            check_labels=False,
        )
    except Exception as exc:  # noqa: BLE001 - a failed run is recorded, the sweep goes on
        env = environment_error(exc)
        if env is not None:  # what the writer had written is removed (DatasetWriter.abort)
            raise env from None
        reason = f"{type(exc).__name__}: {exc}"
        write_failure(work, spec, reason, traceback.format_exc())
        return {
            "run_id": spec.run_id,
            "status": "failed",
            "reason": reason,
            "has_data": False,
            "simulated_s": 0.0,
            "solver_s": 0.0,
            "wall_s": time.perf_counter() - t0,
        }
    reason = failed_reason(
        {"termination_reason": s.termination_reason, "nonfinite_from_t_s": s.nonfinite_t}
    )
    return {
        "run_id": spec.run_id,
        "status": "failed" if reason else "done",
        "reason": reason,
        "has_data": True,
        "simulated_s": s.simulated_s,
        "solver_s": s.wall_s,
        "wall_s": time.perf_counter() - t0,
    }


def run_serial(specs, work: str, on_result) -> None:
    """Every run in this process, one after another."""
    for spec in specs:
        on_result(spec, run_one(spec, work))


#: seconds between a worker's checks that the sweep that started it still runs
PARENT_POLL_S = 0.5


def _worker_init(parent: int) -> None:
    # the parent decides what an interrupt does (it stops the workers). SIGINT was blocked
    # until now (_worker_start): one that came meanwhile is dropped here
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    # end without the collector's passes over numba's objects at shutdown (~0.3 s of each
    # worker's exit, which the sweep waits for); its runs are committed by then
    atexit.register(gc.freeze)
    import threading

    threading.Thread(
        target=_exit_with_parent, args=(parent,), daemon=True, name="r2rsim-parent-watch"
    ).start()


def _exit_with_parent(parent: int) -> None:
    """End this worker when the sweep process that started it is gone (kill -9, the OOM
    killer): a pool worker holds both ends of its task queue, so it would otherwise wait for
    tasks for ever. What the run was writing is a temporary that the next sweep into the
    directory removes."""
    while os.getppid() == parent:
        time.sleep(PARENT_POLL_S)
    os._exit(1)


@contextlib.contextmanager
def _one_thread_each():
    """Worker processes started inside use one BLAS/OpenMP thread each (N workers on N
    cores; the solver's linear algebra is small)."""
    keys = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS")
    saved = {k: os.environ.get(k) for k in keys}
    os.environ.update({k: "1" for k in keys})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _died(spec, attempts: dict) -> dict | None:
    """Count a worker death against a run; a record once it has died too often."""
    attempts[spec.run_id] = attempts.get(spec.run_id, 0) + 1
    if attempts[spec.run_id] < MAX_ATTEMPTS:
        return None
    return {
        "run_id": spec.run_id,
        "status": "failed",
        "has_data": False,
        "reason": f"the worker process running it died {MAX_ATTEMPTS} times (killed, or "
        f"out of memory?)",
        "simulated_s": 0.0,
        "solver_s": 0.0,
        "wall_s": 0.0,
    }


def _pool(workers: int):
    from concurrent.futures import ProcessPoolExecutor

    from ._worker_start import worker_context

    with _one_thread_each():
        return ProcessPoolExecutor(
            workers,
            mp_context=worker_context(),
            initializer=_worker_init,
            initargs=(os.getpid(),),
        )


def _workers_start() -> bool:
    """Whether a worker process starts and answers at all (a script without the
    ``__main__`` guard makes every one die as it starts)."""
    from concurrent.futures.process import BrokenProcessPool

    pool = _pool(1)
    try:
        pool.submit(os.getpid).result()
        return True
    except BrokenProcessPool:
        return False
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def run_processes(specs, work: str, on_result, workers: int, task=None, kinds: bytes = b"") -> None:
    """The runs on ``workers`` local processes (spawned, one BLAS thread each).

    When a worker dies (killed, out of memory), the pool breaks and every run in flight is
    lost, with no telling whose worker died. Those runs are then suspects: each runs again
    alone, so a death is charged to the run that caused it (``MAX_ATTEMPTS`` deaths and it
    is recorded as failed), never to the runs beside it. ``task`` stands in for
    :func:`run_one` (tests); ``kinds``: :func:`kinds_for_workers`.
    """
    from concurrent.futures import FIRST_COMPLETED, wait
    from concurrent.futures.process import BrokenProcessPool

    task = task or functools.partial(run_one, kinds=kinds)
    queue = list(reversed(specs))
    suspects: list = []  # in flight when a pool broke: each runs alone next
    attempts: dict[str, int] = {}
    while queue or suspects:
        alone = bool(suspects)
        pool = _pool(1 if alone else workers)
        pending = {pool.submit(task, suspects[-1], work): suspects.pop()} if alone else {}
        lost = []  # runs whose pool broke under them
        try:
            while pending or (queue and not alone):
                while not alone and queue and len(pending) < 2 * workers:
                    spec = queue.pop()
                    pending[pool.submit(task, spec, work)] = spec
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    spec = pending.pop(f)
                    try:
                        rec = f.result()
                    except BrokenProcessPool:
                        lost.append(spec)
                        continue
                    on_result(spec, rec)
                if lost:
                    lost += pending.values()
                    break
        except BaseException:
            _stop(pool)
            raise
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        if not alone:
            suspects.extend(reversed(lost))  # which of them died is not known: no charge
            continue
        if lost and not _workers_start():
            raise R2RError(
                "the worker processes die as they start. From a Python script, call "
                'run_sweep() under `if __name__ == "__main__":` (each worker process '
                "imports the script); --workers 0 runs the sweep in this process. The "
                "finished runs are kept"
            )
        for spec in lost:  # alone: its own worker died
            rec = _died(spec, attempts)
            if rec is None:
                suspects.append(spec)
            else:
                on_result(spec, rec)


def _stop(pool) -> None:
    """Terminate the pool's workers now (an interrupt, SIGTERM); what they were writing is
    left as temporaries that the next sweep into the directory removes."""
    for p in list(getattr(pool, "_processes", {}).values()):
        with contextlib.suppress(Exception):
            p.terminate()


def check_scheduler(scheduler: str) -> None:
    """Refuse ``--scheduler`` before anything is written: dask.distributed must be installed,
    and an address must answer.

    Raises
    ------
    InputError
    """
    _distributed()
    if scheduler != "local":
        _connect(scheduler).close()


def _distributed():
    """The dask.distributed module, or an InputError saying how to install it."""
    try:
        import distributed
    except ImportError:
        raise InputError(
            "--scheduler needs dask.distributed: pip install "
            "'dask[distributed]' (or pip install -e \".[dask]\" in the r2rsim "
            "checkout)"
        ) from None
    return distributed


def _connect(scheduler: str):
    """A client of the Dask scheduler at an address, or an InputError naming it."""
    try:
        return _distributed().Client(scheduler, timeout=CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as exc:
        raise InputError(
            f"--scheduler: cannot reach a Dask scheduler at '{scheduler}' "
            f"({type(exc).__name__}: {exc})"
        ) from None


def run_dask(specs, work: str, on_result, scheduler: str, workers: int, kinds: bytes = b"") -> None:
    """The runs on a Dask cluster: ``scheduler`` is an address (``tcp://host:8786``) or
    ``local`` to start a :class:`distributed.LocalCluster` of ``workers`` processes. The
    output directory must be on a file system every worker sees. ``kinds``:
    :func:`kinds_for_workers`."""
    import logging

    _distributed()
    from dask import config as dask_config
    from distributed import Client, LocalCluster, as_completed

    cluster = None
    environ = dict(os.environ)  # a LocalCluster's nannies change it: put back at the end
    try:
        if scheduler == "local":
            # without Dask's MALLOC_TRIM_THRESHOLD_=65536 for its workers: glibc then gives
            # freed memory back to the kernel at once, and every run takes ~16x the page
            # faults and ~35 % more time (a run's memory is flat; a value the user set in the
            # environment still reaches the workers)
            with (
                _one_thread_each(),
                dask_config.set(
                    {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}
                ),
            ):
                # the scheduler's HTTP server (metrics) starts even without a dashboard, on
                # port 8787 unless told otherwise: a free port instead, so that two sweeps
                # (or a user's own cluster) do not warn "Port 8787 is already in use"
                cluster = LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    dashboard_address=None,
                    silence_logs=logging.ERROR,
                    scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"},
                )
            client = Client(cluster)
        else:
            client = _connect(scheduler)
        try:
            _dask_loop(
                client,
                as_completed,
                specs,
                work,
                on_result,
                max(2 * workers, 2 * len(client.nthreads() or {0: 1})),
                kinds,
            )
        finally:
            client.close()
    finally:
        if cluster is not None:
            cluster.close()
        if scheduler == "local":
            _restore_environ(environ)


def _restore_environ(saved: dict) -> None:
    """Put ``os.environ`` back as it was. A LocalCluster's nannies set variables in this
    process before starting their workers (MALLOC_TRIM_THRESHOLD_, PYTHONHASHSEED,
    __DASK_PARENT_PID) and leave them: they would reach every process started later in the
    same session, a local sweep's workers included."""
    for k in [k for k in os.environ if k not in saved]:
        del os.environ[k]
    for k, v in saved.items():
        if os.environ.get(k) != v:
            os.environ[k] = v


#: seconds between checks that the Dask client still has its scheduler
DASK_POLL_S = 0.05


def _scheduler_lost(exc: BaseException) -> bool:
    """An exception of a run's future that says the scheduler went away, not the run."""
    import asyncio
    import concurrent.futures

    return isinstance(exc, (asyncio.CancelledError, concurrent.futures.CancelledError)) or type(
        exc
    ).__name__ in ("CommClosedError", "FutureCancelledError")


def _dask_loop(
    client, as_completed, specs, work, on_result, window: int, kinds: bytes = b""
) -> None:
    """At most ``window`` runs on the cluster at a time, their results as they come. A lost
    scheduler stops the sweep (it waited for ever; the runs in flight were recorded as
    failed), and the finished runs are kept; so does a :class:`WorkerSetupError`. ``kinds``:
    :func:`kinds_for_workers`."""
    queue = list(reversed(specs))
    pending: dict[str, RunSpec] = {}  # future key -> its run
    ac = as_completed()
    lost = R2RError(
        "the Dask scheduler went away; the finished runs are kept: run the same "
        "command again to continue"
    )

    def submit():
        while queue and len(pending) < window:
            spec = queue.pop()
            f = client.submit(run_one, spec, work, kinds, key=f"r2rsim-{spec.run_id}", pure=False)
            pending[f.key] = spec
            ac.add(f)

    submit()
    while pending:
        if not ac.has_ready():
            if client.status in ("closing", "closed"):  # it gave up reconnecting
                raise lost
            time.sleep(DASK_POLL_S)
            continue
        for f in ac.next_batch(block=False):
            spec = pending.pop(f.key)
            try:
                rec = f.result()
            except Exception as exc:  # noqa: BLE001 - KilledWorker and the like: recorded
                if _scheduler_lost(exc):
                    raise lost from None
                if isinstance(exc, WorkerSetupError):
                    raise exc from None
                env = environment_error(exc)
                if env is not None:  # a full or read-only disk: the sweep stops
                    raise env from None
                rec = {
                    "run_id": spec.run_id,
                    "status": "failed",
                    "has_data": False,
                    "reason": f"{type(exc).__name__}: {exc}",
                    "simulated_s": 0.0,
                    "solver_s": 0.0,
                    "wall_s": 0.0,
                }
            f.release()
            on_result(spec, rec)
        submit()
