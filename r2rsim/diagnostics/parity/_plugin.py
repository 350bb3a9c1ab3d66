"""The ``parity`` plug-in: nonlinear parity-space sensor validation of the registration span
(thesis Ch. 3) under the contract of :mod:`r2rsim.diagnostics.base`."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import InputError
from ...schema import plausibility as P
from ..base import Diagnostic
from ._design import KINDS, design_relation, sensitivity
from ._model import NonlinearModel, registration_model
from ._signal import savgol_derivatives, savgol_window_samples

MODES = ("literal", "model")
TIME_BASES = ("travel", "time")


@lru_cache(maxsize=32)
def _cached_model(EA, L, L0, Rd, Ro) -> NonlinearModel:
    return registration_model(EA, L, L0, Rd, Ro)


def registration_parameters(line, span: str = "registration", drive: str = "reg_drive",
                            downstream: str = "reg_idler", pitch_sensor: str = "sensor_B"):
    """EA [N], span length [m], relaxed pitch [m] and the two roller radii [m] of the
    reduced registration model, read from a line file (or a loaded ``Line``).

    The relaxed pitch is the pitch sensor's ``relaxed_pitch`` or its law's q0 (the roll-radius
    term q1·R³ is unknown to a monitor; the plug-in can calibrate L0 on healthy data).
    """
    from ...schema.loader import load_line

    ln = load_line(line) if not hasattr(line, "elements") else line
    els = {e.id: e for e in ln.elements}
    spans = {s.id: s for s in ln.spans}
    sens = {s.id: s for s in ln.sensors}
    for what, key, table in (("span", span, spans), ("element", drive, els),
                             ("element", downstream, els), ("sensor", pitch_sensor, sens)):
        if key not in table:
            raise InputError(f"parity: the line has no {what} '{key}'")
    b = sens[pitch_sensor]
    L0 = b.relaxed_pitch if b.relaxed_pitch is not None else b.relaxed_pitch_law.q0
    return {"web_EA_N": ln.web.modulus * ln.web.thickness * ln.web.width,
            "span_length_m": spans[span].length, "relaxed_pitch_m": L0,
            "drive_radius_m": els[drive].radius, "downstream_radius_m": els[downstream].radius}


#: physically plausible ranges of the reduced model's numbers (value from, to, unit): far
#: outside them the design corners overflow or underflow and the fit failed inside numpy
#: (EA = 1e308 N or 1e-300 N: "SVD did not converge"). EA spans the webs that
#: r2rsim.schema.plausibility accepts without a warning (modulus x thickness x width, from
#: elastomer tape, 0.1 N, to metal strip, 2.7e10 N); span and pitch lengths from the shortest
#: span it accepts (1 mm) to the longest without a warning (100 m); radii from a 1 mm rod to a
#: 10 m roll.
_PHYSICAL_RANGES = {
    "web_EA_N": (P.MODULUS_RANGE[0] * P.THICKNESS_RANGE[0] * P.WIDTH_RANGE[0],
                 P.MODULUS_RANGE[1] * P.THICKNESS_RANGE[1] * P.WIDTH_RANGE[1], "N"),
    "span_length_m": (P.SPAN_MIN, P.SPAN_RANGE[1], "m"),
    "relaxed_pitch_m": (P.SPAN_MIN, P.SPAN_RANGE[1], "m"),
    "drive_radius_m": (1e-3, 10.0, "m"),
    "downstream_radius_m": (1e-3, 10.0, "m"),
}


class ParitySpaceDetector(Diagnostic):
    """Nonlinear parity-space validation of sensors A (load cell) and B (pitch length).

    The reduced model (:func:`registration_model`) has one state, the registration-span
    tension, and the inputs [driven-roller speed, downstream idler speed, upstream tension]
    from the encoders and the upstream load cell. Its Lie-derivative stack
    Y = [y_A, ẏ_A, y_B, ẏ_B] has n − N = 3 parity relations: r1 mixes A and B (designed by
    the robust min-max), r2 uses B only and r3 A only (fixed by the null space; thesis Table
    3-2). Residuals are in newton-equivalents; ``statistic`` = max_j |r_j|/σ_j with σ_j from
    the healthy training runs.

    By default the plug-in is causal (an online method): the statistic at sample k uses
    samples 0..k only. Every channel and its derivative come from the same Savitzky-Golay
    window ending at sample k, evaluated at the window's centre, so all the signals of a
    residual (measured values, their derivatives, the inputs and x̂) refer to the same
    instant t_k − (window − 1)/2·dt: the residuals are aligned and lag by that group delay
    (``delay_s_``, 1.5 s with the default 3 s window), and the first window − 1 samples of a
    run have no statistic (NaN). ``causal=False`` is the offline variant: the centred filter
    uses up to half a window of future samples, so the residuals of a step fault move up to
    half a window before its onset.

    There is no operating-point scheduling of Ω: with the ``travel`` time base ∇_x O in the
    scaled rows is [1, −v0/L, 1, −v0/L] at every steady operating point, so Ω re-solved at the
    current point equals the design point's (r1 exactly, r2 and r3 to about 5e-5 between
    OC1 and OC2 of the registration line). What keeps the OC1 design valid at OC2 is the
    ``model`` residual Ω(Y − O(x̂, u)) instead of the linearised ``literal`` one, with the
    travel time base.

    Parameters
    ----------
    line : str, optional
        A line file to read EA, the span length, the relaxed pitch and the radii from
        (overrides the five numbers below).
    web_EA_N : float
        Web axial stiffness EA [N] (default: PET 50 µm × 0.5 m, 112.5 kN).
    span_length_m : float
        Registration span length L [m].
    relaxed_pitch_m : float, optional
        Relaxed pitch L0 [m]; None calibrates it on the healthy training runs (Hooke's law
        between sensors A and B).
    drive_radius_m, downstream_radius_m : float
        Radii of the driven roller and the downstream idler [m].
    sensor_a, sensor_b, drive_speed, downstream_speed, upstream_tension : str
        The channels of y_A [N], y_B [m], ω_d [rad/s], ω_o [rad/s] and T_up [N].
    design : {"fault_normalised", "unit_norm"}
        Normalisation of the min-max relation: ω F = 1 for unit faults on A and on B (the
        default), or the thesis's ‖ω‖ = 1, which can be blind to a sensor's faults.
    mode : {"model", "literal"}
        ``literal``: Ω(Y − E·U) centred on the training data (the thesis's linearised
        residual; it fails away from the design point); ``model``: Ω(Y − O(x̂, u)), which
        holds at every operating point to first order in x̂ − x.
    savgol_window_s : float
        Savitzky-Golay window [s], the same on every channel.
    savgol_order : int
        Savitzky-Golay polynomial order (≥ 2).
    causal : bool
        True (the default): past samples only; the residuals describe the instant half a
        window back (``delay_s_``) and are NaN for the first window − 1 samples. False: the
        centred filter (offline: it uses up to half a window of future samples).
    time_base : {"travel", "time"}
        ``travel``: derivative rows per metre of web, scaled to the design speed (ẏ·v0/v):
        the span's dynamics scale with L/v, so the relations hold at every speed;
        ``time``: per second, as in the thesis.
    modulus_spread : float
        Relative spread of EA in the design corners (EA·(1 ± spread)).
    pitch_spread_m : float
        Spread of L0 in the design corners [m].
    signature_z : float
        Scale of the signature match of :meth:`rank_channels`: each relation's |r_j|/σ_j
        enters capped at 3·signature_z, so one huge residual does not outvote the others.
    alpha : float
        Fraction of healthy training samples above the threshold.

    Attributes
    ----------
    omega_ : ndarray (3, 4)
        The relations r1-r3 on the scaled stack (sensor B rows ÷ L0/EA, derivative rows per
        web travel at the design speed with ``time_base="travel"``).
    design_point_ : ndarray (4,)
        p0 = [x, ω_d, ω_o, T_up], the training mean.
    S_ : ndarray (5, 4, 4)
        Mean-square model errors of the design scenarios (nominal and four corners).
    signature_ : DataFrame
        Which relation uses which sensor.
    center_, sigma_ : ndarray (3,)
        Training mean and standard deviation of each relation.
    delay_s_ : float
        Group delay of the residuals [s]: with ``causal=True`` the statistic at sample k
        describes the instant t_k − delay_s_; 0 with ``causal=False``.
    threshold_ : float
    """

    name = "parity"
    requires = ("meas.*",)

    def __init__(self, line: str | None = None, web_EA_N: float = 112.5e3,
                 span_length_m: float = 1.5, relaxed_pitch_m: float | None = None,
                 drive_radius_m: float = 0.10, downstream_radius_m: float = 0.05,
                 sensor_a: str = "meas.sensor_A.tension_N",
                 sensor_b: str = "meas.sensor_B.pitch_m",
                 drive_speed: str = "meas.u_drive.speed_rad_s",
                 downstream_speed: str = "meas.u_out.speed_rad_s",
                 upstream_tension: str = "meas.lc_unwind.tension_N",
                 design: str = "fault_normalised", mode: str = "model",
                 savgol_window_s: float = 3.0, savgol_order: int = 2, causal: bool = True,
                 time_base: str = "travel",
                 modulus_spread: float = 0.02, pitch_spread_m: float = 5e-6,
                 signature_z: float = 3.0,
                 alpha: float = 0.01):
        self.line = line
        self.web_EA_N = web_EA_N
        self.span_length_m = span_length_m
        self.relaxed_pitch_m = relaxed_pitch_m
        self.drive_radius_m = drive_radius_m
        self.downstream_radius_m = downstream_radius_m
        self.sensor_a = sensor_a
        self.sensor_b = sensor_b
        self.drive_speed = drive_speed
        self.downstream_speed = downstream_speed
        self.upstream_tension = upstream_tension
        self.design = design
        self.mode = mode
        self.savgol_window_s = savgol_window_s
        self.savgol_order = savgol_order
        self.causal = causal
        self.time_base = time_base
        self.modulus_spread = modulus_spread
        self.pitch_spread_m = pitch_spread_m
        self.signature_z = signature_z
        self.alpha = alpha

    # ---- parameters and channels -------------------------------------------------------------
    @property
    def channels(self) -> list[str]:
        """y_A, y_B, ω_d, ω_o, T_up columns, in that order."""
        return [self.sensor_a, self.sensor_b, self.drive_speed, self.downstream_speed,
                self.upstream_tension]

    def _validate(self):
        if self.design not in KINDS:
            raise InputError(f"parity: design must be one of {', '.join(KINDS)}, "
                             f"got {self.design!r}")
        if self.time_base not in TIME_BASES:
            raise InputError(f"parity: time_base must be one of {', '.join(TIME_BASES)}, "
                             f"got {self.time_base!r}")
        if self.mode not in MODES:
            raise InputError(f"parity: mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if self.line is not None and not isinstance(self.line, (str, Path)):
            raise InputError(f"parity: line must be the path of a line file, "
                             f"got {self.line!r}")
        for key in ("sensor_a", "sensor_b", "drive_speed", "downstream_speed",
                    "upstream_tension"):
            if not isinstance(getattr(self, key), str):
                raise InputError(f"parity: {key} must be a column name (a string), "
                                 f"got {getattr(self, key)!r}")
        if not isinstance(self.causal, bool):
            raise InputError(f"parity: causal must be true or false, got {self.causal!r}")
        for key in ("web_EA_N", "span_length_m", "drive_radius_m", "downstream_radius_m",
                    "savgol_window_s", "signature_z"):
            if not (np.isfinite(v := self._number(key)) and v > 0):
                raise InputError(f"parity: {key} must be a positive number, "
                                 f"got {getattr(self, key)!r}")
        for key, (low, high, unit) in _PHYSICAL_RANGES.items():
            if key == "relaxed_pitch_m" and self.relaxed_pitch_m is None:
                continue  # calibrated on the training runs
            if not low <= self._number(key) <= high:
                raise InputError(f"parity: {key} must be from {low:g} to {high:g} {unit}"
                                 f"{' or null' if key == 'relaxed_pitch_m' else ''}, "
                                 f"got {getattr(self, key)!r}")
        # upper limits: beyond them the design corners or the windows mean nothing, and
        # a fit would overflow or allocate without bound
        for key, low, high, unit in (("modulus_spread", 0.0, 0.5, ""),
                                     ("pitch_spread_m", 0.0, 1e-3, " m"),
                                     ("savgol_window_s", 0.0, 600.0, " s")):
            if not low <= self._number(key) <= high:
                raise InputError(f"parity: {key} must be from {low:g} to {high:g}{unit}, "
                                 f"got {getattr(self, key)!r}")
        self._check_int("savgol_order", 2, 10)
        self._check_alpha()

    def required_columns(self, frame: pd.DataFrame) -> list[str]:
        super().required_columns(frame)
        missing = [c for c in self.channels if c not in frame.columns]
        if missing:
            raise InputError(f"parity: the data has no column matching {', '.join(missing)} "
                             f"(set sensor_a, sensor_b, drive_speed, downstream_speed, "
                             f"upstream_tension)")
        self._check_alive(frame[self.channels].to_numpy(float))
        return list(self.channels)

    def _check_alive(self, X: np.ndarray) -> None:
        """Every channel (a column of X) has a finite sample: the relations need them all."""
        dead = [c for j, c in enumerate(self.channels) if not np.isfinite(X[:, j]).any()]
        if dead:
            raise InputError(f"parity: {', '.join(dead)} has no finite sample in this run (a "
                             f"dead sensor: the relations need every channel)")

    def _physical(self) -> dict:
        p = {"web_EA_N": self.web_EA_N, "span_length_m": self.span_length_m,
             "relaxed_pitch_m": self.relaxed_pitch_m, "drive_radius_m": self.drive_radius_m,
             "downstream_radius_m": self.downstream_radius_m}
        if self.line is not None:
            try:
                p.update(registration_parameters(self.line))
            except InputError as exc:
                raise InputError(f"parity: line: {exc.format()}") from None
            if self.relaxed_pitch_m is None:
                p["relaxed_pitch_m"] = None
        return p

    def _model(self, EA=None, L0=None) -> NonlinearModel:
        ph = self.physical_
        return _cached_model(float(EA or ph["web_EA_N"]), float(ph["span_length_m"]),
                             float(L0 or ph["relaxed_pitch_m"]), float(ph["drive_radius_m"]),
                             float(ph["downstream_radius_m"]))

    def reduced_model(self, frames) -> tuple[NonlinearModel, float, float]:
        """The reduced registration model with its EA [N] and L0 [m]; sets ``physical_`` and
        ``model_``. L0 not given (nor by the line) is calibrated on ``frames`` (healthy
        visible frames) by Hooke's law between the sensors, y_B = (y_A/EA + 1)·L0.
        The GSMMS plug-in's physics constraint uses it too."""
        self.physical_ = self._physical()
        EA = float(self.physical_["web_EA_N"])
        if self.physical_["relaxed_pitch_m"] is None:
            ratio = np.concatenate([f[self.sensor_b].to_numpy(float)
                                    / (1 + f[self.sensor_a].to_numpy(float) / EA)
                                    for f in frames])
            self.physical_["relaxed_pitch_m"] = float(np.nanmedian(ratio))
        self.model_ = self._model()
        return self.model_, EA, float(self.physical_["relaxed_pitch_m"])

    def operating_points(self, frame: pd.DataFrame) -> np.ndarray:
        """p = [x̂, ω_d, ω_o, T_up] of every sample (T, 4), NaN where a channel is missing
        (after :meth:`reduced_model`). With ``causal=True`` the row of sample k describes the
        instant half a Savitzky-Golay window back and the first window − 1 rows are NaN."""
        s = self._signals(frame)
        EA, L0 = float(self.physical_["web_EA_N"]), float(self.physical_["relaxed_pitch_m"])
        P = np.vstack([self._xhat(s, EA, L0)[None], s["u"]]).T
        P[s["bad"]] = np.nan
        return P

    # ---- signals -----------------------------------------------------------------------------
    def _signals(self, frame: pd.DataFrame) -> dict:
        """Smoothed stack Y (4, T), inputs u (3, T), u̇ (3, T), the samples without a
        residual (``bad``) and the group delay [s] of the estimates.

        Every channel goes through the same window and is evaluated at the same point of it
        (:func:`savgol_derivatives`), so in causal mode the measured values, their
        derivatives and the inputs of a relation all refer to the same instant, delayed by
        the same group delay: nothing needs re-aligning.
        """
        t = frame["t_s"].to_numpy(float) if "t_s" in frame else np.arange(len(frame)) * 0.01
        dt = float(np.median(np.diff(t))) if len(t) > 1 else 0.01
        X = frame[self.channels].to_numpy(float)
        self._check_alive(X)
        w = savgol_window_samples(self.savgol_window_s, dt, self.savgol_order)
        try:
            D, delay = savgol_derivatives(X, dt, w, self.savgol_order, 1, self.causal)
        except InputError as exc:  # a run shorter than the window
            raise InputError(f"parity: {exc.message} (savgol_window_s = "
                             f"{self.savgol_window_s!r} s)") from None
        (yA, yB, wd, wo, tu), (dA, dB, dwd, dwo, dtu) = D[0].T, D[1].T
        # a drop-out in the raw sample k marks sample k (not the instant it describes in causal
        # mode): the interpolation bridging it reads the next reading, which is not there yet
        # at k; NaN estimates (the causal filter's first window - 1 samples) have no residual
        bad = ~np.all(np.isfinite(X), axis=1) | ~np.isfinite(D).all(axis=(0, 2))
        return {"t": t, "Y": np.vstack([yA, dA, yB, dB]), "u": np.vstack([wd, wo, tu]),
                "du": np.vstack([dwd, dwo, dtu]), "bad": bad, "delay": delay}

    def _xhat(self, s: dict, EA: float, L0: float) -> np.ndarray:
        """The state from both static rows (their mean): any estimate near x will do, since
        Ω annihilates ∇_x O to first order."""
        return 0.5 * (s["Y"][0] + EA * (s["Y"][2] / L0 - 1.0))

    def _errors(self, s, model: NonlinearModel, EA, L0) -> np.ndarray:
        """Y − O(x̂, u, u̇) (4, T)."""
        x = self._xhat(s, EA, L0)[None]
        return s["Y"] - model.observation(x, s["u"], [s["du"]])

    # ---- fit -----------------------------------------------------------------------------------
    def fit(self, runs):
        """Design the relations on healthy runs and set the threshold (see the class doc)."""
        self._validate()
        frames = self._frames(runs)
        for f in frames:
            self.required_columns(f)
        model, EA, L0 = self.reduced_model(frames)
        sigs = [self._signals(f) for f in frames]
        # rows in newton-equivalents (sensor B through ∂h_B/∂x = L0/EA)
        self.scale_ = np.array([1.0, 1.0, L0 / EA, L0 / EA])
        self.row_order_ = np.array([k for _, k in model.rows])
        P = np.hstack([np.vstack([self._xhat(s, EA, L0)[None], s["u"]])[:, ~s["bad"]]
                       for s in sigs])
        self.design_point_ = P.mean(axis=1)
        self.design_speed_m_s_ = float(self._speed(self.design_point_[2]))
        self.delay_s_ = float(sigs[0]["delay"])
        self.S_ = self._scenario_matrices(sigs, EA, L0)
        if hasattr(self, "fault_signs_"):  # a re-fit chooses the signs again
            del self.fault_signs_
        self.omega_ = self._relations(self.design_point_)
        self.signature_ = self._signature_table()
        R = np.hstack([self._residuals(s, center=False)[:, ~s["bad"]] for s in sigs])
        self.center_ = R.mean(axis=1)
        self.sigma_ = R.std(axis=1)
        self.sigma_[self.sigma_ <= 0] = 1.0
        stat = np.max(np.abs(R - self.center_[:, None]) / self.sigma_[:, None], axis=0)
        self.threshold_ = float(np.quantile(stat, 1.0 - self.alpha))
        return self

    def _scenario_matrices(self, sigs, EA, L0) -> np.ndarray:
        """Mean-square model errors (scaled) per design scenario: EA·(1 ± spread) ×
        L0 ± spread, and the nominal model."""
        corners = [(EA, L0)] + [(EA * (1 + a * self.modulus_spread), L0 + b * self.pitch_spread_m)
                                for a in (-1, 1) for b in (-1, 1)]
        S = []
        for ea, l0 in corners:
            m = self._model(ea, l0)
            E = np.hstack([(self._errors(s, m, ea, l0) / self._rowscale(s))[:, ~s["bad"]]
                           for s in sigs])
            S.append(E @ E.T / E.shape[1])
        return np.array(S)

    def _faults(self) -> np.ndarray:
        """Unit offsets of sensors A and B (1 N-equivalent) in the scaled stack."""
        F = np.zeros((4, 2))
        F[0, 0] = F[2, 1] = 1.0
        return F

    def _speed(self, omega_o):
        return self.physical_["downstream_radius_m"] * omega_o

    def _rowscale_at(self, p) -> np.ndarray:
        """Scale of each stack row at the point p (divide Y − O by it): newton-equivalents,
        and with ``time_base="travel"`` derivatives per web travel (× v0/v)."""
        if self.time_base == "time":
            return self.scale_.copy()
        return self.scale_ * (self._speed(p[2]) / self.design_speed_m_s_) ** self.row_order_

    def _rowscale(self, s) -> np.ndarray:
        """The row scales along a run's samples (4, T)."""
        if self.time_base == "time":
            return np.broadcast_to(self.scale_[:, None], s["Y"].shape)
        v = self._speed(s["u"][1]) / self.design_speed_m_s_
        return self.scale_[:, None] * v[None, :] ** self.row_order_[:, None]

    def _N(self, p):
        """∇_x O_NL at p in scaled rows, and its derivatives ∂/∂p (4 params, 4, 1)."""
        sc = self._rowscale_at(p)
        G = self.model_.grad_x(p[:1], p[1:])
        dG = self.model_.grad_xp(p[:1], p[1:]) / sc[None, :, None]
        if self.time_base == "travel":  # the scale depends on ω_o (p[2])
            dsc = sc * self.row_order_ / p[2]
            dG[2] -= G * (dsc / sc**2)[:, None]
        return G / sc[:, None], dG

    def _relations(self, p) -> np.ndarray:
        """Ω (3 x 4, on the scaled stack) at the point p = [x, u]: the min-max mixed
        relation, then the single-sensor ones in the thesis's order (B only, A only)."""
        model = self.model_
        N, _ = self._N(p)
        single = model.sensor_relations(p[:1], p[1:], scale=self._rowscale_at(p))[::-1]
        d = design_relation(self.S_, N, self._faults(), self.design,
                            signs=getattr(self, "fault_signs_", None))
        if not hasattr(self, "fault_signs_"):
            self.fault_signs_ = d.signs  # the design point's; :meth:`sensitivity` keeps them
        return np.vstack([d.omega, *single])

    def _signature_table(self) -> pd.DataFrame:
        """Which relation uses which sensor (True: a fault on that sensor moves it)."""
        sensor_of_row = self.model_.sensor_of_row()
        W = np.abs(self.omega_)
        tab = np.array([[W[k, sensor_of_row == j].max() > 1e-9 * W[k].max()
                         for k in range(len(W))] for j in range(2)])
        return pd.DataFrame(tab, index=[self.sensor_a, self.sensor_b],
                            columns=[f"r{k + 1}" for k in range(len(W))])

    # ---- residuals -----------------------------------------------------------------------------
    def _residuals(self, s, center: bool = True) -> np.ndarray:
        EA, L0 = float(self.physical_["web_EA_N"]), float(self.physical_["relaxed_pitch_m"])
        if self.mode == "literal":
            x = self._xhat(s, EA, L0)
            # E(x̂, u)·u̇: the input part of the stack (eq. 3.13); zero for this model's h
            EU = self.model_.input_part(x[None], s["u"], [s["du"]])
            R = self.omega_ @ ((s["Y"] - EU) / self._rowscale(s))
        else:
            R = self.omega_ @ (self._errors(s, self.model_, EA, L0) / self._rowscale(s))
        if center:
            R = R - self.center_[:, None]
        R[:, s["bad"]] = np.nan
        return R

    def _knots(self, s, step_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Knot times every ``step_s`` and the operating point p = [x̂, u] averaged over
        each interval."""
        EA, L0 = float(self.physical_["web_EA_N"]), float(self.physical_["relaxed_pitch_m"])
        t = s["t"]
        P = np.vstack([self._xhat(s, EA, L0)[None], s["u"]])
        edges = np.arange(t[0], max(t[-1], t[0] + 1e-9), step_s)
        idx = np.clip(np.searchsorted(edges, t, side="right") - 1, 0, len(edges) - 1)
        tk, pk = [], []
        for k in np.unique(idx):
            sel = (idx == k) & np.all(np.isfinite(P), axis=0)
            if sel.any():
                tk.append(t[sel].mean())
                pk.append(P[:, sel].mean(axis=1))
        return np.array(tk), np.array(pk)

    # ---- the contract --------------------------------------------------------------------------
    def score(self, run):
        """Residuals r1..r3 (newton-equivalents, centred on the healthy training data) and
        ``statistic`` = max_j |r_j|/σ_j, indexed like the run's samples."""
        self._check_fitted()
        f = self._frames(run)[0]
        self.required_columns(f)
        R = self._residuals(self._signals(f))
        out = pd.DataFrame(R.T, index=f.index, columns=[f"r{k + 1}" for k in range(len(R))])
        with np.errstate(invalid="ignore"):
            z = np.abs(R) / self.sigma_[:, None]
        stat = np.where(np.all(np.isfinite(z), axis=0), np.max(np.nan_to_num(z), axis=0),
                        np.nan)
        out.insert(0, "statistic", stat)
        return out

    def rank_channels(self, scores: pd.DataFrame) -> pd.DataFrame:
        """Sensors A and B ordered by how well their signature explains the residuals.

        A sensor's evidence is Σ z_k over the relations that use it minus Σ z_k over those
        that do not (z_k = |r_k|/σ_k, capped at 3·``signature_z`` so one huge residual does
        not decide alone): a fault on A moves r1 and r3 and leaves r2, a fault on B the
        mirror image (thesis Fig. 3-4). NaN where the statistic is NaN.
        """
        cols = list(self.signature_.columns)
        z = np.minimum(np.abs(scores[cols].to_numpy(float)) / self.sigma_,
                       3 * self.signature_z)
        sig = self.signature_.to_numpy(float)
        evidence = z @ sig.T - z @ (1 - sig).T  # (T, sensors)
        order = np.argsort(-evidence, axis=1)
        names = np.array(self.signature_.index, dtype=object)[order]
        names[~np.isfinite(scores["statistic"].to_numpy(float))] = np.nan
        return pd.DataFrame(names, index=scores.index)

    def sensitivity(self, run, step_s: float = 1.0) -> pd.DataFrame:
        """Post-optimal sensitivity of the mixed relation along a run (thesis Figs. 3-6,
        3-7): at knots every ``step_s`` the min-max design is re-solved at the operating
        point p = [x̂, ω_d, ω_o, T_up] averaged over the knot's interval, and dJ/dp and dω/dp
        come from its KKT system (eqs. 3.20-3.22). An analysis of the design, not part of
        the statistic.

        Parameters
        ----------
        run : run or frame
        step_s : float
            Knot interval [s], 1 ms to 1e6 s.

        Returns
        -------
        pandas.DataFrame
            ``t_s`` (the mean sample time of the interval; with ``causal=True`` its p
            describes ``delay_s_`` earlier), the point ``p.*``, ``J``, ``dJ/d<p>`` and
            ``domega<i>/d<p>``.
        """
        self._check_fitted()
        if isinstance(step_s, bool) or not isinstance(step_s, (int, float, np.number)) \
                or not 1e-3 <= step_s <= 1e6:
            raise InputError(f"parity: step_s must be a number from 0.001 to 1e+06 s, "
                             f"got {step_s!r}")
        s = self._signals(self._frames(run)[0])
        tk, pk = self._knots(s, step_s)
        names = ["x", "omega_d", "omega_o", "T_up"]
        rows, start = [], self.omega_[0]
        for t, p in zip(tk, pk, strict=False):
            N, dN = self._N(p)
            d = design_relation(self.S_, N, self._faults(), self.design, start=start,
                                signs=self.fault_signs_)
            start = d.omega
            dJ, dom, _ = sensitivity(d, self.S_, N, self._faults(), dN, self.design)
            row = {"t_s": t, **{f"p.{n}": v for n, v in zip(names, p, strict=False)}, "J": d.J}
            row.update({f"dJ/d{n}": v for n, v in zip(names, dJ, strict=False)})
            for i in range(dom.shape[1]):
                row.update({f"domega{i + 1}/d{n}": dom[k, i] for k, n in enumerate(names)})
            rows.append(row)
        return pd.DataFrame(rows)

