"""The README's *First benchmark*: the table it shows is what `r2rsim diagnose` prints on the
first benchmark's data (the values of results/pca/metrics.csv, to the digits shown)."""

from __future__ import annotations

import re

import pandas as pd
import pytest

from r2rsim.cli import main

from conftest import REPO

README = REPO / "README.md"
COLUMNS = {
    "n_runs": "n_runs",
    "far_ff": "far_ff",
    "dr": "dr",
    "pd": "pd",
    "DD med s": "dd_median_s",
    "roc_auc": "roc_auc",
}


def readme_table() -> pd.DataFrame:
    """The pooled rows of the README's first-benchmark table."""
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## First benchmark") : text.index("## Install")]
    block = re.search(r"```\n(condition fault .*?)```", section, flags=re.S).group(1)
    rows = []
    for line in block.splitlines()[1:]:
        cells = line.split()
        if cells[0] == "all":
            cells = cells[1:]
        rows.append(
            {"fault": cells[0], **dict(zip(COLUMNS.values(), map(float, cells[1:]), strict=True))}
        )
    return pd.DataFrame(rows).set_index("fault")


def test_the_readme_table_is_what_diagnose_gives(first_benchmark_home, tmp_path, capsys):
    shown = readme_table()
    assert len(shown) == 3
    out = tmp_path / "pca"
    assert (
        main(
            [
                "diagnose",
                "--method",
                "pca",
                "--data",
                str(first_benchmark_home / "first_benchmark"),
                "-o",
                str(out),
            ]
        )
        == 0
    )
    metrics = pd.read_csv(out / "metrics.csv")
    pooled = metrics[(metrics["condition"] == "all") & metrics["magnitude"].isna()]
    for fault, row in shown.iterrows():
        got = pooled[pooled["fault"] == fault].set_index("metric")
        assert int(got["n_runs"].max()) == row["n_runs"]
        for metric in ("far_ff", "dr", "pd", "dd_median_s", "roc_auc"):
            value = got.loc[metric, "value"]
            assert float(f"{value:.3g}") == pytest.approx(row[metric], abs=0), (fault, metric)
    assert (out / "predictions.parquet").is_file()
    assert main(["report", str(out)]) == 0
    assert (out / "report.html").stat().st_size > 50_000
