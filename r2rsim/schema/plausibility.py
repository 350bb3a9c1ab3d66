"""Plausibility of a valid line or scenario: is it physics, or a typo?

The schema checks that each value has the right type, unit and sign. Here they are checked
against the physics: a valid but absurd input (a web 1 m thick, a 1 nm span, a modulus of
1e20 Pa, a controller gain of 1e300) would otherwise run for minutes or hours, or return
tensions that are rounding noise, without a word. Two levels:

* **error** (:class:`r2rsim.errors.InputError`): physically impossible, or outside what the
  model can integrate: stiffer than diamond, denser than osmium, a web that cannot wrap its
  rollers, a span shorter than 1 mm, a line faster than the web's own wave speed, a loop
  faster than 160 kHz;
* **warning** (:class:`r2rsim.errors.PlausibilityWarning`): possible but far outside the
  ranges of ``physics.md`` §2 (the user may mean it: a 10 mm tape, a 60 m/s line), or a
  choice with a silent consequence (a web with no break stress never breaks, a set-point
  above the break tension breaks the web). ``r2rsim`` prints warnings as
  ``warning: file: path: message`` and runs on.

Each check is a ``(level, yaml_path, message)``; :func:`line_problems` and
:func:`scenario_problems` return them all, and the loader raises or warns.
"""

from __future__ import annotations

import math

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


def _roll_inertia(roll, web) -> float:
    """J(R) at the roll's starting radius (physics.md eq. 1.12), for order-of-magnitude use."""
    cw = roll.build_per_wrap or web.thickness
    rho_w = web.density * web.thickness / cw * web.width
    return roll.core_inertia + 0.5 * math.pi * rho_w * (roll.outer_radius ** 4
                                                        - roll.core_radius ** 4)


def _node_inertia(e, web) -> float | None:
    """Inertia the element's drive turns [kg m^2] (None for a dancer)."""
    if e.type in ("unwind", "rewind"):
        return _roll_inertia(e.roll, web)
    if e.type == "nip":
        pr = e.pressure_roller
        return e.inertia + pr.inertia * (e.radius / pr.radius) ** 2
    return getattr(e, "inertia", None)


def _radius(e) -> float | None:
    if e.type in ("unwind", "rewind"):
        return e.roll.outer_radius
    return getattr(e, "radius", None)


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

    for check in (_web_properties, _web_wraps, _web_strength, _roll_sizes, _span_lengths,
                  _frictions, _wound_in_strains, _sensor_values):
        check(line, err, warn)
    # tension set-points
    for j, c in enumerate(line.controllers):
        if c.type == "tension_pi":
            out += tension_problems(line, c.setpoint, f"controllers[{j}].setpoint")
    if not any(level == ERROR for level, _, _ in out):  # the loop estimates need a sane web
        out += controller_problems(line)
    return out


def _web_properties(line, err, warn) -> None:
    """Modulus, density, thickness and width against the range of real webs."""
    web = line.web
    if web.modulus > MODULUS_MAX:
        err("web.modulus", f"{_fmt(web.modulus)} Pa is stiffer than diamond (1.2e12 Pa), the "
            "stiffest solid; web moduli are 3-130 GPa (physics.md §2.1)")
    elif not MODULUS_RANGE[0] <= web.modulus <= MODULUS_RANGE[1]:
        warn("web.modulus", f"{_fmt(web.modulus)} Pa is outside the range of webs (10 MPa to "
             "450 GPa; physics.md §2.1: 3-130 GPa)")
    if web.density > DENSITY_MAX:
        err("web.density", f"{_fmt(web.density)} kg/m^3 is denser than osmium (22 590 kg/m^3), "
            "the densest element")
    elif not DENSITY_RANGE[0] <= web.density <= DENSITY_RANGE[1]:
        warn("web.density", f"{_fmt(web.density)} kg/m^3 is outside the range of webs (100 to "
             "20 000 kg/m^3; physics.md §2.1: 600-8960)")
    if not THICKNESS_RANGE[0] <= web.thickness <= THICKNESS_RANGE[1]:
        warn("web.thickness", f"{_fmt(web.thickness * 1e6)} µm is outside the range of webs "
             "(1 µm to 5 mm; physics.md §2.1: 6-250 µm)")
    if not WIDTH_RANGE[0] <= web.width <= WIDTH_RANGE[1]:
        warn("web.width", f"{_fmt(web.width)} m is outside the range of webs (10 mm to 12 m; "
             "physics.md §2.1: 0.3-10 m)")


def _web_wraps(line, err, warn) -> None:
    """The web must be thin compared with the smallest radius it wraps."""
    web, els = line.web, line.elements
    radii = []  # (radius, path) of everything the web wraps
    for i, e in enumerate(els):
        if e.type in ("unwind", "rewind"):
            radii.append((e.roll.core_radius, f"elements[{i}].roll.core_radius"))
        elif getattr(e, "radius", None) is not None:
            radii.append((e.radius, f"elements[{i}].radius"))
    if radii:
        r_min, where = min(radii)
        if web.thickness >= r_min:
            err("web.thickness", f"a web {_fmt(web.thickness)} m thick cannot wrap a roller of "
                f"radius {_fmt(r_min)} m ({where}): a web is thin compared with its rollers "
                "(physics.md §2.1: 6-250 µm)")


def _web_strength(line, err, warn) -> None:
    """Break stress: given (or said to be absent), and within what solids can bear."""
    web = line.web
    if web.break_stress is None:
        if web.breakable:
            warn("web.break_stress", "not given, and no material preset gives one: the web "
                 "can never break in this simulation, whatever its tension; give break_stress "
                 "(physics.md §2.1: PET 210 MPa, paper ~27 MPa, aluminium 100 MPa), or "
                 "breakable: false to say so")
    elif web.break_stress > BREAK_STRESS_MAX:
        err("web.break_stress", f"{_fmt(web.break_stress)} Pa is above the ideal strength of "
            "graphene (~1.3e11 Pa); web break stresses are 27-400 MPa (physics.md §2.1)")
    elif web.break_stress / web.modulus > BREAK_STRAIN_MAX:
        warn("web.break_stress", f"the web would stretch by {web.break_stress / web.modulus:.0%}"
             " before it breaks (break_stress / modulus): the linear-elastic span model "
             "T = EA·strain is not meant for that")


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
                warn(f"elements[{i}].{key}.outer_radius",
                     f"the roll holds less than one wrap of web ({_fmt(cw)} m per wrap between "
                     f"radii {_fmt(roll.core_radius)} and {_fmt(roll.outer_radius)} m): it is "
                     "empty at once")


def _span_lengths(line, err, warn) -> None:
    """Free spans between 1 mm (an error: too stiff to integrate) and the range of lines."""
    web = line.web
    for i, sp in enumerate(line.spans):
        if sp.length is None:
            continue
        if sp.length < SPAN_MIN:
            err(f"spans[{i}].length", f"a free span of {_fmt(sp.length)} m is shorter than "
                "1 mm: spans run between roller surfaces (nip and S-wrap spans are 30-300 mm, "
                "physics.md §2.2), and the model cannot integrate a span this stiff "
                f"(EA/L = {_fmt(web.EA / sp.length)} N/m)")
        elif not SPAN_RANGE[0] <= sp.length <= SPAN_RANGE[1]:
            warn(f"spans[{i}].length", f"{_fmt(sp.length)} m is outside the range of free "
                 "spans (10 mm to 100 m; physics.md §2.2: 0.03-30 m)")


def _frictions(line, err, warn) -> None:
    for i, e in enumerate(line.elements):
        frictions = [("friction", e.friction)]
        if e.type == "nip":
            frictions.append(("pressure_roller.friction", e.pressure_roller.friction))
        for where, f in frictions:
            for key, value, unit in (("coulomb", f.coulomb, "N m"),
                                     ("viscous", f.viscous, "N m s")):
                if value > TORQUE_MAX:
                    err(f"elements[{i}].{where}.{key}", f"{_fmt(value)} {unit} is beyond any "
                        f"bearing (at most {_fmt(TORQUE_MAX)} {unit})")


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
                    err(f"elements[{i}].{key}.wound_in_strain", f"a wound-in strain of "
                        f"{_fmt(strain)} at R = {_fmt(R)} m: at a strain of "
                        f"{WOUND_IN_STRAIN_MAX:g} or more Hooke's law no longer describes "
                        "the web")
                    break


def _sensor_values(line, err, warn) -> None:
    for i, s in enumerate(line.sensors):
        p = f"sensors[{i}]"
        if not GAIN_RANGE[0] <= s.gain <= GAIN_RANGE[1]:
            err(f"{p}.gain", f"a calibration gain of {_fmt(s.gain)} is not a calibration "
                f"(from {GAIN_RANGE[0]:g} to {GAIN_RANGE[1]:g}; a sensor.gain fault models a "
                "gain error)")
        for key, value in (("noise", s.noise), ("offset", abs(s.offset)),
                           ("noise_per_speed", s.noise_per_speed * SPEED_MAX)):
            if value > READING_MAX:
                err(f"{p}.{key}", f"{_fmt(getattr(s, key))} is beyond any sensor's reading "
                    f"(at most {READING_MAX:g} in the reading's SI unit"
                    + (f", at {SPEED_MAX:g} m/s" if key == "noise_per_speed" else "") + ")")
        if 0.0 < s.quantization < QUANTIZATION_MIN:
            err(f"{p}.quantization", f"{_fmt(s.quantization)} is finer than any instrument "
                f"(0, for none, or at least {QUANTIZATION_MIN:g})")
        if s.type == "pitch_length":
            L0 = s.relaxed_pitch if s.relaxed_pitch is not None else s.relaxed_pitch_law.q0
            key = "relaxed_pitch" if s.relaxed_pitch is not None else "relaxed_pitch_law.q0"
            if L0 > SPAN_RANGE[1]:
                err(f"{p}.{key}", f"a relaxed pitch of {_fmt(L0)} m is longer than any span "
                    f"({SPAN_RANGE[1]:g} m)")


def tension_problems(line, tension: float, path: str) -> list[tuple[str, str, str]]:
    """A tension set-point or initial tension against the web's break tension and EA."""
    web = line.web
    out = []
    if tension > web.break_tension:
        out.append((WARNING, path, f"{_fmt(tension)} N is above the web's break tension "
                    f"{_fmt(web.break_tension)} N (break_stress x thickness x width): the web "
                    "breaks"))
    if 0 < tension / web.EA < STRAIN_RESOLUTION:
        out.append((WARNING, path, f"{_fmt(tension)} N stretches the web by only "
                    f"{tension / web.EA:.1e} (T/EA, EA = {_fmt(web.EA)} N): below 1e-9 the span "
                    "states cannot resolve the tension, which becomes rounding noise"))
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
    return [line.spans[i].length for i in (k - 1, k)
            if 0 <= i < len(line.spans) and line.spans[i].length]


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
            J = _node_inertia(e, web)
            if J:
                rates = (kp / J, math.sqrt(ki / J))
                kind = f"speed loop (kp/J, J = {_fmt(J)} kg m^2)"
                lag = getattr(getattr(e, "drive", None), "torque_lag", 0.0)
                if lag > 0:
                    limit, why = SPEED_OVER_TORQUE / lag, \
                        f"ten times its drive's torque loop (1/torque_lag = {_fmt(1 / lag)} rad/s)"
        elif c.type == "tension_pi" and e is not None:
            lengths = _sensor_spans(line, c.sensor)
            L = min(lengths) if lengths else None
            roll = e.type in ("unwind", "rewind")
            torque_mode = roll and getattr(e, "drive", None) is not None and \
                e.drive.type == "torque" and c.element not in speed_ctrl
            if L and torque_mode:
                wn = _radius(e) * math.sqrt(web.EA / (_roll_inertia(e.roll, web) * L))
                rates = (math.sqrt(kp) * wn, (ki * wn * wn) ** (1 / 3))
                kind = f"torque-mode tension loop (sqrt(kp)·ω_n, ω_n = {_fmt(wn)} rad/s)"
            elif L:
                g = web.EA / L
                rates = (kp * g, math.sqrt(ki * g))
                kind = f"speed-trim tension loop (kp·EA/L, EA/L = {_fmt(g)} N/m)"
            limit, why = TRIM_RATE_WARN, "the speed loops it trims (10-50 Hz; tension loops " \
                                         "run at 0.5-5 Hz, physics.md §1.10)"
        elif c.type == "dancer_pi":
            rates = (kp / 2, math.sqrt(ki / 2))
            kind = "dancer loop (kp/2)"
            limit, why = TRIM_RATE_WARN, "the speed loops it trims (10-50 Hz; dancer loops " \
                                         "run at 0.5-5 Hz, physics.md §1.10)"
        aw = c.anti_windup_gain
        if aw is not None and aw > LOOP_RATE_MAX:
            out.append((ERROR, f"{p}.anti_windup_gain", f"{_fmt(aw)} 1/s is faster than any "
                        f"loop ({_fmt(LOOP_RATE_MAX)} rad/s at most)"))
        if rates is None:
            continue
        rate = max(rates)
        key = "kp" if rates[0] >= rates[1] else "ki"
        if rate > LOOP_RATE_MAX:
            out.append((ERROR, f"{p}.{key}", f"these gains (kp {_fmt(c.kp)}, ki {_fmt(ki)}) make "
                        f"a {kind} of about {_fmt(rate)} rad/s, above "
                        f"{_fmt(LOOP_RATE_MAX)} rad/s (160 kHz): no drive is that fast (current "
                        "loops run at 0.5-2 kHz, physics.md §1.10), and the solver would need "
                        "sub-microsecond steps"))
        elif limit is not None and rate > limit:
            out.append((WARNING, f"{p}.{key}", f"these gains (kp {_fmt(c.kp)}, ki {_fmt(ki)}) "
                        f"make a {kind} of about {_fmt(rate)} rad/s, faster than {why}: expect "
                        "oscillation or a very slow run"))
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
                out.append((ERROR, f"{p}.line_speed", f"{_fmt(st.line_speed)} m/s is faster "
                            f"than the web's longitudinal wave speed sqrt(E/rho) = {_fmt(wave)} "
                            "m/s: the span model assumes the web moves far slower than its "
                            "strain waves (physics.md §2.1)"))
            elif v > SPEED_MAX:
                out.append((WARNING, f"{p}.line_speed", f"{_fmt(st.line_speed)} m/s is faster "
                            "than any line in physics.md §2.2 (paper machines: 15-35 m/s)"))
        for cid, T in (st.tension or {}).items():
            out += tension_problems(line, T, f"{p}.tension.{cid}")
    init = scenario.initial
    if init.tension is not None:
        out += [(lvl, path, msg + ("" if "break tension" not in msg else
                                   " at t = 0 (the run ends there)"))
                for lvl, path, msg in tension_problems(line, init.tension, "initial.tension")]
    for sid, T in init.span_tension.items():
        out += tension_problems(line, T, f"initial.span_tension.{sid}")
    return out + disturbance_problems(scenario)


def disturbance_problems(scenario) -> list[tuple[str, str, str]]:
    """Disturbances beyond physics, and two eccentricities of one roller (which would not
    say what they do together)."""
    out = []
    eccentric: dict[str, int] = {}
    for i, d in enumerate(scenario.disturbances):
        p = f"disturbances[{i}]"
        if d.type == "out_of_round":
            if d.element in eccentric:
                out.append((ERROR, f"{p}.element", f"'{d.element}' is already out of round "
                            f"(disturbances[{eccentric[d.element]}]): give one eccentricity"))
            eccentric.setdefault(d.element, i)
            continue
        try:
            std = d.std_si()
        except ValueError:  # a bad unit: the loader reports it with its path
            continue
        if d.type == "bearing_drag" and std > TORQUE_MAX:
            out.append((ERROR, f"{p}.std", f"a drag torque of {_fmt(std)} N m is beyond any "
                        f"bearing (at most {_fmt(TORQUE_MAX)} N m)"))
        if d.type == "wound_in_strain" and 4 * std >= WOUND_IN_STRAIN_MAX:
            out.append((ERROR, f"{p}.std", f"a wound-in strain of std {_fmt(std)} reaches "
                        f"{WOUND_IN_STRAIN_MAX:g} within 4 standard deviations, where Hooke's "
                        "law no longer describes the web"))
    return out
