"""``r2rsim list channels`` of a scenario file: exactly the columns a run of it writes (the
scenario's set-point, splice-joint and fault-label columns too), without simulating; of a
line file as before; anything else refused with one message naming the file."""

from __future__ import annotations

import pandas as pd
import pyarrow.parquet as pq
import pytest

from r2rsim.cli import main

from conftest import REPO


def _listed(capsys, path) -> list[str]:
    assert main(["list", "channels", str(path)]) == 0
    rows = capsys.readouterr().out.splitlines()
    assert rows[0].split() == ["channel", "unit", "description"]
    return [r.split()[0] for r in rows[1:]]


@pytest.mark.parametrize(
    "scenario", ["quickstart.yaml", "torque_modes.yaml", "roll_variability.yaml"]
)
def test_scenario_channels_are_the_columns_of_its_run(tmp_path, capsys, scenario):
    path = REPO / "scenarios" / scenario
    listed = _listed(capsys, path)
    out = tmp_path / "run"
    assert main(["run", str(path), "-o", str(out), "--duration", "1 s", "-q"]) == 0
    capsys.readouterr()
    channels = pd.read_parquet(out / "channels.parquet")
    assert listed == list(channels.channel)
    [part] = (out / "samples").glob("run_id=*/part-*.parquet")
    written = ["run_id"] + pq.read_schema(part).names  # run_id: the hive partition key
    assert sorted(listed) == sorted(written)
    assert any(c.startswith("label.ch.") for c in listed)
    assert any(c.startswith("sp.") for c in listed)


def test_scenario_dependent_columns(capsys):
    """What a line's listing cannot know: a programme's draw set-point, a varied spliced
    web's joint slots."""
    torque = _listed(capsys, REPO / "scenarios" / "torque_modes.yaml")
    line = _listed(capsys, REPO / "lines" / "pet_film_line_torque_modes.yaml")
    assert set(torque) - set(line) == {"sp.swrapB.draw"}
    varied = _listed(capsys, REPO / "scenarios" / "roll_variability.yaml")
    line = _listed(capsys, REPO / "lines" / "newsprint_line.yaml")
    assert {c for c in set(varied) - set(line)} == {
        f"state.splice_joint{i}.{q}" for i in (3, 4) for q in ("lead_m", "span_index")
    }


@pytest.mark.parametrize(
    "text,words",
    [
        ("name: x\naxes: []\n", "this is a sweep file"),
        ("name: x\nfoo: 1\n", "neither a line file (elements: ...) nor a scenario (line: ...)"),
    ],
)
def test_neither_line_nor_scenario(tmp_path, capsys, text, words):
    f = tmp_path / "other.yaml"
    f.write_text(text)
    assert main(["list", "channels", str(f)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"error: {f}: ") and words in err and len(err.splitlines()) == 1
