"""What every engine reports per frame (:class:`FrameRecord`), and the one log that collects it.

The engines (:mod:`.rgb_engine`, :mod:`.yuv_engine`) differ in how they find and
measure the markers; what they hand on is the same: one :class:`FrameRecord` a
frame, added to a :class:`TrackLog`, from which the driver
(:func:`servoscope.pipeline.track_video`) builds the :class:`~servoscope.markers.Track`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from .colour import ColourModel
from .marker_state import Blob, MarkerTracker
from .settings import TrackerSettings

__all__ = ["EngineInput", "FrameRecord", "TrackLog"]


@dataclass
class EngineInput:
    """What an engine is asked to track: the video, its settings and the markers' starting state.

    Attributes
    ----------
    path : Path
    fields : {None, "tff", "bff"}
        Interlaced fields to split frames into, in this order; None: whole frames.
    settings : TrackerSettings
    lead, trail : MarkerTracker
    lead_spec, trail_spec : (r, g, b) or "auto"
        The markers' colours as given.
    led_model : ColourModel or None
        The LED's seed colour; None without an LED.
    progress : callable or None
        Called with the number of frames done, now and then.
    led_brightness : {"bright", "dark"} or None
        An LED told by brightness (monochrome footage): its model is made from the first frame.
    """

    path: Path
    fields: str | None
    settings: TrackerSettings
    lead: MarkerTracker
    trail: MarkerTracker
    lead_spec: object
    trail_spec: object
    led_model: ColourModel | None
    progress: Callable[[int], None] | None = None
    led_brightness: str | None = None


@dataclass
class FrameRecord:
    """One frame (or field) as an engine measured it.

    Attributes
    ----------
    index : int
        The frame's (field's) number in decoding order.
    time_s : float
        Its presentation time.
    intra : bool
        Whether the codec coded it on its own.
    row_offset, row_step : int
        Where its rows lie in the whole frame (a field: offset 0 or 1, step 2).
    found : dict of str to Blob
        The markers found in it (``"lead"``, ``"trail"``).
    reason : str
        Why it is invalid ("" when valid).
    repeated : bool
        Whether it repeats the previous image bit for bit.
    image : callable
        Gives the frame's RGB image (taken as the track's snapshot only when needed).
    led_level : float or None
        The LED's brightness (NaN where not measured); None: no LED is being followed.
    led_peak_dn : float or None
        The brightest luma in the LED's disk, for the clipping check; None: not measured.
    """

    index: int
    time_s: float
    intra: bool
    row_offset: int
    row_step: int
    found: dict[str, Blob]
    reason: str
    repeated: bool
    image: Callable[[], np.ndarray]
    led_level: float | None = None
    led_peak_dn: float | None = None


@dataclass
class TrackLog:
    """The per-frame records of one run, column by column, and the run's warnings."""

    time_s: list[float] = field(default_factory=list)
    intra: list[bool] = field(default_factory=list)
    xy: dict[str, list[tuple[float, float]]] = field(default_factory=lambda: {"lead": [], "trail": []})
    area: dict[str, list[float]] = field(default_factory=lambda: {"lead": [], "trail": []})
    sigma: dict[str, list[float]] = field(default_factory=lambda: {"lead": [], "trail": []})
    shape: dict[str, list[tuple[float, float, float]]] = field(default_factory=lambda: {"lead": [], "trail": []})
    reasons: list[str] = field(default_factory=list)
    repeated: list[bool] = field(default_factory=list)
    led_signal: list[float] = field(default_factory=list)
    led_peak_dn: list[float] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    snapshot: np.ndarray | None = None
    snapshot_index: int = 0
    #: The LED's candidates and their levels (:class:`~servoscope.markers.led_search.LedSearch`); None: no LED.
    led_search: object | None = None

    def add(self, rec: FrameRecord) -> None:
        """Append one frame: centroids in frame rows, areas, uncertainties and second moments (NaN where a marker is missing).

        A field (``row_step`` 2) has half the rows: its areas count double and its
        y uncertainty is that of a pixel twice as tall. The first valid whole
        frame becomes the snapshot.
        """
        self.time_s.append(rec.time_s)
        self.intra.append(rec.intra)
        for name in ("lead", "trail"):
            if name in rec.found:
                m = rec.found[name].moments
                self.xy[name].append((float(m.x_px), float(rec.row_offset + rec.row_step * m.y_px)))
                self.area[name].append(m.m00 * rec.row_step)
                self.sigma[name].append(rec.found[name].sigma_px * math.sqrt(0.5 * (1 + rec.row_step**2)))
                # Second moments in frame pixels: a field's rows are twice as tall.
                self.shape[name].append((float(m.mu20), float(m.mu11) * rec.row_step, float(m.mu02) * rec.row_step**2))
            else:
                self.xy[name].append((math.nan, math.nan))
                self.area[name].append(math.nan)
                self.sigma[name].append(math.nan)
                self.shape[name].append((math.nan, math.nan, math.nan))
        self.reasons.append(rec.reason)
        self.repeated.append(rec.repeated)
        if self.snapshot is None and not rec.reason and rec.row_step == 1:
            self.snapshot, self.snapshot_index = rec.image(), rec.index
        if rec.led_level is not None:
            self.led_signal.append(rec.led_level)
        if rec.led_peak_dn is not None:
            self.led_peak_dn.append(rec.led_peak_dn)

    def __len__(self) -> int:
        return len(self.time_s)
