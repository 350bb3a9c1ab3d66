"""Measured channels of the line's sensors.

Controllers act on the noise-free signal each sensor delivers inside the simulation
(calibration gain/offset and first-order filter included). The recorded measured channel adds,
on the sensor's own sample clock: zero-order hold at the sensor rate, Gaussian noise from the
measurement stream, and quantisation (encoders). Noise is drawn per sensor from its own child
stream, only at the sensor's sample instants, so it depends neither on solver steps nor on how
the run was chunked.
"""

from __future__ import annotations

import math

import numpy as np

from ..compile.compiler import CompiledLine

_QUANTITY = {"load_cell": ("tension", "N"), "encoder": ("speed", "rad_s"),
             "roll_diameter": ("diameter", "m"), "pitch_length": ("pitch", "m"),
             "dancer_position": ("position", None)}


class MeasurementModel:
    """Stateful per-run measurement of every sensor (keeps hold values across chunks).

    Parameters
    ----------
    cl : CompiledLine
    record_rate : float
        Rate of the recorded samples [Hz].
    seed_sequence : numpy.random.SeedSequence
        The run's measurement-noise stream; one child per sensor.
    """

    def __init__(self, cl: CompiledLine, record_rate: float, seed_sequence):
        self.cl = cl
        self.record_rate = record_rate
        children = seed_sequence.spawn(len(cl.sensors))
        self.channels = []
        for s, child in zip(cl.sensors, children, strict=True):
            q, u = _QUANTITY[s.type]
            if u is None:  # dancer position: m (travel) or rad (arm angle)
                u = next(n for n in cl.aux_names
                         if n.startswith(f"{s.id}.{q}_") and "_seen_" not in n).rsplit("_", 1)[1]
            rate = min(s.rate or record_rate, record_rate)
            self.channels.append({
                "sensor": s, "name": f"meas.{s.id}.{q}_{u}", "true": f"true.{s.id}.{q}_{u}",
                "seen_col": cl.aux_index(f"{s.id}.{q}_seen_{u}"),
                "true_col": cl.aux_index(f"{s.id}.{q}_{u}"),
                "rate": rate, "last_tick": None, "held": math.nan,
                "rng": np.random.default_rng(child),
            })

    def measure(self, t: np.ndarray, aux: np.ndarray) -> dict[str, np.ndarray]:
        """Measured and true channels for one chunk of samples."""
        out = {}
        for ch in self.channels:
            s = ch["sensor"]
            seen = aux[:, ch["seen_col"]]
            ticks = np.floor(t * ch["rate"] + 1e-6).astype(np.int64)
            prev = np.concatenate([[ch["last_tick"] if ch["last_tick"] is not None else -1],
                                   ticks[:-1]])
            fresh = ticks != prev
            nf = int(fresh.sum())
            vals = seen[fresh].copy()
            if s.noise > 0:
                vals += s.noise * ch["rng"].standard_normal(nf)
            if s.type == "encoder" and s.counts_per_rev:
                q = 2 * math.pi * ch["rate"] / s.counts_per_rev  # one count per sample period
                vals = np.round(vals / q) * q
            # zero-order hold between sensor samples
            idx = np.cumsum(fresh) - 1
            held = np.where(idx >= 0, vals[np.maximum(idx, 0)] if nf else ch["held"], ch["held"])
            if nf:
                ch["held"] = vals[-1]
            ch["last_tick"] = int(ticks[-1]) if len(ticks) else ch["last_tick"]
            out[ch["name"]] = held
            out[ch["true"]] = aux[:, ch["true_col"]]
        return out
