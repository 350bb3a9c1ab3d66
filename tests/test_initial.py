"""Initial states: the steady state found from a poor guess, and a run that says so when
none is found."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest

import r2rsim
from r2rsim.cli import main
from r2rsim.solve.initial import (
    _mover_tensions,
    condition_1,
    lu_factor,
    lu_solve,
    norm2,
    taut_guess,
)

from conftest import write

# one scenario per shipped line with tension loops, dancers or a festoon
SCENARIOS = [
    "quickstart.yaml",
    "line_a_faults.yaml",
    "newsprint_splice.yaml",
    "thesis_normal_cycles.yaml",
    "thesis/oc1_nominal.yaml",
    "torque_modes.yaml",
]


@pytest.mark.parametrize("name", SCENARIOS)
def test_steady_state_from_spans_at_zero_tension(repo, name):
    # a nominal state at 0 N puts every span exactly on the slack boundary, where the span
    # stiffness has its kink and the Newton matrix is singular: steady_state failed there
    # on every shipped line and `r2rsim run` quietly started from the nominal state
    scen, line, _ = r2rsim.load_scenario(repo / "scenarios" / name)
    cl = r2rsim.compile_line(line, r2rsim.Programme.from_steps(line, scen.programme))
    good = r2rsim.steady_state(
        cl, r2rsim.nominal_state(cl, scen.initial.tension, scen.initial.span_tension)
    )
    assert good is not None
    zero = r2rsim.nominal_state(cl, 0.0)
    assert taut_guess(cl, zero) is not None
    found = r2rsim.steady_state(cl, zero)
    assert found is not None
    # the same steady state: every span's tension, and dy/dt = 0
    for out in (good, found):
        f = cl.rhs(0.0, out)
        free = [k not in ("roll_length", "material", "angle") for k in cl.state_kinds]
        assert np.max(np.abs(f[free]) / (np.abs(out[free]) + 1e3 * cl.atol[free])) < 1e-6
    Tg = cl.outputs(0.0, good[None, :])[0]
    Tf = cl.outputs(0.0, found[None, :])[0]
    for sid in cl.span_ids:
        i = cl.aux_index(f"{sid}.tension_N")
        assert Tf[i] == pytest.approx(Tg[i], rel=1e-6, abs=1e-6), sid
        assert Tg[i] > 0.0


def test_taut_guess_leaves_a_taut_state_alone(repo):
    scen, line, _ = r2rsim.load_scenario(repo / "scenarios" / "quickstart.yaml")
    cl = r2rsim.compile_line(line, r2rsim.Programme.from_steps(line, scen.programme))
    y = r2rsim.nominal_state(cl)
    assert taut_guess(cl, y) is None
    # one span at 0 N takes the median tension set-point at t = 0 (260 N on every loop)
    y[cl.index("span2.strain")] = 0.0
    taut = taut_guess(cl, y)
    assert taut[cl.index("span2.strain")] * line.web.EA == pytest.approx(260.0, rel=1e-12)
    assert np.array_equal(
        np.delete(taut, cl.index("span2.strain")), np.delete(y, cl.index("span2.strain"))
    )


def test_run_says_when_no_steady_state_is_found(tmp_path, repo, capsys):
    # a line at rest between kinematic nodes: the span strain is not determined
    scen = write(
        tmp_path / "rest.yaml",
        f"""\
        name: rest
        line: {repo / "lines" / "single_span.yaml"}
        duration: 0.5 s
        record_rate: 100 Hz
        initial: {{state: steady}}
        programme:
          - {{at: 0 s, line_speed: 0 m/s}}
        """,
    )
    assert main(["run", str(scen), "-o", str(tmp_path / "out"), "-q"]) == 0
    cap = capsys.readouterr()
    assert cap.err.count("warning:") == 1
    assert str(scen) in cap.err and "initial.state" in cap.err
    assert "no steady state" in cap.err
    assert "WARNING" in cap.out and "no steady state" in cap.out
    runs = pq.read_table(tmp_path / "out" / "runs.parquet").to_pylist()[0]
    assert runs["initial_state"].startswith("nominal (no steady state")
    # a steady state found: no warning
    assert (
        main(
            [
                "run",
                str(repo / "scenarios" / "quickstart.yaml"),
                "-o",
                str(tmp_path / "qs"),
                "-q",
                "--duration",
                "0.5",
            ]
        )
        == 0
    )
    cap = capsys.readouterr()
    assert "warning" not in cap.err.lower() and "WARNING" not in cap.out


STARTUP = "scenarios/thesis_realistic/testbed_startup.yaml"


def _startup_variant(tmp_path, repo, initial: str, name="s.yaml"):
    """The test-bed start-up scenario with another ``initial`` block (flow style)."""
    text = (repo / STARTUP).read_text()
    head, rest = text.split("initial:\n", 1)
    rest = rest.split("programme:\n", 1)[1]
    text = (
        head.replace("../../lines/", str(repo / "lines") + "/")
        + f"initial: {initial}\nprogramme:\n"
        + rest
    )
    return write(tmp_path / name, text)


def test_slack_start_closed_form(repo):
    """initial.slack: a span's strain starts at -slack/L (0 N); initial.position puts the
    dancer there, at rest; spans without slack keep the nominal tension."""
    scen, line, _ = r2rsim.load_scenario(repo / STARTUP)
    cl = r2rsim.compile_line(line, r2rsim.Programme.from_steps(line, scen.programme))
    init = scen.initial
    assert init.position["dancer"] == pytest.approx(np.radians(-44.0), rel=1e-12)
    y = r2rsim.nominal_state(cl, init.tension, init.span_tension, init.slack, init.position)
    aux = cl.outputs(0.0, y[None, :])[0]
    for sid, extra in init.slack.items():
        length = aux[cl.aux_index(f"{sid}.length_m")]
        assert y[cl.index(f"{sid}.strain")] == pytest.approx(-extra / length, rel=1e-12)
        assert aux[cl.aux_index(f"{sid}.tension_N")] == 0.0
    assert y[cl.index("dancer.position")] == init.position["dancer"]
    assert y[cl.index("dancer.velocity")] == 0.0
    assert y[cl.index("span8.strain")] == 0.0  # not slack: at the nominal 0 N


@pytest.mark.parametrize(
    "initial, path, words",
    [
        ("{state: steady, slack: {span1: 5 cm}}", "initial", "state: nominal"),
        ("{state: nominal, slack: {nope: 5 cm}}", "initial.slack.nope", "no span 'nope'"),
        ("{state: nominal, slack: {span1: -5 cm}}", "initial.slack.span1", "must be > 0"),
        ("{state: nominal, slack: {span1: 5 N}}", "initial.slack.span1", "length"),
        ("{state: nominal, slack: {span1: 0.6 m}}", "initial.slack.span1", "half the span"),
        ("{state: nominal, position: {s2a: 0.1}}", "initial.position.s2a", "no dancer or festoon"),
        (
            "{state: nominal, position: {dancer: -45 deg}}",
            "initial.position.dancer",
            "strictly inside",
        ),
        ("{state: nominal, position: {dancer: 5 cm}}", "initial.position.dancer", "angle"),
        ("{state: nominal, position: {dancer: .nan}}", "initial.position.dancer", "finite"),
    ],
)
def test_bad_slack_or_position(tmp_path, repo, capsys, initial, path, words):
    scen = _startup_variant(tmp_path, repo, initial)
    out = tmp_path / "out"
    assert main(["run", str(scen), "-o", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("error") == 1, err
    assert str(scen) in err and path in err and words in err, err
    assert not out.exists()


@pytest.mark.parametrize(
    "line, mover, value, si, bad",
    [
        ("newsprint_line.yaml", "festoon", "2.5 m", 2.5, "4 m"),  # festoon stroke [0, 4] m
        ("pet_film_line_dancer.yaml", "dancer", "-5 cm", -0.05, "0.15 m"),  # travel ±0.15 m
    ],
)
def test_position_of_a_festoon_and_a_linear_dancer(
    tmp_path, repo, capsys, line, mover, value, si, bad
):
    def scenario(pos):
        return write(
            tmp_path / "p.yaml",
            f"""\
            name: p
            line: {repo / "lines" / line}
            duration: 0.1 s
            record_rate: 100 Hz
            initial: {{state: nominal, position: {{{mover}: {pos}}}}}
            programme:
              - {{at: 0 s, line_speed: 1 m/s}}
            """,
        )

    scen, ln, _ = r2rsim.load_scenario(scenario(value))
    assert scen.initial.position[mover] == pytest.approx(si, rel=1e-12)
    cl = r2rsim.compile_line(ln, r2rsim.Programme.from_steps(ln, scen.programme))
    y = r2rsim.nominal_state(cl, position=scen.initial.position)
    assert y[cl.index(f"{mover}.position")] == pytest.approx(si, rel=1e-12)
    assert main(["run", str(scenario(bad)), "-o", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert f"initial.position.{mover}" in err and "strictly inside" in err
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("n", [1, 2, 7, 60])
def test_the_steady_states_linear_algebra_against_lapack(n):
    # the steady-state Newton solves without LAPACK/BLAS (their kernels round differently
    # on different CPUs, issue 37): the same answers as numpy's LAPACK to rounding
    rng = np.random.default_rng(n)
    a = rng.normal(size=(n, n)) + n * np.eye(n) * (n > 2)
    b = rng.normal(size=n)
    factors = lu_factor(a)
    np.testing.assert_allclose(lu_solve(factors, b), np.linalg.solve(a, b), rtol=1e-12, atol=1e-13)
    rhs = rng.normal(size=(n, 3))
    np.testing.assert_allclose(
        lu_solve(factors, rhs), np.linalg.solve(a, rhs), rtol=1e-12, atol=1e-13
    )
    assert condition_1(a, factors) == pytest.approx(np.linalg.cond(a, 1), rel=1e-10)
    assert norm2(b) == pytest.approx(float(np.linalg.norm(b)), rel=1e-15)
    # a zero pivot column: singular, no factors
    a[:, 0] = 0.0
    assert lu_factor(a) is None


def test_pivot_dancer_rest_tension_closed_form(repo):
    # battery_foil_line: a pivot dancer (arm 0.3 m along +x at 0 rad) whose roller (r 40 mm,
    # at (0, -0.3) m) hangs between two idlers (r 40 mm, at (-/+0.1, 0) m), web crossing
    # from each idler to the dancer; loaded by an air cylinder and the arm's and roller's
    # weight. Moment balance about the pivot at the initial arm angle, both spans at T:
    #   T·(arm·cos(a) + arm·cos(a)) + M_cylinder + M_gravity = 0,
    # a the spans' tilt from vertical (centre line tilt minus the crossed tangent's angle)
    line = r2rsim.load_line(repo / "lines" / "battery_foil_line.yaml")
    cl = r2rsim.compile_line(line, r2rsim.Programme.constant(line, line_speed=0.5))
    arm, r = 0.3, 0.04
    d = np.hypot(0.1, 0.3)
    tilt = np.arctan2(0.1, 0.3) - np.arcsin(2 * r / d)
    lever = 2 * arm * np.cos(tilt)
    # cylinder: arm point (-0.15, -0.3), fixed point (-0.15, 0.2): it pushes straight down
    # on a 0.15 m lever; gravity: (0.5 kg · 0.3 m + 1.0 kg · 0.15 m) · g on the level arm
    m_cyl = -220.4 * 0.15
    m_grav = -(0.5 * 0.3 + 1.0 * 0.15) * 9.81
    T = -(m_cyl + m_grav) / lever
    assert T == pytest.approx(60.14, abs=0.01)  # the line file's comment
    assert _mover_tensions(cl) == [pytest.approx(T, rel=1e-9)]
    # a nominal state at 0 N is made taut at the median of the tension set-point (60 N)
    # and the dancer's rest tension, and the steady state is found from it
    zero = r2rsim.nominal_state(cl, 0.0)
    taut = taut_guess(cl, zero)
    for sid in cl.span_ids:
        assert taut[cl.index(f"{sid}.strain")] * line.web.EA == pytest.approx(
            np.median([60.0, T]), rel=1e-12
        )
    found = r2rsim.steady_state(cl, zero)
    assert found is not None
    aux = cl.outputs(0.0, found[None, :])[0]
    q = found[cl.index("dancer.position")]
    load, dL = cl.mover_balance(0, q)
    for sid in cl.span_ids[1:3]:  # the dancer's spans hold its load at the steady angle
        assert aux[cl.aux_index(f"{sid}.tension_N")] == pytest.approx(load / dL, rel=1e-3)
