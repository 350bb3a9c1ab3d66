"""The calibrated thesis set (issue 16 item 4; scenarios/thesis_realistic/, docs/dataset.md
§9): its files are valid, its noise sits where the calibration put it, the test bed changes
rolls often enough, and the regimes switch inside a run."""

from __future__ import annotations

import importlib.util

import numpy as np
import pyarrow.parquet as pq
import pytest

from r2rsim import run_scenario
from r2rsim.sweep import plan_sweep

from conftest import REPO

SET = REPO / "scenarios" / "thesis_realistic"


def _calibration():
    spec = importlib.util.spec_from_file_location(
        "calibrate_thesis_realistic", REPO / "benchmarks" / "calibrate_thesis_realistic.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(
    "sweep, n_runs",
    [
        ("healthy.yaml", 80),
        ("faults.yaml", 220),
        ("switching.yaml", 10),
        ("testbed_cycles.yaml", 6),
        ("faults_p2.yaml", 110),
        ("testbed_dancer_failure_sweep.yaml", 6),
    ],
)
def test_the_sweeps_plan(sweep, n_runs):
    plan = plan_sweep(SET / sweep)
    assert len(plan.runs) == n_runs


#: every sweep file shipped (a sweep names its base scenario with a top-level scenario: key)
SWEEPS = sorted(
    p
    for p in [*SET.glob("*.yaml"), *(REPO / "sweeps").glob("*.yaml")]
    if any(line.startswith("scenario:") for line in p.read_text(encoding="utf-8").splitlines())
)


@pytest.mark.parametrize("sweep", SWEEPS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_every_shipped_sweep_has_fault_free_runs(sweep):
    # r2rsim diagnose --data DIR splits a sweep's own fault-free runs into train and val; a
    # fault sweep's fault-free runs share the fault runs' seeds (their plants)
    runs = plan_sweep(sweep).runs
    healthy = {r.seed for r in runs if not r.scenario_data.get("faults")}
    faulty = {r.seed for r in runs if r.scenario_data.get("faults")}
    assert len([r for r in runs if not r.scenario_data.get("faults")]) >= 2
    if sweep.name in ("faults.yaml", "faults_p2.yaml", "testbed_dancer_failure_sweep.yaml"):
        assert healthy == faulty


def test_local_residual_noise_is_calibrated_reduced():
    """CI's reduced calibration: 3 + 3 seeds of 120 s in OC1. The full study (10 seeds of
    300 s per condition, benchmarks/calibrate_thesis_realistic.py) measured σ = 4.46 N, i.e.
    P05 = 1.46σ and P20 = 5.83σ; with six short runs the estimate is looser, so the band is
    wider than the target's (1-1.5σ), but a sensor or disturbance change that halves or
    doubles σ fails it."""
    cal = _calibration()
    m = cal.calibrate(
        fit_seeds=[2001, 2002, 2003],
        test_seeds=[2004, 2005, 2006],
        duration="120 s",
        workers=0,
        modes=["OC1"],
    )["OC1"]
    assert 0.9 < m["P05_sigmas"] < 2.5, m
    assert 3.6 < m["P20_sigmas"] < 10.0, m


@pytest.mark.slow
def test_local_residual_noise_is_calibrated_full():
    """The calibration target on fresh seeds (not those of the calibration): a 5 % fault
    1-1.5σ (to 1.8σ in OC2, the noisier regime only by little) and a 20 % fault 4-7σ."""
    cal = _calibration()
    for mode, m in cal.calibrate(
        fit_seeds=range(3001, 3006), test_seeds=range(3006, 3011), workers=2
    ).items():
        assert 1.0 < m["P05_sigmas"] < 1.8, (mode, m)
        assert 4.0 < m["P20_sigmas"] < 7.2, (mode, m)


def test_testbed_changes_rolls_that_differ(tmp_path):
    out = run_scenario(SET / "testbed.yaml", tmp_path / "tb").output
    events = pq.read_table(out / "events.parquet").to_pandas()
    swaps = events[(events.kind == "splice") & (events.state == "swap")]
    assert len(swaps) >= 7
    v = pq.read_table(out / "variability.parquet").to_pandas()
    strain = v[v.parameter == "wound_in_strain"].set_index("roll").value
    assert len(strain) == len(swaps) + 1 and strain.nunique() == len(strain)
    s = pq.read_table(
        next((out / "samples").glob("*/part-0.parquet")),
        columns=["meas.speed_unwind.speed_rad_s", "meas.speed_drive4.speed_rad_s"],
    ).to_pandas()
    # the inputs of the Ch. 2 model are measured: the driven roller at 0.5 m/s / 0.1 m
    assert abs(np.nanmedian(s["meas.speed_drive4.speed_rad_s"]) - 5.0) < 0.05
    assert np.nanmax(s["meas.speed_unwind.speed_rad_s"]) > 5.0


def test_testbed_startup_gives_censored_load_cell_readings(tmp_path):
    """The start-up from a slack-threaded web (issue 16 item 4): the stage-2 load cell,
    ranged at 0 N, reads exactly 0 N with its clipped flag while the slack is taken up, and
    never once production runs."""
    from r2rsim.dataset.validate import validate_dataset

    out = run_scenario(SET / "testbed_startup.yaml", tmp_path / "su").output
    assert validate_dataset(out) == []
    s = pq.read_table(
        next((out / "samples").glob("*/part-0.parquet")),
        columns=[
            "t_s",
            "meas.lc_stage2.tension_N",
            "flag.lc_stage2.clipped",
            "state.span3.tension_N",
            "label.mode",
        ],
    ).to_pandas()
    clipped = s["flag.lc_stage2.clipped"].to_numpy()
    assert clipped.sum() >= 20  # measured 46-50 over seeds 1-4
    assert np.all(s["meas.lc_stage2.tension_N"][clipped] == 0.0)
    assert np.all(s["meas.lc_stage2.tension_N"][~clipped].dropna() > 0.0)
    # the censored samples are the start-up's, while the web was slack
    assert s.t_s[clipped].max() < 5.0
    assert s["state.span3.tension_N"].iloc[0] == 0.0
    production = (s["label.mode"] == "production").to_numpy()
    assert production.any() and not clipped[production].any()
