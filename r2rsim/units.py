"""Quantities in input files: bare numbers are SI, strings carry units and are parsed once.

``parse_quantity("300 m/min", "speed")`` returns 5.0. Pint is used only here, at load time;
nothing downstream of the schema sees a pint object.
"""

from __future__ import annotations

import functools
import math

# Dimensions accepted by schema fields: name -> (pint dimensionality string, SI unit, example).
DIMENSIONS: dict[str, tuple[str, str, str]] = {
    "length": ("[length]", "m", "1.5 m"),
    "speed": ("[length] / [time]", "m/s", "300 m/min"),
    "acceleration": ("[length] / [time] ** 2", "m/s^2", "0.5 m/s^2"),
    "time": ("[time]", "s", "1 ms"),
    "frequency": ("1 / [time]", "Hz", "1 kHz"),
    "force": ("[length] * [mass] / [time] ** 2", "N", "260 N"),
    "force_rate": ("[length] * [mass] / [time] ** 3", "N/s", "100 N/s"),
    "stiffness": ("[mass] / [time] ** 2", "N/m", "2000 N/m"),
    "damping": ("[mass] / [time]", "N*s/m", "50 N*s/m"),
    "pressure": ("[mass] / [length] / [time] ** 2", "Pa", "4.5 GPa"),
    "density": ("[mass] / [length] ** 3", "kg/m^3", "1390 kg/m^3"),
    "mass": ("[mass]", "kg", "10 kg"),
    "inertia": ("[length] ** 2 * [mass]", "kg*m^2", "0.5 kg*m^2"),
    "torque": ("[length] ** 2 * [mass] / [time] ** 2", "N*m", "50 N*m"),
    "viscous_torque": ("[length] ** 2 * [mass] / [time]", "N*m*s", "0.01 N*m*s"),
    "angle": ("", "rad", "90 deg"),
    "angular_speed": ("1 / [time]", "rad/s", "100 rpm"),
    "dimensionless": ("", "1", "0.001"),
}


class QuantityError(ValueError):
    """A quantity string could not be parsed or has the wrong dimension."""


@functools.lru_cache(maxsize=1)
def _registry():
    import pint

    ureg = pint.UnitRegistry(autoconvert_offset_to_baseunit=True)
    return ureg


def parse_quantity(value: object, dimension: str) -> float:
    """Convert a YAML value to an SI float.

    Parameters
    ----------
    value : float, int or str
        A bare number (taken as SI) or a string with units such as ``"50 um"``.
    dimension : str
        One of the keys of :data:`DIMENSIONS`.

    Returns
    -------
    float
        The value in SI units (angles in rad, angular speeds in rad/s).

    Raises
    ------
    QuantityError
        If the string cannot be parsed, has the wrong dimension, or is not finite.
    """
    dim, si_unit, example = DIMENSIONS[dimension]
    if isinstance(value, bool):
        raise QuantityError(f"expected a {dimension.replace('_', ' ')}, got a boolean")
    if isinstance(value, (int, float)):
        out = float(value)
    elif isinstance(value, str):
        text = value.strip()
        try:
            out = float(text)
        except ValueError:
            out = _parse_string(text, dimension, dim, si_unit, example)
    else:
        raise QuantityError(
            f"expected a {dimension.replace('_', ' ')} as a number in {si_unit} or a string "
            f"such as '{example}', got {type(value).__name__}"
        )
    if not math.isfinite(out):
        raise QuantityError(f"{value!r} is not a finite number")
    return out


def _parse_string(text: str, dimension: str, dim: str, si_unit: str, example: str) -> float:
    import pint

    ureg = _registry()
    try:
        q = ureg.Quantity(text)
    except (pint.errors.PintError, ValueError, TypeError, AttributeError, SyntaxError) as exc:
        raise QuantityError(
            f"cannot read {text!r} as a quantity ({exc.__class__.__name__}); "
            f"write e.g. '{example}'"
        ) from None
    if not isinstance(q, ureg.Quantity):  # a plain number such as "1e3"
        return float(q)
    want = ureg.Quantity(1, si_unit if si_unit != "1" else "")
    if q.dimensionality != want.dimensionality:
        got = str(q.dimensionality) or "dimensionless"
        raise QuantityError(
            f"{text!r} has dimension {got}, expected a {dimension.replace('_', ' ')} "
            f"(e.g. '{example}')"
        )
    if dimension == "angular_speed":
        return float(q.to("rad/s").magnitude) if q.check("1/[time]") else float(q.magnitude)
    return float(q.to(want.units).magnitude)
