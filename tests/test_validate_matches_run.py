"""``r2rsim validate`` refuses what ``r2rsim run`` refuses, with the same one-line message
naming the file: the checks made while a run is prepared (programme ramps, the compiled
line's geometry and load cells, faults drawn from the seed) included. Also: a problem of a
line file validated beside its scenario is printed once, not once per file that reads it."""

from __future__ import annotations

import pytest

from r2rsim.cli import main

from conftest import REPO

DANCER_LINE = (REPO / "lines" / "pet_film_line_dancer.yaml").read_text(encoding="utf-8")
SCENARIO = """\
line: line.yaml
duration: 60 s
record_rate: 10 Hz
seed: 3
programme:
  - {at: 0 s, line_speed: 1 m/s}
  - {at: 2 s, line_speed: 3 m/s, rate: 0.3 m/s^2}
"""

# (what is changed: (old, new) in the line, (old, new) in the scenario; the file and YAML
# path the error names; words of the message)
CASES = {
    "a ramp still running at the next step": (
        None,
        ("rate: 0.3 m/s^2}\n", "rate: 0.3 m/s^2}\n  - {at: 8 s, line_speed: 2 m/s}\n"),
        "scen.yaml",
        "programme[2].at",
        "before the ramp of programme[1] ends at 8.66667 s",
    ),
    "a dancer roller that overlaps its neighbour": (
        ("position: [0.15 m, -0.75 m]", "position: [0.05 m, -0.05 m]"),
        None,
        "line.yaml",
        "elements[2]",
        "the dancer roller overlaps its upstream neighbour",
    ),
    "a load cell whose axis sees no tension": (
        (
            "element: idler1, wrap_angle: 90 deg",
            "element: idler1, wrap_angle: 180 deg, axis_angle: 90 deg",
        ),
        None,
        "line.yaml",
        "sensors[0].axis_angle",
        "its measuring axis sees no tension",
    ),
    "a fault end before the onset it may draw": (
        None,
        (
            "programme:",
            "faults:\n  - {id: f, type: sensor.offset, target: lc_rewind, "
            "onset: {uniform: [30 s, 40 s]}, end: 31 s, magnitude: 5 N}\nprogramme:",
        ),
        "scen.yaml",
        "faults[0].end",
        "end 31 s can come before the onset, which is drawn up to 40 s",
    ),
}


def _files(tmp_path, line_edit, scen_edit):
    line, scen = DANCER_LINE, SCENARIO
    if line_edit:
        assert line_edit[0] in line
        line = line.replace(*line_edit)
    if scen_edit:
        assert scen_edit[0] in scen
        scen = scen.replace(*scen_edit)
    (tmp_path / "line.yaml").write_text(line, encoding="utf-8")
    (tmp_path / "scen.yaml").write_text(scen, encoding="utf-8")
    return tmp_path / "line.yaml", tmp_path / "scen.yaml"


def test_the_unchanged_files_are_valid_and_run(tmp_path, capsys):
    # the cases below fail because of their one change
    line, scen = _files(tmp_path, None, None)
    assert main(["validate", str(line), str(scen)]) == 0
    out = capsys.readouterr().out
    assert "line.yaml: valid line" in out and "scen.yaml: valid scenario" in out
    assert main(["run", str(scen), "-o", str(tmp_path / "out"), "-q", "--duration", "3"]) == 0


@pytest.mark.parametrize("case", CASES)
def test_validate_refuses_what_run_refuses_with_the_same_message(tmp_path, capsys, case):
    line_edit, scen_edit, file, ypath, words = CASES[case]
    line, scen = _files(tmp_path, line_edit, scen_edit)
    assert main(["validate", str(scen)]) == 2
    checked = capsys.readouterr()
    assert "valid" not in checked.out, checked.out
    [message] = checked.err.splitlines()
    assert f"{file}: {ypath}: " in message and words in message, message

    out = tmp_path / "out"
    assert main(["run", str(scen), "-o", str(out), "-q"]) == 2
    ran = capsys.readouterr().err.strip()
    assert ran == f"error: {message}", (ran, message)  # the same words, file and path
    assert not out.exists()


def test_a_line_problem_is_printed_once_when_its_scenario_is_validated_too(tmp_path, capsys):
    # the line's problem reached twice: through line.yaml, and through scen.yaml's line
    line, scen = _files(tmp_path, CASES["a dancer roller that overlaps its neighbour"][0], None)
    assert main(["validate", str(line), str(scen)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and "line.yaml: elements[2]: " in err[0], err


def test_a_warning_is_printed_once_when_its_line_is_read_twice(tmp_path, capsys):
    line, scen = _files(tmp_path, ("break_stress: 210 MPa", "break_stress: 1 MPa"), None)
    assert main(["validate", str(line), str(scen)]) == 0
    warns = [w for w in capsys.readouterr().err.splitlines() if "break tension" in w]
    assert len(warns) == 1 and warns[0].startswith("warning: "), warns
