"""The blade's angle from the two markers' centroids."""

from __future__ import annotations

import numpy as np

__all__ = ["angle_rad_from_centroids", "blade_angle"]


def angle_rad_from_centroids(lead_xy_px: np.ndarray, trail_xy_px: np.ndarray) -> np.ndarray:
    """Angle of the line from the trailing to the leading marker.

    θ = atan2(y_trail − y_lead, x_lead − x_trail) in image coordinates (y down),
    so counter-clockwise as seen in the image is positive.
    """
    lead = np.asarray(lead_xy_px, dtype=np.float64).reshape(-1, 2)
    trail = np.asarray(trail_xy_px, dtype=np.float64).reshape(-1, 2)
    return np.arctan2(trail[:, 1] - lead[:, 1], lead[:, 0] - trail[:, 0])


def blade_angle(lead_xy_px: np.ndarray, trail_xy_px: np.ndarray, valid: np.ndarray, lead_sigma_px: np.ndarray,
                trail_sigma_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The blade's angle per frame, unwrapped over the valid frames, and its uncertainty.

    Parameters
    ----------
    lead_xy_px, trail_xy_px : ndarray, shape (n, 2)
        Centroids (undistorted when a lens model is known).
    valid : ndarray of bool
    lead_sigma_px, trail_sigma_px : ndarray
        Each centroid coordinate's standard uncertainty (px).

    Returns
    -------
    angle_rad : ndarray
        :func:`angle_rad_from_centroids`, NaN where invalid.
    angle_sigma_rad : ndarray
        Only the components across the joining line turn it:
        σθ = √(σ_lead² + σ_trail²) / L; NaN where invalid.
    """
    angle = angle_rad_from_centroids(lead_xy_px, trail_xy_px)
    angle[~valid] = np.nan
    if valid.any():
        angle[valid] = np.unwrap(angle[valid])
    separation = np.hypot(*(lead_xy_px - trail_xy_px).T)
    angle_sigma = np.where(valid, np.hypot(lead_sigma_px, trail_sigma_px) / separation, np.nan)
    return angle, angle_sigma
