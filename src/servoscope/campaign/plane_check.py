"""The camera's view of the blade's plane over a campaign: the check, the warning, the affine correction.

Without a plane (``[camera] plane``), the markers' separation over every frame of every test
tells how far off square the camera looks (:func:`servoscope.angle.view.oblique_view`): above
:data:`~servoscope.defaults.OBLIQUE_VIEW_WARNING_DEG` ``identify`` warns with the gain error
it implies. With a plane, the same estimate on the plane's positions checks the plane: a
residual view means the plane is not the blade's (another camera position, a board held
askew). ``identify(self_calibrate_plane=True)`` maps every track by the estimated affine
correction instead: it takes out the foreshortening, not the perspective.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..angle.geometry import blade_angle
from ..angle.rigid import rigid_motion
from ..angle.view import ObliqueView, oblique_view
from ..defaults import OBLIQUE_VIEW_LOWER_DEG, OBLIQUE_VIEW_WARNING_DEG
from ..errors import ServoscopeError
from ..markers.track import Track
from .manifest import Campaign

__all__ = ["SELF_CALIBRATED", "campaign_in_view", "plane_summary", "pooled_view", "view_warning", "with_view_correction"]

#: What a track says of the plane it was measured in when the footage's own view corrected it.
SELF_CALIBRATED = "self-calibrated (affine)"


def pooled_view(tracks: list[Track]) -> ObliqueView | None:
    """The view estimated from every valid frame of ``tracks`` together (one camera set-up).

    Parameters
    ----------
    tracks : list of Track

    Returns
    -------
    ObliqueView or None
        None with too few valid frames.
    """
    if not tracks:
        return None
    lead = np.concatenate([t.lead_xy_px for t in tracks])
    trail = np.concatenate([t.trail_xy_px for t in tracks])
    valid = np.concatenate([t.valid for t in tracks])
    lead_area = np.concatenate([t.lead_area_px for t in tracks])
    trail_area = np.concatenate([t.trail_area_px for t in tracks])
    segment = np.concatenate([np.full(t.n_frames, k) for k, t in enumerate(tracks)])
    return oblique_view(lead, trail, valid, lead_area_px=lead_area, trail_area_px=trail_area, segment=segment)


def view_warning(view: ObliqueView | None, *, plane: str | None, where: str = "") -> str | None:
    """The warning a view earns, or None: off square without a plane, or a plane that does not fit.

    Parameters
    ----------
    view : ObliqueView or None
        The estimate (of the image's positions without a plane, of the plane's with one).
    plane : str or None
        The plane the positions were measured in (None: the image).
    where : str
        What to name the command after (``"servoscope plane board.jpg --board 9x6 --square 25"``).
    """
    if view is None or not (view.view_angle_deg >= OBLIQUE_VIEW_WARNING_DEG
                            and view.view_angle_ci95_deg[0] >= OBLIQUE_VIEW_LOWER_DEG):
        return None
    how = where or "servoscope plane BOARD_PHOTO --board COLSxROWS --square MM --out plane.json"
    if plane is None:
        return (f"{view.describe()}; calibrate the plane: photograph a chessboard held against the blade with "
                f"this camera, run `{how}` and name it in [camera] plane (or track --plane)")
    if plane == SELF_CALIBRATED:
        return None
    return (f"in the plane of {plane}, the markers still show a view {view.view_angle_deg:.0f}° off square "
            f"(95 %: {view.view_angle_ci95_deg[0]:.0f}–{view.view_angle_ci95_deg[1]:.0f}°): the plane does not "
            "seem to be the blade's (the camera moved since the board photo, or the board was not flat against "
            "the blade); angles read about "
            f"{abs(100.0 * (view.angle_gain - 1.0)):.1f} % {'small' if view.angle_gain < 1 else 'large'}")


def _mapped(xy: np.ndarray, correction: np.ndarray, centre: np.ndarray) -> np.ndarray:
    return (xy - centre) @ correction.T + centre


def with_view_correction(track: Track, view: ObliqueView, centre_xy_px: tuple[float, float]) -> Track:
    """The track with its positions mapped by the view's affine correction, and its angles measured again.

    Parameters
    ----------
    track : Track
    view : ObliqueView
        The estimate whose :attr:`~ObliqueView.correction` is applied (determinant 1).
    centre_xy_px : (float, float)
        The point that stays put (the picture's centre).

    Returns
    -------
    Track
        Lead, trail and extra markers' positions mapped; the angle (less the reference
        line's motion where reference stickers took it off: that line is the image's), its
        uncertainty and the bending measured again; ``plane`` says ``"self-calibrated (affine)"``.

    Raises
    ------
    ServoscopeError
        For a track already measured in a plane.
    """
    if track.plane is not None:
        raise ServoscopeError(f"{track.video}: already measured in the plane {track.plane}: "
                              "the footage's own view correction is for footage without one")
    c = np.asarray(view.correction, dtype=np.float64)
    centre = np.asarray(centre_xy_px, dtype=np.float64)
    lead = _mapped(track.lead_xy_px, c, centre)
    trail = _mapped(track.trail_xy_px, c, centre)
    angle, sigma = blade_angle(lead, trail, track.valid, track.lead_sigma_px, track.trail_sigma_px)
    if track.reference_angle_rad is not None:
        angle = angle - np.nan_to_num(track.reference_angle_rad)
        # Its uncertainty held both lines'; the correction (determinant 1) changes the blade's by a few %.
        sigma = np.where(track.valid, track.angle_sigma_rad, np.nan)
    changes: dict = {"lead_xy_px": lead, "trail_xy_px": trail, "angle_rad": np.where(track.valid, angle, np.nan),
                     "angle_sigma_rad": sigma, "plane": SELF_CALIBRATED, "plane_mm_per_px": None}
    if track.extra_xy_px is not None and track.bending_px is not None and track.valid.any():
        extra = _mapped(track.extra_xy_px, c, centre)
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
    view = pooled_view(ordered)
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
    if view is None or not view.determined:
        swing = "too few frames" if view is None else (
            f"a {view.swing_deg:.1f}° swing gives a view of {view.view_angle_deg:.0f}° "
            f"(95 %: {view.view_angle_ci95_deg[0]:.0f}–{view.view_angle_ci95_deg[1]:.0f}°)")
        raise ServoscopeError(f"{campaign.path}: the footage does not tell the camera's view ({swing}): the blade must "
                              "turn further for a self-calibration; calibrate the plane with a board photo instead "
                              "(servoscope plane)")
    valid = np.concatenate([t.valid for t in ordered])
    mids = np.concatenate([0.5 * (t.lead_xy_px + t.trail_xy_px) for t in ordered])[valid]
    centre = tuple(float(v) for v in np.median(mids, axis=0))
    corrected = {label: with_view_correction(t, view, centre) for label, t in tracks.items()}
    lo, hi = view.angle_gain_ci95
    rel = (hi - lo) / (2.0 * 1.96) / view.angle_gain
    warnings.insert(0, f"angles corrected for the camera's view as the footage tells it: {view.describe()}; the "
                       "correction takes out the foreshortening, not the perspective (a board photo, "
                       "servoscope plane, takes out both)")
    return corrected, view, (rel, "the view self-calibrated from the footage")


def plane_summary(campaign: Campaign, tracks: dict[str, Track]) -> dict | None:
    """What result.json says of the plane the angles were measured in; None: the image."""
    if campaign.plane is not None:
        return {"source": campaign.plane.source or "plane.json", **campaign.plane.summary()}
    if any(t.plane == SELF_CALIBRATED for t in tracks.values()):
        return {"source": SELF_CALIBRATED}
    return None
