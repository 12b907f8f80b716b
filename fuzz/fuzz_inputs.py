"""Coverage-guided fuzzing (atheris) of the manifest parser and the video opener.

Run for a bounded time, e.g. 60 s each:

    .venv/bin/pip install atheris
    .venv/bin/python fuzz/fuzz_inputs.py manifest -max_total_time=60
    .venv/bin/python fuzz/fuzz_inputs.py video -max_total_time=60

Any exception other than ServoscopeError is a finding (atheris stops and
writes the crashing input to crash-*).
"""

from __future__ import annotations

import os
import sys
import tempfile

import atheris

# Libraries first, uninstrumented: only servoscope's own code is traced.
import av  # noqa: F401
import cv2  # noqa: F401
import matplotlib.colors  # noqa: F401
import numpy  # noqa: F401

with atheris.instrument_imports(include=["servoscope"]):
    from servoscope.campaign.manifest import load_campaign
    from servoscope.errors import ServoscopeError
    from servoscope.video.reader import iter_frames, probe_video

_DIR = tempfile.mkdtemp(prefix="servoscope-fuzz-")
_SEED_MANIFEST = b"""[markers]
lead = "#d62728"
trail = "green"
[[tests]]
video = "a.mp4"
kind = "sine"
frequency_hz = 1.0
amplitude = 0.1
"""


def fuzz_manifest(data: bytes) -> None:
    path = os.path.join(_DIR, "campaign.toml")
    with open(path, "wb") as fh:
        fh.write(data)
    try:
        load_campaign(path, check_videos=False)
    except ServoscopeError:
        pass


def fuzz_video(data: bytes) -> None:
    path = os.path.join(_DIR, "clip.mp4")
    with open(path, "wb") as fh:
        fh.write(data)
    try:
        probe_video(path)
        for i, _ in enumerate(iter_frames(path)):
            if i >= 3:
                break
    except ServoscopeError:
        pass


def _seed_video(path: str) -> None:
    """A tiny real H.264 clip, so that mutations start from a valid container."""
    with av.open(path, "w") as out:
        stream = out.add_stream("libx264", rate=25)
        stream.width, stream.height, stream.pix_fmt = 32, 32, "yuv420p"
        for i in range(3):
            frame = av.VideoFrame.from_ndarray(numpy.full((32, 32, 3), 60 * i, numpy.uint8), format="rgb24")
            for packet in stream.encode(frame):
                out.mux(packet)
        for packet in stream.encode():
            out.mux(packet)


def main() -> None:
    target = sys.argv.pop(1) if len(sys.argv) > 1 else "manifest"
    corpus = os.path.join(_DIR, "corpus")
    os.makedirs(corpus, exist_ok=True)
    if target == "manifest":
        with open(os.path.join(corpus, "seed.toml"), "wb") as fh:
            fh.write(_SEED_MANIFEST)
    else:
        _seed_video(os.path.join(corpus, "seed.mp4"))
    sys.argv.append(corpus)
    atheris.Setup(sys.argv, fuzz_manifest if target == "manifest" else fuzz_video)
    atheris.Fuzz()


if __name__ == "__main__":
    main()
