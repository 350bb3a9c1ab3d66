"""r2rsim.evaluate.splits: the seed and condition splits of a pool of runs.

The runs are made by hand (a few samples each, as in test_harness.py): a split looks only at
their seeds, modes, fault labels and ``runs.split``. The expected counts are worked out by
hand from the rule (largest remainders, at least one run per role), not by calling it.
"""

from __future__ import annotations

import hashlib
import random
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from r2rsim.dataset.read import Run
from r2rsim.errors import InputError
from r2rsim.evaluate.splits import (
    Split,
    apportion,
    is_faulty,
    no_training_run,
    split_by_condition,
    split_by_seed,
)

from conftest import REPO

N_SAMPLES = 6
DT_S = 0.5


def _samples(onset: int | None) -> pd.DataFrame:
    k = np.arange(N_SAMPLES)
    faulty = k >= onset if onset is not None else np.zeros(N_SAMPLES, bool)
    return pd.DataFrame(
        {
            "k": k,
            "t_s": k * DT_S,
            "label.is_faulty": faulty,
            "label.score_mask": np.ones(N_SAMPLES, bool),
        }
    ).set_index("k", drop=False)


#: shared by the fault-free runs (a split never changes a run): thousands of runs stay cheap
HEALTHY_SAMPLES = _samples(None)
NO_FAULTS = pd.DataFrame({"fault_type": [], "target_id": [], "onset_t_s": []})


def make_run(
    seed: int,
    *,
    mode: str | None = "OC1",
    onset: int | None = None,
    split: str | None = None,
    rid: str | None = None,
    fault_onset_s: float | None = None,
) -> Run:
    """A run of N_SAMPLES samples. ``onset``: faulty from that sample on (labels and a fault
    row); ``fault_onset_s``: a fault row with that onset time and no faulty sample."""
    onsets = (
        [onset * DT_S]
        if onset is not None
        else [fault_onset_s]
        if fault_onset_s is not None
        else []
    )
    faults = (
        pd.DataFrame(
            {
                "fault_type": ["sensor.offset"] * len(onsets),
                "target_id": ["s1"] * len(onsets),
                "onset_t_s": onsets,
            }
        )
        if onsets
        else NO_FAULTS
    )
    samples = _samples(onset) if onset is not None else HEALTHY_SAMPLES
    rid = rid or f"{mode}_{'f' if onset is not None else 'h'}_s{seed}"
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


def counts(split: Split) -> tuple[int, int, int]:
    return len(split.train), len(split.val), len(split.test)


def seeds(runs) -> set[int]:
    return {int(r.info["seed"]) for r in runs}


def ids(split: Split) -> tuple[set, set, set]:
    return tuple({r.run_id for r in getattr(split, role)} for role in ("train", "val", "test"))


def by_mode(runs) -> dict[str, int]:
    return dict(Counter(r.mode for r in runs))


# --------------------------------------------------------------------------- apportion
#: train/val/test of n runs at 60/20/20, by hand: shares 0.6n, 0.2n, 0.2n rounded down, the
#: rest to the largest fractional parts (train before val before test on a tie), then at
#: least one run per role as far as n allows (n = 3: 2/1/0 becomes 1/1/1)
BY_HAND_60_20_20 = {
    0: (0, 0, 0),
    1: (1, 0, 0),
    2: (1, 1, 0),
    3: (1, 1, 1),
    4: (2, 1, 1),
    5: (3, 1, 1),
    6: (4, 1, 1),
    7: (4, 2, 1),
    8: (5, 2, 1),
    9: (5, 2, 2),
    10: (6, 2, 2),
    11: (7, 2, 2),
    13: (8, 3, 2),
    20: (12, 4, 4),
    40: (24, 8, 8),
}


@pytest.mark.parametrize("n,expected", sorted(BY_HAND_60_20_20.items()))
def test_apportion_by_hand(n, expected):
    assert tuple(apportion(n, (0.6, 0.2, 0.2))) == expected


@pytest.mark.parametrize(
    "n,expected",
    [
        (1, (1, 0, 0)),
        (2, (1, 1, 0)),
        (4, (3, 1, 0)),
        (5, (4, 1, 0)),
        (6, (5, 1, 0)),
        (7, (5, 2, 0)),
        (20, (15, 5, 0)),
    ],
)
def test_apportion_a_two_way_split(n, expected):
    # 6 runs at 75/25: 4.5 and 1.5, the tie of the remainders goes to train
    assert tuple(apportion(n, (0.75, 0.25, 0.0))) == expected


def test_apportion_gives_the_minimum_before_the_share():
    # 3 runs at 90/5/5: the shares 2.7/0.15/0.15 round to 3/0/0; val and test each take one
    # run from train, so train is 1.7 runs below its share
    assert apportion(3, (0.9, 0.05, 0.05)) == [1, 1, 1]
    assert apportion(2, (0.9, 0.05, 0.05)) == [1, 1, 0]
    assert apportion(5, (0.0, 0.5, 0.5)) == [0, 3, 2]  # a role of fraction 0 gets nothing
    assert apportion(4, (1.0, 0.0, 0.0)) == [4, 0, 0]


# --------------------------------------------------------------------------- by seed
def test_the_counts_the_issue_asks_for():
    assert counts(split_by_seed([make_run(s) for s in range(1, 21)])) == (12, 4, 4)
    assert counts(split_by_seed([make_run(s) for s in range(1, 6)])) == (3, 1, 1)


def check_counts(split: Split, n: int, fractions) -> None:
    got = counts(split)
    assert sum(got) == n
    train, val, test = ids(split)
    assert len(train | val | test) == n  # every run in exactly one role
    for count, fraction in zip(got, fractions, strict=True):
        assert abs(count - fraction * n) < 1, (n, got, fractions)
    want_min = [1 if f > 0 else 0 for f in fractions]
    positive = [i for i, f in enumerate(fractions) if f > 0][:n]
    for i in positive:
        assert got[i] >= want_min[i], (n, got)


@pytest.mark.parametrize(
    "fractions",
    [(0.6, 0.2, 0.2), (0.5, 0.25, 0.25), (0.7, 0.3, 0.0), (0.8, 0.1, 0.1), (1 / 3, 1 / 3, 1 / 3)],
)
def test_seeds_1_to_n_meet_the_fractions_within_one_run(fractions):
    for n in range(1, 41):
        split = split_by_seed([make_run(s) for s in range(1, n + 1)], *fractions)
        if min(f for f in fractions if f > 0) * n >= 1:  # no run moved for the minimum
            check_counts(split, n, fractions)
        assert sum(counts(split)) == n
        served = [len(getattr(split, role)) > 0 for role in ("train", "val", "test")]
        positive = [f > 0 for f in fractions]
        assert served[: min(n, sum(positive))] == positive[: min(n, sum(positive))], (n, served)


def test_random_seed_sets_meet_the_fractions_within_one_run():
    rng = random.Random(20240611)
    for _ in range(100):
        n = rng.randint(1, 60)
        pool = [make_run(s) for s in {rng.randrange(2**63) for _ in range(n)}]
        n = len(pool)
        check_counts(split_by_seed(pool), n, (0.6, 0.2, 0.2))


def test_a_small_pool_serves_train_first():
    assert counts(split_by_seed([make_run(7)])) == (1, 0, 0)
    assert counts(split_by_seed([make_run(7), make_run(8)])) == (1, 1, 0)
    assert counts(split_by_seed([make_run(s) for s in (7, 8, 9)])) == (1, 1, 1)


def test_the_order_within_a_condition_is_that_of_a_hash_of_the_seed():
    # seeds 1-5 ordered by sha256("r2rsim.split:<seed>"): the first 3 train, then 1 val, 1 test
    order = sorted(
        range(1, 6), key=lambda s: hashlib.sha256(f"r2rsim.split:{s}".encode()).hexdigest()
    )
    assert order == [3, 1, 2, 4, 5]
    split = split_by_seed([make_run(s) for s in range(1, 6)])
    assert (seeds(split.train), seeds(split.val), seeds(split.test)) == ({1, 2, 3}, {4}, {5})


def test_runs_of_one_seed_stay_together():
    # two scenarios, seeds 1-5 each, one condition: 10 runs, 6/2/2, whole seeds per role
    pool = [make_run(s, rid=f"{name}_s{s}") for name in ("a", "b") for s in range(1, 6)]
    split = split_by_seed(pool)
    assert counts(split) == (6, 2, 2)
    assert (seeds(split.train), seeds(split.val), seeds(split.test)) == ({1, 2, 3}, {4}, {5})


def test_the_split_does_not_depend_on_the_order_of_the_runs():
    pool = (
        [make_run(s, mode="OC1") for s in range(1, 12)]
        + [make_run(s, mode="OC2") for s in range(30, 37)]
        + [make_run(s, onset=2) for s in range(3)]
    )
    expected = ids(split_by_seed(pool))
    rng = random.Random(3)
    for _ in range(20):
        shuffled = pool[:]
        rng.shuffle(shuffled)
        assert ids(split_by_seed(shuffled)) == expected
    # each role lists its runs in the order given
    split = split_by_seed(pool)
    for role in ("train", "val", "test"):
        got = getattr(split, role)
        assert got == [r for r in pool if r in got]


def test_every_condition_is_in_every_role():
    pool = (
        [make_run(s, mode="OC1") for s in range(1, 8)]  # 7: 4/2/1
        + [make_run(s, mode="OC2") for s in range(1, 4)]  # 3: 1/1/1
        + [make_run(s, mode="P2") for s in range(50, 55)]  # 5: 3/1/1
        + [make_run(s, mode=None) for s in range(1, 3)]
    )  # 2: 1/1/0, no mode: a group
    split = split_by_seed(pool)
    assert by_mode(split.train) == {"OC1": 4, "OC2": 1, "P2": 3, "": 1}
    assert by_mode(split.val) == {"OC1": 2, "OC2": 1, "P2": 1, "": 1}
    assert by_mode(split.test) == {"OC1": 1, "OC2": 1, "P2": 1}


def test_a_condition_is_split_the_same_whatever_other_conditions_are_present():
    oc1 = [make_run(s, mode="OC1") for s in range(1, 10)]
    alone = ids(split_by_seed(oc1))
    for others in (
        [make_run(s, mode="OC2") for s in range(1, 4)],
        [make_run(s, mode="OC3") for s in range(100, 120)] + [make_run(1, mode=None)],
    ):
        mixed = split_by_seed(oc1 + others)
        assert (
            tuple(
                {r.run_id for r in getattr(mixed, role) if r.mode == "OC1"}
                for role in ("train", "val", "test")
            )
            == alone
        )


def test_a_split_named_by_the_scenario_is_kept_and_not_counted():
    pool = (
        [make_run(s) for s in range(1, 6)]  # 3/1/1
        + [make_run(s, split="val", rid=f"v{s}") for s in (1, 2)]
        + [make_run(9, split="train", rid="t9"), make_run(10, split="test", rid="e10")]
    )
    split = split_by_seed(pool)
    assert counts(split) == (4, 3, 2)
    assert {"t9"} < {r.run_id for r in split.train}
    assert {"v1", "v2"} < {r.run_id for r in split.val}
    assert {"e10"} < {r.run_id for r in split.test}
    # the five runs without a split of their own are apportioned as without the others
    assert seeds(r for r in split.train if r.info["split"] is None) == {1, 2, 3}


def test_every_faulty_run_is_a_test_run():
    healthy = [make_run(s) for s in range(1, 11)]  # 6/2/2
    faulty = [make_run(s, onset=3, split="train" if s % 2 else None) for s in range(1, 7)]
    split = split_by_seed(healthy + faulty)
    assert counts(split) == (6, 2, 8)
    assert not any(is_faulty(r) for r in split.train + split.val)
    assert sum(is_faulty(r) for r in split.test) == 6
    assert split.describe() == "split 'seed': 6 train, 2 val, 8 test (6 faulty)"


def test_a_fault_that_never_acted_leaves_the_run_fault_free():
    # the onset (10 s) is after the last sample (2.5 s): the run is fault-free, and counted
    never = make_run(4, fault_onset_s=10.0)
    acted = make_run(5, fault_onset_s=1.0)
    assert not is_faulty(never) and is_faulty(acted)
    split = split_by_seed([make_run(s) for s in (1, 2)] + [never, acted])
    assert counts(split) == (1, 1, 2) and acted in split.test


def test_fractions_are_checked():
    with pytest.raises(
        InputError,
        match=r"split fractions must lie in \[0, 1\] and sum to 1, "
        r"got train=0.5, val=0.2, test=0.2",
    ):
        split_by_seed([make_run(1)], train=0.5, val=0.2, test=0.2)
    with pytest.raises(InputError, match=r"got train=1.2, test=-0.4"):
        split_by_seed([make_run(1)], train=1.2, val=0.2, test=-0.4)
    with pytest.raises(InputError, match=r"got train=-0.5"):
        split_by_condition([make_run(1, mode="OC1"), make_run(2, mode="OC2")], val=1.5)


def test_why_there_is_no_training_run():
    faulty = [make_run(s, onset=1) for s in range(4)]
    assert no_training_run(faulty) == (
        "split 'seed': all 4 runs have faults, and plug-ins learn from fault-free runs only: "
        "add fault-free runs (--data), or name the roles with --train/--val/--test"
    )
    named = faulty + [
        make_run(1, split="val", rid="v1"),
        make_run(2, split="val", rid="v2"),
        make_run(3, split="test", rid="t3"),
    ]
    assert not split_by_seed(named).train
    assert no_training_run(named) == (
        "split 'seed': each of the 3 fault-free runs has a split of its own in its scenario "
        "(runs.split: 2 val, 1 test), and none is train: add fault-free runs without a "
        "split: of their own, or name the roles with --train/--val/--test"
    )


# --------------------------------------------------------------------------- by condition
def test_five_healthy_runs_of_the_train_mode_give_four_train_one_val():
    pool = (
        [make_run(s, mode="OC1") for s in range(1, 6)]
        + [make_run(s, mode="OC2") for s in range(1, 6)]
        + [make_run(s, mode="OC2", onset=2) for s in range(6, 26)]
        + [make_run(s, mode="OC1", onset=2) for s in range(6, 66)]
        + [make_run(s, mode="OC3") for s in range(1, 4)]
        + [make_run(9, mode=None)]
    )
    split = split_by_condition(pool)
    assert split.name == "condition OC1->OC2"
    assert counts(split) == (4, 1, 25)
    assert by_mode(split.train + split.val) == {"OC1": 5}
    assert not any(is_faulty(r) for r in split.train + split.val)
    assert by_mode(split.test) == {"OC2": 25} and sum(map(is_faulty, split.test)) == 20
    assert (seeds(split.train), seeds(split.val)) == ({1, 2, 3, 4}, {5})


@pytest.mark.parametrize(
    "n,val,expected",
    [
        (1, 0.25, (1, 0)),
        (2, 0.25, (1, 1)),
        (5, 0.25, (4, 1)),
        (6, 0.25, (5, 1)),
        (7, 0.25, (5, 2)),
        (20, 0.25, (15, 5)),
        (20, 0.0, (20, 0)),
        (3, 0.5, (2, 1)),
    ],
)
def test_condition_split_counts(n, val, expected):
    pool = [make_run(s, mode="OC1") for s in range(1, n + 1)] + [make_run(1, mode="OC2")]
    split = split_by_condition(pool, train="OC1", test="OC2", val=val)
    assert (len(split.train), len(split.val)) == expected and len(split.test) == 1


def test_the_condition_split_ignores_runs_split_and_the_order():
    pool = [make_run(s, mode="OC1", split="test" if s < 3 else None) for s in range(1, 9)] + [
        make_run(s, mode="OC2", split="train") for s in range(1, 3)
    ]
    split = split_by_condition(pool, val=0.25)
    assert counts(split) == (6, 2, 2)
    assert ids(split_by_condition(pool[::-1], val=0.25)) == ids(split)


def test_a_missing_mode_is_refused():
    pool = [make_run(s, mode="OC1") for s in range(3)] + [make_run(5, mode=None)]
    with pytest.raises(
        InputError,
        match=r"split by condition: no run has the test mode 'OC2' "
        r"\(modes present: \(none\), OC1\)",
    ):
        split_by_condition(pool)
    with pytest.raises(InputError, match="no run has the train mode 'OC9'"):
        split_by_condition(pool, train="OC9", test="OC1")


# --------------------------------------------------------------------------- shipped sweeps
def test_the_shipped_sweeps_have_fault_free_runs():
    """Every sweep file in sweeps/ has fault-free runs in every operating condition it has,
    at least three per condition (one for each role of the seed split)."""
    from r2rsim.sweep import plan_sweep

    expected = {
        "quickstart.yaml": {None: 4},
        "thesis_sensor_faults.yaml": {"OC1": 5, "OC2": 5},
        "first_benchmark.yaml": {"OC1": 5, "OC2": 5},
    }
    assert sorted(p.name for p in (REPO / "sweeps").glob("*.yaml")) == sorted(expected)
    for name, want in expected.items():
        plan = plan_sweep(REPO / "sweeps" / name)
        healthy = Counter()
        for spec in plan.runs:
            scenario = spec.scenario_data
            if not scenario.get("faults"):
                modes = {step.get("mode") for step in scenario["programme"]} - {None}
                healthy["+".join(sorted(modes)) or None] += 1
        assert dict(healthy) == want, name
