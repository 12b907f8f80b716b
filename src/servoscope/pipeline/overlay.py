"""An overlay video: the footage with what the tracker measured drawn on it.

To check tracking by eye: each frame shows both centroids (a cross and a
circle of the marker's size), the line joining them, and the angle; a frame
the tracker rejected carries a red ``invalid: <reason>`` label instead.

Centroids in a :class:`~servoscope.markers.track.Track` are in the ideal
(undistorted) image when the track was made with a camera model; pass the
same camera here and they are mapped back through the lens
(:meth:`CameraModel.distort_points`) so that they land on the stickers in the
recorded image.
"""

from __future__ import annotations

import math
import unicodedata
from pathlib import Path

import cv2
import numpy as np

from ..camera.model import CameraModel
from ..camera.plane_map import recorded_points
from ..errors import ServoscopeError
from ..video.reader import iter_frames, probe_video
from ..video.writer import VideoWriter, container_suffixes
from .._io import atomic_path

__all__ = ["write_overlay", "annotate_frame", "overlay_bit_rate"]

#: RGB colours of the drawing.
LEAD_RGB = (255, 64, 255)
TRAIL_RGB = (0, 255, 255)
LINE_RGB = (255, 255, 255)
TEXT_RGB = (255, 255, 255)
INVALID_RGB = (255, 40, 40)

_SHIFT = 4  # fixed-point bits: OpenCV draws at 1/16 px, so subpixel centroids stay subpixel
_FONT = cv2.FONT_HERSHEY_SIMPLEX


def overlay_bit_rate(width: int, height: int, fps: float) -> int:
    """H.264 bit rate for an overlay video (bit/s).

    0.1 bit per pixel per frame keeps the thin lines and small text sharp
    with x264's fast presets (8 Mbit/s at 720×576, 100 frames/s), between
    2 and 40 Mbit/s.
    """
    rate = 0.1 * width * height * (fps if fps and math.isfinite(fps) else 25.0)
    return int(min(max(rate, 2e6), 40e6))


def _ascii(text: str) -> str:
    # Hershey fonts draw ASCII only: "é" → "e", "θ" → "?".
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode()
    return text if text else "?"


def _pt(xy: np.ndarray) -> tuple[int, int]:
    return int(round(xy[0] * (1 << _SHIFT))), int(round(xy[1] * (1 << _SHIFT)))


def _label(img: np.ndarray, text: str, origin: tuple[int, int], colour, scale: float) -> None:
    """Text on a darkened box, readable on any background.

    (Not an outline drawn thicker: OpenCV widens the glyph advance with the
    thickness, so a thick outline and a thin fill do not line up.)
    """
    thick = max(1, int(round(1.6 * scale)))
    (tw, th), base = cv2.getTextSize(text, _FONT, scale, thick)
    x, y = origin
    h, w = img.shape[:2]
    x0, y0, x1, y1 = max(0, x - 3), max(0, y - th - 3), min(w, x + tw + 3), min(h, y + base + 2)
    if x1 > x0 and y1 > y0:
        img[y0:y1, x0:x1] = (img[y0:y1, x0:x1].astype(np.uint16) * 2 // 7).astype(np.uint8)
    cv2.putText(img, text, origin, _FONT, scale, colour, thick, cv2.LINE_AA)


def annotate_frame(
    rgb: np.ndarray,
    lead_xy_px: np.ndarray,
    trail_xy_px: np.ndarray,
    *,
    angle_rad: float = math.nan,
    valid: bool = True,
    reason: str = "",
    lead_radius_px: float = 6.0,
    trail_radius_px: float = 6.0,
    caption: str = "",
) -> np.ndarray:
    """Draw one frame's measurement on a copy of the frame.

    Parameters
    ----------
    rgb : ndarray of uint8, shape (h, w, 3)
    lead_xy_px, trail_xy_px : array-like, shape (2,)
        Centroids in *recorded* image pixels (already re-distorted); NaN
        when not found (nothing drawn for that marker).
    angle_rad : float
        The frame's angle (rad), written in degrees; NaN: not written.
    valid : bool
    reason : str
        Why the frame is invalid, shown as ``invalid: <reason>``.
    lead_radius_px, trail_radius_px : float
        Circle radii (px), e.g. the markers' equivalent radius sqrt(area/π).
    caption : str
        First line of text (frame number and time).

    Returns
    -------
    ndarray of uint8, shape (h, w, 3)
    """
    img = np.ascontiguousarray(rgb, dtype=np.uint8).copy()
    h, w = img.shape[:2]
    scale = max(0.4, min(h, w) / 720.0)
    lead = np.asarray(lead_xy_px, dtype=np.float64).reshape(2)
    trail = np.asarray(trail_xy_px, dtype=np.float64).reshape(2)
    have_lead, have_trail = bool(np.all(np.isfinite(lead))), bool(np.all(np.isfinite(trail)))
    if have_lead and have_trail:
        cv2.line(img, _pt(lead), _pt(trail), LINE_RGB, 1, cv2.LINE_AA, _SHIFT)
    for xy, have, colour, radius in ((lead, have_lead, LEAD_RGB, lead_radius_px), (trail, have_trail, TRAIL_RGB, trail_radius_px)):
        if not have:
            continue
        r = radius if math.isfinite(radius) and radius > 0 else 6.0
        cv2.circle(img, _pt(xy), int(round(r * (1 << _SHIFT))), colour, 1, cv2.LINE_AA, _SHIFT)
        arm = 4.0
        for d in (np.array([arm, 0.0]), np.array([0.0, arm])):
            cv2.line(img, _pt(xy - d), _pt(xy + d), colour, 1, cv2.LINE_AA, _SHIFT)
    line_h = int(round(28 * scale))
    y = line_h
    if caption:
        _label(img, _ascii(caption), (8, y), TEXT_RGB, 0.6 * scale)
        y += line_h
    if valid:
        if math.isfinite(angle_rad):
            _label(img, f"angle {math.degrees(angle_rad):+.3f} deg", (8, y), TEXT_RGB, 0.6 * scale)
    else:
        _label(img, _ascii(f"invalid: {reason or 'no reason given'}"), (8, y), INVALID_RGB, 0.6 * scale)
        # A red frame border: visible even when the video is played small.
        cv2.rectangle(img, (0, 0), (w - 1, h - 1), INVALID_RGB, max(2, int(round(3 * scale))))
    return img


def write_overlay(
    video_path: str | Path,
    track,
    out_path: str | Path,
    *,
    camera: CameraModel | None = None,
    bit_rate: int | None = None,
    plane=None,
) -> Path:
    """Write the footage with the track drawn on it, as H.264 MP4.

    Parameters
    ----------
    video_path : path-like
        The video the track was made from.
    track : Track
        Its track (``servoscope.markers.Track``).
    out_path : path-like
        ``.mp4`` or ``.mov`` file to write; replaced whole (written under a
        temporary name, then renamed).
    camera : CameraModel, optional
        The camera model the track was made with: centroids are re-distorted
        with it before drawing. None: drawn where the track says.
    bit_rate : int, optional
        H.264 bit rate (bit/s); default :func:`overlay_bit_rate`.
    plane : Plane, optional
        The plane the track was measured in (``servoscope.camera.plane.Plane``): its
        positions are mapped back into the picture first.

    Returns
    -------
    Path
        ``out_path``.

    Raises
    ------
    ServoscopeError
        When the video cannot be read, ``out_path`` is not .mp4/.mov or is
        the video itself, or the track has rows for frames the video does
        not have (a track of another video).
    """
    video_path, out_path = Path(video_path), Path(out_path)
    if out_path.suffix.lower() not in container_suffixes("h264"):
        raise ServoscopeError(f"{out_path}: an overlay video is H.264: name it .mp4 or .mov")
    if out_path.resolve() == video_path.resolve():
        raise ServoscopeError(f"{out_path}: would overwrite the footage itself; choose another file")
    info = probe_video(video_path)
    lead = recorded_points(np.asarray(track.lead_xy_px, dtype=np.float64).reshape(-1, 2), camera, plane)
    trail = recorded_points(np.asarray(track.trail_xy_px, dtype=np.float64).reshape(-1, 2), camera, plane)
    lead_r = np.sqrt(np.asarray(track.lead_area_px, dtype=np.float64) / math.pi)
    trail_r = np.sqrt(np.asarray(track.trail_area_px, dtype=np.float64) / math.pi)
    # A track of a deinterlaced video has one row per *field*, two per
    # decoded frame (the tracker numbers fields 0, 1, 2, …): the frame shows
    # its first field's measurement, flagged invalid when either field is.
    n_rows = int(np.asarray(track.frame).size)
    per_frame = 2 if info.frame_count and n_rows == 2 * info.frame_count else 1
    if info.frame_count and n_rows and n_rows > per_frame * info.frame_count:
        # Known before decoding anything, where the container says how many frames it has.
        raise ServoscopeError(_mismatch(video_path, track, n_rows, info.frame_count))
    fps = info.frame_rate_hz or 25.0
    width, height = info.width + info.width % 2, info.height + info.height % 2  # yuv420p needs even sizes
    rate = bit_rate if bit_rate is not None else overlay_bit_rate(width, height, fps)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    n_frames = 0
    with atomic_path(out_path) as tmp:
        # x264 "veryfast" with its own threads: this video is for eyes, its
        # bytes need not be reproducible, and ultrafast smears thin lines.
        with VideoWriter(tmp, width, height, fps, codec="h264", bit_rate=rate, preset="veryfast", threads=0) as writer:
            for frame in iter_frames(video_path):
                row = frame.index * per_frame
                if row >= n_rows:
                    img = annotate_frame(frame.rgb, (math.nan,) * 2, (math.nan,) * 2, valid=False,
                                         reason="no track data for this frame",
                                         caption=f"frame {frame.index}  t = {frame.time_s:.3f} s")
                else:
                    rows = range(row, min(row + per_frame, n_rows))
                    valid = all(bool(track.valid[r]) for r in rows)
                    reason = next((str(track.reason[r]) for r in rows if not track.valid[r]), "")
                    img = annotate_frame(
                        frame.rgb, lead[row], trail[row],
                        angle_rad=float(track.angle_rad[row]), valid=valid, reason=reason,
                        lead_radius_px=float(lead_r[row]), trail_radius_px=float(trail_r[row]),
                        caption=f"frame {frame.index}  t = {float(track.time_s[row]):.3f} s"
                        + ("  (field 1 of 2)" if per_frame == 2 else ""),
                    )
                if img.shape[:2] != (height, width):
                    img = cv2.copyMakeBorder(img, 0, height - img.shape[0], 0, width - img.shape[1], cv2.BORDER_REPLICATE)
                writer.write(img)
                n_frames += 1
        if n_rows > per_frame * n_frames:
            raise ServoscopeError(_mismatch(video_path, track, n_rows, n_frames))
    return out_path


def _mismatch(video_path: Path, track, n_rows: int, n_frames: int) -> str:
    return (f"{video_path}: the track has {n_rows} rows but the video has {n_frames} frames: "
            f"is it the track of another video ({track.video})?")
