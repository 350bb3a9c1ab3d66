"""Discovery of diagnostic plug-ins through the ``r2rsim.diagnostics`` entry-point group, so
a separate package can add a method without touching r2rsim."""

from __future__ import annotations

from importlib.metadata import entry_points

from ..errors import InputError

GROUP = "r2rsim.diagnostics"


def plugins() -> dict[str, type]:
    """Every registered plug-in class by name (loaded on call)."""
    out = {}
    for ep in sorted(entry_points(group=GROUP), key=lambda e: e.name):
        out[ep.name] = ep.load()
    return out


def get(name: str) -> type:
    """The plug-in class registered as ``name``."""
    found = {ep.name: ep for ep in entry_points(group=GROUP)}
    if name not in found:
        raise InputError(f"no diagnostic plug-in '{name}' (registered: "
                         f"{', '.join(sorted(found)) or 'none'}; `r2rsim list plugins`)")
    return found[name].load()


def unknown_parameter(cls: type, key: str) -> str | None:
    """The problem with giving plug-in ``cls`` the parameter ``key`` (None if it has it)."""
    known = cls().get_params()
    if key in known:
        return None
    return f"{cls.name} has no parameter '{key}' (its parameters: {', '.join(known) or 'none'})"
