"""The GSMMS figures of the report stage (r2rsim.report._gsmms): what each one shows."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("matplotlib")

from test_gsmms import PARAMS, run_frame  # noqa: E402

from r2rsim.diagnostics.gsmms import GSMMS  # noqa: E402
from r2rsim.errors import InputError  # noqa: E402
from r2rsim.report import plot_gsmms_map, plot_gsmms_residuals, plot_severity  # noqa: E402


class FakeRun:
    """A run with samples holding label.is_faulty, as plot_gsmms_residuals reads it."""

    def __init__(self, frame, faulty_from):
        self._f = frame
        self.samples = frame.assign(**{"label.is_faulty": frame["t_s"] >= faulty_from})

    def visible(self):
        return self._f


@pytest.fixture(scope="module")
def fitted():
    return GSMMS(**PARAMS).fit([run_frame(r, s) for r in (0, 1) for s in (1, 2)])


def test_map_colours_samples_by_node_and_draws_the_nodes(fitted):
    runs = [run_frame(0, 5), run_frame(1, 6)]
    fig = plot_gsmms_map(fitted, runs, "sp.level", "meas.a", max_points=500)
    (ax,) = fig.axes
    labels = [c.get_label() for c in ax.collections]
    assert labels == ["node 0", "node 1"]
    # the points of each node are the samples of one regime (levels 100 and 150)
    levels = {c.get_label(): set(np.round(c.get_offsets()[:, 0])) for c in ax.collections}
    assert sorted(levels.values(), key=min) == [{100.0}, {150.0}]
    assert sum(len(c.get_offsets()) for c in ax.collections) == 500
    # sp.level is the partition feature: one vertical line per node, at its codebook
    # position (near the set-points; the neighbourhood pulls nodes a little together)
    book = sorted((fitted.graph_.codebook * fitted.s_scale_ + fitted.s_mean_)[:, 0])
    xs = sorted(ln.get_xdata()[0] for ln in ax.lines)
    np.testing.assert_allclose(xs, book)
    np.testing.assert_allclose(xs, [100.0, 150.0], atol=2.0)
    # both axes partition features: node markers and the map's one edge
    fig = plot_gsmms_map(fitted, runs, "sp.level", "sp.level")
    (ax,) = fig.axes
    assert ax.collections[-1].get_label() == "nodes" and len(ax.lines) == 1
    np.testing.assert_allclose(sorted(ax.collections[-1].get_offsets()[:, 0]), book)


def test_map_without_partition_axes_draws_no_nodes(fitted):
    fig = plot_gsmms_map(fitted, [run_frame(0, 5)], "meas.a", "meas.b")
    assert [c.get_label() for c in fig.axes[0].collections] == ["node 0"] or [
        c.get_label() for c in fig.axes[0].collections
    ] == ["node 1"]
    assert not fig.axes[0].lines
    with pytest.raises(InputError, match="no column"):
        plot_gsmms_map(fitted, [run_frame(0, 5)], "meas.zz", "meas.b")


def test_residuals_per_run_with_thresholds_and_fault_window(fitted):
    healthy, faulty = run_frame(0, 7), FakeRun(run_frame(1, 8, fault=0.0), faulty_from=10.0)
    fig = plot_gsmms_residuals(fitted, {"healthy": healthy, "faulty": faulty})
    assert len(fig.axes) == 2
    for ax, f in zip(fig.axes, (healthy, faulty.visible()), strict=True):
        line = ax.lines[0]
        np.testing.assert_allclose(line.get_xdata(), f["t_s"])
        np.testing.assert_allclose(line.get_ydata(), fitted.score(f)["z.0"], equal_nan=True)
        assert sorted(ax.lines[i].get_ydata()[0] for i in (1, 2)) == [-2.0, 2.0]
    assert not fig.axes[0].patches  # no fault window in the healthy run
    (span,) = fig.axes[1].patches
    # an axvspan is a Polygon in matplotlib 3.7 and a Rectangle later: read its extent
    ext = span.get_patch_transform().transform_path(span.get_path()).get_extents()
    assert ext.x0 == pytest.approx(10.0)
    assert ext.x1 == pytest.approx(float(faulty.visible()["t_s"].iloc[-1]))


def test_severity_lines_per_condition():
    vals = {"OC1": {0.2: 4.0, 0.05: 1.0, 0.1: 2.0}, "OC2": {0.05: 1.5, 0.2: 5.0}}
    fig = plot_severity(vals, threshold=2.0)
    (ax,) = fig.axes
    lines = [ln for ln in ax.lines if ln.get_label() in vals]
    assert [ln.get_label() for ln in lines] == ["OC1", "OC2"]
    np.testing.assert_allclose(lines[0].get_xdata(), [0.05, 0.1, 0.2])
    np.testing.assert_allclose(lines[0].get_ydata(), [1.0, 2.0, 4.0])
    assert [ln.get_ydata()[0] for ln in ax.lines if ln.get_label() == "threshold"] == [2.0]
    with pytest.raises(InputError):
        plot_severity({})
