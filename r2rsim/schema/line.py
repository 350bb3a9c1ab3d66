"""Pydantic models of a line file (README.md "A line file"; every key: docs/keys.md).

A line is a list of elements in web order (unwind first, rewind last), the spans between
consecutive elements, the web material, and the sensors and controllers as data. All
quantities are SI floats after validation. Cross-references are checked in
:meth:`Line._cross_check`; its messages start with the YAML path of the problem.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Annotated, Any, Literal, TypeAlias

from pydantic import BeforeValidator, Field, WithJsonSchema, model_validator

from ..limits import MAX_LINE_ITEMS
from ..units import QuantityError, parse_quantity
from .kinds import all_kinds, element_union, kind_of, kinds_in_family

# the element models and their parts live in kinds/ and parts.py; re-exported (``X as X``)
# for the code and the plug-ins that import them from here
from .kinds.dancer import Dancer as Dancer
from .kinds.driven import Driven as Driven
from .kinds.idler import Idler as Idler
from .kinds.nip import Nip as Nip
from .kinds.nip import PressureRoller as PressureRoller
from .kinds.pivot_dancer import Cylinder as Cylinder
from .kinds.pivot_dancer import PivotDancer as PivotDancer
from .kinds.pivot_dancer import TorsionSpring as TorsionSpring
from .kinds.rewind import Rewind as Rewind
from .kinds.unwind import Unwind as Unwind
from .materials import MATERIALS
from .parts import GRAVITY as GRAVITY
from .parts import ID_PATTERN as ID_PATTERN
from .parts import Drive as Drive
from .parts import ElementBase as ElementBase
from .parts import FloatPair, Id, LengthPair, NonNegTime, PosLength, Strict
from .parts import Friction as Friction
from .parts import Roll as Roll
from .parts import SpliceJoint as SpliceJoint
from .parts import Splicer as Splicer
from .parts import TorqueRipple as TorqueRipple
from .parts import Vec2 as Vec2
from .parts import Wrap as Wrap
from .parts import pair as pair
from .quantities import (
    Acceleration,
    Angle,
    AngularSpeed,
    Damping,
    Density,
    Dimensionless,
    Force,
    Frequency,
    Inertia,
    InverseArea,
    Length,
    Mass,
    NumberOrText,
    Pressure,
    Speed,
    Time,
)


class Web(Strict):
    """Web material. ``material`` picks a preset (PET, paper, aluminium, copper); any property
    given here overrides the preset."""

    material: Literal["PET", "paper", "aluminium", "aluminum", "copper"] | None = Field(
        None,
        description="material preset that gives modulus, density and break_stress (each "
        "can still be given here)",
    )
    thickness: PosLength = Field(description="caliper t_w [m]")
    width: PosLength = Field(description="web width w [m]")
    modulus: Annotated[Pressure, Field(gt=0)] | None = Field(None, description="E (MD) [Pa]")
    density: Annotated[Density, Field(gt=0)] | None = Field(None, description="rho [kg/m^3]")
    break_stress: Annotated[Pressure, Field(gt=0)] | None = Field(
        None, description="tensile stress at break [Pa]; the break tension is stress x area"
    )
    breakable: bool = Field(True, description="false switches the web-break event off")

    @model_validator(mode="after")
    def _fill_from_preset(self):
        preset = MATERIALS.get(self.material or "", {})
        for key in ("modulus", "density", "break_stress"):
            if getattr(self, key) is None and key in preset:
                setattr(self, key, preset[key])
        for key in ("modulus", "density"):
            if getattr(self, key) is None:
                raise ValueError(f"web.{key}: missing; give it or choose a `material` preset")
        return self

    @property
    def area(self) -> float:
        """Cross-section A = thickness x width [m^2]."""
        return self.thickness * self.width

    @property
    def EA(self) -> float:  # noqa: N802 - the physics symbol
        """Axial stiffness E·A [N]."""
        assert self.modulus is not None  # _fill_from_preset fills it or refuses the web
        return self.modulus * self.area

    @property
    def break_tension(self) -> float:
        """Tension at break [N] (inf when unbreakable or no break stress)."""
        if not self.breakable or self.break_stress is None:
            return math.inf
        return self.break_stress * self.area


#: the element kinds shipped with r2rsim (the registry, r2rsim/schema/kinds/, has the
#: current ones, plug-ins included): kept for code that imported these names
DANCERS = tuple(k.name for k in kinds_in_family("mover"))
ROTATING_WITH_DRIVE = tuple(k.name for k in all_kinds() if k.has_drive)
#: one entry of Line.elements: the union of the registered kinds' models (by ``type``)
if TYPE_CHECKING:
    # built at run time from the registry (plug-ins add kinds), so a type checker cannot
    # know its members; like the kinds' hooks, it sees any element
    Element: TypeAlias = Any
else:
    Element = element_union()


class Festoon(Strict):
    """Festoon accumulator lumped into its span (physics.md eq. 1.18): ``moving_rollers`` on a
    carriage give 2n strands; the span length is ``length + 2n·x``."""

    moving_rollers: Annotated[int, Field(ge=1)] = Field(
        description="rollers on the carriage (n); the stored web is 2n·x"
    )
    carriage_mass: Annotated[Mass, Field(gt=0)] = Field(
        description="moving mass of the carriage with its rollers [kg]"
    )
    stroke: LengthPair = Field(description="carriage end stops [x_min, x_max] [m]")
    initial_position: Length = Field(description="carriage position x at t = 0 [m]")
    force: Force = Field(description="carriage actuator force along +x (storage grows) [N]")
    gravity: Acceleration = Field(
        0.0, description="gravity component along +x [m/s^2] (-9.81: storage grows upward)"
    )
    damping: Annotated[Damping, Field(ge=0)] = Field(
        0.0, description="viscous damping of the carriage [N s/m]"
    )
    coulomb: Annotated[Force, Field(ge=0)] = Field(
        0.0, description="Coulomb friction force on the carriage [N]"
    )
    smoothing_speed: Annotated[Speed, Field(gt=0)] = Field(
        1e-3, description="tanh smoothing of the Coulomb friction [m/s]"
    )


class Span(Strict):
    """Free span between consecutive elements."""

    id: Id | None = Field(None, description="default: span1, span2, ... in web order")
    length: PosLength | None = Field(
        None,
        description="free length [m]; omitted next to a dancer (from the geometry); "
        "with a festoon, the length at carriage position 0",
    )
    festoon: Festoon | None = Field(None, description="a festoon accumulator in this span")


NOISE_PER_SPEED_DOC = (
    "speed-dependent noise (vibration): a zero-mean Gaussian term of std noise_per_speed·|v| "
    "added to each recorded sample, v the web speed at the sensor [m/s] (the element's surface "
    "speed; for a span or festoon, that of its downstream element); in the reading's SI unit "
    "per m/s (N·s/m for a load cell, s for a pitch or diameter). Not a labelled fault"
)


class _Sensor(Strict):
    id: Id = Field(
        description="name of the sensor, unique in the line; its columns are meas.<id>.* and "
        "true.<id>.*"
    )
    element: Id = Field(description="id of the element the sensor is on")
    rate: Annotated[Frequency, Field(gt=0)] | None = Field(
        None, description="sample rate [Hz]; default: the scenario's record rate"
    )
    filter: NonNegTime = Field(0.0, description="first-order filter time constant [s]")
    gain: float = Field(1.0, description="calibration gain g in y = g·x + b")
    range: FloatPair | None = Field(
        None,
        description="measuring range [low, high] in the reading's SI unit; recorded "
        "samples outside are clipped and flagged (censored data)",
    )
    quantization: Annotated[float, Field(ge=0)] = Field(
        0.0, description="resolution of the recorded reading (SI unit of the reading)"
    )
    delay: NonNegTime = Field(0.0, description="transport/processing delay of the record [s]")
    noise_per_speed: Annotated[float, Field(ge=0)] = Field(0.0, description=NOISE_PER_SPEED_DOC)

    @model_validator(mode="after")
    def _check_range(self):
        if self.range is not None and not self.range[0] < self.range[1]:
            raise ValueError("range must be [low, high] with low < high")
        return self


class LoadCell(_Sensor):
    """Load cell on a roller: measures the bearing force component along its axis and reports
    the indicated tension (physics.md §1.3)."""

    type: Literal["load_cell"] = Field(description="selects a load cell")
    wrap_angle: Annotated[Angle, Field(gt=0, le=2 * math.pi)] | None = Field(
        None, description="wrap angle; default: the element's wrap_angle, else 180 deg"
    )
    axis_angle: Angle = Field(
        0.0, description="angle of the measuring axis from the wrap bisector [rad]"
    )
    noise: Annotated[Force, Field(ge=0)] = Field(0.0, description="noise std of tension [N]")
    offset: Force = Field(0.0, description="calibration offset b [N]")


class Encoder(_Sensor):
    """Encoder on a rotating element: angular speed."""

    type: Literal["encoder"] = Field(description="selects an encoder")
    counts_per_rev: Annotated[int, Field(gt=0)] | None = Field(
        None,
        description="edges per revolution: the recorded speed is the difference of the "
        "accumulated edge count over the counting window, times 2π/(counts_per_rev·window) "
        "(unbiased; resolution one count per window). Default: an ideal (analogue) speed",
    )
    window: Annotated[Time, Field(gt=0)] | None = Field(
        None,
        description="counting window of an encoder with counts_per_rev [s]; default: "
        "one sensor sample period",
    )
    noise: Annotated[AngularSpeed, Field(ge=0)] = Field(
        0.0, description="noise std of the speed reading [rad/s]"
    )
    offset: AngularSpeed = Field(0.0, description="calibration offset b [rad/s]")

    @model_validator(mode="after")
    def _check_window(self):
        if self.window is not None and self.counts_per_rev is None:
            raise ValueError("window applies to an encoder with counts_per_rev")
        return self


class RollDiameter(_Sensor):
    """Ultrasonic/laser roll-diameter sensor on an unwind or rewind."""

    type: Literal["roll_diameter"] = Field(description="selects a roll-diameter sensor")
    noise: Annotated[Length, Field(ge=0)] = Field(
        0.0, description="noise std of the diameter reading [m]"
    )
    offset: Length = Field(0.0, description="calibration offset b [m]")


class DancerPosition(_Sensor):
    """Position of a dancer (travel in m, or arm angle in rad) or festoon carriage (m);
    ``element`` is the dancer's id or the festoon span's id."""

    type: Literal["dancer_position"] = Field(description="selects a dancer-position sensor")
    noise: NumberOrText = Field(
        0.0,
        description="noise std of the position reading (≥ 0): a length, or an angle for "
        "a pivoted dancer's arm; a number in m (rad) or a string with units",
    )
    offset: NumberOrText = Field(
        0.0,
        description="calibration offset b: a length, or an angle for a pivoted dancer's "
        "arm; a number in m (rad) or a string with units",
    )


class RelaxedPitchLaw(Strict):
    """Relaxed pitch as a function of the unwind roll's radius R (thesis eq. 2.24):
    L0(R) = q0 + q1·R³."""

    q0: PosLength = Field(description="relaxed pitch at R = 0 [m]")
    q1: InverseArea = Field(description="coefficient of R³ [1/m²] (may be negative)")
    unwind: Id | None = Field(
        None,
        description="the unwind whose roll radius R is used; default: the line's unwind "
        "(the first element)",
    )


class PitchVariation(Strict):
    """Relaxed-pitch (printing) repeatability: a zero-mean, smooth random variation of L0 along
    the web, of standard deviation ``std`` and Gaussian correlation exp(-(Δs/ℓ)²) over the
    unwound web length Δs (ℓ = ``correlation_length``: the lag at which the correlation falls
    to 1/e). Realised per run from the run's process stream as a sum of 64 cosines of the
    unwound length of the relaxed_pitch_law's unwind (default: the line's unwind)."""

    std: Annotated[Length, Field(gt=0)] = Field(description="standard deviation of L0 [m]")
    correlation_length: Annotated[Length, Field(ge=1e-3)] = Field(
        description="correlation length ℓ along the web [m] (correlation 1/e at lag ℓ, as "
        "for a wound_in_strain disturbance, whose correlation is exponential where this one "
        "is Gaussian); at least 1 mm"
    )


class PitchLength(Strict):
    """2-D vision pitch-length measurement on a span (thesis eq. 2.11, Hooke's law):
    pitch = (T/(E·S) + 1)·L0, with L0 constant (``relaxed_pitch``) or L0(R) = q0 + q1·R³
    (``relaxed_pitch_law``, thesis eq. 2.20/2.24), plus an optional printing variation
    (``pitch_variation``). The variation is physical: it is in the true pitch and, if a
    controller reads the sensor, in the loop. A tension_pi reading it converts the pitch back to
    tension with the web's nominal E·S and the nominal L0 (the law, without the variation)."""

    id: Id = Field(
        description="name of the sensor, unique in the line; its columns are meas.<id>.* and "
        "true.<id>.*"
    )
    type: Literal["pitch_length"] = Field(description="selects a pitch-length (vision) sensor")
    span: Id = Field(description="id of the span the camera sees")
    relaxed_pitch: PosLength | None = Field(
        None,
        description="constant pitch length L0 of the relaxed web [m]; give this or "
        "relaxed_pitch_law",
    )
    relaxed_pitch_law: RelaxedPitchLaw | None = Field(
        None, description="L0(R) = q0 + q1·R³ of the unwind roll's radius R (thesis eq. 2.24)"
    )
    pitch_variation: PitchVariation | None = Field(
        None, description="zero-mean printing variation of L0, correlated along the web"
    )
    rate: Annotated[Frequency, Field(gt=0)] | None = Field(
        None, description="sample rate [Hz]; default: the scenario's record rate"
    )
    filter: NonNegTime = Field(0.0, description="first-order filter time constant [s]")
    gain: float = Field(1.0, description="calibration gain g in y = g·x + b")
    noise: Annotated[Length, Field(ge=0)] = Field(
        0.0, description="noise std of the pitch reading [m]"
    )
    offset: Length = Field(0.0, description="calibration offset b [m]")
    range: FloatPair | None = Field(None, description="[low, high] in m")
    quantization: Annotated[float, Field(ge=0)] = Field(0.0, description="resolution [m]")
    delay: NonNegTime = Field(0.0, description="processing delay of the record [s]")
    noise_per_speed: Annotated[float, Field(ge=0)] = Field(0.0, description=NOISE_PER_SPEED_DOC)

    @model_validator(mode="after")
    def _check_pitch(self):
        if (self.relaxed_pitch is None) == (self.relaxed_pitch_law is None):
            raise ValueError(
                "give either relaxed_pitch (a constant L0) or relaxed_pitch_law "
                "(L0(R) = q0 + q1·R³), exactly one of them"
            )
        L0 = self.relaxed_pitch if self.relaxed_pitch is not None else self.relaxed_pitch_law.q0
        if self.pitch_variation is not None and not 10 * self.pitch_variation.std < L0:
            raise ValueError(
                f"pitch_variation.std {self.pitch_variation.std:g} m must be below "
                f"a tenth of the relaxed pitch {L0:g} m"
            )
        if self.range is not None and not self.range[0] < self.range[1]:
            raise ValueError("range must be [low, high] with low < high")
        return self


Sensor = Annotated[
    LoadCell | Encoder | RollDiameter | DancerPosition | PitchLength, Field(discriminator="type")
]


class _Controller(Strict):
    id: Id = Field(
        description="name of the controller, unique in the line; its columns are ctrl.<id>.*"
    )
    element: Id = Field(description="id of the element whose drive the controller commands")
    kp: float = Field(description="proportional gain")
    ki: Annotated[float, Field(ge=0)] = Field(0.0, description="integral gain")
    anti_windup_gain: Annotated[float, Field(ge=0)] | None = Field(
        None, description="back-calculation gain [1/s]; default ki/kp (tracking time kp/ki)"
    )


class SpeedPI(_Controller):
    """Speed PI on a torque-driven element: omega_ref = line speed·(1 + draw)/R + trim/R.
    kp [N m s/rad], ki [N m/rad]."""

    type: Literal["speed_pi"] = Field(description="selects a speed loop")
    master: bool = Field(False, description="the master speed node sets line speed (draw 0)")
    draw: Dimensionless = Field(
        0.0,
        description="relative speed offset from line speed (0.01: 1 % faster); the master has 0",
    )
    torque_feedforward: bool = Field(True, description="add J·d(omega_ref)/dt")
    encoder: Id | None = Field(None, description="encoder sensor read; default true speed")


class InertiaEstimate(Strict):
    """The roll inertia J_est the torque-mode feed-forward uses: ``factor``·J(R_hat) (J(R) of
    physics.md eq. 1.12 at the radius estimate) or a fixed ``value``."""

    factor: Annotated[Dimensionless, Field(ge=0)] | None = Field(
        None, description="J_est = factor·J(R_hat); 1 is the exact inertia"
    )
    value: Annotated[Inertia, Field(ge=0)] | None = Field(
        None, description="J_est = value [kg m^2], whatever the radius"
    )

    @model_validator(mode="after")
    def _check(self):
        if (self.factor is None) == (self.value is None):
            raise ValueError("give the inertia estimate as factor or as value (one of them)")
        return self


def _inertia_from_bool(v):
    # true: the exact J(R_hat); false: no inertia compensation (J_est = 0)
    if isinstance(v, bool):
        return {"factor": 1.0 if v else 0.0}
    return v


class FeedForward(Strict):
    """Terms of the torque-mode feed-forward of a tension PI on an unwind/rewind:
    tau = sgn·R_hat·(T_ref + u) + J_est·alpha + tau_f(omega), sgn = -1 unwind, +1 rewind,
    alpha = a/R_hat - sgn·c_w·v^2/(2π·R_hat^3) (docs/model.md). Every term is on by default."""

    tension: bool = Field(True, description="the tension term sgn·T_ref·R_hat")
    inertia: Annotated[
        InertiaEstimate,
        BeforeValidator(_inertia_from_bool),
        WithJsonSchema(
            {
                "anyOf": [{"type": "boolean"}, InertiaEstimate.model_json_schema()],
                "description": "inertia compensation J_est·alpha: true (J(R_hat)), "
                "false (off), {factor: f} or {value: J}",
            }
        ),
    ] = Field(default_factory=lambda: InertiaEstimate(factor=1.0))
    radius_rate: bool = Field(
        True,
        description="the radius-rate part -sgn·c_w·v^2/(2π·R_hat^3) of alpha (the roll "
        "must spin up as its radius shrinks, physics.md 1.4)",
    )
    friction: bool = Field(
        True, description="friction compensation tau_f(omega) with the element's nominal friction"
    )

    def is_default(self) -> bool:
        """True when every term is on with the exact inertia."""
        return self.tension and self.radius_rate and self.friction and self.inertia.factor == 1.0

    def is_off(self) -> bool:
        """True when every term is off (``feedforward: false``)."""
        return not (
            self.tension
            or self.radius_rate
            or self.friction
            or self.inertia.value
            or self.inertia.factor
        )


def _feedforward_from_bool(v):
    # the historical master switch: true = every term, false = none
    if isinstance(v, bool):
        return {"tension": v, "inertia": v, "radius_rate": v, "friction": v}
    return v


class TensionPI(_Controller):
    """Tension PI reading a load cell. On an unwind/rewind with a torque drive it commands
    torque (radius-compensated feed-forward T_ref·R + load-cell trim, kp [N/N], ki [N/(N s)]);
    on a speed-controlled element it trims the surface speed (kp [(m/s)/N], ki [(m/s)/(N s)])."""

    type: Literal["tension_pi"] = Field(description="selects a tension loop")
    sensor: Id = Field(description="id of the load_cell or pitch_length sensor the loop reads")
    setpoint: Annotated[Force, Field(ge=0)] = Field(
        description="tension set-point [N] (the scenario's programme can change it)"
    )
    output_limit: Annotated[float, Field(gt=0)] | None = Field(
        None, description="|PI output| limit: N (torque mode) or m/s (speed trim)"
    )
    feedforward: Annotated[
        FeedForward,
        BeforeValidator(_feedforward_from_bool),
        WithJsonSchema(
            {
                "anyOf": [{"type": "boolean"}, FeedForward.model_json_schema()],
                "description": "torque mode: true (every term), false (none) or the "
                "terms {tension, inertia, radius_rate, friction}",
            }
        ),
    ] = Field(default_factory=FeedForward)
    radius_sensor: Id | None = Field(
        None, description="roll_diameter sensor for the radius estimate; default true radius"
    )


class DancerPI(_Controller):
    """Dancer (or festoon) position loop: trims the surface speed of ``element`` (a
    speed-controlled element upstream or downstream of the dancer) by
    kp·e + ki·∫e, e = setpoint - position, limited to ±output_limit (physics.md §1.10).
    kp [(m/s)/m] or [(m/s)/rad]. The sign is chosen from the geometry so that a dancer
    short of web speeds an upstream element up (or slows a downstream one)."""

    type: Literal["dancer_pi"] = Field(description="selects a dancer (or festoon) position loop")
    dancer: Id = Field(description="dancer element id or festoon span id")
    sensor: Id | None = Field(None, description="dancer_position sensor; default true position")
    setpoint: float | None = Field(
        None, description="position set-point; default the initial position"
    )
    output_limit: Annotated[float, Field(gt=0)] | None = Field(None, description="[m/s]")


Controller = Annotated[SpeedPI | TensionPI | DancerPI, Field(discriminator="type")]


class Line(Strict):
    """A roll-to-roll line."""

    name: str | None = Field(None, description="name of the line, for messages and the dataset")
    description: str | None = Field(None, description="free text")
    span_model: Literal["exact", "linear"] = Field(
        "exact", description="exact mass conservation (default) or the textbook linear form"
    )
    web: Web = Field(description="the web material and its cross-section")
    elements: Annotated[list[Element], Field(min_length=2, max_length=MAX_LINE_ITEMS)] = Field(
        description="rolls and rollers in web order; span i joins element i-1 to element i"
    )
    spans: Annotated[list[Span], Field(max_length=MAX_LINE_ITEMS)] = Field(
        description="one entry per span (number of elements - 1), in web order"
    )
    sensors: Annotated[list[Sensor], Field(max_length=MAX_LINE_ITEMS)] = Field(
        description="measurements; each records meas.* and true.* columns", default_factory=list
    )
    controllers: Annotated[list[Controller], Field(max_length=MAX_LINE_ITEMS)] = Field(
        description="speed, tension and dancer loops", default_factory=list
    )

    @model_validator(mode="after")
    def _cross_check(self):
        problems = check_line(self)
        if problems:
            path, msg = problems[0]
            raise ValueError(f"@{path}@ {msg}")
        for i, span in enumerate(self.spans):
            if span.id is None:
                span.id = f"span{i + 1}"
        _dancer_readings_in_si(self)
        return self

    # convenience look-ups (not used in the solver path)
    def element(self, element_id: str):
        """Return the element with this id."""
        return next(e for e in self.elements if e.id == element_id)


def rebuild_element_union() -> None:
    """Rebuild :class:`Line` with the union of the kinds registered now (the registry calls
    this when a kind is registered or removed): the field keeps its constraints and
    description, only the type of an entry changes; the key reference and the loader's
    did-you-mean read the field's annotation, so they follow."""
    field = Line.model_fields["elements"]
    # a union built at run time (a type checker cannot read list[...] of it); pydantic's
    # FieldInfo.annotation is declared type[Any] | None but holds any annotation
    field.annotation = list[element_union()]  # type: ignore[misc, assignment]
    Line.model_rebuild(force=True)


def dancer_reading_dimension(line: Line, sensor) -> str:
    """Dimension of a dancer_position sensor's reading: the arm angle of a pivoted dancer,
    else the travel of a dancer or festoon carriage."""
    el = next((e for e in line.elements if e.id == sensor.element), None)
    return "angle" if el is not None and kind_of(el).coordinate_unit == "rad" else "length"


def _dancer_readings_in_si(line: Line) -> None:
    """A dancer_position sensor's noise and offset in SI, in the unit its dancer fixes (a
    length or an angle: known only once the line is)."""
    for j, s in enumerate(line.sensors):
        if s.type != "dancer_position":
            continue
        dim = dancer_reading_dimension(line, s)
        for key in ("noise", "offset"):
            try:
                value = parse_quantity(getattr(s, key), dim)
            except QuantityError as exc:
                raise ValueError(f"@sensors[{j}].{key}@ {exc}") from None
            if key == "noise" and value < 0:
                raise ValueError(f"@sensors[{j}].noise@ must be >= 0, got {value:g}")
            setattr(s, key, value)


def check_line(line: Line) -> list[tuple[str, str]]:
    """Cross-field checks of a line; returns ``[(yaml_path, message), ...]`` in the order
    of the checks (the first is the one reported)."""
    ix = _LineIndex.of(line)
    return [
        *_check_topology(line),
        *_check_geometry(line),
        *_check_sensors(line, ix),
        *_check_dancer_loops(line, ix),
        *_check_splicers(line, ix),
        *_check_drive_loops(line, ix),
        *_check_tension_loops(line, ix),
        *_check_torque_commands(line),
    ]


@dataclass
class _LineIndex:
    """Look-ups the cross checks share."""

    by_id: dict  # element id -> (index, element)
    movers: set  # dancers and festoon spans
    sensors: dict  # sensor id -> sensor
    span_names: set
    speed_ctrl: dict  # element id -> index of its speed_pi

    @classmethod
    def of(cls, line: Line) -> _LineIndex:
        els = line.elements
        festoons = {
            sp.id or f"span{i + 1}" for i, sp in enumerate(line.spans) if sp.festoon is not None
        }
        return cls(
            by_id={e.id: (i, e) for i, e in enumerate(els)},
            movers={e.id for e in els if kind_of(e).is_mover} | festoons,
            sensors={s.id: s for s in line.sensors},
            span_names={sp.id or f"span{i + 1}" for i, sp in enumerate(line.spans)},
            speed_ctrl={
                c.element: j for j, c in enumerate(line.controllers) if c.type == "speed_pi"
            },
        )


def _check_topology(line: Line) -> list[tuple[str, str]]:
    """An unwind first, a rewind last, a span between each pair, unique ids, rolls larger
    than their cores."""
    out: list[tuple[str, str]] = []
    els = line.elements
    if kind_of(els[0]).node_kind != "UNWIND":
        out.append(
            ("elements[0].type", f"the first element must be an unwind, got '{els[0].type}'")
        )
    if kind_of(els[-1]).node_kind != "REWIND":
        out.append(
            (
                f"elements[{len(els) - 1}].type",
                f"the last element must be a rewind, got '{els[-1].type}'",
            )
        )
    for i, e in enumerate(els[1:-1], start=1):
        if kind_of(e).is_roll:
            out.append((f"elements[{i}].type", f"'{e.type}' is allowed only at the line ends"))
    if len(line.spans) != len(els) - 1:
        out.append(
            (
                "spans",
                f"expected {len(els) - 1} spans (one between each pair of consecutive "
                f"elements), got {len(line.spans)}",
            )
        )
    seen: dict[str, str] = {}
    groups = [
        ("elements", els),
        ("spans", line.spans),
        ("sensors", line.sensors),
        ("controllers", line.controllers),
    ]
    for group, items in groups:
        for i, item in enumerate(items):
            if item.id is None:
                continue
            if item.id in seen:
                out.append((f"{group}[{i}].id", f"duplicate id '{item.id}' (also {seen[item.id]})"))
            seen[item.id] = f"{group}[{i}]"
    for i, e in enumerate(els):
        if kind_of(e).is_roll:
            r = e.roll
            if r.core_radius >= r.outer_radius:
                out.append(
                    (
                        f"elements[{i}].roll.core_radius",
                        f"core radius {r.core_radius:g} m must be smaller than the roll's "
                        f"outer radius {r.outer_radius:g} m",
                    )
                )
    return out


def _check_sensors(line: Line, ix: _LineIndex) -> list[tuple[str, str]]:
    """Every sensor sits on something that exists and can carry it."""
    out: list[tuple[str, str]] = []
    by_id = ix.by_id
    for j, s in enumerate(line.sensors):
        if s.type == "pitch_length":
            if s.span not in ix.span_names:
                out.append((f"sensors[{j}].span", _missing("span", s.span, ix.span_names)))
            out += _check_pitch_law(j, s, by_id)
            continue
        if s.type == "dancer_position":
            if s.element not in ix.movers:
                out.append(
                    (
                        f"sensors[{j}].element",
                        _missing("dancer or festoon span", s.element, ix.movers),
                    )
                )
            continue
        if s.element not in by_id:
            out.append((f"sensors[{j}].element", _missing("element", s.element, by_id)))
            continue
        _, e = by_id[s.element]
        if s.type == "roll_diameter" and not kind_of(e).is_roll:
            out.append(
                (
                    f"sensors[{j}].element",
                    f"a roll_diameter sensor needs an unwind or rewind, '{e.id}' is {e.type}",
                )
            )
        if s.type in ("encoder", "load_cell") and not hasattr(e, "friction"):
            out.append((f"sensors[{j}].element", f"'{e.id}' cannot carry a {s.type}"))
        elif s.type == "load_cell" and sum(load_cell_weights(line, by_id[s.element][0], s)) <= 1e-9:
            out.append(
                (
                    f"sensors[{j}].axis_angle",
                    f"load cell '{s.id}': its measuring axis sees no tension",
                )
            )
    return out


def _check_dancer_loops(line: Line, ix: _LineIndex) -> list[tuple[str, str]]:
    """A dancer_pi reads a position sensor on its dancer and trims a speed."""
    out: list[tuple[str, str]] = []
    sensors = ix.sensors
    for j, c in enumerate(line.controllers):
        if c.type != "dancer_pi":
            continue
        p = f"controllers[{j}]"
        if c.dancer not in ix.movers:
            out.append((f"{p}.dancer", _missing("dancer or festoon span", c.dancer, ix.movers)))
        if c.sensor is not None:
            s = sensors.get(c.sensor)
            if s is None or s.type != "dancer_position":
                out.append(
                    (
                        f"{p}.sensor",
                        _missing(
                            "dancer_position sensor",
                            c.sensor,
                            {k: v for k, v in sensors.items() if v.type == "dancer_position"},
                        ),
                    )
                )
            elif s.element != c.dancer:
                out.append(
                    (f"{p}.sensor", f"sensor '{s.id}' is on '{s.element}', not on '{c.dancer}'")
                )
        if c.element not in ix.by_id:
            out.append((f"{p}.element", _missing("element", c.element, ix.by_id)))
            continue
        drive = getattr(ix.by_id[c.element][1], "drive", None)
        if drive is None or (drive.type == "torque" and c.element not in ix.speed_ctrl):
            out.append(
                (
                    f"{p}.element",
                    f"a dancer_pi trims a speed: '{c.element}' needs an "
                    f"ideal_speed drive or a speed_pi",
                )
            )
    return out


def _check_splicers(line: Line, ix: _LineIndex) -> list[tuple[str, str]]:
    """A splicer has its spare roll, a trigger radius within the rolls, and what a
    zero-speed splice needs (speed control, a web store)."""
    out: list[tuple[str, str]] = []
    for i, e in enumerate(line.elements):
        sp = getattr(e, "splicer", None)
        if sp is None:
            continue
        p = f"elements[{i}]"
        if e.spare_roll is None:
            out.append((f"{p}.spare_roll", "a splicer needs the spare roll it loads"))
        elif sp.trigger_radius is not None and not (
            e.roll.core_radius < sp.trigger_radius < e.spare_roll.outer_radius
        ):
            out.append(
                (
                    f"{p}.splicer.trigger_radius",
                    f"{sp.trigger_radius:g} m must lie between the core radius "
                    f"{e.roll.core_radius:g} m and the spare roll's radius "
                    f"{e.spare_roll.outer_radius:g} m",
                )
            )
        if sp.type == "zero_speed":
            if e.id not in ix.speed_ctrl and e.drive.type != "ideal_speed":
                out.append(
                    (
                        f"{p}.splicer.type",
                        "a zero_speed splice stops the unwind under "
                        "speed control: add a speed_pi on it",
                    )
                )
            if not ix.movers:
                out.append(
                    (
                        f"{p}.splicer.type",
                        "a zero_speed splice needs a dancer or a "
                        "festoon to supply web while the roll stops",
                    )
                )
    return out


def _check_drive_loops(line: Line, ix: _LineIndex) -> list[tuple[str, str]]:
    """Speed and tension loops act on a driven element and read the right sensors; one
    master speed node at most."""
    out: list[tuple[str, str]] = []
    sensors, speed_ctrl = ix.sensors, ix.speed_ctrl
    for j, c in enumerate(line.controllers):
        p = f"controllers[{j}]"
        if c.type == "dancer_pi":
            continue
        if c.element not in ix.by_id:
            out.append((f"{p}.element", _missing("element", c.element, ix.by_id)))
            continue
        _, e = ix.by_id[c.element]
        drive = getattr(e, "drive", None)
        if drive is None:
            out.append((f"{p}.element", f"'{e.id}' is an {e.type} and has no drive to control"))
            continue
        if c.type == "speed_pi":
            if speed_ctrl.get(c.element, j) != j:
                out.append(
                    (
                        f"{p}.element",
                        f"'{e.id}' already has a speed controller "
                        f"(controllers[{speed_ctrl[c.element]}])",
                    )
                )
            if drive.type != "torque":
                out.append(
                    (
                        f"{p}.element",
                        f"speed_pi needs a torque drive; '{e.id}' has an "
                        f"ideal_speed drive (its speed is already imposed)",
                    )
                )
            if c.encoder is not None:
                s = sensors.get(c.encoder)
                if s is None or s.type != "encoder":
                    out.append((f"{p}.encoder", _missing("encoder sensor", c.encoder, sensors)))
                elif s.element != c.element:
                    out.append(
                        (
                            f"{p}.encoder",
                            f"encoder '{s.id}' is on '{s.element}', not on '{c.element}'",
                        )
                    )
            if c.master and c.draw != 0:
                out.append(
                    (f"{p}.draw", "the master speed node defines line speed: draw must be 0")
                )
        else:
            s = sensors.get(c.sensor)
            if s is None or s.type not in ("load_cell", "pitch_length"):
                out.append(
                    (
                        f"{p}.sensor",
                        _missing(
                            "load_cell or pitch_length sensor",
                            c.sensor,
                            {
                                k: v
                                for k, v in sensors.items()
                                if v.type in ("load_cell", "pitch_length")
                            },
                        ),
                    )
                )
            if c.radius_sensor is not None:
                s = sensors.get(c.radius_sensor)
                if s is None or s.type != "roll_diameter":
                    out.append(
                        (
                            f"{p}.radius_sensor",
                            _missing("roll_diameter sensor", c.radius_sensor, sensors),
                        )
                    )
                elif s.element != c.element:
                    out.append(
                        (
                            f"{p}.radius_sensor",
                            f"sensor '{s.id}' is on '{s.element}', not on '{c.element}'",
                        )
                    )
    masters = [j for j, c in enumerate(line.controllers) if c.type == "speed_pi" and c.master]
    if len(masters) > 1:
        out.append((f"controllers[{masters[1]}].master", "only one master speed node is allowed"))
    return out


def _check_tension_loops(line: Line, ix: _LineIndex) -> list[tuple[str, str]]:
    """One tension loop per element, in a mode its drive supports, with feed-forward
    only in torque mode."""
    out: list[tuple[str, str]] = []
    tension_ctrl: dict[str, int] = {}
    for j, c in enumerate(line.controllers):
        if c.type != "tension_pi" or c.element not in ix.by_id:
            continue
        p = f"controllers[{j}]"
        _, e = ix.by_id[c.element]
        drive = getattr(e, "drive", None)
        if drive is None:
            continue
        if c.element in tension_ctrl:
            out.append(
                (
                    f"{p}.element",
                    f"'{e.id}' already has a tension controller "
                    f"(controllers[{tension_ctrl[c.element]}])",
                )
            )
        tension_ctrl[c.element] = j
        roll = kind_of(e).is_roll
        if drive.type == "torque" and not roll and c.element not in ix.speed_ctrl:
            out.append(
                (
                    f"{p}.element",
                    f"a tension_pi on driven element '{e.id}' trims its speed "
                    f"and needs a speed_pi on the same element",
                )
            )
        if drive.type == "torque" and roll and c.element in ix.speed_ctrl:
            out.append(
                (
                    f"{p}.element",
                    f"'{e.id}' has both a speed_pi and a torque-mode tension_pi; use one of them",
                )
            )
        if c.radius_sensor is not None and not roll:
            out.append((f"{p}.radius_sensor", "a radius sensor applies only to unwind/rewind"))
        ff = c.feedforward
        if not (roll and drive.type == "torque") and not (ff.is_default() or ff.is_off()):
            out.append(
                (
                    f"{p}.feedforward",
                    f"feed-forward terms apply to torque mode (a "
                    f"tension_pi on an unwind/rewind with a torque "
                    f"drive); on '{e.id}' the loop trims a speed",
                )
            )
    return out


def _check_torque_commands(line: Line) -> list[tuple[str, str]]:
    """A torque command needs a torque drive that no loop already commands."""
    out: list[tuple[str, str]] = []
    for i, e in enumerate(line.elements):
        drive = getattr(e, "drive", None)
        if drive is None or drive.torque_command is None:
            continue
        problem: str | None
        if drive.type != "torque":
            problem = (
                "an ideal_speed drive imposes the speed; a torque command needs a torque drive"
            )
        else:
            problem = torque_problem(line, e.id)
        if problem:
            out.append((f"elements[{i}].drive.torque_command", problem))
    return out


def _commanding_controller(line: Line, element_id: str):
    """(index, controller) of the speed_pi or torque-mode tension_pi that commands the torque
    of an element, or None."""
    e = line.element(element_id)
    roll = kind_of(e).is_roll
    for j, c in enumerate(line.controllers):
        if c.element != element_id:
            continue
        if c.type == "speed_pi" or (c.type == "tension_pi" and roll):
            return j, c
    return None


def _drive_of(line: Line, element_id: str, purpose: str):
    """``(drive, None)`` of an element, or ``(None, why not)`` if it is unknown or has no
    drive (``purpose`` ends that message)."""
    ids = [e.id for e in line.elements]
    if element_id not in ids:
        return None, f"no element '{element_id}' in the line (known: {', '.join(ids)})"
    e = line.element(element_id)
    drive = getattr(e, "drive", None)
    if drive is None:
        return None, f"'{element_id}' ({e.type}) has no drive, {purpose}"
    return drive, None


def draw_problem(line: Line, element_id: str) -> str | None:
    """Why the draw (speed ratio to the line) of an element cannot be programmed, or None.

    A draw belongs to an ideal_speed drive (``drive.draw``) or to a non-master speed_pi
    (``draw``)."""
    drive, problem = _drive_of(line, element_id, "so no draw")
    if problem:
        return problem
    if drive.type == "ideal_speed":
        return None
    cc = _commanding_controller(line, element_id)
    if cc is None:
        return (
            f"'{element_id}' has a torque drive without a speed_pi: it has no speed "
            f"reference to draw"
        )
    j, c = cc
    if c.type == "tension_pi":
        return (
            f"'{element_id}' is tension-controlled in torque mode (controllers[{j}]): it "
            f"has no speed reference to draw"
        )
    if c.master:
        return (
            f"'{element_id}' is the master speed node (controllers[{j}]): it defines line "
            f"speed, so its draw stays 0"
        )
    return None


def torque_problem(line: Line, element_id: str) -> str | None:
    """Why an element's drive cannot take an open-loop torque command, or None (it needs a
    torque drive that no speed_pi or torque-mode tension_pi commands)."""
    drive, problem = _drive_of(line, element_id, "so no torque command")
    if problem:
        return problem
    if drive.type != "torque":
        return (
            f"'{element_id}' has an ideal_speed drive (its speed is imposed); a torque "
            f"command needs a torque drive"
        )
    cc = _commanding_controller(line, element_id)
    if cc is not None:
        j, c = cc
        return (
            f"the torque of '{element_id}' is commanded by {c.type} '{c.id}' "
            f"(controllers[{j}]); a torque command is for a drive without a controller"
        )
    return None


def pitch_unwind(line: Line, sensor) -> str:
    """Id of the unwind whose radius and unwound length a pitch_length sensor's relaxed pitch
    follows (its law's ``unwind``, else the line's first element)."""
    law = sensor.relaxed_pitch_law
    return law.unwind if law is not None and law.unwind is not None else line.elements[0].id


def _check_pitch_law(j: int, s, by_id) -> list[tuple[str, str]]:
    """The relaxed-pitch law of a pitch_length sensor names an unwind and stays positive."""
    law = s.relaxed_pitch_law
    if law is None:
        return []
    p = f"sensors[{j}].relaxed_pitch_law"
    if law.unwind is not None:
        if law.unwind not in by_id:
            return [(f"{p}.unwind", _missing("element", law.unwind, by_id))]
        e = by_id[law.unwind][1]
        if not kind_of(e).pays_out:
            return [(f"{p}.unwind", f"'{e.id}' is a {e.type}, not an unwind")]
    else:
        e = next(iter(by_id.values()))[1]
        if not kind_of(e).pays_out:
            return []  # reported for elements[0]
    rolls = [e.roll] + ([e.spare_roll] if e.spare_roll is not None else [])
    for r in rolls:
        for R in (r.core_radius, r.outer_radius):
            L0 = law.q0 + law.q1 * R**3
            if not L0 > 0:
                return [
                    (
                        f"{p}.q1",
                        f"L0 = q0 + q1·R³ = {L0:g} m at R = {R:g} m of '{e.id}'; "
                        "the relaxed pitch must stay positive over the roll",
                    )
                ]
    return []


def _check_geometry(line: Line) -> list[tuple[str, str]]:
    """Span lengths, festoons and the dancer geometry."""
    out: list[tuple[str, str]] = []
    els = line.elements
    for i, sp in enumerate(line.spans):
        if i + 1 >= len(els):
            break
        a, b = els[i], els[i + 1]
        near_dancer = kind_of(a).is_mover or kind_of(b).is_mover
        if kind_of(a).is_mover and kind_of(b).is_mover:
            out.append(
                (
                    f"spans[{i}]",
                    f"two dancers next to each other ('{a.id}', '{b.id}') "
                    f"are not supported; put a roller between them",
                )
            )
        elif near_dancer and sp.length is not None:
            out.append(
                (
                    f"spans[{i}].length",
                    "the length of a span next to a dancer comes from "
                    "the geometry (positions); leave it out",
                )
            )
        elif not near_dancer and sp.length is None:
            out.append((f"spans[{i}].length", "missing: give the span's free length"))
        if sp.festoon is not None:
            f = sp.festoon
            if near_dancer:
                out.append((f"spans[{i}].festoon", "a festoon span cannot end on a dancer"))
            if not f.stroke[0] < f.stroke[1]:
                out.append(
                    (f"spans[{i}].festoon.stroke", "must be [x_min, x_max] with x_min < x_max")
                )
            elif not f.stroke[0] <= f.initial_position <= f.stroke[1]:
                out.append(
                    (
                        f"spans[{i}].festoon.initial_position",
                        f"{f.initial_position:g} m is outside the stroke {list(f.stroke)}",
                    )
                )
            elif sp.length is not None and sp.length + 2 * f.moving_rollers * f.stroke[0] <= 0:
                out.append(
                    (
                        f"spans[{i}].festoon.stroke",
                        "the span length length + 2n·x_min must stay positive",
                    )
                )
    for i, e in enumerate(els):
        kind = kind_of(e)
        p = f"elements[{i}]"
        out += kind.check(e, p)
        if not kind.is_mover:
            continue
        placed = True
        for j in (i - 1, i + 1):
            n = els[j]
            if n.position is None or n.wrap is None:
                placed = False
                out.append(
                    (
                        f"elements[{j}].position",
                        f"'{n.id}' is next to dancer '{e.id}': give its position and wrap",
                    )
                )
        problem = dancer_overlap(line, i) if placed and not out else None
        if problem:
            out.append((p, problem))
    return out


def wrap_sign(e) -> float:
    """+1 where the web travels counter-clockwise around the roller (it lies on the left)."""
    return 1.0 if e.wrap == "ccw" else -1.0


def roller_radius(e) -> float:
    """Outer radius of a roller, or of a roll (full for an unwind, as declared)."""
    return kind_of(e).surface_radius(e)


def dancer_offsets(line: Line, k: int) -> tuple[float, float]:
    """Signed offsets of the tangent lines of the dancer at element k from the lines
    between roller centres: upstream (neighbour k-1 to the dancer) and downstream."""
    e, a, b = line.elements[k], line.elements[k - 1], line.elements[k + 1]
    sd = wrap_sign(e)
    return (
        sd * e.radius - wrap_sign(a) * roller_radius(a),
        wrap_sign(b) * roller_radius(b) - sd * e.radius,
    )


def dancer_centre(e, q: float) -> tuple[float, float]:
    """Roller centre of dancer ``e`` at travel q [m] (a linear dancer) or arm angle q [rad]
    (a pivot dancer): its kind's geometry."""
    return kind_of(e).centre(e, q)


def dancer_overlap(line: Line, k: int) -> str | None:
    """Whether the dancer at element k, at either end of its range or where it starts,
    comes so close to a neighbour that the web has no tangent between them."""
    e = line.elements[k]
    kind = kind_of(e)
    lo, hi = kind.mover_range(e)
    q0 = kind.mover_start(e)
    du, dd = dancer_offsets(line, k)
    for q in (lo, hi, q0):
        cx, cy = dancer_centre(e, q)
        for side, (x, y), delta in (
            ("upstream", line.elements[k - 1].position, du),
            ("downstream", line.elements[k + 1].position, dd),
        ):
            dist = math.hypot(cx - x, cy - y)
            if dist <= abs(delta) + 1e-9:
                return (
                    f"at position {q:g} the dancer roller overlaps its {side} neighbour "
                    f"(centre distance {dist:.4g} m): check positions and ranges"
                )
    return None


def load_cell_weights(line: Line, k: int, sensor) -> tuple[float, float]:
    """(c_in, c_out): the components along a load cell's measuring axis of the tensions of
    the spans entering and leaving element k (physics.md §1.3); a line end has one span."""
    e = line.elements[k]
    beta = sensor.wrap_angle or e.wrap_angle or math.pi
    half = 0.5 * (math.pi - beta)
    cin = math.cos(half - sensor.axis_angle) if k > 0 else 0.0
    cout = math.cos(half + sensor.axis_angle) if k < len(line.elements) - 1 else 0.0
    return cin, cout


def _missing(what: str, name: str, known) -> str:
    names = ", ".join(sorted(known)) or "none defined"
    return f"no {what} with id '{name}' (known: {names})"
