"""Preprocessing (thesis §2.6: de-noising, smoothing differentiation, R1 = diameter/2) and
the per-stage physics regressors of eqs. 2.15-2.19, with signs from r2rsim's roller balance
``J·dω/dt = R·(T_out - T_in) + τ_m - b·ω`` (docs/model.md; the applied torque τ_m is
positive in the direction of web travel, so an unwind brake is negative)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.ndimage import median_filter
from scipy.signal import savgol_filter

from ...errors import InputError
from ._line import LineStages

DENOISE = ("savgol", "wavelet", None)


def _fill(x: np.ndarray) -> np.ndarray:
    """NaNs (dropped-out readings) linearly interpolated, ends held."""
    ok = np.isfinite(x)
    if ok.all():
        return x
    if not ok.any():
        return np.zeros_like(x)
    i = np.arange(len(x))
    return np.interp(i, i[ok], x[ok])


def wavelet_denoise(x: np.ndarray, wavelet: str = "db4", level: int | None = None):
    """Soft universal-threshold wavelet de-noising (Donoho-Johnstone), sigma from the MAD of
    the finest detail coefficients.

    Raises
    ------
    InputError
        When PyWavelets is not installed (``pip install r2rsim[wavelet]``).
    """
    try:
        import pywt
    except ImportError as exc:
        raise InputError("denoise='wavelet' needs PyWavelets: pip install "
                         "'r2rsim[wavelet]'") from exc
    coeffs = pywt.wavedec(x, wavelet, level=level, mode="symmetric")
    sigma = np.median(np.abs(coeffs[-1])) / 0.6745
    thr = sigma * np.sqrt(2.0 * np.log(max(len(x), 2)))
    coeffs[1:] = [pywt.threshold(c, thr, mode="soft") for c in coeffs[1:]]
    return pywt.waverec(coeffs, wavelet, mode="symmetric")[: len(x)]


def _smooth(x, dt, window_s, denoise, deriv=False):
    """A smoothed signal or its time derivative (Savitzky-Golay, quadratic)."""
    if denoise == "wavelet" and len(x) >= 16:
        x = wavelet_denoise(x)
    n = max(5, int(round(window_s / dt)) | 1)
    if denoise is None:
        return np.gradient(x, dt) if deriv else x
    if n >= len(x):
        return np.gradient(x, dt) if deriv else x
    return savgol_filter(x, n, 2, deriv=int(deriv), delta=dt, mode="interp")


@dataclass
class Signals:
    """Preprocessed measured channels of one run (arrays aligned to its samples).

    ``R`` unwind radius [m], ``w1``/``dw1`` unwind speed and acceleration, ``v``/``dv``
    web speed [m/s] and its derivative from the stage-2 encoder, ``w4``/``dw4`` the driven
    roller, ``tau1``/``tau4`` applied torques [N·m], ``alpha``/``dalpha`` dancer angle
    [rad] and rate, ``T2`` the stage-2 load cell (raw, may be censored), ``T2s`` smoothed,
    ``censored`` its clipped flag, ``Y`` pitch [m], ``valid`` rows without a dropped-out
    reading.
    """

    t: np.ndarray
    R: np.ndarray
    w1: np.ndarray
    dw1: np.ndarray
    v: np.ndarray
    dv: np.ndarray
    w4: np.ndarray
    dw4: np.ndarray
    tau1: np.ndarray
    tau4: np.ndarray
    alpha: np.ndarray
    dalpha: np.ndarray
    T2: np.ndarray
    T2s: np.ndarray
    censored: np.ndarray
    Y: np.ndarray
    valid: np.ndarray


def required_columns(st: LineStages) -> list[str]:
    """The visible columns (measured and drive data) the model reads."""
    return [st.column(k) for k in ("diameter", "speed_unwind", "speed_idler",
                                   "speed_driven", "tension", "angle", "pitch")] + [
        st.torque_column(st.unwind), st.torque_column(st.driven.id)]


def signals(frame: pd.DataFrame, st: LineStages, denoise: str | None = "savgol",
            window_s: float = 0.5, lower_limit: float = 0.0) -> Signals:
    """Preprocess one run's visible frame (thesis §2.6).

    Parameters
    ----------
    frame : pandas.DataFrame
        Visible columns with drive data (``t_s``, ``meas.*``, ``act.*``).
    st : LineStages
    denoise : {"savgol", "wavelet", None}
        Savitzky-Golay smoothing and differentiation; the same after wavelet de-noising
        (PyWavelets); or raw values with central differences.
    window_s : float
        Smoothing window [s].
    lower_limit : float
        The load cell's lower range limit [N]: readings at or below it are censored.
    """
    missing = [c for c in required_columns(st) + ["t_s"] if c not in frame.columns]
    if missing:
        raise InputError(f"hybrid-sov: the data has no column {', '.join(missing)} "
                         f"(torques need drive data: --drive-data)")
    t = frame["t_s"].to_numpy(float)
    if len(t) < 8:
        raise InputError("hybrid-sov: a run needs at least 8 samples")
    dt = float(np.median(np.diff(t)))
    raw = {k: frame[c].to_numpy(float) for k, c in zip(
        ("dia", "w1", "wi", "w4", "T2", "alpha", "Y", "tau1", "tau4"), required_columns(st),
        strict=True)}
    valid = np.all([np.isfinite(v) for v in raw.values()], axis=0)
    x = {k: _fill(v) for k, v in raw.items()}
    sm = {k: _smooth(x[k], dt, window_s, denoise) for k in x}
    d = {k: _smooth(x[k], dt, window_s, denoise, deriv=True) for k in ("w1", "wi", "w4",
                                                                       "alpha")}
    r_idler = st.sensor_ids["speed_idler_radius"]
    flag = f"flag.{st.sensor_ids['tension']}.clipped"
    censored = raw["T2"] <= lower_limit
    if flag in frame.columns:
        censored |= frame[flag].to_numpy(float) > 0
    # the roll radius changes slowly but jumps at a roll change: a running median over 1 s
    # removes the reading's noise (and outliers) without smearing the jump
    R = 0.5 * median_filter(x["dia"], size=max(1, int(round(1.0 / dt))) | 1, mode="nearest")
    return Signals(t=t, R=R, w1=sm["w1"], dw1=d["w1"], v=sm["wi"] * r_idler,
                   dv=d["wi"] * r_idler, w4=sm["w4"], dw4=d["w4"], tau1=sm["tau1"],
                   tau4=sm["tau4"], alpha=sm["alpha"], dalpha=d["alpha"], T2=x["T2"],
                   T2s=sm["T2"], censored=censored, Y=x["Y"], valid=valid)


def roll_index(R: np.ndarray, jump: float = 1e-3) -> np.ndarray:
    """Number of the material roll at each sample: it steps up where the (median-filtered)
    unwind radius jumps up by more than ``jump`` [m], i.e. at a roll change."""
    return np.concatenate([[0], np.cumsum(np.diff(R) > jump)])


def idler_sum(st: LineStages, stage: int, s: Signals) -> np.ndarray:
    """Σ_i (J_i·ω̇_i + b_i·ω_i)/R_i over a stage's idlers, with ω_i = v/R_i (web-speed
    equality, thesis §2.6): the tension gained across them (eqs. 2.8, 2.16)."""
    out = np.zeros_like(s.v)
    for r in st.idlers[stage]:
        out += (r.inertia * s.dv / r.radius + r.viscous * s.v / r.radius) / r.radius
    return out


def driven_term(st: LineStages, s: Signals) -> np.ndarray:
    """(J·ω̇ + b·ω - τ)/R of the driven roller: T_s4 - T_s3 (eqs. 2.7, 2.18)."""
    d = st.driven
    return (d.inertia * s.dw4 + d.viscous * s.w4 - s.tau4) / d.radius


def stage1_terms(st: LineStages, s: Signals) -> dict[str, np.ndarray]:
    """The unwind's torque balance (eqs. 2.6, 2.15) split into regressors; the outgoing
    tension is their sum with unit coefficients plus the wound-in polynomial T_s0(R)
    (eq. 2.22, zero here) and, as a candidate, the thesis's d(Jω)/dt term."""
    R = s.R
    return {
        "tau1/R": -s.tau1 / R,                                   # brake torque (τ < 0)
        "J1*dw1/R": st.roll_inertia(R) * s.dw1 / R,              # roll inertia, J(R)
        "b1*w1/R": st.unwind_viscous * s.w1 / R,                 # bearing friction
        # -ρ·w·t·R²·ω² of thesis eq. 2.15 (from d(Jω)/dt; r2rsim integrates J·dω/dt)
        "rho*w*t*R^2*w1^2": -st.web_density * st.web_width * st.web_thickness * R**2
        * s.w1**2,
        "R": R,
        "R^2": R**2,
    }


def physics_T1(st: LineStages, s: Signals) -> np.ndarray:
    """T_s1 from the unwind torque balance with the nominal constants (no fitting)."""
    t = stage1_terms(st, s)
    return t["tau1/R"] + t["J1*dw1/R"] + t["b1*w1/R"]


def raw_candidates(s: Signals, downstream: bool) -> dict[str, np.ndarray]:
    """The data-driven comparator's raw channels (no physics): the same information the
    hybrid model uses for the target. For the stage-2 tension, the stage-1/2 channels
    (radius, unwind speed and torque, web speed, with derivatives); with ``downstream``
    (for the pitch) also the stage-2 tension reading, the dancer and the driven roller."""
    raw = {"R": s.R, "w1": s.w1, "dw1": s.dw1, "tau1": s.tau1, "v": s.v, "dv": s.dv}
    if downstream:
        raw.update({"T2": s.T2s, "alpha": s.alpha, "dalpha": s.dalpha, "w4": s.w4,
                    "dw4": s.dw4, "tau4": s.tau4})
    return raw


def second_order(raw: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The raw channels, their squares and pairwise products (a quadratic response
    surface: the flexible data-driven candidate set)."""
    names = list(raw)
    out = dict(raw)
    for i, a in enumerate(names):
        for b in names[i:]:
            out[f"{a}*{b}"] = raw[a] * raw[b]
    return out
