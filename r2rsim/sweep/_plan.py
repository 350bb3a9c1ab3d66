"""From a sweep file to the list of runs: combinations of the axes, crossed with the seeds,
each applied to the base scenario and validated, before anything is simulated."""

from __future__ import annotations

import copy
import hashlib
import itertools
import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import limits
from .._version import __version__
from ..errors import InputError, PlausibilityWarning, R2RError
from ..schema import paths as _paths
from ..schema.line import Line
from ..schema.loader import _validate, build_scenario, line_path_of, load_line, read_yaml
from ..schema.sweep import Axis, Sweep
from ..units import QuantityError, parse_any

#: scenario keys a sweep sets itself (run ids, seeds, where the data goes)
_RESERVED = {
    "name": "the base scenario's name is kept as scenario_id",
    "seed": "give the sweep's seeds: instead",
    "output": "the sweep writes one dataset",
    "line": "one sweep runs one line file",
}
#: invalid combinations listed in full; more are counted
MAX_LISTED = 50


@dataclass(frozen=True)
class Template:
    """The base scenario and line with the sweep's ``set:`` applied, and the axes' paths:
    every run's data is made from it and the run's axis values (so a plan holds one copy of
    the data, not one per run)."""

    scenario: dict
    line: dict
    paths: tuple[str, ...]

    def build(self, values: tuple) -> _Combination:
        return _Combination(self.paths, values, self.scenario, self.line)


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep, as a worker needs it (small: cheap to keep for every run and to
    send to a process)."""

    run_id: str
    seed: int
    combination: int
    values: tuple
    template: Template
    source: str
    line_file: str
    name: str
    line_config: str
    config_sha256: str
    columns: dict
    column_types: tuple

    def data(self) -> tuple[dict, dict]:
        """The run's scenario and line, as mappings read from YAML."""
        combo = self.template.build(self.values)
        return combo.scenario, combo.line

    @property
    def scenario_data(self) -> dict:
        return self.data()[0]

    @property
    def line_data(self) -> dict:
        return self.data()[1]


@dataclass
class SweepPlan:
    """A validated sweep: every run, in order (combination by combination, seeds inside)."""

    sweep: Sweep
    file: Path
    scenario_path: Path
    line_path: Path
    runs: list[RunSpec]
    n_combinations: int
    seeds: list[int]
    axes: list[dict]
    files: dict[str, str]
    warnings: list[str] = field(default_factory=list)

    @property
    def default_output(self) -> Path:
        """The sweep's ``output`` (relative to the sweep file, inside its directory), else
        ``runs/<name>``."""
        if self.sweep.output is None:
            return Path("runs") / self.sweep.name
        base = self.file.resolve().parent
        target = (base / self.sweep.output).resolve()
        if target == base or not target.is_relative_to(base):
            raise InputError(
                f"'{self.sweep.output}' is outside the sweep's directory {base}: "
                f"output names a directory inside it; to write elsewhere give "
                f"-o",
                file=str(self.file),
                path="output",
            )
        return base / self.sweep.output


def load_sweep(path: str | Path) -> Sweep:
    """Read and validate a sweep file (its own keys; :func:`plan_sweep` checks the runs)."""
    path = Path(path)
    sweep = _validate(Sweep, read_yaml(path), str(path))
    for where, p in [
        *((f"set.{k}", k) for k in sweep.set),
        *((f"axes[{i}].path", a.path) for i, a in enumerate(sweep.axes)),
    ]:
        root = _paths.parse(p)[0]
        if root in _RESERVED and len(_paths.parse(p)) == 1:
            raise InputError(f"'{p}' is not swept: {_RESERVED[root]}", file=str(path), path=where)
        try:
            _paths.split_root(p)
        except _paths.PathError as exc:
            raise InputError(str(exc), file=str(path), path=where) from None
    return sweep


def _si(value, file: str, where: str) -> tuple[float, dict | None]:
    """A number (SI, no dimension) or a quantity string: ``(SI value, dimensions)``."""
    if isinstance(value, (int, float)):
        return float(value), None
    try:
        out, dims = parse_any(value)
    except QuantityError as exc:
        raise InputError(str(exc), file=file, path=where) from None
    return out, dims


def _same_dims(pairs: list, file: str, where: str) -> list[float]:
    dims = [d for _, d in pairs if d is not None]
    if any(d != dims[0] for d in dims):
        raise InputError("the values have different dimensions", file=file, path=where)
    return [v for v, _ in pairs]


def _axis_values(axis: Axis, file: str, where: str) -> list:
    """The values of a list or range axis (a range in SI numbers)."""
    if axis.values is not None:
        return list(axis.values)
    r = axis.range
    assert r is not None  # the schema: an axis has values, a range or a distribution
    parts = [_si(r.start, file, f"{where}.range.start"), _si(r.stop, file, f"{where}.range.stop")]
    if r.step is not None:
        parts.append(_si(r.step, file, f"{where}.range.step"))
    nums = _same_dims(parts, file, f"{where}.range")
    start, stop = nums[0], nums[1]
    if r.num is not None:
        return [float(v) for v in np.linspace(start, stop, r.num)]
    step = nums[2]
    if step == 0 or (stop - start) * step < 0:
        raise InputError(
            f"step {step:g} does not lead from {start:g} to {stop:g}",
            file=file,
            path=f"{where}.range.step",
        )
    if not math.isfinite(stop - start):
        raise InputError(
            f"the range from {start:g} to {stop:g} is wider than floating point can hold",
            file=file,
            path=f"{where}.range",
        )
    count = (stop - start) / step  # inf for a step near 1e-320
    if not count <= limits.MAX_AXIS_VALUES:
        raise InputError(
            f"the range from {start:g} to {stop:g} in steps of {step:g} has "
            f"more than {limits.MAX_AXIS_VALUES} values",
            file=file,
            path=f"{where}.range",
        )
    n = math.floor(count * (1 + 1e-12) + 1e-9) + 1
    if n > limits.MAX_AXIS_VALUES:
        raise InputError(
            f"the range has {n} values; at most {limits.MAX_AXIS_VALUES}",
            file=file,
            path=f"{where}.range",
        )
    return [start + i * step for i in range(n)]


def _distribution(axis: Axis, file: str, where: str):
    """A function ``rng -> value`` of a uniform or log-uniform axis (SI)."""
    key = "uniform" if axis.uniform is not None else "loguniform"
    lo, hi = _same_dims(
        [_si(v, file, f"{where}.{key}") for v in getattr(axis, key)], file, f"{where}.{key}"
    )
    if not lo < hi:
        raise InputError(f"low {lo:g} must be below high {hi:g}", file=file, path=f"{where}.{key}")
    if not math.isfinite(hi - lo):  # numpy's uniform cannot draw from a wider interval
        raise InputError(
            f"the interval from {lo:g} to {hi:g} is wider than floating point can hold",
            file=file,
            path=f"{where}.{key}",
        )
    if key == "uniform":
        return lambda rng: float(rng.uniform(lo, hi))
    if lo <= 0:
        raise InputError("loguniform needs low > 0", file=file, path=f"{where}.{key}")
    return lambda rng: float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def combinations(sweep: Sweep, file: str) -> list[tuple]:
    """Every combination: a tuple with one value per axis (in the axes' order).

    Raises
    ------
    InputError
        For axes that cannot be combined (zip of unequal lengths) or too many runs.
    """
    n_seeds = sweep.seeds if isinstance(sweep.seeds, int) else len(sweep.seeds or [0])
    if not sweep.axes:
        return [()]
    if sweep.combine == "random":
        rng = np.random.default_rng(sweep.seed)
        draw = []
        for i, a in enumerate(sweep.axes):
            if a.is_distribution:
                draw.append(_distribution(a, file, f"axes[{i}]"))
            else:
                vals = _axis_values(a, file, f"axes[{i}]")
                draw.append(lambda rng, vals=vals: vals[int(rng.integers(len(vals)))])
        count = sweep.n
        assert count is not None  # the schema: combine: random needs n
        _check_count(count * n_seeds, file)
        return [tuple(d(rng) for d in draw) for _ in range(count)]
    values = [_axis_values(a, file, f"axes[{i}]") for i, a in enumerate(sweep.axes)]
    if sweep.combine == "zip":
        lengths = {len(v) for v in values}
        if len(lengths) > 1:
            shown = ", ".join(
                f"{a.path}: {len(v)}" for a, v in zip(sweep.axes, values, strict=True)
            )
            raise InputError(
                f"combine: zip needs axes of equal length ({shown})", file=file, path="axes"
            )
        _check_count(len(values[0]) * n_seeds, file)
        return list(zip(*values, strict=True))
    _check_count(math.prod(len(v) for v in values) * n_seeds, file)
    return list(itertools.product(*values))


def _check_count(n: int, file: str) -> None:
    if n > limits.MAX_SWEEP_RUNS:
        raise InputError(
            f"the sweep makes {n} runs; at most {limits.MAX_SWEEP_RUNS} "
            f"(docs/security.md): split it",
            file=file,
            path="axes",
        )


def _digest(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=repr).encode()).hexdigest()


def _structure(obj):
    """``obj`` with every number replaced by its type: what the sample columns of a run can
    depend on (which elements, sensors and faults exist), not the values."""
    if isinstance(obj, dict):
        return {k: _structure(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_structure(v) for v in obj]
    if isinstance(obj, (int, float)) and not isinstance(obj, bool):
        return 0
    return obj


class _Combination:
    """One combination applied to copies of the base scenario and line."""

    def __init__(self, paths: tuple[str, ...], values: tuple, scenario: dict, line: dict):
        self.scenario = copy.deepcopy(scenario)
        self.line = copy.deepcopy(line)
        self.values = values
        self.where: dict[int, tuple[str, str]] = {}  # axis -> (root, index path)
        self.applied: dict[str, object] = {}  # path -> value, what makes the run id
        self.removed: list[tuple[str, str]] = []
        self.missing: dict[int, str] = {}  # axis -> why its path is not in the base
        removals = []
        for i, (path, value) in enumerate(zip(paths, values, strict=True)):
            root, parts = _paths.split_root(path)
            data = self.line if root == "line" else self.scenario
            try:
                _paths.resolve(data, parts)
            except _paths.PathError as exc:
                self.missing[i] = str(exc)
            if value is None and not isinstance(parts[-1], int):
                parent = _paths.resolve(data, parts, create=True)[0]
                if isinstance(parent, list):
                    removals.append((i, root, parts))
                    continue
            # a copy: a value (a whole fault) is shared by every combination that has it,
            # and a later axis may set a value inside it (faults.f, then faults.f.magnitude)
            self.where[i] = (root, _paths.set_value(data, parts, copy.deepcopy(value)))
        for i, root, parts in removals:  # after the values set inside the element
            data = self.line if root == "line" else self.scenario
            self.where[i] = (root, _paths.remove(data, parts))
            self.removed.append(self.where[i])
        for i, path in enumerate(paths):
            if self.applies(i):
                self.applied[path] = values[i]

    def applies(self, i: int) -> bool:
        """Whether axis ``i`` has an effect (it is not inside an element another removed)."""
        root, where = self.where[i]
        return not any(
            root == r and where != w and (where.startswith(w + ".") or where.startswith(w + "["))
            for r, w in self.removed
        )


def _apply_set(sweep: Sweep, scenario: dict, line: dict, file: str) -> None:
    for key, value in sweep.set.items():
        root, parts = _paths.split_root(key)
        try:
            _paths.set_value(line if root == "line" else scenario, parts, copy.deepcopy(value))
        except _paths.PathError as exc:
            raise InputError(str(exc), file=file, path=f"set.{key}") from None


def _blame(exc: InputError, combo: _Combination, sweep: Sweep, files: dict) -> list[int]:
    """The axes an error is about: those whose path holds, or lies in, the error's path."""
    root = "line" if exc.file == files["line"] else "scenario"
    path = exc.path or ""
    out = []
    for i in combo.where:
        r, where = combo.where[i]
        if r != root:
            continue
        if (
            path == where
            or path.startswith((where + ".", where + "["))
            or (path and where.startswith((path + ".", path + "[")))
        ):
            out.append(i)
    return out


def _value(v) -> str:
    return json.dumps(v) if not isinstance(v, str) else repr(v)


@dataclass
class _Made:
    """What the plan keeps of a valid combination (not its data: the template rebuilds
    it)."""

    values: tuple
    digest: str
    configs: list[str]  # config_sha256 per seed
    row: dict  # axis column -> SI value
    overrides_json: str
    name: str | None


class _Checker:
    """Validates combinations one by one, collecting problems, warnings and sample-column
    sets (every combination must give the runs the same columns)."""

    def __init__(self, sweep: Sweep, file: str, files: dict, seeds: list[int]):
        self.sweep, self.file, self.files, self.seeds = sweep, file, files, seeds
        self.problems: list[str] = []
        self.invalid: set[int] = set()  # combinations with a problem (one may have several)
        self.warnings: dict[str, int] = {}
        self.lines: dict[str, Line] = {}  # validated lines by their data's digest
        self.columns_of: dict[str, tuple] = {}  # data structure -> sample columns
        self.first: tuple | None = None  # (sample columns, combination) of the first
        self.ids: dict[str, int] = {}

    def fail(self, k: int, problems: list[str]) -> None:
        self.problems += problems
        self.invalid.add(k)

    def check(self, k: int, combo: _Combination) -> _Made | None:
        """The combination's record, or None (a problem noted, or a duplicate skipped)."""
        sweep, file = self.sweep, self.file
        digest = _digest(combo.applied)[:10]
        if digest in self.ids:
            if len(combo.applied) < len(sweep.axes):
                # an axis value inside an element another axis removed: the run of the
                # combination without it (a grid of [null, fault] x magnitudes has one
                # run without the fault, not one per magnitude)
                return None
            self.fail(
                k,
                [
                    f"{file}: draws {self.ids[digest]} and {k} of combine: random make the same "
                    f"run ({_shown(sweep, combo.values)}): the axes' values repeat; draw from "
                    f"uniform or loguniform, draw fewer (n), or combine by grid"
                    if sweep.combine == "random"
                    else f"{file}: combinations {self.ids[digest]} and {k} make the same run "
                    f"({_shown(sweep, combo.values)}): a value is listed twice"
                ],
            )
            return None
        self.ids[digest] = k
        try:
            scenario, line = self._validate(combo)
        except InputError as exc:
            self.fail(k, _problems(exc, combo, sweep, self.files, file))
            return None
        if not self._same_columns(k, combo, scenario, line):
            return None
        data = {"scenario": combo.scenario, "line": combo.line}
        configs = [_digest({**data, "seed": seed, "r2rsim": __version__}) for seed in self.seeds]
        return _Made(
            combo.values,
            digest,
            configs,
            _axis_row(sweep, combo, scenario, line),
            json.dumps(combo.applied, sort_keys=True, default=repr),
            scenario.name,
        )

    def _validate(self, combo: _Combination):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", PlausibilityWarning)
            key = _digest(combo.line)
            line = self.lines.get(key)
            if line is None:
                line = self.lines[key] = load_line(combo.line, file=self.files["line"])
            scenario, line = build_scenario(
                combo.scenario, line, self.files["scenario"], self.files["line"]
            )
        for w in caught:
            msg = w.message.format() if hasattr(w.message, "format") else str(w.message)
            self.warnings[msg] = self.warnings.get(msg, 0) + 1
        return scenario, line

    def _same_columns(self, k: int, combo: _Combination, scenario, line) -> bool:
        structure = _digest([_structure(combo.line), _structure(combo.scenario)])
        if structure not in self.columns_of:
            from ..run import sample_columns

            try:
                self.columns_of[structure] = sample_columns(
                    scenario, line, file=self.files["scenario"]
                )
            except R2RError as exc:
                self.fail(k, [f"{self.file}: {_shown(self.sweep, combo.values)}: {exc}"])
                return False
        cols = self.columns_of[structure]
        if self.first is None:
            self.first = (cols, k)
        elif cols != self.first[0]:
            diff = sorted(set(cols) ^ set(self.first[0]))[:3]
            self.fail(
                k,
                [
                    f"{self.file}: {_shown(self.sweep, combo.values)}: the runs of this "
                    f"combination have other sample columns than those of combination "
                    f"{self.first[1]} ({', '.join(diff)}...); one dataset holds runs of "
                    f"one set of columns: make two sweeps"
                ],
            )
            return False
        return True

    def raise_problems(self, n_combos: int) -> None:
        if not self.problems:
            return
        # one line per problem: the same one in several combinations (an invalid value of
        # one axis, crossed with the others) is listed once, with their number
        counts: dict[str, int] = {}
        for p in self.problems:
            counts[p] = counts.get(p, 0) + 1
        # the sweep file is named once, in front of the list
        problems = [
            p.removeprefix(f"{self.file}: ") + ("" if n == 1 else f" (in {n} combinations)")
            for p, n in counts.items()
        ]
        more = len(problems) - MAX_LISTED
        listed = problems[:MAX_LISTED] + ([f"... and {more} more"] if more > 0 else [])
        n = len(self.invalid)
        err = InputError(
            f"{n} of {_count(n_combos, 'combination')} {'is' if n == 1 else 'are'}"
            f" invalid (nothing was run):\n  " + "\n  ".join(listed),
            file=self.file,
        )
        err.problems = [("", p) for p in problems]
        raise err


def _count(n: int, what: str) -> str:
    return f"{n} {what}{'' if n == 1 else 's'}"


def plan_sweep(path: str | Path) -> SweepPlan:
    """Read a sweep file and make and validate every one of its runs.

    Raises
    ------
    InputError
        For a problem with the sweep file or its base scenario, or when combinations are
        invalid: the message lists every invalid one (file, axis, value, why), up to
        :data:`MAX_LISTED`.
    """
    path = Path(path)
    file = str(path)
    sweep = load_sweep(path)
    scenario_path = path.parent / sweep.scenario
    if not scenario_path.is_file():
        raise InputError(
            f"scenario file '{sweep.scenario}' "
            + ("is not a regular file" if scenario_path.exists() else "not found")
            + f" (looked at {scenario_path.resolve()})",
            file=file,
            path="scenario",
        )
    base = read_yaml(scenario_path)
    line_path = line_path_of(base, scenario_path)
    base_line = read_yaml(line_path)
    files = {"scenario": str(scenario_path), "line": str(line_path)}
    _apply_set(sweep, base, base_line, file)
    seeds = (
        list(sweep.seeds)
        if isinstance(sweep.seeds, list)
        else [sweep.seed + i for i in range(sweep.seeds)]
        if sweep.seeds is not None
        else [base.get("seed", 0) if isinstance(base.get("seed"), int) else 0]
    )
    if seeds[-1] > limits.MAX_SEED:
        raise InputError(f"the last seed {seeds[-1]} is above 2**64 - 1", file=file, path="seeds")
    combos = combinations(sweep, file)
    template = Template(base, base_line, tuple(a.path for a in sweep.axes))
    checker = _Checker(sweep, file, files, seeds)
    made: list[_Made] = []
    for k, values in enumerate(combos):
        try:
            combo = template.build(values)
        except _paths.PathError as exc:
            checker.fail(k, [_path_problem(sweep, values, base, base_line, file, exc)])
            continue
        _check_aliases(sweep, combo, file)
        record = checker.check(k, combo)
        if record is not None:
            made.append(record)
    checker.raise_problems(len(combos))
    axes, runs = _runs(sweep, made, seeds, template, files, scenario_path, line_path)
    line_copy = line_path.name if line_path.name != scenario_path.name else f"line.{line_path.name}"
    copies = {
        f"sweep/{path.name}": path.read_text(encoding="utf-8"),
        f"scenario/{scenario_path.name}": scenario_path.read_text(encoding="utf-8"),
        f"scenario/{line_copy}": line_path.read_text(encoding="utf-8"),
    }
    shown_warnings = [
        m if n == 1 else f"{m} (in {n} combinations)" for m, n in checker.warnings.items()
    ]
    return SweepPlan(
        sweep, path, scenario_path, line_path, runs, len(made), seeds, axes, copies, shown_warnings
    )


def _shown(sweep: Sweep, values: tuple) -> str:
    return (
        ", ".join(f"{a.path} = {_value(v)}" for a, v in zip(sweep.axes, values, strict=True))
        or "the base scenario"
    )


def _check_aliases(sweep: Sweep, combo: _Combination, file: str) -> None:
    """Two spellings of one value (``line.sensors.lc.noise``, ``line.sensors[0].noise``)
    would let the second axis overwrite the first: runs under other ids that are the same
    run. The schema compares the paths as written; here they are compared as resolved."""
    seen: dict[tuple[str, str], int] = {}
    for i, where in sorted(combo.where.items()):
        if where in seen:
            j = seen[where]
            raise InputError(
                f"'{sweep.axes[i].path}' is the value axes[{j}] sweeps "
                f"('{sweep.axes[j].path}'); sweep it once",
                file=file,
                path=f"axes[{i}].path",
            )
        seen[where] = i


def _path_problem(sweep, values, base, base_line, file, exc) -> str:
    """An axis whose path does not lead anywhere in this combination."""
    for i, (axis, value) in enumerate(zip(sweep.axes, values, strict=True)):
        root, parts = _paths.split_root(axis.path)
        try:
            _paths.resolve(base_line if root == "line" else base, parts, create=True)
        except _paths.PathError as e:
            return f"{file}: axes[{i}] ({axis.path}) = {_value(value)}: {e}"
    return f"{file}: {_shown(sweep, values)}: {exc}"


def _problems(exc: InputError, combo, sweep, files, file) -> list[str]:
    out = []
    for p, msg in getattr(exc, "problems", None) or [(exc.path, exc.message)]:
        one = InputError(msg, file=exc.file, path=p or None)
        blamed = _blame(one, combo, sweep, files)
        if blamed:
            who = "; ".join(
                f"axes[{i}] ({sweep.axes[i].path}) = {_value(combo.values[i])}" for i in blamed
            )
        else:
            who = _shown(sweep, combo.values)
        for i in blamed:  # the error is about a mapping the path made on its way
            root, where = combo.where[i]
            if i in combo.missing and p and where.startswith((p + ".", p + "[")):
                who += (
                    f": the path leads nowhere in the base {root} ({combo.missing[i]}); "
                    f"the sweep made a mapping on the way"
                )
                break
        out.append(f"{file}: {who}: {one.format()}")
    return out


def _si_or_text(value):
    """A quantity the model keeps as text (a fault magnitude, whose unit its target fixes)
    as its SI number; anything else as it is."""
    if isinstance(value, str):
        try:
            return parse_any(value)[0]
        except QuantityError:
            return value
    return value


def _column_type(values: list) -> str:
    present = [v for v in values if v is not None]
    if present and all(isinstance(v, bool) for v in present):
        return "bool"
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in present):
        return "float64"
    return "string"


def _as_type(v, kind: str):
    if v is None:
        return None
    if kind == "float64":  # 15 digits: '50 um' is stored as 5e-05, not 4.9999999999999996e-05
        return float(f"{float(v):.15g}")
    if kind == "bool":
        return bool(v)
    return v if isinstance(v, str) else json.dumps(v, sort_keys=True)


def _axis_row(sweep: Sweep, combo: _Combination, scenario, line) -> dict:
    """The axis values of a combination as stored: read back from the validated models (in
    SI), None for an axis that did not apply."""
    dumped = {"scenario": scenario.model_dump(), "line": line.model_dump()}
    row: dict[str, object] = {}
    for i, axis in enumerate(sweep.axes):
        if not combo.applies(i) or combo.values[i] is None:
            row[axis.column] = None
            continue
        root, parts = _paths.split_root(axis.path)
        try:
            value = _paths.get_value(dumped[root], parts)
        except _paths.PathError:  # a key the model stores under another name
            value = combo.values[i]
        row[axis.column] = _si_or_text(value)
    return row


def _runs(sweep, made: list[_Made], seeds, template, files, scenario_path, line_path):
    """The axes' descriptions and the runs (combination by combination, seeds inside)."""
    kinds = {a.column: _column_type([m.row[a.column] for m in made]) for a in sweep.axes}
    axes = [
        {
            "column": a.column,
            "path": a.path,
            "type": kinds[a.column],
            "source": next(
                k for k in ("values", "range", "uniform", "loguniform") if getattr(a, k) is not None
            ),
        }
        for a in sweep.axes
    ]
    types = (
        ("sweep", "string"),
        ("combination", "int64"),
        *((a.column, kinds[a.column]) for a in sweep.axes),
        ("overrides_json", "string"),
        ("config_sha256", "string"),
    )
    runs = []
    base_name = next((m.name for m in made if m.name), None) or scenario_path.stem
    for k, m in enumerate(made):
        for seed, config in zip(seeds, m.configs, strict=True):
            cols = {
                "sweep": sweep.name,
                "combination": k,
                **{c: _as_type(v, kinds[c]) for c, v in m.row.items()},
                "overrides_json": m.overrides_json,
                "config_sha256": config,
            }
            runs.append(
                RunSpec(
                    f"{sweep.name}__{m.digest}__s{seed}",
                    seed,
                    k,
                    m.values,
                    template,
                    files["scenario"],
                    files["line"],
                    m.name or base_name,
                    line_path.stem,
                    config,
                    cols,
                    types,
                )
            )
    return axes, runs
