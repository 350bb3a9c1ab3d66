"""``unwind``: the roll stand that pays web out at the head of the line."""

from __future__ import annotations

from typing import ClassVar, Literal

from pydantic import Field

from ..parts import Drive, ElementBase, Roll, Splicer
from ._roll import RollKind


class Unwind(ElementBase):
    """Unwind stand: a roll paying out web; torque drive (default) or ideal speed. With a
    ``splicer`` the expiring roll is replaced by a fresh ``spare_roll`` at every splice."""

    type: Literal["unwind"] = Field(description="selects an unwind")
    roll: Roll = Field(description="the roll the run starts with")
    drive: Drive = Field(
        default_factory=Drive, description="the unwind's motor (default: a torque drive)"
    )
    spare_roll: Roll | None = Field(None, description="the roll loaded at each splice")
    splicer: Splicer | None = Field(None, description="roll changes; needs spare_roll")


class UnwindKind(RollKind):
    """A roll paying out web: the first element; the roll-change and material faults are its."""

    name = "unwind"
    model = Unwind
    summary = (
        "roll paying out web: roll (core/outer radius, core inertia, build per wrap, "
        "wound-in strain), friction, drive (torque with lag/saturation, or ideal_speed)"
    )
    order = 10
    node_kind = "UNWIND"
    # the roll's material (modulus change) and its splices are the unwind's
    fault_targets: ClassVar[frozenset[str]] = frozenset({"drive", "roller", "unwind", "splicer"})


KIND = UnwindKind()
