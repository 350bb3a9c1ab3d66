"""The figures of the README, made with ``r2rsim plot`` (needs matplotlib: pip install -e
".[plot]").

    python docs/make_plots.py

Runs scenarios/thesis_normal_cycles.yaml and scenarios/thesis_dancer_failure.yaml into a
temporary directory and plots the tension of stages 2-5 over time with the splice, slack and
dancer events marked (thesis Fig. 2-13, Fig. 2-15a and b), exactly as a user would:

    r2rsim run scenarios/thesis_normal_cycles.yaml -o out
    r2rsim plot out --channels 'state.span[3469].tension_N' 'state.registration.tension_N' \\
        -o docs/thesis_normal_cycles.png
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

from r2rsim.cli import main

ROOT = Path(__file__).resolve().parents[1]
CHANNELS = [
    "state.span[3469].tension_N",
    "state.registration.tension_N",
    "state.dancer.position_rad",
]


def figure(name: str, tmp: Path) -> None:
    out = tmp / name
    rc = main(["run", str(ROOT / "scenarios" / f"{name}.yaml"), "-o", str(out), "-q"])
    if rc != 0:
        sys.exit(f"r2rsim run {name}: exit {rc}")
    rc = main(
        [
            "plot",
            str(out),
            "--overwrite",
            "--channels",
            *CHANNELS,
            "-o",
            str(ROOT / "docs" / f"{name}.png"),
        ]
    )
    if rc != 0:
        sys.exit(f"r2rsim plot {name}: exit {rc}")


if __name__ == "__main__":
    with tempfile.TemporaryDirectory() as td:
        for scenario in ("thesis_normal_cycles", "thesis_dancer_failure"):
            figure(scenario, Path(td))
