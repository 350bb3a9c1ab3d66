"""A tension set-point above the web's break tension (issue: 300 kN on the quick-start line
warned "the web breaks" and the run ended normally). The unwind's tension loop commands its
torque, and its drive saturates at torque_max: it holds at most torque_max / R, 1 kN at the
full roll and 5.3 kN at the core, under the 10.5 kN break tension, so the web cannot break.
The warning now says so, with those numbers; without the torque limit the web does break."""

from __future__ import annotations

import re
import warnings

import numpy as np
import pandas as pd
import pytest

import r2rsim
from r2rsim.errors import PlausibilityWarning

from conftest import REPO

LINE = (REPO / "lines" / "pet_film_line.yaml").read_text(encoding="utf-8")
SCENARIO = """\
name: break_setpoint
line: line.yaml
duration: 6 s
record_rate: 50 Hz
initial: {state: steady}
programme:
  - {at: 0 s, line_speed: 5 m/s}
  - {at: 1 s, tension: {unwind_tension: 300 kN}, ramp: 1 s}
"""


def _files(tmp_path, line=LINE):
    (tmp_path / "line.yaml").write_text(line)
    (tmp_path / "scen.yaml").write_text(SCENARIO)
    return tmp_path / "scen.yaml"


def _run(path, out):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        summary = r2rsim.run_scenario(path, output=out)
    return summary, [str(w.message) for w in caught if issubclass(w.category, PlausibilityWarning)]


def test_torque_limited_unwind_cannot_break_the_web(tmp_path):
    summary, warned = _run(_files(tmp_path), tmp_path / "out")
    [msg] = [w for w in warned if "break tension" in w]
    assert (
        "programme[1].tension.unwind_tension: 3e+05 N is above the web's break tension "
        "1.05e+04 N" in msg
    )
    # computed from the line: 400 N m / 0.40 m and / 0.076 m
    assert (
        ", but the web does not break: 'unwind_tension' commands the torque of 'unwind', "
        "whose torque_max 400 N m holds at most torque_max / R = 1e+03 N at its starting "
        "radius 0.4 m and 5.26e+03 N at its core radius 0.076 m" in msg
    )
    assert not summary.terminated
    assert summary.tension_stats["span1"][2] < 0.2 * 10.5e3  # max: far from breaking
    # settled: the drive saturated at 400 N m, the tension 400 N m / R (R just under 0.4 m)
    s = pd.read_parquet(tmp_path / "out" / "samples")
    end = s[s.t_s >= 5.0]
    assert np.abs(end["act.unwind.torque_N_m"].to_numpy()) == pytest.approx(400.0, rel=1e-3)
    held = 400.0 / end["state.unwind.radius_m"]
    assert end["state.span1.tension_N"].to_numpy() == pytest.approx(held.to_numpy(), rel=0.05)


def test_without_the_torque_limit_the_web_breaks(tmp_path):
    line = LINE.replace(
        "drive: {torque_lag: 1 ms, torque_max: 400 N*m}\n  - id: idler1",
        "drive: {torque_lag: 1 ms}\n  - id: idler1",
    )
    assert line != LINE
    summary, warned = _run(_files(tmp_path, line), tmp_path / "out")
    [msg] = [w for w in warned if "break tension" in w]
    assert msg.endswith("(break_stress x thickness x width): the web breaks")
    assert summary.terminated and summary.termination_reason == "web_break"


@pytest.mark.parametrize(
    "torque_max,words",
    [
        (
            "2000 N*m",
            re.escape(
                ": the web breaks only once the roll has unwound to a radius of "
                "0.19 m (torque_max / break tension)"
            ),
        ),
        ("5000 N*m", r"\(break_stress x thickness x width\): the web breaks$"),
    ],
)
def test_break_depends_on_the_radius_range(tmp_path, torque_max, words):
    from r2rsim.schema import load_line
    from r2rsim.schema.plausibility import tension_problems

    (tmp_path / "line.yaml").write_text(
        LINE.replace(
            "torque_max: 400 N*m}\n  - id: idler1", f"torque_max: {torque_max}}}\n  - id: idler1"
        )
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        line = load_line(tmp_path / "line.yaml")
    [(level, path, msg)] = tension_problems(line, 3e5, "x", "unwind_tension")
    assert level == "warning" and re.search(words, msg), msg
