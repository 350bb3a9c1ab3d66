"""End-to-end throughput of the calibrated thesis set's sweeps, and where the CPU time goes.

A fixed subset of the calibrated set (docs/dataset.md §8.2) is run through the public sweep
API, :func:`r2rsim.sweep.run_sweep`, with one worker: ``workers=0``, i.e. the runs one after
another in this process, so that ``time.process_time`` covers all of the work and numba's
kernels are loaded once, by an untimed warm-up sweep (one 70 s run) before the timed ones.
The subset:

* the first ``--runs`` runs of scenarios/thesis_realistic/faults.yaml (combination by
  combination, 5 seeds each, so rounded up to whole combinations): 300 s at 100 Hz each;
* the first ``--healthy`` seeds of the first combination (OC1) of
  scenarios/thesis_realistic/healthy.yaml.

Each is written as a sweep file of its own (the original's axes cut to the first
combinations, its ``scenario:`` an absolute path) and run into a temporary directory,
finalisation included. Printed: runs, simulated seconds, CPU seconds of this process
(time.process_time) and wall seconds, CPU s per simulated s, and the speed as × real time
per core (simulated s / CPU s) against the target of 1000 × real time per core (PASS/FAIL,
informative only).

Then the same subset (``--profile-runs`` runs of faults.yaml, ``--healthy`` of healthy.yaml)
runs again, into other directories, under a phase profiler, and the CPU time is split by
phase. The profiler (``sys.setprofile``) sees every Python function call and numba
dispatcher call; a function whose module and name mark a phase (:data:`PHASES`) starts that
phase until it returns, and the innermost marked function wins: ``write_chunk`` called from
the solver's output callback counts as writing, not as the solver. Some phases are
containers (:data:`CONTAINERS`): what they call is theirs (the labels derived again by a
validation count as validation, the Parquet files the sweep's merge writes as the merge).
Time outside every marked function is ``rest`` (the run's sink, the sweep's loop, the
garbage collector). The profiler's own cost lands in the phases with many Python calls:
it is estimated (CPU per hook event, measured on a loop of small calls before the sweep,
times the events counted in each phase) and taken out of each phase. The split is printed
as CPU seconds of the profiled run and as shares of it, next to the profiled run's total;
the headline figures come from the run without the profiler. When the output evaluation
moves inside the compiled integrator, its functions are no longer called and it
counts as the solver; a renamed function leaves its phase at 0 s, never an error.

Usage::

    python benchmarks/bench_throughput.py                   # 40 + 4 runs, ~40 s + ~15 s split
    python benchmarks/bench_throughput.py --runs 10 --profile-runs 5   # quicker
    python benchmarks/bench_throughput.py --no-profile      # the headline figures only

The machines are shared and noisy: compare figures within one run. Not a timed test.
"""

from __future__ import annotations

import os

# Pin BLAS/OpenMP/numba threads before numpy is imported (the sweep's workers do the same).
for _var in (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "NUMBA_NUM_THREADS",
):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import yaml  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SET = REPO / "scenarios" / "thesis_realistic"
TARGET_X_REAL_TIME = 1000.0

#: (phase, module path suffix or directory, function names (``co_name`` or ``co_qualname``)
#: or None for all of the module's). The first rule that matches a function names its phase.
PHASES: list[tuple[str, str, tuple[str, ...] | None]] = [
    ("validation", "r2rsim/dataset/validate.py", ("validate_dataset",)),
    ("solver integration", "r2rsim/solve/radau.py", ("integrate",)),
    ("solver integration", "r2rsim/solve/backends/", None),
    ("solver loop (simulate.py: events, samples)", "r2rsim/solve/simulate.py", None),
    ("output evaluation", "r2rsim/compile/compiler.py", ("outputs",)),
    ("output evaluation", "r2rsim/compile/kernels.py", ("rows",)),
    ("measurement model", "r2rsim/measure/", None),
    ("labels", "r2rsim/dataset/labels.py", ("derive_labels",)),
    (
        "run tables, validation, commit",
        "r2rsim/dataset/writer.py",
        (
            "DatasetWriter.__init__",
            "DatasetWriter.write_table",
            "DatasetWriter.write_text",
            "DatasetWriter.commit",
            "DatasetWriter._restore",
            "DatasetWriter.abort",
            "check_output",
            "_signals_deferred",
        ),
    ),
    # the rest of the writer: write_chunk, the row groups (commit writes the last one)
    ("Arrow/Parquet writing", "r2rsim/dataset/writer.py", None),
    ("run tables, validation, commit", "r2rsim/dataset/tables.py", None),
    ("run tables, validation, commit", "r2rsim/run.py", ("_runs_table",)),
    ("sweep merge/store", "r2rsim/sweep/_store.py", None),
    ("sweep planning", "r2rsim/sweep/_plan.py", ("plan_sweep",)),
    ("run setup (scenario, compile, initial state)", "r2rsim/run.py", ("_prepare",)),
    ("run setup (scenario, compile, initial state)", "r2rsim/schema/loader.py", None),
    # the run's own loop and sink: back to "rest" when they are called from inside a phase
    ("rest", "r2rsim/run.py", ("execute", "on_chunk", "_flush", "close")),
]
#: phases that keep everything they call
CONTAINERS = frozenset(
    {
        "validation",
        "sweep merge/store",
        "sweep planning",
        "run setup (scenario, compile, initial state)",
    }
)
ORDER = [
    "solver integration",
    "solver loop (simulate.py: events, samples)",
    "output evaluation",
    "measurement model",
    "labels",
    "Arrow/Parquet writing",
    "run tables, validation, commit",
    "validation",
    "sweep merge/store",
    "sweep planning",
    "run setup (scenario, compile, initial state)",
    "rest",
]


def _phase_of(code) -> str | None:
    """The phase a function's code object marks, or None."""
    path = code.co_filename.replace(os.sep, "/")
    for phase, where, names in PHASES:
        in_module = path.endswith(where) if where.endswith(".py") else f"/{where}" in path
        if in_module and (
            names is None or code.co_name in names or getattr(code, "co_qualname", "") in names
        ):
            return phase
    return None


class PhaseProfiler:
    """CPU time (time.process_time) by phase: see the module docstring.

    The hook's own cost is charged to the phase it runs in; :attr:`seconds` has it taken
    out again, estimated as the events counted in each phase times the cost of one event
    (:meth:`calibrate`); :attr:`raw_seconds` keeps the figures as measured.
    """

    def __init__(self):
        self.raw_seconds = dict.fromkeys(ORDER, 0.0)
        self.events = dict.fromkeys(ORDER, 0)
        self.per_event_s = 0.0
        self._stack: list[tuple[object, str]] = []  # (frame, phase) of marked calls
        self._codes: dict = {}
        self._last = 0.0
        self._count = 0  # events since the last change of phase

    def _charge(self) -> None:
        now = time.process_time()
        phase = self._stack[-1][1] if self._stack else "rest"
        self.raw_seconds[phase] += now - self._last
        self.events[phase] += self._count
        self._last, self._count = now, 0

    def _hook(self, frame, event, arg) -> None:
        self._count += 1
        if event == "call":
            code = frame.f_code
            phase = self._codes.get(code, False)
            if phase is False:
                phase = self._codes[code] = _phase_of(code)
            if phase is None:
                return
            if self._stack and self._stack[-1][1] in CONTAINERS:
                return
            self._charge()
            self._stack.append((frame, phase))
        elif event == "return" and self._stack and self._stack[-1][0] is frame:
            self._charge()
            self._stack.pop()

    def calibrate(self, n: int = 200_000) -> float:
        """CPU seconds the hook adds per event: a loop of ``n`` calls of a small Python
        function that calls a builtin (four events each), with and without the hook, the
        best of three."""

        def small():
            return len(())

        def loop():
            for _ in range(n):
                small()

        def cpu(hooked: bool) -> float:
            t0 = time.process_time()
            if hooked:
                sys.setprofile(self._hook)
            loop()
            sys.setprofile(None)
            return time.process_time() - t0

        extra = min(cpu(True) for _ in range(3)) - min(cpu(False) for _ in range(3))
        self.raw_seconds = dict.fromkeys(ORDER, 0.0)
        self.events = dict.fromkeys(ORDER, 0)
        self.per_event_s = max(extra, 0.0) / (4 * n)
        return self.per_event_s

    @property
    def seconds(self) -> dict[str, float]:
        """CPU seconds by phase, the hook's estimated cost taken out."""
        return {
            p: max(s - self.events[p] * self.per_event_s, 0.0) for p, s in self.raw_seconds.items()
        }

    def __enter__(self) -> PhaseProfiler:
        self._stack, self._count = [], 0
        self._last = time.process_time()
        sys.setprofile(self._hook)
        return self

    def __exit__(self, *exc) -> None:
        sys.setprofile(None)
        self._charge()


def _sweep_file(
    src: Path, combos: int, out: Path, seeds=None, set_extra: dict | None = None
) -> Path:
    """A copy of the sweep file ``src`` with its axes cut to the first ``combos`` values."""
    data = yaml.safe_load(src.read_text(encoding="utf-8"))
    data["scenario"] = str((src.parent / data["scenario"]).resolve())
    data["name"] = f"{data['name']}_first{combos}"
    for axis in data.get("axes", []):
        if "values" in axis:
            axis["values"] = axis["values"][:combos]
    if seeds is not None:
        data["seeds"] = seeds
    if set_extra:
        data.setdefault("set", {}).update(set_extra)
    out.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return out


def _subset(tmp: Path, tag: str, runs: int, healthy: int) -> list[Path]:
    """The subset's sweep files: the first ``runs`` runs of faults.yaml (whole
    combinations) and ``healthy`` seeds of healthy.yaml's first combination."""
    faults = yaml.safe_load((SET / "faults.yaml").read_text(encoding="utf-8"))
    per_combo = len(faults["seeds"]) if isinstance(faults["seeds"], list) else faults["seeds"]
    files = []
    if runs > 0:
        combos = math.ceil(runs / per_combo)
        files.append(_sweep_file(SET / "faults.yaml", combos, tmp / f"faults_{tag}.yaml"))
    if healthy > 0:
        files.append(
            _sweep_file(SET / "healthy.yaml", 1, tmp / f"healthy_{tag}.yaml", seeds=healthy)
        )
    return files


def _run(files: list[Path], tmp: Path, tag: str) -> dict:
    """Run the sweep files one after another (workers=0); totals."""
    from r2rsim.sweep import run_sweep

    total = {"runs": 0, "failed": 0, "simulated_s": 0.0}
    for f in files:
        s = run_sweep(f, tmp / f"{f.stem}_{tag}_out", workers=0)
        if not s.complete:
            raise SystemExit(f"{f.name}: the sweep did not finish")
        total["runs"] += s.done + s.failed
        total["failed"] += s.failed
        total["simulated_s"] += s.simulated_s
    return total


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", type=int, default=40, help="runs of faults.yaml (default 40)")
    ap.add_argument("--healthy", type=int, default=4, help="runs of healthy.yaml (default 4)")
    ap.add_argument(
        "--profile-runs",
        type=int,
        default=10,
        help="runs of faults.yaml in the profiled sweep (default 10)",
    )
    ap.add_argument("--no-profile", action="store_true", help="skip the split by phase")
    args = ap.parse_args(argv)
    warnings.filterwarnings("ignore")  # the calibrated set's plausibility notes

    from r2rsim.solve.compilewatch import compile_seconds

    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        t0 = time.perf_counter()
        warm = _sweep_file(
            SET / "faults.yaml", 1, tmp / "warm.yaml", seeds=[1], set_extra={"duration": "70 s"}
        )
        _run([warm], tmp, "warm")
        print(f"warm-up (numba kernels loaded or compiled): {time.perf_counter() - t0:.1f} s wall")

        files = _subset(tmp, "timed", args.runs, args.healthy)
        c0 = compile_seconds()
        cpu0, wall0 = time.process_time(), time.perf_counter()
        tot = _run(files, tmp, "timed")
        cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
        compiled = compile_seconds() - c0
        sim = tot["simulated_s"]
        x_rt = sim / cpu if cpu > 0 else math.inf
        print(
            f"\nsubset: {', '.join(f.name for f in files)} ({tot['runs']} runs, "
            f"{tot['failed']} failed), one worker (this process, warm)"
        )
        print(f"  runs                      {tot['runs']}")
        print(f"  simulated                 {sim:.0f} s")
        print(
            f"  CPU (this process)        {cpu:.2f} s   ({cpu / max(tot['runs'], 1):.3f} s per run)"
        )
        print(f"  wall                      {wall:.2f} s")
        print(f"  CPU s per simulated s     {cpu / sim:.2e}" if sim else "")
        verdict = "PASS" if x_rt >= TARGET_X_REAL_TIME else "FAIL"
        print(
            f"  x real time per core      {x_rt:.0f}   target {TARGET_X_REAL_TIME:.0f}: "
            f"{verdict} (informative)"
        )
        if compiled > 0.1:
            print(
                f"  WARNING: numba compiled for {compiled:.1f} s during the timed sweeps "
                "(a stale cache?): run again"
            )
        if args.no_profile:
            return 0

        files = _subset(tmp, "profiled", args.profile_runs, args.healthy)
        prof = PhaseProfiler()
        per_event = prof.calibrate()
        cpu0 = time.process_time()
        with prof:
            ptot = _run(files, tmp, "profiled")
        pcpu = time.process_time() - cpu0
        n_events = sum(prof.events.values())
        print(
            f"\nsplit of CPU by phase: a second sweep of the subset ({ptot['runs']} runs, "
            f"{', '.join(f.name for f in files)}) under the phase profiler, "
            f"{pcpu:.2f} s CPU ({pcpu / max(ptot['runs'], 1):.3f} s per run with the "
            f"profiler; {cpu / max(tot['runs'], 1):.3f} s without). The profiler's own "
            f"cost taken out: {n_events} events x {1e9 * per_event:.0f} ns = "
            f"{n_events * per_event:.2f} s"
        )
        print(f"  {'phase':<46} {'CPU s':>8} {'share':>7} {'per run ms':>11}")
        shown = prof.seconds
        total = sum(shown.values())
        # validate_dataset is a phase of its own only to be a container (the commit is
        # not one: it writes the last row group); it is shown inside its group
        shown["run tables, validation, commit"] += shown["validation"]
        for phase in ORDER:
            s = shown[phase]
            label = "  of which validate_dataset" if phase == "validation" else phase
            print(
                f"  {label:<46} {s:8.3f} {100 * s / total:6.1f}% "
                f"{1e3 * s / max(ptot['runs'], 1):11.1f}"
            )
        solver = ("solver integration", "solver loop (simulate.py: events, samples)")
        outside = total - sum(shown[p] for p in (*solver, "output evaluation"))
        print(
            f"  {'outside the solver and output evaluation':<46} {outside:8.3f} "
            f"{100 * outside / total:6.1f}% {1e3 * outside / max(ptot['runs'], 1):11.1f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
