"""Amplitude as a test axis: does the gain at one frequency depend on the input's amplitude?

A linear servo's gain at a frequency is the same at every amplitude. A rate limit
lowers it at large amplitudes (the output cannot follow), backlash and a command's
quantization at small ones (part of the motion is lost in the dead band or a step):
the paper assumed linearity and kept the linear model "for acceptable accuracy".
Dwells at one frequency and several amplitudes test it: their gains, each with its
standard error and a systematic part (a small swing's tracking errors do not
average out), are compared by a χ² test of equality (a weighted mean and the
scatter about it); a p-value below :data:`NONLINEAR_P` says the gain changes with
the amplitude beyond what the measurements' errors allow.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.stats import chi2 as chi2_dist

from servoscope.results import jsonable
from servoscope.sysid.frequency_response import FrequencyResponse

__all__ = ["NONLINEAR_P", "AmplitudeCheck", "gain_against_amplitude"]

#: Below this p-value the gains at one frequency differ by more than their errors allow.
NONLINEAR_P = 1e-3
#: Frequencies closer than this (relative) count as one.
_SAME_FREQUENCY = 1e-3


@dataclass(frozen=True)
class AmplitudeCheck:
    """The gains of one frequency's dwells against their input amplitudes.

    Attributes
    ----------
    frequency_hz : float
    amplitudes : tuple of float
        Input amplitudes (input units), ascending.
    gains, gain_stderrs : tuple of float
        Each dwell's gain (output per input unit) and its standard error (with its
        systematic part, see :func:`gain_against_amplitude`).
    labels : tuple of str
    change : float
        Gain at the largest amplitude over the gain at the smallest, less 1.
    chi2 : float
        Σ ((gain − weighted mean)/stderr)², with ``len(gains) − 1`` degrees of freedom.
    p_value : float
        The probability of so large a χ² if the gain did not depend on the amplitude.
    """

    frequency_hz: float
    amplitudes: tuple[float, ...]
    gains: tuple[float, ...]
    gain_stderrs: tuple[float, ...]
    labels: tuple[str, ...]
    change: float
    chi2: float
    p_value: float

    @property
    def linear(self) -> bool:
        """Whether the gains agree within their errors (p ≥ :data:`NONLINEAR_P`)."""
        return not (self.p_value < NONLINEAR_P)

    def summary(self) -> dict[str, Any]:
        """Plain types, for result.json."""
        return jsonable({"frequency_hz": self.frequency_hz, "amplitudes": list(self.amplitudes),
                         "gains": list(self.gains), "gain_stderrs": list(self.gain_stderrs),
                         "labels": list(self.labels), "change": self.change, "chi2": self.chi2,
                         "p_value": self.p_value, "linear": self.linear})

    @classmethod
    def from_summary(cls, data: dict[str, Any]) -> "AmplitudeCheck":
        """Rebuild a check from its :meth:`summary`."""
        nan = (lambda v: math.nan if v is None else float(v))
        return cls(float(data["frequency_hz"]), tuple(data["amplitudes"]), tuple(data["gains"]),
                   tuple(data["gain_stderrs"]), tuple(data["labels"]), nan(data.get("change")), nan(data.get("chi2")),
                   nan(data.get("p_value")))

    def warning(self) -> str | None:
        """One line when the gain changes with the amplitude; None when it does not."""
        if self.linear:
            return None
        return (f"gain changes with the input amplitude at {self.frequency_hz:.3g} Hz: {100 * self.change:+.1f} % from "
                f"{self.amplitudes[0]:g} to {self.amplitudes[-1]:g} (p = {self.p_value:.1e}): the servo is not linear "
                "there (a rate limit lowers it at large amplitudes; backlash or a quantized command at small ones); "
                "a linear model describes one amplitude at a time")


def gain_against_amplitude(fr: FrequencyResponse, amplitudes, systematic=None) -> list[AmplitudeCheck]:
    """Every frequency measured at two or more amplitudes, its gains compared.

    Parameters
    ----------
    fr : FrequencyResponse
        The dwells' response (gains per input unit).
    amplitudes : array_like
        Each dwell's input amplitude, in ``fr``'s order.
    systematic : array_like, optional
        Each dwell's relative systematic error of its gain, added to its standard
        error in quadrature: a small swing's tracking errors do not average out
        (the twin's linear servo at 12 Hz read its 0.16° swing 1 % larger than its
        0.63° one, 6 standard errors of the fit). The campaign gives each dwell its
        track's measured angle noise over its output amplitude.

    Returns
    -------
    list of AmplitudeCheck
        One per such frequency, ascending; empty when every frequency has one amplitude.
    """
    amps = np.asarray(amplitudes, dtype=float)
    f = np.asarray(fr.frequency_hz, dtype=float)
    rel = np.zeros(f.size) if systematic is None else np.nan_to_num(np.asarray(systematic, dtype=float))
    stderr = np.hypot(fr.gain_stderr, rel * fr.gain)
    ok = np.isfinite(f) & np.isfinite(fr.gain) & (stderr > 0) & np.isfinite(amps)
    out: list[AmplitudeCheck] = []
    done = np.zeros(f.size, dtype=bool)
    for i in np.argsort(f, kind="stable"):
        if done[i] or not ok[i]:
            continue
        group = np.flatnonzero(ok & ~done & (np.abs(f - f[i]) <= _SAME_FREQUENCY * f[i]))
        done[group] = True
        if np.unique(amps[group]).size < 2:
            continue
        group = group[np.argsort(amps[group], kind="stable")]
        g, se = fr.gain[group], stderr[group]
        w = 1.0 / se**2
        mean = float(np.sum(w * g) / np.sum(w))
        chi2 = float(np.sum(((g - mean) / se) ** 2))
        dof = group.size - 1
        out.append(AmplitudeCheck(float(np.mean(f[group])), tuple(float(a) for a in amps[group]),
                                  tuple(float(v) for v in g), tuple(float(v) for v in se),
                                  tuple(fr.labels[k] for k in group), float(g[-1] / g[0] - 1.0), chi2,
                                  float(chi2_dist.sf(chi2, dof)) if dof > 0 else math.nan))
    return out
