"""From the optimizer's solution to a :class:`~servoscope.sysid.TransferFunctionFit`.

Part of the transfer-function fit (:mod:`servoscope.sysid.tf_fit` describes the uncertainty
and the goodness of fit): the covariance from the Jacobian (Birge-scaled), 95 % intervals,
the parameters the data do not determine, CIFER's J, AIC and BIC.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from servoscope.errors import ServoscopeError
from servoscope.parameters import interval95
from servoscope.results import readonly
from servoscope.sysid._rational import FREQ_MARGIN, ZETA_RANGE, Structure, log_response, param_words
from servoscope.sysid._tf_data import FitData, wrap_rad
from servoscope.sysid._tf_metrics import DB_PER_NEPER, cifer_cost
from servoscope.sysid._tf_minimize import residual_jacobian, residuals
from servoscope.sysid.frequency_response import FrequencyResponse
from servoscope.sysid.tf_result import TransferFunctionFit

__all__ = ["build_fit", "canonical_in_bounds", "ci95_intervals"]


def canonical_in_bounds(st: Structure, d: FitData, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """An optimizer's solution in canonical form, clamped to the bounds of ``d``'s band (every fit's result is)."""
    lo_c, hi_c = st.clamp_limits(float(d.w[0]), float(d.w[-1]))
    return np.clip(st.canonical(x), lo_c, hi_c)


def ci95_intervals(names: Sequence[str], vals: NDArray[np.float64], se: NDArray[np.float64],
                   dof: int) -> dict[str, tuple[float, float]]:
    """``value ± t(0.975, dof)·stderr`` per parameter (as nlparci), by :func:`servoscope.parameters.interval95`."""
    return {n: interval95(float(v), float(e), "student", dof=dof) for n, v, e in zip(names, vals, se)}


def build_fit(
    st: Structure,
    d: FitData,
    fr: FrequencyResponse,
    sol: Any,
    mode: str,
    warns: list[str],
) -> TransferFunctionFit:
    """Turn an optimizer solution into a TransferFunctionFit (covariance, CI, J, AIC/BIC)."""
    use_phase = mode == "complex"
    theta = canonical_in_bounds(st, d, sol.x)
    r = residuals(st, d, theta, use_phase)
    J = residual_jacobian(st, d, theta, use_phase)
    # Parameters the user fixed are not estimated: no error, no degree of freedom.
    free = ~st.fixed
    m, p = r.size, int(np.count_nonzero(free))
    dof = m - p
    chi2 = float(r @ r)
    warns = list(warns)
    cov_int = _internal_covariance(J, free, chi2, dof, d.stated, warns)
    vals, der = st.physical(theta)
    cov = der[:, None] * cov_int * der[None, :]
    diag = np.diag(cov)
    se = np.where(np.isfinite(diag), np.sqrt(np.clip(diag, 0.0, None)), np.nan)
    names = st.names()
    params = {n: float(v) for n, v in zip(names, vals)}
    stderr = {n: float(s) for n, s in zip(names, se)}
    ci95 = ci95_intervals(names, vals, se, dof)

    undetermined, more = _undetermined(st, d, names, vals, se)
    warns.extend(more)

    lg = log_response(st, theta, d.w)
    res_db = DB_PER_NEPER * (lg.real - d.lng)
    res_deg = None
    ph_err = None
    if use_phase:
        err = np.degrees(wrap_rad(lg.imag - d.ph))
        ph_err = np.where(d.has_ph, err, np.nan)
        res_deg = float(np.sqrt(np.mean(err[d.has_ph] ** 2)))
    jc = cifer_cost(res_db, ph_err, d.fid)
    aic = chi2 + 2.0 * p
    bic = chi2 + p * math.log(m)

    if not all(math.isfinite(v) for v in vals):
        raise ServoscopeError("transfer-function fit failed: non-finite parameters")
    return TransferFunctionFit(
        covariance=readonly(cov),
        residual_rms_db=float(np.sqrt(np.mean(res_db**2))),
        residual_rms_deg=res_deg,
        n_points=d.n,
        mode=mode,
        cost=0.5 * chi2,
        warnings=tuple(dict.fromkeys(warns)),
        data=fr,
        order=(st.nb, st.na),
        zeros=st.zeros,
        param_names=names,
        params=params,
        stderr=stderr,
        ci95=ci95,
        stderr_jacobian=dict(stderr),
        J=jc,
        aic=aic,
        bic=bic,
        n_params=p,
        n_residuals=m,
        undetermined=tuple(undetermined),
        _structure=st,
        _theta=readonly(theta),
    )


def _internal_covariance(J: NDArray[np.float64], free: NDArray[np.bool_], chi2: float, dof: int, stated: bool,
                         warns: list[str]) -> NDArray[np.float64]:
    """Theta's covariance from the Jacobian's free columns (Birge-scaled), zero for the held ones; warnings appended."""
    Jf = J[:, free]
    cov_int = np.zeros((J.shape[1], J.shape[1]))
    try:
        cov_free = np.linalg.inv(Jf.T @ Jf)
        if not np.all(np.isfinite(cov_free)):
            raise np.linalg.LinAlgError
    except np.linalg.LinAlgError:
        cov_free = np.linalg.pinv(Jf.T @ Jf)
        warns.append("singular Jacobian: standard errors are unreliable (too many parameters for the data?)")
    cov_int[np.ix_(free, free)] = cov_free
    if dof <= 0:
        warns.append("no degrees of freedom left: standard errors unavailable")
        return np.full_like(cov_int, np.nan)
    # Stated errors are trusted unless the misfit says they are too
    # small; without any, the scatter alone sets the scale (nlinfit).
    return cov_int * (max(1.0, chi2 / dof) if stated else chi2 / dof)


def _undetermined(
    st: Structure, d: FitData, names: tuple[str, ...], vals: NDArray[np.float64], se: NDArray[np.float64]
) -> tuple[list[str], list[str]]:
    """Parameters outside the data's band or not determined by them, and the warnings about them.

    Returns the names of the undetermined parameters and the warnings (a dead time at 0, a
    pole or zero outside the band, an implausible damping ratio, a relative error > 100 %, a
    pole just outside the band), in that order.
    """
    warns: list[str] = []
    undetermined: list[str] = []
    w_lo, w_hi = float(d.w[0]), float(d.w[-1])
    for i, (name, kind) in enumerate(zip(names, st.kinds())):
        if kind == "tau":
            if vals[i] < 1e-9:
                warns.append("fitted dead time is at its lower bound 0")
            continue
        if kind not in ("freq", "zeta"):
            continue
        rel = se[i] / vals[i]
        if kind == "freq" and not (w_lo / FREQ_MARGIN <= vals[i] <= w_hi * FREQ_MARGIN):
            undetermined.append(name)
            warns.append(
                f"{param_words(name)} {vals[i]:.4g} rad/s lies far outside the measured band "
                f"[{w_lo:.3g}, {w_hi:.3g}] rad/s: the data do not determine it; try a lower order"
            )
        elif kind == "zeta" and not (ZETA_RANGE[0] <= vals[i] <= ZETA_RANGE[1]):
            undetermined.append(name)
            warns.append(f"{param_words(name)} {vals[i]:.4g} is implausible: the data do not determine it; try a lower order")
        elif not (rel <= 1.0):
            undetermined.append(name)
            warns.append(
                f"{param_words(name)} is not determined by the data (stderr {100 * rel:.0f} % of its value); try a lower order"
            )
        if kind == "freq" and w_hi < vals[i] <= w_hi * FREQ_MARGIN:
            warns.append(
                f"highest measured frequency {w_hi:.3g} rad/s is below the fitted {param_words(name)} "
                f"{vals[i]:.3g} rad/s: it is poorly determined"
            )
        elif kind == "freq" and w_lo / FREQ_MARGIN <= vals[i] < w_lo and name.startswith(("pole", "natural")):
            warns.append(
                f"lowest measured frequency {w_lo:.3g} rad/s is above the fitted {param_words(name)} "
                f"{vals[i]:.3g} rad/s: K is extrapolated"
            )
    return undetermined, warns
