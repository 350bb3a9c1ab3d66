"""``r2rsim bench``: a diagnostic benchmark from a YAML spec (scenarios × seeds × plug-ins ×
metrics), compared with a stored baseline results file.

A spec names *studies* (each: the scenarios and seeds of its train, val and test runs), the
*methods* (registered plug-ins with parameters), the evaluation settings, and which metrics
to compare with the baseline file at which absolute tolerance. The runs are simulated (or
reused from ``workdir``), every method is evaluated by :func:`r2rsim.evaluate.harness.evaluate`
on every study, and a metric *regresses* when it is worse than the baseline by more than its
tolerance, in the direction the metric is better (:data:`r2rsim.evaluate.harness.METRICS`).
See docs/diagnostics.md for the file format.
"""

from __future__ import annotations

import hashlib
import math
import os
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import pandas as pd
from pydantic import Field, model_validator

from ._version import __version__
from .dataset.read import Run, read_runs
from .diagnostics.registry import call, check_param, get, unknown_parameter
from .errors import InputError
from .evaluate.harness import METRICS, Evaluation, evaluate
from .evaluate.metrics import DETECTION_WINDOW_S
from .evaluate.results import write_results as _write_results
from .limits import MAX_BOOTSTRAP, MAX_SEED, MAX_VUS_BUFFER_S
from .schema.line import Id, Strict
from .schema.loader import _validate, read_yaml
from .schema.quantities import Time

KEY = ["study", "label", "condition", "fault", "magnitude", "metric"]


class RunSet(Strict):
    """Runs of one scenario file, one per seed; or the runs of a sweep file, optionally
    selected by their axis values."""

    scenario: str | None = Field(None, description="scenario file, relative to the spec")
    seeds: Annotated[list[Annotated[int, Field(ge=0, le=MAX_SEED)]], Field(min_length=1)] | None = (
        Field(None, description="root seeds (with scenario), each once")
    )
    sweep: str | None = Field(None, description="sweep file, relative to the spec")
    where: dict[str, Any] = Field(
        default_factory=dict,
        description="with sweep: only the runs with these axis values "
        "(axis name or runs.parquet column: value or list of values)",
    )

    @model_validator(mode="after")
    def _one_source(self):
        if (self.scenario is None) == (self.sweep is None):
            raise ValueError("give either scenario (with seeds) or sweep")
        if self.scenario is not None and self.seeds is None:
            raise ValueError("a scenario needs its seeds")
        if self.sweep is not None and self.seeds is not None:
            raise ValueError(
                "a sweep has its own seeds (give no seeds); select its runs with where"
            )
        if self.scenario is not None and self.where:
            raise ValueError("where selects runs of a sweep, not of a scenario")
        return self


class Study(Strict):
    """Train (healthy), val (healthy, threshold calibration) and test runs."""

    name: Id
    train: Annotated[list[RunSet], Field(min_length=1)]
    val: list[RunSet] = Field(default_factory=list)
    test: Annotated[list[RunSet], Field(min_length=1)]


class MethodSpec(Strict):
    """A registered plug-in and its parameters; ``label`` tells apart two settings of one
    method (default: the method name)."""

    method: str
    params: dict[str, Any] = Field(default_factory=dict)
    label: str | None = None

    @property
    def key(self) -> str:
        return self.label or self.method


class EvaluationSettings(Strict):
    alpha: Annotated[float, Field(gt=0, lt=1)] = 0.01
    persistence: Annotated[int, Field(ge=1)] = 1
    grace: Annotated[Time, Field(ge=0)] = 0.0
    detection_window: Annotated[Time, Field(gt=0)] | None = Field(
        DETECTION_WINDOW_S,
        description="W: a fault counts as detected only within W of "
        "being fully developed; null: up to its end",
    )
    own_threshold: Literal["val", "fit"] = Field(
        "val",
        description="the plug-ins' own thresholds: recalibrated on the val runs at "
        "alpha, or as their fit set them",
    )
    n_boot: Annotated[int, Field(ge=0, le=MAX_BOOTSTRAP)] = 200
    seed: Annotated[int, Field(ge=0, le=MAX_SEED)] = Field(0, description="seed of the bootstrap")
    drive_data: bool = Field(False, description="also show plug-ins cmd.*, act.*, ctrl.*")
    mode_strata: bool = Field(False, description="also report per-regime (label.mode) strata")
    window: Literal["fault", "steady"] = Field(
        "fault", description="steady: also report dr/pd/dd over severity-1 samples"
    )
    isolation: bool = Field(False, description="score rank_channels against label.ch.*")
    vus_buffer: Annotated[Time, Field(ge=0, le=MAX_VUS_BUFFER_S)] | None = Field(
        None, description="report vus_pr with buffers up to this duration"
    )


class Compare(Strict):
    """The baseline results file and the metrics checked against it, each with an absolute
    tolerance."""

    baseline: str = Field(description="baseline results CSV, relative to the spec")
    metrics: Annotated[dict[str, Annotated[float, Field(ge=0)]], Field(min_length=1)]


class BenchSpec(Strict):
    name: Id
    description: str = ""
    duration: Annotated[Time, Field(gt=0)] | None = Field(
        None, description="overrides every scenario's duration"
    )
    studies: Annotated[list[Study], Field(min_length=1)]
    methods: Annotated[list[MethodSpec], Field(min_length=1)]
    evaluation: EvaluationSettings = Field(default_factory=EvaluationSettings)
    compare: Compare | None = None


def _spec_file(spec_path: Path, rel: str, what: str, ypath: str) -> Path:
    """A file the spec names (relative to it), which must be a regular file."""
    p = spec_path.parent / rel
    if not p.exists():
        raise InputError(f"{what} file '{rel}' not found", file=str(spec_path), path=ypath)
    if not p.is_file():  # a directory, /dev/zero, a FIFO: there, but nothing to read
        raise InputError(
            f"{what} file '{rel}' is not a regular file", file=str(spec_path), path=ypath
        )
    return p


def load_spec(path: str | Path) -> BenchSpec:
    """Load and check a benchmark spec: scenario and sweep files exist, seeds are listed
    once, methods are registered and their parameters are theirs, and a baseline file that
    exists is one that ``--update`` wrote (:func:`read_baseline`).

    Raises
    ------
    InputError
        Naming the file, the YAML path and the problem.
    """
    path = Path(path)
    spec = _validate(BenchSpec, read_yaml(path), str(path))
    f = str(path)
    names = [s.name for s in spec.studies]
    if len(set(names)) != len(names):
        raise InputError("study names must be unique", file=f, path="studies")
    for i, st in enumerate(spec.studies):
        for role in ("train", "val", "test"):
            for j, rs in enumerate(getattr(st, role)):
                key = "scenario" if rs.scenario is not None else "sweep"
                seeds = rs.seeds or []
                for k, seed in enumerate(seeds):  # the same run twice would count twice
                    if seeds.index(seed) != k:
                        raise InputError(
                            f"seed {seed} is listed twice",
                            file=f,
                            path=f"studies[{i}].{role}[{j}].seeds[{k}]",
                        )
                _spec_file(path, getattr(rs, key), key, f"studies[{i}].{role}[{j}].{key}")
                if key == "sweep" and spec.duration is not None:
                    raise InputError(
                        "duration overrides scenarios, not sweeps: set the "
                        "sweep's duration in the sweep file (set: {duration: "
                        "...})",
                        file=f,
                        path="duration",
                    )
    if spec.compare is not None and (path.parent / spec.compare.baseline).exists():
        # read now, not after the simulations (a missing one: run_bench, by --update)
        read_baseline(_spec_file(path, spec.compare.baseline, "baseline", "compare.baseline"), f)
    for name in spec.compare.metrics if spec.compare else ():
        if name not in METRICS:
            raise InputError(
                f"unknown metric '{name}' (known: {', '.join(METRICS)})",
                file=f,
                path=f"compare.metrics.{name}",
            )
    labels = [m.key for m in spec.methods]
    if len(set(labels)) != len(labels):
        raise InputError(
            "two methods have the same label; give one a 'label'", file=f, path="methods"
        )
    for i, m in enumerate(spec.methods):
        try:
            cls = get(m.method)
        except InputError as exc:
            raise InputError(exc.message, file=f, path=f"methods[{i}].method") from None
        for k in m.params:
            problem = unknown_parameter(cls, k)
            if problem:
                raise InputError(problem, file=f, path=f"methods[{i}].params.{k}")
            try:
                m.params[k] = check_param(cls, k, m.params[k])
            except InputError as exc:
                raise InputError(exc.message, file=f, path=f"methods[{i}].params.{k}") from None
    return spec


#: the columns of a baseline file, in this order (docs/diagnostics.md §7)
BASELINE_COLUMNS = [*KEY, "value"]


def read_baseline(path: str | Path, spec_file: str | None = None) -> pd.DataFrame:
    """Read a baseline results file, checked to be one that ``r2rsim bench --update``
    writes.

    Parameters
    ----------
    path : str or Path
        The baseline CSV.
    spec_file : str, optional
        The spec naming it, for messages.

    Returns
    -------
    pandas.DataFrame
        The columns :data:`BASELINE_COLUMNS`; ``magnitude`` and ``value`` are numbers.

    Raises
    ------
    InputError
        Naming the spec file and ``compare.baseline``: the file cannot be read, its first line
        is not the header of a baseline, or it is not a CSV of numbers.
    """

    def bad(why: str) -> InputError:
        return InputError(f"'{path}' {why}", file=spec_file, path="compare.baseline")

    header = ",".join(BASELINE_COLUMNS)
    try:
        with open(path, "rb") as fh:
            first = fh.readline(len(header) + 3).decode("utf-8", "replace").strip()
    except OSError as exc:
        raise bad(f"cannot be read ({exc.strerror or exc})") from None
    if first.removeprefix("\ufeff") != header:  # (a BOM from a spreadsheet is fine)
        raise bad(
            f"is not a baseline file written by `r2rsim bench --update` (its first "
            f"line is not '{header}')"
        )
    try:  # names as written: a label '007' is not the number 7
        table = pd.read_csv(path, encoding="utf-8-sig", dtype=str, keep_default_na=False)
    except (OSError, ValueError) as exc:  # pandas' ParserError, UnicodeDecodeError
        first = (str(exc).strip().splitlines() or [""])[0]
        raise bad(f"is not a readable CSV ({type(exc).__name__}: {first})") from None
    for col in ("magnitude", "value"):
        try:  # an empty cell is no value (how --update writes NaN)
            table[col] = pd.to_numeric(table[col].where(table[col] != "")).astype(float)
        except (ValueError, TypeError):
            raise bad(f"is not a baseline file: its {col} column holds text, not numbers") from None
    return table


def _update_target(spec_path: Path, rel: str) -> Path:
    """Where ``--update`` may write the baseline ``rel``: inside the spec's directory (a spec,
    which may come from someone else, does not choose to write elsewhere), in a directory that
    exists. An existing file there has already been checked to be a baseline
    (:func:`load_spec`)."""
    base = spec_path.resolve().parent
    target = (spec_path.parent / rel).resolve()
    if target == base or not target.is_relative_to(base):
        raise InputError(
            f"'{rel}' is outside the spec's directory {base}: --update writes the "
            f"baseline only inside it (a path relative to the spec file)",
            file=str(spec_path),
            path="compare.baseline",
        )
    out = spec_path.parent / rel
    if not out.parent.is_dir():  # as the OS walks it (sub/../x needs sub)
        raise InputError(
            f"no directory {out.parent} to write the baseline '{rel}' into",
            file=str(spec_path),
            path="compare.baseline",
        )
    return out


def _write_baseline(table: pd.DataFrame, path: Path) -> None:
    """Write the baseline CSV atomically (a temporary file next to it, then renamed): a
    failure leaves the previous baseline."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            table.to_csv(fh, index=False, float_format="%.10g")
        os.chmod(tmp, 0o644)  # mkstemp's 0600 is for the temporary file only
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


@dataclass
class BenchResult:
    """Outcome of :func:`run_bench`."""

    results: pd.DataFrame
    evaluations: dict[tuple[str, str], Evaluation]
    regressions: list[str]
    improvements: list[str]
    n_checked: int
    baseline: Path | None


def _dataset(
    workdir: Path, scenario: Path, seed: int, duration: float | None, verify: bool = True
) -> list[Run]:
    """The runs of one dataset of the work directory: simulated, or reused if it is already
    there (the name holds a hash of the scenario file, its line file and the r2rsim version,
    the seed and the duration, so an edit to either file or a new release simulates again).

    The work directory is a cache that bench owns: a dataset there that is incomplete (no
    manifest.json), or (``verify``) whose files differ from its manifest.json or whose labels
    differ from its faults.parquet, is deleted and simulated again, with a warning on
    stderr. Without ``verify`` one with a manifest.json is used as it is. Anything else at
    that name (not a dataset) is refused, never deleted."""
    from .run import run_scenario
    from .schema import load_scenario

    line_path = load_scenario(scenario)[2]
    h = hashlib.sha256(scenario.read_bytes() + line_path.read_bytes() + __version__.encode())
    sha = h.hexdigest()[:12]
    out = workdir / f"{scenario.stem}__{sha}__s{seed}__d{duration or 'scenario'}"
    if (out / "manifest.json").is_file():
        try:
            return read_runs(out, verify=verify)
        except InputError as exc:
            if not verify:
                raise
            why = exc.message
    elif out.is_dir() and ((out / "runs.parquet").is_file() or (out / "samples").is_dir()):
        why = f"dataset {out}: incomplete (no manifest.json)"
    elif out.exists():  # not something bench wrote: never deleted
        raise InputError(
            f"bench workdir: {out} exists and is not an r2rsim dataset; remove "
            f"it or choose another --workdir"
        )
    else:
        why = None
    if why is not None:
        print(
            f"warning: bench workdir: {why}; deleting it and simulating it again", file=sys.stderr
        )
        shutil.rmtree(out)
    run_scenario(scenario, output=out, seed=seed, duration=duration)
    return read_runs(out, verify=False)  # just written and validated, labels included


def _sweep_dataset(workdir: Path, sweep: Path, where: dict, log, verify: bool = True) -> list[Run]:
    """The runs of a sweep in the work directory, selected by ``where``: the sweep is run
    (or continued; its finished runs are checked by their checksums and kept) into a
    directory named by a hash of the sweep file, its base scenario and line, and the r2rsim
    version. The selected runs are read verified (``verify``: checksums and labels, as
    ``r2rsim diagnose`` reads): a finished sweep is reopened after a check of its files'
    sizes only, and its runs were checked without their labels as they were written. A
    sweep that fails is an error (never deleted: it may have taken hours)."""
    from .sweep import plan_sweep, run_sweep

    plan = plan_sweep(sweep)
    h = hashlib.sha256("\0".join([*plan.files.values(), __version__]).encode())
    out = workdir / f"{sweep.stem}__{h.hexdigest()[:12]}"
    summary = run_sweep(sweep, output=out)
    if not summary.ok:
        log(
            f"warning: sweep {sweep}: {summary.failed + summary.skipped_failed} run(s) "
            f"failed; the bench uses the runs that have data"
        )
    return read_runs(out, verify=verify, where=where or None)


def study_runs(
    spec_path: Path, spec: BenchSpec, study: Study, workdir: Path, log=print, verify: bool = True
) -> dict[str, list[Run]]:
    """The train, val and test runs of one study of a spec, simulated into ``workdir`` or
    reused from it (:func:`_dataset`, :func:`_sweep_dataset`).

    Parameters
    ----------
    spec_path : Path
        The spec file (its scenario and sweep paths are relative to it).
    spec : BenchSpec
        The spec, as :func:`load_spec` read it.
    study : Study
        One of ``spec.studies``.
    workdir : Path
        The cache of simulated datasets.
    log : callable
        Receives warnings.
    verify : bool
        Read reused datasets checked against their manifest.json and faults.parquet.

    Returns
    -------
    dict
        ``{"train": [Run, ...], "val": [...], "test": [...]}``.
    """
    roles = {}
    for role in ("train", "val", "test"):
        runs = []
        for rs in getattr(study, role):
            if rs.sweep is not None:
                runs += _sweep_dataset(workdir, spec_path.parent / rs.sweep, rs.where, log, verify)
                continue
            for seed in rs.seeds:
                runs += _dataset(
                    workdir, spec_path.parent / rs.scenario, seed, spec.duration, verify
                )
        roles[role] = runs
    return roles


def run_bench(
    spec_path: str | Path,
    workdir: str | Path | None = None,
    *,
    update: bool = False,
    log=print,
    verify: bool = True,
) -> BenchResult:
    """Run a benchmark spec and compare with its baseline file.

    Parameters
    ----------
    spec_path : str or Path
    workdir : str or Path, optional
        Where the simulated datasets go (and are reused from); a temporary directory when
        not given.
    update : bool
        Write the baseline file from this run's results instead of comparing.
    log : callable
        Receives progress and the printed tables.
    verify : bool
        Check the datasets reused from ``workdir`` against their manifest.json, and their
        runs' labels against faults.parquet (:func:`r2rsim.dataset.read.read_runs`); a
        scenario's dataset that fails is simulated again (:func:`_dataset`), a sweep's is an
        error (:func:`_sweep_dataset`).
    """
    spec_path = Path(spec_path)
    spec = load_spec(spec_path)
    # a missing baseline, or one --update must not write, is found before anything is
    # simulated (an existing one is checked by load_spec)
    baseline: Path | None = None
    if spec.compare is not None:
        baseline = spec_path.parent / spec.compare.baseline
        if update:
            baseline = _update_target(spec_path, spec.compare.baseline)
        elif not baseline.is_file():
            raise InputError(
                f"baseline file '{spec.compare.baseline}' not found (create it with "
                f"`r2rsim bench {spec_path} --update`)",
                file=str(spec_path),
                path="compare.baseline",
            )
    tmp = None
    if workdir is None:
        tmp = tempfile.TemporaryDirectory(prefix="r2rsim-bench-")
        workdir = tmp.name
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    ev_set = spec.evaluation
    try:
        frames, evaluations = [], {}
        for study in spec.studies:
            roles = study_runs(spec_path, spec, study, workdir, log, verify)
            log(
                f"study {study.name}: {len(roles['train'])} train, {len(roles['val'])} val, "
                f"{len(roles['test'])} test runs"
            )
            for m in spec.methods:
                cls = get(m.method)
                est = call(cls, "__init__", cls, **m.params)
                ev = evaluate(
                    est,
                    roles["train"],
                    roles["test"],
                    roles["val"],
                    alpha=ev_set.alpha,
                    m=ev_set.persistence,
                    h=ev_set.grace,
                    n_boot=ev_set.n_boot,
                    seed=ev_set.seed,
                    split=study.name,
                    drive_data=ev_set.drive_data,
                    mode_strata=ev_set.mode_strata,
                    window=ev_set.window,
                    isolation=ev_set.isolation,
                    vus_buffer=ev_set.vus_buffer,
                    detection_window=(
                        math.inf if ev_set.detection_window is None else ev_set.detection_window
                    ),
                    own_threshold=ev_set.own_threshold,
                )
                evaluations[(study.name, m.key)] = ev
                log(ev.format())
                frames.append(ev.metrics.assign(study=study.name, label=m.key))
    finally:
        if tmp is not None:
            tmp.cleanup()
    results = pd.concat(frames, ignore_index=True)
    results = results[
        ["study", "label", *[c for c in results.columns if c not in ("study", "label")]]
    ]
    if spec.compare is None or baseline is None:  # the one is set with the other
        return BenchResult(results, evaluations, [], [], 0, None)
    if update:
        keep = results[results["metric"].isin(list(spec.compare.metrics))]
        _write_baseline(keep[BASELINE_COLUMNS], baseline)
        log(f"baseline written: {baseline} ({len(keep)} values)")
        return BenchResult(results, evaluations, [], [], 0, baseline)
    regressions, improvements, n = compare(
        results, read_baseline(baseline, str(spec_path)), spec.compare.metrics
    )
    return BenchResult(results, evaluations, regressions, improvements, n, baseline)


def write_results(results: pd.DataFrame, output: str | Path, overwrite: bool = False) -> Path:
    """Write a bench's results table as ``results.parquet`` and ``results.csv`` into
    ``output``: a new or empty directory, or (``overwrite``) one holding only earlier bench
    results (:func:`r2rsim.evaluate.results.check_results_output`). Returns ``output``."""
    return _write_results(
        output,
        "bench",
        {
            "results.parquet": lambda p: results.to_parquet(p, index=False),
            "results.csv": lambda p: results.to_csv(p, index=False),
        },
        overwrite,
    )


def _fmt(v: float) -> str:
    return "nan" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.6g}"


def compare(
    results: pd.DataFrame, baseline: pd.DataFrame, tolerances: dict[str, float]
) -> tuple[list[str], list[str], int]:
    """Compare results with baseline values, metric by metric.

    Returns
    -------
    regressions : list of str
        One line per metric worse than its baseline by more than its tolerance, or missing.
    improvements : list of str
        One line per metric better by more than its tolerance (the baseline is stale).
    n_checked : int
        Baseline values compared.
    """
    cur = {_key(r): r.value for r in results.itertuples(index=False)}
    regressions, improvements, n = [], [], 0
    for row in baseline.itertuples(index=False):
        if row.metric not in tolerances:
            continue
        n += 1
        where = (
            f"{row.study}/{row.label} {row.condition} {row.fault}"
            + ("" if pd.isna(row.magnitude) else f" magnitude {row.magnitude:g}")
            + f" {row.metric}"
        )
        tol = tolerances[row.metric]
        value = cur.get(_key(row))
        if value is None or math.isnan(value):
            if not math.isnan(row.value):
                regressions.append(f"{where}: baseline {_fmt(row.value)}, now no value")
            continue
        if math.isnan(row.value):
            improvements.append(f"{where}: baseline no value, now {_fmt(value)}")
            continue
        better = METRICS[row.metric].higher_is_better
        # no better direction: a change either way beyond the tolerance counts as worse
        worse = (
            (row.value - value if better else value - row.value)
            if better is not None
            else abs(value - row.value)
        )
        line = (
            f"{where}: baseline {_fmt(row.value)}, now {_fmt(value)} "
            f"({'worse' if worse > 0 else 'better'} by {_fmt(abs(worse))}, "
            f"tolerance {_fmt(tol)})"
        )
        slack = tol + 1e-9 * max(1.0, abs(row.value))  # the CSV keeps 10 digits
        if worse > slack:
            regressions.append(line)
        elif -worse > slack:
            improvements.append(line)
    return regressions, improvements, n


def _key(row) -> tuple:
    """A result's identity; the magnitude as text so that 'no magnitude' (nan) matches."""
    mag = "" if pd.isna(row.magnitude) else f"{float(row.magnitude):.10g}"
    return (row.study, row.label, row.condition, row.fault, mag, row.metric)
