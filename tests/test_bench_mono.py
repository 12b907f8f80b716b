"""``servoscope bench --mono``: the clip it measures on, and that its three runs measure the same thing.

Speed itself is never asserted here (a shared machine's timings are not a test);
what is: the clip is a Photron MRAW of the asked size and depth, servoscope's
engine for it is the monochrome one and tracks every frame, the LED switches
where the clip says, the user's OpenCV script and the file read see every frame,
and the script's centres are servoscope's dots.
"""

from __future__ import annotations

import json

import numpy as np

from servoscope.bench_mono import FPS, render_mono_clip
from servoscope.video.highspeed import read_cih

from support import cli


def test_bench_mono_measures_the_whole_file_on_the_same_dots(tmp_path, capsys):
    frames, size = 200, 256
    code, out, err = cli(capsys, "bench", "--mono", "--frames", frames, "--size", f"{size}x{size}", "--cache",
                         tmp_path, "--json")
    assert code == 0, err
    result = json.loads(out.strip().splitlines()[-1])
    assert result["engine"] == "mono"
    assert result["tracked_frames"] == result["opencv_frames"] == frames
    assert result["valid_fraction"] == 1.0
    # The LED goes dark at frame 100; t0 (the exposure's middle convention) within one frame of it.
    assert abs(result["led_t0_s"] - result["led_t0_true_s"]) <= 1.0 / FPS
    # Thresholded moments step by pixels; servoscope's soft moments do not: a few tenths apart, no more.
    assert result["opencv_agreement_px"] < 0.5
    assert {row["what"] for row in result["targets"]} == {
        "tracking / OpenCV script (in-process)", "tracking / reading the file alone", "tracking, gigapixels/s"}
    for row in result["targets"]:
        assert row["met"] == (row["measured"] >= row["target"])

    # The clip is what a 12-bit Photron camera writes: 16-bit words, 12 effective bits, the asked frames.
    cih = render_mono_clip(tmp_path, frames, size)
    header = read_cih(cih)
    assert (header["Image Width"], header["Image Height"], header["Total Frame"]) == (size, size, frames)
    assert header["Color Bit"] == 16 and int(header["EffectiveBit Depth"]) == 12
    data = np.fromfile(cih.with_suffix(".mraw"), "<u2")
    assert data.size == frames * size * size and int(data.max()) < 4096
    # No frame repeats the one before (the tracker would flag a duplicated frame), across the cycle's seam too.
    clip = data.reshape(frames, size, size)
    assert all(np.any(clip[k] != clip[k + 1]) for k in (0, 98, 99, 100))
