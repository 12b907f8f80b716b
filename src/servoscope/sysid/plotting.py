"""Drawing sysid results on matplotlib axes.

The pieces that both the results' ``.plot(ax=None)`` methods
(:meth:`~servoscope.sysid.FrequencyResponse.plot`, :meth:`~servoscope.sysid.SineFit.plot`,
:meth:`~servoscope.sysid.StepAnalysis.plot`) and the report's figures
(:mod:`servoscope.report.figures`) draw with, so that a figure in a notebook and one in the
report are made by the same code. Each function draws data only (no titles, no axis labels)
and returns the artists it made.

matplotlib is imported only when a function needs to make new axes: importing servoscope
does not choose a backend.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes
    from matplotlib.container import ErrorbarContainer
    from matplotlib.lines import Line2D

__all__ = [
    "new_axes",
    "on_branch_deg",
    "plot_dwell",
    "plot_dwell_residual",
    "plot_gain",
    "plot_model_gain",
    "plot_model_phase",
    "plot_phase",
    "plot_step",
]


def new_axes(ax: Axes | None) -> Axes:
    """`ax`, or the axes of a new figure (pyplot's current backend) when None."""
    if ax is not None:
        return ax
    import matplotlib.pyplot as plt

    _, ax = plt.subplots()
    return ax


def on_branch_deg(phase_deg: ArrayLike, reference_deg: ArrayLike) -> np.ndarray:
    """``phase_deg`` moved by whole turns to the branch nearest ``reference_deg`` (a phase is known modulo 360°).

    Where measured phases are drawn beside a model's continuous phase (a dead time takes it past −180°), or
    a model's beside a measured one; NaN stays NaN.
    """
    phase = np.asarray(phase_deg, dtype=float)
    return phase + 360.0 * np.round((np.asarray(reference_deg, dtype=float) - phase) / 360.0)


def plot_gain(
    ax: Axes, omega_rad_s: ArrayLike, gain: ArrayLike, gain_stderr: ArrayLike | None = None, *, label: str = "measured",
    color: str = "C0", marker: str = "o", ms: float = 5, capsize: float = 3,
) -> ErrorbarContainer:
    """Measured gains in dB against angular frequency, with ±1 standard error bars.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    omega_rad_s, gain : array_like, shape (n,)
        Angular frequencies (rad/s) and gains (output units per input unit).
    gain_stderr : array_like, shape (n,), optional
        Standard errors of the gains (drawn in dB, first-order).
    label : str, default "measured"
    color, marker, ms, capsize
        The points' colour, marker and size, and the error bars' caps (two responses on one plot).

    Returns
    -------
    matplotlib.container.ErrorbarContainer
        Its first element is the line of the points: x = `omega_rad_s`, y = ``20*log10(gain)``.
    """
    gain_db = 20 * np.log10(np.asarray(gain))
    yerr = None
    if gain_stderr is not None:
        yerr = 20 / np.log(10) * np.asarray(gain_stderr) / np.asarray(gain)
    return ax.errorbar(omega_rad_s, gain_db, yerr=yerr, fmt=marker, ms=ms, color=color, capsize=capsize, label=label)


def plot_model_gain(ax: Axes, omega_rad_s: ArrayLike, gain: ArrayLike, *, label: str = "fitted model") -> Line2D:
    """A model's gain in dB against angular frequency (rad/s, log axis), as a line."""
    return ax.semilogx(omega_rad_s, 20 * np.log10(np.asarray(gain)), "-", color="C1", label=label)[0]


def plot_phase(ax: Axes, omega_rad_s: ArrayLike, phase_deg: ArrayLike, *, label: str = "measured") -> Line2D:
    """Measured phases in degrees against angular frequency (rad/s), as points (NaN: not drawn)."""
    return ax.plot(omega_rad_s, phase_deg, "o", ms=5, color="C0", label=label)[0]


def plot_model_phase(ax: Axes, omega_rad_s: ArrayLike, phase_deg: ArrayLike, *, label: str = "fitted model") -> Line2D:
    """A model's phase in degrees against angular frequency (rad/s), as a line."""
    return ax.plot(omega_rad_s, phase_deg, "-", color="C1", label=label)[0]


def plot_dwell(
    ax: Axes,
    time_s: ArrayLike,
    y: ArrayLike,
    fitted: ArrayLike,
    window_s: tuple[float, float],
    *,
    valid: ArrayLike | None = None,
    t0_s: float | None = None,
) -> list[Any]:
    """A sine dwell: the measured samples, the fitted sine over the window, the window shaded.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    time_s, y : array_like, shape (n,)
        Sample times (s) and measured output.
    fitted : array_like, shape (n,)
        The fitted sine at `time_s` (drawn inside the window only).
    window_s : (float, float)
        The steady-state window (first, last time), shaded.
    valid : array_like of bool, shape (n,), optional
        Samples to draw (default all).
    t0_s : float, optional
        Input start, a dotted vertical line.

    Returns
    -------
    list
        ``[measured line, fitted line, window span]`` and the t0 line when drawn.
    """
    time_s = np.asarray(time_s)
    y = np.asarray(y)
    fitted = np.asarray(fitted)
    valid = np.ones(time_s.shape, bool) if valid is None else np.asarray(valid, bool)
    measured = ax.plot(time_s[valid], y[valid], ".", ms=3, color="C0", label="measured")[0]
    inwin = valid & (time_s >= window_s[0]) & (time_s <= window_s[1])
    line = ax.plot(time_s[inwin], fitted[inwin], "-", color="C1", lw=1.2, label="fitted sine")[0]
    return [measured, line, *_window_marks(ax, window_s, t0_s)]


def plot_dwell_residual(
    ax: Axes,
    time_s: ArrayLike,
    y: ArrayLike,
    fitted: ArrayLike,
    window_s: tuple[float, float],
    *,
    valid: ArrayLike | None = None,
    t0_s: float | None = None,
) -> list[Any]:
    """The residual ``y - fitted`` over the window (arguments as :func:`plot_dwell`).

    Returns
    -------
    list
        ``[window span, (t0 line,) residual line]``.
    """
    time_s = np.asarray(time_s)
    y = np.asarray(y)
    fitted = np.asarray(fitted)
    valid = np.ones(time_s.shape, bool) if valid is None else np.asarray(valid, bool)
    inwin = valid & (time_s >= window_s[0]) & (time_s <= window_s[1])
    marks = _window_marks(ax, window_s, t0_s)
    return [*marks, ax.plot(time_s[inwin], y[inwin] - fitted[inwin], "-", color="C3", lw=0.8)[0]]


def _window_marks(ax: Axes, window_s: tuple[float, float], t0_s: float | None) -> list[Any]:
    marks = [ax.axvspan(window_s[0], window_s[1], color="C2", alpha=0.06)]
    if t0_s is not None:
        marks.append(ax.axvline(t0_s, color="k", ls=":", lw=1))
    ax.grid(True, alpha=0.3)
    return marks


def plot_step(
    ax: Axes,
    time_s: ArrayLike,
    y: ArrayLike,
    predicted: ArrayLike | None,
    *,
    valid: ArrayLike | None = None,
    t0_s: float | None = None,
    dead_time_s: float | None = None,
) -> list[Any]:
    """A step response: measured samples, the model's prediction, the input start and dead time.

    Parameters
    ----------
    ax : matplotlib.axes.Axes
    time_s, y : array_like, shape (n,)
        Sample times (s) and measured output.
    predicted : array_like, shape (n,) or None
        The model's prediction at `time_s` (all of them).
    valid : array_like of bool, shape (n,), optional
        Samples to draw (default all).
    t0_s, dead_time_s : float, optional
        Input start and dead time (s): vertical lines at ``t0_s`` and ``t0_s + dead_time_s``.

    Returns
    -------
    list
        The measured line, then the prediction and the vertical lines that were drawn.
    """
    time_s = np.asarray(time_s)
    y = np.asarray(y)
    valid = np.ones(time_s.shape, bool) if valid is None else np.asarray(valid, bool)
    artists: list[Any] = [ax.plot(time_s[valid], y[valid], ".", ms=3, color="C0", label="measured")[0]]
    if predicted is not None:
        artists.append(ax.plot(time_s, predicted, "-", color="C1", lw=1.4, label="predicted (identified model)")[0])
    if t0_s is not None:
        artists.append(ax.axvline(t0_s, color="k", ls=":", lw=1, label="input start (LED off)"))
        if dead_time_s is not None:
            artists.append(
                ax.axvline(t0_s + dead_time_s, color="C2", ls="--", lw=1, label=f"dead time {1e3 * dead_time_s:.1f} ms")
            )
    return artists
