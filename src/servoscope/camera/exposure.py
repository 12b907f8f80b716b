"""The camera's exposure (shutter), from what the footage shows of it.

The rig switches the LED at a time that has nothing to do with the camera's
frame clock, so the switch falls inside an exposure with probability
exposure / frame interval, and then one frame is partly lit; otherwise it
falls in the unexposed gap between two exposures and every frame is clean.
Over a campaign's videos the share of switches that lit a frame partly
estimates the exposure's share of the frame interval (a binomial
proportion, with its Wilson interval).

A campaign of a handful of videos gives the exposure only coarsely (7
videos: ±35 % of the interval); the estimate is reported with that
interval, and "unknown" when no switch lit a frame partly (the shutter is
then short, and how short the footage cannot tell). The LED timing never
relies on it: a switch no frame dated is placed in the widest gap the
footage allows (see :mod:`servoscope.markers.led_timing`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable

__all__ = ["ExposureEstimate", "estimate_exposure"]

_Z95 = 1.959963984540054


@dataclass(frozen=True)
class ExposureEstimate:
    """The exposure of a campaign's camera and where it came from.

    Attributes
    ----------
    value_s : float or None
        The exposure (s); None when unknown.
    stderr_s : float or None
        Its standard uncertainty (s); 0 when given.
    ci95_s : (float, float) or None
        95 % interval (s).
    source : str
        "given" (``[camera] exposure_s``), "LED" (partly lit frames at the
        switches) or "unknown".
    detail : str
        One line a person reads: the evidence.
    frame_interval_s : float or None
        The frame interval it is a share of.
    switches : int
        LED switches found (videos).
    partly_lit : int
        Of those, switches that lit a frame partly.
    """

    value_s: float | None
    stderr_s: float | None
    ci95_s: tuple[float, float] | None
    source: str
    detail: str
    frame_interval_s: float | None = None
    switches: int = 0
    partly_lit: int = 0

    @property
    def known(self) -> bool:
        return self.value_s is not None

    def summary(self) -> dict:
        """Plain types, for result.json."""
        return {
            "value_s": self.value_s,
            "stderr_s": self.stderr_s,
            "ci95_s": None if self.ci95_s is None else list(self.ci95_s),
            "fraction_of_frame_interval": (None if self.value_s is None or not self.frame_interval_s
                                           else self.value_s / self.frame_interval_s),
            "source": self.source,
            "detail": self.detail,
            "frame_interval_s": self.frame_interval_s,
            "led_switches": self.switches,
            "led_switches_partly_lit": self.partly_lit,
        }


def _wilson(k: int, n: int) -> tuple[float, float]:
    """The Wilson score 95 % interval of a binomial proportion k/n."""
    p = k / n
    z2 = _Z95**2
    centre = (p + z2 / (2 * n)) / (1 + z2 / n)
    half = _Z95 * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n)) / (1 + z2 / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def estimate_exposure(switches: Iterable[tuple[int, float]], given_s: float | None = None) -> ExposureEstimate:
    """Estimate the exposure from the LED switches of a campaign's videos.

    Parameters
    ----------
    switches : iterable of (partly_lit_frames, frame_interval_s)
        One per video whose LED switch was found: how many frames at the
        switch were partly lit (0, 1 or 2; see
        :attr:`servoscope.markers.led_timing.SwitchTime.partial_frames`) and
        the video's frame interval.
    given_s : float, optional
        The exposure the user gave (``[camera] exposure_s``): it wins.

    Returns
    -------
    ExposureEstimate
    """
    switches = [(int(k), float(p)) for k, p in switches if p and p > 0]
    period = None
    if switches:
        period = sorted(p for _, p in switches)[len(switches) // 2]
    n = len(switches)
    partly = sum(1 for k, _ in switches if k > 0)
    if given_s is not None:
        return ExposureEstimate(float(given_s), 0.0, (float(given_s), float(given_s)), "given",
                                "[camera] exposure_s", period, n, partly)
    if n == 0 or period is None:
        return ExposureEstimate(None, None, None, "unknown", "no LED switch found: nothing shows the shutter",
                                period, n, partly)
    low, high = _wilson(partly, n)
    if partly == 0:
        return ExposureEstimate(None, None, None, "unknown",
                                f"no LED switch of {n} lit a frame partly: a shutter shorter than the frame "
                                f"interval (≤ {high:.0%} of it, 95 %), how short the footage cannot tell",
                                period, n, partly)
    share = partly / n
    return ExposureEstimate(share * period, math.sqrt(share * (1 - share) / n) * period or (high - low) * period / 4,
                            (low * period, high * period), "LED",
                            f"{partly} of {n} LED switches lit a frame partly: exposure {share:.0%} of the frame "
                            f"interval (95 %: {low:.0%}–{high:.0%})", period, n, partly)
