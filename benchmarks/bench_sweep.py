"""Throughput, overhead and parent memory of ``r2rsim sweep`` (run_sweep), in one run.

Three measurements on sweeps of the quick-start line (scenarios/quickstart.yaml, a
``set: {duration: ...}`` and ``seeds: N``, written to a temporary directory):

1. Scaling: one sweep of ``--runs`` runs of ``--duration`` s of line time (about 0.5-1 s of
   solver time each), run serially in this process (workers=0), on 1 and on 2 local worker
   processes, and on a 2-worker Dask LocalCluster (scheduler='local'), each into a fresh
   output directory; ``--repeat`` rounds, executors interleaved, median wall time. Prints
   wall time, runs per minute, speed-up against 1 worker and scaling efficiency (speed-up /
   workers), and where the wall time goes (solver, rest of each run in the worker, worker
   start-up, finalisation).
2. Overhead of a 60 s quick-start run: ``--overhead-runs`` runs of 60 s, serially and on 1
   and 2 worker processes. Overhead = (wall per run - solver time per run) / wall per run,
   with wall per run = wall x workers / runs for the pools. ``solver`` is the runs' own
   simulation wall time (SweepSummary.solver_s: simulate() with its chunk callback, which
   measures, labels and writes the samples; numba compilation excluded).
3. Parent memory: peak RSS (VmHWM; ru_maxrss where there is no /proc) of a fresh process
   that runs a sweep of 50 and one of 200 short runs on 2 worker processes (the workers
   are other processes and not counted), with its RSS before the sweep.

Bars (PASS/FAIL): 2 workers >= 1.7 x one worker; serial overhead of a 60 s run <= 20 %;
parent peak RSS at 200 runs within 10 % (or 5 MiB) of that at 50 runs.

Usage::

    python benchmarks/bench_sweep.py            # full, 3 rounds (~4.5 min on 2 cores)
    python benchmarks/bench_sweep.py --quick    # one round, smaller sweeps (~1 min)
    python benchmarks/bench_sweep.py --profile  # + where a serial 60 s run's time goes
    python benchmarks/bench_sweep.py --strict   # exit 1 when a bar fails

Every sweep has fixed costs that do not parallelise (planning; per worker process about
1-1.5 s of start-up: spawn, imports, numba cache load; pool shutdown and finalisation), so
the scaling sweep must be long enough for the speed-up to mean something: 24 x 900 s
(about 0.8 s of work per run) by default, 10 x 1200 s with --quick (fewer, longer runs).
The script prints the best speed-up the measured fixed costs allow on the sweep.

Serial runs come after an untimed warm-up in this process (numba cache load); worker
start-up (spawn, imports, numba cache load per worker) is part of the pools' wall time.
A warning is printed when numba's cache is rewritten during a measurement (something
compiled: a stale cache, or two numba versions sharing the source tree's __pycache__); give
r2rsim a cache of its own with NUMBA_CACHE_DIR then. The machines are shared and noisy:
compare results within one run. Not a timed test.
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
import json  # noqa: E402
import resource  # noqa: E402
import shutil  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
BASE = REPO / "scenarios" / "quickstart.yaml"

SPEEDUP_BAR = 1.7
OVERHEAD_BAR = 0.20
RSS_RATIO_BAR = 1.10
RSS_ABS_BAR_MIB = 5.0

# executor label -> (workers, scheduler)
EXECUTORS = {
    "serial (in-process)": (0, None),
    "1 worker process": (1, None),
    "2 worker processes": (2, None),
    "Dask LocalCluster, 2": (2, "local"),
}


def write_sweep(folder: Path, name: str, duration: float, runs: int) -> Path:
    """A sweep of ``runs`` seeds of the quick-start scenario at ``duration`` s."""
    path = folder / f"{name}.yaml"
    path.write_text(
        f"name: {name}\n"
        f"scenario: {json.dumps(str(BASE))}\n"
        f"set: {{duration: {duration:g} s}}\n"
        f"seeds: {runs}\n",
        encoding="utf-8",
    )
    return path


def _status_kib(key: str) -> float | None:
    """A size from /proc/self/status (Linux), KiB."""
    try:
        with open("/proc/self/status", encoding="ascii") as f:
            for ln in f:
                if ln.startswith(key + ":"):
                    return float(ln.split()[1])
    except OSError:
        pass
    return None


def _rss_kib() -> float:
    return _status_kib("VmRSS") or float("nan")


def _peak_rss_kib() -> float:
    """This process's peak RSS. VmHWM, not ru_maxrss: Linux keeps ru_maxrss across exec, so
    a process started by a large one (this benchmark) would report its parent's size."""
    hwm = _status_kib("VmHWM")
    if hwm is not None:
        return hwm
    scale = 1 if sys.platform != "darwin" else 1 / 1024  # ru_maxrss: KiB on Linux
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * scale


def _cpu_s() -> float:
    """CPU seconds of this process and of its children that have been waited for."""
    a = resource.getrusage(resource.RUSAGE_SELF)
    b = resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def _numba_index_stamps() -> dict:
    """The numba cache index files of r2rsim's kernels and their mtimes."""
    import r2rsim

    roots = [Path(r2rsim.__file__).parent]
    if os.environ.get("NUMBA_CACHE_DIR"):
        roots.append(Path(os.environ["NUMBA_CACHE_DIR"]))
    out = {}
    for root in roots:
        for p in root.rglob("*.nbi"):
            try:
                out[str(p)] = p.stat().st_mtime_ns
            except OSError:
                pass
    return out


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def run_once(sweep: Path, out: Path, workers: int, scheduler: str | None) -> dict:
    """Run ``sweep`` into the fresh directory ``out``; the summary and timings."""
    from r2rsim.sweep import run_sweep

    if out.exists():
        shutil.rmtree(out)
    arrivals: list[tuple[float, dict]] = []

    def progress(n, total, rec):
        if rec is not None:
            arrivals.append((time.perf_counter(), rec))

    stamps = _numba_index_stamps()
    environ = dict(os.environ)
    cpu0 = _cpu_s()
    t0 = time.perf_counter()
    s = run_sweep(sweep, out, workers=workers, scheduler=scheduler, progress=progress)
    t1 = time.perf_counter()
    cpu = _cpu_s() - cpu0  # this process + its reaped children (the pool's workers)
    shutil.rmtree(out, ignore_errors=True)
    changed = sorted(k for k in {*environ, *os.environ} if environ.get(k) != os.environ.get(k))
    if changed:  # would reach the next executor's workers: measure each one as it is
        print(
            f"  warning: the sweep ({workers=}, {scheduler=}) left os.environ changed: "
            f"{', '.join(f'{k}={os.environ.get(k)}' for k in changed)}; put back",
            flush=True,
        )
        os.environ.clear()
        os.environ.update(environ)
    if _numba_index_stamps() != stamps:
        print(
            f"  warning: numba's cache was rewritten during this sweep ({workers=}, "
            f"{scheduler=}): something compiled (a stale cache, or another numba "
            f"version sharing it; NUMBA_CACHE_DIR gives r2rsim its own)",
            flush=True,
        )
    ran = s.done + s.failed
    if s.failed or not s.complete:
        raise SystemExit(
            f"sweep {sweep.name} ({workers=}, {scheduler=}) did not finish "
            f"cleanly: {s.done} done, {s.failed} failed: {s.failures[:3]}"
        )
    typical = statistics.median(r["wall_s"] for _, r in arrivals)
    return {
        "runs": ran,
        "wall": s.wall_s,
        "solver": s.solver_s,
        "cpu": cpu,
        "worker_run": sum(r["wall_s"] for _, r in arrivals),
        # the first result's arrival less a typical run: planning, process / cluster
        # start-up, imports and the numba cache load of the first run
        "startup": arrivals[0][0] - t0 - typical,
        # after the last result: pool shutdown and finalisation
        "tail": t1 - arrivals[-1][0],
        "workers": max(workers, 1),
    }


def median_of(results: list[dict]) -> dict:
    """The round with the median wall time (its other figures stay consistent)."""
    ordered = sorted(results, key=lambda r: r["wall"])
    return ordered[(len(ordered) - 1) // 2]


def overhead(r: dict) -> float:
    per_run_wall = r["wall"] * r["workers"] / r["runs"]
    return (per_run_wall - r["solver"] / r["runs"]) / per_run_wall


def scaling(folder: Path, runs: int, duration: float, repeat: int, dask: bool) -> dict[str, dict]:
    sweep = write_sweep(folder, "bench_scaling", duration, runs)
    labels = [k for k in EXECUTORS if dask or EXECUTORS[k][1] is None]
    results: dict[str, list[dict]] = {k: [] for k in labels}
    for i in range(repeat):
        order = labels[i % len(labels) :] + labels[: i % len(labels)]  # spread the noise
        for label in order:
            workers, scheduler = EXECUTORS[label]
            r = run_once(sweep, folder / "out", workers, scheduler)
            results[label].append(r)
            print(f"  round {i + 1}/{repeat} {label:<22} {r['wall']:7.2f} s wall", flush=True)
    return {k: median_of(v) for k, v in results.items()}


def print_scaling(res: dict[str, dict], duration: float) -> float | None:
    one = res["1 worker process"]["wall"]
    print(
        f"\nScaling: quick-start line, {duration:g} s of line time per run "
        f"(median wall of the rounds)"
    )
    hdr = (
        f"{'executor':<22} {'runs':>5} {'wall s':>8} {'runs/min':>9} {'solver s/run':>13} "
        f"{'overhead':>9} {'speed-up':>9} {'efficiency':>11}"
    )
    print(hdr)
    print("-" * len(hdr))
    for label, r in res.items():
        sp = one / r["wall"]
        print(
            f"{label:<22} {r['runs']:>5} {r['wall']:>8.2f} {60 * r['runs'] / r['wall']:>9.1f} "
            f"{r['solver'] / r['runs']:>13.3f} {overhead(r):>8.1%} {sp:>8.2f}x "
            f"{sp / r['workers']:>10.0%}"
        )
    print(
        "\nWhere the wall time goes, s (capacity = wall x workers; solver = the runs' "
        "simulate(); in-run = the rest of each run in its worker: scenario build, "
        "compile_line, steady state, tables, commit with checksums and self-validation; "
        "start-up = first result less a typical run: plan, process start, imports, numba "
        "cache load; tail = after the last result: pool shutdown, finalisation; "
        "CPU = this process + its workers)"
    )
    hdr2 = (
        f"{'executor':<22} {'capacity':>9} {'solver':>8} {'in-run':>8} {'start-up':>9} "
        f"{'tail':>6} {'CPU':>8} {'cores busy':>11}"
    )
    print(hdr2)
    print("-" * len(hdr2))
    for label, r in res.items():
        cap = r["wall"] * r["workers"]
        print(
            f"{label:<22} {cap:>9.2f} {r['solver']:>8.2f} "
            f"{r['worker_run'] - r['solver']:>8.2f} {r['startup']:>9.2f} {r['tail']:>6.2f} "
            f"{r['cpu']:>8.2f} {r['cpu'] / r['wall']:>11.2f}"
        )
    r1, r2 = res["1 worker process"], res.get("2 worker processes")
    if r2:
        f1, f2 = r1["startup"] + r1["tail"], r2["startup"] + r2["tail"]
        print(
            f"fixed costs per sweep (start-up + tail): 1 worker {f1:.2f} s, 2 workers "
            f"{f2:.2f} s; with them, 2 workers can be at most "
            f"{r1['wall'] / (f2 + (r1['wall'] - f1) / 2):.2f}x one worker on this sweep"
        )
    for label, r in res.items():
        if r["workers"] > 1 and r["cpu"] / r["wall"] < 0.8 * r["workers"]:
            print(
                f"note: {label} kept only {r['cpu'] / r['wall']:.2f} of {r['workers']} cores "
                f"busy: other processes had the rest (see the load), so its speed-up "
                f"understates the executor; run again on a quiet machine"
            )
    two = res.get("2 worker processes")
    return one / two["wall"] if two else None


def overhead_table(folder: Path, runs: int, repeat: int) -> float:
    sweep = write_sweep(folder, "bench_overhead", 60.0, runs)
    labels = ["serial (in-process)", "1 worker process", "2 worker processes"]
    results: dict[str, list[dict]] = {k: [] for k in labels}
    for i in range(repeat):
        for label in labels[i % 3 :] + labels[: i % 3]:
            workers, scheduler = EXECUTORS[label]
            results[label].append(run_once(sweep, folder / "out", workers, scheduler))
    print(
        f"\nOverhead per 60 s quick-start run ({runs} runs, median wall of {repeat} "
        f"round(s), load {_load()}; overhead = (wall per run - solver per run) / wall per "
        f"run; pools: wall per run = wall x workers / runs)"
    )
    hdr = (
        f"{'executor':<22} {'runs':>5} {'wall s':>8} {'wall/run s':>11} {'solver/run s':>13} "
        f"{'in-run/run s':>13} {'CPU/run s':>10} {'overhead':>9}"
    )
    print(hdr)
    print("-" * len(hdr))
    for label in labels:
        r = median_of(results[label])
        n = r["runs"]
        print(
            f"{label:<22} {n:>5} {r['wall']:>8.2f} {r['wall'] * r['workers'] / n:>11.3f} "
            f"{r['solver'] / n:>13.3f} {(r['worker_run'] - r['solver']) / n:>13.3f} "
            f"{r['cpu'] / n:>10.3f} {overhead(r):>8.1%}",
            flush=True,
        )
    return overhead(median_of(results["serial (in-process)"]))


# (module, attribute, label) of what --profile times; nested labels are indented
_PROFILED = [
    ("r2rsim.sweep", "plan_sweep", "parent: plan_sweep"),
    ("r2rsim.sweep._store", "SweepStore.finalise", "parent: finalise"),
    ("r2rsim.sweep._execute", "run_one", "run_one (worker)"),
    ("r2rsim.schema.loader", "build_scenario", "  build_scenario"),
    ("r2rsim.run", "execute", "  execute"),
    ("r2rsim.run", "compile_line", "    compile_line"),
    ("r2rsim.run", "steady_state", "    steady_state"),
    ("r2rsim.dataset.writer", "DatasetWriter.__init__", "    DatasetWriter()"),
    ("r2rsim.run", "simulate", "    simulate (solver_s)"),
    ("r2rsim.measure.sensors", "MeasurementModel.measure", "      measurement model"),
    ("r2rsim.run", "derive_labels", "      labels"),
    ("r2rsim.dataset.writer", "DatasetWriter.write_chunk", "      write_chunk (to Arrow)"),
    ("r2rsim.dataset.writer", "DatasetWriter.write_table", "    write_table (runs, channels, ...)"),
    ("r2rsim.dataset.writer", "DatasetWriter.commit", "    commit"),
    ("r2rsim.dataset.writer", "DatasetWriter._flush_row_group", "      Parquet row group (any)"),
    ("r2rsim.dataset.writer", "sha256_file", "      sha256 for the manifest"),
    ("r2rsim.run", "validate_dataset", "      validate_dataset"),
    ("r2rsim.dataset.validate", "_check_samples", "        re-read samples + labels"),
    ("r2rsim.dataset.validate", "dataset_problems", "        re-hash files"),
]


def profile_serial(folder: Path, runs: int) -> None:
    """Where a serial 60 s run's time goes: the functions above, timed by wrapping them."""
    import functools
    import importlib

    from r2rsim.sweep import run_sweep

    acc: dict[str, list[float]] = {}
    undo = []
    for mod_name, attr, label in _PROFILED:
        try:
            obj = importlib.import_module(mod_name)
            *owners, name = attr.split(".")
            for o in owners:
                obj = getattr(obj, o)
            f = getattr(obj, name)
        except (ImportError, AttributeError):
            continue
        acc[label] = [0.0, 0.0, 0]

        def timed(*a, _f=f, _e=acc[label], **k):
            w, c = time.perf_counter(), time.process_time()
            try:
                return _f(*a, **k)
            finally:
                _e[0] += time.perf_counter() - w
                _e[1] += time.process_time() - c
                _e[2] += 1

        setattr(obj, name, functools.wraps(f)(timed))
        undo.append((obj, name, f))
    sweep = write_sweep(folder, "bench_profile", 60.0, runs)
    try:
        w0, c0 = time.perf_counter(), time.process_time()
        s = run_sweep(sweep, folder / "out", workers=0)
        wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    finally:
        for obj, name, f in reversed(undo):
            setattr(obj, name, f)
        shutil.rmtree(folder / "out", ignore_errors=True)
    n = s.done + s.failed
    print(
        f"\nProfile: serial sweep of {n} x 60 s, per run: wall {wall / n * 1e3:.1f} ms, CPU "
        f"{cpu / n * 1e3:.1f} ms, solver_s {s.solver_s / n * 1e3:.1f} ms (overhead "
        f"{(wall - s.solver_s) / wall:.1%}; the wrappers add a little)"
    )
    print(f"{'':40} {'wall ms/run':>11} {'CPU ms/run':>11} {'calls':>6}")
    for label, (w, c, k) in acc.items():
        print(f"{label:40} {w / n * 1e3:>11.2f} {c / n * 1e3:>11.2f} {k:>6}")


def _mem_one(runs: int, duration: float) -> None:
    """Helper mode (a fresh process): one sweep on 2 workers; print peak RSS as JSON."""
    import r2rsim.sweep  # noqa: F401 - what the CLI has imported before a sweep

    with tempfile.TemporaryDirectory(prefix="r2rsim-bench-sweep-mem-") as tmp:
        sweep = write_sweep(Path(tmp), f"bench_mem_{runs}", duration, runs)
        before = _rss_kib()
        r = run_once(sweep, Path(tmp) / "out", 2, None)
    print(
        json.dumps(
            {
                "runs": r["runs"],
                "wall": r["wall"],
                "rss_before_kib": before,
                "maxrss_kib": _peak_rss_kib(),
                "rss_after_kib": _rss_kib(),
            }
        )
    )


def memory(sizes: list[int], duration: float) -> list[dict]:
    print(
        f"\nParent memory: a fresh process runs a sweep of N runs of {duration:g} s on 2 "
        f"worker processes (load {_load()})"
    )
    hdr = (
        f"{'runs':>5} {'wall s':>8} {'RSS before MiB':>15} {'peak RSS MiB':>13} {'growth MiB':>11}"
    )
    print(hdr)
    print("-" * len(hdr))
    rows = []
    for n in sizes:
        p = subprocess.run(
            [sys.executable, __file__, "--mem-one", str(n), "--mem-duration", repr(duration)],
            capture_output=True,
            text=True,
            cwd=REPO,
        )
        if p.returncode != 0:
            raise SystemExit(f"memory helper failed ({p.returncode}): {p.stderr[-2000:]}")
        lines = p.stdout.strip().splitlines()
        for ln in lines[:-1]:
            print(ln)
        r = json.loads(lines[-1])
        rows.append(r)
        print(
            f"{n:>5} {r['wall']:>8.2f} {r['rss_before_kib'] / 1024:>15.1f} "
            f"{r['maxrss_kib'] / 1024:>13.1f} "
            f"{(r['maxrss_kib'] - r['rss_before_kib']) / 1024:>11.1f}",
            flush=True,
        )
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller sweeps (CI, < 2 min)")
    ap.add_argument("--runs", type=int, help="runs of the scaling sweep (24; quick 10)")
    ap.add_argument(
        "--duration", type=float, help="line time of a scaling run [s] (900; quick 1200)"
    )
    ap.add_argument(
        "--repeat", type=int, help="rounds of the scaling and overhead sweeps (3; quick 1)"
    )
    ap.add_argument("--overhead-runs", type=int, help="60 s runs for the overhead (40; quick 16)")
    ap.add_argument("--mem-runs", type=int, nargs=2, default=[50, 200])
    ap.add_argument(
        "--mem-duration", type=float, default=1.0, help="line time of a memory run [s] (1)"
    )
    ap.add_argument("--no-dask", action="store_true", help="skip the Dask LocalCluster")
    ap.add_argument(
        "--profile",
        action="store_true",
        help="also time the parts of a serial 60 s run (wrapping r2rsim functions)",
    )
    ap.add_argument("--strict", action="store_true", help="exit 1 when a bar fails")
    ap.add_argument("--mem-one", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.mem_one is not None:
        _mem_one(args.mem_one, args.mem_duration)
        return 0
    q = args.quick
    runs = args.runs or (10 if q else 24)
    duration = args.duration or (1200.0 if q else 900.0)
    repeat = args.repeat or (1 if q else 3)
    ov_runs = args.overhead_runs or (16 if q else 40)
    dask = not args.no_dask
    if dask:
        try:
            import distributed  # noqa: F401
        except ImportError:
            print("dask.distributed is not installed: no Dask row")
            dask = False

    t_start = time.perf_counter()
    import numpy

    import r2rsim

    print(
        f"r2rsim {r2rsim.__version__}, numpy {numpy.__version__}, Python "
        f"{sys.version.split()[0]}, {os.cpu_count()} cores, load "
        f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}"
    )
    with tempfile.TemporaryDirectory(prefix="r2rsim-bench-sweep-") as tmp:
        folder = Path(tmp)
        # untimed warm-up: numba compile / cache load in this process, cache on disk for
        # the workers
        run_once(write_sweep(folder, "bench_warmup", 2.0, 2), folder / "out", 0, None)
        print(f"\nscaling sweep: {runs} runs x {duration:g} s, {repeat} round(s); load {_load()}")
        res = scaling(folder, runs, duration, repeat, dask)
        speedup = print_scaling(res, duration)
        serial_ov = overhead_table(folder, ov_runs, repeat)
        if args.profile:
            profile_serial(folder, ov_runs)
    mem = memory(args.mem_runs, args.mem_duration)

    small, big = mem
    ratio = big["maxrss_kib"] / small["maxrss_kib"]
    diff_mib = (big["maxrss_kib"] - small["maxrss_kib"]) / 1024
    per_run_kib = (big["maxrss_kib"] - small["maxrss_kib"]) / (big["runs"] - small["runs"])
    verdicts = [
        (
            f"2 worker processes >= {SPEEDUP_BAR}x one worker",
            f"{speedup:.2f}x",
            speedup >= SPEEDUP_BAR,
        ),
        (
            f"serial overhead of a 60 s run <= {OVERHEAD_BAR:.0%}",
            f"{serial_ov:.1%}",
            serial_ov <= OVERHEAD_BAR,
        ),
        (
            f"parent peak RSS {big['runs']} runs within {RSS_RATIO_BAR - 1:.0%} "
            f"(or {RSS_ABS_BAR_MIB:g} MiB) of {small['runs']} runs",
            f"x{ratio:.3f}, {diff_mib:+.1f} MiB ({per_run_kib:+.1f} KiB/run)",
            ratio <= RSS_RATIO_BAR or diff_mib <= RSS_ABS_BAR_MIB,
        ),
    ]
    print(
        f"\nparent growth {per_run_kib:+.1f} KiB per run from {small['runs']} to {big['runs']} "
        f"runs: {per_run_kib * 10000 / 1024:+.0f} MiB at 10 000 runs if it stays linear"
    )
    print("\nBars")
    for what, value, ok in verdicts:
        print(f"  {'PASS' if ok else 'FAIL'}  {what:<52} {value}")
    print(f"\ntotal {time.perf_counter() - t_start:.0f} s, load {_load()}")
    return 1 if args.strict and not all(ok for *_, ok in verdicts) else 0


if __name__ == "__main__":
    sys.exit(main())
