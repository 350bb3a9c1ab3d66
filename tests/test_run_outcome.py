"""How a run ended, told by the exit code of `r2rsim run` (batch users trust `$?`): the step
budget, solver failures, early endings the scenario expects or not, states not finite."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import yaml

import r2rsim
from r2rsim.cli import main

from conftest import write


def _scenario(tmp_path, repo, name, **changes):
    d = yaml.safe_load((repo / "scenarios" / name).read_text())
    d["line"] = str((repo / "scenarios" / d["line"]).resolve())
    d.update(changes)
    return write(tmp_path / name.replace("/", "_"), yaml.safe_dump(d))


def _runs(out):
    return pq.read_table(out / "runs.parquet").to_pylist()[0]


def test_step_budget_ends_a_run_as_a_solver_failure(tmp_path, repo, capsys):
    # the quickstart needs ~25 steps per simulated second on radau5: a budget of 2 per
    # second (120 steps over 60 s) ends it, with the samples up to there kept
    scen = _scenario(tmp_path, repo, "quickstart.yaml", solver={"max_steps_per_s": 2.0})
    out = tmp_path / "out"
    assert main(["run", str(scen), "-o", str(out), "-q"]) == 1
    cap = capsys.readouterr()
    assert "TERMINATED   solver_failure: step budget" in cap.out
    assert cap.err.startswith(f"error: {scen}: the run ended early: solver_failure: step budget")
    runs = _runs(out)
    assert runs["termination_reason"].startswith("solver_failure: step budget: ")
    assert not runs["ended_as_expected"] and 0.0 < runs["termination_t_s"] < 60.0
    # the samples up to the failure are kept, none after it, and no gap before it
    t = pq.read_table(next((out / "samples").glob("*/*.parquet")), columns=["t_s"])
    t = t["t_s"].to_numpy()
    assert len(t) == runs["n_samples"]
    assert runs["termination_t_s"] - 1 / 200 - 1e-9 < t[-1] <= runs["termination_t_s"]
    # the default budget (5e4 steps per simulated second) lets it run to the end
    assert (
        main(
            [
                "run",
                str(repo / "scenarios" / "quickstart.yaml"),
                "-o",
                str(tmp_path / "ok"),
                "-q",
                "--duration",
                "3",
            ]
        )
        == 0
    )
    runs = _runs(tmp_path / "ok")
    assert runs["ended_as_expected"] and runs["nonfinite_from_t_s"] is None


def test_an_expected_web_break_exits_0_and_an_unexpected_one_1(tmp_path, repo, capsys):
    expected = repo / "scenarios" / "thesis_dancer_failure.yaml"
    assert yaml.safe_load(expected.read_text())["expect"] == {"termination": "web_break"}
    assert main(["run", str(expected), "-o", str(tmp_path / "a"), "-q"]) == 0
    cap = capsys.readouterr()
    assert "TERMINATED   web_break" in cap.out and "(expected)" in cap.out and cap.err == ""
    assert _runs(tmp_path / "a")["ended_as_expected"]
    # the same scenario without its expect: key
    d = yaml.safe_load(expected.read_text())
    del d["expect"]
    d["line"] = str((repo / "scenarios" / d["line"]).resolve())
    bare = write(tmp_path / "bare.yaml", yaml.safe_dump(d))
    assert main(["run", str(bare), "-o", str(tmp_path / "b"), "-q"]) == 1
    cap = capsys.readouterr()
    assert "not expected by the scenario" in cap.out
    assert cap.err.count("\n") == 1 and "web_break at t = 70.96" in cap.err
    runs = _runs(tmp_path / "b")
    assert runs["terminated"] and not runs["ended_as_expected"]
    # the data is the same either way: only the verdict differs
    a = pq.read_table(next((tmp_path / "a" / "samples").glob("*/*.parquet")))
    b = pq.read_table(next((tmp_path / "b" / "samples").glob("*/*.parquet")))
    assert a.num_rows == b.num_rows == 7097  # docs/dataset.md §7


def test_a_solver_failure_is_never_expected(tmp_path, repo):
    d = yaml.safe_load((repo / "scenarios" / "quickstart.yaml").read_text())
    d["expect"] = {"termination": "solver_failure"}
    d["line"] = str(repo / "lines" / "pet_film_line.yaml")
    bad = write(tmp_path / "bad.yaml", yaml.safe_dump(d))
    assert main(["run", str(bad), "-o", str(tmp_path / "o"), "-q"]) == 2
    assert not (tmp_path / "o").exists()


def test_states_that_are_not_finite_fail_the_run(tmp_path, repo, monkeypatch, capsys):
    import r2rsim.run as run_module

    def poisoned(cl, y):
        y = y.copy()
        y[cl.index("span2.strain")] = np.nan
        return y

    monkeypatch.setattr(run_module, "steady_state", poisoned)
    out = tmp_path / "out"
    assert (
        main(
            [
                "run",
                str(repo / "scenarios" / "quickstart.yaml"),
                "-o",
                str(out),
                "-q",
                "--duration",
                "1",
            ]
        )
        == 1
    )
    cap = capsys.readouterr()
    assert "FAILED       states not finite (nan or inf) from t = 0.0000 s" in cap.out
    runs = _runs(out)
    assert runs["nonfinite_from_t_s"] == 0.0 and not runs["ended_as_expected"]
    assert runs["termination_reason"].startswith("solver_failure: ")
    summary = r2rsim.run_scenario(
        repo / "scenarios" / "quickstart.yaml", output=tmp_path / "api", duration=1.0
    )
    assert not summary.ok and summary.nonfinite_t == 0.0


def test_wall_clock_budget(tmp_path, repo):
    scen = _scenario(tmp_path, repo, "quickstart.yaml", solver={"max_wall_s": 1e-6})
    assert main(["run", str(scen), "-o", str(tmp_path / "o"), "-q"]) == 1
    runs = _runs(tmp_path / "o")
    assert runs["termination_reason"].startswith("solver_failure: wall-clock budget: ")
    assert runs["termination_t_s"] < 60.0


def test_an_arithmetic_error_in_the_compiled_integrator_is_a_solver_failure(
    tmp_path, repo, monkeypatch, capsys
):
    """numba raises ZeroDivisionError as Python does; inputs whose values overflowed the
    arithmetic (a friction of 1e300 N m, before the plausibility bounds) ended in a traceback.
    Now the run ends as a solver failure, its dataset written and marked."""
    from r2rsim.solve import radau

    def broken(*args):
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(radau, "integrate", broken)
    out = tmp_path / "out"
    assert (
        main(
            [
                "run",
                str(repo / "scenarios" / "quickstart.yaml"),
                "-o",
                str(out),
                "-q",
                "--duration",
                "1",
            ]
        )
        == 1
    )
    cap = capsys.readouterr()
    assert "Traceback" not in cap.err
    assert "solver_failure: ZeroDivisionError in the compiled integrator" in cap.out
    runs = _runs(out)
    assert runs["termination_reason"].startswith("solver_failure: ZeroDivisionError")
    assert runs["termination_t_s"] == 0.0 and runs["n_samples"] == 1
    assert main(["validate", str(out)]) == 0


def test_a_run_shorter_than_one_sample_period_records_its_start(tmp_path, repo, capsys):
    """A run that ends before its first sample (here: shorter than the solver's first
    chunk; also a web break within femtoseconds) records the state at t = 0 instead of
    failing its own dataset check."""
    scen = _scenario(tmp_path, repo, "quickstart.yaml", duration="1e-12 s")
    out = tmp_path / "out"
    assert main(["run", str(scen), "-o", str(out), "-q"]) == 0
    t = pq.read_table(next((out / "samples").glob("*/*.parquet")), columns=["t_s"])
    assert t["t_s"].to_pylist() == [0.0]
    assert _runs(out)["n_samples"] == 1
    assert main(["validate", str(out)]) == 0
