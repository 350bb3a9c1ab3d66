"""A run killed (SIGKILL) at any point of writing its dataset leaves temporaries that the next
run into the same parent directory cleans up (issue 36 item 3): its ``.NAME.tmp-PID``, or,
during an ``--overwrite`` swap, its ``.NAME.old-PID``, which is put back where the swap did
not finish. The list of files a temporary directory may hold is the dataset layout's
(:mod:`r2rsim.dataset.paths`), the same list the writer and ``r2rsim validate`` use."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from r2rsim.cli import main
from r2rsim.dataset.paths import RUN_TABLES, TEMP_RE, clean_stale, layout_problem
from r2rsim.dataset.validate import validate_dataset

ROOT = Path(__file__).resolve().parents[1]
QUICKSTART = ROOT / "scenarios" / "quickstart.yaml"

# A child process runs `r2rsim run` and SIGKILLs itself at one point of the writer's work.
_CHILD = textwrap.dedent("""
    import os, signal, sys
    import r2rsim.dataset.writer as W
    import r2rsim.run as R
    from r2rsim.cli import main

    point, args = sys.argv[1], sys.argv[2:]

    def die():
        os.kill(os.getpid(), signal.SIGKILL)

    def after(cls_or_mod, name, when):
        orig = getattr(cls_or_mod, name)
        def wrapped(*a, **k):
            out = orig(*a, **k)
            if when(*a, **k):
                die()
            return out
        setattr(cls_or_mod, name, wrapped)

    def before(cls_or_mod, name, when):
        orig = getattr(cls_or_mod, name)
        def wrapped(*a, **k):
            if when(*a, **k):
                die()
            return orig(*a, **k)
        setattr(cls_or_mod, name, wrapped)

    if point == "start":             # the temporary directory exists, nothing in it
        after(W.DatasetWriter, "__init__", lambda *a, **k: True)
    elif point == "chunk":           # samples being written
        after(W.DatasetWriter, "write_chunk", lambda *a, **k: True)
    elif point.startswith("table:"):  # a table written
        after(W.DatasetWriter, "write_table", lambda self, name, t: name == point[6:])
    elif point == "text":            # the copies of the input files written
        after(W.DatasetWriter, "write_text", lambda *a, **k: True)
    elif point == "manifest":        # every file and the manifest written, not yet moved
        before(R, "validate_dataset", lambda *a, **k: True)
    elif point == "swap":            # --overwrite: the old dataset moved aside
        before(W, "dataset_problems", lambda p, **k: ".old-" in str(p))
    elif point == "installed":       # --overwrite: the new one in place, the old not removed
        before(W, "remove_dataset", lambda p: ".old-" in str(p))
    sys.exit(main(args))
""")

POINTS = ["start", "chunk", *(f"table:{t}" for t in RUN_TABLES), "text", "manifest"]


def _killed_run(point: str, out: Path, *extra: str) -> None:
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            _CHILD,
            point,
            "run",
            str(QUICKSTART),
            "-o",
            str(out),
            "--duration",
            "1",
            "-q",
            *extra,
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == -signal.SIGKILL, (point, proc.returncode, proc.stderr)


def _temporaries(parent: Path) -> list[str]:
    return sorted(e.name for e in os.scandir(parent) if TEMP_RE.match(e.name))


@pytest.mark.parametrize("point", POINTS)
def test_a_run_killed_while_writing_leaves_what_the_next_run_cleans(tmp_path, point):
    out = tmp_path / "parent" / "ds"
    (tmp_path / "parent").mkdir()
    _killed_run(point, out)
    left = _temporaries(out.parent)
    assert len(left) == 1 and ".tmp-" in left[0], left  # the killed run's temporary
    assert not out.exists()
    # everything in it is a file of the layout (so the cleanup may remove it)
    tmp = out.parent / left[0]
    for p in tmp.rglob("*"):
        if p.is_file():
            assert layout_problem(p.relative_to(tmp).as_posix(), sweep=False) is None, p
    assert (
        main(["run", str(QUICKSTART), "-o", str(out.parent / "next"), "--duration", "1", "-q"]) == 0
    )
    assert _temporaries(out.parent) == []
    assert sorted(p.name for p in out.parent.iterdir()) == ["next"]


@pytest.mark.parametrize("point", ["swap", "installed"])
def test_a_run_killed_while_replacing_a_dataset_leaves_a_dataset(tmp_path, point):
    parent = tmp_path / "parent"
    out = parent / "ds"
    assert main(["run", str(QUICKSTART), "-o", str(out), "--duration", "1", "-q"]) == 0
    _killed_run(point, out, "--overwrite")
    assert any(".old-" in n for n in _temporaries(parent)), _temporaries(parent)
    assert main(["run", str(QUICKSTART), "-o", str(parent / "next"), "--duration", "1", "-q"]) == 0
    assert _temporaries(parent) == []
    # the swap that did not finish is undone; one that did keeps the new dataset
    assert validate_dataset(out) == []
    assert sorted(p.name for p in parent.iterdir()) == ["ds", "next"]


def test_a_temporary_holding_a_file_outside_the_layout_is_left_alone(tmp_path):
    parent = tmp_path / "parent"
    parent.mkdir()
    tmp = parent / ".ds.tmp-999999999"  # no such process
    (tmp / "samples" / "run_id=a").mkdir(parents=True)
    (tmp / "samples" / "run_id=a" / "part-0.parquet").write_bytes(b"x")
    (tmp / "variability.parquet").write_bytes(b"x")
    (tmp / "scenario").mkdir()
    (tmp / "scenario" / "a.yaml").write_text("x")
    keep = parent / ".other.tmp-999999998"
    shutil.copytree(tmp, keep)
    (keep / "notes.txt").write_text("mine")
    empty_foreign = parent / ".third.tmp-999999997"
    (empty_foreign / "analysis").mkdir(parents=True)
    assert clean_stale(parent) == [tmp]
    assert _temporaries(parent) == [".other.tmp-999999998", ".third.tmp-999999997"]


def test_validate_reports_a_listed_file_outside_the_layout(tmp_path):
    import json

    from r2rsim.dataset.paths import sha256_file

    out = tmp_path / "ds"
    assert main(["run", str(QUICKSTART), "-o", str(out), "--duration", "1", "-q"]) == 0
    assert validate_dataset(out) == []
    extra = {
        "notes.txt": out / "notes.txt",
        "failures.parquet": out / "failures.parquet",
        "scenario/deep/x.yaml": out / "scenario" / "deep" / "x.yaml",
    }
    manifest = json.loads((out / "manifest.json").read_text())
    for rel, p in extra.items():
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("x")
        manifest["files"][rel] = {"sha256": sha256_file(p), "bytes": p.stat().st_size}
    (out / "manifest.json").write_text(json.dumps(manifest))
    problems = validate_dataset(out)
    for rel in extra:  # failures.parquet belongs to a sweep's layout, not a run's
        assert (
            f"{rel}: not a file of the r2rsim dataset layout (manifest.json lists it)" in problems
        ), problems
