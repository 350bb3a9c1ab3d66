"""The interface of an element kind (:class:`ElementKind`) and the two writers its hooks get.

A kind is one value of an element's ``type`` key. Its module declares, in one place, what
every stage needs to know about it; the stages ask the registry (``kind_of(element)``)
instead of comparing ``element.type`` to a name. The schema stage may not import the
compiler or the solver, so the hooks that write compiled records or read a compiled line
get duck-typed objects (:class:`RecordWriter`, a ``CompiledLine``).
"""

from __future__ import annotations

from typing import Any, ClassVar, Literal, Protocol

from pydantic import BaseModel

#: how the kernel sees a kind: a roll (its radius follows the wound length: extra states),
#: a roller (one angular speed), or a roller on a mover (a dancer: speed plus a position)
Family = Literal["roll", "roller", "mover"]

#: the dimension of a mover coordinate by its unit
_DIMENSION = {"m": "length", "rad": "angle"}


class RecordWriter(Protocol):
    """A compiled record addressed by field name: ``node["R"] = 0.1`` writes the field the
    compiler's layout calls ``R`` (``NodeP.R``, ``MoverP.MASS``, ...). A name the record
    does not have raises KeyError naming the record's fields."""

    def __setitem__(self, name: str, value: float) -> None: ...


class ElementKind:
    """What one element kind means to every stage of the pipeline.

    Subclass it in a module of ``r2rsim/schema/kinds/`` (found there by itself) or anywhere
    else and pass an instance to :func:`r2rsim.schema.kinds.register`. The class attributes
    are data; the methods are hooks with defaults for a plain roller (``radius`` and
    ``inertia`` keys).

    Attributes
    ----------
    name : str
        The ``type`` value that selects the kind in a line file.
    model : type[pydantic.BaseModel]
        The element's pydantic model; its ``type`` field is ``Literal[name]``. It should
        derive from :class:`r2rsim.schema.parts.ElementBase` (id, friction, wrap, ...).
    summary : str
        One line for ``r2rsim list elements``.
    order : int
        Position among the kinds: in the element union (the order of pydantic's "expected
        one of" and of the key reference), and in ``r2rsim list``. Plug-ins sort last.
    family : {"roll", "roller", "mover"}
        How the kernel sees the element: a roll with radius states, a roller, or a roller
        on a mover.
    node_kind : str
        The kernel's node kind by name (``compile.layout.NodeKind``): ``"UNWIND"`` (a roll
        paying out web, the first element), ``"REWIND"`` (the last) or ``"ROLLER"``.
    mover_kind : str or None
        The kernel's mover geometry by name (``compile.layout.MoverKind``) of a mover kind.
    coordinate_unit : {"m", "rad"} or None
        Unit of a mover's coordinate (carriage travel, arm angle); its position readings,
        set-points and state are in it.
    range_key, start_key : str or None
        A mover's keys of its end stops ``[low, high]`` and of its position at t = 0.
    fault_targets : frozenset of str
        The fault target families (``FaultType.target`` of schema/faults.py) an element of
        this kind may carry; the element's own keys can still rule a fault out (a "drive"
        fault needs a torque drive, a "roller" fault bearing friction).
    """

    name: ClassVar[str]
    model: ClassVar[type[BaseModel]]
    summary: ClassVar[str]
    order: ClassVar[int] = 1000
    family: ClassVar[Family] = "roller"
    node_kind: ClassVar[str] = "ROLLER"
    mover_kind: ClassVar[str | None] = None
    coordinate_unit: ClassVar[Literal["m", "rad"] | None] = None
    range_key: ClassVar[str | None] = None
    start_key: ClassVar[str | None] = None
    fault_targets: ClassVar[frozenset[str]] = frozenset({"roller", "eccentric"})

    def __repr__(self) -> str:
        return f"<element kind {self.name!r}>"

    # ---- derived facts ---------------------------------------------------------------------
    @property
    def has_drive(self) -> bool:
        """Whether an element of the kind has a motor drive (its model has a ``drive``)."""
        return "drive" in self.model.model_fields

    @property
    def is_roll(self) -> bool:
        """A roll (unwind, rewind): radius and wound length are states."""
        return self.family == "roll"

    @property
    def is_mover(self) -> bool:
        """A roller on a mover (a dancer): it has a position state."""
        return self.family == "mover"

    @property
    def pays_out(self) -> bool:
        """A roll paying out web (an unwind): it starts the line and its radius shrinks."""
        return self.node_kind == "UNWIND"

    @property
    def coordinate_dimension(self) -> str | None:
        """``"length"`` or ``"angle"``: the dimension of a mover's coordinate."""
        return _DIMENSION.get(self.coordinate_unit or "")

    # ---- schema hooks ------------------------------------------------------------------------
    def surface_radius(self, e: Any) -> float:
        """Radius the web leaves the element at [m] (a roll's as declared, full)."""
        return e.radius

    def smallest_radius(self, e: Any) -> tuple[float, str] | None:
        """``(radius, key)``: the smallest radius the web wraps on the element (a roll's
        core) and its key under the element; None when it has none."""
        r = getattr(e, "radius", None)
        return None if r is None else (r, "radius")

    def drive_inertia(self, e: Any, web: Any) -> float | None:
        """Inertia [kg m^2] the element's shaft turns, for order-of-magnitude checks."""
        return getattr(e, "inertia", None)

    def frictions(self, e: Any) -> list[tuple[str, Any]]:
        """``[(key, Friction), ...]``: every bearing friction of the element, by key."""
        return [("friction", e.friction)]

    def check(self, e: Any, path: str) -> list[tuple[str, str]]:
        """The kind's own cross-field checks of one element at ``path`` (``elements[3]``):
        ``[(yaml_path, message), ...]``; run with the line's geometry checks."""
        return []

    # ---- compile hooks -----------------------------------------------------------------------
    def pack_node(self, e: Any, node: RecordWriter, web: Any) -> None:
        """Write the element's own fields of its node record: radius ``R``, inertia ``J``
        and whatever else the kind sets (the compiler writes the common ones first:
        friction, drive, wrap; a value written here replaces it)."""
        node["R"] = e.radius
        node["J"] = e.inertia

    def states(self, e: Any) -> tuple[tuple[str, str, str, str, float], ...]:
        """The element's own states, before its angular speed: ``(field, name, unit, kind,
        atol)`` each, where ``field`` is the node record's field (``compile.layout.NodeI``)
        that holds the state's index, the state is called ``<id>.<name>``, and ``kind`` is
        the state kind the solver and the initial-state search know it by. A roller has
        none; a kind with a new state equation declares it here (and its equation in a phase
        of the kernel, r2rsim/compile/model)."""
        return ()

    # ---- mover hooks (family "mover") --------------------------------------------------------
    def centre(self, e: Any, q: float) -> tuple[float, float]:
        """Roller centre [m] of a mover at coordinate ``q``."""
        raise TypeError(f"'{self.name}' is not a mover kind")

    def mover_range(self, e: Any) -> tuple[float, float]:
        """A mover's end stops ``(low, high)``."""
        return getattr(e, self.range_key or "")

    def mover_start(self, e: Any) -> float:
        """A mover's coordinate at t = 0."""
        return getattr(e, self.start_key or "")

    def pack_mover(self, e: Any, mover: RecordWriter) -> None:
        """Write the kind's fields of the mover record (the compiler writes the neighbours,
        span offsets, damping, Coulomb friction and tangents)."""
        raise TypeError(f"'{self.name}' is not a mover kind")

    # ---- solve hooks -------------------------------------------------------------------------
    def rest_tension(self, e: Any, cl: Any) -> float | None:
        """A rough tension [N] the element holds in its spans at rest, a guess for the
        initial Newton solve (``cl`` is the CompiledLine); None when it implies none."""
        return None
