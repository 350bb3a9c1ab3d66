"""The fault catalogue (DESIGN.md §5, fdd-benchmarks.md §6.3) and a scenario's fault entries.

Every fault has an ``id``, a ``type`` from :data:`CATALOGUE`, a ``target`` (the id of a
sensor, element, dancer or unwind, as the type says), an ``onset``, an optional ``end``, a
``profile`` (step, ramp, exp, intermittent) and a ``magnitude`` whose unit the type fixes
(:func:`magnitude_dimension`). Onset and magnitude may be drawn from a seeded distribution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

from pydantic import Field, model_validator

from ..errors import InputError
from ..units import QuantityError, parse_quantity
from .line import Id, Strict
from .quantities import Frequency, Time


@dataclass(frozen=True)
class FaultType:
    """One entry of the catalogue.

    ``target``: what ``target`` names (``sensor``, ``drive``, ``dancer``, ``roller``,
    ``speed_node``, ``unwind``). ``magnitude``: ``reading`` (the sensor's unit), ``reading/s``,
    ``rel`` (relative change, 0.05 = +5 %), ``s``, ``N*m``, ``none``. ``acts``: ``loop`` (inside
    the simulation: a controller reading the sensor sees it), ``record`` (on the recorded
    measurement only), ``model`` (changes the line's equations or parameters).
    """

    name: str
    fault_class: str
    target: str
    magnitude: str
    acts: str
    description: str


_C = [
    FaultType("sensor.offset", "sensor", "sensor", "reading", "loop",
              "adds b to the reading"),
    FaultType("sensor.gain", "sensor", "sensor", "rel", "loop",
              "multiplies the reading by (1 + magnitude)"),
    FaultType("sensor.drift", "sensor", "sensor", "reading/s", "loop",
              "adds magnitude·(t - onset) to the reading"),
    FaultType("sensor.stuck", "sensor", "sensor", "none", "loop",
              "the reading freezes at its value at onset"),
    FaultType("sensor.dropout", "sensor", "sensor", "none", "loop",
              "no reading: recorded as NaN; a controller holds the last valid reading"),
    FaultType("sensor.noise", "sensor", "sensor", "reading", "record",
              "adds white noise of standard deviation magnitude at each sensor sample"),
    FaultType("sensor.spike", "sensor", "sensor", "reading", "record",
              "spikes of +-magnitude at random sensor samples (rate: spikes per second)"),
    FaultType("sensor.quantization", "sensor", "sensor", "reading", "record",
              "the reading is rounded to steps of magnitude"),
    FaultType("sensor.delay", "sensor", "sensor", "s", "record",
              "the reading lags by magnitude seconds"),
]
CATALOGUE: dict[str, FaultType] = {f.name: f for f in _C}

#: fault types that may overlap on one target when both declare ``compose: superpose``
SUPERPOSABLE = {"sensor.offset", "sensor.gain", "sensor.drift", "sensor.noise", "sensor.spike"}


class Uniform(Strict):
    """A value drawn uniformly from [low, high] (seeded by the fault-sampling stream)."""

    uniform: tuple[float | str, float | str]


class LogUniform(Strict):
    """A value whose logarithm is uniform on [log low, log high] (low, high > 0)."""

    loguniform: tuple[float | str, float | str]


class Choice(Strict):
    """One of the listed values, each equally likely."""

    choice: list[float | str] = Field(min_length=1)


Sampled = Uniform | LogUniform | Choice


class Profile(Strict):
    """Time course of a fault's effect, as a fraction p(t) of its magnitude.

    ``step``: p = 1 from onset. ``ramp``: p rises linearly to 1 over ``ramp``. ``exp``:
    p = 1 - exp(-(t - onset)/``ramp``). ``intermittent``: p = 1 for ``duty``·``period`` out of
    every ``period`` from onset, else 0.
    """

    shape: Literal["step", "ramp", "exp", "intermittent"] = "step"
    ramp: Annotated[Time, Field(gt=0)] | None = Field(
        None, description="ramp: time to full magnitude; exp: time constant [s]")
    period: Annotated[Time, Field(gt=0)] | None = Field(None, description="intermittent [s]")
    duty: Annotated[float, Field(gt=0, le=1)] | None = Field(
        None, description="intermittent: fraction of each period the fault acts")

    @model_validator(mode="after")
    def _check(self):
        if self.shape in ("ramp", "exp") and self.ramp is None:
            raise ValueError(f"a {self.shape} profile needs 'ramp' (its time scale)")
        if self.shape == "intermittent" and (self.period is None or self.duty is None):
            raise ValueError("an intermittent profile needs 'period' and 'duty'")
        if self.shape != "intermittent" and (self.period is not None or self.duty is not None):
            raise ValueError("'period' and 'duty' belong to an intermittent profile")
        if self.shape in ("step", "intermittent") and self.ramp is not None:
            raise ValueError(f"'ramp' does not apply to a {self.shape} profile")
        return self


class Fault(Strict):
    """A fault instance of the scenario (``r2rsim list faults`` shows the types)."""

    id: Id
    type: Literal[tuple(CATALOGUE)]  # type: ignore[valid-type]
    target: Id = Field(description="sensor / element / dancer id, as the type requires")
    onset: Annotated[Time, Field(ge=0)] | Sampled
    end: Annotated[Time, Field(gt=0)] | None = Field(
        None, description="when the fault stops acting; default: to the end of the run")
    profile: Profile = Field(default_factory=Profile)
    magnitude: float | str | Sampled | None = Field(
        None, description="in the unit the type fixes (see `r2rsim list faults`); a number "
        "is SI, a string may carry units ('5 N')")
    rate: Annotated[Frequency, Field(gt=0)] | None = Field(
        None, description="sensor.spike: mean number of spikes per second")
    compose: Literal["superpose"] | None = Field(
        None, description="allow overlap with other faults on the same target that also "
        "declare it: offsets and drifts add, gain changes add, noise variances add")

    @model_validator(mode="after")
    def _check(self):
        ft = CATALOGUE[self.type]
        if ft.magnitude == "none" and self.magnitude is not None:
            raise ValueError(f"{self.type} takes no magnitude")
        if ft.magnitude != "none" and self.magnitude is None:
            raise ValueError(f"{self.type} needs a magnitude")
        if (self.type == "sensor.spike") != (self.rate is not None):
            raise ValueError("'rate' is required for sensor.spike and only for it")
        if ft.magnitude == "none" and self.profile.shape not in ("step", "intermittent"):
            raise ValueError(f"{self.type} acts fully or not at all: use a step "
                             "or intermittent profile")
        if self.type == "sensor.drift" and self.profile.shape != "step":
            raise ValueError("a drift grows by itself: use a step profile")
        if self.end is not None and isinstance(self.onset, float) and self.end <= self.onset:
            raise ValueError(f"end {self.end:g} s must come after onset {self.onset:g} s")
        return self


READING = {"load_cell": "force", "encoder": "angular_speed", "roll_diameter": "length",
            "pitch_length": "length"}
SI_UNIT = {"force": "N", "angular_speed": "rad/s", "length": "m", "angle": "rad",
            "time": "s", "dimensionless": "rel"}
RATE_OF = {"force": "force_rate", "length": "speed", "angle": "angular_speed"}


def magnitude_dimension(ftype: str, reading_dim: str) -> str | None:
    """The :data:`r2rsim.units.DIMENSIONS` key of a fault's magnitude, given the dimension of
    the target's reading (None: a plain SI number)."""
    return {"reading": reading_dim, "rel": "dimensionless", "s": "time", "none": None,
            "reading/s": RATE_OF.get(reading_dim)}[CATALOGUE[ftype].magnitude]


def magnitude_unit(ftype: str, reading_dim: str) -> str:
    """SI unit of a fault's magnitude as written to faults.parquet."""
    return {"reading": SI_UNIT[reading_dim], "rel": "rel", "s": "s", "none": "",
            "reading/s": SI_UNIT[reading_dim] + "/s"}[CATALOGUE[ftype].magnitude]


def reading_dimension(line, sensor) -> str:
    """Dimension of a sensor's reading."""
    if sensor.type != "dancer_position":
        return READING[sensor.type]
    el = next((e for e in line.elements if e.id == sensor.element), None)
    return "angle" if el is not None and el.type == "pivot_dancer" else "length"


def bounds(value, dimension) -> tuple[float, float]:
    """Smallest and largest value a fixed value or distribution can take (SI)."""
    def si(v):
        return float(v) if dimension is None else parse_quantity(v, dimension)

    if isinstance(value, Uniform):
        return si(value.uniform[0]), si(value.uniform[1])
    if isinstance(value, LogUniform):
        return si(value.loguniform[0]), si(value.loguniform[1])
    if isinstance(value, Choice):
        vals = [si(v) for v in value.choice]
        return min(vals), max(vals)
    return si(value), si(value)


def check_faults(scenario, line, file: str) -> None:
    """Targets, units and overlaps of the scenario's faults, checked at load time.

    Two faults on one target whose windows can overlap (over the whole range of any drawn
    onset) must both declare ``compose: superpose`` and be of superposable types."""
    sensors = {s.id: s for s in line.sensors}
    windows = []
    for i, f in enumerate(scenario.faults):
        where = f"faults[{i}]"
        ft = CATALOGUE[f.type]
        if ft.target == "sensor" and f.target not in sensors:
            raise InputError(f"{f.type} targets a sensor; no sensor '{f.target}' in the line "
                             f"(known: {', '.join(sorted(sensors)) or 'none'})", file=file,
                             path=f"{where}.target")
        rdim = reading_dimension(line, sensors[f.target])
        try:
            lo, hi = bounds(f.onset, "time")
            if ft.magnitude != "none":
                mlo, mhi = bounds(f.magnitude, magnitude_dimension(f.type, rdim))
                if f.type in ("sensor.noise", "sensor.quantization", "sensor.delay",
                              "sensor.spike") and mlo < 0:
                    raise InputError(f"{f.type} needs a magnitude >= 0", file=file,
                                     path=f"{where}.magnitude")
                if f.type == "sensor.gain" and mlo <= -1:
                    raise InputError("a gain change must be > -1 (the reading would vanish "
                                     "or flip sign)", file=file, path=f"{where}.magnitude")
        except QuantityError as exc:
            raise InputError(str(exc), file=file, path=where) from None
        if hi > scenario.duration:
            raise InputError(f"onset can be {hi:g} s, after the end of the run "
                             f"({scenario.duration:g} s)", file=file, path=f"{where}.onset")
        windows.append((lo, f.end if f.end is not None else math.inf))
    for i, a in enumerate(scenario.faults):
        for j in range(i):
            b = scenario.faults[j]
            if a.target != b.target:
                continue
            (alo, aend), (blo, bend) = windows[i], windows[j]
            if not (alo < bend and blo < aend):
                continue
            if not (a.compose and b.compose):
                raise InputError(
                    f"faults '{b.id}' and '{a.id}' can overlap on '{a.target}' (from "
                    f"{max(alo, blo):g} s); declare compose: superpose on both, or separate "
                    f"them in time", file=file, path=f"faults[{i}]")
            if not ({a.type, b.type} <= SUPERPOSABLE):
                raise InputError(
                    f"faults '{b.id}' ({b.type}) and '{a.id}' ({a.type}) overlap on "
                    f"'{a.target}' and cannot be superposed; separate them in time",
                    file=file, path=f"faults[{i}]")
            if a.profile.shape == "exp" and b.profile.shape == "exp" and \
                    a.profile.ramp != b.profile.ramp:
                raise InputError("two overlapping exp-profile faults on one target need the "
                                 "same time constant", file=file, path=f"faults[{i}].profile")
