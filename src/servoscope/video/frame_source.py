"""Footage that is not a video file: image sequences and high-speed cameras' raw files.

High-speed cameras store their recordings as folders of TIFF/PNG/JPEG frames
or in their makers' raw formats (Photron MRAW with its CIH/CIHX header,
Phantom CINE). :func:`servoscope.video.reader.probe_video`,
:func:`~servoscope.video.reader.iter_frames` and
:func:`~servoscope.video.reader.iter_yuv_frames` accept them wherever they
accept a video file; this module says which paths are such sources, opens
them (:mod:`servoscope.video.sources`) and converts their samples to what the trackers read.

**A source and its options in one string.** An image sequence has no frame
rate of its own, so the rate (and optionally a start time, a timestamps
file, a Bayer pattern, the real bit depth) travels with its path, as one
string ``"<folder or glob>#fps=2000&start=0.5"`` made by
:func:`frame_source`. A string, because a campaign's tracking tasks go to
Dask worker processes as a path string and nothing else.

**Conversion** (docs/formats.md, "Image sequences and high-speed files"):
samples of ``n`` bits (8, 10, 12, 14 or 16: the camera's real depth, from the
header, not the 16-bit word they are stored in) are scaled to 8 bits by
``round(v · 255 / (2^n − 1))``: 12-bit full scale (4095) is 255, nothing is
clipped or stretched to the frame's own range. Colour frames then go to
8-bit 4:2:0 limited-range BT.601 by the same equations as servoscope's video
writer (:func:`servoscope.video.writer.rgb_to_yuv420p`), so a 16-bit TIFF of
an 8-bit frame (``v · 257``) gives the very planes the twin's uncompressed
video gives. Monochrome frames give ``Y = 16 + round(219 · v / (2^n − 1))``
(the gray level in the limited range the trackers' colour model reads) and
neutral chroma (128). Raw Bayer frames are demosaiced (OpenCV, bilinear) on
their ``n``-bit samples first.
"""

from __future__ import annotations

import glob as _glob

from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Protocol
from urllib.parse import parse_qsl, quote, urlencode

import numpy as np

from ..errors import ServoscopeError

__all__ = ["SOURCE_SEPARATOR", "RAW_SUFFIXES", "IMAGE_SUFFIXES", "BAYER_PATTERNS", "SourceSpec", "SourceHeader",
           "FrameSource", "frame_source", "parse_frame_source", "is_frame_source", "MANIFEST_KEYS", "manifest_frame_source",
           "to_rgb8", "to_yuv420", "demosaic", "regularity", "regular_times", "source_name"]

#: Between a source's path and its options.
SOURCE_SEPARATOR = "#"
#: High-speed cameras' raw files (a header's suffix opens its MRAW too).
RAW_SUFFIXES = (".mraw", ".cih", ".cihx", ".cine")
#: Image files an image sequence may hold.
IMAGE_SUFFIXES = (".tif", ".tiff", ".png", ".jpg", ".jpeg")
#: Bayer patterns (the colours of the top-left 2×2 block, row by row) → OpenCV's conversion name.
#: OpenCV names a pattern by the second row's second and third pixels, hence the shift.
BAYER_PATTERNS = {"RGGB": "COLOR_BayerBG2RGB", "BGGR": "COLOR_BayerRG2RGB", "GRBG": "COLOR_BayerGB2RGB",
                  "GBRG": "COLOR_BayerGR2RGB"}
_OPTIONS = {"fps", "start", "timestamps", "bayer", "bits"}


@dataclass(frozen=True)
class SourceSpec:
    """A frame source's path and the options given with it (command line or manifest).

    Attributes
    ----------
    path : str
        Folder, glob, or raw file.
    fps : float or None
        Frame rate given by the user, frames/s (image sequences need it, or ``timestamps``).
    start_s : float
        Time of the first frame, s.
    timestamps : str or None
        A text file with one time (s) per frame, one per line.
    bayer : str or None
        Raw Bayer frames' pattern (a key of :data:`BAYER_PATTERNS`).
    bits : int or None
        The samples' real bit depth where the file does not say it (a 12-bit
        camera's frames in 16-bit TIFFs).
    """

    path: str
    fps: float | None = None
    start_s: float = 0.0
    timestamps: str | None = None
    bayer: str | None = None
    bits: int | None = None


def frame_source(path: str | Path, *, fps: float | None = None, start_s: float = 0.0,
                 timestamps: str | Path | None = None, bayer: str | None = None, bits: int | None = None) -> str:
    """The path string of a frame source with its options (what the readers accept).

    Parameters
    ----------
    path : path-like
        A folder or glob of images, or an MRAW/CIH/CINE file.
    fps, start_s, timestamps, bayer, bits
        As :class:`SourceSpec`; left out of the string when not given.

    Returns
    -------
    str
        ``path`` itself when no option is given, else ``"path#fps=…&…"``.

    Examples
    --------
    >>> frame_source("dwell_01/*.tif", fps=2000)
    'dwell_01/*.tif#fps=2000'
    """
    options = {}
    if fps is not None:
        options["fps"] = f"{float(fps):.17g}"
    if start_s:
        options["start"] = f"{float(start_s):.17g}"
    if timestamps is not None:
        options["timestamps"] = str(timestamps)
    if bayer is not None:
        options["bayer"] = str(bayer)
    if bits is not None:
        options["bits"] = str(int(bits))
    text = str(path)
    return text if not options else text + SOURCE_SEPARATOR + urlencode(options, quote_via=quote, safe="/")


def _number(text: str, name: str, where: str, kind=float):
    try:
        value = kind(text)
    except ValueError:
        raise ServoscopeError(f"{where}: {name} must be a number, not {text!r}") from None
    if not np.isfinite(value):
        raise ServoscopeError(f"{where}: {name} must be finite, not {text!r}")
    return value


def parse_frame_source(path: str | Path) -> SourceSpec:
    """A frame source's path and options, from the string :func:`frame_source` makes.

    Raises
    ------
    ServoscopeError
        For an unknown option or a value out of range.
    """
    text = str(path)
    base, sep, query = text.partition(SOURCE_SEPARATOR)
    if not sep or "=" not in query or Path(text).exists():
        return SourceSpec(text)  # a '#' in a file's own name ("take#2.mp4") is not an option
    options = dict(parse_qsl(query, keep_blank_values=True))
    unknown = set(options) - _OPTIONS
    if unknown:
        raise ServoscopeError(f"{base}: unknown frame-source option(s) {sorted(unknown)} (known: {sorted(_OPTIONS)})")
    spec = SourceSpec(base)
    if "fps" in options:
        fps = _number(options["fps"], "the frame rate", base)
        if fps <= 0:
            raise ServoscopeError(f"{base}: the frame rate must be > 0 frames/s, not {fps:g}")
        spec = replace(spec, fps=fps)
    if "start" in options:
        spec = replace(spec, start_s=_number(options["start"], "the start time", base))
    if "timestamps" in options:
        spec = replace(spec, timestamps=options["timestamps"])
    if "bayer" in options:
        pattern = options["bayer"].upper()
        if pattern not in BAYER_PATTERNS:
            raise ServoscopeError(f"{base}: Bayer pattern {options['bayer']!r} is not one of {sorted(BAYER_PATTERNS)}")
        spec = replace(spec, bayer=pattern)
    if "bits" in options:
        bits = _number(options["bits"], "the bit depth", base, int)
        if not 1 <= bits <= 16:
            raise ServoscopeError(f"{base}: the bit depth must be 1 to 16, not {bits}")
        spec = replace(spec, bits=bits)
    return spec


def is_frame_source(path: str | Path) -> bool:
    """Whether ``path`` names an image sequence or a high-speed raw file rather than a video file.

    A folder, a glob (``*``, ``?``, ``[``), a path with options
    (:func:`frame_source`), a single image file, or a file ending in one of
    :data:`RAW_SUFFIXES`. An existing file of another kind is a video.
    """
    text = str(path)
    p = Path(text)
    if p.is_file():
        return p.suffix.lower() in RAW_SUFFIXES + IMAGE_SUFFIXES
    if p.is_dir():
        return True
    base = parse_frame_source(text).path
    return base != text or _glob.has_magic(base) or Path(base).suffix.lower() in RAW_SUFFIXES


def source_name(path: str | Path) -> str:
    """A name for a frame source's outputs: the folder's name for a sequence, the file's stem for a raw file.

    ``"rec/dwell_01/*.tif#fps=2000"`` → ``"dwell_01"``; ``"rec/beam.cihx"`` → ``"beam"``.
    """
    base = Path(parse_frame_source(path).path)
    if base.is_dir():
        return base.name
    if _glob.has_magic(str(base)):
        parts = [part for part in base.parts if not _glob.has_magic(part)]
        return parts[-1] if parts else "frames"
    return base.stem


@dataclass(frozen=True)
class SourceHeader:
    """What a frame source's header (or its first frame) says.

    Attributes
    ----------
    format : str
        ``"tiff"``, ``"png"``, ``"jpeg"``, ``"mraw"`` or ``"cine"``.
    width, height : int
        As the frames come (before the 8-bit 4:2:0 conversion crops an odd size by one).
    frame_count : int
    frame_rate_hz : float or None
        Frames per second of the frames as saved.
    frame_rate_from : str
        Where the rate came from, e.g. ``"header: record rate 50000 / save step 2500"`` or ``"command line or manifest"``.
    bit_depth : int
        The samples' real bits (12 for a 12-bit sensor stored in 16-bit words).
    colour : str
        ``"colour"``, ``"monochrome"`` or ``"raw Bayer RGGB"`` (…).
    sample_format : str
        How samples are stored, e.g. ``"uint16"``, ``"packed 12-bit"``.
    times_s : ndarray
        Each frame's time, s (from the rate and start time, or from a timestamps file or the file's own).
    times_from : str
        Where the times came from.
    trigger_s : float or None
        The first frame's time from the camera's trigger, s (negative: before it), when the header says.
    files : tuple of str
        The files whose bytes make up the source (for the tracks' cache).
    """

    format: str
    width: int
    height: int
    frame_count: int
    frame_rate_hz: float | None
    frame_rate_from: str
    bit_depth: int
    colour: str
    sample_format: str
    times_s: np.ndarray = field(repr=False)
    times_from: str
    trigger_s: float | None = None
    files: tuple[str, ...] = field(default=(), repr=False)

    @property
    def monochrome(self) -> bool:
        """Frames of one gray level per pixel."""
        return self.colour == "monochrome"


class FrameSource(Protocol):
    """An opened frame source: its header, and its frames' samples one at a time."""

    header: SourceHeader

    def read(self, index: int) -> np.ndarray:
        """Frame ``index``'s samples: (height, width) gray or raw Bayer, or (height, width, 3) RGB."""

    def close(self) -> None:
        """Release the files."""


def regular_times(spec: SourceSpec, n: int, rate_hz: float | None, rate_from: str) -> tuple[np.ndarray, str]:
    """Frame times from a timestamps file when given, else ``start + i / rate``.

    Raises
    ------
    ServoscopeError
        With neither, or a timestamps file that is unreadable, of another
        length than the frames, or not increasing.
    """
    if spec.timestamps is not None:
        where = spec.timestamps
        try:
            times = np.loadtxt(where, dtype=np.float64, ndmin=1, comments="#", delimiter=None)
        except (OSError, ValueError) as exc:
            raise ServoscopeError(f"{where}: not a readable timestamps file (one time in s per line): "
                                  f"{str(exc).splitlines()[0]}") from None
        if times.ndim != 1 or times.size != n:
            raise ServoscopeError(f"{where}: {times.size} timestamps for {n} frames of {spec.path}")
        if n > 1 and not np.all(np.diff(times) > 0):
            raise ServoscopeError(f"{where}: timestamps must increase from frame to frame")
        return times + spec.start_s, f"timestamps file {Path(where).name}"
    if rate_hz is None:
        raise ServoscopeError(f"{spec.path}: an image sequence has no frame rate of its own: give it with --fps "
                              "(or fps = … in the manifest), or a timestamps file")
    return spec.start_s + np.arange(n) / rate_hz, f"frame rate ({rate_from})"


def regularity(times_s: np.ndarray) -> str:
    """How regular frame times are, in words: ``"regular (1/2000 s)"`` or the spread of the intervals."""
    times = np.asarray(times_s, dtype=np.float64)
    if times.size < 2:
        return "one frame"
    dt = np.diff(times)
    median = float(np.median(dt))
    spread = float(np.max(np.abs(dt - median)))
    if spread <= 1e-6 * abs(median):
        return f"regular (every {median * 1e3:.6g} ms)"
    return (f"irregular: intervals {float(dt.min()) * 1e3:.6g} to {float(dt.max()) * 1e3:.6g} ms "
            f"(median {median * 1e3:.6g} ms)")


def demosaic(raw: np.ndarray, pattern: str) -> np.ndarray:
    """Raw Bayer samples (uint8 or uint16, 2-D) as RGB of the same type (OpenCV, bilinear)."""
    import cv2

    return cv2.cvtColor(np.ascontiguousarray(raw), getattr(cv2, BAYER_PATTERNS[pattern]))


def _scale8(samples: np.ndarray, bit_depth: int) -> np.ndarray:
    """``round(v · 255 / (2^n − 1))`` in integers (exact: ``v · 257`` of 16 bits is ``v``)."""
    if samples.dtype == np.uint8 and bit_depth == 8:
        return samples
    top = (1 << bit_depth) - 1
    v = np.minimum(samples.astype(np.uint32), top)  # a sample above the stated depth is full scale
    return ((v * 510 + top) // (2 * top)).astype(np.uint8)


def to_rgb8(samples: np.ndarray, bit_depth: int, bayer: str | None = None) -> np.ndarray:
    """A frame's samples as 8-bit RGB (gray replicated), scaled by the real bit depth.

    Parameters
    ----------
    samples : ndarray
        (h, w) gray or raw Bayer, or (h, w, 3) RGB, uint8 or uint16.
    bit_depth : int
        The samples' real bits.
    bayer : str, optional
        The raw frame's Bayer pattern (2-D samples are gray without it).
    """
    if samples.ndim == 2 and bayer is not None:
        samples = demosaic(samples, bayer)
    rgb = _scale8(samples, bit_depth)
    if rgb.ndim == 2:
        rgb = np.repeat(rgb[:, :, None], 3, axis=2)
    return rgb


def to_yuv420(samples: np.ndarray, bit_depth: int, bayer: str | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A frame's samples as the trackers' 8-bit 4:2:0 limited-range BT.601 planes (odd sizes cropped by one).

    Colour: :func:`to_rgb8` then :func:`servoscope.video.writer.rgb_to_yuv420p`
    (the twin writer's own equations). Monochrome: ``Y = 16 + round(219 · v / (2^n − 1))``,
    chroma 128.
    """
    h, w = samples.shape[0] & ~1, samples.shape[1] & ~1
    if samples.ndim == 2 and bayer is None:
        top = (1 << bit_depth) - 1
        v = np.minimum(samples[:h, :w].astype(np.uint32), top)
        y = (16 + (v * 438 + top) // (2 * top)).astype(np.uint8)
        chroma = np.full((h // 2, w // 2), 128, np.uint8)
        return y, chroma, chroma.copy()
    from .writer import rgb_to_yuv420p

    i420 = rgb_to_yuv420p(to_rgb8(samples, bit_depth, bayer)[:h, :w])
    chroma = i420[h:].reshape(2, h // 2, w // 2)
    return i420[:h], chroma[0], chroma[1]


#: A manifest's ``[[tests]]`` keys for a frame source (``frames`` instead of ``video``).
MANIFEST_KEYS = ("frames", "fps", "start_s", "timestamps", "bayer", "bits")


def manifest_frame_source(entry: dict, base: Path) -> str:
    """A manifest test's frame source: ``frames = "dwell_01/*.tif"`` with ``fps = 2000`` (…), as a path string.

    Parameters
    ----------
    entry : dict
        The ``[[tests]]`` table, with ``frames`` (a folder, a glob or a raw
        file, relative to the manifest's folder) and optionally ``fps``,
        ``start_s``, ``timestamps`` (a file, relative to the manifest's
        folder), ``bayer`` and ``bits``.
    base : Path
        The manifest's folder.

    Raises
    ------
    ServoscopeError
        When ``video`` is given too, or an option is of the wrong type.
    """
    if "video" in entry:
        raise ServoscopeError("give either video (a video file) or frames (an image sequence or a raw file), not both")
    frames = entry["frames"]
    if not isinstance(frames, str) or not frames:
        raise ServoscopeError("frames must be a folder, a glob or a raw file's name")
    numbers = {}
    for key in ("fps", "start_s", "bits"):
        if key in entry:
            value = entry[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
                raise ServoscopeError(f"{key} must be a number, not {value!r}")
            numbers[key] = value
    if numbers.get("fps", 1) <= 0:
        raise ServoscopeError(f"fps must be > 0 frames/s, not {numbers['fps']!r}")
    timestamps = entry.get("timestamps")
    bayer = entry.get("bayer")
    for key, value in (("timestamps", timestamps), ("bayer", bayer)):
        if value is not None and not isinstance(value, str):
            raise ServoscopeError(f"{key} must be text, not {value!r}")
    if bayer is not None and bayer.upper() not in BAYER_PATTERNS:
        raise ServoscopeError(f"bayer must be one of {sorted(BAYER_PATTERNS)}, not {bayer!r}")
    bits = numbers.get("bits")
    return frame_source(base / frames, fps=numbers.get("fps"), start_s=float(numbers.get("start_s", 0.0)),
                        timestamps=None if timestamps is None else (base / timestamps).resolve(),
                        bayer=None if bayer is None else bayer.upper(), bits=None if bits is None else int(bits))
