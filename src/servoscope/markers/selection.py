"""Choosing the two markers in the first frame, as a person would.

The first detection used to take, for each marker, the largest blob of its
colour. A larger object of nearly a sticker's hue (a red-brown box, a red
canopy) then won, even with the sticker's exact colour given. Here every
blob of each marker's colour is a *candidate*, scored on what tells a sticker
from the rest of a workshop:

* **colour**: how close its median hue is to the marker's colour;
* **shape**: its solidity (area over convex-hull area): a disc, a square or a
  tape strip is solid (≥ 0.9), a piece of clothing or a cluttered patch is not;
* **border**: a blob that touches the image border is cut off, so it is not
  a whole sticker;
* **size against the other marker's candidates**: two stickers on one blade
  are of similar size, so the *pair* is scored, not each blob alone.

The best pair wins. When another candidate scores nearly as well for a
marker, a warning names both (colour, position, size) and says how to pin
one. A user can pin a marker by position, as Tracker and DLTdv users click a
point: ``lead = {colour = "#d62728", near = [x, y]}`` in a campaign's
``[markers]``, ``--lead '#d62728@x,y'`` on the command line.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from ..errors import ServoscopeError
from .colour import ColourModel, hsv_of_rgb, parse_colour

__all__ = ["BlobCandidate", "MarkerChoice", "parse_marker_spec", "marker_candidates", "choose_markers",
           "auto_colour_models", "solidity_of", "check_near",
           "CLOSE_CALL_RATIO", "HUE_SCALE", "SIZE_LOG_SCALE"]

#: A runner-up scoring at least this fraction of the chosen pair's score is a close call (warned).
CLOSE_CALL_RATIO = 0.5
#: Hue distance (OpenCV units, 0–90; 1 unit = 2°) at which the colour score falls to e^-1/2:
#: a sticker's recorded hue is within 2–4 units of what the camera made of the given colour.
HUE_SCALE = 6.0
#: Spread of ln(area ratio) of two stickers at which the size score falls to e^-1/2
#: (a ratio of 1.4; two stickers of one sheet differ by their perspective only).
SIZE_LOG_SCALE = 0.35
#: Score factor of a blob that touches the image border (cut off: not a whole sticker).
BORDER_FACTOR = 0.05
#: Candidates below this binary area (px) are specks, not stickers.
MIN_AREA_PX = 12
#: At most this many candidates per marker (largest first) enter the pair scoring.
MAX_CANDIDATES = 24


@dataclass(frozen=True)
class BlobCandidate:
    """One blob of a marker's colour in the first frame.

    Attributes
    ----------
    x_px, y_px : float
        Centroid of the binary blob (px).
    area_px : int
        Binary area (px).
    colour_hex : str
        Median colour, ``"#rrggbb"``.
    hue_distance : float
        Distance of its median hue from the marker's (OpenCV units, 0–90).
    solidity : float
        Area over the area of its convex hull (1 for a convex blob).
    touches_border : bool
        Whether it reaches the image's first or last row or column.
    score : float
        Product of its own factors (colour, shape, border), without the pair's size term.
    """

    x_px: float
    y_px: float
    area_px: int
    colour_hex: str
    hue_distance: float
    solidity: float
    touches_border: bool
    score: float

    def describe(self) -> str:
        """``#rrggbb at (x, y), N px``: how a warning or an error names it."""
        return f"{self.colour_hex} at ({self.x_px:.0f}, {self.y_px:.0f}), {self.area_px} px"


@dataclass(frozen=True)
class MarkerChoice:
    """The chosen blob of each marker and what the choice had to say.

    Attributes
    ----------
    lead, trail : BlobCandidate
    warnings : list of str
        Close calls, each naming both candidates.
    """

    lead: BlobCandidate
    trail: BlobCandidate
    warnings: list[str]


def parse_marker_spec(spec: str, *, what: str = "marker") -> tuple[str, tuple[float, float] | None]:
    """Split ``"#rrggbb@x,y"`` into its colour and the pinned position.

    Parameters
    ----------
    spec : str
        A colour as :func:`~servoscope.markers.colour.parse_colour` takes it,
        optionally followed by ``@x,y``: the marker is the blob of that colour
        at (or nearest to) pixel (x, y) of the first frame.
    what : str
        Names the option or key in error messages.

    Returns
    -------
    (colour, near)
        ``near`` is None when no position is given.

    Raises
    ------
    ServoscopeError
        When the colour or the position does not parse.
    """
    if not isinstance(spec, str) or "@" not in spec:
        return spec, None
    colour, _, where = spec.partition("@")
    parts = where.split(",")
    try:
        x, y = (float(p) for p in parts)
    except ValueError:
        raise ServoscopeError(
            f"{what}: {spec!r}: the position after '@' must be two numbers x,y in pixels "
            "(e.g. '#d62728@412,230')") from None
    near = check_near((x, y), what=what)
    parse_colour(colour, what=what)
    return colour, near


def check_near(near, *, what: str) -> tuple[float, float]:
    """Validate a pinned position: two finite, non-negative pixel coordinates."""
    try:
        x, y = (float(v) for v in near)
    except (TypeError, ValueError):
        raise ServoscopeError(f"{what}: near must be two numbers [x, y] in pixels, got {near!r}") from None
    if not (math.isfinite(x) and math.isfinite(y) and x >= 0 and y >= 0):
        raise ServoscopeError(f"{what}: near must be pixel coordinates >= 0, got [{x:g}, {y:g}]")
    return x, y


def marker_candidates(rgb: np.ndarray, model: ColourModel, seed_hue: float) -> list[BlobCandidate]:
    """Every blob of ``model``'s colour in ``rgb`` (binary components), largest first.

    Parameters
    ----------
    rgb : ndarray, shape (h, w, 3), uint8
    model : ColourModel
        The marker's colour band (its mask defines the blobs).
    seed_hue : float
        The marker's hue (OpenCV units, 0–180) that the candidates' hues are compared with.
    """
    h, w = rgb.shape[:2]
    mask = model.mask(rgb).astype(np.uint8)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    order = np.argsort(-stats[1:, cv2.CC_STAT_AREA], kind="stable") + 1
    out: list[BlobCandidate] = []
    for i in order[:MAX_CANDIDATES]:
        area = int(stats[i, cv2.CC_STAT_AREA])
        if area < MIN_AREA_PX:
            break
        x0, y0, bw, bh = (int(v) for v in stats[i, :4])
        comp = labels[y0:y0 + bh, x0:x0 + bw] == i
        pixels = rgb[y0:y0 + bh, x0:x0 + bw][comp]
        hsv = hsv_of_rgb(pixels).reshape(-1, 3).astype(np.float64)
        ang = hsv[:, 0] * (np.pi / 90.0)
        hue = (math.atan2(float(np.sin(ang).mean()), float(np.cos(ang).mean())) * 90.0 / math.pi) % 180.0
        dh = abs(((hue - seed_hue + 90.0) % 180.0) - 90.0)
        solidity = solidity_of(comp)
        border = x0 == 0 or y0 == 0 or x0 + bw >= w or y0 + bh >= h
        r, g, b = (int(round(c)) for c in np.median(pixels.astype(np.float64), axis=0))
        score = (math.exp(-0.5 * (dh / HUE_SCALE) ** 2) * solidity**2 * (BORDER_FACTOR if border else 1.0)
                 * area / (area + 20.0))
        out.append(BlobCandidate(float(cents[i, 0]), float(cents[i, 1]), area, f"#{r:02x}{g:02x}{b:02x}", dh,
                                 solidity, bool(border), score))
    return out


def solidity_of(component: np.ndarray) -> float:
    """Area of a binary blob over the area of its convex hull (pixel edges, not centres)."""
    comp = np.ascontiguousarray(component, dtype=np.uint8)
    area = float(np.count_nonzero(comp))
    contours, _ = cv2.findContours(comp, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    if not contours:
        return 1.0
    hull = cv2.convexHull(np.concatenate(contours))
    # A contour runs through pixel centres: the hull misses half a pixel all round, which
    # matters for small blobs; add it back (perimeter/2 + the corners' π/4).
    hull_area = cv2.contourArea(hull) + 0.5 * cv2.arcLength(hull, True) + math.pi / 4.0
    return float(min(1.0, area / hull_area)) if hull_area > 0 else 1.0


def auto_colour_models(rgb: np.ndarray, exclude: list[ColourModel]) -> list[ColourModel]:
    """The colours of the two blobs of distinct hue that look most like a pair of stickers.

    For markers given as ``"auto"``: saturated blobs (not of an excluded
    colour, the LED's or a given marker's) are scored as
    :func:`marker_candidates` scores them, less the colour term (there is no
    colour to match): solidity, the border, and the two sizes' likeness.
    Returns the pair's colours, the right-hand blob's first (the lead marker
    is the right one by convention); fewer when fewer blobs are found.
    """
    h, w = rgb.shape[:2]
    hsv = hsv_of_rgb(rgb)
    mask = ((hsv[..., 1] >= 100) & (hsv[..., 2] >= 60)).astype(np.uint8)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    blobs: list[tuple[float, float, float, ColourModel]] = []  # x, area, score, colour
    for i in np.argsort(-stats[1:, cv2.CC_STAT_AREA], kind="stable") + 1:
        area = int(stats[i, cv2.CC_STAT_AREA])
        if area < MIN_AREA_PX or len(blobs) >= 2 * MAX_CANDIDATES:
            break
        x0, y0, bw, bh = (int(v) for v in stats[i, :4])
        comp = labels[y0:y0 + bh, x0:x0 + bw] == i
        model = ColourModel.learn(rgb[y0:y0 + bh, x0:x0 + bw][comp])
        if any(abs(((m.hue - model.hue + 90) % 180) - 90) < 12 for m in exclude):
            continue
        border = x0 == 0 or y0 == 0 or x0 + bw >= w or y0 + bh >= h
        score = solidity_of(comp) ** 2 * (BORDER_FACTOR if border else 1.0) * area / (area + 20.0)
        blobs.append((float(cents[i, 0]), float(area), score, model))
    best: tuple[float, int, int] | None = None
    for i, a in enumerate(blobs):
        for j in range(i + 1, len(blobs)):
            b = blobs[j]
            if abs(((a[3].hue - b[3].hue + 90) % 180) - 90) < 12:
                continue  # one colour: not a pair of differently coloured markers
            size = math.exp(-0.5 * (math.log(a[1] / b[1]) / SIZE_LOG_SCALE) ** 2)
            pair = a[2] * b[2] * size
            if best is None or pair > best[0]:
                best = (pair, i, j)
    if best is None:
        return [blobs[0][3]] if blobs else []
    pair = sorted((blobs[best[1]], blobs[best[2]]), key=lambda f: -f[0])
    return [f[3] for f in pair]


def _pinned(cands: list[BlobCandidate], near: tuple[float, float], name: str, colour: str,
            source: str) -> BlobCandidate:
    """The candidate at (or close to) a pinned point; an error naming the nearest when none is."""
    def gap(c: BlobCandidate) -> float:
        # Distance from the point to the blob, roughly: to its centre less its equivalent radius.
        return max(0.0, math.hypot(c.x_px - near[0], c.y_px - near[1]) - math.sqrt(c.area_px / math.pi))

    if cands:
        best = min(cands, key=gap)
        if gap(best) <= max(5.0, 0.5 * math.sqrt(best.area_px / math.pi)):
            return best
        nearest = f"; the nearest blob of that colour is {best.describe()}"
    else:
        nearest = "; there is no blob of that colour in the first frame"
    raise ServoscopeError(
        f"{source}: the {name} marker is pinned at ({near[0]:g}, {near[1]:g}) but no blob of its colour {colour} "
        f"is there in the first frame{nearest} (see `servoscope markers`)")


def choose_markers(lead: list[BlobCandidate], trail: list[BlobCandidate], *,
                   lead_near: tuple[float, float] | None = None, trail_near: tuple[float, float] | None = None,
                   lead_colour: str = "", trail_colour: str = "", source: str = "video",
                   lead_right: bool = False) -> MarkerChoice:
    """The best pair of candidates (lead, trail), pins honoured.

    Parameters
    ----------
    lead, trail : list of BlobCandidate
        From :func:`marker_candidates`; each non-empty (the caller reports a
        colour that matches nothing).
    lead_near, trail_near : (x, y) or None
        Pinned positions (px): the marker is the blob there.
    lead_colour, trail_colour : str
        The colours as given, for messages.
    source : str
        The file the messages name.
    lead_right : bool
        Only pairs whose lead lies right of its trail (markers of one kind, told apart by side).

    Raises
    ------
    ServoscopeError
        When a pin has no blob of its colour near it, or both markers end up on the same blob.
    """
    if lead_near is not None:
        lead = [_pinned(lead, lead_near, "lead", lead_colour, source)]
    if trail_near is not None:
        trail = [_pinned(trail, trail_near, "trail", trail_colour, source)]
    pairs: list[tuple[float, int, int]] = []
    for i, a in enumerate(lead):
        for j, b in enumerate(trail):
            if math.hypot(a.x_px - b.x_px, a.y_px - b.y_px) < 2.0:
                continue  # one blob matching both colours cannot be both stickers
            if lead_right and a.x_px <= b.x_px:
                continue
            size = math.exp(-0.5 * (math.log(a.area_px / b.area_px) / SIZE_LOG_SCALE) ** 2)
            pairs.append((a.score * b.score * size, i, j))
    if not pairs:
        a, b = lead[0], trail[0]
        raise ServoscopeError(
            f"{source}: the lead and trail markers are the same blob ({a.describe()}): "
            "give each its own sticker's colour, or pin them at different positions")
    # Highest score first; ties to the larger blobs (the order of the candidate lists).
    pairs.sort(key=lambda p: (-p[0], p[1], p[2]))
    best, bi, bj = pairs[0]
    warnings = []
    for name, k, cands, pinned in (("lead", 1, lead, lead_near), ("trail", 2, trail, trail_near)):
        if pinned is not None:
            continue
        chosen = pairs[0][k]
        rival = next((p for p in pairs if p[k] != chosen), None)
        if rival is not None and best > 0 and rival[0] >= CLOSE_CALL_RATIO * best:
            c, r = cands[chosen], cands[rival[k]]
            flag = "--lead" if name == "lead" else "--trail"
            warnings.append(
                f"{name} marker: a close call between {c.describe()} (chosen) and {r.describe()}; if the "
                f"other is the sticker, pin it: {name} = {{colour = \"{r.colour_hex}\", near = [{r.x_px:.0f}, "
                f"{r.y_px:.0f}]}} in [markers], or {flag} '{r.colour_hex}@{r.x_px:.0f},{r.y_px:.0f}'")
    return MarkerChoice(lead[bi], trail[bj], warnings)
