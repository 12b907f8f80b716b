"""Rolling-shutter timing, measured against the digital twin.

A rolling shutter exposes row y at ``frame_time + readout·y/height``. The twin
renders every row at its own time; servoscope, told the readout, dates each
angle sample by its markers' rows and the input start by the LED's row. The
scene here puts the LED on a bracket ~240 rows above the stickers, so that an
uncorrected analysis is late by a few milliseconds.
"""

from __future__ import annotations

import json
import math

from dataclasses import replace
from pathlib import Path

import av
import numpy as np
import pytest

from servoscope.campaign import identify, load_campaign
from servoscope.campaign.cache import TrackCache, tracks_equal
from servoscope.campaign.runner import _settings
from servoscope.errors import ServoscopeError
from servoscope.pipeline.tracker import TrackerSettings, track_video
from servoscope.simulate import PAPER_SERVO, PRESETS, FrameRenderer, Scene, simulate_campaign
from servoscope.video.writer import rgb_to_yuv420p

# run_cli: the command's entry point in this process, as a child ran it (no interpreter to start a call).
from support import GOOD, run_cli, tiny_video as _tiny_video

READOUT_S = 0.015
FPS = 50  # a camcorder's rate: a 15 ms readout fits in its 20 ms frame interval
LED_OFFSET_PX = 230.0
FREQUENCIES_HZ = (2.0, 4.0, 7.0, 12.0)


# -- renderer ---------------------------------------------------------------------
@pytest.mark.parametrize("offset_px", [0.0, LED_OFFSET_PX])
def test_rolling_renderer_draws_each_row_at_its_own_pose(offset_px):
    scene = Scene(led_offset_px=offset_px)
    r = FrameRenderer(scene, PRESETS["quick"].camera(), noise_sigma_dn=0.0)
    h = scene.height
    # One pose and LED level on every row: exactly the global-shutter frame.
    still = r.composite(0.02, 0.4).copy()
    assert np.array_equal(r.composite_rolling(np.full(h, 0.02), np.full(h, 0.4)), still)
    # A pose per row: each row is that row of the global frame at the row's pose.
    pitch = np.linspace(-0.03, 0.05, h)
    level = np.linspace(1.0, 0.0, h)
    rolling = r.composite_rolling(pitch, level).copy()
    lead, trail = scene.sticker_centres_px(0.0)
    rows = {int(round(lead[1])), int(round(trail[1])), int(round(scene.led_centre_px(0.0)[1])), 290, 300}
    for j in sorted(rows):
        ref = r.composite(float(pitch[j]), float(level[j]))[j]
        np.testing.assert_allclose(rolling[j], ref, rtol=0, atol=1e-9)
    # ...and the rows differ from a single-pose frame where the blade is.
    assert np.abs(rolling - still).max() > 10.0


def test_readout_zero_writes_the_global_shutter_frames(tmp_path):
    toml = simulate_campaign(tmp_path, preset="quick", seed=5, frequencies_hz=(4.0,), include_step=False,
                             codec="raw", width=360, height=288, readout_s=0.0)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert "readout_s" not in truth["video"]  # a global shutter's truth.json is unchanged
    rec = truth["tests"][0]
    assert "lead_time_s" not in rec and "readout_s" not in toml.read_text()
    # The video holds FrameRenderer.render's frames at the truth's pose and LED level, byte for byte.
    p = replace(PRESETS["quick"], width=360, height=288)
    scene = Scene.for_size(360, 288, background_seed=5)
    rng = np.random.default_rng(np.random.SeedSequence(5).spawn(1)[0])
    rng.uniform(0.02, 0.98)
    renderer = FrameRenderer(scene, p.camera(), noise_sigma_dn=p.noise_sigma_dn,
                             noise_seed=int(rng.integers(0, 2**63 - 1)))
    with av.open(str(tmp_path / rec["video"])) as c:
        frames = [f.to_ndarray(format="yuv420p") for f in c.decode(video=0)]
    for i in (0, len(frames) // 2, len(frames) - 1):
        expected = renderer.render(rec["pitch_rad"][i], rec["led_level"][i], i)
        assert np.array_equal(frames[i], rgb_to_yuv420p(expected))


# -- the campaign, with and without the correction ---------------------------------------
def _predicted_lag_s(scene: Scene, camera) -> tuple[float, float]:
    """(angle lag, LED lag) behind the frame time, from the scene's geometry at zero pitch.

    The angle is seen at the markers' rows weighted by their lever arms about
    the pivot (their shares of the angle's motion); rows are those of the
    recorded (distorted) image.
    """
    lead_uv, trail_uv = scene.sticker_centres_uv()
    length = float(np.hypot(*(lead_uv - trail_uv)))
    w_lead = float(lead_uv @ ((lead_uv - trail_uv) / length)) / length  # pivot at the blade frame's origin
    rows = camera.distort_points(np.stack([*scene.sticker_centres_px(0.0), scene.led_centre_px(0.0)]))[:, 1]
    y_angle = w_lead * rows[0] + (1.0 - w_lead) * rows[1]
    return READOUT_S * y_angle / scene.height, READOUT_S * rows[2] / scene.height


@pytest.fixture(scope="module")
def rolling(tmp_path_factory):
    out = tmp_path_factory.mktemp("rolling")
    scene = Scene.for_size(720, 576, background_seed=0, led_offset_px=LED_OFFSET_PX)
    toml = simulate_campaign(out, preset="quick", seed=0, fps=FPS, exposure_s=1.0 / FPS, readout_s=READOUT_S,
                             frequencies_hz=FREQUENCIES_HZ, scene=scene)
    campaign = load_campaign(toml)
    settings = _settings(campaign)
    corrected = {t.label: track_video(t.video, settings) for t in campaign.tests}
    plain = {t.label: track_video(t.video, replace(settings, readout_s=0.0)) for t in campaign.tests}
    truth = json.loads((out / "truth.json").read_text())
    return {
        "campaign": campaign, "truth": truth, "scene": scene, "camera": PRESETS["quick"].camera(),
        "corrected": corrected, "plain": plain,
        "with": identify(campaign, tracks=corrected), "without": identify(campaign, tracks=plain),
    }


def _phase_errors_deg(result):
    fr = result.frequency_response
    w = 2 * math.pi * fr.frequency_hz
    true = np.degrees(np.angle(PAPER_SERVO.transfer_function(1j * w) * np.exp(-1j * w * PAPER_SERVO.dead_time_s)))
    err = (fr.phase_deg - true + 180.0) % 360.0 - 180.0
    return fr.frequency_hz, err, fr.phase_stderr_deg


def test_twin_records_the_readout_and_row_times(rolling):
    truth, campaign = rolling["truth"], rolling["campaign"]
    assert truth["video"]["readout_s"] == READOUT_S and campaign.readout_s == READOUT_S
    angle_lag, led_lag = _predicted_lag_s(rolling["scene"], rolling["camera"])
    rec = truth["tests"][0]
    t = np.asarray(rec["time_s"])
    # Within a pixel's row (26 µs) of the geometry at rest.
    assert np.asarray(rec["led_time_s"])[0] - t[0] == pytest.approx(led_lag, abs=3e-5)
    assert np.all(np.asarray(rec["trail_time_s"]) > np.asarray(rec["lead_time_s"]))


def test_track_dates_angles_by_the_markers_lever_weighted_rows(rolling, tmp_path):
    angle_lag, _ = _predicted_lag_s(rolling["scene"], rolling["camera"])
    for label, tr in rolling["corrected"].items():
        assert tr.readout_s == READOUT_S and not any("rolling shutter" in w for w in tr.warnings)
        lag = tr.angle_time_s - tr.time_s
        # The blade's motion moves the rows a little; at rest (the first frames) the geometry holds.
        assert lag[:5].mean() == pytest.approx(angle_lag, abs=5e-5), label
        # The plain mean of the two rows would be 0.23 ms off: the lever weighting is measured.
        plain = rolling["plain"][label]
        assert np.array_equal(plain.angle_time_s, plain.time_s)
        assert np.array_equal(plain.angle_rad, tr.angle_rad, equal_nan=True)
    tr = rolling["corrected"]["step"]
    tr.to_csv(tmp_path / "step.csv")
    header = (tmp_path / "step.csv").read_text().splitlines()[0].split(",")
    assert "angle_time_s" in header and header[:4] == ["frame", "time_s", "angle_rad", "valid"]
    cache = TrackCache(tmp_path / "cache")
    key = cache.key(rolling["campaign"].tests[-1].video, _settings(rolling["campaign"]))
    cache.store(key, tr)
    assert tracks_equal(cache.load(key), tr)


def test_t0_is_corrected_by_the_led_row(rolling):
    _, led_lag = _predicted_lag_s(rolling["scene"], rolling["camera"])
    for rec in rolling["truth"]["tests"]:
        label = Path(rec["video"]).stem
        plain, corrected = rolling["plain"][label], rolling["corrected"][label]
        assert corrected.t0_s - plain.t0_s == pytest.approx(led_lag, abs=3e-5)
        assert corrected.t0_uncertainty_s == plain.t0_uncertainty_s
        assert abs(plain.t0_s - rec["t0_s"] + led_lag) < 2e-4
        assert abs(corrected.t0_s - rec["t0_s"]) < 2e-4


def test_uncorrected_phases_and_dead_time_are_off_by_the_predicted_lag(rolling):
    angle_lag, led_lag = _predicted_lag_s(rolling["scene"], rolling["camera"])
    lag = angle_lag - led_lag  # the angle looks early against t0 by this: a phase lead, a shorter dead time
    assert lag > 5e-3  # the geometry makes it large: ~240 rows of a 576-row frame at 15 ms
    freqs, err_with, se = _phase_errors_deg(rolling["with"])
    _, err_without, _ = _phase_errors_deg(rolling["without"])
    predicted = 360.0 * freqs * lag
    np.testing.assert_allclose(err_without - err_with, predicted, rtol=0.03, atol=0.1)
    np.testing.assert_allclose(err_without, predicted, rtol=0.05, atol=3 * se.max())
    truth_dead = PAPER_SERVO.dead_time_s
    # The dead time from the phases (complex fit) is short by the lag.
    assert rolling["without"].model.dead_time_s - truth_dead == pytest.approx(-lag, abs=3e-4)
    # The step's: the blade's own motion moves its rows during the step (~55 rows, 1.4 ms),
    # which the uncorrected analysis cannot follow either.
    assert rolling["without"].dead_time_s - truth_dead == pytest.approx(-lag, abs=6e-4)


def test_corrected_phases_and_dead_time_match_truth(rolling):
    freqs, err, se = _phase_errors_deg(rolling["with"])
    print("phase error with correction (deg):", np.round(err, 3), "stderr:", np.round(se, 3))
    assert np.all(np.abs(err) < 3.0 * se), (err, se)
    assert abs(rolling["with"].dead_time_s - PAPER_SERVO.dead_time_s) < 5e-4
    assert abs(rolling["with"].model.dead_time_s - PAPER_SERVO.dead_time_s) < 5e-4


# -- bad input ------------------------------------------------------------------------
def test_simulation_refuses_impossible_readouts(tmp_path):
    for bad in (-0.001, 0.01, 0.02, math.nan):  # quick preset: 100 frames/s, 10 ms frames
        with pytest.raises(ServoscopeError, match="readout_s"):
            simulate_campaign(tmp_path, preset="quick", readout_s=bad)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("value,expected", [
    ("-0.001", "--readout must be a time >= 0"),
    ("0.04", "not shorter than the frame interval (40 ms)"),
    ("nan", "--readout must be a time >= 0"),
])
def test_cli_track_bad_readout(tmp_path, value, expected):
    video = _tiny_video(tmp_path / "v.mp4")  # 25 frames/s
    proc = run_cli("track", video, "--readout", value, "--out", tmp_path / "t.csv")
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("servoscope: error: ") and expected in lines[0], proc.stderr
    assert not (tmp_path / "t.csv").exists()


def test_track_video_refuses_negative_readout(tmp_path):
    video = _tiny_video(tmp_path / "v.mp4")
    with pytest.raises(ServoscopeError, match="readout"):
        track_video(video, TrackerSettings(readout_s=-1e-3))


@pytest.mark.parametrize("value,expected", [
    ("-0.01", "camera.readout_s: must be ≥ 0"),
    ("0.05", "camera.readout_s: 0.05 s is not shorter than the frame interval"),
    ('"fast"', "camera.readout_s: must be a finite number"),
])
def test_manifest_bad_readout(tmp_path, value, expected):
    _tiny_video(tmp_path / "a.mp4")
    _tiny_video(tmp_path / "b.mp4")
    manifest = tmp_path / "campaign.toml"
    manifest.write_text(f"[camera]\nreadout_s = {value}\n" + GOOD)
    with pytest.raises(ServoscopeError, match=expected.replace(".", r"\.")):
        load_campaign(manifest)
    proc = run_cli("identify", manifest, "--out", tmp_path / "out")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and expected in proc.stderr, proc.stderr


def test_manifest_good_readout(tmp_path):
    _tiny_video(tmp_path / "a.mp4")
    _tiny_video(tmp_path / "b.mp4")
    manifest = tmp_path / "campaign.toml"
    manifest.write_text(GOOD)
    assert load_campaign(manifest).readout_s == 0.0
    manifest.write_text("[camera]\nreadout_s = 0.03\n" + GOOD)
    campaign = load_campaign(manifest)
    assert campaign.readout_s == 0.03 and _settings(campaign).readout_s == 0.03
    assert campaign.without({"stepper": "gone"}).readout_s == 0.03
