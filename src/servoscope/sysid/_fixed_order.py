"""Fit a transfer function of one given order: the core below both the fit and the order selection.

:func:`fit_fixed_order` prepares the data (:mod:`._tf_data`), runs the multistart minimizer
(:mod:`._tf_minimize`), builds the result (:mod:`._tf_build`) and checks its errors by
resampling (:mod:`._tf_resample`). :func:`~servoscope.sysid.fit_transfer_function` calls it
for a given order, :func:`~servoscope.sysid.select_order` for each candidate, and
``order="auto"`` goes through the selection: every import points down.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from servoscope.errors import ServoscopeError
from servoscope.parameters import check_held as check_parameters_held
from servoscope.results import readonly
from servoscope.sysid._rational import Structure
from servoscope.sysid._tf_build import build_fit
from servoscope.sysid._tf_data import identifiability_problem, prepare_fit_data
from servoscope.sysid._tf_minimize import N_STARTS, multistart
from servoscope.sysid._tf_resample import bootstrap_dwells, with_jackknife
from servoscope.sysid.frequency_response import FrequencyResponse
from servoscope.sysid.tf_result import TransferFunctionFit

__all__ = ["check_fit_options", "check_held", "check_order", "fit_fixed_order"]


def check_fit_options(who: str, mode: str, zeros: str, bootstrap: int) -> None:
    """Raise :class:`~servoscope.errors.ServoscopeError` for an unknown mode or zeros, or a bad bootstrap count."""
    if mode not in ("magnitude", "complex"):
        raise ServoscopeError(f"{who}: unknown mode {mode!r} (use 'magnitude' or 'complex')")
    if zeros not in ("minimum_phase", "free"):
        raise ServoscopeError(f"{who}: unknown zeros {zeros!r} (use 'minimum_phase' or 'free')")
    if zeros == "free" and mode != "complex":
        raise ServoscopeError(
            f"{who}: zeros='free' needs mode='complex' (a magnitude fit cannot tell a zero's sign)"
        )
    if int(bootstrap) < 0:
        raise ServoscopeError(f"{who}: bootstrap must be >= 0, got {bootstrap!r}")


def check_held(order: Any, zeros: str, fix: dict[str, float], bounds: dict[str, tuple[float, float]]) -> None:
    """Raise :class:`~servoscope.errors.ServoscopeError` for held parameters a model of ``order`` cannot take.

    Checked before any tracking, against the complex fit's names (a ``dead_time_s`` held in a
    magnitude fit is refused by the fit itself).
    """
    if not (fix or bounds):
        return
    if isinstance(order, str):
        raise ServoscopeError("fixed or bounded parameters need a given order (their names depend on it), "
                              "not order='auto'")
    nb, na = check_order(order)
    _held(Structure(nb, na, zeros, True, 1.0), fix, bounds, f"model of order ({nb}, {na})")


def _held(st: Structure, fix: dict[str, float] | None, bounds: dict[str, tuple[float, float]] | None,
          who: str) -> Structure:
    """``st`` with ``fix`` and ``bounds`` held (:meth:`Structure.with_held`); a ServoscopeError naming `who` else.

    The names, limits and a fix against its bounds are checked by
    :func:`servoscope.parameters.check_held` (every model's one check); a value the parameter's
    kind cannot take (a frequency ≤ 0) by the structure. A bound on a fixed parameter that
    holds its value says nothing more, and is dropped.
    """
    fix = {k: float(v) for k, v in (fix or {}).items()}
    bounds = {k: (float(v[0]), float(v[1])) for k, v in (bounds or {}).items()}
    check_parameters_held(st.names(), fix, bounds, who=f"the model of order ({st.nb}, {st.na})")
    try:
        return st.with_held(fix, {k: v for k, v in bounds.items() if k not in fix})
    except (ValueError, TypeError, IndexError) as exc:
        raise ServoscopeError(f"{who}: {exc}") from None


def check_order(order: Any) -> tuple[int, int]:
    """``(nb, na)`` as ints, checked (``0 <= nb < na <= 4``)."""
    try:
        nb, na = (int(v) for v in order)
    except (TypeError, ValueError):
        raise ServoscopeError(f"order must be (nb, na) or 'auto', got {order!r}") from None
    if not (0 <= nb < na <= 4):
        raise ServoscopeError(f"order (nb, na) = ({nb}, {na}) is not supported: need 0 <= nb < na <= 4")
    return nb, na


def fit_fixed_order(
    fr: FrequencyResponse,
    order: tuple[int, int] | Sequence[int],
    *,
    mode: str = "magnitude",
    zeros: str = "minimum_phase",
    bootstrap: int = 0,
    seed: int | None = 0,
    n_starts: int | None = None,
    jackknife: bool = True,
    who: str = "fit_transfer_function",
    fix: dict[str, float] | None = None,
    bounds: dict[str, tuple[float, float]] | None = None,
) -> TransferFunctionFit:
    """Fit a model of the given order ``(nb, na)``; the options as :func:`~servoscope.sysid.fit_transfer_function`'s.

    Raises
    ------
    ServoscopeError
        Bad options, or data that cannot determine the model (the message starts with `who`).
    """
    check_fit_options(who, mode, zeros, bootstrap)
    nb, na = check_order(order)
    # Wild starting points and undetermined parameters can overflow on the
    # way; every result is checked for finiteness below, so numpy's warnings
    # would only be noise (and errors under pytest's filter).
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        return _fit_fixed_order(fr, nb, na, mode, zeros, bootstrap, seed, n_starts, who, jackknife,
                                dict(fix or {}), dict(bounds or {}))


def _fit_fixed_order(
    fr: FrequencyResponse, nb: int, na: int, mode: str, zeros: str, bootstrap: int,
    seed: int | None, n_starts: int | None, who: str, jackknife: bool = True,
    fix: dict[str, float] | None = None, bounds: dict[str, tuple[float, float]] | None = None,
) -> TransferFunctionFit:
    d, warns = prepare_fit_data(fr, mode, who)
    w_ref = float(math.exp(np.mean(np.log(d.w)))) if d.n else 1.0
    st = Structure(nb, na, zeros, mode == "complex", w_ref)
    if fix or bounds:
        st = _held(st, fix, bounds, who)
    problem = identifiability_problem(d, st, mode)
    if problem is not None:
        raise ServoscopeError(f"{who}: {problem}")
    if n_starts is None:
        # Free zeros add local minima (an RHP zero's phase lag mimics a
        # delay), so they get more starts.
        n_starts = max(3 * N_STARTS, 4 * st.n_params) if zeros == "free" else max(N_STARTS, 2 * st.n_params)
    sol = multistart(st, d, mode == "complex", n_starts)
    if sol is None:
        raise ServoscopeError(f"{who}: the optimizer failed from every starting point (non-finite data?)")
    fit = build_fit(st, d, fr, sol, mode, warns)
    if fix or bounds:
        held = {**{k: {"fixed": float(v)} for k, v in (fix or {}).items()},
                **{k: {"bounds": [float(v[0]), float(v[1])]} for k, v in (bounds or {}).items()}}
        at_bound = [k for k, (lo, hi) in (bounds or {}).items()
                    if math.isclose(fit.params[k], lo, rel_tol=1e-6) or math.isclose(fit.params[k], hi, rel_tol=1e-6)]
        more = tuple(f"{k} ended at its bound ({fit.params[k]:.6g}): the data would take it further; its "
                     "standard error and interval do not say how far" for k in at_bound)
        fit = replace(fit, held=held, warnings=fit.warnings + more)
    if jackknife:
        fit = with_jackknife(fit, d)
    if bootstrap:
        samples, ci_b, bw = bootstrap_dwells(fit, d, int(bootstrap), seed)
        fit = replace(
            fit,
            bootstrap_samples=readonly(samples),
            ci95_bootstrap=ci_b,
            warnings=fit.warnings + tuple(bw),
        )
    return fit
