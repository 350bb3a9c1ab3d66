"""The virtual-sensor figures of r2rsim.report._hsov (thesis Figs. 2-13 to 2-15): what each
shows, checked on the rendered (Agg) artists."""

from __future__ import annotations

import matplotlib
import numpy as np
import pytest
from scipy import stats

from r2rsim.errors import InputError
from r2rsim.report import plot_profiles, plot_residual_qq, plot_virtual_sensor

matplotlib.use("Agg")


def test_virtual_sensor_panels_curves_and_spans():
    t = np.linspace(0, 10, 101)
    meas, est, true = np.sin(t), np.sin(t) + 0.1, np.cos(t)
    fig = plot_virtual_sensor(
        t,
        [("T_s2 [N]", {"measured": meas, "estimated": est}), ("T_s3 [N]", {"true": true})],
        spans=[(2, 3), (6, 7.5)],
    )
    fig.canvas.draw()
    ax0, ax1 = fig.axes
    assert len(fig.axes) == 2
    np.testing.assert_array_equal(ax0.lines[1].get_ydata(), est)
    np.testing.assert_array_equal(ax1.lines[0].get_xdata(), t)
    spans = [p for p in ax1.patches if p.get_gid() == "span"]
    assert len(spans) == 2
    # the span's corners in data coordinates (a Rectangle or, in older matplotlib, a Polygon)
    corners = ax1.transData.inverted().transform(
        spans[1].get_transform().transform(spans[1].get_path().vertices)
    )
    np.testing.assert_allclose([corners[:, 0].min(), corners[:, 0].max()], [6, 7.5])
    assert [tx.get_text() for tx in ax0.get_legend().get_texts()] == [
        "transient",
        "measured",
        "estimated",
    ]
    with pytest.raises(InputError, match="values for"):
        plot_virtual_sensor(t, [("x", {"bad": t[:5]})])


def test_residual_qq_against_normal_quantiles():
    rng = np.random.default_rng(1)
    r = {"tension": rng.normal(3, 2, 400), "pitch": rng.standard_t(3, 400)}
    fig = plot_residual_qq(r)
    fig.canvas.draw()
    assert len(fig.axes) == 2
    qq = next(ln for ln in fig.axes[0].lines if ln.get_gid() == "qq")
    x, y = qq.get_xdata(), qq.get_ydata()
    z = np.sort((r["tension"] - r["tension"].mean()) / r["tension"].std())
    np.testing.assert_allclose(y, z)
    np.testing.assert_allclose(x, stats.norm.ppf((np.arange(1, 401) - 0.5) / 400))
    assert fig.axes[1].get_title() == "pitch"
    # heavy tails lie off the reference line: the extreme t(3) residual beyond the normal
    qt = next(ln for ln in fig.axes[1].lines if ln.get_gid() == "qq")
    assert abs(qt.get_ydata()[-1]) > abs(qt.get_xdata()[-1])
    with pytest.raises(InputError, match="distinct"):
        plot_residual_qq({"flat": np.ones(10)})


def test_profiles_one_axes_per_group_shared_y():
    x = np.linspace(-5, 5, 11)
    fig = plot_profiles(
        {"normal": [(x, x), (x, 2 * x)], "dancer failure": [(x, -x)]}, ylabel="T_s3 [N]"
    )
    fig.canvas.draw()
    a, b = fig.axes
    assert len([ln for ln in a.lines if ln.get_gid() is None]) == 3  # 2 + the t = 0 line
    np.testing.assert_array_equal(b.lines[0].get_ydata(), -x)
    assert a.get_ylim() == b.get_ylim()
    assert b.get_title() == "dancer failure"
