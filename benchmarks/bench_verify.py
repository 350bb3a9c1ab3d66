"""What checking a dataset costs its readers (issue 36): the sizes and sha256 of its files
against manifest.json, and (``read_runs``) the re-derivation of each run's labels, relative
to reading it without them.

Two datasets, two readers each:

* a long run, ``r2rsim run scenarios/quickstart.yaml --duration 1500`` (300 001 samples),
  read by :func:`r2rsim.dataset.read.read_runs` and drawn by ``r2rsim plot`` (the run figure
  of the default channels, saved to a PNG);
* a sweep of a few hundred short runs, read by ``read_runs`` and drawn by ``r2rsim plot
  --sweep`` (one column of every run). Make one with::

      r2rsim sweep scenarios/thesis_realistic/faults.yaml -o DIR     # 220 runs of 300 s

Each reader is timed with and without verification (``verify=False`` is ``--no-verify``),
the variants interleaved and repeated in this process, in an order rotated from pass to pass,
each timed right after an untimed call of itself (which also puts the files in the page
cache, and lets the reader reuse the memory it had: the one before it would otherwise
decide how many page faults it pays); the figures are the
best (smallest) wall time and CPU time (``time.process_time``: every thread of the process)
of the passes, and the medians. On a shared machine a pass varies by tens of percent (a
reader that allocates hundreds of MB pays page faults or not, by what ran before it, and
other processes take the cores), more than the verification costs: the best of several
passes is the figure that estimates a reader's own cost; the median is shown beside it.
``read_runs`` is also timed verifying without the label check (``check_labels=False``), and
both readers with their hashing in the calling thread instead of a background one
(``r2rsim.dataset.verify.HASH_IN_THREAD``); the sweep figure also with each samples file read
twice, by the hash and by the figure, instead of read once into memory and parsed from there
(``r2rsim.report._sweep.READ_WHOLE_FILES``; the run figure always streams its file).

Usage::

    python benchmarks/bench_verify.py --long /tmp/bv/long --sweep DIR      # ~10 min
    python benchmarks/bench_verify.py --long /tmp/bv/long --repeat 3       # the run only

A ``--long`` directory that does not exist is simulated first (about 3 s).

Last, each part of the verification is timed alone in one thread (best of the passes): the
size check, the sha256 of the files ``read_runs`` parses and of those the figure reads, and
the label check of every run on its samples already in memory; these CPU figures, against
the reader's own CPU time without verification, are steadier than the differences between
whole readers above on a busy machine.
"""

from __future__ import annotations

import argparse
import gc
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def _timed(fn) -> tuple[float, float]:
    gc.collect()
    w, c = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - w, time.process_time() - c


def _variants(root: Path, figure, png: Path):
    """name -> (settings, function) of every variant measured on one dataset."""
    from r2rsim.dataset.read import read_runs

    def rr(**kw):
        return lambda: read_runs(root, **kw)

    def fig(verify):
        return lambda: figure(root, verify).savefig(png)

    thread = {"hash": True, "whole": True}  # the defaults
    inline = {"hash": False, "whole": True}
    return {
        "read_runs, no verify": (thread, rr(verify=False)),
        "read_runs, sizes + sha256": (thread, rr(verify=True, check_labels=False)),
        "read_runs, sizes + sha256 + labels": (thread, rr(verify=True)),
        "read_runs, all, hashes in the reading thread": (inline, rr(verify=True)),
        "plot, no verify": (thread, fig(False)),
        "plot, sizes + sha256": (thread, fig(True)),
        "plot, sizes + sha256, hashed in the plotting thread": (inline, fig(True)),
        "plot, sizes + sha256, sweep files read twice": ({**thread, "whole": False}, fig(True)),
    }


def measure(root: Path, figure, png: Path, repeat: int) -> dict[str, tuple]:
    """Best and median (wall, cpu) of each variant over ``repeat`` interleaved passes."""
    from r2rsim.dataset import verify
    from r2rsim.report import _sweep

    variants = _variants(root, figure, png)
    times: dict[str, list[tuple[float, float]]] = {k: [] for k in variants}
    names = list(variants)
    for p in range(repeat):
        for name in names[p % len(names) :] + names[: p % len(names)]:
            settings, fn = variants[name]
            verify.HASH_IN_THREAD = settings["hash"]
            _sweep.READ_WHOLE_FILES = settings["whole"]
            # run untimed first: a reader pays for what the one before it left (memory a
            # figure gave back to the system is faulted in again), so each is timed after
            # itself, in the same state
            fn()
            times[name].append(_timed(fn))
    verify.HASH_IN_THREAD = _sweep.READ_WHOLE_FILES = True
    return {
        k: (
            min(w for w, _ in v),
            min(c for _, c in v),
            statistics.median(w for w, _ in v),
            statistics.median(c for _, c in v),
        )
        for k, v in times.items()
    }


def components(root: Path, figure_reads: str, repeat: int) -> dict[str, float]:
    """The CPU work of verification itself, each part timed alone in the calling thread
    (best of ``repeat``): the size check of every listed file, the sha256 of the files
    read_runs parses and of those the figure reads, and the label check of every run (on
    its samples already in memory)."""
    import hashlib

    import pyarrow.parquet as pq

    from r2rsim.dataset.read import _label_problem
    from r2rsim.dataset.verify import Verifier

    tables = ["runs.parquet", "faults.parquet"]
    samples = sorted(p.relative_to(root).as_posix() for p in (root / "samples").rglob("*.parquet"))
    fig_files = [
        *tables,
        "channels.parquet",
        "events.parquet",
        *(samples[:1] if figure_reads == "one run" else samples),
    ]
    runs = {r["run_id"]: r for r in pq.read_table(root / "runs.parquet").to_pylist()}
    faults: dict[str, list] = {}
    for f in pq.read_table(root / "faults.parquet").to_pylist():
        faults.setdefault(f["run_id"], []).append(f)

    def sha(files):
        for rel in files:
            hashlib.sha256((root / rel).read_bytes()).hexdigest()

    def labels():
        for rel in samples:
            rid = rel.split("/")[1][len("run_id=") :]
            t = pq.read_table(root / rel)
            c = time.process_time()
            _label_problem(t, runs[rid], faults.get(rid, []), root)
            out[0] += time.process_time() - c

    best: dict[str, float] = {}
    for _ in range(repeat):
        for name, fn in (
            ("sizes", lambda: Verifier(root).close()),
            ("sha256, read_runs", lambda: sha(tables + samples)),
            ("sha256, figure", lambda: sha(fig_files)),
        ):
            cpu = _timed(fn)[1]
            best[name] = min(best.get(name, cpu), cpu)
        out = [0.0]
        labels()
        best["labels"] = min(best.get("labels", out[0]), out[0])
    return best


def report(title: str, res: dict[str, tuple]) -> None:
    print(f"\n{title}")
    print(
        f"  {'variant':<52} {'wall s':>7} {'cpu s':>7} {'+wall':>7} {'+cpu':>7}   "
        f"{'median: wall':>12} {'cpu':>6} {'+wall':>7} {'+cpu':>7}"
    )
    for name, r in res.items():
        base = res["read_runs, no verify" if name.startswith("read_runs") else "plot, no verify"]
        cells = []
        for i in (0, 2):
            w, c = (100 * (r[j] / base[j] - 1) for j in (i, i + 1))
            more = "" if "no verify" in name else f"{w:>6.1f}% {c:>6.1f}%"
            cells.append(f"{r[i]:>7.3f} {r[i + 1]:>7.3f} {more:>15}")
        print(f"  {name:<52} {cells[0]}   {cells[1]}")


def report_components(parts: dict[str, float], res: dict[str, tuple]) -> None:
    """Each part's CPU time against the best CPU time of the reader without verification."""
    rr, fig = res["read_runs, no verify"][1], res["plot, no verify"][1]
    print("  the parts alone (cpu s, best; % of the reader's cpu without verification):")
    for name, cpu in parts.items():
        against = (
            [("read_runs", rr)]
            if name in ("sha256, read_runs", "labels")
            else [("plot", fig)]
            if name == "sha256, figure"
            else [("read_runs", rr), ("plot", fig)]
        )
        print(
            f"    {name:<20} {cpu:>7.3f}   "
            + ", ".join(f"{100 * cpu / base:.1f}% of {who}" for who, base in against)
        )


def _run_figure(root, verify):
    from r2rsim.report import plot_run

    return plot_run(root, verify=verify)


def _sweep_figure(channel):
    def draw(root, verify):
        from r2rsim.report import plot_sweep

        return plot_sweep(root, channel, verify=verify)

    return draw


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--long",
        type=Path,
        required=True,
        help="the 1500 s run (simulated here if the directory does not exist)",
    )
    ap.add_argument("--sweep", type=Path, help="a finished sweep (r2rsim sweep ... -o DIR)")
    ap.add_argument(
        "--channel",
        default="meas.sensor_A.tension_N",
        help="the sweep figure's channel (default: meas.sensor_A.tension_N)",
    )
    ap.add_argument("--repeat", type=int, default=5, help="timed passes (default 5)")
    args = ap.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import r2rsim.report  # noqa: F401 - imported before timing

    if not args.long.exists():
        subprocess.run(
            [
                sys.executable,
                "-m",
                "r2rsim.cli",
                "run",
                str(REPO / "scenarios" / "quickstart.yaml"),
                "--duration",
                "1500",
                "-o",
                str(args.long),
                "-q",
            ],
            check=True,
        )
    with tempfile.TemporaryDirectory(prefix="r2rsim-bench-verify-") as tmp:
        png = Path(tmp) / "figure.png"
        import pyarrow.parquet as pq

        n = pq.read_metadata(next((args.long / "samples").rglob("*.parquet"))).num_rows
        res = measure(args.long, _run_figure, png, args.repeat)
        report(f"(a) one run, {n} samples: {args.long}", res)
        report_components(components(args.long, "one run", args.repeat), res)
        if args.sweep is not None:
            runs = pq.read_metadata(args.sweep / "runs.parquet").num_rows
            res = measure(args.sweep, _sweep_figure(args.channel), png, args.repeat)
            report(f"(b) a sweep of {runs} runs: {args.sweep} (plot --sweep {args.channel})", res)
            report_components(components(args.sweep, "every run", args.repeat), res)
    print(
        f"\n+wall, +cpu: more than the same reader without verification; best of "
        f"{args.repeat} passes, then their median (cpu: every thread of the process)"
    )


if __name__ == "__main__":
    main()
