"""Video writer round trips and the simulated campaign's files."""

from __future__ import annotations

import json
import math
import tomllib

from fractions import Fraction

import av
import numpy as np
import pytest

from servoscope.camera.model import CameraModel
from servoscope.errors import ServoscopeError
from servoscope.simulate import PAPER_SERVO, PRESETS, InputSignal, simulate_campaign
from servoscope.video.writer import VideoWriter, rgb_to_yuv420p


def decode(path):
    with av.open(str(path)) as c:
        frames = list(c.decode(video=0))
    return frames


def smooth_frames(n, h=64, w=96):
    yy, xx = np.mgrid[0:h, 0:w]
    out = []
    for i in range(n):
        f = np.stack([128 + 90 * np.sin(xx / 9 + i), 128 + 90 * np.cos(yy / 7 - i), 128 + 60 * np.sin((xx + yy) / 13)], -1)
        out.append(np.round(f).astype(np.uint8))
    return out


# -- video writer ---------------------------------------------------------------
@pytest.mark.parametrize("codec,suffix", [("h264", ".mp4"), ("raw", ".avi"), ("raw", ".nut")])
@pytest.mark.parametrize("fps", [100, Fraction(30000, 1001)])
def test_writer_round_trip_count_size_and_times(tmp_path, codec, suffix, fps):
    frames = smooth_frames(12)
    path = tmp_path / f"v{suffix}"
    with VideoWriter(path, 96, 64, fps, codec=codec, bit_rate=2_000_000) as w:
        for f in frames:
            w.write(f)
    dec = decode(path)
    assert len(dec) == 12
    assert all((d.width, d.height) == (96, 64) for d in dec)
    assert [d.pts for d in dec] == sorted(d.pts for d in dec)
    times = np.array([float(d.time) for d in dec])
    assert np.max(np.abs(times - np.arange(12) / float(Fraction(fps)))) < 1e-9
    if codec == "raw":
        # lossless container: exactly the yuv420p we converted to
        for d, f in zip(dec, frames):
            assert np.array_equal(d.to_ndarray(format="yuv420p"), rgb_to_yuv420p(f))
    else:
        rgb = dec[5].to_ndarray(format="rgb24").astype(int)
        assert np.mean(np.abs(rgb - frames[5])) < 3.0


def test_rgb_to_yuv420p_agrees_with_ffmpeg():
    f = smooth_frames(1, 144, 176)[0]
    ours = rgb_to_yuv420p(f).astype(int)
    ref = av.VideoFrame.from_ndarray(f, format="rgb24").reformat(format="yuv420p").to_ndarray().astype(int)
    assert ours.shape == ref.shape
    assert np.max(np.abs(ours - ref)) <= 1


@pytest.mark.parametrize("shape", [(96, 128), (2, 2), (58, 86)])
def test_rgb_to_yuv420p_is_the_bt601_equations_in_float32(shape):
    """The conversion is BT.601's limited-range equations in float32, truncated after adding half, with each
    chroma sample from its 2×2 block's sums: numpy's arithmetic of the same equations gives every sample to the
    bit, over random, black, white and strided frames (the twin's videos depend on each bit)."""
    h, w = shape
    rng = np.random.default_rng(h * w)
    wide = rng.integers(0, 256, (h + 4, w + 6, 3), dtype=np.uint8)
    frames = [wide[:h, :w].copy(), np.zeros((h, w, 3), np.uint8), np.full((h, w, 3), 255, np.uint8),
              wide[2:2 + h, 3:3 + w]]
    for rgb in frames:
        f = rgb.astype(np.float32)
        r, g, b = f[..., 0], f[..., 1], f[..., 2]
        y = np.float32(16.5) + (np.float32(65.481) * r + np.float32(128.553) * g + np.float32(24.966) * b) * np.float32(
            1 / 255)
        sums = f.reshape(h // 2, 2, w // 2, 2, 3).sum(axis=(1, 3), dtype=np.float32)
        rs, gs, bs = sums[..., 0], sums[..., 1], sums[..., 2]
        k = np.float32(0.25 / 255)
        u = np.float32(128.5) + (np.float32(-37.797) * rs - np.float32(74.203) * gs + np.float32(112.0) * bs) * k
        v = np.float32(128.5) + (np.float32(112.0) * rs - np.float32(93.786) * gs - np.float32(18.214) * bs) * k
        planes = [p.astype(np.int32).astype(np.uint8).ravel() for p in (y, u, v)]
        assert np.array_equal(rgb_to_yuv420p(rgb), np.concatenate(planes).reshape(h * 3 // 2, w))


def test_writer_rejects_bad_arguments(tmp_path):
    with pytest.raises(ServoscopeError):
        VideoWriter(tmp_path / "a.mp4", 95, 64, 100)
    with pytest.raises(ServoscopeError):
        VideoWriter(tmp_path / "a.mkv", 96, 64, 100, codec="raw")
    with pytest.raises(ServoscopeError):
        VideoWriter(tmp_path / "a.mp4", 96, 64, 100, codec="mjpeg")
    with VideoWriter(tmp_path / "b.mp4", 96, 64, 100) as w:
        with pytest.raises(ServoscopeError):
            w.write(np.zeros((64, 96, 3), dtype=np.float32))


# -- campaign -----------------------------------------------------------------
@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("quick")
    toml = simulate_campaign(out, preset="quick", seed=7, width=360, height=288)
    return toml


def test_campaign_files_are_readable_and_consistent(quick):
    out = quick.parent
    manifest = tomllib.loads(quick.read_text())
    truth = json.loads((out / "truth.json").read_text())
    preset = PRESETS["quick"]
    # Default exposure: one frame interval (a camcorder's 1/100 s shutter at 100 frames/s).
    assert manifest["camera"] == {"calibration": "camera.json", "exposure_s": 0.01}
    assert manifest["markers"] == {"lead": "#d62728", "trail": "#2ca02c", "led": "#ffd400"}
    assert manifest["input"]["units"] == "normalized"
    tests = manifest["tests"]
    assert [t["kind"] for t in tests] == ["sine"] * 4 + ["step"]
    assert [t["frequency_hz"] for t in tests[:4]] == pytest.approx(np.geomspace(1, 12, 4), rel=1e-15)
    assert tests[0]["video"] == "dwell_01_1.00Hz.mp4" and tests[-1]["video"] == "step.mp4"
    assert tests[0]["amplitude"] == 0.1 and tests[-1]["amplitude"] == 0.5
    for t, tt in zip(tests, truth["tests"]):
        assert (out / t["video"]).is_file() and tt["video"] == t["video"]

    cam = CameraModel.load(out / manifest["camera"]["calibration"])
    assert cam.to_dict() == truth["camera"] and cam.image_size == (360, 288)
    assert cam.camera_matrix[0, 0] == pytest.approx(550.0) and cam.has_distortion

    assert truth["preset"] == "quick" and truth["seed"] == 7
    assert truth["model"]["num"] == list(PAPER_SERVO.num) and truth["model"]["dead_time_s"] == 0.085
    assert truth["video"] == {"codec": "h264", "bit_rate": 20_000_000, "gop": None, "fps": 100.0, "fps_rational": [100, 1],
                              "exposure_s": 0.01, "noise_sigma_dn": 1.5, "width": 360, "height": 288}
    # step metrics of 0.23*37^2/(s^2 + 2*0.65*37 s + 37^2), closed forms / python-control
    z = 0.65
    assert truth["step"]["overshoot_pct"] == pytest.approx(100 * math.exp(-z * math.pi / math.sqrt(1 - z * z)),
                                                          rel=1e-4)
    assert truth["step"]["dead_time_s"] == 0.085
    assert truth["bandwidth_rad_s"] == pytest.approx(PAPER_SERVO.bandwidth_rad_s)
    assert preset.pre_roll_s == 0.2


def test_truth_series_are_the_model_and_the_geometry(quick):
    truth = json.loads((quick.parent / "truth.json").read_text())
    offset = truth["sticker_offset_rad"]
    assert offset == 0.05
    t0s = []
    for t in truth["tests"]:
        time_s = np.array(t["time_s"])
        pitch = np.array(t["pitch_rad"])
        n = len(time_s)
        assert np.array_equal(time_s, np.arange(n) / 100.0)
        sig = InputSignal(t["kind"], t["amplitude"], t.get("frequency_hz"), t0_s=t["t0_s"])
        assert np.max(np.abs(np.array(t["pitch_at_frame_time_rad"]) - PAPER_SERVO.response(sig, time_s))) < 1e-12
        # The pose is the output averaged over the exposure window (checked with a finer rule).
        fine = (np.arange(256) + 0.5) / 256 * 0.01 - 0.005
        averaged = PAPER_SERVO.response(sig, (time_s[:, None] + fine).ravel()).reshape(n, -1).mean(axis=1)
        assert np.max(np.abs(pitch - averaged)) < 1e-7
        assert np.max(np.abs(np.array(t["angle_rad"]) - (pitch + offset))) < 1e-12
        lead, trail = np.array(t["lead_xy_px"]), np.array(t["trail_xy_px"])
        assert lead.shape == trail.shape == (n, 2)
        angle = np.arctan2(trail[:, 1] - lead[:, 1], lead[:, 0] - trail[:, 0])
        assert np.max(np.abs(angle - t["angle_rad"])) < 1e-12
        # LED lit during the pre-roll, dark after t0, one partially lit frame
        t0 = t["t0_s"]
        frac = t0 * 100 - math.floor(t0 * 100)
        assert 0.02 <= frac <= 0.98  # not on a frame time
        led = np.array(t["led_level"])
        assert np.all(led[time_s < t0 - 0.005] == 1.0) and np.all(led[time_s > t0 + 0.005] == 0.0)
        partial = (led > 0) & (led < 1)
        assert partial.sum() == 1  # the exposure spans the frame interval: the switch is always seen
        i = int(np.nonzero(partial)[0][0])
        assert led[i] == pytest.approx((t0 - (time_s[i] - 0.005)) / 0.01)
        dur = t0 + (0.2 + 0.8 if t["kind"] == "sine" else 0.6)
        assert n == math.ceil(dur * 100)
        t0s.append(t0)
    assert len(set(t0s)) == len(t0s)  # seeded per test


def test_campaign_videos_decode_with_frame_timestamps(quick):
    truth = json.loads((quick.parent / "truth.json").read_text())
    t = truth["tests"][-1]
    dec = decode(quick.parent / t["video"])
    assert len(dec) == len(t["time_s"])
    assert (dec[0].width, dec[0].height) == (360, 288)
    times = np.array([float(d.time) for d in dec])
    assert np.max(np.abs(times - np.arange(len(dec)) / 100.0)) < 1e-9


def test_rendered_frames_show_the_truth(tmp_path):
    # Raw video: find the red sticker in every frame of a step test and check it
    # sits where truth says (after the lens), frame by frame: an off-by-one
    # frame would be several pixels off while the blade moves.
    toml = simulate_campaign(tmp_path, "quick", seed=1, codec="raw", frequencies_hz=(), width=360, height=288,
                             noise_sigma_dn=0.0)
    truth = json.loads((tmp_path / "truth.json").read_text())
    cam = CameraModel.load(tmp_path / "camera.json")
    t = truth["tests"][0]
    assert t["video"] == "step.avi" and tomllib.loads(toml.read_text())["tests"][0]["video"] == "step.avi"
    expected = cam.distort_points(np.array(t["lead_xy_px"]))
    assert np.ptp(expected[:, 1]) > 5  # it moves
    for frame, xy in zip(decode(tmp_path / "step.avi"), expected):
        rgb = frame.to_ndarray(format="rgb24").astype(float)
        redness = np.clip((rgb[:, :, 0] - rgb[:, :, 1]) / 150.0, 0, 1)
        x0, y0 = int(xy[0]) - 12, int(xy[1]) - 12
        win = redness[y0:y0 + 24, x0:x0 + 24]
        ys, xs = np.mgrid[y0:y0 + 24, x0:x0 + 24]
        c = np.array([(win * xs).sum(), (win * ys).sum()]) / win.sum()
        assert np.hypot(*(c - xy)) < 0.3


def test_same_seed_same_bytes_other_seed_other_footage(tmp_path):
    kw = dict(frequencies_hz=(3.0,), include_step=False, width=160, height=128, min_dwell_s=0.3, settle_s=0.1)
    a = simulate_campaign(tmp_path / "a", "quick", seed=5, **kw).parent
    b = simulate_campaign(tmp_path / "b", "quick", seed=5, **kw).parent
    c = simulate_campaign(tmp_path / "c", "quick", seed=6, **kw).parent
    names = sorted(p.name for p in a.iterdir())
    assert names == ["camera.json", "campaign.toml", "dwell_01_3.00Hz.mp4", "truth.json"]
    for name in names:
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert (a / "dwell_01_3.00Hz.mp4").read_bytes() != (c / "dwell_01_3.00Hz.mp4").read_bytes()


def test_unknown_preset_or_setting_is_refused(tmp_path):
    with pytest.raises(ServoscopeError, match="preset"):
        simulate_campaign(tmp_path, preset="nonesuch")
    with pytest.raises(ServoscopeError, match="frame_rate"):
        simulate_campaign(tmp_path, preset="quick", frame_rate=50)
    with pytest.raises(ServoscopeError):
        simulate_campaign(tmp_path, preset="quick", codec="vp9")
    assert not any(tmp_path.iterdir())
