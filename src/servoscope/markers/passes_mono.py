"""A turning rotor on monochrome footage: bright stickers frame by frame, the blades told by their order.

A monochrome high-speed camera (a Photron MRAW, a Phantom CINE, a TIFF sequence) has no
colour to tell the blades by: every blade carries bright stickers (``[rotor] blades`` all
``{lead = "bright", trail = "bright"}``). Per frame (:func:`scan_rotor_mono`, on the
camera's native samples, :func:`~servoscope.video.native.iter_native_frames`):

1. **a cheap test first**: every 4th row unpacked, every 4th sample of it compared with the
   threshold (halfway between the picture's typical level and its brightest stickers', as
   :class:`~servoscope.markers.colour.BrightnessModel` sets it, from :data:`THRESHOLD_FRAMES` frames
   spread over the clip: :func:`coarse_threshold`); the LED's fixed disk left
   out (the LED is the one bright blob of one of the first :data:`~servoscope.markers.passes.LED_TRIES`
   frames; blades are looked for once it is found or given up). A frame with fewer than :data:`~servoscope.markers.passes.MIN_COARSE` samples
   above it is empty;
2. the coarse samples' blobs: the two of the four largest most nearly side by side and
   alike in size are the stickers, the one on the right the
   lead (the leading edge on the picture's right, as ``servoscope track`` reads "bright"
   markers); each measured by the monochrome kernel
   (:func:`~servoscope.markers.kernel_mono.track_frame_mono`: luma-only unmixing in the
   samples' own DN) over a disk that holds its motion blur. A sticker is whole when its
   disk and ring lie inside the picture. A blob where the previous frame had one
   (:data:`STATIC_COARSE_PX`) is not a sticker but something fixed: a lamp, a glint, an LED
   the campaign does not name (the tip crosses a picture in a few frames, tens of pixels a
   frame). Without that, a sticker leaving the picture was paired with such a blob (5 of 77
   frames on the twin's clip with its LED not named).

The blade is not known frame by frame: the sightings have one column, and the pipeline
numbers the passes in time order, pass k blade k mod N (blade 0 the first seen; stated).
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from ..video.frame_source import is_frame_source
from ..video.native import NativeFrame, NativeSource, iter_native_frames
from . import kernels as K
from .kernel_mono import MONO_NP, MP, track_frame_mono
from .led_level import LED_PEAK_FRAMES, disk_level_native
from .passes import LED_TRIES, MIN_COARSE, RotorSightings

__all__ = ["coarse_threshold", "scan_rotor_mono"]

#: Support beyond a sticker's extent (px), and the background ring's width (px): as the colour scan's.
SUPPORT_MARGIN_PX = 1.0
RING_PX = 1.0
#: Least sticker/background contrast unmixed, in 8-bit DN (the mono engine's).
MIN_CONTRAST_DN8 = 5.8
#: A blob within this many coarse samples (4 px each) of one in the previous frame is fixed, not a sticker:
#: a tip crossing a 320-px picture in ~10 frames moves ~8 coarse samples a frame (~3 at 10,000 frames/s).
STATIC_COARSE_PX = 0.75
#: Frames, spread evenly over the clip, whose coarse samples set the threshold. The first frame alone may show
#: no sticker: then its brightest samples are the background's bright tail, and the threshold set halfway to
#: them let a fifth of a bright background through (issue 33: 778 of 800 frames "seen", the LED not found).
#: A sticker is in view in 12-18 % of the twin's clips' frames (2-3 blades, 20-30 rev/s): ~8-12 of the 64 show one.
THRESHOLD_FRAMES = 64
#: A video has no cheap random access: its threshold frames are every 8th of its first 512 (0.26 s at 2,000
#: frames/s, four revolutions or more of each blade at 15 rev/s and up), decoded twice, not the whole clip.
VIDEO_THRESHOLD_SPAN = 512


def _coarse(frame) -> np.ndarray:
    """Every 4th sample of every 4th row, as stored (:meth:`~servoscope.video.native.NativeFrame.stored`, the
    levels the mono kernel reads; a view where it can be, in the samples' own type)."""
    return frame.stored(slice(None, None, 4))[:, ::4]


def _spread_frames(path: Path):
    """Up to :data:`THRESHOLD_FRAMES` frames spread evenly over the clip (a video: over its first
    :data:`VIDEO_THRESHOLD_SPAN` frames)."""
    src = NativeSource(path) if is_frame_source(path) else None
    if src is None or not src.header.monochrome:
        if src is not None:
            src.close()
        step = max(VIDEO_THRESHOLD_SPAN // THRESHOLD_FRAMES, 1)
        frames = iter_native_frames(path)
        try:
            yield from itertools.islice(frames, 0, VIDEO_THRESHOLD_SPAN, step)
        finally:
            frames.close()  # its decoder now, not when collected
        return
    try:
        h = src.header
        n = int(h.frame_count)
        for i in np.unique(np.linspace(0, n - 1, min(n, THRESHOLD_FRAMES)).round().astype(int)):
            samples, packed = src.view(int(i))
            yield NativeFrame(int(i), float(h.times_s[i]), samples, packed, h.width, h.bit_depth, src.black,
                              src.white, src.shift)
    finally:
        src.close()


def coarse_threshold(path: str | Path) -> float:
    """The cheap test's brightness threshold (samples' own levels) from frames spread over the clip.

    Halfway between the picture's typical level (the median of the frames' medians) and its brightest
    stickers' (the most of the frames' 99.9th percentiles of the coarse samples): the first frame alone may
    show no sticker. Where the brightest is not clearly above the typical level (by a quarter of the way to
    the white level: the frames show no sticker, only the background or a small LED), halfway to white.

    Parameters
    ----------
    path : path-like
        As :func:`scan_rotor_mono`'s.

    Returns
    -------
    float
    """
    typical, extreme, white = [], -math.inf, math.nan
    for frame in _spread_frames(Path(path)):
        g = _coarse(frame)
        typical.append(float(np.median(g)))
        extreme = max(extreme, float(np.percentile(g, 99.9)))
        white = float(frame.white)
    if not typical:
        return math.inf
    level = float(np.median(typical))
    top = extreme if extreme - level > 0.25 * (white - level) else white
    return 0.5 * (level + top)


def _crop(frame, x0: int, y0: int, x1: int, y1: int) -> np.ndarray:
    """The samples in rows y0:y1, columns x0:x1, as stored (:func:`_coarse`: the levels the kernel reads)."""
    return frame.stored(slice(y0, y1))[:, x0:x1].astype(np.float64)


def _sticker_pair(stats: np.ndarray, cents: np.ndarray, fixed: np.ndarray | None = None) -> np.ndarray:
    """The labels of a blade's two stickers among a frame's bright blobs: of the four largest, the pair most
    nearly side by side (the chord lies along the rows: |Δy| < |Δx|/2) and alike in size; else the largest alone.
    ``fixed``: a flag a label (0, the background, included), blobs that are not stickers."""
    candidates = np.arange(1, stats.shape[0]) if fixed is None else 1 + np.flatnonzero(~fixed[1:])
    top = candidates[np.argsort(stats[candidates, cv2.CC_STAT_AREA])[::-1][:4]]
    if top.size < 2:
        return top
    best, pair = math.inf, top[:2]
    for a in range(top.size):
        for b in range(a + 1, top.size):
            i, j = top[a], top[b]
            dx, dy = abs(cents[i, 0] - cents[j, 0]), abs(cents[i, 1] - cents[j, 1])
            ai, aj = stats[i, cv2.CC_STAT_AREA], stats[j, cv2.CC_STAT_AREA]
            score = dy / (dx + 1.0) + abs(math.log(ai / aj))
            if dy < 0.5 * dx and score < best:
                best, pair = score, np.array([i, j])
    # No two side by side (a sticker and something else bright): the largest alone, seen but not a pair.
    return pair if math.isfinite(best) else top[:1]


def scan_rotor_mono(path: str | Path, *, led: bool = True, led_near: tuple[float, float] | None = None,
                    progress: Callable[[int], None] | None = None) -> RotorSightings:
    """Every frame of a monochrome rotor video: the bright stickers in view, their centroids where whole, the LED.

    Parameters
    ----------
    path : path-like
        A monochrome source (MRAW/CIH, CINE, TIFF sequence) or a video (its luma).
    led : bool
        Whether a bright LED is fixed on the airframe (found in the first frame with no blade).
    led_near : (float, float) or None
        Pin the LED by position (px).
    progress : callable, optional

    Returns
    -------
    RotorSightings
        With one blade column: the blades are told apart by the pipeline, by their order.

    Notes
    -----
    Long because the per-frame loop keeps the cheap test, the close measurement and the
    LED together, in the order a frame needs them.
    """
    path = Path(path)
    time_s, seen_rows, lead_rows, trail_rows, lsig_rows, tsig_rows = [], [], [], [], [], []
    out = RotorSightings(np.zeros(0), np.zeros((0, 1), bool), np.zeros((0, 1, 2)), np.zeros((0, 1, 2)),
                         np.zeros((0, 1)), np.zeros((0, 1)))
    threshold = coarse_threshold(path)
    dn8 = None
    level = None
    led_disk = None
    previous = None  # the last frame's bright blobs' centroids (coarse samples)
    best = (0, None)
    prm = np.zeros((1, MONO_NP))
    res = np.zeros((1, K.NQ))
    for frame in iter_native_frames(path):
        h, w = frame.shape
        out.width, out.height = w, h
        g = _coarse(frame)
        if dn8 is None:
            dn8 = (frame.white - frame.black) / 255.0
        mask = (g >= threshold).view(np.uint8)  # bool's bytes as the 0/1 labels connectedComponents wants
        if led_disk is not None:
            (lx, ly), lr = led_disk
            mask[max(0, int((ly - lr - 4) // 4)):int((ly + lr + 4) // 4) + 1,
                 max(0, int((lx - lr - 4) // 4)):int((lx + lr + 4) // 4) + 1] = 0
        seen = False
        lead_xy = trail_xy = (math.nan, math.nan)
        lsig = tsig = math.nan
        boxes = []
        count = int(np.count_nonzero(mask))
        if count > best[0]:
            jj, ii = np.nonzero(mask)
            best = (count, (frame.index, 4.0 * ii.mean(), 4.0 * jj.mean()))
        looking = led and led_disk is None and frame.index < LED_TRIES
        fixed = None
        if count:
            # Every frame with a bright sample: what stays put from frame to frame is not a sticker.
            n, labels, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
            if previous is not None and previous.size:
                near = np.hypot(cents[:, None, 0] - previous[None, :, 0], cents[:, None, 1] - previous[None, :, 1])
                fixed = near.min(axis=1) <= STATIC_COARSE_PX
            previous = cents[1:].copy()
        else:
            previous = None
        if count >= MIN_COARSE and not looking:
            order = _sticker_pair(stats, cents, fixed)
            if order.size:
                seen = True
            found = []
            for lab in order:
                x, y, bw, bh = (int(v) for v in stats[lab, :4])
                box = (4 * x - 6, 4 * y - 6, 4 * (x + bw) + 5, 4 * (y + bh) + 5)
                boxes.append(box)
                x0, y0 = max(0, box[0]), max(0, box[1])
                x1, y1 = min(w, box[2]), min(h, box[3])
                crop = _crop(frame, x0, y0, x1, y1)
                cls = crop >= threshold
                if cls.sum() < 4:
                    continue
                ys, xs = np.nonzero(cls)
                if level is None and xs.min() > 0 and ys.min() > 0 and xs.max() < crop.shape[1] - 1:
                    core = crop[cls]
                    level = float(np.median(core[core >= np.percentile(core, 50)]))
                    mad = float(np.median(np.abs(core - np.median(core))))
                    var = (1.4826 * mad) ** 2 + 1.0 / 12.0
                if level is None:
                    continue
                hx = 0.5 * (xs.max() - xs.min() + 1)
                hy = 0.5 * (ys.max() - ys.min() + 1)
                cx, cy = x0 + 0.5 * (xs.min() + xs.max()), y0 + 0.5 * (ys.min() + ys.max())
                radius = max(hx, hy) + SUPPORT_MARGIN_PX + 0.5
                reach = radius + 1.0 + RING_PX
                whole = cx - reach >= 0 and cy - reach >= 0 and cx + reach <= w - 1 and cy + reach <= h - 1
                if not whole:
                    found.append((cx, None))
                    continue
                p = prm[0]
                p[:] = 0.0
                p[MP.X0], p[MP.Y0], p[MP.X1], p[MP.Y1] = x0, y0, x1, y1
                p[MP.LEVEL], p[MP.THRESHOLD], p[MP.SIGN], p[MP.STEP] = level, threshold, 1.0, 1.0
                p[MP.RADIUS], p[MP.RING], p[MP.ITER], p[MP.ENABLED] = radius, RING_PX, 2.0, 1.0
                p[MP.VAR] = var
                p[MP.ALPHA_LO], p[MP.ALPHA_HI] = 0.0, 1.0
                p[MP.MIN_CONTRAST] = MIN_CONTRAST_DN8 * dn8
                track_frame_mono(frame.samples, frame.packed, frame.width, prm, np.zeros(K.LED_NP), res,
                                 np.zeros(5))
                r = res[0]
                if not (r[K.Q.M00] > 0 and r[K.Q.RING_N] >= 8 and r[K.Q.AT_BORDER] == 0):
                    found.append((cx, None))
                    continue
                found.append((float(r[K.Q.X]), (float(r[K.Q.X]), float(r[K.Q.Y]),
                                                math.sqrt(0.5 * (r[K.Q.VAR_X] + r[K.Q.VAR_Y])))))
            if len(found) == 2 and found[0][1] is not None and found[1][1] is not None:
                right, left = sorted(found, key=lambda f: -f[0])
                lead_xy, lsig = right[1][:2], right[1][2]
                trail_xy, tsig = left[1][:2], left[1][2]
        if looking and count:
            # The LED: the bright blob of the first frame with no blade (or the one at led_near), among the blobs
            # labelled above.
            if n > 1:
                if led_near is not None:
                    lab = 1 + int(np.argmin(np.hypot(4 * cents[1:, 0] - led_near[0], 4 * cents[1:, 1] - led_near[1])))
                else:
                    lab = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
                if n == 2 or led_near is not None:
                    x, y, bw, bh = (int(v) for v in stats[lab, :4])
                    x0, y0 = max(0, 4 * x - 6), max(0, 4 * y - 6)
                    crop = _crop(frame, x0, y0, min(w, 4 * (x + bw) + 6), min(h, 4 * (y + bh) + 6))
                    ys, xs = np.nonzero(crop >= threshold)
                    if xs.size >= 3:
                        centre = (x0 + float(xs.mean()), y0 + float(ys.mean()))
                        led_disk = (centre, 1.5 * math.sqrt(xs.size / math.pi) + 1.0)
                        out.led_xy_px = centre
                        out.snapshot_rgb = frame.rgb
                        seen = False
        lvl = math.nan
        if led_disk is not None:
            (lx, ly), lr = led_disk
            covered = any(b[0] - lr <= lx <= b[2] + lr and b[1] - lr <= ly <= b[3] + lr for b in boxes)
            if not covered:
                # Compiled on the stored samples: NumPy's crop, mask and mean were a fifth of the scan.
                mean, peak = disk_level_native(frame.samples, frame.packed, frame.width, lx, ly, lr)
                # In 8-bit DN, as input_start reads a video's LED.
                lvl = float(frame.to_8bit(mean))
                if len(out.led_peak_dn) < LED_PEAK_FRAMES:
                    out.led_peak_dn.append(float(frame.to_8bit(peak)))
        out.led_level_dn.append(lvl)
        time_s.append(frame.time_s)
        seen_rows.append([seen])
        lead_rows.append([lead_xy])
        trail_rows.append([trail_xy])
        lsig_rows.append([lsig])
        tsig_rows.append([tsig])
        if progress is not None and frame.index % 200 == 0:
            progress(frame.index + 1)
    n = len(time_s)
    if led and led_disk is None:
        out.led_level_dn = [math.nan] * n
    out.time_s = np.asarray(time_s, dtype=np.float64)
    out.seen = np.asarray(seen_rows, dtype=bool).reshape(n, 1)
    out.lead_xy_px = np.asarray(lead_rows, dtype=np.float64).reshape(n, 1, 2)
    out.trail_xy_px = np.asarray(trail_rows, dtype=np.float64).reshape(n, 1, 2)
    out.lead_sigma_px = np.asarray(lsig_rows, dtype=np.float64).reshape(n, 1)
    out.trail_sigma_px = np.asarray(tsig_rows, dtype=np.float64).reshape(n, 1)
    out.colours_seen = [("bright stickers: not seen" if best[1] is None else
                         f"bright stickers: at most {best[0]} coarse samples above {threshold:.0f} DN (frame "
                         f"{best[1][0]}, around x={best[1][1]:.0f}, y={best[1][2]:.0f} px)")]
    return out
