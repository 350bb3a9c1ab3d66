"""The output directory of a sweep: one dataset for all its runs, built so that a sweep can
stop at any moment and continue.

While a sweep runs, its directory holds a marker (:data:`MARKER`, which also carries the lock
that keeps two sweeps out of one directory) and ``.work/``: every finished run is a complete
single-run dataset ``.work/<run_id>/`` (written atomically by the dataset writer, with its
checksums), every run that failed without data a ``.work/<run_id>.failed.json``. A run whose
directory passes its checksums is not run again.

When every run has an outcome the sweep is *finalised*: the runs' samples are hard-linked to
``samples/run_id=<id>/part-0.parquet``, their rows are concatenated into ``runs.parquet``,
``faults.parquet``, ``events.parquet`` and ``failures.parquet``, ``manifest.json`` is written
last, and ``.work/`` and the marker are removed. Every step can be repeated, so an
interruption during finalisation is finished by running the sweep again. A finished sweep
can be reopened (more seeds, ``--retry-failed``): its runs stay, the new ones are added.
"""

from __future__ import annotations

import json
import os
import platform
import re
import shutil
from pathlib import Path
from typing import IO

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from .._version import __version__
from ..dataset.outcome import failed_reason
from ..dataset.paths import (
    MANIFEST,
    RUN_TABLES,
    SAMPLES,
    SWEEP_COPIES,
    SWEEP_MARKER,
    TOP_FILES,
    clean_stale,
    dataset_problems,
    pid_alive,
    read_json,
    read_manifest,
    read_parquet_file,
    remove_dataset,
    sha256_file,
)
from ..dataset.writer import EVENTS_SCHEMA, FAULTS_SCHEMA, SCHEMA_VERSION, VARIABILITY_SCHEMA
from ..errors import InputError, R2RError

MARKER = SWEEP_MARKER
WORK = ".work"
#: the runs' tables concatenated into the sweep's (channels.parquet is merged apart)
TABLES = tuple(t for t in RUN_TABLES if t != "channels")
#: the temporaries of the marker and the manifest (written, then renamed)
_TOP_TEMP = re.compile(rf"^(?:{re.escape(MARKER)}|{re.escape(MANIFEST)})\.tmp-(?P<pid>[0-9]+)$")
_PYARROW_TYPES = {
    "string": pa.string(),
    "float64": pa.float64(),
    "bool": pa.bool_(),
    "int64": pa.int64(),
}


def run_columns(spec) -> dict[str, pa.Array]:
    """A run's sweep columns of runs.parquet as one-element arrays."""
    return {c: pa.array([spec.columns[c]], _PYARROW_TYPES[t]) for c, t in spec.column_types}


def failures_schema(plan) -> pa.Schema:
    types = plan.runs[0].column_types if plan.runs else ()
    return pa.schema(
        [
            ("run_id", pa.string()),
            ("seed", pa.uint64()),
            *((c, _PYARROW_TYPES[t]) for c, t in types),
            ("error", pa.string()),
        ]
    )


def finished(path: Path, config_sha256: str) -> dict | None:
    """The runs.parquet row of a run already written at ``path`` (intact, and made from
    this configuration), else None. A worker that died after writing its run but before
    reporting it has its run given to another worker, which finds it here."""
    if not (path / MANIFEST).is_file() or dataset_problems(path):
        return None
    row = read_parquet_file(path / "runs.parquet").to_pylist()[0]
    return row if row.get("config_sha256") == config_sha256 else None


def write_failure(work: str | Path, spec, reason: str, detail: str | None = None) -> None:
    """Record that a run failed without data: ``<work>/<run_id>.failed.json``, written
    atomically (a resumed sweep reads it, and keeps the run failed unless --retry-failed).
    A record that is there already (the worker's own, with its traceback) is kept."""
    path = Path(work) / f"{spec.run_id}.failed.json"
    if path.exists():
        return
    tmp = Path(work) / f".{spec.run_id}.failed.tmp-{os.getpid()}"
    tmp.write_text(
        json.dumps(
            {
                "run_id": spec.run_id,
                "config_sha256": spec.config_sha256,
                "error": reason,
                "traceback": detail,
            }
        ),
        encoding="utf-8",
    )
    os.replace(tmp, path)


class Outcome:
    """What happened to one run: ``done`` or ``failed`` (``reason``); ``where`` says where
    its data is: ``work`` (.work/<id>/), ``final`` (the finished dataset) or None (a
    failure without data)."""

    __slots__ = ("status", "where", "reason")

    def __init__(self, status: str, where: str | None, reason: str | None = None):
        self.status, self.where, self.reason = status, where, reason


class SweepStore:
    """The output directory of one sweep (see the module docstring).

    Parameters
    ----------
    out : Path
    plan : SweepPlan
    overwrite : bool
        Replace a finished r2rsim dataset at ``out`` (of another sweep, of a run, or of this
        sweep to start it again).
    """

    def __init__(self, out: Path, plan, overwrite: bool = False):
        self.out = Path(out)
        self.plan = plan
        self.overwrite = overwrite
        self.work = self.out / WORK
        self.marker = self.out / MARKER
        self.mode = "new"
        self.final: dict | None = None  # the manifest of a finished dataset being reopened
        self._lock: IO[bytes] | None = None

    # ------------------------------------------------------------------ before writing
    def inspect(self) -> None:
        """Decide what the directory is (new, an unfinished sweep, a finished one) and refuse
        what may not be written to; nothing is written."""
        out = self.out
        if out.is_symlink():
            raise InputError(
                f"output directory '{out}' is a symbolic link; give the "
                f"directory it points to, or another one, with -o"
            )
        if out.exists() and not out.is_dir():
            raise InputError(
                f"output '{out}' exists and is not a directory; choose another with -o"
            )
        name = self.plan.sweep.name
        if self.marker.is_file():
            try:
                info = read_json(self.marker)
            except (OSError, ValueError):
                info = {}
            if not isinstance(info, dict):
                info = {}
            if info.get("sweep") != name:
                raise InputError(
                    f"output directory '{out}' holds an unfinished sweep "
                    f"'{info.get('sweep')}', not '{name}': choose another "
                    f"directory with -o"
                )
            self.mode = "resume"
            manifest, _ = read_manifest(out)
            if manifest and (manifest.get("sweep") or {}).get("name") == name:
                self.final = manifest  # a finished sweep being extended
            self.check_foreign()
            return
        if not out.exists() or not any(out.iterdir()):
            return
        manifest, why = read_manifest(out)
        if manifest is None:
            raise InputError(
                f"output directory '{out}' exists and is not an r2rsim dataset "
                f"({why}); choose another directory with -o"
            )
        same = (manifest.get("sweep") or {}).get("name") == name
        if same and not self.overwrite:
            problems = dataset_problems(out, hashes=False)
            if problems:
                raise InputError(
                    f"output directory '{out}' holds sweep '{name}' but its "
                    f"files differ from its manifest.json ({problems[0]}); "
                    f"r2rsim does not continue it: choose another directory"
                )
            self.mode, self.final = "reopen", manifest
            return
        problems = dataset_problems(out)
        if problems:
            raise InputError(
                f"output directory '{out}' exists and is not an intact r2rsim "
                f"dataset ({problems[0]}); choose another directory with -o"
            )
        if not self.overwrite:
            sweep = manifest.get("sweep")
            what = f"sweep '{sweep.get('name')}'" if isinstance(sweep, dict) else "a run's dataset"
            raise InputError(
                f"output directory '{out}' holds {what}; pass --overwrite to "
                f"replace it, or choose another directory with -o"
            )
        self.mode = "replace"

    def outcomes(self, retry_failed: bool) -> dict[str, Outcome]:
        """The outcome of every run that has one (reading and checking, writing nothing).

        Raises
        ------
        InputError
            When the directory holds runs this sweep does not make, or runs made from
            another configuration (the base scenario, its line or r2rsim changed).
        """
        plan_ids = {s.run_id: s for s in self.plan.runs}
        found: dict[str, Outcome] = {}
        foreign: list[str] = []
        changed: list[str] = []
        if self.final is not None:
            self._final_outcomes(plan_ids, found, foreign, changed)
        if self.work.is_dir():
            self._work_outcomes(plan_ids, found, foreign, changed)
        if foreign:
            raise InputError(
                f"output directory '{self.out}' holds {len(foreign)} run(s) this "
                f"sweep file does not make (e.g. {foreign[0]}): was the sweep "
                f"file changed? Restore it, or write to another directory with -o"
                + (" (or --overwrite)" if self.mode == "reopen" else "")
            )
        if changed:
            raise InputError(
                f"{len(changed)} run(s) in '{self.out}' were made from another "
                f"base scenario, line, sweep file `set:` or r2rsim version (e.g. "
                f"{changed[0]}); "
                f"continuing would mix them: write to another directory with -o"
                + (" (or --overwrite)" if self.mode == "reopen" else "")
            )
        if retry_failed:
            found = {k: o for k, o in found.items() if o.status != "failed"}
        return found

    def _final_outcomes(self, plan_ids, found, foreign, changed) -> None:
        files = (self.final or {}).get("files", {})
        runs = read_parquet_file(self.out / "runs.parquet").to_pylist()
        for row in runs:
            rid = row["run_id"]
            spec = plan_ids.get(rid)
            if spec is None:
                foreign.append(rid)
                continue
            if row.get("config_sha256") != spec.config_sha256:
                changed.append(rid)
                continue
            rel = f"samples/run_id={rid}/part-0.parquet"
            f = self.out / rel
            if not f.is_file() or sha256_file(f) != files.get(rel, {}).get("sha256"):
                continue  # damaged: run again
            reason = failed_reason(row)
            found[rid] = Outcome("failed" if reason else "done", "final", reason)
        failures = self.out / "failures.parquet"
        if failures.is_file():
            for row in read_parquet_file(failures).to_pylist():
                rid = row["run_id"]
                if rid not in plan_ids:
                    foreign.append(rid)
                elif row.get("config_sha256") != plan_ids[rid].config_sha256:
                    changed.append(rid)
                else:
                    found[rid] = Outcome("failed", None, row.get("error"))

    def _work_outcomes(self, plan_ids, found, foreign, changed) -> None:
        for entry in sorted(os.scandir(self.work), key=lambda e: e.name):
            name = entry.name
            if name.startswith("."):
                continue  # a writer's temporary, or the finalisation's
            if name.endswith(".failed.json"):
                rid = name[: -len(".failed.json")]
                if rid not in plan_ids:
                    foreign.append(rid)
                    continue
                try:
                    rec = read_json(entry.path)
                except (OSError, ValueError):
                    continue
                if not isinstance(rec, dict):
                    continue
                if rec.get("config_sha256") != plan_ids[rid].config_sha256:
                    changed.append(rid)
                else:
                    found[rid] = Outcome("failed", None, rec.get("error"))
                continue
            if name not in plan_ids:
                foreign.append(name)
                continue
            path = Path(entry.path)
            if dataset_problems(path):
                continue  # damaged (not as written): run again
            row = read_parquet_file(path / "runs.parquet").to_pylist()[0]
            if row.get("config_sha256") != plan_ids[name].config_sha256:
                changed.append(name)
                continue
            reason = failed_reason(row)
            found[name] = Outcome("failed" if reason else "done", "work", reason)

    def up_to_date(self) -> bool:
        """Whether a finished sweep being reopened already holds what this sweep file would
        write besides its runs: the same copies of the sweep and scenario files and the same
        axes (a renamed axis renames a column of runs.parquet)."""
        if self.final is None:
            return False
        stored = {
            rel for rel in self.final.get("files", {}) if rel.startswith(("sweep/", "scenario/"))
        }
        if stored != set(self.plan.files):
            return False
        for rel, text in self.plan.files.items():
            try:
                if (self.out / rel).read_text(encoding="utf-8") != text:
                    return False
            except (OSError, UnicodeDecodeError):
                return False
        sweep = self.final.get("sweep") or {}
        return (
            sweep.get("axes") == self.plan.axes
            and sweep.get("file") == f"sweep/{self.plan.file.name}"
        )

    # ------------------------------------------------------------------ writing
    def begin(self) -> None:
        """Create the directory and the marker, and take the lock."""
        if self.mode == "replace":
            remove_dataset(self.out)
        self.out.mkdir(parents=True, exist_ok=True)
        created = not self.marker.exists()
        if created:
            tmp = self.out / f"{MARKER}.tmp-{os.getpid()}"
            tmp.write_text(
                json.dumps(
                    {
                        "sweep": self.plan.sweep.name,
                        "r2rsim_version": __version__,
                        "sweep_file": self.plan.file.name,
                    }
                ),
                encoding="utf-8",
            )
            os.replace(tmp, self.marker)
        self._lock = open(self.marker, "rb")  # noqa: SIM115 - held for the whole sweep
        try:
            import fcntl

            fcntl.flock(self._lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except ImportError:  # no fcntl (Windows): no lock
            pass
        except OSError:
            self._lock.close()
            self._lock = None
            raise InputError(
                f"another r2rsim sweep is writing '{self.out}'; wait for it, or "
                f"choose another directory with -o"
            ) from None
        if created and self.mode == "resume":
            # the unfinished sweep inspected a moment ago was finished (or removed) by
            # another sweep before this one could lock it: what was read of it is stale
            self._lock.close()
            self._lock = None
            self.marker.unlink(missing_ok=True)
            raise InputError(
                f"another r2rsim sweep finished writing '{self.out}' while this "
                f"one was starting; run the command again"
            )
        self._remove_dead_top_temporaries()
        self.work.mkdir(exist_ok=True)
        clean_stale(self.work)
        final_tmp = self.work / ".final"
        if final_tmp.is_dir():
            shutil.rmtree(final_tmp)  # an interrupted finalisation's tables

    def _remove_dead_top_temporaries(self) -> None:
        """Remove the marker's and the manifest's temporaries left by a sweep process that
        was killed while writing them (the manifest would otherwise list them)."""
        for e in os.scandir(self.out):
            m = _TOP_TEMP.match(e.name)
            if m and e.is_file(follow_symlinks=False):
                pid = int(m["pid"])
                if pid == os.getpid() or not pid_alive(pid):
                    Path(e.path).unlink(missing_ok=True)

    def clear(self, run_id: str) -> None:
        """Remove what a run left in .work/ before it runs again (--retry-failed, or a run
        whose files no longer match their checksums)."""
        failed = self.work / f"{run_id}.failed.json"
        failed.unlink(missing_ok=True)
        path = self.work / run_id
        if path.is_dir() and not path.is_symlink():
            manifest, _ = read_manifest(path)
            listed = set((manifest or {}).get("files", {})) | {MANIFEST}
            files = {p.relative_to(path).as_posix() for p in path.rglob("*") if not p.is_dir()}
            if not files <= listed:
                raise R2RError(f"'{path}' holds files r2rsim did not write; move it away")
            shutil.rmtree(path)

    def close(self) -> None:
        if self._lock is not None:
            self._lock.close()
            self._lock = None

    # ------------------------------------------------------------------ finalising
    def foreign_files(self) -> list[str]:
        """What is in the directory of an unfinished sweep that neither the sweep nor the
        dataset it reopens wrote (a user's notes, an analysis/ directory): the manifest lists
        every file there, so these must not be there when it is written."""
        ours = set(self.plan.files) | set((self.final or {}).get("files", {}))
        runs = {s.run_id for s in self.plan.runs}
        found = []
        for top in sorted(self.out.iterdir(), key=lambda p: p.name):
            name = top.name
            if name in (WORK, MARKER) or _TOP_TEMP.match(name):
                continue
            if top.is_symlink() or not top.is_dir():
                if name not in TOP_FILES or top.is_symlink():
                    found.append(name)
                continue
            if name not in (SAMPLES, *SWEEP_COPIES):
                found.append(name + "/")
                continue
            for p in sorted(top.rglob("*")):
                rel = p.relative_to(self.out).as_posix()
                if p.is_dir() and not p.is_symlink():
                    if not (name == "samples" and p.parent == top and p.name.startswith("run_id=")):
                        found.append(rel + "/")
                elif rel not in ours and not (
                    p.name == "part-0.parquet"
                    and not p.is_symlink()
                    and p.parent.parent == top
                    and name == "samples"
                    and p.parent.name.removeprefix("run_id=") in runs
                ):
                    found.append(rel)
        return found

    def check_foreign(self) -> None:
        """Refuse to continue a sweep whose directory holds files r2rsim did not write."""
        foreign = self.foreign_files()
        if foreign:
            raise InputError(
                f"output directory '{self.out}' holds an unfinished sweep and "
                f"{len(foreign)} file(s) r2rsim did not write ("
                f"{', '.join(foreign[:3])}{', ...' if len(foreign) > 3 else ''})"
                f": move them out of it, then run the sweep again to finish it"
            )

    def finalise(self, outcomes: dict[str, Outcome]) -> Path:
        """Build the dataset from the runs' outcomes (every run of the plan has one)."""
        self.check_foreign()  # files put there while the sweep ran are not adopted
        tmp = self.work / ".final"
        if tmp.exists():
            shutil.rmtree(tmp)
        tmp.mkdir()
        failed = [
            spec.run_id for spec in self.plan.runs if outcomes[spec.run_id].status == "failed"
        ]
        meta = {
            b"r2rsim.schema_version": SCHEMA_VERSION.encode(),
            b"r2rsim.version": __version__.encode(),
            b"r2rsim.sweep": self.plan.sweep.name.encode(),
            # a sweep with failed runs is never taken for a complete one
            b"r2rsim.sweep.n_runs": str(len(self.plan.runs)).encode(),
            b"r2rsim.sweep.n_failed": str(len(failed)).encode(),
        }
        run_ids, failure_rows, channels = self._merge_tables(outcomes, tmp, meta)
        pq.write_table(
            pa.Table.from_pylist(
                failure_rows, schema=failures_schema(self.plan)
            ).replace_schema_metadata(meta),
            tmp / "failures.parquet",
            compression="zstd",
        )
        if channels is None:
            channels = pa.table({"channel": pa.array([], pa.string())})
        pq.write_table(
            channels.replace_schema_metadata(meta), tmp / "channels.parquet", compression="zstd"
        )
        known_sha = self._place_samples(outcomes)
        self._install(tmp, run_ids, [r["run_id"] for r in failure_rows], failed, known_sha)
        return self.out

    def _merge_tables(self, outcomes: dict[str, Outcome], tmp: Path, meta: dict):
        """Write the runs' small tables (``TABLES``), run after run in the plan's order, to
        ``tmp``; return the finished run ids, the failed runs' rows and the merged channels
        table (None when no run finished)."""
        old = _OldTables(self.out) if self.final is not None else None
        writers: dict[str, _TableWriter] = {}
        schemas = {
            "faults": FAULTS_SCHEMA,
            "events": EVENTS_SCHEMA,
            "variability": VARIABILITY_SCHEMA,
        }
        channels, old_channels = None, False
        seen_channels: set[str] = set()  # the sha256 of each channels table merged
        run_ids, failure_rows = [], []
        try:
            for spec in self.plan.runs:
                o = outcomes[spec.run_id]
                if o.where is None:
                    failure_rows.append(
                        {
                            "run_id": spec.run_id,
                            "seed": spec.seed,
                            **spec.columns,
                            "error": o.reason,
                        }
                    )
                    continue
                run_ids.append(spec.run_id)
                for name in TABLES:
                    table = (
                        read_parquet_file(self.work / spec.run_id / f"{name}.parquet")
                        if o.where == "work" or old is None
                        else old.rows(name, spec.run_id)
                    )
                    if name == "runs":  # as this plan numbers and names them
                        table = _sweep_columns(table, spec)
                    schema = schemas.get(name) or table.schema.remove_metadata()
                    schemas[name] = schema
                    if name not in writers:
                        writers[name] = _TableWriter(
                            tmp / f"{name}.parquet", schema.with_metadata(meta)
                        )
                    writers[name].add(table.replace_schema_metadata(None).cast(schema))
                if o.where == "work" or not old_channels:
                    channels = self._add_channels(channels, spec.run_id, o.where, seen_channels)
                    old_channels = old_channels or o.where != "work"
            for name in TABLES:
                if name not in writers:  # no run has data
                    pq.write_table(
                        pa.Table.from_pylist(
                            [], schema=schemas.get(name, pa.schema([("run_id", pa.string())]))
                        ).replace_schema_metadata(meta),
                        tmp / f"{name}.parquet",
                        compression="zstd",
                    )
        finally:
            for w in writers.values():
                w.close()
        return run_ids, failure_rows, channels

    def _add_channels(self, channels, run_id: str, where: str, seen: set):
        """``channels`` merged with a run's channels table: every run's (those of a reopened
        dataset as one), since a swept record_rate, sensor rate or range changes them. A run
        whose file has bytes already merged (its sha256 in its manifest) is not read again."""
        sha = _listed_sha(self.work / run_id, "channels.parquet") if where == "work" else None
        if sha is not None and sha in seen:
            return channels
        seen.add(sha)
        return _merge_channels(
            channels,
            read_parquet_file(
                self.work / run_id / "channels.parquet"
                if where == "work"
                else self.out / "channels.parquet"
            ),
        )

    def _install(
        self,
        tmp: Path,
        run_ids: list[str],
        without_data: list[str],
        failed: list[str],
        known_sha: dict,
    ) -> None:
        """Move the merged tables into the dataset, write the plan's files and the manifest,
        and remove the work directory and the marker: the dataset is complete."""
        # the old manifest stays until the new one replaces it: the marker already says the
        # dataset is unfinished, and a resume needs the old checksums
        for p in tmp.iterdir():
            os.replace(p, self.out / p.name)
        for rel in (self.final or {}).get("files", {}):  # copies of renamed files
            if rel.startswith(("sweep/", "scenario/")) and rel not in self.plan.files:
                (self.out / rel).unlink(missing_ok=True)
        for rel, text in self.plan.files.items():
            target = self.out / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(text, encoding="utf-8")
        self._write_manifest(run_ids, without_data, failed, known_sha)
        shutil.rmtree(self.work)
        self.close()
        self.marker.unlink()

    def _place_samples(self, outcomes: dict[str, Outcome]) -> dict:
        """Hard-link (else copy) the samples of the runs in .work/ into samples/, and
        remove the samples of runs that have none any more (retried and failed). Returns
        the placed files' sha256 as their runs' manifests give them, by relative path."""
        known_sha: dict = {}
        samples = self.out / "samples"
        samples.mkdir(exist_ok=True)
        for rid, o in outcomes.items():
            rel = f"samples/run_id={rid}/part-0.parquet"
            dst = self.out / rel
            if o.where != "work":
                if o.where is None and dst.parent.is_dir():
                    shutil.rmtree(dst.parent)
                continue
            src = self.work / rid / rel
            wm, _ = read_manifest(self.work / rid)
            known_sha[rel] = (wm or {}).get("files", {}).get(rel, {}).get("sha256")
            if dst.exists():
                if os.path.samefile(src, dst):
                    continue
                dst.unlink()  # an earlier version of the run (retried)
            dst.parent.mkdir(exist_ok=True)
            try:
                os.link(src, dst)
            except OSError:  # a file system without hard links
                shutil.copy2(src, dst)
        return known_sha

    def _write_manifest(
        self, run_ids: list[str], without_data: list[str], failed: list[str], known_sha: dict
    ) -> None:
        old = (self.final or {}).get("files", {})
        files = {}
        for p in sorted(self.out.rglob("*")):
            rel = p.relative_to(self.out).as_posix()
            if p.is_dir() or rel == MANIFEST or rel == MARKER or rel.startswith(WORK + "/"):
                continue
            size = p.stat().st_size
            sha = known_sha.get(rel)
            if sha is None and rel.startswith("samples/") and old.get(rel, {}).get("bytes") == size:
                sha = old[rel]["sha256"]
            files[rel] = {"sha256": sha or sha256_file(p), "bytes": size}
        sw = self.plan.sweep
        manifest = {
            "schema_version": SCHEMA_VERSION,
            "r2rsim_version": __version__,
            "python_version": platform.python_version(),
            "numpy_version": np.__version__,
            "pyarrow_version": pa.__version__,
            "run_ids": run_ids,
            "sweep": {
                "name": sw.name,
                "file": f"sweep/{self.plan.file.name}",
                "combine": sw.combine,
                "n_combinations": self.plan.n_combinations,
                "seeds": self.plan.seeds,
                "axes": self.plan.axes,
                "n_runs": len(self.plan.runs),
                "failed_without_data": without_data,
                "failed": failed,
            },
            "files": files,
        }
        tmp = self.out / f"{MANIFEST}.tmp-{os.getpid()}"
        tmp.write_text(json.dumps(manifest, indent=2, sort_keys=True), encoding="utf-8")
        os.replace(tmp, self.out / MANIFEST)


#: the description of a channel whose description differs between the runs of a sweep
VARIES = " (differs between the runs of this sweep; see each run's configuration)"


def _merge_channels(merged: pa.Table | None, table: pa.Table) -> pa.Table:
    """channels.parquet of a sweep: one run's, with ``rate_hz`` null and the description
    marked where the runs differ (a swept record rate, sensor rate or range; a run's record
    rate is 1 / ``sample_period_s`` in runs.parquet)."""
    table = table.replace_schema_metadata(None)
    if merged is None or merged.equals(table):
        return table if merged is None else merged
    a, b = merged.to_pydict(), table.to_pydict()
    if a["channel"] != b["channel"] or any(a[c] != b[c] for c in ("kind", "unit", "component")):
        raise R2RError(
            "the runs of the sweep have different channels (channels.parquet); "
            "one dataset holds runs of one set of channels"
        )
    for i in range(len(a["channel"])):
        if a["rate_hz"][i] != b["rate_hz"][i]:
            a["rate_hz"][i] = None
        if a["description"][i].removesuffix(VARIES) != b["description"][i]:
            a["description"][i] = a["description"][i].removesuffix(VARIES) + VARIES
    return pa.table(a, schema=merged.schema)


def _listed_sha(root: Path, rel: str) -> str | None:
    """The sha256 that a dataset's manifest.json lists for one of its files."""
    manifest, _ = read_manifest(root)
    return ((manifest or {}).get("files", {}).get(rel) or {}).get("sha256")


_SWEEP_COLUMNS = ("sweep", "combination", "overrides_json", "config_sha256")


def _sweep_columns(table: pa.Table, spec) -> pa.Table:
    """A run's row with the sweep's columns as the current plan has them: a reopened sweep
    may number its combinations anew (a value added to an axis) or rename an axis."""
    keep = [c for c in table.column_names if c not in _SWEEP_COLUMNS and not c.startswith("axis.")]
    table = table.select(keep)
    for col, arr in run_columns(spec).items():
        table = table.append_column(col, arr)
    return table


class _TableWriter:
    """Concatenates the runs' rows of one table, a row group per :data:`ROWS_PER_GROUP`
    rows (not one per run), without holding more than that in memory."""

    ROWS_PER_GROUP = 1 << 14
    TABLES_PER_MERGE = 32

    def __init__(self, path: Path, schema: pa.Schema):
        self.schema = schema
        self.writer = pq.ParquetWriter(path, schema, compression="zstd")
        self.pending: list[pa.Table] = []
        self.rows = 0

    def add(self, table: pa.Table) -> None:
        self.pending.append(table.replace_schema_metadata(self.schema.metadata))
        self.rows += table.num_rows
        if self.rows >= self.ROWS_PER_GROUP:
            self._flush()
        elif len(self.pending) >= self.TABLES_PER_MERGE:
            # a table per run costs ~60 kB of bookkeeping: merge them as they come, so
            # memory does not grow with the number of runs
            self.pending = [pa.concat_tables(self.pending).combine_chunks()]

    def _flush(self) -> None:
        if self.pending:
            self.writer.write_table(pa.concat_tables(self.pending))
        self.pending, self.rows = [], 0

    def close(self) -> None:
        self._flush()
        self.writer.close()


class _OldTables:
    """The tables of the finished dataset being reopened, by run."""

    def __init__(self, root: Path):
        # variability.parquet is newer than some datasets: none is no variability
        self.tables = {
            n: read_parquet_file(root / f"{n}.parquet")
            if n != "variability" or (root / f"{n}.parquet").is_file()
            else VARIABILITY_SCHEMA.empty_table()
            for n in TABLES
        }
        self.index = {}
        for n, t in self.tables.items():
            ids = t.column("run_id").to_pylist()
            idx: dict[str, list[int]] = {}
            for i, rid in enumerate(ids):
                idx.setdefault(rid, []).append(i)
            self.index[n] = idx

    def rows(self, name: str, run_id: str) -> pa.Table:
        return self.tables[name].take(pa.array(self.index[name].get(run_id, []), pa.int64()))
