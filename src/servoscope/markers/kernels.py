"""The fused per-frame tracking kernel, on the decoder's native YUV 4:2:0 planes.

One call per frame measures both markers (and the LED) without converting
the frame to RGB: for each marker, inside its tracking window,

1. **classify** every luma pixel by *chroma* (identity): its (Cb, Cr), taken
   bilinearly from the half-resolution chroma planes, must point within a
   hue tolerance of the marker's chroma direction with a saturation above a
   floor (robust to brightness). The class's binary moments give a coarse
   centre, the detection and its bounding box;
2. sample the **local background** on a ring around that centre, binned by
   angle (a blade/sky edge across the ring is followed bin by bin);
3. **unmix** every pixel of the support disk between the marker's colour
   ``M`` and its own background ``b`` (the ring bin in its direction):

       α = (w_Y·c_Y·r_Y + c_U·r_U + c_V·r_V) / (w_Y·c_Y² + c_U² + c_V²),
       c = M − b,  r = p − b,

   the blend ``α = (w_Y·c_Y²·α_Y + |c_C|²·α_C) / (w_Y·c_Y² + |c_C|²)`` of
   the luma-only ``α_Y = r_Y / c_Y`` and the chroma-only
   ``α_C = c_C·r_C / |c_C|²`` (each clipped to [``alpha_lo``, ``alpha_hi``]
   first, so that a background luma step far above a weak luma contrast
   cannot dominate): with ``w_Y`` ≫ 1 the sharp, full-resolution luma sets
   the sub-pixel weight wherever the marker/background luma contrast is
   adequate, and the (smeared) chroma takes over where it is weak — a
   sticker whose luma equals the blade's or the sky's. Unclipped, it is the
   least-squares unmixing ``(w_Y·c_Y·r_Y + c_C·r_C) / (w_Y·c_Y² + |c_C|²)``.
   Luma's weight is kept only where ``α_Y`` agrees with ``α_C`` (within
   ``agree`` ± 0.1, a ramp): a background pixel whose luma happens to equal
   the marker's (sky next to a green sticker, where the ring's bin mixes
   sky and blade) is then told by its chroma. The two are compared at
   *chroma's* resolution: ``α_Y`` is averaged over the 2×2 blocks the
   writer averaged the chroma over and read bilinearly at chroma's siting,
   exactly as ``α_C``'s chroma was (chroma is linear in the mixture, so
   where luma's background is right the two agree to noise, also across
   the sticker's edge). Compared pixel by pixel, the half-resolution
   chroma's smear made them disagree by 0.2–0.5 all along the edge, so
   luma was dropped exactly where its sharpness matters; a marker whose
   chroma contrast is weak and luma contrast strong (magenta on a dark
   blade) then took the codec's chroma error in full;
4. accumulate the weighted moments m00, m10, m01, the second moments and
   the noise-propagation sums, and recentre (``iterations`` passes).

Then the LED: its disk follows the markers' axis (its position in the
markers' frame is learned once); the mean luma over it is its level.

:func:`track_frame_numpy` is the plain-numpy reference of the same maths;
:func:`track_frame_numba` the compiled one (``nogil``: a decoder thread runs
meanwhile). Both take and fill the same arrays (layouts below) and agree to
rounding (the tests hold them to 1e-9).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "P", "Q", "NP", "NQ", "LED_NP", "LED_NQ", "N_BINS",
    "track_frame_numpy", "track_frame_numba", "track_frame", "led_level_numpy", "led_level_numba",
    "ENGINES", "LED_ENGINES", "chroma_window", "chroma_np", "classify_np",
]

#: Angular bins of the background ring.
N_BINS = 48

#: LLVM's fast-math flags that keep IEEE NaN and infinity semantics (the kernels use NaN as "not
#: measured") and the order of every sum: fused multiply-add, reciprocal for division, the sign
#: of zero. ~7 % off the kernel; results move at the 1e-16 level (the numpy reference is held to
#: 1e-9). Not "reassoc": with it LLVM vectorizes the sums behind run-time checks on where the
#: arrays lie in memory, so the same frame summed in another process could round differently
#: (found by the test that tracks must be bit-identical in-process and on Dask workers).
_FAST = {"contract", "arcp", "nsz"}


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
@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _atan2(y, x):
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


def _atan2_np(y, x):
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


@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _led_centre(out, led):
    # The LED's place in the trail→lead frame (x along the axis, y across it).
    ox, oy = out[1, 7], out[1, 8]
    ax, ay = out[0, 7] - ox, out[0, 8] - oy
    length = math.sqrt(ax * ax + ay * ay)
    ex, ey = ax / length, ay / length
    nx, ny = -ey, ex
    cx = ox + length * (led[1] * ex + led[2] * nx)
    cy = oy + length * (led[1] * ey + led[2] * ny)
    return cx, cy


def chroma_window(prm, row_off, row_step, hc, wc):
    """A marker window (luma rows/columns in ``prm``) as chroma-plane bounds (i0, i1, j0, j1)."""
    x0, y0, x1, y1 = int(prm[0]), int(prm[1]), int(prm[2]), int(prm[3])
    r0 = row_off + row_step * y0
    r1 = row_off + row_step * (y1 - 1)
    return max(0, x0 // 2), min(wc, (x1 + 1) // 2), max(0, r0 // 2), min(hc, r1 // 2 + 1)


_chroma_window_nb = njit(cache=True, nogil=True, fastmath=_FAST, inline="always")(chroma_window)


# ---------------------------------------------------------------------------
# numpy reference
# ---------------------------------------------------------------------------
def _chroma_neighbours_np(xs, ys, row_off, row_step, hc, wc):
    """The 2×2 chroma samples around luma pixels (xs, ys) and the bilinear fractions.

    Chroma sample (i, j) sits at luma (2i+.5, 2j+.5); samples beyond the
    plane's edge are clamped to it. Returns (ia, ib, ja, jb, fx, fy).
    """
    cx = (xs - 0.5) * 0.5
    cy = (row_off + row_step * ys - 0.5) * 0.5
    i0 = np.floor(cx)
    j0 = np.floor(cy)
    fx = cx - i0
    fy = cy - j0
    i0 = i0.astype(np.int64)
    j0 = j0.astype(np.int64)
    return (np.clip(i0, 0, wc - 1), np.clip(i0 + 1, 0, wc - 1), np.clip(j0, 0, hc - 1), np.clip(j0 + 1, 0, hc - 1),
            fx, fy)


def chroma_np(plane, xs, ys, row_off, row_step):
    """Bilinear chroma at luma pixels (xs, ys); chroma sample (i, j) sits at luma (2i+.5, 2j+.5)."""
    ia, ib, ja, jb, fx, fy = _chroma_neighbours_np(xs, ys, row_off, row_step, *plane.shape)
    p = plane
    top = p[ja, ia].astype(np.float64) * (1.0 - fx) + p[ja, ib].astype(np.float64) * fx
    bot = p[jb, ia].astype(np.float64) * (1.0 - fx) + p[jb, ib].astype(np.float64) * fx
    return top * (1.0 - fy) + bot * fy


def classify_np(prm, uv, vv):
    """Chroma samples of the marker's class: saturated enough and within its hue cone."""
    u = uv - 128.0
    v = vv - 128.0
    sat = np.sqrt(u * u + v * v)
    return (sat >= prm[P.SAT_MIN]) & ((u * prm[P.DIR_U] + v * prm[P.DIR_V]) >= prm[P.COS_TOL] * sat)


def _marker_np(Y, U, V, row_off, row_step, prm, out):
    out[:] = 0.0
    if prm[P.ENABLED] == 0.0:
        return
    h, w = Y.shape
    hc, wc = U.shape
    x0, y0 = prm[P.X0], prm[P.Y0]
    i0, i1, j0, j1 = chroma_window(prm, row_off, row_step, hc, wc)
    jj, ii = np.mgrid[j0:j1, i0:i1]
    cls = classify_np(prm, U[j0:j1, i0:i1].astype(np.float64), V[j0:j1, i0:i1].astype(np.float64))
    wq = 4.0 / row_step
    qx = (2.0 * ii[cls] + 0.5) - x0
    qy = ((2.0 * jj[cls] + 0.5 - row_off) / row_step) - y0
    n = wq * cls.sum()
    out[Q.N] = n
    if n == 0.0:
        return
    sx, sy = wq * qx.sum(), wq * qy.sum()
    sxx, sxy, syy = wq * (qx * qx).sum(), wq * (qx * qy).sum(), wq * (qy * qy).sum()
    bx, by = sx / n, sy / n
    out[Q.BX], out[Q.BY] = bx + x0, by + y0
    out[Q.BXX] = sxx / n - bx * bx
    out[Q.BXY] = sxy / n - bx * by
    out[Q.BYY] = syy / n - by * by
    out[Q.XMIN], out[Q.XMAX] = qx.min() + x0, qx.max() + x0
    out[Q.YMIN], out[Q.YMAX] = qy.min() + y0, qy.max() + y0
    cx, cy = (prm[P.CX], prm[P.CY]) if prm[P.USE_CENTRE] != 0.0 else (out[Q.BX], out[Q.BY])
    radius = prm[P.RADIUS]
    outer = radius + 1.0 + prm[P.RING]
    wy = prm[P.W_Y]
    scale = N_BINS / (2.0 * math.pi)
    for _ in range(max(1, int(prm[P.ITER]))):
        ax0 = int(math.floor(cx - outer))
        ay0 = int(math.floor(cy - outer / row_step))
        ax1 = int(math.ceil(cx + outer)) + 1
        ay1 = int(math.ceil(cy + outer / row_step)) + 1
        border = ax0 < 0 or ay0 < 0 or ax1 > w or ay1 > h
        ax0, ay0, ax1, ay1 = max(ax0, 0), max(ay0, 0), min(ax1, w), min(ay1, h)
        if ax1 - ax0 < 3 or ay1 - ay0 < 3:
            out[Q.M00] = 0.0
            return
        gy, gx = np.mgrid[ay0:ay1, ax0:ax1]
        px = gx.ravel().astype(np.float64)
        py = gy.ravel().astype(np.float64)
        dx, dy = px - cx, py - cy
        dym = dy * row_step  # distances in frame rows: a field's disk is an ellipse
        d2 = _support_d2_np(prm, dx, dym, radius)
        pY = Y[ay0:ay1, ax0:ax1].ravel().astype(np.float64)
        ring = (d2 >= (radius + 1.0) ** 2) & (d2 <= outer * outer)
        rU = chroma_np(U, px[ring], py[ring], row_off, row_step)
        rV = chroma_np(V, px[ring], py[ring], row_off, row_step)
        keep = ~classify_np(prm, rU, rV)
        rY = pY[ring][keep]
        rU, rV = rU[keep], rV[keep]
        t = (_atan2_np(dym[ring][keep], dx[ring][keep]) + math.pi) * scale
        rbin = np.minimum(t.astype(np.int64), N_BINS - 1)
        cnt = np.bincount(rbin, minlength=N_BINS).astype(np.float64)
        ring_n = float(rY.size)
        sup = d2 <= radius * radius
        sdx, sdy = dx[sup], dy[sup]
        sY = pY[sup]
        sU = chroma_np(U, px[sup], py[sup], row_off, row_step)
        sV = chroma_np(V, px[sup], py[sup], row_off, row_step)
        flag = classify_np(prm, sU, sV).astype(np.float64)
        have_bg = ring_n >= 8.0
        if have_bg:
            my, mu, mv = _fill_bins_np(cnt, np.bincount(rbin, rY, N_BINS), np.bincount(rbin, rU, N_BINS),
                                       np.bincount(rbin, rV, N_BINS))
            t = (_atan2_np(sdy * row_step, sdx) + math.pi) * scale - 0.5
            kf = np.floor(t)
            f = t - kf
            k0 = kf.astype(np.int64) % N_BINS
            k1 = (k0 + 1) % N_BINS
            bY = my[k0] * (1.0 - f) + my[k1] * f
            bU = mu[k0] * (1.0 - f) + mu[k1] * f
            bV = mv[k0] * (1.0 - f) + mv[k1] * f
            cY, cU, cV = prm[P.YM] - bY, prm[P.UM] - bU, prm[P.VM] - bV
            den = wy * cY * cY + cU * cU + cV * cV
            ok = den >= prm[P.MIN_DEN]
            safe = np.where(ok, den, 1.0)
            lo, hi = prm[P.ALPHA_LO], prm[P.ALPHA_HI]
            cc = cU * cU + cV * cV
            aY = np.minimum(np.maximum((sY - bY) / np.where(cY == 0.0, 1.0, cY), lo), hi)
            aC = np.minimum(np.maximum((cU * (sU - bU) + cV * (sV - bV)) / np.where(cc > 0.0, cc, 1.0), lo), hi)
            aY = np.where(cY == 0.0, 0.0, aY)
            aC = np.where(cc > 0.0, aC, 0.0)
            aref = _luma_alpha_at_chroma_res_np(prm, pY, px, py, dx, dym, d2, radius, my, row_off, row_step,
                                                U.shape, px[sup], py[sup], aY)
            trust = np.minimum(np.maximum((prm[P.AGREE] + 0.1 - np.abs(aref - aC)) / 0.2, 0.0), 1.0)
            gy = wy * cY * cY * trust
            a = (gy * aY + cc * aC) / np.where(gy + cc > 0.0, gy + cc, 1.0)
            wgt = np.where(ok, a, flag)
            var_a = np.where(ok, (wy * wy * cY * cY * prm[P.VAR_Y] + (cU * cU + cV * cV) * prm[P.VAR_C]) / (safe * safe), 0.0)
            c2 = (cY * cY + cU * cU + cV * cV).sum()
            out[Q.BG_Y] = rY.sum() / ring_n
        else:
            wgt = flag
            var_a = np.zeros_like(wgt)
            c2 = 0.0
            out[Q.BG_Y] = math.nan
        m00 = wgt.sum()
        out[Q.M00] = m00
        out[Q.AT_BORDER] = 1.0 if border else 0.0
        out[Q.RING_N] = ring_n
        if not m00 > 0.0:
            return
        xb, yb = (wgt * sdx).sum() / m00, (wgt * sdy).sum() / m00
        ex, ey = sdx - xb, sdy - yb
        out[Q.X], out[Q.Y] = cx + xb, cy + yb
        out[Q.MU20] = (wgt * ex * ex).sum() / m00
        out[Q.MU11] = (wgt * ex * ey).sum() / m00
        out[Q.MU02] = (wgt * ey * ey).sum() / m00
        out[Q.VAR_X] = (var_a * ex * ex).sum() / (m00 * m00)
        out[Q.VAR_Y] = (var_a * ey * ey).sum() / (m00 * m00)
        out[Q.CONTRAST] = math.sqrt(c2 / sdx.size) if sdx.size else 0.0
        cx, cy = out[Q.X], out[Q.Y]


def _support_d2_np(prm, dx, dym, radius):
    """Squared "radius" of each pixel for the support and ring tests (see :func:`_rect_d2`)."""
    if prm[P.RECT] == 0.0:
        return dx * dx + dym * dym
    u = dx * prm[P.COS] + dym * prm[P.SIN]
    v = dym * prm[P.COS] - dx * prm[P.SIN]
    du = np.maximum(np.abs(u) - prm[P.HALF_U], 0.0)
    dv = np.maximum(np.abs(v) - prm[P.HALF_V], 0.0)
    e = radius - prm[P.RECT_MARGIN] + np.sqrt(du * du + dv * dv)
    return e * e


def _luma_alpha_at_chroma_res_np(prm, pY, px, py, dx, dym, d2, radius, my, row_off, row_step, chroma_shape,
                                  sx, sy, own):
    """Luma's α resampled as the chroma is: 2×2 block means, then bilinear at chroma's siting.

    ``pY, px, py, dx, dym, d2`` are the box's pixels (as in :func:`_marker_np`); the blocks are
    filled from its pixels within ``radius`` + 3 px of the centre (every block a support pixel's
    bilinear interpolation reads lies within 2√2 px of it). Returns the value at the support
    pixels ``(sx, sy)``; ``own`` (their own α_Y) where none of the four blocks has a pixel.
    """
    hc, wc = chroma_shape
    scale = N_BINS / (2.0 * math.pi)
    foot = d2 <= (radius + 3.0) ** 2
    t = (_atan2_np(dym[foot], dx[foot]) + math.pi) * scale - 0.5
    kf = np.floor(t)
    f = t - kf
    k0 = kf.astype(np.int64) % N_BINS
    k1 = (k0 + 1) % N_BINS
    bY = my[k0] * (1.0 - f) + my[k1] * f
    cY = prm[P.YM] - bY
    aY = np.minimum(np.maximum((pY[foot] - bY) / np.where(cY == 0.0, 1.0, cY), prm[P.ALPHA_LO]), prm[P.ALPHA_HI])
    aY = np.where(cY == 0.0, 0.0, aY)
    bi = px[foot].astype(np.int64) // 2
    bj = (row_off + row_step * py[foot].astype(np.int64)) // 2
    i_lo, j_lo = int(bi.min()), int(bj.min())
    gs = np.zeros((int(bj.max()) - j_lo + 1, int(bi.max()) - i_lo + 1))
    gn = np.zeros_like(gs)
    # np.add.at adds in the given (raster) order, as the compiled kernel does.
    np.add.at(gs, (bj - j_lo, bi - i_lo), aY)
    np.add.at(gn, (bj - j_lo, bi - i_lo), 1.0)
    gs = np.where(gn > 0.0, gs / np.where(gn > 0.0, gn, 1.0), 0.0)
    ia, ib, ja, jb, fx, fy = _chroma_neighbours_np(sx, sy, row_off, row_step, hc, wc)
    ia, ib, ja, jb = ia - i_lo, ib - i_lo, ja - j_lo, jb - j_lo
    num = np.zeros(sx.size)
    wsum = np.zeros(sx.size)
    for j, i, w in ((ja, ia, (1.0 - fx) * (1.0 - fy)), (ja, ib, fx * (1.0 - fy)), (jb, ia, (1.0 - fx) * fy),
                    (jb, ib, fx * fy)):
        inside = (j >= 0) & (j < gs.shape[0]) & (i >= 0) & (i < gs.shape[1])
        jc, ic = np.where(inside, j, 0), np.where(inside, i, 0)
        have = inside & (gn[jc, ic] > 0.0)
        num = num + np.where(have, w * gs[jc, ic], 0.0)
        wsum = wsum + np.where(have, w, 0.0)
    return np.where(wsum > 0.0, num / np.where(wsum > 0.0, wsum, 1.0), own)


def _fill_bins_np(cnt, sy, su, sv):
    """Per-bin means; an empty bin takes the nearest filled one's (searching k−1, k+1, k−2, …)."""
    my = np.zeros(N_BINS)
    mu = np.zeros(N_BINS)
    mv = np.zeros(N_BINS)
    for k in range(N_BINS):
        src = k
        if cnt[k] == 0:
            for step in range(1, N_BINS):
                if cnt[(k - step) % N_BINS] > 0:
                    src = (k - step) % N_BINS
                    break
                if cnt[(k + step) % N_BINS] > 0:
                    src = (k + step) % N_BINS
                    break
        my[k] = sy[src] / cnt[src]
        mu[k] = su[src] / cnt[src]
        mv[k] = sv[src] / cnt[src]
    return my, mu, mv


def led_level_numpy(Y, led, out, led_out) -> None:
    """Mean luma over the LED's disk, placed by the markers' centroids in ``out`` (numpy)."""
    led_out[:] = math.nan
    led_out[1] = 0.0
    if led[0] == 0.0 or not (out[0, Q.M00] > 0.0 and out[1, Q.M00] > 0.0):
        return
    cx, cy = _led_centre(out, led)
    r = led[3]
    h, w = Y.shape
    x0, x1 = int(max(0.0, math.floor(cx - r))), int(min(float(w), math.floor(cx + r) + 1))
    y0, y1 = int(max(0.0, math.floor(cy - r))), int(min(float(h), math.floor(cy + r) + 1))
    led_out[2], led_out[3] = cx, cy
    if x1 <= x0 or y1 <= y0:
        return
    yy, xx = np.mgrid[y0:y1, x0:x1]
    disk = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    n = float(disk.sum())
    led_out[1] = n
    if n > 0:
        led_out[0] = Y[y0:y1, x0:x1][disk].astype(np.float64).sum() / n


def track_frame_numpy(Y, U, V, row_off, row_step, params, led, out, led_out) -> None:
    """Reference implementation (numpy) of :func:`track_frame_numba`; fills ``out`` and ``led_out``."""
    for k in range(params.shape[0]):
        _marker_np(Y, U, V, int(row_off), int(row_step), params[k], out[k])
    led_level_numpy(Y, led, out, led_out)


# ---------------------------------------------------------------------------
# numba
# ---------------------------------------------------------------------------
@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _bin_pair(kf):
    """Bins k, k+1 (mod N_BINS) around an interpolation position; ``kf`` in [-1, N_BINS - 1] (no modulo)."""
    k0 = int(kf)
    if k0 < 0:
        k0 += N_BINS
    k1 = k0 + 1
    if k1 == N_BINS:
        k1 = 0
    return k0, k1


@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _chroma_neighbours(x, y, row_off, row_step, hc, wc):
    """:func:`_chroma_neighbours_np` for one luma pixel (integer x, y): (ia, ib, ja, jb, fx, fy).

    Chroma sample i sits at luma 2i + 0.5, so luma column x lies between
    samples (x − 1) >> 1 and the next, 3/4 of the way for even x and 1/4 for
    odd x (the same for frame rows): integer arithmetic, the same values as
    the reference's floor.
    """
    i0 = (x - 1) >> 1
    r = row_off + row_step * y
    j0 = (r - 1) >> 1
    fx = 0.75 if (x & 1) == 0 else 0.25
    fy = 0.75 if (r & 1) == 0 else 0.25
    return (min(max(i0, 0), wc - 1), min(max(i0 + 1, 0), wc - 1), min(max(j0, 0), hc - 1),
            min(max(j0 + 1, 0), hc - 1), fx, fy)


@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _chroma_uv_at(U, V, x, y, row_off, row_step):
    """Bilinear Cb and Cr at luma pixel (x, y) (integers), as :func:`chroma_np`."""
    hc, wc = U.shape
    ia, ib, ja, jb, fx, fy = _chroma_neighbours(x, y, row_off, row_step, hc, wc)
    top = float(U[ja, ia]) * (1.0 - fx) + float(U[ja, ib]) * fx
    bot = float(U[jb, ia]) * (1.0 - fx) + float(U[jb, ib]) * fx
    u = top * (1.0 - fy) + bot * fy
    top = float(V[ja, ia]) * (1.0 - fx) + float(V[ja, ib]) * fx
    bot = float(V[jb, ia]) * (1.0 - fx) + float(V[jb, ib]) * fx
    return u, top * (1.0 - fy) + bot * fy


@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _block_bilinear(gs, gm, gi0, gj0, x, y, row_off, row_step, hc, wc, own):
    """Block means ``gs`` read as :func:`_chroma_uv_at` reads a plane, over the blocks that have pixels.

    ``gm`` is 1 where a block has pixels, else 0 (and ``gs`` 0 there); the
    grid has a margin of one empty block all round, so that every tap of a
    support pixel lies inside it and no tap needs a test. ``own`` where none
    of the four blocks has a pixel.
    """
    ia, ib, ja, jb, fx, fy = _chroma_neighbours(x, y, row_off, row_step, hc, wc)
    ia, ib, ja, jb = ia - gi0, ib - gi0, ja - gj0, jb - gj0
    w00 = (1.0 - fx) * (1.0 - fy)
    w01 = fx * (1.0 - fy)
    w10 = (1.0 - fx) * fy
    w11 = fx * fy
    num = w00 * gs[ja, ia] + w01 * gs[ja, ib] + w10 * gs[jb, ia] + w11 * gs[jb, ib]
    wsum = w00 * gm[ja, ia] + w01 * gm[ja, ib] + w10 * gm[jb, ia] + w11 * gm[jb, ib]
    return num / wsum if wsum > 0.0 else own


@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _rect_d2(hu, hv, cs, sn, sm, radius, dx, dym):
    """Squared "radius" of a pixel at (dx, dym) from a rectangular sticker's centre.

    The rectangle has half-sides (hu, hv), its first along (cs, sn): ``(radius − sm + d)²``
    with d the pixel's distance from the rectangle (0 inside), so that the round support's
    tests hold as they are: ``d2 <= radius²`` is "within sm of the rectangle", the ring's
    ``(radius + 1)² <= d2 <= (radius + 1 + ring)²`` is "1 to 1 + ring px beyond that"
    (the numpy reference: :func:`_support_d2_np`).
    """
    u = dx * cs + dym * sn
    v = dym * cs - dx * sn
    du = max(abs(u) - hu, 0.0)
    dv = max(abs(v) - hv, 0.0)
    e = radius - sm + math.sqrt(du * du + dv * dv)
    return e * e


@njit(cache=True, nogil=True, fastmath=_FAST, inline="always")
def _is_class(prm, uv, vv):
    u = uv - 128.0
    v = vv - 128.0
    sat = math.sqrt(u * u + v * v)
    return sat >= prm[10] and (u * prm[7] + v * prm[8]) >= prm[9] * sat


@njit(cache=True, nogil=True, fastmath=_FAST)
def _marker_nb(Y, U, V, row_off, row_step, prm, out, buf):
    for i in range(out.shape[0]):
        out[i] = 0.0
    if prm[16] == 0.0:
        return
    h, w = Y.shape
    hc, wc = U.shape
    x0 = prm[0]
    y0 = prm[1]
    i0, i1, j0, j1 = _chroma_window_nb(prm, row_off, row_step, hc, wc)
    wq = 4.0 / row_step
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
    for j in range(j0, j1):
        qy = ((2.0 * j + 0.5 - row_off) / row_step) - y0
        for i in range(i0, i1):
            if _is_class(prm, float(U[j, i]), float(V[j, i])):
                qx = (2.0 * i + 0.5) - x0
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
    n *= wq
    out[0] = n
    if n == 0.0:
        return
    bx = wq * sx / n
    by = wq * sy / n
    out[1] = bx + x0
    out[2] = by + y0
    out[3] = wq * sxx / n - bx * bx
    out[4] = wq * sxy / n - bx * by
    out[5] = wq * syy / n - by * by
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
    radius = prm[12]
    outer = radius + 1.0 + prm[13]
    r_in2 = (radius + 1.0) * (radius + 1.0)
    r_out2 = outer * outer
    r2 = radius * radius
    wy = prm[14]
    rect = prm[25] != 0.0
    hu, hv, cs, sn, sm = prm[26], prm[27], prm[28], prm[29], prm[30]
    scale = N_BINS / (2.0 * math.pi)
    cnt = np.zeros(N_BINS)
    bsy = np.zeros(N_BINS)
    bsu = np.zeros(N_BINS)
    bsv = np.zeros(N_BINS)
    my = np.zeros(N_BINS)
    mu = np.zeros(N_BINS)
    mv = np.zeros(N_BINS)
    for _ in range(max(1, int(prm[15]))):
        ax0 = int(math.floor(cx - outer))
        ay0 = int(math.floor(cy - outer / row_step))
        ax1 = int(math.ceil(cx + outer)) + 1
        ay1 = int(math.ceil(cy + outer / row_step)) + 1
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
            bsy[k] = 0.0
            bsu[k] = 0.0
            bsv[k] = 0.0
        ring_n = 0.0
        ring_y = 0.0
        ns = 0
        # One sweep: ring pixels into the angle bins; support pixels into the buffer.
        # The same sweep twice, the round support's first: a per-pixel test of the support's kind
        # cost the round stickers' path ~3 %.
        if not rect:
            for y in range(ay0, ay1):
                fy = float(y)
                dy = fy - cy
                dym = dy * row_step  # distances in frame rows: a field's disk is an ellipse
                for x in range(ax0, ax1):
                    fx = float(x)
                    dx = fx - cx
                    d2 = dx * dx + dym * dym
                    if d2 <= r2:
                        buf[ns, 0] = dx
                        buf[ns, 1] = dy
                        buf[ns, 7] = fx
                        buf[ns, 8] = fy
                        buf[ns, 2] = float(Y[y, x])
                        buf[ns, 3], buf[ns, 4] = _chroma_uv_at(U, V, x, y, row_off, row_step)
                        ns += 1
                        continue
                    if d2 < r_in2 or d2 > r_out2:
                        continue
                    uv, vv = _chroma_uv_at(U, V, x, y, row_off, row_step)
                    if _is_class(prm, uv, vv):
                        continue
                    yv = float(Y[y, x])
                    k = min(int((_atan2(dym, dx) + math.pi) * scale), N_BINS - 1)
                    cnt[k] += 1.0
                    bsy[k] += yv
                    bsu[k] += uv
                    bsv[k] += vv
                    ring_n += 1.0
                    ring_y += yv
        else:
            for y in range(ay0, ay1):
                fy = float(y)
                dy = fy - cy
                dym = dy * row_step  # distances in frame rows: a field's disk is an ellipse
                for x in range(ax0, ax1):
                    fx = float(x)
                    dx = fx - cx
                    d2 = _rect_d2(hu, hv, cs, sn, sm, radius, dx, dym)
                    if d2 <= r2:
                        buf[ns, 0] = dx
                        buf[ns, 1] = dy
                        buf[ns, 7] = fx
                        buf[ns, 8] = fy
                        buf[ns, 2] = float(Y[y, x])
                        buf[ns, 3], buf[ns, 4] = _chroma_uv_at(U, V, x, y, row_off, row_step)
                        ns += 1
                        continue
                    if d2 < r_in2 or d2 > r_out2:
                        continue
                    uv, vv = _chroma_uv_at(U, V, x, y, row_off, row_step)
                    if _is_class(prm, uv, vv):
                        continue
                    yv = float(Y[y, x])
                    k = min(int((_atan2(dym, dx) + math.pi) * scale), N_BINS - 1)
                    cnt[k] += 1.0
                    bsy[k] += yv
                    bsu[k] += uv
                    bsv[k] += vv
                    ring_n += 1.0
                    ring_y += yv
        have_bg = ring_n >= 8.0
        if have_bg:
            for k in range(N_BINS):
                src = k
                if cnt[k] == 0.0:
                    for step in range(1, N_BINS):
                        a = (k - step) % N_BINS
                        if cnt[a] > 0.0:
                            src = a
                            break
                        b = (k + step) % N_BINS
                        if cnt[b] > 0.0:
                            src = b
                            break
                my[k] = bsy[src] / cnt[src]
                mu[k] = bsu[src] / cnt[src]
                mv[k] = bsv[src] / cnt[src]
        # One empty block of margin all round (see _block_bilinear).
        gi0 = ax0 // 2 - 1
        gj0 = (row_off + row_step * ay0) // 2 - 1
        gs = np.zeros((1, 1))
        gn = np.zeros((1, 1))
        if have_bg:
            # Luma's α in 2×2 blocks, as the chroma was sampled (see _luma_alpha_at_chroma_res_np).
            gs = np.zeros(((row_off + row_step * (ay1 - 1)) // 2 - gj0 + 2, (ax1 - 1) // 2 - gi0 + 2))
            gn = np.zeros_like(gs)
            rf = radius + 3.0
            rf2 = rf * rf
            s = 0
            if not rect:
                for y in range(ay0, ay1):
                    dym = (float(y) - cy) * row_step
                    gj = (row_off + row_step * y) // 2 - gj0
                    for x in range(ax0, ax1):
                        dx = float(x) - cx
                        d2 = dx * dx + dym * dym
                        if d2 > rf2:
                            continue
                        t = (_atan2(dym, dx) + math.pi) * scale - 0.5
                        if d2 <= r2:
                            buf[s, 9] = t  # the support pixels come in the sweep's (raster) order
                            s += 1
                        kf = math.floor(t)
                        f = t - kf
                        k0, k1 = _bin_pair(kf)
                        bY = my[k0] * (1.0 - f) + my[k1] * f
                        cY = prm[4] - bY
                        aY = 0.0
                        if cY != 0.0:
                            aY = min(max((float(Y[y, x]) - bY) / cY, prm[19]), prm[20])
                        gi = (x >> 1) - gi0  # x >= 0: a shift is its floor half
                        gs[gj, gi] += aY
                        gn[gj, gi] += 1.0
            else:
                for y in range(ay0, ay1):
                    dym = (float(y) - cy) * row_step
                    gj = (row_off + row_step * y) // 2 - gj0
                    for x in range(ax0, ax1):
                        dx = float(x) - cx
                        d2 = _rect_d2(hu, hv, cs, sn, sm, radius, dx, dym)
                        if d2 > rf2:
                            continue
                        t = (_atan2(dym, dx) + math.pi) * scale - 0.5
                        if d2 <= r2:
                            buf[s, 9] = t  # the support pixels come in the sweep's (raster) order
                            s += 1
                        kf = math.floor(t)
                        f = t - kf
                        k0, k1 = _bin_pair(kf)
                        bY = my[k0] * (1.0 - f) + my[k1] * f
                        cY = prm[4] - bY
                        aY = 0.0
                        if cY != 0.0:
                            aY = min(max((float(Y[y, x]) - bY) / cY, prm[19]), prm[20])
                        gi = (x >> 1) - gi0  # x >= 0: a shift is its floor half
                        gs[gj, gi] += aY
                        gn[gj, gi] += 1.0
            for j in range(gs.shape[0]):
                for i in range(gs.shape[1]):
                    if gn[j, i] > 0.0:
                        gs[j, i] /= gn[j, i]
                        gn[j, i] = 1.0  # from here on: whether the block has pixels
        m00 = 0.0
        m10 = 0.0
        m01 = 0.0
        c2s = 0.0
        for s in range(ns):
            dx = buf[s, 0]
            dy = buf[s, 1]
            yv = buf[s, 2]
            uv = buf[s, 3]
            vv = buf[s, 4]
            va = 0.0
            # The class flag is the weight only where no unmixing is possible: evaluated there only
            # (a square root per support pixel saved; the same values either way).
            unmixed = False
            a = 0.0
            if have_bg:
                t = buf[s, 9]
                kf = math.floor(t)
                f = t - kf
                k0, k1 = _bin_pair(kf)
                bY = my[k0] * (1.0 - f) + my[k1] * f
                bU = mu[k0] * (1.0 - f) + mu[k1] * f
                bV = mv[k0] * (1.0 - f) + mv[k1] * f
                cY = prm[4] - bY
                cU = prm[5] - bU
                cV = prm[6] - bV
                den = wy * cY * cY + cU * cU + cV * cV
                c2s += cY * cY + cU * cU + cV * cV
                if den >= prm[21]:
                    cc = cU * cU + cV * cV
                    aY = 0.0
                    if cY != 0.0:
                        aY = min(max((yv - bY) / cY, prm[19]), prm[20])
                    aC = 0.0
                    if cc > 0.0:
                        aC = min(max((cU * (uv - bU) + cV * (vv - bV)) / cc, prm[19]), prm[20])
                    aref = _block_bilinear(gs, gn, gi0, gj0, int(buf[s, 7]), int(buf[s, 8]), row_off, row_step, hc,
                                          wc, aY)
                    trust = min(max((prm[11] + 0.1 - abs(aref - aC)) / 0.2, 0.0), 1.0)
                    gy = wy * cY * cY * trust
                    a = (gy * aY + cc * aC) / (gy + cc) if gy + cc > 0.0 else 0.0
                    va = (wy * wy * cY * cY * prm[17] + (cU * cU + cV * cV) * prm[18]) / (den * den)
                    unmixed = True
            if not unmixed:
                a = 1.0 if _is_class(prm, uv, vv) else 0.0
            buf[s, 5] = a
            buf[s, 6] = va
            m00 += a
            m10 += a * dx
            m01 += a * dy
        out[6] = m00
        out[15] = 1.0 if border else 0.0
        out[16] = ring_n
        out[21] = ring_y / ring_n if have_bg else math.nan
        if not m00 > 0.0:
            return
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
            a = buf[s, 5]
            m20 += a * ex * ex
            m11 += a * ex * ey
            m02 += a * ey * ey
            vx += buf[s, 6] * ex * ex
            vy += buf[s, 6] * ey * ey
        out[7] = cx + xb
        out[8] = cy + yb
        out[9] = m20 / m00
        out[10] = m11 / m00
        out[11] = m02 / m00
        out[12] = vx / (m00 * m00)
        out[13] = vy / (m00 * m00)
        out[14] = math.sqrt(c2s / ns) if ns > 0 else 0.0
        cx = out[7]
        cy = out[8]


@njit(cache=True, nogil=True, fastmath=_FAST)
def led_level_numba(Y, led, out, led_out):
    """Mean luma over the LED's disk, placed by the markers' centroids in ``out``."""
    for i in range(led_out.shape[0]):
        led_out[i] = math.nan
    led_out[1] = 0.0
    if led[0] == 0.0 or not (out[0, 6] > 0.0 and out[1, 6] > 0.0):
        return
    cx, cy = _led_centre(out, led)
    r = led[3]
    h, w = Y.shape
    x0 = int(max(0.0, math.floor(cx - r)))
    x1 = int(min(float(w), math.floor(cx + r) + 1))
    y0 = int(max(0.0, math.floor(cy - r)))
    y1 = int(min(float(h), math.floor(cy + r) + 1))
    led_out[2] = cx
    led_out[3] = cy
    s = 0.0
    n = 0.0
    for y in range(y0, y1):
        for x in range(x0, x1):
            dx = x - cx
            dy = y - cy
            if dx * dx + dy * dy <= r * r:
                s += float(Y[y, x])
                n += 1.0
    led_out[1] = n
    if n > 0.0:
        led_out[0] = s / n


@njit(cache=True, nogil=True, fastmath=_FAST)
def track_frame_numba(Y, U, V, row_off, row_step, params, led, out, led_out):
    """Measure every marker row of ``params`` (and the LED) in one frame; fills ``out`` and ``led_out``."""
    size = 0
    for k in range(params.shape[0]):
        side = 2 * int(params[k, 12] + 1.0 + params[k, 13]) + 4
        size = max(size, side * side)
    buf = np.empty((size, 10))
    for k in range(params.shape[0]):
        _marker_nb(Y, U, V, int(row_off), int(row_step), params[k], out[k], buf)
    led_level_numba(Y, led, out, led_out)


ENGINES = {"numpy": track_frame_numpy, "numba": track_frame_numba}
LED_ENGINES = {"numpy": led_level_numpy, "numba": led_level_numba}


def track_frame(engine: str, Y, U, V, row_off, row_step, params, led, out, led_out) -> None:
    """Dispatch to ``engine`` ("numpy" or "numba")."""
    ENGINES[engine](Y, U, V, row_off, row_step, params, led, out, led_out)
