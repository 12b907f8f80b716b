"""One model for the sines and the step: block-structured servo models fitted to whole traces.

The frequency-domain fit (:mod:`servoscope.sysid.tf_fit`) sees each dwell's fundamental
only. Here a model of :mod:`servoscope.sysid.servo_sim` (the linear dynamics and dead time,
with at most one of a rate limit, backlash, command quantization or saturation) is
simulated for every test and fitted to the measured angle, sample by sample: the dwells'
harmonics and transients count, and so does the step.

Method
------
* Residuals are ``(measured − model − offset)/σ``, each test's rest angle (``offset``)
  projected out. The dwells, the step and the sweeps are data sets, each weighted by its own noise:
  first the tracker's measured noise, then (after a first fit) the larger of that and the
  set's own residual scatter under the best-fitting candidate, so that neither set swamps
  the other by its number of samples (a maximum-likelihood fit with one variance per set).
* The continuous parameters are fitted by :func:`scipy.optimize.least_squares` (positive
  ones on a log scale, from several starts for a nonlinear parameter). Their covariance is
  the Newey–West sandwich of :func:`servoscope.sysid.hac.hac_covariance` (tracking errors
  are correlated from frame to frame); the dead time's adds the input starts' error.
* The quantization step moves the model in jumps (the command's staircase changes only
  when a level crosses a sample), so it is profiled on a grid; its interval is the set of
  steps whose cost is within χ²(1)'s 95 % point of the best, in the fit's own noise units.
* Model selection: AIC and BIC with the cost in units of the best candidate's residual
  variance, widened by its lag-1 autocorrelation ``(1 + ρ)/(1 − ρ)``, and the number of
  effective samples reduced by the same factor. A nonlinear structure is selected only when
  its BIC beats the linear model's by more than :data:`BIC_MARGIN` ("very strong" on Kass &
  Raftery's scale): a tracking artefact must not read as a nonlinearity.
"""

from __future__ import annotations

import math
import warnings as _warnings

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from ..errors import ServoscopeError
from ..parameters import (FitResult, Parameter, Parameters, Tie, check_held, interval95, stderr_of_interval,
                          unit_of)
from ..results import jsonable
from ._tf_metrics import cifer_cost
from .hac import hac_covariance
from .servo_sim import LINEAR_PARAMETERS, NONLINEAR_PARAMETER, STRUCTURES, ServoTrace, simulate_trace

__all__ = ["TRACE_SYSTEMATIC", "ServoModelFit", "check_servo_held", "dwell_cost", "fit_percent", "fit_servo_model",
           "linear_starts", "lag1", "measured_noise", "trace_group"]

#: Systematic uncertainty of the linear part from whole traces, added to the fit's: relative for
#: the gain, ωn and ζ, seconds for the dead time. Measured on the twin's quick campaigns
#: (480×384, seeds 0–2; linear, rate-limited, backlash and quantized servos): errors up to
#: 0.1 % (K), 0.17 % (ωn), 0.13 % (ζ), 0.05 ms (dead time) raw, and 0.26 % (ωn), 0.39 % (ζ),
#: 0.11 ms under H.264 at 20 Mbit/s, several of the fit's own standard errors and common to
#: all tests (so no jackknife sees them): the tracker's sub-pixel bias, the codec's, the
#: rendered exposure.
TRACE_SYSTEMATIC = {"gain": 6e-4, "natural_frequency_rad_s": 1.5e-3, "damping_ratio": 2.5e-3, "dead_time_s": 6e-5}
_CHI2_1_95 = 3.841458820694124
#: Positive parameters, fitted on a log scale.
_POSITIVE = {"natural_frequency_rad_s", "damping_ratio", *NONLINEAR_PARAMETER.values()}
_DEFAULT_BOUNDS = {"gain": (-math.inf, math.inf), "natural_frequency_rad_s": (1e-3, 1e5),
                   "damping_ratio": (1e-3, 20.0), "dead_time_s": (0.0, 2.0)}


def fit_percent(measured: NDArray[np.float64], predicted: NDArray[np.float64]) -> float:
    """MATLAB ``compare``'s fit: ``100·(1 − ‖y − ŷ‖/‖y − mean(y)‖)``, in percent (100: perfect)."""
    y = np.asarray(measured, dtype=float)
    spread = float(np.linalg.norm(y - y.mean()))
    if spread == 0.0:
        return float("nan")
    return 100.0 * (1.0 - float(np.linalg.norm(y - np.asarray(predicted, dtype=float))) / spread)


def check_servo_held(structure: str, fix: dict[str, float] | None,
                     bounds: dict[str, tuple[float, float]] | None, ties: dict[str, str] | None = None) -> None:
    """Raise ServoscopeError for what `structure`'s model cannot hold (:func:`servoscope.parameters.check_held`)."""
    names = set(LINEAR_PARAMETERS)
    if structure in NONLINEAR_PARAMETER:
        names.add(NONLINEAR_PARAMETER[structure])
    check_held(names, fix, bounds, ties, who=f"the {structure} model")


@dataclass(frozen=True)
class ServoModelFit(FitResult):
    """A block-structured model fitted to whole traces (see the module's description).

    Attributes
    ----------
    structure : str
        One of ``"linear"``, ``"rate_limit"``, ``"backlash"``, ``"quantization"``, ``"saturation"``.
    params, stderr : dict
        Every parameter (linear part and the structure's own) and its standard error (0 when held fixed).
    ci95 : dict of name → (lo, hi)
    fixed : tuple of str
        The parameters held fixed.
    tied : dict of name → expression
        Parameters computed from others (lmfit's ``expr``), their errors by the delta method.
    chi2 : float
        The cost, in units of each data set's noise.
    n_samples, n_free : int
        Samples fitted; free parameters (the tests' rest angles included).
    offsets : dict of label → float
        Each test's rest angle, rad.
    sigma : dict of data set → float
        The noise each data set was weighted by, rad.
    aic, bic : float
        Set by :func:`select_servo_model` (NaN for a lone fit).
    J : float
        CIFER's cost of the model's fundamentals against the dwells' measured response (NaN without one).
    step_fit_percent, dwell_fit_percent : float or None
        :func:`fit_percent` of the model on the step, and on the dwells together.
    traces : list of ServoTrace
        What was fitted (for plots and predictions).
    warnings : list of str
    """

    structure: str
    params: dict[str, float]
    stderr: dict[str, float]
    ci95: dict[str, tuple[float, float]]
    fixed: tuple[str, ...]
    chi2: float
    n_samples: int
    n_free: int
    offsets: dict[str, float]
    sigma: dict[str, float]
    aic: float = math.nan
    bic: float = math.nan
    J: float = math.nan
    step_fit_percent: float | None = None
    dwell_fit_percent: float | None = None
    traces: tuple[ServoTrace, ...] = field(default=(), repr=False)
    warnings: tuple[str, ...] = ()
    tied: dict[str, str] = field(default_factory=dict)

    @property
    def model_name(self) -> str:  # type: ignore[override]
        return f"{self.structure} servo model (time domain, whole traces)"

    @property
    def parameters(self) -> Parameters:
        """Every parameter with its error and interval (the log-normal ones never below zero)."""
        out = []
        for name, value in self.params.items():
            kind = interval_kind(self.structure, name, self.tied)
            out.append(Parameter(name, value, self.stderr.get(name, math.nan), self.ci95.get(name, (math.nan, math.nan)),
                                 vary=name not in self.fixed, expr=self.tied.get(name), unit=unit_of(name),
                                 interval="normal" if name in self.fixed else kind))
        return Parameters(out)

    def fit_statistics(self) -> dict[str, Any]:
        """Samples, free parameters, χ², AIC, BIC, CIFER's J, the fits on the step and the dwells."""
        return {"samples": self.n_samples, "free parameters": self.n_free, "chi-square": self.chi2,
                "AIC": self.aic, "BIC": self.bic, "J": self.J, "step fit (%)": self.step_fit_percent,
                "dwell fit (%)": self.dwell_fit_percent}

    def predict(self, trace: ServoTrace, time_s: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """The model's angle for ``trace``'s input, on its rest angle when it was fitted (else 0)."""
        return simulate_trace(trace, self.structure, self.params, time_s=time_s) + self.offsets.get(trace.label, 0.0)

    def describing_function(self, frequency_hz: float, amplitudes: NDArray[np.float64]) -> NDArray[np.complex128]:
        """The model's gain and phase at ``frequency_hz`` for sines of each input amplitude (its fundamental).

        A linear model's is one number; a nonlinear one's changes with the amplitude. Each sine
        is simulated until its transient has died (five of the linear part's time constants),
        then its fundamental taken over three periods.
        """
        p = self.params
        settle = p["dead_time_s"] + 5.0 / max(p["natural_frequency_rad_s"] * p["damping_ratio"], 1e-3)
        period = 1.0 / frequency_hz
        t = np.arange(0.0, settle + 3.0 * period, min(period / 50.0, 1e-3))
        out = []
        for a in np.asarray(amplitudes, dtype=float):
            trace = ServoTrace("df", "sine", float(a), float(frequency_hz), 0.0, t, np.zeros_like(t), 1.0, 0.0,
                               (settle, float(t[-1])))
            out.append(_fundamental(trace, simulate_trace(trace, self.structure, p)))
        return np.asarray(out)

    @property
    def linear_transfer_function(self) -> Any:
        """The linear part, ``K·ωn²/(s² + 2ζωn·s + ωn²)`` (python-control; the dead time not included)."""
        import control

        k, wn, z = (self.params[n] for n in ("gain", "natural_frequency_rad_s", "damping_ratio"))
        return control.tf([k * wn * wn], [1.0, 2.0 * z * wn, wn * wn])

    @property
    def nonlinear_parameter(self) -> str | None:
        """The structure's own parameter's name (None for the linear model)."""
        return NONLINEAR_PARAMETER.get(self.structure)

    def summary(self) -> dict[str, Any]:
        """Plain types: structure, parameters, errors, intervals, costs and fits."""
        return jsonable({
            "structure": self.structure, **self.params, "stderr": dict(self.stderr),
            "ci95": {k: list(v) for k, v in self.ci95.items()}, "fixed": list(self.fixed), "tied": dict(self.tied),
            "chi2": self.chi2, "n_samples": self.n_samples, "n_free": self.n_free, "aic": self.aic, "bic": self.bic,
            "J": self.J, "step_fit_percent": self.step_fit_percent, "dwell_fit_percent": self.dwell_fit_percent,
            "noise_rad": dict(self.sigma), "rest_angle_rad": dict(self.offsets), "warnings": list(self.warnings)})

    @classmethod
    def from_summary(cls, data: dict[str, Any]) -> "ServoModelFit":
        """Rebuild from :meth:`summary` (without the traces)."""
        names = [*LINEAR_PARAMETERS, *([NONLINEAR_PARAMETER[data["structure"]]]
                                       if data["structure"] in NONLINEAR_PARAMETER else [])]

        def num(v: Any) -> float:
            return math.nan if v is None else float(v)

        return cls(data["structure"], {k: num(data[k]) for k in names}, {k: num(v) for k, v in data["stderr"].items()},
                   {k: (num(v[0]), num(v[1])) for k, v in data["ci95"].items()}, tuple(data["fixed"]),
                   num(data["chi2"]), int(data["n_samples"]), int(data["n_free"]),
                   {k: num(v) for k, v in (data.get("rest_angle_rad") or {}).items()},
                   {k: num(v) for k, v in data["noise_rad"].items()}, num(data["aic"]), num(data["bic"]),
                   num(data["J"]), data["step_fit_percent"], data["dwell_fit_percent"],
                   warnings=tuple(data["warnings"]), tied=dict(data.get("tied") or {}))

    def plot(self, ax: Any = None) -> list[Any]:
        """Each trace measured (dots) and the model (line), the rest angle taken off, stacked."""
        import matplotlib.pyplot as plt

        ax = ax or plt.gca()
        lines: list[Any] = []
        for i, tr in enumerate(self.traces):
            shift = 3.0 * i * max(float(np.ptp(tr.angle_rad)), 1e-9)
            off = self.offsets.get(tr.label, 0.0)
            lines += ax.plot(tr.time_s - tr.t0_s, tr.angle_rad - off + shift, ".", ms=2, color="0.5")
            lines += ax.plot(tr.time_s - tr.t0_s, simulate_trace(tr, self.structure, self.params) + shift, "-", lw=1)
        ax.set_xlabel("time after the input's start (s)")
        ax.set_ylabel("angle (rad), tests stacked")
        ax.set_title(f"{self.structure} model against the measured traces")
        return lines


def trace_group(trace: ServoTrace) -> str:
    """The data set a trace is weighted in: ``"dwells"``, ``"step"`` or ``"sweep"`` (each its own noise)."""
    return {"step": "step", "sweep": "sweep"}.get(trace.kind, "dwells")


class _Problem:
    """The residual of one structure over the traces, with some parameters held."""

    def __init__(self, traces: list[ServoTrace], structure: str, values: dict[str, float], free: list[str],
                 sigma: dict[str, float], ties: dict[str, str] | None = None):
        self.traces, self.structure, self.values, self.free = traces, structure, dict(values), free
        self.ties = {name: Tie(expression) for name, expression in (ties or {}).items()}
        self.weight = [1.0 / sigma[trace_group(tr)] for tr in traces]

    def params(self, x: NDArray[np.float64]) -> dict[str, float]:
        p = dict(self.values)
        for name, v in zip(self.free, x):
            p[name] = math.exp(v) if name in _POSITIVE else float(v)
        for name, tie in self.ties.items():
            p[name] = tie(p)
        return p

    def x(self, params: dict[str, float]) -> NDArray[np.float64]:
        return np.array([math.log(params[n]) if n in _POSITIVE else params[n] for n in self.free])

    def residual(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        p = self.params(x)
        out = []
        for tr, w in zip(self.traces, self.weight):
            r = tr.angle_rad - simulate_trace(tr, self.structure, p)
            out.append(w * (r - r.mean()))  # the rest angle, projected out
        return np.concatenate(out)

    def offsets(self, params: dict[str, float]) -> dict[str, float]:
        return {tr.label: float(np.mean(tr.angle_rad - simulate_trace(tr, self.structure, params)))
                for tr in self.traces}


def _x_bounds(problem: _Problem, bounds: dict[str, tuple[float, float]]) -> tuple[NDArray, NDArray]:
    lo, hi = [], []
    for name in problem.free:
        a, b = bounds.get(name, _DEFAULT_BOUNDS.get(name, (0.0, math.inf)))
        if name in _POSITIVE:
            a, b = math.log(max(a, 1e-12)), (math.log(b) if math.isfinite(b) else math.inf)
        lo.append(a)
        hi.append(b)
    return np.array(lo), np.array(hi)


def _solve(problem: _Problem, starts: list[dict[str, float]], bounds: dict[str, tuple[float, float]]):
    """The best of least-squares runs from the best three of ``starts`` (each clipped into the bounds)."""
    lo, hi = _x_bounds(problem, bounds)
    points = []
    for start in starts:
        x0 = problem.x(start)
        margin = 1e-9 * (1.0 + np.abs(x0))
        x0 = np.where(np.isfinite(lo), np.maximum(x0, lo + margin), x0)
        points.append(np.where(np.isfinite(hi), np.minimum(x0, hi - margin), x0))
    if len(points) > 3:
        # A start's own cost says which are worth a descent (one simulation each, not hundreds).
        points.sort(key=lambda x: float(np.sum(problem.residual(x) ** 2)))
        points = points[:3]
    best = None
    for x0 in points:
        sol = least_squares(problem.residual, x0, bounds=(lo, hi), x_scale="jac", diff_step=1e-6, max_nfev=400)
        if best is None or sol.cost < best.cost:
            best = sol
    return best


def _fundamental(trace: ServoTrace, y: NDArray[np.float64]) -> complex:
    """A dwell's complex gain (output over input, phase against the input's sine) in its steady window."""
    lo, hi = trace.window_s or (trace.t0_s, math.inf)
    inside = (trace.time_s >= lo) & (trace.time_s <= hi)
    w = 2.0 * math.pi * float(trace.frequency_hz) * (trace.time_s[inside] - trace.t0_s)
    design = np.column_stack([np.sin(w), np.cos(w), np.ones_like(w)])
    (a, b, _), *_ = np.linalg.lstsq(design, y[inside], rcond=None)
    # M·sin(w + φ) = M·cos φ·sin w + M·sin φ·cos w: (a, b) is M·e^{jφ}.
    return complex(a, b) / trace.amplitude


def dwell_cost(params: dict[str, float], structure: str, traces: list[ServoTrace],
               response: dict[str, tuple[float, float, float]]) -> float:
    """CIFER's J of a model's fundamentals against the measured ones, over the dwells in ``response``.

    ``response`` maps a dwell's label to its measured (gain, phase in degrees, coherence); the
    model's fundamental is taken from its simulated trace in the dwell's window, as the
    measured one was.
    """
    db, deg, coh = [], [], []
    for tr in traces:
        if tr.kind != "sine" or tr.label not in response:
            continue
        gain, phase_deg, coherence = response[tr.label]
        model = _fundamental(tr, simulate_trace(tr, structure, params))
        db.append(20.0 * math.log10(max(abs(model) / gain, 1e-6)))  # a model that does not move: -120 dB
        deg.append((math.degrees(math.atan2(model.imag, model.real)) - phase_deg + 180.0) % 360.0 - 180.0
                   if math.isfinite(phase_deg) else math.nan)
        coh.append(coherence)
    return cifer_cost(db, deg, coh) if db else math.nan


def _nonlinear_starts(traces: list[ServoTrace], structure: str, gain: float) -> tuple[list[float], tuple]:
    """Starting values and default bounds of a structure's parameter, from the tests' sizes.

    The last start is where the structure is all but linear (a play of almost nothing, a
    limit far beyond every slew or swing), so the fit is never worse than the linear model's.
    """
    swing = [0.5 * float(np.ptp(tr.angle_rad)) for tr in traces]
    if structure == "backlash":
        s = float(np.median(swing))
        return [0.03 * s, 0.15 * s, 0.5 * s, 1e-3 * s], (1e-5 * s, 4.0 * s)
    if structure == "quantization":
        # Profiled on its grid (no starts): from a step that changes nothing to twice the smallest sine.
        amp = min(tr.amplitude for tr in traces)
        return [], (amp / 1000.0, 2.0 * amp)
    if structure == "saturation":
        s = max(swing)
        return [0.8 * s, 1.0 * s, 1.3 * s, 50.0 * s], (0.05 * s, 100.0 * s)
    # A step's slew is unbounded; the sines' and sweeps' largest, or the step's size over 10 ms, sets the scale.
    slew = max(abs(gain) * tr.amplitude * (2.0 * math.pi * tr.top_frequency_hz if tr.kind != "step" else 100.0)
               for tr in traces)
    return [0.3 * slew, 0.7 * slew, 1.5 * slew, 1e3 * slew], (1e-3 * slew, 1e4 * slew)


def _quantization_profile(traces, starts, free, sigma, bounds, ties) -> tuple[list[float], list[Any], float]:
    """The best fit at each quantization step on a log grid (each from the last), refined around the best."""
    lo, hi = bounds["quantization_step"]
    grid = list(np.geomspace(lo, hi, 40))
    sols: list[Any] = []
    values = dict(starts[0])
    problems = []
    for q in grid:
        problems.append(_Problem(traces, "quantization", {**values, "quantization_step": q}, free, sigma, ties))
        sols.append(_solve(problems[-1], starts, bounds))
        starts = [problems[-1].params(sols[-1].x)]
    # The profile has several dips (a step and its half make alike staircases): refine around the three best.
    coarse = list(grid)
    for k in sorted(range(len(coarse)), key=lambda i: sols[i].cost)[:3]:
        best = problems[k].params(sols[k].x)
        for q in np.geomspace(coarse[max(k - 1, 0)], coarse[min(k + 1, len(coarse) - 1)], 9)[1:-1]:
            problem = _Problem(traces, "quantization", {**values, "quantization_step": q}, free, sigma, ties)
            sols.append(_solve(problem, [best], bounds))
            grid.append(float(q))
    return grid, sols, float(grid[int(np.argmin([s.cost for s in sols]))])


def fit_servo_model(traces: list[ServoTrace], structure: str = "linear", *,
                    start: dict[str, float] | list[dict[str, float]] | None = None,
                    fix: dict[str, float] | None = None, bounds: dict[str, tuple[float, float]] | None = None,
                    sigma: dict[str, float] | None = None,
                    response: dict[str, tuple[float, float, float]] | None = None,
                    t0_stderr_s: float = 0.0, ties: dict[str, str] | None = None) -> ServoModelFit:
    """Fit one block structure to whole traces (see the module's description).

    Parameters
    ----------
    traces : list of ServoTrace
        The dwells, the step and the sweeps, any of them.
    structure : str
        One of ``"linear"``, ``"rate_limit"``, ``"backlash"``, ``"quantization"``, ``"saturation"``.
    start : dict or list of dict, optional
        Starting values of ``gain``, ``natural_frequency_rad_s``, ``damping_ratio``,
        ``dead_time_s`` (the frequency-domain fit's, say), or several sets; a structure's
        own parameter may be given too (else it starts from several values scaled to the
        tests). Default: the best points of a coarse grid over the linear model
        (:func:`linear_starts`).
    fix, bounds : dict, optional
        Parameters held at a value, or within ``(lo, hi)``.
    sigma : dict, optional
        Noise (rad) of each data set, ``"dwells"``, ``"step"`` and ``"sweep"`` (:func:`trace_group`); default
        the traces' measured noise.
    response : dict, optional
        The dwells' measured (gain, phase_deg, coherence) by label, for CIFER's J.
    t0_stderr_s : float
        The input starts' standard error, added to the dead time's.
    ties : dict of name → expression, optional
        Parameters computed from the others, as lmfit's ``expr``: ``{"rate_limit_rad_s":
        "4*gain"}`` (arithmetic and math functions, evaluated by asteval; an expression
        may use free and fixed parameters, not another tied one).

    Returns
    -------
    ServoModelFit

    Raises
    ------
    ServoscopeError
        An unknown structure or parameter, no traces, or fewer samples than parameters.
    """
    if structure not in STRUCTURES:
        raise ServoscopeError(f"unknown model structure {structure!r} (choose from {', '.join(STRUCTURES)})")
    if not traces:
        raise ServoscopeError("a time-domain fit needs at least one test")
    fix, bounds, ties = dict(fix or {}), dict(bounds or {}), dict(ties or {})
    check_servo_held(structure, fix, bounds, ties)
    names = list(LINEAR_PARAMETERS) + ([NONLINEAR_PARAMETER[structure]] if structure in NONLINEAR_PARAMETER else [])
    sigma = sigma or measured_noise(traces)
    starts = linear_starts(traces, sigma) if start is None else [start] if isinstance(start, dict) else list(start)
    starts = [{**s, **fix} for s in starts]
    values = {**{k: float(starts[0][k]) for k in LINEAR_PARAMETERS}, **fix}
    nl = NONLINEAR_PARAMETER.get(structure)
    if nl is not None and nl not in bounds and nl not in ties:
        bounds[nl] = _nonlinear_starts(traces, structure, values["gain"])[1]
    free = [n for n in names if n not in fix and n not in ties]
    if sum(tr.time_s.size for tr in traces) <= len(free) + len(traces):
        raise ServoscopeError(f"{sum(tr.time_s.size for tr in traces)} samples cannot fit {len(free)} parameters "
                              f"and {len(traces)} rest angles")
    profile = None
    if structure == "quantization" and nl in free:
        free.remove(nl)
        grid, sols, q = _quantization_profile(traces, starts, free, sigma, bounds, ties)
        profile = (grid, [2.0 * s.cost for s in sols])
        values[nl] = q
        sol = sols[int(np.argmin(profile[1]))]
    else:
        problem = _Problem(traces, structure, values, free, sigma, ties)
        if nl in free:
            starts = [s if nl in s else {**s, nl: v} for s in starts
                      for v in _nonlinear_starts(traces, structure, s["gain"])[0]]
        sol = _solve(problem, starts, bounds)
    problem = _Problem(traces, structure, values, free, sigma, ties)
    return _finish(problem, sol, structure, names, fix, bounds, profile, response, t0_stderr_s, sigma)


def linear_starts(traces: list[ServoTrace], sigma: dict[str, float], keep: int = 3) -> list[dict[str, float]]:
    """The ``keep`` best points of a coarse grid over the linear model's ωn, ζ and dead time.

    The gain is solved for at each point (the linear model is linear in it), so the grid
    needs no gain axis; the result does not depend on another fit having worked.
    """
    sines = [f for tr in traces if tr.kind != "step" for f in (tr.frequency_hz, tr.from_hz, tr.to_hz) if f]
    f_lo, f_hi = (min(sines), max(sines)) if sines else (0.5, 20.0)
    scored = []
    for wn in np.geomspace(2.0 * math.pi * f_lo * 0.5, 2.0 * math.pi * f_hi * 2.0, 8):
        for zeta in (0.25, 0.6, 1.0, 1.6):
            for tau in (0.0, 0.01, 0.03, 0.06, 0.1, 0.15, 0.25, 0.4):
                p = {"gain": 1.0, "natural_frequency_rad_s": wn, "damping_ratio": zeta, "dead_time_s": tau}
                unit, meas = [], []
                for tr in traces:
                    w = 1.0 / sigma[trace_group(tr)]
                    u = simulate_trace(tr, "linear", p)
                    unit.append(w * (u - u.mean()))
                    meas.append(w * (tr.angle_rad - tr.angle_rad.mean()))
                u, y = np.concatenate(unit), np.concatenate(meas)
                k = float(u @ y) / float(u @ u) if float(u @ u) > 0 else 0.0
                scored.append((float(np.sum((y - k * u) ** 2)), {**p, "gain": k if k != 0 else 1e-6}))
    scored.sort(key=lambda c: c[0])
    return [p for _, p in scored[:keep]]


def measured_noise(traces: list[ServoTrace]) -> dict[str, float]:
    out: dict[str, list[float]] = {}
    for tr in traces:
        out.setdefault(trace_group(tr), []).append(tr.noise_rad)
    return {k: float(np.median(v)) for k, v in out.items()}


def _finish(problem: _Problem, sol: Any, structure: str, names: list[str], fix: dict[str, float],
            bounds: dict[str, tuple[float, float]], profile: tuple | None, response: dict | None,
            t0_stderr_s: float, sigma: dict[str, float]) -> ServoModelFit:
    """Parameters, their errors and intervals, and the fit's costs, from the solver's answer."""
    params = problem.params(sol.x)
    residual = problem.residual(sol.x)
    chi2 = float(residual @ residual)
    n = residual.size
    with _warnings.catch_warnings():
        _warnings.simplefilter("ignore", RuntimeWarning)
        cov = hac_covariance(sol.jac, residual) if problem.free else np.zeros((0, 0))
    stderr = {k: 0.0 for k in names}
    warnings: list[str] = []
    for i, name in enumerate(problem.free):
        se_x = math.sqrt(cov[i, i]) if np.isfinite(cov[i, i]) and cov[i, i] >= 0 else math.nan
        stderr[name] = se_x * params[name] if name in _POSITIVE else se_x  # the log scale's delta method
    if "dead_time_s" in problem.free:
        stderr["dead_time_s"] = math.hypot(stderr["dead_time_s"], t0_stderr_s, TRACE_SYSTEMATIC["dead_time_s"])
    for name in ("gain", "natural_frequency_rad_s", "damping_ratio"):
        if name in problem.free:
            stderr[name] = math.hypot(stderr[name], TRACE_SYSTEMATIC[name] * abs(params[name]))
    nl = NONLINEAR_PARAMETER.get(structure)
    if problem.ties and problem.free:
        # A tied parameter's error by the delta method, in the free parameters' natural units: their
        # covariance (the log scale's carried over) plus each one's systematic part, so a tie
        # promises no more than what it is computed from.
        scale = np.array([params[n] if n in _POSITIVE else 1.0 for n in problem.free])
        c_nat = cov * np.outer(scale, scale)
        extra = {n: (stderr[n] ** 2 - c_nat[i, i]) for i, n in enumerate(problem.free)}
        c_nat = c_nat + np.diag([max(extra[n], 0.0) for n in problem.free])
        for name, tie in problem.ties.items():
            grad = np.empty(len(problem.free))
            for i, free_name in enumerate(problem.free):
                h = 1e-6 * max(1.0, abs(params[free_name]))
                up, down = dict(params), dict(params)
                up[free_name] += h
                down[free_name] -= h
                grad[i] = (tie(up) - tie(down)) / (2.0 * h)
            stderr[name] = math.sqrt(max(float(grad @ c_nat @ grad), 0.0))
    # The quantization step's interval is its profile's (below); a placeholder until then.
    kinds = {k: interval_kind(structure, k, problem.ties) for k in names}
    ci95 = {k: interval95(params[k], stderr[k], "normal" if kinds[k] == "profile" else kinds[k]) for k in names}
    if profile is not None:
        order = np.argsort(profile[0])
        grid, cost = np.asarray(profile[0])[order], np.asarray(profile[1])[order]
        rho = lag1(residual)
        limit = _CHI2_1_95 * max(chi2 / max(n - len(names), 1), 1.0) * (1.0 + rho) / (1.0 - rho)
        k = int(np.argmin(cost))
        # The interval runs to the first grid steps outside it (the grid's resolution is part of
        # the promise): never narrower than the neighbouring grid points.
        lo_k, hi_k = k, k
        while lo_k > 0 and cost[lo_k] - cost[k] <= limit:
            lo_k -= 1
        while hi_k < grid.size - 1 and cost[hi_k] - cost[k] <= limit:
            hi_k += 1
        lo_k, hi_k = min(lo_k, max(k - 1, 0)), max(hi_k, min(k + 1, grid.size - 1))
        ci95[nl] = (float(grid[lo_k]), float(grid[hi_k]))
        stderr[nl] = stderr_of_interval(*ci95[nl])
        params[nl] = float(grid[k])
    for name in problem.free:
        lo, hi = bounds.get(name, _DEFAULT_BOUNDS.get(name, (0.0, math.inf)))
        if min(abs(params[name] - lo), abs(params[name] - hi)) <= 1e-6 * max(abs(params[name]), 1e-12):
            warnings.append(f"{structure} model: {name} ended at its limit ({params[name]:.4g}); its interval "
                            "is not a measurement")
    step = [tr for tr in problem.traces if tr.kind == "step"]
    dwells = [tr for tr in problem.traces if tr.kind == "sine"]
    offsets = problem.offsets(params)

    def predicted(tr: ServoTrace) -> NDArray[np.float64]:
        return simulate_trace(tr, structure, params) + offsets.get(tr.label, 0.0)

    return ServoModelFit(
        structure, params, stderr, ci95, tuple(k for k in names if k in fix), chi2, n,
        len(names) - len(fix) - len(problem.ties) + len(problem.traces), offsets, dict(sigma),
        J=dwell_cost(params, structure, problem.traces, response) if response else math.nan,
        step_fit_percent=fit_percent(step[0].angle_rad, predicted(step[0])) if step else None,
        dwell_fit_percent=(fit_percent(np.concatenate([tr.angle_rad - offsets[tr.label] for tr in dwells]),
                                       np.concatenate([predicted(tr) - offsets[tr.label] for tr in dwells]))
                           if dwells else None),
        traces=tuple(problem.traces), warnings=tuple(warnings),
        tied={name: tie.expression for name, tie in problem.ties.items()})


def interval_kind(structure: str, name: str, tied: Mapping[str, Any] = MappingProxyType({})) -> str:
    """How a servo model's parameter's 95 % interval is made (:func:`servoscope.parameters.interval95`).

    The quantization step's from its cost profile; a positive parameter fitted on a log scale
    log-normal (never below zero); a tied one's and the rest normal (delta method, sandwich).
    """
    if structure == "quantization" and name == NONLINEAR_PARAMETER["quantization"] and name not in tied:
        return "profile"
    if name in _POSITIVE and name not in tied:
        return "lognormal"
    return "normal"


def lag1(r: NDArray[np.float64]) -> float:
    r = r - r.mean()
    den = float(r @ r)
    return min(max(float(r[1:] @ r[:-1]) / den, 0.0), 0.95) if den > 0 and r.size > 2 else 0.0
