"""Where the blade turns about, and whether that point stood still: the footage's own check of a steady frame.

Two stickers on one rigid blade that pitches about a fixed axis move, frame by
frame, by a rotation about that axis's point in the picture. The rigid motion
of the markers' pair from the first valid frame to frame t (the turn θ_t of the
line joining them, and its midpoint's move) has one fixed point P when the axis
stands still: ``(I − R_t)·P = m_t − R_t·m_0`` for every t, linear in P and solved
by least squares over the frames. Where the camera shook or rolled, or the
airframe rocked, no single point stays: the RMS of where P goes, frame by frame,
is how much the blade's axis moved in the picture (px). A translation (shake)
leaves the angle alone; a turn of the camera or the airframe does not, and the
angle then holds it, which only reference stickers on the airframe can take off
(:attr:`servoscope.markers.TrackerSettings.reference`).

Measured on the twin (quick preset, 480×384): steady 0.006–0.008 px raw,
0.018–0.026 px under H.264; a camera rolling ±0.5° at 3 Hz 0.68–0.70 px; the
airframe rocking ±0.5° at 2 Hz 1.17 px.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["PIVOT_MOTION_WARN_PX", "PivotMotion", "axis_moved", "heave_px", "pivot_motion"]

#: The axis moving more than this (RMS px, and 10 centroid σ) earns a warning where no reference
#: stickers take the picture's own turn off the angle: six times what H.264 shows of a steady one.
PIVOT_MOTION_WARN_PX = 0.15
#: The pair must turn by at least this for the fixed point to be determined (rad, peak to peak).
MIN_SWING_RAD = math.radians(0.2)


@dataclass(frozen=True)
class PivotMotion:
    """The blade's axis in the picture and how much it moved.

    Attributes
    ----------
    centre_xy_px : (float, float)
        The fixed point of the markers' motion (px, the centroids' image).
    rms_px : float
        RMS of its move from frame to frame about its mean (px).
    swing_rad : float
        How far the pair turned (peak to peak), what the point rests on.
    """

    centre_xy_px: tuple[float, float]
    rms_px: float
    swing_rad: float

    def moved(self, centroid_sigma_px: float = 0.0) -> bool:
        """Whether the axis moved beyond what a steady camera shows (see :data:`PIVOT_MOTION_WARN_PX`)."""
        return self.rms_px > max(PIVOT_MOTION_WARN_PX, 10.0 * centroid_sigma_px)


def pivot_motion(lead_xy_px: np.ndarray, trail_xy_px: np.ndarray, valid: np.ndarray) -> PivotMotion | None:
    """The fixed point of the markers' rigid motion and how much it moved (see the module); None when the pair
    hardly turned (less than :data:`MIN_SWING_RAD`) or fewer than 10 frames are valid."""
    lead, trail = np.asarray(lead_xy_px, dtype=float), np.asarray(trail_xy_px, dtype=float)
    ok = np.asarray(valid, dtype=bool) & np.all(np.isfinite(lead), axis=1) & np.all(np.isfinite(trail), axis=1)
    if np.count_nonzero(ok) < 10:
        return None
    lead, trail = lead[ok], trail[ok]
    d = lead - trail
    theta = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    theta = theta - theta[0]
    swing = float(np.ptp(theta))
    if swing < MIN_SWING_RAD:
        return None
    mid = 0.5 * (lead + trail)
    c, s = np.cos(theta), np.sin(theta)
    m0 = mid[0]
    # (I − R_t)·P = m_t − R_t·m_0, two rows a frame.
    a = np.zeros((2 * theta.size, 2))
    a[0::2, 0], a[0::2, 1] = 1.0 - c, s
    a[1::2, 0], a[1::2, 1] = -s, 1.0 - c
    b = np.empty(2 * theta.size)
    b[0::2] = mid[:, 0] - (c * m0[0] - s * m0[1])
    b[1::2] = mid[:, 1] - (s * m0[0] + c * m0[1])
    p, *_ = np.linalg.lstsq(a, b, rcond=None)
    # Where frame 0's point P is carried in frame t; its spread is the axis's motion.
    moved = np.stack([c * (p[0] - m0[0]) - s * (p[1] - m0[1]) + mid[:, 0],
                      s * (p[0] - m0[0]) + c * (p[1] - m0[1]) + mid[:, 1]], axis=1)
    spread = moved - moved.mean(axis=0)
    return PivotMotion((float(p[0]), float(p[1])), float(np.sqrt(np.mean(np.sum(spread**2, axis=1)))), swing)


def axis_moved(track) -> PivotMotion | None:
    """The blade's axis in a track's picture when it moved beyond what a steady camera shows; else None.

    ``track`` is a :class:`~servoscope.markers.Track` (its centroids, validity and centroid
    uncertainty): the threshold is :meth:`PivotMotion.moved` at the track's median centroid σ.
    """
    pivot = pivot_motion(track.lead_xy_px, track.trail_xy_px, track.valid)
    sigma = np.asarray(track.lead_sigma_px, dtype=float)
    centroid_sigma = float(np.nanmedian(sigma)) if np.isfinite(sigma).any() else 0.0
    return pivot if pivot is not None and pivot.moved(centroid_sigma) else None


def heave_px(lead_xy_px: np.ndarray, trail_xy_px: np.ndarray, valid: np.ndarray, centre_xy_px) -> np.ndarray:
    """The blade's heave per frame (px, up positive): the markers' line's distance from the pitch axis.

    A rigid blade turning about the axis keeps its chord line at one distance from it;
    a blade that flaps moves the line across itself. ``centre_xy_px`` is the axis
    (:attr:`PivotMotion.centre_xy_px`). "Up" is the line's normal turned a quarter turn
    counter-clockwise from trail to lead (up in the picture when the lead is on the
    right). NaN where a frame is not valid; the level is the distance itself (subtract
    a rest value to get the motion).
    """
    lead, trail = np.asarray(lead_xy_px, dtype=float), np.asarray(trail_xy_px, dtype=float)
    d = lead - trail
    u = d / np.hypot(d[:, 0], d[:, 1])[:, None]
    normal = np.stack([u[:, 1], -u[:, 0]], axis=1)
    mid = 0.5 * (lead + trail)
    h = np.sum(normal * (mid - np.asarray(centre_xy_px, dtype=float)), axis=1)
    return np.where(np.asarray(valid, dtype=bool), h, np.nan)
