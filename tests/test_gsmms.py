"""GSMMS (thesis Ch. 4): the growing map's stopping criteria, local relations by SGD against
the exact oracle, per-node detection, online growth, and the plug-in's parameter checks.
Everything runs on synthetic data with known regimes (no simulation)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from r2rsim.diagnostics.gsmms import GSMMS, GlobalParity, fit_relations, objective, oracle_relations
from r2rsim.diagnostics.gsmms._local import fault_normalised_oracle
from r2rsim.diagnostics.gsmms._model import GrowthSettings, grow, initial_map
from r2rsim.errors import InputError

# three regimes: cluster centres in the partition space, each with its own relation
CENTRES = np.array([[0.0, 0.0], [4.0, 0.0], [8.0, 1.0]])
ANGLES = np.array([0.3, 1.2, 2.2])  # direction of each regime's line in the model space


def regimes(n=1500, noise=0.05, seed=0, which=(0, 1, 2)):
    """Partition rows S, model rows Z and the true regime of each row: in regime r the model
    features lie on a line at angle ANGLES[r] with the same normal noise, so a correct
    partition gives every node the same loss (equal shares)."""
    rng = np.random.default_rng(seed)
    S, Z, lab = [], [], []
    for r in which:
        S.append(CENTRES[r] + 0.1 * rng.standard_normal((n, 2)))
        t = rng.standard_normal(n)
        d = np.array([np.cos(ANGLES[r]), np.sin(ANGLES[r])])
        nrm = np.array([-d[1], d[0]])
        Z.append(np.outer(t, d) + np.outer(noise * rng.standard_normal(n), nrm) + r)
        lab.append(np.full(n, r))
    return np.vstack(S), np.vstack(Z), np.concatenate(lab)


def grown(S, Z, seed=0, **kw):
    s = GrowthSettings(solver="eigh", **kw)
    rng = np.random.default_rng(seed)
    history = []
    graph, models = grow(initial_map(S, s.initial_nodes, rng), S, Z, s, rng, history)
    return graph, models, history


def purity(graph, S, lab):
    """Share of each regime's rows in the node that wins most of them."""
    bmu = graph.bmu(S)
    return [np.bincount(bmu[lab == r]).max() / np.sum(lab == r) for r in np.unique(lab)]


# ---- (1) the growing map ---------------------------------------------------------------------
def test_share_criterion_stops_at_the_known_regimes():
    S, Z, lab = regimes()
    graph, _, history = grown(S, Z, zeta_threshold=0.45, min_improvement=None, max_nodes=8)
    assert graph.n_nodes == 3
    assert history[-1].decision == "stop: share"
    assert max(history[-1].zeta) <= 0.45
    assert min(purity(graph, S, lab)) >= 0.99
    # with two nodes one of them spans two regimes and holds most of the loss
    assert history[0].n_nodes == 2 and max(history[0].zeta) > 0.9


def test_absolute_criterion_stops_at_the_known_regimes():
    S, Z, lab = regimes()
    # the share criterion can never hold (threshold 0): only the absolute one stops growth
    graph, _, history = grown(S, Z, zeta_threshold=0.0, min_improvement=0.05, max_nodes=8)
    assert graph.n_nodes == 3
    assert history[-1].decision.startswith("stop: improvement")
    assert history[-1].n_nodes == 4  # the fourth node was tried and undone
    assert min(purity(graph, S, lab)) >= 0.99


def test_max_nodes_bounds_growth():
    S, Z, _ = regimes()
    graph, _, history = grown(S, Z, zeta_threshold=0.0, min_improvement=None, max_nodes=5)
    assert graph.n_nodes == 5 and history[-1].decision == "stop: max_nodes"


@pytest.mark.parametrize("kind", ["noise", "identical", "one_point_outlier"])
def test_growth_terminates_on_adversarial_data(kind):
    rng = np.random.default_rng(3)
    n = 2000
    if kind == "noise":  # no regimes and no relation: every insertion looks useful
        S, Z = rng.uniform(-1, 1, (n, 2)), rng.standard_normal((n, 3))
    elif kind == "identical":  # one point in the partition space: nowhere to grow
        S, Z = np.zeros((n, 2)), rng.standard_normal((n, 3))
    else:  # one far outlier: the farthest-point seed lands on it
        S = np.vstack([rng.standard_normal((n, 2)) * 0.01, [[1e6, 1e6]]])
        Z = rng.standard_normal((n + 1, 3))
    graph, models, history = grown(S, Z, zeta_threshold=0.0, min_improvement=None,
                                   max_nodes=6)
    assert 1 <= graph.n_nodes <= 6
    assert len(history) <= 6
    assert history[-1].decision.startswith("stop")
    assert all(np.all(np.isfinite(om)) for om in models.omega)
    if kind == "identical":
        assert graph.n_nodes == 1 and "no distinct data" in history[-1].decision


def test_growth_is_deterministic_under_random_state():
    S, Z, _ = regimes(n=800)
    runs = []
    for _ in range(2):
        s = GrowthSettings(solver="minibatch", zeta_threshold=0.45, max_nodes=6)
        rng = np.random.default_rng(7)
        g, m = grow(initial_map(S, 2, rng), S, Z, s, rng, [])
        runs.append((g.codebook, np.hstack(m.omega)))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])


# ---- (2) local relations ---------------------------------------------------------------------
def node_data(seed=1, n=40_000):
    """A node's data: three correlated channels, standardised, and topological weights."""
    rng = np.random.default_rng(seed)
    t = 3 * rng.standard_normal(n)
    Z = np.c_[t + 0.3 * rng.standard_normal(n), 2 * t + 0.3 * rng.standard_normal(n),
              rng.standard_normal(n) + 0.2 * t]
    Z = (Z - Z.mean(0)) / Z.std(0) + np.array([0.5, -0.2, 1.0])  # uncentred, as P is
    hops = rng.integers(0, 3, n)
    w = np.exp(-hops**2 / (2 * 0.8**2))
    return Z, w


def cosine(a, b):
    return abs(a @ b) / np.linalg.norm(a) / np.linalg.norm(b)


@pytest.mark.parametrize("lambda1", [1.0, 0.5])
def test_minibatch_sgd_matches_the_eigenvector_oracle(lambda1):
    Z, w = node_data()
    oracle = oracle_relations(Z, w, lambda1=lambda1)
    om, b = fit_relations(Z, w, solver="minibatch", lambda1=lambda1, n_epochs=2.0,
                          rng=np.random.default_rng(0))
    assert cosine(om[:, 0], oracle[:, 0]) >= 0.999
    j_sgd, j_or = (objective(o, Z, w, lambda1) for o in (om, oracle))
    assert abs(j_sgd - j_or) <= 0.01 * j_or
    # the penalised optimum is shorter than 1: ‖Ω‖² = 1 − λ_min / (2 λ1)
    assert np.linalg.norm(oracle) < 1.0
    # the intercept centres the weighted residual
    r = Z @ om[:, 0] + b[0]
    assert abs(np.sum(w * r) / w.sum()) < 1e-9


def test_the_oracle_is_the_exact_minimiser():
    Z, w = node_data(seed=2, n=5000)
    oracle = oracle_relations(Z, w, lambda1=1.0)[:, 0]
    j0 = objective(oracle, Z, w)
    rng = np.random.default_rng(0)
    for _ in range(50):  # no nearby perturbation does better
        assert objective(oracle + 1e-3 * rng.standard_normal(3), Z, w) >= j0


def test_several_relations_are_orthogonal_and_match_the_oracle():
    Z, w = node_data(seed=4)
    oracle = oracle_relations(Z, w, n_relations=2)
    om, _ = fit_relations(Z, w, 2, solver="minibatch", n_epochs=2.0,
                          rng=np.random.default_rng(0))
    assert abs(om[:, 0] @ om[:, 1]) < 1e-9
    for k in range(2):
        assert cosine(om[:, k], oracle[:, k]) >= 0.999


def test_fault_normalised_relation_matches_its_oracle():
    Z, w = node_data(seed=5)
    F = np.eye(3)[:, [0]]
    oracle = fault_normalised_oracle(Z, w, F)
    assert oracle[0, 0] == pytest.approx(1.0)
    om, _ = fit_relations(Z, w, F=F, solver="minibatch", n_epochs=2.0,
                          rng=np.random.default_rng(0))
    assert om[0, 0] == pytest.approx(1.0, abs=1e-9)  # the constraint holds at every step
    assert cosine(om[:, 0], oracle[:, 0]) >= 0.999
    j_sgd, j_or = (objective(o, Z, w, fault_normalised=True) for o in (om, oracle))
    assert abs(j_sgd - j_or) <= 0.01 * j_or


@pytest.mark.parametrize("solver", ["batch", "sgd"])
def test_batch_gd_and_single_sample_sgd_reach_the_oracle(solver):
    Z, w = node_data(seed=6, n=8000)
    oracle = oracle_relations(Z, w)
    om, _ = fit_relations(Z, w, solver=solver, rng=np.random.default_rng(0))
    assert cosine(om[:, 0], oracle[:, 0]) >= 0.999
    assert objective(om, Z, w) <= 1.05 * objective(oracle, Z, w)


def test_the_printed_inverse_square_step_stalls():
    # Σ η0/idx² is finite (1.64 η0): from a random start the iterate cannot travel far
    Z, w = node_data(seed=7, n=20_000)
    j_or = objective(oracle_relations(Z, w), Z, w)
    om, _ = fit_relations(Z, w, solver="minibatch", step="inv_sq",
                          rng=np.random.default_rng(0))
    assert objective(om, Z, w) > 1.5 * j_or


# ---- (3)-(5) the plug-ins on synthetic runs ---------------------------------------------------
def run_frame(regime, seed, n=3000, noise=(1.0, 2.0), fault=0.0):
    """A run in one regime: set-point sp.level, channels meas.a and meas.b related by a
    regime-specific gain (b = g·a + noise), and an optional offset fault on meas.a."""
    rng = np.random.default_rng(seed)
    level, gain = {0: (100.0, 1.0), 1: (150.0, 0.6), 2: (200.0, 1.5)}[regime]
    a = level + 5.0 * np.sin(np.arange(n) / 50.0 + seed) + rng.standard_normal(n)
    b = gain * a + noise[regime % 2] * rng.standard_normal(n)
    a = a + fault
    return pd.DataFrame({"t_s": np.arange(n) * 0.01, "sp.level": level, "meas.a": a,
                         "meas.b": b})


PARAMS = dict(smooth_s=0.0, random_state=0, k_max=100)


def alarm_rate(est, frames):
    return float(np.mean(np.concatenate([est.decide(est.score(f)).to_numpy()
                                         for f in frames])))


def test_gsmms_finds_the_regimes_and_its_threshold_is_regime_aware():
    train = [run_frame(r, s) for r in (0, 1) for s in (1, 2, 3)]
    est = GSMMS(**PARAMS).fit(train)
    assert est.n_nodes_ == 2
    scores = est.score(run_frame(1, 9))
    assert set(scores["bmu"]) == {int(est.graph_.bmu(est._standardised(train[3])[0])[0])}
    assert {"statistic", "bmu", "residual.0"} <= set(scores.columns)
    # 2σ per node: about 4.6 % false alarms in each regime despite their unequal noise
    for r in (0, 1):
        assert 0.02 < alarm_rate(est, [run_frame(r, s) for s in (11, 12)]) < 0.08
    # a fault of 8 on a (8σ of its noise) is caught by GSMMS; the global model's one
    # relation must cancel the difference between the regimes and is far noisier
    glob = GlobalParity(**PARAMS).fit(train)
    assert glob.n_nodes_ == 1
    faulty = [run_frame(0, 13, fault=8.0)]
    assert alarm_rate(est, faulty) > 0.95
    assert alarm_rate(glob, faulty) < 0.5


def test_partial_fit_grows_a_node_for_a_new_regime():
    est = GSMMS(**PARAMS).fit([run_frame(0, s) for s in (1, 2)])
    assert est.n_nodes_ == 1
    new = [run_frame(2, s) for s in (3, 4)]
    before = alarm_rate(est, [run_frame(2, 11)])
    est.partial_fit(new)
    assert est.n_nodes_ == 2
    after = alarm_rate(est, [run_frame(2, 11)])
    assert before > 0.5 and after < 0.08
    assert alarm_rate(est, [run_frame(0, 12)]) < 0.08  # the old regime is still known


def test_calibrate_reestimates_node_statistics():
    est = GSMMS(**PARAMS).fit([run_frame(0, s) for s in (1, 2)])
    sd = est.node_std_.copy()
    est.calibrate([run_frame(0, 5, noise=(3.0, 3.0))])
    assert np.all(est.node_std_ > 1.5 * sd)


def test_fault_normalised_relation_sees_a_fault_the_unit_norm_one_misses():
    # b is held still within a regime (a tightly controlled channel) while a varies; both
    # change between regimes: the minimum-variance unit-norm relation of each node is
    # "b = const", blind to a fault on a (as sensor B on the registration line)
    def frame(seed, level, fault=0.0):
        r = np.random.default_rng(seed)
        n = 3000
        return pd.DataFrame({"t_s": np.arange(n) * 0.01, "sp.level": level,
                             "meas.a": level + 3 * r.standard_normal(n) + fault,
                             "meas.b": level / 2 + r.standard_normal(n)})

    train = [frame(s, lv) for s in (1, 2) for lv in (100.0, 130.0)]
    unit = GSMMS(**PARAMS).fit(train)
    fn = GSMMS(fault_channels="meas.a", **PARAMS).fit(train)
    assert unit.n_nodes_ >= 2 and fn.n_nodes_ == 2
    faulty = [frame(9, 100.0, fault=15.0)]
    assert alarm_rate(unit, faulty) < 0.1
    assert alarm_rate(fn, faulty) > 0.9


@pytest.mark.parametrize("params, match", [
    ({"solver": "adam"}, "solver must be one of"),
    ({"step": "const"}, "step must be one of"),
    ({"max_nodes": 0}, "max_nodes must be at least 1"),
    ({"initial_nodes": 4, "max_nodes": 2}, "initial_nodes"),
    ({"eta0": 0.0}, "eta0 must be a positive finite number"),
    ({"k_sigma": float("inf")}, "k_sigma must be a positive finite number"),
    ({"zeta_threshold": float("nan")}, "zeta_threshold"),
    ({"smooth_s": -1.0}, "smooth_s"),
    ({"smooth_s": float("nan")}, "smooth_s must be a finite number"),
    ({"min_improvement": float("inf")}, "min_improvement"),
    ({"fault_channels": "meas.zzz"}, "fault_channels"),
    ({"partition_features": "sp.nothing"}, "no column matching sp.nothing"),
])
def test_parameters_are_validated(params, match):
    with pytest.raises(InputError, match=match):
        GSMMS(**{**PARAMS, **params}).fit([run_frame(0, 1)])


def test_scores_mark_missing_rows():
    est = GSMMS(**PARAMS).fit([run_frame(0, 1)])
    f = run_frame(0, 2)
    f.loc[10:20, "meas.a"] = np.nan
    s = est.score(f)
    assert (s["bmu"].iloc[10:21] == -1).all() and s["statistic"].iloc[10:21].isna().all()
    assert not est.decide(s).iloc[10:21].any()
