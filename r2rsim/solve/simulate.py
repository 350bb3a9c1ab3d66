"""Integrate a compiled line: segments between programme breakpoints, chunks of dense output,
events detected on the solver's steps and located exactly with root-finding.

The integrators themselves are behind :class:`r2rsim.solve.backends.SolverBackend` (one
module each in :mod:`r2rsim.solve.backends`); this module is the event loop that drives them.

Why events this way: scikit-sundae calls a Python event function after every step, which
doubles the cost of a BDF2 run (solver.md §4.5). Instead the event functions are evaluated by
a numba kernel on the output samples; only when a condition changes between two samples is
that one interval integrated again with root-finding, from the earlier sample, to find the
time and state of the event. A condition that starts and ends between two samples (shorter
than the sample period) is not seen; the record rate sets the event resolution.
"""

from __future__ import annotations

import math
import time as _time
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..compile.compiler import EVENT_LABELS, CompiledLine
from ..errors import InputError
from ..limits import run_size_problem
from ..schema.scenario import SolverOptions
from .backends import Root, SolverBackend, backend_class, make_backend
from .compilewatch import compile_seconds
from .discrete import MODE_EVENTS, DiscreteLogic, Event

#: event kinds by name (``cl.kind("event", m)``)
TERMINAL = {"BREAK", "EMPTY"}
PHYSICAL = {"SLACK", "BREAK", "CAPSTAN", "EMPTY"}


SolverSettings = SolverOptions
"""Integrator settings: the scenario's ``solver:`` block (validated), usable on its own."""


def describe_settings(s: SolverOptions) -> str:
    """One line naming the integrator and its settings (for logs and runs.parquet)."""
    return backend_class(s.backend).describe(s)


@dataclass
class SimulationResult:
    """What a run produced. Arrays are kept only when no chunk callback consumed them.

    Attributes
    ----------
    t : ndarray (n,)
        Sample times [s].
    states : ndarray (n, n_states)
    outputs : ndarray (n, n_aux)
        Algebraic outputs, columns ``compiled.aux_names``.
    events : list of Event
    terminated : bool
        The run ended before its duration (web break, roll empty, solver failure).
    termination_reason, termination_time
    stats : dict
        ``nfev`` (right-hand-side evaluations), ``njev``, ``restarts``, ``wall_s``,
        ``steps``; with the radau5 backend also ``nlu`` (LU factorisations) and
        ``step_limits`` (per state, the accepted steps whose largest scaled error estimate
        was that state's).
    initial_state_mode : str
        ``steady`` or ``nominal`` (what was actually used).
    """

    compiled: CompiledLine
    t: np.ndarray
    states: np.ndarray
    outputs: np.ndarray
    events: list[Event]
    terminated: bool
    termination_reason: str | None
    termination_time: float | None
    stats: dict
    duration: float
    initial_state_mode: str
    y0: np.ndarray

    def __getitem__(self, name: str) -> np.ndarray:
        """A state or algebraic output by name, e.g. ``res["span1.tension_N"]``."""
        cl = self.compiled
        if name in cl.aux_names:
            return self.outputs[:, cl.aux_index(name)]
        if name in cl.state_names:
            return self.states[:, cl.index(name)]
        raise KeyError(f"no output or state named {name!r}")

    def frame(self):
        """The outputs as a pandas DataFrame indexed by time."""
        import pandas as pd

        df = pd.DataFrame(self.outputs, columns=self.compiled.aux_names)
        df.insert(0, "t_s", self.t)
        return df


ChunkCallback = Callable[[np.ndarray, np.ndarray, np.ndarray], None]


def _message(cl: CompiledLine, kind: str, comp: str, on: bool, aux: np.ndarray) -> tuple:
    """Event state label, message and values for the log."""
    if kind == "SLACK":
        return ("start" if on else "end", f"{comp} {'goes slack' if on else 'is taut again'}", {})
    if kind == "BREAK":
        T = aux[cl.aux_index(f"{comp}.tension_N")]
        return "start", f"web break in {comp} at {T:.1f} N", {"tension_N": float(T)}
    if kind == "CAPSTAN":
        ratio = aux[cl.aux_index(f"{comp}.tension_ratio")]
        return (
            "start" if on else "end",
            f"{comp} {'reaches' if on else 'leaves'} its capstan limit (T_hi/T_lo = {ratio:.4f})",
            {"tension_ratio": float(ratio)},
        )
    if kind == "EMPTY":
        return "start", f"{comp} roll is empty (core reached)", {}
    return "", "", {}


def simulate(
    cl: CompiledLine,
    duration: float,
    record_rate: float = 1000.0,
    y0: np.ndarray | None = None,
    settings: SolverSettings | None = None,
    on_chunk: ChunkCallback | None = None,
    progress: Callable[[float], None] | None = None,
    initial_state_mode: str = "given",
    outputs: bool = True,
    events=(),
    faults=(),
    rolls=None,
) -> SimulationResult:
    """Integrate a compiled line over ``[0, duration]`` and sample it at ``record_rate``.

    Parameters
    ----------
    cl : CompiledLine
    duration : float
        Simulated time [s].
    record_rate : float
        Output sample rate [Hz]; also the resolution of event detection.
    y0 : ndarray, optional
        Initial state (default: :func:`r2rsim.solve.initial.nominal_state`).
    settings : SolverSettings, optional
    on_chunk : callable, optional
        ``on_chunk(t, states, outputs)`` receives the samples chunk by chunk; the result then
        holds no arrays (memory stays flat in run length).
    progress : callable, optional
        Called with the simulated time reached.
    outputs : bool
        Compute the algebraic outputs (tensions, speeds, torques, ...) of every sample. With
        False, ``on_chunk`` receives ``None`` for them and the result holds states only.
    events : list of ScenarioEvent
        Scheduled discrete events (splice, e-stop, dancer seize); see
        :class:`r2rsim.solve.discrete.DiscreteLogic`.
    faults : list of FaultInstance
        The run's faults (:func:`r2rsim.compile.faults.realise_faults`); those acting inside
        the loop change the sensor readings the controllers see.
    rolls : RollDraws, optional
        The run's roll variability (:func:`r2rsim.compile.variability.realise_variability`):
        the rolls splices load.

    Returns
    -------
    SimulationResult
    """
    from .initial import nominal_state

    s = settings or SolverSettings()
    size = run_size_problem(duration, record_rate)  # before any array is sized by them
    if size is not None:
        raise InputError(size[1], path=size[0])
    wall0 = _time.perf_counter()
    if y0 is None:
        y0 = nominal_state(cl)
        initial_state_mode = "nominal"
    y0 = np.array(y0, dtype=float)
    backend = make_backend(cl, s)
    backend.record_outputs = outputs
    dt = 1.0 / record_rate
    n_samples = int(math.floor(duration * record_rate + 1e-9)) + 1
    sample_t = np.arange(n_samples) * dt
    # the discrete logic changes modes and parameters in place; the compiled line is put
    # back as it was when the run ends, so it can be run again
    saved = (
        cl.I.copy(),
        cl.P.copy(),
        [list(v) for v in cl.programme.times],
        [list(v) for v in cl.programme.values],
    )
    try:
        return _run(
            cl,
            duration,
            record_rate,
            y0,
            s,
            on_chunk,
            progress,
            initial_state_mode,
            outputs,
            events,
            faults,
            backend,
            sample_t,
            wall0,
            rolls,
        )
    finally:
        cl.I[:], cl.P[:] = saved[0], saved[1]
        cl.programme.times, cl.programme.values = saved[2], saved[3]


def _run(
    cl,
    duration,
    record_rate,
    y0,
    s,
    on_chunk,
    progress,
    initial_state_mode,
    outputs,
    events,
    faults,
    backend,
    sample_t,
    wall0,
    rolls=None,
):
    keep = on_chunk is None
    kept_t, kept_y, kept_a = [], [], []

    def emit(t, Y, A=None):
        # A: the outputs the backend evaluated with the samples (Chunk.aux), else None
        if len(t) == 0:
            return
        if not outputs:
            A = None
        elif A is None:
            A = cl.outputs(t, Y)
        if keep:
            kept_t.append(t.copy())
            kept_y.append(Y.copy())
            kept_a.append(A)
        else:
            on_chunk(t, Y, A)

    loop = _EventLoop(
        cl,
        DiscreteLogic(cl, events, faults, duration, rolls),
        duration,
        s,
        backend,
        sample_t,
        emit,
        progress,
        wall0,
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        loop.run(y0)
    T_all, Y_all, A_all = _kept(cl, kept_t, kept_y, kept_a, keep, outputs)
    wall = _time.perf_counter() - wall0
    stats = {
        "nfev": backend.nfev,
        "njev": backend.njev,
        "restarts": loop.restarts,
        "wall_s": wall,
        "steps": backend.steps if backend.reports_steps else None,
        # LU factorisations and, per state, the accepted steps it limited (the largest
        # scaled error estimate): reported by the compiled Radau IIA, None otherwise
        "nlu": getattr(backend, "nlu", None),
        "step_limits": getattr(backend, "step_limits", None),
        "solver": describe_settings(s),
        "n_samples": int(loop.k_next),
        "solver_messages": list(backend.messages)[:20],
    }
    return SimulationResult(
        cl,
        T_all,
        Y_all,
        A_all,
        loop.log,
        loop.terminated,
        loop.reason,
        loop.t_term,
        stats,
        duration,
        initial_state_mode,
        y0,
    )


class _EventLoop:
    """Integration from discrete change to discrete change: chunks of samples between the
    programme's breakpoints and the discrete logic's times, events found on the solver's
    steps (or by the backend's root finding when "hot") and fired, samples emitted in order.

    Event detection is normally on the solver's steps after each chunk (cheap, but the part
    of the chunk after an event is integrated again). After a discrete change or an event
    more events tend to follow (a splice joint crossing nodes, a dancer at its stops), so the
    next chunks use the backend's root finding, which stops at the event ("hot"; CVODE's,
    see :meth:`SolverBackend.locates_events`; radau5 always locates events in its kernel).
    """

    def __init__(
        self, cl, logic, duration, s, backend: SolverBackend, sample_t, emit, progress, wall0
    ):
        self.cl, self.logic, self.duration, self.s = cl, logic, duration, s
        self.backend, self.sample_t, self.emit, self.progress = backend, sample_t, emit, progress
        self.wall0 = wall0
        self.step_budget = s.max_steps_per_s * max(duration, 1.0)
        self.compile0 = compile_seconds()
        self.prog_breaks = sorted(b for b in cl.programme.breakpoints if 0.0 < b < duration)
        self.rows_per_chunk = max(
            16, int(s.chunk_memory_mb * 1e6 / 8 / max(cl.n_states + len(cl.aux_names), 1))
        )
        self.mode_idx = np.array(
            [m for m in range(len(cl.event_kinds)) if cl.kind("event", m) in MODE_EVENTS], int
        )
        self.log: list[Event] = []
        self.t = 0.0
        self.y: np.ndarray  # the state and the event conditions (g < 0): set by run
        self.flags: np.ndarray
        self.k_next = 0  # next sample index to emit
        self.terminated = False
        self.reason: str | None = None
        self.t_term: float | None = None
        self.restarts = 0
        self.aux: np.ndarray | None = None  # the current chunk's outputs (Chunk.aux)
        self.hot = False
        self.resume = False  # the last chunk ended at a memory boundary only: continue

    def run(self, y0) -> None:
        cl, logic = self.cl, self.logic
        cl.set_segment_start(0.0)
        self.y, entries = logic.apply_due(0.0, y0.copy())
        self.log.extend(entries)
        self.flags = cl.events(0.0, self.y)[0] < 0 if len(cl.event_kinds) else np.zeros(0, bool)
        self.t = 0.0
        y_start = self.y.copy()
        if _broken_at_start(cl, self.y, self.flags, self.log):
            self.k_next = _emit_samples(
                self.emit, self.sample_t, self.k_next, np.array([0.0]), self.y[None, :]
            )
            self.terminated, self.reason, self.t_term = True, EVENT_LABELS["BREAK"], 0.0
        while self.t < self.duration - 1e-12 and not self.terminated:
            if logic.next_time() <= self.t + 1e-12 and not self._apply_due():
                break
            event = self._chunk()
            if event is not None:
                self._fire_at(*event)
        if self.k_next == 0:  # ended (or too short) before its first sample: record t = 0
            self.k_next = _emit_samples(
                self.emit, self.sample_t, 0, np.array([0.0]), y_start[None, :]
            )

    def _aux(self, rows):
        """The current chunk's outputs at ``rows`` (None when the backend gave none)."""
        return None if self.aux is None else self.aux[rows]

    def _refresh_mode_flags(self, t, y, flags):
        # after a discrete change the mode events' functions mean something new: re-read
        # them (a value exactly at 0 keeps the flag it had)
        if len(self.mode_idx):
            g = self.cl.events(t, y)[0]
            for m in self.mode_idx:
                if g[m] != 0.0:
                    flags[m] = g[m] < 0
        return flags

    def _apply_due(self) -> bool:
        """The discrete logic's changes due now; False when they end the run."""
        self.y, entries = self.logic.apply_due(self.t, self.y)
        self.log.extend(entries)
        if self.logic.terminate_reason is not None:
            self.terminated, self.reason, self.t_term = True, self.logic.terminate_reason, self.t
            return False
        self.flags = self._refresh_mode_flags(self.t, self.y, self.flags)
        self.hot = True
        self.resume = False
        return True

    def _chunk(self):
        """Integrate the next chunk of samples up to the segment's end. Returns None when
        the chunk ends without an event (its samples emitted, or the run ended), else the
        event to fire: (t_ev, y_ev, which, tt, Y)."""
        t, logic = self.t, self.logic
        bps = [b for b in (*self.prog_breaks, *logic.extra_breakpoints()) if b > t + 1e-12]
        t_seg_end = min([*bps, logic.next_time(), self.duration])
        self.cl.set_segment_start(t)
        # samples in [t, t_seg_end]; a sample on a segment's end belongs to the next
        # segment: it sees the discrete change made there (a fault acts from its onset on)
        k_end = int(
            np.searchsorted(
                self.sample_t,
                t_seg_end + (1e-9 if t_seg_end >= self.duration else -1e-9),
                side="right",
            )
        )
        k_hi = min(k_end, self.k_next + self.rows_per_chunk)
        tspan = _chunk_times(t, self.sample_t, self.k_next, k_hi, k_end, t_seg_end)
        chunk = self.backend.advance(tspan, self.y, find_events=self.hot, resume=self.resume)
        self.aux = chunk.aux
        self.resume = False
        self.restarts += 1
        err = chunk.failure
        if err is None:
            err = _over_budget(
                self.s,
                self.backend.steps,
                self.step_budget,
                self.wall0,
                chunk.t_steps,
                compile_seconds() - self.compile0,
            )
        if err is not None:
            self.k_next = _emit_samples(
                self.emit, self.sample_t, self.k_next, chunk.t, chunk.y, k_end, chunk.aux
            )
            self.terminated, self.reason = True, f"solver_failure: {err}"
            self.t_term = float(chunk.t_steps[-1]) if len(chunk.t_steps) else t
            return None
        if chunk.root is not None:  # the backend stopped at a root
            return self._at_root(chunk.root, chunk.t, chunk.y)
        return self._on_steps(chunk.t, chunk.y, chunk.t_steps, chunk.y_steps, k_hi, k_end)

    def _at_root(self, root: Root, tt, Y):
        """The backend stopped at a root: the events whose condition turns, or None (and the
        samples before it emitted) when the function touched 0 and turned back."""
        t_ev, y_ev, dirs = root
        # a falling event function makes the condition (g < 0) true
        which = np.array([m for m in np.nonzero(dirs)[0] if (dirs[m] < 0) != self.flags[m]], int)
        if len(which):
            return t_ev, y_ev, which, tt, Y
        before = tt < t_ev - 1e-12
        self.k_next = _emit_samples(
            self.emit, self.sample_t, self.k_next, tt[before], Y[before], None, self._aux(before)
        )
        if t_ev <= self.t + 1e-12:  # stuck on a root at the start: step past it
            self.hot = False
        self.t, self.y = t_ev, y_ev.copy()
        return None

    def _on_steps(self, tt, Y, ts, ys, k_hi, k_end):
        """Event detection at the solver's steps (as CVODE's own root finding does): the
        first event located exactly, or None with the chunk's samples emitted."""
        cl, backend = self.cl, self.backend
        hit = (
            _event_on_steps(cl, self.flags, ts, ys)
            if len(cl.event_kinds) and not backend.locates_events(self.hot)
            else None
        )
        if hit is None:
            self.k_next = _emit_samples(
                self.emit, self.sample_t, self.k_next, tt, Y, k_end, self.aux
            )
            self.t, self.y = float(tt[-1]), Y[-1].copy()
            self.resume = k_hi < k_end and not self.hot
            self.hot = False
            if self.progress:
                self.progress(self.t)
            return None
        # an event between steps hit_row-1 and hit_row: locate it exactly from the earlier
        # step
        hit_row, cond = hit
        r0 = hit_row - 1
        found = backend.locate(float(ts[r0]), ys[r0].copy(), float(ts[hit_row]))
        if found is None:  # no root seen by the backend (g grazing 0): take the step
            t_ev, y_ev = float(ts[hit_row]), ys[hit_row].copy()
            which = np.nonzero(cond[hit_row] != self.flags)[0]
        else:  # only the events found at this root flip; others seen from here on
            t_ev, y_ev, which = found
            which = np.array([m for m in which if cond[hit_row, m] != self.flags[m]] or which)
        return t_ev, y_ev, which, tt, Y

    def _fire_at(self, t_ev, y_ev, which, tt, Y) -> None:
        """Emit the samples before the event, flip the conditions of ``which`` and let the
        discrete logic act on them."""
        self.hot = True
        before = tt < t_ev - 1e-12
        self.k_next = _emit_samples(
            self.emit, self.sample_t, self.k_next, tt[before], Y[before], None, self._aux(before)
        )
        new_flags = self.flags.copy()
        new_flags[which] = ~self.flags[which]
        y_ev, ended = _fire(self.cl, self.logic, self.log, which, new_flags, t_ev, y_ev)
        if ended is not None:
            self.terminated, self.reason, self.t_term = True, ended, t_ev
        self.flags = self._refresh_mode_flags(t_ev, y_ev, new_flags)
        if self.terminated:
            return
        self.t, self.y = t_ev, y_ev
        if self.progress:
            self.progress(self.t)


def _broken_at_start(cl, y, flags, log: list) -> bool:
    """Log a break for every span above its break tension at t = 0; True if any.

    A span that starts above its break tension breaks at once. Events are found as sign
    changes of their functions, and its break condition is true from t = 0 on, so no change
    would ever report it (a 20 kN start on a 10.5 kN web ran on, and later logged "web
    break" when the tension fell through the limit)."""
    broken = [m for m in np.nonzero(flags)[0] if cl.kind("event", m) == "BREAK"]
    if broken:
        aux0 = cl.outputs(np.array([0.0]), y[None, :])[0]
        for m in broken:
            state, msg, vals = _message(cl, "BREAK", cl.event_components[m], True, aux0)
            log.append(
                Event(
                    0.0,
                    EVENT_LABELS["BREAK"],
                    cl.event_components[m],
                    state,
                    msg + " (above the break tension from the start)",
                    vals,
                )
            )
    return bool(broken)


def _chunk_times(
    t: float, sample_t, k_next: int, k_hi: int, k_end: int, t_seg_end: float
) -> np.ndarray:
    """The output times of the next chunk: its start ``t``, the samples after it, and the
    chunk's end (the segment's end, or the last sample at a memory boundary)."""
    t_chunk_end = t_seg_end if k_hi == k_end else float(sample_t[k_hi - 1])
    ts = sample_t[k_next:k_hi]
    tspan = np.concatenate([[t], ts[ts > t + 1e-12]])
    if tspan[-1] < t_chunk_end - 1e-12:
        tspan = np.append(tspan, t_chunk_end)
    if len(tspan) < 3:  # scikit-sundae: 2 points means "every step"; pad
        tspan = np.array([t, 0.5 * (t + tspan[-1]), tspan[-1]])
    return tspan


def _event_on_steps(cl, flags, ts, ys):
    """Event detection at the solver's steps (as CVODE's own root finding does): the first
    step where a condition differs from the step before, with every step's conditions, or
    None."""
    cond = cl.events(ts, ys) < 0
    # the first row is the chunk's start, whose conditions are known (after an event it
    # sits on a root, where the sign of g is not meaningful)
    cond[0] = flags
    prev = np.vstack([flags[None, :], cond[:-1]])
    changed = np.nonzero(np.any(cond != prev, axis=1))[0]
    return (int(changed[0]), cond) if len(changed) else None


def _fire(cl, logic, log: list, which, new_flags, t_ev: float, y_ev):
    """Act on the events ``which`` at t_ev: log the physical ones, hand the others to the
    discrete logic. Returns the state after them and the reason the run ends, or None."""
    aux_ev = cl.outputs(np.array([t_ev]), y_ev[None, :])[0]
    y_ev = y_ev.copy()
    ended = None
    for m in which:
        kind = cl.kind("event", m)
        comp = cl.event_components[m]
        if kind in PHYSICAL:
            state, msg, vals = _message(cl, kind, comp, bool(new_flags[m]), aux_ev)
            log.append(Event(t_ev, EVENT_LABELS[kind], comp, state, msg, vals))
            if kind in TERMINAL and new_flags[m]:
                ended = EVENT_LABELS[kind]
            continue
        y_ev, entries, _ = logic.on_event(int(m), bool(new_flags[m]), t_ev, y_ev)
        log.extend(entries)
        if logic.terminate_reason is not None:
            ended = logic.terminate_reason
    return y_ev, ended


def _kept(cl, kept_t, kept_y, kept_a, keep: bool, outputs: bool):
    """The kept samples as arrays (empty when they went to a chunk callback)."""
    if keep and kept_t:
        T_all = np.concatenate(kept_t)
        Y_all = np.concatenate(kept_y)
        A_all = np.concatenate(kept_a) if outputs else np.zeros((len(T_all), 0))
        return T_all, Y_all, A_all
    return np.zeros(0), np.zeros((0, cl.n_states)), np.zeros((0, len(cl.aux_names)))


def _over_budget(
    s: SolverSettings,
    steps: int | None,
    step_budget: float,
    wall0: float,
    ts: np.ndarray,
    compiled_s: float,
) -> str | None:
    """Why the run must stop now (its step or wall-clock budget is spent), or None. The
    wall-clock budget does not count ``compiled_s``, numba compiling (a cold cache)."""
    t = float(ts[-1]) if ts is not None and len(ts) else 0.0
    if steps is not None and steps > step_budget:
        return (
            f"step budget: {steps} steps by t = {t:.6g} s (solver.max_steps_per_s x "
            f"duration = {step_budget:.3g})"
        )
    if s.max_wall_s is not None and _time.perf_counter() - wall0 > s.max_wall_s + compiled_s:
        return f"wall-clock budget: solver.max_wall_s = {s.max_wall_s:g} s spent by t = {t:.6g} s"
    return None


def _emit_samples(emit, sample_t, k_next, tt, Y, k_stop=None, A=None) -> int:
    """Emit the rows of (tt, Y) (and of their outputs A, when the backend evaluated them)
    that fall on the sample grid from index k_next on (and before index k_stop)."""
    if len(tt) == 0:
        return k_next
    idx = np.searchsorted(sample_t, tt - 1e-9)
    ok = (
        (idx < (len(sample_t) if k_stop is None else k_stop))
        & (np.abs(sample_t[np.minimum(idx, len(sample_t) - 1)] - tt) < 1e-9)
        & (idx >= k_next)
    )
    if np.any(ok):
        emit(tt[ok], Y[ok], None if A is None else A[ok])
        return int(idx[ok][-1]) + 1
    return k_next
