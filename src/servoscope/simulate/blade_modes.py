"""The blade's flapping modes in the twin: their list, their shape along the chord, their heave."""

from __future__ import annotations

import math
from collections.abc import Callable

import control
import numpy as np

from .presets import CampaignPreset
from .scene import Scene
from .servo import InputSignal

__all__ = ["blade_modes_of", "shape_along_chord", "mode_shape", "mode_heaves_px", "steady_heave"]


def blade_modes_of(preset: CampaignPreset) -> list[tuple[float, float, float, float]]:
    """The blade's modes as ``(frequency_hz, damping_ratio, px_per_rad, bend)``: none, one or two."""
    if preset.blade_mode_hz <= 0:
        return []
    first = (preset.blade_mode_hz, preset.blade_mode_damping, preset.blade_mode_px_per_rad, preset.blade_mode_bend)
    return [first] + ([tuple(preset.blade_mode2)] if preset.blade_mode2 is not None else [])


def shape_along_chord(scene: Scene, bend: float) -> Callable[[np.ndarray], np.ndarray]:
    """A blade mode's share of its heave at chord coordinate u (blade frame, px).

    ``1 − 4·bend·f·(1 − f)``, f the place's position from the trail sticker (0) to the lead (1)
    along the chord: the lead and trail stickers move with the heave, the blade between them
    less (``bend`` > 0), beyond them more.
    """
    lead, trail = scene.sticker_centres_uv()

    def share(u: np.ndarray) -> np.ndarray:
        f = (np.asarray(u, dtype=np.float64) - trail[0]) / (lead[0] - trail[0])
        return 1.0 - 4.0 * bend * f * (1.0 - f)
    return share


def mode_shape(scene: Scene, bend: float) -> tuple[float, ...]:
    """A blade mode's share of its heave at each sticker's centre: lead, trail, then the extra stickers."""
    share = shape_along_chord(scene, bend)
    centres = [*scene.sticker_centres_uv(), *scene.extra_centres_uv()]
    return tuple(float(share(np.array([c[0]]))[0]) for c in centres)


def mode_heaves_px(preset: CampaignPreset, signal: InputSignal, time_s: np.ndarray) -> np.ndarray:
    """Each mode's heave (px, up positive) at each frame, shape (modes, frames): driven by the pitch's acceleration.

    ``Q(s)/Θ(s) = −κ s² / (s² + 2ζω s + ω²)`` per mode, simulated with python-control on a grid
    20× finer than the frames (the mode's period is a handful of frames), from rest; shape (0,
    frames) for a rigid blade.

    Averaged over each frame's exposure [t − e/2, t + e/2] (Gauss–Legendre, as the pitch is,
    :func:`~servoscope.simulate.campaign.exposure_averaged_response`): the sensor integrates the
    moving stickers, their heave as much as their turn. (An instantaneous heave beside an averaged
    pitch once made heave/pitch read sinc(f·e)⁻¹ high: κ 1.8 % at 100 frames/s and a full shutter.)
    """
    modes = blade_modes_of(preset)
    if not modes or time_s.size == 0:
        return np.zeros((len(modes), time_s.size))
    e = float(preset.exposure_s or 0.0)
    fine = np.linspace(0.0, float(time_s[-1]) + e, 20 * time_s.size + 1)
    pitch = preset.servo.response(signal, fine)
    nodes, weights = np.polynomial.legendre.leggauss(12)
    at = (np.asarray(time_s, float)[:, None] + 0.5 * e * nodes[None, :]) if e > 0 else np.asarray(time_s, float)[:, None]
    w_avg = 0.5 * weights if e > 0 else np.ones(1)
    out = []
    for hz, z, k, _ in modes:
        w = 2.0 * math.pi * hz
        q = control.forced_response(control.tf([-k, 0.0, 0.0], [1.0, 2.0 * z * w, w * w]), fine, pitch - pitch[0])
        # Before the first fine sample the blade is at rest (np.interp holds the first value, 0).
        out.append(np.interp(at, fine, np.asarray(q.outputs, dtype=float)) @ w_avg)
    return np.array(out)


def steady_heave(preset: CampaignPreset, frequency_hz: float) -> complex:
    """The blade's steady heave at ``frequency_hz`` against the input, px per input unit (complex: its phase
    against the input's sine): each mode's ``κ·ω²/(ωm² − ω² + 2jζ·ωm·ω)`` times the servo's linear response
    with its dead time. The instantaneous heave, not averaged over an exposure: the blade's, not the frames'."""
    w = 2.0 * math.pi * float(frequency_hz)
    servo = preset.servo
    pitch = np.polyval(servo.num, 1j * w) / np.polyval(servo.den, 1j * w) * np.exp(-1j * w * servo.dead_time_s)
    ratio = sum(k * w * w / ((2.0 * math.pi * hz) ** 2 - w * w + 2j * z * 2.0 * math.pi * hz * w)
                for hz, z, k, _ in blade_modes_of(preset))
    return complex(ratio * pitch)
