"""The evaluation harness on small hand-made runs: every number it reports is checked against a
hand count and against the metric functions of r2rsim.evaluate.metrics."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from r2rsim.dataset.read import Run
from r2rsim.diagnostics import Diagnostic
from r2rsim.errors import InputError
from r2rsim.evaluate import metrics as M
from r2rsim.evaluate.harness import (
    _FROM_COUNTS,
    _counts,
    _Rule,
    evaluate,
    run_data,
    split_by_condition,
    split_by_seed,
)


class Passthrough(Diagnostic):
    """statistic = meas.x; alarm when it exceeds ``level``."""

    name = "passthrough"
    requires = ("meas.x",)

    def __init__(self, level: float = 5.0):
        self.level = level

    def fit(self, runs):
        self.columns_ = self.required_columns(self._frames(runs)[0])
        self.threshold_ = self.level
        return self

    def score(self, run):
        self._check_fitted()
        f = self._frames(run)[0]
        return pd.DataFrame({"statistic": f["meas.x"].to_numpy(float)}, index=f.index)


def make_run(
    x,
    *,
    onset=None,
    warmup=0,
    mode="OC1",
    seed=1,
    ftype="sensor.offset",
    target="s1",
    magnitude=1.0,
    split=None,
    rid=None,
    dt=0.5,
) -> Run:
    """A run of len(x) samples at dt; faulty from sample ``onset`` on (None: healthy)."""
    n = len(x)
    k = np.arange(n)
    faulty = (k >= onset) if onset is not None else np.zeros(n, bool)
    samples = pd.DataFrame(
        {
            "k": k,
            "t_s": k * dt,
            "meas.x": np.asarray(x, float),
            "label.is_faulty": faulty,
            "label.score_mask": k >= warmup,
            "label.primary_type": np.where(faulty, ftype, "normal"),
        }
    ).set_index("k", drop=False)
    faults = (
        pd.DataFrame({"fault_type": [ftype], "target_id": [target], "magnitude": [magnitude]})
        if onset is not None
        else pd.DataFrame({"fault_type": [], "target_id": [], "magnitude": []})
    )
    rid = rid or f"r{seed}"
    return Run(
        rid,
        samples,
        faults,
        {
            "run_id": rid,
            "seed": seed,
            "operating_mode": mode,
            "scenario_sha256": "x",
            "split": split,
        },
        Path("."),
    )


def healthy(seed, x=None, **kw):
    return make_run(x if x is not None else [0.0] * 10, seed=seed, **kw)


@pytest.fixture
def train():
    return [healthy(100), healthy(101)]


def value(ev, metric, condition="OC1", fault="sensor.offset:s1", magnitude=None):
    m = ev.metrics
    sel = (m.metric == metric) & (m.condition == condition) & (m.fault == fault)
    sel &= m.magnitude.isna() if magnitude is None else (m.magnitude == magnitude)
    assert sel.sum() == 1, (metric, condition, fault, magnitude)
    return float(m.loc[sel, "value"].iloc[0])


def test_metrics_match_hand_counts(train):
    # healthy: one alarm at k=3 in 8 scored samples (warm-up k<2 holds an alarm that must not count)
    h = healthy(1, [9, 0, 0, 9, 0, 0, 0, 0, 0, 0], warmup=2)
    # faulty, onset k=4: a false alarm at k=1, detected at k=6 (delay 1.0 s), 4 of 6 alarmed
    f1 = make_run([0, 9, 0, 0, 0, 0, 9, 9, 9, 9], onset=4, seed=2)
    # faulty, onset k=5: never alarms (a miss)
    f2 = make_run([0] * 10, onset=5, seed=3)
    ev = evaluate(Passthrough(), train, [h, f1, f2], n_boot=0)
    assert value(ev, "far_ff") == pytest.approx(1 / 8)
    assert value(ev, "far_pre") == pytest.approx(1 / 9)  # k<4 of f1, k<5 of f2
    assert value(ev, "dr") == pytest.approx(4 / 11)  # 4 of 6 + 0 of 5
    assert value(ev, "pd") == pytest.approx(1 / 2)
    assert value(ev, "dd_median_s") == pytest.approx(1.0)
    assert value(ev, "n_missed") == 1
    # censored mean: the miss contributes its horizon t[9] - t[5] = 2 s
    assert value(ev, "dd_censored_mean_s") == pytest.approx((1.0 + 2.0) / 2)
    # and the same numbers from the metric functions on the same runs
    rd = [
        run_data(r, r.samples["meas.x"].to_numpy(), r.samples["meas.x"].to_numpy() > 5)
        for r in (h, f1, f2)
    ]
    fr = M.far(rd)
    assert (fr.far_ff, fr.far_pre) == (value(ev, "far_ff"), value(ev, "far_pre"))
    assert M.detection_rate(rd) == value(ev, "dr")
    assert M.detection_probability(rd) == value(ev, "pd")
    assert M.false_alarm_events(rd).per_hour == pytest.approx(value(ev, "fa_per_h"))
    s, y = M.pooled_scores(rd)
    assert M.roc_auc(s, y) == value(ev, "roc_auc")


def test_count_decomposition_equals_the_metric_functions(train):
    # the bootstrap resamples per-run counts: on the full set they must give the metric values
    rng = np.random.default_rng(4)
    runs = [
        make_run(rng.normal(size=40) * 3, onset=int(rng.integers(5, 35)), seed=i) for i in range(6)
    ] + [healthy(10 + i, rng.normal(size=40) * 3) for i in range(3)]
    rd = [
        run_data(r, r.samples["meas.x"].to_numpy(), r.samples["meas.x"].to_numpy() > 4)
        for r in runs
    ]
    counts = pd.DataFrame([_counts(r, _Rule(2, 0.5, 7.0)) for r in rd])
    cols = {k: counts[k].to_numpy(float) for k in counts.columns}
    fr = M.far(rd)
    dd = M.detection_delay(rd, 2, 0.5, 7.0)
    expect = {
        "far_ff": fr.far_ff,
        "far_pre": fr.far_pre,
        "dr": M.detection_rate(rd),
        "fa_per_h": M.false_alarm_events(rd).per_hour,
        "pd": M.detection_probability(rd, 2, 0.5, 7.0),
        "dd_median_s": dd.median,
        "dd_p90_s": dd.p90,
        "dd_censored_mean_s": dd.censored_mean,
    }
    for name, want in expect.items():
        assert float(_FROM_COUNTS[name](cols)) == pytest.approx(want, nan_ok=True), name


def test_calibrated_threshold_and_cal_metrics(train):
    # validation statistic 0..99: at alpha = 0.01 one exceedance is allowed, theta = 98
    val = [healthy(50, np.arange(100.0))]
    test = [
        healthy(1, [0, 0, 97.5, 98.5, 0, 0, 0, 0]),
        make_run([0, 0, 0, 0, 99, 99, 0, 0], onset=4, seed=2),
    ]
    ev = evaluate(
        Passthrough(level=1000.0), train, test, val, alpha=0.01, n_boot=0, own_threshold="fit"
    )
    assert ev.theta == 98.0
    assert value(ev, "theta", "all", "all") == 98.0
    # the plug-in's own level (1000) never alarms; at theta one healthy sample in 8 does
    assert value(ev, "far_ff") == 0 and value(ev, "pd") == 0
    assert value(ev, "far_ff_cal") == pytest.approx(1 / 8)
    assert value(ev, "dr_cal") == pytest.approx(2 / 4) and value(ev, "pd_cal") == 1.0
    assert value(ev, "dd_median_cal_s") == 0.0
    assert ev.predictions["alarm_cal"].sum() == 3 and not ev.predictions["alarm"].any()


def test_strata_magnitudes_and_mdm90(train):
    test = [
        healthy(1, mode="OC1"),
        healthy(2, mode="OC2"),
        make_run([0] * 4 + [9] * 6, onset=4, seed=3, magnitude=2.0),
        make_run([0] * 10, onset=4, seed=4, magnitude=1.0),
        make_run([0] * 4 + [9] * 6, onset=4, seed=5, magnitude=2.0, mode="OC2"),
        make_run([0] * 4 + [9] * 6, onset=4, seed=6, ftype="sensor.gain", target="s2", mode="OC2"),
    ]
    ev = evaluate(Passthrough(), train, test, n_boot=0)
    strata = set(map(tuple, ev.table().index))
    assert strata == {
        ("OC1", "sensor.offset:s1"),
        ("OC2", "sensor.offset:s1"),
        ("OC2", "sensor.gain:s2"),
        ("OC2", "all"),
        ("all", "sensor.gain:s2"),
        ("all", "sensor.offset:s1"),
        ("all", "all"),
    }
    # a stratum holds its condition's healthy runs and its fault's faulty runs
    assert ev.table().loc[("OC2", "all"), "n_runs"] == 3
    assert ev.table().loc[("all", "sensor.offset:s1"), "n_runs"] == 5
    assert value(ev, "pd", "OC1", magnitude=1.0) == 0.0
    assert value(ev, "pd", "OC1", magnitude=2.0) == 1.0
    assert value(ev, "mdm90", "OC1") == 2.0
    assert value(ev, "mdm90", "all") == 2.0
    assert value(ev, "pd", "all") == pytest.approx(2 / 3)


def test_bootstrap_intervals(train):
    rng = np.random.default_rng(0)
    test = [make_run(np.r_[np.zeros(5), rng.random(5) * 10], onset=5, seed=i) for i in range(8)]
    test += [healthy(20 + i, rng.random(10) * 6) for i in range(4)]
    a = evaluate(Passthrough(), train, test, n_boot=300, seed=3)
    b = evaluate(Passthrough(), train, test, n_boot=300, seed=3)
    pd.testing.assert_frame_equal(
        a.metrics.drop(columns="value").loc[a.metrics.metric != "fit_s"],
        b.metrics.drop(columns="value").loc[b.metrics.metric != "fit_s"],
    )
    m = a.metrics[a.metrics.metric.isin(["far_ff", "dr", "pd"])]
    assert (m.ci_low <= m.value + 1e-12).all() and (m.value <= m.ci_high + 1e-12).all()
    assert (m.ci_high > m.ci_low).any()
    none = evaluate(Passthrough(), train, test, n_boot=0).metrics
    assert none.ci_low.isna().all()


def test_nan_statistic_never_alarms_and_ranks_lowest(train):
    f = make_run([np.nan, 0, 0, 0, np.nan, 9, 9, 9], onset=4, seed=2)
    ev = evaluate(Passthrough(), train, [f, healthy(1, [0.0] * 8)], n_boot=0)
    assert value(ev, "dr") == pytest.approx(3 / 4)
    assert value(ev, "roc_auc") == pytest.approx(
        M.roc_auc([-1, 0, 0, 0, -1, 9, 9, 9] + [0] * 8, [0] * 4 + [1] * 4 + [0] * 8)
    )


def test_bad_input_is_refused(train):
    f = make_run([0] * 10, onset=4, seed=2)
    with pytest.raises(InputError, match="must be fault-free"):
        evaluate(Passthrough(), [f], [f])
    with pytest.raises(InputError, match="validation runs must be fault-free"):
        evaluate(Passthrough(), train, [f], [f])
    with pytest.raises(InputError, match="alpha"):
        evaluate(Passthrough(), train, [f], alpha=1.5)
    with pytest.raises(InputError, match="persistence"):
        evaluate(Passthrough(), train, [f], m=0)
    # numpy refused a negative bootstrap seed with a traceback after the fit
    for seed in (-1, 2**64, 1.5, True):
        with pytest.raises(InputError, match=r"seed must be an integer from 0 to 2\*\*64 - 1"):
            evaluate(Passthrough(), train, [f], seed=seed)
    with pytest.raises(InputError, match="no test runs"):
        evaluate(Passthrough(), train, [])


def test_split_by_seed_is_deterministic_and_keeps_faulty_runs_for_test():
    runs = [healthy(s) for s in range(40)] + [make_run([0] * 10, onset=3, seed=s) for s in range(5)]
    runs.append(healthy(999, split="val"))
    a, b = split_by_seed(runs), split_by_seed(list(reversed(runs)))
    assert {r.info["seed"] for r in a.train} == {r.info["seed"] for r in b.train}
    assert all(not r.faults.shape[0] for r in a.train + a.val)
    assert sum(r.faults.shape[0] > 0 for r in a.test) == 5
    assert any(r.info["seed"] == 999 for r in a.val)
    assert 15 <= len(a.train) <= 33 and len(a.train) + len(a.val) + len(a.test) == len(runs)


def test_split_by_condition():
    runs = [healthy(s, mode="OC1") for s in range(12)] + [
        healthy(50, mode="OC2"),
        make_run([0] * 10, onset=3, seed=51, mode="OC2"),
        make_run([0] * 10, onset=3, seed=52, mode="OC1"),
    ]
    sp = split_by_condition(runs, "OC1", "OC2", val=0.25)
    assert {r.mode for r in sp.train + sp.val} == {"OC1"} and {r.mode for r in sp.test} == {"OC2"}
    assert len(sp.train) + len(sp.val) == 12 and len(sp.val) >= 1 and len(sp.test) == 2
    with pytest.raises(InputError, match="no run has the test mode 'OC3'"):
        split_by_condition(runs, "OC1", "OC3")


def test_results_are_written_typed(tmp_path, train):
    ev = evaluate(
        Passthrough(),
        train,
        [make_run([0] * 4 + [9] * 6, onset=4, seed=2), healthy(1)],
        [healthy(60)],
        n_boot=10,
    )
    out = ev.write(tmp_path / "res")
    m = pd.read_parquet(out / "metrics.parquet")
    assert m.dtypes["value"] == np.float64 and m.dtypes["n_runs"] == np.int64
    assert set(m.metric) >= {"far_ff", "dr", "pd", "roc_auc", "theta", "far_ff_cal"}
    p = pd.read_parquet(out / "predictions.parquet")
    assert len(p) == 20 and p.dtypes["alarm"] == np.bool_
    assert pd.read_csv(out / "metrics.csv").shape == m.shape
    assert "far_ff" in ev.format() and not math.isnan(ev.theta)


def test_results_are_written_whole_or_not_at_all(tmp_path, train, monkeypatch):
    ev = evaluate(Passthrough(), train, [make_run([0] * 4 + [9] * 6, onset=4, seed=2)], n_boot=0)
    out = ev.write(tmp_path / "res")
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def disk_full(*args, **kwargs):
        raise OSError("No space left on device")

    monkeypatch.setattr(pd.DataFrame, "to_csv", disk_full)  # the third file fails
    with pytest.raises(OSError, match="No space"):
        ev.write(tmp_path / "new")
    with pytest.raises(OSError, match="No space"):
        ev.write(out, overwrite=True)
    # no partial directory, no temporary one, the earlier results as they were
    assert [p.name for p in tmp_path.iterdir()] == ["res"]
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    with pytest.raises(InputError, match="pass --overwrite"):
        ev.write(out)


class Spy(Passthrough):
    """Records the columns it is shown."""

    seen: list = []

    def fit(self, runs):
        Spy.seen = [list(f.columns) for f in runs]
        return super().fit(runs)


def test_plugins_see_only_the_visible_columns(train):
    for r in train:
        for c in (
            "label.x",
            "true.s1.x",
            "state.span1.tension_N",
            "cmd.pull.torque_N_m",
            "ctrl.s1.x_seen_N",
            "ctrl.pi.integral",
            "flag.s1.clipped",
        ):
            r.samples[c] = 0.0
    f = make_run([0] * 10, onset=4, seed=2)
    evaluate(Spy(), train, [f], n_boot=0)
    assert Spy.seen[0] == ["t_s", "meas.x", "flag.s1.clipped"]
    # a protocol with observable drive data adds cmd/act/ctrl, but never the *_seen_* copies
    evaluate(Spy(), train, [f], n_boot=0, drive_data=True)
    assert Spy.seen[0] == [
        "t_s",
        "meas.x",
        "cmd.pull.torque_N_m",
        "ctrl.pi.integral",
        "flag.s1.clipped",
    ]


def test_required_columns_are_checked_before_fit_and_score(train):
    class Needy(Passthrough):
        requires = ("meas.x", "meas.y*")

    with pytest.raises(InputError, match=r"no column matching meas\.y\* \(run r100 in"):
        evaluate(Needy(), train, [healthy(1)])


def test_roles_must_not_share_runs(train):
    with pytest.raises(InputError, match="both a train and a test run"):
        evaluate(Passthrough(), train, [train[0]])


def test_mdm90_is_a_magnitude_at_both_operating_points(train):
    # offsets of -2 and +1: the +1 run is missed at the plug-in's level 5 but caught at theta
    test = [
        make_run([0] * 4 + [9] * 6, onset=4, seed=3, magnitude=-2.0),
        make_run([0] * 4 + [3] * 6, onset=4, seed=4, magnitude=1.0),
        healthy(1),
    ]
    ev = evaluate(
        Passthrough(),
        train,
        test,
        [healthy(60, [0.0] * 10 + [2.0])],
        alpha=0.1,
        n_boot=0,
        own_threshold="fit",
    )
    assert ev.theta == 0.0
    assert value(ev, "mdm90") == 2.0 and value(ev, "mdm90_cal") == 1.0


def test_bad_split_fractions_are_refused():
    with pytest.raises(InputError, match="split fractions must lie in"):
        split_by_condition([healthy(1, mode="OC1"), healthy(2, mode="OC2")], val=1.5)
    with pytest.raises(InputError, match="sum to 1"):
        split_by_seed([healthy(1)], train=0.5, val=0.2, test=0.2)


def test_nan_statistic_never_alarms_at_a_low_theta(train):
    # theta far below every test statistic: every finite sample alarms, the nan ones do not
    f = make_run([np.nan, 0, 0, 0, np.nan, 9, 9, 9], onset=4, seed=2)
    ev = evaluate(Passthrough(), train, [f], [healthy(60, [-100.0] * 10)], n_boot=0)
    assert ev.theta == -100.0
    assert ev.predictions["alarm_cal"].tolist() == [
        False,
        True,
        True,
        True,
        False,
        True,
        True,
        True,
    ]


def test_infinite_and_huge_statistics_keep_their_order(train):
    # +inf is the most anomalous value: every faulty sample above every healthy one gives
    # ROC-AUC = AP = 1 (it ranked lowest, with NaN, before); a NaN still ranks lowest, also
    # when the statistics are beyond 2**53, where (smallest finite - 1) equals the smallest
    h = healthy(1, [0.2] * 20)
    f = make_run([0.2] * 10 + [np.inf] * 5 + [5.0] * 5, onset=10, seed=2)
    ev = evaluate(Passthrough(level=0.5), train, [h, f], n_boot=0)
    assert value(ev, "roc_auc") == 1.0 and value(ev, "pr_auc") == 1.0
    assert value(ev, "dr") == 1.0  # +inf alarms at the plug-in's threshold too
    big = 1e16
    h = healthy(1, [big] * 20)
    f = make_run([big] * 10 + [np.nan] * 5 + [3 * big] * 5, onset=10, seed=2)
    ev = evaluate(Passthrough(level=2 * big), train, [h, f], n_boot=0)
    # 5 NaN positives below all 30 negatives, 5 positives above them: AUC = 5/10
    assert value(ev, "roc_auc") == pytest.approx(0.5)
    f1 = make_run([1.0] * 10 + [np.nan] * 5 + [3.0] * 5, onset=10, seed=2)
    ev1 = evaluate(Passthrough(level=2.0), train, [healthy(1, [1.0] * 20), f1], n_boot=0)
    assert value(ev1, "roc_auc") == value(ev, "roc_auc")  # the same at any scale


def test_infinite_validation_statistics_count_as_exceedances(train):
    # theta keeps the validation FAR at or below alpha: +inf samples exceed any theta, so they
    # are exceedances in the pool (they were dropped, and alarmed at theta anyway)
    pool = np.r_[np.arange(95.0), [np.inf] * 5]
    val = [healthy(5, pool)]
    test = [healthy(7, [0.0] * 10), make_run([0.0] * 5 + [99.0] * 5, onset=5, seed=8)]
    ev = evaluate(Passthrough(), train, test, val, alpha=0.05, n_boot=0)
    # 5 of 100 may exceed: the 5 infinite ones, so theta is the largest finite value
    assert ev.theta == 94.0 and np.mean(pool > ev.theta) == 0.05


def test_a_fault_that_never_acted_leaves_the_run_fault_free(train):
    # a web break ended the run before its fault's onset: its labels are all normal, and
    # the split, the strata and the metrics all treat it as fault-free (it was named after
    # the fault and refused for training, while the metrics counted it as fault-free)
    broken = make_run([0.0, 9.0] + [0.0] * 8, onset=5, seed=2)
    faults = broken.faults.assign(onset_t_s=[50.0])  # after its last sample (4.5 s)
    samples = broken.samples.assign(**{"label.is_faulty": False, "label.primary_type": "normal"})
    never = Run(broken.run_id, samples, faults, broken.info, broken.path)
    from r2rsim.evaluate.harness import acting_faults, fault_key

    assert acting_faults(never).empty and fault_key(never) == "none"
    ev = evaluate(Passthrough(), train, [healthy(1), never], n_boot=0)
    assert "sensor.offset:s1" not in set(ev.metrics.fault), set(ev.metrics.fault)
    assert value(ev, "far_ff", fault="none") == pytest.approx(1 / 20)
    # and it may train: its data is healthy
    evaluate(
        Passthrough(),
        [*train, never],
        [healthy(3), make_run([0] * 5 + [9] * 5, onset=5, seed=4)],
        n_boot=0,
    )
