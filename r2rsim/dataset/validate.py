"""Check a dataset directory against the rules of DESIGN.md §4.3 / fdd-benchmarks.md §6.4.

Rules: files listed in the manifest exist with their checksums; the samples' columns are
exactly those of ``channels.parquet``; every ``label.*`` column equals what
:func:`r2rsim.dataset.labels.derive_labels` derives from ``faults.parquet`` and
``runs.parquet`` (so no fault label before an onset); ``onset_k`` is the first sample at or
after the onset; row counts match ``runs.n_samples``; a run that ended early says why and
marks its last sample ``terminated``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from .labels import derive_labels
from .writer import sha256_file


def validate_dataset(path: str | Path) -> list[str]:
    """Every problem found in the dataset at ``path`` (empty: valid)."""
    root = Path(path)
    problems: list[str] = []
    manifest_path = root / "manifest.json"
    if not manifest_path.exists():
        return [f"{root}: no manifest.json (not an r2rsim dataset?)"]
    manifest = json.loads(manifest_path.read_text())
    for rel, info in manifest.get("files", {}).items():
        f = root / rel
        if not f.exists():
            problems.append(f"{rel}: listed in manifest.json but missing")
        elif sha256_file(f) != info["sha256"]:
            problems.append(f"{rel}: checksum differs from manifest.json")
    runs = pq.read_table(root / "runs.parquet").to_pylist()
    faults = pq.read_table(root / "faults.parquet").to_pylist()
    channels = pq.read_table(root / "channels.parquet").column("channel").to_pylist()
    for run in runs:
        rid = run["run_id"]
        part = root / "samples" / f"run_id={rid}" / "part-0.parquet"
        if not part.exists():
            problems.append(f"run {rid}: no samples file {part.relative_to(root)}")
            continue
        table = pq.read_table(part)
        cols = ["run_id", *table.column_names]
        if cols != channels:
            extra = sorted(set(cols) - set(channels))
            missing = sorted(set(channels) - set(cols))
            problems.append(f"run {rid}: sample columns differ from channels.parquet "
                            f"(not listed: {extra[:5]}, absent: {missing[:5]})")
        n = table.num_rows
        if n != run["n_samples"]:
            problems.append(f"run {rid}: {n} rows but runs.n_samples = {run['n_samples']}")
        k = table.column("k").to_numpy()
        t = table.column("t_s").to_numpy()
        rows = [f for f in faults if f["run_id"] == rid]
        for f in rows:
            first = int(np.searchsorted(t, f["onset_t_s"] - 1e-9))
            if first < n and f["onset_k"] != int(k[first]):
                problems.append(f"run {rid}: fault {f['fault_id']} onset_k = {f['onset_k']}"
                                f", but the first sample at or after its onset is {k[first]}")
        if run["terminated"]:
            if not run["termination_reason"]:
                problems.append(f"run {rid}: terminated without a termination_reason")
            if n and t[-1] > run["termination_t_s"] + 1e-9:
                problems.append(f"run {rid}: samples after termination_t_s")
        sensor_channels = {c[len("label.ch."):].split(".")[0]: c[len("label.ch."):]
                           for c in table.column_names if c.startswith("label.ch.")}
        modes = json.loads(run.get("modes_json") or "[]")
        want = derive_labels(rows, k, t, warmup=run["warmup_s"], modes=modes,
                             terminated_k=int(k[-1]) if run["terminated"] and n else None,
                             sensor_channels=sensor_channels)
        for name, expected in want.items():
            if name not in table.column_names:
                problems.append(f"run {rid}: label column {name} missing")
                continue
            got = table.column(name).to_pylist()
            exp = expected if isinstance(expected, list) else np.asarray(expected).tolist()
            if name == "label.severity":
                same = np.allclose(np.asarray(got, float), np.asarray(exp, float), atol=1e-6)
            else:
                same = got == exp
            if not same:
                bad = next(i for i, (a, b) in enumerate(zip(got, exp, strict=True))
                           if a != b and not (isinstance(a, float) and math.isclose(a, b)))
                problems.append(f"run {rid}: {name} at k = {k[bad]} is {got[bad]!r}; "
                                f"faults.parquet gives {exp[bad]!r}")
        if rows:
            first_onset = min(f["onset_t_s"] for f in rows)
            early = table.column("label.is_faulty").to_numpy(zero_copy_only=False) & (
                t < first_onset - 1e-12)
            if early.any():
                problems.append(f"run {rid}: fault labels before the first onset")
    return problems
