"""Writing footage as an image sequence: a folder of 16-bit TIFF frames (the twin's ``frames_format="tiff16"``).

High-speed cameras save image sequences; the twin writes them so that the
readers (:mod:`servoscope.video.sequence`) are tested on what it renders. An
8-bit RGB frame is stored as ``v · 257`` (0 → 0, 255 → 65535): the readers
scale 16 bits back by ``255 / 65535``, which gives ``v`` exactly, so the
sequence and the twin's uncompressed video carry the same pixels.
"""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path
from types import TracebackType

import numpy as np

from ..errors import ServoscopeError

__all__ = ["FRAMES_FORMATS", "TiffSequenceWriter"]

#: Image-sequence formats the twin writes: name → (file suffix, bits).
FRAMES_FORMATS = {"tiff16": (".tif", 16)}


class TiffSequenceWriter:
    """Write RGB uint8 frames as ``frame_000000.tif``, … (16-bit RGB, deflate-compressed) in a folder.

    The same interface as :class:`servoscope.video.writer.VideoWriter`
    (``write``, ``close``, a context manager); frame ``i`` is at ``i / fps``,
    which the manifest's ``fps`` says (the files carry no time).

    Parameters
    ----------
    folder : path-like
        Created if needed; must not already hold TIFF frames.
    width, height : int
    fps : float or Fraction
    """

    def __init__(self, folder: str | Path, width: int, height: int, fps: float | Fraction):
        self.folder = Path(folder)
        self.width, self.height = int(width), int(height)
        self.fps = Fraction(fps).limit_denominator(1_000_000)
        self.folder.mkdir(parents=True, exist_ok=True)
        if any(self.folder.glob("*.tif")):
            raise ServoscopeError(f"{self.folder}: already holds TIFF frames; write a sequence into an empty folder")
        self.frames_written = 0

    def __enter__(self) -> "TiffSequenceWriter":
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def write(self, frame_rgb_uint8: np.ndarray, time_s: float | None = None) -> float:
        """Append one frame (``time_s`` must be ``frames_written / fps`` or None); return its time."""
        import tifffile

        a = np.asarray(frame_rgb_uint8)
        if a.dtype != np.uint8 or a.shape != (self.height, self.width, 3):
            raise ServoscopeError(f"frame must be uint8 of shape {(self.height, self.width, 3)}, not {a.dtype} {a.shape}")
        t = float(Fraction(self.frames_written) / self.fps)
        if time_s is not None and abs(time_s - t) > 1e-9:
            raise ServoscopeError(f"{self.folder}: an image sequence's frames are evenly spaced; frame "
                                  f"{self.frames_written} is at {t} s, not {time_s} s")
        tifffile.imwrite(self.folder / f"frame_{self.frames_written:06d}.tif", a.astype(np.uint16) * np.uint16(257),
                         photometric="rgb", compression="zlib")
        self.frames_written += 1
        return t

    def write_gray(self, frame: np.ndarray, bits: int, time_s: float | None = None) -> float:
        """Append one monochrome frame of ``bits``-bit samples (uint8 for 8, uint16 up to 16), stored as they are.

        A monochrome high-speed camera's file: 8-bit samples in 8-bit TIFFs, 10–16-bit
        ones in 16-bit TIFFs with their depth in the manifest (``bits``), as
        such cameras save them. Returns the frame's time.
        """
        import tifffile

        a = np.asarray(frame)
        want = np.uint8 if bits <= 8 else np.uint16
        if a.dtype != want or a.shape != (self.height, self.width) or (a.size and int(a.max()) >= 2**bits):
            raise ServoscopeError(f"frame must be {np.dtype(want).name} of shape {(self.height, self.width)} with "
                                  f"{bits}-bit samples, not {a.dtype} {a.shape}")
        t = float(Fraction(self.frames_written) / self.fps)
        if time_s is not None and abs(time_s - t) > 1e-9:
            raise ServoscopeError(f"{self.folder}: an image sequence's frames are evenly spaced; frame "
                                  f"{self.frames_written} is at {t} s, not {time_s} s")
        tifffile.imwrite(self.folder / f"frame_{self.frames_written:06d}.tif", a, photometric="minisblack",
                         compression="zlib")
        self.frames_written += 1
        return t

    def close(self) -> None:
        """Nothing held open between frames."""
