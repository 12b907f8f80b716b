"""Fit a second-order transfer function to a measured frequency response.

Model (paper eq. 5)::

    G(s) = K / (s**2/wn**2 + 2*zeta*s/wn + 1) * exp(-s*tau)

``mode="magnitude"`` fits ``|G(jw)| = K*wn**2 / sqrt((wn**2 - w**2)**2 +
(2*zeta*wn*w)**2)`` to the measured gains (``tau`` cannot be identified from
magnitudes). ``mode="complex"`` also fits the measured phases, with the dead
time ``tau``.

Residuals are natural-log magnitudes (and phases in rad), divided by the
measured standard errors in the same units, with the standard errors floored
at ``max(0.5 * median, 1e-3)`` so that one very precise point cannot dominate
and model error is not ignored. The parameters are ``(ln K, ln wn, zeta[,
tau])`` with ``zeta`` in [1e-4, 20] and ``tau >= 0``; several seeds are tried
(``wn`` from the -3 dB point, the -90 deg phase crossing and the frequency
range; ``zeta`` in {0.2, 0.5, 0.8, 1.5}) and the lowest cost is kept.
Standard errors come from the Jacobian, with the covariance scaled by the
reduced chi-square (as lmfit does by default).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Literal

import control
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq, least_squares

from servoscope.errors import ServoscopeError
from servoscope.sysid.frequency_response import FrequencyResponse
from servoscope.sysid.sine import _jsonable, _readonly

__all__ = ["TransferFunctionFit", "bandwidth_rad_s", "fit_second_order"]

_DB_PER_NEPER = 20.0 / math.log(10.0)
_ZETA_BOUNDS = (1e-4, 20.0)
_SIGMA_FLOOR = 1e-3


def _siso_eval(tf: control.TransferFunction, s: NDArray[np.complex128]) -> NDArray[np.complex128]:
    num = np.atleast_1d(np.asarray(tf.num[0][0], dtype=float))
    den = np.atleast_1d(np.asarray(tf.den[0][0], dtype=float))
    return np.polyval(num, s) / np.polyval(den, s)


def bandwidth_rad_s(tf: control.TransferFunction, *, drop_db: float = -3.0) -> float:
    """Frequency where the gain first falls ``|drop_db|`` dB below the DC gain.

    The default is the classic -3 dB bandwidth, defined as ``|G(jw)| =
    |G(0)| * 10**(-3/20)``. Found by scanning a log grid for the first
    crossing and refining it with :func:`scipy.optimize.brentq`.

    Parameters
    ----------
    tf : control.TransferFunction
        Stable, continuous-time SISO transfer function with finite, nonzero DC
        gain (a dead time does not change the magnitude, so pass the
        rational part).
    drop_db : float, default -3.0
        Gain drop in dB (negative).

    Returns
    -------
    float
        Bandwidth in rad/s; ``inf`` when the gain never falls that far.

    Raises
    ------
    ServoscopeError
        For a discrete-time, MIMO or unstable system, or a zero/infinite DC
        gain.
    """
    if not isinstance(tf, control.TransferFunction):
        tf = control.tf(tf)
    if tf.ninputs != 1 or tf.noutputs != 1:
        raise ServoscopeError("bandwidth_rad_s: only SISO systems are supported")
    if tf.isdtime(strict=True):
        raise ServoscopeError("bandwidth_rad_s: only continuous-time systems are supported")
    poles = np.asarray(tf.poles())
    if poles.size and np.any(poles.real >= 0):
        raise ServoscopeError("bandwidth_rad_s: the system is not stable")
    if not drop_db < 0:
        raise ServoscopeError(f"bandwidth_rad_s: drop_db must be negative, got {drop_db}")
    dc = abs(complex(_siso_eval(tf, np.array([0j]))[0]))
    if not (math.isfinite(dc) and dc > 0):
        raise ServoscopeError("bandwidth_rad_s: DC gain is zero or infinite")
    target = dc * 10.0 ** (drop_db / 20.0)
    roots = np.concatenate([poles, np.asarray(tf.zeros())])
    mags = np.abs(roots[np.abs(roots) > 0])
    lo = (mags.min() if mags.size else 1.0) * 1e-4
    hi = (mags.max() if mags.size else 1.0) * 1e4

    def f(w: float) -> float:
        return float(abs(_siso_eval(tf, np.array([1j * w]))[0]) - target)

    grid = np.geomspace(lo, hi, 4001)
    vals = np.abs(_siso_eval(tf, 1j * grid)) - target
    below = np.nonzero(vals < 0)[0]
    if below.size == 0:
        return float("inf")
    k = int(below[0])
    if k == 0:
        return float(brentq(f, 0.0, grid[0], xtol=1e-14, rtol=1e-14))
    return float(brentq(f, grid[k - 1], grid[k], xtol=1e-14, rtol=1e-14))


def _second_order_tf(gain: float, wn: float, zeta: float) -> control.TransferFunction:
    return control.tf([gain], [1.0 / wn**2, 2.0 * zeta / wn, 1.0])


@dataclass(frozen=True)
class TransferFunctionFit:
    """Second-order transfer function fitted to a frequency response.

    ``G(s) = gain / (s**2/wn**2 + 2*zeta*s/wn + 1) * exp(-s*dead_time_s)``.

    Attributes
    ----------
    gain : float
        Static gain ``K`` (output units per input unit, e.g. rad per unit).
    natural_frequency_rad_s : float
        ``wn`` in rad/s.
    damping_ratio : float
        ``zeta`` (dimensionless).
    gain_stderr, natural_frequency_stderr_rad_s, damping_ratio_stderr : float
        Standard errors (same units; NaN when not estimable).
    dead_time_s : float or None
        Dead time ``tau`` in s (mode="complex" only; None for a magnitude fit,
        which cannot identify it).
    dead_time_stderr_s : float or None
        Standard error of `dead_time_s` in s.
    covariance : numpy.ndarray
        Covariance of ``(K, wn, zeta[, tau])`` in physical units.
    residual_rms_db : float
        RMS of ``20*log10(model/measured)`` over the points, dB.
    residual_rms_deg : float or None
        RMS phase residual in degrees (mode="complex").
    n_points : int
        Number of frequency points used.
    mode : str
        "magnitude" or "complex".
    cost : float
        Final least-squares cost ``0.5*sum(r**2)`` of the weighted residuals.
    warnings : tuple of str
        Non-fatal problems (parameter at a bound, poorly covered range, ...).
    data : FrequencyResponse
        The fitted measurements.
    """

    gain: float
    natural_frequency_rad_s: float
    damping_ratio: float
    gain_stderr: float
    natural_frequency_stderr_rad_s: float
    damping_ratio_stderr: float
    dead_time_s: float | None
    dead_time_stderr_s: float | None
    covariance: NDArray[np.float64] = field(repr=False, compare=False)
    residual_rms_db: float = float("nan")
    residual_rms_deg: float | None = None
    n_points: int = 0
    mode: str = "magnitude"
    cost: float = float("nan")
    warnings: tuple[str, ...] = ()
    data: FrequencyResponse | None = field(default=None, repr=False, compare=False)

    @property
    def num(self) -> list[float]:
        """Numerator coefficients, descending powers of s: ``[K]``."""
        return [float(self.gain)]

    @property
    def den(self) -> list[float]:
        """Denominator, descending powers of s: ``[1/wn**2, 2*zeta/wn, 1]``."""
        wn = self.natural_frequency_rad_s
        return [1.0 / wn**2, 2.0 * self.damping_ratio / wn, 1.0]

    @property
    def transfer_function(self) -> control.TransferFunction:
        """The rational part as a ``control.TransferFunction`` (no dead time)."""
        return control.tf(self.num, self.den)

    @property
    def natural_frequency_hz(self) -> float:
        """``wn`` in Hz."""
        return self.natural_frequency_rad_s / (2.0 * math.pi)

    @property
    def bandwidth_rad_s(self) -> float:
        """-3 dB bandwidth (relative to the DC gain) of the fitted model, rad/s."""
        return bandwidth_rad_s(self.transfer_function)

    @property
    def bandwidth_hz(self) -> float:
        """-3 dB bandwidth in Hz."""
        return self.bandwidth_rad_s / (2.0 * math.pi)

    def magnitude(self, omega_rad_s: ArrayLike) -> NDArray[np.float64]:
        """Model ``|G(jw)|`` at angular frequencies `omega_rad_s` (rad/s)."""
        w = np.asarray(omega_rad_s, dtype=float)
        return _mag(w, self.gain, self.natural_frequency_rad_s, self.damping_ratio)

    def phase_rad(self, omega_rad_s: ArrayLike) -> NDArray[np.float64]:
        """Model phase (continuous, incl. the dead time if fitted) in rad."""
        w = np.asarray(omega_rad_s, dtype=float)
        tau = self.dead_time_s or 0.0
        return _phase(w, self.natural_frequency_rad_s, self.damping_ratio) - w * tau

    def summary(self) -> dict[str, Any]:
        """Scalar results as a JSON-serializable dict (NaN -> None)."""
        return _jsonable(
            {
                "mode": self.mode,
                "gain": self.gain,
                "gain_stderr": self.gain_stderr,
                "natural_frequency_rad_s": self.natural_frequency_rad_s,
                "natural_frequency_stderr_rad_s": self.natural_frequency_stderr_rad_s,
                "damping_ratio": self.damping_ratio,
                "damping_ratio_stderr": self.damping_ratio_stderr,
                "dead_time_s": self.dead_time_s,
                "dead_time_stderr_s": self.dead_time_stderr_s,
                "bandwidth_rad_s": self.bandwidth_rad_s,
                "bandwidth_hz": self.bandwidth_hz,
                "num": self.num,
                "den": self.den,
                "residual_rms_db": self.residual_rms_db,
                "residual_rms_deg": self.residual_rms_deg,
                "n_points": self.n_points,
                "warnings": list(self.warnings),
            }
        )

    def to_pandas(self) -> Any:
        """Measured vs. fitted gain (and phase) per point as a DataFrame. Needs pandas."""
        from servoscope.sysid.sine import _import_pandas

        pd = _import_pandas()
        if self.data is None:
            raise ServoscopeError("TransferFunctionFit.to_pandas: no data attached")
        w = self.data.omega_rad_s
        model_db = 20.0 * np.log10(self.magnitude(w))
        return pd.DataFrame(
            {
                "video": list(self.data.labels),
                "omega_rad_s": w,
                "gain_db": self.data.gain_db,
                "model_gain_db": model_db,
                "residual_db": self.data.gain_db - model_db,
                "phase_deg": self.data.phase_deg,
                "model_phase_deg": np.degrees(self.phase_rad(w)),
            }
        )

    def _repr_html_(self) -> str:
        rows = "".join(
            f"<tr><td>{k}</td><td>{v}</td></tr>" for k, v in self.summary().items()
        )
        return f"<table><caption>TransferFunctionFit</caption>{rows}</table>"


def _mag(w: NDArray[np.float64], k: float, wn: float, zeta: float) -> NDArray[np.float64]:
    return k * wn**2 / np.sqrt((wn**2 - w**2) ** 2 + (2.0 * zeta * wn * w) ** 2)


def _phase(w: NDArray[np.float64], wn: float, zeta: float) -> NDArray[np.float64]:
    # Continuous phase of 1/(s^2/wn^2 + 2 zeta s/wn + 1) on s = jw, in (-pi, 0].
    return -np.arctan2(2.0 * zeta * wn * w, wn**2 - w**2)


def _ln_mag(p: NDArray[np.float64], w: NDArray[np.float64]) -> NDArray[np.float64]:
    lnk, lnwn, zeta = p[0], p[1], p[2]
    x = w * np.exp(-lnwn)  # w / wn
    return lnk - 0.5 * np.log((1.0 - x**2) ** 2 + (2.0 * zeta * x) ** 2)


def _ln_mag_jac(p: NDArray[np.float64], w: NDArray[np.float64]) -> NDArray[np.float64]:
    lnwn, zeta = p[1], p[2]
    x = w * np.exp(-lnwn)
    d = (1.0 - x**2) ** 2 + (2.0 * zeta * x) ** 2
    # dd/dx = 2(1-x^2)(-2x) + 8 zeta^2 x ; dx/dlnwn = -x
    dd_dx = -4.0 * x * (1.0 - x**2) + 8.0 * zeta**2 * x
    J = np.empty((w.size, 3))
    J[:, 0] = 1.0
    J[:, 1] = -0.5 / d * dd_dx * (-x)
    J[:, 2] = -0.5 / d * 8.0 * zeta * x**2
    return J


def _phase_model(p: NDArray[np.float64], w: NDArray[np.float64]) -> NDArray[np.float64]:
    wn = math.exp(p[1])
    return _phase(w, wn, p[2]) - w * p[3]


def _phase_jac(p: NDArray[np.float64], w: NDArray[np.float64]) -> NDArray[np.float64]:
    lnwn, zeta = p[1], p[2]
    x = w * np.exp(-lnwn)
    # phase = -atan2(2 zeta x, 1 - x^2); u = 2 zeta x, v = 1 - x^2
    u = 2.0 * zeta * x
    v = 1.0 - x**2
    r2 = u**2 + v**2
    # d atan2(u, v) = (v du - u dv) / r2
    du_dx, dv_dx = 2.0 * zeta, -2.0 * x
    dphi_dx = -(v * du_dx - u * dv_dx) / r2
    J = np.zeros((w.size, 4))
    J[:, 1] = dphi_dx * (-x)
    J[:, 2] = -(v * 2.0 * x) / r2
    J[:, 3] = -w
    return J


def _sigma(values: NDArray[np.float64]) -> NDArray[np.float64]:
    """Floored standard errors: NaN -> median; floor at max(0.5*median, 1e-3)."""
    s = np.asarray(values, dtype=float).copy()
    ok = np.isfinite(s) & (s > 0)
    if not np.any(ok):
        return np.ones_like(s)
    med = float(np.median(s[ok]))
    s[~ok] = med
    return np.maximum(s, max(0.5 * med, _SIGMA_FLOOR))


def _wrap(x: NDArray[np.float64]) -> NDArray[np.float64]:
    return (x + np.pi) % (2.0 * np.pi) - np.pi


def _wn_seeds(fr: FrequencyResponse, w: NDArray[np.float64], lng: NDArray[np.float64]) -> list[float]:
    seeds: list[float] = []
    # -3 dB below the low-frequency gain (first point), interpolated in log w.
    ref = lng[0]
    drop = ref - lng
    idx = np.nonzero(drop >= 0.5 * math.log(2.0))[0]
    if idx.size:
        k = int(idx[0])
        if k == 0:
            seeds.append(float(w[0]))
        else:
            d0, d1 = drop[k - 1], drop[k]
            frac = (0.5 * math.log(2.0) - d0) / (d1 - d0) if d1 != d0 else 0.0
            seeds.append(float(math.exp(math.log(w[k - 1]) + frac * (math.log(w[k]) - math.log(w[k - 1])))))
    # Phase crossing -90 deg.
    ph = fr.phase_rad
    known = np.isfinite(ph)
    if np.count_nonzero(known) >= 2:
        wk, pk = w[known], ph[known]
        idx = np.nonzero(pk <= -math.pi / 2)[0]
        if idx.size and idx[0] > 0:
            k = int(idx[0])
            p0, p1 = pk[k - 1], pk[k]
            frac = (-math.pi / 2 - p0) / (p1 - p0) if p1 != p0 else 0.0
            seeds.append(float(math.exp(math.log(wk[k - 1]) + frac * (math.log(wk[k]) - math.log(wk[k - 1])))))
    gm = float(math.exp(np.mean(np.log(w))))
    seeds.append(gm)
    if seeds:
        base = seeds[0]
        seeds += [base * 2.0, base / 2.0]
    seeds.append(float(w[-1]))
    out: list[float] = []
    for s in seeds:
        if math.isfinite(s) and s > 0 and all(abs(math.log(s / o)) > 1e-3 for o in out):
            out.append(s)
    return out


def fit_second_order(
    fr: FrequencyResponse,
    *,
    mode: Literal["magnitude", "complex"] = "magnitude",
) -> TransferFunctionFit:
    """Fit ``K / (s**2/wn**2 + 2*zeta*s/wn + 1)`` to a frequency response.

    Parameters
    ----------
    fr : FrequencyResponse
        Measured gains (and phases for ``mode="complex"``), with standard
        errors used as weights when available.
    mode : {"magnitude", "complex"}, default "magnitude"
        "magnitude": fit ``|G|`` only (the paper's method); the dead time is
        not identifiable and is reported as None. "complex": fit log-magnitude
        and phase (rad) of ``G(s)*exp(-s*tau)``; points without a phase
        contribute their magnitude only.

    Returns
    -------
    TransferFunctionFit

    Raises
    ------
    ServoscopeError
        Fewer than 3 usable points (4 magnitude+phase residuals for
        "complex"), non-positive gains, no phases in "complex" mode, or an
        unknown mode.
    """
    if mode not in ("magnitude", "complex"):
        raise ServoscopeError(f"fit_second_order: unknown mode {mode!r} (use 'magnitude' or 'complex')")
    w_all = fr.omega_rad_s
    g_all = fr.gain
    use = np.isfinite(w_all) & np.isfinite(g_all) & (g_all > 0) & (w_all > 0)
    if np.count_nonzero(use) < 3:
        raise ServoscopeError(
            f"fit_second_order: need at least 3 points with positive gain, got {int(np.count_nonzero(use))}"
        )
    order = np.argsort(w_all[use], kind="stable")
    w = w_all[use][order]
    lng = np.log(g_all[use][order])
    sig_ln = _sigma((fr.gain_stderr[use] / fr.gain[use])[order])
    ph = fr.phase_rad[use][order]
    ph_known = np.isfinite(ph)
    if mode == "complex" and not np.any(ph_known):
        raise ServoscopeError("fit_second_order: mode='complex' needs phases (t0 unknown for all dwells)")
    sig_ph = _sigma(np.radians(fr.phase_stderr_deg[use][order]))[ph_known] if mode == "complex" else None
    n = w.size
    warns: list[str] = []

    def resid_mag(p: NDArray[np.float64]) -> NDArray[np.float64]:
        return (_ln_mag(p, w) - lng) / sig_ln

    def jac_mag(p: NDArray[np.float64]) -> NDArray[np.float64]:
        return _ln_mag_jac(p[:3], w) / sig_ln[:, None]

    lower = [-np.inf, -np.inf, _ZETA_BOUNDS[0]]
    upper = [np.inf, np.inf, _ZETA_BOUNDS[1]]
    tol = dict(xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=2000)

    best = None
    for wn0 in _wn_seeds(fr, w, lng):
        for z0 in (0.2, 0.5, 0.8, 1.5):
            p0 = np.array([0.0, math.log(wn0), z0])
            # Optimal ln K for these (wn, zeta): weighted mean offset.
            wts = 1.0 / sig_ln**2
            p0[0] = float(np.sum(wts * (lng - _ln_mag(p0, w))) / np.sum(wts))
            sol = least_squares(resid_mag, p0, jac=jac_mag, bounds=(lower, upper), method="trf", **tol)
            if best is None or sol.cost < best.cost - 1e-12 * max(best.cost, 1e-300):
                best = sol
    assert best is not None
    p = best.x
    tau = None
    tau_se = None
    res_deg = None

    if mode == "complex":
        wk = w[ph_known]
        phk = ph[ph_known]

        def resid_c(q: NDArray[np.float64]) -> NDArray[np.float64]:
            rm = (_ln_mag(q, w) - lng) / sig_ln
            rp = _wrap(_phase_model(q, wk) - phk) / sig_ph
            return np.concatenate([rm, rp])

        def jac_c(q: NDArray[np.float64]) -> NDArray[np.float64]:
            Jm = np.zeros((n, 4))
            Jm[:, :3] = _ln_mag_jac(q, w) / sig_ln[:, None]
            Jp = _phase_jac(q, wk) / sig_ph[:, None]
            return np.vstack([Jm, Jp])

        if n + wk.size < 5:
            raise ServoscopeError("fit_second_order: too few points for mode='complex'")
        lower_c = lower + [0.0]
        upper_c = upper + [np.inf]
        best_c = None
        # Dead-time seeds from the phase left over by the magnitude fit.
        extra = _phase(wk, math.exp(p[1]), p[2]) - phk
        extra = np.unwrap(extra)
        tau_seeds = {0.0}
        with np.errstate(divide="ignore", invalid="ignore"):
            est = extra / wk
        est = est[np.isfinite(est)]
        if est.size:
            tau_seeds.add(max(float(np.median(est)), 0.0))
            tau_seeds.add(max(float(est[-1]), 0.0))
        starts = [np.append(p, t) for t in sorted(tau_seeds)]
        for wn0 in _wn_seeds(fr, w, lng)[:2]:
            for z0 in (0.3, 0.7):
                for t in sorted(tau_seeds):
                    starts.append(np.array([p[0], math.log(wn0), z0, t]))
        for q0 in starts:
            q0 = q0.copy()
            q0[2] = min(max(q0[2], _ZETA_BOUNDS[0] * 1.01), _ZETA_BOUNDS[1] * 0.99)
            sol = least_squares(resid_c, q0, jac=jac_c, bounds=(lower_c, upper_c), method="trf", **tol)
            if best_c is None or sol.cost < best_c.cost - 1e-12 * max(best_c.cost, 1e-300):
                best_c = sol
        assert best_c is not None
        best = best_c
        p = best.x
        tau = float(p[3])
        res_deg = float(np.degrees(np.sqrt(np.mean(_wrap(_phase_model(p, wk) - phk) ** 2))))

    J = best.jac
    n_par = p.size
    n_res = best.fun.size
    dof = n_res - n_par
    chi2 = float(best.fun @ best.fun)
    try:
        cov_int = np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov_int = np.linalg.pinv(J.T @ J)
        warns.append("singular Jacobian: standard errors are unreliable")
    if dof > 0:
        cov_int = cov_int * (chi2 / dof)
    else:
        cov_int = np.full_like(cov_int, np.nan)
        warns.append("no degrees of freedom left: standard errors unavailable")
    k_hat, wn_hat, z_hat = math.exp(p[0]), math.exp(p[1]), float(p[2])
    D = np.diag([k_hat, wn_hat] + [1.0] * (n_par - 2))
    cov = D @ cov_int @ D
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    se = np.where(np.isfinite(np.diag(cov)), se, np.nan)
    if tau is not None:
        tau_se = float(se[3])

    if z_hat <= _ZETA_BOUNDS[0] * 1.001 or z_hat >= _ZETA_BOUNDS[1] * 0.999:
        warns.append(f"damping ratio {z_hat:.4g} is at its bound")
    if w[-1] < wn_hat:
        warns.append(
            f"highest measured frequency {w[-1]:.3g} rad/s is below the fitted natural "
            f"frequency {wn_hat:.3g} rad/s: wn and zeta are poorly determined"
        )
    if w[0] > wn_hat:
        warns.append("lowest measured frequency is above the natural frequency: K is extrapolated")

    res_db = _DB_PER_NEPER * (_ln_mag(p, w) - lng)
    return TransferFunctionFit(
        gain=k_hat,
        natural_frequency_rad_s=wn_hat,
        damping_ratio=z_hat,
        gain_stderr=float(se[0]),
        natural_frequency_stderr_rad_s=float(se[1]),
        damping_ratio_stderr=float(se[2]),
        dead_time_s=tau,
        dead_time_stderr_s=tau_se,
        covariance=_readonly(cov),
        residual_rms_db=float(np.sqrt(np.mean(res_db**2))),
        residual_rms_deg=res_deg,
        n_points=int(n),
        mode=mode,
        cost=float(best.cost),
        warnings=tuple(warns),
        data=fr,
    )
