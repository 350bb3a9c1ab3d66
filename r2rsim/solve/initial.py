"""Initial states: nominal (everything at line speed and a given tension) or steady."""

from __future__ import annotations

import math
import warnings

import numpy as np

from ..compile.compiler import CompiledLine
from ..errors import InputError
from ..schema.kinds import kind_of


def nominal_state(
    cl: CompiledLine,
    tension: float | None = None,
    span_tension: dict[str, float] | None = None,
    slack: dict[str, float] | None = None,
    position: dict[str, float] | None = None,
    file: str | None = None,
) -> np.ndarray:
    """All nodes at the t = 0 line speed (times their draw), every span at ``tension``.

    Drive torques and speed-loop integrators are set so that every roller is in torque
    balance; tension-loop integrators so that their torque matches.

    Parameters
    ----------
    cl : CompiledLine
    tension : float, optional
        Tension of every span [N]; default the first tension set-point, else 0.
    span_tension : dict, optional
        Tension [N] by span id, overriding ``tension``.
    slack : dict, optional
        Web [m] a span holds beyond its taut length, by span id: its strain starts at
        ``-slack/L`` (0 N). At most half the span's length at the t = 0 positions.
    position : dict, optional
        Position [rad or m, SI] of a dancer or festoon carriage at t = 0, by id.
    file : str, optional
        The scenario file, named in the message of a slack that does not fit.

    Raises
    ------
    InputError
        When a slack is not below half its span's length.
    """
    line = cl.line
    y = np.zeros(cl.n_states)
    tension_sps = [c.setpoint for c in line.controllers if c.type == "tension_pi"]
    T0 = tension if tension is not None else (tension_sps[0] if tension_sps else 0.0)
    T = [T0 for _ in line.spans]
    for i, sp in enumerate(line.spans):
        if span_tension and sp.id in span_tension:
            T[i] = span_tension[sp.id]
        y[cl.index(f"{sp.id}.strain")] = T[i] / line.web.EA
    needed_torque = _speeds_in_balance(cl, y, T)
    _integrators(cl, y, needed_torque)
    # dancers and festoon carriages at their initial positions, at rest
    for mid, q0 in zip(cl.mover_ids, cl.mover_q0, strict=True):
        y[cl.index(f"{mid}.position")] = (position or {}).get(mid, q0)
    if slack:
        _slack(cl, y, slack, file)
    _filters_at_input(cl, y)
    return y


def _speeds_in_balance(cl: CompiledLine, y: np.ndarray, T: list) -> dict[str, float]:
    """Every roller at the t = 0 line speed times its draw, its drive torque (when it has
    a lag) in balance with the span tensions ``T``; returns the torque each needs."""
    line = cl.line
    V0 = cl.programme.value("line_speed", 0.0)
    draw = {c.element: c.draw for c in line.controllers if c.type == "speed_pi"}
    needed_torque = {}
    for k, e in enumerate(line.elements):
        drive = getattr(e, "drive", None)
        if drive is not None and drive.type == "ideal_speed":
            continue
        R = kind_of(e).surface_radius(e)
        om = V0 * (1.0 + draw.get(e.id, 0.0)) / R
        y[cl.index(f"{e.id}.speed")] = om
        Tup = T[k - 1] if k > 0 else 0.0
        Tdn = T[k] if k < len(line.spans) else 0.0
        f = e.friction
        tf = f.viscous * om + f.coulomb * math.tanh(om / f.smoothing_speed)
        needed_torque[e.id] = -R * (Tdn - Tup) + tf
        if f"{e.id}.drive_torque" in cl.state_names:
            y[cl.index(f"{e.id}.drive_torque")] = needed_torque[e.id]
    return needed_torque


def _integrators(cl: CompiledLine, y: np.ndarray, needed_torque: dict) -> None:
    """Loop integrators such that the PI outputs produce the needed torque at zero error."""
    line = cl.line
    aux = cl.outputs(0.0, y[None, :])[0]
    for c_idx, c in enumerate(line.controllers):
        ix = cl.field("ctrl", c_idx, "X")
        if ix < 0:
            continue
        ki = cl.param("ctrl", c_idx, "KI")
        eid = c.element
        kind = cl.kind("ctrl", c_idx)
        if kind == "SPEED":
            y[ix] = needed_torque.get(eid, 0.0) / ki
        elif kind == "TENSION_TORQUE":
            # torque = cmd_ff + sgn·R·u at u = 0; solve for u
            tau_ff = aux[cl.aux_index(f"{eid}.torque_command_N_m")]
            R = aux[cl.aux_index(f"{eid}.radius_m")]
            sgn = -1.0 if kind_of(line.element(eid)).pays_out else 1.0
            u = (needed_torque.get(eid, 0.0) - tau_ff) / (sgn * R)
            y[ix] = u / ki


def _slack(cl: CompiledLine, y: np.ndarray, slack: dict, file: str | None) -> None:
    """Spans that hold web beyond their taut length start at strain -slack/L (0 N)."""
    aux = cl.outputs(0.0, y[None, :])[0]
    for sid, extra in slack.items():
        length = aux[cl.aux_index(f"{sid}.length_m")]
        if not extra < 0.5 * length:
            raise InputError(
                f"{extra:g} m of slack is not below half the span's length ({length:g} m at t = 0)",
                file=file,
                path=f"initial.slack.{sid}",
            )
        y[cl.index(f"{sid}.strain")] = -extra / length


def _filters_at_input(cl: CompiledLine, y: np.ndarray) -> None:
    """Sensor filters start at their input. Two passes, as the first version had: the
    second changes nothing unless a reading depends on a filter's state."""
    for _ in range(2):
        aux = cl.outputs(0.0, y[None, :])[0]
        for s in cl.sensors:
            name = f"{s.id}.filtered"
            if name in cl.state_names:
                q = {
                    "load_cell": "tension_N",
                    "encoder": "speed_rad_s",
                    "roll_diameter": "diameter_m",
                    "pitch_length": "pitch_m",
                }.get(s.type)
                q = q or next(
                    n.split(".", 1)[1] for n in cl.aux_names if n.startswith(f"{s.id}.position_")
                )
                y[cl.index(name)] = s.gain * aux[cl.aux_index(f"{s.id}.{q}")] + s.offset


def steady_state(
    cl: CompiledLine, y_guess: np.ndarray, tol: float = 1e-10, max_iter: int = 60
) -> np.ndarray | None:
    """The steady state at the t = 0 set-points near ``y_guess``.

    Newton's method with a backtracking line search on dy/dt = 0 for every state except
    the roll lengths and roller angles. If it fails from the guess and the guess has spans
    at or below zero strain (a nominal state at 0 N: a span's stiffness has its kink there,
    so the Newton matrix is singular), it starts again from the guess made taut at the
    line's tension set-points (:func:`taut_guess`).

    Returns
    -------
    ndarray or None
        None when no steady state is found (for example a line at rest, where span strains
        are not determined by the speeds).
    """
    y = _newton(cl, y_guess, tol, max_iter)
    if y is None:
        taut = taut_guess(cl, y_guess)
        if taut is not None:
            y = _newton(cl, taut, tol, max_iter)
    return y


def taut_guess(cl: CompiledLine, y: np.ndarray) -> np.ndarray | None:
    """``y`` with every span at or below zero strain set to a taut strain, or None if none
    is. The strain is that of the median of the tension set-points at t = 0 and the
    tensions dancers and festoons hold at rest, else 1e-4."""
    spans = [cl.index(f"{sp}.strain") for sp in cl.span_ids]
    if all(y[i] > 0.0 for i in spans):
        return None
    line = cl.line
    refs = [cl.programme.value(c.id, 0.0) for c in line.controllers if c.type == "tension_pi"]
    refs += _mover_tensions(cl)
    refs = [r for r in refs if r > 0.0]
    eps = float(np.median(refs)) / line.web.EA if refs else 1e-4
    out = y.copy()
    for i in spans:
        if out[i] <= 0.0:
            out[i] = eps
    return out


def _mover_tensions(cl: CompiledLine) -> list[float]:
    """Rough web tensions [N] that dancers and festoons hold at rest (a guess for Newton,
    not a result): each element's kind's guess (``ElementKind.rest_tension``: the load
    shared by the strands of a translating dancer; for a pivot dancer, the tension of both
    spans whose moment about the pivot balances the arm's load at its initial arm angle),
    then the load shared by the strands of each festoon."""
    line = cl.line
    out = []
    for e in line.elements:
        tension = kind_of(e).rest_tension(e, cl)
        if tension is not None:
            out.append(tension)
    for sp in line.spans:
        f = getattr(sp, "festoon", None)
        if f is not None:
            out.append(abs(f.force) / (2 * f.moving_rollers))
    return out


#: a Newton matrix whose 1-norm condition number exceeds this is taken as singular
MAX_CONDITION = 1e14


def _newton(cl: CompiledLine, y_guess: np.ndarray, tol: float, max_iter: int):
    free = np.array([k not in ("roll_length", "material", "angle") for k in cl.state_kinds])
    scale = np.abs(y_guess) + 1e3 * cl.atol
    y = y_guess.copy()
    cl.set_segment_start(0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for _ in range(max_iter):
            f = cl.rhs(0.0, y)[free]
            if not np.all(np.isfinite(f)):
                return None
            Jf = cl.jacobian(0.0, y)[np.ix_(free, free)]
            lu = lu_factor(Jf)
            if lu is None:
                return None
            dx = lu_solve(lu, -f)
            if not np.all(np.isfinite(dx)):
                return None
            lam = 1.0
            f0 = norm2(f)
            for _ls in range(20):
                y_try = y.copy()
                y_try[free] += lam * dx
                if norm2(cl.rhs(0.0, y_try)[free]) <= (1 - 1e-4 * lam) * f0 or f0 == 0:
                    break
                lam *= 0.5
            y = y_try
            if np.max(np.abs(lam * dx) / scale[free]) < tol:
                if condition_1(Jf, lu) > MAX_CONDITION:
                    return None
                return y
    return None


# ---- dense linear algebra without LAPACK/BLAS ----------------------------------------------
# The steady state is the initial state of a run, so every sample depends on it. LAPACK and
# BLAS (np.linalg.solve, np.linalg.norm's dot product) pick CPU-specific kernels that round
# differently, so the data would differ between machines. These use element-wise numpy
# operations only (each a correctly rounded IEEE operation, in a fixed order) and math.fsum
# (exactly rounded sums): the same bytes on every machine. n is the number of states
# (tens to a few hundred), and this runs a few times per run.


def norm2(x: np.ndarray) -> float:
    """Euclidean norm, with an exactly rounded sum of squares."""
    return math.sqrt(math.fsum(np.square(x)))


def lu_factor(a: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """LU factors of a square matrix with partial pivoting (the first largest pivot of each
    column): ``(lu, perm)`` with L below the diagonal (unit diagonal) and U on and above it,
    rows permuted by ``perm``; None when a pivot is zero or not finite."""
    lu = np.array(a, dtype=float, copy=True)
    n = lu.shape[0]
    perm = np.arange(n)
    for j in range(n):
        p = j + int(np.argmax(np.abs(lu[j:, j])))
        if not (np.isfinite(lu[p, j]) and lu[p, j] != 0.0):
            return None
        if p != j:
            lu[[j, p]] = lu[[p, j]]
            perm[[j, p]] = perm[[p, j]]
        lu[j + 1 :, j] /= lu[j, j]
        lu[j + 1 :, j + 1 :] -= np.multiply.outer(lu[j + 1 :, j], lu[j, j + 1 :])
    return lu, perm


def lu_solve(factors: tuple[np.ndarray, np.ndarray], b: np.ndarray) -> np.ndarray:
    """Solve a x = b (b a vector, or a matrix of right-hand sides as columns) with the
    factors of :func:`lu_factor`, column by column of the factors."""
    lu, perm = factors
    x = np.array(b, dtype=float)[perm]
    n = lu.shape[0]
    for j in range(n):  # L y = P b
        x[j + 1 :] -= (
            np.multiply.outer(lu[j + 1 :, j], x[j]) if x.ndim > 1 else lu[j + 1 :, j] * x[j]
        )
    for j in range(n - 1, -1, -1):  # U x = y
        x[j] /= lu[j, j]
        x[:j] -= np.multiply.outer(lu[:j, j], x[j]) if x.ndim > 1 else lu[:j, j] * x[j]
    return x


def condition_1(a: np.ndarray, factors: tuple[np.ndarray, np.ndarray]) -> float:
    """The 1-norm condition number ||a||_1 ||a^-1||_1, a^-1 from the factors."""
    inv = lu_solve(factors, np.eye(a.shape[0]))

    def norm1(m):
        return max(math.fsum(col) for col in np.abs(m).T)

    return norm1(a) * norm1(inv)
