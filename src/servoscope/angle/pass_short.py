"""Short passes: a blade seen whole in 2 or 3 frames only (a fast rotor at 2,000 frames/s), read with the others' help.

At 2,000 frames/s a 0.3 m tip at 25–30 rev/s crosses a 320-px picture in 4–5 frames, 2–3
of them with both stickers whole: too few for a pass's own crossing time and its own
straight line (:func:`servoscope.angle.passes.fit_pass` needs 4). What the camera's
geometry fixes is common to the passes, so a short pass borrows it (docs/rotor.md):

* **its crossing time** (:func:`pooled_crossing_times`): the stickers' midpoint crosses the
  picture along the same path every pass (the tip's orbit through a fixed camera), so
  ``t = t_c,pass + P(x − x_c)``, one polynomial ``P`` (no constant) common to a blade's
  passes and one ``t_c`` a pass, is linear least squares: a pass of 2 frames gives its
  ``t_c`` with the path learnt from every pass of the blade;
* **the foreshortening** ``k``: common (fitted over every pass, or from the rig's geometry);
* **the pitch's own rate** θ1 through the pass (:func:`fit_short_pass`): the frames' own
  slope shrunk towards 0 by the rate's spread over the clip (:func:`pitch_rate_spread_rad_s`,
  from the passes' pitches) against the slope's noise, the pitch read as the mean of its
  frames' corrected angles at their mean time t̄ carried to t_c by it, the rate's remaining
  error times ``t̄ − t_c`` (≤ half a frame interval, ≤ 0.25 ms at 2,000 frames/s) in its error.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .pass_k import pitch_rate_spread_rad_s
from .passes import PassFit, foreshortening

__all__ = ["MIN_SHORT_FRAMES", "fit_short_pass", "pitch_rate_spread_rad_s", "pooled_crossing_times",
           "pooled_slope_rad_s"]

#: Fewest frames with both stickers whole for a short pass's pitch (fewer: the pass is left out).
MIN_SHORT_FRAMES = 2


def pooled_crossing_times(time_s: NDArray[np.float64], x_mid_px: NDArray[np.float64], pass_id: NDArray[np.int64],
                          x_c_px: float, *, degree: int = 3) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Each pass's time at column ``x_c_px`` from one path common to the passes: ``t = t_c,pass + P(x − x_c)``.

    Parameters
    ----------
    time_s, x_mid_px : ndarray
        Every pass's frames (exposure-middle times, s; the stickers' midpoint's column, px).
    pass_id : ndarray of int
        Which pass each frame belongs to (0 … n − 1).
    x_c_px : float
        The column of ψ = 0 (:func:`~servoscope.angle.passes.centre_column`).
    degree : int
        ``P``'s degree (lowered when the frames are too few to tell it).

    Returns
    -------
    (t_c, stderr) : (ndarray, ndarray)
        One a pass (s); the errors from the pooled residuals (NaN when no degree of freedom is left).
    """
    t = np.asarray(time_s, dtype=np.float64)
    x = np.asarray(x_mid_px, dtype=np.float64)
    ids = np.asarray(pass_id, dtype=np.int64)
    n_pass = int(ids.max()) + 1 if ids.size else 0
    if n_pass == 0:
        return np.array([]), np.array([])
    scale = max(0.5 * float(np.ptp(x)), 1e-9)
    u = (x - x_c_px) / scale
    # A pass's own times set its t_c; the path's shape needs frames beyond one a pass.
    degree = int(max(1, min(degree, t.size - n_pass - 1)))
    A = np.zeros((t.size, n_pass + degree))
    A[np.arange(t.size), ids] = 1.0
    for d in range(1, degree + 1):
        A[:, n_pass + d - 1] = u ** d
    t_ref = float(t.mean())
    coef, *_ = np.linalg.lstsq(A, t - t_ref, rcond=None)
    r = (t - t_ref) - A @ coef
    dof = t.size - A.shape[1]
    tc = t_ref + coef[:n_pass]
    if dof <= 0:
        return tc, np.full(n_pass, math.nan)
    cov = np.linalg.pinv(A.T @ A) * float(r @ r) / dof
    return tc, np.sqrt(np.clip(np.diag(cov)[:n_pass], 0.0, None))


def pooled_slope_rad_s(passes: list[tuple[NDArray[np.float64], NDArray[np.float64]]], t_c_s: NDArray[np.float64],
                       rev_per_s: float, k: float) -> tuple[float, float]:
    """The corrected angle's slope through the passes, pooled (each pass about its own mean), and its variance.

    The pitch's own rates average out over a dwell; what is left is the slope every pass
    shares (a short pass's rate prior, :func:`fit_short_pass`).

    Returns
    -------
    (slope, variance) : (float, float)
        rad/s and (rad/s)²; 0, 0 when the passes span no time.
    """
    num = sxx_total = 0.0
    slopes, weights = [], []
    for (t, phi), tc in zip(passes, t_c_s):
        tau = np.asarray(t, dtype=np.float64) - tc
        theta = np.arctan(np.tan(np.asarray(phi, dtype=np.float64)) / foreshortening(2 * math.pi * rev_per_s * tau, k))
        d = tau - tau.mean()
        sxx = float(d @ d)
        if sxx <= 0:
            continue
        num += float(d @ (theta - theta.mean()))
        sxx_total += sxx
        slopes.append(float(d @ (theta - theta.mean())) / sxx)
        weights.append(sxx)
    if sxx_total <= 0 or len(slopes) < 2:
        return 0.0, 0.0
    slope = num / sxx_total
    w = np.asarray(weights)
    # Its variance from the passes' own slopes' scatter about it (their rates and their noise alike).
    resid = np.asarray(slopes) - slope
    var = float(np.sum(w * w * resid * resid)) / sxx_total ** 2 * len(slopes) / (len(slopes) - 1)
    return slope, var


def fit_short_pass(time_s: NDArray[np.float64], angle_rad: NDArray[np.float64], t_c_s: float, rev_per_s: float,
                   k: float, *, rate_spread_rad_s: float = 0.0, frame_variance_rad2: float = math.inf,
                   rate_prior_rad_s: float = 0.0, rate_prior_var: float = 0.0, t_c_stderr_s: float = 0.0,
                   k_stderr: float = 0.0) -> PassFit:
    """A pass of few frames: its frames' corrected angles at their mean time, the pitch's own rate shrunk towards 0.

    The rate through the pass is the frames' own slope shrunk towards 0 by what is known of
    it: the slope's noise (one frame's variance over Σ(τ − τ̄)²) against the rate's spread
    over the clip, ``rate = slope·s²/(s² + v)``, its error variance ``s²·v/(s² + v)``. On
    raw monochrome footage (frames good to 0.003°) the slope is kept; on H.264 (0.02°, two
    frames 0.5 ms apart) it is mostly held at 0. The pitch at ψ = 0 is the frames' mean
    less the rate times ``t̄ − t_c`` (≤ half a frame interval), the rate's error entering
    through that lever.

    Parameters
    ----------
    time_s, angle_rad : ndarray
        The frames with both stickers whole (s; the trail→lead image angle, rad).
    t_c_s : float
        The pass's ψ = 0 time (:func:`pooled_crossing_times`).
    rev_per_s, k : float
        The rotor's speed and the foreshortening's curvature (common to the passes).
    rate_spread_rad_s : float
        The pitch rate's RMS (:func:`pitch_rate_spread_rad_s`); 0 holds the rate at 0.
    frame_variance_rad2 : float
        One frame's error variance about its pass's line (rad²); inf holds the rate at the prior.
    rate_prior_rad_s, rate_prior_var : float
        What the rate is shrunk towards, and that value's own error variance: the passes' pooled
        slope (:func:`pooled_slope_rad_s`). Not 0 on the twin: ψ = 0 read 50–80 µs late makes the
        even correction slightly odd through the pass, ~0.003° a degree of ψ, a slope common to
        every pass that a long pass's line takes up.
    t_c_stderr_s, k_stderr : float
        Their errors (t_c's enters through the rate's spread too).

    Returns
    -------
    PassFit
        ``line_stderr_rad`` NaN (the frames do not tell their own scatter: the pooled one does,
        :func:`~servoscope.pipeline.rotor.track_passes`); ``pitch_stderr_rad`` the rate's and
        k's parts alone; ``residual_rms_rad`` about the frames' own line (0 for two frames).
    """
    t = np.asarray(time_s, dtype=np.float64)
    phi = np.asarray(angle_rad, dtype=np.float64)
    tau = t - t_c_s
    psi = 2.0 * math.pi * rev_per_s * tau
    theta = np.arctan(np.tan(phi) / foreshortening(psi, k))
    lever = float(tau.mean())
    dtau = tau - lever
    sxx = float(dtau @ dtau)
    s2 = rate_spread_rad_s ** 2
    rate, rate_var, w = rate_prior_rad_s, s2, 0.0
    if sxx > 0 and s2 > 0 and math.isfinite(frame_variance_rad2):
        v = frame_variance_rad2 / sxx
        own = float(dtau @ (theta - theta.mean())) / sxx
        w = s2 / (s2 + v)
        rate = rate_prior_rad_s + (own - rate_prior_rad_s) * w
        rate_var = s2 * v / (s2 + v)
    rate_var += (1.0 - w) ** 2 * rate_prior_var  # the prior's own error, as much as it is leant on
    theta0 = float(theta.mean()) - rate * lever
    var = rate_var * lever ** 2 + s2 * t_c_stderr_s ** 2
    if k_stderr > 0:
        h = 1e-4 * max(abs(k), 1.0)
        theta_h = np.arctan(np.tan(phi) / foreshortening(psi, k + h))
        var += ((float(theta_h.mean()) - float(theta.mean())) / h * k_stderr) ** 2
    # The residual about the frames' own line (0 for two frames): one frame's scatter, the rate taken out.
    own_line = float(dtau @ (theta - theta.mean())) / sxx if sxx > 0 else 0.0
    r = theta - theta.mean() - own_line * dtau
    return PassFit(float(t_c_s), theta0, math.sqrt(var), rate, float(psi.min()), float(psi.max()), int(t.size),
                   float(np.sqrt(np.mean(r * r))), math.nan)
