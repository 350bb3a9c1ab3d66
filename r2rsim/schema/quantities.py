"""Annotated float types for schema fields: an SI number or a unit string, parsed by
:mod:`r2rsim.units`."""

from __future__ import annotations

import math
from typing import Annotated

from pydantic import BeforeValidator, WithJsonSchema

from ..units import DIMENSIONS, parse_quantity


def _quantity(dimension: str):
    _, si_unit, example = DIMENSIONS[dimension]

    def convert(value):
        return parse_quantity(value, dimension)

    # x-dimension and x-unit survive a field's own description, which replaces this one
    # (docs/keys.md is generated from them: r2rsim.schema.reference_markdown)
    schema = {
        "anyOf": [{"type": "number"}, {"type": "string"}],
        "description": f"{dimension.replace('_', ' ')}: a number in {si_unit} or a string with "
        f"units such as '{example}'",
        "x-dimension": dimension.replace("_", " "),
        "x-unit": si_unit,
    }
    return Annotated[float, BeforeValidator(convert), WithJsonSchema(schema)]


Length = _quantity("length")
Speed = _quantity("speed")
Time = _quantity("time")
Frequency = _quantity("frequency")
Force = _quantity("force")
Pressure = _quantity("pressure")
Density = _quantity("density")
Mass = _quantity("mass")
Inertia = _quantity("inertia")
Torque = _quantity("torque")
ViscousTorque = _quantity("viscous_torque")
Angle = _quantity("angle")
AngularSpeed = _quantity("angular_speed")
Dimensionless = _quantity("dimensionless")
Stiffness = _quantity("stiffness")
Damping = _quantity("damping")
Acceleration = _quantity("acceleration")
InverseArea = _quantity("inverse_area")


def number_or_text(value):
    """Before-validator of a field that takes a number or a string (parsed later, with the
    unit its context fixes): refuses booleans and non-finite numbers with one message,
    before a union's members would each report their own."""
    if isinstance(value, bool):
        raise ValueError(
            f"expected a number or a string with units, got {str(value).lower()} (a boolean)"
        )
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"{value} is not a finite number (.nan and .inf are not allowed)")
    return value


#: a number (SI) or a string with units whose dimension is checked later
NumberOrText = Annotated[float | str, BeforeValidator(number_or_text)]
