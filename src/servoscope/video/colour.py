"""Y'CbCr ↔ R'G'B' by the standard equations (ITU-R BT.601 / BT.709 / BT.2020, ITU-T H.273).

The trackers' YUV path expects what servoscope's own writer makes: 8-bit
4:2:0, limited ("TV") range, BT.601 matrix. Cameras also record 10-bit,
4:2:2, full ("PC"/JPEG) range and BT.709 (every HD camera and phone). This
module maps any planar Y'CbCr source onto that target exactly, from the
stream's own tags, and builds such sources from RGB for the writer.

Why not libswscale: its conversions are fixed-point and, depending on the
path, ignore the source range or matrix; docs/formats.md lists what it gives
against these equations (up to tens of DN on saturated colours).

Quantisation (H.273, bit depth n): limited range ``Y = 2^(n-8)·(16 + 219·E'Y)``,
``C = 2^(n-8)·(128 + 224·E'P)``; full range ``Y = (2^n − 1)·E'Y``,
``C = (2^n − 1)·E'P + 2^(n−1)``. E'P is E'Pb or E'Pr, in [−0.5, 0.5]:
``E'Pb = (E'B − E'Y) / (2(1 − Kb))``, ``E'Pr = (E'R − E'Y) / (2(1 − Kr))``.
"""

from __future__ import annotations

import re

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from ..errors import ServoscopeError

__all__ = ["MATRICES", "YuvLayout", "ycbcr_matrix", "quantisation", "layout_of_format", "matrix_of_colorspace",
           "encode_ycbcr", "to_i420_bt601", "to_rgb"]

#: Matrix name → (Kr, Kb) luma coefficients.
MATRICES: dict[str, tuple[float, float]] = {
    "bt601": (0.299, 0.114),     # BT.601 / BT.470BG / SMPTE 170M: SD, and the unlabelled default
    "bt709": (0.2126, 0.0722),   # BT.709: HD cameras and phones
    "bt2020": (0.2627, 0.0593),  # BT.2020 non-constant luminance: HDR phones
    "smpte240m": (0.212, 0.087),
    "fcc": (0.30, 0.11),
}

#: FFmpeg's AVColorSpace → matrix name (unspecified, 2, reads as BT.601, FFmpeg's own default).
_COLORSPACES = {1: "bt709", 2: "bt601", 4: "fcc", 5: "bt601", 6: "bt601", 7: "smpte240m", 9: "bt2020", 10: "bt2020"}

#: Matrix name → the AVColorSpace the writer tags (BT.601 as SMPTE 170M, what cameras write).
COLORSPACE_CODES = {"bt601": 6, "bt709": 1, "bt2020": 9, "smpte240m": 7, "fcc": 4}

_PLANAR = re.compile(r"^yuv(j?)(420|422|444|440|411|410)p(?:(9|10|12|14|16)le)?$")
#: Chroma subsampling name → (horizontal, vertical) factors.
_SUBSAMPLING = {"420": (2, 2), "422": (2, 1), "444": (1, 1), "440": (1, 2), "411": (4, 1), "410": (4, 4)}
_SUBSAMPLING_NAME = {"420": "4:2:0", "422": "4:2:2", "444": "4:4:4", "440": "4:4:0", "411": "4:1:1", "410": "4:1:0"}


def ycbcr_matrix(matrix: str) -> np.ndarray:
    """The 3×3 matrix taking (E'R, E'G, E'B) to (E'Y, E'Pb, E'Pr) for a named matrix."""
    try:
        kr, kb = MATRICES[matrix]
    except KeyError:
        raise ServoscopeError(f"unknown colour matrix {matrix!r} (choose from {sorted(MATRICES)})") from None
    kg = 1.0 - kr - kb
    return np.array([[kr, kg, kb],
                     [-kr / (2 * (1 - kb)), -kg / (2 * (1 - kb)), 0.5],
                     [0.5, -kg / (2 * (1 - kr)), -kb / (2 * (1 - kr))]])


def quantisation(bit_depth: int, full_range: bool) -> tuple[float, float, float, float]:
    """``(y_offset, y_scale, c_offset, c_scale)``: code value = offset + scale·E'."""
    if full_range:
        top = float(2 ** bit_depth - 1)
        return 0.0, top, float(2 ** (bit_depth - 1)), top
    k = float(2 ** (bit_depth - 8))
    return 16.0 * k, 219.0 * k, 128.0 * k, 224.0 * k


def matrix_of_colorspace(code: int) -> str:
    """Matrix name of an FFmpeg AVColorSpace code (unknown or unspecified: BT.601)."""
    return _COLORSPACES.get(int(code), "bt601")


@dataclass(frozen=True)
class YuvLayout:
    """How a planar Y'CbCr picture is coded.

    Attributes
    ----------
    bit_depth : int
    subsampling : str
        e.g. ``"4:2:0"``.
    factors : (int, int)
        Chroma subsampling, horizontal and vertical (2, 2 for 4:2:0).
    full_range : bool
        Full ("PC", JPEG) range rather than limited ("TV").
    matrix : str
        A key of :data:`MATRICES`.
    """

    bit_depth: int
    subsampling: str
    factors: tuple[int, int]
    full_range: bool
    matrix: str

    @property
    def is_writer_default(self) -> bool:
        """8-bit 4:2:0 limited-range BT.601: what the trackers take as it is."""
        return self.bit_depth == 8 and self.factors == (2, 2) and not self.full_range and self.matrix == "bt601"


def layout_of_format(pix_fmt: str, color_range: int, colorspace: int) -> YuvLayout | None:
    """The layout of a planar Y'CbCr pixel format with its tags, or None for other formats.

    Parameters
    ----------
    pix_fmt : str
        FFmpeg pixel format name, e.g. ``"yuv422p10le"``; the ``yuvj`` formats
        are full range whatever the range tag says.
    color_range : int
        AVColorRange: 2 (JPEG) full, anything else limited (FFmpeg's reading of unspecified).
    colorspace : int
        AVColorSpace (see :func:`matrix_of_colorspace`).
    """
    m = _PLANAR.match(pix_fmt or "")
    if m is None:
        return None
    bits = int(m.group(3) or 8)
    return YuvLayout(bits, _SUBSAMPLING_NAME[m.group(2)], _SUBSAMPLING[m.group(2)],
                     bool(m.group(1)) or int(color_range) == 2, matrix_of_colorspace(colorspace))


def encode_ycbcr(rgb: np.ndarray, *, matrix: str = "bt601", full_range: bool = False, bit_depth: int = 8,
                 factors: tuple[int, int] = (2, 2)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RGB (uint8, full-scale 0–255 = E' 0–1) → Y, Cb, Cr code-value planes.

    Chroma is the mean of each ``factors`` block of the full-resolution E'Pb,
    E'Pr (centre-sited, as the writer's 8-bit path); values are rounded half
    up and clipped to the code range.

    Returns
    -------
    y, cb, cr : ndarray of uint8 (8-bit) or uint16
    """
    e = np.asarray(rgb, dtype=np.float64) / 255.0
    ypp = e @ ycbcr_matrix(matrix).T
    h, w = e.shape[:2]
    fx, fy = factors
    if h % fy or w % fx:
        raise ServoscopeError(f"frame size {w}x{h} is not a multiple of the chroma subsampling {fx}x{fy}")
    chroma = ypp[..., 1:].reshape(h // fy, fy, w // fx, fx, 2).mean(axis=(1, 3))
    yo, ys, co, cs = quantisation(bit_depth, full_range)
    top = 2 ** bit_depth - 1
    dtype = np.uint8 if bit_depth == 8 else np.uint16
    y = np.clip(np.floor(yo + ys * ypp[..., 0] + 0.5), 0, top).astype(dtype)
    c = np.clip(np.floor(co + cs * chroma + 0.5), 0, top).astype(dtype)
    return y, np.ascontiguousarray(c[..., 0]), np.ascontiguousarray(c[..., 1])


@lru_cache(maxsize=32)
def _coefficients(layout: YuvLayout, target: str) -> np.ndarray:
    """The kernels' ``k`` for a layout, to "i420" (BT.601 TV) or "rgb"; computed once per layout, not per frame."""
    if target == "i420":
        m = ycbcr_matrix("bt601") @ np.linalg.inv(ycbcr_matrix(layout.matrix))
        return _affine(m, layout, np.array([219.0, 224.0, 224.0]), np.array([16.0, 128.0, 128.0]))
    return _affine(np.linalg.inv(ycbcr_matrix(layout.matrix)), layout, np.full(3, 255.0), np.zeros(3))


def _affine(m: np.ndarray, layout: YuvLayout, scale: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """Output code values as affine functions of the source's (Y, U, V) code values, float32 (3, 4).

    ``m`` maps the source's (E'Y, E'Pb, E'Pr) to the output's normalised values, which are coded as
    ``offset + scale·value``.
    """
    yo, ys, co, cs = quantisation(layout.bit_depth, layout.full_range)
    # (E'Y, E'Pb, E'Pr) = diag(1/ys, 1/cs, 1/cs) · ((Y, U, V) − (yo, co, co))
    lin = m / np.array([ys, cs, cs])
    k = np.empty((3, 4))
    k[:, 1:] = scale[:, None] * lin
    k[:, 0] = offset - k[:, 1:] @ np.array([yo, co, co])
    return k.astype(np.float32)


def _check_planes(y: np.ndarray, u: np.ndarray, v: np.ndarray, layout: YuvLayout) -> tuple[int, int]:
    fx, fy = layout.factors
    h, w = y.shape
    if u.shape != v.shape or u.shape[0] * fy < h or u.shape[1] * fx < w:
        raise ServoscopeError(f"chroma planes {u.shape} do not cover a {w}x{h} {layout.subsampling} picture")
    return h - h % 2, w - w % 2


def to_i420_bt601(y: np.ndarray, u: np.ndarray, v: np.ndarray, layout: YuvLayout) -> np.ndarray:
    """Any planar Y'CbCr picture → 8-bit 4:2:0 limited-range BT.601, exactly by the standard equations.

    Each pixel is decoded with its own chroma sample (nearest; a 4:2:2
    sample serves the two pixels it covers), re-expressed in BT.601's
    E'Y, E'Pb, E'Pr, then the output chroma is the mean over each 2×2 block
    (centre-sited, as servoscope's writer), rounded half up. Odd sizes lose
    their last row/column.

    Parameters
    ----------
    y, u, v : ndarray of uint8 or uint16
        The picture's planes (strided views allowed).
    layout : YuvLayout

    Returns
    -------
    ndarray of uint8, shape (h·3/2, w)
        I420: Y plane, then Cb, then Cr (PyAV's yuv420p layout).
    """
    h, w = _check_planes(y, u, v, layout)
    k = _coefficients(layout, "i420")
    from .colour_kernels import i420_kernel  # deferred: numba is slow to import, and most videos never need it

    out = np.empty((h * 3 // 2, w), np.uint8)
    fx, fy = layout.factors
    i420_kernel(y, u, v, fx, fy, k, out)
    return out


def to_rgb(y: np.ndarray, u: np.ndarray, v: np.ndarray, layout: YuvLayout) -> np.ndarray:
    """Any planar Y'CbCr picture → RGB uint8 (0–255 = E' 0–1), by the standard equations.

    Each pixel takes its nearest chroma sample; values are rounded half up
    and clipped.
    """
    h, w = y.shape
    _check_planes(y, u, v, layout)
    k = _coefficients(layout, "rgb")
    from .colour_kernels import rgb_kernel

    out = np.empty((h, w, 3), np.uint8)
    fx, fy = layout.factors
    rgb_kernel(y, u, v, fx, fy, k, out)
    return out
