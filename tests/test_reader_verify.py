"""Every reader verifies (issue 36 item 2): a dataset changed after it was written is refused
by every command that reads one, ``r2rsim plot`` (run and --sweep), ``report --data``,
``diagnose``, ``bench``, ``validate`` and the Python ``read_runs``, with a non-zero exit and
one message naming the dataset and the file or run; ``--no-verify`` reads it anyway.

Three changes: (i) one byte of a samples file flipped, (ii) one byte of faults.parquet
flipped (both in a string of the Parquet footer, so that the file still parses and only the
sha256 sees the change), (iii) labels forged with manifest.json re-hashed so that every
checksum passes: a fault's onset moved in faults.parquet of a sweep, a label column edited
in a run. Only what re-derives the labels catches (iii): ``validate``, ``read_runs`` (so
``diagnose``, ``bench`` and ``report``) and the run figure, which shades fault windows; the
sweep figure reads no label and no fault (docs/dataset.md §9.1)."""

from __future__ import annotations

import hashlib
import json
import shutil
import textwrap
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

pytest.importorskip("matplotlib")
import matplotlib  # noqa: E402

matplotlib.use("Agg")

from test_sweep import QUICK, scenario_copy, sweep_file  # noqa: E402

from r2rsim.cli import main  # noqa: E402
from r2rsim.dataset.read import read_runs  # noqa: E402
from r2rsim.dataset.validate import validate_dataset  # noqa: E402
from r2rsim.errors import InputError  # noqa: E402
from r2rsim.report import plot_run, plot_sweep  # noqa: E402
from r2rsim.sweep import run_sweep  # noqa: E402

#: two runs of 4 s (the quick-start warm-up is 2 s), an offset on the rewind load cell from 3 s
SWEEP_BODY = """\
set:
  duration: 4 s
  faults:
    - {id: lc_offset, type: sensor.offset, target: lc_rewind, onset: 3 s, magnitude: 5 N}
axes:
  - {name: offset, path: faults.lc_offset.magnitude, values: [-10 N, 10 N]}
seeds: 1
"""
CHANNEL = "meas.lc_rewind.tension_N"


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """A training run (quick start, 10 s, seed 1), a test run (seed 2), the two-run sweep,
    and a diagnose result scored on the test run and the sweep (for ``report --data``)."""
    d = tmp_path_factory.mktemp("verify")
    for name, seed in (("train", 1), ("run", 2)):
        assert (
            main(
                [
                    "run",
                    str(QUICK),
                    "--duration",
                    "10",
                    "--seed",
                    str(seed),
                    "-o",
                    str(d / name),
                    "-q",
                ]
            )
            == 0
        )
    summary = run_sweep(sweep_file(d / "sw", SWEEP_BODY, name="vsw"), output=d / "sweep", workers=0)
    assert summary.ok and summary.done == 2
    assert (
        main(
            [
                "diagnose",
                "--method",
                "residual",
                "--train",
                str(d / "train"),
                "--test",
                str(d / "run"),
                str(d / "sweep"),
                "--n-boot",
                "5",
                "-o",
                str(d / "results"),
            ]
        )
        == 0
    )
    return d


# ---- changing a copy of a dataset -----------------------------------------------------------


def samples_file(ds: Path, i: int = 0) -> Path:
    return sorted((ds / "samples").glob("run_id=*/part-0.parquet"))[i]


def flip_byte(f: Path) -> None:
    """Flip one bit of one byte in the file's footer (the last digit of the major version in
    its created_by string, "parquet-cpp-arrow version 26.0.1" -> 27.0.1): the file keeps
    its size and still parses, only its sha256 differs."""
    raw = bytearray(f.read_bytes())
    by = pq.read_metadata(f).created_by.encode()
    major = by.rsplit(b" ", 1)[1].split(b".")[0]
    raw[raw.rindex(by) + len(by) - len(by.rsplit(b" ", 1)[1]) + len(major) - 1] ^= 0x01
    f.write_bytes(bytes(raw))
    assert pq.read_metadata(f).created_by != by.decode()


def rehash(ds: Path) -> None:
    """manifest.json rewritten to match the files as they are now (what a forger does)."""
    man = json.loads((ds / "manifest.json").read_text())
    for rel, info in man["files"].items():
        f = ds / rel
        info["sha256"] = hashlib.sha256(f.read_bytes()).hexdigest()
        info["bytes"] = f.stat().st_size
    (ds / "manifest.json").write_text(json.dumps(man, indent=2, sort_keys=True))


def move_onset(ds: Path, by: float = 0.5) -> str:
    """The first fault's onset_t_s moved by ``by`` in faults.parquet, manifest re-hashed;
    returns the fault's run."""
    t = pq.read_table(ds / "faults.parquet")
    onset = t.column("onset_t_s").to_pylist()
    onset[0] += by
    i = t.column_names.index("onset_t_s")
    pq.write_table(
        t.set_column(i, "onset_t_s", pa.array(onset, pa.float64())), ds / "faults.parquet"
    )
    rehash(ds)
    return t.column("run_id")[0].as_py()


def edit_label(ds: Path, k: int = 1000) -> None:
    """label.is_faulty set at sample k of the first run's samples, manifest re-hashed."""
    f = samples_file(ds)
    t = pq.read_table(f)
    flags = t.column("label.is_faulty").to_pylist()
    flags[k] = not flags[k]
    i = t.column_names.index("label.is_faulty")
    pq.write_table(t.set_column(i, "label.is_faulty", pa.array(flags)), f)
    rehash(ds)


def changed(data, tmp_path, name: str, how: str) -> tuple[Path, str, str]:
    """A copy of dataset ``name`` changed ``how``; the file and run the refusal must name."""
    ds = shutil.copytree(data / name, tmp_path / name)
    run = read_runs(data / name)[0].run_id
    if how == "samples byte":
        f = samples_file(ds)
        flip_byte(f)
        return ds, f.relative_to(ds).as_posix(), run
    if how == "faults byte":
        flip_byte(ds / "faults.parquet")
        return ds, "faults.parquet", ""
    if name == "sweep":
        return ds, "label.", move_onset(ds)
    edit_label(ds)
    return ds, "label.is_faulty", run


def err_line(capsys, *words) -> str:
    """stderr is one 'error:' line holding every word."""
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "\n" not in err and "Traceback" not in err, err
    for w in words:
        assert str(w) in err, (w, err)
    return err


CASES = [
    (name, how) for name in ("run", "sweep") for how in ("samples byte", "faults byte", "labels")
]


# ---- the untouched datasets -----------------------------------------------------------------


def test_untouched_datasets_pass_every_reader(data, tmp_path, capsys):
    for name in ("run", "sweep"):
        assert len(read_runs(data / name)) == (1 if name == "run" else 2)
        assert main(["validate", str(data / name)]) == 0
        assert main(["plot", str(data / name), "-o", str(tmp_path / f"{name}.png")]) == 0
    assert (
        main(["plot", str(data / "sweep"), "--sweep", CHANNEL, "-o", str(tmp_path / "sw.png")]) == 0
    )
    assert (
        main(
            [
                "diagnose",
                "--method",
                "residual",
                "--train",
                str(data / "train"),
                "--test",
                str(data / "run"),
                str(data / "sweep"),
                "--n-boot",
                "5",
                "-o",
                str(tmp_path / "res"),
            ]
        )
        == 0
    )
    assert (
        main(
            [
                "report",
                str(data / "results"),
                "--data",
                str(data / "run"),
                str(data / "sweep"),
                "-o",
                str(tmp_path / "r.html"),
            ]
        )
        == 0
    )
    assert "error" not in capsys.readouterr().err


# ---- (i), (ii), (iii) -----------------------------------------------------------------------


@pytest.mark.parametrize("name, how", CASES)
def test_changed_dataset_is_refused_by_every_reader(name, how, data, tmp_path, capsys):
    ds, what, run = changed(data, tmp_path, name, how)
    words = [f"dataset {ds}", what, "--no-verify"] + ([f"run {run}"] if run else [])
    checksum = how != "labels"
    if checksum:
        words.append("checksum differs from manifest.json")
    else:
        words += ["faults.parquet gives", "r2rsim validate"]
    # read_runs, and diagnose and report --data through it
    with pytest.raises(InputError) as exc:
        read_runs(ds)
    for w in words:
        assert w in str(exc.value), (w, str(exc.value))
    out = tmp_path / "out"
    train = str(data / "train")
    assert (
        main(
            [
                "diagnose",
                "--method",
                "residual",
                "--train",
                train,
                "--test",
                str(ds),
                "--n-boot",
                "5",
                "-o",
                str(out),
            ]
        )
        == 2
    )
    err_line(capsys, *words)
    assert not out.exists()
    html = tmp_path / "r.html"
    scored = [str(ds), str(data / "sweep")] if name == "run" else [str(data / "run"), str(ds)]
    assert main(["report", str(data / "results"), "--data", *scored, "-o", str(html)]) == 2
    err_line(capsys, *words)
    assert not html.exists()
    # validate lists it (every problem, one per line)
    assert main(["validate", str(ds)]) == 2
    err = capsys.readouterr().err
    assert ("checksum differs from manifest.json" if checksum else "faults.parquet gives") in err
    # the figures: a changed file is refused; the run figure, which shades the fault
    # windows, also checks the labels of the run it draws (the sweep figure reads no label
    # and no fault: an edited faults.parquet is refused there by its checksum only)
    png = tmp_path / "fig.png"
    figures = [["plot", str(ds), "-o", str(png)] + (["--run", run] if run else [])]
    if name == "sweep":
        figures.append(["plot", str(ds), "--sweep", CHANNEL, "-o", str(png)])
    for args in figures:
        if checksum:
            assert main(args) == 2
            err_line(
                capsys, f"dataset {ds}", what, "checksum differs from manifest.json", "--no-verify"
            )
            assert not png.exists()
        elif "--sweep" not in args:
            assert main(args) == 2
            err_line(capsys, f"dataset {ds}", f"run {run}", "faults.parquet gives", "--no-verify")
            assert not png.exists()
        assert main([*args, "--no-verify", "--overwrite"]) == 0
        assert png.exists()
        png.unlink()
        capsys.readouterr()
    # --no-verify reads it
    assert (
        main(
            [
                "diagnose",
                "--method",
                "residual",
                "--train",
                train,
                "--test",
                str(ds),
                "--n-boot",
                "5",
                "-o",
                str(out),
                "--no-verify",
            ]
        )
        == 0
    )
    assert (
        main(["report", str(data / "results"), "--data", *scored, "-o", str(html), "--no-verify"])
        == 0
    )
    assert len(read_runs(ds, verify=False)) == len(read_runs(data / name))


def test_forged_labels_name_the_run_column_k_and_both_values(data, tmp_path):
    ds, _, run = changed(data, tmp_path, "run", "labels")
    with pytest.raises(
        InputError,
        match=rf"run {run}: label\.is_faulty at k = 1000 is True; "
        rf"faults\.parquet gives False: .*`r2rsim validate {ds}`",
    ):
        read_runs(ds)
    # the checksums alone pass; check_labels=False skips the label check
    assert read_runs(ds, check_labels=False)[0].samples["label.is_faulty"].iloc[1000]


def test_a_moved_onset_is_refused_though_the_samples_are_untouched(data, tmp_path):
    ds, _, run = changed(data, tmp_path, "sweep", "labels")  # onset 3 s -> 3.5 s
    with pytest.raises(InputError, match=rf"run {run}: label\.\S+ at k = 600 is"):
        read_runs(ds)
    other = [r for r in read_runs(data / "sweep") if r.run_id != run]
    # where= selects the other run: its labels are right, so it is read
    assert [r.run_id for r in read_runs(ds, where={"run_id": other[0].run_id})] == [other[0].run_id]


# ---- what the figures check -----------------------------------------------------------------


def flip_in_column(f: Path, column: str) -> None:
    """Flip a byte in the middle of one column's data (compressed: reading it fails)."""
    meta = pq.read_metadata(f)
    i = meta.schema.names.index(column)
    cc = meta.row_group(0).column(i)
    start = cc.dictionary_page_offset or cc.data_page_offset
    raw = bytearray(f.read_bytes())
    raw[start + cc.total_compressed_size // 2] ^= 0xFF
    f.write_bytes(bytes(raw))


def test_the_figure_hashes_the_whole_samples_file(data, tmp_path, capsys):
    """The run figure reads a few columns; a byte changed in a column it does not read is
    still refused (the whole file is hashed), and drawn with --no-verify."""
    ds = shutil.copytree(data / "run", tmp_path / "ds")
    f = samples_file(ds)
    flip_in_column(f, "label.severity")
    png = tmp_path / "fig.png"
    assert main(["plot", str(ds), "--channels", "sp.*", "-o", str(png)]) == 2
    err_line(capsys, f.relative_to(ds).as_posix(), "checksum differs from manifest.json")
    assert main(["plot", str(ds), "--channels", "sp.*", "-o", str(png), "--no-verify"]) == 0
    with pytest.raises(InputError, match="checksum differs"):
        plot_run(ds, channels="sp.*")
    plot_run(ds, channels="sp.*", verify=False)


def test_a_damaged_file_is_refused_by_its_size_or_checksum_first(data, tmp_path, capsys):
    """A truncated file: its size, before anything is parsed; one that no longer parses:
    its checksum, not the parse error."""
    ds = shutil.copytree(data / "sweep", tmp_path / "ds")
    f = samples_file(ds, 1)
    size = f.stat().st_size
    f.write_bytes(f.read_bytes()[:100])
    png = tmp_path / "fig.png"
    assert main(["plot", str(ds), "--sweep", CHANNEL, "-o", str(png)]) == 2
    err_line(
        capsys,
        f.relative_to(ds).as_posix(),
        f"has 100 bytes, manifest.json says {size}",
        "--no-verify",
    )
    ds2 = shutil.copytree(data / "run", tmp_path / "ds2")
    f = samples_file(ds2)
    meta = pq.read_metadata(f)
    cc = meta.row_group(0).column(meta.schema.names.index("t_s"))
    raw = bytearray(f.read_bytes())  # the page header of t_s overwritten: unreadable
    start = cc.dictionary_page_offset or cc.data_page_offset
    raw[start : start + 16] = b"\xff" * 16
    f.write_bytes(bytes(raw))
    assert main(["plot", str(ds2), "-o", str(png)]) == 2
    err_line(capsys, "checksum differs from manifest.json")
    assert main(["plot", str(ds2), "-o", str(png), "--no-verify"]) == 2
    err_line(capsys, "cannot be read")


def test_an_unlisted_file_is_never_read(data, tmp_path, capsys):
    ds = shutil.copytree(data / "run", tmp_path / "ds")
    f = samples_file(ds)
    shutil.copy(f, f.with_name("part-1.parquet"))  # a second part the run never wrote
    png = tmp_path / "fig.png"
    assert main(["plot", str(ds), "-o", str(png)]) == 2
    err_line(capsys, "part-1.parquet is not listed in manifest.json", "--no-verify")
    with pytest.raises(InputError, match="part-1.parquet is not listed in manifest.json"):
        read_runs(ds)


def test_a_listed_file_gone_is_refused_though_the_figure_does_not_read_it(data, tmp_path, capsys):
    ds = shutil.copytree(data / "sweep", tmp_path / "ds")
    (ds / "events.parquet").unlink()
    assert main(["plot", str(ds), "--sweep", CHANNEL, "-o", str(tmp_path / "f.png")]) == 2
    err_line(capsys, "events.parquet is missing (listed in manifest.json)")
    (ds / "manifest.json").unlink()
    with pytest.raises(InputError, match="no manifest.json"):
        plot_sweep(ds, CHANNEL)
    plot_sweep(ds, CHANNEL, verify=False)


def test_an_unfinished_sweep_is_refused(data, tmp_path, capsys):
    ds = shutil.copytree(data / "sweep", tmp_path / "ds")
    (ds / ".r2rsim-sweep.json").write_text("{}")
    for args in ([str(ds)], [str(ds), "--sweep", CHANNEL]):
        assert main(["plot", *args, "-o", str(tmp_path / "f.png"), "--no-verify"]) == 2
        err_line(capsys, f"dataset {ds}: an unfinished sweep")


# ---- bench --------------------------------------------------------------------------------


BENCH = """\
name: verify
studies:
  - name: s
    train: [{{scenario: {scenario}, seeds: [1]}}]
    test: [{{sweep: {sweep}}}]
methods:
  - {{method: residual}}
evaluation: {{n_boot: 5}}
"""


@pytest.fixture(scope="module")
def bench(data, tmp_path_factory):
    """A bench spec training on a 10 s quick-start run and testing on the two-run sweep, run
    once into a work directory."""
    d = tmp_path_factory.mktemp("bench")
    scenario = scenario_copy(d / "scen", duration="10 s")
    sweep = sweep_file(d / "sw", SWEEP_BODY, name="vsw", scenario=scenario)
    spec = d / "spec.yaml"
    spec.write_text(textwrap.dedent(BENCH.format(scenario=scenario, sweep=sweep)))
    assert main(["bench", str(spec), "--workdir", str(d / "work")]) == 0
    return spec, d / "work"


def test_bench_refuses_a_sweep_with_forged_labels_in_its_workdir(bench, tmp_path, capsys):
    """A finished sweep in the work directory is reopened after a check of its sizes only,
    and its runs were written without their labels checked: read_runs checks them."""
    spec, work = bench
    work = shutil.copytree(work, tmp_path / "work")
    (sweep,) = [p for p in work.iterdir() if p.name.startswith("sweep__")]
    run = move_onset(sweep)
    capsys.readouterr()
    assert main(["bench", str(spec), "--workdir", str(work)]) == 2
    err_line(capsys, f"dataset {sweep}", f"run {run}", "faults.parquet gives", "--no-verify")
    assert main(["bench", str(spec), "--workdir", str(work), "--no-verify"]) == 0


def test_bench_simulates_a_changed_sweep_run_again(bench, tmp_path, capsys):
    """A byte flipped in a run of the sweep: the sweep, reopened, finds the run's checksum
    wrong and simulates it again; bench then reads the sweep verified."""
    spec, work = bench
    work = shutil.copytree(work, tmp_path / "work")
    (sweep,) = [p for p in work.iterdir() if p.name.startswith("sweep__")]
    flip_byte(samples_file(sweep))
    assert main(["bench", str(spec), "--workdir", str(work)]) == 0
    assert validate_dataset(sweep) == []


def test_bench_simulates_a_forged_scenario_dataset_again(bench, tmp_path, capsys):
    """A scenario's dataset in the work directory is bench's cache: one whose labels were
    forged is deleted and simulated again (with a warning), never used."""
    spec, work = bench
    work = shutil.copytree(work, tmp_path / "work")
    (ds,) = [p for p in work.iterdir() if p.name.startswith("base__")]
    edit_label(ds)
    capsys.readouterr()
    assert main(["bench", str(spec), "--workdir", str(work)]) == 0
    err = capsys.readouterr().err
    assert f"warning: bench workdir: dataset {ds}" in err
    assert "label.is_faulty at k = 1000" in err and "simulating it again" in err
    assert read_runs(ds)  # the new one is intact
