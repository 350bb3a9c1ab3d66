"""Nonlinear parity-space sensor validation (thesis Shui 2018, Ch. 3): Lie-derivative
observation matrix, parity space, robust min-max coefficients, KKT post-optimal sensitivity,
Savitzky-Golay derivatives, and the ``parity`` plug-in (:class:`ParitySpaceDetector`)."""

from ._design import Design, design_relation, sensitivity
from ._model import NonlinearModel, registration_model
from ._plugin import ParitySpaceDetector, registration_parameters
from ._signal import savgol_derivatives, savgol_window_samples

__all__ = ["Design", "NonlinearModel", "ParitySpaceDetector", "design_relation",
           "registration_model", "registration_parameters", "savgol_derivatives",
           "savgol_window_samples", "sensitivity"]
