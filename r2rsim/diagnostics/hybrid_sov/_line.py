"""The stage structure of a line file and the physical constants the hybrid model needs
(thesis §2.6: unwind, splice idlers, dancer, driven roller, registration idlers): each role
found from the elements' ``stage:`` keys and the sensors' types and positions, or named by
id (the plug-in's role parameters)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import InputError
from ...schema.kinds import kind_of
from ..line import named


@dataclass(frozen=True)
class Roller:
    """A roller of a stage: id, radius R [m], inertia J [kg·m²], viscous friction b
    [N·m·s]."""

    id: str
    radius: float
    inertia: float
    viscous: float


@dataclass(frozen=True)
class LineStages:
    """The five thesis stages of a line and the channels that observe them
    (:func:`load_stages`).

    Attributes
    ----------
    name : str
    unwind : str
        Stage-1 material roll.
    core_radius, core_inertia, unwind_viscous : float
        Its core radius [m], core inertia [kg·m²], viscous friction [N·m·s].
    web_density, web_width, web_thickness, web_EA : float
        ρ [kg/m³], w [m], t [m], and E·A [N] of the web.
    idlers : dict of int -> list of Roller
        Idlers of stages 2, 3 (with the dancer roller) and 5.
    driven : Roller
        The stage-4 driven roller.
    dancer : str
        The stage-3 dancer.
    sensor_ids : dict
        ``diameter``, ``speed_unwind``, ``speed_idler`` (+ ``speed_idler_radius``),
        ``speed_driven``, ``tension`` (the stage-2 load cell), ``angle`` (dancer), ``pitch``.
    relaxed_pitch : float
        The pitch sensor's nominal relaxed pitch [m] (a starting value only).
    dancer_position_unit : {"rad", "m"}
        Unit of the dancer-position reading: the arm angle of a pivoted dancer, the travel
        of a translating one.
    """

    name: str
    unwind: str
    core_radius: float
    core_inertia: float
    unwind_viscous: float
    web_density: float
    web_width: float
    web_thickness: float
    web_EA: float
    idlers: dict
    driven: Roller
    dancer: str
    sensor_ids: dict
    relaxed_pitch: float
    dancer_position_unit: str = "rad"

    def column(self, key: str) -> str:
        """The visible column of a sensor role (e.g. ``"tension"``)."""
        unit = {
            "diameter": "diameter_m",
            "speed_unwind": "speed_rad_s",
            "speed_idler": "speed_rad_s",
            "speed_driven": "speed_rad_s",
            "tension": "tension_N",
            "angle": f"position_{self.dancer_position_unit}",
            "pitch": "pitch_m",
        }[key]
        return f"meas.{self.sensor_ids[key]}.{unit}"

    def torque_column(self, element: str) -> str:
        """The applied-torque column of a driven element (drive data)."""
        return f"act.{element}.torque_N_m"

    def roll_inertia(self, R: np.ndarray) -> np.ndarray:
        """J(R) = J_c + (π/2)·ρ·w·(R⁴ - R_c⁴), the unwind's inertia at radius R [kg·m²]."""
        return self.core_inertia + 0.5 * np.pi * self.web_density * self.web_width * (
            R**4 - self.core_radius**4
        )


def _roller(e) -> Roller:
    return Roller(e.id, float(e.radius), float(e.inertia), float(e.friction.viscous))


#: the role parameters of the plug-in and of :func:`load_stages`: what each names, and what
#: the model uses it for (docs/diagnostics.md §9.1, "What a line needs")
ROLES = {
    "unwind": "the stage-1 unwind (its torque balance, eqs. 2.6, 2.15)",
    "dancer": "the stage-3 dancer (eq. 2.23)",
    "driven": "the stage-4 driven roller (its torque balance, eq. 2.18)",
    "diameter_sensor": "the roll-diameter sensor on the unwind (the radius R)",
    "unwind_encoder": "the encoder on the unwind (ω1)",
    "idler_encoder": "the encoder on a stage-2 idler (the web speed v)",
    "driven_encoder": "the encoder on the driven roller (ω4)",
    "load_cell": "the load cell on a stage-2 idler (the stage-2 tension T_s2)",
    "dancer_sensor": "the dancer-position sensor on the dancer (α)",
    "pitch_sensor": "the pitch-length sensor on the span leaving the driven roller (Y)",
}


#: element roles: (which element kinds may fill it, "a ...", plural, stage, what the model
#: needs it for); the driven roller is the ``driven`` kind itself: the model's torque
#: balance has one roller (a nip's pressure roller is not in it)
_ELEMENT_ROLES = {
    "unwind": (
        lambda k: k.pays_out,
        "an unwind",
        "unwinds",
        1,
        "stage 1 (the unwind's torque balance)",
    ),
    "dancer": (lambda k: k.is_mover, "a dancer", "dancers", 3, "stage 3 (the dancer stage)"),
    "driven": (
        lambda k: k.name == "driven",
        "a driven roller",
        "driven rollers",
        4,
        "stage 4 (the driven roller's torque balance)",
    ),
}

#: sensor roles: (sensor type, "a ...", plural, the key in LineStages.sensor_ids, what the
#: model needs the reading for)
_SENSOR_ROLES = {
    "diameter_sensor": (
        "roll_diameter",
        "a roll-diameter sensor",
        "roll-diameter sensors",
        "diameter",
        "the unwind radius R",
    ),
    "unwind_encoder": ("encoder", "an encoder", "encoders", "speed_unwind", "the unwind speed ω1"),
    "idler_encoder": ("encoder", "an encoder", "encoders", "speed_idler", "the web speed v"),
    "driven_encoder": (
        "encoder",
        "an encoder",
        "encoders",
        "speed_driven",
        "the driven roller's speed ω4",
    ),
    "load_cell": ("load_cell", "a load cell", "load cells", "tension", "the stage-2 tension T_s2"),
    "dancer_sensor": (
        "dancer_position",
        "a dancer-position sensor",
        "dancer-position sensors",
        "angle",
        "the dancer position α",
    ),
    "pitch_sensor": (
        "pitch_length",
        "a pitch-length sensor",
        "pitch-length sensors",
        "pitch",
        "the pitch Y",
    ),
}


def _ids(items) -> str:
    return ", ".join(x.id for x in items) or "none"


def _find_element(line, role: str, given: str | None):
    """The element of an element role: the one named ``given`` (of the role's type), else
    the only one of the role's type with the role's ``stage:``."""
    fits, a, plural, stage, need = _ELEMENT_ROLES[role]
    cands = [e for e in line.elements if fits(kind_of(e))]
    if given is not None:
        return named(cands, given, "hybrid-sov", role, a, plural)
    if not cands:
        raise InputError(
            f"hybrid-sov: {role}: the line has no {a.split(' ', 1)[1]}, needed for {need}"
        )
    staged = [e for e in cands if e.stage == stage]
    if not staged:
        raise InputError(
            f"hybrid-sov: {role}: no {a.split(' ', 1)[1]} of the line has stage: "
            f"{stage} ({plural}: {_ids(cands)}); mark one stage: {stage} or name "
            f"it with {role}=<id>"
        )
    if len(staged) > 1:
        raise InputError(
            f"hybrid-sov: {role}: {len(staged)} {plural} have stage: {stage} "
            f"({_ids(staged)}); name one with {role}=<id>"
        )
    return staged[0]


def _find_sensor(
    line,
    role: str,
    given: str | None,
    places: list[str],
    where: str,
    loc=lambda s: getattr(s, "element", None),
):
    """The sensor of a sensor role: of the role's type, at one of ``places`` (element or
    span ids; ``where`` says so in words); the one named ``given``, else the only one."""
    typ, a, plural, _key, need = _SENSOR_ROLES[role]
    cands = [s for s in line.sensors if s.type == typ]
    if given is not None:
        hit = named(cands, given, "hybrid-sov", role, a, plural)
        if loc(hit) not in places:
            raise InputError(f"hybrid-sov: {role} '{given}' is on {loc(hit)}, not {where}")
        return hit
    here = [s for s in cands if loc(s) in places]
    if not here:
        raise InputError(
            f"hybrid-sov: {role}: the line has no {a.split(' ', 1)[1]} {where}, "
            f"needed for {need} ({plural}: {_ids(cands)})"
        )
    if len(here) > 1:
        listed = ", ".join(f"{s.id} on {loc(s)}" for s in here)
        raise InputError(
            f"hybrid-sov: {role}: the line has {len(here)} {plural} {where}: "
            f"{listed}; name one with {role}=<id>"
        )
    return here[0]


def _is_idler(e) -> bool:
    kind = kind_of(e)
    return kind.family == "roller" and not kind.has_drive


def _idlers(line, index: dict, uw, dancer, drv) -> dict[int, list]:
    """The idlers of stages 2, 3 and 5: the idlers with ``stage: k``; for a stage no element
    is marked with, the idlers on the web path: between the unwind and the dancer (2),
    between the dancer and the driven roller (3), and those right after the driven roller
    (5). The dancer's roller is always one of stage 3 (it spins like an idler). An idler is
    a roller without a drive (the ``idler`` kind, or a plug-in roller like it)."""
    els = line.elements
    path = {
        2: [e for e in els[index[uw.id] + 1 : index[dancer.id]] if _is_idler(e)],
        3: [e for e in els[index[dancer.id] + 1 : index[drv.id]] if _is_idler(e)],
        5: [],
    }
    for e in els[index[drv.id] + 1 :]:
        if not _is_idler(e):
            break
        path[5].append(e)
    marked = {e.stage for e in els}
    out = {}
    for k in (2, 3, 5):
        if k in marked:
            out[k] = [e for e in els if e.stage == k and _is_idler(e)]
        else:
            out[k] = path[k]
    if dancer.id not in {e.id for e in out[3]}:
        out[3] = sorted(out[3] + [dancer], key=lambda e: index[e.id])
    return {k: [_roller(e) for e in v] for k, v in out.items()}


def load_stages(path, roles: dict | None = None) -> LineStages:
    """Read a line file's stages (thesis §2.6) and the sensors the hybrid model reads.

    Every role is found from the elements' ``stage:`` keys and the sensors' types and
    positions, unless ``roles`` names it by id (docs/diagnostics.md §9.1, "What a line
    needs"):

    * ``unwind``, ``dancer``, ``driven``: the only unwind with ``stage: 1``, dancer
      (translating or pivoted) with ``stage: 3``, driven roller with ``stage: 4``; a given
      id must be an element of that type. The dancer must lie between the unwind and the
      driven roller along the web.
    * the idlers of stages 2, 3 and 5: the idlers with ``stage: k``; a stage no element is
      marked with takes the idlers on the web path between the unwind and the dancer (2),
      the dancer and the driven roller (3), and those right after the driven roller (5).
      The dancer's roller is always one of stage 3.
    * ``diameter_sensor``, ``unwind_encoder``: the roll-diameter sensor, the encoder on the
      unwind; ``driven_encoder``: the encoder on the driven roller; ``idler_encoder``,
      ``load_cell``: the encoder, the load cell on a stage-2 idler; ``dancer_sensor``: the
      dancer-position sensor on the dancer; ``pitch_sensor``: the pitch-length sensor on
      the span leaving the driven roller. Found when exactly one sensor of the type is at
      that place; a given id must be a sensor of the type at that place.

    Parameters
    ----------
    path : str or Path
        A line YAML.
    roles : dict, optional
        Role name (a key of :data:`ROLES`) -> id in the line, or None to search.

    Raises
    ------
    InputError
        When the file cannot be read, a given id is not of the role's kind (the message
        names the parameter and lists the line's candidates), or a role has no candidate or
        several (the message says what is missing, or asks for the parameter).
    """
    from ...schema.loader import load_line

    roles = dict(roles or {})
    unknown = sorted(set(roles) - set(ROLES))
    if unknown:
        raise InputError(
            f"hybrid-sov: unknown role {', '.join(unknown)} (roles: {', '.join(ROLES)})"
        )
    # a line file, or a loaded line (the run's, r2rsim.diagnostics.line.frame_line)
    line = path if hasattr(path, "elements") else load_line(Path(path))
    index = {e.id: i for i, e in enumerate(line.elements)}
    uw = _find_element(line, "unwind", roles.get("unwind"))
    dancer = _find_element(line, "dancer", roles.get("dancer"))
    drv = _find_element(line, "driven", roles.get("driven"))
    if not index[uw.id] < index[dancer.id] < index[drv.id]:
        raise InputError(
            f"hybrid-sov: dancer '{dancer.id}' is not between the unwind "
            f"'{uw.id}' and the driven roller '{drv.id}' along the web: the "
            f"model needs unwind (stage 1), dancer (stage 3) and driven roller "
            f"(stage 4) in this order"
        )
    idlers = _idlers(line, index, uw, dancer, drv)
    stage2 = [r.id for r in idlers[2]]
    on2 = f"on a stage-2 idler ({', '.join(stage2) or 'there is none'})"
    span = line.spans[index[drv.id]].id  # the span leaving the driven roller
    found = {
        "diameter_sensor": ([uw.id], f"on the unwind '{uw.id}'"),
        "unwind_encoder": ([uw.id], f"on the unwind '{uw.id}'"),
        "idler_encoder": (stage2, on2),
        "driven_encoder": ([drv.id], f"on the driven roller '{drv.id}'"),
        "load_cell": (stage2, on2),
        "dancer_sensor": ([dancer.id], f"on the dancer '{dancer.id}'"),
    }
    sensors = {}
    for role, (places, where) in found.items():
        sensors[_SENSOR_ROLES[role][3]] = _find_sensor(
            line, role, roles.get(role), places, where
        ).id
    pitch = _find_sensor(
        line,
        "pitch_sensor",
        roles.get("pitch_sensor"),
        [span],
        f"on the span leaving the driven roller '{drv.id}' ({span})",
        loc=lambda s: s.span,
    )
    sensors["pitch"] = pitch.id
    enc = next(s for s in line.sensors if s.id == sensors["speed_idler"])
    sensors["speed_idler_radius"] = next(r.radius for r in idlers[2] if r.id == enc.element)
    law = pitch.relaxed_pitch_law
    relaxed = float(law.q0) if law is not None else float(pitch.relaxed_pitch or 0.0)
    w = line.web
    return LineStages(
        line.name,
        uw.id,
        float(uw.roll.core_radius),
        float(uw.roll.core_inertia),
        float(uw.friction.viscous),
        float(w.density),
        float(w.width),
        float(w.thickness),
        float(w.modulus * w.width * w.thickness),
        idlers,
        _roller(drv),
        dancer.id,
        sensors,
        relaxed,
        kind_of(dancer).coordinate_unit,
    )
