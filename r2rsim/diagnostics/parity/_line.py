"""The registration span of a line as the ``parity`` plug-in models it: its roles (span,
driven roller, downstream roller, the five sensors) found from the line's sensor types and
positions or named by id, and the numbers of the reduced model read through them
(docs/diagnostics.md §10, "What a line needs")."""

from __future__ import annotations

from ...errors import InputError
from ..line import named

#: the role parameters of the plug-in: what each names, and what the model uses it for
ROLES = {
    "span": "the registration span (its length L)",
    "drive": "the driven roller upstream of the span (its radius, the input ω_d)",
    "downstream": "the roller ending the span (its radius, the input ω_o)",
    "pitch_sensor": "the pitch-length sensor on the span (sensor B, y_B; its relaxed pitch)",
    "load_cell": "the load cell on the downstream roller (sensor A, y_A)",
    "upstream_load_cell": "the load cell on the element upstream of the driven roller (T_up)",
    "drive_encoder": "the encoder on the driven roller (ω_d)",
    "downstream_encoder": "the encoder on the downstream roller (ω_o)",
}

#: ``preset=`` values: role ids filled in for the roles not given
PRESETS = {
    "thesis_registration": {
        "span": "registration",
        "drive": "reg_drive",
        "downstream": "reg_idler",
        "pitch_sensor": "sensor_B",
        "load_cell": "sensor_A",
        "upstream_load_cell": "lc_unwind",
        "drive_encoder": "u_drive",
        "downstream_encoder": "u_out",
    },
}

#: column parameter -> (role, unit suffix of its column)
COLUMNS = {
    "sensor_a": ("load_cell", "tension_N"),
    "sensor_b": ("pitch_sensor", "pitch_m"),
    "drive_speed": ("drive_encoder", "speed_rad_s"),
    "downstream_speed": ("downstream_encoder", "speed_rad_s"),
    "upstream_tension": ("upstream_load_cell", "tension_N"),
}

#: the numbers of the reduced model a line gives (relaxed pitch: a nominal value)
NUMBERS = ("web_EA_N", "span_length_m", "relaxed_pitch_m", "drive_radius_m", "downstream_radius_m")

#: sensor roles: (sensor type, "a ...", plural)
_SENSOR_KIND = {
    "pitch_sensor": ("pitch_length", "a pitch-length sensor", "pitch-length sensors"),
    "load_cell": ("load_cell", "a load cell", "load cells"),
    "upstream_load_cell": ("load_cell", "a load cell", "load cells"),
    "drive_encoder": ("encoder", "an encoder", "encoders"),
    "downstream_encoder": ("encoder", "an encoder", "encoders"),
}


def _ids(items) -> str:
    return ", ".join(str(x.id) for x in items) or "none"


def _placed(items, loc) -> str:
    return ", ".join(f"{s.id} on {loc(s)}" for s in items) or "none"


def _rollers(line) -> list:
    return [e for e in line.elements if getattr(e, "radius", None) is not None]


def _element(line, role: str, given: str):
    return named(_rollers(line), given, "parity", role, "a roller", "rollers")


def _sensor(line, role: str, given: str | None, place: str | None, where: str, need: str):
    """The sensor of a sensor role: the one named ``given`` (of the role's type), else the
    only one of the type at ``place`` (an element or span id; ``where`` says so)."""
    typ, a, plural = _SENSOR_KIND[role]
    cands = [s for s in line.sensors if s.type == typ]
    loc = (lambda s: s.span) if typ == "pitch_length" else (lambda s: s.element)
    if given is not None:
        return named(cands, given, "parity", role, a, plural)
    here = [s for s in cands if place is None or loc(s) == place]
    if not here:
        raise InputError(
            f"parity: {role}: the line has no {a.split(' ', 1)[1]}{where}, "
            f"needed for {need} ({plural}: {_placed(cands, loc)}); name one "
            f"with {role}=<id>"
        )
    if len(here) > 1:
        raise InputError(
            f"parity: {role}: the line has {len(here)} {plural}{where} "
            f"({_placed(here, loc)}); name one with {role}=<id>"
        )
    return here[0]


def find_roles(line, given: dict | None = None) -> dict[str, str]:
    """Every role of :data:`ROLES` in ``line``: the id ``given`` for it (checked to be of the
    role's kind), else inferred.

    Inference: ``pitch_sensor`` is the only pitch-length sensor (on ``span`` when that is
    given); ``span`` its span; ``drive`` and ``downstream`` the elements upstream and
    downstream of the span; ``load_cell`` the only load cell on ``downstream``;
    ``upstream_load_cell`` the only load cell on the element upstream of ``drive``;
    ``drive_encoder`` and ``downstream_encoder`` the only encoder on ``drive`` and on
    ``downstream``.

    Raises
    ------
    InputError
        One line naming the parameter and listing the line's candidates, when a given id is
        not of the role's kind or a role has no candidate or several.
    """
    given = {k: v for k, v in (given or {}).items() if v is not None}
    spans = {s.id: j for j, s in enumerate(line.spans)}
    els = line.elements
    index = {e.id: i for i, e in enumerate(els)}
    roles: dict[str, str] = {}
    if "span" in given:
        named(line.spans, given["span"], "parity", "span", "a span", "spans")
    span = given.get("span")
    pitch = _sensor(
        line,
        "pitch_sensor",
        given.get("pitch_sensor"),
        span,
        f" on span '{span}'" if span else "",
        "the pitch y_B",
    )
    roles["pitch_sensor"] = pitch.id
    roles["span"] = span = span or pitch.span
    j = spans[span]
    for role, k, side in (("drive", j, "upstream"), ("downstream", j + 1, "downstream")):
        if role in given:
            roles[role] = _element(line, role, given[role]).id
            continue
        e = els[k]
        if getattr(e, "radius", None) is None:
            raise InputError(
                f"parity: {role}: the element {side} of span '{span}' is "
                f"'{e.id}' ({e.type}), which has no radius; name the roller "
                f"with {role}=<id> (rollers: {_ids(_rollers(line))})"
            )
        roles[role] = e.id
    drive, down = roles["drive"], roles["downstream"]
    up = els[index[drive] - 1].id if index[drive] > 0 else None
    for role, place, where, need in (
        ("load_cell", down, f" on the downstream roller '{down}'", "the span tension y_A"),
        (
            "upstream_load_cell",
            up,
            f" on the element upstream of the driven roller '{drive}' ({up or 'none'})",
            "the upstream tension T_up",
        ),
        ("drive_encoder", drive, f" on the driven roller '{drive}'", "the input ω_d"),
        ("downstream_encoder", down, f" on the downstream roller '{down}'", "the input ω_o"),
    ):
        if place is None and role not in given:
            raise InputError(
                f"parity: {role}: the driven roller '{drive}' is the line's first "
                f"element; name the upstream load cell with {role}=<id>"
            )
        roles[role] = _sensor(line, role, given.get(role), place, where, need).id
    return {r: roles[r] for r in ROLES}


def line_numbers(line, roles: dict[str, str]) -> dict[str, float]:
    """E·A [N] of the web, the span length L [m], the pitch sensor's nominal relaxed pitch
    [m] (``relaxed_pitch`` or its law's q0; the roll-radius term q1·R³ is unknown to a
    monitor) and the radii [m] of the ``drive`` and ``downstream`` rollers, read from
    ``line`` through ``roles`` (ids checked as by :func:`find_roles`)."""
    roles = find_roles(line, roles)
    span = next(s for s in line.spans if s.id == roles["span"])
    els = {e.id: e for e in line.elements}
    b = next(s for s in line.sensors if s.id == roles["pitch_sensor"])
    L0 = b.relaxed_pitch if b.relaxed_pitch is not None else b.relaxed_pitch_law.q0
    w = line.web
    return {
        "web_EA_N": float(w.modulus * w.thickness * w.width),
        "span_length_m": float(span.length),
        "relaxed_pitch_m": float(L0),
        "drive_radius_m": float(els[roles["drive"]].radius),
        "downstream_radius_m": float(els[roles["downstream"]].radius),
    }


def role_columns(roles: dict) -> dict[str, str | None]:
    """The column of each channel parameter built from its role's sensor id (None when the
    role is unknown): ``meas.<id>.tension_N``, ``meas.<id>.pitch_m``,
    ``meas.<id>.speed_rad_s``."""
    return {
        key: (f"meas.{roles[role]}.{unit}" if roles.get(role) else None)
        for key, (role, unit) in COLUMNS.items()
    }
