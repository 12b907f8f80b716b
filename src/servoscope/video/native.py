"""Monochrome frames as the camera stored them: native samples, memory-mapped, no 8-bit rounding.

The monochrome engine (:mod:`servoscope.markers.mono_engine`) reads a few
windows of each frame; converting whole frames to 8-bit RGB or YUV (what
:func:`~servoscope.video.reader.iter_frames` and
:func:`~servoscope.video.reader.iter_yuv_frames` do) costs more than its
measurement and rounds 12-bit samples away. :func:`iter_native_frames` gives
each frame as a :class:`NativeFrame`: a 2-D array of the stored samples,

* **Photron MRAW**: a view of the file, memory-mapped once (8-bit and 16-bit
  words as they are; 12-bit samples as the packed bytes, two samples in three
  bytes, which :func:`sample_at` decodes where the kernel reads them, so that
  only the windows' rows are ever touched);
* **Phantom CINE**: a view of the file at the image offset pims reads
  (``image_locations`` plus the image's own header size), rows bottom-up as
  the file stores them (a negative-stride view); packed 10/12-bit CINEs are
  read and unpacked by pims;
* **image sequences**: each file read (on a reader thread, as the YUV path does);
* **video files** (gray footage in H.264…) and colour or raw Bayer frames:
  the 8-bit luma plane the YUV path makes (:func:`~servoscope.video.reader.iter_yuv_frames`).

No frame is copied whole except where the file is not an array of samples
(TIFF, packed CINE, video). The whole-frame 8-bit RGB image (the first frame's
detection, a lost marker's search, snapshots) is made on demand
(:attr:`NativeFrame.rgb`), as :func:`~servoscope.video.frame_source.to_rgb8` makes it.

**Levels.** A sample ``v`` is the 8-bit level ``(v − black) · 255 / (white − black)``
(unrounded): ``black`` 0 and ``white`` ``2^n − 1`` for an ``n``-bit source (a
16-bit word whose samples sit in its high bits: ``white`` shifted likewise,
so that no shift is needed per sample), 16 and 235 for a video's luma.
"""

from __future__ import annotations

import mmap
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
from numba import njit

from .frame_source import is_frame_source, to_rgb8
from .highspeed import PhantomCine, PhotronMraw
from .sources import open_frame_source, prefetch

__all__ = ["NativeFrame", "NativeSource", "iter_native_frames", "sample_at", "unpack_rows"]

#: Limited-range luma of black and white (a video file's gray levels).
VIDEO_BLACK_DN, VIDEO_WHITE_DN = 16.0, 235.0


@njit(cache=True, nogil=True, inline="always")
def sample_at(img, y, x, packed):
    """Sample (y, x) of a frame as a float: ``img[y, x]``, or decoded from Photron's packed 12-bit bytes.

    Packed (``packed`` true): row ``y`` of ``img`` holds the row's samples two in
    three bytes, big-endian nibbles (:func:`~servoscope.video.highspeed.unpack_12bit`).
    """
    if packed:
        k = (x >> 1) * 3
        if (x & 1) == 0:
            return float((np.int32(img[y, k]) << 4) | (np.int32(img[y, k + 1]) >> 4))
        return float(((np.int32(img[y, k + 1]) & 15) << 8) | np.int32(img[y, k + 2]))
    return float(img[y, x])


@njit(cache=True, nogil=True)
def _unpack_rows_nb(img, out):
    h, w = out.shape
    for y in range(h):
        for i in range(w // 2):
            k = 3 * i
            b0 = np.uint16(img[y, k])
            b1 = np.uint16(img[y, k + 1])
            b2 = np.uint16(img[y, k + 2])
            out[y, 2 * i] = (b0 << 4) | (b1 >> 4)
            out[y, 2 * i + 1] = ((b1 & 15) << 8) | b2


def unpack_rows(packed: np.ndarray, width: int) -> np.ndarray:
    """Packed 12-bit rows (shape (h, 3·width/2), uint8) as samples, shape (h, width), uint16."""
    out = np.empty((packed.shape[0], width), np.uint16)
    _unpack_rows_nb(packed, out)
    return out


@dataclass
class NativeFrame:
    """One monochrome frame as stored: its samples (or packed bytes) and their levels.

    Attributes
    ----------
    index, time_s, intra, row_offset, row_step
        As :class:`~servoscope.video.reader.Frame` (whole frames: offset 0, step 1).
    samples : ndarray, 2-D, uint8 or uint16
        The stored samples, a view of the file where it is an array of them;
        packed 12-bit: the packed bytes, shape (height, 3·width/2).
    packed : bool
        Whether ``samples`` holds packed 12-bit bytes (:func:`sample_at` reads them).
    width : int
    bit_depth : int
        The samples' real bits (8 for a video's luma).
    black, white : float
        The sample values of 8-bit 0 and 255 (see the module's notes).
    shift : int
        Bits the samples sit above a 16-bit word's low end (``white`` includes it).
    rgb_of : callable or None
        Makes the RGB image (a video's decoder does); None: from the samples.
    """

    index: int
    time_s: float
    samples: np.ndarray
    packed: bool
    width: int
    bit_depth: int
    black: float
    white: float
    shift: int = 0
    intra: bool = True
    row_offset: int = 0
    row_step: int = 1
    rgb_of: Callable[[], np.ndarray] | None = field(default=None, repr=False, compare=False)
    _rgb: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # The samples go on read-only, whatever their source: a file's view is read-only, a decoder's or a
        # reader thread's array writeable, and numba compiles every kernel that reads them once for each
        # (2–8 s of CPU each on a fresh install, and in every test worker). A view: nothing is copied.
        if self.samples.flags.writeable:
            view = self.samples.view()
            view.flags.writeable = False
            self.samples = view

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the frame."""
        return int(self.samples.shape[0]), int(self.width)

    @property
    def gray(self) -> np.ndarray:
        """The samples as a (height, width) array of their real bits (packed 12-bit unpacked, a word's shift undone)."""
        rows = self.stored()
        return rows >> self.shift if self.shift else rows

    def stored(self, rows: slice = slice(None)) -> np.ndarray:
        """Rows of the samples as stored, as the compiled engines read them (:func:`sample_at`) and as
        ``black`` and ``white`` count them: packed 12-bit unpacked, a word's samples left in its high bits
        (:attr:`gray` shifts them down). A view where no unpacking is needed."""
        part = self.samples[rows]
        return unpack_rows(np.ascontiguousarray(part), self.width) if self.packed else part

    @property
    def rgb(self) -> np.ndarray:
        """The frame as 8-bit RGB (gray replicated), as the RGB path reads it; made on first use."""
        if self._rgb is None:
            self._rgb = (self.rgb_of() if self.rgb_of is not None
                         else to_rgb8(np.ascontiguousarray(self.gray), self.bit_depth))
        return self._rgb

    def to_8bit(self, level: float) -> float:
        """A sample level as the 8-bit level the RGB path reads (unrounded)."""
        return (level - self.black) * 255.0 / (self.white - self.black)

    def from_8bit(self, level: float) -> float:
        """An 8-bit level as a sample level."""
        return self.black + level * (self.white - self.black) / 255.0


class NativeSource:
    """A monochrome frame source opened for :class:`NativeFrame` views (see the module's notes).

    Parameters
    ----------
    path : str or Path
        A frame source (:func:`~servoscope.video.frame_source.frame_source`'s string).
    """

    def __init__(self, path: str | Path):
        self.source = open_frame_source(path)
        self.header = self.source.header
        self._mm: mmap.mmap | None = None
        self._file = None
        h = self.header
        self.width, self.height = h.width, h.height
        top = float((1 << h.bit_depth) - 1)
        self.black, self.white = 0.0, top
        self.shift = 0
        self.kind = "read"
        if isinstance(self.source, PhotronMraw) and h.monochrome:
            src = self.source
            self._map(src.mraw)
            self.kind = {8: "u1", 12: "packed", 16: "u2"}[src.word_bits]
            self.frame_bytes = src.frame_bytes
            if src.shift:
                self.shift = src.shift
                self.white = top * float(1 << src.shift)  # samples in the word's high bits, read unshifted
        elif isinstance(self.source, PhantomCine):
            c = self.source.cine
            image_bytes = int(c.bitmapinfo_dict["bi_image_size"])
            dtype = np.dtype(c.pixel_type)
            if image_bytes == self.width * self.height * dtype.itemsize and dtype.itemsize in (1, 2):
                self._map(self.source.path)
                self.kind = "cine-" + dtype.str[1:]
                self._cine_offsets = [int(at) + self._image_header(int(at)) for at in c.image_locations]

    def _map(self, path) -> None:
        self._file = open(path, "rb")
        self._mm = mmap.mmap(self._file.fileno(), 0, access=mmap.ACCESS_READ)

    def _image_header(self, at: int) -> int:
        """A CINE image's own header size (the annotation's first 4 bytes, little-endian; 8 without annotation)."""
        return int(np.frombuffer(self._mm, "<u4", 1, at)[0])  # type: ignore[arg-type]

    def view(self, index: int) -> tuple[np.ndarray, bool]:
        """Frame ``index``'s samples (a view of the file where possible) and whether they are packed 12-bit."""
        h, w = self.height, self.width
        if self.kind == "u1":
            return np.frombuffer(self._mm, np.uint8, h * w, index * self.frame_bytes).reshape(h, w), False
        if self.kind == "u2":
            return np.frombuffer(self._mm, "<u2", h * w, index * self.frame_bytes).reshape(h, w), False
        if self.kind == "packed":
            return (np.frombuffer(self._mm, np.uint8, self.frame_bytes, index * self.frame_bytes)
                    .reshape(h, w * 3 // 2), True)
        if self.kind.startswith("cine-"):
            dtype = np.dtype("<" + self.kind[5:])
            # Rows stored bottom-up (as pims flips them): a view with a negative row stride.
            return np.frombuffer(self._mm, dtype, h * w, self._cine_offsets[index]).reshape(h, w)[::-1], False
        return self.source.read(index), False

    def close(self) -> None:
        """Release the mapping and the files (views still held keep the mapping alive)."""
        if self._mm is not None:
            try:
                self._mm.close()
            except BufferError:
                pass  # a view still refers to it: released with the last view
            self._mm = None
        if self._file is not None:
            self._file.close()
            self._file = None
        self.source.close()


def iter_native_frames(path: str | Path, queue_size: int = 8) -> Iterator[NativeFrame]:
    """Each frame of a monochrome source (or a video's luma) as a :class:`NativeFrame`, in order.

    Memory-mapped files are viewed, not read: a frame costs what its windows
    touch. Image sequences are read on a reader thread, ``queue_size`` ahead.

    Raises
    ------
    ServoscopeError
        As the sources' readers do (a missing, truncated or unreadable file).
    """
    src = NativeSource(path) if is_frame_source(path) else None
    if src is None or not src.header.monochrome:
        # A video, or colour (or raw Bayer) frames: their luma, as the YUV path makes it.
        if src is not None:
            src.close()
        from .reader import iter_yuv_frames

        for f in iter_yuv_frames(path, queue_size=queue_size):
            yield NativeFrame(f.index, f.time_s, f.y, False, f.y.shape[1], 8, VIDEO_BLACK_DN, VIDEO_WHITE_DN,
                              intra=f.intra, rgb_of=lambda f=f: f.rgb)
        return
    try:
        h = src.header
        times = h.times_s
        args = (h.width, h.bit_depth, src.black, src.white, src.shift)
        if src.kind == "read":
            def read():
                for i in range(h.frame_count):
                    yield i, src.source.read(i)

            for i, samples in prefetch(read(), queue_size):
                yield NativeFrame(i, float(times[i]), samples, False, *args)
            return
        for i in range(h.frame_count):
            samples, packed = src.view(i)
            yield NativeFrame(i, float(times[i]), samples, packed, *args)
    finally:
        src.close()
