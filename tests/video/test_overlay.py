"""The overlay video: every frame drawn, centroids put back through the lens, invalid frames labelled."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from servoscope.campaign import load_campaign
from servoscope.errors import ServoscopeError
from servoscope.video import iter_frames, probe_video
from servoscope.pipeline import overlay
from servoscope.pipeline.overlay import annotate_frame, write_overlay


def _reddish(img: np.ndarray) -> np.ndarray:
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r > 180) & (g < 110) & (b < 110)


def test_annotate_frame_draws_markers_and_labels_invalid_frames():
    blank = np.full((240, 320, 3), 90, np.uint8)
    valid = annotate_frame(blank, (250.25, 120.5), (60.0, 140.0), angle_rad=0.1, caption="frame 3")
    assert valid.shape == blank.shape and valid.dtype == np.uint8
    assert not np.array_equal(blank, valid)
    assert np.any(valid[118:124, 247:254] != 90)  # the lead cross, at its subpixel position
    assert np.any(valid[137:143, 57:64] != 90)  # the trail cross
    assert not _reddish(valid).any()
    invalid = annotate_frame(blank, (np.nan, np.nan), (60.0, 140.0), valid=False, reason="lead marker not found")
    red = _reddish(invalid)
    assert red[:60, :240].sum() > 50  # the "invalid: …" text, top left
    assert red[0, :].all() and red[-1, :].all()  # and a red border
    # Non-ASCII reasons (the tracker writes "%" and could write "—") do not break OpenCV's fonts.
    annotate_frame(blank, (1.0, 1.0), (2.0, 2.0), valid=False, reason="partly hidden — 80 % ½")


def test_overlay_video_matches_the_footage(quick_campaign, quick_result, tmp_path, monkeypatch):
    campaign = load_campaign(quick_campaign)
    test = campaign.tests[-1]  # the step: the shortest video
    track = quick_result.tracks[test.label]
    assert campaign.camera is not None and campaign.camera.has_distortion
    bad_frame = 7
    valid = track.valid.copy()
    valid[bad_frame] = False
    reason = list(track.reason)
    reason[bad_frame] = "trail marker partly hidden"
    edited = dataclasses.replace(track, valid=valid, reason=reason)

    drawn: dict[int, tuple] = {}
    real = overlay.annotate_frame

    def spy(rgb, lead, trail, **kw):
        drawn[len(drawn)] = (np.asarray(lead, float), np.asarray(trail, float))
        return real(rgb, lead, trail, **kw)

    monkeypatch.setattr(overlay, "annotate_frame", spy)
    out = write_overlay(test.video, edited, tmp_path / "overlay.mp4", camera=campaign.camera)

    info, source = probe_video(out), probe_video(test.video)
    assert (info.width, info.height, info.codec) == (source.width, source.height, "h264")
    frames = {f.index: f.rgb for f in iter_frames(out)}
    assert len(frames) == track.n_frames == len(drawn)
    # The track's centroids are ideal (undistorted) pixels: drawn where the lens put them.
    good = np.flatnonzero(track.valid)[:5]
    for i in good:
        expected_lead = campaign.camera.distort_points(track.lead_xy_px[i : i + 1])[0]
        expected_trail = campaign.camera.distort_points(track.trail_xy_px[i : i + 1])[0]
        np.testing.assert_allclose(drawn[i][0], expected_lead, atol=1e-9)
        np.testing.assert_allclose(drawn[i][1], expected_trail, atol=1e-9)
        assert np.hypot(*(expected_lead - track.lead_xy_px[i])) > 0.5  # so the test tells them apart
    # The invalid frame carries a red border after H.264; a valid one does not.
    assert _reddish(frames[bad_frame][:3, :]).mean() > 0.5
    assert _reddish(frames[bad_frame - 1][:3, :]).mean() < 0.05
    assert not list(tmp_path.glob(".*tmp*")), "temporary file left behind"


def test_overlay_refuses_a_track_of_another_video(quick_campaign, quick_result, tmp_path):
    campaign = load_campaign(quick_campaign)
    longer = quick_result.tracks[campaign.tests[0].label]  # 121 frames onto the 81-frame step
    with pytest.raises(ServoscopeError, match="another video"):
        write_overlay(campaign.tests[-1].video, longer, tmp_path / "o.mp4")
    assert not (tmp_path / "o.mp4").exists()
    with pytest.raises(ServoscopeError, match="mp4"):
        write_overlay(campaign.tests[-1].video, longer, tmp_path / "o.avi")


def test_overlay_of_a_field_track_draws_each_frames_first_field(quick_campaign, quick_result, tmp_path, monkeypatch):
    campaign = load_campaign(quick_campaign)
    test = campaign.tests[-1]
    track = quick_result.tracks[test.label]
    # A deinterlaced track has two rows (fields) per frame: fabricate one, the second field shifted.
    n = track.n_frames
    doubled = {}
    for f in dataclasses.fields(track):
        value = getattr(track, f.name)
        if isinstance(value, np.ndarray) and value.shape[:1] == (n,):
            value = np.repeat(value, 2, axis=0)
        elif f.name == "reason":
            value = [r for r in value for _ in range(2)]
        doubled[f.name] = value
    doubled["frame"] = np.arange(2 * n)
    doubled["lead_xy_px"] = doubled["lead_xy_px"].copy()
    doubled["lead_xy_px"][1::2] += 5.0
    doubled["valid"] = doubled["valid"].copy()
    doubled["valid"][2 * 4 + 1] = False  # frame 4's second field
    fields = type(track)(**doubled)

    drawn = []
    real = overlay.annotate_frame

    def spy(rgb, lead, trail, **kw):
        drawn.append((np.asarray(lead, float), kw.get("valid", True)))
        return real(rgb, lead, trail, **kw)

    monkeypatch.setattr(overlay, "annotate_frame", spy)
    write_overlay(test.video, fields, tmp_path / "fields.mp4")  # no camera: drawn as given
    assert len(drawn) == n
    for k in range(n):
        np.testing.assert_array_equal(drawn[k][0], fields.lead_xy_px[2 * k])
    assert [k for k in range(n) if not drawn[k][1]] == [k for k in range(n) if not (track.valid[k] and (k != 4))]
