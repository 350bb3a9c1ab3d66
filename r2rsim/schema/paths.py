"""YAML paths (the axes of a sweep): find, set and remove a value of a scenario (or, under
``line.``, of its line) by its YAML path.

``programme[1].line_speed`` and ``programme.1.line_speed`` index a list;
``faults.my_fault.magnitude`` picks the list element whose ``id`` is ``my_fault``. Mappings
that are missing on the way are created (``solver.rtol`` in a scenario without ``solver:``).
"""

from __future__ import annotations

import re
from typing import Any

_PART = re.compile(r"([A-Za-z_][A-Za-z0-9_-]*|[0-9]+)|\[([0-9]+)\]")


class PathError(ValueError):
    """A path that does not lead to a value of the data."""


def parse(path: str) -> list[str | int]:
    """``"programme[1].line_speed"`` -> ``["programme", 1, "line_speed"]``."""
    parts: list[str | int] = []
    for m in _PART.finditer(path):
        key, index = m.groups()
        text = index if index is not None else key
        parts.append(int(text) if text.isdigit() else text)
    return parts


def split_root(path: str) -> tuple[str, list[str | int]]:
    """``("line", [...])`` for a path under ``line.``, else ``("scenario", [...])``."""
    parts = parse(path)
    if parts[0] == "line":
        if len(parts) == 1:
            raise PathError(
                "the line file itself cannot be swept (one sweep runs one line "
                "file; its values can: line.web.thickness, ...)"
            )
        return "line", parts[1:]
    return "scenario", parts


def _ids(items: list) -> list[str]:
    return [str(x["id"]) for x in items if isinstance(x, dict) and "id" in x]


def _step(node, part, shown: str, create: bool):
    """The child ``part`` of ``node`` and its key there (``(child, key)``)."""
    if isinstance(node, dict):
        if isinstance(part, int):
            raise PathError(f"{shown} is a mapping, not a list: [{part}] does not apply")
        if part not in node:
            if not create:
                raise PathError(f"{shown} has no key '{part}'")
            return None, part
        return node[part], part
    if isinstance(node, list):
        if isinstance(part, int):
            if part >= len(node):
                raise PathError(f"{shown} has {len(node)} entries; [{part}] is past the end")
            return node[part], part
        for i, item in enumerate(node):
            if isinstance(item, dict) and str(item.get("id")) == part:
                return item, i
        known = ", ".join(_ids(node)) or "none has an id"
        raise PathError(f"{shown} has no entry with id '{part}' (ids: {known})")
    raise PathError(f"{shown} is a single value, not a mapping or list")


def _shown(parts: list) -> str:
    out = ""
    for p in parts:
        out += f"[{p}]" if isinstance(p, int) else ("." if out else "") + str(p)
    return out or "the file"


def resolve(data, parts: list, create: bool = False) -> tuple[dict[str, Any] | list[Any], Any, str]:
    """``(parent, key, index_path)`` of the value at ``parts``: the container holding it, its
    key (a str) or index (an int) there, and the path with list elements by index (as
    validation errors name them). With ``create``, missing mappings on the way are made."""
    node = data
    done: list = []
    for i, part in enumerate(parts):
        last = i == len(parts) - 1
        child, key = _step(node, part, _shown(done), create)
        if last:
            return node, key, _shown([*done, key])
        if child is None:  # a missing mapping on the way
            if isinstance(parts[i + 1], int):
                raise PathError(f"{_shown(done)} has no key '{part}'")
            child = node[key] = {}
        done.append(key)
        node = child
    raise PathError("an empty path")


def set_value(data, parts: list, value) -> str:
    """Set the value at ``parts`` (creating missing mappings); returns the index path."""
    parent, key, where = resolve(data, parts, create=True)
    parent[key] = value
    return where


def remove(data, parts: list) -> str:
    """Remove the list element chosen by its id at ``parts``; returns the index path."""
    if isinstance(parts[-1], int):
        raise PathError(
            "null removes a list element chosen by its id (faults.my_fault); "
            f"an index ([{parts[-1]}]) would shift the others"
        )
    parent, key, where = resolve(data, parts)
    if not isinstance(parent, list):
        raise PathError(
            f"null removes a list element chosen by its id; {_shown(parts)} is a key of a mapping"
        )
    del parent[key]
    return where


def get_value(data, parts: list):
    """The value at ``parts``; :class:`PathError` if there is none."""
    parent, key, _ = resolve(data, parts)
    return parent[key]
