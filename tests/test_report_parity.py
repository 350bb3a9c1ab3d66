"""The report stage's residual, signature and sensitivity figures (r2rsim/report/_parity.py),
rendered with Agg: what they show, checked against their input."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from r2rsim.errors import InputError

pytest.importorskip("matplotlib")

from r2rsim.report import plot_residuals, plot_sensitivity, plot_signature  # noqa: E402


def _frame(k):
    t = np.arange(0, 10, 0.5)
    return pd.DataFrame({"t_s": t, "r1": k * t, "r2": np.sin(t) + k, "r3": -t})


def _span_x(patch):
    xy = np.asarray(patch.get_xy()) if hasattr(patch, "get_xy") else None
    if xy is not None and xy.ndim == 2:
        return xy[:, 0].min(), xy[:, 0].max()
    return patch.get_x(), patch.get_x() + patch.get_width()


def test_residual_panels_data_threshold_and_spans():
    series = {"a": _frame(1.0), "b": _frame(2.0)}
    fig = plot_residuals(
        series,
        ["r1", "r2"],
        scale={"r1": 2.0},
        threshold=3.0,
        spans=[(4.0, 10.0, "fault")],
        title="x",
    )
    axes = fig.get_axes()
    assert len(axes) == 2
    lines = [ln for ln in axes[0].get_lines() if ln.get_gid() != "threshold"]
    assert len(lines) == 2
    np.testing.assert_allclose(lines[1].get_ydata(), 2.0 * series["b"]["t_s"] / 2.0)
    np.testing.assert_allclose(lines[0].get_xdata(), series["a"]["t_s"])
    # r2 is not scaled
    l2 = [ln for ln in axes[1].get_lines() if ln.get_gid() != "threshold"]
    np.testing.assert_allclose(l2[0].get_ydata(), series["a"]["r2"])
    thr = sorted(ln.get_ydata()[0] for ln in axes[0].get_lines() if ln.get_gid() == "threshold")
    assert thr == [-3.0, 3.0]
    for ax in axes:
        spans = [p for p in ax.patches if str(p.get_gid()).startswith("span:")]
        assert len(spans) == 1 and _span_x(spans[0]) == pytest.approx((4.0, 10.0))
    assert axes[0].get_ylabel() == "r1 [σ]"
    with pytest.raises(InputError, match="has no column r4"):
        plot_residuals(series, ["r4"])
    with pytest.raises(InputError, match="no series"):
        plot_residuals({}, ["r1"])


def test_signature_matrix_cells_and_fired_outlines():
    table = pd.DataFrame(
        [[4.0, 0.2, 5.0], [-3.5, 3.1, 0.1]],
        index=["A +15 %", "B +15 %"],
        columns=["r1", "r2", "r3"],
    )
    fig = plot_signature(table, threshold=3.0)
    ax = fig.get_axes()[0]
    np.testing.assert_allclose(ax.get_images()[0].get_array(), table.to_numpy())
    texts = [t.get_text() for t in ax.texts]
    assert texts == ["+4.0", "+0.2", "+5.0", "-3.5", "+3.1", "+0.1"]
    fired = [p for p in ax.patches if p.get_gid() == "fired"]
    assert sorted((p.get_x() + 0.5, p.get_y() + 0.5) for p in fired) == [
        (0.0, 0.0),
        (0.0, 1.0),
        (1.0, 1.0),
        (2.0, 0.0),
    ]
    assert [t.get_text() for t in ax.get_yticklabels()] == ["A +15 %", "B +15 %"]
    with pytest.raises(InputError, match="empty"):
        plot_signature(pd.DataFrame())


def test_sensitivity_panels():
    s = {
        "OC1": pd.DataFrame({"t_s": [0.0, 1.0, 2.0], "dJ/dx": [1.0, 1.0, 1.1]}),
        "OC2": pd.DataFrame({"t_s": [0.0, 1.0, 2.0], "dJ/dx": [2.0, 3.0, 1.0]}),
    }
    fig = plot_sensitivity(s, ["dJ/dx"])
    ax = fig.get_axes()[0]
    assert len(fig.get_axes()) == 1 and len(ax.get_lines()) == 2
    np.testing.assert_allclose(ax.get_lines()[1].get_ydata(), [2.0, 3.0, 1.0])
    assert ax.get_ylabel() == "dJ/dx"
