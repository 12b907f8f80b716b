"""Image sequences: a folder or a glob of TIFF, PNG or JPEG frames, read one at a time.

Frames come in natural sort order (``f9.tif`` before ``f10.tif``), and a
numbered sequence must have no gap: a missing ``frame_000123.tif`` would
otherwise shift every later frame's time by one interval. TIFFs are read with
``tifffile`` (8 or 16 bits, gray, RGB or raw Bayer; the real bit depth from
the ``BitsPerSample`` tag or the ``bits`` option), PNG and JPEG with OpenCV.
Only one frame is in memory at a time; the file list itself takes about
150 bytes a frame (3 MB for 20,000 frames).
"""

from __future__ import annotations

import glob as _glob
import os
import re


import numpy as np

from ..errors import ServoscopeError
from .frame_source import IMAGE_SUFFIXES, SourceHeader, SourceSpec, regular_times

__all__ = ["ImageSequence", "natural_key", "sequence_files"]

_DIGITS = re.compile(r"(\d+)")
_FORMATS = {".tif": "tiff", ".tiff": "tiff", ".png": "png", ".jpg": "jpeg", ".jpeg": "jpeg"}


def natural_key(name: str) -> tuple:
    """Sort key that orders embedded numbers by value: ``f2`` < ``f10`` (of a file name or path)."""
    return tuple(int(part) if part.isdigit() else part.lower() for part in _DIGITS.split(os.path.basename(name)))


def sequence_files(pattern: str) -> list[str]:
    """The image files of a folder or glob, in natural order (paths as strings: 20,000 Paths cost 10 MB).

    Raises
    ------
    ServoscopeError
        When nothing matches, or the numbers in the names have a gap.
    """
    if os.path.isdir(pattern):
        files = [os.path.join(pattern, name) for name in os.listdir(pattern)]
    elif _glob.has_magic(pattern):
        files = _glob.glob(pattern)
    elif os.path.isfile(pattern):
        files = [pattern]
    else:
        raise ServoscopeError(f"{pattern}: no such file or folder")
    files = [p for p in files if os.path.splitext(p)[1].lower() in IMAGE_SUFFIXES and os.path.isfile(p)]
    if not files:
        raise ServoscopeError(f"{pattern}: no readable image (TIFF, PNG or JPEG) in it")
    files.sort(key=natural_key)
    _check_numbering(pattern, files)
    return files


def _check_numbering(pattern: str, files: list[str]) -> None:
    """Frames numbered in their names (the last run of digits) must follow each other without a gap."""
    numbers = []
    for p in files:
        runs = _DIGITS.findall(os.path.splitext(os.path.basename(p))[0])
        if not runs:
            return  # names without numbers: their order is all there is
        numbers.append(int(runs[-1]))
    steps = np.diff(numbers)
    bad = np.flatnonzero(steps != 1)
    if bad.size:
        k = int(bad[0])
        what = "the same number twice" if steps[k] == 0 else f"a gap: {int(steps[k]) - 1} frame(s) missing"
        raise ServoscopeError(f"{pattern}: frame numbering has {what} between {os.path.basename(files[k])} and "
                              f"{os.path.basename(files[k + 1])}; every frame's time depends on its place in the sequence")


def _is_tiff(path: str) -> bool:
    return path.lower().endswith((".tif", ".tiff"))


def _tiff_bits(path: str) -> int | None:
    import tifffile

    with tifffile.TiffFile(path) as tif:
        tag = tif.pages[0].tags.get("BitsPerSample")
        if tag is None:
            return None
        value = tag.value
        return int(value[0] if isinstance(value, tuple) else value)


class ImageSequence:
    """A folder or glob of image files as a frame source (see :mod:`servoscope.video.frame_source`).

    Parameters
    ----------
    spec : SourceSpec
        The folder or glob, with its frame rate or timestamps file.

    Raises
    ------
    ServoscopeError
        No image, a gap in the numbering, no frame rate, an unreadable first frame.
    """

    def __init__(self, spec: SourceSpec):
        self.spec = spec
        self.files = sequence_files(spec.path)
        first = self._load(0)
        self.shape = first.shape
        self.dtype = first.dtype
        if first.dtype not in (np.uint8, np.uint16):
            raise ServoscopeError(f"{self.files[0]}: {first.dtype} samples; servoscope reads 8- and 16-bit images")
        bits = spec.bits or (_tiff_bits(self.files[0]) if _is_tiff(self.files[0]) else None)
        bits = bits or 8 * first.dtype.itemsize
        if first.ndim == 3 and first.shape[2] not in (3, 4) or first.ndim not in (2, 3):
            raise ServoscopeError(f"{self.files[0]}: frames of shape {first.shape}; servoscope reads gray and RGB")
        if first.ndim == 2:
            colour = f"raw Bayer {spec.bayer}" if spec.bayer else "monochrome"
        else:
            colour = "colour"
        times, times_from = regular_times(spec, len(self.files), spec.fps,
                                          "command line or manifest" if spec.fps else "")
        self.header = SourceHeader(
            format=_FORMATS[os.path.splitext(self.files[0])[1].lower()], width=int(first.shape[1]), height=int(first.shape[0]),
            frame_count=len(self.files), frame_rate_hz=spec.fps,
            frame_rate_from="command line or manifest" if spec.fps else "none (timestamps file)",
            bit_depth=int(bits), colour=colour, sample_format=str(first.dtype), times_s=times, times_from=times_from,
            files=tuple(self.files))
        self.read(len(self.files) - 1)  # a last frame of another size: said now, before any work

    def _load(self, index: int) -> np.ndarray:
        path = self.files[index]
        try:
            if _is_tiff(path):
                import tifffile

                image = tifffile.imread(path)
            else:
                import cv2

                image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
                if image is None:
                    raise ValueError("OpenCV cannot decode it")
                if image.ndim == 3:
                    image = cv2.cvtColor(image, cv2.COLOR_BGR2RGB if image.shape[2] == 3 else cv2.COLOR_BGRA2RGB)
        except (OSError, ValueError, KeyError, IndexError) as exc:
            text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ServoscopeError(f"{path}: not a readable image ({text})") from None
        if image.ndim == 3 and image.shape[2] == 4:
            image = image[:, :, :3]  # alpha carries nothing the trackers use
        return image

    def read(self, index: int) -> np.ndarray:
        """Frame ``index``'s samples, checked against the first frame's size and type.

        Raises
        ------
        ServoscopeError
            When the frame is unreadable or of another size or type than the first.
        """
        image = self._load(index)
        if image.shape != self.shape or image.dtype != self.dtype:
            raise ServoscopeError(f"{self.files[index]}: {image.dtype} frame of {image.shape[1]}×{image.shape[0]}"
                                  f"{'×3' if image.ndim == 3 else ''} in a sequence of {self.dtype} frames of "
                                  f"{self.shape[1]}×{self.shape[0]}{'×3' if len(self.shape) == 3 else ''} "
                                  f"({os.path.basename(self.files[0])}); every frame must have the same size")
        return image

    def close(self) -> None:
        """Nothing to release: each frame's file is opened and closed as it is read."""
