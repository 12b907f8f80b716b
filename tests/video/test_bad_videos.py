"""A corpus of broken video files, made here: every one is a clear error or a usable partial track."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import av
import numpy as np
import pytest

from servoscope.errors import ServoscopeError
from servoscope.pipeline import TrackerSettings, track_video
from servoscope.video import probe_video
from support import DATA


@pytest.fixture(scope="module")
def good_video(quick_campaign) -> Path:
    return sorted(quick_campaign.parent.glob("dwell_01_*.mp4"))[0]


def _corpus(good: Path, folder: Path) -> dict[str, Path]:
    data = good.read_bytes()
    rng = np.random.default_rng(11)
    files: dict[str, bytes] = {
        "empty": b"",
        "random_bytes": rng.integers(0, 256, 50_000, dtype=np.uint8).tobytes(),
        "text": b"hello, this is a text file that is named like a video\n" * 20,
        "header_only": data[:1000],
    }
    for frac in (0.3, 0.6, 0.95):
        files[f"truncated_{int(frac * 100)}"] = data[: int(len(data) * frac)]
    flipped = bytearray(data)
    for pos in rng.integers(2000, len(data), 200):
        flipped[pos] ^= 1 << int(rng.integers(0, 8))
    files["bit_flipped"] = bytes(flipped)
    paths = {}
    for name, blob in files.items():
        p = folder / f"{name}.mp4"
        p.write_bytes(blob)
        paths[name] = p
    # A container without a video stream: audio only.
    p = folder / "audio_only.mka"
    with av.open(str(p), "w") as out:
        stream = out.add_stream("pcm_s16le", rate=8000)
        frame = av.AudioFrame.from_ndarray(np.zeros((1, 800), np.int16), format="s16", layout="mono")
        frame.rate = 8000
        for packet in stream.encode(frame):
            out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)
    paths["audio_only"] = p
    return paths


@pytest.fixture(scope="module")
def corpus(good_video, tmp_path_factory):
    return _corpus(good_video, tmp_path_factory.mktemp("broken"))


SETTINGS = TrackerSettings()


@pytest.mark.parametrize("name", ["empty", "random_bytes", "text", "header_only", "audio_only"])
def test_unreadable_files_are_one_clear_error(corpus, name):
    with pytest.raises(ServoscopeError) as info:
        probe_video(corpus[name])
        track_video(corpus[name], SETTINGS)
    message = str(info.value)
    assert corpus[name].name in message and "\n" not in message


@pytest.mark.parametrize("name", ["truncated_30", "truncated_60", "truncated_95", "bit_flipped"])
def test_damaged_files_give_a_partial_track_or_a_clear_error(corpus, good_video, name):
    full = track_video(good_video, SETTINGS)
    try:
        track = track_video(corpus[name], SETTINGS)
    except ServoscopeError as exc:
        assert corpus[name].name in str(exc) and "\n" not in str(exc)
        return
    assert 0 < track.n_frames <= full.n_frames
    if name.startswith("truncated") and track.n_frames < full.n_frames:
        # The container announced more frames than it gave: said, with both counts.
        assert any(f"decoded {track.n_frames} of {full.n_frames} announced frames: the file ends early" in w
                   for w in track.warnings), track.warnings
    # Whatever decoded is measured, never silently wrong: valid frames agree with the intact file.
    n = track.n_frames
    both = track.valid & full.valid[:n]
    if name.startswith("truncated") and both.any():
        np.testing.assert_allclose(track.angle_rad[both], full.angle_rad[:n][both], atol=1e-9)


@pytest.mark.parametrize("name", ["empty", "random_bytes", "truncated_60", "bit_flipped", "audio_only"])
def test_cli_track_never_shows_a_traceback(corpus, tmp_path, name):
    out = tmp_path / "t.csv"
    proc = subprocess.run(
        [sys.executable, "-m", "servoscope", "track", str(corpus[name]), "--out", str(out)],
        capture_output=True, text=True, timeout=300,
    )
    assert "Traceback" not in proc.stderr
    assert proc.returncode in (0, 2), proc.stderr
    if proc.returncode == 2:
        assert proc.stderr.startswith("servoscope: error: ") and len(proc.stderr.strip().splitlines()) == 1
        assert not out.exists()


def test_fuzz_findings_stay_fixed():
    """Inputs that atheris found crashing the video opener (fuzz/fuzz_inputs.py) now give a clear error."""
    for path in sorted((DATA / "fuzz").glob("video-*")):
        with pytest.raises(ServoscopeError, match="cannot decode|not a readable video|no video stream|empty"):
            probe_video(path)
