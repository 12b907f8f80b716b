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

from dataclasses import replace

import cv2
from collections.abc import Callable, Sequence

import numpy as np

from ..camera.model import CameraModel
from ..errors import ServoscopeError
from .coverage import accumulated, composite, composite_rows, polygon_coverage, signed_area
from .scene import Scene, colour_rgb
from .render_parts import (add_table_noise, airframe_motion, distort_fast, draw_clutter, gaussian_table, moved_points,
                           picture_motion, scene_background, viewed_background)
from .view import ObliqueView, densify_closed

__all__ = ["polygon_coverage", "FrameRenderer", "airframe_motion", "picture_motion", "render_frame"]


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
        self._bg = scene_background(scene) if self.view is None else self._viewed_static()
        self._work = self._bg.copy()
        self._dirty: list[tuple[int, int, int, int]] = []
        # Noise values pre-scaled to DN; float32 keeps the table in L2 cache.
        self._noise_table = (gaussian_table() * self.noise_sigma_dn).astype(np.float32)
        self._noise_index = np.empty(0, dtype=np.uint16)
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
        bg = viewed_background(replace(self.scene, clutter=()), self.view).copy()
        draw_clutter(bg, self.scene, None, place=self._clutter_place(None))
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
                xy = moved_points(xy, None, airframe)
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
        xy = moved_points(self.scene.to_image(uv, float(pitch_rad)), None, airframe)
        if self._fixed_led:
            xy = np.concatenate([xy, *self._fixed_led], axis=0)
        if self.view is not None:
            xy = self.view.apply(xy)
        if self.camera is not None:
            xy = distort_fast(self.camera, xy)
        if self._fixed_led:
            n = len(self._all_uv)
            return np.split(xy[:n], self._splits) + np.split(xy[n:], [len(self._fixed_led[0])])
        return np.split(xy, self._splits)

    def _airframe_map(self, airframe: np.ndarray | None):
        """Recorded points of something fixed to the airframe → where the airframe's turn puts them (through the lens)."""
        if airframe is None:
            return None
        if self.camera is None:
            return lambda xy: moved_points(xy, None, airframe)
        camera = self.camera
        return lambda xy: camera.distort_points(moved_points(camera.undistort_points(xy)[0], None, airframe))

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
            plain = scene_background(bare) if self.view is None else viewed_background(bare, self.view)
            if motion is None:
                self._work[:] = plain
            else:
                self._work[:] = cv2.warpAffine(np.ascontiguousarray(plain), motion, (w, h), flags=cv2.INTER_CUBIC,
                                               borderMode=cv2.BORDER_REFLECT)
            if self.view is None:
                draw_clutter(self._work, self.scene, motion, self._airframe_map(airframe))
            else:
                draw_clutter(self._work, self.scene, motion, place=self._clutter_place(airframe))
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
            outlines = [moved_points(xy, motion) for xy in outlines]
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
                xy = distort_fast(self.camera, xy.reshape(-1, 2)).reshape(xy.shape)
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
        if self._noise_index.size < work.size + 3:
            self._noise_index = np.empty(work.size + 3, dtype=np.uint16)  # the kernel's scratch, kept
        add_table_noise(work, out, self._noise_table, np.uint64(state), self._noise_index)
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
