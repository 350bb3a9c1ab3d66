"""Start-up costs of the command line (issue 37): what a fresh CI runner pays on its first
run, and what every short command pays.

Prints, each measured in a child process (CPU = user + system time of the process and its
children, from ``os.wait4``; wall from the clock):

* **cold compile**: ``r2rsim run scenarios/quickstart.yaml`` with an empty numba cache (its
  own ``NUMBA_CACHE_DIR``), as on a fresh machine; then the functions numba compiled, by
  their own compile time (nested compilations excluded), from numba's event API;
* **warm start-up**: the same run with the cache filled, as a process, and in phases
  measured inside a process: the imports, a first run (with the one-time loading of the
  cached kernels and of lazily imported modules) and a second run in the same process;
* ``r2rsim --help``, ``r2rsim list plugins`` and ``r2rsim diagnose --method no-such`` (an
  unknown method is refused), which should not import scikit-learn, pandas or the plug-ins.

Usage: ``python benchmarks/bench_startup.py [--repeat N] [--skip-cold]``. Not a test: the
figures depend on the machine and its load; the targets (issue 37) are a cold quick-start run
under 20 s of CPU, a warm one under 0.8 s, ``list plugins`` under 0.5 s.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
QUICKSTART = ROOT / "scenarios" / "quickstart.yaml"

# A child that times the compile of every numba function (own time, nested ones excluded)
# while it runs the quick-start scenario in-process.
_PROFILE = r"""
import json, sys, time
from numba.core import event

stack, own = [], {}

class L(event.Listener):
    def on_start(self, ev):
        stack.append([ev.data["dispatcher"].py_func.__qualname__, time.process_time(), 0.0])
    def on_end(self, ev):
        name, t0, nested = stack.pop()
        took = time.process_time() - t0
        own[name] = own.get(name, 0.0) + took - nested
        if stack:
            stack[-1][2] += took

event.register("numba:compile", L())
from r2rsim.run import run_scenario
run_scenario(sys.argv[1], output=sys.argv[2], overwrite=True)
print(json.dumps(own))
"""

# A child that times the phases of a warm run in-process: the imports, a first run (which
# also loads the cached kernels and whatever is imported lazily) and a second run of the same
# scenario in the same process (only the run's own work).
_PHASES = r"""
import json, sys, time
t = [time.process_time()]
from r2rsim.run import run_scenario
t.append(time.process_time())
first = run_scenario(sys.argv[1], output=sys.argv[2], overwrite=True)
t.append(time.process_time())
second = run_scenario(sys.argv[1], output=sys.argv[2], overwrite=True)
t.append(time.process_time())
print(json.dumps({"imports (r2rsim.run)": t[1] - t[0], "first run": t[2] - t[1],
                  "second run in the same process": t[3] - t[2],
                  "one-time: kernels loaded, lazy imports": (t[2] - t[1]) - (t[3] - t[2]),
                  "the simulation (wall, second run)": second.wall_s}))
"""


def _cpu_of(cmd: list[str], env: dict | None = None) -> tuple[float, float, int, str]:
    """CPU seconds (user + system, the process and its children) and wall seconds."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run(
        cmd, capture_output=True, text=True, cwd=ROOT, env={**os.environ, **(env or {})}
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, proc.returncode, proc.stdout + proc.stderr


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="repetitions of the warm figures")
    ap.add_argument("--skip-cold", action="store_true", help="skip the cold compile (~1 min)")
    args = ap.parse_args()
    r2rsim = [sys.executable, "-m", "r2rsim.cli"]
    with tempfile.TemporaryDirectory() as tmp:
        out = str(Path(tmp) / "qs")
        if not args.skip_cold:
            cache = str(Path(tmp) / "numba-cold")
            cpu, wall, code, text = _cpu_of(
                [*r2rsim, "run", str(QUICKSTART), "-o", out, "-q", "--overwrite"],
                {"NUMBA_CACHE_DIR": cache},
            )
            assert code == 0, text
            print(
                f"cold compile: quick-start run with an empty numba cache: {cpu:.1f} s CPU, "
                f"{wall:.1f} s wall"
            )
            cache2 = str(Path(tmp) / "numba-cold2")
            _, _, code, text = _cpu_of(
                [sys.executable, "-c", _PROFILE, str(QUICKSTART), out], {"NUMBA_CACHE_DIR": cache2}
            )
            assert code == 0, text
            own = json.loads(text.strip().splitlines()[-1])
            total = sum(own.values())
            print(
                f"  compiled functions: {len(own)}, {total:.1f} s CPU of compiling "
                f"(own time of each, nested ones excluded):"
            )
            for name, s in sorted(own.items(), key=lambda kv: -kv[1])[:12]:
                print(f"    {s:6.2f} s  {100 * s / total:5.1f} %  {name}")
        # warm: the default cache (filled by a first run)
        _cpu_of([*r2rsim, "run", str(QUICKSTART), "-o", out, "-q", "--overwrite"])
        rows = {
            "warm quick-start run (process)": [
                *r2rsim,
                "run",
                str(QUICKSTART),
                "-o",
                out,
                "-q",
                "--overwrite",
            ],
            "r2rsim --help": [*r2rsim, "--help"],
            "r2rsim list plugins": [*r2rsim, "list", "plugins"],
            "r2rsim diagnose --method no-such": [
                *r2rsim,
                "diagnose",
                "--method",
                "no-such",
                "--data",
                out,
            ],
        }
        print(f"warm start-up, median of {args.repeat} (CPU s, wall s):")
        for label, cmd in rows.items():
            cpus, walls = [], []
            for _ in range(args.repeat):
                cpu, wall, _, _ = _cpu_of(cmd)
                cpus.append(cpu)
                walls.append(wall)
            print(
                f"  {label:<36} {statistics.median(cpus):6.2f} CPU  "
                f"{statistics.median(walls):6.2f} wall"
            )
        phases = []
        for _ in range(args.repeat):
            _, _, code, text = _cpu_of([sys.executable, "-c", _PHASES, str(QUICKSTART), out])
            assert code == 0, text
            phases.append(json.loads(text.strip().splitlines()[-1]))
        print("  phases of a warm run in-process (CPU s, median):")
        for k in phases[0]:
            print(f"    {k:<34} {statistics.median(p[k] for p in phases):6.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
