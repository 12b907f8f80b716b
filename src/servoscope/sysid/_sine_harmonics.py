"""Sines and their harmonics at a given frequency: design matrix, periodogram, harmonics' test.

Steps of :func:`~servoscope.sysid.fit_sine` (:mod:`servoscope.sysid.sine`, "Sinusoidal fidelity
and harmonics").
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2 as chi2_dist

from servoscope.sysid import hac
from servoscope.sysid.hac import hac_covariance

__all__ = ["HARMONICS", "design_matrix", "fit_harmonics", "fit_power"]

#: The harmonics fitted beside the fundamental.
HARMONICS = (2, 3, 4, 5)


def design_matrix(t: NDArray[np.float64], freq_hz: float, tc: float) -> NDArray[np.float64]:
    """Columns ``1, cos, sin`` of ``2*pi*freq_hz*(t - tc)``."""
    theta = 2.0 * math.pi * freq_hz * (t - tc)
    return np.column_stack([np.ones_like(t), np.cos(theta), np.sin(theta)])


def fit_power(t: NDArray[np.float64], y: NDArray[np.float64], freqs: NDArray[np.float64], tc: float) -> NDArray[np.float64]:
    """Floating-mean periodogram: AC power explained by a sine at each frequency.

    For each frequency, the sum of squares explained by the least-squares fit
    of ``offset + a*cos + b*sin`` beyond the mean (same units as ``y**2``).
    """
    yc = y - y.mean()
    th = 2.0 * math.pi * np.outer(freqs, t - tc)
    c = np.cos(th)
    s = np.sin(th)
    c -= c.mean(axis=1, keepdims=True)
    s -= s.mean(axis=1, keepdims=True)
    cc = np.einsum("ij,ij->i", c, c)
    ss = np.einsum("ij,ij->i", s, s)
    cs = np.einsum("ij,ij->i", c, s)
    cy = c @ yc
    sy = s @ yc
    det = cc * ss - cs * cs
    ok = det > 1e-12 * np.maximum(cc * ss, 1e-300)
    out = np.zeros(freqs.size)
    # explained SS = v^T M^{-1} v with M = [[cc, cs], [cs, ss]], v = [cy, sy]
    out[ok] = (ss[ok] * cy[ok] ** 2 - 2 * cs[ok] * cy[ok] * sy[ok] + cc[ok] * sy[ok] ** 2) / det[ok]
    return out


def fit_harmonics(
    t: NDArray[np.float64], y: NDArray[np.float64], freq_hz: float, tc: float, dt_s: float,
    artefact: list[float | None] | None = None,
) -> tuple[list[float | None], list[float | None], float, float]:
    """Amplitudes (and stderrs) of harmonics 2..5, the p-value of the joint
    Wald test that they are all zero, and the residual RMS.

    ``artefact`` (amplitudes per harmonic 2..5, as returned for a null
    channel) adds ``A**2 / 2`` to the variance of both coefficients of each
    harmonic in the test: harmonics no larger than the measurement's own
    artefacts are not significant."""
    th = 2.0 * math.pi * freq_hz * (t - tc)
    ks = [k for k in HARMONICS if dt_s > 0 and k * freq_hz < 0.95 * 0.5 / dt_s]
    cols = [np.ones_like(t), np.cos(th), np.sin(th)]
    for k in ks:
        cols += [np.cos(k * th), np.sin(k * th)]
    X = np.column_stack(cols)
    n, p = X.shape
    amps: list[float | None] = [None] * len(HARMONICS)
    ses: list[float | None] = [None] * len(HARMONICS)
    if n <= p:
        return amps, ses, float("nan"), float("nan")
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    s2 = float(r @ r) / (n - p)
    if hac.USE_HAC:
        # The same noise model as the fundamental's: correlated tracking
        # errors would otherwise make any harmonic look significant.
        cov = hac_covariance(X, r)
    else:
        try:
            cov = np.linalg.inv(X.T @ X) * s2
        except np.linalg.LinAlgError:
            cov = np.linalg.pinv(X.T @ X) * s2
    for j, k in enumerate(ks):
        a, b = float(coef[3 + 2 * j]), float(coef[4 + 2 * j])
        sub = cov[3 + 2 * j : 5 + 2 * j, 3 + 2 * j : 5 + 2 * j]
        amp = math.hypot(a, b)
        g = np.array([a, b]) / amp if amp > 0 else np.array([math.sqrt(0.5), math.sqrt(0.5)])
        amps[HARMONICS.index(k)] = amp
        ses[HARMONICS.index(k)] = math.sqrt(max(float(g @ sub @ g), 0.0))
    # Joint Wald test that all harmonic coefficients are zero.
    p_value = float("nan")
    if ks:
        v = coef[3:]
        block = cov[3:, 3:].copy()
        if artefact is not None:
            for j, k in enumerate(ks):
                extra = artefact[HARMONICS.index(k)]
                if extra is not None and math.isfinite(extra):
                    block[2 * j, 2 * j] += 0.5 * extra * extra
                    block[2 * j + 1, 2 * j + 1] += 0.5 * extra * extra
        try:
            chi2 = float(v @ np.linalg.solve(block, v)) if s2 > 0 else math.inf
        except np.linalg.LinAlgError:
            chi2 = float(v @ np.linalg.pinv(block) @ v)
        p_value = float(chi2_dist.sf(chi2, 2 * len(ks)))
    return amps, ses, p_value, math.sqrt(float(r @ r) / n)
