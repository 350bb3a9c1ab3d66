"""The self-contained HTML report of a ``r2rsim diagnose`` or ``r2rsim bench`` results
directory: the metrics tables and the figures as PNG data URIs, readable offline (no external
style sheet, script, font or image)."""

from __future__ import annotations

import base64
import html
import io
import os
import tempfile
from pathlib import Path
from typing import Any

import pandas as pd

from .._version import __version__
from ..dataset.paths import read_json
from ..errors import InputError
from ..evaluate.harness import METRICS, PRINTED_METRICS, fault_key
from ..evaluate.results import DATASETS_FILE, DATASETS_FILE_MAX_BYTES, REPORT_MARKER
from ._diagnostics import (
    _metric_rows,
    _predictions,
    _test_runs,
    _theta,
    fault_units,
    plot_mdm,
    plot_metric,
    plot_roc_pr,
    plot_statistic,
    results_kind,
    results_table,
)
from ._mpl import require_matplotlib

#: first line of every report: an existing file without it is not overwritten
MARKER = REPORT_MARKER
#: metrics drawn by condition and by fault, when the results have several of either
FIGURE_METRICS = ("far_ff", "pd", "dd_median_s", "roc_auc")
#: at most this many runs get a statistic plot (one per fault stratum)
STATISTIC_RUNS = 6
#: columns of the full table (the hashes go in the header)
FULL_COLUMNS = (
    "study",
    "label",
    "method",
    "split",
    "condition",
    "fault",
    "magnitude",
    "metric",
    "value",
    "ci_low",
    "ci_high",
    "n_runs",
)

CSS = """
body { font-family: sans-serif; margin: 2em; color: #222; }
table { border-collapse: collapse; font-size: 0.85em; margin: 0.5em 0 1.5em; }
th, td { border: 1px solid #ccc; padding: 0.2em 0.5em; text-align: right; }
th { background: #f0f0f0; }
td:nth-child(-n+4) { text-align: left; }
.scroll { overflow-x: auto; }
figure { margin: 1em 0; }
figure img { max-width: 100%; }
figcaption, .note { color: #555; font-size: 0.9em; }
"""


def write_report(results: str | Path, output: str | Path | None = None, datasets=None) -> Path:
    """Write a self-contained HTML report of a results directory.

    Parameters
    ----------
    results : str or Path
        A directory written by ``r2rsim diagnose`` (metrics.parquet, predictions.parquet) or
        ``r2rsim bench -o`` (results.parquet).
    output : str or Path, optional
        The HTML file; default ``<results>/report.html``. Its directory must exist; an
        existing file is replaced only if it is a report r2rsim wrote.
    datasets : path, sequence of paths or of Run, optional
        The test datasets a diagnose result was scored on: adds the ROC/PR curves and the
        statistic of a few test runs (the results directory holds no labels). Default: the
        datasets ``r2rsim diagnose`` recorded in ``datasets.json``, when they still exist.

    Returns
    -------
    Path
        The report, written atomically (a temporary file in its directory, then renamed).

    Raises
    ------
    InputError
        When ``results`` is not a results directory, the output cannot be written there, or
        matplotlib is missing.
    """
    require_matplotlib()
    src = Path(results)
    kind = results_kind(src)
    out = Path(output) if output is not None else src / "report.html"
    _check_output(out)
    table = results_table(src)
    missing_note = None
    if datasets is None and kind == "diagnose":
        datasets, missing_note = _recorded_datasets(src)
    preds = None
    if datasets is not None and kind == "diagnose":  # read once (labels only) for every figure
        preds = _predictions(src)  # read once for every figure
        datasets = list(_test_runs(datasets, preds["run_id"]).values())
    figures = _figures(src, kind, table, datasets, preds)
    if missing_note:
        figures.append(f"<p class='note'>{html.escape(missing_note)}</p>")
    body = [
        f"<h1>r2rsim {kind} report</h1>",
        _header(src, kind, table),
        "<h2>Summary</h2>",
        _summary(table),
        "<h2>Figures</h2>",
        *figures,
        "<h2>All results</h2>",
        f"<p class='note'>{len(table)} rows: every row of the results table.</p>",
        _table(_full(table), table_id="results"),
    ]
    _write_atomic(out, _page(f"r2rsim {kind} report: {src.name}", body))
    return out


def _recorded_datasets(src: Path) -> tuple[list[str] | None, str | None]:
    """The test datasets recorded by ``r2rsim diagnose`` (``datasets.json``), or None and a
    note saying which of them are gone (results written before the file existed have none)."""
    f = src / DATASETS_FILE
    if not f.is_file():
        return None, None
    try:
        recorded: Any = read_json(f, DATASETS_FILE_MAX_BYTES)  # checked below
        paths = recorded["test"]
        if not (isinstance(paths, list) and all(isinstance(p, str) for p in paths)):
            raise TypeError("'test' is not a list of paths")
    except (ValueError, KeyError, TypeError) as exc:
        raise InputError(f"{f}: not a datasets file written by r2rsim diagnose ({exc})") from exc
    gone = [p for p in paths if not Path(p).is_dir()]
    if gone or not paths:
        return None, (
            f"the test datasets recorded in {DATASETS_FILE} are not found "
            f"({', '.join(gone)}): name them with --data"
        )
    return paths, None


# --------------------------------------------------------------------------- content


def _header(src: Path, kind: str, table: pd.DataFrame) -> str:
    items = {
        "results": f"{src} ({'r2rsim diagnose' if kind == 'diagnose' else 'r2rsim bench'})",
        "methods": ", ".join(dict.fromkeys(table["series"])),
    }
    if "study" in table.columns:
        items["studies"] = ", ".join(dict.fromkeys(table["study"]))
    for col in ("params_sha256", "dataset_sha256"):
        if col in table.columns:
            items[col] = ", ".join(v[:12] for v in dict.fromkeys(table[col].astype(str)))
    theta = table[table["metric"] == "theta"]
    if len(theta):
        items["theta (M6, calibrated on the validation runs)"] = ", ".join(
            f"{s} {v:.6g}" for s, v in zip(theta["series"], theta["value"], strict=True)
        )
    items["written by"] = f"r2rsim {__version__}"
    rows = "".join(f"<li><b>{html.escape(k)}</b>: {html.escape(v)}</li>" for k, v in items.items())
    return f"<ul>{rows}</ul>"


def _summary(table: pd.DataFrame) -> str:
    """One row per method × condition × fault (magnitude rows left out), the main metrics as
    columns."""
    m = table[table["magnitude"].isna() & table["metric"].isin(PRINTED_METRICS)]
    keys = ["series", "condition", "fault"]
    wide = m.pivot_table(index=keys, columns="metric", values="value", aggfunc="first", sort=False)
    cols = [c for c in PRINTED_METRICS if c in wide.columns]
    wide = wide[cols].rename_axis(columns=None).reset_index().rename(columns={"series": "method"})
    desc = "; ".join(f"{c}: {METRICS[c].description}" for c in cols if c in METRICS)
    return (
        _table(wide, table_id="summary")
        + f"<p class='note'>{html.escape(desc)}</p>"
        + f"<p class='note'>{html.escape(_thresholds(table))}</p>"
    )


def _thresholds(table: pd.DataFrame) -> str:
    """Which threshold the columns without _cal use, per method (own_threshold column)."""
    if "own_threshold" not in table.columns:
        return "Columns without _cal: at each plug-in's own threshold; _cal: at theta."
    how = {"val": "recalibrated on the val runs at alpha", "fit": "as its fit set it"}
    by = (
        table.dropna(subset=["own_threshold"])
        .groupby("series", sort=False)["own_threshold"]
        .first()
    )
    parts = [f"{s}: {how.get(v, v)}" for s, v in by.items()]
    return (
        "Columns without _cal are at each plug-in's own threshold ("
        + "; ".join(parts)
        + "); _cal columns at theta, calibrated on the val runs at alpha."
    )


def _full(table: pd.DataFrame) -> pd.DataFrame:
    return table[[c for c in FULL_COLUMNS if c in table.columns]]


def _table(df: pd.DataFrame, table_id: str) -> str:
    # to_html escapes every cell and header (escape=True)
    text = df.to_html(
        index=False, na_rep="", border=0, table_id=table_id, float_format=lambda v: f"{v:.6g}"
    )
    return f"<div class='scroll'>{text}</div>"


def report_figures(results: str | Path, datasets=None) -> list:
    """The figures :func:`write_report` puts in the report of a results directory.

    Parameters
    ----------
    results : str or Path
        A directory written by ``r2rsim diagnose`` or ``r2rsim bench -o``.
    datasets : path, sequence of paths or of Run, optional
        The test datasets of a diagnose result, as :func:`write_report` takes them.

    Returns
    -------
    list of (str, matplotlib.figure.Figure)
        Each figure with its caption, in the report's order; a figure the results cannot
        give (a note in the report) is left out.
    """
    require_matplotlib()
    src = Path(results)
    kind = results_kind(src)
    table = results_table(src)
    if datasets is None and kind == "diagnose":
        datasets = _recorded_datasets(src)[0]
    preds = None
    if datasets is not None and kind == "diagnose":
        preds = _predictions(src)
        datasets = list(_test_runs(datasets, preds["run_id"]).values())
    return [
        item
        for item in _figures(src, kind, table, datasets, preds, render=_built)
        if isinstance(item, tuple)
    ]


def _built(caption: str, plot, *args, **kwargs):
    """``(caption, figure)``, or None for a figure these results cannot give."""
    try:
        return caption, plot(*args, **kwargs)
    except InputError:
        return None


def _figures(src: Path, kind: str, table: pd.DataFrame, runs, preds=None, render=None) -> list:
    """The figures as HTML; one that cannot be drawn from these results is a note.
    ``render(caption, plot, *args, **kwargs)`` makes each figure's entry (default: its
    HTML, :func:`_figure`)."""
    figure = render or _html_figure
    out = []
    for by in ("condition", "fault"):
        for metric in FIGURE_METRICS:
            if _n_levels(table, metric, by) > 1:
                out.append(figure(f"{metric} by {by}", plot_metric, table, metric, by))
    if (table["metric"].eq("pd") & table["magnitude"].notna()).any():
        out.append(
            figure(
                "detection probability by fault magnitude (MDM)",
                plot_mdm,
                table,
                units=fault_units(runs),
            )
        )
    if kind != "diagnose":
        return out
    if runs is None:
        out.append(
            "<p class='note'>ROC/PR curves and the statistic over time need the test "
            "datasets (their labels are not in the results directory): "
            "<code>r2rsim report RESULTS --data DATASET...</code></p>"
        )
        return out
    preds = _predictions(src) if preds is None else preds
    out.append(figure("ROC and PR curves of the scored test samples", plot_roc_pr, preds, runs))
    for rid in _example_runs(preds, runs):
        method = str(preds.loc[preds["run_id"] == rid, "method"].iloc[0])
        out.append(
            figure(
                f"statistic of run {rid}",
                plot_statistic,
                preds,
                runs,
                rid,
                theta=_theta(table, method),
            )
        )
    return out


def _n_levels(table: pd.DataFrame, metric: str, by: str) -> int:
    try:
        return _metric_rows(table, metric, by, None, None)[by].nunique()
    except InputError:
        return 0


def _example_runs(preds: pd.DataFrame, runs) -> list[str]:
    """The first test run of each fault (fault-free first), at most :data:`STATISTIC_RUNS`."""
    by_id = {r.run_id: r for r in runs}
    first: dict[str, str] = {}
    for rid in dict.fromkeys(preds["run_id"]):
        first.setdefault(fault_key(by_id[rid]), rid)
    return [first[k] for k in sorted(first, key=lambda k: (k != "none", k))][:STATISTIC_RUNS]


def _html_figure(caption: str, plot, *args, **kwargs) -> str:
    try:
        fig = plot(*args, **kwargs)
    except InputError as exc:
        return f"<p class='note'>{html.escape(caption)}: not drawn ({html.escape(exc.message)})</p>"
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, metadata={"Software": None})
    data = base64.b64encode(buf.getvalue()).decode("ascii")
    cap = html.escape(caption)
    return (
        f'<figure><img src="data:image/png;base64,{data}" alt="{cap}">'
        f"<figcaption>{cap}</figcaption></figure>"
    )


def _page(title: str, body: list[str]) -> str:
    return (
        f'{MARKER}\n<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        f"<title>{html.escape(title)}</title>\n<style>{CSS}</style>\n</head>\n<body>\n"
        + "\n".join(body)
        + "\n</body>\n</html>\n"
    )


# --------------------------------------------------------------------------- writing


def _check_output(out: Path) -> None:
    """Refuse an output whose directory is missing, a directory, or a file r2rsim did not
    write (a report replaces only an earlier report)."""
    if not out.parent.is_dir():
        raise InputError(f"{out}: the directory {out.parent} does not exist")
    if out.is_dir():
        raise InputError(f"{out}: is a directory; name the HTML file to write")
    if out.exists():
        with open(out, "rb") as f:
            if not f.read(len(MARKER)).startswith(MARKER.encode()):
                raise InputError(
                    f"{out}: exists and is not a report r2rsim wrote; remove it "
                    f"or choose another output"
                )


def _write_atomic(out: Path, text: str) -> None:
    """Write to a temporary file next to ``out`` and rename it: a reader never sees half a
    report, and a failure leaves the previous one."""
    fd, tmp = tempfile.mkstemp(dir=out.parent, prefix=f".{out.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.chmod(tmp, 0o644)  # mkstemp's 0600 is for the temporary file only
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
