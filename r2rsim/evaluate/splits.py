"""Splitting a pool of runs into the roles of an evaluation: train, val and test.

Plug-ins learn from fault-free runs only, so a split apportions the *fault-free* runs: every
faulty run is a test run. The fault-free runs are apportioned per operating condition
(``runs.operating_mode``; a run without one is a condition of its own), so that train, val
and (when asked for) test each hold runs of every condition, and the requested fractions are
met to within one run in every condition, however few runs it has.

Within a condition the runs are put in a fixed order that depends on the runs alone (not on
the order they are given in, nor on the other conditions present): by a hash of the seed
(:func:`seed_order_key`), so that seed ranges carry no meaning and the runs of one seed, which
share their noise and plant draws (docs/sweeps.md §3), stand next to each other; then by run
id. :func:`apportion` gives the number of runs of each role (largest remainders, with at
least one run per role when the condition has enough), and the roles take the ordered runs
in blocks: the first ones train, the next val, the rest test.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass

import pandas as pd

from ..dataset.read import Run
from ..errors import InputError

__all__ = [
    "ROLES",
    "Split",
    "acting_faults",
    "apportion",
    "is_faulty",
    "no_training_run",
    "seed_order_key",
    "split_by_condition",
    "split_by_seed",
]

#: the roles of a split, in the order they are served (train first)
ROLES = ("train", "val", "test")
#: decimals a share (fraction x number of runs) is rounded to, so that 0.6 x 5 is 3, not
#: 2.9999999999999996
_SHARE_DECIMALS = 9


@dataclass
class Split:
    """Runs by role: fit on ``train``, calibrate on ``val``, score ``test``.

    Attributes
    ----------
    train, val, test : list of Run
    name : str
        How the split was made (``explicit``, ``seed``, ``condition OC1->OC2``): the
        ``split`` column of the results.
    """

    train: list[Run]
    val: list[Run]
    test: list[Run]
    name: str = "explicit"

    def describe(self) -> str:
        """One line: how many runs each role has.

        Returns
        -------
        str
            For example ``split 'seed': 6 train, 2 val, 82 test (80 faulty)``.
        """
        n_faulty = sum(is_faulty(r) for r in self.test)
        return (
            f"split '{self.name}': {len(self.train)} train, {len(self.val)} val, "
            f"{len(self.test)} test ({n_faulty} faulty)"
        )


def acting_faults(run: Run) -> pd.DataFrame:
    """The run's faults that act in it.

    A fault whose onset comes after the run's last sample (a web break ended the run first)
    never acted, and the run is as fault-free as its labels say, for the split, the strata
    and the metrics alike.

    Parameters
    ----------
    run : Run

    Returns
    -------
    pandas.DataFrame
        The run's rows of faults.parquet whose onset is at or before its last sample (all of
        them for a hand-made run without ``onset_t_s`` or without samples).
    """
    faults = run.faults
    if "onset_t_s" not in faults.columns or run.samples.empty:  # (a hand-made Run)
        return faults
    return faults[faults["onset_t_s"].to_numpy(float) <= run.samples["t_s"].iloc[-1]]


def is_faulty(run: Run) -> bool:
    """Whether a fault acts in the run: a fault row with its onset inside the run, or a
    sample labelled faulty.

    Parameters
    ----------
    run : Run

    Returns
    -------
    bool
    """
    return len(acting_faults(run)) > 0 or bool(run.samples["label.is_faulty"].any())


def _fractions(train: float, val: float, test: float) -> tuple[float, float, float]:
    """The fractions of the roles, checked: each in [0, 1], summing to 1 (InputError)."""
    fr = {"train": train, "val": val, "test": test}
    bad = [f"{k}={v:g}" for k, v in fr.items() if not 0.0 <= v <= 1.0]
    if bad or abs(train + val + test - 1.0) > 1e-9:
        raise InputError(
            f"split fractions must lie in [0, 1] and sum to 1, got "
            f"{', '.join(bad) or ', '.join(f'{k}={v:g}' for k, v in fr.items())}"
        )
    return float(train), float(val), float(test)


def apportion(n: int, fractions: Sequence[float]) -> list[int]:
    """How many of ``n`` runs each role gets.

    1. Largest remainders: each role gets the whole part of its share ``fraction * n``;
       the runs left over go one each to the roles with the largest fractional parts (on a
       tie, to the earlier role: train before val before test).
    2. At least one run per role: the roles with a positive fraction, in order, each get
       at least one run as far as ``n`` allows (``n = 1``: the first of them; ``n = 2``: the
       first two; and so on). A role short of its run takes it from the role with the most
       runs over its share among those that can spare one (on a tie, the later role).

    Every count is the floor or the ceiling of its share unless step 2 had to move a run,
    which it never does when each positive fraction is at least ``1 / n``. With the default
    fractions of :func:`split_by_seed` (0.6/0.2/0.2) and ``split_by_condition``'s
    (0.75/0.25/0) it never moves a run past the floor or the ceiling at any ``n``. A role
    with fraction 0 gets no run.

    Parameters
    ----------
    n : int
        Number of runs, >= 0.
    fractions : sequence of float
        One fraction per role, each in [0, 1], summing to 1.

    Returns
    -------
    list of int
        The number of runs of each role, summing to ``n``.
    """
    shares = [round(f * n, _SHARE_DECIMALS) for f in fractions]
    counts = [math.floor(s) for s in shares]
    by_remainder = sorted(range(len(shares)), key=lambda i: (-(shares[i] - counts[i]), i))
    for i in by_remainder[: n - sum(counts)]:
        counts[i] += 1
    positive = [i for i, f in enumerate(fractions) if f > 0]
    minimum = [0] * len(fractions)
    for i in positive[:n]:
        minimum[i] = 1
    for i in range(len(fractions)):
        while counts[i] < minimum[i]:
            donors = [j for j in range(len(fractions)) if counts[j] > minimum[j]]
            j = max(donors, key=lambda j: (counts[j] - shares[j], j))
            counts[j] -= 1
            counts[i] += 1
    return counts


def seed_order_key(run: Run) -> tuple[str, str, str]:
    """The key that orders the runs of one condition before they are apportioned.

    A SHA-256 of the run's root seed (so that the order of the seeds is mixed and the
    runs of one seed stay together), then the run id and the scenario's SHA-256 (runs of
    the same seed). It depends on the run alone.

    Parameters
    ----------
    run : Run

    Returns
    -------
    tuple of str
    """
    seed = int(run.info["seed"])
    digest = hashlib.sha256(f"r2rsim.split:{seed}".encode()).hexdigest()
    return digest, str(run.run_id), str(run.info.get("scenario_sha256") or "")


def _apportion_runs(
    runs: Sequence[Run], indices: Sequence[int], fractions: Sequence[float]
) -> dict[str, list[int]]:
    """The runs ``runs[i]`` for i in ``indices``, all of one condition, by role (as indices):
    in :func:`seed_order_key` order, the first ``counts[0]`` are train, the next
    ``counts[1]`` val, the rest test."""
    ordered = sorted(indices, key=lambda i: seed_order_key(runs[i]))
    counts = apportion(len(ordered), fractions)
    out: dict[str, list[int]] = {}
    start = 0
    for role, count in zip(ROLES, counts, strict=True):
        out[role] = ordered[start : start + count]
        start += count
    return out


def _by_condition(runs: Sequence[Run], indices: Sequence[int]) -> dict[str, list[int]]:
    """The indices of the runs by operating condition (``Run.mode``: '' for none)."""
    groups: dict[str, list[int]] = {}
    for i in indices:
        groups.setdefault(runs[i].mode, []).append(i)
    return groups


def split_by_seed(
    runs: Sequence[Run], train: float = 0.6, val: float = 0.2, test: float = 0.2
) -> Split:
    """Assign runs to roles, deterministically, in the requested fractions per condition.

    * Every faulty run (:func:`is_faulty`) is a test run, whatever its seed or scenario.
    * A fault-free run whose scenario names its split (``runs.split``: train, val or test)
      keeps that role, and is left out of the counts below.
    * The other fault-free runs are apportioned per operating condition
      (``runs.operating_mode``; runs without one form one condition): in each condition the
      n runs are ordered by :func:`seed_order_key` and counted out by :func:`apportion`: the
      first ones train, the next val, the rest test. Each role's count is ``fraction * n``
      rounded down or up (so 12/4/4 of 20 runs, 3/1/1 of 5), and each role with a positive
      fraction gets at least one run of every condition that has enough of them: a condition
      with one run gives it to train, with two runs one to train and one to val (no
      fault-free test run of it then), with three or more at least one to each. Rounding is
      per condition, so the totals are within one run per condition of the fractions.

    The roles depend only on the runs: not on the order they are given in, and a condition's
    runs are assigned the same whatever other conditions are present. Each role lists its
    runs in the order given.

    Parameters
    ----------
    runs : sequence of Run
    train, val, test : float
        Fractions of the fault-free runs without a split of their own, per condition: each
        in [0, 1], summing to 1.

    Returns
    -------
    Split
        Named ``seed``.

    Raises
    ------
    InputError
        A fraction outside [0, 1], or fractions that do not sum to 1.
    """
    fractions = _fractions(train, val, test)
    roles: dict[str, list[int]] = {role: [] for role in ROLES}
    pool: list[int] = []
    for i, r in enumerate(runs):
        named = r.info.get("split")
        if is_faulty(r):
            roles["test"].append(i)
        elif named in roles:
            roles[named].append(i)
        else:
            pool.append(i)
    for group in _by_condition(runs, pool).values():
        for role, chosen in _apportion_runs(runs, group, fractions).items():
            roles[role] += chosen
    by_role = {role: [runs[i] for i in sorted(roles[role])] for role in ROLES}
    return Split(by_role["train"], by_role["val"], by_role["test"], name="seed")


def no_training_run(runs: Sequence[Run]) -> str:
    """Why :func:`split_by_seed` put none of ``runs`` in train, and what to do.

    Parameters
    ----------
    runs : sequence of Run
        The pool given to :func:`split_by_seed` (at its default fractions).

    Returns
    -------
    str
        One line for the command line's error message.
    """
    healthy = [r for r in runs if not is_faulty(r)]
    if not healthy:
        return (
            f"split 'seed': all {len(runs)} runs have faults, and plug-ins learn from "
            f"fault-free runs only: add fault-free runs (--data), or name the roles with "
            f"--train/--val/--test"
        )
    named = [str(r.info.get("split")) for r in healthy if r.info.get("split") in ROLES]
    if len(named) == len(healthy):
        counts = ", ".join(f"{named.count(role)} {role}" for role in ROLES if role in named)
        return (
            f"split 'seed': each of the {len(healthy)} fault-free runs has a split of its "
            f"own in its scenario (runs.split: {counts}), and none is train: add "
            f"fault-free runs without a split: of their own, or name the roles with "
            f"--train/--val/--test"
        )
    return (
        f"split 'seed': none of the {len(healthy)} fault-free runs is in train: name the "
        f"roles with --train/--val/--test"
    )


def split_by_condition(
    runs: Sequence[Run], train: str = "OC1", test: str = "OC2", val: float = 0.25
) -> Split:
    """Train and calibrate on one operating condition, test on another.

    Every run of mode ``test`` is a test run, faulty or not. The fault-free runs of mode
    ``train`` are apportioned into train and val as by :func:`split_by_seed` with fractions
    ``1 - val``, ``val`` and 0: ``val * n`` rounded down or up go to val (1 of 5 at 0.25,
    5 of 20), and with two runs or more each role gets at least one when its fraction is
    positive (one run: train only, no val). ``runs.split`` is not used here: the conditions
    decide the roles. Faulty runs of mode ``train`` and runs of other modes are not used.

    Parameters
    ----------
    runs : sequence of Run
    train, test : str
        Operating modes as named in the scenarios' programmes (``runs.operating_mode``; a
        run with two modes has ``OC1+OC2``, which matches neither).
    val : float
        Fraction of the fault-free ``train``-mode runs held out for calibration, in [0, 1].

    Returns
    -------
    Split
        Named ``condition TRAIN->TEST``.

    Raises
    ------
    InputError
        No run has mode ``train`` or mode ``test``; ``val`` outside [0, 1].
    """
    fractions = _fractions(1.0 - val, val, 0.0)
    modes = sorted({r.mode for r in runs})
    for role, mode in (("train", train), ("test", test)):
        if mode not in modes:
            raise InputError(
                f"split by condition: no run has the {role} mode '{mode}' "
                f"(modes present: {', '.join(m or '(none)' for m in modes)})"
            )
    tested = [r for r in runs if r.mode == test]
    pool = [i for i, r in enumerate(runs) if r.mode == train != test and not is_faulty(r)]
    roles = _apportion_runs(runs, pool, fractions)
    return Split(
        [runs[i] for i in sorted(roles["train"])],
        [runs[i] for i in sorted(roles["val"])],
        tested,
        name=f"condition {train}->{test}",
    )
