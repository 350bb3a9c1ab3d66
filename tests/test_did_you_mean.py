"""Misspelt keys: "did you mean ...?" from the keys allowed at that place of the file, the
typo's line of the file quoted, and a misspelt required key reported as the typo it is, not
as the required key missing."""

from __future__ import annotations

import re

import pytest

from r2rsim.cli import main
from r2rsim.errors import InputError
from r2rsim.schema.line import Line
from r2rsim.schema.loader import allowed_keys, suggestion
from r2rsim.schema.scenario import Scenario

from conftest import REPO


def _files(tmp_path, line_edit=None, scen_edit=None):
    line = (REPO / "lines" / "pet_film_line.yaml").read_text(encoding="utf-8")
    scen = (
        (REPO / "scenarios" / "quickstart.yaml")
        .read_text(encoding="utf-8")
        .replace("../lines/pet_film_line.yaml", "line.yaml")
    )
    (tmp_path / "line.yaml").write_text(line_edit(line) if line_edit else line)
    (tmp_path / "scen.yaml").write_text(scen_edit(scen) if scen_edit else scen)
    return tmp_path / "scen.yaml"


def _run(capsys, *argv):
    code = main(list(map(str, argv)))
    return code, capsys.readouterr().err


def _line_no(path, text):
    return next(i for i, ln in enumerate(path.read_text().splitlines(), 1) if text in ln)


def test_misspelt_required_key_leads_with_the_typo(tmp_path, capsys):
    scen = _files(tmp_path, scen_edit=lambda s: s.replace("\nduration: 60 s", "\ndurations: 60 s"))
    n = _line_no(scen, "durations:")
    code, err = _run(capsys, "run", scen, "-o", tmp_path / "out", "-q")
    assert code == 2
    first, quoted = err.rstrip("\n").split("\n")
    assert first == (
        f"error: {scen}: line {n}: durations: unknown key 'durations' (did you mean 'duration'?)"
    )
    assert quoted == "    durations: 60 s"
    assert "missing required key" not in err
    assert not (tmp_path / "out").exists()


def test_misspelt_key_in_a_nested_mapping(tmp_path, capsys):
    # elements[2] is the S-wrap roller: radius (required) and wrap_angle (optional) misspelt
    def edit(text):
        head, sep, tail = text.partition("  - id: swrapA\n")
        tail = tail.replace(
            "    radius: 0.10 m\n", "    radus: 0.10 m\n    wrap_angel: 180 deg\n", 1
        )
        return head + sep + tail

    scen = _files(tmp_path, line_edit=edit)
    line = tmp_path / "line.yaml"
    code, err = _run(capsys, "validate", line)
    assert code == 2
    lines = err.rstrip("\n").split("\n")
    assert lines == [
        f"{line}: line {_line_no(line, 'radus:')}: elements[2].radus: unknown key 'radus' "
        "(did you mean 'radius'?)",
        "    radus: 0.10 m",
        f"{line}: line {_line_no(line, 'wrap_angel:')}: elements[2].wrap_angel: unknown key "
        "'wrap_angel' (did you mean 'wrap_angle'?)",
        "    wrap_angel: 180 deg",
    ]
    # a run of a scenario on that line: the first problem, its line quoted last
    code, err = _run(capsys, "run", scen, "-o", tmp_path / "out", "-q")
    first, quoted = err.rstrip("\n").split("\n")
    assert (
        code == 2
        and "elements[2].radus: unknown key 'radus' (did you mean 'radius'?) (and 1 more problem"
        in first
        and quoted == "    radus: 0.10 m"
    )


def test_misspelt_keys_in_a_sweep_file(tmp_path, capsys):
    sweep = (REPO / "sweeps" / "quickstart.yaml").read_text(encoding="utf-8")
    sweep = sweep.replace(
        "../scenarios/quickstart.yaml", str(REPO / "scenarios" / "quickstart.yaml")
    )
    sw = tmp_path / "sw.yaml"
    sw.write_text(
        sweep.replace("seeds: 2", "seedz: 2").replace(
            "values: [3 m/s, 5 m/s]", "vaules: [3 m/s, 5 m/s]"
        )
    )
    code, err = _run(capsys, "validate", sw)
    assert code == 2
    lines = err.rstrip("\n").split("\n")
    assert lines[0] == (
        f"{sw}: line {_line_no(sw, 'vaules:')}: axes[0].vaules: unknown key "
        "'vaules' (did you mean 'values'?)"
    )
    assert lines[1].startswith("    - {name: top_speed") and "vaules:" in lines[1]
    assert lines[2:] == [
        f"{sw}: line {_line_no(sw, 'seedz:')}: seedz: unknown key 'seedz' "
        "(did you mean 'seed' or 'seeds'?)",
        "    seedz: 2",
    ]
    assert "missing required key" not in err
    code, err = _run(capsys, "sweep", sw, "-o", tmp_path / "out")
    assert code == 2 and err.startswith(f"error: {sw}: line ") and "'vaules'" in err


def test_no_close_match_no_suggestion(tmp_path, capsys):
    scen = _files(tmp_path, scen_edit=lambda s: s.replace("seed: 1\n", "seed: 1\nzz_frob: 3\n"))
    code, err = _run(capsys, "validate", scen)
    assert code == 2
    first, quoted = err.rstrip("\n").split("\n")
    assert re.fullmatch(
        rf"{re.escape(str(scen))}: line \d+: zz_frob: unknown key 'zz_frob'", first
    ), first
    assert quoted == "    zz_frob: 3" and "did you mean" not in err


def test_data_not_from_the_file_has_no_line(tmp_path):
    """The Python API with a mapping: the message without a line (there is no file)."""
    import yaml

    from r2rsim import load_line

    d = yaml.safe_load((REPO / "lines" / "pet_film_line.yaml").read_text())
    d["web"]["thicknes"] = d["web"].pop("thickness")
    with pytest.raises(InputError) as exc:
        load_line(d)
    assert str(exc.value) == (
        "<line>: web.thicknes: unknown key 'thicknes' (did you mean 'thickness'?)"
    )


def test_allowed_keys_follow_the_schema():
    assert {"duration", "line", "programme"} <= allowed_keys(Scenario, ())
    # a discriminated union: the member the error's location names
    idler = allowed_keys(Line, ("elements", 1, "idler"))
    assert {"radius", "wrap_angle"} <= idler and "roll" not in idler
    assert "torque_max" in allowed_keys(Line, ("elements", 0, "unwind", "drive"))
    assert suggestion("durations", {"duration", "line"}) == ["duration"]
    assert suggestion("radius", {"radius"}, present={"radius"}) is None
    assert suggestion("zz", {"duration"}) is None
