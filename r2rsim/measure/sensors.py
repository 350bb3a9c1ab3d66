"""Measured channels of the line's sensors.

Controllers act on the reading each sensor delivers inside the simulation: calibration
gain/offset, first-order filter and the in-loop sensor faults (offset, gain, drift, stuck,
dropout-hold) of the sensors they read. A sensor no controller reads gets those faults here,
on its record, so the process is bit-for-bit untouched by them. The recorded measured channel
takes the reading on the sensor's own sample clock and adds, in this order: delay
(nominal + ``sensor.delay`` faults), Gaussian noise (nominal + ``sensor.noise`` faults),
speed-dependent noise (``noise_per_speed``·|v|, v the web speed at the sensor),
``sensor.spike`` faults, quantisation (nominal, ``sensor.quantization`` faults), clipping to
the sensor's range, and NaN where a ``sensor.dropout`` fault acts. An encoder with
``counts_per_rev`` first turns the speed it sees into an edge count: the roller angle (the
trapezoid integral of that speed over the record samples, from a random initial angle) is
counted as ``floor(angle·cpr/2π)``, and the reading is the count difference over its
``window`` (default one sample period) times 2π/(cpr·window); the counts telescope, so the
quantisation is zero-mean. Every random draw comes from the run's measurement stream
(one child per sensor, one per fault), only at the sensor's sample instants, so it depends
neither on solver steps nor on how the run was chunked.
"""

from __future__ import annotations

import math

import numpy as np

from ..compile.compiler import CompiledLine
from ..compile.faults import loop_sensor_ids

_QUANTITY = {
    "load_cell": ("tension", "N"),
    "encoder": ("speed", "rad_s"),
    "roll_diameter": ("diameter", "m"),
    "pitch_length": ("pitch", "m"),
    "dancer_position": ("position", None),
}
_RECORD_FAULTS = (
    "sensor.noise",
    "sensor.spike",
    "sensor.quantization",
    "sensor.delay",
    "sensor.dropout",
)


def _speed_node(cl: CompiledLine, sensor) -> str:
    """The element whose surface speed is the web speed at a sensor (a span's or festoon's:
    its downstream element)."""
    where = getattr(sensor, "element", None) or sensor.span
    if where in cl.node_ids:
        return where
    return cl.node_ids[cl.span_ids.index(where) + 1]


def channel_names(cl: CompiledLine, sensor) -> tuple[str, str, str]:
    """(measured column, true column, unit suffix of the column names) of a sensor; the
    unit as channels.parquet writes it is :func:`unit_of_suffix` of the suffix."""
    q, u = _QUANTITY[sensor.type]
    if u is None:  # dancer position: m (travel) or rad (arm angle)
        u = next(
            n for n in cl.aux_names if n.startswith(f"{sensor.id}.{q}_") and "_seen_" not in n
        ).rsplit("_", 1)[1]
    return f"meas.{sensor.id}.{q}_{u}", f"true.{sensor.id}.{q}_{u}", u


def unit_of_suffix(suffix: str) -> str:
    """The unit a column-name suffix stands for (``rad_s`` -> ``rad/s``; ``N``, ``m``, ``rad``
    as they are)."""
    return suffix.replace("rad_s", "rad/s")


class MeasurementModel:
    """Stateful per-run measurement of every sensor (keeps hold values and delay history
    across chunks).

    Parameters
    ----------
    cl : CompiledLine
    record_rate : float
        Rate of the recorded samples [Hz].
    seed_sequence : numpy.random.SeedSequence
        The run's measurement-noise stream; one child per sensor, then one per fault, then a
        second one per sensor (an encoder's initial angle, then speed-dependent noise).
    faults : list of FaultInstance
        The run's faults; those on sensors shape the record (see the module docstring).
    """

    def __init__(self, cl: CompiledLine, record_rate: float, seed_sequence, faults=()):
        self.cl = cl
        self.record_rate = record_rate
        in_loop = loop_sensor_ids(cl.line)
        children = seed_sequence.spawn(len(cl.sensors))
        fault_children = seed_sequence.spawn(len(faults))
        # spawned after the existing children: their streams (and old data) stay as they were
        extra_children = seed_sequence.spawn(len(cl.sensors))
        self.channels = []
        for s, child, extra in zip(cl.sensors, children, extra_children, strict=True):
            q, _ = _QUANTITY[s.type]
            name, true, u = channel_names(cl, s)
            rate = min(s.rate or record_rate, record_rate)
            mine = [
                (f, np.random.default_rng(c))
                for f, c in zip(faults, fault_children, strict=True)
                if f.target == s.id
            ]
            self.channels.append(
                {
                    "sensor": s,
                    "name": name,
                    "true": true,
                    "seen_col": cl.aux_index(f"{s.id}.{q}_seen_{u}"),
                    "true_col": cl.aux_index(f"{s.id}.{q}_{u}"),
                    "rate": rate,
                    "last_tick": None,
                    "held": math.nan,
                    "clip_held": False,
                    "rng": np.random.default_rng(child),
                    "faults": mine,
                    "hist_t": np.zeros(0),
                    "hist_v": np.zeros(0),
                    "record_loop_faults": [
                        f
                        for f, _ in mine
                        if f.kind.acts == "loop" and (s.id not in in_loop or f.record_only)
                    ],
                    "stuck_at": {},
                    "speed_col": (
                        cl.aux_index(f"{_speed_node(cl, s)}.surface_speed_m_s")
                        if s.noise_per_speed > 0
                        else None
                    ),
                    "rng_extra": np.random.default_rng(extra),
                }
            )
            ch = self.channels[-1]
            if s.type == "encoder" and s.counts_per_rev:
                # random initial roller angle: the quantisation phase of the count
                ch["enc"] = {
                    "theta0": float(ch["rng_extra"].uniform(0.0, 2.0 * math.pi)),
                    "window": float(s.window or 1.0 / rate),
                    "t0": None,
                    "om0": 0.0,
                    "ht": np.zeros(0),
                    "hth": np.zeros(0),
                }

    def measure(self, t: np.ndarray, aux: np.ndarray) -> dict[str, np.ndarray]:
        """Measured and true channels (and clip flags) for one chunk of samples.

        Parameters
        ----------
        t : numpy.ndarray
            Record times of the chunk [s], increasing, continuing the previous chunk.
        aux : numpy.ndarray
            Algebraic outputs at those times (rows; columns ``cl.aux_names``).

        Returns
        -------
        dict
            Column name -> values; the same whatever the chunking of the run.
        """
        out = {}
        for ch in self.channels:
            s = ch["sensor"]
            seen = aux[:, ch["seen_col"]]
            ticks = np.floor(t * ch["rate"] + 1e-6).astype(np.int64)
            prev = np.concatenate(
                [[ch["last_tick"] if ch["last_tick"] is not None else -1], ticks[:-1]]
            )
            fresh = ticks != prev
            nf = int(fresh.sum())
            tt = t[fresh]
            if "enc" in ch:
                vals = self._encoder_counts(ch, t, seen, fresh, tt)
            else:
                vals = seen[fresh].copy()
            vals = self._loop_faults_on_record(ch, tt, vals)
            vals = self._delay(ch, tt, vals)
            if s.noise > 0:
                vals += s.noise * ch["rng"].standard_normal(nf)
            if ch["speed_col"] is not None:  # vibration: std proportional to the web speed
                v = np.abs(aux[fresh, ch["speed_col"]])
                vals += s.noise_per_speed * v * ch["rng_extra"].standard_normal(nf)
            quant = np.full(nf, s.quantization)
            dropped = np.zeros(nf, bool)
            for f, rng in ch["faults"]:
                eff = f.effect(tt)
                on = f.p(tt) > 0
                if f.type == "sensor.noise":  # drawn at every tick: the stream stays aligned
                    vals += eff * rng.standard_normal(nf)
                elif f.type == "sensor.spike":
                    # a tick's two draws (hit, sign) side by side, so that the stream is
                    # consumed tick by tick whatever the chunks (hit for a whole chunk and
                    # then sign moved the draws with the chunk boundaries)
                    u = rng.random((nf, 2))
                    hit = u[:, 0] < f.rate / ch["rate"]
                    sign = np.where(u[:, 1] < 0.5, -1.0, 1.0)
                    vals += np.where(hit & on, sign * eff, 0.0)
                elif f.type == "sensor.quantization":
                    quant = np.where(on, np.maximum(quant, eff), quant)
                elif f.type == "sensor.dropout":
                    dropped |= on
            vals = np.where(
                quant > 0, np.round(vals / np.where(quant > 0, quant, 1.0)) * quant, vals
            )
            clipped = np.zeros(nf, bool)
            if s.range is not None:
                lo, hi = s.range
                clipped = (vals < lo) | (vals > hi)
                vals = np.clip(vals, lo, hi)
            vals = np.where(dropped, np.nan, vals)
            clipped &= ~dropped
            # zero-order hold between sensor samples
            idx = np.cumsum(fresh) - 1
            held = np.where(idx >= 0, vals[np.maximum(idx, 0)] if nf else ch["held"], ch["held"])
            held_clip = np.where(
                idx >= 0, clipped[np.maximum(idx, 0)] if nf else ch["clip_held"], ch["clip_held"]
            )
            if nf:
                ch["held"] = vals[-1]
                ch["clip_held"] = bool(clipped[-1])
            ch["last_tick"] = int(ticks[-1]) if len(ticks) else ch["last_tick"]
            out[ch["name"]] = held
            out[ch["true"]] = aux[:, ch["true_col"]]
            if s.range is not None:
                out[f"flag.{s.id}.clipped"] = held_clip.astype(bool)
        return out

    @staticmethod
    def _encoder_counts(ch, t, seen, fresh, tt):
        """Speed of an edge-counting encoder at the sensor sample instants ``tt``.

        The roller angle is the trapezoid integral of the speed the sensor sees over the
        record samples ``t`` (carried across chunks), plus a random initial angle; the count is
        ``floor(angle·cpr/2π)``; the reading is the count difference over the window divided
        by the window, times 2π/cpr. The counts telescope, so the mean reading is unbiased
        (error below one count over the whole record).
        """
        enc = ch["enc"]
        s = ch["sensor"]
        if len(t) == 0:
            return np.zeros(0)
        if enc["t0"] is None:  # first chunk: the angle starts at the random offset
            enc["t0"], enc["om0"] = float(t[0]), float(seen[0])
            inc = 0.5 * (seen[1:] + seen[:-1]) * np.diff(t)
            th = np.add.accumulate(np.concatenate([[enc["theta0"]], inc]))
        else:  # the same sequential sums as in one chunk: the result does not depend on chunks
            tp = np.concatenate([[enc["last"][0]], t])
            op = np.concatenate([[enc["last"][1]], seen])
            inc = 0.5 * (op[1:] + op[:-1]) * np.diff(tp)
            th = np.add.accumulate(np.concatenate([[enc["last"][2]], inc]))[1:]
        enc["last"] = (float(t[-1]), float(seen[-1]), float(th[-1]))
        ht = np.concatenate([enc["ht"], t])
        hth = np.concatenate([enc["hth"], th])
        w = enc["window"]
        th_now = th[fresh]
        tq = tt - w
        th_then = np.interp(tq, ht, hth)
        before = tq < enc["t0"]  # before the record: the speed of its first sample
        th_then = np.where(before, enc["theta0"] + enc["om0"] * (tq - enc["t0"]), th_then)
        k = s.counts_per_rev / (2.0 * math.pi)
        counts = np.floor(th_now * k) - np.floor(th_then * k)
        keep = ht >= ht[-1] - w - 1.0
        enc["ht"], enc["hth"] = ht[keep], hth[keep]
        return counts / (k * w)

    @staticmethod
    def _loop_faults_on_record(ch, tt, vals):
        """Offset, gain, drift, stuck of a sensor no controller reads, as in the kernel."""
        faults = ch["record_loop_faults"]
        if not faults:
            return vals
        gain = np.ones(len(tt))
        bias = np.zeros(len(tt))
        for f in faults:
            if f.type == "sensor.gain":
                gain += f.effect(tt)
            elif f.type in ("sensor.offset", "sensor.drift"):
                bias += f.effect(tt)
        out = gain * vals + bias
        for f in faults:
            if f.type not in ("sensor.stuck", "sensor.dropout"):
                continue
            on = f.p(tt) > 0
            held = ch["stuck_at"].get(f.id)
            for i in range(len(tt)):  # hold the reading of the first sample of each on-phase
                if on[i]:
                    if held is None:
                        held = out[i]
                    out[i] = held
                else:
                    held = None
            ch["stuck_at"][f.id] = held
        return out

    def _delay(self, ch, tt, vals):
        """The reading as it was ``delay`` seconds before each sensor sample."""
        s = ch["sensor"]
        d = np.full(len(tt), float(s.delay))
        for f, _ in ch["faults"]:
            if f.type == "sensor.delay":
                d += f.effect(tt)
        if self._max_delay(ch) == 0.0:
            return vals
        ht = np.concatenate([ch["hist_t"], tt])
        hv = np.concatenate([ch["hist_v"], vals])
        j = np.searchsorted(ht, tt - d + 1e-9, side="right") - 1
        out = hv[np.maximum(j, 0)]
        keep = ht >= (tt[-1] if len(tt) else 0.0) - self._max_delay(ch) - 1.0
        ch["hist_t"], ch["hist_v"] = ht[keep], hv[keep]
        return out

    @staticmethod
    def _max_delay(ch) -> float:
        d = float(ch["sensor"].delay)
        for f, _ in ch["faults"]:
            if f.type == "sensor.delay":
                d += abs(f.magnitude)
        return d
