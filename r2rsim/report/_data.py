"""Reading what a figure needs from a dataset, and no more: the requested columns of one
run, streamed row group by row group and reduced to min/max envelopes, so a long run plots
in a memory far below the size of its samples."""

from __future__ import annotations

import contextlib
import difflib
import fnmatch
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from ..dataset.read import is_dataset_dir
from ..dataset.verify import Verifier, refuse_unfinished
from ..errors import InputError

#: the dataset's tables every figure checks against manifest.json when it verifies (each is a
#: few kB; the run figure reads faults and events, the sweep figure only their checksums)
TABLES = ("runs.parquet", "channels.parquet", "faults.parquet", "events.parquet")


def decimate_minmax(t, y, n_buckets: int, t_range: tuple[float, float] | None = None):
    """Thin a time series for display, keeping each bucket's smallest and largest sample.

    The time span is cut into ``n_buckets`` equal buckets (one per pixel column, say); each
    bucket keeps the samples holding its minimum and its maximum, in time order, so a
    single-sample spike survives at any zoom. NaN samples (a sensor dropout) are ignored;
    a bucket holding only NaN keeps one NaN sample, so the drawn line breaks there.

    Parameters
    ----------
    t : array_like
        Sample times, non-decreasing.
    y : array_like
        Values, same length as ``t``.
    n_buckets : int
        Number of buckets (at least 1). Series of at most ``2 * n_buckets`` samples are
        returned whole.
    t_range : (float, float), optional
        Time span the buckets divide (default ``t[0]`` to ``t[-1]``). Give the whole span
        when decimating a long series chunk by chunk, so the chunks share bucket edges.

    Returns
    -------
    t_out, y_out : numpy.ndarray
        The kept samples (at most ``2 * n_buckets``), in time order.

    Examples
    --------
    >>> t = np.arange(10_000) * 1e-3
    >>> y = np.zeros_like(t); y[4321] = 5.0
    >>> td, yd = decimate_minmax(t, y, 100)
    >>> len(td) <= 200, yd.max()
    (True, 5.0)
    """
    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    if n_buckets < 1:
        raise ValueError(f"n_buckets must be at least 1, got {n_buckets}")
    if t.shape != y.shape or t.ndim != 1:
        raise ValueError(f"t and y must be 1-D of the same length, got {t.shape} and {y.shape}")
    if t.size <= 2 * n_buckets:
        return t.copy(), y.copy()
    idx = _minmax_indices(y, _bucket_starts(t, n_buckets, t_range))
    return t[idx], y[idx]


def _bucket_starts(t: np.ndarray, n_buckets: int, t_range) -> np.ndarray:
    """Index of the first sample of each non-empty bucket (``t`` sorted: buckets are runs)."""
    lo, hi = t_range if t_range is not None else (t[0], t[-1])
    width = (hi - lo) / n_buckets if hi > lo else 1.0
    bucket = np.clip(((t - lo) / width).astype(np.int64), 0, n_buckets - 1)
    return np.flatnonzero(np.diff(bucket, prepend=-1))


def _minmax_indices(y: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Sorted indices of each bucket's first minimum and first maximum (NaN ignored); the
    first index of an all-NaN bucket."""
    counts = np.diff(np.append(starts, y.size))
    bucket = np.repeat(np.arange(starts.size), counts)
    with np.errstate(invalid="ignore"):
        lo = np.fmin.reduceat(y, starts)  # fmin/fmax skip NaN; all-NaN buckets give NaN
        hi = np.fmax.reduceat(y, starts)
    keep = [starts[np.isnan(lo)]]
    for extreme in (lo, hi):
        hit = np.flatnonzero(y == extreme[bucket])
        first = np.diff(bucket[hit], prepend=-1) != 0  # the first hit of each bucket
        keep.append(hit[first])
    return np.unique(np.concatenate(keep))


# ---- the dataset --------------------------------------------------------------------------


@dataclass
class RunData:
    """Where one run's samples are, and what they hold."""

    root: Path
    run_id: str
    files: list[Path]
    metas: list[pq.FileMetaData]  # the files' footers
    columns: list[str]  # numeric sample columns, in file order
    t_start: float
    t_end: float
    verifier: Verifier | None = None  # checks the files against manifest.json
    data: list[bytes] | None = None  # the files' bytes, when read whole (``whole=True``)


@contextlib.contextmanager
def _reading(root: Path, path: Path, verifier: Verifier | None = None):
    """A file of the dataset that cannot be read, or lacks a column a figure needs, is one
    error naming it. When the figure verifies (``verifier``), a file that differs from
    manifest.json is refused as such first (its checksum is waited for); without it, a
    damaged file shows here."""
    try:
        yield
    except (pa.ArrowException, OSError, KeyError, StopIteration) as exc:
        if verifier is not None:
            verifier.check(path.relative_to(root).as_posix())
        text = str(exc.args[0] if isinstance(exc, KeyError) and exc.args else exc).strip()
        why = text.splitlines()[0] if text else type(exc).__name__
        raise InputError(
            f"dataset {root}: {path.relative_to(root)} cannot be read "
            f"({why}); `r2rsim validate {root}` checks every file"
        ) from None


def open_dataset(path) -> Path:
    """The dataset directory, checked to be one (runs.parquet and samples/, and not an
    unfinished sweep)."""
    root = Path(path)
    if not root.is_dir():
        raise InputError(f"{root}: no such dataset directory")
    refuse_unfinished(root)
    if (
        not is_dataset_dir(root)
        or not (root / "runs.parquet").is_file()
        or not (root / "samples").is_dir()
    ):
        raise InputError(f"{root}: not an r2rsim dataset (no runs.parquet and samples/)")
    return root


def verified(v: Verifier) -> None:
    """Before a figure is returned: the dataset's tables it did not read (:data:`TABLES`)
    are hashed too, and every checksum begun (the samples files it opened, hashed in the
    background while it read them) is waited for; the first file that differs from
    manifest.json is refused."""
    if v.verify:
        for rel in TABLES:
            if rel in v.files:
                v.start(rel)  # a table already read and checked is not hashed again
    v.check()


def _whole(root: Path, rel: str, verifier: Verifier | None):
    """What pyarrow reads a whole table from: the path, or (verifying) the file's bytes,
    checked against its sha256 (so what is parsed is what was hashed)."""
    if verifier is None or not verifier.verify:
        return root / rel
    return pa.BufferReader(verifier.read(rel))


def runs_table(root: Path, verifier: Verifier | None = None) -> pd.DataFrame:
    """runs.parquet of the dataset (with its run_id column)."""
    with _reading(root, root / "runs.parquet", verifier):
        runs = pq.read_table(_whole(root, "runs.parquet", verifier)).to_pandas()
        if "run_id" not in runs:
            raise KeyError("no column run_id")
    return runs


def sample_files(root: Path, run_id: str) -> list[Path]:
    """The run's samples files, in part order (empty when the run wrote none)."""
    folder = root / "samples" / f"run_id={run_id}"
    return sorted(folder.glob("part-*.parquet"), key=lambda p: int(p.stem.split("-")[-1]))


def resolve_run(root: Path, run_id: str | None, verifier: Verifier | None = None) -> str:
    """The run to plot: ``run_id``, checked to be in runs.parquet, or the first run."""
    known = runs_table(root, verifier)["run_id"].tolist()
    if not known:
        raise InputError(f"dataset {root}: runs.parquet lists no runs")
    if run_id is None:
        return known[0]
    if run_id not in known:
        few = ", ".join(known[:5]) + (f", ... ({len(known)} runs)" if len(known) > 5 else "")
        raise InputError(f"dataset {root}: no run '{run_id}' (runs: {few})")
    return run_id


def open_run(
    root: Path, run_id: str, verifier: Verifier | None = None, *, whole: bool = False
) -> RunData:
    """Locate the run's samples and read their footers: schema, row-group statistics. With
    a ``verifier``, each file must be listed in manifest.json, and its sha256 is computed in
    the background while the figure reads it (``verifier.check()`` waits for it). ``whole``:
    read each file into memory once, hashed and parsed from the same bytes (for short runs
    of which a figure reads little: the sweep figure)."""
    files = sample_files(root, run_id)
    if not files:
        raise InputError(
            f"dataset {root}: run {run_id} has no samples (samples/run_id={run_id}/part-*.parquet)"
        )
    metas: list[pq.FileMetaData] = []
    data: list[bytes] = []  # with whole
    for f in files:
        rel = f.relative_to(root).as_posix()
        with _reading(root, f, verifier):
            blob = None
            if whole:
                if verifier is not None:
                    verifier.listed(rel, run_id)
                blob = f.read_bytes()
                data.append(blob)
            if verifier is not None:
                verifier.start(rel, run_id, blob)
            metas.append(pq.read_metadata(pa.BufferReader(blob) if blob is not None else f))
            _stats(metas[-1], "t_s")  # the time column is there
    numeric = [
        f.name
        for f in metas[0].schema.to_arrow_schema()
        if f.name not in ("k", "t_s")
        and (
            pa.types.is_floating(f.type)
            or pa.types.is_integer(f.type)
            or pa.types.is_boolean(f.type)
        )
    ]
    run = RunData(
        root, run_id, files, metas, numeric, np.nan, np.nan, verifier, data if whole else None
    )
    # + 0.0: Parquet statistics store a float minimum of 0 as -0 (the format's rule)
    run.t_start, run.t_end = (v + 0.0 for v in _column_range(run, "t_s"))
    return run


def _stats(meta: pq.FileMetaData, column: str) -> list:
    """The statistics of a top-level column in each row group (None where missing)."""
    # leaf columns, not Arrow fields: a list column (label.fault_ids) has its own paths
    leaf = next((i for i in range(meta.num_columns) if meta.schema.column(i).path == column), None)
    if leaf is None:
        raise KeyError(f"no column {column}")
    out = []
    for g in range(meta.num_row_groups):
        st = meta.row_group(g).column(leaf).statistics
        out.append(st if st is not None and st.has_min_max else None)
    return out


def _column_range(run: RunData, column: str) -> tuple[float, float]:
    """Smallest and largest value of a column in the run, from the row-group statistics
    (NaN, NaN when a row group has none)."""
    stats = [st for meta in run.metas for st in _stats(meta, column)]
    if not stats or any(st is None for st in stats):
        return np.nan, np.nan
    return min(float(st.min) for st in stats), max(float(st.max) for st in stats)


def constant_columns(run: RunData, columns: list[str]) -> set[str]:
    """The columns whose value never changes in the run (an idler's radius), known from the
    row-group statistics without reading the data."""
    out = set()
    for c in columns:
        lo, hi = _column_range(run, c)
        if lo == hi:
            out.add(c)
    return out


def select_channels(run: RunData, globs) -> list[str]:
    """The numeric columns matching the globs (fnmatch), in glob order, each once.

    Raises
    ------
    InputError
        Naming the first glob that matches no column, with a few columns like it.
    """
    picked: dict[str, None] = {}
    for g in globs:
        hits = [c for c in run.columns if fnmatch.fnmatchcase(c, g)]
        if not hits:
            like = difflib.get_close_matches(g, run.columns, n=4, cutoff=0.3) or run.columns[:4]
            raise InputError(
                f"dataset {run.root}: run {run.run_id}: channel glob '{g}' "
                f"matches no numeric column (e.g. {', '.join(like)})"
            )
        picked.update(dict.fromkeys(hits))
    return list(picked)


def channel_units(root: Path, verifier: Verifier | None = None) -> dict[str, str]:
    """Unit of each column from channels.parquet (empty when the file is missing)."""
    return {c: unit for c, (unit, _) in channel_table(root, verifier).items()}


def channel_table(root: Path, verifier: Verifier | None = None) -> dict[str, tuple[str, str]]:
    """``(unit, description)`` of each column from channels.parquet (empty when the file is
    missing; a description ``""`` when it has none). The description names the sensor type
    of a reading (``encoder 'enc_pull' on pull: measured ...``)."""
    f = root / "channels.parquet"
    if not f.is_file():
        return {}
    with _reading(root, f, verifier):
        table = pq.read_table(_whole(root, f.name, verifier))
        ch = table.select(
            ["channel", "unit", *(["description"] if "description" in table.column_names else [])]
        ).to_pandas()
    desc = ch["description"].fillna("") if "description" in ch else [""] * len(ch)
    return dict(zip(ch["channel"], zip(ch["unit"].fillna(""), desc, strict=True), strict=True))


def is_encoder(description: str) -> bool:
    """Whether a channel is an encoder's reading (its channels.parquet description)."""
    return str(description).startswith("encoder ")


def run_rows(root: Path, name: str, run_id: str, verifier: Verifier | None = None) -> pd.DataFrame:
    """The run's rows of faults.parquet or events.parquet (empty when the file is missing)."""
    f = root / name
    if not f.is_file():
        return pd.DataFrame()
    with _reading(root, f, verifier):
        df = pq.read_table(
            _whole(root, name, verifier), filters=[("run_id", "=", run_id)]
        ).to_pandas()
    return df.reset_index(drop=True)


def run_rows_all(
    root: Path, name: str, columns: list[str], verifier: Verifier | None = None
) -> pd.DataFrame:
    """These columns (those the file has) of every row of faults.parquet or events.parquet
    (empty when the file is missing); the file is checked whole."""
    f = root / name
    if not f.is_file():
        return pd.DataFrame()
    with _reading(root, f, verifier):
        table = pq.read_table(_whole(root, name, verifier))
    return table.select([c for c in columns if c in table.column_names]).to_pandas()


def _row_groups_in(meta: pq.FileMetaData, t0: float, t1: float) -> list[int]:
    """Row groups of a file that may hold samples with t0 <= t_s <= t1."""
    return [
        g
        for g, st in enumerate(_stats(meta, "t_s"))
        if st is None or (st.max >= t0 and st.min <= t1)
    ]


def iter_window(run: RunData, columns: list[str], t0: float, t1: float):
    """Yield ``(t, {column: values})`` per row group of the samples with t0 <= t_s <= t1,
    reading only these columns and only the row groups that overlap the window (a row
    group is about 16 MB of all columns, so a chunk is a few MB)."""
    sources: Sequence[bytes | None] = run.data or [None] * len(run.files)
    for path, meta, data in zip(run.files, run.metas, sources, strict=True):
        f = pq.ParquetFile(path if data is None else pa.BufferReader(data), metadata=meta)
        for g in _row_groups_in(meta, t0, t1):
            with _reading(run.root, path, run.verifier):
                table = f.read_row_group(g, columns=["t_s", *columns])
            pa.default_memory_pool().release_unused()  # keep the process small on long runs
            t = table.column(0).to_numpy()
            inside = (t >= t0) & (t <= t1)
            if inside.any():
                yield (
                    t[inside],
                    {c: _floats(table.column(i + 1))[inside] for i, c in enumerate(columns)},
                )


def label_tables(root: Path, verifier: Verifier | None) -> tuple[list, list]:
    """The rows of runs.parquet and faults.parquet as Python values (for the label check)."""
    out = []
    for name in ("runs.parquet", "faults.parquet"):
        with _reading(root, root / name, verifier):
            out.append(pq.read_table(_whole(root, name, verifier)).to_pylist())
    return out[0], out[1]


def check_run_labels(run: RunData) -> None:
    """Refuse a run whose labels differ from what faults.parquet and runs.parquet give (an
    edited ``faults.parquet`` with its manifest entry re-hashed), as every reader does:
    :func:`r2rsim.dataset.labels.quick_label_problem` on the run's ``k``, ``t_s`` and the
    label columns it compares (read apart from what the figure draws: a few small columns).

    Raises
    ------
    InputError
        Naming the run, the column, the first differing ``k`` and both values.
    """
    from ..dataset.labels import QUICK_LABELS, quick_label_problem

    v = run.verifier
    names = set(run.metas[0].schema.to_arrow_schema().names)
    wanted = [
        "k",
        "t_s",
        *(c for c in QUICK_LABELS if c in names),
        *sorted(c for c in names if c.startswith("label.ch.")),
    ]
    sources: Sequence[bytes | None] = run.data or [None] * len(run.files)
    tables = []
    for path, meta, data in zip(run.files, run.metas, sources, strict=True):
        with _reading(run.root, path, v):
            f = pq.ParquetFile(path if data is None else pa.BufferReader(data), metadata=meta)
            tables.append(f.read(columns=wanted))
    table = pa.concat_tables(tables) if len(tables) > 1 else tables[0]
    runs, faults = label_tables(run.root, v)
    row = [r for r in runs if r["run_id"] == run.run_id]
    try:
        problem = (
            quick_label_problem(table, row[0], [f for f in faults if f["run_id"] == run.run_id])
            if row
            else None
        )
    except (KeyError, TypeError, ValueError, pa.ArrowException) as exc:
        problem = (
            f"its labels cannot be checked ({type(exc).__name__}: {exc}): not a "
            f"complete r2rsim dataset"
        )
    if problem:
        raise InputError(
            f"dataset {run.root}: run {run.run_id}: {problem}: the labels in the "
            f"samples differ from what faults.parquet and runs.parquet give "
            f"(edited after the writing?); refusing to use it (`r2rsim validate "
            f"{run.root}` lists every problem; --no-verify reads it anyway)"
        )


def _floats(arr: pa.ChunkedArray) -> np.ndarray:
    """A numeric Arrow column as float64 (nulls as NaN)."""
    return arr.cast(pa.float64()).to_numpy(zero_copy_only=False)


def read_envelopes(
    run: RunData, columns: list[str], t0: float, t1: float, n_buckets: int, means=()
) -> dict[str, tuple[np.ndarray, ...]]:
    """Each column's min/max envelope (:func:`decimate_minmax`) over [t0, t1], streamed: the
    chunks share bucket edges, so the result is the envelope of the whole window.

    The columns in ``means`` (encoder speeds: a count difference over each sample period,
    quantised to one count, so the envelope of a steady speed is a band between two levels)
    are reduced to each bucket's mean instead, with its minimum and maximum:
    ``(t, mean, min, max)``, ``t`` the mean time of the bucket's samples. The mean of an
    encoder's speeds over a bucket is its count difference over the bucket divided by its
    duration: the speed measured with a longer counting window."""
    parts: dict[str, list] = {c: [] for c in columns}
    for t, values in iter_window(run, columns, t0, t1):
        whole = t.size <= 2 * n_buckets
        # shared by the columns; whole: a bucket per sample
        starts = np.arange(t.size) if whole else _bucket_starts(t, n_buckets, (t0, t1))
        for c, y in values.items():
            if c in means:
                parts[c].append(_bucket_means(t, y, starts))
            elif whole:
                parts[c].append((t, y))
            else:
                idx = _minmax_indices(y, starts)
                parts[c].append((t[idx], y[idx]))
    return {
        c: tuple(
            np.concatenate([p[i] for p in ps]) if ps else np.empty(0)
            for i in range(4 if c in means else 2)
        )
        for c, ps in parts.items()
    }


def _bucket_means(t: np.ndarray, y: np.ndarray, starts: np.ndarray) -> tuple:
    """Mean time, mean, min and max of each bucket's non-NaN samples (NaN for a bucket
    without any)."""
    ok = np.isfinite(y)
    counts = np.add.reduceat(ok.astype(float), starts)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.add.reduceat(np.where(ok, y, 0.0), starts) / counts
        lo = np.fmin.reduceat(y, starts)
        hi = np.fmax.reduceat(y, starts)
    tm = np.add.reduceat(t, starts) / np.diff(np.append(starts, t.size))
    return tm, mean, lo, hi


# ---- the labels of test runs (the report's ROC/PR curves and statistic figures) -----------

#: the samples columns the diagnostics figures take from a test run: the ground truth the
#: harness scores against (:func:`r2rsim.evaluate.harness.run_data`) and the labels the
#: check compares with faults.parquet (:data:`r2rsim.dataset.labels.QUICK_LABELS`, and every
#: ``label.ch.*``)
LABEL_COLUMNS = (
    "k",
    "t_s",
    "label.is_faulty",
    "label.score_mask",
    "label.primary_type",
    "label.severity",
    "label.n_active",
    "label.mode",
)
_NEEDED_LABELS = ("k", "t_s", "label.is_faulty", "label.score_mask", "label.primary_type")


def label_runs(paths, verify: bool = True) -> list:
    """The runs of the test datasets with only the samples columns the diagnostics figures
    use (:data:`LABEL_COLUMNS`), as :class:`r2rsim.dataset.read.Run` objects: what
    :func:`r2rsim.evaluate.harness.read_datasets` gives, without parsing the hundreds of
    channels the figures do not draw. Checked as it checks them (``verify``): every file
    the manifest lists is there with its size, each file read has its sha256 (hashed whole,
    from the bytes parsed), and each run's labels agree with faults.parquet and runs.parquet
    (:func:`r2rsim.dataset.labels.quick_label_problem`). A directory holding datasets one
    level down contributes all of them.

    Raises
    ------
    InputError
        For a missing or incomplete dataset, a file that differs from manifest.json, labels
        that differ from faults.parquet (``verify``), or an unreadable file.
    """
    from ..dataset.paths import SWEEP_MARKER

    out = []
    for p in map(Path, paths):
        if not p.is_dir():
            raise InputError(f"{p}: no such dataset directory")
        if is_dataset_dir(p) or (p / SWEEP_MARKER).is_file():
            dirs = [p]
        else:
            dirs = sorted(d for d in p.iterdir() if d.is_dir() and is_dataset_dir(d))
            if not dirs:
                raise InputError(f"{p}: not an r2rsim dataset and holds none")
        for d in dirs:
            out += _label_runs(open_dataset(d), verify)
    return out


def _label_runs(root: Path, verify: bool) -> list:
    from ..dataset.labels import quick_label_problem
    from ..dataset.read import Run

    with Verifier(root, verify) as v:
        tables = {}
        for name in ("runs.parquet", "faults.parquet"):
            with _reading(root, root / name, v):
                tables[name] = pq.read_table(_whole(root, name, v))
        runs_t, faults_t = tables["runs.parquet"], tables["faults.parquet"]
        for t, name in ((runs_t, "runs.parquet"), (faults_t, "faults.parquet")):
            if "run_id" not in t.column_names:
                raise v.fail(f"{name} has no column run_id: not a complete r2rsim dataset")
        faults = faults_t.to_pandas()
        fault_rows: dict[str, list[dict]] = {}
        for f in faults_t.to_pylist() if verify else ():
            fault_rows.setdefault(str(f["run_id"]), []).append(f)
        out = []
        for info, row in zip(
            runs_t.to_pandas().to_dict("records"), runs_t.to_pylist(), strict=True
        ):
            rid = str(row["run_id"])
            table = _label_table(root, rid, v)
            if verify:
                try:
                    problem = quick_label_problem(table, row, fault_rows.get(rid, []))
                except (KeyError, TypeError, ValueError, pa.ArrowException) as exc:
                    raise v.fail(
                        f"its labels cannot be checked ({type(exc).__name__}: "
                        f"{exc}): not a complete r2rsim dataset (--no-verify reads "
                        f"it anyway)",
                        rid,
                    ) from None
                if problem:
                    raise v.fail(
                        f"{problem}: the labels in the samples differ from what "
                        f"faults.parquet and runs.parquet give (edited after the "
                        f"writing?); refusing to use it (`r2rsim validate {root}` "
                        f"lists every problem; --no-verify reads it anyway)",
                        rid,
                    )
            samples = table.to_pandas().set_index("k", drop=False).sort_index()
            out.append(
                Run(
                    rid,
                    samples,
                    faults[faults["run_id"].astype(str) == rid].reset_index(drop=True),
                    info,
                    root,
                )
            )
        v.check()
    return out


def _label_table(root: Path, run_id: str, v: Verifier) -> pa.Table:
    """The label columns of one run's samples files (each file hashed whole, from the
    bytes parsed)."""
    if run_id in ("", ".", "..") or any(c in run_id for c in "/\\\0"):
        raise v.fail(
            f"run id {run_id!r} in runs.parquet is not a plain name (its samples "
            f"would lie outside samples/)"
        )
    files = sample_files(root, run_id)
    if not files:
        raise v.fail(
            "no samples file (samples/run_id=<id>/part-*.parquet): the directory "
            "is not a complete r2rsim dataset",
            run_id,
        )
    parts = []
    for f in files:
        rel = f.relative_to(root).as_posix()
        with _reading(root, f, v):
            v.listed(rel, run_id)
            data = f.read_bytes()
            v.start(rel, run_id, data)
            pf = pq.ParquetFile(pa.BufferReader(data))
            names = pf.schema_arrow.names
            cols = [
                c
                for c in (*LABEL_COLUMNS, *sorted(n for n in names if n.startswith("label.ch.")))
                if c in names
            ]
            parts.append(pf.read(columns=cols))
        v.check(rel)  # a changed file is told as such, before anything else about it
    table = parts[0] if len(parts) == 1 else pa.concat_tables(parts, promote_options="default")
    missing = [c for c in _NEEDED_LABELS if c not in table.column_names]
    if missing:
        raise v.fail(
            f"the samples have no column {', '.join(missing)}: not a complete r2rsim dataset",
            run_id,
        )
    return table
