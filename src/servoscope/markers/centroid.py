"""Subpixel centroid of one sticker from a soft colour membership.

Each pixel ``p`` near the sticker is modelled as a blend of the sticker's
colour ``M`` and the background ``b`` just outside the sticker,

    p − b = α·(M − b) + γ·d + noise,

where ``α`` in [0, 1] is the fraction of the pixel that the sticker covers
(its *soft membership*), and ``d`` is the direction in which the background
itself varies around the sticker (blade vs. sky: a sticker on a blade's edge
has both). Solving for ``α`` by weighted least squares, with the weight the
inverse noise covariance measured on the sticker's own interior, gives each
pixel's coverage; its first moments over a disk that contains the whole
sticker are the centroid (the paper's eqs. 1–4 with a soft ``I(x, y)``).

Why this beats a threshold: a binary flag moves the centroid by whole pixels
as edge pixels flip (the paper's 1 px quantization); ``α`` moves smoothly
with the edge. Why no clipping of ``α``: background pixels inside the disk
have ``α = 0 + noise``; clipping at 0 would turn that zero-mean noise into a
positive bias that changes with the disk's position, so ``α`` is left signed.
Why the nuisance term ``γ·d``: a pixel whose nearest background sample is
blade while it really lies over sky would otherwise read as part sticker.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from .moments import Moments, weighted_moments

__all__ = ["SoftCentroid", "soft_centroid"]

#: Regularisation of the per-channel noise variance (DN²): the 8-bit
#: quantization alone contributes 1/12 DN².
_NOISE_FLOOR_DN2 = 0.25

#: Side of the box over which ring pixels are averaged into the background (px).
BACKGROUND_BOX_PX = 7
#: Project out the background's main colour variation (blade vs. sky).
USE_NUISANCE = True
#: Width of the window's cosine taper, ending at the support radius (px).
#: Measured on H.264 footage: 5 px beats 0 (hard edge) and 7 px.
TAPER_PX = 5.0
#: Weight channels by the noise covariance of the sticker's interior. Off:
#: a codec leaves a flat interior almost free of chroma noise, which would
#: make the chroma channels weigh most exactly where the codec's chroma
#: errors at the edges are largest (measured: worse on H.264, no gain raw).
NOISE_WEIGHTING = False


@dataclass(frozen=True)
class SoftCentroid:
    """A sticker's soft-membership moments and what they rest on.

    Attributes
    ----------
    moments : Moments
        Moments of the signed membership ``α`` over the support disk (px, px²).
    sigma_px : float
        Standard uncertainty of each centroid coordinate from pixel noise
        (px), propagated from the noise covariance measured on the sticker.
    support_radius_px : float
        Radius of the disk the moments were taken over (px).
    contrast_dn : float
        Median length of ``M − b`` after removing the background's own
        variation direction (DN): how well the sticker stands out.
    foreign_fraction : float
        Fraction of support pixels whose colour the sticker/background blend
        cannot explain (χ² > 30): a hint of an occluder or another object.
    at_border : bool
        The support disk or its background ring leaves the image.
    """

    moments: Moments
    sigma_px: float
    support_radius_px: float
    contrast_dn: float
    foreign_fraction: float
    at_border: bool


def _noise_weight(marker_pixels_rgb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Marker colour (median) and inverse noise covariance from its core pixels."""
    px = np.asarray(marker_pixels_rgb, dtype=np.float64).reshape(-1, 3)
    marker = np.median(px, axis=0)
    if px.shape[0] >= 12:
        dev = px - marker
        # A robust covariance: drop the 10 % most deviant pixels (codec ringing, specks).
        d2 = np.einsum("ij,ij->i", dev, dev)
        keep = dev[d2 <= np.percentile(d2, 90)]
        cov = keep.T @ keep / max(keep.shape[0] - 1, 1)
    else:
        cov = np.eye(3) * 4.0
    cov = cov + np.eye(3) * _NOISE_FLOOR_DN2
    if not NOISE_WEIGHTING:
        # Only the scale: the noise structure of a flat interior (where a
        # codec keeps little chroma noise) misjudges the edges' errors.
        cov = np.eye(3) * (np.trace(cov) / 3.0)
    return marker, np.linalg.inv(cov)


def soft_centroid(
    rgb: np.ndarray,
    centre_xy_px: tuple[float, float],
    support_radius_px: float,
    marker_pixels_rgb: np.ndarray,
    *,
    ring_width_px: float = 4.0,
    iterations: int = 4,
) -> SoftCentroid | None:
    """Centroid of the sticker near ``centre_xy_px`` from its soft colour membership.

    Parameters
    ----------
    rgb : ndarray, shape (h, w, 3), uint8
        The frame.
    centre_xy_px : (float, float)
        First guess of the centroid (px), e.g. a binary blob's centroid.
    support_radius_px : float
        Radius of the disk that holds the whole sticker plus a margin of a
        few pixels of background (px).
    marker_pixels_rgb : ndarray, shape (n, 3)
        Pixels from the sticker's interior: give its colour and noise.
    ring_width_px : float
        Width of the background ring just outside the support (px).
    iterations : int
        Passes; each recentres the support disk on the previous centroid.

    Returns
    -------
    SoftCentroid, or None when the membership sums to nothing.

    Long because it is one estimator's steps (background ring, unmixing direction,
    membership, moments, their uncertainty) on arrays they share.
    """
    h, w = rgb.shape[:2]
    marker, weight = _noise_weight(marker_pixels_rgb)
    cx, cy = float(centre_xy_px[0]), float(centre_xy_px[1])
    radius = float(support_radius_px)
    outer = radius + 1.0 + ring_width_px
    result: SoftCentroid | None = None
    for _ in range(max(1, iterations)):
        x0, x1 = int(math.floor(cx - outer)), int(math.ceil(cx + outer)) + 1
        y0, y1 = int(math.floor(cy - outer)), int(math.ceil(cy + outer)) + 1
        at_border = x0 < 0 or y0 < 0 or x1 > w or y1 > h
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        if x1 - x0 < 3 or y1 - y0 < 3:
            return None
        roi = rgb[y0:y1, x0:x1].astype(np.float64)
        yy, xx = np.mgrid[y0:y1, x0:x1]
        dist = np.hypot(xx - cx, yy - cy)
        support = dist <= radius
        ring = (dist >= radius + 1.0) & (dist <= outer)
        ring_rgb = roi[ring]
        if ring_rgb.shape[0] < 8:
            return None
        # Ring pixels that look like the marker (a neighbouring sticker of the
        # same colour, a reflection) are not background.
        ref_bg = np.median(ring_rgb, axis=0)
        contrast0 = marker - ref_bg
        frac = (ring_rgb - ref_bg) @ contrast0 / max(float(contrast0 @ contrast0), 1e-9)
        bg_ok = frac < 0.25
        if bg_ok.sum() >= 8:
            ring_idx = np.flatnonzero(ring.ravel())
            ring = np.zeros_like(ring)
            ring.ravel()[ring_idx[bg_ok]] = True
            ring_rgb = ring_rgb[bg_ok]
        # Per-pixel background: the colour of the nearest ring pixel, averaged
        # over the ring pixels around it (a normalised box filter, so that no
        # sticker pixel leaks in): less noise than one pixel's colour, and
        # the blade/sky mixtures it makes lie along the nuisance direction.
        ring_f = ring.astype(np.float64)
        k = (BACKGROUND_BOX_PX, BACKGROUND_BOX_PX)
        smooth = cv2.blur(roi * ring_f[..., None], k) / np.maximum(cv2.blur(ring_f, k), 1e-9)[..., None]
        _, labels = cv2.distanceTransformWithLabels((~ring).astype(np.uint8), cv2.DIST_L2, 5,
                                                    labelType=cv2.DIST_LABEL_PIXEL)
        lut = np.zeros((int(labels.max()) + 1, 3))
        lut[labels[ring]] = smooth[ring]
        sel = support
        bg = lut[labels[sel]]
        r = roi[sel] - bg
        c = marker - bg
        # The background's own main direction of variation (if well above noise).
        d = _nuisance_direction(ring_rgb, weight, marker - ring_rgb.mean(axis=0)) if USE_NUISANCE else None
        wc = c @ weight
        cwc = np.einsum("ij,ij->i", wc, c)
        cwr = np.einsum("ij,ij->i", wc, r)
        if d is not None:
            wd = weight @ d
            dwd = float(d @ wd)
            cwd = c @ wd
            dwr = r @ wd
            det = np.maximum(cwc * dwd - cwd * cwd, 1e-9)
            alpha = (dwd * cwr - cwd * dwr) / det
            var_alpha = dwd / det
            gamma = (cwc * dwr - cwd * cwr) / det
            resid = r - alpha[:, None] * c - gamma[:, None] * d
            contrast = np.sqrt(np.maximum(cwc - cwd * cwd / dwd, 0.0))
        else:
            alpha = cwr / np.maximum(cwc, 1e-9)
            var_alpha = 1.0 / np.maximum(cwc, 1e-9)
            resid = r - alpha[:, None] * c
            contrast = np.sqrt(cwc)
        chi2 = np.einsum("ij,ij->i", resid @ weight, resid)
        alpha_img = np.zeros(support.shape)
        # A flat-top window, 1 over the sticker, tapering to 0 across the
        # margin: background pixels far out (lever arm, codec ringing) weigh
        # less. Recentred each pass, its fixed point is the centre of a
        # symmetric sticker whatever the taper.
        # Small stickers: keep the flat part over the sticker itself.
        taper_px = min(TAPER_PX, 0.3 * radius)
        taper = np.clip((radius - dist[sel]) / max(taper_px, 1e-9), 0.0, 1.0)
        taper = 0.5 - 0.5 * np.cos(np.pi * taper)
        alpha_img[sel] = alpha * taper
        m = weighted_moments(alpha_img, (float(x0), float(y0))) if alpha.sum() > 0 else None
        if m is None or not (m.m00 > 0):
            return None
        # Background noise enters through b as well (a mean of several ring pixels).
        var_alpha = var_alpha * (1.0 + 1.0 / 8.0)
        xs, ys = xx[sel], yy[sel]
        var_x = float(np.sum(var_alpha * (xs - m.x_px) ** 2)) / m.m00**2
        var_y = float(np.sum(var_alpha * (ys - m.y_px) ** 2)) / m.m00**2
        # Contrast in DN: undo the noise weighting with the mean noise variance.
        noise_dn2 = 3.0 / float(np.trace(weight))
        result = SoftCentroid(
            moments=m,
            sigma_px=math.sqrt(0.5 * (var_x + var_y)),
            support_radius_px=radius,
            contrast_dn=float(np.median(contrast)) * math.sqrt(noise_dn2),
            foreign_fraction=float(np.mean(chi2 > 30.0)),
            at_border=at_border,
        )
        if not (math.isfinite(m.x_px) and math.isfinite(m.y_px)):
            return None
        cx, cy = m.x_px, m.y_px
    return result


def _nuisance_direction(ring_rgb: np.ndarray, weight: np.ndarray, contrast: np.ndarray) -> np.ndarray | None:
    """Principal direction of the background's colour variation, if it matters.

    Returned only when its variance is well above the noise along it and it
    is not nearly parallel to the sticker's contrast (in the noise metric),
    where projecting it out would remove the signal too.
    """
    dev = ring_rgb - ring_rgb.mean(axis=0)
    cov = dev.T @ dev / max(dev.shape[0] - 1, 1)
    vals, vecs = np.linalg.eigh(cov)
    d = vecs[:, -1]
    noise_along = 1.0 / float(d @ weight @ d) if float(d @ weight @ d) > 0 else 1.0
    if vals[-1] < 9.0 * noise_along + 4.0:
        return None
    cwc = float(contrast @ weight @ contrast)
    dwd = float(d @ weight @ d)
    cwd = float(contrast @ weight @ d)
    if cwc <= 0 or cwd * cwd > 0.9 * cwc * dwd:
        return None
    return d
