"""Load line and scenario files: safe YAML, pydantic validation, one clear message per problem."""

from __future__ import annotations

import codecs
import difflib
import json
import math
import os
import re
import stat
import types
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, Literal, TypeAlias, Union, get_args, get_origin

import yaml
from pydantic import BaseModel, ValidationError
from pydantic_core import ErrorDetails

from .. import limits
from ..errors import InputError, PlausibilityWarning, R2RError
from ..units import QuantityError, parse_quantity
from . import plausibility
from .faults import check_faults, target_problem
from .kinds import kind_of
from .line import Line, draw_problem, pitch_unwind, torque_problem
from .scenario import Scenario
from .variability import sensor_dimension

_CROSS = re.compile(r"^(?:Value error, )?@(?P<path>[^@]*)@ (?P<msg>.*)$", re.S)


class _Problem(yaml.YAMLError):
    """A refused YAML construct, reported without the "invalid YAML" prefix."""

    def __init__(self, problem: str, mark=None):
        super().__init__(problem)
        self.problem = problem
        self.problem_mark = mark


if TYPE_CHECKING:  # a type checker sees one class (a variable cannot be a base class)
    _BaseLoader: TypeAlias = yaml.SafeLoader
else:
    _BaseLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)  # libyaml when it is there


class _Loader(_BaseLoader):
    """The safe loader (no Python objects, no code) with duplicate keys refused and integers
    limited to :data:`r2rsim.limits.MAX_INT_CHARS` characters."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen: dict = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge" or not isinstance(
                    key_node, yaml.ScalarNode
                ):
                    continue  # '<<' merges may be overridden; other keys fail as unhashable
                key = self.construct_object(key_node)
                try:
                    first = seen.setdefault(key, key_node)
                except TypeError:
                    continue
                if first is not key_node:
                    raise _Problem(
                        f"duplicate key '{key}' (first given at line "
                        f"{first.start_mark.line + 1}); give each key once",
                        key_node.start_mark,
                    )
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node):
        if len(node.value) > limits.MAX_INT_CHARS:
            raise _Problem(
                f"an integer of {len(node.value)} characters is too long (at most "
                f"{limits.MAX_INT_CHARS})",
                node.start_mark,
            )
        return super().construct_yaml_int(node)


_Loader.add_constructor("tag:yaml.org,2002:int", _Loader.construct_yaml_int)
# YAML 1.1 reads 1e-4 (no decimal point) as a string; YAML 1.2 and people read a number.
# The models take no strings for plain numbers, so resolve it as a float here.
_Loader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*)(?:\.[0-9_]*)?[eE][-+]?[0-9]+$"),
    list("-+0123456789"),
)

_BOMS = (
    (codecs.BOM_UTF32_LE, "UTF-32"),
    (codecs.BOM_UTF32_BE, "UTF-32"),
    (codecs.BOM_UTF16_LE, "UTF-16"),
    (codecs.BOM_UTF16_BE, "UTF-16"),
)
_CONTROL = re.compile(r"[\x00-\x08\x0b\x0c\x0e-\x1f\x7f]")


def _read_bytes(path: Path) -> bytes:
    """The bytes of a regular file of at most :data:`r2rsim.limits.MAX_FILE_BYTES`.

    Opened without blocking and checked with ``fstat`` on the open descriptor, so a FIFO, a
    device (``/dev/zero`` reads forever) or a directory is refused before a byte is read.
    """
    file = str(path)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(path, flags)
    except FileNotFoundError:
        raise InputError("file not found", file=file) from None
    except OSError as exc:
        raise InputError(f"cannot read file ({exc.strerror})", file=file) from None
    to_close: int | None = fd  # None once the file object owns the descriptor
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            kind = (
                "a directory"
                if stat.S_ISDIR(st.st_mode)
                else "a FIFO (named pipe)"
                if stat.S_ISFIFO(st.st_mode)
                else "a device"
                if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode)
                else "a socket"
                if stat.S_ISSOCK(st.st_mode)
                else "not a regular file"
            )
            raise InputError(f"is {kind}; line and scenario files must be regular files", file=file)
        if st.st_size > limits.MAX_FILE_BYTES:
            raise InputError(_too_big(st.st_size), file=file)
        with os.fdopen(fd, "rb") as f:
            to_close = None
            data = f.read(limits.MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise InputError(f"cannot read file ({exc.strerror})", file=file) from None
    finally:
        if to_close is not None:
            os.close(to_close)
    if len(data) > limits.MAX_FILE_BYTES:  # it grew while being read
        raise InputError(_too_big(len(data)), file=file)
    return data


def _too_big(size: int) -> str:
    return (
        f"the file is {size} bytes, more than the limit of {limits.MAX_FILE_BYTES} bytes "
        "(1 MiB; docs/security.md)"
    )


def _decode(data: bytes, file: str) -> str:
    """UTF-8 text (a UTF-8 byte-order mark is dropped); anything else is refused, with the
    line and column of the first byte that is not UTF-8."""
    for bom, name in _BOMS:
        if data.startswith(bom):
            raise InputError(f"the file is {name} text; save it as UTF-8", file=file)
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8) :]
    nul = data.find(b"\x00")
    if nul >= 0:
        raise InputError(
            "the file contains NUL bytes (a binary file, or UTF-16 text without "
            "a byte-order mark?); save it as UTF-8 text",
            file=file,
            path=_where(data, nul),
        )
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(
            f"not UTF-8 text: byte 0x{data[exc.start]:02x} cannot be read "
            "(Latin-1 or another encoding?); save the file as UTF-8",
            file=file,
            path=_where(data, exc.start),
        ) from None


def _where(data, offset: int) -> str:
    """``line L, column C`` of a byte or character offset."""
    nl = "\n" if isinstance(data, str) else b"\n"
    line = data.count(nl, 0, offset) + 1
    return f"line {line}, column {offset - (data.rfind(nl, 0, offset) + 1) + 1}"


def _check_nesting(text: str) -> None:
    """Refuse nesting deeper than :data:`r2rsim.limits.MAX_NESTING` from the parser's event
    stream, before the composer (which recurses once per level, and crashes libyaml when
    deep enough) builds anything.

    The libyaml of newer PyYAML wheels (6.0.4) refuses 1000 levels itself, in its scanner,
    which reads a flow collection ahead before the first event: the nesting is then
    located again with the pure-Python parser (no such limit, not recursive), so the
    message and place do not depend on the PyYAML release."""
    try:
        _nesting_events(text, _Loader)
    except yaml.YAMLError as exc:
        if _Loader is yaml.SafeLoader or "nesting depth" not in str(
            getattr(exc, "problem", None) or exc
        ):
            raise
        _nesting_events(text, yaml.SafeLoader)
        raise


def _nesting_events(text: str, loader) -> None:
    depth = 0
    for ev in yaml.parse(text, Loader=loader):
        if isinstance(ev, (yaml.SequenceStartEvent, yaml.MappingStartEvent)):
            depth += 1
            if depth > limits.MAX_NESTING:
                raise _Problem(
                    f"lists and mappings are nested more than {limits.MAX_NESTING} levels deep",
                    ev.start_mark,
                )
        elif isinstance(ev, (yaml.SequenceEndEvent, yaml.MappingEndEvent)):
            depth -= 1


#: one entry of :func:`_check_values`' walk: (node, depth, parent entry, key in the parent)
_Entry: TypeAlias = "tuple[Any, int, _Entry | None, Any]"


def _check_values(data: Any, file: str) -> None:
    """Walk the parsed data once, without recursion: refuse control characters (NUL,
    escape...) in strings and keys, nesting deeper than :data:`r2rsim.limits.MAX_NESTING`
    and data that expands to more than :data:`r2rsim.limits.MAX_VALUES` values (the text was
    checked, but YAML aliases can nest data in itself or repeat it exponentially)."""

    def path_of(entry) -> str | None:  # built only for a message: cheap walk, long paths
        parts = []
        while entry is not None and entry[3] is not None:
            key = entry[3]
            parts.append(f"[{key}]" if isinstance(key, int) else f".{key}")
            entry = entry[2]
        return "".join(reversed(parts)).lstrip(".") or None

    stack: list[_Entry] = [(data, 0, None, None)]
    count = 0
    while stack:
        entry = stack.pop()
        node, depth = entry[0], entry[1]
        count += 1
        if count > limits.MAX_VALUES:
            raise InputError(
                f"the file expands to more than {limits.MAX_VALUES} values "
                "(YAML aliases that repeat other aliases?)",
                file=file,
            )
        if depth > limits.MAX_NESTING:
            raise InputError(
                f"lists and mappings are nested more than {limits.MAX_NESTING} "
                "levels deep (through YAML aliases; one that refers to itself?)",
                file=file,
                path=path_of(entry[2]),
            )
        if isinstance(node, str):
            m = _CONTROL.search(node)
            if m:
                raise InputError(
                    f"the string contains the control character "
                    f"{m.group()!r} (NUL, escape and other control characters "
                    "are not allowed)",
                    file=file,
                    path=path_of(entry),
                )
        elif isinstance(node, dict):
            for k, v in node.items():
                if isinstance(k, str) and _CONTROL.search(k):
                    raise InputError(
                        f"the key {k!r} contains a control character",
                        file=file,
                        path=path_of(entry),
                    )
                stack.append((v, depth + 1, entry, k))
        elif isinstance(node, list):
            stack.extend((v, depth + 1, entry, i) for i, v in enumerate(node))


def read_yaml(path: str | Path) -> Any:
    """Read a YAML file with the safe loader; errors become :class:`InputError`.

    The file must be a regular file of at most 1 MiB of UTF-8 text (:mod:`r2rsim.limits`);
    duplicate keys, control characters in strings, nesting deeper than 32 levels and
    integers longer than 100 characters are refused.
    """
    path = Path(path)
    file = str(path)
    text = _decode(_read_bytes(path), file)
    try:
        _check_nesting(text)
        data = yaml.load(text, Loader=_Loader)  # noqa: S506 - a safe loader
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else None
        if isinstance(exc, yaml.reader.ReaderError) or (
            mark is None and isinstance(getattr(exc, "position", None), int)
        ):
            where = _where(text, exc.position)
            ch = exc.character
            problem = (
                f"unacceptable character U+{ch:04X} ({exc.reason})"
                if isinstance(ch, int)
                else f"unacceptable character {ch!r}"
            )
        else:
            problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        prefix = "" if isinstance(exc, _Problem) else "invalid YAML: "
        raise InputError(f"{prefix}{problem}", file=file, path=where) from None
    except (RecursionError, MemoryError, ValueError, OverflowError) as exc:
        raise InputError(
            f"invalid YAML: {str(exc).splitlines()[0] if str(exc) else exc!r}", file=file
        ) from None
    if not isinstance(data, dict):
        raise InputError("expected a mapping of keys at the top level", file=file)
    _check_values(data, file)
    return data


# the tag pydantic puts in an error's location for the member of a union it tried: a model
# name (CamelCase), a type (float, list[...]) or a validator (function-before[...])
_UNION_LABEL = re.compile(r"^(?:[A-Z]\w*|float|int|str|bool|none|[\w-]+\[.*\])$", re.S)


def _locate(loc: tuple, data: Any) -> tuple[str, int, tuple | None]:
    """A pydantic location in the data: ``(yaml_path, depth, member)``. ``depth`` counts the
    parts found in the data; ``member`` is ``(path, tag)`` of the first union member's tag
    pydantic inserted (None when there is none)."""
    out = ""
    node = data
    depth = 0
    member = None
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
            if isinstance(node, list) and part < len(node):
                node, depth = node[part], depth + 1
            else:
                node = None
            continue
        if isinstance(node, dict) and part in node:
            out += ("." if out else "") + str(part)
            node, depth = node[part], depth + 1
        elif isinstance(node, dict) and node.get("type") == part:
            continue  # discriminated-union tag: the one member tried, not an alternative
        elif (node is not None and not isinstance(node, dict)) or (
            isinstance(node, dict) and _UNION_LABEL.match(str(part))
        ):
            if member is None:  # the tag of a union member pydantic tried
                member = (out, str(part))
        else:
            out += ("." if out else "") + str(part)
            node = None
    return out, depth, member


def _yaml_path(loc: tuple, data: Any) -> str:
    """Turn a pydantic location into ``elements[2].roll.core_radius``, dropping union tags."""
    return _locate(loc, data)[0]


def _union_errors(errors: list[ErrorDetails], data: Any) -> list[ErrorDetails]:
    """Of the union members that each reported errors for one value, keep the ones that got
    furthest into the data, and of those the ones whose errors are not all plain type
    mismatches: ``wound_in_strain: [0.001, .inf]`` is about the .inf (the list member), not
    about a list not being a number (the scalar member)."""
    info = [_locate(e["loc"], data) for e in errors]
    unions: dict[str, dict[str, list[int]]] = {}
    for i, (_, _, member) in enumerate(info):
        if member is not None:
            unions.setdefault(member[0], {}).setdefault(member[1], []).append(i)
    drop: set[int] = set()
    for members in unions.values():
        depth = {tag: max(info[i][1] for i in idx) for tag, idx in members.items()}
        best = [tag for tag in members if depth[tag] == max(depth.values())]
        typed = {
            tag for tag in best if all(errors[i]["type"].endswith("_type") for i in members[tag])
        }
        if len(typed) < len(best):
            best = [tag for tag in best if tag not in typed]
        drop |= {i for tag, idx in members.items() if tag not in best for i in idx}
    return [e for i, e in enumerate(errors) if i not in drop]


def _describe(err: ErrorDetails) -> tuple[str, str | None]:
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
        op = {
            "greater_than": ">",
            "greater_than_equal": ">=",
            "less_than": "<",
            "less_than_equal": "<=",
        }[kind]
        bound = next(iter(ctx.values())) if ctx else "?"
        return f"must be {op} {bound}, got {inp!r}", None
    if kind == "literal_error":
        return f"got {inp!r}, expected {ctx.get('expected')}", None
    if kind == "string_pattern_mismatch":
        return f"{inp!r} is not a valid id (letters, digits and '_', starting with a letter)", None
    if kind == "finite_number":
        return f"{inp} is not a finite number (.nan and .inf are not allowed)", None
    if kind in (
        "float_type",
        "int_type",
        "bool_type",
        "float_parsing",
        "int_parsing",
        "int_from_float",
    ):
        want = {
            "bool_type": "true or false",
            "int_type": "a whole number",
            "int_parsing": "a whole number",
            "int_from_float": "a whole number",
        }.get(kind, "a number")
        if isinstance(inp, bool):
            return f"expected {want}, got {str(inp).lower()} (a boolean)", None
        return f"expected {want}, got {inp!r}", None
    if kind == "too_long":
        n, most = ctx.get("actual_length"), ctx.get("max_length")
        return (
            f"too many entries ({n}); at most {most} (docs/security.md)"
            if n is not None
            else f"too many entries; at most {most}"
        ), None
    if kind == "recursion_loop":
        return "the data refers to itself (a YAML alias inside its own anchor)", None
    msg = err["msg"]
    if msg.startswith("Value error, "):
        msg = msg[len("Value error, ") :]
    return msg, None


def _unwrap(tp):
    """The type inside ``Annotated[...]`` (and nested ones)."""
    while get_origin(tp) is Annotated:
        tp = get_args(tp)[0]
    return tp


def _union_members(tp) -> list | None:
    if get_origin(tp) in (Union, types.UnionType):
        return [_unwrap(a) for a in get_args(tp) if a is not type(None)]
    return None


def _is_model(tp) -> bool:
    return isinstance(tp, type) and issubclass(tp, BaseModel)


def _field_keys(model) -> set[str]:
    return {k for name, f in model.model_fields.items() for k in (name, f.alias) if k}


def _tags(model) -> set[str]:
    """What pydantic names a union member by in an error's location: its ``type`` literal
    (a discriminated union) and its class name."""
    out = {model.__name__}
    f = model.model_fields.get("type")
    if f is not None and get_origin(_unwrap(f.annotation)) is Literal:
        out |= {str(v) for v in get_args(_unwrap(f.annotation))}
    return out


def allowed_keys(tp, loc: tuple) -> set[str]:
    """The keys a mapping at the pydantic location ``loc`` (inside a value of type ``tp``)
    may have: the fields (and aliases) of the model(s) there; empty when there is none."""
    tp = _unwrap(tp)
    members = _union_members(tp)
    if members is not None:
        if loc and isinstance(loc[0], str):
            tagged = [m for m in members if _is_model(m) and loc[0] in _tags(m)]
            if tagged:
                return set().union(*(allowed_keys(m, loc[1:]) for m in tagged))
            if _UNION_LABEL.match(loc[0]) and not any(
                _is_model(m) and loc[0] in m.model_fields for m in members
            ):
                return set().union(*(allowed_keys(m, loc[1:]) for m in members))
        return set().union(*(allowed_keys(m, loc) for m in members))
    if not loc:
        return _field_keys(tp) if _is_model(tp) else set()
    part, rest = loc[0], loc[1:]
    if _is_model(tp):
        for name, f in tp.model_fields.items():
            if part in (name, f.alias):
                return allowed_keys(f.annotation, rest)
        return set()
    origin, args = get_origin(tp), get_args(tp)
    if origin in (list, tuple, set, frozenset) and args and isinstance(part, int):
        return allowed_keys(args[0], rest)
    if origin is dict and len(args) == 2:
        return allowed_keys(args[1], rest)
    return set()


def _parent(node: Any, parts: list) -> Any:
    for p in parts:
        if isinstance(node, dict) and p in node:
            node = node[p]
        elif isinstance(node, list) and isinstance(p, int) and p < len(node):
            node = node[p]
        else:
            return None
    return node


def _data_parts(loc: tuple, data: Any) -> list:
    """The parts of a pydantic location that are in the data (union tags dropped)."""
    out, node = [], data
    for part in loc:
        if isinstance(node, dict) and part in node:
            out.append(part)
            node = node[part]
        elif isinstance(node, list) and isinstance(part, int) and part < len(node):
            out.append(part)
            node = node[part]
        elif isinstance(node, dict):
            continue  # a union member's tag
        else:
            break
    return out


def suggestion(key: Any, allowed: set[str], present=()) -> list[str] | None:
    """The allowed keys closest to a misspelt one (difflib, closest first; at most 3), if
    any is close; keys the mapping already has are not suggested."""
    if not isinstance(key, str):
        return None
    left = sorted(k for k in allowed if k not in present and k != key)
    close = difflib.get_close_matches(key, left, n=3, cutoff=0.7) or difflib.get_close_matches(
        key.lower(), left, n=3, cutoff=0.7
    )
    return close or None


def _did_you_mean(close: list[str]) -> str:
    names = [f"'{k}'" for k in close]
    listed = ", ".join(names[:-1]) + " or " + names[-1] if len(names) > 1 else names[0]
    return f" (did you mean {listed}?)"


def _unknown_keys_first(
    errors: list[ErrorDetails], model, data: Any
) -> tuple[list[ErrorDetails], dict]:
    """Suggestions for the unknown keys (``id(err) -> key``), the unknown keys that resemble
    a missing required key put first, and those missing-key errors dropped: the typo is the
    one problem (``durations: 60 s`` is an unknown key, not a missing ``duration``)."""
    hints: dict[int, list[str]] = {}
    for err in errors:
        if err["type"] == "extra_forbidden":
            allowed = allowed_keys(model, tuple(err["loc"][:-1]))
            parent = _parent(data, _data_parts(err["loc"][:-1], data))
            hint = suggestion(
                err["loc"][-1], allowed, parent.keys() if isinstance(parent, dict) else ()
            )
            if hint is not None:
                hints[id(err)] = hint
    missing = {(tuple(e["loc"][:-1]), e["loc"][-1]): e for e in errors if e["type"] == "missing"}
    first, drop = [], set()
    for err in errors:
        gone = [
            missing[key]
            for key in ((tuple(err["loc"][:-1]), h) for h in hints.get(id(err), ()))
            if key in missing
        ]
        if gone:
            first.append(err)
            drop.add(id(gone[0]))
    rest = [e for e in errors if id(e) not in drop and all(e is not f for f in first)]
    return first + rest, hints


def validation_errors(
    exc: ValidationError, data: Any, model=None, file: str | None = None
) -> list[tuple[str, str]]:
    """All problems of a failed validation as ``[(yaml_path, message), ...]``.

    With the ``model`` validated, an unknown key gets the allowed key closest to it ("did you
    mean ...?"), and one that resembles a missing required key is reported first, instead of
    that key's absence. With the ``file`` the data was read from, the path of an unknown key
    is preceded by its line in the file (``line 4: durations``), and the message followed by
    that line of the file."""
    errors = _union_errors(exc.errors(), data)
    hints: dict = {}
    if model is not None:
        errors, hints = _unknown_keys_first(errors, model, data)
    source = None
    out = []
    for err in errors:
        msg, extra = _describe(err)
        m = _CROSS.match(msg)
        if m:
            out.append((m.group("path"), m.group("msg")))
            continue
        path = _yaml_path(err["loc"], data)
        if extra:
            path = f"{path}.{extra}" if path else extra
        if err["type"] == "extra_forbidden":
            if id(err) in hints:
                msg += _did_you_mean(hints[id(err)])
            if file is not None:
                if source is None:
                    source = _SourceLines(file)
                where = source.key_line(_data_parts(err["loc"], data))
                if where is not None:
                    number, text = where
                    path = f"line {number}: {path}" if path else f"line {number}"
                    msg += f"\n    {text}"
        out.append((path, msg))
    return out


class _SourceLines:
    """The lines of a YAML file where keys are, read again only when an error needs them."""

    def __init__(self, file: str):
        self.root = None
        try:
            path = Path(file)
            if path.is_file():
                self.text = _decode(_read_bytes(path), file)
                self.root = yaml.compose(self.text, Loader=_BaseLoader)
        except (R2RError, OSError, yaml.YAMLError, RecursionError, ValueError):
            self.root = None

    def key_line(self, parts: list) -> tuple[int, str] | None:
        """``(line number, the line's text)`` of the key at ``parts`` in the file (None when
        the file does not have it there: the data came from elsewhere, e.g. a sweep)."""
        node, key_node = self.root, None
        for part in parts:
            if isinstance(node, yaml.MappingNode):
                found = [
                    (k, v)
                    for k, v in node.value
                    if isinstance(k, yaml.ScalarNode) and k.value == str(part)
                ]
                if not found:
                    return None
                key_node, node = found[-1]
            elif (
                isinstance(node, yaml.SequenceNode)
                and isinstance(part, int)
                and part < len(node.value)
            ):
                key_node, node = None, node.value[part]
            else:
                return None
        if key_node is None:
            return None
        i = key_node.start_mark.line
        lines = self.text.splitlines()
        return (i + 1, lines[i].strip()) if i < len(lines) else None


def _validate(model, data: Any, file: str):
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        problems = validation_errors(exc, data, model, file)
        path, msg = problems[0]
        if len(problems) > 1:
            msg, nl, quoted = msg.partition("\n")  # the quoted source line stays last
            msg += (
                f" (and {len(problems) - 1} more problem{'s' if len(problems) > 2 else ''}; "
                f"`r2rsim validate` lists them all){nl}{quoted}"
            )
        err = InputError(msg, file=file, path=path or None)
        err.problems = problems
        raise err from None


def load_line(source: str | Path | dict, file: str | None = None) -> Line:
    """Load and validate a line.

    Parameters
    ----------
    source : str, Path or dict
        Path of a line YAML file, or the already-parsed mapping.
    file : str, optional
        The file named in error messages (default: the path, or ``<line>`` for a mapping).

    Returns
    -------
    Line
        The validated line with every quantity in SI.

    Raises
    ------
    InputError
        Naming the file, the YAML path and the problem.
    """
    if file is None:
        file = "<line>" if isinstance(source, dict) else str(source)
    data = source if isinstance(source, dict) else read_yaml(source)
    line = _validate(Line, data, file)
    _report(plausibility.line_problems(line), file)
    return line


def line_path_of(scenario_data: dict, scenario_file: str | Path) -> Path:
    """The line file a scenario names (``line:``, relative to the scenario file), checked to
    be a regular file.

    Raises
    ------
    InputError
        When ``line`` is missing or not a string, or the file is not there or not a regular
        file.
    """
    source = Path(scenario_file)
    name = scenario_data.get("line") if isinstance(scenario_data, dict) else None
    if not isinstance(name, str):
        # the scenario's own validation says what is wrong with it
        _validate(Scenario, scenario_data, str(source))
        raise InputError("missing required key 'line'", file=str(source), path="line")
    try:
        line_path = (source.parent / name).resolve()
        found = line_path.exists()
    except (OSError, ValueError) as exc:
        raise InputError(
            f"cannot use '{name}' as a path ({exc})", file=str(source), path="line"
        ) from None
    if found and not line_path.is_file():  # a device (/dev/zero), FIFO or directory
        raise InputError(
            f"'{name}' is not a regular file ({line_path}); a line file must be one",
            file=str(source),
            path="line",
        )
    if not found:
        raise InputError(
            f"line file '{name}' not found (looked at {line_path})", file=str(source), path="line"
        )
    return line_path


def build_scenario(
    data: dict, line_data: dict | Line, file: str, line_file: str
) -> tuple[Scenario, Line]:
    """Validate a scenario and its line from parsed mappings (what :func:`load_scenario`
    does after reading the files; a sweep calls it with its overrides applied).

    Parameters
    ----------
    data : dict
        The scenario, as read from YAML.
    line_data : dict or Line
        The line, as read from YAML (or already validated).
    file, line_file : str
        The files named in error messages.

    Raises
    ------
    InputError
        Naming the file, the YAML path and the problem.
    """
    scenario = _validate(Scenario, data, file)
    line = line_data if isinstance(line_data, Line) else load_line(line_data, file=line_file)
    check_scenario_against_line(scenario, line, file)
    _report(plausibility.scenario_problems(scenario, line), file)
    return scenario, line


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
    _validate(Scenario, data, str(source))  # the scenario's own problems first
    line_path = line_path_of(data, source)
    scenario, line = build_scenario(data, read_yaml(line_path), str(source), str(line_path))
    return scenario, line, line_path


def _report(problems: list[tuple[str, str, str]], file: str) -> None:
    """Raise the plausibility errors (all of them in ``.problems``, for ``r2rsim validate``),
    else issue the warnings as :class:`PlausibilityWarning`."""
    errors = [(path, msg) for level, path, msg in problems if level == plausibility.ERROR]
    if errors:
        path, msg = errors[0]
        if len(errors) > 1:
            msg += (
                f" (and {len(errors) - 1} more problem{'s' if len(errors) > 2 else ''}; "
                f"`r2rsim validate` lists them all)"
            )
        err = InputError(msg, file=file, path=path)
        err.problems = errors
        raise err
    for _, path, msg in problems:
        warnings.warn(PlausibilityWarning(msg, file=file, path=path), stacklevel=3)


def check_scenario_against_line(scenario: Scenario, line: Line, file: str) -> None:
    """References from the scenario into the line (controller and span ids)."""
    tension_ids = {c.id for c in line.controllers if c.type == "tension_pi"}
    for i, step in enumerate(scenario.programme):
        for cid in step.tension or {}:
            if cid not in tension_ids:
                known = ", ".join(sorted(tension_ids)) or "none defined"
                raise InputError(
                    f"no tension controller '{cid}' in the line (known: {known})",
                    file=file,
                    path=f"programme[{i}].tension.{cid}",
                )
        for eid in step.draw or {}:
            problem = draw_problem(line, eid)
            if problem:
                raise InputError(problem, file=file, path=f"programme[{i}].draw.{eid}")
        for eid in step.torque or {}:
            problem = torque_problem(line, eid)
            if problem:
                raise InputError(problem, file=file, path=f"programme[{i}].torque.{eid}")
        if step.rate is not None and step.line_speed is None:
            raise InputError(
                "rate applies to a line_speed change", file=file, path=f"programme[{i}].rate"
            )
    splicers = [e.id for e in line.elements if getattr(e, "splicer", None) is not None]
    movers = _mover_ids(line)
    for i, ev in enumerate(scenario.events):
        if ev.type == "splice":
            if not splicers:
                raise InputError(
                    "no unwind of the line has a splicer: give the unwind a "
                    "'splicer:' (docs/keys.md) to splice onto a new roll",
                    file=file,
                    path=f"events[{i}]",
                )
            if ev.element is None and len(splicers) > 1:
                raise InputError(
                    f"name the unwind to splice (unwinds with a splicer: {', '.join(splicers)})",
                    file=file,
                    path=f"events[{i}].element",
                )
            if ev.element is not None and ev.element not in splicers:
                raise InputError(
                    f"no unwind with a splicer named '{ev.element}' (known: "
                    f"{', '.join(splicers) or 'none'})",
                    file=file,
                    path=f"events[{i}].element",
                )
        if ev.type == "dancer_seize" and ev.element not in movers:
            raise InputError(
                f"no dancer or festoon named '{ev.element}' (known: {', '.join(movers) or 'none'})",
                file=file,
                path=f"events[{i}].element",
            )
        if ev.at > scenario.duration:
            raise InputError(
                f"at {ev.at:g} s is after the end of the run ({scenario.duration:g} s)",
                file=file,
                path=f"events[{i}].at",
            )
    check_faults(scenario, line, file)
    check_disturbances(scenario, line, file)
    check_variability(scenario, line, file)
    span_ids = {s.id for s in line.spans}
    for key in ("span_tension", "slack"):
        for sid in getattr(scenario.initial, key):
            if sid not in span_ids:
                raise InputError(
                    f"no span '{sid}' in the line", file=file, path=f"initial.{key}.{sid}"
                )
    _check_initial_positions(scenario, line, file)


def _mover_ids(line) -> list[str]:
    """Ids of the line's dancers and festoon carriages, in line order."""
    return [e.id for e in line.elements if kind_of(e).is_mover] + [
        s.id for s in line.spans if s.festoon is not None
    ]


def _check_initial_positions(scenario, line, file: str) -> None:
    """``initial.position``: a dancer or festoon, in its unit, strictly inside its stops (a
    mover started on a stop would not latch there). Converts the values to SI in place."""
    movers = _mover_ids(line)
    for mid, value in scenario.initial.position.items():
        path = f"initial.position.{mid}"
        if mid not in movers:
            raise InputError(
                f"no dancer or festoon named '{mid}' (known: {', '.join(movers) or 'none'})",
                file=file,
                path=path,
            )
        el = next((e for e in line.elements if e.id == mid and kind_of(e).is_mover), None)
        sp = next((s for s in line.spans if s.id == mid and s.festoon is not None), None)
        if el is not None:
            kind = kind_of(el)
            dim, (lo, hi), what = kind.coordinate_dimension, kind.mover_range(el), kind.range_key
        else:
            assert sp is not None  # mid is one of the movers: a dancer or a festoon span
            dim, (lo, hi), what = "length", sp.festoon.stroke, "stroke"
        assert dim is not None  # a mover kind's coordinate has a unit
        try:
            q = parse_quantity(value, dim)
        except QuantityError as exc:
            raise InputError(str(exc), file=file, path=path) from None
        if not lo < q < hi:
            raise InputError(
                f"{q:g} is not strictly inside the end stops [{lo:g}, {hi:g}] "
                f"({what}, SI units); a start on a stop would not latch there",
                file=file,
                path=path,
            )
        scenario.initial.position[mid] = q


def _sines_top(d, v_max: float) -> float:
    """Highest frequency [Hz] of a sum-of-sinusoids disturbance
    (:data:`r2rsim.compile.disturbances.CUTOFF` corner frequencies)."""
    from ..compile.disturbances import CUTOFF

    if d.type == "bearing_drag":
        return CUTOFF * d.bandwidth
    return CUTOFF * v_max / (2.0 * math.pi * d.correlation_length)


def check_disturbances(scenario, line, file: str) -> None:
    """Targets and values of the scenario's process disturbances."""
    eccentric_faults = {f.target for f in scenario.faults if f.type == "process.eccentricity"}
    v_max = max(
        (abs(s.line_speed) for s in scenario.programme if s.line_speed is not None), default=0.0
    )
    ids = [e.id for e in line.elements]
    for i, d in enumerate(scenario.disturbances):
        where = f"disturbances[{i}]"
        if d.element not in ids:
            raise InputError(
                f"no element '{d.element}' in the line (known: {', '.join(ids)})",
                file=file,
                path=f"{where}.element",
            )
        e = line.element(d.element)
        drive = getattr(e, "drive", None)
        problem = None
        if d.type == "out_of_round":  # the same rules as an eccentricity fault
            problem = target_problem("process.eccentricity", d.element, line)
            if problem is None and d.element in eccentric_faults:
                problem = (
                    f"'{d.element}' is out of round and also has a "
                    "process.eccentricity fault; give it one or the other"
                )
        elif d.type == "wound_in_strain" and not kind_of(e).pays_out:
            problem = f"wound_in_strain applies to an unwind; '{d.element}' is a {e.type}"
        elif (
            d.type == "wound_in_strain"
            and d.shape == "table"
            and limits.wound_in_strain_points(v_max, scenario.duration, d.correlation_length)
            > limits.MAX_SAMPLES
        ):
            raise InputError(
                f"a correlation length of {d.correlation_length:g} m needs a table "
                f"of more than {limits.MAX_SAMPLES:.0e} points (ten per "
                f"correlation length over the {v_max:g} m/s x "
                f"{scenario.duration:g} s of web of this run; docs/security.md)",
                file=file,
                path=f"{where}.correlation_length",
            )
        elif (
            d.type != "out_of_round"
            and d.shape != "table"
            and _sines_top(d, v_max) > 0.5 * scenario.record_rate
        ):
            what = "bandwidth" if d.type == "bearing_drag" else "correlation_length"
            raise InputError(
                f"its highest frequency, {_sines_top(d, v_max):.3g} Hz (ten times "
                "the corner of its spectrum"
                + ("" if d.type == "bearing_drag" else f" at {v_max:g} m/s")
                + "), is above half the record rate "
                f"({0.5 * scenario.record_rate:g} Hz): the solver would have to "
                "follow a disturbance the samples cannot show; give a "
                + ("lower bandwidth" if d.type == "bearing_drag" else "longer correlation length")
                + " or a higher record rate",
                file=file,
                path=f"{where}.{what}",
            )
        elif d.type == "bearing_drag" and drive is not None and drive.type == "ideal_speed":
            problem = (
                f"'{d.element}' turns at an imposed speed (ideal_speed drive): a drag "
                "torque would have no effect"
            )
        if problem:
            raise InputError(
                problem.replace("process.eccentricity", "out_of_round"),
                file=file,
                path=f"{where}.element",
            )
        if d.type == "out_of_round":
            if d.eccentricity >= e.radius:
                raise InputError(
                    f"an eccentricity of {d.eccentricity:g} m is not less than "
                    f"the roller radius {e.radius:g} m",
                    file=file,
                    path=f"{where}.eccentricity",
                )
            continue
        try:
            std = d.std_si()
        except QuantityError as exc:
            raise InputError(str(exc), file=file, path=f"{where}.std") from None
        if not std >= 0:
            raise InputError("std must be >= 0", file=file, path=f"{where}.std")


def check_variability(scenario, line, file: str) -> None:
    """Targets and spreads of the scenario's ``variability``: each drawn value stays in its
    physical range even at the cut of a normal draw (four standard deviations)."""
    var = scenario.variability
    if var is None:
        return

    def width(spread, nominal, dim, where):
        try:
            w = spread.reach(nominal, dim)
        except QuantityError as exc:
            raise InputError(str(exc), file=file, path=where) from None
        if not (math.isfinite(w) and w >= 0):
            raise InputError("the spread must be a finite number >= 0", file=file, path=where)
        return w

    unwinds = [e.id for e in line.elements if kind_of(e).pays_out]
    material = [uid for uid, r in var.rolls.items() if r.modulus or r.thickness or r.relaxed_pitch]
    for uid, r in var.rolls.items():
        where = f"variability.rolls.{uid}"
        if uid not in unwinds:
            raise InputError(
                f"no unwind '{uid}' in the line (unwinds: {', '.join(unwinds) or 'none'})",
                file=file,
                path=where,
            )
        if len(material) > 1 and uid == material[1]:
            raise InputError(
                "the web's modulus, thickness and relaxed pitch vary with the "
                f"rolls of one unwind only (already '{material[0]}')",
                file=file,
                path=where,
            )
        e = line.element(uid)
        rolls = [e.roll] + ([e.spare_roll] if e.spare_roll is not None else [])
        checks = [
            ("modulus", line.web.modulus, "pressure", 0.0, "0"),
            ("thickness", line.web.thickness, "length", 0.0, "0"),
        ]
        checks += [
            (
                "outer_radius",
                roll.outer_radius,
                "length",
                roll.core_radius,
                f"the core radius {roll.core_radius:g} m",
            )
            for roll in rolls
        ]
        for name, nominal, dim, low, what in checks:
            spread = getattr(r, name)
            if spread is None:
                continue
            path = f"{where}.{name}.{spread.key}"
            if nominal - width(spread, nominal, dim, path) <= low:
                raise InputError(
                    f"{name} {nominal:g} could be drawn down to {what} or "
                    "below (a normal draw reaches 4 standard deviations)",
                    file=file,
                    path=path,
                )
        if r.wound_in_strain is not None:
            path = f"{where}.wound_in_strain.{r.wound_in_strain.key}"
            e0 = max(abs(roll.wound_in_coefficients()[0]) for roll in rolls)
            if (
                e0 + width(r.wound_in_strain, 0.0, "dimensionless", path)
                >= plausibility.WOUND_IN_STRAIN_MAX
            ):
                raise InputError(
                    f"the wound-in strain could be drawn to "
                    f"{plausibility.WOUND_IN_STRAIN_MAX:g} or beyond, where "
                    "Hooke's law no longer describes the web (a normal draw "
                    "reaches 4 standard deviations)",
                    file=file,
                    path=path,
                )
        if r.relaxed_pitch is not None:
            _check_pitch_offset(
                line,
                uid,
                r.relaxed_pitch,
                width,
                file,
                f"{where}.relaxed_pitch.{r.relaxed_pitch.key}",
            )
    sensors = {s.id: s for s in line.sensors}
    for sid, cal in var.sensors.items():
        where = f"variability.sensors.{sid}"
        if sid not in sensors:
            raise InputError(
                f"no sensor '{sid}' in the line (known: {', '.join(sensors) or 'none'})",
                file=file,
                path=where,
            )
        s = sensors[sid]
        if cal.gain is not None:
            path = f"{where}.gain.{cal.gain.key}"
            if s.gain - width(cal.gain, s.gain, "dimensionless", path) <= 0:
                raise InputError(
                    f"gain {s.gain:g} could be drawn down to 0 or below", file=file, path=path
                )
        if cal.offset is not None:
            path = f"{where}.offset.{cal.offset.key}"
            w = width(cal.offset, s.offset, sensor_dimension(line, s)[0], path)
            if abs(s.offset) + w > plausibility.READING_MAX:
                raise InputError(
                    f"the offset could be drawn beyond any sensor's reading "
                    f"({plausibility.READING_MAX:g} in its SI unit)",
                    file=file,
                    path=path,
                )


def _check_pitch_offset(line, uid, spread, width, file, path) -> None:
    """A roll's relaxed-pitch offset needs a pitch_length sensor on the unwind's web, and
    keeps every such sensor's L0 positive at the cut of a draw."""
    readers = [s for s in line.sensors if s.type == "pitch_length" and pitch_unwind(line, s) == uid]
    if not readers:
        raise InputError(
            f"no pitch_length sensor reads the web of '{uid}' (a sensor reads "
            "the unwind of its relaxed_pitch_law, default the line's first "
            "element)",
            file=file,
            path=path,
        )
    w = width(spread, 0.0, "length", path)
    for s in readers:
        L0 = s.relaxed_pitch if s.relaxed_pitch is not None else s.relaxed_pitch_law.q0
        if w >= 0.1 * L0:
            raise InputError(
                f"the offset could reach {w:g} m, a tenth or more of the "
                f"relaxed pitch {L0:g} m of sensor '{s.id}'",
                file=file,
                path=path,
            )


def json_schema(kind: str) -> str:
    """JSON Schema of a ``line``, ``scenario`` or ``sweep`` file, for editors."""
    from .sweep import Sweep

    models: dict[str, type[BaseModel]] = {"line": Line, "scenario": Scenario, "sweep": Sweep}
    return json.dumps(models[kind].model_json_schema(), indent=2)
