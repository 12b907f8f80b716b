"""The twin's image-sequence output: its frames track as its uncompressed video does, to the last bit (issue 16)."""

from __future__ import annotations

import tomllib

import numpy as np
import pytest

from servoscope.campaign import load_campaign
from servoscope.campaign.runner import track_campaign
from servoscope.simulate import simulate_campaign
from servoscope.video.reader import iter_yuv_frames, probe_video

pytest.importorskip("tifffile")

SMALL = dict(width=360, height=288, fps=100, frequencies_hz=(1.0, 6.0), pre_roll_s=0.2, settle_s=0.3,
             min_dwell_s=1.0, min_periods=0.0, include_step=True, step_after_t0_s=0.8)


@pytest.fixture(scope="module")
def twins(tmp_path_factory):
    video = simulate_campaign(tmp_path_factory.mktemp("raw"), preset="quick", seed=2, codec="raw", **SMALL)
    frames = simulate_campaign(tmp_path_factory.mktemp("tiff"), preset="quick", seed=2, frames_format="tiff16", **SMALL)
    return video, frames


def test_manifest_says_frames_and_fps(twins):
    _, frames = twins
    tests = tomllib.loads(frames.read_text())["tests"]
    assert tests[0]["frames"] == "dwell_01_1.00Hz/*.tif" and tests[0]["fps"] == 100.0 and "video" not in tests[0]
    info = probe_video(load_campaign(frames).tests[0].video)
    assert (info.codec, info.bit_depth, info.width, info.height, info.frame_rate_hz) == ("tiff", 16, 360, 288, 100.0)


def test_same_planes_and_same_tracks_as_the_raw_video(twins):
    video, frames = twins
    a, b = load_campaign(video), load_campaign(frames)
    assert [t.label for t in a.tests] == [t.label for t in b.tests]
    # The pixels: 16-bit v·257 read back as v, converted by the writer's own equations.
    for fa, fb in zip(iter_yuv_frames(a.tests[0].video), iter_yuv_frames(b.tests[0].video)):
        assert fa.time_s == fb.time_s
        assert np.array_equal(fa.i420, fb.i420)
    ta, tb = track_campaign(a, workers=1), track_campaign(b, workers=1)
    for label in ta:
        x, y = ta[label], tb[label]
        for name in ("time_s", "lead_xy_px", "trail_xy_px", "angle_rad", "valid", "led_level", "lead_sigma_px",
                     "angle_sigma_rad"):
            assert np.array_equal(getattr(x, name), getattr(y, name), equal_nan=name != "valid"), (label, name)
        assert (x.t0_s, x.t0_uncertainty_s) == (y.t0_s, y.t0_uncertainty_s)
        assert x.t0_s is not None and x.valid.mean() > 0.95  # tracks worth comparing
