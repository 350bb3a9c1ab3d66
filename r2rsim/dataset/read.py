"""Reading datasets back: one :class:`Run` per run, with its samples, fault rows and run
row. The diagnostics and the evaluation harness work on these."""

from __future__ import annotations

import fnmatch
import hashlib
import io
import math
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ..errors import InputError
from .paths import SWEEP_MARKER, read_json

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


#: columns the harness needs in each table
_NEEDED = {"runs.parquet": ("run_id",), "faults.parquet": ("run_id",),
           "samples": ("k", "t_s", "label.is_faulty", "label.score_mask",
                       "label.primary_type")}
_NO_VERIFY = "--no-verify reads it anyway"


def is_dataset_dir(path: Path) -> bool:
    """Whether ``path`` looks like a dataset directory (it has runs.parquet or
    manifest.json), complete or not."""
    return (path / "runs.parquet").is_file() or (path / "manifest.json").is_file()


class _Reader:
    """Reads the files of one dataset, checking each against manifest.json when verifying:
    every listed file exists with its size (all of them, at once), and a file that is read has
    its sha256 (hashed from the same bytes that are parsed, so it is read once)."""

    def __init__(self, root: Path, verify: bool):
        self.root = root
        self.verify = verify
        self.files: dict | None = None
        if verify:
            self._check_manifest()

    def fail(self, msg: str, run: str | None = None) -> InputError:
        return InputError(f"dataset {self.root}: {f'run {run}: ' if run else ''}{msg}")

    def _check_manifest(self) -> None:
        mf = self.root / "manifest.json"
        if not mf.is_file():
            raise self.fail("no manifest.json, so its files cannot be checked: not a "
                            f"complete r2rsim dataset ({_NO_VERIFY})")
        try:
            files = read_json(mf)["files"]
            items = [(str(rel), str(info["sha256"]), info.get("bytes")) for rel, info in
                     files.items()]
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise self.fail(f"manifest.json is not readable ({type(exc).__name__}: "
                            f"{str(exc).splitlines()[0] if str(exc) else ''}); "
                            f"{_NO_VERIFY}") from None
        self.files = {rel: (sha, size) for rel, sha, size in items}
        for rel, (_, size) in self.files.items():
            f = self.root / rel
            part = rel.split("/")
            run = (part[1][len("run_id="):] if len(part) > 2 and part[0] == "samples"
                   and part[1].startswith("run_id=") else None)
            if not f.is_file():
                raise self.fail(f"{rel} is missing (listed in manifest.json): the directory "
                                f"is not a complete r2rsim dataset", run)
            if size is not None and f.stat().st_size != size:
                raise self.fail(f"{rel} has {f.stat().st_size} bytes, manifest.json says "
                                f"{size}: the file was changed or truncated after it was "
                                f"written; refusing to use it (`r2rsim validate "
                                f"{self.root}` lists every problem; {_NO_VERIFY})", run)

    def table(self, rel: str, needed: tuple[str, ...] = (), run: str | None = None
              ) -> pd.DataFrame:
        """A Parquet file of the dataset as a DataFrame (``run``: named in errors)."""
        f = self.root / rel
        if not f.is_file():
            raise self.fail(f"{rel} is missing: the directory is not a complete r2rsim "
                            f"dataset", run)
        source: object = f
        if self.verify:
            if rel not in self.files:
                raise self.fail(f"{rel} is not listed in manifest.json: it was added after "
                                f"the dataset was written; refusing to use it ({_NO_VERIFY})",
                                run)
            data = f.read_bytes()
            if hashlib.sha256(data).hexdigest() != self.files[rel][0]:
                raise self.fail(f"{rel}: checksum differs from manifest.json: the file was "
                                f"changed after it was written; refusing to use it "
                                f"(`r2rsim validate {self.root}` lists every problem; "
                                f"{_NO_VERIFY})", run)
            source = io.BytesIO(data)
        try:
            df = pd.read_parquet(source)
        except Exception as exc:  # noqa: BLE001 - pyarrow raises several types on bad files
            raise self.fail(f"{rel} is not a readable Parquet file ({type(exc).__name__}: "
                            f"{(str(exc).strip().splitlines() or [''])[0]})", run) from None
        missing = [c for c in needed if c not in df.columns]
        if missing:
            raise self.fail(f"{rel} has no column {', '.join(missing)}: not a complete "
                            f"r2rsim dataset", run)
        return df


def _matches(value, wanted) -> bool:
    """Whether a runs.parquet value is one of the wanted ones (numbers to 1e-9 relative)."""
    missing = value is None or (not isinstance(value, (list, dict)) and bool(pd.isna(value)))
    for w in wanted:
        if w is None:
            if missing:  # null: an axis that did not apply to the run (a removed fault)
                return True
        elif missing:
            continue
        elif isinstance(w, (int, float)) and not isinstance(w, bool) and isinstance(
                value, (int, float)) and not isinstance(value, bool):
            if math.isclose(float(value), float(w), rel_tol=1e-9, abs_tol=1e-12):
                return True
        elif value == w:
            return True
    return False


def select_rows(rows: list[dict], where: dict, dataset: Path) -> list[dict]:
    """The rows of runs.parquet whose columns have the wanted values.

    ``where`` maps a column (an axis may be named without its ``axis.`` prefix) to a value
    or a list of values; a string with units (``"3 m/s"``) is compared in SI.

    Raises
    ------
    InputError
        For a column runs.parquet does not have (naming the axis columns it has).
    """
    from ..units import QuantityError, parse_any

    columns = set(rows[0]) if rows else set()
    out = rows
    for key, wanted in where.items():
        col = key if key in columns or not rows else (
            f"axis.{key}" if f"axis.{key}" in columns else key)
        if rows and col not in columns:
            axes = sorted(c[len("axis."):] for c in columns if c.startswith("axis."))
            kind = "none" if "sweep" in columns else "none, not a sweep"
            raise InputError(f"dataset {dataset}: runs.parquet has no column '{key}' to select "
                             f"runs by (axes: {', '.join(axes) or kind}); a selection "
                             f"applies to every dataset named (a bench spec selects per "
                             f"run set)")
        values = wanted if isinstance(wanted, (list, tuple)) else [wanted]
        si = []
        for v in values:
            if isinstance(v, str):
                try:
                    v = parse_any(v)[0]  # "3 m/s" as stored, in SI
                except QuantityError:
                    pass  # a text value ("OC1")
            si.append(v)
        out = [r for r in out if _matches(r.get(col), si)]
    return out


def read_runs(path: str | Path, verify: bool = True, where: dict | None = None) -> list[Run]:
    """Read every run of a dataset directory written by ``r2rsim run`` or ``r2rsim sweep``.

    Parameters
    ----------
    path : str or Path
    verify : bool
        Check the files against manifest.json first: every listed file must exist with its
        size, and the files read (``runs.parquet``, ``faults.parquet`` and the samples of each
        run) must have their sha256. A dataset changed after it was written is refused.
    where : dict, optional
        Only the runs whose runs.parquet columns have these values (:func:`select_rows`):
        ``{"offset": [-10, 10], "seed": 1}`` selects by a sweep's axis ``axis.offset`` and
        by seed.

    Raises
    ------
    InputError
        If ``path`` is not a complete dataset, a file is unreadable, or (``verify``) a file
        differs from the manifest; one line naming the dataset, the file and the problem.
    """
    path = Path(path)
    if not path.is_dir():
        raise InputError(f"{path}: no such dataset directory")
    if (path / SWEEP_MARKER).is_file():
        raise InputError(f"dataset {path}: an unfinished sweep (interrupted, or still "
                         f"running): run the same `r2rsim sweep` command again to finish it")
    if not is_dataset_dir(path) or not (path / "samples").is_dir():
        what = "runs.parquet" if not (path / "runs.parquet").exists() else "samples/"
        raise InputError(f"dataset {path}: {what} is missing: the directory is not a "
                         f"complete r2rsim dataset")
    rd = _Reader(path, verify)
    runs = rd.table("runs.parquet", _NEEDED["runs.parquet"])
    faults = rd.table("faults.parquet", _NEEDED["faults.parquet"])
    out = []
    rows = runs.to_dict("records")
    if where:
        rows = select_rows(rows, where, path)
    for row in rows:
        rid = str(row["run_id"])
        if rid in ("", ".", "..") or any(c in rid for c in "/\\\0"):
            raise rd.fail(f"run id {rid!r} in runs.parquet is not a plain name (its samples "
                          f"would lie outside samples/)")
        part = path / "samples" / f"run_id={rid}"
        if part.is_dir():
            files = sorted(p for p in part.iterdir() if p.is_file() and p.suffix == ".parquet")
        else:  # a samples/ directory without hive partitions (filtered on run_id below)
            files = sorted(p for p in (path / "samples").iterdir()
                           if p.is_file() and p.suffix == ".parquet")
        if not files:
            raise rd.fail(f"no samples file (samples/run_id={rid}/part-0.parquet is "
                          f"missing): the directory is not a complete r2rsim dataset", rid)
        frames = [rd.table(f.relative_to(path).as_posix(), run=rid) for f in files]
        s = frames[0] if len(frames) == 1 else pd.concat(frames, ignore_index=True)
        if "run_id" in s.columns:
            s = s[s["run_id"].astype(str) == rid].drop(columns="run_id")
        missing = [c for c in _NEEDED["samples"] if c not in s.columns]
        if missing:
            raise rd.fail(f"the samples have no column {', '.join(missing)}: not a "
                          f"complete r2rsim dataset", rid)
        s = s.set_index("k", drop=False).sort_index()
        out.append(Run(rid, s, faults[faults.run_id.astype(str) == rid].reset_index(drop=True),
                       row, path))
    return out
