"""When the machine fails, not the run (issue 36): a full disk stops a sweep, which the same
command continues to the same data; an output that cannot be written is refused before
anything is simulated; stops say what was kept; process liveness sends no signal on Windows.

The file-system tests mount small tmpfs file systems, which needs root (CI runs as root);
elsewhere they are skipped with the reason."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

import r2rsim.dataset.paths as paths
from r2rsim.cli import main
from r2rsim.dataset.paths import TEMP_RE
from r2rsim.sweep._execute import environment_error

ROOT = Path(__file__).resolve().parents[1]
QUICKSTART = ROOT / "scenarios" / "quickstart.yaml"
SWEEP = ROOT / "sweeps" / "quickstart.yaml"


def _mount(where: Path, *options: str) -> None:
    where.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", ",".join(options), "tmpfs", str(where)],
        capture_output=True,
        text=True,
    )
    if proc.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here (needs root): {proc.stderr.strip()}")


@pytest.fixture
def mounts():
    """Mount tmpfs file systems for a test; all unmounted at its end."""
    if sys.platform != "linux" or os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root on Linux")
    made: list[Path] = []

    def mount(where: Path, *options: str) -> Path:
        _mount(where, *options)
        made.append(where)
        return where

    yield mount
    for where in reversed(made):
        subprocess.run(["umount", "-l", str(where)], capture_output=True)


def _samples_and_labels(ds: Path) -> dict:
    """What must not differ between two sweeps of the same file: every file's sha256 but
    those of the tables holding wall-clock times, and those tables without the times."""
    files = json.loads((ds / "manifest.json").read_text())["files"]
    out = {
        rel: info["sha256"]
        for rel, info in files.items()
        if rel not in ("runs.parquet", "manifest.json")
    }
    runs = pq.read_table(ds / "runs.parquet").to_pylist()
    out["runs"] = [
        {
            k: v
            for k, v in r.items()
            if "wall" not in k and "real_time" not in k and "compile" not in k
        }
        for r in runs
    ]
    return out


def test_a_full_disk_stops_the_sweep_and_the_same_command_finishes_it(tmp_path, mounts, capsys):
    ref = tmp_path / "ref"
    assert main(["sweep", str(SWEEP), "-o", str(ref), "-q", "--workers", "0"]) == 0
    capsys.readouterr()
    disk = mounts(tmp_path / "disk", "size=1200k")  # room for about 3 of the 12 runs
    out = disk / "ds"
    cmd = ["sweep", str(SWEEP), "-o", str(out), "-q", "--workers", "2"]
    assert main(cmd) == 1
    err = capsys.readouterr().err
    assert "No space left on device" in err and "The finished runs are kept" in err
    assert "run the same command again to continue" in err
    # not a finished-looking dataset: the marker stays, validate and readers refuse it
    assert main(["validate", str(out)]) == 2
    assert "an unfinished sweep" in capsys.readouterr().err
    kept = [p.name for p in (out / ".work").iterdir() if not p.name.startswith(".")]
    assert kept and not any(n.endswith(".failed.json") for n in kept)  # none called failed
    assert 0 < len(kept) < 12
    # space freed: the plain re-run finishes it, to the data of an uninterrupted sweep
    subprocess.run(["mount", "-o", "remount,size=64m", str(disk)], check=True)
    assert main(cmd) == 0
    summary = capsys.readouterr().out
    assert f"{len(kept)} skipped" in summary
    assert main(["validate", str(out)]) == 0
    assert _samples_and_labels(out) == _samples_and_labels(ref)
    assert [e for e in os.listdir(disk) if TEMP_RE.match(e)] == []


def test_an_unwritable_output_is_refused_before_anything_is_simulated(
    tmp_path, mounts, monkeypatch, capsys
):
    import r2rsim.run

    def no_simulation(*args, **kwargs):
        raise AssertionError("simulated although the output cannot be written")

    monkeypatch.setattr(r2rsim.run, "simulate", no_simulation)
    ro = mounts(tmp_path / "ro", "size=1m", "ro")
    for cmd, words in [
        (["run", str(QUICKSTART), "-o", str(ro / "ds")], "is on a read-only file system"),
        (["run", str(QUICKSTART), "-o", str(ro)], "is a mount point"),
        (
            ["sweep", str(SWEEP), "-o", str(ro / "ds"), "--workers", "0"],
            "is on a read-only file system",
        ),
    ]:
        assert main([*cmd, "-q"]) == 2, cmd
        err = capsys.readouterr().err
        assert words in err and "choose another directory" in err or "(-o " in err, err
    # a writable mount point: a run is refused (a rename cannot replace it), a run into a
    # directory inside it works
    rw = mounts(tmp_path / "rw", "size=4m")
    assert main(["run", str(QUICKSTART), "-o", str(rw), "-q"]) == 2
    assert f"give a directory inside it (-o {rw / 'NAME'})" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["run", "sweep"])
def test_an_output_under_a_file_is_bad_input(tmp_path, command, capsys):
    afile = tmp_path / "notes.txt"
    afile.write_text("mine")
    source = QUICKSTART if command == "run" else SWEEP
    assert main([command, str(source), "-o", str(afile / "sub" / "ds"), "-q"]) == 2
    err = capsys.readouterr().err
    assert f"'{afile}' is a file, not a directory" in err
    assert afile.read_text() == "mine" and sorted(tmp_path.iterdir()) == [afile]


def test_errors_of_the_machine_are_told_from_errors_of_the_run():
    import errno

    full = OSError(
        errno.ENOSPC, "Error writing bytes to file. Detail: [errno 28] No space left on device"
    )  # as pyarrow raises it
    try:
        try:
            raise full
        except OSError as exc:
            raise RuntimeError("while writing the dataset") from exc
    except RuntimeError as wrapped:
        env = environment_error(wrapped)
    assert env.errno == errno.ENOSPC and env.strerror == os.strerror(errno.ENOSPC)
    assert environment_error(OSError(errno.EROFS, "x")).errno == errno.EROFS
    assert environment_error(FileNotFoundError(errno.ENOENT, "x")) is None
    assert environment_error(ValueError("solver")) is None
    # a run's own failure is recorded, the sweep goes on (tests/test_sweep.py); an error of
    # the machine is raised from the worker instead of recorded
    import r2rsim.run
    from r2rsim.sweep import plan_sweep
    from r2rsim.sweep._execute import run_one

    spec = plan_sweep(SWEEP).runs[0]

    def disk_full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    work = Path(os.environ.get("TMPDIR", "/tmp"))  # unused: nothing is written
    orig = r2rsim.run.execute
    r2rsim.run.execute = disk_full
    try:
        with pytest.raises(OSError, match="No space left on device"):
            run_one(spec, str(work / "no-such-work-dir"))
    finally:
        r2rsim.run.execute = orig
    assert not (work / "no-such-work-dir").exists()


@pytest.mark.parametrize("delay_s", [0.15, 0.5, 1.0, 2.0])
def test_sigterm_at_any_moment_of_a_sweep_says_what_was_kept(tmp_path, delay_s):
    # two worker processes: the sweep takes several seconds (their start, 12 runs)
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "r2rsim.cli",
            "sweep",
            str(SWEEP),
            "-o",
            str(tmp_path / "ds"),
            "-q",
            "--workers",
            "2",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(delay_s)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 143, (proc.returncode, err)
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("terminated (SIGTERM)"), err
    # what was kept, or (stopped while its arguments were still being read: a loaded machine
    # at 0.15 s) that nothing was written
    assert "kept" in lines[0] or lines[0] == "terminated (SIGTERM); nothing written", err


@pytest.mark.parametrize(
    "module, deferred",
    [
        ("pydantic._internal._generate_schema", True),
        ("multiprocessing.popen_spawn_posix", True),
        ("concurrent.futures.process", True),
        ("concurrent.futures._base", False),  # waiting for results: stops at once
        ("multiprocessingx", False),
        ("r2rsim.sweep._execute", False),
    ],
)
@pytest.mark.parametrize("signum, stop", [(signal.SIGTERM, "Terminated"), (signal.SIGINT, "KI")])
def test_the_stop_handlers_defer_inside_uninterruptible_code_only(
    monkeypatch, module, deferred, signum, stop
):
    """A stop signal that arrives while pydantic runs (pydantic-core builds a validator in
    Rust and calls back into Python: an exception there panicked with pydantic 2.6, exit 1,
    once in CI when the signal met the schema's import) or while a worker process is being
    started (its start-up data half-sent: the worker printed an EOFError traceback, once in
    CI) is sent again a moment later; anywhere else it stops the command at once."""
    from types import SimpleNamespace

    from r2rsim import cli
    from r2rsim.errors import Terminated

    started, installed = [], []
    monkeypatch.setattr(
        cli.threading, "Timer", lambda s, f, a: SimpleNamespace(start=lambda: started.append(a))
    )
    monkeypatch.setattr(cli.signal, "signal", lambda *a: installed.append(a))
    monkeypatch.setattr(cli, "_deferred_since", {})
    handler = cli._raise_terminated if signum == signal.SIGTERM else cli._raise_interrupted
    outer = SimpleNamespace(f_globals={"__name__": module}, f_back=None)
    inner = SimpleNamespace(f_globals={"__name__": "r2rsim.schema.line"}, f_back=outer)
    if deferred:
        handler(signum, inner)
        assert started == [(os.getpid(), signum)] and installed == []
    else:
        with pytest.raises(KeyboardInterrupt) as exc:
            handler(signum, inner)
        assert isinstance(exc.value, Terminated) == (stop == "Terminated")
        assert started == [] and len(installed) == 1  # the next one: the default's


def test_a_stop_is_deferred_for_a_bounded_time(monkeypatch):
    """Stuck inside uninterruptible code, a stop signal interrupts after STOP_DEFER_MAX_S."""
    from types import SimpleNamespace

    from r2rsim import cli

    clock = [100.0]
    started = []
    monkeypatch.setattr(cli, "time", SimpleNamespace(monotonic=lambda: clock[0]))
    monkeypatch.setattr(
        cli.threading, "Timer", lambda s, f, a: SimpleNamespace(start=lambda: started.append(a))
    )
    monkeypatch.setattr(cli.signal, "signal", lambda *a: None)
    monkeypatch.setattr(cli, "_deferred_since", {})
    inside = SimpleNamespace(f_globals={"__name__": "multiprocessing.connection"}, f_back=None)
    cli._raise_interrupted(signal.SIGINT, inside)
    clock[0] += cli.STOP_DEFER_MAX_S * 0.9
    cli._raise_interrupted(signal.SIGINT, inside)
    assert len(started) == 2  # sent again twice
    clock[0] += cli.STOP_DEFER_MAX_S * 0.2
    with pytest.raises(KeyboardInterrupt):
        cli._raise_interrupted(signal.SIGINT, inside)
    assert len(started) == 2 and cli._deferred_since == {}


#: a script run as ``python -m stopper <how> <r2rsim arguments>``: it stops the command at a
#: chosen moment, as a signal from outside would
STOPPER = """
import os, signal, sys, time
from multiprocessing import util
from r2rsim import cli


def main():
    how, argv = sys.argv[1], sys.argv[2:]
    spawn, workers = util.spawnv_passfds, []

    def spawn_then_stop(path, args, passfds):
        pid = spawn(path, args, passfds)
        if any("spawn_main" in os.fsdecode(a) for a in args) and not workers:
            workers.append(pid)
            if how == "ctrl-c":  # the terminal signals the whole group, the new worker too
                time.sleep(1.0)  # it has started and waits for its start-up data
                os.killpg(0, signal.SIGINT)
            else:
                os.kill(os.getpid(), getattr(signal, how))
            time.sleep(0.2)  # the handler runs here, the start-up data not yet sent
        return pid

    util.spawnv_passfds = spawn_then_stop
    if how == "exec":  # an interrupt raised inside exec'd code, and caught
        cli._run_command = lambda args: exec("raise KeyboardInterrupt")
    sys.exit(cli.main(argv))


if __name__ == "__main__":
    main()
"""


def _stopped_command(tmp_path, how, *argv):
    (tmp_path / "stopper.py").write_text(STOPPER)
    proc = subprocess.run(
        [sys.executable, "-m", "stopper", how, *argv],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        start_new_session=True,  # os.killpg(0, ...) reaches this command and its workers only
    )
    return proc.returncode, [ln for ln in proc.stderr.splitlines() if ln.strip()]


@pytest.mark.parametrize(
    "how, code, said",
    [
        ("SIGTERM", 143, "terminated (SIGTERM)"),
        ("SIGINT", 130, "interrupted"),
        ("ctrl-c", 130, "interrupted"),
    ],
)
def test_a_stop_while_a_worker_starts_says_one_line(tmp_path, how, code, said):
    """Stopped between a worker's start and the sending of its start-up data, the sweep
    finishes starting it, stops it and says one line; a worker interrupted as it starts
    (Ctrl-C reaches the whole group) prints nothing. Before, the worker printed an EOFError
    or KeyboardInterrupt traceback."""
    rc, lines = _stopped_command(
        tmp_path, how, "sweep", str(SWEEP), "-o", str(tmp_path / "ds"), "-q", "--workers", "2"
    )
    assert rc == code and len(lines) == 1 and lines[0].startswith(said), (rc, lines)


def test_an_interrupt_caught_inside_exec_keeps_the_exit_status(tmp_path):
    """CPython 3.11 marks a KeyboardInterrupt leaving exec'd code as unhandled even when it
    is caught, and under ``python -m`` then dies of SIGINT at exit (status -2, seen once in
    every few Ctrl-Cs of a starting sweep); the command's own status is kept."""
    rc, lines = _stopped_command(tmp_path, "exec", "run", str(QUICKSTART), "-o", "x")
    assert rc == 130 and lines == ["interrupted; no dataset written"], (rc, lines)
    assert not (tmp_path / "x").exists()


def test_liveness_sends_no_signal_on_windows(monkeypatch):
    asked = []
    monkeypatch.setattr(paths.os, "name", "nt")
    monkeypatch.setattr(paths, "_pid_alive_windows", lambda pid: asked.append(pid) or False)

    def kill(*args):
        raise AssertionError("os.kill would end the process on Windows")

    monkeypatch.setattr(paths.os, "kill", kill)
    assert paths.pid_alive(4321) is False and asked == [4321]


def test_liveness_on_posix():
    if os.name != "posix":
        pytest.skip("POSIX only")
    assert paths.pid_alive(os.getpid())
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    assert not paths.pid_alive(child.pid)
