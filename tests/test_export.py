"""``r2rsim export``: a dataset as TimeEval and TSB-AD CSV files (docs/dataset.md §13).

The files are read back with pandas (and, where installed, aeon's TimeEval loader) and
compared with the dataset: the values exactly as float32, the labels against what
faults.parquet gives (onset <= t < end, computed here independently), the index rows against
the files, the split against its definition.
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from r2rsim.cli import main
from r2rsim.dataset.read import read_runs
from r2rsim.evaluate.export import TIMEEVAL_INDEX_COLUMNS, export_dataset, select_channels
from r2rsim.sweep import run_sweep

from conftest import REPO

pytestmark = pytest.mark.filterwarnings("ignore::r2rsim.errors.PlausibilityWarning")

# fault-free, one sensor offset, and the offset with an actuator bias and a dropout (NaN
# readings), each at 4 seeds: 12 runs of 4 s at 50 Hz, a warm-up of 1 s
OFFSET = "{id: f_off, type: sensor.offset, target: lc_rewind, onset: 2 s, end: 3 s, magnitude: 5 N}"
SWEEP = f"""\
name: exp
scenario: {REPO / "scenarios/quickstart.yaml"}
set: {{duration: 4 s, record_rate: 50 Hz, warmup: 1 s}}
axes:
  - name: case
    path: faults
    values:
      - []
      - [{OFFSET}]
      - [{OFFSET},
         {{id: bias, type: actuator.bias, target: pull, onset: 2.5 s, magnitude: 2 N*m}},
         {{id: drop, type: sensor.dropout, target: lc_unwind, onset: 3.0 s, end: 3.2 s}}]
seeds: 4
"""


#: pandas before 3 parses floats with a fast parser that can be off by an ulp (seen with
#: pandas 2.1, the lowest version r2rsim supports); pandas 3 parses them exactly by default
#: and deprecates the option
_EXACT = {"float_precision": "round_trip"} if int(pd.__version__.split(".")[0]) < 3 else {}


def _read(path):
    """A CSV read the way an exact reader reads it."""
    return pd.read_csv(path, **_EXACT)


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("export")
    (d / "sweep.yaml").write_text(SWEEP, encoding="utf-8")
    summary = run_sweep(d / "sweep.yaml", output=d / "ds", workers=0)
    assert summary.ok and summary.done == 12
    return d / "ds"


@pytest.fixture(scope="module")
def runs(dataset):
    return {r.run_id: r for r in read_runs(dataset)}


@pytest.fixture(scope="module")
def timeeval(dataset, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("te") / "out"
    assert main(["export", str(dataset), "--format", "timeeval", "-o", str(out)]) == 0
    return out


def _faults_label(dataset: Path, run_id: str, t: np.ndarray, which=None) -> np.ndarray:
    """1 where a fault of the run (of type or class ``which``; any when None) is present,
    from faults.parquet alone: onset <= t < end (no end: to the end of the run)."""
    f = pd.read_parquet(dataset / "faults.parquet")
    f = f[f.run_id == run_id]
    if which is not None:
        f = f[(f.fault_type == which) | (f.fault_class == which)]
    y = np.zeros(len(t), bool)
    for onset, end in zip(f.onset_t_s, f.end_t_s, strict=True):
        y |= (t >= onset) & (t < (np.inf if pd.isna(end) else end))
    return y


def _meas(run) -> list[str]:
    return [c for c in run.samples.columns if c.startswith("meas.")]


def _segments(y: np.ndarray) -> list[int]:
    d = np.diff(np.concatenate([[0], y.astype(int), [0]]))
    return (np.flatnonzero(d == -1) - np.flatnonzero(d == 1)).tolist()


def test_timeeval_series_round_trip_exactly(timeeval, runs, dataset):
    files = sorted((timeeval / "r2rsim").glob("*.csv"))
    assert [f.stem for f in files] == sorted(runs)
    saw_nan = False
    for f in files:
        run = runs[f.stem]
        df = _read(f)
        # first column the time in s, the measured channels in samples order, the label last
        assert list(df.columns) == ["timestamp", *_meas(run), "is_anomaly"]
        assert not any(
            c.startswith(("true.", "state.", "act.", "cmd.", "label.", "flag.")) for c in df.columns
        )
        np.testing.assert_array_equal(df["timestamp"].to_numpy(), run.samples["t_s"].to_numpy())
        for c in _meas(run):
            got = df[c].to_numpy(np.float64).astype(np.float32)
            np.testing.assert_array_equal(got, run.samples[c].to_numpy())  # NaN == NaN here
            saw_nan |= bool(np.isnan(got).any())
        assert df["is_anomaly"].dtype.kind == "i" and set(df["is_anomaly"]) <= {0, 1}
        t = run.samples["t_s"].to_numpy()
        np.testing.assert_array_equal(
            df["is_anomaly"].to_numpy(bool), _faults_label(dataset, f.stem, t)
        )
        np.testing.assert_array_equal(
            df["is_anomaly"].to_numpy(bool), run.samples["label.is_faulty"].to_numpy()
        )
    assert saw_nan  # the dropout's NaN readings went through


def test_timeeval_index_matches_the_files(timeeval, runs):
    idx = _read(timeeval / "datasets.csv")
    assert tuple(idx.columns) == TIMEEVAL_INDEX_COLUMNS
    assert sorted(idx.dataset_name) == sorted(runs) and set(idx.collection_name) == {"r2rsim"}
    for row in idx.itertuples():
        df = _read(timeeval / row.test_path)
        y = df["is_anomaly"].to_numpy()
        seg = _segments(y)
        assert row.length == len(df) and row.dimensions == len(df.columns) - 2
        assert row.num_anomalies == len(seg) and row.contamination == pytest.approx(y.mean())
        assert row.min_anomaly_length == min(seg, default=0)
        assert row.max_anomaly_length == max(seg, default=0)
        assert row.input_type == "multivariate" and row.dataset_type == "synthetic"
        assert row.mean == pytest.approx(df.iloc[:, 1:-1].mean().mean())
        assert row.stddev == pytest.approx(df.iloc[:, 1:-1].std().mean())
        if row.train_type == "semi-supervised":
            # the training series: a fault-free run of the split's train role
            assert row.train_is_normal and row.train_path != row.test_path
            train = _read(timeeval / row.train_path)
            assert train["is_anomaly"].sum() == 0
            assert list(train.columns) == list(df.columns)
        else:
            assert row.train_type == "unsupervised" and pd.isna(row.train_path)
    # one run, the training series itself, is unsupervised; every other run trains on it
    unsup = idx[idx.train_type == "unsupervised"]
    assert len(unsup) == 1
    assert set(idx.train_path.dropna()) == {unsup.test_path.iloc[0]}


def test_split_selects_the_roles(dataset, tmp_path, runs):
    got = {}
    for role in ("train", "val", "test"):
        out = tmp_path / role
        assert (
            main(["export", str(dataset), "--format", "tsb-ad", "--split", role, "-o", str(out)])
            == 0
        )
        got[role] = set(_read(out / "file_list.csv").run_id)
    faulty = {rid for rid, r in runs.items() if len(r.faults)}
    assert got["train"] | got["val"] | got["test"] == set(runs)
    assert not (got["train"] & got["val"]) and not (got["train"] | got["val"]) & got["test"]
    assert faulty <= got["test"]  # every faulty run is a test run
    assert not faulty & (got["train"] | got["val"])
    # 4 fault-free runs apportioned 0.6/0.2/0.2: 2 train, 1 val, 1 test
    assert (len(got["train"]), len(got["val"]), len(got["test"])) == (2, 1, 9)
    # the TimeEval export of the test role still writes the training series it names
    out = tmp_path / "te-test"
    assert (
        main(["export", str(dataset), "--format", "timeeval", "--split", "test", "-o", str(out)])
        == 0
    )
    idx = _read(out / "datasets.csv")
    assert set(idx.dataset_name) == got["test"]
    train = {Path(p).stem for p in idx.train_path.dropna()}
    assert len(train) == 1 and train <= got["train"]
    assert len(list((out / "r2rsim").glob("*.csv"))) == 10


@pytest.mark.parametrize("which", ["sensor.offset", "sensor", "actuator"])
def test_family_labels_follow_faults_parquet(dataset, tmp_path, runs, which):
    out = tmp_path / "out"
    assert (
        main(["export", str(dataset), "--format", "tsb-ad", "--label", which, "-o", str(out)]) == 0
    )
    lst = _read(out / "file_list.csv")
    assert len(lst) == len(runs)
    differs_from_any = False
    for name, rid in zip(lst.file_name, lst.run_id, strict=True):
        run = runs[rid]
        df = _read(out / name)
        assert list(df.columns) == [*_meas(run), "Label"]  # no timestamp in TSB-AD
        t = run.samples["t_s"].to_numpy()
        want = _faults_label(dataset, rid, t, which)
        np.testing.assert_array_equal(df["Label"].to_numpy(bool), want)
        differs_from_any |= bool((want != run.samples["label.is_faulty"].to_numpy()).any())
        # TSB-AD reads the training-prefix length from the name's third field from the end
        fields = name.split(".")[0].split("_")
        first = int(np.argmax(want)) if want.any() else len(want)
        assert int(fields[-3]) == first and int(fields[-1]) == first
        assert re.fullmatch(r"\d{3}_R2RSIM_id_\d+_Sensor_tr_\d+_1st_\d+\.csv", name)
        for c in _meas(run):
            np.testing.assert_array_equal(
                df[c].to_numpy(np.float64).astype(np.float32), run.samples[c].to_numpy()
            )
    assert differs_from_any  # the family label is not the any-fault label in this sweep


def test_drop_warmup_writes_the_scored_rows(dataset, tmp_path, runs):
    out = tmp_path / "out"
    export_dataset(dataset, out, "timeeval", drop_warmup=True, split="test")
    for f in (out / "r2rsim").glob("*.csv"):
        run = runs[f.stem]
        df = _read(f)
        mask = run.samples["label.score_mask"].to_numpy()
        np.testing.assert_array_equal(
            df["timestamp"].to_numpy(), run.samples["t_s"].to_numpy()[mask]
        )
        assert df["timestamp"].iloc[0] == run.info["warmup_s"]


def test_output_is_deterministic(dataset, timeeval, tmp_path):
    out = tmp_path / "again"
    export_dataset(dataset, out, "timeeval")
    for f in timeeval.rglob("*.csv"):
        assert (out / f.relative_to(timeeval)).read_bytes() == f.read_bytes(), f


def test_channel_selection_protects_ground_truth(runs):
    cols = list(next(iter(runs.values())).samples.columns)
    everything = select_channels(cols, ["*"])
    assert everything and not any(
        c.startswith(("true.", "state.", "act.", "cmd.", "label.", "flag."))
        or "_seen_" in c
        or c in ("k", "t_s")
        for c in everything
    )
    assert any(c.startswith("sp.") for c in everything)
    assert select_channels(cols, ["true.*"]) == [c for c in cols if c.startswith("true.")]
    assert select_channels(cols, ["meas.lc_*", "true.lc_rewind.*"]) == [
        "meas.lc_unwind.tension_N",
        "meas.lc_rewind.tension_N",
        "true.lc_rewind.tension_N",
    ]
    assert "ctrl.lc_rewind.tension_seen_N" in select_channels(cols, ["ctrl.*_seen_*"])


def test_where_selects_runs(dataset, tmp_path):
    out = tmp_path / "out"
    assert (
        main(["export", str(dataset), "--format", "tsb-ad", "--where", "seed=0,1", "-o", str(out)])
        == 0
    )
    rids = _read(out / "file_list.csv").run_id
    assert len(rids) == 6 and all(r.endswith(("__s0", "__s1")) for r in rids)


@pytest.mark.parametrize(
    "args, msg",
    [
        (["--format", "csv"], "--format 'csv' is not one of timeeval, tsb-ad"),
        (["--format", "timeeval", "--label", "sensor.ofset"], "--label 'sensor.ofset' is not"),
        (["--format", "timeeval", "--split", "holdout"], "--split 'holdout' is not one of"),
        (
            ["--format", "timeeval", "--channels", "state.*", "meas.nope*"],
            "--channels 'meas.nope*' selects no channel",
        ),
        (["--format", "timeeval", "--channels", "*tension_N*x"], "selects no channel"),
        (["--format", "tsb-ad", "--channels", "label.*"], "holds "),
        (["--format", "timeeval", "--where", "seed=99"], "no run of"),
        (["--format", "timeeval", "--where", "size=1"], "no column 'size'"),
        (["--format", "timeeval", "--where", "seed"], "--where expects KEY=VALUE"),
    ],
)
def test_bad_input_exits_2_and_writes_nothing(dataset, tmp_path, capsys, args, msg):
    out = tmp_path / "out"
    code = main(["export", str(dataset), "-o", str(out), *args])
    err = capsys.readouterr().err
    assert code == 2, err
    assert err.startswith("error: ") and msg in err and len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []


def test_hidden_channels_are_named_in_the_message(dataset, tmp_path, capsys):
    code = main(
        [
            "export",
            str(dataset),
            "-o",
            str(tmp_path / "o"),
            "--format",
            "timeeval",
            "--channels",
            "*.lc_rewind.tension_N",
            "true.lc_unwind.*x",
        ]
    )
    assert code == 2
    assert "selects no channel" in capsys.readouterr().err
    # a pattern matching only protected columns says how to name them
    code = main(
        [
            "export",
            str(dataset),
            "-o",
            str(tmp_path / "o"),
            "--format",
            "timeeval",
            "--channels",
            "*.span1.*",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "--channels 'state.*'" in err, err


def test_existing_output_is_refused_and_left_alone(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    code = main(["export", str(dataset), "--format", "timeeval", "-o", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "exists and is not empty" in err
    assert [p.name for p in out.iterdir()] == ["notes.txt"]
    assert (out / "notes.txt").read_text() == "mine"
    # inside the dataset: refused (the dataset would no longer match its manifest)
    code = main(["export", str(dataset), "--format", "timeeval", "-o", str(dataset / "x")])
    assert code == 2 and "inside the dataset" in capsys.readouterr().err
    assert not (dataset / "x").exists()
    # an empty directory is filled
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["export", str(dataset), "--format", "tsb-ad", "-o", str(empty)]) == 0
    assert (empty / "file_list.csv").is_file()


def test_an_interrupted_export_leaves_nothing(dataset, tmp_path, monkeypatch):
    from r2rsim.evaluate import export

    real, calls = export._write_csv, []

    def stop_after_two(*args, **kwargs):
        calls.append(1)
        if len(calls) > 2:
            raise KeyboardInterrupt
        real(*args, **kwargs)

    monkeypatch.setattr(export, "_write_csv", stop_after_two)
    with pytest.raises(KeyboardInterrupt):
        export_dataset(dataset, tmp_path / "out", "timeeval")
    assert list(tmp_path.iterdir()) == []  # no output, no temporary directory


def test_aeon_reads_the_timeeval_files(timeeval, runs):
    """An independent reader: aeon's TimeEval loader. Skipped without aeon, unless
    R2RSIM_REQUIRE_AEON=1 (CI installs it), where a missing aeon fails."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        if os.environ.get("R2RSIM_REQUIRE_AEON") == "1":
            from aeon.datasets import load_from_timeeval_csv_file
        else:
            datasets = pytest.importorskip("aeon.datasets")
            load_from_timeeval_csv_file = datasets.load_from_timeeval_csv_file
    idx = _read(timeeval / "datasets.csv")
    for row in idx.itertuples():
        X, y = load_from_timeeval_csv_file(timeeval / row.test_path)
        run = runs[row.dataset_name]
        want = run.samples[_meas(run)].to_numpy()
        assert X.shape == want.shape == (row.length, row.dimensions)
        np.testing.assert_array_equal(X.astype(np.float32), want)
        np.testing.assert_array_equal(y, run.samples["label.is_faulty"].to_numpy().astype(int))


def test_a_missing_dataset_and_a_comma_list_of_patterns(dataset, tmp_path, capsys):
    code = main(
        ["export", str(tmp_path / "nope"), "--format", "timeeval", "-o", str(tmp_path / "out")]
    )
    err = capsys.readouterr().err
    assert code == 2 and "no such dataset directory" in err and not (tmp_path / "out").exists()
    summary = export_dataset(
        dataset, tmp_path / "out", "tsb-ad", channels="meas.lc_*,sp.line_*", split="val"
    )
    assert summary.channels == [
        "meas.lc_unwind.tension_N",
        "meas.lc_rewind.tension_N",
        "sp.line_speed_m_s",
        "sp.line_acceleration_m_s2",
    ]
    assert summary.exported == list(summary.files) and len(summary.exported) == 1
