"""The chessboard's corners for the blade's plane: found, refined, checked, and fitted one view at a time.

The lower half of :func:`servoscope.camera.plane.calibrate_plane` and
:func:`~servoscope.camera.plane.fit_plane`: each photo's or video frame's corners,
refined sub-pixel on the photo smoothed, undistorted, and each view's own homography
(refused when its board is not flat); the consensus of the views is
:mod:`servoscope.camera.plane_fit`'s.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from ..errors import ServoscopeError
from .calibrate import detect_corners, parse_board, refine_corners, video_candidates
from .model import CameraModel
from .plane_fit import HomographyFit, fit_homography

__all__ = ["MAX_RMS_PX", "check_board", "check_consensus", "check_image_size", "fit_view", "ideal_corners",
           "refine_plane_corners", "video_corners"]

#: A board whose corners miss the fitted homography by more than this (RMS, px) is refused.
MAX_RMS_PX = 2.0
#: Corners are refined on the photo smoothed by a Gaussian of this σ per px of corner spacing, at most
#: ``MAX_SMOOTHING_PX`` (see :func:`refine_plane_corners`).
SMOOTHING_PER_SPACING = 0.12
MAX_SMOOTHING_PX = 2.0


def refine_plane_corners(gray: np.ndarray, corners: np.ndarray, board: tuple[int, int]) -> np.ndarray:
    """Sub-pixel corners for the plane: :func:`~servoscope.camera.calibrate.refine_corners` on the photo smoothed.

    :func:`cv2.cornerSubPix` on a sharp photo is *pixel-locked*: each corner is pulled
    towards the nearest half pixel, by up to 0.08 px where its sub-pixel phase is a quarter
    (measured on the twin's exactly rendered boards). Across a board seen off square the
    phase drifts smoothly, so the errors of neighbouring corners agree, the homography
    absorbs them and its fit's residuals do not show them: at 30° they turned every angle
    measured in the plane 0.046 % small while ``angle_gain_std`` said 0.010 %. A Gaussian
    of σ = 0.12 × the smallest corner spacing (at most 2 px) first takes most of the
    locking out (0.08 → 0.012 px RMS; the angle gain 0.046 → 0.005 %) and leaves a
    photo's own blur and a corner's position as they were (a point-symmetric pattern stays
    point-symmetric about its corner).

    Parameters
    ----------
    gray : ndarray (h, w)
        The photo, gray.
    corners : ndarray (n, 1, 2)
        The detector's corners.
    board : (int, int)
        Inner corners (cols, rows).

    Returns
    -------
    ndarray (n, 1, 2) float32
    """
    g = np.asarray(corners, dtype=np.float64).reshape(board[1], board[0], 2)
    spacing = min(float(np.hypot(*np.diff(g, axis=a).reshape(-1, 2).T).min()) for a in (0, 1))
    sigma = min(MAX_SMOOTHING_PX, SMOOTHING_PER_SPACING * spacing)
    smooth = cv2.GaussianBlur(np.asarray(gray, dtype=np.float32), (0, 0), sigma)
    return refine_corners(smooth, corners, board)


def video_corners(path: Path, board: tuple[int, int], k: int, sizes: dict, camera: CameraModel | None
                   ) -> tuple[list[tuple[int, np.ndarray]], tuple[int, int] | None]:
    """Refined corners of up to ``k`` frames spread through those with the board; (missed, sampled) or None.

    Evenly spread in time rather than chosen for variety (as calibration does): the board
    is meant to lie still in one plane, so a board filmed still gives frames that agree,
    and their scatter is the measurement's.
    """
    found: list[tuple[int, np.ndarray]] = []
    sampled = 0
    for index, gray in video_candidates(path, 4 * k):
        sampled += 1
        check_image_size(path, gray.shape, sizes, camera)
        corners = detect_corners(gray, board, fast=True)
        if corners is not None:
            found.append((index, refine_plane_corners(gray, corners, board)))
    picks = np.unique(np.round(np.linspace(0, len(found) - 1, min(len(found), k))).astype(int)) if found else []
    missed = sampled - len(found)
    return [found[i] for i in picks], ((missed, sampled) if missed else None)


def check_image_size(path: Path, shape: tuple[int, ...], sizes: dict, camera: CameraModel | None) -> None:
    """Refuse a photo of another size than the first one's or than the calibration's."""
    wh = (int(shape[1]), int(shape[0]))
    if camera is not None and wh != tuple(camera.image_size):
        cw, ch = camera.image_size
        raise ServoscopeError(f"{path}: image size {wh[0]}x{wh[1]}, but the calibration is for {cw}x{ch} images;"
                              " use the camera.json made for this camera and mode")
    if sizes and wh not in sizes:
        (first, from_), = sizes.items()
        raise ServoscopeError(f"{path}: image size {wh[0]}x{wh[1]} differs from {first[0]}x{first[1]} of {from_}"
                              " (all photos must come from one camera position and mode)")
    sizes.setdefault(wh, path)


def check_board(board: tuple[int, int] | str, square_mm: float) -> tuple[tuple[int, int], float]:
    """The board's inner corners ``(cols, rows)`` (each ≥ 3) and its square's side (mm, > 0); refused otherwise."""
    if isinstance(board, str):
        board = parse_board(board)
    try:
        cols, rows = int(board[0]), int(board[1])
        ok = len(tuple(board)) == 2 and (cols, rows) == tuple(board)
    except (TypeError, ValueError, IndexError):
        ok = False
    if not ok or cols < 3 or rows < 3:
        raise ServoscopeError(f"board {board!r}: need two integers ≥ 3 (inner corners, COLSxROWS), e.g. 9x6")
    try:
        square = float(square_mm)
    except (TypeError, ValueError):
        square = float("nan")
    if isinstance(square_mm, bool) or not (math.isfinite(square) and square > 0):
        raise ServoscopeError(f"square size {square_mm!r}: must be a positive number of mm")
    return (cols, rows), square


def ideal_corners(corners: np.ndarray, name: str, board: tuple[int, int], camera: CameraModel | None) -> np.ndarray:
    """One view's corners as (n, 2) float64 in the ideal image (undistorted through ``camera``)."""
    c = np.asarray(corners, dtype=np.float64)
    n = board[0] * board[1]
    if c.size != 2 * n or not np.all(np.isfinite(c)):
        raise ServoscopeError(f"{name}: expected {n} finite corners of a {board[0]}x{board[1]} board, got {c.size // 2}")
    c = c.reshape(n, 2)
    if camera is None:
        return c
    ideal, converged = camera.undistort_points(c)
    if not converged.all():
        raise ServoscopeError(f"{name}: the calibration's lens model cannot undistort {int((~converged).sum())} "
                              "corner(s); is camera.json this camera's?")
    return ideal


def fit_view(board_mm: np.ndarray, corners: np.ndarray, name: str, camera: CameraModel | None) -> HomographyFit:
    """One view's own homography; refused when its corners miss a flat board by more than ``MAX_RMS_PX``."""
    try:
        fit = fit_homography(board_mm, corners)
    except ServoscopeError as exc:
        raise ServoscopeError(f"{name}: {exc}") from None
    if not fit.rms_px <= MAX_RMS_PX:
        hint = "" if camera is not None else ", or the lens distorts (give the camera's calibration, camera.json)"
        raise ServoscopeError(
            f"{name}: the board's corners miss a flat board's image by {fit.rms_px:.2f} px RMS (over {MAX_RMS_PX:g} px): "
            f"it is not flat or not a plausible chessboard{hint}")
    return fit


def check_consensus(fit: HomographyFit, names: Sequence[str]) -> None:
    """Refuse views whose boards miss one plane seen from one place by more than ``MAX_RMS_PX``."""
    if not fit.rms_px <= MAX_RMS_PX:
        worst = int(np.argmax(fit.view_rms_px()))
        raise ServoscopeError(
            f"{len(names)} views: their boards miss one plane seen from one place by {fit.rms_px:.2f} px RMS "
            f"(over {MAX_RMS_PX:g} px; worst {names[worst]}): the camera moved, or a photo shows another plane")
