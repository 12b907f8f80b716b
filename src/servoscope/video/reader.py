"""Reading footage with PyAV, frame by frame, with each frame's own timestamp.

Times come from each frame's presentation timestamp (PTS × time base), never
from frame index × nominal rate: camcorders drop and duplicate frames, and
variable-frame-rate phones have no nominal rate at all.

Whatever the source's samples (8 or 10 bits, 4:2:0 / 4:2:2 / 4:4:4, limited
or full range, BT.601 or BT.709 matrix, read from the stream's tags), the
YUV path hands the trackers what they expect, 8-bit 4:2:0 limited-range
BT.601, converted by the standard equations (:mod:`servoscope.video.colour`),
and the RGB path the source's own R'G'B'. Frames come upright, as a player
shows them: a phone's rotation (the container's display matrix) is applied.
Untagged 8-bit yuv420p (servoscope's own twin) passes through untouched.
"""

from __future__ import annotations

import os

from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import Iterator

import av
import numpy as np

from ..errors import ServoscopeError
from .timestamps import rate_from_timestamps
from .colour import layout_of_format
from .frame_source import is_frame_source, to_rgb8, to_yuv420
from .sources import iter_source, open_frame_source, prefetch
from .planes import (frame_layout, frame_rgb, i420_of_planes, native_planes, quarter_turns,  # noqa: F401
                     yuv_planes)

__all__ = ["VideoInfo", "Frame", "YuvFrame", "FIELD_ORDERS", "probe_video", "iter_frames", "iter_yuv_frames",
           "yuv_planes", "is_intra", "configure_decoder", "default_decoder_threads", "i420_of_planes",
           "frame_layout", "quarter_turns", "native_planes", "frame_rgb"]


@dataclass(frozen=True)
class VideoInfo:
    """What the container says about a video's first video stream.

    Attributes
    ----------
    path : Path
    width, height : int
        Frame size in pixels as the frames come, upright (a phone's portrait
        video stored as 1920×1080 with a 90° rotation reads as 1080×1920).
    codec : str
        Decoder name, e.g. ``"h264"`` or ``"rawvideo"``.
    pixel_format : str
        e.g. ``"yuv420p"``.
    frame_rate_hz : float or None
        Nominal (average) rate, for information only.
    frame_count : int or None
        Frames the container announces (0 or None when unknown).
    duration_s : float or None
    bit_depth : int or None
        Bits per sample (8, 10, …; None for formats other than planar Y'CbCr).
    chroma_subsampling : str or None
        ``"4:2:0"``, ``"4:2:2"``, ``"4:4:4"``…
    color_range : str or None
        ``"tv"`` (limited) or ``"pc"`` (full, JPEG), as tagged; untagged reads as ``"tv"``.
    matrix : str or None
        ``"bt601"``, ``"bt709"``, …, as tagged; untagged reads as ``"bt601"`` (FFmpeg's default).
    rotation_deg : int
        Counter-clockwise rotation applied to show the frames upright (the
        container's display matrix; 0, 90, 180 or 270).
    """

    path: Path
    width: int
    height: int
    codec: str
    pixel_format: str | None
    frame_rate_hz: float | None
    frame_count: int | None
    duration_s: float | None
    bit_depth: int | None = 8
    chroma_subsampling: str | None = "4:2:0"
    color_range: str | None = "tv"
    matrix: str | None = "bt601"
    rotation_deg: int = 0

    def conversion_note(self) -> str | None:
        """What the reader does to this video's frames for the trackers, or None when nothing.

        E.g. ``"hevc yuv422p10le: 10-bit 4:2:2, full range, BT.709, rotated 90°: read as 8-bit 4:2:0
        limited-range BT.601, upright"``.
        """
        said = []
        if self.bit_depth is not None and self.bit_depth != 8:
            said.append(f"{self.bit_depth}-bit")
        if self.chroma_subsampling not in (None, "4:2:0"):
            said.append(str(self.chroma_subsampling))
        if self.color_range == "pc":
            said.append("full range")
        if self.matrix not in (None, "bt601"):
            said.append(str(self.matrix).upper().replace("BT", "BT."))
        done = "read as 8-bit 4:2:0 limited-range BT.601" if said else "read"
        if self.rotation_deg:
            said.append(f"rotated {self.rotation_deg}°")
            done += ", upright" if len(said) > 1 else " upright"
        if not said:
            return None
        return f"{self.codec} {self.pixel_format}: {', '.join(said)}: {done}"

    @property
    def sensor_height(self) -> int:
        """Rows of the picture as stored (the sensor's rows, which a rolling shutter reads in turn)."""
        return self.width if self.rotation_deg % 180 else self.height

    def sensor_rows(self, xy_px: np.ndarray) -> np.ndarray:
        """Row of the stored picture (px, pixel centres at integers) of upright image points.

        A rolling shutter exposes the stored picture's rows in turn; a phone's
        90° rotation makes them the upright image's columns.

        Parameters
        ----------
        xy_px : array_like, shape (..., 2)
            Points in the upright image (as the frames come), px.

        Returns
        -------
        ndarray, shape (...)
        """
        xy = np.asarray(xy_px, dtype=np.float64)
        x, y = xy[..., 0], xy[..., 1]
        # np.rot90(stored, k) shows the stored picture upright; invert it for each k.
        turns = (self.rotation_deg // 90) % 4
        if turns == 0:
            return y.copy()
        if turns == 1:
            return x.copy()
        if turns == 2:
            return (self.height - 1) - y
        return (self.width - 1) - x


@dataclass(frozen=True)
class Frame:
    """One decoded frame.

    Attributes
    ----------
    index : int
        Position in decoding order, from 0 (counting fields when split).
    time_s : float
        Presentation time in seconds (PTS × time base; for the second field
        of a split frame, half a frame interval later).
    rgb : ndarray, shape (height, width, 3), uint8
        The frame, or one field of it (every second row).
    row_offset, row_step : int
        Row ``j`` of ``rgb`` is row ``row_offset + row_step·j`` of the full
        frame: (0, 1) for whole frames, (0, 2) / (1, 2) for top / bottom fields.
    intra : bool
        The codec coded this frame on its own (an I-frame; every frame of
        uncompressed or intra-only video), not as a change from other frames.
    """

    index: int
    time_s: float
    rgb: np.ndarray
    row_offset: int = 0
    row_step: int = 1
    intra: bool = True

    def to_frame_xy(self, xy_px: np.ndarray) -> np.ndarray:
        """Points in this image (px, shape (..., 2)) in full-frame coordinates."""
        xy = np.array(xy_px, dtype=np.float64, copy=True)
        xy[..., 1] = self.row_offset + self.row_step * xy[..., 1]
        return xy


def _open(path: Path) -> av.container.InputContainer:
    if not path.exists():
        raise ServoscopeError(f"{path}: video not found")
    if path.is_dir():
        raise ServoscopeError(f"{path}: is a folder, not a video")
    if path.stat().st_size == 0:
        raise ServoscopeError(f"{path}: empty file, not a video")
    try:
        container = av.open(str(path), mode="r")
    except (av.error.FFmpegError, UnicodeDecodeError, ValueError) as exc:
        raise ServoscopeError(f"{path}: not a readable video ({_reason(exc)})") from None
    if not container.streams.video:
        container.close()
        raise ServoscopeError(f"{path}: has no video stream")
    if container.streams.video[0].codec_context is None:
        # Found by fuzzing: a stream whose codec FFmpeg does not know has no decoder context.
        container.close()
        raise ServoscopeError(f"{path}: video stream in a codec FFmpeg cannot decode")
    return container



def _frame_time_s(frame, time_base, rate, last_time: float | None) -> float:
    """A frame's presentation time (PTS × time base), in seconds."""
    if frame.pts is not None:
        return float(frame.pts * time_base)
    if last_time is not None and rate:
        # No PTS at all (some raw streams): the nominal rate is all there is.
        return last_time + 1.0 / float(rate)
    return 0.0

def _reason(exc: Exception) -> str:
    text = getattr(exc, "strerror", None) or str(exc)
    return text.splitlines()[0] if text else type(exc).__name__


def probe_video(path: str | Path) -> VideoInfo:
    """Open a video and read its stream properties, decoding nothing.

    Raises
    ------
    ServoscopeError
        When the file is missing, empty, not a video, or has no video stream.
        Image sequences and high-speed raw files (:mod:`servoscope.video.frame_source`)
        are described from their headers.
    """
    if is_frame_source(path):
        return _source_info(path)
    path = Path(path)
    container = _open(path)
    try:
        stream = container.streams.video[0]
        ctx = stream.codec_context
        if ctx.width <= 0 or ctx.height <= 0:
            raise ServoscopeError(f"{path}: video stream has no frame size")
        rate = stream.average_rate or rate_from_timestamps(path) or stream.guessed_rate
        duration = None
        if stream.duration is not None and stream.time_base is not None:
            duration = float(stream.duration * stream.time_base)
        elif container.duration is not None:
            duration = container.duration / 1e6
        pix_fmt = ctx.format.name if ctx.format is not None else None
        layout = layout_of_format(pix_fmt or "", ctx.color_range, ctx.colorspace)
        turns = _first_frame_turns(path, container, stream)
        width, height = (int(ctx.height), int(ctx.width)) if turns % 2 else (int(ctx.width), int(ctx.height))
        return VideoInfo(
            path=path,
            width=width,
            height=height,
            codec=ctx.name,
            pixel_format=pix_fmt,
            frame_rate_hz=float(rate) if rate else None,
            frame_count=int(stream.frames) if stream.frames else None,
            duration_s=duration,
            bit_depth=layout.bit_depth if layout else None,
            chroma_subsampling=layout.subsampling if layout else None,
            color_range=None if layout is None else ("pc" if layout.full_range else "tv"),
            matrix=layout.matrix if layout else None,
            rotation_deg=90 * turns,
        )
    finally:
        container.close()


def _source_info(path: str | Path) -> VideoInfo:
    """An image sequence's or a high-speed file's header as a :class:`VideoInfo` (``codec``: its format)."""
    source = open_frame_source(path)
    source.close()
    h = source.header
    duration = h.frame_count / h.frame_rate_hz if h.frame_rate_hz else float(h.times_s[-1] - h.times_s[0])
    return VideoInfo(Path(path), h.width, h.height, h.format, h.sample_format, h.frame_rate_hz, h.frame_count,
                     duration, h.bit_depth, None, None, None)


def _check_fields(path: str | Path, fields: str | None) -> None:
    if fields not in FIELD_ORDERS:
        raise ServoscopeError(f"fields must be one of None, 'tff', 'bff', not {fields!r}")
    if fields is not None and is_frame_source(path):
        raise ServoscopeError(f"{path}: fields apply to interlaced video, not to an image sequence or a raw file")


def _first_frame_turns(path: Path, container, stream) -> int:
    """Quarter turns of the first frame (the display matrix reaches PyAV on decoded frames only)."""
    try:
        for frame in container.decode(stream):
            return _in_file(path, quarter_turns, frame)
    except av.error.FFmpegError:
        pass  # a damaged stream: its frames' own errors are reported when they are read
    return 0


def _in_file(path: Path, convert, frame):
    """``convert(frame)``, its errors naming the file."""
    try:
        return convert(frame)
    except ServoscopeError as exc:
        raise ServoscopeError(f"{path}: {exc}") from None


#: Accepted values of ``iter_frames(..., fields=)``.
FIELD_ORDERS = (None, "tff", "bff")


def iter_frames(path: str | Path, *, threads: int = 0, fields: str | None = None) -> Iterator[Frame]:
    """Decode a video's frames in order, as RGB arrays with their PTS times.

    Parameters
    ----------
    path : path-like
    threads : int
        Decoder threads; 0 lets FFmpeg choose.
    fields : {None, "tff", "bff"}
        Split each interlaced frame into its two fields (every second row),
        yielded in recording order (top field first for ``"tff"``), the
        second half a frame interval after the first: twice the rate, half
        the rows (see :attr:`Frame.row_offset`).

    Yields
    ------
    Frame

    Raises
    ------
    ServoscopeError
        When the file cannot be opened, or it breaks before the first frame.
        A video that breaks later ends early; the caller sees fewer frames.
    """
    _check_fields(path, fields)
    if is_frame_source(path):
        yield from (Frame(i, t, rgb) for i, t, rgb in iter_source(path, to_rgb8))
        return
    path = Path(path)
    container = _open(path)
    try:
        stream = container.streams.video[0]
        configure_decoder(stream, threads)
        time_base = stream.time_base or Fraction(1, 1)
        rate = stream.average_rate or stream.guessed_rate
        index = 0
        last_time = None
        try:
            for frame in container.decode(stream):
                time_s = last_time = _frame_time_s(frame, time_base, rate, last_time)
                rgb = _in_file(path, frame_rgb, frame)
                intra = is_intra(frame)
                if fields is None:
                    yield Frame(index, time_s, rgb, intra=intra)
                    index += 1
                    continue
                half = 0.5 / float(rate) if rate else 0.0
                order = (0, 1) if fields == "tff" else (1, 0)
                for k, parity in enumerate(order):
                    yield Frame(index, time_s + k * half, np.ascontiguousarray(rgb[parity::2]), parity, 2, intra)
                    index += 1
        except av.error.FFmpegError as exc:
            if index == 0:
                raise ServoscopeError(f"{path}: cannot decode any frame ({_reason(exc)})") from None
            # A recording cut short: the frames before the break are good.
            return
        if index == 0:
            raise ServoscopeError(f"{path}: contains no decodable frames")
    finally:
        container.close()


@dataclass
class YuvFrame:
    """One decoded frame as its native YUV 4:2:0 planes (no RGB conversion).

    The planes are views of the decoder's own buffers (no copy: copying the
    three planes of a 720×576 frame costs ~0.1 ms, a tenth of decoding an
    H.264 frame); rows may be padded (strided arrays).

    Attributes
    ----------
    index, time_s, row_offset, row_step
        As :class:`Frame`.
    y : ndarray, shape (rows, width), uint8
        Luma of the frame, or of one field (every second row).
    u, v : ndarray, shape (height/2, width/2), uint8
        The whole frame's chroma planes (Cb, Cr), shared by both fields: a
        kernel maps image row ``j`` to frame row ``row_offset + row_step·j``.
    luma : ndarray, shape (height, width), uint8
        The whole frame's luma plane (``y`` is ``luma`` or one field of it).
    intra : bool
        As :attr:`Frame.intra`.
    """

    index: int
    time_s: float
    y: np.ndarray
    u: np.ndarray
    v: np.ndarray
    luma: np.ndarray
    row_offset: int = 0
    row_step: int = 1
    intra: bool = True
    _i420: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    @property
    def i420(self) -> np.ndarray:
        """The planes as one contiguous array (PyAV's yuv420p layout, shape (height·3/2, width)).

        Made on first use only: the per-frame fast path never needs it.
        """
        if self._i420 is None:
            self._i420 = i420_of_planes(self.luma, self.u, self.v)
        return self._i420

    @property
    def rgb(self) -> np.ndarray:
        """The frame (or field) as RGB uint8, converted on demand (BT.601 limited range)."""
        import cv2

        rgb = cv2.cvtColor(self.i420, cv2.COLOR_YUV2RGB_I420)
        if self.row_step == 1:
            return rgb
        return np.ascontiguousarray(rgb[self.row_offset::self.row_step])

    def to_frame_xy(self, xy_px: np.ndarray) -> np.ndarray:
        """Points in this image (px, shape (..., 2)) in full-frame coordinates."""
        xy = np.array(xy_px, dtype=np.float64, copy=True)
        xy[..., 1] = self.row_offset + self.row_step * xy[..., 1]
        return xy


_END = object()


#: Decoder threads when a caller passes 0 (0 here: the budget, then :func:`default_decoder_threads`).
#: A process that runs one video per core (``bench``'s one-core runs) sets 1 here so that its
#: decoders do not compete with each other for the same cores.
DECODER_THREADS = 0

#: Environment variable with the threads one video may use in this process (decoder threads,
#: OpenCV's pool): what a campaign's Dask workers are given (cores / workers), as Dask gives
#: them one BLAS/OpenMP thread each; ``dask worker`` processes started by hand may set it too.
THREADS_ENV = "SERVOSCOPE_THREADS"


def thread_budget() -> int:
    """Threads one video may use in this process: ``SERVOSCOPE_THREADS``, or 0 (no limit set)."""
    text = os.environ.get(THREADS_ENV, "").strip()
    try:
        return max(0, int(text)) if text else 0
    except ValueError:
        return 0


def default_decoder_threads() -> int:
    """Decoder threads when nothing else is set: three per usable core, at most 16.

    With frame threading, each H.264 frame's thread waits for the rows of
    its reference frames; FFmpeg's own choice (cores + 1 threads) then
    leaves cores idle while the tracking thread and the decoder take turns.
    Measured on 2 cores, 3000 frames of 720×576 at 20 Mbit/s, tracking:
    3 threads (FFmpeg's choice) 1190 frames/s, 4: 1220, 5: 1250,
    6: 1300, 8: 1270–1310 (docs/performance.md).
    """
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        cores = os.cpu_count() or 1
    return max(1, min(16, 3 * cores))


def configure_decoder(stream, threads: int = 0) -> None:
    """The decoder settings of every servoscope decoding loop (and of ``bench``'s decode-only run).

    Frame and slice threading (``"AUTO"``); ``threads`` decoder threads, 0
    meaning :data:`DECODER_THREADS`, then ``SERVOSCOPE_THREADS``, then
    :func:`default_decoder_threads`.
    """
    stream.thread_type = "AUTO"
    stream.codec_context.thread_count = threads or DECODER_THREADS or thread_budget() or default_decoder_threads()


def is_intra(frame) -> bool:
    """Whether a decoded frame was coded on its own (an I-frame or a key frame).

    Such a frame's picture does not lean on other frames' motion
    compensation, so a motion the codec smooths or holds back in the frames
    predicted from others is where it is in this one (docs/accuracy.md,
    "The codec check").
    """
    return bool(frame.key_frame) or int(frame.pict_type) == 1  # AV_PICTURE_TYPE_I


def _decode_into(path: Path, q, stop, threads: int) -> None:
    """Decoder thread: (time_s, (y, u, v), rate) items into ``q``; then _END, or the exception."""
    import queue as _queue

    def put(item) -> bool:
        while not stop.is_set():
            try:
                q.put(item, timeout=0.1)
                return True
            except _queue.Full:
                continue
        return False

    try:
        container = _open(path)
    except BaseException as exc:  # noqa: BLE001 - handed to the consumer
        put(exc)
        return
    try:
        stream = container.streams.video[0]
        configure_decoder(stream, threads)
        time_base = stream.time_base or Fraction(1, 1)
        rate = stream.average_rate or stream.guessed_rate
        rate_hz = float(rate) if rate else 0.0
        last_time = None
        n = 0
        try:
            for frame in container.decode(stream):
                time_s = last_time = _frame_time_s(frame, time_base, rate, last_time)
                if not put((time_s, _in_file(path, yuv_planes, frame), rate_hz, is_intra(frame))):
                    return
                n += 1
        except av.error.FFmpegError as exc:
            if n == 0:
                put(ServoscopeError(f"{path}: cannot decode any frame ({_reason(exc)})"))
                return
        if n == 0:
            put(ServoscopeError(f"{path}: contains no decodable frames"))
            return
        put(_END)
    except BaseException as exc:  # noqa: BLE001
        put(exc)
    finally:
        container.close()


def iter_yuv_frames(path: str | Path, *, threads: int = 0, fields: str | None = None,
                    queue_size: int = 8) -> Iterator[YuvFrame]:
    """Decode a video's frames as YUV 4:2:0 planes, on a decoder thread, streaming.

    A decoder thread fills a bounded queue (``queue_size`` frames) while the
    caller works on the previous frames: decoding and tracking overlap, and
    memory stays bounded whatever the video's length. Frames in other pixel
    formats are converted to yuv420p (odd sizes cropped by one pixel).

    Parameters and errors as :func:`iter_frames`; yields :class:`YuvFrame`.
    """
    import queue as _queue
    import threading

    _check_fields(path, fields)
    if is_frame_source(path):
        # Frames read and converted one at a time on a reader thread, queue_size ahead: memory flat.
        yield from (YuvFrame(i, t, *yuv, yuv[0]) for i, t, yuv in prefetch(iter_source(path, to_yuv420), queue_size))
        return
    path = Path(path)
    q: _queue.Queue = _queue.Queue(maxsize=max(1, int(queue_size)))
    stop = threading.Event()
    worker = threading.Thread(target=_decode_into, args=(path, q, stop, threads), name="servoscope-decode",
                              daemon=True)
    worker.start()
    index = 0
    try:
        while True:
            item = q.get()
            if item is _END:
                return
            if isinstance(item, BaseException):
                raise item
            time_s, (y, u, v), rate, intra = item
            if fields is None:
                yield YuvFrame(index, time_s, y, u, v, y, intra=intra)
                index += 1
                continue
            half = 0.5 / rate if rate else 0.0
            order = (0, 1) if fields == "tff" else (1, 0)
            for k, parity in enumerate(order):
                yield YuvFrame(index, time_s + k * half, y[parity::2], u, v, y, parity, 2, intra)
                index += 1
    finally:
        stop.set()
        while worker.is_alive():
            try:
                q.get(timeout=0.05)
            except _queue.Empty:
                pass
        worker.join()
