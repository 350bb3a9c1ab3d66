"""Exporting a dataset to the CSV layouts of TimeEval and TSB-AD (``r2rsim export``).

Anomaly-detection methods are often run in frameworks that read their own file layout:
TimeEval (one CSV per time series, ``timestamp``, the channels and ``is_anomaly``, and a
``datasets.csv`` index) and TSB-AD (one CSV per time series, the channels and ``Label``, with
the training-prefix length and the first anomaly in the file name). This module writes an
r2rsim dataset (a run's or a sweep's) in those layouts, one file per run, reading it with the
verified reader (:func:`r2rsim.dataset.read.read_runs`: checksums and labels) and assigning
the runs to train/val/test with the split ``r2rsim diagnose --data --split seed`` makes
(:func:`r2rsim.evaluate.splits.split_by_seed`); hence its place in the evaluation stage.
docs/dataset.md §13 describes the files.
"""

from __future__ import annotations

import fnmatch
import os
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..dataset.labels import fault_presence
from ..dataset.paths import check_writable, occupied_output
from ..dataset.read import Run, read_runs
from ..errors import InputError
from .splits import ROLES, seed_order_key, split_by_seed

__all__ = [
    "DEFAULT_CHANNELS",
    "FORMATS",
    "PROTECTED",
    "SPLITS",
    "TIMEEVAL_INDEX_COLUMNS",
    "ExportSummary",
    "export_dataset",
]

#: the layouts written
FORMATS = ("timeeval", "tsb-ad")
#: the runs exported: one role of the split, or every run
SPLITS = (*ROLES, "all")
#: the channels exported by default: the measured readings (docs/dataset.md §2)
DEFAULT_CHANNELS = ("meas.*",)
#: column families exported only when a pattern names the family itself (``true.*``, not
#: ``*``): ground truth and hidden states a detector must never see, drive data, labels and
#: flags (docs/dataset.md §2)
PROTECTED = ("true.", "state.", "act.", "cmd.", "label.", "flag.")
#: the noise-free controller copies of the readings, including in-loop faults (they leak the
#: faults): exported only by a pattern that contains ``_seen_``
_SEEN = "ctrl.*_seen_*"
#: the index columns, never a channel (``t_s`` is TimeEval's timestamp)
_INDEX = ("k", "t_s")
#: the collection name of the TimeEval index and the folder of its series
COLLECTION = "r2rsim"
#: the columns of TimeEval's ``datasets.csv`` (its ``DatasetManager`` index), in order
TIMEEVAL_INDEX_COLUMNS = (
    "collection_name",
    "dataset_name",
    "train_path",
    "test_path",
    "dataset_type",
    "datetime_index",
    "split_at",
    "train_type",
    "train_is_normal",
    "input_type",
    "length",
    "dimensions",
    "contamination",
    "num_anomalies",
    "min_anomaly_length",
    "median_anomaly_length",
    "max_anomaly_length",
    "mean",
    "stddev",
    "trend",
    "stationarity",
    "period_size",
)
#: the file listing a TSB-AD export (TSB-AD's runners read its ``file_name`` column)
TSB_AD_LIST = "file_list.csv"
#: the collection and domain fields of a TSB-AD file name
_TSB_COLLECTION, _TSB_DOMAIN = "R2RSIM", "Sensor"


@dataclass
class ExportSummary:
    """What :func:`export_dataset` wrote.

    Attributes
    ----------
    out : Path
        The output directory.
    format : str
    channels : list of str
        The exported channels, in file order.
    label : str
    split : str
        The split name and counts (:meth:`r2rsim.evaluate.splits.Split.describe`).
    files : dict
        Run id -> the file written for it, relative to ``out``.
    roles : dict
        Run id -> its role in the split (``train``, ``val`` or ``test``), for every run
        written (a TimeEval training series outside the selection included).
    exported : list of str
        The run ids of the selection, in the order written.
    """

    out: Path
    format: str
    channels: list[str]
    label: str
    split: str
    files: dict[str, str] = field(default_factory=dict)
    roles: dict[str, str] = field(default_factory=dict)
    exported: list[str] = field(default_factory=list)

    def describe(self) -> str:
        """One line: how many runs were written where."""
        extra = len(self.files) - len(self.exported)
        train = f" and {extra} training series" if extra else ""  # (series: also plural)
        index = "datasets.csv" if self.format == "timeeval" else TSB_AD_LIST
        n = len(self.exported)
        return (
            f"exported {n} run{'s' * (n != 1)}{train} ({len(self.channels)} channels, "
            f"label {self.label}) to {self.out} ({self.format}: {index} and "
            f"{len(self.files)} series files)"
        )


# --------------------------------------------------------------------------- checks


def _check_label(label: str) -> str:
    """``any``, a fault class or a catalogue type (InputError otherwise)."""
    from ..schema.faults import CATALOGUE

    classes = sorted({f.fault_class for f in CATALOGUE.values()})
    if label == "any" or label in classes or label in CATALOGUE:
        return label
    raise InputError(
        f"--label '{label}' is not 'any', a fault class ({', '.join(classes)}) "
        f"or a fault type (`r2rsim list faults`, e.g. sensor.offset)"
    )


def _patterns(channels: str | Sequence[str] | None) -> list[str]:
    if channels is None:
        return list(DEFAULT_CHANNELS)
    items = [channels] if isinstance(channels, str) else list(channels)
    pats = [p.strip() for item in items for p in str(item).split(",") if p.strip()]
    if not pats:
        raise InputError("--channels names no pattern (default: meas.*)")
    return pats


def _admits(pattern: str, column: str) -> bool:
    """Whether ``pattern`` selects ``column``: it matches, and a protected family is named by
    the pattern itself (``true.*`` selects ``true.`` columns, ``*`` does not)."""
    if not fnmatch.fnmatchcase(column, pattern):
        return False
    for prefix in PROTECTED:
        if column.startswith(prefix) and not pattern.startswith(prefix):
            return False
    return not (fnmatch.fnmatchcase(column, _SEEN) and "_seen_" not in pattern)


def select_channels(columns: Sequence[str], patterns: Sequence[str]) -> list[str]:
    """The columns the patterns select, in the samples' order.

    Parameters
    ----------
    columns : sequence of str
        The samples columns.
    patterns : sequence of str
        Glob patterns (:mod:`fnmatch`, case-sensitive). A column of a :data:`PROTECTED`
        family (``true.``, ``state.``, ``act.``, ``cmd.``, ``label.``, ``flag.``) is selected
        only by a pattern that starts with its prefix, and a ``ctrl.*_seen_*`` column only by
        a pattern containing ``_seen_``; ``k`` and ``t_s`` never.

    Returns
    -------
    list of str

    Raises
    ------
    InputError
        A pattern that selects nothing (naming what it would match if named explicitly).
    """
    cols = [c for c in columns if c not in _INDEX]
    for p in patterns:
        if not any(_admits(p, c) for c in cols):
            hidden = [c for c in cols if fnmatch.fnmatchcase(c, p)]
            why = (
                f" (it matches {hidden[0]}, which is exported only when named by its "
                f"family, e.g. --channels '{hidden[0].split('.')[0]}.*')"
                if hidden
                else ""
            )
            raise InputError(f"--channels '{p}' selects no channel of the dataset{why}")
    return [c for c in cols if any(_admits(p, c) for p in patterns)]


def _check_output(out: Path, source: Path) -> None:
    """The output: absent or empty, writable, not inside the dataset (InputError)."""
    if occupied_output(out):
        raise InputError(
            f"output directory '{out}' exists and is not empty; r2rsim export "
            f"writes only into a new or empty directory: choose another with -o"
        )
    src = source.resolve()
    dst = Path(os.path.abspath(out)).resolve()
    if dst == src or src in dst.parents:
        raise InputError(
            f"output directory '{out}' is inside the dataset {source} (a "
            f"dataset holds only its own files): choose another with -o"
        )
    check_writable(out, inside_out=False)


# --------------------------------------------------------------------------- values


def _format_column(values: np.ndarray) -> np.ndarray:
    """A column as CSV text: float32 with 9 significant digits (``%.9g``: read back as a
    float64 and cast to float32 it is the stored value exactly), float64 by ``repr`` (the
    shortest text that reads back exactly), booleans as 0/1, integers as they are; NaN as
    ``nan``."""
    if values.dtype == np.bool_:
        return np.where(values, "1", "0").astype(object)
    if values.dtype.kind in "iu":
        return values.astype(str).astype(object)
    if values.dtype == np.float32:  # (a list comprehension: 2.5x np.char.mod's speed)
        return np.array([f"{v:.9g}" for v in values.astype(np.float64).tolist()], dtype=object)
    if values.dtype.kind == "f":
        return np.array([repr(v) for v in values.astype(np.float64).tolist()], dtype=object)
    raise TypeError(values.dtype)


def _numeric(run: Run, name: str) -> np.ndarray:
    """A samples column as numpy (InputError for a column that is not numbers or booleans)."""
    col = run.samples[name]
    kind = getattr(col.dtype, "kind", "O")
    if kind not in "biuf":
        raise InputError(
            f"channel '{name}' holds {col.dtype} values, not numbers: it cannot "
            f"be a channel of a CSV series (choose others with --channels)"
        )
    return col.to_numpy()


def _fault_rows(run: Run) -> list[dict]:
    """The run's rows of faults.parquet as plain Python values (lists, not arrays)."""
    rows = []
    for rec in run.faults.to_dict("records"):
        for key in ("composed_with", "expected_channels"):
            v = rec.get(key)
            rec[key] = [] if v is None or (isinstance(v, float) and v != v) else list(v)
        rows.append(rec)
    return rows


def _label(run: Run, label: str) -> np.ndarray:
    """The 0/1 label of every sample: ``label.is_faulty`` for ``any``; else where a fault of
    that type or class is present (the same presence rule, :func:`fault_presence`)."""
    if label == "any":
        return run.samples["label.is_faulty"].to_numpy(dtype=bool)
    t = run.samples["t_s"].to_numpy(dtype=float)
    faults, present = fault_presence(_fault_rows(run), t)
    keep = [i for i, f in enumerate(faults) if f.type == label or f.kind.fault_class == label]
    return np.asarray(present[keep].any(axis=0)) if keep else np.zeros(len(t), dtype=bool)


@dataclass
class _Series:
    run: Run
    rows: np.ndarray  # which samples are written (all, or the scored ones)
    label: np.ndarray  # 0/1 of the rows written


def _anomalies(label: np.ndarray) -> list[int]:
    """The lengths of the runs of 1 (TimeEval's anomalies), in order."""
    y = np.concatenate([[0], label.astype(np.int8), [0]])
    d = np.diff(y)
    return (np.flatnonzero(d == -1) - np.flatnonzero(d == 1)).tolist()


def _write_csv(path: Path, s: _Series, channels: list[str], first: str | None, last: str) -> None:
    """One series: [``first`` = the time in s], the channels, ``last`` = the 0/1 label."""
    cols = []
    if first is not None:
        cols.append(_format_column(s.run.samples["t_s"].to_numpy(dtype=np.float64)[s.rows]))
    cols += [_format_column(_numeric(s.run, c)[s.rows]) for c in channels]
    cols.append(np.where(s.label, "1", "0").astype(object))
    header = ([first] if first is not None else []) + channels + [last]
    with open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(",".join(header) + "\n")
        step = 65536
        for start in range(0, len(s.label), step):
            part = [c[start : start + step] for c in cols]
            f.write("".join(",".join(r) + "\n" for r in zip(*part, strict=True)))


def _num(v: float) -> str:
    return "" if not np.isfinite(v) else repr(float(v))


def _stats(s: _Series, channels: list[str]) -> tuple[str, str]:
    """TimeEval's ``mean`` and ``stddev``: the channels' means and standard deviations
    (ddof 1, NaN skipped), averaged over the channels."""
    means, sds = [], []
    for c in channels:
        x = _numeric(s.run, c)[s.rows].astype(np.float64)
        x = x[np.isfinite(x)]
        means.append(x.mean() if len(x) else np.nan)
        sds.append(x.std(ddof=1) if len(x) > 1 else np.nan)
    m, sd = np.array(means), np.array(sds)
    return (
        _num(m[np.isfinite(m)].mean()) if np.isfinite(m).any() else "",
        _num(sd[np.isfinite(sd)].mean()) if np.isfinite(sd).any() else "",
    )


# --------------------------------------------------------------------------- layouts


def _timeeval(
    tmp: Path,
    series: dict[str, _Series],
    selected: list[str],
    trainer: dict[str, str | None],
    channels: list[str],
    summary: ExportSummary,
) -> None:
    (tmp / COLLECTION).mkdir()
    for rid, s in series.items():
        rel = f"{COLLECTION}/{rid}.csv"
        _write_csv(tmp / rel, s, channels, "timestamp", "is_anomaly")
        summary.files[rid] = rel
    lines = [",".join(TIMEEVAL_INDEX_COLUMNS)]
    for rid in selected:
        s = series[rid]
        train = trainer.get(rid) or rid  # semi-supervised: trained on another run
        semi = train != rid
        lengths = _anomalies(s.label)
        n = len(s.label)
        mean, sd = _stats(s, channels)
        row = {
            "collection_name": COLLECTION,
            "dataset_name": rid,
            "train_path": summary.files[train] if semi else "",
            "test_path": summary.files[rid],
            "dataset_type": "synthetic",
            "datetime_index": "False",
            "split_at": "",
            "train_type": "semi-supervised" if semi else "unsupervised",
            "train_is_normal": "True" if semi else "False",
            "input_type": "univariate" if len(channels) == 1 else "multivariate",
            "length": str(n),
            "dimensions": str(len(channels)),
            "contamination": repr(float(s.label.sum()) / n) if n else "",
            "num_anomalies": str(len(lengths)),
            "min_anomaly_length": str(min(lengths, default=0)),
            "median_anomaly_length": str(int(np.median(lengths)) if lengths else 0),
            "max_anomaly_length": str(max(lengths, default=0)),
            "mean": mean,
            "stddev": sd,
            "trend": "",
            "stationarity": "",
            "period_size": "",
        }
        lines.append(",".join(row[c] for c in TIMEEVAL_INDEX_COLUMNS))
    (tmp / "datasets.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")


def tsb_ad_name(number: int, width: int, train: int, first: int) -> str:
    """A TSB-AD file name: ``<NNN>_R2RSIM_id_<N>_Sensor_tr_<train>_1st_<first>.csv``.

    TSB-AD's runners read the training-prefix length as the third field from the end
    (``name.split('.')[0].split('_')[-3]``) and drop nothing else from the name.
    """
    return (
        f"{number:0{width}d}_{_TSB_COLLECTION}_id_{number}_{_TSB_DOMAIN}_tr_{train}_1st_{first}.csv"
    )


def _tsb_ad(
    tmp: Path,
    series: dict[str, _Series],
    selected: list[str],
    roles: dict[str, str],
    channels: list[str],
    summary: ExportSummary,
) -> None:
    width = max(3, len(str(len(selected))))
    lines = ["file_name,run_id,split,length,num_anomalies"]
    for i, rid in enumerate(selected, start=1):
        s = series[rid]
        ones = np.flatnonzero(s.label)
        first = int(ones[0]) if len(ones) else len(s.label)
        name = tsb_ad_name(i, width, first, first)
        _write_csv(tmp / name, s, channels, None, "Label")
        summary.files[rid] = name
        lines.append(f"{name},{rid},{roles[rid]},{len(s.label)},{len(_anomalies(s.label))}")
    (tmp / TSB_AD_LIST).write_text("\n".join(lines) + "\n", encoding="utf-8")


# --------------------------------------------------------------------------- entry point


def export_dataset(
    path: str | Path,
    out: str | Path,
    format: str,
    *,
    channels: str | Sequence[str] | None = None,
    label: str = "any",
    split: str = "all",
    where: dict | None = None,
    drop_warmup: bool = False,
    verify: bool = True,
) -> ExportSummary:
    """Write a dataset's runs as TimeEval or TSB-AD CSV files.

    Parameters
    ----------
    path : str or Path
        A dataset directory written by ``r2rsim run`` or ``r2rsim sweep``. It is read with
        :func:`r2rsim.dataset.read.read_runs`: its files are checked against manifest.json
        and its labels against faults.parquet.
    out : str or Path
        The output directory: it must not exist, or be empty. The files are written into a
        temporary directory next to it and moved into place when all are complete, so a
        failure or an interruption leaves nothing.
    format : {"timeeval", "tsb-ad"}
        ``timeeval``: ``datasets.csv`` (TimeEval's index) and ``r2rsim/<run_id>.csv`` per run
        (``timestamp`` in s, the channels, ``is_anomaly``). ``tsb-ad``:
        ``<NNN>_R2RSIM_id_<N>_Sensor_tr_<T>_1st_<F>.csv`` per run (the channels, ``Label``)
        and ``file_list.csv`` (``file_name`` and the run id).
    channels : str or sequence of str, optional
        Glob patterns of the samples columns to export (default ``meas.*``);
        :func:`select_channels` says which families only an explicit pattern selects.
    label : str
        ``any`` (default): ``label.is_faulty``. A fault class (``sensor``, ``actuator``,
        ``dancer``, ``process``) or type (``sensor.offset``): 1 where a fault of that class or
        type is present (onset <= t < end, the rule of ``label.is_faulty``).
    split : {"all", "train", "val", "test"}
        The runs exported, by their role in the split ``r2rsim diagnose --data --split seed``
        makes of the same runs (:func:`r2rsim.evaluate.splits.split_by_seed`): every faulty
        run is a test run. Default: every run.
    where : dict, optional
        Only the runs with these runs.parquet values (as ``read_runs(where=)``); the split is
        made of these runs, as ``r2rsim diagnose --where`` makes it.
    drop_warmup : bool
        Leave out the samples outside ``label.score_mask`` (the warm-up): the rows written
        are then exactly those r2rsim's own scoring uses. Default: every sample is written.
    verify : bool
        Check the dataset against its manifest and its labels (``--no-verify`` skips it).

    Returns
    -------
    ExportSummary

    Raises
    ------
    InputError
        An unknown format, split or label, a channel pattern that selects nothing, a split
        role without runs, an output that exists and is not empty (nothing is written), or
        a dataset the reader refuses.
    """
    if format not in FORMATS:
        raise InputError(f"--format '{format}' is not one of {', '.join(FORMATS)}")
    if split not in SPLITS:
        raise InputError(f"--split '{split}' is not one of {', '.join(SPLITS)}")
    label = _check_label(label)
    patterns = _patterns(channels)
    path, out = Path(path), Path(out)
    if not path.is_dir():
        raise InputError(f"{path}: no such dataset directory")
    _check_output(out, path)

    runs, sp, roles, selected = _selected_runs(path, split, where, verify)
    chans = select_channels(list(runs[0].samples.columns), patterns)
    for r in selected:
        missing = [c for c in chans if c not in r.samples.columns]
        if missing:
            raise InputError(f"run {r.run_id} of {path} has no channel {missing[0]}")
        for c in chans:
            _numeric(r, c)
    trainer = _trainers(sp, selected) if format == "timeeval" else {}
    position = {r.run_id: i for i, r in enumerate(runs)}
    order = [r.run_id for r in selected]  # then the training series outside the selection
    order += sorted(
        {t for t in trainer.values() if t is not None} - set(order), key=position.__getitem__
    )
    by_id = {r.run_id: r for r in runs}
    series = {}
    for rid in order:
        r = by_id[rid]
        rows = (
            r.samples["label.score_mask"].to_numpy(dtype=bool)
            if drop_warmup
            else np.ones(len(r.samples), dtype=bool)
        )
        series[rid] = _Series(r, rows, _label(r, label)[rows])

    summary = ExportSummary(
        out,
        format,
        chans,
        label,
        sp.describe(),
        roles={rid: roles[rid] for rid in order},
        exported=[r.run_id for r in selected],
    )
    _write(out, series, trainer, roles, summary)
    return summary


def _selected_runs(path: Path, split: str, where: dict | None, verify: bool):
    """The dataset's runs (checked), their split, each run's role and the runs of ``split``."""
    runs = read_runs(path, verify=verify, where=where or None)
    if where and not runs:
        raise InputError(
            f"no run of {path} has " + ", ".join(f"{k} = {v}" for k, v in where.items())
        )
    if not runs:
        raise InputError(f"dataset {path} holds no run")
    sp = split_by_seed(runs)
    roles = {r.run_id: role for role in ROLES for r in getattr(sp, role)}
    selected = [r for r in runs if split == "all" or roles[r.run_id] == split]
    if not selected:
        raise InputError(
            f"--split {split}: no run of {path} has that role ({sp.describe()}; "
            f"every faulty run is a test run)"
        )
    return runs, sp, roles, selected


def _trainers(sp, selected: list[Run]) -> dict[str, str | None]:
    """TimeEval's training series of each selected run: the first train run of its operating
    condition in the split's order (fault-free by construction), or None."""
    first_train: dict[str, Run] = {}
    for r in sorted(sp.train, key=seed_order_key):
        first_train.setdefault(r.mode, r)
    trainer: dict[str, str | None] = {}
    for r in selected:
        t = first_train.get(r.mode)
        trainer[r.run_id] = t.run_id if t is not None else None
    return trainer


def _write(out: Path, series: dict, trainer: dict, roles: dict, summary: ExportSummary) -> None:
    """Write the files into a temporary directory next to ``out`` and move them into place
    when all are written; on any failure (or Ctrl-C) the temporary directory is removed."""
    dest = Path(os.path.abspath(out))  # (``-o .``: its parent, not itself, holds the tmp)
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=dest.parent, prefix=f".{dest.name}.export-"))
    try:
        if summary.format == "timeeval":
            _timeeval(tmp, series, summary.exported, trainer, summary.channels, summary)
        else:
            _tsb_ad(tmp, series, summary.exported, roles, summary.channels, summary)
        os.chmod(tmp, 0o755)  # mkdtemp's 0700 is for the temporary directory only
        if not dest.exists():
            os.rename(tmp, dest)
            return
        _move_into(tmp, dest, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _move_into(tmp: Path, dest: Path, out: Path) -> None:
    """Move the files of ``tmp`` into the empty directory ``dest`` (not the directory itself:
    a shell whose working directory is ``dest``, ``-o .``, keeps seeing it), then remove
    ``tmp``; on a failure, take back what was moved (InputError if ``dest`` was filled
    meanwhile)."""
    if occupied_output(dest):
        raise InputError(
            f"output directory '{out}' was filled while the export ran; nothing was written"
        )
    moved = []
    try:
        for entry in sorted(tmp.iterdir()):
            os.rename(entry, dest / entry.name)
            moved.append(dest / entry.name)
    except BaseException:
        for p in moved:  # only what this export wrote
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p)
            else:
                p.unlink()
        raise
    tmp.rmdir()
