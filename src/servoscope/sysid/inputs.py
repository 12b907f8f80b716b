"""Test inputs as pure functions of the time since the input's start.

A frequency sweep (chirp) is written here once, below every stage that needs it:
the twin renders it (:class:`servoscope.simulate.InputSignal`), the manifest
describes it (:class:`servoscope.campaign.manifest.TestSpec`), the rig drives it
and the identification reads it. Nothing here imports servoscope beyond the
foundation.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from ..errors import ServoscopeError

__all__ = ["SWEEP_SHAPES", "recorded_command", "sweep_command", "sweep_problems", "sweep_frequency_hz"]

#: The sweep shapes a manifest may name, and scipy.signal.chirp's method for each.
SWEEP_SHAPES = {"log": "logarithmic", "linear": "linear"}


def sweep_problems(from_hz, to_hz, duration_s, shape) -> list[tuple[str, str]]:
    """What is wrong with a sweep's parameters: ``(key, message)`` pairs, empty when none.

    ``from_hz`` must be > 0 (a logarithmic sweep cannot start at 0 Hz, and a linear
    one starting there is no test of anything), ``to_hz`` > ``from_hz``, ``duration_s``
    > 0 and ``shape`` one of :data:`SWEEP_SHAPES`. A None value counts as missing.
    """
    out: list[tuple[str, str]] = []

    def number(key, value):
        if value is None:
            out.append((key, "missing: a sweep test needs it"))
            return None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            out.append((key, f"must be a finite number, got {value!r}"))
            return None
        if value <= 0:
            out.append((key, f"must be > 0, got {value!r}"))
            return None
        return float(value)

    lo = number("from_hz", from_hz)
    hi = number("to_hz", to_hz)
    number("duration_s", duration_s)
    if lo is not None and hi is not None and not hi > lo:
        out.append(("to_hz", f"must be > from_hz ({lo:g} Hz), got {hi:g}"))
    if shape not in SWEEP_SHAPES:
        import difflib

        near = difflib.get_close_matches(str(shape), sorted(SWEEP_SHAPES), n=1)
        hint = f" (did you mean {near[0]!r}?)" if near else ""
        out.append(("shape", f"unknown sweep shape {shape!r}{hint} (use \"log\" or \"linear\")"))
    return out


def _checked(from_hz, to_hz, duration_s, shape) -> None:
    problems = sweep_problems(from_hz, to_hz, duration_s, shape)
    if problems:
        raise ServoscopeError("sweep: " + "; ".join(f"{k}: {m}" for k, m in problems))


def sweep_command(t_rel_s, amplitude: float, from_hz: float, to_hz: float, duration_s: float,
                  shape: str = "log") -> np.ndarray:
    """A frequency sweep's command at ``t_rel_s`` seconds after the input's start.

    ``amplitude · scipy.signal.chirp(t, from_hz, duration_s, to_hz, method, phi=-90)`` for
    ``0 ≤ t ≤ duration_s`` (a sine that starts at zero, its frequency swept from ``from_hz``
    to ``to_hz``, ``method`` "logarithmic" for shape "log", "linear" for "linear"), 0 before
    the start and after the sweep.

    Parameters
    ----------
    t_rel_s : array_like
        Time since the input's start, seconds.
    amplitude : float
        Input units.
    from_hz, to_hz : float
        Start and end frequencies, Hz (``0 < from_hz < to_hz``).
    duration_s : float
        Length of the sweep, seconds.
    shape : {"log", "linear"}

    Returns
    -------
    ndarray
        Same shape as ``t_rel_s``.
    """
    _checked(from_hz, to_hz, duration_s, shape)
    t = np.asarray(t_rel_s, dtype=float)
    inside = (t >= 0.0) & (t <= duration_s)
    v = scipy.signal.chirp(np.clip(t, 0.0, duration_s), float(from_hz), float(duration_s), float(to_hz),
                           method=SWEEP_SHAPES[shape], phi=-90.0)
    return np.where(inside, float(amplitude) * v, 0.0)


def sweep_frequency_hz(t_rel_s, from_hz: float, to_hz: float, duration_s: float, shape: str = "log") -> np.ndarray:
    """The sweep's instantaneous frequency at ``t_rel_s`` (Hz; clipped to the sweep's span)."""
    _checked(from_hz, to_hz, duration_s, shape)
    t = np.clip(np.asarray(t_rel_s, dtype=float), 0.0, duration_s) / duration_s
    if shape == "log":
        return from_hz * (to_hz / from_hz) ** t
    return from_hz + (to_hz - from_hz) * t


def recorded_command(t_rel_s, time_s, command) -> np.ndarray:
    """A recorded input's command at ``t_rel_s`` seconds after the input's start.

    The samples ``(time_s, command)`` (``time_s`` strictly increasing, ≥ 0, seconds after the
    start) joined by straight lines (:func:`numpy.interp`); 0 before the start, as every
    other kind (the LED dates the input's first instant), the first sample's value from the
    start to the first sample, and the last sample's value after the last (a stick left where
    the pilot let go).

    Parameters
    ----------
    t_rel_s : array_like
        Time since the input's start, seconds.
    time_s, command : array_like
        The recording's samples, seconds and input units.

    Returns
    -------
    ndarray
        Same shape as ``t_rel_s``.
    """
    t = np.asarray(t_rel_s, dtype=float)
    v = np.interp(t, np.asarray(time_s, dtype=float), np.asarray(command, dtype=float))
    return np.where(t >= 0.0, v, 0.0)
