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

With ``--fair`` (issue 40) it measures the calibrated set's base run against a baseline
that is not at rest: the same line, realistic sensors and run-to-run variability under a
speed programme that visits the set's three operating conditions (OC1 -> OC2 -> OC3 -> OC1,
20 s ramps), disturbances off; then each disturbance alone, all of them, and all of them
with the bearing drags band-limited (``--band-limit``, default 5 Hz). For each: CPU time
of the whole ``r2rsim run`` and of the solver alone (``simulate`` with its outputs), solver
steps, RHS and Jacobian evaluations, LU factorisations, the states that limit the step size
(share of accepted steps whose largest scaled error estimate is that state's), and the
accuracy: the largest difference of any true span tension from a reference run of the same
case at rtol 1e-9 (``--no-accuracy`` skips the references).

    python benchmarks/bench_disturbances.py
    python benchmarks/bench_disturbances.py --fair --repeat 3
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


#: the calibrated set's operating conditions (scenarios/thesis_realistic/registration.yaml)
CONDITIONS = {"OC1": (0.5, 130.0), "OC2": (1.0, 160.0), "OC3": (0.75, 145.0)}


def _moving_programme(duration: float) -> list[dict]:
    """OC1, then OC2, OC3 and OC1 again, each reached by a 20 s ramp, at even intervals."""
    steps = []
    for j, mode in enumerate(("OC1", "OC2", "OC3", "OC1")):
        v, T = CONDITIONS[mode]
        step = {
            "at": round(j * duration / 4.0, 6),
            "line_speed": v,
            "tension": {"registration_loop": T, "unwind_tension": T},
            "mode": mode,
        }
        if j:
            step["ramp"] = min(20.0, duration / 8.0)
        steps.append(step)
    return steps


def _fair_cases(base: dict, band_limit: float) -> dict[str, list]:
    """Disturbance lists by case: none, each alone, all, all with band-limited drags."""
    dist = base["disturbances"]
    cases: dict[str, list] = {"baseline (off)": []}
    for d in dist:
        cases[f"{d['type']} {d['element']}"] = [d]
    cases["all"] = dist
    if band_limit > 0:
        cases[f"all, drags <= {band_limit:g} Hz"] = [
            dict(d, band_limit=f"{band_limit} Hz") if d["type"] == "bearing_drag" else d
            for d in dist
        ]
    return cases


def _count(stats, key) -> str:
    """A solver counter, '-' where the backend (or an older r2rsim) reports none."""
    v = stats.get(key)
    return "-" if v is None else str(v)


def simulate_as_run(path: Path, *, outputs: bool = True, keep: bool = True):
    """``simulate`` a scenario file as ``r2rsim run`` integrates it (variability and
    disturbances drawn, the steady start, its events and faults), without the dataset;
    returns (CPU s of ``simulate``, its result, the compiled line). ``keep=False`` hands the
    samples to a callback that drops them, as a run's writer takes them."""
    from r2rsim.run import _prepare, plan_from_file

    plan = plan_from_file(path)
    prep = _prepare(plan)
    sc = plan.scenario
    c0 = time.process_time()
    res = r2rsim.simulate(
        prep.cl,
        sc.duration,
        sc.record_rate,
        prep.y0,
        sc.solver,
        on_chunk=None if keep else (lambda t, Y, A: None),
        initial_state_mode=prep.init_mode,
        outputs=outputs,
        events=sc.events,
        faults=prep.faults,
        rolls=prep.rolls,
    )
    return time.process_time() - c0, res, prep.cl


def _solver_stats(path: Path, repeat: int):
    """(median solver CPU s, stats, state names, true span tensions) of ``simulate`` with
    outputs (:func:`simulate_as_run`)."""
    runs = [simulate_as_run(path) for _ in range(repeat)]
    _, res, cl = runs[-1]
    spans = [res[f"{s}.tension_N"] for s in cl.span_ids]
    cpu = sorted(r[0] for r in runs)[repeat // 2]
    return cpu, res.stats, cl.state_names, np.column_stack(spans)


def _limits(stats, names, top: int = 3) -> str:
    lim = stats.get("step_limits")
    if lim is None or lim.sum() == 0:
        return "-"
    order = np.argsort(lim)[::-1][:top]
    return ", ".join(f"{names[i]} {100 * lim[i] / lim.sum():.0f}%" for i in order if lim[i])


def fair(repeat: int, duration: float, band_limit: float, accuracy: bool) -> None:
    """Issue 40's benchmark: a baseline that is not at rest, per-disturbance costs, solver
    counters, the states that limit the step size and the accuracy of each case."""
    base = yaml.safe_load(
        (ROOT / "scenarios" / "thesis_realistic" / "registration.yaml").read_text()
    )
    base["line"] = str(ROOT / "lines" / "registration_realistic.yaml")
    base["duration"] = duration
    base["programme"] = _moving_programme(duration)
    cases = _fair_cases(base, band_limit)
    rows = {}
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        paths = {}
        for j, (label, dist) in enumerate(cases.items()):
            paths[label] = tmp / f"case{j}.yaml"
            paths[label].write_text(yaml.safe_dump(dict(base, name=f"case{j}", disturbances=dist)))
        r2rsim.run_scenario(paths["all"], output=tmp / "warm", overwrite=True)  # compile
        runs: dict[str, list[float]] = {k: [] for k in cases}
        for _ in range(repeat):  # alternated, so that machine load hits all cases alike
            for label, path in paths.items():
                c0 = time.process_time()
                r2rsim.run_scenario(path, output=tmp / "out", overwrite=True)
                runs[label].append(time.process_time() - c0)
        for label, path in paths.items():
            cpu, stats, names, T = _solver_stats(path, repeat)
            err = float("nan")
            if accuracy:
                ref = yaml.safe_load(path.read_text())
                ref["solver"] = {**ref.get("solver", {}), "rtol": 1e-9, "atol_scale": 1e-3}
                ref_path = tmp / f"ref_{path.name}"
                ref_path.write_text(yaml.safe_dump(ref))
                T_ref = _solver_stats(ref_path, 1)[3]
                n = min(len(T), len(T_ref))
                err = float(np.max(np.abs(T[:n] - T_ref[:n])))
            rows[label] = (sorted(runs[label])[repeat // 2], cpu, stats, names, err)
    b_run, b_cpu = rows["baseline (off)"][:2]
    print(
        f"calibrated set base run on a moving programme (OC1->OC2->OC3->OC1, 20 s ramps), "
        f"{duration:g} s at 100 Hz, realistic sensors and variability; CPU s, median of "
        f"{repeat}; max |dT|: true span tensions against rtol 1e-9 (sensor A noise 1.5 N)"
    )
    print(
        f"{'case':<28} {'run s':>6} {'x base':>6} {'solver s':>8} {'x base':>6} {'steps':>6} "
        f"{'RHS':>7} {'Jac':>4} {'LU':>5} {'max|dT| N':>9}  step size limited by"
    )
    for label, (run_cpu, cpu, st, names, err) in rows.items():
        print(
            f"{label:<28} {run_cpu:6.3f} {run_cpu / b_run:6.2f} {cpu:8.3f} {cpu / b_cpu:6.1f} "
            f"{st['steps']:6d} {st['nfev']:7d} {st['njev']:4d} {_count(st, 'nlu'):>5} "
            f"{err:9.4f}  "
            f"{_limits(st, names)}"
        )
    worst = rows["all"][0] / b_run
    limited = rows.get(f"all, drags <= {band_limit:g} Hz")
    print(
        f"bar: whole run with all disturbances <= 2x the moving baseline: "
        f"{'PASS' if worst <= 2.0 else 'FAIL'} (x{worst:.2f}"
        + (f"; band-limited x{limited[0] / b_run:.2f})" if limited else ")")
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
    ap.add_argument(
        "--fair",
        action="store_true",
        help="issue 40's benchmark: a moving baseline, per-disturbance costs, counters",
    )
    ap.add_argument(
        "--band-limit",
        type=float,
        default=5.0,
        help="with --fair: the drags' band limit [Hz] (0: no band-limited case)",
    )
    ap.add_argument(
        "--no-accuracy", action="store_true", help="with --fair: skip the reference runs"
    )
    args = ap.parse_args()
    if args.fair:
        fair(
            args.repeat,
            300.0 if args.duration == 120.0 else args.duration,
            args.band_limit,
            not args.no_accuracy,
        )
        return
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
