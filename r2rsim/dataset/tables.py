"""The tables of a run's dataset besides its samples (docs/dataset.md): its row of
runs.parquet, channels.parquet, faults.parquet, events.parquet and variability.parquet, and
the key-value metadata every Parquet file of the run carries.

:func:`r2rsim.run.execute` builds them from what the run computed and hands them to the
:class:`~r2rsim.dataset.writer.DatasetWriter`; the schema version they follow is
:data:`r2rsim.dataset.writer.SCHEMA_VERSION`.
"""

from __future__ import annotations

import json
import platform
from collections.abc import Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pyarrow as pa

from .._version import __version__
from ..measure.sensors import channel_names, unit_of_suffix
from .writer import EVENTS_SCHEMA, FAULTS_SCHEMA, SCHEMA_VERSION, VARIABILITY_SCHEMA

if TYPE_CHECKING:
    from ..compile.compiler import CompiledLine
    from ..schema import Scenario
    from ..solve import Event

__all__ = [
    "LABEL_CHANNELS",
    "channels_table",
    "events_table",
    "faults_table",
    "file_metadata",
    "runs_table",
    "variability_table",
]


def file_metadata(scenario_sha256: str, root_seed: int) -> dict[str, str]:
    """The key-value metadata of every Parquet file of a run's dataset (``r2rsim.*``)."""
    return {
        "r2rsim.schema_version": SCHEMA_VERSION,
        "r2rsim.version": __version__,
        "r2rsim.scenario_sha256": scenario_sha256,
        "r2rsim.root_seed": str(root_seed),
    }


#: the label columns of every dataset, with their descriptions (channels.parquet)
LABEL_CHANNELS = [
    ("label.is_faulty", "any fault present"),
    ("label.n_active", "number of faults present"),
    ("label.fault_ids", "ids of the faults present"),
    (
        "label.primary_type",
        "type of the present fault with the largest magnitude_rel, else 'normal'",
    ),
    ("label.severity", "profile p(t) of the primary fault, 0-1"),
    ("label.phase", "warmup / normal / faulty / terminated"),
    ("label.mode", "operating mode named by the programme"),
    ("label.score_mask", "false during warm-up"),
]


def channels_table(
    cl: CompiledLine,
    measured: Iterable[Mapping[str, Any]],
    state_columns: Iterable[Mapping[str, Any]],
    sensor_chan: Mapping[str, str],
    rate: float,
) -> pa.Table:
    """channels.parquet: the dictionary of every samples column, in the order they are
    written.

    Parameters
    ----------
    cl : CompiledLine
    measured : iterable of dict
        :attr:`r2rsim.measure.MeasurementModel.channels`, in the order it measures them.
    state_columns : iterable of dict
        :func:`r2rsim.dataset.columns.true_state_columns` of ``cl``.
    sensor_chan : dict
        Sensor id -> its measured channel without ``meas.``.
    rate : float
        The record rate [Hz].
    """
    rows: list[tuple[str, str, str, str, str, float | None]] = [
        ("run_id", "index", "", "", "run id (the hive partition key of samples/)", None),
        ("k", "index", "", "", "sample index from 0", None),
        ("t_s", "index", "s", "", "simulation time", None),
    ]
    for mc in measured:
        s = mc["sensor"]
        unit = unit_of_suffix(channel_names(cl, s)[2])
        where = getattr(s, "element", None) or s.span
        rows.append(
            (
                mc["name"],
                "measured",
                unit,
                where,
                f"{s.type} '{s.id}' on {where}: measured (noise, sampling)",
                mc["rate"],
            )
        )
        rows.append(
            (
                mc["true"],
                "true",
                unit,
                where,
                f"noise- and fault-free shadow of {mc['name']} (never give to algorithms)",
                rate,
            )
        )
        if s.range is not None:
            rows.append(
                (
                    f"flag.{s.id}.clipped",
                    "flag",
                    "",
                    s.id,
                    f"{mc['name']} was clipped to its range {list(s.range)} (censored)",
                    mc["rate"],
                )
            )
    rows += [
        (c["column"], c["kind"], c["unit"], c["component"], c["description"], rate)
        for c in state_columns
    ]
    rows += [(col, "label", "", "", text, None) for col, text in LABEL_CHANNELS]
    rows += [
        (f"label.ch.{c}", "label", "", sid, f"a sensor fault acts on meas.{c}", None)
        for sid, c in sensor_chan.items()
    ]
    return pa.table(
        {
            "channel": [r[0] for r in rows],
            "kind": [r[1] for r in rows],
            "unit": [r[2] for r in rows],
            "component": [r[3] for r in rows],
            "description": [r[4] for r in rows],
            "rate_hz": pa.array([r[5] if r[5] is not None else rate for r in rows], pa.float64()),
        }
    )


def faults_table(fault_rows: Sequence[Mapping[str, Any]]) -> pa.Table:
    """faults.parquet: one row per fault of the run (``Fault.record``)."""
    if not fault_rows:
        return FAULTS_SCHEMA.empty_table()
    return pa.Table.from_pylist(list(fault_rows), schema=FAULTS_SCHEMA)


def events_table(run_id: str, events: Sequence[Event]) -> pa.Table:
    """events.parquet: the run's event log, in time order."""
    return pa.table(
        {
            "run_id": [run_id] * len(events),
            "t_s": [e.t for e in events],
            "kind": [e.kind for e in events],
            "component": [e.component for e in events],
            "state": [e.state for e in events],
            "message": [e.message for e in events],
            "values_json": [json.dumps(e.values) for e in events],
        },
        schema=EVENTS_SCHEMA,
    )


def variability_table(run_id: str, rows: Iterable[Mapping[str, Any]]) -> pa.Table:
    """variability.parquet: the values the run's ``variability:`` drew (ground truth)."""
    return pa.Table.from_pylist([{"run_id": run_id, **r} for r in rows], schema=VARIABILITY_SCHEMA)


def runs_table(
    *,
    run_id: str,
    scenario: Scenario,
    scenario_id: str,
    scenario_sha256: str,
    line_config: str,
    seed_streams: Mapping[str, np.random.SeedSequence],
    modes: Sequence[tuple[float, str]],
    n_samples: int,
    n_faults: int,
    terminated: bool,
    termination_reason: str | None,
    termination_t: float | None,
    simulated_s: float,
    nonfinite_t: float | None,
    ended_as_expected: bool,
    initial_state: str,
    solver: str,
    rhs_evaluations: int,
    wallclock_s: float,
) -> pa.Table:
    """The run's row of runs.parquet.

    ``seed_streams`` maps ``process``, ``measurement`` and ``fault_sampling`` to the run's
    random streams (each is recorded as the first 64-bit word of its state); ``modes`` is
    the programme's ``(at, mode)`` steps.
    """
    seeds = {
        name: int(seed_streams[name].generate_state(1, np.uint64)[0])
        for name in ("process", "measurement", "fault_sampling")
    }
    return pa.table(
        {
            "run_id": [run_id],
            "scenario_id": [scenario_id],
            "scenario_sha256": [scenario_sha256],
            "seed": pa.array([scenario.seed], pa.uint64()),
            "seed_streams": pa.array(
                [seeds],
                pa.struct(
                    [
                        ("process", pa.uint64()),
                        ("measurement", pa.uint64()),
                        ("fault_sampling", pa.uint64()),
                    ]
                ),
            ),
            "split": pa.array([scenario.split_of(scenario.seed)], pa.string()),
            "line_config": [line_config],
            "operating_mode": pa.array(
                ["+".join(dict.fromkeys(m for _, m in modes)) or None], pa.string()
            ),
            "modes_json": [json.dumps(modes)],
            "disturbances_json": [json.dumps([d.model_dump() for d in scenario.disturbances])],
            "sample_period_s": [1.0 / scenario.record_rate],
            "duration_s": [scenario.duration],
            "n_samples": pa.array([n_samples], pa.int64()),
            "warmup_s": [scenario.warmup],
            "has_fault": [n_faults > 0],
            "n_faults": pa.array([n_faults], pa.int16()),
            "terminated": [terminated],
            "termination_reason": pa.array([termination_reason], pa.string()),
            "termination_t_s": pa.array([termination_t], pa.float64()),
            "simulated_s": [float(simulated_s)],
            "nonfinite_from_t_s": pa.array([nonfinite_t], pa.float64()),
            "ended_as_expected": [ended_as_expected],
            "initial_state": [initial_state],
            "solver": [solver],
            "rhs_evaluations": pa.array([rhs_evaluations], pa.int64()),
            "r2rsim_version": [__version__],
            "python_version": [platform.python_version()],
            "numpy_version": [np.__version__],
            "wallclock_s": [wallclock_s],
        }
    )
