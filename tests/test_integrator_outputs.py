"""The compiled Radau IIA's own work at each step and sample (issue 40): the algebraic
outputs evaluated at the sample times inside the integrator, the event functions taken from
the step's last right-hand side, and the count of which state limits the step size."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

import r2rsim
from r2rsim.compile import kernels
from r2rsim.run import _prepare, plan_from_file
from r2rsim.solve.backends.radau5 import Radau5Backend

from conftest import REPO, write


def _simulate(path, monkeypatch=None, second_pass=False):
    """simulate() as ``r2rsim run`` calls it; ``second_pass``: the backend returns no
    outputs, so the event loop evaluates them in Python afterwards (the earlier path)."""
    plan = plan_from_file(path)
    prep = _prepare(plan)
    sc = plan.scenario
    if second_pass:
        advance = Radau5Backend.advance
        monkeypatch.setattr(
            Radau5Backend,
            "advance",
            lambda self, *a, **k: advance(self, *a, **k)._replace(aux=None),
        )
    res = r2rsim.simulate(
        prep.cl,
        sc.duration,
        sc.record_rate,
        prep.y0,
        sc.solver,
        events=sc.events,
        faults=prep.faults,
        rolls=prep.rolls,
    )
    return res


@pytest.mark.parametrize(
    "scenario, has_events",
    [
        ("newsprint_splice.yaml", True),  # a flying splice: the joint's events, new parameters
        ("thesis_dancer_failure.yaml", True),  # a dancer seizing and its stops' events
        ("torque_modes.yaml", False),  # winding-mode switches in the programme
    ],
)
def test_outputs_from_the_integrator_are_those_of_the_second_pass(
    scenario, has_events, monkeypatch
):
    # the same evaluation (same state, time, discrete state and kernel) in another place:
    # every output of every sample is the same to the bit, and so are the events
    inside = _simulate(REPO / "scenarios" / scenario)
    after = _simulate(REPO / "scenarios" / scenario, monkeypatch, second_pass=True)
    assert (len(inside.events) > 0) == has_events
    assert [(e.t, e.message) for e in inside.events] == [(e.t, e.message) for e in after.events]
    np.testing.assert_array_equal(inside.t, after.t)
    np.testing.assert_array_equal(inside.states, after.states)
    assert inside.outputs.shape == after.outputs.shape and inside.outputs.shape[1] > 10
    np.testing.assert_array_equal(inside.outputs, after.outputs)


def test_outputs_follow_the_discrete_state_of_their_sample(monkeypatch):
    # a splice changes the web's parameters mid-run: an output evaluated afterwards with the
    # line as it was at the start would differ, the integrator's must not
    res = _simulate(REPO / "scenarios" / "newsprint_splice.yaml")
    cl = res.compiled
    first = min(e.t for e in res.events)
    early = res.t < first
    assert early.any() and (~early).any()
    np.testing.assert_array_equal(res.outputs[early], cl.outputs(res.t[early], res.states[early]))


def test_event_values_from_the_last_rhs_equal_a_fresh_evaluation():
    # the integrator takes the event functions from what its step-end evaluation left in the
    # scratch array; at any state that must be what event_values computes from scratch
    for name in ("newsprint_splice.yaml", "thesis_dancer_failure.yaml"):
        cl = _prepare(plan_from_file(REPO / "scenarios" / name)).cl
        assert len(cl.event_kinds) > 0
        rng = np.random.default_rng(3)
        y0 = r2rsim.nominal_state(cl)
        n, m = cl.n_states, len(cl.event_kinds)
        for _ in range(20):
            y = y0 * (1.0 + 0.05 * rng.standard_normal(n))
            t = float(rng.uniform(0.0, 30.0))
            yd, f = np.zeros(n), np.zeros(n)
            fresh, reused = np.zeros(m), np.zeros(m)
            kernels.event_values(t, y, fresh, cl.I, cl.P, cl._W, cl._GI, cl._GC, cl._GV, yd, cl._J1)
            kernels.evaluate(
                t, y, f, cl._J1, kernels.RUNTIME_MODE[kernels.MODE_RHS], cl.I, cl.P, cl._W,
                cl._GI, cl._GC, cl._GV, cl._aux0,
            )  # fmt: skip
            kernels.event_values_after_rhs(t, y, reused, cl.I, cl.P, cl._W)
            np.testing.assert_array_equal(reused, fresh)


def test_step_limits_count_every_accepted_step_at_the_forced_states(tmp_path):
    # a 2 Hz bearing drag on idler1 alone (no noise in the loop): every accepted step is
    # counted once, and the states that limit the steps are the forced idler's and its spans'
    d = yaml.safe_load((REPO / "lines" / "pet_film_line.yaml").read_text())
    for s in d["sensors"]:
        s.pop("noise", None)
    line = write(tmp_path / "line.yaml", yaml.safe_dump(d))
    sc = {
        "name": "drag",
        "line": str(line),
        "duration": 10.0,
        "record_rate": 100.0,
        "initial": {"state": "steady"},
        "programme": [{"at": 0, "line_speed": 5.0}],
        "disturbances": [
            {"type": "bearing_drag", "element": "idler1", "std": "0.02 N*m", "bandwidth": "2 Hz"}
        ],
    }
    res = _simulate(write(tmp_path / "drag.yaml", yaml.safe_dump(sc)))
    lim = res.stats["step_limits"]
    assert lim.dtype == np.int64 and lim.sum() == res.stats["steps"] > 100
    names = res.compiled.state_names
    top = names[int(np.argmax(lim))]
    assert top in {"idler1.speed", "span1.strain", "span2.strain"}, top
    assert res.stats["nlu"] > 0


def test_cvode_reports_no_step_limits_and_still_records_outputs():
    path = REPO / "scenarios" / "quickstart.yaml"
    plan = plan_from_file(path)
    prep = _prepare(plan)
    sc = plan.scenario
    res = r2rsim.simulate(
        prep.cl, 5.0, sc.record_rate, prep.y0, r2rsim.SolverSettings(backend="cvode")
    )
    assert res.stats["step_limits"] is None and res.stats["nlu"] is None
    # CVODE returns no outputs with its samples: the event loop evaluates them
    assert res.outputs.shape == (len(res.t), len(prep.cl.aux_names)) and len(res.t) > 100
    tension = [prep.cl.aux_index(f"{s}.tension_N") for s in prep.cl.span_ids]
    assert np.all(res.outputs[:, tension] > 100.0)  # quickstart's webs run taut


def _lines_with_every_disturbance():
    """Compiled lines whose disturbances include every kind (the calibrated set's base run
    has all three; the test bed's variant has drags and an eccentric drive)."""
    out = []
    for name in ("thesis_realistic/registration.yaml", "thesis_realistic/testbed.yaml"):
        plan = plan_from_file(REPO / "scenarios" / name)
        assert len(plan.scenario.disturbances) >= 3
        out.append(_prepare(plan).cl)
    return out


def test_outputs_mode_skips_only_what_no_output_reads():
    # Mode.OUTPUTS leaves out the bearing-drag and wound-in-strain sums (dy/dt's only); the
    # outputs must be those of a full right-hand-side evaluation, to the bit
    rng = np.random.default_rng(5)
    rhs, outputs = (kernels.RUNTIME_MODE[m] for m in (kernels.MODE_RHS, kernels.MODE_OUTPUTS))
    for cl in _lines_with_every_disturbance():
        n, na = cl.n_states, len(cl.aux_names)
        y0 = r2rsim.nominal_state(cl)
        yd = np.zeros(n)
        for _ in range(25):
            y = y0 * (1.0 + 0.02 * rng.standard_normal(n))
            t = float(rng.uniform(0.0, 300.0))
            full, skipped = np.zeros(na), np.zeros(na)
            args = (cl.I, cl.P, cl._W, cl._GI, cl._GC, cl._GV)
            kernels.evaluate(t, y, yd, cl._J1, rhs, *args, full)
            with_drag = yd.copy()
            kernels.evaluate(t, y, yd, cl._J1, outputs, *args, skipped)
            np.testing.assert_array_equal(skipped, full)
            # and it did skip: dy/dt differs where a drag or the wound-in strain acts
            assert not np.array_equal(yd, with_drag)
