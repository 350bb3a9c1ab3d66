"""Derivatives of sampled channels by Savitzky-Golay filtering, the same window on every
channel so that the stacked Y = [y, ẏ, ...] of all sensors refer to the same instant."""

from __future__ import annotations

import numpy as np
from scipy.signal import savgol_filter

from ...errors import InputError


def savgol_window_samples(window_s: float, dt: float, order: int) -> int:
    """The odd number of samples in a ``window_s`` window (at least order + 2)."""
    if not window_s > 0:
        raise InputError(f"savgol_window_s must be > 0 s, got {window_s!r}")
    w = int(round(window_s / dt))
    w += 1 - w % 2
    return max(w, order + 2 + (order + 2 + 1) % 2)


def savgol_derivatives(
    X, dt: float, window: int, order: int, max_deriv: int = 1, causal: bool = False
):
    """Smoothed channels and their time derivatives.

    Parameters
    ----------
    X : array (T, k)
        Samples (rows) of k channels, uniformly spaced by ``dt`` [s]; NaNs (drop-outs) are
        filled by linear interpolation first.
    dt : float
        Sample period [s].
    window : int
        Odd window length [samples], the same for every channel.
    order : int
        Polynomial order (> max_deriv).
    max_deriv : int
    causal : bool
        False: the centred (zero-phase) filter of :func:`scipy.signal.savgol_filter`; each
        estimate refers to its own sample and uses (window − 1)/2 future samples (an offline
        filter). True: only samples 0..k enter the estimates at sample k; the polynomial
        fitted to the window ending at sample k is evaluated at the window's centre, so every
        channel and every derivative refers to the same instant t_k − (window − 1)/2·dt (the
        returned group delay): values and derivatives stay aligned with one another. The
        first window − 1 samples, which have no full window behind them, are NaN, and so is
        a channel's estimate at its own drop-out samples (the interpolation that bridges a
        drop-out reads the next valid sample; later estimates read only samples up to
        their own).

    Notes
    -----
    The causal estimates are evaluated at the window's centre, not at its end point (which
    would have no delay), because the end-point estimates of a quadratic fit are far noisier:
    for white noise on a 301-sample window of order 2, 3.9 times the variance of the centre
    value and 15.9 times that of the centre derivative. The centre estimate is the centred
    filter's, delayed: same noise, same bias, so a relation designed on centred or causal
    estimates sees the same statistics.

    Returns
    -------
    D : ndarray (max_deriv + 1, T, k)
        D[d] is the d-th derivative (d = 0: the smoothed channel), in units per s^d.
    delay_s : float
        Group delay of the estimates [s] (0 for the centred filter).
    """
    X = np.asarray(X, dtype=float)
    if X.ndim == 1:
        X = X[:, None]
    if window % 2 != 1 or window <= order:
        raise InputError(f"savgol window must be odd and > order ({order}), got {window}")
    if order <= max_deriv:
        raise InputError(f"savgol_order must exceed the highest derivative ({max_deriv})")
    missing = ~np.isfinite(X)
    X = _fill(X)
    T = len(X)
    if T < window:
        raise InputError(f"{T} samples are fewer than the Savitzky-Golay window ({window})")
    out = np.empty((max_deriv + 1, T, X.shape[1]))
    if not causal:
        for d in range(max_deriv + 1):
            out[d] = savgol_filter(X, window, order, deriv=d, delta=dt, axis=0, mode="interp")
        return out, 0.0
    half = (window - 1) // 2
    for d in range(max_deriv + 1):
        # the fit over the window ending at k evaluated at its centre = the centred filter
        # one half-window earlier: zero-phase estimate, delayed by half a window. Only the
        # centred filter's interior (a plain convolution over [k - half, k + half]) is used:
        # its first `half` values come from a polynomial fitted to the whole first window,
        # which would let samples up to window - 1 into the estimates at samples half..window-2
        full = savgol_filter(X, window, order, deriv=d, delta=dt, axis=0, mode="interp")
        out[d, half:] = full[: T - half]
        out[d, : window - 1] = np.nan
        out[d][missing] = np.nan
    return out, half * dt


def _fill(X: np.ndarray) -> np.ndarray:
    bad = ~np.isfinite(X)
    if not bad.any():
        return X
    X = X.copy()
    idx = np.arange(len(X))
    for j in range(X.shape[1]):
        ok = ~bad[:, j]
        if not ok.any():
            raise InputError("a channel has no finite sample")
        X[bad[:, j], j] = np.interp(idx[bad[:, j]], idx[ok], X[ok, j])
    return X
