"""Wall time and peak memory of ``plot_run`` on a long run (issue 17: an hour at 1 kHz plots
in under 5 s, in less memory than its samples take).

Simulating an hour at 1 kHz takes long, so the script writes a synthetic run in the dataset
layout instead (``samples/run_id=<id>/part-0.parquet`` with runs, channels, faults and
events tables): the columns of ``scenarios/line_a_faults.yaml`` (five spans, six rollers, four
sensors, controllers, set-points, labels; float32 like ``r2rsim run`` writes them, row
groups of about 16 MB, zstd, byte-stream-split), smooth signals with noise on the readings,
one single-sample spike, two faults and a few events, and a manifest.json (the figure checks
the files' sizes and checksums against it, so the time includes that). It is built in a
child process, so the measuring process's peak resident set size starts from its imports;
then it plots the default channel set to a PNG and prints the wall time (read + draw +
save), the peak RSS growth over the process's size after its imports, the tracemalloc peak
of a second, untimed pass (numpy and Python allocations; Arrow's buffers are not traced),
and the samples' size on disk and in memory (Arrow, uncompressed).

``--cli`` measures the commands instead, as a user runs them: the CPU time (user + system,
imports included, best of three) of ``r2rsim plot`` on the quick-start run and of ``r2rsim
report`` on a ``r2rsim diagnose`` result of the quick-start sweep, each made first in a
scratch directory (about 15 s).

Usage::

    python benchmarks/bench_plot.py                  # 1 h at 1 kHz (~1 min to write)
    python benchmarks/bench_plot.py --seconds 600    # shorter
    python benchmarks/bench_plot.py --keep DIR       # keep the dataset and the PNG in DIR
    python benchmarks/bench_plot.py --cli            # CPU time of r2rsim plot and report
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

RUN_ID = "long__s0"
SPIKE_AT = 0.3427  # one sample of state.span3.tension_N, this far into the run, is SPIKE_N
SPIKE_N = 1.0e4
_SPANS = [f"span{i}" for i in range(1, 6)]
_NODES = ["unwind", "idler1", "swrapA", "swrapB", "pull", "rewind"]
_SENSORS = [
    ("lc_unwind", "tension_N", "N"),
    ("lc_rewind", "tension_N", "N"),
    ("enc_pull", "speed_rad_s", "rad/s"),
    ("dia_unwind", "diameter_m", "m"),
]


def channel_table() -> list[tuple[str, str]]:
    """(column, unit) of the float channels, named as for the line of line_a_faults."""
    cols = []
    for s, q, unit in _SENSORS:
        cols += [(f"meas.{s}.{q}", unit), (f"true.{s}.{q}", unit), (f"ctrl.{s}.{q}", unit)]
    for s in _SPANS:
        cols += [
            (f"state.{s}.tension_N", "N"),
            (f"state.{s}.geometric_strain", "1"),
            (f"state.{s}.length_m", "m"),
        ]
    for n in _NODES:
        cols += [
            (f"state.{n}.surface_speed_m_s", "m/s"),
            (f"state.{n}.speed_rad_s", "rad/s"),
            (f"state.{n}.radius_m", "m"),
            (f"state.{n}.inertia_kg_m2", "kg*m^2"),
            (f"state.{n}.web_mass_kg", "kg"),
            (f"act.{n}.torque_N_m", "N*m"),
            (f"cmd.{n}.torque_N_m", "N*m"),
            (f"state.{n}.tension_ratio", "1"),
        ]
    for c in ("pull_speed", "swrapA_speed", "swrapB_speed", "unwind_tension", "rewind_tension"):
        cols += [(f"ctrl.{c}.error", ""), (f"ctrl.{c}.output", ""), (f"ctrl.{c}.integral", "")]
    cols += [
        ("sp.line_speed_m_s", "m/s"),
        ("sp.line_acceleration_m_s2", "m/s^2"),
        ("sp.unwind_tension.tension_N", "N"),
        ("sp.rewind_tension.tension_N", "N"),
        ("label.severity", "1"),
    ]
    return cols


def _signal(column: str, t: np.ndarray, j: int, rng: np.random.Generator) -> np.ndarray:
    """A plausible smooth signal per column, with noise on the readings."""
    level = 250.0 if column.endswith("tension_N") else 5.0 if "speed" in column else 0.3
    y = level * (1 + 0.02 * np.sin(2 * np.pi * t / (60 + 7 * j)) + 0.002 * np.sin(40 * t + j))
    if column.startswith("meas."):
        y += rng.normal(0, 0.002 * level, t.size)
    if column.startswith("sp.") or ".idler1.radius" in column:
        y = np.full_like(t, level)
    return y.astype(np.float32)


def make_dataset(root: Path, seconds: float = 3600.0, rate: float = 1000.0) -> Path:
    """Write a synthetic one-run dataset of ``seconds`` at ``rate`` into ``root``."""
    cols = channel_table()
    fields = [pa.field("k", pa.int64()), pa.field("t_s", pa.float64())]
    fields += [pa.field(c, pa.float32()) for c, _ in cols]
    fields += [
        pa.field("label.is_faulty", pa.bool_()),
        pa.field("label.primary_type", pa.dictionary(pa.int8(), pa.string())),
    ]
    schema = pa.schema(fields)
    n = int(round(seconds * rate)) + 1
    rows_per_group = (16 << 20) // (8 + 8 + 4 * len(cols) + 2)
    folder = root / "samples" / f"run_id={RUN_ID}"
    folder.mkdir(parents=True)
    rng = np.random.default_rng(0)
    floats = [f.name for f in fields if pa.types.is_floating(f.type)]
    with pq.ParquetWriter(
        folder / "part-0.parquet",
        schema,
        compression="zstd",
        compression_level=3,
        use_byte_stream_split=floats,
        use_dictionary=["label.primary_type"],
        write_statistics=True,
    ) as w:
        for k0 in range(0, n, rows_per_group):
            k = np.arange(k0, min(n, k0 + rows_per_group))
            t = k / rate
            arrays = [pa.array(k), pa.array(t)]
            for j, (c, _) in enumerate(cols):
                y = _signal(c, t, j, rng)
                if c == "state.span3.tension_N":
                    y[k == round(SPIKE_AT * (n - 1))] = SPIKE_N
                arrays.append(pa.array(y))
            faulty = (t >= 600) & (t < 900)
            arrays.append(pa.array(faulty))
            arrays.append(pa.array(np.where(faulty, "sensor.offset", "normal")).dictionary_encode())
            w.write_table(pa.Table.from_arrays(arrays, schema=schema), row_group_size=len(k))
    pq.write_table(
        pa.table({"run_id": [RUN_ID], "sample_period_s": [1 / rate], "duration_s": [seconds]}),
        root / "runs.parquet",
    )
    pq.write_table(
        pa.table({"channel": [c for c, _ in cols], "unit": [u for _, u in cols]}),
        root / "channels.parquet",
    )
    pq.write_table(
        pa.table(
            {
                "run_id": [RUN_ID] * 2,
                "fault_id": ["lc_offset", "drag"],
                "fault_type": ["sensor.offset", "process.bearing_friction"],
                "onset_t_s": [600.0, 2400.0],
                "end_t_s": [900.0, None],
            }
        ),
        root / "faults.parquet",
    )
    ev_t = [1800.0, 1830.0, 1850.0]
    pq.write_table(
        pa.table(
            {
                "run_id": [RUN_ID] * 3,
                "t_s": ev_t,
                "kind": ["splice", "splice", "slack"],
                "component": ["unwind", "unwind", "span2"],
                "state": ["fill", "complete", "start"],
                "message": [""] * 3,
                "values_json": ["{}"] * 3,
            }
        ),
        root / "events.parquet",
    )
    write_manifest(root)
    return root


def write_manifest(root: Path) -> None:
    """manifest.json listing every file with its sha256 and size, as r2rsim writes it (the
    figures check a dataset against it)."""
    from r2rsim.dataset.paths import sha256_file
    from r2rsim.dataset.writer import SCHEMA_VERSION

    files = {
        p.relative_to(root).as_posix(): {"sha256": sha256_file(p), "bytes": p.stat().st_size}
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != "manifest.json"
    }
    (root / "manifest.json").write_text(
        json.dumps(
            {"schema_version": SCHEMA_VERSION, "run_ids": [RUN_ID], "files": files},
            indent=2,
            sort_keys=True,
        )
    )


def _vm(field: str) -> int:
    """A /proc/self/status memory figure in bytes (Linux)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(field + ":"):
            return int(line.split()[1]) * 1024
    raise RuntimeError(f"no {field} in /proc/self/status")


def measure(root: Path, png: Path) -> dict:
    """Plot the run's default channels to ``png``; wall time and memory."""
    import matplotlib

    matplotlib.use("Agg")
    from r2rsim.report import plot_run

    rss0 = _vm("VmRSS")
    t = time.perf_counter()
    fig = plot_run(root, verify=False)  # synthetic: no complete faults.parquet to check
    fig.savefig(png)
    wall = time.perf_counter() - t
    rss_growth, rss_peak = _vm("VmHWM") - rss0, _vm("VmHWM")
    tracemalloc.start()  # a second pass: tracing slows allocation down, so it is not timed
    plot_run(root, verify=False).savefig(png)
    traced = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    spans = [
        ln for ax in fig.axes for ln in ax.get_lines() if ln.get_label() == "state.span3.tension_N"
    ]
    part = next((root / "samples").rglob("part-0.parquet"))
    meta = pq.ParquetFile(part).metadata
    in_memory = sum(meta.row_group(g).total_byte_size for g in range(meta.num_row_groups))
    return {
        "rows": meta.num_rows,
        "columns": meta.num_columns,
        "wall_s": wall,
        "peak_rss_growth_bytes": rss_growth,
        "peak_rss_bytes": rss_peak,
        "tracemalloc_peak_bytes": traced,
        "samples_on_disk_bytes": part.stat().st_size,
        "samples_in_memory_bytes": in_memory,
        "spike_survives": bool(spans and max(ln.get_ydata().max() for ln in spans) == SPIKE_N),
        "lines": sum(len(ax.get_lines()) for ax in fig.axes),
        "axes": len(fig.axes),
    }


def cli_cpu(args: list[str], repeat: int = 3) -> float:
    """The least CPU time (user + system, s) of ``r2rsim <args>`` in a child process."""
    best = float("inf")
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run(
            [sys.executable, "-m", "r2rsim.cli", *args], check=True, stdout=subprocess.DEVNULL
        )
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        best = min(best, after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return best


def measure_cli(where: Path) -> dict:
    """CPU time of ``r2rsim plot`` (the quick-start run, default channels) and ``r2rsim
    report`` (pca on the quick-start sweep), the data made in ``where`` first."""
    repo = Path(__file__).resolve().parents[1]
    run, sweep, res = where / "quickstart", where / "quickstart_sweep", where / "pca"
    for args in (
        ["run", str(repo / "scenarios" / "quickstart.yaml"), "-o", str(run), "-q"],
        ["sweep", str(repo / "sweeps" / "quickstart.yaml"), "-o", str(sweep), "-q"],
        ["diagnose", "--method", "pca", "--data", str(sweep), "-o", str(res)],
    ):
        subprocess.run(
            [sys.executable, "-m", "r2rsim.cli", *args], check=True, stdout=subprocess.DEVNULL
        )
    return {
        "plot_cpu_s": cli_cpu(["plot", str(run), "-o", str(where / "run.png"), "--overwrite"]),
        "plot_sweep_cpu_s": cli_cpu(
            [
                "plot",
                str(sweep),
                "--sweep",
                "meas.lc_rewind.tension_N",
                "--axis",
                "offset",
                "-o",
                str(where / "sweep.png"),
                "--overwrite",
            ]
        ),
        "report_cpu_s": cli_cpu(["report", str(res), "-o", str(where / "report.html")]),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=3600.0)
    ap.add_argument("--rate", type=float, default=1000.0)
    ap.add_argument("--keep", type=Path, help="write the dataset and PNG here and keep them")
    ap.add_argument("--make", type=Path, help=argparse.SUPPRESS)  # child process: build only
    ap.add_argument(
        "--cli",
        action="store_true",
        help="CPU time of r2rsim plot and r2rsim report on the quick start",
    )
    args = ap.parse_args()
    if args.cli:
        with tempfile.TemporaryDirectory(prefix="r2rsim-bench-cli-") as tmp:
            r = measure_cli(args.keep or Path(tmp))
        print(f"r2rsim plot (run)    {r['plot_cpu_s']:.2f} s CPU")
        print(f"r2rsim plot --sweep  {r['plot_sweep_cpu_s']:.2f} s CPU")
        print(f"r2rsim report        {r['report_cpu_s']:.2f} s CPU")
        print(json.dumps(r))
        return
    if args.make:
        make_dataset(args.make, args.seconds, args.rate)
        return
    with tempfile.TemporaryDirectory(prefix="r2rsim-bench-plot-") as tmp:
        where = args.keep or Path(tmp)
        root = where / "long"
        t = time.perf_counter()
        subprocess.run(
            [
                sys.executable,
                __file__,
                "--make",
                str(root),
                "--seconds",
                repr(args.seconds),
                "--rate",
                repr(args.rate),
            ],
            check=True,
        )
        print(f"wrote the synthetic dataset in {time.perf_counter() - t:.1f} s")
        r = measure(root, where / "long.png")
    mib = 1 << 20
    print(
        f"run          {r['rows']} rows x {r['columns']} columns ({args.seconds:g} s at "
        f"{args.rate:g} Hz)"
    )
    print(
        f"samples      {r['samples_on_disk_bytes'] / mib:.0f} MiB on disk, "
        f"{r['samples_in_memory_bytes'] / mib:.0f} MiB uncompressed"
    )
    print(
        f"plot_run     {r['wall_s']:.2f} s wall (read, draw, save PNG); {r['axes']} axes, "
        f"{r['lines']} lines"
    )
    print(
        f"memory       peak RSS growth {r['peak_rss_growth_bytes'] / mib:.0f} MiB (process "
        f"peak {r['peak_rss_bytes'] / mib:.0f} MiB with its imports), "
        f"tracemalloc peak {r['tracemalloc_peak_bytes'] / mib:.0f} MiB"
    )
    print(f"spike        {'survives' if r['spike_survives'] else 'LOST'} the decimation")
    ok = r["wall_s"] < 5 and r["peak_rss_growth_bytes"] < r["samples_on_disk_bytes"]
    print(
        f"verdict      {'PASS' if ok else 'FAIL'} (< 5 s, peak RSS growth below the "
        f"samples' size on disk)"
    )
    print(json.dumps(r))


if __name__ == "__main__":
    main()
