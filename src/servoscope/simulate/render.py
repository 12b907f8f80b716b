"""The digital twin's frame renderer: the scene drawn with exact coverage, the camera's motion and noise.

Every part of the scene (blade, stickers, LED, clutter) is drawn with its exact
area coverage of each pixel (:mod:`servoscope.simulate.coverage`), moved as the
camera shakes or rolls and the airframe rocks (:func:`picture_motion`,
:func:`airframe_motion`). A camera that looks at the blade's plane from the side
(:class:`~servoscope.simulate.view.ObliqueView`) maps every outline by its
homography; the maps act in the order airframe rocking (in the plane) → view →
lens → picture motion (in the recorded picture).

Sensor noise uses a splitmix64 stream (in numba) whose state is drawn per
frame from a numpy ``SeedSequence([noise_seed, frame_index])``, mapped through
an inverse-CDF table of 65536 Gaussian quantiles: numpy's
``standard_normal`` plus rounding on 1.2 M samples per frame would by itself
eat most of the 10 ms budget per frame. The table truncates the Gaussian at
about ±4.3 sigma, irrelevant after rounding to 8 bits.
"""

from __future__ import annotations

import functools
import math

from dataclasses import replace

import cv2
from collections.abc import Callable, Sequence

import numpy as np
import scipy.special

from numba import njit

from ..camera.model import CameraModel
from ..errors import ServoscopeError
from .coverage import accumulated, composite, composite_rows, polygon_coverage, signed_area
from .scene import Scene, colour_rgb
from .view import ObliqueView, densify_closed

__all__ = ["polygon_coverage", "FrameRenderer", "render_frame"]


# -- kernels -------------------------------------------------------------------
@njit(cache=True, inline="always")
def _round_clip(v: np.float32) -> np.uint8:
    # Branch-free clip, then truncation of v + 1/2 (v >= 0) is rounding; the
    # branchy version is ten times slower on noisy data.
    v = min(max(v + np.float32(0.5), np.float32(0.0)), np.float32(255.0))
    return np.uint8(np.int32(v))


@njit(cache=True)
def _finish(work: np.ndarray, out: np.ndarray, scaled_table: np.ndarray, state: np.uint64) -> None:
    """out = clip(round(work + noise), 0, 255) as uint8; noise = scaled_table[random index]."""
    w = work.ravel()
    o = out.ravel()
    n = w.shape[0]
    s = state
    golden = np.uint64(0x9E3779B97F4A7C15)
    m1 = np.uint64(0xBF58476D1CE4E5B9)
    m2 = np.uint64(0x94D049BB133111EB)
    mask = np.uint64(0xFFFF)
    s16 = np.uint64(16)
    s32 = np.uint64(32)
    s48 = np.uint64(48)
    nblocks = (n + 3) // 4
    for b in range(nblocks):
        # splitmix64: one 64-bit draw feeds four 16-bit table indices.
        s = s + golden
        z = s
        z = (z ^ (z >> np.uint64(30))) * m1
        z = (z ^ (z >> np.uint64(27))) * m2
        z = z ^ (z >> np.uint64(31))
        k = 4 * b
        if k + 4 <= n:
            o[k] = _round_clip(w[k] + scaled_table[np.intp(z & mask)])
            o[k + 1] = _round_clip(w[k + 1] + scaled_table[np.intp((z >> s16) & mask)])
            o[k + 2] = _round_clip(w[k + 2] + scaled_table[np.intp((z >> s32) & mask)])
            o[k + 3] = _round_clip(w[k + 3] + scaled_table[np.intp(z >> s48)])
        else:
            for q in range(n - k):
                o[k + q] = _round_clip(w[k + q] + scaled_table[np.intp((z >> np.uint64(16 * q)) & mask)])


# -- public helpers ---------------------------------------------------------------
def _distort(camera: CameraModel, points_px: np.ndarray) -> np.ndarray:
    """``camera.distort_points`` in numpy, for the many vertices of a rolling-shutter frame.

    OpenCV's forward model (what ``projectPoints`` computes with no rotation
    or translation) for up to five coefficients; projectPoints costs ~70 ns a
    point, which a frame's ~50 000 per-row vertices would turn into 4 ms.
    Other coefficient counts go to OpenCV.
    """
    d = np.asarray(camera.dist_coeffs, dtype=np.float64).ravel()
    if d.size > 5:
        return camera.distort_points(points_px)
    k1, k2, p1, p2, k3 = np.concatenate([d, np.zeros(5 - d.size)])
    k = camera.camera_matrix
    x = (points_px[:, 0] - k[0, 2]) / k[0, 0]
    y = (points_px[:, 1] - k[1, 2]) / k[1, 1]
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    return np.stack([k[0, 0] * xd + k[0, 2], k[1, 1] * yd + k[1, 2]], axis=1)


@functools.lru_cache(maxsize=4)
def _background(scene: Scene) -> np.ndarray:
    # Campaigns render many videos of one scene: build its background once.
    bg = scene.background()
    _draw_clutter(bg, scene, None)
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
def _viewed_background(scene: Scene, view: ObliqueView) -> np.ndarray:
    # The plain background (no clutter) as the oblique camera sees it, once per scene and view.
    # It is smooth (blotches tenths of the picture wide): a cubic warp by the homography alone
    # draws it to ~1e-3 DN; the lens's bending of it would not show.
    plain = np.ascontiguousarray(scene.background())
    bg = cv2.warpPerspective(plain, view.homography, (scene.width, scene.height), flags=cv2.INTER_CUBIC,
                             borderMode=cv2.BORDER_REFLECT)
    bg.flags.writeable = False
    return bg


def _moved(xy: np.ndarray, motion: np.ndarray | None, airframe: np.ndarray | None = None) -> np.ndarray:
    if airframe is not None:
        xy = xy @ airframe[:, :2].T + airframe[:, 2]
    return xy if motion is None else xy @ motion[:, :2].T + motion[:, 2]


def _draw_clutter(image: np.ndarray, scene: Scene, motion: np.ndarray | None, airframe=None, place=None) -> None:
    """Composite the scene's clutter, moved by the picture's ``motion`` (2×3; the airframe's items first by
    ``airframe``, a map of recorded points), into ``image`` (float32 RGB). ``place(xy, on_airframe)``, when
    given, replaces ``airframe``: where an oblique camera records each item (its rocking included)."""
    for item in scene.clutter:
        xy = item.outline_px()
        if place is not None:
            xy = place(xy, item.airframe)
        elif item.airframe and airframe is not None:
            xy = airframe(xy)
        xy = _moved(xy, motion)
        acc, x0, y0, sign = accumulated(xy, scene.width, scene.height)
        if acc.shape[0] > 0 and acc.shape[1] > 1:
            composite(image, acc, x0, y0, colour_rgb(item.colour), sign)


def _gaussian_table() -> np.ndarray:
    # Midpoint quantiles of 65536 equiprobable bins: an exact-mean, unit-ish
    # variance discrete Gaussian (variance 1 - 4e-5 from the truncated tails).
    p = (np.arange(65536) + 0.5) / 65536.0
    return scipy.special.ndtri(p).astype(np.float64)


class FrameRenderer:
    """Renders frames of a Scene as a (possibly distorting) camera records them.

    The static background is computed once; each frame only restores and
    redraws the bounding boxes of the blade, stickers and LED, then adds
    noise and rounds to 8 bits.

    Parameters
    ----------
    scene : Scene
        What is filmed.
    camera : CameraModel, optional
        Lens model; None means an ideal (distortion-free) camera. Its
        image_size must equal the scene's.
    noise_sigma_dn : float
        Standard deviation of the Gaussian sensor noise, DN (per channel).
    noise_seed : int
        Seed of the noise; frame ``i``'s noise depends only on
        ``(noise_seed, i)``.
    mode_shape : callable, optional
        The blade mode's shape along the chord: ``mode_shape(u)`` (u the blade
        frame's chord coordinate, px) is how far a point there moves across
        the chord per px of ``heave_px`` (a bending mode). The blade's outline
        and the LED bend with it, each sticker moves whole by its centre's
        share. None: 1 everywhere (the whole blade heaves). A sequence: one
        shape per mode (None for a rigid one), each frame's ``heave_px`` then one
        value per mode.
    view : ObliqueView, optional
        A camera that looks at the blade's plane from the side: the scene's
        coordinates are then plane px, and every outline (blade, stickers,
        LED, clutter) is mapped by the view's homography before the lens; the
        plain background is warped by it once. Its picture size must be the
        scene's. None or a square-on view: the square-on camera (the same
        code path, the same bytes).
    """

    def __init__(self, scene: Scene, camera: CameraModel | None = None, *,
                 noise_sigma_dn: float = 1.5, noise_seed: int = 0,
                 mode_shape: Callable[[np.ndarray], np.ndarray] | None
                 | Sequence[Callable[[np.ndarray], np.ndarray] | None] = None,
                 view: ObliqueView | None = None) -> None:
        if camera is not None and tuple(camera.image_size) != (scene.width, scene.height):
            raise ServoscopeError(
                f"camera image size {camera.image_size} differs from the scene's {(scene.width, scene.height)}")
        if view is not None and (view.width, view.height) != (scene.width, scene.height):
            raise ServoscopeError(f"view picture size {(view.width, view.height)} differs from the scene's "
                                  f"{(scene.width, scene.height)}")
        if not noise_sigma_dn >= 0:
            raise ServoscopeError("noise_sigma_dn must be >= 0")
        self.scene = scene
        self.camera = camera if camera is not None and camera.has_distortion else None
        self.noise_sigma_dn = float(noise_sigma_dn)
        self.noise_seed = int(noise_seed)
        # A square-on view is the identity: dropped, so that the square-on code path draws it.
        self.view = view if view is not None and not view.is_square_on else None
        self._bg = _background(scene) if self.view is None else self._viewed_static()
        self._work = self._bg.copy()
        self._dirty: list[tuple[int, int, int, int]] = []
        # Noise values pre-scaled to DN; float32 keeps the table in L2 cache.
        self._noise_table = (_gaussian_table() * self.noise_sigma_dn).astype(np.float32)
        # Blade-frame outlines of everything that moves, in compositing order.
        lead_uv, trail_uv = scene.sticker_centres_uv()
        k = scene.sticker_vertices
        ang = 2.0 * np.pi * np.arange(k) / k
        unit = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        rl = 0.5 * scene.led_diameter_px
        sticker = scene.sticker_outline_uv()
        self._parts_uv = [scene.blade_outline_uv(), lead_uv + sticker, trail_uv + sticker,
                          *(c + sticker for c in scene.extra_centres_uv())]
        self._colours = [colour_rgb(c) for c in (scene.blade_colour, scene.lead_colour, scene.trail_colour,
                                                  *(c for c, _ in scene.extra_stickers))]
        # An LED on the stand (fixed in the picture): its housing and disk, ideal px, drawn last.
        self._fixed_led: list[np.ndarray] = []
        if scene.led_fixed_px is not None:
            self._fixed_led = [np.asarray(scene.led_fixed_px) + 2.5 * rl * unit,
                               np.asarray(scene.led_fixed_px) + rl * unit]
            self._colours.append(colour_rgb(scene.blade_colour))
        elif scene.led_offset_px != 0:
            # An LED off the chord sits in a dark housing (the blade's colour) on
            # a bracket, as on the blade itself: a tracker that reads the LED's
            # brightness around it sees the LED on a dark ground either way.
            self._parts_uv.append(scene.led_centre_uv() + 2.5 * rl * unit)
            self._colours.append(colour_rgb(scene.blade_colour))
        if scene.led_fixed_px is None:
            self._parts_uv.append(scene.led_centre_uv() + rl * unit)
        self._splits = np.cumsum([len(p) for p in self._parts_uv])[:-1]
        self._all_uv = np.concatenate(self._parts_uv, axis=0)
        # How far each vertex moves per px of each mode's heave: a sticker (a stiff patch) by its
        # centre's share, everything else by its own place's; None: a mode that moves all alike.
        shapes = list(mode_shape) if isinstance(mode_shape, (list, tuple)) else [mode_shape]
        self._heave_share: list[np.ndarray | None] = [self._share_of(f, [lead_uv, trail_uv,
                                                                         *scene.extra_centres_uv()])
                                                      for f in shapes]
        self._led_on = colour_rgb(scene.led_colour)
        self._led_off = colour_rgb(scene.led_off_colour)

    def _viewed_static(self) -> np.ndarray:
        """The oblique camera's static picture: the warped plain background and the clutter drawn on it."""
        bg = _viewed_background(replace(self.scene, clutter=()), self.view).copy()
        _draw_clutter(bg, self.scene, None, place=self._clutter_place(None))
        bg.flags.writeable = False
        return bg

    def _clutter_place(self, airframe: np.ndarray | None):
        """Where the oblique camera records a clutter item given in the square-on recorded picture.

        The square-on picture's points go back through the lens to the plane (its ideal image),
        the airframe's items rock there, then the view and the lens map them to this picture.
        The lens bends straight edges: outlines are densified first.
        """
        camera, view, step = self.camera, self.view, self.scene.max_segment_px

        def place(xy: np.ndarray, on_airframe: bool) -> np.ndarray:
            if camera is not None:
                xy = camera.undistort_points(densify_closed(xy, step))[0]
            if on_airframe and airframe is not None:
                xy = _moved(xy, None, airframe)
            xy = view.apply(xy)
            return xy if camera is None else camera.distort_points(xy)
        return place

    def _share_of(self, shape, centres) -> np.ndarray | None:
        if shape is None:
            return None
        share = [np.asarray(shape(p[:, 0]), dtype=np.float64) for p in self._parts_uv]
        for k, c in enumerate(centres):
            share[1 + k] = np.full(len(self._parts_uv[1 + k]), float(shape(np.array([c[0]]))[0]))
        return np.concatenate(share)

    def outlines_px(self, pitch_rad: float, airframe: np.ndarray | None = None,
                    heave_px: float | Sequence[float] = 0.0) -> list[np.ndarray]:
        """Recorded (distorted) outlines of blade, lead sticker, trail sticker, extra stickers, (LED housing,) LED.

        ``airframe`` (2×3, :func:`airframe_motion`) turns them with the airframe, in the
        ideal image (before the lens), as the airframe turns in the world. ``heave_px``
        moves the whole blade across its chord (the blade flapping, up positive): one value
        per mode shape the renderer was given.
        """
        q = (float(heave_px),) if np.isscalar(heave_px) else tuple(float(v) for v in heave_px)
        if len(q) != len(self._heave_share):
            raise ServoscopeError(f"heave_px: {len(q)} values for {len(self._heave_share)} modes")
        if not any(q):
            uv = self._all_uv
        elif len(q) == 1 and self._heave_share[0] is None:
            uv = self._all_uv + np.array([0.0, q[0]])
        else:
            uv = self._all_uv.copy()
            for qj, share in zip(q, self._heave_share):
                uv[:, 1] += qj if share is None else qj * share
        xy = _moved(self.scene.to_image(uv, float(pitch_rad)), None, airframe)
        if self._fixed_led:
            xy = np.concatenate([xy, *self._fixed_led], axis=0)
        if self.view is not None:
            xy = self.view.apply(xy)
        if self.camera is not None:
            xy = self.camera.distort_points(xy)
        if self._fixed_led:
            n = len(self._all_uv)
            return np.split(xy[:n], self._splits) + np.split(xy[n:], [len(self._fixed_led[0])])
        return np.split(xy, self._splits)

    def _airframe_map(self, airframe: np.ndarray | None):
        """Recorded points of something fixed to the airframe → where the airframe's turn puts them (through the lens)."""
        if airframe is None:
            return None
        if self.camera is None:
            return lambda xy: _moved(xy, None, airframe)
        camera = self.camera
        return lambda xy: camera.distort_points(_moved(camera.undistort_points(xy)[0], None, airframe))

    def _restore_lit(self, gain: np.ndarray | float, motion: np.ndarray | None,
                     airframe: np.ndarray | None = None) -> None:
        """Fill the whole working buffer with the background, moved (2×3 map) and scaled by the lamps' gain;
        the airframe's clutter moved by ``airframe`` first."""
        h, w = self.scene.height, self.scene.width
        g = np.asarray(gain, dtype=np.float32)
        if motion is None and airframe is None:
            np.multiply(self._bg, g.reshape(-1, 1, 1) if g.ndim else g, out=self._work)
        else:
            # The plain background is smooth (blotches tenths of the image
            # wide): cubic interpolation moves it to ~1e-3 DN. Clutter has
            # sharp edges, which interpolation would not move exactly: it is
            # drawn again, moved, with exact coverage.
            bare = replace(self.scene, clutter=())
            plain = _background(bare) if self.view is None else _viewed_background(bare, self.view)
            if motion is None:
                self._work[:] = plain
            else:
                self._work[:] = cv2.warpAffine(np.ascontiguousarray(plain), motion, (w, h), flags=cv2.INTER_CUBIC,
                                               borderMode=cv2.BORDER_REFLECT)
            if self.view is None:
                _draw_clutter(self._work, self.scene, motion, self._airframe_map(airframe))
            else:
                _draw_clutter(self._work, self.scene, motion, place=self._clutter_place(airframe))
            self._work *= g
        self._dirty = [(0, h, 0, w)]

    def composite(self, pitch_rad: float, led_level: float, lamp_gain: float = 1.0,
                  shift_px: tuple[float, float] = (0.0, 0.0), roll_rad: float = 0.0,
                  rock_rad: float = 0.0, heave_px: float = 0.0) -> np.ndarray:
        """The noise-free frame, float32 DN, shape (height, width, 3).

        The returned array is the renderer's working buffer: copy it before
        the next call if it must be kept.

        Parameters
        ----------
        pitch_rad : float
            Blade pitch.
        led_level : float
            Lit fraction of the exposure, in [0, 1].
        lamp_gain : float
            Mean light of the lamps over the exposure (flicker): scales
            everything the lamps light, not the lit LED. 1 draws only what
            moves over the cached background.
        shift_px : (float, float)
            Translation of the whole picture, recorded pixels (camera shake).
        roll_rad : float
            Rotation of the whole picture about its centre (a camera that rolls, a
            phone's stabilisation), see :func:`picture_motion`.
        rock_rad : float
            The airframe rocking on its skids: the blade and the airframe's clutter
            turn, the rest stays (see :func:`airframe_motion`).
        heave_px : float
            The blade flapping: moved across its chord (px, up positive).
        """
        if not 0.0 <= led_level <= 1.0:
            raise ServoscopeError(f"led_level must be in [0, 1], not {led_level}")
        shift_px = (float(shift_px[0]), float(shift_px[1]))
        motion = None if shift_px == (0.0, 0.0) and roll_rad == 0.0 else picture_motion(self.scene, shift_px, roll_rad)
        airframe = None if rock_rad == 0.0 else airframe_motion(self.scene, rock_rad)
        lit = lamp_gain != 1.0 or motion is not None or airframe is not None
        if lit:
            self._restore_lit(lamp_gain, motion, airframe)
            # The dark LED is seen by the lamps' light; a lit one shines its own.
            led_colour = led_level * self._led_on + (1.0 - led_level) * lamp_gain * self._led_off
            colours = [c * lamp_gain for c in self._colours] + [led_colour]
        else:
            for (y0, y1, x0, x1) in self._dirty:
                self._work[y0:y1, x0:x1] = self._bg[y0:y1, x0:x1]
            self._dirty = []
            led_colour = self._led_off + led_level * (self._led_on - self._led_off)
            colours = self._colours + [led_colour]
        w, h = self.scene.width, self.scene.height
        outlines = self.outlines_px(pitch_rad, airframe, heave_px)
        if motion is not None:
            outlines = [_moved(xy, motion) for xy in outlines]
        for xy, colour in zip(outlines, colours):
            acc, x0, y0, sign = accumulated(xy, w, h)
            ny, nx = acc.shape[0], acc.shape[1] - 1
            if nx <= 0 or ny <= 0:
                continue
            composite(self._work, acc, x0, y0, colour.astype(np.float64), sign)
            if not lit:
                self._dirty.append((y0, y0 + ny, x0, x0 + nx))
        return self._work

    def composite_rolling(self, row_pitch_rad: np.ndarray, row_led_level: np.ndarray,
                          row_lamp_gain: np.ndarray | None = None) -> np.ndarray:
        """The noise-free frame of a rolling shutter: row y shows the scene at its own time.

        Every moving part is drawn row by row, each row with the part's
        outline at that row's pitch and the LED in that row's level; only the
        rows a part can reach in this frame are visited. With the same pitch
        and level on every row this draws what :meth:`composite` draws (up to
        rounding: the coverage is accumulated per row).

        Parameters
        ----------
        row_pitch_rad : ndarray, shape (height,)
            Blade pitch seen by each image row (the pose at the row's time,
            averaged over its exposure).
        row_led_level : ndarray, shape (height,)
            Lit fraction of each row's exposure, in [0, 1].
        row_lamp_gain : ndarray, shape (height,), optional
            Mean light of flickering lamps over each row's exposure (the
            bands a rolling shutter shows); None: steady lamps.

        Returns
        -------
        ndarray of float32, shape (height, width, 3)
            The renderer's working buffer (copy it to keep it).
        """
        h, w = self.scene.height, self.scene.width
        pitch = np.asarray(row_pitch_rad, dtype=np.float64)
        level = np.asarray(row_led_level, dtype=np.float64)
        if pitch.shape != (h,) or level.shape != (h,):
            raise ServoscopeError(f"composite_rolling: need one pitch and one LED level per row ({h})")
        if not (np.all(level >= 0.0) and np.all(level <= 1.0)):
            raise ServoscopeError("row_led_level must be in [0, 1]")
        if row_lamp_gain is None:
            for (y0, y1, x0, x1) in self._dirty:
                self._work[y0:y1, x0:x1] = self._bg[y0:y1, x0:x1]
            self._dirty = []
            row_colours = [np.broadcast_to(c, (h, 3)) for c in self._colours]
            row_colours.append(self._led_off[None, :] + level[:, None] * (self._led_on - self._led_off)[None, :])
        else:
            gain = np.asarray(row_lamp_gain, dtype=np.float64)
            if gain.shape != (h,) or not np.all(np.isfinite(gain)):
                raise ServoscopeError(f"composite_rolling: need one finite lamp gain per row ({h})")
            self._restore_lit(gain, None)
            row_colours = [gain[:, None] * c[None, :] for c in self._colours]
            row_colours.append(level[:, None] * self._led_on[None, :]
                               + ((1.0 - level) * gain)[:, None] * self._led_off[None, :])
        keep_dirty = row_lamp_gain is None
        # The rows a part can reach: its extent at the frame's extreme pitches,
        # widened by 2 px for the curvature of the arcs its vertices follow
        # in between (R·δp²/8, far below a pixel for a frame's motion).
        lo, hi = self.outlines_px(float(pitch.min())), self.outlines_px(float(pitch.max()))
        for uv, a, b, colours in zip(self._parts_uv, lo, hi, row_colours):
            ys = np.concatenate([a[:, 1], b[:, 1]])
            y0 = max(int(np.floor(ys.min() + 0.5)) - 2, 0)
            y1 = min(int(np.floor(ys.max() + 0.5)) + 2, h - 1)
            if y1 < y0:
                continue
            rows = np.arange(y0, y1 + 1)
            xy = self.scene.to_image(uv, pitch[rows])
            if self.view is not None:
                xy = self.view.apply(xy)
            if self.camera is not None:
                xy = _distort(self.camera, xy.reshape(-1, 2)).reshape(xy.shape)
            xs = np.ascontiguousarray(xy[..., 0])
            yy = np.ascontiguousarray(xy[..., 1])
            x0 = max(int(np.floor(xs.min() + 0.5)), 0)
            x1 = min(int(np.floor(xs.max() + 0.5)), w - 1)
            if x1 < x0:
                continue
            sign = -1.0 if signed_area(xy[0]) >= 0 else 1.0
            composite_rows(self._work, xs, yy, rows.astype(np.int64), x0, x1 - x0 + 1,
                            np.ascontiguousarray(colours[rows], dtype=np.float64), sign)
            if keep_dirty:
                self._dirty.append((y0, y1 + 1, x0, x1 + 1))
        return self._work

    def render_rolling(self, row_pitch_rad: np.ndarray, row_led_level: np.ndarray, frame_index: int = 0,
                       row_lamp_gain: np.ndarray | None = None) -> np.ndarray:
        """One recorded rolling-shutter frame: :meth:`composite_rolling`, seeded noise, uint8.

        Parameters
        ----------
        row_pitch_rad, row_led_level : ndarray, shape (height,)
            See :meth:`composite_rolling`.
        frame_index : int
            Index of the frame (selects its noise, as in :meth:`render`).
        row_lamp_gain : ndarray, shape (height,), optional
            See :meth:`composite_rolling`.

        Returns
        -------
        ndarray of uint8, shape (height, width, 3)
        """
        return self._finished(self.composite_rolling(row_pitch_rad, row_led_level, row_lamp_gain), frame_index)

    def static_picture(self) -> np.ndarray:
        """The recorded static picture (background and clutter, through the view), float32 DN, a copy."""
        return self._bg.copy()

    def add_noise(self, clean: np.ndarray, frame_index: int = 0) -> np.ndarray:
        """``clean`` (float32 DN, the frame's shape) with frame ``frame_index``'s seeded sensor noise, as uint8.

        The frames' noise model and seeds (:meth:`render`): for pictures composed outside the
        renderer, such as the twin's board photo.
        """
        work = np.ascontiguousarray(clean, dtype=np.float32)
        if work.shape != self._bg.shape:
            raise ServoscopeError(f"add_noise: need a {self._bg.shape} picture, not {work.shape}")
        return self._finished(work, frame_index)

    def _finished(self, work: np.ndarray, frame_index: int) -> np.ndarray:
        out = np.empty(work.shape, dtype=np.uint8)
        state = np.random.SeedSequence([self.noise_seed, int(frame_index)]).generate_state(1, np.uint64)[0]
        _finish(work, out, self._noise_table, np.uint64(state))
        return out

    def render(self, pitch_rad: float, led_level: float, frame_index: int = 0, lamp_gain: float = 1.0,
               shift_px: tuple[float, float] = (0.0, 0.0), roll_rad: float = 0.0,
               rock_rad: float = 0.0, heave_px: float = 0.0) -> np.ndarray:
        """One recorded frame: composite, add seeded noise, round to uint8.

        Parameters
        ----------
        pitch_rad : float
            Blade pitch at the frame time.
        led_level : float
            Fraction of the exposure during which the LED was lit, in [0, 1].
        frame_index : int
            Index of the frame (selects its noise).
        lamp_gain, shift_px, roll_rad, rock_rad, heave_px : float, (float, float), float, float, float
            Lamps' flicker, camera shake and roll, the airframe's rocking, the blade's flapping,
            see :meth:`composite`.

        Returns
        -------
        ndarray of uint8, shape (height, width, 3)
            RGB frame.
        """
        return self._finished(self.composite(pitch_rad, led_level, lamp_gain, shift_px, roll_rad, rock_rad,
                                             heave_px), frame_index)

    def render_blurred(self, pitch_rad: np.ndarray, led_lit: np.ndarray, frame_index: int = 0,
                       lamp_gain: np.ndarray | None = None, shift_px: tuple[float, float] = (0.0, 0.0),
                       roll_rad: float = 0.0, rock_rad: float = 0.0) -> np.ndarray:
        """One recorded frame with real motion blur: the mean of sub-exposure composites.

        A sensor integrates the moving blade: sampling the exposure at
        ``m`` instants (equal sub-intervals, each drawn at its middle) and
        averaging the noise-free frames smears the stickers along their arcs
        as a long shutter does.

        Parameters
        ----------
        pitch_rad : ndarray, shape (m,)
            Pitch at the middle of each sub-interval.
        led_lit : ndarray, shape (m,)
            Lit fraction of each sub-interval, in [0, 1].
        frame_index : int
            Index of the frame (selects its noise).
        lamp_gain : ndarray, shape (m,), optional
            The lamps' light in each sub-interval; None: steady.
        shift_px : (float, float)
            Camera shake (the same throughout the exposure).
        roll_rad, rock_rad : float
            Camera roll and the airframe's rocking (the same throughout the exposure).

        Returns
        -------
        ndarray of uint8, shape (height, width, 3)
        """
        pitch = np.asarray(pitch_rad, dtype=np.float64).ravel()
        lit = np.asarray(led_lit, dtype=np.float64).ravel()
        gain = np.ones_like(pitch) if lamp_gain is None else np.asarray(lamp_gain, dtype=np.float64).ravel()
        if pitch.size == 0 or lit.shape != pitch.shape or gain.shape != pitch.shape:
            raise ServoscopeError("render_blurred: need one pitch, LED level and lamp gain per sample")
        total = np.zeros((self.scene.height, self.scene.width, 3), dtype=np.float64)
        for p, level, g in zip(pitch, lit, gain):
            total += self.composite(float(p), float(level), float(g), shift_px, roll_rad, rock_rad)
        return self._finished((total / pitch.size).astype(np.float32), frame_index)


def render_frame(scene: Scene, pitch_rad: float, led_level: float = 1.0, *,
                 camera: CameraModel | None = None, noise_sigma_dn: float = 0.0,
                 noise_seed: int = 0, frame_index: int = 0) -> np.ndarray:
    """Render a single frame (convenience wrapper around :class:`FrameRenderer`).

    Returns
    -------
    ndarray of uint8, shape (height, width, 3)
    """
    r = FrameRenderer(scene, camera, noise_sigma_dn=noise_sigma_dn, noise_seed=noise_seed)
    return r.render(pitch_rad, led_level, frame_index)
