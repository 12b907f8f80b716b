"""The minimizer of the transfer-function fit: weighted residuals, their Jacobian, multistart.

Part of the transfer-function fit (:mod:`servoscope.sysid.tf_fit` describes the model and the
weights). :func:`residuals` and :func:`residual_jacobian` are the weighted misfit of a parameter
vector (``ln|G|`` over the ln-gain errors, and in complex mode the wrapped phase over the phase
errors); :func:`multistart` runs :func:`local_fit` (Levenberg-Marquardt) from the best of 256
quasi-random starting points, each with ``ln K`` and the dead time set to their least-squares
values first.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.stats import qmc

from servoscope.sysid._rational import Structure, delay_limit_s, log_response, log_response_jac
from servoscope.sysid._tf_data import FitData, wrap_rad

__all__ = ["N_STARTS", "local_fit", "multistart", "residual_jacobian", "residuals"]

_N_SEEDS = 256
#: Fewest local optimizations per fit (more for many parameters or free zeros).
N_STARTS = 8


def _limits(st: Structure, d: FitData) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    return st.clamp_limits(float(d.w.min()), float(d.w.max()))


def residuals(
    st: Structure, d: FitData, theta: NDArray[np.float64], use_phase: bool,
    limits: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> NDArray[np.float64]:
    """Weighted residuals of parameter vector `theta` (clipped to the band's limits)."""
    lo, hi = limits if limits is not None else _limits(st, d)
    lg = log_response(st, np.clip(theta, lo, hi), d.w)
    rm = (lg.real - d.lng) / d.sig_ln
    if not use_phase:
        return rm
    hp = d.has_ph
    rp = wrap_rad(lg.imag[hp] - d.ph[hp]) / d.sig_ph[hp]
    return np.concatenate([rm, rp])


def residual_jacobian(
    st: Structure, d: FitData, theta: NDArray[np.float64], use_phase: bool,
    limits: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> NDArray[np.float64]:
    """Jacobian of :func:`residuals` (zero columns where `theta` is clipped)."""
    lo, hi = limits if limits is not None else _limits(st, d)
    clipped = np.clip(theta, lo, hi)
    J = log_response_jac(st, clipped, d.w)
    J[:, (clipped != theta) | (lo == hi)] = 0.0  # clipped, or held fixed by the user
    jm = J.real / d.sig_ln[:, None]
    if not use_phase:
        return jm
    hp = d.has_ph
    return np.vstack([jm, J[hp].imag / d.sig_ph[hp][:, None]])


def _seeds(st: Structure, w_min: float, w_max: float) -> NDArray[np.float64]:
    """Quasi-random starting points (ln K and tau left at 0)."""
    kinds = st.kinds()
    free = [i for i, k in enumerate(kinds) if i > 0 and k != "tau"]
    P = st.n_params
    if not free:
        return np.zeros((1, P))
    u = qmc.Sobol(len(free), scramble=True, seed=20240611).random(_N_SEEDS)
    out = np.zeros((_N_SEEDS, P))
    lo, hi = math.log(w_min / 4.0), math.log(w_max * 4.0)
    for col, i in enumerate(free):
        if kinds[i] == "ln":
            out[:, i] = lo + (hi - lo) * u[:, col]
        elif kinds[i] == "zeta":
            out[:, i] = math.log(0.05) + (math.log(3.0) - math.log(0.05)) * u[:, col]
        else:  # free numerator coefficient (scaled)
            out[:, i] = -3.0 + 6.0 * u[:, col]
    # Free coefficients: also start from "no zeros" (c = 0).
    if st.n_zero_coef:
        o = st.offsets()["zc"]
        out[::4, o : o + st.n_zero_coef] = 0.0
    return out


def _delay_seed(residual_rad: NDArray[np.float64], w: NDArray[np.float64], weight: NDArray[np.float64]) -> NDArray[np.float64]:
    """Dead time that best explains each row's phase residual (measured − rational part) as −w·tau.

    The residual is known modulo 2π only. Unwrapping it across the dwells
    assumes the delay turns the phase by less than π between neighbouring
    frequencies, which sparse sweeps break (85 ms between 5.2 and 12 Hz:
    3.6 rad), and then every start carries the same wrong delay. So the
    delay is found on a grid by a cost that is blind to whole turns,
    Σ weight·(1 − cos(residual + w·tau)), fine enough that the top dwell's
    phase moves by 0.25 rad per step, over 0 … max(1 s, one period of the
    lowest dwell), then refined by weighted least squares on the wrapped
    residuals around the best grid point.
    """
    tau_max = delay_limit_s(float(w.min()))
    grid = np.arange(0.0, tau_max, 0.25 / float(w.max()))
    total = np.zeros((residual_rad.shape[0], grid.size))
    for k in range(w.size):  # one dwell at a time: (seeds × grid) memory only
        total += weight[k] * (1.0 - np.cos(residual_rad[:, k:k + 1] + w[k] * grid[None, :]))
    tau0 = grid[np.argmin(total, axis=1)]
    wrapped = wrap_rad(residual_rad + w[None, :] * tau0[:, None])
    tau = tau0 - (wrapped * weight * w).sum(axis=1) / np.sum(weight * w**2)
    return np.clip(tau, 0.0, None)


def _fill_gain_and_delay(st: Structure, d: FitData, seeds: NDArray[np.float64], use_phase: bool,
                         delay_seed: str = "unwrap") -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Set ln K (and tau) of each seed to their least-squares values; return seeds and costs.

    ``delay_seed``: "unwrap" (the phases unwrapped across the dwells: right
    when they are dense) or "grid" (:func:`_delay_seed`: right when sparse).
    """
    lg = log_response(st, seeds, d.w, with_delay=False)  # (S, n)
    wts = 1.0 / d.sig_ln**2
    seeds = seeds.copy()
    seeds[:, 0] = ((d.lng[None, :] - lg.real) * wts).sum(axis=1) / wts.sum()
    rm = (lg.real + seeds[:, :1] - d.lng[None, :]) / d.sig_ln
    cost = np.sum(rm**2, axis=1)
    if use_phase:
        hp = d.has_ph
        wk, phk, sk = d.w[hp], d.ph[hp], d.sig_ph[hp]
        model = lg.imag[:, hp]
        if st.delay:
            residual = phk[None, :] - model
            v = 1.0 / sk**2
            if delay_seed == "grid":
                tau = _delay_seed(residual, wk, v)
            else:
                # The phase left over by the rational part is -w*tau (mod 2 pi), unwrapped across the dwells.
                dd = np.unwrap(residual, axis=1)
                dd -= 2.0 * np.pi * np.round(dd[:, :1] / (2.0 * np.pi))
                tau = np.clip(-(dd * v * wk).sum(axis=1) / np.sum(v * wk**2), 0.0, None)
            seeds[:, st.offsets()["tau"]] = np.sqrt(tau)
            model = model - wk[None, :] * tau[:, None]
        rp = wrap_rad(model - phk[None, :]) / sk
        cost = cost + np.sum(rp**2, axis=1)
    return seeds, cost


def local_fit(st: Structure, d: FitData, theta0: NDArray[np.float64], use_phase: bool, max_nfev_per_param: int = 100) -> Any:
    """One Levenberg-Marquardt run from `theta0` (scipy's ``OptimizeResult``)."""
    limits = _limits(st, d)
    x0 = np.clip(np.array(theta0, dtype=float), *limits)
    if st.delay and x0[-1] == 0.0:
        # tau = u**2 has a zero derivative at u = 0: start just off it.
        x0[-1] = 1e-3
    return least_squares(
        lambda th: residuals(st, d, th, use_phase, limits),
        x0,
        jac=lambda th: residual_jacobian(st, d, th, use_phase, limits),
        method="lm",
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
        max_nfev=max_nfev_per_param * st.n_params,
    )


def multistart(st: Structure, d: FitData, use_phase: bool, n_starts: int) -> Any:
    """The best local fit from the best `n_starts` seeds (None when every run failed)."""
    if not (use_phase and st.delay):
        return _multistart_from(st, d, use_phase, n_starts, "unwrap")
    # Both ways of starting the delay, each with its own starts, and the magnitudes' own fit with the
    # delay its phases leave; the lower cost wins.
    runs = [_multistart_from(st, d, use_phase, n_starts, how) for how in ("unwrap", "grid")]
    runs.append(_from_magnitudes(st, d, n_starts))
    runs = [r for r in runs if r is not None]
    return min(runs, key=lambda r: r.cost) if runs else None


def _aliased(st: Structure, d: FitData, x: NDArray[np.float64]) -> bool:
    """Whether a fit's dead time lies beyond :func:`~servoscope.sysid._rational.delay_limit_s` (a phase alias)."""
    return bool(st.delay and float(x[st.offsets()["tau"]]) ** 2 > delay_limit_s(float(d.w.min())))


def _from_magnitudes(st: Structure, d: FitData, n_starts: int) -> Any:
    """The complex fit started from the magnitude-only fit, its delay from the phases that fit leaves.

    A few precise phases make the delay's basin narrow (a millisecond wide where the top
    dwell's phase is known to 0.2°) and each quasi-random seed's rational part wrong by
    tens of degrees, so every seed's delay can miss it and the solver end in another
    (found: 685 ms for 85 ms, cost 20050 against 3.2, on three dwells). The magnitudes
    alone fix the rational part well where the dwells span the corner; what its phase
    leaves is then −ω·τ, told by :func:`_delay_seed`.
    """
    hp = d.has_ph
    rational = replace(st, delay=False, held=tuple(h for h in st.held if h[0] < st.n_params - 1))
    # Magnitudes alone cannot tell a free zero's side, nor fit more parameters than points.
    if st.zeros == "free" or not hp.any() or d.w.size < rational.n_params:
        return None
    mag = _multistart_from(rational, d, False, n_starts, "unwrap")
    if mag is None or not np.all(np.isfinite(mag.x)):
        return None
    seed = np.append(np.asarray(mag.x, dtype=float), 0.0)  # τ, the last entry, set below
    lg = log_response(rational, mag.x[None, :], d.w)[0]
    residual = (d.ph[hp] - lg.imag[hp])[None, :]
    tau = _delay_seed(residual, d.w[hp], 1.0 / d.sig_ph[hp] ** 2)[0]
    seed[st.offsets()["tau"]] = math.sqrt(tau)
    sol = local_fit(st, d, seed, True)
    return sol if np.all(np.isfinite(sol.x)) and math.isfinite(sol.cost) and not _aliased(st, d, sol.x) else None


def _multistart_from(st: Structure, d: FitData, use_phase: bool, n_starts: int, delay_seed: str) -> Any:
    seeds = _seeds(st, float(d.w.min()), float(d.w.max()))
    seeds, cost = _fill_gain_and_delay(st, d, seeds, use_phase, delay_seed)
    order = np.argsort(cost, kind="stable")
    best = None
    agree = 0
    # Short runs from each start (an over-parameterized model crawls along a
    # flat valley for as long as it is allowed), then one long polish. Once
    # three runs have ended at the same lowest cost, more starts are
    # unlikely to find a lower one.
    for i in order[: max(1, n_starts)]:
        sol = local_fit(st, d, seeds[i], use_phase, max_nfev_per_param=20)
        if not np.all(np.isfinite(sol.x)) or not math.isfinite(sol.cost) or _aliased(st, d, sol.x):
            continue
        tol = 1e-7 * max(sol.cost, 1e-12) if best is None else 1e-7 * max(best.cost, 1e-12)
        if best is None or sol.cost < best.cost - tol:
            best = sol
            agree = 1
        elif abs(sol.cost - best.cost) <= tol:
            agree += 1
            if agree >= 3:
                break
    if best is not None and best.status == 0:
        polished = local_fit(st, d, best.x, use_phase)
        if np.all(np.isfinite(polished.x)) and polished.cost <= best.cost and not _aliased(st, d, polished.x):
            best = polished
    return best
