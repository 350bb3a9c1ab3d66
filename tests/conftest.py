"""Shared helpers: write small line/scenario YAML files and run them through the public API."""

from __future__ import annotations

import textwrap
from pathlib import Path

import pytest

import r2rsim
from r2rsim.schema.scenario import ProgrammeStep

REPO = Path(__file__).resolve().parents[1]

# a small valid line and scenario (as parsed YAML) for the bad-input tests to break
SMALL_LINE = {
    "name": "small",
    "web": {"material": "PET", "thickness": "50 um", "width": "1 m"},
    "elements": [
        {
            "id": "unwind",
            "type": "unwind",
            "roll": {"core_radius": "76 mm", "outer_radius": "0.3 m", "core_inertia": 0.5},
        },
        {"id": "idler1", "type": "idler", "radius": 0.05, "inertia": 0.011},
        {"id": "pull", "type": "driven", "radius": 0.1, "inertia": 0.2},
        {
            "id": "rewind",
            "type": "rewind",
            "roll": {"core_radius": "76 mm", "outer_radius": "0.1 m", "core_inertia": 0.5},
        },
    ],
    "spans": [{"length": "1.5 m"}, {"length": 1.0}, {"length": 1.0}],
    "sensors": [{"id": "lc", "type": "load_cell", "element": "idler1"}],
    "controllers": [
        {"id": "speed", "type": "speed_pi", "element": "pull", "master": True, "kp": 25, "ki": 790},
        {
            "id": "tens",
            "type": "tension_pi",
            "element": "unwind",
            "sensor": "lc",
            "setpoint": "200 N",
            "kp": 0.1,
            "ki": 0.5,
        },
    ],
}
SMALL_SCENARIO = {
    "line": "line.yaml",
    "duration": "0.2 s",
    "record_rate": "100 Hz",
    "programme": [{"at": 0, "line_speed": "1 m/s"}],
}


def write(path: Path, text: str) -> Path:
    path.write_text(textwrap.dedent(text), encoding="utf-8")
    return path


def kinematic_line(
    tmp_path: Path,
    *,
    model: str,
    EA: float,
    spans: list[float],
    draws: list[float],
    wound_strain: float = 0.0,
    middle: list[str] | None = None,
    break_stress: str | None = None,
    name: str = "line",
) -> Path:
    """A line of ideal-speed nodes (physics.md 'kinematic nodes'), in YAML.

    ``draws[k]`` is node k's relative speed offset; ``middle`` holds YAML snippets of extra
    keys for the interior nodes (default: ideal-speed driven rollers).
    """
    n = len(spans) + 1
    assert len(draws) == n
    thickness = 1e-4
    E = EA / thickness
    roll = "roll: {core_radius: 0.045, outer_radius: 0.5, core_inertia: 1.0}"
    els = [
        f"  - {{id: src, type: unwind, {roll[:-1]}, wound_in_strain: {wound_strain!r}}}, "
        f"drive: {{type: ideal_speed, draw: {draws[0]!r}}}}}"
    ]
    for k in range(1, n - 1):
        body = (
            middle[k - 1]
            if middle
            else f"type: driven, radius: 0.1, inertia: 0.1, drive: {{type: ideal_speed, "
            f"draw: {draws[k]!r}}}"
        )
        els.append(f"  - {{id: n{k}, {body}}}")
    els.append(
        f"  - {{id: sink, type: rewind, {roll}, drive: {{type: ideal_speed, draw: {draws[-1]!r}}}}}"
    )
    brk = f"break_stress: {break_stress}" if break_stress else "breakable: false"
    text = (
        f"name: {name}\nspan_model: {model}\n"
        f"web: {{thickness: {thickness}, width: 1.0, modulus: {E!r}, density: 1000.0, "
        f"{brk}}}\n"
        "elements:\n"
        + "\n".join(els)
        + "\nspans:\n"
        + "\n".join(f"  - {{length: {L!r}}}" for L in spans)
        + "\n"
    )
    return write(tmp_path / f"{name}.yaml", text)


def run_line(
    path: Path,
    *,
    duration: float,
    rate: float = 1000.0,
    steps=(),
    tension=None,
    span_tension=None,
    rtol: float = 1e-9,
    atol_scale: float = 1e-3,
    initial: str = "nominal",
    extra_yaml: str = "",
    backend: str = "cvode",
):
    """Load, compile and simulate a line file through the public API."""
    line = r2rsim.load_line(path)
    prog = r2rsim.Programme.from_steps(line, [ProgrammeStep(**s) for s in steps])
    cl = r2rsim.compile_line(line, prog)
    y0 = r2rsim.nominal_state(cl, tension, span_tension)
    if initial == "steady":
        y0 = r2rsim.steady_state(cl, y0)
        assert y0 is not None
    res = r2rsim.simulate(
        cl,
        duration,
        rate,
        y0,
        r2rsim.SolverSettings(backend=backend, rtol=rtol, atol_scale=atol_scale),
    )
    return cl, res


@pytest.fixture(scope="session")
def repo() -> Path:
    return REPO


def edited(base: dict, path, value) -> dict:
    """A deep copy of a YAML mapping with the value at ``path`` (keys and list indices)
    replaced."""
    import copy

    d = copy.deepcopy(base)
    node = d
    for p in path[:-1]:
        node = node[p]
    node[path[-1]] = value
    return d


@pytest.fixture(scope="session")
def first_benchmark_home(tmp_path_factory) -> Path:
    """A data home (``r2rsim.datasets``) holding the first benchmark, generated once per test
    session (40 runs of 20 s: about 10 s of CPU) for the tests that read it."""
    from r2rsim import datasets

    home = tmp_path_factory.mktemp("r2rsim_data")
    datasets.load_first_benchmark(data_home=home, quiet=True)
    return home
