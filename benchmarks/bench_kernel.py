"""Kernel throughput of this tree against another tree, side by side in one run.

    python benchmarks/bench_kernel.py --base /path/to/other/checkout   # ratios this/base
    python benchmarks/bench_kernel.py                                  # this tree alone

For a few shipped scenarios it measures, in a compiled loop (no Python per call):

* right-hand side calls per second and Jacobian calls per second of the line kernel
  (``r2rsim.compile.kernels.evaluate``) at 50 states around the run's initial state;
* the solver steps, right-hand-side and Jacobian evaluations of a radau5 run of the scenario's
  first ``DURATION_S`` seconds (these must not change at all under a refactoring), and its
  wall time.

With ``--base`` the two trees run in alternating worker processes (base, this, base, this,
...), ``--repeat`` times each, and the table gives the median of each figure and the ratio
this/base: a ratio of calls per second below 1 is slower. A refactoring of the kernel aims
at ratios within ±3 % and identical step counts.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
SCENARIOS = (
    "scenarios/quickstart.yaml",
    "scenarios/thesis_realistic/registration.yaml",
    "scenarios/newsprint_splice.yaml",
    "scenarios/thesis_normal_cycles.yaml",
)
N_STATES = 50
DURATION_S = 10.0
MIN_TIME_S = 0.3


def _modes():
    from r2rsim.compile import layout

    for rhs, jac in (("MODE_RHS", "MODE_JAC"),):
        if hasattr(layout, rhs):
            return int(getattr(layout, rhs)), int(getattr(layout, jac))
    mode = layout.Mode  # after the record families became enums
    return int(mode.RHS), int(mode.JAC)


def _loop():
    from numba import njit

    from r2rsim.compile import kernels

    ev = kernels.evaluate

    @njit
    def loop(n, T, Y, yd, JJ, mode, I, P, W, GI, GC, GV, aux):
        for _ in range(n):
            for s in range(Y.shape[0]):
                ev(T[s], Y[s], yd, JJ, mode, I, P, W, GI, GC, GV, aux)

    return loop


def _calls_per_s(loop, cl, T, Y, mode) -> float:
    import numpy as np

    n = cl.n_states
    JJ = np.zeros((n, n)) if mode else cl._J1
    args = (T, Y, np.zeros(n), JJ, mode, cl.I, cl.P, cl._W, cl._GI, cl._GC, cl._GV, cl._aux0)
    loop(1, *args)  # compile
    reps = 1
    while True:
        t0 = time.perf_counter()
        loop(reps, *args)
        dt = time.perf_counter() - t0
        if dt > MIN_TIME_S:
            return reps * len(T) / dt
        reps *= 4


def worker() -> dict:
    """The figures of the tree this process imports r2rsim from."""
    import numpy as np

    import r2rsim
    from r2rsim.run import _prepare, plan_from_file

    mode_rhs, mode_jac = _modes()
    loop = _loop()
    out = {"r2rsim": str(Path(r2rsim.__file__).parent.parent)}
    for rel in SCENARIOS:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            plan = plan_from_file(HERE / rel)
            prep = _prepare(plan)
        cl, y0 = prep.cl, prep.y0
        rng = np.random.default_rng(0)
        size = np.where(np.abs(y0) > 0, np.abs(y0), 1e-3)
        Y = np.ascontiguousarray(y0 + 0.01 * size * rng.standard_normal((N_STATES, len(y0))))
        T = np.linspace(0.0, DURATION_S, N_STATES)
        res = r2rsim.simulate(cl, duration=DURATION_S, record_rate=100.0, y0=y0)  # warm-up
        cl2 = _prepare(plan).cl
        t0 = time.perf_counter()
        res = r2rsim.simulate(cl2, duration=DURATION_S, record_rate=100.0, y0=y0)
        wall = time.perf_counter() - t0
        out[rel] = {
            "rhs_per_s": _calls_per_s(loop, cl, T, Y, mode_rhs),
            "jac_per_s": _calls_per_s(loop, cl, T, Y, mode_jac),
            "steps": res.stats["steps"],
            "nfev": res.stats["nfev"],
            "njev": res.stats["njev"],
            "run_wall_s": wall,
        }
    return out


def _spawn(tree: Path) -> dict:
    env = dict(os.environ, PYTHONPATH=str(tree))
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker"]
    done = subprocess.run(cmd, env=env, cwd=tree, capture_output=True, text=True, check=True)
    got = json.loads(done.stdout.strip().splitlines()[-1])
    if Path(got["r2rsim"]).resolve() != tree.resolve():
        raise SystemExit(f"the worker imported r2rsim from {got['r2rsim']}, not {tree}")
    return got


FIGURES = ("rhs_per_s", "jac_per_s", "steps", "nfev", "njev", "run_wall_s")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", type=Path, help="another checkout to compare with")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(worker()))
        return 0
    trees = {"this": HERE} | ({"base": args.base} if args.base else {})
    runs: dict[str, list[dict]] = {k: [] for k in trees}
    for _ in range(args.repeat):
        for name in sorted(trees, reverse=True):  # base first, then this
            runs[name].append(_spawn(trees[name]))
    print(f"median of {args.repeat} alternating runs; {N_STATES} states; {DURATION_S:g} s runs")
    head = f"{'scenario':44s} {'figure':11s} {'this':>12s}"
    print(head + (f" {'base':>12s} {'this/base':>10s}" if args.base else ""))
    for rel in SCENARIOS:
        for fig in FIGURES:
            this = statistics.median(r[rel][fig] for r in runs["this"])
            row = f"{rel:44s} {fig:11s} {this:12.6g}"
            if args.base:
                base = statistics.median(r[rel][fig] for r in runs["base"])
                row += f" {base:12.6g} {this / base:10.4f}"
            print(row)
    return 0


if __name__ == "__main__":
    sys.exit(main())
