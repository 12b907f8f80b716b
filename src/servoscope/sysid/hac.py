"""Newey–West (HAC) covariance: standard errors that hold when tracking errors are correlated.

Tracking errors depend on where a sticker sits on the pixel grid, which changes slowly from
frame to frame, so the residuals of a sine fit are correlated; :func:`hac_covariance` gives
least-squares parameters a covariance that accounts for it (:mod:`servoscope.sysid.sine`,
"Method").
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["USE_HAC", "andrews_lag", "hac_covariance", "newey_west_lag"]

#: Newey–West (HAC) standard errors instead of the white-noise ones in every sine fit (a switch
#: for tests that compare the two; read at each call).
USE_HAC = True


def newey_west_lag(n: int) -> int:
    """Bandwidth (largest lag) of the Newey–West covariance for ``n`` samples.

    Newey & West (1994)'s rule of thumb for the Bartlett kernel,
    ``floor(4 * (n / 100)**(2/9))`` (the default of statsmodels'
    ``cov_type="HAC"`` users and of Stock & Watson's textbook); at least 1.
    """
    return max(1, int(math.floor(4.0 * (max(n, 1) / 100.0) ** (2.0 / 9.0))))


def andrews_lag(residual: ArrayLike) -> int:
    """Data-dependent Bartlett bandwidth of Andrews (1991), AR(1) plug-in.

    ``ceil(1.1447 * (alpha * n)**(1/3))`` with ``alpha = 4 rho**2 /
    ((1 - rho)**2 (1 + rho)**2)`` and ``rho`` the lag-1 autocorrelation of
    the residuals (clipped to ±0.97). Strongly correlated errors (as H.264
    tracking errors of slow dwells, rho ≈ 0.9) need many more lags than
    :func:`newey_west_lag` gives.
    """
    r = np.asarray(residual, dtype=float).ravel()
    n = r.size
    if n < 3:
        return 1
    r = r - r.mean()
    den = float(r @ r)
    rho = float(r[1:] @ r[:-1]) / den if den > 0 else 0.0
    rho = min(max(rho, -0.97), 0.97)
    alpha = 4.0 * rho * rho / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
    return max(1, int(math.ceil(1.1447 * (alpha * n) ** (1.0 / 3.0))))


def hac_covariance(
    jac: NDArray[np.float64], residual: NDArray[np.float64], lag: int | None = None,
    groups: NDArray[np.int_] | None = None,
) -> NDArray[np.float64]:
    """Newey–West (HAC) covariance of least-squares parameters.

    The sandwich ``B @ S @ B`` with ``B = inv(J.T @ J)`` and ``S`` the
    long-run covariance of the scores ``u_t = J[t] * r[t]`` estimated with
    Bartlett weights ``1 - l/(L + 1)`` for lags ``l <= L`` (Newey & West
    1987), times the small-sample factor ``n / (n - p)`` (as statsmodels'
    ``use_correction``). For white residuals it equals the classical
    ``s**2 * inv(J.T @ J)`` on average; residuals correlated from frame to
    frame (tracking errors that depend on the marker's sub-pixel position
    change slowly as it moves) make it larger where the classical one is
    too small. For a sinusoidal regressor it measures, in effect, the
    residual's spectral density at the regressor's frequency.

    Parameters
    ----------
    jac : numpy.ndarray, shape (n, p)
        Jacobian (design matrix) of the model at the estimate, rows in time
        order (samples equally spaced, gaps of invalid frames ignored).
    residual : numpy.ndarray, shape (n,)
        Residuals at the estimate, same order.
    lag : int, optional
        Largest lag L; default the larger of :func:`newey_west_lag` and
        :func:`andrews_lag` of the residuals, at most ``n // 2``.
    groups : numpy.ndarray of int, shape (n,), optional
        Which series each row belongs to (several tests' traces fitted at once): scores are
        taken as correlated within a series only, lagged products across two are left out.

    Returns
    -------
    numpy.ndarray, shape (p, p)
        Covariance matrix; NaN when ``n <= p``.
    """
    J = np.asarray(jac, dtype=float)
    r = np.asarray(residual, dtype=float)
    n, p = J.shape
    if n <= p:
        return np.full((p, p), np.nan)
    L = min(max(newey_west_lag(n), andrews_lag(r)), n // 2) if lag is None else int(lag)
    u = J * r[:, None]
    S = u.T @ u
    same = None if groups is None else np.asarray(groups)
    for l in range(1, min(L, n - 1) + 1):
        g = (u[l:] * (same[l:] == same[:-l])[:, None]).T @ u[:-l] if same is not None else u[l:].T @ u[:-l]
        S += (1.0 - l / (L + 1.0)) * (g + g.T)
    try:
        B = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        B = np.linalg.pinv(J.T @ J)
    return (B @ S @ B) * (n / (n - p))
