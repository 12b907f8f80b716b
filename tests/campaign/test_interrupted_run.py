"""A killed `identify` leaves nothing that looks complete, and the next run resumes."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path


def _entries(cache: Path) -> dict[str, float]:
    # An entry is whole once its JSON exists (written last). A kill in the middle of writing one leaves
    # the atomic writer's hidden temporary (".KEY.PID.tmp.json"), which no reader takes for an entry.
    return ({p.name: p.stat().st_mtime_ns for p in cache.rglob("*.json") if not p.name.startswith(".")}
            if cache.exists() else {})


def test_kill_part_way_then_resume(tmp_path, quick_campaign, quick_result):
    out = tmp_path / "out"
    cache = out / ".cache"
    cmd = [sys.executable, "-m", "servoscope", "identify", str(quick_campaign), "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while len(_entries(cache)) < 2 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert proc.poll() is None, "identify finished before it could be interrupted"
        os.killpg(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=60)
    done_before = _entries(cache)
    assert 2 <= len(done_before) < 5
    # Nothing that looks like a finished run.
    for name in ("result.json", "report.html", "frequency_response.csv"):
        assert not (out / name).exists()
    assert not list(out.glob("tracks/*.csv"))

    again = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    assert again.returncode == 0, again.stderr
    after = _entries(cache)
    assert len(after) == 5
    # The tracks finished before the kill were reused, not redone.
    assert all(after[name] == mtime for name, mtime in done_before.items())
    # The resumed run's answer is the uninterrupted one's, to the bit.
    result = json.loads((out / "result.json").read_text())
    whole = json.loads(json.dumps(quick_result.summary()))
    for key in ("model", "frequency_response", "step", "dead_time", "exposure"):
        assert result[key] == whole[key], key
