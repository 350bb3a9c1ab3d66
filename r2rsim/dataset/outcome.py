"""What counts as a failed run, from its row of runs.parquet, and how many runs of a sweep's
dataset failed (docs/sweeps.md §7 "Failures")."""

from __future__ import annotations

import math
from pathlib import Path

from .paths import read_manifest, read_parquet_file


def failed_reason(row: dict) -> str | None:
    """Why a run with data counts as failed (None: it did not fail). A solver failure or
    states that are not finite fail; a web break or an emptied roll do not.

    Parameters
    ----------
    row : dict
        The run's row of runs.parquet (``termination_reason``, ``nonfinite_from_t_s``).
    """
    reason = row.get("termination_reason")
    if isinstance(reason, str) and reason.startswith("solver_failure"):
        return reason
    t = row.get("nonfinite_from_t_s")
    if t is not None and not (isinstance(t, float) and math.isnan(t)):
        return f"states not finite from t = {t:g} s"
    return None


def sweep_failures(root: str | Path) -> tuple[list[str], int] | None:
    """The ids of a sweep dataset's failed runs and its number of runs (None: not a sweep's
    dataset). A failed run has no data (a row of failures.parquet) or data that
    :func:`failed_reason` rejects (a row of runs.parquet)."""
    root = Path(root)
    manifest, _ = read_manifest(root)
    sweep = (manifest or {}).get("sweep")
    if not isinstance(sweep, dict):
        return None
    failed = sweep.get("failed")
    if not isinstance(failed, list):  # written before r2rsim listed them: derived
        failed = list(sweep.get("failed_without_data") or [])
        try:
            rows = read_parquet_file(root / "runs.parquet").to_pylist()
        except Exception:  # noqa: BLE001 - unreadable: validate reports it
            rows = []
        failed += [r["run_id"] for r in rows if failed_reason(r)]
    return [str(r) for r in failed], int(sweep.get("n_runs") or 0)
