"""Smaller edges of the command line: a line file given to ``run``, ``--debug`` after the
subcommand, a closed pipe, SUNDIALS messages kept off stdout, and the numba compile of a
cold cache announced on stderr and kept out of the wall time and real-time factor."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import time

import pytest
import yaml

import r2rsim.run as run_module
from r2rsim.cli import build_parser, main
from r2rsim.errors import InputError
from r2rsim.solve.compilewatch import compile_seconds, notify_compiling

from conftest import REPO

LINE = REPO / "lines" / "pet_film_line.yaml"
QUICKSTART = REPO / "scenarios" / "quickstart.yaml"
COMPILING = "compiling (first run only)…"


def cli(*args, **kw):
    return subprocess.run(
        [sys.executable, "-m", "r2rsim.cli", *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        **kw,
    )


def scenario_copy(tmp_path, **changes):
    """The quickstart scenario in tmp_path (line path made absolute) with keys changed."""
    data = yaml.safe_load(QUICKSTART.read_text(encoding="utf-8"))
    data["line"] = str((QUICKSTART.parent / data["line"]).resolve())
    data.update(changes)
    path = tmp_path / "scenario.yaml"
    path.write_text(yaml.safe_dump(data), encoding="utf-8")
    return path


# --------------------------------------------------------------------------- a line file


def test_run_on_a_line_file_says_so(tmp_path, capsys):
    out = tmp_path / "x"
    assert main(["run", str(LINE), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith(f"error: {LINE}: ")
    assert "this is a line file, not a scenario" in err
    assert f"r2rsim validate {LINE}" in err and "scenario" in err
    assert not out.exists()
    with pytest.raises(InputError, match="this is a line file"):
        run_module.run_scenario(LINE, output=out)


def test_a_scenario_without_line_key_is_not_called_a_line_file(tmp_path, capsys):
    bad = tmp_path / "s.yaml"
    bad.write_text("programme:\n  - {at: 0 s, line_speed: 1 m/s}\n", encoding="utf-8")
    assert main(["run", str(bad), "-o", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "line file, not a scenario" not in err and "line" in err


# --------------------------------------------------------------------------- --debug


@pytest.mark.parametrize(
    "argv",
    [
        ["run", "S"],
        ["validate", "S"],
        ["schema", "line"],
        ["diagnose", "--method", "pca"],
        ["bench", "S"],
        ["list", "plugins"],
    ],
)
def test_debug_is_accepted_after_every_subcommand(argv):
    p = build_parser()
    assert p.parse_args(argv).debug is False
    assert p.parse_args([*argv, "--debug"]).debug is True
    assert p.parse_args(["--debug", *argv]).debug is True


@pytest.mark.parametrize("where", ["before", "after"])
def test_debug_shows_the_traceback_before_or_after(tmp_path, where):
    argv = ["run", str(tmp_path / "missing.yaml")]
    argv = ["--debug", *argv] if where == "before" else [*argv, "--debug"]
    with pytest.raises(InputError, match="file not found"):
        main(argv)
    assert main(argv[1:] if where == "before" else argv[:-1]) == 2


# --------------------------------------------------------------------------- broken pipe


def test_a_closed_pipe_ends_quietly(tmp_path):
    r, w = os.pipe()
    os.close(r)  # nobody reads: the first write fails with EPIPE, as after `| head` exits
    try:
        p = subprocess.run(
            [sys.executable, "-m", "r2rsim.cli", "list", "channels", str(LINE)],
            stdout=w,
            stderr=subprocess.PIPE,
            text=True,
            timeout=300,
        )
    finally:
        os.close(w)
    assert p.stderr == ""
    assert p.returncode == 141


def test_piped_into_head(tmp_path):
    p = subprocess.run(
        f'"{sys.executable}" -m r2rsim.cli list channels "{LINE}" | head -n 1',
        shell=True,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert p.stdout.split()[:2] == ["channel", "unit"]
    assert p.stderr == ""


# --------------------------------------------------------------------------- CVODE on stdout


def test_cvode_run_prints_only_the_summary(tmp_path, capfd, monkeypatch):
    """SUNDIALS reports a failure with print(); the CLI's stdout holds only the summary."""
    scen = scenario_copy(tmp_path, solver={"backend": "cvode"})
    summaries = []
    real = run_module.run_scenario

    def spy(*a, **kw):
        summaries.append(real(*a, **kw))
        return summaries[-1]

    def poisoned(cl, y):  # a state that is not finite: CVODE prints its error message
        y = y.copy()
        y[cl.index("span2.strain")] = float("nan")
        return y

    monkeypatch.setattr(run_module, "run_scenario", spy)
    monkeypatch.setattr(run_module, "steady_state", poisoned)
    capfd.readouterr()
    code = main(["run", str(scen), "-o", str(tmp_path / "out"), "--duration", "1", "-q"])
    out = capfd.readouterr().out
    (summary,) = summaries
    assert summary.solver_stats["solver_messages"]  # SUNDIALS did speak...
    assert out == summary.format() + "\n"  # ...but not on stdout
    assert code in (0, 1)


def test_cvode_run_stdout_in_a_subprocess(tmp_path):
    scen = scenario_copy(tmp_path, solver={"backend": "cvode"})
    p = cli("run", scen, "-o", tmp_path / "out", "--duration", "2", "-q", cwd=tmp_path)
    assert p.returncode == 0, p.stderr
    assert p.stderr == ""
    lines = p.stdout.splitlines()
    assert lines[0] == f"dataset      {tmp_path / 'out'}"
    assert lines[1].startswith("simulated    ") and "CVODE" in lines[2]
    assert lines[3].startswith("tension [N]") and lines[-1].startswith("events")


# --------------------------------------------------------------------------- numba compile


def test_compile_watch_counts_nested_compiles_once():
    from numba import njit

    @njit
    def inner(x):
        return x * 2.0

    @njit
    def outer(x):
        return inner(x) + 1.0

    calls = []
    c0 = compile_seconds()
    with notify_compiling(calls.append):
        assert outer(1.0) == 3.0
        assert outer(2.0) == 5.0  # compiled: no event
    assert calls == [True, False]
    assert compile_seconds() - c0 > 0
    outer(3)  # a new signature compiles again, outside the block: nobody is told
    assert calls == [True, False]


@pytest.fixture
def compiling_simulate(monkeypatch):
    """simulate() that first compiles a fresh numba function (a cold cache in small)."""
    from numba import njit

    real = run_module.simulate
    seen = {}

    def simulate(*a, **kw):
        @njit
        def fresh(n):
            s = 0.0
            for i in range(n):
                s += i**0.5
            return s

        t0, c0 = time.perf_counter(), compile_seconds()
        fresh(10)
        seen["compile_s"] = compile_seconds() - c0
        c1 = compile_seconds()
        res = real(*a, **kw)
        seen["total_s"] = time.perf_counter() - t0  # compile + simulation
        # the simulation's own wall time without any compile in it (a cold cache)
        seen["sim_s"] = res.stats["wall_s"] - (compile_seconds() - c1)
        return res

    monkeypatch.setattr(run_module, "simulate", simulate)
    return seen


def test_wall_time_excludes_the_compile(tmp_path, monkeypatch):
    """A compile of 1 s inside the simulation (a sleep the watch is told is a compile) is
    left out of the wall time and real-time factor, and reported as compile_s."""
    real_sim, real_cs = run_module.simulate, run_module.compile_seconds
    extra = [0.0]
    seen = {}

    def simulate(*a, **kw):
        time.sleep(1.0)
        extra[0] += 1.0
        res = real_sim(*a, **kw)
        seen["sim_s"] = res.stats["wall_s"] - (real_cs() - c0)  # without real compiles
        return res

    monkeypatch.setattr(run_module, "simulate", simulate)
    monkeypatch.setattr(run_module, "compile_seconds", lambda: real_cs() + extra[0])
    c0 = real_cs()
    s = run_module.run_scenario(QUICKSTART, output=tmp_path / "o", duration=1.0)
    assert s.solver_stats["compile_s"] >= 1.0
    assert seen["sim_s"] - 1e-3 <= s.wall_s < seen["sim_s"] + 0.5
    assert s.real_time_factor == pytest.approx(1.0 / s.wall_s)
    text = s.format()
    assert (
        f"compiled     numba kernels in {s.solver_stats['compile_s']:.1f} s (first run "
        f"only; not in the wall time above)"
    ) in text
    fast = dataclasses.replace(s, solver_stats={**s.solver_stats, "compile_s": 0.3})
    assert "compiled " not in fast.format()  # under a second: not worth a line


def test_compile_notice_on_stderr_not_stdout(tmp_path, capsys, compiling_simulate):
    assert main(["run", str(QUICKSTART), "-o", str(tmp_path / "a"), "--duration", "1"]) == 0
    out, err = capsys.readouterr()
    assert err.count(COMPILING) == 1 and COMPILING not in out
    assert main(["run", str(QUICKSTART), "-o", str(tmp_path / "b"), "--duration", "1", "-q"]) == 0
    out, err = capsys.readouterr()
    assert COMPILING not in err + out


def test_compile_notice_in_the_progress_bar(tmp_path, capsys, monkeypatch, compiling_simulate):
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    assert main(["run", str(QUICKSTART), "-o", str(tmp_path / "a"), "--duration", "1"]) == 0
    out, err = capsys.readouterr()
    assert COMPILING in err and COMPILING not in out
    assert "simulating: 1.0/1.0 s sim" in err  # the bar is back once compiled


# --------------------------------------------------------------------------- quick exit

_EXIT_PROBE = """
import atexit, gc, sys
# registered before main(), so it runs after main()'s own exit handlers
atexit.register(lambda: print("frozen at exit:", gc.get_freeze_count() > 0, flush=True))
from r2rsim.cli import main
sys.argv = ["r2rsim", *sys.argv[1:]]
sys.exit(main())
"""


@pytest.mark.parametrize("command, frozen", [("run", True), ("validate", False)])
def test_the_console_script_skips_the_collector_at_exit_after_a_run(tmp_path, command, frozen):
    """`r2rsim run` and `sweep` freeze the collector at exit (their shutdown took ~0.3 s of
    passes over numba's objects); the dataset is whole; other commands exit as usual."""
    out = tmp_path / "out"
    assert main(["run", str(scenario_copy(tmp_path)), "-o", str(out), "--duration", "2", "-q"]) == 0
    args = (
        ["run", scenario_copy(tmp_path), "-o", out, "--overwrite", "--duration", "2", "-q"]
        if command == "run"
        else ["validate", out]
    )
    p = subprocess.run(
        [sys.executable, "-c", _EXIT_PROBE, *map(str, args)],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert p.returncode == 0, p.stderr
    assert p.stdout.splitlines()[-1] == f"frozen at exit: {frozen}"
    assert main(["validate", str(out)]) == 0


def test_main_called_in_process_leaves_the_shutdown_alone(tmp_path, monkeypatch):
    """A caller of main() (a test, a notebook) keeps a full interpreter shutdown."""
    import atexit
    import gc

    calls, real = [], atexit.register
    monkeypatch.setattr(
        atexit, "register", lambda f, *a, **k: (calls.append(f), real(f, *a, **k))[1]
    )
    assert (
        main(
            [
                "run",
                str(scenario_copy(tmp_path)),
                "-o",
                str(tmp_path / "o"),
                "--duration",
                "1",
                "-q",
            ]
        )
        == 0
    )
    assert gc.freeze not in calls
