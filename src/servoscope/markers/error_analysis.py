"""Angle error from centroid error, for the actual footage (the paper's Fig. 6).

The blade angle comes from two centroids a distance ``L`` apart. A centroid
error ``δ`` across the joining line turns it by ``atan(δ / L)``: the paper
bounds this *quantization error* at 0.1° for ``L = 600 px`` and ``δ = 1 px``
(a binary threshold moves a centroid by up to a pixel). With independent
errors of standard deviation ``σ_lead``, ``σ_trail`` per coordinate, the
statistical angle error is ``σθ = √(σ_lead² + σ_trail²) / L``.

:func:`angle_error_analysis` evaluates both for a :class:`Track`, plus an
empirical angle noise from the track itself; :func:`plot_angle_error` draws
the paper's figure with the footage's operating point.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ServoscopeError

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.figure import Figure

__all__ = ["angle_error_analysis", "common_shake_px", "plot_angle_error", "rigid_motion_null", "worst_case_angle_error_rad"]


class TrackLike(Protocol):
    """What the analysis reads of a :class:`~servoscope.markers.track.Track` (which imports this module)."""

    lead_xy_px: np.ndarray
    trail_xy_px: np.ndarray
    lead_sigma_px: np.ndarray
    trail_sigma_px: np.ndarray
    angle_rad: np.ndarray
    valid: np.ndarray


#: Frames the null channel's RMS needs to be a usable estimate (±16 % at 20 independent frames).
_MIN_NULL_FRAMES = 20


def worst_case_angle_error_rad(separation_px: np.ndarray | float, centroid_error_px: float = 1.0) -> np.ndarray:
    """The paper's bound: ``atan(δ / L)`` (rad) for a centroid error δ (px) at separation L (px)."""
    return np.arctan(centroid_error_px / np.asarray(separation_px, dtype=np.float64))


def _empirical_noise_rad(angle_rad: np.ndarray) -> float | None:
    """Angle noise from second differences of consecutive valid frames (rad).

    For white noise of standard deviation σ, Δ²θ has variance 6σ²; the
    median absolute value (÷ 0.6745) keeps fast motion in a minority of
    frames from counting. An upper bound where the blade moves fast all along.
    """
    a = np.asarray(angle_rad, dtype=np.float64)
    ok = np.isfinite(a)
    runs = np.flatnonzero(ok[:-2] & ok[1:-1] & ok[2:])
    if runs.size < 5:
        return None
    d2 = a[runs] - 2.0 * a[runs + 1] + a[runs + 2]
    return float(np.median(np.abs(d2)) / 0.6745 / math.sqrt(6.0))


def rigid_motion_null(
    lead_xy_px: ArrayLike, trail_xy_px: ArrayLike, valid: ArrayLike | None = None
) -> NDArray[np.float64]:
    """A null channel of two markers on a rigid blade, in angle units (rad).

    A rigid blade turning about a fixed axis moves each marker across the
    line joining them by ``r_i * sin(theta)`` (``r_i``: its signed distance
    from the axis), so ``d_a - rho * d_b`` with ``rho = r_a / r_b`` holds no
    motion at all: whatever the blade does, linear or not, cancels. What is
    left are the two markers' own measurement errors, among them those
    locked to the motion (pixel locking, codec artefacts), which repeat at
    the harmonics of a sine dwell. ``rho`` is the least-squares slope of
    ``d_a`` on ``d_b`` over the valid frames (the marker that moves more as
    ``b``, so ``|rho| <= 1``). Scaled by ``sqrt(2 / (1 + rho**2)) / L``
    (``L``: the markers' mean separation), the channel has, for independent
    errors of equal size in both markers, the size of the angle's error
    ``(e_a - e_b) / L``.

    Parameters
    ----------
    lead_xy_px, trail_xy_px : array_like, shape (n, 2)
        Marker centroids (px); NaN where not found.
    valid : array_like of bool, shape (n,), optional
        Frames to use (default: where both are finite).

    Returns
    -------
    numpy.ndarray, shape (n,)
        The null channel in rad (mean zero), NaN where invalid; all NaN
        when fewer than 3 frames are usable or the markers do not move.
    """
    lead = np.asarray(lead_xy_px, dtype=float).reshape(-1, 2)
    trail = np.asarray(trail_xy_px, dtype=float).reshape(-1, 2)
    if lead.shape != trail.shape:
        raise ServoscopeError("rigid_motion_null: lead and trail have different shapes")
    ok = np.all(np.isfinite(lead), axis=1) & np.all(np.isfinite(trail), axis=1)
    if valid is not None:
        ok &= np.asarray(valid, dtype=bool).ravel()
    out = np.full(lead.shape[0], np.nan)
    if np.count_nonzero(ok) < 3:
        return out
    line = np.mean(lead[ok] - trail[ok], axis=0)
    sep = math.hypot(float(line[0]), float(line[1]))
    if not sep > 0:
        return out
    normal = np.array([-line[1], line[0]]) / sep
    da, db = lead @ normal, trail @ normal
    va, vb = float(np.var(da[ok])), float(np.var(db[ok]))
    if va > vb:
        da, db, va, vb = db, da, vb, va
    if not vb > 0:
        return out
    xa, xb = da[ok] - da[ok].mean(), db[ok] - db[ok].mean()
    rho = float(xa @ xb) / float(xb @ xb)
    out[ok] = (xa - rho * xb) * math.sqrt(2.0 / (1.0 + rho * rho)) / sep
    return out


#: Camera shake is declared when the markers' common motion along their line varies by more than
#: this many times what their own errors explain (variance ratio; 0.5–1.2 measured without shake,
#: 6 at 0.05 px RMS of shake, ~200 at 0.3 px).
SHAKE_VARIANCE_RATIO = 4.0


def common_shake_px(lead_xy_px: ArrayLike, trail_xy_px: ArrayLike, angle_rad: ArrayLike,
                    valid: ArrayLike) -> tuple[float | None, float | None]:
    """The camera's shake along the markers' line, and the markers' along-line noise (px, RMS).

    A rigid blade turning about a fixed axis moves the markers' midpoint
    along their line only by ``cos`` of the turn (fitted out here); a camera
    that shakes moves both markers together. The midpoint's along-line
    residual has the variance ``shake² + σ_sep²/4`` (``σ_sep`` the spread of
    the separation, which shake and rotation leave alone); shake is the
    excess.

    Returns
    -------
    (shake_px, separation_sigma_px)
        Shake RMS (0 when none is seen; None with fewer than 20 frames) and
        the separation's standard deviation.
    """
    ok = np.asarray(valid, dtype=bool).ravel()
    lead = np.asarray(lead_xy_px, dtype=float).reshape(-1, 2)[ok]
    trail = np.asarray(trail_xy_px, dtype=float).reshape(-1, 2)[ok]
    theta = np.asarray(angle_rad, dtype=float).ravel()[ok]
    good = np.isfinite(lead).all(axis=1) & np.isfinite(trail).all(axis=1) & np.isfinite(theta)
    lead, trail, theta = lead[good], trail[good], theta[good]
    if theta.size < _MIN_NULL_FRAMES:
        return None, None
    line = np.mean(lead - trail, axis=0)
    sep_mean = math.hypot(float(line[0]), float(line[1]))
    if not sep_mean > 0:
        return None, None
    mid = 0.5 * (lead + trail) @ (line / sep_mean)
    d = theta - theta.mean()
    design = np.c_[np.ones_like(d), np.cos(d), np.sin(d)]
    resid = mid - design @ np.linalg.lstsq(design, mid, rcond=None)[0]
    sep = np.hypot(*(lead - trail).T)
    var_sep = float(np.var(sep))
    var_mid = float(np.mean(resid**2)) * theta.size / max(theta.size - 3, 1)
    excess = var_mid - var_sep / 4.0
    shaken = var_mid > SHAKE_VARIANCE_RATIO * var_sep / 4.0
    return (math.sqrt(excess) if shaken and excess > 0 else 0.0), math.sqrt(var_sep)


def angle_error_analysis(track: TrackLike, *, quantization_px: float = 1.0) -> dict:
    """Angle error budget of one track (plain types, for reports).

    Parameters
    ----------
    track : Track
    quantization_px : float
        Centroid error of the paper's worst case (px), 1 px for a binary threshold.

    Returns
    -------
    dict with keys
        ``separation_px`` (mean sticker separation, px),
        ``separation_std_px`` (its spread over the valid frames, px),
        ``centroid_sigma_px`` (median per-frame centroid uncertainty, px),
        ``worst_case_rad`` / ``worst_case_deg`` (atan(quantization_px / L)),
        ``angle_sigma_rad`` / ``angle_sigma_deg`` (√(σ_lead² + σ_trail²) / L),
        ``empirical_noise_rad`` / ``empirical_noise_deg`` (from second
        differences of the angle; an upper bound while the blade moves;
        None with too few frames),
        ``measured_noise_rad`` / ``measured_noise_deg`` (the RMS of the
        markers' :func:`rigid_motion_null` channel: the tracking error
        itself, codec errors included, whatever the blade does; None with
        fewer than 20 frames; when the camera shakes, whose common motion
        that channel cannot tell from the markers' errors, the spread of the
        markers' separation over L instead, which shake leaves alone),
        ``measured_noise_source`` (``"rigid-motion null"`` or
        ``"separation (camera shake)"``),
        ``camera_shake_px`` (the markers' common along-line motion beyond
        their own noise, RMS; 0 when none is seen; see :func:`common_shake_px`),
        ``quantization_px``, ``valid_frames``.
        Values are None when no frame is valid.
    """
    valid = np.asarray(track.valid, dtype=bool)
    sep = np.hypot(*(track.lead_xy_px - track.trail_xy_px).T)[valid]
    sep = sep[np.isfinite(sep)]
    out: dict = {"quantization_px": float(quantization_px), "valid_frames": int(valid.sum())}
    if sep.size == 0:
        for k in ("separation_px", "separation_std_px", "centroid_sigma_px", "worst_case_rad", "worst_case_deg",
                  "angle_sigma_rad", "angle_sigma_deg", "empirical_noise_rad", "empirical_noise_deg",
                  "measured_noise_rad", "measured_noise_deg", "measured_noise_source", "camera_shake_px"):
            out[k] = None
        return out
    length = float(np.mean(sep))
    s_lead = np.asarray(track.lead_sigma_px, dtype=np.float64)[valid]
    s_trail = np.asarray(track.trail_sigma_px, dtype=np.float64)[valid]
    both = np.isfinite(s_lead) & np.isfinite(s_trail)
    sigma_c = float(np.median(np.concatenate([s_lead[both], s_trail[both]]))) if both.any() else None
    angle_sigma = float(np.median(np.hypot(s_lead[both], s_trail[both]))) / length if both.any() else None
    worst = float(worst_case_angle_error_rad(length, quantization_px))
    emp = _empirical_noise_rad(np.where(valid, track.angle_rad, np.nan))
    null = rigid_motion_null(track.lead_xy_px, track.trail_xy_px, valid)
    measured = float(np.nanstd(null)) if np.count_nonzero(np.isfinite(null)) >= _MIN_NULL_FRAMES else None
    source = None if measured is None else "rigid-motion null"
    shake, sep_sigma = common_shake_px(track.lead_xy_px, track.trail_xy_px, track.angle_rad, valid)
    if shake and sep_sigma is not None:
        # The null channel holds (1 − ρ)× the shake across the line; the separation does not.
        # Its spread is the markers' along-line error, the same size as their across-line error
        # when the shake moves them both ways (measured: 1.0–1.3× the true angle error).
        measured, source = sep_sigma / length, "separation (camera shake)"
    out.update({
        "separation_px": length,
        "separation_std_px": float(np.std(sep)),
        "centroid_sigma_px": sigma_c,
        "worst_case_rad": worst,
        "worst_case_deg": math.degrees(worst),
        "angle_sigma_rad": angle_sigma,
        "angle_sigma_deg": None if angle_sigma is None else math.degrees(angle_sigma),
        "empirical_noise_rad": emp,
        "empirical_noise_deg": None if emp is None else math.degrees(emp),
        "measured_noise_rad": measured,
        "measured_noise_deg": None if measured is None else math.degrees(measured),
        "measured_noise_source": source,
        "camera_shake_px": shake,
    })
    return out


def plot_angle_error(analysis: dict, *, ax=None, separation_range_px: tuple[float, float] = (50.0, 1000.0)) -> "Figure":
    """The paper's Fig. 6 for this footage: angle error vs. sticker separation.

    Draws the 1 px worst case ``atan(1 px / L)`` and the statistical error
    ``√2·σ_c / L`` for the measured centroid uncertainty, and marks the
    footage's separation with both values.

    Parameters
    ----------
    analysis : dict
        From :func:`angle_error_analysis`.
    ax : matplotlib Axes, optional
        Draw into it; else a new figure.
    separation_range_px : (float, float)
        Range of separations to plot (px).

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib.pyplot as plt

    if ax is None:
        fig, ax = plt.subplots(figsize=(6.0, 4.0))
    else:
        fig = ax.figure
    length = np.geomspace(*separation_range_px, 200)
    q = analysis.get("quantization_px", 1.0)
    ax.loglog(length, np.degrees(worst_case_angle_error_rad(length, q)), label=f"worst case, {q:g} px centroid error")
    sigma_c = analysis.get("centroid_sigma_px")
    if sigma_c:
        ax.loglog(length, np.degrees(math.sqrt(2.0) * sigma_c / length),
                  label=f"statistical, σ = {sigma_c:.3f} px per centroid")
    sep = analysis.get("separation_px")
    if sep:
        ax.axvline(sep, color="0.5", lw=0.8, ls="--")
        ax.plot([sep], [analysis["worst_case_deg"]], "o", color="C0")
        if analysis.get("angle_sigma_deg"):
            ax.plot([sep], [analysis["angle_sigma_deg"]], "o", color="C1")
        if analysis.get("measured_noise_deg"):
            ax.plot([sep], [analysis["measured_noise_deg"]], "s", color="C2",
                    label="measured angle noise (rigid-motion null channel)")
        elif analysis.get("empirical_noise_deg"):
            ax.plot([sep], [analysis["empirical_noise_deg"]], "s", color="C2",
                    label="angle noise from 2nd differences (upper bound)")
        ax.annotate(f"L = {sep:.0f} px", (sep, ax.get_ylim()[0]), textcoords="offset points", xytext=(4, 6), fontsize=8)
    ax.set_xlabel("sticker separation L (px)")
    ax.set_ylabel("angle error (deg)")
    ax.set_title("Angle error from centroid error")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return fig
