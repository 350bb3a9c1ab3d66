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
    ``arrow_type``; chosen once per file, since it runs for every column of every chunk."""
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


def _nonfinite_finder(fields):
    """A function ``find(t, arrays)`` giving ``(t_s, column)`` of the first sample of a chunk
    (its Arrow arrays, as written) where a ``true.``, ``state.``, ``act.`` or ``cmd.`` column
    is not finite, or None; None instead of a function when there is no such column.

    The arrays are the float32 ones written, so a value beyond float32's range (3.4e38),
    stored as inf, counts. A null (a value that is not defined, :func:`undefined_as_null`)
    does not. A finite chunk costs one concatenation and one ``isfinite`` over all the
    checked columns."""
    names = [f.name for f in fields]
    checked = [
        i
        for i, f in enumerate(fields)
        if f.type == pa.float32() and f.name.startswith(("true.", "state.", "act.", "cmd."))
    ]
    if not checked:
        return None

    def find(t, arrays):
        joined = pa.concat_arrays([arrays[i] for i in checked])
        flat = joined.to_numpy(zero_copy_only=False)  # nulls as NaN
        bad = ~np.isfinite(flat)
        if not bad.any():
            return None
        if joined.null_count:
            bad &= ~joined.is_null().to_numpy(zero_copy_only=False)
        bad = bad.reshape(len(checked), -1)
        rows = bad.any(axis=0)
        if not rows.any():
            return None
        r = int(np.argmax(rows))
        return float(np.asarray(t)[r]), names[checked[int(np.argmax(bad[:, r]))]]

    return find


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
        self._schema = None
        self._converters: list = []
        self._pending: list[pa.Table] = []  # chunks of the row group being collected
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
        given as an Arrow array keeps its type)."""
        if self._writer is None:
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
            self._converters = [
                (f.name, _converter(f.type, columns[f.name], f.name)) for f in fields
            ]
            self._find_nonfinite = _nonfinite_finder(fields)
            self._writer = pq.ParquetWriter(
                self._samples,
                self._schema,
                compression="zstd",
                compression_level=3,
                use_dictionary=[f.name for f in fields if pa.types.is_dictionary(f.type)],
                use_byte_stream_split=float_cols,
                write_statistics=True,
            )
        with np.errstate(over="ignore"):  # beyond float32's range is inf, as Arrow casts
            arrays = [convert(columns[name]) for name, convert in self._converters]
        if self.first_nonfinite is None and self._find_nonfinite is not None:
            # chunks come in time order: the first one found is the earliest
            self.first_nonfinite = self._find_nonfinite(columns["t_s"], arrays)
        table = pa.Table.from_arrays(arrays, schema=self._schema)
        self._pending.append(table)
        self._pending_bytes += table.nbytes
        if self._pending_bytes >= ROW_GROUP_BYTES:
            self._flush_row_group()
        self.n_rows += len(columns["t_s"])

    def _flush_row_group(self) -> None:
        """Write the collected chunks as one row group."""
        if self._pending:
            assert self._writer is not None  # opened by the first chunk
            table = pa.concat_tables(self._pending).unify_dictionaries()
            self._writer.write_table(table, row_group_size=table.num_rows)
        self._pending, self._pending_bytes = [], 0

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
        self._pending = []
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
