"""A track's view of the blade's plane: the stickers' observations, the view they tell, its warning, the correction.

The track-level half of the oblique-view check (issue 27), apart from the campaign's
(:mod:`servoscope.campaign.plane_check`) so that ``servoscope track`` needs nothing of the
identification stages: the stickers' shapes and sizes over every sharp frame tell how far off
square the camera looks (:func:`servoscope.angle.view.oblique_view`); above
:data:`~servoscope.defaults.OBLIQUE_VIEW_WARNING_DEG` a warning says so, and
``--self-calibrate-plane`` maps the positions by the view's homography (foreshortening and
perspective, resting on round or square stickers of one size).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..angle.geometry import blade_angle
from ..angle.rigid import rigid_motion
from ..angle.view import ObliqueView, oblique_view
from ..camera.model import CameraModel
from ..camera.plane import Plane
from ..camera.plane_fit import apply_homography
from ..camera.plane_map import undistort_jacobian
from ..defaults import OBLIQUE_GAIN_WARNING, OBLIQUE_VIEW_WARNING_DEG
from ..errors import ServoscopeError
from ..markers.track import Track

__all__ = ["SELF_CALIBRATED", "pooled_view", "sticker_observations", "told_view", "view_warning",
           "with_view_correction"]

#: What a track says of the plane it was measured in when the footage's own view corrected it.
SELF_CALIBRATED = "self-calibrated (stickers' shapes)"


def _moments(shape_px2: np.ndarray) -> np.ndarray:
    """A track's (mu20, mu11, mu02) rows as 2×2 second-moment matrices."""
    m = np.asarray(shape_px2, dtype=np.float64).reshape(-1, 3)
    return np.stack([np.stack([m[:, 0], m[:, 1]], -1), np.stack([m[:, 1], m[:, 2]], -1)], -2)


def sticker_observations(track: Track, camera: CameraModel | None, plane: Plane | None) -> tuple[np.ndarray, ...]:
    """Each sticker's centroid, second moments, area, and the Jacobian into the frame of the track's positions.

    The moments and areas are measured in the recorded picture; the positions are the ideal
    image's (a lens model given) or the plane's: ``J``, the local Jacobian of the lens's inverse
    (and of the plane's map), carries the moments there (``M → J·M·Jᵀ``, which the view's fit
    does) and the areas (``|det J|``, done here).

    Returns
    -------
    lead_xy, trail_xy : ndarray, shape (n, 2)
    lead_moments, trail_moments : ndarray, shape (n, 2, 2)
        As recorded.
    lead_area, trail_area : ndarray, shape (n,)
        In the positions' frame.
    lead_jacobian, trail_jacobian : ndarray, shape (n, 2, 2)
    """
    out = []
    for xy, shape, area in ((track.lead_xy_px, track.lead_shape_px2, track.lead_area_px),
                            (track.trail_xy_px, track.trail_shape_px2, track.trail_area_px)):
        m = _moments(shape)
        a = np.asarray(area, dtype=np.float64).copy()
        ideal = plane.from_rectified(xy) if plane is not None else np.asarray(xy, dtype=np.float64)
        good = np.all(np.isfinite(ideal), axis=1)
        jac = np.tile(np.eye(2), (len(a), 1, 1))
        if camera is not None and camera.has_distortion and good.any():
            recorded = camera.distort_points(ideal[good])
            jac[good] = undistort_jacobian(camera, recorded)
        if plane is not None and good.any():
            jac[good] = plane.rectified_jacobian(ideal[good]) @ jac[good]
        a = a * np.abs(np.linalg.det(jac))
        out.append((np.asarray(xy, dtype=np.float64), m, a, jac))
    (lx, lm, la, lj), (tx, tm, ta, tj) = out
    return lx, tx, lm, tm, la, ta, lj, tj


def pooled_view(tracks: list[Track], camera: CameraModel | None = None, plane: Plane | None = None) -> ObliqueView | None:
    """The view told by every valid frame of ``tracks`` together (one camera set-up).

    Parameters
    ----------
    tracks : list of Track
    camera : CameraModel, optional
        The lens model the tracks were made with (their shapes are the recorded picture's).
    plane : Plane, optional
        The plane the tracks were measured in: the view is then the plane's residual one.

    Returns
    -------
    ObliqueView or None
        None with too few sharp frames.
    """
    if not tracks:
        return None
    camera = camera if camera is not None else (plane.camera if plane is not None else None)
    parts = [sticker_observations(t, camera, plane) for t in tracks]
    lead, trail, lm, tm, la, ta, lj, tj = (np.concatenate([p[k] for p in parts]) for k in range(8))
    valid = np.concatenate([t.valid for t in tracks])
    segment = np.concatenate([np.full(t.n_frames, k) for k, t in enumerate(tracks)])
    centre = _principal_point(tracks[0], camera, plane)
    return oblique_view(lead, trail, lm, tm, la, ta, valid, segment=segment, centre_px=centre, lead_to_frame=lj,
                        trail_to_frame=tj)


def _principal_point(track: Track, camera: CameraModel | None, plane: Plane | None) -> tuple[float, float] | None:
    """The principal point in the track's frame: the calibration's, else the picture's centre; None unknown."""
    if camera is not None:
        c = np.array([[camera.camera_matrix[0, 2], camera.camera_matrix[1, 2]]])
    elif plane is not None:
        c = np.array([[(plane.image_size[0] - 1) / 2.0, (plane.image_size[1] - 1) / 2.0]])
    elif track.snapshot_rgb is not None:
        h, w = track.snapshot_rgb.shape[:2]
        c = np.array([[(w - 1) / 2.0, (h - 1) / 2.0]])
    else:
        return None
    if plane is not None:
        c = plane.to_rectified(c)
    return float(c[0, 0]), float(c[0, 1])


def view_warning(view: ObliqueView | None, *, plane: str | None, where: str = "", lens: bool = True) -> str | None:
    """The warning a view earns, or None: off square without a plane, or a plane that does not fit.

    Parameters
    ----------
    view : ObliqueView or None
        The estimate (of the image's positions without a plane, of the plane's with one).
    plane : str or None
        The plane the positions were measured in (None: the image); with one, nothing is said.
    where : str
        What to name the command after (``"servoscope plane board.jpg --board 9x6 --square 25"``).
    lens : bool
        Whether the track was made with a lens model. Without one the lens's own distortion
        stretches the stickers off the picture's centre as a view does (a square-on twin with a
        barrel lens of k1 = −0.08 read 9°, 95 %: 1–17°), and the warning says so.
    """
    if view is None or not view.determined:
        return None  # stickers that are not round or square tell nothing of the view
    tilted = view.view_angle_deg >= OBLIQUE_VIEW_WARNING_DEG and view.view_angle_ci95_deg[0] > 0.0
    lo, hi = view.angle_gain_ci95
    # Perspective and foreshortening can cancel in the angles (not in the heave): either one warns.
    scaled = min(abs(lo - 1.0), abs(hi - 1.0)) >= OBLIQUE_GAIN_WARNING and not lo <= 1.0 <= hi
    if not (tilted or scaled):
        return None
    how = where or "servoscope plane BOARD_PHOTO --board COLSxROWS --square MM --out plane.json"
    if plane is None:
        unsure = ("; with no lens calibration given, the lens's own distortion may be what the stickers show: "
                  "calibrate the lens first (servoscope calibrate, then [camera] calibration or --calibration)"
                  if not lens else "")
        return (f"{view.describe()}; calibrate the plane: photograph a chessboard held against the blade with "
                f"this camera, run `{how}` and name it in [camera] plane (or track --plane){unsure}")
    # In a plane (a board photo's, or self-calibrated) the stickers' own estimate is no check: carried
    # into the plane, the tracker's isotropic spread of about 1 px² turns anisotropic and read 8–11° at
    # 30° off square with the board's plane right to 0.02 % in K (docs/accuracy.md).
    return None


def told_view(view: ObliqueView | None, where) -> ObliqueView:
    """``view`` when the footage tells it, for ``--self-calibrate-plane``; one clear error naming ``where`` otherwise."""
    if view is None or not view.determined:
        raise ServoscopeError(f"{where}: the footage does not tell the camera's view ("
                              f"{'too few sharp frames' if view is None else view.why}) for --self-calibrate-plane; "
                              "calibrate the plane with a board photo instead (servoscope plane)")
    return view


def with_view_correction(track: Track, view: ObliqueView) -> Track:
    """The track with its positions mapped into the plane the stickers tell, and its angles measured again.

    Parameters
    ----------
    track : Track
    view : ObliqueView
        The estimate whose :attr:`~ObliqueView.correction` (a homography into the plane's
        rectified px) is applied.

    Returns
    -------
    Track
        Lead, trail and extra markers' positions mapped; the angle (less the reference
        line's motion where reference stickers took it off: that line is the image's), its
        uncertainty and the bending measured again; ``plane`` says :data:`SELF_CALIBRATED`.

    Raises
    ------
    ServoscopeError
        For a track already measured in a plane.
    """
    if track.plane is not None:
        raise ServoscopeError(f"{track.video}: already measured in the plane {track.plane}: "
                              "the footage's own view correction is for footage without one")
    c = np.asarray(view.correction, dtype=np.float64)
    lead, trail = apply_homography(c, track.lead_xy_px), apply_homography(c, track.trail_xy_px)
    angle, sigma = blade_angle(lead, trail, track.valid, track.lead_sigma_px, track.trail_sigma_px)
    if track.reference_angle_rad is not None:
        angle = angle - np.nan_to_num(track.reference_angle_rad)
        # Its uncertainty held both lines'; the correction (near a similarity) changes the blade's by a few %.
        sigma = np.where(track.valid, track.angle_sigma_rad, np.nan)
    changes: dict = {"lead_xy_px": lead, "trail_xy_px": trail, "angle_rad": np.where(track.valid, angle, np.nan),
                     "angle_sigma_rad": sigma, "plane": SELF_CALIBRATED, "plane_mm_per_px": None}
    if track.extra_xy_px is not None and track.bending_px is not None and track.valid.any():
        extra = apply_homography(c, track.extra_xy_px).reshape(track.extra_xy_px.shape)
        points = np.concatenate([lead[:, None], trail[:, None], extra], axis=1)
        sig = np.concatenate([track.lead_sigma_px[:, None], track.trail_sigma_px[:, None], track.extra_sigma_px],
                             axis=1)
        fit = rigid_motion(points, sig, track.valid, fit_markers=2)
        changes.update(extra_xy_px=extra, bending_px=np.where(track.valid[:, None], fit.bending_px, np.nan))
    return replace(track, **changes)
