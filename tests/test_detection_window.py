"""The bounded detection window, the null detection rate and the MDM90 significance test
(docs/diagnostics.md §5.1): hand-built alarm sequences with known answers, a random detector
whose P_D must equal its null rate, and the harness's causality and calibration marks."""

from __future__ import annotations

import math
import zlib

import numpy as np
import pandas as pd
import pytest
from scipy.stats import binom
from sklearn.metrics import average_precision_score, roc_auc_score
from test_harness import Passthrough, healthy, make_run, value

from r2rsim.cli import build_parser
from r2rsim.diagnostics import Diagnostic
from r2rsim.errors import InputError, PluginError
from r2rsim.evaluate import metrics as M
from r2rsim.evaluate.harness import evaluate
from r2rsim.report._diagnostics import results_table


def run(n, alarm_on=(), fault=None, period=1.0, severity=None, scored=None) -> M.RunData:
    """n samples at ``period``; alarms on the inclusive index ranges; fault (lo, hi)."""
    a = np.zeros(n, bool)
    for lo, hi in alarm_on:
        a[lo : hi + 1] = True
    f = np.zeros(n, bool)
    if fault is not None:
        f[fault[0] : fault[1] + 1] = True
    return M.RunData(
        t=period * np.arange(n),
        faulty=f,
        scored=np.ones(n, bool) if scored is None else scored,
        alarm=a,
        severity=severity,
    )


# ----------------------------------------------------------------------------- the window


def test_a_fault_that_never_ends_is_detected_only_within_w():
    # fault from sample 10 to the end of a 100 s run at 1 Hz: the window is [10, 30] at W = 20
    late = run(100, [(35, 40)], fault=(10, 99))
    assert late.window_end(w=20.0) == 30
    d = M.detect_run(late, w=20.0)
    assert not d.detected and d.horizon == 20.0
    # the unbounded window of earlier versions counted the alarm at 35 as a detection
    assert M.detect_run(late, w=math.inf).k_star == 35
    assert M.detect_run(run(100, [(30, 31)], fault=(10, 99)), w=20.0).k_star == 30
    # the default is DETECTION_WINDOW_S
    assert M.DETECTION_WINDOW_S == 20.0
    assert M.detect_run(late).horizon == 20.0


def test_the_window_ends_at_the_fault_end_plus_grace_when_that_comes_first():
    r = run(100, fault=(10, 15))
    assert r.window_end(h=0.0) == 15 and r.window_end(h=2.0) == 17
    assert run(100, fault=(90, 99)).window_end(h=5.0) == 99  # the run's end


def test_the_window_counts_from_the_end_of_a_ramp():
    # a degradation ramping in over samples 10..29 (severity 1 from 30): W counts from 30
    sev = np.clip((np.arange(100) - 9) / 21.0, 0.0, 1.0)
    r = run(100, [(45, 47)], fault=(10, 99), severity=sev)
    assert r.full_onset() == 30 and r.window_end(w=20.0) == 50
    d = M.detect_run(r, w=20.0)
    assert d.detected and d.delay == 35.0
    # a fault that never develops fully is watched to its end
    never = run(50, fault=(10, 49), severity=np.clip((np.arange(50) - 9) / 100, 0, 1))
    assert never.full_onset() == 49 and never.window_end(w=5.0) == 49


def test_an_alarm_raised_before_a_step_and_kept_on_is_detected_with_delay_zero():
    # 100 Hz; the alarm rises 1 s before the step at 20 s and stays on (a centred filter)
    n, tau = 4000, 2000
    r = run(n, [(tau - 100, n - 1)], fault=(tau, n - 1), period=0.01)
    for m in (1, 3, 50):
        d = M.detect_run(r, m=m)
        assert d.detected and d.k_star == tau and d.delay == 0.0
    # its 100 samples before the onset are false alarms nonetheless
    assert M.far([r]).alarms_pre == 100 and M.false_alarm_events([r]).n_events == 1


def test_window_settings_are_checked():
    with pytest.raises(ValueError, match="detection window"):
        run(10, fault=(2, 5)).window_end(w=0.0)
    with pytest.raises(InputError, match="detection window must be a time > 0 s"):
        evaluate(Passthrough(), [healthy(100)], [healthy(1)], detection_window=-1.0)
    with pytest.raises(InputError, match="own_threshold must be one of val, fit"):
        evaluate(Passthrough(), [healthy(100)], [healthy(1)], own_threshold="never")


def test_the_command_line_default_is_the_metrics_default():
    args = build_parser().parse_args(["diagnose", "--method", "pca", "--data", "x"])
    assert args.detection_window == M.DETECTION_WINDOW_S
    assert args.own_threshold == "val"


# ----------------------------------------------------------------------------- the null rate


def test_null_detection_by_hand():
    # a fault-free run of 60 s at 1 Hz: a confirmed (m = 3) event 12..14, a short one at 41
    h = run(60, [(12, 14), (41, 41)])
    windows = [(10.0, 5.0), (40.0, 5.0), (20.0, 5.0), (58.0, 10.0), (70.0, 5.0)]
    # [10, 15] holds 12..14; [40, 45] only a one-sample event; [20, 25] nothing;
    # [58, 59] (cut at the run's end) nothing; [70, ...] lies past the run: not eligible
    assert M.null_detection(h, windows, m=3) == (1, 4)
    assert M.null_detection(h, windows, m=1) == (2, 4)
    assert M.null_detection_rate([h, h], windows, m=3) == pytest.approx(2 / 8)
    # an event on at the pretend onset counts, as it does for a real one
    assert M.null_detection(run(60, [(5, 30)]), [(10.0, 5.0)], m=3) == (1, 1)
    # the pretend windows are the real ones: (t_tau, t_w - t_tau) of the eligible faulty runs
    f1 = run(60, fault=(10, 59))
    f2 = run(60, fault=(40, 44))
    unscored = run(60, fault=(3, 5), scored=np.arange(60) > 8)
    assert M.detection_windows([f1, f2, unscored, h], w=20.0) == [(10.0, 20.0), (40.0, 4.0)]
    with pytest.raises(ValueError, match="fault-free"):
        M.null_detection(f1, windows)


def test_pd_null_and_mdm90_in_the_harness():
    # statistic = meas.x, own level 5 (fit threshold kept). Faults from sample 4 (dt 0.5 s)
    train = [healthy(100), healthy(101)]
    flat = [0.0] * 20
    # fault-free test runs: one alarms over samples 3..6 (on at the pretend onset at 2 s),
    # one never: pd_null = 1/2 for every window starting at 2 s
    noisy = healthy(1, [0, 0, 0, 9, 9, 9, 9] + [0] * 13)
    quiet = healthy(2, flat)
    big = [make_run([0] * 4 + [9] * 16, onset=4, seed=10 + i, magnitude=2.0) for i in range(5)]
    small = [
        make_run([0] * 4 + [9] * 16, onset=4, seed=20 + i, magnitude=1.0) for i in range(4)
    ] + [make_run(flat, onset=4, seed=30, magnitude=1.0)]
    ev = evaluate(
        Passthrough(), train, [noisy, quiet, *big, *small], n_boot=0, m=2, own_threshold="fit"
    )
    assert value(ev, "pd") == pytest.approx(9 / 10)
    assert value(ev, "pd_null") == pytest.approx(0.5)
    assert value(ev, "pd", magnitude=2.0) == 1.0 and value(ev, "pd", magnitude=1.0) == 0.8
    assert value(ev, "pd_null", magnitude=1.0) == pytest.approx(0.5)
    # magnitude 2: 5 of 5 against p0 = 1/2, p = 1/32 < 0.05: the MDM90
    assert value(ev, "mdm90") == 2.0
    # four runs of 4 are not enough against p0 = 1/2 (p = 1/16): no MDM90
    ev4 = evaluate(
        Passthrough(), train, [noisy, quiet, *big[:4], *small], n_boot=0, m=2, own_threshold="fit"
    )
    assert value(ev4, "pd", magnitude=2.0) == 1.0
    assert (ev4.metrics["metric"] == "mdm90").sum() == 0
    # without fault-free test runs there is no null rate, and so no MDM90
    ev0 = evaluate(Passthrough(), train, [*big, *small], n_boot=0, m=2, own_threshold="fit")
    assert not ev0.metrics["metric"].isin(["pd_null", "mdm90"]).any()


def test_detectability_with_a_null_rate():
    mag = [1.0] * 10 + [2.0] * 10 + [3.0] * 10
    det = [True] * 9 + [False] + [True] * 10 + [True] * 10
    curve = M.detectability(mag, det, null={1.0: 0.2, 2.0: 0.95, 3.0: 0.5})
    t = curve.table.set_index("magnitude")
    assert t.loc[1.0, "p_value"] == pytest.approx(binom.sf(8, 10, 0.2))
    assert t.loc[2.0, "p_value"] == pytest.approx(0.95**10)
    assert list(t["significant"]) == [True, False, True]
    assert curve.mdm == 1.0
    assert M.detectability(mag, det, null={1.0: 0.9, 2.0: 0.95, 3.0: 0.5}).mdm == 3.0
    assert math.isnan(M.detectability(mag, det, null={}).mdm)  # no null: no MDM


# ----------------------------------------------------------------------------- chance


class RandomAlarm(Diagnostic):
    """Alarms at random: an i.i.d. uniform statistic per sample (seeded by the run's data),
    so that its alarms at the threshold calibrated at alpha are Bernoulli(alpha)."""

    name = "random-alarm"
    requires = ("meas.x",)

    def __init__(self, random_state: int = 0):
        self.random_state = random_state

    def fit(self, runs):
        self.columns_ = self.required_columns(self._frames(runs)[0])
        self.threshold_ = 0.99
        return self

    def score(self, run):
        self._check_fitted()
        f = self._frames(run)[0]
        key = zlib.crc32(f["meas.x"].to_numpy().tobytes())  # the same in every process
        rng = np.random.default_rng([self.random_state, key])
        return pd.DataFrame({"statistic": rng.random(len(f))}, index=f.index)


@pytest.mark.parametrize("rate, m", [(0.0002, 1), (0.0006, 1), (0.03, 2)])
def test_a_random_detector_scores_its_null_rate(rate, m):
    # 300 faulty and 300 fault-free runs of 30 s at 100 Hz, onsets drawn in 5-15 s; the
    # alarm is Bernoulli(rate) whatever the fault: P_D must equal pd_null within the
    # binomial scatter of both estimates
    rng = np.random.default_rng(7)
    n, dt = 3000, 0.01
    t = dt * np.arange(n)
    ok = np.ones(n, bool)
    faulty, clean = [], []
    for _ in range(300):
        tau = int(rng.integers(500, 1500))
        f = np.arange(n) >= tau
        faulty.append(M.RunData(t=t, faulty=f, scored=ok, alarm=rng.random(n) < rate))
        clean.append(
            M.RunData(t=t, faulty=np.zeros(n, bool), scored=ok, alarm=rng.random(n) < rate)
        )
    pd_ = M.detection_probability(faulty, m=m)
    p0 = M.null_detection_rate(clean, M.detection_windows(faulty), m=m)
    # expected: 1 - P(no confirmed event in a window of ~1500-2500 samples)
    assert 0.05 < p0 < 0.95
    sd = math.sqrt(p0 * (1 - p0) / 300)
    assert abs(pd_ - p0) < 4 * sd * math.sqrt(2), (pd_, p0)


def test_a_random_plugin_gets_its_null_rate_and_no_mdm90():
    rng = np.random.default_rng(3)

    def x(n=2000):
        return rng.normal(size=n)

    train = [healthy(100 + i, x(), dt=0.01) for i in range(2)]
    val = [healthy(200 + i, x(), dt=0.01) for i in range(3)]
    test = [healthy(300 + i, x(), dt=0.01) for i in range(80)]
    test += [
        make_run(
            x(),
            onset=int(rng.integers(300, 800)),
            seed=400 + i,
            dt=0.01,
            magnitude=float(1 + i % 3),
        )
        for i in range(120)
    ]
    ev = evaluate(RandomAlarm(), train, test, val, alpha=0.001, m=1, n_boot=200)
    pd_, p0 = value(ev, "pd"), value(ev, "pd_null")
    row = ev.metrics[
        (ev.metrics.metric == "pd_null")
        & ev.metrics.magnitude.isna()
        & (ev.metrics.condition == "OC1")
        & (ev.metrics.fault == "sensor.offset:s1")
    ].iloc[0]
    # P_D and the null rate differ by no more than the binomial scatter of both: 120 faulty
    # runs, and 80 fault-free runs (the pretend windows on one run overlap, so the null rate
    # is worth about one trial per run); its bootstrap interval is reported
    sd = math.sqrt(p0 * (1 - p0) * (1 / 120 + 1 / 80))
    assert 0.3 < p0 < 0.95 and abs(pd_ - p0) < 3 * sd, (pd_, p0)
    assert row.ci_low <= p0 <= row.ci_high
    assert (ev.metrics["metric"] == "mdm90").sum() == 0
    assert (ev.metrics["metric"] == "mdm90_cal").sum() == 0
    # its own threshold was recalibrated on the val runs: own and theta alarms coincide
    assert ev.settings["own_threshold"] == "val"
    assert value(ev, "far_ff") == value(ev, "far_ff_cal")


# ----------------------------------------------------------------------------- contract marks


class CentredMean(Passthrough):
    """An offline method: a centred moving average reads two samples ahead."""

    name = "centred"
    causal = False

    def score(self, run):
        s = super().score(run)
        return s.assign(statistic=s["statistic"].rolling(5, center=True, min_periods=1).mean())


def test_an_offline_method_is_marked_in_every_output():
    train = [healthy(100), healthy(101)]
    test = [healthy(1), make_run([0] * 4 + [9] * 6, onset=4, seed=2)]
    ev = evaluate(CentredMean(), train, test, n_boot=0)
    assert ev.settings["causal"] is False and not ev.metrics["causal"].any()
    assert "OFFLINE method" in ev.format()
    assert set(results_table(ev.metrics)["series"]) == {"centred (offline)"}
    online = evaluate(Passthrough(), train, test, n_boot=0)
    assert online.metrics["causal"].all() and "OFFLINE" not in online.format()


def test_the_own_threshold_is_recalibrated_on_the_val_runs():
    train = [healthy(100), healthy(101)]
    val = [healthy(50, np.arange(100.0))]
    test = [
        healthy(1, [0, 0, 97.5, 98.5, 0, 0, 0, 0]),
        make_run([0, 0, 0, 0, 99, 99, 0, 0], onset=4, seed=2),
    ]
    kept = evaluate(Passthrough(level=1000.0), train, test, val, n_boot=0, own_threshold="fit")
    moved = evaluate(Passthrough(level=1000.0), train, test, val, n_boot=0)
    assert value(kept, "pd") == 0.0 and value(moved, "pd") == 1.0
    assert value(moved, "far_ff") == pytest.approx(1 / 8)  # the val quantile, 98
    assert "own threshold recalibrated on val" in moved.format()
    assert "own threshold from fit" in kept.format()

    class NoCalibrate:
        """A plug-in that is not a Diagnostic and has no calibrate."""

        def __init__(self):
            pass

        def get_params(self, deep=True):
            return {}

        def fit(self, runs):
            return self

        def required_columns(self, frame):
            return ["meas.x"]

        def score(self, run):
            return pd.DataFrame({"statistic": run["meas.x"].to_numpy()}, index=run.index)

        def decide(self, scores):
            return scores["statistic"] > 5

    with pytest.raises(PluginError, match="has no calibrate"):
        evaluate(NoCalibrate(), train, test, val, n_boot=0)


# ----------------------------------------------------------------------------- AUC, AP


def test_roc_auc_and_average_precision_agree_with_scikit_learn():
    rng = np.random.default_rng(11)
    for _ in range(5):
        y = rng.random(500) < 0.3
        s = np.round(rng.normal(size=500) + y, 1)  # ties on purpose
        assert M.roc_auc(s, y) == pytest.approx(roc_auc_score(y, s), abs=1e-12)
        assert M.average_precision(s, y) == pytest.approx(average_precision_score(y, s), abs=1e-12)


def test_pd_steady_has_its_null_rate():
    # a fault from sample 4 (2 s at dt 0.5 s) ramping to full size at sample 10 (5 s): the
    # window of pd is [2 s, 5 s + W], that of pd_steady [5 s, 5 s + W], W = 2 s. The fault-free
    # run alarms over samples 4..6 (2-3 s) only: chance "detects" the first window, not the
    # steady one
    train = [healthy(100), healthy(101)]
    sev = np.clip((np.arange(20) - 3) / 7.0, 0.0, 1.0)
    f = make_run([0] * 10 + [9] * 10, onset=4, seed=2)
    f.samples["label.severity"] = np.where(np.arange(20) >= 4, sev, 0.0)
    h = healthy(1, [0] * 4 + [9] * 3 + [0] * 13)
    h.samples["label.severity"] = 0.0
    ev = evaluate(
        Passthrough(),
        train,
        [h, f],
        n_boot=0,
        m=2,
        window="steady",
        detection_window=2.0,
        own_threshold="fit",
    )
    assert value(ev, "pd") == 1.0 and value(ev, "pd_null") == 1.0
    assert value(ev, "pd_steady") == 1.0 and value(ev, "pd_steady_null") == 0.0
