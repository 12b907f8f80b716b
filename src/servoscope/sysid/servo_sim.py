"""Block-structured servo models, simulated in the time domain for fitting.

The models the joint and nonlinear fits (:mod:`servoscope.sysid.servo_fit`) compare with
the whole measured traces: the paper's 2nd-order dynamics ``K·ωn²/(s² + 2ζωn·s + ωn²)``
after a dead time, with at most one hard nonlinearity where the physics of a hobby or
industrial servo puts it::

    command u --quantization--> delay τ --rate limit--> G(s) --saturation--> --backlash--> angle

* ``quantization``: the command's resolution (a PWM servo's set-point steps), in input
  units; it acts before everything, so it commutes with the delay.
* ``rate_limit``: the set-point slews at a bounded speed into a linear position loop. It is
  stated as the blade's steady slew, ``rate_limit_rad_s`` = K × the reference's limit, so
  that it reads in the output's units whatever K is. (A limit on the motor's speed inside
  the loop would change the loop's dynamics while it acts; this model does not, and the
  report's trace comparison shows where that matters.)
* ``saturation``: the servo's travel, ``±saturation_rad`` about the rest angle.
* ``backlash``: play of total width ``backlash_rad`` in the linkage between the servo and
  the blade: the blade follows once the gap is taken up (a play operator).

Written independently of the digital twin's simulator (:mod:`servoscope.simulate.servo`):
the twin is the truth the fits are tested against, so the fitter must not share its code.
The simulation is a zero-order hold of the reference sampled at the middle of each grid
interval (exact for a step on the grid's first point, second order for smooth inputs) on a
``GRID_STEP_S`` grid that starts at the delayed input start, so the dead time moves the grid
and not the samples: the output is continuous in τ. A camera's exposure averages the
output over the exposure window centred on each sample time.
"""

from __future__ import annotations

import functools
import math

from dataclasses import dataclass, field

import numpy as np
import scipy.linalg

from numba import njit
from numpy.typing import NDArray

from ..errors import ServoscopeError
from .inputs import recorded_command, sweep_command, sweep_problems

__all__ = ["GRID_STEP_S", "LINEAR_PARAMETERS", "NONLINEAR_PARAMETER", "STRUCTURES", "ServoTrace", "simulate_trace"]

#: Grid step of the time-domain simulation, seconds: 0.1 ms keeps the dead time's and the
#: corners' discretisation far under a frame interval of even a 1000 frames/s camera.
GRID_STEP_S = 1e-4

#: The block structures, the linear model first.
STRUCTURES = ("linear", "rate_limit", "backlash", "quantization", "saturation")

#: Each nonlinear structure's parameter, named with its unit.
NONLINEAR_PARAMETER = {"rate_limit": "rate_limit_rad_s", "backlash": "backlash_rad",
                       "quantization": "quantization_step", "saturation": "saturation_rad"}

#: The linear part's parameters, named as the frequency-domain fit names them.
LINEAR_PARAMETERS = ("gain", "natural_frequency_rad_s", "damping_ratio", "dead_time_s")


@dataclass(frozen=True)
class ServoTrace:
    """One test's measured angle with its input, as the time-domain fit reads it.

    Attributes
    ----------
    label : str
    kind : {"sine", "step", "sweep"}
    amplitude : float
        Sine or sweep amplitude, or step size, input units.
    frequency_hz : float or None
        A sine's frequency; None for a step or a sweep.
    t0_s : float
        When the input started, seconds (the LED's switch or the manifest's t0).
    time_s : ndarray
        When each angle was sampled (the exposure's middle), seconds; valid frames only.
    angle_rad : ndarray
        The measured angle, rad.
    noise_rad : float
        The angle's measured noise (one frame's standard deviation), rad.
    exposure_s : float
        The exposure that averages each sample (0: instantaneous).
    window_s : (float, float) or None
        A dwell's steady-state window, where its fundamental was measured (for CIFER's J).
    sticker_radius_px : float
        How far each sticker moves per radian of pitch (half their separation), px; NaN when
        not known. It turns a model's effect into what the picture shows.
    from_hz, to_hz, duration_s, shape
        A sweep's chirp (:func:`~servoscope.sysid.inputs.sweep_command`); None for the other kinds.
        A recorded input's band, its length and None.
    input_samples : (ndarray, ndarray) or None
        A recorded input's samples ``(time since its start, command)``
        (:func:`~servoscope.sysid.inputs.recorded_command`), the command instead of a chirp; None
        for the other inputs.
    """

    label: str
    kind: str
    amplitude: float
    frequency_hz: float | None
    t0_s: float
    time_s: NDArray[np.float64]
    angle_rad: NDArray[np.float64]
    noise_rad: float
    exposure_s: float = 0.0
    window_s: tuple[float, float] | None = None
    sticker_radius_px: float = math.nan
    from_hz: float | None = None
    to_hz: float | None = None
    duration_s: float | None = None
    shape: str | None = None
    input_samples: tuple[NDArray[np.float64], NDArray[np.float64]] | None = field(default=None, compare=False,
                                                                                   repr=False)

    def __post_init__(self) -> None:
        if self.kind not in ("sine", "step", "sweep"):
            raise ServoscopeError(f"{self.label}: a trace is a sine, a step or a sweep, not {self.kind!r}")
        if self.input_samples is not None:
            if self.kind != "sweep" or not (self.from_hz and self.to_hz and 0 < self.from_hz < self.to_hz):
                raise ServoscopeError(f"{self.label}: a recorded input is a sweep with a band 0 < from_hz < to_hz")
        elif self.kind == "sweep":
            problems = sweep_problems(self.from_hz, self.to_hz, self.duration_s, self.shape or "log")
            if problems:
                raise ServoscopeError(f"{self.label}: " + "; ".join(f"{k}: {m}" for k, m in problems))
        if self.time_s.shape != self.angle_rad.shape or self.time_s.ndim != 1:
            raise ServoscopeError(f"{self.label}: time and angle differ in shape")
        if not (self.noise_rad > 0 and math.isfinite(self.noise_rad)):
            raise ServoscopeError(f"{self.label}: the angle's noise must be > 0, not {self.noise_rad!r}")

    @functools.cached_property
    def _grid_command(self) -> NDArray[np.float64]:
        # The input at the middle of each grid interval from the start to the last sample (and an
        # exposure beyond): the same for every dead time, which only shortens it.
        end = float(np.max(self.time_s)) + 0.5 * self.exposure_s if self.time_s.size else self.t0_s
        n = max(int(math.ceil((end - self.t0_s) / GRID_STEP_S)) + 2, 2)
        return self.command(self.t0_s + (np.arange(n) + 0.5) * GRID_STEP_S)

    def grid_command(self, n: int) -> NDArray[np.float64]:
        """The input at the middle of the first ``n`` grid intervals after the input's start."""
        cached = self._grid_command
        if n <= cached.size:
            return cached[:n]
        return self.command(self.t0_s + (np.arange(n) + 0.5) * GRID_STEP_S)

    @property
    def top_frequency_hz(self) -> float | None:
        """The highest frequency the input holds: a sine's, a sweep's ``to_hz``; None for a step."""
        return self.to_hz if self.kind == "sweep" else self.frequency_hz

    def command(self, time_s: NDArray[np.float64]) -> NDArray[np.float64]:
        """The input at ``time_s`` (0 before the start; a sweep's 0 after it too), input units."""
        dt = time_s - self.t0_s
        if self.input_samples is not None:
            return recorded_command(dt, *self.input_samples)
        if self.kind == "sweep":
            return sweep_command(dt, self.amplitude, float(self.from_hz), float(self.to_hz), float(self.duration_s),
                                 self.shape or "log")
        if self.kind == "sine":
            u = self.amplitude * np.sin(2.0 * math.pi * float(self.frequency_hz) * dt)
        else:
            u = np.full_like(dt, self.amplitude)
        return np.where(dt >= 0.0, u, 0.0)


@functools.lru_cache(maxsize=256)
def _zoh(wn: float, zeta: float, dt: float) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Zero-order-hold discretisation of ``ωn²/(s² + 2ζωn s + ωn²)`` in the states (y, ẏ).

    Cached: a fit simulates every trace at the same (ωn, ζ), and the matrix exponential cost as much
    as the simulation itself. The arrays are read-only, since every caller shares them.
    """
    a = np.array([[0.0, 1.0], [-wn * wn, -2.0 * zeta * wn]])
    b = np.array([0.0, wn * wn])
    m = np.zeros((3, 3))
    m[:2, :2] = a * dt
    m[:2, 2] = b * dt
    e = scipy.linalg.expm(m)
    phi, gam = e[:2, :2].copy(), e[:2, 2].copy()
    phi.flags.writeable = False
    gam.flags.writeable = False
    return phi, gam


@njit(cache=True)
def _chain(command, gain, phi, gam, rate_step, saturation, half_play):  # pragma: no cover - numba
    # The reference after the rate limit, through G, then the travel and the play, one grid step at a time.
    n = command.size
    out = np.empty(n + 1)
    x0 = 0.0
    x1 = 0.0
    r = 0.0
    z = 0.0
    out[0] = 0.0
    for k in range(n):
        c = command[k]
        if rate_step > 0.0:
            d = c - r
            if d > rate_step:
                d = rate_step
            elif d < -rate_step:
                d = -rate_step
            r = r + d
        else:
            r = c
        u = gain * r
        y0 = phi[0, 0] * x0 + phi[0, 1] * x1 + gam[0] * u
        y1 = phi[1, 0] * x0 + phi[1, 1] * x1 + gam[1] * u
        x0 = y0
        x1 = y1
        y = x0
        if saturation > 0.0:
            if y > saturation:
                y = saturation
            elif y < -saturation:
                y = -saturation
        if half_play > 0.0:
            if y - half_play > z:
                z = y - half_play
            elif y + half_play < z:
                z = y + half_play
            y = z
        out[k + 1] = y
    return out


def simulate_trace(trace: ServoTrace, structure: str, params: dict[str, float], *,
                   time_s: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
    """The model's angle (about the rest angle) at a trace's sample times.

    Parameters
    ----------
    trace : ServoTrace
        The test: its input and its sample times (and exposure).
    structure : str
        One of :data:`STRUCTURES`.
    params : dict
        :data:`LINEAR_PARAMETERS` and, for a nonlinear structure, its
        :data:`NONLINEAR_PARAMETER`.
    time_s : ndarray, optional
        Other sample times (default the trace's).

    Returns
    -------
    ndarray
        Angle in rad, 0 before the delayed input arrives.
    """
    t = trace.time_s if time_s is None else np.asarray(time_s, dtype=float)
    gain, wn, zeta, tau = (float(params[k]) for k in LINEAR_PARAMETERS)
    half_e = 0.5 * trace.exposure_s
    start = trace.t0_s + tau
    t_end = float(np.max(t)) + half_e if t.size else start
    n = max(int(math.ceil((t_end - start) / GRID_STEP_S)) + 2, 2)
    # Input times (before the delay) at the middle of each grid interval.
    command = trace.grid_command(n) if time_s is None else trace.command(trace.t0_s + (np.arange(n) + 0.5) * GRID_STEP_S)
    if structure == "quantization":
        q = float(params["quantization_step"])
        command = q * np.round(command / q)
    phi, gam = _zoh(wn, zeta, GRID_STEP_S)
    rate_step = float(params["rate_limit_rad_s"]) / abs(gain) * GRID_STEP_S if structure == "rate_limit" else 0.0
    saturation = float(params["saturation_rad"]) if structure == "saturation" else 0.0
    half_play = 0.5 * float(params["backlash_rad"]) if structure == "backlash" else 0.0
    y = _chain(command, gain, phi, gam, rate_step, saturation, half_play)
    t = np.ascontiguousarray(t, dtype=np.float64)
    if half_e <= 0.0:
        return _on_grid(t, start, GRID_STEP_S, y)
    # The exposure's average: the output's running integral (trapezoids) across the window; 0 before
    # the grid starts (the integral's first value).
    integral = _running_integral(y, GRID_STEP_S)
    area = _on_grid(t + half_e, start, GRID_STEP_S, integral) - _on_grid(t - half_e, start, GRID_STEP_S, integral)
    return area / trace.exposure_s


@njit(cache=True)
def _running_integral(y, step):  # pragma: no cover - numba
    # concatenate(([0], cumsum(0.5 * (y[1:] + y[:-1]) * step))), in numpy's order of operations (the same bits)
    # without its four temporaries: a fit calls this for every trace at every evaluation.
    out = np.empty(y.size)
    out[0] = 0.0
    acc = 0.0
    for k in range(1, y.size):
        acc = acc + 0.5 * (y[k] + y[k - 1]) * step
        out[k] = acc
    return out


@njit(cache=True)
def _on_grid(x, start, step, fp):  # pragma: no cover - numba
    # np.interp(x, start + arange(fp.size) * step, fp, left=0.0) to the bit (numpy's interpolation formula
    # and its grid's arithmetic), without building the grid: a fit calls this for every trace at every
    # evaluation.
    n = fp.size
    out = np.empty(x.size)
    last = start + float(n - 1) * step
    for i in range(x.size):
        xi = x[i]
        if not xi >= start:  # before the grid (or NaN, as np.interp's left)
            out[i] = 0.0 if xi < start else xi
            continue
        if xi >= last:
            out[i] = fp[n - 1]
            continue
        j = int((xi - start) / step)
        if j > n - 2:
            j = n - 2
        # The grid's own values decide the interval, as numpy's search over them does.
        while j > 0 and start + float(j) * step > xi:
            j -= 1
        while j < n - 2 and start + float(j + 1) * step <= xi:
            j += 1
        x0 = start + float(j) * step
        x1 = start + float(j + 1) * step
        slope = (fp[j + 1] - fp[j]) / (x1 - x0)
        value = slope * (xi - x0) + fp[j]
        if value != value:  # numpy's fallbacks where the slope is not finite
            value = slope * (xi - x1) + fp[j + 1]
            if value != value and fp[j] == fp[j + 1]:
                value = fp[j]
        out[i] = value
    return out
