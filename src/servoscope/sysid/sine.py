"""Fit a sinusoid to one sine-dwell recording.

The collective input of a sine dwell is ``u(t) = A_in * sin(2*pi*f*(t - t0))``
for ``t >= t0`` (``t0`` is the instant the LED switches off). Once the
transient has died out, a linear system responds with
``y(t) = offset + amplitude * sin(2*pi*f*(t - t0) + phase_rad)``;
:func:`fit_sine` estimates those quantities, with standard errors, from the
steady-state part of the record.

Method
------
The model ``offset + a*cos(w*(t - tc)) + b*sin(w*(t - tc))`` (``tc``: the mean
time of the window, for good conditioning) is first fitted by linear least
squares at the commanded frequency. With ``refine_frequency=True`` the
frequency is then freed and ``(offset, a, b, f)`` are refined with
:func:`scipy.optimize.least_squares`. Standard errors come from the
Newey–West (HAC) covariance of the fit (:func:`hac_covariance`: Bartlett
kernel, lag the larger of ``floor(4 (n/100)**(2/9))`` and Andrews' AR(1)
plug-in), because tracking errors are
correlated from frame to frame (on the twin's raw footage the lag-1
autocorrelation of the tracking error is up to 0.2 at slow dwells, on
H.264 up to 0.9); for white residuals it equals the classical
residual-variance-scaled covariance on average. The phase relative to ``t0`` is
obtained from the phase at ``tc`` by the delta method, so its standard error
includes the frequency uncertainty times the lever arm ``tc - t0``.

Steady-state window (``settle_s="auto"``)
-----------------------------------------
A reference model (offset, fundamental with a linear phase drift, 2nd and
3rd harmonics) is fitted to the second half of the record after ``t0`` and
subtracted from all of it. The transient (and the dead time, during which
the output has not moved yet) shows up as a residual well above the
second half's noise: the window starts at the end of the last sliding
window (8 samples) whose RMS residual exceeds 3 times that noise (noise
floored at 1e-4 of the amplitude). The same test, run with a numeric ``settle_s``, warns
when a transient is still visible after it.

Sinusoidal fidelity and harmonics
---------------------------------
``fidelity`` is the share of the window's AC power in the fitted
fundamental (the paper's check, its Fig. 8: a flattened sine leaves a
periodic residual). Harmonics 2 to 5 (those below 95 % of the Nyquist
frequency of the samples) are fitted jointly with the fundamental by
linear least squares at the fitted frequency; ``thd`` is
``sqrt(sum A_k**2) / A_1``. ``flags`` names the problems found:
``low_fidelity`` (< 0.95), ``distorted`` (THD > 1 % and the harmonics
significant at the 0.1 % level in a joint Wald test with the same HAC
covariance, plus, when a ``null_channel`` is given, the variance of the
measurement's own motion-locked artefacts: the null channel's harmonics,
pooled over 2..5, added to each harmonic's two coefficients — pixel
locking and codec errors repeat every period, so no noise model tells
them from distortion, but a channel the motion cannot reach shows them), ``aliasing`` (frequency at or above 80 %
of the Nyquist frequency), ``frequency_mismatch``, ``few_periods`` (< 2),
``few_samples`` (< 20), ``invalid_frames`` (> 20 % of the frames in the
window invalid), ``transient`` (not over within the window), ``flat``,
``codec`` (below).

The codec check (``intra``)
---------------------------
A video codec codes most frames as changes from other frames (P- and
B-frames), and at a camcorder's bit rate it drops changes too small to pay
for: a sticker that moves less than a pixel per frame is held back, and
the dwell's amplitude shrinks (measured on the twin: MPEG-2 at 25 Mbit/s,
HDV's, loses 0.2 % at 0.5 Hz and 4.5 % at 15 Hz; its B-frames alone 6 %).
Frames coded on their own (I-frames) show the sticker where it is. When
``intra`` marks them and at least 8 of them, but not all frames, fall in
the steady-state window, the fundamental is fitted to them alone, at the
frequency fitted to all frames: that fit is free of the codec's motion
bias, and its standard error says how well they alone determine it.
``amplitude``, ``phase_rad`` and their standard errors are then the intra
fit's (``estimator = "intra frames"``), unless its amplitude's standard
error exceeds 4 times the all-frame fit's (their times fall at nearly one
phase of the sine: an I-frame rate close to the dwell's frequency or a
multiple), when the all-frame fit is kept with a warning. The difference
between the two fits (``codec_gain_bias``, ``codec_phase_bias_rad``, with
standard errors) is the codec's bias as measured on this dwell; beyond 3
standard errors it is flagged ``codec``. Footage whose frames are all
intra-coded (uncompressed, MJPEG, intra-only codecs) or that has fewer
I-frames (a GOP of seconds) is fitted on all frames as before.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares
from scipy.stats import chi2 as chi2_dist

from servoscope.defaults import DISTORTED_THD, LOW_FIDELITY, MAX_INVALID_FRACTION, NEAR_NYQUIST
from servoscope.errors import ServoscopeError
from servoscope.results import html_table, import_pandas, jsonable, readonly
# The null channel is a property of the two markers' tracks; re-exported here, where fit_sine uses it.
from servoscope.markers.error_analysis import rigid_motion_null

__all__ = ["SineFit", "fit_sine", "hac_covariance", "newey_west_lag", "rigid_motion_null"]

_MIN_SAMPLES = 5
#: Intra-coded frames in the window needed for the codec check.
_MIN_INTRA = 8
#: The intra fit replaces the all-frame fit unless its amplitude error is this many times larger.
_INTRA_SE_RATIO = 4.0
_FEW_SAMPLES = 20
_FEW_PERIODS = 2.0
_HARMONICS = (2, 3, 4, 5)
_TRANSIENT_SIGMAS = 3.0
#: Newey–West (HAC) standard errors instead of the white-noise ones.
_HAC = True


def _wrap_pi(angle_rad: float) -> float:
    """Wrap an angle to (-pi, pi]."""
    w = math.remainder(angle_rad, 2.0 * math.pi)
    return math.pi if w == -math.pi else w


@dataclass(frozen=True)
class SineFit:
    """Result of :func:`fit_sine` for one sine dwell.

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

    def _repr_html_(self) -> str:
        return html_table(self.summary(), "SineFit")


def _design(t: NDArray[np.float64], freq_hz: float, tc: float) -> NDArray[np.float64]:
    theta = 2.0 * math.pi * freq_hz * (t - tc)
    return np.column_stack([np.ones_like(t), np.cos(theta), np.sin(theta)])


def _fit_power(t: NDArray[np.float64], y: NDArray[np.float64], freqs: NDArray[np.float64], tc: float) -> NDArray[np.float64]:
    """Floating-mean periodogram: AC power explained by a sine at each frequency.

    For each frequency, the sum of squares explained by the least-squares fit
    of ``offset + a*cos + b*sin`` beyond the mean (same units as ``y**2``).
    """
    yc = y - y.mean()
    th = 2.0 * math.pi * np.outer(freqs, t - tc)
    c = np.cos(th)
    s = np.sin(th)
    c -= c.mean(axis=1, keepdims=True)
    s -= s.mean(axis=1, keepdims=True)
    cc = np.einsum("ij,ij->i", c, c)
    ss = np.einsum("ij,ij->i", s, s)
    cs = np.einsum("ij,ij->i", c, s)
    cy = c @ yc
    sy = s @ yc
    det = cc * ss - cs * cs
    ok = det > 1e-12 * np.maximum(cc * ss, 1e-300)
    out = np.zeros(freqs.size)
    # explained SS = v^T M^{-1} v with M = [[cc, cs], [cs, ss]], v = [cy, sy]
    out[ok] = (ss[ok] * cy[ok] ** 2 - 2 * cs[ok] * cy[ok] * sy[ok] + cc[ok] * sy[ok] ** 2) / det[ok]
    return out


def _steady_state_start(
    t: NDArray[np.float64], y: NDArray[np.float64], freq_hz: float, t_from: float
) -> tuple[float, bool]:
    """Start of the steady state after ``t_from`` (see the module docstring).

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
    exceed = np.nonzero(ok & (rms > _TRANSIENT_SIGMAS * sigma))[0]
    if exceed.size == 0:
        return t_from, False
    start = float(ts[exceed[-1]]) + width
    if start >= mid:
        return mid, True
    return max(start, t_from), False


def newey_west_lag(n: int) -> int:
    """Bandwidth (largest lag) of the Newey–West covariance for ``n`` samples.

    Newey & West (1994)'s rule of thumb for the Bartlett kernel,
    ``floor(4 * (n / 100)**(2/9))`` (the default of statsmodels'
    ``cov_type="HAC"`` users and of Stock & Watson's textbook); at least 1.
    """
    return max(1, int(math.floor(4.0 * (max(n, 1) / 100.0) ** (2.0 / 9.0))))


def andrews_lag(residual: ArrayLike) -> int:
    """Data-dependent Bartlett bandwidth of Andrews (1991), AR(1) plug-in.

    ``ceil(1.1447 * (alpha * n)**(1/3))`` with ``alpha = 4 rho**2 /
    ((1 - rho)**2 (1 + rho)**2)`` and ``rho`` the lag-1 autocorrelation of
    the residuals (clipped to ±0.97). Strongly correlated errors (as H.264
    tracking errors of slow dwells, rho ≈ 0.9) need many more lags than
    :func:`newey_west_lag` gives.
    """
    r = np.asarray(residual, dtype=float).ravel()
    n = r.size
    if n < 3:
        return 1
    r = r - r.mean()
    den = float(r @ r)
    rho = float(r[1:] @ r[:-1]) / den if den > 0 else 0.0
    rho = min(max(rho, -0.97), 0.97)
    alpha = 4.0 * rho * rho / ((1.0 - rho) ** 2 * (1.0 + rho) ** 2)
    return max(1, int(math.ceil(1.1447 * (alpha * n) ** (1.0 / 3.0))))


def hac_covariance(
    jac: NDArray[np.float64], residual: NDArray[np.float64], lag: int | None = None
) -> NDArray[np.float64]:
    """Newey–West (HAC) covariance of least-squares parameters.

    The sandwich ``B @ S @ B`` with ``B = inv(J.T @ J)`` and ``S`` the
    long-run covariance of the scores ``u_t = J[t] * r[t]`` estimated with
    Bartlett weights ``1 - l/(L + 1)`` for lags ``l <= L`` (Newey & West
    1987), times the small-sample factor ``n / (n - p)`` (as statsmodels'
    ``use_correction``). For white residuals it equals the classical
    ``s**2 * inv(J.T @ J)`` on average; residuals correlated from frame to
    frame (tracking errors that depend on the marker's sub-pixel position
    change slowly as it moves) make it larger where the classical one is
    too small. For a sinusoidal regressor it measures, in effect, the
    residual's spectral density at the regressor's frequency.

    Parameters
    ----------
    jac : numpy.ndarray, shape (n, p)
        Jacobian (design matrix) of the model at the estimate, rows in time
        order (samples equally spaced, gaps of invalid frames ignored).
    residual : numpy.ndarray, shape (n,)
        Residuals at the estimate, same order.
    lag : int, optional
        Largest lag L; default the larger of :func:`newey_west_lag` and
        :func:`andrews_lag` of the residuals, at most ``n // 2``.

    Returns
    -------
    numpy.ndarray, shape (p, p)
        Covariance matrix; NaN when ``n <= p``.
    """
    J = np.asarray(jac, dtype=float)
    r = np.asarray(residual, dtype=float)
    n, p = J.shape
    if n <= p:
        return np.full((p, p), np.nan)
    L = min(max(newey_west_lag(n), andrews_lag(r)), n // 2) if lag is None else int(lag)
    u = J * r[:, None]
    S = u.T @ u
    for l in range(1, min(L, n - 1) + 1):
        g = u[l:].T @ u[:-l]
        S += (1.0 - l / (L + 1.0)) * (g + g.T)
    try:
        B = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        B = np.linalg.pinv(J.T @ J)
    return (B @ S @ B) * (n / (n - p))


def _harmonics(
    t: NDArray[np.float64], y: NDArray[np.float64], freq_hz: float, tc: float, dt_s: float,
    artefact: list[float | None] | None = None,
) -> tuple[list[float | None], list[float | None], float, float]:
    """Amplitudes (and stderrs) of harmonics 2..5, the p-value of the joint
    Wald test that they are all zero, and the residual RMS.

    ``artefact`` (amplitudes per harmonic 2..5, as returned for a null
    channel) adds ``A**2 / 2`` to the variance of both coefficients of each
    harmonic in the test: harmonics no larger than the measurement's own
    artefacts are not significant."""
    th = 2.0 * math.pi * freq_hz * (t - tc)
    ks = [k for k in _HARMONICS if dt_s > 0 and k * freq_hz < 0.95 * 0.5 / dt_s]
    cols = [np.ones_like(t), np.cos(th), np.sin(th)]
    for k in ks:
        cols += [np.cos(k * th), np.sin(k * th)]
    X = np.column_stack(cols)
    n, p = X.shape
    amps: list[float | None] = [None] * len(_HARMONICS)
    ses: list[float | None] = [None] * len(_HARMONICS)
    if n <= p:
        return amps, ses, float("nan"), float("nan")
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    r = y - X @ coef
    s2 = float(r @ r) / (n - p)
    if _HAC:
        # The same noise model as the fundamental's: correlated tracking
        # errors would otherwise make any harmonic look significant.
        cov = hac_covariance(X, r)
    else:
        try:
            cov = np.linalg.inv(X.T @ X) * s2
        except np.linalg.LinAlgError:
            cov = np.linalg.pinv(X.T @ X) * s2
    for j, k in enumerate(ks):
        a, b = float(coef[3 + 2 * j]), float(coef[4 + 2 * j])
        sub = cov[3 + 2 * j : 5 + 2 * j, 3 + 2 * j : 5 + 2 * j]
        amp = math.hypot(a, b)
        g = np.array([a, b]) / amp if amp > 0 else np.array([math.sqrt(0.5), math.sqrt(0.5)])
        amps[_HARMONICS.index(k)] = amp
        ses[_HARMONICS.index(k)] = math.sqrt(max(float(g @ sub @ g), 0.0))
    # Joint Wald test that all harmonic coefficients are zero.
    p_value = float("nan")
    if ks:
        v = coef[3:]
        block = cov[3:, 3:].copy()
        if artefact is not None:
            for j, k in enumerate(ks):
                extra = artefact[_HARMONICS.index(k)]
                if extra is not None and math.isfinite(extra):
                    block[2 * j, 2 * j] += 0.5 * extra * extra
                    block[2 * j + 1, 2 * j + 1] += 0.5 * extra * extra
        try:
            chi2 = float(v @ np.linalg.solve(block, v)) if s2 > 0 else math.inf
        except np.linalg.LinAlgError:
            chi2 = float(v @ np.linalg.pinv(block) @ v)
        p_value = float(chi2_dist.sf(chi2, 2 * len(ks)))
    return amps, ses, p_value, math.sqrt(float(r @ r) / n)


def fit_sine(
    time_s: ArrayLike,
    y: ArrayLike,
    frequency_hz: float,
    *,
    t0_s: float | None = None,
    settle_s: float | str = "auto",
    valid: ArrayLike | None = None,
    refine_frequency: bool | str = "auto",
    t0_stderr_s: float | None = None,
    null_channel: ArrayLike | None = None,
    intra: ArrayLike | None = None,
) -> SineFit:
    """Fit ``offset + amplitude*sin(2*pi*f*(t - t0) + phase)`` to a sine dwell.

    Parameters
    ----------
    time_s : array_like, shape (n,)
        Sample (frame) times in s.
    y : array_like, shape (n,)
        Measured output (e.g. blade pitch angle in rad). NaNs are excluded.
    frequency_hz : float
        Commanded input frequency in Hz (> 0).
    t0_s : float, optional
        Input start time in s (LED off). Needed for the phase.
    settle_s : float or "auto", default "auto"
        Time in s skipped after ``t0_s`` (or after the first sample when
        ``t0_s`` is None) to let the transient die out; "auto" detects the
        end of the transient from the data (module docstring). With a
        number, a transient still visible after it is warned about.
    valid : array_like of bool, shape (n,), optional
        False marks frames to exclude.
    refine_frequency : {"auto", True, False}, default "auto"
        True: also fit the frequency (nonlinear least squares) instead of
        fixing it at the commanded value. "auto": fit it, but keep the refined
        value only when it differs from the commanded one by more than 3
        standard errors (a free frequency on a short window costs phase
        accuracy). In both cases ``frequency_stderr_hz`` is the refined
        fit's standard error. False: the commanded frequency, no stderr.
    t0_stderr_s : float, optional
        Standard uncertainty of ``t0_s`` (s); it adds ``2πf·t0_stderr_s`` in
        quadrature to the phase's standard error.
    null_channel : array_like, shape (n,), optional
        A signal from the same measurement, in output units, that the true
        motion does not reach but the measurement's artefacts do (e.g.
        :func:`~servoscope.markers.error_analysis.rigid_motion_null` of the two markers); NaN where unknown.
        Its harmonics at the fitted frequency measure the artefacts that are
        locked to the motion (pixel locking, codec), which no noise model
        can tell from distortion; they are added to the harmonics' variance
        in the distortion test (module docstring).
    intra : array_like of bool, shape (n,), optional
        True for the frames the codec coded on their own (I-frames): the
        codec check (module docstring).

    Returns
    -------
    SineFit

    Raises
    ------
    ServoscopeError
        Inputs of mismatched shapes, a non-positive frequency, or fewer than
        5 usable samples in the window.
    """
    t_all = np.asarray(time_s, dtype=float).ravel()
    y_all = np.asarray(y, dtype=float).ravel()
    if t_all.shape != y_all.shape:
        raise ServoscopeError(
            f"fit_sine: time_s has {t_all.size} samples but y has {y_all.size}"
        )
    f_cmd = float(frequency_hz)
    if not (math.isfinite(f_cmd) and f_cmd > 0):
        raise ServoscopeError(f"fit_sine: frequency_hz must be positive, got {frequency_hz!r}")
    auto_settle = isinstance(settle_s, str)
    if auto_settle and settle_s != "auto":
        raise ServoscopeError(f"fit_sine: settle_s must be a number >= 0 or 'auto', got {settle_s!r}")
    if not auto_settle and not (math.isfinite(float(settle_s)) and float(settle_s) >= 0):
        raise ServoscopeError(f"fit_sine: settle_s must be >= 0, got {settle_s!r}")
    if t0_s is not None and not math.isfinite(float(t0_s)):
        raise ServoscopeError(f"fit_sine: t0_s must be finite, got {t0_s!r}")
    mask = np.isfinite(t_all) & np.isfinite(y_all)
    if valid is not None:
        v = np.asarray(valid, dtype=bool).ravel()
        if v.shape != t_all.shape:
            raise ServoscopeError(
                f"fit_sine: valid has {v.size} entries but time_s has {t_all.size}"
            )
        mask &= v
    if not np.any(np.isfinite(t_all)):
        raise ServoscopeError("fit_sine: no finite sample times")
    if not np.any(mask):
        raise ServoscopeError("fit_sine: no valid frames (every sample is invalid or NaN)")
    origin = float(t0_s) if t0_s is not None else float(np.nanmin(t_all))
    warnings: list[str] = []
    flags: list[str] = []
    o_all = np.argsort(t_all[mask], kind="stable")
    t_ok, y_ok = t_all[mask][o_all], y_all[mask][o_all]
    detected, too_long = _steady_state_start(t_ok, y_ok, f_cmd, origin)
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
    mask &= t_all >= start
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
    if n_periods < _FEW_PERIODS:
        warnings.append(
            f"steady-state window covers only {n_periods:.2f} periods (< {_FEW_PERIODS:g})"
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

    tc = float(np.mean(t))
    yc = yw - yw.mean()
    sst = float(yc @ yc)
    scale = float(np.max(np.abs(yw)))
    flat = sst == 0.0 or math.sqrt(sst / n) <= 1e-10 * scale
    if flat:
        sst = 0.0
        warnings.append("no AC signal in the steady-state window (constant output)")
        flags.append("flat")

    # Linear fit at the commanded frequency.
    X = _design(t, f_cmd, tc)
    coef, *_ = np.linalg.lstsq(X, yw, rcond=None)
    params = np.array([coef[0], coef[1], coef[2], f_cmd])

    # Periodogram check: is the energy where the commanded frequency says?
    if span > 0 and dt_med > 0 and sst > 0:
        res_f = 1.0 / span
        lo = max(f_cmd / 3.0, 0.5 * res_f)
        hi = min(3.0 * f_cmd, 0.5 / dt_med)
        if hi > lo:
            n_grid = int(min(2000, max(50, math.ceil((hi - lo) / (0.1 * res_f)))))
            grid = np.linspace(lo, hi, n_grid)
            power = _fit_power(t, yw, grid, tc)
            k = int(np.argmax(power))
            p_cmd = float(_fit_power(t, yw, np.array([f_cmd]), tc)[0])
            if abs(grid[k] - f_cmd) > 1.5 * res_f and power[k] > 2.0 * max(p_cmd, 0.0):
                warnings.append(
                    f"periodogram peak at {grid[k]:.4g} Hz, not at the commanded "
                    f"{f_cmd:.4g} Hz (power there is {p_cmd / power[k]:.2g} of the peak)"
                )
                flags.append("frequency_mismatch")

    if refine_frequency not in (True, False, "auto"):
        raise ServoscopeError(f"fit_sine: refine_frequency must be True, False or 'auto', got {refine_frequency!r}")
    p_names = 3
    refined_se: float | None = None
    if refine_frequency is not False and not flat:
        two_pi = 2.0 * math.pi
        dtc = t - tc

        def resid(p: NDArray[np.float64]) -> NDArray[np.float64]:
            th = two_pi * p[3] * dtc
            return p[0] + p[1] * np.cos(th) + p[2] * np.sin(th) - yw

        def jac(p: NDArray[np.float64]) -> NDArray[np.float64]:
            th = two_pi * p[3] * dtc
            c, s = np.cos(th), np.sin(th)
            J = np.empty((n, 4))
            J[:, 0] = 1.0
            J[:, 1] = c
            J[:, 2] = s
            J[:, 3] = two_pi * dtc * (-p[1] * s + p[2] * c)
            return J

        if n > 5:
            sol = least_squares(resid, params, jac=jac, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
            J4 = jac(sol.x)
            s2_refined = float(sol.fun @ sol.fun) / (n - 4)
            try:
                f_var = float(np.linalg.inv(J4.T @ J4)[3, 3]) * s2_refined
            except np.linalg.LinAlgError:
                f_var = float("inf")
            refined_se = math.sqrt(max(f_var, 0.0))
            # "auto" keeps the refined frequency only when the data say it
            # differs from the commanded one: when the rig's and the camera's
            # clocks agree, a free frequency only adds phase noise.
            significant = abs(sol.x[3] - f_cmd) > 3.0 * refined_se
            # Over less than two periods, or with the transient still in the window, a
            # frequency that differs from the commanded one is the transient's or the
            # drift's fingerprint, not a clock's: "auto" keeps the command there.
            trusted = n_periods >= _FEW_PERIODS and "transient" not in flags
            if sol.x[3] > 0 and (refine_frequency is True or (significant and trusted)):
                params = sol.x
                p_names = 4
                if span > 0 and abs(params[3] - f_cmd) > 2.0 / span:
                    warnings.append(
                        f"refined frequency {params[3]:.4g} Hz is far from the commanded "
                        f"{f_cmd:.4g} Hz"
                    )
                    flags.append("frequency_mismatch")
        Jm = jac(params)[:, :p_names]
    else:
        Jm = _design(t, f_cmd, tc)

    c0, a, b = float(params[0]), float(params[1]), float(params[2])
    f_hat = float(params[3])
    theta_hat = 2.0 * math.pi * f_hat * (t - tc)
    model_vals = c0 + a * np.cos(theta_hat) + b * np.sin(theta_hat)
    residual = yw - model_vals
    ssr = float(residual @ residual)
    dof = n - p_names
    s2 = ssr / dof if dof > 0 else float("nan")
    JtJ = Jm.T @ Jm
    try:
        cov = np.linalg.inv(JtJ) * s2
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(JtJ) * s2
        warnings.append("singular Jacobian: standard errors are unreliable")
    if _HAC and dof > 0:
        # Tracking errors are not white: they depend on where the marker
        # sits on the pixel grid, which changes slowly from frame to frame.
        # The Newey–West covariance accounts for that correlation.
        cov = hac_covariance(Jm, residual)

    amp = math.hypot(a, b)
    # Delta method for amplitude and phase at tc.
    if amp > 0:
        g_amp = np.zeros(p_names)
        g_amp[1], g_amp[2] = a / amp, b / amp
        amp_se = math.sqrt(max(float(g_amp @ cov @ g_amp), 0.0))
    else:
        amp_se = math.sqrt(max(float(cov[1, 1] + cov[2, 2]) / 2.0, 0.0))
    offset_se = math.sqrt(max(float(cov[0, 0]), 0.0))
    f_se: float | None = math.sqrt(max(float(cov[3, 3]), 0.0)) if p_names == 4 else refined_se

    phase: float | None = None
    phase_se: float | None = None
    if t0_s is not None:
        # y = amp*sin(w(t - tc) + phi_c), phi_c = atan2(a, b);
        # relative to t0: phi = phi_c + w*(t0 - tc).
        phi_c = math.atan2(a, b)
        lever = float(t0_s) - tc
        phase = _wrap_pi(phi_c + 2.0 * math.pi * f_hat * lever)
        g_ph = np.zeros(p_names)
        amp2 = amp * amp  # may underflow to 0 for a vanishing amplitude (found by hypothesis)
        if amp2 > 0:
            g_ph[1], g_ph[2] = b / amp2, -a / amp2
        if p_names == 4:
            g_ph[3] = 2.0 * math.pi * lever
        phase_se = math.sqrt(max(float(g_ph @ cov @ g_ph), 0.0)) if amp2 > 0 else float("nan")
        if t0_stderr_s is not None and math.isfinite(phase_se):
            phase_se = math.hypot(phase_se, 2.0 * math.pi * f_hat * float(t0_stderr_s))

    check = _codec_check(intra, t_all, y_all, mask, n, flat, f_hat, tc, amp, amp_se, phase,
                         None if p_names != 4 else float(cov[3, 3]), t0_s, t0_stderr_s)
    if check is not None:
        warnings.extend(check.pop("warnings"))
        flags.extend(check.pop("flags"))
        if check["estimator"] == "intra frames":
            amp, amp_se = check["amplitude"], check["amplitude_stderr"]
            phase, phase_se = check["phase_rad"], check["phase_stderr_rad"]
        for key in ("amplitude", "amplitude_stderr", "phase_rad", "phase_stderr_rad"):
            check.pop(key, None)

    fidelity = 1.0 - ssr / sst if sst > 0 else float("nan")
    ref = float(t0_s) if t0_s is not None else float(t[0])
    null_amps: list[float | None] | None = None
    if null_channel is not None:
        z_all = np.asarray(null_channel, dtype=float).ravel()
        if z_all.shape != t_all.shape:
            raise ServoscopeError(
                f"fit_sine: null_channel has {z_all.size} samples but time_s has {t_all.size}"
            )
        zm = mask & np.isfinite(z_all)
        if np.count_nonzero(zm) > 2 * len(_HARMONICS) + 3:
            null_amps = _harmonics(t_all[zm], z_all[zm], f_hat, tc, dt_med)[0]
    artefact = None
    if null_amps is not None:
        # One null channel is one draw of the artefacts: pooled over the
        # harmonics, its power is a steadier estimate of their size at each.
        sq = [a * a for a in null_amps if a is not None]
        pooled = math.sqrt(sum(sq) / len(sq)) if sq else None
        artefact = [None if a is None else pooled for a in null_amps]
    h_amps, h_ses, h_p, h_rms = _harmonics(t, yw, f_hat, tc, dt_med, artefact)
    fitted = [a for a in h_amps if a is not None]
    thd = math.sqrt(sum(a * a for a in fitted)) / amp if fitted and amp > 0 else float("nan")
    if math.isfinite(fidelity) and fidelity < LOW_FIDELITY:
        warnings.append(
            f"low sinusoidal fidelity {fidelity:.3f} (< {LOW_FIDELITY:g}): the output is not a clean sine "
            "(nonlinearity or noise)"
        )
        flags.append("low_fidelity")
    if math.isfinite(thd) and thd > DISTORTED_THD and h_p < 1e-3:
        warnings.append(
            f"harmonic distortion {100 * thd:.1f} % (> {100 * DISTORTED_THD:g} %): nonlinear response "
            "(rate limit, backlash, saturation?)"
        )
        flags.append("distorted")

    return SineFit(
        frequency_hz=f_hat,
        frequency_stderr_hz=f_se,
        commanded_frequency_hz=f_cmd,
        amplitude=amp,
        amplitude_stderr=amp_se,
        phase_rad=phase,
        phase_stderr_rad=phase_se,
        offset=c0,
        offset_stderr=offset_se,
        residual_rms=math.sqrt(ssr / n),
        fidelity=fidelity,
        n_samples=int(n),
        window_s=(float(t[0]), float(t[-1])),
        t0_s=None if t0_s is None else float(t0_s),
        reference_time_s=ref,
        warnings=tuple(warnings),
        settle_s=float(settle_used),
        harmonic_amplitudes=tuple(h_amps),
        harmonic_amplitude_stderrs=tuple(h_ses),
        thd=float(thd),
        harmonic_residual_rms=float(h_rms),
        invalid_fraction=float(invalid_fraction),
        flags=tuple(dict.fromkeys(flags)),
        null_harmonic_amplitudes=None if null_amps is None else tuple(null_amps),
        time_s=readonly(t),
        y=readonly(yw),
        residual=readonly(residual),
        covariance=readonly(cov),
        _center_s=tc,
        _cos_coef=a,
        _sin_coef=b,
        **(check or {}),
    )


def _codec_check(intra: ArrayLike | None, t_all: NDArray[np.float64], y_all: NDArray[np.float64],
                 mask: NDArray[np.bool_], n: int, flat: bool, f_hat: float, tc: float, amp: float, amp_se: float,
                 phase: float | None, f_var: float | None, t0_s: float | None,
                 t0_stderr_s: float | None) -> dict[str, Any] | None:
    """The fundamental fitted to the intra-coded frames alone, and its difference from all frames'.

    Returns None when the check does not apply (module docstring), else the
    SineFit fields (``estimator``, ``n_intra``, ``all_frames_*``,
    ``codec_*``) plus the intra fit's ``amplitude``, ``phase_rad`` and their
    standard errors, and ``warnings`` and ``flags`` to add.
    """
    if intra is None:
        return None
    i_all = np.asarray(intra, dtype=bool).ravel()
    if i_all.shape != t_all.shape:
        raise ServoscopeError(f"fit_sine: intra has {i_all.size} entries but time_s has {t_all.size}")
    sel = mask & i_all
    n_i = int(np.count_nonzero(sel))
    if flat or n_i == n:
        return None
    out: dict[str, Any] = {"estimator": "all frames", "n_intra": n_i, "warnings": [], "flags": []}
    if n_i < _MIN_INTRA:
        return out
    ti, yi = t_all[sel], y_all[sel]
    X = _design(ti, f_hat, tc)
    if np.linalg.cond(X) > 1e3:
        # Every intra frame at (nearly) one phase of the sine: cos and sin are (almost) constant there.
        out["warnings"].append(
            f"codec check impossible: the {n_i} intra-coded frames all fall at one phase of the sine (the "
            "I-frame rate is the dwell's frequency or a multiple of it); gain and phase from all frames"
        )
        return out
    coef, *_ = np.linalg.lstsq(X, yi, rcond=None)
    r = yi - X @ coef
    if _HAC:
        # Errors that depend on where the sticker sits on the pixel grid change slowly on slow
        # dwells: correlated from one intra frame to the next too.
        order = np.argsort(ti, kind="stable")
        cov = hac_covariance(X[order], r[order])
    else:
        # X is well conditioned here (checked above).
        cov = np.linalg.inv(X.T @ X) * (float(r @ r) / (n_i - 3))
    a, b = float(coef[1]), float(coef[2])
    amp_i = math.hypot(a, b)
    if not amp_i > 0:
        return out
    g = np.array([0.0, a / amp_i, b / amp_i])
    amp_i_se = math.sqrt(max(float(g @ cov @ g), 0.0))
    phase_i = phase_i_se = None
    gp = np.array([0.0, b / amp_i**2, -a / amp_i**2])
    var_at_tc = max(float(gp @ cov @ gp), 0.0)  # the intra fit's phase at tc
    if t0_s is not None:
        lever = float(t0_s) - tc
        phase_i = _wrap_pi(math.atan2(a, b) + 2.0 * math.pi * f_hat * lever)
        var = var_at_tc
        if f_var is not None:
            var += (2.0 * math.pi * lever) ** 2 * f_var
        if t0_stderr_s is not None:
            var += (2.0 * math.pi * f_hat * float(t0_stderr_s)) ** 2
        phase_i_se = math.sqrt(var)
    # The two fits share the intra frames, so their difference is less uncertain than this: conservative.
    diff_se = math.hypot(amp_se, amp_i_se)
    out.update(
        all_frames_amplitude=amp, all_frames_phase_rad=phase,
        codec_gain_bias=amp / amp_i - 1.0, codec_gain_bias_stderr=diff_se / amp_i,
        amplitude=amp_i, amplitude_stderr=amp_i_se, phase_rad=phase_i, phase_stderr_rad=phase_i_se,
    )
    if phase is not None and phase_i is not None:
        # t0 and the frequency are common to both fits: the difference's error is that of the
        # phases at tc (the all-frame one ≈ its amplitude's relative error).
        out["codec_phase_bias_rad"] = _wrap_pi(phase - phase_i)
        out["codec_phase_bias_stderr_rad"] = math.hypot(math.sqrt(var_at_tc), amp_se / amp)
    if amp_i_se > _INTRA_SE_RATIO * amp_se:
        out["warnings"].append(
            f"codec check inconclusive: the {n_i} intra-coded frames fall at nearly one phase of the sine "
            f"(amplitude error {amp_i_se / amp_se:.0f}x the all-frame fit's); gain and phase from all frames"
        )
        return out
    out["estimator"] = "intra frames"
    big_gain = abs(amp - amp_i) > 3.0 * diff_se
    big_phase = ("codec_phase_bias_rad" in out
                 and abs(out["codec_phase_bias_rad"]) > 3.0 * out["codec_phase_bias_stderr_rad"])
    if big_gain or big_phase:
        out["warnings"].append(
            f"video compression: the frames the codec predicted from others move {100 * (amp / amp_i - 1.0):+.2f} % "
            f"(± {100 * diff_se / amp_i:.2f} %) against its {n_i} intra-coded frames"
            + (f", {math.degrees(out['codec_phase_bias_rad']):+.2f}° in phase" if "codec_phase_bias_rad" in out else "")
            + "; gain and phase taken from the intra-coded frames"
        )
        out["flags"].append("codec")
    return out
