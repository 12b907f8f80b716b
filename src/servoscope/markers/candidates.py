"""Candidate coloured (or, on monochrome footage, bright) blobs in a frame, so that a user can pick the markers."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .colour import BRIGHT, BrightnessModel, ColourModel, hsv_of_rgb
from .selection import solidity_of

__all__ = ["Candidate", "draw_candidates", "find_brightness_candidates", "find_candidates", "is_gray"]


@dataclass(frozen=True)
class Candidate:
    """A saturated blob.

    Attributes
    ----------
    number : int
        1-based, largest first.
    colour_hex : str
        Median colour of the blob, "#rrggbb" (or ``"bright"``/``"dark"``: a blob told by brightness).
    x_px, y_px : float
        Centroid (pixels).
    area_px : int
    hue_deg : float
        0–360 (NaN for a blob told by brightness).
    solidity : float
        Area over convex-hull area: ≥ 0.9 for a disc, a square or a strip.
    touches_border : bool
        Whether the blob reaches the image's edge (then it is cut off).
    """

    number: int
    colour_hex: str
    x_px: float
    y_px: float
    area_px: int
    hue_deg: float
    solidity: float = 1.0
    touches_border: bool = False


def find_candidates(
    rgb: np.ndarray, *, min_saturation: int = 90, min_value: int = 50, min_area_px: int = 12, limit: int = 20
) -> list[Candidate]:
    """Saturated connected blobs of one frame, largest first.

    Parameters
    ----------
    rgb : ndarray, shape (h, w, 3), uint8
    min_saturation, min_value : int
        OpenCV HSV floors (0–255): grey, black and white are not markers.
    min_area_px : int
    limit : int
        At most this many candidates.
    """
    hsv = hsv_of_rgb(rgb)
    mask = (hsv[..., 1] >= min_saturation) & (hsv[..., 2] >= min_value)

    def describe(pixels: np.ndarray) -> tuple[str, float]:
        model = ColourModel.learn(pixels)
        r, g, b = (int(round(c)) for c in model.rgb)
        return f"#{r:02x}{g:02x}{b:02x}", 2.0 * model.hue

    return _blobs(rgb, mask, describe, min_area_px, limit)


def is_gray(rgb: np.ndarray) -> bool:
    """Whether a frame has no colour at all (monochrome footage: three equal channels)."""
    a = np.asarray(rgb)
    return bool(np.array_equal(a[..., 0], a[..., 1]) and np.array_equal(a[..., 1], a[..., 2]))


def find_brightness_candidates(rgb: np.ndarray, spec: str = BRIGHT, *, min_area_px: int = 12,
                               limit: int = 20) -> list[Candidate]:
    """Blobs brighter (``"bright"``) or darker (``"dark"``) than the frame's marker threshold, largest first.

    Monochrome footage's markers: the threshold is the tracker's own
    (:meth:`~servoscope.markers.colour.BrightnessModel.from_frame`). Each
    candidate's ``colour_hex`` is the spec (``"bright"``), its hue NaN.
    """
    mask = BrightnessModel.from_frame(rgb, spec).mask(rgb)
    return _blobs(rgb, mask, lambda pixels: (spec, float("nan")), min_area_px, limit)


def _blobs(rgb: np.ndarray, mask: np.ndarray, describe, min_area_px: int, limit: int) -> list[Candidate]:
    """The connected blobs of ``mask`` (opened by 3×3), largest first, as candidates (``describe``: colour, hue)."""
    mask = cv2.morphologyEx(mask.astype(np.uint8), cv2.MORPH_OPEN, np.ones((3, 3), np.uint8))
    n, labels, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    order = np.argsort(-stats[1:, cv2.CC_STAT_AREA]) + 1
    out: list[Candidate] = []
    for i in order:
        area = int(stats[i, cv2.CC_STAT_AREA])
        if area < min_area_px or len(out) >= limit:
            break
        colour, hue = describe(rgb[labels == i])
        x0, y0, bw, bh = (int(v) for v in stats[i, :4])
        border = x0 == 0 or y0 == 0 or x0 + bw >= rgb.shape[1] or y0 + bh >= rgb.shape[0]
        out.append(Candidate(len(out) + 1, colour, float(cents[i, 0]), float(cents[i, 1]), area, hue,
                             solidity_of(labels[y0:y0 + bh, x0:x0 + bw] == i), bool(border)))
    return out


def draw_candidates(rgb: np.ndarray, candidates: list[Candidate]) -> np.ndarray:
    """A copy of the frame with each candidate circled and numbered (RGB uint8)."""
    canvas = np.ascontiguousarray(rgb.copy())
    for c in candidates:
        radius = int(max(6, np.sqrt(c.area_px / np.pi) + 5))
        centre = (int(round(c.x_px)), int(round(c.y_px)))
        cv2.circle(canvas, centre, radius, (255, 255, 255), 1, cv2.LINE_AA)
        cv2.putText(canvas, str(c.number), (centre[0] + radius + 2, centre[1] - radius), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return canvas
