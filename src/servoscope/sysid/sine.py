"""Fit a sinusoid to one sine-dwell recording.

:func:`fit_sine` and its own steps; the window (:mod:`._sine_window`), harmonics
(:mod:`._sine_harmonics`), codec check (:mod:`._sine_codec`), covariance (:mod:`.hac`) and
result (:mod:`.sine_result`) live beside it.

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

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from servoscope.defaults import DISTORTED_THD, LOW_FIDELITY, SETTLE_AUTO
from servoscope.errors import ServoscopeError

# The null channel is a property of the two markers' tracks; re-exported here, where fit_sine uses it.
from servoscope.markers.error_analysis import rigid_motion_null
from servoscope.results import readonly
from servoscope.sysid import hac
from servoscope.sysid._sine_codec import codec_check
from servoscope.sysid._sine_harmonics import HARMONICS, design_matrix, fit_harmonics, fit_power
from servoscope.sysid._sine_window import FEW_PERIODS, select_window, window_checks
from servoscope.sysid.hac import andrews_lag, hac_covariance, newey_west_lag
from servoscope.sysid.sine_result import SineFit, wrap_pi

__all__ = ["SineFit", "andrews_lag", "fit_sine", "hac_covariance", "newey_west_lag", "rigid_motion_null"]


def fit_sine(
    time_s: ArrayLike,
    y: ArrayLike,
    frequency_hz: float,
    *,
    t0_s: float | None = None,
    settle_s: float | str = SETTLE_AUTO,
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
        (``servoscope identify`` passes campaign.toml's ``[analysis]
        settle_s``: :data:`~servoscope.defaults.SETTLE_S` unless it says a
        number or "auto".)
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

    Notes
    -----
    The steps, in order: the inputs checked (:func:`_checked_inputs`), the steady-state window
    and its checks (:mod:`._sine_window`), the linear fit at the commanded frequency, the
    periodogram check, the frequency refined (:func:`_refine_frequency`), the covariance,
    amplitude and phase, the codec check (:mod:`._sine_codec`), the harmonics and the quality
    flags (:mod:`._sine_harmonics`). This function only sequences them (about 80 lines, most of
    them the result's fields).

    Raises
    ------
    ServoscopeError
        Inputs of mismatched shapes, a non-positive frequency, or fewer than
        5 usable samples in the window.

    Long because it is the fit's order written out (window, frequency, least squares,
    covariance, harmonics, codec check, flags), each step a call to its module.
    """
    t_all, y_all, f_cmd, mask = _checked_inputs(time_s, y, frequency_hz, t0_s, settle_s, valid)
    warnings: list[str] = []
    flags: list[str] = []
    win = select_window(t_all, y_all, mask, f_cmd, t0_s, settle_s, warnings, flags)
    t, yw, mask = win.t, win.y, win.mask
    n = t.size
    span, n_periods, dt_med = window_checks(t, f_cmd, win.invalid_fraction, warnings, flags)

    tc = float(np.mean(t))
    sst, flat = _ac_power(yw, warnings, flags)
    # Linear fit at the commanded frequency.
    X = design_matrix(t, f_cmd, tc)
    coef, *_ = np.linalg.lstsq(X, yw, rcond=None)
    params = np.array([coef[0], coef[1], coef[2], f_cmd])
    _periodogram_check(t, yw, f_cmd, tc, span, dt_med, sst, warnings, flags)
    if refine_frequency not in (True, False, "auto"):
        raise ServoscopeError(f"fit_sine: refine_frequency must be True, False or 'auto', got {refine_frequency!r}")
    params, Jm, refined_se = _refine_frequency(t, yw, tc, params, refine_frequency, flat, n_periods, span,
                                               warnings, flags)

    c0, a, b = float(params[0]), float(params[1]), float(params[2])
    f_hat = float(params[3])
    theta_hat = 2.0 * math.pi * f_hat * (t - tc)
    model_vals = c0 + a * np.cos(theta_hat) + b * np.sin(theta_hat)
    residual = yw - model_vals
    ssr = float(residual @ residual)
    cov = _covariance(Jm, residual, ssr, warnings)
    amp, amp_se, offset_se, f_se = _amplitude_offset_frequency(a, b, cov, refined_se)
    phase, phase_se = _phase(a, b, amp, cov, f_hat, tc, t0_s, t0_stderr_s)

    check = codec_check(intra, t_all, y_all, mask, n, flat, f_hat, tc, amp, amp_se, phase,
                        None if Jm.shape[1] != 4 else float(cov[3, 3]), t0_s, t0_stderr_s)
    if check is not None:
        warnings.extend(check.pop("warnings"))
        flags.extend(check.pop("flags"))
        if check["estimator"] == "intra frames":
            amp, amp_se = check["amplitude"], check["amplitude_stderr"]
            phase, phase_se = check["phase_rad"], check["phase_stderr_rad"]
        for key in ("amplitude", "amplitude_stderr", "phase_rad", "phase_stderr_rad"):
            check.pop(key, None)

    fidelity = 1.0 - ssr / sst if sst > 0 else float("nan")
    null_amps, artefact = _null_artefacts(null_channel, t_all, mask, f_hat, tc, dt_med)
    h_amps, h_ses, h_p, h_rms = fit_harmonics(t, yw, f_hat, tc, dt_med, artefact)
    fitted = [a for a in h_amps if a is not None]
    thd = math.sqrt(sum(a * a for a in fitted)) / amp if fitted and amp > 0 else float("nan")
    _quality_flags(fidelity, thd, h_p, warnings, flags)

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
        reference_time_s=float(t0_s) if t0_s is not None else float(t[0]),
        warnings=tuple(warnings),
        settle_s=float(win.settle_s),
        harmonic_amplitudes=tuple(h_amps),
        harmonic_amplitude_stderrs=tuple(h_ses),
        thd=float(thd),
        harmonic_residual_rms=float(h_rms),
        invalid_fraction=float(win.invalid_fraction),
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


def _checked_inputs(
    time_s: ArrayLike, y: ArrayLike, frequency_hz: float, t0_s: float | None, settle_s: float | str,
    valid: ArrayLike | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], float, NDArray[np.bool_]]:
    """Times, values, commanded frequency and the usable samples' mask, checked (ServoscopeError)."""
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
    if auto_settle and settle_s != SETTLE_AUTO:
        raise ServoscopeError(f"fit_sine: settle_s must be a number >= 0 or {SETTLE_AUTO!r}, got {settle_s!r}")
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
    return t_all, y_all, f_cmd, mask


def _ac_power(yw: NDArray[np.float64], warnings: list[str], flags: list[str]) -> tuple[float, bool]:
    """The window's AC sum of squares, and whether it is flat (then 0, flagged "flat")."""
    n = yw.size
    yc = yw - yw.mean()
    sst = float(yc @ yc)
    scale = float(np.max(np.abs(yw)))
    flat = sst == 0.0 or math.sqrt(sst / n) <= 1e-10 * scale
    if flat:
        sst = 0.0
        warnings.append("no AC signal in the steady-state window (constant output)")
        flags.append("flat")
    return sst, flat


def _periodogram_check(
    t: NDArray[np.float64], yw: NDArray[np.float64], f_cmd: float, tc: float, span: float, dt_med: float,
    sst: float, warnings: list[str], flags: list[str],
) -> None:
    """Flag "frequency_mismatch" when the periodogram's peak is not at the commanded frequency."""
    if span > 0 and dt_med > 0 and sst > 0:
        res_f = 1.0 / span
        lo = max(f_cmd / 3.0, 0.5 * res_f)
        hi = min(3.0 * f_cmd, 0.5 / dt_med)
        if hi > lo:
            n_grid = int(min(2000, max(50, math.ceil((hi - lo) / (0.1 * res_f)))))
            grid = np.linspace(lo, hi, n_grid)
            power = fit_power(t, yw, grid, tc)
            k = int(np.argmax(power))
            p_cmd = float(fit_power(t, yw, np.array([f_cmd]), tc)[0])
            if abs(grid[k] - f_cmd) > 1.5 * res_f and power[k] > 2.0 * max(p_cmd, 0.0):
                warnings.append(
                    f"periodogram peak at {grid[k]:.4g} Hz, not at the commanded "
                    f"{f_cmd:.4g} Hz (power there is {p_cmd / power[k]:.2g} of the peak)"
                )
                flags.append("frequency_mismatch")


def _refine_frequency(
    t: NDArray[np.float64], yw: NDArray[np.float64], tc: float, params: NDArray[np.float64],
    refine_frequency: bool | str, flat: bool, n_periods: float, span: float, warnings: list[str], flags: list[str],
) -> tuple[NDArray[np.float64], NDArray[np.float64], float | None]:
    """Free the frequency (nonlinear least squares) and keep it as `refine_frequency` says.

    `params` is ``(offset, a, b, f_cmd)`` from the linear fit. Returns the parameters, the
    Jacobian of the kept model (3 columns, or 4 with the frequency) and the refined fit's
    frequency standard error (None when not refined).
    """
    n = t.size
    f_cmd = float(params[3])
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
            trusted = n_periods >= FEW_PERIODS and "transient" not in flags
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
        Jm = design_matrix(t, f_cmd, tc)
    return params, Jm, refined_se


def _covariance(Jm: NDArray[np.float64], residual: NDArray[np.float64], ssr: float,
                warnings: list[str]) -> NDArray[np.float64]:
    """Covariance of the fitted parameters: Newey–West (HAC), or white-noise when that is off."""
    n, p_names = Jm.shape
    dof = n - p_names
    s2 = ssr / dof if dof > 0 else float("nan")
    JtJ = Jm.T @ Jm
    try:
        cov = np.linalg.inv(JtJ) * s2
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(JtJ) * s2
        warnings.append("singular Jacobian: standard errors are unreliable")
    if hac.USE_HAC and dof > 0:
        # Tracking errors are not white: they depend on where the marker
        # sits on the pixel grid, which changes slowly from frame to frame.
        # The Newey–West covariance accounts for that correlation.
        cov = hac_covariance(Jm, residual)
    return cov


def _amplitude_offset_frequency(
    a: float, b: float, cov: NDArray[np.float64], refined_se: float | None
) -> tuple[float, float, float, float | None]:
    """Amplitude and its standard error (delta method), the offset's and the frequency's errors."""
    p_names = cov.shape[0]
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
    return amp, amp_se, offset_se, f_se


def _phase(
    a: float, b: float, amp: float, cov: NDArray[np.float64], f_hat: float, tc: float, t0_s: float | None,
    t0_stderr_s: float | None,
) -> tuple[float | None, float | None]:
    """Phase relative to the input start `t0_s` and its standard error (None, None without it).

    The delta method from the phase at `tc`, with the frequency's error times the lever arm
    ``tc - t0`` and `t0_stderr_s` added.
    """
    if t0_s is None:
        return None, None
    p_names = cov.shape[0]
    # y = amp*sin(w(t - tc) + phi_c), phi_c = atan2(a, b);
    # relative to t0: phi = phi_c + w*(t0 - tc).
    phi_c = math.atan2(a, b)
    lever = float(t0_s) - tc
    phase = wrap_pi(phi_c + 2.0 * math.pi * f_hat * lever)
    g_ph = np.zeros(p_names)
    amp2 = amp * amp  # may underflow to 0 for a vanishing amplitude (found by hypothesis)
    if amp2 > 0:
        g_ph[1], g_ph[2] = b / amp2, -a / amp2
    if p_names == 4:
        g_ph[3] = 2.0 * math.pi * lever
    phase_se = math.sqrt(max(float(g_ph @ cov @ g_ph), 0.0)) if amp2 > 0 else float("nan")
    if t0_stderr_s is not None and math.isfinite(phase_se):
        phase_se = math.hypot(phase_se, 2.0 * math.pi * f_hat * float(t0_stderr_s))
    return phase, phase_se


def _null_artefacts(
    null_channel: ArrayLike | None, t_all: NDArray[np.float64], mask: NDArray[np.bool_], f_hat: float, tc: float,
    dt_med: float,
) -> tuple[list[float | None] | None, list[float | None] | None]:
    """The null channel's harmonic amplitudes, and the pooled artefact per harmonic for the test."""
    null_amps: list[float | None] | None = None
    if null_channel is not None:
        z_all = np.asarray(null_channel, dtype=float).ravel()
        if z_all.shape != t_all.shape:
            raise ServoscopeError(
                f"fit_sine: null_channel has {z_all.size} samples but time_s has {t_all.size}"
            )
        zm = mask & np.isfinite(z_all)
        if np.count_nonzero(zm) > 2 * len(HARMONICS) + 3:
            null_amps = fit_harmonics(t_all[zm], z_all[zm], f_hat, tc, dt_med)[0]
    artefact = None
    if null_amps is not None:
        # One null channel is one draw of the artefacts: pooled over the
        # harmonics, its power is a steadier estimate of their size at each.
        sq = [a * a for a in null_amps if a is not None]
        pooled = math.sqrt(sum(sq) / len(sq)) if sq else None
        artefact = [None if a is None else pooled for a in null_amps]
    return null_amps, artefact


def _quality_flags(fidelity: float, thd: float, h_p: float, warnings: list[str], flags: list[str]) -> None:
    """Flag low sinusoidal fidelity, and distortion (THD with significant harmonics)."""
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
