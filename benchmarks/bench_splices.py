"""Cost of roll changes: the same 60 s run of Line A (with its dancer) without splices and
with ten flying splices (speed-match error 0.1 %), in one process. Prints the extra wall time,
RHS evaluations and solver steps per splice. Not a timed test.

    python benchmarks/bench_splices.py
"""

from __future__ import annotations

import time
from pathlib import Path

import yaml

import r2rsim
from r2rsim.schema.scenario import ProgrammeStep, ScenarioEvent

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    d = yaml.safe_load((ROOT / "lines" / "pet_film_line_dancer.yaml").read_text())
    unwind = d["elements"][0]
    unwind["spare_roll"] = dict(unwind["roll"])
    unwind["splicer"] = {"type": "flying", "speed_match_error": 0.001}
    line = r2rsim.Line.model_validate(d)
    prog = r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=5.0)])
    cl = r2rsim.compile_line(line, prog)
    y0 = r2rsim.steady_state(cl, r2rsim.nominal_state(cl))
    splices = [ScenarioEvent(at=5.0 + 5.0 * i, type="splice") for i in range(10)]
    r2rsim.simulate(cl, 1.0, 1000.0, y0, events=splices[:1])  # compile the kernels
    rows = {}
    for label, events in (("no splice", []), ("10 splices", splices)):
        walls = []
        for _ in range(3):
            t0 = time.perf_counter()
            res = r2rsim.simulate(cl, 60.0, 1000.0, y0, events=events)
            walls.append(time.perf_counter() - t0)
        walls.sort()
        swaps = sum(e.state == "swap" for e in res.events)
        rows[label] = (walls[1], res.stats["nfev"], res.stats["steps"], swaps)
        print(
            f"{label:>10}: {walls[1]:.3f} s wall (median of 3, RTF {60 / walls[1]:.0f}), "
            f"{res.stats['nfev']} RHS, {res.stats['steps']} steps, {swaps} swaps, "
            f"{len(res.events)} events"
        )
    (w0, f0, s0, _), (w1, f1, s1, n) = rows["no splice"], rows["10 splices"]
    print(
        f"per splice: +{(w1 - w0) / n * 1e3:.1f} ms wall, +{(f1 - f0) / n:.0f} RHS "
        f"evaluations, +{(s1 - s0) / n:.0f} steps"
    )


if __name__ == "__main__":
    main()
