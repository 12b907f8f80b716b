"""A campaign's step test: analysed against the identified model, its dead time's error with the model's.

A step of :func:`servoscope.campaign.runner.identify`.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Callable

import numpy as np

from ..defaults import STEP_DISCERNIBLE_SIGMA
from ..errors import ServoscopeError
from ..markers.track import Track
from ..sysid import analyse_step
from .manifest import Campaign, TestSpec
from .result import input_start, input_start_stderr

__all__ = ["step_against_time_domain_model", "step_analysis", "step_dead_time_model_stderr", "step_test",
           "step_with_model_error"]


def step_dead_time_model_stderr(model, run_step: Callable[[object], object]) -> float:
    """How much the step's dead time moves with the model's own uncertainty (s).

    The step's dead time is fitted against the model's step shape (its gain
    free): a natural frequency or damping that is off by its standard error
    makes the motion start earlier or later. Propagated by central
    differences over (ωn, ζ) with their covariance; 0 for models of other
    forms (their shape parameters are not the physical ones).
    """
    import control  # deferred: only here

    names = list(model.param_names)
    if not {"gain", "natural_frequency_rad_s", "damping_ratio"} <= set(names):
        return 0.0
    idx = [names.index("natural_frequency_rad_s"), names.index("damping_ratio")]
    cov = np.asarray(model.covariance, dtype=float)[np.ix_(idx, idx)]
    if not np.all(np.isfinite(cov)):
        return 0.0
    base = {k: float(model.params[k]) for k in ("gain", "natural_frequency_rad_s", "damping_ratio")}
    grad = []
    for i, name in enumerate(("natural_frequency_rad_s", "damping_ratio")):
        h = math.sqrt(max(cov[i, i], 0.0))
        if h <= 0:
            grad.append(0.0)
            continue
        taus = []
        for sign in (1.0, -1.0):
            p = dict(base)
            p[name] += sign * h
            wn, zeta = p["natural_frequency_rad_s"], p["damping_ratio"]
            result = run_step(control.tf([p["gain"] * wn**2], [1.0, 2.0 * zeta * wn, wn**2]))
            taus.append(getattr(result, "dead_time_s", None))
        if any(t is None or not math.isfinite(t) for t in taus):
            return 0.0
        grad.append((taus[0] - taus[1]) / (2.0 * h))
    g = np.asarray(grad)
    return float(math.sqrt(max(g @ cov @ g, 0.0)))


def step_with_model_error(run_step, model):
    """The step analysed against the frequency-domain model, its dead time's error with the model's."""
    step = run_step(model.transfer_function)
    if step.dead_time_s is not None and step.dead_time_stderr_s is not None:
        # Fitted against the model's shape: the model's uncertainty is the step's too.
        model_se = step_dead_time_model_stderr(model, run_step)
        step = replace(step, dead_time_stderr_s=math.hypot(step.dead_time_stderr_s, model_se))
    return step


def step_against_time_domain_model(run_step, selection):
    """The step analysed against the time-domain model's linear part, its dead time's error with it."""
    step = replace(run_step(selection.selected.linear_transfer_function),
                   model_source=f"{selection.selected.structure} model's linear part")
    linear_se = selection.selected.stderr.get("dead_time_s") or 0.0
    if step.dead_time_stderr_s is not None:
        step = replace(step, dead_time_stderr_s=math.hypot(step.dead_time_stderr_s, linear_se))
    return step


def step_analysis(test: TestSpec, track: Track, t0: float, model, selection, warnings: list[str]):
    """One step test against the model (else the time-domain model's linear part); None when it fails."""
    def run_step(tf):
        return analyse_step(track.angle_time_s, track.angle_rad, t0_s=t0, step_size=test.amplitude,
                            valid=track.valid, model=tf, t0_stderr_s=input_start_stderr(test, track))

    try:
        return step_with_model_error(run_step, model)
    except ServoscopeError as exc:
        # Also when the analysis stood and only its dead time's model error failed: left out whole.
        failure = exc
    if selection is not None:
        # A servo the frequency-domain model cannot describe (it ended unstable): the step is
        # analysed against the time-domain model's linear part.
        try:
            step = step_against_time_domain_model(run_step, selection)
        except ServoscopeError:
            pass
        else:
            warnings.append(f"{test.label}: step analysed against the {selection.selected.structure} "
                            f"model's linear part (the frequency-domain model: {failure})")
            return step
    warnings.append(f"{test.label}: step test left out: {failure}")
    return None


def step_test(campaign: Campaign, tracks: dict[str, Track], model, selection, warnings: list[str]):
    """The first step test's analysis and label: (None, None) without one that moved and could be analysed."""
    if not campaign.step_tests:
        return None, None
    test = campaign.step_tests[0]
    track = tracks[test.label]
    t0 = input_start(test, track)
    step = None
    if t0 is None:
        warnings.append(f"{test.label}: step test without an input start (LED or t0_s): dead time not measured")
    elif track.n_valid < 10:
        warnings.append(f"{test.label}: step test has only {track.n_valid} valid frames; left out")
    else:
        step = step_analysis(test, track, t0, model, selection, warnings)
        if step is not None and not step.output_moved:
            # Metrics of a step that never moved would be NaN or noise.
            warnings.append(
                f"{test.label}: step test left out: the output never moves "
                f"(change within {STEP_DISCERNIBLE_SIGMA:g} noise sigma of the baseline)"
            )
            step = None
    if len(campaign.step_tests) > 1:
        warnings.append(f"{len(campaign.step_tests)} step tests: only the first ({test.label}) is analysed")
    return step, (None if step is None else test.label)
