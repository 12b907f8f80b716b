"""The time base of a recording: dropped, duplicated and irregular frames.

servoscope dates every frame by its presentation timestamp (PTS), so a
dropped frame costs a sample but no timing error, and a variable frame rate
is no error at all. What *is* an error is a frame whose timestamp does not
advance (its content cannot be dated) and a frame that repeats the previous
image under a new timestamp (a camcorder's duplicated frame: its content is
dated wrongly). This module finds the former from the timestamps; the
tracker finds the latter from the pixels.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["FrameTiming", "frame_timing"]


@dataclass(frozen=True)
class FrameTiming:
    """What the timestamps of one recording say.

    Attributes
    ----------
    period_s : float
        Median frame interval (s); NaN with fewer than two frames.
    gaps : ndarray of int
        Frames ``i`` preceded by a gap of more than 1.5 local intervals.
    dropped_count : int
        Frames estimated missing in those gaps.
    stalled : ndarray of int
        Frames ``i`` whose time does not exceed frame ``i − 1``'s.
    variable_rate : bool
        The intervals vary by more than 10 % (90th vs 10th percentile).
    warnings : list of str
    """

    period_s: float
    gaps: np.ndarray
    dropped_count: int
    stalled: np.ndarray
    variable_rate: bool
    warnings: list[str] = field(default_factory=list)


def frame_timing(time_s: np.ndarray, *, gap_factor: float = 1.5) -> FrameTiming:
    """Find dropped frames and stalled timestamps in a sequence of frame times.

    Parameters
    ----------
    time_s : ndarray, shape (n,)
        Presentation times in decoding order (s).
    gap_factor : float
        An interval longer than this many local median intervals means
        frames are missing.

    Returns
    -------
    FrameTiming
    """
    t = np.asarray(time_s, dtype=np.float64)
    empty = np.zeros(0, dtype=np.int64)
    if t.size < 2:
        return FrameTiming(float("nan"), empty, 0, empty, False)
    dt = np.diff(t)
    stalled = np.flatnonzero(dt <= 0) + 1
    pos = dt[dt > 0]
    if pos.size == 0:
        return FrameTiming(float("nan"), empty, 0, stalled, False,
                           [f"timestamps do not advance ({stalled.size} frames)"])
    period = float(np.median(pos))
    # Local median interval (±3 frames): a variable-rate stream changes its
    # interval gradually, a drop is a sudden multiple.
    k = 3
    padded = np.pad(np.where(dt > 0, dt, np.nan), k, mode="edge")
    windows = np.lib.stride_tricks.sliding_window_view(padded, 2 * k + 1)
    local = np.nanmedian(windows, axis=1)
    local = np.where(np.isfinite(local), local, period)
    gap_idx = np.flatnonzero(dt > gap_factor * local)
    dropped = int(np.sum(np.maximum(np.round(dt[gap_idx] / local[gap_idx]) - 1, 1)))
    p10, p90 = np.percentile(pos, [10, 90])
    variable = bool(p90 > 1.1 * p10)
    warnings: list[str] = []
    if gap_idx.size:
        where = ", ".join(f"{t[i]:.3f}–{t[i + 1]:.3f} s" for i in gap_idx[:5])
        more = "" if gap_idx.size <= 5 else f" and {gap_idx.size - 5} more"
        warnings.append(f"about {dropped} dropped frame(s) in {gap_idx.size} gap(s): {where}{more}")
    if stalled.size:
        warnings.append(f"{stalled.size} frame(s) whose timestamp does not advance (marked invalid)")
    if variable:
        warnings.append(f"variable frame rate: intervals {1e3 * p10:.2f}–{1e3 * p90:.2f} ms (timestamps used as they are)")
    return FrameTiming(period, gap_idx + 1, dropped, stalled, variable, warnings)
