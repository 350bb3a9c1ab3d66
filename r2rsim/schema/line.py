"""Pydantic models of a line file (DESIGN.md §4.1).

A line is a list of elements in web order (unwind first, rewind last), the spans between
consecutive elements, the web material, and the sensors and controllers as data. All
quantities are SI floats after validation. Cross-references are checked in
:meth:`Line._cross_check`; its messages start with the YAML path of the problem.
"""

from __future__ import annotations

import math
from typing import Annotated, Literal

from pydantic import BaseModel, ConfigDict, Field, model_validator

from .materials import MATERIALS
from .quantities import (
    Angle,
    AngularSpeed,
    Density,
    Dimensionless,
    Force,
    Frequency,
    Inertia,
    Length,
    Pressure,
    Time,
    Torque,
    ViscousTorque,
)

Id = Annotated[str, Field(pattern=r"^[A-Za-z][A-Za-z0-9_]*$", max_length=64)]
PosLength = Annotated[Length, Field(gt=0)]
NonNegTime = Annotated[Time, Field(ge=0)]


class Strict(BaseModel):
    """Base model: unknown keys are errors."""

    model_config = ConfigDict(extra="forbid", frozen=False)


class Web(Strict):
    """Web material. ``material`` picks a preset (PET, paper, aluminium, copper); any property
    given here overrides the preset."""

    material: Literal["PET", "paper", "aluminium", "aluminum", "copper"] | None = None
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
        return self.modulus * self.area

    @property
    def break_tension(self) -> float:
        """Tension at break [N] (inf when unbreakable or no break stress)."""
        if not self.breakable or self.break_stress is None:
            return math.inf
        return self.break_stress * self.area


class Friction(Strict):
    """Bearing friction tau_f = viscous·omega + coulomb·tanh(omega/smoothing_speed)."""

    viscous: Annotated[ViscousTorque, Field(ge=0)] = 0.0
    coulomb: Annotated[Torque, Field(ge=0)] = 0.0
    smoothing_speed: Annotated[AngularSpeed, Field(gt=0)] = Field(
        1e-2, description="tanh smoothing of the Coulomb term near zero speed [rad/s]"
    )


class TorqueRipple(Strict):
    """A sinusoidal disturbance torque amplitude·sin(2π·frequency·t) at a drive's shaft."""

    amplitude: Annotated[Torque, Field(ge=0)]
    frequency: Annotated[Frequency, Field(gt=0)]


class Drive(Strict):
    """A motor drive. ``torque``: first-order torque lag and saturation, commanded by the
    element's controllers. ``ideal_speed``: the surface speed is imposed (line speed x
    (1 + draw) + trim), a kinematic node for verification and idealised studies."""

    type: Literal["torque", "ideal_speed"] = "torque"
    torque_lag: NonNegTime = Field(1e-3, description="current/torque loop time constant [s]")
    torque_max: Annotated[Torque, Field(gt=0)] | None = Field(
        None, description="torque saturation |tau| <= torque_max [N m]"
    )
    draw: Dimensionless = Field(0.0, description="ideal_speed only: relative speed offset")
    torque_ripple: TorqueRipple | None = Field(
        None, description="sinusoidal torque disturbance added at the shaft (cogging, "
        "gear mesh, an eccentric load)"
    )


class Roll(Strict):
    """A wound roll on an unwind or rewind."""

    core_radius: PosLength
    outer_radius: PosLength = Field(description="radius at the start of the run [m]")
    core_inertia: Annotated[Inertia, Field(ge=0)] = Field(
        description="core + shaft + chucks + reflected rotor inertia [kg m^2]"
    )
    build_per_wrap: PosLength | None = Field(
        None, description="radial build per wrap c_w [m]; default: the web thickness"
    )
    wound_in_strain: Dimensionless = Field(
        0.0, description="strain frozen into the roll when it was wound (unwind inflow strain)"
    )


class _Element(Strict):
    id: Id
    stage: Annotated[int, Field(ge=1)] | None = Field(None, description="thesis stage 1..5")
    friction: Friction = Field(default_factory=Friction)
    wrap_angle: Annotated[Angle, Field(gt=0, le=2 * math.pi)] | None = Field(
        None, description="wrap angle of the web on this element [rad]"
    )
    friction_coefficient: Annotated[Dimensionless, Field(gt=0)] | None = Field(
        None, description="web-roller friction coefficient mu; with wrap_angle enables the "
        "capstan (slip-risk) monitor"
    )


class Unwind(_Element):
    """Unwind stand: a roll paying out web; torque drive (default) or ideal speed."""

    type: Literal["unwind"]
    roll: Roll
    drive: Drive = Field(default_factory=Drive)


class Rewind(_Element):
    """Rewind stand: a roll taking up web."""

    type: Literal["rewind"]
    roll: Roll
    drive: Drive = Field(default_factory=Drive)


class Idler(_Element):
    """Undriven roller."""

    type: Literal["idler"]
    radius: PosLength
    inertia: Annotated[Inertia, Field(gt=0)]


class Driven(_Element):
    """Motor-driven roller (pull roll, S-wrap roller, ...)."""

    type: Literal["driven"]
    radius: PosLength
    inertia: Annotated[Inertia, Field(gt=0)]
    drive: Drive = Field(default_factory=Drive)


class PressureRoller(Strict):
    """The undriven roller of a nip pair."""

    radius: PosLength
    inertia: Annotated[Inertia, Field(ge=0)]
    friction: Friction = Field(default_factory=Friction)


class Nip(_Element):
    """Nip pair clamping the web (no slip): one degree of freedom with
    J_eff = J1 + J2 (R1/R2)^2 (physics.md eq. 1.9). The drive acts on the main roller."""

    type: Literal["nip"]
    radius: PosLength
    inertia: Annotated[Inertia, Field(gt=0)]
    drive: Drive = Field(default_factory=Drive)
    pressure_roller: PressureRoller


Element = Annotated[Unwind | Rewind | Idler | Driven | Nip, Field(discriminator="type")]
ROTATING_WITH_DRIVE = ("unwind", "rewind", "driven", "nip")


class Span(Strict):
    """Free span between consecutive elements."""

    id: Id | None = Field(None, description="default: span1, span2, ... in web order")
    length: PosLength


class _Sensor(Strict):
    id: Id
    element: Id
    rate: Annotated[Frequency, Field(gt=0)] | None = Field(
        None, description="sample rate [Hz]; default: the scenario's record rate"
    )
    filter: NonNegTime = Field(0.0, description="first-order filter time constant [s]")
    gain: float = Field(1.0, description="calibration gain g in y = g·x + b")


class LoadCell(_Sensor):
    """Load cell on a roller: measures the bearing force component along its axis and reports
    the indicated tension (physics.md §1.3)."""

    type: Literal["load_cell"]
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

    type: Literal["encoder"]
    counts_per_rev: Annotated[int, Field(gt=0)] | None = None
    noise: Annotated[AngularSpeed, Field(ge=0)] = 0.0
    offset: AngularSpeed = 0.0


class RollDiameter(_Sensor):
    """Ultrasonic/laser roll-diameter sensor on an unwind or rewind."""

    type: Literal["roll_diameter"]
    noise: Annotated[Length, Field(ge=0)] = 0.0
    offset: Length = 0.0


Sensor = Annotated[LoadCell | Encoder | RollDiameter, Field(discriminator="type")]


class _Controller(Strict):
    id: Id
    element: Id
    kp: float = Field(description="proportional gain")
    ki: Annotated[float, Field(ge=0)] = Field(0.0, description="integral gain")
    anti_windup_gain: Annotated[float, Field(ge=0)] | None = Field(
        None, description="back-calculation gain [1/s]; default ki/kp (tracking time kp/ki)"
    )


class SpeedPI(_Controller):
    """Speed PI on a torque-driven element: omega_ref = line speed·(1 + draw)/R + trim/R.
    kp [N m s/rad], ki [N m/rad]."""

    type: Literal["speed_pi"]
    master: bool = Field(False, description="the master speed node sets line speed (draw 0)")
    draw: Dimensionless = 0.0
    torque_feedforward: bool = Field(True, description="add J·d(omega_ref)/dt")
    encoder: Id | None = Field(None, description="encoder sensor read; default true speed")


class TensionPI(_Controller):
    """Tension PI reading a load cell. On an unwind/rewind with a torque drive it commands
    torque (radius-compensated feed-forward T_ref·R + load-cell trim, kp [N/N], ki [N/(N s)]);
    on a speed-controlled element it trims the surface speed (kp [(m/s)/N], ki [(m/s)/(N s)])."""

    type: Literal["tension_pi"]
    sensor: Id
    setpoint: Annotated[Force, Field(ge=0)]
    output_limit: Annotated[float, Field(gt=0)] | None = Field(
        None, description="|PI output| limit: N (torque mode) or m/s (speed trim)"
    )
    feedforward: bool = Field(True, description="torque mode: T_ref·R + inertia·accel FF")
    radius_sensor: Id | None = Field(
        None, description="roll_diameter sensor for the radius estimate; default true radius"
    )


Controller = Annotated[SpeedPI | TensionPI, Field(discriminator="type")]


class Line(Strict):
    """A roll-to-roll line."""

    name: str | None = None
    description: str | None = None
    span_model: Literal["exact", "linear"] = Field(
        "exact", description="exact mass conservation (default) or the textbook linear form"
    )
    web: Web
    elements: Annotated[list[Element], Field(min_length=2)]
    spans: list[Span]
    sensors: list[Sensor] = Field(default_factory=list)
    controllers: list[Controller] = Field(default_factory=list)

    @model_validator(mode="after")
    def _cross_check(self):
        problems = check_line(self)
        if problems:
            path, msg = problems[0]
            raise ValueError(f"@{path}@ {msg}")
        for i, span in enumerate(self.spans):
            if span.id is None:
                span.id = f"span{i + 1}"
        return self

    # convenience look-ups (not used in the solver path)
    def element(self, element_id: str):
        """Return the element with this id."""
        return next(e for e in self.elements if e.id == element_id)


def check_line(line: Line) -> list[tuple[str, str]]:
    """Cross-field checks of a line; returns ``[(yaml_path, message), ...]``."""
    out: list[tuple[str, str]] = []
    els = line.elements
    if els[0].type != "unwind":
        out.append(("elements[0].type",
                    f"the first element must be an unwind, got '{els[0].type}'"))
    if els[-1].type != "rewind":
        out.append((f"elements[{len(els) - 1}].type",
                    f"the last element must be a rewind, got '{els[-1].type}'"))
    for i, e in enumerate(els[1:-1], start=1):
        if e.type in ("unwind", "rewind"):
            out.append((f"elements[{i}].type", f"'{e.type}' is allowed only at the line ends"))
    if len(line.spans) != len(els) - 1:
        out.append(("spans", f"expected {len(els) - 1} spans (one between each pair of consecutive "
                             f"elements), got {len(line.spans)}"))
    seen: dict[str, str] = {}
    groups = [("elements", els), ("spans", line.spans), ("sensors", line.sensors),
              ("controllers", line.controllers)]
    for group, items in groups:
        for i, item in enumerate(items):
            if item.id is None:
                continue
            if item.id in seen:
                out.append((f"{group}[{i}].id", f"duplicate id '{item.id}' (also {seen[item.id]})"))
            seen[item.id] = f"{group}[{i}]"
    for i, e in enumerate(els):
        if e.type in ("unwind", "rewind"):
            r = e.roll
            if r.core_radius >= r.outer_radius:
                out.append((f"elements[{i}].roll.core_radius",
                            f"core radius {r.core_radius:g} m must be smaller than the roll's "
                            f"outer radius {r.outer_radius:g} m"))
    by_id = {e.id: (i, e) for i, e in enumerate(els)}
    sensors = {s.id: s for s in line.sensors}
    for j, s in enumerate(line.sensors):
        if s.element not in by_id:
            out.append((f"sensors[{j}].element", _missing("element", s.element, by_id)))
            continue
        _, e = by_id[s.element]
        if s.type == "roll_diameter" and e.type not in ("unwind", "rewind"):
            out.append((f"sensors[{j}].element",
                        f"a roll_diameter sensor needs an unwind or rewind, '{e.id}' is {e.type}"))
        if s.type in ("encoder", "load_cell") and not hasattr(e, "friction"):
            out.append((f"sensors[{j}].element", f"'{e.id}' cannot carry a {s.type}"))
    speed_ctrl: dict[str, int] = {}
    for j, c in enumerate(line.controllers):
        p = f"controllers[{j}]"
        if c.element not in by_id:
            out.append((f"{p}.element", _missing("element", c.element, by_id)))
            continue
        _, e = by_id[c.element]
        drive = getattr(e, "drive", None)
        if drive is None:
            out.append((f"{p}.element", f"'{e.id}' is an {e.type} and has no drive to control"))
            continue
        if c.type == "speed_pi":
            if drive.type != "torque":
                out.append((f"{p}.element", f"speed_pi needs a torque drive; '{e.id}' has an "
                                            f"ideal_speed drive (its speed is already imposed)"))
            if c.element in speed_ctrl:
                out.append((f"{p}.element", f"'{e.id}' already has a speed controller "
                                            f"(controllers[{speed_ctrl[c.element]}])"))
            speed_ctrl[c.element] = j
            if c.encoder is not None:
                s = sensors.get(c.encoder)
                if s is None or s.type != "encoder":
                    out.append((f"{p}.encoder", _missing("encoder sensor", c.encoder, sensors)))
                elif s.element != c.element:
                    out.append((f"{p}.encoder", f"encoder '{s.id}' is on '{s.element}', not on "
                                                f"'{c.element}'"))
            if c.master and c.draw != 0:
                out.append((f"{p}.draw",
                            "the master speed node defines line speed: draw must be 0"))
        else:
            s = sensors.get(c.sensor)
            if s is None or s.type != "load_cell":
                out.append((f"{p}.sensor", _missing("load_cell sensor", c.sensor,
                                                    {k: v for k, v in sensors.items()
                                                     if v.type == "load_cell"})))
            if c.radius_sensor is not None:
                s = sensors.get(c.radius_sensor)
                if s is None or s.type != "roll_diameter":
                    out.append((f"{p}.radius_sensor",
                                _missing("roll_diameter sensor", c.radius_sensor, sensors)))
                elif s.element != c.element:
                    out.append((f"{p}.radius_sensor",
                                f"sensor '{s.id}' is on '{s.element}', not on '{c.element}'"))
    masters = [j for j, c in enumerate(line.controllers) if c.type == "speed_pi" and c.master]
    if len(masters) > 1:
        out.append((f"controllers[{masters[1]}].master", "only one master speed node is allowed"))
    tension_ctrl: dict[str, int] = {}
    for j, c in enumerate(line.controllers):
        if c.type != "tension_pi" or c.element not in by_id:
            continue
        p = f"controllers[{j}]"
        _, e = by_id[c.element]
        drive = getattr(e, "drive", None)
        if drive is None:
            continue
        if c.element in tension_ctrl:
            out.append((f"{p}.element", f"'{e.id}' already has a tension controller "
                                        f"(controllers[{tension_ctrl[c.element]}])"))
        tension_ctrl[c.element] = j
        roll = e.type in ("unwind", "rewind")
        if drive.type == "torque" and not roll and c.element not in speed_ctrl:
            out.append((f"{p}.element", f"a tension_pi on driven element '{e.id}' trims its speed "
                                        f"and needs a speed_pi on the same element"))
        if drive.type == "torque" and roll and c.element in speed_ctrl:
            out.append((f"{p}.element", f"'{e.id}' has both a speed_pi and a torque-mode "
                                        f"tension_pi; use one of them"))
        if c.radius_sensor is not None and not roll:
            out.append((f"{p}.radius_sensor", "a radius sensor applies only to unwind/rewind"))
    return out


def _missing(what: str, name: str, known) -> str:
    names = ", ".join(sorted(known)) or "none defined"
    return f"no {what} with id '{name}' (known: {names})"
