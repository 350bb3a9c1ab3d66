"""Selecting the runs of a sweep dataset by axis value: ``read_runs(where=)``, ``r2rsim
diagnose --where``, and the messages for selections that cannot be made."""

from __future__ import annotations

import pytest

from r2rsim.cli import main
from r2rsim.dataset.read import read_runs
from r2rsim.sweep import run_sweep

from conftest import REPO

pytestmark = pytest.mark.filterwarnings("ignore::r2rsim.errors.PlausibilityWarning")

SWEEP = f"""\
name: select
scenario: {REPO / "scenarios/thesis/oc1_nominal.yaml"}
set: {{duration: 24 s}}
combine: zip
axes:
  - {{name: fault_entry, path: faults.f,
      values: [null, {{id: f, onset: 20 s}}, {{id: f, onset: 20 s}}]}}
  - {{name: type, path: faults.f.type, values: [null, sensor.offset, sensor.offset]}}
  - {{name: sensor, path: faults.f.target, values: [null, sensor_A, sensor_A]}}
  - {{name: magnitude, path: faults.f.magnitude, values: [null, 6.5 N, 19.5 N]}}
seeds: [1, 2, 3, 4, 5, 6]
"""


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    d = tmp_path_factory.mktemp("select")
    # the base scenario has no fault 'f': the healthy case removes nothing, the others add it
    text = SWEEP.replace(
        "set: {duration: 24 s}",
        "set: {duration: 24 s, faults: [{id: f, type: sensor.offset, "
        "target: sensor_A, onset: 20 s, magnitude: 1 N}]}",
    )
    (d / "sweep.yaml").write_text(text, encoding="utf-8")
    summary = run_sweep(d / "sweep.yaml", output=d / "ds", workers=0)
    assert summary.ok and summary.done == 18
    return d / "ds"


def test_where_selects_by_axis_value_in_si_and_by_null(dataset):
    assert len(read_runs(dataset)) == 18
    big = read_runs(dataset, where={"magnitude": "19.5 N"})
    assert sorted(int(r.info["seed"]) for r in big) == [1, 2, 3, 4, 5, 6]
    assert all(float(r.faults["magnitude"].iloc[0]) == 19.5 for r in big)
    healthy = read_runs(dataset, where={"type": None, "seed": [1, 2]})
    assert len(healthy) == 2 and all(r.faults.empty for r in healthy)
    both = read_runs(dataset, where={"axis.magnitude": [6.5, 19.5], "seed": 3})
    assert sorted(float(r.info["axis.magnitude"]) for r in both) == [6.5, 19.5]


def test_where_unknown_column_names_the_axes(dataset):
    from r2rsim.errors import InputError

    with pytest.raises(
        InputError,
        match=r"no column 'size'.*axes: fault_entry, magnitude, "
        r"sensor, type",
    ):
        read_runs(dataset, where={"size": 1})


def test_diagnose_where_on_a_sweep(dataset, tmp_path, capsys):
    """The pool is the healthy runs and the 19.5 N offset: split by seed, every faulty run
    tests, and the 6.5 N runs are not read at all."""
    code = main(
        [
            "diagnose",
            "--method",
            "residual",
            "--data",
            str(dataset),
            "--where",
            "magnitude=null,19.5 N",
            "--n-boot",
            "0",
            "-o",
            str(tmp_path / "res"),
        ]
    )
    out = capsys.readouterr()
    assert code == 0, out.err
    import pandas as pd

    tested = set(pd.read_parquet(tmp_path / "res" / "predictions.parquet")["run_id"])
    mags = {r.run_id: r.info["axis.magnitude"] for r in read_runs(dataset)}
    faulty = {rid for rid in tested if mags[rid] == mags[rid]}  # not NaN
    assert {mags[rid] for rid in faulty} == {19.5} and len(faulty) == 6
    m = pd.read_csv(tmp_path / "res" / "metrics.csv")
    dr = m[(m.metric == "dr") & (m.fault == "sensor.offset:sensor_A")]["value"]
    assert len(dr) == 1 and dr.iloc[0] > 0.5  # a 15 % offset on the monitored load cell


@pytest.mark.parametrize(
    "arg,msg",
    [
        ("magnitude", "--where expects KEY=VALUE"),
        ("=3", "--where expects KEY=VALUE"),
        ("speed=1", "no column 'speed'"),
        ("magnitude=123", "no run of"),
    ],
)
def test_diagnose_bad_where(dataset, tmp_path, capsys, arg, msg):
    code = main(
        [
            "diagnose",
            "--method",
            "residual",
            "--data",
            str(dataset),
            "--where",
            arg,
            "-o",
            str(tmp_path / "res"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and msg in err and len(err.strip().splitlines()) == 1


def test_a_seed_split_of_few_runs_serves_train_first_and_says_why_it_cannot(
    dataset, tmp_path, capsys
):
    # two fault-free runs (seeds 4 and 5): one trains, one calibrates (docs/diagnostics.md §4)
    code = main(
        [
            "diagnose",
            "--method",
            "residual",
            "--data",
            str(dataset),
            "--where",
            "seed=4,5",
            "--where",
            "magnitude=null,19.5 N",
            "--n-boot",
            "0",
            "-o",
            str(tmp_path / "two"),
        ]
    )
    out = capsys.readouterr()
    assert code == 0, out.err
    assert "split 'seed': 1 train, 1 val, 2 test (2 faulty)" in out.out
    # only faulty runs: nothing to learn from
    code = main(
        [
            "diagnose",
            "--method",
            "residual",
            "--data",
            str(dataset),
            "--where",
            "magnitude=19.5 N",
            "-o",
            str(tmp_path / "res"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and "all 6 runs have faults" in err, err
    assert "--train/--val/--test" in err and not (tmp_path / "res").exists()


def test_a_selection_on_a_sweep_without_axes_is_not_called_a_non_sweep(tmp_path):
    from r2rsim.dataset.read import select_rows
    from r2rsim.errors import InputError

    with pytest.raises(InputError, match=r"\(axes: none\); a selection applies to every"):
        select_rows([{"run_id": "a", "sweep": "seeds_only", "seed": 1}], {"size": 1}, tmp_path)
    with pytest.raises(InputError, match=r"\(axes: none, not a sweep\)"):
        select_rows([{"run_id": "a", "seed": 1}], {"size": 1}, tmp_path)


def test_json_schema_of_the_sweep_file(capsys):
    """`r2rsim schema sweep` prints the sweep file's JSON Schema, whose keys are the ones
    the shipped sweeps use."""
    import json

    import yaml

    assert main(["schema", "sweep"]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert schema["additionalProperties"] is False
    keys = set(schema["properties"])
    assert {"name", "scenario", "set", "axes", "combine", "n", "seed", "seeds"} <= keys
    assert set(schema["$defs"]["Axis"]["properties"]) == {
        "path",
        "name",
        "values",
        "range",
        "uniform",
        "loguniform",
    }
    for path in sorted((REPO / "sweeps").glob("*.yaml")):
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
        assert set(data) <= keys, path
        for axis in data.get("axes", []):
            assert set(axis) <= set(schema["$defs"]["Axis"]["properties"]), path


def test_workers_that_cannot_start_fail_fast(tmp_path):
    """A script that calls run_sweep without the ``__main__`` guard: every spawned worker
    re-runs the script and dies. The sweep stops once a run alone has lost its worker and a
    bare worker does not start either, with a message that says what to do, instead of
    retrying every run."""
    import subprocess
    import sys
    import time

    (tmp_path / "s.yaml").write_text(
        f"name: nm\nscenario: {REPO / 'scenarios/quickstart.yaml'}\n"
        "set: {duration: 1 s}\nseeds: 40\n",
        encoding="utf-8",
    )
    script = tmp_path / "script.py"
    script.write_text(
        "from r2rsim.sweep import run_sweep\n"
        f"run_sweep({str(tmp_path / 's.yaml')!r}, "
        f"output={str(tmp_path / 'out')!r}, workers=2)\n",
        encoding="utf-8",
    )
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path
    )
    assert proc.returncode != 0
    assert "the worker processes die as they start" in proc.stderr
    assert 'if __name__ == "__main__":' in proc.stderr
    assert time.perf_counter() - t0 < 60
