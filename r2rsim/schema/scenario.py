"""Pydantic models of a scenario file (README.md "A scenario file"; every key: docs/keys.md).

A scenario names a line, a duration, a record rate, a seed, an output location, the initial
state, an operating programme of set-point changes (with operating-mode names), scheduled
events, faults (:mod:`r2rsim.schema.faults`) and the run's data split.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from .. import limits
from ..units import parse_quantity
from .faults import Fault
from .line import Id, Strict
from .quantities import (
    Acceleration,
    Dimensionless,
    Force,
    Frequency,
    Length,
    NumberOrText,
    Speed,
    Time,
    Torque,
)
from .variability import Variability


class ProgrammeStep(Strict):
    """A set-point change at time ``at``: line speed, tension set-points, draws of
    speed-controlled elements and torque commands of open-loop torque drives.

    A change is a step unless ``ramp`` (duration) or ``rate`` (line-speed acceleration) is
    given, in which case the set-point moves linearly to its new value.
    """

    at: Annotated[Time, Field(ge=0)] = Field(description="time of the change [s]")
    line_speed: Speed | None = Field(
        None, description="new line speed [m/s] (the master speed node's surface speed)"
    )
    tension: dict[Id, Annotated[Force, Field(ge=0)]] | None = Field(
        None, description="new set-points of tension controllers, by controller id"
    )
    draw: dict[Id, Annotated[Dimensionless, Field(gt=-1)]] | None = Field(
        None,
        description="new draws (relative speed offsets to the line speed) of "
        "elements with an ideal_speed drive or a non-master speed_pi, by element id",
    )
    torque: dict[Id, Torque] | None = Field(
        None,
        description="new torque commands [N m] of torque drives without a controller, "
        "by element id",
    )
    ramp: Annotated[Time, Field(ge=0)] | None = Field(None, description="ramp duration [s]")
    rate: Annotated[Acceleration, Field(gt=0)] | None = Field(
        None, description="line-speed ramp rate [m/s^2] (instead of ramp)"
    )
    mode: Id | None = Field(
        None, description="operating-mode name from this step on (label.mode), e.g. OC1"
    )

    @model_validator(mode="after")
    def _check(self):
        if (
            self.line_speed is None
            and not self.tension
            and not self.draw
            and not self.torque
            and self.mode is None
        ):
            raise ValueError(
                "a programme step must change line_speed, tension, draw, torque or mode"
            )
        if self.ramp is not None and self.rate is not None:
            raise ValueError("give either ramp (a duration) or rate, not both")
        return self


class ScenarioEvent(Strict):
    """A scheduled discrete event.

    ``splice``: start a roll change on ``element`` (an unwind with a splicer; default the
    only one). ``e_stop``: ramp the line speed down to 0 at ``deceleration``.
    ``dancer_seize``: the dancer (or festoon carriage) ``element`` seizes where it is.
    """

    at: Annotated[Time, Field(ge=0)] = Field(description="time of the event [s]")
    type: Literal["splice", "e_stop", "dancer_seize"] = Field(
        description="splice: start a roll change; e_stop: ramp the line speed down to 0; "
        "dancer_seize: the dancer or festoon carriage seizes where it is"
    )
    element: Id | None = Field(
        None,
        description="splice: the unwind (default the only one with a splicer); "
        "dancer_seize: the dancer or festoon span",
    )
    deceleration: Annotated[Acceleration, Field(gt=0)] | None = Field(
        None, description="e_stop: line deceleration limit [m/s^2]"
    )

    @model_validator(mode="after")
    def _check(self):
        if self.type == "e_stop" and self.deceleration is None:
            raise ValueError("an e_stop needs its deceleration limit")
        if self.type == "dancer_seize" and self.element is None:
            raise ValueError("a dancer_seize names the dancer (element)")
        return self


class Initial(Strict):
    """Initial state. ``steady``: solve for the steady state at the t = 0 set-points (default).
    ``nominal``: all nodes at line speed, every span at ``tension`` (overridable per span)."""

    state: Literal["steady", "nominal"] = Field(
        "steady",
        description="steady: the steady state at the t = 0 set-points; nominal: every "
        "node at line speed, every span at tension",
    )
    tension: Annotated[Force, Field(ge=0)] | None = Field(
        None,
        description="nominal mode: tension of every span [N]; default the first "
        "tension set-point, else 0",
    )
    span_tension: dict[Id, Annotated[Force, Field(ge=0)]] = Field(
        default_factory=dict,
        description="nominal mode: tension [N] of single spans, by span id, instead of tension",
    )
    slack: dict[Id, Annotated[Length, Field(gt=0)]] = Field(
        default_factory=dict,
        description="nominal mode: web [m] a span holds beyond its taut "
        "length, by span id (less than half the span): the span starts slack, at 0 N, as a "
        "web threaded slack before a start-up",
    )
    position: dict[Id, NumberOrText] = Field(
        default_factory=dict,
        description="nominal mode: position at t = 0 of a dancer or "
        "festoon carriage, by id (arm angle for a pivot dancer, travel [m] otherwise), strictly "
        "inside its end stops; default the line's initial position",
    )

    @model_validator(mode="after")
    def _check(self):
        if self.state == "steady" and (self.slack or self.position):
            raise ValueError(
                "slack and position set a nominal start; give state: nominal "
                "(a steady state has no slack and fixes the dancer positions)"
            )
        return self


class SolverOptions(Strict):
    """Integrator settings (solver.md §6)."""

    backend: Literal["cvode", "radau5", "radau"] = Field(
        "radau5",
        description="radau5: r2rsim's compiled Radau IIA, order 5 (default: the "
        "fastest at equal accuracy on the project's benchmark); cvode: SUNDIALS CVODE BDF2 "
        "(scikit-sundae); radau: scipy's Radau (cross-check)",
    )
    rtol: Annotated[float, Field(gt=0, lt=1)] = Field(
        1e-6, description="relative tolerance of the integrator"
    )
    atol_scale: Annotated[float, Field(gt=0)] = Field(
        1.0, description="multiplies the per-state absolute tolerances"
    )
    max_order: Annotated[int, Field(ge=1, le=5)] = Field(
        2,
        description="CVODE's BDF order limit (cvode only); 2 is A-stable (orders 3-5 are "
        "unstable on web modes)",
    )
    chunk_memory_mb: Annotated[float, Field(gt=0)] = Field(
        64.0, description="memory for one integration chunk of dense output"
    )
    max_steps_per_s: Annotated[float, Field(gt=0)] = Field(
        5.0e4,
        description="step budget per simulated second (of at least 1 s): a run that "
        "needs more ends as 'solver_failure: step budget' instead of running for hours (the "
        "shipped scenarios take 25-250 steps/s on radau5, about 10x on cvode)",
    )
    max_wall_s: Annotated[float, Field(gt=0)] | None = Field(
        None,
        description="wall-clock budget of the integration [s]; off by default, since "
        "it makes the data depend on the machine's speed",
    )


class Expect(Strict):
    """How the scenario is meant to end. A run that ends early in a way not listed here
    exits non-zero from ``r2rsim run`` (its data kept and marked in ``runs.parquet``)."""

    termination: list[Literal["web_break", "roll_empty"]] = Field(
        default_factory=list,
        description="early endings that are the point of the scenario "
        "(e.g. [web_break] for a dancer failure that breaks the web); a solver failure is "
        "never expected",
    )

    @field_validator("termination", mode="before")
    @classmethod
    def _one_or_many(cls, v):
        return [v] if isinstance(v, str) else v


class SplitBySeed(Strict):
    """Assign the run to a split from its seed: fractions of train/val/test, deterministic
    in the seed (the same seed always lands in the same split)."""

    by: Literal["seed"] = Field(description="assign the split from the run's seed")
    train: Annotated[float, Field(ge=0, le=1)] = Field(
        0.6, description="fraction of seeds in the train split"
    )
    val: Annotated[float, Field(ge=0, le=1)] = Field(
        0.2, description="fraction of seeds in the val split"
    )
    test: Annotated[float, Field(ge=0, le=1)] = Field(
        0.2, description="fraction of seeds in the test split"
    )

    @model_validator(mode="after")
    def _check(self):
        if abs(self.train + self.val + self.test - 1.0) > 1e-9:
            raise ValueError("train + val + test must be 1")
        return self

    def assign(self, seed: int) -> str:
        import numpy as np

        u = np.random.default_rng(np.random.SeedSequence([seed, 0x5B117])).random()
        return "train" if u < self.train else "val" if u < self.train + self.val else "test"


class Disturbance(Strict):
    """A process disturbance: always present, drawn from the run's process-noise stream
    (one child stream per disturbance, so it depends neither on the solver's steps nor on
    the measurement noise). Not a fault: it carries no label.

    ``bearing_drag``: a random drag torque on a roller, a stationary random signal of
    standard deviation ``std`` [N m] with the first-order spectrum of corner ``bandwidth``
    [Hz] (that of white noise through a first-order filter).
    ``wound_in_strain``: the strain wound into an unwind's roll varies along the web, with
    standard deviation ``std`` and an exponential autocorrelation of ``correlation_length``
    [m] (tension and thickness history of the roll); it enters the first span as the web
    leaves the roll.
    ``out_of_round``: a roller turns about an axis ``eccentricity`` off its centre from
    t = 0, at a random initial angle (see the process.eccentricity fault).

    The random ones are smooth sums of 32 sinusoids by default (``shape``; docs/model.md,
    :mod:`r2rsim.compile.disturbances`).
    """

    type: Literal["bearing_drag", "wound_in_strain", "out_of_round"] = Field(
        description="bearing_drag: a random drag torque on a roller; wound_in_strain: strain "
        "wound into an unwind's roll, varying along the web; out_of_round: an eccentric roller"
    )
    element: Id = Field(
        description="id of the roller (bearing_drag, out_of_round) or unwind (wound_in_strain)"
    )
    std: NumberOrText | None = Field(
        None,
        description="bearing_drag: torque [N m]; wound_in_strain: strain [1]. The "
        "standard deviation: with shape sines, the mean square of every realisation over a "
        "long record is exactly std^2 (32 terms of equal power)",
    )
    bandwidth: Annotated[Frequency, Field(gt=0)] | None = Field(
        None,
        description="bearing_drag: corner frequency f_c [Hz] of the first-order "
        "spectrum S(f) ~ 1/(1 + (f/f_c)^2), autocorrelation exp(-2 pi f_c |lag|); with shape "
        "sines the spectrum is cut off at 10 f_c",
    )
    correlation_length: Annotated[Length, Field(gt=0)] | None = Field(
        None,
        description="wound_in_strain: correlation length l_c [m] along the unwound web, "
        "autocorrelation exp(-|lag|/l_c) (a first-order spectrum of corner 1/(2 pi l_c) per "
        "metre); with shape sines the spectrum is cut off at 10/(2 pi l_c) per metre, "
        "wavelengths down to 0.63 l_c",
    )
    eccentricity: Annotated[Length, Field(gt=0)] | None = Field(
        None,
        description="out_of_round: distance of the axis of rotation from the roller's centre [m]",
    )
    band_limit: Annotated[Frequency, Field(gt=0)] | None = Field(
        None,
        description="bearing_drag with shape sines, optional: drop the terms above this "
        "frequency [Hz] (at least the bandwidth). The terms below it are those the same seed "
        "draws without it, so the run is the full one minus its high-frequency part; the "
        "standard deviation falls to std*sqrt(kept/32). Default none: the spectrum reaches "
        "10 times the bandwidth. A limit below the web's resonances lets the solver take "
        "longer steps (docs/model.md, 'Band-limited disturbances')",
    )
    shape: Literal["sines", "table"] | None = Field(
        None,
        description="bearing_drag and wound_in_strain: 'sines' (default), a smooth sum "
        "of 32 sinusoids with random phases and frequencies drawn from the declared spectrum "
        "cut off at 10 times its corner; 'table', the earlier first-order autoregressive "
        "table interpolated linearly (on the sample grid for a bearing drag, ten points per "
        "correlation length for a wound-in strain), to reproduce data made before r2rsim "
        "issue 16. A table has a kink at every grid point, which the stiff solver must "
        "resolve: about ten times the RHS evaluations",
    )

    @model_validator(mode="after")
    def _check(self):
        need = {
            "bearing_drag": ("std", "bandwidth"),
            "wound_in_strain": ("std", "correlation_length"),
            "out_of_round": ("eccentricity",),
        }[self.type]
        for k in ("std", "bandwidth", "correlation_length", "eccentricity"):
            if (getattr(self, k) is None) == (k in need):
                raise ValueError(
                    f"a {self.type} disturbance "
                    + (f"needs '{k}'" if k in need else f"takes no '{k}'")
                )
        if self.type == "out_of_round" and self.shape is not None:
            raise ValueError("an out_of_round disturbance takes no 'shape'")
        if self.band_limit is not None:
            if self.type != "bearing_drag" or self.shape == "table":
                raise ValueError(
                    "'band_limit' applies to a bearing_drag disturbance of shape sines only"
                )
            assert self.bandwidth is not None  # a bearing_drag needs it (checked above)
            if self.band_limit < self.bandwidth:
                raise ValueError(
                    f"band_limit ({self.band_limit:g} Hz) is below the bandwidth "
                    f"({self.bandwidth:g} Hz): it would remove most of the declared process"
                )
        return self

    def std_si(self) -> float:
        """``std`` in SI (a torque for bearing drag, a plain number for a strain); raises
        :class:`r2rsim.units.QuantityError` for a bad unit."""
        return parse_quantity(
            self.std, "torque" if self.type == "bearing_drag" else "dimensionless"
        )


class Scenario(Strict):
    """An operating scenario for a line."""

    name: Id | None = Field(
        None,
        description="the run's name, an identifier (letters, digits and '_', starting "
        "with a letter): it names the run id <name>__s<seed> and paths in the dataset; "
        "default the file name",
    )
    description: str | None = Field(None, description="free text")
    line: str = Field(description="path of the line file, relative to the scenario file")
    duration: Annotated[Time, Field(gt=0)] = Field(description="simulated time [s]")
    record_rate: Annotated[Frequency, Field(gt=0)] = Field(
        1000.0, description="rate of the recorded samples [Hz]"
    )
    seed: Annotated[int, Field(ge=0, le=limits.MAX_SEED)] = Field(
        0, description="root seed, 0 to 2**64 - 1"
    )
    output: str | None = Field(
        None,
        description="output directory, relative to the scenario file and inside the "
        "directory that holds it (-o writes anywhere); default runs/<scenario name> in the "
        "working directory",
    )
    initial: Initial = Field(default_factory=Initial, description="the state at t = 0")
    programme: Annotated[list[ProgrammeStep], Field(max_length=limits.MAX_PROGRAMME_STEPS)] = Field(
        default_factory=list,
        description="set-point changes in time order; the first, "
        "at 0 s, sets the starting line speed and set-points",
    )
    events: Annotated[list[ScenarioEvent], Field(max_length=limits.MAX_EVENTS)] = Field(
        description="scheduled discrete events: splices, e-stops, dancer seizures",
        default_factory=list,
    )
    solver: SolverOptions = Field(default_factory=SolverOptions, description="integrator settings")
    warmup: Annotated[Time, Field(ge=0)] = Field(
        0.0, description="initial period labelled 'warmup' in the dataset [s]"
    )
    faults: Annotated[list[Fault], Field(max_length=limits.MAX_FAULTS)] = Field(
        description="the faults injected into the run (labelled; r2rsim list faults)",
        default_factory=list,
    )
    disturbances: Annotated[list[Disturbance], Field(max_length=limits.MAX_DISTURBANCES)] = Field(
        default_factory=list, description="process disturbances, always present and not labelled"
    )
    variability: Variability | None = Field(
        None,
        description="unlabelled spread between rolls (modulus, thickness, starting "
        "radius, wound-in strain) and runs (bearing friction, sensor calibration), drawn "
        "from the run's process stream and recorded in variability.parquet",
    )
    split: Literal["train", "val", "test"] | SplitBySeed | None = Field(
        None, description="data split of the run: fixed, or {by: seed, train:, val:, test:}"
    )
    expect: Expect = Field(
        default_factory=Expect, description="how the run is meant to end ({termination: web_break})"
    )

    @model_validator(mode="after")
    def _check(self):
        size = limits.run_size_problem(self.duration, self.record_rate)
        if size is not None:
            raise ValueError(f"@{size[0]}@ {size[1]}")
        last = -1.0
        for i, step in enumerate(self.programme):
            if step.at < last:
                raise ValueError(
                    f"@programme[{i}].at@ steps must be in time order "
                    f"({step.at:g} s comes after {last:g} s)"
                )
            last = step.at
        ids = [f.id for f in self.faults]
        for i, f in enumerate(self.faults):
            if ids.index(f.id) != i:
                raise ValueError(f"@faults[{i}].id@ fault id '{f.id}' is used twice")
        return self

    def split_of(self, seed: int) -> str | None:
        """The run's split (None when the scenario does not say)."""
        if isinstance(self.split, SplitBySeed):
            return self.split.assign(seed)
        return self.split
