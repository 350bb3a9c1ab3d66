"""``r2rsim sweep``: many seeded runs of one base scenario as one dataset.

A sweep file names a base scenario and the axes along which its runs differ (docs/sweeps.md)::

    from r2rsim.sweep import run_sweep
    summary = run_sweep("sweeps/quickstart.yaml", output="runs/qs_sweep", workers=2)

Every combination is validated before anything runs; runs go to local worker processes (or
a Dask cluster); finished runs are kept and skipped when the sweep is run again.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from .. import limits
from ..dataset.paths import check_writable
from ..errors import InputError
from ..units import QuantityError, parse_quantity
from ._plan import RunSpec, SweepPlan, load_sweep, plan_sweep
from ._store import Outcome, SweepStore, write_failure

__all__ = [
    "RunSpec",
    "SweepPlan",
    "SweepSummary",
    "choose_workers",
    "default_workers",
    "load_sweep",
    "plan_sweep",
    "planned_seconds",
    "run_sweep",
]

#: simulated seconds of runs that pay for one more local worker process. A worker's start
#: (spawn, imports, loading numba's cached kernels) costs ~1.4-1.8 s of CPU, while the
#: shipped lines simulate 1 s in ~1-4 ms of CPU (~0.1 s per run on top): on 2 cores, 2
#: workers were slower than 1 for every sweep up to 2400 simulated s and no faster at 7200 s
#: (a shared machine, load 2-6); on an idle one the second worker's share of the runs
#: outweighs its start from ~4-5 s of serial CPU, ~1200-1500 simulated s of the heavier line
#: (docs/sweeps.md §6 has the measurements).
SIM_S_PER_WORKER = 2000.0


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def planned_seconds(specs) -> float:
    """The simulated seconds the runs ``specs`` are planned for (each run's ``duration``,
    with the sweep's overrides applied)."""
    total = 0.0
    for spec in specs:
        try:
            total += parse_quantity(spec.scenario_data.get("duration"), "time")
        except (QuantityError, TypeError, ValueError):  # validated: not expected
            total += SIM_S_PER_WORKER
    return total


def choose_workers(planned_s: float, n_runs: int, cores: int | None = None) -> int:
    """The default number of local worker processes: one per :data:`SIM_S_PER_WORKER`
    simulated seconds of planned runs (rounded up), at most one per core and per run, and
    at least one. ``--workers N`` overrides it.

    Parameters
    ----------
    planned_s : float
        Simulated seconds of the runs to do (:func:`planned_seconds`).
    n_runs : int
        How many runs there are to do.
    cores : int, optional
        The cores this process may use (default :func:`default_workers`).
    """
    cores = default_workers() if cores is None else cores
    want = math.ceil(planned_s / SIM_S_PER_WORKER) if planned_s > 0 else 1
    return max(1, min(cores, n_runs, want))


@dataclass
class SweepSummary:
    """What ``r2rsim sweep`` reports at the end."""

    output: Path
    n_runs: int
    done: int = 0
    failed: int = 0
    skipped: int = 0
    skipped_failed: int = 0
    simulated_s: float = 0.0
    solver_s: float = 0.0
    wall_s: float = 0.0
    #: the dataset is finalised: every run has an outcome (``ok`` says whether none failed)
    complete: bool = False
    failures: list[tuple[str, str | None]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    executor: str = ""

    def add(self, run_id: str, record: dict) -> None:
        """Count a run's result (a record of :func:`r2rsim.sweep._execute.run_one`)."""
        if record["status"] == "done":
            self.done += 1
        else:
            self.failed += 1
            self.failures.append((run_id, record["reason"]))
        self.simulated_s += record["simulated_s"]
        self.solver_s += record["solver_s"]

    @property
    def runs_per_minute(self) -> float:
        ran = self.done + self.failed
        return 60.0 * ran / self.wall_s if self.wall_s > 0 else 0.0

    @property
    def ok(self) -> bool:
        """Every run has data and none failed (``r2rsim sweep`` exits 1 otherwise)."""
        return self.complete and self.failed == 0 and self.skipped_failed == 0

    def format(self) -> str:
        n_failed = self.failed + self.skipped_failed
        state = (
            " (unfinished)"
            if not self.complete
            else f" (incomplete: {n_failed} of {self.n_runs} runs failed)"
            if n_failed
            else ""
        )
        lines = [
            f"dataset      {self.output}{state}",
            f"runs         {self.n_runs}: {self.done} done, {self.failed} failed, "
            f"{self.skipped} skipped (already done"
            + (f", {self.skipped_failed} of them failed before" if self.skipped_failed else "")
            + ")",
            f"executor     {self.executor}",
            f"simulated    {self.simulated_s:.1f} s of line time in {self.wall_s:.1f} s "
            f"wall ({self.runs_per_minute:.1f} runs per minute)",
        ]
        for rid, why in self.failures[:20]:
            lines.append(f"FAILED       {rid}: {why}")
        if len(self.failures) > 20:
            lines.append(
                f"  ... {len(self.failures) - 20} more (failures.parquet, "
                f"runs.parquet termination_reason)"
            )
        return "\n".join(lines)


def run_sweep(
    sweep_path: str | Path,
    output: str | Path | None = None,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    retry_failed: bool = False,
    overwrite: bool = False,
    progress=None,
) -> SweepSummary:
    """Run a sweep file into one dataset.

    Parameters
    ----------
    sweep_path : str or Path
    output : str or Path, optional
        The dataset directory (default: the sweep's ``output``, else ``runs/<name>``). A
        directory holding this sweep, finished or not, is continued.
    workers : int, optional
        Local worker processes (default: by the work, :func:`choose_workers`: one per 2000
        simulated seconds of runs to do, at most one per core); 0 runs in this process.
        With ``scheduler: local`` the workers of the LocalCluster (default: one per core).
    scheduler : str, optional
        A Dask scheduler address, or ``local`` to start a LocalCluster.
    retry_failed : bool
        Run again the runs that failed before (kept as failed otherwise).
    overwrite : bool
        Replace a finished r2rsim dataset at the output (another sweep's, a run's, or this
        sweep's to start again).
    progress : callable, optional
        ``progress(n_finished, n_to_run, record)`` after every run (record None at start).

    Returns
    -------
    SweepSummary

    Raises
    ------
    InputError
        For a bad sweep file, invalid combinations (all listed) or an output directory that
        may not be used (under a file, read-only, not writable); nothing is written then.
    OSError
        When the machine fails the sweep (no space left, a disk turned read-only, an I/O
        error; :func:`r2rsim.sweep._execute.environment_error`), in this process or in a
        worker: the sweep stops, its finished runs are kept, and calling it again with the
        same arguments continues it. A run's own failure (the solver, its physics) does not
        raise: it is recorded, and the sweep goes on.
    """
    from . import _execute

    t0 = time.perf_counter()
    plan = plan_sweep(sweep_path)
    out = Path(output) if output is not None else plan.default_output
    chosen = workers is None and scheduler is None  # by the work, once it is known
    workers = default_workers() if workers is None else workers
    if workers < 0 or (scheduler is not None and workers < 1):
        raise InputError(f"--workers must be >= {1 if scheduler else 0}, got {workers}")
    if workers > limits.MAX_LOCAL_WORKERS and scheduler in (None, "local"):
        raise InputError(
            f"--workers {workers}: at most {limits.MAX_LOCAL_WORKERS} worker "
            "processes on one machine (docs/security.md)"
        )
    store = SweepStore(out, plan, overwrite)
    store.inspect()
    outcomes = store.outcomes(retry_failed)
    todo = [s for s in plan.runs if s.run_id not in outcomes]
    planned = planned_seconds(todo) if chosen else None
    if planned is not None:  # chosen
        workers = choose_workers(planned, len(todo), workers)
    summary = SweepSummary(
        out, len(plan.runs), warnings=plan.warnings, executor=_describe(workers, scheduler, planned)
    )
    summary.skipped = len(outcomes)
    summary.skipped_failed = sum(o.status == "failed" for o in outcomes.values())
    summary.failures = [(k, o.reason) for k, o in outcomes.items() if o.status == "failed"]
    if not todo and store.mode == "reopen" and store.up_to_date():  # nothing is written
        summary.complete = True
        summary.executor = "none (nothing to run)"
        summary.wall_s = time.perf_counter() - t0
        return summary
    check_writable(out, inside_out=True)  # a full or read-only disk: before any work
    if scheduler is not None and todo:
        _execute.check_scheduler(scheduler)  # before anything is written
    # the element kinds registered here, for the workers (refused now if they cannot go)
    in_workers = bool(todo) and (scheduler is not None or workers > 0)
    kinds = _execute.kinds_for_workers() if in_workers else b""
    store.begin()
    try:
        for spec in todo:
            store.clear(spec.run_id)
        work = str(store.work.resolve())
        if progress:
            progress(0, len(todo), None)

        def on_result(spec, rec):
            if rec["status"] == "failed" and not rec["has_data"]:
                write_failure(store.work, spec, rec["reason"])  # the worker died
            outcomes[spec.run_id] = Outcome(
                rec["status"], "work" if rec["has_data"] else None, rec["reason"]
            )
            summary.add(spec.run_id, rec)
            if progress:
                progress(summary.done + summary.failed, len(todo), rec)

        if not todo:
            summary.executor = "none (nothing to run" + (
                "; the changed sweep file applied)" if store.mode == "reopen" else ")"
            )
        elif scheduler is not None:
            _execute.run_dask(
                todo, work, on_result, scheduler, min(workers, len(todo)), kinds=kinds
            )
        elif workers == 0:
            _execute.run_serial(todo, work, on_result)
        else:
            _execute.run_processes(todo, work, on_result, min(workers, len(todo)), kinds=kinds)
        store.finalise(outcomes)
        summary.complete = True
    finally:
        store.close()
        summary.wall_s = time.perf_counter() - t0
    return summary


def _describe(workers: int, scheduler: str | None, planned_s: float | None = None) -> str:
    """The executor line of the summary; ``planned_s``: the workers were chosen by the
    work (:func:`choose_workers`), which it says."""
    if scheduler == "local":
        return f"Dask LocalCluster, {workers} worker processes"
    if scheduler is not None:
        return f"Dask scheduler {scheduler}"
    if workers == 0:
        return "this process (serial)"
    text = f"{workers} local worker process{'es' if workers != 1 else ''}"
    return text if planned_s is None else f"{text} (the default for {planned_s:.3g} s of runs)"
