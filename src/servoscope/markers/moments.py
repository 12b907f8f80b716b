"""Image moments of a weight image (the paper's eqs. 1–4), with subpixel centroids.

The paper's ``I(x, y)`` is a binary flag; here it may be any weight in [0, 1]
(a soft colour membership), of which the flag is the special case.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["Moments", "weighted_moments"]


@dataclass(frozen=True)
class Moments:
    """Raw and central moments of a weight image, in pixels.

    Attributes
    ----------
    m00 : float
        Total weight (area in pixels for a binary mask), eq. 3.
    x_px, y_px : float
        Centroid ``(m10/m00, m01/m00)``, eq. 4, pixel centres at integers.
    mu20, mu11, mu02 : float
        Central second moments divided by m00 (px²): the blob's shape.
    """

    m00: float
    x_px: float
    y_px: float
    mu20: float
    mu11: float
    mu02: float

    @cached_property
    def axes_px(self) -> tuple[float, float]:
        """Standard deviations along the major and minor axes (px).

        Computed once per instance (a frozen instance's value never changes): a
        marker's shape check and its acceptance both read it every frame.
        """
        common = 0.5 * (self.mu20 + self.mu02)
        diff = math.hypot(0.5 * (self.mu20 - self.mu02), self.mu11)
        return math.sqrt(max(common + diff, 0.0)), math.sqrt(max(common - diff, 0.0))


def weighted_moments(weight: np.ndarray, origin_xy_px: tuple[float, float] = (0.0, 0.0)) -> Moments | None:
    """Moments of a 2-D weight image.

    Parameters
    ----------
    weight : ndarray, shape (h, w)
        Non-negative weights; row index is y, column index is x.
    origin_xy_px : (float, float)
        Image coordinates of ``weight[0, 0]``, to place a window in its frame.

    Returns
    -------
    Moments, or None when the total weight is zero.
    """
    w = np.asarray(weight, dtype=np.float64)
    m00 = float(w.sum())
    if not m00 > 0.0:
        return None
    col = w.sum(axis=0)
    row = w.sum(axis=1)
    xs = np.arange(w.shape[1], dtype=np.float64)
    ys = np.arange(w.shape[0], dtype=np.float64)
    # Centroid first, then central moments about it: fewer cancellation errors
    # than m20/m00 − x̄² on a window far from the origin.
    xbar = float(col @ xs) / m00
    ybar = float(row @ ys) / m00
    dx = xs - xbar
    dy = ys - ybar
    mu20 = float(col @ (dx * dx)) / m00
    mu02 = float(row @ (dy * dy)) / m00
    mu11 = float(dy @ (w @ dx)) / m00
    return Moments(m00, xbar + origin_xy_px[0], ybar + origin_xy_px[1], mu20, mu11, mu02)
