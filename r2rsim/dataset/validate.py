"""Check a dataset directory against the rules of docs/dataset.md (§4, §9.1).

Rules: the directory holds exactly the files its manifest lists, with their sizes and
checksums, and no listed path or run id leads outside it
(:func:`r2rsim.dataset.paths.dataset_problems`); the samples' columns are exactly those of
``channels.parquet``; ``k`` counts 0, 1, 2, ...; every ``label.*`` column equals what
:func:`r2rsim.dataset.labels.derive_labels` derives from ``faults.parquet`` and
``runs.parquet`` (so no fault label before an onset); ``onset_k`` is the first sample at or
after the onset; row counts match ``runs.n_samples``; a run that ended early says why and
marks its last sample ``terminated``.

The samples are read in batches of :data:`BATCH_ROWS` rows, and only the columns the rules
need (``k``, ``t_s`` and the labels), so memory does not grow with the length of a run.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

# the label comparison lives in labels.py: every reader checks labels with it too
from .labels import (
    _item,  # noqa: F401 - kept importable from here
    derive_labels,
)
from .labels import check_labels as _check_labels
from .labels import first_difference as _first_difference  # noqa: F401 - kept importable
from .labels import first_list_difference as _first_list_difference  # noqa: F401
from .labels import label_column as _column
from .paths import (
    SWEEP_MARKER,
    dataset_problems,
    inside,
    layout_problem,
    read_json,
    read_parquet_file,
    safe_component,
)
from .writer import (
    VARIABILITY_SCHEMA,
    sha256_file,  # noqa: F401 - kept importable from here
)

#: rows per batch read back from a samples file
BATCH_ROWS = 1 << 13


def validate_dataset(path: str | Path, labels: bool = True) -> list[str]:
    """Every problem found in the dataset at ``path`` (empty: valid).

    Parameters
    ----------
    path : str or Path
        A dataset directory.
    labels : bool
        Also read every label column back and derive it again from faults.parquet (the
        costly part: ~20 ms for a run of 12 000 samples). Without it, the samples are
        checked by their columns, row count and ``k`` only; a sweep's runs are checked
        this way as they are written, and ``r2rsim validate`` checks the finished dataset
        in full.

    Returns
    -------
    list of str
        One message per problem, naming the file or the run.
    """
    root = Path(path)
    if (root / SWEEP_MARKER).is_file():
        return [
            f"{root}: an unfinished sweep (interrupted, or still running): run the same "
            f"`r2rsim sweep` command again to finish it"
        ]
    if not (root / "manifest.json").is_file():
        return [f"{root}: no manifest.json (not an r2rsim dataset?)"]
    # the light check follows the writer's own hashing: sizes are enough to find a file
    # missing or extra (the full check re-reads every byte)
    problems = dataset_problems(root, hashes=labels)
    try:
        manifest = read_json(root / "manifest.json")
    except (OSError, ValueError):
        return problems
    files = manifest.get("files") if isinstance(manifest, dict) else None
    sweep = isinstance(manifest, dict) and isinstance(manifest.get("sweep"), dict)
    for rel in files if isinstance(files, dict) else ():
        why = layout_problem(rel, sweep=sweep) if isinstance(rel, str) else "not a path"
        if why:
            problems.append(f"{rel}: {why} (manifest.json lists it)")
    for name in ("runs", "faults", "channels"):
        if not (root / f"{name}.parquet").is_file():
            return [*problems, f"{name}.parquet: missing"]
    tables = {}
    for name in ("runs", "faults", "channels"):
        try:  # a file that is not Parquet is a problem to list, not a crash
            tables[name] = read_parquet_file(root / f"{name}.parquet")
        except Exception as exc:  # noqa: BLE001 - pyarrow raises several types on bad files
            problems.append(f"{name}.parquet: {_unreadable(exc)}")
    if len(tables) < 3:
        return problems
    runs = tables["runs"].to_pylist()
    faults = tables["faults"].to_pylist()
    channels = tables["channels"].column("channel").to_pylist()
    listed = manifest.get("run_ids") if isinstance(manifest, dict) else None
    if listed is not None and listed != [r["run_id"] for r in runs]:
        problems.append(f"manifest.json run_ids {listed} differ from runs.parquet")
    for run in runs:
        rid = run["run_id"]
        # the run id names a directory: one that is not a plain name leads elsewhere
        if not safe_component(rid):
            problems.append(
                f"run {rid!r}: the run id is not a plain directory name, so its "
                f"samples path leaves samples/"
            )
            continue
        try:
            part = inside(root, f"samples/run_id={rid}/part-0.parquet")
        except Exception:  # noqa: BLE001 - R2RError: resolves outside the dataset
            problems.append(f"run {rid}: samples path leads outside the dataset")
            continue
        if not part.is_file():
            problems.append(f"run {rid}: no samples file samples/run_id={rid}/part-0.parquet")
            continue
        rows = [f for f in faults if f["run_id"] == rid]
        try:
            problems += [
                f"run {rid}: {p}" for p in _check_samples(part, run, rows, channels, labels)
            ]
        except Exception as exc:  # noqa: BLE001 - pyarrow raises several types on bad files
            problems.append(f"run {rid}: samples/run_id={rid}/part-0.parquet: {_unreadable(exc)}")
    return problems + _variability_problems(root, {r["run_id"] for r in runs})


def _variability_problems(root: Path, run_ids: set[str]) -> list[str]:
    """variability.parquet (newer than some datasets, so it may be absent): its columns,
    and rows of the dataset's runs only."""
    path = root / "variability.parquet"
    if not path.is_file():
        return []
    try:
        table = read_parquet_file(path)
    except Exception as exc:  # noqa: BLE001 - pyarrow raises several types on bad files
        return [f"variability.parquet: {_unreadable(exc)}"]
    missing = [n for n in VARIABILITY_SCHEMA.names if n not in table.column_names]
    if missing:
        return [f"variability.parquet: no column {', '.join(missing)}"]
    strays = sorted(set(table.column("run_id").to_pylist()) - run_ids, key=str)
    return (
        [f"variability.parquet: rows of run {strays[0]!r}, which is not in runs.parquet"]
        if strays
        else []
    )


def _unreadable(exc: Exception) -> str:
    """One line for a file pyarrow could not read."""
    first = (str(exc).strip().splitlines() or [""])[0]
    return f"not a readable Parquet file ({type(exc).__name__}: {first})"


def _check_samples(
    part: Path, run: dict, rows: list[dict], channels: list[str], labels: bool = True
) -> list[str]:
    """The problems of one run's samples file, read batch by batch."""
    pf = pq.ParquetFile(part)
    names = pf.schema_arrow.names
    problems = _check_layout(pf, run, channels)
    if "k" not in names or "t_s" not in names:
        return [*problems, "no k or t_s column"]
    if not labels:
        k = pf.read(columns=["k"]).column("k").to_numpy()
        if not np.array_equal(k, np.arange(len(k))):
            problems.append("k does not count 0, 1, 2, ...")
        return problems
    terminated_k = None
    if run["terminated"]:
        if not run["termination_reason"]:
            problems.append("terminated without a termination_reason")
        terminated_k = _last_k(pf)
    sensor_channels = {
        c[len("label.ch.") :].split(".")[0]: c[len("label.ch.") :]
        for c in names
        if c.startswith("label.ch.")
    }
    modes = json.loads(run.get("modes_json") or "[]")
    first_onset = min((f["onset_t_s"] for f in rows), default=None)
    onset_seen = {f["fault_id"]: False for f in rows}
    reported: set[str] = set()  # one message per label column, at its first difference
    k_next, t_last = 0, None
    wanted = ["k", "t_s", *(c for c in names if c.startswith("label."))]
    for batch in pf.iter_batches(batch_size=BATCH_ROWS, columns=wanted):
        k = batch.column("k").to_numpy()
        t = batch.column("t_s").to_numpy()
        m = len(k)
        if m == 0:
            continue
        if "k" not in reported and not np.array_equal(k, np.arange(k_next, k_next + m)):
            bad = int(np.argmax(k != np.arange(k_next, k_next + m)))
            problems.append(f"k is {k[bad]} in row {k_next + bad}; it must count 0, 1, 2, ...")
            reported.add("k")
        k_next += m
        t_last = float(t[-1])
        problems += _check_onsets(rows, k, t, onset_seen)
        want = derive_labels(
            rows,
            k,
            t,
            warmup=run["warmup_s"],
            modes=modes,
            terminated_k=terminated_k,
            sensor_channels=sensor_channels,
        )
        problems += _check_labels(batch, k, want, names, reported)
        if first_onset is not None and "early" not in reported and "label.is_faulty" in names:
            early = _column(batch, "label.is_faulty").astype(bool) & (t < first_onset - 1e-12)
            if early.any():
                problems.append("fault labels before the first onset")
                reported.add("early")
    if (
        run["terminated"]
        and t_last is not None
        and run["termination_t_s"] is not None
        and t_last > run["termination_t_s"] + 1e-9
    ):
        problems.append("samples after termination_t_s")
    return problems


def _check_layout(pf: pq.ParquetFile, run: dict, channels: list[str]) -> list[str]:
    """The samples' columns against channels.parquet, their rows against runs.parquet."""
    problems = []
    names = pf.schema_arrow.names
    if ["run_id", *names] != channels:
        extra = sorted(set(names) - set(channels) - {"run_id"})
        missing = sorted(set(channels) - set(names) - {"run_id"})
        problems.append(
            f"sample columns differ from channels.parquet "
            f"(not listed: {extra[:5]}, absent: {missing[:5]})"
        )
    n = pf.metadata.num_rows
    if n != run["n_samples"]:
        problems.append(f"{n} rows but runs.n_samples = {run['n_samples']}")
    return problems


def _last_k(pf: pq.ParquetFile) -> int | None:
    """The last sample's k (row groups read from the end until one has rows)."""
    for i in reversed(range(pf.num_row_groups)):
        last = pf.read_row_group(i, columns=["k"]).column("k")
        if len(last):
            return int(last[-1].as_py())
    return None


def _check_onsets(rows: list[dict], k: np.ndarray, t: np.ndarray, seen: dict) -> list[str]:
    """Each fault's onset_k against the first sample at or after its onset, in the batch
    (k, t) that holds it (``seen`` marks the faults already checked)."""
    problems = []
    for f in rows:
        if seen[f["fault_id"]]:
            continue
        first = int(np.searchsorted(t, f["onset_t_s"] - 1e-9))
        if first < len(k):
            seen[f["fault_id"]] = True
            if f["onset_k"] != int(k[first]):
                problems.append(
                    f"fault {f['fault_id']} onset_k = {f['onset_k']}, but "
                    f"the first sample at or after its onset is {k[first]}"
                )
    return problems
