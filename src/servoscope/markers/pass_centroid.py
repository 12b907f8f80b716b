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

:func:`chroma_row_centroid` measures such a sticker's height from the *native* 4:2:0 chroma rows
instead (each the mean of two luma rows, sited between them), each row's split between its two luma
rows taken from luma; measured on the twin, not used by the caller by default (its docstring says why).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["CHROMA_EDGE_ALPHA", "CHROMA_MARGIN_ROWS", "EDGE_SHARE", "LUMA_MARGIN_PX", "MIN_CHROMA_CONTRAST_DN",
           "MIN_LUMA_CONTRAST_DN", "MIN_SPLIT_CONTRAST_DN",
           "chroma_row_centroid", "luma_row_centroid"]

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


#: Native chroma rows beyond those the sticker's extent reaches into, each side, in :func:`chroma_row_centroid`'s
#: window. None: the twin's tip leaves about one chroma row of blade above and below its blue sticker, and a margin
#: row takes in the section's edge (sky, 0.09-0.12 of the sticker's chroma contrast on average there). Noise-free
#: raw sweep: rms 0.017 px with 1 row, 0.004 with none; on H.264 at 40 Mbit/s none cuts the codec's chroma smear
#: above the sticker (mean α +0.009 a column in the row just above, raw +0.002): the height reads +0.012 px low
#: (mean of 7 clips), a blade's pitch offset of ~−0.01° that does not change with the row.
CHROMA_MARGIN_ROWS = 0
#: Largest |mean chroma − the blade's| over the sticker's columns in the chroma row just beyond the window, as a
#: share of the sticker's chroma contrast (with a 3σ noise floor); more: the section's edge is within a chroma row
#: of the sticker and likely inside the window's end rows, no height. It refused 0-1 of 36-92 whole frames of the
#: blue sticker on the twin's clips; a drawn sky 1-2 px beyond the sticker is refused at every row.
CHROMA_EDGE_ALPHA = 0.05
#: Least |sticker chroma − blade chroma| (DN) for :func:`chroma_row_centroid`.
MIN_CHROMA_CONTRAST_DN = 20.0
#: Least |sticker luma − blade luma| (DN) for the luma's split of each chroma row's two luma rows; below it the
#: chroma rows are taken as they are, with the 2-px binning's bias (drawn 14-px disc: ±0.012 px unsplit, ≤ 0.0053
#: split at the blue sticker's 17 DN of luma contrast, the rest the luma's 1-DN steps).
MIN_SPLIT_CONTRAST_DN = 8.0


def chroma_row_centroid(Y: np.ndarray, U: np.ndarray, V: np.ndarray, cx: float, cy: float, half_u_px: float,
                        half_v_px: float, margin_px: float, sticker_yuv_dn: tuple[float, float, float],
                        chroma_var_dn2: float, luma_var_dn2: float, luma_split: bool = True) -> tuple[float, float]:
    """A sticker's vertical centroid (luma px) from the native 4:2:0 chroma rows, and its standard error.

    Chroma sample ``(i, j)`` is the mean over luma rows ``2j, 2j + 1`` (columns likewise; the twin's and most
    encoders' vertical downsampling, sited midway for MPEG-2, H.264 and HEVC alike), so the window's sum of
    the unmixed share α = ((uv − uv_blade)·(uv_sticker − uv_blade)) / |uv_sticker − uv_blade|² (unclipped)
    is the sticker's area, whatever its sub-pixel row, and its first moment is exact but for each chroma
    row's own split between its two luma rows. That split (the 2-px binning's bias: ±0.01 px for a
    sharp-edged 14-px disc) is taken from luma's difference between the two rows, in which the blade's
    level cancels and whose noise enters with a lever of ±0.5 px, not the centroid's ±7 px. The window
    is the whole chroma rows the sticker's extent reaches into (no margin, :data:`CHROMA_MARGIN_ROWS`):
    beyond them, on a tip, the section's edge, which must not lie in the row just beyond
    (:data:`CHROMA_EDGE_ALPHA`). The blade's chroma is the ring's sides' (as :func:`luma_row_centroid`'s
    luma), one level for the window; the height is recentred as there.

    Not used by :mod:`.passes` by default (docs/rotor.md, "The pitch's scale"): on the twin it halves the
    per-pass pitch RMS of a 17-DN-luma sticker on raw yuv420p and removes its blade's row bias there and
    on the 3-blade H.264 clip, but on H.264 the chroma smear it cuts leaves a constant offset, and on the
    2-blade clips the per-pass RMS grew.

    Parameters
    ----------
    Y : ndarray, shape (h, w)
        The frame's luma plane.
    U, V : ndarray, shape (h/2, w/2)
        The frame's chroma planes, not upsampled.
    cx, cy : float
        The kernel's centroid (luma px): the window's first centre.
    half_u_px, half_v_px : float
        The sticker's half-sides (luma px) along the rows and across them.
    margin_px : float
        Support beyond the half-side along the rows (luma px).
    sticker_yuv_dn : (float, float, float)
        The sticker's own Y, U, V (DN).
    chroma_var_dn2, luma_var_dn2 : float
        Each chroma channel's and the luma's noise variance (DN²).
    luma_split : bool
        Take each chroma row's split between its luma rows from luma (where the sticker's luma contrast is at
        least :data:`MIN_SPLIT_CONTRAST_DN`); False: the chroma rows as they are.

    Returns
    -------
    (float, float)
        ``(y_px, sigma_px)``; NaN, NaN where the window leaves the picture, the ring's sides leave too few
        samples for the blade's chroma, the blade's chroma differs from the sticker's by under
        :data:`MIN_CHROMA_CONTRAST_DN`, or the row just beyond the window is not the blade's.
    """
    ys, us, vs = (float(v) for v in sticker_yuv_dn)
    y, sigma = _chroma_rows_nb(Y, U, V, float(cx), float(cy), float(half_u_px), float(half_v_px), float(margin_px),
                               ys, us, vs, float(chroma_var_dn2), float(luma_var_dn2), CHROMA_MARGIN_ROWS,
                               CHROMA_EDGE_ALPHA, MIN_CHROMA_CONTRAST_DN,
                               MIN_SPLIT_CONTRAST_DN if luma_split else math.inf, ITERATIONS)
    return float(y), float(sigma)


@njit(cache=True, nogil=True)
def _chroma_rows_nb(Y, U, V, cx, cy, hu, hv, m, ym, um, vm, var, var_y, mrows, edge_alpha, min_contrast, min_split,
                    iterations):
    """:func:`chroma_row_centroid`'s loops (compiled, as :func:`luma_row_centroid`'s).

    Long because each recentring pass takes the blade's level, checks the rows beyond the window and sums
    the moments over one window's indices; split, the parts would pass a dozen of them between them.
    """
    hc, wc = U.shape
    # Chroma column i's centre is at luma 2i + 0.5. The ring's sides: 1.5 to 5.5 luma px beyond the support.
    reach_u = hu + m + 5.5
    i0 = int(math.floor((cx - reach_u - 0.5) / 2.0))
    i1 = int(math.ceil((cx + reach_u - 0.5) / 2.0)) + 1
    y = cy
    sigma = math.nan
    for _ in range(iterations):
        # Whole chroma rows: those the sticker's extent reaches into (row j spans luma [2j − 0.5, 2j + 1.5]).
        jc0 = int(math.floor((y - hv + 0.5) / 2.0)) - mrows
        jc1 = int(math.floor((y + hv + 0.5) / 2.0)) + mrows
        if i0 < 0 or i1 > wc or jc0 - 1 < 0 or jc1 + 2 > hc:
            return math.nan, math.nan
        # The blade's chroma (and luma): the ring's sides, rows within the sticker's half-height.
        ns_max = (i1 - i0) * (jc1 - jc0 + 1)
        bu = np.empty(ns_max)
        bv = np.empty(ns_max)
        by = np.empty(ns_max)
        nside = 0
        for j in range(jc0, jc1 + 1):
            if abs(2.0 * j + 0.5 - y) > hv:
                continue
            for i in range(i0, i1):
                d = abs(2.0 * i + 0.5 - cx) - (hu + m)
                if 1.5 <= d <= 5.5:
                    bu[nside] = float(U[j, i])
                    bv[nside] = float(V[j, i])
                    by[nside] = 0.25 * (float(Y[2 * j, 2 * i]) + float(Y[2 * j, 2 * i + 1])
                                        + float(Y[2 * j + 1, 2 * i]) + float(Y[2 * j + 1, 2 * i + 1]))
                    nside += 1
        if nside < 4:
            return math.nan, math.nan
        mu = np.median(bu[:nside])
        mv = np.median(bv[:nside])
        tol = max(4.0 * math.sqrt(var), 3.0)
        su = 0.0
        sv = 0.0
        sy = 0.0
        kept = 0
        for k in range(nside):
            if abs(bu[k] - mu) <= tol and abs(bv[k] - mv) <= tol:
                su += bu[k]
                sv += bv[k]
                sy += by[k]
                kept += 1
        if kept < 4:
            return math.nan, math.nan
        du = um - su / kept
        dv = vm - sv / kept
        lu = su / kept
        lv = sv / kept
        c2 = du * du + dv * dv
        if not c2 >= min_contrast * min_contrast:
            return math.nan, math.nan
        cy_dn = ym - sy / kept
        split = abs(cy_dn) >= min_split
        # The rows just beyond the window, over the sticker's columns: the blade's chroma, or the section's edge
        # (sky, wall) within a chroma row of the sticker's extent, and so likely inside the window's end rows too.
        # The whole chroma difference, not its share along the sticker's: a sky may differ from the blade across it.
        for jj in (jc0 - 1, jc1 + 1):
            tu = 0.0
            tv = 0.0
            n = 0
            for i in range(i0, i1):
                if abs(2.0 * i + 0.5 - cx) <= hu + m:
                    tu += float(U[jj, i]) - lu
                    tv += float(V[jj, i]) - lv
                    n += 1
            if n == 0 or math.hypot(tu / n, tv / n) > max(edge_alpha * math.sqrt(c2), 3.0 * math.sqrt(2.0 * var / n)):
                return math.nan, math.nan
        m00 = 0.0
        m01 = 0.0
        vsum = 0.0
        ssum = 0.0
        for j in range(jc0, jc1 + 1):
            dy = 2.0 * j + 0.5 - y
            for i in range(i0, i1):
                wx = min(max((hu + m + 1.0 - abs(2.0 * i + 0.5 - cx)) / 2.0, 0.0), 1.0)
                if wx == 0.0:
                    continue
                a = wx * ((float(U[j, i]) - lu) * du + (float(V[j, i]) - lv) * dv) / c2
                m00 += a
                m01 += a * dy
                if split:
                    # The cell's own first moment about its centre: half the lower luma row's share less the
                    # upper's (the cell's α is their mean; luma's blade level cancels in the difference).
                    dl = (float(Y[2 * j + 1, 2 * i]) + float(Y[2 * j + 1, 2 * i + 1])
                          - float(Y[2 * j, 2 * i]) - float(Y[2 * j, 2 * i + 1])) / cy_dn
                    m01 += wx * 0.125 * dl
                    ssum += 4.0 * (wx * 0.125 / cy_dn) ** 2
                vsum += (wx * dy) ** 2
        if not m00 > 0.0:
            return math.nan, math.nan
        sigma = math.sqrt(var * vsum / c2 + var_y * ssum) / m00
        y = y + m01 / m00
    return y, sigma
