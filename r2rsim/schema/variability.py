"""Unlabelled process variability of a scenario (``variability:``): the spread of the line's
values between rolls and between runs, drawn from the run's process stream. Not a fault:
it carries no label, and the drawn values are ground truth (``variability.parquet``) that
diagnostic plug-ins never see.

Each varied value names its spread in exactly one way: ``std`` (normal, in the value's
unit), ``rel_std`` (normal, a fraction of the nominal value), ``tolerance`` (uniform within
plus or minus, in the value's unit) or ``rel_tolerance`` (uniform, a fraction). Normal draws
are cut at four standard deviations, so a value never leaves its physical range.
"""

from __future__ import annotations

from typing import Annotated

from pydantic import Field, model_validator

from ..units import parse_quantity
from .kinds import kind_of
from .line import Id, Strict
from .quantities import Dimensionless, NumberOrText

#: a normal draw is cut at this many standard deviations
CUT_SIGMAS = 4.0


class Spread(Strict):
    """The spread of one value: exactly one of ``std``, ``rel_std``, ``tolerance`` and
    ``rel_tolerance``."""

    std: NumberOrText | None = Field(
        None, description="normal, standard deviation in the value's unit (cut at 4 std)"
    )
    rel_std: Annotated[Dimensionless, Field(ge=0, le=0.2)] | None = Field(
        None,
        description="normal, standard deviation as a fraction of the nominal value, "
        "e.g. '2 %' (cut at 4 std)",
    )
    tolerance: NumberOrText | None = Field(
        None, description="uniform within +- tolerance, in the value's unit"
    )
    rel_tolerance: Annotated[Dimensionless, Field(ge=0, le=0.5)] | None = Field(
        None, description="uniform within +- a fraction of the nominal value, e.g. '0.5 %'"
    )

    @model_validator(mode="after")
    def _one(self):
        given = [
            k
            for k in ("std", "rel_std", "tolerance", "rel_tolerance")
            if getattr(self, k) is not None
        ]
        if len(given) != 1:
            raise ValueError(
                "give exactly one of std, rel_std, tolerance and rel_tolerance"
                + (f" (got {', '.join(given)})" if given else "")
            )
        return self

    @property
    def relative(self) -> bool:
        """True for ``rel_std`` and ``rel_tolerance``."""
        return self.rel_std is not None or self.rel_tolerance is not None

    @property
    def key(self) -> str:
        """The one key given."""
        return next(
            k
            for k in ("std", "rel_std", "tolerance", "rel_tolerance")
            if getattr(self, k) is not None
        )

    def si(self, nominal: float, dimension: str) -> tuple[str, float]:
        """``("normal" | "uniform", width)``: the standard deviation or half-width in SI
        around ``nominal``. Raises :class:`r2rsim.units.QuantityError` for a value of the
        wrong dimension."""
        if self.rel_std is not None:
            return "normal", self.rel_std * abs(nominal)
        if self.rel_tolerance is not None:
            return "uniform", self.rel_tolerance * abs(nominal)
        if self.std is not None:
            return "normal", parse_quantity(self.std, dimension)
        return "uniform", parse_quantity(self.tolerance, dimension)

    def reach(self, nominal: float, dimension: str) -> float:
        """How far from ``nominal`` a draw can go: 4 standard deviations, or the
        tolerance."""
        kind, width = self.si(nominal, dimension)
        return width * (CUT_SIGMAS if kind == "normal" else 1.0)


class RollVariability(Strict):
    """What differs from one roll of an unwind to the next: drawn for the roll on the unwind
    at t = 0 and again for each roll a splice loads."""

    modulus: Spread | None = Field(
        None,
        description="the roll's web modulus E [Pa]; its E·A enters the spans as the "
        "roll's web does",
    )
    thickness: Spread | None = Field(
        None, description="the roll's web thickness [m]: its E·A and its radial build"
    )
    outer_radius: Spread | None = Field(None, description="the roll's starting radius [m]")
    wound_in_strain: Spread | None = Field(
        None,
        description="an offset on the roll's wound-in strain (the e0 of the roll's "
        "law; std or tolerance, since the nominal may be 0)",
    )
    relaxed_pitch: Spread | None = Field(
        None,
        description="an offset [m] on the relaxed pitch L0 of the roll's printed web, "
        "read by the pitch_length sensors on this unwind's web (std or tolerance); it "
        "reaches a sensor with the roll's web",
    )


class SensorCalibration(Strict):
    """A sensor's calibration error of one run: its gain and offset in y = g·x + b."""

    gain: Spread | None = Field(
        None, description="calibration gain g (nominal from the line, usually 1)"
    )
    offset: Spread | None = Field(
        None, description="calibration offset b, in the sensor's unit (N, rad/s, m)"
    )


class Variability(Strict):
    """Unlabelled process variability: what differs between the rolls of an unwind and
    between runs, drawn from the run's process stream and recorded in variability.parquet,
    never in the columns a method sees (docs/dataset.md §8.1; this module's docstring)."""

    rolls: dict[Id, RollVariability] = Field(
        default_factory=dict, description="per unwind id: what differs between its rolls"
    )
    friction: Spread | None = Field(
        None,
        description="per run and element: the bearing friction (viscous and Coulomb "
        "together) as a fraction of the line's value (rel_std or rel_tolerance)",
    )
    sensors: dict[Id, SensorCalibration] = Field(
        default_factory=dict, description="per sensor id: its calibration error in this run"
    )

    @model_validator(mode="after")
    def _check(self):
        if self.friction is not None and not self.friction.relative:
            raise ValueError(
                "@variability.friction@ the friction spread is relative: "
                "give rel_std or rel_tolerance"
            )
        for eid, r in self.rolls.items():
            w = r.wound_in_strain
            if w is not None and w.relative:
                raise ValueError(
                    f"@variability.rolls.{eid}.wound_in_strain@ give std or "
                    "tolerance (the nominal wound-in strain may be 0)"
                )
            p = r.relaxed_pitch
            if p is not None and p.relative:
                raise ValueError(
                    f"@variability.rolls.{eid}.relaxed_pitch@ give std or "
                    "tolerance: the value is an offset on the sensors' L0 [m]"
                )
        return self


_SENSOR_UNIT = {
    "load_cell": ("force", "N"),
    "encoder": ("angular_speed", "rad/s"),
    "roll_diameter": ("length", "m"),
    "pitch_length": ("length", "m"),
}


def sensor_dimension(line, sensor) -> tuple[str, str]:
    """(dimension, unit) of a sensor's reading (and calibration offset)."""
    if sensor.type == "dancer_position":
        pivot = kind_of(line.element(sensor.element)).coordinate_unit == "rad"
        return ("angle", "rad") if pivot else ("length", "m")
    return _SENSOR_UNIT[sensor.type]
