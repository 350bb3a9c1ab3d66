"""The refactoring oracle of the physics kernel: what the kernel computes at a few hundred
random states of every shipped scenario and line, recorded once and compared after each step
of a refactoring that must not change a number.

    python benchmarks/refactor_oracle.py record DIR      # with the code before the change
    python benchmarks/refactor_oracle.py compare DIR     # with the code after it

For every scenario file under scenarios/ (its line compiled as a run compiles it: variability,
disturbances and faults drawn at the scenario's seed) and every line file under lines/ (at a
constant 1 m/s), at ``N_STATES`` states around the run's initial state (each state variable
perturbed by 30 % of its size, so that spans go slack, speeds reverse and controllers saturate
at some of them) and times spread over the run: the right-hand side, the dense analytic
Jacobian, the algebraic outputs and the event functions. ``compare`` fails when any value
differs by more than ``RTOL`` relative to the larger of the two (values that are both below
``ATOL_FRACTION`` of their array's largest magnitude are compared against that instead).

The recorded files are outputs of the code, not sources: they live outside the repository
and are deleted when the refactoring is done.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np
import yaml

REPO = Path(__file__).resolve().parents[1]
N_STATES = 200
RTOL = 1e-12
ATOL_FRACTION = 1e-14


def _cases():
    """(name, CompiledLine, initial state, duration) of every scenario and line."""
    from r2rsim.compile import Programme, compile_line
    from r2rsim.run import _prepare, plan_from_file
    from r2rsim.schema import load_line
    from r2rsim.solve import nominal_state

    for path in sorted((REPO / "scenarios").rglob("*.yaml")):
        if "line" not in yaml.safe_load(path.read_text(encoding="utf-8")):
            continue  # a sweep file
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            plan = plan_from_file(path)
            prep = _prepare(plan)
        yield str(path.relative_to(REPO)), prep.cl, prep.y0, plan.scenario.duration
    for path in sorted((REPO / "lines").glob("*.yaml")):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            line = load_line(path)
        cl = compile_line(line, Programme.constant(line, line_speed=1.0))
        yield str(path.relative_to(REPO)), cl, nominal_state(cl), 10.0


def _states(y0: np.ndarray, duration: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``N_STATES`` times over the run and states around ``y0``."""
    rng = np.random.default_rng(seed)
    size = np.where(np.abs(y0) > 0, np.abs(y0), 1e-3)
    Y = y0 + 0.3 * size * rng.standard_normal((N_STATES, len(y0)))
    return np.sort(rng.uniform(0.0, duration, N_STATES)), Y


def _evaluate(cl, T: np.ndarray, Y: np.ndarray) -> dict[str, np.ndarray]:
    rhs = np.array([cl.rhs(t, y) for t, y in zip(T, Y, strict=True)])
    jac = np.array([cl.jacobian(t, y) for t, y in zip(T, Y, strict=True)])
    return {"rhs": rhs, "jac": jac, "outputs": cl.outputs(T, Y), "events": cl.events(T, Y)}


KEYS = ("y0", "rhs", "jac", "outputs", "events")


def _file(root: Path, name: str) -> Path:
    return root / (name.replace("/", "__") + ".npz")


def record(root: Path) -> int:
    root.mkdir(parents=True, exist_ok=True)
    for i, (name, cl, y0, duration) in enumerate(_cases()):
        T, Y = _states(y0, duration, seed=i)
        np.savez(_file(root, name), T=T, Y=Y, y0=y0, **_evaluate(cl, T, Y))
        print(f"recorded {name}: {cl.n_states} states")
    return 0


def _worst(a: np.ndarray, b: np.ndarray) -> float:
    """The largest difference relative to the larger value (or to the array's scale)."""
    if a.shape != b.shape:
        return np.inf
    both_nan = np.isnan(a) & np.isnan(b)
    scale = max(np.nanmax(np.abs(a), initial=0.0), np.nanmax(np.abs(b), initial=0.0))
    den = np.maximum(np.maximum(np.abs(a), np.abs(b)), ATOL_FRACTION * scale)
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = np.where(both_nan | (a == b), 0.0, np.abs(a - b) / den)
    return float(np.nanmax(np.where(np.isnan(rel), np.inf, rel), initial=0.0))


def compare(root: Path) -> int:
    failed = 0
    for name, cl, y0, _ in _cases():
        path = _file(root, name)
        if not path.is_file():
            print(f"MISSING {name}")
            failed += 1
            continue
        ref = np.load(path)
        if ref["Y"].shape[1] != cl.n_states:
            print(f"FAIL {name}: {cl.n_states} states, the record has {ref['Y'].shape[1]}")
            failed += 1
            continue
        got = {"y0": y0, **_evaluate(cl, ref["T"], ref["Y"])}
        worst = {k: _worst(ref[k], got[k]) for k in KEYS}
        bad = {k: v for k, v in worst.items() if v > RTOL}
        print(
            ("FAIL " if bad else "ok   ")
            + name
            + "  "
            + "  ".join(f"{k} {v:.1e}" for k, v in worst.items())
        )
        failed += bool(bad)
    print(f"{failed} case(s) differ by more than {RTOL:g}" if failed else "all cases agree")
    return 1 if failed else 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("action", choices=("record", "compare"))
    ap.add_argument("dir", type=Path, help="where the records are (outside the repository)")
    args = ap.parse_args(argv)
    return record(args.dir) if args.action == "record" else compare(args.dir)


if __name__ == "__main__":
    sys.exit(main())
