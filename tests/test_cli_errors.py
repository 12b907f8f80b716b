"""Bad input on the command line: exit 2, one line, no traceback, nothing written."""

import subprocess
import sys
from pathlib import Path

import pytest

from test_manifest import GOOD, _tiny_video


def run_cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "servoscope", *map(str, args)], capture_output=True, text=True, cwd=cwd, timeout=120
    )


CASES = {
    "not_toml": ("this is = = not toml", "not valid TOML"),
    "missing_video": (GOOD.replace('video = "a.mp4"\nkind = "sine"', 'video = "gone.mp4"\nkind = "sine"'), "gone.mp4: video not found"),
    "unknown_kind": (GOOD.replace('kind = "sine"', 'kind = "ramp"'), "unknown kind 'ramp'"),
    "zero_frequency": (GOOD.replace("frequency_hz = 1.0", "frequency_hz = 0"), "frequency_hz must be > 0"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_identify_bad_manifest(tmp_path, case):
    text, expected = CASES[case]
    _tiny_video(tmp_path / "a.mp4")
    manifest = tmp_path / "campaign.toml"
    manifest.write_text(text)
    out = tmp_path / "out"
    proc = run_cli("identify", manifest, "--out", out)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("servoscope: error: ") and expected in lines[0]
    assert "Traceback" not in proc.stderr
    assert not out.exists()


def test_identify_video_that_is_not_a_video(tmp_path):
    (tmp_path / "a.mp4").write_bytes(b"PK\x03\x04 this is a zip file, not a video" * 10)
    manifest = tmp_path / "campaign.toml"
    manifest.write_text(GOOD)
    proc = run_cli("identify", manifest, "--out", tmp_path / "out")
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and "a.mp4" in proc.stderr and "servoscope: error:" in proc.stderr
    assert not (tmp_path / "out").exists()


def test_track_missing_video(tmp_path):
    proc = run_cli("track", tmp_path / "none.mp4", "--out", tmp_path / "t.csv")
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"servoscope: error: {tmp_path / 'none.mp4'}: video not found"
    assert not (tmp_path / "t.csv").exists()


def test_usage_error_is_one_line(tmp_path):
    proc = run_cli("identify")
    assert proc.returncode == 2
    assert proc.stderr.strip().startswith("servoscope: error: ") and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
