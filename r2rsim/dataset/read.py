"""Reading datasets back: one :class:`Run` per run, with its samples, fault rows and run
row. The diagnostics and the evaluation harness work on these."""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ..errors import InputError

#: column families a diagnosis algorithm sees by default (docs/dataset.md §2): the time, the
#: recorded readings with their clipping flags, and the set-points. Never ``true.``,
#: ``state.`` or ``label.``.
VISIBLE = ("t_s", "meas.*", "flag.*", "sp.*")
#: added under a protocol that treats drive data as observable: commanded and applied torques
#: and controller internals. Not the ``ctrl.*_seen_*`` channels: they are noise-free copies of
#: the readings including in-loop faults, so they would leak the faults.
DRIVE_DATA = ("cmd.*", "act.*", "ctrl.*")
_LEAKS = ("ctrl.*_seen_*",)


@dataclass
class Run:
    """One run of a dataset.

    Attributes
    ----------
    run_id : str
    samples : pandas.DataFrame
        Every column of the run's samples, indexed by ``k``.
    faults : pandas.DataFrame
        The run's rows of faults.parquet.
    info : dict
        The run's row of runs.parquet.
    path : Path
        The dataset directory.
    """

    run_id: str
    samples: pd.DataFrame
    faults: pd.DataFrame
    info: dict
    path: Path

    def visible(self, drive_data: bool = False) -> pd.DataFrame:
        """The columns an algorithm may use: :data:`VISIBLE`, and with ``drive_data`` also
        :data:`DRIVE_DATA` (without the ``*_seen_*`` channels)."""
        pats = VISIBLE + (DRIVE_DATA if drive_data else ())
        cols = [c for c in self.samples.columns if any(fnmatch.fnmatch(c, p) for p in pats)
                and not any(fnmatch.fnmatch(c, p) for p in _LEAKS)]
        return self.samples[cols]

    @property
    def mode(self) -> str:
        """Operating mode(s) of the run (``runs.operating_mode``, '' when none)."""
        m = self.info.get("operating_mode")
        return m if isinstance(m, str) else ""


def read_runs(path: str | Path) -> list[Run]:
    """Read every run of a dataset directory written by ``r2rsim run``.

    Raises
    ------
    InputError
        If ``path`` is not a dataset.
    """
    path = Path(path)
    if not (path / "runs.parquet").is_file() or not (path / "samples").is_dir():
        raise InputError(f"{path}: not an r2rsim dataset (no runs.parquet or samples/)")
    runs = pd.read_parquet(path / "runs.parquet")
    faults = pd.read_parquet(path / "faults.parquet")
    out = []
    for row in runs.to_dict("records"):
        rid = row["run_id"]
        part = path / "samples" / f"run_id={rid}"
        s = pd.read_parquet(part if part.is_dir() else path / "samples")
        if "run_id" in s.columns:
            s = s[s["run_id"].astype(str) == rid].drop(columns="run_id")
        s = s.set_index("k", drop=False).sort_index()
        out.append(Run(rid, s, faults[faults.run_id == rid].reset_index(drop=True), row, path))
    return out
