"""Every key of the line, scenario and sweep files as Markdown tables, generated from the
schema models (their JSON Schema), so the reference cannot fall behind what is accepted.

``docs/keys.md`` is this text (``r2rsim schema --markdown``); ``tests/test_keys_doc.py``
checks that the page is current and that every key has a description.
"""

from __future__ import annotations

import json
import typing

from pydantic import BaseModel

from .line import ID_PATTERN

KINDS = ("line", "scenario", "sweep")
_TITLES = {"line": "Line file", "scenario": "Scenario file", "sweep": "Sweep file"}
_BOUNDS = (("minimum", "≥"), ("exclusiveMinimum", ">"), ("maximum", "≤"), ("exclusiveMaximum", "<"))


def _root(kind: str) -> type[BaseModel]:
    from .line import Line
    from .scenario import Scenario
    from .sweep import Sweep

    roots: dict[str, type[BaseModel]] = {"line": Line, "scenario": Scenario, "sweep": Sweep}
    return roots[kind]


def _models(model: type[BaseModel], found: dict | None = None) -> dict[str, type[BaseModel]]:
    """Every model reachable from ``model``'s fields, by name (the JSON Schema's titles)."""
    found = {} if found is None else found
    found[model.__name__] = model
    for field in model.model_fields.values():
        stack = [field.annotation]
        while stack:
            t = stack.pop()
            if isinstance(t, type) and issubclass(t, BaseModel):
                if t.__name__ not in found:
                    _models(t, found)
            else:
                stack += typing.get_args(t)
    return found


def _anchor(kind: str, name: str) -> str:
    return f"{kind}-{name.lower()}"


def _ref_name(node: dict) -> str | None:
    ref = node.get("$ref")
    if ref is None and len(node.get("allOf", ())) == 1:  # older pydantic wraps a $ref
        ref = node["allOf"][0].get("$ref")
    return ref.rsplit("/", 1)[-1] if ref else None


def _bounds(node: dict) -> str:
    parts = [
        f"{sign} {node[key] if isinstance(node[key], int) else format(node[key], 'g')}"
        for key, sign in _BOUNDS
        if key in node
    ]
    return f" ({', '.join(parts)})" if parts else ""


def _type(node: dict, kind: str) -> str:
    """The type of a property, as a reader needs it: a quantity's dimension and SI unit,
    the allowed words, a link to a nested table."""
    name = _ref_name(node)
    if name is not None:
        return f"[{name}](#{_anchor(kind, name)})"
    if "x-unit" in node:
        unit = node["x-unit"]
        return node["x-dimension"] + ("" if unit == "1" else f" [{unit}]")
    if "const" in node:
        return f"`{node['const']}`"
    if "enum" in node:
        return " \\| ".join(f"`{v}`" for v in node["enum"])
    for key in ("anyOf", "oneOf"):
        if key in node:
            members = [m for m in node[key] if m.get("type") != "null"]
            return " or ".join(dict.fromkeys(_type(m, kind) for m in members))
    t = node.get("type")
    if t == "array":
        if "prefixItems" in node:
            return "[" + ", ".join(_type(m, kind) for m in node["prefixItems"]) + "]"
        items = node.get("items", {})
        return f"list of {_type(items, kind)}" if items else "list"
    if t == "object":
        patterns = node.get("patternProperties", {})
        if len(patterns) == 1:
            ((pattern, values),) = patterns.items()
            keys = "ids" if pattern == ID_PATTERN else "paths" if kind == "sweep" else "keys"
            return f"mapping of {keys} to {_type(values, kind)}"
        values = node.get("additionalProperties")
        return (
            f"mapping of names to {_type(values, kind)}" if isinstance(values, dict) else "mapping"
        )
    if t in ("number", "integer"):
        return f"{t}{_bounds(node)}"
    return t or "any"


def _default(field) -> str:
    """A field's default as YAML would write it (defaults made by a factory included, which
    the JSON Schema leaves out)."""
    if field.is_required():
        return "required"
    value = field.get_default(call_default_factory=True)
    if value is None:
        return "none"
    if isinstance(value, BaseModel):
        return "its defaults"
    if isinstance(value, tuple):
        value = list(value)
    return f"`{json.dumps(value, ensure_ascii=False)}`"


def _meaning(prop: dict) -> str:
    """The property's own description (not its quantity type's)."""
    text = prop.get("description", "")
    if "x-unit" in prop and text.startswith(f"{prop['x-dimension']}: a number in"):
        return ""
    return " ".join(text.split()).replace("|", "\\|")


def _order(schema: dict) -> list[str]:
    """Definitions in the order a reader meets them: breadth first from the file's root."""
    defs = schema.get("$defs", {})
    seen: list[str] = []
    queue = [schema]
    while queue:
        node = queue.pop(0)
        for name in _refs(node):
            if name not in seen:
                seen.append(name)
                queue.append(defs[name])
    return seen


def _refs(node) -> list[str]:
    out: list[str] = []
    if isinstance(node, dict):
        if isinstance(node.get("$ref"), str):
            out.append(node["$ref"].rsplit("/", 1)[-1])
        for key, value in node.items():
            if key not in ("$defs", "discriminator"):
                out += _refs(value)
    elif isinstance(node, list):
        for value in node:
            out += _refs(value)
    return out


def _table(kind: str, name: str, node: dict, model: type[BaseModel]) -> list[str]:
    doc = " ".join(node.get("description", "").split())
    lines = [f"### {kind}: {name}", ""] + ([doc, ""] if doc else [])
    lines += ["| key | type | default | meaning |", "| --- | --- | --- | --- |"]
    for key, prop in node.get("properties", {}).items():
        lines.append(
            f"| `{key}` | {_type(prop, kind)} | {_default(model.model_fields[key])} "
            f"| {_meaning(prop)} |"
        )
    return lines + [""]


def reference_markdown(kinds=KINDS) -> str:
    """Markdown tables of every key of the given file kinds: one table per mapping, from
    the file's top level down, with each key's type (a quantity's dimension and SI unit),
    default and description."""
    out = [
        "# Every key of the input files",
        "",
        "Generated from r2rsim's schema models by `r2rsim schema --markdown`; do not edit. "
        'A quantity takes an SI number or a string with units (`"50 um"`, README § A '
        "line file). `r2rsim schema line|scenario|sweep` prints the same models as JSON "
        "Schema for editors.",
        "",
    ]
    for kind in kinds:
        root = _root(kind)
        schema, models = root.model_json_schema(), _models(root)
        out += [f"## {_TITLES[kind]}", ""]
        out += _table(kind, root.__name__, schema, root)
        for name in _order(schema):
            out += _table(kind, name, schema["$defs"][name], models[name])
    return "\n".join(out).rstrip() + "\n"


def undocumented(kinds=KINDS) -> list[str]:
    """``kind: Model.key`` of every key without a description of its own."""
    missing = []
    for kind in kinds:
        root = _root(kind)
        schema = root.model_json_schema()
        nodes = {root.__name__: schema, **schema.get("$defs", {})}
        for name, node in nodes.items():
            missing += [
                f"{kind}: {name}.{key}"
                for key, prop in node.get("properties", {}).items()
                if not _meaning(prop)
            ]
    return missing
