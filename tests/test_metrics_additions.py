"""Metrics the thesis methods need (issue 16 item 5): VUS-PR against a brute-force reference,
channel hit@n (M13), the steady-state window and per-regime restriction, on hand-made runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from r2rsim.evaluate.metrics import (
    RunData,
    average_precision,
    hit_at_n,
    localization_counts,
    range_pr_auc,
    restrict_to_mode,
    run_hit,
    steady_counts,
    steady_detection,
    steady_detection_rate,
    vus_pr,
)
from r2rsim.limits import MAX_VUS_BUFFER_SAMPLES


def bits(s: str) -> np.ndarray:
    return np.array([c == "1" for c in s])


# --------------------------------------------------------------------------- VUS-PR


def reference_vus(score, y, max_buffer, groups):
    """VUS-PR written out as its definition, sample by sample and threshold by threshold."""
    n = len(score)
    ranges, k = [], 0
    while k < n:  # maximal runs of anomalies within one group
        if y[k]:
            j = k
            while j + 1 < n and y[j + 1] and groups[j + 1] == groups[k]:
                j += 1
            ranges.append((k, j))
            k = j + 1
        else:
            k += 1
    areas = []
    for ell in range(max_buffer + 1):
        w = []
        for k in range(n):
            best = 1.0 if y[k] else 0.0
            for a, b in ranges:
                d = a - k if k < a else k - b
                if groups[a] == groups[k] and not y[k] and 1 <= d <= ell:
                    best = max(best, math.sqrt(1 - d / (ell + 1)))
            w.append(best)
        area = prev = 0.0
        for th in sorted(set(score), reverse=True):
            pred = [x >= th for x in score]
            tp = sum(wk for wk, p in zip(w, pred, strict=True) if p)
            exist = sum(
                any(
                    pred[j] and groups[j] == groups[a]
                    for j in range(max(0, a - ell), min(n, b + ell + 1))
                )
                for a, b in ranges
            )
            recall = min(tp / sum(y), 1.0) * exist / len(ranges)
            area += (recall - prev) * tp / sum(pred)
            prev = recall
        areas.append(area)
    return sum(areas) / len(areas)


@pytest.mark.parametrize("case", range(25))
def test_vus_pr_matches_a_brute_force_reference(case):
    rng = np.random.default_rng(case)
    n = int(rng.integers(20, 70))
    y = np.zeros(n, bool)
    for _ in range(int(rng.integers(1, 4))):  # a few anomaly ranges
        a = int(rng.integers(0, n - 3))
        y[a : a + int(rng.integers(1, 8))] = True
    score = np.round(rng.random(n) + 0.6 * y * rng.random(), 1)  # rounding makes ties
    groups = np.sort(rng.integers(0, 3, n))  # up to three runs
    buf = int(rng.integers(0, 6))
    want = reference_vus(list(score), list(y), buf, list(groups))
    assert vus_pr(score, y, buf, groups=groups) == pytest.approx(want, abs=1e-12)


def test_vus_pr_buffer_zero_single_range_is_average_precision():
    rng = np.random.default_rng(1)
    y = np.zeros(200, bool)
    y[120:160] = True
    s = rng.random(200) + 0.4 * y
    assert range_pr_auc(s, y, 0) == pytest.approx(average_precision(s, y), abs=1e-12)
    assert vus_pr(s, y, 0) == pytest.approx(average_precision(s, y), abs=1e-12)


def test_vus_pr_properties():
    y = bits("0001110000111100")
    perfect = y * 2.0 + 0.5
    for buf in (0, 1, 3, 10):
        assert vus_pr(perfect, y, buf) == 1.0
    rng = np.random.default_rng(2)
    s = rng.random(y.size)
    # a monotone transform of the scores changes nothing
    assert vus_pr(np.exp(3 * s), y, 4) == pytest.approx(vus_pr(s, y, 4), abs=1e-12)
    assert math.isnan(vus_pr(s, np.zeros(y.size, bool), 2))
    # an alarm one sample before a range: credited only with a buffer
    early = bits("0010000000000000") * 1.0
    y1 = bits("0001110000000000")
    assert range_pr_auc(early, y1, 0) < range_pr_auc(early, y1, 1)
    # ranges and buffers do not cross groups: in another run the early alarm earns nothing,
    # as if it were not there
    two_runs = [0] * 3 + [1] * 13
    assert range_pr_auc(early, y1, 1, groups=two_runs) == pytest.approx(
        range_pr_auc(np.zeros(16), y1, 1, groups=two_runs), abs=1e-12
    )
    assert range_pr_auc(early, y1, 1) > range_pr_auc(early, y1, 1, groups=two_runs)
    with pytest.raises(ValueError, match="max_buffer"):
        vus_pr(s, y, -1)


def test_vus_pr_refuses_more_buffer_lengths_than_the_limit():
    # one range-PR AUC per buffer length: 1e9 lengths ran for hours; the limit bounds it
    y = bits("0001110000111100")
    s = np.random.default_rng(3).random(y.size)
    assert 0 <= vus_pr(s, y, MAX_VUS_BUFFER_SAMPLES) <= 1
    for bad in (MAX_VUS_BUFFER_SAMPLES + 1, 10**9, math.inf, math.nan):
        with pytest.raises(ValueError, match="max_buffer must be an integer from 0 to 10000"):
            vus_pr(s, y, bad)


# --------------------------------------------------------------------------- M13


def channel_run(alarm, fault, truth_a, truth_b, top, **kw):
    """A run over channels ('a', 'b'): per-sample truth of each and the top-ranked index."""
    n = len(alarm)
    return RunData(
        t=np.arange(n, dtype=float),
        faulty=bits(fault),
        scored=np.ones(n, bool),
        alarm=bits(alarm),
        channels=("a", "b"),
        channel_truth=np.c_[bits(truth_a), bits(truth_b)],
        ranking=np.array([[int(c)] for c in top]),
        **kw,
    )


def test_hit_at_1_at_the_first_detection_onset():
    # detected at k=4; the ranking there names b (index 1), the faulty channel
    hit = channel_run("0000111", "0001111", "0000000", "0001111", "0001100")
    # detected at k=5 where the ranking names a: a miss, although b is named later
    miss = channel_run("0000011", "0001111", "0000000", "0001111", "1111101")
    # never detected: not counted
    undetected = channel_run("0000000", "0001111", "0001111", "0000000", "0000000")
    # a process fault (no faulty measured channel): not counted
    process = channel_run("0001111", "0001111", "0000000", "0000000", "0000000")
    assert run_hit(hit) == (1, 1) and run_hit(miss) == (0, 1)
    assert run_hit(undetected) == (0, 0) and run_hit(process) == (0, 0)
    assert hit_at_n([hit, miss, undetected, process]) == 0.5
    assert hit_at_n([undetected, process]) != hit_at_n([undetected, process])  # nan
    # an unknown channel (-1) never hits
    assert run_hit(channel_run("0001", "0001", "0000", "0001", "000" + "0")) == (0, 1)


def test_localization_counts_per_alarmed_sample():
    # alarmed fault samples k=4..6; truth on b at k>=4 only (k=3: faulty, severity 0)
    r = channel_run("0001111", "0001111", "0000000", "0000111", "0001101")
    assert localization_counts(r) == (2, 3)  # k=4 and k=6 name b, k=5 names a
    assert localization_counts(channel_run("1", "0", "0", "0", "0")) == (0, 0)


# --------------------------------------------------------------------------- steady state


def test_steady_window_leaves_the_ramp_out():
    # onset k=2, ramp to k=4, steady from k=5 to k=11
    sev = [0, 0, 0.25, 0.5, 0.75] + [1.0] * 7
    r = RunData(
        t=np.arange(12.0),
        faulty=bits("001111111111"),
        scored=np.ones(12, bool),
        alarm=bits("000110011011"),
        severity=sev,
    )
    assert steady_counts(r) == (4, 7)  # k=7, 8, 10, 11; the ramp alarms k=3, 4 are left out
    assert steady_detection_rate([r]) == pytest.approx(4 / 7)
    # the alarm event from the ramp ends at k=4; the next one starts at k=7: delay 2 s
    d = steady_detection(r, m=1)
    assert d.detected and d.k_star == 7 and d.delay == 2.0
    # an alarm running from the ramp into the steady state detects at once (lenient)
    r2 = RunData(
        t=np.arange(12.0),
        faulty=r.faulty,
        scored=r.scored,
        alarm=bits("000111100000"),
        severity=sev,
    )
    assert steady_detection(r2, m=2).delay == 0.0
    # a run that never reaches severity 1 has no steady window
    r3 = RunData(
        t=np.arange(4.0),
        faulty=bits("0111"),
        scored=np.ones(4, bool),
        alarm=bits("0111"),
        severity=[0, 0.2, 0.4, 0.6],
    )
    assert steady_counts(r3) == (0, 0) and steady_detection(r3) is None
    with pytest.raises(ValueError, match="severity"):
        steady_counts(RunData(t=[0.0], faulty=[True], scored=[True], alarm=[True]))


def test_restrict_to_mode_keeps_the_truth():
    r = RunData(
        t=np.arange(6.0),
        faulty=bits("000111"),
        scored=bits("011111"),
        alarm=bits("111111"),
        mode=["OC1"] * 4 + ["OC2"] * 2,
    )
    oc2 = restrict_to_mode(r, "OC2")
    assert list(oc2.scored) == [False] * 4 + [True] * 2
    assert oc2.onset == 3 and oc2.is_faulty
