"""``pivot_dancer``: a roller at the end of an arm turning about a pivot (physics.md
eq. 1.17); the kernel's PIVOT mover."""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar, Literal

from pydantic import Field

from ..parts import (
    GRAVITY,
    AccelerationPair,
    AnglePair,
    ElementBase,
    PosLength,
    Strict,
    Vec2,
    Wrap,
)
from ..quantities import (
    Angle,
    AngularSpeed,
    Force,
    Inertia,
    Length,
    Mass,
    Torque,
    ViscousTorque,
)
from ._base import ElementKind, Family, RecordWriter


class Cylinder(Strict):
    """Air cylinder between a fixed point and a point on the arm; regulated pressure gives a
    constant force (physics.md §1.5). Positive force pushes the two points apart."""

    force: Force = Field(
        description="constant cylinder force [N]; positive pushes the two points apart"
    )
    fixed_point: Vec2 = Field(description="the cylinder's fixed mounting point [x, y] [m]")
    arm_point: PosLength = Field(description="distance of the rod end from the pivot [m]")


class TorsionSpring(Strict):
    """Torsion spring at the pivot: M = -stiffness·(angle - free_angle)."""

    stiffness: Annotated[Torque, Field(ge=0)] = Field(description="[N m/rad]")
    free_angle: Angle = Field(
        0.0, description="arm angle at which the spring exerts no torque [rad]"
    )


class PivotDancer(ElementBase):
    """Pivoted (pendulum) dancer: roller at the end of an arm (physics.md eq. 1.17), loaded by
    an air cylinder, a torsion spring, a torque motor and/or gravity."""

    type: Literal["pivot_dancer"] = Field(description="selects a pivoted dancer")
    radius: PosLength = Field(description="dancer roller radius [m]")
    inertia: Annotated[Inertia, Field(gt=0)] = Field(description="roller spin inertia")
    wrap: Wrap = Field(
        description="direction the web travels around the dancer roller (x right, y up): cw or ccw"
    )
    pivot: Vec2 = Field(description="arm pivot [x, y] [m]")
    arm_length: PosLength = Field(description="pivot to roller centre [m]")
    arm_angle: Angle = Field(description="arm angle from +x at t = 0 [rad]")
    angle_range: AnglePair = Field(description="end stops [min, max] [rad]")
    arm_inertia: Annotated[Inertia, Field(ge=0)] = Field(
        description="arm inertia about the pivot, without the roller [kg m^2]"
    )
    roller_mass: Annotated[Mass, Field(ge=0)] = Field(
        0.0,
        description="mass of the roller at the arm's end [kg] (inertia about the pivot and "
        "gravity)",
    )
    arm_mass: Annotated[Mass, Field(ge=0)] = Field(
        0.0, description="mass of the arm [kg] (gravity, at arm_com)"
    )
    arm_com: Length | None = Field(
        None, description="pivot to arm centre of mass; default half the arm length"
    )
    cylinder: Cylinder | None = Field(None, description="air cylinder loading the arm")
    torsion_spring: TorsionSpring | None = Field(None, description="torsion spring at the pivot")
    torque: Torque = Field(0.0, description="torque motor at the pivot (active dancer)")
    damping: Annotated[ViscousTorque, Field(ge=0)] = Field(
        0.0, description="viscous damping at the pivot [N m s/rad]"
    )
    coulomb: Annotated[Torque, Field(ge=0)] = Field(
        0.0, description="Coulomb friction torque at the pivot [N m]"
    )
    smoothing_speed: Annotated[AngularSpeed, Field(gt=0)] = Field(
        1e-3, description="tanh smoothing of the Coulomb friction [rad/s]"
    )
    gravity: AccelerationPair = Field(GRAVITY, description="gravity vector [g_x, g_y] [m/s^2]")


class PivotDancerKind(ElementKind):
    """A roller on a pivoted arm (a PIVOT mover, coordinate in rad)."""

    name = "pivot_dancer"
    model = PivotDancer
    summary = (
        "pivoted dancer: roller on an arm (pivot, arm_length, arm_inertia, "
        "cylinder, torsion_spring, torque, gravity, angle_range end stops)"
    )
    order = 70
    family: ClassVar[Family] = "mover"
    mover_kind = "PIVOT"
    coordinate_unit = "rad"
    range_key = "angle_range"
    start_key = "arm_angle"
    fault_targets: ClassVar[frozenset[str]] = frozenset({"roller", "eccentric", "dancer"})

    def check(self, e: Any, path: str) -> list[tuple[str, str]]:
        out = []
        lo, hi = e.angle_range
        if e.position is not None:
            out.append(
                (
                    f"{path}.position",
                    "a pivot dancer's roller position follows from "
                    "pivot, arm_length and arm_angle; leave it out",
                )
            )
        if not lo < hi:
            out.append((f"{path}.angle_range", "must be [min, max] with min < max"))
        elif not lo <= e.arm_angle <= hi:
            out.append(
                (f"{path}.arm_angle", f"{e.arm_angle:g} rad is outside the angle range {[lo, hi]}")
            )
        return out

    def centre(self, e: Any, q: float) -> tuple[float, float]:
        return e.pivot[0] + e.arm_length * math.cos(q), e.pivot[1] + e.arm_length * math.sin(q)

    def pack_mover(self, e: Any, mover: RecordWriter) -> None:
        """Pivot, arm, inertia about the pivot, the gravity moment's lever, the torque
        motor, torsion spring and air cylinder."""
        gx, gy = e.gravity
        arm = e.arm_length
        mover["CX"], mover["CY"] = e.pivot
        mover["NX"] = arm
        mover["MASS"] = e.arm_inertia + e.roller_mass * arm**2
        mover["QMIN"], mover["QMAX"] = e.angle_range
        mover["F0"] = e.torque
        lever = e.roller_mass * arm + e.arm_mass * (
            e.arm_com if e.arm_com is not None else 0.5 * arm
        )
        mover["G1"], mover["G2"] = lever * gy, -lever * gx
        if e.torsion_spring is not None:
            mover["K"], mover["Q0"] = e.torsion_spring.stiffness, e.torsion_spring.free_angle
        if e.cylinder is not None:
            mover["CYLF"] = e.cylinder.force
            mover["CYLX"], mover["CYLY"] = e.cylinder.fixed_point
            mover["CYLA"] = e.cylinder.arm_point

    def rest_tension(self, e: Any, cl: Any) -> float | None:
        """The tension of both spans whose moment about the pivot balances the arm's load
        at its initial angle, from the compiled line's own load and span geometry."""
        m = cl.mover_ids.index(e.id)
        load, lever = cl.mover_balance(m, cl.mover_q0[m])
        return load / lever if lever != 0.0 else None


KIND = PivotDancerKind()
