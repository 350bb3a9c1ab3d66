"""docs/keys.md: every key of the line, scenario and sweep files, generated from the schema
models (r2rsim.schema.reference_markdown, `r2rsim schema --markdown`).

The page must be the generator's text (regenerate it with `r2rsim schema --markdown >
docs/keys.md`), every key must have a description of its own, and the tables must say what
the models accept: types with SI units, defaults (those made by a factory too), links that
lead to a table.
"""

from __future__ import annotations

import json
import re

import pytest

from r2rsim.cli import main
from r2rsim.schema import json_schema, reference_markdown
from r2rsim.schema._reference import undocumented

from conftest import REPO

PAGE = REPO / "docs" / "keys.md"


@pytest.fixture(scope="module")
def text():
    return reference_markdown()


def _row(text: str, table: str, key: str) -> list[str]:
    """The cells of ``key``'s row in the table under ``### <table>``."""
    section = text.split(f"### {table}\n", 1)[1].split("\n### ", 1)[0]
    for line in section.splitlines():
        if line.startswith(f"| `{key}` |"):
            return [c.strip() for c in line.strip("|").split(" | ")]
    raise AssertionError(f"no row {key} under {table}")


def test_the_page_is_the_generated_reference(text):
    assert PAGE.read_text(encoding="utf-8") == text, (
        "docs/keys.md is out of date: run `r2rsim schema --markdown > docs/keys.md`"
    )


def test_every_key_has_a_description_of_its_own():
    assert undocumented() == []


def test_rows_say_what_the_models_accept(text):
    assert _row(text, "line: Idler", "radius") == [
        "`radius`",
        "length [m]",
        "required",
        "roller radius [m]",
    ]
    assert _row(text, "line: Friction", "viscous")[1:3] == ["viscous torque [N*m*s]", "`0.0`"]
    # defaults made by a factory, which the JSON Schema leaves out
    assert _row(text, "sweep: Sweep", "axes")[2] == "`[]`"
    assert _row(text, "line: Unwind", "drive")[2] == "its defaults"
    # a dimensionless quantity has no unit; integer bounds are exact
    assert _row(text, "line: SpeedPI", "draw")[1] == "dimensionless"
    assert _row(text, "scenario: Scenario", "seed")[1] == "integer (≥ 0, ≤ 18446744073709551615)"
    assert _row(text, "scenario: ProgrammeStep", "tension")[1] == "mapping of ids to force [N]"
    assert _row(text, "sweep: Sweep", "set")[1] == "mapping of paths to any"
    assert _row(text, "scenario: Initial", "state")[1:3] == ["`steady` \\| `nominal`", '`"steady"`']


def test_every_link_leads_to_a_table(text):
    anchors = {
        re.sub(r"[^a-z0-9 -]", "", h.lower()).replace(" ", "-")
        for h in re.findall(r"^### (.+)$", text, flags=re.M)
    }
    links = set(re.findall(r"\]\(#([^)]+)\)", text))
    assert links and links <= anchors, sorted(links - anchors)
    # every definition of each file's schema has its table
    for kind in ("line", "scenario", "sweep"):
        for name in json.loads(json_schema(kind)).get("$defs", {}):
            assert f"### {kind}: {name}\n" in text


def test_a_described_quantity_keeps_its_unit_for_editors():
    """A field's own description replaces its quantity type's in the JSON Schema; the
    dimension and SI unit stay (x-dimension, x-unit)."""
    radius = json.loads(json_schema("line"))["$defs"]["Idler"]["properties"]["radius"]
    assert radius["description"] == "roller radius [m]"
    assert (radius["x-dimension"], radius["x-unit"]) == ("length", "m")


def test_the_cli_prints_the_reference(capsys, text):
    assert main(["schema", "--markdown"]) == 0
    assert capsys.readouterr().out == text
    assert main(["schema", "--markdown", "sweep"]) == 0
    out = capsys.readouterr().out
    assert "## Sweep file" in out and "## Line file" not in out
    assert main(["schema", "line"]) == 0
    assert json.loads(capsys.readouterr().out)["title"] == "Line"


@pytest.mark.parametrize(
    "argv, words",
    [
        (["schema"], "name one of line, scenario, sweep"),
        (["schema", "line", "sweep"], "name one of line, scenario, sweep"),
        (["schema", "lines"], "unknown file kind 'lines'"),
        (["schema", "--markdown", "bogus"], "unknown file kind 'bogus'"),
    ],
)
def test_the_cli_refuses_what_it_cannot_print(capsys, argv, words):
    assert main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and words in captured.err
