"""Solver benchmark on the docs/solver.md §2 chain line: r2rsim vs scipy Radau.

For each number of spans N the script builds the chain line (unwind roll -> N-1 rollers ->
rewind roll, PET web, random span lengths), runs the scenario (60 s of line time, 1 kHz
output, line speed ramping 1 -> 5 m/s over 0...20 s) with

* r2rsim with ``backend="cvode"``: :func:`r2rsim.simulate` on CVODE BDF (``max_order=2``,
  band, analytic Jacobian),
* r2rsim with ``backend="radau5"`` (the default since 0.2): its compiled Radau IIA
  (:mod:`r2rsim.solve.radau`, the same method as scipy's, the whole integration in one numba
  kernel),
* the peer: ``scipy.integrate.solve_ivp(method="Radau")`` fed the same compiled numba RHS
  and the analytic sparse Jacobian, integrated segment by segment like ``simulate`` does,

and compares all three against a tight reference (CVODE at rtol 1e-10, atol x 1e-4). It
prints three table rows per N with PASS/FAIL against the targets of benchmarks/README.md. "Equal
accuracy": each r2rsim backend is run down a ladder of tolerances until its max tension error
is at most scipy Radau's.

Usage::

    python benchmarks/bench_solver.py            # N = 20, 100, 500
    python benchmarks/bench_solver.py --quick    # N = 20 only (< 1 min)
    python benchmarks/bench_solver.py --n 20 100 --repeat 5
    python benchmarks/bench_solver.py --quick --profile --strict

Timing notes
------------
* Both solvers run after a warm-up call (numba JIT / cache load, imports), in the same
  process, interleaved (r2rsim, Radau, r2rsim, Radau, ...); the reported wall time is the
  median of ``--repeat`` runs.
* r2rsim is run the way :func:`r2rsim.run_scenario` runs it: with an ``on_chunk`` callback
  (memory stays flat; at N = 500 keeping every output column at 1 kHz would need ~3 GB).
  Its wall time therefore includes the algebraic outputs of every sample (all tensions,
  speeds, torques, ... at 1 kHz) and event detection on the sample grid. The Radau wall time
  is the bare ``solve_ivp`` calls (states at 1 kHz); the tensions for the error are computed
  afterwards, untimed, on the 100 Hz subsample only. This favours the peer.
"""

from __future__ import annotations

import os

# Pin BLAS/OpenMP/numba threads before numpy is imported (shared 2-core machines).
for _var in (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "NUMBA_NUM_THREADS",
):
    os.environ[_var] = "1"

import argparse  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from dataclasses import dataclass, field  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import scipy  # noqa: E402
import scipy.sparse as sps  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

# Benchmark the checkout this file lives in (also works when the editable install is stale).
_REPO = Path(__file__).resolve().parents[1]
if str(_REPO) not in sys.path:
    sys.path.insert(0, str(_REPO))

import r2rsim  # noqa: E402
from r2rsim.compile import kernels  # noqa: E402
from r2rsim.schema.scenario import ProgrammeStep  # noqa: E402

# ---- the scenario (docs/solver.md §2) --------------------------------------------------
DURATION = 60.0  # s of line time
RECORD_RATE = 1000.0  # Hz
ERROR_RATE = 100.0  # Hz, subsample on which errors are measured
V_START, V_END, RAMP = 1.0, 5.0, 20.0  # m/s, m/s, s
T_SET = 200.0  # N, tension set-points
RTOL = 1e-6
REF_RTOL, REF_ATOL_SCALE = 1e-10, 1e-4
WARMUP_S = 0.05

# ---- targets (benchmarks/README.md) -----------------------------------------------------
RTF_TARGETS = {20: 200.0, 100: 100.0, 500: 50.0}
RATIO_TARGET = 2.0
ABS_ERR_OK = 0.05  # N; accuracy accepted if not better than Radau but below this


# =========================================================================================
# the line
# =========================================================================================
def chain_line_dict(n_spans: int, seed: int = 0) -> dict:
    """The chain line of docs/solver.md §2 (without the dancer) as a line-file mapping.

    Parameters
    ----------
    n_spans : int
        Number of spans N (>= 2): unwind, N - 1 rollers ``roller1 ... roller{N-1}``, rewind.
    seed : int
        Seed of ``numpy.random.default_rng`` for the span lengths.

    Returns
    -------
    dict
        A mapping accepted by :func:`r2rsim.load_line`.

    Notes
    -----
    Span free lengths are uniform in 0.1...2 m, the first and last span 1 m. Rollers 2, 12,
    22, ... are speed-PI driven rollers (R 0.10 m, J 0.02 kg m^2, 20 Hz speed loop; the first
    one is the master), all others idlers (R 0.05 m, J 1e-3 kg m^2, viscous 1e-5 N m s,
    Coulomb 2e-3 N m). Unwind and rewind are torque-mode tension-PI stands reading a load cell
    on roller 1 and on the rewind.
    """
    if n_spans < 2:
        raise ValueError("the chain line needs at least 2 spans")
    rng = np.random.default_rng(seed)
    lengths = rng.uniform(0.1, 2.0, n_spans)
    lengths[0] = lengths[-1] = 1.0

    stand = {"friction": {"viscous": 0.01}, "drive": {"torque_lag": 1e-3}}
    # docs/solver.md §2: the unwind carries a 0.5 N m, 7 Hz torque ripple (roll eccentricity)
    unwind_drive = {"torque_lag": 1e-3, "torque_ripple": {"amplitude": 0.5, "frequency": 7.0}}
    elements: list[dict] = [
        {
            "id": "unwind",
            "type": "unwind",
            "roll": {"core_radius": 0.076, "outer_radius": 0.3, "core_inertia": 0.5},
            "friction": {"viscous": 0.01},
            "drive": unwind_drive,
        }
    ]
    controllers: list[dict] = []
    master = True
    for k in range(1, n_spans):
        rid = f"roller{k}"
        if k >= 2 and (k - 2) % 10 == 0:
            J = 0.02
            kp = J * 2 * math.pi * 20.0
            ki = kp * 2 * math.pi * 20.0 / 4.0
            elements.append(
                {
                    "id": rid,
                    "type": "driven",
                    "radius": 0.10,
                    "inertia": J,
                    "drive": {"torque_lag": 1e-3},
                }
            )
            ctrl = {"id": f"{rid}_speed", "type": "speed_pi", "element": rid, "kp": kp, "ki": ki}
            ctrl.update({"master": True} if master else {"draw": 0.0})
            controllers.append(ctrl)
            master = False
        else:
            elements.append(
                {
                    "id": rid,
                    "type": "idler",
                    "radius": 0.05,
                    "inertia": 1e-3,
                    "friction": {"viscous": 1e-5, "coulomb": 2e-3},
                }
            )
    elements.append(
        {
            "id": "rewind",
            "type": "rewind",
            "roll": {"core_radius": 0.076, "outer_radius": 0.1, "core_inertia": 0.5},
            **stand,
        }
    )
    sensors = [
        {
            "id": "lc_in",
            "type": "load_cell",
            "element": "roller1",
            "wrap_angle": 3.1416,
            "filter": 0.0,
        },
        {"id": "lc_rewind", "type": "load_cell", "element": "rewind", "filter": 0.0},
    ]
    tension = {"type": "tension_pi", "setpoint": T_SET, "kp": 0.1, "ki": 0.5, "output_limit": 150.0}
    controllers += [
        {"id": "unwind_tension", "element": "unwind", "sensor": "lc_in", **tension},
        {"id": "rewind_tension", "element": "rewind", "sensor": "lc_rewind", **tension},
    ]
    return {
        "name": f"chain_{n_spans}",
        "description": "solver.md §2 chain line (no dancer)",
        "web": {
            "material": "PET",
            "modulus": 4e9,
            "thickness": 50e-6,
            "width": 0.5,
            "density": 1390.0,
        },
        "elements": elements,
        "spans": [{"length": float(x)} for x in lengths],
        "sensors": sensors,
        "controllers": controllers,
    }


def build_case(n_spans: int):
    """Load, programme and compile the chain line; find its initial state.

    Parameters
    ----------
    n_spans : int

    Returns
    -------
    cl : r2rsim.CompiledLine
    y0 : ndarray
        Steady state at t = 0 (or the nominal state when no steady state is found).
    init_mode : str
        ``"steady"`` or ``"nominal"``.
    """
    line = r2rsim.load_line(chain_line_dict(n_spans))
    steps = [
        ProgrammeStep(at=0.0, line_speed=V_START),
        ProgrammeStep(at=0.0, line_speed=V_END, ramp=RAMP),
    ]
    prog = r2rsim.Programme.from_steps(line, steps)
    cl = r2rsim.compile_line(line, prog)
    y_nom = r2rsim.nominal_state(cl)
    y_ss = r2rsim.steady_state(cl, y_nom)
    if y_ss is None:
        return cl, y_nom, "nominal"
    return cl, y_ss, "steady"


def tension_columns(cl) -> np.ndarray:
    """Columns of ``cl.outputs`` holding the span tensions, in span order."""
    return np.array([cl.aux_index(f"{s}.tension_N") for s in cl.span_ids], np.int64)


# =========================================================================================
# runs
# =========================================================================================
@dataclass
class RunResult:
    """Timing, counters and the tensions on the error subsample of one run."""

    wall: float
    nfev: int
    njev: int
    k: np.ndarray  # sample indices (1 kHz grid) of the subsample rows
    T: np.ndarray  # (len(k), N) span tensions [N]
    extra: dict = field(default_factory=dict)


class _TensionRecorder:
    """``on_chunk`` callback keeping the span tensions on the error subsample.

    With ``strain_cols`` the tensions come from the strain states (T = EA·max(eps, 0)), so
    the run needs no algebraic outputs (``simulate(outputs=False)``), like ``solve_ivp``.
    """

    def __init__(
        self,
        cols: np.ndarray,
        rate: float,
        sub_every: int,
        strain_cols: np.ndarray | None = None,
        EA: float = 0.0,
    ):
        self.cols, self.rate, self.every = cols, rate, sub_every
        self.strain_cols, self.EA = strain_cols, EA
        self.k: list[np.ndarray] = []
        self.T: list[np.ndarray] = []

    def __call__(self, t: np.ndarray, Y: np.ndarray, A: np.ndarray | None) -> None:
        k = np.rint(t * self.rate).astype(np.int64)
        m = k % self.every == 0
        if np.any(m):
            self.k.append(k[m])
            if A is None:
                self.T.append(self.EA * np.maximum(Y[np.ix_(m, self.strain_cols)], 0.0))
            else:
                self.T.append(A[np.ix_(m, self.cols)])

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        if not self.k:
            return np.zeros(0, np.int64), np.zeros((0, len(self.cols)))
        return np.concatenate(self.k), np.concatenate(self.T)


def run_r2rsim(cl, y0: np.ndarray, settings, outputs: bool = False) -> RunResult:
    """One timed :func:`r2rsim.simulate` run of the scenario.

    Parameters
    ----------
    cl : r2rsim.CompiledLine
    y0 : ndarray
    settings : r2rsim.SolverSettings
    outputs : bool
        Also compute every algebraic output at every sample (what ``r2rsim run`` does for
        the dataset). False compares like with like: ``solve_ivp`` returns states only.

    Returns
    -------
    RunResult
    """
    every = int(round(RECORD_RATE / ERROR_RATE))
    strain = np.array([cl.index(f"{s}.strain") for s in cl.span_ids], np.int64)
    rec = _TensionRecorder(tension_columns(cl), RECORD_RATE, every, strain, cl.line.web.EA)
    t0 = time.perf_counter()
    res = r2rsim.simulate(cl, DURATION, RECORD_RATE, y0, settings, on_chunk=rec, outputs=outputs)
    wall = time.perf_counter() - t0
    k, T = rec.arrays()
    extra = {
        "terminated": res.terminated,
        "reason": res.termination_reason,
        "inner_wall": res.stats["wall_s"],
        "restarts": res.stats["restarts"],
        "events": len(res.events),
        "steps": res.stats.get("steps"),
    }
    return RunResult(wall, int(res.stats["nfev"]), int(res.stats["njev"]), k, T, extra)


def radau_callbacks(cl):
    """``fun(t, y)`` and sparse ``jac(t, y)`` for ``solve_ivp`` from the compiled kernels.

    Parameters
    ----------
    cl : r2rsim.CompiledLine

    Returns
    -------
    fun, jac : callable
    """
    n = cl.n_states
    f = cl.make_rhs()
    rows, cols = cl.pattern
    JJ = np.zeros((n, n))
    yd = np.zeros(n)
    vals = np.zeros(len(rows))

    def fun(t, y):
        yp = np.empty(n)
        f(t, y, yp)
        return yp

    def jac(t, y):
        kernels.jac_values(t, y, JJ, cl.I, cl.P, cl._W, cl._GI, cl._GC, cl._GV, yd, vals)
        return sps.csc_matrix((vals.copy(), (rows, cols)), shape=(n, n))

    return fun, jac


def _segments(cl, duration: float) -> list[tuple[float, float]]:
    """Integration segments between programme breakpoints (as ``simulate`` uses them)."""
    bps = [b for b in cl.programme.breakpoints if 0.0 < b < duration]
    edges = [0.0, *bps, duration]
    return list(zip(edges[:-1], edges[1:], strict=True))


def _radau_solve(cl, y0, duration, fun, jac, rtol, atol):
    """Integrate [0, duration] with Radau, one ``solve_ivp`` call per programme segment.

    Returns the sample indices, the states at those samples (n_samples, n) and counters.
    """
    n_samples = int(math.floor(duration * RECORD_RATE + 1e-9)) + 1
    sample_t = np.arange(n_samples) / RECORD_RATE
    y = np.array(y0, float)
    ks, Ys = [], []
    nfev = njev = nlu = 0
    k_next = 0
    for a, b in _segments(cl, duration):
        cl.set_segment_start(a)
        k_end = int(np.searchsorted(sample_t, b + 1e-9, side="right"))
        kk = np.arange(k_next, k_end)
        t_eval = np.clip(sample_t[kk], a, b)
        off_grid = len(t_eval) == 0 or t_eval[-1] < b  # breakpoint between two samples
        if off_grid:
            t_eval = np.append(t_eval, b)
        sol = solve_ivp(
            fun, (a, b), y, method="Radau", t_eval=t_eval, jac=jac, rtol=rtol, atol=atol
        )
        if not sol.success:
            raise RuntimeError(f"Radau failed on [{a:g}, {b:g}] s: {sol.message}")
        nfev, njev, nlu = nfev + sol.nfev, njev + sol.njev, nlu + sol.nlu
        y = sol.y[:, -1].copy()
        ks.append(kk)
        Ys.append(sol.y.T[: len(kk)])
        k_next = k_end
    return ks, Ys, nfev, njev, nlu


def run_radau(cl, y0: np.ndarray, rtol: float = RTOL, all_outputs: bool = False) -> RunResult:
    """One timed scipy Radau run of the scenario with the compiled RHS and Jacobian.

    Parameters
    ----------
    cl : r2rsim.CompiledLine
    y0 : ndarray
    rtol : float
    all_outputs : bool
        Also measure (untimed in ``wall``) what computing every algebraic output at every
        1 kHz sample would cost, in chunks of the size :func:`r2rsim.simulate` uses; stored
        as ``extra["all_outputs_s"]``. This is the work r2rsim's wall time includes.

    Returns
    -------
    RunResult
        ``wall`` covers the ``solve_ivp`` calls only; ``extra["outputs_s"]`` is the untimed
        cost of computing the tensions on the error subsample.
    """
    fun, jac = radau_callbacks(cl)
    atol = cl.atol
    t0 = time.perf_counter()
    ks, Ys, nfev, njev, nlu = _radau_solve(cl, y0, DURATION, fun, jac, rtol, atol)
    wall = time.perf_counter() - t0
    # tensions on the subsample, per segment (the set-point outputs read the segment start)
    t1 = time.perf_counter()
    every = int(round(RECORD_RATE / ERROR_RATE))
    cols = tension_columns(cl)
    k_out, T_out = [], []
    for (a, _b), kk, Y in zip(_segments(cl, DURATION), ks, Ys, strict=True):
        m = kk % every == 0
        cl.set_segment_start(a)
        A = cl.outputs(kk[m] / RECORD_RATE, Y[m])
        k_out.append(kk[m])
        T_out.append(A[:, cols])
    extra = {"nlu": nlu, "outputs_s": time.perf_counter() - t1}
    if all_outputs:
        rows = max(16, int(64e6 / 8 / (cl.n_states + len(cl.aux_names))))  # as simulate()
        t1 = time.perf_counter()
        for (a, _b), kk, Y in zip(_segments(cl, DURATION), ks, Ys, strict=True):
            cl.set_segment_start(a)
            for i in range(0, len(kk), rows):
                cl.outputs(kk[i : i + rows] / RECORD_RATE, Y[i : i + rows])
        extra["all_outputs_s"] = time.perf_counter() - t1
    cl.set_segment_start(0.0)
    return RunResult(wall, nfev, njev, np.concatenate(k_out), np.concatenate(T_out), extra)


def warm_up(cl, y0: np.ndarray, rtol: float, radau_rtol: float) -> None:
    """Short untimed runs of both solvers (numba compile / cache load, imports)."""
    for backend in ("cvode", "radau5"):
        r2rsim.simulate(
            cl,
            WARMUP_S,
            RECORD_RATE,
            y0,
            r2rsim.SolverSettings(backend=backend, rtol=rtol),
            on_chunk=lambda t, Y, A: None,
        )
    fun, jac = radau_callbacks(cl)
    cl.set_segment_start(0.0)
    solve_ivp(
        fun,
        (0.0, WARMUP_S),
        y0,
        method="Radau",
        jac=jac,
        rtol=radau_rtol,
        atol=cl.atol,
        t_eval=np.linspace(0.0, WARMUP_S, 6),
    )
    cl.outputs(np.zeros(2), np.vstack([y0, y0]))


def tension_errors(run: RunResult, ref: RunResult) -> tuple[float, float]:
    """Max |T - T_ref| over all spans on the common subsample, and at the last sample.

    Returns
    -------
    max_err, end_err : float
        ``inf`` if the run does not cover the reference's samples.
    """
    common, i_run, i_ref = np.intersect1d(run.k, ref.k, return_indices=True)
    if len(common) != len(ref.k):
        return math.inf, math.inf
    d = np.abs(run.T[i_run] - ref.T[i_ref])
    return float(np.max(d)), float(np.max(d[-1]))


def profile_r2rsim(cl, y0: np.ndarray, settings, log, top: int = 8) -> None:
    """cProfile one extra r2rsim run and log where its wall time goes."""
    import cProfile
    import pstats

    prof = cProfile.Profile()
    prof.enable()
    run = run_r2rsim(cl, y0, settings)
    prof.disable()
    st = pstats.Stats(prof)
    entries = sorted(st.stats.items(), key=lambda kv: kv[1][2], reverse=True)[:top]
    log(f"  profile of one r2rsim run ({run.wall:.3f} s wall, top {top} by own time):")
    for (fname, line, func), (_cc, ncalls, tottime, _cum, _callers) in entries:
        where = f"{Path(fname).parent.name}/{Path(fname).name}:{line}" if line else fname
        log(
            f"    {tottime:8.3f} s {100 * tottime / run.wall:5.1f} %  {ncalls:7d} calls  "
            f"{func} ({where})"
        )


# =========================================================================================
# one benchmark case
# =========================================================================================
def _ladder(cl, y0, ref, backend: str, target: float, log) -> dict | None:
    """The loosest tolerance on a backend's ladder whose max tension error is at most
    ``target`` (Radau's), timed like the main runs; None if no rung reaches it."""
    for rt, sc in EQUAL_ACCURACY_LADDER[backend]:
        run = run_r2rsim(cl, y0, r2rsim.SolverSettings(backend=backend, rtol=rt, atol_scale=sc))
        err = tension_errors(run, ref)[0]
        log(
            f"  ladder {backend}: rtol {rt:g}, atol x {sc:g}: {run.wall:.3f} s, max err {err:.2e} N"
        )
        if err <= target:
            return {"rtol": rt, "atol_scale": sc, "wall": run.wall, "err": err}
    return None


def bench_case(
    n_spans: int,
    repeat: int,
    log,
    rtol: float = RTOL,
    radau_rtol: float = RTOL,
    profile: bool = False,
) -> dict:
    """Run the whole comparison for one N.

    Parameters
    ----------
    n_spans : int
    repeat : int
        Timed runs per solver (interleaved); the median wall time is reported.
    log : callable
        Receives progress lines.
    rtol, radau_rtol : float
        Relative tolerances of r2rsim (both backends) and of scipy's Radau.
    profile : bool
        Also cProfile one extra r2rsim run and log the top entries.

    Returns
    -------
    dict
        The table row: ``r_*`` r2rsim on CVODE, ``c_*`` r2rsim's compiled
        Radau IIA (``radau5``), ``p_*`` the peer (scipy Radau); ``eq``/``c_eq`` the rung of
        each r2rsim backend's ladder that is at least as accurate as the peer.
    """
    t_build = time.perf_counter()
    cl, y0, init_mode = build_case(n_spans)
    log(
        f"N={n_spans}: {cl.n_states} states, Jacobian nnz {len(cl.pattern[0])}, band "
        f"({cl.lband}, {cl.uband}), {len(cl.aux_names)} outputs, initial state {init_mode} "
        f"(built in {time.perf_counter() - t_build:.1f} s)"
    )
    warm_up(cl, y0, rtol, radau_rtol)

    cvode = r2rsim.SolverSettings(backend="cvode", rtol=rtol)
    radau5 = r2rsim.SolverSettings(backend="radau5", rtol=rtol)
    runs_r, runs_c, runs_p = [], [], []
    for i in range(repeat):
        runs_r.append(run_r2rsim(cl, y0, cvode))
        runs_c.append(run_r2rsim(cl, y0, radau5))
        runs_p.append(run_radau(cl, y0, radau_rtol, all_outputs=i == repeat - 1))
        log(
            f"  run {i + 1}/{repeat}: r2rsim cvode {runs_r[-1].wall:.3f} s, radau5 "
            f"{runs_c[-1].wall:.3f} s, scipy Radau {runs_p[-1].wall:.3f} s"
        )
    wall_r = float(np.median([r.wall for r in runs_r]))
    wall_c = float(np.median([r.wall for r in runs_c]))
    wall_p = float(np.median([r.wall for r in runs_p]))
    rr, rc, rp = runs_r[-1], runs_c[-1], runs_p[-1]
    for name, run in (("cvode", rr), ("radau5", rc)):
        if run.extra["terminated"]:
            log(f"  WARNING: r2rsim {name} run terminated early: {run.extra['reason']}")

    t_ref = time.perf_counter()
    ref = run_r2rsim(
        cl, y0, r2rsim.SolverSettings(backend="cvode", rtol=REF_RTOL, atol_scale=REF_ATOL_SCALE)
    )
    log(
        f"  reference (CVODE, rtol {REF_RTOL:g}, atol x {REF_ATOL_SCALE:g}): "
        f"{time.perf_counter() - t_ref:.1f} s, {ref.nfev} RHS evals"
    )
    if ref.extra["terminated"]:
        log(f"  WARNING: reference run terminated early: {ref.extra['reason']}")
    err_r, end_r = tension_errors(rr, ref)
    err_c, end_c = tension_errors(rc, ref)
    err_p, end_p = tension_errors(rp, ref)
    all_out = rp.extra["all_outputs_s"]
    log(
        f"  r2rsim cvode: {rr.extra['steps']} steps, {rr.nfev} RHS, {rr.njev} Jac, "
        f"{rr.extra['restarts']} solver calls; radau5: {rc.extra['steps']} steps, {rc.nfev} "
        f"RHS, {rc.njev} Jac; scipy Radau: {rp.nfev} RHS, {rp.njev} Jac, {rp.extra['nlu']} LU"
    )
    log(
        f"  not in the scipy Radau wall: all {len(cl.aux_names)} outputs at every 1 kHz "
        f"sample (which r2rsim computes) {all_out:.3f} s"
    )
    # the same run computing every algebraic output at every sample, as `r2rsim run` does
    with_out = run_r2rsim(cl, y0, cvode, outputs=True)
    log(
        f"  r2rsim cvode with all {len(cl.aux_names)} algebraic outputs at 1 kHz: "
        f"{with_out.wall:.3f} s (RTF {DURATION / with_out.wall:.1f})"
    )
    eq = _ladder(cl, y0, ref, "cvode", err_p, log)
    c_eq = _ladder(cl, y0, ref, "radau5", err_p, log)
    if profile:
        profile_r2rsim(cl, y0, cvode, log)
    return {
        "out_rtf": DURATION / with_out.wall,
        "eq": eq,
        "c_eq": c_eq,
        "N": n_spans,
        "n": cl.n_states,
        "r_wall": wall_r,
        "r_rtf": DURATION / wall_r,
        "r_nfev": rr.nfev,
        "r_err": err_r,
        "r_end": end_r,
        "c_wall": wall_c,
        "c_rtf": DURATION / wall_c,
        "c_nfev": rc.nfev,
        "c_err": err_c,
        "c_end": end_c,
        "p_wall": wall_p,
        "p_rtf": DURATION / wall_p,
        "p_nfev": rp.nfev,
        "p_err": err_p,
        "p_end": end_p,
        "ratio": wall_p / wall_r,
        "c_ratio": wall_p / wall_c,
    }


#: (rtol, atol scale) rungs tried, loosest first, until a backend is as accurate as scipy's
#: Radau at its tolerance. radau5 is the same method, so its rungs are close together.
EQUAL_ACCURACY_LADDER = {
    "cvode": [
        (1e-6, 1.0),
        (1e-7, 1.0),
        (1e-7, 0.1),
        (1e-8, 0.1),
        (1e-8, 0.01),
        (1e-9, 0.01),
        (1e-10, 0.001),
    ],
    "radau5": [
        (1e-6, 1.0),
        (7e-7, 1.0),
        (5e-7, 1.0),
        (3e-7, 1.0),
        (2e-7, 1.0),
        (1e-7, 1.0),
        (1e-8, 0.1),
        (1e-9, 0.01),
    ],
}


def _ratio_verdict(eq: dict | None, p_wall: float) -> str:
    if eq is None:
        return "FAIL (scipy Radau's accuracy not reached on the ladder)"
    ratio = p_wall / eq["wall"]
    return (
        f"{'PASS' if ratio >= RATIO_TARGET else 'FAIL'} (x{ratio:.2f} at rtol "
        f"{eq['rtol']:g}, atol x {eq['atol_scale']:g})"
    )


def verdicts(row: dict) -> tuple[str, str, str]:
    """PASS/FAIL of the real-time-factor target (on CVODE, the slower r2rsim backend at
    small N) and of the
    ">= 2x scipy Radau at equal or better accuracy" target for each r2rsim backend.

    Equal accuracy: the loosest rung of the backend's ladder whose max tension error is at
    most scipy Radau's; its wall time is compared with scipy Radau's.
    """
    target = RTF_TARGETS.get(row["N"])
    rtf = (
        "n/a"
        if target is None
        else (f"{'PASS' if row['r_rtf'] >= target else 'FAIL'} (>={target:g})")
    )
    return (
        rtf,
        _ratio_verdict(row.get("eq"), row["p_wall"]),
        _ratio_verdict(row.get("c_eq"), row["p_wall"]),
    )


def format_table(rows: list[dict]) -> str:
    """The results table (one row per N)."""
    head = (
        f"{'N':>4} {'states':>6} | {'backend':<13} {'wall s':>7} {'RTF':>7} {'RHS':>7} "
        f"{'maxTerr N':>9} {'endTerr':>8} | {'ratio':>6} | verdicts"
    )
    out = [head, "-" * (len(head) + 50)]
    for r in rows:
        v_rtf, v_cv, v_r5 = verdicts(r)
        for key, name, verdict in (
            ("r", "r2rsim cvode", f"RTF {v_rtf}; >=2x at equal accuracy: {v_cv}"),
            ("c", "r2rsim radau5", f">=2x at equal accuracy: {v_r5}"),
            ("p", "scipy Radau", ""),
        ):
            ratio = f"{r['p_wall'] / r[key + '_wall']:>6.2f}"
            out.append(
                f"{r['N']:>4} {r['n']:>6} | {name:<13} {r[key + '_wall']:>7.3f} "
                f"{r[key + '_rtf']:>7.1f} {r[key + '_nfev']:>7d} {r[key + '_err']:>9.2e} "
                f"{r[key + '_end']:>8.1e} | {ratio} | {verdict}"
            )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns 1 with ``--strict`` if a target failed, else 0."""
    ap = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter
    )
    ap.add_argument(
        "--n",
        type=int,
        nargs="+",
        default=[20, 100, 500],
        metavar="N",
        help="numbers of spans (default: 20 100 500)",
    )
    ap.add_argument("--quick", action="store_true", help="N = 20 only")
    ap.add_argument(
        "--repeat",
        type=int,
        default=None,
        help="timed runs per solver, median reported (default 3)",
    )
    ap.add_argument(
        "--rtol", type=float, default=RTOL, help=f"r2rsim relative tolerance (default {RTOL:g})"
    )
    ap.add_argument(
        "--radau-rtol",
        type=float,
        default=RTOL,
        help=f"Radau relative tolerance (default {RTOL:g})",
    )
    ap.add_argument(
        "--profile",
        action="store_true",
        help="cProfile one extra r2rsim run per N and print where time goes",
    )
    ap.add_argument(
        "--strict",
        action="store_true",
        help="exit with status 1 if any target FAILs (default: report only, since "
        "timings on shared machines are noisy)",
    )
    args = ap.parse_args(argv)
    ns = [20] if args.quick else args.n
    repeat = args.repeat if args.repeat is not None else 3
    if repeat < 1 or min(ns) < 2:
        ap.error("--repeat must be >= 1 and every N >= 2")

    def log(msg: str) -> None:
        print(msg, flush=True)

    log(
        f"r2rsim {r2rsim.__version__} ({Path(r2rsim.__file__).parent}), numpy "
        f"{np.__version__}, scipy {scipy.__version__}, Python {platform.python_version()}, "
        f"{os.cpu_count()} CPUs"
    )
    log(
        f"scenario: {DURATION:g} s, {RECORD_RATE:g} Hz output, line speed {V_START:g} -> "
        f"{V_END:g} m/s over 0...{RAMP:g} s; rtol r2rsim {args.rtol:g}, Radau "
        f"{args.radau_rtol:g}; errors on a {ERROR_RATE:g} Hz subsample vs rtol {REF_RTOL:g} / "
        f"atol x {REF_ATOL_SCALE:g}; median of {repeat} run(s)"
    )
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        for n in ns:
            rows.append(bench_case(n, repeat, log, args.rtol, args.radau_rtol, args.profile))
    print()
    print(format_table(rows))
    print(
        "RTF = simulated s / wall s. maxTerr: max |T - T_ref| over all spans and the "
        f"{ERROR_RATE:g} Hz subsample; endTerr: at t = {DURATION:g} s. ratio = scipy Radau "
        "wall / this wall, all at the same rtol (states at every sample). Equal accuracy: "
        "the loosest rung of the backend's tolerance ladder at least as accurate as scipy "
        "Radau. r2rsim cvode with every algebraic output at every sample (what `r2rsim run` "
        "writes): RTF " + ", ".join(f"{r['out_rtf']:.1f} (N={r['N']})" for r in rows) + "."
    )
    # --strict: the RTF target (CVODE) and >= 2x scipy Radau at equal accuracy
    # with at least one r2rsim backend
    all_ok = all(
        not v[0].startswith("FAIL") and not (v[1].startswith("FAIL") and v[2].startswith("FAIL"))
        for v in map(verdicts, rows)
    )
    return 0 if all_ok or not args.strict else 1


if __name__ == "__main__":
    sys.exit(main())
