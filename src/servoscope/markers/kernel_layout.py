"""The YUV kernels' shared ground: parameter/output row layouts, compile flags, scalar helpers.

See :mod:`servoscope.markers.kernels` for what the kernels compute; the numpy
reference (:mod:`.kernel_numpy`) and the compiled kernel (:mod:`.kernel_numba`)
both read and write these layouts and share these helpers.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["FASTMATH", "LED_NP", "LED_NQ", "N_BINS", "NP", "NQ", "P", "Q", "atan2_nb", "atan2_np",
           "chroma_window", "chroma_window_nb", "led_centre", "nearest_filled_bin", "soft_moments_out"]

#: Angular bins of the background ring.
N_BINS = 48

#: LLVM's fast-math flags that keep IEEE NaN and infinity semantics (the kernels use NaN as "not
#: measured") and the order of every sum: fused multiply-add, reciprocal for division, the sign
#: of zero. ~7 % off the kernel; results move at the 1e-16 level (the numpy reference is held to
#: 1e-9). Not "reassoc": with it LLVM vectorizes the sums behind run-time checks on where the
#: arrays lie in memory, so the same frame summed in another process could round differently
#: (found by the test that tracks must be bit-identical in-process and on Dask workers).
FASTMATH = {"contract", "arcp", "nsz"}


class P:
    """Column indices of a marker's parameter row (float64)."""

    X0, Y0, X1, Y1 = 0, 1, 2, 3  # window, luma pixels, half-open
    YM, UM, VM = 4, 5, 6  # marker colour (DN)
    DIR_U, DIR_V = 7, 8  # unit chroma direction of the marker (from neutral 128)
    COS_TOL = 9  # cos of the hue tolerance
    SAT_MIN = 10  # chroma saturation floor (DN)
    AGREE = 11  # luma's α is trusted where it is within this of chroma's (ramp ±0.1)
    RADIUS = 12  # support radius (px)
    RING = 13  # ring width (px)
    W_Y = 14  # luma weight
    ITER = 15  # recentring passes
    ENABLED = 16
    VAR_Y, VAR_C = 17, 18  # noise variance of luma and of each chroma channel (DN²)
    ALPHA_LO, ALPHA_HI = 19, 20
    MIN_DEN = 21  # least w_Y·c_Y² + |c_C|² for unmixing (DN²); below: the class flag
    CX, CY = 22, 23  # centre to use when USE_CENTRE (else the class's centroid)
    USE_CENTRE = 24
    # A rectangular sticker (a square, a tape strip): support and ring follow its outline, a
    # rectangle of half-sides HALF_U × HALF_V whose U axis points along (COS, SIN) in the image
    # (x right, frame rows down), grown by RECT_MARGIN px with round corners; the ring lies
    # 1 to 1 + RING px beyond that. RECT = 0: the disk of RADIUS (round stickers).
    RECT, HALF_U, HALF_V, COS, SIN, RECT_MARGIN = 25, 26, 27, 28, 29, 30


NP = 31


class Q:
    """Column indices of a marker's output row (float64)."""

    N = 0  # class pixels in the window
    BX, BY = 1, 2  # class centroid
    BXX, BXY, BYY = 3, 4, 5  # class central second moments / N
    M00, X, Y = 6, 7, 8  # soft moments
    MU20, MU11, MU02 = 9, 10, 11  # central second moments / m00
    VAR_X, VAR_Y = 12, 13  # centroid variance from pixel noise (px²)
    CONTRAST = 14  # RMS |M − b| over the support (DN)
    AT_BORDER = 15  # the support or its ring left the image
    RING_N = 16  # ring pixels used
    XMIN, YMIN, XMAX, YMAX = 17, 18, 19, 20  # bounding box of the class pixels
    BG_Y = 21  # mean background luma of the ring


NQ = 22


#: LED parameters: enabled, local x, local y (in the trail→lead frame, units of
#: the marker separation), disk radius (px).
LED_NP = 4
#: LED outputs: mean luma over the disk (NaN when not measured), pixels, centre x, centre y.
LED_NQ = 4


# ---------------------------------------------------------------------------
# shared scalar helpers (compiled; the numpy reference mirrors them op by op)
# ---------------------------------------------------------------------------
@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
def atan2_nb(y, x):
    """atan2 to ~1e-5 rad (a minimax polynomial): only bins the ring by angle."""
    ax = abs(x)
    ay = abs(y)
    mx = max(ax, ay)
    if mx == 0.0:
        return 0.0
    a = min(ax, ay) / mx
    s = a * a
    r = ((-0.0464964749 * s + 0.15931422) * s - 0.327622764) * s * a + a
    if ay > ax:
        r = 1.5707963267948966 - r
    if x < 0.0:
        r = 3.141592653589793 - r
    if y < 0.0:
        r = -r
    return r


def atan2_np(y, x):
    """:func:`atan2_nb` on arrays, op by op (the numpy reference's)."""
    ax = np.abs(x)
    ay = np.abs(y)
    mx = np.maximum(ax, ay)
    a = np.minimum(ax, ay) / np.where(mx == 0.0, 1.0, mx)
    s = a * a
    r = ((-0.0464964749 * s + 0.15931422) * s - 0.327622764) * s * a + a
    r = np.where(ay > ax, 1.5707963267948966 - r, r)
    r = np.where(x < 0.0, 3.141592653589793 - r, r)
    r = np.where(y < 0.0, -r, r)
    return np.where(mx == 0.0, 0.0, r)


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
def led_centre(out, led):
    """The LED's centre (px) from the markers' centroids in ``out`` and its place ``led`` in their frame."""
    # The LED's place in the trail→lead frame (x along the axis, y across it).
    ox, oy = out[1, 7], out[1, 8]
    ax, ay = out[0, 7] - ox, out[0, 8] - oy
    length = math.sqrt(ax * ax + ay * ay)
    ex, ey = ax / length, ay / length
    nx, ny = -ey, ex
    cx = ox + length * (led[1] * ex + led[2] * nx)
    cy = oy + length * (led[1] * ey + led[2] * ny)
    return cx, cy


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
def nearest_filled_bin(cnt, k):
    """Bin ``k`` of the background ring if it holds pixels, else the nearest one that does (either way round)."""
    if cnt[k] != 0.0:
        return k
    n = cnt.shape[0]
    for step in range(1, n):
        a = (k - step) % n
        if cnt[a] > 0.0:
            return a
        b = (k + step) % n
        if cnt[b] > 0.0:
            return b
    return k


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
def soft_moments_out(buf, ns, ia, iva, m00, m10, m01, cx, cy, c2s, out):
    """A marker's soft centroid, central second moments and their noise into its output row.

    ``buf[:ns]`` holds each support pixel's offset from the centre (cx, cy) in columns 0
    and 1, its membership in column ``ia`` and the membership's variance in ``iva``;
    ``m00, m10, m01`` are the membership's raw sums, ``c2s`` the sum of the squared
    contrasts. Shared by the colour and the monochrome kernels, whose unmixing differs
    and whose moments do not (inlined: the same operations, in the same order, in each).
    """
    xb = m10 / m00
    yb = m01 / m00
    m20 = 0.0
    m11 = 0.0
    m02 = 0.0
    vx = 0.0
    vy = 0.0
    for s in range(ns):
        ex = buf[s, 0] - xb
        ey = buf[s, 1] - yb
        a = buf[s, ia]
        m20 += a * ex * ex
        m11 += a * ex * ey
        m02 += a * ey * ey
        vx += buf[s, iva] * ex * ex
        vy += buf[s, iva] * ey * ey
    out[7] = cx + xb
    out[8] = cy + yb
    out[9] = m20 / m00
    out[10] = m11 / m00
    out[11] = m02 / m00
    out[12] = vx / (m00 * m00)
    out[13] = vy / (m00 * m00)
    out[14] = math.sqrt(c2s / ns) if ns > 0 else 0.0


def chroma_window(prm, row_off, row_step, hc, wc):
    """A marker window (luma rows/columns in ``prm``) as chroma-plane bounds (i0, i1, j0, j1)."""
    x0, y0, x1, y1 = int(prm[0]), int(prm[1]), int(prm[2]), int(prm[3])
    r0 = row_off + row_step * y0
    r1 = row_off + row_step * (y1 - 1)
    return max(0, x0 // 2), min(wc, (x1 + 1) // 2), max(0, r0 // 2), min(hc, r1 // 2 + 1)


chroma_window_nb = njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")(chroma_window)

