"""The plain-numpy reference of the YUV kernel (``engine="numpy"``): the same maths, op by op, slowly."""

from __future__ import annotations

import math

import numpy as np

from .kernel_layout import N_BINS, P, Q, atan2_np, chroma_window, led_centre

__all__ = ["chroma_np", "classify_np", "led_level_numpy", "track_frame_numpy"]


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
    """One marker's soft moments in its window, in plain numpy: the compiled kernel's reference.

    Long because it follows the compiled kernel step for step, in the same order, so
    that the two can be compared line by line.
    """
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
        t = (atan2_np(dym[ring][keep], dx[ring][keep]) + math.pi) * scale
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
            t = (atan2_np(sdy * row_step, sdx) + math.pi) * scale - 0.5
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
    t = (atan2_np(dym[foot], dx[foot]) + math.pi) * scale - 0.5
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
    cx, cy = led_centre(out, led)
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

