"""Fit a rational transfer function with dead time to a measured frequency response.

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

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal

import control
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import brentq, least_squares
from scipy.stats import qmc
from scipy.stats import t as student_t

from servoscope.errors import ServoscopeError
from servoscope.sysid._rational import (
    FREQ_MARGIN,
    ZETA_RANGE,
    Structure,
    continuous_phase_rad,
    log_response,
    log_response_jac,
)
from servoscope.sysid.frequency_response import FrequencyResponse
from servoscope.results import import_pandas, jsonable, readonly

if TYPE_CHECKING:  # pragma: no cover
    from servoscope.sysid.order import OrderSelection

__all__ = [
    "TransferFunctionFit",
    "bandwidth_rad_s",
    "cifer_cost",
    "fit_second_order",
    "fit_transfer_function",
]

_DB_PER_NEPER = 20.0 / math.log(10.0)
_SIGMA_FLOOR = 1e-3
#: CIFER's phase weight W_p (per deg**2, with W_g = 1 per dB**2).
CIFER_PHASE_WEIGHT = 0.01745
#: CIFER's thresholds on J.
J_NEAR_PERFECT = 50.0
J_ACCEPTABLE = 100.0
_N_SEEDS = 256
_N_STARTS = 8
_LOW_FIDELITY = 0.95
# Without fit_sine's significance test (a hand-made FrequencyResponse), a
# plain threshold well above the noise floor of the THD estimate.
_HIGH_THD = 0.05

Mode = Literal["magnitude", "complex"]
Zeros = Literal["minimum_phase", "free"]


# ---------------------------------------------------------------- bandwidth
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


# --------------------------------------------------------------- data prep
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


@dataclass(frozen=True)
class _Data:
    """Usable points, sorted by frequency, in fitting units."""

    w: NDArray[np.float64]  # rad/s
    lng: NDArray[np.float64]  # ln gain
    sig_ln: NDArray[np.float64]
    ph: NDArray[np.float64]  # rad, NaN where unknown
    has_ph: NDArray[np.bool_]
    sig_ph: NDArray[np.float64]  # rad, NaN where unknown
    fid: NDArray[np.float64]
    labels: tuple[str, ...]
    #: Whether the response came with standard errors (else the weights are
    #: arbitrary and only the scatter can give the scale).
    stated: bool = True

    @property
    def n(self) -> int:
        return int(self.w.size)

    def take(self, idx: NDArray[np.intp]) -> _Data:
        return _Data(
            self.w[idx], self.lng[idx], self.sig_ln[idx], self.ph[idx], self.has_ph[idx],
            self.sig_ph[idx], self.fid[idx], tuple(self.labels[i] for i in idx), self.stated,
        )


def _prepare(fr: FrequencyResponse, mode: str, who: str) -> tuple[_Data, list[str]]:
    warns: list[str] = []
    w_all = fr.omega_rad_s
    g_all = fr.gain
    use = np.isfinite(w_all) & np.isfinite(g_all) & (g_all > 0) & (w_all > 0)
    dropped = [fr.labels[i] for i in np.nonzero(~use)[0]]
    if dropped:
        warns.append(
            f"{len(dropped)} dwell(s) without a usable gain left out: {', '.join(dropped)}"
        )
    idx = np.nonzero(use)[0]
    idx = idx[np.argsort(w_all[idx], kind="stable")]
    w = w_all[idx]
    lng = np.log(g_all[idx])
    sig_ln = _sigma(fr.gain_stderr[idx] / fr.gain[idx]) if idx.size else np.zeros(0)
    ph = fr.phase_rad[idx]
    has_ph = np.isfinite(ph) & (mode == "complex")
    if mode == "complex" and idx.size and not np.any(has_ph):
        raise ServoscopeError(f"{who}: mode='complex' needs phases (t0 unknown for all dwells); use mode='magnitude'")
    sig_ph = np.full(idx.size, np.nan)
    if np.any(has_ph):
        sig_ph[has_ph] = _sigma(np.radians(fr.phase_stderr_deg[idx][has_ph]))
    if mode == "complex":
        missing = [fr.labels[i] for i, h in zip(idx, has_ph) if not h]
        if missing:
            warns.append(f"no phase for {', '.join(missing)}: magnitude only there")
    fid = fr.fidelity[idx]
    labels = tuple(fr.labels[i] for i in idx)
    low = [lab for lab, f in zip(labels, fid) if math.isfinite(f) and f < _LOW_FIDELITY]
    if low:
        warns.append(
            f"low sinusoidal fidelity (< {_LOW_FIDELITY:g}) at {', '.join(low)}: the response there is "
            "not a clean sine (nonlinearity or noise); a linear model describes it only approximately"
        )
    thd_u = np.asarray(fr.thd, dtype=float)[idx]
    flagged = [("distorted" in fr.flags[i]) for i in idx]
    if any(fr.flags[i] for i in idx):
        # fit_sine tested the harmonics' significance: trust its flag.
        high = [f"{lab} ({100 * v:.1f} %)" for lab, v, fl in zip(labels, thd_u, flagged) if fl]
    else:
        high = [f"{lab} ({100 * v:.1f} %)" for lab, v in zip(labels, thd_u) if math.isfinite(v) and v > _HIGH_THD]
    if high:
        warns.append(
            f"harmonic distortion at {', '.join(high)}: nonlinear response "
            "(rate limit, backlash, saturation?); the fit describes the fundamental only"
        )
    se_g = fr.gain_stderr[idx]
    se_p = fr.phase_stderr_deg[idx]
    stated = bool(np.any(np.isfinite(se_g) & (se_g > 0)) or np.any(np.isfinite(se_p) & (se_p > 0)))
    return _Data(w, lng, sig_ln, ph, has_ph, sig_ph, fid, labels, stated), warns


def _distinct(w: NDArray[np.float64]) -> int:
    return int(np.unique(np.round(np.log(w), 9)).size) if w.size else 0


def _identifiability_problem(d: _Data, st: Structure, mode: str) -> str | None:
    """None when the data can determine the model, else what is missing."""
    p = st.n_params
    nd = _distinct(d.w)
    nd_ph = _distinct(d.w[d.has_ph]) if mode == "complex" else 0
    order = f"order ({st.nb}, {st.na}) in mode {mode!r} has {p} parameters"
    if d.n == 0:
        return f"{order} but no dwell has a usable gain"
    if nd < 2:
        return (
            f"{order} but all {d.n} usable dwell(s) are at one frequency "
            f"({d.w[0] / (2 * math.pi):.4g} Hz): measure at more frequencies"
        )
    if mode == "magnitude":
        if d.n < p:
            return f"{order} but only {d.n} dwell(s) are usable: measure at least {p} frequencies"
        if nd < p:
            return f"{order} but the dwells cover only {nd} distinct frequencies: measure at least {p}"
    else:
        if nd + nd_ph < p:
            return (
                f"{order} but the dwells give only {nd} magnitude(s) and {nd_ph} phase(s) at distinct "
                f"frequencies: measure at more frequencies"
            )
    return None


# ------------------------------------------------------------ the fitting
def _limits(st: Structure, d: _Data) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    return st.clamp_limits(float(d.w.min()), float(d.w.max()))


def _resid(
    st: Structure, d: _Data, theta: NDArray[np.float64], use_phase: bool,
    limits: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> NDArray[np.float64]:
    lo, hi = limits if limits is not None else _limits(st, d)
    lg = log_response(st, np.clip(theta, lo, hi), d.w)
    rm = (lg.real - d.lng) / d.sig_ln
    if not use_phase:
        return rm
    hp = d.has_ph
    rp = _wrap(lg.imag[hp] - d.ph[hp]) / d.sig_ph[hp]
    return np.concatenate([rm, rp])


def _jac(
    st: Structure, d: _Data, theta: NDArray[np.float64], use_phase: bool,
    limits: tuple[NDArray[np.float64], NDArray[np.float64]] | None = None,
) -> NDArray[np.float64]:
    lo, hi = limits if limits is not None else _limits(st, d)
    clipped = np.clip(theta, lo, hi)
    J = log_response_jac(st, clipped, d.w)
    J[:, clipped != theta] = 0.0
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
    tau_max = max(1.0, 2.0 * np.pi / float(w.min()))
    grid = np.arange(0.0, tau_max, 0.25 / float(w.max()))
    total = np.zeros((residual_rad.shape[0], grid.size))
    for k in range(w.size):  # one dwell at a time: (seeds × grid) memory only
        total += weight[k] * (1.0 - np.cos(residual_rad[:, k:k + 1] + w[k] * grid[None, :]))
    tau0 = grid[np.argmin(total, axis=1)]
    wrapped = _wrap(residual_rad + w[None, :] * tau0[:, None])
    tau = tau0 - (wrapped * weight * w).sum(axis=1) / np.sum(weight * w**2)
    return np.clip(tau, 0.0, None)


def _fill_gain_and_delay(st: Structure, d: _Data, seeds: NDArray[np.float64], use_phase: bool,
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
        rp = _wrap(model - phk[None, :]) / sk
        cost = cost + np.sum(rp**2, axis=1)
    return seeds, cost


def _local(st: Structure, d: _Data, theta0: NDArray[np.float64], use_phase: bool, max_nfev_per_param: int = 100) -> Any:
    limits = _limits(st, d)
    x0 = np.clip(np.array(theta0, dtype=float), *limits)
    if st.delay and x0[-1] == 0.0:
        # tau = u**2 has a zero derivative at u = 0: start just off it.
        x0[-1] = 1e-3
    return least_squares(
        lambda th: _resid(st, d, th, use_phase, limits),
        x0,
        jac=lambda th: _jac(st, d, th, use_phase, limits),
        method="lm",
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
        max_nfev=max_nfev_per_param * st.n_params,
    )


def _multistart(st: Structure, d: _Data, use_phase: bool, n_starts: int) -> Any:
    if not (use_phase and st.delay):
        return _multistart_from(st, d, use_phase, n_starts, "unwrap")
    # Both ways of starting the delay, each with its own starts; the lower cost wins.
    runs = [_multistart_from(st, d, use_phase, n_starts, how) for how in ("unwrap", "grid")]
    runs = [r for r in runs if r is not None]
    return min(runs, key=lambda r: r.cost) if runs else None


def _multistart_from(st: Structure, d: _Data, use_phase: bool, n_starts: int, delay_seed: str) -> Any:
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
        sol = _local(st, d, seeds[i], use_phase, max_nfev_per_param=20)
        if not np.all(np.isfinite(sol.x)) or not math.isfinite(sol.cost):
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
        polished = _local(st, d, best.x, use_phase)
        if np.all(np.isfinite(polished.x)) and polished.cost <= best.cost:
            best = polished
    return best


def cifer_cost(
    measured_db_error: ArrayLike,
    phase_error_deg: ArrayLike | None = None,
    coherence: ArrayLike | None = None,
) -> float:
    """CIFER's frequency-response cost function J.

    ``J = (20/n) * sum W_gamma * (W_g * dB_err**2 + W_p * deg_err**2)`` with
    ``W_g = 1``, ``W_p = 0.01745`` and ``W_gamma = (1.58*(1 - exp(-gamma**2)))**2``.

    Parameters
    ----------
    measured_db_error : array_like, shape (n,)
        Magnitude errors (model - measured) in dB.
    phase_error_deg : array_like, shape (n,), optional
        Phase errors in degrees (NaN: no phase there); None for a
        magnitude-only J.
    coherence : array_like, shape (n,), optional
        Coherence ``gamma**2`` per point (0..1; NaN or None: 1).

    Returns
    -------
    float
        J (dimensionless); <= 50 near-perfect, <= 100 acceptable.
    """
    db = np.asarray(measured_db_error, dtype=float)
    n = db.size
    if n == 0:
        return float("nan")
    g2 = np.ones(n) if coherence is None else np.asarray(coherence, dtype=float).copy()
    g2 = np.where(np.isfinite(g2), np.clip(g2, 0.0, 1.0), 1.0)
    wg = (1.58 * (1.0 - np.exp(-g2))) ** 2
    term = db**2
    if phase_error_deg is not None:
        ph = np.asarray(phase_error_deg, dtype=float)
        term = term + CIFER_PHASE_WEIGHT * np.where(np.isfinite(ph), ph, 0.0) ** 2
    return float(20.0 / n * np.sum(wg * term))


def _j_rating(j: float) -> str:
    if not math.isfinite(j):
        return "unknown"
    if j <= J_NEAR_PERFECT:
        return "near-perfect"
    if j <= J_ACCEPTABLE:
        return "acceptable"
    return "poor"


# ----------------------------------------------------------- the result
def _words(name: str) -> str:
    return name.replace("_rad_s", "").replace("_s", "").replace("_", " ")


@dataclass(frozen=True)
class TransferFunctionFit:
    """Transfer function ``K * N(s)/D(s) * exp(-s*tau)`` fitted to a frequency response.

    Attributes
    ----------
    gain : float
        Static gain ``K = G(0)`` (output units per input unit, e.g. rad per unit).
    natural_frequency_rad_s, damping_ratio : float or None
        ``wn`` (rad/s) and ``zeta`` of a second-order denominator (``na ==
        2``); None for other orders (see `params`).
    gain_stderr : float
        Standard error of `gain` (NaN when not estimable).
    natural_frequency_stderr_rad_s, damping_ratio_stderr : float or None
        Their standard errors (None for other orders).
    dead_time_s : float or None
        Dead time ``tau`` in s (mode="complex"; None for a magnitude fit,
        which cannot identify it).
    dead_time_stderr_s : float or None
        Standard error of `dead_time_s` in s.
    covariance : numpy.ndarray
        Covariance of the physical parameters, in the order of `param_names`.
    residual_rms_db : float
        RMS of ``20*log10(model/measured)`` over the points, dB.
    residual_rms_deg : float or None
        RMS phase residual in degrees (mode="complex").
    n_points : int
        Number of frequency points (dwells) used.
    mode : str
        "magnitude" or "complex".
    cost : float
        Final least-squares cost ``0.5*sum(r**2)`` of the weighted residuals.
    warnings : tuple of str
        Non-fatal problems (parameter at a bound, distorted dwells, ...).
    data : FrequencyResponse or None
        The fitted measurements.
    order : tuple of int
        ``(nb, na)``: numerator and denominator degrees.
    zeros : str
        "minimum_phase" or "free" (how the zeros were parameterized).
    param_names : tuple of str
        Physical parameter names: "gain"; "pole_rad_s" (real pole at
        ``-p``); "natural_frequency_rad_s", "damping_ratio" (one quadratic
        factor) or "natural_frequency1_rad_s", "damping_ratio1", ...
        (two, ascending frequency); "zero_rad_s", "zero_natural_frequency_rad_s",
        "zero_damping_ratio" (minimum-phase zeros) or "num_c1", ... (free
        numerator coefficients of ``s**i``, units s**i); "dead_time_s".
    params, stderr : dict of str to float
        Values and standard errors (Jacobian), physical units.
    ci95 : dict of str to (float, float)
        95 % intervals ``value +- t(0.975, dof)*stderr`` (as nlparci).
    ci95_bootstrap : dict of str to (float, float) or None
        Percentile intervals from resampling the dwells (when asked).
    bootstrap_samples : numpy.ndarray or None
        The bootstrap estimates, shape (N, n_params), columns as `param_names`.
    J : float
        CIFER cost (magnitude term only in magnitude mode).
    aic, bic : float
        Akaike / Bayesian information criteria (unknown noise scale).
    n_params, n_residuals : int
        Number of fitted parameters and of residuals.
    undetermined : tuple of str
        Pole/zero parameters the data do not determine (empty for a
        well-posed fit); see the module docstring.
    order_selection : OrderSelection or None
        The comparison of orders when the order was chosen automatically.
    stderr_jacobian : dict of str to float
        Standard errors from the Jacobian (Birge-scaled), before the
        jackknife's check.
    stderr_jackknife : dict of str to float or None
        Delete-one-dwell jackknife standard errors (None when there are too
        few dwells, fewer than ``n_params + 2``).
    influence : dict of str to dict or None
        Per parameter, the dwell whose removal moves it most:
        ``{"dwell": label, "without": value, "shift_stderr": (value without
        − value) / stated stderr}``.
    """

    gain: float
    natural_frequency_rad_s: float | None
    damping_ratio: float | None
    gain_stderr: float
    natural_frequency_stderr_rad_s: float | None
    damping_ratio_stderr: float | None
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
    order: tuple[int, int] = (0, 2)
    zeros: str = "minimum_phase"
    param_names: tuple[str, ...] = ()
    params: dict[str, float] = field(default_factory=dict, repr=False)
    stderr: dict[str, float] = field(default_factory=dict, repr=False)
    ci95: dict[str, tuple[float, float]] = field(default_factory=dict, repr=False)
    ci95_bootstrap: dict[str, tuple[float, float]] | None = field(default=None, repr=False)
    bootstrap_samples: NDArray[np.float64] | None = field(default=None, repr=False, compare=False)
    J: float = float("nan")
    aic: float = float("nan")
    bic: float = float("nan")
    n_params: int = 0
    n_residuals: int = 0
    order_selection: OrderSelection | None = field(default=None, repr=False, compare=False)
    undetermined: tuple[str, ...] = ()
    stderr_jacobian: dict[str, float] = field(default_factory=dict, repr=False)
    stderr_jackknife: dict[str, float] | None = field(default=None, repr=False)
    influence: dict[str, dict[str, Any]] | None = field(default=None, repr=False)
    _structure: Structure | None = field(default=None, repr=False, compare=False)
    _theta: NDArray[np.float64] | None = field(default=None, repr=False, compare=False)

    # -------------------------------------------------------------- model
    @property
    def num(self) -> list[float]:
        """Numerator coefficients, descending powers of s (``K*[c_nb, ..., c1, 1]``)."""
        assert self._structure is not None and self._theta is not None
        return [float(v) for v in self._structure.num_den(self._theta)[0]]

    @property
    def den(self) -> list[float]:
        """Denominator, descending powers of s, constant term 1 (``[1/wn**2, 2*zeta/wn, 1]`` for order (0, 2))."""
        assert self._structure is not None and self._theta is not None
        return [float(v) for v in self._structure.num_den(self._theta)[1]]

    @property
    def transfer_function(self) -> control.TransferFunction:
        """The rational part as a ``control.TransferFunction`` (no dead time)."""
        return control.tf(self.num, self.den)

    @property
    def poles_rad_s(self) -> NDArray[np.complex128]:
        """Poles in rad/s (all with negative real part)."""
        return np.roots(self.den)

    @property
    def zeros_rad_s(self) -> NDArray[np.complex128]:
        """Zeros in rad/s."""
        num = np.trim_zeros(np.asarray(self.num), "f")
        return np.roots(num) if num.size > 1 else np.zeros(0, dtype=complex)

    @property
    def natural_frequency_hz(self) -> float | None:
        """``wn`` in Hz (None for orders other than na == 2)."""
        wn = self.natural_frequency_rad_s
        return None if wn is None else wn / (2.0 * math.pi)

    @property
    def bandwidth_rad_s(self) -> float:
        """-3 dB bandwidth (relative to the DC gain) of the fitted model, rad/s."""
        return bandwidth_rad_s(self.transfer_function)

    @property
    def bandwidth_hz(self) -> float:
        """-3 dB bandwidth in Hz."""
        return self.bandwidth_rad_s / (2.0 * math.pi)

    @property
    def J_rating(self) -> str:
        """CIFER's verdict on `J`: "near-perfect" (<= 50), "acceptable" (<= 100) or "poor"."""
        return _j_rating(self.J)

    def frequency_response(self, omega_rad_s: ArrayLike) -> NDArray[np.complex128]:
        """Model ``G(jw)`` including the dead time (if fitted), complex."""
        assert self._structure is not None and self._theta is not None
        w = np.asarray(omega_rad_s, dtype=float)
        return np.exp(log_response(self._structure, self._theta, w.ravel())).reshape(w.shape)

    def magnitude(self, omega_rad_s: ArrayLike) -> NDArray[np.float64]:
        """Model ``|G(jw)|`` at angular frequencies `omega_rad_s` (rad/s)."""
        return np.abs(self.frequency_response(omega_rad_s))

    def phase_rad(self, omega_rad_s: ArrayLike) -> NDArray[np.float64]:
        """Model phase in rad, continuous in w (incl. the dead time if fitted)."""
        assert self._structure is not None and self._theta is not None
        w = np.asarray(omega_rad_s, dtype=float)
        return continuous_phase_rad(self._structure, self._theta, w.ravel()).reshape(w.shape)

    def phase_deg(self, omega_rad_s: ArrayLike) -> NDArray[np.float64]:
        """Model phase in degrees (see :meth:`phase_rad`)."""
        return np.degrees(self.phase_rad(omega_rad_s))

    # ------------------------------------------------------------- output
    def summary(self) -> dict[str, Any]:
        """Scalar results as a JSON-serializable dict (NaN -> None).

        Keys: mode, order, zeros, gain (+ _stderr), natural_frequency_rad_s,
        damping_ratio (+ stderrs; None unless na == 2), dead_time_s,
        dead_time_stderr_s, bandwidth_rad_s, bandwidth_hz, num, den, poles
        and zeros_rad_s (``[re, im]`` pairs), params, stderr, ci95,
        ci95_bootstrap, fit ({mode, J, J_rating, AIC, BIC, n_points,
        n_params, n_residuals, dof}), residual_rms_db, residual_rms_deg,
        n_points, undetermined, warnings.
        """
        try:
            bw = self.bandwidth_rad_s
        except ServoscopeError:
            bw = float("nan")
        return jsonable(
            {
                "mode": self.mode,
                "order": list(self.order),
                "zeros": self.zeros,
                "gain": self.gain,
                "gain_stderr": self.gain_stderr,
                "natural_frequency_rad_s": self.natural_frequency_rad_s,
                "natural_frequency_stderr_rad_s": self.natural_frequency_stderr_rad_s,
                "damping_ratio": self.damping_ratio,
                "damping_ratio_stderr": self.damping_ratio_stderr,
                "dead_time_s": self.dead_time_s,
                "dead_time_stderr_s": self.dead_time_stderr_s,
                "bandwidth_rad_s": bw,
                "bandwidth_hz": bw / (2.0 * math.pi),
                "num": self.num,
                "den": self.den,
                "poles": [[p.real, p.imag] for p in self.poles_rad_s],
                "zeros_rad_s": [[z.real, z.imag] for z in self.zeros_rad_s],
                "params": dict(self.params),
                "stderr": dict(self.stderr),
                "ci95": {k: list(v) for k, v in self.ci95.items()},
                "ci95_bootstrap": None
                if self.ci95_bootstrap is None
                else {k: list(v) for k, v in self.ci95_bootstrap.items()},
                "stderr_jacobian": dict(self.stderr_jacobian),
                "stderr_jackknife": None if self.stderr_jackknife is None else dict(self.stderr_jackknife),
                "influence": None if self.influence is None else {k: dict(v) for k, v in self.influence.items()},
                "fit": {
                    "mode": self.mode,
                    "J": self.J,
                    "J_rating": self.J_rating,
                    "AIC": self.aic,
                    "BIC": self.bic,
                    "n_points": self.n_points,
                    "n_params": self.n_params,
                    "n_residuals": self.n_residuals,
                    "dof": self.n_residuals - self.n_params,
                },
                "residual_rms_db": self.residual_rms_db,
                "residual_rms_deg": self.residual_rms_deg,
                "n_points": self.n_points,
                "undetermined": list(self.undetermined),
                "warnings": list(self.warnings),
            }
        )

    def to_pandas(self) -> Any:
        """Measured vs. fitted gain (and phase) per point as a DataFrame. Needs pandas."""
        pd = import_pandas()
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
        head = "<tr><th>parameter</th><th>value</th><th>std. error</th><th>95 % interval</th></tr>"
        body = ""
        for name in self.param_names:
            lo, hi = self.ci95.get(name, (float("nan"), float("nan")))
            body += (
                f"<tr><td>{name}</td><td>{self.params[name]:.6g}</td><td>{self.stderr[name]:.3g}</td>"
                f"<td>[{lo:.6g}, {hi:.6g}]</td></tr>"
            )
        fit = (
            f"order {self.order}, {self.mode} fit, J = {self.J:.3g} ({self.J_rating}), "
            f"AIC = {self.aic:.4g}, BIC = {self.bic:.4g}, {self.n_points} points"
        )
        warn = "".join(f"<li>{w}</li>" for w in self.warnings)
        return (
            f"<table><caption>TransferFunctionFit: {fit}</caption>{head}{body}</table>"
            + (f"<ul>{warn}</ul>" if warn else "")
        )


# ----------------------------------------------------------- public fits
def _check_order(order: Any) -> tuple[int, int]:
    try:
        nb, na = (int(v) for v in order)
    except (TypeError, ValueError):
        raise ServoscopeError(f"order must be (nb, na) or 'auto', got {order!r}") from None
    if not (0 <= nb < na <= 4):
        raise ServoscopeError(f"order (nb, na) = ({nb}, {na}) is not supported: need 0 <= nb < na <= 4")
    return nb, na


def _canonical_in_bounds(st: Structure, d: _Data, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """An optimizer's solution in canonical form, clamped to the bounds of ``d``'s band (every fit's result is)."""
    lo_c, hi_c = st.clamp_limits(float(d.w[0]), float(d.w[-1]))
    return np.clip(st.canonical(x), lo_c, hi_c)


def _ci95(names: Sequence[str], vals: NDArray[np.float64], se: NDArray[np.float64],
          dof: int) -> dict[str, tuple[float, float]]:
    """``value ± t(0.975, dof)·stderr`` per parameter (as nlparci)."""
    tq = float(student_t.ppf(0.975, dof)) if dof > 0 else float("nan")
    return {n: (float(v - tq * e), float(v + tq * e)) for n, v, e in zip(names, vals, se)}


def _stderr_fields(st: Structure, stderr: dict[str, float]) -> dict[str, float | None]:
    """The TransferFunctionFit attributes that repeat ``stderr``'s entries by name (None where absent)."""
    second = st.na == 2
    return {
        "gain_stderr": stderr["gain"],
        "natural_frequency_stderr_rad_s": stderr["natural_frequency_rad_s"] if second else None,
        "damping_ratio_stderr": stderr["damping_ratio"] if second else None,
        "dead_time_stderr_s": stderr["dead_time_s"] if st.delay else None,
    }


def _refit(fit: TransferFunctionFit, d: _Data, sub: _Data) -> NDArray[np.float64] | None:
    """Physical parameters of ``fit``'s model refitted to the dwells ``sub`` from its estimate.

    Clamped to the bounds of the full data ``d``'s band, as the fit itself was
    (a refit that runs off towards a bound gives the bound, never an
    overflow); None when ``sub`` cannot determine the model or the refit fails.
    """
    st = fit._structure
    assert st is not None and fit._theta is not None
    if _identifiability_problem(sub, st, fit.mode) is not None:
        return None
    sol = _local(st, sub, np.asarray(fit._theta), fit.mode == "complex")
    if not np.all(np.isfinite(sol.x)):
        return None
    return st.physical(_canonical_in_bounds(st, d, sol.x))[0]


def _build(
    st: Structure,
    d: _Data,
    fr: FrequencyResponse,
    sol: Any,
    mode: str,
    warns: list[str],
) -> TransferFunctionFit:
    """Turn an optimizer solution into a TransferFunctionFit (covariance, CI, J, AIC/BIC)."""
    use_phase = mode == "complex"
    theta = _canonical_in_bounds(st, d, sol.x)
    r = _resid(st, d, theta, use_phase)
    J = _jac(st, d, theta, use_phase)
    m, p = r.size, theta.size
    dof = m - p
    chi2 = float(r @ r)
    warns = list(warns)
    try:
        cov_int = np.linalg.inv(J.T @ J)
        if not np.all(np.isfinite(cov_int)):
            raise np.linalg.LinAlgError
    except np.linalg.LinAlgError:
        cov_int = np.linalg.pinv(J.T @ J)
        warns.append("singular Jacobian: standard errors are unreliable (too many parameters for the data?)")
    if dof > 0:
        # Stated errors are trusted unless the misfit says they are too
        # small; without any, the scatter alone sets the scale (nlinfit).
        cov_int = cov_int * (max(1.0, chi2 / dof) if d.stated else chi2 / dof)
    else:
        cov_int = np.full_like(cov_int, np.nan)
        warns.append("no degrees of freedom left: standard errors unavailable")
    vals, der = st.physical(theta)
    cov = der[:, None] * cov_int * der[None, :]
    diag = np.diag(cov)
    se = np.where(np.isfinite(diag), np.sqrt(np.clip(diag, 0.0, None)), np.nan)
    names = st.names()
    params = {n: float(v) for n, v in zip(names, vals)}
    stderr = {n: float(s) for n, s in zip(names, se)}
    ci95 = _ci95(names, vals, se, dof)

    # Parameters outside the data or not determined by them.
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
                f"{_words(name)} {vals[i]:.4g} rad/s lies far outside the measured band "
                f"[{w_lo:.3g}, {w_hi:.3g}] rad/s: the data do not determine it; try a lower order"
            )
        elif kind == "zeta" and not (ZETA_RANGE[0] <= vals[i] <= ZETA_RANGE[1]):
            undetermined.append(name)
            warns.append(f"{_words(name)} {vals[i]:.4g} is implausible: the data do not determine it; try a lower order")
        elif not (rel <= 1.0):
            undetermined.append(name)
            warns.append(
                f"{_words(name)} is not determined by the data (stderr {100 * rel:.0f} % of its value); try a lower order"
            )
        if kind == "freq" and w_hi < vals[i] <= w_hi * FREQ_MARGIN:
            warns.append(
                f"highest measured frequency {w_hi:.3g} rad/s is below the fitted {_words(name)} "
                f"{vals[i]:.3g} rad/s: it is poorly determined"
            )
        elif kind == "freq" and w_lo / FREQ_MARGIN <= vals[i] < w_lo and name.startswith(("pole", "natural")):
            warns.append(
                f"lowest measured frequency {w_lo:.3g} rad/s is above the fitted {_words(name)} "
                f"{vals[i]:.3g} rad/s: K is extrapolated"
            )

    lg = log_response(st, theta, d.w)
    res_db = _DB_PER_NEPER * (lg.real - d.lng)
    res_deg = None
    ph_err = None
    if use_phase:
        err = np.degrees(_wrap(lg.imag - d.ph))
        ph_err = np.where(d.has_ph, err, np.nan)
        res_deg = float(np.sqrt(np.mean(err[d.has_ph] ** 2)))
    jc = cifer_cost(res_db, ph_err, d.fid)
    aic = chi2 + 2.0 * p
    bic = chi2 + p * math.log(m)

    second = st.na == 2
    tau = params.get("dead_time_s") if st.delay else None
    if not all(math.isfinite(v) for v in vals):
        raise ServoscopeError("transfer-function fit failed: non-finite parameters")
    return TransferFunctionFit(
        gain=params["gain"],
        natural_frequency_rad_s=params["natural_frequency_rad_s"] if second else None,
        damping_ratio=params["damping_ratio"] if second else None,
        dead_time_s=tau,
        **_stderr_fields(st, stderr),
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


#: A parameter whose jackknife error exceeds its Jacobian error this many times gets a warning.
_RESTS_ON_ONE = 2.0


def _with_jackknife(fit: TransferFunctionFit, d: _Data) -> TransferFunctionFit:
    """The fit with its standard errors checked by the delete-one-dwell jackknife (module docstring)."""
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
        if se_jack[k] > _RESTS_ON_ONE * se[k]:
            warns.append(
                f"{_words(name)} rests on {inf['dwell']} more than the dwells' stated errors allow (without it: "
                f"{inf['without']:.5g}); its interval was widened {se_jack[k] / se[k]:.1f}x by leaving each dwell "
                "out in turn. A systematic error in that dwell? (video compression of very small motions, a "
                "resonance the model lacks)"
            )
    return replace(
        fit,
        warnings=tuple(dict.fromkeys(fit.warnings + tuple(warns))),
        covariance=readonly(cov),
        stderr=stderr,
        ci95=_ci95(names, vals, se_new, fit.n_residuals - fit.n_params),
        stderr_jackknife={n: float(v) for n, v in zip(names, se_jack)},
        influence=influence,
        **_stderr_fields(st, stderr),
    )


def _bootstrap(
    fit: TransferFunctionFit, d: _Data, n_boot: int, seed: int | None
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
    if isinstance(order, str):
        if order != "auto":
            raise ServoscopeError(f"{who}: order must be (nb, na) or 'auto', got {order!r}")
        from servoscope.sysid.order import select_order

        sel = select_order(fr, mode=mode, max_order=max_order, zeros=zeros)
        best = sel.best
        if bootstrap:
            best = fit_transfer_function(fr, order=best.order, mode=mode, zeros=zeros, bootstrap=bootstrap, seed=seed,
                                         n_starts=n_starts, jackknife=jackknife)
        elif jackknife:
            with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
                best = _with_jackknife(best, _prepare(fr, mode, who)[0])
        return replace(best, order_selection=sel)
    nb, na = _check_order(order)
    # Wild starting points and undetermined parameters can overflow on the
    # way; every result is checked for finiteness below, so numpy's warnings
    # would only be noise (and errors under pytest's filter).
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
        return _fit_fixed_order(fr, nb, na, mode, zeros, bootstrap, seed, n_starts, who, jackknife)


def _fit_fixed_order(
    fr: FrequencyResponse, nb: int, na: int, mode: str, zeros: str, bootstrap: int,
    seed: int | None, n_starts: int | None, who: str, jackknife: bool = True,
) -> TransferFunctionFit:
    d, warns = _prepare(fr, mode, who)
    w_ref = float(math.exp(np.mean(np.log(d.w)))) if d.n else 1.0
    st = Structure(nb, na, zeros, mode == "complex", w_ref)
    problem = _identifiability_problem(d, st, mode)
    if problem is not None:
        raise ServoscopeError(f"{who}: {problem}")
    if n_starts is None:
        # Free zeros add local minima (an RHP zero's phase lag mimics a
        # delay), so they get more starts.
        n_starts = max(3 * _N_STARTS, 4 * st.n_params) if zeros == "free" else max(_N_STARTS, 2 * st.n_params)
    sol = _multistart(st, d, mode == "complex", n_starts)
    if sol is None:
        raise ServoscopeError(f"{who}: the optimizer failed from every starting point (non-finite data?)")
    fit = _build(st, d, fr, sol, mode, warns)
    if jackknife:
        fit = _with_jackknife(fit, d)
    if bootstrap:
        samples, ci_b, bw = _bootstrap(fit, d, int(bootstrap), seed)
        fit = replace(
            fit,
            bootstrap_samples=readonly(samples),
            ci95_bootstrap=ci_b,
            warnings=fit.warnings + tuple(bw),
        )
    return fit


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
