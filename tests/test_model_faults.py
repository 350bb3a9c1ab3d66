"""Faults that change the line's equations or parameters (actuator, dancer, process): each
against its definition, with a known answer where one exists, and labels that follow
faults.parquet exactly."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
import yaml

import r2rsim
from r2rsim.errors import InputError

from conftest import REPO, write

EA = 225e3  # Line A: 50 um x 1 m PET


def line_file(tmp_path, base="pet_film_line.yaml", edit=None, name="line.yaml"):
    d = yaml.safe_load((REPO / "lines" / base).read_text())
    for s in d["sensors"]:
        s.pop("noise", None)
    if edit:
        edit(d)
    return write(tmp_path / name, yaml.safe_dump(d))


def run(
    tmp_path,
    line,
    faults,
    *,
    duration=12.0,
    rate=100.0,
    name="f",
    programme=None,
    events=None,
    initial=None,
):
    d = {
        "name": name,
        "line": str(line),
        "duration": duration,
        "record_rate": rate,
        "seed": 1,
        "warmup": 1.0,
        "initial": initial or {"state": "steady"},
        "programme": programme or [{"at": 0, "line_speed": 5.0}],
        "faults": faults,
        "events": events or [],
    }
    path = write(tmp_path / f"{name}.yaml", yaml.safe_dump(d))
    out = tmp_path / f"out_{name}"
    r2rsim.run_scenario(path, output=out)
    return (
        pd.read_parquet(out / "samples"),
        pd.read_parquet(out / "faults.parquet"),
        pd.read_parquet(out / "runs.parquet"),
    )


def at(s, t):
    return int(np.searchsorted(s.t_s.to_numpy(), t - 1e-9))


def assert_labels(s, f):
    """label.is_faulty is exactly 'some fault present' from faults.parquet, and a fault
    that changes the process marks no measured channel as corrupted."""
    t = s.t_s.to_numpy()
    present = np.zeros(len(t), bool)
    for row in f.itertuples():
        end = row.end_t_s if row.end_t_s is not None and not math.isnan(row.end_t_s) else np.inf
        present |= (t >= row.onset_t_s) & (t < end)
    assert (s["label.is_faulty"].to_numpy() == present).all()
    assert (s["label.phase"].to_numpy()[present & (t >= 1.0)] == "faulty").all()
    for c in s.columns:
        if c.startswith("label.ch."):
            assert not s[c].any(), c
    assert (f.fault_class != "sensor").all()


def open_loop_unwind(d):
    """The unwind in pure torque mode: feed-forward T_ref·R, no load-cell trim."""
    for c in d["controllers"]:
        if c["id"] == "unwind_tension":
            c["kp"], c["ki"] = 0.0, 0.0


# ---- actuator -----------------------------------------------------------------------------
def test_actuator_bias_shifts_torque_mode_tension_by_b_over_r(tmp_path):
    # torque mode without trim: the unwind brakes with R·T_ref, so a torque bias b makes
    # T = T_ref - b/R (the sign of an unwind's braking torque is negative)
    line = line_file(tmp_path, edit=open_loop_unwind)
    s, f, _ = run(
        tmp_path,
        line,
        [
            {
                "id": "b",
                "type": "actuator.bias",
                "target": "unwind",
                "onset": 3.0,
                "magnitude": "13 N*m",
            }
        ],
    )
    T, R = s["state.span1.tension_N"].to_numpy(), s["state.unwind.radius_m"].to_numpy()
    assert T[at(s, 2.9)] == pytest.approx(260.0, rel=1e-4)
    assert T[-1] == pytest.approx(260.0 - 13.0 / R[-1], rel=1e-4)
    # the delivered torque is the command plus b from the onset on (1 ms drive lag)
    d = (s["act.unwind.torque_N_m"] - s["cmd.unwind.torque_N_m"]).to_numpy()
    assert np.allclose(d[: at(s, 3.0)], 0.0, atol=1e-3)
    assert np.allclose(d[at(s, 3.05) :], 13.0, atol=1e-3)
    row = f.iloc[0]
    assert (row.fault_class, row.magnitude, row.magnitude_unit) == ("actuator", 13.0, "N*m")
    assert_labels(s, f)


def test_actuator_loss_of_effectiveness_step_and_ramp(tmp_path):
    line = line_file(tmp_path)
    s, f, _ = run(
        tmp_path,
        line,
        [
            {
                "id": "e",
                "type": "actuator.loss_of_effectiveness",
                "target": "unwind",
                "onset": 3.0,
                "end": 9.0,
                "profile": {"shape": "ramp", "ramp": 4.0},
                "magnitude": 0.3,
            }
        ],
    )
    ratio = (s["act.unwind.torque_N_m"] / s["cmd.unwind.torque_N_m"]).to_numpy()
    # delivered/commanded = 1 - m·p(t): 1 before, 1 - 0.15 half-way up the ramp, 0.7 at
    # full magnitude, 1 again after the end (the kernel follows the ramp between restarts;
    # the 1 ms drive lag costs about 1e-5)
    assert ratio[at(s, 2.9)] == pytest.approx(1.0, abs=1e-4)
    assert ratio[at(s, 5.0)] == pytest.approx(0.85, abs=1e-4)
    assert ratio[at(s, 8.0)] == pytest.approx(0.70, abs=1e-4)
    assert ratio[at(s, 11.0)] == pytest.approx(1.0, abs=1e-4)
    # the brake weakens, so the tension falls until the load-cell trim catches up
    T = s["state.span1.tension_N"].to_numpy()
    assert T[at(s, 8.0)] < 250.0
    assert_labels(s, f)


def test_actuator_stuck_holds_the_torque_at_onset(tmp_path):
    line = line_file(tmp_path)
    prog = [
        {"at": 0, "line_speed": 5.0},
        {"at": 4.0, "line_speed": 5.0},
        {"at": 5.0, "line_speed": 5.5},
    ]  # a ramp during the fault: the command moves
    s, f, _ = run(
        tmp_path,
        line,
        [{"id": "st", "type": "actuator.stuck", "target": "pull", "onset": 3.0, "end": 7.0}],
        programme=prog,
    )
    clean, _, _ = run(tmp_path, line, [], programme=prog, name="clean")
    a = s["act.pull.torque_N_m"].to_numpy()
    win = slice(at(s, 3.0), at(s, 7.0))
    assert np.ptp(a[win]) == 0.0
    i = at(s, 3.0)  # the value held is the torque at onset (the onset sample is on the grid)
    assert a[i] == pytest.approx(clean["act.pull.torque_N_m"].to_numpy()[i], abs=1e-5)
    assert np.ptp(s["cmd.pull.torque_N_m"].to_numpy()[win]) > 1.0
    # after the end the drive follows its command again (1 ms behind it)
    j = at(s, 11.5)
    assert a[j] == pytest.approx(s["cmd.pull.torque_N_m"].to_numpy()[j], abs=0.05)
    assert_labels(s, f)


def test_actuator_saturation_limits_the_unwind_brake(tmp_path):
    # the unwind brake is limited to 60 N m: T = (60 + tau_f + J·dw/dt)/R from the roll's
    # torque balance, whatever the tension loop asks for
    line = line_file(tmp_path)
    s, f, _ = run(
        tmp_path,
        line,
        [
            {
                "id": "sat",
                "type": "actuator.saturation",
                "target": "unwind",
                "onset": 3.0,
                "magnitude": "60 N*m",
            }
        ],
    )
    a = s["act.unwind.torque_N_m"].to_numpy()
    assert a[at(s, 2.9)] == pytest.approx(-103.5, abs=0.5)  # -R·T + friction
    assert np.all(np.abs(a[at(s, 3.02) :]) <= 60.0 + 1e-4)  # after the 1 ms drive lag
    t = s.t_s.to_numpy()
    w = s["state.unwind.speed_rad_s"].to_numpy()
    J = s["state.unwind.inertia_kg_m2"].to_numpy()
    R = s["state.unwind.radius_m"].to_numpy()
    dw = np.gradient(w, t)
    T_pred = (60.0 + 0.01 * w + J * dw) / R
    T = s["state.span1.tension_N"].to_numpy()
    assert T[-2] == pytest.approx(T_pred[-2], rel=2e-3)
    assert T[-2] == pytest.approx(151.2, abs=0.5)
    assert_labels(s, f)


# ---- dancer -------------------------------------------------------------------------------
def test_dancer_arm_stuck_freezes_the_carriage_and_frees_it_at_end(tmp_path):
    line = line_file(tmp_path, base="pet_film_line_dancer.yaml")
    prog = [
        {"at": 0, "line_speed": 5.0},
        {"at": 4.0, "line_speed": 5.0},
        {"at": 5.0, "line_speed": 6.0},
    ]
    s, f, _ = run(
        tmp_path,
        line,
        [{"id": "as", "type": "dancer.arm_stuck", "target": "dancer", "onset": 3.0, "end": 8.0}],
        programme=prog,
    )
    free, _, _ = run(tmp_path, line, [], programme=prog, name="free")
    q, qf = s["state.dancer.position_m"].to_numpy(), free["state.dancer.position_m"].to_numpy()
    win = slice(at(s, 3.0), at(s, 8.0))
    assert np.ptp(q[win]) == 0.0
    assert (s["state.dancer.stop_state"].to_numpy()[win] == 2.0).all()
    assert np.ptp(qf[win]) > 1e-3  # a free dancer moves with the speed ramp
    assert s["state.dancer.stop_state"].iloc[-1] == 0.0
    assert np.ptp(q[at(s, 8.0) :]) > 1e-5
    assert_labels(s, f)


def test_dancer_loss_of_loading_scales_the_tension(tmp_path):
    # the dancer sets 2T = F_air + m·g (421.9 + 98.1 N); losing half the air force gives
    # T_new/T_old = (0.5·421.9 + 98.1)/520 at the same carriage position
    line = line_file(tmp_path, base="pet_film_line_dancer.yaml")
    s, f, _ = run(
        tmp_path,
        line,
        [
            {
                "id": "ll",
                "type": "dancer.loss_of_loading",
                "target": "dancer",
                "onset": 3.0,
                "magnitude": 0.5,
            }
        ],
        duration=20.0,
    )
    T = s["state.span2.tension_N"].to_numpy()
    assert T[-1] / T[at(s, 2.9)] == pytest.approx((0.5 * 421.9 + 98.1) / 520.0, rel=1e-4)
    assert_labels(s, f)


def test_dancer_friction_increase_scales_the_carriage_friction(tmp_path):
    # at the onset the carriage acceleration changes by -m·c·v/M (viscous damping c)
    from r2rsim.compile import Programme, compile_line
    from r2rsim.compile.faults import realise_faults
    from r2rsim.schema.loader import load_scenario
    from r2rsim.solve.discrete import DiscreteLogic

    line = line_file(tmp_path, base="pet_film_line_dancer.yaml")
    faults = [
        {
            "id": "fi",
            "type": "dancer.friction_increase",
            "target": "dancer",
            "onset": 3.0,
            "magnitude": 4.0,
        }
    ]
    s, f, _ = run(tmp_path, line, faults, duration=6.0)
    assert_labels(s, f)
    sc, ln, _ = load_scenario(tmp_path / "f.yaml")
    cl = compile_line(ln, Programme.from_steps(ln, sc.programme), sc.faults)
    inst = realise_faults(sc, ln, np.random.SeedSequence(1))
    logic = DiscreteLogic(cl, faults=inst, duration=6.0)
    y = np.zeros(cl.n_states)
    iv = cl.index("dancer.velocity")
    y[cl.index("span2.strain")] = y[cl.index("span3.strain")] = 1e-3
    y[iv] = 0.02
    before = cl.rhs(3.0, y)[iv]
    logic.apply_due(3.0, y.copy())
    after = cl.rhs(3.0, y)[iv]
    assert after - before == pytest.approx(-4.0 * 100.0 * 0.02 / 10.0, rel=1e-9)


# ---- process ------------------------------------------------------------------------------
def test_bearing_friction_increase_shows_as_tension_step_across_the_idler(tmp_path):
    # an idler in steady motion: T_out - T_in = tau_f/R = (1 + m)·b·omega/R
    line = line_file(tmp_path)
    s, f, _ = run(
        tmp_path,
        line,
        [
            {
                "id": "bf",
                "type": "process.bearing_friction",
                "target": "idler1",
                "onset": 3.0,
                "magnitude": 3.0,
            }
        ],
        duration=8.0,
    )
    dT = (s["state.span2.tension_N"] - s["state.span1.tension_N"]).to_numpy()
    w = s["state.idler1.speed_rad_s"].to_numpy()
    assert dT[at(s, 2.9)] == pytest.approx(5e-4 * w[at(s, 2.9)] / 0.05, rel=1e-3)
    assert dT[-1] == pytest.approx(4.0 * 5e-4 * w[-1] / 0.05, rel=1e-3)
    assert_labels(s, f)


ECC_LINE = """\
name: eccentric_idler
span_model: linear
web: {thickness: 100 um, width: 1 m, modulus: 1 GPa, density: 1390 kg/m^3,
      break_stress: 50 MPa}
elements:
  - {id: unwind, type: unwind, roll: {core_radius: 76 mm, outer_radius: 0.4 m,
     core_inertia: 0.5}, drive: {type: ideal_speed, draw: -0.001}}
  - {id: idler, type: idler, radius: 0.05, inertia: 1000.0, wrap_angle: 90 deg}
  - {id: rewind, type: rewind, roll: {core_radius: 76 mm, outer_radius: 0.1 m,
     core_inertia: 0.5}, drive: {type: ideal_speed, draw: 0.001}}
spans: [{id: span1, length: 2 m}, {id: span2, length: 1 m}]
"""


def test_eccentric_idler_tension_ripple_matches_linearised_mass_balance(tmp_path):
    # Between kinematic nodes a span whose length varies as dL = a·cos(w t) obeys, linearised,
    # x' = (v/L)(x_in - x) + dL'/L, so with complex amplitudes
    #   x1 = iw·e/L1 / (iw + v/L1),   x2 = ((v/L2)·x1 - iw·e·exp(-i·wrap)/L2) / (iw + v/L2)
    # (span 1 grows by e·cos(theta), span 2 shrinks by e·cos(theta - wrap)); the heavy idler
    # turns at a constant w. Tension ripple amplitude = EA·|x|.
    line = write(tmp_path / "ecc_line.yaml", ECC_LINE)
    e, L1, L2, v, beta, EA_ = 1e-4, 2.0, 1.0, 5.0, math.pi / 2, 1e5
    s, f, _ = run(
        tmp_path,
        line,
        [
            {
                "id": "ec",
                "type": "process.eccentricity",
                "target": "idler",
                "onset": 1.0,
                "magnitude": "0.1 mm",
            }
        ],
        duration=4.0,
        rate=1000.0,
        initial={"state": "steady", "tension": 100.0},
    )
    t = s.t_s.to_numpy()
    w = s["state.idler.speed_rad_s"].to_numpy()[t > 2.5].mean()
    x1 = 1j * w * e / L1 / (1j * w + v / L1)
    x2 = ((v / L2) * x1 - 1j * w * e * np.exp(-1j * beta) / L2) / (1j * w + v / L2)
    m = t > 2.5
    basis = np.c_[np.ones(m.sum()), np.cos(w * t[m]), np.sin(w * t[m])]
    for k, x in ((1, x1), (2, x2)):
        T = s[f"state.span{k}.tension_N"].to_numpy()
        c, *_ = np.linalg.lstsq(basis, T[m], rcond=None)
        assert np.hypot(c[1], c[2]) == pytest.approx(EA_ * abs(x), rel=5e-3), k
        assert np.std(T[m] - basis @ c) < 1e-3 * EA_ * abs(x)  # a pure sinusoid at w
        assert np.ptp(T[t < 1.0]) < 1e-3  # nothing before the onset
    assert_labels(s, f)


def test_modulus_change_travels_with_the_web(tmp_path):
    # new material (EA·1.5) leaves the unwind at the onset; in a span it has filled, the
    # strain is T/(1.5·EA); the front reaches span 5 only after 5.6 m of web (1.12 s)
    line = line_file(tmp_path)
    s, f, _ = run(
        tmp_path,
        line,
        [
            {
                "id": "mc",
                "type": "process.modulus_change",
                "target": "unwind",
                "onset": 3.0,
                "magnitude": 0.5,
            }
        ],
    )
    for k in range(1, 6):
        T = s[f"state.span{k}.tension_N"].to_numpy()
        eps = s[f"state.span{k}.geometric_strain"].to_numpy()
        assert eps[at(s, 2.9)] * EA == pytest.approx(T[at(s, 2.9)], rel=1e-5)
        assert eps[-1] * 1.5 * EA == pytest.approx(T[-1], rel=1e-5)
    i = at(s, 3.5)
    T5 = s["state.span5.tension_N"].to_numpy()[i]
    assert s["state.span5.geometric_strain"].to_numpy()[i] * EA == pytest.approx(T5, rel=1e-5)
    assert f.iloc[0].magnitude_unit == "rel"
    assert_labels(s, f)


def test_draw_error_on_the_pull_roll(tmp_path):
    # the pull roll's effective radius is 0.1 % larger: its surface runs 0.1 % fast while
    # its drive (and encoder) keep omega = V/R; the span before it settles where mass flow
    # balances: 1 + eps4 = (1 + eps3)·(1 + delta)
    line = line_file(tmp_path)
    s, f, _ = run(
        tmp_path,
        line,
        [
            {
                "id": "de",
                "type": "process.draw_error",
                "target": "pull",
                "onset": 3.0,
                "magnitude": 0.001,
            }
        ],
        duration=30.0,
    )
    T3, T4 = s["state.span3.tension_N"].iloc[-1], s["state.span4.tension_N"].iloc[-1]
    assert T4 == pytest.approx(EA * ((1.0 + T3 / EA) * 1.001 - 1.0), rel=1e-3)
    assert T4 == pytest.approx(485.8, abs=0.5)
    assert s["state.pull.speed_rad_s"].iloc[-1] == pytest.approx(50.0, rel=1e-5)
    assert s["state.pull.surface_speed_m_s"].iloc[-1] == pytest.approx(5.005, rel=1e-5)
    assert_labels(s, f)


def _splicing_line(d):
    u = d["elements"][0]
    u["spare_roll"] = dict(u["roll"])
    u["splicer"] = {"type": "flying"}


@pytest.mark.parametrize("strength, breaks", [(200.0, True), (5000.0, False)])
def test_weak_splice_breaks_at_the_joint(tmp_path, strength, breaks):
    line = line_file(tmp_path, base="pet_film_line_dancer.yaml", edit=_splicing_line)
    s, f, runs = run(
        tmp_path,
        line,
        [
            {
                "id": "ws",
                "type": "process.weak_splice",
                "target": "unwind",
                "onset": 2.0,
                "magnitude": f"{strength} N",
            }
        ],
        events=[{"at": 4.0, "type": "splice"}],
        duration=8.0,
    )
    r = runs.iloc[0]
    if breaks:  # made under 260 N, the 200 N joint fails at the splice
        assert r.termination_reason == "web_break"
        assert r.terminated and r.termination_t_s == pytest.approx(4.0)
        assert s["label.phase"].iloc[-1] == "terminated"
    else:
        assert not r.terminated
        assert s.t_s.iloc[-1] == pytest.approx(8.0)
    t = s.t_s.to_numpy()
    assert (s["label.is_faulty"].to_numpy() == (t >= 2.0)).all()


# ---- validation ---------------------------------------------------------------------------
@pytest.mark.parametrize(
    "fault, message",
    [
        ({"type": "actuator.bias", "target": "idler1", "magnitude": 1.0}, "torque drive"),
        ({"type": "actuator.loss_of_effectiveness", "target": "pull", "magnitude": 1.5}, "(0, 1]"),
        (
            {"type": "actuator.stuck", "target": "pull", "profile": {"shape": "ramp", "ramp": 1}},
            "step or intermittent",
        ),
        (
            {"type": "process.bearing_friction", "target": "nope", "magnitude": 1.0},
            "no element 'nope'",
        ),
        (
            {"type": "process.eccentricity", "target": "idler1", "magnitude": "60 mm"},
            "not less than the roller radius",
        ),
        ({"type": "process.eccentricity", "target": "unwind", "magnitude": "1 mm"}, "roll"),
        (
            {"type": "process.modulus_change", "target": "unwind", "magnitude": 0.2, "end": 5.0},
            "leave out 'end'",
        ),
        ({"type": "process.weak_splice", "target": "unwind", "magnitude": "100 N"}, "splicer"),
        (
            {"type": "process.weak_splice", "target": "unwind", "magnitude": "100 N", "splicer": 1},
            "no splice on 'unwind' at or after the onset",
        ),
        (
            {"type": "process.draw_error", "target": "idler1", "magnitude": 0.001},
            "driven roller or nip",
        ),
        ({"type": "dancer.arm_stuck", "target": "pull"}, "dancer or festoon"),
        ({"type": "actuator.bias", "target": "pull", "magnitude": "1 N"}, "dimension"),
    ],
)
def test_bad_model_faults_are_rejected(tmp_path, fault, message):
    fault = dict(fault)
    line = line_file(tmp_path, edit=_splicing_line if fault.pop("splicer", 0) else None)
    sc = {
        "name": "bad",
        "line": str(line),
        "duration": 5.0,
        "programme": [{"at": 0, "line_speed": 5.0}],
        "faults": [{"id": "x", "onset": 1.0, **fault}],
    }
    path = write(tmp_path / "bad.yaml", yaml.safe_dump(sc))
    with pytest.raises(InputError) as exc:
        r2rsim.run_scenario(path, output=tmp_path / "out_bad")
    assert message in str(exc.value)
    assert "faults[0]" in str(exc.value)
    assert not (tmp_path / "out_bad").exists()


def test_model_fault_overlaps(tmp_path):
    line = line_file(tmp_path)

    def scenario(faults):
        sc = {
            "name": "ov",
            "line": str(line),
            "duration": 6.0,
            "programme": [{"at": 0, "line_speed": 5.0}],
            "faults": faults,
        }
        return write(tmp_path / "ov.yaml", yaml.safe_dump(sc))

    bias = {
        "id": "b",
        "type": "actuator.bias",
        "target": "pull",
        "onset": 2.0,
        "magnitude": 1.0,
        "compose": "superpose",
    }
    draw = {
        "id": "d",
        "type": "process.draw_error",
        "target": "pull",
        "onset": 3.0,
        "magnitude": 0.001,
        "compose": "superpose",
    }
    stuck = {
        "id": "s",
        "type": "actuator.stuck",
        "target": "pull",
        "onset": 3.0,
        "compose": "superpose",
    }
    # two mechanisms on one roller compose when both say so
    r2rsim.run_scenario(scenario([bias, draw]), output=tmp_path / "ok")
    with pytest.raises(InputError, match="cannot be superposed"):
        r2rsim.run_scenario(scenario([bias, stuck]), output=tmp_path / "no")
    with pytest.raises(InputError, match="declare compose"):
        r2rsim.run_scenario(scenario([{**bias, "compose": None}, draw]), output=tmp_path / "no")


def test_shipped_fault_scenario(tmp_path):
    """scenarios/line_a_faults.yaml (shortened): every fault row labels its window, and the
    draw error shows in span 4 at the size mass balance gives."""
    out = tmp_path / "out"
    r2rsim.run_scenario(REPO / "scenarios" / "line_a_faults.yaml", output=out, duration=30.0)
    s = pd.read_parquet(out / "samples")
    f = pd.read_parquet(out / "faults.parquet")
    assert set(f.fault_type) == {
        "process.draw_error",
        "process.bearing_friction",
        "actuator.loss_of_effectiveness",
    }
    assert_labels(s, f)
    runs = pd.read_parquet(out / "runs.parquet")
    assert len(yaml.safe_load(runs.disturbances_json.iloc[0])) == 3
    # 0.1 % draw on the pull roll at full magnitude (15-25 s): span 4 about EA·0.001 higher
    T4 = s["state.span4.tension_N"].to_numpy()
    rise = T4[at(s, 24.0)] - T4[at(s, 9.0)]
    assert rise == pytest.approx(EA * 0.001 * (1 + 260 / EA), rel=0.05)
