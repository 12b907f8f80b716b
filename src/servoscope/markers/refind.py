"""The engines' shared per-marker steps: the search window, and a marker lost from it found again in the whole frame."""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

from .kernel_layout import Q
from .marker_state import Blob, MarkerTracker

__all__ = ["refind", "search_window", "take_markers"]


def search_window(tracker: MarkerTracker, shape: tuple[int, int], centre: tuple[float, float] | None = None
                  ) -> tuple[int, int, int, int] | None:
    """The marker's search window (x0, y0, x1, y1; half-open px) around its prediction, clipped to the frame.

    Around ``centre`` instead (a blob just found): the marker's extent and 6 px. None when
    there is no prediction or the window is empty.
    """
    h, w = shape
    c = tracker.predicted_xy() if centre is None else centre
    if c is None:
        return None
    r = tracker.search_radius_px + tracker.extent_px if centre is None else tracker.extent_px + 6.0
    x0 = int(max(0, math.floor(c[0] - r)))
    y0 = int(max(0, math.floor(c[1] - r)))
    x1 = int(min(w, math.ceil(c[0] + r) + 1))
    y1 = int(min(h, math.ceil(c[1] + r) + 1))
    if x1 - x0 <= 2 or y1 - y0 <= 2:
        return None
    return x0, y0, x1, y1


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


def take_markers(trackers, windows: list, out: np.ndarray, shape: tuple[int, int],
                 blob_of: Callable[[MarkerTracker, np.ndarray, tuple, tuple[int, int]], Blob | None],
                 rgb: Callable[[], np.ndarray], measure_one: Callable[..., Blob | None],
                 found: dict[str, Blob]) -> tuple[str, bool]:
    """Each marker's blob from its kernel row, or found again in the whole frame; accepted, into ``found``.

    The engines' per-frame step after their kernel call. ``blob_of(tracker, row,
    window, shape)`` reads a kernel row (None: implausible in the window);
    ``measure_one(k, window, centre)`` runs the kernel for marker ``k`` alone;
    ``rgb()`` gives the frame's RGB image, made only when a marker is looked for in
    the whole frame (:func:`refind`).

    Returns
    -------
    (str, bool)
        The frame's first flaw (or why a marker was not found; "" for none), and whether
        a marker took the slow path.
    """
    reason, slow = "", False
    for k, tracker in enumerate(trackers):
        blob = blob_of(tracker, out[k], windows[k], shape) if windows[k] is not None else None
        if blob is None:
            slow = True

            def at(c, k=k, tracker=tracker):
                return measure_one(k, search_window(tracker, shape, c), c)

            blob, why = refind(tracker, rgb(), at, out[k])
            if blob is None:
                reason = reason or why
                continue
        tracker.accept(blob, None)
        found[tracker.name] = blob
        reason = reason or blob.flaw
    return reason, slow
