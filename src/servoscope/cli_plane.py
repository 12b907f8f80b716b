"""The command line's side of the blade's plane: ``track --plane``/``--self-calibrate-plane`` (issue 27)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import click

from .camera.plane import Plane
from .pipeline.plane_view import pooled_view, told_view, view_warning, with_view_correction
from .errors import ServoscopeError

__all__ = ["load_plane_option", "track_in_view"]


def load_plane_option(plane_json: Path | None, self_calibrate: bool) -> Plane | None:
    """``--plane``'s plane.json, read (one clear line when it is not one); refused beside ``--self-calibrate-plane``."""
    if plane_json is None:
        return None
    if self_calibrate:
        raise ServoscopeError(f"--plane {plane_json} and --self-calibrate-plane: give one of them (the plane "
                              "from a board photo corrects the perspective too)")
    return Plane.load(plane_json)


def track_in_view(name: str, result, self_calibrate: bool, camera=None, plane: Plane | None = None):
    """The track checked for a camera that is not square-on: a warning, or (asked) corrected by the footage's view.

    Parameters
    ----------
    name : str
        The footage's name, for the messages.
    result : Track
    self_calibrate : bool
        Correct the track by the view its markers show (``--self-calibrate-plane``).
    camera : CameraModel, optional
        The lens model the track was made with.
    plane : Plane, optional
        The plane it was measured in (the view is then a check of it).

    Returns
    -------
    Track
        ``result`` with the view's warning added, or corrected.

    Raises
    ------
    ServoscopeError
        ``self_calibrate`` where the footage does not tell the view.
    """
    view = pooled_view([result], camera, plane)
    if not self_calibrate:
        said = view_warning(view, plane=result.plane, lens=camera is not None or plane is not None)
        return replace(result, warnings=(*result.warnings, said)) if said else result
    view = told_view(view, name)
    click.echo(f"{name}: angles corrected for the camera's view: {view.describe()} (resting on round or square "
               "stickers of one size)")
    return with_view_correction(result, view)
