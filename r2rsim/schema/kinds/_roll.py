"""What the two roll kinds (unwind, rewind) share: the roll's inertia and its node record."""

from __future__ import annotations

import math
from typing import Any, ClassVar

from ._base import ElementKind, Family, RecordWriter


def roll_inertia(roll: Any, web: Any) -> float:
    """J(R) at the roll's starting radius (physics.md eq. 1.12), for order-of-magnitude use."""
    cw = roll.build_per_wrap or web.thickness
    rho_w = web.density * web.thickness / cw * web.width
    return roll.core_inertia + 0.5 * math.pi * rho_w * (roll.outer_radius**4 - roll.core_radius**4)


class RollKind(ElementKind):
    """A roll on a stand: its radius follows the wound length (the kernel's roll states)."""

    family: ClassVar[Family] = "roll"
    fault_targets: ClassVar[frozenset[str]] = frozenset({"drive", "roller"})

    def surface_radius(self, e: Any) -> float:
        return e.roll.outer_radius

    def smallest_radius(self, e: Any) -> tuple[float, str] | None:
        return e.roll.core_radius, "roll.core_radius"

    def drive_inertia(self, e: Any, web: Any) -> float | None:
        return roll_inertia(e.roll, web)

    def states(self, e: Any) -> tuple[tuple[str, str, str, str, float], ...]:
        """The web length through the tangent point s and the unstretched length u."""
        return (
            ("S", "length", "m", "roll_length", 1e-6),
            ("U", "unstretched_length", "m", "material", 1e-6),
        )

    def pack_node(self, e: Any, node: RecordWriter, web: Any) -> None:
        """Roll geometry, wound density and wound-in strain (the inertia is the kernel's,
        from the radius)."""
        r = e.roll
        cw = r.build_per_wrap if r.build_per_wrap is not None else web.thickness
        node["R0"], node["RC"], node["JC"], node["CW"] = (
            r.outer_radius,
            r.core_radius,
            r.core_inertia,
            cw,
        )
        # wound density from mass conservation: rho_r·c_w = rho·t_w (physics.md 1.4)
        node["RHOW"] = web.density * web.thickness / cw * web.width
        node["EPSW"], node["EPSW1"], node["EPSW2"] = r.wound_in_coefficients()
        node["R"] = r.outer_radius
        splicer = getattr(e, "splicer", None)
        if splicer is not None and splicer.trigger_radius is not None:
            node["RTRIG"] = splicer.trigger_radius
