"""Compressed TIFF sequences (issue 28, build 4): LZW, Deflate, PackBits and JPEG frames read through servoscope.

High-speed cameras' software often saves compressed TIFFs; tifffile decodes LZW and
JPEG only with imagecodecs, a dependency. Oracles: the samples written, and the same
frames saved uncompressed, read through the same reader.
"""

from __future__ import annotations

import numpy as np
import pytest
import tifffile

from servoscope.video import iter_frames
from servoscope.video.frame_source import frame_source, parse_frame_source
from servoscope.video.sequence import ImageSequence

#: The lossless ones: tifffile's name → the TIFF Compression tag's (zlib is Adobe Deflate). JPEG is
#: tested apart: tifffile writes 16-bit samples as 12-bit JPEG (libjpeg's precision).
LOSSLESS = {"lzw": "LZW", "zlib": "ADOBE_DEFLATE", "packbits": "PACKBITS"}


def _frames(bits: int, colour: bool = False) -> list[np.ndarray]:
    """Three frames of a smooth scene with a bright dot that moves, ``bits``-bit samples in uint16."""
    y, x = np.mgrid[0:96, 0:128].astype(np.float64)
    top = 2**bits - 1
    out = []
    for i in range(3):
        level = 0.3 + 0.1 * np.sin(x / 17.0) * np.cos(y / 13.0) + 0.6 * np.exp(-((x - 40 - 5 * i) ** 2 + (y - 50) ** 2) / 40)
        frame = np.round(np.clip(level, 0, 1) * top).astype(np.uint16)
        out.append(np.stack([frame, frame // 2, frame // 3], axis=-1) if colour else frame)
    return out


def _write(folder, frames, compression):
    folder.mkdir()
    for i, frame in enumerate(frames):
        tifffile.imwrite(folder / f"frame_{i:03d}.tif", frame, photometric="rgb" if frame.ndim == 3 else "minisblack",
                         compression=compression)
    return frame_source(folder, fps=100)


def _eight_bit(source) -> list[np.ndarray]:
    return [f.rgb.copy() for f in iter_frames(source)]


@pytest.mark.parametrize("colour", [False, True], ids=["gray", "rgb"])
@pytest.mark.parametrize("compression", sorted(LOSSLESS))
def test_lossless_compressed_16bit_frames_read_exactly(tmp_path, compression, colour):
    frames = _frames(16, colour)
    packed = _write(tmp_path / compression, frames, compression)
    with tifffile.TiffFile(sorted((tmp_path / compression).iterdir())[0]) as tif:
        assert tif.pages[0].compression.name == LOSSLESS[compression]  # compressed as asked
    seq = ImageSequence(parse_frame_source(packed))
    assert seq.header.bit_depth == 16 and seq.header.frame_count == 3
    for i, frame in enumerate(frames):
        assert np.array_equal(seq.read(i), frame)
    plain = _write(tmp_path / "plain", frames, None)
    for a, b in zip(_eight_bit(packed), _eight_bit(plain)):
        assert np.array_equal(a, b)  # what the trackers see: the uncompressed sequence's frames to the bit


@pytest.mark.parametrize("colour", [False, True], ids=["gray", "rgb"])
def test_jpeg_compressed_12bit_frames_read_close(tmp_path, colour):
    frames = _frames(12, colour)
    packed = _write(tmp_path / "jpeg", frames, "jpeg")
    seq = ImageSequence(parse_frame_source(packed))
    assert seq.header.bit_depth == 12  # the JPEG's precision, from BitsPerSample
    for i, frame in enumerate(frames):
        error = np.abs(seq.read(i).astype(np.int64) - frame)
        # Lossy: the gray frame within a few of 4096 levels, the colour one (chroma subsampled) within 1.5 %.
        assert error.max() <= (60 if colour else 8) and error.mean() < 2.0
    _write(tmp_path / "plain", frames, None)
    plain = frame_source(tmp_path / "plain", fps=100, bits=12)  # 12 bits in 16-bit words: said, not read
    for a, b in zip(_eight_bit(packed), _eight_bit(plain)):
        assert np.abs(a.astype(int) - b).max() <= (4 if colour else 1)
