"""Centroids from the (ideal) image into the blade's plane, and the checks that a plane fits the footage.

The plane (:class:`~servoscope.camera.plane.Plane`, made by ``servoscope plane`` from a board
held against the blade) maps ideal image pixels to its *rectified* pixels: the picture a
square-on camera at the same distance would record, at the picture's own scale near its
centre. Angles, separations, heave and bending measured there are the plane's.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np

from ..errors import ServoscopeError
from .model import CameraModel
from .plane import Plane

__all__ = ["area_scale_map", "centroids_in_plane", "plane_camera", "recorded_points", "undistort_jacobian"]


def plane_camera(plane: Plane, camera: CameraModel | None, size: tuple[int, int], where: str | Path) -> CameraModel | None:
    """The lens model to undistort with before the plane, after checking the plane fits the footage.

    Parameters
    ----------
    plane : Plane
    camera : CameraModel or None
        The campaign's (or ``--calibration``'s) lens model.
    size : (int, int)
        The footage's frame size (width, height), upright.
    where : str or Path
        The video, for the message.

    Returns
    -------
    CameraModel or None
        ``camera``, or the plane's own when ``camera`` is None.

    Raises
    ------
    ServoscopeError
        A plane made from photos of another size, or with another calibration than ``camera``
        (its homography maps undistorted points of *that* lens), or without one while the
        footage is undistorted by ``camera``.
    """
    name = plane.source or "plane.json"
    if tuple(plane.image_size) != tuple(size):
        raise ServoscopeError(f"{where}: frames are {size[0]}x{size[1]} but {name} was made from "
                              f"{plane.image_size[0]}x{plane.image_size[1]} photos: photograph the board "
                              "with the campaign's camera in the same mode (servoscope plane)")
    own = plane.camera
    if own is None:
        if camera is not None and camera.has_distortion:
            raise ServoscopeError(f"{where}: {name} was made without a lens calibration but the footage is "
                                  "undistorted with one: make the plane again with "
                                  "`servoscope plane … --calibration camera.json`")
        return camera
    if camera is None:
        return own
    same = (tuple(camera.image_size) == tuple(own.image_size)
            and np.allclose(camera.camera_matrix, own.camera_matrix, rtol=1e-9, atol=1e-9)
            and np.allclose(camera.dist_coeffs, own.dist_coeffs, rtol=1e-9, atol=1e-12))
    if not same:
        raise ServoscopeError(f"{where}: {name} was made with another camera calibration than the one given: "
                              "make the plane again with the campaign's camera.json (servoscope plane "
                              "… --calibration camera.json)")
    return camera


def centroids_in_plane(plane: Plane, xy_px: np.ndarray, sigma_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Map centroids into the plane's rectified pixels, with their uncertainty.

    Parameters
    ----------
    plane : Plane
    xy_px : ndarray, shape (n, 2)
        Ideal (undistorted) image centroids; NaN rows kept.
    sigma_px : ndarray, shape (n,)
        Each coordinate's standard uncertainty in the image (px).

    Returns
    -------
    xy : ndarray, shape (n, 2)
        Rectified px.
    sigma : ndarray, shape (n,)
        The uncertainty there: the image's scaled by the map's local area scale
        ``√|det J|`` (the geometric mean of its stretches; the map is near a similarity
        over a sticker).
    """
    xy = np.array(xy_px, dtype=np.float64, copy=True).reshape(-1, 2)
    sigma = np.array(sigma_px, dtype=np.float64, copy=True).reshape(-1)
    good = np.all(np.isfinite(xy), axis=1)
    if good.any():
        jac = plane.rectified_jacobian(xy[good])
        xy[good] = plane.to_rectified(xy[good])
        sigma[good] = sigma[good] * np.sqrt(np.abs(np.linalg.det(jac)))
    return xy, sigma


def recorded_points(points: np.ndarray, camera: CameraModel | None, plane: Plane | None = None) -> np.ndarray:
    """A track's positions back in the recorded picture, for drawing on its frames.

    Parameters
    ----------
    points : ndarray, shape (n, 2)
        Positions as a track holds them: the plane's rectified px with a plane, else ideal
        (undistorted) px with a lens model, else recorded px. NaN rows kept NaN.
    camera : CameraModel or None
        The lens model the track was made with (the plane's own when the track had none).
    plane : Plane or None
        The plane the track was measured in.

    Returns
    -------
    ndarray, shape (n, 2)
        Recorded-image px.
    """
    out = np.array(points, dtype=np.float64, copy=True).reshape(-1, 2)
    good = np.all(np.isfinite(out), axis=1)
    if not good.any():
        return out
    if plane is not None:
        out[good] = plane.from_rectified(out[good])
        camera = camera if camera is not None else plane.camera
    if camera is not None and camera.has_distortion:
        out[good] = camera.distort_points(out[good])
    return out


#: Cell of the area scale's lookup grid (px): the view's scale changes by ~0.1 % over it at 30°
#: off square (a sticker's area is checked to 3 %).
_AREA_CELL_PX = 8


def area_scale_map(plane: Plane | None, camera: CameraModel | None) -> Callable[[float, float], float] | None:
    """How much a sticker's recorded area grows when it stands at (x, y) of the picture, as the plane says.

    Under an oblique view the nearer part of the plane looks bigger: a sticker's area changes with its
    place as the blade turns, smoothly, where a hidden sticker's drops at once. The tracker divides its
    areas by this before comparing them with the sticker's reference (a square-on camera: 1 everywhere).

    Parameters
    ----------
    plane : Plane or None
    camera : CameraModel or None
        The lens model (its own area change is in the map too).

    Returns
    -------
    callable (x_px, y_px) → float, or None without a plane
        What a recorded area at a recorded point is multiplied by to be the area it would have at
        the picture's centre (nearest cell of an :data:`_AREA_CELL_PX` grid).
    """
    if plane is None:
        return None
    w, h = plane.image_size
    xs = np.arange(0.0, w + _AREA_CELL_PX, _AREA_CELL_PX)
    ys = np.arange(0.0, h + _AREA_CELL_PX, _AREA_CELL_PX)
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx.ravel(), gy.ravel()], axis=1)
    factor = np.ones(len(pts))
    ideal = pts
    if camera is not None and camera.has_distortion:
        ideal = camera.undistort_points(pts)[0]
        factor = np.abs(np.linalg.det(undistort_jacobian(camera, pts)))
    factor = factor * np.abs(np.linalg.det(plane.rectified_jacobian(ideal)))
    # Rectified px per recorded px: a sticker's recorded area times it is the same wherever it stands.
    grid = factor.reshape(gx.shape)
    centre = grid[int(round((h - 1) / 2 / _AREA_CELL_PX)), int(round((w - 1) / 2 / _AREA_CELL_PX))]
    grid = grid / centre
    rows, cols = grid.shape

    def scale(x_px: float, y_px: float) -> float:
        i = min(max(int(round(y_px / _AREA_CELL_PX)), 0), rows - 1)
        j = min(max(int(round(x_px / _AREA_CELL_PX)), 0), cols - 1)
        return float(grid[i, j])

    return scale


def undistort_jacobian(camera: CameraModel, recorded_px: np.ndarray, step_px: float = 0.5) -> np.ndarray:
    """The lens's inverse's local Jacobian at recorded points: (n, 2, 2), ``J[k, a, b] = ∂ideal_a/∂recorded_b``.

    Central differences of :meth:`~servoscope.camera.CameraModel.undistort_points`: the distortion
    varies over hundreds of px, so a half-pixel step leaves an error of ~1e-7.
    """
    pts = np.asarray(recorded_px, dtype=np.float64).reshape(-1, 2)
    dx = (camera.undistort_points(pts + [step_px, 0.0])[0] - camera.undistort_points(pts - [step_px, 0.0])[0])
    dy = (camera.undistort_points(pts + [0.0, step_px])[0] - camera.undistort_points(pts - [0.0, step_px])[0])
    return np.stack([dx, dy], axis=-1) / (2.0 * step_px)
