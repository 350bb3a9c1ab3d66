"""Fault-detection metrics (docs/diagnostics.md §5) on small hand-computed cases.

Runs are written as strings, one character per sample: ``alarm="0011100"`` means the alarm is on
at samples 2..4, ``fault="0000111"`` means the fault is active at samples 4..6. Sample k is at
t = k * period (period 1 s unless stated), and the first ``warm`` samples are unscored.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from r2rsim.evaluate.metrics import (
    RunData,
    apply_threshold,
    average_precision,
    bootstrap_ci,
    calibrate_threshold,
    confirmed,
    detect_run,
    detectability,
    detection_delay,
    detection_probability,
    detection_rate,
    false_alarm_events,
    far,
    fault_free_scores,
    isolation_accuracy,
    pooled_scores,
    roc_auc,
)


def bits(s: str) -> np.ndarray:
    return np.array([c == "1" for c in s], dtype=bool)


def mk(
    alarm: str,
    fault: str | None = None,
    *,
    warm: int = 0,
    period: float = 1.0,
    score=None,
    diag=None,
    fault_type: str = "A",
    magnitude: float = math.nan,
) -> RunData:
    a = bits(alarm)
    f = bits(fault) if fault is not None else np.zeros(a.size, dtype=bool)
    assert f.size == a.size
    return RunData(
        t=period * np.arange(a.size),
        faulty=f,
        scored=np.arange(a.size) >= warm,
        alarm=a,
        score=score,
        diagnosis=diag,
        true_type=np.where(f, fault_type, "normal"),
        magnitude=magnitude,
    )


def long_run(
    n: int,
    alarm_on: list[tuple[int, int]],
    fault: tuple[int, int] | None = None,
    period: float = 1.0,
) -> RunData:
    """A run of n samples with alarms on the inclusive index ranges in alarm_on."""
    a = np.zeros(n, dtype=bool)
    for lo, hi in alarm_on:
        a[lo : hi + 1] = True
    f = np.zeros(n, dtype=bool)
    if fault is not None:
        f[fault[0] : fault[1] + 1] = True
    return RunData(t=period * np.arange(n), faulty=f, scored=np.ones(n, dtype=bool), alarm=a)


# ----------------------------------------------------------------------------- persistence


def test_confirmed_persistence_window():
    a = bits("111011")
    np.testing.assert_array_equal(confirmed(a, 1), a)
    # m=2: pairs (0,1) (1,2) are on, (2,3) breaks, (4,5) on; k=5 has a window of one sample
    np.testing.assert_array_equal(confirmed(a, 2), bits("110010"))
    # m=3: only a[0..2]; the trailing "11" is shorter than m, so not confirmed
    np.testing.assert_array_equal(confirmed(a, 3), bits("100000"))
    assert not confirmed(bits("11"), 3).any()
    with pytest.raises(ValueError):
        confirmed(a, 0)


def test_rundata_validates_shapes():
    with pytest.raises(ValueError, match="alarm"):
        RunData(t=[0.0, 1.0, 2.0], faulty=[0, 0, 0], scored=[1, 1, 1], alarm=[0, 1])
    with pytest.raises(ValueError, match="increasing"):
        RunData(t=[0.0, 0.0], faulty=[0, 0], scored=[1, 1], alarm=[0, 0])
    r = mk("0000110", "0001111")
    assert (r.onset, r.end, r.period) == (3, 6, 1.0)


# ----------------------------------------------------------------------------- M1 / M2


def test_far_strata_ff_vs_pre():
    runs = [
        mk("0100010000"),  # fault-free: 2 alarms / 10 samples
        mk("0010001111", "0000001111"),  # faulty, tau=6: pre-onset 0..5 has 1 alarm / 6
    ]
    r = far(runs)
    assert (r.alarms_ff, r.n_ff) == (2, 10)
    assert r.far_ff == pytest.approx(2 / 10)
    assert (r.alarms_pre, r.n_pre) == (1, 6)
    assert r.far_pre == pytest.approx(1 / 6)
    # pooled over all fault-free samples: (2 + 1) / (10 + 6); in-fault alarms do not count
    assert r.far == pytest.approx(3 / 16)
    # an empty stratum is nan, not 0
    assert math.isnan(far([runs[0]]).far_pre)
    assert math.isnan(far([runs[1]]).far_ff)


def test_fa_per_hour_two_events_on_fault_free_run():
    # 1800 samples at 1 s = 0.5 h of scored fault-free time; events at 100..104 and 700
    run = long_run(1800, [(100, 104), (700, 700)])
    fa = false_alarm_events([run])
    assert fa.n_events == 2
    assert fa.hours == pytest.approx(0.5)
    assert fa.per_hour == pytest.approx(2 / 0.5)  # 4 events per hour
    assert fa.mtbfa_h == pytest.approx(0.25)  # 1 / 4 h


def test_fa_per_hour_counts_events_by_start_sample():
    # faulty run, fault 900..1799: 900 fault-free s = 0.25 h.
    #   100..110  starts fault-free            -> counted
    #   895..905  starts fault-free, runs into the fault -> counted once
    #   1000..1500 starts inside the fault     -> not a false alarm
    faulty = long_run(1800, [(100, 110), (895, 905), (1000, 1500)], fault=(900, 1799))
    fa = false_alarm_events([faulty])
    assert fa.n_events == 2
    assert fa.hours == pytest.approx(0.25)
    assert fa.per_hour == pytest.approx(8.0)  # 2 / 0.25
    # pooled with the 0.5 h fault-free run above (2 events): 4 events / 0.75 h
    both = false_alarm_events([faulty, long_run(1800, [(100, 104), (700, 700)])])
    assert both.per_hour == pytest.approx(4 / 0.75)
    # the period is read from t: the same alarms at 0.5 s per sample give twice the rate
    half = long_run(1800, [(100, 104), (700, 700)], period=0.5)
    assert false_alarm_events([half]).per_hour == pytest.approx(2 / 0.25)
    assert false_alarm_events([long_run(1800, [])]).mtbfa_h == math.inf


# ----------------------------------------------------------------------------- masking


def test_warmup_alarms_change_no_metric():
    # first 3 samples unscored; the alarms there must be invisible
    noisy = [mk("1111000010", warm=3), mk("1110110000", "0000011110", warm=3)]
    clean = [mk("0001000010", warm=3), mk("0000110000", "0000011110", warm=3)]
    # hand values (scored samples 3..9):
    #   fault-free run: alarms at 3 and 8 -> FAR_ff 2/7, 2 events (3 and 8, both starting at
    #   scored samples; with the raw alarm the first event would start in warm-up at 0)
    #   faulty run: tau=5, pre-onset scored samples 3,4 with alarm at 4 -> FAR_pre 1/2;
    #   alarm event 4..5 starts before tau and is on at tau -> detected at tau (delay 0)
    for runs in (noisy, clean):
        r = far(runs)
        assert r.far_ff == pytest.approx(2 / 7)
        assert r.far_pre == pytest.approx(1 / 2)
        assert r.n_masked == 6
        fa = false_alarm_events(runs)
        # fault-free scored samples: 7 (run 1) + 3 (run 2: 3, 4 and 9) = 10 s;
        # events starting at fault-free samples: 3, 8 (run 1) and 4 (run 2)
        assert fa.n_events == 3
        assert fa.hours == pytest.approx(10 / 3600)
        assert detection_rate(runs) == pytest.approx(1 / 4)  # window 5..8: alarm at 5 only
        assert detection_probability(runs) == 1.0
        assert detection_delay(runs).median == 0.0


def test_warmup_excluded_from_detection_rate():
    # fault 1..6 starts inside the 3-sample warm-up: scored window samples 3..6 (4 samples);
    # effective alarms there at 3 and 5 -> DR = 2/4 (unmasked it would be 5/6)
    run = mk("0111010000", "0111111000", warm=3)
    assert detection_rate([run]) == pytest.approx(2 / 4)


# ----------------------------------------------------------------------------- M3


def test_detection_rate_pooled_over_fault_windows():
    runs = [
        mk("0100110110", "0001111100"),  # window 3..7 (5 samples): alarms at 4,5,7 -> 3
        mk("1000000001", "0000011111"),  # window 5..9 (5 samples): alarm at 9      -> 1
        mk("1111111111"),  # fault-free: ignored
    ]
    assert detection_rate(runs) == pytest.approx((3 + 1) / (5 + 5))
    assert math.isnan(detection_rate([runs[2]]))


# ----------------------------------------------------------------------------- M4


def test_an_alarm_on_at_the_onset_detects_with_delay_zero():
    # fault 4..7 (tau=4, eps=7)
    # run 1: the event 2..5 began before tau and is on at tau: detected at tau, delay 0
    # (its samples 2 and 3 stay false alarms before the onset)
    on_at_onset = mk("0011110000", "0000111100")
    d = detect_run(on_at_onset)
    assert d.detected and d.k_star == 4 and d.delay == 0.0
    assert far([on_at_onset]).alarms_pre == 2
    # run 2: the early event 1..2 ended before tau; a new one starts at 7 inside the window
    new_event = mk("0110000110", "0000111100")
    assert detect_run(new_event).k_star == 7
    assert detect_run(new_event).delay == pytest.approx(3.0)  # t7 - t4
    # run 3: nothing in the window
    missed = mk("0110000001", "0000111100")
    assert not detect_run(missed).detected and detect_run(missed).k_star is None
    assert math.isnan(detect_run(missed).delay)
    runs = [on_at_onset, new_event, missed]
    assert detection_probability(runs) == pytest.approx(2 / 3)
    # persistence counts the event from its start: 2..5 is four samples long
    assert detect_run(on_at_onset, m=4).k_star == 4
    assert not detect_run(on_at_onset, m=5).detected


def test_persistence_m3_changes_detection():
    # fault 2..9; events 2..3 (2 samples) and 5..7 (3 samples)
    run = mk("0011011100", "0011111111")
    assert detect_run(run, m=1).k_star == 2 and detect_run(run, m=1).delay == 0.0
    # m=3: the 2-sample event is not confirmed; the first confirmed onset is 5, DD = t5 - t2
    assert detect_run(run, m=3).k_star == 5
    assert detect_run(run, m=3).delay == pytest.approx(3.0)
    # a 2-sample event as the only alarm: detected with m=1, missed with m=3
    short = mk("0011000000", "0011111000")
    assert detection_probability([short], m=1) == 1.0
    assert detection_probability([short], m=3) == 0.0
    # the onset must lie in the window, its confirmation may run past eps (onset 4 = eps)
    assert detect_run(mk("0000111000", "0011100000"), m=3).k_star == 4


def test_grace_period_extends_window():
    # fault 2..4, alarm only at 6; period 0.5 s so t[eps] = 2.0 s and t[6] = 3.0 s
    run = mk("0000001000", "0011100000", period=0.5)
    assert not detect_run(run, h=0.0).detected
    assert detect_run(run, h=0.5).horizon == pytest.approx(1.5)  # t5 - t2, still a miss
    assert not detect_run(run, h=0.5).detected
    d = detect_run(run, h=1.0)  # window 2..6
    assert d.detected and d.delay == pytest.approx(2.0)  # t6 - t2 = 3.0 - 1.0
    # the window is cut at the last sample: 2.0 + 100 s -> horizon t9 - t2 = 3.5 s
    assert detect_run(run, h=100.0).horizon == pytest.approx(3.5)


# ----------------------------------------------------------------------------- M5


def test_delay_stats_with_a_miss():
    runs = [
        mk("000100000000", "011111111110"),  # tau=1, onset 3  -> DD = 2
        mk("000010000000", "001111111110"),  # tau=2, onset 4  -> DD = 2
        mk("000000001000", "011111111110"),  # tau=1, onset 8  -> DD = 7
        mk("100000000000", "000111111100"),  # tau=3, eps=9: miss, horizon t9 - t3 = 6
        mk("010000000000"),  # fault-free: not part of DD
    ]
    dd = detection_delay(runs)
    assert (dd.n_detected, dd.n_missed) == (3, 1)
    assert dd.median == pytest.approx(2.0)  # median of [2, 2, 7]
    assert dd.mean == pytest.approx((2 + 2 + 7) / 3)  # misses are not in the mean
    # p90 by linear interpolation: position 0.9 * 2 = 1.8 -> 2 + 0.8 * (7 - 2) = 6
    assert dd.p90 == pytest.approx(6.0)
    # censored mean: the miss contributes its horizon 6 -> (2 + 2 + 7 + 6) / 4
    assert dd.censored_mean == pytest.approx(17 / 4)
    assert detection_probability(runs) == pytest.approx(3 / 4)
    only_miss = detection_delay([runs[3]])
    assert math.isnan(only_miss.median) and only_miss.censored_mean == pytest.approx(6.0)


# ----------------------------------------------------------------------------- M6


def test_calibrated_threshold_far_below_alpha():
    rng = np.random.default_rng(7)
    # two validation fault-free runs; their 2 warm-up samples score 1e6 and must be ignored
    runs = []
    for _ in range(2):
        s = rng.normal(size=500)
        s[:2] = 1e6
        runs.append(
            RunData(
                t=np.arange(500.0),
                faulty=np.zeros(500, bool),
                scored=np.arange(500) >= 2,
                alarm=np.zeros(500, bool),
                score=s,
            )
        )
    pool = fault_free_scores(runs)
    assert pool.size == 996 and pool.max() < 1e6
    for alpha in (0.01, 0.05, 0.29):
        theta = calibrate_threshold(pool, alpha)
        far_ff = far(apply_threshold(runs, theta)).far_ff
        assert far_ff <= alpha
        # theta is the smallest score that achieves it: floor(alpha * 996) exceedances
        assert (pool > theta).sum() == math.floor(alpha * 996)
        assert (pool >= theta).sum() > alpha * pool.size


def test_calibrated_threshold_hand_cases_and_ties():
    s = np.arange(100.0)
    # alpha = 0.05: 5 exceedances allowed -> theta = 94, alarms at 95..99
    assert calibrate_threshold(s, 0.05) == 94.0
    # 0.29 * 100 is 28.999999999999996 in floating point; still 29 exceedances -> theta = 70
    assert calibrate_threshold(s, 0.29) == 70.0
    assert calibrate_threshold(s, 0.0) == 99.0
    tied = [1.0, 2.0, 2.0, 2.0, 3.0]
    # alpha 0.2: 1 exceedance -> theta = 2 (only the 3 alarms): FAR 1/5
    assert calibrate_threshold(tied, 0.2) == 2.0
    # alpha 0.4: 2 allowed, but theta = 1 would alarm 4/5 -> ties keep theta at 2, FAR 1/5
    assert calibrate_threshold(tied, 0.4) == 2.0
    with pytest.raises(ValueError):
        calibrate_threshold(s, 1.0)


# ----------------------------------------------------------------------------- M7


def test_roc_auc_and_average_precision_with_a_tie():
    s = [0.1, 0.4, 0.4, 0.8]
    y = [0, 0, 1, 1]
    # pairs (pos, neg): 0.4 > 0.1 -> 1, 0.4 = 0.4 -> 1/2, 0.8 beats both -> 2; total 3.5 / 4
    assert roc_auc(s, y) == pytest.approx(0.875)
    # thresholds 0.8: P = 1/1, R = 1/2; 0.4: P = 2/3, R = 2/2; 0.1: R unchanged
    # AP = (1/2 - 0) * 1 + (1 - 1/2) * 2/3 = 5/6 (positive-first tie breaking would give 1)
    assert average_precision(s, y) == pytest.approx(5 / 6)
    assert roc_auc([0.2, 0.9], [0, 1]) == 1.0 and roc_auc([0.9, 0.2], [0, 1]) == 0.0
    assert math.isnan(roc_auc([0.1, 0.2], [0, 0]))
    assert math.isnan(average_precision([0.1, 0.2], [0, 0]))


def test_ranking_metrics_pooled_over_scored_samples():
    # the unscored warm-up sample of run A (score 0.9, negative) must not enter the pool
    a = RunData(
        t=[0.0, 1.0, 2.0],
        faulty=[0, 0, 0],
        scored=[0, 1, 1],
        alarm=[0, 0, 0],
        score=[0.9, 0.1, 0.4],
    )
    b = RunData(t=[0.0, 1.0], faulty=[1, 1], scored=[1, 1], alarm=[0, 0], score=[0.4, 0.8])
    s, y = pooled_scores([a, b])
    np.testing.assert_array_equal(s, [0.1, 0.4, 0.4, 0.8])
    np.testing.assert_array_equal(y, [False, False, True, True])
    assert roc_auc(s, y) == pytest.approx(0.875)  # with 0.9 included it would be 3.5 / 6


# ----------------------------------------------------------------------------- M9


def test_isolation_accuracy_sample_weighted():
    n = "normal"
    runs = [
        # fault A at 2..5; alarm at 1..5 (1 is pre-onset, excluded);
        # window alarms 2,3,4,5 with diagnoses B, A, A, unknown -> 2 correct of 4
        mk("0111110", "0011110", fault_type="A", diag=[n, "A", "B", "A", "A", "unknown", n]),
        # fault B at 1..3; alarms at 2, 3 diagnosed B, B -> 2 of 2; the unalarmed sample 1
        # (diagnosed A) does not count
        mk("0011000", "0111000", fault_type="B", diag=[n, "A", "B", "B", n, n, n]),
        mk("1100000", diag=["A"] * 7),  # fault-free: ignored
    ]
    assert isolation_accuracy(runs) == pytest.approx((2 + 2) / (4 + 2))


def test_isolation_accuracy_masking_gaps_and_missing_diagnosis():
    n = "normal"
    # warm-up of 2 hides the wrong diagnosis at 1; intermittent fault A at 1..2 and 4..5, the
    # gap sample 3 is still judged against A: alarms at 2,3,4 diagnosed A, A, B -> 2 of 3
    run = mk("0111100", "0110110", warm=2, fault_type="A", diag=[n, "B", "A", "A", "B", n, n])
    assert isolation_accuracy([run]) == pytest.approx(2 / 3)
    assert math.isnan(isolation_accuracy([mk("0110000", "0111000")]))


# ----------------------------------------------------------------------------- M15


def test_detectability_mdm90():
    mags = [0.5] * 10 + [1.0] * 10 + [2.0] * 10 + [math.nan] * 3
    det = [True] * 5 + [False] * 5 + [True] * 9 + [False] + [True] * 10 + [True] * 3
    res = detectability(mags, det)
    # P_D: 0.5 -> 5/10, 1.0 -> 9/10, 2.0 -> 10/10; nan magnitudes (fault-free runs) dropped
    np.testing.assert_allclose(res.table["magnitude"], [0.5, 1.0, 2.0])
    np.testing.assert_allclose(res.table["p_d"], [0.5, 0.9, 1.0])
    assert res.table["n_runs"].tolist() == [10, 10, 10]
    assert res.mdm == 1.0  # 0.9 >= 0.9 counts
    assert detectability(mags, det, level=0.95).mdm == 2.0
    # sorted by |m|: a negative magnitude -0.8 with P_D 1 beats +1.0
    signed = detectability(mags + [-0.8] * 4, det + [True] * 4)
    assert signed.table["magnitude"].tolist() == [0.5, -0.8, 1.0, 2.0]
    assert signed.mdm == -0.8
    assert math.isnan(detectability([0.5, 1.0], [False, False]).mdm)


def test_detectability_from_run_detections():
    runs = [
        mk("0011000", "0011100", magnitude=1.0),
        mk("0000000", "0011100", magnitude=1.0),
        mk("0010000", "0011100", magnitude=3.0),
    ]
    dets = [detect_run(r) for r in runs]
    res = detectability([d.magnitude for d in dets], [d.detected for d in dets])
    # 1.0 -> 1/2, 3.0 -> 1/1
    np.testing.assert_allclose(res.table["p_d"], [0.5, 1.0])
    assert res.mdm == 3.0


# ----------------------------------------------------------------------------- bootstrap


def test_bootstrap_ci_deterministic_and_brackets_estimate():
    values = [0.0, 1.0, 0.0, 1.0, 1.0]
    a = bootstrap_ci(values, n_boot=500, seed=3)
    b = bootstrap_ci(values, n_boot=500, seed=3)
    assert a == b
    assert a.estimate == pytest.approx(0.6)
    assert 0.0 <= a.low < a.estimate < a.high <= 1.0
    # with continuous values a different seed gives a different interval
    cont = np.random.default_rng(0).normal(size=20)
    assert bootstrap_ci(cont, seed=1) != bootstrap_ci(cont, seed=2)
    # constant per-run values: every replicate is 0.5
    c = bootstrap_ci([0.5] * 4, n_boot=50)
    assert (c.low, c.high) == (0.5, 0.5)
    # two runs {0, 1}: replicate means 0, 1/2, 1 with probabilities 1/4, 1/2, 1/4, so the
    # 30th and 70th percentiles (level 0.4) are both 1/2, and the 95% interval is [0, 1]
    assert (
        bootstrap_ci([0.0, 1.0], n_boot=4000, level=0.4).low,
        bootstrap_ci([0.0, 1.0], n_boot=4000, level=0.4).high,
    ) == (0.5, 0.5)
    wide = bootstrap_ci([0.0, 1.0], n_boot=4000)
    assert (wide.low, wide.high) == (0.0, 1.0)


def test_bootstrap_ci_resamples_runs_with_a_callable():
    det = mk("0011000", "0011100")
    miss = mk("0000000", "0011100")
    runs = [det, miss, det, det]
    sizes = []

    def p_d(rs):
        sizes.append(len(rs))
        return detection_probability(rs)

    ci = bootstrap_ci(p_d, runs, n_boot=200, seed=1)
    assert ci.estimate == pytest.approx(3 / 4)
    assert set(sizes) == {4}  # each replicate draws 4 runs, not samples
    assert ci.low <= 0.75 <= ci.high and ci.n_valid == 200
    assert ci == bootstrap_ci(detection_probability, runs, n_boot=200, seed=1)
    # a replicate without a faulty run gives nan and is left out of the percentiles
    ff = mk("0000000")
    mixed = bootstrap_ci(detection_probability, [det, ff], n_boot=200, seed=0)
    assert 0 < mixed.n_valid < 200 and mixed.low == mixed.high == 1.0
