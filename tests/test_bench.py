"""Smoke test of `servoscope bench` on tiny clips (no timing assertions)."""

import json

from click.testing import CliRunner

from servoscope.bench import bench


def test_bench_json_on_tiny_clips(tmp_path):
    res = CliRunner().invoke(bench, ["--json", "--frames", "6", "--size", "160x128", "--cache", str(tmp_path),
                                     "--workers", "1"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.output.strip().splitlines()[-1])
    for codec in ("raw", "h264"):
        row = out["clips"][codec]
        assert row["decode_fps"] > 0 and row["track_fps"] > 0 and row["opencv_fps"] > 0
        assert row["track_over_opencv"] > 0 and row["track_over_decode"] > 0
    # The clips are cached: a second run renders nothing new.
    files = sorted(p.name for p in tmp_path.iterdir())
    res = CliRunner().invoke(bench, ["--frames", "6", "--size", "160x128", "--cache", str(tmp_path), "--workers", "1"])
    assert res.exit_code == 0 and "track/opencv" in res.output
    assert sorted(p.name for p in tmp_path.iterdir()) == files


def test_bench_rejects_bad_size():
    res = CliRunner().invoke(bench, ["--size", "71x40"])
    assert res.exit_code != 0 and "even" in res.output
