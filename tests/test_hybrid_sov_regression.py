"""Unit oracles of the hybrid-sov estimators (thesis §2.5, eq. 2.10): Tobit against known
coefficients, against OLS without censoring and against a hand-computed log-likelihood;
forward stepwise selection on a synthetic problem."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from r2rsim.diagnostics.hybrid_sov import (
    fit_defect_classifier,
    fit_ols,
    fit_tobit,
    forward_stepwise,
    tobit_loglike,
)
from r2rsim.errors import InputError


def _design(n, rng):
    return np.column_stack([np.ones(n), rng.normal(size=n), rng.uniform(-1, 1, size=n)])


def test_tobit_recovers_coefficients_within_3_se():
    rng = np.random.default_rng(7)
    X = _design(4000, rng)
    beta, sigma = np.array([0.4, 1.2, -2.0]), 1.5
    y = np.maximum(X @ beta + rng.normal(scale=sigma, size=len(X)), 0.0)
    assert 0.3 < np.mean(y <= 0) < 0.6  # heavily censored
    f = fit_tobit(X, y, censor_at=0.0)
    assert np.all(np.abs(f.beta - beta) < 3 * f.se)
    assert abs(f.sigma - sigma) < 0.1
    # OLS on the censored data is biased: the point of the Tobit model
    assert np.any(np.abs(fit_ols(X, y).beta - beta) > 5 * f.se)


def test_tobit_equals_ols_without_censoring():
    rng = np.random.default_rng(8)
    X = _design(500, rng)
    y = X @ np.array([50.0, 3.0, -1.0]) + rng.normal(size=len(X))
    assert y.min() > 0
    t, o = fit_tobit(X, y), fit_ols(X, y)
    np.testing.assert_allclose(t.beta, o.beta, rtol=0, atol=1e-6)
    assert t.sigma == pytest.approx(np.sqrt(np.mean((y - X @ o.beta) ** 2)), rel=1e-6)
    assert t.llf == pytest.approx(o.llf, rel=1e-9)


def test_tobit_loglike_matches_hand_computation():
    X = np.array([[1.0, 0.5], [1.0, -1.0], [1.0, 2.0], [1.0, 0.0], [1.0, -2.5]])
    y = np.array([1.3, 0.0, 2.2, 0.4, 0.0])
    beta, sigma = np.array([0.3, 0.9]), 0.8
    mu = X @ beta
    hand = 0.0
    for yi, mi in zip(y, mu, strict=True):
        if yi <= 0.0:
            hand += np.log(stats.norm.cdf((0.0 - mi) / sigma))
        else:
            hand += np.log(stats.norm.pdf((yi - mi) / sigma) / sigma)
    assert tobit_loglike(X, y, beta, sigma, 0.0) == pytest.approx(hand, abs=1e-10)


def test_stepwise_finds_the_true_variables():
    rng = np.random.default_rng(3)
    n = 600
    cols = {"const": np.ones(n)}
    for k in range(8):
        cols[f"x{k}"] = rng.normal(size=n)
    y = 2.0 + 1.5 * cols["x1"] - 0.8 * cols["x4"] + 0.5 * cols["x6"] + rng.normal(size=n)
    res = forward_stepwise(cols, y, ["const"], [f"x{k}" for k in range(8)], "ols", 0.01)
    assert sorted(res.selected) == ["x1", "x4", "x6"]
    assert res.test == "F" and res.path[-1]["entered"] is False
    # Tobit stages use likelihood-ratio tests, and find the same support under censoring
    yc = np.maximum(y - 2.0, 0.0)
    res_t = forward_stepwise(cols, yc, ["const"], [f"x{k}" for k in range(8)], "tobit", 0.01)
    assert res_t.test == "LR" and sorted(res_t.selected) == ["x1", "x4", "x6"]


def test_regression_input_errors():
    with pytest.raises(InputError, match="more observations"):
        fit_ols(np.ones((2, 2)), np.ones(2))
    with pytest.raises(InputError, match="alpha_enter"):
        forward_stepwise({"c": np.ones(9)}, np.ones(9), ["c"], [], alpha_enter=1.5)
    with pytest.raises(InputError, match="two classes"):
        fit_defect_classifier(np.ones((5, 1)), ["normal"] * 5)


def test_defect_classifier_separates_slack_from_normal():
    rng = np.random.default_rng(4)
    T = np.concatenate([rng.normal(300, 10, 200), rng.normal(5, 3, 50), rng.normal(600, 10, 50)])
    labels = np.array(["normal"] * 200 + ["slack"] * 50 + ["over_stretch"] * 50)
    clf = fit_defect_classifier(T[:, None], labels, random_state=0)
    assert (clf.predict(T[:, None]) == labels).mean() > 0.99
