"""Per-sample labels, derived only from ``faults.parquet`` and ``runs.parquet`` (docs/dataset.md
§4). The writer and the validator call the same function, so the labels
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


class _FaultsAt:
    """The run's faults at the times ``t``: which are present, their profiles p(t), how many
    are on, the primary one (the present fault with the largest ``magnitude_rel``, the first
    on ties; ``len(faults)`` where none is) and its severity. What :func:`derive_labels` and
    :func:`quick_label_problem` both derive from faults.parquet."""

    def __init__(self, fault_rows: list[dict], t: np.ndarray):
        n = len(t)
        self.faults = faults = [from_record(r) for r in fault_rows]
        self.present = np.array([f.present(t) for f in faults], dtype=bool).reshape(len(faults), n)
        self.prof = np.array([f.p(t) for f in faults], dtype=float).reshape(len(faults), n)
        self.n_active = self.present.sum(axis=0)
        self.any_on = self.n_active > 0
        rel = np.array(
            [f.magnitude_rel if not math.isnan(f.magnitude_rel) else -1.0 for f in faults]
        )
        score = np.where(self.present, rel[:, None], -np.inf)
        first = np.argmax(score, axis=0) if faults else np.zeros(n, int)
        self.primary = np.where(self.any_on, first, len(faults))
        self.severity = np.where(
            self.any_on, self.prof[first, np.arange(n)] if faults else 0.0, 0.0
        )

    def sensor_mask(self, sensor_id: str) -> np.ndarray:
        """Where a sensor fault of ``sensor_id`` corrupts its channel (p > 0)."""
        mask = np.zeros(self.present.shape[1], bool)
        for f, p in zip(self.faults, self.prof, strict=True):
            if f.target == sensor_id and f.type.startswith("sensor."):
                mask |= p > 0
        return mask


def derive_labels(
    fault_rows: list[dict],
    k: np.ndarray,
    t: np.ndarray,
    *,
    warmup: float,
    modes: list,
    terminated_k: int | None,
    sensor_channels: dict[str, str],
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
    fa = _FaultsAt(fault_rows, t)
    faults, present, any_on, n_active = fa.faults, fa.present, fa.any_on, fa.n_active
    types = np.array([f.type for f in faults] + ["normal"], dtype=object)
    primary_type = np.where(any_on, types[fa.primary], "normal")
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
        "label.severity": fa.severity.astype(np.float32),
        "label.phase": phase,
        "label.mode": mode_at(modes, t),
        "label.score_mask": np.asarray(t) >= warmup,
    }
    for sid, chan in sensor_channels.items():
        out[f"label.ch.{chan}"] = fa.sensor_mask(sid)
    return out


def fault_presence(fault_rows: list[dict], t: np.ndarray) -> tuple[list, np.ndarray]:
    """Where each of a run's faults is present, by the rule of ``label.is_faulty``.

    A fault is present for ``onset_t_s <= t < end_t_s`` (docs/dataset.md §4), the same
    derivation as :func:`derive_labels`, so the OR over every fault is ``label.is_faulty``;
    the OR over some of them (one fault type or class) is a label of those faults alone
    (``r2rsim export --label``).

    Parameters
    ----------
    fault_rows : list of dict
        The run's rows of faults.parquet.
    t : ndarray
        Sample times.

    Returns
    -------
    faults : list of FaultInstance
        The faults, in faults.parquet order (``.type`` is the catalogue type).
    present : ndarray of bool, shape (len(faults), len(t))
    """
    fa = _FaultsAt(fault_rows, t)
    return fa.faults, fa.present


# ---- checking stored labels against their derivation (r2rsim validate, every reader) ------


def label_column(batch, name: str) -> np.ndarray | pa.Array:
    """A column of a record batch (or table) as numpy, strings as Python objects (a
    dictionary-encoded one taken from its dictionary, not decoded string by string); a list
    column stays an Arrow array."""
    col = batch.column(name)
    if isinstance(col, pa.ChunkedArray):
        col = (
            col.unify_dictionaries().combine_chunks()
            if pa.types.is_dictionary(col.type)
            else col.combine_chunks()
        )
    if pa.types.is_dictionary(col.type):
        if col.null_count == 0:
            values = col.dictionary.to_numpy(zero_copy_only=False)
            if values.dtype != object:
                values = values.astype(object)
            return values[col.indices.to_numpy(zero_copy_only=False)]
        col = col.dictionary_decode()
    if pa.types.is_list(col.type) or pa.types.is_large_list(col.type):
        return col
    return col.to_numpy(zero_copy_only=False)


def _item(v):
    if isinstance(v, pa.Scalar):
        return v.as_py()
    return v.item() if isinstance(v, np.generic) else v


def first_list_difference(got: pa.Array, expected: pa.Array) -> int | None:
    """Index of the first row where two Arrow list arrays differ (null lists differ)."""
    if not (pa.types.is_list(got.type) or pa.types.is_large_list(got.type)):
        return 0
    n_got = got.value_lengths().fill_null(-1).to_numpy()
    n_exp = expected.value_lengths().fill_null(-1).to_numpy()
    diff = n_got != n_exp
    if not diff.any():  # same lengths: compare the values, mapped back to their rows
        import pyarrow.compute as pc

        v_got, v_exp = got.flatten(), expected.flatten()
        if pa.types.is_dictionary(v_got.type):
            v_got = v_got.dictionary_decode()
        if v_got.type != v_exp.type:
            v_got = v_got.cast(v_exp.type)
        differs = pc.fill_null(pc.not_equal(v_got, v_exp), True).to_numpy(zero_copy_only=False)
        row = np.repeat(np.arange(len(n_got)), np.maximum(n_got, 0))
        diff = np.zeros(len(n_got), dtype=bool)
        diff[row[differs]] = True
    return int(np.argmax(diff)) if diff.any() else None


def first_difference(name: str, got, expected) -> int | None:
    """Index of the first row where a label column differs from its derivation."""
    if isinstance(expected, pa.Array):  # label.fault_ids: lists of ids
        return first_list_difference(got, expected) if isinstance(got, pa.Array) else 0
    exp = np.asarray(expected)
    got = np.asarray(got)
    if name == "label.severity":
        diff = ~np.isclose(got.astype(float), exp.astype(float), rtol=1e-5, atol=1e-6)
    elif exp.dtype == object or got.dtype == object:
        diff = got.astype(object, copy=False) != exp.astype(object, copy=False)
    else:
        diff = got != exp
    diff = np.asarray(diff, dtype=bool)
    return int(np.argmax(diff)) if diff.any() else None


def check_labels(
    batch, k: np.ndarray, want: dict, names: list[str], reported: set[str]
) -> list[str]:
    """The batch's label columns against those derived from faults.parquet (``want``, from
    :func:`derive_labels`): one message per column, at its first difference (``reported``
    holds the columns already told)."""
    problems = []
    for name, expected in want.items():
        if name in reported:
            continue
        if name not in names:
            problems.append(f"label column {name} missing")
            reported.add(name)
            continue
        got = label_column(batch, name)
        bad = first_difference(name, got, expected)
        if bad is not None:
            problems.append(
                f"{name} at k = {k[bad]} is {_item(got[bad])!r}; "
                f"faults.parquet gives {_item(expected[bad])!r}"
            )
            reported.add(name)
    return problems


#: the label columns :func:`quick_label_problem` compares (the others follow from them, the
#: run's warm-up and its programme, not from faults.parquet alone)
QUICK_LABELS = (
    "label.is_faulty",
    "label.n_active",
    "label.primary_type",
    "label.severity",
    "label.score_mask",
)


def quick_label_problem(table: pa.Table, run: dict, fault_rows: list[dict]) -> str | None:
    """The cheap part of the label check: every label that faults.parquet determines,
    compared sample by sample with what the fault rows give, in numeric form.

    ``label.is_faulty``, ``label.n_active``, ``label.severity``, ``label.score_mask`` and
    every ``label.ch.*`` mask are compared as numbers; ``label.primary_type`` by the index of
    the fault it names (its dictionary codes, not its strings). So an edited onset, end,
    ramp, fault type, target or ranking in faults.parquet is found at its first sample. Not
    compared: ``label.fault_ids``, ``label.phase`` and ``label.mode`` (string columns that
    ``r2rsim validate`` compares in full, with :func:`derive_labels`).

    Returns
    -------
    str or None
        The first difference, naming the column, the sample ``k`` and both values.
    """
    t = table.column("t_s").to_numpy()
    k = table.column("k").to_numpy()
    fa = _FaultsAt(fault_rows, t)
    want = {
        "label.is_faulty": fa.any_on,
        "label.n_active": fa.n_active,
        "label.severity": fa.severity.astype(np.float32),
        "label.score_mask": t >= run["warmup_s"],
    }
    for name in table.column_names:
        if name.startswith("label.ch."):
            want[name] = fa.sensor_mask(name[len("label.ch.") :].split(".")[0])
    for name, expected in want.items():
        if name not in table.column_names:
            return f"label column {name} missing"
        got = table.column(name).to_numpy()
        bad = first_difference(name, got, expected)
        if bad is not None:
            return (
                f"{name} at k = {k[bad]} is {_item(got[bad])!r}; faults.parquet gives "
                f"{_item(expected[bad])!r}"
            )
    return _primary_problem(table, k, fa.primary, [f.type for f in fa.faults])


def _primary_problem(table: pa.Table, k, primary: np.ndarray, types: list[str]) -> str | None:
    """``label.primary_type`` against the derived primary fault, through the column's
    dictionary codes."""
    if "label.primary_type" not in table.column_names:
        return "label column label.primary_type missing"
    col = table.column("label.primary_type")
    names = [*types, "normal"]
    if pa.types.is_dictionary(col.type):
        col = col.unify_dictionaries().combine_chunks() if isinstance(col, pa.ChunkedArray) else col
        words = col.dictionary.to_pylist()
        got = col.indices.to_numpy(zero_copy_only=False)
        # each stored word's meaning as a fault index; several faults may share a type
        ok = np.zeros((len(words), len(names)), bool)
        for i, w in enumerate(words):
            ok[i] = [w == name for name in names]
        bad = ~ok[got, primary]
    else:
        got_words = col.to_numpy(zero_copy_only=False)
        bad = got_words != np.array(names, dtype=object)[primary]
    if not bad.any():
        return None
    i = int(np.argmax(bad))
    stored = col[i].as_py() if not isinstance(col, pa.DictionaryArray) else col[i].as_py()
    return (
        f"label.primary_type at k = {k[i]} is {stored!r}; faults.parquet gives "
        f"{names[primary[i]]!r}"
    )
