"""The monochrome kernel: brightness markers' soft moments on the camera's native samples (issue 28, build 3).

What the YUV kernel (:mod:`.kernels`) does per marker, luma-only and on the
samples as stored (uint8 or uint16, or Photron's packed 12-bit bytes, read
through :func:`~servoscope.video.native.sample_at`): no conversion to 8 bits,
RGB or YUV, and only the markers' windows and the LED's disk are read. For
each marker, inside its window:

1. **classify** every pixel by its level: at or above the threshold (a
   bright marker; at or below for a dark one). The class's binary moments
   give a coarse centre, the detection and its bounding box;
2. sample the **local background** on a ring 1 to 1 + ``ring`` px beyond the
   support disk, class pixels left out, binned by angle (a blade/sky edge
   across the ring is followed bin by bin, interpolated between bins);
3. **unmix** every pixel of the support disk between the marker's level ``M``
   and its own background ``b``: ``α = (p − b) / (M − b)``, clipped to
   [``alpha_lo``, ``alpha_hi``]; where ``|M − b|`` is under ``min_contrast``
   the class flag is the weight. The noise of α is ``σ² / (M − b)²``;
4. accumulate the weighted moments m00, m10, m01, the second moments and
   the noise-propagation sums, and recentre (``iterations`` passes).

Levels, thresholds and noise are in the samples' own units (DN of ``n``
bits); the engine (:mod:`.mono_engine`) scales what it learns in 8-bit units
by ``(2^n − 1) / 255``. The output row is :class:`~.kernel_layout.Q`'s, so
that the engines' checks read it as they read the YUV kernel's; the
parameter row is :class:`MP` (the columns it shares with
:class:`~.kernel_layout.P` at the same places).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ..video.native import sample_at
from .kernel_layout import FASTMATH, N_BINS, NP, atan2_nb, led_centre, nearest_filled_bin, soft_moments_out

__all__ = ["MONO_LED_NQ", "MONO_NP", "MP", "mono_led_level", "track_frame_mono"]


class MP:
    """Column indices of a marker's parameter row in the monochrome kernel (float64; P's places where shared)."""

    X0, Y0, X1, Y1 = 0, 1, 2, 3  # window, pixels, half-open
    LEVEL = 4  # the marker's level M (DN of the samples)
    THRESHOLD = 5  # class threshold (DN)
    SIGN = 6  # +1: a bright marker (class at or above the threshold); -1: a dark one
    STEP = 7  # the class is sampled every STEP pixels each way (1: every pixel)
    RADIUS = 12  # support radius (px)
    RING = 13  # ring width (px)
    ITER = 15  # recentring passes
    ENABLED = 16
    VAR = 17  # noise variance of a sample (DN²)
    ALPHA_LO, ALPHA_HI = 19, 20
    MIN_CONTRAST = 21  # least |M − b| (DN) for unmixing; below: the class flag
    CX, CY = 22, 23  # centre to use when USE_CENTRE (else the class's centroid)
    USE_CENTRE = 24
    RECT = 25  # always 0: round supports only (a rectangular sticker is measured as a disk around it)


#: Width of a parameter row: the YUV kernel's, so that the shared columns mean the same.
MONO_NP = NP
#: LED outputs: the YUV kernel's four (mean, pixels, centre x, centre y) and the disk's peak sample.
MONO_LED_NQ = 5


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
def _pair(kf):
    """Bins k, k+1 (mod N_BINS) around an interpolation position ``kf`` in [-1, N_BINS - 1]."""
    k0 = int(kf)
    if k0 < 0:
        k0 += N_BINS
    k1 = k0 + 1
    if k1 == N_BINS:
        k1 = 0
    return k0, k1


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def _marker_mono(img, packed, width, prm, out, buf):
    """One marker's soft moments in its window: parameters in ``prm`` (:class:`MP`), results in ``out`` (Q).

    Long because it is one fused, compiled pass over a window's pixels (as the YUV
    kernel's ``_marker_nb``): split, numba would keep the loops apart.
    """
    for i in range(out.shape[0]):
        out[i] = 0.0
    if prm[16] == 0.0:
        return
    h = img.shape[0]
    w = width
    x0 = int(prm[0])
    y0 = int(prm[1])
    x1 = int(prm[2])
    y1 = int(prm[3])
    thr = prm[5]
    sign = prm[6]
    n = 0.0
    sx = 0.0
    sy = 0.0
    sxx = 0.0
    sxy = 0.0
    syy = 0.0
    xmin = 1e300
    ymin = 1e300
    xmax = -1e300
    ymax = -1e300
    step = int(prm[7])
    for y in range(y0, y1, step):
        qy = float(y - y0)
        for x in range(x0, x1, step):
            v = sample_at(img, y, x, packed)
            if sign * (v - thr) >= 0.0:
                qx = float(x - x0)
                n += 1.0
                sx += qx
                sy += qy
                sxx += qx * qx
                sxy += qx * qy
                syy += qy * qy
                xmin = min(xmin, qx)
                xmax = max(xmax, qx)
                ymin = min(ymin, qy)
                ymax = max(ymax, qy)
    out[0] = n * step * step  # each sample stands for step × step pixels
    if n == 0.0:
        return
    bx = sx / n
    by = sy / n
    out[1] = bx + x0
    out[2] = by + y0
    out[3] = sxx / n - bx * bx
    out[4] = sxy / n - bx * by
    out[5] = syy / n - by * by
    out[17] = xmin + x0
    out[18] = ymin + y0
    out[19] = xmax + x0
    out[20] = ymax + y0
    if prm[24] != 0.0:
        cx = prm[22]
        cy = prm[23]
    else:
        cx = out[1]
        cy = out[2]
    level = prm[4]
    radius = prm[12]
    outer = radius + 1.0 + prm[13]
    r_in2 = (radius + 1.0) * (radius + 1.0)
    r_out2 = outer * outer
    r2 = radius * radius
    alo = prm[19]
    ahi = prm[20]
    min_c = prm[21]
    var = prm[17]
    scale = N_BINS / (2.0 * math.pi)
    cnt = np.zeros(N_BINS)
    bs = np.zeros(N_BINS)
    bg = np.zeros(N_BINS)
    for _ in range(max(1, int(prm[15]))):
        ax0 = int(math.floor(cx - outer))
        ay0 = int(math.floor(cy - outer))
        ax1 = int(math.ceil(cx + outer)) + 1
        ay1 = int(math.ceil(cy + outer)) + 1
        border = ax0 < 0 or ay0 < 0 or ax1 > w or ay1 > h
        ax0 = max(ax0, 0)
        ay0 = max(ay0, 0)
        ax1 = min(ax1, w)
        ay1 = min(ay1, h)
        if ax1 - ax0 < 3 or ay1 - ay0 < 3:
            out[6] = 0.0
            return
        for k in range(N_BINS):
            cnt[k] = 0.0
            bs[k] = 0.0
        ring_n = 0.0
        ring_s = 0.0
        ns = 0
        # One sweep: ring pixels into the angle bins, support pixels (with their bin position) into the buffer.
        for y in range(ay0, ay1):
            dy = float(y) - cy
            rem = r_out2 - dy * dy
            if rem < 0.0:
                continue
            # Only the row's chord of the outer disk: the box's corners hold neither support nor ring.
            half = math.sqrt(rem)
            for x in range(max(ax0, int(math.floor(cx - half))), min(ax1, int(math.ceil(cx + half)) + 1)):
                dx = float(x) - cx
                d2 = dx * dx + dy * dy
                if d2 > r_out2 or (d2 > r2 and d2 < r_in2):
                    continue
                v = sample_at(img, y, x, packed)
                t = (atan2_nb(dy, dx) + math.pi) * scale
                if d2 <= r2:
                    buf[ns, 0] = dx
                    buf[ns, 1] = dy
                    buf[ns, 2] = v
                    buf[ns, 3] = t - 0.5
                    ns += 1
                    continue
                if sign * (v - thr) >= 0.0:
                    continue  # the marker's own (or another bright thing's) pixels are not background
                k = min(int(t), N_BINS - 1)
                cnt[k] += 1.0
                bs[k] += v
                ring_n += 1.0
                ring_s += v
        have_bg = ring_n >= 8.0
        if have_bg:
            for k in range(N_BINS):
                src = nearest_filled_bin(cnt, k)
                bg[k] = bs[src] / cnt[src]
        m00 = 0.0
        m10 = 0.0
        m01 = 0.0
        c2s = 0.0
        for s in range(ns):
            dx = buf[s, 0]
            dy = buf[s, 1]
            v = buf[s, 2]
            a = 0.0
            va = 0.0
            unmixed = False
            if have_bg:
                t = buf[s, 3]
                kf = math.floor(t)
                f = t - kf
                k0, k1 = _pair(kf)
                b = bg[k0] * (1.0 - f) + bg[k1] * f
                c = level - b
                c2s += c * c
                if abs(c) >= min_c:
                    a = min(max((v - b) / c, alo), ahi)
                    va = var / (c * c)
                    unmixed = True
            if not unmixed:
                a = 1.0 if sign * (v - thr) >= 0.0 else 0.0
            buf[s, 4] = a
            buf[s, 5] = va
            m00 += a
            m10 += a * dx
            m01 += a * dy
        out[6] = m00
        out[15] = 1.0 if border else 0.0
        out[16] = ring_n
        out[21] = ring_s / ring_n if have_bg else math.nan
        if not m00 > 0.0:
            return
        soft_moments_out(buf, ns, 4, 5, m00, m10, m01, cx, cy, c2s, out)
        cx = out[7]
        cy = out[8]


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def mono_led_level(img, packed, width, led, out, led_out):
    """Mean and peak sample over the LED's disk, placed by the markers' centroids in ``out`` (NaN: not measured).

    ``led`` is the YUV kernel's LED row (enabled, place in the markers' frame,
    radius); ``led_out``: mean, pixels, centre x, centre y, peak.
    """
    for i in range(led_out.shape[0]):
        led_out[i] = math.nan
    led_out[1] = 0.0
    if led[0] == 0.0 or not (out[0, 6] > 0.0 and out[1, 6] > 0.0):
        return
    cx, cy = led_centre(out, led)
    r = led[3]
    h = img.shape[0]
    x0 = int(max(0.0, math.floor(cx - r)))
    x1 = int(min(float(width), math.floor(cx + r) + 1))
    y0 = int(max(0.0, math.floor(cy - r)))
    y1 = int(min(float(h), math.floor(cy + r) + 1))
    led_out[2] = cx
    led_out[3] = cy
    s = 0.0
    n = 0.0
    peak = -1.0
    for y in range(y0, y1):
        for x in range(x0, x1):
            dx = x - cx
            dy = y - cy
            if dx * dx + dy * dy <= r * r:
                v = sample_at(img, y, x, packed)
                s += v
                n += 1.0
                peak = max(peak, v)
    led_out[1] = n
    if n > 0.0:
        led_out[0] = s / n
        led_out[4] = peak


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def track_frame_mono(img, packed, width, params, led, out, led_out):
    """Measure every marker row of ``params`` (and the LED) in one frame's samples; fills ``out`` and ``led_out``.

    Parameters
    ----------
    img : ndarray, 2-D, uint8 or uint16
        The frame's samples (any strides: a memory-mapped file's view), or
        packed 12-bit bytes (``packed``).
    packed : bool
    width : int
        The frame's width in samples.
    params : ndarray, shape (markers, MONO_NP)
    led : ndarray, shape (LED_NP,)
    out : ndarray, shape (markers, NQ)
    led_out : ndarray, shape (5,)
    """
    size = 0
    for k in range(params.shape[0]):
        side = 2 * int(params[k, 12] + 1.0 + params[k, 13]) + 4
        size = max(size, side * side)
    buf = np.empty((size, 6))
    for k in range(params.shape[0]):
        _marker_mono(img, packed, width, params[k], out[k], buf)
    mono_led_level(img, packed, width, led, out, led_out)


