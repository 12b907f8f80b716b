"""Tracking streams: a long video costs no more memory than a short one.

Both clips are tracked by ``servoscope track`` (the CLI's ``main``) in a fresh
process, which reports its own peak resident memory (``VmHWM``) at exit. The long
clip is the short clip's frames repeated (uncompressed packets copied, no
re-encoding), so that making it takes seconds, not a render of 3000 frames.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

#: The whole command run in a child process; prints its peak RSS (kB) as its last line. VmHWM, not
#: getrusage's ru_maxrss: Linux carries ru_maxrss over exec from the forking parent (here pytest, whose
#: own size would hide the child's), while VmHWM belongs to the new process image alone.
_RUN_AND_REPORT = (
    "import sys\n"
    "from servoscope.cli import main\n"
    "try:\n"
    "    main(sys.argv[1:])\n"
    "except SystemExit as exc:\n"
    "    if exc.code:\n"
    "        raise\n"
    "hwm = [line for line in open('/proc/self/status') if line.startswith('VmHWM:')][0]\n"
    "print(int(hwm.split()[1]))\n"
)

#: Frames of the rendered clip; its pitch is periodic over them, so repeating it has no jump.
PERIOD = 100


def _repeat_raw(src: Path, dst: Path, repeats: int) -> None:
    """Write ``src``'s (uncompressed) frames ``repeats`` times into ``dst``, one packet per frame."""
    import av

    with av.open(str(src)) as inp:
        template = inp.streams.video[0]
        payloads = [bytes(p) for p in inp.demux(template) if p.size]
        with av.open(str(dst), "w") as out:
            stream = out.add_stream("rawvideo", rate=template.average_rate)
            stream.width, stream.height = template.width, template.height
            stream.pix_fmt = template.codec_context.pix_fmt
            n = 0
            for _ in range(repeats):
                for data in payloads:
                    # A fresh packet each time: muxing takes the packet's data over.
                    packet = av.Packet(data)
                    packet.stream = stream
                    packet.time_base = template.time_base
                    packet.pts = packet.dts = n
                    packet.is_keyframe = True
                    out.mux(packet)
                    n += 1


def _peak_rss_mb(video: Path, out_csv: Path) -> float:
    done = subprocess.run([sys.executable, "-c", _RUN_AND_REPORT, "track", str(video), "--out", str(out_csv)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert out_csv.exists()
    return int(done.stdout.strip().splitlines()[-1]) / 1024.0


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs Linux's /proc/self/status (VmHWM)")
def test_long_video_uses_no_more_memory_than_short(tmp_path):
    from servoscope.simulate import Scene
    from servoscope.simulate.clips import render_clip

    base = tmp_path / "base.avi"
    pitch = 0.02 * np.sin(2 * np.pi * np.arange(PERIOD) / PERIOD)
    render_clip(base, Scene.for_size(720, 576, background_seed=2), pitch, fps=100, codec="raw", noise_seed=1)
    short, long = tmp_path / "short.avi", tmp_path / "long.avi"
    try:
        _repeat_raw(base, short, 3)  # 300 frames
        _repeat_raw(base, long, 30)  # 3000 frames, 1.9 GB uncompressed
        rss_short = _peak_rss_mb(short, tmp_path / "short.csv")
        rss_long = _peak_rss_mb(long, tmp_path / "long.csv")
        assert sum(1 for _ in open(tmp_path / "long.csv")) == 3001
    finally:
        long.unlink(missing_ok=True)  # pytest keeps recent tmp folders: do not leave 1.9 GB behind
    assert rss_long <= rss_short + 50.0, f"peak RSS {rss_long:.0f} MB for 3000 frames vs {rss_short:.0f} MB for 300"
