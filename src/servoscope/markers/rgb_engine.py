"""The RGB reference engine (``engine="reference-rgb"``): every frame converted to RGB, HSV masks.

Slower and, on compressed footage, less accurate than the YUV engines
(:mod:`.yuv_engine`); kept as the reference they are compared with, and as the
path of the experimental ``centroid="projected"`` estimator.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import ServoscopeError
from ..video.reader import iter_frames
from .colour import AUTO, BRIGHTNESS, BrightnessModel
from .first_frame import choose_first, nothing_matches, take_auto_colours
from .frame_record import EngineInput, FrameRecord, TrackLog
from .led_level import led_brightness, locate_led
from .led_search import follow_candidates
from .marker_state import Blob

__all__ = ["run_rgb"]


def run_rgb(job: EngineInput, log: TrackLog) -> None:
    """Track ``job``'s video frame by frame in RGB, adding one record a frame to ``log``.

    Raises
    ------
    ServoscopeError
        When a marker is not found in the first frame.
    """
    lead, trail, led_model, path = job.lead, job.trail, job.led_model, job.path
    led_local: np.ndarray | None = None  # LED position in the marker frame (trail→lead axes)
    led_radius = 0.0
    prev_rgb: np.ndarray | None = None
    for frame in iter_frames(path, fields=job.fields):
        rgb = frame.rgb
        if frame.index == 0:
            # Markers (and an LED) told by brightness: their thresholds from this frame's levels.
            for tracker, spec in ((lead, job.lead_spec), (trail, job.trail_spec)):
                if spec in BRIGHTNESS:
                    tracker.model = BrightnessModel.from_frame(rgb, spec)
            if job.led_brightness is not None:
                led_model = BrightnessModel.from_frame(rgb, job.led_brightness)
        if frame.index == 0 and AUTO in (job.lead_spec, job.trail_spec):
            take_auto_colours(path, rgb, (lead, trail), led_model)
        if frame.index == 0:
            log.warnings.extend(choose_first(path, rgb, (lead, trail), job.settings, frame.row_offset, frame.row_step))
        # A camcorder's duplicated frame: the same image under a new timestamp.
        repeated = prev_rgb is not None and prev_rgb.shape == rgb.shape and np.array_equal(prev_rgb, rgb)
        prev_rgb = rgb
        found: dict[str, Blob] = {}
        reason = ""
        for tracker in (lead, trail):
            blob, why = tracker.find(rgb)
            if blob is None:
                tracker.lose()
                reason = reason or why
                if frame.index == 0:
                    raise ServoscopeError(nothing_matches(path, tracker, rgb))
                continue
            if tracker.reach_px is None:
                tracker.learn(rgb, blob)
                # Measure again with the learned colour and size.
                blob = tracker.find(rgb)[0] or blob
            tracker.accept(blob, rgb)
            found[tracker.name] = blob
            reason = reason or blob.flaw

        led_level = None
        follow_candidates(log, rgb, lambda: rgb, led_model, found, job.settings.led_near, frame.row_offset,
                          frame.row_step)
        if led_model is not None:
            if led_local is None and len(found) == 2:
                led_local, led_radius = locate_led(rgb, led_model, found["lead"].moments, found["trail"].moments)
                if led_local is None:
                    log.warnings.append("LED not found in the first frames: no input start (t0)")
                    led_model = None
            led_level = (led_brightness(rgb, led_local, led_radius, found.get("lead"), found.get("trail"))
                         if led_local is not None else math.nan)
        log.add(FrameRecord(frame.index, frame.time_s, frame.intra, frame.row_offset, frame.row_step, found, reason,
                            repeated, rgb.copy, led_level))
        if job.progress is not None and frame.index % 50 == 0:
            job.progress(frame.index + 1)
