"""Estimators of the hybrid model (thesis §2.5): OLS, Tobit left-censored regression with
analytic derivatives (thesis eq. 2.10, A.7-A.13), forward stepwise selection with F-tests
(OLS) or likelihood-ratio tests (Tobit), AIC, and a multinomial logistic defect classifier
(thesis eqs. 2.12-2.13)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import special, stats

from ...errors import InputError

_LOG_2PI = np.log(2.0 * np.pi)


@dataclass
class LinearFit:
    """A fitted linear model y = X·beta (+ censoring for Tobit).

    Attributes
    ----------
    names : list of str
        Regressor names, in the column order of ``beta``.
    beta, se : numpy.ndarray
        Coefficients and their standard errors (inverse observed information for Tobit,
        the usual OLS formula otherwise).
    sigma : float
        Residual standard deviation (the latent-noise sigma for Tobit).
    llf : float
        Gaussian (OLS) or Tobit log-likelihood at the estimate.
    n : int
        Number of observations.
    kind : {"ols", "tobit"}
    censor_at : float or None
        Left-censoring point (Tobit only).
    """

    names: list[str]
    beta: np.ndarray
    se: np.ndarray
    sigma: float
    llf: float
    n: int
    kind: str
    censor_at: float | None = None

    @property
    def n_params(self) -> int:
        """Estimated parameters, sigma included."""
        return len(self.beta) + 1

    @property
    def aic(self) -> float:
        """Akaike's information criterion, 2k - 2 log L (k counts sigma)."""
        return 2.0 * self.n_params - 2.0 * self.llf

    def predict(self, X: np.ndarray) -> np.ndarray:
        """The linear predictor X·beta (the latent mean for Tobit)."""
        return np.asarray(X, float) @ self.beta

    def coef(self) -> dict[str, float]:
        """Coefficients by name."""
        return dict(zip(self.names, map(float, self.beta), strict=True))


def _check_xy(X, y):
    X = np.asarray(X, float)
    y = np.asarray(y, float)
    if X.ndim != 2 or y.ndim != 1 or len(X) != len(y):
        raise InputError(f"regression needs X (n, p) and y (n,), got {X.shape} and {y.shape}")
    if len(y) <= X.shape[1] + 1:
        raise InputError(
            f"regression needs more observations ({len(y)}) than parameters ({X.shape[1] + 1})"
        )
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(y))):
        raise InputError("regression data hold NaN or infinite values")
    return X, y


def fit_ols(X, y, names=None) -> LinearFit:
    """Ordinary least squares with the Gaussian log-likelihood at sigma² = RSS/n.

    Parameters
    ----------
    X : array (n, p)
        Regressors (include a column of ones for an intercept).
    y : array (n,)
    names : list of str, optional
    """
    X, y = _check_xy(X, y)
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    resid = y - X @ beta
    n, p = X.shape
    rss = float(resid @ resid)
    s2 = rss / max(n - p, 1)
    cov = s2 * np.linalg.pinv(X.T @ X)
    sigma_ml = np.sqrt(rss / n)
    llf = -0.5 * n * (_LOG_2PI + 2 * np.log(sigma_ml) + 1.0)
    return LinearFit(
        list(names or [f"x{i}" for i in range(p)]),
        beta,
        np.sqrt(np.clip(np.diag(cov), 0, None)),
        float(np.sqrt(s2)),
        float(llf),
        n,
        "ols",
    )


class _Tobit:
    """The Tobit likelihood with parameters theta = (beta, log sigma): value, score and
    Hessian in closed form (thesis A.7-A.13 written for a log-sigma parameter)."""

    def __init__(self, X, y, censor_at):
        self.X, self.y, self.c = X, y, censor_at
        self.cens = y <= censor_at

    def _parts(self, theta):
        beta, s = theta[:-1], theta[-1]
        sigma = np.exp(s)
        mu = self.X @ beta
        e = (self.y - mu) / sigma  # uncensored standardised residual
        z = (self.c - mu) / sigma  # censored standardised limit
        return sigma, e, z

    def loglikeobs(self, theta):
        sigma, e, z = self._parts(theta)
        return np.where(
            self.cens, special.log_ndtr(z), -0.5 * _LOG_2PI - np.log(sigma) - 0.5 * e**2
        )

    def loglike(self, theta):
        return float(np.sum(self.loglikeobs(theta)))

    def _lam(self, z):
        # inverse Mills ratio phi(z)/Phi(z) = sqrt(2/pi)/erfcx(-z/sqrt(2)), stable for all z
        return np.sqrt(2.0 / np.pi) / special.erfcx(-z / np.sqrt(2.0))

    def score(self, theta):
        sigma, e, z = self._parts(theta)
        lam = self._lam(z)
        g_mu = np.where(self.cens, -lam, e) / sigma  # d l_i / d(x_i beta) * ...
        g_s = np.where(self.cens, -lam * z, e**2 - 1.0)
        return np.append(self.X.T @ g_mu, g_s.sum())

    def hessian(self, theta):
        sigma, e, z = self._parts(theta)
        lam = self._lam(z)
        c = self.cens
        w_bb = np.where(c, -lam * (z + lam), -1.0) / sigma**2
        w_bs = np.where(c, lam * (1.0 - z * (z + lam)), -2.0 * e) / sigma
        w_ss = np.where(c, lam * z * (1.0 - z * (z + lam)), -2.0 * e**2)
        X = self.X
        p = X.shape[1]
        H = np.empty((p + 1, p + 1))
        H[:p, :p] = (X * w_bb[:, None]).T @ X
        H[:p, p] = H[p, :p] = X.T @ w_bs
        H[p, p] = w_ss.sum()
        return H


def tobit_loglike(X, y, beta, sigma, censor_at=0.0) -> float:
    """The Tobit log-likelihood of (beta, sigma), left-censored at ``censor_at``."""
    X, y = _check_xy(X, y)
    return _Tobit(X, y, censor_at).loglike(np.append(beta, np.log(sigma)))


def _tobit_model(X, y, censor_at):
    """A statsmodels GenericLikelihoodModel whose likelihood, score and Hessian are the
    closed forms of :class:`_Tobit`."""
    from statsmodels.base.model import GenericLikelihoodModel

    class TobitModel(GenericLikelihoodModel):
        def __init__(self, endog, exog):
            super().__init__(endog, exog, extra_params_names=["log_sigma"])
            self._tobit = _Tobit(self.exog, self.endog, censor_at)

        def loglikeobs(self, params):
            return self._tobit.loglikeobs(params)

        def loglike(self, params):
            return self._tobit.loglike(params)

        def score(self, params):
            return self._tobit.score(params)

        def hessian(self, params):
            return self._tobit.hessian(params)

    return TobitModel(y, X)


def fit_tobit(X, y, censor_at: float = 0.0, names=None, maxiter: int = 100) -> LinearFit:
    """Tobit (type I) maximum likelihood, left-censored at ``censor_at``.

    Observations with ``y <= censor_at`` are censored. statsmodels' Newton-Raphson on a
    ``GenericLikelihoodModel`` with the analytic score and Hessian, from the OLS start;
    standard errors from the inverse observed information.

    Parameters
    ----------
    X : array (n, p)
    y : array (n,)
    censor_at : float
    names : list of str, optional
    maxiter : int

    Raises
    ------
    InputError
        Bad shapes or non-finite data.
    RuntimeError
        When Newton's method does not converge.
    """
    X, y = _check_xy(X, y)
    ols = fit_ols(X, y)
    start = np.append(ols.beta, np.log(max(ols.sigma, 1e-12)))
    model = _tobit_model(X, y, float(censor_at))
    # a trust-region Newton method (scipy's trust-exact through statsmodels) with the
    # analytic score and Hessian: plain Newton can overshoot to sigma -> 0 under heavy
    # censoring
    res = model.fit(
        start_params=start,
        method="minimize",
        min_method="trust-exact",
        maxiter=maxiter,
        gtol=1e-10,
        disp=0,
        warn_convergence=False,
    )
    theta = np.asarray(res.params, float)
    # converged when the Newton decrement g'H^-1 g is negligible (robust to nearly
    # collinear regressors, along which the parameters may still creep)
    g = model.score(theta)
    decrement = float(-g @ np.linalg.lstsq(model.hessian(theta), g, rcond=None)[0])
    if not (res.mle_retvals.get("converged", False) or decrement < 1e-8):
        raise RuntimeError(
            f"Tobit Newton iterations did not converge in {maxiter} steps "
            f"(Newton decrement {decrement:.3g})"
        )
    cov = np.linalg.pinv(-model.hessian(theta))
    return LinearFit(
        list(names or [f"x{i}" for i in range(X.shape[1])]),
        theta[:-1],
        np.sqrt(np.clip(np.diag(cov)[:-1], 0, None)),
        float(np.exp(theta[-1])),
        float(model.loglike(theta)),
        len(y),
        "tobit",
        float(censor_at),
    )


def fit(X, y, kind: str, censor_at: float = 0.0, names=None) -> LinearFit:
    """``fit_ols`` or ``fit_tobit`` by ``kind`` ("ols" or "tobit")."""
    if kind == "ols":
        return fit_ols(X, y, names)
    if kind == "tobit":
        return fit_tobit(X, y, censor_at, names)
    raise InputError(f"regression kind must be 'ols' or 'tobit', got {kind!r}")


@dataclass
class StepwiseResult:
    """Forward stepwise selection: the final fit and the path.

    Attributes
    ----------
    fit : LinearFit
        The model with the forced and the selected regressors.
    selected : list of str
        Regressors added, in order of entry.
    test : {"F", "LR"}
        The entry test used (F for OLS, likelihood ratio for Tobit).
    path : list of dict
        One entry per step: candidate, statistic, p-value, entered.
    """

    fit: LinearFit
    selected: list[str]
    test: str
    path: list[dict] = field(default_factory=list)


def _entry_test(base: LinearFit, new: LinearFit, test: str) -> tuple[float, float]:
    if test == "F":
        rss0 = base.sigma**2 * (base.n - len(base.beta))
        rss1 = new.sigma**2 * (new.n - len(new.beta))
        dfd = new.n - len(new.beta)
        f = (rss0 - rss1) / (rss1 / dfd) if rss1 > 0 else np.inf
        return float(f), float(stats.f.sf(f, 1, dfd))
    lr = max(2.0 * (new.llf - base.llf), 0.0)
    return float(lr), float(stats.chi2.sf(lr, 1))


def forward_stepwise(
    columns: dict[str, np.ndarray],
    y,
    forced: list[str],
    candidates: list[str],
    kind: str = "ols",
    alpha_enter: float = 0.05,
    censor_at: float = 0.0,
    select_rows=None,
) -> StepwiseResult:
    """Forward stepwise selection (thesis §2.5.2, steps 1-3).

    Starting from the ``forced`` regressors, add at each step the candidate with the
    smallest entry p-value while it is below ``alpha_enter``: a partial F-test for OLS, a
    likelihood-ratio chi-square(1) test for Tobit (F is exact only for OLS).

    Parameters
    ----------
    columns : dict of name -> array (n,)
        All regressors by name (forced and candidates).
    y : array (n,)
    forced, candidates : list of str
    kind : {"ols", "tobit"}
    alpha_enter : float
    censor_at : float
    select_rows : array of int or slice, optional
        Rows the selection tests use (e.g. a decimated subset, so that strongly
        autocorrelated samples do not inflate significance); the final model is refitted
        on all rows.
    """
    if not 0.0 < alpha_enter < 1.0:
        raise InputError(f"alpha_enter must be in (0, 1), got {alpha_enter!r}")
    unknown = [c for c in forced + candidates if c not in columns]
    if unknown:
        raise InputError(f"stepwise: unknown regressors {unknown}")
    test = "F" if kind == "ols" else "LR"
    rows = slice(None) if select_rows is None else select_rows
    y = np.asarray(y, float)

    def design(names, r=rows):
        return np.column_stack([np.asarray(columns[c], float)[r] for c in names])

    chosen = list(forced)
    base = fit(design(chosen), y[rows], kind, censor_at, chosen)
    remaining = [c for c in candidates if c not in chosen]
    path, selected = [], []
    while remaining:
        trials = []
        for c in remaining:
            trial = fit(design(chosen + [c]), y[rows], kind, censor_at, chosen + [c])
            trials.append((*_entry_test(base, trial, test), c, trial))
        stat, p, c, trial = min(trials, key=lambda t: (t[1], -t[0]))
        entered = p < alpha_enter
        path.append(
            {"candidate": c, "statistic": stat, "p_value": p, "entered": entered, "test": test}
        )
        if not entered:
            break
        chosen.append(c)
        selected.append(c)
        remaining.remove(c)
        base = trial
    final = fit(design(chosen, slice(None)), y, kind, censor_at, chosen)
    return StepwiseResult(final, selected, test, path)


def fit_defect_classifier(X, labels, random_state=None):
    """Multinomial logistic regression of defect classes (thesis eqs. 2.12-2.13).

    Parameters
    ----------
    X : array (n, p)
        Tension estimates and process variables.
    labels : array (n,)
        Class per sample (e.g. "normal", "slack", "over_stretch"); at least two classes.
    random_state : int, optional

    Returns
    -------
    sklearn.linear_model.LogisticRegression
        Fitted on standardised X (a pipeline), multinomial for three or more classes.
    """
    from sklearn.linear_model import LogisticRegression
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler

    labels = np.asarray(labels)
    if len(np.unique(labels)) < 2:
        raise InputError("the defect classifier needs at least two classes in the data")
    clf = make_pipeline(
        StandardScaler(), LogisticRegression(max_iter=1000, random_state=random_state)
    )
    return clf.fit(np.asarray(X, float), labels)
