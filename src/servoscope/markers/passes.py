"""A turning rotor's blades frame by frame: which blade's stickers are in the picture, their centroids, the passes.

A camera in the rotor's plane sees each blade's tip cross the picture once a revolution,
in a burst of frames; between passes the picture shows no blade. Each blade carries its
own pair of colours (lead, trail), so a frame's blade is told by its colours.

Per frame (:func:`scan_rotor_video`, on the decoder's YUV planes):

1. **a cheap test first**: every colour's class (the YUV kernels' chroma
   classification, :func:`~servoscope.markers.kernels.classify_np`) counted on the chroma
   planes subsampled 2×2 (one sample per 4×4 luma pixels). A frame where no colour has
   :data:`MIN_COARSE` samples is empty: it costs that count and the LED's disk, nothing
   more;
2. for each colour seen: its class on the full chroma planes in a window around the
   coarse samples, the largest blob's bounding box, and the fused kernel
   (:func:`~servoscope.markers.kernels.track_frame_numba`) over a support that follows
   that box (the motion blur smears a sticker along the picture's rows), unmixing each
   pixel between the sticker's colour and its own background: the sub-pixel centroid
   ``servoscope track`` measures. A sticker is *whole* when its support and background
   ring lie inside the picture; a sticker cut by the picture's edge is seen (the blade is
   there) but not measured. The vertical coordinate is then taken again from luma alone
   (:func:`~servoscope.markers.pass_centroid.luma_row_centroid`): the kernel's leans on 4:2:0
   chroma and is biased with the sticker's sub-pixel row, a bias frozen through a pass.

Each sticker's colour (its YUV, hue cone, noise) is learned the first time it is whole,
as the static engines learn it from their first frame; before that the given colour seeds
the classification. The LED, fixed on the airframe, is found in the first frame with no
blade (the largest blob of its colour, or the one at ``led_near``) and its level read in
a fixed disk every frame (NaN where a blade's sticker covers it).

:func:`segment_passes` cuts each blade's seen frames into passes: a pass begins when a
blade's stickers enter the picture and ends when they leave.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import cv2
import numpy as np

from ..errors import ServoscopeError
from ..video.reader import iter_yuv_frames
from . import kernels as K
from .colour import BRIGHTNESS, ColourModel, parse_colour, ycbcr_bt601
from .led_level import LED_PEAK_FRAMES, disk_level
from .pass_centroid import MIN_LUMA_CONTRAST_DN, luma_row_centroid
from .yuv_engine import learn_colour_model

__all__ = ["LUMA_ROWS", "MIN_COARSE", "PassFrames", "RotorSightings", "blade_colours", "scan_rotor_video", "segment_passes"]

#: Coarse-grid samples (one per 4×4 luma pixels) of a colour for a frame to be looked at closely.
MIN_COARSE = 2
#: Luma px around the coarse samples' box in which the full-resolution class is taken.
COARSE_GROW_PX = 8
#: Hue half-width of a seed colour's cone before its sticker is learned (rad).
SEED_TOLERANCE_RAD = math.radians(20.0)
#: Support beyond a sticker's extent (px): its edge blur and the codec's chroma smear. Small: a tip
#: sticker sits close to the section's edge, and a support or ring that reaches past it takes in sky
#: the ring's bins mix with the blade (on the twin's raw footage, per-frame angle SD 0.069° with
#: 2 px and a 4 px ring, 0.024° with 1 px and 1 px).
SUPPORT_MARGIN_PX = 1.0
#: Background ring width (px).
RING_PX = 1.0
#: Measure twice, the second time over a support sized by the first's soft moments.
SUPPORT_FROM_MOMENTS = True
#: Luma's weight in the unmixing (the YUV kernels' ``W_Y``). Higher than the static engine's 1: in a
#: pass the stickers move along the rows only, so each sticker's *vertical* sub-pixel phase, and the
#: bias it gives the centroid, is the same in every frame of the pass and does not average out; the
#: full-resolution luma halves it against the 2-px chroma. Measured on the twin (2 blades, 320×240,
#: 4000–5000 frames/s, per-pass pitch RMS): W_Y 1 / 4 / 8 / 16: raw 0.021 / 0.018 / 0.020 / 0.025°,
#: H.264 0.040 / 0.028 / 0.025° (3 blades 0.045 / 0.030 / 0.018°), a second H.264 clip at 25 rev/s
#: 0.024 / 0.018 / 0.015°.
W_Y = 8.0
#: Each whole sticker's vertical coordinate from full-resolution luma (:mod:`.pass_centroid`), not the kernel's:
#: the kernel's has a ±0.03 px saw-tooth with the row's sub-pixel phase (4:2:0 chroma's tail cut by the 1-px
#: support), which read as a pitch scale of 0.983-1.017; from luma ≤ 0.003 px (4 mm stickers, per-pass pitch
#: against truth: slopes 0.998-1.002 raw, 1.002-1.006 H.264 at 40 Mbit/s; docs/rotor.md).
LUMA_ROWS = True
#: Whole frames of a sticker before its heights' source is judged (a warning when luma read under half of them).
KERNEL_ROWS_MIN_FRAMES = 5
#: Empty frames the LED is looked for in before the video is taken to have none.
LED_TRIES = 20
#: A pass's seen frames may miss this many frames in a row (a sticker hidden by noise) and stay one pass.
MAX_GAP_FRAMES = 2


def blade_colours(blades) -> tuple[tuple[str, str], ...]:
    """``(lead, trail)`` per blade from a ``[rotor]`` spec (an object with ``.blades``), pairs, or dicts.

    Raises
    ------
    ServoscopeError
        For no blades, a colour that does not parse, a brightness (monochrome footage
        cannot tell blades by colour), or two blades' stickers of one colour.
    """
    blades = getattr(blades, "blades", blades)
    pairs: list[tuple[str, str]] = []
    for i, b in enumerate(blades or ()):
        lead, trail = (b["lead"], b["trail"]) if isinstance(b, dict) else tuple(b)
        for what, spec in (("lead", lead), ("trail", trail)):
            parsed = parse_colour(spec, what=f"[rotor] blade {i} {what} colour")
            if isinstance(parsed, str):
                why = ("monochrome footage cannot tell blades apart by colour; tracking passes needs colour footage"
                       if parsed in BRIGHTNESS else "give the sticker's colour as \"#rrggbb\"")
                raise ServoscopeError(f"[rotor] blade {i} {what} colour {spec!r}: {why}")
        pairs.append((str(lead), str(trail)))
    if not pairs:
        raise ServoscopeError("[rotor] blades: give one {lead = \"#rrggbb\", trail = \"#rrggbb\"} per blade")
    specs = [s.lower() for p in pairs for s in p]
    if len(set(specs)) != len(specs):
        raise ServoscopeError(f"[rotor] blades: every sticker needs its own colour to tell the blades apart, got {pairs}")
    return tuple(pairs)


class _Sticker:
    """One sticker's kernel row: seeded by its given colour, learned when first seen whole."""

    def __init__(self, name: str, rgb) -> None:
        self.name = name
        self.rgb = tuple(float(c) for c in rgb)
        y, u, v = ycbcr_bt601(self.rgb)
        sat = math.hypot(u - 128.0, v - 128.0)
        self.angle = math.atan2(v - 128.0, u - 128.0)
        self.prm = np.zeros(K.NP)
        p = self.prm
        p[K.P.YM], p[K.P.UM], p[K.P.VM] = y, u, v
        p[K.P.DIR_U], p[K.P.DIR_V] = math.cos(self.angle), math.sin(self.angle)
        p[K.P.COS_TOL] = math.cos(SEED_TOLERANCE_RAD)
        # Half the seed's saturation: lighting and the codec take some away; a grey sky none.
        p[K.P.SAT_MIN] = max(6.0, 0.35 * sat)
        p[K.P.AGREE] = 0.15
        p[K.P.RING] = RING_PX
        p[K.P.W_Y] = W_Y
        # Two passes, recentred on the soft centroid: a support centred on the class's box (its
        # chroma quantised to 2 px) biased a sticker by 0.08 px on the twin's raw footage; recentred, 0.02.
        p[K.P.ITER] = 2.0
        p[K.P.VAR_Y] = p[K.P.VAR_C] = 1.0
        p[K.P.ALPHA_LO], p[K.P.ALPHA_HI] = 0.0, 1.0
        p[K.P.MIN_DEN] = 100.0
        p[K.P.RECT] = 1.0
        p[K.P.COS], p[K.P.SIN] = 1.0, 0.0
        p[K.P.RECT_MARGIN] = SUPPORT_MARGIN_PX
        p[K.P.USE_CENTRE] = 0.0
        self.learned = False
        self.max_tol = SEED_TOLERANCE_RAD

    def learn(self, Y, U, V, blob: np.ndarray, i0: int, j0: int) -> None:
        """The sticker's colour, hue cone and noise from its blob's core (chroma samples, eroded by one)."""
        core = cv2.erode(blob.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
        if core.sum() < 3:
            core = blob
        jj, ii = np.nonzero(core)
        ci, cj = ii + i0, jj + j0
        u = U[cj, ci].astype(np.float64)
        v = V[cj, ci].astype(np.float64)
        # Luma of the 2×2 block each chroma sample covers.
        yb = np.mean([Y[np.minimum(2 * cj + dy, Y.shape[0] - 1), np.minimum(2 * ci + dx, Y.shape[1] - 1)]
                      for dy in (0, 1) for dx in (0, 1)], axis=0)
        self.angle, _ = learn_colour_model(self.prm, yb, u, v, self.max_tol)
        self.learned = True


def _separate(stickers: list[_Sticker]) -> None:
    """Narrow each sticker's hue cone to under half the angle to every other sticker's colour."""
    for s in stickers:
        gaps = [abs(math.remainder(s.angle - o.angle, 2 * math.pi)) for o in stickers if o is not s]
        if gaps:
            s.max_tol = min(SEED_TOLERANCE_RAD, max(0.45 * min(gaps), math.radians(4.0)))
            s.prm[K.P.COS_TOL] = max(s.prm[K.P.COS_TOL], math.cos(s.max_tol))


@dataclass
class RotorSightings:
    """What :func:`scan_rotor_video` saw: per frame and blade, whether the blade's stickers were there and where.

    Attributes
    ----------
    time_s : ndarray, shape (n,)
        Each frame's timestamp (s, the container's clock).
    seen : ndarray of bool, shape (n, blades)
        Any of the blade's stickers in the picture (whole or cut).
    lead_xy_px, trail_xy_px : ndarray, shape (n, blades, 2)
        Sub-pixel centroids where the sticker is whole, else NaN.
    lead_sigma_px, trail_sigma_px : ndarray, shape (n, blades)
        Each centroid coordinate's standard error from the pixels' noise (px).
    led_level_dn, led_peak_dn : list of float
        The fixed LED's mean luma per frame (NaN where not measured), and its brightest
        pixel in the first frames (the clip check).
    led_xy_px : (float, float) or None
        Where the LED is.
    snapshot_rgb : ndarray or None
        The first frame with no blade (RGB), where the LED was found.
    width, height : int
    colours_seen : list of str
        What the cheap test saw of each colour (for the error when no pass is found).
    kernel_rows : list of str
        The stickers whose height was mostly the colour kernel's, not luma's (:data:`LUMA_ROWS`), each
        with why it matters and what avoids it: a warning.
    """

    time_s: np.ndarray
    seen: np.ndarray
    lead_xy_px: np.ndarray
    trail_xy_px: np.ndarray
    lead_sigma_px: np.ndarray
    trail_sigma_px: np.ndarray
    led_level_dn: list[float] = field(default_factory=list)
    led_peak_dn: list[float] = field(default_factory=list)
    led_xy_px: tuple[float, float] | None = None
    snapshot_rgb: np.ndarray | None = None
    width: int = 0
    height: int = 0
    colours_seen: list[str] = field(default_factory=list)
    kernel_rows: list[str] = field(default_factory=list)


def _class_blob(st: _Sticker, U, V, box, shape):
    """The sticker's largest blob of class samples in ``box`` (luma x0, y0, x1, y1): mask and its offset, or None."""
    h, w = shape
    hc, wc = U.shape
    x0, y0, x1, y1 = box
    i0, i1 = max(0, x0 // 2), min(wc, (x1 + 1) // 2 + 1)
    j0, j1 = max(0, y0 // 2), min(hc, (y1 + 1) // 2 + 1)
    if i1 <= i0 or j1 <= j0:
        return None
    cls = K.classify_np(st.prm, U[j0:j1, i0:i1].astype(np.float64), V[j0:j1, i0:i1].astype(np.float64))
    if not cls.any():
        return None
    n, labels, stats, _ = cv2.connectedComponentsWithStats(cls.astype(np.uint8), connectivity=8)
    lab = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return labels == lab, i0, j0


def _measure(st: _Sticker, Y, U, V, blob, i0: int, j0: int, out_row: np.ndarray,
             luma_rows: bool = True) -> tuple[bool, float, float, float, bool]:
    """The sticker's kernel measurement over a support following its blob's box: (whole, x, y, σ, y from luma)."""
    h, w = Y.shape
    jj, ii = np.nonzero(blob)
    # Chroma sample (i, j) covers luma columns 2i, 2i+1 (rows likewise).
    bx0, bx1 = 2 * (ii.min() + i0), 2 * (ii.max() + i0) + 1
    by0, by1 = 2 * (jj.min() + j0), 2 * (jj.max() + j0) + 1
    cx, cy = 0.5 * (bx0 + bx1), 0.5 * (by0 + by1)
    hu, hv = 0.5 * (bx1 - bx0) + 0.5, 0.5 * (by1 - by0) + 0.5
    reach_x = hu + SUPPORT_MARGIN_PX + 1.0 + RING_PX
    reach_y = hv + SUPPORT_MARGIN_PX + 1.0 + RING_PX
    whole = cx - reach_x >= 0 and cy - reach_y >= 0 and cx + reach_x <= w - 1 and cy + reach_y <= h - 1
    if not whole:
        return False, math.nan, math.nan, math.nan, False
    p = st.prm.copy()
    p[K.P.HALF_U], p[K.P.HALF_V] = hu, hv
    p[K.P.RADIUS] = math.hypot(hu, hv) + SUPPORT_MARGIN_PX
    p[K.P.X0], p[K.P.Y0] = max(0, bx0 - 2), max(0, by0 - 2)
    p[K.P.X1], p[K.P.Y1] = min(w, bx1 + 3), min(h, by1 + 3)
    p[K.P.CX], p[K.P.CY] = cx, cy
    p[K.P.ENABLED] = 1.0
    params = np.zeros((1, K.NP))
    params[0] = p
    out = np.zeros((1, K.NQ))
    K.track_frame_numba(Y, U, V, 0, 1, params, np.zeros(K.LED_NP), out, np.zeros(K.LED_NQ))
    r = out[0]
    if SUPPORT_FROM_MOMENTS and r[K.Q.M00] > 0 and r[K.Q.MU02] > 0:
        # Again over a support sized by the soft moments (not the class box, quantised to the chroma's
        # 2 px): a round sticker's radius 2√μ02 across the motion, and along it the blur's length
        # √(12(μ20 − μ02)) added (a disc swept along the rows), centred on the soft centroid.
        hv = 2.0 * math.sqrt(r[K.Q.MU02])
        hu = hv + 0.5 * math.sqrt(max(0.0, 12.0 * (r[K.Q.MU20] - r[K.Q.MU02])))
        p[K.P.HALF_U], p[K.P.HALF_V] = hu, hv
        p[K.P.RADIUS] = math.hypot(hu, hv) + SUPPORT_MARGIN_PX
        p[K.P.CX], p[K.P.CY], p[K.P.USE_CENTRE], p[K.P.ITER] = r[K.Q.X], r[K.Q.Y], 1.0, 1.0
        cx, cy = r[K.Q.X], r[K.Q.Y]
        if not (cx - hu - SUPPORT_MARGIN_PX - 1.0 - RING_PX >= 0 and cy - hv - SUPPORT_MARGIN_PX - 1.0 - RING_PX >= 0
                and cx + hu + SUPPORT_MARGIN_PX + 1.0 + RING_PX <= w - 1
                and cy + hv + SUPPORT_MARGIN_PX + 1.0 + RING_PX <= h - 1):
            return False, math.nan, math.nan, math.nan, False
        params[0] = p
        K.track_frame_numba(Y, U, V, 0, 1, params, np.zeros(K.LED_NP), out, np.zeros(K.LED_NQ))
        r = out[0]
    out_row[:] = r
    if not (r[K.Q.M00] > 0 and r[K.Q.RING_N] >= 8 and r[K.Q.AT_BORDER] == 0):
        return False, math.nan, math.nan, math.nan, False
    y, var_y = float(r[K.Q.Y]), float(r[K.Q.VAR_Y])
    from_luma = False
    if luma_rows:
        # The vertical coordinate again from luma alone (pass_centroid: the kernel's leans on 4:2:0 chroma,
        # whose cut tail biases it with the row's sub-pixel phase, frozen through a pass).
        yl, sl = luma_row_centroid(Y, float(r[K.Q.X]), y, p[K.P.HALF_U], p[K.P.HALF_V], SUPPORT_MARGIN_PX,
                                   RING_PX, p[K.P.YM], p[K.P.VAR_Y])
        if math.isfinite(yl):
            y, var_y, from_luma = yl, sl * sl, True
    return True, float(r[K.Q.X]), y, math.sqrt(0.5 * (r[K.Q.VAR_X] + var_y)), from_luma


def _hex(rgb) -> str:
    return "#" + "".join(f"{int(round(min(max(c, 0.0), 255.0))):02x}" for c in rgb)


def _find_led(rgb: np.ndarray, spec, near) -> tuple[tuple[float, float], float] | None:
    """The fixed LED: the largest blob of its colour (or the one at ``near``): centre and radius (px)."""
    mask = ColourModel.from_seed(spec).mask(rgb).astype(np.uint8)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    if n <= 1:
        return None
    if near is not None:
        lab = int(labels[int(round(near[1])), int(round(near[0]))])
        if lab == 0:
            d = np.hypot(cents[1:, 0] - near[0], cents[1:, 1] - near[1])
            lab = 1 + int(np.argmin(d))
    else:
        lab = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    if stats[lab, cv2.CC_STAT_AREA] < 3:
        return None
    return (float(cents[lab, 0]), float(cents[lab, 1])), math.sqrt(stats[lab, cv2.CC_STAT_AREA] / math.pi)


def scan_rotor_video(path: str | Path, blades: Sequence[tuple[str, str]], *, led: str | None = None,
                     led_near: tuple[float, float] | None = None,
                     progress: Callable[[int], None] | None = None, luma_rows: bool | None = None) -> RotorSightings:
    """Every frame of a rotor's video: each blade's stickers, their centroids where whole, the fixed LED's level.

    Parameters
    ----------
    path : path-like
        A colour video (anything the YUV engines decode).
    blades : sequence of (lead, trail)
        Each blade's sticker colours (:func:`blade_colours`).
    led : str or None
        The LED's colour (fixed on the airframe); None: no LED.
    led_near : (float, float) or None
        Pin the LED by position (px).
    progress : callable, optional
        Called with the number of frames done, now and then.
    luma_rows : bool, optional
        Each sticker's vertical coordinate from luma (:mod:`.pass_centroid`); False: the fused kernel's
        (biased with the row's sub-pixel phase, for comparison); None: :data:`LUMA_ROWS`.

    Returns
    -------
    RotorSightings

    Notes
    -----
    Long because the per-frame loop keeps the cheap test, the close measurement and the
    LED together, in the order a frame needs them.
    """
    path = Path(path)
    luma_rows = LUMA_ROWS if luma_rows is None else bool(luma_rows)
    pairs = blade_colours(blades)
    nb = len(pairs)
    stickers = [_Sticker(f"blade {b} {which}", parse_colour(spec)) for b, pair in enumerate(pairs)
                for which, spec in zip(("lead", "trail"), pair)]
    _separate(stickers)
    led_spec = parse_colour(led, what="LED colour") if led else None
    if isinstance(led_spec, str):
        led_spec = None  # a brightness LED on colour footage: read as none here (stated by the caller)
    time_s: list[float] = []
    seen_rows: list[np.ndarray] = []
    lead_rows: list[np.ndarray] = []
    trail_rows: list[np.ndarray] = []
    lsig_rows: list[np.ndarray] = []
    tsig_rows: list[np.ndarray] = []
    out = RotorSightings(np.zeros(0), np.zeros((0, nb), bool), np.zeros((0, nb, 2)), np.zeros((0, nb, 2)),
                         np.zeros((0, nb)), np.zeros((0, nb)))
    led_disk = None
    coarse_max = np.zeros(len(stickers), dtype=np.int64)
    n_whole = [0] * len(stickers)  # whole measurements of each sticker, and how many took their height from luma
    n_luma = [0] * len(stickers)
    coarse_where: list[tuple[int, float, float] | None] = [None] * len(stickers)
    row = np.zeros(K.NQ)
    sat_floor = np.float32(min(st.prm[K.P.SAT_MIN] for st in stickers))
    led_tries = 0
    for frame in iter_yuv_frames(path):
        Y, U, V = frame.y, frame.u, frame.v
        h, w = Y.shape
        out.width, out.height = w, h
        # The cheap test: classify_np's own test (saturation floor, hue cone) on the coarse grid, its
        # chroma offsets and saturation computed once for every colour.
        us = U[::2, ::2].astype(np.float32) - np.float32(128.0)
        vs = V[::2, ::2].astype(np.float32) - np.float32(128.0)
        sat = np.sqrt(us * us + vs * vs)
        # Only samples above the lowest saturation floor can be any sticker's: an empty frame (a grey sky,
        # a dark blade) usually has none, and stops here.
        cand = np.flatnonzero(sat.ravel() >= sat_floor)
        us_c, vs_c, sat_c = us.ravel()[cand], vs.ravel()[cand], sat.ravel()[cand]
        grid_w = sat.shape[1]
        seen = np.zeros(nb, dtype=bool)
        lead_xy = np.full((nb, 2), np.nan)
        trail_xy = np.full((nb, 2), np.nan)
        lsig = np.full(nb, np.nan)
        tsig = np.full(nb, np.nan)
        boxes = []
        for s, st in enumerate(stickers):
            if cand.size == 0:
                break
            prm = st.prm
            hit = (sat_c >= prm[K.P.SAT_MIN]) & ((us_c * prm[K.P.DIR_U] + vs_c * prm[K.P.DIR_V])
                                                 >= prm[K.P.COS_TOL] * sat_c)
            if not hit.any():
                continue
            jj, ii = np.divmod(cand[hit], grid_w)
            if led_disk is not None:
                (lx, ly), lr = led_disk
                away = (np.abs(4.0 * ii + 1.5 - lx) > lr + 4.0) | (np.abs(4.0 * jj + 1.5 - ly) > lr + 4.0)
                jj, ii = jj[away], ii[away]
            count = int(jj.size)
            if count > coarse_max[s]:
                coarse_max[s] = count
                coarse_where[s] = (frame.index, 4.0 * ii.mean() + 1.5, 4.0 * jj.mean() + 1.5)
            if count < MIN_COARSE:
                continue
            b, which = divmod(s, 2)
            seen[b] = True
            # Coarse sample (i, j) is chroma (2i, 2j): luma columns 4i … 4i + 1 (+ its neighbours' reach).
            box = (int(4 * ii.min()) - COARSE_GROW_PX, int(4 * jj.min()) - COARSE_GROW_PX,
                   int(4 * ii.max() + 3) + COARSE_GROW_PX, int(4 * jj.max() + 3) + COARSE_GROW_PX)
            boxes.append(box)
            found = _class_blob(st, U, V, box, (h, w))
            if found is None:
                continue
            blob, i0, j0 = found
            if not st.learned:
                whole = _measure(st, Y, U, V, blob, i0, j0, row, luma_rows=False)[0]  # only whether whole
                if not whole:
                    continue
                st.learn(Y, U, V, blob, i0, j0)
                sat_floor = np.float32(min(o.prm[K.P.SAT_MIN] for o in stickers))
                found = _class_blob(st, U, V, box, (h, w))
                if found is None:
                    continue
                blob, i0, j0 = found
            whole, x, y, sig, from_luma = _measure(st, Y, U, V, blob, i0, j0, row, luma_rows)
            if whole:
                n_whole[s] += 1
                n_luma[s] += from_luma
                if which == 0:
                    lead_xy[b], lsig[b] = (x, y), sig
                else:
                    trail_xy[b], tsig[b] = (x, y), sig
        if led_spec is not None and led_disk is None and not seen.any() and led_tries < LED_TRIES:
            led_tries += 1
            rgb = frame.rgb
            led_disk = _find_led(rgb, led_spec, led_near)
            if led_disk is not None:
                out.snapshot_rgb = rgb
                out.led_xy_px = led_disk[0]
                # The disk read: the blob's radius grown by half and a pixel, as the static engines' LED disk.
                led_disk = (led_disk[0], 1.5 * led_disk[1] + 1.0)
        level = math.nan
        if led_disk is not None:
            (lx, ly), lr = led_disk
            covered = any(x0 - lr <= lx <= x1 + lr and y0 - lr <= ly <= y1 + lr for x0, y0, x1, y1 in boxes)
            if not covered:
                level, peak = disk_level(Y, lx, ly, lr)
                if len(out.led_peak_dn) < LED_PEAK_FRAMES:
                    out.led_peak_dn.append(peak)
        out.led_level_dn.append(level)
        time_s.append(frame.time_s)
        seen_rows.append(seen)
        lead_rows.append(lead_xy)
        trail_rows.append(trail_xy)
        lsig_rows.append(lsig)
        tsig_rows.append(tsig)
        if progress is not None and frame.index % 200 == 0:
            progress(frame.index + 1)
    n = len(time_s)
    if led_spec is not None and led_disk is None:
        # No frame without a blade, or no LED in it: its level is unknown everywhere.
        out.led_level_dn = [math.nan] * n
    out.time_s = np.asarray(time_s, dtype=np.float64)
    out.seen = np.asarray(seen_rows, dtype=bool).reshape(n, nb)
    out.lead_xy_px = np.asarray(lead_rows, dtype=np.float64).reshape(n, nb, 2)
    out.trail_xy_px = np.asarray(trail_rows, dtype=np.float64).reshape(n, nb, 2)
    out.lead_sigma_px = np.asarray(lsig_rows, dtype=np.float64).reshape(n, nb)
    out.trail_sigma_px = np.asarray(tsig_rows, dtype=np.float64).reshape(n, nb)
    out.colours_seen = [
        (f"{st.name} {_hex(st.rgb)}: " + ("not seen" if coarse_where[s] is None else
                                         f"at most {coarse_max[s]} coarse samples (frame {coarse_where[s][0]}, "
                                         f"around x={coarse_where[s][1]:.0f}, y={coarse_where[s][2]:.0f} px)"))
        for s, st in enumerate(stickers)]
    if luma_rows:
        out.kernel_rows = [
            f"{st.name} {_hex(st.rgb)}: its height read by the colour kernel in {n_whole[s] - n_luma[s]} of "
            f"{n_whole[s]} frames (its luma under {MIN_LUMA_CONTRAST_DN:.0f} DN from the blade's, or the tip's edge "
            "too near): biased with its sub-pixel row by up to 0.03 px, a scale on the pitch of up to ±1.7 %; a "
            f"colour whose luma differs from the blade's by {MIN_LUMA_CONTRAST_DN:.0f} DN or more avoids it"
            for s, st in enumerate(stickers) if n_whole[s] >= KERNEL_ROWS_MIN_FRAMES and 2 * n_luma[s] < n_whole[s]]
    return out


@dataclass(frozen=True)
class PassFrames:
    """One pass: a blade's stickers from entering the picture to leaving it.

    Attributes
    ----------
    blade : int
    first_frame, last_frame : int
        The first and last frame in which the blade's stickers were seen.
    whole : ndarray of int
        The frames (indices) in which both stickers were whole: the pitch's frames.
    """

    blade: int
    first_frame: int
    last_frame: int
    whole: np.ndarray

    @property
    def frames(self) -> int:
        """Frames from entering to leaving."""
        return self.last_frame - self.first_frame + 1


def segment_passes(sightings: RotorSightings, *, max_gap: int = MAX_GAP_FRAMES) -> list[PassFrames]:
    """Each blade's seen frames cut into passes (runs with gaps of at most ``max_gap`` frames), in time order.

    Parameters
    ----------
    sightings : RotorSightings
    max_gap : int
        Unseen frames a pass may hold.

    Returns
    -------
    list of PassFrames
        Sorted by first frame.
    """
    passes: list[PassFrames] = []
    whole_all = (np.isfinite(sightings.lead_xy_px[..., 0]) & np.isfinite(sightings.trail_xy_px[..., 0]))
    for b in range(sightings.seen.shape[1]):
        idx = np.flatnonzero(sightings.seen[:, b])
        if idx.size == 0:
            continue
        cuts = np.flatnonzero(np.diff(idx) > max_gap + 1)
        starts = np.r_[idx[0], idx[cuts + 1]]
        ends = np.r_[idx[cuts], idx[-1]]
        for a, e in zip(starts, ends):
            frames = np.arange(a, e + 1)
            passes.append(PassFrames(b, int(a), int(e), frames[whole_all[a:e + 1, b]]))
    return sorted(passes, key=lambda p: p.first_frame)
