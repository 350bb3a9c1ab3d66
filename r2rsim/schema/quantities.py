"""Annotated float types for schema fields: an SI number or a unit string, parsed by
:mod:`r2rsim.units`."""

from __future__ import annotations

from typing import Annotated

from pydantic import BeforeValidator, WithJsonSchema

from ..units import DIMENSIONS, parse_quantity


def _quantity(dimension: str):
    _, si_unit, example = DIMENSIONS[dimension]

    def convert(value):
        return parse_quantity(value, dimension)

    schema = {
        "anyOf": [{"type": "number"}, {"type": "string"}],
        "description": f"{dimension.replace('_', ' ')}: a number in {si_unit} or a string with "
        f"units such as '{example}'",
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
