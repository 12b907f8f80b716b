"""The steady-state window of a sine dwell, and the checks on what it holds.

Steps of :func:`~servoscope.sysid.fit_sine` (:mod:`servoscope.sysid.sine`, "Steady-state
window"): where the transient ends, which samples are fitted, and the warnings about them (too
few samples or periods, invalid frames, aliasing).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from servoscope.defaults import MAX_INVALID_FRACTION, NEAR_NYQUIST, TRANSIENT_SIGMAS
from servoscope.errors import ServoscopeError

__all__ = ["FEW_PERIODS", "Window", "select_window", "steady_state_start", "window_checks"]

_MIN_SAMPLES = 5
_FEW_SAMPLES = 20
#: Fewer periods in the window earn a "few_periods" flag (and keep the commanded frequency).
FEW_PERIODS = 2.0


def steady_state_start(
    t: NDArray[np.float64], y: NDArray[np.float64], freq_hz: float, t_from: float
) -> tuple[float, bool]:
    """Start of the steady state after ``t_from`` (:mod:`servoscope.sysid.sine`).

    Returns
    -------
    start_s : float
        First time of the steady state, s (``t_from`` when no transient is
        seen or the record is too short to tell).
    too_long : bool
        True when the transient seems to last beyond half the record (the
        start is then clamped to the middle of the record).
    """
    sel = t >= t_from
    ts, ys = t[sel], y[sel]
    if ts.size < 24:
        return t_from, False
    span = float(ts[-1] - ts[0])
    dt = float(np.median(np.diff(ts)))
    if not (span > 0 and dt > 0):
        return t_from, False
    mid = float(ts[0]) + 0.5 * span
    late = ts >= mid
    tc = float(np.mean(ts[late]))
    th = 2.0 * math.pi * freq_hz * (ts - tc)
    cols = [np.ones_like(ts), np.cos(th), np.sin(th), (ts - tc) * np.cos(th), (ts - tc) * np.sin(th)]
    for k in (2, 3):
        if k * freq_hz < 0.45 / dt:
            cols += [np.cos(k * th), np.sin(k * th)]
    X = np.column_stack(cols)
    n_late, p = int(np.count_nonzero(late)), X.shape[1]
    if n_late < p + 4:
        return t_from, False
    coef, *_ = np.linalg.lstsq(X[late], ys[late], rcond=None)
    r = ys - X @ coef
    amp = math.hypot(float(coef[1]), float(coef[2]))
    # Noise of the late half; floored at -80 dB of the sine so that
    # noise-free data do not wait for the transient to reach round-off.
    sigma = math.sqrt(float(r[late] @ r[late]) / (n_late - p))
    sigma = max(sigma, 1e-4 * amp, 1e-300)
    # Short windows (8 samples) locate the end of the transient to within a
    # few frames whatever the period; 8 samples keep the RMS test's false
    # alarm rate (3 sigma) below 1e-8 per window.
    width = min(8.0 * dt, 0.25 * span)
    end_idx = np.searchsorted(ts, ts + width, side="left")
    csum = np.concatenate([[0.0], np.cumsum(r**2)])
    idx = np.arange(ts.size)
    count = end_idx - idx
    ok = (count >= 4) & (ts < mid)
    rms = np.zeros(ts.size)
    rms[ok] = np.sqrt((csum[end_idx[ok]] - csum[idx[ok]]) / count[ok])
    exceed = np.nonzero(ok & (rms > TRANSIENT_SIGMAS * sigma))[0]
    if exceed.size == 0:
        return t_from, False
    start = float(ts[exceed[-1]]) + width
    if start >= mid:
        return mid, True
    return max(start, t_from), False


class Window(NamedTuple):
    """The samples of the steady-state window, in time order."""

    t: NDArray[np.float64]
    y: NDArray[np.float64]
    #: Which of all the samples are in it (finite, valid, after the start).
    mask: NDArray[np.bool_]
    #: Start of the window minus the input start (or the first sample), s.
    settle_s: float
    #: Share of the frames after the start that are invalid.
    invalid_fraction: float


def select_window(
    t_all: NDArray[np.float64], y_all: NDArray[np.float64], mask: NDArray[np.bool_], f_cmd: float,
    t0_s: float | None, settle_s: float | str, warnings: list[str], flags: list[str],
) -> Window:
    """The steady-state window: from ``t0_s + settle_s``, or where the transient ends ("auto").

    Appends to `warnings` and `flags` a transient still visible after a numeric `settle_s`,
    or one lasting beyond half the record.

    Raises
    ------
    ServoscopeError
        Fewer than 5 usable samples in the window.
    """
    auto_settle = isinstance(settle_s, str)
    origin = float(t0_s) if t0_s is not None else float(np.nanmin(t_all))
    o_all = np.argsort(t_all[mask], kind="stable")
    t_ok, y_ok = t_all[mask][o_all], y_all[mask][o_all]
    detected, too_long = steady_state_start(t_ok, y_ok, f_cmd, origin)
    if auto_settle:
        start = detected
    else:
        start = origin + float(settle_s)
        step = float(np.median(np.diff(t_ok))) if t_ok.size > 1 else 0.0
        if detected > start + step:
            warnings.append(
                f"a transient is still visible {detected - origin:.3g} s after the input start, "
                f"beyond settle_s = {float(settle_s):g} s; consider settle_s='auto'"
            )
            flags.append("transient")
    if too_long:
        warnings.append("the transient seems to last beyond half the record: record a longer dwell")
        flags.append("transient")
    settle_used = start - origin
    in_window = np.isfinite(t_all) & (t_all >= start)
    mask = mask & (t_all >= start)
    n_frames = int(np.count_nonzero(in_window))
    invalid_fraction = 1.0 - np.count_nonzero(mask) / n_frames if n_frames else 1.0
    order = np.argsort(t_all[mask], kind="stable")
    t = t_all[mask][order]
    yw = y_all[mask][order]
    n = t.size
    if n < _MIN_SAMPLES:
        raise ServoscopeError(
            f"fit_sine: only {n} usable samples after t = {start:.4g} s "
            f"(need at least {_MIN_SAMPLES}); record longer or reduce settle_s"
        )
    return Window(t, yw, mask, settle_used, invalid_fraction)


def window_checks(
    t: NDArray[np.float64], f_cmd: float, invalid_fraction: float, warnings: list[str], flags: list[str]
) -> tuple[float, float, float]:
    """Flag invalid frames, too few samples or periods, and aliasing in the window `t`.

    Returns
    -------
    span_s, n_periods, dt_median_s : float
        The window's length, the commanded periods in it and the median sample spacing
        (NaN for one sample).
    """
    n = t.size
    if invalid_fraction > MAX_INVALID_FRACTION:
        warnings.append(
            f"{100 * invalid_fraction:.0f} % of the frames in the steady-state window are invalid "
            f"(> {100 * MAX_INVALID_FRACTION:g} %)"
        )
        flags.append("invalid_frames")
    span = float(t[-1] - t[0])
    n_periods = span * f_cmd
    if n < _FEW_SAMPLES:
        warnings.append(f"only {n} samples in the steady-state window (< {_FEW_SAMPLES})")
        flags.append("few_samples")
    if n_periods < FEW_PERIODS:
        warnings.append(
            f"steady-state window covers only {n_periods:.2f} periods (< {FEW_PERIODS:g})"
        )
        flags.append("few_periods")
    dt_med = float(np.median(np.diff(t))) if n > 1 else float("nan")
    if dt_med > 0 and f_cmd >= 0.5 / dt_med:
        warnings.append(
            f"commanded frequency {f_cmd:g} Hz is at or above the Nyquist frequency "
            f"{0.5 / dt_med:g} Hz of the samples"
        )
        flags.append("aliasing")
    elif dt_med > 0 and f_cmd >= NEAR_NYQUIST * 0.5 / dt_med:
        warnings.append(
            f"commanded frequency {f_cmd:g} Hz is close to the Nyquist frequency "
            f"{0.5 / dt_med:g} Hz of the samples: aliasing risk, few samples per period"
        )
        flags.append("aliasing")
    return span, n_periods, dt_med
