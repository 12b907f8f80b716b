"""A pilot's frequency sweep, as the twin records it (issue 31): the input of a ``piloted_sweep`` test.

A pilot sweeping a stick by hand follows a chirp only roughly: the frequency rises from the
lowest to the highest in the time given but wanders about that law, and the swing grows and
shrinks as the hand tires and corrects. :func:`pilot_input` makes such an input, seeded, sampled
at 1 kHz (a transmitter's log of the stick); the twin writes it as the test's ``u.csv``
(:func:`servoscope.campaign.recorded_input.write_input_file`) and drives its servo with the
samples (:class:`~servoscope.simulate.InputSignal` ``kind="recorded"``).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..campaign.recorded_input import write_input_file
from ..errors import ServoscopeError

__all__ = ["PILOT_FILE", "PILOT_RATE_HZ", "pilot_input", "record_pilot"]

#: The piloted sweep's recorded input, beside its video (``input = "u.csv"``).
PILOT_FILE = "u.csv"

#: How often the pilot's stick is logged, Hz.
PILOT_RATE_HZ = 1000.0
#: How far the frequency wanders about the chirp's law (log-ratio's standard deviation) and the swing
#: about its mean (relative standard deviation): a steady hand, not a machine.
_FREQUENCY_WANDER = 0.12
_AMPLITUDE_WANDER = 0.2
#: The swing fades in and out over this long (s, at most a tenth of the sweep): the stick starts and ends centred.
_FADE_S = 0.5


def _wander(rng: np.random.Generator, t: np.ndarray, duration_s: float) -> np.ndarray:
    """A smooth random wander of unit standard deviation: four slow sines (2 to 12 cycles over the sweep)."""
    cycles = rng.uniform(2.0, 12.0, 4)
    phases = rng.uniform(0.0, 2.0 * math.pi, 4)
    w = np.sin(2.0 * math.pi * np.outer(t, cycles / duration_s) + phases).sum(axis=1)
    return w / math.sqrt(2.0)  # four unit sines: variance 4 · 1/2


def pilot_input(from_hz: float, to_hz: float, duration_s: float, amplitude: float, seed: int
                ) -> tuple[np.ndarray, np.ndarray]:
    """A pilot-like sweep: ``(time_s, command)`` sampled at :data:`PILOT_RATE_HZ` from 0 to ``duration_s``.

    The frequency follows the log chirp from ``from_hz`` to ``to_hz`` times ``exp(0.12·w₁(t))``
    (kept inside the band), the swing is ``amplitude·(1 + 0.2·w₂(t))`` faded in and out by
    half-cosines of 0.5 s (a tenth of the sweep at most); ``w₁``, ``w₂`` are slow random
    wanders drawn from ``seed``. The command is 0 at the start (the LED's switch) and at the end.

    Parameters
    ----------
    from_hz, to_hz : float
        The band the pilot sweeps, Hz (``0 < from_hz < to_hz``).
    duration_s : float
        How long, s.
    amplitude : float
        The mean swing, input units.
    seed : int
        Seed of the wanders.

    Returns
    -------
    time_s, command : ndarray
    """
    if not (0 < from_hz < to_hz and duration_s > 0 and amplitude > 0):
        raise ServoscopeError(f"a piloted sweep needs 0 < from_hz < to_hz, duration_s > 0 and amplitude > 0 (got "
                              f"{from_hz!r}, {to_hz!r}, {duration_s!r}, {amplitude!r})")
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * PILOT_RATE_HZ)) + 1
    t = np.arange(n) / PILOT_RATE_HZ
    law = from_hz * (to_hz / from_hz) ** (t / duration_s)
    f = np.clip(law * np.exp(_FREQUENCY_WANDER * _wander(rng, t, duration_s)), from_hz, to_hz)
    # The phase is the frequency's integral (trapezoids): the stick never jumps.
    phase = 2.0 * math.pi * np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) / PILOT_RATE_HZ)])
    swing = amplitude * np.clip(1.0 + _AMPLITUDE_WANDER * _wander(rng, t, duration_s), 0.3, None)
    fade = min(_FADE_S, 0.1 * duration_s)
    edge = np.clip(np.minimum(t, t[-1] - t) / fade, 0.0, 1.0)
    return t, swing * 0.5 * (1.0 - np.cos(math.pi * edge)) * np.sin(phase)


def record_pilot(folder: Path, band: tuple[float, float, float], samples: tuple[np.ndarray, np.ndarray]) -> dict:
    """Write the piloted sweep's samples to :data:`PILOT_FILE` in ``folder``; its test's truth, as a sweep's.

    Returns ``kind`` "sweep", ``input`` (the file's name), and the band the pilot swept
    (``from_hz``, ``to_hz``, ``duration_s``).
    """
    write_input_file(Path(folder) / PILOT_FILE, *samples)
    return {"kind": "sweep", "input": PILOT_FILE, "from_hz": band[0], "to_hz": band[1], "duration_s": band[2]}
