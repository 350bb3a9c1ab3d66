"""Preprocessing (thesis §2.6: de-noising, smoothing differentiation, R1 = diameter/2) and
the per-stage physics regressors of eqs. 2.15-2.19, with signs from r2rsim's roller balance
``J·dω/dt = R·(T_out - T_in) + τ_m - b·ω`` (docs/model.md; the applied torque τ_m is
positive in the direction of web travel, so an unwind brake is negative)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd
from scipy.ndimage import median_filter
from scipy.signal import savgol_coeffs, savgol_filter

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


def _fill_causal(x: np.ndarray) -> np.ndarray:
    """NaNs (dropped-out readings) replaced by the last finite reading (a causal hold); a
    leading gap takes the first finite reading."""
    ok = np.isfinite(x)
    if ok.all():
        return x
    if not ok.any():
        return np.zeros_like(x)
    last = np.maximum.accumulate(np.where(ok, np.arange(len(x)), -1))
    return x[np.where(last < 0, np.argmax(ok), last)]


def wavelet_denoise(x: np.ndarray, wavelet: str = "db4", level: int | None = None):
    """Soft universal-threshold wavelet de-noising (Donoho-Johnstone), sigma from the MAD of
    the finest detail coefficients.

    Raises
    ------
    InputError
        When PyWavelets is not installed (``pip install PyWavelets``, the ``[wavelet]`` extra).
    """
    try:
        import pywt
    except ImportError as exc:
        raise InputError(
            "denoise='wavelet' needs PyWavelets: pip install 'r2rsim[wavelet]'"
        ) from exc
    coeffs = pywt.wavedec(x, wavelet, level=level, mode="symmetric")
    sigma = np.median(np.abs(coeffs[-1])) / 0.6745
    thr = sigma * np.sqrt(2.0 * np.log(max(len(x), 2)))
    coeffs[1:] = [pywt.threshold(c, thr, mode="soft") for c in coeffs[1:]]
    return pywt.waverec(coeffs, wavelet, mode="symmetric")[: len(x)]


def _smooth(x, dt, window_s, denoise, deriv=False):
    """A smoothed signal or its time derivative (Savitzky-Golay, quadratic), centred: the
    offline preprocessing (``causal=False``), which reads half a window of later samples."""
    if denoise == "wavelet" and len(x) >= 16:
        x = wavelet_denoise(x)
    n = window_samples(window_s, dt)
    if denoise is None:
        return np.gradient(x, dt) if deriv else x
    if n >= len(x):
        return np.gradient(x, dt) if deriv else x
    return savgol_filter(x, n, 2, deriv=int(deriv), delta=dt, mode="interp")


def window_samples(window_s: float, dt: float) -> int:
    """The odd number of samples of the smoothing window (at least 5)."""
    return max(5, int(round(window_s / dt)) | 1)


def trailing_savgol(
    x: np.ndarray, n: int, dt: float, deriv: int = 0, pos: int | None = None
) -> np.ndarray:
    """Causal Savitzky-Golay filter: at every sample k, the least-squares quadratic fitted to
    the trailing window ``x[k-n+1 .. k]``, or its time derivative, evaluated at position
    ``pos`` of the window (0 its first sample, n - 1 its last; default the centre).

    Evaluated at the centre it is the centred filter of :func:`_smooth` delayed by
    (n - 1)/2 samples, with its noise gain; the value at k uses no sample after k. Before the
    window has filled (k < n - 1) the missing samples are taken equal to ``x[0]`` (the line
    as it was at the start of the record), a causal choice.

    Parameters
    ----------
    x : numpy.ndarray
        Uniformly sampled signal, without NaN.
    n : int
        Window length [samples], >= 3.
    dt : float
        Sample period [s].
    deriv : int
        0: the smoothed value; 1: its time derivative [per s].
    pos : int or None
        Evaluation position in the window; None: (n - 1) // 2.

    Returns
    -------
    numpy.ndarray
        Same length as ``x``.
    """
    pos = (n - 1) // 2 if pos is None else pos
    c = savgol_coeffs(n, 2, deriv=deriv, delta=dt, pos=pos, use="dot")
    xp = np.concatenate([np.full(n - 1, x[0]), x])
    # a dot product of the coefficients with each trailing window: out[k] uses xp[k .. k+n-1]
    # = x[k-n+1 .. k], so the same leading samples give the same value whatever follows
    return np.convolve(xp, c[::-1], mode="valid")


def trailing_median(x: np.ndarray, n: int) -> np.ndarray:
    """Running median over the trailing window ``x[k-n+1 .. k]`` (``x[0]`` before the
    record): causal, and for a slowly varying signal the value at the window's centre."""
    return median_filter(x, size=n, origin=(n - 1) // 2, mode="nearest")


def _delay(x: np.ndarray, lag: int) -> np.ndarray:
    """``x`` delayed by ``lag`` samples (the first sample held before the record)."""
    lag = min(lag, len(x))
    return np.concatenate([np.full(lag, x[0]), x[: len(x) - lag]])


@dataclass
class Signals:
    """Preprocessed measured channels of one run (arrays aligned to its samples).

    ``R`` unwind radius [m], ``w1``/``dw1`` unwind speed and acceleration, ``v``/``dv``
    web speed [m/s] and its derivative from the stage-2 encoder, ``w4``/``dw4`` the driven
    roller, ``tau1``/``tau4`` applied torques [N·m], ``alpha``/``dalpha`` dancer angle
    [rad] and rate, ``T2`` the stage-2 load cell (raw, may be censored), ``T2s`` smoothed,
    ``censored`` its clipped flag, ``Y`` pitch [m], ``valid`` rows without a dropped-out
    reading (causal: nor an unfilled window), ``dt`` the sample period used [s] and
    ``delay_s`` the age of every row's values: row k describes the line at
    ``t[k] - delay_s`` (0 offline; half the smoothing window with the causal filter).
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
    dt: float = float("nan")
    delay_s: float = 0.0


def required_columns(st: LineStages) -> list[str]:
    """The visible columns (measured and drive data) the model reads."""
    return [
        st.column(k)
        for k in (
            "diameter",
            "speed_unwind",
            "speed_idler",
            "speed_driven",
            "tension",
            "angle",
            "pitch",
        )
    ] + [st.torque_column(st.unwind), st.torque_column(st.driven.id)]


def check_frame(frame: pd.DataFrame, st: LineStages) -> None:
    """Refuse a frame without the columns the model reads or with fewer than 8 samples."""
    missing = [c for c in required_columns(st) + ["t_s"] if c not in frame.columns]
    if missing:
        raise InputError(
            f"hybrid-sov: the data has no column {', '.join(missing)} "
            f"(torques need drive data: --drive-data)"
        )
    if len(frame) < 8:
        raise InputError("hybrid-sov: a run needs at least 8 samples")


#: the channels whose time derivative the regressors use
_DERIVED = ("w1", "wi", "w4", "alpha")


def signals(
    frame: pd.DataFrame,
    st: LineStages,
    denoise: str | None = "savgol",
    window_s: float = 0.5,
    lower_limit: float = 0.0,
    causal: bool = True,
    dt: float | None = None,
) -> Signals:
    """Preprocess one run's visible frame (thesis §2.6).

    Offline (``causal=False``, the thesis's preprocessing): centred Savitzky-Golay smoothing
    and differentiation (quadratic, ``window_s``), NaNs interpolated between their
    neighbours, a centred 1 s running median of the radius; every value refers to its own
    sample but reads half a window of later samples.

    Causal (the default): the value at sample k uses samples 0..k only. Each channel is
    fitted by least squares with a quadratic over the trailing window of n samples (n as
    offline) and the fit is read at the window's centre: that is the centred filter's
    value for sample k - (n - 1)/2, with the centred filter's noise. The estimate at the
    window's last sample would have no delay, but its noise variance is 3.4 times larger
    for the value and 15 times for the derivative (n = 25), and the regressors are mostly
    derivatives. So the delay is compensated instead: the raw load cell and pitch (the
    regression targets), the censoring flags, the validity of the row and the radius (a
    trailing median over the same n samples) are delayed by the same (n - 1)/2 samples, and
    every signal of a row refers to the one instant t_k - ``delay_s``. The first n - 1
    rows (the window not yet full) are not valid. A dropped-out reading is held at the last
    finite one. ``denoise=None`` gives the raw values and central differences one sample
    late. Wavelet de-noising transforms the whole run and has no causal form here: it is
    refused.

    Parameters
    ----------
    frame : pandas.DataFrame
        Visible columns with drive data (``t_s``, ``meas.*``, ``act.*``).
    st : LineStages
    denoise : {"savgol", "wavelet", None}
        Savitzky-Golay smoothing and differentiation; the same after wavelet de-noising
        (PyWavelets, offline only); or raw values with central differences.
    window_s : float
        Smoothing window [s].
    lower_limit : float
        The load cell's lower range limit [N]: readings at or below it are censored.
    causal : bool
        True: only past and present samples (above); False: the offline preprocessing.
    dt : float or None
        Sample period [s]; None: the median step of ``t_s`` over the whole run (the plug-in
        passes its training period when scoring causally, so that nothing depends on later
        time stamps).

    Returns
    -------
    Signals

    Raises
    ------
    InputError
        Missing columns, fewer than 8 samples, or ``denoise="wavelet"`` with ``causal``.
    """
    check_frame(frame, st)
    if causal and denoise == "wavelet":
        raise InputError(
            "hybrid-sov: denoise='wavelet' de-noises each run as a whole, "
            "which reads later samples: it needs causal=False (offline)"
        )
    t = frame["t_s"].to_numpy(float)
    if dt is None:
        dt = float(np.median(np.diff(t)))
    raw = {
        k: frame[c].to_numpy(float)
        for k, c in zip(
            ("dia", "w1", "wi", "w4", "T2", "alpha", "Y", "tau1", "tau4"),
            required_columns(st),
            strict=True,
        )
    }
    valid = np.all([np.isfinite(v) for v in raw.values()], axis=0)
    r_idler = st.sensor_ids["speed_idler_radius"]
    flag = f"flag.{st.sensor_ids['tension']}.clipped"
    censored = raw["T2"] <= lower_limit
    if flag in frame.columns:
        censored |= frame[flag].to_numpy(float) > 0
    if not causal:
        x = {k: _fill(v) for k, v in raw.items()}
        sm = {k: _smooth(x[k], dt, window_s, denoise) for k in x}
        d = {k: _smooth(x[k], dt, window_s, denoise, deriv=True) for k in _DERIVED}
        # the roll radius changes slowly but jumps at a roll change: a running median over
        # 1 s removes the reading's noise (and outliers) without smearing the jump
        R = 0.5 * median_filter(x["dia"], size=max(1, int(round(1.0 / dt))) | 1, mode="nearest")
        T2, Y, lag = x["T2"], x["Y"], 0
    else:
        x = {k: _fill_causal(v) for k, v in raw.items()}
        w = 3 if denoise is None else window_samples(window_s, dt)
        lag = (w - 1) // 2
        if denoise is None:  # np.gradient's central difference, one sample late
            sm = {k: _delay(v, 1) for k, v in x.items()}
            d = {k: (x[k] - _delay(x[k], 2)) / (2.0 * dt) for k in _DERIVED}
        else:
            sm = {k: trailing_savgol(v, w, dt) for k, v in x.items()}
            d = {k: trailing_savgol(x[k], w, dt, deriv=1) for k in _DERIVED}
        # the trailing median's centre is the same instant; a median keeps the roll
        # change's jump sharp (delayed like everything else)
        R = 0.5 * trailing_median(x["dia"], w)
        T2, Y = _delay(x["T2"], lag), _delay(x["Y"], lag)
        censored = _delay(censored, lag)
        valid = _delay(valid, lag) & (np.arange(len(t)) >= w - 1)
    return Signals(
        t=t,
        R=R,
        w1=sm["w1"],
        dw1=d["w1"],
        v=sm["wi"] * r_idler,
        dv=d["wi"] * r_idler,
        w4=sm["w4"],
        dw4=d["w4"],
        tau1=sm["tau1"],
        tau4=sm["tau4"],
        alpha=sm["alpha"],
        dalpha=d["alpha"],
        T2=T2,
        T2s=sm["T2"],
        censored=censored,
        Y=Y,
        valid=valid,
        dt=dt,
        delay_s=lag * dt,
    )


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
        "tau1/R": -s.tau1 / R,  # brake torque (τ < 0)
        "J1*dw1/R": st.roll_inertia(R) * s.dw1 / R,  # roll inertia, J(R)
        "b1*w1/R": st.unwind_viscous * s.w1 / R,  # bearing friction
        # -ρ·w·t·R²·ω² of thesis eq. 2.15 (from d(Jω)/dt; r2rsim integrates J·dω/dt)
        "rho*w*t*R^2*w1^2": -st.web_density * st.web_width * st.web_thickness * R**2 * s.w1**2,
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
        raw.update(
            {
                "T2": s.T2s,
                "alpha": s.alpha,
                "dalpha": s.dalpha,
                "w4": s.w4,
                "dw4": s.dw4,
                "tau4": s.tau4,
            }
        )
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
