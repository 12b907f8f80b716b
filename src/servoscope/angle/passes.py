"""A turning rotor's blades, pass by pass: the pitch at ψ = 0 from each pass's frames, and the rotor speed.

A fixed camera in the rotor's plane, outside the disc, looks at the rotor axis. Once a
revolution each blade's tip crosses the picture end-on, its lead and trail stickers
either side of the pitch axis along the chord. Through the pass the blade turns about
the axis by the azimuth ψ (0 when it points at the camera), and the image angle of the
trail→lead line is the pitch foreshortened:

    tan φ = tan θ(t) · F(ψ),   F(ψ) = 1 / cos(√(2k)·ψ) ≈ 1 + k·ψ²,

with k = ½ in the orthographic limit (tan φ = tan θ / cos ψ) and k = (D + R) / (2 (D − R))
for a pinhole at distance D from the axis looking at a tip of radius R (the tip seen
obliquely *and* off the optical axis: both even in ψ). F(0) = 1: at ψ = 0 the image
angle *is* the pitch, read the way ``servoscope track`` reads a static blade
(:func:`servoscope.angle.angle_rad_from_centroids`: counter-clockwise positive, the
lead sticker's side).

The estimator (:func:`fit_passes`), documented in docs/rotor.md:

1. **ψ = 0's place in the picture** (:func:`centre_column`): the stickers' horizontal
   separation is largest at ψ = 0 (the chord is square to the line of sight and
   nearest) and even in ψ; pooled over a blade's passes, the column of the stickers'
   midpoint where it peaks is found by a least-squares fit of
   ``s = a_pass + b·(x − x_c)² + c·(x − x_c)⁴`` (one ``a`` a pass: the pitch changes
   ``cos θ``). Falls back to the picture's centre when the passes do not tell.
2. **The pass's time** (:func:`crossing_time`): when the midpoint crosses x_c, from a
   polynomial t(x) through the pass (the tip crosses the picture at a near-constant
   rate, so the crossing is known to microseconds).
3. **The rotor speed** (:func:`rotor_speed`): each blade's passes one revolution apart;
   the revolutions between each blade's first and last pass over the time between them
   (pooled over the blades): the mean Ω over the passes' span, whatever the drift.
4. **The pitch** (:func:`fit_passes`): ψ_k = 2πΩ(t_k − t_c); each frame's angle
   corrected, θ_k = atan(tan φ_k / F(ψ_k)), and a straight line θ_k = θ0 + θ1·(t_k − t_c)
   fitted through the pass (the pitch's own change through it), one pass of 4-MAD
   outlier rejection; ``k`` common to every pass (it is the camera's geometry) and
   fitted by minimising the passes' pooled residual (:mod:`servoscope.angle.pass_k`; with short
   passes among them, each weighed by what it tells). θ0 is the pitch at ψ = 0.
   Its standard error (:func:`with_pass_error`): the line's intercept error, with the
   crossing time's error through θ1 and ``k``'s error through the correction; and what a
   pass's frames share (the stickers cross the same rows in every frame of a pass, so each
   sticker's vertical sub-pixel bias is frozen through it and does not average): a null
   channel measures it, the stickers' midpoint height at ψ = 0 from pass to pass
   (:func:`midpoint_variance_rad2`), pooled over the blades and shrunk towards a prior where the
   passes are few (:mod:`servoscope.angle.pass_error`).
5. **Short passes** (2–3 frames with both stickers whole, :mod:`servoscope.angle.pass_short`):
   their crossing time from the path the blade's every pass follows, ``k`` common, their own
   rate shrunk towards the passes' pooled slope with its remaining error in theirs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..errors import ServoscopeError
from .pass_k import MIN_PASS_FRAMES, fit_k_mixed, foreshortening
from .pass_table import PassTable

__all__ = ["MIN_PASS_FRAMES", "PassFit", "PassTable", "centre_column", "crossing_time", "fit_pass", "fit_passes",
           "foreshortening", "frame_variance_rad2", "midpoint_variance_rad2", "rotor_speed", "with_pass_error"]

#: Residuals beyond this many robust σ (1.4826·MAD) are dropped from a pass's line (once).
OUTLIER_MADS = 4.0


def centre_column(x_mid_px: NDArray[np.float64], separation_px: NDArray[np.float64],
                  pass_id: NDArray[np.int64]) -> tuple[float, float]:
    """The picture column where the stickers' horizontal separation peaks (ψ = 0), pooled over passes.

    Parameters
    ----------
    x_mid_px : ndarray
        The stickers' midpoint's column in each frame (px).
    separation_px : ndarray
        The lead's column less the trail's (px), same frames.
    pass_id : ndarray of int
        Which pass each frame belongs to (each pass its own level).

    Returns
    -------
    (x_c, stderr) : (float, float)
        px; NaN, NaN when the frames do not span a peak (or are too few).
    """
    x = np.asarray(x_mid_px, dtype=np.float64)
    s = np.abs(np.asarray(separation_px, dtype=np.float64))
    ids = np.unique(pass_id, return_inverse=True)[1]
    n_pass = int(ids.max()) + 1 if ids.size else 0
    if x.size < n_pass + 5 or np.ptp(x) <= 0:
        return math.nan, math.nan
    scale = 0.5 * float(np.ptp(x))

    def rss(xc: float) -> tuple[float, np.ndarray, np.ndarray]:
        u = (x - xc) / scale
        A = np.zeros((x.size, n_pass + 2))
        A[np.arange(x.size), ids] = 1.0
        A[:, n_pass], A[:, n_pass + 1] = u * u, u ** 4
        coef, *_ = np.linalg.lstsq(A, s, rcond=None)
        r = s - A @ coef
        return float(r @ r), coef, A

    lo, hi = float(x.min()), float(x.max())
    grid = np.linspace(lo, hi, 41)
    best = grid[int(np.argmin([rss(g)[0] for g in grid]))]
    from scipy.optimize import minimize_scalar

    step = (hi - lo) / 40.0
    res = minimize_scalar(lambda g: rss(g)[0], bounds=(max(lo, best - step), min(hi, best + step)), method="bounded",
                          options={"xatol": 1e-4})
    xc = float(res.x)
    total, coef, A = rss(xc)
    if not coef[n_pass] < 0:  # no peak: the separation does not fall away from a centre
        return math.nan, math.nan
    # The centre's error from the curvature of the residual (a parabola's three points).
    h = 0.02 * scale
    r0, rp, rm = total, rss(xc + h)[0], rss(xc - h)[0]
    curv = (rp + rm - 2.0 * r0) / (h * h)
    dof = max(x.size - n_pass - 3, 1)
    sigma2 = r0 / dof
    stderr = math.sqrt(2.0 * sigma2 / curv) if curv > 0 else math.nan
    if not lo <= xc <= hi:
        return math.nan, math.nan
    return xc, stderr


def crossing_time(time_s: NDArray[np.float64], x_mid_px: NDArray[np.float64], x_c_px: float) -> tuple[float, float]:
    """When the stickers' midpoint crosses column ``x_c_px``: a polynomial t(x) through the pass, evaluated there.

    Parameters
    ----------
    time_s, x_mid_px : ndarray
        The pass's frames (exposure-middle times, s; the midpoint's column, px).
    x_c_px : float
        The column of ψ = 0 (:func:`centre_column`).

    Returns
    -------
    (t_c, stderr) : (float, float)
        s; the error from the fit's residuals (in time) at x_c.
    """
    t = np.asarray(time_s, dtype=np.float64)
    x = np.asarray(x_mid_px, dtype=np.float64)
    if t.size < 3:
        return math.nan, math.nan
    deg = 3 if t.size >= 8 else (2 if t.size >= 5 else 1)
    t_ref = float(t.mean())
    x_ref, x_scale = float(x.mean()), max(0.5 * float(np.ptp(x)), 1e-9)
    u = (x - x_ref) / x_scale
    A = np.vander(u, deg + 1)
    coef, *_ = np.linalg.lstsq(A, t - t_ref, rcond=None)
    uc = (x_c_px - x_ref) / x_scale
    a = np.vander(np.array([uc]), deg + 1)[0]
    tc = t_ref + float(a @ coef)
    r = (t - t_ref) - A @ coef
    dof = t.size - deg - 1
    if dof <= 0:
        return tc, math.nan
    cov = np.linalg.pinv(A.T @ A) * float(r @ r) / dof
    return tc, math.sqrt(max(float(a @ cov @ a), 0.0))


def rotor_speed(time_s: NDArray[np.float64], blade: NDArray[np.int64],
                time_stderr_s: NDArray[np.float64] | None = None) -> tuple[float, float, NDArray[np.int64]]:
    """The rotor's mean speed over the passes' span: each blade's passes one revolution apart.

    Each pass gets its revolution number (its blade's first pass 0), counted with the
    median interval between the blade's passes and refined by a least-squares rate
    (``n = Ω·t + d_blade``). The speed is then the revolutions between each blade's first
    and last pass over the time between them, pooled over the blades: exactly the mean of
    Ω(t) over that span whatever the engine's drift (a least-squares slope weighs the
    span's middle; under a curved drift the two differ by ~1e-4).

    Parameters
    ----------
    time_s : ndarray
        Each pass's time at ψ = 0 (s).
    blade : ndarray of int
        Each pass's blade.
    time_stderr_s : ndarray, optional
        The times' standard errors: the speed's error from the first and last passes'.
        None: from the least-squares fit's residuals.

    Returns
    -------
    (rev_per_s, stderr, revolution) : (float, float, ndarray of int)
        NaN, NaN when no blade passes twice.
    """
    t = np.asarray(time_s, dtype=np.float64)
    b = np.asarray(blade, dtype=np.int64)
    ok = np.isfinite(t)
    rev = np.zeros(t.size, dtype=np.int64)
    gaps = []
    for k in np.unique(b[ok]):
        tb = np.sort(t[ok & (b == k)])
        gaps.extend(np.diff(tb).tolist())
    if not gaps:
        return math.nan, math.nan, rev
    period = float(np.min(gaps)) if len(gaps) < 3 else float(np.median(gaps))
    blades = np.unique(b[ok])
    rate = 1.0 / period
    for _ in range(2):
        for k in blades:
            sel = ok & (b == k)
            rev[sel] = np.round((t[sel] - t[sel].min()) * rate).astype(np.int64)
        A = np.zeros((int(ok.sum()), 1 + blades.size))
        A[:, 0] = t[ok]
        for j, k in enumerate(blades):
            A[:, 1 + j] = b[ok] == k
        coef, *_ = np.linalg.lstsq(A, rev[ok].astype(np.float64), rcond=None)
        rate = float(coef[0])
    turns = span = var = 0.0
    for k in blades:
        sel = np.flatnonzero(ok & (b == k))
        if sel.size < 2:
            continue
        first, last = sel[np.argmin(t[sel])], sel[np.argmax(t[sel])]
        turns += float(rev[last] - rev[first])
        span += float(t[last] - t[first])
        if time_stderr_s is not None:
            var += float(np.nan_to_num(time_stderr_s[first]) ** 2 + np.nan_to_num(time_stderr_s[last]) ** 2)
    speed = turns / span
    if time_stderr_s is not None:
        return speed, speed * math.sqrt(var) / span, rev
    r = rev[ok] - A @ coef
    dof = int(ok.sum()) - A.shape[1]
    if dof <= 0:
        return speed, math.nan, rev
    cov = np.linalg.pinv(A.T @ A) * float(r @ r) / dof
    return speed, math.sqrt(max(float(cov[0, 0]), 0.0)), rev


@dataclass(frozen=True)
class PassFit:
    """One pass's pitch at ψ = 0 and how it was read.

    Attributes
    ----------
    time_s : float
        When the blade pointed at the camera (ψ = 0), the video's clock (s).
    pitch_rad, pitch_stderr_rad : float
        The pitch then, and its standard error (rad).
    pitch_rate_rad_s : float
        The pitch's own change through the pass (rad/s).
    azimuth_from_rad, azimuth_to_rad : float
        ψ at the first and last frame used.
    frames_used : int
        Frames in the line (both stickers whole, outliers out).
    residual_rms_rad : float
        RMS of the line's residuals (rad).
    line_stderr_rad : float
        The line's own intercept error, from its residuals alone (rad).
    """

    time_s: float
    pitch_rad: float
    pitch_stderr_rad: float
    pitch_rate_rad_s: float
    azimuth_from_rad: float
    azimuth_to_rad: float
    frames_used: int
    residual_rms_rad: float
    line_stderr_rad: float = math.nan


def _line(tau: np.ndarray, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Straight line through (tau, theta) with one round of 4-MAD rejection: (coef, cov, residual), kept mask last."""
    keep = np.ones(tau.size, dtype=bool)
    for _ in range(2):
        A = np.c_[np.ones(int(keep.sum())), tau[keep]]
        coef, *_ = np.linalg.lstsq(A, theta[keep], rcond=None)
        r_all = theta - (coef[0] + coef[1] * tau)
        mad = 1.4826 * float(np.median(np.abs(r_all[keep] - np.median(r_all[keep]))))
        new = np.abs(r_all) <= OUTLIER_MADS * max(mad, 1e-12) if mad > 0 else keep
        if keep.sum() - (new & keep).sum() == 0 or new.sum() < MIN_PASS_FRAMES:
            break
        keep = new
    A = np.c_[np.ones(int(keep.sum())), tau[keep]]
    coef, *_ = np.linalg.lstsq(A, theta[keep], rcond=None)
    r = theta[keep] - A @ coef
    dof = max(int(keep.sum()) - 2, 1)
    cov = np.linalg.inv(A.T @ A) * float(r @ r) / dof
    return coef, cov, r, keep


def fit_pass(time_s: NDArray[np.float64], angle_rad: NDArray[np.float64], t_c_s: float, rev_per_s: float, k: float,
             *, t_c_stderr_s: float = 0.0, k_stderr: float = 0.0) -> PassFit:
    """One pass's pitch at ψ = 0: each frame's angle corrected for F(ψ), a line through time.

    Parameters
    ----------
    time_s : ndarray
        The frames' exposure-middle times (s), both stickers whole.
    angle_rad : ndarray
        Each frame's image angle of the trail→lead line (rad,
        :func:`~servoscope.angle.angle_rad_from_centroids`).
    t_c_s : float
        The pass's ψ = 0 time (:func:`crossing_time`).
    rev_per_s : float
        The rotor's speed (ψ = 2π·rev_per_s·(t − t_c)).
    k : float
        The foreshortening's curvature (:func:`foreshortening`).
    t_c_stderr_s, k_stderr : float
        Their standard errors, carried into the pitch's.

    Returns
    -------
    PassFit
    """
    t = np.asarray(time_s, dtype=np.float64)
    phi = np.asarray(angle_rad, dtype=np.float64)
    if t.size < MIN_PASS_FRAMES:
        raise ServoscopeError(f"a pass needs {MIN_PASS_FRAMES} frames with both stickers whole, this one has {t.size}")
    tau = t - t_c_s
    psi = 2.0 * math.pi * rev_per_s * tau
    theta = np.arctan(np.tan(phi) / foreshortening(psi, k))
    coef, cov, r, keep = _line(tau, theta)
    var = float(cov[0, 0]) + (coef[1] * t_c_stderr_s) ** 2
    if k_stderr > 0:
        # d θ_k / d k through the correction, averaged as the intercept averages the frames.
        h = 1e-4 * max(abs(k), 1.0)
        theta_h = np.arctan(np.tan(phi) / foreshortening(psi, k + h))
        coef_h = np.linalg.lstsq(np.c_[np.ones(int(keep.sum())), tau[keep]], theta_h[keep], rcond=None)[0]
        var += ((coef_h[0] - coef[0]) / h * k_stderr) ** 2
    return PassFit(float(t_c_s), float(coef[0]), math.sqrt(var), float(coef[1]), float(psi[keep].min()),
                   float(psi[keep].max()), int(keep.sum()), float(np.sqrt(np.mean(r * r))),
                   math.sqrt(float(cov[0, 0])))


def fit_passes(passes: list[tuple[NDArray[np.float64], NDArray[np.float64]]], t_c_s: NDArray[np.float64],
               rev_per_s: float, *, t_c_stderr_s: NDArray[np.float64] | None = None,
               k: float | None = None, shared_error: bool = True, k_min_frames: int = MIN_PASS_FRAMES,
               blade: NDArray[np.int64] | None = None,
               k_stderr: float = math.nan) -> tuple[list[PassFit], float, float]:
    """Every pass's pitch at ψ = 0, the foreshortening's ``k`` fitted common to them.

    Parameters
    ----------
    passes : list of (time_s, angle_rad)
        Each pass's frames with both stickers whole.
    t_c_s : ndarray
        Each pass's ψ = 0 time.
    rev_per_s : float
    t_c_stderr_s : ndarray, optional
    k : float, optional
        Hold ``k`` (e.g. from the camera's distance and the tip's radius); None: fitted.
    k_stderr : float
        A held ``k``'s standard error, carried into each pass's pitch error; NaN: none stated.
    shared_error : bool
        Add one frame's residual variance (pooled over the passes) to each pass's pitch
        variance: the frames of a pass share their centroid errors (True, the default; False
        gives the line's own error, for independent frames).
    k_min_frames : int
        Passes of at least this many frames (and fewer than :data:`MIN_PASS_FRAMES`) tell ``k``
        too, each by its frames' mean (its own rate held at 0: odd in ψ, it does not bias the
        even correction); their pitch is :func:`servoscope.angle.pass_short.fit_short_pass`'s
        (None here). With short passes among them ``k`` is :func:`~servoscope.angle.pass_k.fit_k_mixed`'s
        (each short pass weighed by what it tells, its own rate a random effect).
    blade : ndarray of int, optional
        Each pass's blade (its pitch offset out of the rate's spread, :func:`~servoscope.angle.pass_k.fit_k_mixed`).

    Returns
    -------
    (fits, k, k_stderr) : (list of PassFit, float, float)
        ``k_stderr`` NaN when not determined (then ``k`` is ½, the orthographic limit) or held without one.
    """
    t_c = np.asarray(t_c_s, dtype=np.float64)
    err = np.zeros(t_c.size) if t_c_stderr_s is None else np.nan_to_num(np.asarray(t_c_stderr_s, dtype=float))
    usable = [i for i, (t, _) in enumerate(passes) if np.size(t) >= MIN_PASS_FRAMES and np.isfinite(t_c[i])]
    telling = [i for i, (t, _) in enumerate(passes)
               if np.size(t) >= min(k_min_frames, MIN_PASS_FRAMES) and np.isfinite(t_c[i])]
    if k is None:
        k, k_stderr = fit_k_mixed([passes[i] for i in telling], t_c[telling], rev_per_s,
                                  None if blade is None else np.asarray(blade)[telling])
    fits = [fit_pass(*passes[i], t_c[i], rev_per_s, k, t_c_stderr_s=err[i],
                     k_stderr=0.0 if not math.isfinite(k_stderr) else k_stderr) for i in usable]
    if shared_error and fits:
        fits = with_pass_error(fits, frame_variance_rad2(fits), add_line=True)
    out: list[PassFit | None] = [None] * len(passes)
    for i, f in zip(usable, fits):
        out[i] = f
    return out, k, k_stderr  # type: ignore[return-value]


def frame_variance_rad2(fits: list[PassFit]) -> float:
    """One frame's residual variance about its pass's line, pooled over the passes (rad²).

    A pass's frames share their errors (the stickers cross the same rows in every frame of a
    pass, so each sticker's vertical sub-pixel bias is frozen through it: on the twin's colour
    footage the pass-to-pass error's SD is about one frame's, not 1/√n of it): the fallback
    floor of a pass's error when :func:`midpoint_variance_rad2` has too few passes.
    """
    ss = sum(f.residual_rms_rad ** 2 * f.frames_used for f in fits)
    dof = sum(f.frames_used - 2 for f in fits)
    return ss / dof if dof > 0 else 0.0


#: Fewest passes of a blade for the midpoint's null channel (:func:`midpoint_variance_rad2`).
MIN_NULL_PASSES = 5


def midpoint_variance_rad2(pitch_rad: NDArray[np.float64], midpoint_y_px: NDArray[np.float64],
                           separation_px: float) -> tuple[float, int]:
    """A pass's pitch error variance from a null channel: the stickers' midpoint height at ψ = 0, pass to pass.

    The pitch reads the stickers' vertical *difference*; their vertical *mean* at ψ = 0
    (each pass's intercept, fitted through the same frames the same way) carries the same
    errors, shared by the pass's frames or not, and otherwise moves only with the pitch
    (the midpoint turns about the pitch axis): regressed on the passes' pitches, its
    residual variance v is that error's. With the two stickers' errors alike and
    independent, the height's error is uncorrelated with the pitch's, and
    v = var_θ·(L²/4 + B²) (L the stickers' separation, B the height's slope against the
    pitch, px/rad, through which the pitch's own error enters). A blade that heaves or flaps
    from pass to pass makes it larger (conservative).

    Parameters
    ----------
    pitch_rad : ndarray
        One blade's passes' pitches at ψ = 0.
    midpoint_y_px : ndarray
        The same passes' midpoint heights at ψ = 0 (px).
    separation_px : float
        The stickers' separation (px).

    Returns
    -------
    (variance_rad2, dof) : (float, int)
        NaN, 0 with fewer than :data:`MIN_NULL_PASSES` passes.
    """
    th = np.asarray(pitch_rad, dtype=np.float64)
    y = np.asarray(midpoint_y_px, dtype=np.float64)
    ok = np.isfinite(th) & np.isfinite(y)
    if ok.sum() < MIN_NULL_PASSES or not separation_px > 0:
        return math.nan, 0
    A = np.c_[np.ones(int(ok.sum())), th[ok] - th[ok].mean()]
    coef, *_ = np.linalg.lstsq(A, y[ok], rcond=None)
    r = y[ok] - A @ coef
    dof = int(ok.sum()) - 2
    # The residual is the height's error less B times the pitch's (B the fitted slope, px/rad): with the
    # stickers' errors alike and independent the two are uncorrelated, var_r = var_θ·(L²/4 + B²).
    return float(r @ r) / dof / (0.25 * separation_px ** 2 + float(coef[1]) ** 2), dof


def with_pass_error(fits: list[PassFit], variance_rad2: float, *, add_line: bool) -> list[PassFit]:
    """Each pass's pitch error with the error its frames share.

    ``pitch_stderr_rad``² = line² + variance (``add_line``: the variance is the shared part
    alone, :func:`frame_variance_rad2`) or max(line², variance) (the variance is the whole
    error, :func:`midpoint_variance_rad2`), plus the crossing time's and k's parts.
    """
    out = []
    for f in fits:
        line2 = f.line_stderr_rad ** 2 if math.isfinite(f.line_stderr_rad) else f.pitch_stderr_rad ** 2
        rest = max(f.pitch_stderr_rad ** 2 - line2, 0.0)
        total = line2 + variance_rad2 if add_line else max(line2, variance_rad2)
        out.append(replace(f, pitch_stderr_rad=math.sqrt(total + rest)))
    return out
