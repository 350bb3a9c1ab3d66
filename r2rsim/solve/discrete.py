"""Discrete behaviour of a line: what happens at an event or a scheduled time.

The ODE right-hand side is smooth between discrete changes; every change of equations or
parameters (dancer latched at an end stop, roll swap, splice phase, e-stop ramp, dancer
seized) is made here, between two solver segments, and the integrator restarts from the new
state (physics.md §1.11). Mode flags live in the compiled parameter vector, so the kernel
sees them without any Python in the right-hand side.

A zero-speed splice (physics.md §1.7) runs as scheduled phases:
``fill`` (unwind at overspeed, dancer loop on hold) → ``brake`` (unwind speed reference
ramps to 0) → ``dwell`` (roll at rest) → ``swap`` (new roll, joint injected) +
``accelerate`` → ``refill`` (overspeed until the dancer/festoon is back at its set-point) →
``complete`` (dancer loop resumes, integrator restored: bumpless). A flying splice swaps at
once, with the new roll turning at v·(1 + δ)/R_new.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field

import numpy as np

from ..compile.compiler import EVENT_LABELS, CompiledLine
from ..compile.faults import loop_sensor_ids

#: joint length of new material that runs until the next roll change
OPEN_JOINT = 1e9  # m: longer than any roll

#: events whose handling changes the model (their flags are recomputed after a change)
#: (by kind name, as ``cl.kind("event", m)`` gives it)
MODE_EVENTS = {"STOP_LO", "STOP_HI", "JOINT_PASS", "SPLICE_RADIUS", "REFILL"}


@dataclass(order=True)
class _Action:
    t: float
    seq: int
    kind: str = field(compare=False)
    target: int = field(compare=False, default=-1)
    data: dict = field(compare=False, default_factory=dict)


@dataclass
class Event:
    """One entry of the event log (physical events and discrete changes alike)."""

    t: float
    kind: str
    component: str
    state: str
    message: str
    values: dict = field(default_factory=dict)


class DiscreteLogic:
    """Scheduled actions and event handlers of one run.

    Parameters
    ----------
    cl : CompiledLine
    events : list of ScenarioEvent
        The scenario's scheduled events (``splice``, ``e_stop``, ``dancer_seize``).
    faults : list of FaultInstance
        The run's faults; those acting inside the simulation get an action at every
        breakpoint of their profile.
    duration : float
        Length of the run [s] (bounds the breakpoints of an intermittent fault).
    """

    def __init__(
        self, cl: CompiledLine, events=(), faults=(), duration: float = math.inf, rolls=None
    ):
        self.cl = cl
        self.rolls = rolls  # RollDraws: the varied rolls a splice loads (None: the spare)
        self.line = cl.line
        # unwind node -> (E·A ratio, relaxed-pitch offset or None) of the material it pays
        # out, while that differs from the first roll's (a material joint is open)
        self._material: dict[int, tuple[float, float | None]] = {}
        self._queue: list[_Action] = []
        self._seq = 0
        self.splicing: dict[int, str] = {}  # unwind node -> phase
        self._saved_integral: dict[int, float] = {}
        self.terminate_reason: str | None = None
        self._breakpoints: list[float] = []
        self._sensor_faults: dict[int, list] = {}
        self._param_faults: dict[int, list] = {}  # P index -> faults
        self._slot: dict[int, int] = {}  # P index -> slot
        self._base: dict[int, float] = {}
        self._weak_splice: dict[int, float] = {}  # unwind node -> joint break tension
        self._schedule_sensor_faults(faults, duration)
        self._schedule_model_faults(faults, duration)
        # scheduled events after the faults: a fault at the time of an event acts on it
        # (a weak splice at the splice time makes that joint weak)
        self._schedule_events(events)

    def _schedule_sensor_faults(self, faults, duration: float) -> None:
        """Faults acting inside the loop: an action at each breakpoint of their profiles
        resets the target sensor's fault coefficients (the solver restarts there)."""
        sensor_idx = {s.id: j for j, s in enumerate(self.cl.sensors)}
        in_loop = loop_sensor_ids(self.cl.line)
        for f in faults:
            if (
                f.kind.acts != "loop"
                or f.kind.target != "sensor"
                or f.target not in in_loop
                or f.record_only
            ):
                continue
            j = sensor_idx[f.target]
            self._sensor_faults.setdefault(j, []).append(f)
            for tb in f.breakpoints(duration):
                self._push(tb, "sensor_fault", j)

    def _schedule_model_faults(self, faults, duration: float) -> None:
        """Faults that change the model: parameters through slots (one per parameter), or
        discrete changes (stuck drive or dancer, new material, weak splice)."""
        cl = self.cl
        for f in faults:
            if f.kind.acts != "model":
                continue
            spec = self._parameter_of(f)
            if spec is None:
                kind = f.type.split(".", 1)[1]
                for tb in f.breakpoints(duration):
                    self._push(tb, kind, -1, {"fault": f})
                continue
            idx, _ = spec
            if f.type == "process.eccentricity" and f"{f.target}.angle" not in cl.state_names:
                raise ValueError(
                    f"fault '{f.id}': compile the line with its faults "
                    "(compile_line(line, programme, faults)) for the angle state"
                )
            if idx not in self._slot:
                if len(self._slot) >= cl.header("NFS"):
                    raise ValueError(
                        f"fault '{f.id}': no parameter slot left; compile the "
                        "line with its faults (compile_line(..., faults=...))"
                    )
                self._slot[idx] = len(self._slot)
                self._base[idx] = float(cl.P[idx])
            self._param_faults.setdefault(idx, []).append(f)
            for tb in f.breakpoints(duration):
                self._push(tb, "param_fault", idx)

    def _schedule_events(self, events) -> None:
        """The scenario's scheduled events: splices, e-stops, dancer seizures."""
        node_idx = {nid: k for k, nid in enumerate(self.cl.node_ids)}
        mover_idx = {mid: m for m, mid in enumerate(self.cl.mover_ids)}
        for ev in events:
            if ev.type == "splice":
                k = node_idx[ev.element] if ev.element else self.cl.splice_nodes[0]
                self._push(ev.at, "splice", k)
            elif ev.type == "e_stop":
                self._push(ev.at, "e_stop", -1, {"decel": ev.deceleration})
            elif ev.type == "dancer_seize":
                self._push(ev.at, "seize", mover_idx[ev.element])

    # ---- queue ----------------------------------------------------------------------------
    def _push(self, t, kind, target=-1, data=None):
        self._seq += 1
        heapq.heappush(self._queue, _Action(float(t), self._seq, kind, target, data or {}))

    def next_time(self) -> float:
        """Time of the next scheduled action (inf when none)."""
        return self._queue[0].t if self._queue else math.inf

    def extra_breakpoints(self) -> list[float]:
        """Set-point breakpoints added at run time (e-stop ramp end)."""
        return list(self._breakpoints)

    # ---- parameter access -------------------------------------------------------------------
    def _np(self, k, f):
        return self.cl.param_index("node", k, f)

    def _ni(self, k, f):
        return self.cl.field("node", k, f)

    def _ctrls_on(self, k, types):
        for c in range(len(self.cl.controllers)):
            if self.cl.field("ctrl", c, "NODE") == k and self.cl.kind("ctrl", c) in types:
                yield c

    # ---- scheduled actions ------------------------------------------------------------------
    def apply_due(self, t: float, y: np.ndarray) -> tuple[np.ndarray, list[Event]]:
        """Apply every action scheduled at or before t."""
        log: list[Event] = []
        while self._queue and self._queue[0].t <= t + 1e-12:
            a = heapq.heappop(self._queue)
            y = getattr(self, f"_do_{a.kind}")(t, y, a, log)
        return y, log

    def _do_splice(self, t, y, a, log):
        k = a.target
        if k in self.splicing:
            log.append(
                Event(
                    t,
                    "splice",
                    self.cl.node_ids[k],
                    "ignored",
                    "splice requested while one is in progress",
                )
            )
            return y
        sp = self.line.elements[k].splicer
        if sp.type == "flying":
            self.splicing[k] = "swap"
            y = self._swap(t, y, k, log, flying=True)
            del self.splicing[k]
            return y
        self.splicing[k] = "fill"
        P = self.cl.P
        P[self._np(k, "VGAIN")] = 1.0 + sp.fill_overspeed
        for c in self._dancer_loops(k):
            ix = int(self.cl.field("ctrl", c, "X"))
            self._saved_integral[c] = float(y[ix]) if ix >= 0 else 0.0
            self.cl.set_param("ctrl", c, "GATE", 0.0)
        log.append(self._phase(t, k, "fill", f"fill: unwind at +{sp.fill_overspeed:.0%} speed"))
        self._push(t + sp.fill_time, "brake", k)
        return y

    def _do_brake(self, t, y, a, log):
        k = a.target
        if self.splicing.get(k) != "fill":
            return y
        sp = self.line.elements[k].splicer
        v0 = self._reference_speed(t, k)
        self._set_ref(k, gain=0.0, off=v0, slope=-sp.brake_decel, t0=t)
        self.splicing[k] = "brake"
        log.append(self._phase(t, k, "brake", f"brake: unwind from {v0:.3g} m/s to rest"))
        self._push(t + max(v0, 0.0) / sp.brake_decel, "dwell", k)
        return y

    def _do_dwell(self, t, y, a, log):
        k = a.target
        if self.splicing.get(k) != "brake":
            return y
        self._set_ref(k, gain=0.0, off=0.0, slope=0.0, t0=t)
        self.splicing[k] = "dwell"
        log.append(self._phase(t, k, "dwell", "dwell: roll at rest, splicing"))
        self._push(t + self.line.elements[k].splicer.dwell, "accelerate", k)
        return y

    def _do_accelerate(self, t, y, a, log):
        k = a.target
        if self.splicing.get(k) != "dwell":
            return y
        sp = self.line.elements[k].splicer
        y = self._swap(t, y, k, log, flying=False)
        target = self._line_speed(t, k) * (1.0 + sp.fill_overspeed)
        self._set_ref(k, gain=0.0, off=0.0, slope=sp.accel, t0=t)
        self.splicing[k] = "accelerate"
        log.append(self._phase(t, k, "accelerate", f"accelerate the new roll to {target:.3g} m/s"))
        self._push(t + target / sp.accel, "refill", k)
        return y

    def _do_refill(self, t, y, a, log):
        k = a.target
        if self.splicing.get(k) != "accelerate":
            return y
        sp = self.line.elements[k].splicer
        self._set_ref(k, gain=1.0 + sp.fill_overspeed, off=0.0, slope=0.0, t0=t)
        for c in self._dancer_loops(k):
            self.cl.set_param("ctrl", c, "GATE", -1.0)  # armed: refill event
        self.splicing[k] = "refill"
        log.append(self._phase(t, k, "refill", "refill the dancer/festoon"))
        self._push(t + sp.refill_timeout, "complete", k, {"timeout": True})
        return y

    def _do_complete(self, t, y, a, log):
        k = a.target
        if self.splicing.get(k) != "refill":
            return y
        return self._complete(t, y, k, log, timeout=a.data.get("timeout", False))

    def _complete(self, t, y, k, log, timeout=False):
        self._set_ref(k, gain=1.0, off=0.0, slope=0.0, t0=t)
        for c in self._dancer_loops(k):
            self.cl.set_param("ctrl", c, "GATE", 1.0)
            ix = int(self.cl.field("ctrl", c, "X"))
            if ix >= 0:
                y[ix] = self._saved_integral.get(c, 0.0)
        del self.splicing[k]
        log.append(
            self._phase(
                t, k, "complete", "splice complete" + (" (refill timed out)" if timeout else "")
            )
        )
        return y

    def _do_e_stop(self, t, y, a, log):
        decel = a.data["decel"]
        v = self._line_speed(t, -1)
        cl = self.cl
        I, P = cl.I, cl.P
        # set-point channel 0 (line speed): its point count in I, its times and values in P
        mx = cl.header("MAXPTS")
        n = int(I[cl.header("OFF_SCHN")])
        bt, bv = cl.header("OFF_SCHT"), cl.header("OFF_SCHV")
        keep = [m for m in range(n) if P[bt + m] <= t]
        times = [float(P[bt + m]) for m in keep] + [t, t + v / decel]
        vals = [float(P[bv + m]) for m in keep] + [v, 0.0]
        if len(times) > mx:
            times, vals = times[-mx:], vals[-mx:]
        P[bt : bt + mx] = math.inf
        P[bt : bt + len(times)] = times
        P[bv : bv + len(vals)] = vals
        I[cl.header("OFF_SCHN")] = len(times)
        self.cl.programme.times[0], self.cl.programme.values[0] = times, vals
        self._breakpoints = [*self._breakpoints, t, t + v / decel]
        for k in list(self.splicing):  # an e-stop aborts a splice sequence
            self._set_ref(k, gain=1.0, off=0.0, slope=0.0, t0=t)
            for c in self._dancer_loops(k):
                self.cl.set_param("ctrl", c, "GATE", 1.0)
            del self.splicing[k]
        log.append(
            Event(
                t,
                "e_stop",
                "line",
                "start",
                f"e-stop: line speed {v:.3g} m/s -> 0 at {decel:g} m/s^2",
                {"deceleration_m_s2": decel},
            )
        )
        self._push(t + v / decel, "stopped")
        return y

    def _do_stopped(self, t, y, a, log):
        log.append(Event(t, "e_stop", "line", "end", "line at rest after e-stop"))
        return y

    def _do_seize(self, t, y, a, log):
        return self._seize(t, y, a.target, log, "")

    def _seize(self, t, y, m, log, why):
        """Mover m seizes where it is: q' = 0 and held (mover field "MODE" 2)."""
        self.cl.set_param("mover", m, "MODE", 2.0)
        y[self.cl.field("mover", m, "QD")] = 0.0
        q = float(y[self.cl.field("mover", m, "Q")])
        mid = self.cl.mover_ids[m]
        log.append(
            Event(
                t,
                "dancer_seized",
                mid,
                "start",
                f"{mid} seizes at position {q:.4g}{why}",
                {"position": q},
            )
        )
        return y

    def _do_sensor_fault(self, t, y, a, log):
        """Re-express every in-loop fault on sensor j as coefficients from time t on."""
        j = a.target
        bias = [0.0, 0.0, 0.0, 1.0]
        gain = [0.0, 0.0, 0.0, 1.0]
        stuck = False
        for g in self._sensor_faults[j]:
            ca, cb, cc, tau = g.segment(t)
            if g.type in ("sensor.stuck", "sensor.dropout"):
                stuck = stuck or ca > 0.0
                continue
            acc = gain if g.type == "sensor.gain" else bias
            acc[0] += ca
            acc[1] += cb
            if cc != 0.0:
                acc[2] += cc
                acc[3] = tau
        cl = self.cl  # writes reach the kernel at its next evaluation
        was_stuck = cl.param("sensor", j, "STUCK") != 0.0
        if stuck and not was_stuck:  # hold the reading the controllers see now
            cl.set_param("sensor", j, "SV", self._seen(t, y, j))
        cl.set_param("sensor", j, "STUCK", 1.0 if stuck else 0.0)
        cl.set_param("sensor", j, "FT0", t)
        for name, v in zip(("BA", "BB", "BC", "BTAU"), bias, strict=True):
            cl.set_param("sensor", j, name, v)
        for name, v in zip(("GA", "GB", "GC", "GTAU"), gain, strict=True):
            cl.set_param("sensor", j, name, v)
        on = stuck or any(bias[:3]) or any(gain[:3])
        cl.set_param("sensor", j, "FON", 1.0 if on else 0.0)
        return y

    # ---- faults that change the model ----------------------------------------------------
    def _parameter_of(self, f):
        """(index in P, gain K) of a parameter fault: P = base + K·effect(t); None for the
        faults handled by a discrete action."""
        cl = self.cl
        if f.kind.target == "dancer":
            m = cl.mover_ids.index(f.target)
            field_, K = {
                "dancer.loss_of_loading": ("LOADF", -1.0),
                "dancer.friction_increase": ("FRICF", 1.0),
            }.get(f.type, (None, 0))
            return None if field_ is None else (cl.param_index("mover", m, field_), K)
        k = cl.node_ids.index(f.target)
        field_, K = {
            "actuator.bias": ("TBIAS", 1.0),
            "actuator.loss_of_effectiveness": ("TEFF", -1.0),
            "actuator.saturation": ("TMAX", 1.0),
            "process.bearing_friction": ("FRICF", 1.0),
            "process.draw_error": ("REFF", 1.0),
            "process.eccentricity": ("ECC", 1.0),
        }.get(f.type, (None, 0))
        return None if field_ is None else (self._np(k, field_), K)

    def _do_param_fault(self, t, y, a, log):
        """Re-express every fault on one parameter from time t on: P = base + A + B·dt +
        C·exp(-dt/tau); a slot lets the kernel follow a ramp or exponential."""
        idx = a.target
        P = self.cl.P
        base = self._base[idx]
        acc = [0.0, 0.0, 0.0, 1.0]
        value = None
        ecc_node = None
        for f in self._param_faults[idx]:
            ca, cb, cc, tau = f.segment(t)
            if f.type == "actuator.saturation":  # step or intermittent: the new limit
                if ca > 0.0 or (f.magnitude == 0.0 and f.p(np.array([t]))[0] > 0):
                    value = f.magnitude
                continue
            if f.type == "process.eccentricity":
                ecc_node = self.cl.node_ids.index(f.target)
            K = self._parameter_of(f)[1]
            acc[0] += K * ca
            acc[1] += K * cb
            if cc != 0.0:
                acc[2] += K * cc
                acc[3] = tau
        lengths = self._span_lengths(t, y) if ecc_node is not None else None
        P[idx] = value if value is not None else base + acc[0]
        slot = self._slot[idx]
        names = ("IDX", "BASE", "T0", "A", "B", "C", "TAU")
        for name, v in zip(names, (idx, base, t, *acc), strict=True):
            self.cl.set_param("fault", slot, name, v)
        on = (acc[1] != 0.0 or acc[2] != 0.0) and value is None
        self.cl.set_param("fault", slot, "ON", 1.0 if on else 0.0)
        if lengths is not None:
            # the roller's centre jumps by the new eccentricity: each span keeps its
            # unstretched length (mass), so its strain follows its new length
            new = self._span_lengths(t, y)
            for i, (l0, l1) in enumerate(zip(lengths, new, strict=True)):
                ie = self.cl.index(f"{self.cl.span_ids[i]}.strain")
                y[ie] = (1.0 + y[ie]) * l1 / l0 - 1.0
        return y

    def _span_lengths(self, t, y):
        cl = self.cl
        aux = cl.outputs(np.array([t]), y[None, :])[0]
        return [float(aux[cl.aux_index(f"{s}.length_m")]) for s in cl.span_ids]

    def _do_stuck(self, t, y, a, log):
        """actuator.stuck: the drive torque freezes at its value now (or thaws)."""
        f = a.data["fault"]
        k = self.cl.node_ids.index(f.target)
        on = f.p(np.array([t]))[0] > 0.0
        P = self.cl.P
        if on and P[self._np(k, "TSTUCK")] == 0.0:
            aux = self.cl.outputs(np.array([t]), y[None, :])[0]
            P[self._np(k, "TSV")] = aux[self.cl.aux_index(f"{f.target}.torque_N_m")]
        P[self._np(k, "TSTUCK")] = 1.0 if on else 0.0
        return y

    def _do_arm_stuck(self, t, y, a, log):
        """dancer.arm_stuck: the arm or carriage seizes where it is (or is freed)."""
        f = a.data["fault"]
        m = self.cl.mover_ids.index(f.target)
        if f.p(np.array([t]))[0] > 0.0:
            return self._seize(t, y, m, log, f" ({f.id})")
        if self.cl.param("mover", m, "MODE") == 2.0:
            mid = self.cl.mover_ids[m]
            q = float(y[self.cl.field("mover", m, "Q")])
            # free again; its end stops are re-detected as events
            self.cl.set_param("mover", m, "MODE", 0.0)
            log.append(
                Event(
                    t, "dancer_seized", mid, "end", f"{mid} is free again ({f.id})", {"position": q}
                )
            )
        return y

    def _do_modulus_change(self, t, y, a, log):
        """process.modulus_change: from now the unwind pays out web of modulus EA·(1 + m),
        carried as an open-ended splice joint (closed by the next roll change)."""
        f = a.data["fault"]
        if f.p(np.array([t]))[0] <= 0.0:
            return y
        k = self.cl.node_ids.index(f.target)
        ratio, dl0 = self._material.get(k, (1.0, None))
        self._open_material(
            k,
            y[self._ni(k, "U")],
            ratio * (1.0 + f.magnitude),
            f"fault '{f.id}': no splice-joint slot for the new material; "
            "compile the line with its faults (compile_line(..., faults=...))",
            dl0,
        )
        return y

    def _do_weak_splice(self, t, y, a, log):
        """process.weak_splice: the next joint made on the unwind breaks at the magnitude."""
        f = a.data["fault"]
        if f.p(np.array([t]))[0] > 0.0:
            self._weak_splice[self.cl.node_ids.index(f.target)] = f.magnitude
        return y

    def _open_material(
        self, k: int, u_now: float, ea_ratio: float, no_slot: str, dl0: float | None = None
    ) -> None:
        """From ``u_now`` the unwind at node k pays out web of E·A x ``ea_ratio`` (over the
        first roll's; a modulus change, or a new roll's web) and relaxed-pitch offset ``dl0``
        [m] (None: that of the first roll): an open-ended joint, closed by the next roll
        change. Raises ValueError(``no_slot``) when every joint slot is taken."""
        slot = self._free_joint_slot()
        if slot is None:
            raise ValueError(no_slot)
        self._material[k] = (ea_ratio, dl0)
        self.cl.set_param("joint", slot, "ACTIVE", 1.0)
        self.cl.set_param("joint", slot, "MAT", 1.0)
        self.cl.set_param("joint", slot, "DL0", self._first_dl0(k) if dl0 is None else dl0)
        self.cl.set_param("joint", slot, "U0", u_now)
        self.cl.set_param("joint", slot, "LEN", OPEN_JOINT)
        self.cl.set_param("joint", slot, "RATIO", ea_ratio)
        # no joint to break: the web's own break applies
        self.cl.set_param("joint", slot, "TBRK", 1e30)
        self.cl.set_param("joint", slot, "SPAN", float(k))
        self.cl.set_param("joint", slot, "TSPAN", float(k) - 1.0)
        self.cl.set_param("joint", slot, "NODE", float(k))

    def _first_dl0(self, k: int) -> float:
        """Relaxed-pitch offset of the first roll of the unwind at node k (0: not drawn)."""
        if self.rolls is None:
            return 0.0
        return self.rolls.pitch_offset0.get(self.cl.node_ids[k], 0.0)

    def _free_joint_slot(self) -> int | None:
        for js in range(self.cl.n_joint_slots):
            if self.cl.param("joint", js, "ACTIVE") == 0.0:
                return js
        return None

    def _seen(self, t, y, j) -> float:
        """The reading sensor j delivers to the controllers at (t, y)."""
        cl = self.cl
        s = cl.sensors[j]
        name = next(n for n in cl.aux_names if n.startswith(f"{s.id}.") and "_seen_" in n)
        return float(cl.outputs(np.array([t]), y[None, :])[0][cl.aux_index(name)])

    # ---- event handlers ---------------------------------------------------------------------
    def on_event(self, m: int, on: bool, t: float, y: np.ndarray):
        """Handle a change of event m's condition. Returns (y, log entries, handled)."""
        kind = self.cl.kind("event", m)
        comp = self.cl.event_components[m]
        log: list[Event] = []
        if kind in ("STOP_LO", "STOP_HI"):
            self._on_stop(m, kind == "STOP_LO", on, t, y, comp, log)
        elif kind == "JOINT_PASS" and on:
            self._on_joint_pass(m, t, y, comp, log)
        elif kind == "JOINT_BREAK" and on:
            self._on_joint_break(m, t, y, log)
        elif kind == "SPLICE_RADIUS" and on:
            k = self._event_index(m)
            if k not in self.splicing:
                self._push(t, "splice", k)
                y, log = self.apply_due(t, y)
        elif kind == "REFILL" and on:
            c = self._event_index(m)
            k = int(self.cl.field("ctrl", c, "NODE"))
            if self.splicing.get(k) == "refill":
                y = self._complete(t, y, k, log)
        else:
            return y, log, kind in MODE_EVENTS or kind == "JOINT_BREAK"
        return y, log, True

    def _on_stop(
        self, m: int, lo: bool, on: bool, t: float, y: np.ndarray, comp: str, log: list
    ) -> None:
        """A dancer or festoon carriage reaches (on) or leaves (off) an end stop: it latches
        there at rest, then moves freely again."""
        mv = self._event_index(m)
        iq = self.cl.field("mover", mv, "Q")
        iqd = self.cl.field("mover", mv, "QD")
        kind = "STOP_LO" if lo else "STOP_HI"
        if on and self.cl.param("mover", mv, "MODE") == 0.0:
            v = float(y[iqd])
            self.cl.set_param("mover", mv, "MODE", -1.0 if lo else 1.0)
            y[iq] = self.cl.param("mover", mv, "QMIN" if lo else "QMAX")
            y[iqd] = 0.0
            log.append(
                Event(
                    t,
                    EVENT_LABELS[kind],
                    comp,
                    "start",
                    f"{comp} hits its {'lower' if lo else 'upper'} stop at {v:.3g}/s",
                    {"velocity": v},
                )
            )
        elif not on and self.cl.param("mover", mv, "MODE") in (-1.0, 1.0):
            self.cl.set_param("mover", mv, "MODE", 0.0)
            log.append(
                Event(
                    t,
                    EVENT_LABELS[kind],
                    comp,
                    "end",
                    f"{comp} leaves its {'lower' if lo else 'upper'} stop",
                )
            )

    def _on_joint_pass(self, m: int, t: float, y: np.ndarray, comp: str, log: list) -> None:
        """A splice joint's lead or trail crosses a node: it enters the next span, or has
        left the line."""
        js = self._event_index(m)
        nS = len(self.cl.span_ids)
        if self._joint_lead_crossed(js, t, y):
            self.cl.set_param("joint", js, "SPAN", self.cl.param("joint", js, "SPAN") + 1.0)
            sp = int(self.cl.param("joint", js, "SPAN"))
            if sp < nS:
                log.append(
                    Event(
                        t,
                        "splice_joint",
                        comp,
                        self.cl.span_ids[sp],
                        f"{comp} passes {self.cl.node_ids[sp]} into {self.cl.span_ids[sp]}",
                    )
                )
        else:  # the trail crossed a node: the joint has left a span
            self.cl.set_param("joint", js, "TSPAN", self.cl.param("joint", js, "TSPAN") + 1.0)
            if int(self.cl.param("joint", js, "TSPAN")) >= nS:
                self.cl.set_param("joint", js, "ACTIVE", 0.0)
                log.append(
                    Event(
                        t,
                        "splice_joint",
                        comp,
                        "end",
                        f"{comp} is wound into {self.cl.node_ids[-1]}",
                    )
                )

    def _on_joint_break(self, m: int, t: float, y: np.ndarray, log: list) -> None:
        """A weak splice joint breaks: the run ends with a web break."""
        js = self._event_index(m)
        sp = int(self.cl.param("joint", js, "SPAN"))
        span = self.cl.span_ids[sp]
        T = float(self.cl.outputs(t, y[None, :])[0][self.cl.aux_index(f"{span}.tension_N")])
        log.append(
            Event(
                t,
                "web_break",
                span,
                "start",
                f"web break at the splice joint in {span} at {T:.1f} N",
                {"tension_N": T, "at_splice_joint": True},
            )
        )
        self.terminate_reason = "web_break"

    # ---- helpers ----------------------------------------------------------------------------
    def _event_index(self, m):
        return int(self.cl.field("event", m, "INDEX"))

    def _dancer_loops(self, k):
        return list(self._ctrls_on(k, ("DANCER",)))

    def _phase(self, t, k, state, msg):
        return Event(t, "splice", self.cl.node_ids[k], state, msg)

    def _set_ref(self, k, gain, off, slope, t0):
        P = self.cl.P
        P[self._np(k, "VGAIN")] = gain
        P[self._np(k, "VOFF")] = off
        P[self._np(k, "VSLOPE")] = slope
        P[self._np(k, "VT0")] = t0

    def _line_speed(self, t, k):
        from ..compile.kernels import setpoint

        self.cl.set_segment_start(t)
        return float(setpoint(self.cl.I, self.cl.P, 0, t)[0])

    def _reference_speed(self, t, k):
        """The unwind's current speed reference without the (held) dancer trim."""
        P = self.cl.P
        draw = 0.0
        for c in self.line.controllers:
            if c.type == "speed_pi" and c.element == self.cl.node_ids[k]:
                draw = c.draw
        name = f"draw:{self.cl.node_ids[k]}"
        if name in self.cl.programme.names:  # a programmed draw
            draw = self.cl.programme.value(name, t)
        return (
            self._line_speed(t, k) * (1.0 + draw) * P[self._np(k, "VGAIN")]
            + P[self._np(k, "VOFF")]
            + P[self._np(k, "VSLOPE")] * (t - P[self._np(k, "VT0")])
        )

    def _joint_lead_crossed(self, js: int, t: float, y: np.ndarray) -> bool:
        """At a joint-pass event: True if the joint's lead reached a node, False if its
        trail did (whichever of the two is closer to its node)."""
        cl = self.cl
        aux = cl.outputs(np.array([t]), y[None, :])[0]
        ell = np.array(
            [
                aux[cl.aux_index(f"{s}.length_m")]
                / (1.0 + aux[cl.aux_index(f"{s}.geometric_strain")])
                for s in cl.span_ids
            ]
        )
        c = np.concatenate([[0.0], np.cumsum(ell)])  # node positions from the splice node
        lead = y[self._ni(int(cl.param("joint", js, "NODE")), "U")] - cl.param("joint", js, "U0")
        trail = lead - cl.param("joint", js, "LEN")
        sp, st = int(cl.param("joint", js, "SPAN")), int(cl.param("joint", js, "TSPAN"))
        g_lead = abs(c[sp + 1] - lead) if sp < len(ell) else np.inf
        return g_lead <= abs(c[st + 1] - trail)

    def _swap(self, t, y, k, log, flying):
        """Replace the expiring roll by a fresh spare roll; inject the splice joint."""
        e = self.line.elements[k]
        sp, new = e.splicer, e.spare_roll
        ea_ratio, dl0, drawn = None, None, {}
        if self.rolls is not None:
            n_rows = len(self.rolls.rows)
            new, ea_ratio, dl0 = self.rolls.next_roll(e.id, new, t)
            drawn = {r["parameter"]: r["value"] for r in self.rolls.rows[n_rows:]}
        R_old = float(self.cl.outputs(t, y[None, :])[0][self.cl.aux_index(f"{e.id}.radius_m")])
        self._load_roll(k, new)
        y[self._ni(k, "S")] = 0.0
        iw = self._ni(k, "W")
        if iw >= 0:  # the new roll is brought up to the running web's surface speed
            v_web = R_old * float(y[iw])
            y[iw] = v_web * (1.0 + sp.speed_match_error) / new.outer_radius if flying else 0.0
        elif flying:  # an imposed-speed unwind keeps the new roll's speed error
            self.cl.P[self._np(k, "VGAIN")] = 1.0 + sp.speed_match_error
        self._restart_loops(k, y, R_old, new)
        u_now = y[self._ni(k, "U")]
        self._close_material_joints(k, u_now)
        slot = self._splice_joint(k, sp, u_now)
        self._material.pop(k, None)  # the new roll's web is the line's again, unless:
        if ea_ratio is not None:
            self._open_material(
                k,
                u_now,
                ea_ratio,
                dl0=dl0,
                no_slot=(
                    f"no splice-joint slot for the web of the roll loaded on '{e.id}'; compile "
                    "the line with extra_joint_slots=joint_slots_needed(scenario, line)"
                ),
            )
        log.append(
            Event(
                t,
                "splice",
                e.id,
                "swap",
                f"roll change: radius {R_old:.4g} m -> {new.outer_radius:.4g} m"
                + (f", speed-match error {sp.speed_match_error:+.2%}" if flying else ""),
                {
                    "radius_old_m": R_old,
                    "radius_new_m": new.outer_radius,
                    "joint_slot": slot,
                    **({"roll_drawn": drawn} if drawn else {}),
                },
            )
        )
        if slot is not None:
            self._joint_born_broken(t, y, k, slot, log)
        return y

    def _load_roll(self, k, new):
        """The new roll's geometry, inertia, wound density and wound-in strain."""
        P, web = self.cl.P, self.line.web
        cw = new.build_per_wrap if new.build_per_wrap is not None else web.thickness
        P[self._np(k, "R0")] = new.outer_radius
        P[self._np(k, "R")] = new.outer_radius
        P[self._np(k, "RC")] = new.core_radius
        P[self._np(k, "JC")] = new.core_inertia
        P[self._np(k, "CW")] = cw
        P[self._np(k, "RHOW")] = web.density * web.thickness / cw * web.width
        (P[self._np(k, "EPSW")], P[self._np(k, "EPSW1")], P[self._np(k, "EPSW2")]) = (
            new.wound_in_coefficients()
        )

    def _restart_loops(self, k, y, R_old, new):
        """Bumpless transfer: the tension trims of the old roll restart from zero; the
        speed loop's integrator, which holds the tension torque -T·R, is scaled to the new
        radius so the drive takes the web's pull from the first instant; the radius
        estimate (diameter-sensor filter) takes the new roll's measured diameter."""
        for c in self._ctrls_on(k, ("TENSION_TORQUE", "TENSION_TRIM")):
            ix = int(self.cl.field("ctrl", c, "X"))
            if ix >= 0:
                y[ix] = 0.0
        for c in self._ctrls_on(k, ("SPEED",)):
            ix = int(self.cl.field("ctrl", c, "X"))
            if ix >= 0:
                y[ix] *= new.outer_radius / R_old
        for j, s in enumerate(self.cl.sensors):
            if (
                self.cl.kind("sensor", j) == "DIAMETER"
                and self.cl.field("sensor", j, "NODE") == k
                and self.cl.field("sensor", j, "F") >= 0
            ):
                y[self.cl.field("sensor", j, "F")] = s.gain * 2.0 * new.outer_radius + s.offset

    def _close_material_joints(self, k, u_now):
        """New material paid out since a modulus change ends here: close its joint."""
        for js in range(self.cl.n_joint_slots):
            if (
                self.cl.param("joint", js, "ACTIVE") != 0.0
                and self.cl.param("joint", js, "NODE") == k
                and self.cl.param("joint", js, "LEN") == OPEN_JOINT
            ):
                self.cl.set_param("joint", js, "LEN", u_now - self.cl.param("joint", js, "U0"))
                # its trail leaves the roll now
                self.cl.set_param("joint", js, "TSPAN", float(k))

    def _splice_joint(self, k, sp, u_now):
        """The splice joint, in a free slot (its index, or None when none is free)."""
        slot = self._free_joint_slot()
        if slot is None:
            return None
        self.cl.set_param("joint", slot, "ACTIVE", 1.0)
        self.cl.set_param("joint", slot, "MAT", 0.0)
        self.cl.set_param("joint", slot, "DL0", 0.0)
        self.cl.set_param("joint", slot, "U0", u_now)
        self.cl.set_param("joint", slot, "LEN", sp.joint.length)
        self.cl.set_param("joint", slot, "RATIO", sp.joint.stiffness_ratio)
        self.cl.set_param(
            "joint",
            slot,
            "TBRK",
            sp.joint.break_tension
            if sp.joint.break_tension is not None
            else self.line.web.break_tension,
        )
        if k in self._weak_splice:
            self.cl.set_param("joint", slot, "TBRK", self._weak_splice.pop(k))
        self.cl.set_param("joint", slot, "SPAN", float(k))
        self.cl.set_param("joint", slot, "TSPAN", float(k) - 1.0)
        self.cl.set_param("joint", slot, "NODE", float(k))
        return slot

    def _joint_born_broken(self, t, y, k, slot, log):
        """A joint weaker than the tension it is made under breaks at once (its break
        event can only see a crossing, not a joint born past its limit)."""
        span = self.cl.span_ids[k]
        T = float(self.cl.outputs(t, y[None, :])[0][self.cl.aux_index(f"{span}.tension_N")])
        if T >= self.cl.param("joint", slot, "TBRK"):
            log.append(
                Event(
                    t,
                    "web_break",
                    span,
                    "start",
                    f"web break at the new splice joint in {span}"
                    f" at {T:.1f} N (joint strength {self.cl.param('joint', slot, 'TBRK'):.1f} N)",
                    {"tension_N": T, "at_splice_joint": True},
                )
            )
            self.terminate_reason = "web_break"
