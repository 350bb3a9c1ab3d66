"""GSMMS (thesis Ch. 4): the growing map's stopping criteria, local relations by SGD against
the exact oracle, per-node detection, online growth, the default's response to a fault on
every model channel, and the plug-in's parameter checks,
on synthetic data with known regimes; the physics term of eq. 4.21 also on two short runs
of the calibrated registration line."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

import r2rsim
from r2rsim.dataset.read import read_runs
from r2rsim.diagnostics.gsmms import GSMMS, GlobalParity, fit_relations, objective, oracle_relations
from r2rsim.diagnostics.gsmms._local import fault_normalised_oracle, weighted_moments
from r2rsim.diagnostics.gsmms._model import GrowthSettings, grow, initial_map
from r2rsim.diagnostics.line import LINE_ATTR, attach_line
from r2rsim.errors import InputError

from conftest import REPO

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
    graph, models, history = grown(S, Z, zeta_threshold=0.0, min_improvement=None, max_nodes=6)
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
    Z = np.c_[
        t + 0.3 * rng.standard_normal(n),
        2 * t + 0.3 * rng.standard_normal(n),
        rng.standard_normal(n) + 0.2 * t,
    ]
    Z = (Z - Z.mean(0)) / Z.std(0) + np.array([0.5, -0.2, 1.0])  # uncentred, as P is
    hops = rng.integers(0, 3, n)
    w = np.exp(-(hops**2) / (2 * 0.8**2))
    return Z, w


def cosine(a, b):
    return abs(a @ b) / np.linalg.norm(a) / np.linalg.norm(b)


@pytest.mark.parametrize("lambda1", [1.0, 0.5])
def test_minibatch_sgd_matches_the_eigenvector_oracle(lambda1):
    Z, w = node_data()
    oracle = oracle_relations(Z, w, lambda1=lambda1)
    om, b = fit_relations(
        Z, w, solver="minibatch", lambda1=lambda1, n_epochs=2.0, rng=np.random.default_rng(0)
    )
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
    om, _ = fit_relations(Z, w, 2, solver="minibatch", n_epochs=2.0, rng=np.random.default_rng(0))
    assert abs(om[:, 0] @ om[:, 1]) < 1e-9
    for k in range(2):
        assert cosine(om[:, k], oracle[:, k]) >= 0.999


def test_fault_normalised_relation_matches_its_oracle():
    Z, w = node_data(seed=5)
    F = np.eye(3)[:, [0]]
    oracle = fault_normalised_oracle(Z, w, F)
    assert oracle[0, 0] == pytest.approx(1.0)
    om, _ = fit_relations(Z, w, F=F, solver="minibatch", n_epochs=2.0, rng=np.random.default_rng(0))
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
    om, _ = fit_relations(Z, w, solver="minibatch", step="inv_sq", rng=np.random.default_rng(0))
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
    return pd.DataFrame({"t_s": np.arange(n) * 0.01, "sp.level": level, "meas.a": a, "meas.b": b})


PARAMS = dict(smooth_s=0.0, random_state=0, k_max=100)


def alarm_rate(est, frames):
    return float(np.mean(np.concatenate([est.decide(est.score(f)).to_numpy() for f in frames])))


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
        return pd.DataFrame(
            {
                "t_s": np.arange(n) * 0.01,
                "sp.level": level,
                "meas.a": level + 3 * r.standard_normal(n) + fault,
                "meas.b": level / 2 + r.standard_normal(n),
            }
        )

    train = [frame(s, lv) for s in (1, 2) for lv in (100.0, 130.0)]
    unit = GSMMS(fault_channels=None, **PARAMS).fit(train)  # the thesis's relation
    fn = GSMMS(fault_channels="meas.a", **PARAMS).fit(train)
    assert unit.n_nodes_ >= 2 and fn.n_nodes_ == 2
    assert unit.models_.omega[0].shape == (2, 1)
    faulty = [frame(9, 100.0, fault=15.0)]
    assert alarm_rate(unit, faulty) < 0.1
    assert alarm_rate(fn, faulty) > 0.9
    # the old unit-norm design still takes several relations
    two = GSMMS(fault_channels=None, n_relations=2, **PARAMS).fit(train)
    assert two.models_.omega[0].shape == (2, 2)


def held_frame(seed, level, fault_a=0.0, fault_b=0.0, n=3000):
    """meas.b held still within a regime (noise 1), meas.a free (noise 3), both following
    the set-point: the case where one unit-norm relation is blind to a."""
    r = np.random.default_rng(seed)
    return pd.DataFrame(
        {
            "t_s": np.arange(n) * 0.01,
            "sp.level": level,
            "meas.a": level + 3 * r.standard_normal(n) + fault_a,
            "meas.b": level / 2 + r.standard_normal(n) + fault_b,
        }
    )


def test_default_sees_a_fault_on_every_model_channel():
    # the default (fault_channels="all"): one relation per model channel with unit response
    # to that channel's fault, so a step on either channel moves the statistic by its size
    # in node σ; the unit-norm relation of the same data moves by less than 1σ for a
    train = [held_frame(s, lv) for s in (1, 2, 3) for lv in (100.0, 130.0)]
    est = GSMMS(**PARAMS).fit(train)
    est.calibrate([held_frame(s, lv) for s in (4, 5) for lv in (100.0, 130.0)])
    assert est.fault_channels == "all"
    for om in est.models_.omega:  # e_j·Ω_j = 1 for every node and channel
        np.testing.assert_allclose(np.diag(om), 1.0, atol=1e-9)
    unit = GSMMS(fault_channels=None, **PARAMS).fit(train)
    unit.calibrate([held_frame(s, lv) for s in (4, 5) for lv in (100.0, 130.0)])

    def shift(e, **fault):  # mean statistic, faulty minus healthy (same noise, seed 9)
        return float(
            np.mean(e.score(held_frame(9, 100.0, **fault))["statistic"])
            - np.mean(e.score(held_frame(9, 100.0))["statistic"])
        )

    k = 3.0
    # steps of 5σ of each channel's own noise (a: 15, b: 5)
    assert shift(est, fault_a=15.0) > k and shift(est, fault_b=5.0) > k
    assert alarm_rate(est, [held_frame(9, 100.0, fault_a=15.0)]) > 0.9
    assert alarm_rate(est, [held_frame(9, 100.0, fault_b=5.0)]) > 0.9
    # the unit-norm relation of the same map is "b = const", blind to a
    assert shift(unit, fault_a=15.0) < 1.0


def test_default_sees_both_sensors_of_the_registration_line(registration_runs):
    # 20 s of OC1 and OC2, relations over sensor A and sensor B by default (fault_channels
    # "all"; their residual σ here: about 2 N and 3 µm): a step offset of 15 N on A (12 % of
    # OC1's 130 N) and of 20 µm on B's 0.25 m pitch (a gain of 8e-5) from t = 10 s each
    # move the statistic by more than 3 node σ on average over the faulty samples
    est = GSMMS(model_features=[A_COL, B_COL], random_state=0).fit(registration_runs)
    assert len(est.models_.omega[0].T) == 2
    for run in registration_runs:
        f = run.visible()
        late = (f["t_s"] >= 12.0).to_numpy()  # 2 s after the step (1 s smoothing)
        base = est.score(f)["statistic"].to_numpy()[late]
        for col, step in ((A_COL, 15.0), (B_COL, 20e-6)):
            g = f.copy()
            g.loc[g["t_s"] >= 10.0, col] += step
            moved = est.score(g)["statistic"].to_numpy()[late]
            assert np.mean(moved) - np.mean(base) > 3.0, (run.mode, col)


def test_fault_normalised_oracle_with_a_constant_channel():
    # a channel the node's data never move: its relation is that channel alone (zero
    # variance, unit response) instead of C⁺f/(fᵀC⁺f) = 0/0
    Z, w = node_data(seed=3, n=2000)
    Z = np.c_[Z, np.full(len(Z), 0.7)]
    om = fault_normalised_oracle(Z, w, np.eye(4))
    assert np.all(np.isfinite(om))
    np.testing.assert_allclose(np.diag(om), 1.0, atol=1e-12)
    np.testing.assert_allclose(om[:, 3], [0, 0, 0, 1], atol=1e-12)
    for j in range(3):  # the others ignore the constant channel's (null) direction
        assert abs(om[3, j]) < 1e-9


@pytest.mark.parametrize(
    "params, match",
    [
        ({"solver": "adam"}, "solver must be one of"),
        ({"step": "const"}, "step must be one of"),
        ({"max_nodes": 0}, "max_nodes must be an integer from 1 to 1000"),
        ({"initial_nodes": 4, "max_nodes": 2}, "initial_nodes"),
        ({"eta0": 0.0}, "eta0 must be > 0 and at most 2"),
        ({"eta0": 1e300}, "eta0 must be > 0 and at most 2"),
        ({"n_epochs": 1e300}, "n_epochs must be > 0 and at most 100"),
        ({"sigma0": 1e300}, "sigma0 must be > 0 and at most 1000"),
        ({"k_max": 10**12}, "k_max must be an integer from 1 to 100000"),
        ({"batch_size": 10**12}, "batch_size must be an integer from 1 to 4096"),
        ({"batch_size": 128.5}, "batch_size must be an integer"),
        ({"max_nodes": True}, "max_nodes must be an integer"),
        ({"k_sigma": float("inf")}, "k_sigma must be a positive finite number"),
        ({"zeta_threshold": float("nan")}, "zeta_threshold"),
        ({"smooth_s": -1.0}, "smooth_s"),
        ({"smooth_s": float("nan")}, "smooth_s must be a finite number"),
        ({"min_improvement": float("inf")}, "min_improvement"),
        ({"fault_channels": "meas.zzz"}, "fault_channels"),
        ({"partition_features": "sp.nothing"}, "no column matching sp.nothing"),
        # failed inside the fit (numpy's seed, fnmatch) as plug-in crashes, exit 1
        (
            {"random_state": -1},
            "random_state must be null or an integer from 0 to 18446744073709551615, got -1",
        ),
        ({"random_state": 2**64}, "random_state must be null or an integer"),
        ({"model_features": [1, 2]}, "model_features must be a glob pattern or a list of them"),
        ({"partition_features": 3}, "partition_features must be a glob pattern"),
        ({"fault_channels": [None]}, "fault_channels must be a glob pattern"),
        ({"fault_channels": 3}, "fault_channels must be a glob pattern or a list of them"),
        ({"fault_channels": []}, "fault_channels"),
        # several unit-norm relations need the unit-norm design (the default is fault-normalised)
        (
            {"n_relations": 2},
            r"n_relations = 2 applies to the unit-norm relations \(fault_channels:"
            r" null\); with fault_channels 'all' there is one",
        ),
        ({"n_relations": 2, "fault_channels": "meas.a"}, "n_relations = 2 applies to the unit"),
        # accepted before, contradicting the method: a widening neighbourhood, a share above 1
        # (the map never grew), truthiness deciding a switch ("no" turned derivatives on)
        ({"sigma0": 1.0, "sigma_final": 5.0}, r"sigma_final \(5.0\) must not exceed sigma0"),
        ({"zeta_threshold": 5.0}, r"zeta_threshold is a share of the loss, in \(0, 1\)"),
        ({"derivatives": "no"}, "derivatives must be true or false, got 'no'"),
        # more relations than the model features leave: a bare ValueError inside the fit
        (
            {"n_relations": 10, "fault_channels": None},
            "n_relations = 10, but the 2 model features leave 2 dimension",
        ),
    ],
)
def test_parameters_are_validated(params, match):
    with pytest.raises(InputError, match=match):
        GSMMS(**{**PARAMS, **params}).fit([run_frame(0, 1)])


def test_scoring_data_without_the_fitted_columns_is_an_input_error():
    # another line's data: a KeyError of pandas before
    est = GSMMS(**PARAMS).fit([run_frame(0, 1)])
    with pytest.raises(InputError, match=r"gsmms: the data has no column meas.b \(fitted"):
        est.score(run_frame(0, 2).drop(columns=["meas.b"]))


def test_global_model_checks_its_seed():
    with pytest.raises(InputError, match="gsmms_global: random_state must be null or an"):
        GlobalParity(**{**PARAMS, "random_state": -1}).fit([run_frame(0, 1)])


def test_scores_mark_missing_rows():
    est = GSMMS(**PARAMS).fit([run_frame(0, 1)])
    f = run_frame(0, 2)
    f.loc[10:20, "meas.a"] = np.nan
    s = est.score(f)
    assert (s["bmu"].iloc[10:21] == -1).all() and s["statistic"].iloc[10:21].isna().all()
    assert not est.decide(s).iloc[10:21].any()


# ---- the physics term of eq. 4.21 (λ2, ∇_x O_NL from the parity plug-in's model) ----------
def test_fault_normalised_oracle_with_a_constraint_solves_the_kkt_system():
    # minimise ΩᵀCΩ subject to f·Ω = 1 and GᵀΩ = 0: against the KKT linear system
    Z, w = node_data(seed=8, n=5000)
    F = np.eye(3)[:, [0]]
    G = np.array([[1.0], [0.5], [-0.2]])
    om = fault_normalised_oracle(Z, w, F, G=G)[:, 0]
    assert om @ F[:, 0] == pytest.approx(1.0, abs=1e-12)
    assert abs(om @ G[:, 0]) < 1e-12
    mu = w @ Z / w.sum()
    C = ((Z - mu) * w[:, None]).T @ (Z - mu) / w.sum()
    A = np.c_[F, G]
    K = np.block([[2 * C, A], [A.T, np.zeros((2, 2))]])
    kkt = np.linalg.solve(K, np.r_[np.zeros(3), 1.0, 0.0])[:3]
    np.testing.assert_allclose(om, kkt, rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="span of the constraint"):
        fault_normalised_oracle(Z, w, F, G=F)


@pytest.mark.parametrize("lambda2", [1.0, 5.0])
def test_sgd_minimises_the_penalised_loss_and_the_oracle_is_its_hard_limit(lambda2):
    # with node scaling (tr C = 1) the loss is Ωᵀ(C + λ2·GGᵀ)Ω + λ1(‖Ω‖² − 1)²: its
    # minimiser is the smallest eigenvector of C + λ2·GGᵀ, which tends to the constrained
    # oracle as λ2 grows
    Z, w = node_data(seed=9)
    G = np.array([[0.6], [0.8], [0.0]])  # unit norm, as the plug-in gives it
    _, C = weighted_moments(Z, w)
    soft, _ = fit_relations(
        Z, w, solver="minibatch", lambda2=lambda2, G=G, n_epochs=2.0, rng=np.random.default_rng(0)
    )
    exact = np.linalg.eigh(C + lambda2 * G @ G.T)[1][:, 0]
    assert cosine(soft[:, 0], exact) >= 0.999
    hard, _ = fit_relations(Z, w, solver="eigh", G=G)
    assert abs(hard[:, 0] @ G[:, 0]) < 1e-12
    assert cosine(np.linalg.eigh(C + 1e8 * G @ G.T)[1][:, 0], hard[:, 0]) >= 1 - 1e-9
    free, _ = fit_relations(Z, w, solver="eigh")
    assert cosine(free[:, 0], hard[:, 0]) < 0.99  # the constraint changes the relation


@pytest.mark.parametrize("lambda2", [1.0, 5.0])
def test_fault_normalised_sgd_minimises_the_penalised_loss(lambda2):
    # min Ωᵀ(C + λ2·GGᵀ)Ω subject to f·Ω = 1: Ω = M⁻¹f / (fᵀM⁻¹f) with M = C + λ2·GGᵀ
    Z, w = node_data(seed=5)  # the data of the unconstrained fault-normalised test
    G = np.array([[0.6], [0.0], [0.8]])
    f = np.eye(3)[:, 0]
    _, C = weighted_moments(Z, w)
    soft, _ = fit_relations(
        Z,
        w,
        solver="minibatch",
        lambda2=lambda2,
        G=G,
        F=f[:, None],
        n_epochs=2.0,
        rng=np.random.default_rng(0),
    )
    m = np.linalg.solve(C + lambda2 * G @ G.T, f)
    assert soft[0, 0] == pytest.approx(1.0, abs=1e-9)
    assert cosine(soft[:, 0], m / (f @ m)) >= 0.999


A_COL, B_COL = "meas.sensor_A.tension_N", "meas.sensor_B.pitch_m"
REG_LINE = str(REPO / "lines" / "registration_realistic.yaml")


@pytest.fixture(scope="module")
def registration_runs(tmp_path_factory):
    """20 s of the calibrated registration line in OC1 and in OC2 (encoders on the model's
    inputs), healthy."""
    import yaml

    d = tmp_path_factory.mktemp("gsmms_physics")
    base = yaml.safe_load(
        (REPO / "scenarios" / "thesis_realistic" / "registration.yaml").read_text(encoding="utf-8")
    )
    out = []
    for mode, v, T in (("OC1", 0.5, 130), ("OC2", 1.0, 160)):
        sc = {
            **base,
            "line": REG_LINE,
            "duration": "20 s",
            "programme": [
                {
                    "at": "0 s",
                    "line_speed": f"{v} m/s",
                    "mode": mode,
                    "tension": {"registration_loop": f"{T} N", "unwind_tension": f"{T} N"},
                }
            ],
        }
        (d / f"{mode}.yaml").write_text(yaml.safe_dump(sc), encoding="utf-8")
        r2rsim.run_scenario(d / f"{mode}.yaml", output=d / mode, seed=1)
        out.append(read_runs(d / mode)[0])
    return out


@pytest.mark.parametrize("derivatives", [False, True])
def test_physics_relations_cancel_the_state_of_the_reduced_model(registration_runs, derivatives):
    est = GSMMS(
        model_features=[A_COL, B_COL],
        fault_channels=A_COL,
        derivatives=derivatives,
        physics={"line": REG_LINE},
        solver="eigh",
        random_state=0,
    )
    est.fit(registration_runs)
    det = est.physics_
    EA, L0 = det.physical_["web_EA_N"], det.physical_["relaxed_pitch_m"]
    # L0 calibrated by Hooke's law between the sensors, independently here
    f = registration_runs[0].samples
    assert L0 == pytest.approx(np.nanmedian(f[B_COL] / (1 + f[A_COL] / EA)), rel=1e-3)
    P = est._kept[2]
    bmu = est.graph_.bmu(est._kept[0])
    for m in range(est.n_nodes_):
        p = np.nanmean(P[bmu == m], axis=0)
        # ∂O_NL/∂x at the node's point by central differences of the observation itself
        h = 1e-3 * abs(p[0])
        dO = (
            det.model_.observation_nl(p[:1] + h, p[1:])
            - det.model_.observation_nl(p[:1] - h, p[1:])
        ) / (2 * h)
        g = dO[[0, 2, 1, 3] if derivatives else [0, 2]]  # stack [A, Ȧ, B, Ḃ] -> features
        omega_raw = est.models_.omega[m][:, 0] / est.z_scale_
        assert abs(omega_raw @ g) <= 1e-6 * np.linalg.norm(omega_raw) * np.linalg.norm(g)
        assert omega_raw[0] * est.z_scale_[0] == pytest.approx(1.0)  # unit response to A
    assert est.decide(est.score(registration_runs[1])).mean() < 0.2


@pytest.mark.parametrize(
    "params, match",
    [
        ({"physics": "lines/registration_realistic.yaml"}, "physics must be a mapping"),
        ({"physics": {"line": REG_LINE, "speed": 1}}, "physics has no parameter speed"),
        ({"physics": {"line": REG_LINE}, "model_features": [A_COL]}, "must be the reduced model"),
        ({"physics": {"line": REG_LINE, "design": "x"}}, "design must be one of"),
        ({"physics": {"line": REG_LINE, "drive_speed": "meas.none"}}, "meas.none"),
        ({"lambda2": -1.0}, "lambda2 must be a finite number >= 0"),
        ({"lambda2": float("nan")}, "lambda2"),
        ({"lambda2": True}, "lambda2 must be a number"),
        ({"physics": {"line": True}}, "line must be the path of a line file"),
    ],
)
def test_physics_parameters_are_validated(registration_runs, params, match):
    with pytest.raises(InputError, match=match):
        GSMMS(**{"model_features": [A_COL, B_COL], **params}).fit(registration_runs[:1])


def test_training_arrays_are_what_the_fit_used():
    # refitting each node's relation on them with the exact solver gives the fitted one
    runs = [run_frame(0, 1), run_frame(1, 2)]
    est = GSMMS(**{**PARAMS, "solver": "eigh", "max_samples": 4000, "fault_channels": None}).fit(
        runs
    )
    S, Z = est.training_arrays(runs)
    assert S.shape == (4000, len(est.partition_columns_))
    assert Z.shape == (4000, len(est.model_columns_))
    bmu = est.graph_.bmu(S)
    for m in range(est.n_nodes_):
        om, _ = fit_relations(Z[bmu == m], np.ones(np.sum(bmu == m)), solver="eigh")
        om /= np.linalg.norm(om)
        assert cosine(om[:, 0], est.models_.omega[m][:, 0]) == pytest.approx(1.0, abs=1e-12)
    with pytest.raises(RuntimeError, match="not fitted"):
        GSMMS().training_arrays(runs)


def test_the_physics_term_refuses_a_run_of_another_line(registration_runs):
    # fitted with the physics term configured from the runs' own line; a run said to come
    # from a line with a longer registration span is refused, naming the number
    est = GSMMS(
        model_features=[A_COL, B_COL],
        fault_channels=A_COL,
        physics={},
        solver="eigh",
        random_state=0,
    ).fit(registration_runs)
    assert est.physics_.physical_["span_length_m"] == 1.5
    frame = attach_line(registration_runs[1].visible(), registration_runs[1])
    other = json.loads(frame.attrs[LINE_ATTR])
    next(s for s in other["spans"] if s.get("id") == "registration")["length"] = "2 m"
    frame.attrs[LINE_ATTR] = json.dumps(other)
    with pytest.raises(
        InputError,
        match=r"span_length_m 2 m where the model was fitted "
        r"with 1.5 m",
    ):
        est.score(frame)
