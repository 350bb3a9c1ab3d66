"""Hostile and absurd input: every case is refused before anything is compiled or simulated,
with one ``file: yaml.path: problem`` line, exit code 2 from the CLI, no traceback and
nothing written (docs/security.md). Valid but unusual values give ``warning:`` lines and run
on. Each case takes milliseconds: none of them reaches the solver."""

from __future__ import annotations

import math
import os

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

import r2rsim
from r2rsim import limits
from r2rsim.cli import build_parser, main
from r2rsim.errors import InputError, PlausibilityWarning
from r2rsim.schema.scenario import ProgrammeStep, Scenario

from conftest import REPO, SMALL_LINE, SMALL_SCENARIO, edited

LINE, SCENARIO = SMALL_LINE, SMALL_SCENARIO
NAN, INF = math.nan, math.inf


def L(path, value):  # noqa: N802 - a line with one value changed
    return ("line", edited(LINE, path, value))


def S(path, value):  # noqa: N802 - a scenario with one value changed
    return ("scen", edited(SCENARIO, path, value))


def _fault(**kw):
    return {
        "id": "f1",
        "type": "sensor.offset",
        "target": "lc",
        "onset": 0.1,
        "magnitude": 1.0,
        **kw,
    }


def _write(tmp_path, which=None, data=None, text=None):
    """line.yaml and scen.yaml in tmp_path; one of them replaced by ``data`` or raw
    ``text`` (str or bytes)."""
    files = {"line": tmp_path / "line.yaml", "scen": tmp_path / "scen.yaml"}
    files["line"].write_text(yaml.safe_dump(LINE, sort_keys=False))
    files["scen"].write_text(yaml.safe_dump(SCENARIO, sort_keys=False))
    if data is not None:
        files[which].write_text(yaml.safe_dump(data, sort_keys=False))
    if text is not None:
        if isinstance(text, str):
            text = text.encode()
        files[which].write_bytes(text)
    return files


def _run(tmp_path, capsys, *extra):
    out = tmp_path / "out"
    code = main(["run", str(tmp_path / "scen.yaml"), "-o", str(out), "-q", *extra])
    err = capsys.readouterr().err.strip()
    assert not out.exists(), "an output directory was written"
    assert not any(p.name.startswith(".out") for p in tmp_path.iterdir())
    return code, err


def _assert_one_line(code, err, file, ypath, words):
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    assert err.startswith("error: ") and "Traceback" not in err
    where = f"{file}: {ypath}: " if ypath else f"{file}: "
    assert where in err, err
    assert words in err, err


# (name, (which file, its data), file named, yaml path, words in the message)
CASES = [
    # 3. quantities: the restricted parser's refusal reaches the CLI as one line
    (
        "power tower",
        L(["spans", 0, "length"], "10**10**10 m"),
        "line.yaml",
        "spans[0].length",
        "cannot read '10**10**10 m'",
    ),
    (
        "division by zero",
        L(["spans", 0, "length"], "1/0 m"),
        "line.yaml",
        "spans[0].length",
        "cannot read",
    ),
    # 4. nan and inf, for every kind of numeric key
    (
        "nan gain",
        L(["controllers", 0, "kp"], NAN),
        "line.yaml",
        "controllers[0].kp",
        "not a finite number",
    ),
    (
        "inf quantity",
        L(["controllers", 1, "setpoint"], INF),
        "line.yaml",
        "controllers[1].setpoint",
        "not a finite number",
    ),
    (
        "-inf thickness",
        L(["web", "thickness"], -INF),
        "line.yaml",
        "web.thickness",
        "not a finite number",
    ),
    (
        "inf in wound_in_strain list",
        L(["elements", 0, "roll", "wound_in_strain"], [1e-3, -INF]),
        "line.yaml",
        "elements[0].roll.wound_in_strain[1]",
        "not a finite number",
    ),
    (
        "inf in a sensor range",
        L(["sensors", 0, "range"], [0.0, INF]),
        "line.yaml",
        "sensors[0].range[1]",
        "not a finite number",
    ),
    (
        "nan in a dict value",
        S(["initial"], {"state": "nominal", "span_tension": {"span1": NAN}}),
        "scen.yaml",
        "initial.span_tension.span1",
        "not a finite number",
    ),
    (
        "inf tension set-point step",
        S(["programme", 0, "tension"], {"tens": INF}),
        "scen.yaml",
        "programme[0].tension.tens",
        "not a finite number",
    ),
    (
        "nan in a drawn onset",
        S(["faults"], [_fault(onset={"uniform": [0.0, NAN]})]),
        "scen.yaml",
        "faults[0].onset.uniform[1]",
        "not a finite number",
    ),
    (
        "inf in a magnitude choice",
        S(["faults"], [_fault(magnitude={"choice": [1.0, INF]})]),
        "scen.yaml",
        "faults[0].magnitude.choice[1]",
        "not a finite number",
    ),
    (
        "nan profile parameter",
        S(
            ["faults"],
            [
                _fault(
                    type="sensor.gain",
                    magnitude=0.1,
                    profile={"shape": "intermittent", "period": 1.0, "duty": NAN},
                )
            ],
        ),
        "scen.yaml",
        "faults[0].profile.duty",
        "not a finite number",
    ),
    (
        "nan disturbance std",
        S(
            ["disturbances"],
            [{"type": "bearing_drag", "element": "idler1", "std": NAN, "bandwidth": 2.0}],
        ),
        "scen.yaml",
        "disturbances[0].std",
        "not a finite number",
    ),
    (
        "nan solver setting",
        S(["solver"], {"rtol": NAN}),
        "scen.yaml",
        "solver.rtol",
        "not a finite number",
    ),
    # 5. booleans are not numbers
    (
        "std: true",
        S(
            ["disturbances"],
            [{"type": "bearing_drag", "element": "idler1", "std": True, "bandwidth": 2.0}],
        ),
        "scen.yaml",
        "disturbances[0].std",
        "got true (a boolean)",
    ),
    (
        "output_limit: true",
        L(["controllers", 1, "output_limit"], True),
        "line.yaml",
        "controllers[1].output_limit",
        "got true (a boolean)",
    ),
    (
        "kp: false",
        L(["controllers", 0, "kp"], False),
        "line.yaml",
        "controllers[0].kp",
        "got false (a boolean)",
    ),
    ("seed: true", S(["seed"], True), "scen.yaml", "seed", "got true (a boolean)"),
    (
        "magnitude: true",
        S(["faults"], [_fault(magnitude=True)]),
        "scen.yaml",
        "faults[0].magnitude",
        "(a boolean)",
    ),
    (
        "a boolean quantity",
        L(["web", "thickness"], True),
        "line.yaml",
        "web.thickness",
        "got a boolean",
    ),
    (
        "a number is not a boolean",
        L(["controllers", 0, "master"], 1),
        "line.yaml",
        "controllers[0].master",
        "expected true or false",
    ),
    # 5. sizes: refused before any array is sized by them
    (
        "record_rate 1e300",
        S(["record_rate"], 1e300),
        "scen.yaml",
        "record_rate",
        "above the limit of 100000 Hz",
    ),
    ("duration 1e300", S(["duration"], 1e300), "scen.yaml", "duration", "longer than the limit"),
    (
        "record_rate 1 MHz",
        S(["record_rate"], "1 MHz"),
        "scen.yaml",
        "record_rate",
        "above the limit",
    ),
    (
        "too many samples",
        ("scen", {**SCENARIO, "duration": "1e6 s", "record_rate": "1 kHz"}),
        "scen.yaml",
        "duration",
        "1e+09 samples, more than the limit of 1e+08",
    ),
    ("seed above 2**64 - 1", S(["seed"], 2**64), "scen.yaml", "seed", "18446744073709551615"),
    (
        "a programme too long",
        S(["programme"], [{"at": 0.0, "line_speed": 1.0}] * 10_001),
        "scen.yaml",
        "programme",
        "too many entries (10001); at most 10000",
    ),
    (
        "too many events",
        S(["events"], [{"at": 0.1, "type": "dancer_seize", "element": "x"}] * 1001),
        "scen.yaml",
        "events",
        "at most 1000",
    ),
    (
        "a disturbance table too fine",
        S(
            ["disturbances"],
            [
                {
                    "type": "wound_in_strain",
                    "element": "unwind",
                    "std": 1e-5,
                    "shape": "table",
                    "correlation_length": "1 nm",
                }
            ],
        ),
        "scen.yaml",
        "disturbances[0].correlation_length",
        "more than 1e+08 points",
    ),
    (
        "a disturbance too fast",
        S(
            ["disturbances"],
            [
                {
                    "type": "wound_in_strain",
                    "element": "unwind",
                    "std": 1e-5,
                    "correlation_length": "1 nm",
                }
            ],
        ),
        "scen.yaml",
        "disturbances[0].correlation_length",
        "above half the record rate",
    ),
    # 6. physically impossible: refused before a run that would hang or mislead
    (
        "web 1 m thick",
        L(["web", "thickness"], "1 m"),
        "line.yaml",
        "web.thickness",
        "cannot wrap a roller of radius 0.05 m",
    ),
    (
        "kp 1e300 on a tension loop",
        L(["controllers", 1, "kp"], 1e300),
        "line.yaml",
        "controllers[1].kp",
        "no drive is that fast",
    ),
    (
        "kp 1e300 on a speed loop",
        L(["controllers", 0, "kp"], 1e300),
        "line.yaml",
        "controllers[0].kp",
        "no drive is that fast",
    ),
    (
        "modulus 1e20",
        L(["web", "modulus"], 1e20),
        "line.yaml",
        "web.modulus",
        "stiffer than diamond",
    ),
    (
        "density above osmium",
        L(["web", "density"], 1e5),
        "line.yaml",
        "web.density",
        "denser than osmium",
    ),
    (
        "1 nm span",
        L(["spans", 0, "length"], "1 nm"),
        "line.yaml",
        "spans[0].length",
        "shorter than 1 mm",
    ),
    (
        "faster than the web's waves",
        S(["programme", 0, "line_speed"], "5 km/s"),
        "scen.yaml",
        "programme[0].line_speed",
        "wave speed",
    ),
    # values whose arithmetic overflowed the integrator or the float32 samples (they ended
    # in a ZeroDivisionError traceback, or in columns of inf with exit 0)
    (
        "coulomb friction 1e300",
        L(["elements", 1, "friction"], {"coulomb": "1e300 N*m"}),
        "line.yaml",
        "elements[1].friction.coulomb",
        "beyond any bearing",
    ),
    (
        "bearing drag 1e300",
        S(
            ["disturbances"],
            [
                {
                    "type": "bearing_drag",
                    "element": "idler1",
                    "std": "1e300 N*m",
                    "bandwidth": "1 Hz",
                }
            ],
        ),
        "scen.yaml",
        "disturbances[0].std",
        "beyond any bearing",
    ),
    (
        "gain 1e300 on the loop's load cell",
        L(["sensors", 0, "gain"], 1e300),
        "line.yaml",
        "sensors[0].gain",
        "not a calibration",
    ),
    ("gain 0", L(["sensors", 0, "gain"], 0.0), "line.yaml", "sensors[0].gain", "not a calibration"),
    (
        "load-cell noise 1e300",
        L(["sensors", 0, "noise"], "1e300 N"),
        "line.yaml",
        "sensors[0].noise",
        "beyond any sensor's reading",
    ),
    (
        "speed noise 1e300",
        L(["sensors", 0, "noise_per_speed"], 1e300),
        "line.yaml",
        "sensors[0].noise_per_speed",
        "beyond any sensor's reading",
    ),
    (
        "quantization 1e-320",
        L(["sensors", 0, "quantization"], 1e-320),
        "line.yaml",
        "sensors[0].quantization",
        "finer than any instrument",
    ),
    (
        "wound-in strain 17",
        L(["elements", 0, "roll", "wound_in_strain"], 17.0),
        "line.yaml",
        "elements[0].roll.wound_in_strain",
        "Hooke's law no longer describes",
    ),
    (
        "wound-in strain std 0.1",
        S(
            ["disturbances"],
            [
                {
                    "type": "wound_in_strain",
                    "element": "unwind",
                    "std": 0.1,
                    "correlation_length": "5 m",
                }
            ],
        ),
        "scen.yaml",
        "disturbances[0].std",
        "within 4 standard deviations",
    ),
    (
        "a drawn wound-in strain of 10",
        S(["variability"], {"rolls": {"unwind": {"wound_in_strain": {"std": 10}}}}),
        "scen.yaml",
        "variability.rolls.unwind.wound_in_strain.std",
        "Hooke's law no longer describes",
    ),
    (
        "a drawn offset of 1e30 N",
        S(["variability"], {"sensors": {"lc": {"offset": {"tolerance": "1e30 N"}}}}),
        "scen.yaml",
        "variability.sensors.lc.offset.tolerance",
        "beyond any sensor's reading",
    ),
    (
        "two eccentricities on one roller",
        S(
            ["disturbances"],
            [
                {"type": "out_of_round", "element": "idler1", "eccentricity": "0.01 mm"},
                {"type": "out_of_round", "element": "idler1", "eccentricity": "0.02 mm"},
            ],
        ),
        "scen.yaml",
        "disturbances[1].element",
        "already out of round",
    ),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_value_one_line_through_run(tmp_path, capsys, case):
    _, (which, data), file, ypath, words = case
    _write(tmp_path, which, data)
    _assert_one_line(*_run(tmp_path, capsys), file, ypath, words)


@pytest.mark.parametrize(
    "case", [c for c in CASES if c[1][0] == "line"], ids=[c[0] for c in CASES if c[1][0] == "line"]
)
def test_bad_line_value_through_validate(tmp_path, capsys, case):
    _, (which, data), file, ypath, words = case
    files = _write(tmp_path, which, data)
    assert main(["validate", str(files["line"])]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert f"{file}: {ypath}: " in err[0] and words in err[0], err


# raw files: encodings, YAML constructs, sizes. (name, file, text, yaml path, words)
_NEST = "[" * 5000 + "]" * 5000
_LAUGHS = "".join(
    f"{c}: &{c} [{', '.join([f'*{p}'] * 9)}]\n" for p, c in zip("abcdefgh", "bcdefghi", strict=True)
)
RAW = [
    (
        "duplicate key",
        "scen",
        "line: line.yaml\nduration: 1 s\nduration: 2 s\n",
        "line 3, column 1",
        "duplicate key 'duration' (first given at line 2)",
    ),
    (
        "duplicate key in a nested mapping",
        "line",
        yaml.safe_dump(LINE, sort_keys=False).replace(
            "  width: 1 m\n", "  width: 1 m\n  width: 2 m\n"
        ),
        "line 6, column 3",
        "duplicate key 'width' (first given at line 5)",
    ),
    (
        "UTF-16 with a byte-order mark",
        "scen",
        yaml.safe_dump(SCENARIO).encode("utf-16"),
        None,
        "the file is UTF-16 text; save it as UTF-8",
    ),
    (
        "UTF-16 without a byte-order mark",
        "scen",
        yaml.safe_dump(SCENARIO).encode("utf-16-le"),
        "line 1, column 2",
        "NUL bytes",
    ),
    (
        "Latin-1 bytes",
        "line",
        yaml.safe_dump(LINE, sort_keys=False)
        .replace("name: small", "name: caf\xe9")
        .encode("latin-1"),
        "line 1, column 10",
        "not UTF-8",
    ),
    (
        "an escaped NUL in a string",
        "scen",
        'line: line.yaml\nduration: 1 s\nname: "a\\0b"\n',
        "name",
        "control character '\\x00'",
    ),
    (
        "a raw control character",
        "scen",
        "line: line.yaml\nduration: 1 s\nname: a\x1bb\n",
        "line 3, column 8",
        "unacceptable character U+001B",
    ),
    (
        "5000 nested lists",
        "scen",
        f"line: line.yaml\nduration: 1 s\nprogramme: {_NEST}\n",
        "line 3, column 43",
        "nested more than 32 levels",
    ),
    (
        "an integer of 5000 digits",
        "scen",
        "line: line.yaml\nduration: 1 s\nseed: " + "9" * 5000 + "\n",
        "line 3, column 7",
        "too long",
    ),
    (
        "billion laughs",
        "scen",
        "line: line.yaml\nduration: 1 s\nx:\n  a: &a [1, 2, 3, 4, 5, 6, "
        "7, 8, 9]\n" + "".join("  " + ln + "\n" for ln in _LAUGHS.splitlines()),
        None,
        "expands to more than 500000 values",
    ),
    (
        "an alias inside itself",
        "scen",
        "line: line.yaml\nduration: 1 s\nx: &x [*x]\n",
        None,
        "nested more than 32 levels deep",
    ),
    (
        "a python tag",
        "scen",
        "line: !!python/object/apply:os.system ['true']\n",
        "line 1, column 7",
        "invalid YAML",
    ),
    (
        "more than 1 MiB",
        "scen",
        "line: line.yaml\nduration: 1 s\ndescription: '" + "x" * limits.MAX_FILE_BYTES + "'\n",
        None,
        "more than the limit of 1048576 bytes",
    ),
]


@pytest.mark.parametrize("case", RAW, ids=[c[0] for c in RAW])
def test_bad_file_one_line_through_run_and_validate(tmp_path, capsys, case):
    _, which, text, ypath, words = case
    files = _write(tmp_path, which, text=text)
    file = files[which].name
    if which == "scen":
        _assert_one_line(*_run(tmp_path, capsys), file, ypath, words)
    assert main(["validate", str(files[which])]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert (f"{file}: {ypath}: " if ypath else f"{file}: ") in err and words in err, err


def test_yaml_12_floats_are_numbers(tmp_path, capsys):
    # YAML 1.1 reads 1e-4 as a string; the loader reads it as the number everyone means
    files = _write(tmp_path, "line", edited(LINE, ["controllers", 1, "ki"], "KI"))
    files["line"].write_text(files["line"].read_text().replace("KI", "1e-4"))
    assert r2rsim.load_line(files["line"]).controllers[1].ki == 1e-4


# 11. what the line: key may name
def test_line_file_from_dev_zero_is_refused_at_once(tmp_path, capsys):
    _write(tmp_path, "scen", edited(SCENARIO, ["line"], "/dev/zero"))
    _assert_one_line(*_run(tmp_path, capsys), "scen.yaml", "line", "not a regular file")
    assert main(["validate", "/dev/zero"]) == 2
    assert "is a device; line and scenario files must be regular files" in capsys.readouterr().err


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_fifo_is_refused_without_blocking(tmp_path, capsys):
    os.mkfifo(tmp_path / "pipe.yaml")  # opening it for reading would wait for a writer
    _write(tmp_path, "scen", edited(SCENARIO, ["line"], "pipe.yaml"))
    _assert_one_line(*_run(tmp_path, capsys), "scen.yaml", "line", "not a regular file")
    assert main(["validate", str(tmp_path / "pipe.yaml")]) == 2
    assert "is a FIFO (named pipe)" in capsys.readouterr().err


def test_directory_as_line_file(tmp_path, capsys):
    (tmp_path / "lines").mkdir()
    _write(tmp_path, "scen", edited(SCENARIO, ["line"], "lines"))
    _assert_one_line(*_run(tmp_path, capsys), "scen.yaml", "line", "not a regular file")


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="no symlinks here")
def test_symlinked_line_file_is_fine(tmp_path, capsys):
    files = _write(tmp_path)
    (tmp_path / "link.yaml").symlink_to(files["line"])
    files["scen"].write_text(yaml.safe_dump(edited(SCENARIO, ["line"], "link.yaml")))
    assert main(["validate", str(files["scen"])]) == 0, capsys.readouterr().err


# command-line values
def test_duration_takes_units_like_the_files():
    args = build_parser().parse_args(["run", "s.yaml", "--duration", "90 s"])
    assert args.duration == 90.0
    assert build_parser().parse_args(["run", "s.yaml", "--duration", "2 min"]).duration == 120
    assert build_parser().parse_args(["run", "s.yaml", "--duration", "1.5"]).duration == 1.5


@pytest.mark.parametrize(
    "value, words",
    [("inf", "not a finite number"), ("nan", "not a finite number"), ("5 m", "expected a time")],
)
def test_bad_duration_is_an_argparse_error(capsys, value, words):
    with pytest.raises(SystemExit) as exc:
        main(["run", "s.yaml", "--duration", value])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "argument --duration" in err and words in err and "Traceback" not in err


@pytest.mark.parametrize(
    "flag, value, words",
    [
        ("--duration", "1e300", "longer than the limit of 1e+06 s"),
        # just over the limit: the value is printed in full, not rounded onto the limit
        ("--duration", "1000001", "1000001 s is longer than the limit of 1e+06 s"),
        ("--duration", "1e6", "samples, more than the limit"),
        ("--seed", "99999999999999999999999", "--seed must be at most 2**64 - 1"),
    ],
)
def test_bad_override_one_line(tmp_path, capsys, flag, value, words):
    _write(tmp_path, "scen", edited(SCENARIO, ["record_rate"], "1 kHz"))
    code, err = _run(tmp_path, capsys, flag, value)
    assert code == 2 and len(err.splitlines()) == 1 and words in err, err


# warnings: valid but unusual, printed as one line each, and the command goes on
@pytest.mark.parametrize(
    "which, data, ypath, words",
    [
        (
            "line",
            edited(
                LINE,
                ["web"],
                {"thickness": "50 um", "width": "1 m", "modulus": "4.5 GPa", "density": 1390},
            ),
            "web.break_stress",
            "can never break",
        ),
        (
            "line",
            edited(LINE, ["controllers", 1, "setpoint"], "20 kN"),
            "controllers[1].setpoint",
            "above the web's break tension 1.05e+04 N",
        ),
        (
            "line",
            edited(LINE, ["spans", 1, "length"], "2 km"),
            "spans[1].length",
            "outside the range of free spans",
        ),
        (
            "line",
            edited(LINE, ["web", "thickness"], "8 mm"),
            "web.thickness",
            "outside the range of webs",
        ),
        (
            "scen",
            edited(SCENARIO, ["programme", 0, "line_speed"], "60 m/s"),
            "programme[0].line_speed",
            "faster than any line",
        ),
        (
            "scen",
            edited(SCENARIO, ["initial"], {"state": "nominal", "tension": "20 kN"}),
            "initial.tension",
            "the web breaks at t = 0",
        ),
    ],
)
def test_plausibility_warning_is_one_line_and_validate_passes(
    tmp_path, capsys, which, data, ypath, words
):
    files = _write(tmp_path, which, data)
    assert main(["validate", str(files[which])]) == 0
    out = capsys.readouterr()
    # (60 m/s also finds no steady state: validate prints the warning `run` would)
    warns = [w for w in out.err.splitlines() if f": {ypath}: " in w]
    assert len(warns) == 1 and warns[0].startswith("warning: "), out.err
    assert f"{files[which].name}: {ypath}: " in warns[0] and words in warns[0], warns
    assert "valid" in out.out
    with pytest.warns(PlausibilityWarning, match=words.replace("+", r"\+")):
        (r2rsim.load_line if which == "line" else r2rsim.load_scenario)(files[which])


def test_shipped_files_are_plausible(recwarn):
    from r2rsim.sweep import plan_sweep

    for p in [*(REPO / "lines").glob("*.yaml"), *(REPO / "scenarios").rglob("*.yaml")]:
        if p.parent.name == "lines":
            r2rsim.load_line(p)
        elif "scenario" in yaml.safe_load(p.read_text(encoding="utf-8")):
            plan_sweep(p)  # a sweep beside its base scenario: every combination loads
        else:
            r2rsim.load_scenario(p)
    assert not [w for w in recwarn if issubclass(w.category, PlausibilityWarning)]


# the Python API refuses the same values
def test_api_refuses_nan_bool_and_sizes():
    with pytest.raises(InputError, match=r"controllers\[0\].kp: nan is not a finite number"):
        r2rsim.load_line(edited(LINE, ["controllers", 0, "kp"], NAN))
    with pytest.raises(InputError, match=r"disturbances\[0\].std: expected a number"):
        _write_scenario_model(
            {
                "disturbances": [
                    {"type": "bearing_drag", "element": "idler1", "std": True, "bandwidth": 2.0}
                ]
            }
        )
    with pytest.raises(ValidationError, match="at most 10000 items"):
        Scenario.model_validate(
            {**SCENARIO, "programme": [{"at": 0.0, "line_speed": 1.0}] * 10_001}
        )
    with pytest.raises(ValidationError, match="finite number"):
        ProgrammeStep(at=NAN, line_speed=1.0)


def _write_scenario_model(extra):
    from r2rsim.schema.loader import _validate

    return _validate(Scenario, {**SCENARIO, **extra}, "<scenario>")


@pytest.fixture(scope="module")
def single_span():
    line = r2rsim.load_line(REPO / "lines" / "single_span.yaml")  # breaks at 500 N
    return r2rsim.compile_line(line)


def test_simulate_refuses_absurd_sizes_before_sizing_arrays(single_span):
    for duration, rate, key in [
        (1e300, 100.0, "duration"),
        (1.0, 1e300, "record_rate"),
        (math.inf, 100.0, "duration"),
    ]:
        with pytest.raises(InputError, match=key):
            r2rsim.simulate(single_span, duration, rate)


def test_a_web_above_its_break_tension_at_t0_breaks_at_once(single_span):
    # the break condition is true from the start: no crossing would ever report it (a web
    # started at 20 kN on a 10.5 kN line ran on and logged a "break" when it relaxed)
    y0 = r2rsim.nominal_state(single_span, 600.0)
    res = r2rsim.simulate(single_span, 1.0, 100.0, y0, r2rsim.SolverSettings(backend="radau"))
    assert res.terminated and res.termination_reason == "web_break"
    assert res.termination_time == 0.0
    assert [(e.t, e.kind, e.component) for e in res.events] == [(0.0, "web_break", "span1")]
    assert "from the start" in res.events[0].message
    assert len(res.t) == 1 and np.isfinite(res.states).all()
