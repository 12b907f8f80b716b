"""The rigid-blade check: two stickers on one blade keep their distance (frames where they do not are invalid).

Run on the markers' undistorted centroids (or the plane's), after the camera stage and
before the angle (:func:`servoscope.pipeline.tracker.track_video`); a view that is not
square-on foreshortens the separation by the blade's angle, so the check fits that.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import ServoscopeError
from .geometry import angle_rad_from_centroids

__all__ = ["flag_nonrigid"]


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
