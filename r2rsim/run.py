"""Run a scenario end to end: load → compile → initial state → solve → measure → dataset.

This is the Python API behind ``r2rsim run``::

    from r2rsim import run_scenario
    summary = run_scenario("scenarios/quickstart.yaml", output="runs/qs")
"""

from __future__ import annotations

import hashlib
import math
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import yaml

from .compile import CompiledLine, Programme, compile_line
from .compile.disturbances import realise_disturbances, realise_pitch_variations
from .compile.faults import realise_faults
from .compile.variability import RollDraws, joint_slots_needed, realise_variability
from .dataset import DatasetWriter, tables, true_state_columns
from .dataset.labels import derive_labels
from .dataset.validate import validate_dataset
from .dataset.writer import check_output
from .errors import InputError, R2RError
from .limits import MAX_SEED, run_size_problem
from .measure import MeasurementModel
from .measure.sensors import channel_names
from .schema import Line, Scenario, load_scenario
from .schema.loader import read_yaml
from .solve import Event, nominal_state, simulate, steady_state
from .solve.compilewatch import compile_seconds


def ended_as_expected(terminated: bool, reason: str | None, expected, nonfinite_t) -> bool:
    """A run reached its duration, or ended early in a way its scenario's
    ``expect.termination`` lists, with finite states (a solver failure never is expected)."""
    return nonfinite_t is None and (not terminated or reason in expected)


@dataclass
class RunSummary:
    """What ``r2rsim run`` reports at the end."""

    output: Path
    run_id: str
    simulated_s: float
    wall_s: float
    n_samples: int
    tension_stats: dict[str, tuple[float, float, float]]
    events: list
    terminated: bool
    termination_reason: str | None
    termination_time: float | None
    initial_state: str
    solver_stats: dict = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    expected_terminations: list[str] = field(default_factory=list)
    nonfinite_t: float | None = None

    @property
    def real_time_factor(self) -> float:
        return self.simulated_s / self.wall_s if self.wall_s > 0 else math.inf

    @property
    def ok(self) -> bool:
        """The run ended as its scenario meant: it reached its duration, or it ended early
        in a way the scenario's ``expect.termination`` lists. A solver failure and states
        that are not finite never are. ``r2rsim run`` exits 1 when this is False."""
        return ended_as_expected(
            self.terminated, self.termination_reason, self.expected_terminations, self.nonfinite_t
        )

    def format(self) -> str:
        lines = [
            f"dataset      {self.output}",
            f"simulated    {self.simulated_s:.3f} s in {self.wall_s:.2f} s wall "
            f"(real-time factor {self.real_time_factor:.0f}), {self.n_samples} samples",
            f"solver       {self.solver_stats.get('solver', '')}, "
            f"{self.solver_stats.get('nfev', 0)} RHS evaluations; initial state "
            f"{self.initial_state}",
        ]
        compile_s = self.solver_stats.get("compile_s", 0.0)
        if compile_s >= 1.0:  # a cold numba cache: reported apart from the wall time
            lines.insert(
                2,
                f"compiled     numba kernels in {compile_s:.1f} s (first run only; "
                f"not in the wall time above)",
            )
        lines += [f"WARNING      {w}" for w in self.warnings]
        if self.terminated:
            how = "expected" if self.ok else "not expected by the scenario (expect.termination)"
            lines.append(
                f"TERMINATED   {self.termination_reason} at "
                f"t = {self.termination_time:.4f} s ({how})"
            )
        if self.nonfinite_t is not None:
            lines.append(
                f"FAILED       states not finite (nan or inf) from t = "
                f"{self.nonfinite_t:.4f} s; the samples are kept, marked in runs.parquet"
            )
        lines.append("tension [N]  span        min       mean        max")
        for sid, (lo, mean, hi) in self.tension_stats.items():
            lines.append(f"             {sid:<8} {lo:9.2f}  {mean:9.2f}  {hi:9.2f}")
        if self.events:
            lines.append(f"events       {len(self.events)}")
            for ev in self.events[:20]:
                lines.append(f"  t = {ev.t:10.4f} s  {ev.kind:<10} {ev.message}")
            if len(self.events) > 20:
                lines.append(f"  ... {len(self.events) - 20} more in events.parquet")
        else:
            lines.append("events       none")
        return "\n".join(lines)


def _refuse_line_file(path: Path) -> None:
    """A line file given where a scenario is expected: say so (one line), rather than list
    the scenario keys it lacks. Any other problem is left to load_scenario."""
    try:
        data = read_yaml(path)
    except R2RError:
        return
    if ("elements" in data or "web" in data) and "line" not in data and "programme" not in data:
        raise InputError(
            "this is a line file, not a scenario: a scenario names a line file "
            "(line: ...) and drives it through a programme. Check the line with "
            f"`r2rsim validate {path}`, or write a scenario for it (see "
            "scenarios/quickstart.yaml)",
            file=str(path),
        )


def _name_from_stem(scenario_path: Path) -> str:
    """A scenario without ``name:`` is named after its file, if that is a safe name."""
    stem = scenario_path.stem
    if not _STEM.fullmatch(stem):
        raise InputError(
            f"the scenario has no name, and its file name '{stem}' cannot name "
            f"the run (letters, digits, '_', '-', '.'; starting with a letter or "
            f"digit): add a name",
            file=str(scenario_path),
            path="name",
        )
    return stem


_STEM = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]{0,63}")


def _scenario_output(scenario_path: Path, output: str) -> Path:
    """The scenario's ``output:`` as a path: relative to the scenario file, and inside the
    directory that holds it (a scenario file does not choose to write elsewhere; ``-o``
    does)."""
    base = scenario_path.resolve().parent
    target = (base / output).resolve()
    if target == base or not target.is_relative_to(base):
        raise InputError(
            f"'{output}' is outside the scenario's directory {base}: output "
            f"names a directory inside it (relative to the scenario file); to "
            f"write elsewhere give -o on the command line",
            file=str(scenario_path),
            path="output",
        )
    return base / output


@dataclass
class RunPlan:
    """A validated scenario and line, ready to simulate (what :func:`run_scenario` reads
    from the files; a sweep builds one per run from its overrides).

    Attributes
    ----------
    scenario, line
        The validated models (SI).
    name : str
        The scenario's name (the run id is ``<name>__s<seed>`` unless given).
    source : str
        The scenario file, for messages.
    scenario_sha256 : str
        Hash of what defines the run (the scenario and line texts, or a sweep run's
        configuration).
    files : dict
        Text files copied into the dataset (relative path -> text).
    manifest : dict
        Extra keys of the dataset's manifest.json.
    line_config : str
        What runs.parquet calls the line when it has no name (the line file's stem).
    """

    scenario: Scenario
    line: Line
    name: str
    source: str
    scenario_sha256: str
    files: dict[str, str] = field(default_factory=dict)
    manifest: dict = field(default_factory=dict)
    line_config: str = ""


def plan_from_file(
    scenario_path: str | Path, seed: int | None = None, duration: float | None = None
) -> RunPlan:
    """Load a scenario file (and its line) into a :class:`RunPlan`, with ``--seed`` and
    ``--duration`` applied.

    Raises
    ------
    InputError
        For any problem with the files or the overrides.
    """
    scenario_path = Path(scenario_path)
    _refuse_line_file(scenario_path)
    scenario, line, line_path = load_scenario(scenario_path)
    if duration is not None:
        if not duration > 0:
            raise InputError(f"--duration must be > 0, got {duration:g}")
        size = run_size_problem(duration, scenario.record_rate)
        if size is not None:  # the same limits as the file's duration (r2rsim.limits)
            raise InputError(
                f"--duration with record_rate {scenario.record_rate:g} Hz: {size[1]}",
                file=str(scenario_path),
            )
        scenario.duration = duration
    if seed is not None:
        if not 0 <= seed <= MAX_SEED:
            raise InputError(
                f"--seed must be >= 0, got {seed}"
                if seed < 0
                else f"--seed must be at most 2**64 - 1 = {MAX_SEED}, got {seed}"
            )
        scenario.seed = seed
    name = scenario.name or _name_from_stem(scenario_path)
    scenario_text = scenario_path.read_text(encoding="utf-8")
    line_text = line_path.read_text(encoding="utf-8")
    # the two copies must not overwrite each other (a.yaml next to lines/a.yaml)
    line_copy = line_path.name if line_path.name != scenario_path.name else f"line.{line_path.name}"
    files = {
        f"scenario/{scenario_path.name}": scenario_text,
        f"scenario/{line_copy}": line_text,
        f"scenario/{name}.normalised.yaml": yaml.safe_dump(
            scenario.model_dump(mode="json"), sort_keys=True
        ),
    }
    sha = hashlib.sha256((scenario_text + "\0" + line_text).encode()).hexdigest()
    return RunPlan(
        scenario,
        line,
        name,
        str(scenario_path),
        sha,
        files,
        {"scenario": scenario_path.name, "line": line_copy},
        line_path.stem,
    )


def check_plan(plan: RunPlan) -> list[str]:
    """Everything a run checks before it simulates, without simulating: the programme (a
    ramp still running at the next step), the variability, disturbances and faults drawn
    at the plan's seed, the compiled line and the initial state. ``r2rsim validate`` calls
    it, so that it refuses what ``r2rsim run`` would.

    Returns
    -------
    list of str
        Warnings the run would print (a steady state that cannot be found).

    Raises
    ------
    InputError
        For a problem ``r2rsim run`` would refuse the scenario with.
    """
    return _prepare(plan).warnings


def sample_columns(scenario, line, file: str | None = None) -> tuple[str, ...]:
    """The columns the samples of a run of ``scenario`` on ``line`` will have, without
    simulating (compiles the line: ~1 ms once numba's kernels are loaded). A sweep checks
    with it that all its runs fit one dataset; ``file`` names the scenario in errors."""
    prog = Programme.from_steps(line, scenario.programme, file=file or "<scenario>")
    disturbances = realise_disturbances(scenario, line, np.random.SeedSequence(0))
    cl = compile_line(line, prog, scenario.faults, disturbances)
    cols = []
    for s in cl.sensors:
        meas, true, _ = channel_names(cl, s)
        cols += [meas, true] + ([f"flag.{s.id}.clipped"] if s.range is not None else [])
    cols += [c["column"] for c in true_state_columns(cl)]
    return tuple(cols)


def run_scenario(
    scenario_path: str | Path,
    output: str | Path | None = None,
    seed: int | None = None,
    duration: float | None = None,
    progress=None,
    overwrite: bool = False,
) -> RunSummary:
    """Run a scenario file and write its dataset.

    Parameters
    ----------
    scenario_path : str or Path
    output : str or Path, optional
        Dataset directory, anywhere (default: the scenario's ``output``, relative to the
        scenario file and inside its directory, else ``runs/<name>`` in the working
        directory). It must not exist, be empty, or be an r2rsim dataset to ``overwrite``.
    seed : int, optional
        Overrides the scenario's root seed.
    duration : float, optional
        Overrides the scenario's duration [s].
    progress : callable, optional
        Called as ``progress(t, duration)`` with the simulated time reached.
    overwrite : bool
        Replace an existing dataset at the output. Only a directory that is verifiably an
        r2rsim dataset is ever replaced (:func:`r2rsim.dataset.writer.check_output`).

    Returns
    -------
    RunSummary

    Raises
    ------
    InputError
        For any problem with the input files or the output directory; nothing is written.
    """
    compile0 = compile_seconds()
    plan = plan_from_file(scenario_path, seed, duration)
    out = Path(output) if output is not None else default_output(plan)
    return execute(plan, out, progress=progress, overwrite=overwrite, compile0=compile0)


def default_output(plan: RunPlan) -> Path:
    """Where a run of a scenario file writes without ``-o``: the scenario's ``output``
    (relative to the scenario file and inside its directory), else ``runs/<name>``.

    Raises
    ------
    InputError
        For an ``output`` outside the scenario file's directory.
    """
    if plan.scenario.output is None:
        return Path(f"runs/{plan.name}")
    return _scenario_output(Path(plan.source), plan.scenario.output)


def execute(
    plan: RunPlan,
    out: str | Path,
    *,
    run_id: str | None = None,
    progress=None,
    overwrite: bool = False,
    run_columns: dict | None = None,
    compile0: float | None = None,
    clean_stale: bool = True,
    check_labels: bool = True,
) -> RunSummary:
    """Simulate a :class:`RunPlan` and write its dataset at ``out``.

    Parameters
    ----------
    plan : RunPlan
    out : str or Path
        The dataset directory (:func:`r2rsim.dataset.writer.check_output` rules).
    run_id : str, optional
        Default ``<name>__s<seed>``.
    progress : callable, optional
        ``progress(t, duration)``.
    overwrite : bool
        Replace an r2rsim dataset at ``out``.
    run_columns : dict, optional
        Extra columns of the run's row of runs.parquet (name -> one-element pyarrow array).
    compile0 : float, optional
        :func:`r2rsim.solve.compilewatch.compile_seconds` when the work began.
    clean_stale : bool
        Let the dataset writer clean up dead processes' temporaries next to ``out``.
    check_labels : bool
        Read the labels back and derive them again when the dataset checks itself
        (:func:`r2rsim.dataset.validate.validate_dataset`).

    Returns
    -------
    RunSummary
    """
    out = Path(out)
    compile0 = compile_seconds() if compile0 is None else compile0
    scenario, name = plan.scenario, plan.name
    check_output(out, overwrite)  # before the work: refuse early what commit would refuse

    prep = _prepare(plan)
    cl, faults, sensor_chan = prep.cl, prep.faults, prep.sensor_chan
    run_id = run_id or f"{name}__s{scenario.seed}"
    meta = tables.file_metadata(plan.scenario_sha256, scenario.seed)
    rate = scenario.record_rate
    fault_rows = [f.record(run_id, int(math.ceil(f.onset * rate - 1e-9))) for f in faults]
    modes = [(st.at, st.mode) for st in scenario.programme if st.mode is not None]
    writer = DatasetWriter(out, run_id, meta, overwrite=overwrite, clean=clean_stale)
    try:
        sink = _ChunkSink(
            writer,
            MeasurementModel(cl, rate, prep.ss_meas, faults),
            cl,
            fault_rows,
            scenario.warmup,
            modes,
            sensor_chan,
        )
        wall0, compile_sim0 = time.perf_counter(), compile_seconds()
        res = simulate(
            cl,
            scenario.duration,
            rate,
            prep.y0,
            scenario.solver,
            on_chunk=sink.on_chunk,
            progress=(lambda t: progress(t, scenario.duration)) if progress else None,
            initial_state_mode=prep.init_mode,
            events=scenario.events,
            faults=faults,
            rolls=prep.rolls,
        )
        sink.close(res.terminated)
        nonfinite_t, warnings = sink.nonfinite_t, list(prep.warnings)
        if writer.first_nonfinite is not None:  # an output (float32 as written), not a state
            t_col, column = writer.first_nonfinite
            if nonfinite_t is None or t_col < nonfinite_t:
                nonfinite_t = t_col
                warnings.append(
                    f"{plan.source}: the samples column {column} is not finite "
                    f"from t = {t_col:g} s (nan or inf; a value beyond float32's "
                    "range, 3.4e38, is written as inf)"
                )
        # the wall time and real-time factor without numba compiling (reported apart)
        wall = time.perf_counter() - wall0 - (compile_seconds() - compile_sim0)
        res.stats["compile_s"] = compile_seconds() - compile0
        sim_end = _end_time(res, scenario.duration)

        writer.write_table(
            "channels",
            tables.channels_table(cl, sink.meas.channels, sink.cols, sensor_chan, rate),
        )
        writer.write_table("faults", tables.faults_table(fault_rows))
        events = _run_events(res, faults, sim_end)
        writer.write_table("events", tables.events_table(run_id, events))
        variability_rows = prep.variability_rows + (
            prep.rolls.rows if prep.rolls is not None else []
        )
        writer.write_table("variability", tables.variability_table(run_id, variability_rows))
        runs = _runs_table(
            plan, prep, run_id, res, modes, writer.n_rows, sim_end, nonfinite_t, wall
        )
        for col, arr in (run_columns or {}).items():
            runs = runs.append_column(col, arr)
        writer.write_table("runs", runs)
        for rel, text in plan.files.items():
            writer.write_text(rel, text)
        path = writer.commit(
            {
                "run_ids": [run_id],
                "scenario_sha256": plan.scenario_sha256,
                "root_seed": scenario.seed,
                **plan.manifest,
            },
            check=lambda d: validate_dataset(d, labels=check_labels),
        )
    except BaseException:
        writer.abort()
        raise
    return RunSummary(
        path,
        run_id,
        float(sim_end),
        wall,
        writer.n_rows,
        sink.tension_stats(cl.span_ids),
        events,
        res.terminated,
        res.termination_reason,
        res.termination_time,
        prep.init_mode,
        res.stats,
        warnings,
        list(scenario.expect.termination),
        nonfinite_t,
    )


@dataclass
class _Prepared:
    """A run's realised line (variability drawn), its compiled form and initial state, and
    the random streams of the rest of the run."""

    line: Line
    cl: CompiledLine
    rolls: RollDraws | None
    variability_rows: list
    y0: np.ndarray
    init_mode: str
    warnings: list
    ss_process: np.random.SeedSequence
    ss_meas: np.random.SeedSequence
    ss_faults: np.random.SeedSequence
    faults: list
    sensor_chan: dict


def _compiled(plan: RunPlan, ss_process: np.random.SeedSequence):
    """The run's line with its variability and disturbances drawn, compiled: ``(line, cl,
    rolls, variability_rows, disturbances)``."""
    scenario, line = plan.scenario, plan.line
    prog = Programme.from_steps(line, scenario.programme, file=plan.source)
    declared_web = line.web
    line, rolls, variability_rows = realise_variability(scenario, line, ss_process)
    disturbances = realise_disturbances(scenario, line, ss_process)
    pitch_var = realise_pitch_variations(line, ss_process)
    cl = compile_line(
        line,
        prog,
        scenario.faults,
        disturbances,
        pitch_var,
        joint_slots_needed(scenario, line),
        nominal_web=declared_web,
        pitch_offsets=rolls.sensor_pitch_offsets if rolls else None,
    )
    return line, cl, rolls, variability_rows, disturbances


def channels_table(plan: RunPlan) -> pa.Table:
    """channels.parquet of a run of ``plan`` without simulating it (``r2rsim list channels
    SCENARIO``): every column its samples will have, in the order they are written, with
    unit and description. The line is compiled as the run compiles it (~1 ms once numba's
    kernels are loaded); no steady state is looked for and no fault is drawn (neither
    changes the columns)."""
    ss_process, ss_meas, _ = np.random.SeedSequence(plan.scenario.seed).spawn(3)
    cl = _compiled(plan, ss_process)[1]
    rate = plan.scenario.record_rate
    sensor_chan = {s.id: channel_names(cl, s)[0][len("meas.") :] for s in cl.sensors}
    measured = MeasurementModel(cl, rate, ss_meas).channels
    return tables.channels_table(cl, measured, true_state_columns(cl), sensor_chan, rate)


def _end_time(res, duration: float) -> float:
    """Where the run's data ends [s]: where it terminated, else its duration."""
    if res.terminated and res.termination_time is not None:
        return float(res.termination_time)
    return float(duration)


def _prepare(plan: RunPlan) -> _Prepared:
    """Draw the run's variability and disturbances from its process stream, compile the
    line, find the initial state (steady, or nominal when none is found) and draw the
    faults from their stream."""
    scenario = plan.scenario
    ss_process, ss_meas, ss_faults = np.random.SeedSequence(scenario.seed).spawn(3)
    line, cl, rolls, variability_rows, disturbances = _compiled(plan, ss_process)
    init = scenario.initial
    y0 = nominal_state(
        cl,
        init.tension,
        init.span_tension,
        init.slack,
        {k: float(v) for k, v in init.position.items()},  # numbers once loaded
        file=plan.source,
    )
    for d in disturbances:  # an out-of-round roller starts at a random angle
        if d.type == "out_of_round":
            y0[cl.index(f"{d.element}.angle")] = d.phase
    init_mode, warnings = "nominal", []
    if init.state == "steady":
        y_ss = steady_state(cl, y0)
        if y_ss is not None:
            y0, init_mode = y_ss, "steady"
        else:
            init_mode = "nominal (no steady state at the t = 0 set-points)"
            warnings.append(
                f"{plan.source}: initial.state: steady was asked for, but no steady state "
                "was found at the t = 0 set-points (is the line at rest, or are span tensions "
                "not held by any loop or draw?); the run starts from the nominal state"
            )
    sensor_chan = {s.id: channel_names(cl, s)[0][len("meas.") :] for s in cl.sensors}
    faults = realise_faults(
        scenario, line, ss_faults, plan.source, channel_of=lambda sid: f"meas.{sensor_chan[sid]}"
    )
    return _Prepared(
        line,
        cl,
        rolls,
        variability_rows,
        y0,
        init_mode,
        warnings,
        ss_process,
        ss_meas,
        ss_faults,
        faults,
        sensor_chan,
    )


class _ChunkSink:
    """Receives the solver's output chunks: measures them, labels them and hands them to
    the dataset writer one chunk late (the last chunk learns how the run ended); keeps
    the span tensions' range and the first non-finite sample."""

    def __init__(self, writer, meas, cl, fault_rows, warmup, modes, sensor_chan):
        self.writer, self.meas = writer, meas
        self.fault_rows, self.warmup, self.modes = fault_rows, warmup, modes
        self.sensor_chan = sensor_chan
        self.cols = true_state_columns(cl)
        self.aux_idx = np.array([c["aux"] for c in self.cols], dtype=np.int64)
        self.span_cols = [cl.aux_index(f"{s}.tension_N") for s in cl.span_ids]
        n = len(self.span_cols)
        self.t_min, self.t_max, self.t_sum = np.full(n, np.inf), np.full(n, -np.inf), np.zeros(n)
        self.n = 0
        self.held: list[dict] = []
        self.nonfinite_t: float | None = None  # the first sample whose states are not finite

    def on_chunk(self, t, Y, A):
        n = len(t)
        if self.nonfinite_t is None:
            bad = ~np.isfinite(Y).all(axis=1)
            if bad.any():
                self.nonfinite_t = float(t[np.argmax(bad)])
        data = {"k": np.arange(self.n, self.n + n, dtype=np.int64), "t_s": t}
        data.update(self.meas.measure(t, A))
        for c, j in zip(self.cols, self.aux_idx, strict=True):
            data[c["column"]] = A[:, j]
        if self.held:
            self._flush(False)
        self.held.append(data)
        T = A[:, self.span_cols]
        self.t_min = np.minimum(self.t_min, T.min(axis=0))
        self.t_max = np.maximum(self.t_max, T.max(axis=0))
        self.t_sum += T.sum(axis=0)
        self.n += n

    def _flush(self, terminated: bool):
        data = self.held.pop()
        k_last = int(data["k"][-1]) if terminated and len(data["k"]) else None
        data.update(
            derive_labels(
                self.fault_rows,
                data["k"],
                data["t_s"],
                warmup=self.warmup,
                modes=self.modes,
                terminated_k=k_last,
                sensor_channels=self.sensor_chan,
            )
        )
        self.writer.write_chunk(data)

    def close(self, terminated: bool):
        """Write the held last chunk, knowing how the run ended."""
        if self.held:
            self._flush(terminated)

    def tension_stats(self, span_ids) -> dict:
        """(min, mean, max) true tension of each span [N]."""
        n = max(self.n, 1)
        return {
            sid: (float(self.t_min[i]), float(self.t_sum[i] / n), float(self.t_max[i]))
            for i, sid in enumerate(span_ids)
        }


def _run_events(res, faults, sim_end: float) -> list[Event]:
    """The solver's events and every fault's start and end within the simulated time, in
    time order."""
    events = list(res.events) + [
        Event(
            tb,
            "fault",
            f.target,
            state,
            f"{f.id}: {f.type} on {f.target} {state}s",
            {"fault_id": f.id},
        )
        for f in faults
        for tb, state in ((f.onset, "start"), (f.end, "end"))
        if tb is not None and tb <= sim_end
    ]
    events.sort(key=lambda e: e.t)
    return events


def _runs_table(
    plan: RunPlan,
    prep: _Prepared,
    run_id: str,
    res,
    modes,
    n_rows: int,
    sim_end: float,
    nonfinite_t: float | None,
    wall: float,
) -> pa.Table:
    """The run's row of runs.parquet (:func:`r2rsim.dataset.tables.runs_table`)."""
    scenario = plan.scenario
    return tables.runs_table(
        run_id=run_id,
        scenario=scenario,
        scenario_id=plan.name,
        scenario_sha256=plan.scenario_sha256,
        line_config=prep.line.name or plan.line_config,
        seed_streams={
            "process": prep.ss_process,
            "measurement": prep.ss_meas,
            "fault_sampling": prep.ss_faults,
        },
        modes=modes,
        n_samples=n_rows,
        n_faults=len(prep.faults),
        terminated=res.terminated,
        termination_reason=res.termination_reason,
        termination_t=res.termination_time,
        simulated_s=sim_end,
        nonfinite_t=nonfinite_t,
        ended_as_expected=ended_as_expected(
            res.terminated, res.termination_reason, scenario.expect.termination, nonfinite_t
        ),
        initial_state=prep.init_mode,
        solver=res.stats["solver"],
        rhs_evaluations=res.stats["nfev"],
        wallclock_s=wall,
    )
