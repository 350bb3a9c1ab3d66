"""Every shipped closed-loop line is linearly stable at its operating point, with a full and
with a nearly empty unwind roll (the roll inertia changes about a hundredfold between the two,
which is where mis-tuned unwind loops go unstable)."""

from __future__ import annotations

import numpy as np
import pytest
import yaml

import r2rsim
from r2rsim.schema.scenario import ProgrammeStep

from conftest import REPO, write

# operating speeds [m/s] of the shipped lines (physics.md §2.3; thesis testbed and the
# registration line run at the thesis scenarios' speeds). single_span.yaml is left out: it is
# the open-loop line of the verification tests and has no operating point of its own.
SPEEDS = {
    "pet_film_line": 5.0,
    "pet_film_line_dancer": 5.0,
    "newsprint_line": 12.0,
    "battery_foil_line": 1.0,
    "thesis_testbed": 0.5,
    "registration": 0.5,
    "pet_film_line_torque_modes": 5.0,
    "registration_realistic": 0.5,
    "thesis_testbed_realistic": 0.5,
    "second_registration_line": 1.5,
}


def test_every_shipped_line_is_listed():
    shipped = {p.stem for p in (REPO / "lines").glob("*.yaml")} - {"single_span"}
    assert shipped == set(SPEEDS)


@pytest.mark.parametrize("roll", ["full", "near_core"])
@pytest.mark.parametrize("name", sorted(SPEEDS))
def test_shipped_line_is_linearly_stable(tmp_path, name, roll):
    d = yaml.safe_load((REPO / "lines" / f"{name}.yaml").read_text())
    if roll == "near_core":
        core = r2rsim.Line.model_validate(d).elements[0].roll.core_radius
        d["elements"][0]["roll"]["outer_radius"] = 1.2 * core
    line = r2rsim.load_line(write(tmp_path / f"{name}.yaml", yaml.safe_dump(d)))
    cl = r2rsim.compile_line(
        line, r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=SPEEDS[name])])
    )
    y = r2rsim.steady_state(cl, r2rsim.nominal_state(cl))
    assert y is not None
    _, lam = cl.linearise(0.0, y)
    # roll lengths are pure integrators (eigenvalue 0); the slow radius drift leaves a few
    # 1e-6 1/s; anything growing faster than e per 1000 s is an instability
    worst = lam[np.argmax(lam.real)]
    assert worst.real < 1e-3, f"{name} ({roll} roll): unstable mode {worst:.4g} 1/s"
