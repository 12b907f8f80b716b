"""A sine dwell fitted to a turning rotor's passes: irregular samples, one offset a blade.

A camera in the rotor's plane sees each blade once a revolution, when it points at the lens
(azimuth ψ = 0): the tracker gives one pitch a pass (``time_s`` at ψ = 0, ``blade``,
``pitch_rad``, ``pitch_stderr_rad``), N passes a revolution, 1/(N·Ω) apart, their times
drifting with the engine's speed. :func:`fit_pass_sine` fits one dwell to them and returns a
:class:`PassSineFit`, a :class:`~servoscope.sysid.sine_result.SineFit` that
:meth:`FrequencyResponse.from_sine_fits
<servoscope.sysid.frequency_response.FrequencyResponse.from_sine_fits>` takes as it takes a
static dwell's, so the frequency response, the transfer-function fit and the report run
unchanged.

Model
-----
``pitch_k = c[blade_k] + a·cos(ω(t_k − tc)) + b·sin(ω(t_k − tc))`` at the dwell's known
frequency ω = 2πf (no frequency refinement: the rig's clock sets it), ``tc`` the window's
mean time: the sine (in-phase and quadrature parts) common to every blade, one constant a
blade (a blade rigged off its twin, each blade's own pitch-link length). Weighted least
squares with weights ``1/pitch_stderr_rad²``. Amplitude, phase (relative to the input
start ``t0_s``, :func:`~servoscope.sysid.fit_sine`'s convention: a lagging system has a
negative phase) and their errors by the delta method. ``offset`` is the blades' mean
constant; each blade's own (:class:`BladeOffset`) and each blade's difference from blade 0
(:class:`BladeDifference`, the rigging error a rotor technician wants) come with 95 %
intervals from :func:`~servoscope.parameters.interval95`.

Standard errors
---------------
With stated errors, the weighted least squares' covariance ``inv(Xᵀ W X)``, scaled by the
reduced χ² where the residuals scatter more than the tracker says (never scaled down: the
stated errors are a floor). Where the whitened residuals (rows divided by their stated
errors, in time order) are correlated from pass to pass (a slow drift of the tracker's
error, a blade's flapping that the pitch reading picks up; Ljung–Box over the first lags
rejects whiteness at :data:`CORRELATION_TEST_LEVEL`, :func:`residuals_correlated`), the
Newey–West (HAC) covariance of the whitened problem
(:func:`~servoscope.sysid.hac.hac_covariance`) instead, scaled up by 1/χ² where χ² < 1.
HAC is kept for correlated residuals only because on white ones it is a noisier estimate of
the same thing, biased low for ~100 passes (measured: 2 blades at 20 rev/s, a 2 Hz dwell,
600 rotors: the amplitude's 95 % interval held the truth 92.3 % of the time with HAC, 95.3 %
with the stated errors). Without stated errors the scatter alone, by HAC, as
:func:`fit_sine`: with one blade and regular samples every number is its with
``refine_frequency=False``.

What passes cannot see
----------------------
The passes sample the pitch at N·Ω: a dwell at or above the pass-rate Nyquist frequency
N·Ω/2 cannot be told from one at N·Ω − f (anything in the pitch at that frequency lands on
it): flagged ``aliasing``, as is one above :data:`~servoscope.defaults.NEAR_NYQUIST` of it
(few passes a period). Each blade alone samples at Ω: a dwell near a multiple k·Ω looks
still to every blade and cannot be told from the blades' offsets (the fit's variance
inflates): flagged ``rotor_harmonic`` when the offsets more than double the sine's
variance. :func:`pass_nyquist_hz` and :func:`rotor_harmonic_warning` are the rules
``servoscope plan --rotor-hz`` plans with.
"""

from __future__ import annotations

import math
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.stats import chi2 as chi2_dist

from servoscope.defaults import DISTORTED_THD, LOW_FIDELITY, NEAR_NYQUIST, SETTLE_AUTO
from servoscope.errors import ServoscopeError
from servoscope.parameters import interval95
from servoscope.results import readonly
from servoscope.sysid._sine_harmonics import fit_harmonics
from servoscope.sysid._sine_window import FEW_PERIODS, steady_state_start
from servoscope.sysid.hac import hac_covariance, newey_west_lag
from servoscope.sysid.pass_result import BladeDifference, BladeOffset, PassSineFit, readonly_int
from servoscope.sysid.sine_result import wrap_pi

__all__ = ["BladeDifference", "BladeOffset", "PassSineFit", "blade_design", "fit_pass_sine", "pass_nyquist_hz",
           "readonly_int", "residuals_correlated", "rev_per_s_from_passes", "rotor_harmonic_warning"]

_MIN_PASSES = 5
_FEW_PASSES = 20
#: The blades' offsets may inflate the sine's variance this many times before the dwell is
#: flagged ``rotor_harmonic`` (it happens within about 1/T of a multiple k·Ω of the rotor's
#: speed, T the window's length).
ROTOR_HARMONIC_INFLATION = 2.0
#: Residuals whose Ljung–Box test rejects whiteness at this level take the HAC covariance.
CORRELATION_TEST_LEVEL = 0.05


def pass_nyquist_hz(rev_per_s: float, n_blades: int) -> float:
    """The pass-rate Nyquist frequency N·Ω/2, Hz: the highest dwell the passes can tell apart.

    Parameters
    ----------
    rev_per_s : float
        Rotor speed Ω, rev/s (> 0).
    n_blades : int
        Blades N (≥ 1), equally spaced, each seen once a revolution.
    """
    if not (math.isfinite(rev_per_s) and rev_per_s > 0) or int(n_blades) != n_blades or n_blades < 1:
        raise ServoscopeError(f"a rotor needs a speed > 0 and at least one blade, got {rev_per_s!r} rev/s, "
                              f"{n_blades!r} blades")
    return 0.5 * float(n_blades) * float(rev_per_s)


def rotor_harmonic_warning(frequency_hz: float, rev_per_s: float, span_s: float) -> str | None:
    """Why a dwell at `frequency_hz` sits on a rotor harmonic k·Ω (None when it does not).

    Each blade sees the pitch once a revolution: a dwell within about ``1/span_s`` of k·Ω
    (k ≥ 1) is nearly still to every blade and cannot be told from the blades' offsets.

    Parameters
    ----------
    frequency_hz, rev_per_s : float
        The dwell's frequency and the rotor's speed (Hz, rev/s).
    span_s : float
        The dwell's analysed length, s (sets the resolution: within ``max(1/span_s, 2 %)``).
    """
    k = round(frequency_hz / rev_per_s)
    if k < 1:
        return None
    tol = max(1.0 / span_s if span_s > 0 else 0.0, 0.02 * frequency_hz)
    if abs(frequency_hz - k * rev_per_s) >= tol:
        return None
    times = f"{k}×" if k > 1 else ""
    return (f"{frequency_hz:g} Hz is within {tol:.2g} Hz of {times}the rotor speed ({k * rev_per_s:.4g} Hz): each "
            "blade sees the sine nearly still at its passes, and it cannot be told from the blades' pitch offsets")


def rev_per_s_from_passes(time_s: ArrayLike, blade: ArrayLike) -> float:
    """The rotor speed from the passes: one over the median time between a blade's passes, rev/s.

    Pairs more than 1.5 median periods apart (a pass missed) are left out. NaN when no blade
    was seen twice.
    """
    t, b = np.asarray(time_s, dtype=float), np.asarray(blade)
    gaps = []
    for k in np.unique(b):
        tk = np.sort(t[(b == k) & np.isfinite(t)])
        gaps.append(np.diff(tk))
    d = np.concatenate(gaps) if gaps else np.zeros(0)
    d = d[d > 0]
    if d.size == 0:
        return float("nan")
    med = float(np.median(d))
    d = d[d < 1.5 * med]
    return 1.0 / float(np.mean(d))


def blade_design(time_s: NDArray[np.float64], blade_index: NDArray[np.int_], n_blades: int, frequency_hz: float,
                 tc: float) -> NDArray[np.float64]:
    """Columns: one indicator a blade (``blade_index`` 0…n−1), then cos and sin of ``2πf(t − tc)``."""
    X = np.zeros((time_s.size, n_blades + 2))
    X[np.arange(time_s.size), blade_index] = 1.0
    th = 2.0 * math.pi * frequency_hz * (time_s - tc)
    X[:, -2], X[:, -1] = np.cos(th), np.sin(th)
    return X


def fit_pass_sine(
    time_s: ArrayLike,
    blade: ArrayLike,
    pitch_rad: ArrayLike,
    pitch_stderr_rad: ArrayLike | None,
    frequency_hz: float,
    *,
    t0_s: float | None = None,
    settle_s: float | str = SETTLE_AUTO,
    valid: ArrayLike | None = None,
    rev_per_s: float | None = None,
    n_blades: int | None = None,
    t0_stderr_s: float | None = None,
) -> PassSineFit:
    """Fit a dwell's sine, common to all blades, and one offset a blade, to a rotor's passes.

    Parameters
    ----------
    time_s : array_like, shape (n,)
        Each pass's time (the blade at ψ = 0), s, on the video's clock.
    blade : array_like of int, shape (n,)
        Which blade passed (0 first).
    pitch_rad : array_like, shape (n,)
        The blade's pitch at the pass, rad; NaN excluded.
    pitch_stderr_rad : array_like, shape (n,), or None
        Its stated standard error, rad (the weights, and the covariance's floor); None: all
        passes weighted alike, the scatter alone sets the errors.
    frequency_hz : float
        The dwell's commanded frequency, Hz (> 0).
    t0_s : float, optional
        Input start (the LED's switch), s: the phase's reference.
    settle_s : float or "auto", default "auto"
        Time skipped after `t0_s` (or the first pass); "auto" finds where the transient ends
        (:func:`~servoscope.sysid.fit_sine`'s rule, each blade's offset removed first).
    valid : array_like of bool, shape (n,), optional
        False marks passes to leave out.
    rev_per_s : float, optional
        Rotor speed Ω, rev/s; default measured from the passes (:func:`rev_per_s_from_passes`).
    n_blades : int, optional
        Blades on the rotor; default the number of blades seen.
    t0_stderr_s : float, optional
        Standard uncertainty of `t0_s`, s: adds ``2πf·t0_stderr_s`` to the phase's error.

    Returns
    -------
    PassSineFit

    Raises
    ------
    ServoscopeError
        Inputs of mismatched shapes, a negative blade number, a non-positive frequency,
        stated errors that are not positive, or fewer than 5 usable passes (or too few for
        the blades' offsets) in the window.
    """
    t_all, b_all, y_all, s_all, mask, f = _checked(time_s, blade, pitch_rad, pitch_stderr_rad, frequency_hz,
                                                   valid, settle_s, t0_s)
    blades_seen = np.unique(b_all[mask])
    n_b = int(n_blades) if n_blades is not None else int(blades_seen.size)
    if n_b < blades_seen.size:
        raise ServoscopeError(f"fit_pass_sine: n_blades {n_blades} but blades {blades_seen.tolist()} were seen")
    omega_rev = float(rev_per_s) if rev_per_s is not None else rev_per_s_from_passes(t_all[mask], b_all[mask])
    warnings: list[str] = []
    flags: list[str] = []
    origin = float(t0_s) if t0_s is not None else float(np.min(t_all[mask]))
    t, bl, y, sig, start, invalid_fraction = _window(t_all, b_all, y_all, s_all, mask, f, origin, settle_s)
    present = np.unique(bl)
    n = t.size
    idx = np.searchsorted(present, bl)
    tc = float(np.mean(t))
    X = blade_design(t, idx, present.size, f, tc)
    w = np.ones(n) if sig is None else 1.0 / sig
    coef, *_ = np.linalg.lstsq(X * w[:, None], y * w, rcond=None)
    resid = y - X @ coef
    cov, chi2, hac_used = _covariance(X, resid, w, sig is not None)
    p = present.size
    a, b_ = float(coef[p]), float(coef[p + 1])
    amp = math.hypot(a, b_)
    # (offset, a, b): the blades' mean constant and the sine at tc.
    T = np.zeros((3, p + 2))
    T[0, :p] = 1.0 / p
    T[1, p], T[2, p + 1] = 1.0, 1.0
    cov3 = T @ cov @ T.T
    offset = float(T[0] @ coef)
    amp_se = _se(np.array([0.0, a / amp, b_ / amp]) if amp > 0 else np.array([0.0, 1.0, 1.0]) / math.sqrt(2), cov3)
    phase = phase_se = None
    if t0_s is not None:
        phase = wrap_pi(math.atan2(a, b_) + 2.0 * math.pi * f * (float(t0_s) - tc))
        phase_se = _se(np.array([0.0, b_, -a]) / (amp * amp), cov3) if amp > 0 else float("nan")
        if t0_stderr_s is not None and math.isfinite(phase_se):
            phase_se = math.hypot(phase_se, 2.0 * math.pi * f * float(t0_stderr_s))
    offsets, diffs = _blades(present, coef, cov, bl)

    aligned = y - (coef[idx] - offset)
    ssr = float(resid @ resid)
    yc = aligned - aligned.mean()
    sst = float(yc @ yc)
    if sst == 0.0 or math.sqrt(sst / n) <= 1e-10 * float(np.max(np.abs(aligned))):
        sst = 0.0
        warnings.append("no AC signal in the steady-state window (constant pitch)")
        flags.append("flat")
    nyq = pass_nyquist_hz(omega_rev, n_b) if math.isfinite(omega_rev) else float("nan")
    span = float(t[-1] - t[0])
    _checks(f, n, span, invalid_fraction, omega_rev, n_b, nyq, X, w, warnings, flags)
    dt_med = float(np.median(np.diff(t))) if n > 1 else float("nan")
    h_amps, h_ses, h_p, h_rms = fit_harmonics(t, aligned, f, tc, dt_med)
    fitted = [h for h in h_amps if h is not None]
    thd = math.sqrt(sum(h * h for h in fitted)) / amp if fitted and amp > 0 else float("nan")
    fidelity = 1.0 - ssr / sst if sst > 0 else float("nan")
    _quality(fidelity, thd, h_p, warnings, flags)
    return PassSineFit(
        frequency_hz=f, frequency_stderr_hz=None, commanded_frequency_hz=f, amplitude=amp, amplitude_stderr=amp_se,
        phase_rad=phase, phase_stderr_rad=phase_se, offset=offset, offset_stderr=_se(np.array([1.0, 0, 0]), cov3),
        residual_rms=math.sqrt(ssr / n), fidelity=fidelity, n_samples=int(n), window_s=(float(t[0]), float(t[-1])),
        t0_s=None if t0_s is None else float(t0_s), warnings=tuple(warnings),
        reference_time_s=float(t0_s) if t0_s is not None else float(t[0]),
        settle_s=float(start - origin), harmonic_amplitudes=tuple(h_amps), harmonic_amplitude_stderrs=tuple(h_ses),
        thd=float(thd), harmonic_residual_rms=float(h_rms), invalid_fraction=float(invalid_fraction),
        flags=tuple(dict.fromkeys(flags)), time_s=readonly(t), y=readonly(aligned), residual=readonly(resid),
        covariance=readonly(cov3), _center_s=tc, _cos_coef=a, _sin_coef=b_,
        blade_offsets=offsets, blade_differences=diffs, rev_per_s=omega_rev, n_blades=n_b, pass_rate_hz=2.0 * nyq,
        pass_nyquist_hz=nyq, chi2_reduced=chi2, covariance_kind="HAC" if hac_used else "stated errors",
        blade=readonly_int(bl), pitch_rad=readonly(y),
        pitch_stderr_rad=readonly(np.full(n, np.nan) if sig is None else sig),
    )


def _checked(time_s: ArrayLike, blade: ArrayLike, pitch_rad: ArrayLike, pitch_stderr_rad: ArrayLike | None,
             frequency_hz: float, valid: ArrayLike | None, settle_s: float | str, t0_s: float | None,
             ) -> tuple[NDArray[np.float64], NDArray[np.int_], NDArray[np.float64], NDArray[np.float64] | None,
                        NDArray[np.bool_], float]:
    """The arrays checked (ServoscopeError naming what is wrong) and the usable passes' mask."""
    t = np.asarray(time_s, dtype=float).ravel()
    y = np.asarray(pitch_rad, dtype=float).ravel()
    b_raw = np.asarray(blade).ravel()
    arrays = {"blade": b_raw.size, "pitch_rad": y.size}
    s = None
    if pitch_stderr_rad is not None:
        s = np.asarray(pitch_stderr_rad, dtype=float).ravel()
        arrays["pitch_stderr_rad"] = s.size
    if valid is not None:
        arrays["valid"] = np.asarray(valid).size
    for name, size in arrays.items():
        if size != t.size:
            raise ServoscopeError(f"fit_pass_sine: time_s has {t.size} passes but {name} has {size}")
    if b_raw.size and (not np.all(np.equal(np.mod(b_raw, 1), 0)) or np.min(b_raw) < 0):
        raise ServoscopeError("fit_pass_sine: blade must hold whole numbers ≥ 0 (0 for the first blade)")
    b = b_raw.astype(int)
    f = float(frequency_hz)
    if not (math.isfinite(f) and f > 0):
        raise ServoscopeError(f"fit_pass_sine: frequency_hz must be positive, got {frequency_hz!r}")
    if isinstance(settle_s, str) and settle_s != SETTLE_AUTO:
        raise ServoscopeError(f"fit_pass_sine: settle_s must be a number ≥ 0 or {SETTLE_AUTO!r}, got {settle_s!r}")
    if not isinstance(settle_s, str) and not (math.isfinite(float(settle_s)) and float(settle_s) >= 0):
        raise ServoscopeError(f"fit_pass_sine: settle_s must be ≥ 0, got {settle_s!r}")
    if t0_s is not None and not math.isfinite(float(t0_s)):
        raise ServoscopeError(f"fit_pass_sine: t0_s must be finite, got {t0_s!r}")
    mask = np.isfinite(t) & np.isfinite(y)
    if s is not None:
        bad = mask & ~(np.isfinite(s) & (s > 0))
        if np.any(bad):
            raise ServoscopeError(f"fit_pass_sine: {int(np.count_nonzero(bad))} passes have a stated error that is "
                                  "not a positive number (give pitch_stderr_rad > 0, or None to weight alike)")
    if valid is not None:
        mask &= np.asarray(valid, dtype=bool).ravel()
    if not np.any(mask):
        raise ServoscopeError("fit_pass_sine: no usable passes (every one invalid or NaN)")
    return t, b, y, s, mask, f


def _window(t_all: NDArray[np.float64], b_all: NDArray[np.int_], y_all: NDArray[np.float64],
            s_all: NDArray[np.float64] | None, mask: NDArray[np.bool_], f: float, origin: float,
            settle_s: float | str) -> tuple[NDArray[np.float64], NDArray[np.int_], NDArray[np.float64],
                                            NDArray[np.float64] | None, float, float]:
    """The steady-state window's passes in time order: times, blades, pitches, stated errors; its start and
    the share of its passes left out (ServoscopeError when too few remain)."""
    if isinstance(settle_s, str):
        start = _auto_start(t_all[mask], b_all[mask], y_all[mask], f, origin)
    else:
        start = origin + float(settle_s)
    in_window = np.isfinite(t_all) & (t_all >= start)
    keep = mask & in_window
    n_frames = int(np.count_nonzero(in_window))
    invalid_fraction = 1.0 - np.count_nonzero(keep) / n_frames if n_frames else 1.0
    order = np.argsort(t_all[keep], kind="stable")
    t, bl, y = t_all[keep][order], b_all[keep][order], y_all[keep][order]
    n_b = np.unique(bl).size
    if t.size < max(_MIN_PASSES, n_b + 3):
        raise ServoscopeError(f"fit_pass_sine: only {t.size} usable passes after t = {start:.4g} s (need at least "
                              f"{max(_MIN_PASSES, n_b + 3)} for {n_b} blades' offsets and the sine); record longer "
                              "or reduce settle_s")
    return t, bl, y, None if s_all is None else s_all[keep][order], start, invalid_fraction


def _auto_start(t: NDArray[np.float64], b: NDArray[np.int_], y: NDArray[np.float64], f: float,
                origin: float) -> float:
    """Where the transient ends (:func:`steady_state_start`), the blades' offsets removed first.

    The offsets are those of the record's second half (sine and offsets fitted there): a
    0.2° offset between blades would otherwise read as a transient that never ends.
    """
    order = np.argsort(t, kind="stable")
    t, b, y = t[order], b[order], y[order]
    present = np.unique(b)
    if present.size > 1:
        after = t >= origin
        if np.count_nonzero(after) >= present.size + 8:
            mid = float(t[after][0]) + 0.5 * float(t[after][-1] - t[after][0])
            late = t >= mid
            idx = np.searchsorted(present, b)
            X = blade_design(t[late], idx[late], present.size, f, float(np.mean(t[late])))
            coef, *_ = np.linalg.lstsq(X, y[late], rcond=None)
            c = coef[: present.size]
            y = y - (c[idx] - float(np.mean(c)))
    return steady_state_start(t, y, f, origin)[0]


def residuals_correlated(residual: NDArray[np.float64], level: float = CORRELATION_TEST_LEVEL) -> bool:
    """Whether residuals in time order are correlated: Ljung–Box over the first lags, at `level`.

    The lags are :func:`~servoscope.sysid.hac.newey_west_lag`'s (4 for 100 passes); False for
    fewer than 10 residuals.
    """
    r = np.asarray(residual, dtype=float)
    n = r.size
    if n < 10:
        return False
    r = r - r.mean()
    den = float(r @ r)
    if den <= 0:
        return False
    lags = min(newey_west_lag(n), n // 4)
    q = n * (n + 2.0) * sum((float(r[k:] @ r[:-k]) / den) ** 2 / (n - k) for k in range(1, lags + 1))
    return bool(chi2_dist.sf(q, lags) < level)


def _covariance(X: NDArray[np.float64], resid: NDArray[np.float64], w: NDArray[np.float64],
                stated: bool) -> tuple[NDArray[np.float64], float, bool]:
    """The fit's covariance (module docstring, "Standard errors"), the reduced χ², and whether HAC was used."""
    n, p = X.shape
    Jw, rw = X * w[:, None], resid * w
    if not stated:  # fit_sine's noise model: the scatter, correlated or not
        return hac_covariance(Jw, rw), float("nan"), True
    chi2 = float(rw @ rw) / (n - p) if n > p else float("nan")
    scale = max(chi2, 1.0) if math.isfinite(chi2) else 1.0
    if not residuals_correlated(rw):
        try:
            return np.linalg.inv(Jw.T @ Jw) * scale, chi2, False
        except np.linalg.LinAlgError:
            return np.linalg.pinv(Jw.T @ Jw) * scale, chi2, False
    cov = hac_covariance(Jw, rw)
    # The residuals scatter less than the tracker says: its errors are the floor (the HAC
    # covariance of white residuals is their scatter's, on average chi2 times the stated one's).
    if math.isfinite(chi2) and 0 < chi2 < 1:
        cov = cov / chi2
    return cov, chi2, True


def _se(g: NDArray[np.float64], cov: NDArray[np.float64]) -> float:
    return math.sqrt(max(float(g @ cov @ g), 0.0))


def _blades(present: NDArray[np.int_], coef: NDArray[np.float64], cov: NDArray[np.float64],
            bl: NDArray[np.int_]) -> tuple[tuple[BladeOffset, ...], tuple[BladeDifference, ...]]:
    """Each blade's constant, and each other blade's difference from the first, with intervals."""
    k = present.size
    offsets = []
    for i, blade in enumerate(present):
        se = math.sqrt(max(float(cov[i, i]), 0.0))
        offsets.append(BladeOffset(int(blade), float(coef[i]), se, interval95(float(coef[i]), se),
                                   int(np.count_nonzero(bl == blade))))
    diffs = []
    for i in range(1, k):
        d = float(coef[i] - coef[0])
        se = math.sqrt(max(float(cov[i, i] + cov[0, 0] - 2.0 * cov[i, 0]), 0.0))
        diffs.append(BladeDifference(int(present[i]), int(present[0]), d, se, interval95(d, se)))
    return tuple(offsets), tuple(diffs)


def _checks(f: float, n: int, span: float, invalid_fraction: float, rev: float, n_b: int, nyq: float,
            X: NDArray[np.float64], w: NDArray[np.float64], warnings: list[str], flags: list[str]) -> None:
    """Few passes or periods, invalid passes, the pass-rate Nyquist and the rotor's harmonics."""
    if invalid_fraction > 0.2:
        warnings.append(f"{100 * invalid_fraction:.0f} % of the passes in the steady-state window are invalid")
        flags.append("invalid_frames")
    if n < _FEW_PASSES:
        warnings.append(f"only {n} passes in the steady-state window (< {_FEW_PASSES})")
        flags.append("few_samples")
    if span * f < FEW_PERIODS:
        warnings.append(f"steady-state window covers only {span * f:.2f} periods (< {FEW_PERIODS:g})")
        flags.append("few_periods")
    if math.isfinite(nyq):
        rate = 2.0 * nyq
        if f >= nyq:
            warnings.append(
                f"{f:g} Hz is at or above the pass-rate Nyquist frequency {nyq:.4g} Hz ({n_b} blades × {rev:.4g} "
                f"rev/s / 2): the passes cannot tell it from {abs(rate - f):.4g} Hz (N·Ω − f); plan dwells below "
                f"{NEAR_NYQUIST * nyq:.3g} Hz (`servoscope plan --rotor-hz`)")
            flags.append("aliasing")
        elif f >= NEAR_NYQUIST * nyq:
            warnings.append(
                f"{f:g} Hz is close to the pass-rate Nyquist frequency {nyq:.4g} Hz ({n_b} blades × {rev:.4g} "
                f"rev/s / 2): few passes a period, and anything at {rate - f:.4g} Hz (N·Ω − f) lands on it")
            flags.append("aliasing")
    # The blades' offsets against the sine: how much they inflate its variance.
    Xw = X * w[:, None]
    p = X.shape[1]
    try:
        full = np.linalg.inv(Xw.T @ Xw)[p - 2:, p - 2:]
        one = np.column_stack([w, Xw[:, -2:]])
        alone = np.linalg.inv(one.T @ one)[1:, 1:]
        inflation = float(np.trace(full) / np.trace(alone))
    except np.linalg.LinAlgError:
        inflation = math.inf
    if inflation > ROTOR_HARMONIC_INFLATION:
        text = rotor_harmonic_warning(f, rev, span) if math.isfinite(rev) else None
        warnings.append(text or f"{f:g} Hz: the blades' offsets inflate the sine's variance {inflation:.3g} times: "
                                "each blade sees it nearly still at its passes")
        flags.append("rotor_harmonic")


def _quality(fidelity: float, thd: float, h_p: float, warnings: list[str], flags: list[str]) -> None:
    """Low sinusoidal fidelity, and distortion (THD with significant harmonics): fit_sine's rules."""
    if math.isfinite(fidelity) and fidelity < LOW_FIDELITY:
        warnings.append(f"low sinusoidal fidelity {fidelity:.3f} (< {LOW_FIDELITY:g}): the pitch is not a clean "
                        "sine (nonlinearity or noise)")
        flags.append("low_fidelity")
    if math.isfinite(thd) and thd > DISTORTED_THD and h_p < 1e-3:
        warnings.append(f"harmonic distortion {100 * thd:.1f} % (> {100 * DISTORTED_THD:g} %): nonlinear response "
                        "(rate limit, backlash, saturation?)")
        flags.append("distorted")
