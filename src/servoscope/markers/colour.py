"""Marker colours: parsing what the user wrote, and learning what the camera saw.

A given colour is only a seed. After lighting, white balance and the codec the
recorded sticker differs, so the tracker measures each marker's actual colour
on the footage (:class:`ColourModel`) and segments with that.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit

from ..errors import ServoscopeError

__all__ = ["AUTO", "BRIGHT", "BRIGHTNESS", "DARK", "BrightnessModel", "parse_colour", "ColourModel", "hsv_of_rgb",
           "luma_bt601", "seed_model", "ycbcr_bt601"]

AUTO = "auto"
#: Markers told by brightness rather than colour (monochrome footage): white dots on a dark
#: blade ("bright") or dark dots on a light one ("dark").
BRIGHT, DARK = "bright", "dark"
BRIGHTNESS = (BRIGHT, DARK)


def parse_colour(spec: str, *, what: str = "colour") -> tuple[float, float, float] | str:
    """Parse ``"#rrggbb"``, a CSS colour name, ``"auto"``, or a brightness (``"bright"``, ``"dark"``).

    Returns
    -------
    (r, g, b) in 0–255, or the string ``"auto"``, ``"bright"`` or ``"dark"``.

    Raises
    ------
    ServoscopeError
        For anything else; the message names ``what``.
    """
    if not isinstance(spec, str):
        raise ServoscopeError(f"{what}: expected a colour string like \"#d62728\", \"red\" or \"auto\", got {spec!r}")
    text = spec.strip().lower()
    if text in (AUTO, *BRIGHTNESS):
        return text
    if text.startswith("#"):
        # Hex is parsed here: importing matplotlib for it would cost 0.2 s of
        # every `servoscope track`'s start-up.
        if len(text) != 7 or not all(c in "0123456789abcdef" for c in text[1:]):
            raise ServoscopeError(
                f"{what}: {spec!r} is not a colour (use \"#rrggbb\", a CSS colour name, or \"auto\")")
        return tuple(float(int(text[i:i + 2], 16)) for i in (1, 3, 5))  # type: ignore[return-value]
    # Deferred: matplotlib holds the CSS colour table; only names need it.
    from matplotlib import colors as mcolors

    if text not in mcolors.CSS4_COLORS:
        raise ServoscopeError(
            f"{what}: {spec!r} is not a colour (use \"#rrggbb\", a CSS colour name, or \"auto\")"
        ) from None
    rgb = mcolors.to_rgb(mcolors.CSS4_COLORS[text])
    return tuple(float(c) * 255.0 for c in rgb)  # type: ignore[return-value]


def ycbcr_bt601(rgb) -> np.ndarray:
    """Limited-range BT.601 YCbCr of one RGB colour (0–255), as the writer and decoder use.

    Parameters
    ----------
    rgb : sequence of 3 floats
        Red, green, blue in 0–255.

    Returns
    -------
    ndarray, shape (3,)
        Y in 16–235, Cb and Cr in 16–240 (128 neutral), unrounded.
    """
    r, g, b = (float(c) for c in rgb)
    return np.array([16.0 + (65.481 * r + 128.553 * g + 24.966 * b) / 255.0,
                     128.0 + (-37.797 * r - 74.203 * g + 112.0 * b) / 255.0,
                     128.0 + (112.0 * r - 93.786 * g - 18.214 * b) / 255.0])


def hsv_of_rgb(rgb: np.ndarray) -> np.ndarray:
    """OpenCV HSV (H in 0–180, S and V in 0–255) of RGB uint8 pixels, any shape (..., 3)."""
    arr = np.ascontiguousarray(np.asarray(rgb, dtype=np.uint8).reshape(-1, 1, 3))
    return cv2.cvtColor(arr, cv2.COLOR_RGB2HSV).reshape(np.shape(rgb))


@dataclass(frozen=True)
class ColourModel:
    """A hue band with saturation and value floors, in OpenCV's HSV units.

    Hue is circular (0–180 in OpenCV's 8-bit HSV), so a red marker whose hue
    straddles 0 is one band, not two.

    Attributes
    ----------
    rgb : (r, g, b)
        Representative colour, 0–255.
    hue : float
        Centre of the band, 0–180.
    hue_halfwidth : float
    min_saturation, min_value : float
        0–255.
    """

    rgb: tuple[float, float, float]
    hue: float
    hue_halfwidth: float
    min_saturation: float
    min_value: float

    @classmethod
    def from_seed(cls, rgb: tuple[float, float, float]) -> "ColourModel":
        """A permissive model around a user-given colour, for the first detection."""
        h, s, v = hsv_of_rgb(np.array(rgb, dtype=np.float64).round().clip(0, 255).astype(np.uint8)).ravel()
        # Saturation floor at half the seed's: a blue sticker must not match
        # a blue-grey sky (saturation ~60) before its own colour is learned.
        return cls(tuple(rgb), float(h), 12.0, max(40.0, 0.5 * float(s)), max(30.0, 0.25 * float(v)))

    @classmethod
    def learn(cls, pixels_rgb: np.ndarray) -> "ColourModel":
        """Fit the band to a detected marker's core pixels, shape (n, 3) uint8."""
        hsv = hsv_of_rgb(pixels_rgb).reshape(-1, 3).astype(np.float64)
        angle = hsv[:, 0] * (np.pi / 90.0)
        mean_angle = np.arctan2(np.sin(angle).mean(), np.cos(angle).mean())
        hue = (mean_angle * 90.0 / np.pi) % 180.0
        spread = np.abs(((hsv[:, 0] - hue + 90.0) % 180.0) - 90.0)
        halfwidth = float(np.clip(3.0 * np.percentile(spread, 90), 6.0, 20.0))
        s_med = float(np.median(hsv[:, 1]))
        v_med = float(np.median(hsv[:, 2]))
        rgb = tuple(float(c) for c in np.median(np.asarray(pixels_rgb, dtype=np.float64).reshape(-1, 3), axis=0))
        return cls(rgb, float(hue), halfwidth, max(30.0, 0.45 * s_med), max(25.0, 0.35 * v_med))

    def learned(self, pixels_rgb: np.ndarray) -> "ColourModel":
        """The band fitted to a detected marker's core pixels (:meth:`learn`)."""
        return ColourModel.learn(pixels_rgb)

    def mask(self, rgb: np.ndarray) -> np.ndarray:
        """Binary membership of RGB uint8 pixels, shape (..., 3) → (...) bool."""
        hsv = cv2.cvtColor(np.ascontiguousarray(rgb), cv2.COLOR_RGB2HSV) if rgb.ndim == 3 else hsv_of_rgb(rgb)
        h = hsv[..., 0].astype(np.int16)
        dh = np.abs(((h - int(round(self.hue)) + 90) % 180) - 90)
        return (dh <= self.hue_halfwidth) & (hsv[..., 1] >= self.min_saturation) & (hsv[..., 2] >= self.min_value)


def luma_bt601(rgb: np.ndarray) -> np.ndarray:
    """BT.601 luma (0–255) of RGB pixels, shape (..., 3) → (...): a gray frame's own level.

    8-bit images (shape (h, w, 3)) by a compiled loop: the monochrome engine's
    first frame asks for a megapixel frame's luma a dozen times (its brightness
    masks), ~5 ms each through NumPy's float32 temporaries against ~1 ms. The
    same float32 products and sums in the same order (no fastmath): the same bits.
    """
    if isinstance(rgb, np.ndarray) and rgb.dtype == np.uint8 and rgb.ndim == 3 and rgb.shape[2] == 3:
        out = np.empty(rgb.shape[:2], np.float32)
        _luma_u8(rgb, out)
        return out
    a = np.asarray(rgb, dtype=np.float32)
    return a[..., 0] * np.float32(0.299) + a[..., 1] * np.float32(0.587) + a[..., 2] * np.float32(0.114)


@njit(cache=True, nogil=True)
def _luma_u8(rgb, out):
    c0, c1, c2 = np.float32(0.299), np.float32(0.587), np.float32(0.114)
    for i in range(rgb.shape[0]):
        for j in range(rgb.shape[1]):
            out[i, j] = (np.float32(rgb[i, j, 0]) * c0 + np.float32(rgb[i, j, 1]) * c1) + np.float32(rgb[i, j, 2]) * c2


@dataclass(frozen=True)
class BrightnessModel:
    """A marker told by its brightness: the level above (or below) which a pixel is the marker's.

    Monochrome footage (most high-speed cameras) has no colour to tell stickers by:
    white dots on a dark blade are the brightest blobs of the frame. The threshold sits
    halfway between the frame's typical level (its median) and the extreme level of
    the markers (the 99.9th percentile, or the 0.1th for dark markers); the sub-pixel
    moments then unmix each pixel between the marker's level and the local
    background's, as for colours (:mod:`.centroid`).

    Attributes
    ----------
    rgb : (r, g, b)
        The marker's level (gray: three equal values).
    bright : bool
        True: the marker is brighter than what surrounds it; False: darker.
    threshold_dn : float
        Luma (0–255) that separates it.
    hue : float
        0: brightness markers have no hue (the candidates' hue test is moot).
    """

    rgb: tuple[float, float, float]
    bright: bool
    threshold_dn: float
    hue: float = 0.0

    @classmethod
    def from_frame(cls, rgb: np.ndarray, spec: str) -> "BrightnessModel":
        """The threshold for ``spec`` ("bright" or "dark") from a frame's levels."""
        y = luma_bt601(rgb).ravel()
        typical = float(np.median(y))
        extreme = float(np.percentile(y, 99.9 if spec == BRIGHT else 0.1))
        level = (extreme,) * 3
        return cls(level, spec == BRIGHT, 0.5 * (typical + extreme))

    def learned(self, pixels_rgb: np.ndarray) -> "BrightnessModel":
        """The marker's level from its core pixels; the threshold stays (flicker scales both sides)."""
        level = float(np.median(luma_bt601(np.asarray(pixels_rgb).reshape(-1, 3))))
        return BrightnessModel((level,) * 3, self.bright, self.threshold_dn)

    def mask(self, rgb: np.ndarray) -> np.ndarray:
        """Binary membership of RGB pixels, shape (..., 3) → (...) bool."""
        y = luma_bt601(rgb)
        return y >= self.threshold_dn if self.bright else y <= self.threshold_dn


def seed_model(spec, frame_rgb: np.ndarray) -> ColourModel | BrightnessModel:
    """The first model of a marker given as ``spec`` (a parsed colour or a brightness), for ``frame_rgb``.

    A colour seeds a permissive :class:`ColourModel`; ``"bright"`` or ``"dark"`` a
    :class:`BrightnessModel` whose threshold comes from the frame's own levels
    (what the tracker does on a monochrome video's first frame). Whatever takes a
    marker's spec (the report's segmentation, the rolling shutter's LED row) goes
    through here, so that no caller treats a brightness as a colour.

    Raises
    ------
    ServoscopeError
        For ``"auto"``, which has no model until the markers are found.
    """
    if isinstance(spec, str):
        if spec in BRIGHTNESS:
            return BrightnessModel.from_frame(frame_rgb, spec)
        raise ServoscopeError(f"marker {spec!r}: not a colour or a brightness to segment by")
    return ColourModel.from_seed(spec)
