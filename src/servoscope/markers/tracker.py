"""Tracking two coloured markers (and a status LED) through a video.

The first frame's blobs of each marker's colour are scored and the best
pair taken, or the blobs the user pinned (:mod:`servoscope.markers.selection`).
Per frame: find each marker's blob by colour inside a window around its
predicted position (the whole frame when lost), then measure its centroid
from a *soft* membership: each pixel's colour is unmixed between the marker's
colour and the local background's, so a pixel half covered by the sticker
counts one half. That makes the centroid subpixel, where a binary threshold
(the paper's flag) moves by whole pixels as edge pixels flip (see
:mod:`servoscope.markers.centroid`). The learned colours follow the frame's
illumination (:mod:`servoscope.markers.illumination`); a rectangular sticker
is measured over a support that follows its outline.

A frame is *invalid*, with a reason, when a marker is not found, is partly
hidden (its soft area or second moments differ from the marker's own
reference), touches the image border, or its centroid lies outside the
lens model's trusted region; when the markers' separation departs from a
rigid blade's (a track where most frames do is refused); and when the frame
repeats the previous image (a duplicated frame) or its timestamp does not
advance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from ..errors import ServoscopeError
from ..video.reader import VideoInfo, iter_frames, iter_yuv_frames, probe_video, thread_budget
from .centroid import SoftCentroid, distortion_centroid_offset, soft_centroid
from .colour import AUTO, ColourModel, parse_colour, ycbcr_bt601
from .moments import Moments, weighted_moments
from .led_timing import TIMESTAMP_CONVENTIONS, exposure_middle_offset_s, frame_period_s, led_switch_time
from .illumination import GAIN_DEADBAND, GlobalGain, scale_colour
from .selection import auto_colour_models, choose_markers, marker_candidates
from .timebase import frame_timing
from . import kernels as K
from ..angle.geometry import angle_rad_from_centroids
from .settings import BACKENDS, ENGINES, TrackerSettings, resolve_engine
from .track import Track

__all__ = ["TrackerSettings", "Track", "track_video", "angle_rad_from_centroids", "resolve_engine", "ENGINES", "BACKENDS"]

_KERNEL3 = np.ones((3, 3), np.uint8)


@dataclass
class _Blob:
    moments: Moments
    sigma_px: float
    flaw: str  # "" when the blob looks whole, else why it does not


class _MarkerTracker:
    """State of one marker: its learned colour, size, shape and last position."""

    #: Frames whose soft area and axes set the marker's reference shape.
    _REFERENCE_FRAMES = 5

    def __init__(self, name: str, spec: tuple[float, float, float] | str, settings: TrackerSettings):
        self.name = name
        self.seed = spec
        self.model: ColourModel | None = None if spec == AUTO else ColourModel.from_seed(spec)  # type: ignore[arg-type]
        self.expected_area: float | None = None  # binary area of the hue mask (px²)
        # Position and velocity as Python floats: updated every frame, where small-array NumPy costs
        # more than the arithmetic.
        self._last: tuple[float, float] | None = None
        self._velocity: tuple[float, float] = (0.0, 0.0)
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

    def predicted_xy(self) -> tuple[float, float] | None:
        """Where the marker should be in this frame (px): last position plus velocity."""
        if self._last is None:
            return None
        return self._last[0] + self._velocity[0], self._last[1] + self._velocity[1]

    def find(self, rgb: np.ndarray) -> tuple[_Blob | None, str]:
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

    def _refine(self, rgb: np.ndarray, window, component: np.ndarray) -> _Blob | None:
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
        return _Blob(soft.moments, soft.sigma_px, self._flaw(soft))

    def _flaw(self, soft: SoftCentroid) -> str:
        if soft.at_border:
            return f"{self.name} marker at the image border"
        if self.reference is None:
            return ""
        m00, major, minor = self.reference
        a, b = soft.moments.axes_px
        # Edge effects (noise, codec, pixel phase) change the area in
        # proportion to perimeter / area ∝ 1 / radius: the tolerance is for a
        # 13 px radius sticker and grows for smaller ones.
        tol = self.tolerance * max(1.0, 13.0 / math.sqrt(m00 / math.pi)) * self.edge_factor
        area_ratio = soft.moments.m00 / m00
        if area_ratio < 1.0 - tol:
            return f"{self.name} marker partly hidden (area {100 * area_ratio:.0f} % of its reference)"
        # Upwards and in shape the codec's chroma bleed alone reaches a few
        # per cent (measured on H.264 at 20 Mbit/s): looser bounds there; a
        # hidden part shows first as lost area.
        if area_ratio > 1.0 + 2.5 * tol:
            return f"{self.name} marker merged with something (area {100 * area_ratio:.0f} % of its reference)"
        if abs(a / major - 1.0) > 2.0 * tol or abs(b / minor - 1.0) > 2.0 * tol:
            return f"{self.name} marker misshapen (axes {a:.1f}/{b:.1f} px, reference {major:.1f}/{minor:.1f} px)"
        return ""

    def accept(self, blob: _Blob, rgb: np.ndarray, binary_area: float | None = None) -> None:
        """Take a blob as this frame's position (also when it is flagged)."""
        x, y = blob.moments.x_px, blob.moments.y_px
        if self._last is not None:
            vx, vy = self._velocity
            self._velocity = (0.5 * vx + 0.5 * (x - self._last[0]), 0.5 * vy + 0.5 * (y - self._last[1]))
        self._last = (x, y)
        if blob.flaw:
            return
        m = blob.moments
        a, b = m.axes_px
        if self.reference is None:
            self._ref.append((m.m00, a, b))
            if len(self._ref) >= self._REFERENCE_FRAMES:
                self.reference = tuple(float(v) for v in np.median(np.asarray(self._ref), axis=0))  # type: ignore[assignment]
        else:
            # Slow drift (zoom, lighting) is followed; a sudden change is flagged.
            self.reference = tuple(0.95 * r + 0.05 * v for r, v in zip(self.reference, (m.m00, a, b)))  # type: ignore[assignment]

    def learn(self, rgb: np.ndarray, blob: _Blob) -> None:
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
            self.model = ColourModel.learn(roi[sel])
            self.expected_area = float(self.model.mask(roi).sum())
        self.extent_px = r

    def lose(self) -> None:
        self._velocity = (0.0, 0.0)


def _choose_first(path: Path, rgb: np.ndarray, trackers, settings: TrackerSettings, row_offset: int = 0,
                  row_step: int = 1) -> list[str]:
    """Choose each marker's blob in the first frame (see :mod:`.selection`); set the trackers' hints.

    Returns the close-call warnings. When a marker's colour matches no blob
    big enough to be a candidate, no hint is set and the first detection
    reports it as before (the closest coloured blobs listed), unless the marker
    is pinned: then the pin's error names the nearest blob.
    """
    lead, trail = trackers
    cands = [marker_candidates(rgb, t.model, t.model.hue) if t.model is not None else [] for t in trackers]
    pinned = settings.lead_near is not None or settings.trail_near is not None
    if not pinned and not all(cands):
        return []
    def in_image(near):
        # Pins are in frame pixels; a field's image has every row_step-th row from row_offset.
        return None if near is None else (near[0], (near[1] - row_offset) / row_step)

    choice = choose_markers(cands[0], cands[1], lead_near=in_image(settings.lead_near),
                            trail_near=in_image(settings.trail_near),
                            lead_colour=_spec_text(lead.seed), trail_colour=_spec_text(trail.seed), source=str(path))
    lead.hint = (choice.lead.x_px, choice.lead.y_px)
    trail.hint = (choice.trail.x_px, choice.trail.y_px)
    return choice.warnings


def _auto_models(rgb: np.ndarray, exclude: list[ColourModel]) -> list[ColourModel]:
    """The two blobs of distinct hue most like a pair of stickers, right one first (see :mod:`.selection`)."""
    return auto_colour_models(rgb, exclude)


def _record_markers(frame, found: dict, xy: dict, area: dict, sigma: dict) -> None:
    """Append one frame's centroids, areas and uncertainties (NaN where a marker is missing).

    A field (``row_step`` 2) has half the rows: its areas count double and its
    y uncertainty is that of a pixel twice as tall.
    """
    for name in ("lead", "trail"):
        if name in found:
            m = found[name].moments
            xy[name].append((float(m.x_px), float(frame.row_offset + frame.row_step * m.y_px)))
            area[name].append(m.m00 * frame.row_step)
            sigma[name].append(found[name].sigma_px * math.sqrt(0.5 * (1 + frame.row_step**2)))
        else:
            xy[name].append((math.nan, math.nan))
            area[name].append(math.nan)
            sigma[name].append(math.nan)

def track_video(
    path: str | Path,
    settings: TrackerSettings | None = None,
    *,
    progress: Callable[[int], None] | None = None,
) -> Track:
    """Track both markers (and the LED) through one video.

    Parameters
    ----------
    path : path-like
        Any video PyAV decodes.
    settings : TrackerSettings
    progress : callable, optional
        Called with the number of frames done, now and then.

    Returns
    -------
    Track

    Raises
    ------
    ServoscopeError
        When the video cannot be read, or a marker colour matches nothing in
        the first frame (the message lists the closest coloured blobs).
    """
    settings = settings or TrackerSettings()
    path = Path(path)
    budget = thread_budget()
    if budget and cv2.getNumThreads() != budget:
        # A process given a share of the cores (a campaign's Dask worker): OpenCV's pool
        # keeps to it too, as the decoder does (see video.reader.thread_budget).
        cv2.setNumThreads(budget)
    info = probe_video(path)
    lead_spec = parse_colour(settings.lead, what="lead marker colour")
    trail_spec = parse_colour(settings.trail, what="trail marker colour")
    led_spec = parse_colour(settings.led, what="LED colour") if settings.led else None
    if led_spec == AUTO:
        raise ServoscopeError("LED colour: \"auto\" is not supported for the LED; give its colour")
    fields = {None: None, "fields": "tff", "fields-tff": "tff", "fields-bff": "bff"}.get(settings.deinterlace, "?")
    if fields == "?":
        raise ServoscopeError(f"deinterlace: {settings.deinterlace!r} is not one of 'fields', 'fields-bff' or None")
    if settings.centroid not in ("local", "projected"):
        raise ServoscopeError(f"centroid: {settings.centroid!r} is not 'local' or 'projected'")
    if not (settings.shape_tolerance > 0 and settings.support_margin_px >= 1):
        raise ServoscopeError("shape_tolerance must be > 0 and support_margin_px >= 1")
    _check_readout(settings.readout_s, info.frame_rate_hz, fields is not None)
    if info.frame_rate_hz:
        # Before any work: the container's nominal frame (or field) interval.
        _check_exposure(path, settings, np.arange(2) / (info.frame_rate_hz * (2 if fields is not None else 1)))
    engine = resolve_engine(settings)
    lead = _MarkerTracker("lead", lead_spec, settings)
    trail = _MarkerTracker("trail", trail_spec, settings)
    led_model = ColourModel.from_seed(led_spec) if led_spec is not None else None  # type: ignore[arg-type]

    times: list[float] = []
    intra: list[bool] = []  # frames the codec coded on their own (I-frames)
    xy: dict[str, list[tuple[float, float]]] = {"lead": [], "trail": []}
    area: dict[str, list[float]] = {"lead": [], "trail": []}
    sigma: dict[str, list[float]] = {"lead": [], "trail": []}
    reasons: list[str] = []
    led_signal: list[float] = []
    led_peak_dn: list[float] = []  # brightest luma in the LED's disk, first lit frames (YUV engines)
    warnings: list[str] = []
    repeated: list[bool] = []
    snapshot = None
    snapshot_index = 0
    led_local: np.ndarray | None = None  # LED position in the marker frame (trail→lead axes)
    led_radius = 0.0
    prev_rgb: np.ndarray | None = None

    if engine != "reference-rgb":
        (snapshot, snapshot_index) = _loop_yuv(path, fields, engine, settings, lead, trail, lead_spec, trail_spec,
                                               led_model, progress, times, intra, xy, area, sigma, reasons,
                                               led_signal, warnings, repeated, led_peak_dn)
    else:
        for frame in iter_frames(path, fields=fields):
            rgb = frame.rgb
            if frame.index == 0 and AUTO in (lead_spec, trail_spec):
                exclude = [led_model] if led_model is not None else []
                exclude += [m.model for m in (lead, trail) if m.model is not None]
                models = _auto_models(rgb, exclude)
                for tracker in (lead, trail):
                    if tracker.model is None:
                        if not models:
                            raise ServoscopeError(f"{path}: no coloured blob found for the {tracker.name} marker (\"auto\")")
                        tracker.model = models.pop(0)
            if frame.index == 0:
                warnings.extend(_choose_first(path, rgb, (lead, trail), settings, frame.row_offset, frame.row_step))
            # A camcorder's duplicated frame: the same image under a new timestamp.
            repeated.append(prev_rgb is not None and prev_rgb.shape == rgb.shape and np.array_equal(prev_rgb, rgb))
            prev_rgb = rgb
            found: dict[str, _Blob] = {}
            reason = ""
            for tracker in (lead, trail):
                blob, why = tracker.find(rgb)
                if blob is None:
                    tracker.lose()
                    reason = reason or why
                    if frame.index == 0:
                        raise ServoscopeError(_nothing_matches(path, tracker, rgb))
                    continue
                if tracker.reach_px is None:
                    tracker.learn(rgb, blob)
                    # Measure again with the learned colour and size.
                    blob = tracker.find(rgb)[0] or blob
                tracker.accept(blob, rgb)
                found[tracker.name] = blob
                reason = reason or blob.flaw
            times.append(frame.time_s)
            intra.append(frame.intra)
            _record_markers(frame, found, xy, area, sigma)
            reasons.append(reason)
            if snapshot is None and not reason and frame.row_step == 1:
                snapshot, snapshot_index = rgb.copy(), frame.index

            if led_model is not None:
                if led_local is None and len(found) == 2:
                    led_local, led_radius = _locate_led(rgb, led_model, found["lead"].moments, found["trail"].moments)
                    if led_local is None:
                        warnings.append("LED not found in the first frames: no input start (t0)")
                        led_model = None
                led_signal.append(
                    _led_brightness(rgb, led_local, led_radius, found.get("lead"), found.get("trail"))
                    if led_local is not None
                    else math.nan
                )
            if progress is not None and frame.index % 50 == 0:
                progress(frame.index + 1)

    n = len(times)
    if progress is not None:
        progress(n)
    expected = (info.frame_count or 0) * (2 if fields else 1)
    if expected and n < expected:
        warnings.append(f"decoded {n} of {expected} announced frames: the file ends early")
    time_s = np.asarray(times)
    _check_exposure(path, settings, time_s)
    lead_arr = np.asarray(xy["lead"], dtype=np.float64).reshape(-1, 2)
    trail_arr = np.asarray(xy["trail"], dtype=np.float64).reshape(-1, 2)
    lead_sigma = np.asarray(sigma["lead"], dtype=np.float64)
    trail_sigma = np.asarray(sigma["trail"], dtype=np.float64)

    timing = frame_timing(time_s)
    warnings.extend(timing.warnings)
    for i in timing.stalled:
        reasons[i] = reasons[i] or "timestamp does not advance"
    _flag_repeated(np.asarray(repeated, dtype=bool), lead_arr, trail_arr, reasons, warnings)

    valid = np.array([r == "" for r in reasons], dtype=bool)
    # A rolling shutter exposes the rows of the *recorded* image in turn: keep
    # the recorded rows before undistortion replaces the centroids (the stored
    # picture's rows: a phone's 90° rotation makes them the upright image's columns).
    lead_row, trail_row = info.sensor_rows(lead_arr), info.sensor_rows(trail_arr)
    if settings.camera is not None:
        for arr, name in ((lead_arr, "lead"), (trail_arr, "trail")):
            good = np.isfinite(arr[:, 0])
            if good.any():
                raw = arr[good].copy()
                und, _ = settings.camera.undistort_points(raw)
                # The centroid of the lens's image of a disk is not the image of its centre.
                radius = np.sqrt(np.asarray(area[name], dtype=np.float64)[good] / np.pi)
                und -= distortion_centroid_offset(settings.camera, und, radius)
                trusted = settings.camera.in_valid_region(raw)
                arr[good] = und
                bad = np.flatnonzero(good)[~trusted]
                for i in bad:
                    valid[i] = False
                    reasons[i] = reasons[i] or f"{name} centroid outside the calibrated region"
    _flag_nonrigid(path, lead_arr, trail_arr, valid, reasons, warnings)
    angle = angle_rad_from_centroids(lead_arr, trail_arr)
    angle[~valid] = np.nan
    if valid.any():
        angle[valid] = np.unwrap(angle[valid])
    # Only the components across the joining line turn it: σθ = √(σ_lead² + σ_trail²) / L.
    separation = np.hypot(*(lead_arr - trail_arr).T)
    angle_sigma = np.where(valid, np.hypot(lead_sigma, trail_sigma) / separation, np.nan)
    # Angles and t0 on the exposures' middle clock (the LED and the stickers share each exposure).
    angle_clock_s = time_s.astype(np.float64) + exposure_middle_offset_s(settings.timestamp, settings.exposure_s)
    angle_time = angle_clock_s.copy()
    if settings.readout_s > 0 and n:
        w_lead, why = _angle_row_weights(lead_arr, trail_arr, valid)
        if why:
            warnings.append(f"rolling shutter: {why}; the angle's sample time uses the mean of the two markers' rows")
        row = w_lead * lead_row + (1.0 - w_lead) * trail_row
        if np.isfinite(row).any():
            # Frames without both markers have no angle; give them the typical row.
            row = np.where(np.isfinite(row), row, np.nanmedian(row))
            angle_time = angle_time + settings.readout_s * row / info.sensor_height
    invalid = n - int(valid.sum())
    if n and not valid.any():
        warnings.append("no frame has both markers")
    elif invalid:
        counts: dict[str, int] = {}
        for r in reasons:
            if r:
                key = r.split(" (")[0]
                counts[key] = counts.get(key, 0) + 1
        detail = "; ".join(f"{k}: {v}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1]))
        warnings.append(f"{invalid} of {n} frames invalid ({detail})")

    led_level = np.full(n, np.nan)
    t0 = t0_unc = None
    t0_window: tuple[float, float] | None = None
    led_partial: int | None = None
    led_peak = max((p for p in led_peak_dn if math.isfinite(p)), default=math.nan)
    led_clipped = led_peak >= _LED_CLIP_DN
    if led_signal and np.isfinite(led_signal).sum() >= 3:
        signal = np.asarray(led_signal, dtype=np.float64)
        good = np.flatnonzero(np.isfinite(signal))
        head = signal[good[: min(5, good.size)]]
        tail = signal[good[-min(5, good.size):]]
        on, off = float(np.median(head)), float(np.median(tail))
        if on - off > 10.0:
            led_level = (signal - off) / (on - off)
            switch, why = led_switch_time(angle_clock_s, led_level, settings.exposure_s)
            if why:
                warnings.append(why)
            if switch is not None:
                t0, t0_unc = switch.t0_s, switch.stderr_s
                t0_window = (switch.earliest_s, switch.latest_s)
                led_partial = switch.partial_frames
            if t0 is not None and led_clipped:
                # A clipped LED reads fully lit for part of the exposure it was not: the
                # partly lit frame's level, and so t0 within that frame, is not known
                # (within the whole frame interval when the exposure is not known).
                period = frame_period_s(time_s)
                exposure = period if settings.exposure_s is None else min(settings.exposure_s, period)
                t0_unc = max(t0_unc or 0.0, exposure / math.sqrt(12.0))
                t0_window = (min(t0_window[0], t0 - exposure / 2), max(t0_window[1], t0 + exposure / 2))
                warnings.append(
                    f"LED at the video's white level (luma {led_peak:.0f}): a clipped LED's "
                    "partly lit frame looks brighter than it was, so t0 is known only to within its "
                    f"exposure (±{1e3 * t0_unc:.2f} ms, 1σ); dim the LED or shorten the exposure")
            if t0 is not None and settings.readout_s > 0:
                # The LED's rows are exposed readout·y/H after the frame time. Its
                # position before the input starts is where it switched (the
                # blade is at rest until then); the first clean frame shows it.
                led_row = _led_row_px(snapshot, led_spec, info) if snapshot is not None else None
                if led_row is None:
                    warnings.append("rolling shutter: LED not found in the reference frame; "
                                    "t0 not corrected for the LED's row")
                else:
                    t0 = t0 + settings.readout_s * led_row / info.sensor_height
        else:
            warnings.append("LED brightness does not change: no input start (t0) found")

    return Track(
        video=path.name,
        frame=np.arange(n),
        time_s=time_s,
        lead_xy_px=lead_arr,
        trail_xy_px=trail_arr,
        lead_area_px=np.asarray(area["lead"], dtype=np.float64),
        trail_area_px=np.asarray(area["trail"], dtype=np.float64),
        angle_rad=angle,
        valid=valid,
        reason=reasons,
        led_level=led_level,
        t0_s=t0,
        t0_uncertainty_s=t0_unc,
        warnings=warnings,
        snapshot_rgb=snapshot,
        snapshot_index=snapshot_index,
        lead_sigma_px=lead_sigma,
        trail_sigma_px=trail_sigma,
        angle_sigma_rad=angle_sigma,
        angle_time_s=angle_time,
        readout_s=float(settings.readout_s),
        intra=np.asarray(intra, dtype=bool),
        t0_earliest_s=None if t0_window is None else float(t0_window[0]),
        t0_latest_s=None if t0_window is None else float(t0_window[1]),
        led_partial_frames=led_partial,
    )


def _check_exposure(path: Path, settings: TrackerSettings, time_s: np.ndarray) -> None:
    """Refuse an exposure no camera gives: zero or negative, or longer than the frame interval."""
    if settings.timestamp not in TIMESTAMP_CONVENTIONS:
        raise ServoscopeError(f"{path}: timestamp {settings.timestamp!r}: use one of {', '.join(TIMESTAMP_CONVENTIONS)}")
    if settings.exposure_s is None:
        return
    period = frame_period_s(time_s)
    if not settings.exposure_s > 0:
        raise ServoscopeError(f"{path}: exposure {settings.exposure_s} s: an exposure must be > 0 "
                              "(leave it out when the shutter is not known)")
    if period > 0 and settings.exposure_s > 1.001 * period:
        raise ServoscopeError(f"{path}: exposure {1e3 * settings.exposure_s:.4g} ms is longer than the frame interval "
                              f"({1e3 * period:.4g} ms): a frame cannot expose longer than it lasts; give the shutter "
                              "time (e.g. 1/1000 s = 0.001), or leave it out when not known")


def _check_readout(readout_s: float, frame_rate_hz: float | None, fields: bool) -> None:
    """Refuse a readout time no sensor can have: negative, or not shorter than the frame interval.

    A sensor reads all of a frame's rows before it reads the next frame's
    (an interlaced one, a field's before the next field's).
    """
    if isinstance(readout_s, bool) or not (isinstance(readout_s, (int, float)) and math.isfinite(readout_s)
                                           and readout_s >= 0):
        raise ServoscopeError(f"readout: must be a time >= 0 in seconds, got {readout_s!r}")
    if readout_s > 0 and frame_rate_hz:
        interval_s = 1.0 / (frame_rate_hz * (2 if fields else 1))
        if readout_s >= interval_s:
            raise ServoscopeError(
                f"readout: {readout_s:g} s is not shorter than the {'field' if fields else 'frame'} interval "
                f"({1e3 * interval_s:.4g} ms): a sensor reads one frame's rows before the next frame's")


def _angle_row_weights(lead_xy_px: np.ndarray, trail_xy_px: np.ndarray, valid: np.ndarray) -> tuple[float, str]:
    """Share of the lead marker in the angle's motion; weights its row in the angle's sample time.

    With each marker seen at its own row's time, the angle is, to first order
    in the time difference, ``w·θ(t_lead) + (1 − w)·θ(t_trail)`` where w is
    the lead's share of the angle's change: each marker moves across the
    joining line by its lever arm about the pivot times the rotation, so
    ``w = (s_lead − s_pivot)/L`` along the line of length L. That is
    ``θ(w·t_lead + (1 − w)·t_trail)``: the angle is sampled at the
    lever-weighted mean row, not the plain mean (the plain mean is right only
    for a pivot midway between the stickers; with the paper's quarter-chord
    pivot w ≈ 0.21). w is measured from the track itself: the regression of
    the lead's motion across the line on the angle's, ``n_lead = w·(n_lead − n_trail)``.

    Returns
    -------
    w_lead : float
        0.5 when it cannot be measured.
    why : str
        Why not ("" when measured).
    """
    ok = valid & np.isfinite(lead_xy_px).all(axis=1) & np.isfinite(trail_xy_px).all(axis=1)
    if ok.sum() < 10:
        return 0.5, "too few frames with both markers to measure their lever arms"
    lead, trail = lead_xy_px[ok], trail_xy_px[ok]
    axis = lead.mean(axis=0) - trail.mean(axis=0)
    e = axis / np.hypot(*axis)
    normal = np.array([-e[1], e[0]])
    n_lead = (lead - lead.mean(axis=0)) @ normal
    n_trail = (trail - trail.mean(axis=0)) @ normal
    d = n_lead - n_trail
    sdd = float(d @ d)
    if not sdd > 0:
        return 0.5, "the markers do not move, so their lever arms cannot be measured"
    w = float(n_lead @ d) / sdd
    resid = n_lead - w * d
    se = math.sqrt(float(resid @ resid) / max(d.size - 1, 1) / sdd)
    # 0.05 of the two rows' difference is < 0.1 ms at 20 ms readout for markers 30 rows apart.
    if not se < 0.05:
        return 0.5, f"the markers move too little to measure their lever arms (share {w:.2f} ± {se:.2f})"
    return w, ""


def _led_row_px(rgb: np.ndarray, led_spec, info: VideoInfo) -> float | None:
    """Row (stored picture, px) of the largest lit-LED-coloured blob in ``rgb``; None when there is none."""
    model = ColourModel.from_seed(led_spec)
    mask = model.mask(rgb).astype(np.uint8)
    n, _, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return None
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    if stats[best, cv2.CC_STAT_AREA] < 3:
        return None
    return float(info.sensor_rows(cents[best]))


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


#: A frame's marker separation may depart from the rigid blade's by this many times the
#: separation's frame-to-frame noise, and at least :data:`_RIGID_FLOOR_PX` px or
#: :data:`_RIGID_FLOOR_FRACTION` of the separation (a lens's focus breathing, a blade that bends
#: a little): more, and the two "markers" did not keep their distance in that frame.
_RIGID_SIGMAS = 6.0
_RIGID_FLOOR_PX = 0.5
_RIGID_FLOOR_FRACTION = 0.005
#: A camera that does not face the blade square-on foreshortens the markers' separation by the
#: blade's angle: under any affine view, separation² = A + B·cos 2θ + C·sin 2θ. Fitted when the
#: angle spans this much (rad); a fitted modulation √(B² + C²)/A above :data:`_RIGID_MAX_MODULATION`
#: (a view more than ~40° off square) is not a camera's, and the constant separation is kept.
_RIGID_MIN_SPAN_RAD = 0.1
_RIGID_MAX_MODULATION = 0.3


def _rigid_separation(theta: np.ndarray, sep: np.ndarray, use: np.ndarray) -> np.ndarray:
    """The separation a rigid blade would show at each angle: constant, or foreshortened by the view."""
    med = float(np.median(sep[use]))
    if np.count_nonzero(use) < 10 or float(np.ptp(theta[use])) < _RIGID_MIN_SPAN_RAD:
        return np.full(sep.shape, med)
    design = np.c_[np.ones(theta.size), np.cos(2.0 * theta), np.sin(2.0 * theta)]
    coef = np.linalg.lstsq(design[use], sep[use] ** 2, rcond=None)[0]
    if not (coef[0] > 0 and math.hypot(coef[1], coef[2]) <= _RIGID_MAX_MODULATION * coef[0]):
        return np.full(sep.shape, med)
    return np.sqrt(np.maximum(design @ coef, 0.0))


def _flag_nonrigid(path: Path, lead: np.ndarray, trail: np.ndarray, valid: np.ndarray, reasons: list[str],
                   warnings: list[str]) -> None:
    """Invalidate frames whose marker separation changed; refuse a track where most did.

    Two stickers on one rigid blade keep their distance whatever the blade
    does and wherever the camera is (a view that is not square-on
    foreshortens it by the blade's angle, smoothly: that is fitted, see
    :func:`_rigid_separation`). Two things that only have the markers'
    colours (clothing of passers-by, a box and a sticker) do not.

    Raises
    ------
    ServoscopeError
        When more than half the otherwise valid frames changed their separation.
    """
    sep = np.hypot(*(lead - trail).T)
    ok = valid & np.isfinite(sep)
    if np.count_nonzero(ok) < 10:
        return
    theta = np.where(ok, angle_rad_from_centroids(lead, trail), 0.0)
    theta = np.where(ok, np.unwrap(theta), 0.0)
    med = float(np.median(sep[ok]))
    use = ok.copy()
    for _ in range(2):  # fit, then fit again without the frames that departed
        resid = sep - _rigid_separation(theta, sep, use)
        steps = np.diff(resid[ok])
        # Frame-to-frame changes: noise (√2 σ) where the blade is rigid, whatever the mean does.
        sigma = 1.4826 * float(np.median(np.abs(steps - np.median(steps)))) / math.sqrt(2.0)
        allow = max(_RIGID_SIGMAS * sigma, _RIGID_FLOOR_PX, _RIGID_FLOOR_FRACTION * med)
        bad = ok & (np.abs(resid) > allow)
        if np.count_nonzero(ok & ~bad) < 10:
            break
        use = ok & ~bad
    n_bad, n_ok = int(np.count_nonzero(bad)), int(np.count_nonzero(ok))
    if n_bad > n_ok / 2:
        lo, hi = float(np.min(sep[ok])), float(np.max(sep[ok]))
        raise ServoscopeError(
            f"{path}: the two markers' distance changes from {lo:.0f} to {hi:.0f} px in {n_bad} of {n_ok} frames "
            f"(a rigid blade keeps it within {allow:.1f} px): these are not two stickers on one rigid part; "
            "check the marker colours (`servoscope markers`) or pin them (--lead '#rrggbb@x,y')")
    for i in np.flatnonzero(bad):
        valid[i] = False
        reasons[i] = reasons[i] or f"separation changed ({resid[i]:+.1f} px from a rigid blade's {sep[i] - resid[i]:.1f} px)"
    if n_bad:
        warnings.append(f"{n_bad} frame(s) where the markers' separation changed by more than {allow:.1f} px "
                        "marked invalid")


def _flag_repeated(repeated: np.ndarray, lead: np.ndarray, trail: np.ndarray, reasons: list[str],
                   warnings: list[str]) -> None:
    """Invalidate duplicated frames: a repeated image while the blade moves.

    A bit-identical frame is a duplicate only if the markers moved between
    the frames around it; a static scene without noise repeats legitimately.
    """
    n = repeated.size
    dup = 0
    for i in np.flatnonzero(repeated):
        j = i + 1
        while j < n and repeated[j]:
            j += 1
        if j >= n:
            moved = True  # nothing after it to tell: distrust it
        else:
            step = max(float(np.nanmax(np.abs(lead[j] - lead[i - 1]))), float(np.nanmax(np.abs(trail[j] - trail[i - 1]))))
            moved = not step <= 0.05
        if moved:
            reasons[i] = reasons[i] or f"duplicate of frame {i - 1} (repeated image)"
            dup += 1
    if dup:
        warnings.append(f"{dup} duplicated frame(s) (an image repeated under a new timestamp) marked invalid")


def _nothing_matches(path: Path, tracker: _MarkerTracker, rgb: np.ndarray) -> str:
    """Error message for a marker colour that matches nothing, with the closest blobs."""
    from .candidates import find_candidates

    text = _spec_text(tracker.seed) if tracker.seed != AUTO else "auto"
    msg = f"{path}: the {tracker.name} marker's colour {text} matches nothing in the first frame"
    cands = find_candidates(rgb)
    if not cands:
        return msg + "; no saturated blob in that frame at all"
    hue = tracker.model.hue * 2.0 if tracker.model is not None else 0.0
    cands.sort(key=lambda c: abs(((c.hue_deg - hue + 180.0) % 360.0) - 180.0))
    listed = ", ".join(f"#{c.number} {c.colour_hex} (hue {c.hue_deg:.0f}°, {c.area_px} px at {c.x_px:.0f},{c.y_px:.0f})"
                       for c in cands[:3])
    return msg + f"; closest coloured blobs: {listed} (see `servoscope markers`)"


def _spec_text(spec) -> str:
    if isinstance(spec, str):
        return spec
    return "#%02x%02x%02x" % tuple(int(round(c)) for c in spec)


def _marker_axes(lead: Moments, trail: Moments) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    origin = np.array([trail.x_px, trail.y_px])
    axis = np.array([lead.x_px, lead.y_px]) - origin
    length = float(np.hypot(*axis))
    e = axis / length
    nrm = np.array([-e[1], e[0]])
    return origin, e, nrm, length


def _locate_led(rgb, model: ColourModel, lead: Moments, trail: Moments):
    """The LED's position in the markers' frame (units of their separation) and its radius (px).

    The LED is the largest blob of its colour once the markers' own disks are
    masked out: a yellow LED's hue band reaches an orange sticker's, whose
    brightness never changes. Where several blobs remain, those within a
    separation of the markers' segment (on or by the blade) come first.
    """
    mask = model.mask(rgb).astype(np.uint8)
    for m in (lead, trail):
        # Cover the sticker and its blurred edge: its equivalent radius grown by half, plus 3 px.
        r = 1.5 * math.sqrt(max(m.m00, 0.0) / math.pi) + 3.0
        cv2.circle(mask, (int(round(m.x_px)), int(round(m.y_px))), int(math.ceil(r)), 0, -1)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return None, 0.0
    origin, e, nrm, length = _marker_axes(lead, trail)
    rel = cents[1:] - origin
    along, across = rel @ e, rel @ nrm
    off = np.maximum(np.maximum(-along, along - length), 0.0)
    near = np.hypot(off, across) <= length
    areas = stats[1:, cv2.CC_STAT_AREA].astype(np.float64)
    best = 1 + int(np.argmax(np.where(near, areas, -1.0) if near.any() else areas))
    if stats[best, cv2.CC_STAT_AREA] < 3:
        return None, 0.0
    d = cents[best] - origin
    local = np.array([d @ e, d @ nrm]) / length
    radius = math.sqrt(stats[best, cv2.CC_STAT_AREA] / math.pi)
    return local, radius


def _led_brightness(rgb, local, radius, lead: _Blob | None, trail: _Blob | None) -> float:
    """Mean brightness (HSV value) in a disk that follows the LED on the blade."""
    if lead is None or trail is None:
        return math.nan
    origin, e, nrm, length = _marker_axes(lead.moments, trail.moments)
    centre = origin + length * (local[0] * e + local[1] * nrm)
    r = 1.5 * radius + 1.0
    h, w = rgb.shape[:2]
    x0, x1 = int(max(0, centre[0] - r)), int(min(w, centre[0] + r + 1))
    y0, y1 = int(max(0, centre[1] - r)), int(min(h, centre[1] + r + 1))
    if x1 <= x0 or y1 <= y0:
        return math.nan
    yy, xx = np.mgrid[y0:y1, x0:x1]
    disk = (xx - centre[0]) ** 2 + (yy - centre[1]) ** 2 <= r * r
    roi = rgb[y0:y1, x0:x1]
    return float(roi[disk].max(axis=1).mean())


# ---------------------------------------------------------------------------
# The YUV path: the fused kernel on the decoder's planes
# ---------------------------------------------------------------------------
#: Luma weight of the unmixing (see kernels): luma's α weighs w_Y·c_Y² against
#: chroma's |c_C|². Measured on the twin's H.264 footage, a strong luma weight
#: (16–64) is *worse* (0.0059–0.0067°) than 1 (0.0049°): around these stickers
#: the background's luma varies (blade edge, sky gradient) as much as the
#: marker/background luma contrast, and the ring's per-angle background does
#: not capture it finely enough for luma; chroma's background is flatter.
W_Y = 1.0
#: Recentring passes of the soft moments.
YUV_ITERATIONS = 1
#: Width of the background ring (px).
RING_PX = 4.0
#: Extra support margin of the YUV path over ``support_margin_px`` (px): the
#: chroma's 2-px smear must fit inside the support.
YUV_EXTRA_MARGIN_PX = -1.5
#: Largest |α_Y − α_C| at which luma still sets the weight (see kernels; compared at chroma's
#: resolution, ramp ±0.1). Where both are right they differ only by noise: ~1 DN of codec error
#: per sample (H.264 − raw, measured) over contrasts of 30–90 DN, α noise ≈ 0.01–0.03, so
#: 0.15 (full trust below 0.05, none above 0.25) is ≥ 3 σ; results are flat for 0.1–0.2.
AGREE = 0.15
#: Clip of the membership.
ALPHA_RANGE = (0.0, 1.0)


def _chroma_angle(uv: np.ndarray) -> np.ndarray:
    return np.arctan2(uv[..., 1] - 128.0, uv[..., 0] - 128.0)


class _YuvState:
    """A marker's YUV model: its kernel parameter row and class area.

    ``phi0`` is a rectangular sticker's long-side direction (rad, image
    coordinates) at the first frame, where the markers' line had direction
    ``beta0``; None for a round sticker.
    """

    def __init__(self) -> None:
        self.prm = np.zeros(K.NP)
        self.class_area: float | None = None
        self.phi0: float | None = None
        self.beta0 = 0.0


#: A sticker whose binary blob fills at least this fraction of its minimum-area bounding
#: rectangle is rectangular (a square, a tape strip): its support follows that rectangle. A
#: disk fills π/4 = 0.785 of its square (0.74–0.82 measured on pixelated 17–26 px disks, H.264).
RECT_FILL = 0.86
#: ...or at least this fraction with a half-length under this many second-moment σ along its long
#: axis (a rectangle √3 = 1.73, 1.81–1.84 measured; a disk 2, 1.91–2.05 measured).
RECT_FILL_ELONGATED = 0.83
RECT_SIGMA_RATIO = 1.86
#: Support beyond a rectangular sticker's outline (px), as a round sticker's reaches ~2 px beyond
#: its edge: the edge blur and the codec's chroma smear fit inside.
RECT_SUPPORT_PX = 2.0


def _learn_rect(tracker: _MarkerTracker, frame, m: Moments) -> None:
    """Decide whether the found sticker is rectangular; if so, set its kernel row's rectangle."""
    st = tracker.yuv
    if frame.row_step != 1 or tracker.model is None:
        return  # fields: a rectangle in field rows is sheared; round support as before
    rgb = frame.rgb
    h, w = rgb.shape[:2]
    r = float(tracker.reach_px or tracker.extent_px) + 2.0
    x0, x1 = int(max(0, math.floor(m.x_px - r))), int(min(w, math.ceil(m.x_px + r) + 1))
    y0, y1 = int(max(0, math.floor(m.y_px - r))), int(min(h, math.ceil(m.y_px + r) + 1))
    mask = tracker.model.mask(rgb[y0:y1, x0:x1]).astype(np.uint8)
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return
    lab = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    ys, xs = np.nonzero(labels == lab)
    if xs.size < 12:
        return
    pts = np.c_[xs + x0, ys + y0].astype(np.float32)
    (cx, cy), (rw, rh), _ = cv2.minAreaRect(pts)
    # minAreaRect spans pixel centres: a pixel more each way reaches their edges.
    fill = xs.size / ((rw + 1.0) * (rh + 1.0))
    major_ratio = 0.5 * (max(rw, rh) + 1.0) / max(m.axes_px[0], 1e-9)
    # A rectangle's half-side is √3 its second-moment σ, a disk's or an ellipse's radius 2σ.
    if not (fill >= RECT_FILL or (fill >= RECT_FILL_ELONGATED and major_ratio <= RECT_SIGMA_RATIO)):
        return
    corners = cv2.boxPoints(((cx, cy), (rw, rh), _))
    side_a, side_b = corners[1] - corners[0], corners[2] - corners[1]
    long_side = side_a if np.hypot(*side_a) >= np.hypot(*side_b) else side_b
    # The half-sides from the soft second moments (a rectangle's half-side is √3 σ), not the binary
    # extents: those grow with the edge blur and the chroma smear, and a support that reaches
    # further takes in background the ring does not describe (a blade's edge beside a strip).
    a, b = m.axes_px
    hu, hv = math.sqrt(3.0) * a, math.sqrt(3.0) * b
    prm = st.prm
    prm[K.P.RECT] = 1.0
    prm[K.P.HALF_U], prm[K.P.HALF_V] = hu, hv
    prm[K.P.RECT_MARGIN] = RECT_SUPPORT_PX
    prm[K.P.RADIUS] = math.hypot(hu, hv) + RECT_SUPPORT_PX
    st.phi0 = math.atan2(float(long_side[1]), float(long_side[0]))
    tracker.edge_factor = (hu + hv) / math.sqrt(math.pi * hu * hv)
    _orient(prm, st.phi0)


def _orient(prm: np.ndarray, phi: float) -> None:
    prm[K.P.COS], prm[K.P.SIN] = math.cos(phi), math.sin(phi)


def _line_direction(lead: _MarkerTracker, trail: _MarkerTracker) -> float | None:
    """Direction (rad, image coordinates) from the trail marker's predicted position to the lead's."""
    a, b = lead.predicted_xy(), trail.predicted_xy()
    if a is None or b is None:
        return None
    return math.atan2(a[1] - b[1], a[0] - b[0])


def _learn_yuv(tracker: _MarkerTracker, frame, m: Moments, margin_px: float) -> None:
    """Marker colour (median), chroma direction, hue tolerance and noise from the core of the found blob."""
    reach = float(tracker.reach_px or tracker.extent_px)
    h, w = frame.y.shape
    r_core = max(1.5, 0.6 * (reach - 1.5))
    prm = tracker.yuv.prm
    rect = bool(prm[K.P.RECT])
    r_box = math.hypot(prm[K.P.HALF_U], prm[K.P.HALF_V]) if rect else r_core
    x0, x1 = int(max(0, math.floor(m.x_px - r_box))), int(min(w, math.ceil(m.x_px + r_box) + 1))
    y0, y1 = int(max(0, math.floor(m.y_px - r_box))), int(min(h, math.ceil(m.y_px + r_box) + 1))
    yy, xx = np.mgrid[y0:y1, x0:x1]
    if rect:
        # A strip's disk of radius 0.6·reach is mostly background: its rectangle, 2 px in.
        c, s = float(prm[K.P.COS]), float(prm[K.P.SIN])
        u, v = (xx - m.x_px) * c + (yy - m.y_px) * s, (yy - m.y_px) * c - (xx - m.x_px) * s
        core = ((np.abs(u) <= max(1.0, prm[K.P.HALF_U] - 2.0)) & (np.abs(v) <= max(1.0, prm[K.P.HALF_V] - 2.0)))
    else:
        core = (xx - m.x_px) ** 2 + (yy - m.y_px) ** 2 <= r_core**2
    xs, ys = xx[core].astype(np.float64), yy[core].astype(np.float64)
    Y = frame.y[y0:y1, x0:x1][core].astype(np.float64)
    U = K.chroma_np(frame.u, xs, ys, frame.row_offset, frame.row_step)
    V = K.chroma_np(frame.v, xs, ys, frame.row_offset, frame.row_step)
    ym, um, vm = float(np.median(Y)), float(np.median(U)), float(np.median(V))
    sat = math.hypot(um - 128.0, vm - 128.0)
    ang = np.arctan2(V - 128.0, U - 128.0)
    mean_ang = math.atan2(vm - 128.0, um - 128.0)
    spread = np.abs(np.angle(np.exp(1j * (ang - mean_ang))))
    tol = float(np.clip(3.0 * np.percentile(spread, 90), math.radians(10.0), math.radians(20.0)))

    def robust_var(x):
        mad = float(np.median(np.abs(x - np.median(x))))
        return (1.4826 * mad) ** 2 + 0.25

    st = tracker.yuv
    prm[K.P.YM], prm[K.P.UM], prm[K.P.VM] = ym, um, vm
    prm[K.P.DIR_U], prm[K.P.DIR_V] = (um - 128.0) / max(sat, 1e-9), (vm - 128.0) / max(sat, 1e-9)
    prm[K.P.COS_TOL] = math.cos(tol)
    prm[K.P.SAT_MIN] = max(6.0, 0.45 * sat)
    prm[K.P.AGREE] = AGREE
    if not rect:  # a rectangle's support is set by its shape (see _learn_rect)
        prm[K.P.RADIUS] = reach + margin_px + YUV_EXTRA_MARGIN_PX
    prm[K.P.RING] = RING_PX
    prm[K.P.W_Y] = W_Y
    prm[K.P.ITER] = YUV_ITERATIONS
    prm[K.P.ENABLED] = 1.0
    prm[K.P.VAR_Y] = robust_var(Y)
    # A codec leaves a flat interior almost free of chroma noise while its chroma errors at the
    # edges are larger: take at least the luma's noise for the chroma.
    prm[K.P.VAR_C] = max(0.5 * (robust_var(U) + robust_var(V)), prm[K.P.VAR_Y])
    prm[K.P.ALPHA_LO], prm[K.P.ALPHA_HI] = ALPHA_RANGE
    prm[K.P.MIN_DEN] = 100.0
    st.tolerance_rad = tol


def _separate_hues(states: list[_YuvState], led_rgb) -> None:
    """Narrow each marker's hue tolerance to under half the angle to the other colours (markers, LED)."""
    dirs = [math.atan2(st.prm[K.P.DIR_V], st.prm[K.P.DIR_U]) for st in states]
    others = list(dirs)
    if led_rgb is not None:
        y, u, v = ycbcr_bt601(led_rgb)
        others.append(math.atan2(v - 128.0, u - 128.0))
    for i, st in enumerate(states):
        gaps = [abs(math.remainder(dirs[i] - o, 2 * math.pi)) for j, o in enumerate(others) if j != i]
        tol = st.tolerance_rad
        if gaps:
            tol = min(tol, 0.45 * min(gaps))
        st.prm[K.P.COS_TOL] = math.cos(max(tol, math.radians(4.0)))


def _window(tracker: _MarkerTracker, shape, centre=None) -> tuple[int, int, int, int] | None:
    h, w = shape
    c = tracker.predicted_xy() if centre is None else centre
    if c is None:
        return None
    r = tracker.search_radius_px + tracker.extent_px if centre is None else tracker.extent_px + 6.0
    x0 = int(max(0, math.floor(c[0] - r)))
    y0 = int(max(0, math.floor(c[1] - r)))
    x1 = int(min(w, math.ceil(c[0] + r) + 1))
    y1 = int(min(h, math.ceil(c[1] + r) + 1))
    if x1 - x0 <= 2 or y1 - y0 <= 2:
        return None
    return x0, y0, x1, y1


def _kernel_blob(tracker: _MarkerTracker, row: np.ndarray, window, shape) -> _Blob | None:
    """The marker's blob from its kernel output row, or None when the window's class is implausible."""
    st = tracker.yuv
    row = row.tolist()  # Python floats: indexing and arithmetic on NumPy scalars cost more
    n = row[K.Q.N]
    if not n > 0 or not row[K.Q.M00] > 0:
        return None
    if st.class_area is not None and not (0.4 * st.class_area <= n <= 2.5 * st.class_area):
        return None
    h, w = shape
    x0, y0, x1, y1 = window
    # A class cut by the window's edge (not the image's) may be part of something larger: look wider.
    if ((row[K.Q.XMIN] < x0 + 1 and x0 > 0) or (row[K.Q.YMIN] < y0 + 1 and y0 > 0)
            or (row[K.Q.XMAX] > x1 - 2 and x1 < w) or (row[K.Q.YMAX] > y1 - 2 and y1 < h)):
        return None
    if math.hypot(row[K.Q.X] - row[K.Q.BX], row[K.Q.Y] - row[K.Q.BY]) > 0.5 * tracker.extent_px + 2.0:
        return None
    m = Moments(row[K.Q.M00], row[K.Q.X], row[K.Q.Y], row[K.Q.MU20], row[K.Q.MU11], row[K.Q.MU02])
    radius = float(st.prm[K.P.RADIUS])
    rx = ry = radius
    if st.prm[K.P.RECT]:
        # A rectangle's support reaches its own bounding box, not the disk around it.
        hu, hv, c, s = (float(st.prm[i]) for i in (K.P.HALF_U, K.P.HALF_V, K.P.COS, K.P.SIN))
        sm = float(st.prm[K.P.RECT_MARGIN])
        rx, ry = abs(hu * c) + abs(hv * s) + sm, abs(hu * s) + abs(hv * c) + sm
    support_out = m.x_px - rx < 0 or m.y_px - ry < 0 or m.x_px + rx > w - 1 or m.y_px + ry > h - 1
    at_border = bool(support_out or row[K.Q.RING_N] < 8)
    soft = SoftCentroid(m, math.sqrt(0.5 * (row[K.Q.VAR_X] + row[K.Q.VAR_Y])), radius, row[K.Q.CONTRAST],
                        0.0, at_border)
    return _Blob(m, soft.sigma_px, tracker._flaw(soft))


def _loop_yuv(path, fields, engine, settings, lead, trail, lead_spec, trail_spec, led_model, progress, times, intra,
              xy, area, sigma, reasons, led_signal, warnings, repeated, led_peak_dn):
    """Per-frame loop of the YUV engines; fills the per-frame lists; returns (snapshot, snapshot_index)."""
    kernel = K.ENGINES[engine]
    led_kernel = K.LED_ENGINES[engine]
    trackers = (lead, trail)
    for t in trackers:
        t.yuv = _YuvState()
    params = np.zeros((2, K.NP))
    out = np.zeros((2, K.NQ))
    led_prm = np.zeros(K.LED_NP)
    led_out = np.zeros(K.LED_NQ)
    led_rgb = led_model.rgb if led_model is not None else None
    led_local = None
    snapshot = None
    snapshot_index = 0
    prev = None
    learned = False
    if settings.backend == "cuda":
        from .gpu import require_cuda

        require_cuda()  # the per-window sub-pixel work stays on the CPU (see gpu.py)

    gain_of = GlobalGain()
    gain = 1.0  # this frame's illumination against the first frame's (see illumination.py)
    gains: list[float] = []

    def measure_one(k: int, frame, window, centre=None) -> _Blob | None:
        one = np.zeros((2, K.NP))
        one[k] = trackers[k].yuv.prm
        _apply_gain(one[k], gain)
        one[k, K.P.X0:K.P.Y1 + 1] = window
        if centre is not None:
            one[k, K.P.CX], one[k, K.P.CY], one[k, K.P.USE_CENTRE] = centre[0], centre[1], 1.0
        tmp = np.zeros((2, K.NQ))
        kernel(frame.y, frame.u, frame.v, frame.row_offset, frame.row_step, one, np.zeros(K.LED_NP), tmp,
               np.zeros(K.LED_NQ))
        out[k] = tmp[k]
        return _kernel_blob(trackers[k], tmp[k], window, frame.y.shape)

    for frame in iter_yuv_frames(path, fields=fields):
        shape = frame.y.shape
        # A camcorder's duplicated frame: the same image under a new timestamp.
        repeated.append(prev is not None and _same_image(prev, frame))
        prev = frame
        gain = gain_of(frame.y, frame.row_offset)
        gains.append(gain)
        found: dict[str, _Blob] = {}
        reason = ""
        slow = False
        if not learned:
            rgb = frame.rgb
            if AUTO in (lead_spec, trail_spec):
                exclude = [led_model] if led_model is not None else []
                exclude += [m.model for m in trackers if m.model is not None]
                models = _auto_models(rgb, exclude)
                for tracker in trackers:
                    if tracker.model is None:
                        if not models:
                            raise ServoscopeError(f"{path}: no coloured blob found for the {tracker.name} marker (\"auto\")")
                        tracker.model = models.pop(0)
            warnings.extend(_choose_first(path, rgb, trackers, settings, frame.row_offset, frame.row_step))
            first = {}
            for tracker in trackers:
                blob, why = tracker.find(rgb)
                if blob is None:
                    raise ServoscopeError(_nothing_matches(path, tracker, rgb))
                tracker.learn(rgb, blob)
                blob = tracker.find(rgb)[0] or blob
                first[tracker.name] = blob
                # The shape first: a rectangle's colour is learned from its own interior.
                _learn_rect(tracker, frame, blob.moments)
                _learn_yuv(tracker, frame, blob.moments, settings.support_margin_px)
            _separate_hues([t.yuv for t in trackers], led_rgb)
            for tracker in trackers:
                if tracker.yuv.phi0 is not None:
                    # A rectangle turns with the blade: the markers' line says by how much.
                    ml, mt = first["lead"].moments, first["trail"].moments
                    tracker.yuv.beta0 = math.atan2(ml.y_px - mt.y_px, ml.x_px - mt.x_px)
            for k, tracker in enumerate(trackers):
                m = first[tracker.name].moments
                window = _window(tracker, shape, (m.x_px, m.y_px))
                measure_one(k, frame, window)
                tracker.yuv.class_area = float(out[k, K.Q.N]) if out[k, K.Q.N] > 0 else None
            learned = True
            slow = True
        params[:] = 0.0
        windows = []
        beta = _line_direction(lead, trail)
        for k, tracker in enumerate(trackers):
            if tracker.yuv.phi0 is not None and beta is not None:
                _orient(tracker.yuv.prm, tracker.yuv.phi0 + beta - tracker.yuv.beta0)
            params[k] = tracker.yuv.prm
            _apply_gain(params[k], gain)
            window = _window(tracker, shape) if tracker.has_position or not slow else None
            if window is None and slow:
                m = first[tracker.name].moments  # the first frame: around the found blob
                window = _window(tracker, shape, (m.x_px, m.y_px))
            windows.append(window)
            if window is None:
                params[k, K.P.ENABLED] = 0.0
            else:
                params[k, K.P.X0:K.P.Y1 + 1] = window
        led_prm[0] = 1.0 if led_local is not None else 0.0
        kernel(frame.y, frame.u, frame.v, frame.row_offset, frame.row_step, params, led_prm, out, led_out)
        for k, tracker in enumerate(trackers):
            blob = _kernel_blob(tracker, out[k], windows[k], shape) if windows[k] is not None else None
            if blob is None:
                # Lost or implausible in the predicted window: find it in the whole frame (RGB, components),
                # then measure it with the kernel around what was found.
                slow = True
                rgb_blob, why = tracker.find(frame.rgb)
                if rgb_blob is not None:
                    m = rgb_blob.moments
                    blob = measure_one(k, frame, _window(tracker, shape, (m.x_px, m.y_px)), (m.x_px, m.y_px))
                    if blob is None:
                        blob = rgb_blob
                        out[k, K.Q.M00], out[k, K.Q.X], out[k, K.Q.Y] = m.m00, m.x_px, m.y_px
                else:
                    out[k, K.Q.M00] = 0.0
                    tracker.lose()
                    reason = reason or why
                    continue
            tracker.accept(blob, None)
            found[tracker.name] = blob
            reason = reason or blob.flaw
        times.append(frame.time_s)
        intra.append(frame.intra)
        _record_markers(frame, found, xy, area, sigma)
        reasons.append(reason)
        if snapshot is None and not reason and frame.row_step == 1:
            snapshot, snapshot_index = frame.rgb, frame.index
        if led_model is not None:
            if led_local is None and len(found) == 2:
                led_local, led_radius = _locate_led(frame.rgb, led_model, found["lead"].moments, found["trail"].moments)
                if led_local is None:
                    warnings.append("LED not found in the first frames: no input start (t0)")
                    led_model = None
                else:
                    led_prm[:] = (1.0, led_local[0], led_local[1], 1.5 * led_radius + 1.0)
                    slow = True
            if led_local is not None and slow:
                led_kernel(frame.y, led_prm, out, led_out)
            led_signal.append(float(led_out[0]) if led_local is not None and len(found) == 2 else math.nan)
            if led_local is not None and len(found) == 2 and len(led_peak_dn) < _LED_PEAK_FRAMES:
                led_peak_dn.append(_disk_peak(frame.y, led_out[2], led_out[3], led_prm[3]))
        if progress is not None and frame.index % 50 == 0:
            progress(frame.index + 1)
    corrected = [g for g in gains if abs(g - 1.0) > GAIN_DEADBAND]
    if corrected:
        lo, hi = min(gains), max(gains)
        warnings.append(f"illumination varied ({100 * (lo - 1):+.1f} % to {100 * (hi - 1):+.1f} % of the first "
                        f"frame's: flicker, auto-exposure or clouds) in {len(corrected)} of {len(gains)} frames; "
                        "the markers' colours were scaled with it")
    return snapshot, snapshot_index


def _apply_gain(prm: np.ndarray, gain: float) -> None:
    """Scale a marker's learned colour (and saturation floor) in its kernel row to this frame's light.

    Within :data:`~servoscope.markers.illumination.GAIN_DEADBAND` of 1 the row is left as it is.
    """
    if abs(gain - 1.0) <= GAIN_DEADBAND:
        return
    prm[K.P.YM], prm[K.P.UM], prm[K.P.VM] = scale_colour((prm[K.P.YM], prm[K.P.UM], prm[K.P.VM]), gain)
    prm[K.P.SAT_MIN] *= min(gain, 1.0)


#: Frames whose brightest LED pixel is checked for clipping, and the luma that counts as
#: clipped: 2 DN below the limited-range white (235) that camcorders record; full-range
#: footage (white 255) with an LED this bright is at least close to clipping too.
_LED_PEAK_FRAMES = 5
_LED_CLIP_DN = 233.0


def _disk_peak(Y, cx: float, cy: float, r: float) -> float:
    """Brightest luma within radius ``r`` of (cx, cy); NaN when the disk is off the image."""
    if not (math.isfinite(cx) and math.isfinite(cy) and r > 0):
        return math.nan
    h, w = Y.shape
    x0, x1 = max(0, int(math.floor(cx - r))), min(w, int(math.floor(cx + r)) + 1)
    y0, y1 = max(0, int(math.floor(cy - r))), min(h, int(math.floor(cy + r)) + 1)
    if x1 <= x0 or y1 <= y0:
        return math.nan
    yy, xx = np.mgrid[y0:y1, x0:x1]
    inside = (xx - cx) ** 2 + (yy - cy) ** 2 <= r * r
    return float(np.asarray(Y[y0:y1, x0:x1])[inside].max()) if inside.any() else math.nan


def _same_image(a, b) -> bool:
    if a.y.shape != b.y.shape or a.row_offset != b.row_offset:
        return False
    # Rows from the middle first: a differing frame differs there at once. The whole-frame planes are
    # compared (not the field's rows), on the decoder's own (strided) buffers: no copy.
    h = a.luma.shape[0]
    mid = slice(h // 2, h // 2 + 8)
    return (_planes_equal(a.luma[mid], b.luma[mid]) and _planes_equal(a.luma, b.luma)
            and _planes_equal(a.u, b.u) and _planes_equal(a.v, b.v))


@K.njit(cache=True, nogil=True)
def _planes_equal(a, b) -> bool:
    if a.shape != b.shape:
        return False
    for i in range(a.shape[0]):
        for j in range(a.shape[1]):
            if a[i, j] != b[i, j]:
                return False
    return True
