"""docs/physics.md §3 verification tests, through line files and the public API.

Expected values and tolerances are those of physics.md §3; where the exact span model
(eq. 1.2) has a different answer and §3 does not list it, the closed form is derived in the
test (logistic solution of the single-span equation) and stated there.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import r2rsim

from conftest import kinematic_line, run_line, write

MODELS = ["linear", "exact"]


@pytest.fixture(params=["cvode", "radau5"])
def backend(request):
    """Every simulated verification runs on both r2rsim integrators (the compiled Radau
    IIA, the default, and CVODE BDF2)."""
    return request.param


def at(res, name, t):
    """Value of an output at a sample time (must be on the grid)."""
    k = int(np.argmin(np.abs(res.t - t)))
    assert abs(res.t[k] - t) < 1e-9 * max(1.0, t), (res.t[k], t)
    return res[name][k]


# ---------------------------------------------------------------- V1 single-span step response
@pytest.mark.parametrize("model", MODELS)
def test_v1_single_span_step(tmp_path, model, backend):
    path = kinematic_line(tmp_path, model=model, EA=1.0e5, spans=[2.0], draws=[0.0, 0.001])
    tau = 2.0 / 1.001
    # record rate chosen so that t = tau, 1 s and 10 s fall on the sample grid
    cl, res = run_line(
        path,
        backend=backend,
        duration=10.0,
        rate=1000.0,
        steps=[{"at": 0, "line_speed": 1.0}],
        tension=0.0,
    )
    _, res_tau = run_line(
        path,
        backend=backend,
        duration=tau,
        rate=1000.0 / tau,
        steps=[{"at": 0, "line_speed": 1.0}],
        tension=0.0,
    )
    T_tau = res_tau["span1.tension_N"][-1]
    assert res_tau.t[-1] == pytest.approx(tau, rel=1e-12)
    if model == "linear":
        T_inf = 99.9001
        assert T_tau == pytest.approx(63.1489, rel=1e-5)
        assert at(res, "span1.tension_N", 1.0) == pytest.approx(39.3379, rel=1e-5)
        assert at(res, "span1.tension_N", 10.0) == pytest.approx(99.2303, rel=1e-5)
        assert T_inf * (1 - math.exp(-1)) == pytest.approx(T_tau, rel=1e-5)
    else:
        assert T_tau == pytest.approx(63.1888, rel=1e-5)
        # logistic closed form of eq. (1.2): w = 1 + eps, w(t) = r / (1 + (r - 1) e^(-v1 t/L))
        r = 1.001
        for t in (1.0, 10.0):
            w = r / (1 + (r - 1) * math.exp(-1.001 * t / 2.0))
            assert at(res, "span1.tension_N", t) == pytest.approx(1e5 * (w - 1), rel=1e-5)
        assert 1e5 * (r - 1) == pytest.approx(100.0)  # T_inf = EA (v1/v0 - 1)


# ---------------------------------------------------------------- V3 steady tension chain
@pytest.mark.parametrize(
    "model,expected",
    [
        ("linear", [299.7003, 499.0020, 399.4009]),
        ("exact", [300.1000, 500.2000, 400.1500]),
    ],
)
def test_v3_draw_chain(tmp_path, model, expected, backend):
    EA = 2.0e5
    path = kinematic_line(
        tmp_path,
        model=model,
        EA=EA,
        spans=[1.0, 1.0, 1.0],
        draws=[0.0, 0.001, 0.002, 0.0015],
        wound_strain=100.0 / EA,
    )
    _, res = run_line(
        path,
        backend=backend,
        duration=8.0,
        rate=100.0,
        steps=[{"at": 0, "line_speed": 5.0}],
        tension=100.0,
    )
    got = [res[f"span{i}.tension_N"][-1] for i in (1, 2, 3)]
    np.testing.assert_allclose(got, expected, atol=1e-3)
    # and it started far from there (the test integrates, it does not start at the answer)
    assert abs(res["span2.tension_N"][0] - expected[1]) > 100


# ---------------------------------------------------------------- V5 tension transfer over idler
def _idler_line(tmp_path, model, *, J=0.01, coulomb=0.0, viscous=0.0, EA=1.0e5):
    idler = (
        f"type: idler, radius: 0.05, inertia: {J!r}, "
        f"friction: {{coulomb: {coulomb!r}, viscous: {viscous!r}}}"
    )
    return kinematic_line(
        tmp_path,
        model=model,
        EA=EA,
        spans=[1.0, 1.0],
        draws=[0, 0, 0],
        wound_strain=100.0 / EA,
        middle=[idler],
    )


@pytest.mark.parametrize("model", MODELS)
def test_v5_idler_transfer(tmp_path, model, backend):
    EA = 1.0e5
    path = _idler_line(tmp_path, model)
    _, res = run_line(
        path,
        backend=backend,
        duration=5.0,
        rate=100.0,
        steps=[{"at": 0, "line_speed": 5.0}],
        tension=100.0,
    )
    assert abs(res["span2.tension_N"][-1] - res["span1.tension_N"][-1]) < 1e-9 * EA
    path = _idler_line(tmp_path, model, coulomb=0.02)
    _, res = run_line(
        path,
        backend=backend,
        duration=5.0,
        rate=100.0,
        steps=[{"at": 0, "line_speed": 5.0}],
        tension=100.0,
    )
    dT = res["span2.tension_N"][-1] - res["span1.tension_N"][-1]
    assert dT == pytest.approx(0.400, abs=1e-6)  # tau_c / R, downstream higher
    path = _idler_line(tmp_path, model, coulomb=0.02, viscous=1e-4)
    _, res = run_line(
        path,
        backend=backend,
        duration=5.0,
        rate=100.0,
        steps=[{"at": 0, "line_speed": 5.0}],
        tension=100.0,
    )
    dT = res["span2.tension_N"][-1] - res["span1.tension_N"][-1]
    om = res["n1.speed_rad_s"][-1]  # v/R to O(strain): the idler runs at the web speed
    assert om == pytest.approx(100.0, rel=2e-3)
    assert dT == pytest.approx(0.400 + 1e-4 * om / 0.05, abs=1e-6)  # + b·omega/R


# ---------------------------------------------------------------- V6 idler inertia
@pytest.mark.parametrize("model", MODELS)
def test_v6_idler_inertia_under_acceleration(tmp_path, model, backend):
    path = _idler_line(tmp_path, model, J=0.0109)
    _, res = run_line(
        path,
        backend=backend,
        duration=8.0,
        rate=100.0,
        steps=[{"at": 0, "line_speed": 1.0}, {"at": 1.0, "line_speed": 6.0, "rate": 0.5}],
        tension=100.0,
    )
    dT = at(res, "span2.tension_N", 8.0) - at(res, "span1.tension_N", 8.0)
    assert dT == pytest.approx(0.0109 * 0.5 / 0.05**2, rel=0.01)  # 2.18 N
    assert abs(at(res, "span2.tension_N", 0.9) - at(res, "span1.tension_N", 0.9)) < 1e-3


# ---------------------------------------------------------------- V7 idler/span elastic mode
@pytest.mark.parametrize(
    "v,expected",
    [
        (0.0, [223.495j, -223.495j]),
        (5.0, [-3.7502 + 223.4775j, -3.7502 - 223.4775j, -2.4997]),
    ],
)
def test_v7_idler_span_mode(tmp_path, v, expected):
    path = _idler_line(tmp_path, "linear", J=0.01)
    line = r2rsim.load_line(path)
    from r2rsim.schema.scenario import ProgrammeStep

    cl = r2rsim.compile_line(
        line, r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=v)])
    )
    y0 = r2rsim.nominal_state(cl, tension=100.0)
    # the linearisation point is a steady state
    assert np.max(np.abs(cl.rhs(0.0, y0)[[cl.index("span1.strain"), cl.index("n1.speed")]])) < 1e-9
    _, eig = cl.linearise(0.0, y0)
    eig = eig[np.abs(eig) > 1e-6]
    assert len(eig) == len(expected)
    for lam in expected:
        nearest = eig[np.argmin(np.abs(eig - lam))]
        assert abs(nearest - lam) <= 1e-3 * abs(lam), (nearest, lam)
    # closed form (Appendix A.4): omega = R sqrt((EA - T)(1/L1 + 1/L2)/J)
    om = 0.05 * math.sqrt((1e5 - 100.0) * 2.0 / 0.01)
    assert np.max(np.abs(eig.imag)) == pytest.approx(om, rel=2e-3)


# ---------------------------------------------------------------- V9 radius law
@pytest.mark.parametrize("model", MODELS)
def test_v9_radius_law_and_roll_empty(tmp_path, model, backend):
    path = kinematic_line(tmp_path, model=model, EA=1e5, spans=[1.0], draws=[0.0, 0.0])
    text = path.read_text().replace("thickness: 0.0001", "thickness: 5.0e-05")
    write(path, text)  # c_w = thickness = 50 um
    _, res = run_line(
        path,
        backend=backend,
        duration=3200.0,
        rate=1.0,
        steps=[{"at": 0, "line_speed": 5.0}],
        tension=0.0,
        rtol=1e-10,
    )
    assert at(res, "src.radius_m", 600.0) == pytest.approx(0.449726, abs=1e-6)
    assert at(res, "src.radius_m", 600.0) == pytest.approx(
        math.sqrt(0.25 - 50e-6 * 5.0 * 600.0 / math.pi), abs=1e-9
    )
    assert at(res, "src.length", 600.0) == pytest.approx(3000.000, abs=1e-6)
    # the roll empties at R = R_core = 0.045 m: a terminal event at t = 3116.1 s
    assert res.terminated and res.termination_reason == "roll_empty"
    t_empty = math.pi * (0.5**2 - 0.045**2) / (50e-6 * 5.0)
    assert t_empty == pytest.approx(3116.1, abs=0.05)
    assert res.termination_time == pytest.approx(t_empty, abs=1e-3)
    assert res.t[-1] <= res.termination_time


# ---------------------------------------------------------------- V10 inertia and mass
@pytest.mark.parametrize("R,J,m", [(0.5, 136.454, 1082.86), (0.25, 8.5200, 264.08)])
def test_v10_roll_inertia_and_mass(tmp_path, R, J, m, backend):
    text = f"""\
        span_model: exact
        web: {{material: PET, thickness: 50 um, width: 1 m}}
        elements:
          - id: unwind
            type: unwind
            roll: {{core_radius: 0.045, outer_radius: {R}, core_inertia: 0}}
            drive: {{type: ideal_speed}}
          - id: rewind
            type: rewind
            roll: {{core_radius: 0.045, outer_radius: 0.1, core_inertia: 0}}
            drive: {{type: ideal_speed}}
        spans: [{{length: 1 m}}]
        """
    path = write(tmp_path / "roll.yaml", text)
    _, res = run_line(path, backend=backend, duration=0.01, rate=100.0)
    rho, w, Rc = 1390.0, 1.0, 0.045
    assert res["unwind.inertia_kg_m2"][0] == pytest.approx(
        0.5 * math.pi * rho * w * (R**4 - Rc**4), rel=1e-12
    )
    assert res["unwind.web_mass_kg"][0] == pytest.approx(
        math.pi * rho * w * (R**2 - Rc**2), rel=1e-12
    )
    # physics.md quotes J to 6 and m to 5-6 significant digits: half a unit of the last one
    assert res["unwind.inertia_kg_m2"][0] == pytest.approx(J, abs=5e-4 if R == 0.5 else 5e-5)
    assert res["unwind.web_mass_kg"][0] == pytest.approx(m, abs=5e-3)


# ---------------------------------------------------------------- V18 break event time
@pytest.mark.parametrize("model", MODELS)
def test_v18_break_time(tmp_path, model, backend):
    # EA = 1e5 N with A = 1e-4 m^2; break stress 5 MPa -> T_break = 500 N
    path = kinematic_line(
        tmp_path, model=model, EA=1e5, spans=[2.0], draws=[0.0, 0.01], break_stress="5 MPa"
    )
    _, res = run_line(
        path,
        backend=backend,
        duration=3.0,
        rate=1000.0,
        steps=[{"at": 0, "line_speed": 1.0}],
        tension=0.0,
    )
    if model == "linear":
        t_b = 1.392470  # physics.md V18
    else:  # logistic solution of (1.2): t = (L/v1) ln((r - 1)/(r/w_b - 1)), w_b = 1 + Tb/EA
        r, wb = 1.01, 1.005
        t_b = 2.0 / 1.01 * math.log((r - 1) / (r / wb - 1))
    assert res.terminated and res.termination_reason == "web_break"
    assert res.termination_time == pytest.approx(t_b, abs=1e-3)
    breaks = [e for e in res.events if e.kind == "web_break"]
    assert len(breaks) == 1 and breaks[0].component == "span1"
    assert breaks[0].values["tension_N"] == pytest.approx(500.0, abs=0.5)
    assert res.t[-1] < t_b and res.t[-1] > t_b - 2e-3  # data kept up to the break


# ---------------------------------------------------------------- V19 capstan threshold
@pytest.mark.parametrize(
    "mu,beta,ratio", [(0.3, "3.141592653589793", 2.5663), (0.2, "90 deg", 1.3691)]
)
def test_v19_capstan_threshold(tmp_path, mu, beta, ratio, backend):
    EA = 1e5
    node = (
        f"type: driven, radius: 0.1, inertia: 0.1, wrap_angle: {beta}, "
        f"friction_coefficient: {mu}, drive: {{type: ideal_speed}}"
    )
    path = kinematic_line(
        tmp_path,
        model="linear",
        EA=EA,
        spans=[1.0, 1.0],
        draws=[0.0, 0.0, 0.003],
        wound_strain=100.0 / EA,
        middle=[node],
    )
    _, res = run_line(
        path,
        backend=backend,
        duration=3.0,
        rate=1000.0,
        steps=[{"at": 0, "line_speed": 1.0}],
        tension=100.0,
    )
    risk = [e for e in res.events if e.kind == "slip_risk"]
    assert len(risk) == 1 and risk[0].state == "start" and risk[0].component == "n1"
    assert risk[0].values["tension_ratio"] == pytest.approx(ratio, rel=1e-4)
    # closed form of the crossing time: T2(t) = T2inf + (100 - T2inf) e^(-v2 t / L)
    v1, v2 = 1.0, 1.003
    T2inf = (EA * (v2 - v1) + v1 * 100.0) / v2
    t_cross = (
        -1.0
        / v2
        * math.log(
            (math.exp(mu * (math.pi if mu == 0.3 else math.pi / 2)) * 100.0 - T2inf)
            / (100.0 - T2inf)
        )
    )
    assert risk[0].t == pytest.approx(t_cross, abs=1e-3)
    assert not res.terminated


# ---------------------------------------------------------------- V24 speed-trim PI
def test_v24_speed_trim_first_order(tmp_path, backend):
    EA, L, v = 2.25e5, 1.5, 5.0
    wc = 4 * math.pi
    kp = wc * L / EA
    ki = kp / (L / v)
    text = f"""\
        span_model: linear
        web: {{thickness: 1.0e-4, width: 1.0, modulus: {EA / 1e-4!r}, density: 1390,
               breakable: false}}
        elements:
          - {{id: unwind, type: unwind, roll: {{core_radius: 0.076, outer_radius: 0.4,
             core_inertia: 0.5}}, drive: {{type: ideal_speed}}}}
          - {{id: rewind, type: rewind, roll: {{core_radius: 0.076, outer_radius: 0.2,
             core_inertia: 0.5}}, drive: {{type: ideal_speed}}}}
        spans: [{{length: {L}}}]
        sensors:
          - {{id: lc, type: load_cell, element: rewind}}
        controllers:
          - {{id: trim, type: tension_pi, element: rewind, sensor: lc, setpoint: 260 N,
             kp: {kp!r}, ki: {ki!r}}}
        """
    path = write(tmp_path / "v24.yaml", text)
    assert kp == pytest.approx(8.3776e-5, rel=1e-4) and ki == pytest.approx(2.7925e-4, rel=1e-4)
    _, res = run_line(
        path,
        backend=backend,
        duration=3.0 / wc,
        rate=1000.0 * wc,
        steps=[{"at": 0, "line_speed": v}],
        tension=0.0,
    )
    assert at(res, "span1.tension_N", 1 / wc) == pytest.approx(164.31, rel=1e-3)
    assert res["span1.tension_N"][-1] == pytest.approx(247.01, rel=1e-3)
    _, res = run_line(
        path,
        backend=backend,
        duration=1.0,
        rate=1000.0,
        steps=[{"at": 0, "line_speed": v}],
        tension=0.0,
    )
    assert at(res, "span1.tension_N", 1.0) == pytest.approx(260.00, rel=1e-3)
