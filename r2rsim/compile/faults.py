"""Fault instances of one run: the scenario's fault entries with their distributions drawn
(from the run's fault-sampling stream), magnitudes in SI, and the profile arithmetic that the
solver (effects inside the loop), the measurement model (effects on the record) and the
labels all share, so the three cannot disagree.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from ..schema.faults import (
    CATALOGUE,
    Choice,
    LogUniform,
    Uniform,
    magnitude_dimension,
    magnitude_unit,
    reading_dimension,
)
from ..units import QuantityError, parse_quantity


@dataclass
class FaultInstance:
    """One fault of one run, every number in SI."""

    id: str
    type: str
    target: str
    onset: float
    end: float | None
    shape: str
    ramp: float | None
    period: float | None
    duty: float | None
    magnitude: float
    unit: str
    rate: float | None = None
    compose: str | None = None
    record_only: bool = False
    composed_with: list[str] = field(default_factory=list)
    sampled_from: str | None = None
    expected_channels: list[str] = field(default_factory=list)
    magnitude_rel: float = math.nan

    @property
    def kind(self):
        return CATALOGUE[self.type]

    def present(self, t: np.ndarray) -> np.ndarray:
        """True where the fault exists (onset <= t < end), whatever its profile does."""
        t = np.asarray(t, float)
        return (t >= self.onset) & (t < (self.end if self.end is not None else np.inf))

    def p(self, t: np.ndarray) -> np.ndarray:
        """Profile p(t) in [0, 1]: the fraction of the magnitude acting at t."""
        t = np.asarray(t, float)
        dt = t - self.onset
        if self.shape == "step":
            out = np.ones_like(t)
        elif self.shape == "ramp":
            assert self.ramp is not None  # set with a ramp or exp profile
            out = np.clip(dt / self.ramp, 0.0, 1.0)
        elif self.shape == "exp":
            assert self.ramp is not None
            out = -np.expm1(-np.maximum(dt, 0.0) / self.ramp)
        else:  # intermittent
            assert self.period is not None and self.duty is not None  # set when intermittent
            phase = np.mod(np.maximum(dt, 0.0), self.period)
            out = (phase < self.duty * self.period - 1e-12).astype(float)
        return np.where(self.present(t), out, 0.0)

    def effect(self, t: np.ndarray) -> np.ndarray:
        """The fault's effect value at t: magnitude·p(t) (a drift: magnitude·(t - onset))."""
        if self.type == "sensor.drift":
            return np.where(self.present(t), self.magnitude * (np.asarray(t) - self.onset), 0.0)
        return self.magnitude * self.p(t)

    def breakpoints(self, duration: float) -> list[float]:
        """Times at which the effect is not smooth (onset, ramp end, switches, end)."""
        stop = min(self.end if self.end is not None else math.inf, duration)
        out = [self.onset]
        if self.shape == "ramp":
            assert self.ramp is not None  # set with a ramp profile
            out.append(self.onset + self.ramp)
        if self.shape == "intermittent":
            assert self.period is not None and self.duty is not None  # set when intermittent
            k = 0
            while True:
                t_on = self.onset + k * self.period
                if t_on >= stop:
                    break
                out += [t_on, t_on + self.duty * self.period]
                k += 1
        if self.end is not None:
            out.append(self.end)
        return sorted({b for b in out if b < duration})

    def segment(self, t: float) -> tuple[float, float, float, float]:
        """Coefficients (a, b, c, tau) with effect(t') = a + b·(t'-t) + c·exp(-(t'-t)/tau)
        for t' from the breakpoint t to the next one."""
        if not self.present(np.array([t]))[0]:
            return 0.0, 0.0, 0.0, 1.0
        m = self.magnitude
        if self.type == "sensor.drift":
            return m * (t - self.onset), m, 0.0, 1.0
        if self.shape == "ramp":
            assert self.ramp is not None  # set with a ramp profile
            if t < self.onset + self.ramp - 1e-12:
                return m * (t - self.onset) / self.ramp, m / self.ramp, 0.0, 1.0
        if self.shape == "exp":
            assert self.ramp is not None  # set with an exp profile
            return m, 0.0, -m * math.exp(-(t - self.onset) / self.ramp), self.ramp
        return m * float(self.p(np.array([t]))[0]), 0.0, 0.0, 1.0

    def record(self, run_id: str, onset_k: int) -> dict:
        """Row of faults.parquet."""
        return {
            "run_id": run_id,
            "fault_id": self.id,
            "fault_type": self.type,
            "fault_class": self.kind.fault_class,
            "target_id": self.target,
            "component_path": self.target,
            "onset_t_s": self.onset,
            "onset_k": onset_k,
            "profile": self.shape,
            "ramp_s": self.ramp,
            "end_t_s": self.end,
            "magnitude": self.magnitude,
            "magnitude_unit": self.unit,
            "magnitude_rel": self.magnitude_rel,
            "params_json": json.dumps(
                {
                    k: v
                    for k, v in (
                        ("period_s", self.period),
                        ("duty", self.duty),
                        ("rate_hz", self.rate),
                        ("compose", self.compose),
                        ("record_only", self.record_only or None),
                    )
                    if v is not None
                }
            ),
            "expected_channels": list(self.expected_channels),
            "composed_with": list(self.composed_with),
            "sampled_from": self.sampled_from,
        }


def loop_sensor_ids(line) -> set[str]:
    """Sensors some controller reads: their faults act inside the simulation. Faults on
    the other (monitoring) sensors act on the record only, and the process is untouched."""
    out = set()
    for c in line.controllers:
        for attr in ("sensor", "radius_sensor", "encoder"):
            v = getattr(c, attr, None)
            if v:
                out.add(v)
    return out


def from_record(row: dict) -> FaultInstance:
    """Rebuild a fault instance from its faults.parquet row (labels and the validator)."""
    params = json.loads(row.get("params_json") or "{}")

    def num(v):
        return None if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)

    return FaultInstance(
        id=row["fault_id"],
        type=row["fault_type"],
        target=row["target_id"],
        onset=float(row["onset_t_s"]),
        end=num(row["end_t_s"]),
        shape=row["profile"],
        ramp=num(row["ramp_s"]),
        period=params.get("period_s"),
        duty=params.get("duty"),
        magnitude=float(row["magnitude"]),
        unit=row["magnitude_unit"],
        rate=params.get("rate_hz"),
        compose=params.get("compose"),
        record_only=bool(params.get("record_only", False)),
        composed_with=list(row["composed_with"] or []),
        sampled_from=row["sampled_from"],
        expected_channels=list(row["expected_channels"] or []),
        magnitude_rel=float(row["magnitude_rel"]) if row["magnitude_rel"] is not None else math.nan,
    )


def _draw(value, dimension, rng, where, file):
    """A number in SI from a fixed value or a distribution; returns (value, spec or None)."""

    def si(v):
        if dimension is None:
            if isinstance(v, str):
                raise InputError(
                    "give this magnitude as a number in SI units", file=file, path=where
                )
            return float(v)
        try:
            return parse_quantity(v, dimension)
        except QuantityError as exc:
            raise InputError(str(exc), file=file, path=where) from None

    if isinstance(value, Uniform):
        lo, hi = si(value.uniform[0]), si(value.uniform[1])
        if not hi >= lo:
            raise InputError("uniform: high must be >= low", file=file, path=where)
        return float(rng.uniform(lo, hi)), json.dumps({"uniform": [lo, hi]})
    if isinstance(value, LogUniform):
        lo, hi = si(value.loguniform[0]), si(value.loguniform[1])
        if not (0 < lo <= hi):
            raise InputError("loguniform needs 0 < low <= high", file=file, path=where)
        return float(math.exp(rng.uniform(math.log(lo), math.log(hi)))), json.dumps(
            {"loguniform": [lo, hi]}
        )
    if isinstance(value, Choice):
        vals = [si(v) for v in value.choice]
        return float(vals[int(rng.integers(len(vals)))]), json.dumps({"choice": vals})
    return si(value), None


def realise_faults(
    scenario, line, seed_sequence, file: str = "<scenario>", channel_of=None
) -> list[FaultInstance]:
    """Draw the run's fault instances.

    Parameters
    ----------
    scenario : Scenario
    line : Line
    seed_sequence : numpy.random.SeedSequence
        The run's fault-sampling stream; each fault draws from its own child, so adding a
        fault does not change the draws of the others.
    channel_of : callable, optional
        ``channel_of(sensor_id)`` -> measured channel name, for ``expected_channels``.
    """
    children = seed_sequence.spawn(len(scenario.faults))
    out = []
    sensors = {s.id: s for s in line.sensors}
    for i, (f, child) in enumerate(zip(scenario.faults, children, strict=True)):
        rng = np.random.default_rng(child)
        where = f"faults[{i}]"
        ft = CATALOGUE[f.type]
        s = sensors[f.target] if ft.target == "sensor" else None
        rdim = reading_dimension(line, s)
        onset, onset_spec = _draw(f.onset, "time", rng, f"{where}.onset", file)
        unit = magnitude_unit(f.type, rdim)
        if ft.magnitude == "none":
            mag, mag_spec = 1.0, None
        else:
            mag, mag_spec = _draw(
                f.magnitude, magnitude_dimension(f.type, rdim), rng, f"{where}.magnitude", file
            )
        if f.end is not None and f.end <= onset:
            raise InputError(
                f"end {f.end:g} s comes before the drawn onset {onset:g} s",
                file=file,
                path=f"{where}.end",
            )
        spec = {k: v for k, v in (("onset", onset_spec), ("magnitude", mag_spec)) if v}
        noise = (getattr(s, "noise", 0.0) or 0.0) if s is not None else 0.0
        rel = math.nan
        if ft.magnitude == "rel":
            rel = abs(mag)
        elif ft.magnitude == "reading" and noise > 0:
            rel = abs(mag) / noise
        inst = FaultInstance(
            id=f.id,
            type=f.type,
            target=f.target,
            onset=onset,
            end=f.end,
            shape=f.profile.shape,
            ramp=f.profile.ramp,
            period=f.profile.period,
            duty=f.profile.duty,
            magnitude=mag,
            unit=unit,
            rate=f.rate,
            compose=f.compose,
            record_only=f.record_only,
            sampled_from=json.dumps({k: json.loads(v) for k, v in spec.items()}) if spec else None,
            expected_channels=[channel_of(f.target)] if channel_of and s is not None else [],
            magnitude_rel=rel,
        )
        out.append(inst)
    for a in out:
        a.composed_with = sorted(
            b.id
            for b in out
            if b is not a and b.target == a.target and _overlap(a, b) and a.compose and b.compose
        )
    return out


def _overlap(a: FaultInstance, b: FaultInstance) -> bool:
    a_end = a.end if a.end is not None else math.inf
    b_end = b.end if b.end is not None else math.inf
    return a.onset < b_end and b.onset < a_end
