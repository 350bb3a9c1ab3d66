"""Process disturbances of one run (the scenario's ``disturbances``), drawn from the run's
process-noise stream, so that they depend neither on the solver's steps nor on the
measurement noise.

A random disturbance (``bearing_drag`` against time, ``wound_in_strain`` along the unwound
web) is, by default (``shape: sines``), a sum of :data:`N_SINES` sinusoids whose spectrum is
the first-order (Lorentzian) spectrum the scenario declares, cut off at :data:`CUTOFF` times
its corner frequency. It is smooth (every derivative exists), so a stiff solver need not
resolve grid knots. ``shape: table`` keeps the earlier form, a first-order autoregressive
table the kernel interpolates linearly, to reproduce data made with it.

The sum of sinusoids (the spectral representation with stratified random frequencies)::

    x(s) = sum_k a·sin(2·pi·f_k·s + phi_k),   a = std·sqrt(2/N),   k = 0 .. N-1

``s`` is time [s] for a bearing drag, unwound length [m] for a wound-in strain; ``f_c`` is
the corner: the ``bandwidth`` [Hz], or 1/(2·pi·correlation_length) [1/m]. The target is the
one-sided spectrum ``S(f) ∝ 1/(1 + (f/f_c)^2)`` of first-order filtered white noise
(autocorrelation ``std²·exp(-2·pi·f_c·|lag|)``: ``exp(-|lag|/correlation_length)`` along
the web), truncated at ``f_max = CUTOFF·f_c``. With ``theta = atan(f/f_c)`` that spectrum
is uniform in ``theta`` on ``[0, atan(CUTOFF)]``; the range is cut into N bins of equal
power and ``f_k = f_c·tan(theta_k)`` with ``theta_k`` uniform in bin k, so every term
carries the same power std²/N. Phases ``phi_k`` are uniform on [0, 2·pi).

* Band limit (``band_limit``, bearing drag only, optional): the terms above it are dropped
  after the draw, so the terms below are the ones the same seed gives without a limit (the
  band-limited run is the full run minus its high-frequency part) and the variance falls to
  std²·(terms kept)/N.
* Variance: sum a²/2 = std² exactly, so the mean square of every realisation over a long
  record is std² (not only its ensemble average). Over a record shorter than 1/f_c the
  sample std scatters, as for any first-order process.
* Spectrum: averaged over the draws of f_k, the autocorrelation is exactly that of the
  truncated spectrum, ``R(lag) = std²/atan(CUTOFF)·∫_0^atan(CUTOFF) cos(2·pi·f_c·tan(θ)·lag)
  dθ`` (:func:`autocorrelation`). The cut-off drops the 6.3 % of the first-order power above
  10·f_c (the variance is renormalised to std²): ``R`` at one time constant
  ``1/(2·pi·f_c)`` (one correlation length) is 0.360·std² against exp(-1) = 0.368·std², and
  ``R`` is smooth at lag 0 instead of having a cusp.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from ..errors import InputError
from ..limits import MAX_SAMPLES, wound_in_strain_points

#: Terms of one sum-of-sinusoids disturbance.
N_SINES = 32
#: Highest frequency of a sum-of-sinusoids disturbance, in corner frequencies.
CUTOFF = 10.0


@dataclass
class DisturbanceInstance:
    """One realised disturbance of a run.

    ``shape == "sines"``: ``amplitudes``, ``omegas`` (angular frequency: [rad/s] against
    time for a bearing drag, [rad/m] against unwound web length for a wound-in strain) and
    ``phases`` [rad] of the sum ``sum a·sin(omega·s + phase)``.
    ``shape == "table"``: a table ``values`` on the grid ``x0 + k·dx``.
    ``type == "out_of_round"``: an eccentric roller (``eccentricity`` [m] and initial
    ``phase`` [rad]).
    """

    type: str
    element: str
    shape: str = ""
    x0: float = 0.0
    dx: float = 1.0
    values: np.ndarray | None = None
    amplitudes: np.ndarray | None = None
    omegas: np.ndarray | None = None
    phases: np.ndarray | None = None
    eccentricity: float = 0.0
    phase: float = 0.0

    def value(self, s) -> np.ndarray | np.float64:
        """The disturbance at ``s`` (time or unwound length), as the kernel evaluates it.

        Parameters
        ----------
        s : float or array_like

        Returns
        -------
        ndarray
            (a numpy float for a scalar ``s``)
        """
        s = np.asarray(s, dtype=float)
        if self.shape == "sines":
            assert self.omegas is not None and self.phases is not None  # set with "sines"
            ph = np.multiply.outer(s, self.omegas) + self.phases
            return np.sin(ph) @ self.amplitudes
        if self.shape == "table":
            assert self.values is not None  # set with "table"
            grid = self.x0 + self.dx * np.arange(len(self.values))
            return np.interp(s, grid, self.values)
        raise ValueError(f"a {self.type} disturbance has no value")


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


def _sines(rng, std: float, f_c: float):
    """Amplitudes, angular frequencies and phases of a sum of :data:`N_SINES` sinusoids with
    the first-order spectrum of corner ``f_c`` cut off at ``CUTOFF·f_c`` (module docstring)."""
    return _spectral_terms(rng, N_SINES, std, "first_order", f_c)


def _spectral_terms(rng, n: int, std: float, spectrum: str, scale: float):
    """The ``n`` terms (amplitudes, angular frequencies, phases) of a random sum of
    sinusoids of standard deviation ``std``: equal amplitudes ``std·sqrt(2/n)`` (so the mean
    square of every realisation is std²), frequencies stratified over the spectrum's
    probability (one per stratum), uniform phases. The one representation behind the
    process disturbances and the pitch_length printing variation.

    ``spectrum``: ``"first_order"`` (the Lorentzian of corner ``scale`` = f_c, cut off at
    :data:`CUTOFF`·f_c: correlation close to exp(-2·pi·f_c·|lag|)), or ``"gaussian"``
    (``scale`` = ℓ: correlation exp(-(lag/ℓ)²), the angular frequency sqrt(2)·z/ℓ with z
    half-normal).
    """
    strata = np.arange(n) + rng.uniform(0.0, 1.0, n)
    if spectrum == "first_order":
        top = math.atan(CUTOFF)
        omegas = 2.0 * math.pi * scale * np.tan(strata * (top / n))
    else:
        inv = NormalDist().inv_cdf
        z = np.array([inv(0.5 + 0.5 * min(p, 1.0 - 1e-12)) for p in strata / n])
        omegas = math.sqrt(2.0) * z / scale
    phases = rng.uniform(0.0, 2.0 * math.pi, n)
    return np.full(n, std * math.sqrt(2.0 / n)), omegas, phases


def autocorrelation(lag, f_c: float, std: float = 1.0) -> np.ndarray:
    """Ensemble autocorrelation of a sum-of-sinusoids disturbance of corner ``f_c``.

    Parameters
    ----------
    lag : float or array_like
        Lag [s] (or [m] along the web).
    f_c : float
        Corner frequency: ``bandwidth`` [Hz], or ``1/(2·pi·correlation_length)`` [1/m].
    std : float

    Returns
    -------
    ndarray
        ``std²`` times the mean of ``cos(2·pi·f·lag)`` over the truncated spectrum.
    """
    top = math.atan(CUTOFF)
    theta = (np.arange(4000) + 0.5) * (top / 4000)  # midpoint rule in theta
    f = f_c * np.tan(theta)
    return (
        std
        * std
        * np.cos(2.0 * math.pi * np.multiply.outer(np.asarray(lag, float), f)).mean(axis=-1)
    )


def realise_disturbances(scenario, line, seed_sequence) -> list[DisturbanceInstance]:
    """Draw the run's process disturbances.

    Parameters
    ----------
    scenario : Scenario
    line : Line
    seed_sequence : numpy.random.SeedSequence
        The run's process-noise stream; each disturbance draws from its own child.

    Returns
    -------
    list of DisturbanceInstance
    """
    out = []
    children = seed_sequence.spawn(len(scenario.disturbances))
    rate = scenario.record_rate
    speeds = [abs(s.line_speed) for s in scenario.programme if s.line_speed is not None]
    v_max = max(speeds, default=0.0)
    for d, child in zip(scenario.disturbances, children, strict=True):
        rng = np.random.default_rng(child)
        if d.type == "out_of_round":
            out.append(
                DisturbanceInstance(
                    d.type,
                    d.element,
                    eccentricity=d.eccentricity,
                    phase=float(rng.uniform(0.0, 2.0 * math.pi)),
                )
            )
            continue
        shape = d.shape or "sines"  # the table form: to reproduce data made before issue 16
        if shape == "sines":
            f_c = (
                d.bandwidth
                if d.type == "bearing_drag"
                else 1.0 / (2.0 * math.pi * d.correlation_length)
            )
            a, w, ph = _sines(rng, d.std_si(), f_c)
            if d.band_limit is not None:  # the same terms, those above the limit dropped
                keep = w <= 2.0 * math.pi * d.band_limit
                a, w, ph = a[keep], w[keep], ph[keep]
            out.append(
                DisturbanceInstance(d.type, d.element, shape, amplitudes=a, omegas=w, phases=ph)
            )
        elif d.type == "bearing_drag":
            # on the sample grid; first-order filter of the given bandwidth
            n = int(math.ceil(scenario.duration * rate)) + 2
            a = math.exp(-2.0 * math.pi * d.bandwidth / rate)
            out.append(
                DisturbanceInstance(
                    d.type, d.element, shape, 0.0, 1.0 / rate, _ar1(rng, n, a, d.std_si())
                )
            )
        else:  # wound_in_strain along the web, ten points per correlation length
            dx = d.correlation_length / 10.0
            if (
                wound_in_strain_points(v_max, scenario.duration, d.correlation_length) > MAX_SAMPLES
            ):  # checked at load; again for a --duration override
                raise InputError(
                    f"a correlation length of {d.correlation_length:g} m needs a "
                    f"table of more than {MAX_SAMPLES:.0e} points over this run",
                    path="disturbances[].correlation_length",
                )
            length = 1.5 * v_max * scenario.duration + 10.0 * d.correlation_length
            n = int(math.ceil(length / dx)) + 2
            out.append(
                DisturbanceInstance(
                    d.type, d.element, shape, 0.0, dx, _ar1(rng, n, math.exp(-0.1), d.std_si())
                )
            )
    return out


#: cosines of a realised relaxed-pitch variation (pitch_length ``pitch_variation``)
PITCH_VARIATION_TERMS = 64
#: spawn key (under the run's process stream) of the pitch variations; far above the
#: disturbances' children, next to the variability stream's (r2rsim.compile.variability)
PITCH_VARIATION_KEY = (1 << 20) + 1


def realise_pitch_variations(line, seed_sequence) -> dict[str, np.ndarray]:
    """Draw the relaxed-pitch (printing) variation of every pitch_length sensor that declares
    one.

    The variation of the relaxed pitch along the web is the band-limited sum
    ``sum_m a·cos(kappa_m·u + phi_m)`` of :data:`PITCH_VARIATION_TERMS` cosines in the
    unwound length u [m], drawn as the disturbances' sums are (:func:`_spectral_terms`) with
    a Gaussian spectrum: ``a = std·sqrt(2/M)`` (its variance over a long record is exactly
    ``std²``), uniform phases and wavenumbers kappa_m = sqrt(2)·z_m/ℓ, z_m stratified from the
    half-normal distribution, so that its correlation ``mean_m cos(kappa_m·Δ)`` follows
    ``exp(-(Δ/ℓ)²)`` closely. It is smooth (no knots for the stiff solver to resolve).

    Parameters
    ----------
    line : Line
    seed_sequence : numpy.random.SeedSequence
        The run's process-noise stream; each such sensor draws from its own child at the
        fixed key (:data:`PITCH_VARIATION_KEY`, sensor index), never spawned, so neither the
        disturbances nor other sensors move it.

    Returns
    -------
    dict
        Sensor id -> array (M, 3) of (amplitude [m], wavenumber [rad/m], phase [rad]).
    """
    sensors = [
        (j, s)
        for j, s in enumerate(line.sensors)
        if s.type == "pitch_length" and s.pitch_variation is not None
    ]
    # a fixed spawn key per sensor (not the next spawn() after the disturbances'), so adding
    # a disturbance or another sensor does not change a sensor's variation
    ss = seed_sequence
    children = [
        np.random.SeedSequence(ss.entropy, spawn_key=(*ss.spawn_key, PITCH_VARIATION_KEY, j))
        for j, _ in sensors
    ]
    out = {}
    for (_, s), child in zip(sensors, children, strict=True):
        pv = s.pitch_variation
        amp, kappa, phase = _spectral_terms(
            np.random.default_rng(child),
            PITCH_VARIATION_TERMS,
            pv.std,
            "gaussian",
            pv.correlation_length,
        )
        out[s.id] = np.column_stack([amp, kappa, phase])
    return out
