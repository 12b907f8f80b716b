"""A signal's sine at a dwell's known frequency, against the input: the blade's heave per dwell (issue 18).

The heave (px) is not an angle and has no rigid-motion null channel or codec check, so it
gets the plain part of :func:`servoscope.sysid.fit_sine`: sin, cos and a level at the
input's frequency over the dwell's steady window, errors from the Newey–West covariance.
"""

from __future__ import annotations

import math

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..results import jsonable
from .hac import hac_covariance

__all__ = ["HEAVE_SYSTEMATIC_PX", "HeaveRow", "dwell_heave"]

#: Systematic uncertainty of a dwell's heave amplitude, px, added to the fit's: a rigid blade
#: (quick preset, 720×576, H.264, seed 3) showed 0.063 px at 1 Hz, 6 of the fit's standard
#: errors: the axis found on the step, the lens and the codec leave that much apparent heave.
HEAVE_SYSTEMATIC_PX = 0.05


@dataclass(frozen=True)
class HeaveRow:
    """One dwell's heave at its input frequency: gain (px per input unit) and phase against the input.

    Attributes
    ----------
    label : str
    frequency_hz : float
    gain, gain_stderr : float
        Heave amplitude over input amplitude, px per input unit.
    phase_deg, phase_stderr_deg : float
        Against the input's sine (0 before its start), degrees in (−180, 180].
    amplitude_px : float
    """

    label: str
    frequency_hz: float
    gain: float
    gain_stderr: float
    phase_deg: float
    phase_stderr_deg: float
    amplitude_px: float

    def summary(self) -> dict[str, Any]:
        """Plain types, a row of result.json's ``heave_response``."""
        return jsonable({"video": self.label, "frequency_hz": self.frequency_hz, "gain": self.gain,
                         "gain_stderr": self.gain_stderr, "phase_deg": self.phase_deg,
                         "phase_stderr_deg": self.phase_stderr_deg, "amplitude_px": self.amplitude_px,
                         "units": "px per input unit"})

    @classmethod
    def from_summary(cls, d: dict[str, Any]) -> "HeaveRow":
        return cls(d["video"], d["frequency_hz"], d["gain"], d["gain_stderr"], d["phase_deg"], d["phase_stderr_deg"],
                   d["amplitude_px"])


def dwell_heave(time_s: np.ndarray, heave: np.ndarray, frequency_hz: float, t0_s: float, amplitude: float,
                window_s: tuple[float, float], label: str = "") -> HeaveRow | None:
    """The heave's sine at ``frequency_hz`` in a dwell's steady window, by least squares with HAC errors.

    The errors include :data:`HEAVE_SYSTEMATIC_PX` (in phase as that much displacement
    across the amplitude); None with fewer than 10 samples in the window.
    """
    t, h = np.asarray(time_s, float), np.asarray(heave, float)
    inside = np.isfinite(h) & (t >= window_s[0]) & (t <= window_s[1])
    if np.count_nonzero(inside) < 10:
        return None
    w = 2.0 * math.pi * frequency_hz * (t[inside] - t0_s)
    design = np.column_stack([np.sin(w), np.cos(w), np.ones_like(w)])
    coef, *_ = np.linalg.lstsq(design, h[inside], rcond=None)
    cov = hac_covariance(design, h[inside] - design @ coef)
    a, b = float(coef[0]), float(coef[1])
    amp = math.hypot(a, b)
    if not amp > 0:
        return None
    # Amplitude and phase of a·sin + b·cos = amp·sin(w + φ), by the delta method.
    ga = np.array([a, b]) / amp
    gp = np.array([-b, a]) / amp**2
    c2 = cov[:2, :2]
    se_amp = math.hypot(math.sqrt(max(float(ga @ c2 @ ga), 0.0)), HEAVE_SYSTEMATIC_PX)
    se_phase = math.hypot(math.sqrt(max(float(gp @ c2 @ gp), 0.0)), HEAVE_SYSTEMATIC_PX / amp)
    return HeaveRow(label, float(frequency_hz), amp / abs(amplitude), se_amp / abs(amplitude),
                    math.degrees(math.atan2(b, a)), math.degrees(se_phase), amp)
