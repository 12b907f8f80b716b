"""Bad input on the command line: exit 2, one line, no traceback, nothing written."""

from pathlib import Path

import pytest

# run_cli: the command's entry point in this process, as a child ran it (no interpreter to start a call).
from support import GOOD, run_cli, tiny_video as _tiny_video


CASES = {
    "not_toml": ("this is = = not toml", "not valid TOML"),
    "missing_video": (GOOD.replace('video = "a.mp4"\nkind = "sine"', 'video = "gone.mp4"\nkind = "sine"'), "gone.mp4: video not found"),
    "unknown_kind": (GOOD.replace('kind = "sine"', 'kind = "ramp"'), "unknown kind 'ramp'"),
    "zero_frequency": (GOOD.replace("frequency_hz = 1.0", "frequency_hz = 0"), "tests[1].frequency_hz: must be > 0"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_identify_bad_manifest(tmp_path, case):
    text, expected = CASES[case]
    _tiny_video(tmp_path / "a.mp4")
    _tiny_video(tmp_path / "b.mp4")
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
    _tiny_video(tmp_path / "b.mp4")
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


def test_keep_going_leaves_a_broken_video_out(tmp_path, quick_campaign):
    """One broken video out of five: --keep-going identifies from the rest and says so."""
    import json
    import shutil

    folder = tmp_path / "campaign"
    shutil.copytree(quick_campaign.parent, folder)
    broken = sorted(folder.glob("dwell_02_*.mp4"))[0]
    broken.write_bytes(broken.read_bytes()[:2000])  # cut short before the first frame
    manifest = folder / "campaign.toml"
    strict = run_cli("identify", manifest, "--out", tmp_path / "strict")
    assert strict.returncode == 2 and broken.name in strict.stderr and not (tmp_path / "strict").exists()
    proc = run_cli("identify", manifest, "--out", tmp_path / "out", "--keep-going", "--quiet")
    assert proc.returncode == 0, proc.stderr
    result = json.loads((tmp_path / "out" / "result.json").read_text())
    assert [s["label"] for s in result["skipped"]] == [broken.stem]
    assert any(broken.stem in w for w in result["warnings"])
    assert len(result["frequency_response"]) == 3
    assert broken.stem in (tmp_path / "out" / "report.html").read_text()


def test_out_cannot_overwrite_inputs(tmp_path):
    _tiny_video(tmp_path / "a.mp4")
    _tiny_video(tmp_path / "b.mp4")
    (tmp_path / "campaign.toml").write_text(GOOD.replace('video = "b.mp4"', 'video = "result.json"'))
    (tmp_path / "result.json").write_bytes((tmp_path / "b.mp4").read_bytes())
    before = (tmp_path / "result.json").read_bytes()
    proc = run_cli("identify", tmp_path / "campaign.toml", "--out", tmp_path)
    assert proc.returncode == 2 and "would overwrite an input" in proc.stderr
    assert (tmp_path / "result.json").read_bytes() == before


@pytest.mark.parametrize("args, words", [
    (["--fps", "50", "--readout", "0.03"], "shorter than the frame interval"),
    (["--readout", "-0.001"], "-0.001"),
])
def test_simulate_rejects_an_impossible_camera_in_one_line(tmp_path, args, words):
    out = tmp_path / "twin"
    r = run_cli("simulate", str(out), "--preset", "quick", *args)
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and r.stderr.startswith("servoscope: error:") and words in r.stderr
    assert not (out / "campaign.toml").exists()


def test_simulate_offers_every_codec_the_writer_has():
    # The CLI lists the codecs itself (importing the writer would load numba for every command); they must agree.
    import click

    from servoscope.cli import simulate
    from servoscope.video.writer import CODECS

    choice = next(p for p in simulate.params if p.name == "codec").type
    assert isinstance(choice, click.Choice) and sorted(choice.choices) == sorted(CODECS)
