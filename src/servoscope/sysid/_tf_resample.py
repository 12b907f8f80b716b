"""Resampling the dwells: the delete-one jackknife that checks a fit's errors, and the bootstrap.

Part of the transfer-function fit (:mod:`servoscope.sysid.tf_fit`, "Uncertainty"). Both refit
the model from its estimate to a subset of the dwells.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from servoscope.defaults import JACKKNIFE_WIDENING_WARNING
from servoscope.parameters import interval95
from servoscope.sysid._rational import param_words
from servoscope.sysid._tf_build import canonical_in_bounds, ci95_intervals
from servoscope.sysid._tf_data import FitData, identifiability_problem
from servoscope.sysid._tf_minimize import local_fit
from servoscope.results import readonly
from servoscope.sysid.tf_result import TransferFunctionFit

__all__ = ["bootstrap_dwells", "with_gain_scale_uncertainty", "with_jackknife"]


def _refit(fit: TransferFunctionFit, d: FitData, sub: FitData) -> NDArray[np.float64] | None:
    """Physical parameters of ``fit``'s model refitted to the dwells ``sub`` from its estimate.

    Clamped to the bounds of the full data ``d``'s band, as the fit itself was
    (a refit that runs off towards a bound gives the bound, never an
    overflow); None when ``sub`` cannot determine the model or the refit fails.
    """
    st = fit._structure
    assert st is not None and fit._theta is not None
    if identifiability_problem(sub, st, fit.mode) is not None:
        return None
    sol = local_fit(st, sub, np.asarray(fit._theta), fit.mode == "complex")
    if not np.all(np.isfinite(sol.x)):
        return None
    return st.physical(canonical_in_bounds(st, d, sol.x))[0]


def with_jackknife(fit: TransferFunctionFit, d: FitData) -> TransferFunctionFit:
    """The fit with its standard errors checked by the delete-one-dwell jackknife (:mod:`servoscope.sysid.tf_fit`, "Uncertainty")."""
    st = fit._structure
    if st is None or fit._theta is None or d.n < st.n_params + 2:
        return fit
    names = st.names()
    se = np.array([fit.stderr_jacobian.get(n, fit.stderr[n]) for n in names])
    if not np.all(np.isfinite(se) & (se > 0)):
        return fit
    rows = np.full((d.n, st.n_params), np.nan)
    for i in range(d.n):
        row = _refit(fit, d, d.take(np.delete(np.arange(d.n), i)))
        if row is not None:
            rows[i] = row
    ok = np.all(np.isfinite(rows), axis=1)
    m = int(ok.sum())
    if m < 3:
        return fit
    kept = rows[ok]
    se_jack = np.sqrt((m - 1) / m * np.sum((kept - kept.mean(axis=0)) ** 2, axis=0))
    se_new = np.maximum(se, se_jack)
    scale = se_new / se
    cov = np.asarray(fit.covariance) * scale[:, None] * scale[None, :]
    vals = np.array([fit.params[n] for n in names])
    stderr = {n: float(v) for n, v in zip(names, se_new)}
    labels = [lab for lab, good in zip(d.labels, ok) if good]
    influence = {}
    warns = []
    for k, name in enumerate(names):
        i = int(np.argmax(np.abs(kept[:, k] - vals[k])))
        inf = influence[name] = {"dwell": labels[i], "without": float(kept[i, k]),
                                 "shift_stderr": float((kept[i, k] - vals[k]) / se_new[k])}
        if se_jack[k] > JACKKNIFE_WIDENING_WARNING * se[k]:
            warns.append(
                f"{param_words(name)} rests on {inf['dwell']} more than the dwells' stated errors allow (without it: "
                f"{inf['without']:.5g}); its interval was widened {se_jack[k] / se[k]:.1f}x by leaving each dwell "
                "out in turn. A systematic error in that dwell? (video compression of very small motions, a "
                "resonance the model lacks)"
            )
    return replace(
        fit,
        warnings=tuple(dict.fromkeys(fit.warnings + tuple(warns))),
        covariance=readonly(cov),
        stderr=stderr,
        ci95=ci95_intervals(names, vals, se_new, fit.n_residuals - fit.n_params),
        stderr_jackknife={n: float(v) for n, v in zip(names, se_jack)},
        influence=influence,
    )


def bootstrap_dwells(
    fit: TransferFunctionFit, d: FitData, n_boot: int, seed: int | None
) -> tuple[NDArray[np.float64], dict[str, tuple[float, float]], list[str]]:
    """Resample the dwells with replacement, refit from the estimate, percentile intervals."""
    st = fit._structure
    assert st is not None and fit._theta is not None
    rng = np.random.default_rng(seed)
    rows = []
    skipped = 0
    attempts = 0
    n = d.n
    while len(rows) < n_boot and attempts < 10 * n_boot:
        attempts += 1
        row = _refit(fit, d, d.take(np.sort(rng.integers(0, n, n))))
        if row is None:
            skipped += 1
            continue
        rows.append(row)
    warns = []
    if skipped:
        warns.append(f"bootstrap: {skipped} resample(s) could not determine the model and were redrawn")
    if len(rows) < n_boot:
        warns.append(f"bootstrap: only {len(rows)} of {n_boot} resamples could be fitted")
    samples = np.array(rows).reshape(-1, st.n_params)
    ci = {}
    for j, name in enumerate(st.names()):
        if samples.shape[0]:
            lo, hi = np.percentile(samples[:, j], [2.5, 97.5])
            ci[name] = (float(lo), float(hi))
        else:
            ci[name] = (float("nan"), float("nan"))
    return samples, ci, warns


def with_gain_scale_uncertainty(fit: TransferFunctionFit, relative_stderr: float, reason: str) -> TransferFunctionFit:
    """The fit with an uncertainty of the angle's scale added to its gain's.

    Every dwell's gain shares one scale error when the angles themselves are read with a
    scale uncertainty (a plane calibrated from a board photo, a view estimated from the
    footage): no number of dwells averages it away, so it is added to the gain's standard
    error in quadrature, ``σK² + (K·relative_stderr)²``, after the fit. The other parameters
    (frequencies, damping, dead time) are ratios of the response's shape and keep theirs.

    Parameters
    ----------
    fit : TransferFunctionFit
    relative_stderr : float
        The angle scale's relative standard uncertainty (0.01: 1 %).
    reason : str
        Where it comes from, said in the fit's warnings when it widens the interval by more
        than 10 %.
    """
    rel = float(relative_stderr)
    if not (math.isfinite(rel) and rel > 0) or "gain" not in fit.stderr:
        return fit
    k = float(fit.params.get("gain", fit.gain))
    old = float(fit.stderr["gain"])
    new = math.hypot(old, abs(k) * rel)
    names = list(fit.param_names)
    stderr = {**fit.stderr, "gain": new}
    cov = np.array(fit.covariance, dtype=np.float64, copy=True)
    if "gain" in names and cov.ndim == 2 and cov.size:
        i = names.index("gain")
        cov[i, i] = new * new
    vals = np.array([fit.params[n] for n in names])
    ses = np.array([stderr[n] for n in names])
    ci = ci95_intervals(names, vals, ses, fit.n_residuals - fit.n_params)
    boot = None
    if fit.ci95_bootstrap is not None and "gain" in fit.ci95_bootstrap:
        lo, hi = fit.ci95_bootstrap["gain"]
        add = interval95(0.0, abs(k) * rel, "normal")[1]  # the scale error's own 95 % half width
        boot = {**fit.ci95_bootstrap, "gain": (k - math.hypot(k - lo, add), k + math.hypot(hi - k, add))}
    warns = fit.warnings
    if new > 1.1 * old:
        warns = tuple(dict.fromkeys(warns + (f"the gain's interval includes the angle scale's uncertainty "
                                             f"({100.0 * rel:.2g} %, {reason}): ×{new / old:.1f} wider",)))
    return replace(fit, covariance=readonly(cov), stderr=stderr, ci95=ci,
                   ci95_bootstrap=boot if boot is not None else fit.ci95_bootstrap, warnings=warns)
