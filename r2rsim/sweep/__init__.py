"""``r2rsim sweep``: many seeded runs of one base scenario as one dataset.

A sweep file names a base scenario and the axes along which its runs differ (docs/sweeps.md)::

    from r2rsim.sweep import run_sweep
    summary = run_sweep("sweeps/quickstart.yaml", output="runs/qs_sweep", workers=2)

Every combination is validated before anything runs; runs go to local worker processes (or
a Dask cluster); finished runs are kept and skipped when the sweep is run again.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from .. import limits
from ..dataset.paths import check_writable
from ..errors import InputError
from ._plan import RunSpec, SweepPlan, load_sweep, plan_sweep
from ._store import Outcome, SweepStore, write_failure

__all__ = ["RunSpec", "SweepPlan", "SweepSummary", "default_workers", "load_sweep",
           "plan_sweep", "run_sweep"]


def default_workers() -> int:
    """The cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


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
    failures: list[tuple[str, str]] = field(default_factory=list)
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
        state = (" (unfinished)" if not self.complete else
                 f" (incomplete: {n_failed} of {self.n_runs} runs failed)" if n_failed else "")
        lines = [f"dataset      {self.output}{state}",
                 f"runs         {self.n_runs}: {self.done} done, {self.failed} failed, "
                 f"{self.skipped} skipped (already done"
                 + (f", {self.skipped_failed} of them failed before" if self.skipped_failed
                    else "") + ")",
                 f"executor     {self.executor}",
                 f"simulated    {self.simulated_s:.1f} s of line time in {self.wall_s:.1f} s "
                 f"wall ({self.runs_per_minute:.1f} runs per minute)"]
        for rid, why in self.failures[:20]:
            lines.append(f"FAILED       {rid}: {why}")
        if len(self.failures) > 20:
            lines.append(f"  ... {len(self.failures) - 20} more (failures.parquet, "
                         f"runs.parquet termination_reason)")
        return "\n".join(lines)


def run_sweep(sweep_path: str | Path, output: str | Path | None = None, *,
              workers: int | None = None, scheduler: str | None = None,
              retry_failed: bool = False, overwrite: bool = False,
              progress=None) -> SweepSummary:
    """Run a sweep file into one dataset.

    Parameters
    ----------
    sweep_path : str or Path
    output : str or Path, optional
        The dataset directory (default: the sweep's ``output``, else ``runs/<name>``). A
        directory holding this sweep, finished or not, is continued.
    workers : int, optional
        Local worker processes (default: the number of cores); 0 runs in this process.
        With ``scheduler: local`` the workers of the LocalCluster.
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
    workers = default_workers() if workers is None else workers
    if workers < 0 or (scheduler is not None and workers < 1):
        raise InputError(f"--workers must be >= {1 if scheduler else 0}, got {workers}")
    if workers > limits.MAX_LOCAL_WORKERS and scheduler in (None, "local"):
        raise InputError(f"--workers {workers}: at most {limits.MAX_LOCAL_WORKERS} worker "
                         "processes on one machine (docs/security.md)")
    store = SweepStore(out, plan, overwrite)
    store.inspect()
    outcomes = store.outcomes(retry_failed)
    todo = [s for s in plan.runs if s.run_id not in outcomes]
    summary = SweepSummary(out, len(plan.runs), warnings=plan.warnings,
                           executor=_describe(workers, scheduler))
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
            outcomes[spec.run_id] = Outcome(rec["status"], "work" if rec["has_data"]
                                            else None, rec["reason"])
            summary.add(spec.run_id, rec)
            if progress:
                progress(summary.done + summary.failed, len(todo), rec)

        if not todo:
            summary.executor = "none (nothing to run" + (
                "; the changed sweep file applied)" if store.mode == "reopen" else ")")
        elif scheduler is not None:
            _execute.run_dask(todo, work, on_result, scheduler, min(workers, len(todo)))
        elif workers == 0:
            _execute.run_serial(todo, work, on_result)
        else:
            _execute.run_processes(todo, work, on_result, min(workers, len(todo)))
        store.finalise(outcomes)
        summary.complete = True
    finally:
        store.close()
        summary.wall_s = time.perf_counter() - t0
    return summary


def _describe(workers: int, scheduler: str | None) -> str:
    if scheduler == "local":
        return f"Dask LocalCluster, {workers} worker processes"
    if scheduler is not None:
        return f"Dask scheduler {scheduler}"
    return "this process (serial)" if workers == 0 else f"{workers} local worker processes"
