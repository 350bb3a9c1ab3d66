"""Bad input: one message naming the file, the YAML path and the problem; a non-zero exit
code; no output directory (README.md, "A line file")."""

from __future__ import annotations

import copy
import re
import subprocess
import sys

import pytest
import yaml

from r2rsim.cli import main

from conftest import SMALL_LINE, SMALL_SCENARIO

LINE, SCENARIO = SMALL_LINE, SMALL_SCENARIO


def _line(mutate):
    d = copy.deepcopy(LINE)
    mutate(d)
    return d


def _scen(mutate):
    d = copy.deepcopy(SCENARIO)
    mutate(d)
    return d


def _set(path, value):
    def f(d):
        node = d
        for p in path[:-1]:
            node = node[p]
        node[path[-1]] = value

    return f


def _del(path):
    def f(d):
        node = d
        for p in path[:-1]:
            node = node[p]
        del node[path[-1]]

    return f


CASES = [
    # (name, line dict or None, scenario dict or None, file, yaml path, words in the message)
    (
        "unknown key",
        _line(_set(["elements", 1, "radios"], 0.05)),
        None,
        "line.yaml",
        "elements[1].radios",
        "unknown key 'radios'",
    ),
    (
        "unknown element type",
        _line(_set(["elements", 1, "type"], "roller")),
        None,
        "line.yaml",
        "elements[1].type",
        "unknown type 'roller'",
    ),
    (
        "missing reference",
        _line(_set(["sensors", 0, "element"], "idler9")),
        None,
        "line.yaml",
        "sensors[0].element",
        "no element with id 'idler9'",
    ),
    (
        "negative length",
        _line(_set(["spans", 1, "length"], "-1 m")),
        None,
        "line.yaml",
        "spans[1].length",
        "must be > 0",
    ),
    (
        "core radius >= roll radius",
        _line(_set(["elements", 3, "roll", "core_radius"], "0.2 m")),
        None,
        "line.yaml",
        "elements[3].roll.core_radius",
        "must be smaller",
    ),
    (
        "bad unit string",
        _line(_set(["spans", 0, "length"], "1.5 meterz")),
        None,
        "line.yaml",
        "spans[0].length",
        "cannot read '1.5 meterz'",
    ),
    (
        "wrong dimension",
        _line(_set(["spans", 2, "length"], "3 N")),
        None,
        "line.yaml",
        "spans[2].length",
        "expected a length",
    ),
    (
        "missing required key",
        _line(_del(["elements", 2, "radius"])),
        None,
        "line.yaml",
        "elements[2].radius",
        "missing required key 'radius'",
    ),
    (
        "duplicate id",
        _line(_set(["elements", 2, "id"], "idler1")),
        None,
        "line.yaml",
        "elements[2].id",
        "duplicate id 'idler1'",
    ),
    (
        "controller on an idler",
        _line(_set(["controllers", 0, "element"], "idler1")),
        None,
        "line.yaml",
        "controllers[0].element",
        "no drive",
    ),
    (
        "wrong span count",
        _line(lambda d: d["spans"].pop()),
        None,
        "line.yaml",
        "spans",
        "expected 3 spans",
    ),
    (
        "first element not an unwind",
        _line(lambda d: d["elements"].reverse()),
        None,
        "line.yaml",
        "elements[0].type",
        "must be an unwind",
    ),
    (
        "unknown material",
        _line(_set(["web", "material"], "kevlar")),
        None,
        "line.yaml",
        "web.material",
        "kevlar",
    ),
    (
        "scenario unknown key",
        None,
        _scen(_set(["durations"], 3)),
        "scen.yaml",
        "durations",
        "unknown key",
    ),
    (
        "scenario wrong dimension",
        None,
        _scen(_set(["duration"], "5 m")),
        "scen.yaml",
        "duration",
        "expected a time",
    ),
    (
        "scenario unknown controller",
        None,
        _scen(_set(["programme"], [{"at": 1, "tension": {"nope": 100}}])),
        "scen.yaml",
        "programme[0].tension.nope",
        "no tension controller 'nope'",
    ),
    (
        "splicer without a spare roll",
        _line(_set(["elements", 0, "splicer"], {"type": "flying"})),
        None,
        "line.yaml",
        "elements[0].spare_roll",
        "needs the spare roll",
    ),
    (
        "dancer loop on an unknown dancer",
        _line(
            lambda d: d["controllers"].append(
                {"id": "dl", "type": "dancer_pi", "dancer": "nope", "element": "unwind", "kp": 1}
            )
        ),
        None,
        "line.yaml",
        "controllers[2].dancer",
        "no dancer or festoon span with id 'nope'",
    ),
    (
        "scenario splice without a splicer",
        None,
        _scen(_set(["events"], [{"at": 1, "type": "splice"}])),
        "scen.yaml",
        "events[0]",
        "no unwind of the line has a splicer: give the unwind a 'splicer:'",
    ),
    (
        "scenario e_stop without deceleration",
        None,
        _scen(_set(["events"], [{"at": 1, "type": "e_stop"}])),
        "scen.yaml",
        "events[0]",
        "needs its deceleration limit",
    ),
    (
        "scenario missing line file",
        None,
        _scen(_set(["line"], "missing.yaml")),
        "scen.yaml",
        "line",
        "not found",
    ),
    (
        "scenario draw of an idler",
        None,
        _scen(_set(["programme"], [{"at": 1, "draw": {"idler1": 0.001}}])),
        "scen.yaml",
        "programme[0].draw.idler1",
        "has no drive, so no draw",
    ),
    (
        "scenario draw of a torque-mode roll",
        None,
        _scen(_set(["programme"], [{"at": 1, "draw": {"unwind": 0.001}}])),
        "scen.yaml",
        "programme[0].draw.unwind",
        "tension-controlled in torque mode",
    ),
    (
        "scenario torque on a speed-controlled roller",
        None,
        _scen(_set(["programme"], [{"at": 1, "torque": {"pull": 2}}])),
        "scen.yaml",
        "programme[0].torque.pull",
        "commanded by speed_pi 'speed'",
    ),
    (
        "torque command on a controlled drive",
        _line(_set(["elements", 2, "drive"], {"torque_command": "2 N*m"})),
        None,
        "line.yaml",
        "elements[2].drive.torque_command",
        "commanded by speed_pi 'speed'",
    ),
    (
        "inertia estimate twice",
        _line(_set(["controllers", 1, "feedforward"], {"inertia": {"factor": 1, "value": 2}})),
        None,
        "line.yaml",
        "controllers[1].feedforward.inertia",
        "factor or as value",
    ),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_input_one_clear_message(tmp_path, capsys, case):
    _, line, scen, file, ypath, words = case
    (tmp_path / "line.yaml").write_text(yaml.safe_dump(line or LINE, sort_keys=False))
    (tmp_path / "scen.yaml").write_text(yaml.safe_dump(scen or SCENARIO, sort_keys=False))
    out = tmp_path / "out"
    code = main(["run", str(tmp_path / "scen.yaml"), "-o", str(out), "-q"])
    err = capsys.readouterr().err.strip()
    assert code != 0
    first, *quoted = err.splitlines()
    # one line; an unknown key is located by its line and quoted from the file below it
    assert len(quoted) == ("unknown key" in words), err
    assert re.search(rf"{re.escape(file)}: (line \d+: )?{re.escape(ypath)}: ", first), err
    assert words in first, err
    assert not out.exists()
    assert not any(p.name.startswith(".out") for p in tmp_path.iterdir())


def test_invalid_yaml_names_line_and_column(tmp_path, capsys):
    (tmp_path / "scen.yaml").write_text("line: x.yaml\nduration: [1, 2\n")
    assert main(["run", str(tmp_path / "scen.yaml"), "-q"]) != 0
    err = capsys.readouterr().err
    assert "scen.yaml: line 3" in err and "invalid YAML" in err


def test_yaml_is_loaded_safely(tmp_path, capsys):
    (tmp_path / "scen.yaml").write_text("line: !!python/object/apply:os.system ['echo hi']\n")
    assert main(["validate", str(tmp_path / "scen.yaml")]) != 0
    assert "invalid YAML" in capsys.readouterr().err


def test_validate_lists_every_problem(tmp_path, capsys):
    bad = _line(_set(["spans", 0, "length"], "-1 m"))
    bad["elements"][1]["radios"] = 1
    (tmp_path / "line.yaml").write_text(yaml.safe_dump(bad))
    assert main(["validate", str(tmp_path / "line.yaml")]) == 2
    # one line per problem (the unknown key's followed by its line of the file, indented)
    err = [e for e in capsys.readouterr().err.splitlines() if not e.startswith(" ")]
    assert len(err) == 2
    assert any("spans[0].length" in e for e in err)
    assert any("elements[1].radios" in e for e in err)


def test_real_exit_code_and_debug_traceback(tmp_path):
    (tmp_path / "line.yaml").write_text(yaml.safe_dump(_line(_set(["spans", 0, "length"], -1))))
    (tmp_path / "scen.yaml").write_text(yaml.safe_dump(SCENARIO))
    cmd = [sys.executable, "-m", "r2rsim.cli", "run", str(tmp_path / "scen.yaml"), "-q"]
    p = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path)
    assert p.returncode == 2
    assert p.stderr.startswith("error: ") and "Traceback" not in p.stderr
    p = subprocess.run(
        cmd[:3] + ["--debug"] + cmd[3:], capture_output=True, text=True, cwd=tmp_path
    )
    assert p.returncode != 0 and "Traceback" in p.stderr
    assert not (tmp_path / "runs").exists()


def test_valid_files_validate(repo, capsys):
    files = [repo / "lines" / "pet_film_line.yaml", repo / "scenarios" / "quickstart.yaml"]
    assert main(["validate", *map(str, files)]) == 0
    out = capsys.readouterr().out
    assert "valid line" in out and "valid scenario" in out


@pytest.mark.parametrize(
    "flag,value,words",
    [("--duration", "-1", "--duration must be > 0"), ("--seed", "-3", "--seed must be >= 0")],
)
def test_bad_cli_values(tmp_path, capsys, repo, flag, value, words):
    out = tmp_path / "out"
    code = main(
        ["run", str(repo / "scenarios" / "quickstart.yaml"), "-o", str(out), flag, value, "-q"]
    )
    err = capsys.readouterr().err.strip()
    assert code == 2 and words in err and len(err.splitlines()) == 1
    assert not out.exists()


def test_solver_settings_are_validated():
    import r2rsim

    with pytest.raises(ValueError, match="rtol"):
        r2rsim.SolverSettings(rtol=-1.0)
    assert r2rsim.SolverSettings().max_order == 2
