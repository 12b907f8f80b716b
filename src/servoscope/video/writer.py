"""Write RGB frames to a video file with exact, frame-indexed timestamps.

Four codecs:

* ``"h264"``: libx264, yuv420p, constant *average* bit rate, in an MP4 (or
  MOV) container — what a camcorder records. The default 20 Mbit/s is a
  typical camcorder rate; the paper's HDV camera (Sony HVR-Z7E) records
  25 Mbit/s (MPEG-2). The default x264 preset is ``ultrafast``: at these
  bit rates its quality is ample, and it is the only preset that keeps the
  simulator's budget (a 300-frame 720×576 dwell rendered and encoded in
  under 3 s on one core; ``superfast`` alone takes ~11 ms per frame).
  The encoder runs single-threaded by default so that the same input gives
  the same bytes on every machine (x264's output depends on its thread count).
* ``"mpeg2"``: MPEG-2 video (FFmpeg's ``mpeg2video``), yuv420p, in an MPEG
  transport stream (``.ts``/``.m2t``, what HDV camcorders write) or program
  stream (``.mpg``): the paper's camera's codec, at 25 Mbit/s there. A GOP
  of 15 frames with 2 B-frames between references, as HDV's; a single
  encoder thread, deterministic.
* ``"hevc"``: H.265 (libx265) in MP4 or MOV, as phones and action cameras
  record; one frame thread, deterministic like h264. (Through FFmpeg 8,
  libx265 now and then leaves a clip of one or two frames without
  timestamps and the muxer fails: write three or more.)
* ``"raw"``: uncompressed yuv420p (``rawvideo``) in AVI or NUT; both carry
  the stream time base 1/fps exactly, so decoded ``frame.time == i / fps``.
  (Matroska is not offered: its millisecond time base cannot represent
  e.g. 30000/1001 fps.)

Frame ``i`` gets ``pts = i`` in time base ``1/fps``, unless the caller gives
each frame's time (variable frame rate, h264/hevc only, with a finer
``time_base``).

What real cameras write besides (h264 and hevc only; the defaults write
none of it, and their bytes are unchanged): 10-bit and 4:2:2 pixel formats
(``pix_fmt``), full-range ("PC", JPEG) YUV (``color_range="pc"``), a BT.709
matrix (``matrix="bt709"``), each tagged in the stream as cameras tag it, and
a phone's rotation (``rotation_deg``: the container's display matrix). Those
samples are computed from RGB by the standard equations
(:func:`servoscope.video.colour.encode_ycbcr`), not by libswscale.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path
from types import TracebackType

import av
import numpy as np

from numba import njit

from ..errors import ServoscopeError
from .colour import COLORSPACE_CODES, MATRICES, encode_ycbcr, layout_of_format

__all__ = ["VideoWriter", "CODECS", "LOSSY", "PIX_FMTS", "COLOR_RANGES", "CAMERA_CODECS", "container_suffixes",
           "rgb_to_yuv420p"]

#: Codec name → allowed file suffixes.
CODECS: dict[str, tuple[str, ...]] = {"h264": (".mp4", ".mov"), "mpeg2": (".ts", ".m2t", ".mpg"),
                                      "raw": (".avi", ".nut"), "hevc": (".mp4", ".mov")}

#: Codecs with a bit rate (the others are lossless).
LOSSY = ("h264", "mpeg2", "hevc")

#: Codecs that take the camera options (pix_fmt, color_range, matrix, rotation_deg, time_base).
CAMERA_CODECS = ("h264", "hevc")

#: Pixel formats the writer offers (h264 and hevc): 8/10-bit, 4:2:0/4:2:2.
PIX_FMTS = ("yuv420p", "yuv420p10le", "yuv422p", "yuv422p10le")

#: ``color_range`` values: limited ("TV", 16–235 at 8 bits) or full ("PC", JPEG, 0–255).
COLOR_RANGES = ("tv", "pc")

#: FFmpeg's encoder for each lossy codec.
_ENCODERS = {"h264": "libx264", "hevc": "libx265", "mpeg2": "mpeg2video"}


def container_suffixes(codec: str) -> tuple[str, ...]:
    """File suffixes accepted for ``codec`` (the first is the preferred one)."""
    try:
        return CODECS[codec]
    except KeyError:
        raise ServoscopeError(f"unknown codec {codec!r} (choose from {sorted(CODECS)})") from None


@njit(cache=True)
def _rgb_to_yuv420p(rgb: np.ndarray, out: np.ndarray) -> None:
    # Luma row by row and chroma from pairs of rows, each a plain loop over a contiguous row that LLVM
    # vectorizes (a loop over 2x2 blocks, luma and chroma together, did not: ten times slower). The same float32
    # expressions as one pass over the blocks; a block's sums are of integers under 2**24, exact in any order.
    h, w = rgb.shape[0], rgb.shape[1]
    hw, ww = h // 2, w // 2
    cb_off = h * w
    cr_off = cb_off + hw * ww
    flat = out.ravel()
    src = rgb.reshape(h, w * 3)
    for y in range(2 * hw):
        row = src[y]
        luma_row = flat[y * w:y * w + 2 * ww]
        for x in range(2 * ww):
            r = np.float32(row[3 * x])
            g = np.float32(row[3 * x + 1])
            b = np.float32(row[3 * x + 2])
            luma = np.float32(16.5) + (np.float32(65.481) * r + np.float32(128.553) * g
                                       + np.float32(24.966) * b) * np.float32(1.0 / 255.0)
            luma_row[x] = np.uint8(np.int32(luma))
    k = np.float32(0.25 / 255.0)
    for by in range(hw):
        top = src[2 * by]
        bottom = src[2 * by + 1]
        cb_row = flat[cb_off + by * ww:cb_off + (by + 1) * ww]
        cr_row = flat[cr_off + by * ww:cr_off + (by + 1) * ww]
        for bx in range(ww):
            i = 6 * bx
            rs = np.float32(top[i]) + np.float32(top[i + 3]) + np.float32(bottom[i]) + np.float32(bottom[i + 3])
            gs = (np.float32(top[i + 1]) + np.float32(top[i + 4]) + np.float32(bottom[i + 1])
                  + np.float32(bottom[i + 4]))
            bs = (np.float32(top[i + 2]) + np.float32(top[i + 5]) + np.float32(bottom[i + 2])
                  + np.float32(bottom[i + 5]))
            u = np.float32(128.5) + (np.float32(-37.797) * rs - np.float32(74.203) * gs + np.float32(112.0) * bs) * k
            v = np.float32(128.5) + (np.float32(112.0) * rs - np.float32(93.786) * gs - np.float32(18.214) * bs) * k
            cb_row[bx] = np.uint8(np.int32(u))
            cr_row[bx] = np.uint8(np.int32(v))


def rgb_to_yuv420p(frame_rgb_uint8: np.ndarray) -> np.ndarray:
    """BT.601 limited-range ("TV") RGB → planar yuv420p, as FFmpeg's default.

    Chroma is the mean of each 2×2 block (centre-sited). Faster than
    libswscale's generic path, which took ~2 ms per 720×576 frame.

    Parameters
    ----------
    frame_rgb_uint8 : ndarray of uint8, shape (h, w, 3), h and w even

    Returns
    -------
    ndarray of uint8, shape (h * 3 // 2, w)
        Y plane, then Cb, then Cr (PyAV's yuv420p ndarray layout).
    """
    a = np.ascontiguousarray(frame_rgb_uint8, dtype=np.uint8)
    h, w = a.shape[:2]
    out = np.empty((h * 3 // 2, w), dtype=np.uint8)
    _rgb_to_yuv420p(a, out)
    return out


def _as_fraction(fps: float | int | Fraction) -> Fraction:
    try:
        f = Fraction(fps)
    except (TypeError, ValueError):
        raise ServoscopeError(f"frame rate must be a positive number, not {fps!r}") from None
    # A float like 29.97 becomes 2997/100 rather than its binary expansion.
    f = f.limit_denominator(1_000_000)
    if f <= 0:
        raise ServoscopeError(f"frame rate must be positive, not {fps!r}")
    return f


class VideoWriter:
    """Context manager writing RGB uint8 frames to a video file.

    Parameters
    ----------
    path : str or Path
        Output file; its suffix must suit the codec (``.mp4``/``.mov`` for
        h264 and hevc, ``.ts``/``.m2t``/``.mpg`` for mpeg2, ``.avi``/``.nut`` for raw).
    width, height : int
        Frame size in pixels (even: yuv420p subsamples chroma 2×2).
    fps : float or Fraction
        Frame rate, e.g. ``100`` or ``Fraction(30000, 1001)`` (with explicit
        frame times, the nominal rate the encoder's rate control assumes).
    codec : {"h264", "hevc", "mpeg2", "raw"}
        H.264 (libx264), H.265 (libx265), MPEG-2 (HDV's) or uncompressed yuv420p.
    bit_rate : int
        Average bit rate of the lossy codecs, bit/s (20 Mbit/s: a camcorder's
        rate; the paper's HDV camera records 25 Mbit/s). Ignored for raw.
    preset : str
        x264 / x265 speed preset.
    threads : int
        Encoder threads; 1 (default) makes the bytes machine-independent.
    gop : int, optional
        Frames from one intra-coded frame to the next (the GOP length):
        default x264's 250 for h264 and HDV's 15 for mpeg2; camcorders'
        AVCHD uses 12–15 at 25/30 frames/s.
    pix_fmt : {"yuv420p", "yuv420p10le", "yuv422p", "yuv422p10le"}
        Samples as stored (h264 and hevc): 8 or 10 bits, 4:2:0 or 4:2:2.
    color_range : {None, "tv", "pc"}
        None: untagged limited range (the default bytes); "tv": limited,
        tagged; "pc": full range (JPEG YUV, what phones often record), tagged.
    matrix : {None, "bt601", "bt709", "bt2020", ...}
        None: untagged BT.601 (the default bytes); otherwise the matrix the
        samples are computed with, tagged in the stream (colour primaries and
        transfer tagged alike).
    rotation_deg : {0, 90, 180, 270}
        Counter-clockwise rotation a player applies to show the frames upright
        (the container's display matrix, as phones write it; FFmpeg's and
        PyAV's ``rotation`` convention). The frames are stored as given.
    time_base : Fraction, optional
        Unit of the frames' timestamps (default ``1/fps``). A finer one (e.g.
        ``Fraction(1, 90000)``, MPEG's clock; phones use 1/600 or 1/90000) lets
        :meth:`write` take each frame's own time: variable frame rate.

    Examples
    --------
    >>> with VideoWriter("out.mp4", 720, 576, 100) as w:  # doctest: +SKIP
    ...     w.write(frame_rgb_uint8)
    """

    def __init__(self, path: str | Path, width: int, height: int, fps: float | Fraction, *,
                 codec: str = "h264", bit_rate: int = 20_000_000, preset: str = "ultrafast",
                 threads: int = 1, gop: int | None = None, pix_fmt: str = "yuv420p",
                 color_range: str | None = None, matrix: str | None = None, rotation_deg: int = 0,
                 time_base: Fraction | None = None) -> None:
        self.path = Path(path)
        suffixes = container_suffixes(codec)
        if self.path.suffix.lower() not in suffixes:
            raise ServoscopeError(f"{self.path}: a {codec} video needs a file ending in {' or '.join(suffixes)}")
        if width <= 0 or height <= 0 or width % 2 or height % 2:
            raise ServoscopeError(f"video size {width}x{height}: width and height must be positive and even")
        if gop is not None and not int(gop) >= 1:
            raise ServoscopeError(f"GOP must be at least 1 frame, not {gop}")
        if codec in LOSSY and not bit_rate > 0:
            raise ServoscopeError(f"bit rate must be positive, not {bit_rate}")
        self._check_camera_options(codec, pix_fmt, color_range, matrix, rotation_deg, time_base)
        self.width, self.height = int(width), int(height)
        self.fps = _as_fraction(fps)
        self.codec = codec
        self.bit_rate = int(bit_rate)
        self.time_base = 1 / self.fps if time_base is None else Fraction(time_base)
        self.pix_fmt = pix_fmt
        self.color_range = color_range
        self.matrix = matrix
        self.rotation_deg = int(rotation_deg) % 360
        # The writer's own 8-bit path (numba, bit-identical to before) unless a camera option changes the samples.
        self._layout = None
        if pix_fmt != "yuv420p" or color_range == "pc" or matrix not in (None, "bt601"):
            self._layout = layout_of_format(pix_fmt, 2 if color_range == "pc" else 1,
                                            COLORSPACE_CODES[matrix or "bt601"])
        self.frames_written = 0
        self._last_pts: int | None = None
        # With explicit frame times the first frame need not be at 0; MP4's edit list states that offset
        # in the movie time scale (1 ms by default), which would shift every frame: use the stream's own.
        options = {} if time_base is None else {"movie_timescale": str(self.time_base.denominator)}
        self._container = av.open(str(self.path), mode="w", options=options)
        try:
            if codec in ("h264", "hevc"):
                stream = self._container.add_stream(_ENCODERS[codec], rate=self.fps)
                stream.bit_rate = self.bit_rate
                if codec == "h264":
                    stream.options = {"preset": preset}
                else:
                    # One frame thread: the same bytes on every run (checked: 3 runs, 20 frames, 8 and
                    # 10 bits). Pinning x265's worker pool ("pools=") made it lose some packets' times.
                    stream.options = {"preset": preset,
                                      "x265-params": "log-level=error:frame-threads=1"}
                if gop is not None:
                    stream.codec_context.gop_size = int(gop)  # x264's / x265's keyint
            elif codec == "mpeg2":
                stream = self._container.add_stream(_ENCODERS[codec], rate=self.fps)
                stream.bit_rate = self.bit_rate
                stream.codec_context.gop_size = 15 if gop is None else int(gop)
                stream.codec_context.max_b_frames = 2
            else:
                stream = self._container.add_stream("rawvideo", rate=self.fps)
            stream.width = self.width
            stream.height = self.height
            stream.pix_fmt = pix_fmt
            stream.time_base = self.time_base
            stream.codec_context.time_base = self.time_base
            stream.codec_context.thread_count = int(threads)
            if color_range is not None:
                stream.codec_context.color_range = 2 if color_range == "pc" else 1
            if matrix is not None:
                code = COLORSPACE_CODES[matrix]
                stream.codec_context.colorspace = code
                # Primaries and transfer as cameras tag them with that matrix (same H.273 code points).
                stream.codec_context.color_primaries = code
                stream.codec_context.color_trc = {"bt2020": 14}.get(matrix, code)
            if self.rotation_deg:
                stream.set_display_rotation(self.rotation_deg)
        except Exception:
            self._container.close()
            raise
        self._stream = stream

    @staticmethod
    def _check_camera_options(codec: str, pix_fmt: str, color_range: str | None, matrix: str | None,
                              rotation_deg: int, time_base: Fraction | None) -> None:
        if pix_fmt not in PIX_FMTS:
            raise ServoscopeError(f"pixel format {pix_fmt!r}: choose from {', '.join(PIX_FMTS)}")
        if color_range not in (None, *COLOR_RANGES):
            raise ServoscopeError(f"colour range {color_range!r}: choose 'tv' (limited) or 'pc' (full, JPEG)")
        if matrix is not None and matrix not in MATRICES:
            raise ServoscopeError(f"colour matrix {matrix!r}: choose from {', '.join(MATRICES)}")
        if int(rotation_deg) % 90:
            raise ServoscopeError(f"rotation {rotation_deg}°: a phone's rotation is a multiple of 90°")
        if time_base is not None and not Fraction(time_base) > 0:
            raise ServoscopeError(f"time base must be positive, not {time_base}")
        given = [name for name, on in (("pix_fmt", pix_fmt != "yuv420p"), ("color_range", color_range is not None),
                                       ("matrix", matrix is not None), ("rotation_deg", int(rotation_deg) % 360),
                                       ("time_base", time_base is not None)) if on]
        if given and codec not in CAMERA_CODECS:
            raise ServoscopeError(f"{', '.join(given)}: offered for {' and '.join(CAMERA_CODECS)} only, not {codec}")

    def __enter__(self) -> "VideoWriter":
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def write(self, frame_rgb_uint8: np.ndarray, time_s: float | None = None) -> float:
        """Append one frame.

        Parameters
        ----------
        frame_rgb_uint8 : ndarray of uint8, shape (height, width, 3)
            RGB frame.
        time_s : float, optional
            The frame's presentation time, s, rounded to the time base (frames
            must come in increasing time). Default ``frames_written / fps``.

        Returns
        -------
        float
            The time stored (``pts × time_base``), what a reader gets back.
        """
        a = np.asarray(frame_rgb_uint8)
        if a.dtype != np.uint8 or a.shape != (self.height, self.width, 3):
            raise ServoscopeError(
                f"frame must be uint8 of shape {(self.height, self.width, 3)}, not {a.dtype} {a.shape}")
        if time_s is None:
            pts = round(self.frames_written / (self.fps * self.time_base))  # = frames_written at 1/fps
        else:
            if not np.isfinite(time_s) or time_s < 0:
                raise ServoscopeError(f"{self.path}: frame time {time_s} s must be finite and ≥ 0")
            pts = round(Fraction(float(time_s)) / self.time_base)
        if self._last_pts is not None and pts <= self._last_pts:
            raise ServoscopeError(f"{self.path}: frame time {float(pts * self.time_base)} s is not after the previous "
                                  f"frame's ({float(self._last_pts * self.time_base)} s) at time base {self.time_base}")
        if self._layout is None:
            frame = av.VideoFrame.from_ndarray(rgb_to_yuv420p(a), format="yuv420p")
        else:
            frame = _planar_frame(encode_ycbcr(a, matrix=self._layout.matrix, full_range=self._layout.full_range,
                                               bit_depth=self._layout.bit_depth, factors=self._layout.factors),
                                  self.pix_fmt)
        self._encode(frame, pts)
        return float(pts * self.time_base)

    def write_yuv420p(self, i420: np.ndarray) -> float:
        """Append one frame given as its 8-bit planes, PyAV's yuv420p layout (the Y plane, then Cb, then Cr).

        What :meth:`write` encodes after its RGB conversion, so a lossless (raw) file's frames re-encoded this
        way give the same bytes as the frames written again (:func:`servoscope.simulate.reencode_campaign`).
        For the writer's default samples only (yuv420p, limited range, BT.601); the frame's time as
        :meth:`write`'s default, ``frames_written / fps``.
        """
        a = np.asarray(i420)
        if a.dtype != np.uint8 or a.shape != (self.height * 3 // 2, self.width):
            raise ServoscopeError(
                f"{self.path}: yuv420p planes must be uint8 of shape {(self.height * 3 // 2, self.width)}, not "
                f"{a.dtype} {a.shape}")
        if self._layout is not None or self.color_range is not None or self.matrix is not None:
            raise ServoscopeError(f"{self.path}: yuv420p planes are written as they are: not with camera options "
                                  "(pix_fmt, color_range, matrix)")
        pts = round(self.frames_written / (self.fps * self.time_base))  # write()'s default time
        self._encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(a), format="yuv420p"), pts)
        return float(pts * self.time_base)

    def _encode(self, frame: av.VideoFrame, pts: int) -> None:
        if self.color_range is not None:
            frame.color_range = 2 if self.color_range == "pc" else 1
        if self.matrix is not None:
            frame.colorspace = COLORSPACE_CODES[self.matrix]
        frame.pts = pts
        frame.time_base = self.time_base
        for packet in self._stream.encode(frame):
            self._container.mux(packet)
        self.frames_written += 1
        self._last_pts = pts

    def close(self) -> None:
        """Flush the encoder and close the file (idempotent)."""
        if self._container is None:
            return
        try:
            for packet in self._stream.encode(None):
                self._container.mux(packet)
        finally:
            self._container.close()
            self._container = None


def _planar_frame(planes: tuple[np.ndarray, np.ndarray, np.ndarray], pix_fmt: str) -> av.VideoFrame:
    """A VideoFrame of ``pix_fmt`` holding the given Y, Cb, Cr code values (rows padded to line_size)."""
    y = planes[0]
    frame = av.VideoFrame(y.shape[1], y.shape[0], pix_fmt)
    for plane, data in zip(frame.planes, planes):
        row = plane.line_size // data.itemsize
        padded = np.zeros((data.shape[0], row), data.dtype)
        padded[:, :data.shape[1]] = data
        plane.update(padded.astype(data.dtype.newbyteorder("<"), copy=False).tobytes())
    return frame
