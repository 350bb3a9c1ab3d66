"""The element kinds of ``Line.elements``, one module each, and their registry.

Each module of this package (a name without a leading underscore) defines one kind: its
pydantic model and a module-level ``KIND``, an instance of an
:class:`~r2rsim.schema.kinds.ElementKind` subclass that says what the kind means to every
stage: its ``r2rsim list`` text, its family (how the kernel sees it: a roll with radius
states, a roller, or a roller on a mover, and the mover's kind), the unit of a mover's
coordinate, the fault target families it may carry, whether it has a drive, its own checks,
what the compiler packs into its node and mover records, and its rest-tension guess for the
initial state. The stages ask the registry (``kind_of(element)``) rather than compare
``element.type`` to a name.

The registry finds the modules of this package itself (``pkgutil``): a new kind is a new
module, no list to edit. A kind defined elsewhere (a plug-in, a test) is added with
:func:`register` and removed with :func:`unregister`; either rebuilds the element union of
:class:`~r2rsim.schema.line.Line`, so the next line validated accepts (or refuses) it.

Festoons are not element kinds: a festoon is a carriage lumped into a span
(``spans[i].festoon``, schema/line.py) and is out of this package's scope.

What a new kind touches
-----------------------
* **A roller kind without new state** (it spins like an idler; its keys differ): its module
  here, nothing else (the node record's fields ``R``, ``J``, ``B``, ``TC`` ... exist;
  ``pack_node`` writes them by name). A kind defined outside the package: its module and a
  :func:`register` call.
* **A new mover kind** (a roller on a carriage or arm of a new geometry): its module here
  (``family = "mover"``, ``mover_kind``, ``coordinate_unit``, ``range_key``,
  ``start_key``, ``centre``, ``pack_mover``, ``rest_tension``), a member of ``MoverKind``
  in r2rsim/compile/layout.py (with any new ``MoverP`` fields), and the kernel's mover
  geometry and load for it (``mover_lengths`` and ``mover_load``, the mover phase of the
  kernel: r2rsim/compile/model/movers.py).
* **A kind with a new state equation** (neither a roller, a roll nor a mover): its module
  here (its ``states`` hook declares the states, which the compiler lays out; ``pack_node``
  its parameters), the node record's new fields in r2rsim/compile/layout.py (``NodeI`` for
  the state's index, ``NodeP`` for its parameters), and its equation in the kernel: a phase
  of r2rsim/compile/model/ (an existing one, or a new function there plus its call in
  r2rsim/compile/kernels.py). r2rsim/solve/initial.py only when Newton needs a guess for
  it. Three package files, four with a new phase function.
"""

from __future__ import annotations

import importlib
import pkgutil
from typing import Annotated, Any, Union, get_args

from pydantic import Field

from ._base import ElementKind, Family, RecordWriter

__all__ = [
    "ElementKind",
    "Family",
    "RecordWriter",
    "added_kinds",
    "all_kinds",
    "element_union",
    "kind_named",
    "kind_names",
    "kind_of",
    "kinds_in_family",
    "register",
    "unregister",
]

_KINDS: dict[str, ElementKind] = {}
#: the kinds this package's modules define, as found (:func:`_discover`)
_FOUND: dict[str, ElementKind] = {}


def all_kinds() -> tuple[ElementKind, ...]:
    """Every registered kind, in their ``order`` (then by name)."""
    return tuple(sorted(_KINDS.values(), key=lambda k: (k.order, k.name)))


def kind_names() -> tuple[str, ...]:
    """The ``type`` values of every registered kind, in order."""
    return tuple(k.name for k in all_kinds())


def kind_named(name: str) -> ElementKind:
    """The kind whose ``type`` is ``name``.

    Raises
    ------
    KeyError
        If no kind of that name is registered (the message lists the known ones).
    """
    try:
        return _KINDS[name]
    except KeyError:
        raise KeyError(f"no element kind {name!r}; known: {', '.join(kind_names())}") from None


def kind_of(element: Any) -> ElementKind:
    """The kind of a validated element (by its ``type``)."""
    return kind_named(element.type)


def kinds_in_family(family: Family) -> tuple[ElementKind, ...]:
    """The kinds of one family (``"roll"``, ``"roller"`` or ``"mover"``), in order."""
    return tuple(k for k in all_kinds() if k.family == family)


def added_kinds() -> tuple[ElementKind, ...]:
    """The kinds :func:`register` added or replaced (the registry holds them, not the
    package's modules), in order: what a process that imports r2rsim afresh (a sweep's
    worker) must be given to read the same lines."""
    return tuple(k for k in all_kinds() if _FOUND.get(k.name) is not k)


def element_union() -> Any:
    """The pydantic type of one entry of ``Line.elements``: the union of every registered
    kind's model, discriminated by ``type``."""
    models = tuple(k.model for k in all_kinds())
    return Annotated[Union[models], Field(discriminator="type")]  # noqa: UP007 - a runtime tuple


def register(kind: ElementKind, *, replace: bool = False) -> ElementKind:
    """Add a kind to the registry and rebuild ``Line``'s element union.

    Parameters
    ----------
    kind : ElementKind
        The kind (an instance); its ``model.type`` must be ``Literal[kind.name]``.
    replace : bool
        Replace a registered kind of the same name instead of refusing it.

    Returns
    -------
    ElementKind
        ``kind``, so that a module can write ``KIND = register(MyKind())``.

    Raises
    ------
    ValueError
        If a kind of that name is registered and ``replace`` is false.
    """
    _add(kind, replace)
    _rebuild_line()
    return kind


def unregister(name: str) -> ElementKind:
    """Remove the kind called ``name`` and rebuild ``Line``'s element union; returns it."""
    kind = kind_named(name)
    del _KINDS[name]
    _rebuild_line()
    return kind


def _add(kind: ElementKind, replace: bool) -> None:
    # the union is discriminated by ``type``: a model without Literal[name] there would be
    # refused by pydantic with a message that names neither the kind nor the fix
    field = kind.model.model_fields.get("type")
    if field is None or get_args(field.annotation) != (kind.name,):
        raise ValueError(
            f"element kind {kind.name!r}: its model {kind.model.__name__} needs "
            f'type: Literal["{kind.name}"]'
        )
    if kind.is_mover:
        missing = [
            a
            for a in ("mover_kind", "coordinate_unit", "range_key", "start_key")
            if getattr(kind, a) is None
        ]
        if missing:
            raise ValueError(
                f"element kind {kind.name!r} is a mover kind and needs {', '.join(missing)}"
            )
    if kind.name in _KINDS and not replace:
        raise ValueError(f"element kind {kind.name!r} is already registered")
    _KINDS[kind.name] = kind


def _rebuild_line() -> None:
    # imported here: line.py builds its union from this registry when it is imported
    from ..line import rebuild_element_union

    rebuild_element_union()


def _discover() -> None:
    """Register the ``KIND`` of every public module of this package (no rebuild: ``Line``
    is built from the registry after this)."""
    for info in pkgutil.iter_modules(__path__):
        if info.name.startswith("_"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        _add(module.KIND, replace=False)
        _FOUND[module.KIND.name] = module.KIND


_discover()
