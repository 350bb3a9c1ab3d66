"""Cost of the record rate (issue 40): the calibrated set's base run
(scenarios/thesis_realistic/registration.yaml: 300 s, realistic sensors, disturbances and
variability) recorded at 100 Hz and at 1 kHz, in one process, median of ``--repeat``, CPU
time. For each rate: the solver alone with states only (``simulate(outputs=False)``), with
every algebraic output of every sample (what ``r2rsim run`` asks for), and the whole
``r2rsim run`` (measurement, labels, Parquet, validation). Then the 1 kHz / 100 Hz ratio of
each, against the bar of 1.3. Not a timed test.

    python benchmarks/bench_record_rate.py
    python benchmarks/bench_record_rate.py --repeat 5 --duration 120
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import yaml  # noqa: E402
from bench_disturbances import simulate_as_run  # noqa: E402  (this directory)

import r2rsim  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def _solver_cpu(path: Path, outputs: bool) -> float:
    """CPU seconds of ``simulate`` as ``r2rsim run`` integrates the scenario."""
    return simulate_as_run(path, outputs=outputs, keep=False)[0]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--duration", type=float, default=300.0)
    args = ap.parse_args()
    base = yaml.safe_load(
        (ROOT / "scenarios" / "thesis_realistic" / "registration.yaml").read_text()
    )
    base["line"] = str(ROOT / "lines" / "registration_realistic.yaml")
    base["duration"] = args.duration
    rates = (100.0, 1000.0)
    what = ("states only", "with outputs", "whole run")
    cpu: dict[tuple[float, str], list[float]] = {(r, w): [] for r in rates for w in what}
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        paths = {}
        for r in rates:
            paths[r] = tmp / f"rate{int(r)}.yaml"
            paths[r].write_text(yaml.safe_dump(dict(base, name=f"rate{int(r)}", record_rate=r)))
        r2rsim.run_scenario(paths[1000.0], output=tmp / "warm", overwrite=True)  # compile
        for _ in range(args.repeat):  # alternated: machine load hits both rates alike
            for r, path in paths.items():
                cpu[(r, "states only")].append(_solver_cpu(path, False))
                cpu[(r, "with outputs")].append(_solver_cpu(path, True))
                c0 = time.process_time()
                r2rsim.run_scenario(path, output=tmp / "out", overwrite=True)
                cpu[(r, "whole run")].append(time.process_time() - c0)
    med = {k: sorted(v)[len(v) // 2] for k, v in cpu.items()}
    print(
        f"calibrated set base run, {args.duration:g} s, all disturbances; CPU s, median of "
        f"{args.repeat}"
    )
    print(f"{'':<14} {'100 Hz':>8} {'1 kHz':>8} {'ratio':>6}")
    for w in what:
        a, b = med[(100.0, w)], med[(1000.0, w)]
        print(f"{w:<14} {a:8.3f} {b:8.3f} {b / a:6.2f}")
    per_sample = (
        (med[(1000.0, "with outputs")] - med[(1000.0, "states only")])
        - (med[(100.0, "with outputs")] - med[(100.0, "states only")])
    ) / (900.0 * args.duration)
    print(f"outputs: {per_sample * 1e6:.2f} us per extra sample")
    ratio = med[(1000.0, "with outputs")] / med[(100.0, "with outputs")]
    print(
        f"bar: 1 kHz recording <= 1.3x 100 Hz (solver with outputs): "
        f"{'PASS' if ratio <= 1.3 else 'FAIL'} (x{ratio:.2f}; whole run "
        f"x{med[(1000.0, 'whole run')] / med[(100.0, 'whole run')]:.2f})"
    )


if __name__ == "__main__":
    main()
