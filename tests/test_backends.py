"""The solver-backend interface (r2rsim.solve.backends): every registered backend is a
SolverBackend, returns the declared Chunk / Root / Located types, and the three agree with
each other on a short run; an unknown backend name is refused with the scenario's message."""

from __future__ import annotations

import inspect
import typing

import numpy as np
import pytest
import yaml
from pydantic import ValidationError

import r2rsim
from r2rsim.errors import InputError
from r2rsim.schema.scenario import ProgrammeStep, SolverOptions
from r2rsim.solve.backends import (
    BACKENDS,
    Chunk,
    Located,
    Root,
    SolverBackend,
    backend_class,
    make_backend,
)
from r2rsim.solve.simulate import describe_settings

from conftest import SMALL_LINE, SMALL_SCENARIO, kinematic_line, run_line

# how runs.parquet names each integrator at the default settings
DESCRIBED = {
    "radau5": "r2rsim Radau IIA order 5 (compiled) band analytic-jac rtol=1e-06",
    "cvode": "CVODE BDF max_order=2 band analytic-jac rtol=1e-06",
    "radau": "scipy Radau sparse analytic-jac rtol=1e-06",
}
# how far a backend's run may be from radau5's, as a fraction of each state's range
AGREE = {"radau5": 0.0, "radau": 1e-6, "cvode": 1e-4}
# physics.md V18: a single span pulled by a 1 % draw from 0 N breaks at 500 N at this time
T_BREAK = 1.392470


def test_registry_holds_every_backend_the_schema_allows():
    allowed = typing.get_args(SolverOptions.model_fields["backend"].annotation)
    assert set(BACKENDS) == set(allowed)
    for name, cls in BACKENDS.items():
        assert issubclass(cls, SolverBackend) and not inspect.isabstract(cls)
        assert cls.name == name and backend_class(name) is cls
        assert describe_settings(r2rsim.SolverSettings(backend=name)) == DESCRIBED[name]
    # the base class cannot be built, nor a backend that leaves a method out
    assert inspect.isabstract(SolverBackend)

    class Half(SolverBackend):
        name = "half"

        @staticmethod
        def describe(settings):
            return "half"

        @staticmethod
        def locates_events(hot):
            return False

    with pytest.raises(TypeError, match="abstract"):
        Half(None, r2rsim.SolverSettings())


@pytest.fixture(scope="module")
def break_line(tmp_path_factory):
    """V18's line compiled, its start state, and the event function of the break."""
    path = kinematic_line(
        tmp_path_factory.mktemp("v18"),
        model="linear",
        EA=1e5,
        spans=[2.0],
        draws=[0.0, 0.01],
        break_stress="5 MPa",
    )
    line = r2rsim.load_line(path)
    prog = r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=1.0)])
    cl = r2rsim.compile_line(line, prog)
    y0 = r2rsim.nominal_state(cl, 0.0)
    m_break = [k for k, c in enumerate(cl.event_components) if c == "span1"][-1]
    return cl, y0, m_break


@pytest.mark.parametrize("name", list(BACKENDS))
def test_backend_returns_the_declared_types(break_line, name):
    cl, y0, m_break = break_line
    n, m = cl.n_states, len(cl.event_kinds)
    backend = make_backend(cl, r2rsim.SolverSettings(backend=name, rtol=1e-9, atol_scale=1e-3))
    assert isinstance(backend, BACKENDS[name])
    # a quiet chunk: every sample, no failure, no root; the inputs untouched
    tspan = np.linspace(0.0, 1.3, 14)
    y_start, t_start = y0.copy(), tspan.copy()
    chunk = backend.advance(tspan, y_start)
    assert type(chunk) is Chunk
    assert chunk.failure is None and chunk.root is None
    np.testing.assert_array_equal(chunk.t, tspan)
    assert chunk.y.shape == (len(tspan), n) and np.all(np.isfinite(chunk.y))
    np.testing.assert_array_equal(chunk.y[0], y0)
    assert chunk.t_steps[0] == 0.0 and chunk.t_steps[-1] == pytest.approx(1.3, abs=1e-12)
    assert chunk.y_steps.shape == (len(chunk.t_steps), n)
    assert np.array_equal(y_start, y0) and np.array_equal(tspan, t_start)
    assert backend.nfev > 0 and backend.steps > 0
    # a hot chunk over the break
    y13 = chunk.y[-1].copy()
    hot = backend.advance(np.linspace(1.3, 1.5, 21), y13, find_events=True)
    assert type(hot) is Chunk and hot.failure is None
    if backend.locates_events(True):  # stopped at the break: the samples before it
        assert type(hot.root) is Root
        assert hot.root.t == pytest.approx(T_BREAK, abs=1e-6)
        assert hot.root.y.shape == (n,) and hot.root.directions.shape == (m,)
        assert hot.root.directions[m_break] == -1  # the break's function falls through 0
        assert np.count_nonzero(hot.root.directions) == 1
        assert hot.t[-1] <= hot.root.t and len(hot.y) == len(hot.t)
    else:  # the caller finds it on the steps
        assert hot.root is None and len(hot.t) == 21
        g = cl.events(hot.t_steps, hot.y_steps)[:, m_break]
        assert g[0] > 0 and g[-1] < 0
    # located exactly: at or just past the root
    found = backend.locate(1.3, y13, 1.5)
    assert type(found) is Located
    assert found.t == pytest.approx(T_BREAK, abs=1e-6)
    assert found.y.shape == (n,) and list(found.which) == [m_break]
    assert cl.events(found.t, found.y)[0, m_break] <= 0.0


def _small_line_run(tmp_path, backend):
    (tmp_path / "line.yaml").write_text(yaml.safe_dump(SMALL_LINE, sort_keys=False))
    scen_data = {
        **SMALL_SCENARIO,
        "programme": [
            {"at": 0, "line_speed": "1 m/s"},
            {"at": 0.05, "line_speed": "1.2 m/s", "ramp": "0.1 s"},
        ],
    }
    (tmp_path / "scen.yaml").write_text(yaml.safe_dump(scen_data, sort_keys=False))
    scen, line, _ = r2rsim.load_scenario(tmp_path / "scen.yaml")
    cl = r2rsim.compile_line(line, r2rsim.Programme.from_steps(line, scen.programme))
    s = r2rsim.SolverSettings(backend=backend, rtol=1e-9, atol_scale=1e-3)
    return cl, s, r2rsim.simulate(cl, scen.duration, scen.record_rate, r2rsim.nominal_state(cl), s)


def test_backends_agree_on_a_short_run(tmp_path):
    runs = {b: _small_line_run(tmp_path, b) for b in BACKENDS}
    cl, s, ref = runs["radau5"]
    assert not ref.terminated and len(ref.t) == 21 and ref.events
    tensions = [n for n in cl.aux_names if n.endswith(".tension_N")]
    scale = max(np.max(np.abs(ref[n])) for n in tensions)
    for b, (_, _, res) in runs.items():
        assert not res.terminated and np.array_equal(res.t, ref.t), b
        # the same events (span3 goes slack at 0.037 s), located within 2e-8 s of each other
        assert [(e.kind, e.component, e.state) for e in res.events] == [
            (e.kind, e.component, e.state) for e in ref.events
        ]
        assert all(abs(a.t - r.t) < 1e-6 for a, r in zip(res.events, ref.events, strict=True))
        # every state within a fraction of its range over the run (at rtol 1e-9: CVODE BDF2,
        # order 2, measured 3e-6, scipy's Radau, the method of radau5, 4e-9)
        rng = np.max(np.abs(ref.states), axis=0) + cl.atol * s.atol_scale
        rel = np.max(np.abs(res.states - ref.states), axis=0) / rng
        assert np.max(rel) <= AGREE[b], (b, cl.state_names[int(np.argmax(rel))], np.max(rel))
        for n in tensions:
            assert np.max(np.abs(res[n] - ref[n])) <= AGREE[b] * scale, (b, n)


def test_backends_agree_on_an_event(tmp_path):
    # the V18 break through the whole event loop: same event, same time, same samples
    path = kinematic_line(
        tmp_path, model="linear", EA=1e5, spans=[2.0], draws=[0.0, 0.01], break_stress="5 MPa"
    )
    runs = {
        b: run_line(
            path,
            backend=b,
            duration=1.5,
            rate=100.0,
            steps=[{"at": 0, "line_speed": 1.0}],
            tension=0.0,
        )[1]
        for b in BACKENDS
    }
    for b, res in runs.items():
        assert res.terminated and res.termination_reason == "web_break", b
        assert res.termination_time == pytest.approx(T_BREAK, abs=1e-6), b
        assert [e.kind for e in res.events] == ["web_break"]
        assert np.array_equal(res.t, runs["radau5"].t)
        T, T_ref = res["span1.tension_N"], runs["radau5"]["span1.tension_N"]
        assert np.max(np.abs(T - T_ref)) < 1e-3, b  # of 500 N, at rtol 1e-9
    assert runs["cvode"].stats["steps"] > 0 and runs["radau5"].stats["steps"] > 0
    assert runs["radau"].stats["steps"] is None  # scipy does not report its steps


def test_unknown_backend_is_refused_with_the_scenario_message(tmp_path):
    with pytest.raises(InputError) as by_registry:
        backend_class("radau6")
    assert str(by_registry.value) == "solver.backend: got 'radau6', expected " + (
        "'cvode', 'radau5' or 'radau'"
    )
    # the same words as a scenario that names it (the schema's Literal)
    (tmp_path / "line.yaml").write_text(yaml.safe_dump(SMALL_LINE, sort_keys=False))
    scen = {**SMALL_SCENARIO, "solver": {"backend": "radau6"}}
    (tmp_path / "scen.yaml").write_text(yaml.safe_dump(scen, sort_keys=False))
    with pytest.raises(InputError) as by_schema:
        r2rsim.load_scenario(tmp_path / "scen.yaml")
    assert by_schema.value.path == by_registry.value.path == "solver.backend"
    assert by_schema.value.message == by_registry.value.message
    with pytest.raises(ValidationError, match="radau6"):
        r2rsim.SolverSettings(backend="radau6")
    # settings built without validation reach the registry: the same error, not a KeyError
    line = r2rsim.load_line(tmp_path / "line.yaml")
    prog = r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=1.0)])
    cl = r2rsim.compile_line(line, prog)
    with pytest.raises(InputError, match="solver.backend: got 'radau6'"):
        r2rsim.simulate(cl, 0.01, 100.0, settings=SolverOptions.model_construct(backend="radau6"))
