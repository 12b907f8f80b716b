"""Step-response analysis: rise time, overshoot, settling time and dead time.

Input convention: ``u(t) = step_size`` for ``t >= t0_s``, 0 before.

Measured metrics (from the data, no model)
------------------------------------------
* initial value: median of the valid samples before ``t0_s`` (pre-roll);
* final value: mean of the samples in the last 25 % of the post-``t0``
  record, i.e. ``t >= t_end - 0.25*(t_end - t0_s)``;
* normalized response ``r = (y - initial) / (final - initial)``;
* rise time: 10 % -> 90 % of the change. Each crossing time is the *last*
  upward crossing of the level before the response's peak (so
  noise-induced re-crossings near the level do not cut the rise short, and
  later oscillations are ignored), located between the two frames by the
  cubic through the 4 surrounding frames (linear interpolation when frames
  are missing there; linear interpolation alone is biased by the curvature
  of the response, ~0.7 ms at 100 fps for the paper's model);
* overshoot: peak of ``r`` above 1 in percent; the peak is refined by a
  quadratic fit through the 5 frames around the largest value of a 3-frame
  moving average (sub-frame peak, noise averaged; skipped when frames are
  missing there), clipped at >= 0;
* settling time (from ``t0_s``): when a 3-frame moving average of ``r``
  last enters the band ``|r - 1| <= 0.02``, linearly interpolated;
* noise sigma: 1.4826 * MAD of the pre-roll (or of the first differences of
  the final segment / sqrt 2 when the pre-roll has fewer than 5 samples).

Dead time
---------
``dead_time_threshold_s`` (always): the paper's frame counting, the time
from ``t0_s`` to the first frame where ``|y - initial|`` exceeds
``max(5*sigma, 0.02*|change|)``. It is biased late by the time the
response needs to reach that level.

``dead_time_s`` (when a delay-free ``model`` transfer function is given):
least-squares fit of ``y(t) = b + g*step_size*s(t - t0 - tau)`` over the
samples with ``t >= t0``, where ``s`` is the model's unit-step response
normalized to a DC gain of 1; ``b``, ``g`` and ``tau >= 0`` are free. This
has sub-frame precision; its standard error comes from the Jacobian with
the residual variance.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import control
import numpy as np
import scipy.linalg
from numba import njit
from numpy.typing import ArrayLike, NDArray
from scipy.interpolate import CubicSpline
from scipy.optimize import least_squares

from servoscope.defaults import STEP_DISCERNIBLE_SIGMA
from servoscope.errors import ServoscopeError
from servoscope.results import readonly
from servoscope.sysid.step_result import StepAnalysis, step_discernible

__all__ = ["StepAnalysis", "analyse_step", "model_step_metrics", "step_response_on_grid", "unit_step_function"]

_SETTLING_BAND = 0.02
_RISE_LIMITS = (0.1, 0.9)


def _moving_average3(r: NDArray[np.float64]) -> NDArray[np.float64]:
    if r.size < 3:
        return r.copy()
    out = r.copy()
    out[1:-1] = (r[:-2] + r[1:-1] + r[2:]) / 3.0
    return out


def _interp_cross(t0: float, t1: float, v0: float, v1: float, level: float) -> float:
    if v1 == v0:
        return t1
    return t0 + (level - v0) / (v1 - v0) * (t1 - t0)


def _cubic_cross(t: NDArray[np.float64], v: NDArray[np.float64], i: int, level: float) -> float:
    """Crossing of `level` between samples i and i+1 (v[i] < level <= v[i+1]).

    Uses the cubic through samples i-1..i+2 when they exist, are evenly
    spaced and the cubic crosses once inside the interval (removes most of
    the curvature bias of linear interpolation); otherwise linear.
    """
    lin = _interp_cross(t[i], t[i + 1], v[i], v[i + 1], level)
    if i < 1 or i + 2 >= t.size:
        return lin
    tt = t[i - 1 : i + 3]
    h = np.diff(tt)
    if np.max(h) > 1.5 * np.min(h):
        return lin
    x = (tt - t[i]) / (t[i + 1] - t[i])
    c = np.polyfit(x, v[i - 1 : i + 3] - level, 3)
    roots = np.roots(c)
    real = roots[np.abs(roots.imag) < 1e-9].real
    inside = real[(real >= 0.0) & (real <= 1.0)]
    if inside.size != 1:
        return lin
    return float(t[i] + inside[0] * (t[i + 1] - t[i]))


@njit(cache=True)
def _held_input_response(ad, bd, c, d, n):  # pragma: no cover - numba
    # From rest with a unit input held: x[k+1] = Ad x[k] + Bd, y[k] = C x[k] + D (exact at the grid's points).
    m = ad.shape[0]
    x = np.zeros(m)
    nxt = np.empty(m)
    out = np.empty(n)
    for k in range(n):
        acc = d
        for i in range(m):
            acc += c[i] * x[i]
        out[k] = acc
        for i in range(m):
            total = bd[i]
            for j in range(m):
                total += ad[i, j] * x[j]
            nxt[i] = total
        for i in range(m):
            x[i] = nxt[i]
    return out


def step_response_on_grid(model: control.TransferFunction | control.StateSpace,
                          grid: NDArray[np.float64]) -> NDArray[np.float64]:
    """A continuous SISO model's response to a unit step at t = 0, on a uniform grid starting at 0.

    The same values as :func:`control.step_response` (the state's exact recursion between grid
    points, a constant input being exact under a zero-order hold), to rounding, without its loop over
    the samples in Python: on the 20,000-400,000-point grids below it took ~0.1 s a model, most of an
    identification's time.
    """
    grid = np.asarray(grid, dtype=np.float64)
    sys = control.ss(model)
    a, b, c, d = (np.atleast_2d(np.asarray(v, dtype=np.float64)) for v in (sys.A, sys.B, sys.C, sys.D))
    m = a.shape[0] if a.size else 0
    if grid.size < 2 or m == 0:
        return np.full(grid.size, float(d[0, 0]))
    dt = float(grid[1] - grid[0])
    aug = np.zeros((m + 1, m + 1))
    aug[:m, :m] = a * dt
    aug[:m, m] = b[:, 0] * dt
    e = scipy.linalg.expm(aug)
    return _held_input_response(np.ascontiguousarray(e[:m, :m]), np.ascontiguousarray(e[:m, m]),
                                np.ascontiguousarray(c[0]), float(d[0, 0]), grid.size)


def unit_step_function(model: control.TransferFunction, span_s: float, dt_hint_s: float) -> Callable[[NDArray[np.float64]], NDArray[np.float64]]:
    """Spline of the model's unit-step response normalized to DC gain 1 (0 for t < 0)."""
    if not isinstance(model, (control.TransferFunction, control.StateSpace)):
        raise ServoscopeError("analyse_step: model must be a control.TransferFunction")
    if model.ninputs != 1 or model.noutputs != 1 or model.isdtime(strict=True):
        raise ServoscopeError("analyse_step: model must be a continuous-time SISO system")
    poles = np.asarray(model.poles())
    if poles.size and np.any(poles.real >= 0):
        raise ServoscopeError("analyse_step: model must be stable")
    dc = float(np.real(model.dcgain()))
    if not (math.isfinite(dc) and dc != 0):
        raise ServoscopeError("analyse_step: model DC gain must be finite and nonzero")
    pmax = float(np.max(np.abs(poles))) if poles.size else 1.0
    dt = min(dt_hint_s / 20.0, 0.02 / max(pmax, 1e-12))
    n = int(min(200_001, max(2001, math.ceil(span_s / dt) + 1)))
    grid = np.linspace(0.0, span_s, n)
    vals = step_response_on_grid(model, grid) / dc
    spline = CubicSpline(grid, vals)

    def s(u: NDArray[np.float64]) -> NDArray[np.float64]:
        # 0 before the step; beyond the grid the last (settled) value is held.
        u = np.asarray(u, dtype=float)
        return np.where(u < 0, 0.0, spline(np.clip(u, 0.0, span_s)))

    s.derivative = lambda u: np.where(  # type: ignore[attr-defined]
        (np.asarray(u) < 0) | (np.asarray(u) > span_s), 0.0, spline(np.clip(u, 0.0, span_s), 1)
    )
    return s


def analyse_step(
    time_s: ArrayLike,
    y: ArrayLike,
    *,
    t0_s: float,
    step_size: float,
    valid: ArrayLike | None = None,
    model: control.TransferFunction | None = None,
    t0_stderr_s: float | None = None,
) -> StepAnalysis:
    """Measure rise time, overshoot, settling time and dead time of a step.

    See the module docstring for the exact definitions.

    Parameters
    ----------
    time_s : array_like, shape (n,)
        Frame times in s.
    y : array_like, shape (n,)
        Output (e.g. blade pitch in rad); NaNs are excluded.
    t0_s : float
        Step time (LED off) in s; there must be samples before it.
    step_size : float
        Input step amplitude (input units, nonzero).
    valid : array_like of bool, optional
        False marks frames to exclude.
    model : control.TransferFunction, optional
        Delay-free model (e.g. ``TransferFunctionFit.transfer_function``)
        used to estimate the dead time with sub-frame precision.
    t0_stderr_s : float, optional
        Standard uncertainty of ``t0_s`` (s), e.g. the LED switch time's:
        the dead time is counted from t0, so its uncertainty adds in.

    Returns
    -------
    StepAnalysis

    Raises
    ------
    ServoscopeError
        Mismatched inputs, no samples before ``t0_s``, fewer than 5 samples
        after it, or a zero step.
    """
    t_all = np.asarray(time_s, dtype=float).ravel()
    y_all = np.asarray(y, dtype=float).ravel()
    if t_all.shape != y_all.shape:
        raise ServoscopeError(f"analyse_step: time_s has {t_all.size} samples but y has {y_all.size}")
    t0 = float(t0_s)
    step = float(step_size)
    if not math.isfinite(t0):
        raise ServoscopeError("analyse_step: t0_s must be finite")
    if not (math.isfinite(step) and step != 0):
        raise ServoscopeError(f"analyse_step: step_size must be finite and nonzero, got {step_size!r}")
    mask = np.isfinite(t_all) & np.isfinite(y_all)
    if valid is not None:
        v = np.asarray(valid, dtype=bool).ravel()
        if v.shape != t_all.shape:
            raise ServoscopeError(f"analyse_step: valid has {v.size} entries but time_s has {t_all.size}")
        mask &= v
    order = np.argsort(t_all[mask], kind="stable")
    t = t_all[mask][order]
    yv = y_all[mask][order]
    pre = t < t0
    post = ~pre
    n_pre = int(np.count_nonzero(pre))
    n_post = int(np.count_nonzero(post))
    if n_pre == 0:
        raise ServoscopeError("analyse_step: no valid samples before t0_s (a pre-roll is needed for the baseline)")
    if n_post < 5:
        raise ServoscopeError(f"analyse_step: only {n_post} valid samples after t0_s (need at least 5)")
    warns: list[str] = []
    if n_pre < 5:
        warns.append(f"only {n_pre} samples before t0: baseline is uncertain")

    initial = float(np.median(yv[pre]))
    tp, yp = t[post], yv[post]
    t_end = float(tp[-1])
    final_sel = tp >= t_end - 0.25 * (t_end - t0)
    final = float(np.mean(yp[final_sel]))
    change = final - initial

    if n_pre >= 5:
        sigma = 1.4826 * float(np.median(np.abs(yv[pre] - np.median(yv[pre]))))
    else:
        d = np.diff(yp[final_sel])
        sigma = 1.4826 * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(2.0) if d.size else 0.0

    rise, overshoot, peak_time, settling, dead_thr = _response_metrics(tp, yp, t0, initial, change, sigma, warns)

    dead = dead_se = g_fit = g_se = b_fit = None
    unit_step = None
    predicted_metrics: dict[str, float] | None = None
    if model is not None:
        dead, dead_se, g_fit, g_se, b_fit, unit_step = _dead_time_fit(
            model, t, tp, yp, t0, step, initial, change, dead_thr, t_end, t0_stderr_s, warns
        )
        predicted_metrics = _predicted_metrics(model, dead, step, warns)

    return StepAnalysis(
        t0_s=t0,
        step_size=step,
        initial_value=initial,
        final_value=final,
        change=change,
        gain=change / step,
        rise_time_s=float(rise),
        overshoot_pct=float(overshoot),
        peak_time_s=float(peak_time),
        settling_time_s=float(settling),
        dead_time_s=dead,
        dead_time_stderr_s=dead_se,
        dead_time_threshold_s=float(dead_thr),
        fitted_gain=g_fit,
        fitted_gain_stderr=g_se,
        fitted_baseline=b_fit,
        noise_sigma=float(sigma),
        warnings=tuple(warns),
        time_s=readonly(t),
        y=readonly(yv),
        _unit_step=unit_step,
        predicted_metrics=predicted_metrics,
    )


def _response_metrics(
    tp: NDArray[np.float64], yp: NDArray[np.float64], t0: float, initial: float, change: float, sigma: float,
    warns: list[str],
) -> tuple[float, float, float, float, float]:
    """Rise time, overshoot, peak time, settling time and threshold dead time (NaN when not measurable).

    From the samples after the step (`tp`, `yp`), normalized by `initial` and `change`
    (the module docstring gives the definitions); appends to `warns` what could not be measured.
    """
    nan = float("nan")
    rise = overshoot = peak_time = settling = dead_thr = nan
    if not step_discernible(change, sigma):
        warns.append(f"no discernible step response (change within {STEP_DISCERNIBLE_SIGMA:g} noise sigma)")
        return rise, overshoot, peak_time, settling, dead_thr
    r = (yp - initial) / change
    rs = _moving_average3(r)
    # Peak (sub-frame via local quadratic).
    k = int(np.argmax(rs))
    peak_val = float(r[k])
    peak_time = float(tp[k] - t0)
    dt_med = float(np.median(np.diff(tp)))
    if 2 <= k <= r.size - 3 and tp[k + 2] - tp[k - 2] <= 4.5 * dt_med:
        tt = tp[k - 2 : k + 3] - tp[k]
        c2, c1, c0 = np.polyfit(tt, r[k - 2 : k + 3], 2)
        if c2 < 0:
            tv = -c1 / (2 * c2)
            if abs(tv) <= (tt[-1] - tt[0]) / 2:
                peak_val = float(c0 - c1**2 / (4 * c2))
                peak_time = float(tp[k] + tv - t0)
    overshoot = max(0.0, 100.0 * (peak_val - 1.0))
    # Rise: last upward crossing of each level before the peak.
    seg = r[: k + 1]
    tseg = tp[: k + 1]
    cross = []
    for level in _RISE_LIMITS:
        below = np.nonzero(seg < level)[0]
        if below.size == 0 or below[-1] + 1 >= seg.size:
            cross.append(nan)
        else:
            i = int(below[-1])
            cross.append(_cubic_cross(tseg, seg, i, level))
    rise = cross[1] - cross[0]
    if not math.isfinite(rise):
        warns.append("rise time not measurable (10 % or 90 % level not crossed before the peak)")
    # Settling (2 % band) on the mildly smoothed response.
    dev = np.abs(rs - 1.0)
    outside = np.nonzero(dev > _SETTLING_BAND)[0]
    if outside.size == 0:
        settling = 0.0
    elif outside[-1] + 1 >= rs.size:
        warns.append("response does not settle within the 2 % band before the end of the record")
    else:
        i = int(outside[-1])
        settling = _interp_cross(tp[i], tp[i + 1], dev[i], dev[i + 1], _SETTLING_BAND) - t0
    # Paper-style threshold dead time.
    thr = max(5.0 * sigma, 0.02 * abs(change))
    exceed = np.nonzero(np.abs(yp - initial) > thr)[0]
    if exceed.size:
        dead_thr = float(tp[exceed[0]] - t0)
    return rise, overshoot, peak_time, settling, dead_thr


def _dead_time_fit(
    model: control.TransferFunction | control.StateSpace, t: NDArray[np.float64], tp: NDArray[np.float64],
    yp: NDArray[np.float64], t0: float, step: float, initial: float, change: float, dead_thr: float, t_end: float,
    t0_stderr_s: float | None, warns: list[str],
) -> tuple[float, float, float, float, float, Callable[[NDArray[np.float64]], NDArray[np.float64]]]:
    """Baseline, gain and dead time of `model`'s step response fitted to the samples after the step.

    Returns ``(dead, dead_se, g_fit, g_se, b_fit, unit_step)``: the dead time and fitted gain with
    their standard errors (t0's uncertainty added to the dead time's), the baseline, and the
    model's unit-step spline.
    """
    nan = float("nan")
    dts = np.diff(t)
    dt_hint = float(np.median(dts)) if dts.size else 0.01
    span = float(t_end - t0) + 1.0
    unit_step = unit_step_function(model, span, dt_hint)
    u = tp - t0

    def resid(p: NDArray[np.float64]) -> NDArray[np.float64]:
        return p[0] + p[1] * step * unit_step(u - p[2]) - yp

    def jac(p: NDArray[np.float64]) -> NDArray[np.float64]:
        J = np.empty((u.size, 3))
        J[:, 0] = 1.0
        J[:, 1] = step * unit_step(u - p[2])
        J[:, 2] = -p[1] * step * unit_step.derivative(u - p[2])  # type: ignore[attr-defined]
        return J

    g0 = change / step if change != 0 else 1.0
    # Seeds: threshold estimate minus the model's own time to reach 2 %.
    grid = np.linspace(0.0, span, 20001)
    sg = unit_step(grid)
    reach = np.nonzero(np.abs(sg) > 0.02)[0]
    t_reach = float(grid[reach[0]]) if reach.size else 0.0
    seeds = {0.0}
    if math.isfinite(dead_thr):
        seeds.add(max(dead_thr - t_reach, 0.0))
        seeds.add(max(dead_thr - t_reach - dt_hint, 0.0))
        seeds.add(max(dead_thr, 0.0))
    best = None
    for tau0 in sorted(seeds):
        sol = least_squares(
            resid,
            np.array([initial, g0, tau0]),
            jac=jac,
            bounds=([-np.inf, -np.inf, 0.0], [np.inf, np.inf, span]),
            method="trf",
            xtol=1e-14,
            ftol=1e-14,
            gtol=1e-14,
        )
        if best is None or sol.cost < best.cost:
            best = sol
    assert best is not None
    b_fit, g_fit, dead = (float(x) for x in best.x)
    Jb = jac(best.x)
    dof = u.size - 3
    s2 = float(best.fun @ best.fun) / dof if dof > 0 else nan
    try:
        cov = np.linalg.inv(Jb.T @ Jb) * s2
    except np.linalg.LinAlgError:
        cov = np.linalg.pinv(Jb.T @ Jb) * s2
        warns.append("singular Jacobian in the dead-time fit: standard errors are unreliable")
    # The fit locates the motion's start; the dead time is counted from t0, whose own
    # uncertainty (independent: the LED, not the blade) adds in quadrature.
    dead_se = float(math.hypot(math.sqrt(max(cov[2, 2], 0.0)), t0_stderr_s or 0.0))
    g_se = float(math.sqrt(max(cov[1, 1], 0.0)))
    if dead <= 0.0:
        warns.append("fitted dead time is at its lower bound 0")
    return dead, dead_se, g_fit, g_se, b_fit, unit_step


def _predicted_metrics(
    model: control.TransferFunction | control.StateSpace, dead: float, step: float, warns: list[str]
) -> dict[str, float] | None:
    """The model's step metrics with the fitted dead time (None, with a warning, when unavailable)."""
    predicted_metrics: dict[str, float] | None = None
    try:
        pm = model_step_metrics(model, dead_time_s=dead)
        predicted_metrics = {
            "rise_time_s": pm["rise_time_s"],
            "overshoot_pct": pm["overshoot_pct"],
            "settling_time_s": pm["settling_time_s"],
            "peak_time_s": pm["peak_time_s"],
            "final_change": pm["steady_state_value"] * step,
        }
    except (ServoscopeError, ValueError, ZeroDivisionError) as exc:
        warns.append(f"model step metrics unavailable: {exc}")
    return predicted_metrics


def model_step_metrics(tf: control.TransferFunction, *, dead_time_s: float = 0.0) -> dict[str, float]:
    """Rise time, overshoot and settling time of a model's step response.

    Uses :func:`control.step_info` (10-90 % rise time, 2 % settling band) on
    a fine time grid.

    Parameters
    ----------
    tf : control.TransferFunction
        Stable, continuous-time SISO model (without delay).
    dead_time_s : float, default 0.0
        Dead time in s, added to the settling and peak times (it does not
        change rise time or overshoot).

    Returns
    -------
    dict
        ``rise_time_s``, ``overshoot_pct``, ``settling_time_s``,
        ``peak_time_s``, ``peak``, ``steady_state_value`` (plain floats).
    """
    poles = np.asarray(tf.poles())
    if poles.size and np.any(poles.real >= 0):
        raise ServoscopeError("model_step_metrics: the model must be stable")
    slow = float(np.min(np.abs(poles.real))) if poles.size else 1.0
    fast = float(np.max(np.abs(poles))) if poles.size else 1.0
    t_end = 12.0 / slow
    n = int(min(400_001, max(20_001, math.ceil(t_end * fast * 200))))
    grid = np.linspace(0.0, t_end, n)
    # The response computed here (python-control's own simulation loops in Python); its final value the
    # model's DC gain, as step_info takes it from a system.
    info = control.step_info(step_response_on_grid(tf, grid), T=grid, yfinal=float(np.real(control.dcgain(tf))),
                             SettlingTimeThreshold=_SETTLING_BAND, RiseTimeLimits=_RISE_LIMITS)
    tau = float(dead_time_s)
    return {
        "rise_time_s": float(info["RiseTime"]),
        "overshoot_pct": float(info["Overshoot"]),
        "settling_time_s": float(info["SettlingTime"]) + tau,
        "peak_time_s": float(info["PeakTime"]) + tau,
        "peak": float(info["Peak"]),
        "steady_state_value": float(info["SteadyStateValue"]),
    }
