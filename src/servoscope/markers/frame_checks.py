"""Checks across frames: the markers keep a rigid blade's distance; a repeated image is a duplicate."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from numba import njit

from ..angle.geometry import angle_rad_from_centroids
from ..errors import ServoscopeError

__all__ = ["flag_nonrigid", "flag_repeated", "same_image"]


#: A frame's marker separation may depart from the rigid blade's by this many times the
#: separation's frame-to-frame noise, and at least :data:`_RIGID_FLOOR_PX` px or
#: :data:`_RIGID_FLOOR_FRACTION` of the separation (a lens's focus breathing, a blade that bends
#: a little): more, and the two "markers" did not keep their distance in that frame.
_RIGID_SIGMAS = 6.0
_RIGID_FLOOR_PX = 0.5
_RIGID_FLOOR_FRACTION = 0.005
#: A camera that does not face the blade square-on foreshortens the markers' separation by the
#: blade's angle: under any affine view, separation² = A + B·cos 2θ + C·sin 2θ. Fitted when the
#: angle spans this much (rad); a fitted modulation √(B² + C²)/A above :data:`_RIGID_MAX_MODULATION`
#: (a view more than ~40° off square) is not a camera's, and the constant separation is kept.
_RIGID_MIN_SPAN_RAD = 0.1
_RIGID_MAX_MODULATION = 0.3


def _rigid_separation(theta: np.ndarray, sep: np.ndarray, use: np.ndarray) -> np.ndarray:
    """The separation a rigid blade would show at each angle: constant, or foreshortened by the view."""
    med = float(np.median(sep[use]))
    if np.count_nonzero(use) < 10 or float(np.ptp(theta[use])) < _RIGID_MIN_SPAN_RAD:
        return np.full(sep.shape, med)
    design = np.c_[np.ones(theta.size), np.cos(2.0 * theta), np.sin(2.0 * theta)]
    coef = np.linalg.lstsq(design[use], sep[use] ** 2, rcond=None)[0]
    if not (coef[0] > 0 and math.hypot(coef[1], coef[2]) <= _RIGID_MAX_MODULATION * coef[0]):
        return np.full(sep.shape, med)
    return np.sqrt(np.maximum(design @ coef, 0.0))


def flag_nonrigid(path: Path, lead: np.ndarray, trail: np.ndarray, valid: np.ndarray, reasons: list[str],
                   warnings: list[str]) -> None:
    """Invalidate frames whose marker separation changed; refuse a track where most did.

    Two stickers on one rigid blade keep their distance whatever the blade
    does and wherever the camera is (a view that is not square-on
    foreshortens it by the blade's angle, smoothly: that is fitted, see
    :func:`_rigid_separation`). Two things that only have the markers'
    colours (clothing of passers-by, a box and a sticker) do not.

    Raises
    ------
    ServoscopeError
        When more than half the otherwise valid frames changed their separation.
    """
    sep = np.hypot(*(lead - trail).T)
    ok = valid & np.isfinite(sep)
    if np.count_nonzero(ok) < 10:
        return
    theta = np.where(ok, angle_rad_from_centroids(lead, trail), 0.0)
    theta = np.where(ok, np.unwrap(theta), 0.0)
    med = float(np.median(sep[ok]))
    use = ok.copy()
    for _ in range(2):  # fit, then fit again without the frames that departed
        resid = sep - _rigid_separation(theta, sep, use)
        steps = np.diff(resid[ok])
        # Frame-to-frame changes: noise (√2 σ) where the blade is rigid, whatever the mean does.
        sigma = 1.4826 * float(np.median(np.abs(steps - np.median(steps)))) / math.sqrt(2.0)
        allow = max(_RIGID_SIGMAS * sigma, _RIGID_FLOOR_PX, _RIGID_FLOOR_FRACTION * med)
        bad = ok & (np.abs(resid) > allow)
        if np.count_nonzero(ok & ~bad) < 10:
            break
        use = ok & ~bad
    n_bad, n_ok = int(np.count_nonzero(bad)), int(np.count_nonzero(ok))
    if n_bad > n_ok / 2:
        lo, hi = float(np.min(sep[ok])), float(np.max(sep[ok]))
        raise ServoscopeError(
            f"{path}: the two markers' distance changes from {lo:.0f} to {hi:.0f} px in {n_bad} of {n_ok} frames "
            f"(a rigid blade keeps it within {allow:.1f} px): these are not two stickers on one rigid part; "
            "check the marker colours (`servoscope markers`) or pin them (--lead '#rrggbb@x,y')")
    for i in np.flatnonzero(bad):
        valid[i] = False
        reasons[i] = reasons[i] or f"separation changed ({resid[i]:+.1f} px from a rigid blade's {sep[i] - resid[i]:.1f} px)"
    if n_bad:
        warnings.append(f"{n_bad} frame(s) where the markers' separation changed by more than {allow:.1f} px "
                        "marked invalid")


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
