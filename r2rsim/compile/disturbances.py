"""Process disturbances of one run (the scenario's ``disturbances``), drawn from the run's
process-noise stream on fixed grids, so that they depend neither on the solver's steps nor
on the measurement noise. The compiler lowers them into tables the kernel interpolates."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..limits import MAX_SAMPLES, wound_in_strain_points


@dataclass
class DisturbanceInstance:
    """One realised disturbance: a table ``values`` on the grid ``x0 + k·dx`` (time for a
    bearing drag [s], unwound web length for a wound-in strain [m]), or an out-of-round
    roller (``eccentricity`` [m] and initial ``phase`` [rad])."""

    type: str
    element: str
    x0: float = 0.0
    dx: float = 1.0
    values: np.ndarray | None = None
    eccentricity: float = 0.0
    phase: float = 0.0


def _ar1(rng, n: int, a: float, std: float) -> np.ndarray:
    """A stationary first-order autoregressive sequence (filtered white noise) of standard
    deviation std and lag-one correlation a."""
    e = rng.standard_normal(n)
    x = np.empty(n)
    x[0] = std * e[0]
    s = std * math.sqrt(max(1.0 - a * a, 0.0))
    for k in range(1, n):
        x[k] = a * x[k - 1] + s * e[k]
    return x


def realise_disturbances(scenario, line, seed_sequence) -> list[DisturbanceInstance]:
    """Draw the run's process disturbances.

    Parameters
    ----------
    scenario : Scenario
    line : Line
    seed_sequence : numpy.random.SeedSequence
        The run's process-noise stream; each disturbance draws from its own child.
    """
    out = []
    children = seed_sequence.spawn(len(scenario.disturbances))
    rate = scenario.record_rate
    speeds = [abs(s.line_speed) for s in scenario.programme if s.line_speed is not None]
    v_max = max(speeds, default=0.0)
    for d, child in zip(scenario.disturbances, children, strict=True):
        rng = np.random.default_rng(child)
        if d.type == "out_of_round":
            out.append(DisturbanceInstance(d.type, d.element, eccentricity=d.eccentricity,
                                           phase=float(rng.uniform(0.0, 2.0 * math.pi))))
        elif d.type == "bearing_drag":
            # on the sample grid; first-order filter of the given bandwidth
            n = int(math.ceil(scenario.duration * rate)) + 2
            a = math.exp(-2.0 * math.pi * d.bandwidth / rate)
            out.append(DisturbanceInstance(d.type, d.element, 0.0, 1.0 / rate,
                                           _ar1(rng, n, a, d.std_si())))
        else:  # wound_in_strain along the web, ten points per correlation length
            dx = d.correlation_length / 10.0
            if wound_in_strain_points(v_max, scenario.duration, d.correlation_length) > \
                    MAX_SAMPLES:  # checked at load; again for a --duration override
                raise InputError(f"a correlation length of {d.correlation_length:g} m needs a "
                                 f"table of more than {MAX_SAMPLES:.0e} points over this run",
                                 path="disturbances[].correlation_length")
            length = 1.5 * v_max * scenario.duration + 10.0 * d.correlation_length
            n = int(math.ceil(length / dx)) + 2
            out.append(DisturbanceInstance(d.type, d.element, 0.0, dx,
                                           _ar1(rng, n, math.exp(-0.1), d.std_si())))
    return out


#: cosines of a realised relaxed-pitch variation (pitch_length ``pitch_variation``)
PITCH_VARIATION_TERMS = 64


def realise_pitch_variations(line, seed_sequence) -> dict[str, np.ndarray]:
    """Draw the relaxed-pitch (printing) variation of every pitch_length sensor that declares
    one.

    The variation of the relaxed pitch along the web is the band-limited sum
    ``sum_m a·cos(kappa_m·u + phi_m)`` of :data:`PITCH_VARIATION_TERMS` cosines in the
    unwound length u [m], with ``a = std·sqrt(2/M)`` (its variance over a long record is
    exactly ``std²``), uniform phases and wavenumbers kappa_m = sqrt(2)·z_m/ℓ, z_m drawn
    stratified from the half-normal distribution (one per probability stratum), so that its
    correlation ``mean_m cos(kappa_m·Δ)`` follows ``exp(-(Δ/ℓ)²)`` closely. It is smooth (no
    knots for the stiff solver to resolve).

    Parameters
    ----------
    line : Line
    seed_sequence : numpy.random.SeedSequence
        The run's process-noise stream; spawned once more (one child per such sensor, after
        the disturbances' children), so the disturbances stay as they were.

    Returns
    -------
    dict
        Sensor id -> array (M, 3) of (amplitude [m], wavenumber [rad/m], phase [rad]).
    """
    from statistics import NormalDist

    sensors = [s for s in line.sensors
               if s.type == "pitch_length" and s.pitch_variation is not None]
    children = seed_sequence.spawn(len(sensors))
    inv = NormalDist().inv_cdf
    m_terms = PITCH_VARIATION_TERMS
    out = {}
    for s, child in zip(sensors, children, strict=True):
        rng = np.random.default_rng(child)
        pv = s.pitch_variation
        strata = (np.arange(m_terms) + rng.random(m_terms)) / m_terms
        z = np.array([inv(0.5 + 0.5 * min(p, 1.0 - 1e-12)) for p in strata])
        kappa = math.sqrt(2.0) * z / pv.correlation_length
        phase = rng.uniform(0.0, 2.0 * math.pi, m_terms)
        amp = np.full(m_terms, pv.std * math.sqrt(2.0 / m_terms))
        out[s.id] = np.column_stack([amp, kappa, phase])
    return out
