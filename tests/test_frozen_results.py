"""Results are frozen (docs/architecture.md): a later stage makes a new object with dataclasses.replace."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from servoscope.campaign.result import IdentificationResult
from servoscope.markers.track import Track


def _track(**more) -> Track:
    n = 4
    xy = np.zeros((n, 2))
    return Track(video="v.mp4", frame=np.arange(n), time_s=np.arange(n) / 100.0, lead_xy_px=xy, trail_xy_px=xy + 1.0,
                 lead_area_px=np.ones(n), trail_area_px=np.ones(n), angle_rad=np.zeros(n), valid=np.ones(n, bool),
                 reason=[""] * n, led_level=np.full(n, np.nan), **more)


def test_a_track_is_frozen():
    track = _track(warnings=["one"])
    with pytest.raises(dataclasses.FrozenInstanceError):
        track.t0_s = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        track.warnings = ()
    assert track.warnings == ("one",)  # a list given is kept as a tuple: nothing appends to it
    later = dataclasses.replace(track, t0_s=0.5, warnings=(*track.warnings, "two"))
    assert later.t0_s == 0.5 and later.warnings == ("one", "two")
    assert track.t0_s is None and track.warnings == ("one",)
    # Filled in at construction still (the columns an older track lacks).
    assert later.angle_time_s is not None and later.lead_sigma_px.shape == (4,)


def test_an_identification_result_is_frozen():
    track = _track()
    result = IdentificationResult(campaign=None, tracks={"a": track}, sine_fits={}, frequency_response=None,
                                  model=None, warnings=["w"], modes=[], heave_response=[])
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.warnings = ()
    with pytest.raises(dataclasses.FrozenInstanceError):
        result.step = None
    assert result.warnings == ("w",) and result.modes == () and result.heave_response == ()
    with pytest.raises(TypeError):
        result.tracks["b"] = track  # a read-only mapping
    assert dict(result.tracks) == {"a": track}
    later = dataclasses.replace(result, warnings=(*result.warnings, "x"))
    assert later.warnings == ("w", "x") and result.warnings == ("w",)
