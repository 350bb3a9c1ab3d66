"""Measured channels of the line's sensors.

Controllers act on the reading each sensor delivers inside the simulation: calibration
gain/offset, first-order filter and the in-loop sensor faults (offset, gain, drift, stuck,
dropout-hold) of the sensors they read. A sensor no controller reads gets those faults here,
on its record, so the process is bit-for-bit untouched by them. The recorded measured channel
takes the reading on the sensor's own sample clock and adds, in this order: delay
(nominal + ``sensor.delay`` faults), Gaussian noise (nominal + ``sensor.noise`` faults),
``sensor.spike`` faults, quantisation (nominal, encoder counts, ``sensor.quantization``
faults), clipping to the sensor's range, and NaN where a
``sensor.dropout`` fault acts. Every random draw comes from the run's measurement stream
(one child per sensor, one per fault), only at the sensor's sample instants, so it depends
neither on solver steps nor on how the run was chunked.
"""

from __future__ import annotations

import math

import numpy as np

from ..compile.compiler import CompiledLine
from ..compile.faults import loop_sensor_ids

_QUANTITY = {"load_cell": ("tension", "N"), "encoder": ("speed", "rad_s"),
             "roll_diameter": ("diameter", "m"), "pitch_length": ("pitch", "m"),
             "dancer_position": ("position", None)}
_RECORD_FAULTS = ("sensor.noise", "sensor.spike", "sensor.quantization", "sensor.delay",
                  "sensor.dropout")


def channel_names(cl: CompiledLine, sensor) -> tuple[str, str, str]:
    """(measured column, true column, unit) of a sensor."""
    q, u = _QUANTITY[sensor.type]
    if u is None:  # dancer position: m (travel) or rad (arm angle)
        u = next(n for n in cl.aux_names
                 if n.startswith(f"{sensor.id}.{q}_") and "_seen_" not in n).rsplit("_", 1)[1]
    return f"meas.{sensor.id}.{q}_{u}", f"true.{sensor.id}.{q}_{u}", u


class MeasurementModel:
    """Stateful per-run measurement of every sensor (keeps hold values and delay history
    across chunks).

    Parameters
    ----------
    cl : CompiledLine
    record_rate : float
        Rate of the recorded samples [Hz].
    seed_sequence : numpy.random.SeedSequence
        The run's measurement-noise stream; one child per sensor, then one per fault.
    faults : list of FaultInstance
        The run's faults; those on sensors shape the record (see the module docstring).
    """

    def __init__(self, cl: CompiledLine, record_rate: float, seed_sequence, faults=()):
        self.cl = cl
        self.record_rate = record_rate
        in_loop = loop_sensor_ids(cl.line)
        children = seed_sequence.spawn(len(cl.sensors))
        fault_children = seed_sequence.spawn(len(faults))
        self.channels = []
        for s, child in zip(cl.sensors, children, strict=True):
            q, _ = _QUANTITY[s.type]
            name, true, u = channel_names(cl, s)
            rate = min(s.rate or record_rate, record_rate)
            mine = [(f, np.random.default_rng(c)) for f, c in zip(faults, fault_children,
                                                                  strict=True)
                    if f.target == s.id]
            self.channels.append({
                "sensor": s, "name": name, "true": true,
                "seen_col": cl.aux_index(f"{s.id}.{q}_seen_{u}"),
                "true_col": cl.aux_index(f"{s.id}.{q}_{u}"),
                "rate": rate, "last_tick": None, "held": math.nan, "clip_held": False,
                "rng": np.random.default_rng(child), "faults": mine,
                "hist_t": np.zeros(0), "hist_v": np.zeros(0),
                "record_loop_faults": [f for f, _ in mine if f.kind.acts == "loop"
                                       and s.id not in in_loop],
                "stuck_at": {},
            })

    def measure(self, t: np.ndarray, aux: np.ndarray) -> dict[str, np.ndarray]:
        """Measured and true channels (and clip flags) for one chunk of samples."""
        out = {}
        for ch in self.channels:
            s = ch["sensor"]
            seen = aux[:, ch["seen_col"]]
            ticks = np.floor(t * ch["rate"] + 1e-6).astype(np.int64)
            prev = np.concatenate([[ch["last_tick"] if ch["last_tick"] is not None else -1],
                                   ticks[:-1]])
            fresh = ticks != prev
            nf = int(fresh.sum())
            tt = t[fresh]
            vals = seen[fresh].copy()
            vals = self._loop_faults_on_record(ch, tt, vals)
            vals = self._delay(ch, tt, vals)
            if s.noise > 0:
                vals += s.noise * ch["rng"].standard_normal(nf)
            quant = np.full(nf, s.quantization)
            dropped = np.zeros(nf, bool)
            for f, rng in ch["faults"]:
                eff = f.effect(tt)
                on = f.p(tt) > 0
                if f.type == "sensor.noise":  # drawn at every tick: the stream stays aligned
                    vals += eff * rng.standard_normal(nf)
                elif f.type == "sensor.spike":
                    hit = rng.random(nf) < f.rate / ch["rate"]
                    sign = np.where(rng.random(nf) < 0.5, -1.0, 1.0)
                    vals += np.where(hit & on, sign * eff, 0.0)
                elif f.type == "sensor.quantization":
                    quant = np.where(on, np.maximum(quant, eff), quant)
                elif f.type == "sensor.dropout":
                    dropped |= on
            if s.type == "encoder" and s.counts_per_rev:
                q = 2 * math.pi * ch["rate"] / s.counts_per_rev  # one count per sample period
                vals = np.round(vals / q) * q
            vals = np.where(quant > 0, np.round(vals / np.where(quant > 0, quant, 1.0))
                            * quant, vals)
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
            held_clip = np.where(idx >= 0, clipped[np.maximum(idx, 0)] if nf else
                                 ch["clip_held"], ch["clip_held"])
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
