"""The run and sweep figures (r2rsim.report.plot_run, plot_sweep, decimate_minmax) and
``r2rsim plot``: what the figures show, checked against the dataset's own tables."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pandas as pd
import pytest

pytest.importorskip("matplotlib")
import matplotlib  # noqa: E402

matplotlib.use("Agg")

import r2rsim  # noqa: E402
from r2rsim.cli import main  # noqa: E402
from r2rsim.errors import InputError  # noqa: E402
from r2rsim.report import decimate_minmax, plot_run, plot_sweep  # noqa: E402
from r2rsim.report._data import (  # noqa: E402
    _bucket_starts,
    _minmax_indices,
    constant_columns,
    open_run,
)
from r2rsim.sweep import run_sweep  # noqa: E402

from conftest import REPO  # noqa: E402

# ---- datasets (module scope: each is simulated once) ---------------------------------------


@pytest.fixture(scope="module")
def faults_ds(tmp_path_factory):
    """line_a_faults for 35 s: pull_draw 10-25 s, idler_bearing from 30 s without an end,
    unwind_drive (onset 40 s) beyond the run."""
    out = tmp_path_factory.mktemp("plot") / "faults"
    r2rsim.run_scenario(
        REPO / "scenarios" / "line_a_faults.yaml", output=out, duration=35.0, overwrite=True
    )
    return out


@pytest.fixture(scope="module")
def splice_ds(tmp_path_factory):
    """newsprint_splice for 30 s: a zero-speed splice (fill, brake, dwell, swap...) and the
    joint passing the spans."""
    out = tmp_path_factory.mktemp("plot") / "splice"
    r2rsim.run_scenario(
        REPO / "scenarios" / "newsprint_splice.yaml", output=out, duration=30.0, overwrite=True
    )
    return out


@pytest.fixture(scope="module")
def sweep_ds(tmp_path_factory):
    """sweeps/quickstart.yaml: 12 runs, axes top_speed x fault x offset, 2 seeds; the 4
    fault-free runs have no offset."""
    out = tmp_path_factory.mktemp("plot") / "sweep"
    run_sweep(REPO / "sweeps" / "quickstart.yaml", output=out, workers=0)
    return out


@pytest.fixture(scope="module")
def long_ds(tmp_path_factory):
    """The benchmark's synthetic run, 200 s at 1 kHz: five row groups, one spike."""
    spec = importlib.util.spec_from_file_location(
        "bench_plot", REPO / "benchmarks" / "bench_plot.py"
    )
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    root = bench.make_dataset(tmp_path_factory.mktemp("plot") / "long", 200.0, 1000.0)
    return root, bench


def samples(root, run_id=None) -> pd.DataFrame:
    rid = run_id or pd.read_parquet(root / "runs.parquet")["run_id"][0]
    return pd.read_parquet(root / "samples" / f"run_id={rid}")


def lines_by_label(fig) -> dict:
    return {ln.get_label(): ln for ax in fig.axes for ln in ax.get_lines()}


def span_x(patch) -> tuple[float, float]:
    """Data x extent of an axvspan (a Polygon before matplotlib 3.9, a Rectangle after)."""
    x = patch.get_patch_transform().transform(patch.get_path().vertices)[:, 0]
    return float(x.min()), float(x.max())


# ---- decimation ------------------------------------------------------------------------------


def test_decimate_keeps_a_single_sample_spike_either_way():
    t = np.arange(100_000) * 1e-3
    y = np.sin(t)
    y[31_337], y[77_001] = 50.0, -50.0
    td, yd = decimate_minmax(t, y, 500)
    assert len(td) <= 1000
    assert yd.max() == 50.0 and yd.min() == -50.0
    assert td[yd.argmax()] == t[31_337] and td[yd.argmin()] == t[77_001]
    assert np.all(np.diff(td) > 0)  # time order, no duplicates


def test_decimate_envelope_is_each_buckets_min_and_max():
    rng = np.random.default_rng(1)
    t = np.arange(10_000, dtype=float)
    y = rng.normal(size=t.size)
    td, yd = decimate_minmax(t, y, 10)  # buckets of 1000 samples
    for b in range(10):
        got = yd[(td >= 1000 * b) & (td < 1000 * (b + 1))]
        assert sorted(got) == sorted(
            [y[1000 * b : 1000 * (b + 1)].min(), y[1000 * b : 1000 * (b + 1)].max()]
        )


def test_decimate_short_series_whole_and_nan_buckets_break_the_line():
    t = np.arange(10.0)
    assert np.array_equal(decimate_minmax(t, t * 2, 5)[1], t * 2)
    t = np.arange(1000.0)
    y = np.ones_like(t)
    y[500:600] = np.nan  # a dropout covering whole buckets
    y[10] = np.nan  # one NaN inside a bucket is skipped
    td, yd = decimate_minmax(t, y, 100)
    assert np.isnan(yd).sum() == 10  # one NaN per all-NaN bucket
    assert np.all(yd[td < 500] == 1.0)
    with pytest.raises(ValueError):
        decimate_minmax(t, y, 0)


def test_chunks_sharing_bucket_edges_give_the_whole_envelope():
    t = np.linspace(0, 10, 20_001)
    y = np.cos(3 * t)
    y[12_345] = 9.0
    whole = _minmax_indices(y, _bucket_starts(t, 50, (0, 10)))
    parts = []
    for lo in range(0, t.size, 7_000):  # chunk edges fall inside buckets
        sl = slice(lo, lo + 7_000)
        parts.append(lo + _minmax_indices(y[sl], _bucket_starts(t[sl], 50, (0, 10))))
    chunked = np.concatenate(parts)
    assert set(whole) <= set(chunked) and y[chunked].max() == 9


# ---- the run figure --------------------------------------------------------------------------


def test_default_run_figure_groups_quantities_and_draws_setpoints(faults_ds):
    fig = plot_run(faults_ds)
    labels = [ax.get_ylabel() for ax in fig.axes]
    assert labels == [
        "tension (N)",
        "angular speed (rad/s)",
        "diameter (mm)",
        "speed (m/s)",
        "radius (mm)",
        "torque (N*m)",
    ]
    lines = lines_by_label(fig)
    # set-points are drawn (dashed), however constant; an idler's constant radius is not
    assert lines["sp.unwind_tension.tension_N"].get_linestyle() == "--"
    assert "sp.line_speed_m_s" in lines and "state.idler1.radius_m" not in lines
    assert "state.unwind.radius_m" in lines


def test_axes_follow_the_globs(faults_ds):
    fig = plot_run(faults_ds, channels=["state.span*.tension_N", "meas.lc_*", "state.*.radius_m"])
    assert [ax.get_ylabel() for ax in fig.axes] == ["tension (N)", "radius (mm)"]
    assert len(fig.axes[0].get_lines()) == 5 + 2
    assert len(fig.axes[1].get_lines()) == 6  # explicit globs keep constant channels


def test_fault_spans_match_faults_parquet(faults_ds):
    fig = plot_run(faults_ds, channels="state.span*.tension_N")
    faults = pd.read_parquet(faults_ds / "faults.parquet")
    end = samples(faults_ds)["t_s"].max()
    want = {
        f.fault_id: (f.onset_t_s, end if pd.isna(f.end_t_s) else f.end_t_s)
        for f in faults.itertuples()
        if f.onset_t_s <= end
    }
    assert set(want) == {"pull_draw", "idler_bearing"}  # unwind_drive starts after the run
    for ax in fig.axes:
        got = {
            p.get_gid()[len("fault:") :]: span_x(p)
            for p in ax.patches
            if (p.get_gid() or "").startswith("fault:")
        }
        assert got.keys() == want.keys()
        for fid, (lo, hi) in want.items():
            assert got[fid] == pytest.approx((lo, hi))


def test_event_lines_match_events_parquet(splice_ds):
    fig = plot_run(splice_ds, channels=["state.*.tension_N"], t0=4.0, t1=30.0)
    ev = pd.read_parquet(splice_ds / "events.parquet")
    ev = ev[(ev.kind != "fault") & ev.t_s.between(4.0, 30.0)]
    assert {"splice", "splice_joint"} <= set(ev.kind)
    ax = fig.axes[0]
    drawn = {
        c.get_gid()[len("event:") :]: sorted(s[0][0] for s in c.get_segments())
        for c in ax.collections
        if (c.get_gid() or "").startswith("event:")
    }
    assert drawn.keys() == set(ev.kind)
    for kind, rows in ev.groupby("kind"):
        assert drawn[kind] == pytest.approx(sorted(rows.t_s))
    legend = [t.get_text() for t in fig.legends[0].get_texts()]
    assert f"splice ({(ev.kind == 'splice').sum()})" in legend


def test_lines_hold_the_true_extremes_of_the_window(faults_ds):
    t0, t1 = 26.0, 31.0
    fig = plot_run(
        faults_ds, channels=["state.span4.tension_N", "meas.enc_pull.*"], t0=t0, t1=t1, n_buckets=50
    )
    s = samples(faults_ds)
    window = s[s.t_s.between(t0, t1)]
    for name, line in lines_by_label(fig).items():
        x, y = line.get_xdata(), line.get_ydata()
        assert x.min() >= t0 and x.max() <= t1
        assert len(x) <= 100 < len(window)  # decimated
        if name.startswith("meas.enc_"):  # an encoder: its mean per bucket in a min-max band
            (band,) = [
                c for ax in fig.axes for c in ax.collections if c.get_gid() == f"band:{name}"
            ]
            y = band.get_paths()[0].vertices[:, 1]
        assert np.nanmax(y) == window[name].max() and np.nanmin(y) == window[name].min()
    assert fig.axes[0].get_xlim() == (t0, t1)
    # the window leaves out the draw-error peak of span 4 (about 490 N at 15-25 s)
    assert (
        lines_by_label(fig)["state.span4.tension_N"].get_ydata().max()
        < s["state.span4.tension_N"].max() - 50
    )


def test_long_run_streams_row_groups_and_keeps_the_spike(long_ds):
    root, bench = long_ds
    import pyarrow.parquet as pq

    part = next((root / "samples").rglob("part-0.parquet"))
    assert pq.ParquetFile(part).metadata.num_row_groups > 3
    # verify=False: the synthetic dataset's tables hold only what the figure reads, so its
    # labels cannot be checked against faults.parquet (tests/test_reader_verify.py does)
    fig = plot_run(root, channels=["state.span3.tension_N", "meas.*"], n_buckets=300, verify=False)
    lines = lines_by_label(fig)
    s = pd.read_parquet(part, columns=["state.span3.tension_N", "meas.lc_unwind.tension_N"])
    assert lines["state.span3.tension_N"].get_ydata().max() == bench.SPIKE_N
    y = lines["meas.lc_unwind.tension_N"].get_ydata()
    assert (y.min(), y.max()) == (
        s["meas.lc_unwind.tension_N"].min(),
        s["meas.lc_unwind.tension_N"].max(),
    )
    assert len(y) <= 2 * 300 + 2 * pq.ParquetFile(part).metadata.num_row_groups


def test_constant_columns_from_the_row_group_statistics(faults_ds):
    run = open_run(faults_ds, "line_a_faults__s7")
    cols = [
        "label.severity",
        "label.ch.lc_unwind.tension_N",
        "state.idler1.radius_m",
        "state.unwind.radius_m",
    ]
    s = samples(faults_ds)
    assert constant_columns(run, cols) == {c for c in cols if s[c].nunique() == 1}
    assert constant_columns(run, cols) == {"label.ch.lc_unwind.tension_N", "state.idler1.radius_m"}


def test_run_figure_errors_name_the_problem(faults_ds, tmp_path):
    with pytest.raises(InputError, match="no such dataset"):
        plot_run(tmp_path / "nothing")
    with pytest.raises(InputError, match=r"no run 'x__s1' \(runs: line_a_faults__s7\)"):
        plot_run(faults_ds, run_id="x__s1")
    with pytest.raises(InputError, match=r"'state\.spam\*' matches no numeric column"):
        plot_run(faults_ds, channels=["state.span1.tension_N", "state.spam*"])
    with pytest.raises(InputError, match="no samples between"):
        plot_run(faults_ds, t0=100.0, t1=200.0)


# ---- the sweep figure ------------------------------------------------------------------------


def per_run_stat(root, channel, stat, t0=None):
    runs = pd.read_parquet(root / "runs.parquet")
    out = []
    for r in runs.itertuples():
        s = samples(root, r.run_id)
        if t0 is not None:
            s = s[s.t_s >= t0]
        v = s[channel].astype(float)  # stored as float32; the figure computes in float64
        out.append(float(np.sqrt((v**2).mean())) if stat == "rms" else getattr(v, stat)())
    return runs.assign(value=out)


@pytest.mark.parametrize("stat", ["mean", "std", "rms", "max"])
def test_sweep_points_are_the_per_run_statistic(sweep_ds, stat):
    ch = "meas.lc_rewind.tension_N"
    fig = plot_sweep(sweep_ds, ch, stat, axis="offset", t0=6.0)
    (line,) = fig.axes[0].get_lines()
    want = per_run_stat(sweep_ds, ch, stat, t0=6.0).dropna(subset=["axis.offset"])
    got = sorted(zip(line.get_xdata(), line.get_ydata(), strict=True))
    exp = sorted(zip(want["axis.offset"], want["value"], strict=True))
    assert len(got) == 8
    assert np.allclose(got, exp, rtol=1e-12, atol=0)
    assert fig.axes[0].get_ylabel() == f"{stat} of {ch} (N)"


def test_sweep_groups_by_a_second_axis(sweep_ds):
    fig = plot_sweep(
        sweep_ds, "state.rewind.speed_rad_s", "mean", axis="axis.offset", group="top_speed"
    )
    want = per_run_stat(sweep_ds, "state.rewind.speed_rad_s", "mean").dropna(subset=["axis.offset"])
    lines = fig.axes[0].get_lines()
    assert [ln.get_label() for ln in lines] == ["top_speed = 3 m/s", "top_speed = 5 m/s"]
    for line, (_, rows) in zip(lines, want.groupby("axis.top_speed"), strict=True):
        assert sorted(line.get_ydata()) == pytest.approx(sorted(rows.value))


def test_sweep_runs_without_an_x_value_are_left_out_and_counted(sweep_ds):
    # a run an axis did not apply to (the fault-free runs: the fault removed with null) has
    # no x: it is not drawn, and the title counts it rather than claiming all runs are plotted
    fig = plot_sweep(sweep_ds, "meas.lc_rewind.tension_N", axis="offset")
    (line,) = fig.axes[0].get_lines()
    assert len(line.get_xdata()) == 8 and np.isfinite(line.get_xdata()).all()
    assert fig._suptitle.get_text() == "sweep: 8 runs; 4 run(s) without a value of offset left out"


def test_sweep_errors(sweep_ds, faults_ds):
    with pytest.raises(
        InputError, match=r"no sweep axis 'speed' \(axes: top_speed, fault, offset\)"
    ):
        plot_sweep(sweep_ds, "meas.lc_rewind.tension_N", axis="speed")
    with pytest.raises(InputError, match="no numeric channel 'meas.lc_rewind'"):
        plot_sweep(sweep_ds, "meas.lc_rewind")
    with pytest.raises(InputError, match="unknown statistic 'median'"):
        plot_sweep(sweep_ds, "meas.lc_rewind.tension_N", "median")
    with pytest.raises(InputError, match="no sweep axes"):
        plot_sweep(faults_ds, "state.span1.tension_N")


# ---- r2rsim plot -----------------------------------------------------------------------------


def test_cli_writes_the_run_and_sweep_figures(faults_ds, sweep_ds, tmp_path, capsys):
    png, svg = tmp_path / "run.png", tmp_path / "sweep.svg"
    assert (
        main(
            [
                "plot",
                str(faults_ds),
                "--channels",
                "state.span*.tension_N",
                "--t0",
                "5",
                "--t1",
                "20 s",
                "-o",
                str(png),
            ]
        )
        == 0
    )
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (
        main(
            [
                "plot",
                str(sweep_ds),
                "--sweep",
                "meas.lc_rewind.tension_N",
                "--axis",
                "offset",
                "--group",
                "top_speed",
                "-o",
                str(svg),
            ]
        )
        == 0
    )
    assert b"<svg" in svg.read_bytes()[:500]
    assert capsys.readouterr().out.splitlines() == [f"wrote {png}", f"wrote {svg}"]


def test_cli_default_output_is_plot_png_here(faults_ds, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["plot", str(faults_ds), "--channels", "sp.*"]) == 0
    assert (tmp_path / "plot.png").is_file()


def test_cli_keeps_an_existing_file_unless_overwrite(faults_ds, tmp_path, capsys):
    """A file r2rsim did not write is never replaced without being asked."""
    mine = tmp_path / "mine.png"
    mine.write_bytes(b"not r2rsim's")
    assert main(["plot", str(faults_ds), "--channels", "sp.*", "-o", str(mine)]) == 2
    err = capsys.readouterr().err
    assert err.count("error") == 1 and "pass --overwrite" in err
    assert mine.read_bytes() == b"not r2rsim's"
    assert main(["plot", str(faults_ds), "--channels", "sp.*", "-o", str(mine), "--overwrite"]) == 0
    assert mine.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def files(*dirs) -> set:
    return {p for d in dirs for p in d.rglob("*")}


@pytest.fixture
def no_matplotlib(monkeypatch):
    """Importing matplotlib fails, as when it is not installed."""
    for name in [m for m in sys.modules if m == "matplotlib" or m.startswith("matplotlib.")]:
        monkeypatch.setitem(sys.modules, name, None)


@pytest.mark.parametrize(
    "case, needle",
    [
        ("missing", "no such dataset directory"),
        ("run", "no run 'nope__s0' (runs: line_a_faults__s7)"),
        ("glob", "channel glob 'meas.nothing*' matches no numeric column"),
        ("extension", "unknown figure format '.jpg' (use .png, .svg, .pdf)"),
        ("inside", "inside the dataset"),
        ("directory", "no directory"),
        (
            "matplotlib",
            "plotting needs matplotlib, which is not installed: pip install matplotlib "
            '(or pip install -e ".[plot]" in the r2rsim checkout)',
        ),
    ],
)
def test_cli_errors_exit_2_with_one_message_and_no_file(
    case, needle, faults_ds, tmp_path, capsys, request
):
    out = tmp_path / "fig.png"
    args = {
        "missing": [str(tmp_path / "nothing")],
        "run": [str(faults_ds), "--run", "nope__s0"],
        "glob": [str(faults_ds), "--channels", "sp.*", "meas.nothing*"],
        "extension": [str(faults_ds), "-o", str(tmp_path / "fig.jpg")],
        "inside": [str(faults_ds), "-o", str(faults_ds / "fig.png")],
        "directory": [str(faults_ds), "-o", str(tmp_path / "no" / "fig.png")],
        "matplotlib": [str(faults_ds)],
    }[case]
    if "-o" not in args:
        args += ["-o", str(out)]
    if case == "matplotlib":
        request.getfixturevalue("no_matplotlib")
    before = files(tmp_path, faults_ds)
    assert main(["plot", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and needle in err
    assert files(tmp_path, faults_ds) == before


def _damage(ds, how: str):
    """Break one file of a copy of a dataset the way a disk or a careless edit would."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    samples = next((ds / "samples").glob("*/part-0.parquet"))
    small = pa.table({"x": [1]})
    if how == "runs truncated":
        (ds / "runs.parquet").write_bytes((ds / "runs.parquet").read_bytes()[:10])
    elif how == "samples truncated":
        samples.write_bytes(samples.read_bytes()[:100])
    elif how == "runs without run_id":
        pq.write_table(small, ds / "runs.parquet")
    elif how == "samples without t_s":
        pq.write_table(pq.read_table(samples).drop(["t_s"]), samples)
    else:  # channels / faults / events of the wrong shape
        pq.write_table(small, ds / f"{how.split()[0]}.parquet")
    return {
        "runs truncated": "runs.parquet",
        "samples truncated": samples.relative_to(ds),
        "runs without run_id": "runs.parquet",
        "samples without t_s": samples.relative_to(ds),
    }.get(how, f"{how.split()[0]}.parquet")


@pytest.mark.parametrize(
    "how",
    [
        "runs truncated",
        "samples truncated",
        "runs without run_id",
        "samples without t_s",
        "channels of the wrong shape",
        "faults of the wrong shape",
        "events of the wrong shape",
    ],
)
def test_a_damaged_dataset_is_one_error_naming_the_file(how, faults_ds, tmp_path, capsys):
    """With --no-verify, plot reads only what it draws and does not check checksums: a
    damaged file (it gave ArrowInvalid, KeyError or StopIteration tracebacks) is one error
    naming it. (Verified, the manifest refuses it first: tests/test_reader_verify.py.)"""
    import shutil

    ds = tmp_path / "ds"
    shutil.copytree(faults_ds, ds)
    name = _damage(ds, how)
    out = tmp_path / "fig.png"
    assert main(["plot", str(ds), "-o", str(out), "--no-verify"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith(f"error: dataset {ds}: {name} cannot be read (")
    assert err.rstrip().endswith(f"`r2rsim validate {ds}` checks every file")
    assert not out.exists()
