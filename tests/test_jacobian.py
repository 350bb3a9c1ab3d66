"""The analytic Jacobian of every element, drive, controller and sensor against central finite
differences, at states that exercise every branch (taut and slack spans, forward and reverse
web motion, saturated and unsaturated controllers). Also: no finite-difference entry lies
outside the compiled pattern, and the band is what the web ordering promises."""

from __future__ import annotations

import numpy as np
import pytest

import r2rsim
from r2rsim.schema.scenario import ProgrammeStep

from conftest import REPO, write

FULL = """\
span_model: {model}
web: {{material: PET, thickness: 50 um, width: 1 m}}
elements:
  - id: unwind
    type: unwind
    roll: {{core_radius: 0.076, outer_radius: 0.4, core_inertia: 0.5, wound_in_strain: 1e-4}}
    friction: {{viscous: 0.01, coulomb: 0.2}}
    drive: {{torque_lag: 1 ms, torque_max: 150}}
  - {{id: idler1, type: idler, radius: 0.05, inertia: 0.011, friction: {{viscous: 5e-4,
     coulomb: 0.02}}, wrap_angle: 90 deg, friction_coefficient: 0.3}}
  - id: nip
    type: nip
    radius: 0.1
    inertia: 0.15
    friction: {{viscous: 0.01}}
    drive: {{torque_lag: 0}}
    pressure_roller: {{radius: 0.08, inertia: 0.03, friction: {{viscous: 0.002, coulomb: 0.1}}}}
  - {{id: pull, type: driven, radius: 0.1, inertia: 0.2, drive: {{torque_lag: 2 ms}}}}
  - {{id: trim_roll, type: driven, radius: 0.1, inertia: 0.2, drive: {{type: ideal_speed,
     draw: 0.001}}}}
  - id: rewind
    type: rewind
    roll: {{core_radius: 0.076, outer_radius: 0.1, core_inertia: 0.5}}
    drive: {{torque_lag: 1 ms}}
spans: [{{length: 1.5}}, {{length: 1.0}}, {{length: 0.1}}, {{length: 3.0}}, {{length: 1.5}}]
sensors:
  - {{id: lc1, type: load_cell, element: idler1, filter: 2 ms, gain: 1.05, offset: 3}}
  - {{id: lc2, type: load_cell, element: pull, axis_angle: 10 deg}}
  - {{id: lc3, type: load_cell, element: rewind, filter: 5 ms}}
  - {{id: enc, type: encoder, element: pull, filter: 1 ms}}
  - {{id: enc_ideal, type: encoder, element: trim_roll, filter: 1 ms}}
  - {{id: dia, type: roll_diameter, element: unwind, filter: 20 ms}}
controllers:
  - {{id: c_pull, type: speed_pi, element: pull, master: true, kp: 25, ki: 790, encoder: enc}}
  - {{id: c_nip, type: speed_pi, element: nip, kp: 18, ki: 590, draw: 0.0005,
     torque_feedforward: false}}
  - {{id: c_unw, type: tension_pi, element: unwind, sensor: lc1, setpoint: 260, kp: 0.1,
     ki: 0.5, output_limit: {limit}, radius_sensor: dia}}
  - {{id: c_nip_t, type: tension_pi, element: nip, sensor: lc2, setpoint: 250, kp: 1e-4,
     ki: 3e-4}}
  - {{id: c_trim, type: tension_pi, element: trim_roll, sensor: lc3, setpoint: 240, kp: 1e-4,
     ki: 3e-4, output_limit: 0.5}}
  - {{id: c_rew, type: tension_pi, element: rewind, sensor: lc3, setpoint: 240, kp: 0.1,
     ki: 0.5, feedforward: false}}
"""


def _state(cl, rng, *, slack=(), reverse=False):
    y = np.zeros(cl.n_states)
    typical = {
        "strain": 1.1e-3,
        "speed": 50.0,
        "roll_length": 200.0,
        "material": 199.0,
        "torque": 20.0,
        "controller": 3.0,
        "sensor_filter": 250.0,
    }
    for i, (name, kind) in enumerate(zip(cl.state_names, cl.state_kinds, strict=True)):
        y[i] = typical[kind] * (1 + 0.2 * rng.standard_normal())
        if name == "dia.filtered":
            y[i] = 0.75
        if name in ("enc.filtered", "enc_ideal.filtered"):
            y[i] = 48.0
    for sp in slack:
        y[cl.index(f"{sp}.strain")] = -2e-4
    if reverse:
        for i, kind in enumerate(cl.state_kinds):
            if kind == "speed":
                y[i] = -abs(y[i])
    return y


def _fd(cl, t, y):
    n = cl.n_states
    J = np.zeros((n, n))
    for j in range(n):
        h = 1e-6 * max(1.0, abs(y[j])) if cl.state_kinds[j] != "strain" else 1e-10
        yp, ym = y.copy(), y.copy()
        yp[j] += h
        ym[j] -= h
        J[:, j] = (cl.rhs(t, yp) - cl.rhs(t, ym)) / (2 * h)
    return J


def _assert_jacobian_matches_fd(cl, t, y, floor):
    """Analytic Jacobian = central differences (relative 1e-4, entries below ``floor`` of
    the row's largest ignored), and no finite-difference entry outside the pattern."""
    J = cl.jacobian(t, y)
    Jfd = _fd(cl, t, y)
    scale = np.abs(Jfd).max(axis=1, keepdims=True) + 1e-300
    err = np.abs(J - Jfd) / (np.abs(Jfd) + floor * scale + 1e-12)
    bad = np.argwhere(err > 1e-4)
    detail = [(cl.state_names[i], cl.state_names[j], J[i, j], Jfd[i, j]) for i, j in bad[:5]]
    assert not len(bad), detail
    mask = np.zeros_like(J, dtype=bool)
    mask[cl.pattern] = True
    assert np.all(Jfd[~mask] == 0.0), "finite differences found entries outside the pattern"


@pytest.mark.parametrize("model", ["exact", "linear"])
@pytest.mark.parametrize("case", ["taut", "slack", "reverse", "saturated"])
def test_every_element_jacobian_against_finite_differences(tmp_path, model, case):
    limit = 1e-3 if case == "saturated" else 200
    path = write(tmp_path / "full.yaml", FULL.format(model=model, limit=limit))
    line = r2rsim.load_line(path)
    prog = r2rsim.Programme.from_steps(
        line, [ProgrammeStep(at=0, line_speed=2.0), ProgrammeStep(at=0.5, line_speed=5.0, ramp=4.0)]
    )
    cl = r2rsim.compile_line(line, prog)
    cl.set_segment_start(0.5)
    rng = np.random.default_rng(3)
    y = _state(
        cl, rng, slack=("span2", "span4") if case == "slack" else (), reverse=case == "reverse"
    )
    _assert_jacobian_matches_fd(cl, 1.7, y, floor=1e-7)


def test_band_of_line_a(repo):
    cl = r2rsim.compile_line(r2rsim.load_line(REPO / "lines" / "pet_film_line.yaml"))
    # the unwind's tension loop reads the load cell on the next idler: the widest coupling
    assert (cl.lband, cl.uband) == (6, 4)
    rows, cols = cl.pattern
    assert np.all(np.abs(rows - cols) <= 6)


def test_chain_band_does_not_grow_with_length(tmp_path):
    def chain(n):
        idlers = "\n".join(
            f"  - {{id: i{k}, type: idler, radius: 0.05, inertia: 0.001}}" for k in range(n)
        )
        text = (
            "web: {material: PET, thickness: 50 um, width: 1 m}\nelements:\n"
            "  - {id: u, type: unwind, roll: {core_radius: 0.07, outer_radius: 0.3, "
            "core_inertia: 0.5}}\n"
            + idlers
            + "\n  - {id: r, type: rewind, roll: {core_radius: 0.07, outer_radius: 0.1, "
            "core_inertia: 0.5}}\nspans:\n"
            + "\n".join("  - {length: 1}" for _ in range(n + 1))
            + "\n"
        )
        cl = r2rsim.compile_line(r2rsim.load_line(write(tmp_path / f"c{n}.yaml", text)))
        return cl.lband, cl.uband

    assert chain(5) == chain(50)


MOVERS = """\
span_model: {model}
web: {{material: PET, thickness: 50 um, width: 1 m}}
elements:
  - id: unwind
    type: unwind
    roll: {{core_radius: 0.076, outer_radius: 0.4, core_inertia: 0.5,
           wound_in_strain: [1e-4, 2e-3, -1e-3]}}
    drive: {{torque_lag: 1 ms}}
  - {{id: i1, type: idler, radius: 0.05, inertia: 0.011, position: [0, 0], wrap: cw}}
  - id: d1
    type: dancer
    radius: 0.06
    inertia: 0.02
    position: [0.2, -0.8]
    wrap: ccw
    direction: [0.3, -1]
    travel_range: [-0.2, 0.2]
    mass: 10
    load_force: 400
    spring_stiffness: 200
    damping: 30
    coulomb: 5
  - {{id: i2, type: idler, radius: 0.05, inertia: 0.011, position: [0.5, 0.1], wrap: cw}}
  - id: d2
    type: pivot_dancer
    radius: 0.04
    inertia: 0.002
    wrap: ccw
    pivot: [1.0, 0.4]
    arm_length: 0.3
    arm_angle: -100 deg
    angle_range: [-150 deg, -30 deg]
    arm_inertia: 0.4
    roller_mass: 2
    arm_mass: 3
    cylinder: {{force: 900, fixed_point: [1.4, 0.5], arm_point: 0.2}}
    torsion_spring: {{stiffness: 20, free_angle: -90 deg}}
    damping: 0.5
    coulomb: 0.3
  - {{id: pull, type: driven, radius: 0.1, inertia: 0.2, position: [1.3, 0.0], wrap: cw}}
  - {{id: exit, type: driven, radius: 0.1, inertia: 0.2}}
  - id: rewind
    type: rewind
    roll: {{core_radius: 0.076, outer_radius: 0.1, core_inertia: 0.5}}
spans:
  - {{length: 1.5}}
  - {{}}
  - {{}}
  - {{}}
  - {{}}
  - id: fest
    length: 2.0
    festoon: {{moving_rollers: 3, carriage_mass: 40, stroke: [0, 3], initial_position: 1.2,
              force: 1600, gravity: -9.81, damping: 50, coulomb: 10}}
  - {{length: 1.0}}
sensors:
  - {{id: lc1, type: load_cell, element: i1, filter: 2 ms}}
  - {{id: pos1, type: dancer_position, element: d1, filter: 5 ms, gain: 1.02, offset: 0.001}}
  - {{id: posf, type: dancer_position, element: fest}}
controllers:
  - {{id: c_pull, type: speed_pi, element: pull, master: true, kp: 25, ki: 790}}
  - {{id: c_exit, type: speed_pi, element: exit, kp: 25, ki: 790}}
  - {{id: c_unw, type: speed_pi, element: unwind, kp: 25, ki: 790}}
  - {{id: c_rew, type: tension_pi, element: rewind, sensor: lc1, setpoint: 240, kp: 0.1,
     ki: 0.5}}
  - {{id: loop1, type: dancer_pi, dancer: d1, element: unwind, sensor: pos1, kp: 4, ki: 1,
     output_limit: {limit}}}
  - {{id: loop2, type: dancer_pi, dancer: d2, element: pull, kp: 2, ki: 0.5}}
  - {{id: loop3, type: dancer_pi, dancer: fest, element: exit, kp: 1, ki: 0, setpoint: 1.0}}
"""


@pytest.mark.parametrize("model", ["exact", "linear"])
@pytest.mark.parametrize("case", ["moving", "latched", "saturated"])
def test_dancer_festoon_and_loop_jacobian_against_finite_differences(tmp_path, model, case):
    limit = 1e-4 if case == "saturated" else 0.5
    line = r2rsim.load_line(
        write(tmp_path / "movers.yaml", MOVERS.format(model=model, limit=limit))
    )
    prog = r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=3.0)])
    cl = r2rsim.compile_line(line, prog)
    y = r2rsim.nominal_state(cl, 250.0)
    rng = np.random.default_rng(5)
    for i, kind in enumerate(cl.state_kinds):
        if kind in ("strain", "speed", "torque", "controller", "sensor_filter"):
            y[i] *= 1 + 0.05 * rng.standard_normal()
        if kind == "mover":
            y[i] += 0.02 * rng.standard_normal()
    if case == "latched":
        from r2rsim.compile.layout import N_MOVER_P, H, MoverP

        cl.P[cl.I[H.OFF_MP] + 0 * N_MOVER_P + MoverP.MODE] = -1.0
        cl.P[cl.I[H.OFF_MP] + 2 * N_MOVER_P + MoverP.MODE] = 2.0
    _assert_jacobian_matches_fd(cl, 0.3, y, floor=1e-6)


CONTROLS = """\
span_model: {model}
web: {{material: PET, thickness: 50 um, width: 1 m}}
elements:
  - id: unwind
    type: unwind
    roll: {{core_radius: 0.076, outer_radius: 0.4, core_inertia: 0.5}}
    friction: {{viscous: 0.01, coulomb: 0.2}}
    drive: {{torque_lag: 1 ms}}
  - {{id: helper, type: driven, radius: 0.05, inertia: 0.011, friction: {{viscous: 5e-4,
     coulomb: 0.02}}, drive: {{torque_lag: 2 ms, torque_max: 0.5, torque_command: 0.05}}}}
  - {{id: s1, type: driven, radius: 0.1, inertia: 0.15, drive: {{torque_lag: 1 ms}}}}
  - {{id: pull, type: driven, radius: 0.1, inertia: 0.2, drive: {{torque_lag: 0}}}}
  - {{id: trim_roll, type: driven, radius: 0.1, inertia: 0.2, drive: {{type: ideal_speed,
     draw: 0.001}}}}
  - id: rewind
    type: rewind
    roll: {{core_radius: 0.076, outer_radius: 0.1, core_inertia: 0.5}}
    friction: {{viscous: 0.01}}
    drive: {{torque_lag: 1 ms}}
spans: [{{length: 1.5}}, {{length: 1.0}}, {{length: 0.1}}, {{length: 3.0}}, {{length: 1.5}}]
sensors:
  - {{id: lc1, type: load_cell, element: helper, filter: 2 ms}}
  - {{id: lc2, type: load_cell, element: rewind, filter: 5 ms}}
  - {{id: enc, type: encoder, element: s1, filter: 1 ms}}
  - {{id: dia, type: roll_diameter, element: unwind, filter: 20 ms}}
controllers:
  - {{id: c_pull, type: speed_pi, element: pull, master: true, kp: 25, ki: 790}}
  - {{id: c_s1, type: speed_pi, element: s1, kp: 18, ki: 590, draw: 0.0005, encoder: enc}}
  - {{id: c_unw, type: tension_pi, element: unwind, sensor: lc1, setpoint: 260, kp: 0.1,
     ki: 0.5, radius_sensor: dia, output_limit: {limit},
     feedforward: {{inertia: {{factor: 0.9}}, radius_rate: false}}}}
  - {{id: c_trim, type: tension_pi, element: trim_roll, sensor: lc2, setpoint: 240, kp: 1e-4,
     ki: 3e-4, output_limit: 0.5}}
  - {{id: c_rew, type: tension_pi, element: rewind, sensor: lc2, setpoint: 240, kp: 0.1,
     ki: 0.5, feedforward: {{tension: false, inertia: {{value: 2 kg*m^2}}, friction: false}}}}
"""


@pytest.mark.parametrize("model", ["exact", "linear"])
@pytest.mark.parametrize("case", ["taut", "slack", "reverse", "saturated"])
def test_feedforward_torque_command_and_draw_jacobian(tmp_path, model, case):
    """Feed-forward terms switched one by one, an inertia estimate by factor and by value, an
    open-loop torque command (saturated in the 'saturated' case), and programmed draws (on a
    speed PI and an ideal-speed node) evaluated inside their ramps."""
    limit = 1e-3 if case == "saturated" else 200
    text = CONTROLS.format(model=model, limit=limit)
    if case == "saturated":
        text = text.replace("torque_max: 0.5", "torque_max: 0.01")
    line = r2rsim.load_line(write(tmp_path / "controls.yaml", text))
    prog = r2rsim.Programme.from_steps(
        line,
        [
            ProgrammeStep(at=0, line_speed=2.0),
            ProgrammeStep(at=0.5, line_speed=5.0, ramp=4.0),
            ProgrammeStep(
                at=0.5, draw={"s1": 0.002, "trim_roll": -0.001}, torque={"helper": 0.2}, ramp=2.0
            ),
        ],
    )
    assert prog.names == [
        "line_speed",
        "c_unw",
        "c_trim",
        "c_rew",
        "torque:helper",
        "draw:s1",
        "draw:trim_roll",
    ]
    cl = r2rsim.compile_line(line, prog)
    cl.set_segment_start(0.5)
    rng = np.random.default_rng(7)
    y = _state(
        cl, rng, slack=("span2", "span4") if case == "slack" else (), reverse=case == "reverse"
    )
    y[cl.index("enc.filtered")] = 48.0
    _assert_jacobian_matches_fd(cl, 1.7, y, floor=1e-7)
