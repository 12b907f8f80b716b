"""The blade's angle from the two markers' centroids."""

from __future__ import annotations

import numpy as np

__all__ = ["angle_rad_from_centroids"]


def angle_rad_from_centroids(lead_xy_px: np.ndarray, trail_xy_px: np.ndarray) -> np.ndarray:
    """Angle of the line from the trailing to the leading marker.

    θ = atan2(y_trail − y_lead, x_lead − x_trail) in image coordinates (y down),
    so counter-clockwise as seen in the image is positive.
    """
    lead = np.asarray(lead_xy_px, dtype=np.float64).reshape(-1, 2)
    trail = np.asarray(trail_xy_px, dtype=np.float64).reshape(-1, 2)
    return np.arctan2(trail[:, 1] - lead[:, 1], lead[:, 0] - trail[:, 0])
