"""r2rsim.datasets: the canonical datasets, generated on first use into a cache, checked on
every use, split as `r2rsim diagnose` splits them, and the same data as the command line."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys

import pytest

from r2rsim import InputError, datasets
from r2rsim.evaluate.splits import is_faulty

from conftest import REPO


def _sha256s(root):
    """{relative path: sha256} of a dataset's samples files, from its manifest.json."""
    files = json.loads((root / "manifest.json").read_text())["files"]
    return {rel: f["sha256"] for rel, f in files.items() if rel.startswith("samples/")}


def test_first_benchmark_split(first_benchmark_home):
    data = datasets.load_first_benchmark(data_home=first_benchmark_home, quiet=True)
    split = data.split
    assert (len(split.train), len(split.val), len(split.test)) == (6, 2, 32)
    # fit and calibrate on fault-free runs of both conditions; every faulty run is a test run
    for role in (split.train, split.val):
        assert not any(is_faulty(r) for r in role)
        assert {r.info["operating_mode"] for r in role} == {"OC1", "OC2"}
    faulty = [r for r in split.test if is_faulty(r)]
    assert len(faulty) == 30
    types = {(r.faults["fault_type"].iloc[0], r.faults["target_id"].iloc[0]) for r in faulty}
    assert types == {
        ("sensor.offset", "sensor_A"),
        ("sensor.gain", "sensor_B"),
        ("process.draw_error", "reg_drive"),
    }
    assert len({r.run_id for r in data.runs}) == 40
    assert all(r.samples["t_s"].iloc[-1] == pytest.approx(20.0) for r in data.runs)
    assert data.paths == [first_benchmark_home / "first_benchmark"]


def test_a_second_load_reuses_the_cache(first_benchmark_home, capsys):
    root = first_benchmark_home / "first_benchmark"
    before = {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file()}
    data = datasets.load_first_benchmark(data_home=first_benchmark_home)
    after = {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file()}
    assert after == before  # nothing simulated nor rewritten
    assert "simulating" not in capsys.readouterr().err
    assert len(data.runs) == 40


def test_same_data_as_the_command_line(first_benchmark_home, tmp_path):
    out = tmp_path / "cli"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "r2rsim.cli",
            "sweep",
            str(REPO / "sweeps/first_benchmark.yaml"),
            "-o",
            str(out),
            "-q",
        ],
        check=True,
        cwd=tmp_path,
    )
    cached = _sha256s(first_benchmark_home / "first_benchmark")
    assert len(cached) == 40
    assert _sha256s(out) == cached


def test_a_changed_cache_is_simulated_again(first_benchmark_home, tmp_path, capsys):
    """A samples file changed in the cache fails its checksum when the sweep is reopened: that
    run is simulated again, and the data are the same as before."""
    home = tmp_path / "home"
    shutil.copytree(first_benchmark_home, home)
    part = sorted((home / "first_benchmark" / "samples").rglob("*.parquet"))[3]
    raw = bytearray(part.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    part.write_bytes(bytes(raw))
    data = datasets.load_first_benchmark(data_home=home, quiet=True)
    assert len(data.runs) == 40
    assert _sha256s(home / "first_benchmark") == _sha256s(first_benchmark_home / "first_benchmark")
    assert (
        hashlib.sha256(part.read_bytes()).hexdigest()
        == _sha256s(first_benchmark_home / "first_benchmark")[
            part.relative_to(home / "first_benchmark").as_posix()
        ]
    )


def test_data_home(tmp_path, monkeypatch):
    monkeypatch.setenv("R2RSIM_DATA", str(tmp_path / "a"))
    assert datasets.get_data_home() == tmp_path / "a"
    assert (tmp_path / "a").is_dir()
    assert datasets.get_data_home(tmp_path / "b") == tmp_path / "b"
    monkeypatch.delenv("R2RSIM_DATA")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert datasets.get_data_home() == tmp_path / "xdg" / "r2rsim" / "datasets"


def test_unknown_thesis_study(tmp_path):
    with pytest.raises(InputError, match="unknown study 'globl'.*local, global"):
        datasets.load_thesis_realistic("globl", data_home=tmp_path)
    assert not (tmp_path / "thesis_realistic").exists()


def test_a_study_is_split_as_bench_splits_it(tmp_path):
    """The thesis loader's mechanism on a small spec: the runs of each role of the study, in
    the data home, and reused on the next call."""
    spec = tmp_path / "spec.yaml"
    spec.write_text(f"""\
name: small
duration: 22 s
studies:
  - name: s
    train: [{{scenario: {REPO}/scenarios/thesis/oc1_nominal.yaml, seeds: [1, 2]}}]
    val: [{{scenario: {REPO}/scenarios/thesis/oc1_nominal.yaml, seeds: [3]}}]
    test: [{{scenario: {REPO}/scenarios/thesis/sensor_a_offset_P05.yaml, seeds: [4]}}]
methods: [{{method: pca}}]
""")
    work = tmp_path / "home" / "small"
    data = datasets._load_study("small", spec, "s", work, quiet=True)
    assert [len(data.split.train), len(data.split.val), len(data.split.test)] == [2, 1, 1]
    assert [r.info["seed"] for r in data.split.train] == [1, 2]
    assert is_faulty(data.split.test[0]) and not is_faulty(data.split.val[0])
    assert data.split.name == "s" and len(data.paths) == 4
    mtimes = {p: p.stat().st_mtime_ns for p in work.rglob("*") if p.is_file()}
    again = datasets._load_study("small", spec, "s", work, quiet=True)
    assert {p: p.stat().st_mtime_ns for p in work.rglob("*") if p.is_file()} == mtimes
    assert [r.run_id for r in again.runs] == [r.run_id for r in data.runs]
    with pytest.raises(InputError, match="no study 'x'"):
        datasets._load_study("small", spec, "x", work, quiet=True)


def test_the_loaders_need_the_source_tree(monkeypatch, tmp_path):
    monkeypatch.setitem(datasets.DATASETS, "first_benchmark", ("sweeps/not_there.yaml", "gone"))
    with pytest.raises(InputError, match="install r2rsim from a checkout"):
        datasets.load_first_benchmark(data_home=tmp_path)
    assert os.listdir(tmp_path) == []
