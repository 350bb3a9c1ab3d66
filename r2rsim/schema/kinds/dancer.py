"""``dancer``: a roller on a carriage that translates along a direction (physics.md
eq. 1.15); the kernel's LINEAR mover."""

from __future__ import annotations

import math
from typing import Annotated, Any, ClassVar, Literal

from pydantic import Field

from ..parts import (
    GRAVITY,
    AccelerationPair,
    ElementBase,
    FloatPair,
    LengthPair,
    PosLength,
    Vec2,
    Wrap,
)
from ..quantities import Damping, Force, Inertia, Length, Mass, Speed, Stiffness
from ._base import ElementKind, Family, RecordWriter


class Dancer(ElementBase):
    """Translating dancer: a roller on a carriage that moves along ``direction``
    (physics.md eq. 1.15). The roller spins like an idler; the lengths of the spans on both
    sides follow from the geometry (the neighbours need ``position`` and ``wrap``)."""

    type: Literal["dancer"] = Field(description="selects a translating dancer")
    radius: PosLength = Field(description="dancer roller radius [m]")
    inertia: Annotated[Inertia, Field(gt=0)] = Field(description="roller spin inertia")
    position: Vec2 = Field(description="roller centre at travel 0 [m]")
    wrap: Wrap = Field(
        description="direction the web travels around the dancer roller (x right, y up): cw or ccw"
    )
    direction: FloatPair = Field(
        (0.0, -1.0), description="unit vector along which the travel x grows (normalised)"
    )
    travel_range: LengthPair = Field(description="end stops [x_min, x_max] [m]")
    initial_travel: Length = Field(0.0, description="travel x at t = 0 [m]")
    mass: Annotated[Mass, Field(gt=0)] = Field(description="moving mass incl. roller [kg]")
    load_force: Force = Field(
        0.0, description="actuator force along direction (air cylinder at regulated pressure)"
    )
    spring_stiffness: Annotated[Stiffness, Field(ge=0)] = Field(
        0.0,
        description="spring on the carriage, force -spring_stiffness·(x - "
        "spring_free_travel) [N/m]",
    )
    spring_free_travel: Length = Field(
        0.0, description="travel x at which the spring exerts no force [m]"
    )
    damping: Annotated[Damping, Field(ge=0)] = Field(
        0.0, description="viscous damping of the carriage [N s/m]"
    )
    coulomb: Annotated[Force, Field(ge=0)] = Field(0.0, description="carriage Coulomb friction")
    smoothing_speed: Annotated[Speed, Field(gt=0)] = Field(
        1e-3, description="tanh smoothing of the Coulomb friction [m/s]"
    )
    gravity: AccelerationPair = Field(
        GRAVITY, description="gravity vector [g_x, g_y] acting on the moving mass [m/s^2] (y up)"
    )


def _unit_direction(e: Any) -> tuple[float, float]:
    nx, ny = e.direction
    nrm = math.hypot(nx, ny)
    return nx / nrm, ny / nrm


class DancerKind(ElementKind):
    """A roller on a translating carriage (a LINEAR mover, coordinate in m)."""

    name = "dancer"
    model = Dancer
    summary = (
        "translating dancer: roller on a carriage (mass, load_force, spring, damping, "
        "coulomb, travel_range end stops); span lengths from the geometry"
    )
    order = 60
    family: ClassVar[Family] = "mover"
    mover_kind = "LINEAR"
    coordinate_unit = "m"
    range_key = "travel_range"
    start_key = "initial_travel"
    fault_targets: ClassVar[frozenset[str]] = frozenset({"roller", "eccentric", "dancer"})

    def check(self, e: Any, path: str) -> list[tuple[str, str]]:
        out = []
        lo, hi = e.travel_range
        if math.hypot(*e.direction) < 1e-9:
            out.append((f"{path}.direction", "must be a non-zero vector"))
        if not lo < hi:
            out.append((f"{path}.travel_range", "must be [x_min, x_max] with x_min < x_max"))
        elif not lo <= e.initial_travel <= hi:
            out.append(
                (
                    f"{path}.initial_travel",
                    f"{e.initial_travel:g} m is outside the travel range {[lo, hi]}",
                )
            )
        return out

    def centre(self, e: Any, q: float) -> tuple[float, float]:
        nx, ny = _unit_direction(e)  # (as the compiled record holds it)
        return e.position[0] + q * nx, e.position[1] + q * ny

    def pack_mover(self, e: Any, mover: RecordWriter) -> None:
        """Carriage position and direction, mass, its weight along the direction, the
        actuator force and the spring."""
        gx, gy = e.gravity
        nx, ny = _unit_direction(e)
        mover["CX"], mover["CY"] = e.position
        mover["NX"], mover["NY"] = nx, ny
        mover["MASS"] = e.mass
        mover["QMIN"], mover["QMAX"] = e.travel_range
        mover["F0"] = e.mass * (gx * nx + gy * ny)
        mover["FAIR"] = e.load_force
        mover["K"], mover["Q0"] = e.spring_stiffness, e.spring_free_travel

    def rest_tension(self, e: Any, cl: Any) -> float | None:
        """Half the load on the carriage (two strands), its weight taken as vertical."""
        return 0.5 * abs(e.load_force + e.mass * 9.81)


KIND = DancerKind()
