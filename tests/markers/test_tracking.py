"""Tracking against the renderer's truth, and the tracker's behaviour on its own footage."""

import json
import math

import numpy as np
import pytest

from servoscope.angle import angle_rad_from_centroids
from servoscope.campaign import load_campaign
from servoscope.errors import ServoscopeError
from servoscope.pipeline import TrackerSettings, track_video


def _truth(manifest):
    return json.loads((manifest.parent / "truth.json").read_text())


@pytest.fixture(scope="module")
def step_track(quick_campaign):
    campaign = load_campaign(quick_campaign)
    test = campaign.step_tests[0]
    settings = TrackerSettings(campaign.lead, campaign.trail, campaign.led, campaign.camera, campaign.exposure_s)
    return test, track_video(test.video, settings)


def test_angle_convention():
    lead = np.array([[100.0, 50.0]])
    trail = np.array([[0.0, 60.0]])  # trail lower in the image (y down): counter-clockwise, positive
    assert angle_rad_from_centroids(lead, trail)[0] == pytest.approx(math.atan2(10, 100))


def test_angles_match_rendered_truth(quick_campaign, step_track):
    test, track = step_track
    truth = next(t for t in _truth(quick_campaign)["tests"] if t["video"] == test.video.name)
    true_angle = np.asarray(truth["angle_rad"])
    assert track.n_frames == len(true_angle)
    np.testing.assert_allclose(track.time_s, truth["time_s"], atol=1e-9)
    assert track.valid.all()
    error_deg = np.degrees(track.angle_rad - true_angle)
    rms = float(np.sqrt(np.mean(error_deg**2)))
    print(f"angle error on rendered H.264 footage: RMS {rms:.4f} deg, max {np.abs(error_deg).max():.4f} deg")
    assert np.abs(error_deg).max() < 0.05
    assert rms < 0.02


def test_centroids_match_rendered_truth(quick_campaign, step_track):
    test, track = step_track
    truth = next(t for t in _truth(quick_campaign)["tests"] if t["video"] == test.video.name)
    for key, measured in (("lead_xy_px", track.lead_xy_px), ("trail_xy_px", track.trail_xy_px)):
        err = np.hypot(*(measured - np.asarray(truth[key])).T)
        print(f"{key}: centroid error RMS {np.sqrt(np.mean(err**2)):.4f} px")
        assert np.sqrt(np.mean(err**2)) < 0.15


def test_led_switch_time(quick_campaign, step_track):
    test, track = step_track
    truth = next(t for t in _truth(quick_campaign)["tests"] if t["video"] == test.video.name)
    assert track.t0_s is not None
    period = float(np.median(np.diff(track.time_s)))
    print(f"LED t0 error {1e3 * (track.t0_s - truth['t0_s']):+.3f} ms (frame period {1e3 * period:.1f} ms)")
    assert abs(track.t0_s - truth["t0_s"]) < 0.25 * period
    # The level is 1 while lit and 0 once off.
    np.testing.assert_allclose(track.led_level[track.time_s < truth["t0_s"] - period], 1.0, atol=0.1)
    np.testing.assert_allclose(track.led_level[track.time_s > truth["t0_s"] + period], 0.0, atol=0.1)


def test_swapped_colours_mirror_the_angle(quick_campaign, step_track):
    test, track = step_track
    campaign = load_campaign(quick_campaign)
    swapped = track_video(test.video, TrackerSettings(campaign.trail, campaign.lead, campaign.led, campaign.camera))
    # Identity comes from colour: swapping the colours swaps the ends, so the angle turns by π.
    diff = np.angle(np.exp(1j * (swapped.angle_rad - track.angle_rad)))
    np.testing.assert_allclose(np.abs(diff), math.pi, atol=1e-9)


def test_colour_that_matches_nothing(quick_campaign):
    campaign = load_campaign(quick_campaign)
    with pytest.raises(ServoscopeError, match="#0000ff.*matches nothing"):
        track_video(campaign.tests[0].video, TrackerSettings(lead="#0000ff", trail=campaign.trail, led=None))


def test_measured_angle_noise_matches_the_true_tracking_error(quick_campaign, quick_result):
    """The rigid-motion null channel's RMS is the angle's real tracking error on H.264 footage,
    where the per-frame σ from pixel noise is several times too small (the codec's errors)."""
    from servoscope.markers import angle_error_analysis

    truth = {t["video"]: t for t in _truth(quick_campaign)["tests"]}
    campaign = load_campaign(quick_campaign)
    ratios, pixel_ratios = [], []
    for test in campaign.sine_tests:
        track = quick_result.tracks[test.label]
        err = (track.angle_rad - np.asarray(truth[test.video.name]["angle_rad"]))[track.valid]
        true_rms = float(np.std(err))  # the constant sticker offset is not a tracking error
        analysis = angle_error_analysis(track)
        ratios.append(analysis["measured_noise_rad"] / true_rms)
        pixel_ratios.append(analysis["angle_sigma_rad"] / true_rms)
        assert track.summary()["angle_noise_measured_rad"] == analysis["measured_noise_rad"]
    print("measured / true:", np.round(ratios, 2), "pixel-noise σ / true:", np.round(pixel_ratios, 2))
    assert all(0.6 < r < 1.6 for r in ratios)
    assert max(pixel_ratios) < 0.5  # what the measurement is for: the pixel-noise σ misses most of it
