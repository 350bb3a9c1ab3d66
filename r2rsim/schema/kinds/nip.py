"""``nip``: a driven roller and a pressure roller clamping the web, one degree of freedom
(physics.md eq. 1.9): its node carries the pair's effective inertia and friction."""

from __future__ import annotations

from typing import Annotated, Any, ClassVar, Literal

from pydantic import Field

from ..parts import Drive, ElementBase, Friction, PosLength, Strict
from ..quantities import Inertia
from ._base import ElementKind, RecordWriter


class PressureRoller(Strict):
    """The undriven roller of a nip pair."""

    radius: PosLength = Field(description="pressure roller radius [m]")
    inertia: Annotated[Inertia, Field(ge=0)] = Field(
        description="pressure roller spin inertia [kg m^2]"
    )
    friction: Friction = Field(
        default_factory=Friction, description="bearing friction of the pressure roller"
    )


class Nip(ElementBase):
    """Nip pair clamping the web (no slip): one degree of freedom with
    J_eff = J1 + J2 (R1/R2)^2 (physics.md eq. 1.9). The drive acts on the main roller."""

    type: Literal["nip"] = Field(description="selects a nip")
    radius: PosLength = Field(description="radius of the main (driven) roller [m]")
    inertia: Annotated[Inertia, Field(gt=0)] = Field(
        description="spin inertia of the main roller [kg m^2]"
    )
    drive: Drive = Field(
        default_factory=Drive, description="the main roller's motor (default: a torque drive)"
    )
    pressure_roller: PressureRoller = Field(
        description="the undriven roller pressed on the main one; it turns with it without slip"
    )


class NipKind(ElementKind):
    """A nip pair: one node with the pair's effective inertia and friction."""

    name = "nip"
    model = Nip
    summary = "nip pair as one degree of freedom: radius, inertia, drive, pressure_roller"
    order = 50
    fault_targets: ClassVar[frozenset[str]] = frozenset(
        {"drive", "roller", "eccentric", "speed_node"}
    )

    def drive_inertia(self, e: Any, web: Any) -> float | None:
        pr = e.pressure_roller
        return e.inertia + pr.inertia * (e.radius / pr.radius) ** 2

    def frictions(self, e: Any) -> list[tuple[str, Any]]:
        return [("friction", e.friction), ("pressure_roller.friction", e.pressure_roller.friction)]

    def pack_node(self, e: Any, node: RecordWriter, web: Any) -> None:
        """The pressure roller turns at ratio R1/R2 without slip: its inertia counts with
        the ratio squared, its viscous friction too, its Coulomb torque with the ratio."""
        f, pr = e.friction, e.pressure_roller
        ratio = e.radius / pr.radius
        node["R"] = e.radius
        node["J"] = e.inertia + pr.inertia * ratio**2
        node["B"] = f.viscous + pr.friction.viscous * ratio**2
        node["TC"] = f.coulomb + pr.friction.coulomb * ratio


KIND = NipKind()
