"""Short test clips with a known answer, for tracking accuracy checks.

Unlike :func:`~servoscope.simulate.simulate_campaign` (a whole campaign),
:func:`render_clip` renders one short video of a given pitch trajectory, with
optional extras that real footage has: an occluder that slides over a
sticker (a hand, a cable), and a duplicated frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path

import numpy as np

from ..camera.model import CameraModel
from ..errors import ServoscopeError
from ..video.writer import VideoWriter
from .render import FrameRenderer, polygon_coverage
from .scene import Scene, colour_rgb, marker_angle_rad

__all__ = ["Occluder", "render_clip"]


@dataclass(frozen=True)
class Occluder:
    """A rectangle that slides horizontally across the image.

    Attributes
    ----------
    colour : str
        "#rrggbb" or a CSS name.
    y_range_px : (float, float)
        Top and bottom edges (px).
    width_px : float
        Width of the rectangle (px).
    x_start_px, x_end_px : float
        Left edge at the first and the last frame (px), moving linearly.
    """

    colour: str
    y_range_px: tuple[float, float]
    width_px: float
    x_start_px: float
    x_end_px: float

    def outline(self, fraction: float) -> np.ndarray:
        """Corners at ``fraction`` (0–1) of the clip (px, shape (4, 2))."""
        x0 = self.x_start_px + fraction * (self.x_end_px - self.x_start_px)
        y0, y1 = self.y_range_px
        return np.array([[x0, y0], [x0 + self.width_px, y0], [x0 + self.width_px, y1], [x0, y1]], dtype=np.float64)


def render_clip(path: str | Path, scene: Scene, pitch_rad: np.ndarray, *, fps: float | Fraction = 100,
                led_level: np.ndarray | None = None, camera: CameraModel | None = None, codec: str = "h264",
                bit_rate: int = 20_000_000, noise_sigma_dn: float = 1.5, noise_seed: int = 0,
                occluder: Occluder | None = None, duplicate_frames: tuple[int, ...] = (),
                preset: str = "ultrafast", gop: int | None = None, lamp_gain: np.ndarray | None = None,
                shake_xy_px: np.ndarray | None = None) -> dict:
    """Render and encode one clip; return its truth.

    Parameters
    ----------
    path : path-like
        Output video (.mp4 for h264, .avi / .nut for raw).
    scene : Scene
    pitch_rad : ndarray, shape (n,)
        Blade pitch per frame (rad).
    fps : float or Fraction
        Frame rate (Hz).
    led_level : ndarray, shape (n,), optional
        LED level per frame in [0, 1]; default lit throughout.
    camera : CameraModel, optional
        Lens distortion; None = ideal camera.
    codec, bit_rate : str, int
        As :class:`~servoscope.video.writer.VideoWriter`.
    noise_sigma_dn : float
        Sensor noise (DN).
    noise_seed : int
    occluder : Occluder, optional
        Drawn over everything.
    duplicate_frames : tuple of int
        Frames whose image is replaced by the previous frame's (their truth
        stays that of the previous image).
    preset, gop : str, int or None
        x264 speed preset and GOP length, as
        :class:`~servoscope.video.writer.VideoWriter`.
    lamp_gain : ndarray, shape (n,), optional
        The lamps' light per frame (flicker, e.g. from
        :func:`~servoscope.simulate.scene.lamp_gain`): scales everything but
        the lit LED; None: steady.
    shake_xy_px : ndarray, shape (n, 2), optional
        Translation of the whole picture per frame (camera shake), pixels;
        the truth's sticker centres stay the blade's.

    Returns
    -------
    dict with ``time_s``, ``angle_rad``, ``lead_xy_px``, ``trail_xy_px``
    (ideal pixels), ``lead_hidden``, ``trail_hidden`` (fraction of each
    sticker's area under the occluder, per frame), ``shake_xy_px``, all
    ndarrays.
    """
    pitch = np.asarray(pitch_rad, dtype=np.float64)
    n = pitch.size
    fps = Fraction(fps).limit_denominator(1_000_000)
    time_s = (np.arange(n, dtype=np.float64) * fps.denominator) / fps.numerator
    led = np.ones(n) if led_level is None else np.asarray(led_level, dtype=np.float64)
    gain = np.ones(n) if lamp_gain is None else np.asarray(lamp_gain, dtype=np.float64)
    shake = np.zeros((n, 2)) if shake_xy_px is None else np.asarray(shake_xy_px, dtype=np.float64)
    if gain.shape != (n,) or shake.shape != (n, 2):
        raise ServoscopeError(f"render_clip: lamp_gain needs shape ({n},) and shake_xy_px ({n}, 2)")
    renderer = FrameRenderer(scene, camera, noise_sigma_dn=noise_sigma_dn, noise_seed=noise_seed)
    lead, trail = scene.sticker_centres_px(pitch)
    hidden = {"lead": np.zeros(n), "trail": np.zeros(n)}
    occ_rgb = colour_rgb(occluder.colour) if occluder is not None else None
    prev = None
    with VideoWriter(path, scene.width, scene.height, fps, codec=codec, bit_rate=bit_rate, preset=preset,
                     gop=gop) as writer:
        for i in range(n):
            if i in duplicate_frames and prev is not None:
                writer.write(prev)
                lead[i], trail[i], pitch[i] = lead[i - 1], trail[i - 1], pitch[i - 1]
                continue
            frame = renderer.render(float(pitch[i]), float(led[i]), i, float(gain[i]), tuple(shake[i]))
            if occluder is not None:
                poly = occluder.outline(i / max(n - 1, 1))
                cov, x0, y0 = polygon_coverage(poly, (scene.width, scene.height))
                if cov.size:
                    region = frame[y0:y0 + cov.shape[0], x0:x0 + cov.shape[1]].astype(np.float64)
                    region += cov[..., None] * (occ_rgb - region)
                    frame[y0:y0 + cov.shape[0], x0:x0 + cov.shape[1]] = np.clip(np.round(region), 0, 255).astype(np.uint8)
                for name, centre in (("lead", lead[i]), ("trail", trail[i])):
                    hidden[name][i] = _overlap_fraction(scene, renderer, centre, float(pitch[i]), poly)
            writer.write(frame)
            prev = frame
    return {
        "time_s": time_s,
        "angle_rad": marker_angle_rad(lead, trail),
        "lead_xy_px": lead,
        "trail_xy_px": trail,
        "lead_hidden": hidden["lead"],
        "trail_hidden": hidden["trail"],
        "shake_xy_px": shake,
    }


def _overlap_fraction(scene: Scene, renderer: FrameRenderer, centre: np.ndarray, pitch_rad: float,
                      rect: np.ndarray) -> float:
    """Fraction of a sticker (its shape, turned by the pitch; ideal pixels) under an axis-aligned rectangle."""
    if scene.sticker_shape == "disc" and scene.sticker_aspect in (None, 1.0):
        outline = scene.disk_outline(centre, scene.sticker_diameter_px)
    else:
        # The sticker's outline about its centre, turned with the blade.
        outline = scene.to_image(scene.sticker_outline_uv(), pitch_rad) - np.asarray(scene.pivot_xy_px) + centre
    if renderer.camera is not None:
        outline = renderer.camera.distort_points(outline)
    cov, x0, y0 = polygon_coverage(outline)
    ys, xs = np.mgrid[y0:y0 + cov.shape[0], x0:x0 + cov.shape[1]]
    inside = (xs >= rect[0, 0]) & (xs <= rect[1, 0]) & (ys >= rect[0, 1]) & (ys <= rect[2, 1])
    return float((cov * inside).sum() / max(cov.sum(), 1e-12))
