"""Discovery of diagnostic plug-ins through the ``r2rsim.diagnostics`` entry-point group, so
a separate package can add a method without touching r2rsim.

One broken plug-in (it fails to import, or its entry point is not a
:class:`~r2rsim.diagnostics.Diagnostic` class) never stops the others: :func:`discover` reports
it with its error, :func:`plugins` leaves it out, and :func:`get` raises
:class:`~r2rsim.errors.PluginError` only when that plug-in is asked for.
"""

from __future__ import annotations

import ast
import importlib.util
import inspect
import types
import typing
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path

from ..errors import InputError, PluginError

GROUP = "r2rsim.diagnostics"


def one_line(exc: BaseException) -> str:
    """``Type: first line of the message`` of an exception."""
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__


@dataclass
class Entry:
    """A registered plug-in: its class, or why it cannot be loaded."""

    name: str
    value: str  # "module:attribute" of the entry point
    cls: type | None
    error: str | None


def _load(ep) -> type:
    """The class behind an entry point; PluginError naming it and the problem."""
    from .base import Diagnostic

    where = f"plug-in '{ep.name}' ({ep.value})"
    try:
        obj = ep.load()
    except Exception as exc:  # noqa: BLE001 - any import failure of third-party code
        raise PluginError(f"{where} cannot be loaded: {one_line(exc)}") from exc
    if not isinstance(obj, type):
        raise PluginError(
            f"{where} is not a class (it is a {type(obj).__name__}); an entry "
            f"point must name a subclass of r2rsim.diagnostics.Diagnostic"
        )
    if not issubclass(obj, Diagnostic):
        raise PluginError(f"{where} is not a subclass of r2rsim.diagnostics.Diagnostic")
    return obj


def discover() -> dict[str, Entry]:
    """Every registered plug-in by name, loaded, with the error of those that cannot be."""
    out = {}
    for ep in sorted(entry_points(group=GROUP), key=lambda e: e.name):
        try:
            out[ep.name] = Entry(ep.name, ep.value, _load(ep), None)
        except PluginError as exc:
            out[ep.name] = Entry(ep.name, ep.value, None, str(exc))
    return out


@dataclass
class Listing:
    """A registered plug-in as its installed metadata and source describe it, without
    importing it: ``summary`` is the first line of the class's docstring, ``problem`` why it
    certainly cannot load (None: it may; only loading it, :func:`discover`, tells)."""

    name: str
    value: str
    summary: str
    problem: str | None


def listing() -> dict[str, Listing]:
    """Every registered plug-in by name, read from the entry points and the source of the
    module each names (parsed, not imported): quick, and no plug-in code runs. A plug-in whose
    module is not installed, or whose name is not a class in it, is listed with that
    problem; whether the class is a :class:`~r2rsim.diagnostics.Diagnostic` that loads is
    known only once it is loaded (:func:`discover`)."""
    out = {}
    for ep in sorted(entry_points(group=GROUP), key=lambda e: e.name):
        module, _, attr = ep.value.partition(":")
        summary, problem = _class_doc(module.strip(), attr.strip())
        out[ep.name] = Listing(ep.name, ep.value, summary, problem)
    return out


def _find_spec_without_importing(module: str):
    """The spec of a dotted module, found part by part in its parents' search paths, so that
    no package's ``__init__`` runs (``importlib.util.find_spec`` imports the parents)."""
    import importlib.machinery

    parts = module.split(".")
    spec = importlib.util.find_spec(parts[0])  # a top-level name: nothing is imported
    for part in parts[1:]:
        if spec is None or spec.submodule_search_locations is None:
            return None
        spec = importlib.machinery.PathFinder.find_spec(
            f"{spec.name}.{part}", list(spec.submodule_search_locations)
        )
    return spec


def _class_doc(module: str, attr: str, depth: int = 0) -> tuple[str, str | None]:
    """(first docstring line, problem) of class ``attr`` of ``module``, from its source; it
    follows ``from .x import attr`` re-exports a few levels deep."""
    try:
        spec = _find_spec_without_importing(module)
    except (ImportError, ValueError) as exc:
        return "", f"cannot be loaded: {one_line(exc)}"
    if spec is None:
        return "", f"cannot be loaded: ModuleNotFoundError: No module named '{module}'"
    origin = spec.origin
    if not origin or not origin.endswith(".py") or not attr or depth > 3:
        return "", None  # a compiled module, a namespace package: only loading tells
    try:
        tree = ast.parse(Path(origin).read_text(encoding="utf-8"))
    except (OSError, SyntaxError, UnicodeDecodeError, ValueError) as exc:
        return "", f"cannot be loaded: {one_line(exc)}"
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name == attr:
            doc = (ast.get_docstring(node) or "").strip().splitlines()
            return (doc[0] if doc else ""), None
        if isinstance(node, ast.ImportFrom):
            for alias in node.names:
                if (alias.asname or alias.name) == attr:
                    base = (
                        importlib.util.resolve_name(
                            "." * node.level + (node.module or ""),
                            spec.parent if spec.parent is not None else module,
                        )
                        if node.level
                        else node.module
                    )
                    return _class_doc(base or "", alias.name, depth + 1)
        targets = (
            node.targets
            if isinstance(node, ast.Assign)
            else [node.target]
            if isinstance(node, ast.AnnAssign)
            else [ast.Name(node.name)]
            if isinstance(node, ast.FunctionDef)
            else []
        )
        if any(isinstance(t, ast.Name) and t.id == attr for t in targets):
            return "", None  # assigned or a function: only loading tells what it is
    return "", f"is not defined in module '{module}'"


def plugins() -> dict[str, type]:
    """Every registered plug-in class that loads, by name (see :func:`discover` for the
    broken ones)."""
    return {name: e.cls for name, e in discover().items() if e.cls is not None}


def get(name: str) -> type:
    """The plug-in class registered as ``name`` (only that entry point is loaded).

    Raises
    ------
    InputError
        No plug-in of that name.
    PluginError
        It is registered but cannot be loaded.
    """
    return _load(require_registered(name))


def require_registered(name: str):
    """The entry point of the plug-in registered as ``name``, not loaded (so an unknown name
    is refused at once).

    Raises
    ------
    InputError
        No plug-in of that name (the message lists the registered ones).
    """
    found = {ep.name: ep for ep in entry_points(group=GROUP)}
    if name not in found:
        raise InputError(
            f"no diagnostic plug-in '{name}' (registered: "
            f"{', '.join(sorted(found)) or 'none'}; `r2rsim list plugins`)"
        )
    return found[name]


def call(cls_or_est, method: str, fn, *args, **kwargs):
    """``fn(*args, **kwargs)``, a method of a plug-in: any exception it raises (except an
    :class:`InputError` and a ``MemoryError``) becomes a one-line :class:`PluginError` naming
    the plug-in, the method and the exception, chained to the original."""
    try:
        return fn(*args, **kwargs)
    except (InputError, MemoryError):
        raise
    except Exception as exc:  # noqa: BLE001 - third-party code may raise anything
        name = (
            getattr(cls_or_est, "name", None)
            or getattr(cls_or_est, "__name__", None)
            or type(cls_or_est).__name__
        )
        raise PluginError(f"plug-in '{name}': {method} raised {one_line(exc)}") from exc


def default_params(cls: type) -> dict:
    """The parameters of plug-in ``cls`` with their defaults (``cls().get_params()``)."""
    est = call(cls, "__init__ (with its default parameters)", cls)
    return call(cls, "get_params", est.get_params)


def unknown_parameter(cls: type, key: str) -> str | None:
    """The problem with giving plug-in ``cls`` the parameter ``key`` (None if it has it)."""
    known = default_params(cls)
    if key in known:
        return None
    return f"{cls.name} has no parameter '{key}' (its parameters: {', '.join(known) or 'none'})"


# --------------------------------------------------------------------------- parameter types

_NAMES = {
    int: "an integer",
    float: "a number",
    str: "a string",
    bool: "true or false",
    type(None): "null",
    list: "a list",
    dict: "a mapping",
    tuple: "a list",
}


def _expected(cls: type, key: str) -> tuple[tuple[type, ...], str] | None:
    """The types a parameter accepts and how to say so: from the annotation of ``__init__``
    when it is made of plain types, else from the type of a non-None default; None when
    nothing is known (any value is passed on)."""
    try:
        sig = inspect.signature(cls.__init__, eval_str=True)
    except Exception:  # noqa: BLE001 - an annotation that does not evaluate: no check
        try:
            sig = inspect.signature(cls.__init__)
        except (TypeError, ValueError):
            return None
    p = sig.parameters.get(key)
    if p is None:
        return None
    ann = p.annotation
    types_: tuple[type, ...] | None = None
    if ann is not inspect.Parameter.empty and not isinstance(ann, str):
        args = (
            typing.get_args(ann)
            if typing.get_origin(ann) in (typing.Union, types.UnionType)
            else (ann,)
        )
        args = tuple(typing.get_origin(a) or a for a in args)
        if all(a in _NAMES for a in args):
            types_ = args
    if types_ is None and p.default is not inspect.Parameter.empty and p.default is not None:
        if type(p.default) in _NAMES:
            types_ = (type(p.default),)
            if types_ == (float,):
                types_ = (float, int)
    if types_ is None:
        return None
    if float in types_ and int not in types_:
        types_ = (*types_, int)  # an integer is a number
    words = []
    for t in types_:
        w = _NAMES[t]
        if w not in words and not (t is int and float in types_):
            words.append(w)
    return types_, " or ".join(words)


def check_param(cls: type, key: str, value):
    """``value`` for parameter ``key`` of plug-in ``cls``, converted where a number was
    given as text (``1e-3`` is a string to YAML); raises InputError naming the parameter and
    the type it expects when the value has another type."""
    exp = _expected(cls, key)
    if exp is None:
        return value
    types_, words = exp
    if isinstance(value, str) and str not in types_:
        for t in (int, float):
            if t in types_:
                try:
                    return t(value)
                except ValueError:
                    pass
    ok = isinstance(value, types_) and not (isinstance(value, bool) and bool not in types_)
    if isinstance(value, int) and not isinstance(value, bool) and float in types_:
        ok = True
    if not ok:
        raise InputError(
            f"{cls.name} expects {words} for {key}, got {value!r} "
            f"({_NAMES.get(type(value), type(value).__name__)})"
        )
    return value
