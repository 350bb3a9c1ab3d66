"""The ``r2rsim`` command line: a thin layer over the Python API.

Errors are one line on stderr and a non-zero exit code; ``--debug`` shows the traceback.
"""

from __future__ import annotations

import argparse
import atexit
import contextlib
import gc
import os
import signal
import sys
import threading
import time
from pathlib import Path

from ._version import __version__
from .errors import InputError, R2RError, Terminated

EXIT_INPUT = 2
EXIT_FAILURE = 1
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE, what a shell reports for a program killed by it
EXIT_INTERRUPTED = 130  # 128 + SIGINT (Ctrl-C)
EXIT_TERMINATED = 143  # 128 + SIGTERM

#: the entries of ``r2rsim list elements`` that are not element kinds (each kind's line is
#: its ``summary``, r2rsim/schema/kinds/); listed after the kinds
ELEMENT_EXTRAS = {
    "festoon (span)": "spans[i].festoon: carriage with n moving rollers, 2n lumped strands",
    "splicer (unwind)": "unwind.splicer + spare_roll: zero_speed (fill, brake, dwell, swap, "
    "accelerate, refill) or flying (speed_match_error); splice joint",
}
SENSORS = {
    "load_cell": "bearing force of a roller -> indicated tension (wrap_angle, axis_angle)",
    "encoder": "angular speed (counts_per_rev: unbiased edge-count difference over window)",
    "roll_diameter": "ultrasonic/laser diameter of an unwind/rewind roll",
    "dancer_position": "dancer travel [m] / arm angle [rad] or festoon carriage position [m]",
    "pitch_length": "2-D vision pitch length on a span, (T/ES + 1)·L0 (thesis eq. 2.11); "
    "L0 = q0 + q1·R³ (relaxed_pitch_law, eq. 2.24) + pitch_variation",
}
CONTROLLERS = {
    "speed_pi": "speed PI on a torque drive, torque feed-forward, draw; one master node",
    "tension_pi": "tension PI on a load cell: torque mode on unwind/rewind (T_ref·R feed-"
    "forward + trim), speed trim on speed-controlled elements; reads a "
    "load_cell or a pitch_length sensor",
    "dancer_pi": "dancer/festoon position loop trimming the speed of an upstream or "
    "downstream element, with limits",
}


COMPILING = "compiling (first run only)…"


def _compile_notice(bar, quiet: bool):
    """What to do when numba starts (True) and stops (False) compiling the kernels: on a
    terminal the progress bar says so while it lasts; otherwise one line on stderr; with -q
    nothing. Never on stdout."""
    if quiet:
        return None
    if bar is not None:
        fmt = bar.bar_format

        def on_bar(compiling: bool) -> None:
            bar.bar_format = "{desc}" if compiling else fmt  # no clock: nothing redraws it
            bar.set_description_str(COMPILING if compiling else "simulating")

        return on_bar
    said = []

    def on_stderr(compiling: bool) -> None:
        if compiling and not said:
            said.append(True)
            print(COMPILING, file=sys.stderr, flush=True)

    return on_stderr


#: seconds after which a stop signal that arrived where it must not interrupt is sent again
STOP_RETRY_S = 0.02
#: seconds after which a stop signal that keeps arriving there interrupts all the same (that
#: code is short where r2rsim runs it; this bounds the wait should it ever block)
STOP_DEFER_MAX_S = 2.0

#: modules whose code a stop signal must not interrupt (the handler sends it again a moment
#: later, until it arrives outside them):
#:
#: - pydantic: pydantic-core builds a model's validator in Rust, calling back into Python,
#:   and an exception raised in such a callback makes it panic (pydantic 2.6: exit 1 with a
#:   Rust message instead of the line saying what was kept);
#: - multiprocessing and concurrent.futures.process: a sweep's worker process is started by
#:   writing its start-up data down a pipe after the process exists; stopped in between, the
#:   new worker reads a closed pipe and prints a traceback (``EOFError``), and a worker not yet
#:   entered in the pool's table is not stopped with the others.
UNINTERRUPTIBLE_MODULES = ("pydantic", "multiprocessing", "concurrent.futures.process")


#: when each stop signal was first deferred (:func:`_stop_handler`), by signal number
_deferred_since: dict[int, float] = {}


def _stop_handler(signum, frame, stop: type[BaseException], after) -> None:
    """Raise ``stop`` (the command then stops, cleans up and says what it kept), unless the
    signal arrived inside :data:`UNINTERRUPTIBLE_MODULES`: then it is sent again
    :data:`STOP_RETRY_S` later, for at most :data:`STOP_DEFER_MAX_S`. ``after`` is the
    signal's handler from then on."""
    now = time.monotonic()
    if _inside_uninterruptible(frame):
        if now - _deferred_since.setdefault(signum, now) < STOP_DEFER_MAX_S:
            timer = threading.Timer(STOP_RETRY_S, os.kill, (os.getpid(), signum))
            timer.daemon = True
            timer.start()
            return
    _deferred_since.pop(signum, None)
    signal.signal(signum, after)
    raise stop()


def _raise_terminated(signum, frame):
    """SIGTERM handler of the commands: stop the way Ctrl-C does, so the dataset writer cleans
    up. A second SIGTERM kills at once (its temporary directory is removed by the next run
    into the same directory)."""
    _stop_handler(signum, frame, Terminated, signal.SIG_DFL)


def _raise_interrupted(signum, frame):
    """SIGINT (Ctrl-C) handler of the commands: Python's own (``KeyboardInterrupt``), except
    that it waits to be outside :data:`UNINTERRUPTIBLE_MODULES`. A second Ctrl-C is Python's
    own handler's."""
    _stop_handler(signum, frame, KeyboardInterrupt, signal.default_int_handler)


def _inside_uninterruptible(frame) -> bool:
    """Whether ``frame`` or one of its callers is code of :data:`UNINTERRUPTIBLE_MODULES`."""
    while frame is not None:
        module = str(frame.f_globals.get("__name__", ""))
        if any(module == m or module.startswith(m + ".") for m in UNINTERRUPTIBLE_MODULES):
            return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def _stop_signals_as_interrupts():
    """Within the block, SIGTERM stops the work the way Ctrl-C does (:func:`_raise_terminated`)
    and neither of them interrupts the code of :data:`UNINTERRUPTIBLE_MODULES`; the previous
    handlers are put back after it. Outside the main thread (embedded use) the signals are
    left alone, and so is a SIGINT that is ignored (a background job's) or handled by the
    caller."""
    try:
        previous = {signal.SIGTERM: signal.signal(signal.SIGTERM, _raise_terminated)}
    except ValueError:
        yield
        return
    _deferred_since.clear()  # a deferral left over from an earlier command is not this one's
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        previous[signal.SIGINT] = signal.signal(signal.SIGINT, _raise_interrupted)
    try:
        yield
    finally:  # None: a handler not set from Python, i.e. the default
        for signum, handler in previous.items():
            signal.signal(signum, handler if handler is not None else signal.SIG_DFL)


def _cmd_run(args) -> int:
    from .run import run_scenario
    from .solve.compilewatch import notify_compiling

    bar = None
    progress = None
    if sys.stderr.isatty() and not args.quiet:
        from tqdm import tqdm

        bar = tqdm(
            total=0,
            unit="s",
            desc="simulating",
            leave=False,
            bar_format="{desc}: {n:.1f}/{total:.1f} s sim [{elapsed}<{remaining}]",
        )

        def progress(t, total):
            bar.total = total
            bar.n = t
            bar.refresh()

    try:
        with _stop_signals_as_interrupts(), notify_compiling(_compile_notice(bar, args.quiet)):
            summary = run_scenario(
                args.scenario,
                output=args.output,
                seed=args.seed,
                duration=args.duration,
                progress=progress,
                overwrite=args.overwrite,
            )
    finally:
        if bar is not None:
            bar.close()
    for w in summary.warnings:  # also with -q, and apart from the summary on stdout
        print(f"warning: {w}", file=sys.stderr)
    print(summary.format())
    if not summary.ok:  # batch users must be able to trust $?
        why = (
            f"states not finite from t = {summary.nonfinite_t:g} s"
            if summary.nonfinite_t is not None
            else f"the run ended early: {summary.termination_reason} at "
            f"t = {summary.termination_time:g} s"
        )
        print(
            f"error: {args.scenario}: {why}; the dataset is written and marked "
            f"(runs.parquet termination_reason)",
            file=sys.stderr,
        )
        return EXIT_FAILURE
    return 0


def _cmd_sweep(args) -> int:
    bar = None
    started = False  # the sweep began to write (its first progress call)

    def progress(n, total, rec):
        nonlocal bar, started
        started = True
        if not (sys.stderr.isatty() and not args.quiet):
            return
        if bar is None:
            from tqdm import tqdm

            bar = tqdm(total=total, unit="run", desc="sweep", leave=False)
        if rec is not None:
            bar.update(1)

    try:
        from .sweep import run_sweep

        with _stop_signals_as_interrupts():
            summary = run_sweep(
                args.sweep,
                output=args.output,
                workers=args.workers,
                scheduler=args.scheduler,
                retry_failed=args.retry_failed,
                overwrite=args.overwrite,
                progress=progress,
            )
    except OSError as exc:  # the disk is full, a directory read-only: the runs are kept
        if args.debug:
            raise
        where = f" ({exc.filename})" if exc.filename else ""
        print(
            f"error: cannot write the sweep's files: {exc.strerror or exc}{where}. The "
            f"finished runs are kept: free space or fix the permissions, and run the same "
            f"command again to continue"
            if started
            else f"error: {exc.strerror or exc}{where}; nothing was written",
            file=sys.stderr,
        )
        return EXIT_FAILURE
    except KeyboardInterrupt as exc:
        what = "terminated (SIGTERM)" if isinstance(exc, Terminated) else "interrupted"
        print(
            f"{what}; the finished runs are kept: run the same command again to continue"
            if started
            else f"{what} before this sweep ran a run; runs it finished before, if any, are kept",
            file=sys.stderr,
        )
        return EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED
    finally:
        if bar is not None:
            bar.close()
    for w in summary.warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(summary.format())
    if not summary.ok:
        n = summary.failed + summary.skipped_failed
        print(
            f"error: {n} run{'s' if n != 1 else ''} of the sweep failed (listed above; "
            f"failures.parquet, runs.parquet termination_reason); the others are written. "
            f"--retry-failed runs them again (a solver failure repeats unless the cause, "
            f"e.g. the solver settings, changes)",
            file=sys.stderr,
        )
        return EXIT_FAILURE
    return 0


def _parse_params(items: list[str], cls) -> dict:
    """``k=v`` pairs; values are YAML scalars or lists (``alpha=0.01``, ``lags=3``)."""
    import yaml

    from .diagnostics.registry import check_param, unknown_parameter

    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise InputError(f"--param expects key=value, got '{item}'")
        problem = unknown_parameter(cls, key)
        if problem:
            raise InputError(f"--param {key}: {problem}")
        try:
            out[key] = yaml.safe_load(value)
        except yaml.YAMLError:
            raise InputError(f"--param {key}: cannot read the value '{value}'") from None
        try:
            out[key] = check_param(cls, key, out[key])
        except InputError as exc:
            raise InputError(f"--param {key}: {exc.message}") from None
    return out


def parse_where(items: list[str]) -> dict:
    """``--where KEY=V[,V...]`` (repeatable): runs.parquet columns, a sweep's axes by name;
    values are YAML scalars or strings with units (``top_speed=3 m/s``)."""
    import yaml

    out: dict = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep or not key.strip() or not text.strip():
            raise InputError(f"--where expects KEY=VALUE[,VALUE...], got '{item}'")
        values = []
        for part in text.split(","):
            try:
                values.append(yaml.safe_load(part))
            except yaml.YAMLError:
                values.append(part.strip())
        out.setdefault(key.strip(), []).extend(values)
    return out


def _cmd_diagnose(args) -> int:
    from .diagnostics.registry import call, get, require_registered

    require_registered(args.method)  # an unknown name is refused before the heavy imports
    from .evaluate.harness import (
        check_settings,
        evaluate,
        no_training_run,
        read_datasets,
        split_by_condition,
        split_by_seed,
    )
    from .evaluate.results import check_results_output

    cls = get(args.method)
    params = _parse_params(args.param, cls)
    # every flag, and the output directory, is checked before a dataset is read
    check_settings(
        alpha=args.alpha,
        m=args.persistence,
        h=args.grace,
        n_boot=args.n_boot,
        window=args.window,
        vus_buffer=args.vus_buffer,
        seed=args.seed,
        detection_window=args.detection_window,
        own_threshold=args.own_threshold,
    )
    output = args.output or Path("results") / args.method
    check_results_output(output, "diagnose", args.overwrite)
    est = call(cls, "__init__", cls, **params)
    verify = not args.no_verify
    where = parse_where(args.where)
    if args.data:
        if args.train or args.test or args.val:
            raise InputError("give either --data with --split, or --train/--val/--test")
        runs = read_datasets(args.data, verify=verify, where=where)
        if args.split == "seed":
            split = split_by_seed(runs)
            if not split.train:
                raise InputError(no_training_run(runs))
        else:
            split = split_by_condition(
                runs, train=args.train_mode, test=args.test_mode, val=args.val_fraction
            )
    else:
        if not args.train or not args.test:
            raise InputError(
                "name the training and test datasets (--train and --test), or "
                "pool them with --data and --split"
            )
        from .evaluate.harness import Split

        split = Split(
            read_datasets(args.train, verify=verify, where=where),
            read_datasets(args.val or [], verify=verify, where=where),
            read_datasets(args.test, verify=verify, where=where),
        )
    print(split.describe())
    if not split.val:
        print("no validation runs: metrics at the plug-in's own threshold only (no *_cal)")
    ev = evaluate(
        est,
        split.train,
        split.test,
        split.val,
        alpha=args.alpha,
        m=args.persistence,
        h=args.grace,
        n_boot=args.n_boot,
        seed=args.seed,
        split=split.name,
        drive_data=args.drive_data,
        mode_strata=args.mode_strata,
        window=args.window,
        isolation=args.isolation,
        vus_buffer=args.vus_buffer,
        detection_window=args.detection_window,
        own_threshold=args.own_threshold,
    )
    out = ev.write(output, overwrite=args.overwrite)
    print(ev.format())
    print(f"written: {out}/predictions.parquet, metrics.parquet, metrics.csv, datasets.json")
    return 0


def _cmd_bench(args) -> int:
    from .bench import run_bench, write_results
    from .evaluate.results import check_results_output

    if args.output:  # before anything is simulated
        check_results_output(args.output, "bench", args.overwrite)
    res = run_bench(args.spec, workdir=args.workdir, update=args.update, verify=not args.no_verify)
    if args.output:
        out = write_results(res.results, args.output, overwrite=args.overwrite)
        print(f"results written: {out}/results.parquet, results.csv")
    if res.baseline is None or args.update:
        return 0
    for line in res.improvements:
        print(f"improved: {line}")
    if res.improvements:
        print("(better than the baseline beyond tolerance: update it with --update)")
    if res.regressions:
        for line in res.regressions:
            print(f"REGRESSION: {line}", file=sys.stderr)
        print(
            f"error: {len(res.regressions)} of {res.n_checked} metrics regressed beyond "
            f"their tolerance against {res.baseline}",
            file=sys.stderr,
        )
        return EXIT_FAILURE
    print(f"bench passed: {res.n_checked} metrics within tolerance of {res.baseline}")
    return 0


def _cmd_report(args) -> int:
    from .report import write_report

    datasets = args.data
    if args.no_verify:  # read here unchecked; write_report reads the paths it is given checked
        datasets = _report_datasets_unverified(Path(args.results), args.data)
    out = write_report(args.results, output=args.output, datasets=datasets)
    print(f"report written: {out}")
    return 0


def _report_datasets_unverified(results: Path, data: list[str] | None):
    """``report --no-verify``: the test datasets of a diagnose result (``--data``, else those
    recorded in datasets.json) read without checking them against their manifest.json, as
    runs for write_report; None when there are none to read (a bench result, or recorded
    datasets that are gone: write_report says so)."""
    from .report._data import label_runs
    from .report._diagnostics import results_kind
    from .report._html import _recorded_datasets

    if results_kind(results) != "diagnose":
        return data
    paths = data if data is not None else _recorded_datasets(results)[0]
    return None if paths is None else label_runs(paths, verify=False)  # the labels only


def _add_report_parser(sub) -> None:
    rp = sub.add_parser(
        "report",
        help="write a self-contained HTML report (tables and "
        "figures) of a diagnose or bench results directory",
    )
    rp.add_argument(
        "results",
        metavar="RESULTS_DIR",
        help="written by `r2rsim diagnose -o` or `r2rsim bench -o`",
    )
    rp.add_argument(
        "-o",
        "--output",
        help="HTML file (default: RESULTS_DIR/report.html); "
        "an existing file is replaced only if it is an r2rsim report",
    )
    rp.add_argument(
        "--data",
        nargs="+",
        metavar="DATASET",
        help="the test datasets a diagnose result was scored on: adds ROC/PR "
        "curves and the statistic of a few runs (default: those r2rsim "
        "diagnose recorded in RESULTS_DIR/datasets.json). They are checked as "
        "`r2rsim diagnose` checks them: sizes and checksums against their "
        "manifest.json, and each run's labels against faults.parquet",
    )
    rp.add_argument(
        "--no-verify",
        action="store_true",
        help="read test datasets whose files differ from their manifest.json "
        "(or whose labels differ from faults.parquet) anyway",
    )
    rp.set_defaults(func=_cmd_report)


def _cmd_export(args) -> int:
    where = parse_where(args.where)  # a malformed --where is refused before the imports
    from .evaluate.export import export_dataset

    summary = export_dataset(
        args.dataset,
        args.output,
        args.format,
        channels=args.channels,
        label=args.label,
        split=args.split,
        where=where,
        drop_warmup=args.drop_warmup,
        verify=not args.no_verify,
    )
    print(summary.split)
    print(summary.describe())
    return 0


def _add_export_parser(sub) -> None:
    ex = sub.add_parser(
        "export",
        help="write a dataset's runs as TimeEval or TSB-AD CSV files (docs/dataset.md §13)",
    )
    ex.add_argument("dataset", help="a run's or a sweep's dataset directory")
    # no `choices`: a bad value is one `error:` line from export_dataset, not argparse's usage
    ex.add_argument(
        "--format",
        required=True,
        metavar="{timeeval,tsb-ad}",
        help="timeeval: datasets.csv and r2rsim/RUN.csv (timestamp, channels, "
        "is_anomaly); tsb-ad: NNN_R2RSIM_id_N_Sensor_tr_T_1st_F.csv (channels, "
        "Label) and file_list.csv",
    )
    ex.add_argument(
        "-o", "--output", required=True, help="output directory; must not exist, or be empty"
    )
    ex.add_argument(
        "--channels",
        nargs="+",
        metavar="PATTERN",
        help="glob patterns of the columns to export (default: meas.*); true.*, "
        "state.*, act.*, cmd.*, label.*, flag.* and ctrl.*_seen_* only when a "
        "pattern names that family",
    )
    ex.add_argument(
        "--label",
        default="any",
        help="any (label.is_faulty, default), a fault class (sensor) or type "
        "(sensor.offset): 1 where such a fault is present",
    )
    ex.add_argument(
        "--split",
        default="all",
        metavar="{all,train,val,test}",
        help="the runs of one role of the split `r2rsim diagnose --data --split "
        "seed` makes (every faulty run is a test run), or all (default)",
    )
    ex.add_argument(
        "--where",
        action="append",
        default=[],
        metavar="KEY=VALUE[,VALUE]",
        help="only the runs with these runs.parquet values, e.g. a sweep's axis: "
        "offset=-10,10 (repeatable)",
    )
    ex.add_argument(
        "--drop-warmup",
        action="store_true",
        help="leave out the warm-up samples (outside label.score_mask)",
    )
    ex.add_argument(
        "--no-verify",
        action="store_true",
        help="use a dataset whose files differ from their manifest.json checksums",
    )
    ex.set_defaults(func=_cmd_export)


def _failed_runs_note(path: Path) -> str:
    """``; an incomplete sweep: ...`` for a sweep's dataset with failed runs (it is valid, and
    not the complete sweep)."""
    from .dataset.outcome import sweep_failures

    found = sweep_failures(path)
    if not found or not found[0]:
        return ""
    failed, n_runs = found
    return (
        f"; an INCOMPLETE sweep: {len(failed)} of {n_runs} runs failed (e.g. {failed[0]}; "
        f"failures.parquet and runs.parquet termination_reason say why; `r2rsim sweep "
        f"--retry-failed` runs them again)"
    )


def _cmd_validate(args) -> int:
    from .schema import load_line, read_yaml

    status = 0
    shown: set[str] = set()  # a line's problem once, though its scenario names it again

    def problem(exc: InputError) -> None:
        key = InputError(
            exc.message, file=exc.file and str(Path(exc.file).resolve()), path=exc.path
        ).format()
        if key not in shown:
            shown.add(key)
            print(exc.format(), file=sys.stderr)

    for f in args.files:
        path = Path(f)
        if path.is_dir():
            from .dataset.validate import validate_dataset

            problems = validate_dataset(path)
            for msg in problems:
                print(f"{f}: {msg}", file=sys.stderr)
            if problems:
                status = EXIT_INPUT
            else:
                print(f"{f}: valid dataset{_failed_runs_note(path)}")
            continue
        try:
            data = read_yaml(path)
            if "elements" in data:
                load_line(path)
                kind = "line"
            elif "axes" in data or ("scenario" in data and "line" not in data):
                from .sweep import plan_sweep

                plan = plan_sweep(path)
                _ = plan.default_output  # raises for an output outside its folder

                def n(k, what):
                    return f"{k} {what}{'' if k == 1 else 's'}"

                kind = (
                    f"sweep ({n(len(plan.runs), 'run')}: "
                    f"{n(plan.n_combinations, 'combination')} x "
                    f"{n(len(plan.seeds), 'seed')})"
                )
            else:
                from .run import check_plan, default_output, plan_from_file

                plan = plan_from_file(path)
                default_output(plan)  # what `r2rsim run` checks, in its order
                for warning in check_plan(plan):
                    print(f"warning: {warning}", file=sys.stderr)
                kind = "scenario"
            print(f"{f}: valid {kind}")
        except InputError as exc:
            status = EXIT_INPUT
            problems = getattr(exc, "problems", None)
            for p, msg in problems or []:
                problem(InputError(msg, file=exc.file, path=p or None))
            if not problems:
                problem(exc)
    return status


def _cmd_schema(args) -> int:
    from .schema import json_schema, reference_markdown

    kinds = ("line", "scenario", "sweep")
    bad = [k for k in args.kind if k not in kinds]
    if bad:
        print(
            f"error: r2rsim schema: unknown file kind '{bad[0]}' (line, scenario or sweep)",
            file=sys.stderr,
        )
        return EXIT_INPUT
    if args.markdown:
        print(reference_markdown(args.kind or kinds), end="")
        return 0
    if len(args.kind) != 1:
        print(
            "error: r2rsim schema: name one of line, scenario, sweep (or give --markdown for "
            "the reference of every key)",
            file=sys.stderr,
        )
        return EXIT_INPUT
    print(json_schema(args.kind[0]))
    return 0


def _list_plugins(load: bool) -> int:
    """``r2rsim list plugins``: from the entry points' metadata and the plug-ins' source
    (nothing is imported: fast), or with ``--load`` each imported and checked."""
    from .diagnostics.registry import GROUP, discover, listing

    print(f"{'name':<12} {'class':<55} first line of its docstring")
    broken = 0
    if load:
        for name, e in discover().items():
            if e.cls is None:  # listed with its error; the other plug-ins still work
                broken += 1
                print(f"{name:<12} {e.value:<55} BROKEN: {e.error}")
                continue
            doc = (e.cls.__doc__ or "").strip().splitlines()
            print(
                f"{name:<12} {e.cls.__module__ + '.' + e.cls.__qualname__:<55} "
                f"{doc[0] if doc else ''}"
            )
        print(f"(entry-point group '{GROUP}'; every plug-in imported and checked)")
    else:
        for name, e in listing().items():
            broken += e.problem is not None
            cls = e.value.replace(":", ".")
            print(
                f"{name:<12} {cls:<55} "
                + (f"BROKEN: plug-in '{name}' ({e.value}) {e.problem}" if e.problem else e.summary)
            )
        print(
            f"(entry-point group '{GROUP}'; read from the metadata and source without "
            f"importing the plug-ins: `r2rsim list plugins --load` imports and checks each)"
        )
    if broken:
        print(
            f"warning: {broken} registered plug-in{'s' if broken > 1 else ''} cannot be "
            f"loaded (marked BROKEN above); the others work",
            file=sys.stderr,
        )
    return 0


def _elements() -> dict[str, str]:
    """The ``r2rsim list elements`` table: each element kind's ``summary`` in the kinds'
    ``order``, then the extras. The kinds registered in this process (plug-ins too) when the
    registry is loaded; else read from the kind modules' source, as ``list plugins`` reads
    the plug-ins': importing them imports pydantic, which this quick command must not."""
    registry = sys.modules.get("r2rsim.schema.kinds")
    if registry is not None:
        rows = [(k.order, k.name, k.summary) for k in registry.all_kinds()]
    else:
        rows = _kinds_in_source(Path(__file__).parent / "schema" / "kinds")
    return {**{name: text for _, name, text in sorted(rows)}, **ELEMENT_EXTRAS}


def _kinds_in_source(folder: Path) -> list[tuple[int, str, str]]:
    """``(order, name, summary)`` of the kind classes in the public modules of ``folder``:
    the classes that assign ``name`` and ``summary`` literals (``order`` defaults to the
    base class's 1000)."""
    import ast

    rows = []
    for path in sorted(folder.glob("[!_]*.py")):
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            if not isinstance(node, ast.ClassDef):
                continue
            values = {
                stmt.targets[0].id: stmt.value
                for stmt in node.body
                if isinstance(stmt, ast.Assign) and isinstance(stmt.targets[0], ast.Name)
            }
            if "name" in values and "summary" in values:
                order = ast.literal_eval(values["order"]) if "order" in values else 1000
                rows.append(
                    (order, ast.literal_eval(values["name"]), ast.literal_eval(values["summary"]))
                )
    return rows


def _cmd_list(args) -> int:
    if args.what == "plugins":
        return _list_plugins(args.load)
    if args.what == "faults":
        from .schema.faults import CATALOGUE

        acts = {
            "loop": "inside the loop if a controller reads the sensor and the fault "
            "is not record_only, else on the record",
            "record": "on the recorded measurement",
            "model": "on the line's equations",
        }
        print(f"{'type':<31} {'target':<10} {'magnitude':<10} description")
        for ft in CATALOGUE.values():
            print(
                f"{ft.name:<31} {ft.target:<10} {ft.magnitude:<10} {ft.description} "
                f"(acts {acts[ft.acts]})"
            )
        return 0
    if args.what == "channels":
        if not args.line:
            raise InputError("name the line or scenario file: r2rsim list channels LINE|SCENARIO")
        return _list_channels(args.line)
    tables = {"elements": _elements(), "sensors": SENSORS, "controllers": CONTROLLERS}
    for name, desc in tables[args.what].items():
        print(f"{name:<17} {desc}")
    return 0


def _list_channels(path: str) -> int:
    """The columns a run writes (its channels.parquet), without simulating: of a run of a
    scenario file (with its set-point, fault-label and other scenario-dependent columns), or
    of a line file (as a scenario with an empty programme and the default record rate)."""
    from .run import RunPlan, channels_table, plan_from_file
    from .schema import load_line, read_yaml
    from .schema.scenario import Scenario

    data = read_yaml(path)
    if "line" in data:  # a scenario names its line
        plan = plan_from_file(path)
    elif "elements" in data or "web" in data:
        line = load_line(path)
        scenario = Scenario.model_validate({"line": path, "duration": 1})
        plan = RunPlan(scenario, line, name="line", source=str(path), scenario_sha256="")
    elif "axes" in data or "scenario" in data:
        raise InputError(
            "this is a sweep file: list the channels of its scenario (scenario: "
            "...); every run of a sweep writes the same columns",
            file=str(path),
        )
    else:
        raise InputError(
            "neither a line file (elements: ...) nor a scenario (line: ...): "
            "r2rsim list channels LINE|SCENARIO",
            file=str(path),
        )
    table = channels_table(plan).to_pydict()
    print(f"{'channel':<44} {'unit':<8} description")
    for name, unit, desc in zip(table["channel"], table["unit"], table["description"], strict=True):
        print(f"{name:<44} {unit or '-':<8} {desc}")
    return 0


PLOT_FORMATS = (".png", ".svg", ".pdf")


def _plot_output(output: str, dataset: str, overwrite: bool = False) -> Path:
    """The file ``r2rsim plot`` writes, checked before any work: a known extension, an
    existing directory to put it in, not inside the dataset (whose manifest lists every
    file it holds), and no existing file unless ``--overwrite``."""
    out = Path(output)
    if out.suffix.lower() not in PLOT_FORMATS:
        raise InputError(
            f"-o {output}: unknown figure format '{out.suffix}' (use {', '.join(PLOT_FORMATS)})"
        )
    if out.is_dir():
        raise InputError(f"-o {output}: is a directory; name the file to write")
    if not out.parent.resolve().is_dir():
        raise InputError(f"-o {output}: no directory {out.parent} to write into")
    if out.resolve().is_relative_to(Path(dataset).resolve()):
        raise InputError(
            f"-o {output}: inside the dataset {dataset}; write the figure "
            f"elsewhere (a dataset holds only its own files)"
        )
    if out.exists() and not overwrite:
        raise InputError(f"-o {output}: the file exists; pass --overwrite to replace it")
    return out


def _cmd_plot(args) -> int:
    """``r2rsim plot``: a run figure, or with --sweep a sweep figure, saved to one file."""
    from .report import plot_run, plot_sweep

    out = _plot_output(args.output, args.dataset, args.overwrite)
    if args.sweep is not None:
        if args.run is not None or args.channels is not None:
            raise InputError("--sweep plots every run: drop --run and --channels")
        fig = plot_sweep(
            args.dataset,
            args.sweep,
            args.statistic,
            args.axis,
            group=args.group,
            t0=args.t0,
            t1=args.t1,
            verify=not args.no_verify,
        )
    else:
        if (args.axis, args.group) != (None, None):
            raise InputError("--axis and --group go with --sweep CHANNEL")
        fig = plot_run(
            args.dataset, args.run, args.channels, args.t0, args.t1, verify=not args.no_verify
        )
    fig.savefig(out, format=out.suffix.lower()[1:])
    print(f"wrote {out}")
    return 0


def _add_plot_parser(sub) -> None:
    pl = sub.add_parser(
        "plot",
        help="plot a run's channels, faults and events, or a sweep statistic, to "
        "a PNG/SVG/PDF file (needs matplotlib: the [plot] extra)",
        description="Plot one run of DATASET: the chosen channels on shared time axes, one "
        "axes per quantity, fault windows shaded, events marked. With --sweep CHANNEL: the "
        "statistic of CHANNEL per run against a sweep axis. Without -o the figure goes to "
        "plot.png in the current directory; an existing file is kept unless --overwrite. "
        "The dataset is checked against its manifest.json first, as every command that "
        "reads one does: every listed file there with its size, and each file the figure "
        "reads (the runs, channels, faults and events tables, the samples files it opens) "
        "with its sha256; a dataset changed after it was written, or an unfinished sweep, "
        "is refused (exit 2). --no-verify draws it anyway.",
    )
    pl.add_argument("dataset", metavar="DATASET", help="dataset directory (r2rsim run or sweep)")
    pl.add_argument("--run", metavar="ID", help="run id (default: the first run)")
    pl.add_argument(
        "--channels",
        nargs="+",
        metavar="GLOB",
        help="column globs, e.g. 'state.span*.tension_N' 'meas.*' (default: "
        "span tensions, readings, set-points, speeds, positions, radii, torques)",
    )
    pl.add_argument("--t0", type=_duration_arg, metavar="T", help="window start (s or with units)")
    pl.add_argument("--t1", type=_duration_arg, metavar="T", help="window end")
    pl.add_argument(
        "--sweep",
        metavar="CHANNEL",
        help="plot a statistic of CHANNEL per run against a sweep axis",
    )
    pl.add_argument(
        "--statistic",
        default="mean",
        choices=["mean", "std", "min", "max", "rms"],
        help="with --sweep: per run, over --t0..--t1 (default: mean)",
    )
    pl.add_argument(
        "--axis", metavar="NAME", help="with --sweep: the x axis (default: the first sweep axis)"
    )
    pl.add_argument("--group", metavar="NAME", help="with --sweep: colour by this axis")
    pl.add_argument(
        "-o",
        "--output",
        default="plot.png",
        help="figure file, .png, .svg or .pdf (default: plot.png)",
    )
    pl.add_argument("--overwrite", action="store_true", help="replace the figure file if it exists")
    pl.add_argument(
        "--no-verify",
        action="store_true",
        help="draw a dataset whose files differ from their manifest.json sizes "
        "or checksums (or that has none)",
    )
    pl.set_defaults(func=_cmd_plot)


def _duration_arg(text: str) -> float:
    """``--duration``: a time like the files take (``90``, ``"90 s"``, ``"2 min"``)."""
    from .units import QuantityError, parse_quantity

    try:
        return parse_quantity(text, "time")
    except QuantityError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _run_command(args) -> int:
    """Run the subcommand. Plausibility warnings (:class:`r2rsim.errors.PlausibilityWarning`,
    issued while files load) are printed as ``warning: file: path: message`` on stderr, each
    one once (a line file read again for its scenario warns again), and the command carries
    on."""
    import warnings

    from .errors import PlausibilityWarning

    with warnings.catch_warnings():
        show_other = warnings.showwarning
        shown = set()

        def show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, PlausibilityWarning):
                where = getattr(message, "file", None)
                key = (
                    where and str(Path(where).resolve()),
                    getattr(message, "path", None),
                    getattr(message, "message", str(message)),
                )
                if key not in shown:
                    shown.add(key)
                    print(f"warning: {message}", file=sys.stderr)
            else:
                show_other(message, category, filename, lineno, file, line)

        warnings.simplefilter("always", PlausibilityWarning)
        warnings.showwarning = show
        return args.func(args)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="r2rsim",
        description="Roll-to-roll web-handling line simulator with labelled Parquet datasets.",
    )
    p.add_argument("--version", action="version", version=f"r2rsim {__version__}")
    p.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = p.add_subparsers(dest="command", required=True)
    for add in (
        _add_run_parser,
        _add_sweep_parser,
        _add_file_parsers,
        _add_diagnose_parser,
        _add_bench_parser,
        _add_report_parser,
        _add_export_parser,
        _add_list_parser,
        _add_plot_parser,
    ):
        add(sub)
    for sp in sub.choices.values():  # `r2rsim run X --debug` as well as `r2rsim --debug run X`
        sp.add_argument(
            "--debug",
            action="store_true",
            default=argparse.SUPPRESS,
            help="show tracebacks on errors",
        )
    return p


def _add_run_parser(sub) -> None:
    r = sub.add_parser("run", help="run a scenario and write its dataset")
    r.add_argument("scenario")
    r.add_argument(
        "-o",
        "--output",
        help="dataset directory (default: the scenario's "
        "output, else runs/NAME); must not exist, or be empty",
    )
    r.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the output directory if it holds an r2rsim dataset (never "
        "a directory holding other files)",
    )
    r.add_argument("--seed", type=int, help="root seed (overrides the scenario)")
    r.add_argument(
        "--duration",
        type=_duration_arg,
        help="simulated time, s or with units ('90 s', '2 min'); overrides the scenario",
    )
    r.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    r.set_defaults(func=_cmd_run)


def _add_sweep_parser(sub) -> None:
    sw = sub.add_parser(
        "sweep",
        help="run a sweep file (a base scenario x axes x seeds) "
        "into one dataset; continues an unfinished one",
    )
    sw.add_argument("sweep")
    sw.add_argument(
        "-o",
        "--output",
        help="dataset directory (default: the sweep's output, "
        "else runs/NAME); a directory holding this sweep is continued",
    )
    sw.add_argument(
        "--workers",
        type=int,
        help="worker processes (default: by the planned "
        "work, one per 2000 simulated seconds of runs, at most one per core; 0: in "
        "this process)",
    )
    sw.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on a Dask cluster: a "
        "scheduler address, or 'local' to start a LocalCluster of --workers "
        "processes (needs dask.distributed: the [dask] extra)",
    )
    sw.add_argument(
        "--retry-failed", action="store_true", help="run again the runs that failed before"
    )
    sw.add_argument(
        "--overwrite",
        action="store_true",
        help="replace a finished r2rsim dataset at the output (never a directory "
        "holding other files)",
    )
    sw.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    sw.set_defaults(func=_cmd_sweep)


def _add_file_parsers(sub) -> None:
    """``validate`` and ``schema``."""
    v = sub.add_parser(
        "validate", help="check line, scenario and sweep files and datasets, list every problem"
    )
    v.add_argument("files", nargs="+")
    v.set_defaults(func=_cmd_validate)

    s = sub.add_parser(
        "schema",
        help="print the JSON Schema of a line, scenario or sweep "
        "file, or (--markdown) a reference of every key",
    )
    # no `choices`: argparse (3.11) checks an empty nargs="*" list against them and fails
    s.add_argument(
        "kind",
        nargs="*",
        metavar="{line,scenario,sweep}",
        help="the file kind (with --markdown: any number, default all)",
    )
    s.add_argument(
        "--markdown",
        action="store_true",
        help="print every key (type, default, meaning) as Markdown tables: the text "
        "of docs/keys.md",
    )
    s.set_defaults(func=_cmd_schema)


def _add_diagnose_parser(sub) -> None:
    d = sub.add_parser(
        "diagnose",
        help="fit a diagnostic plug-in on healthy runs, score "
        "test runs, write predictions and metrics",
    )
    d.add_argument("--method", required=True, help="registered plug-in (r2rsim list plugins)")
    d.add_argument("--train", nargs="+", metavar="DATASET", help="fault-free datasets to fit on")
    d.add_argument(
        "--val",
        nargs="+",
        metavar="DATASET",
        help="fault-free datasets to calibrate the threshold on (M6)",
    )
    d.add_argument("--test", nargs="+", metavar="DATASET", help="datasets to score")
    d.add_argument(
        "--data", nargs="+", metavar="DATASET", help="a pool of datasets to split with --split"
    )
    d.add_argument(
        "--split",
        choices=["seed", "condition"],
        default="seed",
        help="with --data: by seed (60/20/20) or by operating condition",
    )
    d.add_argument("--train-mode", default="OC1", help="--split condition: training mode")
    d.add_argument("--test-mode", default="OC2", help="--split condition: test mode")
    d.add_argument(
        "--val-fraction",
        type=float,
        default=0.25,
        help="--split condition: fraction of the healthy training-mode runs "
        "held out for calibration",
    )
    d.add_argument(
        "--drive-data",
        action="store_true",
        help="also show the plug-in cmd.*, act.* and ctrl.* (drive data)",
    )
    d.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="plug-in parameter (repeatable)",
    )
    d.add_argument(
        "--where",
        action="append",
        default=[],
        metavar="KEY=VALUE[,VALUE]",
        help="only the runs with these runs.parquet values, e.g. a sweep's axis: "
        "offset=-10,10 (repeatable)",
    )
    d.add_argument("--alpha", type=float, default=0.01, help="calibration false-alarm rate")
    d.add_argument(
        "-m",
        "--persistence",
        type=int,
        default=1,
        help="consecutive alarms that confirm a detection",
    )
    d.add_argument("--grace", type=float, default=0.0, help="grace period after a fault [s]")
    # the default is r2rsim.evaluate.metrics.DETECTION_WINDOW_S, written out so that the
    # parser does not import the evaluation stage (tests/test_detection_window.py checks it)
    d.add_argument(
        "--detection-window",
        type=float,
        default=20.0,
        metavar="SECONDS",
        help="W: a fault counts as detected only within W of being fully "
        "developed (default 20 s; inf: up to its end)",
    )
    d.add_argument(
        "--own-threshold",
        choices=("val", "fit"),
        default="val",
        help="the plug-in's own threshold: recalibrated on the val runs at "
        "--alpha (default) or as its fit set it",
    )
    d.add_argument(
        "--mode-strata",
        action="store_true",
        help="also report per-regime strata from label.mode (mode:<name>)",
    )
    d.add_argument(
        "--window",
        choices=("fault", "steady"),
        default="fault",
        help="steady: also report dr/pd/dd over severity-1 samples",
    )
    d.add_argument(
        "--isolation", action="store_true", help="score rank_channels against label.ch.* (hit1)"
    )
    d.add_argument(
        "--vus-buffer",
        type=float,
        default=None,
        metavar="SECONDS",
        help="report vus_pr with buffers from 0 to SECONDS (at most 60 s)",
    )
    d.add_argument("--n-boot", type=int, default=1000, help="bootstrap replicates over runs")
    d.add_argument("--seed", type=int, default=0, help="seed of the bootstrap (0 to 2**64 - 1)")
    d.add_argument(
        "-o",
        "--output",
        help="output directory (default: results/METHOD); must not exist, or be empty",
    )
    d.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the output directory if it holds r2rsim diagnose results "
        "(never a directory holding other files)",
    )
    d.add_argument(
        "--no-verify",
        action="store_true",
        help="use datasets whose files differ from their manifest.json checksums",
    )
    d.set_defaults(func=_cmd_diagnose)


def _add_bench_parser(sub) -> None:
    b = sub.add_parser(
        "bench",
        help="run a diagnostic benchmark spec and compare with its "
        "baseline results (non-zero exit on a regression)",
    )
    b.add_argument("spec")
    b.add_argument("--workdir", help="keep (and reuse) the simulated datasets here")
    b.add_argument("--update", action="store_true", help="write the baseline file")
    b.add_argument(
        "-o",
        "--output",
        help="write results.parquet/.csv into this directory; it must not exist, or be empty",
    )
    b.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the -o directory if it holds r2rsim bench results (never a "
        "directory holding other files)",
    )
    b.add_argument(
        "--no-verify",
        action="store_true",
        help="reuse --workdir datasets without checking their checksums",
    )
    b.set_defaults(func=_cmd_bench)


def _add_list_parser(sub) -> None:
    ls = sub.add_parser(
        "list",
        help="list element, sensor, controller or fault types, "
        "diagnostic plug-ins, or the channels of a line or scenario",
    )
    ls.add_argument(
        "what", choices=["elements", "sensors", "controllers", "faults", "plugins", "channels"]
    )
    ls.add_argument(
        "line",
        nargs="?",
        metavar="FILE",
        help="line or scenario file (for 'channels': the columns a run of it "
        "writes; a scenario's include its set-point and fault-label columns)",
    )
    ls.add_argument(
        "--load",
        action="store_true",
        help="plugins: import every plug-in and check it (slower: imports "
        "scikit-learn and each plug-in's modules); without it they are listed "
        "from their metadata and source",
    )
    ls.set_defaults(func=_cmd_list)


def _quick_exit() -> None:
    """Skip the garbage collector's passes over every live object when the interpreter
    shuts down: with numba's compiled kernels loaded they take about 0.3 s, a fifth of a
    quick-start ``r2rsim run``. Files are closed and stdout flushed before then, so nothing
    is lost; the frozen objects are freed with the process. Only for the console script's
    own process (main() called in-process returns to a caller that may need a full
    shutdown), and only for the commands that load no plug-ins (some extension libraries
    report objects left at exit as leaks)."""
    atexit.register(gc.freeze)


#: what an interrupted command leaves behind, for its one line on stderr (`sweep` says it
#: itself: whether runs were kept depends on how far it got)
_KEPT_WHEN_STOPPED = {
    "run": "no dataset written",
    "sweep": "no run started; runs the sweep finished before, if any, are kept",
    "bench": "the datasets it finished are kept (the next `r2rsim bench` reuses them); no "
    "results or baseline written",
}


def _stopped(command: str | None, exc: KeyboardInterrupt) -> int:
    """Say in one line that the command was stopped and what it kept; its exit status."""
    what = "terminated (SIGTERM)" if isinstance(exc, Terminated) else "interrupted"
    print(f"{what}; {_KEPT_WHEN_STOPPED.get(command or '', 'nothing written')}", file=sys.stderr)
    return EXIT_TERMINATED if isinstance(exc, Terminated) else EXIT_INTERRUPTED


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``r2rsim`` console script.

    From its first line SIGTERM stops a command the way Ctrl-C does, so every stop ends with
    one line on stderr saying what was kept (exit 143 and 130)."""
    args = None
    with _stop_signals_as_interrupts():
        try:
            args = build_parser().parse_args(argv)
            if argv is None and args.command in ("run", "sweep"):
                _quick_exit()
            return _main(args)
        except KeyboardInterrupt as exc:  # Terminated too
            return _stopped(getattr(args, "command", None), exc)
        finally:
            _forget_interrupts_caught_in_eval()


def _forget_interrupts_caught_in_eval() -> None:
    """Keep the exit status ours after an interrupt the command caught.

    CPython (3.11) marks a KeyboardInterrupt that leaves code run by ``exec``/``eval`` of a
    string (numba, dataclasses and namedtuple generate code that way) as unhandled, even when
    a caller catches it; under ``python -m r2rsim.cli`` the interpreter then kills itself with
    SIGINT as it exits (status -2 where 130 or 143 was returned). Each evaluation of a string
    clears that mark first, so evaluating one more clears it."""
    eval("None")


def _main(args) -> int:
    try:
        code = _run_command(args)
        sys.stdout.flush()  # a closed pipe shows here, not at interpreter exit
        return code
    except BrokenPipeError:
        # the reader went away (`r2rsim list channels LINE | head`): stop quietly, and keep
        # Python from complaining when it flushes stdout at exit
        try:
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        except (OSError, ValueError):  # stdout is not a file (embedded use): nothing to do
            pass
        return EXIT_BROKEN_PIPE
    except InputError as exc:
        if args.debug:
            raise
        print(f"error: {exc.format()}", file=sys.stderr)
        return EXIT_INPUT
    except (R2RError, OSError) as exc:
        if args.debug:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILURE


if __name__ == "__main__":
    sys.exit(main())
