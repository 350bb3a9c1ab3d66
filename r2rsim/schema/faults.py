"""The fault catalogue (docs/dataset.md §5.1) and a scenario's fault entries.

Every fault has an ``id``, a ``type`` from :data:`CATALOGUE`, a ``target`` (the id of a
sensor, element, dancer or unwind, as the type says), an ``onset``, an optional ``end``, a
``profile`` (step, ramp, exp, intermittent) and a ``magnitude`` whose unit the type fixes
(:func:`magnitude_dimension`). Onset and magnitude may be drawn from a seeded distribution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

from pydantic import BeforeValidator, Discriminator, Field, Tag, model_validator

from ..errors import InputError
from ..units import QuantityError, parse_quantity
from .kinds import kind_of
from .line import Id, Strict, dancer_reading_dimension
from .parts import NumberOrTextPair
from .quantities import Frequency, NumberOrText, Time, number_or_text


@dataclass(frozen=True)
class FaultType:
    """One entry of the catalogue.

    ``target``: what ``target`` names (``sensor``; ``drive``: an element with a torque
    drive; ``dancer``: a dancer or festoon carriage; ``roller``: an element that turns
    freely or under a torque drive; ``eccentric``: such a roller between two spans;
    ``speed_node``: a driven roller or nip; ``unwind``: an unwind; ``splicer``: an unwind with
    a splicer). ``magnitude``: ``reading`` (the sensor's unit), ``reading/s``, ``rel``
    (relative change, 0.05 = +5 %), ``s``, ``N*m``, ``N``, ``m``, ``none``. ``acts``: ``loop``
    (inside the simulation: a controller reading the sensor sees it), ``record`` (on the
    recorded measurement only), ``model`` (changes the line's equations or parameters; the
    solver restarts at every breakpoint of the profile). ``profiles``: the profile shapes
    that make sense for the type; ``end``: whether the fault can stop acting.
    """

    name: str
    fault_class: str
    target: str
    magnitude: str
    acts: str
    description: str
    profiles: tuple[str, ...] = ("step", "ramp", "exp", "intermittent")
    end: bool = True


_C = [
    FaultType("sensor.offset", "sensor", "sensor", "reading", "loop", "adds b to the reading"),
    FaultType(
        "sensor.gain",
        "sensor",
        "sensor",
        "rel",
        "loop",
        "multiplies the reading by (1 + magnitude)",
    ),
    FaultType(
        "sensor.drift",
        "sensor",
        "sensor",
        "reading/s",
        "loop",
        "adds magnitude·(t - onset) to the reading",
    ),
    FaultType(
        "sensor.stuck",
        "sensor",
        "sensor",
        "none",
        "loop",
        "the reading freezes at its value at onset",
    ),
    FaultType(
        "sensor.dropout",
        "sensor",
        "sensor",
        "none",
        "loop",
        "no reading: recorded as NaN; a controller holds the last valid reading",
    ),
    FaultType(
        "sensor.noise",
        "sensor",
        "sensor",
        "reading",
        "record",
        "adds white noise of standard deviation magnitude at each sensor sample",
    ),
    FaultType(
        "sensor.spike",
        "sensor",
        "sensor",
        "reading",
        "record",
        "spikes of +-magnitude at random sensor samples (rate: spikes per second)",
    ),
    FaultType(
        "sensor.quantization",
        "sensor",
        "sensor",
        "reading",
        "record",
        "the reading is rounded to steps of magnitude",
    ),
    FaultType(
        "sensor.delay", "sensor", "sensor", "s", "record", "the reading lags by magnitude seconds"
    ),
    FaultType(
        "actuator.bias",
        "actuator",
        "drive",
        "N*m",
        "model",
        "the drive delivers its command + magnitude (then its torque limit)",
    ),
    FaultType(
        "actuator.loss_of_effectiveness",
        "actuator",
        "drive",
        "rel",
        "model",
        "the drive delivers (1 - magnitude) x its command, magnitude in (0, 1]",
    ),
    FaultType(
        "actuator.stuck",
        "actuator",
        "drive",
        "none",
        "model",
        "the drive torque freezes at its value at onset",
        ("step", "intermittent"),
    ),
    FaultType(
        "actuator.saturation",
        "actuator",
        "drive",
        "N*m",
        "model",
        "the drive's torque limit falls to magnitude",
        ("step", "intermittent"),
    ),
    FaultType(
        "dancer.arm_stuck",
        "dancer",
        "dancer",
        "none",
        "model",
        "the dancer arm or carriage seizes where it is: its spans become fixed length",
        ("step", "intermittent"),
    ),
    FaultType(
        "dancer.loss_of_loading",
        "dancer",
        "dancer",
        "rel",
        "model",
        "the loading actuator (air cylinder, torque motor) loses magnitude of its "
        "force, magnitude in (0, 1]",
    ),
    FaultType(
        "dancer.friction_increase",
        "dancer",
        "dancer",
        "rel",
        "model",
        "the carriage/arm friction (viscous and Coulomb) grows by magnitude",
    ),
    FaultType(
        "process.bearing_friction",
        "process",
        "roller",
        "rel",
        "model",
        "the bearing friction (viscous and Coulomb) grows by magnitude",
    ),
    FaultType(
        "process.eccentricity",
        "process",
        "eccentric",
        "m",
        "model",
        "the roller turns about an axis magnitude off its centre: span lengths and "
        "tension vary at the rotation frequency",
        ("step",),
    ),
    FaultType(
        "process.modulus_change",
        "process",
        "unwind",
        "rel",
        "model",
        "the web coming off the roll from onset has its modulus changed by magnitude "
        "(new material) until the next splice",
        ("step",),
        end=False,
    ),
    FaultType(
        "process.draw_error",
        "process",
        "speed_node",
        "rel",
        "model",
        "the effective radius is R x (1 + magnitude): the surface speed and torque "
        "arm change, the drive's radius (and encoder) do not",
    ),
    FaultType(
        "process.weak_splice",
        "process",
        "splicer",
        "N",
        "model",
        "the first splice at or after onset makes a joint that breaks at magnitude N",
        ("step",),
        end=False,
    ),
]
CATALOGUE: dict[str, FaultType] = {f.name: f for f in _C}

#: fault types that may overlap on one target when both declare ``compose: superpose``
#: (their effects add)
SUPERPOSABLE = {
    "sensor.offset",
    "sensor.gain",
    "sensor.drift",
    "sensor.noise",
    "sensor.spike",
    "actuator.bias",
    "process.draw_error",
    "process.bearing_friction",
    "dancer.friction_increase",
}
#: faults that take over their target completely: nothing superposes on them
_EXCLUSIVE = {"sensor.stuck", "sensor.dropout", "actuator.stuck", "dancer.arm_stuck"}


def superposable(a: str, b: str) -> bool:
    """Whether faults of types a and b may act on one target at once (when both declare
    ``compose: superpose``): types whose effects add, or two different model faults that
    change different parameters."""
    if a in _EXCLUSIVE or b in _EXCLUSIVE:
        return False
    if a in SUPERPOSABLE and b in SUPERPOSABLE:
        return True
    return a != b and CATALOGUE[a].acts == "model" and CATALOGUE[b].acts == "model"


class Uniform(Strict):
    """A value drawn uniformly from [low, high] (seeded by the fault-sampling stream)."""

    uniform: NumberOrTextPair = Field(
        description="[low, high]: the value is drawn uniformly between them"
    )


class LogUniform(Strict):
    """A value whose logarithm is uniform on [log low, log high] (low, high > 0)."""

    loguniform: NumberOrTextPair = Field(
        description="[low, high], both > 0: the logarithm of the value is drawn uniformly"
    )


class Choice(Strict):
    """One of the listed values, each equally likely."""

    choice: list[NumberOrText] = Field(
        min_length=1, max_length=1000, description="the values to choose from, each equally likely"
    )


def _sampled_kind(value) -> str | None:
    """Which distribution a mapping names (its one key), for the tagged union below."""
    if isinstance(value, dict):
        return next((k for k in ("uniform", "loguniform", "choice") if k in value), None)
    kinds: dict[type, str] = {Uniform: "uniform", LogUniform: "loguniform", Choice: "choice"}
    return kinds.get(type(value))


# Tagged by the distribution's key, so each form is validated once: an untagged union of
# strict models is tried strictly first, and before pydantic 2.11 the [low, high] list of
# `uniform` then failed (a list is no tuple in strict mode) with a misleading message.
Sampled = Annotated[
    Annotated[Uniform, Tag("uniform")]
    | Annotated[LogUniform, Tag("loguniform")]
    | Annotated[Choice, Tag("choice")],
    Discriminator(_sampled_kind),
]


class Profile(Strict):
    """Time course of a fault's effect, as a fraction p(t) of its magnitude.

    ``step``: p = 1 from onset. ``ramp``: p rises linearly to 1 over ``ramp``. ``exp``:
    p = 1 - exp(-(t - onset)/``ramp``). ``intermittent``: p = 1 for ``duty``·``period`` out of
    every ``period`` from onset, else 0.
    """

    shape: Literal["step", "ramp", "exp", "intermittent"] = Field(
        "step", description="step, ramp, exp or intermittent: how the effect grows from onset"
    )
    ramp: Annotated[Time, Field(gt=0)] | None = Field(
        None, description="ramp: time to full magnitude; exp: time constant [s]"
    )
    period: Annotated[Time, Field(gt=0)] | None = Field(None, description="intermittent [s]")
    duty: Annotated[float, Field(gt=0, le=1)] | None = Field(
        None, description="intermittent: fraction of each period the fault acts"
    )

    @model_validator(mode="after")
    def _check(self):
        if self.shape in ("ramp", "exp") and self.ramp is None:
            raise ValueError(f"a {self.shape} profile needs 'ramp' (its time scale)")
        if self.shape == "intermittent" and (self.period is None or self.duty is None):
            raise ValueError("an intermittent profile needs 'period' and 'duty'")
        if self.shape != "intermittent" and (self.period is not None or self.duty is not None):
            raise ValueError("'period' and 'duty' belong to an intermittent profile")
        if self.shape in ("step", "intermittent") and self.ramp is not None:
            raise ValueError(f"'ramp' does not apply to a {self.shape} profile")
        return self


class Fault(Strict):
    """A fault instance of the scenario (``r2rsim list faults`` shows the types)."""

    id: Id = Field(
        description="name of the fault instance, unique in the scenario (faults.parquet, label.* "
        "columns)"
    )
    type: Literal[tuple(CATALOGUE)] = Field(  # type: ignore[valid-type]
        description="the fault type (r2rsim list faults)"
    )
    target: Id = Field(description="sensor / element / dancer id, as the type requires")
    onset: Annotated[Time, Field(ge=0)] | Sampled = Field(
        description="when the fault starts [s], or a distribution to draw it from"
    )
    end: Annotated[Time, Field(gt=0)] | None = Field(
        None, description="when the fault stops acting; default: to the end of the run"
    )
    profile: Profile = Field(
        default_factory=Profile, description="time course of the effect (default: a step)"
    )
    magnitude: Annotated[float | str | Sampled | None, BeforeValidator(number_or_text)] = Field(
        None,
        description="in the unit the type fixes (see `r2rsim list faults`); a number "
        "is SI, a string may carry units ('5 N')",
    )
    rate: Annotated[Frequency, Field(gt=0)] | None = Field(
        None, description="sensor.spike: mean number of spikes per second"
    )
    record_only: bool = Field(
        False,
        description="a sensor fault that acts in the loop acts on the recorded "
        "measurement only: a controller reading the sensor does not see it, and the process "
        "is untouched (as when faults are injected into recorded data, thesis §3.5)",
    )
    compose: Literal["superpose"] | None = Field(
        None,
        description="allow overlap with other faults on the same target that also "
        "declare it: offsets and drifts add, gain changes add, noise variances add",
    )

    @model_validator(mode="after")
    def _check(self):
        ft = CATALOGUE[self.type]
        if ft.magnitude == "none" and self.magnitude is not None:
            raise ValueError(f"{self.type} takes no magnitude")
        if ft.magnitude != "none" and self.magnitude is None:
            raise ValueError(f"{self.type} needs a magnitude")
        if (self.type == "sensor.spike") != (self.rate is not None):
            raise ValueError("'rate' is required for sensor.spike and only for it")
        if self.profile.shape not in ft.profiles:
            raise ValueError(
                f"{self.type} takes a {' or '.join(ft.profiles)} profile, not {self.profile.shape}"
            )
        if not ft.end and self.end is not None:
            raise ValueError(f"{self.type} lasts to the end of the run: leave out 'end'")
        if self.record_only and not (ft.target == "sensor" and ft.acts == "loop"):
            raise ValueError(
                f"record_only applies to sensor faults that act in the loop; "
                f"{self.type} acts on the {ft.acts}"
            )
        if self.type == "sensor.drift" and self.profile.shape != "step":
            raise ValueError("a drift grows by itself: use a step profile")
        if self.end is not None and isinstance(self.onset, float) and self.end <= self.onset:
            raise ValueError(f"end {self.end:g} s must come after onset {self.onset:g} s")
        return self


READING = {
    "load_cell": "force",
    "encoder": "angular_speed",
    "roll_diameter": "length",
    "pitch_length": "length",
}
SI_UNIT = {
    "force": "N",
    "angular_speed": "rad/s",
    "length": "m",
    "angle": "rad",
    "time": "s",
    "dimensionless": "rel",
}
RATE_OF = {"force": "force_rate", "length": "speed", "angle": "angular_speed"}


def magnitude_dimension(ftype: str, reading_dim: str | None) -> str | None:
    """The :data:`r2rsim.units.DIMENSIONS` key of a fault's magnitude, given the dimension of
    the target's reading (sensor faults; None otherwise). None: a plain SI number."""
    return {
        "reading": reading_dim,
        "rel": "dimensionless",
        "s": "time",
        "none": None,
        "reading/s": None if reading_dim is None else RATE_OF.get(reading_dim),
        "N*m": "torque",
        "N": "force",
        "m": "length",
    }[CATALOGUE[ftype].magnitude]


def magnitude_unit(ftype: str, reading_dim: str | None) -> str:
    """SI unit of a fault's magnitude as written to faults.parquet."""
    code = CATALOGUE[ftype].magnitude
    if code in ("reading", "reading/s"):
        assert reading_dim is not None  # only sensor faults, whose reading has a dimension
        return SI_UNIT[reading_dim] + ("/s" if code == "reading/s" else "")
    return {"rel": "rel", "none": ""}.get(code, code)


def target_problem(ftype: str, target: str, line) -> str | None:
    """Why ``target`` cannot carry a fault of type ``ftype`` (None if it can)."""
    kind = CATALOGUE[ftype].target
    sensors = {s.id for s in line.sensors}
    els = {e.id: (k, e) for k, e in enumerate(line.elements)}
    movers = [e.id for e in line.elements if "dancer" in kind_of(e).fault_targets] + [
        sp.id for sp in line.spans if sp.festoon is not None
    ]
    if kind == "sensor":
        return (
            None
            if target in sensors
            else (
                f"{ftype} targets a sensor; no sensor '{target}' in the line (known: "
                f"{', '.join(sorted(sensors)) or 'none'})"
            )
        )
    if kind == "dancer":
        if target not in movers:
            return (
                f"{ftype} targets a dancer or festoon; none is called '{target}' (known: "
                f"{', '.join(movers) or 'none'})"
            )
        if ftype == "dancer.friction_increase":
            el = els.get(target)
            obj = el[1] if el else next(sp.festoon for sp in line.spans if sp.id == target)
            if obj.damping == 0 and obj.coulomb == 0:
                return f"'{target}' has no friction (damping, coulomb) to increase"
        return None
    if target not in els:
        return (
            f"{ftype} targets an element; no element '{target}' in the line (known: "
            f"{', '.join(els)})"
        )
    k, e = els[target]
    targets = kind_of(e).fault_targets  # the fault families the element's kind may carry
    drive = getattr(e, "drive", None)
    if kind == "drive" and (drive is None or drive.type != "torque"):
        return f"{ftype} needs an element with a torque drive; '{target}' has none"
    ideal = drive is not None and drive.type == "ideal_speed"
    if kind in ("roller", "eccentric") and ideal:
        return (
            f"'{target}' turns at an imposed speed (ideal_speed drive): its {ftype} "
            f"would have no effect"
        )
    if kind == "roller" and e.friction.viscous == 0 and e.friction.coulomb == 0:
        return f"'{target}' has no bearing friction (friction: viscous, coulomb) to increase"
    if kind == "eccentric":
        if "eccentric" not in targets:
            return f"{ftype} applies to a roller, not to the roll '{target}'"
        if not 0 < k < len(line.elements) - 1:
            return f"{ftype} needs a roller with a span on each side"
    if kind == "speed_node" and ("speed_node" not in targets or drive is None):
        return f"{ftype} applies to a driven roller or nip; '{target}' is a {e.type}"
    if kind == "unwind" and "unwind" not in targets:
        return f"{ftype} applies to an unwind; '{target}' is a {e.type}"
    if kind == "splicer" and getattr(e, "splicer", None) is None:
        return f"{ftype} needs an unwind with a splicer; '{target}' has none"
    if kind not in targets:  # a plug-in kind that opts out (the shipped ones are caught above)
        return f"{ftype} does not apply to a {e.type} ('{target}')"
    return None


#: the allowed range of a magnitude: (low, high, low inclusive, why)
_RANGES = {
    "sensor.noise": (0.0, math.inf, True, "needs a magnitude >= 0"),
    "sensor.spike": (0.0, math.inf, True, "needs a magnitude >= 0"),
    "sensor.quantization": (0.0, math.inf, True, "needs a magnitude >= 0"),
    "sensor.delay": (0.0, math.inf, True, "needs a magnitude >= 0"),
    "sensor.gain": (
        -1.0,
        math.inf,
        False,
        "a gain change must be > -1 (the reading would vanish or flip sign)",
    ),
    "actuator.loss_of_effectiveness": (0.0, 1.0, False, "needs a magnitude in (0, 1]"),
    "actuator.saturation": (0.0, math.inf, True, "needs a torque limit >= 0"),
    "dancer.loss_of_loading": (0.0, 1.0, False, "needs a magnitude in (0, 1]"),
    "dancer.friction_increase": (-1.0, math.inf, False, "needs a magnitude > -1"),
    "process.bearing_friction": (-1.0, math.inf, False, "needs a magnitude > -1"),
    "process.eccentricity": (0.0, math.inf, False, "needs an eccentricity > 0"),
    "process.modulus_change": (-1.0, math.inf, False, "needs a modulus change > -1"),
    "process.draw_error": (-0.5, 0.5, False, "needs a draw error in (-0.5, 0.5)"),
    "process.weak_splice": (0.0, math.inf, False, "needs a joint break tension > 0"),
}


def magnitude_problem(ftype: str, lo: float, hi: float, line, target: str) -> str | None:
    """Why a magnitude range [lo, hi] (SI) is not allowed for the type (None if it is)."""
    rng = _RANGES.get(ftype)
    if rng is not None:
        a, b, incl, why = rng
        if lo < a or (lo == a and not incl) or hi > b:
            return f"{ftype} {why}"
    if ftype == "process.eccentricity":
        r = next(e for e in line.elements if e.id == target).radius
        if hi >= r:
            return f"an eccentricity of {hi:g} m is not less than the roller radius {r:g} m"
    return None


def reading_dimension(line, sensor) -> str | None:
    """Dimension of a sensor's reading (None when ``sensor`` is None: not a sensor fault)."""
    if sensor is None:
        return None
    if sensor.type != "dancer_position":
        return READING[sensor.type]
    return dancer_reading_dimension(line, sensor)


def bounds(value, dimension) -> tuple[float, float]:
    """Smallest and largest value a fixed value or distribution can take (SI)."""

    def si(v):
        return float(v) if dimension is None else parse_quantity(v, dimension)

    if isinstance(value, Uniform):
        return si(value.uniform[0]), si(value.uniform[1])
    if isinstance(value, LogUniform):
        return si(value.loguniform[0]), si(value.loguniform[1])
    if isinstance(value, Choice):
        vals = [si(v) for v in value.choice]
        return min(vals), max(vals)
    return si(value), si(value)


def check_faults(scenario, line, file: str) -> None:
    """Targets, units and overlaps of the scenario's faults, checked at load time.

    Two faults on one target whose windows can overlap (over the whole range of any drawn
    onset) must both declare ``compose: superpose`` and be of superposable types."""
    sensors = {s.id: s for s in line.sensors}
    windows = []
    for i, f in enumerate(scenario.faults):
        where = f"faults[{i}]"
        ft = CATALOGUE[f.type]
        problem = target_problem(f.type, f.target, line)
        if problem:
            raise InputError(problem, file=file, path=f"{where}.target")
        rdim = reading_dimension(line, sensors.get(f.target) if ft.target == "sensor" else None)
        try:
            lo, hi = bounds(f.onset, "time")
        except QuantityError as exc:
            raise InputError(str(exc), file=file, path=f"{where}.onset") from None
        if ft.magnitude != "none":
            try:
                mlo, mhi = bounds(f.magnitude, magnitude_dimension(f.type, rdim))
            except QuantityError as exc:
                raise InputError(str(exc), file=file, path=f"{where}.magnitude") from None
            problem = magnitude_problem(f.type, mlo, mhi, line, f.target)
            if problem:
                raise InputError(problem, file=file, path=f"{where}.magnitude")
        if f.type == "process.weak_splice":
            splicer = next(e for e in line.elements if e.id == f.target).splicer
            later = [
                ev
                for ev in scenario.events
                if ev.type == "splice" and ev.at >= lo and ev.element in (None, f.target)
            ]
            if not later and splicer.trigger_radius is None:
                raise InputError(
                    f"no splice on '{f.target}' at or after the onset: schedule "
                    "one (events: type splice) or give the splicer a "
                    "trigger_radius",
                    file=file,
                    path=f"{where}.onset",
                )
        drawn = "can be" if hi > lo else "is"
        if hi > scenario.duration:
            raise InputError(
                f"onset {drawn} {hi:g} s, after the end of the run ({scenario.duration:g} s)",
                file=file,
                path=f"{where}.onset",
            )
        if f.end is not None and f.end <= hi:  # a drawn onset: refused whatever the seed
            raise InputError(
                f"end {f.end:g} s can come before the onset, which is drawn up to {hi:g} s",
                file=file,
                path=f"{where}.end",
            )
        windows.append((lo, f.end if f.end is not None else math.inf))
    for i, a in enumerate(scenario.faults):
        for j in range(i):
            b = scenario.faults[j]
            if a.target != b.target:
                continue
            (alo, aend), (blo, bend) = windows[i], windows[j]
            if not (alo < bend and blo < aend):
                continue
            if not (a.compose and b.compose):
                raise InputError(
                    f"faults '{b.id}' and '{a.id}' can overlap on '{a.target}' (from "
                    f"{max(alo, blo):g} s); declare compose: superpose on both, or separate "
                    f"them in time",
                    file=file,
                    path=f"faults[{i}]",
                )
            if not superposable(a.type, b.type):
                raise InputError(
                    f"faults '{b.id}' ({b.type}) and '{a.id}' ({a.type}) overlap on "
                    f"'{a.target}' and cannot be superposed; separate them in time",
                    file=file,
                    path=f"faults[{i}]",
                )
            if (
                a.profile.shape == "exp"
                and b.profile.shape == "exp"
                and a.profile.ramp != b.profile.ramp
            ):
                raise InputError(
                    "two overlapping exp-profile faults on one target need the same time constant",
                    file=file,
                    path=f"faults[{i}].profile",
                )
