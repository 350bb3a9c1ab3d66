"""Lower a validated line (and its operating programme) into a :class:`CompiledLine`.

States are laid out along the web path: for each element its own states (roll length and
unstretched length, angular speed, drive torque, controller integrators, sensor filters),
then the strain of the span that leaves it. Only neighbours interact, so the Jacobian is
banded; the exact pattern is obtained from the kernel itself (``Mode.TOUCH``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import cast

import numpy as np

from ..errors import InputError
from ..schema.kinds import kind_of
from ..schema.line import (
    Line,
    dancer_centre,
    dancer_offsets,
    draw_problem,
    load_cell_weights,
    pitch_unwind,
    torque_problem,
)
from . import kernels
from .disturbances import realise_pitch_variations
from .layout import (
    AUX_CTRL,
    AUX_JOINT,
    AUX_MOVER,
    AUX_NODE,
    AUX_SENS,
    AUX_SPAN,
    HEADER,
    N_CTRL_I,
    N_CTRL_P,
    N_EVENT_I,
    N_FAULT_P,
    N_JOINT_P,
    N_MOVER_I,
    N_MOVER_P,
    N_NODE_I,
    N_NODE_P,
    N_SENSOR_I,
    N_SENSOR_P,
    N_SPAN_I,
    N_SPAN_P,
    N_TABLE_I,
    RECORD_BLOCKS,
    CtrlI,
    CtrlKind,
    CtrlP,
    DriveKind,
    EventKind,
    H,
    Mode,
    MoverI,
    MoverKind,
    MoverP,
    NodeI,
    NodeKind,
    NodeP,
    SensorI,
    SensorKind,
    SensorP,
    Shape,
    SpanI,
    SpanP,
    TableI,
    TableKind,
)

MAXD = 16  # gradient slots per intermediate quantity


def _names(enum) -> dict[str, int]:
    return {name: int(member) for name, member in enum.__members__.items()}


#: record families by name: "I"/"P" -> (header slot of the block offset, of the count,
#: record size, field name -> offset), from the layout's one declaration of the blocks
_FAMILIES: dict[str, dict[str, tuple]] = {}
for (_family, _array), (_off, _count, _fields) in RECORD_BLOCKS.items():
    _FAMILIES.setdefault(_family, {})[_array] = (_off, _count, len(_fields), _names(_fields))


def _kind_names(enum) -> dict[int, str]:
    return {int(member): name for name, member in enum.__members__.items()}


#: family -> (default kind field, kind field -> (value -> kind name))
_KIND_FIELDS = {
    "node": ("KIND", {"KIND": _kind_names(NodeKind), "DRIVE": _kind_names(DriveKind)}),
    "sensor": ("TYPE", {"TYPE": _kind_names(SensorKind)}),
    "ctrl": ("TYPE", {"TYPE": _kind_names(CtrlKind)}),
    "mover": ("KIND", {"KIND": _kind_names(MoverKind)}),
    "event": ("KIND", {"KIND": _kind_names(EventKind)}),
}

_HEADER_FIELDS = _names(H)

#: event kind -> name used in the event log
EVENT_NAMES = {
    EventKind.SLACK: "slack",
    EventKind.BREAK: "web_break",
    EventKind.CAPSTAN: "slip_risk",
    EventKind.EMPTY: "roll_empty",
    EventKind.STOP_LO: "dancer_stop_low",
    EventKind.STOP_HI: "dancer_stop_high",
    EventKind.JOINT_PASS: "splice_joint",
    EventKind.JOINT_BREAK: "splice_break",
    EventKind.SPLICE_RADIUS: "splice_trigger",
    EventKind.REFILL: "splice_refilled",
}
#: event kind name -> name used in the event log (``EVENT_LABELS[cl.kind("event", m)]``)
EVENT_LABELS = {kind.name: label for kind, label in EVENT_NAMES.items()}
N_JOINT_SLOTS = 2  # splice joints on the line at once (a joint leaves at the rewind)


@dataclass
class Programme:
    """Piecewise-linear set-point tables, one channel each:

    * channel 0: line speed [m/s];
    * one per tension controller, named by its id: the tension set-point [N];
    * ``torque:<element>``: the torque command [N m] of a torque drive without a controller
      (the line's ``drive.torque_command``, or 0 until the programme sets one);
    * ``draw:<element>``: the draw of an element whose draw the programme changes (it starts
      at the line's ``draw``).

    ``breakpoints`` are the times where a set-point or its slope jumps: the solver stops and
    re-initialises there."""

    names: list[str]
    times: list[list[float]]
    values: list[list[float]]
    breakpoints: list[float] = field(default_factory=list)

    @classmethod
    def constant(cls, line: Line, line_speed: float = 0.0, torque=(), draw=()) -> Programme:
        """Constant set-points: ``line_speed``, the controllers' tension set-points, the
        drives' torque commands; ``torque`` and ``draw`` name further elements that get a
        channel (at 0 N m and at their line-file draw)."""
        names = ["line_speed"] + [c.id for c in line.controllers if c.type == "tension_pi"]
        vals = [line_speed] + [c.setpoint for c in line.controllers if c.type == "tension_pi"]
        for e in line.elements:
            cmd = getattr(getattr(e, "drive", None), "torque_command", None)
            if cmd is not None or e.id in torque:
                names.append(f"torque:{e.id}")
                vals.append(cmd if cmd is not None else 0.0)
        for e in line.elements:
            if e.id in draw:
                names.append(f"draw:{e.id}")
                vals.append(_line_draw(line, e))
        return cls(names, [[0.0] for _ in names], [[v] for v in vals], [])

    @classmethod
    def from_steps(cls, line: Line, steps, file: str = "<scenario>") -> Programme:
        """Build the tables from scenario programme steps (validated, time-ordered)."""
        tension_ids = {c.id for c in line.controllers if c.type == "tension_pi"}
        for i, st in enumerate(steps):
            for cid in st.tension or {}:
                if cid not in tension_ids:
                    known = ", ".join(sorted(tension_ids)) or "none defined"
                    raise InputError(
                        f"no tension controller '{cid}' in the line (known: {known})",
                        file=file,
                        path=f"programme[{i}].tension.{cid}",
                    )
            for key, check in (("draw", draw_problem), ("torque", torque_problem)):
                for eid in getattr(st, key) or {}:
                    problem = check(line, eid)
                    if problem:
                        raise InputError(problem, file=file, path=f"programme[{i}].{key}.{eid}")
        prog = cls.constant(
            line,
            torque={e for st in steps for e in st.torque or {}},
            draw={e for st in steps for e in st.draw or {}},
        )
        chan = {n: i for i, n in enumerate(prog.names)}
        busy_until = [0.0] * len(prog.names)
        busy_by = [""] * len(prog.names)
        for i, st in enumerate(steps):
            changes = []
            if st.line_speed is not None:
                changes.append((0, st.line_speed))
            for cid, val in (st.tension or {}).items():
                changes.append((chan[cid], val))
            for eid, val in (st.torque or {}).items():
                changes.append((chan[f"torque:{eid}"], val))
            for eid, val in (st.draw or {}).items():
                changes.append((chan[f"draw:{eid}"], val))
            for ch, new in changes:
                ts, vs = prog.times[ch], prog.values[ch]
                old = vs[-1]
                if st.at < busy_until[ch] - 1e-12:
                    raise InputError(
                        f"starts at {st.at:g} s, before the ramp of {busy_by[ch]} "
                        f"ends at {busy_until[ch]:g} s",
                        file=file,
                        path=f"programme[{i}].at",
                    )
                if st.rate is not None and ch == 0:
                    dur = abs(new - old) / st.rate
                else:
                    dur = st.ramp or 0.0
                if st.at == 0.0 and dur == 0.0:
                    vs[-1] = new  # initial value
                    continue
                if st.at > ts[-1]:
                    ts.append(st.at)
                    vs.append(old)
                ts.append(st.at + dur)
                vs.append(new)
                busy_until[ch] = st.at + dur
                busy_by[ch] = f"programme[{i}]"
        bps = sorted({t for ts in prog.times for t in ts if t > 0.0})
        prog.breakpoints = bps
        return prog

    def value(self, name: str, t: float) -> float:
        """Set-point value at time t (right-continuous), evaluated in Python; ``name`` is a
        channel name (``line_speed``, a tension controller id, ``torque:<element>``,
        ``draw:<element>``)."""
        ch = self.names.index(name)
        ts, vs = self.times[ch], self.values[ch]
        k = max(m for m in range(len(ts)) if ts[m] <= t)
        if k >= len(ts) - 1:
            return vs[-1]
        dt = ts[k + 1] - ts[k]
        return vs[k] if dt <= 0 else vs[k] + (vs[k + 1] - vs[k]) * (t - ts[k]) / dt


def _line_draw(line: Line, e) -> float:
    """The draw an element has in the line file: its ideal_speed drive's or its speed_pi's."""
    drive = getattr(e, "drive", None)
    if drive is not None and drive.type == "ideal_speed":
        return drive.draw
    return next(
        (c.draw for c in line.controllers if c.type == "speed_pi" and c.element == e.id), 0.0
    )


@dataclass
class CompiledLine:
    """A line lowered to flat arrays, ready for the solver.

    Attributes
    ----------
    line : Line
    I, P : ndarray
        Flat int64 topology/index array and float64 parameter vector read by the kernel.
    n_states : int
    state_names : list of str
        ``<component>.<state>`` for every state, in web order.
    state_units : list of str
    atol : ndarray
        Per-state absolute tolerances.
    pattern : (rows, cols)
        Jacobian sparsity pattern (exact, from the kernel).
    lband, uband : int
        Band widths of the pattern.
    aux_names, aux_units : list of str
        Names of the algebraic outputs (columns of :meth:`outputs`).
    event_names : list of (kind, component)
    """

    line: Line
    programme: Programme
    I: np.ndarray
    P: np.ndarray
    n_states: int
    state_names: list[str]
    state_units: list[str]
    state_kinds: list[str]
    atol: np.ndarray
    aux_names: list[str]
    aux_units: list[str]
    event_kinds: list[int]
    event_components: list[str]
    node_ids: list[str]
    span_ids: list[str]
    sensors: list
    controllers: list
    mover_ids: list[str] = field(default_factory=list)
    mover_q0: list[float] = field(default_factory=list)
    splice_nodes: list[int] = field(default_factory=list)
    n_joint_slots: int = 0
    pattern: tuple[np.ndarray, np.ndarray] = (np.zeros(0, np.int64), np.zeros(0, np.int64))
    lband: int = 0
    uband: int = 0

    def __post_init__(self):
        nq = int(self.I[H.NQ])
        drag_cache, end = kernels.scratch_layout(self.I)
        self._W = np.zeros(
            max(
                end,
                4 * self.n_states
                + 16 * (len(self.node_ids) + len(self.span_ids))
                + 8 * (len(self.sensors) + len(self.controllers))
                + 16,
            )
        )
        self._W[drag_cache:end] = np.nan  # no time matches an empty slot
        self._GI = np.zeros(nq * MAXD, np.int64)
        self._GC = np.zeros(nq, np.int64)
        self._GV = np.zeros(nq * MAXD)
        self._J1 = np.zeros((1, 1))
        self._aux0 = np.zeros(0)
        self._yd = np.zeros(self.n_states)

    # ---- the record families: zero-copy views of I and P ----------------------------------
    def _records(self, arr: np.ndarray, off: H, count: H, size: int) -> np.ndarray:
        o, n = int(self.I[off]), int(self.I[count])
        return arr[o : o + n * size].reshape(n, size)  # a view: writes reach the kernel

    @property
    def node_i(self) -> np.ndarray:
        """Node records of I, (nodes, :class:`NodeI`): ``cl.node_i[k, NodeI.W]``."""
        return self._records(self.I, H.OFF_NI, H.NN, N_NODE_I)

    @property
    def node_p(self) -> np.ndarray:
        """Node records of P, (nodes, :class:`NodeP`): ``cl.node_p[k, NodeP.TEFF]``."""
        return self._records(self.P, H.OFF_NP, H.NN, N_NODE_P)

    @property
    def span_i(self) -> np.ndarray:
        return self._records(self.I, H.OFF_SI, H.NS, N_SPAN_I)

    @property
    def span_p(self) -> np.ndarray:
        return self._records(self.P, H.OFF_SP, H.NS, N_SPAN_P)

    @property
    def sensor_i(self) -> np.ndarray:
        return self._records(self.I, H.OFF_SEI, H.NSE, N_SENSOR_I)

    @property
    def sensor_p(self) -> np.ndarray:
        return self._records(self.P, H.OFF_SEP, H.NSE, N_SENSOR_P)

    @property
    def ctrl_i(self) -> np.ndarray:
        return self._records(self.I, H.OFF_CI, H.NC, N_CTRL_I)

    @property
    def ctrl_p(self) -> np.ndarray:
        return self._records(self.P, H.OFF_CP, H.NC, N_CTRL_P)

    @property
    def mover_i(self) -> np.ndarray:
        return self._records(self.I, H.OFF_MI, H.NM, N_MOVER_I)

    @property
    def mover_p(self) -> np.ndarray:
        return self._records(self.P, H.OFF_MP, H.NM, N_MOVER_P)

    @property
    def joint_p(self) -> np.ndarray:
        """Splice-joint slots of P, (slots, :class:`JointP`)."""
        return self._records(self.P, H.OFF_JP, H.NJ, N_JOINT_P)

    @property
    def fault_p(self) -> np.ndarray:
        """Fault parameter slots of P, (slots, :class:`FaultP`)."""
        return self._records(self.P, H.OFF_FS, H.NFS, N_FAULT_P)

    @property
    def event_i(self) -> np.ndarray:
        """Event records of I, (events, :class:`EventI`)."""
        return self._records(self.I, H.OFF_EV, H.NEV, N_EVENT_I)

    # ---- fields by name: the solver's access (it never imports the layout) ---------------
    # Families: "node", "span", "sensor", "ctrl", "mover" (int and float records), "joint",
    # "fault" (float only), "event" (int only). Field names are those of the layout's enums
    # (``"TEFF"`` is ``NodeP.TEFF``); a name not in the family raises KeyError naming the
    # family and its fields. Kinds are compared by name: ``cl.kind("node", k) == "UNWIND"``.
    # These are Python-side calls for discrete events, not the kernel's path.

    def param_index(self, family: str, i: int, name: str) -> int:
        """Absolute index in P of float field ``name`` of record ``i`` of ``family``
        (``cl.P[cl.param_index("node", k, "TEFF")]``; what a fault slot stores)."""
        return self._flat_index(family, "P", i, name)

    def field_index(self, family: str, i: int, name: str) -> int:
        """Absolute index in I of int field ``name`` of record ``i`` of ``family``."""
        return self._flat_index(family, "I", i, name)

    def param(self, family: str, i: int, name: str) -> float:
        """Float field ``name`` of record ``i`` of ``family``: ``cl.param("node", k, "TEFF")``."""
        return float(self.P[self._flat_index(family, "P", i, name)])

    def set_param(self, family: str, i: int, name: str, value: float) -> None:
        """Set float field ``name`` of record ``i``: ``cl.set_param("ctrl", j, "SETP", v)``;
        the kernel sees it at its next evaluation."""
        self.P[self._flat_index(family, "P", i, name)] = value

    def field(self, family: str, i: int, name: str) -> int:
        """Int field ``name`` of record ``i`` of ``family`` (a state index, a node, ...):
        ``cl.field("mover", m, "Q")``."""
        return int(self.I[self._flat_index(family, "I", i, name)])

    def kind(self, family: str, i: int, name: str | None = None) -> str:
        """The kind of record ``i`` by name: ``"UNWIND"``, ``"ROLLER"`` ... for ``"node"``,
        ``"SPEED"`` ... for ``"ctrl"``, ``"PIVOT"`` ... for ``"mover"``, ``"DIAMETER"`` ...
        for ``"sensor"``, ``"BREAK"`` ... for ``"event"``; ``cl.kind("node", k, "DRIVE")``
        is the drive's kind (``"NONE"``, ``"TORQUE"``, ``"IDEAL"``). Compare with strings."""
        try:
            default, names = _KIND_FIELDS[family]
        except KeyError:
            raise KeyError(
                f"no kinds for record family {family!r}; known: {', '.join(_KIND_FIELDS)}"
            ) from None
        name = name or default
        try:
            kinds = names[name]
        except KeyError:
            raise KeyError(
                f"{family} field {name!r} is not a kind; kind fields: {', '.join(names)}"
            ) from None
        return kinds[self.field(family, i, name)]

    def header(self, name: str) -> int:
        """Header slot ``name`` of I (a count or block offset, e.g. ``"NFS"``)."""
        try:
            return int(self.I[_HEADER_FIELDS[name]])
        except KeyError:
            raise KeyError(
                f"header has no field {name!r}; known fields: {', '.join(_HEADER_FIELDS)}"
            ) from None

    def _flat_index(self, family: str, which: str, i: int, name: str) -> int:
        try:
            off, count, size, fields = _FAMILIES[family][which]
        except KeyError:
            known = [f for f, d in _FAMILIES.items() if which in d]
            raise KeyError(
                f"no {'float' if which == 'P' else 'int'} record family {family!r}; "
                f"known: {', '.join(known)}"
            ) from None
        try:
            f = fields[name]
        except KeyError:
            raise KeyError(
                f"{family} records have no {'float' if which == 'P' else 'int'} field "
                f"{name!r}; known fields: {', '.join(fields)}"
            ) from None
        n = int(self.I[count])
        if not -n <= i < n:
            raise IndexError(f"{family} record {i} out of range ({n} records)")
        return int(self.I[off]) + (i % n) * size + f

    def mover_balance(self, m: int, q: float) -> tuple[float, float]:
        """``(load, dL/dq)`` of dancer ``m`` (linear or pivot) at coordinate ``q``: the
        kernel's generalised actuator + spring + torque + gravity force (N, or N m for a pivot
        arm: cylinder force times its moment arm, torsion spring, torque motor, gravity of arm
        and roller) and the sum of its two spans' length derivatives, the lever of their
        tensions (m for a pivot). At rest with both spans at tension T: ``T = load / (dL/dq)``."""
        kind = int(self.field("mover", m, "KIND"))
        if kind == MoverKind.FESTOON:
            raise ValueError(f"mover {m} is a festoon carriage, not a dancer")
        mp = self.mover_p
        load = kernels.mover_load(mp, m, kind, float(q))
        _, dlu, _, dld = kernels.mover_lengths(mp, m, kind, float(q))
        return float(load), float(dlu + dld)

    def node_param(self, k: int, name: str) -> float:
        """Parameter ``name`` (a :class:`NodeP` field, e.g. ``"TEFF"``) of node ``k``."""
        return self.param("node", k, name)

    def set_node_param(self, k: int, name: str, value: float) -> None:
        """Set parameter ``name`` (a :class:`NodeP` field) of node ``k``."""
        self.set_param("node", k, name, value)

    # ---- the callbacks ------------------------------------------------------------------
    def make_rhs(self):
        """Return ``rhs(t, y, yp)`` filling yp in place (the form scikit-sundae calls)."""
        ev, I, P, W, GI, GC, GV, J1, a0 = (
            kernels.evaluate,
            self.I,
            self.P,
            self._W,
            self._GI,
            self._GC,
            self._GV,
            self._J1,
            self._aux0,
        )

        def rhs(t, y, yp):
            ev(t, y, yp, J1, int(Mode.RHS), I, P, W, GI, GC, GV, a0)

        return rhs

    def make_jac(self):
        """Return ``jac(t, y, yp, JJ)`` writing the pattern entries of the (n, n) array JJ."""
        ev, I, P, W, GI, GC, GV, a0 = (
            kernels.evaluate,
            self.I,
            self.P,
            self._W,
            self._GI,
            self._GC,
            self._GV,
            self._aux0,
        )
        ydw = np.zeros(self.n_states)

        def jac(t, y, yp, JJ):
            ev(t, y, ydw, JJ, int(Mode.JAC), I, P, W, GI, GC, GV, a0)

        return jac

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        """dy/dt at (t, y) (allocates; for analysis, not the solver path)."""
        yd = np.zeros(self.n_states)
        kernels.evaluate(
            float(t),
            np.ascontiguousarray(y, float),
            yd,
            self._J1,
            int(Mode.RHS),
            self.I,
            self.P,
            self._W,
            self._GI,
            self._GC,
            self._GV,
            self._aux0,
        )
        return yd

    def jacobian(self, t: float, y: np.ndarray) -> np.ndarray:
        """Analytic Jacobian d(dy/dt)/dy at (t, y) as a dense array."""
        n = self.n_states
        JJ = np.zeros((n, n))
        kernels.evaluate(
            float(t),
            np.ascontiguousarray(y, float),
            np.zeros(n),
            JJ,
            int(Mode.JAC),
            self.I,
            self.P,
            self._W,
            self._GI,
            self._GC,
            self._GV,
            self._aux0,
        )
        return JJ

    def linearise(self, t: float, y: np.ndarray):
        """Linearisation at (t, y): the Jacobian and its eigenvalues [1/s]."""
        A = self.jacobian(t, y)
        return A, np.linalg.eigvals(A)

    def outputs(self, t: float | np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Algebraic outputs (columns :attr:`aux_names`) for each row of a state matrix."""
        Y = np.ascontiguousarray(Y, float)
        t = np.ascontiguousarray(np.broadcast_to(t, (Y.shape[0],)), float)
        AUX = np.empty((Y.shape[0], len(self.aux_names)))
        kernels.rows(
            kernels.ROWS_OUTPUTS,
            t,
            Y,
            AUX,
            self.I,
            self.P,
            self._W,
            self._GI,
            self._GC,
            self._GV,
            np.zeros(self.n_states),
            self._J1,
        )
        return AUX

    def events(self, t, Y: np.ndarray) -> np.ndarray:
        """Event-function values at times t for each row of a state matrix (an event's
        condition holds where its value is < 0)."""
        Y = np.atleast_2d(np.ascontiguousarray(Y, float))
        t = np.ascontiguousarray(np.broadcast_to(t, (Y.shape[0],)), float)
        G = np.empty((Y.shape[0], len(self.event_kinds)))
        kernels.rows(
            kernels.ROWS_EVENTS,
            t,
            Y,
            G,
            self.I,
            self.P,
            self._W,
            self._GI,
            self._GC,
            self._GV,
            np.zeros(self.n_states),
            self._J1,
        )
        return G

    def set_segment_start(self, t0: float) -> None:
        """Tell the kernel which piece of the programme is active (see ``kernels.setpoint``)."""
        self.P[self.I[H.OFF_RT]] = t0

    def index(self, name: str) -> int:
        """Index of a state by name, e.g. ``span2.strain``."""
        return self.state_names.index(name)

    def aux_index(self, name: str) -> int:
        """Column of an algebraic output by name, e.g. ``span2.tension_N``."""
        return self.aux_names.index(name)

    def describe(self) -> str:
        """Human-readable summary of the state layout."""
        lines = [
            f"{self.n_states} states, Jacobian nnz {len(self.pattern[0])}, "
            f"band (lower {self.lband}, upper {self.uband})"
        ]
        lines += [
            f"  {i:4d}  {n} [{u}]"
            for i, (n, u) in enumerate(zip(self.state_names, self.state_units, strict=True))
        ]
        return "\n".join(lines)


def compile_line(
    line: Line,
    programme: Programme | None = None,
    faults=(),
    disturbances=(),
    pitch_variations=None,
    extra_joint_slots: int = 0,
    nominal_web=None,
    pitch_offsets=None,
) -> CompiledLine:
    """Compile a validated line.

    Parameters
    ----------
    line : Line
    programme : Programme, optional
        Set-point tables; default: constant set-points (line speed 0, the controllers'
        tension set-points).
    faults : sequence of r2rsim.schema.faults.Fault, optional
        The scenario's faults: they reserve parameter slots, splice-joint slots (a modulus
        change) and an angle state for each eccentric roller.
    disturbances : sequence of DisturbanceInstance, optional
        The run's realised process disturbances
        (:func:`r2rsim.compile.disturbances.realise_disturbances`).
    pitch_variations : dict, optional
        The run's realised relaxed-pitch variations
        (:func:`r2rsim.compile.disturbances.realise_pitch_variations`); a sensor declaring
        one that is missing here gets the realisation of seed 0 (for analysis and tests).
    extra_joint_slots : int
        Splice-joint slots for the web of varied rolls
        (:func:`r2rsim.compile.variability.joint_slots_needed`).
    nominal_web : Web, optional
        The web the line's controllers are calibrated for (a tension_pi reading a pitch
        sensor converts pitch to tension with its E·S); default ``line.web``. With process
        variability, ``line.web`` is the first roll's drawn web and this the declared one.
    pitch_offsets : dict, optional
        Sensor id -> relaxed-pitch offset [m] of the first roll's web (process variability,
        :class:`r2rsim.compile.variability.RollDraws`); the rolls spliced later bring theirs.

    Returns
    -------
    CompiledLine
    """
    prog = programme or Programme.constant(line)
    pk = _Packer(line, prog, faults, disturbances, extra_joint_slots, nominal_web, pitch_offsets)
    for k, e in enumerate(line.elements):  # states in web order: element, then its span
        pk.element(k, e)
        pk.element_controllers(k, e)
        pk.element_sensors(k, e)
        if k < pk.nS:
            pk.span(k)
    ev_I, ev_kinds, ev_comp = pk.events()
    aux_names, aux_units = pk.outputs()
    I, P = pk.pack(ev_I, len(aux_names), pitch_variations)
    cl = CompiledLine(
        line=line,
        programme=prog,
        I=I,
        P=P,
        n_states=len(pk.names),
        state_names=pk.names,
        state_units=pk.units,
        state_kinds=pk.kinds,
        atol=np.array(pk.atol),
        aux_names=aux_names,
        aux_units=aux_units,
        event_kinds=ev_kinds,
        event_components=ev_comp,
        node_ids=[e.id for e in line.elements],
        span_ids=pk.span_ids,
        sensors=pk.sensors,
        controllers=pk.ctrls,
        mover_ids=pk.mover_ids,
        mover_q0=pk.mover_q0,
        splice_nodes=pk.splice_nodes,
        n_joint_slots=pk.nJ,
    )
    assert (
        len(aux_names)
        == AUX_SPAN * pk.nS
        + AUX_NODE * pk.nN
        + AUX_SENS * pk.nSe
        + AUX_CTRL * pk.nC
        + AUX_MOVER * pk.nM
        + AUX_JOINT * pk.nJ
        + 2
        + (len(prog.names) - 1)
    )
    _attach_pattern(cl)
    return cl


class _Packer:
    """The integer (I) and float (P) records of a line's elements, spans, sensors,
    controllers and movers, and its states in web order, filled element by element by
    :func:`compile_line`; :meth:`pack` lays them out for the kernels (layout.py)."""

    def __init__(
        self,
        line: Line,
        prog: Programme,
        faults,
        disturbances,
        extra_joint_slots: int,
        nominal_web,
        pitch_offsets,
    ):
        self.line, self.prog = line, prog
        self.faults, self.disturbances = faults, disturbances
        self.web = line.web
        self.EA = self.web.EA
        self.els = els = line.elements
        self.nN, self.nS = len(els), len(line.spans)
        self.sensors = list(line.sensors)
        self.ctrls = list(line.controllers)
        self.nSe, self.nC = len(self.sensors), len(self.ctrls)
        self.sens_idx = {s.id: j for j, s in enumerate(self.sensors)}
        self.node_idx = {e.id: k for k, e in enumerate(els)}
        self.channel = {name: ch for ch, name in enumerate(prog.names)}
        self.nominal_web, self.pitch_offsets = nominal_web, pitch_offsets

        self.names: list[str] = []
        self.units: list[str] = []
        self.kinds: list[str] = []
        self.atol: list[float] = []

        self.node_I = np.full((self.nN, N_NODE_I), -1, np.int64)
        self.node_P = np.zeros((self.nN, N_NODE_P))
        self.span_I = np.full((self.nS, N_SPAN_I), -1, np.int64)
        self.span_P = np.zeros((self.nS, N_SPAN_P))
        self.sens_I = np.full((max(self.nSe, 0), N_SENSOR_I), -1, np.int64)
        self.sens_P = np.zeros((max(self.nSe, 0), N_SENSOR_P))
        self.ctrl_I = np.full((max(self.nC, 0), N_CTRL_I), -1, np.int64)
        self.ctrl_P = np.zeros((max(self.nC, 0), N_CTRL_P))
        self.ctrl_P[:, CtrlP.GATE] = 1.0  # loops are on (a splice gates the dancer loop off)

        self.speed_of = {c.element: j for j, c in enumerate(self.ctrls) if c.type == "speed_pi"}
        self.tens_of = {c.element: j for j, c in enumerate(self.ctrls) if c.type == "tension_pi"}

        # movers: dancers (on a node) and festoon carriages (on a span)
        # Span.id is optional in the file; Line's validator names every span (span1, ...)
        self.span_ids = cast(list[str], [sp.id for sp in line.spans])
        self.mover_ids = [e.id for e in els if kind_of(e).is_mover] + [
            sp.id for sp in line.spans if sp.festoon is not None
        ]
        self.nM = len(self.mover_ids)
        self.mover_idx = {m: i for i, m in enumerate(self.mover_ids)}
        self.mov_I = np.full((self.nM, N_MOVER_I), -1, np.int64)
        self.mov_P = np.zeros((self.nM, N_MOVER_P))
        self.mover_q0 = [0.0] * self.nM
        self.splice_nodes = [
            k for k, e in enumerate(els) if getattr(e, "splicer", None) is not None
        ]
        n_modulus = sum(f.type == "process.modulus_change" for f in faults)
        self.nJ = (N_JOINT_SLOTS if self.splice_nodes else 0) + n_modulus + extra_joint_slots
        self.nFS = len(faults)
        self.eccentric = {f.target for f in faults if f.type == "process.eccentricity"} | {
            d.element for d in disturbances if d.type == "out_of_round"
        }
        self.pitch_filters: list = []
        self.pitch_var_terms: list = []  # (sensor index, sensor) with a relaxed-pitch variation

    # ---- states ------------------------------------------------------------------------------
    def add(self, name, unit, kind, tol) -> int:
        """A new state (its index)."""
        self.names.append(name)
        self.units.append(unit)
        self.kinds.append(kind)
        self.atol.append(tol)
        return len(self.names) - 1

    def add_mover(self, mid, kind, k_node, span_u, span_d, mp, q0, unit):
        """A dancer or festoon carriage, then its position loops and position sensors,
        which sit next to it (keeps the band narrow)."""
        m = self.mover_idx[mid]
        self.mov_P[m] = mp
        self.mov_P[m, MoverP.LOADF] = self.mov_P[m, MoverP.FRICF] = 1.0
        self.mover_q0[m] = q0
        mi = self.mov_I[m]
        mi[MoverI.NODE] = k_node
        mi[MoverI.SPAN_U], mi[MoverI.SPAN_D] = span_u, span_d
        tol = 1e-7 if unit == "m" else 1e-6
        mi[MoverI.Q] = self.add(f"{mid}.position", unit, "mover", tol)
        mi[MoverI.QD] = self.add(f"{mid}.velocity", f"{unit}/s", "mover", 10 * tol)
        mi[MoverI.KIND] = kind
        for j, c in enumerate(self.ctrls):
            if c.type == "dancer_pi" and c.dancer == mid:
                self._dancer_loop(j, c, m, k_node, span_u, q0)
        for j, sn in enumerate(self.sensors):
            if sn.type == "dancer_position" and sn.element == mid:
                self.sens_I[j, SensorI.TYPE] = SensorKind.DANCER
                self.sens_I[j, SensorI.NODE] = m
                (
                    self.sens_P[j, SensorP.GAIN],
                    self.sens_P[j, SensorP.OFF],
                    self.sens_P[j, SensorP.TAU],
                ) = (
                    sn.gain,
                    sn.offset,
                    sn.filter,
                )
                if sn.filter > 0:
                    self.sens_I[j, SensorI.F] = self.add(
                        f"{sn.id}.filtered", unit, "sensor_filter", tol
                    )

    def _dancer_loop(self, j, c, m, k_node, span_u, q0):
        ci, cp = self.ctrl_I[j], self.ctrl_P[j]
        ci[CtrlI.TYPE] = CtrlKind.DANCER
        ci[CtrlI.NODE] = self.node_idx[c.element]
        ci[CtrlI.MOVER] = m
        ci[CtrlI.SENSOR] = self.sens_idx[c.sensor] if c.sensor else -1
        cp[CtrlP.KP], cp[CtrlP.KI] = c.kp, c.ki
        cp[CtrlP.KAW] = (
            c.anti_windup_gain
            if c.anti_windup_gain is not None
            else (c.ki / c.kp if c.kp > 0 else 1.0)
        )
        cp[CtrlP.LIM] = c.output_limit if c.output_limit is not None else math.inf
        cp[CtrlP.SETP] = c.setpoint if c.setpoint is not None else q0
        cp[CtrlP.GATE] = 1.0
        # storage grows with q where sum(dL/dq) > 0; a short dancer speeds an
        # upstream element up or slows a downstream one
        grow = _storage_slope(self.mov_P[m], self.mov_I[m, MoverI.KIND], q0)
        upstream = ci[CtrlI.NODE] <= (k_node - 1 if k_node >= 0 else span_u)
        cp[CtrlP.SIGN] = math.copysign(1.0, grow) * (1.0 if upstream else -1.0)
        if c.ki > 0:
            ci[CtrlI.X] = self.add(f"{c.id}.integral", "", "controller", 1e-8 / c.ki)

    # ---- element by element ------------------------------------------------------------------
    def element(self, k, e):
        """Element k's record, its states (roll lengths, speed, angle, drive torque) and,
        for a dancer, its mover."""
        f, kind = e.friction, kind_of(e)
        ni, npr = self.node_I[k], self.node_P[k]
        npr[NodeP.VGAIN] = 1.0
        npr[NodeP.TEFF] = npr[NodeP.FRICF] = 1.0
        npr[NodeP.WRAP] = e.wrap_angle if e.wrap_angle is not None else math.pi
        for d in self.disturbances:
            if d.type == "out_of_round" and d.element == e.id:
                npr[NodeP.ECC] = d.eccentricity
        ni[NodeI.KIND] = NodeKind[kind.node_kind]
        drive = getattr(e, "drive", None)
        ni[NodeI.DRIVE] = (
            DriveKind.NONE
            if drive is None
            else (DriveKind.IDEAL if drive.type == "ideal_speed" else DriveKind.TORQUE)
        )
        ni[NodeI.SPAN_UP] = k - 1 if k > 0 else -1
        ni[NodeI.SPAN_DN] = k if k < self.nN - 1 else -1
        ni[NodeI.SPEEDC] = self.speed_of.get(e.id, -1)
        ni[NodeI.TENSC] = self.tens_of.get(e.id, -1)
        ni[NodeI.DRAWCH] = self.channel.get(f"draw:{e.id}", -1)
        ni[NodeI.TQCH] = self.channel.get(f"torque:{e.id}", -1)
        npr[NodeP.B], npr[NodeP.TC], npr[NodeP.WEPS] = f.viscous, f.coulomb, f.smoothing_speed
        npr[NodeP.TMAX] = math.inf
        if drive is not None:
            npr[NodeP.TLAG] = drive.torque_lag
            npr[NodeP.TMAX] = drive.torque_max if drive.torque_max is not None else math.inf
            npr[NodeP.DRAW] = drive.draw
            if drive.torque_ripple is not None:
                npr[NodeP.RIPA] = drive.torque_ripple.amplitude
                npr[NodeP.RIPW] = 2.0 * math.pi * drive.torque_ripple.frequency
        if e.wrap_angle is not None and e.friction_coefficient is not None:
            npr[NodeP.EMB] = math.exp(e.friction_coefficient * e.wrap_angle)
        # the kind's own fields (radius, inertia, a roll's geometry) after the common ones
        kind.pack_node(e, _Fields(npr, NodeP, "node"), self.web)
        for slot, name, unit, state_kind, atol in kind.states(e):  # e.g. a roll's lengths
            ni[NodeI[slot]] = self.add(f"{e.id}.{name}", unit, state_kind, atol)
        if ni[NodeI.DRIVE] != DriveKind.IDEAL:
            ni[NodeI.W] = self.add(f"{e.id}.speed", "rad/s", "speed", 1e-6)
        if e.id in self.eccentric:
            ni[NodeI.TH] = self.add(f"{e.id}.angle", "rad", "angle", 1e-6)
        if ni[NodeI.DRIVE] == DriveKind.TORQUE and drive.torque_lag > 0:
            ni[NodeI.TAU] = self.add(f"{e.id}.drive_torque", "N*m", "torque", 1e-4)
        if kind.is_mover:
            mp, mover_kind, q0, unit = _dancer_record(self.line, k)
            self.add_mover(e.id, mover_kind, k, k - 1, k, mp, q0, unit)
            ni[NodeI.MOVER] = self.mover_idx[e.id]

    def element_controllers(self, k, e):
        """The speed and tension loops acting on element k (dancer loops sit with their
        dancer)."""
        for j, c in enumerate(self.ctrls):
            if c.element != e.id or c.type == "dancer_pi":
                continue
            ci, cp = self.ctrl_I[j], self.ctrl_P[j]
            ci[CtrlI.NODE] = k
            cp[CtrlP.KP], cp[CtrlP.KI] = c.kp, c.ki
            cp[CtrlP.KAW] = (
                c.anti_windup_gain
                if c.anti_windup_gain is not None
                else (c.ki / c.kp if c.kp > 0 else 1.0)
            )
            cp[CtrlP.LIM] = math.inf
            if c.type == "speed_pi":
                ci[CtrlI.TYPE] = CtrlKind.SPEED
                ci[CtrlI.SENSOR] = self.sens_idx[c.encoder] if c.encoder else -1
                cp[CtrlP.DRAW] = c.draw
                cp[CtrlP.FF] = 1.0 if c.torque_feedforward else 0.0
                out_tol = 1e-4  # N m
            else:
                out_tol = self._tension_loop(k, e, c, ci, cp)
            if c.ki > 0:
                ci[CtrlI.X] = self.add(f"{c.id}.integral", "", "controller", out_tol / c.ki)

    def _tension_loop(self, k, e, c, ci, cp) -> float:
        """A tension loop's record; returns the tolerance of its output."""
        roll = kind_of(e).is_roll
        ci[CtrlI.TYPE] = (
            CtrlKind.TENSION_TORQUE
            if (roll and e.drive.type == "torque")
            else CtrlKind.TENSION_TRIM
        )
        ci[CtrlI.SENSOR] = self.sens_idx[c.sensor]
        ci[CtrlI.RSENSOR] = self.sens_idx[c.radius_sensor] if c.radius_sensor else -1
        ci[CtrlI.CH] = self.channel[c.id]
        cp[CtrlP.LIM] = c.output_limit if c.output_limit is not None else math.inf
        ff = c.feedforward
        cp[CtrlP.FF] = 1.0 if ff.tension else 0.0
        if ff.inertia.value is not None:
            cp[CtrlP.JABS] = ff.inertia.value
        else:
            cp[CtrlP.JFAC] = ff.inertia.factor
        cp[CtrlP.RR] = 1.0 if ff.radius_rate else 0.0
        cp[CtrlP.FRF] = 1.0 if ff.friction else 0.0
        # a trim raises the tension of a span upstream of the node, lowers one downstream
        sm = self.sensors[self.sens_idx[c.sensor]]
        meas = (
            self.span_ids.index(sm.span) + 1
            if sm.type == "pitch_length"
            else self.node_idx[sm.element]
        )
        cp[CtrlP.SIGN] = 1.0 if meas <= k else -1.0
        return 1e-4 if ci[CtrlI.TYPE] == CtrlKind.TENSION_TORQUE else 1e-8

    def element_sensors(self, k, e):
        """The load cells, encoders and diameter sensors on element k."""
        for j, s in enumerate(self.sensors):
            if getattr(s, "element", None) != e.id or s.type == "dancer_position":
                continue
            si, sp = self.sens_I[j], self.sens_P[j]
            si[SensorI.NODE] = k
            sp[SensorP.GAIN], sp[SensorP.OFF], sp[SensorP.TAU] = s.gain, s.offset, s.filter
            if s.type == "load_cell":
                si[SensorI.TYPE] = SensorKind.LOADCELL
                cin, cout = load_cell_weights(self.line, k, s)  # > 0 in sum: checked at load
                sp[SensorP.CIN], sp[SensorP.COUT] = cin, cout
                sp[SensorP.WIN], sp[SensorP.WOUT] = cin / (cin + cout), cout / (cin + cout)
                unit, tol = "N", 1e-4
            elif s.type == "encoder":
                si[SensorI.TYPE] = SensorKind.ENCODER
                unit, tol = "rad/s", 1e-6
            else:
                si[SensorI.TYPE] = SensorKind.DIAMETER
                unit, tol = "m", 1e-8
            if s.filter > 0:
                si[SensorI.F] = self.add(f"{s.id}.filtered", unit, "sensor_filter", tol)

    def span(self, k):
        """Span k (after element k): its festoon, pitch sensors and strain state."""
        line = self.line
        sp_k = line.spans[k]
        si_ = self.span_I[k]
        si_[SpanI.UP], si_[SpanI.DN] = k, k + 1
        fe = sp_k.festoon
        if fe is not None:
            mp = np.zeros(N_MOVER_P)
            mp[MoverP.MASS] = fe.carriage_mass
            mp[MoverP.QMIN], mp[MoverP.QMAX] = fe.stroke
            mp[MoverP.C], mp[MoverP.FC], mp[MoverP.EPS] = fe.damping, fe.coulomb, fe.smoothing_speed
            mp[MoverP.F0] = fe.carriage_mass * fe.gravity
            mp[MoverP.FAIR] = fe.force
            mp[MoverP.NSTR] = 2.0 * fe.moving_rollers
            self.add_mover(sp_k.id, MoverKind.FESTOON, -1, k, -1, mp, fe.initial_position, "m")
            si_[SpanI.MOVER] = self.mover_idx[sp_k.id]
        self.span_P[k, SpanP.L] = sp_k.length or 0.0
        for j, sn in enumerate(self.sensors):
            if sn.type == "pitch_length" and sn.span == sp_k.id:
                self._pitch_sensor(j, sn, k)
        self.span_P[k, SpanP.EA] = self.EA
        self.span_P[k, SpanP.TBRK] = self.web.break_tension
        # strain tolerance ~1e-4 N of tension (physics.md 1.2, solver.md 6)
        si_[SpanI.E] = self.add(f"{sp_k.id}.strain", "", "strain", 1e-4 / self.EA)
        for j, sn in self.pitch_filters:
            if sn.filter > 0:
                self.sens_I[j, SensorI.F] = self.add(
                    f"{sn.id}.filtered", "m", "sensor_filter", 1e-9
                )
        self.pitch_filters.clear()

    def _pitch_sensor(self, j, sn, k):
        si, sp = self.sens_I[j], self.sens_P[j]
        si[SensorI.TYPE], si[SensorI.NODE] = SensorKind.PITCH, k
        sp[SensorP.GAIN], sp[SensorP.OFF], sp[SensorP.TAU] = sn.gain, sn.offset, sn.filter
        # the loop's Hooke calibration: the declared web, not a drawn roll's
        sp[SensorP.COUT] = self.EA if self.nominal_web is None else self.nominal_web.EA
        law = sn.relaxed_pitch_law
        dl0 = (self.pitch_offsets or {}).get(sn.id)
        sp[SensorP.DL0] = dl0 or 0.0
        if law is None and sn.pitch_variation is None and dl0 is None:
            sp[SensorP.CIN] = sn.relaxed_pitch
        else:  # L0 = q0 + q1·R³ (+ variation) of an unwind's radius
            sp[SensorP.CIN] = sn.relaxed_pitch if law is None else law.q0
            sp[SensorP.Q1] = 0.0 if law is None else law.q1
            si[SensorI.RNODE] = self.node_idx[pitch_unwind(self.line, sn)]
            si[SensorI.VN] = 0
            if sn.pitch_variation is not None:
                self.pitch_var_terms.append((j, sn))
        self.pitch_filters.append((j, sn))

    # ---- the whole line ----------------------------------------------------------------------
    def events(self) -> tuple[list, list, list]:
        """(kind, index) of every event the kernels watch, with kinds and components:
        slack and break per span, capstan per monitored interior roller, empty unwind,
        splice radius, mover stops, splice joints, dancer refill."""
        ev_I: list[tuple[int, int]] = []
        ev_comp: list[str] = []

        def ev(kind, index, component):
            ev_I.append((kind, index))
            ev_comp.append(component)

        for i, sp in enumerate(self.line.spans):
            ev(EventKind.SLACK, i, sp.id)
            if math.isfinite(self.web.break_tension):
                ev(EventKind.BREAK, i, sp.id)
        for k, e in enumerate(self.els):
            if 0 < k < self.nN - 1 and self.node_P[k, NodeP.EMB] > 0:
                ev(EventKind.CAPSTAN, k, e.id)
            if kind_of(e).pays_out:
                ev(EventKind.EMPTY, k, e.id)
            if k in self.splice_nodes:
                ev(EventKind.SPLICE_RADIUS, k, e.id)
        for m, mid in enumerate(self.mover_ids):
            for kind in (EventKind.STOP_LO, EventKind.STOP_HI):
                ev(kind, m, mid)
        for js in range(self.nJ):
            for kind in (EventKind.JOINT_PASS, EventKind.JOINT_BREAK):
                ev(kind, js, f"splice_joint{js + 1}")
        for j, c in enumerate(self.ctrls):
            if c.type == "dancer_pi" and self.node_idx[c.element] in self.splice_nodes:
                ev(EventKind.REFILL, j, c.element)
        return ev_I, [k for k, _ in ev_I], ev_comp

    def outputs(self) -> tuple[list[str], list[str]]:
        """Names and units of the algebraic outputs, in the kernels' order."""
        names, units = [], []
        for sp in self.line.spans:
            names += [f"{sp.id}.tension_N", f"{sp.id}.geometric_strain", f"{sp.id}.length_m"]
            units += ["N", "1", "m"]
        for e in self.els:
            names += [
                f"{e.id}.surface_speed_m_s",
                f"{e.id}.speed_rad_s",
                f"{e.id}.radius_m",
                f"{e.id}.inertia_kg_m2",
                f"{e.id}.web_mass_kg",
                f"{e.id}.torque_N_m",
                f"{e.id}.torque_command_N_m",
                f"{e.id}.tension_ratio",
            ]
            units += ["m/s", "rad/s", "m", "kg*m^2", "kg", "N*m", "N*m", "1"]
        mover_unit = {
            mid: self.units[self.mov_I[m, MoverI.Q]] for m, mid in enumerate(self.mover_ids)
        }
        for s in self.sensors:
            u = {
                "load_cell": "N",
                "encoder": "rad_s",
                "roll_diameter": "m",
                "pitch_length": "m",
                "dancer_position": mover_unit.get(getattr(s, "element", ""), "m"),
            }[s.type]
            q = {
                "load_cell": "tension",
                "encoder": "speed",
                "roll_diameter": "diameter",
                "dancer_position": "position",
                "pitch_length": "pitch",
            }[s.type]
            names += [f"{s.id}.{q}_{u}", f"{s.id}.{q}_seen_{u}", f"{s.id}.force_N"]
            units += [u.replace("_", "/"), u.replace("_", "/"), "N"]
        for j, c in enumerate(self.ctrls):
            if c.type == "speed_pi":
                names += [f"{c.id}.error_rad_s", f"{c.id}.output_N_m", f"{c.id}.integral"]
                units += ["rad/s", "N*m", "rad"]
            elif c.type == "dancer_pi":
                u = mover_unit.get(c.dancer, "m")
                names += [f"{c.id}.error_{u}", f"{c.id}.output_m_s", f"{c.id}.integral"]
                units += [u, "m/s", f"{u}*s"]
            else:
                out_u = "N" if self.ctrl_I[j, CtrlI.TYPE] == CtrlKind.TENSION_TORQUE else "m_s"
                names += [f"{c.id}.error_N", f"{c.id}.output_{out_u}", f"{c.id}.integral"]
                units += ["N", out_u.replace("_", "/"), "N*s"]
        for mid in self.mover_ids:
            u = mover_unit[mid]
            f_u = "N" if u == "m" else "N_m"
            names += [
                f"{mid}.position_{u}",
                f"{mid}.velocity_{u}_s",
                f"{mid}.web_force_{f_u}",
                f"{mid}.static_force_{f_u}",
                f"{mid}.stop_state",
            ]
            units += [u, f"{u}/s", f_u.replace("_", "*"), f_u.replace("_", "*"), "1"]
        for js in range(self.nJ):
            names += [f"splice_joint{js + 1}.lead_m", f"splice_joint{js + 1}.span_index"]
            units += ["m", "1"]
        names += ["setpoint.line_speed_m_s", "setpoint.line_acceleration_m_s2"]
        units += ["m/s", "m/s^2"]
        for name in self.prog.names[1:]:
            kind, _, eid = name.rpartition(":")
            if kind == "torque":
                names.append(f"setpoint.{eid}.torque_N_m")
                units.append("N*m")
            elif kind == "draw":
                names.append(f"setpoint.{eid}.draw")
                units.append("1")
            else:
                names.append(f"setpoint.{name}.tension_N")
                units.append("N")
        return names, units

    def _programme_tables(self):
        """The set-point tables, padded with +inf times (room for an e-stop ramp)."""
        prog = self.prog
        nch = len(prog.names)
        maxpts = max(len(t) for t in prog.times) + 4
        sch_n = np.array([len(t) for t in prog.times], np.int64)
        sch_t = np.zeros((nch, maxpts))
        sch_v = np.zeros((nch, maxpts))
        for ch in range(nch):
            sch_t[ch, : sch_n[ch]] = prog.times[ch]
            sch_v[ch, : sch_n[ch]] = prog.values[ch]
            sch_t[ch, sch_n[ch] :] = math.inf
        return nch, maxpts, sch_n, sch_t, sch_v

    def _disturbance_tables(self):
        """The bearing-drag and wound-in-strain disturbances: records and values."""
        tables = [d for d in self.disturbances if d.type in ("bearing_drag", "wound_in_strain")]
        tab_I = np.zeros((len(tables), N_TABLE_I), np.int64)
        tab_P = []
        for m, d in enumerate(tables):
            kind = {"bearing_drag": TableKind.DRAG, "wound_in_strain": TableKind.WOUND}[d.type]
            if d.shape == "sines":
                tab_I[m] = (kind, self.node_idx[d.element], len(d.amplitudes), 0, Shape.SINES)
                tab_P.append(np.concatenate([d.amplitudes, d.omegas, d.phases]))
            else:
                tab_I[m] = (kind, self.node_idx[d.element], len(d.values), 0, Shape.TABLE)
                tab_P.append(np.concatenate([[d.x0, d.dx], d.values]))
        return tab_I, tab_P

    def _pitch_variation_terms(self, pitch_variations) -> list[np.ndarray]:
        """The relaxed-pitch variations' terms, sensor by sensor (a missing one: seed 0's)."""
        pitch_variations = pitch_variations or {}
        out = []
        for j, sn in self.pitch_var_terms:
            terms = pitch_variations.get(sn.id)
            if terms is None:
                terms = realise_pitch_variations(self.line, np.random.SeedSequence(0))[sn.id]
            self.sens_I[j, SensorI.VN] = len(terms)
            out.append(np.ascontiguousarray(terms, float).ravel())
        return out

    def pack(self, ev_I, n_aux: int, pitch_variations) -> tuple[np.ndarray, np.ndarray]:
        """The header and the record blocks as the kernels' I (int64) and P (float64)."""
        nch, maxpts, sch_n, sch_t, sch_v = self._programme_tables()
        tab_I, tab_P = self._disturbance_tables()
        blocks_I = [
            self.node_I.ravel(),
            self.span_I.ravel(),
            self.sens_I.ravel(),
            self.ctrl_I.ravel(),
            sch_n,
            np.array(ev_I, np.int64).reshape(-1, N_EVENT_I).ravel(),
            self.mov_I.ravel(),
            tab_I.ravel(),
        ]
        offs_I, pos = [], HEADER
        for b in blocks_I:
            offs_I.append(pos)
            pos += b.size
        var_P = self._pitch_variation_terms(pitch_variations)
        nJ, nFS = self.nJ, self.nFS
        blocks_P = [
            self.node_P.ravel(),
            self.span_P.ravel(),
            self.sens_P.ravel(),
            self.ctrl_P.ravel(),
            sch_t.ravel(),
            sch_v.ravel(),
            np.zeros(4),
            self.mov_P.ravel(),
            np.zeros(nJ * N_JOINT_P),
            np.array([self.EA]),
            np.zeros(nFS * N_FAULT_P),
            *tab_P,
            *var_P,
        ]
        offs_P, ppos = [], 0
        for b in blocks_P:
            offs_P.append(ppos)
            ppos += b.size
        P = np.concatenate(blocks_P)
        header = np.zeros(HEADER, np.int64)
        header[H.NN], header[H.NS], header[H.NSE], header[H.NC], header[H.NY] = (
            self.nN,
            self.nS,
            self.nSe,
            self.nC,
            len(self.names),
        )
        header[H.OFF_NI], header[H.OFF_SI], header[H.OFF_SEI], header[H.OFF_CI] = offs_I[:4]
        header[H.OFF_SCHN], header[H.OFF_EV] = offs_I[4], offs_I[5]
        header[H.OFF_NP], header[H.OFF_SP], header[H.OFF_SEP], header[H.OFF_CP] = offs_P[:4]
        header[H.OFF_SCHT], header[H.OFF_SCHV], header[H.OFF_RT] = offs_P[4:7]
        header[H.NM], header[H.OFF_MI], header[H.OFF_MP] = self.nM, offs_I[6], offs_P[7]
        header[H.NJ], header[H.OFF_JP], header[H.EA] = nJ, offs_P[8], offs_P[9]
        header[H.NFS], header[H.OFF_FS] = nFS, offs_P[10]
        header[H.NTB], header[H.OFF_TB] = len(tab_P), offs_I[7]
        for m in range(len(tab_P)):  # each table's values follow the fault slots in P
            tab_I[m, TableI.OFFP] = offs_P[11 + m]
        blocks_I[7] = tab_I.ravel()
        for m, (j, _) in enumerate(self.pitch_var_terms):  # the variations follow the tables
            self.sens_I[j, SensorI.VOFF] = offs_P[11 + len(tab_P) + m]
        blocks_I[2] = self.sens_I.ravel()
        header[H.MODEL] = 1 if self.line.span_model == "linear" else 0
        header[H.NCH], header[H.MAXPTS] = nch, maxpts
        header[H.NQ], header[H.MAXD] = 3 * self.nS + 7 * self.nN + 2 * self.nSe + 2 * self.nC, MAXD
        header[H.NAUX] = n_aux
        header[H.NEV] = len(ev_I)
        return np.concatenate([header] + blocks_I), P


def _attach_pattern(cl: CompiledLine) -> None:
    """Mark the Jacobian pattern with the kernel (Mode.TOUCH) and store it in I."""
    n = cl.n_states
    touch = np.zeros((n, n))
    y = np.zeros(n)
    kernels.evaluate(
        0.0,
        y,
        np.zeros(n),
        touch,
        int(Mode.TOUCH),
        cl.I,
        cl.P,
        cl._W,
        cl._GI,
        cl._GC,
        cl._GV,
        cl._aux0,
    )
    rows, cols = np.nonzero(touch)
    cl.pattern = (rows.astype(np.int64), cols.astype(np.int64))
    cl.lband = int(max(0, (rows - cols).max(initial=0)))
    cl.uband = int(max(0, (cols - rows).max(initial=0)))
    cl.I[H.NPAT] = len(rows)
    cl.I[H.OFF_PAT] = len(cl.I)
    cl.I = np.concatenate([cl.I, cl.pattern[0], cl.pattern[1]])


def _dancer_record(line: Line, k: int):
    """Mover parameters of the dancer at element k: (record, mover kind, initial q, unit of
    q). The neighbours, the span offsets and the friction here; the rest is the kind's."""
    e, kind = line.elements[k], kind_of(line.elements[k])
    a, b = line.elements[k - 1], line.elements[k + 1]
    mp = np.zeros(N_MOVER_P)
    mp[MoverP.DU], mp[MoverP.DD] = dancer_offsets(line, k)
    mp[MoverP.AX], mp[MoverP.AY] = a.position
    mp[MoverP.BX], mp[MoverP.BY] = b.position
    mp[MoverP.EPS] = e.smoothing_speed
    mp[MoverP.C], mp[MoverP.FC] = e.damping, e.coulomb
    kind.pack_mover(e, _Fields(mp, MoverP, "mover"))
    q0 = kind.mover_start(e)
    # reference directions of the two spans at the initial position: there L = free length
    # (the roller clears its neighbours over its whole range: checked at load)
    mp[MoverP.TUX], mp[MoverP.TUY], mp[MoverP.TDX], mp[MoverP.TDY] = 1.0, 0.0, 1.0, 0.0
    tu, td = _tangents(mp, dancer_centre(e, q0))
    mp[MoverP.TUX], mp[MoverP.TUY] = tu
    mp[MoverP.TDX], mp[MoverP.TDY] = td
    assert kind.mover_kind is not None  # a mover kind names its MoverKind
    return mp, MoverKind[kind.mover_kind], q0, kind.coordinate_unit


class _Fields:
    """A record row addressed by field name, for the element kinds' packing hooks: the
    schema stage cannot import this layout, so a kind writes ``node["R"] = r`` and this
    writes ``row[NodeP.R]``."""

    def __init__(self, row: np.ndarray, fields: type[IntEnum], record: str):
        self._row, self._fields, self._record = row, fields, record

    def __setitem__(self, name: str, value: float) -> None:
        try:
            index = self._fields[name]
        except KeyError:
            raise KeyError(
                f"the {self._record} record has no field {name!r}; fields: "
                f"{', '.join(self._fields.__members__)}"
            ) from None
        self._row[index] = value


def _tangents(mp, centre):
    """Unit vectors of travel along the upstream and downstream spans, the dancer roller at
    ``centre``."""
    cx, cy = centre
    out = []
    for ax, ay, bx, by, delta in (
        (mp[MoverP.AX], mp[MoverP.AY], cx, cy, mp[MoverP.DU]),
        (cx, cy, mp[MoverP.BX], mp[MoverP.BY], mp[MoverP.DD]),
    ):
        dx, dy = bx - ax, by - ay
        d2 = dx * dx + dy * dy
        lam = math.sqrt(d2 - delta * delta)
        out.append(((lam * dx + delta * dy) / d2, (lam * dy - delta * dx) / d2))
    return out


def _storage_slope(mp, kind, q):
    """d(stored length)/dq of a mover at q (sum over its spans)."""
    if kind == MoverKind.FESTOON:
        return mp[MoverP.NSTR]
    _, dlu, _, dld = kernels.mover_lengths(mp.reshape(1, -1), 0, int(kind), q)  # one record
    return dlu + dld
