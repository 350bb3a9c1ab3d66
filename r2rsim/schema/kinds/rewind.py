"""``rewind``: the roll stand that takes web up at the tail of the line."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from ..parts import Drive, ElementBase, Roll
from ._roll import RollKind


class Rewind(ElementBase):
    """Rewind stand: a roll taking up web."""

    type: Literal["rewind"] = Field(description="selects a rewind")
    roll: Roll = Field(description="the roll (core and the web already wound) the run starts with")
    drive: Drive = Field(
        default_factory=Drive, description="the rewind's motor (default: a torque drive)"
    )


class RewindKind(RollKind):
    """A roll taking up web: the last element."""

    name = "rewind"
    model = Rewind
    summary = "roll taking up web (same keys as unwind)"
    order = 20
    node_kind = "REWIND"


KIND = RewindKind()
