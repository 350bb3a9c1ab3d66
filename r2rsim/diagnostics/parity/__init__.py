"""Nonlinear parity-space sensor validation (thesis Shui 2018, Ch. 3): Lie-derivative
observation matrix, parity space, robust min-max coefficients, KKT post-optimal sensitivity,
Savitzky-Golay derivatives, and the ``parity`` plug-in (:class:`ParitySpaceDetector`)."""

from ._design import Design, design_relation, sensitivity
from ._line import PRESETS, ROLES, find_roles, line_numbers
from ._model import NonlinearModel, registration_model
from ._plugin import ParitySpaceDetector, registration_parameters
from ._signal import savgol_derivatives, savgol_window_samples

__all__ = [
    "PRESETS",
    "ROLES",
    "Design",
    "NonlinearModel",
    "ParitySpaceDetector",
    "design_relation",
    "find_roles",
    "line_numbers",
    "registration_model",
    "registration_parameters",
    "savgol_derivatives",
    "savgol_window_samples",
    "sensitivity",
]
