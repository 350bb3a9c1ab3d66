"""``driven``: a motor-driven roller (pull roll, S-wrap roller)."""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

from pydantic import Field

from ..parts import Drive, ElementBase, PosLength
from ..quantities import Inertia
from ._base import ElementKind


class Driven(ElementBase):
    """Motor-driven roller (pull roll, S-wrap roller, ...)."""

    type: Literal["driven"] = Field(description="selects a driven roller")
    radius: PosLength = Field(description="roller radius [m]")
    inertia: Annotated[Inertia, Field(gt=0)] = Field(
        description="roller and motor inertia [kg m^2]"
    )
    drive: Drive = Field(
        default_factory=Drive, description="the roller's motor (default: a torque drive)"
    )


class DrivenKind(ElementKind):
    """A roller with a motor: a plain roller's record, and speed-node faults."""

    name = "driven"
    model = Driven
    summary = "motor-driven roller: radius, inertia, friction, drive"
    order = 40
    # a speed-node fault (draw error) acts on the speed a driven roller is held at
    fault_targets: ClassVar[frozenset[str]] = frozenset(
        {"drive", "roller", "eccentric", "speed_node"}
    )


KIND = DrivenKind()
