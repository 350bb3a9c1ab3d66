"""The compiled Radau IIA backend (``solver: {backend: radau5}``): the method's constants, the
banded LU, agreement with scipy's Radau (the same method), a step-count guard, events, and a
dataset run through the CLI. The physics.md verification tests run on it too
(``tests/test_verification.py``)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

import r2rsim
from r2rsim.cli import main
from r2rsim.schema.scenario import ProgrammeStep, ScenarioEvent
from r2rsim.solve import radau

# radau5 steps / RHS evaluations of the Line A speed ramp at rtol 1e-6 (measured when the
# guard was set: 1513 steps, 11597 RHS, 9 Jacobians; scipy's Radau needs 11763 RHS there).
REFERENCE_STEPS = 1513


def test_method_constants_are_those_of_radau_iia():
    A, C = radau.A, radau.C
    # collocation: sum_j a_ij c_j^(k-1) = c_i^k / k for k = 1..3 (simplifying assumption C(3))
    for k in (1, 2, 3):
        np.testing.assert_allclose(A @ C ** (k - 1), C**k / k, atol=1e-15)
    # B(5) with b = last row of A (stiffly accurate): sum_j b_j c_j^(k-1) = 1/k, k = 1..5
    for k in range(1, 6):
        assert A[2] @ C ** (k - 1) == pytest.approx(1.0 / k, abs=1e-14)
    # T block-diagonalises A^-1: real eigenvalue gamma and the pair alpha +- i beta
    L = radau.TI @ np.linalg.inv(A) @ radau.T
    a, b = radau.MU.real, -radau.MU.imag
    np.testing.assert_allclose(L, [[radau.GAMMA, 0, 0], [0, a, b], [0, -b, a]], atol=1e-12)
    assert radau.GAMMA == pytest.approx(3.0 + 3.0 ** (2 / 3) - 3.0 ** (1 / 3), rel=1e-14)
    # the dense-output matrix interpolates the stages: sum_k (Z^T P)_k c_s^(k+1) = Z_s
    Z = np.random.default_rng(0).normal(size=(3, 4))
    Q = radau.P.T @ Z
    np.testing.assert_allclose(np.vander(C, 4, increasing=True)[:, 1:] @ Q, Z, atol=1e-12)


def test_method_constants_are_correctly_rounded_and_machine_independent():
    # columns 2-3 of T as Hairer's RADAU5 types them to 20 digits (its T12, T13, T22, T23;
    # its imaginary part has the opposite sign): the decimal derivation rounds to the very
    # same doubles, which a LAPACK eigen-solve misses by up to ~250 ulps (issue 37)
    assert radau.T[0, 1] == -0.14125529502095420843
    assert radau.T[1, 1] == 0.20412935229379993199
    assert radau.T[0, 2] == 3.0029194105147424492e-02
    assert radau.T[1, 2] == -0.38294211275726193779
    # its first column is scaled to T31 = 0.966...; ours to a last component of 1
    np.testing.assert_allclose(
        radau.T[:2, 0] * 0.96604818261509293619,
        [9.1232394870892942792e-02, 0.24171793270710701896],
        rtol=2e-16,
    )
    # nothing of the derivation goes through LAPACK/BLAS: recomputing gives the same bytes
    # in any process, whatever kernel OpenBLAS picked (tests/test_determinism.py runs the
    # simulator under several)
    again = radau._constants()
    assert again[0] == radau.GAMMA and again[1] == radau.MU
    for x, y in zip(again[2:], (radau.T, radau.TI, radau.P), strict=True):
        assert x.tobytes() == y.tobytes()


@pytest.mark.parametrize("dtype", [float, complex])
def test_band_lu_solves_like_a_dense_solver(dtype):
    rng = np.random.default_rng(1)
    n, kl, ku = 40, 3, 2
    a = np.zeros((n, n), dtype)
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            a[i, j] = rng.normal() + (1j * rng.normal() if dtype is complex else 0.0)
    a[np.arange(n), np.arange(n)] *= 1e-3  # small diagonal: partial pivoting must swap rows
    ku2 = ku + kl
    ab = np.zeros((n, 2 * kl + ku + 1), dtype)
    for i in range(n):
        for j in range(max(0, i - kl), min(n, i + ku + 1)):
            ab[j, i - j + ku2] = a[i, j]
    piv = np.zeros(n, np.int64)
    assert radau.band_lu(ab, piv, n, kl, ku2)
    assert np.any(piv != np.arange(n))
    b = rng.normal(size=n).astype(dtype)
    x = b.copy()
    radau.band_solve(ab, piv, x, n, kl, ku2)
    np.testing.assert_allclose(x, np.linalg.solve(a, b), rtol=1e-9, atol=1e-12)
    singular = np.zeros((n, 2 * kl + ku + 1), dtype)
    assert not radau.band_lu(singular, piv, n, kl, ku2)


def _line_a(repo):
    scen, line, _ = r2rsim.load_scenario(repo / "scenarios" / "speed_ramp.yaml")
    cl = r2rsim.compile_line(line, r2rsim.Programme.from_steps(line, scen.programme))
    y0 = r2rsim.steady_state(cl, r2rsim.nominal_state(cl))
    return cl, y0, scen


def _max_tension_error(cl, res, ref):
    return max(np.max(np.abs(res[f"{s}.tension_N"] - ref[f"{s}.tension_N"])) for s in cl.span_ids)


def test_same_method_as_scipy_radau_and_step_count_guard(repo):
    cl, y0, scen = _line_a(repo)

    def run(**kw):
        return r2rsim.simulate(cl, scen.duration, scen.record_rate, y0, r2rsim.SolverSettings(**kw))

    ref = run(backend="cvode", rtol=1e-10, atol_scale=1e-4)  # an independent integrator
    r5, sp, cv = run(backend="radau5"), run(backend="radau"), run(backend="cvode")
    # measured (40 s ramp of Line A, rtol 1e-6): radau5 5.3e-3 N in 11597 RHS, scipy Radau
    # 5.4e-3 N in 11763 RHS, CVODE BDF2 0.28 N
    e5, ep, ec = (_max_tension_error(cl, r, ref) for r in (r5, sp, cv))
    assert e5 < 1.25 * ep and e5 < 0.01, (e5, ep)
    assert abs(r5.stats["nfev"] - sp.stats["nfev"]) < 0.1 * sp.stats["nfev"]
    assert e5 < ec / 10  # fifth order vs second order at the same rtol
    # the guard: a broken Jacobian reuse, step-size controller or error estimate shows here
    steps = r5.stats["steps"]
    assert 0.8 * REFERENCE_STEPS <= steps <= 1.25 * REFERENCE_STEPS, steps
    assert r5.stats["nfev"] < 10 * steps and r5.stats["njev"] < 30
    # tighter tolerance: the error falls (measured 6.2e-4 N at rtol 1e-8)
    assert _max_tension_error(cl, run(backend="radau5", rtol=1e-8), ref) < 2e-3


def test_events_match_a_tight_reference(repo):
    """Three flying splices on Line A with its dancer: 21 events (splices, the joint passing
    each span), all located in the kernel."""
    d = yaml.safe_load((repo / "lines" / "pet_film_line_dancer.yaml").read_text())
    unwind = d["elements"][0]
    unwind["spare_roll"] = dict(unwind["roll"])
    unwind["splicer"] = {"type": "flying", "speed_match_error": 0.001}
    line = r2rsim.Line.model_validate(d)
    cl = r2rsim.compile_line(
        line, r2rsim.Programme.from_steps(line, [ProgrammeStep(at=0, line_speed=5.0)])
    )
    y0 = r2rsim.steady_state(cl, r2rsim.nominal_state(cl))
    splices = [ScenarioEvent(at=2.0 + 3.0 * i, type="splice") for i in range(3)]

    def run(**kw):
        return r2rsim.simulate(cl, 12.0, 1000.0, y0, r2rsim.SolverSettings(**kw), events=splices)

    ref, r5 = run(backend="cvode", rtol=1e-10, atol_scale=1e-4), run(backend="radau5")
    assert len(ref.events) == 21
    assert [(e.kind, e.component, e.state) for e in r5.events] == [
        (e.kind, e.component, e.state) for e in ref.events
    ]
    # measured: event times within 6e-10 s. Tensions: the largest error is the ringing
    # just after a joint crosses a node, and its size depends on where the steps fall around
    # the restart (0.006 N before the straddled node was latched by the events, 0.020 N
    # after; scipy's Radau, the same method, 0.011 N over the first splice, rtol 1e-6 all).
    # Last-bit changes move the steps: 0.042 N since the step-size controller's x ** 0.25
    # became sqrt(sqrt(x)) (libm's pow rounds differently on different CPUs, issue 37). The
    # bound, 0.06 N, is 2.3e-4 of the 260 N running tension, under a third of CVODE BDF2's
    # 0.21 N.
    assert max(abs(a.t - b.t) for a, b in zip(r5.events, ref.events, strict=True)) < 1e-6
    assert _max_tension_error(cl, r5, ref) < 0.06
    # scipy's Radau (the cross-check backend) over the first splice, at several tolerances:
    # its step sequence (and so whether a step straddles a joint crossing) changes with rtol,
    # the dependency versions and the CPU. When the node a joint straddles was read from the
    # state, the flux jumped inside a step and Radau failed ("required step size is less
    # than spacing between numbers") at rtol 1e-5, 3e-6 and 1e-7 on one machine and 1e-6 on
    # another; before that, every event after the first was lost and a joint event located
    # on the near side of its root stopped the run.
    first = [e for e in ref.events if e.t < 4.0]
    assert len(first) == 7
    for rtol in (1e-5, 1e-6, 1e-7):
        sp = r2rsim.simulate(
            cl, 4.0, 1000.0, y0, r2rsim.SolverSettings(backend="radau", rtol=rtol), events=splices
        )
        assert not sp.terminated, (rtol, sp.termination_reason)
        assert [(e.kind, e.component, e.state) for e in sp.events] == [
            (e.kind, e.component, e.state) for e in first
        ], rtol
        # measured: within 1.2e-8 s at rtol 1e-5, 4.5e-10 s at 1e-6
        assert max(abs(a.t - b.t) for a, b in zip(sp.events, first, strict=True)) < 1e-6


def test_shipped_radau5_scenario_runs_reproducibly(tmp_path, repo, capsys):
    scen = repo / "scenarios" / "speed_ramp_radau5.yaml"
    tables = []
    for k in range(2):
        out = tmp_path / f"ds{k}"
        assert main(["run", str(scen), "-o", str(out), "--duration", "5", "-q"]) == 0
        runs = pq.read_table(out / "runs.parquet").to_pylist()[0]
        assert "Radau IIA" in runs["solver"] and "rtol=1e-06" in runs["solver"]
        assert runs["ended_as_expected"]  # its step and wall-clock budgets are not hit
        assert not runs["terminated"]
        tables.append(pq.read_table(next((out / "samples").glob("*/part-0.parquet"))))
    assert tables[0].num_rows == 2501  # 5 s at 500 Hz
    assert tables[0].equals(tables[1])
    # an unknown backend: one line naming the file and the key, exit 2, nothing written
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        scen.read_text()
        .replace("backend: radau5", "backend: radau6")
        .replace("../lines", str(repo / "lines"))
    )
    capsys.readouterr()
    assert main(["run", str(bad), "-o", str(tmp_path / "bad_out"), "-q"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(bad) in err and "solver.backend" in err
    assert "radau6" in err and not (tmp_path / "bad_out").exists()


def test_memory_chunks_continue_warm_and_keep_the_answer(repo):
    cl, y0, scen = _line_a(repo)

    def run(**kw):
        return r2rsim.simulate(
            cl, scen.duration, scen.record_rate, y0, r2rsim.SolverSettings(backend="radau5", **kw)
        )

    one, many = run(), run(chunk_memory_mb=0.05)  # ~ 100-sample chunks
    ref = r2rsim.simulate(
        cl,
        scen.duration,
        scen.record_rate,
        y0,
        r2rsim.SolverSettings(backend="cvode", rtol=1e-10, atol_scale=1e-4),
    )
    assert many.stats["restarts"] > 100 > one.stats["restarts"]
    # warm: the Jacobian and step size carry over. A cold restart evaluates a Jacobian every
    # time (>= 395 here); measured 151 (390 of 395 calls warm; the rest are Newton's own
    # re-evaluations on ~0.1 s chunks)
    assert many.stats["njev"] < many.stats["restarts"] / 2, many.stats
    assert many.stats["steps"] < 1.3 * one.stats["steps"]
    assert np.array_equal(one.t, many.t)
    assert _max_tension_error(cl, many, ref) < 0.01


def test_cached_integrator_is_rebuilt_when_the_line_kernel_changes():
    # numba keys its cache on the function's own file and bytecode; the integrator inlines
    # the line kernel, so it is built in a closure over a hash of the kernel's sources (a
    # closure variable is part of the cache key). Editing compile/kernels.py alone left the
    # cached integrator running the old right-hand side (seen while fixing eq. 1.4). The hash
    # covers the orchestrator, the layout and every module of the phases (compile/model).
    from r2rsim.compile import kernels, layout

    files = [Path(kernels.__file__), Path(layout.__file__)]
    files += sorted((Path(kernels.__file__).parent / "model").glob("*.py"))
    h = hashlib.sha256()
    for path in files:
        h.update(path.read_bytes())
    stamp = int(h.hexdigest()[:15], 16)
    for fn in (radau.integrate, radau._initial_step):
        cells = [c.cell_contents for c in fn.py_func.__closure__ or ()]
        assert stamp in cells, fn
