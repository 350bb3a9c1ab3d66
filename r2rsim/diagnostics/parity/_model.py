"""Nonlinear model description, Lie derivatives and the observation matrix (thesis §3.3,
eqs. 3.1-3.13), computed exactly with SymPy at design time and evaluated with NumPy."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import sympy as sp
from scipy.linalg import null_space

from ...errors import InputError


class NonlinearModel:
    """ẋ = f(x, u), y = h(x, u) with its stacked Lie derivatives (eqs. 3.3-3.5).

    Parameters
    ----------
    f : callable
        ``f(x, u)`` returning the N state derivatives; called once with SymPy symbols, so it
        must be written with arithmetic and SymPy functions (``sympy.exp``...).
    h : callable
        ``h(x, u)`` returning one expression per sensor.
    n_states, n_inputs : int
    orders : sequence of int, optional
        m_j, the highest Lie derivative of sensor j in the stack (default: N for every
        sensor, the largest rank ∇_x of one sensor's stack can reach).
    sensor_names : sequence of str, optional

    Notes
    -----
    The stack is sensor by sensor, Y = [y_1, ẏ_1, ..., y_1^(m_1), y_2, ...] (eq. 3.25a, the
    order of thesis Table 3-2). L_f h = (∂h/∂x) f + (∂h/∂u) u̇ needs the input derivatives:
    they are the symbols ``du`` (and ``d2u``... for higher orders). The split O = O_NL + E·U
    of eq. 3.7 takes O_NL as O with every input derivative set to zero.
    """

    def __init__(
        self,
        f: Callable,
        h: Callable,
        n_states: int,
        n_inputs: int,
        orders: Sequence[int] | None = None,
        sensor_names: Sequence[str] | None = None,
    ):
        self.n_states, self.n_inputs = int(n_states), int(n_inputs)
        self.x = sp.symbols(f"x0:{self.n_states}", real=True)
        self.u = sp.symbols(f"u0:{self.n_inputs}", real=True)
        f_expr = [sp.sympify(e) for e in _as_list(f(self.x, self.u))]
        h_expr = [sp.sympify(e) for e in _as_list(h(self.x, self.u))]
        if len(f_expr) != self.n_states:
            raise InputError(f"f returns {len(f_expr)} expressions for {self.n_states} states")
        self.f_expr, self.h_expr = f_expr, h_expr
        n_sensors = len(h_expr)
        self.orders = tuple(
            int(m) for m in (orders if orders is not None else [self.n_states] * n_sensors)
        )
        if len(self.orders) != n_sensors or min(self.orders) < 0:
            raise InputError(f"orders must give one m_j >= 0 per sensor ({n_sensors})")
        self.sensor_names = tuple(sensor_names or [f"y{j}" for j in range(n_sensors)])
        m = max(self.orders)
        # input derivatives u^(1..m): the jet L_f needs
        self.du = [sp.symbols(f"d{k}u0:{self.n_inputs}", real=True) for k in range(1, m + 1)]
        self.stack = self._lie_stack()
        self.rows = [(j, k) for j, mj in enumerate(self.orders) for k in range(mj + 1)]
        self._compile()

    # ---- symbolic --------------------------------------------------------------------------
    def lie(self, expr):
        """d/dt of ``expr`` along ẋ = f: (∂/∂x) f + Σ (∂/∂u^(k)) u^(k+1)."""
        out = sum(
            (sp.diff(expr, xi) * fi for xi, fi in zip(self.x, self.f_expr, strict=False)),
            sp.Integer(0),
        )
        jets = [self.u, *self.du]
        for k in range(len(jets) - 1):
            out += sum(
                (sp.diff(expr, a) * b for a, b in zip(jets[k], jets[k + 1], strict=False)),
                sp.Integer(0),
            )
        return out

    def _lie_stack(self):
        stack = []
        for hj, mj in zip(self.h_expr, self.orders, strict=False):
            e = hj
            for _ in range(mj + 1):
                stack.append(e)
                e = self.lie(e)
        return sp.Matrix(stack)

    def _compile(self):
        zero = {s: 0 for jet in self.du for s in jet}
        self.O_expr = self.stack
        self.O_nl_expr = self.stack.subs(zero)
        self.EU_expr = sp.simplify(self.O_expr - self.O_nl_expr)
        self.E_expr = (
            self.O_expr.jacobian(self.du[0]).subs(zero)
            if self.du
            else sp.zeros(len(self.stack), self.n_inputs)
        )
        self.grad_x_expr = self.O_nl_expr.jacobian(self.x)
        p = [*self.x, *self.u]
        # ∂(∇_x O_NL)/∂p, one n x N matrix per p_k (KKT sensitivity, eqs. 3.18-3.22)
        self.grad_xp_expr = [self.grad_x_expr.diff(pk) for pk in p]
        args = (self.x, self.u, *self.du)
        self._O = sp.lambdify(args, list(self.O_expr), "numpy")
        self._O_nl = sp.lambdify((self.x, self.u), list(self.O_nl_expr), "numpy")
        self._E = sp.lambdify((self.x, self.u), self.E_expr, "numpy")
        self._EU = sp.lambdify(args, list(self.EU_expr), "numpy")
        self._gx = sp.lambdify((self.x, self.u), self.grad_x_expr, "numpy")
        self._gxp = [sp.lambdify((self.x, self.u), g, "numpy") for g in self.grad_xp_expr]

    # ---- numeric ---------------------------------------------------------------------------
    @property
    def n_outputs(self) -> int:
        """n = Σ (m_j + 1), the length of the stack."""
        return len(self.rows)

    def observation(self, x, u, du=None) -> np.ndarray:
        """O(x, u, u̇) (n,) at one point, or (n, T) for arrays of T samples."""
        du = list(du) if du is not None else [np.zeros(self.n_inputs)] * len(self.du)
        return _stack(self._O(_cols(x), _cols(u), *[_cols(d) for d in du]))

    def observation_nl(self, x, u) -> np.ndarray:
        """O_NL(x, u): the observation with the input derivatives set to zero (eq. 3.7)."""
        return _stack(self._O_nl(_cols(x), _cols(u)))

    def input_part(self, x, u, du=None) -> np.ndarray:
        """E·U = O − O_NL (n,) or (n, T): the part of the stack carried by the input
        derivatives (eqs. 3.7, 3.13)."""
        du = list(du) if du is not None else [np.zeros(self.n_inputs)] * len(self.du)
        x, u = _cols(x), _cols(u)
        T = np.broadcast_shapes(*(np.shape(a) for a in (*x, *u)))
        return np.stack(
            [
                np.broadcast_to(np.asarray(v, float), T)
                for v in self._EU(x, u, *[_cols(d) for d in du])
            ]
        )

    def input_matrix(self, x, u) -> np.ndarray:
        """E(x, u) = ∂O/∂u̇ (n x n_inputs) at one point (eq. 3.13); E·u̇ is the input part
        for m_j <= 1."""
        return np.asarray(self._E(_cols(x), _cols(u)), dtype=float)

    def grad_x(self, x, u) -> np.ndarray:
        """∇_x O_NL(x, u) (n x N) at one point."""
        return np.asarray(self._gx(_cols(x), _cols(u)), dtype=float)

    def grad_xp(self, x, u) -> np.ndarray:
        """∂(∇_x O_NL)/∂p with p = [x, u]: (N + n_inputs, n, N) at one point."""
        return np.stack([np.asarray(g(_cols(x), _cols(u)), dtype=float) for g in self._gxp])

    def n_relations(self, x, u, tol: float = 1e-10) -> int:
        """n − N of eq. 3.11 (N = rank ∇_x O at the point; the thesis prints n − M)."""
        return self.n_outputs - int(np.linalg.matrix_rank(self.grad_x(x, u), tol=tol))

    def parity_space(self, x, u) -> np.ndarray:
        """An orthonormal basis of Ω^⊥ (rows), the left null space of ∇_x O_NL (eq. 3.8)."""
        return null_space(self.grad_x(x, u).T).T

    def sensor_relations(self, x, u, scale=None) -> list[np.ndarray]:
        """The relations that use one sensor only, from the left null space of that sensor's
        block of ∇_x O_NL, embedded with zeros elsewhere (the zero pattern of thesis
        Table 3-2). With ``scale`` (n,) the relations act on Y/scale."""
        G = self.grad_x(x, u)
        if scale is not None:
            G = G / np.asarray(scale, float)[:, None]
        out = []
        for j in range(len(self.orders)):
            idx = [i for i, (jj, _) in enumerate(self.rows) if jj == j]
            for v in null_space(G[idx].T).T:
                w = np.zeros(self.n_outputs)
                w[idx] = v * np.sign(v[np.argmax(np.abs(v))])  # sign: largest entry > 0
                out.append(w)
        return out

    def sensor_of_row(self) -> np.ndarray:
        """The sensor index of each row of the stack."""
        return np.array([j for j, _ in self.rows])


def _as_list(v):
    if isinstance(v, sp.MatrixBase):
        return list(v)
    return list(v) if isinstance(v, (list, tuple)) else [v]


def _cols(a):
    """A point (k,) or samples (k, T) as a tuple of k scalars or arrays."""
    a = np.asarray(a, dtype=float)
    return tuple(a) if a.ndim else (a,)


def _stack(values) -> np.ndarray:
    """Lambdified rows (scalars or arrays, constants broadcast) as one array."""
    arrs = [np.asarray(v, dtype=float) for v in values]
    shape = np.broadcast_shapes(*(a.shape for a in arrs))
    return np.stack([np.broadcast_to(a, shape) for a in arrs])


def registration_model(
    EA: float, span_length: float, relaxed_pitch: float, drive_radius: float, out_radius: float
) -> NonlinearModel:
    """The reduced registration-span model of thesis §3.5 (eq. 3.24) on r2rsim's span law.

    x = T, the registration-span tension [N]; u = [ω_d, ω_o, T_up]: the driven roller's
    and the downstream idler's angular speeds [rad/s] (encoders) and the tension entering the
    driven roller [N] (the upstream load cell). Mass conservation of the span with the web
    upwinded (docs/model.md) gives, with ε = T/EA,

        ẋ = (EA + x)/L · (R_o ω_o − R_d ω_d (EA + x)/(EA + T_up)).

    Sensors: y_A = x (load cell A), y_B = (x/EA + 1)·L0 (pitch length, Hooke's law with the
    relaxed pitch L0). Orders m_A = m_B = 1, so n = 4 and there are n − N = 3 relations.
    """

    def f(x, u):
        v1, v2 = drive_radius * u[0], out_radius * u[1]
        return [(EA + x[0]) / span_length * (v2 - v1 * (EA + x[0]) / (EA + u[2]))]

    def h(x, u):
        return [x[0], (x[0] / EA + 1) * relaxed_pitch]

    return NonlinearModel(f, h, 1, 3, orders=(1, 1), sensor_names=("A", "B"))
