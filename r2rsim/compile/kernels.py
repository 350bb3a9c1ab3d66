"""The numba kernel of a compiled line: right-hand side, analytic Jacobian, outputs, events.

:func:`evaluate` computes the right-hand side by calling the phases of
:mod:`r2rsim.compile.model` in order, one per family of elements (spans, rolls, movers,
sensors, controllers, drives, joints). With ``mode=Mode.JAC`` each phase also propagates,
for every intermediate quantity it computes (span tension, node speed, sensor reading,
controller output, drive torque, ...), a short sparse gradient with respect to the states,
and accumulates the chain rule into the Jacobian; ``Mode.TOUCH`` marks the entries instead,
which is how the compiler obtains the exact sparsity pattern. Every dependency is recorded
whichever branch is taken (slack or taut, forward or reverse flow, saturated or not), with a
zero derivative where it is inactive, so the pattern is the same at every state.

Everything the kernel reads is in two flat arrays, ``I`` (int64) and ``P`` (float64), laid out
by :mod:`r2rsim.compile.layout`; scratch arrays are allocated once by the compiler. Nothing
here allocates or touches a Python object. The phases are inlined into :func:`evaluate`
(see :mod:`r2rsim.compile.model.base`), so the split costs no calls.
"""

from __future__ import annotations

from numba.core.dispatcher import Dispatcher

from .layout import RUNTIME_MODE
from .model import controllers, drives, faults, joints, movers, outputs, rolls, sensors, spans
from .model.base import STAMP, H, Mode, StampedCache, borrow, kernel, quantity_ids, scratch_layout
from .model.events import event_functions
from .model.movers import mover_lengths, mover_load
from .model.programme import setpoint

__all__ = [
    "MODE_OUTPUTS",
    "MODE_RHS",
    "STAMP",
    "evaluate",
    "event_values",
    "event_values_after_rhs",
    "hermite",
    "jac_values",
    "mover_lengths",
    "mover_load",
    "rows",
    "scratch_layout",
    "setpoint",
]

#: index of the right-hand-side mode in RUNTIME_MODE, for compiled callers outside
#: ``compile/`` (the integrator in ``solve/radau.py``): ``RUNTIME_MODE[MODE_RHS]`` is an int64,
#: so numba compiles :func:`evaluate` once for it and Python's calls alike
MODE_RHS = int(Mode.RHS)
#: likewise, the outputs mode (the algebraic outputs of recorded samples)
MODE_OUTPUTS = int(Mode.OUTPUTS)


@kernel
def _start(JJ, mode, I, GC):
    """Empty every gradient and (JAC) zero the Jacobian's pattern entries."""
    for q in range(quantity_ids(I).count):
        GC[q] = 0
    if mode == Mode.JAC:
        npat = I[H.NPAT]
        op = I[H.OFF_PAT]
        for m in range(npat):
            JJ[I[op + m], I[op + npat + m]] = 0.0


@kernel(inline=False)
def evaluate(t, y, yd, JJ, mode, I, P, W, GI, GC, GV, aux):
    """Evaluate the line's ODE right-hand side into ``yd`` (and the Jacobian into ``JJ``).

    Parameters
    ----------
    t : float
        Time [s].
    y : ndarray
        State vector.
    yd : ndarray
        Output: dy/dt.
    JJ : ndarray (n, n)
        Jacobian (``Mode.JAC``: pattern entries are zeroed then filled; ``Mode.TOUCH``: pattern
        entries are set to 1). Ignored for ``Mode.RHS``.
    mode : int
        ``Mode.RHS``, ``Mode.JAC``, ``Mode.TOUCH`` or ``Mode.OUTPUTS`` (the outputs into
        ``aux``, skipping the disturbance sums that only dy/dt needs; ``yd`` is then not
        dy/dt).
    I, P : ndarray
        The compiled line (layout in :mod:`r2rsim.compile.layout`).
    W, GI, GC, GV : ndarray
        Scratch: values of intermediates; gradient indices, counts and values.
    aux : ndarray
        Output row of algebraic quantities (length 0 to skip).
    """
    # the phases read borrowed aliases of the arrays (model.base.Borrowed: no reference
    # counting), and are inlined here
    y_, yd_, JJ_, I_, P_, W_ = borrow(y), borrow(yd), borrow(JJ), borrow(I), borrow(P), borrow(W)
    GI_, GC_, GV_, aux_ = borrow(GI), borrow(GC), borrow(GV), borrow(aux)
    if mode == Mode.JAC or mode == Mode.TOUCH:
        _start(JJ_, mode, I_, GC_)
    V, A = setpoint(I_, P_, 0, t)
    faults.fault_profiles(t, I_, P_)
    spans.fixed_lengths(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    movers.mover_spans(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    rolls.eccentric_lengths(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    joints.joint_compliance(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    spans.span_tensions(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    rolls.roll_geometry(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    movers.mover_dynamics(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    sensors.sensor_readings(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    controllers.tension_loops(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    controllers.torque_commands(t, V, A, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    drives.drive_torques(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    rolls.surface_speeds(t, V, A, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    sensors.imposed_speed_encoders(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    rolls.torque_balance(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    rolls.roll_lengths(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    spans.span_balance(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    sensors.sensor_filters(t, y_, yd_, JJ_, mode, I_, P_, W_, GI_, GC_, GV_)
    if aux_.shape[0] > 0:
        outputs.outputs(t, V, A, y_, aux_, I_, P_, W_)


@kernel(inline=False)
def event_values(t, y, g, I, P, W, GI, GC, GV, yd, JJ):
    """Event functions at one state (:mod:`r2rsim.compile.model.events`); an event's
    condition holds where its value is < 0."""
    evaluate(t, y, yd, JJ, RUNTIME_MODE[Mode.RHS], I, P, W, GI, GC, GV, yd[:0])
    event_functions(t, borrow(y), borrow(g), borrow(I), borrow(P), borrow(W))


@kernel(inline=False)
def event_values_after_rhs(t, y, g, I, P, W):
    """The event functions at (t, y) from the intermediates an RHS evaluation at that same
    (t, y) has just left in ``W``: what :func:`event_values` returns, without evaluating the
    right-hand side again (the integrator evaluates dy/dt at every step's end anyway)."""
    event_functions(t, borrow(y), borrow(g), borrow(I), borrow(P), borrow(W))


#: what :func:`rows` evaluates for each row
ROWS_RHS, ROWS_OUTPUTS, ROWS_EVENTS = 0, 1, 2


@kernel(inline=False)
def rows(what, T, Y, OUT, I, P, W, GI, GC, GV, yd, JJ):
    """For every row r of a state matrix ``Y`` (at times ``T``), into ``OUT[r]``: dy/dt
    (``ROWS_RHS``), the algebraic outputs (``ROWS_OUTPUTS``) or the event functions
    (``ROWS_EVENTS``). One function rather than three: every compiled caller of
    :func:`evaluate` optimises the kernel again when it is first compiled."""
    rhs = RUNTIME_MODE[Mode.RHS]
    out = RUNTIME_MODE[Mode.OUTPUTS]
    for r in range(Y.shape[0]):
        if what == ROWS_RHS:
            evaluate(T[r], Y[r], OUT[r], JJ, rhs, I, P, W, GI, GC, GV, yd[:0])
        elif what == ROWS_OUTPUTS:
            evaluate(T[r], Y[r], yd, JJ, out, I, P, W, GI, GC, GV, OUT[r])
        else:
            event_values(T[r], Y[r], OUT[r], I, P, W, GI, GC, GV, yd, JJ)


@kernel(inline=False)
def jac_values(t, y, JJ, I, P, W, GI, GC, GV, yd, vals):
    """Jacobian at (t, y) as values on the compiled pattern (for sparse solvers)."""
    evaluate(t, y, yd, JJ, RUNTIME_MODE[Mode.JAC], I, P, W, GI, GC, GV, yd[:0])
    npat = I[H.NPAT]
    op = I[H.OFF_PAT]
    for m in range(npat):
        vals[m] = JJ[I[op + m], I[op + npat + m]]


@kernel(inline=False)
def hermite(ts, ys, fs, tq, out):
    """Cubic Hermite interpolation of solver steps (ts, ys, dy/dt = fs) at sorted times tq.

    Exact derivatives at both ends of each step make it fourth-order accurate, better than the
    BDF2 solution it interpolates; at a step time it returns the step state exactly.
    """
    n = ys.shape[1]
    j = 0
    last = ts.shape[0] - 1
    for r in range(tq.shape[0]):
        t = tq[r]
        while j < last - 1 and ts[j + 1] < t:
            j += 1
        h = ts[j + 1] - ts[j]
        if h <= 0.0:
            for i in range(n):
                out[r, i] = ys[j + 1, i]
            continue
        s = (t - ts[j]) / h
        s2 = s * s
        s3 = s2 * s
        h00 = 2.0 * s3 - 3.0 * s2 + 1.0
        h10 = s3 - 2.0 * s2 + s
        h01 = -2.0 * s3 + 3.0 * s2
        h11 = s3 - s2
        for i in range(n):
            out[r, i] = (
                h00 * ys[j, i] + h10 * h * fs[j, i] + h01 * ys[j + 1, i] + h11 * h * fs[j + 1, i]
            )


# every dispatcher above is inlined into its callers or carries the stamp in its cache key
# (kernel() does either); a plain njit function here would not, which
# tests/test_kernel_stamp.py checks
assert all(
    f.targetoptions.get("forceinline") or isinstance(f._cache, StampedCache)  # type: ignore[attr-defined]
    for f in list(globals().values())
    if isinstance(f, Dispatcher)
)
