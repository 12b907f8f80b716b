"""Real-camera options of the digital twin (issue 14): each does what it claims; defaults unchanged."""

from __future__ import annotations

import hashlib
import json
import math
import tomllib

import cv2
import numpy as np
import pytest

from servoscope.errors import ServoscopeError
from servoscope.simulate import FrameRenderer, Scene, simulate_campaign
from servoscope.simulate.presets import get_preset
from servoscope.simulate.scene import Clutter, colour_rgb, lamp_gain
from servoscope.video.reader import iter_frames

W, H = 320, 256
SMALL = dict(width=W, height=H, codec="raw", frequencies_hz=(3.0,), min_dwell_s=0.3)


def _camera():
    p = get_preset("quick")
    return type(p)(name="x", servo=p.servo, frequencies_hz=(1.0,), width=W, height=H).camera()


def test_default_frames_and_campaign_are_bit_identical_to_before(tmp_path):
    # Hashes taken on main before the options existed (commit 0b18418).
    r = FrameRenderer(Scene.for_size(W, H, background_seed=3), _camera(), noise_sigma_dn=1.5, noise_seed=7)
    h = hashlib.sha256()
    for i, p in enumerate(np.linspace(-0.1, 0.1, 5)):
        h.update(r.render(float(p), i / 4, i).tobytes())
    assert h.hexdigest() == "b694653221493af5d6cdfa34d2ec822b1359b90b8062d2ca74528a00e1b05851"
    simulate_campaign(tmp_path, "quick", seed=2, **SMALL)
    digest = {f.name: hashlib.sha256(f.read_bytes()).hexdigest() for f in tmp_path.iterdir()}
    # truth.json: everything servoscope decides, to the bit. Its bandwidth and step metrics come
    # from python-control and scipy, whose last bits move between releases (OpenCV 5 / scipy 1.17
    # changed the file's hash with no change of ours): checked against closed forms instead.
    truth = json.loads((tmp_path / "truth.json").read_text())
    bandwidth, step = truth.pop("bandwidth_rad_s"), truth.pop("step")
    assert sorted(truth["video"]) == ["bit_rate", "codec", "exposure_s", "fps", "fps_rational", "gop", "height",
                                      "noise_sigma_dn", "width"]  # no option recorded
    # Retaken once since: the servo's matrix exponential in plain loops, not numba's BLAS ``@``, moves the
    # response's last bit (≤ 2.2e-16 rad); the videos did not change.
    assert hashlib.sha256(json.dumps(truth, sort_keys=True).encode()).hexdigest() == (
        "4bd60a47d6b95b7a8f68aa0793b21583e4360e83a17834219b136f4379001594")
    wn, zeta = truth["model"]["natural_frequency_rad_s"], truth["model"]["damping_ratio"]
    # |G(jω)|/K = 1/√2 of a 2nd-order system, and its overshoot exp(−πζ/√(1−ζ²)).
    assert bandwidth == pytest.approx(wn * math.sqrt(1 - 2 * zeta**2 + math.sqrt((1 - 2 * zeta**2) ** 2 + 1)), rel=1e-9)
    assert step["overshoot_pct"] == pytest.approx(100 * math.exp(-math.pi * zeta / math.sqrt(1 - zeta**2)), rel=1e-4)
    assert digest["campaign.toml"] == "a6ca4bbf904d46047e1519b4e23235e55f1fa44834ab804584f61a16f2bc3b47"
    assert digest["dwell_01_3.00Hz.avi"] == "db44802194fb8fa1a7be5fe37223c109bcc7c2737eebc0972b48daaf8b8dee0f"


def test_lamp_gain_is_the_exposure_mean_of_the_flicker():
    t = np.linspace(0.0, 0.1, 17)
    e, f, d = 0.004, 100.0, 0.3
    tau = t[:, None] + e * (np.arange(4000) + 0.5)[None, :] / 4000 - e / 2
    numeric = np.mean(1 + d * np.sin(2 * np.pi * f * tau), axis=1)
    assert np.allclose(lamp_gain(t, e, f, d), numeric, atol=1e-7)
    assert np.allclose(lamp_gain(t, 0.01, 100.0, d), 1.0)  # a whole flicker period sees none


def test_flicker_scales_lamp_lit_pixels_not_the_lit_led():
    scene = Scene.for_size(W, H)
    r = FrameRenderer(scene, None, noise_sigma_dn=0.0)
    steady = r.composite(0.0, 1.0).copy()
    dim = r.composite(0.0, 1.0, lamp_gain=0.7).copy()
    led = scene.led_centre_px(0.0)
    yy, xx = np.mgrid[0:H, 0:W]
    inside_led = np.hypot(xx - led[0], yy - led[1]) < 0.5 * scene.led_diameter_px - 1.5
    assert inside_led.sum() >= 5
    assert np.allclose(dim[inside_led], colour_rgb(scene.led_colour), atol=1e-3)
    assert np.allclose(dim[0:20], 0.7 * steady[0:20], atol=1e-3)  # background rows
    # The dark LED is lamp-lit.
    dark = r.composite(0.0, 0.0, lamp_gain=0.7)
    assert np.allclose(dark[inside_led], 0.7 * colour_rgb(scene.led_off_colour), atol=1e-3)
    # Back to steady: the cached-background path draws the steady frame again.
    assert np.array_equal(r.composite(0.0, 1.0), steady)


def test_flicker_in_a_campaign_follows_the_lamps_at_its_frequency(tmp_path):
    f, d, e = 37.0, 0.2, 0.0025
    simulate_campaign(tmp_path, "quick", seed=1, include_step=False, flicker_hz=f, flicker_depth=d, exposure_s=e,
                      noise_sigma_dn=0.0, **SMALL)
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["video"]["flicker_hz"] == f and truth["video"]["flicker_depth"] == d
    test = truth["tests"][0]
    level = np.array([fr.rgb[:20, :, 1].astype(float).mean() for fr in iter_frames(tmp_path / test["video"])])
    t = np.array(test["time_s"])
    rel = level / level.mean() - 1.0
    spec = np.abs(np.fft.rfft(rel * np.hanning(rel.size)))
    freqs = np.fft.rfftfreq(rel.size, 1 / 100.0)
    assert abs(freqs[np.argmax(spec[1:]) + 1] - f) <= 100.0 / rel.size
    # Least squares of the level on sin/cos at f: the lamps' amplitude and phase (drawn from the seed).
    phase = truth["video"]["flicker_phase_rad"]
    a = np.stack([np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t), np.ones_like(t)], axis=1)
    coef = np.linalg.lstsq(a, rel, rcond=None)[0]
    amp = d * np.sinc(f * e)
    assert coef[:2] == pytest.approx([amp * np.cos(phase), amp * np.sin(phase)], abs=0.01)


def test_lamps_at_the_frame_rate_look_steady_to_a_global_shutter(tmp_path):
    # 50 Hz mains, 100 Hz lamps, 100 frames/s: every frame sees the same part of the cycle.
    simulate_campaign(tmp_path, "quick", seed=1, include_step=False, flicker_hz=100.0, flicker_depth=0.3,
                      flicker_phase_rad=1.0, exposure_s=0.0025, noise_sigma_dn=0.0, **SMALL)
    simulate_campaign(tmp_path / "steady", "quick", seed=1, include_step=False, exposure_s=0.0025,
                      noise_sigma_dn=0.0, **SMALL)
    name = json.loads((tmp_path / "truth.json").read_text())["tests"][0]["video"]
    level = np.array([f.rgb[:20].astype(float).mean() for f in iter_frames(tmp_path / name)])
    steady = np.array([f.rgb[:20].astype(float).mean() for f in iter_frames(tmp_path / "steady" / name)])
    assert np.ptp(level / steady) < 0.01
    assert np.mean(level / steady) == pytest.approx(float(lamp_gain(0.0, 0.0025, 100.0, 0.3, 1.0)), abs=0.01)


def test_clutter_box_is_where_asked_with_its_colour():
    box = Clutter(colour="#8a3324", centre_px=(60.5, 40.25), size_px=(40.0, 24.0), angle_rad=0.3)
    scene = Scene.for_size(W, H, clutter=({"colour": "#30a0a0", "centre_px": (280, 30), "size_px": (20, 20),
                                           "shape": "disc"}, box))
    bg = FrameRenderer(scene, None, noise_sigma_dn=0.0).composite(0.0, 1.0)
    plain = FrameRenderer(Scene.for_size(W, H), None, noise_sigma_dn=0.0).composite(0.0, 1.0)
    want = colour_rgb("#8a3324")
    # Coverage from the blend: frame = plain + a·(colour − plain) on the box's side of the image.
    region = np.s_[0:H // 2 - 40, 0:W // 2]
    a = ((bg[region] - plain[region]) / (want - plain[region]))[..., 0]
    yy, xx = np.mgrid[region]
    assert a.sum() == pytest.approx(40.0 * 24.0, rel=1e-4)
    assert (a * xx).sum() / a.sum() == pytest.approx(60.5, abs=1e-3)
    assert (a * yy).sum() / a.sum() == pytest.approx(40.25, abs=1e-3)
    assert np.allclose(bg[40, 60], want, atol=1e-3)
    assert np.allclose(bg[30, 280], colour_rgb("#30a0a0"), atol=1e-3)
    with pytest.raises(ServoscopeError):
        Scene.for_size(W, H, clutter=({"colour": "#000000", "centre_px": (1, 1), "size_px": (0, 2)},))


@pytest.mark.parametrize("shape, aspect, var_u, var_v", [
    ("disc", None, 1 / 16, 1 / 16), ("square", None, 1 / 12, 1 / 12), ("strip", None, 16 / 12, 1 / 12),
    ("square", 2.0, 4 / 12, 1 / 12)])
def test_sticker_shape_second_moments_and_centroid(shape, aspect, var_u, var_v):
    # var_* are in units of the sticker's width (diameter) squared.
    pitch = 0.4
    # Small stickers near mid-chord, where the blade is thick enough to hold a strip.
    kw = dict(sticker_shape=shape, sticker_aspect=aspect, sticker_diameter_px=16.0, sticker_separation_px=100.0)
    scene = Scene.for_size(W, H, **kw)
    blank = Scene.for_size(W, H, **{**kw, "lead_colour": Scene().blade_colour})
    img = FrameRenderer(scene, None, noise_sigma_dn=0.0).composite(pitch, 1.0).astype(float)
    ref = FrameRenderer(blank, None, noise_sigma_dn=0.0).composite(pitch, 1.0).astype(float)
    a = (img - ref)[..., 0] / (colour_rgb(scene.lead_colour)[0] - colour_rgb(scene.blade_colour)[0])
    lead, _ = scene.sticker_centres_px(pitch)
    yy, xx = np.mgrid[0:H, 0:W]
    m = a.sum()
    cx, cy = (a * xx).sum() / m, (a * yy).sum() / m
    assert (cx, cy) == pytest.approx((lead[0], lead[1]), abs=1e-3)
    # Moments along the chord (u, rotated by the pitch) and across it.
    u = (xx - cx) * np.cos(pitch) - (yy - cy) * np.sin(pitch)
    v = -(xx - cx) * np.sin(pitch) - (yy - cy) * np.cos(pitch)
    d2 = 16.0**2
    # + 1/12 px²: a pixel's own extent (area sampling), a small correction at 16 px.
    assert (a * u * u).sum() / m == pytest.approx(var_u * d2 + 1 / 12, rel=0.01)
    assert (a * v * v).sum() / m == pytest.approx(var_v * d2 + 1 / 12, rel=0.01)


def test_shake_is_recorded_and_recovered_by_image_registration(tmp_path):
    # Textured top band (clutter boxes) so that registration has edges to lock on.
    rng = np.random.default_rng(0)
    colours = ("#8a3324", "#e0e0e0", "#202020", "#30a0a0")
    clutter = tuple({"colour": colours[k % 4], "centre_px": (float(x), float(y)), "size_px": (float(w), float(h)),
                     "angle_rad": float(a)}
                    for k, (x, y, w, h, a) in enumerate(zip(rng.uniform(10, 310, 16), rng.uniform(5, 65, 16),
                                                            rng.uniform(6, 25, 16), rng.uniform(6, 20, 16),
                                                            rng.uniform(0, 3, 16))))
    simulate_campaign(tmp_path, "quick", seed=4, include_step=False, shake_px=0.6, shake_smooth_frames=3,
                      noise_sigma_dn=0.0, clutter=clutter, **SMALL)
    truth = json.loads((tmp_path / "truth.json").read_text())
    test = truth["tests"][0]
    shake = np.array(test["shake_xy_px"])
    assert shake.std(axis=0) == pytest.approx([0.6, 0.6], rel=1e-6)
    frames = [fr.rgb for fr in iter_frames(tmp_path / test["video"])]
    grey = [cv2.cvtColor(f[:70], cv2.COLOR_RGB2GRAY).astype(np.float32) for f in frames]
    errors = []
    for i in range(1, len(frames), 5):
        # Phase correlation for a start (it is biased by up to 0.3 px between
        # whole pixels), ECC for the sub-pixel shift.
        (dx, dy), _ = cv2.phaseCorrelate(grey[0].astype(np.float64), grey[i].astype(np.float64))
        m = np.array([[1, 0, dx], [0, 1, dy]], dtype=np.float32)
        _, m = cv2.findTransformECC(grey[0], grey[i], m, cv2.MOTION_TRANSLATION,
                                    (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-6), None, 1)
        errors.append(np.hypot(m[0, 2] - (shake[i, 0] - shake[0, 0]), m[1, 2] - (shake[i, 1] - shake[0, 1])))
    assert max(errors) < 0.06
    assert np.ptp(shake, axis=0).min() > 1.0  # the shake is large enough to matter
    # The angle's truth is the blade's: the same campaign without shake has the same angles.
    simulate_campaign(tmp_path / "still", "quick", seed=4, include_step=False, noise_sigma_dn=0.0, **SMALL)
    still = json.loads((tmp_path / "still" / "truth.json").read_text())["tests"][0]
    assert still["angle_rad"] == test["angle_rad"]


def test_t0_phase_manifest_exposure_and_timestamp_options(tmp_path):
    simulate_campaign(tmp_path, "quick", seed=5, t0_frame_phase=0.3, manifest_exposure=False, timestamp_at="start",
                      **SMALL)
    truth = json.loads((tmp_path / "truth.json").read_text())
    manifest = tomllib.loads((tmp_path / "campaign.toml").read_text())
    assert "exposure_s" not in manifest["camera"] and manifest["camera"]["timestamp"] == "start"
    e = truth["video"]["exposure_s"]
    pre = get_preset("quick").pre_roll_s
    for test in truth["tests"]:
        assert test["t0_s"] == pytest.approx((round(pre * 100) + 0.3) / 100, abs=1e-12)
        mid = np.array(test["exposure_mid_s"])
        assert np.allclose(mid, np.array(test["time_s"]) + e / 2)
        # The LED goes dark in the frame whose exposure holds t0.
        led = np.array(test["led_level"])
        k = int(np.argmax(led < 1))
        assert mid[k] - e / 2 < test["t0_s"] < mid[k] + e / 2


def test_motion_blur_smears_along_the_arc_and_keeps_the_centroid():
    scene = Scene.for_size(W, H)
    r = FrameRenderer(scene, None, noise_sigma_dn=0.0)
    # 16 poses spread over 0.04 rad: the lead sticker (~150 px from the pivot) sweeps ~6 px.
    pitches = np.linspace(-0.02, 0.02, 16)
    blank = Scene.for_size(W, H, lead_colour=scene.blade_colour)
    rb = FrameRenderer(blank, None, noise_sigma_dn=0.0)
    blurred = np.mean([r.composite(float(p), 1.0).astype(float) - rb.composite(float(p), 1.0) for p in pitches], 0)
    sharp = r.composite(0.0, 1.0).astype(float) - rb.composite(0.0, 1.0)
    frame = r.render_blurred(pitches, np.ones(16), 0)
    a_blur = blurred[..., 0]
    a_sharp = sharp[..., 0]
    yy, xx = np.mgrid[0:H, 0:W]
    lead, _ = scene.sticker_centres_px(0.0)
    near = np.hypot(xx - lead[0], yy - lead[1]) < 25
    cyb = (a_blur * yy * near).sum() / (a_blur * near).sum()
    lead_all, _ = scene.sticker_centres_px(pitches)
    assert cyb == pytest.approx(lead_all[:, 1].mean(), abs=0.01)
    var_b = (a_blur * (yy - cyb) ** 2 * near).sum() / (a_blur * near).sum()
    cys = (a_sharp * yy * near).sum() / (a_sharp * near).sum()
    var_s = (a_sharp * (yy - cys) ** 2 * near).sum() / (a_sharp * near).sum()
    assert var_b - var_s == pytest.approx(np.var(lead_all[:, 1]), rel=0.05)
    # The rendered blurred frame is the rounded mean of the sub-exposure frames.
    mean_frame = np.mean([r.composite(float(p), 1.0).astype(float) for p in pitches], 0)
    assert np.abs(frame - mean_frame).max() <= 0.5 + 1e-3


def test_motion_blur_campaign_truth_is_the_exposure_averaged_pose(tmp_path):
    simulate_campaign(tmp_path / "a", "quick", seed=6, include_step=False, noise_sigma_dn=0.0, **SMALL)
    simulate_campaign(tmp_path / "b", "quick", seed=6, include_step=False, noise_sigma_dn=0.0, motion_blur=True,
                      blur_step_px=0.5, blur_max_samples=12, **SMALL)
    a = json.loads((tmp_path / "a" / "truth.json").read_text())["tests"][0]
    b = json.loads((tmp_path / "b" / "truth.json").read_text())["tests"][0]
    assert a["angle_rad"] == b["angle_rad"] and 1 < b["blur_samples"] <= 12
    fa = [f.rgb for f in iter_frames(tmp_path / "a" / a["video"])]
    fb = [f.rgb for f in iter_frames(tmp_path / "b" / b["video"])]
    assert len(fa) == len(fb) and any(not np.array_equal(x, y) for x, y in zip(fa, fb))


def test_rolling_shutter_refuses_what_it_cannot_render(tmp_path):
    for bad in ({"motion_blur": True}, {"shake_px": 0.5}):
        with pytest.raises(ServoscopeError, match="rolling shutter"):
            simulate_campaign(tmp_path, "quick", readout_s=0.005, **bad, **SMALL)
    with pytest.raises(ServoscopeError, match="timestamp_at"):
        simulate_campaign(tmp_path, "quick", timestamp_at="later", **SMALL)
    assert not (tmp_path / "campaign.toml").exists()


def test_rolling_shutter_flicker_bands_follow_the_row_times(tmp_path):
    f, d = 100.0, 0.3
    simulate_campaign(tmp_path, "quick", seed=1, include_step=False, readout_s=0.008, exposure_s=0.002,
                      flicker_hz=f, flicker_depth=d, noise_sigma_dn=0.0, **SMALL)
    truth = json.loads((tmp_path / "truth.json").read_text())["tests"][0]
    frame = next(iter(iter_frames(tmp_path / truth["video"]))).rgb
    simulate_campaign(tmp_path / "steady", "quick", seed=1, include_step=False, readout_s=0.008, exposure_s=0.002,
                      noise_sigma_dn=0.0, **SMALL)
    steady = next(iter(iter_frames(tmp_path / "steady" / truth["video"]))).rgb
    # The left edge is background only near the top and the bottom.
    rows = np.r_[0:60, H - 60:H]
    ratio = frame[rows, :20].astype(float).mean(axis=(1, 2)) / steady[rows, :20].astype(float).mean(axis=(1, 2))
    phase = json.loads((tmp_path / "truth.json").read_text())["video"]["flicker_phase_rad"]
    want = lamp_gain(truth["time_s"][0] + 0.008 * rows / H, 0.002, f, d, phase)
    assert np.abs(ratio - want).max() < 0.02  # 8-bit rounding: 1 DN in ~100
    assert np.ptp(want) > 0.3  # the band is there to see


def test_simulate_cli_passes_the_options_and_refuses_bad_combinations(tmp_path):
    from click.testing import CliRunner

    from servoscope.cli import cli

    runner = CliRunner()
    out = tmp_path / "c"
    res = runner.invoke(cli, ["simulate", str(out), "--preset", "quick", "--codec", "raw", "--flicker-hz", "100",
                              "--flicker-depth", "0.2", "--t0-phase", "0.25", "--no-manifest-exposure",
                              "--timestamp-at", "end", "--sticker-shape", "square"])
    assert res.exit_code == 0, res.output
    truth = json.loads((out / "truth.json").read_text())
    manifest = tomllib.loads((out / "campaign.toml").read_text())
    assert truth["video"]["flicker_hz"] == 100.0 and truth["video"]["flicker_depth"] == 0.2
    assert truth["video"]["t0_frame_phase"] == 0.25 and truth["video"]["timestamp_at"] == "end"
    assert manifest["camera"] == {"calibration": "camera.json", "timestamp": "end"}
    res = runner.invoke(cli, ["simulate", str(tmp_path / "bad"), "--preset", "quick", "--readout", "0.005",
                              "--shake", "0.5"])
    assert res.exit_code != 0 and "rolling shutter" in str(res.exception or res.output)
    assert not (tmp_path / "bad").exists()


def test_render_clip_takes_flicker_and_shake_and_occludes_shaped_stickers(tmp_path):
    from servoscope.simulate.clips import Occluder, render_clip

    scene = Scene.for_size(W, H, sticker_shape="strip", sticker_diameter_px=10.0)
    lead, _ = scene.sticker_centres_px(0.0)
    # Hides the strip's left half (its length 40 px along x at pitch 0), still from frame to frame.
    occ = Occluder("#101010", (lead[1] - 30, lead[1] + 30), 60.0, lead[0] - 60, lead[0] - 60)
    n = 6
    shake = np.stack([np.linspace(0, 1.5, n), np.zeros(n)], axis=1)
    truth = render_clip(tmp_path / "c.avi", scene, np.zeros(n), codec="raw", noise_sigma_dn=0.0, occluder=occ,
                        lamp_gain=np.linspace(0.8, 1.2, n), shake_xy_px=shake)
    assert np.allclose(truth["lead_hidden"], 0.5, atol=0.03) and np.all(truth["trail_hidden"] == 0)
    assert np.array_equal(truth["shake_xy_px"], shake)
    render_clip(tmp_path / "s.avi", scene, np.zeros(n), codec="raw", noise_sigma_dn=0.0, occluder=occ,
                shake_xy_px=shake)
    top = np.array([f.rgb[:20, 200:].astype(float).mean() for f in iter_frames(tmp_path / "c.avi")])
    steady = np.array([f.rgb[:20, 200:].astype(float).mean() for f in iter_frames(tmp_path / "s.avi")])
    assert np.allclose(top / steady, np.linspace(0.8, 1.2, n), atol=0.005)
    with pytest.raises(ServoscopeError):
        render_clip(tmp_path / "d.avi", scene, np.zeros(n), codec="raw", lamp_gain=np.ones(n + 1))
