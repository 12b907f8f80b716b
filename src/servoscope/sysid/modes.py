"""The blade's structural modes, from its free motion after a step: a damped sinusoid fitted by least squares.

After the servo has settled, what still moves the blade is its own structure: a mode of
frequency f and damping ratio ζ rings down as ``A·exp(−ζ·2πf·t)·cos(2πf·√(1−ζ²)·t + φ) + c``.
:func:`fit_damped_mode` fits that to a signal (the blade's heave across its chord,
:func:`servoscope.angle.heave_px`) from a start time on, with scipy's ``curve_fit``,
started from the windowed signal's spectral peak; the standard errors come from its
covariance (residual-scaled, and widened by the residuals' lag-1 autocorrelation),
carried to f and ζ by the delta method, plus a systematic part
(:data:`MODE_SYSTEMATIC`, what a codec does to a sub-pixel ring-down).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import OptimizeWarning, curve_fit

from servoscope.results import jsonable

from .hac import hac_covariance

__all__ = ["ModeFit", "ModeShape", "fit_damped_mode", "fit_mode_shape", "pool_modes"]

#: A ring-down is taken as seen when its amplitude is this many times the signal's noise.
MIN_SNR = 10.0
#: Relative systematic uncertainty of a mode's frequency and damping ratio, added to the fit's:
#: what a codec and the tracker do to a sub-pixel ring-down. Measured on the twin's 9 Hz, 3 %
#: mode (quick preset, 480×384): raw −0.01…+0.03 % and +0.7…+1.3 %; H.264 at 20 Mbit/s −0.26 %
#: and +5 %, each several of the fit's own standard errors.
MODE_SYSTEMATIC = {"frequency": 0.004, "damping": 0.08}
_Z95 = 1.959963984540054
#: Largest damping ratio reported as a mode: a structure that rings for at least a cycle or two
#: (its amplitude falls by no more than 4x per cycle). A decaying drift of the heave that the
#: fit can also read as a sinusoid (seen on a rigid blade at 720×576, quick preset seed 3:
#: "13.4 Hz, ζ 0.88") is not a mode.
MAX_MODE_DAMPING = 0.2


@dataclass(frozen=True)
class ModeFit:
    """One structural mode: frequency, damping ratio, their uncertainties, where it was seen.

    Attributes
    ----------
    frequency_hz, frequency_stderr_hz : float
        Undamped natural frequency and its standard error.
    damping_ratio, damping_ratio_stderr : float
    amplitude : float
        The ring-down's amplitude at the window's start (the signal's units).
    source : str
        What it was fitted to (``"step"``).
    shape : ModeShape or None
        Which markers move in it and how (:func:`fit_mode_shape`); None with two markers.
    """

    frequency_hz: float
    frequency_stderr_hz: float
    damping_ratio: float
    damping_ratio_stderr: float
    amplitude: float
    source: str
    shape: "ModeShape | None" = None

    def summary(self) -> dict[str, Any]:
        """Plain types, for result.json's ``modes``."""
        return jsonable({
            "frequency_hz": self.frequency_hz, "damping_ratio": self.damping_ratio,
            "stderr": {"frequency_hz": self.frequency_stderr_hz, "damping_ratio": self.damping_ratio_stderr},
            "ci95": {"frequency_hz": [self.frequency_hz - _Z95 * self.frequency_stderr_hz,
                                      self.frequency_hz + _Z95 * self.frequency_stderr_hz],
                     "damping_ratio": [self.damping_ratio - _Z95 * self.damping_ratio_stderr,
                                       self.damping_ratio + _Z95 * self.damping_ratio_stderr]},
            "amplitude": self.amplitude, "source": self.source,
            **({"shape": self.shape.summary()} if self.shape is not None else {})})

    @classmethod
    def from_summary(cls, d: dict[str, Any]) -> "ModeFit":
        """The mode back from :meth:`summary`'s dict."""
        return cls(d["frequency_hz"], d["stderr"]["frequency_hz"], d["damping_ratio"], d["stderr"]["damping_ratio"],
                   d["amplitude"], d["source"], None if "shape" not in d else ModeShape.from_summary(d["shape"]))


@dataclass(frozen=True)
class ModeShape:
    """A mode's shape: each marker's ring-down amplitude across the chord line, and its phase against the first's.

    Attributes
    ----------
    markers, colours : tuple of str
        The markers' names (``lead``, ``trail``, ``extra1`` …) and colours.
    amplitude_px, amplitude_stderr_px : tuple of float
        Each marker's ring-down amplitude at the window's start (px).
    phase_deg, phase_stderr_deg : tuple of float
        Each marker's phase against the first marker's (degrees in (−180, 180]): 0 moves with
        it, 180 against it.
    """

    markers: tuple[str, ...]
    colours: tuple[str, ...]
    amplitude_px: tuple[float, ...]
    amplitude_stderr_px: tuple[float, ...]
    phase_deg: tuple[float, ...]
    phase_stderr_deg: tuple[float, ...]

    def relative(self) -> np.ndarray:
        """Each marker's signed amplitude over the first marker's (cos of the phase carries the sign)."""
        amp = np.asarray(self.amplitude_px)
        return amp * np.cos(np.radians(self.phase_deg)) / amp[0]

    def summary(self) -> list[dict[str, Any]]:
        """Plain types, a mode's ``shape`` in result.json: one entry per marker."""
        rel = self.relative()
        return jsonable([{"marker": m, "colour": c, "amplitude_px": a, "amplitude_stderr_px": sa,
                          "relative_amplitude": r, "phase_deg": p, "phase_stderr_deg": sp}
                         for m, c, a, sa, r, p, sp in zip(self.markers, self.colours, self.amplitude_px,
                                                          self.amplitude_stderr_px, rel, self.phase_deg,
                                                          self.phase_stderr_deg)])

    @classmethod
    def from_summary(cls, rows: list[dict[str, Any]]) -> "ModeShape":
        """The shape back from :meth:`summary`'s list."""
        return cls(*(tuple(r[k] for r in rows) for k in ("marker", "colour", "amplitude_px", "amplitude_stderr_px",
                                                          "phase_deg", "phase_stderr_deg")))


def fit_mode_shape(time_s: np.ndarray, signals: np.ndarray, start_s: float, mode: ModeFit,
                   markers: tuple[str, ...], colours: tuple[str, ...], *,
                   systematic_px: float = 0.0) -> ModeShape | None:
    """Each marker's share of a fitted mode: its signal's ring-down at the mode's frequency and damping.

    With the mode's frequency and damping held, each marker's signal (its distance across the
    chord line from where it rests, px) from ``start_s`` on is a linear least-squares fit of
    ``e^(−σt)·(a·cos ω_d t + b·sin ω_d t) + c``; its amplitude and phase by the delta method from
    the Newey–West covariance, plus ``systematic_px`` in amplitude (and that much displacement
    in phase). Phases are against the first marker's. None with fewer than 20 samples.
    """
    t = np.asarray(time_s, dtype=float)
    y = np.asarray(signals, dtype=float)
    keep = np.isfinite(t) & (t >= start_s) & np.all(np.isfinite(y), axis=1)
    if np.count_nonzero(keep) < 20:
        return None
    tt = t[keep] - start_s
    wn = 2.0 * math.pi * mode.frequency_hz
    sigma, wd = mode.damping_ratio * wn, wn * math.sqrt(max(1.0 - mode.damping_ratio**2, 0.0))
    env = np.exp(-sigma * tt)
    design = np.column_stack([env * np.cos(wd * tt), env * np.sin(wd * tt), np.ones_like(tt)])
    amps, amp_se, phases, phase_se = [], [], [], []
    for k in range(y.shape[1]):
        v = y[keep, k]
        coef, *_ = np.linalg.lstsq(design, v, rcond=None)
        cov = hac_covariance(design, v - design @ coef)[:2, :2]
        a, b = float(coef[0]), float(coef[1])
        amp = math.hypot(a, b)
        amp = max(amp, 1e-12)
        # a·cos + b·sin = amp·cos(ω_d t + φ) with φ = atan2(−b, a).
        ga = np.array([a, b]) / amp
        gp = np.array([b, -a]) / amp**2
        amps.append(amp)
        amp_se.append(math.hypot(math.sqrt(max(float(ga @ cov @ ga), 0.0)), systematic_px))
        phases.append(math.atan2(-b, a))
        phase_se.append(math.hypot(math.sqrt(max(float(gp @ cov @ gp), 0.0)), systematic_px / amp))
    rel = [math.degrees(math.remainder(p - phases[0], 2.0 * math.pi)) for p in phases]
    # The first marker's phase is the reference: the others' errors carry its error too.
    rel_se = [0.0] + [math.degrees(math.hypot(s, phase_se[0])) for s in phase_se[1:]]
    return ModeShape(tuple(markers), tuple(colours), tuple(amps), tuple(amp_se), tuple(rel), tuple(rel_se))


def _ringdown(t, a, sigma, wd, phi, c):
    return a * np.exp(-sigma * t) * np.cos(wd * t + phi) + c


def fit_damped_mode(time_s: np.ndarray, y: np.ndarray, start_s: float, *, noise: float | None = None,
                    source: str = "step", forced_hz: float | None = None) -> ModeFit | None:
    """Fit a ring-down to ``y`` from ``start_s`` on; None when there is none to see.

    Parameters
    ----------
    time_s, y : ndarray
        The signal (NaN where not measured).
    start_s : float
        Where the free motion starts (after the servo has settled).
    noise : float, optional
        The signal's noise (its units); a ring-down of less than :data:`MIN_SNR` times it
        is not fitted. Default: from the fit's own residual.
    source : str
        Recorded with the mode.
    forced_hz : float, optional
        A sine dwell's frequency: the forced motion there (a sine of any amplitude and phase)
        is fitted beside the ring-down, and the spectral peak looked for away from it.

    Returns
    -------
    ModeFit or None
    """
    t, v = np.asarray(time_s, dtype=float), np.asarray(y, dtype=float)
    keep = np.isfinite(t) & np.isfinite(v) & (t >= start_s)
    if np.count_nonzero(keep) < 20:
        return None
    t, v = t[keep] - start_s, v[keep]
    dt = float(np.median(np.diff(t)))
    # The spectral peak of the window (mean removed, zero-padded 16x) starts the frequency.
    x = v - v.mean()
    forced = None
    if forced_hz is not None:
        wf = 2.0 * math.pi * forced_hz
        forced = np.column_stack([np.sin(wf * t), np.cos(wf * t)])
        b = np.linalg.lstsq(np.column_stack([forced, np.ones_like(t)]), v, rcond=None)[0]
        x = v - forced @ b[:2] - b[2]
    spectrum = np.abs(np.fft.rfft(x * np.hanning(x.size), 16 * x.size))
    freqs = np.fft.rfftfreq(16 * x.size, dt)
    spectrum[freqs < 2.0 / (t[-1] + dt)] = 0.0  # at least two cycles in the window
    if forced_hz is not None:
        spectrum[np.abs(freqs - forced_hz) < 1.5 / (t[-1] + dt)] = 0.0  # the forced line's own width
    f0 = float(freqs[int(np.argmax(spectrum))])
    if not f0 > 0:
        return None
    w0 = 2.0 * math.pi * f0
    a0 = float(np.max(np.abs(x[: max(3, int(round(1.0 / (f0 * dt))))])))
    p0 = [a0, 0.03 * w0, w0, 0.0, float(v.mean())]
    if forced is None:
        model = _ringdown
    else:
        def model(tt, a, sigma, wd, phi, c, bs, bc):
            return _ringdown(tt, a, sigma, wd, phi, c) + bs * np.sin(wf * tt) + bc * np.cos(wf * tt)
        p0 += [float(b[0]), float(b[1])]
    try:
        # A fit that wanders (a growing exponential overflows) or whose covariance cannot be estimated
        # is refused below (σ > 0, finite residual and covariance): no warning on the way.
        with warnings.catch_warnings(), np.errstate(over="ignore", invalid="ignore"):
            warnings.simplefilter("ignore", OptimizeWarning)
            popt, pcov = curve_fit(model, t, v, p0=p0, maxfev=20000)
            residual = v - model(t, *popt)
    except (RuntimeError, ValueError):
        return None
    a, sigma, wd = popt[:3]
    if not np.all(np.isfinite(residual)):
        return None
    scatter = float(np.std(residual))
    if abs(a) < MIN_SNR * max(scatter, noise or 0.0) or not (wd > 0 and sigma > 0) or not np.all(np.isfinite(pcov)):
        return None
    # Residuals that follow each other (tracking errors, what is left of the servo's forced
    # motion) carry less information than white ones: the covariance grows by the AR(1)
    # factor (1 + ρ)/(1 − ρ) of their lag-1 autocorrelation ρ (≥ 0).
    r = residual - residual.mean()
    rho = float(r[1:] @ r[:-1]) / float(r @ r) if float(r @ r) > 0 else 0.0
    rho = min(max(rho, 0.0), 0.95)
    pcov = pcov * (1.0 + rho) / (1.0 - rho)
    wn = math.hypot(wd, sigma)
    # Delta method: f = hypot(wd, σ)/2π, ζ = σ / hypot(wd, σ).
    jf = np.array([wd, sigma]) / (wn * 2.0 * math.pi)  # d f / d(wd, σ)... ordered (σ, wd) below
    cov = pcov[np.ix_([1, 2], [1, 2])]  # (σ, wd)
    g_f = np.array([jf[1], jf[0]])
    g_z = np.array([wd**2 / wn**3, -sigma * wd / wn**3])
    f, z = wn / (2.0 * math.pi), sigma / wn
    if z > MAX_MODE_DAMPING:
        return None
    se_f = math.hypot(math.sqrt(max(float(g_f @ cov @ g_f), 0.0)), MODE_SYSTEMATIC["frequency"] * f)
    se_z = math.hypot(math.sqrt(max(float(g_z @ cov @ g_z), 0.0)), MODE_SYSTEMATIC["damping"] * z)
    return ModeFit(f, se_f, z, se_z, float(abs(a)), source)


def pool_modes(modes: list[ModeFit], source: str) -> ModeFit | None:
    """One mode from several fits of it (each dwell's ring-down): inverse-variance means.

    The systematic part (:data:`MODE_SYSTEMATIC`) is common to every fit, so it is taken off
    before pooling and added once after; fits that disagree beyond their errors (χ² over
    its degrees of freedom above 1) widen the pooled error by its square root. None when
    ``modes`` is empty.
    """
    if not modes:
        return None
    out = {}
    for key, value_of, se_of in (("frequency", lambda m: m.frequency_hz, lambda m: m.frequency_stderr_hz),
                                 ("damping", lambda m: m.damping_ratio, lambda m: m.damping_ratio_stderr)):
        v = np.array([value_of(m) for m in modes], dtype=float)
        se = np.array([se_of(m) for m in modes], dtype=float)
        stat = np.sqrt(np.maximum(se**2 - (MODE_SYSTEMATIC[key] * v) ** 2, (1e-3 * se) ** 2))
        w = 1.0 / stat**2
        mean = float(np.sum(w * v) / np.sum(w))
        pooled = math.sqrt(1.0 / float(np.sum(w)))
        if v.size > 1:
            chi2 = float(np.sum(w * (v - mean) ** 2)) / (v.size - 1)
            pooled *= math.sqrt(max(chi2, 1.0))
        out[key] = (mean, math.hypot(pooled, MODE_SYSTEMATIC[key] * mean))
    amplitude = max(m.amplitude for m in modes)
    return ModeFit(out["frequency"][0], out["frequency"][1], out["damping"][0], out["damping"][1], amplitude, source)
