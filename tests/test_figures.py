"""Every figure ``r2rsim plot`` (run and sweep) and ``r2rsim report`` draw is held to the same
rules, checked on the rendered (Agg) figure:

* **units**: every axes that shows data has an x and a y label ending in ``(unit)``: an SI
  unit as the dataset stores it (``tension (N)``, ``offset (N)``), possibly with a prefix
  chosen for short ticks (``pitch (mm)``, ``gain (ppm)``), or ``(1)`` for a unitless number
  (a probability, a rate as a fraction, a count, a detector statistic), ``(relative)`` for a
  relative magnitude. An axis whose ticks name categories (conditions, faults) is exempt
  from the unit, not from the label. In a column of axes sharing x, the bottom one's x
  label covers the column;
* **nothing clipped**: every text (titles, labels, tick labels, legends) lies inside the
  figure;
* **nothing overprinted**: tick labels of one axis do not overlap each other, and titles,
  axis labels and tick labels do not overlap one another.

Then one test per defect users reported (each fails on the figures of r2rsim 0.2.0.dev0 before
the fix), and one that renders the HTML report in a headless browser (skipped without
chromium, unless R2RSIM_REQUIRE_BROWSER=1).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import subprocess
import textwrap

import numpy as np
import pandas as pd
import pytest
import yaml

pytest.importorskip("matplotlib")
import matplotlib  # noqa: E402

matplotlib.use("Agg")
from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: E402

import r2rsim  # noqa: E402
from r2rsim.cli import main  # noqa: E402
from r2rsim.report import plot_mdm, plot_run, plot_sweep, write_report  # noqa: E402
from r2rsim.sweep import run_sweep  # noqa: E402

from conftest import REPO  # noqa: E402

THESIS = REPO / "scenarios" / "thesis"
DURATION = 22.0  # the thesis faults start at 20 s
TRAIN = [("h1", "oc1_nominal", 1), ("h2", "oc1_nominal", 2)]
VAL = [("h3", "oc1_nominal", 3)]
TEST = [
    ("h4", "oc1_nominal", 4),
    ("oP05", "sensor_a_offset_P05", 5),
    ("oN05", "sensor_a_offset_N05", 6),
    ("bP05", "sensor_b_gain_P05", 7),
    ("bN05", "sensor_b_gain_N05", 8),
    ("bP15", "sensor_b_gain_P15", 9),
    ("bN15", "sensor_b_gain_N15", 10),
]
UNIT = re.compile(r"\(([^()]+)\)$")


# ---- data (module scope: each is simulated once, all small) ---------------------------------


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """The quick start for 30 s: the pull roll's encoder (4096 counts per turn) at a steady
    50 rad/s from 10 s, two tension set-points (both 260 N) on one axes."""
    out = tmp_path_factory.mktemp("fig") / "quick"
    r2rsim.run_scenario(REPO / "scenarios" / "quickstart.yaml", output=out, duration=30.0)
    return out


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """sweeps/quickstart.yaml cut to 4 s runs and one seed: 6 runs over top speed, fault-free
    or a load-cell offset of -10/+10 N."""
    d = tmp_path_factory.mktemp("fig")
    spec = yaml.safe_load((REPO / "sweeps" / "quickstart.yaml").read_text(encoding="utf-8"))
    spec["scenario"] = str(REPO / "scenarios" / "quickstart.yaml")
    spec["set"]["duration"] = "4 s"
    spec["set"]["faults"][0]["onset"] = "2 s"
    spec["axes"][1]["values"][1]["onset"] = "2 s"
    spec["seeds"] = 1
    (d / "sweep.yaml").write_text(yaml.safe_dump(spec), encoding="utf-8")
    run_sweep(d / "sweep.yaml", output=d / "sweep", workers=0)
    return d / "sweep"


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    """``r2rsim diagnose --method pca`` on the registration process: sensor-A (load cell)
    offsets of ±6.5 N and sensor-B (pitch camera) gains of ±5.8e-5 and ±1.7e-4 from 20 s."""
    d = tmp_path_factory.mktemp("fig_diag")
    for name, scen, seed in TRAIN + VAL + TEST:
        r2rsim.run_scenario(THESIS / f"{scen}.yaml", output=d / name, seed=seed, duration=DURATION)
    sets = {
        k: [str(d / n) for n, _, _ in v]
        for k, v in (("--train", TRAIN), ("--val", VAL), ("--test", TEST))
    }
    assert (
        main(
            [
                "diagnose",
                "--method",
                "pca",
                *[a for k, v in sets.items() for a in (k, *v)],
                "--n-boot",
                "10",
                "-o",
                str(d / "res"),
            ]
        )
        == 0
    )
    return d


# ---- the rules ------------------------------------------------------------------------------


def render(fig):
    """Draw the figure on an Agg canvas (as savefig does) and return the renderer."""
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    return canvas.get_renderer()


def shows_data(ax) -> bool:
    return ax.get_visible() and bool(ax.lines or ax.collections or ax.patches or ax.images)


def categorical(axis) -> bool:
    """An axis whose ticks name categories (set_xticks with labels: words, not numbers)."""
    texts = [lab.get_text() for lab in drawn_ticklabels(axis)]
    return bool(texts) and any(not re.fullmatch(r"[-+−\d.,e ]*", t) for t in texts)


def drawn_ticklabels(axis) -> list:
    """The tick labels the axis draws (in its view, visible, not empty)."""
    ticks = axis._update_ticks()  # the ticks draw() draws: those in the view interval
    return [
        lab for t in ticks for lab in (t.label1, t.label2) if lab.get_visible() and lab.get_text()
    ]


def label_problems(fig) -> list[str]:
    out = []
    for i, ax in enumerate(fig.axes):
        if not shows_data(ax):
            continue
        for which, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
            label = axis.get_label_text()
            if not label and which == "x":  # a column sharing x: the bottom axes names it
                label = next(
                    (
                        a.get_xlabel()
                        for a in ax.get_shared_x_axes().get_siblings(ax)
                        if a.get_xlabel()
                    ),
                    "",
                )
            if not label:
                out.append(f"axes {i}: no {which} label")
            elif not categorical(axis) and not UNIT.search(label.strip()):
                out.append(f"axes {i}: {which} label {label!r} has no (unit)")
    return out


def clipped(fig, renderer) -> list[str]:
    """Texts reaching outside the figure."""
    box = fig.bbox
    out = []
    ticks, drawn = set(), set()  # every tick label, and those drawn (in the view)
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            ticks |= {
                id(lab) for t in axis.majorTicks + axis.minorTicks for lab in (t.label1, t.label2)
            }
            drawn |= {id(lab) for lab in drawn_ticklabels(axis)}
    for t in fig.findobj(matplotlib.text.Text):
        if not (t.get_visible() and t.get_text().strip()) or t.get_clip_on() and t.axes:
            continue  # a text clipped to its axes (a fault's name) is not drawn outside it
        if id(t) in ticks and id(t) not in drawn:
            continue  # a tick outside the view: not drawn
        bb = t.get_window_extent(renderer)
        if bb.x0 < box.x0 - 1 or bb.x1 > box.x1 + 1 or bb.y0 < box.y0 - 1 or bb.y1 > box.y1 + 1:
            out.append(f"{t.get_text()!r} at {bb.bounds} outside {box.bounds}")
    tight = fig.get_tightbbox(renderer)  # inches
    whole = fig.bbox_inches
    if (
        tight.x0 < -0.02
        or tight.y0 < -0.02
        or tight.x1 > whole.x1 + 0.02
        or tight.y1 > whole.y1 + 0.02
    ):
        out.append(f"the figure's artists span {tight.bounds}, the figure {whole.bounds}")
    return out


def _overlap(a, b, pad: float = 0.5) -> bool:
    return (min(a.x1, b.x1) - max(a.x0, b.x0) > pad) and (min(a.y1, b.y1) - max(a.y0, b.y0) > pad)


def overprinted(fig, renderer) -> list[str]:
    """Tick labels of one axis overlapping each other; titles, axis labels and tick labels
    overlapping one another."""
    out, texts = [], []
    if fig._suptitle is not None and fig._suptitle.get_text():
        texts.append(("suptitle", fig._suptitle))
    for i, ax in enumerate(fig.axes):
        if not ax.get_visible():
            continue
        for t in (ax.title, ax._left_title, ax._right_title, ax.xaxis.label, ax.yaxis.label):
            if t.get_visible() and t.get_text():
                texts.append((f"axes {i} {t.get_text()!r}", t))
        for name, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
            labels = drawn_ticklabels(axis)
            boxes = [lab.get_window_extent(renderer) for lab in labels]
            for j in range(len(boxes)):
                for k in range(j + 1, len(boxes)):
                    if _overlap(boxes[j], boxes[k]):
                        out.append(
                            f"axes {i} {name} tick labels {labels[j].get_text()!r} "
                            f"and {labels[k].get_text()!r} overlap"
                        )
            texts += [(f"axes {i} {name} tick {lab.get_text()!r}", lab) for lab in labels]
    boxes = [(name, t, t.get_window_extent(renderer)) for name, t in texts]
    for j in range(len(boxes)):
        for k in range(j + 1, len(boxes)):
            (na, _, a), (nb, _, b) = boxes[j], boxes[k]
            if " tick " in na and " tick " in nb:
                continue  # tick labels of one axis: above; of two axes: never adjacent
            if _overlap(a, b):
                out.append(f"{na} and {nb} overlap")
    return out


def assert_printable(fig, what: str) -> None:
    renderer = render(fig)
    problems = label_problems(fig) + clipped(fig, renderer) + overprinted(fig, renderer)
    assert not problems, f"{what}:\n" + "\n".join(problems)


# ---- every figure ---------------------------------------------------------------------------


def test_run_figures_are_printable(quick, diagnosed):
    assert_printable(plot_run(quick), "run figure of the quick start")
    assert_printable(plot_run(quick, channels=["meas.*", "sp.*"], t0=9, t1=12), "zoomed run figure")
    assert_printable(plot_run(diagnosed / "bP05"), "run figure of the registration line")


def test_sweep_figures_are_printable(sweep):
    for axis, group in (
        ("offset", "top_speed"),
        ("top_speed", "offset"),
        ("top_speed", None),
        ("fault", None),
        ("top_speed", "fault"),
    ):  # a fault axis: its JSON
        assert_printable(
            plot_sweep(sweep, "meas.lc_rewind.tension_N", "mean", axis, group=group),
            f"sweep figure by {axis}",
        )


def test_report_figures_are_printable(diagnosed):
    from r2rsim.report import report_figures

    figures = report_figures(diagnosed / "res")
    captions = [c for c, _ in figures]
    assert any("MDM" in c for c in captions) and any("ROC" in c for c in captions)
    assert any(c.startswith("statistic of run") for c in captions)
    assert any(c.endswith("by fault") for c in captions)
    for caption, fig in figures:
        assert_printable(fig, caption)


# ---- the defects users reported -------------------------------------------------------------


def mdm_axes(diagnosed):
    fig = plot_mdm(diagnosed / "res")
    return fig, {ax.get_title(): ax for ax in fig.axes}


def test_mdm_title_is_not_clipped(diagnosed):
    fig, _ = mdm_axes(diagnosed)
    renderer = render(fig)
    title = fig._suptitle.get_window_extent(renderer)
    assert title.x0 >= 0 and title.x1 <= fig.bbox.x1, (title.bounds, fig.bbox.bounds)


def test_mdm_magnitude_axis_has_the_fault_unit(diagnosed):
    _, axes = mdm_axes(diagnosed)
    assert axes["sensor.offset:sensor_A"].get_xlabel() == "offset (N)"
    # a gain is relative: 5.8e-5 is shown as 58 ppm
    assert axes["sensor.gain:sensor_B"].get_xlabel() == "gain (ppm)"
    x = sorted(axes["sensor.gain:sensor_B"].get_lines()[0].get_xdata())
    assert x == pytest.approx([-173.13, -57.711, 57.711, 173.13], rel=1e-3)


def test_mdm_sensor_B_tick_labels_do_not_overprint(diagnosed):
    fig, axes = mdm_axes(diagnosed)
    renderer = render(fig)
    labels = drawn_ticklabels(axes["sensor.gain:sensor_B"].xaxis)
    boxes = [lab.get_window_extent(renderer) for lab in labels]
    assert len(boxes) >= 3
    for a, b in zip(boxes, boxes[1:], strict=False):
        assert not _overlap(a, b)


def test_encoder_is_drawn_as_its_speed_not_a_barcode(quick):
    """The pull roll turns at a steady 50 rad/s from 10 s; its encoder (4096 counts per turn,
    read at 200 Hz) resolves 0.31 rad/s, so its readings flip between two levels. Drawn as
    a min/max envelope, that is a barcode of vertical strokes; drawn as the mean per pixel
    column (the speed over a longer counting window), a line."""
    fig = plot_run(quick, channels="meas.enc_pull.*", t0=12, t1=28, n_buckets=200)
    (ax,) = fig.axes
    (line,) = ax.get_lines()
    y = line.get_ydata()
    resolution = 2 * np.pi * 200 / 4096
    assert np.abs(np.diff(y)).mean() < 0.25 * resolution  # no strokes from level to level
    assert np.abs(y - 50.0).max() < resolution
    assert ax.get_ylabel() == "angular speed (rad/s)"
    # the band keeps the readings' extremes
    s = pd.read_parquet(
        next((quick / "samples").rglob("*.parquet")), columns=["t_s", "meas.enc_pull.speed_rad_s"]
    )
    s = s[s.t_s.between(12, 28)]["meas.enc_pull.speed_rad_s"]
    (band,) = [c for c in ax.collections if c.get_gid() == "band:meas.enc_pull.speed_rad_s"]
    ys = band.get_paths()[0].vertices[:, 1]
    assert ys.max() == pytest.approx(s.max()) and ys.min() == pytest.approx(s.min())


def test_run_figure_ticks_are_plain_numbers(diagnosed):
    """The pitch (0.25021 m, moving by microns) was labelled with an offset,
    ``1e-5+2.502e-1``; every axis of the run figure now has plain tick labels."""
    fig = plot_run(diagnosed / "bP05")
    render(fig)
    (pitch,) = [ax for ax in fig.axes if ax.get_ylabel().startswith("pitch")]
    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            assert axis.get_offset_text().get_text() == ""
            for lab in drawn_ticklabels(axis):
                assert re.fullmatch(r"[-−]?\d+(\.\d+)?", lab.get_text()), lab.get_text()
    assert pitch.get_ylabel() == "pitch (mm)"
    ticks = [float(lab.get_text()) for lab in drawn_ticklabels(pitch.yaxis)]
    assert 250.0 < min(ticks) < max(ticks) < 250.5


def test_setpoints_are_distinguishable(quick):
    fig = plot_run(quick)
    ax = next(ax for ax in fig.axes if ax.get_ylabel().startswith("tension"))
    sps = [ln for ln in ax.get_lines() if ln.get_label().startswith("sp.")]
    assert len(sps) == 2  # the unwind's and the rewind's, both at 260 N
    styles = {
        (matplotlib.colors.to_hex(ln.get_color()), str(ln.get_linestyle()), str(ln._dash_pattern))
        for ln in sps
    }
    assert len(styles) == 2
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert all(ln.get_label() in legend for ln in sps)


def test_sweep_axis_has_its_unit(sweep):
    ch = "meas.lc_rewind.tension_N"
    fig = plot_sweep(sweep, ch, axis="offset", group="top_speed")
    ax = fig.axes[0]
    assert ax.get_xlabel() == "offset (N)"  # a load cell's offset: the fault's unit
    assert ax.get_ylabel() == f"mean of {ch} (N)"
    assert [ln.get_label() for ln in ax.get_lines()] == ["top_speed = 3 m/s", "top_speed = 5 m/s"]
    assert plot_sweep(sweep, ch, axis="top_speed").axes[0].get_xlabel() == "top_speed (m/s)"


def readme_sweep_plot(readme: str) -> tuple[str, str]:
    """The sweep file and the channel of the README's ``r2rsim plot --sweep`` example."""
    line = next(ln for ln in readme.splitlines() if "--sweep" in ln and "r2rsim sweep" in ln)
    words = shlex.split(line.split("#")[0].replace("&&", " && "))
    return words[words.index("sweep") + 1], words[words.index("--sweep") + 1]


def test_readme_sweep_example_draws_the_channel_the_fault_acts_on(sweep):
    sweep_file, channel = readme_sweep_plot((REPO / "README.md").read_text(encoding="utf-8"))
    spec = yaml.safe_load((REPO / sweep_file).read_text(encoding="utf-8"))
    targets = {f["target"] for f in spec["set"]["faults"]}
    assert any(channel.startswith(f"meas.{t}.") for t in targets), (channel, targets)
    # and it draws (the test sweep is the README's, shorter)
    faults = pd.read_parquet(sweep / "faults.parquet")
    assert all(channel in list(e) for e in faults["expected_channels"])
    plot_sweep(sweep, channel, axis="offset", group="top_speed")


# ---- the report in a browser ----------------------------------------------------------------


def _chromium() -> str | None:
    return next(
        (
            shutil.which(n)
            for n in ("chromium", "chromium-browser", "google-chrome")
            if shutil.which(n)
        ),
        None,
    )


def test_browser_renders_the_report_with_every_image(diagnosed, tmp_path):
    """The report opened in headless chromium: every <img> decoded (naturalWidth > 0), no
    script error, no request leaving the page (it is self-contained)."""
    browser = _chromium()
    if browser is None:
        if os.environ.get("R2RSIM_REQUIRE_BROWSER") == "1":
            pytest.fail("R2RSIM_REQUIRE_BROWSER=1 but no chromium on PATH")
        pytest.skip("no chromium on PATH (apt-get install chromium)")
    page = write_report(diagnosed / "res", output=tmp_path / "report.html")
    n_img = page.read_text(encoding="utf-8").count("<img ")
    assert n_img >= 5
    # a probe page loads the report in an iframe and writes what it finds into its own DOM
    probe = tmp_path / "probe.html"
    probe.write_text(
        textwrap.dedent(f"""\
        <!DOCTYPE html><html><body><pre id="out">pending</pre>
        <iframe id="r" src="{page.name}" width="1200" height="800"></iframe>
        <script>
        var errors = [];
        window.addEventListener("error", function (e) {{ errors.push(String(e.message)); }});
        document.getElementById("r").addEventListener("load", function () {{
          var doc = this.contentDocument, imgs = Array.from(doc.images);
          var bad = imgs.filter(function (i) {{ return !(i.complete && i.naturalWidth > 0); }});
          document.getElementById("out").textContent = "RESULT " + JSON.stringify({{
            images: imgs.length, undecoded: bad.map(function (i) {{ return i.alt; }}),
            widths: imgs.map(function (i) {{ return i.naturalWidth; }}),
            tables: doc.querySelectorAll("table").length, errors: errors,
            title: doc.title}});
        }});
        </script></body></html>
        """),
        encoding="utf-8",
    )
    profile = tmp_path / "profile"
    cmd = [
        browser,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-quic",
        "--no-first-run",
        "--disable-background-networking",
        "--disable-component-update",
        "--disable-sync",
        f"--user-data-dir={profile}",
        "--allow-file-access-from-files",
        "--virtual-time-budget=10000",
        "--dump-dom",
        probe.as_uri(),
    ]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr[-2000:]
    found = re.search(r"RESULT (\{.*?\})</pre>", res.stdout)
    assert found, f"the probe did not run: {res.stdout[-1000:]} {res.stderr[-1000:]}"
    import html
    import json

    got = json.loads(html.unescape(found.group(1)))
    assert got["images"] == n_img and got["undecoded"] == [], got
    assert min(got["widths"]) >= 400
    assert got["tables"] >= 2 and got["errors"] == []
    assert got["title"].startswith("r2rsim diagnose report")
