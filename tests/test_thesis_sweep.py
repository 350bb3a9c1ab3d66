"""The thesis sensor-fault sweep makes exactly the runs of the 18 registration scenario files
it replaces (same line, programme, faults, onsets, profiles and magnitudes; only the seeds,
names and descriptions differ)."""

import pandas as pd
import pytest

from r2rsim.schema import load_scenario
from r2rsim.schema.loader import build_scenario
from r2rsim.sweep import plan_sweep
from r2rsim.units import parse_any

from conftest import REPO

CASES = [
    "oc1_nominal",
    "oc2_nominal",
    "sensor_a_offset_N15",
    "sensor_a_offset_N05",
    "sensor_a_offset_P05",
    "sensor_a_offset_P15",
    "sensor_b_gain_N15",
    "sensor_b_gain_N05",
    "sensor_b_gain_P05",
    "sensor_b_gain_P15",
    *(f"sensor_a_degradation_P{m}_{oc}" for oc in ("OC1", "OC2") for m in ("05", "10", "15", "20")),
]

pytestmark = pytest.mark.filterwarnings("ignore::r2rsim.errors.PlausibilityWarning")


@pytest.fixture(scope="module")
def plan():
    return plan_sweep("sweeps/thesis_sensor_faults.yaml")


def _comparable(scenario) -> dict:
    d = scenario.model_dump()
    for key in ("name", "description", "seed"):
        d.pop(key)
    for f in d["faults"]:
        f.pop("id")
        if isinstance(f["magnitude"], str):  # "6.5 N": its unit is fixed by the target
            f["magnitude"] = parse_any(f["magnitude"])[0]
    return d


def test_one_combination_per_file_and_five_seeds(plan):
    assert plan.n_combinations == len(CASES) == 18
    assert plan.seeds == [1, 2, 3, 4, 5]
    assert len(plan.runs) == 90
    assert len({r.run_id for r in plan.runs}) == 90


@pytest.mark.parametrize("k,case", list(enumerate(CASES)))
def test_case_equals_its_scenario_file(plan, k, case):
    spec = next(r for r in plan.runs if r.combination == k)
    swept, swept_line = build_scenario(spec.scenario_data, spec.line_data, "sweep", "line")
    single, single_line, _ = load_scenario(f"scenarios/thesis/{case}.yaml")
    assert _comparable(swept) == _comparable(single)
    assert swept_line.model_dump() == single_line.model_dump()
    healthy = case.endswith("nominal")
    assert (spec.columns["axis.type"] is None) == healthy
    assert spec.columns["axis.mode"] == ("OC2" if "OC2" in case or case == "oc2_nominal" else "OC1")


def _small_thesis_sweep(d, seeds="[5]", duration="22 s"):
    """The thesis sweep with a shorter duration and other seeds, written into ``d``."""
    text = (REPO / "sweeps" / "thesis_sensor_faults.yaml").read_text(encoding="utf-8")
    text = text.replace(
        "scenario: ../scenarios/thesis/oc1_nominal.yaml",
        f"scenario: {REPO / 'scenarios/thesis/oc1_nominal.yaml'}",
    )
    text = text.replace("set:\n", f"set:\n  duration: {duration}\n")
    text = text.replace("seeds: 5\nseed: 1\n", f"seeds: {seeds}\n")
    (d / "thesis.yaml").write_text(text, encoding="utf-8")
    return d / "thesis.yaml"


def test_sweep_run_has_the_data_of_its_scenario_file(tmp_path):
    """A run of the sweep and the run of the scenario file it replaces, at the same seed and
    duration, have the same samples bit for bit (only the fault's id differs)."""
    import numpy as np
    import pandas as pd

    from r2rsim.run import run_scenario
    from r2rsim.sweep import run_sweep

    sweep = _small_thesis_sweep(tmp_path)
    summary = run_sweep(sweep, output=tmp_path / "sweep", workers=0)
    assert summary.ok and summary.done == 18
    runs = pd.read_parquet(tmp_path / "sweep" / "runs.parquet")
    row = runs[(runs["axis.type"] == "sensor.offset") & (runs["axis.magnitude"] == 19.5)]
    assert len(row) == 1 and row["seed"].iloc[0] == 5
    rid = row["run_id"].iloc[0]
    swept = pd.read_parquet(tmp_path / "sweep" / "samples" / f"run_id={rid}")
    single = run_scenario(
        REPO / "scenarios/thesis/sensor_a_offset_P15.yaml",
        output=tmp_path / "single",
        seed=5,
        duration=22.0,
    )
    ref = pd.read_parquet(single.output / "samples").drop(columns="run_id")
    cols = [c for c in ref.columns if c.split(".")[0] in ("meas", "true", "state", "act")]
    assert len(cols) > 10 and list(swept.columns) == list(ref.columns)
    for c in cols + ["label.is_faulty", "label.phase"]:
        assert np.array_equal(swept[c].to_numpy(), ref[c].to_numpy()), c
    faulty = swept["label.is_faulty"].to_numpy()
    assert faulty.any() and (faulty == (swept["t_s"].to_numpy() >= 20.0 - 1e-9)).all()


def test_bench_study_names_a_sweep(tmp_path, capsys):
    """A bench study takes its runs from a sweep, selected by axis values and seeds."""
    from r2rsim.cli import main

    _small_thesis_sweep(tmp_path, seeds="[1, 2, 3, 4]", duration="30 s")
    spec = tmp_path / "spec.yaml"
    spec.write_text(
        "name: sweep_bench\n"
        "studies:\n"
        "  - name: reg\n"
        "    train: [{sweep: thesis.yaml, where: {type: null, mode: OC1, seed: [1, 2]}}]\n"
        "    val: [{sweep: thesis.yaml, where: {type: null, mode: OC1, seed: 3}}]\n"
        "    test:\n"
        "      - {sweep: thesis.yaml, where: {seed: 4, mode: OC1}}\n"
        "methods: [{method: residual}]\n"
        "evaluation: {n_boot: 20, persistence: 2}\n",
        encoding="utf-8",
    )
    assert (
        main(["bench", str(spec), "--workdir", str(tmp_path / "work"), "-o", str(tmp_path / "res")])
        == 0
    )
    out = capsys.readouterr().out
    # 2 healthy OC1 train runs, 1 val, and the 14 OC1 cases at seed 4 (healthy + 12 faults
    # at OC1: 4 offsets, 4 gains on B, 4 ramps on A; plus the healthy one)
    assert "study reg: 2 train, 1 val, 13 test runs" in out
    res = pd.read_csv(tmp_path / "res" / "results.csv")
    offsets = res[
        (res.metric == "dr") & res.fault.str.startswith("sensor.offset") & res.magnitude.notna()
    ]
    assert sorted(offsets.magnitude) == [-19.5, -6.5, 6.5, 19.5]
    assert offsets["value"].notna().all() and (offsets["value"] > 0.5).all()
