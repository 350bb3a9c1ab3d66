"""Write a run as a self-describing Parquet dataset (DESIGN.md §4.3, fdd-benchmarks.md §6).

Layout::

    <dataset>/
      runs.parquet  channels.parquet  faults.parquet  events.parquet  manifest.json
      samples/run_id=<id>/part-0.parquet
      scenario/<name>.yaml  scenario/<line>.yaml

Everything is written into a temporary sibling directory and moved into place only when the
run is complete, so a failed run leaves no partial dataset.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .._version import __version__
from ..errors import InputError, R2RError

SCHEMA_VERSION = "0.1"

FAULTS_SCHEMA = pa.schema([
    ("run_id", pa.string()), ("fault_id", pa.string()), ("fault_type", pa.string()),
    ("fault_class", pa.string()), ("target_id", pa.string()), ("component_path", pa.string()),
    ("onset_t_s", pa.float64()), ("onset_k", pa.int64()), ("profile", pa.string()),
    ("ramp_s", pa.float64()), ("end_t_s", pa.float64()), ("magnitude", pa.float64()),
    ("magnitude_unit", pa.string()), ("magnitude_rel", pa.float64()),
    ("params_json", pa.string()), ("expected_channels", pa.list_(pa.string())),
    ("composed_with", pa.list_(pa.string())), ("sampled_from", pa.string()),
])

EVENTS_SCHEMA = pa.schema([
    ("run_id", pa.string()), ("t_s", pa.float64()), ("kind", pa.string()),
    ("component", pa.string()), ("state", pa.string()), ("message", pa.string()),
    ("values_json", pa.string()),
])


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class DatasetWriter:
    """Streams one run's samples into a temporary dataset directory, then commits it.

    Parameters
    ----------
    output : Path
        Final dataset directory.
    run_id : str
    metadata : dict
        String key-value metadata stored in every Parquet file (``r2rsim.*`` keys).
    """

    def __init__(self, output: Path, run_id: str, metadata: dict[str, str]):
        self.output = Path(output)
        if self.output.exists() and not (self.output / "manifest.json").exists():
            if any(self.output.iterdir()):
                raise InputError(f"output directory '{self.output}' exists and is not an "
                                 f"r2rsim dataset; choose another with -o")
        self.run_id = run_id
        self.metadata = {k: str(v) for k, v in metadata.items()}
        self.tmp = self.output.parent / f".{self.output.name}.tmp-{os.getpid()}"
        if self.tmp.exists():
            shutil.rmtree(self.tmp)
        (self.tmp / "samples" / f"run_id={run_id}").mkdir(parents=True)
        (self.tmp / "scenario").mkdir()
        self._writer = None
        self._schema = None
        self.n_rows = 0

    def write_chunk(self, columns: dict[str, np.ndarray]) -> None:
        """Append one chunk of samples (same columns in the same order every time)."""
        if self._writer is None:
            fields = []
            for name, arr in columns.items():
                if name in ("k",):
                    fields.append(pa.field(name, pa.int64()))
                elif name == "t_s":
                    fields.append(pa.field(name, pa.float64()))
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
            self._writer = pq.ParquetWriter(
                self.tmp / "samples" / f"run_id={self.run_id}" / "part-0.parquet",
                self._schema, compression="zstd", compression_level=3,
                use_dictionary=[f.name for f in fields if pa.types.is_dictionary(f.type)],
                use_byte_stream_split=float_cols, write_statistics=True,
            )
        arrays = []
        for f in self._schema:
            arr = columns[f.name]
            if pa.types.is_dictionary(f.type):
                arrays.append(pa.array(arr.astype(str)).dictionary_encode().cast(f.type))
            elif pa.types.is_list(f.type):
                arrays.append(pa.array(arr, type=f.type))
            else:
                arrays.append(pa.array(arr, type=f.type, from_pandas=False))
        self._writer.write_table(pa.Table.from_arrays(arrays, schema=self._schema))
        self.n_rows += len(columns["t_s"])

    def write_table(self, name: str, table: pa.Table) -> None:
        meta = dict(table.schema.metadata or {})
        meta.update({k.encode(): v.encode() for k, v in self.metadata.items()})
        pq.write_table(table.replace_schema_metadata(meta), self.tmp / f"{name}.parquet",
                       compression="zstd")

    def write_text(self, relpath: str, text: str) -> None:
        (self.tmp / relpath).write_text(text, encoding="utf-8")

    def commit(self, manifest_extra: dict, check=None) -> Path:
        """Close the files, write the manifest with checksums, run ``check(directory)`` (a
        list of problems; any problem aborts) and move the dataset in place."""
        if self._writer is not None:
            self._writer.close()
        files = sorted(p for p in self.tmp.rglob("*") if p.is_file())
        manifest = {
            "schema_version": SCHEMA_VERSION,
            "r2rsim_version": __version__,
            "python_version": platform.python_version(),
            "numpy_version": np.__version__,
            "pyarrow_version": pa.__version__,
            **manifest_extra,
            "files": {str(p.relative_to(self.tmp)): {"sha256": sha256_file(p),
                                                      "bytes": p.stat().st_size}
                      for p in files},
        }
        (self.tmp / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True))
        problems = check(self.tmp) if check is not None else []
        if problems:
            raise R2RError("the dataset failed its own validation (a bug in r2rsim; please "
                           "report it): " + "; ".join(problems[:5]))
        if self.output.exists():
            trash = self.output.parent / f".{self.output.name}.old-{os.getpid()}"
            os.replace(self.output, trash)
            os.replace(self.tmp, self.output)
            shutil.rmtree(trash, ignore_errors=True)
        else:
            self.output.parent.mkdir(parents=True, exist_ok=True)
            os.replace(self.tmp, self.output)
        return self.output

    def abort(self) -> None:
        """Remove the temporary directory (no partial output is left behind)."""
        try:
            if self._writer is not None:
                self._writer.close()
        except Exception:  # noqa: BLE001 - cleaning up after a failure
            pass
        shutil.rmtree(self.tmp, ignore_errors=True)
