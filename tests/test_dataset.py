"""The dataset contract (docs/dataset.md): files, columns with units, provenance, streaming,
determinism, early termination, readability without r2rsim."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import numpy as np
import pyarrow.dataset as pads
import pyarrow.parquet as pq
import pytest

from r2rsim.cli import main
from r2rsim.dataset.writer import sha256_file


@pytest.fixture(scope="module")
def quick_dataset(tmp_path_factory, repo):
    out = tmp_path_factory.mktemp("ds") / "qs"
    assert (
        main(
            [
                "run",
                str(repo / "scenarios" / "quickstart.yaml"),
                "-o",
                str(out),
                "--duration",
                "4",
                "-q",
            ]
        )
        == 0
    )
    return out


def test_dataset_layout_and_manifest(quick_dataset):
    ds = quick_dataset
    for f in (
        "runs.parquet",
        "channels.parquet",
        "faults.parquet",
        "events.parquet",
        "manifest.json",
    ):
        assert (ds / f).is_file(), f
    parts = list((ds / "samples").glob("run_id=*/part-0.parquet"))
    assert len(parts) == 1 and parts[0].parent.name == "run_id=quickstart__s1"
    man = json.loads((ds / "manifest.json").read_text())
    assert man["schema_version"] == "0.1" and man["root_seed"] == 1
    for rel, info in man["files"].items():
        assert sha256_file(ds / rel) == info["sha256"], rel
    assert not list(ds.parent.glob(".qs.tmp-*"))  # the temporary directory is gone


def test_samples_columns_units_and_labels(quick_dataset):
    t = pq.read_table(quick_dataset / "samples" / "run_id=quickstart__s1" / "part-0.parquet")
    cols = set(t.column_names)
    assert {
        "k",
        "t_s",
        "meas.lc_unwind.tension_N",
        "true.lc_unwind.tension_N",
        "state.span3.tension_N",
        "state.unwind.radius_m",
        "act.unwind.torque_N_m",
        "cmd.unwind.torque_N_m",
        "sp.line_speed_m_s",
        "label.is_faulty",
        "label.phase",
        "label.score_mask",
    } <= cols
    assert t.num_rows == 4 * 200 + 1
    k = t["k"].to_numpy()
    np.testing.assert_array_equal(k, np.arange(t.num_rows))
    np.testing.assert_allclose(t["t_s"].to_numpy(), k / 200.0)
    assert t.schema.field("meas.lc_unwind.tension_N").type == "float"  # float32
    assert t.schema.metadata[b"r2rsim.root_seed"] == b"1"
    phase = t["label.phase"].to_pylist()
    assert phase[0] == "warmup" and phase[-1] == "normal"  # warm-up is 2 s
    ch = pq.read_table(quick_dataset / "channels.parquet").to_pandas().set_index("channel")
    assert set(t.column_names) | {"run_id"} == set(ch.index)  # every column is described
    assert ch.loc["meas.lc_unwind.tension_N", "kind"] == "measured"
    assert ch.loc["true.lc_unwind.tension_N", "kind"] == "true"
    assert ch.loc["state.span1.tension_N", "unit"] == "N"
    # measured = true + noise (0.5 N std) on the load cell
    d = t["meas.lc_unwind.tension_N"].to_numpy() - t["true.lc_unwind.tension_N"].to_numpy()
    assert 0.3 < d.std() < 0.8


def test_runs_and_faults_tables(quick_dataset):
    runs = pq.read_table(quick_dataset / "runs.parquet").to_pylist()[0]
    assert runs["run_id"] == "quickstart__s1" and runs["seed"] == 1
    assert runs["terminated"] is False and runs["termination_reason"] is None
    assert runs["n_samples"] == 801 and runs["has_fault"] is False
    assert set(runs["seed_streams"]) == {"process", "measurement", "fault_sampling"}
    faults = pq.read_table(quick_dataset / "faults.parquet")
    assert faults.num_rows == 0 and "onset_t_s" in faults.column_names


def test_same_seed_same_data_and_noise_seed_leaves_truth(tmp_path, repo):
    scen = str(repo / "scenarios" / "quickstart.yaml")
    outs = []
    for name, seed in (("a", 5), ("b", 5), ("c", 6)):
        out = tmp_path / name
        assert (
            main(["run", scen, "-o", str(out), "--duration", "3", "--seed", str(seed), "-q"]) == 0
        )
        outs.append(pq.read_table(next((out / "samples").glob("*/part-0.parquet"))))
    a, b, c = outs
    assert a.equals(b)
    assert not np.array_equal(
        a["meas.lc_unwind.tension_N"].to_numpy(), c["meas.lc_unwind.tension_N"].to_numpy()
    )
    for col in a.column_names:
        if not col.startswith("meas."):
            assert a[col].equals(c[col]), col


def test_rerun_replaces_dataset_with_overwrite(tmp_path, repo, capsys):
    scen = str(repo / "scenarios" / "quickstart.yaml")
    out = tmp_path / "x"
    assert main(["run", scen, "-o", str(out), "--duration", "1", "-q"]) == 0
    # no-clobber by default: the first dataset stays
    assert main(["run", scen, "-o", str(out), "--duration", "2", "-q"]) == 2
    assert "pass --overwrite to replace it" in capsys.readouterr().err
    assert pq.read_table(out / "runs.parquet")["n_samples"][0].as_py() == 201
    assert main(["run", scen, "-o", str(out), "--duration", "2", "-q", "--overwrite"]) == 0
    assert pq.read_table(out / "runs.parquet")["n_samples"][0].as_py() == 401
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x"]  # no .x.old-*/.x.tmp-* left


def test_refuses_to_overwrite_a_foreign_directory(tmp_path, repo, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "thesis.tex").write_text("precious")
    assert (
        main(
            [
                "run",
                str(repo / "scenarios" / "quickstart.yaml"),
                "-o",
                str(out),
                "--duration",
                "1",
                "-q",
            ]
        )
        == 2
    )
    assert (out / "thesis.tex").read_text() == "precious"
    assert "is not an r2rsim dataset" in capsys.readouterr().err


def test_web_break_ends_run_and_is_recorded(tmp_path, repo):
    line = (repo / "lines" / "single_span.yaml").read_text().replace("draw: 0.001", "draw: 0.01")
    (tmp_path / "line.yaml").write_text(line)
    (tmp_path / "s.yaml").write_text(
        textwrap.dedent("""\
        name: breaks
        line: line.yaml
        duration: 5 s
        record_rate: 1 kHz
        initial: {state: nominal, tension: 0 N}
        programme: [{at: 0, line_speed: 1 m/s}]
        expect: {termination: web_break}
        """)
    )
    out = tmp_path / "ds"
    assert main(["run", str(tmp_path / "s.yaml"), "-o", str(out), "-q"]) == 0
    runs = pq.read_table(out / "runs.parquet").to_pylist()[0]
    assert runs["terminated"] and runs["termination_reason"] == "web_break"
    t_b = 2.0 / 1.01 * np.log(0.01 / (1.01 / 1.005 - 1))  # exact span model, see V18
    assert runs["termination_t_s"] == pytest.approx(t_b, abs=1e-3)
    s = pq.read_table(next((out / "samples").glob("*/part-0.parquet")))
    assert s["t_s"].to_numpy()[-1] < t_b and runs["n_samples"] == s.num_rows
    ev = pq.read_table(out / "events.parquet").to_pylist()
    assert [e["kind"] for e in ev] == ["web_break"] and ev[0]["component"] == "span1"


READER = """
import sys
sys.modules["r2rsim"] = None  # reading must not need r2rsim
import duckdb, pandas as pd, pyarrow.dataset as ds
root = sys.argv[1]
df = pd.read_parquet(root + "/samples")
assert "run_id" in df.columns and len(df) == 801, df.shape
d = ds.dataset(root + "/samples", format="parquet", partitioning="hive")
t = d.to_table(columns=["t_s", "state.span1.tension_N"])
assert t.num_rows == 801
n = duckdb.sql(f"select count(*), avg(\\"state.span1.tension_N\\") from "
               f"read_parquet('{root}/samples/*/*.parquet', hive_partitioning=true)").fetchall()[0]
assert n[0] == 801 and 200 < n[1] < 320, n
runs = pd.read_parquet(root + "/runs.parquet")
ch = duckdb.sql(f"select count(*) from '{root}/channels.parquet'").fetchall()[0][0]
assert ch == len(df.columns), (ch, len(df.columns))
print("ok")
"""


def test_readable_without_r2rsim(quick_dataset, tmp_path):
    script = tmp_path / "read.py"
    script.write_text(READER)
    p = subprocess.run(
        [sys.executable, str(script), str(quick_dataset)],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert p.returncode == 0 and p.stdout.strip() == "ok", p.stderr


def test_pyarrow_dataset_reads_all_tables(quick_dataset):
    from r2rsim.dataset.writer import EVENTS_SCHEMA, FAULTS_SCHEMA

    tables = {
        name: pads.dataset(quick_dataset / f"{name}.parquet").to_table()
        for name in ("runs", "channels", "faults", "events")
    }
    runs = tables["runs"].to_pylist()
    assert len(runs) == 1 and runs[0]["run_id"] == "quickstart__s1"
    assert runs[0]["n_samples"] == 801 and not runs[0]["terminated"]
    samples = pq.read_schema(next((quick_dataset / "samples").glob("*/part-0.parquet")))
    assert tables["channels"].num_rows == len(samples.names) + 1  # + the run_id partition
    # the quickstart has no faults and no events in its first 4 s: empty, but typed
    for name, schema in (("faults", FAULTS_SCHEMA), ("events", EVENTS_SCHEMA)):
        assert tables[name].num_rows == 0
        assert tables[name].schema.names == schema.names


def test_progress_bar_on_a_terminal(tmp_path, repo, capsys, monkeypatch):
    # the bar appears only on a terminal; its total is the scenario's simulated duration
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert (
        main(
            [
                "run",
                str(repo / "scenarios" / "quickstart.yaml"),
                "-o",
                str(tmp_path / "p"),
                "--duration",
                "2",
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert "simulating: 2.0/2.0 s sim" in err, err[-300:]


def test_scenario_and_line_of_the_same_file_name_are_both_kept(tmp_path, repo):
    (tmp_path / "lines").mkdir()
    line = (repo / "lines" / "single_span.yaml").read_text()
    (tmp_path / "lines" / "a.yaml").write_text(line)
    scen = textwrap.dedent("""\
        name: same
        line: lines/a.yaml
        duration: 0.1 s
        record_rate: 100 Hz
        programme: [{at: 0, line_speed: 1 m/s}]
        """)
    (tmp_path / "a.yaml").write_text(scen)
    out = tmp_path / "ds"
    assert main(["run", str(tmp_path / "a.yaml"), "-o", str(out), "-q"]) == 0
    assert (out / "scenario" / "a.yaml").read_text() == scen
    assert (out / "scenario" / "line.a.yaml").read_text() == line
    assert json.loads((out / "manifest.json").read_text())["line"] == "line.a.yaml"
