"""``idler``: an undriven roller, the plainest roller kind (every default of
:class:`~r2rsim.schema.kinds.ElementKind` is its)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from ..parts import ElementBase, PosLength
from ..quantities import Inertia
from ._base import ElementKind


class Idler(ElementBase):
    """Undriven roller."""

    type: Literal["idler"] = Field(description="selects an idler")
    radius: PosLength = Field(description="roller radius [m]")
    inertia: Annotated[Inertia, Field(gt=0)] = Field(description="roller spin inertia [kg m^2]")


class IdlerKind(ElementKind):
    """An undriven roller: every default of the base class."""

    name = "idler"
    model = Idler
    summary = "undriven roller: radius, inertia, friction, wrap_angle, friction_coefficient"
    order = 30


KIND = IdlerKind()
