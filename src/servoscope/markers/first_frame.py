"""The first frame: which blobs are the markers (selection, "auto" colours), and the error when none is."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..defaults import MARKER_HUE_GATE
from ..errors import ServoscopeError
from .colour import AUTO, BRIGHTNESS, ColourModel
from .marker_state import MarkerTracker
from .selection import BlobCandidate, auto_colour_models, choose_markers, marker_candidates
from .settings import TrackerSettings

__all__ = ["choose_first", "gate_candidates", "nothing_matches", "take_auto_colours"]


def take_auto_colours(path: Path, rgb: np.ndarray, trackers, led_model: ColourModel | None) -> None:
    """Give each marker set to ``"auto"`` a colour: the blobs most like a pair of stickers (see :mod:`.selection`).

    The LED's and the other marker's colours are excluded.

    Raises
    ------
    ServoscopeError
        When no coloured blob is left for a marker.
    """
    exclude = [led_model] if led_model is not None else []
    exclude += [m.model for m in trackers if m.model is not None]
    models = auto_colour_models(rgb, exclude)
    for tracker in trackers:
        if tracker.model is None:
            if not models:
                raise ServoscopeError(f"{path}: no coloured blob found for the {tracker.name} marker (\"auto\")")
            tracker.model = models.pop(0)


def choose_first(path: Path, rgb: np.ndarray, trackers, settings: TrackerSettings, row_offset: int = 0,
                  row_step: int = 1) -> list[str]:
    """Choose each marker's blob in the first frame (see :mod:`.selection`); set the trackers' hints.

    Returns the close-call warnings. When a marker's colour matches no blob
    big enough to be a candidate, no hint is set and the first detection
    reports it as before (the closest coloured blobs listed), unless the marker
    is pinned: then the pin's error names the nearest blob.
    """
    lead, trail = trackers
    cands = [marker_candidates(rgb, t.model, t.model.hue) if t.model is not None else [] for t in trackers]
    pins = (settings.lead_near, settings.trail_near)
    cands = [gate_candidates(path, t, c, rgb, pin is not None, row_offset, row_step)
             for t, c, pin in zip(trackers, cands, pins)]
    pinned = settings.lead_near is not None or settings.trail_near is not None
    if not pinned and not all(cands):
        return []
    def in_image(near):
        # Pins are in frame pixels; a field's image has every row_step-th row from row_offset.
        return None if near is None else (near[0], (near[1] - row_offset) / row_step)

    # Two markers of one brightness are the same kind of blob: the lead is the one on the right
    # (as the twin and the paper film them), unless a pin says otherwise.
    same_kind = isinstance(lead.seed, str) and lead.seed in BRIGHTNESS and lead.seed == trail.seed
    choice = choose_markers(cands[0], cands[1], lead_near=in_image(settings.lead_near),
                            trail_near=in_image(settings.trail_near),
                            lead_colour=_spec_text(lead.seed), trail_colour=_spec_text(trail.seed), source=str(path),
                            lead_right=same_kind and settings.lead_near is None and settings.trail_near is None)
    lead.hint = (choice.lead.x_px, choice.lead.y_px)
    trail.hint = (choice.trail.x_px, choice.trail.y_px)
    return choice.warnings


def gate_candidates(path: Path, tracker, cands: list[BlobCandidate], rgb: np.ndarray, pinned: bool = False,
                    row_offset: int = 0, row_step: int = 1) -> list[BlobCandidate]:
    """The candidates whose hue is within :data:`~servoscope.defaults.MARKER_HUE_GATE` of the colour asked.

    What is not there is not found: a blob further from the colour asked than
    lighting, white balance and codecs move a sticker's is not that marker.
    Markers told by brightness, or given as ``"auto"`` (their colour is a blob's
    own), are not gated.

    Raises
    ------
    ServoscopeError
        When blobs of the marker's colour band were seen but none is within
        the gate: one line naming the marker, the closest colours seen and where;
        when no blob of its colour band is big enough to be a sticker (and it is
        not pinned: the pin's error names the nearest blob), :func:`nothing_matches`.
    """
    if not isinstance(tracker.model, ColourModel) or isinstance(tracker.seed, str):
        return cands
    if not cands:
        if pinned:
            return cands
        raise ServoscopeError(nothing_matches(path, tracker, rgb))
    kept = [c for c in cands if c.hue_distance <= MARKER_HUE_GATE]
    if kept:
        return kept
    closest = sorted(cands, key=lambda c: c.hue_distance)[:3]
    seen = ", ".join(f"{c.colour_hex} at ({c.x_px:.0f}, {c.y_px * row_step + row_offset:.0f}) "
                     f"({2.0 * c.hue_distance:.0f}° of hue off)" for c in closest)
    raise ServoscopeError(
        f"{path}: no {tracker.name} marker of colour {_spec_text(tracker.seed)} in the first frame: the closest "
        f"colours seen are {seen}, further than the {2.0 * MARKER_HUE_GATE:.0f}° of hue that lighting, white "
        f"balance and codecs move a sticker's colour; check the footage with `servoscope markers {path}` and "
        "give the stickers' colours")


def _auto_models(rgb: np.ndarray, exclude: list[ColourModel]) -> list[ColourModel]:
    """The two blobs of distinct hue most like a pair of stickers, right one first (see :mod:`.selection`)."""
    return auto_colour_models(rgb, exclude)


def nothing_matches(path: Path, tracker: MarkerTracker, rgb: np.ndarray) -> str:
    """Error message for a marker colour that matches nothing, with the closest blobs."""
    from .candidates import find_candidates

    if isinstance(tracker.seed, str) and tracker.seed in BRIGHTNESS:
        return (f"{path}: no {tracker.seed} blob for the {tracker.name} marker in the first frame (threshold "
                f"{getattr(tracker.model, 'threshold_dn', float('nan')):.0f} of 255); check the footage with "
                "`servoscope markers`, or pin the marker: lead = {brightness = \"bright\", near = [x, y]}")
    text = _spec_text(tracker.seed) if tracker.seed != AUTO else "auto"
    msg = f"{path}: the {tracker.name} marker's colour {text} matches nothing in the first frame"
    cands = find_candidates(rgb)
    if not cands:
        return msg + "; no saturated blob in that frame at all"
    hue = tracker.model.hue * 2.0 if tracker.model is not None else 0.0
    cands.sort(key=lambda c: abs(((c.hue_deg - hue + 180.0) % 360.0) - 180.0))
    listed = ", ".join(f"#{c.number} {c.colour_hex} (hue {c.hue_deg:.0f}°, {c.area_px} px at {c.x_px:.0f},{c.y_px:.0f})"
                       for c in cands[:3])
    return msg + f"; closest coloured blobs: {listed} (see `servoscope markers`)"


def _spec_text(spec) -> str:
    if isinstance(spec, str):
        return spec
    return "#%02x%02x%02x" % tuple(int(round(c)) for c in spec)
