"""A marker lost from its tracking window, found again in the whole frame: the engines' shared slow path."""

from __future__ import annotations

from typing import Callable

import numpy as np

from .kernel_layout import Q
from .marker_state import Blob, MarkerTracker

__all__ = ["refind"]


def refind(tracker: MarkerTracker, rgb: np.ndarray, measure_at: Callable[[tuple[float, float]], Blob | None],
           out_row: np.ndarray) -> tuple[Blob | None, str]:
    """Find ``tracker``'s marker in the whole frame (RGB, components), then measure it with the engine's kernel there.

    Parameters
    ----------
    tracker : MarkerTracker
    rgb : ndarray
        The frame's RGB image.
    measure_at : callable
        The engine's kernel around a centre (px): the marker's blob, or None where the
        kernel finds it implausible there.
    out_row : ndarray
        The marker's kernel output row (:class:`~.kernel_layout.Q`), set to what was found:
        the kernel's, else the components' centroid and area (the LED's place follows the
        markers' rows), else zero area (not found).

    Returns
    -------
    (Blob or None, str)
        The blob (the kernel's, else the components' own) and ``""``; or None and why not
        found (the tracker is then marked lost).
    """
    rgb_blob, why = tracker.find(rgb)
    if rgb_blob is None:
        out_row[Q.M00] = 0.0
        tracker.lose()
        return None, why
    m = rgb_blob.moments
    blob = measure_at((m.x_px, m.y_px))
    if blob is None:
        out_row[Q.M00], out_row[Q.X], out_row[Q.Y] = m.m00, m.x_px, m.y_px
        return rgb_blob, ""
    return blob, ""
