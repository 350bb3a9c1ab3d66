"""The default number of sweep worker processes, by the planned work (issue: on 2 cores two
workers were slower than one for short sweeps; docs/sweeps.md §6 has the measurements).
No timing here: the decision function and the durations it reads."""

from __future__ import annotations

import textwrap

import pytest

from r2rsim.sweep import SIM_S_PER_WORKER, choose_workers, plan_sweep, planned_seconds, run_sweep

from conftest import REPO

QUICK = REPO / "scenarios" / "quickstart.yaml"


@pytest.mark.parametrize(
    "planned_s,n_runs,cores,want",
    [
        (0.0, 0, 2, 1),  # nothing to do: still a valid count
        (24.0, 12, 2, 1),  # the quick-start sweep at 2 s per run
        (120.0, 12, 2, 1),  # ... at 10 s (the shipped sweep)
        (SIM_S_PER_WORKER, 12, 2, 1),  # exactly one worker's share
        (SIM_S_PER_WORKER + 1, 12, 2, 2),  # just over: a second worker
        (720.0, 12, 2, 1),  # ... at 60 s: 2 workers were slower
        (7200.0, 40, 2, 2),  # 40 runs of 180 s: both cores
        (7200.0, 40, 1, 1),  # never more than the cores
        (1e6, 3, 64, 3),  # never more than the runs
        (1e6, 200, 64, 64),
        (5 * SIM_S_PER_WORKER, 200, 64, 5),  # in proportion to the work
    ],
)
def test_choose_workers(planned_s, n_runs, cores, want):
    assert choose_workers(planned_s, n_runs, cores) == want


def test_choose_workers_defaults_to_this_process_cores(monkeypatch):
    import r2rsim.sweep as sweep

    monkeypatch.setattr(sweep, "default_workers", lambda: 3)
    assert choose_workers(1e9, 100) == 3


def _sweep(tmp_path, body):
    path = tmp_path / "sweep.yaml"
    path.write_text(f"name: t\nscenario: {QUICK}\n" + textwrap.dedent(body), encoding="utf-8")
    return path


def test_planned_seconds_reads_each_runs_duration(tmp_path):
    # a swept duration (with units, and a bare number of seconds) times the seeds
    plan = plan_sweep(
        _sweep(
            tmp_path,
            """\
        axes:
          - {name: d, path: duration, values: [2 s, 500 ms, 3]}
        seeds: 2
        """,
        )
    )
    assert len(plan.runs) == 6
    assert planned_seconds(plan.runs) == pytest.approx(2 * (2 + 0.5 + 3))
    # the shipped quick-start sweep: 12 runs of 10 s
    shipped = plan_sweep(REPO / "sweeps" / "quickstart.yaml")
    assert planned_seconds(shipped.runs) == pytest.approx(120.0)
    assert choose_workers(120.0, 12, 2) == 1


def test_default_and_override_on_a_sweep(tmp_path):
    sw = _sweep(
        tmp_path,
        """\
        set: {duration: 0.5 s}
        axes:
          - {name: speed, path: 'programme[0].line_speed', values: [1 m/s, 2 m/s]}
        """,
    )
    s = run_sweep(sw, output=tmp_path / "auto")
    assert s.ok and s.executor == "1 local worker process (the default for 1 s of runs)"
    s = run_sweep(sw, output=tmp_path / "two", workers=2)
    assert s.ok and s.executor == "2 local worker processes"
