"""The camera's view of the blade's plane over a campaign: the check, the warning, the correction.

Without a plane (``[camera] plane``), the stickers' shapes and sizes over every sharp frame of every
test tell how far off square the camera looks (:mod:`servoscope.pipeline.plane_view`): above
:data:`~servoscope.defaults.OBLIQUE_VIEW_WARNING_DEG` ``identify`` warns with the gain error
it implies. ``identify(self_calibrate_plane=True)`` maps every track by the estimated
correction instead (foreshortening and perspective, resting on round or square stickers of one size).
"""

from __future__ import annotations

from ..angle.view import ObliqueView
from ..errors import ServoscopeError
from ..parameters import stderr_of_interval
from ..pipeline.plane_view import SELF_CALIBRATED, pooled_view, told_view, view_warning, with_view_correction
from ..markers.track import Track
from .manifest import Campaign

__all__ = ["campaign_in_view", "plane_summary"]


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
        said = view_warning(view, plane=None if plane is None else (plane.source or "plane.json"),
                            lens=campaign.camera is not None or plane is not None)
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
    rel = stderr_of_interval(lo, hi) / view.angle_gain
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
