"""The samples writer collects the solver's chunks as numpy arrays and builds one Arrow table
per row group (r2rsim.dataset.writer): what it writes must be what converting every chunk to
Arrow wrote, row group by row group, and the earliest non-finite sample is still found."""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from r2rsim.dataset import writer as writer_mod
from r2rsim.dataset.writer import DatasetWriter, undefined_as_null

DICT = pa.dictionary(pa.int8(), pa.string())


def _chunk(rng, k0: int, n: int) -> dict:
    """A chunk like the run's sink hands over: k, t, float64 outputs (some beyond float32's
    range, NaN in a measured one), a tension ratio written as null where it is undefined,
    flags, and the label columns (strings, a list column given as an Arrow array)."""
    k = np.arange(k0, k0 + n, dtype=np.int64)
    ratio = rng.normal(size=n)
    ratio[rng.random(n) < 0.3] = np.inf
    meas = rng.normal(size=n)
    meas[rng.random(n) < 0.1] = np.nan  # a dropout
    ids = [f"f{j % 2}" for j in range(n)]
    return {
        "k": k,
        "t_s": k / 100.0,
        "meas.lc.tension_N": meas,
        "true.lc.tension_N": rng.normal(size=n) * 100.0,
        "state.reg.tension_ratio": ratio,
        "flag.lc.clipped": rng.random(n) < 0.5,
        "label.is_faulty": rng.random(n) < 0.5,
        "label.n_active": rng.integers(0, 3, n).astype(np.int8),
        "label.fault_ids": pa.ListArray.from_arrays(
            pa.array(np.arange(n + 1, dtype=np.int32)), pa.array(ids, pa.string())
        ),
        "label.primary_type": np.array(
            rng.choice(["normal", "sensor.offset", "sensor.gain"], n), dtype=object
        ),
        # str objects made one by one (np.where(...).astype(object)), as derive_labels does
        "label.phase": np.where(k < 40, "warmup", "normal").astype(object),
        "label.severity": rng.random(n).astype(np.float32),
    }


def _as_arrow(name: str, a, typ: pa.DataType) -> pa.Array:
    """One chunk's column converted as the writer converted every chunk before."""
    if typ == DICT:
        return pa.array(a, type=pa.string()).dictionary_encode().cast(DICT)
    if isinstance(a, pa.Array):
        return a
    if typ == pa.float32():
        x = np.asarray(a).astype(np.float32)
        undefined = ~np.isfinite(x)
        if undefined_as_null(name) and undefined.any():
            return pa.array(x, mask=undefined)
        return pa.array(x)
    return pa.array(a, type=typ)


def _expected_groups(chunks: list[dict], schema: pa.Schema, limit: int) -> list[int]:
    """Rows per row group by the rule: a row group ends once its chunks, as Arrow arrays,
    hold ``limit`` bytes."""
    groups, rows, size = [], 0, 0
    for c in chunks:
        size += sum(_as_arrow(f.name, c[f.name], f.type).nbytes for f in schema)
        rows += len(c["k"])
        if size >= limit:
            groups.append(rows)
            rows, size = 0, 0
    if rows:
        groups.append(rows)
    return groups


def _string_dictionary(t: pa.DataType) -> bool:
    """A dictionary of strings, as read back: the writer writes int8 indices, and pyarrow
    before 16 reads every Parquet dictionary column with int32 ones."""
    return pa.types.is_dictionary(t) and t.value_type == pa.string()


def _same(a: list, b: list) -> bool:
    return len(a) == len(b) and all(
        x == y or (isinstance(x, float) and math.isnan(x) and math.isnan(y))
        for x, y in zip(a, b, strict=True)
    )


@pytest.mark.parametrize("limit", [3_000, 20_000, 1 << 24])
def test_many_small_chunks_give_the_rows_and_row_groups_of_arrow_per_chunk(
    tmp_path, monkeypatch, limit
):
    monkeypatch.setattr(writer_mod, "ROW_GROUP_BYTES", limit)
    rng = np.random.default_rng(7)
    chunks, k0 = [], 0
    for n in rng.choice([1, 2, 3, 5, 17, 60], size=80):
        chunks.append(_chunk(rng, k0, int(n)))
        k0 += int(n)
    w = DatasetWriter(tmp_path / "ds", "r1", {"r2rsim.x": "1"})
    for c in chunks:
        w.write_chunk(c)
    w.commit({})
    pf = pq.ParquetFile(tmp_path / "ds" / "samples" / "run_id=r1" / "part-0.parquet")
    # the schema as written: int8 dictionary indices (pyarrow < 16 reads them as int32)
    schema = pa.schema(
        [pa.field(f.name, DICT if _string_dictionary(f.type) else f.type) for f in pf.schema_arrow],
        metadata=pf.schema_arrow.metadata,
    )
    assert schema.field("true.lc.tension_N").type == pa.float32()
    assert schema.field("t_s").type == pa.float64()
    assert _string_dictionary(pf.schema_arrow.field("label.phase").type)
    assert schema.field("label.fault_ids").type == pa.list_(pa.string())
    assert schema.metadata[b"r2rsim.x"] == b"1"
    groups = [pf.metadata.row_group(i).num_rows for i in range(pf.num_row_groups)]
    assert groups == _expected_groups(chunks, schema, limit)
    if limit < 1 << 24:
        assert len(groups) > 1  # the small limits do split the run
    table = pf.read()
    for f in schema:
        want = pa.chunked_array(
            [_as_arrow(f.name, c[f.name], f.type) for c in chunks], type=f.type
        ).to_pylist()
        assert _same(table[f.name].to_pylist(), want), f.name
    assert table["state.reg.tension_ratio"].null_count > 0  # undefined: null, not inf
    # a row group's dictionary lists its strings in the order they first occur in it
    row = 0
    for i, n in enumerate(groups):
        phase = pf.read_row_group(i, columns=["label.phase"])["label.phase"]
        first = list(dict.fromkeys(table["label.phase"].to_pylist()[row : row + n]))
        assert phase.chunk(0).dictionary.to_pylist() == first
        row += n


def test_the_first_nonfinite_sample_is_found_across_chunks_of_one_row_group(tmp_path):
    rng = np.random.default_rng(1)
    w = DatasetWriter(tmp_path / "ds", "r1", {})
    try:
        fine = _chunk(rng, 0, 10)
        w.write_chunk(fine)
        assert w.first_nonfinite is None
        later = _chunk(rng, 10, 10)
        later["true.lc.tension_N"][6] = 1e300  # inf as float32
        w.write_chunk(later)
        assert w.first_nonfinite == (0.16, "true.lc.tension_N")
        last = _chunk(rng, 20, 10)
        last["true.lc.tension_N"][0] = np.nan
        w.write_chunk(last)
        assert w.first_nonfinite == (0.16, "true.lc.tension_N")  # the earliest stays
        assert w.n_rows == 30
        # all three chunks are still collected in one row group: the search did not wait
        assert w._pending_rows == 30
    finally:
        w.abort()


def test_the_earliest_row_wins_over_the_column_order(tmp_path):
    rng = np.random.default_rng(2)
    w = DatasetWriter(tmp_path / "ds", "r1", {})
    try:
        c = _chunk(rng, 0, 10)
        c["state.span1.length_m"] = np.ones(10)
        c["act.pull.torque_N_m"] = np.ones(10)
        c["state.span1.length_m"][7] = np.inf
        c["act.pull.torque_N_m"][3] = -np.inf  # a later column, an earlier row
        w.write_chunk(c)
        assert w.first_nonfinite == (0.03, "act.pull.torque_N_m")
    finally:
        w.abort()


def test_memory_stays_within_a_row_group_and_the_caller_may_reuse_its_buffers(
    tmp_path, monkeypatch
):
    limit = 10_000
    monkeypatch.setattr(writer_mod, "ROW_GROUP_BYTES", limit)
    rng = np.random.default_rng(3)
    w = DatasetWriter(tmp_path / "ds", "r1", {})
    buffer = np.empty(25)  # one buffer for every chunk's true. column, as a solver may do
    written = []
    largest = 0
    for i in range(200):
        c = _chunk(rng, 25 * i, 25)
        buffer[:] = rng.normal(size=25)
        c["true.lc.tension_N"] = buffer
        written.append(buffer.astype(np.float32))
        w.write_chunk(c)
        largest = max(largest, w._pending_bytes)
        held = sum(len(col.chunks) for col in w._columns)
        assert held == 0 or w._pending_bytes < limit
    assert largest < limit
    w.commit({})
    pf = pq.ParquetFile(tmp_path / "ds" / "samples" / "run_id=r1" / "part-0.parquet")
    assert pf.num_row_groups > 10
    np.testing.assert_array_equal(
        pf.read(columns=["true.lc.tension_N"])["true.lc.tension_N"].to_numpy(),
        np.concatenate(written),
    )


def test_chunks_without_rows_make_no_row_group(tmp_path):
    rng = np.random.default_rng(4)
    w = DatasetWriter(tmp_path / "ds", "r1", {})
    w.write_chunk(_chunk(rng, 0, 5))
    w._flush_row_group()
    w.write_chunk(_chunk(rng, 5, 0))  # an event at a sample: before, commit raised here
    w.commit({})
    pf = pq.ParquetFile(tmp_path / "ds" / "samples" / "run_id=r1" / "part-0.parquet")
    assert pf.num_row_groups == 1 and pf.metadata.num_rows == 5


def test_a_string_column_with_a_missing_value_is_converted_by_arrow(tmp_path):
    # None is not a string: the chunk goes the way of every chunk before (Arrow), as null
    rng = np.random.default_rng(5)
    w = DatasetWriter(tmp_path / "ds", "r1", {})
    a, b = _chunk(rng, 0, 4), _chunk(rng, 4, 4)
    b["label.primary_type"] = np.array(["normal", None, "x", "normal"], dtype=object)
    w.write_chunk(a)
    w.write_chunk(b)
    w.commit({})
    t = pq.read_table(tmp_path / "ds" / "samples" / "run_id=r1" / "part-0.parquet")
    assert _string_dictionary(t.schema.field("label.primary_type").type)
    assert t["label.primary_type"].to_pylist() == [
        *a["label.primary_type"].tolist(),
        "normal",
        None,
        "x",
        "normal",
    ]
