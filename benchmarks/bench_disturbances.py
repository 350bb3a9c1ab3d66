"""Cost of the process disturbances (issue 16, item 3): the registration line
(lines/registration.yaml) at 0.5 m/s and 1.0 m/s for 120 s, with the disturbances of the
calibrated thesis set (docs/dataset.md §8.2: out_of_round on in_idler 0.05 mm and reg_drive
0.02 mm, bearing_drag 0.02 N·m at 2 Hz on both idlers, wound_in_strain std 3e-5 with a 5 m
correlation length) and without them, side by side in one process. Prints, for each, the
solver alone (``simulate`` with every algebraic output, median of ``--repeat``: wall time,
real-time factor, RHS evaluations, steps) and the whole ``r2rsim run`` (Parquet writing and
checks included: wall time and RTF), and the RTF ratio with / without (the bar: at least
0.5). Not a timed test.

With ``--realistic`` it measures instead the realistic scenario the bar names: the calibrated
set's base run (scenarios/thesis_realistic/registration.yaml: realistic sensors, run-to-run
variability, 300 s) in OC1 and OC2, whole runs with its disturbances and with
``disturbances: []``, alternated, median of ``--repeat``. ``--rtol`` and ``--atol-scale``
set both runs' solver tolerances (default: the scenario's, rtol 1e-6), and the table then
also gives the accuracy they cost: the largest difference of any true span tension
(``state.*.tension_N``) from a reference run of the same seed at rtol 1e-9, against sensor
A's noise (1.5 N).

    python benchmarks/bench_disturbances.py
    python benchmarks/bench_disturbances.py --duration 60 --repeat 1
    python benchmarks/bench_disturbances.py --realistic --repeat 3
    python benchmarks/bench_disturbances.py --realistic --rtol 1e-4 --atol-scale 100
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402
import yaml  # noqa: E402

import r2rsim  # noqa: E402
from r2rsim.compile.compiler import Programme  # noqa: E402
from r2rsim.compile.disturbances import realise_disturbances  # noqa: E402
from r2rsim.schema.loader import load_scenario  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]

HARDER = [
    {"type": "out_of_round", "element": "in_idler", "eccentricity": "0.05 mm"},
    {"type": "out_of_round", "element": "reg_drive", "eccentricity": "0.02 mm"},
    {"type": "bearing_drag", "element": "in_idler", "std": "0.02 N*m", "bandwidth": "2 Hz"},
    {"type": "bearing_drag", "element": "reg_idler", "std": "0.02 N*m", "bandwidth": "2 Hz"},
    {"type": "wound_in_strain", "element": "unwind", "std": 3e-5, "correlation_length": "5 m"},
]


def prepare(tmp: Path, speed: float, duration: float, disturbances: list, name: str):
    """Compile the scenario as ``r2rsim run`` does; return (compiled line, y0, scenario,
    path of the scenario file)."""
    sc = {
        "name": name,
        "line": str(ROOT / "lines" / "registration.yaml"),
        "duration": duration,
        "record_rate": 100.0,
        "seed": 100,
        "warmup": 5.0,
        "initial": {"state": "steady"},
        "programme": [{"at": 0, "line_speed": speed}],
        "disturbances": disturbances,
    }
    path = tmp / f"{name}.yaml"
    path.write_text(yaml.safe_dump(sc))
    scenario, line, _ = load_scenario(path)
    prog = Programme.from_steps(line, scenario.programme)
    ss_process = np.random.SeedSequence(scenario.seed).spawn(3)[0]
    dist = realise_disturbances(scenario, line, ss_process)
    cl = r2rsim.compile_line(line, prog, scenario.faults, dist)
    y0 = r2rsim.nominal_state(cl)
    for d in dist:
        if d.type == "out_of_round":
            y0[cl.index(f"{d.element}.angle")] = d.phase
    y1 = r2rsim.steady_state(cl, y0)
    return cl, (y0 if y1 is None else y1), scenario, path


def measure(cl, y0, scenario, repeat: int):
    """Median wall time of ``repeat`` runs, with every algebraic output computed and
    delivered chunk by chunk (as ``r2rsim run`` does, without the Parquet writing)."""
    walls, res = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        res = r2rsim.simulate(
            cl,
            scenario.duration,
            scenario.record_rate,
            y0,
            scenario.solver,
            on_chunk=lambda t, Y, A: None,
        )
        walls.append(time.perf_counter() - t0)
    walls.sort()
    return walls[len(walls) // 2], res.stats["nfev"], res.stats["steps"], res.terminated


def _tension_error(out: Path, reference: Path) -> float:
    """Largest |difference| of the true span tensions of two runs' datasets [N]."""
    from r2rsim.dataset.read import read_runs

    a, b = (read_runs(p)[0].samples for p in (out, reference))
    cols = [c for c in a.columns if c.startswith("state.") and c.endswith(".tension_N")]
    return float(np.max(np.abs(a[cols].to_numpy(float) - b[cols].to_numpy(float))))


def realistic(repeat: int, rtol: float | None = None, atol_scale: float | None = None) -> None:
    """The bar on the calibrated set's base scenario: whole runs, with and without its
    disturbances, alternated so that machine load hits both alike; with tolerances, also
    the error they cost against a tight reference."""
    base = yaml.safe_load(
        (ROOT / "scenarios" / "thesis_realistic" / "registration.yaml").read_text()
    )
    base["line"] = str(ROOT / "lines" / "registration_realistic.yaml")
    solver = {k: v for k, v in (("rtol", rtol), ("atol_scale", atol_scale)) if v is not None}
    if solver:
        base["solver"] = {**base.get("solver", {}), **solver}
    conditions = {"OC1": (0.5, 130), "OC2": (1.0, 160)}
    worst = 1.0
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        print(
            f"calibrated set base run, {base['duration']}, whole r2rsim run: median of "
            f"{repeat}; solver {solver or 'as the scenario (rtol 1e-6)'}"
        )
        print(
            f"{'condition':>9} {'without s':>10} {'with s':>8} {'RTF without':>12} "
            f"{'RTF with':>9} {'ratio':>6}" + (f" {'max |dT| N':>11}" if solver else "")
        )
        for mode, (v, T) in conditions.items():
            paths = {}
            for label in ("without", "with"):
                sc = dict(base, name=f"{label}_{mode}")
                sc["programme"] = [
                    {
                        "at": 0,
                        "line_speed": v,
                        "mode": mode,
                        "tension": {"registration_loop": T, "unwind_tension": T},
                    }
                ]
                if label == "without":
                    sc["disturbances"] = []
                paths[label] = tmp / f"{label}_{mode}.yaml"
                paths[label].write_text(yaml.safe_dump(sc))
            r2rsim.run_scenario(paths["with"], output=tmp / "warm", overwrite=True)
            walls = {"without": [], "with": []}
            for _ in range(repeat):
                for label, path in paths.items():
                    t0 = time.perf_counter()
                    r2rsim.run_scenario(path, output=tmp / f"out_{label}", overwrite=True)
                    walls[label].append(time.perf_counter() - t0)
            w0, w1 = (sorted(walls[k])[repeat // 2] for k in ("without", "with"))
            duration = 300.0
            worst = min(worst, w0 / w1)
            err = ""
            if solver:
                ref = yaml.safe_load(paths["with"].read_text())
                ref["solver"] = {**ref["solver"], "rtol": 1e-9, "atol_scale": 1e-3}
                paths["ref"] = tmp / f"ref_{mode}.yaml"
                paths["ref"].write_text(yaml.safe_dump(ref))
                r2rsim.run_scenario(paths["ref"], output=tmp / "out_ref", overwrite=True)
                err = f" {_tension_error(tmp / 'out_with', tmp / 'out_ref'):11.4f}"
            print(
                f"{mode:>9} {w0:10.2f} {w1:8.2f} {duration / w0:12.0f} {duration / w1:9.0f} "
                f"{w0 / w1:6.2f}" + err
            )
    print(
        f"bar: RTF with disturbances >= 50 % of without: {'PASS' if worst >= 0.5 else 'FAIL'}"
        f" (worst {worst * 100:.0f} %)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=120.0)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--speeds", type=float, nargs="+", default=[0.5, 1.0])
    ap.add_argument(
        "--realistic",
        action="store_true",
        help="measure the calibrated set's base scenario (whole runs)",
    )
    ap.add_argument("--rtol", type=float, help="with --realistic: both runs' rtol")
    ap.add_argument("--atol-scale", type=float, help="with --realistic: both runs' atol_scale")
    args = ap.parse_args()
    if args.realistic:
        realistic(args.repeat, args.rtol, args.atol_scale)
        return
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        cl, y0, sc, _ = prepare(tmp, 0.5, 1.0, HARDER, "warm")
        r2rsim.simulate(cl, 1.0, 100.0, y0, sc.solver)  # compile the kernels, not timed
        print(f"registration line, {args.duration:g} s, 100 Hz; solver: median of {args.repeat}")
        print(
            f"{'speed':>7} {'disturbances':>12} {'wall s':>8} {'RTF':>7} {'RHS':>8} "
            f"{'steps':>7} {'run wall s':>10} {'run RTF':>8}"
        )
        ratios = {"solver": [], "run": []}
        for v in args.speeds:
            rows = {}
            for label, dist in (("without", []), ("with", HARDER)):
                name = f"{label}_{int(round(v * 1000))}"
                cl, y0, sc, path = prepare(tmp, v, args.duration, dist, name)
                wall, nfev, steps, term = measure(cl, y0, sc, args.repeat)
                t0 = time.perf_counter()
                r2rsim.run_scenario(path, output=tmp / f"out_{name}")
                run_wall = time.perf_counter() - t0
                rows[label] = (wall, nfev, steps, run_wall)
                print(
                    f"{v:>3g} m/s {label:>12} {wall:8.3f} {args.duration / wall:7.0f} "
                    f"{nfev:8d} {steps:7d} {run_wall:10.3f} {args.duration / run_wall:8.0f}"
                    + ("  (terminated)" if term else "")
                )
            (w0, f0, s0, r0), (w1, f1, s1, r1) = rows["without"], rows["with"]
            ratios["solver"].append(w0 / w1)
            ratios["run"].append(r0 / r1)
            print(
                f"{'':>7} with/without: solver RTF x{w0 / w1:.2f} (RHS x{f1 / f0:.0f}, "
                f"steps x{s1 / s0:.0f}), run RTF x{r0 / r1:.2f}"
            )
        for what, r in ratios.items():
            print(
                f"bar ({what}): RTF with disturbances >= 50 % of without: "
                f"{'PASS' if min(r) >= 0.5 else 'FAIL'} (worst {min(r) * 100:.0f} %)"
            )


if __name__ == "__main__":
    main()
