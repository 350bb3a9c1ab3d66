"""The ``parity`` plug-in: nonlinear parity-space sensor validation of the registration span
(thesis Ch. 3) under the contract of :mod:`r2rsim.diagnostics.base`."""

from __future__ import annotations

import copy
import warnings
from functools import lru_cache
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import InputError
from ...schema import plausibility as P
from ..base import Diagnostic
from ._design import KINDS, design_relation, sensitivity
from ._line import COLUMNS, NUMBERS, PRESETS, ROLES, find_roles, line_numbers, role_columns
from ._model import NonlinearModel, registration_model
from ._signal import savgol_derivatives, savgol_window_samples

MODES = ("literal", "model")
TIME_BASES = ("travel", "time")


@lru_cache(maxsize=32)
def _cached_model(EA, L, L0, Rd, Ro) -> NonlinearModel:
    return registration_model(EA, L, L0, Rd, Ro)


def registration_parameters(
    line, *, span: str, drive: str, downstream: str, pitch_sensor: str
) -> dict[str, float]:
    """EA [N], span length [m], relaxed pitch [m] and the two roller radii [m] of the
    reduced registration model, read from a line file (or a loaded ``Line``) through the
    ids of its span, driven and downstream rollers and pitch-length sensor (no default: see
    :func:`find_roles` to infer them, :data:`PRESETS` for the thesis line's).

    The relaxed pitch is the pitch sensor's ``relaxed_pitch`` or its law's q0 (the roll-radius
    term q1·R³ is unknown to a monitor; the plug-in calibrates L0 on healthy data).
    """
    from ...schema.loader import load_line

    ln = load_line(line) if not hasattr(line, "elements") else line
    roles = {"span": span, "drive": drive, "downstream": downstream, "pitch_sensor": pitch_sensor}
    for key, value in roles.items():
        if not isinstance(value, str):
            raise InputError(f"parity: {key} must be an id of the line, got {value!r}")
    spans = {s.id: s for s in ln.spans}
    if span not in spans:
        raise InputError(
            f"parity: span '{span}' is not a span of the line (spans: {', '.join(map(str, spans))})"
        )
    # the sensor roles do not matter for the numbers: any of each kind will do
    for role, typ in (
        ("load_cell", "load_cell"),
        ("upstream_load_cell", "load_cell"),
        ("drive_encoder", "encoder"),
        ("downstream_encoder", "encoder"),
    ):
        roles[role] = next((x.id for x in ln.sensors if x.type == typ), None)
        if roles[role] is None:
            raise InputError(f"parity: the line has no {typ.replace('_', ' ')}")
    return line_numbers(ln, roles)


#: physically plausible ranges of the reduced model's numbers (value from, to, unit): far
#: outside them the design corners overflow or underflow and the fit failed inside numpy
#: (EA = 1e308 N or 1e-300 N: "SVD did not converge"). EA spans the webs that
#: r2rsim.schema.plausibility accepts without a warning (modulus x thickness x width, from
#: elastomer tape, 0.1 N, to metal strip, 2.7e10 N); span and pitch lengths from the shortest
#: span it accepts (1 mm) to the longest without a warning (100 m); radii from a 1 mm rod to a
#: 10 m roll.
_PHYSICAL_RANGES = {
    "web_EA_N": (
        P.MODULUS_RANGE[0] * P.THICKNESS_RANGE[0] * P.WIDTH_RANGE[0],
        P.MODULUS_RANGE[1] * P.THICKNESS_RANGE[1] * P.WIDTH_RANGE[1],
        "N",
    ),
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
    span, drive, downstream, pitch_sensor, load_cell, upstream_load_cell, drive_encoder, \
downstream_encoder : str, optional
        Ids of the line's roles: the registration span, the driven roller upstream of it, the
        roller ending it, the pitch-length sensor on it (sensor B), the load cell on the
        downstream roller (sensor A), the load cell on the element upstream of the driven
        roller (T_up), the encoders on the driven and the downstream rollers. None: from
        ``preset``, else inferred from the run's line (the only sensor of the kind at that
        place; see :func:`~r2rsim.diagnostics.parity.find_roles`). A wrong, missing or
        ambiguous role is refused with one line listing the line's candidates.
    preset : {"thesis_registration"}, optional
        Fill the roles not given with the thesis line's ids (``registration``,
        ``reg_drive``, ``reg_idler``, ``sensor_B``, ``sensor_A``, ``lc_unwind``,
        ``u_drive``, ``u_out``).
    line : str, optional
        A line file, used for frames that carry no line of their own (the harness's frames
        carry their run's: :func:`r2rsim.diagnostics.line.frame_line`).
    web_EA_N, span_length_m, drive_radius_m, downstream_radius_m : float, optional
        Web axial stiffness EA [N], span length L [m], radii of the driven and downstream
        rollers [m]. None: read from the line through the roles; a value given overrides the
        line's (a scored line that differs then warns instead of refusing). Without a line
        they must be given.
    relaxed_pitch_m : float, optional
        Relaxed pitch L0 [m]; None calibrates it on the healthy training runs (Hooke's law
        between sensors A and B).
    sensor_a, sensor_b, drive_speed, downstream_speed, upstream_tension : str, optional
        The channels of y_A [N], y_B [m], ω_d [rad/s], ω_o [rad/s] and T_up [N]; None:
        ``meas.<load_cell>.tension_N``, ``meas.<pitch_sensor>.pitch_m``,
        ``meas.<drive_encoder>.speed_rad_s``, ``meas.<downstream_encoder>.speed_rad_s``,
        ``meas.<upstream_load_cell>.tension_N``.
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

    With a line, :meth:`score` (and :meth:`calibrate`) reads the scored run's line through
    the fitted roles: a missing role, or an E·A, L or radius that differs from the fitted
    model's, is refused (``fit on data of this line``); a different relaxed pitch, or a
    differing number that was given as a parameter, only warns.

    Attributes
    ----------
    roles_ : dict
        Role -> id in the line (None for a role nothing named, without a line).
    columns_ : dict
        Column parameter -> the column used.
    physical_ : dict
        ``web_EA_N``, ``span_length_m``, ``relaxed_pitch_m``, ``drive_radius_m``,
        ``downstream_radius_m`` of the model.
    sources_ : dict
        Where each of them came from: ``parameter``, ``line`` or ``calibrated``.
    line_numbers_ : dict or None
        The numbers the training runs' line gives (the relaxed pitch: the pitch sensor's
        nominal value), or None without a line.
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

    def __init__(
        self,
        line: str | None = None,
        preset: str | None = None,
        span: str | None = None,
        drive: str | None = None,
        downstream: str | None = None,
        pitch_sensor: str | None = None,
        load_cell: str | None = None,
        upstream_load_cell: str | None = None,
        drive_encoder: str | None = None,
        downstream_encoder: str | None = None,
        web_EA_N: float | None = None,
        span_length_m: float | None = None,
        relaxed_pitch_m: float | None = None,
        drive_radius_m: float | None = None,
        downstream_radius_m: float | None = None,
        sensor_a: str | None = None,
        sensor_b: str | None = None,
        drive_speed: str | None = None,
        downstream_speed: str | None = None,
        upstream_tension: str | None = None,
        design: str = "fault_normalised",
        mode: str = "model",
        savgol_window_s: float = 3.0,
        savgol_order: int = 2,
        causal: bool = True,
        time_base: str = "travel",
        modulus_spread: float = 0.02,
        pitch_spread_m: float = 5e-6,
        signature_z: float = 3.0,
        alpha: float = 0.01,
    ):
        self.line = line
        self.preset = preset
        self.span = span
        self.drive = drive
        self.downstream = downstream
        self.pitch_sensor = pitch_sensor
        self.load_cell = load_cell
        self.upstream_load_cell = upstream_load_cell
        self.drive_encoder = drive_encoder
        self.downstream_encoder = downstream_encoder
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
        """y_A, y_B, ω_d, ω_o, T_up columns, in that order (after :meth:`configure`: the
        columns built from the roles where not given)."""
        cols = getattr(self, "columns_", None) or {k: getattr(self, k) for k in COLUMNS}
        return [cols[k] for k in COLUMNS]

    def _validate(self):
        if self.design not in KINDS:
            raise InputError(
                f"parity: design must be one of {', '.join(KINDS)}, got {self.design!r}"
            )
        if self.time_base not in TIME_BASES:
            raise InputError(
                f"parity: time_base must be one of {', '.join(TIME_BASES)}, got {self.time_base!r}"
            )
        if self.mode not in MODES:
            raise InputError(f"parity: mode must be one of {', '.join(MODES)}, got {self.mode!r}")
        if self.line is not None and not isinstance(self.line, (str, Path)):
            raise InputError(f"parity: line must be the path of a line file, got {self.line!r}")
        if self.preset is not None and self.preset not in PRESETS:
            raise InputError(
                f"parity: preset must be one of {', '.join(PRESETS)} or null, got {self.preset!r}"
            )
        for key in ROLES:
            if getattr(self, key) is not None and not isinstance(getattr(self, key), str):
                raise InputError(
                    f"parity: {key} must be an id of the line (a string) or "
                    f"null, got {getattr(self, key)!r}"
                )
        for key in COLUMNS:
            if getattr(self, key) is not None and not isinstance(getattr(self, key), str):
                raise InputError(
                    f"parity: {key} must be a column name (a string) or null, "
                    f"got {getattr(self, key)!r}"
                )
        if not isinstance(self.causal, bool):
            raise InputError(f"parity: causal must be true or false, got {self.causal!r}")
        for key in (
            "web_EA_N",
            "span_length_m",
            "drive_radius_m",
            "downstream_radius_m",
            "savgol_window_s",
            "signature_z",
        ):
            if getattr(self, key) is None and key in NUMBERS:
                continue  # read from the run's line
            if not (np.isfinite(v := self._number(key)) and v > 0):
                raise InputError(
                    f"parity: {key} must be a positive number, got {getattr(self, key)!r}"
                )
        for key, (low, high, unit) in _PHYSICAL_RANGES.items():
            if getattr(self, key) is None:
                continue  # read from the line (the relaxed pitch: calibrated)
            if not low <= self._number(key) <= high:
                raise InputError(
                    f"parity: {key} must be from {low:g} to {high:g} {unit} "
                    f"or null, got {getattr(self, key)!r}"
                )
        # upper limits: beyond them the design corners or the windows mean nothing, and
        # a fit would overflow or allocate without bound
        for key, low, high, unit in (
            ("modulus_spread", 0.0, 0.5, ""),
            ("pitch_spread_m", 0.0, 1e-3, " m"),
            ("savgol_window_s", 0.0, 600.0, " s"),
        ):
            if not low <= self._number(key) <= high:
                raise InputError(
                    f"parity: {key} must be from {low:g} to {high:g}{unit}, "
                    f"got {getattr(self, key)!r}"
                )
        self._check_int("savgol_order", 2, 10)
        self._check_alpha()

    # ---- the line: roles, numbers, columns ---------------------------------------------------
    def _given_roles(self) -> dict:
        """The role ids given as parameters, completed by the preset's."""
        given = dict(PRESETS.get(self.preset) or {})
        given.update({k: getattr(self, k) for k in ROLES if getattr(self, k) is not None})
        return given

    def _fallback_line(self):
        """The ``line=`` file, loaded (None without one)."""
        if self.line is None:
            return None
        from ...schema.loader import load_line

        try:
            return load_line(Path(self.line))
        except InputError as exc:
            raise InputError(f"parity: line: {exc.format()}") from None

    def configure(self, frames) -> ParitySpaceDetector:
        """Find the roles, the numbers and the columns of the reduced model (before
        :meth:`fit`; the GSMMS plug-in's physics term uses it too): sets ``roles_``,
        ``columns_``, ``physical_`` (the relaxed pitch None until calibrated),
        ``sources_`` (where each number came from: ``parameter``, ``line`` or
        ``calibrated``) and ``line_numbers_`` (the numbers the line gives, or None).

        The line is the frames' (``frame.attrs``, :func:`r2rsim.diagnostics.line.frame_line`),
        else the ``line=`` file. Every frame's line must give the same E·A, L and radii."""
        from ..line import frame_line

        self._validate()
        fallback = self._fallback_line()
        given = self._given_roles()
        lines = [frame_line(f) for f in frames]
        lines = [ln for ln in lines if ln is not None] or ([fallback] if fallback else [])
        roles = {k: given.get(k) for k in ROLES}
        numbers = None
        if lines:
            roles = find_roles(lines[0], given)
            numbers = line_numbers(lines[0], roles)
            for ln in lines[1:]:
                self._line_check(
                    ln,
                    roles,
                    numbers,
                    "a training run's line",
                    "fit on runs of one line",
                    explicit_ok=True,
                )
        self.roles_ = roles
        self.line_numbers_ = numbers
        self.physical_, self.sources_ = {}, {}
        missing = []
        for key in NUMBERS:
            if getattr(self, key) is not None:
                self.physical_[key], self.sources_[key] = float(getattr(self, key)), "parameter"
            elif key == "relaxed_pitch_m":
                self.physical_[key], self.sources_[key] = None, "calibrated"
            elif numbers is not None:
                self.physical_[key], self.sources_[key] = numbers[key], "line"
            else:
                missing.append(key)
        built = role_columns(roles)
        self.columns_ = {
            k: getattr(self, k) if getattr(self, k) is not None else built[k] for k in COLUMNS
        }
        missing += [k for k, v in self.columns_.items() if v is None]
        if missing:
            raise InputError(
                f"parity: the frames carry no line and line= is not given, so nothing gives "
                f"{', '.join(missing)}: give line=<line file>, or preset=thesis_registration "
                f"with web_EA_N, span_length_m, drive_radius_m and downstream_radius_m, or "
                f"those numbers with the columns sensor_a, sensor_b, drive_speed, "
                f"downstream_speed and upstream_tension"
            )
        return self

    def _line_check(
        self, line, roles, numbers, what: str, advice: str, explicit_ok: bool = False
    ) -> dict:
        """The numbers of ``line`` through ``roles``, compared with ``numbers``: a missing
        role or a different E·A, L or radius is refused (warned instead for a number given
        as a parameter), a different relaxed pitch warned. Returns the line's numbers."""
        try:
            mine = line_numbers(line, roles)
        except InputError as exc:
            raise InputError(
                f"parity: {what} does not have the fitted roles: "
                f"{exc.message.removeprefix('parity: ')}: {advice}"
            ) from None
        where = {
            "span_length_m": f"span '{roles['span']}'",
            "drive_radius_m": f"drive '{roles['drive']}'",
            "downstream_radius_m": f"downstream '{roles['downstream']}'",
            "relaxed_pitch_m": f"pitch_sensor '{roles['pitch_sensor']}'",
            "web_EA_N": "the web's modulus x thickness x width",
        }
        for key in NUMBERS:
            a, b = mine[key], numbers[key]
            if abs(a - b) <= 1e-9 * max(abs(a), abs(b)):
                continue
            unit = _PHYSICAL_RANGES[key][2]
            msg = (
                f"parity: {what} has {key} {a:g} {unit} where the model was fitted with "
                f"{b:g} {unit} ({where[key]})"
            )
            if key == "relaxed_pitch_m":
                warnings.warn(
                    f"{msg}: the relaxed pitch is calibrated on the training runs", stacklevel=3
                )
            elif getattr(self, key) is not None and not explicit_ok:
                warnings.warn(f"{msg}; {key} was given as a parameter, which is used", stacklevel=3)
            elif getattr(self, key) is None:
                raise InputError(f"{msg}: {advice}")
        return mine

    def _scored_frame(self, run) -> pd.DataFrame:
        """The frame of a run to score, its line (if it carries one) checked against the
        fitted model's."""
        from ..line import frame_line

        f = self._frames(run)[0]
        line = frame_line(f)
        if line is not None and getattr(self, "line_numbers_", None) is not None:
            self._line_check(
                line,
                self.roles_,
                self.line_numbers_,
                "the scored run's line",
                "fit on data of this line",
            )
        return f

    def required_columns(self, frame: pd.DataFrame) -> list[str]:
        super().required_columns(frame)
        # before a fit: the columns of the roles in this frame's line
        cols = (
            self.channels
            if getattr(self, "columns_", None)
            else copy.copy(self).configure([frame]).channels
        )
        missing = [c for c in cols if c not in frame.columns]
        if missing:
            raise InputError(
                f"parity: the data has no column matching {', '.join(missing)} "
                f"(set sensor_a, sensor_b, drive_speed, downstream_speed, "
                f"upstream_tension)"
            )
        X = frame[cols].to_numpy(float)
        dead = [c for j, c in enumerate(cols) if not np.isfinite(X[:, j]).any()]
        if dead:
            raise InputError(
                f"parity: {', '.join(dead)} has no finite sample in this run (a "
                f"dead sensor: the relations need every channel)"
            )
        return list(cols)

    def _check_alive(self, X: np.ndarray) -> None:
        """Every channel (a column of X) has a finite sample: the relations need them all."""
        dead = [c for j, c in enumerate(self.channels) if not np.isfinite(X[:, j]).any()]
        if dead:
            raise InputError(
                f"parity: {', '.join(dead)} has no finite sample in this run (a "
                f"dead sensor: the relations need every channel)"
            )

    def _model(self, EA=None, L0=None) -> NonlinearModel:
        ph = self.physical_
        return _cached_model(
            float(EA or ph["web_EA_N"]),
            float(ph["span_length_m"]),
            float(L0 or ph["relaxed_pitch_m"]),
            float(ph["drive_radius_m"]),
            float(ph["downstream_radius_m"]),
        )

    def reduced_model(self, frames) -> tuple[NonlinearModel, float, float]:
        """The reduced registration model with its EA [N] and L0 [m]; :meth:`configure`s the
        plug-in on ``frames`` (healthy visible frames) and sets ``model_``. L0 not given is
        calibrated on ``frames`` by Hooke's law between the sensors, y_B = (y_A/EA + 1)·L0
        (the pitch sensor's nominal value, ``line_numbers_``, ignores the roll-radius term).
        The GSMMS plug-in's physics constraint uses it too."""
        self.configure(frames)
        EA = float(self.physical_["web_EA_N"])
        if self.physical_["relaxed_pitch_m"] is None:
            a, b = self.columns_["sensor_a"], self.columns_["sensor_b"]
            ratio = np.concatenate(
                [f[b].to_numpy(float) / (1 + f[a].to_numpy(float) / EA) for f in frames]
            )
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
            raise InputError(
                f"parity: {exc.message} (savgol_window_s = {self.savgol_window_s!r} s)"
            ) from None
        (yA, yB, wd, wo, tu), (dA, dB, dwd, dwo, dtu) = D[0].T, D[1].T
        # a drop-out in the raw sample k marks sample k (not the instant it describes in causal
        # mode): the interpolation bridging it reads the next reading, which is not there yet
        # at k; NaN estimates (the causal filter's first window - 1 samples) have no residual
        bad = ~np.all(np.isfinite(X), axis=1) | ~np.isfinite(D).all(axis=(0, 2))
        return {
            "t": t,
            "Y": np.vstack([yA, dA, yB, dB]),
            "u": np.vstack([wd, wo, tu]),
            "du": np.vstack([dwd, dwo, dtu]),
            "bad": bad,
            "delay": delay,
        }

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
        frames = self._frames(runs)
        self.configure(frames)
        for f in frames:
            self.required_columns(f)
        model, EA, L0 = self.reduced_model(frames)
        sigs = [self._signals(f) for f in frames]
        # rows in newton-equivalents (sensor B through ∂h_B/∂x = L0/EA)
        self.scale_ = np.array([1.0, 1.0, L0 / EA, L0 / EA])
        self.row_order_ = np.array([k for _, k in model.rows])
        P = np.hstack(
            [np.vstack([self._xhat(s, EA, L0)[None], s["u"]])[:, ~s["bad"]] for s in sigs]
        )
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
        corners = [(EA, L0)] + [
            (EA * (1 + a * self.modulus_spread), L0 + b * self.pitch_spread_m)
            for a in (-1, 1)
            for b in (-1, 1)
        ]
        S = []
        for ea, l0 in corners:
            m = self._model(ea, l0)
            E = np.hstack(
                [(self._errors(s, m, ea, l0) / self._rowscale(s))[:, ~s["bad"]] for s in sigs]
            )
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
        d = design_relation(
            self.S_, N, self._faults(), self.design, signs=getattr(self, "fault_signs_", None)
        )
        if not hasattr(self, "fault_signs_"):
            self.fault_signs_ = d.signs  # the design point's; :meth:`sensitivity` keeps them
        return np.vstack([d.omega, *single])

    def _signature_table(self) -> pd.DataFrame:
        """Which relation uses which sensor (True: a fault on that sensor moves it)."""
        sensor_of_row = self.model_.sensor_of_row()
        W = np.abs(self.omega_)
        tab = np.array(
            [
                [W[k, sensor_of_row == j].max() > 1e-9 * W[k].max() for k in range(len(W))]
                for j in range(2)
            ]
        )
        return pd.DataFrame(
            tab, index=self.channels[:2], columns=[f"r{k + 1}" for k in range(len(W))]
        )

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
        f = self._scored_frame(run)
        self.required_columns(f)
        R = self._residuals(self._signals(f))
        out = pd.DataFrame(R.T, index=f.index, columns=[f"r{k + 1}" for k in range(len(R))])
        with np.errstate(invalid="ignore"):
            z = np.abs(R) / self.sigma_[:, None]
        stat = np.where(np.all(np.isfinite(z), axis=0), np.max(np.nan_to_num(z), axis=0), np.nan)
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
        z = np.minimum(np.abs(scores[cols].to_numpy(float)) / self.sigma_, 3 * self.signature_z)
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
        if (
            isinstance(step_s, bool)
            or not isinstance(step_s, (int, float, np.number))
            or not 1e-3 <= step_s <= 1e6
        ):
            raise InputError(
                f"parity: step_s must be a number from 0.001 to 1e+06 s, got {step_s!r}"
            )
        s = self._signals(self._scored_frame(run))
        tk, pk = self._knots(s, step_s)
        names = ["x", "omega_d", "omega_o", "T_up"]
        rows, start = [], self.omega_[0]
        for t, p in zip(tk, pk, strict=False):
            N, dN = self._N(p)
            d = design_relation(
                self.S_, N, self._faults(), self.design, start=start, signs=self.fault_signs_
            )
            start = d.omega
            dJ, dom, _ = sensitivity(d, self.S_, N, self._faults(), dN, self.design)
            row = {"t_s": t, **{f"p.{n}": v for n, v in zip(names, p, strict=False)}, "J": d.J}
            row.update({f"dJ/d{n}": v for n, v in zip(names, dJ, strict=False)})
            for i in range(dom.shape[1]):
                row.update({f"domega{i + 1}/d{n}": dom[k, i] for k, n in enumerate(names)})
            rows.append(row)
        return pd.DataFrame(rows)
