"""What real cameras write: HEVC, 10-bit, 4:2:2, full-range YUV, BT.709, rotation, variable frame rate.

Every file here is made by servoscope's writer with real FFmpeg encoders
(libx264 / libx265 through PyAV) and read back by the reader. The oracle is
the standard equations (BT.601 / BT.709, H.273 quantisation) evaluated in
float64 on the source RGB, independently of the code under test.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import av
import numpy as np
import pytest

from servoscope.errors import ServoscopeError
from servoscope.pipeline import TrackerSettings, track_video
from servoscope.simulate import Scene
from servoscope.simulate.render import FrameRenderer
from servoscope.simulate.scene import marker_angle_rad
from servoscope.video.colour import layout_of_format, to_i420_bt601, to_rgb
from servoscope.video.reader import iter_frames, iter_yuv_frames, probe_video
from servoscope.video.writer import VideoWriter

needs_x265 = pytest.mark.skipif("libx265" not in av.codecs_available, reason="PyAV's FFmpeg has no libx265")

#: Patch colours: the twin's stickers and LED, saturated primaries, greys, near-black and white.
COLOURS = ["#d62728", "#2ca02c", "#ffd400", "#1f77b4", "#ff7f0e", "#9467bd", "#808080", "#ffffff",
           "#101010", "#00ff00", "#ff0000", "#0000ff"]
W, H = 256, 192
PATCH = 64

#: (codec, pix_fmt, color_range, matrix): the formats under test.
FORMATS = [
    ("h264", "yuv420p", None, None),            # the twin's default
    ("hevc", "yuv420p", None, None),
    ("h264", "yuv420p", "pc", None),            # full-range (JPEG) YUV
    ("h264", "yuv420p", "tv", "bt709"),         # an HD camcorder's
    ("h264", "yuv420p10le", None, None),
    ("h264", "yuv422p", None, None),
    ("hevc", "yuv422p10le", None, None),
    ("hevc", "yuv420p", "pc", "bt709"),         # a phone's
    ("hevc", "yuv422p10le", "pc", "bt709"),
]


def _rgb(colour: str) -> np.ndarray:
    return np.array([int(colour[i:i + 2], 16) for i in (1, 3, 5)], np.float64)


def _patches() -> np.ndarray:
    img = np.zeros((H, W, 3), np.uint8)
    for k, colour in enumerate(COLOURS):
        r, c = divmod(k, W // PATCH)
        img[r * PATCH:(r + 1) * PATCH, c * PATCH:(c + 1) * PATCH] = _rgb(colour)
    return img


def _centres():
    for k in range(len(COLOURS)):
        r, c = divmod(k, W // PATCH)
        yield r * PATCH + PATCH // 2, c * PATCH + PATCH // 2


def _bt601_tv(rgb: np.ndarray) -> np.ndarray:
    """The oracle: exact (unrounded) 8-bit limited-range BT.601 Y, Cb, Cr of an RGB colour."""
    r, g, b = rgb / 255.0
    y = 0.299 * r + 0.587 * g + 0.114 * b
    return np.array([16 + 219 * y, 128 + 224 * (b - y) / 1.772, 128 + 224 * (r - y) / 1.402])


@pytest.mark.parametrize("pix_fmt,color_range,colorspace", [
    ("yuv420p", 2, 1), ("yuv422p10le", 1, 1), ("yuv422p10le", 2, 5), ("yuv444p", 1, 9), ("yuvj420p", 0, 2),
])
def test_conversion_is_the_standard_equations(pix_fmt, color_range, colorspace):
    # Random code values straight into the converter (no codec): every output sample is the
    # float64 oracle's value, rounded (float32 arithmetic inside: 1e-3 DN of slack).
    layout = layout_of_format(pix_fmt, color_range, colorspace)
    fx, fy = layout.factors
    n = layout.bit_depth
    rng = np.random.default_rng(7)
    h, w = 34, 46
    y = rng.integers(0, 2 ** n, (h, w)).astype(np.uint8 if n == 8 else np.uint16)
    u = rng.integers(0, 2 ** n, (h // fy, w // fx)).astype(y.dtype)
    v = rng.integers(0, 2 ** n, (h // fy, w // fx)).astype(y.dtype)
    kr, kb = {1: (0.2126, 0.0722), 9: (0.2627, 0.0593)}.get(colorspace, (0.299, 0.114))
    full = layout.full_range
    top = 2 ** n - 1
    sy = top if full else 219 * 2 ** (n - 8)
    sc = top if full else 224 * 2 ** (n - 8)
    yf, uf, vf = (a.astype(np.float64) for a in (y, u, v))
    e_y = (yf - (0 if full else 16 * 2 ** (n - 8))) / sy
    centre = 2 ** (n - 1)
    pb = np.repeat(np.repeat((uf - centre) / sc, fy, 0), fx, 1)
    pr = np.repeat(np.repeat((vf - centre) / sc, fy, 0), fx, 1)
    r = e_y + 2 * (1 - kr) * pr
    b = e_y + 2 * (1 - kb) * pb
    g = (e_y - kr * r - kb * b) / (1 - kr - kb)
    want_rgb = np.stack([r, g, b], -1) * 255
    got_rgb = to_rgb(y, u, v, layout)
    exact = np.clip(want_rgb, 0, 255)
    assert np.abs(got_rgb - exact).max() <= 0.5 + 1e-3
    # BT.601 limited range of the same R'G'B', chroma the mean of each 2×2 block.
    y601 = 0.299 * r + 0.587 * g + 0.114 * b
    want = [16 + 219 * y601, 128 + 224 * (b - y601) / 1.772, 128 + 224 * (r - y601) / 1.402]
    i420 = to_i420_bt601(y, u, v, layout)
    got_y = i420[:h]
    chroma = i420[h:].reshape(2, h // 2, w // 2)
    assert np.abs(got_y - np.clip(want[0], 0, 255)).max() <= 0.5 + 1e-3
    for k in (1, 2):
        block = want[k].reshape(h // 2, 2, w // 2, 2).mean(axis=(1, 3))
        assert np.abs(chroma[k - 1] - np.clip(block, 0, 255)).max() <= 0.5 + 1e-3


def _write(path, frames, fps=100, **kw) -> list[float]:
    h, w = frames[0].shape[:2]
    with VideoWriter(path, w, h, fps, **kw) as writer:
        return [writer.write(f) for f in frames]


def _needs(codec):
    if codec == "hevc" and "libx265" not in av.codecs_available:
        pytest.skip("PyAV's FFmpeg has no libx265")


@pytest.fixture(scope="module")
def patch_videos(tmp_path_factory):
    folder = tmp_path_factory.mktemp("formats")
    img = _patches()
    out = {}
    for fmt in FORMATS:
        if fmt[0] == "hevc" and "libx265" not in av.codecs_available:
            continue
        codec, pix_fmt, rng, matrix = fmt
        path = folder / f"{codec}_{pix_fmt}_{rng}_{matrix}.mp4"
        _write(path, [img] * 3, codec=codec, pix_fmt=pix_fmt, color_range=rng, matrix=matrix, bit_rate=40_000_000)
        out[fmt] = path
    return img, out


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: "-".join(str(x) for x in f))
def test_the_stream_says_what_was_written(patch_videos, fmt):
    _needs(fmt[0])
    codec, pix_fmt, rng, matrix = fmt
    info = probe_video(patch_videos[1][fmt])
    assert info.codec == codec
    assert info.bit_depth == (10 if "10" in pix_fmt else 8)
    assert info.chroma_subsampling == ("4:2:2" if "422" in pix_fmt else "4:2:0")
    assert info.color_range == (rng or "tv")
    assert info.matrix == (matrix or "bt601")
    assert (info.width, info.height, info.rotation_deg) == (W, H, 0)


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: "-".join(str(x) for x in f))
def test_yuv_the_trackers_get_is_8bit_420_tv_bt601_of_the_source(patch_videos, fmt):
    # Whatever the file's bits, subsampling, range and matrix, the planes are the source colours'
    # limited-range BT.601 values: within a rounding (0.5 DN, twice: the file's, then the reader's)
    # plus the codec's residue on a flat patch.
    _needs(fmt[0])
    frame = next(iter(iter_yuv_frames(patch_videos[1][fmt])))
    assert frame.y.dtype == np.uint8 and frame.y.shape == (H, W) and frame.u.shape == (H // 2, W // 2)
    worst = 0.0
    for (cy, cx), colour in zip(_centres(), COLOURS):
        want = _bt601_tv(_rgb(colour))
        got = [frame.y[cy - 16:cy + 16, cx - 16:cx + 16].mean(),
               frame.u[cy // 2 - 8:cy // 2 + 8, cx // 2 - 8:cx // 2 + 8].mean(),
               frame.v[cy // 2 - 8:cy // 2 + 8, cx // 2 - 8:cx // 2 + 8].mean()]
        worst = max(worst, float(np.abs(np.array(got) - want).max()))
    print(f"{fmt}: worst patch Y/Cb/Cr error {worst:.2f} DN")
    assert worst <= 1.05


@pytest.mark.parametrize("fmt", FORMATS, ids=lambda f: "-".join(str(x) for x in f))
def test_rgb_is_the_source_colour(patch_videos, fmt):
    _needs(fmt[0])
    img, videos = patch_videos
    rgb = next(iter(iter_frames(videos[fmt]))).rgb
    assert rgb.shape == (H, W, 3)
    err = max(float(np.abs(rgb[cy - 16:cy + 16, cx - 16:cx + 16].mean(axis=(0, 1)) - img[cy, cx]).max())
              for cy, cx in _centres())
    print(f"{fmt}: worst patch RGB error {err:.2f} DN")
    # 3 DN: libswscale's fixed-point path, kept for the twin's untagged 8-bit 4:2:0 (bit-identical
    # reading). The other layouts are converted by the standard equations: what is left is the
    # file's own quantisation, up to 2 DN at 8 bits limited range (half a code of Cr is 0.8 DN of R),
    # 1 DN at 8 bits full range or 10 bits (and a hundredth of a DN of codec residue on the patch).
    if fmt[1:] == ("yuv420p", None, None):
        tolerance = 3.0
    elif "10" not in fmt[1] and fmt[2] != "pc":
        tolerance = 2.0
    else:
        tolerance = 1.05
    assert err <= tolerance


def _asymmetric() -> np.ndarray:
    # A red block at the top-left corner and a green bar along the bottom: each rotation moves them apart.
    img = np.full((H, W, 3), 40, np.uint8)
    img[8:40, 8:56] = (220, 30, 30)
    img[H - 24:H - 8, 16:W - 16] = (30, 200, 30)
    return img


@pytest.mark.parametrize("rotation", [90, 180, 270])
@pytest.mark.parametrize("codec,pix_fmt", [("h264", "yuv420p"), ("hevc", "yuv422p10le")])
def test_rotation_metadata_gives_upright_frames(tmp_path, rotation, codec, pix_fmt):
    _needs(codec)
    upright = _asymmetric()
    # A phone stores the sensor's picture and tags the turn that shows it upright: store the
    # upright picture turned back by that angle (clockwise), and expect the upright one on reading.
    stored = np.ascontiguousarray(np.rot90(upright, -rotation // 90))
    path = tmp_path / "phone.mp4"
    _write(path, [stored] * 3, codec=codec, pix_fmt=pix_fmt, rotation_deg=rotation, bit_rate=20_000_000)
    info = probe_video(path)
    assert (info.width, info.height, info.rotation_deg) == (W, H, rotation)
    rgb = next(iter(iter_frames(path))).rgb
    assert rgb.shape == upright.shape
    assert np.abs(rgb.astype(int) - upright).mean() < 2.0
    yuv = next(iter(iter_yuv_frames(path)))
    assert yuv.y.shape == (H, W) and yuv.u.shape == (H // 2, W // 2)
    assert np.abs(yuv.rgb.astype(int) - upright).mean() < 3.0
    # The oracle of the direction: FFmpeg's own transpose filter turns the stored frame the same way.
    with av.open(str(path)) as container:
        frame = next(container.decode(video=0))
        graph = av.filter.Graph()
        src = graph.add_buffer(template=container.streams.video[0])
        chain = {90: ["transpose=cclock"], 180: ["hflip", "vflip"], 270: ["transpose=clock"]}[rotation]
        node = src
        for spec in chain:
            name, _, args = spec.partition("=")
            nxt = graph.add(name, args or None)
            node.link_to(nxt)
            node = nxt
        sink = graph.add("buffersink")
        node.link_to(sink)
        graph.configure()
        graph.push(frame)
        turned = graph.pull().to_ndarray(format="rgb24")
    assert np.abs(turned.astype(int) - rgb).mean() < 2.0


def test_a_rotation_no_camera_writes_is_one_clear_error(tmp_path):
    path = tmp_path / "tilted.mp4"
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=100)
        stream.width, stream.height, stream.pix_fmt = 64, 48, "yuv420p"
        stream.set_display_rotation(45)
        for i in range(3):
            frame = av.VideoFrame.from_ndarray(np.zeros((72, 64), np.uint8), format="yuv420p")
            frame.pts = i
            for packet in stream.encode(frame):
                container.mux(packet)
        for packet in stream.encode(None):
            container.mux(packet)
    for read in (probe_video, lambda p: list(iter_frames(p)), lambda p: list(iter_yuv_frames(p))):
        with pytest.raises(ServoscopeError) as info:
            read(path)
        message = str(info.value)
        assert message.startswith(str(path)) and "45" in message and "\n" not in message


@pytest.mark.parametrize("codec", ["h264", "hevc"])
def test_variable_frame_rate_times_come_back_as_written(tmp_path, codec):
    _needs(codec)
    rng = np.random.default_rng(5)
    # Slow motion with hiccups: 240 frames/s nominal, intervals from 3.1 to 6.9 ms.
    times = np.cumsum(rng.uniform(0.0031, 0.0069, 30))
    frames = [np.full((64, 96, 3), 60 + 5 * i, np.uint8) for i in range(30)]
    path = tmp_path / "vfr.mp4"
    with VideoWriter(path, 96, 64, 240, codec=codec, time_base=Fraction(1, 90000)) as writer:
        stored = [writer.write(f, time_s=float(t)) for f, t in zip(frames, times)]
    np.testing.assert_allclose(stored, times, atol=0.5 / 90000)
    read = [f.time_s for f in iter_frames(path)]
    np.testing.assert_allclose(read, stored, atol=1e-12)
    assert [f.time_s for f in iter_yuv_frames(path)] == read


def test_writer_refuses_what_it_cannot_write(tmp_path):
    frame = np.zeros((64, 96, 3), np.uint8)
    with pytest.raises(ServoscopeError, match="pixel format"):
        VideoWriter(tmp_path / "a.mp4", 96, 64, 100, pix_fmt="nv12")
    with pytest.raises(ServoscopeError, match="colour range"):
        VideoWriter(tmp_path / "a.mp4", 96, 64, 100, color_range="full")
    with pytest.raises(ServoscopeError, match="multiple of 90"):
        VideoWriter(tmp_path / "a.mp4", 96, 64, 100, rotation_deg=45)
    with pytest.raises(ServoscopeError, match="h264 and hevc only"):
        VideoWriter(tmp_path / "a.avi", 96, 64, 100, codec="raw", pix_fmt="yuv422p")
    with VideoWriter(tmp_path / "b.mp4", 96, 64, 100, time_base=Fraction(1, 1000)) as writer:
        writer.write(frame, time_s=0.010)
        with pytest.raises(ServoscopeError, match="not after the previous"):
            writer.write(frame, time_s=0.0101)  # rounds onto the same millisecond


# -- a twin clip, tracked from each format -----------------------------------------------------------

N_FRAMES = 40


@pytest.fixture(scope="module")
def twin_frames():
    scene = Scene(background_seed=4)
    pitch = 0.05 * np.sin(np.arange(N_FRAMES) / 5.0)
    renderer = FrameRenderer(scene, None, noise_sigma_dn=1.5, noise_seed=0)
    frames = [renderer.render(float(p), 1.0, i) for i, p in enumerate(pitch)]
    lead, trail = scene.sticker_centres_px(pitch)
    return frames, marker_angle_rad(lead, trail)


@pytest.mark.parametrize("kw", [
    dict(codec="hevc"),
    dict(codec="hevc", pix_fmt="yuv422p10le"),
    dict(codec="h264", color_range="pc", matrix="bt709"),
    dict(codec="hevc", pix_fmt="yuv422p10le", color_range="pc", matrix="bt709", rotation_deg=90),
], ids=["hevc", "hevc-10bit-422", "h264-full-range-bt709", "hevc-10bit-422-pc-bt709-rot90"])
def test_twin_clip_tracks_to_its_truth_from_every_format(tmp_path, twin_frames, kw):
    _needs(kw["codec"])
    frames, truth = twin_frames
    turns = kw.get("rotation_deg", 0) // 90
    path = tmp_path / "clip.mp4"
    _write(path, [np.ascontiguousarray(np.rot90(f, -turns)) for f in frames], **kw)
    track = track_video(path, TrackerSettings(led=None))
    assert track.valid.all()
    err = np.degrees(np.angle(np.exp(1j * (track.angle_rad - truth))))
    rms = float(np.sqrt(np.mean(err ** 2)))
    print(f"{kw}: angle error RMS {rms:.4f} deg, max {np.abs(err).max():.4f} deg")
    # As the H.264 twin's own accuracy test (tests/markers/test_tracking.py).
    assert np.abs(err).max() < 0.05 and rms < 0.02
    # `servoscope track` says what it did to the frames (nothing, for plain 8-bit 4:2:0 TV BT.601).
    from click.testing import CliRunner

    from servoscope.cli import cli

    run = CliRunner().invoke(cli, ["track", str(path), "--led", "none", "--out", str(tmp_path / "t.csv")])
    assert run.exit_code == 0, run.output
    notes = [line for line in run.output.splitlines() if line.startswith("clip.mp4: ") and "read" in line]
    if len(kw) == 1:
        assert notes == []
    else:
        assert len(notes) == 1 and "8-bit 4:2:0 limited-range BT.601" in notes[0]
        assert ("upright" in notes[0]) == ("rotation_deg" in kw)


def test_rolling_shutter_of_a_rotated_phone_video_reads_the_sensor_rows(tmp_path):
    # A rolling shutter exposes the *stored* picture's rows in turn; a 90° tag makes them the
    # upright image's columns. The same stored frames, tagged 0° and 90°: the angles differ by the
    # turn, but every angle's sample time and the LED's switch time must be the same.
    readout, fps, t0 = 0.015, 50, 0.3
    scene = Scene.for_size(720, 576, background_seed=0, led_offset_px=230.0)
    renderer = FrameRenderer(scene, None, noise_sigma_dn=1.5, noise_seed=0)
    rows = np.arange(scene.height)
    frames = []
    for i in range(40):
        t = i / fps + readout * rows / scene.height
        pitch = np.where(t > t0, 0.05 * np.sin(2 * np.pi * 3.0 * (t - t0)), 0.0)
        frames.append(renderer.render_rolling(pitch, (t < t0).astype(np.float64), i))
    tracks = {}
    for rotation in (0, 90):
        path = tmp_path / f"phone_{rotation}.mp4"
        _write(path, frames, fps, codec="h264", rotation_deg=rotation)
        tracks[rotation] = track_video(path, TrackerSettings(readout_s=readout))
    flat, turned = tracks[0], tracks[90]
    assert flat.valid.all() and turned.valid.all()
    assert flat.t0_s is not None
    lag = flat.angle_time_s - flat.time_s
    assert lag.min() > 0.005  # the markers sit mid-picture: the correction is several ms
    np.testing.assert_allclose(turned.angle_time_s, flat.angle_time_s, atol=2e-6)
    assert turned.t0_s == pytest.approx(flat.t0_s, abs=2e-6)
    turn = np.angle(np.exp(1j * (turned.angle_rad - flat.angle_rad)))
    assert np.abs(turn - np.median(turn)).max() < 2e-4 and abs(abs(np.median(turn)) - np.pi / 2) < 1e-3


from support import CHESSBOARD


@pytest.mark.skipif(len(sorted(CHESSBOARD.glob("left*.jpg"))) != 13,
                    reason=f"OpenCV sample chessboard photos not found in {CHESSBOARD}")
def test_calibration_from_a_rotated_video_is_of_the_upright_images(tmp_path):
    # The tracker reads a phone's video upright; its calibration must describe those images
    # (size, principal point), not the stored ones. Oracle: the same photos calibrated as they are.
    import cv2

    from servoscope.camera import calibrate

    photos = sorted(CHESSBOARD.glob("left*.jpg"))
    grays = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in photos]
    path = tmp_path / "phone.mp4"
    # Stored turned clockwise, tagged to be shown turned back (counter-clockwise) upright.
    _write(path, [np.ascontiguousarray(np.rot90(np.repeat(g[..., None], 3, axis=2), -1)) for g in grays],
           codec="h264", rotation_deg=90, bit_rate=40_000_000)
    from_video = calibrate([path], (9, 6))
    from_photos = calibrate(photos, (9, 6))
    assert tuple(from_video.camera.image_size) == tuple(from_photos.camera.image_size) == (640, 480)
    k, k0 = from_video.camera.camera_matrix, from_photos.camera.camera_matrix
    for i, j in [(0, 0), (1, 1), (0, 2), (1, 2)]:
        assert k[i, j] == pytest.approx(k0[i, j], rel=0.02), (i, j)


def test_variable_frame_rate_twin_clip_tracks_at_its_own_times(tmp_path):
    # A phone's slow motion: the interval wanders (8–12 ms) and the angle is sampled at each frame's
    # own time; the track's times are the stored ones and its angles the truth at those times.
    rng = np.random.default_rng(9)
    times = 0.01 + np.cumsum(rng.uniform(0.008, 0.012, N_FRAMES))
    pitch = 0.05 * np.sin(2 * np.pi * 4.0 * times)
    scene = Scene(background_seed=5)
    renderer = FrameRenderer(scene, None, noise_sigma_dn=1.5, noise_seed=1)
    path = tmp_path / "slowmo.mp4"
    with VideoWriter(path, scene.width, scene.height, 100, codec="hevc" if "libx265" in av.codecs_available
                     else "h264", time_base=Fraction(1, 90000)) as writer:
        stored = np.array([writer.write(renderer.render(float(p), 1.0, i), time_s=float(t))
                           for i, (p, t) in enumerate(zip(pitch, times))])
    track = track_video(path, TrackerSettings(led=None))
    np.testing.assert_allclose(track.time_s, stored, atol=1e-12)
    assert track.valid.all()
    lead, trail = scene.sticker_centres_px(0.05 * np.sin(2 * np.pi * 4.0 * stored))
    err = np.degrees(np.angle(np.exp(1j * (track.angle_rad - marker_angle_rad(lead, trail)))))
    assert np.abs(err).max() < 0.05 and np.sqrt(np.mean(err ** 2)) < 0.02
