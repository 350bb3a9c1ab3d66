"""The sweep file: a base scenario and the axes along which its runs differ.

A sweep sets values of the scenario (and of its line, under ``line.``) by their YAML path,
combines the axes by grid, zip or random sampling, and crosses every combination with the
seeds. The paths and how they are applied are described in docs/sweeps.md; this module only
holds the file's models (the JSON Schema of ``r2rsim schema sweep``).
"""

from __future__ import annotations

import re
from typing import Annotated, Any, Literal

from pydantic import AfterValidator, Field, model_validator

from .. import limits
from .line import Id, Strict
from .parts import NumberOrTextPair
from .quantities import NumberOrText

#: one component of an axis path: a key, a list index, or the id of a list element
PATH_PART = r"(?:[A-Za-z_][A-Za-z0-9_-]*|[0-9]+)"
PATH_RE = re.compile(rf"^{PATH_PART}(?:\.{PATH_PART}|\[[0-9]+\])*$")
NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_.-]*$")


def _matching(regex: re.Pattern, what: str):
    """A validator that refuses a string ``regex`` does not match, saying what it must be
    (a pattern constraint would call every such string "not a valid id")."""

    def check(value: str) -> str:
        if not regex.match(value):
            raise ValueError(f"{value!r} is not {what}")
        return value

    return AfterValidator(check)


AxisName = Annotated[
    str,
    Field(max_length=100, json_schema_extra={"pattern": NAME_RE.pattern}),
    _matching(NAME_RE, "a column name (letters, digits, '_', '.', '-', starting with a letter)"),
]
Path_ = Annotated[
    str,
    Field(max_length=300, json_schema_extra={"pattern": PATH_RE.pattern}),
    _matching(
        PATH_RE,
        "a YAML path (keys, list indices [i] and list element "
        "ids joined by '.': programme[1].line_speed, "
        "faults.my_fault.magnitude)",
    ),
]


class Range(Strict):
    """Evenly spaced values from ``start`` to ``stop`` (both included): ``num`` of them, or
    ``step`` apart. Numbers or strings with units (``"0.5 m/s"``; start, stop and step in one
    dimension)."""

    start: NumberOrText = Field(description="the first value")
    stop: NumberOrText = Field(description="the last value (with step: the last one not beyond it)")
    num: Annotated[int, Field(ge=1, le=limits.MAX_AXIS_VALUES)] | None = Field(
        None, description="how many values"
    )
    step: NumberOrText | None = Field(None, description="their spacing, from start towards stop")

    @model_validator(mode="after")
    def _one_spacing(self):
        if (self.num is None) == (self.step is None):
            raise ValueError("give either num (how many values) or step (their spacing)")
        return self


class Axis(Strict):
    """One axis of a sweep: a path and its values (a list, a range, or a distribution that
    ``combine: random`` draws from)."""

    path: Path_ = Field(
        description="YAML path of the value in the scenario, or under 'line.' "
        "in its line: 'programme[1].line_speed', 'faults.my_fault.magnitude' "
        "(a list element by its id), 'line.web.thickness'"
    )
    name: AxisName | None = Field(
        None, description="column name in runs.parquet (axis.<name>); default the path"
    )
    values: Annotated[list[Any], Field(min_length=1, max_length=limits.MAX_AXIS_VALUES)] | None = (
        Field(
            None,
            description="the values, as the scenario would write them; null on a "
            "list element chosen by id (faults.f) leaves the element out",
        )
    )
    range: Range | None = Field(None, description="evenly spaced numbers")
    uniform: NumberOrTextPair | None = Field(
        None, description="[low, high]: drawn uniformly (combine: random)"
    )
    loguniform: NumberOrTextPair | None = Field(
        None, description="[low, high] > 0: log drawn uniformly (combine: random)"
    )

    @model_validator(mode="after")
    def _one_source(self):
        given = [
            k for k in ("values", "range", "uniform", "loguniform") if getattr(self, k) is not None
        ]
        if len(given) != 1:
            raise ValueError(
                "give exactly one of values, range, uniform, loguniform"
                + (f" (got {', '.join(given)})" if given else "")
            )
        return self

    @property
    def column(self) -> str:
        """The axis's column in runs.parquet."""
        return "axis." + (self.name or self.path.replace("[", ".").replace("]", ""))

    @property
    def is_distribution(self) -> bool:
        return self.uniform is not None or self.loguniform is not None


class Sweep(Strict):
    """A sweep: runs of one base scenario that differ along axes, crossed with seeds."""

    name: Id = Field(
        description="names the sweep, its run ids and its default output directory runs/<name>"
    )
    description: str | None = Field(None, description="free text, for people")
    scenario: str = Field(description="the base scenario file, relative to the sweep file")
    output: str | None = Field(
        None,
        description="output directory, relative to the sweep file and inside its "
        "directory (-o writes anywhere); default runs/<name> in the working directory",
    )
    set: dict[Path_, Any] = Field(
        default_factory=dict,
        description="values set in every run (path: value), before the axes; e.g. {duration: 10 s}",
    )
    axes: Annotated[list[Axis], Field(max_length=100)] = Field(
        default_factory=list, description="the values that change from run to run"
    )
    combine: Literal["grid", "zip", "random"] = Field(
        "grid",
        description="grid: every combination of the axes' values; zip: the i-th "
        "value of every axis together (equal lengths); random: n draws",
    )
    n: Annotated[int, Field(ge=1, le=limits.MAX_SWEEP_RUNS)] | None = Field(
        None, description="combine: random: how many combinations to draw"
    )
    seed: Annotated[int, Field(ge=0, le=limits.MAX_SEED)] = Field(
        0, description="seeds the random draws of the axes; with seeds: N also the first run seed"
    )
    seeds: (
        Annotated[int, Field(ge=1, le=limits.MAX_SWEEP_RUNS)]
        | Annotated[
            list[Annotated[int, Field(ge=0, le=limits.MAX_SEED)]],
            Field(min_length=1, max_length=limits.MAX_SWEEP_RUNS),
        ]
        | None
    ) = Field(
        None,
        description="root seeds of every combination: a count N (seed, seed+1, ..., "
        "seed+N-1) or a list; default the base scenario's seed",
    )

    @model_validator(mode="after")
    def _check(self):
        if self.combine == "random" and self.n is None:
            raise ValueError("@n@ combine: random needs n, the number of combinations to draw")
        if self.combine != "random" and self.n is not None:
            raise ValueError(
                f"@n@ n applies to combine: random (this sweep combines by {self.combine})"
            )
        for i, axis in enumerate(self.axes):
            if axis.is_distribution and self.combine != "random":
                raise ValueError(
                    f"@axes[{i}]@ a distribution (uniform, loguniform) is drawn "
                    f"by combine: random with n; give values or a range to "
                    f"combine by {self.combine}"
                )
        columns = [a.column for a in self.axes]
        for i, c in enumerate(columns):
            if columns.index(c) != i:
                raise ValueError(
                    f"@axes[{i}]@ two axes have the column '{c}'; give one a different name"
                )
        paths = [a.path for a in self.axes]
        for i, p in enumerate(paths):
            if paths.index(p) != i:
                raise ValueError(f"@axes[{i}].path@ the path '{p}' is swept by two axes")
        if isinstance(self.seeds, list) and len(set(self.seeds)) != len(self.seeds):
            raise ValueError("@seeds@ a seed is listed twice")
        return self
