"""The compiled YUV kernel (``engine="numba"``, nogil): what :mod:`.kernel_numpy` computes, fast."""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit, types

from .kernel_layout import (FASTMATH, N_BINS, atan2_nb, chroma_window_nb, led_centre, nearest_filled_bin,
                            soft_moments_out)

__all__ = ["led_level_numba", "track_frame_numba"]


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
def _bin_pair(kf):
    """Bins k, k+1 (mod N_BINS) around an interpolation position; ``kf`` in [-1, N_BINS - 1] (no modulo)."""
    k0 = int(kf)
    if k0 < 0:
        k0 += N_BINS
    k1 = k0 + 1
    if k1 == N_BINS:
        k1 = 0
    return k0, k1


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
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


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
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


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
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


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
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


@njit(cache=True, nogil=True, fastmath=FASTMATH, inline="always")
def _is_class(prm, uv, vv):
    u = uv - 128.0
    v = vv - 128.0
    sat = math.sqrt(u * u + v * v)
    return sat >= prm[10] and (u * prm[7] + v * prm[8]) >= prm[9] * sat


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def _marker_nb(Y, U, V, row_off, row_step, prm, out, buf):
    """One marker's soft moments in its window (compiled): parameters in ``prm`` (layout P), results in ``out`` (Q).

    Long because it is one fused, compiled pass over a window's pixels: split into
    functions, numba would keep the loops apart and the per-frame cost would grow.
    """
    for i in range(out.shape[0]):
        out[i] = 0.0
    if prm[16] == 0.0:
        return
    h, w = Y.shape
    hc, wc = U.shape
    x0 = prm[0]
    y0 = prm[1]
    i0, i1, j0, j1 = chroma_window_nb(prm, row_off, row_step, hc, wc)
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
                    k = min(int((atan2_nb(dym, dx) + math.pi) * scale), N_BINS - 1)
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
                    k = min(int((atan2_nb(dym, dx) + math.pi) * scale), N_BINS - 1)
                    cnt[k] += 1.0
                    bsy[k] += yv
                    bsu[k] += uv
                    bsv[k] += vv
                    ring_n += 1.0
                    ring_y += yv
        have_bg = ring_n >= 8.0
        if have_bg:
            for k in range(N_BINS):
                src = nearest_filled_bin(cnt, k)
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
                        t = (atan2_nb(dym, dx) + math.pi) * scale - 0.5
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
                        t = (atan2_nb(dym, dx) + math.pi) * scale - 0.5
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
        soft_moments_out(buf, ns, 5, 6, m00, m10, m01, cx, cy, c2s, out)
        cx = out[7]
        cy = out[8]


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def led_level_numba(Y, led, out, led_out):
    """Mean luma over the LED's disk, placed by the markers' centroids in ``out``."""
    for i in range(led_out.shape[0]):
        led_out[i] = math.nan
    led_out[1] = 0.0
    if led[0] == 0.0 or not (out[0, 6] > 0.0 and out[1, 6] > 0.0):
        return
    cx, cy = led_centre(out, led)
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


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def _track_frame_nb(Y, U, V, row_off, row_step, params, led, out, led_out):
    size = 0
    for k in range(params.shape[0]):
        side = 2 * int(params[k, 12] + 1.0 + params[k, 13]) + 4
        size = max(size, side * side)
    buf = np.empty((size, 10))
    for k in range(params.shape[0]):
        _marker_nb(Y, U, V, int(row_off), int(row_step), params[k], out[k], buf)
    led_level_numba(Y, led, out, led_out)



# One compiled version of the frame kernel for every layout of the planes. Left to itself numba compiles
# the kernel once for each combination of array types it meets (C-contiguous planes, a decoder's padded
# rows, an interlaced field's every other row, read-only or not): ~8 s of CPU each, three on this
# project's tests and as many for a user's first footage of each kind. The planes typed as read-only
# arrays of any layout take them all (numba converts the others to it) and run as fast as the
# C-contiguous version (measured: 176-195 µs a frame against 200-215 µs on the tests' 128×96 frame).
_PLANE = types.Array(types.uint8, 2, "A", readonly=True)
_ROWS = types.Array(types.float64, 2, "A")
_VECTOR = types.Array(types.float64, 1, "A")
_FRAME_SIGNATURE = (_PLANE, _PLANE, _PLANE, types.int64, types.int64, _ROWS, _VECTOR, _ROWS, _VECTOR)


@functools.lru_cache(maxsize=None)
def _frame_kernel():
    # On first use, not at import: a command that never tracks colour footage compiles nothing.
    _track_frame_nb.compile(_FRAME_SIGNATURE)
    _track_frame_nb.disable_compile()
    return _track_frame_nb


def track_frame_numba(Y: np.ndarray, U: np.ndarray, V: np.ndarray, row_off: int, row_step: int, params: np.ndarray,
                      led: np.ndarray, out: np.ndarray, led_out: np.ndarray) -> None:
    """Measure every marker row of ``params`` (and the LED) in one frame; fills ``out`` and ``led_out``.

    ``Y``, ``U``, ``V``: the frame's uint8 planes, any layout; ``row_off``, ``row_step``: the frame's rows in
    the picture (a field: 0 or 1, 2); ``params``: a row of :data:`~servoscope.markers.kernels.NP` numbers a
    marker; ``led``: :data:`~servoscope.markers.kernels.LED_NP` numbers; ``out``, ``led_out``: filled.
    """
    _frame_kernel()(Y, U, V, row_off, row_step, params, led, out, led_out)
