"""Exact mathematics of the parity-space method (thesis Ch. 3): Lie derivatives, the
observation matrix and its split, the parity space and its zero pattern, the robust min-max
design against a second solver, and the KKT sensitivities against re-solved designs."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from r2rsim.diagnostics.parity import (
    NonlinearModel,
    design_relation,
    registration_model,
    savgol_derivatives,
    savgol_window_samples,
    sensitivity,
)
from r2rsim.errors import InputError

EA, L, L0, RD, RO = 112.5e3, 1.5, 0.25, 0.10, 0.05
X0, U0 = np.array([130.0]), np.array([5.0, 10.0 * (1 + 1e-5), 129.0])
SCALE = np.array([1.0, 1.0, L0 / EA, L0 / EA])  # newton-equivalent rows


@pytest.fixture(scope="module")
def model():
    return registration_model(EA, L, L0, RD, RO)


def f_span(x, u):
    """The registration span law, written out by hand (docs/model.md)."""
    v1, v2 = RD * u[0], RO * u[1]
    return (EA + x) / L * (v2 - v1 * (EA + x) / (EA + u[2]))


def test_lie_derivatives_and_gradient_match_finite_differences(model):
    O = model.observation(X0, U0)
    assert O[0] == pytest.approx(130.0, rel=1e-15)
    assert O[1] == pytest.approx(f_span(130.0, U0), rel=1e-12)
    assert O[2] == pytest.approx((130.0 / EA + 1) * L0, rel=1e-15)
    assert O[3] == pytest.approx(L0 / EA * f_span(130.0, U0), rel=1e-12)
    h = 1e-3
    fd = (model.observation_nl(X0 + h, U0) - model.observation_nl(X0 - h, U0)) / (2 * h)
    np.testing.assert_allclose(model.grad_x(X0, U0)[:, 0], fd, rtol=1e-7)
    # ∂(∇_x O)/∂p against central differences in each p_k
    p0 = np.concatenate([X0, U0])
    for k, G in enumerate(model.grad_xp(X0, U0)):
        e = np.zeros(4)
        e[k] = 1e-4 * max(abs(p0[k]), 1.0)
        gp = model.grad_x((p0 + e)[:1], (p0 + e)[1:])
        gm = model.grad_x((p0 - e)[:1], (p0 - e)[1:])
        np.testing.assert_allclose(G, (gp - gm) / (2 * e[k]), rtol=1e-6, atol=1e-15)


def test_input_part_E_U_on_a_model_whose_sensor_reads_the_input():
    # h depends on u, so L_f h carries (∂h/∂u)·u̇: the E·U term of eqs. 3.7/3.13
    m = NonlinearModel(
        lambda x, u: [-2.0 * x[0] + u[0]], lambda x, u: [x[0] * (1 + 0.1 * u[0]), x[0] ** 2], 1, 1
    )
    x, u, du = np.array([3.0]), np.array([0.5]), np.array([0.7])
    O = m.observation(x, u, [du])
    f = -2 * 3.0 + 0.5
    np.testing.assert_allclose(O, [3 * 1.05, 1.05 * f + 0.3 * 0.7, 9.0, 6.0 * f], rtol=1e-14)
    np.testing.assert_allclose(m.input_part(x, u, [du]), [0, 0.3 * 0.7, 0, 0], atol=1e-15)
    np.testing.assert_allclose(m.input_matrix(x, u)[:, 0], [0, 0.3, 0, 0], atol=1e-15)
    np.testing.assert_allclose(O - m.observation_nl(x, u), m.input_part(x, u, [du]), atol=1e-15)
    # the registration sensors do not read the inputs: E·U is identically zero there
    reg = registration_model(EA, L, L0, RD, RO)
    assert np.all(reg.input_part(X0, U0, [np.array([1.0, 2.0, 3.0])]) == 0)


def test_number_of_relations_is_n_minus_N(model):
    # n = Σ(m_j + 1) = 4 rows, N = 1 state: 3 relations (eq. 3.11), not the printed n − M = 2
    assert model.n_outputs == 4
    assert model.n_relations(X0, U0) == 3
    assert model.parity_space(X0, U0).shape == (3, 4)
    two = NonlinearModel(
        lambda x, u: [x[1], -x[0] + u[0]], lambda x, u: [x[0], x[0] + x[1]], 2, 1, orders=(1, 1)
    )
    assert two.n_outputs == 4 and two.n_relations([0.3, 0.1], [0.0]) == 2


def test_null_space_condition(model):
    G = model.grad_x(X0, U0)
    W = model.parity_space(X0, U0)
    for w in W:
        assert np.linalg.norm(w @ G) <= 1e-9 * np.linalg.norm(w) * np.linalg.norm(G)
    for w in model.sensor_relations(X0, U0, scale=SCALE):
        r = (w / SCALE) @ G
        assert abs(r) <= 1e-9 * np.linalg.norm(w / SCALE) * np.linalg.norm(G)


def test_zero_pattern_of_table_3_2_falls_out_of_the_null_space(model):
    # the relations in Ω^⊥ with no sensor-A entries form a 1-D space (Ω², B only) and those
    # with no sensor-B entries another (Ω³, A only): found from the parity-space basis alone
    W = model.parity_space(X0, U0) / SCALE  # relations on the newton-equivalent stack
    W = W / np.linalg.norm(W, axis=1, keepdims=True)
    fx = model.grad_x(X0, U0)[1, 0]
    d = sp.diff(f_span(sp.Symbol("x"), U0), sp.Symbol("x")).subs("x", 130.0)
    assert fx == pytest.approx(float(d), rel=1e-12)
    for zero_cols, keep in (([0, 1], [2, 3]), ([2, 3], [0, 1])):
        from scipy.linalg import null_space

        c = null_space(W[:, zero_cols].T)
        assert c.shape[1] == 1
        w = c[:, 0] @ W
        w = w / np.linalg.norm(w) * np.sign(w[keep[1]])
        assert np.max(np.abs(w[zero_cols])) <= 1e-12
        # the closed form: ẏ − f_x·y within the sensor's block (rows in N-equivalents)
        expect = np.array([-fx, 1.0]) / np.hypot(fx, 1.0)
        np.testing.assert_allclose(w[keep], expect, rtol=1e-9)


def _scenarios(seed=0, K=3):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(K):
        A = rng.normal(size=(4, 4)) * np.array([3.0, 1.5, 3.0, 2.0])
        out.append(A.T @ A / 4 + 0.1 * np.eye(4))
    return np.array(out)


def _N(model, p):
    return model.grad_x(p[:1], p[1:]) / SCALE[:, None]


def _dN(model, p):
    return model.grad_xp(p[:1], p[1:]) / SCALE[None, :, None]


P0 = np.concatenate([X0, U0])
F_A = np.array([[1.0], [0.0], [0.0], [0.0]])
F_AB = np.array([[1.0, 0.0], [0.0, 0.0], [0.0, 1.0], [0.0, 0.0]])


@pytest.mark.parametrize(
    "kind,F", [("fault_normalised", F_A), ("fault_normalised", F_AB), ("unit_norm", None)]
)
def test_min_max_matches_a_second_solver(model, kind, F):
    S = _scenarios()
    a = design_relation(S, _N(model, P0), F, kind, solver="slsqp")
    b = design_relation(S, _N(model, P0), F, kind, solver="trust-constr", polish=False)
    assert np.max(np.abs(a.omega - b.omega)) <= 1e-6 * np.max(np.abs(a.omega))
    assert abs(a.J - b.J) <= 1e-6 * a.J
    # it is a min-max: the optimum is the max over the scenarios, and no feasible move
    # along the constraint set lowers it (checked on random feasible directions)
    assert a.J == pytest.approx(max(a.omega @ s @ a.omega for s in S), rel=1e-12)
    assert np.linalg.norm(a.omega @ _N(model, P0)) < 1e-12


def test_fault_normalised_design_is_not_blind_where_unit_norm_is(model):
    # raw SI units: the pitch rows are ~1e-6 m, so the smallest ‖ω‖ = 1 residual lives in
    # the B rows alone: a relation that no fault of sensor A can move
    S = np.diag([1.5**2, 1.0, (8e-6) ** 2, (5e-6) ** 2])[None]
    G = model.grad_x(X0, U0)
    unit = design_relation(S, G, None, "unit_norm")
    offset_A = np.array([1.0, 0.0, 0.0, 0.0])  # 1 N on sensor A, as it enters the stack
    assert abs(unit.omega @ offset_A) < 1e-5  # blind: a 100 N offset moves it < 1e-3
    assert abs(unit.omega @ offset_A) * 100 < 1e-3
    fn = design_relation(S, G, offset_A[:, None], "fault_normalised")
    assert fn.omega @ offset_A == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("kind,F", [("fault_normalised", F_A), ("unit_norm", None)])
def test_kkt_sensitivities_match_finite_differences(model, kind, F):
    S = _scenarios(seed=3)
    d = design_relation(S, _N(model, P0), F, kind)
    dJ, dom, env = sensitivity(d, S, _N(model, P0), F, _dN(model, P0), kind)
    np.testing.assert_allclose(dJ, env, rtol=1e-8, atol=1e-14 * abs(d.J))
    for k in range(4):
        h = 1e-4 * max(abs(P0[k]), 1.0)
        e = np.zeros(4)
        e[k] = h
        up = design_relation(S, _N(model, P0 + e), F, kind, start=d.omega)
        dn = design_relation(S, _N(model, P0 - e), F, kind, start=d.omega)
        fd_J = (up.J - dn.J) / (2 * h)
        fd_w = (up.omega - dn.omega) / (2 * h)
        assert fd_J == pytest.approx(dJ[k], rel=1e-5)
        assert np.max(np.abs(fd_w - dom[k])) <= 1e-5 * np.max(np.abs(dom[k]))


def test_design_parameters_are_validated(model):
    with pytest.raises(InputError, match="design must be one of"):
        design_relation(_scenarios(), _N(model, P0), F_A, "rayleigh")
    with pytest.raises(InputError, match="needs fault directions"):
        design_relation(_scenarios(), _N(model, P0), None, "fault_normalised")


def test_savitzky_golay_derivatives_and_group_delay():
    dt = 0.01
    t = np.arange(0, 5, dt)
    X = np.column_stack([3 + 2 * t - 0.5 * t**2, np.sin(t)])
    w = savgol_window_samples(0.5, dt, 2)
    assert w == 51
    D, delay = savgol_derivatives(X, dt, w, 3, 1)
    assert delay == 0.0
    # a quadratic is fitted exactly by an order-3 filter, derivative included
    np.testing.assert_allclose(D[0][:, 0], X[:, 0], atol=1e-10)
    np.testing.assert_allclose(D[1][:, 0], 2 - t, atol=1e-9)
    np.testing.assert_allclose(D[1][60:-60, 1], np.cos(t[60:-60]), atol=2e-5)
    # causal: past samples only, estimates of the instant half a window back, the values
    # and the derivatives alike (both aligned at t - delay)
    Dc, delay_c = savgol_derivatives(X, dt, w, 3, 1, causal=True)
    assert delay_c == pytest.approx(25 * dt)
    k = np.arange(w - 1, len(t))
    td = t[k] - delay_c
    np.testing.assert_allclose(Dc[0][k, 0], 3 + 2 * td - 0.5 * td**2, atol=1e-9)
    np.testing.assert_allclose(Dc[1][k, 0], 2 - td, atol=1e-9)
    np.testing.assert_allclose(Dc[1][k, 1], np.cos(td), atol=2e-5)
    # no full window behind the first w - 1 samples: no estimate (the centred filter's
    # edge fit there would read samples up to w - 1)
    assert np.all(np.isnan(Dc[:, : w - 1])) and np.all(np.isfinite(Dc[:, w - 1 :]))
    # causality: the estimates from samples 0..k are those of the whole record
    for k in (w - 1, w, 200, len(t) - 2):
        Dk, _ = savgol_derivatives(X[: k + 1], dt, w, 3, 1, causal=True)
        np.testing.assert_array_equal(Dk, Dc[:, : k + 1])
    # the centred filter reads half a window ahead: cutting the record changes its end
    Dk, _ = savgol_derivatives(X[:201], dt, w, 3, 1)
    assert np.max(np.abs(Dk[1][-25:, 1] - D[1][175:201, 1][-25:])) > 1e-4
    # a drop-out is bridged, not propagated
    Xn = X.copy()
    Xn[200, 0] = np.nan
    assert np.all(np.isfinite(savgol_derivatives(Xn, dt, w, 3, 1)[0]))
    # causal: the bridge reads sample 201, so the estimate at 200 itself is NaN (that
    # channel only); from 201 on the bridged record is used, as in the centred filter
    Dn, _ = savgol_derivatives(Xn, dt, w, 3, 1, causal=True)
    assert np.all(np.isnan(Dn[:, 200, 0])) and np.all(np.isfinite(Dn[:, 200, 1]))
    assert np.all(np.isfinite(Dn[:, 201:]))
    for k in (200, 201, 230):
        np.testing.assert_array_equal(
            savgol_derivatives(Xn[: k + 1], dt, w, 3, 1, True)[0], Dn[:, : k + 1]
        )
    with pytest.raises(InputError, match="odd"):
        savgol_derivatives(X, dt, 50, 3)
