"""Every frame a plug-in gets carries its run's line (r2rsim.diagnostics.line): rebuilt from
the dataset's copy of the line file, with a sweep's set: and the run's line axes applied."""

from __future__ import annotations

import json
import textwrap

import pandas as pd
import pytest

from r2rsim import run_scenario
from r2rsim.diagnostics import Diagnostic
from r2rsim.diagnostics.line import LINE_ATTR, frame_line, run_line_data
from r2rsim.evaluate.harness import evaluate, read_datasets
from r2rsim.schema.loader import read_yaml
from r2rsim.sweep import run_sweep

from conftest import REPO

SCENARIO = f"""\
name: tiny
line: {REPO / "lines" / "single_span.yaml"}
duration: 2 s
record_rate: 50 Hz
warmup: 0.2 s
programme:
  - {{at: 0 s, line_speed: 1 m/s, mode: M1}}
"""


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    d = tmp_path_factory.mktemp("line")
    (d / "tiny.yaml").write_text(SCENARIO, encoding="utf-8")
    (d / "sweep.yaml").write_text(
        textwrap.dedent("""\
        name: tiny_sweep
        scenario: tiny.yaml
        set:
          line.web.width: 0.5 m
        axes:
          - {name: thickness, path: line.web.thickness, values: [100 um, 200 um]}
        seeds: [1, 2]
        """),
        encoding="utf-8",
    )
    run_sweep(d / "sweep.yaml", output=d / "data", workers=0)
    run_scenario(d / "tiny.yaml", output=d / "single")
    return d


class LineSpy(Diagnostic):
    """Records E·A of the line of every frame it is given."""

    name = "line-spy"
    seen: list = []

    def __init__(self):
        pass

    def fit(self, runs):
        frames = self._frames(runs)
        LineSpy.seen = [self._ea(f) for f in frames]
        self.threshold_ = 1.0
        return self

    def score(self, run):
        f = self._frames(run)[0]
        LineSpy.seen.append(self._ea(f))
        return pd.DataFrame({"statistic": 0.0}, index=f.index)

    @staticmethod
    def _ea(frame):
        line = frame_line(frame)
        return None if line is None else line.web.modulus * line.web.thickness * line.web.width


def test_a_single_run_carries_its_line_file(sweep):
    run = read_datasets([sweep / "single"])[0]
    assert run_line_data(run) == read_yaml(REPO / "lines" / "single_span.yaml")


def test_a_sweep_run_carries_set_and_axis_values(sweep):
    runs = read_datasets([sweep / "data"])
    assert len(runs) == 4
    for r in runs:
        data = run_line_data(r)
        assert data["web"]["width"] == "0.5 m"
        assert (
            data["web"]["thickness"] == json.loads(r.info["overrides_json"])["line.web.thickness"]
        )
    # what a plug-in sees: E·A = 1 GPa x thickness x 0.5 m, per run, in fit and in score
    train = [r for r in runs if r.info["seed"] == 1]
    test = [r for r in runs if r.info["seed"] == 2]
    evaluate(LineSpy(), train, test, n_boot=0)
    expect = [1e9 * float(r.info["axis.thickness"]) * 0.5 for r in train + test]
    assert LineSpy.seen == pytest.approx(expect)
    assert sorted(set(LineSpy.seen)) == pytest.approx([5e4, 1e5])


def test_frames_without_a_line():
    frame = pd.DataFrame({"t_s": [0.0, 1.0]})
    assert frame_line(frame) is None
    assert LINE_ATTR == "r2rsim.line"
