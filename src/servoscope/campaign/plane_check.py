"""The camera's view of the blade's plane over a campaign: the check, the warning, the affine correction.

Without a plane (``[camera] plane``), the stickers' shapes and sizes over every sharp frame of every
test tell how far off square the camera looks (:func:`servoscope.angle.view.oblique_view`): above
:data:`~servoscope.defaults.OBLIQUE_VIEW_WARNING_DEG` ``identify`` warns with the gain error
it implies. With a plane, the same estimate on the plane's positions checks the plane: a
residual view means the plane is not the blade's (another camera position, a board held
askew). ``identify(self_calibrate_plane=True)`` maps every track by the estimated affine
correction instead (foreshortening and perspective, resting on round or square stickers of one size).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..angle.geometry import blade_angle
from ..angle.rigid import rigid_motion
from ..angle.view import ObliqueView, oblique_view
from ..defaults import OBLIQUE_GAIN_WARNING, OBLIQUE_VIEW_WARNING_DEG
from ..errors import ServoscopeError
from ..camera.model import CameraModel
from ..camera.plane import Plane
from ..camera.plane_fit import apply_homography
from ..camera.plane_map import undistort_jacobian
from ..markers.track import Track
from .manifest import Campaign

__all__ = ["SELF_CALIBRATED", "campaign_in_view", "plane_summary", "pooled_view", "sticker_observations", "told_view",
           "view_warning", "with_view_correction"]

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


def view_warning(view: ObliqueView | None, *, plane: str | None, where: str = "") -> str | None:
    """The warning a view earns, or None: off square without a plane, or a plane that does not fit.

    Parameters
    ----------
    view : ObliqueView or None
        The estimate (of the image's positions without a plane, of the plane's with one).
    plane : str or None
        The plane the positions were measured in (None: the image); with one, nothing is said.
    where : str
        What to name the command after (``"servoscope plane board.jpg --board 9x6 --square 25"``).
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
        return (f"{view.describe()}; calibrate the plane: photograph a chessboard held against the blade with "
                f"this camera, run `{how}` and name it in [camera] plane (or track --plane)")
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


def campaign_in_view(campaign: Campaign, tracks: dict[str, Track], self_calibrate: bool,
                     warnings: list[str]) -> tuple[dict[str, Track], ObliqueView | None, tuple[float, str] | None]:
    """The campaign's tracks in the blade's plane as far as it is known, the view they show, the angle scale's error.

    Parameters
    ----------
    campaign : Campaign
    tracks : dict of label → Track
    self_calibrate : bool
        Correct the tracks by the footage's own view (refused with a plane, or where the
        footage does not tell the view).
    warnings : list of str
        Appended to: the view's warning (off square without a plane, a plane that does not
        fit), or what the self-calibration did.

    Returns
    -------
    tracks : dict of label → Track
        As given, or corrected.
    view : ObliqueView or None
        What the markers show (before a self-calibration's correction).
    scale_error : (float, str) or None
        The angles' relative scale uncertainty and where it comes from (the plane's
        calibration, or the self-calibration's estimate), for the gain's interval.
    """
    ordered = [tracks[t.label] for t in campaign.tests if t.label in tracks]
    view = pooled_view(ordered, campaign.camera, campaign.plane)
    plane = campaign.plane
    if not self_calibrate:
        said = view_warning(view, plane=None if plane is None else (plane.source or "plane.json"))
        if said:
            warnings.insert(0, said)
        if plane is not None and plane.angle_gain_std > 0:
            return tracks, view, (float(plane.angle_gain_std), f"the plane's calibration, {plane.source or 'plane.json'}")
        return tracks, view, None
    if plane is not None:
        raise ServoscopeError(f"{campaign.path}: [camera] plane is given: the footage's own view correction "
                              "(--self-calibrate-plane) is for footage without a plane; leave one of them out")
    view = told_view(view, campaign.path)
    corrected = {label: with_view_correction(t, view) for label, t in tracks.items()}
    lo, hi = view.angle_gain_ci95
    rel = (hi - lo) / (2.0 * 1.96) / view.angle_gain
    warnings.insert(0, f"angles corrected for the camera's view as the stickers tell it: {view.describe()}; the "
                       "correction rests on round or square stickers of one size (a board photo, servoscope plane, "
                       "rests on nothing about them)")
    return corrected, view, (rel, "the view self-calibrated from the footage")


def plane_summary(campaign: Campaign, tracks: dict[str, Track]) -> dict | None:
    """What result.json says of the plane the angles were measured in; None: the image."""
    if campaign.plane is not None:
        return {"source": campaign.plane.source or "plane.json", **campaign.plane.summary()}
    if any(t.plane == SELF_CALIBRATED for t in tracks.values()):
        return {"source": SELF_CALIBRATED}
    return None
