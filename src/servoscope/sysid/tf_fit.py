"""Fit a rational transfer function with dead time to a measured frequency response.

The entry points (:func:`fit_transfer_function`, :func:`fit_second_order`). The fit is built
as lmfit's is, in rooms of one purpose: the model (:mod:`._rational`: structure, parameters
and their names), the data and weights (:mod:`._tf_data`), the residuals and the multistart
minimizer (:mod:`._tf_minimize`), the result (:mod:`.tf_result`, built by :mod:`._tf_build`),
resampling (:mod:`._tf_resample`), metrics (:mod:`._tf_metrics`) and one order's fit
(:mod:`._fixed_order`), which the order selection (:mod:`.order`) uses too.

Model (paper eq. 4/5, any ``nb < na <= 4``)::

    G(s) = K * (c_nb s**nb + ... + c1 s + 1) / (a_na s**na + ... + a1 s + 1) * exp(-s*tau)

so ``num = K * [c_nb, ..., c1, 1]`` and ``den = [a_na, ..., a1, 1]``; ``K``
is the static (DC) gain. The second-order model of the paper is order
``(0, 2)``: ``K / (s**2/wn**2 + 2*zeta*s/wn + 1)``.

Parameterization (stable by construction)
-----------------------------------------
The denominator is a product of quadratic factors
``s**2/wn**2 + 2*zeta*s/wn + 1`` (``wn > 0``, ``zeta > 0``; a
complex pair for ``zeta < 1``, two real poles for ``zeta >= 1``) and, for an
odd ``na``, one real factor ``s/p + 1`` (``p > 0``). Every stable
denominator of degree <= 4 has this form and no parameter value makes it
unstable. Zeros:

* ``zeros="minimum_phase"`` (default): the numerator is built from the same
  factors, so every zero lies in the open left half plane. This is the only
  choice in ``mode="magnitude"``, where the sign of a zero cannot be seen
  (``|jw - z| = |jw + z|``).
* ``zeros="free"`` (``mode="complex"`` only): the normalized numerator
  coefficients ``c_i`` are free reals; right-half-plane zeros are allowed.

Frequencies and damping ratios are fitted as logarithms and the dead time
as the square of a free number, so every real parameter vector is a stable
model with ``tau >= 0`` and the unconstrained Levenberg-Marquardt solver
applies. A parameter the data do not determine (relative standard error
above 100 %, a pole or zero more than 100x outside the measured band, a
damping ratio outside [1e-4, 20]) is listed in `undetermined` with a
warning; :func:`~servoscope.sysid.order.select_order` rejects such models.

Residuals and weights
---------------------
``mode="magnitude"``: ``ln|G(jw_i)| - ln(gain_i)``, divided by the standard
error of ``ln(gain_i)`` (the dead time is not identifiable and is not
fitted). ``mode="complex"``: in addition, the phase residual
``wrap(arg G(jw_i) - phase_i)`` in rad divided by the phase standard error,
with ``tau >= 0`` fitted. Standard errors are floored at
``max(0.5 * median, 1e-3)`` (so one very precise point cannot dominate and
model error is not ignored) and replaced by the median where unknown.

Optimization: :func:`scipy.optimize.least_squares` (``lm``, analytic
Jacobian) from the best few of 256 quasi-random starting points
(scrambled Sobol, fixed seed: deterministic), after ``ln K`` and ``tau``
have been set to their least-squares values for each starting point.

Uncertainty
-----------
Covariance from the Jacobian, scaled by ``max(1, chi2/dof)`` (the Birge
ratio; CIFER's Cramér–Rao bounds with a misfit factor; by chi2/dof alone when
the response has no standard errors at all): when the residuals
exceed their stated errors the intervals grow with the misfit (as MATLAB's
``nlinfit``), but they are not shrunk below what the stated (floored)
per-dwell errors give when the model happens to fit better than those
errors; with a dozen dwells ``chi2/dof`` scatters by ±40 %, and the floors
above stand for tracking systematics that the scatter cannot show
(docs/accuracy.md, "Identification: stated uncertainty"). 95 % intervals ``value +- t(0.975, dof) *
stderr`` in physical units (as ``nlparci``). With ``bootstrap=N`` the
dwells are also resampled with replacement N times, the model refitted from
the estimate, and percentile intervals reported (``ci95_bootstrap``).

The Jacobian's errors assume that each dwell's error is what its standard
error says. A dwell with a systematic error (a codec that shrinks the
smallest motions, a resonance the model does not have) moves the estimate
by more than that, and the fit cannot tell. So every fit with at least
``n_params + 2`` dwells is also refitted with each dwell left out in turn,
from the estimate (the delete-one jackknife), and each parameter's stated
standard error is the larger of the two (``stderr_jacobian``,
``stderr_jackknife``; the covariance is scaled to match, its correlations
kept): where one dwell carries a parameter, its interval says so.
``influence`` names, per parameter, the dwell whose removal moves it most
and the value without it.

Goodness of fit
---------------
CIFER's cost ``J = (20/n) * sum W_gamma * (dB_err**2 + 0.01745 * deg_err**2)``
over the ``n`` points, where ``W_gamma = (1.58 * (1 - exp(-gamma**2)))**2``
with the dwell's sinusoidal fidelity as the coherence ``gamma**2`` (both
are the share of output power that is linear in the input). In magnitude
mode the phase term is left out. ``J <= 50``: near-perfect; ``J <= 100``:
acceptable. AIC and BIC treat the measured standard errors as the noise
level (as in frequency-domain maximum likelihood): ``chi2 + 2p`` and
``chi2 + p*ln(m)`` with ``chi2`` the sum of squared weighted residuals,
``m`` residuals and ``p`` parameters (up to a constant common to all
models of the same data). The form with an unknown noise scale,
``m*ln(chi2/m) + ...``, rewards fitting the noise when m is a dozen dwells.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Literal

import numpy as np

from servoscope.errors import ServoscopeError
from servoscope.sysid._fixed_order import check_fit_options, fit_fixed_order
from servoscope.sysid._tf_data import Mode, Zeros, prepare_fit_data
from servoscope.sysid._tf_metrics import CIFER_PHASE_WEIGHT, J_ACCEPTABLE, J_NEAR_PERFECT, bandwidth_rad_s, cifer_cost
from servoscope.sysid._tf_resample import with_jackknife
from servoscope.sysid.frequency_response import FrequencyResponse
from servoscope.sysid.order import select_order
from servoscope.sysid.tf_result import TransferFunctionFit

__all__ = [
    "CIFER_PHASE_WEIGHT",
    "J_ACCEPTABLE",
    "J_NEAR_PERFECT",
    "TransferFunctionFit",
    "bandwidth_rad_s",
    "cifer_cost",
    "fit_second_order",
    "fit_transfer_function",
]


def fit_transfer_function(
    fr: FrequencyResponse,
    *,
    order: tuple[int, int] | Sequence[int] | Literal["auto"] = (0, 2),
    mode: Mode = "magnitude",
    zeros: Zeros = "minimum_phase",
    bootstrap: int = 0,
    seed: int | None = 0,
    max_order: int = 4,
    n_starts: int | None = None,
    jackknife: bool = True,
    fix: dict[str, float] | None = None,
    bounds: dict[str, tuple[float, float]] | None = None,
) -> TransferFunctionFit:
    """Fit ``K * N(s)/D(s) * exp(-s*tau)`` of order ``(nb, na)`` to a frequency response.

    See the module docstring for the model, its parameterization, the
    weights and the uncertainty.

    Parameters
    ----------
    fr : FrequencyResponse
        Measured gains (and phases for ``mode="complex"``), with standard
        errors used as weights when available. Points without a usable gain
        (NaN, <= 0) are left out with a warning.
    order : (int, int) or "auto", default (0, 2)
        Numerator and denominator degrees, ``0 <= nb < na <= 4``. "auto":
        chosen by :func:`~servoscope.sysid.order.select_order` (the result
        carries the comparison as `order_selection`).
    mode : {"magnitude", "complex"}, default "magnitude"
        "magnitude": fit ``|G|`` only (the paper's method); the dead time is
        not identifiable and is None. "complex": fit magnitude and phase of
        ``G(s)*exp(-s*tau)``, ``tau >= 0`` included; points without a phase
        contribute their magnitude only.
    zeros : {"minimum_phase", "free"}, default "minimum_phase"
        Zero parameterization; "free" needs ``mode="complex"``.
    bootstrap : int, default 0
        Number of bootstrap resamples of the dwells (0: none).
    seed : int or None, default 0
        Seed of the bootstrap's random generator (deterministic for an int).
    max_order : int, default 4
        Highest ``na`` tried by ``order="auto"``.
    n_starts : int, optional
        Most local optimizations (from the best quasi-random seeds); default
        ``max(8, 2 * n_params)`` (``max(24, 4 * n_params)`` for free zeros). They stop early once three have ended at
        the same lowest cost.
    jackknife : bool, default True
        Check the standard errors by refitting with each dwell left out (see
        the module docstring); ``select_order`` skips it for the candidates
        and does it for the chosen one.
    fix : dict of str to float, optional
        Parameters held at a value, by name (``{"damping_ratio": 0.8}``), as
        lmfit's ``vary=False``: not estimated, standard error 0, not counted
        in the degrees of freedom, AIC or BIC. Needs a given order.
    bounds : dict of str to (float, float), optional
        Parameters kept within limits (physical units, ``{"natural_frequency_rad_s":
        (20, 80)}``); one that ends at a limit earns a warning. Needs a given order.

    Returns
    -------
    TransferFunctionFit

    Raises
    ------
    ServoscopeError
        An unknown mode/order/zeros option, no phases in complex mode, or
        data that cannot determine the model (fewer usable dwells or
        distinct frequencies than parameters, all dwells at one frequency);
        the message says what is missing.
    """
    who = "fit_transfer_function"
    check_fit_options(who, mode, zeros, bootstrap)
    if isinstance(order, str):
        if order != "auto":
            raise ServoscopeError(f"{who}: order must be (nb, na) or 'auto', got {order!r}")
        if fix or bounds:
            raise ServoscopeError(f"{who}: fixed or bounded parameters need a given order (their names depend "
                                  "on it), not order='auto'")
        sel = select_order(fr, mode=mode, max_order=max_order, zeros=zeros)
        best = sel.best
        if bootstrap:
            best = fit_fixed_order(fr, best.order, mode=mode, zeros=zeros, bootstrap=bootstrap, seed=seed,
                                   n_starts=n_starts, jackknife=jackknife, who=who)
        elif jackknife:
            with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
                best = with_jackknife(best, prepare_fit_data(fr, mode, who)[0])
        return replace(best, order_selection=sel)
    return fit_fixed_order(fr, order, mode=mode, zeros=zeros, bootstrap=bootstrap, seed=seed, n_starts=n_starts,
                           jackknife=jackknife, who=who, fix=fix, bounds=bounds)


def fit_second_order(
    fr: FrequencyResponse,
    *,
    mode: Mode = "magnitude",
    bootstrap: int = 0,
    seed: int | None = 0,
) -> TransferFunctionFit:
    """Fit ``K / (s**2/wn**2 + 2*zeta*s/wn + 1) [* exp(-s*tau)]`` (paper eq. 5).

    Shorthand for ``fit_transfer_function(fr, order=(0, 2), mode=mode, ...)``.

    Parameters
    ----------
    fr : FrequencyResponse
        Measured gains (and phases for ``mode="complex"``).
    mode : {"magnitude", "complex"}, default "magnitude"
        "magnitude": the paper's method, dead time None; "complex": magnitude
        and phase with the dead time.
    bootstrap : int, default 0
        Bootstrap resamples of the dwells (0: none).
    seed : int or None, default 0
        Bootstrap seed.

    Returns
    -------
    TransferFunctionFit
        With `natural_frequency_rad_s`, `damping_ratio` and their standard
        errors filled in.

    Raises
    ------
    ServoscopeError
        See :func:`fit_transfer_function`.
    """
    return fit_transfer_function(fr, order=(0, 2), mode=mode, bootstrap=bootstrap, seed=seed)
