"""Load line and scenario files: safe YAML, pydantic validation, one clear message per problem."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from ..errors import InputError
from ..units import QuantityError
from .faults import check_faults, target_problem
from .line import Line, draw_problem, torque_problem
from .scenario import Scenario

_CROSS = re.compile(r"^(?:Value error, )?@(?P<path>[^@]*)@ (?P<msg>.*)$", re.S)


def read_yaml(path: str | Path) -> Any:
    """Read a YAML file with the safe loader; errors become :class:`InputError`."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("file not found", file=str(path)) from None
    except OSError as exc:
        raise InputError(f"cannot read file ({exc.strerror})", file=str(path)) from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else None
        problem = getattr(exc, "problem", None) or str(exc)
        raise InputError(f"invalid YAML: {problem}", file=str(path), path=where) from None
    if not isinstance(data, dict):
        raise InputError("expected a mapping of keys at the top level", file=str(path))
    return data


def _yaml_path(loc: tuple, data: Any) -> str:
    """Turn a pydantic location into ``elements[2].roll.core_radius``, dropping union tags."""
    out = ""
    node = data
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
            node = node[part] if isinstance(node, list) and part < len(node) else None
        else:
            if isinstance(node, dict) and part in node:
                out += ("." if out else "") + str(part)
                node = node[part]
            elif isinstance(node, dict) and part not in node and node.get("type") == part:
                continue  # discriminated-union tag inserted by pydantic
            else:
                out += ("." if out else "") + str(part)
                node = None
    return out


def _describe(err: dict) -> tuple[str, str | None]:
    """Return (message, extra path part) for one pydantic error."""
    kind = err["type"]
    ctx = err.get("ctx") or {}
    inp = err.get("input")
    if kind == "extra_forbidden":
        return f"unknown key '{err['loc'][-1]}'", None
    if kind == "missing":
        return f"missing required key '{err['loc'][-1]}'", None
    if kind == "union_tag_invalid":
        tags = ctx.get("expected_tags", "")
        return f"unknown type '{ctx.get('tag')}' (expected one of: {tags})", "type"
    if kind == "union_tag_not_found":
        return "missing key 'type'", None
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        op = {"greater_than": ">", "greater_than_equal": ">=", "less_than": "<",
              "less_than_equal": "<="}[kind]
        bound = next(iter(ctx.values())) if ctx else "?"
        return f"must be {op} {bound}, got {inp!r}", None
    if kind == "literal_error":
        return f"got {inp!r}, expected {ctx.get('expected')}", None
    if kind == "string_pattern_mismatch":
        return f"{inp!r} is not a valid id (letters, digits and '_', starting with a letter)", None
    msg = err["msg"]
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, "):]
    return msg, None


def validation_errors(exc: ValidationError, data: Any) -> list[tuple[str, str]]:
    """All problems of a failed validation as ``[(yaml_path, message), ...]``."""
    out = []
    for err in exc.errors():
        msg, extra = _describe(err)
        m = _CROSS.match(msg)
        if m:
            out.append((m.group("path"), m.group("msg")))
            continue
        path = _yaml_path(err["loc"], data)
        if extra:
            path = f"{path}.{extra}" if path else extra
        out.append((path, msg))
    return out


def _validate(model, data: Any, file: str):
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        problems = validation_errors(exc, data)
        path, msg = problems[0]
        if len(problems) > 1:
            msg += f" (and {len(problems) - 1} more problem{'s' if len(problems) > 2 else ''}; " \
                   f"`r2rsim validate` lists them all)"
        err = InputError(msg, file=file, path=path or None)
        err.problems = problems
        raise err from None


def load_line(source: str | Path | dict) -> Line:
    """Load and validate a line.

    Parameters
    ----------
    source : str, Path or dict
        Path of a line YAML file, or the already-parsed mapping.

    Returns
    -------
    Line
        The validated line with every quantity in SI.

    Raises
    ------
    InputError
        Naming the file, the YAML path and the problem.
    """
    if isinstance(source, dict):
        return _validate(Line, source, "<line>")
    data = read_yaml(source)
    return _validate(Line, data, str(source))


def load_scenario(source: str | Path) -> tuple[Scenario, Line, Path]:
    """Load a scenario and the line it names.

    Returns
    -------
    scenario : Scenario
    line : Line
    line_path : Path
        The resolved path of the line file.
    """
    source = Path(source)
    data = read_yaml(source)
    scenario = _validate(Scenario, data, str(source))
    line_path = (source.parent / scenario.line).resolve()
    if not line_path.exists():
        raise InputError(f"line file '{scenario.line}' not found (looked at {line_path})",
                         file=str(source), path="line")
    line = load_line(line_path)
    check_scenario_against_line(scenario, line, str(source))
    return scenario, line, line_path


def check_scenario_against_line(scenario: Scenario, line: Line, file: str) -> None:
    """References from the scenario into the line (controller and span ids)."""
    tension_ids = {c.id for c in line.controllers if c.type == "tension_pi"}
    for i, step in enumerate(scenario.programme):
        for cid in step.tension or {}:
            if cid not in tension_ids:
                known = ", ".join(sorted(tension_ids)) or "none defined"
                raise InputError(f"no tension controller '{cid}' in the line (known: {known})",
                                 file=file, path=f"programme[{i}].tension.{cid}")
        for eid in step.draw or {}:
            problem = draw_problem(line, eid)
            if problem:
                raise InputError(problem, file=file, path=f"programme[{i}].draw.{eid}")
        for eid in step.torque or {}:
            problem = torque_problem(line, eid)
            if problem:
                raise InputError(problem, file=file, path=f"programme[{i}].torque.{eid}")
        if step.rate is not None and step.line_speed is None:
            raise InputError("rate applies to a line_speed change", file=file,
                             path=f"programme[{i}].rate")
    splicers = [e.id for e in line.elements if getattr(e, "splicer", None) is not None]
    movers = {e.id for e in line.elements if e.type in ("dancer", "pivot_dancer")} | {
        s.id for s in line.spans if s.festoon is not None}
    for i, ev in enumerate(scenario.events):
        if ev.type == "splice":
            if ev.element is None and len(splicers) != 1:
                raise InputError(f"name the unwind to splice (unwinds with a splicer: "
                                 f"{', '.join(splicers) or 'none'})", file=file,
                                 path=f"events[{i}].element")
            if ev.element is not None and ev.element not in splicers:
                raise InputError(f"no unwind with a splicer named '{ev.element}' (known: "
                                 f"{', '.join(splicers) or 'none'})", file=file,
                                 path=f"events[{i}].element")
        if ev.type == "dancer_seize" and ev.element not in movers:
            raise InputError(f"no dancer or festoon named '{ev.element}' (known: "
                             f"{', '.join(sorted(movers)) or 'none'})", file=file,
                             path=f"events[{i}].element")
        if ev.at > scenario.duration:
            raise InputError(f"at {ev.at:g} s is after the end of the run ({scenario.duration:g}"
                             f" s)", file=file, path=f"events[{i}].at")
    check_faults(scenario, line, file)
    check_disturbances(scenario, line, file)
    span_ids = {s.id for s in line.spans}
    for sid in scenario.initial.span_tension:
        if sid not in span_ids:
            raise InputError(f"no span '{sid}' in the line", file=file,
                             path=f"initial.span_tension.{sid}")


def check_disturbances(scenario, line, file: str) -> None:
    """Targets and values of the scenario's process disturbances."""
    eccentric_faults = {f.target for f in scenario.faults if f.type == "process.eccentricity"}
    ids = [e.id for e in line.elements]
    for i, d in enumerate(scenario.disturbances):
        where = f"disturbances[{i}]"
        if d.element not in ids:
            raise InputError(f"no element '{d.element}' in the line (known: {', '.join(ids)})",
                             file=file, path=f"{where}.element")
        e = line.element(d.element)
        drive = getattr(e, "drive", None)
        problem = None
        if d.type == "out_of_round":  # the same rules as an eccentricity fault
            problem = target_problem("process.eccentricity", d.element, line)
            if problem is None and d.element in eccentric_faults:
                problem = (f"'{d.element}' is out of round and also has a "
                           "process.eccentricity fault; give it one or the other")
        elif d.type == "wound_in_strain" and e.type != "unwind":
            problem = f"wound_in_strain applies to an unwind; '{d.element}' is a {e.type}"
        elif d.type == "bearing_drag" and drive is not None and drive.type == "ideal_speed":
            problem = (f"'{d.element}' turns at an imposed speed (ideal_speed drive): a drag "
                       "torque would have no effect")
        if problem:
            raise InputError(problem.replace("process.eccentricity", "out_of_round"),
                             file=file, path=f"{where}.element")
        if d.type == "out_of_round":
            if d.eccentricity >= e.radius:
                raise InputError(f"an eccentricity of {d.eccentricity:g} m is not less than "
                                 f"the roller radius {e.radius:g} m", file=file,
                                 path=f"{where}.eccentricity")
            continue
        try:
            std = d.std_si()
        except QuantityError as exc:
            raise InputError(str(exc), file=file, path=f"{where}.std") from None
        if not std >= 0:
            raise InputError("std must be >= 0", file=file, path=f"{where}.std")


def json_schema(kind: str) -> str:
    """JSON Schema of a ``line`` or ``scenario`` file, for editors."""
    model = {"line": Line, "scenario": Scenario}[kind]
    return json.dumps(model.model_json_schema(), indent=2)
