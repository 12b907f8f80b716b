"""The turning rotor's footage (issue 33): frames of blades passing the camera, and a clip with its truth.

Every part is drawn with its exact area coverage (:mod:`servoscope.simulate.coverage`), in the
ideal pinhole picture of :class:`~servoscope.simulate.rotor.RotorRig`: each blade's span from its
root radius to its tip is a prism of the tip's section, whose silhouette is the convex hull of
its two end sections' projections (the section is convex); the tip face's two stickers are discs
on it, projected (ellipses away from ψ = 0), drawn while the tip face looks at the camera. Blades
are painted far to near. The motion blur is real: a 0.3 m tip at 20 rev/s moves ~130,000 px/s
across a 320-px picture at 0.32 m, 3 px in a 1/40,000 s shutter, so each frame is the mean of
sub-exposure pictures no more than ``blur_step_px`` of tip travel apart. The LED is fixed on the
airframe (a static spot in a dark housing) and goes dark at the input's start, lit for the
exposure's share before it. The background, the clutter, the sensor noise (colour) and the
monochrome camera's samples are the static twin's.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path

import cv2
import numpy as np

from ..errors import ServoscopeError
from ..video.sequence_writer import MrawWriter
from ..video.writer import VideoWriter
from .coverage import accumulated, composite
from .render import FrameRenderer
from .render_parts import gray_frame
from .rotor import RotorRig, rotor_passes
from .scene import Scene, colour_rgb, led_exposure_fraction

__all__ = ["RotorRenderer", "WHITE_STICKER", "render_rotor_clip", "rotor_frame_times_s", "pass_frames"]

# Vertices of a sticker's disc: the coverage is exact for the polygon, whose centroid is the
# disc's centre by symmetry; its area is 0.3 % short of the circle's, as a printed sticker's
# size is unknown anyway.
_STICKER_VERTICES = 64
#: A monochrome camera's stickers: white dots on the dark tip, as the static twin's.
WHITE_STICKER = "#f4f4f4"


def rotor_frame_times_s(n_frames: int, fps: Fraction) -> np.ndarray:
    """Frame k's time, ``k / fps`` (s), each correctly rounded: the video's own clock."""
    fps = Fraction(fps)
    return (np.arange(n_frames, dtype=np.float64) * fps.denominator) / fps.numerator


class RotorRenderer:
    """Renders the rotor as the high-speed camera records it.

    Parameters
    ----------
    rig : RotorRig
    width, height : int
        Picture size, px.
    exposure_s : float
        Shutter time (s); 0: no blur.
    noise_sigma_dn : float
        Sensor noise (DN, per channel), seeded per frame as the static twin's.
    noise_seed : int
    background_seed : int
        The static background's blotches.
    led_xy_px : (float, float) or None
        The airframe's LED (px); None: a tenth of the width in, a sixth of the height down.
    led_diameter_px : float
    blur_step_px : float
        Most tip travel between two sub-exposure pictures, px.
    blur_max_samples : int
    white_stickers : bool
        Every sticker white, as a monochrome camera's users stick on (the blades then told apart by their order).
    """

    def __init__(self, rig: RotorRig, width: int, height: int, *, exposure_s: float, noise_sigma_dn: float = 1.5,
                 noise_seed: int = 0, background_seed: int = 0, led_xy_px: tuple[float, float] | None = None,
                 led_diameter_px: float = 8.0, blur_step_px: float = 1.0, blur_max_samples: int = 24,
                 white_stickers: bool = False) -> None:
        if not (exposure_s >= 0 and math.isfinite(exposure_s)):
            raise ServoscopeError(f"exposure_s must be >= 0, not {exposure_s!r}")
        self.rig = rig
        self.width, self.height = int(width), int(height)
        self.exposure_s = float(exposure_s)
        led = (0.1 * width, height / 6.0) if led_xy_px is None else (float(led_xy_px[0]), float(led_xy_px[1]))
        self.led_xy_px = led
        self.scene = Scene.for_size(self.width, self.height, background_seed=background_seed, led_fixed_px=led)
        # The static twin's renderer, for its background and its seeded sensor noise only.
        self._frames = FrameRenderer(self.scene, None, noise_sigma_dn=noise_sigma_dn, noise_seed=noise_seed)
        self.noise_sigma_dn = float(noise_sigma_dn)
        self.noise_seed = int(noise_seed)
        bg = self._frames.static_picture()
        k = 96
        ang = 2.0 * np.pi * np.arange(k) / k
        unit = np.stack([np.cos(ang), np.sin(ang)], axis=1)
        r = 0.5 * led_diameter_px
        self._led_disc = np.asarray(led) + r * unit
        self._draw(bg, np.asarray(led) + 2.5 * r * unit, colour_rgb(rig.blade_colour))  # the LED's dark housing
        self._bg = bg
        self._led_on = colour_rgb(self.scene.led_colour)
        self._led_off = colour_rgb(self.scene.led_off_colour)
        self.blur_samples = 1 if self.exposure_s == 0 else int(min(blur_max_samples, max(
            1, math.ceil(rig.tip_speed_px_per_s() * self.exposure_s / blur_step_px))))
        self._section = rig.section_uv_m()
        lead, trail = rig.sticker_centres_uv_m()
        ang = 2.0 * np.pi * np.arange(_STICKER_VERTICES) / _STICKER_VERTICES
        disc = 0.5 * rig.sticker_diameter_m * np.stack([np.cos(ang), np.sin(ang)], axis=1)
        self._stickers = (lead + disc, trail + disc)
        # Every outline point as (u, v, span radius): the tip's section, the root's, the two stickers on the tip face.
        n = len(self._section)
        self._uvr = np.concatenate([
            np.column_stack([self._section, np.full(n, rig.tip_radius_m)]),
            np.column_stack([self._section, np.full(n, rig.root_radius_m)]),
            *(np.column_stack([d, np.full(len(d), rig.tip_radius_m)]) for d in self._stickers)])
        self._colours = [(colour_rgb(WHITE_STICKER), colour_rgb(WHITE_STICKER)) if white_stickers
                         else (colour_rgb(a), colour_rgb(b)) for a, b in rig.blades]
        self._blade_rgb = colour_rgb(rig.blade_colour)
        # How far (px) a blade's outline can reach beyond its section centres' projections: the
        # chord's and thickness's largest half-extent at the nearest depth, widened.
        self._reach_px = 0.8 * rig.chord_m * rig.focal_length_px / (rig.camera_distance_m - rig.tip_radius_m) + 4.0

    @staticmethod
    def _draw(image: np.ndarray, xy: np.ndarray, colour: np.ndarray, offset: tuple[int, int] = (0, 0)) -> None:
        """Composite polygon ``xy`` (px) in ``colour`` into ``image`` (float32, its (0, 0) at picture px ``offset``)."""
        h, w = image.shape[:2]
        acc, x0, y0, sign = accumulated(xy - np.asarray(offset, dtype=np.float64), w, h)
        if acc.shape[0] > 0 and acc.shape[1] > 1:
            composite(image, acc, x0, y0, colour, sign)

    def sub_times_s(self, time_s: np.ndarray | float) -> np.ndarray:
        """The sub-exposure instants of frames at ``time_s``: shape (…, m), each a sub-interval's middle."""
        m = self.blur_samples
        t = np.asarray(time_s, dtype=np.float64)
        return t[..., None] + self.exposure_s * ((np.arange(m) + 0.5) / m - 0.5)

    def _outline_points(self, azimuth_rad: np.ndarray, pitch_rad: np.ndarray) -> np.ndarray:
        """Every outline point of one blade at instants of azimuth ψ and pitch θ (each shape (m,)), picture px,
        shape (m, P, 2): the tip's section, the root's, the lead sticker's disc, the trail's (the slices below)."""
        rig = self.rig
        psi = np.asarray(azimuth_rad, dtype=np.float64)[:, None]
        th = np.asarray(pitch_rad, dtype=np.float64)[:, None]
        u, v, r = self._uvr[:, 0], self._uvr[:, 1], self._uvr[:, 2]
        wx, wy, wz = rig.blade_xyz_m(u, v, r, psi, th)
        depth = rig.camera_distance_m - wx
        f = rig.focal_length_px
        x = 0.5 * (self.width - 1) + f * wy / depth
        y = 0.5 * (self.height - 1) - f * wz / depth
        return np.stack([x, y], axis=-1)

    def blade_polygons(self, azimuth_rad: float, pitch_rad: float, blade: int,
                       points: np.ndarray | None = None) -> list[tuple[np.ndarray, np.ndarray]]:
        """One blade's (outline px, colour) at one instant, in painting order: its span's silhouette, then its
        stickers while the tip face looks at the camera; empty when it is out of the picture. ``points``: the
        instant's :meth:`_outline_points`, when already computed."""
        rig, w, h = self.rig, self.width, self.height
        pts = self._outline_points(np.array([azimuth_rad]), np.array([pitch_rad]))[0] if points is None else points
        n = len(self._section)
        both = pts[:2 * n]
        lo, hi = both.min(axis=0), both.max(axis=0)
        if hi[0] < -0.5 or lo[0] > w - 0.5 or hi[1] < -0.5 or lo[1] > h - 0.5:
            return []
        hull = cv2.convexHull(both.astype(np.float32), returnPoints=False).ravel()
        out = [(both[hull], self._blade_rgb)]
        if rig.camera_distance_m * math.cos(azimuth_rad) > rig.tip_radius_m:  # the tip face looks at the camera
            k = _STICKER_VERTICES
            out += [(pts[2 * n:2 * n + k], self._colours[blade][0]), (pts[2 * n + k:], self._colours[blade][1])]
        return out

    def composite(self, time_s: float, pitch_rad_at: Callable[[np.ndarray], np.ndarray] | np.ndarray,
                  led_level: float = 1.0) -> np.ndarray:
        """The noise-free frame exposed around ``time_s`` (float32 DN, (height, width, 3), a new array).

        ``pitch_rad_at(t)`` gives the collective at sub-exposure instants ``t`` (shape (m,)); an array is taken as
        the collective at :meth:`sub_times_s` already. ``led_level``: the LED's lit share of the exposure.
        """
        sub = self.sub_times_s(float(time_s))
        collective = (np.asarray(pitch_rad_at, dtype=np.float64).reshape(sub.shape) if not callable(pitch_rad_at)
                      else np.asarray(pitch_rad_at(sub), dtype=np.float64))
        return self._composite(sub, collective, led_level)

    def _composite(self, sub: np.ndarray, collective: np.ndarray, led_level: float) -> np.ndarray:
        # The frame is the mean of the sub-exposure pictures. Coverage is linear, so each layer (a blade's
        # silhouette, then its stickers, which lie inside it) is drawn once with its coverage averaged over the
        # instants: exact where layers do not cross partly covered pixels at once, which only the far and near
        # blades' dark silhouettes do (same colour; the mean of a product of coverages there, for the product
        # of their means: a few edge pixels of the blade bodies, never a sticker).
        rig = self.rig
        frame = self._bg.copy()
        m = sub.size
        psi = np.stack([rig.azimuth_rad(sub, b) for b in range(rig.n_blades)], axis=1)  # (m, N)
        near = self._near_picture(psi)
        layers = []  # (depth, [m lists of (outline, colour)]) per blade in the picture
        for b in np.flatnonzero(near.any(axis=0)):
            js = np.flatnonzero(near[:, b])
            pitch = rig.blade_pitch_rad(collective[js], sub[js], int(b))
            pts = self._outline_points(psi[js, b], pitch)
            polys = [self.blade_polygons(float(psi[j, b]), float(pitch[q]), int(b), pts[q]) for q, j in enumerate(js)]
            if any(polys):
                mid_x = 0.5 * (rig.tip_radius_m + rig.root_radius_m) * float(np.cos(psi[:, b]).mean())
                depth = rig.camera_distance_m - mid_x
                layers.append((depth, polys))
        layers.sort(key=lambda e: -e[0])
        for _, polys in layers:
            for k in range(max(len(p) for p in polys)):  # silhouette, lead, trail
                self._draw_mean(frame, [p[k][0] for p in polys if len(p) > k], polys[0][k][1] if len(polys[0]) > k
                                else next(p[k][1] for p in polys if len(p) > k), m)
        self._draw(frame, self._led_disc, self._led_off + float(led_level) * (self._led_on - self._led_off))
        return frame

    def _draw_mean(self, frame: np.ndarray, outlines: list[np.ndarray], colour: np.ndarray, m: int) -> None:
        """Composite ``colour`` with the coverage of ``outlines`` (px) summed and divided by ``m`` (their mean over
        the exposure's m instants; an instant that does not show the part adds none)."""
        w, h = self.width, self.height
        parts = [accumulated(xy, w, h) for xy in outlines]
        parts = [p for p in parts if p[0].shape[0] > 0 and p[0].shape[1] > 1]
        if not parts:
            return
        x0 = min(p[1] for p in parts)
        y0 = min(p[2] for p in parts)
        x1 = max(p[1] + p[0].shape[1] - 1 for p in parts)
        y1 = max(p[2] + p[0].shape[0] for p in parts)
        total = np.zeros((y1 - y0, x1 - x0 + 1))
        for acc, ax, ay, sign in parts:
            total[ay - y0:ay - y0 + acc.shape[0], ax - x0:ax - x0 + acc.shape[1]] += acc * (sign / m)
        composite(frame, total, x0, y0, colour, 1.0)

    def _near_picture(self, azimuth_rad: np.ndarray) -> np.ndarray:
        """Whether any of a blade at these azimuths may reach into the picture (a cheap test on its span's line)."""
        rig = self.rig
        c, s = np.cos(azimuth_rad), np.sin(azimuth_rad)
        half = 0.5 * (self.width - 1) + self._reach_px
        xs = [rig.focal_length_px * r * s / (rig.camera_distance_m - r * c) for r in (rig.root_radius_m,
                                                                                       rig.tip_radius_m)]
        return ~((np.minimum(*xs) > half) | (np.maximum(*xs) < -half))

    def render(self, time_s: float, pitch_rad_at, led_level: float = 1.0, frame_index: int = 0) -> np.ndarray:
        """One recorded colour frame: :meth:`composite`, the seeded sensor noise, uint8 (height, width, 3)."""
        return self._frames.add_noise(self.composite(time_s, pitch_rad_at, led_level), frame_index)

    def gray(self, clean: np.ndarray, frame_index: int, bit_depth: int, light_level: float = 1.0) -> np.ndarray:
        """A monochrome camera's frame of ``clean``: BT.601 luma at ``bit_depth`` bits, its noise, as the static
        twin's (:func:`~servoscope.simulate.render_parts.gray_frame`: the noise ``noise_sigma_dn`` of 8-bit DN
        scaled to the depth, seeded per frame)."""
        return gray_frame(clean, bit_depth, light_level, self.noise_sigma_dn, (self.noise_seed, 0x6A7, int(frame_index)))


def pass_frames(renderer: RotorRenderer, passes: list[dict], n_frames: int, fps: Fraction,
                collective_rad_at: Callable[[np.ndarray], np.ndarray]) -> list[dict]:
    """Each pass with ``first_frame`` and ``last_frame``: the frames whose exposure shows any part of that blade's
    stickers (their outlines' extent over the exposure's instants meets the picture); passes never in the video
    left out."""
    rig, w, h = renderer.rig, renderer.width, renderer.height
    fps = Fraction(fps)
    period = 1.0 / rig.rev_per_s
    out = []
    for p in passes:
        # Frames within a quarter revolution of the pass: far more than a picture's width of azimuth.
        k_lo = max(int(math.floor((p["time_s"] - 0.25 * period) * fps)), 0)
        k_hi = min(int(math.ceil((p["time_s"] + 0.25 * period) * fps)), n_frames - 1)
        if k_hi < k_lo:
            continue
        t = rotor_frame_times_s(k_hi + 1, fps)[k_lo:]
        sub = renderer.sub_times_s(t)
        psi = rig.azimuth_rad(sub, p["blade"])
        collective = np.asarray(collective_rad_at(sub.ravel()), dtype=np.float64).reshape(sub.shape)
        pitch = rig.blade_pitch_rad(collective, sub, p["blade"])
        pts = np.concatenate([rig.project_px(rig.world_points(uv, rig.tip_radius_m, psi.ravel(), pitch.ravel()), w, h)
                              for uv in renderer._stickers], axis=1).reshape(len(t), -1, 2)
        facing = (rig.camera_distance_m * np.cos(psi) > rig.tip_radius_m).all(axis=1)
        seen = ((pts[..., 0].max(axis=1) >= -0.5) & (pts[..., 0].min(axis=1) <= w - 0.5)
                & (pts[..., 1].max(axis=1) >= -0.5) & (pts[..., 1].min(axis=1) <= h - 0.5) & facing)
        frames = np.flatnonzero(seen) + k_lo
        if frames.size:
            out.append({**p, "first_frame": int(frames[0]), "last_frame": int(frames[-1])})
    return out


def render_rotor_clip(path: str | Path, rig: RotorRig, collective_rad_at: Callable[[np.ndarray], np.ndarray],
                      duration_s: float, *, fps: float | Fraction = 4000, exposure_s: float = 1.0 / 40000,
                      width: int = 320, height: int = 240, led_off_s: float | None = None, codec: str = "h264",
                      bit_rate: int = 40_000_000, x264_preset: str = "ultrafast", monochrome: bool = False,
                      bit_depth: int = 12, light_level: float = 1.0, noise_sigma_dn: float = 1.5,
                      noise_seed: int = 0, background_seed: int = 0, led_xy_px: tuple[float, float] | None = None,
                      blur_step_px: float = 1.0) -> dict:
    """Render and write one clip of the turning rotor; return its truth.

    Parameters
    ----------
    path : path-like
        A colour video file (``.mp4`` for H.264, as :class:`~servoscope.video.writer.VideoWriter`), or, for
        ``monochrome``, a folder that gets a Photron MRAW (``frames.mraw`` and ``frames.cih``).
    rig : RotorRig
    collective_rad_at : callable
        The collective pitch (rad) at an array of times (s), e.g. ``lambda t: servo.response(signal, t)``.
    duration_s : float
        Frames at ``k / fps < duration_s``.
    fps, exposure_s : float
        Frame rate and shutter time.
    width, height : int
    led_off_s : float or None
        When the airframe's LED goes dark (the input's start); None: lit throughout.
    codec, bit_rate, x264_preset : str, int, str
        The colour video's (:class:`~servoscope.video.writer.VideoWriter`).
    monochrome, bit_depth, light_level : bool, int, float
        A monochrome camera's MRAW of ``bit_depth`` (8, 12 or 16) bits (white stickers on every blade); its
        exposure against the scene's.
    noise_sigma_dn, noise_seed, background_seed : float, int, int
    led_xy_px : (float, float) or None
        See :class:`RotorRenderer`.
    blur_step_px : float
        Most tip travel between two sub-exposure pictures (px).

    Returns
    -------
    dict
        ``time_s`` (frame times), ``fps``, ``exposure_s``, ``t0_s`` (the LED's switch, or None), ``led_level``,
        ``rev_per_s`` (the mean over the clip), ``blur_samples``, and ``passes``: per pass ``blade``, ``time_s``
        (ψ = 0), ``pitch_rad`` (collective + cyclic + offset then), ``first_frame``, ``last_frame``. Blade b's
        azimuth at any time is ``rig.azimuth_rad(t, b)``.
    """
    fps = Fraction(fps).limit_denominator(1_000_000)
    n = int(math.ceil(duration_s * fps))
    if n < 1:
        raise ServoscopeError(f"render_rotor_clip: duration_s {duration_s!r} gives no frame")
    if exposure_s * fps > 1 + 1e-12:
        raise ServoscopeError(f"render_rotor_clip: exposure_s ({exposure_s:g} s) exceeds the frame interval "
                              f"({float(1 / fps):g} s)")
    time_s = rotor_frame_times_s(n, fps)
    renderer = RotorRenderer(rig, width, height, exposure_s=exposure_s, noise_sigma_dn=noise_sigma_dn,
                             noise_seed=noise_seed, background_seed=background_seed, led_xy_px=led_xy_px,
                             blur_step_px=blur_step_px, white_stickers=monochrome)
    led = (np.ones(n) if led_off_s is None else led_exposure_fraction(time_s, led_off_s, exposure_s))
    sub = renderer.sub_times_s(time_s)
    collective = np.asarray(collective_rad_at(sub.ravel()), dtype=np.float64).reshape(sub.shape)
    if monochrome:
        writer_cm = MrawWriter(path, width, height, fps, bit_depth)
    else:
        writer_cm = VideoWriter(path, width, height, fps, codec=codec, bit_rate=bit_rate, preset=x264_preset)
    with writer_cm as writer:
        for k in range(n):
            clean = renderer._composite(sub[k], collective[k], float(led[k]))
            if monochrome:
                writer.write_gray(renderer.gray(clean, k, bit_depth, light_level), bit_depth)
            else:
                writer.write(renderer._frames.add_noise(clean, k))
    passes = pass_frames(renderer, rotor_passes(rig, collective_rad_at, -0.5 / rig.rev_per_s,
                                                float(time_s[-1]) + 0.5 / rig.rev_per_s), n, fps, collective_rad_at)
    return {
        "time_s": time_s.tolist(), "fps": float(fps), "exposure_s": float(exposure_s),
        "t0_s": None if led_off_s is None else float(led_off_s), "led_level": led.tolist(),
        "rev_per_s": rig.mean_rev_per_s(0.0, float(n / fps)), "blur_samples": renderer.blur_samples,
        "passes": passes,
    }
