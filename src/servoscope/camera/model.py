"""Pinhole camera with Brown–Conrady distortion, in OpenCV's conventions.

Only *points* are undistorted (centroids), never whole images: that is
cheaper and avoids resampling the pixels whose moments we measure.
"""

from __future__ import annotations

import json

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ..errors import ServoscopeError
from .._io import write_text_atomic

__all__ = ["CameraModel"]


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics and lens distortion of one camera.

    Parameters
    ----------
    image_size : (int, int)
        Width and height in pixels.
    camera_matrix : ndarray, shape (3, 3)
        ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels.
    dist_coeffs : ndarray, shape (5,)
        ``[k1, k2, p1, p2, k3]`` (OpenCV's order).
    rms_reprojection_error_px : float or None
        RMS reprojection error of the calibration that produced the model.
    """

    image_size: tuple[int, int]
    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray = field(default_factory=lambda: np.zeros(5))
    rms_reprojection_error_px: float | None = None

    def __post_init__(self) -> None:
        k = np.asarray(self.camera_matrix, dtype=float).reshape(3, 3)
        d = np.zeros(5)
        given = np.asarray(self.dist_coeffs, dtype=float).ravel()
        if given.size > 5:
            raise ValueError("dist_coeffs: at most 5 coefficients [k1, k2, p1, p2, k3]")
        d[: given.size] = given
        object.__setattr__(self, "camera_matrix", k)
        object.__setattr__(self, "dist_coeffs", d)
        object.__setattr__(self, "image_size", (int(self.image_size[0]), int(self.image_size[1])))

    # -- construction -----------------------------------------------------
    @classmethod
    def ideal(cls, width: int, height: int, focal_px: float | None = None) -> "CameraModel":
        """A distortion-free camera with the principal point at the image centre."""
        f = float(focal_px) if focal_px is not None else float(max(width, height))
        k = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
        return cls((width, height), k, np.zeros(5))

    @classmethod
    def load(cls, path: str | Path) -> "CameraModel":
        """Read ``camera.json`` (see docs/formats.md); bad content raises ServoscopeError."""
        path = Path(path)
        try:
            data = json.loads(path.read_text())
        except FileNotFoundError:
            raise ServoscopeError(f"{path}: calibration file not found") from None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise ServoscopeError(f"{path}: not a readable JSON calibration ({exc})") from None
        try:
            size = data["image_size"]
            k = np.asarray(data["camera_matrix"], dtype=float)
            d = np.asarray(data.get("dist_coeffs", [0, 0, 0, 0, 0]), dtype=float)
            if k.shape != (3, 3) or len(size) != 2 or d.size > 5:
                raise ValueError("wrong shapes")
            if not (np.all(np.isfinite(k)) and np.all(np.isfinite(d)) and k[0, 0] > 0 and k[1, 1] > 0):
                raise ValueError("non-finite or non-positive focal length")
            rms = data.get("rms_reprojection_error_px")
            return cls((int(size[0]), int(size[1])), k, d, None if rms is None else float(rms))
        except (KeyError, TypeError, ValueError) as exc:
            raise ServoscopeError(
                f"{path}: not a camera calibration (need image_size, camera_matrix 3x3, "
                f"dist_coeffs [k1,k2,p1,p2,k3]): {exc}"
            ) from None

    def to_dict(self) -> dict:
        """Plain-typed form, the content of ``camera.json``."""
        return {
            "image_size": list(self.image_size),
            "camera_matrix": self.camera_matrix.tolist(),
            "dist_coeffs": self.dist_coeffs.tolist(),
            "rms_reprojection_error_px": self.rms_reprojection_error_px,
        }

    def save(self, path: str | Path) -> None:
        write_text_atomic(path, json.dumps(self.to_dict(), indent=2) + "\n")

    # -- geometry ------------------------------------------------------------
    @property
    def has_distortion(self) -> bool:
        return bool(np.any(self.dist_coeffs != 0.0))

    def distort_points(self, points_px: np.ndarray) -> np.ndarray:
        """Map ideal (undistorted) pixel coordinates to distorted ones.

        Parameters
        ----------
        points_px : ndarray, shape (n, 2)
            Points in the ideal pinhole image, pixels.

        Returns
        -------
        ndarray, shape (n, 2)
            Where the lens puts them in the recorded image, pixels.
        """
        pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
        if not self.has_distortion:
            return pts.copy()
        k = self.camera_matrix
        # Normalized coordinates, then OpenCV's own forward model (projectPoints)
        # so that our distortion is exactly the one calibrateCamera estimates.
        xn = (pts[:, 0] - k[0, 2]) / k[0, 0]
        yn = (pts[:, 1] - k[1, 2]) / k[1, 1]
        obj = np.stack([xn, yn, np.ones_like(xn)], axis=1).reshape(-1, 1, 3)
        out, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), k, self.dist_coeffs)
        return out.reshape(-1, 2)

    def undistort_points(self, points_px: np.ndarray, *, tolerance_px: float = 1e-6) -> tuple[np.ndarray, np.ndarray]:
        """Map recorded (distorted) pixel coordinates to ideal ones.

        Uses OpenCV's iterative inverse (``cv2.undistortPointsIter`` in
        OpenCV 4, ``cv2.undistortPoints`` with a ``criteria`` argument in
        OpenCV 5; up to 100 iterations), then checks convergence by
        distorting the answer again. See also :meth:`in_valid_region`.

        Parameters
        ----------
        points_px : ndarray, shape (n, 2)
            Points in the recorded (distorted) image, pixels.
        tolerance_px : float, optional
            Convergence tolerance of the iteration, pixels.

        Returns
        -------
        points_px : ndarray, shape (n, 2)
            Ideal pixel coordinates.
        converged : ndarray of bool, shape (n,)
            False where re-distorting misses the input by more than
            ``tolerance_px`` * 1000 (the model is not invertible there, e.g. far
            outside the calibrated field of view).
        """
        pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
        if not self.has_distortion or pts.size == 0:
            return pts.copy(), np.ones(len(pts), dtype=bool)
        k = self.camera_matrix
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, tolerance_px / max(k[0, 0], 1.0))
        src = pts.reshape(-1, 1, 2)
        if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4.x spells the iterative form apart
            und = cv2.undistortPointsIter(src, k, self.dist_coeffs, None, k, criteria)
        else:
            und = cv2.undistortPoints(src, k, self.dist_coeffs, R=None, P=k, criteria=criteria)
        und = und.reshape(-1, 2)
        back = self.distort_points(und)
        miss = np.hypot(*(back - pts).T)
        converged = np.isfinite(miss) & (miss < max(1e3 * tolerance_px, 1e-3))
        return und, converged

    @property
    def monotonic_radius(self) -> float:
        """Normalized radius up to which the radial distortion is one-to-one.

        The radial model ``r_d = r (1 + k1 r² + k2 r⁴ + k3 r⁶)`` folds back
        where ``d r_d / d r = 1 + 3 k1 r² + 5 k2 r⁴ + 7 k3 r⁶`` first reaches
        zero; beyond that radius (in normalized coordinates, i.e. pixels /
        focal length) an undistorted point is not unique and the model has
        no physical meaning. Tangential terms are ignored here.

        Returns
        -------
        float
            The smallest positive fold radius, or ``inf`` when there is none.
        """
        k1, k2, _p1, _p2, k3 = self.dist_coeffs
        # Polynomial in u = r², highest power first, leading zeros dropped.
        coeffs = np.trim_zeros(np.array([7.0 * k3, 5.0 * k2, 3.0 * k1, 1.0]), "f")
        if coeffs.size <= 1:
            return float("inf")
        roots = np.roots(coeffs)
        u = roots[(np.abs(roots.imag) <= 1e-12 * np.maximum(1.0, np.abs(roots.real))) & (roots.real > 0)].real
        return float(np.sqrt(u.min())) if u.size else float("inf")

    def in_valid_region(self, points_px: np.ndarray, *, margin: float = 0.1) -> np.ndarray:
        """Flag recorded points where the calibrated model can be trusted.

        A point is valid when it lies inside the image enlarged by ``margin``
        × width (resp. height) on each side, its undistortion converges (see
        :meth:`undistort_points`) and its undistorted radius is below
        :attr:`monotonic_radius`. Far outside the calibrated field of view
        a polynomial lens model extrapolates wildly even where it inverts.

        Parameters
        ----------
        points_px : ndarray, shape (n, 2)
            Points in the recorded (distorted) image, pixels.
        margin : float, optional
            Allowed excursion beyond the image border, as a fraction of the
            image width and height (0.1 = 10 %).

        Returns
        -------
        ndarray of bool, shape (n,)
        """
        pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
        w, h = self.image_size
        mx, my = margin * w, margin * h
        inside = (
            np.isfinite(pts).all(axis=1)
            & (pts[:, 0] >= -0.5 - mx) & (pts[:, 0] <= w - 0.5 + mx)
            & (pts[:, 1] >= -0.5 - my) & (pts[:, 1] <= h - 0.5 + my)
        )
        if not self.has_distortion or not inside.any():
            return inside
        und, converged = self.undistort_points(np.where(inside[:, None], pts, 0.0))
        k = self.camera_matrix
        r = np.hypot((und[:, 0] - k[0, 2]) / k[0, 0], (und[:, 1] - k[1, 2]) / k[1, 1])
        return inside & converged & (r < self.monotonic_radius)
