"""A decoded frame's planes: native views, upright turns, and the trackers' 8-bit 4:2:0 BT.601.

Moved from :mod:`servoscope.video.reader` (which re-exports every public name)
so that the reader keeps to opening, timing and streaming frames.
"""

from __future__ import annotations

import numpy as np

from ..errors import ServoscopeError
from .colour import YuvLayout, layout_of_format, to_i420_bt601, to_rgb

__all__ = ["quarter_turns", "frame_layout", "native_planes", "frame_rgb", "yuv_planes", "i420_of_planes"]


def quarter_turns(frame) -> int:
    """Counter-clockwise quarter turns (0–3) that show a decoded frame upright (its display matrix).

    Raises
    ------
    ServoscopeError
        For a rotation that is not a multiple of 90° (no camera writes one).
    """
    degrees = frame.rotation
    if not degrees:
        return 0
    if degrees % 90:
        raise ServoscopeError(f"display rotation of {degrees}° is not a multiple of 90°; servoscope cannot show "
                              "such a frame upright (re-encode it upright)")
    return (int(degrees) // 90) % 4


def frame_layout(frame) -> YuvLayout | None:
    """A decoded frame's planar Y'CbCr layout from its pixel format and tags (None for other formats)."""
    return layout_of_format(frame.format.name, frame.color_range, frame.colorspace)


def native_planes(frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A planar Y'CbCr frame's three planes as views of its buffers (uint8, or uint16 above 8 bits)."""
    dtype = np.dtype(np.uint8) if frame.format.components[0].bits <= 8 else np.dtype("<u2")
    out = []
    for plane in frame.planes[:3]:
        # Rows are padded to line_size bytes (e.g. 768 for 720 pixels): a strided view, not a copy.
        buf = np.frombuffer(plane, dtype)
        stride = plane.line_size // dtype.itemsize
        out.append(buf[: plane.height * stride].reshape(plane.height, stride)[:, :plane.width])
    return out[0], out[1], out[2]


def _upright(a: np.ndarray, turns: int) -> np.ndarray:
    return a if not turns else np.ascontiguousarray(np.rot90(a, turns))


def frame_rgb(frame) -> np.ndarray:
    """A decoded frame as upright RGB uint8, by its own tags.

    Untagged 8-bit yuv420p (servoscope's twin) and formats other than
    planar Y'CbCr go through libswscale as before; every other Y'CbCr
    layout through :func:`servoscope.video.colour.to_rgb` (the standard
    equations with the stream's range, matrix and bit depth).
    """
    layout = frame_layout(frame)
    if layout is None or layout.is_writer_default:
        rgb = frame.to_ndarray(format="rgb24")
    else:
        rgb = to_rgb(*native_planes(frame), layout)
    return _upright(rgb, quarter_turns(frame))


def i420_of_planes(y: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Y, U, V planes (possibly strided) as one contiguous (height·3/2, width) I420 array."""
    h, w = y.shape
    out = np.empty((h * 3 // 2, w), np.uint8)
    out[:h] = y
    chroma = out[h:].reshape(2, h // 2, w // 2)
    chroma[0] = u
    chroma[1] = v
    return out


def yuv_planes(frame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A decoded frame's Y, U, V planes as 8-bit 4:2:0 limited-range BT.601, upright.

    Untagged (or BT.601-tagged, limited-range) 8-bit yuv420p of even size,
    unrotated, is returned as uint8 views of the frame's buffers (no copy;
    the views keep the buffers alive). Other planar Y'CbCr layouts are
    converted by the standard equations from the frame's own range, matrix
    and bit depth (:func:`servoscope.video.colour.to_i420_bt601`); other
    pixel formats (RGB, grey) go through libswscale to yuv420p (cropped to
    even size). A rotated frame is turned upright (a copy).
    """
    turns = quarter_turns(frame)
    layout = frame_layout(frame)
    if layout is not None and not layout.is_writer_default:
        y, u, v = _split_i420(to_i420_bt601(*native_planes(frame), layout))
    else:
        if frame.format.name != "yuv420p" or frame.width % 2 or frame.height % 2:
            frame = frame.reformat(width=frame.width - frame.width % 2, height=frame.height - frame.height % 2,
                                   format="yuv420p")
        y, u, v = native_planes(frame)
    if turns:
        y, u, v = _upright(y, turns), _upright(u, turns), _upright(v, turns)
    return y, u, v


def _split_i420(i420: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    h = i420.shape[0] * 2 // 3
    chroma = i420[h:].reshape(2, h // 2, i420.shape[1] // 2)
    return i420[:h], chroma[0], chroma[1]
