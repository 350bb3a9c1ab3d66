"""The harness options for the thesis methods (issue 16 item 5) on hand-made runs: per-regime
strata, the steady-state window, channel isolation (hit@1) and VUS-PR. Off, they change
nothing."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from test_harness import Passthrough, healthy, make_run, value

from r2rsim.diagnostics.baselines import ResidualThreshold
from r2rsim.errors import InputError
from r2rsim.evaluate import metrics as M
from r2rsim.evaluate.harness import evaluate, run_data


def with_labels(run, **cols):
    """The run with extra label columns (per-sample lists)."""
    for k, v in cols.items():
        run.samples[k] = np.asarray(v)
    return run


def switching(x, onset=None, seed=1, switch=10):
    """A 20-sample run in OC1 until ``switch``, then OC2."""
    r = make_run(x, onset=onset, seed=seed, mode="OC1+OC2")
    return with_labels(
        r,
        **{
            "label.mode": ["OC1"] * switch + ["OC2"] * (len(x) - switch),
            "label.severity": np.where(r.samples["label.is_faulty"], 1.0, 0.0),
        },
    )


@pytest.fixture
def train():
    return [healthy(100, [0.0] * 20), healthy(101, [0.0] * 20)]


def mode_runs():
    h = np.zeros(20)
    h[[2, 12, 13]] = 9  # one false alarm in OC1, two in OC2
    f = np.zeros(20)
    f[[1, 7, 8]] = 9  # OC1: one pre-onset alarm, two of five fault samples
    f[15:] = 9  # OC2: five of ten fault samples
    return [switching(h, seed=1), switching(f, onset=5, seed=2)]


def test_mode_strata_split_a_switching_run_by_regime(train):
    ev = evaluate(Passthrough(), train, mode_runs(), n_boot=0, mode_strata=True)
    c1, c2, fault = "mode:OC1", "mode:OC2", "sensor.offset:s1"
    assert value(ev, "far_ff", c1, fault) == pytest.approx(1 / 10)
    assert value(ev, "far_ff", c2, fault) == pytest.approx(2 / 10)
    assert value(ev, "far_pre", c1, fault) == pytest.approx(1 / 5)
    assert value(ev, "dr", c1, fault) == pytest.approx(2 / 5)
    assert value(ev, "dr", c2, fault) == pytest.approx(5 / 10)
    # the whole-run strata keep their numbers: 3 of 20 and 7 of 15
    assert value(ev, "far_ff", "OC1+OC2", fault) == pytest.approx(3 / 20)
    assert value(ev, "dr", "OC1+OC2", fault) == pytest.approx(7 / 15)
    # per-run metrics are not reported per regime (a run has one onset)
    rows = ev.metrics[ev.metrics.condition.str.startswith("mode:")]
    assert not rows.metric.isin(["pd", "dd_median_s", "n_missed"]).any()
    assert {("mode:OC1", fault), ("mode:OC2", fault)} <= set(map(tuple, ev.table().index))


def test_mode_strata_at_theta(train):
    val = [healthy(50, np.arange(100.0))]  # theta = 98
    runs = mode_runs()
    runs[0].samples.loc[12, "meas.x"] = 99.0  # at theta, only this OC2 sample alarms
    ev = evaluate(Passthrough(level=1000.0), train, runs, val, n_boot=0, mode_strata=True)
    assert value(ev, "far_ff_cal", "mode:OC1", "sensor.offset:s1") == 0.0
    assert value(ev, "far_ff_cal", "mode:OC2", "sensor.offset:s1") == pytest.approx(1 / 10)


def test_options_off_change_nothing(train):
    runs = mode_runs()
    a = evaluate(Passthrough(), train, runs, n_boot=50).metrics
    b = evaluate(
        Passthrough(),
        train,
        runs,
        n_boot=50,
        mode_strata=True,
        window="steady",
        vus_buffer=1.0,
        isolation=True,
    ).metrics
    keep = ~b.condition.str.startswith("mode:") & ~b.metric.isin(
        ["dr_steady", "pd_steady", "pd_steady_null", "dd_steady_median_s", "vus_pr"]
    )
    cols = [c for c in a.columns if c != "value"]
    drop = a.metric == "fit_s"  # wall times differ
    pd.testing.assert_frame_equal(
        a.loc[~drop, cols].reset_index(drop=True),
        b.loc[keep & (b.metric != "fit_s"), cols].reset_index(drop=True),
    )
    assert not a.metric.isin(["dr_steady", "vus_pr", "hit1"]).any()
    assert not a.condition.str.startswith("mode:").any()


def test_steady_window(train):
    x = np.zeros(20)
    x[[6, 7]] = 9  # during the ramp
    x[[12, 13, 15]] = 9  # three of eight steady samples (12..19)
    r = make_run(x, onset=5, seed=3)
    sev = np.r_[np.zeros(5), np.linspace(0.2, 0.9, 7), np.ones(8)]
    with_labels(r, **{"label.severity": sev})
    ev = evaluate(Passthrough(), train, [r], n_boot=0, window="steady")
    assert value(ev, "dr") == pytest.approx(5 / 15)  # M3 unchanged
    assert value(ev, "dr_steady") == pytest.approx(3 / 8)
    assert value(ev, "pd_steady") == 1.0
    assert value(ev, "dd_steady_median_s") == 0.0  # detected at the first steady sample
    with pytest.raises(InputError, match="window"):
        evaluate(Passthrough(), train, [r], window="ramp")
    with pytest.raises(InputError, match="label.severity"):
        evaluate(Passthrough(), train, [make_run(x, onset=5, seed=4)], window="steady")


def two_channel(a, b, *, onset=None, truth=None, seed=1):
    """A run with channels meas.a, meas.b; ``truth``: the channel labelled faulty."""
    n = len(a)
    r = make_run(np.zeros(n), onset=onset, seed=seed)
    r.samples["meas.a"], r.samples["meas.b"] = np.asarray(a, float), np.asarray(b, float)
    faulty = r.samples["label.is_faulty"].to_numpy()
    for ch in ("a", "b"):
        r.samples[f"label.ch.{ch}"] = faulty & (truth == ch)
    del r.samples["meas.x"]
    return r


def test_isolation_hit1_of_the_residual_baseline():
    rng = np.random.default_rng(0)
    train = [
        two_channel(rng.normal(size=200), rng.normal(size=200), seed=100 + i) for i in range(2)
    ]
    noise = rng.normal(size=(3, 2, 60)) * 0.1
    step = np.r_[np.zeros(30), np.full(30, 8.0)]
    test = [
        two_channel(noise[0, 0], noise[0, 1] + step, onset=30, truth="b", seed=1),
        two_channel(noise[1, 0] + step, noise[1, 1], onset=30, truth="a", seed=2),
        # labelled on a, but b carries the fault: the ranking (b first) misses
        two_channel(noise[2, 0], noise[2, 1] + step, onset=30, truth="a", seed=3),
    ]
    ev = evaluate(ResidualThreshold(alpha=0.01), train, test, n_boot=0, isolation=True)
    assert value(ev, "hit1", fault="sensor.offset:s1") == pytest.approx(2 / 3)
    assert value(ev, "hit1_samples", fault="sensor.offset:s1") == pytest.approx(2 / 3)
    assert "hit1" in ev.table().columns
    # a plug-in without a ranking: no hit1
    ev = evaluate(
        Passthrough(), [healthy(100)], [make_run([0] * 10, onset=4)], n_boot=0, isolation=True
    )
    assert "hit1" not in set(ev.metrics.metric)


def test_vus_pr_in_the_table(train):
    rng = np.random.default_rng(5)
    runs = [
        make_run(rng.random(20) + np.r_[np.zeros(8), np.full(12, 0.5)], onset=8, seed=i)
        for i in range(3)
    ] + [healthy(9, rng.random(20))]
    ev = evaluate(Passthrough(), train, runs, n_boot=0, vus_buffer=1.0)  # 2 samples at 0.5 s
    assert ev.settings["vus_max_buffer_samples"] == 2
    rd = [
        run_data(r, r.samples["meas.x"].to_numpy(), r.samples["meas.x"].to_numpy() > 5)
        for r in runs
    ]
    s, y = M.pooled_scores(rd)
    groups = np.repeat(np.arange(len(rd)), [r.n for r in rd])
    assert value(ev, "vus_pr") == pytest.approx(M.vus_pr(s, y, 2, groups=groups))
    assert value(ev, "vus_pr") != pytest.approx(M.vus_pr(s, y, 0, groups=groups))
    with pytest.raises(InputError, match="vus_buffer"):
        evaluate(Passthrough(), train, runs, vus_buffer=-1.0)


class FitRaises(Passthrough):
    """A plug-in whose fit fails: a setting refused with an InputError was checked first."""

    def fit(self, runs):
        raise RuntimeError("fitted")


def test_vus_buffer_is_bounded_before_the_fit(train):
    runs = [make_run(np.r_[np.zeros(8), np.ones(12)], onset=8, seed=1)]
    # seconds: refused before anything is read (60 s at most, docs/security.md)
    for bad in (60.5, 1e9, float("inf"), float("nan")):
        with pytest.raises(InputError, match="vus_buffer must be from 0 to 60 s"):
            evaluate(FitRaises(), train, runs, vus_buffer=bad)
    # samples: 50 s at 1 kHz is 50 000 buffer lengths, more than 10 000
    fast = [make_run(np.r_[np.zeros(8), np.ones(12)], onset=8, seed=2, dt=0.001)]
    with pytest.raises(
        InputError,
        match=r"vus_buffer 50 s is 5e\+04 samples .* limit of "
        r"10000 buffer lengths",
    ):
        evaluate(FitRaises(), [healthy(100, dt=0.001)], fast, vus_buffer=50.0)
    ev = evaluate(Passthrough(), train, runs, n_boot=0, vus_buffer=60.0)  # 120 samples
    assert ev.settings["vus_max_buffer_samples"] == 120
