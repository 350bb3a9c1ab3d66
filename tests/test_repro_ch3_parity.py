"""The machinery of benchmarks/reproduction/ch3_parity.py, cheaply: its sweep subsets, its
assertion table and its argument handling (CI runs the --quick study itself)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pandas as pd
import pytest

from conftest import REPO

PATH = REPO / "benchmarks" / "reproduction" / "ch3_parity.py"


@pytest.fixture(scope="module")
def study():
    spec = importlib.util.spec_from_file_location("ch3_parity", PATH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_sweep_subsets_are_valid_sweeps(study, tmp_path):
    from r2rsim.sweep import plan_sweep

    plan = study.Plan(quick=True)
    cases = {f"{c} OC1" for c in plan.cases}
    path = study._subset_sweep(
        study.SET / "faults.yaml",
        tmp_path / "f.yaml",
        lambda v: v["case"] in cases,
        [101, 102],
        60.0,
        30.0,
    )
    # r2rsim makes and validates every run of the subset
    runs = plan_sweep(path).runs
    assert len(runs) == len(plan.cases) * 2
    # the shorter onset reaches every run, also through the axis that sets the whole entry
    assert {str(f["onset"]) for r in runs for f in r.scenario_data["faults"]} == {"30.0 s"}
    text = path.read_text(encoding="utf-8")
    assert "onset: 30.0 s" in text and "duration: 60.0 s" in text
    h = study._subset_sweep(
        study.SET / "healthy.yaml",
        tmp_path / "h.yaml",
        lambda v: v["mode"] in ("OC1", "OC2"),
        [1, 16],
        60.0,
    )
    assert len(plan_sweep(h).runs) == 4


def _result(**over):
    far = pd.DataFrame(
        {
            "OC1": {"model": 0.001, "literal": 0.01, "model, per-second time base": 0.001},
            "OC2": {"model": 0.02, "literal": 0.95, "model, per-second time base": 0.15},
        }
    )
    sig = pd.DataFrame(
        {
            "r1": [-4, -1, 1, 4, 4, 1, -1, -4],
            "r2": [0, 0, 0, 0, -4, -1, 1, 4],
            "r3": [-5, -2, 2, 5, 0, 0, 0, 0],
        },
        index=study_cases(),
        dtype=float,
    )
    iso = pd.DataFrame({"hit@1 (alarmed samples)": [0.95] * 8}, index=study_cases())
    res = {"far": far, "signature": sig, "isolation": iso, "sens_spread": {"OC1": 1.0, "OC2": 2.5}}
    res.update(over)
    return res


def study_cases():
    return [
        "A offset -15 %",
        "A offset -5 %",
        "A offset +5 %",
        "A offset +15 %",
        "B gain -15 % record-only",
        "B gain -5 % record-only",
        "B gain +5 % record-only",
        "B gain +15 % record-only",
    ]


def test_assertions_pass_and_fail_on_the_numbers(study):
    ok = study.check_all(_result())
    # every check passes on these numbers, the B signatures too: those are the documented
    # non-reproductions (EXPECTED_FAILURES), so they are XPASS, which fails the study
    results = [r["result"] for r in ok.rows]
    assert len(ok.rows) == 10 and results.count("PASS") == 8 and results.count("XPASS") == 2
    assert not ok.ok
    bad = _result(sens_spread={"OC1": 1.0, "OC2": 1.9})
    bad["far"].loc["literal", "OC2"] = 0.4
    bad["signature"].loc["B gain +15 % record-only", "r2"] = 2.7
    c = study.check_all(bad)
    failed = [r["assertion"] for r in c.rows if r["result"] == "FAIL"]
    assert len(failed) == 2 and not c.ok
    assert any("literal" in f for f in failed) and any("sensitivity" in f for f in failed)
    assert [r["result"] for r in c.rows if "B gain +15 %" in r["assertion"]] == [
        "XFAIL (documented)"
    ]
    # the OC1 design's model residual at OC2: bounded like OC1 (0.02), however low the OC1
    # FAR (0.001 here: 20 × it passes)
    bad = _result()
    bad["far"].loc["model", "OC2"] = 0.0201
    failed = [r["assertion"] for r in study.check_all(bad).rows if r["result"] == "FAIL"]
    assert failed == ["FAR OC2, model mode designed on OC1"]
    md = study.md(c.table(), index=False)
    assert md.count("\n") == len(c.rows) + 1 and "\\|z\\|" in md


def test_arguments(study, tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        study.main(["-o", str(tmp_path / "o"), "--data", str(tmp_path), str(tmp_path)])
    assert e.value.code == 2 and "not an r2rsim sweep dataset" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        study.main(["--quick"])
    assert e.value.code == 2
    assert study.ASSERTION_FAILED not in (0, 1, 2)
    assert np.isfinite(study.THESIS_TABLE_3_2).all()
