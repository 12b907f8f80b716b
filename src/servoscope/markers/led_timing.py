"""When the LED switched: the input's start (t0), dated from the LED's level in each frame.

The rig switches the LED off at the instant the input starts. Each frame
integrates the LED's light over its exposure, so a frame whose exposure
straddles the switch is *partly lit*, and its level (0 dark … 1 lit) dates
the switch inside that exposure. A switch that falls *between* two
exposures (a shutter shorter than the frame interval) lights no frame
partly: the last lit and the first dark frame are both clean, and t0 is
only known to lie somewhere in the unexposed gap between them. t0 is then
uniform over that gap: its centre, with σ = gap/√12.

When the exposure is not known, nothing is assumed about it: a clean pair
of frames leaves t0 anywhere between the two frame times (the widest gap,
an instantaneous shutter), and one partly lit frame of level f leaves it
between the frame time and f − ½ frame intervals from it (what exposures
from nothing to the whole interval would give, widened by the level's
noise).

Times here are those of the middle of each frame's exposure (the
convention of :class:`~servoscope.markers.settings.TrackerSettings`'s
``timestamp`` is applied before, see :func:`exposure_middle_offset_s`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..defaults import TIMESTAMPS

__all__ = [
    "SwitchTime",
    "TIMESTAMP_CONVENTIONS",
    "exposure_middle_offset_s",
    "frame_period_s",
    "led_level_noise",
    "led_switch_time",
]

#: Where in its exposure a frame's timestamp lies, as a fraction of the exposure from its start:
#: what each of the choices (:data:`servoscope.defaults.TIMESTAMPS`, their one list) means.
TIMESTAMP_CONVENTIONS = {"middle": 0.5, "start": 0.0, "end": 1.0}

#: Bounds of the LED level's noise (in units of its lit − off step) used to tell a partly lit
#: frame from a lit or dark one: at least 0.3 % (8-bit luma of a 100 DN step quantizes to 1 %
#: per pixel; the disk's mean of dozens of pixels is finer). No ceiling: a noisier level
#: (lamp flicker on the unlit LED's housing: ±0.2 under 120 Hz lamps at 20 % depth) must widen
#: the band a partly lit frame has to clear, or noise is read as a partial frame and t0 lands
#: in the wrong frame (5.6 ms off, stated ±0.08 ms). LED_NOISE_CAP is only the level noise
#: assumed when too few settled frames measure it.
LED_NOISE_FLOOR = 0.003
LED_NOISE_CAP = 0.03


@dataclass(frozen=True)
class SwitchTime:
    """The LED's switch time and what the footage says about it.

    Attributes
    ----------
    t0_s : float
        Best estimate of the switch (s, on the exposures' middle clock).
    stderr_s : float
        Its standard uncertainty (s).
    earliest_s, latest_s : float
        The interval t0 can lie in: the unexposed gap (uniform) when no
        frame is partly lit, else ``t0_s ± 3·stderr_s``.
    how : str
        "partial" (one partly lit frame dates it), "end to end" (exposures
        that meet: frames k−1 and k together date it), "gap" (between two
        clean frames) or "partial, exposure unknown".
    partial_frames : int
        How many frames at the switch are partly lit (0, 1 or 2): the
        evidence the exposure estimate pools over a campaign.
    period_s : float
        The median frame interval.
    """

    t0_s: float
    stderr_s: float
    earliest_s: float
    latest_s: float
    how: str
    partial_frames: int
    period_s: float

    @property
    def uniform(self) -> bool:
        """True when t0 is uniform over [earliest_s, latest_s] (no frame dated it)."""
        return self.how in ("gap", "partial, exposure unknown")


def exposure_middle_offset_s(timestamp: str, exposure_s: float | None) -> float:
    """What to add to a frame's timestamp to get the middle of its exposure (s).

    Parameters
    ----------
    timestamp : {"middle", "start", "end"}
        Which point of the exposure the camera's frame times mark.
    exposure_s : float or None
        The exposure; None (unknown) gives 0: the offset is common to the
        LED and the markers, so phases and the dead time do not depend on
        it, only the absolute times do.
    """
    if timestamp not in TIMESTAMPS:
        raise ValueError(f"timestamp {timestamp!r}: use one of {', '.join(TIMESTAMPS)}")
    if exposure_s is None:
        return 0.0
    return (0.5 - TIMESTAMP_CONVENTIONS[timestamp]) * float(exposure_s)


def frame_period_s(time_s: np.ndarray) -> float:
    """The median frame interval (s); 0 for fewer than two frames."""
    return float(np.median(np.diff(time_s))) if np.size(time_s) > 1 else 0.0


#: Settled frames on each side of the switch whose median sets the lit and dark levels there.
LOCAL_LEVEL_FRAMES = 3


#: What measuring against the levels beside the switch does to the level's noise (see above).
LOCAL_LEVEL_NOISE_FACTOR = 1.45


def _local_levels(level: np.ndarray, k: int, noise: float) -> np.ndarray | None:
    """The levels rescaled so that the lit and dark frames next to the switch at ``k`` read 1 and 0; None when they do.

    The video's own 0 and 1 are its first and last frames'. What the LED's disk
    shows drifts: a camera that rolls or shakes, a blade that moves it across the
    pixel grid, lamps that dim. The switch is measured against the levels around
    it (the median of :data:`LOCAL_LEVEL_FRAMES` settled frames each side, not the
    frame next to the switch, which may be the partly lit one): a camera rolling
    ±0.5° at 3 Hz read the lit LED 2 % bright there and put t0 0.27 ms late,
    stated ±0.06 ms. Only when they differ from 1 and 0 by more than the median of
    three frames' noise allows (3 × 1.25σ/√3): steady footage is measured as before.
    """
    ok = np.isfinite(level)
    before = [j for j in range(k - 2, -1, -1) if ok[j]][:LOCAL_LEVEL_FRAMES]
    after = [j for j in range(k + 1, level.size) if ok[j]][:LOCAL_LEVEL_FRAMES]
    if len(before) < LOCAL_LEVEL_FRAMES or len(after) < LOCAL_LEVEL_FRAMES:
        return None
    on, off = float(np.median(level[before])), float(np.median(level[after]))
    allowed = 3.0 * 1.25 * noise / math.sqrt(LOCAL_LEVEL_FRAMES)
    if not on - off > 0.5 or (abs(on - 1.0) <= allowed and abs(off) <= allowed):
        return None
    return (level - off) / (on - off)


def led_level_noise(level: np.ndarray, k: int) -> float:
    """Robust standard deviation of the LED level in the settled frames away from the switch at ``k``.

    At least :data:`LED_NOISE_FLOOR`; :data:`LED_NOISE_CAP` when fewer than four frames
    measure it.
    """
    ok = np.isfinite(level)
    lit = level[: max(k - 1, 0)][ok[: max(k - 1, 0)]]
    dark = level[k + 1:][ok[k + 1:]]
    deviations = np.concatenate([lit - np.median(lit) if lit.size else lit,
                                 dark - np.median(dark) if dark.size else dark])
    if deviations.size < 4:
        return LED_NOISE_CAP
    # The standard deviation (2.7× as efficient as the MAD on Gaussian noise: a few dozen
    # frames give σ to ±10 %), of the frames within 5 MADs: a flicker or a passing
    # reflection must not widen it.
    mad = float(np.median(np.abs(deviations)) / 0.6745)
    kept = deviations[np.abs(deviations) <= 5.0 * mad] if mad > 0 else deviations
    sigma = float(np.sqrt(np.mean(kept**2)))
    return max(sigma, LED_NOISE_FLOOR)


def _dated(t0: float, sigma: float, how: str, partial: int, period: float) -> SwitchTime:
    return SwitchTime(t0, sigma, t0 - 3.0 * sigma, t0 + 3.0 * sigma, how, partial, period)


def _uniform(low: float, high: float, how: str, partial: int, period: float) -> SwitchTime:
    low, high = min(low, high), max(low, high)
    # Never exactly zero: the frame times themselves are known to a part in 10⁴ of a frame.
    sigma = max((high - low) / math.sqrt(12.0), 1e-4 * period)
    return SwitchTime(0.5 * (low + high), sigma, low, high, how, partial, period)


def led_switch_time(time_s: np.ndarray, level: np.ndarray,
                    exposure_s: float | None) -> tuple[SwitchTime | None, str | None]:
    """Sub-frame time at which a lit LED switches off, with its uncertainty.

    Parameters
    ----------
    time_s : ndarray
        Each frame's exposure-middle time (s).
    level : ndarray
        The LED's level per frame, 1 lit, 0 off (NaN where not measured).
    exposure_s : float or None
        The exposure (s), at most one frame interval; None when unknown.

    Returns
    -------
    (SwitchTime or None, str or None)
        The switch, or None with the reason it was not found.

    Notes
    -----
    With exposure window [t − e/2, t + e/2], a partly lit frame's level f
    gives t0 = t − e/2 + f·e, with the level's noise σ (measured on the
    settled frames) as e·σ. When the exposures are end to end (e = frame
    interval), the first dark frame k and the one before give
    t0 = t[k−1] − e/2 + (f[k−1] + f[k])·e (σ√2·e), wherever the switch fell.
    Otherwise a level is taken as partial when it is 3σ clear of both 0 and
    1; when no frame is, the switch fell between exposures or within 3σ·e of
    an exposure's edge: uniform over that interval (never zero: a switch in
    the last 3σ of an exposure looks like a whole lit frame).

    Assumes the LED's luma is linear in its lit fraction of the exposure
    (not clipped at white, no strong gamma).
    """
    ok = np.isfinite(level)
    if ok.sum() < 3:
        return None, "LED: too few frames to find its switch"
    lit = level > 0.5
    first_off = np.flatnonzero(ok & ~lit)
    if not lit[ok][0]:
        return None, "LED not lit in the first frame: no input start found"
    if first_off.size == 0:
        return None, "LED never switches off: no input start found"
    k = int(first_off[0])
    if k < 1:
        return None, "LED not lit in the first frame: no input start found"
    period = frame_period_s(time_s)
    noise = led_level_noise(level, k)
    local = _local_levels(level, k, noise)
    if local is not None:
        # Against levels measured on 3 frames a side: their own error (the median of 3,
        # 1.25σ/√3 each) enters every level; at most √2 more in t0's σ, stated.
        level = local
        noise = LOCAL_LEVEL_NOISE_FACTOR * max(noise, led_level_noise(level, k))
    band = 3.0 * noise
    t_before, t_after = float(time_s[k - 1]), float(time_s[k])
    regular = abs((t_after - t_before) - period) < 0.01 * period
    f_before, f_after = float(level[k - 1]), float(level[k])
    partial = [j for j, f in ((k - 1, f_before), (k, f_after)) if np.isfinite(f) and band < f < 1.0 - band]
    exposure = None if exposure_s is None else min(float(exposure_s), period)

    # (Two partly lit frames in a row, when the exposure is not known, say nothing of it:
    # exposures that meet light one frame partly and the next not at all; the second is
    # noise, a codec's smear or a clipped LED.)
    end_to_end = exposure is not None and exposure >= 0.999 * period
    if end_to_end and regular and np.isfinite(f_before) and np.isfinite(f_after):
        # Exposures end to end: the light of frames k−1 and k together is the time the LED
        # was lit after frame k−1's exposure began, wherever in the two the switch fell.
        # No threshold decides which frame is the partial one, so a noisy level cannot
        # send the estimate to the wrong frame.
        lit_s = float(np.clip(f_before + f_after, 0.0, 2.0)) * exposure
        sigma = math.hypot(math.sqrt(2.0) * noise * exposure, 1e-4 * period)
        return _dated(t_before - exposure / 2.0 + lit_s, sigma, "end to end", len(partial), period), None
    if partial:
        j = min(partial, key=lambda j: abs(level[j] - 0.5))
        f = float(np.clip(level[j], 0.0, 1.0))
        t_j = float(time_s[j])
        if exposure is not None and exposure > 0:
            sigma = math.hypot(noise * exposure, 1e-4 * period)
            return _dated(t_j - exposure / 2.0 + f * exposure, sigma, "partial", len(partial), period), None
        # Exposure unknown: t0 = t_j + (f − ½)·e for some e in (0, period], f within the
        # level's noise band of the one measured.
        low = t_j + min(0.0, f - 0.5 - band) * period
        high = t_j + max(0.0, f - 0.5 + band) * period
        return _uniform(low, high, "partial, exposure unknown", len(partial), period), None
    if exposure is None:
        # Unknown exposure, two clean frames: anywhere between the two frame times
        # (the gap of an instantaneous shutter contains every other's).
        return _uniform(t_before, t_after, "gap", 0, period), None
    # Between the end of frame k−1's exposure and the start of frame k's, widened by the band.
    low = t_before + exposure / 2.0 - band * exposure
    high = t_after - exposure / 2.0 + band * exposure
    return _uniform(low, high, "gap", 0, period), None
