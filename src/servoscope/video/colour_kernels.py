"""Numba kernels of :mod:`servoscope.video.colour` (a module of their own: numba is imported only when needed).

Each takes the output as affine functions of the source's code values,
``k`` of shape (3, 4): ``out[i] = k[i,0] + k[i,1]·Y + k[i,2]·U + k[i,3]·V``.
They release the GIL: the reader's decoder thread converts while the
tracker works on the previous frame.
"""

from __future__ import annotations

import numpy as np

from numba import njit

__all__ = ["expand_row", "i420_kernel", "rgb_kernel"]


@njit(cache=True, nogil=True)
def expand_row(c_row, fx, w, out):
    # A chroma row at luma resolution (nearest sample), as float32.
    # Looping over samples, not pixels: an integer division per pixel cost more than the rest.
    n = (w + fx - 1) // fx
    for c in range(n):
        val = np.float32(c_row[c])
        for j in range(min(fx, w - c * fx)):
            out[c * fx + j] = val


@njit(cache=True, nogil=True)
def i420_kernel(y, u, v, fx, fy, k, out):
    # k: rows of output (Y, Cb, Cr) code value = k[i,0] + k[i,1]·Y + k[i,2]·U + k[i,3]·V, in the
    # source's code values; row by row (vectorisable loops), each pixel with its own chroma sample.
    h, w = out.shape[0] * 2 // 3, out.shape[1]
    hw, ww = h // 2, w // 2
    lum = out[:h]
    cb_plane = out[h:].ravel()[: hw * ww].reshape(hw, ww)
    cr_plane = out[h:].ravel()[hw * ww:].reshape(hw, ww)
    ue = np.empty(w, np.float32)
    ve = np.empty(w, np.float32)
    ysum = np.empty(ww, np.float32)
    usum = np.empty(ww, np.float32)
    vsum = np.empty(ww, np.float32)
    half = np.float32(0.5)
    lo = np.float32(0.0)
    hi = np.float32(255.0)
    for by in range(hw):
        ysum[:] = 0.0
        usum[:] = 0.0
        vsum[:] = 0.0
        for dy in range(2):
            yy = 2 * by + dy
            expand_row(u[yy // fy], fx, w, ue)
            expand_row(v[yy // fy], fx, w, ve)
            y_row = y[yy]
            o_row = lum[yy]
            for xx in range(w):
                yv = np.float32(y_row[xx])
                val = k[0, 0] + k[0, 1] * yv + k[0, 2] * ue[xx] + k[0, 3] * ve[xx]
                o_row[xx] = np.int32(min(hi, max(lo, val)) + half)
            for bx in range(ww):
                ysum[bx] += np.float32(y_row[2 * bx]) + np.float32(y_row[2 * bx + 1])
                usum[bx] += ue[2 * bx] + ue[2 * bx + 1]
                vsum[bx] += ve[2 * bx] + ve[2 * bx + 1]
        quarter = np.float32(0.25)
        for bx in range(ww):
            cb = k[1, 0] + quarter * (k[1, 1] * ysum[bx] + k[1, 2] * usum[bx] + k[1, 3] * vsum[bx])
            cr = k[2, 0] + quarter * (k[2, 1] * ysum[bx] + k[2, 2] * usum[bx] + k[2, 3] * vsum[bx])
            cb_plane[by, bx] = np.int32(min(hi, max(lo, cb)) + half)
            cr_plane[by, bx] = np.int32(min(hi, max(lo, cr)) + half)


@njit(cache=True, nogil=True)
def rgb_kernel(y, u, v, fx, fy, k, out):
    # k: rows of output (R, G, B) = k[i,0] + k[i,1]·Y + k[i,2]·U + k[i,3]·V.
    h, w = out.shape[0], out.shape[1]
    ue = np.empty(w, np.float32)
    ve = np.empty(w, np.float32)
    half = np.float32(0.5)
    lo = np.float32(0.0)
    hi = np.float32(255.0)
    for yy in range(h):
        expand_row(u[yy // fy], fx, w, ue)
        expand_row(v[yy // fy], fx, w, ve)
        y_row = y[yy]
        o_row = out[yy]
        for xx in range(w):
            yv = np.float32(y_row[xx])
            for c in range(3):
                val = k[c, 0] + k[c, 1] * yv + k[c, 2] * ue[xx] + k[c, 3] * ve[xx]
                o_row[xx, c] = np.int32(min(hi, max(lo, val)) + half)
