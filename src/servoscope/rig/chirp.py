"""A frequency-sweep (chirp) test: ``servoscope plan --sweep F0:F1 --duration S``.

One sweep (:func:`~servoscope.sysid.inputs.sweep_command`) instead of sine dwells,
planned to fit the camera (its frame rate and, given, its longest recording), with the
coherence it should reach at its top frequency for the track's angle noise
(:func:`sweep_coherence`). The plan is a :class:`~servoscope.rig.plan.SweepPlan` like
the dwells' (written and driven the same way); see ``docs/rig.md``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..defaults import MIN_DWELL_S, SETTLE_S
from ..errors import ServoscopeError
from ..sysid.inputs import SWEEP_SHAPES
from .plan import (PWM_HARMONICS, Dwell, SweepPlan, fold_hz, frequency_warnings, pause_options, positive_option,
                   step_dwells)

__all__ = [
    "plan_chirp",
    "sweep_coherence",
    "sweep_duration_s",
    "sweep_cycles",
    "sweep_rate_hz_s",
    "ripple_warnings",
    "nominal_gain",
    "CoherenceEstimate",
    "DEFAULT_NOISE_DEG",
    "MIN_COHERENCE",
    "NOMINAL_GAIN_RAD",
    "NOMINAL_WN_RAD_S",
    "NOMINAL_ZETA",
]


#: The plan's prior for the response it expects, the paper's fit
#: ``K·ωn²/(s² + 2ζωn·s + ωn²)`` with K in rad per input unit (as
#: :data:`servoscope.simulate.presets.PAPER_SERVO`, without its dead time, which does
#: not change the gain).
NOMINAL_GAIN_RAD = 0.23
NOMINAL_WN_RAD_S = 37.0
NOMINAL_ZETA = 0.65
#: Per-frame angle noise of the track, degrees, when the plan is given none: the measured
#: angle noise of the ``paper`` preset's dwells, 0.0044–0.0055° (docs/accuracy.md), rounded up.
DEFAULT_NOISE_DEG = 0.005
#: Coherence below which a frequency-response point is not trusted (the flight-test standard's γ² ≥ 0.6).
MIN_COHERENCE = 0.6


def nominal_gain(frequency_hz: float | np.ndarray) -> float | np.ndarray:
    """``|G(j2πf)|`` of the nominal servo (:data:`NOMINAL_GAIN_RAD` …), rad per input unit."""
    s = 2j * np.pi * np.asarray(frequency_hz, dtype=float)
    wn2 = NOMINAL_WN_RAD_S**2
    g = np.abs(NOMINAL_GAIN_RAD * wn2 / (s * s + 2.0 * NOMINAL_ZETA * NOMINAL_WN_RAD_S * s + wn2))
    return float(g) if g.ndim == 0 else g


def sweep_cycles(from_hz: float, to_hz: float, duration_s: float, shape: str = "log") -> float:
    """Cycles of a sweep: its phase at the end over 2π (``f0·T·(r − 1)/ln r`` log, ``T·(f0 + f1)/2`` linear)."""
    if shape == "log":
        ratio = to_hz / from_hz
        return from_hz * duration_s * (ratio - 1.0) / math.log(ratio)
    return duration_s * (from_hz + to_hz) / 2.0


def sweep_duration_s(from_hz: float, to_hz: float, wanted_s: float, shape: str = "log") -> float:
    """A sweep's duration: ``wanted_s`` rounded up to a whole number of cycles, so that the command ends at 0.

    The cycles grow in proportion to the duration (:func:`sweep_cycles`), so the rounding
    adds less than one period of the sweep's mean frequency.
    """
    per_s = sweep_cycles(from_hz, to_hz, 1.0, shape)
    return math.ceil(wanted_s * per_s - 1e-9) / per_s


def sweep_rate_hz_s(frequency_hz: float, from_hz: float, to_hz: float, duration_s: float, shape: str = "log") -> float:
    """How fast the sweep's frequency moves as it passes ``frequency_hz``, Hz/s (``f·ln(f1/f0)/T`` or ``(f1 − f0)/T``)."""
    if shape == "log":
        return frequency_hz * math.log(to_hz / from_hz) / duration_s
    return (to_hz - from_hz) / duration_s


@dataclass(frozen=True)
class CoherenceEstimate:
    """The coherence a sweep should reach at its top frequency (:func:`sweep_coherence`).

    Attributes
    ----------
    frequency_hz : float
        The sweep's top frequency, Hz.
    response_deg : float
        Expected response amplitude there, degrees (amplitude × the prior's gain).
    noise_deg : float
        Per-frame angle noise σ assumed, degrees.
    window_s : float
        Length of the analysis window that sees the most of the sweep's passage, s.
    frames : float
        Frames in that window.
    snr : float
        Signal-to-noise ratio of the window's Fourier coefficient at the top frequency (power).
    coherence : float
        ``snr / (1 + snr)``.
    """

    frequency_hz: float
    response_deg: float
    noise_deg: float
    window_s: float
    frames: float
    snr: float
    coherence: float

    def summary(self) -> str:
        """One line for the plan's printout."""
        return (f"expected coherence at {self.frequency_hz:g} Hz: γ² ≈ {self.coherence:.4f} per {self.window_s:.2g} s "
                f"window (SNR {self.snr:.3g}: response ±{self.response_deg:.3g}°, {self.frames:.0f} frames, "
                f"angle noise {self.noise_deg:.2g}° per frame)")


def _fresnel_gain(x_max: float) -> tuple[float, float]:
    """``max over 0 < X ≤ x_max of (C(X)² + S(X)²)/X`` and the X reaching it (Fresnel integrals)."""
    from scipy.special import fresnel

    x = np.linspace(1e-3, max(min(x_max, 4.0), 2e-3), 4000)
    s_x, c_x = fresnel(x)
    q = (c_x**2 + s_x**2) / x
    i = int(np.argmax(q))
    return float(q[i]), float(x[i])


def sweep_coherence(
    amplitude: float,
    from_hz: float,
    to_hz: float,
    duration_s: float,
    fps: float,
    *,
    shape: str = "log",
    noise_deg: float = DEFAULT_NOISE_DEG,
    gain_rad: float | None = None,
) -> CoherenceEstimate:
    """The coherence γ² a sweep should reach at its top frequency, for a given angle noise.

    Model: the camera samples the blade angle ``y = G·u + n`` at ``fps``, ``n`` white with
    σ = ``noise_deg`` per frame. The response at the top frequency ``f1`` is a tone of
    amplitude ``Y = amplitude·|G(j2πf1)|`` (``gain_rad``, else the nominal servo's
    :func:`nominal_gain`, rad per input unit), whose frequency passes ``f1`` at the rate
    ``ḟ = f1·ln(f1/f0)/T`` (log sweep: the time spent per Hz falls as 1/f) or ``(f1 − f0)/T``
    (linear).

    A window of N frames (length ``T_w``) that ends with the sweep takes the Fourier
    coefficient at ``f1``. White noise gives it ``E|Σ n·e^{−iωt}|² = N·σ²``; a steady tone
    ``(N·Y/2)²``. The sweep is not steady: relative to the tone at ``f1`` its phase is
    ``π·ḟ·(t − T)²``, so its coefficient is ``(fps·Y/2)²·|C(X) + iS(X)|²/(2ḟ)`` with
    ``X = T_w·√(2ḟ)`` (C, S: the Fresnel integrals). The ratio, maximised over the window
    (``X ≈ 1.02``, i.e. ``T_w ≈ 0.72/√ḟ``; a longer window adds noise faster than signal),

        SNR = c · fps · Y² / (4 σ² √(2ḟ)),   c = max (C² + S²)/X ≈ 0.80,

    and γ² = SNR / (1 + SNR), the coherence of an input–output pair whose output carries
    noise of that ratio. A longer sweep raises the SNR as √T, a larger amplitude as its
    square.

    Assumptions: the input is known exactly (the command), so all the noise is on the
    output and is white per frame (the track's measured angle noise: on H.264 footage it
    is correlated from frame to frame, and then this is optimistic); the servo is linear
    with the prior's gain at ``f1``; the window sees the sweep's last passage through
    ``f1`` and nothing of the tail (a rectangular window; CIFER's tapered windows lose a
    little more). It is the coherence of the window around the passage: averaging spectra
    over a whole record of T seconds, most of whose windows hold only noise at ``f1``,
    divides the SNR by about ``T/T_w``. The zero-order hold's ``sinc(f/update_hz)`` is left
    out (the servo sees the staircase either way). Checked against the Fourier coefficient
    of a simulated response in ``tests/rig/test_rig_sweep.py``.

    Parameters
    ----------
    amplitude : float
        Sweep amplitude, input units.
    from_hz, to_hz : float
        Start and top frequency, Hz.
    duration_s : float
        Sweep duration T, s.
    fps : float
        Camera frame rate, frames/s.
    shape : {"log", "linear"}
    noise_deg : float
        Per-frame angle noise σ, degrees.
    gain_rad : float, optional
        ``|G|`` at ``to_hz``, rad per input unit; default the nominal servo's.

    Returns
    -------
    CoherenceEstimate
    """
    gain = nominal_gain(to_hz) if gain_rad is None else float(gain_rad)
    y_deg = abs(amplitude) * math.degrees(gain)
    rate = sweep_rate_hz_s(to_hz, from_hz, to_hz, duration_s, shape)
    c, x = _fresnel_gain(duration_s * math.sqrt(2.0 * rate))
    window_s = x / math.sqrt(2.0 * rate)
    snr = c * fps * y_deg**2 / (4.0 * noise_deg**2 * math.sqrt(2.0 * rate)) if noise_deg > 0 else math.inf
    coherence = 1.0 if math.isinf(snr) else snr / (1.0 + snr)
    return CoherenceEstimate(float(to_hz), y_deg, float(noise_deg), window_s, window_s * fps, snr, coherence)


def ripple_warnings(from_hz: float, to_hz: float, fps: float, update_hz: float) -> list[str]:
    """The servo's PWM ripple (``k·update_hz`` as the camera sees it) inside a sweep's band, one line each."""
    tag = f"sweep {from_hz:g}–{to_hz:g} Hz"
    out = []
    seen: set[float] = set()
    for k in range(1, PWM_HARMONICS + 1):
        ripple_hz = fold_hz(k * update_hz, fps)
        if from_hz <= ripple_hz <= to_hz and round(ripple_hz, 9) not in seen:
            seen.add(round(ripple_hz, 9))
            harmonic = f"{k}×" if k > 1 else ""
            out.append(f"{tag}: the servo's PWM ripple ({harmonic}{update_hz:g} Hz) shows at {ripple_hz:.3g} Hz "
                       f"at {fps:g} fps, inside the sweep; expect a coherence dip there")
    return out


def plan_chirp(
    fps: float,
    from_hz: float,
    to_hz: float,
    duration_s: float,
    *,
    shape: str = "log",
    amplitude: float = 0.1,
    noise_deg: float = DEFAULT_NOISE_DEG,
    record_s: float | None = None,
    settle_s: float = SETTLE_S,
    min_seconds: float = MIN_DWELL_S,
    update_hz: float = 50.0,
    step: bool = True,
    step_amplitude: float = 0.5,
    step_seconds: float = 3.0,
    lead_in_s: float = 1.0,
    tail_s: float = 0.5,
    rest_s: float = 2.0,
    markers: dict[str, str] | None = None,
    units: str = "normalized",
) -> SweepPlan:
    """Plan one frequency sweep (chirp) test and, unless ``step`` is False, the step test.

    The sweep's duration is ``duration_s`` rounded up to a whole number of cycles
    (:func:`sweep_duration_s`), so that the command ends at 0. It is refused when the
    camera could not film it: a top frequency at or above half the frame rate, or (given
    ``record_s``) a lead-in, sweep and tail longer than the camera records. The top
    frequency is checked as a sine dwell's (:func:`~servoscope.rig.plan.frequency_warnings`), the whole band
    for the servo's PWM ripple (:func:`ripple_warnings`), and the coherence expected at
    the top frequency (:func:`sweep_coherence`) is warned about below
    :data:`MIN_COHERENCE`.

    Parameters
    ----------
    fps : float
        Camera frame rate, frames/s.
    from_hz, to_hz : float
        Start and top frequency, Hz (``0 < from_hz < to_hz``).
    duration_s : float
        Sweep duration wanted, s.
    shape : {"log", "linear"}
        Logarithmic (equal time per octave) or linear sweep.
    amplitude : float
        Sweep amplitude, input units.
    noise_deg : float
        Per-frame angle noise σ of the track, degrees (:data:`DEFAULT_NOISE_DEG`).
    record_s : float, optional
        Longest recording the camera makes, s; None: not checked.
    settle_s, min_seconds, update_hz, step, step_amplitude, step_seconds, lead_in_s, tail_s, rest_s, markers, units
        As for :func:`~servoscope.rig.plan.plan_sweep`.

    Returns
    -------
    SweepPlan

    Raises
    ------
    ServoscopeError
        One line naming the option at fault.
    """
    fps = positive_option(fps, "--fps")
    from_hz = positive_option(from_hz, "--sweep (start)")
    to_hz = positive_option(to_hz, "--sweep (top)")
    duration_s = positive_option(duration_s, "--duration")
    amplitude = positive_option(amplitude, "--amplitude")
    noise_deg = positive_option(noise_deg, "--noise-deg", allow_zero=True)
    update_hz = positive_option(update_hz, "--update-hz")
    settle_s, min_seconds, lead_in_s, tail_s, rest_s = pause_options(settle_s, min_seconds, lead_in_s, tail_s, rest_s)
    if shape not in SWEEP_SHAPES:
        raise ServoscopeError(f"--sweep-shape {shape!r}: use log or linear")
    if not to_hz > from_hz:
        raise ServoscopeError(f"--sweep {from_hz:g}:{to_hz:g}: the top frequency must be above the start")
    if to_hz >= fps / 2:  # as the manifest refuses it (campaign.inputs)
        raise ServoscopeError(f"--sweep {from_hz:g}:{to_hz:g}: the top frequency is at or above half the frame rate "
                              f"({fps / 2:g} Hz at {fps:g} fps); the camera cannot show it")
    steps = step_dwells(step, step_amplitude, step_seconds, min_seconds)
    sweep_s = sweep_duration_s(from_hz, to_hz, duration_s, shape)
    if record_s is not None:
        record_s = positive_option(record_s, "--record-seconds")
        filmed_s = lead_in_s + sweep_s + tail_s
        if filmed_s > record_s:
            raise ServoscopeError(
                f"--duration {duration_s:g}: the camera would record {filmed_s:.3g} s ({lead_in_s:g} s lead-in, "
                f"{sweep_s:.3g} s sweep, {tail_s:g} s tail), more than --record-seconds {record_s:g}")
    warnings = [w.replace(f"{to_hz:g} Hz:", f"sweep top {to_hz:g} Hz:", 1)
                for w in frequency_warnings(to_hz, fps, update_hz, ripple=False)]
    warnings += ripple_warnings(from_hz, to_hz, fps, update_hz)
    estimate = sweep_coherence(amplitude, from_hz, to_hz, sweep_s, fps, shape=shape, noise_deg=noise_deg)
    if estimate.coherence < MIN_COHERENCE:
        warnings.append(
            f"sweep top {to_hz:g} Hz: expected coherence γ² ≈ {estimate.coherence:.2f}, below {MIN_COHERENCE:g} "
            f"(response ±{estimate.response_deg:.2g}° against {noise_deg:.2g}° of angle noise); use a longer "
            f"--duration (SNR grows as its square root) or a larger --amplitude (as its square)")
    dwells = [Dwell("sweep", amplitude, None, sweep_s, tuple(warnings), from_hz=from_hz, to_hz=to_hz, shape=shape),
              *steps]
    return SweepPlan(
        fps=fps, update_hz=update_hz, settle_s=settle_s, periods=8.0, min_seconds=min_seconds,
        lead_in_s=lead_in_s, tail_s=tail_s, rest_s=rest_s, dwells=tuple(dwells),
        units=units, **({"markers": dict(markers)} if markers else {}),
    )
