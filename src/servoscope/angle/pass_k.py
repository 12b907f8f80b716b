"""The foreshortening's curvature ``k``, common to every pass of a clip, and the pitch rate's spread over the clip.

``k`` is the camera's geometry (½ orthographic, (D + R)/(2(D − R)) for a pinhole at D looking at
a tip at R), so one value serves every pass; it is fitted by minimising the passes' pooled
residuals after each frame's angle is corrected, θ = atan(tan φ / F(ψ)) (docs/rotor.md).

What makes it hard when every pass is short (2–3 frames with both stickers whole, a fast rotor
at 2,000 frames/s) is the pitch's own rate through a pass: over one frame interval (0.5 ms) a
14 Hz dwell of ±1.7° moves the pitch by ~0.05°, as much as the foreshortening moves it at ψ = 5°
(k·ψ²·sin θ cos θ). A 2-frame pass tells only its two frames' difference, the rate and the
curvature mixed; a 3-frame pass's curvature (the residual about its own line) is the rate's no
matter what. :func:`fit_k_mixed` therefore weighs each short pass by what it tells
(generalised least squares with each short pass's rate a random effect of the clip's spread,
:func:`pitch_rate_spread_rad_s`): the rate's direction of a short pass by σ² + s²·Σd², the rest by
σ² (σ one frame's error, from the residuals of the passes of 3 frames or more). On the twin's
monochrome footage at 2,000 frames/s (2 blades, 25–30 rev/s, every pass 2–3 frames) k came
1.30–1.74 ± 0.21–0.25 from the plain pooled residual, 1.37–1.50 ± 0.04–0.06 this way, against 1.44.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .pass_table import ORTHOGRAPHIC_K

__all__ = ["K_RANGE", "MIN_PASS_FRAMES", "fit_k_mixed", "fit_k_pooled", "foreshortening", "pitch_rate_spread_rad_s"]

#: Fewest frames with both stickers whole for a pass's own line (fewer, down to 2: a short pass,
#: :mod:`servoscope.angle.pass_short`).
MIN_PASS_FRAMES = 4
#: The range ``k`` is searched in: 0 (no foreshortening) to a camera 1.05 tip radii from the axis.
K_RANGE = (0.0, 25.0)
#: Fewest degrees of freedom (frames beyond each pass's line) in 3-frame-or-longer passes for one frame's
#: error σ², which :func:`fit_k_mixed` weighs the short passes with; fewer: :func:`fit_k_pooled`.
MIN_SIGMA_DOF = 3


def foreshortening(psi_rad: NDArray[np.float64] | float, k: float) -> NDArray[np.float64]:
    """F(ψ) = 1 / cos(√(2k)·ψ): how much a pass's image angle's tangent exceeds the pitch's at azimuth ψ.

    Parameters
    ----------
    psi_rad : array_like
        Azimuth from the camera (rad).
    k : float
        The curvature of F at ψ = 0 (F ≈ 1 + k·ψ²): ½ orthographic, (D + R)/(2(D − R)) for a
        pinhole at D from the axis and a tip at radius R.

    Returns
    -------
    ndarray
    """
    return 1.0 / np.cos(math.sqrt(2.0 * max(k, 0.0)) * np.asarray(psi_rad, dtype=np.float64))


def pitch_rate_spread_rad_s(time_s: NDArray[np.float64], pitch_rad: NDArray[np.float64],
                            blade: NDArray[np.int64], noise_rad: float = 0.0) -> float:
    """The RMS of the pitch's rate over the clip, from consecutive passes' pitches (each blade's mean taken out).

    A short pass holds its own rate at 0; this is the rate's spread its error takes on. The
    consecutive passes' differences over their time apart are the rate between them (a sine
    of frequency f sampled h apart: its rate times sin(πfh)/(πfh), 0.81 at 14 Hz and 25 ms);
    their mean square less the pitches' own noise's share (2·noise²/h²).

    Parameters
    ----------
    time_s, pitch_rad : ndarray
        Every pass's time (s) and pitch (rad).
    blade : ndarray of int
    noise_rad : float
        A pass's pitch error (rad, typical).

    Returns
    -------
    float
        rad/s; 0 with fewer than 3 passes.
    """
    t = np.asarray(time_s, dtype=np.float64)
    p = np.asarray(pitch_rad, dtype=np.float64).copy()
    b = np.asarray(blade, dtype=np.int64)
    ok = np.isfinite(t) & np.isfinite(p)
    if ok.sum() < 3:
        return 0.0
    t, p, b = t[ok], p[ok], b[ok]
    for k in np.unique(b):
        p[b == k] -= p[b == k].mean()
    order = np.argsort(t)
    dt, dp = np.diff(t[order]), np.diff(p[order])
    good = dt > 0
    if not good.any():
        return 0.0
    ms = float(np.mean((dp[good] / dt[good]) ** 2) - np.mean(2.0 * noise_rad ** 2 / dt[good] ** 2))
    return math.sqrt(max(ms, 0.0))


def _corrected(taus, phis, rev_per_s: float, k: float) -> list[np.ndarray]:
    return [np.arctan(np.tan(phi) / foreshortening(2.0 * math.pi * rev_per_s * tau, k)) for tau, phi in zip(taus, phis)]


def _line_rss(x: NDArray[np.float64], y: NDArray[np.float64]) -> float:
    """Residual sum of squares of y's least-squares line in x (closed form: the fits call it ~30,000 times
    a video, where ``np.linalg.lstsq``'s overhead was a quarter of a rotor identification's CPU)."""
    dx = x - x.mean()
    dy = y - y.mean()
    sxx = float(dx @ dx)
    sxy = float(dx @ dy)
    return max(float(dy @ dy) - (sxy * sxy / sxx if sxx > 0 else 0.0), 0.0)


def _mean_rss(y: NDArray[np.float64]) -> float:
    """Residual sum of squares of y about its mean."""
    dy = y - y.mean()
    return float(dy @ dy)


def _minimise(cost, grid_points: int = 51) -> float:
    """The ``k`` in :data:`K_RANGE` minimising ``cost``: a grid, then a bounded search around its best."""
    from scipy.optimize import minimize_scalar

    grid = np.linspace(*K_RANGE, grid_points)
    j = int(np.argmin([cost(g) for g in grid]))
    lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
    return float(minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": 1e-5}).x)


def _curvature(cost, k: float, h: float = 0.05) -> float:
    return (cost(k + h) + cost(max(k - h, 0.0)) - 2.0 * cost(k)) / (h * h)


def fit_k_pooled(passes: list[tuple[NDArray[np.float64], NDArray[np.float64]]], t_c_s: NDArray[np.float64],
                 rev_per_s: float) -> tuple[float, float]:
    """``k`` minimising the passes' pooled residuals: a line through each pass, a short pass's mean alone.

    Parameters
    ----------
    passes : list of (time_s, angle_rad)
        Each pass's frames with both stickers whole (s; the trail→lead image angle, rad).
    t_c_s : ndarray
        Each pass's ψ = 0 time (s).
    rev_per_s : float

    Returns
    -------
    (k, stderr) : (float, float)
        (½, NaN) when the passes do not tell it (pitch near 0, too few frames).
    """
    if not passes:
        return ORTHOGRAPHIC_K, math.nan
    taus = [np.asarray(t, dtype=float) - tc for (t, _), tc in zip(passes, t_c_s)]
    phis = [np.asarray(p, dtype=float) for _, p in passes]
    n = sum(x.size for x in taus)
    # A pass of fewer than MIN_PASS_FRAMES frames: its mean alone (its own rate held at 0).
    lines = [x.size >= MIN_PASS_FRAMES for x in taus]
    dof = n - sum(2 if ln else 1 for ln in lines) - 1
    if dof < 3:
        return ORTHOGRAPHIC_K, math.nan

    def rss(k: float) -> float:
        total = 0.0
        for tau, theta, ln in zip(taus, _corrected(taus, phis, rev_per_s, k), lines):
            total += _line_rss(tau, theta) if ln else _mean_rss(theta)
        return total

    k = _minimise(rss)
    curv = _curvature(rss, k)
    if not curv > 0:
        return ORTHOGRAPHIC_K, math.nan
    stderr = math.sqrt(2.0 * (rss(k) / dof) / curv)
    if stderr > max(1.0, k):  # the passes do not tell the curvature (pitch near 0, short passes)
        return ORTHOGRAPHIC_K, math.nan
    return k, stderr


def fit_k_mixed(passes: list[tuple[NDArray[np.float64], NDArray[np.float64]]], t_c_s: NDArray[np.float64],
                rev_per_s: float, blade: NDArray[np.int64] | None = None, *, rounds: int = 2) -> tuple[float, float]:
    """``k`` with each short pass weighed by what it tells: its own rate a random effect of the clip's spread.

    A pass of :data:`MIN_PASS_FRAMES` frames or more keeps its own line (weight 1/σ²). A short pass's
    corrected angles less their mean and a slope ``c`` common to the short passes (ψ = 0 read late
    makes the even correction slightly odd, the same in every pass) are split into the direction
    of its frames' times (its rate's, variance σ² + s²·Σd², d the times about their mean) and the
    rest (σ²). σ² from the residuals about their own lines of the passes of 3 frames or more, s
    from the passes' pitches (:func:`pitch_rate_spread_rad_s`), both re-read at each round's ``k``.
    The error from the χ²'s curvature, scaled by χ²/dof where that exceeds 1.

    Parameters
    ----------
    passes : list of (time_s, angle_rad)
    t_c_s : ndarray
    rev_per_s : float
    blade : ndarray of int, optional
        Each pass's blade (each blade's pitch offset out of the rate's spread); None: one blade.
    rounds : int
        Rounds of σ², s and ``k``.

    Returns
    -------
    (k, stderr) : (float, float)
        :func:`fit_k_pooled`'s when no pass is short, when the passes of 3 frames or more leave fewer
        than :data:`MIN_SIGMA_DOF` degrees of freedom for σ², or when that does not tell ``k``.
    """
    k, stderr = fit_k_pooled(passes, t_c_s, rev_per_s)
    taus = [np.asarray(t, dtype=float) - tc for (t, _), tc in zip(passes, t_c_s)]
    phis = [np.asarray(p, dtype=float) for _, p in passes]
    lines = [x.size >= MIN_PASS_FRAMES for x in taus]
    sigma_dof = sum(x.size - 2 for x in taus if x.size >= 3)
    if all(lines) or not math.isfinite(stderr) or sigma_dof < MIN_SIGMA_DOF:
        return k, stderr
    b = np.zeros(len(taus), dtype=np.int64) if blade is None else np.asarray(blade, dtype=np.int64)
    t_c = np.asarray(t_c_s, dtype=np.float64)
    dof = sum(x.size for x in taus) - sum(2 if ln else 1 for ln in lines) - 2
    d = [tau - tau.mean() for tau in taus]

    def chi2(kk: float, sig2: float, s2: float) -> float:
        theta = _corrected(taus, phis, rev_per_s, kk)
        num = den = 0.0
        for di, th, ln in zip(d, theta, lines):
            if not ln:
                w = 1.0 / (sig2 + s2 * float(di @ di))
                num += w * float(di @ (th - th.mean()))
                den += w * float(di @ di)
        c = num / den if den > 0 else 0.0
        total = 0.0
        for tau, di, th, ln in zip(taus, d, theta, lines):
            if ln:
                total += _line_rss(tau, th) / sig2
                continue
            y = th - th.mean() - c * di
            dd = float(di @ di)
            along = float(di @ y) ** 2 / dd if dd > 0 else 0.0
            total += (float(y @ y) - along) / sig2 + along / (sig2 + s2 * dd)
        return total

    for _ in range(rounds):
        theta = _corrected(taus, phis, rev_per_s, k)
        ss = 0.0
        for tau, th in zip(taus, theta):
            if tau.size >= 3:
                ss += _line_rss(tau, th)
        sig2 = ss / sigma_dof
        if not sig2 > 0:
            return fit_k_pooled(passes, t_c_s, rev_per_s)
        spread = pitch_rate_spread_rad_s(t_c, np.array([float(th.mean()) for th in theta]), b, math.sqrt(sig2))
        s2 = spread * spread
        k = _minimise(lambda kk: chi2(kk, sig2, s2), grid_points=101)
    cost = lambda kk: chi2(kk, sig2, s2)  # noqa: E731
    curv = _curvature(cost, k)
    if not curv > 0 or dof <= 0:
        return fit_k_pooled(passes, t_c_s, rev_per_s)
    stderr = math.sqrt(2.0 * max(cost(k) / dof, 1.0) / curv)
    if stderr > max(1.0, k):
        return ORTHOGRAPHIC_K, math.nan
    return k, stderr
