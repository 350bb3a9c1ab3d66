"""Building blocks the line models share: the strict base model, ids and pairs, and the
parts of elements (bearing friction, drive, roll, splicer, the element base) that several
element kinds use (r2rsim/schema/kinds/). Kept apart from line.py so that the kind modules,
which line.py's element union is built from, can import them without a cycle; line.py
re-exports every name."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Annotated, Literal, TypeAlias

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field

from .quantities import (
    Acceleration,
    Angle,
    AngularSpeed,
    Dimensionless,
    Force,
    Frequency,
    Inertia,
    Length,
    NumberOrText,
    Time,
    Torque,
    ViscousTorque,
)


def _list_to_tuple(value):
    return tuple(value) if isinstance(value, list) else value


def pair(item):
    """``[a, b]`` of two ``item`` values: a YAML list is accepted for the tuple (the items
    stay strict). The list is turned into a tuple before validation: ``Field(strict=False)``
    alone is not honoured inside a union before pydantic 2.11."""
    return Annotated[tuple[item, item], BeforeValidator(_list_to_tuple)]


ID_PATTERN = r"^[A-Za-z][A-Za-z0-9_]*$"
Id = Annotated[str, Field(pattern=ID_PATTERN, max_length=64)]
PosLength = Annotated[Length, Field(gt=0)]
NonNegTime = Annotated[Time, Field(ge=0)]
if TYPE_CHECKING:  # a type checker cannot evaluate pair(...); it sees the tuples
    FloatPair: TypeAlias = tuple[float, float]
    LengthPair: TypeAlias = tuple[float, float]
    AnglePair: TypeAlias = tuple[float, float]
    AccelerationPair: TypeAlias = tuple[float, float]
    Vec2: TypeAlias = tuple[float, float]
    NumberOrTextPair: TypeAlias = tuple[float | str, float | str]
else:
    FloatPair, LengthPair = pair(float), pair(Length)
    AnglePair, AccelerationPair = pair(Angle), pair(Acceleration)
    Vec2 = LengthPair
    NumberOrTextPair = pair(NumberOrText)
Wrap = Literal["cw", "ccw"]
GRAVITY = (0.0, -9.81)


class Strict(BaseModel):
    """Base model of every line and scenario model: unknown keys are errors, and every
    number is strict and finite.

    ``strict``: a boolean is not a number (``std: true`` is refused, not read as 1.0), a
    number is not a boolean, a string is not a plain number (quantities, which take unit
    strings, convert them first); an integer is still accepted where a float is expected.
    ``allow_inf_nan=False``: ``.nan``, ``.inf`` and ``-.inf`` are refused for every float
    field, in lists and dict values too. Tuples (``[x, y]`` pairs) are declared with
    :func:`pair`, which accepts the YAML list.
    """

    model_config = ConfigDict(extra="forbid", frozen=False, strict=True, allow_inf_nan=False)


class Friction(Strict):
    """Bearing friction tau_f = viscous·omega + coulomb·tanh(omega/smoothing_speed)."""

    viscous: Annotated[ViscousTorque, Field(ge=0)] = Field(
        0.0, description="viscous bearing friction coefficient: torque per angular speed [N m s]"
    )
    coulomb: Annotated[Torque, Field(ge=0)] = Field(
        0.0, description="Coulomb (dry) bearing friction torque [N m]"
    )
    smoothing_speed: Annotated[AngularSpeed, Field(gt=0)] = Field(
        1e-2, description="tanh smoothing of the Coulomb term near zero speed [rad/s]"
    )


class TorqueRipple(Strict):
    """A sinusoidal disturbance torque amplitude·sin(2π·frequency·t) at a drive's shaft."""

    amplitude: Annotated[Torque, Field(ge=0)] = Field(description="ripple torque amplitude [N m]")
    frequency: Annotated[Frequency, Field(gt=0)] = Field(description="ripple frequency [Hz]")


class Drive(Strict):
    """A motor drive. ``torque``: first-order torque lag and saturation, commanded by the
    element's controllers, or open loop by ``torque_command``. ``ideal_speed``: the surface
    speed is imposed (line speed x (1 + draw) + trim), a kinematic node for verification and
    idealised studies."""

    type: Literal["torque", "ideal_speed"] = Field(
        "torque",
        description="torque: a motor with a first-order torque loop, commanded by a "
        "controller or torque_command; ideal_speed: an imposed surface speed (line speed x (1 + "
        "draw))",
    )
    torque_lag: NonNegTime = Field(1e-3, description="current/torque loop time constant [s]")
    torque_max: Annotated[Torque, Field(gt=0)] | None = Field(
        None, description="torque saturation |tau| <= torque_max [N m]"
    )
    draw: Dimensionless = Field(0.0, description="ideal_speed only: relative speed offset")
    torque_ripple: TorqueRipple | None = Field(
        None,
        description="sinusoidal torque disturbance added at the shaft (cogging, "
        "gear mesh, an eccentric load)",
    )
    torque_command: Torque | None = Field(
        None,
        description="torque drive without a controller: constant torque command [N m] "
        "(positive drives the web forward); a scenario's programme can change it (torque:)",
    )


class Roll(Strict):
    """A wound roll on an unwind or rewind."""

    core_radius: PosLength = Field(description="radius of the empty core [m]")
    outer_radius: PosLength = Field(description="radius at the start of the run [m]")
    core_inertia: Annotated[Inertia, Field(ge=0)] = Field(
        description="core + shaft + chucks + reflected rotor inertia [kg m^2]"
    )
    build_per_wrap: PosLength | None = Field(
        None, description="radial build per wrap c_w [m]; default: the web thickness"
    )
    wound_in_strain: (
        Dimensionless | Annotated[list[Dimensionless], Field(min_length=1, max_length=3)]
    ) = Field(
        0.0,
        description="strain frozen into the roll when it was wound (the unwind's inflow "
        "strain): a number, or polynomial coefficients [e0, e1, e2] of e0 + e1·R + e2·R^2 over "
        "the roll radius R in m, so tension drifts over a roll (thesis eq. 2.22)",
    )

    def wound_in_coefficients(self) -> tuple[float, float, float]:
        """(e0, e1, e2) of the wound-in strain e0 + e1·R + e2·R²."""
        c = (
            self.wound_in_strain
            if isinstance(self.wound_in_strain, list)
            else [self.wound_in_strain]
        )
        c = [*c, 0.0, 0.0, 0.0]
        return float(c[0]), float(c[1]), float(c[2])


class ElementBase(Strict):
    """Keys every element kind has (its id, stage, bearing friction, wrap and position)."""

    id: Id = Field(
        description="name of the element, unique in the line (letters, digits, _); sensors and "
        "controllers refer to it"
    )
    stage: Annotated[int, Field(ge=1)] | None = Field(None, description="thesis stage 1..5")
    friction: Friction = Field(
        default_factory=Friction, description="bearing friction of the element's shaft"
    )
    wrap_angle: Annotated[Angle, Field(gt=0, le=2 * math.pi)] | None = Field(
        None, description="wrap angle of the web on this element [rad]"
    )
    friction_coefficient: Annotated[Dimensionless, Field(gt=0)] | None = Field(
        None,
        description="web-roller friction coefficient mu; with wrap_angle enables the "
        "capstan (slip-risk) monitor",
    )
    position: Vec2 | None = Field(
        None,
        description="roller centre [x, y] in m (y up); needed next to a dancer, whose "
        "span lengths come from the geometry",
    )
    wrap: Wrap | None = Field(
        None,
        description="direction the web travels around this roller seen with x right and "
        "y up: cw or ccw; needed with position",
    )


class SpliceJoint(Strict):
    """The taped overlap a splice leaves in the web (physics.md eq. 1.19)."""

    length: PosLength = Field(0.05, description="overlap length l_s [m]")
    stiffness_ratio: Annotated[Dimensionless, Field(ge=1)] = Field(
        2.0, description="(EA)_s / EA of the overlap (two webs plus tape: about 2)"
    )
    break_tension: Annotated[Force, Field(gt=0)] | None = Field(
        None, description="break limit of the joint [N]; default the web's"
    )


class Splicer(Strict):
    """Roll change on an unwind (physics.md §1.7). ``zero_speed``: fill the dancer/festoon,
    brake the expiring roll to rest, splice during ``dwell``, accelerate the new roll, refill.
    The unwind needs a speed_pi. ``flying``: the new roll is pre-accelerated to line speed
    with a relative speed-match error and swapped in at once."""

    type: Literal["zero_speed", "flying"] = Field(
        description="zero_speed: the roll stops for the splice while a dancer or festoon feeds "
        "the line; flying: the new roll is spliced on at line speed"
    )
    trigger_radius: PosLength | None = Field(
        None,
        description="splice when the running roll's radius falls to this [m]; "
        "otherwise only at the scenario's splice events",
    )
    joint: SpliceJoint = Field(
        default_factory=SpliceJoint, description="the splice joint that travels with the web"
    )
    fill_time: NonNegTime = Field(5.0, description="zero_speed: fill phase duration [s]")
    fill_overspeed: Annotated[Dimensionless, Field(ge=0, le=0.5)] = Field(
        0.08, description="zero_speed: relative overspeed of the unwind while filling/refilling"
    )
    brake_decel: Annotated[Acceleration, Field(gt=0)] = Field(
        2.0, description="zero_speed: surface deceleration of the expiring roll [m/s^2]"
    )
    dwell: NonNegTime = Field(3.0, description="zero_speed: time at rest for the splice [s]")
    accel: Annotated[Acceleration, Field(gt=0)] = Field(
        2.0, description="zero_speed: surface acceleration of the new roll [m/s^2]"
    )
    refill_timeout: Annotated[Time, Field(gt=0)] = Field(
        60.0,
        description="zero_speed: the refill ends when the dancer/festoon is back at its "
        "set-point, or after this time [s]",
    )
    speed_match_error: Annotated[Dimensionless, Field(gt=-0.5, lt=0.5)] = Field(
        0.0,
        description="flying: relative surface-speed error of the new roll (diameter "
        "error), delta in omega_new = v(1 + delta)/R_new",
    )
