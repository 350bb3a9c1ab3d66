"""Unlabelled process variability of one run (the scenario's ``variability:``; schema in
:mod:`r2rsim.schema.variability`).

The values are drawn from a child of the run's process stream that depends on nothing else
in the scenario: per run (bearing friction, sensor calibration) and per roll (the roll on
each unwind at t = 0, and each roll a splice loads, drawn when it is loaded). The draws of
one value never shift another's: each sensor, and each roll of each unwind, has its own
stream. The run's values enter the line before it is compiled (:func:`realise_variability`
returns the varied line); a spliced roll's enter at the splice
(:meth:`RollDraws.next_roll`, called by the discrete logic). Every drawn value is kept as a
row of ``variability.parquet`` (:data:`VARIABILITY_COLUMNS`).

Modulus and thickness of the roll on the unwind at t = 0 are the web's of the whole line at
t = 0. A later roll's E·A reaches the spans as its web does (an open-ended splice joint of
stiffness ratio E·A_new / E·A_0, as for ``process.modulus_change``); its thickness also sets
its radial build. The web's mass per length in the spans and on the rewind stays that of
the first roll (a per-cent effect on inertia terms only).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..schema.line import pitch_unwind
from ..schema.variability import CUT_SIGMAS, Spread, sensor_dimension

#: spawn key (under the run's process stream) of the variability stream: far above the
#: disturbances' children (at most limits.MAX_DISTURBANCES), so adding a disturbance to a
#: scenario does not change its variability draws
VARIABILITY_KEY = 1 << 20

#: drawn in this order, one draw each if varied (append only: an insertion would shift the
#: draws of every run with the later parameters)
_ROLL_PARAMETERS = (
    ("modulus", "pressure", "Pa"),
    ("thickness", "length", "m"),
    ("outer_radius", "length", "m"),
    ("wound_in_strain", "dimensionless", ""),
    ("relaxed_pitch", "length", "m"),
)

#: the columns of variability.parquet, in order (run_id, then these)
VARIABILITY_COLUMNS = (
    "source",
    "component",
    "roll",
    "parameter",
    "unit",
    "nominal",
    "value",
    "loaded_t_s",
)


def draw(spread: Spread, nominal: float, dimension: str, rng: np.random.Generator) -> float:
    """One value around ``nominal``; always one draw from ``rng`` (normal cut at
    :data:`CUT_SIGMAS`, or uniform)."""
    kind, width = spread.si(nominal, dimension)
    if kind == "normal":
        return nominal + width * float(np.clip(rng.standard_normal(), -CUT_SIGMAS, CUT_SIGMAS))
    return nominal + width * float(rng.uniform(-1.0, 1.0))


def _child(ss: np.random.SeedSequence, *key: int) -> np.random.Generator:
    return np.random.default_rng(
        np.random.SeedSequence(ss.entropy, spawn_key=(*ss.spawn_key, *key))
    )


@dataclass
class RollDraws:
    """The rolls of the run's unwinds: the one at t = 0 (drawn by
    :func:`realise_variability`) and each one a splice loads (:meth:`next_roll`).

    ``rows`` collects the drawn values (rows of variability.parquet without the run id).
    """

    stream: np.random.SeedSequence
    spec: dict  # unwind id -> RollVariability
    node_of: dict  # unwind id -> node index
    web_EA: float  # E·A of the web at t = 0 (the first roll's) [N]
    web_modulus: float  # nominal E [Pa]
    web_thickness: float  # nominal thickness [m]
    web_width: float  # [m]
    rows: list = field(default_factory=list)
    #: unwind id -> relaxed-pitch offset [m] of its roll at t = 0 (varied unwinds only)
    pitch_offset0: dict = field(default_factory=dict)
    #: pitch_length sensor id -> the offset of the web it reads at t = 0
    sensor_pitch_offsets: dict = field(default_factory=dict)
    _count: dict = field(default_factory=dict)

    def roll_values(self, unwind: str, roll, t: float) -> dict[str, float]:
        """Draw roll number ``n`` (0 at t = 0, then 1, 2, ...) of ``unwind`` around the
        nominal ``roll``: {parameter: value} in SI, recorded in ``rows``."""
        n = self._count.get(unwind, 0)
        self._count[unwind] = n + 1
        rng = _child(self.stream, 2, self.node_of[unwind], n)
        spec = self.spec[unwind]
        e0 = roll.wound_in_coefficients()[0]
        nominal = {
            "modulus": self.web_modulus,
            "thickness": self.web_thickness,
            "outer_radius": roll.outer_radius,
            "wound_in_strain": e0,
            "relaxed_pitch": 0.0,
        }
        out = {}
        for name, dim, unit in _ROLL_PARAMETERS:  # fixed order: one draw each, if varied
            spread = getattr(spec, name)
            if spread is None:
                continue
            out[name] = draw(spread, nominal[name], dim, rng)
            self.rows.append(
                {
                    "source": "roll",
                    "component": unwind,
                    "roll": n,
                    "parameter": name,
                    "unit": unit,
                    "nominal": nominal[name],
                    "value": out[name],
                    "loaded_t_s": t,
                }
            )
        return out

    def next_roll(self, unwind: str, roll, t: float):
        """The roll a splice loads on ``unwind`` at ``t``: ``(roll, EA_ratio, pitch_offset)``,
        the varied copy of the nominal spare ``roll``, its web's E·A over the first roll's
        and its relaxed-pitch offset [m] (both None when its web does not vary: the web is the
        first roll's)."""
        if unwind not in self.spec:
            return roll, None, None
        v = self.roll_values(unwind, roll, t)
        if not {"modulus", "thickness", "relaxed_pitch"} & v.keys():
            return apply_roll(roll, v), None, None
        ea = (
            v.get("modulus", self.web_modulus)
            * v.get("thickness", self.web_thickness)
            * self.web_width
        )
        return apply_roll(roll, v), ea / self.web_EA, v.get("relaxed_pitch")


def apply_roll(roll, values: dict[str, float]):
    """A copy of ``roll`` with the drawn starting radius, wound-in strain and (through the
    radial build) thickness."""
    update: dict[str, float | list[float]] = {}
    if "outer_radius" in values:
        update["outer_radius"] = values["outer_radius"]
    if "wound_in_strain" in values:
        c = roll.wound_in_coefficients()
        update["wound_in_strain"] = [values["wound_in_strain"], c[1], c[2]]
    if "thickness" in values and roll.build_per_wrap is None:
        update["build_per_wrap"] = values["thickness"]
    return roll.model_copy(update=update)


def realise_variability(scenario, line, seed_sequence):
    """Draw the run's variability and apply it to a copy of the line.

    Parameters
    ----------
    scenario : Scenario
    line : Line
    seed_sequence : numpy.random.SeedSequence
        The run's process stream.

    Returns
    -------
    line : Line
        The varied line (``line`` itself when the scenario has no ``variability``).
    rolls : RollDraws or None
        The rolls drawn so far (t = 0) and the source of the spliced ones; its ``rows``
        grow with every roll loaded.
    run_rows : list of dict
        The per-run values (friction, sensor calibration) as rows of variability.parquet.
    """
    var = scenario.variability
    if var is None:
        return line, None, []
    stream = np.random.SeedSequence(
        seed_sequence.entropy, spawn_key=(*seed_sequence.spawn_key, VARIABILITY_KEY)
    )
    rows: list[dict] = []
    elements = list(line.elements)
    if var.friction is not None:
        rng = _child(stream, 0)
        for k, e in enumerate(elements):  # one draw per element, in line order
            f = draw(var.friction, 1.0, "dimensionless", rng)
            fr = e.friction
            elements[k] = e.model_copy(
                update={
                    "friction": fr.model_copy(
                        update={"viscous": fr.viscous * f, "coulomb": fr.coulomb * f}
                    )
                }
            )
            for name, unit, value in (
                ("friction.viscous", "N m s/rad", fr.viscous),
                ("friction.coulomb", "N m", fr.coulomb),
            ):
                if value == 0.0:
                    continue  # nothing varies
                rows.append(
                    {
                        "source": "run",
                        "component": e.id,
                        "roll": None,
                        "parameter": name,
                        "unit": unit,
                        "nominal": value,
                        "value": value * f,
                        "loaded_t_s": 0.0,
                    }
                )
    sensors = list(line.sensors)
    for j, s in enumerate(sensors):
        cal = var.sensors.get(s.id)
        if cal is None:
            continue
        rng = _child(stream, 1, j)
        dim, unit = sensor_dimension(line, s)
        update = {}
        for name, spread, nominal, d, u in (
            ("gain", cal.gain, s.gain, "dimensionless", ""),
            ("offset", cal.offset, s.offset, dim, unit),
        ):
            if spread is None:
                continue
            update[name] = draw(spread, nominal, d, rng)
            rows.append(
                {
                    "source": "run",
                    "component": s.id,
                    "roll": None,
                    "parameter": f"calibration.{name}",
                    "unit": u,
                    "nominal": nominal,
                    "value": update[name],
                    "loaded_t_s": 0.0,
                }
            )
        sensors[j] = s.model_copy(update=update)
    web = line.web
    node_of = {e.id: k for k, e in enumerate(elements)}
    rolls = RollDraws(
        stream, dict(var.rolls), node_of, web.EA, web.modulus, web.thickness, web.width
    )
    for uid in var.rolls:
        k = node_of[uid]
        v = rolls.roll_values(uid, elements[k].roll, 0.0)
        elements[k] = elements[k].model_copy(update={"roll": apply_roll(elements[k].roll, v)})
        if "modulus" in v or "thickness" in v:  # the first roll's web is the line's
            web = web.model_copy(
                update={
                    "modulus": v.get("modulus", web.modulus),
                    "thickness": v.get("thickness", web.thickness),
                }
            )
        if "relaxed_pitch" in v:
            rolls.pitch_offset0[uid] = v["relaxed_pitch"]
            for s in sensors:
                if s.type == "pitch_length" and pitch_unwind(line, s) == uid:
                    rolls.sensor_pitch_offsets[s.id] = v["relaxed_pitch"]
    rolls.web_EA = web.EA
    varied = line.model_copy(update={"web": web, "elements": elements, "sensors": sensors})
    return varied, rolls, rows


def joint_slots_needed(scenario, line) -> int:
    """Splice-joint slots the varied web of spliced rolls needs: two per unwind with a
    splicer whose modulus, thickness or relaxed pitch varies (the material being paid out,
    and the one before it while its web is still on the line)."""
    var = scenario.variability
    if var is None:
        return 0
    n = 0
    for uid, r in var.rolls.items():
        e = line.element(uid)
        if getattr(e, "splicer", None) is not None and (
            r.modulus or r.thickness or r.relaxed_pitch
        ):
            n += 2
    return n
