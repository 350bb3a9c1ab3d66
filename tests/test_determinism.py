"""The same scenario and seed give the same bytes on any x86-64 CPU (issue 37).

Each case runs a scenario in a fresh process with the environment of another machine and
compares the sha256 of its samples file with a plain run's:

* ``OPENBLAS_CORETYPE``: OpenBLAS's kernels for other CPUs (nothing that feeds the data goes
  through BLAS or LAPACK: the integrator's constants are derived in decimal arithmetic, the
  steady-state Newton solve is plain element-wise arithmetic);
* ``NPY_DISABLE_CPU_FEATURES``: numpy without its AVX2/AVX-512 code paths;
* ``NUMBA_CPU_NAME=generic``: the kernels compiled for a generic x86-64, not for this CPU
  (with its own numba cache: a cold compile, so it is marked slow and run by ``.ci/run``).

What this machine cannot emulate (another glibc, another CPU's libm code paths) is covered
by ``tests/test_detmath.py`` where r2rsim avoids libm.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: (scenario, simulated seconds): the quick-start line, and the calibrated thesis set's base
#: run (variability, disturbances, realistic sensors, a steady-state start)
SCENARIOS = [
    ("scenarios/quickstart.yaml", 20),
    ("scenarios/thesis_realistic/registration.yaml", 20),
]
#: other machines, as far as this one can play them
OTHER_MACHINES = {
    "openblas-haswell": {"OPENBLAS_CORETYPE": "Haswell"},
    "openblas-sandybridge": {"OPENBLAS_CORETYPE": "Sandybridge"},
    "numpy-baseline-simd": {"NPY_DISABLE_CPU_FEATURES": "X86_V3,X86_V4,AVX512_ICL"},
}


def samples_sha256(scenario: str, seconds: float, out: Path, env: dict) -> str:
    """sha256 of the samples file of a run made in a fresh process with ``env`` added."""
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "r2rsim.cli",
            "run",
            str(ROOT / scenario),
            "-o",
            str(out),
            "--duration",
            str(seconds),
            "-q",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={**os.environ, **env},
        timeout=1800,
    )
    assert proc.returncode == 0, proc.stderr
    (part,) = out.glob("samples/*/part-0.parquet")
    return hashlib.sha256(part.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """The plain runs' hashes, by scenario."""
    d = tmp_path_factory.mktemp("plain")
    return {s: samples_sha256(s, sec, d / Path(s).stem, {}) for s, sec in SCENARIOS}


@pytest.mark.parametrize("machine", sorted(OTHER_MACHINES))
@pytest.mark.parametrize("scenario, seconds", SCENARIOS)
def test_same_samples_with_another_machines_libraries(plain, tmp_path, machine, scenario, seconds):
    got = samples_sha256(scenario, seconds, tmp_path / "ds", OTHER_MACHINES[machine])
    assert got == plain[scenario], f"{scenario} differs under {machine}"


@pytest.mark.slow
@pytest.mark.parametrize("scenario, seconds", SCENARIOS)
def test_same_samples_with_kernels_compiled_for_a_generic_cpu(
    plain, tmp_path_factory, scenario, seconds
):
    cache = tmp_path_factory.getbasetemp() / "numba-generic"  # shared by both scenarios
    got = samples_sha256(
        scenario,
        seconds,
        tmp_path_factory.mktemp("generic") / "ds",
        {"NUMBA_CPU_NAME": "generic", "NUMBA_CACHE_DIR": str(cache)},
    )
    assert got == plain[scenario]
