"""A sticker smeared by its own motion is not "misshapen": the shape check allows what the motion can do."""

from __future__ import annotations

import math

from servoscope.markers.centroid import SoftCentroid
from servoscope.markers.marker_state import MarkerTracker
from servoscope.markers.moments import Moments
from servoscope.markers.settings import TrackerSettings


def _tracker_moving(step_px: float) -> MarkerTracker:
    t = MarkerTracker("lead", (214, 39, 40), TrackerSettings())
    t.reference = (200.0, 4.0, 4.0)  # area (px²), axes σ (px): a still disc of radius 8
    for i in range(4):  # steady motion along x, step_px a frame
        blob = type("B", (), {"moments": Moments(200.0, 100.0 + i * step_px, 50.0, 16.0, 0.0, 16.0), "flaw": "x"})
        t.accept(blob, None)
    return t


def _smeared(length_px: float) -> SoftCentroid:
    # A disc of σ² = 16 px² smeared along x over length_px: σx² grows by length²/12.
    m = Moments(200.0, 130.0, 50.0, 16.0 + length_px**2 / 12.0, 0.0, 16.0)
    return SoftCentroid(m, 0.01, 10.0, 50.0, 0.0, False)


def test_a_fast_stickers_smear_is_not_misshapen_but_a_still_ones_is():
    smear = _smeared(10.0)  # σx 4.86 px: +21 % over the reference's 4
    assert "misshapen" in _tracker_moving(0.0).flaw(smear)  # a still sticker cannot look like that
    assert _tracker_moving(10.0).flaw(smear) == ""  # one moving 10 px a frame can (exposure ≤ a frame)
    # A short shutter leaves a fast sticker unsmeared: that is whole too (blur may, not must).
    assert _tracker_moving(10.0).flaw(_smeared(0.0)) == ""
    # ... but not beyond what a full frame's exposure allows
    assert "misshapen" in _tracker_moving(10.0).flaw(_smeared(22.0))
    assert math.isclose(_tracker_moving(10.0).blur_reach_px, 6.25)
