"""The plug-in checks r2rsim ships (r2rsim.evaluate.check_plugin): they pass on a correct
plug-in with their own built-in data, and each rule of the contract fails a plug-in that
breaks it, with a message naming the plug-in and the rule."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from r2rsim.diagnostics import Diagnostic
from r2rsim.errors import InputError
from r2rsim.evaluate import check_plugin, example_runs


class Zscore(Diagnostic):
    """A correct plug-in: the largest |z| over the measured channels."""

    name = "zscore"

    def __init__(self, scale: float = 1.0):
        self.scale = scale

    def fit(self, runs):
        frames = self._frames(runs)
        self.columns_ = self.required_columns(frames[0])
        X = self._matrix(frames, self.columns_)
        self._fit_scaling(X)
        self.threshold_ = 4.0
        return self

    def score(self, run):
        self._check_fitted()
        frame = self._frames(run)[0]
        z = (frame[self.columns_].to_numpy(float) - self.mean_) / self.std_
        return pd.DataFrame({"statistic": np.abs(z).max(axis=1) * self.scale}, index=frame.index)

    def rank_channels(self, scores):
        return pd.DataFrame({0: [self.columns_[0]] * len(scores)}, index=scores.index)


@pytest.fixture(scope="module")
def runs():
    return example_runs()


def test_the_builtin_data_is_two_healthy_runs_and_a_faulty_one(runs):
    train, test = runs
    assert [r.samples["label.is_faulty"].any() for r in train] == [False, False]
    faulty = test.samples.loc[test.samples["label.is_faulty"], "t_s"]
    assert faulty.min() == pytest.approx(10.0) and len(test.samples) == 1001  # 20 s at 50 Hz
    assert {"meas.lc.tension_N", "meas.enc.speed_rad_s"} <= set(test.visible().columns)


def test_a_correct_plugin_passes_every_check(runs):
    done = check_plugin(Zscore, *runs)
    assert len(done) == 9 and done[0].startswith("__init__ stores its parameters"), done


def test_a_registered_name_with_the_builtin_data():
    # no data given: check_plugin simulates example_runs itself
    assert len(check_plugin("residual")) == 9


class Broken(Zscore):
    name = "broken"


class ChangesItsParameter(Broken):
    def __init__(self, scale=1.0):
        self.scale = scale * 2


class FittedAtInit(Broken):
    def __init__(self, scale=1.0):
        self.scale = scale
        self.ready_ = True


class ScoresUnfitted(Broken):
    def score(self, run):
        return pd.DataFrame({"statistic": 0.0}, index=self._frames(run)[0].index)


class FitReturnsNone(Broken):
    def fit(self, runs):
        super().fit(runs)


class ScoresRenumbered(Broken):
    def score(self, run):
        scores = super().score(run)
        return scores.set_axis(scores.index + 1)


class ScoresWithoutStatistic(Broken):
    def score(self, run):
        return super().score(run).rename(columns={"statistic": "stat"})


class DecidesInIntegers(Broken):
    def decide(self, scores):
        return (scores["statistic"] > 4).astype(int)


class ChangesItsInput(Broken):
    def fit(self, runs):
        frame = self._frames(runs)[0]
        frame.loc[frame.index[0], frame.columns[1]] = -1.0
        return super().fit(runs)


class RanksHiddenChannels(Broken):
    def rank_channels(self, scores):
        return pd.DataFrame({0: ["true.lc.tension_N"] * len(scores)}, index=scores.index)


class Random(Broken):
    def fit(self, runs):
        super().fit(runs)
        self.mean_ = self.mean_ + np.random.default_rng().random()
        return self


class LearnsLabels(Broken):
    def fit(self, runs):
        super().fit(runs)
        self.columns_ = ["label.is_faulty"]
        return self

    def score(self, run):
        self._check_fitted()
        frame = self._frames(run)[0]
        return pd.DataFrame({"statistic": 0.0}, index=frame.index)

    def rank_channels(self, scores):
        return None


class NoColumnsValueError(Broken):
    def fit(self, runs):
        if len(self._frames(runs)[0].columns) == 1:
            raise ValueError("no data")
        return super().fit(runs)


class NoColumnsAccepted(Broken):
    def fit(self, runs):
        if len(self._frames(runs)[0].columns) == 1:
            self.columns_ = []
            return self
        return super().fit(runs)


class ReadsTheFuture(Broken):
    """A centred moving average: the statistic at t reads samples after t."""

    def score(self, run):
        scores = super().score(run)
        return scores.assign(
            statistic=scores["statistic"].rolling(9, center=True, min_periods=1).mean()
        )


class OfflineReadsTheFuture(ReadsTheFuture):
    causal = False


class IgnoresItsThreshold(Broken):
    def decide(self, scores):
        return scores["statistic"] > 0.5


@pytest.mark.parametrize(
    "cls, rule",
    [
        (ReadsTheFuture, "it declares itself causal"),
        (IgnoresItsThreshold, "calibrate must move the threshold its decide uses"),
        (ChangesItsParameter, "__init__ must store each parameter"),
        (FittedAtInit, "__init__ set fitted attributes ['ready_']"),
        (ScoresUnfitted, "score before fit returned"),
        (FitReturnsNone, "fit must return self"),
        (ScoresRenumbered, "indexed like the run's samples"),
        (ScoresWithoutStatistic, "with a 'statistic' column"),
        (DecidesInIntegers, "decide must return a boolean Series"),
        (ChangesItsInput, "leave the frames they are given unchanged"),
        (RanksHiddenChannels, "rank_channels must return a frame"),
        (Random, "two fits with the same parameters must give the same scores"),
        (LearnsLabels, "columns an algorithm may not see: ['label.is_faulty']"),
        (NoColumnsValueError, "fit without its columns raised ValueError"),
        (NoColumnsAccepted, "fit on a frame with only t_s must raise InputError"),
    ],
)
def test_each_broken_rule_is_named(runs, cls, rule):
    with pytest.raises(AssertionError) as info:
        check_plugin(cls, *runs)
    message = str(info.value)
    assert (
        message.startswith("plug-in 'broken' breaks the contract (docs/diagnostics.md §2.1): ")
        and rule in message
    ), message


def test_data_without_the_required_channels_is_an_input_error(runs):
    class NeedsDriveData(Broken):
        requires = ("act.*",)

    with pytest.raises(InputError, match="no column matching act"):
        check_plugin(NeedsDriveData, *runs)
    with pytest.raises(InputError, match="neither a registered plug-in name"):
        check_plugin(int, *runs)


def test_an_offline_plugin_is_not_held_to_causality(runs):
    done = check_plugin(OfflineReadsTheFuture, *runs)
    assert "declares itself offline (causal False): not checked for causality" in done
    assert len(done) == 9


def test_the_default_calibrate_holds_alpha_exactly(runs):
    train, test = runs
    est = Zscore().fit(train)
    frames = [r.visible() for r in train]
    masks = [r.samples["label.score_mask"].to_numpy(bool) for r in train]
    est.calibrate(frames, 0.05, masks)
    stat = np.concatenate(
        [est.score(f)["statistic"].to_numpy()[m] for f, m in zip(frames, masks, strict=True)]
    )
    # the (1 - alpha) quantile in inverted-CDF form: floor(0.05 n) samples exceed it
    assert (stat > est.threshold_).sum() == int(np.floor(0.05 * stat.size))
    assert est.threshold_ == np.sort(stat)[stat.size - 1 - int(np.floor(0.05 * stat.size))]
