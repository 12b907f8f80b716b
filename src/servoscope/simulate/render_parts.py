"""The frame renderer's parts below :class:`~servoscope.simulate.render.FrameRenderer`: the noise kernel,
the lens's fast distortion, the backgrounds, the picture's and the airframe's motions, the clutter.

The sensor noise is a splitmix64 stream (in numba) mapped through an inverse-CDF table of
65536 Gaussian quantiles (:func:`gaussian_table`); see :mod:`servoscope.simulate.render`.
"""

from __future__ import annotations

import functools
import math

import cv2
import numpy as np
import scipy.special
from numba import njit

from ..camera.model import CameraModel
from .coverage import accumulated, composite
from .scene import Scene, colour_rgb
from .view import ObliqueView

__all__ = ["add_table_noise", "airframe_motion", "distort_fast", "draw_clutter", "gaussian_table", "gray_frame",
           "moved_points",
           "picture_motion", "scene_background", "viewed_background"]


# -- kernels -------------------------------------------------------------------
@njit(cache=True, inline="always")
def _round_clip(v: np.float32) -> np.uint8:
    # Branch-free clip, then truncation of v + 1/2 (v >= 0) is rounding; the
    # branchy version is ten times slower on noisy data.
    v = min(max(v + np.float32(0.5), np.float32(0.0)), np.float32(255.0))
    return np.uint8(np.int32(v))


@njit(cache=True, inline="always")
def _splitmix_draw(s: np.uint64) -> np.uint64:
    # splitmix64's output mix of its counter: the sensor noise's draws (both noise kernels).
    z = s
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


@njit(cache=True, inline="always")
def _draw_indices(index: np.ndarray, n: int, state: np.uint64) -> None:
    # The noise's table indices of n values: splitmix64 draw b (state + (b + 1)·golden) feeds values 4b to
    # 4b + 3, one 16-bit index each, low bits first (both noise kernels).
    s = state
    golden = np.uint64(0x9E3779B97F4A7C15)
    mask = np.uint64(0xFFFF)
    for b in range((n + 3) // 4):
        s = s + golden
        z = _splitmix_draw(s)
        k = 4 * b
        index[k] = np.uint16(z & mask)
        index[k + 1] = np.uint16((z >> np.uint64(16)) & mask)
        index[k + 2] = np.uint16((z >> np.uint64(32)) & mask)
        index[k + 3] = np.uint16(z >> np.uint64(48))


@njit(cache=True)
def add_table_noise(work: np.ndarray, out: np.ndarray, scaled_table: np.ndarray, state: np.uint64,
                    index: np.ndarray) -> None:
    """out = clip(round(work + noise), 0, 255) as uint8; noise = scaled_table[random index].

    ``index``: uint16 scratch of at least ``work.size`` rounded up to a multiple of 4 entries.
    """
    w = work.ravel()
    o = out.ravel()
    n = w.shape[0]
    # The indices first, then the table's reads in a loop of their own: the reads (a 256 KB table, from L2)
    # bound the kernel, and apart from the draws they overlap; a 720x576 frame in 1.33-1.45 ms against 1.70-1.78 ms.
    _draw_indices(index, n, state)
    for k in range(n):
        o[k] = _round_clip(w[k] + scaled_table[np.intp(index[k])])


@njit(cache=True)
def add_gray_table_noise(work: np.ndarray, out: np.ndarray, gain: np.float32, scaled_table: np.ndarray,
                         top: np.float32, state: np.uint64, index: np.ndarray) -> None:
    """out = clip(round(luma(work)·gain + noise), 0, top): a monochrome sensor's samples of a float32 RGB
    picture (h, w, 3); luma is BT.601's in float32 (:func:`~servoscope.markers.colour.luma_bt601`'s
    products and sums, in its order), noise = scaled_table[random index] as :func:`add_table_noise` draws it
    (the indices first, into ``index``: uint16 scratch of at least h·w rounded up to a multiple of 4)."""
    h, w = out.shape
    c0, c1, c2 = np.float32(0.299), np.float32(0.587), np.float32(0.114)
    _draw_indices(index, h * w, state)
    for i in range(h):
        row = index[i * w:(i + 1) * w]
        for j in range(w):
            y = ((work[i, j, 0] * c0 + work[i, j, 1] * c1) + work[i, j, 2] * c2) * gain
            v = y + scaled_table[np.intp(row[j])] + np.float32(0.5)
            v = min(max(v, np.float32(0.0)), top)
            out[i, j] = np.int32(v)


@functools.lru_cache(maxsize=8)
def _gray_noise_table(sigma_dn: float) -> np.ndarray:
    table = (gaussian_table() * sigma_dn).astype(np.float32)
    table.flags.writeable = False
    return table


def gray_frame(clean_rgb: np.ndarray, bit_depth: int, light_level: float, noise_sigma_dn: float,
               seed: tuple[int, ...]) -> np.ndarray:
    """A monochrome camera's frame of a noise-free float32 RGB picture (DN of 8 bits, (h, w, 3)).

    BT.601 luma at ``bit_depth`` bits, scaled by ``light_level`` (a dim exposure), with the sensor noise
    ``noise_sigma_dn`` of 8-bit DN scaled to the depth, seeded by ``seed`` (the frame's own entropy), then
    rounded and clipped to the depth's range: uint8 up to 8 bits, else uint16. The static and the rotor twins'
    monochrome cameras both write these, in one compiled pass: 0.26 ms a 320×240 frame against 1.76 ms for
    NumPy's float64 luma and Gaussian draws.
    """
    top = 2 ** int(bit_depth) - 1
    work = np.ascontiguousarray(clean_rgb, dtype=np.float32)
    out = np.empty(work.shape[:2], dtype=np.uint8 if bit_depth <= 8 else np.uint16)
    state = np.random.SeedSequence(list(seed)).generate_state(1, np.uint64)[0]
    add_gray_table_noise(work, out, np.float32(light_level * top / 255.0),
                         _gray_noise_table(float(noise_sigma_dn) * top / 255.0), np.float32(top), np.uint64(state),
                         np.empty(out.size + 3, dtype=np.uint16))
    return out


# -- pictures ---------------------------------------------------------------------
def distort_fast(camera: CameraModel, points_px: np.ndarray) -> np.ndarray:
    """``camera.distort_points`` compiled, for the vertices the renderer draws every frame.

    OpenCV's forward model (what ``projectPoints`` computes with no rotation or translation) for up to five
    coefficients, equal to it within 3e-13 px: projectPoints costs ~70 ns a point and ~60 µs a call, which a
    rolling-shutter frame's ~50,000 per-row vertices, or a frame's few hundred outline vertices at every
    frame, would pay again and again. Other coefficient counts go to OpenCV.
    """
    d = np.asarray(camera.dist_coeffs, dtype=np.float64).ravel()
    if d.size > 5:
        return camera.distort_points(points_px)
    k1, k2, p1, p2, k3 = (float(v) for v in np.concatenate([d, np.zeros(5 - d.size)]))
    k = camera.camera_matrix
    pts = np.ascontiguousarray(points_px, dtype=np.float64).reshape(-1, 2)
    out = np.empty_like(pts)
    _distort5(pts, float(k[0, 0]), float(k[1, 1]), float(k[0, 2]), float(k[1, 2]), k1, k2, p1, p2, k3, out)
    return out


@njit(cache=True)
def _distort5(pts, fx, fy, cx, cy, k1, k2, p1, p2, k3, out):
    # The numpy form's operations in its order, point by point (no fastmath): the same bits.
    for i in range(pts.shape[0]):
        x = (pts[i, 0] - cx) / fx
        y = (pts[i, 1] - cy) / fy
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        out[i, 0] = fx * xd + cx
        out[i, 1] = fy * yd + cy


@functools.lru_cache(maxsize=4)
def scene_background(scene: Scene) -> np.ndarray:
    """The scene's background with its clutter, read-only, cached (campaigns render many videos of one scene)."""
    # Campaigns render many videos of one scene: build its background once.
    bg = scene.background()
    draw_clutter(bg, scene, None)
    bg.flags.writeable = False
    return bg


def picture_motion(scene: Scene, shift_px: tuple[float, float] = (0.0, 0.0), roll_rad: float = 0.0) -> np.ndarray:
    """The 2×3 map of the whole recorded picture: a roll about its centre, then a shift (camera motion).

    ``roll_rad`` turns the picture counter-clockwise as seen (y down), the sense in which
    :func:`servoscope.simulate.scene.marker_angle_rad` counts angles: a rolled camera adds
    the roll to every angle it sees.
    """
    c, s = math.cos(roll_rad), math.sin(roll_rad)
    cx, cy = 0.5 * (scene.width - 1), 0.5 * (scene.height - 1)
    return np.array([[c, s, cx - c * cx - s * cy + shift_px[0]],
                     [-s, c, cy + s * cx - c * cy + shift_px[1]]])


def airframe_motion(scene: Scene, rock_rad: float) -> np.ndarray:
    """The 2×3 map of the airframe rocking on its skids, in the ideal image: a turn by ``rock_rad`` about the
    point below the pivot at the picture's bottom edge, counter-clockwise positive as angles are counted.

    The blade, its pivot and everything fixed to the airframe (``Clutter.airframe``) turn with it;
    the rest of the scene stays.
    """
    c, s = math.cos(rock_rad), math.sin(rock_rad)
    cx, cy = scene.pivot_xy_px[0], float(scene.height - 1)
    return np.array([[c, s, cx - c * cx - s * cy], [-s, c, cy + s * cx - c * cy]])


@functools.lru_cache(maxsize=4)
def viewed_background(scene: Scene, view: ObliqueView) -> np.ndarray:
    """The scene's plain background (no clutter) as an oblique camera sees it, read-only, cached."""
    # The plain background (no clutter) as the oblique camera sees it, once per scene and view.
    # It is smooth (blotches tenths of the picture wide): a cubic warp by the homography alone
    # draws it to ~1e-3 DN; the lens's bending of it would not show.
    plain = np.ascontiguousarray(scene.background())
    bg = cv2.warpPerspective(plain, view.homography, (scene.width, scene.height), flags=cv2.INTER_CUBIC,
                             borderMode=cv2.BORDER_REFLECT)
    bg.flags.writeable = False
    return bg


def moved_points(xy: np.ndarray, motion: np.ndarray | None, airframe: np.ndarray | None = None) -> np.ndarray:
    """Points (n, 2) moved by ``airframe`` (2×3, first) and then by the picture's ``motion`` (2×3); None: not moved."""
    if airframe is not None:
        xy = xy @ airframe[:, :2].T + airframe[:, 2]
    return xy if motion is None else xy @ motion[:, :2].T + motion[:, 2]


def draw_clutter(image: np.ndarray, scene: Scene, motion: np.ndarray | None, airframe=None, place=None) -> None:
    """Composite the scene's clutter, moved by the picture's ``motion`` (2×3; the airframe's items first by
    ``airframe``, a map of recorded points), into ``image`` (float32 RGB). ``place(xy, on_airframe)``, when
    given, replaces ``airframe``: where an oblique camera records each item (its rocking included)."""
    for item in scene.clutter:
        xy = item.outline_px()
        if place is not None:
            xy = place(xy, item.airframe)
        elif item.airframe and airframe is not None:
            xy = airframe(xy)
        xy = moved_points(xy, motion)
        acc, x0, y0, sign = accumulated(xy, scene.width, scene.height)
        if acc.shape[0] > 0 and acc.shape[1] > 1:
            composite(image, acc, x0, y0, colour_rgb(item.colour), sign)


def gaussian_table() -> np.ndarray:
    """65536 equiprobable Gaussian quantiles, the sensor noise's inverse-CDF table (unit σ)."""
    # Midpoint quantiles of 65536 equiprobable bins: an exact-mean, unit-ish
    # variance discrete Gaussian (variance 1 - 4e-5 from the truncated tails).
    p = (np.arange(65536) + 0.5) / 65536.0
    return scipy.special.ndtri(p).astype(np.float64)


