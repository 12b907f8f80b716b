"""Centroids from the recorded image to the ideal (undistorted) one, through a lens model."""

from __future__ import annotations

import numpy as np

from ..markers.centroid import distortion_centroid_offset
from .model import CameraModel

__all__ = ["undistort_centroids"]


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
        (:func:`~servoscope.markers.centroid.distortion_centroid_offset`).

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
