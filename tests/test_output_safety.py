"""What ``r2rsim run`` may write, replace and remove: no-clobber output directories and
``--overwrite``, the scenario's ``output:`` key, names as identifiers, paths checked to stay
inside the dataset, SIGTERM, stale temporary directories, and a validator that reads the
samples batch by batch."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import r2rsim
from r2rsim.cli import main
from r2rsim.dataset import paths, validate, writer
from r2rsim.dataset.paths import clean_stale, dataset_problems, sha256_file
from r2rsim.dataset.validate import validate_dataset
from r2rsim.dataset.writer import DatasetWriter
from r2rsim.errors import InputError, R2RError

REPO = Path(__file__).resolve().parents[1]
QUICK = REPO / "scenarios" / "quickstart.yaml"


def run(out, *extra, scenario=QUICK):
    return main(["run", str(scenario), "-o", str(out), "--duration", "1", "-q", *extra])


def tree(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (hidden ones too) with its bytes."""
    return {
        p.relative_to(root).as_posix(): p.read_bytes()
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def scenario_copy(where: Path, **keys) -> Path:
    """The quickstart scenario in ``where`` (line path made absolute), keys replaced."""
    import yaml

    d = yaml.safe_load(QUICK.read_text())
    d["line"] = str(REPO / "lines" / "pet_film_line.yaml")
    d["duration"] = 1.0
    for k, v in keys.items():
        if v is None:
            d.pop(k, None)
        else:
            d[k] = v
    where.mkdir(parents=True, exist_ok=True)
    path = where / "scen.yaml"
    path.write_text(yaml.safe_dump(d))
    return path


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    """A 1 s quickstart dataset; tests copy it before changing anything."""
    out = tmp_path_factory.mktemp("ds") / "qs"
    assert run(out) == 0
    return out


def copy(ds: Path, dest: Path) -> Path:
    import shutil

    shutil.copytree(ds, dest)
    return dest


def remanifest(root: Path) -> None:
    """Rewrite manifest.json to list the files now present (a consistent but forged
    dataset, as an old r2rsim or a tool could leave)."""
    m = json.loads((root / "manifest.json").read_text())
    m["files"] = {
        p.relative_to(root).as_posix(): {"sha256": sha256_file(p), "bytes": p.stat().st_size}
        for p in sorted(root.rglob("*"))
        if p.is_file() and p.name != "manifest.json"
    }
    (root / "manifest.json").write_text(json.dumps(m))


# 1. output directories: no clobber, --overwrite replaces only r2rsim datasets -------------


def test_directory_with_a_foreign_manifest_is_never_replaced(tmp_path, capsys):
    # the reported data loss: {} in manifest.json was enough to delete the directory
    proj = tmp_path / "proj"
    proj.mkdir()
    (proj / "manifest.json").write_text("{}")
    (proj / "thesis.tex").write_text("precious")
    before = tree(tmp_path)
    for extra in ((), ("--overwrite",)):
        assert run(proj, *extra) == 2
        err = capsys.readouterr().err
        assert "is not an r2rsim dataset" in err and str(proj) in err
        assert len(err.strip().splitlines()) == 1
        assert tree(tmp_path) == before  # nothing changed, no temporary directory left
        assert sorted(p.name for p in tmp_path.iterdir()) == ["proj"]


def test_existing_dataset_needs_overwrite(dataset, tmp_path, capsys):
    out = copy(dataset, tmp_path / "qs")
    before = tree(out)
    assert run(out) == 2
    assert "exists (an r2rsim dataset); pass --overwrite to replace it" in capsys.readouterr().err
    assert tree(out) == before
    with pytest.raises(InputError, match="pass --overwrite"):
        r2rsim.run_scenario(QUICK, output=out, duration=1.0)
    # --overwrite (overwrite=True) replaces it: a 2 s run now
    r2rsim.run_scenario(QUICK, output=out, duration=2.0, overwrite=True)
    assert pq.read_table(out / "runs.parquet")["n_samples"][0].as_py() == 401
    assert validate_dataset(out) == []
    assert sorted(p.name for p in tmp_path.iterdir()) == ["qs"]


@pytest.mark.parametrize(
    "change", ["added file", "same-size edit", "empty dir", "symlink", "missing file"]
)
def test_changed_dataset_is_not_replaced(dataset, tmp_path, capsys, change):
    out = copy(dataset, tmp_path / "qs")
    normalised = next((out / "scenario").glob("*.normalised.yaml"))
    if change == "added file":
        (out / "samples" / "notes.txt").write_text("my notes")
    elif change == "same-size edit":  # only the sha256 tells
        text = normalised.read_bytes()
        normalised.write_bytes(text.replace(b"seed: 1", b"seed: 2"))
        assert len(normalised.read_bytes()) == len(text)
    elif change == "empty dir":
        (out / "analysis").mkdir()
    elif change == "symlink":
        (out / "link").symlink_to(tmp_path)
    else:
        (out / "events.parquet").unlink()
    assert dataset_problems(out)
    before = tree(out)
    assert run(out, "--overwrite") == 2
    assert "is not an r2rsim dataset" in capsys.readouterr().err
    assert tree(out) == before and (out / "analysis").exists() == (change == "empty dir")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["qs"]


def test_empty_directory_is_filled_files_and_links_are_refused(tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert run(empty) == 0 and validate_dataset(empty) == []
    f = tmp_path / "afile"
    f.write_text("x")
    assert run(f, "--overwrite") == 2 and f.read_text() == "x"
    assert "is not a directory" in capsys.readouterr().err
    link = tmp_path / "link"
    link.symlink_to(empty)
    assert run(link, "--overwrite") == 2 and link.is_symlink()
    assert "symbolic link" in capsys.readouterr().err
    assert validate_dataset(empty) == []


def test_a_directory_that_changes_during_the_run_is_checked_again_at_commit(dataset, tmp_path):
    meta = {"r2rsim.schema_version": "0.1"}
    # a dataset, overwrite asked for; a file appears in it while the run writes
    out = copy(dataset, tmp_path / "qs")
    before = tree(out)
    w = DatasetWriter(out, "x__s0", meta, overwrite=True)
    w.write_text("scenario/x.yaml", "x")
    (out / "late.txt").write_text("written during the run")
    with pytest.raises(InputError, match="not an r2rsim dataset"):
        w.commit({})
    w.abort()
    assert tree(out) == {**before, "late.txt": b"written during the run"}
    # nothing there at the start; someone else's directory appears during the run
    out2 = tmp_path / "new"
    w = DatasetWriter(out2, "x__s0", meta)
    w.write_text("scenario/x.yaml", "x")
    out2.mkdir()
    (out2 / "theirs.txt").write_text("theirs")
    with pytest.raises(InputError):
        w.commit({})
    w.abort()
    assert tree(out2) == {"theirs.txt": b"theirs"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new", "qs"]


def test_failed_run_removes_the_parent_directories_it_made(tmp_path):
    out = tmp_path / "a" / "b" / "ds"
    w = DatasetWriter(out, "x__s0", {})
    assert (tmp_path / "a" / "b").is_dir()
    w.abort()
    assert list(tmp_path.iterdir()) == []


def test_output_key_is_relative_to_the_scenario_and_stays_in_its_directory(
    tmp_path, monkeypatch, capsys
):
    proj = tmp_path / "proj"
    elsewhere = tmp_path / "cwd"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # the working directory does not matter
    scen = scenario_copy(proj, output="data/qs")
    assert main(["run", str(scen), "-q"]) == 0
    assert validate_dataset(proj / "data" / "qs") == []
    assert list(elsewhere.iterdir()) == []
    for bad in ("../outside", str(tmp_path / "abs"), ".", "data/../../outside"):
        scen = scenario_copy(proj, output=bad)
        assert main(["run", str(scen), "-q"]) == 2
        err = capsys.readouterr().err
        assert f"{scen}: output: " in err and "outside the scenario's directory" in err
        assert "-o" in err
        # `r2rsim validate` refuses what `r2rsim run` refuses, with the same message
        assert main(["validate", str(scen)]) == 2
        assert f"{scen}: output: " in capsys.readouterr().err
    # a symbolic link inside the project that leads out of it
    (proj / "out_link").symlink_to(tmp_path / "cwd", target_is_directory=True)
    scen = scenario_copy(proj, output="out_link/qs")
    assert main(["run", str(scen), "-q"]) == 2
    assert list(elsewhere.iterdir()) == []
    assert not (tmp_path / "outside").exists() and not (tmp_path / "abs").exists()
    # the user asks on the command line: anywhere
    assert main(["run", str(scen), "-o", str(tmp_path / "outside"), "-q"]) == 0
    assert validate_dataset(tmp_path / "outside") == []


# 2. names are identifiers; every path stays inside the dataset ---------------------------


@pytest.mark.parametrize(
    "name", ["../../../r2r_escape", "x/../../../../pwned", "a b", "", "/etc/r2r", "ok.name"]
)
def test_scenario_name_is_an_identifier(tmp_path, capsys, name):
    scen = scenario_copy(tmp_path / "p" / "q" / "r", name=name)
    before = tree(tmp_path)
    assert main(["run", str(scen), "-o", str(tmp_path / "p" / "out"), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: {scen}: name: ") and "not a valid id" in err
    assert tree(tmp_path) == before  # nothing written anywhere
    assert main(["validate", str(scen)]) == 2


def test_a_file_name_that_cannot_name_the_run_asks_for_a_name(tmp_path, capsys):
    scen = scenario_copy(tmp_path, name=None)
    bad = scen.rename(tmp_path / "my run.yaml")
    assert main(["run", str(bad), "-o", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: name: " in err and "add a name" in err
    assert main(["validate", str(bad)]) == 2  # validate asks for it too
    assert f"{bad}: name: " in capsys.readouterr().err
    good = bad.rename(tmp_path / "run-2024.yaml")
    assert main(["run", str(good), "-o", str(tmp_path / "out"), "-q"]) == 0
    assert (tmp_path / "out" / "samples" / "run_id=run-2024__s1").is_dir()


def test_writer_keeps_every_path_inside_its_temporary_directory(tmp_path):
    base = tmp_path / "base"
    base.mkdir()
    for run_id in ("../x", "a/b", "..", ""):
        with pytest.raises(R2RError):
            DatasetWriter(base / "ds", run_id, {})
    w = DatasetWriter(base / "ds", "x__s0", {})
    for rel in (
        "scenario/../../escape.yaml",
        "../escape.yaml",
        "/tmp/escape.yaml",
        "scenario/../../../escape.normalised.yaml",
        "scenario/leak/escape.yaml",
    ):
        with pytest.raises(R2RError, match="not where the dataset layout keeps"):
            w.write_text(rel, "x")
    with pytest.raises(R2RError, match="not a table of the dataset layout"):
        w.write_table("../runs", pa.table({"a": [1]}))
    # a path of the layout that a symbolic link leads out of: refused once resolved
    (w.tmp / "scenario").mkdir(exist_ok=True)  # made by the first write_text
    (w.tmp / "scenario" / "leak.yaml").symlink_to(tmp_path / "outside.yaml")
    with pytest.raises(R2RError, match="outside the dataset directory"):
        w.write_text("scenario/leak.yaml", "x")
    w.abort()
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["base"]


def test_validator_flags_a_layout_that_escapes(dataset, tmp_path):
    # what the old writer made of name: "../../../r2r_escape": a run id with '..' whose
    # samples landed elsewhere, and a manifest that lists only what stayed inside
    ds = copy(dataset, tmp_path / "ds")
    runs = pq.read_table(ds / "runs.parquet")
    rid = "../../../r2r_escape__s1"
    runs = runs.set_column(0, "run_id", pa.array([rid]))
    pq.write_table(runs, ds / "runs.parquet")
    (ds / "r2r_escape__s1").mkdir()
    os.replace(
        next((ds / "samples").glob("*/part-0.parquet")), ds / "r2r_escape__s1" / "part-0.parquet"
    )
    (ds / "samples" / "run_id=quickstart__s1").rmdir()
    (ds / "samples" / "run_id=..").mkdir()
    m = json.loads((ds / "manifest.json").read_text())
    m["run_ids"] = [rid]
    (ds / "manifest.json").write_text(json.dumps(m))
    remanifest(ds)
    problems = validate_dataset(ds)
    assert any("not a plain directory name" in p for p in problems), problems
    assert main(["validate", str(ds)]) == 2
    # a manifest that lists a file outside the dataset, and a file that is not listed
    ds2 = copy(dataset, tmp_path / "ds2")
    (tmp_path / "outside.txt").write_text("x")
    m = json.loads((ds2 / "manifest.json").read_text())
    m["files"]["../outside.txt"] = {"sha256": sha256_file(tmp_path / "outside.txt"), "bytes": 1}
    (ds2 / "manifest.json").write_text(json.dumps(m))
    (ds2 / "extra.bin").write_bytes(b"?")
    problems = validate_dataset(ds2)
    assert any("'../outside.txt', a path that leaves the dataset" in p for p in problems)
    assert any("extra.bin: not listed in manifest.json" in p for p in problems)
    # a symbolic link out of the dataset
    ds3 = copy(dataset, tmp_path / "ds3")
    (ds3 / "scenario" / "elsewhere").symlink_to(tmp_path, target_is_directory=True)
    assert any("a symbolic link" in p for p in validate_dataset(ds3))


# 7. signals and stale temporary directories ----------------------------------------------


def _dead_pid() -> int:
    """A process id that no process has now."""
    try:
        top = int(Path("/proc/sys/kernel/pid_max").read_text())
    except OSError:
        top = 32768
    for pid in range(top - 1, 300, -1):
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return pid
        except PermissionError:
            continue
    pytest.skip("no free process id found")


def _cli(*args, cwd):
    return subprocess.Popen(
        [sys.executable, "-m", "r2rsim.cli", *args],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_signal_during_a_run_leaves_nothing(tmp_path, sig, code):
    scen = REPO / "scenarios" / "thesis_normal_cycles.yaml"
    p = _cli("run", str(scen), "-o", "out", "--duration", "100000", "-q", cwd=tmp_path)
    part = None
    t0 = time.monotonic()
    while part is None and time.monotonic() - t0 < 180 and p.poll() is None:
        part = next(tmp_path.glob(f".out.tmp-{p.pid}/samples/*/part-0.parquet"), None)
        time.sleep(0.05)
    assert part is not None, "the run never started writing"
    time.sleep(0.5)  # well inside the run
    p.send_signal(sig)
    _, err = p.communicate(timeout=120)
    assert p.returncode == code, err
    assert ("terminated (SIGTERM)" if sig == signal.SIGTERM else "interrupted") in err
    assert "Traceback" not in err
    assert list(tmp_path.iterdir()) == []  # no dataset, no temporary directory


def test_sigterm_handler_is_only_installed_during_the_run(tmp_path):
    before = signal.getsignal(signal.SIGTERM)
    assert run(tmp_path / "out") == 0
    assert signal.getsignal(signal.SIGTERM) == before


def test_stale_temporaries_of_dead_processes_are_removed_and_nothing_else(tmp_path):
    dead = _dead_pid()
    mine = os.getpid()  # a live process (this one) that is not the run's

    def fake_tmp(name: str) -> Path:
        d = tmp_path / name
        (d / "samples" / "run_id=x__s0").mkdir(parents=True)
        (d / "samples" / "run_id=x__s0" / "part-0.parquet").write_bytes(b"PAR1 partial")
        (d / "scenario").mkdir()
        return d

    fake_tmp(f".out.tmp-{dead}")
    fake_tmp(f".other.tmp-{dead}")
    fake_tmp(f".out.tmp-{mine}")
    (tmp_path / ".foo").mkdir()
    (tmp_path / ".foo" / "keep.txt").write_text("keep")
    foreign = tmp_path / f".notes.tmp-{dead}"  # the pattern, but not what r2rsim writes
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("precious")
    p = _cli("run", str(QUICK), "-o", "out", "--duration", "1", "-q", cwd=tmp_path)
    _, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    assert sorted(x.name for x in tmp_path.iterdir()) == sorted(
        [".foo", f".notes.tmp-{dead}", f".out.tmp-{mine}", "out"]
    )
    assert (foreign / "thesis.tex").read_text() == "precious"
    assert (tmp_path / ".foo" / "keep.txt").read_text() == "keep"


def test_an_interrupted_overwrite_is_undone_by_the_next_run(dataset, tmp_path):
    # killed between moving the old dataset aside and moving the new one in: put it back
    dead = _dead_pid()
    old = copy(dataset, tmp_path / f".qs.old-{dead}")
    before = tree(old)
    assert clean_stale(tmp_path) == [tmp_path / "qs"]
    assert tree(tmp_path / "qs") == before
    # killed after the swap: the new dataset is in place, the old one is removed
    copy(dataset, tmp_path / f".qs.old-{dead}")
    assert clean_stale(tmp_path) == [tmp_path / f".qs.old-{dead}"]
    assert sorted(x.name for x in tmp_path.iterdir()) == ["qs"]
    # ... unless it is not (only) an r2rsim dataset
    kept = copy(dataset, tmp_path / f".qs.old-{dead}")
    (kept / "mine.txt").write_text("mine")
    assert clean_stale(tmp_path) == []
    assert (kept / "mine.txt").exists()


def test_own_pid_temporary_is_stale_unless_a_writer_uses_it(tmp_path):
    # a container's first process gets the same pid every time: its leftovers still go
    w = DatasetWriter(tmp_path / "a", "x__s0", {})
    assert clean_stale(tmp_path) == [] and w.tmp.is_dir()  # in use
    paths.ACTIVE.discard(w.tmp.resolve())  # as after a SIGKILL and a restart
    assert clean_stale(tmp_path) == [w.tmp]
    assert list(tmp_path.iterdir()) == []


# 8. memory flat in run length: row groups and a validator that streams -----------------


@pytest.mark.parametrize("group_bytes, groups", [(None, 1), (20_000, (2, 50))])
def test_small_chunks_are_collected_into_row_groups(tmp_path, monkeypatch, group_bytes, groups):
    # solver chunks end at every event, some a few rows long: one row group each made the
    # footer the writer keeps in memory grow with the run
    if group_bytes:
        monkeypatch.setattr(writer, "ROW_GROUP_BYTES", group_bytes)
    w = DatasetWriter(tmp_path / "ds", "x__s0", {})
    rng = np.random.default_rng(0)
    chunks = []
    for i in range(300):
        k = np.arange(10 * i, 10 * i + 10)
        chunks.append(
            {
                "k": k,
                "t_s": k / 100.0,
                "a": rng.random(10).astype(np.float32),
                "label.phase": np.array(["normal", "faulty"] * 5, dtype=object),
                "label.fault_ids": [["f1"], []] * 5,
            }
        )
        w.write_chunk(chunks[-1])
    w.commit({})
    pf = pq.ParquetFile(tmp_path / "ds" / "samples" / "run_id=x__s0" / "part-0.parquet")
    assert pf.metadata.num_rows == 3000
    if isinstance(groups, tuple):
        assert groups[0] <= pf.num_row_groups <= groups[1], pf.num_row_groups
    else:
        assert pf.num_row_groups == groups
    t = pf.read()
    np.testing.assert_array_equal(t["k"].to_numpy(), np.arange(3000))
    np.testing.assert_array_equal(t["a"].to_numpy(), np.concatenate([c["a"] for c in chunks]))
    assert t["label.phase"].to_pylist() == ["normal", "faulty"] * 1500
    assert t["label.fault_ids"].to_pylist() == [["f1"], []] * 1500


def test_validator_reads_the_samples_in_batches(tmp_path, monkeypatch):
    monkeypatch.setattr(validate, "BATCH_ROWS", 300)  # many batches, not row-group aligned
    path = REPO / "scenarios" / "line_a_faults.yaml"
    out = tmp_path / "ds"
    r2rsim.run_scenario(path, output=out, duration=45.0)  # all three onsets
    part = next((out / "samples").glob("*/part-0.parquet"))
    n = pq.ParquetFile(part).metadata.num_rows
    # the validator never loads a whole samples file
    real = pq.read_table

    def no_samples(source, *a, **kw):
        assert "samples" not in str(source), "validate_dataset read a whole samples file"
        return real(source, *a, **kw)

    monkeypatch.setattr(pq, "read_table", no_samples)
    assert validate_dataset(out) == []
    # a wrong label deep in a later batch is still found, at the right k
    faults = real(out / "faults.parquet").to_pylist()
    table = real(part)
    k_bad = n - 7
    flags = table.column("label.phase").to_pylist()
    flags[k_bad] = "warmup"
    i = table.column_names.index("label.phase")
    table = table.set_column(
        i,
        table.schema.field(i),
        pa.array(flags).dictionary_encode().cast(table.schema.field(i).type),
    )
    pq.write_table(table, part, row_group_size=500)
    problems = validate_dataset(out)
    assert any(f"label.phase at k = {k_bad} is 'warmup'" in p for p in problems), problems
    # onset_k is checked against the first sample at or after the onset, in any batch
    assert len(faults) == 3 and all(f["onset_k"] > 300 for f in faults)
    ft = real(out / "faults.parquet")
    j = ft.column_names.index("onset_k")
    pq.write_table(
        ft.set_column(j, "onset_k", pa.array(np.asarray(ft.column("onset_k")) + 1)),
        out / "faults.parquet",
    )
    assert sum("onset_k" in p for p in validate_dataset(out)) == len(faults)
