"""Plausibility of a valid line or scenario: is it physics, or a typo?

The schema checks that each value has the right type, unit and sign. Here they are checked
against the physics: a valid but absurd input (a web 1 m thick, a 1 nm span, a modulus of
1e20 Pa, a controller gain of 1e300) would otherwise run for minutes or hours, or return
tensions that are rounding noise, without a word. Two levels:

* **error** (:class:`r2rsim.errors.InputError`): physically impossible, or outside what the
  model can integrate: stiffer than diamond, denser than osmium, a web that cannot wrap its
  rollers, a span shorter than 1 mm, a line faster than the web's own wave speed, a loop
  faster than 160 kHz; or far beyond every web line (a span longer than 10 km, a roller
  radius outside 1 mm to 10 m, a tension above 10 MN, ...: the magnitudes below), which
  would only make the float32 samples overflow;
* **warning** (:class:`r2rsim.errors.PlausibilityWarning`): possible but far outside the
  ranges of ``physics.md`` §2 (the user may mean it: a 10 mm tape, a 60 m/s line), or a
  choice with a silent consequence (a web with no break stress never breaks, a set-point
  above the break tension breaks the web, unless the loop commands a roll's torque and the
  drive's torque_max / R stays below the break tension: the warning then says so). ``r2rsim``
  prints warnings as ``warning: file: path: message`` and runs on.

Each check is a ``(level, yaml_path, message)``; :func:`line_problems` and
:func:`scenario_problems` return them all, and the loader raises or warns.
"""

from __future__ import annotations

import functools
import math
import typing

import annotated_types
from pydantic import BaseModel, WithJsonSchema

from ..limits import MAX_DURATION_S
from .kinds import kind_of
from .kinds._roll import roll_inertia

ERROR = "error"
WARNING = "warning"

# --- the web (physics.md §2.1) ---------------------------------------------------------------
#: Stiffest solid known (diamond, 1.05-1.2 TPa): any web modulus above it is a typo.
MODULUS_MAX = 1.2e12
#: Ranges of physics.md §2.1 widened to everything sold as a web: elastomer films (~10 MPa)
#: to tungsten or steel strip (200-410 GPa); outside them a warning.
MODULUS_RANGE = (1.0e7, 4.5e11)
#: Densest element (osmium, 22 590 kg/m^3).
DENSITY_MAX = 22_600.0
#: Light nonwovens (~100 kg/m^3) to gold or platinum foil (~20 000).
DENSITY_RANGE = (100.0, 20_000.0)
#: Ideal strength of graphene (~130 GPa): no web breaks above it.
BREAK_STRESS_MAX = 1.3e11
#: Break strain above which T = EA·ε (Hooke, the span model) no longer describes the web.
BREAK_STRAIN_MAX = 0.25
#: Films from 1 µm (capacitor film) to 5 mm (metal strip, board); physics.md §2.1: 6-250 µm.
THICKNESS_RANGE = (1.0e-6, 5.0e-3)
#: Narrow tape (10 mm) to the widest paper machine (~11 m); physics.md §2.1: 0.3-10 m.
WIDTH_RANGE = (1.0e-2, 12.0)
#: Running strain T/EA below which the span states (1 + strain, in double precision) cannot
#: resolve the tension: it would be rounding noise (the 1e20 Pa case).
STRAIN_RESOLUTION = 1.0e-9

# --- geometry and speed (physics.md §2.2) ----------------------------------------------------
#: Shortest free span [m]. Nip and S-wrap spans are 30-300 mm; below 1 mm the span is
#: comparable to the web's thickness and its stiffness EA/L makes the state stiff beyond use
#: (a 1 nm span gave 6 kN on a 260 N line).
SPAN_MIN = 1.0e-3
#: Spans outside [10 mm, 100 m] get a warning (dryer spans reach 30 m).
SPAN_RANGE = (1.0e-2, 100.0)
#: Fastest line in physics.md §2.2: paper machines, 15-35 m/s.
SPEED_MAX = 50.0

# --- torques, strains and sensors --------------------------------------------------------------
#: Largest bearing friction or drag torque [N m] (and viscous coefficient [N m s]): the drives
#: of the largest paper-machine reels deliver ~1e5 N m; a friction beyond 1e6 is a typo, and at
#: 1e300 the integrator's arithmetic overflows.
TORQUE_MAX = 1.0e6
#: A wound-in strain (or its spread) as large as this is not a pre-strain the span model can
#: carry: the break strain above which Hooke's law no longer describes the web.
WOUND_IN_STRAIN_MAX = BREAK_STRAIN_MAX
#: Calibration gain g of y = g·x + b: outside [1e-3, 1e3] it is not a calibration (a sensor
#: whose reading is a thousandth or a thousand times the quantity); sensor.gain faults model
#: gain errors separately.
GAIN_RANGE = (1.0e-3, 1.0e3)
#: Largest noise, offset or speed-noise slope (per m/s at the fastest line) of a reading, in
#: its SI unit (N, m, rad, rad/s): no sensor reads 1e9 of its unit, and readings are stored as
#: float32, which overflows to inf at 3.4e38.
READING_MAX = 1.0e9
#: Finest quantization step of a reading [SI unit] (0 = none): a finer step is below any
#: instrument, and one near 1e-308 overflows when the reading is divided by it.
QUANTIZATION_MIN = 1.0e-12

# --- controllers (physics.md §1.10) ----------------------------------------------------------
#: Highest loop rate [rad/s] an error allows: 1e6 rad/s = 160 kHz, 100 times the fastest
#: current loop (0.5-2 kHz); the solver would need sub-microsecond steps.
LOOP_RATE_MAX = 1.0e6
#: A speed loop is 5-10 times slower than its drive's current (torque) loop (physics.md
#: §1.10); one estimated at more than ten times faster cannot be what its gains say. (Gains
#: tuned for a full roll are ~100 times faster on a near-empty one and stay stable, so the
#: warning is not at 1x.)
SPEED_OVER_TORQUE = 10.0
#: Tension and dancer loops run at 0.5-5 Hz, speed loops at 10-50 Hz; a tension or dancer
#: loop faster than 2π·50 Hz would outrun the speed loops it trims.
TRIM_RATE_WARN = 2 * math.pi * 50.0

# --- magnitudes: values no web line has (errors) ---------------------------------------------
# A value the schema accepts (a positive number, say) but that is far beyond any web line is
# refused too: a 1e300 m span used to run, exit 0 and write inf into its float32 length column.
# Each bound sits one or more orders of magnitude beyond the largest real line of its kind
# (film, foil, paper, board, battery electrodes; steel strip too), so that only typos and
# absurd values are refused, and products of the bounds stay far below float32's 3.4e38. The
# named bounds are checked where the quantity is; MAGNITUDE_MAX bounds every other quantity of
# a line or scenario file by its dimension. The messages give the accepted range.

#: Longest free span [m]: 10 km. The longest real free spans are dryer and oven spans of
#: ~30 m; 100 m to 10 km stays a warning (SPAN_RANGE), as before.
SPAN_MAX = 1.0e4
#: Radii of rolls, cores, rollers, nips and dancers, and the splice trigger radius [m]: 1 mm to
#: 10 m. Guide rollers of narrow tape lines are ~5 mm in radius; the largest are Yankee dryers
#: (~3.4 m) and full paper-machine reels (~1.8 m). On a roller under 1 mm the angular speed v/R
#: of a line at its fastest (1 km/s) would pass 1e6 rad/s, and at 1e-40 m it overflowed.
RADIUS_LIMITS = (1.0e-3, 10.0)
#: Web thickness and radial build per wrap [m]: 10 nm to 100 mm. The thinnest webs are ~1 µm
#: (capacitor film; metal leaf 0.1 µm), the thickest strip (hot-rolled steel) ~25 mm; 1 µm to
#: 5 mm stays without a warning (THICKNESS_RANGE). A build per wrap far below the thickness
#: would make the roll's web density (thickness / build) absurd.
THICKNESS_LIMITS = (1.0e-8, 0.1)
#: Widest web [m]: 100 m. The widest paper machines make ~11 m; above 12 m is a warning
#: (WIDTH_RANGE).
WIDTH_MAX = 100.0
#: Largest web-roller friction coefficient (the capstan slip monitor's mu): 10. Rubber-covered
#: rollers reach 1-2; the capstan factor e^(mu·beta) overflows double precision from mu ~ 113.
FRICTION_COEFFICIENT_MAX = 10.0
#: Fastest line [m/s]: 1 km/s, an error (SPEED_MAX warns from 50 m/s). The fastest web lines
#: (paper machines, slitter-rewinders) run at 35-50 m/s; the line speed sets every roller's.
LINE_SPEED_LIMIT = 1.0e3
#: Largest tension or force [N]: 10 MN. Film and paper lines run at 0.1-20 kN, the strongest
#: webs (steel strip in cold-rolling lines) at up to ~1 MN. A set-point above the web's break
#: tension is a warning below this bound (tension_problems).
FORCE_MAX = 1.0e7
#: Travel of a dancer or festoon carriage (stops, start, spring's free travel) [m]: within
#: ±10 km, the longest span (SPAN_MAX); real strokes are 0.1-30 m (accumulator towers).
TRAVEL_MAX = SPAN_MAX
#: Most rollers on a festoon carriage: 1000 (accumulators have up to a few tens); the stored
#: web is 2n·x, so an n of 1e40 overflowed the span length.
FESTOON_ROLLERS_MAX = 1000
#: Shortest counting window of an edge-counting encoder [s]: 1 µs. One count in the window
#: reads 2π/(counts_per_rev·window): a window near 1e-300 s made the readings overflow.
ENCODER_WINDOW_MIN = 1.0e-6
#: Every other quantity of a line or scenario file, by dimension: the largest magnitude
#: accepted, and why. A quantity with a check of its own is not checked again here: sensor
#: noise and offset (READING_MAX), tension set-points (FORCE_MAX), modulus, density and break
#: stress (MODULUS_MAX, DENSITY_MAX, BREAK_STRESS_MAX), the relaxed-pitch law's q1 (the pitch
#: it gives over the roll), frictions (TORQUE_MAX); a dimension not listed (a plain number,
#: a fault magnitude) is not bounded here.
MAGNITUDE_MAX: dict[str, tuple[float, str]] = {
    # positions, arm lengths, pitch and correlation lengths
    "length": (1.0e5, "longer than the web on any roll (a film roll holds up to ~60 km)"),
    "speed": (LINE_SPEED_LIMIT, "faster than any web line (35-50 m/s at most)"),
    "acceleration": (1.0e3, "100 g: lines accelerate at a few m/s^2, gravity is 9.81 m/s^2"),
    # time constants, delays, splice phases, ramps: none outlasts the longest run
    "time": (MAX_DURATION_S, "longer than the longest run (1e6 s)"),
    "frequency": (
        1.0e6,
        "1 MHz: above any drive or sensor bandwidth (current loops run at 0.5-2 kHz)",
    ),
    "force": (FORCE_MAX, "steel strip runs at up to ~1 MN, film and paper at 0.1-20 kN"),
    # a spring on a dancer carriage; a steel bar of 1 cm^2 x 20 cm is 1e8 N/m
    "stiffness": (1.0e9, "stiffer than a steel bar used as a spring (1e8 N/m)"),
    "damping": (1.0e9, "a damper force of 1 MN at 1 mm/s"),
    # dancer, arm and carriage masses
    "mass": (
        1.0e6,
        "1000 t: heavier than any roll or carriage (a full paper-machine reel is ~100 t)",
    ),
    # (verification lines stand in for an infinitely heavy roller with 1e8 kg m^2)
    "inertia": (1.0e10, "a full paper-machine reel is ~2e5 kg m^2, a Yankee dryer ~1e6"),
    # drive limits, commands and ripple, dancer torques and torsion springs [N m/rad]
    "torque": (1.0e7, "the largest drives (steel-strip coilers) deliver ~1e6 N m"),
    "viscous torque": (TORQUE_MAX, "beyond any bearing or pivot damper"),
    # arm angles and stops, load-cell axes: within a turn
    "angle": (100.0, "16 turns: arm and axis angles lie within one"),
    "angular speed": (1.0e6, "v/R of a 1 mm roller at 1 km/s"),
    # draws, stiffness ratios, inertia-estimate factors (mu and strains have their own checks)
    "dimensionless": (1.0e3, "a draw or ratio of a thousand"),
}


def _amount(x: float, unit: str) -> str:
    """``x`` in ``unit``, a length with a metric prefix (1 mm, 10 km)."""
    if unit == "m" and x != 0:
        for scale, name in ((1e3, "km"), (1.0, "m"), (1e-3, "mm"), (1e-6, "µm"), (1e-9, "nm")):
            if abs(x) >= scale:
                return f"{x / scale:g} {name}"
    return f"{x:g}" + ("" if unit == "1" else f" {unit}")


def _outside(what: str, value: float, unit: str, lo: float, hi: float, why: str) -> str:
    """The message of a value outside [lo, hi] (the value to six digits: 10.1 is not 10)."""
    shown = f"{value:.6g}" + ("" if unit == "1" else f" {unit}")
    return f"{what} {shown} is outside {_amount(lo, unit)} .. {_amount(hi, unit)}: {why}"


def _fmt(x: float) -> str:
    return f"{x:.3g}"


def line_problems(line) -> list[tuple[str, str, str]]:
    """Plausibility of a validated :class:`r2rsim.schema.line.Line`:
    ``[(level, yaml_path, message), ...]``, errors and warnings in file order."""
    out: list[tuple[str, str, str]] = []

    def err(path, msg):
        out.append((ERROR, path, msg))

    def warn(path, msg):
        out.append((WARNING, path, msg))

    for check in (
        _web_properties,
        _web_wraps,
        _web_strength,
        _roll_sizes,
        _span_lengths,
        _frictions,
        _wound_in_strains,
        _sensor_values,
        _dancer_setpoints,
    ):
        check(line, err, warn)
    # tension set-points
    for j, c in enumerate(line.controllers):
        if c.type == "tension_pi":
            out += tension_problems(line, c.setpoint, f"controllers[{j}].setpoint", c.id)
    out += magnitude_problems(line, {path for level, path, _ in out if level == ERROR})
    if not any(level == ERROR for level, _, _ in out):  # the loop estimates need a sane web
        out += controller_problems(line)
    return out


def _web_properties(line, err, warn) -> None:
    """Modulus, density, thickness and width against the range of real webs."""
    web = line.web
    if web.modulus > MODULUS_MAX:
        err(
            "web.modulus",
            f"{_fmt(web.modulus)} Pa is stiffer than diamond (1.2e12 Pa), the "
            "stiffest solid; web moduli are 3-130 GPa (physics.md §2.1)",
        )
    elif not MODULUS_RANGE[0] <= web.modulus <= MODULUS_RANGE[1]:
        warn(
            "web.modulus",
            f"{_fmt(web.modulus)} Pa is outside the range of webs (10 MPa to "
            "450 GPa; physics.md §2.1: 3-130 GPa)",
        )
    if web.density > DENSITY_MAX:
        err(
            "web.density",
            f"{_fmt(web.density)} kg/m^3 is denser than osmium (22 590 kg/m^3), "
            "the densest element",
        )
    elif not DENSITY_RANGE[0] <= web.density <= DENSITY_RANGE[1]:
        warn(
            "web.density",
            f"{_fmt(web.density)} kg/m^3 is outside the range of webs (100 to "
            "20 000 kg/m^3; physics.md §2.1: 600-8960)",
        )
    if not THICKNESS_RANGE[0] <= web.thickness <= THICKNESS_RANGE[1]:
        warn(
            "web.thickness",
            f"{_fmt(web.thickness * 1e6)} µm is outside the range of webs "
            "(1 µm to 5 mm; physics.md §2.1: 6-250 µm)",
        )
    if not WIDTH_RANGE[0] <= web.width <= WIDTH_RANGE[1]:
        warn(
            "web.width",
            f"{_fmt(web.width)} m is outside the range of webs (10 mm to 12 m; "
            "physics.md §2.1: 0.3-10 m)",
        )


def _web_wraps(line, err, warn) -> None:
    """The web must be thin compared with the smallest radius it wraps."""
    web, els = line.web, line.elements
    radii = []  # (radius, path) of everything the web wraps
    for i, e in enumerate(els):
        smallest = kind_of(e).smallest_radius(e)
        if smallest is not None:
            radii.append((smallest[0], f"elements[{i}].{smallest[1]}"))
    if radii:
        r_min, where = min(radii)
        if web.thickness >= r_min:
            err(
                "web.thickness",
                f"a web {_fmt(web.thickness)} m thick cannot wrap a roller of "
                f"radius {_fmt(r_min)} m ({where}): a web is thin compared with its rollers "
                "(physics.md §2.1: 6-250 µm)",
            )


def _web_strength(line, err, warn) -> None:
    """Break stress: given (or said to be absent), and within what solids can bear."""
    web = line.web
    if web.break_stress is None:
        if web.breakable:
            warn(
                "web.break_stress",
                "not given, and no material preset gives one: the web "
                "can never break in this simulation, whatever its tension; give break_stress "
                "(physics.md §2.1: PET 210 MPa, paper ~27 MPa, aluminium 100 MPa), or "
                "breakable: false to say so",
            )
    elif web.break_stress > BREAK_STRESS_MAX:
        err(
            "web.break_stress",
            f"{_fmt(web.break_stress)} Pa is above the ideal strength of "
            "graphene (~1.3e11 Pa); web break stresses are 27-400 MPa (physics.md §2.1)",
        )
    elif web.break_stress / web.modulus > BREAK_STRAIN_MAX:
        warn(
            "web.break_stress",
            f"the web would stretch by {web.break_stress / web.modulus:.0%}"
            " before it breaks (break_stress / modulus): the linear-elastic span model "
            "T = EA·strain is not meant for that",
        )


def _roll_sizes(line, err, warn) -> None:
    """Every roll (and spare roll) holds at least one wrap of web."""
    web, els = line.web, line.elements
    for i, e in enumerate(els):
        for key in ("roll", "spare_roll"):
            roll = getattr(e, key, None)
            if roll is None:
                continue
            cw = roll.build_per_wrap or web.thickness
            if roll.core_radius < roll.outer_radius and cw >= roll.outer_radius - roll.core_radius:
                warn(
                    f"elements[{i}].{key}.outer_radius",
                    f"the roll holds less than one wrap of web ({_fmt(cw)} m per wrap between "
                    f"radii {_fmt(roll.core_radius)} and {_fmt(roll.outer_radius)} m): it is "
                    "empty at once",
                )


def _span_lengths(line, err, warn) -> None:
    """Free spans between 1 mm (an error: too stiff to integrate) and the range of lines."""
    web = line.web
    for i, sp in enumerate(line.spans):
        if sp.length is None:
            continue
        if sp.length < SPAN_MIN:
            err(
                f"spans[{i}].length",
                f"a free span of {_fmt(sp.length)} m is shorter than "
                "1 mm: spans run between roller surfaces (nip and S-wrap spans are 30-300 mm, "
                "physics.md §2.2), and the model cannot integrate a span this stiff "
                f"(EA/L = {_fmt(web.EA / sp.length)} N/m)",
            )
        elif sp.length > SPAN_MAX:
            err(
                f"spans[{i}].length",
                _outside(
                    "span length",
                    sp.length,
                    "m",
                    SPAN_MIN,
                    SPAN_MAX,
                    "the longest free spans (dryer and oven spans) are ~30 m",
                ),
            )
        elif not SPAN_RANGE[0] <= sp.length <= SPAN_RANGE[1]:
            warn(
                f"spans[{i}].length",
                f"{_fmt(sp.length)} m is outside the range of free "
                "spans (10 mm to 100 m; physics.md §2.2: 0.03-30 m)",
            )


def _frictions(line, err, warn) -> None:
    for i, e in enumerate(line.elements):
        for where, f in kind_of(e).frictions(e):
            for key, value, unit in (
                ("coulomb", f.coulomb, "N m"),
                ("viscous", f.viscous, "N m s"),
            ):
                if value > TORQUE_MAX:
                    err(
                        f"elements[{i}].{where}.{key}",
                        f"{_fmt(value)} {unit} is beyond any "
                        f"bearing (at most {_fmt(TORQUE_MAX)} {unit})",
                    )


def _wound_in_strains(line, err, warn) -> None:
    for i, e in enumerate(line.elements):
        for key in ("roll", "spare_roll"):
            roll = getattr(e, key, None)
            if roll is None:
                continue
            e0, e1, e2 = roll.wound_in_coefficients()
            for R in (roll.core_radius, roll.outer_radius):
                strain = e0 + e1 * R + e2 * R * R
                if abs(strain) >= WOUND_IN_STRAIN_MAX:
                    err(
                        f"elements[{i}].{key}.wound_in_strain",
                        f"a wound-in strain of "
                        f"{_fmt(strain)} at R = {_fmt(R)} m: at a strain of "
                        f"{WOUND_IN_STRAIN_MAX:g} or more Hooke's law no longer describes "
                        "the web",
                    )
                    break


def _sensor_values(line, err, warn) -> None:
    for i, s in enumerate(line.sensors):
        p = f"sensors[{i}]"
        if not GAIN_RANGE[0] <= s.gain <= GAIN_RANGE[1]:
            err(
                f"{p}.gain",
                f"a calibration gain of {_fmt(s.gain)} is not a calibration "
                f"(from {GAIN_RANGE[0]:g} to {GAIN_RANGE[1]:g}; a sensor.gain fault models a "
                "gain error)",
            )
        for key, value in (
            ("noise", s.noise),
            ("offset", abs(s.offset)),
            ("noise_per_speed", s.noise_per_speed * SPEED_MAX),
        ):
            if value > READING_MAX:
                err(
                    f"{p}.{key}",
                    f"{_fmt(getattr(s, key))} is beyond any sensor's reading "
                    f"(at most {READING_MAX:g} in the reading's SI unit"
                    + (f", at {SPEED_MAX:g} m/s" if key == "noise_per_speed" else "")
                    + ")",
                )
        if 0.0 < s.quantization < QUANTIZATION_MIN:
            err(
                f"{p}.quantization",
                f"{_fmt(s.quantization)} is finer than any instrument "
                f"(0, for none, or at least {QUANTIZATION_MIN:g})",
            )
        if s.type == "pitch_length":
            L0 = s.relaxed_pitch if s.relaxed_pitch is not None else s.relaxed_pitch_law.q0
            key = "relaxed_pitch" if s.relaxed_pitch is not None else "relaxed_pitch_law.q0"
            if L0 > SPAN_RANGE[1]:
                err(
                    f"{p}.{key}",
                    f"a relaxed pitch of {_fmt(L0)} m is longer than any span "
                    f"({SPAN_RANGE[1]:g} m)",
                )
            elif s.relaxed_pitch_law is not None:
                _pitch_law(line, s, p, err)


def _pitch_law(line, s, p, err) -> None:
    """The relaxed pitch L0(R) = q0 + q1·R³ stays shorter than any span over the rolls of its
    unwind (a huge q1 passed the positivity check of the schema)."""
    from .line import pitch_unwind  # the schema imports this module

    law = s.relaxed_pitch_law
    e = next((e for e in line.elements if e.id == pitch_unwind(line, s)), None)
    if e is None or not kind_of(e).pays_out:
        return  # reported by the schema
    for roll in [e.roll] + ([e.spare_roll] if e.spare_roll is not None else []):
        for R in (roll.core_radius, roll.outer_radius):
            L0 = law.q0 + law.q1 * R**3
            if L0 > SPAN_RANGE[1]:
                err(
                    f"{p}.relaxed_pitch_law.q1",
                    f"a relaxed pitch of {_fmt(L0)} m at R = "
                    f"{_fmt(R)} m of '{e.id}' (q0 + q1·R³) is longer than any span "
                    f"({SPAN_RANGE[1]:g} m)",
                )
                return


def _dancer_setpoints(line, err, warn) -> None:
    """A dancer loop's position set-point within the travel a carriage or arm can have."""
    units = {e.id: kind_of(e).coordinate_unit for e in line.elements}
    for j, c in enumerate(line.controllers):
        if c.type != "dancer_pi" or c.setpoint is None:
            continue
        hi, unit = (
            (MAGNITUDE_MAX["angle"][0], "rad")
            if units.get(c.dancer) == "rad"
            else (TRAVEL_MAX, "m")
        )
        if not -hi <= c.setpoint <= hi:
            err(
                f"controllers[{j}].setpoint",
                _outside(
                    "position set-point",
                    c.setpoint,
                    unit,
                    -hi,
                    hi,
                    "beyond the travel of "
                    "any dancer or festoon (an arm angle within one turn, a stroke of at most "
                    "30 m)",
                ),
            )


#: bounds of particular fields (by field name, in any model), before MAGNITUDE_MAX:
#: (what, low, high, why)
_RADIUS = (
    "radius",
    *RADIUS_LIMITS,
    "rollers and rolls run from ~5 mm (tape lines) to ~3.4 m (Yankee dryers)",
)
_TRAVEL = (
    "travel",
    -TRAVEL_MAX,
    TRAVEL_MAX,
    "no carriage travels further than the longest span (real strokes are 0.1-30 m)",
)
FIELD_BOUNDS: dict[str, tuple[str, float, float, str]] = {
    "radius": _RADIUS,
    "core_radius": _RADIUS,
    "outer_radius": _RADIUS,
    "trigger_radius": _RADIUS,
    "thickness": (
        "thickness",
        *THICKNESS_LIMITS,
        "webs run from ~1 µm (capacitor film) to ~25 mm (steel strip)",
    ),
    "build_per_wrap": (
        "build per wrap",
        *THICKNESS_LIMITS,
        "the range of web thicknesses, ~1 µm (capacitor film) to ~25 mm (steel strip)",
    ),
    "width": ("width", 0.0, WIDTH_MAX, "the widest paper machines make ~11 m"),
    "friction_coefficient": (
        "friction coefficient",
        0.0,
        FRICTION_COEFFICIENT_MAX,
        "rubber-covered rollers reach 1-2",
    ),
    "travel_range": _TRAVEL,
    "initial_travel": _TRAVEL,
    "spring_free_travel": _TRAVEL,
    "stroke": _TRAVEL,
    "initial_position": _TRAVEL,
    "moving_rollers": ("moving_rollers", 1, FESTOON_ROLLERS_MAX, "festoons have up to a few tens"),
    "window": (
        "counting window",
        ENCODER_WINDOW_MIN,
        MAX_DURATION_S,
        "one count in the window reads 2π/(counts_per_rev·window)",
    ),
    "direction": (
        "direction component",
        -1.0e3,
        1.0e3,
        "a direction is normalised: give a unit vector",
    ),
}
#: fields with a bound of their own elsewhere: sensor readings (READING_MAX), calibration
#: gains, tension set-points (tension_problems), dancer set-points, wound-in strains
_OWN_BOUNDS = frozenset({"noise", "offset", "gain", "setpoint", "wound_in_strain"})


@functools.cache
def _field_info(model: type[BaseModel], name: str) -> tuple[str | None, str, bool]:
    """(dimension, SI unit, non-negative) of a field of a schema model, from its annotation:
    the ``x-dimension`` of its quantity type (:mod:`r2rsim.schema.quantities`; None for a
    plain number) and whether a ``ge``/``gt`` bound keeps it at or above 0."""
    found: dict = {"dim": None, "unit": "1", "nonneg": False}

    def visit(ann, meta):
        for m in meta:
            if isinstance(m, WithJsonSchema) and "x-dimension" in (m.json_schema or {}):
                if found["dim"] is None:
                    found["dim"], found["unit"] = (
                        m.json_schema["x-dimension"],
                        m.json_schema["x-unit"],
                    )
            elif isinstance(m, annotated_types.Gt | annotated_types.Ge):
                bound = m.gt if isinstance(m, annotated_types.Gt) else m.ge
                found["nonneg"] = found["nonneg"] or bound >= 0
            elif hasattr(m, "metadata") and isinstance(m.metadata, list):  # a FieldInfo
                visit(None, m.metadata)
        if typing.get_origin(ann) is typing.Annotated:
            args = typing.get_args(ann)
            visit(args[0], args[1:])
        elif ann is not None and typing.get_origin(ann) is not dict:
            for a in typing.get_args(ann):
                visit(a, ())
        elif ann is not None:  # a mapping: its values (the keys are ids)
            visit(typing.get_args(ann)[1], ())

    f = model.model_fields[name]
    visit(f.annotation, f.metadata)
    return found["dim"], found["unit"], found["nonneg"]


def _numbers(value, path: str, model: type[BaseModel] | None = None, name: str = ""):
    """``(yaml path, model, field name, number)`` of every number in a validated schema
    model, recursively; the items of a list or pair are reported at the field's path, the
    values of a mapping at ``path.key``."""
    if isinstance(value, BaseModel):
        for key in type(value).model_fields:
            yield from _numbers(
                getattr(value, key), f"{path}.{key}" if path else key, type(value), key
            )
    elif isinstance(value, dict):
        for k, v in value.items():
            yield from _numbers(v, f"{path}.{k}", model, name)
    elif isinstance(value, list | tuple):
        for i, v in enumerate(value):
            yield from _numbers(
                v, f"{path}[{i}]" if isinstance(v, BaseModel) else path, model, name
            )
    elif isinstance(value, int | float) and not isinstance(value, bool) and model is not None:
        yield path, model, name, value


def magnitude_problems(model, reported: set[str] | None = None) -> list[tuple[str, str, str]]:
    """Errors for every number of a validated line or scenario beyond :data:`FIELD_BOUNDS`
    (by field name) or :data:`MAGNITUDE_MAX` (by dimension); a path in ``reported`` (already
    refused by another check) is skipped, and so are the fields of :data:`_OWN_BOUNDS`."""
    reported = set(reported or ())
    out = []
    for path, cls, name, v in _numbers(model, ""):
        if path in reported or name in _OWN_BOUNDS:
            continue
        dim, unit, nonneg = _field_info(cls, name)
        if name in FIELD_BOUNDS:
            what, lo, hi, why = FIELD_BOUNDS[name]
        elif dim in MAGNITUDE_MAX:
            hi, why = MAGNITUDE_MAX[dim]
            what, lo = dim, (0.0 if nonneg else -hi)
        else:
            continue
        if not lo <= v <= hi:
            out.append((ERROR, path, _outside(what, v, unit, lo, hi, why)))
            reported.add(path)
    return out


def _torque_mode_roll(line, controller_id: str | None):
    """The unwind or rewind a tension loop commands the torque of, when its drive saturates
    (``torque_max``); else None."""
    c = next((c for c in line.controllers if c.id == controller_id), None)
    if c is None or c.type != "tension_pi":
        return None
    e = next((e for e in line.elements if e.id == c.element), None)
    drive = getattr(e, "drive", None)
    if (
        e is None
        or not kind_of(e).is_roll
        or drive is None
        or drive.type != "torque"
        or drive.torque_max is None
        or getattr(e, "roll", None) is None
    ):
        return None
    if any(o.type == "speed_pi" and o.element == e.id for o in line.controllers):
        return None  # a speed trim: the tension comes from the draw, not from this torque
    return e


def _break_by_torque(line, tension: float, controller_id: str | None) -> str:
    """What a tension set-point above the break tension does, when the loop commands the
    torque of a roll: the drive holds at most torque_max / R (the tension of a static
    balance of the roll; accelerating its inertia adds to it), so the web breaks only if
    that reaches the break tension at a radius the roll passes through."""
    T_break = line.web.break_tension
    e = _torque_mode_roll(line, controller_id)
    if e is None:
        return ": the web breaks"
    tau, r0, core = e.drive.torque_max, e.roll.outer_radius, e.roll.core_radius
    held0 = tau / r0
    why = (
        f"'{controller_id}' commands the torque of '{e.id}', whose torque_max "
        f"{_fmt(tau)} N m holds at most torque_max / R = {_fmt(held0)} N at its starting "
        f"radius {_fmt(r0)} m"
    )
    if held0 >= T_break:
        return ": the web breaks"
    if kind_of(e).pays_out and tau / core >= T_break:
        return (
            f": the web breaks only once the roll has unwound to a radius of "
            f"{_fmt(tau / T_break)} m (torque_max / break tension): {why}"
        )
    if kind_of(e).pays_out:
        why += f" and {_fmt(tau / core)} N at its core radius {_fmt(core)} m"
    else:
        why += " (less as the roll grows)"
    return (
        f", but the web does not break: {why}; the drive saturates and the tension stays "
        "below the set-point and the break tension (the dynamic tension of accelerating "
        "the roll aside)"
    )


def tension_problems(
    line, tension: float, path: str, controller_id: str | None = None
) -> list[tuple[str, str, str]]:
    """A tension set-point or initial tension against the web's break tension and EA; a
    set-point of ``controller_id`` above the break tension also against what its drive can
    hold (:func:`_break_by_torque`)."""
    web = line.web
    if tension > FORCE_MAX:
        return [
            (
                ERROR,
                path,
                _outside(
                    "tension",
                    tension,
                    "N",
                    0.0,
                    FORCE_MAX,
                    "film and paper lines run at 0.1-20 kN, steel strip at up to ~1 MN",
                ),
            )
        ]
    out = []
    if tension > web.break_tension:
        out.append(
            (
                WARNING,
                path,
                f"{_fmt(tension)} N is above the web's break tension "
                f"{_fmt(web.break_tension)} N (break_stress x thickness x width)"
                f"{_break_by_torque(line, tension, controller_id)}",
            )
        )
    if 0 < tension / web.EA < STRAIN_RESOLUTION:
        out.append(
            (
                WARNING,
                path,
                f"{_fmt(tension)} N stretches the web by only "
                f"{tension / web.EA:.1e} (T/EA, EA = {_fmt(web.EA)} N): below 1e-9 the span "
                "states cannot resolve the tension, which becomes rounding noise",
            )
        )
    return out


def _sensor_spans(line, sensor_id: str) -> list[float]:
    """Lengths of the spans a tension sensor reads (the spans next to its roller)."""
    s = next((s for s in line.sensors if s.id == sensor_id), None)
    if s is None:
        return []
    if s.type == "pitch_length":
        return [sp.length for sp in line.spans if sp.id == s.span and sp.length]
    k = next((k for k, e in enumerate(line.elements) if e.id == s.element), None)
    if k is None:
        return []
    return [
        line.spans[i].length
        for i in (k - 1, k)
        if 0 <= i < len(line.spans) and line.spans[i].length
    ]


def controller_problems(line) -> list[tuple[str, str, str]]:
    """Each loop's rate estimated from its gains and plant (physics.md §1.10 design rules):
    speed PI kp/J; speed-trim tension PI kp·EA/L; torque-mode tension PI sqrt(kp)·ω_n
    (eq. 1.23); dancer loop kp/2 (two spans). Integral gains count as their PI corner."""
    out = []
    web = line.web
    by_id = {e.id: e for e in line.elements}
    speed_ctrl = {c.element for c in line.controllers if c.type == "speed_pi"}
    for j, c in enumerate(line.controllers):
        p = f"controllers[{j}]"
        e = by_id.get(c.element)
        kp, ki = abs(c.kp), c.ki
        rates, kind, limit, why = None, "", None, ""  # rates: (from kp, from ki)
        if c.type == "speed_pi" and e is not None:
            J = kind_of(e).drive_inertia(e, web)
            if J:
                rates = (kp / J, math.sqrt(ki / J))
                kind = f"speed loop (kp/J, J = {_fmt(J)} kg m^2)"
                lag = getattr(getattr(e, "drive", None), "torque_lag", 0.0)
                if lag > 0:
                    limit, why = (
                        SPEED_OVER_TORQUE / lag,
                        f"ten times its drive's torque loop (1/torque_lag = {_fmt(1 / lag)} rad/s)",
                    )
        elif c.type == "tension_pi" and e is not None:
            lengths = _sensor_spans(line, c.sensor)
            L = min(lengths) if lengths else None
            roll = kind_of(e).is_roll
            torque_mode = (
                roll
                and getattr(e, "drive", None) is not None
                and e.drive.type == "torque"
                and c.element not in speed_ctrl
            )
            if L and torque_mode:
                R, J = kind_of(e).surface_radius(e), roll_inertia(e.roll, web)
                wn = R * math.sqrt(web.EA / (J * L))
                rates = (math.sqrt(kp) * wn, (ki * wn * wn) ** (1 / 3))
                kind = f"torque-mode tension loop (sqrt(kp)·ω_n, ω_n = {_fmt(wn)} rad/s)"
            elif L:
                g = web.EA / L
                rates = (kp * g, math.sqrt(ki * g))
                kind = f"speed-trim tension loop (kp·EA/L, EA/L = {_fmt(g)} N/m)"
            limit, why = (
                TRIM_RATE_WARN,
                "the speed loops it trims (10-50 Hz; tension loops "
                "run at 0.5-5 Hz, physics.md §1.10)",
            )
        elif c.type == "dancer_pi":
            rates = (kp / 2, math.sqrt(ki / 2))
            kind = "dancer loop (kp/2)"
            limit, why = (
                TRIM_RATE_WARN,
                "the speed loops it trims (10-50 Hz; dancer loops "
                "run at 0.5-5 Hz, physics.md §1.10)",
            )
        aw = c.anti_windup_gain
        if aw is not None and aw > LOOP_RATE_MAX:
            out.append(
                (
                    ERROR,
                    f"{p}.anti_windup_gain",
                    f"{_fmt(aw)} 1/s is faster than any loop ({_fmt(LOOP_RATE_MAX)} rad/s at most)",
                )
            )
        if rates is None:
            continue
        rate = max(rates)
        key = "kp" if rates[0] >= rates[1] else "ki"
        if rate > LOOP_RATE_MAX:
            out.append(
                (
                    ERROR,
                    f"{p}.{key}",
                    f"these gains (kp {_fmt(c.kp)}, ki {_fmt(ki)}) make "
                    f"a {kind} of about {_fmt(rate)} rad/s, above "
                    f"{_fmt(LOOP_RATE_MAX)} rad/s (160 kHz): no drive is that fast (current "
                    "loops run at 0.5-2 kHz, physics.md §1.10), and the solver would need "
                    "sub-microsecond steps",
                )
            )
        elif limit is not None and rate > limit:
            out.append(
                (
                    WARNING,
                    f"{p}.{key}",
                    f"these gains (kp {_fmt(c.kp)}, ki {_fmt(ki)}) "
                    f"make a {kind} of about {_fmt(rate)} rad/s, faster than {why}: expect "
                    "oscillation or a very slow run",
                )
            )
    return out


def scenario_problems(scenario, line) -> list[tuple[str, str, str]]:
    """Plausibility of a validated scenario against its line: line speeds against the web's
    wave speed, tension set-points and initial tensions against the break tension."""
    out = []
    web = line.web
    wave = math.sqrt(web.modulus / web.density)
    for i, st in enumerate(scenario.programme):
        p = f"programme[{i}]"
        if st.line_speed is not None:
            v = abs(st.line_speed)
            if v >= wave:
                out.append(
                    (
                        ERROR,
                        f"{p}.line_speed",
                        f"{_fmt(st.line_speed)} m/s is faster "
                        f"than the web's longitudinal wave speed sqrt(E/rho) = {_fmt(wave)} "
                        "m/s: the span model assumes the web moves far slower than its "
                        "strain waves (physics.md §2.1)",
                    )
                )
            elif v > LINE_SPEED_LIMIT:
                out.append(
                    (
                        ERROR,
                        f"{p}.line_speed",
                        _outside(
                            "line speed",
                            st.line_speed,
                            "m/s",
                            -LINE_SPEED_LIMIT,
                            LINE_SPEED_LIMIT,
                            "the fastest web lines (paper machines, slitter-rewinders) run "
                            "at 35-50 m/s",
                        ),
                    )
                )
            elif v > SPEED_MAX:
                out.append(
                    (
                        WARNING,
                        f"{p}.line_speed",
                        f"{_fmt(st.line_speed)} m/s is faster "
                        "than any line in physics.md §2.2 (paper machines: 15-35 m/s)",
                    )
                )
        for cid, T in (st.tension or {}).items():
            out += tension_problems(line, T, f"{p}.tension.{cid}", cid)
    init = scenario.initial
    if init.tension is not None:
        out += [
            (
                lvl,
                path,
                msg + ("" if "break tension" not in msg else " at t = 0 (the run ends there)"),
            )
            for lvl, path, msg in tension_problems(line, init.tension, "initial.tension")
        ]
    for sid, T in init.span_tension.items():
        out += tension_problems(line, T, f"initial.span_tension.{sid}")
    out += disturbance_problems(scenario)
    return out + magnitude_problems(scenario, {path for level, path, _ in out if level == ERROR})


def disturbance_problems(scenario) -> list[tuple[str, str, str]]:
    """Disturbances beyond physics, and two eccentricities of one roller (which would not
    say what they do together)."""
    out = []
    eccentric: dict[str, int] = {}
    for i, d in enumerate(scenario.disturbances):
        p = f"disturbances[{i}]"
        if d.type == "out_of_round":
            if d.element in eccentric:
                out.append(
                    (
                        ERROR,
                        f"{p}.element",
                        f"'{d.element}' is already out of round "
                        f"(disturbances[{eccentric[d.element]}]): give one eccentricity",
                    )
                )
            eccentric.setdefault(d.element, i)
            continue
        try:
            std = d.std_si()
        except ValueError:  # a bad unit: the loader reports it with its path
            continue
        if d.type == "bearing_drag" and std > TORQUE_MAX:
            out.append(
                (
                    ERROR,
                    f"{p}.std",
                    f"a drag torque of {_fmt(std)} N m is beyond any "
                    f"bearing (at most {_fmt(TORQUE_MAX)} N m)",
                )
            )
        if d.type == "wound_in_strain" and 4 * std >= WOUND_IN_STRAIN_MAX:
            out.append(
                (
                    ERROR,
                    f"{p}.std",
                    f"a wound-in strain of std {_fmt(std)} reaches "
                    f"{WOUND_IN_STRAIN_MAX:g} within 4 standard deviations, where Hooke's "
                    "law no longer describes the web",
                )
            )
    return out
