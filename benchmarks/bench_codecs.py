"""File size, write and read CPU time of a run's samples under each Parquet codec.

The samples of one run of the calibrated thesis set (scenarios/thesis_realistic/
registration.yaml: 300 s at 100 Hz, 30 000 rows) are written again with the writer's
options (dictionary encoding of the label strings, statistics, one row group) under zstd at
levels 1, 3 and 6, lz4, snappy and no compression, each with and without
``byte_stream_split`` on the float columns. For each it prints the file size, the CPU time
to write it and the CPU time to read it back whole (``pq.read_table``) and one column of it,
the median of ``--repeat`` rounds (time.process_time, this process only). A sweep's dataset
holds the same files: its finalisation hard-links the runs' samples, it does not re-encode
them. Not a test.

Usage::

    python benchmarks/bench_codecs.py                 # ~15 s after the run (numba warm)
    python benchmarks/bench_codecs.py --repeat 9
    python benchmarks/bench_codecs.py --samples DIR/samples/run_id=X/part-0.parquet

docs/dataset.md ("Compression") has the measured table and the codec chosen.
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import pyarrow as pa  # noqa: E402
import pyarrow.parquet as pq  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
SCENARIO = REPO / "scenarios" / "thesis_realistic" / "registration.yaml"

#: (label, compression, level)
CODECS = [
    ("zstd-1", "zstd", 1),
    ("zstd-3", "zstd", 3),
    ("zstd-6", "zstd", 6),
    ("lz4", "lz4", None),
    ("snappy", "snappy", None),
    ("none", "none", None),
]


def _cpu(repeat: int, fn, *args, **kwargs) -> float:
    """Median CPU seconds of ``repeat`` calls of ``fn(*args, **kwargs)``."""
    times = []
    for _ in range(repeat):
        t0 = time.process_time()
        fn(*args, **kwargs)
        times.append(time.process_time() - t0)
    return statistics.median(times)


def _write(table: pa.Table, path: Path, compression: str, level, bss: bool) -> None:
    """Write as r2rsim.dataset.writer.DatasetWriter writes the samples (one row group)."""
    fields = table.schema
    floats = [f.name for f in fields if f.type in (pa.float32(), pa.float64())]
    with pq.ParquetWriter(
        path,
        table.schema,
        compression=compression,
        compression_level=level,
        use_dictionary=[f.name for f in fields if pa.types.is_dictionary(f.type)],
        use_byte_stream_split=floats if bss else False,
        write_statistics=True,
    ) as w:
        w.write_table(table, row_group_size=table.num_rows)


def _samples(path: Path | None, tmp: Path) -> Path:
    """The samples file to measure: given, or one run of the calibrated set written now."""
    if path is not None:
        return path
    from r2rsim import run_scenario

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        s = run_scenario(SCENARIO, output=tmp / "run")
    return s.output / "samples" / f"run_id={s.run_id}" / "part-0.parquet"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5, help="rounds per figure (median)")
    ap.add_argument("--samples", type=Path, help="a samples file instead of a new run")
    ap.add_argument("--column", default="meas.reg_sensor_A.tension_N", help="column read alone")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as d:
        tmp = Path(d)
        src = _samples(args.samples, tmp)
        table = pq.read_table(src)
        n_float = sum(f.type in (pa.float32(), pa.float64()) for f in table.schema)
        column = args.column if args.column in table.column_names else table.column_names[2]
        print(
            f"samples: {src.name} of {src.parent.name}: {table.num_rows} rows, "
            f"{table.num_columns} columns ({n_float} float), {table.nbytes / 1e6:.1f} MB in "
            f"memory, {src.stat().st_size / 1e6:.2f} MB as written"
        )
        print(
            f"machine: {platform.machine()}, {os.cpu_count()} cores, Python "
            f"{platform.python_version()}, pyarrow {pa.__version__}; median of {args.repeat}"
        )
        print()
        head = (
            f"{'codec':<8} {'byte_stream_split':>17} {'MB':>7} {'ratio':>6} "
            f"{'write ms':>9} {'read ms':>8} {'read 1 col ms':>14}"
        )
        print(head)
        print("-" * len(head))
        for label, compression, level in CODECS:
            for bss in (True, False):
                out = tmp / f"{label}-{bss}.parquet"
                write_s = _cpu(args.repeat, _write, table, out, compression, level, bss)
                read_s = _cpu(args.repeat, pq.read_table, out)
                col_s = _cpu(args.repeat, pq.read_table, out, columns=[column])
                size = out.stat().st_size
                print(
                    f"{label:<8} {'yes' if bss else 'no':>17} {size / 1e6:7.2f} "
                    f"{table.nbytes / size:6.2f} {1e3 * write_s:9.1f} {1e3 * read_s:8.1f} "
                    f"{1e3 * col_s:14.2f}"
                )
        print(
            "\nratio: the table's size in memory (Arrow) / the file's; CPU time of this "
            "process (time.process_time)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
