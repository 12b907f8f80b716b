"""``servoscope track``'s refusal of a track too thin to measure anything.

Part of the command line (:mod:`servoscope.cli`), kept apart so that the commands stay a
thin layer over the API.
"""

from __future__ import annotations

import re

from .defaults import MIN_VALID_FRAMES
from .errors import ServoscopeError

__all__ = ["refuse_too_few_valid"]


def refuse_too_few_valid(name: str, track) -> None:
    """End in an error, not a CSV, when ``track`` has fewer valid frames than a fit can use.

    The threshold is :data:`~servoscope.defaults.MIN_VALID_FRAMES` (the step fit's
    minimum; a sine dwell's is smaller). The message is one line: how many frames
    were valid and the main reasons the others were not.

    A short clip whose every frame is valid is a measurement, only a short one (a benchmark's
    six frames, a user trying a few): it is not refused.

    Raises
    ------
    ServoscopeError
        When ``track.n_valid < MIN_VALID_FRAMES`` and some frames were not valid.
    """
    if track.n_valid >= MIN_VALID_FRAMES or track.n_valid == track.n_frames:
        return
    counts: dict[str, int] = {}
    for reason in track.reason:
        if reason:
            key = re.sub(r"\d+(\.\d+)?", "…", reason.split(" (")[0])  # "duplicate of frame 7": one reason
            counts[key] = counts.get(key, 0) + 1
    main = sorted(counts.items(), key=lambda kv: -kv[1])[:3]
    why = "; ".join(f"{k}: {v}" for k, v in main) or "no reason recorded"
    raise ServoscopeError(
        f"{name}: only {track.n_valid} of {track.n_frames} frames valid (a fit needs at least {MIN_VALID_FRAMES}): "
        f"{why}; nothing written: check the markers with `servoscope markers {name}`")
