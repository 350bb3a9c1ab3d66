"""The diagnostics figures and the HTML report (``r2rsim report``) on real, small diagnose and
bench results: every figure is checked for what it shows (the numbers of the results table,
the faults of the datasets), the report for being readable offline and holding every row."""

from __future__ import annotations

import base64
import html
import json
import math
import shutil
import sys
import textwrap
from html.parser import HTMLParser
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd
import pytest
from matplotlib.container import BarContainer
from sklearn.metrics import roc_auc_score

import r2rsim
from r2rsim.cli import main
from r2rsim.errors import InputError
from r2rsim.report import plot_mdm, plot_metric, plot_roc_pr, plot_statistic, write_report

from conftest import REPO

matplotlib.use("Agg")

THESIS = REPO / "scenarios" / "thesis"
DURATION = 21.0  # faults from 20 s: the sensor-A degradation ramps in over 10 s, so 1 s of it
TRAIN = [("h1", "oc1_nominal", 1), ("h2", "oc1_nominal", 2), ("g1", "oc2_nominal", 11)]
VAL = [("h3", "oc1_nominal", 3), ("g2", "oc2_nominal", 12)]
TEST = [
    ("h4", "oc1_nominal", 4),
    ("g3", "oc2_nominal", 13),
    ("o1", "sensor_a_offset_P05", 5),
    ("o2", "sensor_a_offset_N05", 6),
    ("d05", "sensor_a_degradation_P05_OC1", 20),
    ("d10", "sensor_a_degradation_P10_OC1", 22),
    ("d20", "sensor_a_degradation_P20_OC1", 24),
    ("e10", "sensor_a_degradation_P10_OC2", 23),
]
METHODS = ("pca", "residual")


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """Healthy OC1/OC2 runs (train, val), and test runs: healthy, sensor-A offsets of ±6.5 N
    and sensor-A gain degradations of 0.05, 0.1 and 0.2 (OC1) and 0.1 (OC2)."""
    d = tmp_path_factory.mktemp("report_data")
    for name, scen, seed in TRAIN + VAL + TEST:
        r2rsim.run_scenario(THESIS / f"{scen}.yaml", output=d / name, seed=seed, duration=DURATION)
    return d


def scored_sets(data):
    return [str(data / name) for name, _, _ in TEST]


@pytest.fixture(scope="module")
def diagnosed(data):
    """One diagnose directory per method (persistence 5, so that some faults are missed)."""
    out = {}
    for method in METHODS:
        out[method] = data / f"out_{method}"
        code = main(
            [
                "diagnose",
                "--method",
                method,
                "--train",
                *[str(data / n) for n, _, _ in TRAIN],
                "--val",
                *[str(data / n) for n, _, _ in VAL],
                "--test",
                *scored_sets(data),
                "--n-boot",
                "20",
                "-m",
                "5",
                "-o",
                str(out[method]),
            ]
        )
        assert code == 0
    return out


@pytest.fixture(scope="module")
def benched(tmp_path_factory):
    """``r2rsim bench -o``: two methods on OC1 runs with the sensor-A degradation at three
    magnitudes."""
    d = tmp_path_factory.mktemp("report_bench")
    spec = d / "spec.yaml"
    test = "\n".join(
        f"      - {{scenario: {THESIS}/{s}.yaml, seeds: [{seed}]}}"
        for _, s, seed in TEST
        if "OC2" not in s and "oc2" not in s
    )
    spec.write_text(
        textwrap.dedent(f"""\
        name: report_tiny
        duration: {DURATION} s
        studies:
          - name: reg
            train: [{{scenario: {THESIS}/oc1_nominal.yaml, seeds: [1, 2]}}]
            val: [{{scenario: {THESIS}/oc1_nominal.yaml, seeds: [3]}}]
            test:
        """)
        + test
        + textwrap.dedent("""
        methods: [{method: pca}, {method: residual}]
        evaluation: {n_boot: 20, persistence: 5}
        """),
        encoding="utf-8",
    )
    assert main(["bench", str(spec), "--workdir", str(d / "work"), "-o", str(d / "res")]) == 0
    return d / "res"


def metrics(results_dir):
    return pd.read_parquet(results_dir / "metrics.parquet")


def value(table, metric, condition="all", fault="all", magnitude=None):
    sel = (table.metric == metric) & (table.condition == condition) & (table.fault == fault)
    sel &= table.magnitude.isna() if magnitude is None else table.magnitude == magnitude
    assert sel.sum() == 1, (metric, condition, fault, magnitude)
    return float(table.loc[sel, "value"].iloc[0])


def by_gid(ax, gid):
    found = [a for a in ax.get_children() if a.get_gid() == gid]
    assert len(found) == 1, gid
    return found[0]


def x_span(patch):
    """The data x range of an axvspan (a Polygon in matplotlib 3.7, a Rectangle later)."""
    ext = patch.get_patch_transform().transform_path(patch.get_path()).get_extents()
    return ext.x0, ext.x1


# --------------------------------------------------------------------------- figures


@pytest.mark.parametrize("run", ["d10", "o2", "h4"])
def test_statistic_shows_threshold_fault_windows_and_alarms(data, diagnosed, run):
    ds = data / run
    rid = pd.read_parquet(ds / "runs.parquet")["run_id"].iloc[0]
    fig = plot_statistic(diagnosed["pca"], scored_sets(data), run_id=rid)
    assert len(fig.axes) == 1
    ax = fig.axes[0]
    p = pd.read_parquet(diagnosed["pca"] / "predictions.parquet").query("run_id == @rid")
    stat_line = next(li for li in ax.get_lines() if li.get_label().startswith("statistic"))
    np.testing.assert_array_equal(stat_line.get_xdata(), p["t_s"])
    np.testing.assert_array_equal(stat_line.get_ydata(), p["statistic"])
    # the dashed line is the threshold the harness calibrated on the validation runs
    theta = by_gid(ax, "theta").get_ydata()
    assert theta[0] == theta[1] == value(metrics(diagnosed["pca"]), "theta")
    # the alarm markers sit on the alarmed samples
    alarms = by_gid(ax, "alarms")
    np.testing.assert_array_equal(alarms.get_xdata(), p.loc[p.alarm, "t_s"])
    assert 0 < len(alarms.get_xdata()) < len(p)
    # the warm-up (label.score_mask false) is greyed: scenario warmup 5 s
    warm = [a for a in ax.patches if a.get_label() == "warm-up (not scored)"]
    assert len(warm) == 1 and x_span(warm[0]) == pytest.approx((0.0, 5.0), abs=1e-9)
    # one shaded window per fault, from its onset to its end (the end of the run: it lasts)
    faults = pd.read_parquet(ds / "faults.parquet")
    spans = [a for a in ax.patches if str(a.get_gid()).startswith("fault:")]
    assert len(spans) == len(faults) == (0 if run == "h4" else 1)
    for span, f in zip(spans, faults.itertuples(), strict=True):
        assert span.get_gid() == f"fault:{f.fault_id}" and math.isnan(f.end_t_s)
        assert x_span(span) == pytest.approx((f.onset_t_s, DURATION), abs=1e-12)


def test_statistic_shades_a_fault_that_ends(data, tmp_path):
    """A fault with an end is shaded from its onset to its end, not to the end of the run."""
    scen = tmp_path / "ends.yaml"
    text = (THESIS / "sensor_a_offset_P05.yaml").read_text(encoding="utf-8")
    scen.write_text(
        text.replace("line: ../../", f"line: {REPO}/")
        .replace("magnitude: 6.5 N}", "magnitude: 6.5 N, end: 16 s}")
        .replace("onset: 20 s", "onset: 12 s")
    )
    r2rsim.run_scenario(scen, output=tmp_path / "ends", seed=7, duration=DURATION)
    assert (
        main(
            [
                "diagnose",
                "--method",
                "residual",
                "--train",
                str(data / "h1"),
                "--test",
                str(tmp_path / "ends"),
                "--n-boot",
                "0",
                "-o",
                str(tmp_path / "res"),
            ]
        )
        == 0
    )
    faults = pd.read_parquet(tmp_path / "ends" / "faults.parquet")
    assert faults[["onset_t_s", "end_t_s"]].to_numpy().tolist() == [[12.0, 16.0]]
    ax = plot_statistic(tmp_path / "res", tmp_path / "ends").axes[0]
    spans = [a for a in ax.patches if str(a.get_gid()).startswith("fault:")]
    assert len(spans) == 1 and x_span(spans[0]) == pytest.approx((12.0, 16.0), abs=1e-12)


def test_roc_pr_ranks_nan_statistics_lowest(data, diagnosed, tmp_path):
    """A plug-in that cannot score some samples (nan) still gets curves: those samples rank
    below every finite statistic, as in the harness."""
    preds = pd.read_parquet(diagnosed["residual"] / "predictions.parquet")
    preds.loc[preds.index[::7], "statistic"] = np.nan
    fig = plot_roc_pr(preds, scored_sets(data))
    roc = by_gid(fig.axes[0], "roc:residual")
    # the same area, computed independently from the labels of the scored samples
    truth = []
    for ds in scored_sets(data):
        s = pd.read_parquet(
            next((Path(ds) / "samples").rglob("*.parquet")),
            columns=["k", "label.is_faulty", "label.score_mask"],
        )
        rid = pd.read_parquet(Path(ds) / "runs.parquet")["run_id"].iloc[0]
        truth.append(s.assign(run_id=rid))
    merged = preds.merge(pd.concat(truth), on=["run_id", "k"])
    merged = merged[merged["label.score_mask"]]
    stat = merged["statistic"].to_numpy()
    stat = np.where(np.isnan(stat), np.nanmin(stat) - 1.0, stat)
    expected = roc_auc_score(merged["label.is_faulty"].to_numpy(bool), stat)
    assert np.isnan(merged["statistic"]).sum() > 100
    assert trapezoid(roc.get_xdata(), roc.get_ydata()) == pytest.approx(expected, abs=1e-9)


def test_statistic_defaults_to_a_faulty_run_and_refuses_unknown_runs(data, diagnosed):
    fig = plot_statistic(diagnosed["residual"], scored_sets(data))
    assert "sensor_a_offset_P05" in fig.axes[0].get_title()  # the first faulty test run
    with pytest.raises(InputError, match="no run 'nosuch'"):
        plot_statistic(diagnosed["residual"], scored_sets(data), run_id="nosuch")
    with pytest.raises(InputError, match="is in none of the datasets"):
        plot_statistic(diagnosed["residual"], scored_sets(data)[:2])


def steps_area(x, y):
    """Area under the PR steps drawn with drawstyle steps-post (recall decreasing)."""
    return float(-np.sum(np.diff(x) * y[:-1]))


def trapezoid(x, y):
    return float(np.sum(np.diff(x) * (y[1:] + y[:-1]) / 2))


@pytest.mark.parametrize(
    "condition, fault",
    [("all", "all"), ("OC1", "sensor.gain:sensor_A"), ("all", "sensor.offset:sensor_A")],
)
def test_roc_pr_areas_are_the_metrics_table(data, diagnosed, condition, fault):
    fig = plot_roc_pr(list(diagnosed.values()), scored_sets(data), condition, fault)
    assert len(fig.axes) == 2
    ax_roc, ax_pr = fig.axes
    for method, d in diagnosed.items():
        table = metrics(d)
        roc = by_gid(ax_roc, f"roc:{method}")
        pr = by_gid(ax_pr, f"pr:{method}")
        assert pr.get_drawstyle() == "steps-post"
        auc = value(table, "roc_auc", condition, fault)
        ap = value(table, "pr_auc", condition, fault)
        assert trapezoid(roc.get_xdata(), roc.get_ydata()) == pytest.approx(auc, abs=1e-9)
        assert steps_area(pr.get_xdata(), pr.get_ydata()) == pytest.approx(ap, abs=1e-9)
        assert f"AUC {auc:.3f}" in roc.get_label() and f"AP {ap:.3f}" in pr.get_label()
    if fault == "all":  # not a trivial curve: the two methods and the areas differ from 1
        assert value(metrics(diagnosed["pca"]), "roc_auc") < 0.95


def bars(ax):
    return {
        c.get_label(): [p.get_height() for p in c]
        for c in ax.containers
        if isinstance(c, BarContainer)
    }


def test_metric_bars_by_condition_and_fault_are_the_table_values(diagnosed):
    table = pd.concat([metrics(d) for d in diagnosed.values()])
    fig = plot_metric(list(diagnosed.values()), "pd", by="condition")
    ax = fig.axes[0]
    assert [t.get_text() for t in ax.get_xticklabels()] == ["OC1", "OC2", "all"]
    # each condition pooled over its faults: OC2 has the sensor-A gain only
    pooled = {"OC1": "all", "OC2": "sensor.gain:sensor_A", "all": "all"}
    for method, heights in bars(ax).items():
        t = table[table.method == method]
        assert heights == [value(t, "pd", c, f) for c, f in pooled.items()]
    fig = plot_metric(diagnosed["pca"], "dd_median_s", by="fault", condition="OC1")
    ax = fig.axes[0]
    faults = [t.get_text() for t in ax.get_xticklabels()]
    assert faults == ["sensor.gain:sensor_A", "sensor.offset:sensor_A", "all"]
    assert bars(ax)["pca"] == [
        value(metrics(diagnosed["pca"]), "dd_median_s", "OC1", f) for f in faults
    ]
    assert ax.get_ylabel() == "dd_median_s (s)"


def test_detection_probability_bars_carry_their_null_rate(diagnosed):
    fig = plot_metric(diagnosed["pca"], "pd", by="fault", condition="OC1")
    ax = fig.axes[0]
    faults = [t.get_text() for t in ax.get_xticklabels()]
    null = by_gid(ax, "null:pca").get_ydata()
    assert list(null) == [value(metrics(diagnosed["pca"]), "pd_null", "OC1", f) for f in faults]


def test_metric_by_magnitude_and_bad_arguments(diagnosed):
    table = metrics(diagnosed["residual"])
    fig = plot_metric(diagnosed["residual"], "far_pre", by="magnitude")
    lines = {li.get_gid(): li for li in fig.axes[0].get_lines() if li.get_gid()}
    assert set(lines) == {"residual|sensor.gain:sensor_A", "residual|sensor.offset:sensor_A"}
    gain = lines["residual|sensor.gain:sensor_A"]
    np.testing.assert_array_equal(gain.get_xdata(), [0.05, 0.1, 0.2])
    assert list(gain.get_ydata()) == [
        value(table, "far_pre", "all", "sensor.gain:sensor_A", m) for m in (0.05, 0.1, 0.2)
    ]
    with pytest.raises(InputError, match="no metric 'nosuch'.*far_ff"):
        plot_metric(diagnosed["residual"], "nosuch")
    with pytest.raises(InputError, match="by must be one of condition, fault, magnitude"):
        plot_metric(diagnosed["residual"], "pd", by="seed")


def test_mdm_points_are_the_detection_probabilities(diagnosed):
    fig = plot_mdm(list(diagnosed.values()))
    assert [ax.get_title() for ax in fig.axes] == ["sensor.gain:sensor_A", "sensor.offset:sensor_A"]
    ax = fig.axes[0]
    for method, d in diagnosed.items():
        table = metrics(d)
        line = by_gid(ax, f"{method}|sensor.gain:sensor_A")
        np.testing.assert_array_equal(line.get_xdata(), [0.05, 0.1, 0.2])
        pds = [value(table, "pd", "all", "sensor.gain:sensor_A", m) for m in (0.05, 0.1, 0.2)]
        assert list(line.get_ydata()) == pds
        null = by_gid(ax, f"null:{method}|sensor.gain:sensor_A")
        assert list(null.get_ydata()) == [
            value(table, "pd_null", "all", "sensor.gain:sensor_A", m) for m in (0.05, 0.1, 0.2)
        ]
        mdm = [li for li in ax.get_lines() if li.get_gid() == f"mdm:{method}|sensor.gain:sensor_A"]
        if mdm:
            assert mdm[0].get_xdata()[0] == value(table, "mdm90", "all", "sensor.gain:sensor_A")
        else:  # no magnitude reached 0.9 significantly above chance
            assert not (
                (table.metric == "mdm90")
                & (table.fault == "sensor.gain:sensor_A")
                & (table.condition == "all")
            ).any()
    assert pds[0] < 0.9  # a real curve: the smallest gain is missed
    # ±6.5 N offsets: the MDM90 is marked on both sides
    offs = [
        li.get_xdata()[0]
        for li in fig.axes[1].get_lines()
        if li.get_gid() == "mdm:pca|sensor.offset:sensor_A"
    ]
    assert sorted(offs) == [-6.5, 6.5]
    assert any(li.get_ydata()[0] == 0.9 for li in ax.get_lines() if li.get_label() == "P_D = 0.9")


def test_bench_results_are_plotted_per_label(benched):
    res = pd.read_parquet(benched / "results.parquet")
    fig = plot_mdm(benched, calibrated=True)
    ax = fig.axes[0]
    for label in METHODS:
        r = res[res.label == label]
        line = by_gid(ax, f"{label}|sensor.gain:sensor_A")
        assert list(line.get_ydata()) == [
            value(r, "pd_cal", "OC1", "sensor.gain:sensor_A", m) for m in line.get_xdata()
        ]
    heights = bars(plot_metric(benched, "far_ff", by="fault").axes[0])
    assert set(heights) == set(METHODS)


def test_figures_need_matplotlib(diagnosed, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib.figure", None)
    with pytest.raises(
        InputError, match=r"pip install matplotlib \(or pip install -e \"\.\[plot\]\""
    ):
        plot_metric(diagnosed["pca"], "pd")


# --------------------------------------------------------------------------- HTML report


class Page(HTMLParser):
    """The images, links and table rows of an HTML page."""

    def __init__(self):
        super().__init__()
        self.imgs, self.refs, self.rows, self.table = [], [], {}, None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        self.refs += [v for k, v in attrs if k in ("src", "href")]
        if tag == "img":
            self.imgs.append(a["src"])
        elif tag == "table":
            self.table = a.get("id")
            self.rows[self.table] = []
        elif tag == "tr":
            self.rows[self.table].append([])
        elif tag in ("td", "th"):
            self.rows[self.table][-1].append("")  # an empty cell has no data

    def handle_data(self, text):
        if self.table and self.rows[self.table] and self.rows[self.table][-1]:
            self.rows[self.table][-1][-1] += text.strip()

    def handle_endtag(self, tag):
        if tag == "table":
            self.table = None


def parse(path):
    text = path.read_text(encoding="utf-8")
    page = Page()
    page.feed(text)
    return text, page


def assert_offline(text, page):
    assert "http://" not in text and "https://" not in text
    assert page.imgs and all(s.startswith("data:image/png;base64,") for s in page.imgs)
    for s in page.imgs:
        assert base64.b64decode(s.split(",", 1)[1]).startswith(b"\x89PNG")
    assert all(r.startswith("data:") for r in page.refs)  # no file or URL resource


def assert_every_row(page, table):
    header, *rows = page.rows["results"]
    assert len(rows) == len(table)
    col = {name: i for i, name in enumerate(header)}
    for row, r in zip(rows, table.itertuples(index=False), strict=True):
        assert [row[col[c]] for c in ("condition", "fault", "metric")] == [
            r.condition,
            r.fault,
            r.metric,
        ]
        assert float(row[col["value"]]) == pytest.approx(r.value, rel=1e-5, abs=1e-12)


def test_report_of_a_diagnose_result(data, diagnosed, tmp_path):
    out = write_report(diagnosed["pca"], tmp_path / "pca.html", datasets=scored_sets(data))
    assert out == tmp_path / "pca.html"
    text, page = parse(out)
    assert_offline(text, page)
    assert_every_row(page, metrics(diagnosed["pca"]))
    # 8 metric figures (4 metrics by 3 conditions and by 3 faults), the MDM curves, ROC/PR
    # and the statistic of the first run of each fault stratum (none, gain, offset)
    assert len(page.imgs) == 8 + 1 + 1 + 3
    assert f"pca {value(metrics(diagnosed['pca']), 'theta'):.6g}</li>" in text  # the header
    summary = page.rows["summary"]
    # one row per stratum: OC1 (gain, offset, all), OC2 (gain), all (gain, offset, all)
    assert summary[0][:4] == ["method", "condition", "fault", "far_ff"]
    assert [r[1:3] for r in summary[1:]] == [
        ["OC1", "sensor.gain:sensor_A"],
        ["OC1", "sensor.offset:sensor_A"],
        ["OC1", "all"],
        ["OC2", "sensor.gain:sensor_A"],
        ["all", "sensor.gain:sensor_A"],
        ["all", "sensor.offset:sensor_A"],
        ["all", "all"],
    ]
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left
    # which threshold the columns use is said under the table
    assert (
        html.escape(
            "Columns without _cal are at each plug-in's own threshold (pca: "
            "recalibrated on the val runs at alpha); _cal columns at theta"
        )
        in text
    )


def test_report_finds_the_recorded_datasets(data, diagnosed, tmp_path):
    """r2rsim diagnose records its test datasets; the report reads them back without --data,
    and says so when they are gone or were never recorded."""
    src = diagnosed["residual"]
    recorded = json.loads((src / "datasets.json").read_text())["test"]
    assert recorded == [str((data / n).resolve()) for n, _, _ in TEST]
    text, page = parse(write_report(src, tmp_path / "r.html"))
    assert_offline(text, page)
    assert "need the test datasets" not in text and len(page.imgs) == 8 + 1 + 1 + 3
    # results written before datasets.json existed
    old = tmp_path / "old"
    shutil.copytree(src, old)
    (old / "datasets.json").unlink()
    text, page = parse(write_report(old, tmp_path / "r.html"))
    assert "need the test datasets" in text and len(page.imgs) == 8 + 1
    # datasets moved away since: the figures that need them are left out, with a note
    (old / "datasets.json").write_text(json.dumps({"test": [str(tmp_path / "gone")]}))
    text, page = parse(write_report(old, tmp_path / "r.html"))
    assert len(page.imgs) == 8 + 1 and "not found" in text and "gone" in text
    for bad in ("[1, 2]", '{"test": [1, 2]}', '{"test": "/data/run"}', '{"test": [null]}'):
        (old / "datasets.json").write_text(bad)
        with pytest.raises(InputError, match="not a datasets file"):
            write_report(old, tmp_path / "r.html")
    with open(old / "datasets.json", "wb") as f:  # a sparse file beyond the size limit
        f.truncate((16 << 20) + 1)
    with pytest.raises(InputError, match="larger than 16 MiB"):
        write_report(old, tmp_path / "r.html")


def test_report_without_datasets_and_of_a_bench(diagnosed, benched, tmp_path):
    out = write_report(diagnosed["residual"], tmp_path / "r.html", datasets=None)
    text, page = parse(out)
    assert_offline(text, page)
    assert len(page.imgs) == 8 + 1 + 1 + 3  # the recorded test datasets
    out = write_report(benched)
    assert out == benched / "report.html"
    text, page = parse(out)
    assert_offline(text, page)
    assert_every_row(page, pd.read_parquet(benched / "results.parquet"))
    # one condition (OC1): the 4 metrics by fault and the MDM curves; no predictions, so no
    # ROC/PR or statistic figures and no note asking for datasets
    assert len(page.imgs) == 4 + 1 and "need the test datasets" not in text


def test_report_escapes_text(diagnosed, tmp_path):
    d = tmp_path / "res"
    d.mkdir()
    table = metrics(diagnosed["pca"])
    table["fault"] = table["fault"].str.replace("sensor_A", "<b>A&B</b>")
    table.to_parquet(d / "metrics.parquet")
    text, _ = parse(write_report(d))
    assert "&lt;b&gt;A&amp;B&lt;/b&gt;" in text and "<b>A&B" not in text


def test_report_output_rules(diagnosed, tmp_path):
    src = diagnosed["pca"]
    with pytest.raises(InputError, match="does not exist"):
        write_report(src, tmp_path / "nosuch" / "r.html")
    with pytest.raises(InputError, match="is a directory"):
        write_report(src, tmp_path)
    other = tmp_path / "notes.html"
    other.write_text("mine")
    with pytest.raises(InputError, match="not a report r2rsim wrote"):
        write_report(src, other)
    assert other.read_text() == "mine"
    out = tmp_path / "r.html"
    out.write_text(write_report(src, out).read_text().replace("</body>", "old</body>"))
    assert "old</body>" not in write_report(src, out).read_text()  # its own report: replaced


# --------------------------------------------------------------------------- CLI


def test_cli_report(data, diagnosed, tmp_path, capsys):
    out = tmp_path / "r.html"
    assert (
        main(["report", str(diagnosed["pca"]), "-o", str(out), "--data", *scored_sets(data)]) == 0
    )
    assert capsys.readouterr().out == f"report written: {out}\n"
    assert len(parse(out)[1].imgs) == 13


def one_error(capsys, *words):
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    for w in words:
        assert str(w) in err, (w, err)


def test_cli_errors(data, diagnosed, tmp_path, capsys, monkeypatch):
    out = tmp_path / "r.html"
    assert main(["report", str(tmp_path / "nosuch"), "-o", str(out)]) == 2
    one_error(capsys, "nosuch", "no such results directory")
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "x.csv").write_text("a\n")
    assert main(["report", str(tmp_path / "other"), "-o", str(out)]) == 2
    one_error(capsys, "not an r2rsim results directory", "metrics.parquet", "results.parquet")
    assert main(["report", str(diagnosed["pca"]), "-o", str(out), "--data", str(data / "h4")]) == 2
    one_error(capsys, "of the predictions is in none of the datasets")
    monkeypatch.setitem(sys.modules, "matplotlib.figure", None)
    assert main(["report", str(diagnosed["pca"]), "-o", str(out)]) == 2
    one_error(capsys, "matplotlib", 'pip install matplotlib (or pip install -e ".[plot]"')
    assert list(tmp_path.iterdir()) == [tmp_path / "other"]  # nothing written


def test_damaged_results_files_are_one_line_naming_the_file(diagnosed, tmp_path, capsys):
    # a truncated table gave an ArrowInvalid traceback; a table of the wrong shape a message
    # that did not say which file
    out = tmp_path / "r.html"
    for name in ("metrics.parquet", "predictions.parquet"):
        d = shutil.copytree(diagnosed["pca"], tmp_path / name)
        f = d / name
        f.write_bytes(f.read_bytes()[:100])
        assert main(["report", str(d), "-o", str(out)]) == 2
        one_error(capsys, f"error: {f}: not a readable Parquet file (")
    d = shutil.copytree(diagnosed["pca"], tmp_path / "shape")
    pd.DataFrame({"x": [1]}).to_parquet(d / "metrics.parquet")
    assert main(["report", str(d), "-o", str(out)]) == 2
    one_error(
        capsys,
        f"error: {d / 'metrics.parquet'}: not a results table of r2rsim",
        "no column condition",
    )
    assert not out.exists()
