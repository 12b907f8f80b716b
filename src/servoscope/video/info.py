"""What the reader sees in a piece of footage, as ``ffprobe`` says it for video: ``servoscope info``.

For a video file: the container's and stream's properties (:func:`probe_video`)
and the regularity of its frames' timestamps (packets' PTS, demuxed without
decoding). For an image sequence or a high-speed file: its header's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ServoscopeError
from .frame_source import is_frame_source, parse_frame_source, regularity
from .sources import open_frame_source

__all__ = ["describe_footage", "format_description"]


def _video_times(path: Path) -> np.ndarray:
    """Every video packet's presentation time, s, sorted (display order), read without decoding."""
    import av

    with av.open(str(path)) as container:
        stream = container.streams.video[0]
        base = stream.time_base
        pts = [p.pts for p in container.demux(stream) if p.pts is not None and p.size]
    return np.sort(np.array([float(t * base) for t in pts])) if base is not None else np.zeros(0)


def describe_footage(path: str | Path) -> dict:
    """What servoscope reads from ``path``: a dict of plain JSON types.

    Keys: ``path``, ``format``, ``width``, ``height``, ``frame_count``,
    ``frame_rate_hz``, ``frame_rate_from`` (``"header: …"``, ``"container"``,
    ``"command line or manifest"``), ``bit_depth``, ``colour``
    (``"colour"``, ``"monochrome"``, ``"raw Bayer RGGB"``…), ``sample_format``,
    ``timestamps`` (their regularity, in words), ``first_time_s``,
    ``trigger_s`` (high-speed files; None otherwise), ``conversion`` (what the
    trackers are given).

    Raises
    ------
    ServoscopeError
        As the readers do, for footage that cannot be read.
    """
    from .reader import probe_video

    if is_frame_source(path):
        source = open_frame_source(path)
        source.close()
        h = source.header
        return {
            "path": parse_frame_source(path).path, "format": h.format, "width": h.width, "height": h.height,
            "frame_count": h.frame_count, "frame_rate_hz": h.frame_rate_hz, "frame_rate_from": h.frame_rate_from,
            "bit_depth": h.bit_depth, "colour": h.colour, "sample_format": h.sample_format,
            "timestamps": f"{regularity(h.times_s)}, from the {h.times_from}",
            "first_time_s": float(h.times_s[0]), "trigger_s": h.trigger_s,
            "conversion": (f"{h.bit_depth}-bit samples scaled by 255/{2 ** h.bit_depth - 1} to 8 bits"
                           + (", gray as Y (limited range), neutral chroma" if h.monochrome else
                              ", then 8-bit 4:2:0 limited-range BT.601")),
        }
    info = probe_video(path)
    times = _video_times(Path(path))
    if times.size == 0:
        raise ServoscopeError(f"{path}: no video packet with a timestamp")
    colour = "monochrome" if (info.pixel_format or "").startswith("gray") else "colour"
    return {
        "path": str(path), "format": info.codec, "width": info.width, "height": info.height,
        "frame_count": int(info.frame_count or times.size), "frame_rate_hz": info.frame_rate_hz,
        "frame_rate_from": "container (average rate)", "bit_depth": info.bit_depth, "colour": colour,
        "sample_format": info.pixel_format, "timestamps": f"{regularity(times)}, from the container's PTS",
        "first_time_s": float(times[0]), "trigger_s": None,
        "conversion": info.conversion_note() or "none: 8-bit 4:2:0 limited-range BT.601 as it is",
    }


def format_description(info: dict) -> str:
    """:func:`describe_footage`'s dict as aligned ``key: value`` lines."""
    rate = info["frame_rate_hz"]
    lines = [
        ("file", info["path"]),
        ("format", info["format"]),
        ("size", f"{info['width']}×{info['height']}"),
        ("frames", str(info["frame_count"])),
        ("frame rate", (f"{rate:.6g} frames/s" if rate else "unknown") + f" ({info['frame_rate_from']})"),
        ("bit depth", "unknown" if info["bit_depth"] is None else f"{info['bit_depth']} bits"),
        ("colour", info["colour"]),
        ("samples", str(info["sample_format"])),
        ("timestamps", info["timestamps"]),
        ("first frame at", f"{info['first_time_s']:.9g} s"),
    ]
    if info["trigger_s"] is not None:
        lines.append(("trigger", f"first frame {info['trigger_s']:+.9g} s from it"))
    lines.append(("read as", info["conversion"]))
    width = max(len(k) for k, _ in lines)
    return "\n".join(f"{k:<{width}}  {v}" for k, v in lines)
