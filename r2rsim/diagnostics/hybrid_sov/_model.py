"""The hybrid multistage model (thesis eqs. 2.14-2.24) and the data-driven comparator
(Table 2-3 rows), fitted on lists of preprocessed runs (:class:`~._features.Signals`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from . import _features as F
from ._line import LineStages
from ._regression import LinearFit, StepwiseResult, forward_stepwise

#: stage-3 candidates offered to stepwise selection (the union of thesis §2.5.2, eq. 2.17
#: and eq. 2.23; the cylinder force is constant and unmeasured)
STAGE3_CANDIDATES = ("idlers3", "alpha", "dalpha", "w_d", "dw_d", "w1", "dw1")
#: stage-1/2 physics regressors beyond the forced torque balance
STAGE12_CANDIDATES = ("b1*w1/R", "idlers2", "rho*w*t*R^2*w1^2", "R", "R^2")


class _Design:
    """Named columns standardised with the training mean and scale (``const`` kept), so
    that regressors of very different magnitude fit well conditioned."""

    def __init__(self, columns: dict[str, np.ndarray]):
        self.center = {k: float(np.mean(v)) for k, v in columns.items()}
        self.scale = {k: float(np.std(v)) or 1.0 for k, v in columns.items()}

    def __call__(self, columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = {k: (columns[k] - self.center[k]) / self.scale[k] for k in self.center}
        out["const"] = np.ones(len(next(iter(columns.values()))))
        return out

    @staticmethod
    def matrix(cols: dict, names: list[str]) -> np.ndarray:
        return np.column_stack([cols[n] for n in names])


def _stack(dicts: list[dict]) -> dict[str, np.ndarray]:
    return {k: np.concatenate([d[k] for d in dicts]) for k in dicts[0]}


def _select_rows(sigs: list[F.Signals], period_s: float) -> np.ndarray:
    """Every ``period_s`` seconds of every run, valid rows only (for the selection tests).

    The rows start at each run's ``delay_s``: with the causal preprocessing, row k describes
    the line at t_k - delay_s, so the tests read the same instants of the line as offline
    (a shifted grid of rows gave another selection on the same data)."""
    rows, start = [], 0
    for s in sigs:
        dt = float(np.median(np.diff(s.t)))
        step = max(1, int(round(period_s / dt)))
        idx = np.arange(int(round(s.delay_s / dt)), len(s.t), step)
        rows.append(start + idx[s.valid[idx]])
        start += len(s.t)
    return np.concatenate(rows)


def _gauss_llf(resid: np.ndarray) -> float:
    n = len(resid)
    return float(-0.5 * n * (np.log(2 * np.pi * np.mean(resid**2)) + 1.0))


@dataclass
class Stage3Fit:
    """The dancer stage and the pitch observation: stage-3 stepwise fit, L0(R) fit, the
    number of alternating iterations, the method ("alternating" or "oracle"), and the
    L0(R) used to predict (``const``, ``R^3``; q0 averaged over the training rolls)."""

    stage3: StepwiseResult
    l0: StepwiseResult
    iterations: int
    method: str
    l0_predict: LinearFit


class HybridModel:
    """Hybrid multistage stream-of-variation tension model (thesis §2.5) and virtual sensor.

    Stages 1-2: the unwind torque balance and the splice idlers with free coefficients on the
    physics regressors (eq. 2.10), fitted to the stage-2 load cell by Tobit (censored at
    ``censor_at``) or OLS with forward stepwise selection. Stage 3 (dancer): T_s3 = d0 +
    d1·T_s2 + selected terms (eq. 2.23), fitted either by the alternating scheme of
    :meth:`_alternate` against the pitch observation or (``oracle``) against true
    tensions. Stage 4: T_s4 = T_s3 + (J·ω̇ + b·ω - τ)/R (eq. 2.18). Observation: Y = (T_s4/EA
    + 1)·L0(R), L0 = q0 + q1·R³ (eqs. 2.20, 2.24). Stage 5: T_s5 = T_s4 + idler terms.

    Parameters
    ----------
    stages : LineStages
    kind : {"tobit", "ols"}
    alpha_enter : float
        Entry level of the stepwise tests.
    censor_at : float
        Left-censoring point of the Tobit stages [N].
    select_period_s : float
        Spacing of the rows the selection tests use [s] (autocorrelated samples would
        make every candidate significant); the final fits use all rows.
    max_iter : int
        Alternating iterations of the stage-3 / L0 fit.
    roll_offsets : bool
        Fit L0 with one intercept per material roll of the training data (roll changes
        found from the radius): rolls differ in relaxed pitch. Predictions use the mean.
    """

    def __init__(
        self,
        stages: LineStages,
        kind: str = "tobit",
        alpha_enter: float = 0.05,
        censor_at: float = 0.0,
        select_period_s: float = 0.5,
        max_iter: int = 20,
        roll_offsets: bool = True,
    ):
        self.stages = stages
        self.kind = kind
        self.alpha_enter = alpha_enter
        self.censor_at = censor_at
        self.select_period_s = select_period_s
        self.max_iter = max_iter
        self.roll_offsets = roll_offsets

    # ---- regressors -----------------------------------------------------------------------
    def _cols12(self, s: F.Signals) -> dict[str, np.ndarray]:
        cols = F.stage1_terms(self.stages, s)
        cols["idlers2"] = F.idler_sum(self.stages, 2, s)
        return cols

    def _cols3(self, s: F.Signals) -> dict[str, np.ndarray]:
        r_d = next(r.radius for r in self.stages.idlers[3] if r.id == self.stages.dancer)
        return {
            "T2": s.T2s,
            "idlers3": F.idler_sum(self.stages, 3, s),
            "alpha": s.alpha,
            "dalpha": s.dalpha,
            "w_d": s.v / r_d,
            "dw_d": s.dv / r_d,
            "w1": s.w1,
            "dw1": s.dw1,
        }

    # ---- fitting ------------------------------------------------------------------------
    def fit(self, sigs: list[F.Signals], truth: list[dict] | None = None) -> HybridModel:
        """Fit on preprocessed healthy runs.

        Parameters
        ----------
        sigs : list of Signals
        truth : list of dict, optional
            Per run, true ``T3`` and ``T4`` tensions [N] (``state.*``; r2rsim only): fit
            stage 3 and L0 against them (the oracle variant) instead of the alternating
            scheme.
        """
        self.fit_tension(sigs)
        rows = _select_rows(sigs, self.select_period_s)
        valid = np.concatenate([s.valid for s in sigs])
        c3 = _stack([self._cols3(s) for s in sigs])
        self.design3_ = _Design(c3)
        x4 = np.concatenate([F.driven_term(self.stages, s) for s in sigs])
        R3 = np.concatenate([s.R**3 for s in sigs])
        Y = np.concatenate([s.Y for s in sigs])
        roll = None
        if self.roll_offsets:
            roll = np.concatenate([F.roll_index(s.R) + 1000 * i for i, s in enumerate(sigs)])
        if truth is None:
            self.stage3_ = self._alternate(self.design3_(c3), x4, R3, Y, rows, valid, roll)
        else:
            T3 = np.concatenate([np.asarray(t["T3"], float) for t in truth])
            T4 = np.concatenate([np.asarray(t["T4"], float) for t in truth])
            st3 = self._stepwise(
                self.design3_(c3), T3, ["const", "T2"], list(STAGE3_CANDIDATES), rows, valid
            )
            l0, _, l0_pred = self._fit_l0(
                Y / (1.0 + T4 / self.stages.web_EA), R3, rows, valid, roll
            )
            self.stage3_ = Stage3Fit(st3, l0, 0, "oracle", l0_pred)
        return self

    def fit_tension(self, sigs: list[F.Signals]) -> HybridModel:
        """Fit stages 1-2 only, to the stage-2 load cell (sets ``stage12_``)."""
        rows = _select_rows(sigs, self.select_period_s)
        valid = np.concatenate([s.valid for s in sigs])
        c12 = _stack([self._cols12(s) for s in sigs])
        self.design12_ = _Design(c12)
        y2 = np.concatenate([s.T2 for s in sigs])
        self.stage12_ = self._stepwise(
            self.design12_(c12),
            y2,
            ["const", "tau1/R", "J1*dw1/R"],
            list(STAGE12_CANDIDATES),
            rows,
            valid,
        )
        return self

    def predict_tension(self, s: F.Signals) -> np.ndarray:
        """T̂_s2 from stages 1-2 [N]."""
        f12 = self.stage12_.fit
        return f12.predict(_Design.matrix(self.design12_(self._cols12(s)), f12.names))

    def _stepwise(self, cols, y, forced, candidates, rows, valid, kind=None):
        kind = kind or self.kind
        cols = {k: v[valid] for k, v in cols.items()}
        sel = np.flatnonzero(np.isin(np.flatnonzero(valid), rows))
        return forward_stepwise(
            cols,
            y[valid],
            forced,
            candidates,
            kind,
            self.alpha_enter,
            self.censor_at,
            select_rows=sel,
        )

    def _fit_l0(self, l0_obs, R3, rows, valid, roll=None):
        """Eq. 2.24 with forward selection of the R³ term (OLS, F-test). With ``roll`` (a
        material-roll number per sample) every roll has its own intercept q0: rolls differ
        in relaxed pitch, and the stage-3 target backed out of the pitch would otherwise
        carry those offsets. Returns the selection result, L0 per training sample and the
        prediction fit (q0 = the sample-weighted mean over rolls)."""
        if roll is None or len(np.unique(roll[valid])) < 2:
            res = self._stepwise(
                {"const": np.ones_like(R3), "R^3": R3},
                l0_obs,
                ["const"],
                ["R^3"],
                rows,
                valid,
                kind="ols",
            )
            X = _Design.matrix({"const": np.ones_like(R3), "R^3": R3}, res.fit.names)
            return res, res.fit.predict(X), res.fit
        ids = np.unique(roll[valid])
        cols = {f"roll{k}": (roll == k).astype(float) for k in ids}
        cols["R^3"] = R3
        res = self._stepwise(cols, l0_obs, list(cols)[:-1], ["R^3"], rows, valid, kind="ols")
        l0_hat = res.fit.predict(_Design.matrix(cols, res.fit.names))
        b = res.fit.coef()
        share = np.array([np.sum((roll == k) & valid) for k in ids], float)
        q0 = float(np.dot([b[f"roll{k}"] for k in ids], share / share.sum()))
        names = ["const"] + (["R^3"] if "R^3" in b else [])
        beta = np.array([q0] + ([b["R^3"]] if "R^3" in b else []))
        pred = LinearFit(
            names, beta, np.full(len(beta), np.nan), res.fit.sigma, res.fit.llf, res.fit.n, "ols"
        )
        return res, l0_hat, pred

    def _alternate(self, cols3, x4, R3, Y, rows, valid, roll) -> Stage3Fit:
        """The alternating scheme: start from the physics chain (the dancer stage passes
        the tension on: T_s3 = T_s2 + idler terms), fit L0(R) from the pitch by inverting
        Hooke, back out T_s3 through eq. 2.18, refit stage 3, and iterate. The pitch cannot
        separate an offset of L0 from one of the tension (1 um of L0 reads as EA·1e-6/L0 =
        1.1 N here): the physics start fixes that level."""
        EA = self.stages.web_EA
        T3_hat = self._unscaled(cols3, "T2", self.design3_) + self._unscaled(
            cols3, "idlers3", self.design3_
        )
        l0_prev, iterations = None, 0
        while iterations < self.max_iter:
            iterations += 1
            l0, l0_hat, l0_pred = self._fit_l0(
                Y / (1.0 + (T3_hat + x4) / EA), R3, rows, valid, roll
            )
            T3_obs = (Y / l0_hat - 1.0) * EA - x4
            st3 = self._stepwise(
                cols3, T3_obs, ["const", "T2"], list(STAGE3_CANDIDATES), rows, valid
            )
            T3_hat = st3.fit.predict(_Design.matrix(cols3, st3.fit.names))
            if l0_prev is not None and np.max(np.abs(l0_hat - l0_prev)) < 1e-9:
                break
            l0_prev = l0_hat
        return Stage3Fit(st3, l0, iterations, "alternating", l0_pred)

    @staticmethod
    def _unscaled(cols, name, design):
        return cols[name] * design.scale[name] + design.center[name]

    # ---- prediction ---------------------------------------------------------------------
    def predict(self, s: F.Signals) -> pd.DataFrame:
        """Virtual-sensor tensions ``T_s1..T_s5`` [N] and predicted pitch ``Y_s4`` [m]."""
        T2 = self.predict_tension(s)
        T1 = T2 - F.idler_sum(self.stages, 2, s)  # back through the idlers (eq. 2.16)
        c3 = self.design3_(self._cols3(s))
        f3 = self.stage3_.stage3.fit
        T3 = f3.predict(_Design.matrix(c3, f3.names))
        T4 = T3 + F.driven_term(self.stages, s)
        T5 = T4 + F.idler_sum(self.stages, 5, s)
        R3 = s.R**3
        fl = self.stage3_.l0_predict
        L0 = fl.predict(_Design.matrix({"const": np.ones_like(R3), "R^3": R3}, fl.names))
        Y = (T4 / self.stages.web_EA + 1.0) * L0
        return pd.DataFrame(
            {"T_s1": T1, "T_s2": T2, "T_s3": T3, "T_s4": T4, "T_s5": T5, "Y_s4": Y, "L0_s4": L0}
        )

    def pitch_aic(self, sigs: list[F.Signals]) -> float:
        """AIC of the pitch prediction on these runs (Gaussian residuals; parameters of
        stage 3, L0 and sigma)."""
        resid = np.concatenate([(s.Y - self.predict(s)["Y_s4"].to_numpy())[s.valid] for s in sigs])
        k = len(self.stage3_.stage3.fit.beta) + len(self.stage3_.l0_predict.beta) + 1
        return 2.0 * k - 2.0 * _gauss_llf(resid)


class DataDrivenModel:
    """The comparator of Table 2-3: the stage-2 tension and the pitch regressed directly on
    the raw channels, their squares and pairwise products (no physics), by ``kind`` with
    forward stepwise selection. The pitch model is OLS (the pitch is never censored)."""

    def __init__(
        self,
        kind: str = "tobit",
        alpha_enter: float = 0.05,
        censor_at: float = 0.0,
        select_period_s: float = 0.5,
    ):
        self.kind = kind
        self.alpha_enter = alpha_enter
        self.censor_at = censor_at
        self.select_period_s = select_period_s

    def fit(self, sigs: list[F.Signals]) -> DataDrivenModel:
        """Fit on preprocessed healthy runs."""
        rows = _select_rows(sigs, self.select_period_s)
        valid = np.concatenate([s.valid for s in sigs])
        sel = np.flatnonzero(np.isin(np.flatnonzero(valid), rows))
        ct = _stack([F.second_order(F.raw_candidates(s, False)) for s in sigs])
        cp = _stack([F.second_order(F.raw_candidates(s, True)) for s in sigs])
        self.design_t_, self.design_p_ = _Design(ct), _Design(cp)
        y2 = np.concatenate([s.T2 for s in sigs])[valid]
        Y = np.concatenate([s.Y for s in sigs])[valid]
        zt = {k: v[valid] for k, v in self.design_t_(ct).items()}
        zp = {k: v[valid] for k, v in self.design_p_(cp).items()}
        self.tension_ = forward_stepwise(
            zt,
            y2,
            ["const"],
            [k for k in zt if k != "const"],
            self.kind,
            self.alpha_enter,
            self.censor_at,
            sel,
        )
        self.pitch_ = forward_stepwise(
            zp,
            Y,
            ["const"],
            [k for k in zp if k != "const"],
            "ols",
            self.alpha_enter,
            select_rows=sel,
        )
        return self

    def predict(self, s: F.Signals) -> pd.DataFrame:
        """Predicted stage-2 tension ``T_s2`` [N] and pitch ``Y_s4`` [m]."""
        zt = self.design_t_(F.second_order(F.raw_candidates(s, False)))
        zp = self.design_p_(F.second_order(F.raw_candidates(s, True)))
        ft, fp = self.tension_.fit, self.pitch_.fit
        return pd.DataFrame(
            {
                "T_s2": ft.predict(_Design.matrix(zt, ft.names)),
                "Y_s4": fp.predict(_Design.matrix(zp, fp.names)),
            }
        )

    def pitch_aic(self, sigs: list[F.Signals]) -> float:
        """AIC of the pitch prediction on these runs (as :meth:`HybridModel.pitch_aic`)."""
        resid = np.concatenate([(s.Y - self.predict(s)["Y_s4"].to_numpy())[s.valid] for s in sigs])
        return 2.0 * (len(self.pitch_.fit.beta) + 1) - 2.0 * _gauss_llf(resid)
