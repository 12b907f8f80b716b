"""What the camera sees: a rotor blade's airfoil section, two stickers, an LED.

Coordinates are *ideal* (undistorted) pixel coordinates: x right, y down,
pixel centres on integers; for a camera that looks at the blade obliquely they
are *plane px*, the pixels of a square-on camera at the same distance, which the
view's homography (:mod:`servoscope.simulate.view`) maps to the ideal image. The blade is described in its own frame
``(u, v)``: ``u`` along the chord towards the leading edge, ``v``
perpendicular to it, pointing up in the image at zero pitch; the origin is
the pivot (pitch axis). Blade pitch ``p`` rotates the blade about the pivot
by ``p`` counter-clockwise *as seen in the image*, so that servoscope's angle
convention ``θ = atan2(y_trail - y_lead, x_lead - x_trail)`` gives
``θ = p + sticker_offset_rad``.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, fields, replace

import matplotlib.colors
import numpy as np

from ..defaults import LEAD_COLOUR, LED_COLOUR, TRAIL_COLOUR
from ..errors import ServoscopeError
from .view import densify_closed

__all__ = [
    "Clutter",
    "Scene",
    "STICKER_SHAPES",
    "lamp_gain",
    "colour_rgb",
    "led_exposure_fraction",
    "marker_angle_rad",
    "REFERENCE_SIZE",
]

#: Image size, (width, height), for which Scene's default lengths are given.
REFERENCE_SIZE = (720, 576)

# Length-valued fields, scaled by Scene.for_size.
_LENGTH_FIELDS = ("chord_px", "sticker_separation_px", "sticker_diameter_px", "led_diameter_px")


def colour_rgb(colour: str) -> np.ndarray:
    """A colour ("#rrggbb" or any matplotlib/CSS name) as float RGB in 0..255.

    Raises
    ------
    ServoscopeError
        If the colour is not recognised.
    """
    try:
        return np.asarray(matplotlib.colors.to_rgb(colour), dtype=np.float64) * 255.0
    except (ValueError, TypeError):
        raise ServoscopeError(f"not a colour: {colour!r} (use '#rrggbb' or a CSS colour name)") from None


def marker_angle_rad(lead_xy_px: np.ndarray, trail_xy_px: np.ndarray) -> np.ndarray:
    """servoscope's angle of the line joining the stickers.

    ``θ = atan2(y_trail - y_lead, x_lead - x_trail)``: counter-clockwise
    positive as seen in an image whose y axis points down.
    """
    lead = np.asarray(lead_xy_px, dtype=float)
    trail = np.asarray(trail_xy_px, dtype=float)
    return np.arctan2(trail[..., 1] - lead[..., 1], lead[..., 0] - trail[..., 0])


def led_exposure_fraction(time_s: np.ndarray | float, switch_off_s: float, exposure_s: float) -> np.ndarray:
    """Fraction of each exposure during which an LED that goes off at ``switch_off_s`` was lit.

    The frame at ``time_s`` integrates light over ``[t - e/2, t + e/2]``; the
    LED is lit before ``switch_off_s`` and dark after it.

    Parameters
    ----------
    time_s : array_like
        Frame times (centre of exposure), seconds.
    switch_off_s : float
        When the LED switches off, seconds.
    exposure_s : float
        Exposure time e, seconds (0 = instantaneous).
    """
    t = np.asarray(time_s, dtype=float)
    if exposure_s <= 0:
        return np.where(t < switch_off_s, 1.0, 0.0)
    return np.clip((switch_off_s - (t - 0.5 * exposure_s)) / exposure_s, 0.0, 1.0)


def lamp_gain(time_s: np.ndarray | float, exposure_s: float, flicker_hz: float, flicker_depth: float,
              phase_rad: float = 0.0) -> np.ndarray:
    """Mean gain of flickering lamps over each exposure.

    The lamps' light is ``1 + depth·sin(2π f t + φ)``; a frame exposed over
    ``[t - e/2, t + e/2]`` collects its mean, ``1 + depth·sin(2π f t + φ)·sinc(f e)``
    (``sinc(x) = sin(πx)/(πx)``): a shutter of whole flicker periods sees none.

    Parameters
    ----------
    time_s : array_like
        Exposure centres, seconds.
    exposure_s : float
        Exposure time e, seconds (0 = instantaneous).
    flicker_hz : float
        Flicker frequency f, Hz (mains lamps: twice the mains frequency).
    flicker_depth : float
        Modulation depth, in [0, 1).
    phase_rad : float
        Phase φ of the lamps at t = 0 (the mains is not synchronised with the camera).
    """
    t = np.asarray(time_s, dtype=float)
    return 1.0 + flicker_depth * np.sin(2.0 * np.pi * flicker_hz * t + phase_rad) * np.sinc(flicker_hz * exposure_s)


#: Sticker shapes :class:`Scene` draws.
STICKER_SHAPES = ("disc", "square", "strip")

# A strip's default length / width.
_STRIP_ASPECT = 4.0

_CLUTTER_SHAPES = ("box", "disc")


@dataclass(frozen=True)
class Clutter:
    """A static object in the scene behind the blade (a box, a cable drum, a tool).

    Drawn with exact area coverage into the background, in recorded-image
    pixel coordinates (where it is in the video), lit by the lamps.

    Parameters
    ----------
    colour : str
        "#rrggbb" or a CSS colour name.
    centre_px : (float, float)
        Centre, recorded-image pixels (x right, y down).
    size_px : (float, float)
        Width and height before rotation (a disc's two diameters), pixels.
    angle_rad : float
        Rotation, counter-clockwise as seen in the image.
    shape : {"box", "disc"}
        A rectangle or an ellipse.
    airframe : bool
        Fixed to the airframe (a reference sticker): it rocks with the blade's
        pivot (``rock_rad``), where the rest of the scene stays.
    """

    colour: str
    centre_px: tuple[float, float]
    size_px: tuple[float, float]
    angle_rad: float = 0.0
    shape: str = "box"
    airframe: bool = False

    def __post_init__(self) -> None:
        colour_rgb(self.colour)  # validates
        if self.shape not in _CLUTTER_SHAPES:
            raise ServoscopeError(f"clutter: shape must be one of {', '.join(_CLUTTER_SHAPES)}, not {self.shape!r}")
        cx, cy = (float(v) for v in self.centre_px)
        w, h = (float(v) for v in self.size_px)
        if not (math.isfinite(cx) and math.isfinite(cy) and math.isfinite(self.angle_rad)):
            raise ServoscopeError("clutter: centre_px and angle_rad must be finite")
        if not (w > 0 and h > 0 and math.isfinite(w) and math.isfinite(h)):
            raise ServoscopeError(f"clutter: size_px must be positive, not {self.size_px!r}")
        object.__setattr__(self, "centre_px", (cx, cy))
        object.__setattr__(self, "size_px", (w, h))
        object.__setattr__(self, "angle_rad", float(self.angle_rad))

    def outline_px(self) -> np.ndarray:
        """Outline, recorded-image pixels, shape (n, 2): its area centroid is ``centre_px``."""
        w, h = self.size_px
        if self.shape == "box":
            local = 0.5 * np.array([[-w, -h], [w, -h], [w, h], [-w, h]])
        else:
            ang = 2.0 * np.pi * np.arange(256) / 256
            local = 0.5 * np.stack([w * np.cos(ang), h * np.sin(ang)], axis=1)
        c, s = math.cos(self.angle_rad), math.sin(self.angle_rad)
        # Counter-clockwise on screen, where y points down.
        x = local[:, 0] * c + local[:, 1] * s
        y = -local[:, 0] * s + local[:, 1] * c
        return np.stack([x + self.centre_px[0], y + self.centre_px[1]], axis=1)


@dataclass(frozen=True)
class Scene:
    """The blade as the camera sees it (defaults: the paper's 720×576 view).

    Parameters
    ----------
    width, height : int
        Image size, pixels.
    pivot_xy_px : (float, float)
        Pitch axis in ideal pixel coordinates.
    chord_px : float
        Chord length, pixels.
    thickness_ratio : float
        Airfoil thickness / chord (a symmetric NACA 4-digit section).
    pivot_chord_fraction : float
        Distance from the leading edge to the pivot, in chords (rotor blades
        pitch about the quarter chord).
    blade_colour : str
        Colour of the airfoil section.
    sticker_separation_px : float
        Distance between the sticker centres; the pair is centred on the
        chord's midpoint.
    sticker_diameter_px : float
        Sticker diameter (circumscribed diameter of the polygon).
    sticker_offset_rad : float
        Angle between the sticker line and the chord (misplaced stickers);
        positive when the lead sticker sits higher than the trail sticker.
    sticker_vertices : int
        Vertices of each sticker's regular polygon (>= 128).
    lead_colour, trail_colour : str
        Sticker colours near the leading (right) and trailing (left) edges.
    led_colour, led_off_colour : str
        LED colour when lit and when dark.
    led_diameter_px : float
        LED diameter.
    led_chord_fraction : float
        LED position along the chord, measured from the leading edge.
    led_offset_px : float
        LED offset perpendicular to the chord (blade-frame v, up in the image
        at zero pitch): 0 puts it on the chord line; a non-zero offset models
        an LED on a bracket fixed to the blade, on other image rows than the
        stickers (what a rolling shutter makes matter).
    background_top, background_bottom : str
        Colours of the vertical background gradient.
    blotch_amplitude_dn : float
        Amplitude of the low-frequency background blotches, DN.
    blotch_count : int
        Number of blotches.
    background_seed : int
        Seed of the blotch pattern.
    clutter : tuple of Clutter (or dicts of its fields)
        Static objects drawn into the background (not scaled by
        :meth:`for_size`: they are given in the image's own pixels).
    sticker_shape : {"disc", "square", "strip"}
        Disc of diameter ``sticker_diameter_px``; square of that side;
        rectangle of that width across the chord. All turn with the blade.
    sticker_aspect : float or None
        Length along the chord / width across it: a disc becomes an ellipse,
        a square a rectangle. None: 1 for "disc" and "square", 4 for "strip".
    max_segment_px : float
        Longest polygon edge before lens distortion (edges are densified so
        that the distorted outline follows the lens's curves).
    extra_stickers : tuple of (str, float)
        More stickers on the blade (issue 18's ``[markers] extra``), each
        ``(colour, position)``: its centre on the lead and trail stickers' line,
        at ``position`` of the way from the trail sticker (0) to the lead (1);
        the shape and size of the others'. Empty (the default): two stickers.
    led_fixed_px : (float, float) or None
        An LED fixed to the stand, not the blade: its centre in the ideal image
        (px, not scaled by :meth:`for_size`), in a dark housing; None (the
        default): on the blade at ``led_chord_fraction``.
    """

    width: int = 720
    height: int = 576
    pivot_xy_px: tuple[float, float] = (535.37, 287.81)
    chord_px: float = 700.0
    thickness_ratio: float = 0.08
    pivot_chord_fraction: float = 0.25
    blade_colour: str = "#3a3c40"
    sticker_separation_px: float = 600.0
    sticker_diameter_px: float = 26.0
    sticker_offset_rad: float = 0.05
    sticker_vertices: int = 256
    lead_colour: str = LEAD_COLOUR
    trail_colour: str = TRAIL_COLOUR
    led_colour: str = LED_COLOUR
    led_off_colour: str = "#45441c"
    led_diameter_px: float = 14.0
    led_chord_fraction: float = 0.62
    led_offset_px: float = 0.0
    background_top: str = "#8395a8"
    background_bottom: str = "#5a6a7e"
    blotch_amplitude_dn: float = 10.0
    blotch_count: int = 14
    background_seed: int = 0
    max_segment_px: float = 2.0
    clutter: tuple[Clutter, ...] = ()
    sticker_shape: str = "disc"
    sticker_aspect: float | None = None
    extra_stickers: tuple[tuple[str, float], ...] = ()
    led_fixed_px: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.led_fixed_px is not None:
            xy = tuple(float(v) for v in self.led_fixed_px)
            if len(xy) != 2 or not all(math.isfinite(v) for v in xy):
                raise ServoscopeError(f"scene: led_fixed_px must be two finite coordinates, not {self.led_fixed_px!r}")
            object.__setattr__(self, "led_fixed_px", xy)
        extras = tuple((str(c), float(f)) for c, f in self.extra_stickers)
        object.__setattr__(self, "extra_stickers", extras)
        if any(not math.isfinite(f) for _, f in extras):
            raise ServoscopeError("scene: extra_stickers' positions must be finite")
        if self.width < 2 or self.height < 2:
            raise ServoscopeError(f"scene: image size {self.width}x{self.height} is too small")
        if self.sticker_vertices < 128:
            raise ServoscopeError("scene: sticker_vertices must be >= 128")
        for name in _LENGTH_FIELDS:
            if not getattr(self, name) > 0:
                raise ServoscopeError(f"scene: {name} must be > 0")
        if not 0 < self.thickness_ratio < 1:
            raise ServoscopeError("scene: thickness_ratio must be in (0, 1)")
        if not math.isfinite(self.led_offset_px):
            raise ServoscopeError("scene: led_offset_px must be finite")
        if not self.max_segment_px > 0:
            raise ServoscopeError("scene: max_segment_px must be > 0")
        for name in ("blade_colour", "lead_colour", "trail_colour", "led_colour", "led_off_colour",
                     "background_top", "background_bottom"):
            colour_rgb(getattr(self, name))  # validates
        for colour, _ in self.extra_stickers:
            colour_rgb(colour)
        object.__setattr__(self, "pivot_xy_px", (float(self.pivot_xy_px[0]), float(self.pivot_xy_px[1])))
        items = (self.clutter,) if isinstance(self.clutter, (Clutter, dict)) else tuple(self.clutter)
        try:
            clutter = tuple(c if isinstance(c, Clutter) else Clutter(**c) for c in items)
        except TypeError as e:
            raise ServoscopeError(f"scene: clutter items are Clutter or dicts of its fields ({e})") from None
        object.__setattr__(self, "clutter", clutter)
        if self.sticker_shape not in STICKER_SHAPES:
            raise ServoscopeError(
                f"scene: sticker_shape must be one of {', '.join(STICKER_SHAPES)}, not {self.sticker_shape!r}")
        if self.sticker_aspect is not None and not (self.sticker_aspect > 0 and math.isfinite(self.sticker_aspect)):
            raise ServoscopeError(f"scene: sticker_aspect must be > 0, not {self.sticker_aspect!r}")

    @classmethod
    def for_size(cls, width: int, height: int, **overrides) -> "Scene":
        """The default scene scaled to another image size.

        Lengths scale by ``min(width/720, height/576)``; the pivot keeps its
        position relative to the image centre, scaled likewise.

        Parameters
        ----------
        width, height : int
            Image size, pixels.
        **overrides
            Any Scene field, applied after scaling.
        """
        ref = cls()
        s = min(width / REFERENCE_SIZE[0], height / REFERENCE_SIZE[1])
        cx_ref, cy_ref = REFERENCE_SIZE[0] / 2.0, REFERENCE_SIZE[1] / 2.0
        scaled = {name: getattr(ref, name) * s for name in _LENGTH_FIELDS}
        scaled["led_offset_px"] = ref.led_offset_px * s
        scaled["pivot_xy_px"] = (width / 2.0 + (ref.pivot_xy_px[0] - cx_ref) * s,
                                 height / 2.0 + (ref.pivot_xy_px[1] - cy_ref) * s)
        known = {f.name for f in fields(cls)}
        unknown = set(overrides) - known
        if unknown:
            raise ServoscopeError(f"scene: unknown setting(s) {sorted(unknown)}")
        return replace(ref, width=int(width), height=int(height), **{**scaled, **overrides})

    # -- blade-frame geometry ------------------------------------------------
    def _u_from_le(self, fraction: float) -> float:
        """u coordinate of the chord point ``fraction`` chords behind the leading edge."""
        return (self.pivot_chord_fraction - fraction) * self.chord_px

    def blade_outline_uv(self) -> np.ndarray:
        """Airfoil outline in the blade frame, densified, shape (n, 2), counter-clockwise."""
        n = 240
        xi = 0.5 * (1.0 - np.cos(np.linspace(0.0, np.pi, n + 1)))  # cosine spacing
        # NACA 4-digit symmetric thickness; -0.1036 closes the trailing edge.
        half = 5.0 * self.thickness_ratio * self.chord_px * (
            0.2969 * np.sqrt(xi) - 0.1260 * xi - 0.3516 * xi**2 + 0.2843 * xi**3 - 0.1036 * xi**4)
        u = self._u_from_le(0.0) - xi * self.chord_px
        # Upper surface from LE to TE, lower from TE back to LE (without repeating ends).
        upper = np.stack([u, half], axis=1)
        lower = np.stack([u[::-1], -half[::-1]], axis=1)[1:-1]
        outline = np.concatenate([upper, lower], axis=0)
        return densify_closed(outline, self.max_segment_px)

    def sticker_centres_uv(self) -> tuple[np.ndarray, np.ndarray]:
        """Lead and trail sticker centres in the blade frame."""
        mid = np.array([self._u_from_le(0.5), 0.0])
        half = 0.5 * self.sticker_separation_px
        d = np.array([math.cos(self.sticker_offset_rad), math.sin(self.sticker_offset_rad)])
        return mid + half * d, mid - half * d

    def extra_centres_uv(self) -> np.ndarray:
        """The extra stickers' centres in the blade frame, shape (k, 2) (k = ``len(extra_stickers)``)."""
        lead, trail = self.sticker_centres_uv()
        return np.array([trail + f * (lead - trail) for _, f in self.extra_stickers]).reshape(-1, 2)

    def led_centre_uv(self) -> np.ndarray:
        """LED centre in the blade frame."""
        return np.array([self._u_from_le(self.led_chord_fraction), self.led_offset_px])

    def sticker_outline_uv(self) -> np.ndarray:
        """One sticker's outline about its centre, blade frame, shape (n, 2).

        Its area centroid is exactly the origin (a regular polygon, or a
        rectangle densified to ``max_segment_px`` edges so that the lens
        bends it), counter-clockwise in the blade frame.
        """
        r = 0.5 * self.sticker_diameter_px
        aspect = self.sticker_aspect if self.sticker_aspect is not None else (
            _STRIP_ASPECT if self.sticker_shape == "strip" else 1.0)
        if self.sticker_shape == "disc":
            k = self.sticker_vertices
            ang = 2.0 * np.pi * np.arange(k) / k
            unit = np.stack([np.cos(ang), np.sin(ang)], axis=1)
            return r * unit if aspect == 1.0 else r * unit * np.array([aspect, 1.0])
        a, b = r * aspect, r
        rect = np.array([[a, b], [-a, b], [-a, -b], [a, -b]])
        # Densify about the corners symmetrically (every edge cut in equal
        # pieces) so that the centroid stays exactly at the origin.
        return densify_closed(rect, self.max_segment_px)

    def disk_outline(self, centre_xy_px: np.ndarray, diameter_px: float) -> np.ndarray:
        """Regular ``sticker_vertices``-gon (centroid exactly at the centre), ideal pixels, CCW on screen."""
        k = self.sticker_vertices
        ang = 2.0 * np.pi * np.arange(k) / k
        r = 0.5 * diameter_px
        return np.asarray(centre_xy_px, float) + r * np.stack([np.cos(ang), -np.sin(ang)], axis=1)

    # -- image-frame geometry --------------------------------------------------
    def to_image(self, uv: np.ndarray, pitch_rad: np.ndarray | float) -> np.ndarray:
        """Blade-frame points to ideal pixel coordinates at pitch ``pitch_rad``.

        Parameters
        ----------
        uv : ndarray, shape (n, 2) or (2,)
            Blade-frame points.
        pitch_rad : float or ndarray, shape (m,)
            Pitch; an array broadcasts to shape (m, n, 2) (or (m, 2) for one point).
        """
        uv = np.asarray(uv, dtype=float)
        p = np.asarray(pitch_rad, dtype=float)
        u, v = uv[..., 0], uv[..., 1]
        c, s = np.cos(p), np.sin(p)
        if p.ndim == 1 and uv.ndim == 2:
            c, s = c[:, None], s[:, None]
        x = self.pivot_xy_px[0] + u * c - v * s
        y = self.pivot_xy_px[1] - (u * s + v * c)  # v points up, y down
        return np.stack([x, y], axis=-1)

    def sticker_centres_px(self, pitch_rad: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Lead and trail sticker centres (ideal pixels) at the given pitch(es)."""
        lead_uv, trail_uv = self.sticker_centres_uv()
        return self.to_image(lead_uv, pitch_rad), self.to_image(trail_uv, pitch_rad)

    def led_centre_px(self, pitch_rad: float) -> np.ndarray:
        """LED centre (ideal pixels) at the given pitch (an LED on the stand: where it is fixed)."""
        if self.led_fixed_px is not None:
            return np.array(self.led_fixed_px, dtype=np.float64)
        return self.to_image(self.led_centre_uv(), pitch_rad)

    def background(self) -> np.ndarray:
        """The static background, float32 RGB in DN, shape (height, width, 3).

        A vertical gradient between two blue-greys plus seeded low-frequency
        blotches (Gaussian bumps a few tenths of the image wide), so that it
        is plain but not uniform and nowhere near the marker colours.
        """
        h, w = self.height, self.width
        top, bottom = colour_rgb(self.background_top), colour_rgb(self.background_bottom)
        fy = (np.arange(h) / max(h - 1, 1))[:, None, None]
        img = np.broadcast_to(top + fy * (bottom - top), (h, w, 3)).astype(np.float64)
        rng = np.random.default_rng(self.background_seed)
        yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
        scale = float(min(w, h))
        field = np.zeros((h, w))
        for _ in range(self.blotch_count):
            cx, cy = rng.uniform(0, w), rng.uniform(0, h)
            sigma = rng.uniform(0.08, 0.3) * scale
            amp = rng.uniform(-1.0, 1.0) * self.blotch_amplitude_dn
            field += amp * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * sigma**2))
        # A slight blue/red tilt of the blotches keeps the hue blue-grey.
        tint = np.array([0.9, 1.0, 1.15])
        img += field[:, :, None] * tint
        return np.clip(img, 0.0, 255.0).astype(np.float32)
