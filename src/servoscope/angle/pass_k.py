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


class _Frames:
    """Every pass's frames in flat arrays, with what the fits need per pass: the χ² below is evaluated
    ~1,000 times a clip, and a Python loop over hundreds of passes at each was most of a rotor
    identification's CPU (2.1 s for `paper-rotor`'s four videos)."""

    def __init__(self, taus: list[NDArray[np.float64]], phis: list[NDArray[np.float64]], rev_per_s: float):
        self.n_pass = len(taus)
        self.size = np.array([t.size for t in taus], dtype=np.int64)
        self.seg = np.repeat(np.arange(self.n_pass), self.size)
        self.tau = np.concatenate(taus) if taus else np.zeros(0)
        self.tan_phi = np.tan(np.concatenate(phis)) if phis else np.zeros(0)
        self.omega = 2.0 * math.pi * rev_per_s
        # Each frame's time about its pass's mean, and their sum of squares per pass.
        self.d = self.tau - self.mean(self.tau)[self.seg]
        self.dd = self.sum(self.d * self.d)

    def sum(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per pass sum of a per-frame quantity."""
        return np.bincount(self.seg, weights=x, minlength=self.n_pass)

    def mean(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        return self.sum(x) / self.size

    def corrected(self, k: float) -> NDArray[np.float64]:
        """θ = atan(tan φ / F(ψ)) at every frame."""
        return np.arctan(self.tan_phi / foreshortening(self.omega * self.tau, k))

    def about_mean(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        return theta - self.mean(theta)[self.seg]

    def line_rss(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per pass residual sum of squares of θ's least-squares line in time (closed form)."""
        y = self.about_mean(theta)
        syy, sxy = self.sum(y * y), self.sum(self.d * y)
        with np.errstate(divide="ignore", invalid="ignore"):
            fit = np.where(self.dd > 0, sxy * sxy / np.where(self.dd > 0, self.dd, 1.0), 0.0)
        return np.maximum(syy - fit, 0.0)

    def mean_rss(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """Per pass residual sum of squares of θ about its mean."""
        y = self.about_mean(theta)
        return self.sum(y * y)


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
    lines = np.array([x.size >= MIN_PASS_FRAMES for x in taus])
    dof = n - int(np.sum(np.where(lines, 2, 1))) - 1
    if dof < 3:
        return ORTHOGRAPHIC_K, math.nan
    frames = _Frames(taus, phis, rev_per_s)

    def rss(k: float) -> float:
        theta = frames.corrected(k)
        return float(np.sum(np.where(lines, frames.line_rss(theta), frames.mean_rss(theta))))

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
    frames = _Frames(taus, phis, rev_per_s)
    line = np.array(lines)
    short = ~line
    dd = frames.dd
    three = frames.size >= 3

    def chi2(kk: float, sig2: float, s2: float) -> float:
        theta = frames.corrected(kk)
        y0 = frames.about_mean(theta)
        dy = frames.sum(frames.d * y0)  # Σ d·(θ − θ̄) per pass
        w = 1.0 / (sig2 + s2 * dd)
        den = float(np.sum((w * dd)[short]))
        c = float(np.sum((w * dy)[short])) / den if den > 0 else 0.0
        # A short pass: y = θ − θ̄ − c·d; Σy² = Σ(θ−θ̄)² − 2c·Σd(θ−θ̄) + c²·Σd²; Σd·y = Σd(θ−θ̄) − c·Σd².
        yy = frames.sum(y0 * y0) - 2.0 * c * dy + c * c * dd
        dy_c = dy - c * dd
        with np.errstate(divide="ignore", invalid="ignore"):
            along = np.where(dd > 0, dy_c * dy_c / np.where(dd > 0, dd, 1.0), 0.0)
        short_terms = (yy - along) / sig2 + along / (sig2 + s2 * dd)
        line_terms = frames.line_rss(theta) / sig2
        return float(np.sum(np.where(line, line_terms, short_terms)))

    for _ in range(rounds):
        theta = frames.corrected(k)
        sig2 = float(np.sum(frames.line_rss(theta)[three])) / sigma_dof
        if not sig2 > 0:
            return fit_k_pooled(passes, t_c_s, rev_per_s)
        spread = pitch_rate_spread_rad_s(t_c, frames.mean(theta), b, math.sqrt(sig2))
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
