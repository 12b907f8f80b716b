"""Centroids from the recorded image to the ideal (undistorted) one, through a lens model."""

from __future__ import annotations

import numpy as np

from .model import CameraModel

__all__ = ["distortion_centroid_offset", "undistort_centroids"]


def undistort_centroids(camera: CameraModel, xy_px: np.ndarray, area_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Undistort a marker's centroids, and say which lie outside the model's trusted region.

    Parameters
    ----------
    camera : CameraModel
    xy_px : ndarray, shape (n, 2)
        Centroids in the recorded image (px); NaN rows where not found.
    area_px : ndarray, shape (n,)
        The markers' soft areas (px²): the centroid of the lens's image of a
        disk is not the image of its centre, and the offset depends on its size
        (:func:`distortion_centroid_offset`).

    Returns
    -------
    ideal_xy_px : ndarray, shape (n, 2)
        The centres in the ideal image (NaN rows kept).
    outside : ndarray of bool
        Found centroids outside the calibrated region (not to be trusted).
    """
    ideal = np.array(xy_px, dtype=np.float64, copy=True)
    outside = np.zeros(ideal.shape[0], dtype=bool)
    good = np.isfinite(ideal[:, 0])
    if good.any():
        raw = ideal[good].copy()
        und, _ = camera.undistort_points(raw)
        radius = np.sqrt(np.asarray(area_px, dtype=np.float64)[good] / np.pi)
        und -= distortion_centroid_offset(camera, und, radius)
        trusted = camera.in_valid_region(raw)
        ideal[good] = und
        outside[np.flatnonzero(good)[~trusted]] = True
    return ideal, outside


#: Quadrature of the sticker's disk: Gauss–Legendre nodes in radius (weight ρ dρ),
#: equally spaced angles (exact for its trigonometric terms). The integrand is the lens's
#: smooth mapping over a few pixels: 3 × 12 nodes agree with 16 × 64 to 1e-6 px.
_QUAD_RADII = 3
_QUAD_ANGLES = 12
#: Step of the central differences for the mapping's Jacobian (px): the distortion varies
#: over hundreds of pixels, so 0.5 px leaves an O(h²) error of ~1e-7.
_JACOBIAN_STEP_PX = 0.5
#: The offset is evaluated once per cell of this size (px) and scaled by (r / r_ref)²: it is
#: the distortion's curvature times the disk's second moments, and the curvature changes by
#: ~3e-5 px of offset per px of position under strong distortion (k1 = −0.08), so a 4 px cell
#: costs < 1e-4 px; the next term in r is r⁴ (a 1 % area change: 1e-4 of the offset).
_OFFSET_CELL_PX = 4.0


def distortion_centroid_offset(camera, centre_px: np.ndarray, radius_px: np.ndarray,
                               *, quad: tuple[int, int] = (_QUAD_RADII, _QUAD_ANGLES)) -> np.ndarray:
    """Where a lens moves a round sticker's image centroid off the image of its centre.

    The recording holds the lens's image of the sticker's disk, uniformly coloured: its
    centroid is ``∫ f(u) |J(u)| du / ∫ |J(u)| du`` over the ideal disk (``f`` the distortion,
    ``J`` its Jacobian), which is not ``f(centre)``: the mapping curves across the disk and
    magnifies one side more than the other. Undistorting that centroid misses the centre by
    a second-order amount, ~0.01 px for a 26 px sticker 300 px off-centre under k1 = −0.08
    (the simulator's default lens): most of the raw footage's bias.

    Parameters
    ----------
    camera : servoscope.camera.CameraModel
        The lens model the centroids were undistorted with.
    centre_px : ndarray, shape (n, 2)
        Undistorted (ideal) centroids, used as the disks' centres (the offset is second
        order, so its error from this is third order).
    radius_px : ndarray, shape (n,)
        Radii of the disks in the recorded image, ``sqrt(area / π)`` of the blobs found:
        converted to the ideal image with the lens's local area scale (a few % off 1 near
        the corners: 4e-4 px of the offset). Non-finite or non-positive radii give a zero
        offset.
    quad : (int, int), optional
        Quadrature nodes in radius and in angle.

    Returns
    -------
    ndarray, shape (n, 2)
        ``undistort(centroid of the recorded disk) − centre``: subtract it from undistorted
        centroids. Zeros when the camera has no distortion.
    """
    c = np.asarray(centre_px, dtype=np.float64).reshape(-1, 2)
    r = np.asarray(radius_px, dtype=np.float64).reshape(-1)
    out = np.zeros_like(c)
    ok = np.isfinite(r) & (r > 0) & np.all(np.isfinite(c), axis=1)
    if not camera.has_distortion or not ok.any():
        return out
    cells, inverse = np.unique(np.round(c[ok] / _OFFSET_CELL_PX), axis=0, return_inverse=True)
    cells = cells * _OFFSET_CELL_PX
    inverse = inverse.reshape(-1)
    _, _, area_scale = _mapped_with_jacobian(camera, cells[:, None, :])
    r_ideal = r[ok] / np.sqrt(area_scale[inverse, 0])
    r_ref = float(np.median(r_ideal))
    at = _disk_image_offset(camera, cells, r_ref, *quad)
    out[ok] = at[inverse] * ((r_ideal / r_ref) ** 2)[:, None]
    return out


def _mapped_with_jacobian(camera, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Distorted ``pts`` (..., 2), and |det J| there by central differences; returns (pts, mapped, |J|)."""
    h = _JACOBIAN_STEP_PX
    steps = np.array([[0.0, 0.0], [h, 0.0], [-h, 0.0], [0.0, h], [0.0, -h]])
    mapped = camera.distort_points((pts[None] + steps.reshape(5, *([1] * (pts.ndim - 1)), 2)).reshape(-1, 2))
    mapped = mapped.reshape(5, *pts.shape)
    fx = (mapped[1] - mapped[2]) / (2.0 * h)
    fy = (mapped[3] - mapped[4]) / (2.0 * h)
    return pts, mapped[0], np.abs(fx[..., 0] * fy[..., 1] - fx[..., 1] * fy[..., 0])


def _disk_image_offset(camera, centres: np.ndarray, radius: float, n_radii: int, n_angles: int) -> np.ndarray:
    """``undistort(centroid of f(disk)) − centre`` for disks of one radius at ``centres`` (m, 2)."""
    x, w = np.polynomial.legendre.leggauss(n_radii)
    rho = 0.5 * (x + 1.0)  # on [0, 1]
    wr = 0.5 * w * rho  # ∫₀¹ g(ρ) ρ dρ
    th = 2.0 * np.pi * np.arange(n_angles) / n_angles
    unit = np.stack([(rho[:, None] * np.cos(th)).ravel(), (rho[:, None] * np.sin(th)).ravel()], axis=-1)
    wq = np.repeat(wr, n_angles)
    _, mapped, jac = _mapped_with_jacobian(camera, centres[:, None, :] + radius * unit[None])  # (m, q, ...)
    jac = jac * wq[None]
    image_centroid = (mapped * jac[..., None]).sum(axis=1) / jac.sum(axis=1)[:, None]
    back, _ = camera.undistort_points(image_centroid)
    return back - centres
