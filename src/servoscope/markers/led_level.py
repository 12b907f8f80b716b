"""The status LED's brightness per frame: where it is on the blade, how lit, whether it clips."""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from ..video.native import sample_at
from ..video.reader import VideoInfo
from .colour import ColourModel, seed_model
from .led_timing import frame_period_s, led_switch_time
from .marker_state import Blob
from .moments import Moments

__all__ = ["LED_CLIP_DN", "LED_PEAK_FRAMES", "LED_STAY_FRAMES", "InputStart", "disk_level", "disk_level_native",
           "disk_peak", "input_start",
           "led_brightness", "led_row_px", "locate_led", "stays_down"]


def _marker_axes(lead: Moments, trail: Moments) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    origin = np.array([trail.x_px, trail.y_px])
    axis = np.array([lead.x_px, lead.y_px]) - origin
    length = float(np.hypot(*axis))
    e = axis / length
    nrm = np.array([-e[1], e[0]])
    return origin, e, nrm, length


def locate_led(rgb, model: ColourModel, lead: Moments, trail: Moments):
    """The LED's position in the markers' frame (units of their separation) and its radius (px).

    The LED is the largest blob of its colour once the markers' own disks are
    masked out: a yellow LED's hue band reaches an orange sticker's, whose
    brightness never changes. Where several blobs remain, those within a
    separation of the markers' segment (on or by the blade) come first.
    """
    mask = model.mask(rgb).astype(np.uint8)
    for m in (lead, trail):
        # Cover the sticker and its blurred edge: its equivalent radius grown by half, plus 3 px.
        r = 1.5 * math.sqrt(max(m.m00, 0.0) / math.pi) + 3.0
        cv2.circle(mask, (int(round(m.x_px)), int(round(m.y_px))), int(math.ceil(r)), 0, -1)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return None, 0.0
    origin, e, nrm, length = _marker_axes(lead, trail)
    rel = cents[1:] - origin
    along, across = rel @ e, rel @ nrm
    off = np.maximum(np.maximum(-along, along - length), 0.0)
    near = np.hypot(off, across) <= length
    areas = stats[1:, cv2.CC_STAT_AREA].astype(np.float64)
    best = 1 + int(np.argmax(np.where(near, areas, -1.0) if near.any() else areas))
    if stats[best, cv2.CC_STAT_AREA] < 3:
        return None, 0.0
    d = cents[best] - origin
    local = np.array([d @ e, d @ nrm]) / length
    radius = math.sqrt(stats[best, cv2.CC_STAT_AREA] / math.pi)
    return local, radius


def led_brightness(rgb, local, radius, lead: Blob | None, trail: Blob | None) -> float:
    """Mean brightness (HSV value) in a disk that follows the LED on the blade."""
    if lead is None or trail is None:
        return math.nan
    origin, e, nrm, length = _marker_axes(lead.moments, trail.moments)
    centre = origin + length * (local[0] * e + local[1] * nrm)
    r = 1.5 * radius + 1.0
    h, w = rgb.shape[:2]
    x0, x1 = int(max(0, centre[0] - r)), int(min(w, centre[0] + r + 1))
    y0, y1 = int(max(0, centre[1] - r)), int(min(h, centre[1] + r + 1))
    if x1 <= x0 or y1 <= y0:
        return math.nan
    yy, xx = np.mgrid[y0:y1, x0:x1]
    disk = (xx - centre[0]) ** 2 + (yy - centre[1]) ** 2 <= r * r
    roi = rgb[y0:y1, x0:x1]
    return float(roi[disk].max(axis=1).mean())


#: Frames whose brightest LED pixel is checked for clipping, and the luma that counts as
#: clipped: 2 DN below the limited-range white (235) that camcorders record; full-range
#: footage (white 255) with an LED this bright is at least close to clipping too.
LED_PEAK_FRAMES = 5
LED_CLIP_DN = 233.0

#: Frames a switched-off LED must stay down for (and the video must go on for) to count as a
#: switch: a bright patch that leaves the picture in the last frames, or the video's end, is not one.
LED_STAY_FRAMES = 5
#: Of the frames after the switch, the share that must read dark (a passing reflection is let by).
LED_STAY_SHARE = 0.9


def disk_peak(Y, cx: float, cy: float, r: float) -> float:
    """Brightest luma within radius ``r`` of (cx, cy); NaN when the disk is off the image."""
    return disk_level(Y, cx, cy, r)[1]


def disk_level(Y, cx: float, cy: float, r: float) -> tuple[float, float]:
    """Mean and brightest luma of the pixels within radius ``r`` of (cx, cy); NaN, NaN off the image.

    Compiled: the LED's search follows up to eight candidates twice a frame, and
    NumPy's grid, mask and fancy indexing cost ~60 µs a disk (a fifth of the
    whole command's time on uncompressed footage); the loop costs ~1 µs. The
    mean of integer samples is exact in float64 either way, so the levels are
    NumPy's to the bit.
    """
    return disk_level_native(Y, False, Y.shape[1], cx, cy, r)


def disk_level_native(samples: np.ndarray, packed: bool, width: int, cx: float, cy: float,
                      r: float) -> tuple[float, float]:
    """:func:`disk_level` on a monochrome frame's samples as stored (packed 12-bit read where needed, a word's
    samples where its bits sit): the mean and brightest sample within ``r`` of (cx, cy); NaN, NaN off the image.
    The rotor scan reads its fixed LED's disk every frame with it (~1 µs against NumPy's ~20 µs crop, mask
    and mean; the same sums of integer samples, so the same values)."""
    return _disk_native(samples, bool(packed), int(width), float(cx), float(cy), float(r))


@njit(cache=True, nogil=True)
def _disk_native(img, packed, width, cx, cy, r):
    """:func:`disk_level` on a monochrome frame's native samples (:func:`~servoscope.video.native.sample_at`).

    Packed 12-bit rows decoded where read; ``packed`` False: ``img`` is the samples themselves (any
    2-D array: a video's luma plane, 8- or 16-bit words).
    """
    if not (math.isfinite(cx) and math.isfinite(cy) and r > 0):
        return math.nan, math.nan
    h = img.shape[0]
    w = width
    x0, x1 = max(0, int(math.floor(cx - r))), min(w, int(math.floor(cx + r)) + 1)
    y0, y1 = max(0, int(math.floor(cy - r))), min(h, int(math.floor(cy + r)) + 1)
    total = 0.0
    peak = -math.inf
    n = 0
    for i in range(y0, y1):
        dy = (i - cy) * (i - cy)
        for j in range(x0, x1):
            if (j - cx) * (j - cx) + dy <= r * r:
                v = sample_at(img, i, j, packed)
                total += v
                n += 1
                if v > peak:
                    peak = v
    if n == 0:
        return math.nan, math.nan
    return total / n, peak


@njit(cache=True, nogil=True)
def disks_native(img, packed, width, xs, ys, rs, us, vs, axes, out):
    """The LED candidates' disks on a frame's native samples, in one call (the LED search's :meth:`measure_native`).

    Row k of ``out``: mean and peak of candidate k's disk where it was found
    (``xs``, ``ys``, radius ``rs``), then where the markers carry it (``us``,
    ``vs`` in the markers' frame, placed by ``axes`` = (trail x, trail y, the
    axis's unit x, y, its length, 1); NaN when ``axes[5]`` is 0: a marker is missing).
    """
    for k in range(xs.size):
        out[k, 0], out[k, 1] = _disk_native(img, packed, width, xs[k], ys[k], rs[k])
        if axes[5] == 0.0:
            out[k, 2] = math.nan
            out[k, 3] = math.nan
            continue
        ox, oy, ex, ey, length = axes[0], axes[1], axes[2], axes[3], axes[4]
        u, v = us[k], vs[k]
        # As LedSearch.measure places it, operation for operation (Python's float arithmetic is IEEE's).
        out[k, 2], out[k, 3] = _disk_native(img, packed, width, ox + length * (u * ex - v * ey),
                                            oy + length * (u * ey + v * ex), rs[k])


def led_row_px(rgb: np.ndarray, led_spec, info: VideoInfo) -> float | None:
    """Row (stored picture, px) of the largest lit-LED-coloured (or bright, or dark) blob in ``rgb``; None when there is none."""
    model = seed_model(led_spec, rgb)
    mask = model.mask(rgb).astype(np.uint8)
    n, _, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return None
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    if stats[best, cv2.CC_STAT_AREA] < 3:
        return None
    return float(info.sensor_rows(cents[best]))


@dataclass
class InputStart:
    """The LED's level per frame and the input's start (t0) it gives; None where not found.

    Attributes
    ----------
    led_level : ndarray
        Brightness normalised to 1 lit, 0 off (NaN without an LED).
    t0_s, t0_uncertainty_s : float or None
    t0_window : (float, float) or None
        The interval the switch can lie in.
    partial_frames : int or None
        Partly lit frames at the switch.
    """

    led_level: np.ndarray
    t0_s: float | None = None
    t0_uncertainty_s: float | None = None
    t0_window: tuple[float, float] | None = None
    partial_frames: int | None = None


def input_start(led_signal: list[float], led_peak_dn: list[float], clock_s: np.ndarray, time_s: np.ndarray,
                exposure_s: float | None, readout_s: float, snapshot: np.ndarray | None, led_spec,
                info: VideoInfo, warnings: list[str],
                led_xy: tuple[float, float] | None = None) -> InputStart:
    """The LED's switch-off (the input's start) from its brightness per frame; warnings appended.

    ``clock_s`` are the exposures' middles (the LED and the stickers share each
    exposure). A clipped LED widens t0's uncertainty to its exposure; a rolling
    shutter's readout moves t0 to the LED's row (``led_xy``'s, else found in
    ``snapshot``). A level that goes dark only in the video's last
    :data:`LED_STAY_FRAMES` frames, or does not stay dark, is no switch.
    """
    n = time_s.size
    out = InputStart(np.full(n, np.nan))
    led_peak = max((p for p in led_peak_dn if math.isfinite(p)), default=math.nan)
    led_clipped = led_peak >= LED_CLIP_DN
    if not (led_signal and np.isfinite(led_signal).sum() >= 3):
        return out
    signal = np.asarray(led_signal, dtype=np.float64)
    good = np.flatnonzero(np.isfinite(signal))
    head = signal[good[: min(5, good.size)]]
    tail = signal[good[-min(5, good.size):]]
    on, off = float(np.median(head)), float(np.median(tail))
    if not on - off > 10.0:
        warnings.append("LED brightness does not change: no input start (t0) found")
        return out
    out.led_level = (signal - off) / (on - off)
    why_not = stays_down(out.led_level)
    if why_not:
        warnings.append(f"LED {why_not}: not a switch, no input start (t0) found")
        return out
    t0 = t0_unc = None
    t0_window = None
    switch, why = led_switch_time(clock_s, out.led_level, exposure_s)
    if why:
        warnings.append(why)
    if switch is not None:
        t0, t0_unc = switch.t0_s, switch.stderr_s
        t0_window = (switch.earliest_s, switch.latest_s)
        out.partial_frames = switch.partial_frames
    if t0 is not None and led_clipped:
        # A clipped LED reads fully lit for part of the exposure it was not: the
        # partly lit frame's level, and so t0 within that frame, is not known
        # (within the whole frame interval when the exposure is not known).
        period = frame_period_s(time_s)
        exposure = period if exposure_s is None else min(exposure_s, period)
        t0_unc = max(t0_unc or 0.0, exposure / math.sqrt(12.0))
        t0_window = (min(t0_window[0], t0 - exposure / 2), max(t0_window[1], t0 + exposure / 2))
        warnings.append(
            f"LED at the video's white level (luma {led_peak:.0f}): a clipped LED's "
            "partly lit frame looks brighter than it was, so t0 is known only to within its "
            f"exposure (±{1e3 * t0_unc:.2f} ms, 1σ); dim the LED or shorten the exposure")
    if t0 is not None and readout_s > 0:
        # The LED's rows are exposed readout·y/H after the frame time. Its
        # position before the input starts is where it switched (the
        # blade is at rest until then); the first clean frame shows it.
        if led_xy is not None:
            led_row = float(info.sensor_rows(np.asarray(led_xy, dtype=np.float64)))
        else:
            led_row = led_row_px(snapshot, led_spec, info) if snapshot is not None else None
        if led_row is None:
            warnings.append("rolling shutter: LED not found in the reference frame; "
                            "t0 not corrected for the LED's row")
        else:
            t0 = t0 + readout_s * led_row / info.sensor_height
    out.t0_s, out.t0_uncertainty_s, out.t0_window = t0, t0_unc, t0_window
    return out


def stays_down(level: np.ndarray) -> str:
    """Why a level (1 lit, 0 dark) that goes dark does not stay dark; "" when it does (or never goes dark).

    From its first dark frame on, at least :data:`LED_STAY_FRAMES` measured frames, and
    :data:`LED_STAY_SHARE` of them dark.
    """
    ok = np.isfinite(level)
    dark = np.flatnonzero(ok & (level <= 0.5))
    if dark.size == 0:
        return ""
    after = level[dark[0]:][ok[dark[0]:]]
    if after.size < LED_STAY_FRAMES:
        return f"goes dark only in the video's last {after.size} frames"
    if np.mean(after <= 0.5) < LED_STAY_SHARE:
        return "does not stay dark after it goes dark"
    return ""
