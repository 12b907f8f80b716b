"""Model selection between the time-domain servo structures, and cross-validation (issue 17).

See :mod:`servoscope.sysid.servo_fit` for the fits. :func:`select_servo_model` fits the
linear model and each nonlinear structure asked for, weights the dwells, the step and the
sweeps by their own noise, compares them by AIC and BIC in units of the best fit's residual variance
(widened by its lag-1 autocorrelation, with the effective number of samples reduced by the
same factor), and selects a nonlinear structure only when its BIC beats the linear model's by
more than :data:`BIC_MARGIN` ("very strong" on Kass & Raftery's scale): a tracking artefact
must not read as a nonlinearity. The selected model's errors are widened to the
delete-one-test jackknife's where the tests disagree more than they say, and a play's by the
tracker's sub-pixel bias (:data:`TRACKER_BIAS_PX`).
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from threadpoolctl import threadpool_limits

from ..errors import ServoscopeError
from ..parameters import check_held, interval95, tie_names
from ..results import import_pandas, jsonable
from .servo_fit import (ServoModelFit, dwell_cost, fit_percent, fit_servo_model, interval_kind,
                        lag1, linear_starts, measured_noise, trace_group)
from .servo_sim import LINEAR_PARAMETERS, NONLINEAR_PARAMETER, ServoTrace, simulate_trace

__all__ = ["BIC_MARGIN", "MIN_EFFECT_PX", "STEP_FIT_PREDICTS", "TRACKER_BIAS_PX", "ServoModelSelection",
           "cross_validate", "effect_px", "select_servo_model"]

#: BIC a nonlinear structure must gain over the linear model to be selected.
BIC_MARGIN = 10.0
#: Smallest change a nonlinear structure may make to the stickers' motion (RMS over the traces,
#: px) to be selected: a codec's motion prediction holds a sticker still near each turn, which
#: reads as play. Measured on the twin's linear servo under H.264 (quick preset, 480×384,
#: seeds 0 and 1): "backlash" of 0.00026 rad won the BIC by 500 while moving the stickers
#: 0.013–0.016 px RMS; a true play of 0.004 rad moves them 0.23 px.
MIN_EFFECT_PX = 0.05
#: The tracker's sub-pixel bias on the play's width, px at the stickers: each backlash interval is
#: widened by it over the stickers' radius (issue 31). Measured on the twin's backlash servo (raw
#: frames, 320×256, stickers 133 px from the axis, seeds 0 and 1): from dwells at two amplitudes,
#: or a sweep alone, errors of 0.0036–0.0082 px (1 to 6e-5 rad), common to all tests (no jackknife
#: sees them) and 2 to 4 of the fit's own standard errors.
TRACKER_BIAS_PX = 0.01


@dataclass(frozen=True)
class ServoModelSelection:
    """Every structure tried, the one selected, and the cross-validation between the dwells and the step.

    Attributes
    ----------
    candidates : list of ServoModelFit
        One per structure, each with its AIC and BIC.
    selected : ServoModelFit
    scale : float
        The cost's unit in AIC/BIC: the best candidate's residual variance (in noise units) times
        its autocorrelation factor.
    cross_validation : dict
        ``dwells_to_step`` (the model fitted to the dwells alone, its fit on the step in
        percent), ``step_to_dwells`` (fitted to the step alone, its J on the dwells) and a
        ``verdict``; absent parts are None. Without a step, a sweep's under ``dwells_to_sweep``
        and ``sweep_to_dwells`` (:func:`cross_validate`).
    warnings : list of str
        Why a better-fitting structure was not selected (its effect under
        :data:`MIN_EFFECT_PX`).
    """

    candidates: list[ServoModelFit]
    selected: ServoModelFit
    scale: float
    cross_validation: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    def summary(self) -> dict[str, Any]:
        """Plain types: the selected structure, every candidate's fit, the cross-validation."""
        return jsonable({"selected": self.selected.structure, "scale": self.scale,
                         "candidates": [c.summary() for c in self.candidates],
                         "cross_validation": dict(self.cross_validation), "warnings": list(self.warnings)})

    @classmethod
    def from_summary(cls, data: dict[str, Any]) -> "ServoModelSelection":
        """Rebuild from :meth:`summary` (the fits without their traces: they are the tracks')."""
        fits = [ServoModelFit.from_summary(c) for c in data["candidates"]]
        selected = next(f for f in fits if f.structure == data["selected"])
        return cls(fits, selected, float(data["scale"]), dict(data.get("cross_validation") or {}),
                   tuple(data.get("warnings") or ()))

    def to_pandas(self) -> Any:
        """One row per candidate structure."""
        pd = import_pandas()
        return pd.DataFrame([{"structure": c.structure, "aic": c.aic, "bic": c.bic, "J": c.J, "chi2": c.chi2,
                              "step_fit_percent": c.step_fit_percent, "selected": c is self.selected}
                             for c in self.candidates]).set_index("structure")

    def _repr_html_(self) -> str:
        rows = "".join(f"<tr><td>{c.structure}{' (selected)' if c is self.selected else ''}</td><td>{c.bic:.1f}</td>"
                       f"<td>{c.J:.3g}</td></tr>" for c in self.candidates)
        return f"<table><tr><th>structure</th><th>BIC</th><th>J</th></tr>{rows}</table>"


def _information(fits: list[ServoModelFit]) -> tuple[list[ServoModelFit], float]:
    """Each fit with its AIC and BIC, in units of the best fit's residual variance (see the module's
    description), and that unit."""
    best = min(fits, key=lambda f: f.chi2)
    rho = lag1(np.concatenate([(tr.angle_rad - best.predict(tr)) for tr in best.traces]))
    factor = (1.0 + rho) / (1.0 - rho)
    scale = max(best.chi2 / max(best.n_samples - best.n_free, 1), 1e-12) * factor
    n_eff = max(best.n_samples / factor, 2.0)
    return [replace(f, aic=f.chi2 / scale + 2.0 * f.n_free, bic=f.chi2 / scale + f.n_free * math.log(n_eff))
            for f in fits], scale


def _known(structures) -> set[str]:
    """The parameters of the linear model and of each of ``structures``."""
    return {*LINEAR_PARAMETERS, *(NONLINEAR_PARAMETER[s] for s in structures if s in NONLINEAR_PARAMETER)}


def select_servo_model(traces: list[ServoTrace], structures: tuple[str, ...] | list[str], *,
                       start: dict[str, float] | None = None, fix: dict[str, float] | None = None,
                       ties: dict[str, str] | None = None,
                       bounds: dict[str, tuple[float, float]] | None = None,
                       response: dict[str, tuple[float, float, float]] | None = None,
                       t0_stderr_s: float = 0.0) -> ServoModelSelection:
    """Fit the linear model and each structure in ``structures``; select by BIC; cross-validate.

    Parameters
    ----------
    traces : list of ServoTrace
    structures : sequence of str
        Nonlinear structures to try beside the linear model (which is always tried).
    start, fix, bounds, response, t0_stderr_s, ties
        As for :func:`fit_servo_model`; a held parameter a structure does not have is
        refused (a nonlinear one is held, or tied, only in its own structure).

    Returns
    -------
    ServoModelSelection
    """
    with threadpool_limits(1):  # see pyproject.toml: small matrices, many of them
        return _select(traces, structures, start, fix, bounds, response, t0_stderr_s, dict(ties or {}))


def _select(traces, structures, start, fix, bounds, response, t0_stderr_s, ties) -> ServoModelSelection:
    """The work of :func:`select_servo_model` (see there).

    Long because it is the selection's order written out: a first fit of each structure, the
    data sets' weights from the best, a second fit, the information criteria, the choice,
    the jackknife and the cross-validation.
    """
    tried = ["linear", *[s for s in structures if s != "linear"]]
    fix, bounds = dict(fix or {}), dict(bounds or {})

    def held(structure: str, d: dict) -> dict:
        # A structure's own holds (a tie also needs its expression's names to be the structure's).
        own = set(LINEAR_PARAMETERS) | {NONLINEAR_PARAMETER.get(structure)}
        return {k: v for k, v in d.items() if k in own and (not isinstance(v, str) or tie_names(v) <= own)}

    check_held(_known(tried), fix, bounds, ties, who="the models tried")
    sigma = measured_noise(traces)
    # The linear model from the given start (the frequency-domain fit's) and from a coarse grid, so
    # that a frequency-domain fit gone wrong (a strongly nonlinear servo) does not decide the rest.
    starts = ([start] if start else []) + linear_starts(traces, sigma)
    first = [fit_servo_model(traces, "linear", start=starts, fix=held("linear", fix), bounds=held("linear", bounds),
                             ties=held("linear", ties))]
    lin = {k: first[0].params[k] for k in LINEAR_PARAMETERS}
    first += [fit_servo_model(traces, s, start=lin, fix=held(s, fix), bounds=held(s, bounds), ties=held(s, ties))
              for s in tried[1:]]
    best = min(first, key=lambda f: f.chi2)
    for group in sigma:
        r = np.concatenate([tr.angle_rad - best.predict(tr) for tr in best.traces if trace_group(tr) == group])
        sigma[group] = max(sigma[group], float(np.sqrt(np.mean(r**2))))
    fits = []
    # Refitted with these weights: the linear model and the two best; the rest (far worse) keep
    # their fits, their costs in the new weights.
    refit = {"linear", *sorted(tried, key=lambda s: first[tried.index(s)].chi2)[:2]}
    for s, f in zip(tried, first):
        if s not in refit:
            chi2 = sum(float(np.sum(((tr.angle_rad - f.predict(tr)) / sigma[trace_group(tr)]) ** 2)) for tr in f.traces)
            fits.append(replace(f, chi2=chi2, sigma=dict(sigma),
                                J=dwell_cost(f.params, s, traces, response) if response else math.nan))
            continue
        # From the first fit (the quantization step is profiled again, not started).
        warm = {k: v for k, v in f.params.items() if not (s == "quantization" and k == "quantization_step")}
        fits.append(fit_servo_model(traces, s, start=warm, fix=held(s, fix), bounds=held(s, bounds), ties=held(s, ties),
                                    sigma=sigma, response=response, t0_stderr_s=t0_stderr_s))
    fits, scale = _information(fits)
    linear = fits[0]
    selected = min(fits[1:], key=lambda f: f.bic, default=linear)
    notes: list[str] = []
    if selected is not linear and not linear.bic - selected.bic > BIC_MARGIN:
        selected = linear
    if selected is not linear:
        effect = effect_px(selected, linear)
        if effect < MIN_EFFECT_PX:
            notes.append(f"the {selected.structure} model fits better (BIC {linear.bic - selected.bic:.0f} lower) but "
                         f"moves the stickers only {effect:.3f} px RMS away from the linear model's, under the "
                         f"{MIN_EFFECT_PX} px a codec's motion prediction can fake: the linear model is kept")
            selected = linear
    if len(structures) == 1 and structures[0] != "linear":
        selected = fits[1]  # asked for by name: that structure, the others for comparison
    widened = _tracker_bias(_jackknife(traces, selected, sigma, held(selected.structure, fix),
                                       held(selected.structure, bounds)))
    fits = [widened if f is selected else f for f in fits]
    selected = widened
    cv = cross_validate(traces, selected, sigma=sigma, response=response, fix=held(selected.structure, fix),
                        bounds=held(selected.structure, bounds))
    return ServoModelSelection(fits, selected, scale, cv, tuple(notes))


def effect_px(fit: ServoModelFit, reference: ServoModelFit) -> float:
    """How far ``fit`` moves the stickers from ``reference``'s prediction, RMS over every sample, px.

    Each trace's angle difference times its sticker radius (inf where the radius is not known:
    no floor can be applied then).
    """
    moves = []
    for tr in fit.traces:
        d = simulate_trace(tr, fit.structure, fit.params) - simulate_trace(tr, reference.structure, reference.params)
        d = d - d.mean()  # each test's rest angle is fitted: a constant difference is none
        moves.append(d * tr.sticker_radius_px)
    m = np.concatenate(moves) if moves else np.array([np.nan])
    value = float(np.sqrt(np.mean(m**2)))
    return value if math.isfinite(value) else math.inf


def _jackknife(traces: list[ServoTrace], fit: ServoModelFit, sigma: dict[str, float], fix: dict,
               bounds: dict) -> ServoModelFit:
    """``fit`` with its errors widened to the delete-one-test jackknife's where the tests disagree more than they say.

    The sandwich errors describe the noise within each test; a tracking or rendering
    systematic that differs from test to test (a sticker's sub-pixel bias, an exposure not
    quite modelled) shows only between tests. Each test is left out in turn and the model
    refitted from the full fit (the quantization step held at its profiled value: its
    interval is the profile's). Needs at least 4 tests.
    """
    if len(traces) < 4:
        return fit
    nl = fit.nonlinear_parameter
    hold = dict(fix)
    if fit.structure == "quantization" and nl is not None:
        hold[nl] = fit.params[nl]
    free = [k for k in fit.params if k not in hold and k not in fit.tied]
    values = []
    for i in range(len(traces)):
        rest = traces[:i] + traces[i + 1:]
        try:
            part = fit_servo_model(rest, fit.structure, start=dict(fit.params), fix=hold, bounds=bounds, sigma=sigma,
                                   ties=fit.tied)
        except ServoscopeError:
            return fit
        values.append([part.params[k] for k in free])
    v = np.asarray(values)
    n = v.shape[0]
    jack = np.sqrt((n - 1) / n * np.sum((v - v.mean(axis=0)) ** 2, axis=0))
    stderr, ci95 = dict(fit.stderr), dict(fit.ci95)
    for name, se in zip(free, jack):
        if se > stderr[name]:
            # The interval made as the fit's own was (a positive parameter's log-normal, never below zero).
            stderr[name] = float(se)
            ci95[name] = interval95(fit.params[name], se, interval_kind(fit.structure, name, fit.tied))
    return replace(fit, stderr=stderr, ci95=ci95)


def _tracker_bias(fit: ServoModelFit) -> ServoModelFit:
    """``fit`` with its play's error widened by :data:`TRACKER_BIAS_PX` over the stickers' radius (where known)."""
    name = "backlash_rad"
    radius = [tr.sticker_radius_px for tr in fit.traces if math.isfinite(tr.sticker_radius_px)]
    if fit.structure != "backlash" or name in fit.fixed or name in fit.tied or not radius:
        return fit
    se = math.hypot(fit.stderr[name], TRACKER_BIAS_PX / float(np.median(radius)))
    return replace(fit, stderr={**fit.stderr, name: se},
                   ci95={**fit.ci95, name: interval95(fit.params[name], se, interval_kind(fit.structure, name))})


def cross_validate(traces: list[ServoTrace], model: ServoModelFit, *, sigma: dict[str, float],
                   response: dict | None = None, fix: dict | None = None, bounds: dict | None = None
                   ) -> dict[str, Any]:
    """Fit the model's structure to the dwells alone and predict the step, and the reverse.

    Without a step, a sweep takes its place (``dwells_to_sweep``, ``sweep_to_dwells``): a
    different input, so a test of the model all the same.

    Returns
    -------
    dict
        ``dwells_to_step``: ``{"fit_percent"}`` of the step predicted by the dwells' fit (its
        rest angle the step's own, from the samples before the input arrived);
        ``step_to_dwells``: ``{"J"}`` of the dwells predicted by the step's fit; ``verdict``
        (it says why when nothing could be done). With a sweep and no step, the same under
        ``dwells_to_sweep`` and ``sweep_to_dwells``.
    """
    dwells = [tr for tr in traces if tr.kind == "sine"]
    other = [tr for tr in traces if tr.kind == "step"] or [tr for tr in traces if tr.kind == "sweep"]
    out: dict[str, Any] = {"dwells_to_step": None, "step_to_dwells": None, "verdict": None}
    if not (dwells and other):
        kinds = sorted({tr.kind for tr in traces})
        out["verdict"] = ("not done: cross-validation needs the dwells and a step or a sweep; the campaign has "
                          f"{' and '.join({'sine': 'dwells', 'step': 'a step', 'sweep': 'a sweep'}[k] for k in kinds)}"
                          " only" if kinds else "not done: no tests")
        return out
    name = other[0].kind
    forward, backward = f"dwells_to_{name}", f"{name}_to_dwells"
    out.update({forward: None, backward: None})
    start = dict(model.params)
    problems = []
    try:
        from_dwells = fit_servo_model(dwells, model.structure, start=start, fix=fix, bounds=bounds, sigma=sigma,
                                      ties=model.tied)
        test = other[0]
        predicted = simulate_trace(test, model.structure, from_dwells.params)
        before = test.time_s < test.t0_s + from_dwells.params["dead_time_s"]
        rest = float(np.mean((test.angle_rad - predicted)[before])) if np.any(test.time_s < test.t0_s) else float(
            np.mean(test.angle_rad - predicted))
        out[forward] = {"fit_percent": fit_percent(test.angle_rad, predicted + rest)}
    except ServoscopeError as exc:
        problems.append(f"dwells → {name} not done ({exc})")
    try:
        from_other = fit_servo_model(other, model.structure, start=start, fix=fix, bounds=bounds, sigma=sigma,
                                     ties=model.tied)
        if response:
            out[backward] = {"J": dwell_cost(from_other.params, model.structure, dwells, response)}
    except ServoscopeError as exc:
        problems.append(f"{name} → dwells not done ({exc})")
    out["verdict"] = _verdict(out, problems, name)
    return out


#: The step's (or, without one, the sweep's) fit (percent) a model must reach to be said to predict it.
STEP_FIT_PREDICTS = 90.0


def _verdict(cv: dict[str, Any], problems: list[str], name: str = "step") -> str:
    parts = []
    d2s, s2d = cv[f"dwells_to_{name}"], cv[f"{name}_to_dwells"]
    if d2s is not None:
        ok = d2s["fit_percent"] >= STEP_FIT_PREDICTS
        parts.append(f"the dwells' model {'predicts' if ok else 'does not predict'} the {name} "
                     f"(fit {d2s['fit_percent']:.1f} %)")
    if s2d is not None and math.isfinite(s2d["J"]):
        ok = s2d["J"] <= 100.0
        parts.append(f"the {name}'s model {'predicts' if ok else 'does not predict'} the dwells (J {s2d['J']:.3g})")
    return "; ".join(parts + problems) or "not done"
