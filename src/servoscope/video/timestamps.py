"""A video's frame rate from its packets' timestamps, where its container states none."""

from __future__ import annotations

from pathlib import Path

import av
import numpy as np

__all__ = ["rate_from_timestamps"]


def rate_from_timestamps(path: str | Path, packets: int = 17) -> float | None:
    """Frames per second from the first packets' presentation times, read without decoding.

    For containers that state no average rate: NUT (a raw high-speed clip) keeps only a time base, and
    FFmpeg's guessed rate is then the time base itself (64,000 frames/s for a 2,000 frames/s clip). The
    median step between the first ``packets`` timestamps is the camera's frame interval.

    Returns
    -------
    float or None
        None when the file cannot be read or gives fewer than 3 distinct timestamps.
    """
    try:
        with av.open(str(path)) as container:
            stream = container.streams.video[0]
            base = stream.time_base
            pts = []
            for packet in container.demux(stream):
                if packet.pts is not None:
                    pts.append(int(packet.pts))
                if len(pts) >= packets:
                    break
    except (av.error.FFmpegError, OSError, IndexError):
        return None
    steps = np.diff(np.sort(np.asarray(pts, dtype=np.int64)))
    steps = steps[steps > 0]
    if steps.size < 2 or base is None:
        return None
    return float(1.0 / (float(np.median(steps)) * float(base)))
