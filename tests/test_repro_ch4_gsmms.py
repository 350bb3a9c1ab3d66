"""The Ch. 4 reproduction script's machinery, cheaply (its --quick run is in CI): the sweeps
it would simulate are valid, its tables, and its argument handling."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pandas as pd
import pytest
import yaml

from r2rsim.sweep import plan_sweep

from conftest import REPO

SCRIPT = REPO / "benchmarks" / "reproduction" / "ch4_gsmms.py"


@pytest.fixture(scope="module")
def ch4():
    spec = importlib.util.spec_from_file_location("ch4_gsmms", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look their module up there
    spec.loader.exec_module(mod)
    return mod


def test_quick_sweeps_are_valid_and_hold_what_the_study_reads(ch4, tmp_path):
    specs = ch4._yaml_sweeps(ch4.QUICK, 100.0)
    plans = {}
    for name, spec in specs.items():
        path = tmp_path / f"{name}.yaml"
        path.write_text(yaml.safe_dump(spec, sort_keys=False))
        plans[name] = plan_sweep(path)
    seeds = ch4.QUICK.train + ch4.QUICK.calibrate + ch4.QUICK.test
    assert len(plans["healthy"].runs) == len(ch4.CONDITIONS) * len(seeds)
    assert len(plans["faults"].runs) == 2 * len(ch4.MAGNITUDES) * len(ch4.QUICK.fault_seeds)
    # the case names parse as read_data expects
    cases = specs["faults"]["axes"][0]["values"]
    assert cases[3] == "A degradation P20 over 20 s OC1"


def test_md_table(ch4):
    df = pd.DataFrame({"x": [0.12345, np.nan], "n": [1, 2]}, index=pd.Index(["a", "b"], name="row"))
    assert ch4.md_table(df).splitlines() == [  # the default format: 4 decimals
        "| row | x | n |",
        "|---|---|---|",
        "| a | 0.1235 | 1 |",
        "| b | – | 2 |",
    ]


def test_four_cell_and_check_results(ch4):
    row = {"far_OC1": 0.1, "far_OC2": 0.0, "dr_OC1": 0.5, "dr_OC2": 1.0}
    assert ch4.four_cell(row) == pytest.approx((0.9 + 1.0 + 0.5 + 1.0) / 4)
    assert ch4.Check("a", "t", "m", False).result == "FAIL"
    assert ch4.Check("a", "t", "m", False, asserted=False).result == "(fail)"


def test_data_directory_without_the_datasets_is_refused(ch4, tmp_path):
    with pytest.raises(SystemExit) as e:
        ch4.main(["-o", str(tmp_path / "out"), "--data", str(tmp_path)])
    assert e.value.code == 2


def test_configurations_are_pinned_and_fault_groups_parse(ch4):
    # the study's configurations do not follow the plug-in's defaults
    assert ch4.STUDY["fault_channels"] == ch4.A and ch4.LITERAL["fault_channels"] is None
    assert ch4.STUDY["model_features"] == ch4.LITERAL["model_features"] == [ch4.A, ch4.B]

    class R:
        def __init__(self, case):
            self.info = {"axis.case": case}

    assert [
        ch4._group(R(c))
        for c in (
            "A offset -15 % OC1",
            "A degradation P05 over 120 s OC2",
            "A drift 0.02 N/s OC1",
            "B gain -5 % in loop OC2",
            "B gain +15 % record-only OC1",
            "fault-free OC2",
            "something else",
        )
    ] == [
        "A offset",
        "A degradation",
        "A drift",
        "B gain in loop",
        "B gain record-only",
        "fault-free",
        None,
    ]
