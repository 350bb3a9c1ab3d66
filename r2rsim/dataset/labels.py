"""Per-sample labels, derived only from ``faults.parquet`` and ``runs.parquet`` (DESIGN.md §4.3,
fdd-benchmarks.md §6.4). The writer and the validator call the same function, so the labels
in a dataset can always be re-derived and checked.

Semantics
---------
A fault is *present* from its onset (inclusive) to its end (exclusive). ``label.is_faulty``,
``label.n_active`` and ``label.fault_ids`` count present faults. ``label.primary_type`` is
the type of the present fault with the largest ``magnitude_rel`` (the first listed on a tie;
``normal`` when none). ``label.severity`` is that fault's profile p(t) in [0, 1] (ramps and
intermittent off-phases show here). ``label.ch.<channel>`` is true where a sensor fault acts
on that measured channel (p(t) > 0). ``label.phase`` is ``warmup`` before the warm-up ends,
then ``faulty`` or ``normal``, and ``terminated`` on the last sample of a run that ended early.
``label.score_mask`` is false during the warm-up. ``label.mode`` is the operating mode named
by the programme.
"""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa

from ..compile.faults import from_record


def mode_at(modes: list, t: np.ndarray) -> np.ndarray:
    """Operating mode at each time from ``[(t_from, name), ...]`` (empty string before the
    first)."""
    out = np.full(len(t), "", dtype=object)
    for t0, name in sorted(modes, key=lambda m: m[0]):
        out[np.asarray(t) >= t0 - 1e-12] = name
    return out


def _id_lists(ids: np.ndarray, present: np.ndarray) -> pa.ListArray:
    """Per sample, the ids of the present faults in fault order, as an Arrow list array
    (built from offsets: a Python list per sample costs more than the simulation)."""
    counts = present.sum(axis=0)
    offsets = np.zeros(present.shape[1] + 1, dtype=np.int32)
    np.cumsum(counts, out=offsets[1:])
    values = np.broadcast_to(ids[:, None], present.shape).T[present.T]
    return pa.ListArray.from_arrays(pa.array(offsets), pa.array(values, type=pa.string()))


def derive_labels(fault_rows: list[dict], k: np.ndarray, t: np.ndarray, *, warmup: float,
                  modes: list, terminated_k: int | None, sensor_channels: dict[str, str]
                  ) -> dict[str, np.ndarray | pa.Array]:
    """The ``label.*`` columns of a chunk of samples (``label.fault_ids`` as an Arrow list
    array, the others as numpy arrays).

    Parameters
    ----------
    fault_rows : list of dict
        The run's rows of faults.parquet.
    k, t : ndarray
        Sample indices and times of the chunk.
    warmup : float
        ``warmup_s`` of the run.
    modes : list of (float, str)
        Operating-mode schedule of the run.
    terminated_k : int or None
        Index of the last sample of a run that ended early.
    sensor_channels : dict
        Sensor id -> measured channel name without the ``meas.`` prefix.
    """
    n = len(t)
    faults = [from_record(r) for r in fault_rows]
    present = np.array([f.present(t) for f in faults], dtype=bool).reshape(len(faults), n)
    prof = np.array([f.p(t) for f in faults], dtype=float).reshape(len(faults), n)
    n_active = present.sum(axis=0)
    rel = np.array([f.magnitude_rel if not math.isnan(f.magnitude_rel) else -1.0
                    for f in faults])
    # primary: the present fault with the largest magnitude_rel (first on ties)
    score = np.where(present, rel[:, None], -np.inf)
    primary = np.argmax(score, axis=0) if len(faults) else np.zeros(n, int)
    any_on = n_active > 0
    types = np.array([f.type for f in faults] + ["normal"], dtype=object)
    primary_type = np.where(any_on, types[np.where(any_on, primary, len(faults))], "normal")
    severity = np.where(any_on, prof[primary, np.arange(n)] if len(faults) else 0.0, 0.0)
    ids = np.array([f.id for f in faults], dtype=object)
    fault_ids = _id_lists(ids, present)
    phase = np.where(t < warmup, "warmup", np.where(any_on, "faulty", "normal")).astype(object)
    if terminated_k is not None:
        phase[np.asarray(k) == terminated_k] = "terminated"
    out = {
        "label.is_faulty": any_on,
        "label.n_active": n_active.astype(np.int8),
        "label.fault_ids": fault_ids,
        "label.primary_type": primary_type,
        "label.severity": severity.astype(np.float32),
        "label.phase": phase,
        "label.mode": mode_at(modes, t),
        "label.score_mask": np.asarray(t) >= warmup,
    }
    for sid, chan in sensor_channels.items():
        mask = np.zeros(n, bool)
        for f, p in zip(faults, prof, strict=True):
            if f.target == sid and f.type.startswith("sensor."):
                mask |= p > 0
        out[f"label.ch.{chan}"] = mask
    return out
