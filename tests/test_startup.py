"""Start-up cost of the command line (issue 13, item 8).

``import r2rsim`` is lazy (PEP 562), so the quick commands must not pull in the numerical
stack. Timing would be flaky on a slow CI machine, so these tests check *which* modules a
command imports, in a fresh interpreter, instead of how long it takes.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import r2rsim

REPO = Path(__file__).resolve().parents[1]
LINE = str(REPO / "lines" / "pet_film_line.yaml")

# Modules that cost a large part of a second to import; none is needed to answer these.
HEAVY = ("numba", "scipy", "pandas", "pyarrow", "sklearn", "sksundae", "tqdm")
PROBE = """
import json, sys
from r2rsim.cli import main
try:
    rc = main(json.loads(sys.argv[1]))
except SystemExit as exc:  # --version and --help exit from argparse
    rc = exc.code
print(json.dumps([rc, sorted(m for m in json.loads(sys.argv[2]) if m in sys.modules)]))
"""


def _run_cli(argv: list[str], heavy: tuple[str, ...]) -> tuple[int, list[str]]:
    """Run ``r2rsim argv`` in a fresh interpreter: its exit code and the heavy modules loaded."""
    p = subprocess.run(
        [sys.executable, "-c", PROBE, json.dumps(argv), json.dumps(heavy)],
        capture_output=True,
        text=True,
        cwd=REPO,
        check=True,
    )
    rc, loaded = json.loads(p.stdout.strip().splitlines()[-1])
    return rc, loaded


@pytest.mark.parametrize(
    "argv, heavy",
    [
        (["--version"], HEAVY + ("numpy", "pydantic", "pint")),
        (["list", "elements"], HEAVY + ("numpy", "pydantic", "pint")),
        (["schema", "line"], HEAVY + ("numpy", "pint")),
        (["schema", "sweep"], HEAVY + ("numpy", "pint")),
        (["list", "faults"], HEAVY + ("numpy", "pint")),
        # quantity strings are read by r2rsim.units' own parser; pint only for exotic unit names
        (["validate", LINE], HEAVY + ("numpy", "pint")),
        # the plug-ins are listed from their entry points and source (issue 37)
        (
            ["list", "plugins"],
            HEAVY
            + (
                "r2rsim.diagnostics.base",
                "r2rsim.diagnostics.baselines",
                "r2rsim.diagnostics.gsmms",
                "r2rsim.diagnostics.parity",
                "r2rsim.diagnostics.hybrid_sov",
            ),
        ),
        (["--help"], HEAVY + ("numpy", "pydantic")),
    ],
    ids=[
        "version",
        "list-elements",
        "schema-line",
        "schema-sweep",
        "list-faults",
        "validate-line",
        "list-plugins",
        "help",
    ],
)
def test_quick_commands_do_not_import_the_numerical_stack(argv, heavy):
    rc, loaded = _run_cli(argv, heavy)
    assert rc == 0
    assert loaded == [], f"`r2rsim {' '.join(argv)}` imported {loaded}"


def test_an_unknown_method_is_refused_before_the_heavy_imports(tmp_path):
    rc, loaded = _run_cli(
        ["diagnose", "--method", "no-such", "--data", str(tmp_path)],
        HEAVY + ("r2rsim.diagnostics.base", "r2rsim.evaluate"),
    )
    assert rc == 2 and loaded == []


def test_bare_import_is_lazy_and_names_still_resolve():
    code = """
import sys
import r2rsim
assert "r2rsim.solve" not in sys.modules and "numba" not in sys.modules
assert {"simulate", "compile_line", "load_line", "SolverSettings"} <= set(dir(r2rsim))
from r2rsim.solve import simulate
assert r2rsim.simulate is simulate
print("ok")
"""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert p.returncode == 0, p.stderr
    assert p.stdout.strip() == "ok"


def test_public_names_resolve_through_lazy_access():
    from r2rsim import compile as compile_stage
    from r2rsim import errors, run, schema, solve

    expected = {
        "load_scenario": schema.load_scenario,
        "load_line": schema.load_line,
        "Line": schema.Line,
        "Scenario": schema.Scenario,
        "compile_line": compile_stage.compile_line,
        "Programme": compile_stage.Programme,
        "CompiledLine": compile_stage.CompiledLine,
        "simulate": solve.simulate,
        "steady_state": solve.steady_state,
        "nominal_state": solve.nominal_state,
        "SolverSettings": solve.SolverSettings,
        "SimulationResult": solve.SimulationResult,
        "run_scenario": run.run_scenario,
        "RunSummary": run.RunSummary,
        "InputError": errors.InputError,
        "R2RError": errors.R2RError,
        "SimulationError": errors.SimulationError,
    }
    assert set(expected) | {"__version__"} == set(r2rsim.__all__)
    for name, obj in expected.items():
        assert getattr(r2rsim, name) is obj, name
    assert set(r2rsim.__all__) <= set(dir(r2rsim))
    assert isinstance(r2rsim.__version__, str)
    with pytest.raises(AttributeError, match="no_such_name"):
        r2rsim.no_such_name  # noqa: B018


def test_star_import_gives_every_public_name():
    namespace: dict = {}
    exec("from r2rsim import *", namespace)
    assert set(r2rsim.__all__) <= set(namespace)
