"""Each phase of the kernel (r2rsim/compile/model) against central finite differences: the
sparse gradients of the intermediates it computes (span tension, radius, sensor reading,
controller output, ...) and the Jacobian rows of the state derivatives it writes.

A new phase gets an entry in ``PHASES`` (what it computes, which rows it writes) or in
``NO_JACOBIAN`` (why it has no Jacobian share); ``test_every_phase_is_listed`` fails until
it has one. The whole Jacobian is checked against differences in tests/test_jacobian.py;
here a wrong derivative is traced to the phase that computes it.
"""

from __future__ import annotations

import ast
import importlib
import warnings

import numpy as np
import pytest
from test_jacobian import FULL, MOVERS, _state

import r2rsim
from r2rsim.compile import model
from r2rsim.compile.layout import (
    CtrlI,
    CtrlKind,
    DriveKind,
    H,
    MoverI,
    NodeI,
    SensorI,
    SensorKind,
)
from r2rsim.compile.model import base, movers
from r2rsim.schema.scenario import ProgrammeStep

from conftest import REPO, write

# ---------------------------------------------------------------------------- what each owns


def _all(n):
    return np.arange(n)


def _nodes_where(cl, cond):
    return np.array([k for k in range(len(cl.node_ids)) if cond(cl.node_i[k])], dtype=int)


def _sensors_where(cl, cond):
    return np.array([j for j in range(cl.sensor_i.shape[0]) if cond(cl, cl.sensor_i[j])], dtype=int)


def _ctrls_where(cl, cond):
    return np.array([c for c in range(cl.ctrl_i.shape[0]) if cond(cl.ctrl_i[c])], dtype=int)


def _states(field, records):
    return np.array([r[field] for r in records if r[field] >= 0], dtype=int)


def _imposed_encoder(cl, s):
    return s[SensorI.TYPE] == SensorKind.ENCODER and cl.node_i[s[SensorI.NODE], NodeI.W] < 0


def _mover_spans(cl):
    return np.array([s for r in cl.mover_i for s in r[[MoverI.SPAN_U, MoverI.SPAN_D]] if s >= 0])


def _eccentric_spans(cl):
    ecc = _nodes_where(cl, lambda r: r[NodeI.TH] >= 0)
    spans = cl.node_i[ecc][:, [NodeI.SPAN_UP, NodeI.SPAN_DN]].ravel() if len(ecc) else []
    return np.array([s for s in spans if s >= 0], dtype=int)


def _is_loop(c):
    return c[CtrlI.TYPE] != CtrlKind.SPEED


def _torque_driven_speed_loops(cl):
    return _states(
        NodeI.SPEEDC,
        [r for r in cl.node_i if r[NodeI.DRIVE] == DriveKind.TORQUE],
    )


#: phase -> (function, {intermediate: indices it computes}, state rows it writes)
PHASES = {
    "span_tensions": (lambda cl: ({"tension": _all(len(cl.span_ids))}, [])),
    "mover_spans": (lambda cl: ({"length": _mover_spans(cl), "length_rate": _mover_spans(cl)}, [])),
    "eccentric_lengths": (
        lambda cl: (
            {"length": _eccentric_spans(cl), "length_rate": _eccentric_spans(cl)},
            _states(NodeI.TH, cl.node_i),
        )
    ),
    "roll_geometry": (
        lambda cl: (
            {
                "radius": _all(len(cl.node_ids)),
                "omega": _nodes_where(cl, lambda r: r[NodeI.W] >= 0),
            },
            [],
        )
    ),
    "mover_dynamics": (
        lambda cl: ({}, [*_states(MoverI.Q, cl.mover_i), *_states(MoverI.QD, cl.mover_i)])
    ),
    "sensor_readings": (
        lambda cl: (
            {
                "raw": _sensors_where(cl, lambda cl, s: not _imposed_encoder(cl, s)),
                "seen": _sensors_where(cl, lambda cl, s: not _imposed_encoder(cl, s)),
            },
            [],
        )
    ),
    "tension_loops": (
        lambda cl: (
            {
                "ctrl_out": _ctrls_where(cl, _is_loop),
                "speed_trim": np.unique(
                    [c[CtrlI.NODE] for c in cl.ctrl_i if _is_loop(c)] or np.zeros(0, int)
                ),
            },
            _states(CtrlI.X, [c for c in cl.ctrl_i if _is_loop(c)]),
        )
    ),
    "torque_commands": (
        lambda cl: (
            {
                "ctrl_err": _ctrls_where(cl, lambda c: not _is_loop(c)),
                "torque_cmd": _all(len(cl.node_ids)),
            },
            [],
        )
    ),
    "drive_torques": (
        lambda cl: (
            {"torque": _nodes_where(cl, lambda r: r[NodeI.DRIVE] == DriveKind.TORQUE)},
            [
                *_states(NodeI.TAU, cl.node_i),
                *_states(CtrlI.X, cl.ctrl_i[_torque_driven_speed_loops(cl)]),
            ],
        )
    ),
    "surface_speeds": (
        lambda cl: (
            {
                "speed": _all(len(cl.node_ids)),
                "omega": _nodes_where(cl, lambda r: r[NodeI.W] < 0),
            },
            [],
        )
    ),
    # what the controllers see of an encoder on an imposed-speed node carries no gradient: no
    # controller reads it (a speed loop reads the encoder of its own, free, node)
    "imposed_speed_encoders": (lambda cl: ({"raw": _sensors_where(cl, _imposed_encoder)}, [])),
    "torque_balance": (lambda cl: ({}, _states(NodeI.W, cl.node_i))),
    "roll_lengths": (lambda cl: ({}, [*_states(NodeI.S, cl.node_i), *_states(NodeI.U, cl.node_i)])),
    "span_balance": (lambda cl: ({}, _states(0, cl.span_i))),  # SpanI.E
    "sensor_filters": (lambda cl: ({}, _states(SensorI.F, cl.sensor_i))),
}

#: phases without a Jacobian share, and why
NO_JACOBIAN = {
    "fault_profiles": "writes parameters as functions of time only",
    "fixed_lengths": "writes constants",
    "joint_compliance": "the joint's overlap is held constant between joint-pass events "
    "(physics.md §1.9; the joints module says why)",
    "outputs": "not part of the right-hand side",
}


def test_every_phase_is_listed():
    """Every phase the orchestrator calls has a finite-difference check or a reason."""
    src = (REPO / "r2rsim" / "compile" / "kernels.py").read_text(encoding="utf-8")
    fn = next(
        f for f in ast.parse(src).body if isinstance(f, ast.FunctionDef) and f.name == "evaluate"
    )
    calls = {
        (n.func.value.id, n.func.attr)
        for n in ast.walk(fn)
        if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)
    }
    called = {attr for _, attr in calls}
    assert called == set(PHASES) | set(NO_JACOBIAN)
    assert not set(PHASES) & set(NO_JACOBIAN)
    for module, attr in calls:  # each a documented function of its family's module
        fn = getattr(importlib.import_module(f"{model.__name__}.{module}"), attr)
        assert fn.py_func.__doc__, attr


# ---------------------------------------------------------------------------- the lines
def _full():
    line = r2rsim.load_line(write(_tmp() / "full.yaml", FULL.format(model="exact", limit=200)))
    prog = r2rsim.Programme.from_steps(
        line, [ProgrammeStep(at=0, line_speed=2.0), ProgrammeStep(at=0.5, line_speed=5.0, ramp=4.0)]
    )
    cl = r2rsim.compile_line(line, prog)
    cl.set_segment_start(0.5)
    return cl, _state(cl, np.random.default_rng(3)), 1.7


def _movers():
    line = r2rsim.load_line(write(_tmp() / "movers.yaml", MOVERS.format(model="exact", limit=0.5)))
    cl = r2rsim.compile_line(
        line, r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=3.0)])
    )
    y = r2rsim.nominal_state(cl, 250.0)
    rng = np.random.default_rng(5)
    for i, kind in enumerate(cl.state_kinds):
        if kind in ("strain", "speed", "torque", "controller", "sensor_filter"):
            y[i] *= 1 + 0.05 * rng.standard_normal()
        if kind == "mover":
            y[i] += 0.02 * rng.standard_normal()
    return cl, y, 0.3


def _scenario(rel, t):
    def make():
        from r2rsim.run import _prepare, plan_from_file

        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            prep = _prepare(plan_from_file(REPO / rel))
        cl, y = prep.cl, prep.y0.copy()
        rng = np.random.default_rng(7)
        y *= 1 + 0.01 * rng.standard_normal(len(y))  # taut spans stay taut
        cl.set_segment_start(0.0)
        return cl, y, t

    return make


_TMP = []


def _tmp():
    return _TMP[0]


CASES = {
    "rolls_nip_controllers": _full,
    "dancers_festoon": _movers,
    "testbed_eccentric_disturbed": _scenario("scenarios/thesis_realistic/testbed.yaml", 2.0),
    "registration_pitch": _scenario("scenarios/thesis_realistic/registration.yaml", 1.0),
}


# ---------------------------------------------------------------------------- the check
def _blocks(cl):
    return {name: start for name, (start, _) in base.scratch_blocks(cl.I).items()}


def _gradients(cl):
    """Dense gradient of every quantity after a Jacobian evaluation."""
    qid = base.quantity_offsets(cl.I)
    maxd = cl.I[H.MAXD]
    G = np.zeros((qid.count, cl.n_states))
    for q in range(qid.count):
        for m in range(cl._GC[q]):
            G[q, cl._GI[q * maxd + m]] += cl._GV[q * maxd + m]
    return qid, G


def _central(cl, t, y, steps):
    n = cl.n_states
    dY, dW = np.zeros((n, n)), np.zeros((len(cl._W), n))
    for j, h in enumerate(steps):
        yp, ym = y.copy(), y.copy()
        yp[j] += h
        ym[j] -= h
        fp = cl.rhs(t, yp)
        wp = cl._W.copy()
        fm = cl.rhs(t, ym)
        dY[:, j] = (fp - fm) / (2 * h)
        dW[:, j] = (wp - cl._W) / (2 * h)
    return dY, dW


def _differences(cl, t, y):
    """Central differences of dy/dt and of the scratch W (the intermediates), each with its
    noise: how far the differences move when the step grows tenfold (rounding error falls
    tenfold, a true derivative stays)."""
    kinds = cl.state_kinds
    steps = np.array(
        [1e-6 * max(1.0, abs(v)) if k != "strain" else 1e-10 for v, k in zip(y, kinds, strict=True)]
    )
    dY, dW = _central(cl, t, y, steps)
    dY10, dW10 = _central(cl, t, y, 10 * steps)
    return (dY, np.abs(dY - dY10)), (dW, np.abs(dW - dW10))


@pytest.fixture(scope="module")
def evaluated(tmp_path_factory):
    _TMP.append(tmp_path_factory.mktemp("phases"))
    out = {}
    for name, make in CASES.items():
        cl, y, t = make()
        J = cl.jacobian(t, y)
        qid, G = _gradients(cl)
        dY, dW = _differences(cl, t, y)
        out[name] = (cl, J, qid, G, dY, dW)
    return out


def _compare(analytic, fd, noise, what, floor=1e-6):
    """Analytic = central differences to 1e-4 relative (entries below ``floor`` of the row's
    largest are compared to that instead), give or take twice the differences' noise."""
    scale = np.abs(fd).max(axis=1, keepdims=True) + 1e-300
    tol = 1e-4 * (np.abs(fd) + floor * scale) + 2 * noise + 1e-14
    bad = np.argwhere(np.abs(analytic - fd) > tol)
    assert not len(bad), [(what, i, j, analytic[i, j], fd[i, j]) for i, j in bad[:5]]


@pytest.mark.parametrize("phase", sorted(PHASES))
def test_phase_against_central_differences(evaluated, phase):
    checked = 0
    for case, (cl, J, qid, G, dY, dW) in evaluated.items():
        quantities, rows = PHASES[phase](cl)
        start = _blocks(cl)
        for name, idx in quantities.items():
            idx = np.asarray(idx, dtype=int)
            if not len(idx):
                continue
            analytic = G[getattr(qid, name) + idx]
            rows_w = start[name] + idx
            _compare(analytic, dW[0][rows_w], dW[1][rows_w], f"{case}: {name}")
            checked += len(idx)
        rows = np.asarray(rows, dtype=int)
        if len(rows):
            _compare(J[rows], dY[0][rows], dY[1][rows], f"{case}: rows")
            checked += len(rows)
    assert checked > 0, f"no case exercises {phase}"


# ---------------------------------------------------------------------------- deliberate FD
@pytest.mark.parametrize("kind", ["dancer", "pivot"])
def test_mover_central_differences_are_accurate(tmp_path, kind):
    """The mover phases take d2L/dq2 and d(load)/dq by central differences (steps
    movers.H_LENGTH, movers.H_LOAD); their error against a converged Richardson
    extrapolation of the same closed forms stays below 1e-6 relative (the test line's
    dancer and pivot dancer, over their travel)."""
    line = r2rsim.load_line(write(tmp_path / "m.yaml", MOVERS.format(model="exact", limit=0.5)))
    cl = r2rsim.compile_line(line)
    m = 0 if kind == "dancer" else 1
    mp = cl.mover_p
    mkind = int(cl.mover_i[m, MoverI.KIND])
    q0 = cl.mover_q0[m]
    span = 0.1 if kind == "dancer" else 0.3
    worst_l = worst_f = 0.0
    for q in np.linspace(q0 - span, q0 + span, 9):

        def dl(x):
            _, a, _, b = movers.mover_lengths(mp, m, mkind, x)
            return np.array([a, b])

        def load(x):
            return movers.mover_load(mp, m, mkind, x)

        h = movers.H_LENGTH
        fd_l = (dl(q + h) - dl(q - h)) / (2 * h)
        fd_f = (load(q + movers.H_LOAD) - load(q - movers.H_LOAD)) / (2 * movers.H_LOAD)
        ref_l = _richardson(dl, q, 1e-3)
        ref_f = _richardson(load, q, 1e-2)
        worst_l = max(worst_l, np.max(np.abs(fd_l - ref_l) / (np.abs(ref_l) + 1e-3)))
        worst_f = max(worst_f, abs(fd_f - ref_f) / (abs(ref_f) + 1.0))
    assert worst_l < 1e-6, worst_l
    assert worst_f < 1e-6, worst_f
    print(f"{kind}: d2L/dq2 {worst_l:.1e}, dload/dq {worst_f:.1e}")


def _richardson(f, x, h0):
    """Derivative of f at x by Richardson extrapolation of central differences."""
    table = []
    h = h0
    for i in range(6):
        row = [(np.asarray(f(x + h)) - np.asarray(f(x - h))) / (2 * h)]
        for k in range(1, i + 1):
            row.append(row[k - 1] + (row[k - 1] - table[i - 1][k - 1]) / (4**k - 1))
        table.append(row)
        h /= 2
    return table[-1][-1]
