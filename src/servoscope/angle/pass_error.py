"""A pass's pitch error with what its frames share: the midpoint's null channel, pooled over the blades.

The stickers cross the same rows in every frame of a pass, so each sticker's vertical sub-pixel
bias is frozen through it and does not average (colour footage: a pass's error about one
frame's); on raw monochrome footage the frames' errors are mostly their own and do average.
Which it is, the footage tells through a null channel (:func:`~servoscope.angle.passes.midpoint_variance_rad2`):
the stickers' midpoint height at ψ = 0, read through the same frames the same way as the pitch.

The height must be read *exactly* the way the pitch was, or the null channel measures the
reading's own error. A short pass's pitch (:func:`~servoscope.angle.pass_short.fit_short_pass`) is its
frames' mean carried to ψ = 0 by its own pitch rate; the midpoint moves with the pitch
(B ≈ 17 px/rad on the twin: it sits off the pitch axis), so its height is carried by B times that
rate too (:func:`midpoint_heights_px`). Carried by the blade's pooled slope alone (before), a short
pass's height took B·θ1·(t̄ − t_c) of the pitch's own rate (θ1 up to ~2 rad/s, t̄ − t_c up to
0.25 ms: ~0.01 px, against a monochrome pass's ~0.002 px): the null channel read a monochrome
pass's error 1.5–3× too large on clips of short passes (stated errors ~2× the truth's, z RMS 0.44–0.66).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from .pass_k import MIN_PASS_FRAMES
from .passes import MIN_NULL_PASSES, PassFit, midpoint_variance_rad2, with_pass_error

__all__ = ["FLOOR_PRIOR_DOF", "midpoint_heights_px", "pooled_frame_variance_rad2", "shared_pass_errors",
           "two_frame_variance_rad2"]

#: Degrees of freedom the frames' floor weighs with against the midpoint's null channel.
FLOOR_PRIOR_DOF = 4


def pooled_frame_variance_rad2(fits: list[PassFit], fallback_rad2: float = 0.0) -> float:
    """One frame's residual variance about its pass's own line, pooled over the passes of 3 frames or more.

    ``fallback_rad2``: what is used when those leave fewer than 3 degrees of freedom (every pass of 2
    frames, whose line leaves no residual): :func:`two_frame_variance_rad2`.
    """
    ss = sum(f.residual_rms_rad ** 2 * f.frames_used for f in fits)
    dof = sum(max(f.frames_used - 2, 0) for f in fits)
    if dof >= 3 or not fallback_rad2 > 0:
        return ss / dof if dof > 0 else fallback_rad2
    return fallback_rad2


def two_frame_variance_rad2(pairs: list[tuple[float, float]], rate_prior: float, spread: float) -> float:
    """One frame's variance from passes of 2 frames: their difference, rate·Δτ + e₂ − e₁, about the prior rate.

    E[(d − c·Δτ)²] = s²·Δτ² + 2σ² (c the rate prior, s its spread): σ² from the mean.
    """
    if not pairs:
        return 0.0
    terms = [((d - rate_prior * dt) ** 2 - (spread * dt) ** 2) / 2.0 for d, dt in pairs]
    return max(float(np.mean(terms)), 0.0)


def midpoint_heights_px(tau_s: list[NDArray[np.float64]], midpoint_y_px: list[NDArray[np.float64]],
                        pitch_rad: NDArray[np.float64], pitch_rate_rad_s: NDArray[np.float64],
                        *, rounds: int = 3) -> tuple[NDArray[np.float64], float]:
    """One blade's passes' midpoint heights at ψ = 0, each read the way its pitch was.

    A pass of :data:`MIN_PASS_FRAMES` frames or more: its own line's intercept (as its pitch). A
    short pass: its frames' mean carried to ψ = 0 by the blade's pooled height slope plus
    B·(its pitch rate − the passes' mean rate), B the heights' slope against the pitches (px/rad),
    read again each round.

    Parameters
    ----------
    tau_s, midpoint_y_px : list of ndarray
        Each pass's frames' times from its ψ = 0 (s) and the stickers' midpoint's height (px).
    pitch_rad, pitch_rate_rad_s : ndarray
        Each pass's pitch at ψ = 0 and its own rate through the pass (as fitted).
    rounds : int

    Returns
    -------
    (heights_px, slope_px_rad) : (ndarray, float)
    """
    rates = np.asarray(pitch_rate_rad_s, dtype=np.float64)
    pitch = np.asarray(pitch_rad, dtype=np.float64)
    rate_mean = float(np.mean(rates)) if rates.size else 0.0
    d = [np.asarray(t, dtype=np.float64) - np.mean(t) for t in tau_s]
    sxx = sum(float(x @ x) for x in d)
    heights = np.array([float(np.polyfit(t, y, 1)[1]) if np.size(t) >= MIN_PASS_FRAMES else float(np.mean(y))
                        for t, y in zip(tau_s, midpoint_y_px)])
    slope_b = 0.0
    for _ in range(rounds):
        # The height's slope through a pass pooled over the blade's passes (each about its mean), the pitch's
        # own rates' part (B·rate) taken out first: what is left is the path's, common to the passes.
        slope = (sum(float(x @ (np.asarray(y) - np.mean(y) - slope_b * (r - rate_mean) * x))
                     for x, y, r in zip(d, midpoint_y_px, rates)) / sxx if sxx > 0 else 0.0)
        heights = np.array([float(np.polyfit(t, y, 1)[1]) if np.size(t) >= MIN_PASS_FRAMES
                            else float(np.mean(y) - (slope + slope_b * (r - rate_mean)) * np.mean(t))
                            for t, y, r in zip(tau_s, midpoint_y_px, rates)])
        ok = np.isfinite(heights) & np.isfinite(pitch)
        if ok.sum() < 3 or np.ptp(pitch[ok]) <= 0:
            break
        slope_b = float(np.polyfit(pitch[ok], heights[ok], 1)[0])
    return heights, slope_b


def shared_pass_errors(fits: list[PassFit | None], blade: list[int], frames: list[NDArray[np.int64]],
                       lead_xy_px: NDArray[np.float64], trail_xy_px: NDArray[np.float64], clock_s: NDArray[np.float64],
                       warnings: list[str], fallback_rad2: float = 0.0, *,
                       frames_share_errors: bool = True) -> list[PassFit | None]:
    """Each pass's pitch error with what its frames share: the midpoint null channel, pooled over the blades.

    Each blade's passes give the midpoint's residual variance (:func:`midpoint_variance_rad2`, the
    heights from :func:`midpoint_heights_px`); they are pooled over the blades (one camera, alike
    stickers) and shrunk towards a prior with the weight of :data:`FLOOR_PRIOR_DOF` degrees of freedom,
    so that a short clip's few passes do not make a small error from a lucky variance: one frame's
    variance (:func:`pooled_frame_variance_rad2`) when the frames share their errors (colour), that over
    √n̄ when they are mostly their own (raw monochrome). A short pass (fewer than :data:`MIN_PASS_FRAMES` whole
    frames, its pitch the frames' mean) adds the frames' own scatter its fewer frames leave: one
    frame's variance times 1/n less 1/n̄ (n̄ the passes' harmonic mean frames, what the null
    channel's variance is of).

    Parameters
    ----------
    fits : list of PassFit or None
        Each pass's fit (None: left out).
    blade : list of int
        Each pass's blade.
    frames : list of ndarray of int
        Each pass's frames with both stickers whole (indices into the sightings).
    lead_xy_px, trail_xy_px : ndarray
        The stickers' centroids, (frames, blades, 2) (px).
    clock_s : ndarray
        Each frame's exposure-middle time (s).
    warnings : list of str
        Appended to when the null channel has few degrees of freedom.
    fallback_rad2 : float
        One frame's variance when no pass has 3 frames (:func:`two_frame_variance_rad2`).
    frames_share_errors : bool
        The prior's kind: True for colour footage (a pass's frames share the stickers' sub-pixel bias),
        False for raw monochrome (their errors mostly their own).

    Returns
    -------
    list of PassFit or None
    """
    done = [f for f in fits if f is not None]
    floor = pooled_frame_variance_rad2(done, fallback_rad2)
    total, dof_total = 0.0, 0
    for b in sorted(set(blade)):
        mine = [j for j, bj in enumerate(blade) if bj == b and fits[j] is not None]
        taus = [clock_s[frames[j]] - fits[j].time_s for j in mine]
        ymids = [0.5 * (lead_xy_px[frames[j], b, 1] + trail_xy_px[frames[j], b, 1]) for j in mine]
        seps = [float(np.median(np.hypot(*(lead_xy_px[frames[j], b] - trail_xy_px[frames[j], b]).T))) for j in mine]
        pitches = np.array([fits[j].pitch_rad for j in mine])
        heights, _ = midpoint_heights_px(taus, ymids, pitches, np.array([fits[j].pitch_rate_rad_s for j in mine]))
        var, dof = midpoint_variance_rad2(pitches, heights, float(np.median(seps)) if seps else math.nan)
        if dof:
            total += var * dof
            dof_total += dof
    n_ref = len(done) / sum(1.0 / f.frames_used for f in done) if done else 1.0
    # The prior's target: a pass's error lies between its frames' own scatter averaged (floor/n̄, each
    # frame's error its own) and one frame's (floor, an error the pass's frames share). Colour: one frame's
    # (the stickers' frozen sub-pixel bias, measured, session 9). Raw monochrome: the frames' errors are
    # mostly their own (test_rotor_mono.py's clip: a pass's error 0.0019° RMS, one frame's 0.0051°, n̄ 7),
    # so their geometric mean: the floor target stated its errors ~2× too large (z RMS 0.53).
    prior = floor if frames_share_errors else floor / math.sqrt(n_ref)
    var = (total + FLOOR_PRIOR_DOF * prior) / (dof_total + FLOOR_PRIOR_DOF)
    if dof_total < FLOOR_PRIOR_DOF:
        warnings.append(f"{len(done)} passes: the pitch's error rests mostly on the frames' scatter (the midpoint's "
                        f"check needs {MIN_NULL_PASSES} passes of a blade, and more to be sure)")
    fixed = iter(with_pass_error(done, var, add_line=False))
    out: list[PassFit | None] = []
    for f in fits:
        if f is None:
            out.append(None)
            continue
        g = next(fixed)
        if not math.isfinite(f.line_stderr_rad):  # a short pass: its own parts (its rate, k) and the frames'
            extra = floor * max(1.0 / f.frames_used - 1.0 / n_ref, 0.0)
            g = replace(f, pitch_stderr_rad=math.sqrt(var + extra + f.pitch_stderr_rad ** 2))
        out.append(g)
    return out
