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

from servoscope.parameters import FitResult, Parameter, Parameters, interval95, inverse_variance_mean
from servoscope.results import jsonable

from .hac import hac_covariance

__all__ = ["MODE_SOURCES", "ModeFit", "ModeShape", "fit_damped_mode", "fit_damped_modes", "fit_mode_shape", "fit_mode_shapes",
           "pool_modes", "ringdown_columns"]

#: A ring-down is taken as seen when its amplitude is this many times the signal's noise.
MIN_SNR = 10.0
#: Relative systematic uncertainty of a mode's frequency and damping ratio, added to the fit's:
#: what a codec and the tracker do to a sub-pixel ring-down. Measured on the twin's 9 Hz, 3 %
#: mode (quick preset, 480×384): raw −0.01…+0.03 % and +0.7…+1.3 %; H.264 at 20 Mbit/s −0.26 %
#: and +5 %, each several of the fit's own standard errors.
MODE_SYSTEMATIC = {"frequency": 0.004, "damping": 0.08}
#: Largest damping ratio reported as a mode: a structure that rings for at least a cycle or two
#: (its amplitude falls by no more than 4x per cycle). A decaying drift of the heave that the
#: fit can also read as a sinusoid (seen on a rigid blade at 720×576, quick preset seed 3:
#: "13.4 Hz, ζ 0.88") is not a mode.
MAX_MODE_DAMPING = 0.2
#: Where a mode was seen (:attr:`ModeFit.source`), in words for tables and reports.
MODE_SOURCES = {"step": "the step's ring-down", "dwells": "the dwells' ring-downs",
                "heave_response": "the heave's frequency response", "heave_traces": "the heave's whole traces",
                "held": "held at the step's"}


@dataclass(frozen=True)
class ModeFit(FitResult):
    """One structural mode: frequency, damping ratio, their uncertainties, where it was seen.

    A :class:`~servoscope.parameters.FitResult`: :attr:`parameters` holds ``frequency_hz`` and
    ``damping_ratio``, each with a log-normal 95 % interval (both are positive, their errors
    relative: the damping ratio's is 8 % or more, and a symmetric interval would reach below
    zero), from which ``fit_report()``, ``to_pandas()`` and the notebook's table are made.

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

    @property
    def model_name(self) -> str:  # type: ignore[override]
        return f"damped mode A·exp(−ζ·2πf·t)·cos(2πf·√(1−ζ²)·t + φ) + c ({self.source})"

    def resonates_at(self, frequency_hz: float) -> bool:
        """Whether ``frequency_hz`` lies within this mode's resonance: within 3ζ + 2 % of its frequency, where a
        dwell's forced motion and the mode's own are one (the dwells' ring-downs leave it out, the runner warns,
        the heave there is measured from the settling or is the model's)."""
        return abs(frequency_hz / self.frequency_hz - 1.0) < 3.0 * self.damping_ratio + 0.02

    @property
    def parameters(self) -> Parameters:
        """``frequency_hz`` (Hz) and ``damping_ratio``, their 95 % intervals log-normal (never below zero).

        A mode held at another's (source ``"held"``) has them fixed, its errors NaN as it has them.
        """
        held = self.source == "held"
        return Parameters(
            Parameter(name, float(value), float(se), interval95(value, se, "lognormal"), vary=not held, min=0.0,
                      unit=unit, interval="lognormal")
            for name, value, se, unit in (("frequency_hz", self.frequency_hz, self.frequency_stderr_hz, "Hz"),
                                          ("damping_ratio", self.damping_ratio, self.damping_ratio_stderr, "")))

    def fit_statistics(self) -> dict[str, Any]:
        """Where the mode was seen and its ring-down's amplitude (the signal's units)."""
        return {"source": self.source, "amplitude": float(self.amplitude)}

    @property
    def ci95(self) -> dict[str, tuple[float, float]]:
        """95 % intervals (log-normal, from the standard errors) of ``frequency_hz`` and ``damping_ratio``."""
        return {name: p.ci95 for name, p in self.parameters.items()}

    def summary(self) -> dict[str, Any]:
        """Plain types, for result.json's ``modes``."""
        return jsonable({
            "frequency_hz": self.frequency_hz, "damping_ratio": self.damping_ratio,
            "stderr": {"frequency_hz": self.frequency_stderr_hz, "damping_ratio": self.damping_ratio_stderr},
            "ci95": {k: list(v) for k, v in self.ci95.items()},
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


def ringdown_columns(t: np.ndarray, frequency_hz: float, damping_ratio: float) -> tuple[np.ndarray, np.ndarray]:
    """A mode's two free-decay columns at times ``t`` from its start: ``e^(−σt)·cos ω_d t`` and ``e^(−σt)·sin ω_d t``.

    σ = ζ·ωn and ω_d = ωn·√(1 − ζ²), ωn = 2π·``frequency_hz``: the basis in which a ring-down of
    any amplitude and phase is linear (mode shapes, a dwell's heave beside its sine).
    """
    wn = 2.0 * math.pi * frequency_hz
    sigma, wd = damping_ratio * wn, wn * math.sqrt(max(1.0 - damping_ratio**2, 0.0))
    env = np.exp(-sigma * t)
    return env * np.cos(wd * t), env * np.sin(wd * t)


def fit_mode_shape(time_s: np.ndarray, signals: np.ndarray, start_s: float, mode: ModeFit,
                   markers: tuple[str, ...], colours: tuple[str, ...], *,
                   systematic_px: float = 0.0) -> ModeShape | None:
    """One mode's shape across the markers: :func:`fit_mode_shapes` with that mode alone."""
    shapes = fit_mode_shapes(time_s, signals, start_s, [mode], markers, colours, systematic_px=systematic_px)
    return shapes[0] if shapes else None


def fit_mode_shapes(time_s: np.ndarray, signals: np.ndarray, start_s: float, modes: list[ModeFit],
                    markers: tuple[str, ...], colours: tuple[str, ...], *,
                    systematic_px: float = 0.0) -> list[ModeShape]:
    """Each marker's share of each fitted mode: its signal's ring-downs at the modes' frequencies and dampings.

    With the modes' frequencies and dampings held, each marker's signal (its distance across the
    chord line from where it rests, px) from ``start_s`` on is a linear least-squares fit of
    ``Σⱼ e^(−σⱼt)·(aⱼ·cos ωⱼt + bⱼ·sin ωⱼt) + c`` (all modes together: one's ring-down is not read
    as another's); each amplitude and phase by the delta method from the Newey–West covariance,
    plus ``systematic_px`` in amplitude (and that much displacement in phase). Phases are
    against the first marker's. One shape per mode; empty with fewer than 20 samples.
    """
    t = np.asarray(time_s, dtype=float)
    y = np.asarray(signals, dtype=float)
    keep = np.isfinite(t) & (t >= start_s) & np.all(np.isfinite(y), axis=1)
    if np.count_nonzero(keep) < 20 or not modes:
        return []
    tt = t[keep] - start_s
    columns = []
    for mode in modes:
        columns += ringdown_columns(tt, mode.frequency_hz, mode.damping_ratio)
    design = np.column_stack(columns + [np.ones_like(tt)])
    amps = np.zeros((len(modes), y.shape[1]))
    amp_se, phases, phase_se = np.zeros_like(amps), np.zeros_like(amps), np.zeros_like(amps)
    for k in range(y.shape[1]):
        v = y[keep, k]
        coef, *_ = np.linalg.lstsq(design, v, rcond=None)
        cov_all = hac_covariance(design, v - design @ coef)
        for j in range(len(modes)):
            a, b = float(coef[2 * j]), float(coef[2 * j + 1])
            cov = cov_all[2 * j:2 * j + 2, 2 * j:2 * j + 2]
            amp = max(math.hypot(a, b), 1e-12)
            # a·cos + b·sin = amp·cos(ω_d t + φ) with φ = atan2(−b, a).
            ga = np.array([a, b]) / amp
            gp = np.array([b, -a]) / amp**2
            amps[j, k] = amp
            amp_se[j, k] = math.hypot(math.sqrt(max(float(ga @ cov @ ga), 0.0)), systematic_px)
            phases[j, k] = math.atan2(-b, a)
            phase_se[j, k] = math.hypot(math.sqrt(max(float(gp @ cov @ gp), 0.0)), systematic_px / amp)
    shapes = []
    for j in range(len(modes)):
        rel = [math.degrees(math.remainder(p - phases[j, 0], 2.0 * math.pi)) for p in phases[j]]
        # The first marker's phase is the reference: the others' errors carry its error too.
        rel_se = [0.0] + [math.degrees(math.hypot(e, phase_se[j, 0])) for e in phase_se[j, 1:]]
        shapes.append(ModeShape(tuple(markers), tuple(colours), tuple(float(v) for v in amps[j]),
                                tuple(float(v) for v in amp_se[j]), tuple(rel), tuple(rel_se)))
    return shapes


def _ringdown(t, a, sigma, wd, phi, c):
    return a * np.exp(-sigma * t) * np.cos(wd * t + phi) + c


def _window(time_s: np.ndarray, y: np.ndarray, start_s: float):
    t, v = np.asarray(time_s, dtype=float), np.asarray(y, dtype=float)
    keep = np.isfinite(t) & np.isfinite(v) & (t >= start_s)
    if np.count_nonzero(keep) < 20:
        return None
    return t[keep] - start_s, v[keep]


def _spectral_peak(t: np.ndarray, x: np.ndarray, dt: float, away_hz: list[tuple[float, float]]) -> float:
    """The window's spectral peak (Hanning, zero-padded 16x), at least two cycles in the window and away from
    each ``(frequency, half width)`` given (a forced line, a mode already found)."""
    spectrum = np.abs(np.fft.rfft(x * np.hanning(x.size), 16 * x.size))
    freqs = np.fft.rfftfreq(16 * x.size, dt)
    spectrum[freqs < 2.0 / (t[-1] + dt)] = 0.0  # at least two cycles in the window
    for f, half in away_hz:
        spectrum[np.abs(freqs - f) < half] = 0.0
    return float(freqs[int(np.argmax(spectrum))])


def _fit_ringdowns(t: np.ndarray, v: np.ndarray, p0_modes: list[list[float]], c0: float, forced_hz: float | None,
                   forced0: tuple[float, float], noise: float | None, source: str) -> list[ModeFit] | None:
    """Fit a sum of ring-downs (with a forced sine) from the starts given; each mode's ModeFit, or None.

    None when the fit fails or wanders; a mode that is too small (:data:`MIN_SNR`), not damped
    or damped beyond :data:`MAX_MODE_DAMPING` comes back as None in its place.
    """
    n = len(p0_modes)
    wf = 2.0 * math.pi * forced_hz if forced_hz is not None else 0.0

    if n == 1:
        # One mode: the parameter layout the fit has always had (a, σ, ω_d, φ, c[, b_s, b_c]).
        model = _ringdown if forced_hz is None else (
            lambda tt, a, sigma, wd, phi, c, bs, bc: _ringdown(tt, a, sigma, wd, phi, c)
            + bs * np.sin(wf * tt) + bc * np.cos(wf * tt))
    else:
        def model(tt, *p):
            # The first mode and the level as for one mode, the other modes after them, the forced line last.
            out = _ringdown(tt, *p[:5])
            for j in range(1, n):
                a, sigma, wd, phi = _mode_params(p, j)
                out = out + a * np.exp(-sigma * tt) * np.cos(wd * tt + phi)
            if forced_hz is not None:
                out = out + p[-2] * np.sin(wf * tt) + p[-1] * np.cos(wf * tt)
            return out
    p0 = list(p0_modes[0]) + [c0] + [v for extra in p0_modes[1:] for v in extra]
    if forced_hz is not None:
        p0 += list(forced0)
    try:
        # A fit that wanders (a growing exponential overflows) or whose covariance cannot be estimated
        # is refused below (σ > 0, finite residual and covariance): no warning on the way.
        with warnings.catch_warnings(), np.errstate(over="ignore", invalid="ignore"):
            warnings.simplefilter("ignore", OptimizeWarning)
            popt, pcov = curve_fit(model, t, v, p0=p0, maxfev=20000 * n)
            residual = v - model(t, *popt)
    except (RuntimeError, ValueError):
        return None
    if not np.all(np.isfinite(residual)) or not np.all(np.isfinite(pcov)):
        return None
    scatter = float(np.std(residual))
    # Residuals that follow each other (tracking errors, what is left of the servo's forced
    # motion) carry less information than white ones: the covariance grows by the AR(1)
    # factor (1 + ρ)/(1 − ρ) of their lag-1 autocorrelation ρ (≥ 0).
    r = residual - residual.mean()
    rho = float(r[1:] @ r[:-1]) / float(r @ r) if float(r @ r) > 0 else 0.0
    rho = min(max(rho, 0.0), 0.95)
    pcov = pcov * (1.0 + rho) / (1.0 - rho)
    out: list[ModeFit | None] = []
    for j in range(n):
        idx = _mode_index(j)
        a, sigma, wd = popt[idx[0]], popt[idx[1]], popt[idx[2]]
        if abs(a) < MIN_SNR * max(scatter, noise or 0.0) or not (wd > 0 and sigma > 0):
            out.append(None)
            continue
        wn = math.hypot(wd, sigma)
        cov = pcov[np.ix_([idx[1], idx[2]], [idx[1], idx[2]])]  # (σ, wd)
        # Delta method: f = hypot(wd, σ)/2π, ζ = σ / hypot(wd, σ).
        g_f = np.array([sigma, wd]) / (wn * 2.0 * math.pi)
        g_z = np.array([wd**2 / wn**3, -sigma * wd / wn**3])
        f, z = wn / (2.0 * math.pi), sigma / wn
        if z > MAX_MODE_DAMPING:
            out.append(None)
            continue
        se_f = math.hypot(math.sqrt(max(float(g_f @ cov @ g_f), 0.0)), MODE_SYSTEMATIC["frequency"] * f)
        se_z = math.hypot(math.sqrt(max(float(g_z @ cov @ g_z), 0.0)), MODE_SYSTEMATIC["damping"] * z)
        out.append(ModeFit(f, se_f, z, se_z, float(abs(a)), source))
    return out  # type: ignore[return-value]


def _mode_index(j: int) -> tuple[int, int, int, int]:
    """Where mode j's (a, σ, ω_d, φ) sit in the parameter vector: the first's before the level c, the others after."""
    return (0, 1, 2, 3) if j == 0 else tuple(5 + 4 * (j - 1) + k for k in range(4))  # type: ignore[return-value]


def _mode_params(p, j: int):
    return tuple(p[i] for i in _mode_index(j))


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
    modes = fit_damped_modes(time_s, y, start_s, noise=noise, source=source, forced_hz=forced_hz, max_modes=1)
    return modes[0] if modes else None


def fit_damped_modes(time_s: np.ndarray, y: np.ndarray, start_s: float, *, noise: float | None = None,
                     source: str = "step", forced_hz: float | None = None, max_modes: int = 2) -> list[ModeFit]:
    """Fit up to ``max_modes`` ring-downs to ``y`` from ``start_s`` on, strongest first; empty when none shows.

    The strongest mode is fitted alone (started from the window's spectral peak); the next is
    looked for in what it leaves (the residual's spectral peak, away from the first mode's
    resonance and any forced line), then both are fitted together by least squares. A second
    mode is kept when the joint fit keeps it above :data:`MIN_SNR` times the noise, damped by
    no more than :data:`MAX_MODE_DAMPING` and apart from the first by more than both their
    half-power widths and 3 %: else the first alone stands, as fitted alone. Arguments as
    :func:`fit_damped_mode`.
    """
    win = _window(time_s, y, start_s)
    if win is None:
        return []
    t, v = win
    dt = float(np.median(np.diff(t)))
    x = v - v.mean()
    away: list[tuple[float, float]] = []
    forced0 = (0.0, 0.0)
    if forced_hz is not None:
        wf = 2.0 * math.pi * forced_hz
        forced = np.column_stack([np.sin(wf * t), np.cos(wf * t)])
        b = np.linalg.lstsq(np.column_stack([forced, np.ones_like(t)]), v, rcond=None)[0]
        x = v - forced @ b[:2] - b[2]
        forced0 = (float(b[0]), float(b[1]))
        away.append((forced_hz, 1.5 / (t[-1] + dt)))  # the forced line's own width
    f0 = _spectral_peak(t, x, dt, away)
    if not f0 > 0:
        return []
    w0 = 2.0 * math.pi * f0
    a0 = float(np.max(np.abs(x[: max(3, int(round(1.0 / (f0 * dt))))])))
    first = _fit_ringdowns(t, v, [[a0, 0.03 * w0, w0, 0.0]], float(v.mean()), forced_hz, forced0, noise, source)
    if not first or first[0] is None:
        return []
    if max_modes < 2:
        return [first[0]]
    m1 = first[0]
    # What the first mode leaves: its own fit's residual, less a level.
    w1 = 2.0 * math.pi * m1.frequency_hz
    p1 = _refit_start(t, v, m1, forced_hz)
    x2 = v - p1
    away2 = away + [(m1.frequency_hz, max(3.0 * m1.damping_ratio * m1.frequency_hz, 1.5 / (t[-1] + dt)))]
    f2 = _spectral_peak(t, x2 - x2.mean(), dt, away2)
    if not f2 > 0:
        return [m1]
    w2 = 2.0 * math.pi * f2
    a2 = float(np.max(np.abs((x2 - x2.mean())[: max(3, int(round(1.0 / (f2 * dt))))])))
    start1 = [m1.amplitude, m1.damping_ratio * w1, w1 * math.sqrt(1.0 - m1.damping_ratio**2), _phase0(t, v, m1)]
    both = _fit_ringdowns(t, v, [start1, [a2, 0.03 * w2, w2, 0.0]], float(v.mean()), forced_hz, forced0, noise,
                          source)
    if not both or any(m is None for m in both):
        return [m1]
    a, b2 = both
    apart = abs(a.frequency_hz - b2.frequency_hz) > max(a.damping_ratio * a.frequency_hz
                                                         + b2.damping_ratio * b2.frequency_hz,
                                                         0.03 * a.frequency_hz)
    if not apart:
        return [m1]
    return [a, b2] if a.amplitude >= b2.amplitude else [b2, a]


def _refit_start(t: np.ndarray, v: np.ndarray, mode: ModeFit, forced_hz: float | None) -> np.ndarray:
    """The first mode's (and forced line's, level's) least-squares part of ``v`` at its fitted frequency and damping."""
    cols = [*ringdown_columns(t, mode.frequency_hz, mode.damping_ratio), np.ones_like(t)]
    if forced_hz is not None:
        wf = 2.0 * math.pi * forced_hz
        cols += [np.sin(wf * t), np.cos(wf * t)]
    design = np.column_stack(cols)
    return design @ np.linalg.lstsq(design, v, rcond=None)[0]


def _phase0(t: np.ndarray, v: np.ndarray, mode: ModeFit) -> float:
    """The first mode's phase at the window's start, from a linear fit at its frequency and damping."""
    design = np.column_stack([*ringdown_columns(t, mode.frequency_hz, mode.damping_ratio), np.ones_like(t)])
    c, s_, _ = np.linalg.lstsq(design, v, rcond=None)[0]
    return math.atan2(-s_, c)


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
        mean, pooled = inverse_variance_mean(v, stat)
        out[key] = (mean, math.hypot(pooled, MODE_SYSTEMATIC[key] * mean))
    amplitude = max(m.amplitude for m in modes)
    return ModeFit(out["frequency"][0], out["frequency"][1], out["damping"][0], out["damping"][1], amplitude, source)
