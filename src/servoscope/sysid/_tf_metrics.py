"""How well a transfer function fits, and how fast it is: CIFER's cost J and the -3 dB bandwidth.

Part of the transfer-function fit (:mod:`servoscope.sysid.tf_fit` describes the whole); the
metrics need no data class and no optimizer, so everything else may import them.
"""

from __future__ import annotations

import math

import control
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq

from servoscope.errors import ServoscopeError

__all__ = ["CIFER_PHASE_WEIGHT", "DB_PER_NEPER", "J_ACCEPTABLE", "J_NEAR_PERFECT", "bandwidth_rad_s", "cifer_cost",
           "j_rating"]

#: dB per neper: ``20*log10(x) = DB_PER_NEPER * ln(x)``.
DB_PER_NEPER = 20.0 / math.log(10.0)


#: CIFER's phase weight W_p (per deg**2, with W_g = 1 per dB**2).
CIFER_PHASE_WEIGHT = 0.01745
#: CIFER's thresholds on J.
#: CIFER's thresholds on J.
J_NEAR_PERFECT = 50.0
J_ACCEPTABLE = 100.0


def _siso_eval(tf: control.TransferFunction, s: NDArray[np.complex128]) -> NDArray[np.complex128]:
    num = np.atleast_1d(np.asarray(tf.num[0][0], dtype=float))
    den = np.atleast_1d(np.asarray(tf.den[0][0], dtype=float))
    return np.polyval(num, s) / np.polyval(den, s)


def bandwidth_rad_s(tf: control.TransferFunction, *, drop_db: float = -3.0) -> float:
    """Frequency where the gain first falls ``|drop_db|`` dB below the DC gain.

    The default is the classic -3 dB bandwidth, defined as ``|G(jw)| =
    |G(0)| * 10**(-3/20)``. Found by scanning a log grid for the first
    crossing and refining it with :func:`scipy.optimize.brentq`.

    Parameters
    ----------
    tf : control.TransferFunction
        Stable, continuous-time SISO transfer function with finite, nonzero DC
        gain (a dead time does not change the magnitude, so pass the
        rational part).
    drop_db : float, default -3.0
        Gain drop in dB (negative).

    Returns
    -------
    float
        Bandwidth in rad/s; ``inf`` when the gain never falls that far.

    Raises
    ------
    ServoscopeError
        For a discrete-time, MIMO or unstable system, or a zero/infinite DC
        gain.
    """
    if not isinstance(tf, control.TransferFunction):
        tf = control.tf(tf)
    if tf.ninputs != 1 or tf.noutputs != 1:
        raise ServoscopeError("bandwidth_rad_s: only SISO systems are supported")
    if tf.isdtime(strict=True):
        raise ServoscopeError("bandwidth_rad_s: only continuous-time systems are supported")
    poles = np.asarray(tf.poles())
    if poles.size and np.any(poles.real >= 0):
        raise ServoscopeError("bandwidth_rad_s: the system is not stable")
    if not drop_db < 0:
        raise ServoscopeError(f"bandwidth_rad_s: drop_db must be negative, got {drop_db}")
    dc = abs(complex(_siso_eval(tf, np.array([0j]))[0]))
    if not (math.isfinite(dc) and dc > 0):
        raise ServoscopeError("bandwidth_rad_s: DC gain is zero or infinite")
    target = dc * 10.0 ** (drop_db / 20.0)
    roots = np.concatenate([poles, np.asarray(tf.zeros())])
    mags = np.abs(roots[np.abs(roots) > 0])
    lo = (mags.min() if mags.size else 1.0) * 1e-4
    hi = (mags.max() if mags.size else 1.0) * 1e4

    def f(w: float) -> float:
        return float(abs(_siso_eval(tf, np.array([1j * w]))[0]) - target)

    grid = np.geomspace(lo, hi, 4001)
    vals = np.abs(_siso_eval(tf, 1j * grid)) - target
    below = np.nonzero(vals < 0)[0]
    if below.size == 0:
        return float("inf")
    k = int(below[0])
    if k == 0:
        return float(brentq(f, 0.0, grid[0], xtol=1e-14, rtol=1e-14))
    return float(brentq(f, grid[k - 1], grid[k], xtol=1e-14, rtol=1e-14))


def cifer_cost(
    measured_db_error: ArrayLike,
    phase_error_deg: ArrayLike | None = None,
    coherence: ArrayLike | None = None,
) -> float:
    """CIFER's frequency-response cost function J.

    ``J = (20/n) * sum W_gamma * (W_g * dB_err**2 + W_p * deg_err**2)`` with
    ``W_g = 1``, ``W_p = 0.01745`` and ``W_gamma = (1.58*(1 - exp(-gamma**2)))**2``.

    Parameters
    ----------
    measured_db_error : array_like, shape (n,)
        Magnitude errors (model - measured) in dB.
    phase_error_deg : array_like, shape (n,), optional
        Phase errors in degrees (NaN: no phase there); None for a
        magnitude-only J.
    coherence : array_like, shape (n,), optional
        Coherence ``gamma**2`` per point (0..1; NaN or None: 1).

    Returns
    -------
    float
        J (dimensionless); <= 50 near-perfect, <= 100 acceptable.
    """
    db = np.asarray(measured_db_error, dtype=float)
    n = db.size
    if n == 0:
        return float("nan")
    g2 = np.ones(n) if coherence is None else np.asarray(coherence, dtype=float).copy()
    g2 = np.where(np.isfinite(g2), np.clip(g2, 0.0, 1.0), 1.0)
    wg = (1.58 * (1.0 - np.exp(-g2))) ** 2
    term = db**2
    if phase_error_deg is not None:
        ph = np.asarray(phase_error_deg, dtype=float)
        term = term + CIFER_PHASE_WEIGHT * np.where(np.isfinite(ph), ph, 0.0) ** 2
    return float(20.0 / n * np.sum(wg * term))


def j_rating(j: float) -> str:
    """CIFER's verdict on a cost J: "near-perfect", "acceptable", "poor" or "unknown" (NaN)."""
    if not math.isfinite(j):
        return "unknown"
    if j <= J_NEAR_PERFECT:
        return "near-perfect"
    if j <= J_ACCEPTABLE:
        return "acceptable"
    return "poor"
