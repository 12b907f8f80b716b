"""A rolling shutter's row timing: when a point of the recorded image was exposed.

Row y of a frame is taken as exposed around ``frame_time + readout_s·y/height``
(y in the recorded image, :meth:`~servoscope.video.reader.VideoInfo.sensor_rows`).
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ServoscopeError

__all__ = ["angle_row_weights", "angle_sample_times", "check_readout"]


def check_readout(readout_s: float, frame_rate_hz: float | None, fields: bool) -> None:
    """Refuse a readout time no sensor can have: negative, or not shorter than the frame interval.

    A sensor reads all of a frame's rows before it reads the next frame's
    (an interlaced one, a field's before the next field's).
    """
    if isinstance(readout_s, bool) or not (isinstance(readout_s, (int, float)) and math.isfinite(readout_s)
                                           and readout_s >= 0):
        raise ServoscopeError(f"readout: must be a time >= 0 in seconds, got {readout_s!r}")
    if readout_s > 0 and frame_rate_hz:
        interval_s = 1.0 / (frame_rate_hz * (2 if fields else 1))
        if readout_s >= interval_s:
            raise ServoscopeError(
                f"readout: {readout_s:g} s is not shorter than the {'field' if fields else 'frame'} interval "
                f"({1e3 * interval_s:.4g} ms): a sensor reads one frame's rows before the next frame's")


def angle_row_weights(lead_xy_px: np.ndarray, trail_xy_px: np.ndarray, valid: np.ndarray) -> tuple[float, str]:
    """Share of the lead marker in the angle's motion; weights its row in the angle's sample time.

    With each marker seen at its own row's time, the angle is, to first order
    in the time difference, ``w·θ(t_lead) + (1 − w)·θ(t_trail)`` where w is
    the lead's share of the angle's change: each marker moves across the
    joining line by its lever arm about the pivot times the rotation, so
    ``w = (s_lead − s_pivot)/L`` along the line of length L. That is
    ``θ(w·t_lead + (1 − w)·t_trail)``: the angle is sampled at the
    lever-weighted mean row, not the plain mean (the plain mean is right only
    for a pivot midway between the stickers; with the paper's quarter-chord
    pivot w ≈ 0.21). w is measured from the track itself: the regression of
    the lead's motion across the line on the angle's, ``n_lead = w·(n_lead − n_trail)``.

    Returns
    -------
    w_lead : float
        0.5 when it cannot be measured.
    why : str
        Why not ("" when measured).
    """
    ok = valid & np.isfinite(lead_xy_px).all(axis=1) & np.isfinite(trail_xy_px).all(axis=1)
    if ok.sum() < 10:
        return 0.5, "too few frames with both markers to measure their lever arms"
    lead, trail = lead_xy_px[ok], trail_xy_px[ok]
    axis = lead.mean(axis=0) - trail.mean(axis=0)
    e = axis / np.hypot(*axis)
    normal = np.array([-e[1], e[0]])
    n_lead = (lead - lead.mean(axis=0)) @ normal
    n_trail = (trail - trail.mean(axis=0)) @ normal
    d = n_lead - n_trail
    sdd = float(d @ d)
    if not sdd > 0:
        return 0.5, "the markers do not move, so their lever arms cannot be measured"
    w = float(n_lead @ d) / sdd
    resid = n_lead - w * d
    se = math.sqrt(float(resid @ resid) / max(d.size - 1, 1) / sdd)
    # 0.05 of the two rows' difference is < 0.1 ms at 20 ms readout for markers 30 rows apart.
    if not se < 0.05:
        return 0.5, f"the markers move too little to measure their lever arms (share {w:.2f} ± {se:.2f})"
    return w, ""


def angle_sample_times(clock_s: np.ndarray, lead_xy_px: np.ndarray, trail_xy_px: np.ndarray, valid: np.ndarray,
                       lead_row: np.ndarray, trail_row: np.ndarray, readout_s: float,
                       sensor_height: int) -> tuple[np.ndarray, str]:
    """When each frame's angle was sampled: its clock time plus the readout of the markers' rows.

    Parameters
    ----------
    clock_s : ndarray
        The frames' times (the exposures' middles).
    lead_xy_px, trail_xy_px : ndarray, shape (n, 2)
        The centroids the lever arms are measured from (see :func:`angle_row_weights`).
    valid : ndarray of bool
    lead_row, trail_row : ndarray
        The markers' rows in the recorded image (px).
    readout_s : float
        The sensor's readout time (0: a global shutter, ``clock_s`` returned).
    sensor_height : int
        Rows of the recorded image.

    Returns
    -------
    times : ndarray
        A copy of ``clock_s``, corrected by ``readout_s·y_eff/height``, y_eff the
        lever-weighted row; frames without both markers get the typical row.
    warning : str
        Why the weights could not be measured ("" when they were).
    """
    times = clock_s.copy()
    warning = ""
    if readout_s > 0 and clock_s.size:
        w_lead, why = angle_row_weights(lead_xy_px, trail_xy_px, valid)
        if why:
            warning = f"rolling shutter: {why}; the angle's sample time uses the mean of the two markers' rows"
        row = w_lead * lead_row + (1.0 - w_lead) * trail_row
        if np.isfinite(row).any():
            # Frames without both markers have no angle; give them the typical row.
            row = np.where(np.isfinite(row), row, np.nanmedian(row))
            times = times + readout_s * row / sensor_height
    return times, warning
