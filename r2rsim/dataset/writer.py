"""Write a run as a self-describing Parquet dataset (docs/dataset.md).

Layout::

    <dataset>/
      runs.parquet  channels.parquet  faults.parquet  events.parquet  variability.parquet
      manifest.json
      samples/run_id=<id>/part-0.parquet
      scenario/<name>.yaml  scenario/<line>.yaml

The one list of these files is :mod:`r2rsim.dataset.paths`'s; the cleanup and ``r2rsim
validate`` use it too. Everything is written into a temporary sibling directory
``.<dataset>.tmp-<pid>`` and moved into place only when the run is complete, so a failed run
leaves no partial dataset. Every path is checked to stay inside that directory, an existing
directory is replaced only if it is verifiably an r2rsim dataset and the caller asked for
it, and the temporaries of dead processes are cleaned up (:mod:`r2rsim.dataset.paths`).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import platform
import shutil
import signal
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .._version import __version__
from ..errors import InputError, R2RError
from .paths import (
    ACTIVE,
    RUN_COPIES,
    RUN_TABLES,
    check_writable,
    clean_stale,
    dataset_problems,
    inside,
    layout_problem,
    occupied_output,
    remove_dataset,
    safe_component,
    samples_file,
    sha256_file,
)

SCHEMA_VERSION = "0.1"

FAULTS_SCHEMA = pa.schema(
    [
        ("run_id", pa.string()),
        ("fault_id", pa.string()),
        ("fault_type", pa.string()),
        ("fault_class", pa.string()),
        ("target_id", pa.string()),
        ("component_path", pa.string()),
        ("onset_t_s", pa.float64()),
        ("onset_k", pa.int64()),
        ("profile", pa.string()),
        ("ramp_s", pa.float64()),
        ("end_t_s", pa.float64()),
        ("magnitude", pa.float64()),
        ("magnitude_unit", pa.string()),
        ("magnitude_rel", pa.float64()),
        ("params_json", pa.string()),
        ("expected_channels", pa.list_(pa.string())),
        ("composed_with", pa.list_(pa.string())),
        ("sampled_from", pa.string()),
    ]
)

EVENTS_SCHEMA = pa.schema(
    [
        ("run_id", pa.string()),
        ("t_s", pa.float64()),
        ("kind", pa.string()),
        ("component", pa.string()),
        ("state", pa.string()),
        ("message", pa.string()),
        ("values_json", pa.string()),
    ]
)

#: variability.parquet: the values a run's ``variability:`` drew (ground truth; plug-ins
#: never see it). ``source`` is ``run`` (friction, sensor calibration) or ``roll``; ``roll``
#: counts an unwind's rolls from 0 (the one at t = 0); ``loaded_t_s`` is when it was loaded.
VARIABILITY_SCHEMA = pa.schema(
    [
        ("run_id", pa.string()),
        ("source", pa.string()),
        ("component", pa.string()),
        ("roll", pa.int32()),
        ("parameter", pa.string()),
        ("unit", pa.string()),
        ("nominal", pa.float64()),
        ("value", pa.float64()),
        ("loaded_t_s", pa.float64()),
    ]
)


#: raw column data collected before it is written as one row group. The solver's chunks
#: can be a few rows long (they end at every event); one row group each would make the
#: Parquet footer, which the writer keeps in memory until it closes, grow with run length.
ROW_GROUP_BYTES = 16 << 20
#: the samples' codec (docs/dataset.md, "Compression"; benchmarks/bench_codecs.py measures
#: the others)
COMPRESSION = "zstd"
COMPRESSION_LEVEL = 3

__all__ = [
    "DatasetWriter",
    "EVENTS_SCHEMA",
    "FAULTS_SCHEMA",
    "SCHEMA_VERSION",
    "VARIABILITY_SCHEMA",
    "check_output",
    "sha256_file",
]


def check_output(output: str | Path, overwrite: bool = False, *, hashes: bool = True) -> None:
    """Refuse an output directory that a run must not write to.

    The place must be writable (:func:`r2rsim.dataset.paths.check_writable`: not under a
    file, not read-only, not a mount point). A directory that does not exist, or an empty
    one, is fine. An existing r2rsim dataset
    (:func:`r2rsim.dataset.paths.dataset_problems` finds nothing) is replaced only with
    ``overwrite``. Anything else (a file, a symbolic link, a directory holding files that
    r2rsim did not write, or a dataset changed since) is never replaced.

    Parameters
    ----------
    output : str or Path
        The dataset directory.
    overwrite : bool
        Replace an existing r2rsim dataset.
    hashes : bool
        Compare the sha256 of an existing dataset's files too, not only their sizes.

    Raises
    ------
    InputError
        Saying why and what to do.
    """
    out = Path(output)
    check_writable(out, inside_out=False)
    if not occupied_output(out):
        return  # absent or empty: filled
    problems = dataset_problems(out, hashes=hashes)
    if problems:
        more = f" and {len(problems) - 1} more" if len(problems) > 1 else ""
        raise InputError(
            f"output directory '{out}' exists and is not an r2rsim dataset "
            f"({problems[0]}{more}); r2rsim replaces only a directory holding "
            f"exactly a dataset it wrote: choose another directory with -o"
        )
    if not overwrite:
        raise InputError(
            f"output directory '{out}' exists (an r2rsim dataset); pass --overwrite to replace it"
        )


@contextlib.contextmanager
def _signals_deferred():
    """Hold SIGINT/SIGTERM until the block is done, so that a rename and the note of it
    are not separated by an interrupt (the handler runs right after)."""
    sigs = {signal.SIGINT, signal.SIGTERM}
    try:
        old = signal.pthread_sigmask(signal.SIG_BLOCK, sigs)
    except (AttributeError, OSError, ValueError):  # no POSIX signals
        yield
        return
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def undefined_as_null(name: str) -> bool:
    """Whether a column's non-finite values mean "not defined here" and are written as null:
    ``state.<element>.tension_ratio`` (T_hi/T_lo, undefined when the lower span is slack) and
    ``state.splice_joint<n>.lead_m`` (no joint on the line). Nowhere else does a dataset hold
    null in a ``state.`` column, and no ``true.``/``state.``/``act.``/``cmd.`` column holds a
    non-finite value in a run that ended well (:func:`_nonfinite_finder`)."""
    return name.startswith("state.") and (
        name.endswith(".tension_ratio")
        or (name.startswith("state.splice_joint") and name.endswith(".lead_m"))
    )


def _converter(arrow_type: pa.DataType, example, name: str = ""):
    """A function turning one chunk's column (like ``example``) into an Arrow array of
    ``arrow_type``: the columns :class:`_Collector` does not keep as numpy (Arrow arrays,
    lists, values of another type than the field's), converted chunk by chunk."""
    if pa.types.is_dictionary(arrow_type):
        return lambda a: pa.array(a, type=pa.string()).dictionary_encode().cast(arrow_type)
    if isinstance(example, pa.Array):
        return lambda a: a
    if arrow_type == pa.float32() and undefined_as_null(name):

        def to_float32_or_null(a):
            x = np.asarray(a).astype(np.float32, copy=False)
            undefined = ~np.isfinite(x)
            return pa.array(x, mask=undefined) if undefined.any() else pa.array(x)

        return to_float32_or_null
    if arrow_type == pa.float32():
        # numpy's cast is several times faster than Arrow's checked one
        return lambda a: pa.array(np.asarray(a).astype(np.float32, copy=False))
    if pa.types.is_list(arrow_type):
        return lambda a: pa.array(a, type=arrow_type)
    return lambda a: pa.array(a, type=arrow_type, from_pandas=False)


def _bitmap_bytes(n: int) -> int:
    """Bytes of an Arrow bitmap of ``n`` bits (a bool array's values, a validity buffer)."""
    return (n + 7) // 8


#: the most distinct strings a dictionary column holds (its indices are int8)
_INT8_CODES = 127


class _Collector:
    """One column's chunks of the row group being collected, as numpy arrays where the column
    allows it, built into one Arrow array per row group (:meth:`finish`).

    An Arrow array per column and chunk costs a few microseconds whatever the chunk's
    length, and the solver's chunks can be a few rows long (they end at every event); the
    numpy arrays are copied (the solver may reuse its buffers) and concatenated once. Each
    chunk's size is counted as the Arrow array it replaces would count it (``nbytes``), so
    that a row group ends where it did when every chunk was converted to Arrow.

    Parameters
    ----------
    field : pyarrow.Field
        The column as written.
    example
        The column of the first chunk (chooses numpy or Arrow).
    """

    def __init__(self, field: pa.Field, example):
        self.field = field
        self.name = field.name
        t = field.type
        self.undefined = t == pa.float32() and undefined_as_null(field.name)
        if isinstance(example, (pa.Array, list)):
            self.kind = "arrow"
        elif pa.types.is_dictionary(t) and t == pa.dictionary(pa.int8(), pa.string()):
            self.kind = "dict"
        elif t == pa.float32():
            self.kind = "float32"
        elif pa.types.is_boolean(t) or pa.types.is_integer(t) or pa.types.is_floating(t):
            self.kind = "numeric"
            self.dtype = np.dtype(t.to_pandas_dtype())
        else:
            self.kind = "arrow"
        self.convert = _converter(t, example, field.name)
        self.chunks: list = []
        self.masks: list = []  # float32 columns written with nulls: where, per chunk (or None)

    def add(self, a) -> int:
        """Keep one chunk's column; the bytes its Arrow array would hold (``nbytes``)."""
        kind = self.kind
        if kind == "numeric" and isinstance(a, np.ndarray) and a.dtype == self.dtype:
            x = a.copy()  # the caller's buffer may be reused for the next chunk
            self.chunks.append(x)
            return _bitmap_bytes(len(x)) if x.dtype == bool else x.nbytes
        if kind == "float32":
            x = np.array(a, dtype=np.float32)  # a copy; float64 beyond 3.4e38 is inf
            self.chunks.append(x)
            if not self.undefined:
                return x.nbytes
            undefined = ~np.isfinite(x)
            has = bool(undefined.any())
            self.masks.append(undefined if has else None)
            return x.nbytes + (_bitmap_bytes(len(x)) if has else 0)
        if kind == "dict" and isinstance(a, np.ndarray):
            coded = _dictionary_codes(a)
            if coded is not None:
                self.chunks.append(coded)
                codes, values = coded
                return codes.nbytes + pa.array(values, type=pa.string()).nbytes
        # anything else: an Arrow array per chunk, of the field's type
        arr = self.convert(a)
        self.chunks.append(arr)
        if self.undefined:
            self.masks.append(None)
        return arr.nbytes

    def finish(self) -> pa.Array | pa.ChunkedArray:
        """The row group's column as one Arrow array (its chunks are let go)."""
        chunks, masks = self.chunks, self.masks
        self.chunks, self.masks = [], []
        if any(isinstance(c, pa.Array) for c in chunks):
            # a chunk that did not fit the numpy path (another dtype, a value that is not
            # a string): every chunk as Arrow, as the writer did before (rare)
            return pa.chunked_array(
                [self._as_arrow(c, masks[i] if masks else None) for i, c in enumerate(chunks)],
                type=self.field.type,
            )
        if self.kind == "dict":
            return _dictionary_array(chunks)
        mask = None
        if any(m is not None for m in masks):
            mask = np.concatenate(
                [
                    np.zeros(len(c), bool) if m is None else m
                    for c, m in zip(chunks, masks, strict=True)
                ]
            )
        x = chunks[0] if len(chunks) == 1 else np.concatenate(chunks)
        if mask is not None:
            return pa.array(x, mask=mask)
        return pa.array(x) if self.kind == "float32" else pa.array(x, type=self.field.type)

    def _as_arrow(self, c, mask) -> pa.Array:
        if isinstance(c, pa.Array):
            return c
        if self.kind == "dict":
            return _dictionary_array([c])
        if mask is not None:
            return pa.array(c, mask=mask)
        return pa.array(c, type=self.field.type)


def _dictionary_codes(a: np.ndarray) -> tuple[np.ndarray, list[str]] | None:
    """A string column's chunk as int8 codes into its distinct values, in the order they
    first occur (as Arrow's ``dictionary_encode`` orders them); None when a value is not a
    string (None, a number) or there are more than 127: Arrow converts those, and raises
    where it did before."""
    values = a.tolist()
    first = dict.fromkeys(values)
    if len(first) > _INT8_CODES or not all(type(v) is str for v in first):
        return None
    lookup = {v: i for i, v in enumerate(first)}
    codes = np.fromiter(map(lookup.__getitem__, values), dtype=np.int8, count=len(values))
    return codes, list(first)


def _dictionary_array(
    chunks: list[tuple[np.ndarray, list[str]]],
) -> pa.DictionaryArray | pa.ChunkedArray:
    """The chunks' codes as one dictionary array, its dictionary the distinct strings in the
    order they first occur in the row group (what ``unify_dictionaries`` of the chunks'
    own dictionaries gave)."""
    merged: dict[str, int] = {}
    parts = []
    for codes, values in chunks:
        remap = np.array([merged.setdefault(v, len(merged)) for v in values], dtype=np.int8)
        parts.append(remap[codes] if len(remap) else codes)
    if len(merged) > _INT8_CODES:  # too many for int8: unify_dictionaries raises, as it did
        return pa.chunked_array([_dictionary_array([c]) for c in chunks])
    codes = parts[0] if len(parts) == 1 else np.concatenate(parts)
    return pa.DictionaryArray.from_arrays(pa.array(codes), pa.array(list(merged), pa.string()))


def _nonfinite_column(c) -> int | None:
    """The first row of one chunk's column (float32 as written: numpy, or an Arrow array)
    whose value is not finite; a null does not count."""
    if isinstance(c, np.ndarray):
        # one pass: a float64 sum of float32 values cannot overflow, so it is finite
        # exactly when every value is
        with np.errstate(invalid="ignore"):  # inf - inf: nan, found below
            total = c.sum(dtype=np.float64)
        if math.isfinite(total):
            return None
        return int(np.argmax(~np.isfinite(c)))
    flat = c.to_numpy(zero_copy_only=False)  # nulls as NaN
    bad = ~np.isfinite(flat)
    if c.null_count:
        bad &= ~c.is_null().to_numpy(zero_copy_only=False)
    return int(np.argmax(bad)) if bad.any() else None


def _checked(field: pa.Field) -> bool:
    """Whether a column must be finite in a run that ended well (:func:`undefined_as_null`:
    a value that is not defined there is written as null, and never counts)."""
    return field.type == pa.float32() and field.name.startswith(("true.", "state.", "act.", "cmd."))


class DatasetWriter:
    """Streams one run's samples into a temporary dataset directory, then commits it.

    Parameters
    ----------
    output : Path
        Final dataset directory. It must not exist, be empty, or (with ``overwrite``) be an
        r2rsim dataset (:func:`check_output`).
    run_id : str
        The run's id; a single directory name (``samples/run_id=<run_id>/``).
    metadata : dict
        String key-value metadata stored in every Parquet file (``r2rsim.*`` keys).
    overwrite : bool
        Replace an existing r2rsim dataset at ``output``.
    clean : bool
        Clean up the temporaries of dead processes next to ``output`` first
        (:func:`r2rsim.dataset.paths.clean_stale`); a sweep does it once for all its runs.

    Raises
    ------
    InputError
        For an output directory that may not be written to.
    R2RError
        For a run id that is not a single directory name.
    """

    def __init__(
        self,
        output: Path,
        run_id: str,
        metadata: dict[str, str],
        *,
        overwrite: bool = False,
        clean: bool = True,
    ):
        self.output = Path(output)
        self.overwrite = overwrite
        if not safe_component(run_id) or not safe_component(self.output.name):
            raise R2RError(
                f"run id '{run_id}' or dataset name '{self.output.name}' is not a "
                f"single directory name"
            )
        check_output(self.output, overwrite, hashes=False)  # commit() hashes what it replaces
        self.run_id = run_id
        self.metadata = {k: str(v) for k, v in metadata.items()}
        self.tmp = self.output.parent / f".{self.output.name}.tmp-{os.getpid()}"
        self._writer: pq.ParquetWriter | None = None
        self._schema: pa.Schema | None = None
        # the columns of the row group being collected, and its size as Arrow counts it
        self._columns: list[_Collector] = []
        self._checked: list[int] = []  # the columns that must be finite (_checked)
        self._pending_rows = 0
        self._pending_bytes = 0
        self._trash: Path | None = None  # the dataset being replaced, during the swap
        self._committed = False
        self.n_rows = 0
        #: (t_s, column) of the first sample with a true./state./act./cmd. value that is not
        #: finite as written (float32: beyond 3.4e38 is inf); None while there is none
        self.first_nonfinite: tuple[float, str] | None = None
        # parent directories this writer creates, removed again if the run fails
        self._made: list[Path] = []
        p = self.output.parent
        while not p.exists() and p != p.parent:
            self._made.append(p)
            p = p.parent
        if not self._made and clean:
            clean_stale(self.output.parent)
        if self.tmp.resolve() in ACTIVE:
            raise R2RError(f"another writer of this process is writing {self.output}")
        if self.tmp.exists():  # left by a dead process that had this pid (clean_stale kept it)
            raise R2RError(
                f"'{self.tmp}' exists and is not r2rsim's own temporary directory; move it away"
            )
        self.tmp.mkdir(parents=True)
        ACTIVE.add(self.tmp.resolve())
        self._samples = inside(self.tmp, samples_file(run_id))
        self._samples.parent.mkdir(parents=True)

    def write_chunk(self, columns: dict[str, np.ndarray | pa.Array]) -> None:
        """Append one chunk of samples (same columns in the same order every time; a column
        given as an Arrow array keeps its type).

        The chunk is kept (numpy arrays, copied; float columns already as float32) until
        the row group it belongs to holds :data:`ROW_GROUP_BYTES`, and then written as one
        Arrow table. Its values that are not finite are looked for now, so that
        :attr:`first_nonfinite` holds the earliest one seen so far.
        """
        if self._writer is None:
            self._open(columns)
        n = len(columns["t_s"])
        size = 0
        with np.errstate(over="ignore"):  # beyond float32's range is inf, as Arrow casts
            for col in self._columns:
                size += col.add(columns[col.name])
        if self.first_nonfinite is None and self._checked:
            # chunks come in time order: the first one found is the earliest
            self.first_nonfinite = self._find_nonfinite(columns["t_s"])
        self._pending_rows += n
        self._pending_bytes += size
        if self._pending_bytes >= ROW_GROUP_BYTES:
            self._flush_row_group()
        self.n_rows += n

    def _open(self, columns: dict) -> None:
        """Choose the schema from the first chunk and open the samples file."""
        fields = []
        for name, arr in columns.items():
            if name in ("k",):
                fields.append(pa.field(name, pa.int64()))
            elif name == "t_s":
                fields.append(pa.field(name, pa.float64()))
            elif isinstance(arr, pa.Array):
                fields.append(pa.field(name, arr.type))
            elif isinstance(arr, list):
                fields.append(pa.field(name, pa.list_(pa.string())))
            elif arr.dtype.kind in "iu":
                fields.append(pa.field(name, pa.from_numpy_dtype(arr.dtype)))
            elif arr.dtype == bool:
                fields.append(pa.field(name, pa.bool_()))
            elif arr.dtype.kind in "OU":
                fields.append(pa.field(name, pa.dictionary(pa.int8(), pa.string())))
            else:
                fields.append(pa.field(name, pa.float32()))
        meta = {k.encode(): v.encode() for k, v in self.metadata.items()}
        self._schema = pa.schema(fields, metadata=meta)
        float_cols = [f.name for f in fields if f.type in (pa.float32(), pa.float64())]
        self._columns = [_Collector(f, columns[f.name]) for f in fields]
        # a column written with nulls for its undefined values has no other non-finite one
        self._checked = [
            i
            for i, c in enumerate(self._columns)
            if _checked(c.field) and not (c.undefined and c.kind == "float32")
        ]
        self._writer = pq.ParquetWriter(
            self._samples,
            self._schema,
            compression=COMPRESSION,
            compression_level=COMPRESSION_LEVEL,
            use_dictionary=[f.name for f in fields if pa.types.is_dictionary(f.type)],
            use_byte_stream_split=float_cols,
            write_statistics=True,
        )

    def _find_nonfinite(self, t) -> tuple[float, str] | None:
        """``(t_s, column)`` of the first sample of the chunk just added where a checked
        column is not finite as written (float32: beyond 3.4e38 is inf; a null does not
        count), the first such column on a tie; None if there is none."""
        best: tuple[int, str] | None = None
        for i in self._checked:
            col = self._columns[i]
            r = _nonfinite_column(col.chunks[-1])
            if r is not None and (best is None or r < best[0]):
                best = (r, col.name)
        if best is None:
            return None
        return float(np.asarray(t)[best[0]]), best[1]

    def _flush_row_group(self) -> None:
        """Write the collected chunks as one row group: one Arrow array per column."""
        if self._pending_rows:  # chunks without rows make no row group (Parquet refuses one)
            assert self._writer is not None  # opened by the first chunk
            # column by column, each column's chunks let go as it is built: memory stays
            # within the row group and one column more
            arrays = [c.finish() for c in self._columns]
            table = pa.Table.from_arrays(arrays, schema=self._schema)
            if any(isinstance(a, pa.ChunkedArray) for a in arrays):
                table = table.unify_dictionaries()  # chunks converted one by one (rare)
            self._writer.write_table(table, row_group_size=table.num_rows)
        for col in self._columns:  # what is left: chunks without rows
            col.chunks, col.masks = [], []
        self._pending_rows, self._pending_bytes = 0, 0

    def write_table(self, name: str, table: pa.Table) -> None:
        """Write ``<name>.parquet``, one of the layout's tables
        (:data:`r2rsim.dataset.paths.RUN_TABLES`), with the metadata."""
        if name not in RUN_TABLES:  # the cleanup and validate know only the layout's files
            raise R2RError(
                f"'{name}.parquet' is not a table of the dataset layout ({', '.join(RUN_TABLES)})"
            )
        meta = dict(table.schema.metadata or {})
        meta.update({k.encode(): v.encode() for k, v in self.metadata.items()})
        pq.write_table(
            table.replace_schema_metadata(meta),
            inside(self.tmp, f"{name}.parquet"),
            compression="zstd",
        )

    def write_text(self, relpath: str, text: str) -> None:
        """Write a text file at ``relpath`` inside the dataset: a copy of an input file,
        ``scenario/<file>`` (:func:`r2rsim.dataset.paths.layout_problem`)."""
        if relpath.split("/")[0] not in RUN_COPIES or layout_problem(relpath, sweep=False):
            raise R2RError(
                f"'{relpath}' is not where the dataset layout keeps a copy of an "
                f"input file ({', '.join(d + '/' for d in RUN_COPIES)})"
            )
        path = inside(self.tmp, relpath)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")

    def commit(self, manifest_extra: dict, check=None) -> Path:
        """Close the files, write the manifest with checksums, run ``check(directory)`` (a
        list of problems; any problem aborts) and move the dataset in place.

        An existing directory at the output is checked again here, since it may have
        changed during the run: it must still be empty or absent, or (``overwrite``) an
        r2rsim dataset, which is replaced.
        """
        if self._writer is not None:
            self._flush_row_group()
            self._writer.close()
        files = sorted(p for p in self.tmp.rglob("*") if p.is_file())
        manifest = {
            "schema_version": SCHEMA_VERSION,
            "r2rsim_version": __version__,
            "python_version": platform.python_version(),
            "numpy_version": np.__version__,
            "pyarrow_version": pa.__version__,
            **manifest_extra,
            "files": {
                p.relative_to(self.tmp).as_posix(): {
                    "sha256": sha256_file(p),
                    "bytes": p.stat().st_size,
                }
                for p in files
            },
        }
        inside(self.tmp, "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True))
        problems = check(self.tmp) if check is not None else []
        if problems:
            raise R2RError(
                "the dataset failed its own validation (a bug in r2rsim; please "
                "report it): " + "; ".join(problems[:5])
            )
        out = self.output
        if out.is_symlink() or (out.exists() and (not out.is_dir() or any(out.iterdir()))):
            # raises unless an r2rsim dataset to replace; hashed below, once it is moved
            check_output(out, self.overwrite, hashes=False)
            trash = out.parent / f".{out.name}.old-{os.getpid()}"
            with _signals_deferred():
                os.rename(out, trash)
                self._trash = trash
            # checked again where nobody else writes: what is removed is what was checked
            problems = dataset_problems(trash)
            if problems:
                self._restore()
                raise InputError(
                    f"output directory '{out}' changed during the run and is "
                    f"no longer an r2rsim dataset ({problems[0]}); it is left "
                    f"as it was"
                )
        with _signals_deferred():
            try:
                os.rename(self.tmp, out)  # onto nothing, or an empty directory
            except OSError as exc:
                raise R2RError(
                    f"cannot move the dataset into '{out}' ({exc.strerror}): was "
                    f"it filled during the run?"
                ) from None
            self._committed = True
            ACTIVE.discard(self.tmp.resolve())
        if self._trash is not None:
            remove_dataset(self._trash)
            self._trash = None
        return out

    def _restore(self) -> None:
        """Put the dataset being replaced back in place (the swap did not finish)."""
        if self._trash is not None and not self.output.exists():
            with _signals_deferred():
                os.rename(self._trash, self.output)
                self._trash = None

    def abort(self) -> None:
        """Remove the temporary directory and the parent directories this writer made, and
        put back a dataset it was replacing (no partial output is left behind)."""
        try:
            if self._writer is not None:
                self._writer.close()
        except Exception:  # noqa: BLE001 - cleaning up after a failure
            pass
        for col in self._columns:
            col.chunks, col.masks = [], []
        if not self._committed:
            try:
                self._restore()
            except OSError:
                pass  # clean_stale() puts it back on the next run
            shutil.rmtree(self.tmp, ignore_errors=True)
            ACTIVE.discard(self.tmp.resolve())
        for p in self._made:  # deepest first; only while empty
            try:
                p.rmdir()
            except OSError:
                break
