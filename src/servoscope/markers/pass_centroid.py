"""A rotor sticker's vertical centroid from full-resolution luma: no row-dependent bias from 4:2:0 chroma.

In a pass the stickers move along the picture's rows, so any bias of a sticker's vertical centroid
that depends on its row's sub-pixel phase is the same in every frame of the pass and, over a dwell,
reads as a scale on the pitch (docs/rotor.md, "The pitch's scale"). The fused YUV kernel's centroid
has such a bias where it leans on chroma: 4:2:0 chroma is a 2×2 block mean, and upsampled
(bilinear) it spreads a sticker's edge ~1.5 px beyond the sticker, past the 1-px support margin a tip
sticker allows (a wider one takes in the sky beyond the blade's edge). The support's rows are whole
pixels, so how much of that tail is cut changes with the sticker's row phase: a saw-tooth of
±0.03 px against the fractional row on the twin (a red sticker on a dark blade; a sticker whose
luma contrast dominates the unmixing has none).

:func:`luma_row_centroid` measures the vertical coordinate again from luma alone, whose edges are
as sharp as the optics make them, over the kernel's support with two changes that keep it free of
the phase: a *soft* support edge (each pixel weighted by how far it lies inside the support's
boundary, clipped to [0, 1]: continuous in the centre, so no row enters or leaves at once) and an
unclipped α (clipping the noise at 0 would bias the edge rows upward). The background is the
mean luma of a ring just outside the support, its sides only (the blade along the chord; above and
below, the section's edge is close), its pixels far from the ring's median left out: one level, so a
blade shaded across the sticker would bias it (the twin's blades are flat). The support is centred on
the previous estimate and the centroid taken again: a background error then pulls only towards that
centre, which converges on the truth.

Where luma cannot tell the sticker (a luma contrast under :data:`MIN_LUMA_CONTRAST_DN`, or the sky
just above or below the support: a sticker nearly as tall as the tip is thick) the caller keeps the
kernel's coordinate, and its bias.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["EDGE_SHARE", "LUMA_MARGIN_PX", "MIN_LUMA_CONTRAST_DN", "luma_row_centroid"]

#: Least |sticker luma − background| (DN) for the luma-only coordinate; below it the caller keeps the kernel's
#: (chroma-led, with its row bias). Luma's noise grows as its contrast falls: the twin's blue sticker (17 DN on
#: its dark blade, chroma 72 DN) read 0.062 px per frame from luma against the kernel's 0.031 on H.264 at
#: 2,000 frames/s and 30 rev/s (per-pass pitch RMS 0.025° → 0.035°; 0.028° with it kept on the kernel); the red
#: (27 DN) and every other of the twin's colours (36-79 DN) gain.
MIN_LUMA_CONTRAST_DN = 20.0
#: The luma support's margin beyond the kernel's rectangle across the rows (px; its soft edge reaches half a pixel
#: further): the kernel's own 1 px. Tighter was worse on the twin (raw, 4 mm stickers, mean 0°: slope 0.998 at 1 px,
#: 1.012 at 0, 0.984 at −1; per-pass RMS 0.007° → 0.020°): the row estimate then hangs on the edge rows' noise.
LUMA_MARGIN_PX = 1.0
#: Largest share of the sticker's luma contrast by which the rows just above or below the support may differ
#: from the blade's level before the section's edge (sky) is taken to be there.
EDGE_SHARE = 0.15
#: Recentring passes of the soft support.
ITERATIONS = 2


def luma_row_centroid(Y: np.ndarray, cx: float, cy: float, half_u_px: float, half_v_px: float, margin_px: float,
                      ring_px: float, sticker_luma_dn: float, luma_var_dn2: float) -> tuple[float, float]:
    """A sticker's vertical centroid (px) from luma over a soft rectangular support, and its standard error.

    Parameters
    ----------
    Y : ndarray, shape (h, w)
        The frame's luma plane.
    cx, cy : float
        The kernel's centroid (px): the support's first centre.
    half_u_px, half_v_px : float
        The support rectangle's half-sides (along the rows, across them), before the margin.
    margin_px : float
        Support beyond the rectangle (px); the ring lies 1 px beyond that, ``ring_px`` wide.
    ring_px : float
        Background ring width (px).
    sticker_luma_dn : float
        The sticker's own luma (DN).
    luma_var_dn2 : float
        The luma's noise variance (DN²).

    Returns
    -------
    (float, float)
        ``(y_px, sigma_px)``; NaN, NaN where the window leaves the picture, the ring's sides leave too few
        pixels for the blade's level, a section's edge lies just above or below the support, or the sticker's luma contrast is under :data:`MIN_LUMA_CONTRAST_DN`.
    """
    y, sigma = _luma_rows_nb(Y, float(cx), float(cy), float(half_u_px), float(half_v_px), float(margin_px),
                             float(ring_px), float(sticker_luma_dn), float(luma_var_dn2), LUMA_MARGIN_PX, EDGE_SHARE,
                             MIN_LUMA_CONTRAST_DN, ITERATIONS)
    return float(y), float(sigma)


@njit(cache=True, nogil=True)
def _luma_rows_nb(Y, cx, cy, hu, hv, m, ring, ym, var, lm, edge_share, min_contrast, iterations):
    """:func:`luma_row_centroid`'s loops (compiled: a numpy version cost ~0.3 ms a sticker, a quarter of the
    colour tracker's frame rate)."""
    h, w = Y.shape
    reach_u = hu + m + 1.0 + ring + 1.0
    reach_v = hv + m + 1.0 + ring + 1.0
    x0, x1 = int(math.floor(cx - reach_u)), int(math.ceil(cx + reach_u)) + 1
    y0, y1 = int(math.floor(cy - reach_v)), int(math.ceil(cy + reach_v)) + 1
    if x0 < 0 or y0 < 0 or x1 > w or y1 > h:
        return math.nan, math.nan
    n_max = (x1 - x0) * (y1 - y0)
    side = np.empty(n_max)
    top = np.empty(n_max)
    bottom = np.empty(n_max)
    y = cy
    sigma = math.nan
    for _ in range(iterations):
        ns = 0
        nt = 0
        nb = 0
        for yy in range(y0, y1):
            dy = yy - y
            dv = max(abs(dy) - hv, 0.0)
            for xx in range(x0, x1):
                du = max(abs(xx - cx) - hu, 0.0)
                d = math.sqrt(du * du + dv * dv)
                v = float(Y[yy, xx])
                # The blade's level from the ring's sides (rows within the support's half-height).
                if m + 1.0 <= d <= m + 1.0 + ring and abs(dy) <= hv:
                    side[ns] = v
                    ns += 1
                # Just above and below the support: where the section's edge would show.
                if m + 0.5 <= d <= m + 1.5:
                    if dy < -hv:
                        top[nt] = v
                        nt += 1
                    elif dy > hv:
                        bottom[nb] = v
                        nb += 1
        if ns < 8:
            return math.nan, math.nan
        med = np.median(side[:ns])
        mad = np.median(np.abs(side[:ns] - med))
        tol = max(4.0 * 1.4826 * mad, 3.0 * math.sqrt(var), 2.0)
        total = 0.0
        kept = 0
        for i in range(ns):
            if abs(side[i] - med) <= tol:
                total += side[i]
                kept += 1
        if kept < 8:
            return math.nan, math.nan
        level = total / kept
        contrast = ym - level
        if not abs(contrast) >= min_contrast:
            return math.nan, math.nan
        limit = max(tol, edge_share * abs(contrast))
        if nt > 0 and abs(np.median(top[:nt]) - level) > limit:
            return math.nan, math.nan
        if nb > 0 and abs(np.median(bottom[:nb]) - level) > limit:
            return math.nan, math.nan
        m00 = 0.0
        m01 = 0.0
        vsum = 0.0
        for yy in range(y0, y1):
            dy = yy - y
            wy = min(max(hv + lm + 0.5 - abs(dy), 0.0), 1.0)
            if wy == 0.0:
                continue
            for xx in range(x0, x1):
                wx = min(max(hu + m + 0.5 - abs(xx - cx), 0.0), 1.0)
                if wx == 0.0:
                    continue
                a = wx * wy * (float(Y[yy, xx]) - level) / contrast
                m00 += a
                m01 += a * dy
                vsum += (wx * wy * dy) ** 2
        if not m00 > 0.0:
            return math.nan, math.nan
        sigma = math.sqrt(var * vsum) / (abs(contrast) * m00)
        y = y + m01 / m00
    return y, sigma
