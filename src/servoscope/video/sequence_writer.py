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
from numba import njit

from ..errors import ServoscopeError

__all__ = ["FRAMES_FORMATS", "MRAW_NAME", "MrawWriter", "TIFF_ZLIB_LEVEL", "TiffSequenceWriter", "pack_12bit"]

#: Image-sequence formats the twin writes: name → (file suffix, bits).
FRAMES_FORMATS = {"tiff16": (".tif", 16)}
#: The twin's MRAW in a test's folder: ``<folder>/frames.mraw`` with ``frames.cih`` beside it.
MRAW_NAME = "frames"
#: zlib level of the TIFF frames (lossless at any level). A sensor's noise leaves little for zlib to find:
#: level 1 writes a 720×576 16-bit RGB frame in 18 ms against the default level's 97 ms (a 320×256 12-bit
#: monochrome one in 2.8 against 4.6 ms) for 3 % (0.5 %) more bytes, and reads as fast.
TIFF_ZLIB_LEVEL = 1


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
                         photometric="rgb", compression="zlib",
                         compressionargs={"level": TIFF_ZLIB_LEVEL})
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
                         compression="zlib", compressionargs={"level": TIFF_ZLIB_LEVEL})
        self.frames_written += 1
        return t

    def close(self) -> None:
        """Nothing held open between frames."""


def pack_12bit(samples: np.ndarray) -> np.ndarray:
    """12-bit samples (uint16, an even count) packed two in three bytes as Photron stores them (big-endian nibbles).

    The inverse of :func:`servoscope.video.highspeed.unpack_12bit` (and of pyMRAW's reader).
    """
    v = np.ascontiguousarray(samples, dtype=np.uint16).reshape(-1)
    if v.size % 2:
        raise ServoscopeError(f"12-bit samples are packed in pairs: {v.size} is an odd count")
    out = np.empty(v.size // 2 * 3, np.uint8)
    _pack_12bit(v, out)
    return out


@njit(cache=True)
def _pack_12bit(v, out):  # pragma: no cover - numba
    # One pass, no temporaries: numpy's six whole-frame operations took a seventh of a 12-bit twin's rendering.
    for i in range(v.size // 2):
        a = v[2 * i]
        b = v[2 * i + 1]
        out[3 * i] = np.uint8(a >> 4)
        out[3 * i + 1] = np.uint8(((a & 15) << 4) | (b >> 8))
        out[3 * i + 2] = np.uint8(b & 255)


class MrawWriter:
    """Write monochrome frames as a Photron MRAW with its CIH header (8-bit, packed 12-bit or 16-bit words).

    What a Photron high-speed camera saves (pyMRAW's ``save_mraw`` writes 8- and
    16-bit words only; packed 12-bit is the cameras' own compact format). The
    same interface as :class:`TiffSequenceWriter`'s ``write_gray``; the header is
    written on :meth:`close` (it holds the frame count).

    Parameters
    ----------
    folder : path-like
        Created if needed; the files are ``frames.mraw`` and ``frames.cih`` in it.
    width, height : int
    fps : float or Fraction
    word_bits : {8, 12, 16}
        How samples are stored: bytes, packed 12-bit, or 16-bit words (low bits).
    """

    def __init__(self, folder: str | Path, width: int, height: int, fps: float | Fraction, word_bits: int = 12):
        if word_bits not in (8, 12, 16):
            raise ServoscopeError(f"MRAW samples are stored in 8, 12 (packed) or 16 bits, not {word_bits}")
        if word_bits == 12 and width % 2:
            raise ServoscopeError("a packed 12-bit MRAW needs an even width")
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.mraw = self.folder / f"{MRAW_NAME}.mraw"
        self.cih = self.folder / f"{MRAW_NAME}.cih"
        if self.mraw.exists():
            raise ServoscopeError(f"{self.mraw}: already exists; write an MRAW into an empty folder")
        self.width, self.height = int(width), int(height)
        self.fps = Fraction(fps).limit_denominator(1_000_000)
        self.word_bits = int(word_bits)
        self.bits = 8 if word_bits == 8 else 12
        self.frames_written = 0
        self._file = open(self.mraw, "wb")

    def __enter__(self) -> "MrawWriter":
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()

    def write_gray(self, frame: np.ndarray, bits: int, time_s: float | None = None) -> float:
        """Append one frame of ``bits``-bit samples (no more than the words hold); return its time."""
        a = np.asarray(frame)
        if a.shape != (self.height, self.width) or bits > self.word_bits or (a.size and int(a.max()) >= 2**bits):
            raise ServoscopeError(f"frame must be of shape {(self.height, self.width)} with samples of at most "
                                  f"{self.word_bits} bits, not {a.dtype} {a.shape} of {bits} bits")
        self.bits = int(bits)
        t = float(Fraction(self.frames_written) / self.fps)
        if time_s is not None and abs(time_s - t) > 1e-9:
            raise ServoscopeError(f"{self.mraw}: frames are evenly spaced; frame {self.frames_written} is at {t} s, "
                                  f"not {time_s} s")
        if self.word_bits == 8:
            data = a.astype(np.uint8)
        elif self.word_bits == 12:
            data = pack_12bit(a)
        else:
            data = a.astype("<u2")
        data.tofile(self._file)
        self.frames_written += 1
        return t

    def close(self) -> None:
        """Close the MRAW and write its CIH header (the lines pyMRAW's ``get_cih`` reads)."""
        if self._file.closed:
            return
        self._file.close()
        fields = {"Record Rate(fps)": f"{float(self.fps):.17g}", "Shutter Speed(s)": f"{1.0 / float(self.fps):.9f}",
                  "Total Frame": self.frames_written, "Original Total Frame": self.frames_written,
                  "Start Frame": 0, "Image Width": self.width, "Image Height": self.height, "Color Type": "Mono",
                  "Color Bit": self.word_bits, "File Format": "MRaw", "EffectiveBit Depth": self.bits,
                  "EffectiveBit Side": "Lower", "Comment Text": "servoscope digital twin"}
        self.cih.write_text("#Camera Information Header\n" + "".join(f"{k} : {v}\n" for k, v in fields.items()))
