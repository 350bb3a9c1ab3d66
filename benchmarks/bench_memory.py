"""Peak memory of ``r2rsim run`` against run length (benchmarks/README.md, Memory: memory
flat in run length).

Runs a scenario at its duration (1x) and at ``--factor`` times it (10x by default), each in
its own ``r2rsim run`` subprocess writing a dataset to a temporary directory, and prints the
peak resident set size of each run and their ratio. The target is a ratio of at most 1.3.

Each measurement goes through a fresh helper process: ``resource.getrusage(RUSAGE_CHILDREN)``
reports the largest child a process has waited for, so one helper per run keeps the two
figures apart.

Usage::

    python benchmarks/bench_memory.py    # thesis_normal_cycles, 150 s and 1500 s
    python benchmarks/bench_memory.py scenarios/quickstart.yaml --duration 20 --factor 10

This is a measurement, not a timed test; it takes about a minute on the default scenario.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
DEFAULT = REPO / "scenarios" / "thesis_normal_cycles.yaml"


def _measure(scenario: str, duration: float) -> None:
    """Helper mode: one ``r2rsim run`` subprocess; print its peak RSS (KiB) as JSON."""
    with tempfile.TemporaryDirectory(prefix="r2rsim-mem-") as tmp:
        cmd = [
            sys.executable,
            "-m",
            "r2rsim.cli",
            "run",
            scenario,
            "-o",
            str(Path(tmp) / "ds"),
            "--duration",
            repr(duration),
            "-q",
        ]
        p = subprocess.run(cmd, capture_output=True, text=True)
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        samples = next(
            (ln.split()[-2] for ln in p.stdout.splitlines() if ln.startswith("simulated")), "?"
        )
    # ru_maxrss is in KiB on Linux (bytes on macOS)
    scale = 1 if sys.platform != "darwin" else 1 / 1024
    print(
        json.dumps(
            {
                "returncode": p.returncode,
                "maxrss_kib": usage.ru_maxrss * scale,
                "cpu_s": usage.ru_utime + usage.ru_stime,
                "samples": samples,
                "stderr": p.stderr[-500:],
            }
        )
    )


def measure(scenario: str, duration: float) -> dict:
    """Peak RSS of one ``r2rsim run`` of ``scenario`` for ``duration`` seconds."""
    p = subprocess.run(
        [sys.executable, __file__, "--one", scenario, "--duration", repr(duration)],
        capture_output=True,
        text=True,
        check=True,
    )
    res = json.loads(p.stdout.strip().splitlines()[-1])
    if res["returncode"] != 0:
        raise SystemExit(f"r2rsim run failed ({res['returncode']}): {res['stderr']}")
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario", nargs="?", default=str(DEFAULT))
    ap.add_argument(
        "--duration",
        type=float,
        default=150.0,
        help="simulated time of the 1x run [s] (default 150)",
    )
    ap.add_argument("--factor", type=float, default=10.0, help="length of the long run")
    ap.add_argument("--one", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        _measure(args.scenario, args.duration)
        return 0
    # warm the numba cache first, so neither measurement includes a compilation
    measure(args.scenario, min(args.duration, 1.0))
    rows = []
    for mult in (1.0, args.factor):
        d = args.duration * mult
        res = measure(args.scenario, d)
        rows.append((d, res))
        print(
            f"{Path(args.scenario).name} {d:8.1f} s  {res['samples']:>9} samples  "
            f"peak RSS {res['maxrss_kib'] / 1024:8.1f} MiB  (cpu {res['cpu_s']:.1f} s)",
            flush=True,
        )
    ratio = rows[1][1]["maxrss_kib"] / rows[0][1]["maxrss_kib"]
    print(f"ratio {args.factor:g}x / 1x: {ratio:.2f} (target <= 1.3)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
