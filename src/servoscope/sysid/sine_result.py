"""The result of one sine dwell's fit: :class:`SineFit` (made by :func:`~servoscope.sysid.fit_sine`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from servoscope.results import fields_from_summary, html_table, import_pandas, jsonable, readonly
from servoscope.sysid.plotting import new_axes, plot_dwell

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.axes import Axes

__all__ = ["SineFit", "wrap_pi"]


def wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    w = math.remainder(angle_rad, 2.0 * math.pi)
    return math.pi if w == -math.pi else w


@dataclass(frozen=True)
class SineFit:
    """Result of :func:`~servoscope.sysid.fit_sine` for one sine dwell.

    The fitted output is
    ``offset + amplitude * sin(2*pi*frequency_hz*(t - t0_s) + phase_rad)``.

    Attributes
    ----------
    frequency_hz : float
        Fitted (refined) frequency in Hz; the commanded one when
        ``refine_frequency=False``.
    frequency_stderr_hz : float or None
        Standard error of `frequency_hz` in Hz (None when not refined).
    commanded_frequency_hz : float
        The frequency passed to :func:`fit_sine`, in Hz.
    amplitude : float
        Output amplitude (>= 0), in output units (e.g. rad).
    amplitude_stderr : float
        Standard error of `amplitude`, output units.
    phase_rad : float or None
        Phase of the output relative to the input sine
        ``sin(2*pi*f*(t - t0))``, in rad, wrapped to (-pi, pi]; None when
        ``t0_s`` is unknown. A lagging system has a negative phase.
    phase_stderr_rad : float or None
        Standard error of `phase_rad`, in rad.
    offset : float
        Constant term of the fit, output units.
    offset_stderr : float
        Standard error of `offset`.
    residual_rms : float
        Root-mean-square residual, output units.
    fidelity : float
        Sinusoidal fidelity: power of the fitted fundamental divided by the
        total AC power of the window, ``1 - sum(residual**2) /
        sum((y - mean(y))**2)``; 1.0 for a pure sine. Low values expose
        nonlinearity or noise.
    n_samples : int
        Number of samples in the steady-state window.
    window_s : tuple of float
        (first, last) sample time of the window, in s.
    t0_s : float or None
        Input start time used as phase reference, in s.
    reference_time_s : float
        Time origin ``tr`` of the cos/sin terms (``t0_s`` if known, else the
        first time of the window), in s.
    warnings : tuple of str
        Non-fatal problems (short window, few samples, energy not at the
        commanded frequency, ...).
    settle_s : float
        Time skipped after ``t0_s`` (or the first sample), in s: the value
        given, or the one detected with ``settle_s="auto"``.
    harmonic_amplitudes : tuple of (float or None)
        Amplitudes of harmonics 2..5 (output units); None for those at or
        above 95 % of the Nyquist frequency (not fitted).
    harmonic_amplitude_stderrs : tuple of (float or None)
        Their standard errors.
    thd : float
        Total harmonic distortion ``sqrt(sum A_k**2)/amplitude`` over the
        fitted harmonics (NaN when none could be fitted).
    harmonic_residual_rms : float
        RMS residual after removing the fundamental and the harmonics
        (the noise floor), output units.
    invalid_fraction : float
        Share of the frames inside the window that were invalid or NaN.
    null_harmonic_amplitudes : tuple of (float or None) or None
        Amplitudes of harmonics 2..5 in the null channel (the measurement's
        motion-locked artefacts), when one was given.
    estimator : str
        "all frames", or "intra frames" when `amplitude` and `phase_rad`
        come from the intra-coded frames alone (the codec check, module
        docstring).
    n_intra : int
        Intra-coded frames in the window (0 when unknown).
    all_frames_amplitude, all_frames_phase_rad : float or None
        The all-frame fit's amplitude and phase, when the codec check ran.
    codec_gain_bias, codec_gain_bias_stderr : float or None
        All-frame amplitude over intra-frame amplitude, minus 1, and its
        standard error: the codec's effect on this dwell's gain.
    codec_phase_bias_rad, codec_phase_bias_stderr_rad : float or None
        All-frame phase minus intra-frame phase (rad), and its standard error.
    flags : tuple of str
        Short codes of the problems found (see the module docstring).
    time_s, y, residual : numpy.ndarray
        The window's sample times (s), samples and residuals ``y - model``.
    covariance : numpy.ndarray
        Covariance of the internal parameters ``(offset, a, b[, f])`` with
        the cos/sin terms referenced to the window's mean time.
    """

    frequency_hz: float
    frequency_stderr_hz: float | None
    commanded_frequency_hz: float
    amplitude: float
    amplitude_stderr: float
    phase_rad: float | None
    phase_stderr_rad: float | None
    offset: float
    offset_stderr: float
    residual_rms: float
    fidelity: float
    n_samples: int
    window_s: tuple[float, float]
    t0_s: float | None
    reference_time_s: float
    warnings: tuple[str, ...]
    time_s: NDArray[np.float64] = field(repr=False, compare=False)
    y: NDArray[np.float64] = field(repr=False, compare=False)
    residual: NDArray[np.float64] = field(repr=False, compare=False)
    covariance: NDArray[np.float64] = field(repr=False, compare=False)
    settle_s: float = float("nan")
    harmonic_amplitudes: tuple[float | None, ...] = ()
    harmonic_amplitude_stderrs: tuple[float | None, ...] = ()
    thd: float = float("nan")
    harmonic_residual_rms: float = float("nan")
    invalid_fraction: float = 0.0
    flags: tuple[str, ...] = ()
    null_harmonic_amplitudes: tuple[float | None, ...] | None = None
    estimator: str = "all frames"
    n_intra: int = 0
    all_frames_amplitude: float | None = None
    all_frames_phase_rad: float | None = None
    codec_gain_bias: float | None = None
    codec_gain_bias_stderr: float | None = None
    codec_phase_bias_rad: float | None = None
    codec_phase_bias_stderr_rad: float | None = None
    _center_s: float = field(repr=False, compare=False, default=0.0)
    _cos_coef: float = field(repr=False, compare=False, default=0.0)
    _sin_coef: float = field(repr=False, compare=False, default=0.0)

    @property
    def omega_rad_s(self) -> float:
        """Fitted angular frequency in rad/s."""
        return 2.0 * math.pi * self.frequency_hz

    @property
    def phase_deg(self) -> float | None:
        """`phase_rad` in degrees (None when unknown)."""
        return None if self.phase_rad is None else math.degrees(self.phase_rad)

    @property
    def phase_stderr_deg(self) -> float | None:
        """`phase_stderr_rad` in degrees (None when unknown)."""
        return None if self.phase_stderr_rad is None else math.degrees(self.phase_stderr_rad)

    def model(self, time_s: ArrayLike) -> NDArray[np.float64]:
        """Evaluate the fitted sinusoid.

        Parameters
        ----------
        time_s : array_like
            Times in s (same clock as the fitted data).

        Returns
        -------
        numpy.ndarray
            Fitted output, output units.
        """
        t = np.asarray(time_s, dtype=float)
        theta = 2.0 * math.pi * self.frequency_hz * (t - self._center_s)
        return self.offset + self._cos_coef * np.cos(theta) + self._sin_coef * np.sin(theta)

    @classmethod
    def from_summary(cls, data: dict[str, Any], *, time_s: ArrayLike = (), y: ArrayLike = ()) -> "SineFit":
        """Rebuild a fit from its :meth:`summary` (a dwell of a saved result.json).

        Parameters
        ----------
        data : dict
            What :meth:`summary` returned.
        time_s, y : array_like, optional
            The window's samples (the track's), for :meth:`plot` and :meth:`to_pandas`.

        Returns
        -------
        SineFit
            Its :meth:`summary` equals `data`. The fitted curve (:meth:`model`) is rebuilt
            from amplitude and phase about ``t0_s``; without a known phase it is the offset
            alone.
        """
        t, v = readonly(time_s), readonly(y)
        a, phase = data.get("amplitude") or 0.0, data.get("phase_rad")
        ref = data.get("t0_s") if data.get("t0_s") is not None else data.get("window_s", [0.0])[0]
        known = phase is not None and data.get("t0_s") is not None
        kw = fields_from_summary(cls, data, time_s=t, y=v, residual=readonly([]),
                                 covariance=readonly(np.full((3, 3), np.nan)), reference_time_s=float(ref),
                                 _center_s=float(ref), _cos_coef=a * math.sin(phase) if known else 0.0,
                                 _sin_coef=a * math.cos(phase) if known else 0.0)
        fit = cls(**kw)
        if v.size:  # the residual of the samples against the rebuilt curve
            object.__setattr__(fit, "residual", readonly(v - fit.model(t)))
        return fit

    def summary(self) -> dict[str, Any]:
        """Scalar results as a JSON-serializable dict (NaN -> None)."""
        return jsonable(
            {
                "frequency_hz": self.frequency_hz,
                "frequency_stderr_hz": self.frequency_stderr_hz,
                "commanded_frequency_hz": self.commanded_frequency_hz,
                "amplitude": self.amplitude,
                "amplitude_stderr": self.amplitude_stderr,
                "phase_rad": self.phase_rad,
                "phase_stderr_rad": self.phase_stderr_rad,
                "offset": self.offset,
                "offset_stderr": self.offset_stderr,
                "residual_rms": self.residual_rms,
                "fidelity": self.fidelity,
                "n_samples": self.n_samples,
                "window_s": list(self.window_s),
                "t0_s": self.t0_s,
                "settle_s": self.settle_s,
                "harmonic_amplitudes": list(self.harmonic_amplitudes),
                "null_harmonic_amplitudes": (
                    None if self.null_harmonic_amplitudes is None else list(self.null_harmonic_amplitudes)
                ),
                "thd": self.thd,
                "harmonic_residual_rms": self.harmonic_residual_rms,
                "invalid_fraction": self.invalid_fraction,
                "flags": list(self.flags),
                "warnings": list(self.warnings),
                "estimator": self.estimator,
                "n_intra": self.n_intra,
                "all_frames_amplitude": self.all_frames_amplitude,
                "all_frames_phase_rad": self.all_frames_phase_rad,
                "codec_gain_bias": self.codec_gain_bias,
                "codec_gain_bias_stderr": self.codec_gain_bias_stderr,
                "codec_phase_bias_rad": self.codec_phase_bias_rad,
                "codec_phase_bias_stderr_rad": self.codec_phase_bias_stderr_rad,
            }
        )

    def to_pandas(self) -> Any:
        """Window samples, fitted values and residuals as a pandas DataFrame.

        Columns: ``time_s``, ``y``, ``fitted``, ``residual``. Requires pandas.
        """
        pd = import_pandas()
        return pd.DataFrame(
            {
                "time_s": np.asarray(self.time_s),
                "y": np.asarray(self.y),
                "fitted": self.model(self.time_s),
                "residual": np.asarray(self.residual),
            }
        )

    def plot(self, ax: Axes | None = None) -> list[Any]:
        """Draw the window's samples, the fitted sine and the window on `ax` (a new figure's when None).

        Returns
        -------
        list
            The artists (:func:`~servoscope.sysid.plotting.plot_dwell`): the measured line
            (x = `time_s`, y = `y`), the fitted line (y = ``model(time_s)``), the window's span
            and, when `t0_s` is known, its line.
        """
        return plot_dwell(new_axes(ax), self.time_s, self.y, self.model(self.time_s), self.window_s, t0_s=self.t0_s)

    def _repr_html_(self) -> str:
        return html_table(self.summary(), "SineFit")
