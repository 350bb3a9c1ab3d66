"""The hybrid multistage stream-of-variation tension model and virtual sensor of Shui (2018)
Ch. 2 (docs/diagnostics.md §9): physics regressors per stage, Tobit / OLS with forward
stepwise selection, the pitch observation, and the ``hybrid-sov`` plug-in."""

from ._line import ROLES, LineStages, load_stages
from ._model import DataDrivenModel, HybridModel
from ._plugin import HybridSoV
from ._regression import (
    LinearFit,
    StepwiseResult,
    fit_defect_classifier,
    fit_ols,
    fit_tobit,
    forward_stepwise,
    tobit_loglike,
)

__all__ = [
    "ROLES",
    "DataDrivenModel",
    "HybridModel",
    "HybridSoV",
    "LineStages",
    "LinearFit",
    "StepwiseResult",
    "fit_defect_classifier",
    "fit_ols",
    "fit_tobit",
    "forward_stepwise",
    "load_stages",
    "tobit_loglike",
]
