"""docs/sweeps.md against the code.

* Every ```sql block of the page runs on a fresh run of sweeps/quickstart.yaml. The page's
  queries read ``runs/quickstart_sweep/`` (where ``r2rsim sweep sweeps/quickstart.yaml``
  writes from the repository root); this test replaces that prefix by its own directory.
  A markdown table right after a query is the result the page shows, and must be the result.
* The numbers mean what the page says: the load cell's error is its 0.5 N noise before the
  offset's onset and the swept offset after it, and the in-loop offset moves the true
  tension the other way.
* Every sweep file on the page is valid, and its copy of sweeps/quickstart.yaml is the file.
* The key tables list exactly the keys of the Sweep, Axis and Range models, with their
  defaults and their schema descriptions, so the page cannot fall behind the schema.
"""

from __future__ import annotations

import json
import math
import re

import pytest
import yaml

from r2rsim.schema import paths as _paths
from r2rsim.schema.sweep import Axis, Range, Sweep
from r2rsim.sweep import plan_sweep, run_sweep

from conftest import REPO

duckdb = pytest.importorskip("duckdb")  # a test extra, not an r2rsim dependency

DOC = REPO / "docs" / "sweeps.md"
PREFIX = "runs/quickstart_sweep/"  # the page's dataset path, replaced by the test's

# sweeps/quickstart.yaml and its line: lc_rewind has noise 0.5 N and is read by the
# rewind_tension loop (set-point 260 N); 10 s at 200 Hz, warm-up 2 s, onset 6 s, offsets
# of -10 and +10 N, each at two top speeds and with seeds 0 and 1, and fault-free runs at
# both speeds with the same seeds
NOISE_N = 0.5
SETPOINT_N = 260.0
RATE_HZ, WARMUP_S, ONSET_S, DURATION_S = 200, 2.0, 6.0, 10.0
RUNS_PER_OFFSET = 4
SEEDS = 2
# Tolerances. Runs with the same seed have the same noise samples (docs/sweeps.md §3), so
# an offset's 4 runs hold 2 x 800 independent noise samples per phase: the standard error of
# a mean error is 0.5 N / sqrt(1600) = 0.0125 N, that of an RMS about 0.5 N / sqrt(3200) =
# 0.009 N. TOL_MEAN (8 standard errors, 1 % of the offset) leaves room for the deterministic
# part of meas - true: the 2 ms load-cell filter's lag while the tension moves and at the
# offset's step (docs/dataset.md §12; a few hundredths of a newton here).
TOL_MEAN = 0.1
TOL_RMS = 0.05
# the page's tables show values rounded by the query; allow the last digit to differ
TOL_TABLE = 0.002


def _doc() -> str:
    return DOC.read_text(encoding="utf-8")


def _blocks(text: str, lang: str) -> list[tuple[str, int]]:
    """The ```lang blocks of ``text``: (body, position just after the block)."""
    return [
        (m.group(1), m.end()) for m in re.finditer(rf"^```{lang}\n(.*?)^```\n", text, re.M | re.S)
    ]


def _table_rows(lines: list[str]) -> list[list[str]]:
    rows = []
    for line in lines:
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if all(re.fullmatch(r":?-+:?", c) for c in cells):
            continue  # the header's separator
        rows.append(cells)
    return rows


def _table_after(text: str, pos: int) -> list[list[str]] | None:
    """The markdown table that follows ``pos`` after blank lines only (header first)."""
    lines = text[pos:].split("\n")
    i = 0
    while i < len(lines) and not lines[i].strip():
        i += 1
    table = []
    while i < len(lines) and lines[i].startswith("|"):
        table.append(lines[i])
        i += 1
    return _table_rows(table) if table else None


def _table_under(text: str, marker: str) -> list[list[str]]:
    """The first table after the line that starts with ``marker`` (a heading, a sentence),
    before the next heading."""
    lines = text[text.index(f"\n{marker}") + 1 :].split("\n")
    table = []
    for line in lines[1:]:
        if line.startswith("|"):
            table.append(line)
        elif table or line.startswith("#"):
            break
    assert table, f"no table under '{marker}'"
    return _table_rows(table)


# --------------------------------------------------------------------------- the queries
@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("sweep_docs") / "quickstart_sweep"
    summary = run_sweep(REPO / "sweeps" / "quickstart.yaml", output=out, workers=0)
    assert summary.ok and summary.done == 12, summary.format()
    return out


@pytest.fixture(scope="module")
def queries(dataset):
    """Every sql block of the page: (sql, result DataFrame, the table the page shows)."""
    text = _doc()
    out = []
    for sql, end in _blocks(text, "sql"):
        assert PREFIX in sql, f"a query of docs/sweeps.md does not read {PREFIX}:\n{sql}"
        df = duckdb.sql(sql.replace(PREFIX, dataset.as_posix() + "/")).df()
        out.append((sql, df, _table_after(text, end)))
    return out


def _query(queries, *columns):
    """The result of the page's query whose columns include ``columns``."""
    found = [df for _, df, _ in queries if set(columns) <= set(df.columns)]
    assert len(found) == 1, f"docs/sweeps.md should have one query giving {columns}"
    return found[0]


def test_the_page_has_its_queries(queries):
    assert len(queries) >= 3


def _same_cell(shown: str, value) -> bool:
    if isinstance(value, bool) or type(value).__name__ == "bool_":
        return shown == str(bool(value)).lower()
    if isinstance(value, (int, float)) or hasattr(value, "dtype"):
        return math.isclose(float(shown), float(value), rel_tol=0, abs_tol=TOL_TABLE)
    return shown == str(value)


def test_queries_give_the_tables_the_page_shows(queries):
    for sql, df, table in queries:
        if table is None:
            continue
        header, rows = table[0], table[1:]
        assert header == list(df.columns), sql
        assert len(rows) == len(df), (sql, df)
        for shown, (_, row) in zip(rows, df.iterrows(), strict=True):
            for cell, col in zip(shown, header, strict=True):
                assert _same_cell(cell, row[col]), (sql, col, cell, row[col])


def test_sensor_error_is_its_noise_then_the_offset(queries):
    df = _query(queries, "offset_N", "faulty", "n", "mean_error_N", "rms_error_N")
    assert sorted(set(df["offset_N"])) == [-10.0, 10.0]
    assert len(df) == 4
    per_run = {
        False: round((ONSET_S - WARMUP_S) * RATE_HZ),  # 2 s .. 5.995 s
        True: round((DURATION_S - ONSET_S) * RATE_HZ) + 1,
    }  # 6 s .. 10 s
    for _, r in df.iterrows():
        faulty, offset = bool(r["faulty"]), r["offset_N"]
        assert r["n"] == RUNS_PER_OFFSET * per_run[faulty]
        if faulty:
            assert abs(r["mean_error_N"] - offset) < TOL_MEAN
            assert abs(r["rms_error_N"] - math.hypot(offset, NOISE_N)) < TOL_MEAN
        else:
            assert abs(r["mean_error_N"]) < TOL_MEAN
            assert abs(r["rms_error_N"] - NOISE_N) < TOL_RMS


def test_in_loop_offset_moves_the_true_tension_the_other_way(queries):
    df = _query(queries, "run_id", "offset_N", "top_speed_m_s", "true_tension_N", "at_end_N")
    assert len(df) == RUNS_PER_OFFSET * 2
    for _, r in df.iterrows():
        target = SETPOINT_N - r["offset_N"]  # where the loop takes the true tension
        # between the set-point and the target, and closer to the target at the end
        assert min(SETPOINT_N, target) <= r["true_tension_N"] <= max(SETPOINT_N, target)
        assert abs(r["at_end_N"] - target) < abs(r["true_tension_N"] - target)
    # noise never enters the loop: the seeds of a combination have the same true tension
    for _, g in df.groupby(["offset_N", "top_speed_m_s"]):
        assert len(g) == SEEDS
        assert g["true_tension_N"].nunique() == 1 and g["at_end_N"].nunique() == 1


def test_no_run_of_the_quickstart_sweep_failed(queries):
    assert len(_query(queries, "run_id", "seed", "why")) == 0


# --------------------------------------------------------------------------- sweep files
def _page_sweeps() -> list[dict]:
    sweeps = []
    for body, _ in _blocks(_doc(), "yaml"):
        data = yaml.safe_load(body)
        if isinstance(data, dict) and "scenario" in data and "name" in data:
            sweeps.append(data)
    return sweeps


#: the sweep files of the page: (combinations, runs) as the page says
EXPECTED = {"quickstart_sweep": (6, 12), "offset_study": (6, 12), "baseline_demo": (6, 6)}


def test_the_sweep_files_on_the_page_are_valid(tmp_path):
    sweeps = _page_sweeps()
    assert {s["name"] for s in sweeps} == set(EXPECTED)
    for data in sweeps:
        # the page's files live in sweeps/: their scenario is found from there
        data = dict(data, scenario=str((REPO / "sweeps" / data["scenario"]).resolve()))
        path = tmp_path / f"{data['name']}.yaml"
        path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
        plan = plan_sweep(path)
        assert (plan.n_combinations, len(plan.runs)) == EXPECTED[data["name"]], data["name"]


def test_the_page_shows_the_shipped_quickstart_sweep():
    shown = next(s for s in _page_sweeps() if s["name"] == "quickstart_sweep")
    shipped = yaml.safe_load((REPO / "sweeps" / "quickstart.yaml").read_text(encoding="utf-8"))
    assert shown == shipped


def test_the_example_paths_lead_somewhere():
    """The paths of the page's table in §2 exist in the quick-start scenario and line (with
    the quick-start sweep's fault), or lead to a mapping the sweep makes (solver.*)."""
    text = _doc()
    rows = _table_under(text, "These paths work")[1:]
    paths = [p for row in rows for p in re.findall(r"`([^`]+)`", row[0])]
    assert len(paths) >= 10
    shipped = yaml.safe_load((REPO / "sweeps" / "quickstart.yaml").read_text(encoding="utf-8"))
    scenario = yaml.safe_load((REPO / "scenarios" / "quickstart.yaml").read_text())
    scenario.update(shipped["set"])
    line = yaml.safe_load((REPO / "lines" / "pet_film_line.yaml").read_text())
    made = {"solver.rtol", "solver.max_steps_per_s"}  # quickstart.yaml has no solver:
    for p in paths:
        root, parts = _paths.split_root(p)
        data = line if root == "line" else scenario
        if p in made:
            with pytest.raises(_paths.PathError):
                _paths.get_value(data, parts)
            _paths.resolve(data, parts, create=True)
        else:
            _paths.get_value(data, parts)


# --------------------------------------------------------------------------- key tables
def _norm(s: str) -> str:
    return " ".join(s.replace("`", "").replace("'", "").split())


@pytest.mark.parametrize(
    "model,heading",
    [
        (Sweep, "### 1.1 Keys of the sweep file"),
        (Axis, "### 1.2 Keys of an axis"),
        (Range, "### 1.3 Keys of a range"),
    ],
)
def test_key_table_lists_every_key_of_the_model(model, heading):
    table = _table_under(_doc(), heading)
    assert table[0] == ["key", "type", "default", "meaning"]
    rows = {row[0].strip("`"): row for row in table[1:]}
    assert set(rows) == set(model.model_fields), heading
    for key, field in model.model_fields.items():
        _, _, default, meaning = rows[key]
        if field.is_required():
            assert default == "required", key
        else:
            value = field.get_default(call_default_factory=True)
            shown = (
                "none"
                if value is None
                else f"`{value if isinstance(value, str) else json.dumps(value)}`"
            )
            assert default == shown, key
        if field.description:
            assert _norm(field.description) in _norm(meaning), key
