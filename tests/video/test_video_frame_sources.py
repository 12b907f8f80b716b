"""Image sequences and high-speed raw files read like videos (issue 16).

Real files: pyMRAW's ``beam`` (Photron, MIT) and pims' ``cine_781`` (Phantom,
BSD-3), in tests/data/highspeed with their licences; their expected values
come from the headers and from the reference readers (pyMRAW, pims).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from servoscope.errors import ServoscopeError
from servoscope.video.frame_source import frame_source, is_frame_source, parse_frame_source, to_yuv420
from servoscope.video.highspeed import unpack_12bit
from servoscope.video.reader import iter_frames, iter_yuv_frames, probe_video
from servoscope.video.sources import open_frame_source
from servoscope.video.writer import rgb_to_yuv420p

pyMRAW = pytest.importorskip("pyMRAW")
pims = pytest.importorskip("pims")
tifffile = pytest.importorskip("tifffile")

from support import DATA as _DATA
# run_cli: the command's entry point in this process, as a child ran it (no interpreter to start a call).
from support import run_cli

DATA = _DATA / "highspeed"


# --- real Photron and Phantom files ------------------------------------------------------------

def test_photron_beam_against_header_and_pymraw():
    images, cih = pyMRAW.load_video(str(DATA / "beam.cihx"))
    for given in ("beam.mraw", "beam.cihx"):
        info = probe_video(DATA / given)
        assert (info.codec, info.width, info.height, info.frame_count) == ("mraw", 1024, 80, 4)
        # recordRate 50000, skipFrame 2500 in the CIHX: 20 frames/s as saved.
        assert info.frame_rate_hz == pytest.approx(50000 / 2500)
        assert info.bit_depth == cih["EffectiveBit Depth"] == 12
    source = open_frame_source(DATA / "beam.mraw")
    try:
        assert source.header.trigger_s == 0.0 and source.header.monochrome
        for i in range(4):
            assert np.array_equal(source.read(i), images[i])
    finally:
        source.close()
    frames = list(iter_yuv_frames(DATA / "beam.mraw"))
    assert [f.time_s for f in frames] == pytest.approx([0.0, 0.05, 0.1, 0.15])
    # 12-bit full scale is 4095: Y = 16 + round(219 v / 4095), neutral chroma.
    v = np.asarray(images[2], dtype=np.int64)
    assert np.array_equal(frames[2].y, (16 + (v * 438 + 4095) // 8190).astype(np.uint8))
    assert np.all(frames[2].u == 128) and np.all(frames[2].v == 128)


def test_phantom_cine_against_header_and_pims():
    cine = pims.open(str(DATA / "cine_781.cine"))
    try:
        info = probe_video(DATA / "cine_781.cine")
        assert (info.codec, info.width, info.height, info.frame_count) == ("cine", 256, 256, len(cine)) == \
            ("cine", 256, 256, 15)
        # Recorded at 90,000 frames/s (the header), saved with decimation 10 (the timestamps): 9,000 frames/s.
        assert cine.frame_rate == 90000
        assert info.frame_rate_hz == pytest.approx(9000.0)
        assert info.bit_depth == cine.setup_fields_dict["real_bpp"] == 12
        source = open_frame_source(DATA / "cine_781.cine")
        try:
            assert source.header.trigger_s == pytest.approx(cine.get_time_to_trigger(0))
            stamps = np.array([d.timestamp() + f for d, f in cine.frame_time_stamps])
            assert source.camera_times_s == pytest.approx(stamps - stamps[0])
            for i in range(len(cine)):
                assert np.array_equal(source.read(i), cine[i])
        finally:
            source.close()
        frames = list(iter_frames(DATA / "cine_781.cine"))
        assert np.diff([f.time_s for f in frames]) == pytest.approx(np.full(14, 1 / 9000))
        v = np.asarray(cine[7], dtype=np.int64)
        assert np.array_equal(frames[7].rgb[:, :, 0], ((v * 510 + 4095) // 8190).astype(np.uint8))
    finally:
        cine.close()


@pytest.mark.parametrize("bits", [8, 16])
@pytest.mark.parametrize("step_key", ["Save Step", "Skip Frame"])
def test_mraw_written_by_pymraw(tmp_path, bits, step_key):
    rng = np.random.default_rng(bits)
    top = 255 if bits == 8 else 4095
    images = rng.integers(0, top + 1, size=(5, 24, 32)).astype(np.uint8 if bits == 8 else np.uint16)
    mraw, cih = pyMRAW.save_mraw(images, str(tmp_path / "rec.cih"), bit_depth=bits,
                                 info_dict={"Record Rate(fps)": 15000, step_key: 100})
    info = probe_video(mraw)
    assert info.frame_rate_hz == pytest.approx(150.0)  # 15,000 frames/s saved every 100th
    assert info.bit_depth == (8 if bits == 8 else 12) and info.frame_count == 5
    loaded = pyMRAW.load_images(mraw, 24, 32, 5, bit=bits, roll_axis=False)
    got = [f.y for f in iter_yuv_frames(cih)]
    for image, y in zip(loaded, got):
        v = np.asarray(image, dtype=np.int64)
        assert np.array_equal(y, (16 + (v * 438 + top) // (2 * top)).astype(np.uint8))


def test_photron_12bit_packing_matches_pymraw(tmp_path):
    rng = np.random.default_rng(12)
    values = rng.integers(0, 4096, size=(3, 8, 10)).astype(np.uint16)
    flat = values.reshape(-1, 2).astype(np.uint32)
    packed = np.stack([flat[:, 0] >> 4, ((flat[:, 0] & 15) << 4) | (flat[:, 1] >> 8), flat[:, 1] & 255], axis=1)
    path = tmp_path / "p.mraw"
    packed.astype(np.uint8).tofile(path)
    reference = pyMRAW.load_images(str(path), 8, 10, 3, bit=12, roll_axis=False)
    assert np.array_equal(reference, values)
    assert np.array_equal(unpack_12bit(np.fromfile(path, np.uint8)).reshape(3, 8, 10), reference)


def test_the_twins_12bit_packing_is_what_pymraw_reads(tmp_path):
    from servoscope.errors import ServoscopeError
    from servoscope.video.sequence_writer import pack_12bit

    rng = np.random.default_rng(13)
    values = rng.integers(0, 4096, size=(3, 8, 10)).astype(np.uint16)
    values[0, 0, :4] = (0, 4095, 4095, 0)  # the extremes, in both places of a pair
    path = tmp_path / "p.mraw"
    pack_12bit(values).tofile(path)
    assert path.stat().st_size == values.size * 3 // 2
    assert np.array_equal(pyMRAW.load_images(str(path), 8, 10, 3, bit=12, roll_axis=False), values)
    with pytest.raises(ServoscopeError, match="odd count"):
        pack_12bit(np.zeros(5, np.uint16))


# --- image sequences --------------------------------------------------------------------------

def _colour_frames(n=6, h=20, w=30):
    rng = np.random.default_rng(5)
    return [rng.integers(0, 256, size=(h, w, 3)).astype(np.uint8) for _ in range(n)]


def test_tiff16_png_jpeg_sequences(tmp_path):
    frames = _colour_frames()
    for fmt in ("tif", "png"):
        folder = tmp_path / fmt
        folder.mkdir()
        for i, rgb in enumerate(frames):
            name = folder / f"frame_{i}.{fmt}"  # unpadded numbers: natural order puts 10 after 9
            if fmt == "tif":
                tifffile.imwrite(name, rgb.astype(np.uint16) * 257)
            else:
                cv2.imwrite(str(name), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
        source = frame_source(folder, fps=2000, start_s=0.25)
        info = probe_video(source)
        assert (info.width, info.height, info.frame_count, info.frame_rate_hz) == (30, 20, 6, 2000.0)
        assert info.bit_depth == (16 if fmt == "tif" else 8)
        got = list(iter_yuv_frames(source))
        assert [f.time_s for f in got] == pytest.approx(0.25 + np.arange(6) / 2000)
        for rgb, frame in zip(frames, got):
            # v·257 in 16 bits is v in 8: the very planes the twin's writer makes of the 8-bit frame.
            assert np.array_equal(frame.i420, rgb_to_yuv420p(rgb))
        assert all(np.array_equal(f.rgb, rgb) for f, rgb in zip(iter_frames(source), frames))
    glob_source = frame_source(str(tmp_path / "png" / "*.png"), fps=50)
    assert is_frame_source(glob_source) and len(list(iter_frames(glob_source))) == 6
    jpg = tmp_path / "j"
    jpg.mkdir()
    cv2.imwrite(str(jpg / "a1.jpg"), frames[0])
    assert probe_video(frame_source(jpg, fps=10)).codec == "jpeg"


def test_natural_order_and_timestamps_file(tmp_path):
    for i in (8, 9, 10, 11, 12):
        tifffile.imwrite(tmp_path / f"f{i}.tif", np.full((4, 6), i * 100, np.uint16))
    stamps = tmp_path / "times.txt"
    stamps.write_text("0.0\n0.001\n0.0025\n0.003\n0.0041\n")
    # a 12-bit camera's frames in 16-bit TIFFs: the real depth given.
    source = frame_source(str(tmp_path / "f*.tif"), timestamps=stamps, bits=12)
    frames = list(iter_yuv_frames(source))
    assert [f.time_s for f in frames] == pytest.approx([0.0, 0.001, 0.0025, 0.003, 0.0041])
    assert [int(f.y[0, 0]) for f in frames] == [16 + round(219 * i * 100 / 4095) for i in (8, 9, 10, 11, 12)]


def test_bayer_sequence_demosaiced(tmp_path):
    rgb = np.zeros((16, 16, 3), np.uint16)
    rgb[:, :8] = (3000, 200, 100)   # a red half, 12-bit
    rgb[:, 8:] = (100, 200, 3000)   # a blue half
    mosaic = np.empty((16, 16), np.uint16)  # RGGB: R at (even, even), B at (odd, odd)
    mosaic[0::2, 0::2] = rgb[0::2, 0::2, 0]
    mosaic[0::2, 1::2] = rgb[0::2, 1::2, 1]
    mosaic[1::2, 0::2] = rgb[1::2, 0::2, 1]
    mosaic[1::2, 1::2] = rgb[1::2, 1::2, 2]
    tifffile.imwrite(tmp_path / "b_0.tif", mosaic)
    frame = next(iter(iter_frames(frame_source(tmp_path, fps=100, bayer="RGGB", bits=12))))
    assert tuple(frame.rgb[8, 3]) == (round(3000 * 255 / 4095), round(200 * 255 / 4095), round(100 * 255 / 4095))
    assert tuple(frame.rgb[8, 12]) == (round(100 * 255 / 4095), round(200 * 255 / 4095), round(3000 * 255 / 4095))


def test_options_round_trip():
    text = frame_source("rec/dwell 01/*.tif", fps=2000, start_s=-0.5, timestamps="/x/t s.txt", bayer="GRBG", bits=10)
    spec = parse_frame_source(text)
    assert (spec.path, spec.fps, spec.start_s, spec.timestamps, spec.bayer, spec.bits) == \
        ("rec/dwell 01/*.tif", 2000.0, -0.5, "/x/t s.txt", "GRBG", 10)
    assert parse_frame_source(str(Path(text))) == spec  # survives Path(), as the tracker makes one
    with pytest.raises(ServoscopeError, match="unknown frame-source option"):
        parse_frame_source("a/*.tif#speed=3")
    # A '#' in a video's own name is no option: a missing one is still "video not found".
    assert not is_frame_source("take#2.mp4")
    with pytest.raises(ServoscopeError, match=r"take#2\.mp4: video not found"):
        probe_video("take#2.mp4")


def test_mono_conversion_is_exact_at_the_ends():
    for bits in (8, 10, 12, 14, 16):
        top = (1 << bits) - 1
        samples = np.array([[0, top], [top // 2, 1]], np.uint16 if bits > 8 else np.uint8)
        y, u, v = to_yuv420(samples, bits)
        assert y[0, 0] == 16 and y[0, 1] == 235 and u[0, 0] == v[0, 0] == 128


def test_memory_flat_over_thousands_of_frames(tmp_path):
    """3000 PNG frames of 64×48: the peak does not grow with the number of frames."""
    import tracemalloc

    rgb = _colour_frames(1, 48, 64)[0]
    ok, png = cv2.imencode(".png", rgb)
    for i in range(3000):
        (tmp_path / f"f{i:05d}.png").write_bytes(png.tobytes())

    def peak(n: int) -> int:
        folder = tmp_path / f"n{n}"
        folder.mkdir()
        for i in range(n):
            (folder / f"f{i:05d}.png").symlink_to(tmp_path / f"f{i:05d}.png")
        tracemalloc.start()
        count = sum(1 for _ in iter_yuv_frames(frame_source(folder, fps=1000)))
        _, top = tracemalloc.get_traced_memory()
        tracemalloc.stop()
        assert count == n
        return top

    small, large = peak(300), peak(3000)
    # The file list grows by ~300 bytes a file (its path, its sort key while sorting, its time);
    # the frames themselves do not pile up (20,000 frames: 5.8 MB peak, docs/formats.md).
    assert large - small < 400 * (3000 - 300), (small, large)
    assert large < 1_500_000, large


# --- bad input: one line, exit 2, nothing written ---------------------------------------------

def _bad_cases(tmp: Path) -> dict[str, tuple[list, str]]:
    mixed = tmp / "mixed"
    mixed.mkdir()
    cv2.imwrite(str(mixed / "f1.png"), np.zeros((8, 8, 3), np.uint8))
    cv2.imwrite(str(mixed / "f2.png"), np.zeros((8, 10, 3), np.uint8))
    empty = tmp / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("no frames here")
    gap = tmp / "gap"
    gap.mkdir()
    for i in (1, 2, 4):
        cv2.imwrite(str(gap / f"f{i:03d}.png"), np.zeros((8, 8, 3), np.uint8))
    broken = tmp / "broken"
    broken.mkdir()
    (broken / "f1.png").write_bytes(b"not a png at all")
    lone = tmp / "lone" / "rec.mraw"
    lone.parent.mkdir()
    lone.write_bytes((DATA / "beam.mraw").read_bytes())
    cut = tmp / "cut.cine"
    data = (DATA / "cine_781.cine").read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    return {
        "mixed sizes": ([mixed, "--fps", 100], "every frame must have the same size"),
        "no readable image": ([empty, "--fps", 100], "no readable image"),
        "unreadable image": ([broken, "--fps", 100], "not a readable image"),
        "gap in numbering": ([gap, "--fps", 100], "f002.png and f004.png"),
        "mraw without cih": ([lone], "without its header"),
        "truncated cine": ([cut], "truncated"),
        "glob without fps": ([str(mixed / "f1*.png")], "--fps"),
        "fps for a video": ([DATA / "beam.cihx", "--fps", -3], "--fps must be > 0"),
    }


@pytest.mark.parametrize("case", ["mixed sizes", "no readable image", "unreadable image", "gap in numbering",
                                  "mraw without cih", "truncated cine", "glob without fps", "fps for a video"])
def test_bad_footage_one_line_exit_2(tmp_path, case):
    args, expected = _bad_cases(tmp_path)[case]
    out = tmp_path / "out" / "t.csv"
    proc = run_cli("track", *args, "--out", out)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("servoscope: error: ") and expected in lines[0], proc.stderr
    assert not out.parent.exists()


def test_info_command(tmp_path):
    proc = run_cli("info", DATA / "beam.cihx", "--json")
    assert proc.returncode == 0, proc.stderr
    said = json.loads(proc.stdout)
    assert said["frame_rate_hz"] == 20.0 and "save step 2500" in said["frame_rate_from"]
    assert (said["bit_depth"], said["colour"], said["frame_count"]) == (12, "monochrome", 4)
    proc = run_cli("info", DATA / "cine_781.cine")
    assert proc.returncode == 0 and "9000 frames/s" in proc.stdout and "trigger" in proc.stdout, proc.stdout


# --- the manifest's frames = … -------------------------------------------------------------------

MANIFEST = """
[markers]
lead = "#d62728"
trail = "#1f77b4"

[[tests]]
{source}
kind = "sine"
frequency_hz = 1.0
amplitude = 0.1
"""


def _sequence(folder: Path, n: int = 4) -> None:
    folder.mkdir()
    for i in range(n):
        cv2.imwrite(str(folder / f"f{i:03d}.png"), np.zeros((8, 8, 3), np.uint8))


def test_manifest_frames_with_fps(tmp_path):
    from servoscope.campaign import load_campaign

    _sequence(tmp_path / "dwell_01")
    (tmp_path / "t.txt").write_text("0\n0.01\n0.02\n0.031\n")
    cases = {
        'frames = "dwell_01/*.png"\nfps = 2000': (2000.0, "dwell_01"),
        'frames = "dwell_01"\ntimestamps = "t.txt"\nlabel = "d1"': (None, "d1"),
    }
    for source, (fps, label) in cases.items():
        manifest = tmp_path / "campaign.toml"
        manifest.write_text(MANIFEST.format(source=source))
        test = load_campaign(manifest).tests[0]
        assert test.label == label
        assert probe_video(test.video).frame_rate_hz == fps
    bad = {
        'frames = "dwell_01/*.png"': "give it with --fps (or fps = … in the manifest)",
        'frames = "dwell_01/*.png"\nfps = -5': "fps must be > 0",
        'frames = "dwell_01/*.png"\nvideo = "a.mp4"\nfps = 5': "not both",
        'video = "a.mp4"\nfps = 5': "for frames = …, not a video",
        'frames = "dwell_01"\nfps = 5\nbayer = "XYZW"': "bayer must be one of",
    }
    for source, expected in bad.items():
        manifest = tmp_path / "campaign.toml"
        manifest.write_text(MANIFEST.format(source=source))
        with pytest.raises(ServoscopeError, match=expected.replace("(", r"\(").replace(")", r"\)")):
            load_campaign(manifest)


def test_markers_command_on_a_sequence(tmp_path):
    folder = tmp_path / "seq"
    folder.mkdir()
    for i in range(3):
        img = np.full((60, 80, 3), 90, np.uint8)
        cv2.circle(img, (30 + i, 30), 8, (40, 39, 214), -1)  # BGR of #d62728
        cv2.imwrite(str(folder / f"f{i}.png"), img)
    proc = run_cli("markers", folder, "--fps", 100, "--frame", 2)
    assert proc.returncode == 0, proc.stderr
    assert "seq, frame 2 (t = 0.020 s)" in proc.stdout and "#d62728" in proc.stdout.lower(), proc.stdout


def test_real_text_cih_save_step(tmp_path):
    """pyMRAW's real FASTCAM SA-Z text header: 60,000 frames/s saved every 36th, 49300 frames after the trigger."""
    from servoscope.video.highspeed import read_cih

    cih = read_cih(DATA / "sample_60k_16bit.cih")
    assert (cih["Record Rate(fps)"], cih["save_step"], cih["start_frame"], cih["Total Frame"]) == (60000, 36, 49300, 12)
    header = tmp_path / "sample_60k_16bit.cih"
    header.write_bytes((DATA / "sample_60k_16bit.cih").read_bytes())
    with pytest.raises(ServoscopeError, match="without its sample_60k_16bit.mraw"):
        probe_video(header)
    values = np.arange(12 * 368 * 896, dtype=np.uint64) % 4096
    values.astype("<u2").tofile(tmp_path / "sample_60k_16bit.mraw")
    info = probe_video(header)
    assert info.frame_rate_hz == pytest.approx(60000 / 36) and info.bit_depth == 12 and info.frame_count == 12
    source = open_frame_source(header)
    try:
        assert source.header.trigger_s == pytest.approx(49300 / 60000)
        assert np.array_equal(source.read(11), values[11 * 368 * 896:].reshape(368, 896))
    finally:
        source.close()


def test_reader_thread_errors_and_early_stop(tmp_path):
    import threading

    for i in range(10):
        size = (8, 10) if i == 5 else (8, 8)
        cv2.imwrite(str(tmp_path / f"f{i}.png"), np.zeros((*size, 3), np.uint8))
    source = frame_source(tmp_path, fps=10)
    seen = []
    with pytest.raises(ServoscopeError, match=r"f5\.png: uint8 frame of 10×8×3 in a sequence of uint8 frames of 8×8×3"):
        for frame in iter_yuv_frames(source):
            seen.append(frame.index)
    assert seen == [0, 1, 2, 3, 4]  # the frames before the bad one, in order
    frames = iter_yuv_frames(source, queue_size=2)
    assert next(frames).index == 0
    frames.close()  # the reader thread stops with the generator
    assert not any(t.name == "servoscope-read-frames" for t in threading.enumerate())


def test_truncated_mraw(tmp_path):
    (tmp_path / "beam.cihx").write_bytes((DATA / "beam.cihx").read_bytes())
    (tmp_path / "beam.mraw").write_bytes((DATA / "beam.mraw").read_bytes()[:400_000])
    with pytest.raises(ServoscopeError, match=r"beam\.mraw: truncated: 400000 bytes hold 2 of the 4 frames"):
        probe_video(tmp_path / "beam.mraw")
