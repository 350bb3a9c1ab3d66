"""The stage structure of a line file (``stage:`` attributes) and the physical constants the
hybrid model needs (thesis §2.6: unwind, splice idlers, dancer, driven roller,
registration idlers)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import InputError


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
    """The five thesis stages of a line and the channels that observe them.

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

    def column(self, key: str) -> str:
        """The visible column of a sensor role (e.g. ``"tension"``)."""
        unit = {"diameter": "diameter_m", "speed_unwind": "speed_rad_s",
                "speed_idler": "speed_rad_s", "speed_driven": "speed_rad_s",
                "tension": "tension_N", "angle": "position_rad", "pitch": "pitch_m"}[key]
        return f"meas.{self.sensor_ids[key]}.{unit}"

    def torque_column(self, element: str) -> str:
        """The applied-torque column of a driven element (drive data)."""
        return f"act.{element}.torque_N_m"

    def roll_inertia(self, R: np.ndarray) -> np.ndarray:
        """J(R) = J_c + (π/2)·ρ·w·(R⁴ - R_c⁴), the unwind's inertia at radius R [kg·m²]."""
        return self.core_inertia + 0.5 * np.pi * self.web_density * self.web_width * (
            R**4 - self.core_radius**4)


def _roller(e) -> Roller:
    return Roller(e.id, float(e.radius), float(e.inertia), float(e.friction.viscous))


def load_stages(path: str | Path) -> LineStages:
    """Read a line file's stages (thesis §2.6) and sensors.

    Parameters
    ----------
    path : str or Path
        A line YAML whose elements carry ``stage: 1..5``: stage 1 an unwind, 2 idlers, 3 a
        dancer (and idlers), 4 a driven roller, 5 idlers; with a roll-diameter sensor and an
        encoder on the unwind, an encoder on a stage-2 idler and on the driven roller, a load
        cell on the last stage-2 idler, a dancer-position sensor and a pitch-length sensor on
        the span after the driven roller.

    Raises
    ------
    InputError
        When the file cannot be read or lacks one of these.
    """
    from ...schema.loader import load_line

    line = load_line(Path(path))
    by_stage: dict[int, list] = {}
    for e in line.elements:
        if e.stage is not None:
            by_stage.setdefault(int(e.stage), []).append(e)
    where = f"hybrid-sov: line {Path(path).name}"
    missing = [k for k in range(1, 6) if k not in by_stage]
    if missing:
        raise InputError(f"{where}: no element has stage {missing} (the model needs "
                         f"stage: attributes 1..5)")
    unwinds = [e for e in by_stage[1] if e.type == "unwind"]
    dancers = [e for e in by_stage[3] if "dancer" in e.type]
    driven = [e for e in by_stage[4] if e.type == "driven"]
    if not (unwinds and dancers and driven):
        raise InputError(f"{where}: needs an unwind in stage 1, a dancer in stage 3 and a "
                         f"driven roller in stage 4")
    uw, dancer, drv = unwinds[0], dancers[0], driven[0]
    idlers = {k: [_roller(e) for e in by_stage[k] if e.type in ("idler", "pivot_dancer",
                                                                 "linear_dancer")]
              for k in (2, 3, 5)}
    sensors = {}
    stage2_ids = [r.id for r in idlers[2]]
    for s in line.sensors:
        el = getattr(s, "element", None)
        if s.type == "roll_diameter" and el == uw.id:
            sensors["diameter"] = s.id
        elif s.type == "encoder" and el == uw.id:
            sensors["speed_unwind"] = s.id
        elif s.type == "encoder" and el == drv.id:
            sensors["speed_driven"] = s.id
        elif s.type == "encoder" and el in stage2_ids and "speed_idler" not in sensors:
            sensors["speed_idler"] = s.id
            sensors["speed_idler_radius"] = next(r.radius for r in idlers[2] if r.id == el)
        elif s.type == "load_cell" and el == stage2_ids[-1]:
            sensors["tension"] = s.id
        elif s.type == "dancer_position" and el == dancer.id:
            sensors["angle"] = s.id
        elif s.type == "pitch_length":
            sensors["pitch"] = s.id
            law = s.relaxed_pitch_law
            relaxed = float(law.q0) if law is not None else float(s.relaxed_pitch or 0.0)
    need = ["diameter", "speed_unwind", "speed_idler", "speed_driven", "tension", "angle",
            "pitch"]
    absent = [k for k in need if k not in sensors]
    if absent:
        raise InputError(f"{where}: no sensor for {', '.join(absent)}")
    w = line.web
    return LineStages(line.name, uw.id, float(uw.roll.core_radius),
                      float(uw.roll.core_inertia), float(uw.friction.viscous),
                      float(w.density), float(w.width), float(w.thickness),
                      float(w.modulus * w.width * w.thickness), idlers, _roller(drv),
                      dancer.id, sensors, relaxed)
