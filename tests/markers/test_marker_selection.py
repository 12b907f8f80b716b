"""Choosing the markers as a person would; tracking that light, shake and clutter do not fool.

Scenes are the twin's frames edited as a workshop would edit them: a larger
red-brown box of nearly the lead sticker's hue, lamps flickering at 100 Hz,
a second sticker-like disc, a camera that shakes, two coloured things that
are not on one rigid blade. The truth is the twin's sticker centres (moved
with the shake where there is one).
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from servoscope.errors import ServoscopeError
from servoscope.pipeline import TrackerSettings, track_video
from servoscope.markers.illumination import GlobalGain
from servoscope.markers.selection import parse_marker_spec
from servoscope.simulate import Scene
from servoscope.simulate.render import FrameRenderer
from servoscope.simulate.scene import marker_angle_rad
from servoscope.video.writer import VideoWriter

from support import cli

W, H = 480, 384
BOX_RGB = (160, 48, 42)  # red-brown: the lead sticker's hue (#d62728) within 4°


def _clip(path: Path, *, n: int = 120, fps: float = 200.0, box: bool = False, box_rgb=BOX_RGB, flicker: float = 0.0,
          flicker_phase: float = math.pi / 2, shake_px: float = 0.0, decoy: tuple[float, float] | None = None,
          seed: int = 0) -> np.ndarray:
    """Render a sine of the blade, edit each frame, encode H.264; return the true angle per frame.

    ``flicker``: every frame scaled by 1 + flicker·sin(2π·100·t + phase) (at 200 frames/s
    and phase π/2 the frames alternate bright and dim, the issue's case). ``shake_px``: each
    frame translated by a seeded Gaussian (σ per axis), the truth moved with it. ``decoy``:
    a disc of the lead sticker's colour and size drawn there.
    """
    scene = Scene.for_size(W, H, background_seed=1)
    t = np.arange(n) / fps
    pitch = 0.05 * np.sin(2 * np.pi * 1.5 * t)
    renderer = FrameRenderer(scene, noise_sigma_dn=1.5, noise_seed=seed)
    lead, trail = scene.sticker_centres_px(pitch)
    rng = np.random.default_rng(seed)
    radius = scene.sticker_diameter_px / 2.0
    with VideoWriter(path, W, H, fps, codec="h264", bit_rate=20_000_000) as writer:
        for i in range(n):
            f = renderer.render(float(pitch[i]), 1.0, i).astype(np.float64)
            if box:
                # Larger than a sticker, in the top-right corner, touching the border.
                cv2.rectangle(f, (W - 70, 0), (W - 1, 45), box_rgb, -1)
            if decoy is not None:
                cv2.circle(f, (int(decoy[0] * 16), int(decoy[1] * 16)), int(radius * 16), (214, 39, 40), -1,
                           cv2.LINE_AA, shift=4)
            if flicker:
                f *= 1.0 + flicker * math.sin(2 * math.pi * 100.0 * t[i] + flicker_phase)
            if shake_px:
                dx, dy = rng.normal(0.0, shake_px, 2)
                f = cv2.warpAffine(f, np.float32([[1, 0, dx], [0, 1, dy]]), (W, H), flags=cv2.INTER_CUBIC,
                                   borderMode=cv2.BORDER_REFLECT)
                lead[i] += (dx, dy)
                trail[i] += (dx, dy)
            writer.write(np.clip(np.round(f), 0, 255).astype(np.uint8))
    return marker_angle_rad(lead, trail)


def _run(capsys, *args) -> tuple[int, str]:
    """Run the command line in-process: (exit status, what it printed)."""
    code, out, err = cli(capsys, *args)
    return code, out + err


def _rms_deg(track, truth) -> float:
    err = np.degrees(np.angle(np.exp(1j * (track.angle_rad - truth))))[track.valid]
    return float(np.sqrt(np.mean(err**2)))


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    d = tmp_path_factory.mktemp("sel")
    out = {}
    for name, kw in {
        "clean": {},
        "box_flicker": {"box": True, "flicker": 0.08},
        "flicker240": {"flicker": 0.08, "fps": 240.0, "flicker_phase": 0.0},
        "decoy": {"decoy": (60.0, 330.0)},
        "shake": {"shake_px": 0.3},
    }.items():
        out[name] = (d / f"{name}.mp4", _clip(d / f"{name}.mp4", **kw))
    return out


# -- 1. the first detection weighs colour, size, shape and the border --------------------------
def test_box_and_100hz_flicker_every_frame_valid_and_accurate(clips):
    """The issue's scene: a larger box of the lead's hue at the border and 8 % flicker at 100 Hz.

    Before: the box was taken for the lead marker (0 valid frames); with flicker alone, half
    the frames were "partly hidden". Now every frame is valid and the angle within target.
    """
    path, truth = clips["box_flicker"]
    tr = track_video(path, TrackerSettings(led=None))
    assert tr.valid.all(), set(tr.reason)
    assert _rms_deg(tr, truth) < 0.01
    assert any("illumination varied" in w for w in tr.warnings)
    clean = track_video(clips["clean"][0], TrackerSettings(led=None))
    # The box and flicker cost no accuracy: at most 0.002° worse than the clean clip.
    assert _rms_deg(tr, truth) < _rms_deg(clean, clips["clean"][1]) + 0.002


def test_flicker_at_240_fps_never_invalid(clips):
    """Flicker at 100 Hz filmed at 240 frames/s: every gain between 0.92 and 1.08 occurs."""
    path, truth = clips["flicker240"]
    tr = track_video(path, TrackerSettings(led=None))
    assert tr.valid.all(), set(tr.reason)
    assert _rms_deg(tr, truth) < 0.01


def test_global_gain_recovers_a_scaled_frame():
    rng = np.random.default_rng(3)
    base = rng.uniform(40, 220, (384, 480))
    gain = GlobalGain()
    assert gain(np.round(base).astype(np.uint8)) == 1.0  # the reference
    for g in (0.85, 0.92, 1.0, 1.07):
        frame = 16.0 + g * (base - 16.0) + rng.normal(0, 1.5, base.shape)
        # A moving object over a third of the grid must not move the median.
        frame[:, :150] = rng.uniform(0, 255, (384, 150))
        assert gain(np.clip(np.round(frame), 0, 255).astype(np.uint8)) == pytest.approx(g, abs=0.004)


def test_close_call_warns_naming_both_candidates(clips):
    path, truth = clips["decoy"]
    tr = track_video(path, TrackerSettings(led=None))
    close = [w for w in tr.warnings if "close call" in w]
    assert close and close[0].startswith("lead marker")
    # Both named by colour, position and size, and how to pin the other.
    assert close[0].count(" px") >= 2 and "(60, 330)" in close[0] and "near = [" in close[0] and "@" in close[0]


def test_pinned_marker_is_the_blob_there(clips):
    path, truth = clips["decoy"]
    scene = Scene.for_size(W, H, background_seed=1)
    lead0, trail0 = scene.sticker_centres_px(0.0)
    tr = track_video(path, TrackerSettings(led=None, lead_near=(float(lead0[0]) + 2, float(lead0[1]) - 1)))
    assert tr.valid.all()
    assert not any("close call" in w for w in tr.warnings)  # the user chose: no warning
    assert np.hypot(*(tr.lead_xy_px[0] - lead0)) < 1.0
    assert _rms_deg(tr, truth) < 0.01


def test_cli_pin_parses_and_bad_pins_exit_2_writing_nothing(clips, tmp_path, capsys):
    path, _ = clips["clean"]
    assert parse_marker_spec("#d62728@12.5,30") == ("#d62728", (12.5, 30.0))
    assert parse_marker_spec("red") == ("red", None)
    out = tmp_path / "t.csv"
    # Where there is no red blob at all.
    code, text = _run(capsys, "track", path, "--led", "none", "--lead", "#d62728@20,20", "--out", out)
    assert code == 2 and not out.exists() and text.startswith("servoscope: error: ") and text.count("\n") == 1
    assert str(path) in text and "pinned at (20, 20)" in text and "nearest blob" in text
    # Both markers pinned to the same blob (one colour for both).
    scene = Scene.for_size(W, H, background_seed=1)
    lead0, _ = scene.sticker_centres_px(0.0)
    at = f"{lead0[0]:.1f},{lead0[1]:.1f}"
    code, text = _run(capsys, "track", path, "--led", "none", "--lead", f"#d62728@{at}", "--trail", f"#d62728@{at}",
                      "--out", out)
    assert code == 2 and not out.exists() and "same blob" in text and str(path) in text
    code, text = _run(capsys, "track", path, "--led", "none", "--lead", "#d62728@x,3", "--out", out)
    assert code == 2 and not out.exists() and "--lead" in text


def test_manifest_pin(tmp_path):
    from servoscope.campaign.manifest import load_campaign

    toml = tmp_path / "campaign.toml"
    toml.write_text('[markers]\nlead = {colour = "#d62728", near = [120, 45.5]}\ntrail = "#2ca02c"\n'
                    '[input]\n[[tests]]\nvideo = "a.mp4"\nkind = "step"\namplitude = 0.2\n')
    c = load_campaign(toml, check_videos=False)
    assert c.lead == "#d62728" and c.lead_near == (120.0, 45.5) and c.trail_near is None
    toml.write_text('[markers]\nlead = {colour = "#d62728", near = [-1, 4]}\ntrail = "#2ca02c"\n'
                    '[input]\n[[tests]]\nvideo = "a.mp4"\nkind = "step"\namplitude = 0.2\n')
    with pytest.raises(ServoscopeError, match=r"campaign.toml: markers.lead.near: .*>= 0"):
        load_campaign(toml, check_videos=False)


# -- 4. two stickers on one rigid part keep their distance ----------------------------------------
def test_things_that_are_not_on_one_rigid_part_end_in_a_clear_error(tmp_path, capsys):
    """A red and a green thing walking about (people's clothing): no track, exit 2."""
    n, fps = 60, 25
    path = tmp_path / "walk.mp4"
    rng = np.random.default_rng(5)
    texture = cv2.GaussianBlur(rng.uniform(60, 180, (H, W)), (0, 0), 3)
    with VideoWriter(path, W, H, fps, codec="h264", bit_rate=8_000_000) as writer:
        for i in range(n):
            f = np.repeat(texture[..., None], 3, axis=2)
            cv2.ellipse(f, (60 + 5 * i, 200), (14, 30), 0, 0, 360, (200, 30, 35), -1, cv2.LINE_AA)
            cv2.ellipse(f, (420 - 3 * i, 150 + i), (12, 28), 0, 0, 360, (40, 160, 45), -1, cv2.LINE_AA)
            writer.write(np.clip(f, 0, 255).astype(np.uint8))
    with pytest.raises(ServoscopeError, match="not two stickers on one rigid part"):
        track_video(path, TrackerSettings(led=None))
    out = tmp_path / "walk.csv"
    code, text = _run(capsys, "track", path, "--led", "none", "--out", out)
    assert code == 2 and not out.exists() and str(path) in text and "rigid" in text


# -- 6. measured angle noise, with and without camera shake ---------------------------------------
@pytest.mark.parametrize("name", ["clean", "shake"])
def test_measured_angle_noise_within_1p5_of_true_error(clips, name, tmp_path, capsys):
    path, truth = clips[name]
    tr = track_video(path, TrackerSettings(led=None))
    err = np.angle(np.exp(1j * (tr.angle_rad - truth)))[tr.valid]
    true_rad = float(np.std(err))
    s = tr.summary()
    assert 1 / 1.5 < s["angle_noise_measured_rad"] / true_rad < 1.5
    if name == "shake":
        assert s["camera_shake_px"] == pytest.approx(0.3, rel=0.3)
        code, text = _run(capsys, "track", path, "--led", "none", "--out", tmp_path / "s.csv")
        assert code == 0 and "camera shake 0.3" in text
    else:
        assert s["camera_shake_px"] == 0.0


# -- 5. the LED beside a sticker of a neighbouring hue ------------------------------------------
def test_yellow_led_beside_an_orange_sticker_is_found(tmp_path):
    """The issue's third campaign: orange and violet stickers, the yellow LED on the blade.

    The LED's hue band reaches the orange sticker's, which is larger: it was taken for the LED
    ("LED brightness does not change"). With the markers' disks masked out, the LED is found
    and its switch time is the twin's (frame 40 at 100 frames/s lit for 0.3 of its exposure).
    """
    from servoscope.simulate.clips import render_clip

    scene = Scene.for_size(W, H, background_seed=1, lead_colour="#ff7f0e", trail_colour="#9467bd")
    n = 80
    led = np.r_[np.ones(40), 0.3, np.zeros(n - 41)]
    render_clip(tmp_path / "led.mp4", scene, 0.03 * np.sin(np.arange(n) / 8.0), fps=100, led_level=led)
    tr = track_video(tmp_path / "led.mp4", TrackerSettings("#ff7f0e", "#9467bd", "#ffd400"))
    assert tr.valid.all() and not tr.warnings
    assert tr.t0_s == pytest.approx(0.40 - 0.005 + 0.3 * 0.01, abs=3 * tr.t0_uncertainty_s + 1e-4)


# -- 3. stickers that are not discs ------------------------------------------------------------
def _shaped_clip(path: Path, half_u: float, half_v: float, n: int = 120, fps: float = 200.0) -> np.ndarray:
    """The twin's blade with rectangular stickers (exact area coverage) turning with it; the true angle."""
    from servoscope.simulate.render import polygon_coverage
    from servoscope.simulate.scene import colour_rgb

    # The twin's own stickers shrunk to a 1 px dot, under the rectangle drawn over it.
    scene = Scene.for_size(W, H, background_seed=1, sticker_diameter_px=1.0)
    pitch = 0.05 * np.sin(2 * np.pi * 1.5 * np.arange(n) / fps)
    renderer = FrameRenderer(scene, noise_sigma_dn=1.5, noise_seed=0)
    lead, trail = scene.sticker_centres_px(pitch)
    truth = marker_angle_rad(lead, trail)
    with VideoWriter(path, W, H, fps, codec="h264", bit_rate=20_000_000) as writer:
        for i in range(n):
            f = renderer.render(float(pitch[i]), 1.0, i)
            e = np.array([math.cos(truth[i]), -math.sin(truth[i])])  # along the markers' line (y down)
            nrm = np.array([-e[1], e[0]])
            for c, colour in ((lead[i], scene.lead_colour), (trail[i], scene.trail_colour)):
                pts = np.array([c + su * half_u * e + sv * half_v * nrm for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
                cov, x0, y0 = polygon_coverage(pts, (W, H))
                region = f[y0:y0 + cov.shape[0], x0:x0 + cov.shape[1]].astype(np.float64)
                region += cov[..., None] * (colour_rgb(colour) - region)
                f[y0:y0 + cov.shape[0], x0:x0 + cov.shape[1]] = np.clip(np.round(region), 0, 255).astype(np.uint8)
            writer.write(f)
    return truth


@pytest.mark.parametrize("shape, half_u, half_v", [("square", 7.65, 7.65), ("strip", 17.0, 5.1)])
def test_square_and_strip_stickers_track(tmp_path, shape, half_u, half_v):
    """Rectangles turning with the blade: measured with a support that follows their outline.

    With the round support a strip's support took in the blade's edge beside it: 0.196° RMS
    (the square: 0.0112°); with the rectangle's, 0.0088° (0.0087°), every frame valid.
    """
    truth = _shaped_clip(tmp_path / f"{shape}.mp4", half_u, half_v)
    tr = track_video(tmp_path / f"{shape}.mp4", TrackerSettings(led=None))
    assert tr.valid.all(), set(tr.reason)
    assert _rms_deg(tr, truth) < 0.01


@pytest.mark.parametrize("fields", [(0, 1), (1, 2)])
def test_rectangle_support_numpy_and_numba_agree(fields):
    from servoscope.markers import kernels as K
    from support import kernel_frame as _frame, kernel_params as _params, run_kernel as _run

    i420 = _frame(1)
    params = _params(i420)
    params[:, K.P.RECT] = 1.0
    params[:, K.P.HALF_U], params[:, K.P.HALF_V] = (9.0, 8.0), (6.0, 5.0)
    params[:, K.P.COS], params[:, K.P.SIN] = math.cos(0.4), math.sin(0.4)
    params[:, K.P.RECT_MARGIN] = 2.0
    params[:, K.P.RADIUS] = np.hypot(params[:, K.P.HALF_U], params[:, K.P.HALF_V]) + 2.0
    if fields[1] == 2:
        params[:, K.P.Y0] //= 2
        params[:, K.P.Y1] //= 2
    led = np.array([1.0, 0.3, -0.05, 4.0])
    a, _ = _run("numpy", i420, params, led, *fields)
    b, _ = _run("numba", i420, params, led, *fields)
    assert a[:, K.Q.M00].min() > 10
    np.testing.assert_allclose(b, a, rtol=1e-9, atol=1e-9)
    # The rectangles contain the test's disks (radii 9 and 8 px): the same centroids as the round support.
    disk, _ = _run("numba", i420, _params(i420), led, *fields)
    np.testing.assert_allclose(b[:, [K.Q.X, K.Q.Y]], disk[:, [K.Q.X, K.Q.Y]], atol=0.05)


def test_campaign_warns_when_the_led_is_found_in_some_videos_only(tmp_path):
    from servoscope.campaign.manifest import load_campaign
    from servoscope.campaign.runner import led_coverage_warning
    from servoscope.simulate.clips import render_clip

    scene = Scene.for_size(320, 256, background_seed=1)
    n = 40
    render_clip(tmp_path / "a.mp4", scene, np.zeros(n), led_level=np.r_[np.ones(20), np.zeros(n - 20)])
    render_clip(tmp_path / "b.mp4", scene, np.zeros(n))  # its LED never switches off
    render_clip(tmp_path / "c.mp4", scene, np.zeros(n), led_level=np.r_[np.ones(25), np.zeros(n - 25)])
    toml = tmp_path / "campaign.toml"
    toml.write_text('[markers]\nlead = "#d62728"\ntrail = "#2ca02c"\nled = "#ffd400"\n[input]\n'
                    + "".join(f'[[tests]]\nvideo = "{v}.mp4"\nkind = "sine"\nfrequency_hz = {f}\namplitude = 0.1\n'
                              for v, f in (("a", 1.0), ("b", 2.0), ("c", 3.0))))
    campaign = load_campaign(toml)
    tracks = {t.label: track_video(t.video, TrackerSettings()) for t in campaign.tests}
    assert [tracks[t.label].t0_s is None for t in campaign.tests] == [False, True, False]
    warning = led_coverage_warning(campaign, tracks)
    assert warning.startswith("LED found in 2 of 3 videos but not in 1: ") and campaign.tests[1].label in warning
    # Found everywhere (or nowhere): nothing to say.
    assert led_coverage_warning(campaign, {k: v for k, v in tracks.items() if v.t0_s is not None}) is None


def test_scores_prefer_solid_whole_blobs_of_the_other_markers_size():
    """Candidates on a drawn frame: the disc wins over a larger box at the border, a larger
    solid box away from it (size against the other marker's) and a ring (solidity)."""
    from servoscope.markers.colour import ColourModel
    from servoscope.markers.selection import choose_markers, marker_candidates

    img = np.full((240, 360, 3), 90, np.uint8)
    red, green = (214, 39, 40), (44, 160, 44)
    cv2.circle(img, (100, 150), 8, red, -1, cv2.LINE_AA)  # the lead sticker
    cv2.circle(img, (300, 160), 8, green, -1, cv2.LINE_AA)  # the trail sticker
    cv2.rectangle(img, (300, 0), (359, 40), (160, 48, 42), -1)  # a box at the border
    cv2.rectangle(img, (150, 40), (190, 70), red, -1)  # a larger box, inside
    cv2.circle(img, (60, 60), 12, red, 4, cv2.LINE_AA)  # a ring: the size of a sticker, not solid
    lead_m = ColourModel.from_seed((214.0, 39.0, 40.0))
    trail_m = ColourModel.from_seed((44.0, 160.0, 44.0))
    lead = marker_candidates(img, lead_m, lead_m.hue)
    trail = marker_candidates(img, trail_m, trail_m.hue)
    assert len(lead) == 4 and len(trail) == 1
    ring = min(lead, key=lambda c: c.solidity)
    assert (round(ring.x_px), round(ring.y_px)) == (60, 60) and ring.solidity < 0.7
    assert sum(c.touches_border for c in lead) == 1
    choice = choose_markers(lead, trail)
    assert (round(choice.lead.x_px), round(choice.lead.y_px)) == (100, 150)
    assert not choice.warnings
    # Pinned to the box instead: it is taken (the user knows), and no close call is reported.
    pinned = choose_markers(lead, trail, lead_near=(170.0, 55.0))
    assert (round(pinned.lead.x_px), round(pinned.lead.y_px)) == (170, 55) and not pinned.warnings


def test_auto_colours_pick_the_sticker_pair_not_a_big_box(tmp_path):
    """Markers "auto": a large blue box (a third, distinct hue) used to be one of the two colours."""
    truth = _clip(tmp_path / "blue.mp4", n=30, box=True, box_rgb=(30, 70, 200))
    tr = track_video(tmp_path / "blue.mp4", TrackerSettings(lead="auto", trail="auto", led=None))
    scene = Scene.for_size(W, H, background_seed=1)
    lead0, trail0 = scene.sticker_centres_px(0.05 * np.sin(0.0))
    assert tr.valid.all()
    assert np.hypot(*(tr.lead_xy_px[0] - lead0)) < 0.5 and np.hypot(*(tr.trail_xy_px[0] - trail0)) < 0.5
    assert _rms_deg(tr, truth) < 0.015  # 30 frames: the given colours' track gets 0.010°


def test_a_camera_off_square_is_still_one_rigid_blade(tmp_path):
    """A view 25° off square foreshortens the separation with the blade's angle (362–373 px over
    ±0.5 rad): rigid all the same, every frame valid (a constant separation refused the track)."""
    n, k = 120, math.cos(math.radians(25.0))
    scene = Scene.for_size(W, H, background_seed=1)
    pitch = 0.5 * np.sin(2 * np.pi * np.arange(n) / n)
    renderer = FrameRenderer(scene, noise_sigma_dn=1.5)
    squeeze = np.float32([[k, 0, (1 - k) * W / 2], [0, 1, 0]])  # the affine view of a turned camera
    lead, trail = scene.sticker_centres_px(pitch)
    for xy in (lead, trail):
        xy[:, 0] = k * xy[:, 0] + (1 - k) * W / 2
    with VideoWriter(tmp_path / "tilt.mp4", W, H, 100, codec="h264", bit_rate=20_000_000) as writer:
        for i in range(n):
            writer.write(cv2.warpAffine(renderer.render(float(pitch[i]), 1.0, i), squeeze, (W, H),
                                        flags=cv2.INTER_CUBIC, borderMode=cv2.BORDER_REFLECT))
    assert np.ptp(np.hypot(*(lead - trail).T)) > 10.0
    tr = track_video(tmp_path / "tilt.mp4", TrackerSettings(led=None))
    assert tr.valid.all(), set(tr.reason)
    assert _rms_deg(tr, marker_angle_rad(lead, trail)) < 0.01


def test_markers_command_shows_solidity_and_border(clips, capsys):
    path, _ = clips["box_flicker"]
    code, text = _run(capsys, "markers", path)
    assert code == 0
    rows = [line for line in text.splitlines() if line.startswith("│")]
    box = next(r for r in rows if r.rstrip("│ ").endswith("yes"))  # the box: solid but at the border
    assert " 1.00 " in box or " 0.99 " in box
    assert "--lead '#rrggbb@x,y'" in text
