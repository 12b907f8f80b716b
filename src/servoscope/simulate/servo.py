"""Ground-truth actuator: a proper LTI transfer function with dead time and
optional hard nonlinearities (command quantization, rate limit, backlash).

The signal chain, in order::

    command u(t) --quantize--> --delay by dead_time--> --rate limit--> r(t)
    r(t) --G(s)--> y(t) --backlash (play operator)--> angle

* Quantization acts on the *command* (the digital set-point resolution of a
  servo driver), so it commutes with the delay.
* The rate limit acts on the delayed reference *before* the linear dynamics:
  it models a servo whose set-point slews at a bounded speed while the
  mechanics (G) stay linear. Putting it after G would make the output
  rate-limited but would no longer be "G applied to something", which is
  harder to reason about in tests.
* Backlash is a play operator (hysteresis of total width ``backlash``) on the
  output: the blade follows the servo only once the gap is taken up.

Linear models (no quantization, no rate limit) are simulated exactly: the
input generator (a step, or a sine as a two-state harmonic oscillator) is
appended to the state space and the augmented system is propagated with the
matrix exponential from one requested sample time to the next. There is no
internal grid and no interpolation, so the result is exact to rounding at any
sample times. Models with quantization or a rate limit are simulated on a
fine grid (``dt <= 1e-4 s``) that starts at the delayed onset, with the exact
first-order-hold discretisation of G (the input is linear between grid
points, which is exact for a rate-limited ramp); backlash is applied on the
same grid and the output is interpolated linearly to the sample times.

A sweep or a recorded input (an arbitrary input, no generator of a few states) takes
that grid simulation too, linear model or not. Its error is the input's linear
interpolation between grid points, at most ``A·(2π f dt)²/8`` (1.1e-5 of the
amplitude at 15 Hz), and the output's between them, of the same order: the
tests hold it to python-control's ``forced_response`` of the delayed input.
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field
from typing import Literal

import control
import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.signal

from numba import njit

from ..errors import ServoscopeError
from ..sysid.inputs import recorded_command, sweep_command, sweep_problems

__all__ = ["InputSignal", "ServoModel", "GRID_STEP_S"]

#: Internal grid step of the nonlinear simulation, seconds.
GRID_STEP_S = 1e-4


@dataclass(frozen=True)
class InputSignal:
    """A test input applied at ``t0_s`` (zero before).

    Parameters
    ----------
    kind : {"sine", "step", "sweep", "recorded"}
        Sine dwell, step, frequency sweep (chirp), or a recorded input (a pilot's: its samples).
    amplitude : float
        Amplitude in input units.
    frequency_hz : float or None
        Frequency of a sine, Hz; must be None (or is ignored) for a step or a sweep.
    t0_s : float
        Time at which the input is applied, seconds.
    from_hz, to_hz, duration_s : float or None
        A sweep's start and end frequencies (Hz) and length (s); None for the other kinds.
    shape : {"log", "linear"} or None
        A sweep's frequency law ("log" by default); None for the other kinds.
        See :func:`servoscope.sysid.inputs.sweep_command`.
    samples : (array_like, array_like) or None
        A recorded input's ``(time since t0_s, command)``, time strictly increasing and ≥ 0
        (:func:`servoscope.sysid.inputs.recorded_command`: straight lines between samples, the
        last value after them); None for the other kinds.
    """

    kind: Literal["sine", "step", "sweep", "recorded"]
    amplitude: float
    frequency_hz: float | None = None
    t0_s: float = 0.0
    from_hz: float | None = None
    to_hz: float | None = None
    duration_s: float | None = None
    shape: str | None = None
    samples: tuple[np.ndarray, np.ndarray] | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.kind not in ("sine", "step", "sweep", "recorded"):
            raise ServoscopeError(f"input kind must be 'sine', 'step', 'sweep' or 'recorded', not {self.kind!r}")
        if self.kind == "recorded":
            t, u = (np.array(v, dtype=float) for v in (self.samples or ((), ())))
            if (t.ndim != 1 or t.shape != u.shape or t.size < 2 or not np.isfinite(t).all()
                    or not np.isfinite(u).all() or t[0] < 0 or np.any(np.diff(t) <= 0)):
                raise ServoscopeError("a recorded input needs samples (time, command): finite, of one length >= 2, "
                                      "time strictly increasing from >= 0")
            object.__setattr__(self, "samples", (t, u))
        elif self.samples is not None:
            raise ServoscopeError(f"only a recorded input has samples, not a {self.kind}")
        if not math.isfinite(self.amplitude) or not math.isfinite(self.t0_s):
            raise ServoscopeError("input amplitude and t0_s must be finite")
        if self.kind == "sine":
            if self.frequency_hz is None or not (self.frequency_hz > 0 and math.isfinite(self.frequency_hz)):
                raise ServoscopeError(f"a sine input needs a positive frequency_hz, not {self.frequency_hz!r}")
        else:
            object.__setattr__(self, "frequency_hz", None)
        if self.kind == "sweep":
            if self.shape is None:
                object.__setattr__(self, "shape", "log")
            problems = sweep_problems(self.from_hz, self.to_hz, self.duration_s, self.shape)
            if problems:
                raise ServoscopeError("a sweep input: " + "; ".join(f"{k}: {m}" for k, m in problems))
            for key in ("from_hz", "to_hz", "duration_s"):
                object.__setattr__(self, key, float(getattr(self, key)))
        else:
            for key in ("from_hz", "to_hz", "duration_s", "shape"):
                object.__setattr__(self, key, None)

    @property
    def omega_rad_s(self) -> float:
        """Angular frequency of a sine (0 for a step or a sweep), rad/s."""
        return 2.0 * math.pi * self.frequency_hz if self.kind == "sine" else 0.0

    @property
    def end_s(self) -> float:
        """When the input ends: a sweep's ``t0_s + duration_s``; inf for a sine, a step, a recorded input (held)."""
        return self.t0_s + self.duration_s if self.kind == "sweep" else math.inf

    def value(self, time_s: np.ndarray | float) -> np.ndarray:
        """The input at ``time_s``.

        Parameters
        ----------
        time_s : array_like
            Times, seconds.

        Returns
        -------
        ndarray
            ``amplitude*sin(2*pi*f*(t - t0))`` (sine), ``amplitude`` (step) for
            ``t >= t0``, 0 before; a sweep's
            :func:`~servoscope.sysid.inputs.sweep_command` of ``t - t0`` (0 before and after);
            a recorded input's :func:`~servoscope.sysid.inputs.recorded_command` of ``t - t0``.
        """
        t = np.asarray(time_s, dtype=float)
        if self.kind == "recorded":
            return recorded_command(t - self.t0_s, *self.samples)
        if self.kind == "sweep":
            return sweep_command(t - self.t0_s, self.amplitude, self.from_hz, self.to_hz, self.duration_s, self.shape)
        on = t >= self.t0_s
        if self.kind == "sine":
            v = self.amplitude * np.sin(self.omega_rad_s * (t - self.t0_s))
        else:
            v = np.full_like(t, self.amplitude)
        return np.where(on, v, 0.0)


@dataclass(frozen=True)
class ServoModel:
    """Actuator model: ``G(s) = num(s)/den(s)`` with dead time and nonlinearities.

    Parameters
    ----------
    num, den : sequence of float
        Numerator and denominator coefficients, descending powers of s. The
        transfer function must be proper (``len(num) <= len(den)``).
    dead_time_s : float
        Pure delay between command and reference, seconds.
    input_quantization : float
        Command resolution (rounded to the nearest multiple); 0 disables.
    rate_limit_per_s : float or None
        Largest slew rate of the delayed reference, input units per second;
        None disables.
    backlash : float
        Total width of the play (dead band) on the output, output units;
        0 disables.
    """

    num: tuple[float, ...]
    den: tuple[float, ...]
    dead_time_s: float = 0.0
    input_quantization: float = 0.0
    rate_limit_per_s: float | None = None
    backlash: float = 0.0

    def __post_init__(self) -> None:
        num = np.trim_zeros(np.atleast_1d(np.asarray(self.num, dtype=float)), "f")
        den = np.trim_zeros(np.atleast_1d(np.asarray(self.den, dtype=float)), "f")
        if den.size == 0:
            raise ServoscopeError("servo model: the denominator is zero")
        if num.size == 0:
            num = np.zeros(1)
        if num.size > den.size:
            raise ServoscopeError("servo model: the transfer function must be proper (deg num <= deg den)")
        if not (np.all(np.isfinite(num)) and np.all(np.isfinite(den))):
            raise ServoscopeError("servo model: coefficients must be finite")
        object.__setattr__(self, "num", tuple(float(v) for v in num))
        object.__setattr__(self, "den", tuple(float(v) for v in den))
        if not (self.dead_time_s >= 0 and math.isfinite(self.dead_time_s)):
            raise ServoscopeError(f"servo model: dead_time_s must be >= 0, not {self.dead_time_s}")
        if not (self.input_quantization >= 0 and math.isfinite(self.input_quantization)):
            raise ServoscopeError("servo model: input_quantization must be >= 0")
        if self.rate_limit_per_s is not None and not (self.rate_limit_per_s > 0):
            raise ServoscopeError("servo model: rate_limit_per_s must be > 0 or None")
        if not (self.backlash >= 0 and math.isfinite(self.backlash)):
            raise ServoscopeError("servo model: backlash must be >= 0")

    # -- properties ---------------------------------------------------------
    @property
    def transfer_function(self) -> control.TransferFunction:
        """G(s) without dead time, as a python-control object."""
        return control.tf(list(self.num), list(self.den))

    @property
    def is_linear(self) -> bool:
        """True when no nonlinearity is enabled."""
        return self.input_quantization == 0 and self.rate_limit_per_s is None and self.backlash == 0

    @property
    def gain(self) -> float:
        """DC gain G(0) (inf for a pure integrator)."""
        if self.den[-1] == 0.0:
            return math.inf
        return self.num[-1] / self.den[-1]

    @property
    def natural_frequency_rad_s(self) -> float | None:
        """ω_n of a 2nd-order denominator ``a s² + b s + c`` (None otherwise)."""
        if len(self.den) != 3 or self.den[2] / self.den[0] <= 0:
            return None
        return math.sqrt(self.den[2] / self.den[0])

    @property
    def damping_ratio(self) -> float | None:
        """ζ of a 2nd-order denominator ``a s² + b s + c`` (None otherwise)."""
        wn = self.natural_frequency_rad_s
        if wn is None:
            return None
        return self.den[1] / (2.0 * wn * self.den[0])

    def magnitude(self, omega_rad_s: np.ndarray | float) -> np.ndarray:
        """|G(jω)|."""
        s = 1j * np.asarray(omega_rad_s, dtype=float)
        return np.abs(np.polyval(self.num, s) / np.polyval(self.den, s))

    def truth(self) -> dict:
        """The servo as truth.json states it (``model``): plain types, the gain None where infinite."""
        return {
            "num": list(self.num), "den": list(self.den), "gain": self.gain if math.isfinite(self.gain) else None,
            "natural_frequency_rad_s": self.natural_frequency_rad_s, "damping_ratio": self.damping_ratio,
            "dead_time_s": self.dead_time_s, "input_quantization": self.input_quantization,
            "rate_limit_per_s": self.rate_limit_per_s, "backlash": self.backlash,
        }

    @property
    def bandwidth_rad_s(self) -> float | None:
        """Lowest frequency at which |G(jω)| falls 3 dB below the DC gain.

        Found numerically: a log-spaced scan of |G(jω)| brackets the first
        crossing of ``|G(0)|/sqrt(2)``, then Brent's method refines it. None
        when the DC gain is 0 or infinite or the magnitude never drops that far.
        """
        g0 = abs(self.gain)
        if g0 == 0 or not math.isfinite(g0):
            return None
        level = g0 / math.sqrt(2.0)
        # Scan well beyond every pole and zero so that no crossing is missed.
        roots = np.concatenate([np.roots(self.den), np.roots(self.num) if len(self.num) > 1 else []])
        mags = np.abs(roots[np.abs(roots) > 0]) if roots.size else np.array([1.0])
        lo = (mags.min() if mags.size else 1.0) * 1e-4
        hi = (mags.max() if mags.size else 1.0) * 1e4
        w = np.geomspace(lo, hi, 20001)
        below = np.nonzero(self.magnitude(w) < level)[0]
        if below.size == 0:
            return None
        i = below[0]
        if i == 0:
            return float(w[0])
        f = lambda x: float(self.magnitude(x)) - level  # noqa: E731
        return float(scipy.optimize.brentq(f, w[i - 1], w[i], xtol=1e-14, rtol=1e-14))

    def state_space(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C, D) of a realization of G (controllable canonical form)."""
        a, b, c, d = scipy.signal.tf2ss(list(self.num), list(self.den))
        return (np.asarray(a, float), np.asarray(b, float).reshape(-1),
                np.asarray(c, float).reshape(-1), float(np.asarray(d).ravel()[0]))

    # -- simulation ---------------------------------------------------------
    def reference(self, signal: InputSignal, time_s: np.ndarray) -> np.ndarray:
        """The reference entering G: quantized, delayed, rate-limited input.

        Parameters
        ----------
        signal : InputSignal
            The command.
        time_s : array_like
            Sample times, seconds (any order).

        Returns
        -------
        ndarray
            r(t) at ``time_s`` (linear interpolation of the internal grid when
            a rate limit is active).
        """
        t = np.asarray(time_s, dtype=float)
        if self.rate_limit_per_s is None:
            return self._quantize(signal.value(t - self.dead_time_s))
        t_on, grid_t, r, _, _ = self._reference_grid(signal, float(np.max(t)) if t.size else 0.0)
        return np.where(t < t_on, 0.0, np.interp(t, grid_t, r))

    def response(self, signal: InputSignal, time_s: np.ndarray) -> np.ndarray:
        """Output (blade pitch, rad) at arbitrary sample times.

        The actuator is at rest (zero state, zero output) before the delayed
        onset ``signal.t0_s + dead_time_s``.

        Parameters
        ----------
        signal : InputSignal
            The command.
        time_s : array_like
            Sample times, seconds (any order, any spacing).

        Returns
        -------
        ndarray
            Output at ``time_s``, same shape.
        """
        t = np.asarray(time_s, dtype=float)
        flat = t.ravel()
        if flat.size == 0:
            return np.zeros_like(t)
        if not np.all(np.isfinite(flat)):
            raise ServoscopeError("response: sample times must be finite")
        if (self.input_quantization == 0 and self.rate_limit_per_s is None and self.backlash == 0
                and signal.kind not in ("sweep", "recorded")):
            out = self._linear_exact(signal, flat)
        else:
            out = self._nonlinear_grid(signal, flat)
        return out.reshape(t.shape)

    # -- internals ------------------------------------------------------------
    def _quantize(self, u: np.ndarray) -> np.ndarray:
        q = self.input_quantization
        if q == 0:
            return u
        # floor(x + 1/2): round half up, the same on both sides of every level.
        return q * np.floor(u / q + 0.5)

    def _augmented(self, signal: InputSignal) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """State matrix, initial state at onset and output row of G plus its input generator."""
        a, b, c, d = self.state_space()
        n = a.shape[0]
        amp = signal.amplitude
        if signal.kind == "sine":
            w = signal.omega_rad_s
            m = np.zeros((n + 2, n + 2))
            m[:n, :n] = a
            m[:n, n] = b * amp  # r = amp * w1
            # w1 = sin(w s), w2 = cos(w s): w1' = w w2, w2' = -w w1
            m[n, n + 1] = w
            m[n + 1, n] = -w
            z0 = np.zeros(n + 2)
            z0[n + 1] = 1.0
            row = np.concatenate([c, [d * amp, 0.0]])
        else:
            m = np.zeros((n + 1, n + 1))
            m[:n, :n] = a
            m[:n, n] = b * amp
            z0 = np.zeros(n + 1)
            z0[n] = 1.0
            row = np.concatenate([c, [d * amp]])
        return m, z0, row

    def _linear_exact(self, signal: InputSignal, t: np.ndarray) -> np.ndarray:
        t_on = signal.t0_s + self.dead_time_s
        out = np.zeros_like(t)
        after = t >= t_on
        if not np.any(after):
            return out
        idx = np.nonzero(after)[0]
        order = idx[np.argsort(t[idx], kind="stable")]
        tau = t[order] - t_on
        steps = np.diff(np.concatenate([[0.0], tau]))
        m, z0, row = self._augmented(signal)
        # One matrix exponential per interval; propagating from sample to
        # sample keeps every exponent small and the result exact to rounding.
        ys = _propagate_outputs(m, steps, z0, row)
        out[order] = ys
        return out

    def _reference_grid(self, signal: InputSignal, t_end_s: float
                        ) -> tuple[float, np.ndarray, np.ndarray, np.ndarray, float]:
        """Onset time, grid times, reference on the grid from the onset to t_end, and the grid step.

        Returns ``(t_on, grid_t, r, r_left, step)``: ``r[k]`` is the reference as the interval
        from grid point k starts, ``r_left[k]`` as the interval before it ends; they differ only
        where the input jumps at a grid point (a sweep's end, which its grid step puts on one,
        so that the jump is simulated exactly rather than as a ramp over one step).
        """
        t_on = signal.t0_s + self.dead_time_s
        span = max(t_end_s - t_on, 0.0)
        step = GRID_STEP_S
        if signal.kind == "sweep":
            # The largest step <= GRID_STEP_S that puts the sweep's end on the grid.
            step = signal.duration_s / max(math.ceil(signal.duration_s / GRID_STEP_S - 1e-9), 1)
        n = int(math.ceil(span / step)) + 2
        k = np.arange(n, dtype=float)
        grid_t = t_on + k * step
        if signal.kind == "sweep":
            # The delayed command at grid time t_on + k step is the command k steps after t0.
            rel = k * step
            k_end = int(round(signal.duration_s / step))
            if k_end < n:
                rel[k_end] = signal.duration_s
            u_left = self._quantize(sweep_command(rel, signal.amplitude, signal.from_hz, signal.to_hz,
                                                  signal.duration_s, signal.shape))
            u = u_left.copy()
            if k_end < n:
                u[k_end] = 0.0  # the input is off from the sweep's end on
        else:
            # The delayed command at grid time t_on + k dt is the command at t0 + k dt.
            u = self._quantize(signal.value(signal.t0_s + k * step))
            u_left = u
        if self.rate_limit_per_s is not None:
            r = _rate_limit(u_left, self.rate_limit_per_s * step)
            return t_on, grid_t, r, r, step
        return t_on, grid_t, u, u_left, step

    def _nonlinear_grid(self, signal: InputSignal, t: np.ndarray) -> np.ndarray:
        t_on, grid_t, r, r_left, step = self._reference_grid(signal, float(t.max()))
        a, b, c, d = self.state_space()
        phi, gam0, gam1 = _foh_discretize(a, b, step)
        y = _simulate_foh(phi, gam0, gam1, c, d, r, r_left)
        if self.backlash > 0:
            y = _play_operator(y, 0.5 * self.backlash)
        return np.where(t < t_on, 0.0, np.interp(t, grid_t, y))


def _foh_discretize(a: np.ndarray, b: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact discretisation for an input linear between samples.

    ``x[k+1] = phi x[k] + gam0 u[k] + gam1 u[k+1]``.
    """
    n = a.shape[0]
    m = np.zeros((n + 2, n + 2))
    m[:n, :n] = a * dt
    m[:n, n] = b * dt
    m[n, n + 1] = 1.0
    e = scipy.linalg.expm(m)
    phi = e[:n, :n]
    g1 = e[:n, n]      # ∫ e^{A s} B ds
    g2 = e[:n, n + 1]  # ∫ e^{A s} B (dt - s)/dt ds, the ramp's share
    return phi, g1 - g2, g2


@njit(cache=True)
def _matmul_into(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    # Plain loops, not ``@`` (numba's BLAS bindings) and no slice assignment (its generic
    # broadcasting): the two made _expm's compilation 6.4 s of a fresh process's first simulated
    # response, against ~1 s; for these few-state matrices the loops also run 6x faster.
    n = a.shape[0]
    for i in range(n):
        for j in range(n):
            s = 0.0
            for k in range(n):
                s += a[i, k] * b[k, j]
            out[i, j] = s


@njit(cache=True)
def _expm(a: np.ndarray) -> np.ndarray:
    """Matrix exponential by scaling and squaring with a Taylor series.

    The argument is scaled to 1-norm <= 0.5, where the degree-18 Taylor
    remainder is below 1e-24; for the few-state matrices here this is both
    faster than scipy's per-call overhead and accurate to rounding.
    """
    n = a.shape[0]
    norm = 0.0
    for j in range(n):
        col = 0.0
        for i in range(n):
            col += abs(a[i, j])
        norm = max(norm, col)
    squarings = 0
    if norm > 0.5:
        squarings = int(np.ceil(np.log2(norm / 0.5)))
    x = a / (2.0 ** squarings)
    result = np.eye(n)
    term = np.eye(n)
    work = np.empty((n, n))
    for k in range(1, 19):
        _matmul_into(term, x, work)
        for i in range(n):
            for j in range(n):
                term[i, j] = work[i, j] / k
                result[i, j] += term[i, j]
    for _ in range(squarings):
        _matmul_into(result, result, work)
        result, work = work, result
    return result


@njit(cache=True)
def _propagate_outputs(m: np.ndarray, steps: np.ndarray, z0: np.ndarray, row: np.ndarray) -> np.ndarray:
    n = z0.shape[0]
    z = z0.copy()
    znew = np.empty(n)
    out = np.empty(steps.shape[0])
    for k in range(steps.shape[0]):
        phi = _expm(m * steps[k])
        for i in range(n):
            s = 0.0
            for j in range(n):
                s += phi[i, j] * z[j]
            znew[i] = s
        z, znew = znew, z
        acc = 0.0
        for i in range(n):
            acc += row[i] * z[i]
        out[k] = acc
    return out


@njit(cache=True)
def _rate_limit(u: np.ndarray, max_step: float) -> np.ndarray:
    # r starts at 0 at the onset (the reference was at rest) and moves by at
    # most max_step per grid step towards the command held over that step.
    r = np.empty_like(u)
    prev = 0.0
    r[0] = 0.0
    for k in range(1, u.shape[0]):
        delta = u[k] - prev
        if delta > max_step:
            delta = max_step
        elif delta < -max_step:
            delta = -max_step
        prev = prev + delta
        r[k] = prev
    return r


@njit(cache=True)
def _simulate_foh(phi: np.ndarray, gam0: np.ndarray, gam1: np.ndarray, c: np.ndarray, d: float,
                  r: np.ndarray, r_left: np.ndarray) -> np.ndarray:
    # Interval k runs from r[k] (its start) to r_left[k + 1] (its end), linearly.
    n = phi.shape[0]
    x = np.zeros(n)
    xn = np.empty(n)
    y = np.empty(r.shape[0])
    y[0] = d * r[0]
    for k in range(r.shape[0] - 1):
        for i in range(n):
            s = gam0[i] * r[k] + gam1[i] * r_left[k + 1]
            for j in range(n):
                s += phi[i, j] * x[j]
            xn[i] = s
        x[:] = xn
        acc = d * r_left[k + 1]
        for i in range(n):
            acc += c[i] * x[i]
        y[k + 1] = acc
    return y


@njit(cache=True)
def _play_operator(y: np.ndarray, half_width: float) -> np.ndarray:
    # The output moves only when the input pushes against one side of the gap.
    out = np.empty_like(y)
    b = 0.0
    for k in range(y.shape[0]):
        if y[k] - b > half_width:
            b = y[k] - half_width
        elif y[k] - b < -half_width:
            b = y[k] + half_width
        out[k] = b
    return out
