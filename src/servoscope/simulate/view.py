"""An oblique view of the blade's plane: the homography from plane pixels to the ideal image.

The twin's scene (:class:`~servoscope.simulate.scene.Scene`) is drawn in *plane px*: the
blade's plane, measured in the pixels that a square-on camera at the same distance records,
so that plane px are image px when the camera faces the plane square-on. A camera that
looks at the plane from the side sees it through a homography; :class:`ObliqueView` is that
homography, built from the camera's pose. The lens (``CameraModel.distort_points``) acts
after it, on the ideal image it gives.

Geometry (world axes: x right, y down in the plane, z away from the square-on camera, into
the scene; the look-at point L, the picture centre in the plane, is the origin). The
square-on camera sits at ``(0, 0, −f)``, f = ``focal_px``, looking along +z, so that it
records the plane at magnification 1 at L. The oblique camera is that camera turned about L
by ``yaw_deg`` about the plane's vertical axis, then by ``tilt_deg`` about its own horizontal
axis (a pan–tilt head: its rows stay level), always looking at L. Its centre is

    C = f · (sin yaw · cos tilt, −sin tilt, −cos yaw · cos tilt).

Signs: **positive yaw moves the camera to the right of the blade** (+x), so the plane's right
side is nearer and drawn larger, the left side farther and smaller; **positive tilt moves it
up** (−y, looking down at the blade), so the plane's top is nearer and drawn larger.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field

import numpy as np

from ..errors import ServoscopeError

__all__ = ["ObliqueView", "MAX_VIEW_DEG", "densify_closed"]

#: The steepest yaw or tilt accepted, degrees: beyond it the plane is seen nearly edge-on.
MAX_VIEW_DEG = 80.0


def densify_closed(closed_xy: np.ndarray, max_segment_px: float) -> np.ndarray:
    """Subdivide a closed polygon's edges so that none exceeds ``max_segment_px``.

    A nonlinear map (the lens, or the lens's inverse) bends straight edges: the outline must
    carry enough vertices to follow the curve. The pieces of an edge are equal, so a
    symmetric outline keeps its centroid.
    """
    xy = np.asarray(closed_xy, dtype=np.float64)
    nxt = np.roll(xy, -1, axis=0)
    pieces = np.maximum(1, np.ceil(np.hypot(*(nxt - xy).T) / max_segment_px).astype(int))
    return np.concatenate([a + (np.arange(n)[:, None] / n) * (b - a) for a, b, n in zip(xy, nxt, pieces)], axis=0)


def _rotation(yaw_deg: float, tilt_deg: float) -> np.ndarray:
    """The camera's axes (columns) in world coordinates: the pan about y, then the tilt about its own x."""
    a, b = math.radians(yaw_deg), math.radians(tilt_deg)
    # R_y(−yaw)·R_x(−tilt): the minus signs make positive angles move the camera right and up.
    ry = np.array([[math.cos(a), 0.0, -math.sin(a)], [0.0, 1.0, 0.0], [math.sin(a), 0.0, math.cos(a)]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(b), math.sin(b)], [0.0, -math.sin(b), math.cos(b)]])
    return ry @ rx


@dataclass(frozen=True)
class ObliqueView:
    """A pinhole camera looking at the blade's plane from the side (see the module's docstring).

    Parameters
    ----------
    yaw_deg : float
        Turn about the plane's vertical axis, degrees; positive: the camera moves to the
        right of the blade (the picture's right side nearer). ``|yaw| < 80``.
    tilt_deg : float
        Then the turn about the camera's horizontal axis, degrees; positive: the camera moves
        up (the picture's top nearer). ``|tilt| < 80``.
    focal_px : float
        Focal length, pixels; also the camera's distance from the look-at point in plane px
        (magnification 1 there when square-on).
    width, height : int
        Picture size, pixels; the principal point and the look-at point are its centre
        ``((width − 1)/2, (height − 1)/2)``.

    Raises
    ------
    ServoscopeError
        An angle of 80° or more, a focal length that is not positive and finite, a picture
        under 2×2 px, or a view whose picture would reach the plane's horizon.
    """

    yaw_deg: float
    tilt_deg: float
    focal_px: float
    width: int
    height: int
    _h: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        yaw, tilt, f = float(self.yaw_deg), float(self.tilt_deg), float(self.focal_px)
        if not (math.isfinite(yaw) and math.isfinite(tilt) and abs(yaw) < MAX_VIEW_DEG and abs(tilt) < MAX_VIEW_DEG):
            raise ServoscopeError(f"view: yaw and tilt must be finite and under {MAX_VIEW_DEG:g}° in size, "
                                  f"not {self.yaw_deg!r} and {self.tilt_deg!r}")
        if not (f > 0 and math.isfinite(f)):
            raise ServoscopeError(f"view: focal_px must be positive and finite, not {self.focal_px!r}")
        if int(self.width) != self.width or int(self.height) != self.height or self.width < 2 or self.height < 2:
            raise ServoscopeError(f"view: picture size must be whole pixels, at least 2x2, not "
                                  f"{self.width!r}x{self.height!r}")
        for name, value in (("yaw_deg", yaw), ("tilt_deg", tilt), ("focal_px", f),
                            ("width", int(self.width)), ("height", int(self.height))):
            object.__setattr__(self, name, value)
        cx, cy = 0.5 * (self.width - 1), 0.5 * (self.height - 1)
        r = _rotation(yaw, tilt)
        k = np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])
        # A plane point (X, Y) is the world point (X − cx, Y − cy, 0); in camera coordinates
        # R^T·(P − C) = R^T·P + (0, 0, f), so H = K·[r1 r2 t]·(shift to L), r_i the columns of R^T.
        rt = r.T
        extrinsic = np.column_stack([rt[:, 0], rt[:, 1], [0.0, 0.0, f]])
        shift = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [0.0, 0.0, 1.0]])
        h = k @ extrinsic @ shift
        h = h / h[2, 2]
        # Every ray through the picture must meet the plane in front of the camera (z_world > 0):
        # else the picture shows the plane's horizon and the sky beyond, which no homography draws.
        corners = np.array([[-0.5, -0.5, 1.0], [self.width - 0.5, -0.5, 1.0], [-0.5, self.height - 0.5, 1.0],
                            [self.width - 0.5, self.height - 0.5, 1.0]])
        rays_z = (r @ np.linalg.solve(k, corners.T))[2]
        if np.any(rays_z <= 1e-3 * np.linalg.norm(np.linalg.solve(k, corners.T), axis=0)):
            raise ServoscopeError(f"view: yaw {yaw:g}° and tilt {tilt:g}° with a {f:g} px focal length show the "
                                  "plane's horizon in the picture (use smaller angles or a longer focal length)")
        h.flags.writeable = False
        object.__setattr__(self, "_h", h)

    @property
    def homography(self) -> np.ndarray:
        """The 3×3 map from plane px to ideal image px (homogeneous, ``H[2, 2] = 1``), read-only."""
        return self._h

    @property
    def view_angle_deg(self) -> float:
        """Angle between the plane's normal and the line of sight to the look-at point, degrees."""
        c = math.cos(math.radians(self.yaw_deg)) * math.cos(math.radians(self.tilt_deg))
        return math.degrees(math.acos(min(1.0, max(-1.0, c))))

    @property
    def is_square_on(self) -> bool:
        """Whether the camera faces the plane square-on (the view is then the identity)."""
        return self.yaw_deg == 0.0 and self.tilt_deg == 0.0

    @property
    def camera_centre(self) -> np.ndarray:
        """The camera's centre in world coordinates (plane px; origin at the look-at point, z into the scene)."""
        return _rotation(self.yaw_deg, self.tilt_deg) @ np.array([0.0, 0.0, -self.focal_px])

    def apply(self, xy: np.ndarray) -> np.ndarray:
        """Plane px to ideal image px; ``xy`` of shape (..., 2), any leading shape."""
        return _map(self._h, xy)

    def inverse(self, xy: np.ndarray) -> np.ndarray:
        """Ideal image px back to plane px; ``xy`` of shape (..., 2)."""
        return _map(np.linalg.inv(self._h), xy)

    def to_dict(self) -> dict:
        """What truth.json says of the view: the pose, the view angle and the homography."""
        return {"yaw_deg": self.yaw_deg, "tilt_deg": self.tilt_deg, "focal_px": self.focal_px,
                "view_angle_deg": self.view_angle_deg,
                "homography_plane_to_image": self._h.tolist()}


def _map(h: np.ndarray, xy: np.ndarray) -> np.ndarray:
    p = np.asarray(xy, dtype=np.float64)
    if p.shape[-1:] != (2,):
        raise ServoscopeError(f"view: points must have shape (..., 2), not {p.shape}")
    w = h[2, 0] * p[..., 0] + h[2, 1] * p[..., 1] + h[2, 2]
    x = (h[0, 0] * p[..., 0] + h[0, 1] * p[..., 1] + h[0, 2]) / w
    y = (h[1, 0] * p[..., 0] + h[1, 1] * p[..., 1] + h[1, 2]) / w
    return np.stack([x, y], axis=-1)
