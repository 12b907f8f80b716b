"""Checks across frames: a repeated image is a duplicate.

The rigid-blade check (the markers keep their distance) runs on the undistorted centroids,
after the camera stage: :func:`servoscope.angle.rigid_check.flag_nonrigid`.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["flag_repeated", "same_image"]


def flag_repeated(repeated: np.ndarray, lead: np.ndarray, trail: np.ndarray, reasons: list[str],
                   warnings: list[str]) -> None:
    """Invalidate duplicated frames: a repeated image while the blade moves.

    A bit-identical frame is a duplicate only if the markers moved between
    the frames around it; a static scene without noise repeats legitimately.
    """
    n = repeated.size
    dup = 0
    for i in np.flatnonzero(repeated):
        j = i + 1
        while j < n and repeated[j]:
            j += 1
        if j >= n:
            moved = True  # nothing after it to tell: distrust it
        else:
            step = max(float(np.nanmax(np.abs(lead[j] - lead[i - 1]))), float(np.nanmax(np.abs(trail[j] - trail[i - 1]))))
            moved = not step <= 0.05
        if moved:
            reasons[i] = reasons[i] or f"duplicate of frame {i - 1} (repeated image)"
            dup += 1
    if dup:
        warnings.append(f"{dup} duplicated frame(s) (an image repeated under a new timestamp) marked invalid")


def same_image(a, b) -> bool:
    """Whether two decoded YUV frames hold the very same image (a duplicated frame)."""
    if a.y.shape != b.y.shape or a.row_offset != b.row_offset:
        return False
    # Rows from the middle first: a differing frame differs there at once. The whole-frame planes are
    # compared (not the field's rows), on the decoder's own (strided) buffers: no copy.
    h = a.luma.shape[0]
    mid = slice(h // 2, h // 2 + 8)
    return (_planes_equal(a.luma[mid], b.luma[mid]) and _planes_equal(a.luma, b.luma)
            and _planes_equal(a.u, b.u) and _planes_equal(a.v, b.v))


@njit(cache=True, nogil=True)
def _planes_equal(a, b) -> bool:
    if a.shape != b.shape:
        return False
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            if a[i, j] != b[i, j]:
                return False
    return True
