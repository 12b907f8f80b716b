"""One render, many codecs: a twin campaign rendered lossless (``codec="raw"``) written again with a lossy codec.

The twin's frames cost most of a campaign's making (the scene, the blur, the noise: ~7 ms a 720×576
frame), the encoder the rest (x264 ~4 ms). A raw campaign's videos hold the very yuv420p planes
the writer hands any encoder, so encoding them again gives the bytes that rendering with that codec
would have written (tests/simulate/test_reencode.py checks the files' digests), for the encoder's
cost alone: the same scene under H.264, a camcorder's GOP and MPEG-2, compared frame for frame.
"""

from __future__ import annotations

import json
import re
import shutil
from fractions import Fraction
from pathlib import Path

import av

from .._io import write_text_atomic
from ..errors import ServoscopeError
from ..video.writer import LOSSY, VideoWriter, container_suffixes
from .presets import get_preset

__all__ = ["reencode_campaign"]


def reencode_campaign(campaign: str | Path, out_dir: str | Path, *, codec: str = "h264", bit_rate: int | None = None,
                      gop: int | None = None) -> Path:
    """Write a raw twin campaign's videos again with ``codec``, into a campaign of its own.

    Parameters
    ----------
    campaign : path
        The campaign.toml of a campaign :func:`~servoscope.simulate.simulate_campaign` rendered with
        ``codec="raw"`` (its truth.json beside it).
    out_dir : path
        Folder for the new campaign (created; must not hold a campaign.toml already).
    codec : {"h264", "hevc", "mpeg2"}
        The lossy codec, with the twin's encoder settings (x264's ``ultrafast``, one thread).
    bit_rate : int, optional
        Bits per second; default the campaign's preset's, as ``simulate_campaign`` would have used.
    gop : int, optional
        Frames between intra-coded frames (a camcorder's GOP); default the encoder's.

    Returns
    -------
    Path
        The new campaign.toml. Its truth.json is the source's with the codec, bit rate, GOP and video
        names changed: the same scene, the same answer.

    Raises
    ------
    ServoscopeError
        The source is not a raw twin campaign, the codec is not lossy, or ``out_dir`` holds a campaign.
    """
    src = Path(campaign)
    out = Path(out_dir)
    truth_path = src.with_name("truth.json")
    if not src.is_file() or not truth_path.is_file():
        raise ServoscopeError(f"{src}: not a twin campaign (campaign.toml with its truth.json beside it)")
    truth = json.loads(truth_path.read_text())
    video = truth.get("video", {})
    if video.get("codec") != "raw" or video.get("frames_format"):
        raise ServoscopeError(f"{src}: re-encoding needs a campaign rendered with codec='raw' (lossless), not "
                              f"{video.get('frames_format') or video.get('codec')!r}: a lossy source would add its "
                              "own losses")
    if codec not in LOSSY:
        raise ServoscopeError(f"codec {codec!r}: re-encoding is for the lossy codecs ({', '.join(LOSSY)})")
    if (out / "campaign.toml").exists():
        raise ServoscopeError(f"{out}: holds a campaign already; give an empty folder")
    rate = int(bit_rate if bit_rate is not None else get_preset(truth["preset"]).bit_rate)
    suffix = container_suffixes(codec)[0]
    fps = Fraction(*video["fps_rational"])  # the rate simulate_campaign wrote at (a container may not state it)
    out.mkdir(parents=True, exist_ok=True)
    renamed: dict[str, str] = {}
    for test in truth["tests"]:
        name = test["video"]
        new_name = Path(name).stem + suffix
        renamed[name] = new_name
        _reencode_video(src.parent / name, out / new_name, fps, codec, rate, gop)
    for item in src.parent.iterdir():  # camera.json, the board's photo, ...: everything but the videos
        if item.is_file() and item.name not in renamed and item.name not in ("campaign.toml", "truth.json"):
            shutil.copy2(item, out / item.name)
    text = src.read_text()
    for old, new in renamed.items():
        text = re.sub(rf'(video\s*=\s*")({re.escape(old)})(")', rf"\g<1>{new}\g<3>", text)
    write_text_atomic(out / "campaign.toml", text)
    truth["video"] = {**video, "codec": codec, "bit_rate": rate, "gop": gop}
    truth["tests"] = [{**t, "video": renamed[t["video"]]} for t in truth["tests"]]
    write_text_atomic(out / "truth.json", json.dumps(truth, allow_nan=False) + "\n")  # as simulate_campaign
    return out / "campaign.toml"


def _reencode_video(src: Path, dst: Path, fps: Fraction, codec: str, bit_rate: int, gop: int | None) -> None:
    with av.open(str(src)) as container:
        stream = container.streams.video[0]
        if stream.codec_context.pix_fmt != "yuv420p":
            raise ServoscopeError(f"{src}: holds {stream.codec_context.pix_fmt}, not the writer's yuv420p")
        with VideoWriter(dst, stream.width, stream.height, fps, codec=codec, bit_rate=bit_rate, gop=gop) as writer:
            for frame in container.decode(stream):
                writer.write_yuv420p(frame.to_ndarray())
