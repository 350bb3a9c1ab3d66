"""Reading datasets back: one :class:`Run` per run, with its samples, fault rows and run
row. The diagnostics and the evaluation harness work on these."""

from __future__ import annotations

import fnmatch
import math
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from ..errors import InputError
from .labels import quick_label_problem
from .verify import NO_VERIFY, Verifier, refuse_unfinished

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
        cols = [
            c
            for c in self.samples.columns
            if any(fnmatch.fnmatch(c, p) for p in pats)
            and not any(fnmatch.fnmatch(c, p) for p in _LEAKS)
        ]
        return self.samples[cols]

    @property
    def mode(self) -> str:
        """Operating mode(s) of the run (``runs.operating_mode``, '' when none)."""
        m = self.info.get("operating_mode")
        return m if isinstance(m, str) else ""


#: columns the harness needs in each table
_NEEDED = {
    "runs.parquet": ("run_id",),
    "faults.parquet": ("run_id",),
    "samples": ("k", "t_s", "label.is_faulty", "label.score_mask", "label.primary_type"),
}


def is_dataset_dir(path: Path) -> bool:
    """Whether ``path`` looks like a dataset directory (it has runs.parquet or
    manifest.json), complete or not."""
    return (path / "runs.parquet").is_file() or (path / "manifest.json").is_file()


def _unreadable(rel: str, exc: Exception) -> str:
    return (
        f"{rel} is not a readable Parquet file ({type(exc).__name__}: "
        f"{(str(exc).strip().splitlines() or [''])[0]})"
    )


class _Reader:
    """Reads the files of one dataset through a :class:`~r2rsim.dataset.verify.Verifier`:
    when verifying, every listed file exists with its size (all of them, at once), and a file
    that is read has its sha256, hashed from the same bytes that are parsed (a samples file's
    in a background thread while they are parsed), so each file is read once."""

    def __init__(self, root: Path, verify: bool):
        self.root = root
        self.verify = verify
        self.v = Verifier(root, verify)

    def fail(self, msg: str, run: str | None = None) -> InputError:
        return self.v.fail(msg, run)

    def arrow(self, rel: str, needed: tuple[str, ...] = (), run: str | None = None) -> pa.Table:
        """A Parquet file of the dataset as an Arrow table (``run``: named in errors); the
        checksum of a samples file (``run`` given) is begun, not waited for: call
        ``self.v.check(rel)`` before using what it holds."""
        f = self.root / rel
        if not f.is_file():
            raise self.fail(
                f"{rel} is missing: the directory is not a complete r2rsim dataset", run
            )
        if run is None:
            data = self.v.read(rel)
        else:
            self.v.listed(rel, run)
            data = f.read_bytes()
            self.v.start(rel, run, data)
        try:
            table = pq.read_table(pa.BufferReader(data))
        except Exception as exc:  # noqa: BLE001 - pyarrow raises several types on bad files
            self.v.check(rel)  # a file changed after it was written is told as such
            raise self.fail(_unreadable(rel, exc), run) from None
        missing = [c for c in needed if c not in table.column_names]
        if missing:
            self.v.check(rel)
            raise self.fail(
                f"{rel} has no column {', '.join(missing)}: not a complete r2rsim dataset", run
            )
        return table

    def table(self, rel: str, needed: tuple[str, ...] = (), run: str | None = None) -> pd.DataFrame:
        """A Parquet file of the dataset as a DataFrame, checked."""
        table = self.arrow(rel, needed, run)
        self.v.check(rel)
        return table.to_pandas()


def _matches(value, wanted) -> bool:
    """Whether a runs.parquet value is one of the wanted ones (numbers to 1e-9 relative)."""
    missing = value is None or (not isinstance(value, (list, dict)) and bool(pd.isna(value)))
    for w in wanted:
        if w is None:
            if missing:  # null: an axis that did not apply to the run (a removed fault)
                return True
        elif missing:
            continue
        elif (
            isinstance(w, (int, float))
            and not isinstance(w, bool)
            and isinstance(value, (int, float))
            and not isinstance(value, bool)
        ):
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
        col = (
            key
            if key in columns or not rows
            else (f"axis.{key}" if f"axis.{key}" in columns else key)
        )
        if rows and col not in columns:
            axes = sorted(c[len("axis.") :] for c in columns if c.startswith("axis."))
            kind = "none" if "sweep" in columns else "none, not a sweep"
            raise InputError(
                f"dataset {dataset}: runs.parquet has no column '{key}' to select "
                f"runs by (axes: {', '.join(axes) or kind}); a selection "
                f"applies to every dataset named (a bench spec selects per "
                f"run set)"
            )
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


def read_runs(
    path: str | Path,
    verify: bool = True,
    where: dict | None = None,
    *,
    check_labels: bool | None = None,
) -> list[Run]:
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
    check_labels : bool, optional
        Check each run's ``label.*`` columns against what
        :func:`r2rsim.dataset.labels.derive_labels` derives from the run's rows of
        faults.parquet and runs.parquet (as ``r2rsim validate`` does): a faults.parquet
        edited after the writing, even with manifest.json re-hashed to match, is refused,
        naming the run, the column, the first differing ``k`` and both values. Default: on
        when ``verify`` is (``verify=False`` skips it too).

    Raises
    ------
    InputError
        If ``path`` is not a complete dataset, a file is unreadable, or (``verify``) a file
        differs from the manifest or a run's labels from its faults; one line naming the
        dataset, the file or run and the problem.
    """
    path = Path(path)
    if not path.is_dir():
        raise InputError(f"{path}: no such dataset directory")
    refuse_unfinished(path)
    if not is_dataset_dir(path) or not (path / "samples").is_dir():
        what = "runs.parquet" if not (path / "runs.parquet").exists() else "samples/"
        raise InputError(
            f"dataset {path}: {what} is missing: the directory is not a complete r2rsim dataset"
        )
    labels = verify if check_labels is None else check_labels
    rd = _Reader(path, verify)
    try:
        return _read_runs(rd, path, where, labels)
    finally:
        rd.v.close()


def _label_problem(t: pa.Table, run_row: dict, fault_rows: list[dict], path: Path) -> str | None:
    """Why a run's labels are refused (:func:`r2rsim.dataset.labels.quick_label_problem`:
    every label faults.parquet determines), or None."""
    try:
        problem = quick_label_problem(t, run_row, fault_rows)
    except Exception as exc:  # noqa: BLE001 - a table lacking a column, of another type
        return (
            f"its labels cannot be checked ({type(exc).__name__}: "
            f"{(str(exc).strip().splitlines() or [''])[0]}): not a complete r2rsim "
            f"dataset ({NO_VERIFY})"
        )
    if problem is None:
        return None
    return (
        f"{problem}: the labels in the samples differ from what faults.parquet and "
        f"runs.parquet give (edited after the writing?); refusing to use it (`r2rsim "
        f"validate {path}` lists every problem; {NO_VERIFY})"
    )


def _read_runs(rd: _Reader, path: Path, where: dict | None, labels: bool) -> list[Run]:
    runs_t = rd.arrow("runs.parquet", _NEEDED["runs.parquet"])
    faults_t = rd.arrow("faults.parquet", _NEEDED["faults.parquet"])
    runs, faults = runs_t.to_pandas(), faults_t.to_pandas()
    # the label check takes the rows as validate does (pyarrow's Python values)
    run_rows = {str(r["run_id"]): r for r in runs_t.to_pylist()} if labels else {}
    fault_rows: dict[str, list[dict]] = {}
    for f in faults_t.to_pylist() if labels else ():
        fault_rows.setdefault(str(f["run_id"]), []).append(f)
    out = []
    rows = runs.to_dict("records")
    if where:
        rows = select_rows(rows, where, path)
    for row in rows:
        run, table = _read_run(rd, path, row, faults)
        if labels:
            problem = _label_problem(
                table, run_rows[run.run_id], fault_rows.get(run.run_id, []), path
            )
            if problem:
                raise rd.fail(problem, run.run_id)
        out.append(run)
    return out


def _read_run(rd: _Reader, path: Path, row: dict, faults: pd.DataFrame) -> tuple[Run, pa.Table]:
    """One run, its samples read (checked against manifest.json when verifying), and the
    samples as Arrow (for the label check)."""
    rid = str(row["run_id"])
    if rid in ("", ".", "..") or any(c in rid for c in "/\\\0"):
        raise rd.fail(
            f"run id {rid!r} in runs.parquet is not a plain name (its samples "
            f"would lie outside samples/)"
        )
    part = path / "samples" / f"run_id={rid}"
    if part.is_dir():
        files = sorted(p for p in part.iterdir() if p.is_file() and p.suffix == ".parquet")
    else:  # a samples/ directory without hive partitions (filtered on run_id below)
        files = sorted(
            p for p in (path / "samples").iterdir() if p.is_file() and p.suffix == ".parquet"
        )
    if not files:
        raise rd.fail(
            f"no samples file (samples/run_id={rid}/part-0.parquet is "
            f"missing): the directory is not a complete r2rsim dataset",
            rid,
        )
    rels = [f.relative_to(path).as_posix() for f in files]
    tables = [rd.arrow(rel, run=rid) for rel in rels]
    t = tables[0] if len(tables) == 1 else pa.concat_tables(tables, promote_options="default")
    if "run_id" in t.column_names:
        t = t.filter(pc.equal(t.column("run_id").cast(pa.string()), rid)).drop_columns("run_id")
    for rel in rels:  # a changed file is told as such, before anything else about it
        rd.v.check(rel)
    missing = [c for c in _NEEDED["samples"] if c not in t.column_names]
    if missing:
        raise rd.fail(
            f"the samples have no column {', '.join(missing)}: not a complete r2rsim dataset", rid
        )
    s = t.to_pandas().set_index("k", drop=False).sort_index()
    return Run(
        rid, s, faults[faults.run_id.astype(str) == rid].reset_index(drop=True), row, path
    ), t
