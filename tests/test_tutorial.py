"""docs/tutorial.md is executed as written: its Python blocks in order, in one namespace, from
a directory that looks like the root of a checkout (lines/, scenarios/, sweeps/), with the
first benchmark's data home shared with the other tests."""

from __future__ import annotations

import re

import pytest

from conftest import REPO

pytest.importorskip("matplotlib")  # the [test] extra installs it; the tutorial draws

TUTORIAL = REPO / "docs" / "tutorial.md"


def python_blocks(text: str) -> list[str]:
    """The ```python fenced blocks of a Markdown text, in order."""
    return re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)


def test_the_tutorial_runs_as_written(tmp_path, monkeypatch, first_benchmark_home, capsys):
    for name in ("lines", "scenarios", "sweeps"):
        (tmp_path / name).symlink_to(REPO / name)
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("R2RSIM_DATA", str(first_benchmark_home))
    blocks = python_blocks(TUTORIAL.read_text(encoding="utf-8"))
    assert len(blocks) >= 5
    namespace: dict = {}
    for i, block in enumerate(blocks):
        exec(compile(block, f"{TUTORIAL.name}[block {i + 1}]", "exec"), namespace)
    out = capsys.readouterr().out
    # what the blocks claim: the line's elements, a 20 s run, the split, the table, the files
    assert "('reg_drive', 'driven')" in out
    assert "20 s simulated" in out
    assert "split 'seed': 6 train, 2 val, 32 test (30 faulty)" in out
    table = namespace["table"]
    assert set(table.index.get_level_values("condition")) >= {"OC1", "OC2", "all"}
    assert (table["n_runs"] > 0).all()
    assert ((table["roc_auc"] >= 0) & (table["roc_auc"] <= 1)).all()
    assert (tmp_path / "results/tutorial_pca/roc_auc_by_fault.png").stat().st_size > 10_000
    assert (tmp_path / "results/tutorial_pca/report.html").is_file()
