"""Choose the order ``(nb, na)`` of the transfer function from the data.

The paper estimates the order graphically, from the high-frequency slope of
the log-magnitude plot (about -20 dB/decade per excess pole). This module
does that step numerically and then fits every candidate order and compares
them by an information criterion and CIFER's cost J:

1. *Slope*: weighted straight line through ``gain_db`` against
   ``log10(w)`` over the top half decade of the data (at least 3 points);
   ``relative_degree_estimate = max(1, round(-slope/20))``. The slope
   measured below the asymptote is shallower than the asymptote, so this
   estimate is a lower bound and is reported, not imposed.
2. *Candidates*: every ``0 <= nb < na <= max_order`` that the data can
   determine with at least one degree of freedom left, by increasing
   ``nb`` for each ``na``; once a candidate has a parameter the data do not
   determine, more zeros for the same ``na`` are not tried (they only add
   freedom; this saves most of the time spent on hopeless fits).
3. *Choice*: candidates with a parameter the data do not determine
   (relative standard error > 100 %, a pole or zero far outside the band:
   over-parameterized, typically a near pole-zero cancellation) are
   rejected; among the rest with an acceptable ``J <= 100`` (all of
   them if none is), the lowest criterion (BIC by default); candidates
   whose criterion is within 2 of the lowest are considered equally good
   (Kass & Raftery: "not worth more than a bare mention") and the one with
   the fewest parameters wins (then the lowest criterion).

The criteria are ``chi2/phi + 2p`` (AIC) and ``chi2/phi + p*ln(m)`` (BIC),
where ``phi = max(1, min reduced chi2 over the determined candidates)``:
when even the best-fitting candidate leaves more scatter than the measured
standard errors explain (understated errors, model error), the residuals
are rescaled by it (Mallows' choice) so that the penalty keeps its weight.
The table's AIC/BIC, and those of the fits in `fits`, are these values.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any, Literal

import numpy as np

from servoscope.errors import ServoscopeError
from servoscope.sysid._rational import Structure
from servoscope.sysid.frequency_response import FrequencyResponse
from servoscope.sysid._fixed_order import fit_fixed_order
from servoscope.sysid._tf_data import floored_sigma, identifiability_problem, prepare_fit_data
from servoscope.sysid._tf_metrics import J_ACCEPTABLE
from servoscope.sysid.tf_result import OrderSelection, TransferFunctionFit

__all__ = ["OrderSelection", "estimate_slope_db_per_decade", "select_order"]

#: Criterion differences below this are "not worth more than a bare mention".
CRITERION_TIE = 2.0


def estimate_slope_db_per_decade(fr: FrequencyResponse) -> tuple[float, float]:
    """High-frequency slope of the measured gain, dB/decade, with its standard error.

    Weighted least-squares line of ``gain_db`` against ``log10(w)`` over the
    points within half a decade of the highest frequency (at least the top
    3 points).

    Parameters
    ----------
    fr : FrequencyResponse

    Returns
    -------
    slope_db_per_decade, stderr_db_per_decade : float
        NaN when fewer than 2 distinct frequencies have a usable gain.
    """
    ok = np.isfinite(fr.gain) & (fr.gain > 0)
    w = fr.omega_rad_s[ok]
    if w.size < 2:
        return float("nan"), float("nan")
    o = np.argsort(w, kind="stable")
    w = w[o]
    db = fr.gain_db[ok][o]
    sig = floored_sigma(fr.gain_db_stderr[ok][o] * (math.log(10.0) / 20.0)) * (20.0 / math.log(10.0))
    top = w >= w[-1] / math.sqrt(10.0)
    if np.count_nonzero(top) < 3:
        top = np.zeros(w.size, bool)
        top[-min(3, w.size):] = True
    x = np.log10(w[top])
    if np.ptp(x) <= 0:
        return float("nan"), float("nan")
    y, s = db[top], sig[top]
    A = np.column_stack([np.ones_like(x), x]) / s[:, None]
    b = y / s
    coef, *_ = np.linalg.lstsq(A, b, rcond=None)
    cov = np.linalg.inv(A.T @ A)
    dof = x.size - 2
    if dof > 0:
        r = A @ coef - b
        cov = cov * max(float(r @ r) / dof, 1.0)
    return float(coef[1]), float(math.sqrt(cov[1, 1]))


def select_order(
    fr: FrequencyResponse,
    *,
    mode: Literal["magnitude", "complex"] = "magnitude",
    max_order: int = 4,
    criterion: Literal["BIC", "AIC"] = "BIC",
    zeros: Literal["minimum_phase", "free"] = "minimum_phase",
    candidates: list[tuple[int, int]] | None = None,
) -> OrderSelection:
    """Fit candidate orders and pick one (see the module docstring).

    Parameters
    ----------
    fr : FrequencyResponse
        Measured frequency response.
    mode : {"magnitude", "complex"}, default "magnitude"
        Passed to :func:`~servoscope.sysid.tf_fit.fit_transfer_function`.
    max_order : int, default 4
        Highest denominator degree ``na`` tried (1..4).
    criterion : {"BIC", "AIC"}, default "BIC"
        Information criterion used for the choice.
    zeros : {"minimum_phase", "free"}, default "minimum_phase"
        Zero parameterization of the candidates.
    candidates : list of (nb, na), optional
        Orders to try instead of all ``0 <= nb < na <= max_order``.

    Returns
    -------
    OrderSelection

    Raises
    ------
    ServoscopeError
        Bad options, or no candidate order can be determined by the data
        (the message says what is missing).
    """
    if criterion not in ("BIC", "AIC"):
        raise ServoscopeError(f"select_order: criterion must be 'BIC' or 'AIC', got {criterion!r}")
    if not (1 <= int(max_order) <= 4):
        raise ServoscopeError(f"select_order: max_order must be 1..4, got {max_order!r}")
    if mode not in ("magnitude", "complex"):
        raise ServoscopeError(f"select_order: unknown mode {mode!r} (use 'magnitude' or 'complex')")
    if candidates is None:
        candidates = [(nb, na) for na in range(1, int(max_order) + 1) for nb in range(na)]
    d, _ = prepare_fit_data(fr, mode, "select_order")
    m = d.n + int(np.count_nonzero(d.has_ph))
    warns: list[str] = []
    fits: dict[tuple[int, int], TransferFunctionFit] = {}
    first_problem = None
    hopeless: set[int] = set()  # na values whose fits already had undetermined parameters
    for nb, na in sorted((int(a), int(b)) for a, b in candidates):
        if na in hopeless:
            warns.append(f"order ({nb}, {na}) not tried: ({nb - 1}, {na}) or fewer zeros were already over-parameterized")
            continue
        st = Structure(int(nb), int(na), zeros, mode == "complex", 1.0)
        problem = identifiability_problem(d, st, mode)
        if problem is None and st.n_params >= m:
            problem = f"order ({nb}, {na}) has {st.n_params} parameters for {m} residuals: no degree of freedom left"
        if problem is not None:
            first_problem = first_problem or problem
            warns.append(f"order ({nb}, {na}) not tried: {problem}")
            continue
        fit = fit_fixed_order(fr, (nb, na), mode=mode, zeros=zeros, jackknife=False)
        fits[(nb, na)] = fit
        if fit.undetermined:
            hopeless.add(na)
    if not fits:
        raise ServoscopeError(f"select_order: no candidate order can be fitted: {first_problem}")

    fits, phi, chosen = _choose(fits, criterion)

    slope, slope_se = estimate_slope_db_per_decade(fr)
    rel = None if not math.isfinite(slope) else max(1, int(math.floor(-slope / 20.0 + 0.5)))
    if rel is not None and chosen[1] - chosen[0] < rel:
        warns.append(
            f"the chosen order {chosen} rolls off at {-20 * (chosen[1] - chosen[0])} dB/decade but the data fall at "
            f"{slope:.1f} dB/decade at the highest frequencies"
        )
    rows = _table_rows(fits, chosen)
    return OrderSelection(
        table=tuple(rows),
        best=fits[chosen],
        fits=fits,
        criterion=criterion,
        mode=mode,
        slope_db_per_decade=slope,
        slope_stderr_db_per_decade=slope_se,
        relative_degree_estimate=rel,
        noise_scale=phi,
        warnings=tuple(warns),
    )


def _choose(
    fits: dict[tuple[int, int], TransferFunctionFit], criterion: str
) -> tuple[dict[tuple[int, int], TransferFunctionFit], float, tuple[int, int]]:
    """The candidates with their criteria rescaled by the noise scale, the scale, and the choice.

    See the module docstring, "Choice" and the criteria.
    """
    # Noise scale from the best-fitting determined candidate (see docstring).
    red = [2.0 * f.cost / (f.n_residuals - f.n_params) for f in fits.values() if not f.undetermined]
    phi = max(1.0, min(red)) if red else 1.0
    if phi > 1.0:
        fits = {
            o: replace(
                f,
                aic=2.0 * f.cost / phi + 2.0 * f.n_params,
                bic=2.0 * f.cost / phi + f.n_params * math.log(f.n_residuals),
            )
            for o, f in fits.items()
        }
    key = "bic" if criterion == "BIC" else "aic"
    determined = [o for o, f in fits.items() if not f.undetermined] or list(fits)
    eligible = [o for o in determined if fits[o].J <= J_ACCEPTABLE] or determined
    best_score = min(getattr(fits[o], key) for o in eligible)
    near = [o for o in eligible if getattr(fits[o], key) <= best_score + CRITERION_TIE]
    chosen = min(near, key=lambda o: (fits[o].n_params, getattr(fits[o], key)))
    return fits, phi, chosen


def _table_rows(fits: dict[tuple[int, int], TransferFunctionFit], chosen: tuple[int, int]) -> list[dict[str, Any]]:
    """One row of :attr:`OrderSelection.table` per candidate, by ascending number of parameters."""
    rows = []
    for o in sorted(fits, key=lambda o: (fits[o].n_params, o)):
        f = fits[o]
        rows.append(
            {
                "order": [o[0], o[1]],
                "n_params": f.n_params,
                "J": f.J,
                "AIC": f.aic,
                "BIC": f.bic,
                "residual_rms_db": f.residual_rms_db,
                "residual_rms_deg": f.residual_rms_deg,
                "relative_degree": o[1] - o[0],
                "determined": not f.undetermined,
                "chosen": o == chosen,
            }
        )
    return rows
