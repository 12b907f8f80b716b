"""One marker's state through a video: its learned colour, size, reference shape and motion.

:class:`MarkerTracker` finds the marker in an RGB frame (colour components, then the
soft centroid of the RGB reference estimators) and decides whether a found blob looks
whole; the YUV engines (:mod:`.yuv_engine`) use its prediction, reference shape and
flaw check around their kernel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np

from .centroid import SoftCentroid, soft_centroid
from .colour import AUTO, BRIGHTNESS, BrightnessModel, ColourModel
from .moments import Moments, weighted_moments
from .settings import TrackerSettings

__all__ = ["Blob", "MarkerTracker"]

_KERNEL3 = np.ones((3, 3), np.uint8)


@dataclass
class Blob:
    """A marker found in one frame: its soft moments, centroid uncertainty (px) and any flaw."""

    moments: Moments
    sigma_px: float
    flaw: str  # "" when the blob looks whole, else why it does not


class MarkerTracker:
    """State of one marker: its learned colour, size, shape and last position."""

    #: Frames whose soft area and axes set the marker's reference shape.
    _REFERENCE_FRAMES = 5

    def __init__(self, name: str, spec: tuple[float, float, float] | str, settings: TrackerSettings, *,
                 area_scale: Callable[[float, float], float] | None = None):
        self.name = name
        self.seed = spec
        # "auto" and brightness markers get their model from the first frame.
        self.model: ColourModel | BrightnessModel | None = (
            None if spec == AUTO or spec in BRIGHTNESS else ColourModel.from_seed(spec))  # type: ignore[arg-type]
        self.expected_area: float | None = None  # binary area of the hue mask (px²)
        # Position and velocity as Python floats: updated every frame, where small-array NumPy costs
        # more than the arithmetic.
        self._last: tuple[float, float] | None = None
        self._velocity: tuple[float, float] = (0.0, 0.0)
        self._step_px = 0.0  # the last frame-to-frame move (px), unsmoothed
        self.search_radius_px = settings.search_radius_px
        self.margin_px = settings.support_margin_px
        self.method = settings.centroid
        self.tolerance = settings.shape_tolerance
        self.extent_px = 10.0
        self.reach_px: float | None = None  # sticker radius from its centroid (px)
        self._ref: list[tuple[float, float, float]] = []  # (m00, major, minor) of early frames
        self.reference: tuple[float, float, float] | None = None
        # Where the first detection found this marker (see markers.selection): before the first
        # accepted position, the blob nearest to it is taken, not the largest of the colour.
        self.hint: tuple[float, float] | None = None
        # The sticker's perimeter over that of a disk of its area: edge effects scale with it.
        self.edge_factor = 1.0
        # An oblique view (a plane given) makes a sticker bigger where the plane is nearer: areas and
        # axes are compared at the picture's centre's scale (None: square-on, nothing to undo). The
        # camera stage's map (servoscope.camera.plane_map.area_scale_map), given by the pipeline.
        self.area_scale = area_scale

    # -- detection ---------------------------------------------------------
    def _components(self, rgb: np.ndarray, window: tuple[int, int, int, int]):
        x0, y0, x1, y1 = window
        mask = self.model.mask(rgb[y0:y1, x0:x1]).astype(np.uint8)  # type: ignore[union-attr]
        n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        return labels, stats[1:], n - 1

    @property
    def has_position(self) -> bool:
        """Whether a centroid has been accepted yet."""
        return self._last is not None

    @property
    def blur_reach_px(self) -> float:
        """How far motion blur may smear this sticker past its still outline, each way (px).

        An exposure lasts at most a frame interval, so a sticker that moves d px
        a frame is smeared along at most d px: half of it on each side of its
        centroid. d is the larger of the smoothed velocity and the last move,
        with a quarter more for acceleration (a step's start). Small moves
        (under ½ px of reach) count as none, so that slow footage is measured
        exactly as a still sticker.
        """
        d = max(math.hypot(*self._velocity), self._step_px)
        reach = 0.5 * 1.25 * d
        return reach if reach >= 0.5 else 0.0

    def predicted_xy(self) -> tuple[float, float] | None:
        """Where the marker should be in this frame (px): last position plus velocity."""
        if self._last is None:
            return None
        return self._last[0] + self._velocity[0], self._last[1] + self._velocity[1]

    def find(self, rgb: np.ndarray) -> tuple[Blob | None, str]:
        """The marker's blob in this frame, or None and why not."""
        h, w = rgb.shape[:2]
        p = self.predicted_xy()
        predicted = None if p is None else np.array(p)
        windows = []
        if predicted is not None:
            r = self.search_radius_px + self.extent_px
            x0 = int(max(0, math.floor(predicted[0] - r)))
            y0 = int(max(0, math.floor(predicted[1] - r)))
            x1 = int(min(w, math.ceil(predicted[0] + r) + 1))
            y1 = int(min(h, math.ceil(predicted[1] + r) + 1))
            if x1 - x0 > 2 and y1 - y0 > 2:
                windows.append((x0, y0, x1, y1))
        windows.append((0, 0, w, h))  # fall back to the whole frame when lost
        saw_small = False
        for window in windows:
            labels, stats, n = self._components(rgb, window)
            if n == 0:
                continue
            areas = stats[:, cv2.CC_STAT_AREA].astype(np.float64)
            ok = areas >= 4
            if self.expected_area is not None:
                # Spurious blobs (specks, another object of a similar colour)
                # are rejected by size; a remnant of a hidden sticker too.
                ok &= (areas >= 0.4 * self.expected_area) & (areas <= 2.5 * self.expected_area)
                saw_small |= bool(np.any((areas >= 4) & (areas < 0.4 * self.expected_area)))
            if not ok.any():
                continue
            candidates = np.flatnonzero(ok)
            target = predicted if predicted is not None else (None if self.hint is None else np.array(self.hint))
            if target is not None:
                centres = stats[candidates, :2] + stats[candidates, 2:4] / 2.0 + np.array(window[:2])
                best = candidates[np.argmin(np.hypot(*(centres - target).T))]
            else:
                best = candidates[np.argmax(areas[candidates])]
            blob = self._refine(rgb, window, labels == best + 1)
            if blob is not None:
                return blob, ""
        if saw_small:
            return None, f"{self.name} marker hidden (only a small part visible)"
        return None, f"{self.name} marker not found"

    def _refine(self, rgb: np.ndarray, window, component: np.ndarray) -> Blob | None:
        ys, xs = np.nonzero(component)
        gx = xs + window[0]
        gy = ys + window[1]
        cx, cy = float(gx.mean()), float(gy.mean())
        reach = float(np.sqrt(np.max((gx - cx) ** 2 + (gy - cy) ** 2))) + 0.5
        if self.reach_px is not None:
            # The learned size, not this frame's: a support that jumps with the
            # binary mask would move the centroid.
            reach = self.reach_px
        # Interior pixels (component eroded) give the sticker's colour and noise.
        x0, y0 = int(gx.min()), int(gy.min())
        comp = np.zeros((int(gy.max()) - y0 + 1, int(gx.max()) - x0 + 1), np.uint8)
        comp[gy - y0, gx - x0] = 1
        core = cv2.erode(comp, _KERNEL3)
        if core.sum() < 12:
            core = comp
        iy, ix = np.nonzero(core)
        marker_pixels = rgb[iy + y0, ix + x0]
        if self.method == "projected":
            soft = soft_centroid(rgb, (cx, cy), reach + self.margin_px, marker_pixels)
        else:
            soft = _local_unmixing_centroid(rgb, window, component)
        if soft is None:
            return None
        return Blob(soft.moments, soft.sigma_px, self.flaw(soft))

    def _as_at_centre(self, m) -> tuple[float, float, float]:
        """The blob's axes and area as they would be at the picture's centre (an oblique view's scale undone)."""
        a, b = m.axes_px
        if self.area_scale is None:
            return a, b, m.m00
        s = self.area_scale(m.x_px, m.y_px)
        r = math.sqrt(s)
        return a * r, b * r, m.m00 * s

    def flaw(self, soft: SoftCentroid) -> str:
        """Why ``soft`` does not look like this marker whole (border, hidden, merged, misshapen); "" when it does."""
        if soft.at_border:
            return f"{self.name} marker at the image border"
        if self.reference is None:
            return ""
        m00, major, minor = self.reference
        a, b, area = self._as_at_centre(soft.moments)
        # Motion blur stretches a moving sticker along its motion: up to (2·reach)²/12 px² more
        # variance along it (a box of the smear's length), its area unchanged. It may, not must:
        # the major axis is allowed anywhere from the still one to the most smeared.
        smeared = math.sqrt(major**2 + self.blur_reach_px**2 / 3.0)
        # Edge effects (noise, codec, pixel phase) change the area in
        # proportion to perimeter / area ∝ 1 / radius: the tolerance is for a
        # 13 px radius sticker and grows for smaller ones.
        tol = self.tolerance * max(1.0, 13.0 / math.sqrt(m00 / math.pi)) * self.edge_factor
        area_ratio = area / m00
        k = math.sqrt(area_ratio)
        if (not 1.0 - tol <= area_ratio <= 1.0 + 2.5 * tol and 0.8 < area_ratio < 1.25
                and abs(a / (major * k) - 1.0) < 0.5 * tol and abs(b / (minor * k) - 1.0) < 0.5 * tol):
            # Scaled whole, axes with area: an oblique view's perspective as the sticker moves nearer or
            # farther (or a zoom), not a part hidden or merged, which changes one axis more than the other.
            return ""
        if area_ratio < 1.0 - tol:
            return f"{self.name} marker partly hidden (area {100 * area_ratio:.0f} % of its reference)"
        # Upwards and in shape the codec's chroma bleed alone reaches a few
        # per cent (measured on H.264 at 20 Mbit/s): looser bounds there; a
        # hidden part shows first as lost area.
        if area_ratio > 1.0 + 2.5 * tol:
            return f"{self.name} marker merged with something (area {100 * area_ratio:.0f} % of its reference)"
        if a / major < 1.0 - 2.0 * tol or a / smeared > 1.0 + 2.0 * tol or abs(b / minor - 1.0) > 2.0 * tol:
            return f"{self.name} marker misshapen (axes {a:.1f}/{b:.1f} px, reference {major:.1f}/{minor:.1f} px)"
        return ""

    def accept(self, blob: Blob, rgb: np.ndarray, binary_area: float | None = None) -> None:
        """Take a blob as this frame's position (also when it is flagged)."""
        x, y = blob.moments.x_px, blob.moments.y_px
        if self._last is not None:
            vx, vy = self._velocity
            self._velocity = (0.5 * vx + 0.5 * (x - self._last[0]), 0.5 * vy + 0.5 * (y - self._last[1]))
            self._step_px = math.hypot(x - self._last[0], y - self._last[1])
        self._last = (x, y)
        if blob.flaw:
            return
        m = blob.moments
        a, b, area = self._as_at_centre(m)
        if self.reference is None:
            self._ref.append((area, a, b))
            if len(self._ref) >= self._REFERENCE_FRAMES:
                self.reference = tuple(float(v) for v in np.median(np.asarray(self._ref), axis=0))  # type: ignore[assignment]
        else:
            # Slow drift (zoom, lighting) is followed; a sudden change is flagged.
            self.reference = tuple(0.95 * r + 0.05 * v for r, v in zip(self.reference, (area, a, b)))  # type: ignore[assignment]

    def learn(self, rgb: np.ndarray, blob: Blob) -> None:
        """Learn colour and size from the first detection."""
        m = blob.moments
        a, _ = m.axes_px
        # A uniform disk of radius r has axes r/2; other shapes reach further
        # (a square's corners: 2.45σ): their binary extent says how far.
        r = 2.0 * a + 1.5
        h, w = rgb.shape[:2]
        yy, xx = np.mgrid[0:h, 0:w][:, max(0, int(m.y_px - 2 * r)):int(m.y_px + 2 * r + 1),
                                      max(0, int(m.x_px - 2 * r)):int(m.x_px + 2 * r + 1)]
        sel = self.model.mask(rgb[yy[:, 0], :][:, xx[0]]) if self.model is not None else None
        if sel is not None and sel.any():
            near = sel & (np.hypot(xx - m.x_px, yy - m.y_px) <= 1.5 * r)
            if near.any():
                r = max(r, float(np.sqrt(np.max((xx[near] - m.x_px) ** 2 + (yy[near] - m.y_px) ** 2))) + 1.0)
        self.reach_px = r
        x0, x1 = int(max(0, m.x_px - r)), int(min(w, m.x_px + r + 1))
        y0, y1 = int(max(0, m.y_px - r)), int(min(h, m.y_px + r + 1))
        roi = rgb[y0:y1, x0:x1]
        sel = self.model.mask(roi) if self.model is not None else np.ones(roi.shape[:2], bool)
        if sel.sum() >= 3:
            self.model = self.model.learned(roi[sel]) if self.model is not None else ColourModel.learn(roi[sel])
            self.expected_area = float(self.model.mask(roi).sum())
        self.extent_px = r

    def lose(self) -> None:
        """Forget the velocity: the marker was not found in this frame."""
        self._velocity = (0.0, 0.0)
        self._step_px = 0.0


def _local_unmixing_centroid(rgb: np.ndarray, window: tuple[int, int, int, int],
                             component: np.ndarray) -> SoftCentroid | None:
    """Soft centroid by per-pixel unmixing against the nearest background pixel.

    The blob (``component`` inside ``window``) is dilated by 3 px; each
    pixel's membership is the projection of (pixel − background) on
    (marker − background), with the background that of the nearest pixel of
    a ring 3–6 px outside the blob (3×3 mean) and the marker colour the
    median of the eroded blob, clipped to [0, 1]. Where the contrast is too
    low (< 10 DN) or no ring fits (image border), the binary flag.
    """
    ys, xs = np.nonzero(component)
    pad = 8
    h, w = rgb.shape[:2]
    x0 = max(0, window[0] + xs.min() - pad)
    y0 = max(0, window[1] + ys.min() - pad)
    x1 = min(w, window[0] + xs.max() + pad + 1)
    y1 = min(h, window[1] + ys.max() + pad + 1)
    at_border = (window[0] + xs.min() - pad < 0 or window[1] + ys.min() - pad < 0
                 or window[0] + xs.max() + pad + 1 > w or window[1] + ys.max() + pad + 1 > h)
    roi = rgb[y0:y1, x0:x1].astype(np.float64)
    comp = np.zeros(roi.shape[:2], np.uint8)
    comp[ys + window[1] - y0, xs + window[0] - x0] = 1
    core = cv2.erode(comp, _KERNEL3)
    if core.sum() < 3:
        core = comp
    core_px = roi[core.astype(bool)]
    marker_rgb = np.median(core_px, axis=0)
    near = cv2.dilate(comp, np.ones((7, 7), np.uint8)).astype(bool)
    far = cv2.dilate(comp, np.ones((13, 13), np.uint8)).astype(bool)
    ring = far & ~near
    background = _nearest_ring_background(roi, ring)
    noise_dn2 = float(np.mean(np.var(core_px, axis=0))) + 0.25 if core_px.shape[0] > 3 else 4.0
    if background is None:
        weight = comp.astype(np.float64)
        var_alpha = np.zeros(weight.shape)
    else:
        contrast = marker_rgb - background
        norm2 = np.einsum("ijk,ijk->ij", contrast, contrast)
        alpha = np.einsum("ijk,ijk->ij", roi - background, contrast) / np.maximum(norm2, 1e-9)
        weight = np.where(norm2 >= 100.0, np.clip(alpha, 0.0, 1.0), comp) * near
        # Unclipped, α has variance σ²/|M − b|² per pixel (σ² per channel, measured on the core).
        var_alpha = np.where(near & (norm2 >= 100.0), noise_dn2 / np.maximum(norm2, 1e-9), 0.0)
    moments = weighted_moments(weight, (float(x0), float(y0)))
    if moments is None:
        return None
    yy, xx = np.mgrid[y0:y1, x0:x1]
    var_x = float(np.sum(var_alpha * (xx - moments.x_px) ** 2)) / moments.m00**2
    var_y = float(np.sum(var_alpha * (yy - moments.y_px) ** 2)) / moments.m00**2
    contrast_dn = float(np.linalg.norm(marker_rgb - np.median(roi[ring], axis=0))) if ring.any() else 0.0
    return SoftCentroid(moments, math.sqrt(0.5 * (var_x + var_y)), float(max(x1 - x0, y1 - y0)) / 2.0,
                        contrast_dn, 0.0, bool(at_border and background is None))


def _nearest_ring_background(roi: np.ndarray, ring: np.ndarray) -> np.ndarray | None:
    """Per-pixel background colour: that of the nearest ring pixel (3×3 mean); None if the ring is tiny."""
    if ring.sum() < 8:
        return None
    smooth = cv2.blur(roi, (3, 3))
    # distanceTransformWithLabels labels every pixel with its nearest zero pixel.
    _, labels = cv2.distanceTransformWithLabels((~ring).astype(np.uint8), cv2.DIST_L2, 5,
                                                labelType=cv2.DIST_LABEL_PIXEL)
    lut = np.zeros((int(labels.max()) + 1, roi.shape[2]))
    lut[labels[ring]] = smooth[ring]
    return lut[labels]
